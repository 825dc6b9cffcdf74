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

Modules
-------
This package face only re-exports: :mod:`~lfmbench.flicker.pwm` (:func:`pwm_exposure`, :func:`pwm_level`,
:func:`bin_weights`), :mod:`~lfmbench.flicker.phases` (:func:`frame_phase`, :func:`row_phase`),
:mod:`~lfmbench.flicker.severity` (:func:`flicker_severity`, :func:`miss_probability`), built on
:mod:`~lfmbench.flicker.exact` (the error-free arithmetic of the method above), :mod:`~lfmbench.flicker.kernels`
(the numba kernels) and :mod:`~lfmbench.flicker.args` (argument checks); :mod:`~lfmbench.flicker.waveforms`
holds the gated waveforms of real lamps.
"""
from __future__ import annotations

from lfmbench.flicker.phases import frame_phase, row_phase
from lfmbench.flicker.pwm import bin_weights, pwm_exposure, pwm_level
from lfmbench.flicker.severity import flicker_severity, miss_probability, windows_miss_probability

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
