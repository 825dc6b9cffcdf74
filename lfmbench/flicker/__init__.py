r"""Analytical PWM flicker model: radiant exposure of a pulse-width-modulated LED over a camera exposure.

Defines
-------
- :func:`pwm_exposure`: radiant exposure :math:`\Phi(t_s, t_e)` of a PWM source (eq. 1 of ISET-LFM), exact
  for every exposure length, duty cycle in [0, 1] and phase; optional trapezoidal pulses (finite rise and
  fall times), also in closed form.
- :func:`pwm_level`: the instantaneous source level :math:`I(t)` (for plots and brute-force checks).
- :func:`frame_phase` (eq. 3) and :func:`row_phase` (eq. 4): exposure-start phases of frame *n* and sensor
  row *i*, computed directly (no recursive float sums, so frame :math:`10^9` does not drift).
- :func:`bin_weights`: mean source level in each of K time bins: combines time-resolved radiance with any
  PWM draw.
- :func:`flicker_severity`: flicker severity index FSI (eq. 2), which equals the IEEE P2020 flicker
  modulation index FMI.
- :func:`miss_probability`: probability that an exposure at a uniformly random phase receives nothing of the
  pulse (the light vanishes from that frame), in closed form.

Conventions (SI units throughout)
---------------------------------
A source of period :math:`T` (s), duty cycle :math:`D` (1), ON level ``amplitude + offset`` and OFF level
``offset`` (any radiometric unit per second of exposure, e.g. W sr^-1 m^-2 nm^-1) is ON during
:math:`[kT, kT + DT)` for every integer :math:`k`. ``phase`` :math:`t_s` (s) is the exposure start measured
from a rising edge; the exposure lasts :math:`t_e` (s). The result is
:math:`\Phi = \int_{t_s}^{t_s+t_e} I(t)\,dt` in level x s.

Method
------
The upstream implementation (``get_phi`` of AyushJam/iset-lfm) uses a case table over six exposure regimes
that is wrong for :math:`D > 0.5, t_e > 2T`. Here the exposure is split into :math:`n = \lfloor t_e/T\rfloor`
whole periods, which contribute exactly :math:`nDT`, and a remainder :math:`r = t_e - nT < T` starting at
:math:`a = t_s \bmod T`; the window :math:`[a, a + r)` lies inside :math:`[0, 2T)` and can only meet the ON
intervals :math:`[0, DT)` and :math:`[T, T + DT)`:

.. math::  \Phi/A = nDT + \max(0, \min(r, DT - a)) + \max(0, \min(r - (T - a), DT)).

``a`` is the exact ``fmod``, kept in :math:`(-T, T)`: for :math:`a < 0` the window meets
:math:`[-T, -T + DT)` and :math:`[0, DT)` instead (mirrored formula), so a phase of -1e-164 s stays just before
a rising edge rather than being rounded onto it.

``fmod`` is exact in floating point, and the products and differences near the pulse edges use error-free
transformations (Dekker's TwoProduct, Knuth's TwoSum), so in float64 the result is within a few units in the
last place of the exact value for the given (binary) inputs, also when it is tiny (an exposure of
:math:`10^{-9}T` straddling an edge). In float32 the same formula holds with relative errors of order
:math:`10^{-6}` of :math:`\max(t_e, T)` (``docs/guide/flicker.md``).

Trapezoidal pulses: each edge is a linear ramp of width ``rise_time`` (``fall_time``) centred on the ideal
edge, so that ``duty`` stays the duty cycle at half amplitude and the mean level stays
:math:`\text{offset} + A D`; the ramps must not overlap:
:math:`(t_r + t_f)/2 \le \min(D, 1 - D)\,T`.

References
----------
- A. Jam et al., "ISET-LFM: A Physics-based Simulation Framework and Dataset for LED Flicker in Automotive
  Imaging" (eqs. 1-4).
- T. J. Dekker, "A floating-point technique for extending the available precision", Numer. Math. 18 (1971).
- D. E. Knuth, The Art of Computer Programming, vol. 2, sec. 4.2.2 (TwoSum).
- B. Deegan, "LED flicker: root cause, impact and measurement for automotive imaging applications",
  Electronic Imaging 2018 (FMI).
"""
from __future__ import annotations

import math
import os
import threading
from typing import Any

import numpy as np
import torch

from lfmbench.check import check_array

