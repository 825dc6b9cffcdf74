"""Scoring one batch with every registered metric: :func:`score_batch` and its settings :class:`ScoreOptions`."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import torch

from lfmbench.metrics import display, flicker, regions
from lfmbench.metrics.registry import _BLOCK_OF_GROUP, BLOCKS, REGISTRY

__all__ = ["ScoreOptions", "score_batch"]


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


def _f(x) -> float:
    v = float(x)
    return v if math.isfinite(v) or math.isinf(v) else float("nan")


def _enabled(group: str, o: ScoreOptions) -> bool:
    if group == "perceptual":
        return o.perceptual
    if group == "display":
        return o.isp is not None
    return True


def score_batch(pred: torch.Tensor, batch: dict, options: ScoreOptions | None = None) -> list[dict]:
    """Every registered metric for one batch, one dict per sample (each block computed once).

    Args:
        pred: fused estimate, (B, F, 1, H, W), in the units of ``batch['gt']`` (input-referred e-).
        batch: sample dict (``docs/guide/contracts.md`` section 3) with ``gt`` and ``light_index``; ``saturated`` and
            ``lpd_lcg_e`` are used when present. Metrics whose ``needs`` are missing are left out.
        options: see :class:`ScoreOptions`.

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
    res: list[dict] = [dict() for _ in range(gt.shape[0])]
    for block in BLOCKS.values():
        if not _enabled(block.name, o) or any(batch.get(k) is None for k in block.needs):
            continue
        try:
            out = block.compute(pred, batch, o)
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
        v = s.fn(pred, batch, o)
        for i, r in enumerate(res):
            r[s.name] = _f(v[i])
    for s in REGISTRY.values():
        if s.derive is None:
            continue
        for r in res:
            if all(i in r for i in s.inputs):
                r[s.name] = _f(s.derive(r))
    return res
