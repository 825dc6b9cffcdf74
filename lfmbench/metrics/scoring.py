"""Scoring one batch with every registered metric: :func:`score_batch` and its settings :class:`ScoreOptions`."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import torch

from lfmbench.metrics import display, flicker, regions
from lfmbench.metrics.registry import _BLOCK_OF_GROUP, BLOCKS, REGISTRY
from lfmbench.vocabulary import REFERENCES  # the one definition (torch-free: the command line reads it)

__all__ = ["ScoreOptions", "score_batch", "REFERENCES", "CROSS_SENSOR_GROUPS", "to_common"]

#: What the cross-sensor columns are scored against (:class:`ScoreOptions` ``reference``): ``"own"``, the sensor's
#: own ``gt`` (its reference exposure, every published result before 2026-11-28); ``"common"``, the sample's
#: ``gt_common`` (one fixed reference window through one reference sensor, the same for every sensor:
#: :meth:`lfmbench.datasets.LFMCaptureDataset._gt_common`), so a cross-sensor ranking compares one truth.

#: Metric groups scored against the common reference when ``reference="common"``: the full-image (``hdr``,
#: ``perceptual``, ``display``) and ghost (``region``) columns. The LED groups (``led``, ``flicker``) stay on each
#: sensor's own ``gt``: they score the sensor's own lamps against its own exposure.
CROSS_SENSOR_GROUPS = ("hdr", "region", "perceptual", "display")


@dataclass
class ScoreOptions:
    """Settings of :func:`score_batch`."""

    perceptual: bool = False  #: also PU21-PSNR and ColorVideoVDP (needs the optional cvvdp package)
    fps: float = 60.0  #: frame rate for ColorVideoVDP, s^-1
    cd_per_unit: float | None = None  #: luminance calibration, cd m^-2 per e- (None: GT p99 at display peak)
    region: flicker.RegionMetricOptions = field(default_factory=flicker.RegionMetricOptions)
    margin_px: int = regions.LED_MARGIN_PX
    ring_px: int = regions.GHOST_RING_PX
    #: ISP pipeline (shipped name or YAML path) of the display-referred columns; None: no display metrics
    isp: str | None = display.DEFAULT_PIPELINE
    #: sensor preset (object, name or path) the samples were simulated with; None: ``meta["sensor"]`` of the batch
    sensor: Any = None
    #: ``"own"`` or ``"common"`` (:data:`REFERENCES`): the truth of the :data:`CROSS_SENSOR_GROUPS` columns
    reference: str = "own"


def _f(x) -> float:
    v = float(x)
    return v if math.isfinite(v) or math.isinf(v) else float("nan")


def _enabled(group: str, o: ScoreOptions) -> bool:
    if group == "perceptual":
        return o.perceptual
    if group == "display":
        return o.isp is not None
    return True


def to_common(pred: torch.Tensor, gt: torch.Tensor, gt_common: torch.Tensor) -> torch.Tensor:
    """An estimate in the sensor's own units mapped to the common reference's: per sample and 2x2 CFA phase one gain
    k = sum(gt_common) / sum(gt) over the sample's frames and pixels of that phase (every shipped preset's mosaic is
    GRBG, so a phase is one colour; a phase whose ``gt`` sums to 0 keeps gain 1). The gain comes from the two truths
    only, never from the estimate: it absorbs what a linear map can (pixel size, QE, exposure length, gain) and
    leaves every difference of the estimate from ``gt`` scaled, plus what the sensor's own reference window sees
    differently from the common one (motion over another time, spectral mismatch), in the error.

    Args:
        pred, gt, gt_common: (B, F, 1, H, W) input-referred e- (``gt_common``: of the reference sensor).

    Returns:
        (B, F, 1, H, W) ``pred * k``, in the units of ``gt_common``.
    """
    B = gt.shape[0]
    k = torch.ones(B, 1, 1, 2, 2, dtype=gt.dtype, device=gt.device)
    num, den = gt_common.to(gt.dtype), gt
    for i in range(2):
        for j in range(2):
            n = num[..., i::2, j::2].reshape(B, -1).sum(1)
            d = den[..., i::2, j::2].reshape(B, -1).sum(1)
            k[:, 0, 0, i, j] = torch.where(d > 0, n / torch.where(d > 0, d, torch.ones_like(d)), torch.ones_like(d))
    H, W = gt.shape[-2:]
    gain = k.repeat(1, 1, 1, (H + 1) // 2, (W + 1) // 2)[..., :H, :W]
    return pred * gain


def _common_inputs(pred: torch.Tensor, batch: dict, o: ScoreOptions) -> tuple[torch.Tensor, dict, ScoreOptions]:
    """(pred, batch, options) the :data:`CROSS_SENSOR_GROUPS` are scored with: with ``reference="common"`` the
    estimate mapped by :func:`to_common`, ``gt`` replaced by ``gt_common`` and the display ISP bound to the
    reference sensor (one ISP for every sensor); else the inputs unchanged."""
    if o.reference not in REFERENCES:
        raise ValueError(f"ScoreOptions.reference must be one of {REFERENCES}, got {o.reference!r:.40}")
    if o.reference == "own":
        return pred, batch, o
    gc = batch.get("gt_common")
    if gc is None:
        raise ValueError("ScoreOptions(reference='common') needs the batch's gt_common (a dataset made with "
                         "outputs including 'gt_common', on the per-sample path)")
    if gc.shape != batch["gt"].shape:
        raise ValueError(f"batch['gt_common'] must have the shape of batch['gt'] {tuple(batch['gt'].shape)}, got "
                         f"{tuple(gc.shape)}")
    from dataclasses import replace  # noqa: PLC0415

    from lfmbench.datasets.capture import COMMON_REFERENCE_SENSOR  # noqa: PLC0415

    gt = batch["gt"]
    return (to_common(pred, gt, gc), dict(batch, gt=gc.to(gt.dtype)),
            replace(o, sensor=COMMON_REFERENCE_SENSOR))


def score_batch(pred: torch.Tensor, batch: dict, options: ScoreOptions | None = None) -> list[dict]:
    """Every registered metric for one batch, one dict per sample (each block computed once).

    Args:
        pred: fused estimate, (B, F, 1, H, W), in the units of ``batch['gt']`` (input-referred e-).
        batch: sample dict (``docs/guide/contracts.md`` section 3) with ``gt`` and ``light_index``; ``saturated`` and
            ``lpd_lcg_e`` are used when present. Metrics whose ``needs`` are missing are left out.
        options: see :class:`ScoreOptions`; with ``reference="common"`` the batch needs ``gt_common`` and the
            :data:`CROSS_SENSOR_GROUPS` columns score :func:`to_common` of ``pred`` against it.

    Returns:
        list of B dicts: metric name -> float, plus what the blocks add: ``lights`` (per-light records),
        ``region_frames``, ``n_lights``, ``saturation_flag``, and ``errors`` (texts) when a block with
        ``on_error="record"`` failed (its metrics are then NaN).
    """
    o = options or ScoreOptions()
    gt = batch["gt"]
    if pred.shape != gt.shape:
        raise ValueError(f"pred must have the shape of batch['gt'] {tuple(gt.shape)}, got {tuple(pred.shape)}")
    pred = pred.to(gt.dtype)
    common = _common_inputs(pred, batch, o)

    def inputs(group: str) -> tuple:
        return common if group in CROSS_SENSOR_GROUPS else (pred, batch, o)
    res: list[dict] = [dict() for _ in range(gt.shape[0])]
    for block in BLOCKS.values():
        if not _enabled(block.name, o) or any(batch.get(k) is None for k in block.needs):
            continue
        try:
            out = block.compute(*inputs(block.name))
        except Exception as exc:
            if block.on_error != "record":
                raise
            names = [s.name for s in REGISTRY.values()
                     if _BLOCK_OF_GROUP.get(s.group) == block.name and s.fn is None and s.derive is None]
            for r in res:
                r.update({n: float("nan") for n in names})
                r.setdefault("errors", []).append(f"{block.name}: {type(exc).__name__}: {exc}")
            continue
        for r, a in zip(res, out):
            r.update({k: (_f(v) if isinstance(v, (float, torch.Tensor)) else v) for k, v in a.items()})
    for s in REGISTRY.values():
        if s.fn is None or not _enabled(s.group, o) or any(batch.get(k) is None for k in s.needs):
            continue
        v = s.fn(*inputs(s.group))
        for i, r in enumerate(res):
            r[s.name] = _f(v[i])
    for s in REGISTRY.values():
        if s.derive is None:
            continue
        for r in res:
            if all(i in r for i in s.inputs):
                r[s.name] = _f(s.derive(r))
    return res
