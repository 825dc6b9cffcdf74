"""What a metric is: :class:`MetricSpec` (one registered metric: name, version, reference, unit, ranking
direction, column, aggregation, how it is computed, valid range) and :class:`MetricBlock` (several metrics
computed in one pass). The registered ones: :mod:`lfmbench.metrics.registry`."""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["MetricSpec", "MetricBlock"]


@dataclass(frozen=True)
class MetricSpec:
    """One registered metric; adding a metric is one such entry in :data:`REGISTRY`.

    Attributes:
        name: key in result files.
        version: bumped whenever the definition or a default changes.
        reference: where the definition comes from.
        unit: unit of the value ("1" = dimensionless).
        higher_is_better: ranking direction.
        group: ``hdr``, ``perceptual`` (only with ``ScoreOptions.perceptual``), ``flicker``, ``region``, ``led``,
            ``display`` (only with ``ScoreOptions.isp``; secondary: :data:`SECONDARY_GROUPS`); a metric with
            neither ``fn`` nor ``derive`` is produced by the block of this name in :data:`BLOCKS`.
        header: leaderboard column header.
        aggregate: over scenes: ``mean`` (mean of the per-scene values) or ``pooled`` (sum of value x
            ``weight`` / sum of ``weight``, e.g. dropout over all region-frames).
        weight: per-sample key of the pooling weight (``aggregate="pooled"``).
        fn: ``fn(pred (B, F, 1, H, W), batch, options) -> (B,)`` values, or None.
        derive: ``derive(values: dict) -> float`` from other metrics of the same sample (``inputs``), or None.
        inputs: the metrics ``derive`` reads.
        needs: batch keys ``fn`` needs (the metric is skipped when one is missing).
        digits: decimals shown in tables.
        show: ``console`` (terminal table and Markdown), ``table`` (Markdown only), ``none`` (result file only).
        valid: the documented range ``(lo, hi)`` of a value, in ``unit``; the leaderboard refuses a result file
            holding a value outside it (or a non-finite one), naming the file and the field.
        inf_ok: ``+inf`` is a valid value too (a PSNR of identical images).
    """

    name: str
    version: str
    reference: str
    unit: str
    higher_is_better: bool
    group: str
    header: str = ""
    aggregate: str = "mean"
    weight: str | None = None
    fn: Callable[..., Any] | None = None
    derive: Callable[[dict], float] | None = None
    inputs: tuple[str, ...] = ()
    needs: tuple[str, ...] = ()
    digits: int = 3
    show: str = "table"
    valid: tuple[float, float] = (-math.inf, math.inf)
    inf_ok: bool = False

    def value_error(self, v: Any) -> str | None:
        """Why ``v`` (a value read from a result file: a number, ``None`` or the strings ``"nan"``, ``"inf"``
        that :func:`lfmbench.evaluation.results.jsonable` writes) is not a valid value of this metric, or None.
        Missing values (``None``, NaN) are valid: a sample without LED regions has no LED score."""
        if v is None or (isinstance(v, str) and v == "nan"):
            return None
        if isinstance(v, str) and v in ("inf", "-inf"):
            x = math.inf if v == "inf" else -math.inf
        elif isinstance(v, bool) or not isinstance(v, (int, float)):
            return "is not a number"
        else:
            try:
                x = float(v)
            except OverflowError:
                return "is not a finite number"
        if math.isnan(x):
            return None
        if x == math.inf and self.inf_ok:
            return None
        lo, hi = self.valid
        if not math.isfinite(x):
            return "is not a finite number"
        slack = 1e-6 * (1.0 + abs(x))  # float32 rounding of a value at a bound (an FMI of 1.0000001)
        if not lo - slack <= x <= hi + slack:
            return f"is outside the range of {self.name}, [{lo:g}, {hi:g}] {self.unit}"
        return None

    @property
    def direction(self) -> str:
        """``"higher"`` or ``"lower"`` (is better)."""
        return "higher" if self.higher_is_better else "lower"


@dataclass(frozen=True)
class MetricBlock:
    """Several metrics computed in one pass: ``compute(pred, batch, options) -> list of B dicts``.

    ``needs``: batch keys it needs (skipped when one is missing). ``on_error``: ``raise`` (the scene fails) or
    ``record`` (its metrics become NaN and the error text is added to the sample's ``errors`` list: for an
    optional external package).
    """

    name: str
    compute: Callable[..., list[dict]]
    needs: tuple[str, ...] = ()
    on_error: str = "raise"
