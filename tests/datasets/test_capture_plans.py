"""Capture plans in the dataset: each exposure's electrons against brute-force integration of the time bins over its
windows (global and rolling, chopped unions), the sample keys of every architecture, and bad plans for a corpus."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from lfmbench.datasets import LFMCaptureDataset
from lfmbench.datasets.plan_frames import PlanExposure, compose_plan_frame, static_window_source
from lfmbench.datasets.projection import SceneLayers
from lfmbench.sensor import load_preset
from tests.data.corpus.data import make_corpus

H, W, K = 6, 7, 5
FPS, TS, TL, LT = 60.0, 0.004, 1 / 90, 4e-4
CW = TL + H * LT
PWM = {"period_s": 1 / 331.0, "duty": 0.3, "phase_s": 0.0013, "rise_s": 0.0, "fall_s": 0.0}


def _meta():
    return {"fps": FPS, "height": H, "width": W, "timing": {"short_exposure_s": TS, "long_exposure_s": TL,
                                                             "line_time_s": LT, "capture_window_s": CW, "bins": K}}


def _layers(rng):
    box = (1, 2, 5, 6)                                               # y0, x0, y1, x1
    rates = torch.from_numpy(rng.random((K, 4, 4)).astype(np.float32) * 1e4)   # e-/s per bin
    static = {"lpd": torch.full((2, H, W), 300.0), "spd": torch.full((2, H, W), 500.0)}
    lights = [[(0, "otherlights", box, {"lpd": rates, "spd": rates})] for _ in range(2)]
    return SceneLayers("s", static, {}, lights, {}), box, rates.numpy().astype(np.float64)


def brute_force(windows, frame, rolling, rates, box, level="pwm", n=200_000):
    """(H, W) e-: sum over windows of the integral of s(t) R_k(t) over each row's window, midpoint rule on n points,
    the light's PWM square wave s and the bin k(t) = floor((t - t_n) K / W_c) written here from their definitions."""
    out = np.zeros((H, W))
    t0 = frame / FPS
    y0, x0, y1, x1 = box
    for y in range(y0, y1):
        shift = y * LT if rolling else 0.0
        acc = np.zeros(x1 - x0)
        for a, length in windows:
            dt = length / n
            t = t0 + a + shift + (np.arange(n) + 0.5) * dt
            if level == "pwm":
                s = (np.mod(t - PWM["phase_s"], PWM["period_s"]) < PWM["duty"] * PWM["period_s"]).astype(float)
            else:
                s = np.full(n, PWM["duty"])
            k = np.minimum(((t - t0) * K / CW).astype(int), K - 1)
            w = np.bincount(k, weights=s * dt, minlength=K)                  # s at level 1 per bin
            acc += w @ rates[:, y - y0, :]
        out[y, x0:x1] = acc
    return out


@pytest.mark.parametrize("rolling", [False, True])
@pytest.mark.parametrize("frame", [0, 1])
def test_exposure_electrons_match_brute_force_integration(rolling, frame):
    rng = np.random.default_rng(5)
    layers, box, rates = _layers(rng)
    chopped = ((0.0005, 0.0004), (0.0031, 0.0002), (0.0072, 0.0009))     # a union of three sub-windows
    single = ((0.0100, 0.0011),)
    ex = [PlanExposure("a", 0.5, chopped, rolling, LT), PlanExposure("b", 1.0, single, rolling, LT)]
    out = compose_plan_frame(layers, _meta(), frame, (0, 0, H, W), {0: PWM}, {}, ex, "a")
    for x, key in ((ex[0], "a"), (ex[1], "b")):
        static = sum(n * (300.0 if static_window_source(a, n, _meta()["timing"])[0] == "short" else 500.0)
                     for a, n in x.windows)
        want = x.fill_factor * (brute_force(x.windows, frame, rolling, rates, box) + static)
        np.testing.assert_allclose(out[key].numpy(), want, rtol=2e-4)
    gt = 0.5 * (brute_force(chopped, frame, rolling, rates, box, level="mean")
                + sum(n * (300.0 if static_window_source(a, n, _meta()["timing"])[0] == "short" else 500.0)
                      for a, n in chopped))
    np.testing.assert_allclose(out["gt"].numpy(), gt, rtol=2e-4)


