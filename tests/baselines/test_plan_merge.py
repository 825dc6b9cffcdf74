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
