"""Metrics that score a fusion output against the flicker-free ground truth.

Modules: :mod:`~lfmbench.metrics.hdr` (PSNR-L, PSNR-mu, SSIM-mu, PU21-PSNR, ColorVideoVDP),
:mod:`~lfmbench.metrics.flicker` (IEEE P2020 FMI / FDI / MMP per LED region, FSI, series error, light dropout,
saturation flag) and :mod:`~lfmbench.metrics.regions` (errors outside the LED regions: ghosts and comets).

Every metric is registered in :data:`REGISTRY` with a name, a version string (bumped whenever its definition
or defaults change, so results stay comparable) and its reference; :func:`metric_versions` is what the
evaluation stores with every result. :func:`score_batch` computes them all for one batch.
See ``docs/metrics.md``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from lfmbench.metrics import flicker, hdr, regions

__all__ = ["MetricSpec", "REGISTRY", "metric_versions", "score_batch", "ScoreOptions", "flicker", "hdr", "regions"]


@dataclass(frozen=True)
class MetricSpec:
    """One registered metric: ``name``, ``version``, ``reference``, ``unit`` and ranking direction."""

    name: str
    version: str
    reference: str
    unit: str
    higher_is_better: bool
    group: str  # 'hdr', 'perceptual', 'flicker', 'region'


_KR17 = "Kalantari & Ramamoorthi, ACM TOG 36(4) 2017"
_P2020 = "IEEE P2020; CARpublic/P2020-flicker metrics/flicker.py; Deegan EI 2018 AVM-146"

#: name -> spec of every metric :func:`score_batch` can report.
REGISTRY: dict[str, MetricSpec] = {s.name: s for s in [
    MetricSpec("psnr_l", "1.0", _KR17 + " (normalised by GT peak)", "dB", True, "hdr"),
    MetricSpec("psnr_mu", "1.0", _KR17 + " (mu = 5000)", "dB", True, "hdr"),
    MetricSpec("ssim_mu", "1.0", "Wang et al. IEEE TIP 2004 via kornia.metrics.ssim, on mu-law images", "1", True, "hdr"),
    MetricSpec("pu21_psnr", "1.0", "Mantiuk & Azimi PCS 2021 via pycvvdp.pu_psnr_y", "dB", True, "perceptual"),
    MetricSpec("cvvdp_jod", "1.0", "Mantiuk et al. ACM TOG 2024 (ColorVideoVDP) via pycvvdp", "JOD", True, "perceptual"),
    MetricSpec("fmi_pred", "1.0", _P2020 + " (FMI)", "1", False, "flicker"),
    MetricSpec("fmi_gt", "1.0", _P2020 + " (FMI of the GT)", "1", False, "flicker"),
    MetricSpec("fmi_abs_err", "1.0", "|FMI(output) - FMI(GT)| per light", "1", False, "flicker"),
    MetricSpec("mmp_pred", "1.0", _P2020 + " (MMP, delta 0.1)", "1", True, "flicker"),
    MetricSpec("mmp_gt", "1.0", _P2020 + " (MMP of the GT)", "1", True, "flicker"),
    MetricSpec("fdi_pred", "1.0", _P2020 + " (FDI, threshold 0.1, OFF level from a ring)", "1", True, "flicker"),
    MetricSpec("fdi_gt", "1.0", _P2020 + " (FDI of the GT)", "1", True, "flicker"),
    MetricSpec("fsi_input", "1.0", "ISET-LFM eq. 2 via lfmbench.flicker.flicker_severity, LPD input", "1", False,
               "flicker"),
    MetricSpec("series_rel_rmse", "1.0", "relative RMS error of the ROI series vs GT", "1", False, "flicker"),
    MetricSpec("dropout_rate", "1.0", "ISET-LFM Fig. 5: region-frames with output < 0.5 GT", "1", False, "flicker"),
    MetricSpec("psnr_mu_outside", "1.0", _KR17 + " outside dilated LED regions", "dB", True, "region"),
    MetricSpec("ghost_mae_mu", "1.0", "ISET-LFM Fig. 6: mean |mu-law error| in a band around LEDs", "1", False,
               "region"),
    MetricSpec("comet_excess_mu", "1.0", "ISET-LFM Fig. 6: mean positive mu-law error around LEDs", "1", False,
               "region"),
]}


def metric_versions() -> dict[str, str]:
    """name -> version of every registered metric (stored with every evaluation result)."""
    return {k: v.version for k, v in REGISTRY.items()}


@dataclass
class ScoreOptions:
    """Settings of :func:`score_batch`."""

    perceptual: bool = False  #: also PU21-PSNR and ColorVideoVDP (needs the optional cvvdp package)
    fps: float = 60.0  #: frame rate for ColorVideoVDP, s^-1
    cd_per_unit: float | None = None  #: luminance calibration, cd m^-2 per e- (None: GT p99 at display peak)
    region: flicker.RegionMetricOptions = field(default_factory=flicker.RegionMetricOptions)
    margin_px: int = regions.LED_MARGIN_PX
    ring_px: int = regions.GHOST_RING_PX


def _f(x) -> float:
    v = float(x)
    return v if math.isfinite(v) or math.isinf(v) else float("nan")


def score_batch(pred: torch.Tensor, batch: dict, options: ScoreOptions | None = None) -> list[dict]:
    """All registered metrics for one batch, one dict per sample.

    Args:
        pred: fused estimate, (B, F, 1, H, W), in the units of ``batch['gt']`` (input-referred e-).
        batch: sample dict (``docs/contracts.md`` section 3) with ``gt`` and ``light_index``; ``saturated`` and
            ``lpd_lcg_e`` are used when present.
        options: see :class:`ScoreOptions`.

    Returns:
        list of B dicts: metric name -> float, plus ``lights`` (per-light records).
    """
    o = options or ScoreOptions()
    gt = batch["gt"]
    if pred.shape != gt.shape:
        raise ValueError(f"pred must have the shape of batch['gt'] {tuple(gt.shape)}, got {tuple(pred.shape)}")
    pred = pred.to(gt.dtype)
    res = [dict() for _ in range(gt.shape[0])]
    for name, fn in (("psnr_l", hdr.psnr_l), ("psnr_mu", hdr.psnr_mu), ("ssim_mu", hdr.ssim_mu)):
        v = fn(pred, gt)
        for i, r in enumerate(res):
            r[name] = _f(v[i])
    if o.perceptual:
        for name, fn in (("pu21_psnr", lambda p, g: hdr.pu21_psnr(p, g, o.cd_per_unit, o.fps)),
                         ("cvvdp_jod", lambda p, g: hdr.cvvdp_jod(p, g, o.fps, o.cd_per_unit))):
            v = fn(pred, gt)
            for i, r in enumerate(res):
                r[name] = _f(v[i])
    li = batch.get("light_index")
    if li is not None:
        reg = flicker.region_flicker_metrics(pred, gt, li, batch.get("saturated"), batch.get("lpd_lcg_e"), o.region)
        out = regions.outside_led_metrics(pred, gt, li, o.margin_px, o.ring_px)
        for r, a, b in zip(res, reg, out):
            r.update(a)
            r.update(b)
    return res