def test_static_window_rule():
    tm = _meta()["timing"]
    sa = (TL - TS) / 2
    assert static_window_source(sa, TS, tm) == ("short", True)
    assert static_window_source(0.0, TL, tm) == ("long", True)
    assert static_window_source(sa + 1e-4, 1e-3, tm) == ("short", False)      # inside the short window
    assert static_window_source(0.0, 1e-3, tm) == ("long", False)             # at the frame start: only the long


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return make_corpus(tmp_path_factory.mktemp("plans") / "c", n_scenes=2, frames=2)


@pytest.mark.parametrize("name", ["lofic", "staggered", "chopped", "single"])
def test_dataset_yields_the_plan_captures(corpus, name):
    p = load_preset(name)
    ds = LFMCaptureDataset(corpus, split="all", sensor=name, frames=2, cache_dir=False)
    s = ds[0]
    for c in p.captures:
        assert s[c].shape == (2, 1, 16, 24) and s[f"{c}_e"].shape == (2, 1, 16, 24)
    assert s["saturated"].shape == (2, len(p.captures), 16, 24) and s["gt"].shape == (2, 1, 16, 24)
    assert not {"lpd_hcg", "spd"} & set(s)
    assert s["meta"]["architecture"] == p.architecture and s["meta"]["sensor"] == name
    assert s["meta"]["static_windows"] == ("exact" if name == "single" else "nearest")
    # the readout each capture was read with: the staggered plan's own rolling shutter (the dataset's shutter
    # argument, "global", is only the default of captures and presets that set none)
    want = "rolling" if name == "staggered" else "global"
    assert s["meta"]["shutter"] == "global" and s["meta"]["readout"] == {c: want for c in p.captures}
    # input referral: every unsaturated capture estimates the ground truth (same reference units)
    for c in p.captures:
        ok = ~s["saturated"][:, list(p.captures).index(c):][:, :1]
        rel = ((s[f"{c}_e"] - s["gt"])[ok].mean() / s["gt"][ok].mean()).abs()
        assert rel < 0.1, (c, float(rel))


def test_unit_projection_scales_by_fill_factor_and_pixel_area(corpus):
    """``single`` reads the short window like the ovt LPD: its noise-free gt is ovt's x (FF A) ratio (no PSF)."""
    kw = dict(split="all", frames=2, cache_dir=False, optics=False, noise=False, outputs=("gt",))
    a = LFMCaptureDataset(corpus, sensor="single", **kw)[0]["gt"]
    b = LFMCaptureDataset(corpus, sensor="ovt", **kw)[0]["gt"]
    ratio = (0.9 * 3.0e-6 ** 2) / (1.0 * 2.8e-6 ** 2)
    torch.testing.assert_close(a, b * ratio, rtol=1e-5, atol=1e-6)


def test_a_window_outside_the_capture_window_names_preset_and_corpus(corpus, tmp_path):
    import yaml

    d = yaml.safe_load(open(load_preset("single").source))
    d["captures"]["main"]["exposure"] = [[0.0105, 0.002]]                 # ends at 12.5 ms > 11.27 ms
    d["spectral"]["filters"] = str(load_preset("single").filters_path)
    f = tmp_path / "late.yaml"
    f.write_text(yaml.safe_dump(d, sort_keys=False))
    with pytest.raises(ValueError) as exc:
        LFMCaptureDataset(corpus, split="all", sensor=f, frames=2, cache_dir=False)
    msg = str(exc.value)
    assert "late.yaml" in msg and "'captures.main.exposure'" in msg and str(corpus) in msg and "\n" not in msg


def test_exact_static_windows_refuse_an_unstored_window(corpus):
    with pytest.raises(ValueError, match=r"staggered\.yaml: field 'captures\.long\.exposure'.*static_windows"):
        LFMCaptureDataset(corpus, split="all", sensor="staggered", frames=2, cache_dir=False, static_windows="exact")
    ds = LFMCaptureDataset(corpus, split="all", sensor="single", frames=2, cache_dir=False, static_windows="exact")
    assert ds[0]["meta"]["static_windows"] == "exact"
    with pytest.raises(ValueError, match="static_windows"):
        LFMCaptureDataset(corpus, split="all", sensor="single", frames=2, cache_dir=False, static_windows="bins")


def test_batched_and_counter_paths_serve_the_split_pixel_only(corpus):
    for kw in ({"pieces": True}, {"noise_streams": "counter"}):
        with pytest.raises(ValueError, match="per-sample path"):
            LFMCaptureDataset(corpus, split="all", sensor="lofic", frames=2, cache_dir=False, **kw)


