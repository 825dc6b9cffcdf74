"""LED-flicker metrics per light region: IEEE P2020 FMI, FDI, MMP, saturation flag, FSI, series error, dropout.

Defines
-------
- :func:`fmi`, :func:`fdi`, :func:`mmp`, :func:`saturation_warning`: the IEEE P2020 flicker image-quality
  factors on ROI-mean time series, following the public reference implementation CARpublic/P2020-flicker
  (``metrics/flicker.py``, MIT) definition by definition (differences are listed in each docstring).
- :func:`fsi`: the ISET-LFM flicker severity index (paper eq. 2), through :func:`lfmbench.flicker.flicker_severity`.
- :func:`series_rel_rmse`, :func:`truncated_rel_err`, :func:`dropout_mask`: the error of a region's time series
  against the ground truth's, and the frames where a light is extinguished (output below half the GT: the
  paper's Fig. 5).
- :func:`region_series`: ROI means per light and frame from the sample's ``light_index`` map.
- :func:`region_flicker_metrics`: all of the above per LED region of a batch, output and GT side by side.

Time series are ROI means in the GT's units (input-referred e-); frames along ``dim`` (default last).

References
----------
- IEEE P2020 flicker IQFs; reference code CARpublic/P2020-flicker, ``metrics/flicker.py`` (calc_FMI, calc_FDI,
  calc_MMP, saturation_warning).
- B. Deegan, "LED flicker: root cause, impact and measurement for automotive imaging applications",
  IS&T Electronic Imaging, Autonomous Vehicles and Machines 2018, AVM-146.
- B. Deegan, IS&T Electronic Imaging 2020, AVM-001 (P2020 flicker metric updates).
- A. Jam et al., "ISET-LFM: a physics-based simulation framework and dataset for LED flicker in automotive
  imaging" (FSI, eq. 2; Fig. 5 extinguished lights).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

#: P2020 reference defaults (CARpublic/P2020-flicker measure_flicker_demo.py / metrics/flicker.py).
FDI_CONTRAST_THRESHOLD = 0.1
MMP_DELTA = 0.1
#: A light is extinguished in a frame when its output ROI mean is below this fraction of the GT's (Fig. 5).
DROPOUT_FRACTION = 0.5
#: Ring (px) around a light region whose mean stands for "the light OFF" in the FDI (see region_flicker_metrics).
FDI_RING_PX = 3
#: A light counts in a frame when its region has at least this many pixels.
MIN_REGION_PX = 1


def _as_float(x) -> torch.Tensor:
    """``x`` as a floating tensor: a tensor keeps its dtype (integers -> float64); anything else goes through
    ``numpy.asarray``, so Python numbers are float64 as in the NumPy reference (``torch.as_tensor`` would make
    them float32, 6e-8 relative, enough to move MMP / FDI decisions at a band edge)."""
    t = x if isinstance(x, torch.Tensor) else torch.as_tensor(np.asarray(x))
    return t if t.is_floating_point() else t.double()


def _frames(x: torch.Tensor, dim: int, start_index: int) -> torch.Tensor:
    if start_index < 0 or start_index >= x.shape[dim]:
        raise ValueError(f"start_index must be in [0, {x.shape[dim]}), got {start_index}")
    return x.narrow(dim, start_index, x.shape[dim] - start_index)


def fmi(series, dim: int = -1, start_index: int = 0) -> torch.Tensor:
    r"""Flicker modulation index, IEEE P2020: :math:`(\max_t x - \min_t x) / (\max_t x + \min_t x)`.

    Same as the reference ``calc_FMI`` (frames from ``start_index`` on); 0/0 gives NaN as there.

    Args:
        series: ROI means, shape (..., T, ...) with frames along ``dim``, any linear unit.
        dim: frame axis.
        start_index: first frame used.

    Returns:
        FMI, shape of ``series`` without ``dim``, dimensionless (0 steady, 1 the light vanishes in some frame).

    Example:
        >>> float(fmi([1.0, 3.0]))
        0.5
    """
    x = _frames(_as_float(series), dim, start_index)
    hi, lo = x.amax(dim=dim), x.amin(dim=dim)
    return (hi - lo) / (hi + lo)


def fdi(series, x_off=None, contrast_threshold: float = FDI_CONTRAST_THRESHOLD, dim: int = -1,
        start_index: int = 0) -> torch.Tensor:
    r"""Flicker detection index, IEEE P2020: share of frames whose contrast to the OFF level exceeds a threshold.

    :math:`s_t = (x_t - x_\text{off}) / x_\text{off}`, :math:`\text{FDI} = \#\{t : s_t > c\} / T` with
    :math:`c` = ``contrast_threshold`` (default 0.1), over frames ``t >= start_index``.

    As the reference ``calc_FDI``: when ``x_off`` is None it is the mean of the first ``start_index // 4``
    frames (the baseline frames recorded with the light OFF). Differences: on a 2-D NumPy array the reference
    sums the detections over all ROIs before dividing by T (on a DataFrame, as its demo, it is per ROI as here);
    here each ROI (every index but ``dim``) gets its own FDI. With ``start_index < 4`` and no ``x_off`` the
    reference averages no frame (NaN) and reports 0; here that is a ``ValueError`` (``x_off=nan`` gives 0).
    Checked against the reference in ``tests/metrics/test_p2020_reference.py``.
    ``x_off = 0`` gives ``s_t = inf`` for a positive ``x_t`` (detected) and NaN for 0 (not detected), as numpy.

    Args:
        series: ROI means, shape (..., T, ...), any linear unit.
        x_off: OFF level in that unit, broadcastable to ``series`` without ``dim``, or None (see above).
        contrast_threshold: contrast above which the light counts as detected (dimensionless).
        dim: frame axis.
        start_index: first measured frame.

    Returns:
        FDI in [0, 1], shape of ``series`` without ``dim``.

    Example:
        >>> float(fdi([1.0, 1.05, 2.0, 3.0], x_off=1.0))
        0.5
    """
    x = _as_float(series)
    d = dim % x.ndim
    if x_off is None:
        n_off = start_index // 4
        if n_off < 1:
            raise ValueError("x_off is None, so start_index must be >= 4 (x_off = mean of the first start_index // 4 "
                             f"frames, as the reference), got start_index={start_index}")
        off = x.narrow(d, 0, n_off).mean(dim=d, keepdim=True)
    else:
        off = torch.as_tensor(x_off, dtype=x.dtype).unsqueeze(d) if torch.as_tensor(x_off).ndim else \
            torch.as_tensor(x_off, dtype=x.dtype)
    xs = _frames(x, d, start_index)
    s = (xs - off) / off
    return (s > contrast_threshold).sum(dim=d).to(x.dtype) / xs.shape[d]


def mmp(series, delta: float = MMP_DELTA, dim: int = -1, start_index: int = 0) -> torch.Tensor:
    r"""Modulation mitigation probability, IEEE P2020 (main flicker KPI).

    :math:`\bar x` = mean over the frames; MMP = share of frames with
    :math:`\bar x (1 - \delta) < x_t < \bar x (1 + \delta)` (strict, as the reference ``calc_MMP``), default
    :math:`\delta = 0.1`.

    Args:
        series: ROI means, shape (..., T, ...), any linear unit.
        delta: relative tolerance band (dimensionless).
        dim: frame axis.
        start_index: first frame used.

    Returns:
        MMP in [0, 1], shape of ``series`` without ``dim``. A constant positive series gives 1.

    Example:
        >>> float(mmp([1.0, 1.0, 1.0, 1.2]))
        0.75
    """
    x = _frames(_as_float(series), dim, start_index)
    d = dim % x.ndim
    m = x.mean(dim=d, keepdim=True)
    inside = (x > m - delta * m) & (x < m + delta * m)
    return inside.sum(dim=d).to(x.dtype) / x.shape[d]


def saturation_warning(series, max_val) -> tuple[bool, torch.Tensor]:
    """Saturation flag of the reference ``saturation_warning``: frames whose ROI mean exceeds ``max_val``.

    Args:
        series: ROI means, any shape, any linear unit.
        max_val: clip threshold in that unit (the reference demo uses 240 DN for 8-bit video).

    Returns:
        (flag: any frame saturated, mask: bool tensor of the shape of ``series``).

    Both sides are compared in float64 (as the NumPy reference does): a float32 threshold would move by up to
    6e-8 relative and flip frames just above it.

    >>> saturation_warning([0.1000000001], 0.1)[0]
    True
    """
    s = series.double() if isinstance(series, torch.Tensor) else torch.as_tensor(series, dtype=torch.float64)
    idx = torch.gt(s, torch.as_tensor(max_val, dtype=torch.float64))
    return bool(idx.any()), idx


def fsi(series, dim: int = -1) -> torch.Tensor:
    """Flicker severity index (ISET-LFM eq. 2) through :func:`lfmbench.flicker.flicker_severity`.

    Equal to the P2020 FMI; negative values (noise in an output) are clipped to 0 first, and an all-zero
    series gives 0 (see ``flicker_severity``).

    Args:
        series: radiant exposures or ROI means, shape (..., T, ...), non-negative, any linear unit.
        dim: frame axis.

    Returns:
        FSI in [0, 1], shape of ``series`` without ``dim``.
    """
    from lfmbench.flicker import flicker_severity

    return flicker_severity(_as_float(series).clamp_min(0.0), dim=dim)


def series_rel_rmse(pred_series, gt_series, dim: int = -1) -> torch.Tensor:
    r"""Relative RMS error of a region's time series against the GT series.

    :math:`\sqrt{\overline{(p_t - g_t)^2}} / \overline{g_t}` over the frames (dimensionless; NaN if the GT mean
    is 0).

    Args:
        pred_series, gt_series: ROI means, same shape (..., T, ...), same unit.
        dim: frame axis.

    Returns:
        shape without ``dim``.
    """
    p, g = _as_float(pred_series), _as_float(gt_series)
    if p.shape != g.shape:
        raise ValueError(f"pred_series and gt_series must have the same shape, got {tuple(p.shape)}, {tuple(g.shape)}")
    return (p - g).pow(2).mean(dim=dim).sqrt() / g.mean(dim=dim)


def dropout_mask(pred_series, gt_series, fraction: float = DROPOUT_FRACTION) -> torch.Tensor:
    """Frames where a light is extinguished: output ROI mean below ``fraction`` of the GT's (paper Fig. 5).

    Args:
        pred_series, gt_series: ROI means, same shape, same unit.
        fraction: threshold as a fraction of the GT (default 0.5).

    Returns:
        bool tensor of the same shape.
    """
    p, g = _as_float(pred_series), _as_float(gt_series)
    return p < fraction * g


def truncated_rel_err(pred_series, gt_series) -> torch.Tensor:
    r"""Relative error of a light's brightness per frame, truncated at 1: :math:`\min(1, |p_t - g_t| / g_t)`.

    A light that is extinguished (:math:`p_t = 0`) or shown at twice its brightness or more scores 1 (fully
    wrong); an exact reproduction scores 0. Frames with :math:`g_t \le 0` give NaN (no light to compare with).

    Args:
        pred_series, gt_series: ROI means, same shape, same unit.

    Returns:
        tensor of the same shape, dimensionless, in [0, 1] or NaN.
    """
    p, g = _as_float(pred_series), _as_float(gt_series)
    if p.shape != g.shape:
        raise ValueError(f"pred_series and gt_series must have the same shape, got {tuple(p.shape)}, {tuple(g.shape)}")
    r = ((p - g).abs() / g.clamp_min(torch.finfo(g.dtype).tiny)).clamp_max(1.0)
    return torch.where(g > 0, r, torch.full_like(r, float("nan")))


def region_series(images: torch.Tensor, light_index: torch.Tensor, num_lights: int | None = None
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """ROI mean of every light in every frame, from the per-pixel light index.

    Args:
        images: (B, F, C, H, W) float, any unit.
        light_index: (B, F, 1, H, W) int, index of the light seen at the pixel, -1 for none.
        num_lights: number of light ids (default: max index + 1).

    Returns:
        (means (B, L, F) in the unit of ``images``, NaN where the light has no pixel; pixel counts (B, L, F)).
    """
    if images.ndim != 5 or light_index.ndim != 5:
        raise ValueError(f"images and light_index must be (B, F, C, H, W), got {tuple(images.shape)}, "
                         f"{tuple(light_index.shape)}")
    b, f, c, h, w = images.shape
    if light_index.shape != (b, f, 1, h, w):
        raise ValueError(f"light_index must have shape {(b, f, 1, h, w)}, got {tuple(light_index.shape)}")
    idx = light_index.long()
    n = int(idx.max().item()) + 1 if num_lights is None else int(num_lights)
    n = max(n, 0)
    x = images.double().mean(dim=2).reshape(b, f, h * w)
    ids = (idx.reshape(b, f, h * w) + 1).clamp(0, n)  # 0 = no light
    sums = torch.zeros(b, f, n + 1, dtype=torch.float64, device=images.device).scatter_add_(2, ids, x)
    cnts = torch.zeros(b, f, n + 1, dtype=torch.float64, device=images.device).scatter_add_(
        2, ids, torch.ones_like(x))
    means = torch.where(cnts > 0, sums / cnts.clamp_min(1), torch.full_like(sums, float("nan")))
    return means[..., 1:].permute(0, 2, 1), cnts[..., 1:].permute(0, 2, 1)


def _light_boxes(idx: torch.Tensor, n: int) -> list[tuple[int, int, int, int] | None]:
    """Bounding box ``(y_min, y_max, x_min, x_max)`` (px, inclusive) of each light id 0..n-1 over all images of
    ``idx`` ((N, H, W) int, -1 = no light), None for an id without pixels: one scatter pass over the pixels."""
    _, h, w = idx.shape
    flat = idx.reshape(-1).long()
    keep = (flat >= 0) & (flat < n)
    ids = flat[keep]
    pix = torch.arange(h * w, device=idx.device).repeat(idx.shape[0])[keep]
    ys, xs = pix // w, pix % w
    big = torch.full((n,), max(h, w), dtype=torch.long, device=idx.device)
    neg = torch.full((n,), -1, dtype=torch.long, device=idx.device)
    box = torch.stack([big.scatter_reduce(0, ids, ys, "amin"), neg.scatter_reduce(0, ids, ys, "amax"),
                       big.scatter_reduce(0, ids, xs, "amin"), neg.scatter_reduce(0, ids, xs, "amax")], 1)
    return [tuple(r) if r[1] >= 0 else None for r in box.tolist()]


def _ring_series(images: Sequence[torch.Tensor], light_index: torch.Tensor, n: int,
                 ring_px: int) -> list[torch.Tensor]:
    """Mean of each of ``images`` over a ring of ``ring_px`` around each light, off every light: (B, L, F) each.

    Each light is processed inside its bounding box (over all frames) grown by the ring, so the cost follows
    the lights' size, not the image's; the ring of a light is built once for all ``images`` (all (B, F, C, H, W)).
    """
    from lfmbench.metrics.regions import dilate

    b, f, c, h, w = images[0].shape
    idx = light_index.reshape(b * f, h, w)
    xs = [im.double().mean(dim=2).reshape(b * f, h, w) for im in images]
    outs = [torch.full((b, n, f), float("nan"), dtype=torch.float64, device=images[0].device) for _ in images]
    pad = ring_px + 2
    for j, box in enumerate(_light_boxes(idx, n)):
        if box is None:
            continue
        y0, y1 = max(box[0] - pad, 0), min(box[1] + pad + 1, h)
        x0, x1 = max(box[2] - pad, 0), min(box[3] + pad + 1, w)
        sub = idx[:, y0:y1, x0:x1]
        ring = dilate(sub == j, ring_px) & ~dilate(sub >= 0, 1)
        cnt = ring.sum(dim=(1, 2)).double()
        for x, out in zip(xs, outs):
            s = (x[:, y0:y1, x0:x1] * ring).sum(dim=(1, 2))
            out[:, j, :] = torch.where(cnt > 0, s / cnt.clamp_min(1), torch.full_like(s, float("nan"))).reshape(b, f)
    return outs


@dataclass
class RegionMetricOptions:
    """Settings of :func:`region_flicker_metrics` (defaults = P2020 reference defaults)."""

    contrast_threshold: float = FDI_CONTRAST_THRESHOLD
    delta: float = MMP_DELTA
    dropout_fraction: float = DROPOUT_FRACTION
    ring_px: int = FDI_RING_PX
    min_region_px: int = MIN_REGION_PX


def _fdi_ring(series: torch.Tensor, ring: torch.Tensor, threshold: float) -> float:
    """FDI with the OFF level = mean of the ring means; NaN when no frame has a ring (no OFF reference)."""
    x_off = torch.nanmean(ring)
    if not bool(torch.isfinite(x_off)):
        return float("nan")
    return float(fdi(series, x_off, threshold))


def _nanmean(v: list[float]) -> float:
    a = np.asarray([x for x in v if x is not None], dtype=np.float64)
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else float("nan")


def region_flicker_metrics(pred: torch.Tensor, gt: torch.Tensor, light_index: torch.Tensor,
                           saturated: torch.Tensor | None = None, lpd: torch.Tensor | None = None,
                           options: RegionMetricOptions | None = None) -> list[dict]:
    """Flicker metrics of every LED region, output and GT side by side, per sample of a batch.

    For light j in sample b the ROI of frame t is ``light_index == j`` in that frame (so a moving light is
    tracked); frames where the region has fewer than ``min_region_px`` pixels are left out. Per light:

    - ``fmi_pred``, ``fmi_gt``, ``mmp_pred``, ``mmp_gt``: P2020 FMI / MMP (:func:`fmi`, :func:`mmp`).
    - ``fdi_pred``, ``fdi_gt``: P2020 FDI with the OFF level measured, in the same image, as the mean over the
      valid frames of a ``ring_px`` ring around the region that touches no light (the sample holds no
      light-OFF capture; the reference uses baseline frames recorded with the light OFF instead).
    - ``fsi_input``: FSI of the LPD input's region series (``lpd``, the flicker the method had to undo).
    - ``series_rel_rmse``: :func:`series_rel_rmse` of the output series against the GT series.
    - ``dropout_frames``: frames where the light is extinguished (:func:`dropout_mask`).
    - ``led_rel_err``: mean over the frames of :func:`truncated_rel_err` (brightness error of the light).
    - ``saturated_frames``: frames where some ROI pixel is saturated in all three captures (``saturated``
      (B, F, 3, H, W)), i.e. no capture measured it: the P2020 saturation warning for this sensor.

    Args:
        pred: output, (B, F, 1, H, W), input-referred e-.
        gt: flicker-free GT, (B, F, 1, H, W), same unit.
        light_index: (B, F, 1, H, W) int, -1 = no light.
        saturated: optional (B, F, 3, H, W) bool per capture (hcg, lcg, spd).
        lpd: optional (B, F, 1, H, W) LPD input in e- for ``fsi_input``.
        options: thresholds, see :class:`RegionMetricOptions`.

    Returns:
        One dict per sample: ``lights`` (list of per-light dicts) and the scene summary ``fmi_pred``,
        ``fmi_gt``, ``fmi_abs_err``, ``mmp_pred``, ``mmp_gt``, ``fdi_pred``, ``fdi_gt``, ``series_rel_rmse``
        (means over lights), ``dropout_rate`` (dropped region-frames / region-frames), ``led_rel_err`` (mean of
        :func:`truncated_rel_err` over all region-frames with a lit GT), ``region_frames``,
        ``n_lights``, ``saturation_flag``.
    """
    o = options or RegionMetricOptions()
    if pred.shape != gt.shape:
        raise ValueError(f"pred and gt must have the same shape, got {tuple(pred.shape)}, {tuple(gt.shape)}")
    n = int(light_index.max().item()) + 1 if light_index.numel() else 0
    n = max(n, 0)
    p_ser, cnt = region_series(pred, light_index, n)
    g_ser, _ = region_series(gt, light_index, n)
    p_off, g_off = _ring_series([pred, gt], light_index, n, o.ring_px)
    l_ser = region_series(lpd, light_index, n)[0] if lpd is not None else None
    if saturated is not None:
        all_sat = saturated.all(dim=2, keepdim=True).double()
        sat_cnt, _ = region_series(all_sat, light_index, n)  # share of ROI pixels saturated in every capture
    out = []
    for b in range(pred.shape[0]):
        lights = []
        n_rf, n_drop, rel_sum, n_rel = 0, 0, 0.0, 0
        for j in range(n):
            valid = cnt[b, j] >= o.min_region_px
            if int(valid.sum()) < 1:
                continue
            p, g = p_ser[b, j][valid], g_ser[b, j][valid]
            drop = dropout_mask(p, g, o.dropout_fraction)
            n_rf += int(valid.sum())
            n_drop += int(drop.sum())
            rel = truncated_rel_err(p, g)
            rel_ok = torch.isfinite(rel)
            rel_sum += float(rel[rel_ok].sum())
            n_rel += int(rel_ok.sum())
            rec = {
                "light_id": j,
                "frames": int(valid.sum()),
                "pixels_mean": float(cnt[b, j][valid].mean()),
                "series_pred": [float(v) for v in p],
                "series_gt": [float(v) for v in g],
                "fmi_pred": float(fmi(p)), "fmi_gt": float(fmi(g)),
                "mmp_pred": float(mmp(p, o.delta)), "mmp_gt": float(mmp(g, o.delta)),
                "fdi_pred": _fdi_ring(p, p_off[b, j][valid], o.contrast_threshold),
                "fdi_gt": _fdi_ring(g, g_off[b, j][valid], o.contrast_threshold),
                "series_rel_rmse": float(series_rel_rmse(p, g)),
                "dropout_frames": int(drop.sum()),
                "led_rel_err": float(rel[rel_ok].mean()) if bool(rel_ok.any()) else float("nan"),
            }
            if l_ser is not None:
                rec["fsi_input"] = float(fsi(l_ser[b, j][valid]))
            if saturated is not None:
                rec["saturated_frames"] = int((sat_cnt[b, j][valid] > 0).sum())
            lights.append(rec)
        summ = {k: _nanmean([r[k] for r in lights]) for k in
                ("fmi_pred", "fmi_gt", "mmp_pred", "mmp_gt", "fdi_pred", "fdi_gt", "series_rel_rmse")}
        summ["fmi_abs_err"] = _nanmean([abs(r["fmi_pred"] - r["fmi_gt"]) for r in lights])
        if l_ser is not None:
            summ["fsi_input"] = _nanmean([r["fsi_input"] for r in lights])
        summ["dropout_rate"] = n_drop / n_rf if n_rf else float("nan")
        summ["led_rel_err"] = rel_sum / n_rel if n_rel else float("nan")
        summ["region_frames"] = n_rf
        summ["n_lights"] = len(lights)
        summ["saturation_flag"] = bool(any(r.get("saturated_frames", 0) > 0 for r in lights))
        summ["lights"] = lights
        out.append(summ)
    return out
