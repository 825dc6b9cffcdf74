"""The array-generic core of :func:`lfmbench.flicker.pwm_exposure` (numpy or torch): the error-free
transformations (Dekker's TwoProduct, Knuth's TwoSum), the exact period reduction and the pulse integral
(the method: :mod:`lfmbench.flicker`)."""
from __future__ import annotations

import numpy as np


class _Splits(dict):
    """numpy dtypes at first; torch's float64/float32 added when first asked for (torch is not imported for the
    numpy path, :mod:`lfmbench.flicker.args`)."""

    def __missing__(self, dtype):
        import torch  # noqa: PLC0415 - a torch dtype: torch is loaded

        self.update({torch.float64: self[np.dtype(np.float64)], torch.float32: self[np.dtype(np.float32)]})
        if dtype not in (torch.float64, torch.float32):
            raise KeyError(dtype)
        return self[dtype]


# Veltkamp splitting constants 2^ceil(p/2) + 1 for TwoProduct (p = 53 for float64, 24 for float32).
_SPLIT = _Splits({np.dtype(np.float64): 134217729.0, np.dtype(np.float32): 4097.0})


class _Ops:
    """The few array functions the core needs, for numpy or torch."""

    def __init__(self, torch_mode: bool):
        if torch_mode:
            import torch  # noqa: PLC0415 - torch mode: an argument is a tensor, torch is loaded

            self.minimum, self.maximum, self.where = torch.minimum, torch.maximum, torch.where
            self.fmod, self.round, self.clip = torch.fmod, torch.round, torch.clamp
        else:
            self.minimum, self.maximum, self.where = np.minimum, np.maximum, np.where
            self.fmod, self.round, self.clip = np.fmod, np.round, np.clip


def _two_prod(x, y, split: float):
    """Dekker's TwoProduct: ``x*y == p + e`` exactly (no FMA needed)."""
    p = x * y
    cx = split * x
    xh = cx - (cx - x)
    xl = x - xh
    cy = split * y
    yh = cy - (cy - y)
    yl = y - yh
    e = ((xh * yh - p) + xh * yl + xl * yh) + xl * yl
    return p, e


def _two_sum(x, y):
    """Knuth's TwoSum: ``x + y == s + e`` exactly."""
    s = x + y
    bb = s - x
    e = (x - (s - bb)) + (y - bb)
    return s, e


def _mod_period(x, T, ops: _Ops):
    """``x mod T`` in ``[0, T)``; exact up to one rounding for negative ``x``."""
    a = ops.fmod(x, T)
    a = ops.where(a < 0, a + T, a)
    return ops.where(a >= T, a - T, a)


def _ramp_integral(a, b, e, w, ops: _Ops):
    r"""Integral over ``[a, b)`` of a unit step at ``e`` smoothed into a linear ramp of width ``w``."""
    hi_edge = e + w / 2
    lo_edge = e - w / 2
    above = ops.maximum(b - ops.maximum(a, hi_edge), 0 * a)
    u0 = ops.minimum(ops.maximum(a, lo_edge), hi_edge)
    u1 = ops.minimum(ops.maximum(b, lo_edge), hi_edge)
    safe_w = ops.where(w > 0, w, 1 + 0 * w)
    ramp = (u1 - u0) * (0.5 + ((u0 + u1) / 2 - e) / safe_w)
    return above + ops.where(w > 0, ramp, 0 * ramp)


def _pulse_core(phase, exposure, period, duty, rise_time, fall_time, ops: _Ops, split: float, trapezoid: bool):
    """ON time (s, ideal pulse) or integral of the unit pulse (s, trapezoid) over the exposure."""
    T, D = period, duty
    r = ops.fmod(exposure, T)                       # exact
    n = ops.round((exposure - r) / T)               # whole periods (an exact integer value)
    p, e = _two_prod(D, T, split)                   # D*T == p + e
    full = n * p + n * e
    if not trapezoid:
        # a = phase mod T kept in (-T, T) (fmod is exact; adding T to a tiny negative a would round it away)
        a = ops.fmod(phase, T)
        zero = 0 * r
        # a >= 0: the window [a, a + r) meets [0, DT) and [T, T + DT)
        s, se = _two_sum(T, -a)                     # T - a == s + se
        o1 = ops.maximum(ops.minimum(r, (p - a) + e), zero)
        o2 = ops.maximum(ops.minimum((r - s) - se, p + e), zero)
        # a < 0: the window meets [-T, -T + DT) and [0, DT)
        q, qe = _two_sum(p, -T)                     # D*T - T == q + qe + e
        m1 = ops.maximum(ops.minimum(r, (q - a) + (qe + e)), zero)
        m2 = ops.maximum(ops.minimum(r + a, p + e), zero)
        return full + ops.where(a < 0, m1 + m2, o1 + o2)
    a = _mod_period(phase, T, ops)                  # the ramps are continuous: [0, T) reduction suffices
    b = a + r
    dt = p + e
    rising = sum(_ramp_integral(a, b, k * T, rise_time, ops) for k in (0, 1, 2))
    falling = sum(_ramp_integral(a, b, k * T + dt, fall_time, ops) for k in (0, 1))
    return full + (rising - falling)
