"""Presets of real products reproduce their sources' headline figures (docs/guide/references.md, "Sensor presets"),
and the general capture plans (several photodiodes and gains, companding, per-photodiode QE) hold.

Dynamic range (dB) is computed from the model, not copied: 20 log10 of the largest signal the plan reads without
clipping (input-referred to the reference capture: saturation capacity x sensitivity ratio x exposure ratio) over
the smallest read noise; SNR_MAX from a simulated flat field just below the clip (mean / temporal std of a pair
difference, EMVA 1288 R4.0 sec. 6), against 10 log10(full well) of the shot-noise limit.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import yaml

from lfmbench.sensor import PRESET_DIR, load_preset, simulate_plan_electrons
from lfmbench.sensor.noise import compand, decompand
from lfmbench.sensor.plan import resolve_windows, total_length_s

TIMING = {"short_exposure_s": 0.004, "long_exposure_s": 1 / 90}


def model_dr_db(p) -> float:
    """20 log10(max unclipped input-referred signal / min read noise) over the plan's captures, in dB."""
    ref = p.captures[p.reference]
    ff_ref = p.photodiodes[ref.photodiode].fill_factor
    t_ref = total_length_s(resolve_windows(ref.exposure, TIMING))
    top, floor = 0.0, math.inf
    for c, spec in p.captures.items():
        pd = p.photodiodes[spec.photodiode]
        t = total_length_s(resolve_windows(spec.exposure, TIMING))
        top = max(top, p.saturation_capacity_e(c) * (ff_ref / pd.fill_factor) * (t_ref / t))
        floor = min(floor, spec.read_noise_e * (ff_ref / pd.fill_factor) * (t_ref / t))
    return 20 * math.log10(top / floor)


# (preset, published dynamic range dB, tolerance dB, source)
HEADLINES = [("imx490_4read", 120.0, 0.5, "Sony IMX490 announcement: 120 dB"),
             ("ar0132at", 115.0, 0.5, "AR0132AT datasheet Table 1: > 115 dB"),
             ("lofic_akahane2006", 100.0, 0.5, "Akahane et al. JSSC 2006: 100 dB")]


@pytest.mark.parametrize("name, dr_db, tol, source", HEADLINES)
def test_dynamic_range_of_published_presets(name, dr_db, tol, source):
    assert model_dr_db(load_preset(name)) == pytest.approx(dr_db, abs=tol), source


def test_mt9v024_linear_dynamic_range_and_companding():
    """> 55 dB linear (datasheet) and at most what its 12-bit code holds; the 12->10 bit curve is monotone and
    decompanding recovers every linear code to within half an output step's width."""
    p = load_preset("mt9v024")
    dr = model_dr_db(p)
    assert 55.0 <= dr <= 55.5
    comp = p.captures["main"].companding
    lin = torch.arange(0, 4096, dtype=torch.float64)
    out = compand(lin, comp).round()
    assert out.max() == 1023 and bool((out[1:] >= out[:-1]).all())
    back = decompand(out, comp)
    slope = torch.tensor([1, 0.5, 0.25, 0.25, 0.125], dtype=torch.float64)
    step = 1.0 / slope[torch.bucketize(lin, torch.tensor([255, 511, 1023, 2047.0]), right=False).clamp_max(4)]
    assert bool(((back - lin).abs() <= 0.5 * step + 1e-9).all())


def _flat(p, level_e: float, seed: int, size: int = 64):
    """A pair of flat fields of ``level_e`` mean e- on every exposure, the simulated DN and ``*_e``."""
    t = {k: total_length_s(resolve_windows(p.captures[k].exposure, TIMING)) for k in p.exposures}
    x = torch.full((2, 1, size, size), float(level_e), dtype=torch.float64)
    return simulate_plan_electrons({k: x.clone() for k in p.exposures}, p, t, torch.Generator().manual_seed(seed))