__all__ = [
    "pwm_exposure",
    "pwm_level",
    "frame_phase",
    "row_phase",
    "bin_weights",
    "flicker_severity",
    "miss_probability",
    "windows_miss_probability",
]

ArrayLike = Any  # float, numpy array or torch tensor

# Veltkamp splitting constants 2^ceil(p/2) + 1 for TwoProduct (p = 53 for float64, 24 for float32).
_SPLIT = {np.dtype(np.float64): 134217729.0, np.dtype(np.float32): 4097.0,
          torch.float64: 134217729.0, torch.float32: 4097.0}


# ----------------------------------------------------------------------------------------------------------
# Input checks
# ----------------------------------------------------------------------------------------------------------
def _is_torch(*xs: ArrayLike) -> bool:
    return any(isinstance(x, torch.Tensor) for x in xs)


def _np_view(x: ArrayLike) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    return np.asarray(x)


def _check_broadcast(names: tuple[str, ...], values: tuple[ArrayLike, ...]) -> None:
    shapes = [tuple(np.shape(_np_view(v))) if not isinstance(v, torch.Tensor) else tuple(v.shape)
              for v in values]
    try:
        np.broadcast_shapes(*shapes)
    except ValueError:
        desc = ", ".join(f"{n}{s}" for n, s in zip(names, shapes))
        raise ValueError(f"shape mismatch: {desc} do not broadcast together") from None


def _check_pwm_args(phase, exposure, period, duty, amplitude, offset, rise_time, fall_time) -> None:
    check_array("phase", phase)
    check_array("exposure", exposure, lo=0.0)
    check_array("period", period, lo=0.0, lo_open=True)
    check_array("duty", duty, lo=0.0, hi=1.0)
    check_array("amplitude", amplitude, lo=0.0)
    check_array("offset", offset, lo=0.0)
    check_array("rise_time", rise_time, lo=0.0)
    check_array("fall_time", fall_time, lo=0.0)
    _check_broadcast(("phase", "exposure", "period", "duty", "amplitude", "offset", "rise_time", "fall_time"),
                     (phase, exposure, period, duty, amplitude, offset, rise_time, fall_time))
    ramps = (_np_view(rise_time) + _np_view(fall_time)) / 2.0
    T, D = _np_view(period), _np_view(duty)
    room = np.minimum(D, 1.0 - D) * T
    if (ramps > room * (1 + 1e-12)).any():
        raise ValueError("rise_time and fall_time too long for this duty and period: the ramps overlap; "
                         "need (rise_time + fall_time)/2 <= min(duty, 1 - duty) * period")


# ----------------------------------------------------------------------------------------------------------
# Array-generic core (numpy or torch): used for torch (differentiable) and as the numpy fallback
# ----------------------------------------------------------------------------------------------------------
class _Ops:
    """The few array functions the core needs, for numpy or torch."""

    def __init__(self, torch_mode: bool):
        if torch_mode:
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


# ----------------------------------------------------------------------------------------------------------
# numba kernel for float64 numpy inputs (ideal pulse): the same arithmetic as _pulse_core, fused and threaded
# ----------------------------------------------------------------------------------------------------------
_NUMBA_KERNELS: dict | None = None
#: Process that imported this module: only there (and in its main thread) is the threaded kernel used.
_IMPORT_PID = os.getpid()


def _kernel_scalar(phase, exposure, period, duty, amplitude, offset):  # pragma: no cover - compiled by numba
    """Ideal-pulse exposure of one element: the arithmetic of :func:`_pulse_core`, for numba."""
    T = period
    D = duty
    if not (T > 0.0 and exposure >= 0.0 and D >= 0.0 and D <= 1.0
            and math.isfinite(phase) and math.isfinite(exposure) and math.isfinite(T)):
        return math.nan  # the caller re-checks and names the argument
    a = np.fmod(phase, T)  # in (-T, T), exact
    r = np.fmod(exposure, T)
    n = np.rint((exposure - r) / T)
    # TwoProduct D*T = p + e
    p = D * T
    c = 134217729.0 * D
    dh = c - (c - D)
    dl = D - dh
    c = 134217729.0 * T
    th = c - (c - T)
    tl = T - th
    e = ((dh * th - p) + dh * tl + dl * th) + dl * tl
    if a >= 0.0:
        # TwoSum T - a = s + se; the window meets [0, DT) and [T, T + DT)
        s = T - a
        bb = s - T
        se = (T - (s - bb)) + (-a - bb)
        o1 = min(r, (p - a) + e)
        o2 = min((r - s) - se, p + e)
    else:
        # TwoSum p - T = q + qe; the window meets [-T, -T + DT) and [0, DT)
        q = p - T
        bb = q - p
        qe = (p - (q - bb)) + (-T - bb)
        o1 = min(r, (q - a) + (qe + e))
        o2 = min(r + a, p + e)
    if o1 < 0.0:
        o1 = 0.0
    if o2 < 0.0:
        o2 = 0.0
    return amplitude * ((n * p + n * e) + (o1 + o2)) + offset * exposure


