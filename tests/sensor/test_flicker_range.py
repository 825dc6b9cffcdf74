"""PWM flicker over the real range (90 Hz - 2 kHz) of the presets' exposures: the exact captured fraction
(:mod:`lfmbench.sensor.flicker_table`, from :func:`lfmbench.flicker.pwm_exposure`) against brute-force time
integration and against closed forms, and the corrected claims of ``chopped.yaml`` and ``lofic.yaml``."""
from __future__ import annotations

import numpy as np
import pytest

from lfmbench.sensor import available_presets, load_preset
from lfmbench.sensor.flicker_table import TIMING, captured_fraction_range, first_miss_hz
from lfmbench.sensor.plan import resolve_windows


def brute_fraction(windows, f, duty, phases, n=20000):
    """Captured fraction at each phase by the midpoint rule on n points per window (independent of the model)."""
    T = 1.0 / f
    out = []
    for ph in phases:
        tot, on = 0.0, 0.0
        for a, w in windows:
            t = a + ph + (np.arange(n) + 0.5) * (w / n)
            on += np.mean((t % T) < duty * T) * w
            tot += w
        out.append(on / (duty * tot))
    return np.array(out)


@pytest.mark.parametrize("f", [90.0, 1087.0, 2000.0])
def test_exact_fraction_equals_brute_force_for_every_preset(f):
    """Every exposure of every shipped preset, 5 phases per period, up to 2 kHz: the exact model's lowest and highest
    captured fraction bound the brute-force values, and the brute force reaches them to its resolution."""
    for name in available_presets():
        p = load_preset(name)
        for key in p.exposures:
            wins = resolve_windows(p.captures[key].exposure, TIMING)
            lo, hi, _ = captured_fraction_range(wins, f, 0.1)
            b = brute_fraction(wins, f, 0.1, np.linspace(0, 1 / f, 5, endpoint=False))
            # midpoint rule: each pulse edge inside a window misplaces at most one sample (w / n) of ON time
            tot = sum(w for _, w in wins)
            step = sum((2 * w * f + 2) * (w / 20000) for _, w in wins) / (0.1 * tot) + 1e-9
            assert lo - step <= b.min() and b.max() <= hi + step, (name, key)


def test_lofic_exposure_swings_with_phase_closed_form():
    """11 ms at 100 Hz, D = 0.1: 1.1 periods; the ON time caught is 1 or 2 ms, i.e. 1/1.1 = 0.909 to 2/1.1 = 1.818 of
    the mean (the 'no flicker by construction' claim was wrong)."""
    wins = resolve_windows(load_preset("lofic").captures["hcg"].exposure, TIMING)
    lo, hi, miss = captured_fraction_range(wins, 100.0, 0.1)
    assert lo == pytest.approx(1 / 1.1, abs=1e-9) and hi == pytest.approx(2 / 1.1, abs=1e-9) and miss == 0.0


def test_chopped_misses_above_its_design_range():
    """The chopped plan never misses a D = 0.1 light at 90-120 Hz, but does at 1,087 Hz on ~79 % of the phases
    (brute force on 512 phases agrees) and first at 122 Hz."""
    wins = resolve_windows(load_preset("chopped").captures["chopped"].exposure, TIMING)
    for f in (90.0, 100.0, 110.0, 120.0):
        assert captured_fraction_range(wins, f, 0.1)[0] > 0.05
    lo, hi, miss = captured_fraction_range(wins, 1087.0, 0.1)
    b = brute_fraction(wins, 1087.0, 0.1, np.arange(512) / 512 / 1087.0, n=400)
    assert lo == 0.0 and miss == pytest.approx(np.mean(b == 0.0), abs=0.02) and 0.75 < miss < 0.83
    first, _ = first_miss_hz(wins, 0.1, 118, 124)
    assert first == 122
