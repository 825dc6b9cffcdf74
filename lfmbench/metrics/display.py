"""Display-referred metrics: PSNR and SSIM of a fusion estimate and its ground truth after the same ISP.

The primary metrics (the LED score and everything it is built from) stay on linear, input-referred values. These
secondary columns answer another question: how different do the two look on an sRGB display after a camera's
processing? Both images go through one ISP pipeline (:class:`lfmbench.isp.ISP`, default
``lfmbench/configs/isp/default.yaml``) bound to the sample's sensor preset, with every image statistic (the tone
curve) taken from the ground truth (:meth:`lfmbench.isp.ISP.pair`), so an estimate that is too bright looks too
bright.

Defines
-------
- :func:`display_pair`: (pred, gt) -> the two display images, (B, F, 3, H, W) encoded sRGB in [0, 1].
- :func:`psnr_srgb`, :func:`ssim_srgb`: PSNR (peak 1) and SSIM (Wang et al. 2004, kornia) of display images.
- :func:`display_metrics`: both, from linear mosaics, one ISP pass per batch.

References
----------
- IEC 61966-2-1:1999 (sRGB encoding). Z. Wang, A. C. Bovik, H. R. Sheikh, E. P. Simoncelli, "Image quality
  assessment: from error visibility to structural similarity", IEEE TIP 13(4), 2004.
"""
from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import torch

from lfmbench.metrics.hdr import SSIM_WINDOW, psnr, ssim_map

__all__ = ["DEFAULT_PIPELINE", "isp_for", "display_pair", "psnr_srgb", "ssim_srgb", "display_metrics",
           "sensor_of_batch"]

#: The ISP pipeline of the display-referred columns unless :class:`lfmbench.metrics.ScoreOptions` names another.
DEFAULT_PIPELINE = "default"


@functools.lru_cache(maxsize=8)
def _isp_cached(pipeline: str, preset):
    from lfmbench.isp import ISP  # noqa: PLC0415

    return ISP(pipeline, preset)


def isp_for(pipeline: str | Path, preset) -> Any:
    """The :class:`lfmbench.isp.ISP` of a pipeline (name or path) bound to a preset (object or name), cached."""
    from lfmbench.sensor.preset import resolve  # noqa: PLC0415

    return _isp_cached(str(pipeline), resolve(preset))


def sensor_of_batch(batch: dict) -> str:
    """The sensor preset name a batch was simulated with (``meta["sensor"]``; collated: a list of names)."""
    meta = batch.get("meta")
    s = None
    if isinstance(meta, dict):
        s = meta.get("sensor")
    elif isinstance(meta, (list, tuple)) and meta and isinstance(meta[0], dict):
        s = meta[0].get("sensor")
    if isinstance(s, (list, tuple)):
        if len(set(s)) > 1:
            raise ValueError(f"a batch mixes sensors {sorted(set(s))}; display metrics need one sensor per batch")
        s = s[0] if s else None
    if not isinstance(s, str) or not s:
        raise ValueError("the batch names no sensor (meta['sensor']); give ScoreOptions(sensor=...)")
    return s


def display_pair(pred: torch.Tensor, gt: torch.Tensor, isp) -> tuple[torch.Tensor, torch.Tensor]:
    """Both images through the ISP, statistics from ``gt``.

    Args:
        pred, gt: (B, F, 1, H, W) linear mosaics in one unit (input-referred e-).
        isp: a bound :class:`lfmbench.isp.ISP`.

    Returns:
        (pred_display, gt_display): (B, F, 3, H, W) each, encoded sRGB in [0, 1] for the shipped pipelines.
    """
    return isp.pair(pred, gt)


def psnr_srgb(pred_display: torch.Tensor, gt_display: torch.Tensor) -> torch.Tensor:
    """PSNR of display images, peak 1, MSE over every frame, channel and pixel of a sample.

    Args:
        pred_display, gt_display: (B, *) encoded display values in [0, 1].

    Returns:
        (B,) in dB; ``inf`` for identical images.
    """
    return psnr(pred_display, gt_display, 1.0)


def ssim_srgb(pred_display: torch.Tensor, gt_display: torch.Tensor, window_size: int = SSIM_WINDOW) -> torch.Tensor:
    """Mean SSIM of display images: each channel of each frame an image (kornia, Gaussian window sigma 1.5,
    K1 = 0.01, K2 = 0.03, data range 1), averaged over frames, channels and pixels.

    Args:
        pred_display, gt_display: (B, *, H, W) encoded display values in [0, 1].
        window_size: odd Gaussian window taps.

    Returns:
        (B,) dimensionless in [-1, 1].
    """
    return ssim_map(pred_display, gt_display, window_size).reshape(pred_display.shape[0], -1).mean(dim=1)


def display_metrics(pred: torch.Tensor, gt: torch.Tensor, preset, pipeline: str | Path = DEFAULT_PIPELINE
                    ) -> dict[str, torch.Tensor]:
    """``{"psnr_srgb": (B,), "ssim_srgb": (B,)}`` of linear mosaics after one ISP pass each.

    Args:
        pred, gt: (B, F, 1, H, W) linear mosaics (input-referred e-).
        preset: the sensor preset (object or name) the samples were simulated with.
        pipeline: ISP pipeline name or YAML path.
    """
    p, g = display_pair(pred, gt, isp_for(pipeline, preset))
    return {"psnr_srgb": psnr_srgb(p, g), "ssim_srgb": ssim_srgb(p, g)}