def test_rolling_weights_at_the_lamps_rows_are_the_full_computations():
    """A rolling readout's bin weights are computed only at the rows each lamp's box covers (_rolling_bin_exposure):
    there they equal window_bin_exposure over every row bit for bit (the same element-wise formula), elsewhere 0."""
    import numpy as np

    from lfmbench.datasets.assembly import _box_rows, _rolling_bin_exposure, bin_edges, window_bin_exposure

    rng = np.random.default_rng(3)
    L, Wn, R, y0 = 4, 3, 40, 100
    edges = 0.02 + bin_edges(0.0123, 8)
    starts = 0.02 + rng.uniform(0, 0.004, (Wn, 1)) + np.arange(R)[None, :] * 2e-5         # (Wn, R) s
    length = rng.uniform(1e-4, 8e-3, (Wn, 1, 1))
    pa = {"period_s": 1 / rng.uniform(90, 2000, L), "duty": rng.uniform(0, 1, L), "phase_s": rng.uniform(0, 0.01, L),
          "rise_s": np.zeros(L), "fall_s": np.zeros(L)}
    pa = {k: v.reshape(L, 1, 1, 1) for k, v in pa.items()}
    group = [(None, (0, 0), (y0 + a, y0 + b, 0, 5), None) for a, b in ((0, 3), (10, 40), (5, 6), (12, 30))]
    pairs = _box_rows(group, y0)
    for level in ("pwm", "mean"):
        full = window_bin_exposure(edges, starts, length, pa["period_s"], pa["duty"], pa["phase_s"], pa["rise_s"],
                                   pa["fall_s"], level, check=False)                      # (L, Wn, R, K)
        part = _rolling_bin_exposure(edges, starts, length, pa, level, pairs, L)
        assert part.shape == full.shape
        mask = np.zeros((L, R), dtype=bool)
        mask[pairs] = True
        assert np.array_equal(part.transpose(0, 2, 1, 3)[mask], full.transpose(0, 2, 1, 3)[mask])
        assert not part.transpose(0, 2, 1, 3)[~mask].any()
        assert mask.sum() == 3 + 30 + 1 + 18


@pytest.mark.parametrize("name, checked", [("imx490_4read", ("sp1_hcg", "sp1_lcg", "sp2_hcg", "sp2_lcg")),
                                           ("mt9v024", ("main",)), ("ar0132at", ("t1",)),
                                           ("lofic_otani2025", ("hcg",))])
def test_dataset_yields_the_general_plans_of_real_presets(corpus, monkeypatch, name, checked):
    """Four reads of two photodiodes, a companded capture, three staggered exposures, three reads of one LOFIC charge:
    every capture comes out, and the ``checked`` ones (those whose input-referred noise the dark test corpus
    resolves) estimate the ground truth in the reference units (decompanded where the part compands). The sample is
    the same, bit for bit, when the sensor chain runs as the torch chain instead of compiled (the CPU default): the
    compiled chain changes no sample a user gets."""
    from functools import partial

    from lfmbench.datasets import capture as _capture

    p = load_preset(name)
    ds = LFMCaptureDataset(corpus, split="all", sensor=name, frames=2, cache_dir=False)
    s = ds[0]
    monkeypatch.setattr(_capture._sensor, "simulate_plan_electrons",
                        partial(_capture._sensor.simulate_plan_electrons, backend="torch"))
    ref = ds[0]
    keys = [k for k, v in ref.items() if isinstance(v, torch.Tensor)]
    assert {*p.captures, *(f"{c}_e" for c in p.captures), "saturated", "gt"} <= set(keys)
    for k in keys:
        assert s[k].dtype == ref[k].dtype and torch.equal(s[k], ref[k]), k
    assert s["saturated"].shape == (2, len(p.captures), 16, 24) and s["meta"]["architecture"] == p.architecture
    for i, c in enumerate(p.captures):
        assert s[c].shape == (2, 1, 16, 24) and float(s[c].max()) <= p.max_dn
        if c in checked:
            ok = ~s["saturated"][:, i:i + 1] & (s["gt"] > 5 * p.captures[c].read_noise_e)
            assert ok.sum() > 20
            rel = ((s[f"{c}_e"] - s["gt"])[ok].mean() / s["gt"][ok].mean()).abs()
            assert rel < 0.1, (c, float(rel))

