"""Tests of lfmbench.sensor: presets, spectral response, noise statistics, clipping, extreme inputs."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import scipy.constants as sc
import scipy.stats as st
import torch
import yaml

from lfmbench.sensor import (
    CAPTURES,
    PRESET_DIR,
    CFAPattern,
    SplitPixelSensor,
    available_presets,
    band_widths_nm,
    electron_weights,
    fixed_pattern,
    ideal_electrons,
    load_preset,
    mosaic,
    read_spectral_csv,
    shot_noise,
    silicon_qe,
    simulate_split_pixel,
    simulate_split_pixel_electrons,
    spectral_qe,
)

WL = list(range(400, 701, 10))
T_S, T_L = 4e-3, 1 / 90


def _gen(seed=0):
    return torch.Generator().manual_seed(seed)


def _flat(e_lpd, preset, shape=(1, 1, 8, 8), dtype=torch.float64, wl=550.0):
    """Radiant exposure (J m^-2 nm^-1, one 1 nm band at ``wl``) giving ``e_lpd`` mean e- on the LPD green pixels."""
    w = electron_weights(preset, [wl], "lpd", bandwidths_nm=[1.0])[1, 0].item()
    return torch.full(shape, e_lpd / w, dtype=dtype)


# ------------------------------------------------------------------------------------------------ presets
def test_shipped_presets_hold_upstream_values():
    assert {"ovt", "imx490"} <= set(available_presets())
    p = load_preset("ovt")
    assert p.cfa is CFAPattern.GRBG and p.adc_bits == 12 and p.pixel_pitch_m == 2.8e-6
    assert p.photodiodes["lpd"].full_well_e == 22000 and p.photodiodes["spd"].full_well_e == 7900
    assert p.photodiodes["lpd"].dark_current_e_per_s == 25.6 and p.photodiodes["spd"].dark_current_e_per_s == 4.2
    assert p.photodiodes["spd"].fill_factor == 0.01 and p.sensitivity_ratio == pytest.approx(100.0)
    assert p.captures["lpd_lcg"].conversion_gain_v_per_e == 49e-6
    assert p.captures["lpd_lcg"].voltage_swing_v == pytest.approx(22000 * 49e-6)
    assert p.captures["spd"].voltage_swing_v == pytest.approx(7900 * 49e-6, rel=1e-4)
    assert [p.captures[c].read_noise_e for c in CAPTURES] == [0.83, 3.05, 0.83]
    assert p.saturation_capacity_e("lpd_hcg") == pytest.approx(5390.0)          # "saturates near 5.4k e-"
    assert p.optics.f_number == pytest.approx(17.19 / 3.0, rel=1e-3)
    q = load_preset("imx490")
    assert q.pixel_pitch_m == 3e-6 and q.photodiodes["lpd"].full_well_e == 120000
    assert q.photodiodes["spd"].full_well_e == 60000 and q.photodiodes["lpd"].prnu == 0.007
    cg = {c: q.captures[c].conversion_gain_v_per_e for c in CAPTURES}
    assert cg["lpd_hcg"] == pytest.approx(4 * cg["lpd_lcg"], rel=1e-3)
    assert q.sensitivity_ratio == pytest.approx(9.0)


def _ovt_dict():
    return yaml.safe_load((PRESET_DIR / "ovt.yaml").read_text())


def test_user_preset_from_file(tmp_path):
    d = _ovt_dict()
    d["name"] = "mine"
    d["captures"]["lpd_lcg"]["read_noise_e"] = 2.0
    d["spectral"]["filters"] = str(Path(load_preset("ovt").filters_path))
    f = tmp_path / "mine.yaml"
    f.write_text(yaml.safe_dump(d))
    p = load_preset(f)
    assert p.name == "mine" and p.captures["lpd_lcg"].read_noise_e == 2.0
    assert load_preset(str(f)) is p                       # cached


@pytest.mark.parametrize("mutate, field", [
    (lambda d: d["photodiodes"]["lpd"].__setitem__("full_well_e", -5), "photodiodes.lpd.full_well_e"),
    (lambda d: d["captures"]["spd"].__setitem__("conversion_gain_v_per_e", "big"),
     "captures.spd.conversion_gain_v_per_e"),
    (lambda d: d.__setitem__("cfa", "XYZW"), "cfa"),
    (lambda d: d.__setitem__("adc_bits", 12.5), "adc_bits"),
    (lambda d: d.__setitem__("colour", 1), "colour"),
    (lambda d: d["captures"].pop("lpd_hcg"), "captures.lpd_hcg"),
    (lambda d: d["captures"]["spd"].__setitem__("photodiode", "lpd"), "captures"),
    (lambda d: d["spectral"].__setitem__("filters", "nope.csv"), "spectral.filters"),
    (lambda d: d["photodiodes"]["spd"].__setitem__("fill_factor", 0.0), "photodiodes.spd.fill_factor"),
    (lambda d: d["optics"].__setitem__("f_number", 0), "optics.f_number"),
])
def test_invalid_preset_names_field_and_file(tmp_path, mutate, field):
    d = _ovt_dict()
    mutate(d)
    f = tmp_path / "bad.yaml"
    f.write_text(yaml.safe_dump(d))
    with pytest.raises(ValueError) as exc:
        load_preset(f)
    assert field in str(exc.value) and "bad.yaml" in str(exc.value)


def test_unknown_preset_name():
    with pytest.raises(ValueError, match="unknown sensor preset"):
        load_preset("no-such-sensor")


# ---------------------------------------------------------------------------------------------- spectral
def test_cfa_patterns_and_kornia_mapping():
    idx = CFAPattern.GRBG.index_map(4, 4)
    assert idx[:2, :2].tolist() == [[1, 0], [2, 1]] and idx[2:, 2:].tolist() == [[1, 0], [2, 1]]
    # round trip through kornia's demosaic: a constant colour survives mosaic -> raw_to_rgb exactly (interior)
    from kornia.color import raw_to_rgb

    for pat in CFAPattern:
        rgb = torch.tensor([0.2, 0.5, 0.9]).reshape(1, 3, 1, 1).expand(1, 3, 8, 8).contiguous()
        raw = mosaic(rgb, pat)
        back = raw_to_rgb(raw, pat.to_kornia())
        assert torch.allclose(back[..., 2:-2, 2:-2], rgb[..., 2:-2, 2:-2], atol=1e-6), pat


def test_spectral_data_files_have_sources():
    for name in ("cfa_nikon_d5100_npl.csv", "silicon_green2008.csv"):
        text = (Path(load_preset("ovt").filters_path).parent / name).read_text()
        assert text.startswith("#") and "Source" in text
    wl, names, vals = read_spectral_csv(load_preset("ovt").filters_path)
    assert names == ["r", "g", "b"] and np.allclose(vals.max(axis=0), 1.0)
    qe = spectral_qe("ovt", WL)
    assert qe.shape == (3, 31) and qe.max() == pytest.approx(0.6, rel=1e-6) and qe.min() >= 0
    # green peaks in the middle, red at long and blue at short wavelengths
    assert WL[int(np.argmax(qe[0]))] > 570 and 500 < WL[int(np.argmax(qe[1]))] < 570 and WL[int(np.argmax(qe[2]))] < 490


def test_ideal_electrons_monochromatic_hand_count():
    p = load_preset("ovt")
    H = torch.zeros(1, 31, 4, 4, dtype=torch.float64)
    H[0, 15] = 2e-6                                        # J m^-2 nm^-1 in the 550 nm band only
    e = ideal_electrons(H, p, WL, mosaic_output=False)
    qe = spectral_qe(p, [550.0])[:, 0]
    photons = 2e-6 * 10.0 * (2.8e-6) ** 2 * 550e-9 / (sc.h * sc.c)   # 10 nm band, scipy's h and c
    assert torch.allclose(e[0, :, 0, 0], torch.tensor(qe * photons), rtol=1e-9)
    m = ideal_electrons(H, p, WL)
    assert m.shape == (1, 1, 4, 4)
    assert float(m[0, 0, 0, 1]) == pytest.approx(qe[0] * photons)    # GRBG: (0, 1) is red
    spd = ideal_electrons(H, p, WL, photodiode="spd")
    assert torch.allclose(spd * 100, m)
    assert np.allclose(band_widths_nm(WL), 10.0)


def test_silicon_qe_model_hand_values():
    # 700 nm, no reflection: 1 - exp(-alpha d), alpha = 1890 /cm (Green 2008), d = 3 um
    assert silicon_qe([700.0], 3e-6, reflectance=0.0)[0] == pytest.approx(1 - math.exp(-1890e2 * 3e-6))
    # 550 nm, bare silicon Fresnel loss with n = 4.077, k = alpha lambda / 4 pi
    k = 6390e2 * 550e-9 / (4 * math.pi)
    R = ((4.077 - 1) ** 2 + k ** 2) / ((4.077 + 1) ** 2 + k ** 2)
    assert silicon_qe([550.0], 3e-6)[0] == pytest.approx((1 - R) * (1 - math.exp(-6390e2 * 3e-6)), rel=1e-9)
    qe = silicon_qe(WL, 3e-6, reflectance=0.05)
    assert np.all(np.diff(qe[15:]) < 0)                   # thin silicon loses red response
    with pytest.raises(ValueError, match="wavelengths_nm"):
        silicon_qe([300.0])


# ------------------------------------------------------------------------------------------------- noise
@pytest.mark.parametrize("backend", ["numba", "torch"])
def test_poisson_shot_noise_chi_square(backend):
    g = _gen(1)
    mu = torch.full((200000,), 4.0, dtype=torch.float64)
    s = shot_noise(mu, g, 1000.0, backend=backend).numpy().astype(int)
    ks = np.arange(0, 13)
    obs = np.array([(s == k).sum() for k in ks[:-1]] + [(s >= ks[-1]).sum()])
    pmf = st.poisson.pmf(ks[:-1], 4.0)
    exp = np.append(pmf, 1 - pmf.sum()) * s.size
    chi2 = ((obs - exp) ** 2 / exp).sum()
    assert chi2 < st.chi2.ppf(0.999, len(ks) - 1)


@pytest.mark.parametrize("backend", ["numba", "torch"])
def test_gaussian_branch_moments_and_switch(backend):
    g = _gen(2)
    mu = torch.cat([torch.full((100000,), 5000.0), torch.full((100000,), 50.0)]).double()
    s = shot_noise(mu, g, 1000.0, backend=backend)
    big, small = s[:100000], s[100000:]
    assert torch.equal(s, s.round())
    assert float(big.mean()) == pytest.approx(5000.0, abs=4 * math.sqrt(5000 / 1e5))
    assert float(big.var()) == pytest.approx(5000.0, rel=0.02)
    assert float(small.var()) == pytest.approx(50.0, rel=0.03)
    # exact Poisson everywhere when the switch is infinite
    s2 = shot_noise(mu[:10], _gen(2), float("inf"))
    assert torch.equal(s2, s2.round())


def test_determinism_and_seed_dependence():
    p = load_preset("ovt")
    x = _flat(300.0, p, (2, 1, 16, 16))
    a = simulate_split_pixel(x, x, p, [550.0], T_S, T_L, _gen(5), bandwidths_nm=[1.0])
    b = simulate_split_pixel(x, x, p, [550.0], T_S, T_L, _gen(5), bandwidths_nm=[1.0])
    c = simulate_split_pixel(x, x, p, [550.0], T_S, T_L, _gen(6), bandwidths_nm=[1.0])
    for k in CAPTURES:
        assert torch.equal(a[k], b[k])
    assert not torch.equal(a["lpd_hcg"], c["lpd_hcg"])


def test_fixed_pattern_reproducible_and_scaled():
    p = load_preset("imx490")
    f1 = fixed_pattern(p, 256, 256, dtype=torch.float64)
    f2 = fixed_pattern(p, 256, 256, dtype=torch.float32)
    assert torch.allclose(f1["lpd_gain"].float(), f2["lpd_gain"])
    assert float(f1["lpd_gain"].std()) == pytest.approx(0.007, rel=0.03)
    assert float(f1["lpd_gain"].mean()) == pytest.approx(1.0, abs=1e-3)
    assert not torch.equal(f1["lpd_gain"], f1["spd_gain"])
    assert torch.all(f1["lpd_offset_e"] == 0)                           # DSNU 0 in this preset
    # PRNU shows in the spatial statistics of a bright, noisy flat field: var = mu + (prnu mu)^2 (+ read, quant.)
    x = torch.full((1, 1, 256, 256), 1.0, dtype=torch.float64)
    w = electron_weights(p, [550.0], "lpd", bandwidths_nm=[1.0])[1, 0].item()
    out = simulate_split_pixel(x * (50000 / w), x * 0, p, [550.0], T_S, T_L, _gen(3), bandwidths_nm=[1.0])
    green = CFAPattern.GRBG.index_map(256, 256) == 1
    e = out["lpd_lcg_e"][0, 0][green].double()
    expected = 50000 + (0.007 * 50000) ** 2 + 1.0 + (1 / p.system_gain("lpd_lcg")) ** 2 / 12
    assert float(e.var()) == pytest.approx(expected, rel=0.05)


# ------------------------------------------------------------------------------------ signal chain checks
def test_noise_free_chain_is_exact():
    p = load_preset("ovt")
    levels = torch.tensor([0.0, 10.0, 1000.0, 5000.0, 20000.0], dtype=torch.float64)
    x = torch.stack([_flat(float(v), p, (1, 4, 4))[..., :, :] for v in levels])   # (5, 1, 4, 4)
    out = simulate_split_pixel(x, x * (T_L / T_S), p, [550.0], T_S, T_L, noise=False, bandwidths_nm=[1.0])
    g = CFAPattern.GRBG.index_map(4, 4) == 1
    for cap in ("lpd_hcg", "lpd_lcg"):
        K = p.system_gain(cap)
        e = levels + 25.6 * T_S
        clip = p.saturation_capacity_e(cap)
        dn_expected = torch.round(64 + torch.clamp(e, max=clip) * K).clamp(max=4095)
        assert torch.equal(out[cap][:, 0][:, g][:, 0], dn_expected)
        # input-referred (dark signal removed) within half a DN of the photo-signal below the clip point
        ok = e < clip
        assert torch.all((out[f"{cap}_e"][:, 0][:, g][:, 0] - levels)[ok].abs() <= 0.5 / K + 1e-9)
    # SPD fed with the long-exposure equivalent of the same radiance: its input-referred value is the LPD signal
    e_spd = levels * (T_L / T_S) / 100 + 4.2 * T_L
    assert torch.allclose(out["spd_e"][:, 0][:, g][:, 0],
                          (torch.round(64 + e_spd.clamp(max=7900) * p.system_gain("spd")).sub(64)
                           / p.system_gain("spd") - 4.2 * T_L) * 100 * T_S / T_L)
    ref = levels
    mid = levels < 20000
    assert torch.all((out["spd_e"][:, 0][:, g][:, 0] - ref)[mid].abs() <= 0.5 / p.system_gain("spd") * 100 * T_S / T_L)


def test_saturation_flag_threshold():
    p = load_preset("ovt")
    clip = p.saturation_capacity_e("lpd_hcg")
    levels = torch.tensor([0.94, 0.949, 0.951, 0.96, 1.2], dtype=torch.float64) * clip - 25.6 * T_S
    x = torch.stack([_flat(float(v), p, (1, 2, 2)) for v in levels])
    out = simulate_split_pixel(x, x * 0, p, [550.0], T_S, T_L, noise=False, bandwidths_nm=[1.0])
    flag = out["saturated"][:, 0, 0, 0]                     # hcg channel at a green pixel
    assert flag.tolist() == [False, False, True, True, True]
    assert not out["saturated"][:, 1].any()                  # LCG far from its swing
    assert out["saturated"].shape == (5, 3, 2, 2) and out["saturated"].dtype == torch.bool


# ---------------------------------------------------------------------------------------- extreme inputs
def test_all_dark_input():
    p = load_preset("ovt")
    x = torch.zeros(2, 31, 96, 96)
    out = simulate_split_pixel(x, x, p, WL, T_S, T_L, _gen(0))
    for cap in CAPTURES:
        assert torch.isfinite(out[cap]).all() and torch.isfinite(out[f"{cap}_e"]).all()
        assert abs(float(out[cap].mean()) - 64) < 1.0
    assert not out["saturated"].any()
    # input-referred values have the mean dark signal removed: they average to 0 e-, while the raw HCG mean sits
    # 25.6 e-/s x 4 ms = 0.10 e- x K above the black level
    for cap in CAPTURES:
        assert float(out[f"{cap}_e"].mean()) == pytest.approx(0.0, abs=0.05 if cap == "lpd_hcg" else 0.5)
    assert float(out["lpd_hcg"].mean()) - 64 == pytest.approx(25.6 * T_S * p.system_gain("lpd_hcg"), abs=0.03)


@pytest.mark.parametrize("scale", [1e6, 1e30])
def test_sun_in_view_clips_cleanly(scale):
    p = load_preset("ovt")
    x = torch.full((1, 31, 8, 8), scale)
    out = simulate_split_pixel(x, x, p, WL, T_S, T_L, _gen(0))
    for cap in CAPTURES:
        assert torch.isfinite(out[cap]).all() and torch.isfinite(out[f"{cap}_e"]).all()
        # photodiode charge stops at the full well and read noise is added after it: where the full well equals
        # the voltage swing (LCG, SPD) the code sits within 5 read-noise sigma of the top; HCG clips at its swing
        sigma_dn = p.captures[cap].read_noise_e * p.system_gain(cap)
        assert float(out[cap].min()) >= 4095 - max(5 * sigma_dn, 0.5) and float(out[cap].max()) == 4095
    assert torch.all(out["lpd_hcg"] == 4095)
    assert out["saturated"].all()
    assert float(out["lpd_lcg_e"].mean()) == pytest.approx(22000.0, rel=1e-3)


def test_dynamic_range_1e6():
    """A 10^6 : 1 scene: 0.2 e- and 2e5 e- (LPD-equivalent); HCG reads the dark side, the SPD the bright side."""
    p = load_preset("ovt")
    dark, bright = 0.2, 2e5
    x = _flat(1.0, p, (1, 1, 64, 128), dtype=torch.float32)
    x[..., :64] *= dark
    x[..., 64:] *= bright
    out = simulate_split_pixel(x, x * (T_L / T_S), p, [550.0], T_S, T_L, _gen(9), bandwidths_nm=[1.0])
    g = (CFAPattern.GRBG.index_map(64, 128) == 1)
    left, right = g.clone(), g.clone()
    left[:, 64:] = False
    right[:, :64] = False
    for k in CAPTURES:
        assert torch.isfinite(out[k]).all() and torch.isfinite(out[f"{k}_e"]).all()
    hcg = out["lpd_hcg_e"][0, 0]
    assert float(hcg[left].mean()) == pytest.approx(dark, abs=0.05)
    assert out["saturated"][0, 0][right].all() and out["saturated"][0, 1][right].all()
    assert not out["saturated"][0, 2][right].any()
    spd = out["spd_e"][0, 0]
    assert float(spd[right].mean()) == pytest.approx(bright, rel=0.01)


def test_float32_and_float64_agree():
    p = load_preset("ovt")
    x64 = torch.rand(1, 31, 8, 8, dtype=torch.float64) * 1e-6
    o64 = simulate_split_pixel(x64, x64, p, WL, T_S, T_L, noise=False)
    o32 = simulate_split_pixel(x64.float(), x64.float(), p, WL, T_S, T_L, noise=False)
    for k in CAPTURES:
        assert o64[k].dtype == torch.float64 and o32[k].dtype == torch.float32
        assert (o64[k] - o32[k].double()).abs().max() <= 1.0          # at most one code from rounding ties
    on = simulate_split_pixel(x64.float(), x64.float(), p, WL, T_S, T_L, _gen(1))
    assert all(on[k].dtype == torch.float32 for k in CAPTURES)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -1e-9])
@pytest.mark.parametrize("which", ["lpd_radiant_exposure", "spd_radiant_exposure"])
def test_bad_values_raise_naming_argument(bad, which):
    p = load_preset("ovt")
    good = torch.ones(1, 31, 4, 4) * 1e-7
    badt = good.clone()
    badt[0, 3, 1, 2] = bad
    args = (badt, good) if which == "lpd_radiant_exposure" else (good, badt)
    with pytest.raises(ValueError, match=which):
        simulate_split_pixel(*args, p, WL, T_S, T_L, _gen(0))


def test_argument_checks():
    p = load_preset("ovt")
    x = torch.ones(1, 31, 4, 4) * 1e-7
    with pytest.raises(ValueError, match="generator"):
        simulate_split_pixel(x, x, p, WL, T_S, T_L)
    with pytest.raises(ValueError, match="wavelengths_nm"):
        simulate_split_pixel(x, x, p, WL[:-1], T_S, T_L, _gen(0))
    with pytest.raises(ValueError, match="spd_radiant_exposure"):
        simulate_split_pixel(x, x[..., :2], p, WL, T_S, T_L, _gen(0))
    with pytest.raises(ValueError, match="exposure_short_s"):
        simulate_split_pixel(x, x, p, WL, -1.0, T_L, _gen(0))
    with pytest.raises(ValueError, match="bandwidths_nm"):
        simulate_split_pixel(x[:, :1], x[:, :1], p, [550.0], T_S, T_L, _gen(0))


def test_per_sample_exposure_and_module():
    p = load_preset("ovt")
    x = torch.zeros(2, 31, 4, 4, dtype=torch.float64)
    t = torch.tensor([1.0, 3.0], dtype=torch.float64)                # long exposures -> dark current differs
    out = simulate_split_pixel(x, x, p, WL, t, 2 * t, noise=False)
    e = (out["lpd_hcg"][:, 0, 0, 0] - 64) / p.system_gain("lpd_hcg")       # raw signal holds the dark current
    assert e.tolist() == pytest.approx([25.6, 76.8], abs=0.7)
    assert out["lpd_hcg_e"][:, 0, 0, 0].abs().max() <= 0.7                 # input-referred: dark removed
    m = SplitPixelSensor("ovt", WL, noise=False)
    out2 = m(x, x, t, 2 * t)
    for k in CAPTURES:
        assert torch.equal(out[k], out2[k])


def test_electron_entry_point_matches_radiant_path():
    from lfmbench.sensor import simulate_split_pixel_electrons

    p = load_preset("imx490")
    x = torch.rand(2, 31, 8, 8, dtype=torch.float64) * 1e-6
    a = simulate_split_pixel(x, 2.7 * x, p, WL, T_S, T_L, _gen(4))
    le = ideal_electrons(x, p, WL, "lpd")
    se = ideal_electrons(2.7 * x, p, WL, "spd")
    b = simulate_split_pixel_electrons(le, se, p, T_S, T_L, _gen(4))
    for k in list(CAPTURES) + ["saturated"]:
        assert torch.equal(a[k], b[k])
    bad = le.clone()
    bad[0, 0, 0, 0] = -1.0
    with pytest.raises(ValueError, match="lpd_electrons"):
        simulate_split_pixel_electrons(bad, se, p, T_S, T_L, _gen(4))
    with pytest.raises(ValueError, match=r"\(\*, 1, H, W\)"):
        simulate_split_pixel_electrons(x, x, p, T_S, T_L, _gen(4))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_compiled_cpu_chain_is_bit_identical_to_the_torch_chain(dtype):
    """The compiled CPU chain (backend "numba": one pass per photodiode, one per capture) against the torch
    element-wise chain, output for output, bit for bit: PRNU and DSNU on (full-frame and per-sample maps) and off,
    noise on and off, one generator or one per sample, means from 0 through saturation to past the input cap
    (1e9 e-), per-frame exposures."""
    from dataclasses import replace

    from lfmbench.sensor import simulate_split_pixel_electrons

    g = _gen(7)
    B, F, H, W = 3, 2, 10, 12
    le = torch.rand(B, F, 1, H, W, generator=g, dtype=dtype) ** 6 * 4e4
    le[0, 0, 0, :2, :2] = 1e9
    le[1, 1, 0, 3] = 0.0
    se = le * torch.rand(le.shape, generator=g, dtype=dtype) * 0.05
    t_s = torch.tensor([[4e-3, 3e-3]] * B, dtype=torch.float64)
    ovt = load_preset("ovt")
    fpn_preset = replace(ovt, photodiodes={k: replace(v, prnu=0.02, dsnu_e=1.5) for k, v in ovt.photodiodes.items()})
    full = fixed_pattern(fpn_preset, 16, 20, dtype=dtype)
    per_sample = {k: torch.stack([v[2 * b:2 * b + H, 4:4 + W] for b in range(B)])[:, None, None]
                  for k, v in full.items()}                                         # (B, 1, 1, H, W)
    n_checked = 0
    for preset, fpn in ((ovt, None), (fpn_preset, None), (fpn_preset, per_sample)):
        for noise in (True, False):
            for per_sample_gens in (True, False):
                outs = []
                for backend in ("torch", "numba"):
                    gens = [_gen(10 + b) for b in range(B)] if per_sample_gens else _gen(3)
                    outs.append(simulate_split_pixel_electrons(le, se, preset, t_s, T_L, gens, noise, fpn,
                                                               backend=backend))
                ref, got = outs
                assert set(ref) == set(got)
                for k in ref:
                    assert got[k].dtype == ref[k].dtype and torch.equal(got[k], ref[k]), (k, noise, per_sample_gens)
                n_checked += 1
    assert n_checked == 12 and ref["saturated"].any() and not ref["saturated"].all()
    one, three = (simulate_split_pixel_electrons(le, se, fpn_preset, t_s, T_L, [_gen(10 + b) for b in range(B)],
                                                 threads=n) for n in (1, 3))
    assert all(torch.equal(one[k], three[k]) for k in one)              # samples in parallel threads: same result
    with pytest.raises(ValueError, match="backend"):
        simulate_split_pixel_electrons(le, se, ovt, T_S, T_L, _gen(0), backend="fused")
    with pytest.raises(ValueError, match="backend='numba'"):
        simulate_split_pixel_electrons(torch.ones(1, 1, 2, 2).half(), torch.ones(1, 1, 2, 2).half(), ovt, T_S, T_L,
                                       _gen(0), backend="numba")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_cuda_matches_cpu():
    from lfmbench.sensor.optics import airy_kernel, apply_psf

    p = load_preset("imx490")
    x = torch.rand(2, 31, 32, 32, dtype=torch.float64) * 1e-6
    cpu = simulate_split_pixel(x, x, p, WL, T_S, T_L, noise=False)
    gpu = simulate_split_pixel(x.cuda(), x.cuda(), p, WL, T_S, T_L, noise=False)
    for k in CAPTURES:
        assert gpu[k].device.type == "cuda"
        assert (gpu[k].cpu() - cpu[k]).abs().max() <= 1.0
    g = torch.Generator(device="cuda").manual_seed(0)
    noisy = simulate_split_pixel(x.cuda().float(), x.cuda().float(), p, WL, T_S, T_L, generator=g)
    assert all(torch.isfinite(noisy[k]).all() for k in CAPTURES)
    with pytest.raises(ValueError, match="generator"):
        simulate_split_pixel(x.cuda(), x.cuda(), p, WL, T_S, T_L, generator=_gen(0))
    k = airy_kernel(WL, 5.73, 2.8e-6, 4, dtype=torch.float64)
    assert torch.allclose(apply_psf(x.cuda(), k.cuda()).cpu(), apply_psf(x, k), atol=1e-12)
    assert torch.allclose(airy_kernel(WL, 5.73, 2.8e-6, 4, dtype=torch.float64, device="cuda").cpu(), k, atol=1e-9)


def test_preset_edits_are_picked_up_and_inf_switch_allowed(tmp_path):
    d = _ovt_dict()
    d["spectral"]["filters"] = str(load_preset("ovt").filters_path)
    d["shot_noise_gaussian_above_e"] = float("inf")
    f = tmp_path / "p.yaml"
    f.write_text(yaml.safe_dump(d))
    assert load_preset(f).shot_noise_gaussian_above_e == float("inf")
    d["captures"]["spd"]["read_noise_e"] = 1.5
    f.write_text(yaml.safe_dump(d))
    import os
    os.utime(f, ns=(f.stat().st_atime_ns, f.stat().st_mtime_ns + 10**9))
    assert load_preset(f).captures["spd"].read_noise_e == 1.5
    with pytest.raises(TypeError):
        load_preset(f).captures["spd"] = None            # read-only mapping


def test_preset_pickles_for_dataloader_workers():
    import copy
    import pickle

    p = load_preset("imx490")
    q = pickle.loads(pickle.dumps(p))
    assert q == p and q.captures["spd"] == p.captures["spd"] and q.system_gain("lpd_hcg") == p.system_gain("lpd_hcg")
    assert copy.deepcopy(p) == p
    assert hash(q) == hash(p) and len({p, q, load_preset("ovt")}) == 2
    m = pickle.loads(pickle.dumps(SplitPixelSensor("ovt", WL)))
    assert m.preset.name == "ovt"


def test_capture_inputs_are_checked_by_the_one_tensor_check():
    """The LPD/SPD pair and radiometric inputs go through lfmbench.check.check_tensor / check_same_shape: a
    non-tensor is a TypeError naming the argument, a dtype or shape mismatch a ValueError naming both."""
    p = load_preset("ovt")
    x = torch.ones(1, 1, 4, 4)
    with pytest.raises(ValueError, match=r"^lpd_electrons and spd_electrons must have the same dtype"):
        simulate_split_pixel_electrons(x, x.double(), p, T_S, T_L, noise=False)
    with pytest.raises(ValueError, match=r"^lpd_electrons and spd_electrons must have the same shape"):
        simulate_split_pixel_electrons(x, x[..., :2], p, T_S, T_L, noise=False)
    with pytest.raises(TypeError, match=r"^spd_electrons must be a torch.Tensor, got list$"):
        simulate_split_pixel_electrons(x, [1.0], p, T_S, T_L, noise=False)
    with pytest.raises(ValueError, match=r"^lpd_electrons must have at least 3 dims \(\*, C, H, W\)"):
        simulate_split_pixel_electrons(x[0, 0], x[0, 0], p, T_S, T_L, noise=False)
