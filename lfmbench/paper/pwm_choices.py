"""The PWM parameters the paper figures choose: the phase that makes a light drop out of a frame
(:func:`dropout_phase`, Figs. 4-5), the exposure of a row (:func:`row_exposure`) and the phases of Fig. 7's
rolling-shutter bands (:func:`fig7_phases`)."""
from __future__ import annotations

import numpy as np


#: PWM of the light that drops out (Figs. 4, 5): 100 Hz, D = 0.2 (2 ms ON, 8 ms OFF > the 5 ms LPD exposure).
DROPOUT_PWM = (100.0, 0.2)


#: PWM of the second dropout (Fig. 5, yellow): 95 Hz, D = 0.25.
DROPOUT2_PWM = (95.0, 0.25)


#: PWM of the comet light (Fig. 6): 90 Hz, D = 0.5 (5.6 ms ON: a long SPD trail).
COMET_PWM = (90.0, 0.5)


#: Paper ranges of the other vehicle lights: f in [90, 110] Hz, D in [0.1, 0.5].
FREQ_RANGE_HZ, DUTY_RANGE = (90.0, 110.0), (0.1, 0.5)


#: Fig. 7: all vehicle LEDs synchronised at 105 Hz, D = 0.2 (the paper's values).
FIG7_PWM = (105.0, 0.2)


def dropout_phase(freq_hz: float, duty: float, off_frame: int, frames: int, fps: float, lpd_start_s: float,
                  short_s: float, steps: int = 2000) -> float:
    """Phase (s, a rising edge after the start of frame 0) that puts a PWM light OFF for the whole short
    exposure of frame ``off_frame`` and ON for as much as possible of the other frames' short exposures.

    Global shutter: frame n's LPD window is ``[n / fps + lpd_start_s, + short_s)`` (s). Among the phases on a
    grid of ``steps`` points over one period whose ``off_frame`` window holds no ON time, the one with the
    largest margin to the nearest pulse edge is taken (ties: most ON time in the other frames).

    Args:
        freq_hz: PWM frequency (Hz). duty: duty cycle (1). off_frame: frame index (0-based) to put OFF.
        frames: frames in the sequence. fps: frame rate (1/s). lpd_start_s: LPD window start in a frame (s).
        short_s: LPD exposure (s).

    Returns:
        The phase in s, in [0, 1 / freq_hz).

    Raises:
        ValueError: no phase puts the light OFF (the OFF time ``(1 - duty) / freq_hz`` is shorter than ``short_s``).
    """
    from lfmbench.flicker import pwm_exposure

    T = 1.0 / freq_hz
    if (1.0 - duty) * T <= short_s:
        raise ValueError(f"duty {duty} at {freq_hz} Hz: OFF time {(1 - duty) * T * 1e3:.2f} ms is not longer than "
                         f"the short exposure {short_s * 1e3:.2f} ms; no phase can hide the light")
    phases = np.arange(steps) * (T / steps)
    starts = np.arange(frames) / fps + lpd_start_s                              # (F,) s
    phi = pwm_exposure(starts[None, :] - phases[:, None], short_s, T, duty)     # (steps, F) s of ON time
    off = phi[:, off_frame] == 0.0
    # margin: how far the phase can move either way and keep the window dark
    margin = np.zeros(steps)
    for i in np.flatnonzero(off):
        d = 1
        while d < steps // 2 and off[(i + d) % steps] and off[(i - d) % steps]:
            d += 1
        margin[i] = d
    others = np.delete(phi, off_frame, axis=1).min(axis=1) if frames > 1 else np.zeros(steps)
    score = np.where(off, margin * steps + others / (duty * T + 1e-30), -np.inf)
    return float(phases[int(np.argmax(score))])


def row_exposure(rows, phase_s: float, freq_hz: float, duty: float, lpd_start_s: float, short_s: float,
                 line_time_s: float) -> np.ndarray:
    """ON time (s) of a PWM light in each row's short exposure under a rolling shutter (frame 0).

    Row r opens at ``lpd_start_s + r * line_time_s`` (s). rows: (R,) row indices. Returns (R,) s.
    """
    from lfmbench.flicker import pwm_exposure

    rows = np.asarray(rows, dtype=np.float64)
    return np.asarray(pwm_exposure(lpd_start_s + rows * line_time_s - phase_s, short_s, 1.0 / freq_hz, duty))


def fig7_phases(upper_rows: tuple[int, int], lower_rows: tuple[int, int], target_rows: tuple[int, int],
                freq_hz: float, duty: float, lpd_start_s: float, short_s: float, line_time_s: float
                ) -> tuple[float, float]:
    """Phases (s) of Fig. 7 for a rolling shutter (rows open ``line_time_s`` apart).

    Phase A puts the start of the lit band of rows (E > 0) half-way between the ``upper_rows`` (e.g. high-mount
    brake lights, then dark) and the ``lower_rows`` (tail lights, then lit): a dark band above the tail
    lights. Phase B starts the lit band just below ``target_rows`` (the motorcycle's light), so its rows,
    ending ``target_rows[1]`` (exclusive), hold no ON time at all.

    Args:
        upper_rows, lower_rows, target_rows: (first, last + 1) row ranges (px). freq_hz (Hz), duty (1).
        lpd_start_s: row 0's window start in the frame (s). short_s: exposure (s). line_time_s: row delay (s).

    Returns:
        ``(phase_a, phase_b)`` in s, each in [0, 1 / freq_hz).
    """
    T = 1.0 / freq_hz
    # a row's window [s, s + te) first touches the pulse [phase, phase + DT) when s = phase - te: rows opening
    # at or before that (mod T, back to the previous pulse's end) are dark
    edge_a = 0.5 * (upper_rows[1] - 1 + lower_rows[0])
    phase_a = lpd_start_s + edge_a * line_time_s + short_s
    phase_b = lpd_start_s + (target_rows[1] - 1 + 0.5) * line_time_s + short_s
    return phase_a % T, phase_b % T
