"""The PWM source: radiant exposure over an exposure window (:func:`pwm_exposure`, eq. 1 of ISET-LFM), the
instantaneous level (:func:`pwm_level`) and the mean level per time bin (:func:`bin_weights`)."""
from __future__ import annotations


import numpy as np

from lfmbench.check import check_array
from lfmbench.flicker.args import ArrayLike, _as_tensors, _check_pwm_args, _is_tensor, _is_torch, _is_zero, _np_view
from lfmbench.flicker.exact import _Ops, _SPLIT, _mod_period, _pulse_core
from lfmbench.flicker.kernels import _numba_kernel

__all__ = ["pwm_exposure", "pwm_level", "bin_weights"]


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
        if _is_tensor(x):
            return x.unsqueeze(-1) if x.ndim > 0 else x
        x = np.asarray(x, dtype=np.float64)
        return x[..., None] if x.ndim > 0 else x

    phi = pwm_exposure(edges[..., :-1] - per_row(led_phase), width, per_row(period), per_row(duty),
                       per_row(amplitude), per_row(offset), per_row(rise_time), per_row(fall_time))
    return phi / width