@pytest.mark.parametrize("name, capture, snr_db, tol", [("ar0132at", "t1", 43.9, 0.3)])
def test_snr_max_from_simulation(name, capture, snr_db, tol):
    """SNR_MAX 43.9 dB (AR0132AT datasheet) from a simulated flat field at 97 % of the well."""
    p = load_preset(name)
    fw = p.saturation_capacity_e(capture)
    out = _flat(p, 0.97 * fw, 7)
    y = out[capture][:, 0].numpy().astype(np.float64)
    K = p.system_gain(capture)
    mu = (y.mean() - p.black_level_dn) / K
    sd = np.sqrt(0.5 * np.var(y[0] - y[1])) / K
    assert 20 * math.log10(mu / sd) == pytest.approx(snr_db + 10 * math.log10(0.97), abs=tol)


def test_imx490_four_reads_share_two_charges():
    """Two photodiodes x two gains: the HCG and LCG reads of one photodiode read the same charge (their
    input-referred values agree where neither clips), the two photodiodes differ by their sensitivity."""
    p = load_preset("imx490_4read")
    assert p.exposures == {"sp1_hcg": ("sp1_hcg", "sp1_lcg"), "sp2_hcg": ("sp2_hcg", "sp2_lcg")}
    out = _flat(p, 2000.0, 3, 32)
    d = (out["sp1_hcg_e"] - out["sp1_lcg_e"]).std().item()
    assert d < 3 * math.hypot(1.0, 1.0 * 4) + 1.5      # read noises only (LCG 1 e- x its 4x coarser DN step)
    assert out["saturated"].shape[-3] == 4


def _write(tmp_path, d, name="bad.yaml"):
    f = tmp_path / name
    f.write_text(yaml.safe_dump(d, sort_keys=False))
    return f


def _imx(tmp_path):
    d = yaml.safe_load((PRESET_DIR / "imx490_4read.yaml").read_text())
    d["spectral"]["filters"] = str(load_preset("imx490_4read").filters_path)
    return d


@pytest.mark.parametrize("mutate, field", [
    # a split pixel's windows other than the corpus's: accepted and ignored before, now refused
    (lambda d: d.update(yaml.safe_load((PRESET_DIR / "ox03c10.yaml").read_text()), spectral=d["spectral"])
     or d["captures"]["spd"].update(exposure=[[0.0, 0.011]]), "captures"),
    # overlapping windows of one photodiode
    (lambda d: d["captures"]["sp2_lcg"].update(exposure=[[0.0, 0.002]]) or d["captures"]["sp2_hcg"].update(
        exposure=[[0.001, 0.002]]), "captures.sp2_lcg.exposure"),
    # out of frame
    (lambda d: d.update(frame_time_s=0.005) or d["captures"]["sp1_hcg"].update(exposure=[[0.004, 0.002]]),
     "captures.sp1_hcg.exposure[0]"),
    # gains of one charge not highest first
    (lambda d: d["captures"]["sp1_hcg"].update(conversion_gain_v_per_e=1e-6), "captures"),
    # a photodiode nobody reads
    (lambda d: d["photodiodes"].update(sp3=dict(d["photodiodes"]["sp2"])), "captures"),
    # companding: bad knees, and on a split pixel
    (lambda d: d["captures"]["sp1_hcg"].update(companding={"linear_bits": 16, "knees": [[0, 0], [100, 50]]}),
     "captures.sp1_hcg.companding.knees"),
    (lambda d: d["captures"]["sp1_hcg"].update(companding={"linear_bits": 16, "knees": [[0, 0], [60000, 4000],
                                                                                        [50000, 4095]]}),
     "captures.sp1_hcg.companding.knees"),
    # QE above 1
    (lambda d: d["spectral"].update(peak_qe=1.0) or d.update(spectral={"filters": "onsemi_mt9v024_rgb.csv",
                                                                       "peak_qe": 1.0})
     or d["photodiodes"]["sp1"].update(spectral={"filters": "cfa_nikon_d5100_npl.csv", "peak_qe": 1.0}) or
     d["spectral"].update(peak_qe=1.7), "spectral.peak_qe"),
])
def test_bad_general_plans_name_file_and_field(tmp_path, mutate, field):
    d = _imx(tmp_path)
    mutate(d)
    with pytest.raises(ValueError) as exc:
        load_preset(_write(tmp_path, d))
    msg = str(exc.value)
    assert "bad.yaml" in msg and f"'{field}'" in msg and "\n" not in msg, msg


