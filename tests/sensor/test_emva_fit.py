"""``lfmbench sensor fit``: a preset from EMVA 1288 results, round trip and bad input.

Round trip: simulate flat-field pairs of a preset at a series of irradiances (fixed exposure time, EMVA 1288 R4.0
sec. 6.1) and dark pairs at two exposure times, analyse them the EMVA way (written
here from the standard: mean of the pair, temporal variance = half the variance of the pair difference, system gain
K = slope of the photon transfer curve up to 70 % of saturation, temporal dark noise from the dark variance minus
the 1/12 DN^2 quantisation, saturation capacity at the variance maximum, dark current from the dark mean's slope
against exposure time), write the results as an EMVA file, fit, and compare the fitted preset with the original.
Tolerances: K 2 %, read noise 6 %, dark current 10 %, saturation capacity -7 % / +0.5 % (EMVA's mu_e.sat lies 2-4 %
below the clip point, tests/sensor/test_emva1288.py derives why; the variance maximum of 2304-pixel pairs on a 1.7 % level grid adds up to 3 %).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import yaml
from typer.testing import CliRunner

from lfmbench.cli import app
from lfmbench.sensor import DATA_DIR, load_preset, simulate_plan_electrons
from lfmbench.sensor.emva import preset_from_emva

SIZE = 48


def _pairs(p, levels_e, t_s: float, seed: int):
    """(2, L, N) DN of flat-field pairs at mean photo-electrons ``levels_e`` (L,) over one exposure ``t_s`` (s)."""
    key = next(iter(p.exposures))
    x = torch.as_tensor(np.asarray(levels_e, dtype=np.float64)).reshape(1, -1, 1, 1, 1).expand(
        2, -1, 1, SIZE, SIZE).contiguous()
    out = simulate_plan_electrons({key: x}, p, {key: float(t_s)}, torch.Generator().manual_seed(seed))
    return out[key][:, :, 0].reshape(2, len(levels_e), -1).numpy()


def emva_analysis(y, dark_y, dark_t):
    ya, yb = y[0].astype(np.float64), y[1].astype(np.float64)
    mu = 0.5 * (ya.mean(-1) + yb.mean(-1))
    var = 0.5 * (ya - yb).var(-1)
    da, db = dark_y[0].astype(np.float64), dark_y[1].astype(np.float64)
    mu_d = 0.5 * (da.mean(-1) + db.mean(-1))
    var_d = 0.5 * (da - db).var(-1)
    i_sat = int(np.argmax(var))
    sel = (mu - mu_d[0] > 0) & (mu - mu_d[0] <= 0.7 * (mu[i_sat] - mu_d[0]))
    K = np.polyfit(mu[sel] - mu_d[0], var[sel] - var_d[0], 1)[0]
    dark_rate = np.polyfit(dark_t, mu_d, 1)[0] / K
    return {"K": K, "sigma_d": math.sqrt(max(var_d[0] - 1 / 12, 0.0)) / K, "sat": (mu[i_sat] - mu_d[0]) / K,
            "dark": dark_rate, "t_dark": float(dark_t[0]), "black": float(np.round(mu_d[0] - dark_rate * dark_t[0] * K))}


def _emva_file(tmp_path, res, bits, pitch, **over):
    d = {"emva1288_release": 4, "name": "fitted", "pixel_pitch_m": pitch, "adc_bits": bits,
         "black_level_dn": res["black"], "system_gain_dn_per_e": float(res["K"]),
         "temporal_dark_noise_e": float(res["sigma_d"]), "saturation_capacity_e": float(res["sat"]),
         "qe_curve": "qe.csv", "dark_current_e_per_s": float(res["dark"]),
         "dark_noise_exposure_s": res["t_dark"], "dsnu_e": 0.0, "prnu_percent": 0.0}
    d.update(over)
    (tmp_path / "qe.csv").write_text((DATA_DIR / "onsemi_mt9v024_rgb.csv").read_text())
    f = tmp_path / "emva.yaml"
    f.write_text(yaml.safe_dump(d))
    return f


def test_round_trip_recovers_the_parameters(tmp_path):
    p = load_preset("single")
    spec, pd = p.captures["main"], p.photodiodes["pd"]
    sat = p.saturation_capacity_e("main")
    levels = np.concatenate([np.linspace(0.02, 0.7, 14), np.linspace(0.72, 1.15, 26)]) * sat
    t_exp = 0.004
    y = _pairs(p, levels, t_exp, 100)
    dark_t = np.array([t_exp, 0.2, 0.5])
    dark = np.concatenate([_pairs(p, [0.0], t, 200 + i) for i, t in enumerate(dark_t)], axis=1)
    res = emva_analysis(y, dark, dark_t)
    f = _emva_file(tmp_path, res, p.adc_bits, p.pixel_pitch_m)
    r = CliRunner().invoke(app, ["sensor", "fit", str(f), "--out", str(tmp_path / "fit.yaml"),
                                 "--exposure", "[[0.0, 0.004]]"])
    assert r.exit_code == 0, r.output
    q = load_preset(tmp_path / "fit.yaml")
    assert q.architecture == "single" and q.captures["main"].exposure == ((0.0, 0.004),)
    assert q.system_gain("main") == pytest.approx(p.system_gain("main"), rel=0.02)
    assert q.captures["main"].read_noise_e == pytest.approx(spec.read_noise_e, rel=0.06)
    assert q.photodiodes["pd"].dark_current_e_per_s == pytest.approx(pd.dark_current_e_per_s, rel=0.10)
    assert 0.93 * sat <= q.saturation_capacity_e("main") <= 1.005 * sat


@pytest.mark.parametrize("over, field", [
    ({"system_gain_dn_per_e": -0.3}, "system_gain_dn_per_e"),
    ({"system_gain_dn_per_e": None}, "system_gain_dn_per_e"),
    ({"emva1288_release": 3}, "emva1288_release"),
    ({"prnu_percent": 80}, "prnu_percent"),
    ({"saturation_capacity_e": 1e7}, "saturation_capacity_e"),
    ({"temporal_dark_noise_e": 0.01, "dark_current_e_per_s": 1000.0, "dark_noise_exposure_s": 0.1},
     "temporal_dark_noise_e"),
    ({"qe_curve": "qe_bad.csv"}, "qe_curve"),
    ({"exposure_ms": 3}, "exposure_ms"),
])
def test_bad_emva_input_names_file_and_field_and_writes_nothing(tmp_path, over, field):
    res = {"K": 0.3, "sigma_d": 2.0, "sat": 10000.0, "dark": 1.0, "t_dark": 0.001, "black": 64.0}
    (tmp_path / "qe_bad.csv").write_text("wavelength_nm,r,g,b\n500,0.5,1.2,0.3\n600,0.4,0.9,0.1\n")
    f = _emva_file(tmp_path, res, 12, 3e-6, **over)
    if over.get("system_gain_dn_per_e", 0) is None:
        d = yaml.safe_load(f.read_text())
        d.pop("system_gain_dn_per_e")
        f.write_text(yaml.safe_dump(d))
    out = tmp_path / "fit.yaml"
    r = CliRunner().invoke(app, ["sensor", "fit", str(f), "--out", str(out), "--exposure", "short"])
    assert r.exit_code == 2 and not out.exists()
    msg = r.output.strip()
    assert "emva.yaml" in msg and f"'{field}'" in msg and len(msg.splitlines()) == 1, msg


def test_fit_plans_and_bad_exposure(tmp_path):
    res = {"K": 0.3, "sigma_d": 2.0, "sat": 10000.0, "dark": 1.0, "t_dark": 0.001, "black": 64.0}
    f = _emva_file(tmp_path, res, 12, 3e-6)
    d = yaml.safe_load(f.read_text())
    p = preset_from_emva(d, [[[0.0, 0.001]], [[0.001, 0.008]]], str(f))
    assert p["architecture"] == "staggered" and p["captures"]["e1"]["exposure"] == [[0.001, 0.008]]
    assert preset_from_emva(d, [[[0.0, 0.001], [0.005, 0.001]]], str(f))["architecture"] == "chopped"
    out = tmp_path / "fit.yaml"
    r = CliRunner().invoke(app, ["sensor", "fit", str(f), "--out", str(out), "--exposure", "[[0.0, -1]]"])
    assert r.exit_code == 2 and not out.exists() and "exposure[0][0][1]" in r.output
