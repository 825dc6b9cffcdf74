"""EMVA 1288 photon-transfer test of the split-pixel sensor model.

Method of EMVA Standard 1288 Release 4.0 Linear (2021), linear camera model and photon-transfer method: pairs of
flat fields at a series of irradiances (fixed exposure time), mean from the average of the pair, temporal variance
from half the variance of the difference of the pair (removes fixed-pattern noise), dark mean/variance from a dark
pair;

- system gain K (DN/e-): slope of sigma_y^2 - sigma_y.dark^2 against mu_y - mu_y.dark, fitted from the dark level
  up to 70 % of saturation (linear model: sigma_y^2 = K^2 sigma_d^2 + sigma_q^2 + K (mu_y - mu_y.dark));
- temporal dark noise sigma_d = sqrt(sigma_y.dark^2 - sigma_q^2) / K with sigma_q^2 = 1/12 DN^2; it includes the
  dark-current shot noise, so the configured read noise is compared with sqrt(read^2 + dark_current * t_exp).
  With DSNU = 0 every pixel sits at the same place on the code grid, and for sigma_y.dark < ~1 DN the 1/12 DN^2
  rule is biased (-4 to -8 % for the SPD here). We therefore also invert the exact variance of a rounded Gaussian,
  Var[round(c + sigma Z)] (c = offset of the dark mean from the nearest code), for sigma, and test that value;
  the plain EMVA value is tested with a looser tolerance;
- saturation capacity mu_e.sat = (mu_y.sat - mu_y.dark) / K, mu_y.sat the mean at the maximum of the variance. By
  this definition mu_e.sat lies 2-4 % below the clip point min(full well, swing / conversion gain): the variance
  falls once the upper tail of the shot-noise distribution clips. The expected position of the maximum is computed
  independently here by Gauss-Hermite quadrature of Y = min(min(X, FW) + R, S), X ~ N(mu, mu), R ~ N(0, read^2),
  and the measured value is compared with it and with the configured clip point;
- responsivity R = K eta (DN per photon), eta from the shipped spectral curve at the test wavelength, photons
  counted with CODATA h and c taken from scipy (independent of lfmbench.constants).

The analysis is written here from the standard, independently of lfmbench's simulation code.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.constants as sc
import torch
from scipy.optimize import brentq
from scipy.stats import norm

from lfmbench.sensor import electron_weights, load_preset, read_spectral_csv, simulate_split_pixel

WL_NM = 530.0          # monochromatic test light (EMVA 1288 uses narrow-band light)
BAND_NM = 1.0          # radiant exposure given per nm over a 1 nm band
SIZE = 128             # flat-field side in pixels (8192 green pixels per frame)
T_SHORT = 1e-3         # s, LPD exposure
T_LONG = 1e-3          # s, SPD exposure (equal, so dark current stays small for both)


def _flat_field_pairs(preset, capture: str, levels_e: np.ndarray, seed: int, counter: bool = False) -> np.ndarray:
    """Simulate two frames per level; returns DN of the green pixels, shape (2, L, N)."""
    pd = preset.captures[capture].photodiode
    # radiant exposure that gives the wanted mean electrons on a green pixel; computed with scipy's constants
    wl_csv, _, vals = read_spectral_csv(preset.filters_path)
    eta = preset.peak_qe * np.interp(WL_NM, wl_csv, vals[:, 1])
    photons_per_j = (WL_NM * 1e-9) / (sc.h * sc.c)
    e_per_unit = eta * preset.pixel_pitch_m ** 2 * preset.photodiodes[pd].fill_factor * BAND_NM * photons_per_j
    H = torch.as_tensor(levels_e / e_per_unit, dtype=torch.float32)
    x = H.reshape(1, -1, 1, 1, 1).expand(2, -1, 1, SIZE, SIZE).contiguous()
    zero = torch.zeros_like(x)
    lpd, spd = (x, zero) if pd == "lpd" else (zero, x)
    if counter:  # counter-based noise: one seed per frame of the pair (the leading, sample dimension)
        out = simulate_split_pixel(lpd, spd, preset, [WL_NM], T_SHORT, T_LONG, bandwidths_nm=[BAND_NM],
                                   seeds=torch.tensor([seed, seed + 1]))
    else:
        g = torch.Generator().manual_seed(seed)
        out = simulate_split_pixel(lpd, spd, preset, [WL_NM], T_SHORT, T_LONG, generator=g, bandwidths_nm=[BAND_NM])
    dn = out[capture][:, :, 0].numpy()                                   # (2, L, H, W)
    green = preset.cfa.index_map(SIZE, SIZE).numpy() == 1
    return dn[..., green], eta


def rounded_gaussian_variance(sigma: float, c: float) -> float:
    """Exact variance (DN^2) of round(c + sigma Z), Z ~ N(0, 1), for an offset c in [-0.5, 0.5] DN."""
    k = np.arange(-60, 61, dtype=np.float64)
    p = norm.cdf((k + 0.5 - c) / sigma) - norm.cdf((k - 0.5 - c) / sigma)
    m = float((k * p).sum())
    return float((k * k * p).sum() - m * m)


def photon_transfer(y: np.ndarray) -> dict:
    """EMVA 1288 R4.0 photon-transfer analysis of (2, L, N) DN pairs; level 0 must be dark."""
    ya, yb = y[0].astype(np.float64), y[1].astype(np.float64)
    mu = 0.5 * (ya.mean(-1) + yb.mean(-1))
    d = ya - yb
    var = 0.5 * ((d - d.mean(-1, keepdims=True)) ** 2).mean(-1)
    mu_dark, var_dark = mu[0], var[0]
    i_sat = int(np.argmax(var))
    mu_sat = mu[i_sat]
    sel = (np.arange(len(mu)) > 0) & (mu - mu_dark <= 0.7 * (mu_sat - mu_dark))
    K, _ = np.polyfit(mu[sel] - mu_dark, var[sel] - var_dark, 1)
    sigma_d = np.sqrt(max(var_dark - 1.0 / 12.0, 0.0)) / K
    c = float(mu_dark - np.round(mu_dark))
    sigma_y_exact = brentq(lambda s: rounded_gaussian_variance(s, c) - var_dark, 1e-3, 50.0)
    return {"K": K, "sigma_d": sigma_d, "sigma_d_exact": sigma_y_exact / K, "mu_e_sat": (mu_sat - mu_dark) / K,
            "mu": mu, "var": var,
            "mu_dark": mu_dark, "fit": sel}


def expected_saturation_e(full_well: float, clip_e: float, read_e: float) -> float:
    """Mean electrons at the variance maximum of Y = min(min(X, FW) + R, S) (see module docstring), in e-."""
    xn, xw = np.polynomial.hermite_e.hermegauss(200)
    rn, rw = np.polynomial.hermite_e.hermegauss(40)
    w = (xw / xw.sum())[:, None] * (rw / rw.sum())[None, :]
    s = min(full_well, clip_e)
    mus = np.linspace(0.85 * s, 1.02 * s, 1701)
    x = mus[:, None, None] + np.sqrt(mus)[:, None, None] * xn[None, :, None]
    y = np.minimum(np.minimum(x, full_well) + read_e * rn[None, None, :], clip_e)
    m = (y * w).sum((1, 2))
    v = (y * y * w).sum((1, 2)) - m * m
    return float(m[np.argmax(v)])


# tolerances (relative): about 3 standard deviations of the estimates over seeds (K: 0.9 %, sigma_d: 1.3 %,
# mu_e.sat: 1.5 %; 6 seeds at SIZE = 128, see docs/benchmarks/sensor.md); the plain 1/12 DN^2 rule is biased by -4 to -8 % for
# the SPD (sigma_y.dark = 0.42 DN).
TOL = {"K": 0.03, "sigma_d": 0.05, "sigma_d_emva": 0.12, "sat": 0.05, "R": 0.03}


@pytest.mark.parametrize("backend", ["numba", "torch", "counter-numba"])
@pytest.mark.parametrize("capture", ["lpd_hcg", "lpd_lcg", "spd"])
def test_photon_transfer_recovers_ovt_parameters(capture, backend, monkeypatch):
    # every shot-noise sampler must pass EMVA 1288: the compiled CPU one, torch.poisson (which CUDA uses), and
    # the counter-based streams (lfmbench.sensor.counter_noise; its torch chain gives the compiled chain's numbers:
    # tests/sensor/test_counter_noise.py)
    import lfmbench.sensor.poisson

    monkeypatch.setattr(lfmbench.sensor.poisson, "available", lambda: backend.endswith("numba"))
    preset = load_preset("ovt")
    sat = preset.saturation_capacity_e(capture)
    levels = np.concatenate([[0.0], np.linspace(0.02, 0.7, 20) * sat, np.linspace(0.71, 1.15, 45) * sat])
    y, eta = _flat_field_pairs(preset, capture, levels, seed=1288, counter=backend.startswith("counter"))
    res = photon_transfer(y)

    spec = preset.captures[capture]
    pd = preset.photodiodes[spec.photodiode]
    t_exp = T_SHORT if spec.photodiode == "lpd" else T_LONG
    # configured values, computed here from the preset fields (not from the model's helper methods)
    K_true = spec.conversion_gain_v_per_e * (2 ** preset.adc_bits - 1 - preset.black_level_dn) / spec.voltage_swing_v
    sigma_d_true = np.sqrt(spec.read_noise_e ** 2 + pd.dark_current_e_per_s * t_exp)
    clip_e = spec.voltage_swing_v / spec.conversion_gain_v_per_e
    sat_true = min(pd.full_well_e, clip_e)
    sat_emva = expected_saturation_e(pd.full_well_e, clip_e, spec.read_noise_e)

    assert res["fit"].sum() >= 15
    assert res["K"] == pytest.approx(K_true, rel=TOL["K"])
    assert res["sigma_d_exact"] == pytest.approx(sigma_d_true, rel=TOL["sigma_d"])
    assert res["sigma_d"] == pytest.approx(sigma_d_true, rel=TOL["sigma_d_emva"])
    assert res["mu_e_sat"] == pytest.approx(sat_emva, rel=TOL["sat"])
    # the variance maximum lies below the configured clip point, within 8 % of it
    assert 0.92 * sat_true <= res["mu_e_sat"] <= sat_true

    # responsivity R = K eta: slope of mu_y - mu_y.dark against the photon count (linear range)
    photons = levels / eta
    sel = res["fit"]
    R = np.polyfit(photons[sel], res["mu"][sel] - res["mu_dark"], 1)[0]
    assert R == pytest.approx(K_true * eta, rel=TOL["R"])


def test_photon_transfer_matches_model_helpers():
    """The preset's helper methods agree with the EMVA quantities computed from the raw fields."""
    preset = load_preset("ovt")
    for cap in ("lpd_hcg", "lpd_lcg", "spd"):
        spec = preset.captures[cap]
        assert preset.system_gain(cap) == pytest.approx(
            spec.conversion_gain_v_per_e * (4095 - 64) / spec.voltage_swing_v, rel=1e-12)
    assert preset.saturation_capacity_e("lpd_hcg") == pytest.approx(1.078 / 200e-6)
    assert preset.saturation_capacity_e("lpd_lcg") == pytest.approx(22000.0)
    assert preset.saturation_capacity_e("spd") == pytest.approx(7900.0, rel=1e-3)
    # and the electron weights reproduce the photon count computed with scipy's constants
    w = electron_weights(preset, [WL_NM], "lpd", bandwidths_nm=[BAND_NM])
    wl_csv, _, vals = read_spectral_csv(preset.filters_path)
    eta_g = preset.peak_qe * np.interp(WL_NM, wl_csv, vals[:, 1])
    expected = eta_g * (2.8e-6) ** 2 * 1.0 * BAND_NM * (WL_NM * 1e-9) / (sc.h * sc.c)
    assert float(w[1, 0]) == pytest.approx(expected, rel=1e-9)