def test_split_pixel_beside_a_very_short_exposure(tmp_path):
    """multi_photodiode: LPD at HCG/LCG over [0, 4) ms plus a 0.1 ms LPD exposure after it, SPD over the long
    window; a named window beside another integration of the same photodiode is refused (its time is the scene's)."""
    d = yaml.safe_load((PRESET_DIR / "ovt.yaml").read_text())
    d["spectral"]["filters"] = str(load_preset("ovt").filters_path)
    d["architecture"] = "multi_photodiode"
    c = d["captures"]
    c["lpd_hcg"]["exposure"] = c["lpd_lcg"]["exposure"] = [[0.0, 0.004]]
    c["lpd_vs"] = dict(c["lpd_lcg"], exposure=[[0.004, 0.0001]])
    c["spd"]["exposure"] = "long"
    p = load_preset(_write(tmp_path, d, "vs.yaml"))
    assert p.exposures == {"lpd_hcg": ("lpd_hcg", "lpd_lcg"), "spd": ("spd",), "lpd_vs": ("lpd_vs",)}
    out = _flat(p, 3000.0, 9, 16)
    # 3000 e- collected over 0.1 ms, referred to the reference (LPD over 4 ms): x 40
    assert out["lpd_vs_e"].mean().item() == pytest.approx(3000.0 * 0.004 / 0.0001, rel=0.01)
    c["lpd_hcg"]["exposure"] = c["lpd_lcg"]["exposure"] = "short"
    with pytest.raises(ValueError, match=r"bad\.yaml: field 'captures\.lpd_hcg\.exposure': photodiode 'lpd'"):
        load_preset(_write(tmp_path, d))


def test_staggered_with_dual_gain_and_triple_gain_lofic(tmp_path):
    d = yaml.safe_load((PRESET_DIR / "staggered.yaml").read_text())
    d["spectral"]["filters"] = str(load_preset("staggered").filters_path)
    long = d["captures"]["long"]
    d["captures"] = {"long_hcg": dict(long, conversion_gain_v_per_e=320e-6), "long_lcg": long,
                     "medium": d["captures"]["medium"], "short": d["captures"]["short"]}
    p = load_preset(_write(tmp_path, d, "dual.yaml"))
    assert p.exposures["long_hcg"] == ("long_hcg", "long_lcg") and len(p.exposures) == 3
    e = yaml.safe_load((PRESET_DIR / "lofic.yaml").read_text())
    e["spectral"]["filters"] = str(load_preset("lofic").filters_path)
    e["captures"] = {"hcg": e["captures"]["hcg"], "mcg": dict(e["captures"]["hcg"], conversion_gain_v_per_e=20e-6,
                                                                 read_noise_e=5.0), "lcg": e["captures"]["lcg"]}
    q = load_preset(_write(tmp_path, e, "tri.yaml"))
    assert q.exposures == {"hcg": ("hcg", "mcg", "lcg")}
    out = _flat(q, 30000.0, 5, 16)
    assert out["saturated"][:, 0].all() and not out["saturated"][:, 2].any()   # HCG clips, LCG does not


def test_per_photodiode_spectral_response(tmp_path):
    """A photodiode's own curve changes its electrons (sensor side) and the dataset refuses it in one line."""
    from lfmbench.datasets.projection import unit_projection_preset
    from lfmbench.sensor import electron_weights

    d = _imx(tmp_path)
    d["photodiodes"]["sp2"]["spectral"] = {"filters": "onsemi_mt9v024_rgb.csv", "peak_qe": 1.0}
    p = load_preset(_write(tmp_path, d, "own.yaml"))
    w1 = electron_weights(p, [450.0, 550.0, 650.0], "sp2") / p.photodiodes["sp2"].fill_factor
    w0 = electron_weights(p, [450.0, 550.0, 650.0], "sp1") / p.photodiodes["sp1"].fill_factor
    assert not torch.allclose(w0, w1, rtol=0.05)
    with pytest.raises(ValueError, match=r"own\.yaml: field 'photodiodes\.sp2\.spectral'"):
        unit_projection_preset(p)


