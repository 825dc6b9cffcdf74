"""``lfmbench flicker-report``: the paper's Fig. 3 experiment (temporal flicker at 30 fps) with the exact model.

Prints the radiant exposure per frame of a PWM LED for a short (5 ms) and a long (11.11 ms) exposure and the
flicker severity of each, and optionally plots Phi[n] (ISET-LFM, Fig. 3).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from lfmbench.fileio import atomic_save_figure

#: Exposure times of the split-pixel sensor used throughout (s): LPD short, SPD long (1/90 s).
FIG3_EXPOSURES_S = (5e-3, 1 / 90)


def fig3_series(freq_hz: float = 95.0, duty: float = 0.2, fps: float = 30.0, frames: int = 30,
                phase0_s: float = 0.0, exposures_s=FIG3_EXPOSURES_S) -> dict:
    """Per-frame radiant exposure (s of ON time, amplitude 1) for each exposure; eq. 3 phases.

    Returns:
        dict with ``frame`` (N,), ``phase_s`` (N,), and for each exposure te (s) the key ``te`` -> Phi (N,) (s)
        and ``("fsi", te)`` -> FSI.
    """
    from lfmbench.flicker import flicker_severity, frame_phase, pwm_exposure  # noqa: PLC0415 - torch: keep CLI start fast

    period = 1.0 / freq_hz
    n = np.arange(frames)
    ts = frame_phase(phase0_s, n, 1.0 / fps, period)
    out: dict = {"frame": n, "phase_s": ts}
    for te in exposures_s:
        phi = pwm_exposure(ts, te, period, duty)
        out[te] = phi
        out[("fsi", te)] = float(flicker_severity(phi))
    return out


def plot_fig3(path: str | Path, **kw) -> Path:
    """Write the Fig. 3 plot (Phi[n] for both exposures) to ``path`` (PNG)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = fig3_series(**kw)
    fig, axes = plt.subplots(2, 1, figsize=(7, 4.5), sharex=True)
    for ax, te in zip(axes, FIG3_EXPOSURES_S):
        ax.stem(s["frame"], s[te] * 1e3, basefmt=" ")
        ax.set_ylabel("Phi [ms of ON time]")
        ax.set_title(f"te = {te * 1e3:.2f} ms: FSI = {s[('fsi', te)]:.3f}", fontsize=9)
        ax.set_ylim(bottom=0)
    axes[-1].set_xlabel("frame n (30 fps)")
    fig.suptitle(f"Temporal flicker, f = {kw.get('freq_hz', 95.0):g} Hz, D = {kw.get('duty', 0.2):g}")
    fig.tight_layout()
    path = atomic_save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path
