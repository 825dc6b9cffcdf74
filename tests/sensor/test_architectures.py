"""The shipped capture plans of every architecture against independent answers: the chopped spacing never misses a
90-120 Hz PWM at D >= 0.1 (analytic phase sweep), staggered exposure ratios, the general chain's noise-free
electrons and input referral."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from lfmbench.sensor import available_presets, load_preset, simulate_plan_electrons
from lfmbench.sensor.plan import ARCHITECTURES, resolve_windows, total_length_s

TIMING = {"short_exposure_s": 0.004, "long_exposure_s": 1 / 90}


def on_time_in_windows(windows, period, duty, phase) -> float:
    """Time (s) a PWM of ``period`` (s) and ``duty`` whose ON intervals are [phase + m P, phase + m P + D P) spends ON
    inside ``windows`` ((start, length) s): interval intersections, written here independently of lfmbench."""
    total = 0.0
    for a, n in windows:
        m0 = int(np.floor((a - phase) / period)) - 1
        m1 = int(np.ceil((a + n - phase) / period)) + 1
        for m in range(m0, m1 + 1):
            lo, hi = phase + m * period, phase + m * period + duty * period
            total += max(0.0, min(hi, a + n) - max(lo, a))
    return total


def test_every_architecture_has_a_shipped_preset():
    have = {load_preset(n).architecture for n in available_presets()}
    assert have == set(ARCHITECTURES)


@pytest.mark.parametrize("freq", [90.0, 97.0, 105.0, 113.0, 120.0])
def test_chopped_phase_sweep_never_misses_a_pwm_of_90_to_120_hz(freq):
    wins = resolve_windows(load_preset("chopped").captures["chopped"].exposure, TIMING)
    assert len(wins) >= 2
    P, D = 1.0 / freq, 0.1
    phases = np.linspace(0.0, P, 2001)
    got = np.array([on_time_in_windows(wins, P, D, ph) for ph in phases])
    assert got.min() > 0.0, f"{freq} Hz: a phase with zero exposure at {phases[got.argmin()]}"
    # one sub-window alone misses the light for a range of phases (a conventional short exposure)
    one = np.array([on_time_in_windows(wins[:1], P, D, ph) for ph in phases])
    assert (one == 0.0).sum() > 0.5 * len(phases)


def test_chopped_sweep_agrees_with_the_library_pwm_integral():
    """The analytic sweep above and lfmbench.flicker.pwm_exposure give the same ON time per sub-window."""
    from lfmbench.flicker import pwm_exposure

    wins = resolve_windows(load_preset("chopped").captures["chopped"].exposure, TIMING)
    P, D = 1 / 113.0, 0.1
    for ph in np.linspace(0.0, P, 37):
        lib = sum(float(pwm_exposure(np.array([a - ph]), n, P, D)[0]) for a, n in wins)
        assert lib == pytest.approx(on_time_in_windows(wins, P, D, ph), abs=1e-12)


def test_staggered_exposure_ratios_are_exact():
    p = load_preset("staggered")
    lens = [total_length_s(resolve_windows(c.exposure, TIMING)) for c in p.captures.values()]
    assert lens[0] / lens[1] == pytest.approx(10.0, rel=1e-12) and lens[1] / lens[2] == pytest.approx(10.0, rel=1e-12)
    # a flat scene, noise-free: each capture's electrons scale with its exposure, and input referral undoes it
    rate = 4.0e5                                                       # e-/s
    mean_e = {k: torch.full((1, 1, 4, 4), rate * t, dtype=torch.float64) for k, t in zip(p.exposures, lens)}
    out = simulate_plan_electrons(mean_e, p, dict(zip(p.exposures, lens)), noise=False)
    e = {c: out[f"{c}_e"] for c in p.captures}
    # quantisation (one DN = 1 / K e-) is the only difference from the ideal reference electrons rate x T_long
    K = p.system_gain("long")
    for c in p.captures:
        ideal = rate * lens[0]
        step = lens[0] / total_length_s(resolve_windows(p.captures[c].exposure, TIMING)) / K
        assert torch.allclose(e[c], torch.full_like(e[c], ideal), atol=0.5 * step + 1e-6 * ideal)


@pytest.mark.parametrize("name", ["lofic", "staggered", "chopped", "single"])
def test_noise_free_chain_matches_the_linear_model(name):
    """Per capture, by hand: DN = round(black + min(min(e + dark T, FW) cg, swing) dn_per_volt)."""
    p = load_preset(name)
    ts = {k: total_length_s(resolve_windows(p.captures[k].exposure, TIMING)) for k in p.exposures}
    levels = torch.tensor([0.0, 10.0, 900.0, 9000.0, 5e4, 1e6, 1e9], dtype=torch.float64).reshape(1, 1, 1, -1)
    mean_e = {k: levels.clone() for k in p.exposures}
    out = simulate_plan_electrons(mean_e, p, ts, noise=False)
    assert out["saturated"].shape == (1, len(p.captures), 1, levels.shape[-1])
    for i, (c, spec) in enumerate(p.captures.items()):
        key = next(k for k, caps in p.exposures.items() if c in caps)
        pd = p.photodiodes[spec.photodiode]
        e = np.minimum(levels.numpy().ravel() + pd.dark_current_e_per_s * ts[key], pd.full_well_e)
        v = np.minimum(e * spec.conversion_gain_v_per_e, spec.voltage_swing_v)
        dn = np.clip(np.round(p.black_level_dn + v * (2 ** p.adc_bits - 1 - p.black_level_dn) / spec.voltage_swing_v),
                     0, 2 ** p.adc_bits - 1)
        assert np.array_equal(out[c].numpy().ravel(), dn), c
        assert np.array_equal(out["saturated"][0, i, 0].numpy(), v >= p.saturation_fraction * spec.voltage_swing_v)


def test_plan_chain_checks_its_inputs():
    p = load_preset("lofic")
    x = torch.zeros(1, 1, 2, 2)
    with pytest.raises(ValueError, match="exposures"):
        simulate_plan_electrons({"nope": x}, p, {"nope": 0.01}, noise=False)
    with pytest.raises(ValueError, match="generator"):
        simulate_plan_electrons({"hcg": x}, p, {"hcg": 0.01}, noise=True)
    with pytest.raises(ValueError):
        simulate_plan_electrons({"hcg": torch.full((1, 1, 2, 2), float("nan"))}, p, {"hcg": 0.01}, noise=False)


def test_plan_chain_of_a_split_pixel_is_the_split_pixel_chain():
    from lfmbench.sensor import simulate_split_pixel_electrons

    p = load_preset("ovt")
    g = torch.Generator().manual_seed(3)
    lpd, spd = torch.rand(2, 1, 8, 8, generator=g) * 3000, torch.rand(2, 1, 8, 8, generator=g) * 30
    a = simulate_plan_electrons({"lpd_hcg": lpd, "spd": spd}, p, {"lpd_hcg": 0.004, "spd": 1 / 90},
                                torch.Generator().manual_seed(9))
    b = simulate_split_pixel_electrons(lpd, spd, p, 0.004, 1 / 90, torch.Generator().manual_seed(9))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