def test_photon_transfer_imx490_prnu_removed_by_difference():
    """With 0.7 % PRNU (imx490) the pair difference still gives the shot-noise-limited K of the LCG capture."""
    preset = load_preset("imx490")
    cap = "lpd_lcg"
    sat = preset.saturation_capacity_e(cap)
    levels = np.concatenate([[0.0], np.linspace(0.02, 0.7, 20) * sat, np.linspace(0.75, 1.1, 12) * sat])
    y, _ = _flat_field_pairs(preset, cap, levels, seed=7)
    res = photon_transfer(y)
    spec = preset.captures[cap]
    K_true = spec.conversion_gain_v_per_e * (4095 - preset.black_level_dn) / spec.voltage_swing_v
    assert res["K"] == pytest.approx(K_true, rel=TOL["K"])
    # the spatial variance of one frame, by contrast, contains PRNU: (0.007 mu_e)^2 K^2 at 70 % of full well
    ya = y[0, 15].astype(np.float64)
    mu_e = levels[15]
    spatial = ya.var()
    temporal = res["var"][15]
    expected_extra = (0.007 * mu_e * K_true) ** 2
    assert spatial - temporal == pytest.approx(expected_extra, rel=0.25)


# ------------------------------------------------------------------ every capture of every other architecture
def _plan_flat_field_pairs(preset, capture: str, levels_e: np.ndarray, seed: int):
    """As :func:`_flat_field_pairs` through the capture-plan chain: the capture's exposure at each level (the
    other exposures dark), (2, L, N) DN of the green pixels, and the green QE."""
    from lfmbench.sensor import ideal_electrons, simulate_plan_electrons
    from lfmbench.sensor.plan import resolve_windows, total_length_s

    pd = preset.captures[capture].photodiode
    wl_csv, _, vals = read_spectral_csv(preset.filters_path)
    eta = preset.peak_qe * np.interp(WL_NM, wl_csv, vals[:, 1])
    photons_per_j = (WL_NM * 1e-9) / (sc.h * sc.c)
    e_per_unit = eta * preset.pixel_pitch_m ** 2 * preset.photodiodes[pd].fill_factor * BAND_NM * photons_per_j
    H = torch.as_tensor(levels_e / e_per_unit, dtype=torch.float32).reshape(1, -1, 1, 1, 1).expand(
        2, -1, 1, SIZE, SIZE).contiguous()
    timing = {"short_exposure_s": 0.004, "long_exposure_s": 1 / 90}
    key = next(k for k, caps in preset.exposures.items() if capture in caps)
    e = ideal_electrons(H, preset, [WL_NM], pd, [BAND_NM])
    mean_e = {k: (e if k == key else torch.zeros_like(e)) for k in preset.exposures}
    t = {k: total_length_s(resolve_windows(preset.captures[k].exposure, timing)) for k in preset.exposures}
    out = simulate_plan_electrons(mean_e, preset, t, torch.Generator().manual_seed(seed))
    green = preset.cfa.index_map(SIZE, SIZE).numpy() == 1
    return out[capture][:, :, 0].numpy()[..., green], eta, t[key]