#: Elements from which the threaded kernel pays off (its launch costs far more than a small serial loop).
PARALLEL_MIN_SIZE = 100_000


def _numba_kernel(size: int = PARALLEL_MIN_SIZE):
    """The compiled ideal-pulse ufunc for this call site, or None when numba is unavailable.

    Two builds of :func:`_kernel_scalar`: ``target="parallel"`` (both cores) for calls of at least
    :data:`PARALLEL_MIN_SIZE` elements in the importing process's main thread, ``target="cpu"`` otherwise. Each is compiled only when first needed: building the parallel one loads
    numba's threading layer, which sets the OpenMP thread count; in a forked DataLoader worker whose parent has
    used OpenMP (torch does) that makes torch's next parallel region deadlock. So workers only ever build the
    serial kernel; their parallelism is the workers.
    """
    global _NUMBA_KERNELS
    if _NUMBA_KERNELS is None:
        try:
            __import__("numba")  # only whether it imports: the kernels import it where they are built
        except ImportError:  # pragma: no cover - numba is a dependency; the numpy path still works without it
            _NUMBA_KERNELS = {}
            return None
        _NUMBA_KERNELS = {"available": True}
    if not _NUMBA_KERNELS:
        return None
    main = os.getpid() == _IMPORT_PID and threading.current_thread() is threading.main_thread()
    target = "parallel" if (main and size >= PARALLEL_MIN_SIZE) else "cpu"
    if target not in _NUMBA_KERNELS:
        import numba

        if target == "parallel" and "NUMBA_THREADING_LAYER" not in os.environ:
            # numba's fork-safe layer: its OpenMP layer aborts or deadlocks forked children (DataLoader workers);
            # the parallel kernel is only ever called from the main thread, so workqueue's lack of thread
            # safety does not matter. A user's NUMBA_THREADING_LAYER wins.
            numba.config.THREADING_LAYER = "workqueue"
        sig = ["float64(float64, float64, float64, float64, float64, float64)"]
        _NUMBA_KERNELS[target] = numba.vectorize(sig, target=target, cache=target == "cpu")(_kernel_scalar)
    return _NUMBA_KERNELS[target]