def test_every_preset_number_is_cited_or_estimated():
    """Each value line of the real-product presets names a source tag or says 'estimated'."""
    for name in ("imx490_4read", "ar0132at", "mt9v024", "ox03c10", "lofic_akahane2006", "ar0820at",
                 "lofic_otani2025"):
        text = (PRESET_DIR / f"{name}.yaml").read_text()
        head = text[:text.index("\nname:")]
        tags = {t.split("]")[0] for t in head.split("[")[1:]}
        for line in text[text.index("\nname:"):].splitlines():
            if "#" in line and not line.lstrip().startswith("#"):
                c = line.split("#", 1)[1]
                assert "estimated" in c or any(f"[{t}]" in c for t in tags) or "1 / 90" in c or "from [" in c, \
                    (name, line)


def test_ar0820at_exposure_ratios_and_combined_output():
    """onsemi AR0820AT eHDR: three sequential, non-overlapping exposures of one photodiode at the TI driver's ratios
    T1:T2 = 11 and T1:T3 = 92 (computed from the resolved windows), and a plan whose range fits the 24-bit combined
    output NVIDIA lists for the part (20 log10(2^24) = 144.5 dB)."""
    p = load_preset("ar0820at")
    assert p.architecture == "staggered" and list(p.exposures) == ["t1", "t2", "t3"]
    w = {c: resolve_windows(p.captures[c].exposure, TIMING) for c in p.captures}
    t = {c: total_length_s(w[c]) for c in w}
    assert t["t1"] / t["t2"] == pytest.approx(11.0, rel=1e-9)
    assert t["t1"] / t["t3"] == pytest.approx(92.0, rel=1e-9)
    ends = [w[c][0][0] + w[c][0][1] for c in ("t1", "t2", "t3")]
    starts = [w[c][0][0] for c in ("t1", "t2", "t3")]
    assert all(s >= e - 1e-12 for s, e in zip(starts[1:], ends[:-1])) and ends[-1] <= p.frame_time_s
    dr = model_dr_db(p)
    assert 20 * math.log10(92 * 10000 / 2.0) == pytest.approx(dr, abs=1e-6)   # the estimated well / noise, x 92
    assert dr <= 20 * math.log10(2 ** 24)


def _snr_db(p, out, capture):
    """SNR (dB) of ``capture`` from a simulated pair of flat fields: mean over the temporal std of the pair
    difference, both in e- (EMVA 1288 R4.0 sec. 6)."""
    y = out[capture][:, 0].numpy().astype(np.float64)
    K = p.system_gain(capture)
    mu = (y.mean() - p.black_level_dn) / K
    sd = np.sqrt(0.5 * np.var(y[0] - y[1])) / K
    return 20 * math.log10(mu / sd)


def test_triple_gain_lofic_improves_the_switch_snr_drop_by_8_05_db():
    """Otani et al. (Sensors 2025): the triple-gain readout improves the SNR drop at the gain switch by 8.05 dB over
    the dual-gain one. Simulated: the drop of the HCG/LCG readout at the HCG's clip, minus the worst drop of the
    HCG/MCG/LCG readout (at the HCG's and at the MCG's clip), each at 95 % of the lower read's clip; within 0.5 dB
    (each SNR from 2 x 128 x 128 pixels is known to about 0.05 dB)."""
    p = load_preset("lofic_otani2025")
    assert p.exposures == {"hcg": ("hcg", "mcg", "lcg")}
    s1, s2 = 0.95 * p.saturation_capacity_e("hcg"), 0.95 * p.saturation_capacity_e("mcg")
    a, b = _flat(p, s1, 11, 128), _flat(p, s2, 12, 128)
    dual = _snr_db(p, a, "hcg") - _snr_db(p, a, "lcg")
    triple = max(_snr_db(p, a, "hcg") - _snr_db(p, a, "mcg"), _snr_db(p, b, "mcg") - _snr_db(p, b, "lcg"))
    assert dual - triple == pytest.approx(8.05, abs=0.5), (dual, triple)
    assert dual > 9.0          # the dual-gain drop this fixes is large (LCG read noise 300 e- at 9.5 ke-)