@pytest.mark.parametrize("name, capture", [("lofic", "hcg"), ("lofic", "lcg"), ("staggered", "long"),
                                           ("staggered", "short"), ("chopped", "chopped"), ("single", "main")])
def test_photon_transfer_of_every_architecture(name, capture):
    """EMVA 1288 photon transfer of each capture of the LOFIC, staggered, chopped and single presets recovers the
    configured system gain, dark noise (read + dark-current shot noise over the capture's own integration time),
    saturation capacity and responsivity (PRNU 0.5 % removed by the pair difference)."""
    preset = load_preset(name)
    spec = preset.captures[capture]
    pd = preset.photodiodes[spec.photodiode]
    clip_e = spec.voltage_swing_v / spec.conversion_gain_v_per_e
    sat_true = min(pd.full_well_e, clip_e)
    levels = np.concatenate([[0.0], np.linspace(0.02, 0.7, 20) * sat_true, np.linspace(0.71, 1.15, 45) * sat_true])
    y, eta, t_exp = _plan_flat_field_pairs(preset, capture, levels, seed=1288)
    res = photon_transfer(y)
    K_true = spec.conversion_gain_v_per_e * (2 ** preset.adc_bits - 1 - preset.black_level_dn) / spec.voltage_swing_v
    sigma_d_true = np.sqrt(spec.read_noise_e ** 2 + pd.dark_current_e_per_s * t_exp)
    assert res["fit"].sum() >= 15
    assert res["K"] == pytest.approx(K_true, rel=TOL["K"])
    assert res["sigma_d_exact"] == pytest.approx(sigma_d_true, rel=TOL["sigma_d"])
    assert res["mu_e_sat"] == pytest.approx(expected_saturation_e(pd.full_well_e, clip_e, spec.read_noise_e),
                                            rel=TOL["sat"])
    assert 0.92 * sat_true <= res["mu_e_sat"] <= sat_true
    photons = levels / eta
    R = np.polyfit(photons[res["fit"]], res["mu"][res["fit"]] - res["mu_dark"], 1)[0]
    assert R == pytest.approx(K_true * eta, rel=TOL["R"])