# ----------------------------------------------------------------------------------------------------------
# Public API
# ----------------------------------------------------------------------------------------------------------
def pwm_exposure(phase: ArrayLike, exposure: ArrayLike, period: ArrayLike, duty: ArrayLike,
                 amplitude: ArrayLike = 1.0, offset: ArrayLike = 0.0, rise_time: ArrayLike = 0.0,
                 fall_time: ArrayLike = 0.0, *, check: bool = True, backend: str = "auto") -> ArrayLike:
    r"""Radiant exposure of a PWM source over ``[phase, phase + exposure)`` (eq. 1 of ISET-LFM).

    .. math:: \Phi = \int_{t_s}^{t_s + t_e} I(t)\,dt,\qquad
              I(t) = \text{offset} + A\,[\,t \bmod T < DT\,]

    Args:
        phase: exposure start relative to a rising edge of the source, :math:`t_s` (s); any real value.
        exposure: exposure duration :math:`t_e \ge 0` (s); any length, also many periods.
        period: PWM period :math:`T > 0` (s); validated from 1 us to 1 s, any positive value accepted.
        duty: duty cycle :math:`D \in [0, 1]` (1); 0 = always OFF, 1 = always ON.
        amplitude: level :math:`A \ge 0` added while ON (e.g. W sr^-1 m^-2 nm^-1).
        offset: level :math:`\ge 0` present at all times (a source that never goes fully dark).
        rise_time, fall_time: widths (s) of linear ramps centred on the rising / falling edges; 0 = ideal.
        check: validate inputs (finite, in range, broadcastable); ``False`` skips the checks for speed (an
            invalid value still raises: the compiled kernel flags it and the checks then run).
        backend: numpy inputs only: ``"auto"`` (numba kernel for ideal pulses when numba is installed),
            ``"numba"`` or ``"numpy"`` (the array formula shared with torch).

    All arguments broadcast (numpy broadcasting); numpy inputs give float64 numpy arrays (0-d for scalars),
    any torch tensor among the inputs gives a tensor on that device, in the promoted floating dtype,
    differentiable with respect to every argument (almost everywhere).

    Returns:
        :math:`\Phi` in level x s, same broadcast shape. Guaranteed
        :math:`0 \le \Phi \le (A + \text{offset})\,t_e`.

    Raises:
        ValueError: NaN or inf, ``period <= 0``, ``exposure < 0``, ``duty`` outside [0, 1], negative levels,
            overlapping ramps or a shape mismatch; the message names the argument.

    Example:
        >>> float(pwm_exposure(0.0, 0.005, 0.01, 0.2))   # ON for the first 2 ms of a 5 ms exposure
        0.002
        >>> float(pwm_exposure(0.0025, 0.005, 0.01, 0.2))  # exposure inside the OFF time: the LED vanishes
        0.0
    """
    if backend not in ("auto", "numba", "numpy"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'numpy'; got {backend!r}")
    trapezoid = not (_is_zero(rise_time) and _is_zero(fall_time))
    if check:
        _check_pwm_args(phase, exposure, period, duty, amplitude, offset, rise_time, fall_time)
    if _is_torch(phase, exposure, period, duty, amplitude, offset, rise_time, fall_time):
        args = _as_tensors(phase, exposure, period, duty, amplitude, offset, rise_time, fall_time)
        ph, te, T, D, A, off, tr, tf = args
        ops = _Ops(True)
        pulse = _pulse_core(ph, te, T, D, tr, tf, ops, _SPLIT[ph.dtype], trapezoid)
        return A * pulse + off * te
    if not trapezoid and backend != "numpy":
        size = int(np.prod(np.broadcast_shapes(*(np.shape(x) for x in (phase, exposure, period, duty, amplitude,
                                                                        offset)))))
        kernel = _numba_kernel(size)
        if kernel is None and backend == "numba":
            raise ValueError("backend='numba' needs the numba package")
        if kernel is not None:
            arrays = [np.asarray(x, dtype=np.float64) for x in (phase, exposure, period, duty, amplitude, offset)]
            out = kernel(*arrays)
            if not check and np.isnan(out).any():
                _check_pwm_args(phase, exposure, period, duty, amplitude, offset, rise_time, fall_time)
            return np.asarray(out)
    ph, te, T, D, A, off, tr, tf = (np.asarray(x, dtype=np.float64) for x in
                                      (phase, exposure, period, duty, amplitude, offset, rise_time, fall_time))
    pulse = _pulse_core(ph, te, T, D, tr, tf, _Ops(False), _SPLIT[np.dtype(np.float64)], trapezoid)
    return np.asarray(A * pulse + off * te)


def _is_zero(x: ArrayLike) -> bool:
    if isinstance(x, (int, float)):
        return x == 0
    return not bool(_np_view(x).any())


def _as_tensors(*xs: ArrayLike) -> list[torch.Tensor]:
    """Promote mixed numpy/torch/float arguments to tensors of one floating dtype on one device."""
    tensors = [x for x in xs if isinstance(x, torch.Tensor)]
    device = tensors[0].device
    dtype = tensors[0].dtype if tensors[0].is_floating_point() else torch.get_default_dtype()
    for t in tensors[1:]:
        if t.is_floating_point():
            dtype = torch.promote_types(dtype, t.dtype)
    if dtype not in (torch.float32, torch.float64):
        dtype = torch.float32 if dtype in (torch.float16, torch.bfloat16) else torch.float64
    out = []
    for x in xs:
        if isinstance(x, torch.Tensor):
            out.append(x.to(device=device, dtype=dtype))
        elif isinstance(x, (int, float)) and not isinstance(x, bool):
            # a fill on the device, not a copy from the host (a copy would wait for the device's queue)
            out.append(torch.full((), float(x), dtype=dtype, device=device))
        else:
            out.append(torch.as_tensor(np.asarray(x, dtype=np.float64), device=device).to(dtype))
    return out


def pwm_level(t: ArrayLike, period: ArrayLike, duty: ArrayLike, amplitude: ArrayLike = 1.0,
              offset: ArrayLike = 0.0, rise_time: ArrayLike = 0.0, fall_time: ArrayLike = 0.0) -> ArrayLike:
    r"""Instantaneous source level :math:`I(t)` (same units as ``amplitude``) at time ``t`` (s).

    Rising edges at :math:`kT`. For ideal pulses the level is ``offset + amplitude`` on
    :math:`[kT, kT + DT)` (left-closed) and ``offset`` elsewhere; with ramps it is the derivative of
    :func:`pwm_exposure` in its exposure length.
    """
    check_array("t", t)
    _check_pwm_args(0.0, 0.0, period, duty, amplitude, offset, rise_time, fall_time)
    torch_mode = _is_torch(t, period, duty, amplitude, offset, rise_time, fall_time)
    ops = _Ops(torch_mode)
    if torch_mode:
        t, T, D, A, off, tr, tf = _as_tensors(t, period, duty, amplitude, offset, rise_time, fall_time)
    else:
        t, T, D, A, off, tr, tf = (np.asarray(x, dtype=np.float64)
                                   for x in (t, period, duty, amplitude, offset, rise_time, fall_time))
    u = _mod_period(t, T, ops)
    dt = D * T
    one = 1 + 0 * u

    def step(x, w):  # unit step smoothed into a ramp of width w (ideal step for w == 0: H(0) = 1)
        safe = ops.where(w > 0, w, one)
        ramp = ops.clip(0.5 + x / safe, 0.0, 1.0)
        return ops.where(w > 0, ramp, ops.where(x >= 0, one, 0 * one))

    level = (step(u, tr) + step(u - T, tr) - step(u - dt, tf))
    # the rising ramp of the next period starts at T - tr/2 (covered by step(u - T, tr)); clip guards rounding
    return off + A * ops.clip(level, 0.0, 1.0)


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


def bin_weights(edges: ArrayLike, period: ArrayLike, duty: ArrayLike, led_phase: ArrayLike = 0.0,
                amplitude: ArrayLike = 1.0, offset: ArrayLike = 0.0, rise_time: ArrayLike = 0.0,
                fall_time: ArrayLike = 0.0) -> ArrayLike:
    r"""Mean source level in each time bin.

    For bin edges :math:`t_0 < t_1 < \dots < t_K` (s) and a source whose rising edges fall at
    ``led_phase + k * period``, bin k gets :math:`\frac{1}{t_{k+1}-t_k}\int_{t_k}^{t_{k+1}} I(t)\,dt`
    (level units). Multiplying radiance rendered per bin with these weights and the bin widths gives the
    exposure of any PWM draw without re-rendering.

    Args:
        edges: bin edges, shape (..., K+1), strictly increasing along the last axis (s).
        period, duty, led_phase, amplitude, offset, rise_time, fall_time: source parameters, each a scalar or
            of shape broadcastable to ``edges.shape[:-1]`` (one value per row of bins).

    Returns:
        Mean levels, shape (..., K).
    """
    check_array("edges", edges)
    torch_mode = _is_torch(edges, period, duty, led_phase, amplitude, offset, rise_time, fall_time)
    if torch_mode:
        edges, period, duty, led_phase, amplitude, offset, rise_time, fall_time = _as_tensors(
            edges, period, duty, led_phase, amplitude, offset, rise_time, fall_time)
    else:
        edges = np.asarray(edges, dtype=np.float64)
    if edges.ndim < 1 or edges.shape[-1] < 2:
        raise ValueError(f"edges must have shape (..., K+1) with K >= 1; got shape {tuple(edges.shape)}")
    width = edges[..., 1:] - edges[..., :-1]
    if (_np_view(width) <= 0).any():
        raise ValueError("edges must be strictly increasing along the last axis")

    def per_row(x):  # a per-row parameter gains a trailing bin axis
        if isinstance(x, torch.Tensor):
            return x.unsqueeze(-1) if x.ndim > 0 else x
        x = np.asarray(x, dtype=np.float64)
        return x[..., None] if x.ndim > 0 else x

    phi = pwm_exposure(edges[..., :-1] - per_row(led_phase), width, per_row(period), per_row(duty),
                       per_row(amplitude), per_row(offset), per_row(rise_time), per_row(fall_time))
    return phi / width


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
    if isinstance(phi, torch.Tensor):
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
    and checked against a phase sweep of it (tests/test_flicker.py).

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
