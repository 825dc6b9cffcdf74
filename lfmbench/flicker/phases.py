"""Exposure-start phases of frame *n* (eq. 3 of ISET-LFM) and sensor row *i* (eq. 4), computed directly (no
recursive float sums, so frame :math:`10^9` does not drift)."""
from __future__ import annotations


import numpy as np

from lfmbench.check import check_array
from lfmbench.flicker.args import ArrayLike, _as_tensors, _check_broadcast, _is_torch
from lfmbench.flicker.exact import _Ops, _SPLIT, _mod_period, _two_prod

__all__ = ["frame_phase", "row_phase"]


def _affine_phase(base: ArrayLike, index: ArrayLike, step: ArrayLike, period: ArrayLike) -> ArrayLike:
    r"""``(base + index * step) mod period`` in [0, period), with ``index*step`` split exactly (TwoProduct)."""
    torch_mode = _is_torch(base, index, step, period)
    ops = _Ops(torch_mode)
    if torch_mode:
        base, index, step, period = _as_tensors(base, index, step, period)
        split = _SPLIT[base.dtype]
    else:
        base, index, step, period = (np.asarray(x, dtype=np.float64) for x in (base, index, step, period))
        split = _SPLIT[np.dtype(np.float64)]
    p, e = _two_prod(index, step, split)
    # every term is reduced before it is added, so nothing large is ever summed
    s = _mod_period(p, period, ops) + _mod_period(e, period, ops) + _mod_period(base, period, ops)
    return _mod_period(s, period, ops)


def _checked_affine_phase(names: tuple[str, str, str, str], start: ArrayLike, index: ArrayLike, step: ArrayLike,
                          period: ArrayLike) -> ArrayLike:
    """``(start + index * step) mod period`` (s) after the checks of eqs. 3 and 4: finite values, ``index`` and
    ``step`` >= 0, ``period`` > 0, shapes that broadcast; ``names`` name the four arguments in the messages."""
    check_array(names[0], start)
    check_array(names[1], index, lo=0.0)
    check_array(names[2], step, lo=0.0)
    check_array(names[3], period, lo=0.0, lo_open=True)
    _check_broadcast(names, (start, index, step, period))
    return _affine_phase(start, index, step, period)


def frame_phase(phase0: ArrayLike, frame_index: ArrayLike, frame_time: ArrayLike, period: ArrayLike) -> ArrayLike:
    r"""Exposure-start phase of frame ``n`` (eq. 3, solved in closed form).

    .. math:: t_s^{(n)} = (t_s^{(0)} + n\,t_f) \bmod T

    Args:
        phase0: phase of frame 0, :math:`t_s^{(0)}` (s).
        frame_index: frame number :math:`n \ge 0` (integer-valued, exact up to :math:`2^{53}`).
        frame_time: frame interval :math:`t_f` (s), e.g. 1/60.
        period: PWM period :math:`T` (s).

    Returns:
        Phase in [0, T) (s), broadcast shape. Unlike the recursion of eq. 3, ``n * t_f`` is split exactly, so
        frame :math:`10^9` is within a few ulp of :math:`T`.
    """
    return _checked_affine_phase(("phase0", "frame_index", "frame_time", "period"),
                                 phase0, frame_index, frame_time, period)


def row_phase(phase: ArrayLike, row: ArrayLike, line_time: ArrayLike, period: ArrayLike) -> ArrayLike:
    r"""Exposure-start phase of sensor row ``i`` under a rolling shutter (eq. 4, rows counted from 0).

    .. math:: t_s^{(i, n)} = (t_s^{(n)} + i\,t_d) \bmod T

    Args:
        phase: phase of row 0 in this frame (s).
        row: row index :math:`i \ge 0`, e.g. ``numpy.arange(H)``.
        line_time: line delay :math:`t_d` (s), e.g. 10e-6.
        period: PWM period :math:`T` (s).

    Returns:
        Phase in [0, T) (s), broadcast shape (``phase[..., None]`` with ``row`` of shape (H,) gives (..., H)).
    """
    return _checked_affine_phase(("phase", "row", "line_time", "period"), phase, row, line_time, period)
