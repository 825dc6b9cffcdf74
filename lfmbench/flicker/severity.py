"""Flicker measures of the PWM model: the flicker severity index FSI (eq. 2 of ISET-LFM, equal to the IEEE
P2020 flicker modulation index FMI) and the probability that an exposure misses the pulse."""
from __future__ import annotations

import math


import numpy as np

from lfmbench.check import check_array
from lfmbench.flicker.args import ArrayLike, _as_tensors, _check_pwm_args, _is_tensor, _is_torch
from lfmbench.flicker.exact import _Ops

__all__ = ["flicker_severity", "miss_probability", "windows_miss_probability"]


def flicker_severity(phi: ArrayLike, dim: int = -1) -> ArrayLike:
    r"""Flicker severity index FSI (eq. 2), identical to the IEEE P2020 flicker modulation index FMI.

    .. math:: \mathrm{FSI} = \frac{\Phi_{\max} - \Phi_{\min}}{\Phi_{\max} + \Phi_{\min}}

    Args:
        phi: radiant exposures (or ROI means) of a sequence of frames, shape (..., N, ...) with the frames
            along ``dim``; non-negative, finite.
        dim: the frame axis.

    Returns:
        FSI in [0, 1], shape of ``phi`` without ``dim``. 0 = steady, 1 = the light vanishes in some frame.
        **All-dark convention:** where every frame is 0 the ratio is 0/0; it is defined as 0 (a source that is
        never seen shows no modulation). Use the P2020 detection index (FDI) to tell a dark light from a steady one.

    Example:
        >>> float(flicker_severity(np.array([1.0, 3.0])))
        0.5
    """
    check_array("phi", phi, lo=0.0)
    if _is_tensor(phi):
        import torch  # noqa: PLC0415 - phi is a tensor: torch is loaded

        hi = phi.amax(dim=dim)
        lo = phi.amin(dim=dim)
        den = hi + lo
        return torch.where(den > 0, (hi - lo) / torch.where(den > 0, den, torch.ones_like(den)),
                           torch.zeros_like(den))
    phi = np.asarray(phi, dtype=np.float64)
    hi = phi.max(axis=dim)
    lo = phi.min(axis=dim)
    den = hi + lo
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, (hi - lo) / np.where(den > 0, den, 1.0), 0.0)


def miss_probability(exposure: ArrayLike, period: ArrayLike, duty: ArrayLike, rise_time: ArrayLike = 0.0,
                     fall_time: ArrayLike = 0.0) -> ArrayLike:
    r"""Probability that an exposure of length ``exposure`` (s), started at a phase drawn uniformly over one
    period, receives none of the pulse: the light is missed in that frame (or row).

    The pulse level is non-zero for :math:`DT + (t_r + t_f)/2` of every period (the ramps are centred on the
    ideal edges, module docstring), so it is zero on one interval of length :math:`g = (1-D)T - (t_r+t_f)/2`
    per period. An exposure :math:`[s, s + t_e)` receives nothing exactly when it lies inside such a gap, which
    for :math:`s` uniform over a period has probability

    .. math:: p_{miss} = \max(0,\ g - t_e) / T = \max\!\left(0,\ 1 - D - \frac{t_e + (t_r+t_f)/2}{T}\right).

    For ideal pulses this is the "exposure shorter than the OFF time" condition of ISET-LFM (Sec. 2) made a
    probability; with many frames it is the expected share of frames in which the short exposure shows a
    PWM light dark (what drives the dropout metric). Derived here from the pulse model of :func:`pwm_exposure`
    and checked against a phase sweep of it (tests/flicker/test_flicker.py).

    Args:
        exposure: exposure time :math:`t_e` (s), >= 0.
        period: PWM period :math:`T` (s), > 0.
        duty: duty cycle :math:`D` in [0, 1] (1).
        rise_time, fall_time: ramp widths :math:`t_r, t_f` (s), >= 0.

    Returns:
        :math:`p_{miss}` in [0, 1] (1), the broadcast shape of the inputs (numpy float64 or torch). A pulse of
        zero length (:math:`D = 0` without ramps) or an exposure of zero length receives nothing: 1.

    Example:
        >>> float(miss_probability(4e-3, 1 / 100.0, 0.25))  # 10 ms period, 7.5 ms dark, 4 ms exposure
        0.35
    """
    _check_pwm_args(0.0, exposure, period, duty, 1.0, 0.0, rise_time, fall_time)
    torch_mode = _is_torch(exposure, period, duty, rise_time, fall_time)
    args = (exposure, period, duty, rise_time, fall_time)
    exposure, period, duty, rise_time, fall_time = (_as_tensors(*args) if torch_mode else
                                                    [np.asarray(x, dtype=np.float64) for x in args])
    ops = _Ops(torch_mode)
    ramps = 0.5 * (rise_time + fall_time)
    p = ops.clip(((1.0 - duty) * period - ramps - exposure) / period, 0.0, 1.0)
    return ops.where((duty * period + ramps > 0) & (exposure > 0), p, 1.0)


def windows_miss_probability(windows, period: float, duty: float, rise_time: float = 0.0,
                             fall_time: float = 0.0) -> float:
    r"""Probability that a capture integrating the union of ``windows`` (``[(start_s, length_s), ...]``, s, from one
    time origin: a chopped exposure's sub-windows, or one window) receives none of the pulse, the PWM phase drawn
    uniformly over one period: :func:`miss_probability` generalised from one window to a union.

    The pulse is non-zero on :math:`[\phi, \phi + w)` modulo :math:`T` with :math:`w = DT + (t_r + t_f)/2` (the
    model of :func:`pwm_exposure`). It meets window :math:`[a, a + n)` exactly when :math:`\phi` lies in
    :math:`(a - w, a + n)` modulo :math:`T` (the whole period when :math:`n + w \ge T`), so the capture misses the
    light for the phases outside the union of these arcs: :math:`p_{miss} = 1 - |\bigcup_i (a_i - w, a_i + n_i)
    \bmod T| / T`, computed exactly as a union of intervals. One window gives :func:`miss_probability`'s
    :math:`\max(0, 1 - D - (t_e + (t_r+t_f)/2)/T)` (tested against it and against a phase sweep).

    Args:
        windows: one or more ``(start_s, length_s)``, s, lengths >= 0. period: T, s, > 0. duty: D in [0, 1].
        rise_time, fall_time: ramp widths, s, >= 0.

    Returns:
        :math:`p_{miss}` in [0, 1] (float). 1 for a pulse of zero length or windows of zero total length.
    """
    T = float(period)
    if not (math.isfinite(T) and T > 0):
        raise ValueError(f"period must be > 0 s, got {period!r}")
    w = float(duty) * T + 0.5 * (float(rise_time) + float(fall_time))
    if w <= 0:
        return 1.0
    arcs = []
    for a, n in windows:
        a, n = float(a), float(n)
        if n <= 0:
            continue
        if n + w >= T:
            return 0.0
        lo = (a - w) % T
        hi = lo + n + w
        arcs += [(lo, min(hi, T))] + ([(0.0, hi - T)] if hi > T else [])
    if not arcs:
        return 1.0
    arcs.sort()
    covered, cur_lo, cur_hi = 0.0, arcs[0][0], arcs[0][1]
    for lo, hi in arcs[1:]:
        if lo > cur_hi:
            covered += cur_hi - cur_lo
            cur_lo, cur_hi = lo, hi
        else:
            cur_hi = max(cur_hi, hi)
    covered += cur_hi - cur_lo
    return float(min(1.0, max(0.0, 1.0 - covered / T)))
