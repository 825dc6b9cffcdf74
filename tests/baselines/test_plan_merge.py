"""Exposure selection, the standard HDR merge of the LOFIC, staggered, chopped and single-exposure plans: the LOFIC
SNR-vs-signal curve against its closed form, the selection rule, and the registry per architecture."""
from __future__ import annotations

import math

import pytest
import torch

from lfmbench.baselines import REGISTRY, exposure_select, methods_for
from lfmbench.baselines.classic import BatchError
from lfmbench.sensor import load_preset, simulate_plan_electrons
from lfmbench.sensor.plan import ARCHITECTURES

SHAPE = (1, 8, 1, 64, 64)          # one sample, 8 frames of 64 x 64 flat field: 32768 pixels per level


def _lofic_batch(level_e: float, seed: int) -> dict:
    p = load_preset("lofic")
    t = 0.011
    x = torch.full(SHAPE, level_e, dtype=torch.float64)
    out = simulate_plan_electrons({"hcg": x}, p, {"hcg": t}, torch.Generator().manual_seed(seed))
    return {k: v for k, v in out.items() if k.endswith("_e") or k == "saturated"}


def lofic_snr_closed_form(level_e: float) -> float:
    """SNR of the merged LOFIC output at a mean signal of ``level_e`` e- (EMVA 1288 linear model): shot noise of the
    signal and the dark current, the read noise and the quantisation noise (1/12 DN^2 / K^2) of the capture the
    merge uses, HCG below its saturation flag (0.95 x swing = 9500 e-), LCG above; all from the preset's fields."""
    p = load_preset("lofic")
    pd = p.photodiodes["pd"]
    cap = "hcg" if level_e < 0.95 * p.captures["hcg"].voltage_swing_v / p.captures["hcg"].conversion_gain_v_per_e \
        else "lcg"
    c = p.captures[cap]
    K = c.conversion_gain_v_per_e * (2 ** p.adc_bits - 1 - p.black_level_dn) / c.voltage_swing_v   # DN/e-
    var = level_e + pd.dark_current_e_per_s * 0.011 + c.read_noise_e ** 2 + 1.0 / (12.0 * K * K)
    return level_e / math.sqrt(var)


@pytest.mark.parametrize("level", [50.0, 500.0, 5000.0, 9000.0, 10500.0, 50000.0, 300000.0])
def test_lofic_snr_curve_matches_its_closed_form(level):
    a, b = _lofic_batch(level, 1), _lofic_batch(level, 2)
    ya, yb = exposure_select(a), exposure_select(b)
    # temporal noise from the pair difference (removes the 0.5 % PRNU, a fixed pattern: EMVA 1288)
    sigma = float((ya - yb).double().std() / math.sqrt(2.0))
    assert level / sigma == pytest.approx(lofic_snr_closed_form(level), rel=0.04)
    assert float(ya.double().mean()) == pytest.approx(level, rel=0.01, abs=1.0)


def test_lofic_switches_gain_at_the_hcg_saturation_flag():
    lo, hi = _lofic_batch(9000.0, 3), _lofic_batch(10500.0, 3)
    assert not lo["saturated"][:, :, 0].any() and hi["saturated"][:, :, 0].all()
    assert torch.equal(exposure_select(lo), lo["hcg_e"]) and torch.equal(exposure_select(hi), hi["lcg_e"])
    # the SNR dips at the switch (LCG read + quantisation noise >> HCG's), by the closed form's amount
    assert lofic_snr_closed_form(10500.0) < lofic_snr_closed_form(9000.0) * math.sqrt(10500 / 9000)


def test_exposure_select_takes_the_first_unsaturated_capture_in_plan_order():
    e = {f"c{i}_e": torch.full((1, 1, 1, 1, 4), float(i)) for i in range(3)}
    sat = torch.tensor([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1]], dtype=torch.bool).T.reshape(1, 1, 3, 1, 4)
    out = exposure_select({**e, "saturated": sat})
    assert out.flatten().tolist() == [0.0, 1.0, 2.0, 2.0]
    with pytest.raises(BatchError, match="one channel per capture"):
        exposure_select({**e, "saturated": sat[:, :, :2]})
    with pytest.raises(BatchError, match="input-referred"):
        exposure_select({"saturated": sat})


def test_every_architecture_names_a_registered_baseline():
    for name, arch in ARCHITECTURES.items():
        assert arch.baseline in REGISTRY and arch.baseline in methods_for(name)
    assert "exposure_select" not in methods_for("split_pixel") and "lpd_only" in methods_for("split_pixel")
    with pytest.raises(ValueError, match="architecture"):
        methods_for("quantum")


def test_bounded_selection_is_selection_bounded_below_by_the_saturated_captures():
    """Per pixel max(exposure_select, the saturated captures' values): equal to exposure_select where nothing
    saturates, never below it, and the saturated long capture's value where a short one missed the pulse."""
    from lfmbench.baselines import exposure_select_bounded

    e = {"long_e": torch.tensor([5.0, 9.0, 9.0, 9.0]), "medium_e": torch.tensor([5.0, 0.0, 20.0, 0.0]),
         "short_e": torch.tensor([5.0, 0.0, 0.0, 12.0])}
    e = {k: v.reshape(1, 1, 1, 1, 4) for k, v in e.items()}
    sat = torch.tensor([[0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 1, 0]], dtype=torch.bool).T.reshape(1, 1, 3, 1, 4)
    b = {**e, "saturated": sat}
    assert exposure_select(b).flatten().tolist() == [5.0, 0.0, 20.0, 12.0]
    assert exposure_select_bounded(b).flatten().tolist() == [5.0, 9.0, 20.0, 12.0]
    assert "exposure_select_bounded" in methods_for("staggered")
    for arch in ("lofic", "chopped", "single", "split_pixel"):       # one window per photodiode: nothing to bound
        assert "exposure_select_bounded" not in methods_for(arch)
    for name, arch in ARCHITECTURES.items():
        assert all(o in REGISTRY and o in methods_for(name) for o in arch.others)


def test_bounded_selection_keeps_a_lamp_the_short_exposures_missed():
    """The staggered plan simulated (its own noise chain): an LED ON through the 10 ms exposure and OFF during the
    1 ms and 0.1 ms ones (their windows missed the pulse), 3x the long exposure's full well. exposure_select reads
    the unsaturated medium capture (about 0: a dropout); the bounded merge keeps at least the long capture's
    saturation level, below the truth (the long exposure's mean, the gt units)."""
    from lfmbench.baselines import exposure_select_bounded

    p = load_preset("staggered")
    full = p.photodiodes[p.captures["long"].photodiode].full_well_e
    x = {"long": torch.full(SHAPE, 3.0 * full, dtype=torch.float64), "medium": torch.zeros(SHAPE, dtype=torch.float64),
         "short": torch.zeros(SHAPE, dtype=torch.float64)}
    out = simulate_plan_electrons(x, p, {"long": 0.010, "medium": 0.001, "short": 0.0001},
                                  torch.Generator().manual_seed(5))
    b = {k: v for k, v in out.items() if k.endswith("_e") or k == "saturated"}
    assert b["saturated"][:, :, 0].all() and not b["saturated"][:, :, 1:].any()
    sel, bnd = exposure_select(b), exposure_select_bounded(b)
    assert float(sel.abs().mean()) < 0.01 * full                               # the dropout
    assert float(bnd.min()) >= 0.8 * full and float(bnd.max()) <= 3.0 * full   # bounded below, still below truth
    assert torch.equal(bnd, torch.maximum(sel, b["long_e"]))
