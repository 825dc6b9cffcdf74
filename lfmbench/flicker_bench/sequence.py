r"""Sequences at a frame rate: the phase walks by the beat between frame rate and PWM; KPIs over N frames as a
camera records them; frames needed to visit every phase.

Frame n starts at :math:`n t_f`; an LED whose rising edge is at phase :math:`\varphi_0` in frame 0 is at

.. math:: \varphi_n = (\varphi_0 - n\,t_f) \bmod T

in frame n (ISET-LFM eq. 3, from the exposure's side; :func:`lfmbench.flicker.frame_phase` computes it without
drift). The phase steps by :math:`-\{t_f/T\}\,T` per frame, the beat of the frame rate against the PWM
frequency (:math:`|f - k f_{frame}|` for the nearest harmonic k): a slow beat visits few phases in N frames.

Frames to cover every phase: the first N frames visit the points :math:`\{n\alpha\}` on the unit circle,
:math:`\alpha = \{t_f / T\}`. By the three-distance theorem (V. T. Sós, "On the distribution mod 1 of the sequence
n alpha", Ann. Univ. Sci. Budapest. 1 (1958) 127-134) their largest gap is, for
:math:`N = r q_k + q_{k-1} + s` (:math:`1 \le r \le a_{k+1}`, :math:`0 \le s < q_k`),

.. math:: g(N) = \eta_{k-1} - (r - 1)\,\eta_k,

with :math:`a_k, q_k` the partial quotients and convergent denominators of :math:`\alpha` and
:math:`\eta_k = |q_k\alpha - p_k|` (:math:`\eta_{-1} = 1`, :math:`\eta_0 = \alpha`). :func:`frames_to_cover` returns
the least N with :math:`g(N) \le` ``tol`` (every phase within ``tol * T`` of a visited one, counting the gap between
its two neighbours) in exact rational arithmetic of the float inputs; ``None`` when it never happens within
``n_max`` frames (a commensurate frame rate visits only :math:`q` phases). Tested against brute force.
"""
from __future__ import annotations

from fractions import Fraction
from typing import Callable, Mapping

import numpy as np
import torch

from lfmbench.flicker_bench.exact import capture_state, evaluate_panels, on_fraction
from lfmbench.flicker_bench.model import SensorModel, grid_cells
from lfmbench.flicker import frame_phase
from lfmbench.metrics.flicker import fdi, fmi, mmp

__all__ = ["sequence_phases", "sequence_series", "sequence_kpis", "frames_to_cover", "max_gap"]


def sequence_phases(frame_time_s: float, period_s: np.ndarray, n_frames: int, phase0_s: float = 0.0) -> np.ndarray:
    """LED rising-edge phase (s, [0, T)) in frames 0..N-1, shape (..., N) for ``period_s`` of shape (...)."""
    T = np.asarray(period_s, np.float64)[..., None]
    u = frame_phase(-float(phase0_s), np.arange(n_frames, dtype=np.float64), frame_time_s, T)  # (n t_f - phi0) mod T
    phi = T - u
    return np.where(phi >= T, phi - T, phi)


def sequence_series(model: SensorModel, freqs_hz: np.ndarray, duties: np.ndarray, lums: np.ndarray,
                    methods: Mapping[str, Callable], n_frames: int, phase0_s: float = 0.0) -> dict[str, np.ndarray]:
    """Noise-free ROI values (reference e-) of every panel in frames 0..N-1: {panel: (C, L, N)}, cells as in
    :func:`lfmbench.flicker_bench.exact.phase_map`."""
    f, d = grid_cells(freqs_hz, duties)
    T = 1.0 / f
    ph = sequence_phases(model.frame_time_s, T, n_frames, phase0_s)                     # (C, N)
    bg = model.settings["background_cd_m2"]
    lums = np.asarray(lums, np.float64)
    frac = {}
    for c in model.captures:
        if c.group not in frac:
            frac[c.group] = on_fraction(c, ph, T[:, None], d[:, None])                    # (C, N)
    mu = {c.name: torch.from_numpy(c.rate * (lums[None, :, None] * frac[c.group][:, None, :] + bg) + c.dark_e)
          for c in model.captures}
    vals, flags = capture_state(model, mu)
    return {k: v.numpy() for k, v in evaluate_panels(model, methods, vals, flags).items()}


def sequence_kpis(series: Mapping[str, np.ndarray], off: Mapping[str, float], delta: float = 0.1,
                  contrast: float = 0.1) -> dict[str, dict[str, np.ndarray]]:
    """P2020 FMI, MMP and FDI (:mod:`lfmbench.metrics.flicker`, equal to the CARpublic reference) of each panel's
    series (frames on the last axis); the FDI's OFF level is the panel's LED-OFF value ``off``."""
    out = {}
    for p, x in series.items():
        t = torch.from_numpy(np.ascontiguousarray(x))
        with np.errstate(invalid="ignore", divide="ignore"):
            out[p] = {"fmi": fmi(t).numpy(), "mmp": mmp(t, delta=delta).numpy(),
                      "fdi": fdi(t, x_off=float(off[p]), contrast_threshold=contrast).numpy()}
    return out


def max_gap(frame_time_s: float, freq_hz: float, n: int) -> float:
    """Largest gap (share of the period) between the phases of frames 0..n-1, by the three-distance formula."""
    alpha = Fraction(frame_time_s) * Fraction(freq_hz)
    alpha -= alpha.numerator // alpha.denominator
    if n <= 1 or alpha == 0:
        return 1.0
    eta_prev, eta, q_prev, q = Fraction(1), alpha, 0, 1
    while True:
        a = eta_prev // eta
        q_next = a * q + q_prev
        if n < q_next + q:  # N = r q + q_prev + s in this level
            r = (n - q_prev) // q
            return float(eta_prev - (r - 1) * eta)
        eta_next = eta_prev - a * eta
        if eta_next == 0:
            return float(eta)
        eta_prev, eta, q_prev, q = eta, eta_next, q, q_next


def frames_to_cover(frame_time_s: float, freq_hz: float, tol: float = 0.01, n_max: int = 10 ** 6) -> int | None:
    """Least number of frames whose phases leave no gap wider than ``tol`` x T (module docstring); None when
    more than ``n_max`` frames would be needed (or never: commensurate rates)."""
    if tol >= 1:
        return 1
    alpha = Fraction(frame_time_s) * Fraction(freq_hz)
    alpha -= alpha.numerator // alpha.denominator
    if alpha == 0:
        return None
    tol_f = Fraction(tol)
    eta_prev, eta, q_prev, q = Fraction(1), alpha, 0, 1
    while True:
        a = eta_prev // eta
        # g = eta_prev - (r - 1) eta <= tol  <=>  r >= 1 + (eta_prev - tol) / eta
        need = (eta_prev - tol_f) / eta
        r = max(1, 1 + -(-need.numerator // need.denominator))
        if r <= a:
            n = r * q + q_prev
            return n if n <= n_max else None
        eta_next = eta_prev - a * eta
        q_next = a * q + q_prev
        if eta_next == 0 or q_next > n_max:
            return None
        eta_prev, eta, q_prev, q = eta, eta_next, q, q_next
