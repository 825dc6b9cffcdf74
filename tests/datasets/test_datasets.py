"""LFMCaptureDataset on tiny generated corpora (no rendering, no network).

Physics checks use an independent answer: brute-force time integration of the PWM waveform over the bins.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader, DistributedSampler

from lfmbench import corpus as C
from lfmbench.datasets import DatasetNotFoundError, LFMCaptureDataset, compose_frame
from lfmbench.datasets.projection import build_layers
from lfmbench.flicker import pwm_level
from lfmbench.sensor import load_preset
from tests.data.corpus.data import H, W, fake_frames, fake_meta, fake_scene, make_corpus  # noqa: F401 - make_corpus re-exported

def test_sample_keys_shapes_and_units(corpus):
    ds = LFMCaptureDataset(corpus, split="all", frames=3, crop=(8, 12), cache_dir=False)
    s = ds[0]
    for k in ("lpd_hcg", "lpd_lcg", "spd", "lpd_hcg_e", "lpd_lcg_e", "spd_e", "gt", "depth"):
        assert s[k].shape == (3, 1, 8, 12), k
        assert torch.isfinite(s[k]).all(), k
    assert s["saturated"].shape == (3, 3, 8, 12) and s["saturated"].dtype == torch.bool
    assert s["light_index"].dtype == torch.int64
    assert s["lpd_lcg"].max() <= 4095 and s["lpd_lcg"].min() >= 0  # 12-bit DN
    m = s["meta"]
    assert m["num_lights"] == 2 and m["flicker"][:2].all() and m["light_id"][2] == -1
    assert ((m["freq_hz"][:2] >= 90) & (m["freq_hz"][:2] <= 120)).all()
    assert ((m["duty"][:2] >= 0.1) & (m["duty"][:2] <= 0.5)).all()
    assert (m["phase_s"][:2] < 1 / m["freq_hz"][:2]).all()
    assert m["crop"][0] % 2 == 0 and m["crop"][1] % 2 == 0  # Bayer phase kept


def test_only_requested_outputs(corpus):
    ds = LFMCaptureDataset(corpus, split="all", outputs=("gt",), cache_dir=False)
    assert set(ds[0]) == {"gt", "meta"}
    ds = LFMCaptureDataset(corpus, split="all", outputs=("rgb",), frames=2, cache_dir=False)
    s = ds[1]
    assert {"lpd_lcg_rgb", "spd_rgb", "gt_rgb"} <= set(s) and "lpd_lcg_e" not in s and "gt" not in s
    assert s["gt_rgb"].shape == (2, 3, H, W)


def test_deterministic_per_seed_epoch_index_and_worker_independent(corpus):
    ds = LFMCaptureDataset(corpus, split="all", crop=8, cache_dir=False)
    a, b = ds[2], ds[2]
    assert torch.equal(a["lpd_hcg"], b["lpd_hcg"]) and torch.equal(a["meta"]["duty"], b["meta"]["duty"])
    ds.set_epoch(1)
    c = ds[2]
    assert not torch.equal(a["meta"]["duty"], c["meta"]["duty"])
    ds.set_epoch(0)
    serial = [ds[i] for i in range(len(ds))]
    loader = DataLoader(ds, batch_size=1, num_workers=2, shuffle=False)
    for ref, got in zip(serial, loader):
        assert torch.equal(ref["lpd_lcg"], got["lpd_lcg"][0])
        assert torch.equal(ref["gt"], got["gt"][0])


def test_distributed_sampler_shards_give_the_same_samples(corpus):
    ds = LFMCaptureDataset(corpus, split="all", samples_per_scene=2, crop=8, cache_dir=False)
    seen = {}
    for rank in range(2):
        sampler = DistributedSampler(ds, num_replicas=2, rank=rank, shuffle=True, seed=3)
        for i in sampler:
            seen.setdefault(i, []).append(ds[i]["spd"])
    assert sorted(seen) == list(range(len(ds)))
    for i, samples in seen.items():
        assert torch.equal(samples[0], ds[i]["spd"])


def _brute_force_light(layers, meta, frame, light_id, p, window, rate_key, level="pwm", rows=None):
    """Mean e- of one light over a window by dense sampling of the waveform (independent of pwm_exposure)."""
    tm = meta["timing"]
    K = tm["bins"]
    t0 = frame / meta["fps"]
    edges = t0 + np.linspace(0, tm["capture_window_s"], K + 1)
    (lid, _g, box, rates), = [x for x in layers.lights[frame] if x[0] == light_id]
    a, te = window
    n = 400_000
    t = a + (np.arange(n) + 0.5) * te / n
    k = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, K - 1)
    s = pwm_level(t - p["phase_s"], p["period_s"], p["duty"]) if level == "pwm" else np.full(n, p["duty"])
    wk = np.bincount(k, weights=s, minlength=K) * te / n                    # s at level 1 per bin
    return box, torch.einsum("kyx,k->yx", rates[rate_key].double(), torch.from_numpy(wk))


def test_composition_matches_brute_force_time_integration(corpus):
    c = C.Corpus(corpus)
    sid = c.scenes[0]
    meta = c.meta(sid)
    preset = load_preset("ovt")
    layers = build_layers(c, sid, preset, None, 3, optics=True)
    tm = meta["timing"]
    params = {0: dict(period_s=1 / 97, duty=0.23, phase_s=0.0041, rise_s=0.0, fall_s=0.0),
              1: dict(period_s=1 / 113, duty=0.41, phase_s=0.0007, rise_s=0.0, fall_s=0.0)}
    for frame in (0, 2):
        out = compose_frame(layers, meta, frame, (0, 0, H, W), params, {})
        static_only = compose_frame(layers, meta, frame, (0, 0, H, W), {}, {})  # lights absent from params
        t0 = frame / meta["fps"]
        ts, tl = tm["short_exposure_s"], tm["long_exposure_s"]
        for key, window, rk, level in (("lpd", (t0 + (tl - ts) / 2, ts), "lpd", "pwm"),
                                       ("spd", (t0, tl), "spd", "pwm"), ("gt", (t0 + (tl - ts) / 2, ts), "lpd", "mean")):
            expect = layers.static[rk][frame].double() * window[1]
            for lid, p in params.items():
                (y0, x0, y1, x1), e = _brute_force_light(layers, meta, frame, lid, p, window, rk, level)
                expect[y0:y1, x0:x1] += e
            err = (out[key].double() - expect).abs().max() / expect.abs().max()
            assert err < 2e-4, (key, frame, float(err))  # dense sampling: ~1/400000 per edge
        assert static_only["lpd"].sum() < out["lpd"].sum() or params[0]["duty"] == 0


def test_whole_period_long_exposure_and_always_on_gt(tmp_path):
    root = make_corpus(tmp_path / "c", n_scenes=1, static_camera=True)
    c = C.Corpus(root)
    sid = c.scenes[0]
    meta = c.meta(sid)
    layers = build_layers(c, sid, load_preset("ovt"), None, 3)
    tl = meta["timing"]["long_exposure_s"]
    # a 90 Hz LED and the 1/90 s SPD exposure: whole periods -> the SPD sees exactly duty x ON level
    params = {i: dict(period_s=tl, duty=0.3, phase_s=0.002 * i, rise_s=0.0, fall_s=0.0) for i in (0, 1)}
    on = {i: dict(period_s=tl, duty=1.0, phase_s=0.0, rise_s=0.0, fall_s=0.0) for i in (0, 1)}
    for frame in range(3):
        a = compose_frame(layers, meta, frame, (0, 0, H, W), params, {})
        b = compose_frame(layers, meta, frame, (0, 0, H, W), on, {})
        static = layers.static["spd"][frame] * tl
        np.testing.assert_allclose((a["spd"] - static).numpy(), 0.3 * (b["spd"] - static).numpy(), rtol=2e-5, atol=1e-3)
        # always ON: the flickering capture equals the flicker-free truth
        np.testing.assert_allclose(b["lpd"].numpy(), b["gt"].numpy(), rtol=1e-6)


def test_rolling_shutter_row_windows(corpus):
    c = C.Corpus(corpus)
    sid = c.scenes[1]
    meta = c.meta(sid)
    layers = build_layers(c, sid, load_preset("ovt"), None, 3)
    params = {i: dict(period_s=1 / 105, duty=0.2, phase_s=0.001, rise_s=0.0, fall_s=0.0) for i in (0, 1)}
    g = compose_frame(layers, meta, 1, (0, 0, H, W), params, {}, "global")
    r = compose_frame(layers, meta, 1, (0, 0, H, W), params, {}, "rolling")
    tm = meta["timing"]
    ts, tl, td = tm["short_exposure_s"], tm["long_exposure_s"], tm["line_time_s"]
    (y0, x0, y1, x1) = [x for x in layers.lights[1] if x[0] == 0][0][2]
    for row in (y0, y1 - 1):
        a = 1 / meta["fps"] + (tl - ts) / 2 + row * td
        box, e = _brute_force_light(layers, meta, 1, 0, params[0], (a, ts), "lpd")
        other = [x for x in layers.lights[1] if x[0] == 1][0][2]
        if other[0] <= row < other[2]:
            continue  # the second light overlaps this row
        expect = layers.static["lpd"][1, row].double() * ts
        expect[box[1]:box[3]] += e[row - box[0]]
        assert (r["lpd"][row].double() - expect).abs().max() / expect.max() < 2e-4
    assert torch.equal(g["lpd"][0], r["lpd"][0]) or y0 > 0


def test_test_split_params_frozen_in_corpus(tmp_path):
    root = make_corpus(tmp_path / "c", n_scenes=5)
    a = LFMCaptureDataset(root, split="test", seed=1, cache_dir=False)
    path = root / "test_params.json"
    assert path.is_file()
    b = LFMCaptureDataset(root, split="test", seed=99, cache_dir=False)
    b.set_epoch(5)
    assert torch.equal(a[0]["meta"]["duty"], b[0]["meta"]["duty"])
    assert torch.equal(a[0]["lpd_lcg"], b[0]["lpd_lcg"])
    json.loads(path.read_text())["samples"]


def test_disk_cache_reused_and_equal(tmp_path):
    root = make_corpus(tmp_path / "c", n_scenes=1)
    ds = LFMCaptureDataset(root, split="all", noise=False)
    a = ds[0]
    files = list((root / ".cache").rglob("*.pt"))
    assert len(files) == 1
    ds2 = LFMCaptureDataset(root, split="all", noise=False)
    assert torch.equal(ds2[0]["gt"], a["gt"])


def test_imported_corpus_without_bins_uses_one_weight_per_frame(tmp_path):
    groups = {"skymap": {"flicker": False}, "otherlights": {"flicker": True, "bins": 0}}
    root = make_corpus(tmp_path / "c", n_scenes=1, groups=groups)
    ds = LFMCaptureDataset(root, split="all", noise=False, cache_dir=False)
    s = ds[0]
    assert s["meta"]["flicker_mode"] == "per_frame_weight"
    assert torch.isfinite(s["gt"]).all()


@pytest.mark.parametrize("pwm", [{"duty": {"dist": "constant", "value": 0.0}},
                                 {"duty": {"dist": "constant", "value": 1.0}}])
def test_extreme_duty(corpus, pwm):
    ds = LFMCaptureDataset(corpus, split="all", pwm=pwm, noise=False, cache_dir=False)
    s = ds[0]
    assert torch.isfinite(s["lpd_lcg_e"]).all() and torch.isfinite(s["gt"]).all()
    if pwm["duty"]["value"] == 1.0:  # always ON: no flicker, the noise-free LPD equals the truth where unclipped
        ok = ~s["saturated"][:, 1:2]
        assert torch.allclose(s["lpd_lcg_e"][ok], s["gt"][ok], rtol=2e-3, atol=20.0)


@pytest.mark.parametrize("scale", [0.0, 1e6])
def test_all_dark_and_sun_in_view(tmp_path, scale):
    root = make_corpus(tmp_path / "c", n_scenes=1, scale=scale)
    s = LFMCaptureDataset(root, split="all", cache_dir=False)[0]
    for k in ("lpd_hcg", "lpd_lcg", "spd", "lpd_lcg_e", "spd_e", "gt"):
        assert torch.isfinite(s[k]).all(), k
    if scale == 0.0:
        assert s["gt"].abs().max() == 0 and not s["saturated"].any()
    else:
        assert s["saturated"].all() and s["lpd_lcg"].max() == 4095


def test_bad_input_is_a_clear_error(tmp_path, corpus):
    with pytest.raises(DatasetNotFoundError, match="root"):
        LFMCaptureDataset(tmp_path / "nothing")
    with pytest.raises(ValueError, match="split"):
        LFMCaptureDataset(corpus, split="bogus")
    with pytest.raises(ValueError, match="outputs"):
        LFMCaptureDataset(corpus, outputs=("raw", "nope"))
    with pytest.raises(ValueError, match="frames"):
        LFMCaptureDataset(corpus, split="all", frames=9)
    with pytest.raises(ValueError, match="crop"):
        LFMCaptureDataset(corpus, split="all", crop=1000)
    with pytest.raises(ValueError, match="duty"):
        LFMCaptureDataset(corpus, split="all", pwm={"duty": {"dist": "uniform", "low": 0.2, "high": 1.5}})
    with pytest.raises(ValueError, match="unknown field"):
        LFMCaptureDataset(corpus, split="all", pwm={"dutty": {"dist": "constant", "value": 0.2}})


def test_corrupt_exr_names_the_file(tmp_path):
    root = make_corpus(tmp_path / "c", n_scenes=1)
    sid = C.Corpus(root).scenes[0]
    bad = root / "scenes" / sid / "f000" / "headlights.exr"
    bad.write_bytes(b"not an exr")
    with pytest.raises(Exception, match="headlights.exr"):
        LFMCaptureDataset(root, split="all", cache_dir=False)[0]


def test_plot_returns_figure(corpus):
    ds = LFMCaptureDataset(corpus, split="all", frames=2, cache_dir=False)
    s = ds[0]
    fig = ds.plot(s, prediction=s["gt"])
    rows = [ax.get_ylabel() for ax in fig.axes[::2]]  # a row per capture, gt, the prediction; a column per frame
    assert rows == ["lpd_hcg (capture)", "lpd_lcg (capture)", "spd (capture)", "ground truth", "prediction"]
    assert len(fig.axes) == 2 * 5
    # the prediction equals the ground truth and goes through the same ISP with the same statistics
    assert (fig.axes[6].images[0].get_array() == fig.axes[8].images[0].get_array()).all()


def test_training_example_in_docs_runs(tmp_path):
    """The DataLoader training loop of docs/guide/datasets.md runs (2 workers) and updates the network."""
    import re
    from pathlib import Path

    root = make_corpus(tmp_path / "c", n_scenes=3)
    text = (Path(__file__).resolve().parents[2] / "docs" / "guide" / "datasets.md").read_text()
    code = re.findall(r"```python\n(.*?)```", text, re.S)[-1]
    code = (code.replace('"demo_out/corpus"', repr(str(root))).replace("crop=128", "crop=8")
            .replace("range(3)", "range(2)").replace("split=\"train\"", "split=\"all\""))
    ns: dict = {}
    exec(compile(code, "docs/guide/datasets.md", "exec"), ns)
    assert torch.isfinite(ns["loss"]) and ns["loss"].requires_grad
    assert ns["ds"].epoch == 1


def test_line_time_override_checked_against_rendered_bins(corpus):
    ok = LFMCaptureDataset(corpus, split="all", shutter="rolling", line_time_s=5e-6, cache_dir=False)
    assert torch.isfinite(ok[0]["gt"]).all()
    with pytest.raises(ValueError, match="line_time_s"):
        LFMCaptureDataset(corpus, split="all", shutter="rolling", line_time_s=1e-3, cache_dir=False)


def test_workers_forked_after_parent_openmp_do_not_deadlock(tmp_path):
    """Regression: workers forked after the parent ran OpenMP (training) hung in torch ops once numba's
    parallel layer had been loaded in them. Run in a subprocess with a timeout so a hang fails, not blocks.
    Also checks that the constructor builds the serial CPU kernels in the parent (workers inherit them)."""
    import subprocess
    import sys
    import textwrap
    from pathlib import Path

    script = textwrap.dedent(f"""
        import sys, torch
        sys.path.insert(0, {str(Path(__file__).resolve().parents[2])!r})
        import tests.data.corpus.data as T
        from pathlib import Path
        T.H, T.W = 96, 128   # 3 frames x 96 x 128 > torch's parallel grain size: workers would enter OpenMP
        root = T.make_corpus(Path({str(tmp_path / 'c')!r}), n_scenes=2)
        from lfmbench.datasets import LFMCaptureDataset
        from lfmbench.flicker import kernels as flicker_kernels
        from lfmbench.sensor._poisson_kernel import kernel
        from torch.utils.data import DataLoader
        assert not kernel.signatures and "cpu" not in (flicker_kernels._NUMBA_KERNELS or {{}})
        ds = LFMCaptureDataset(root, split="all", samples_per_scene=2)
        # the serial kernels are built in the parent, so forked workers inherit them instead of compiling
        assert kernel.signatures and "cpu" in flicker_kernels._NUMBA_KERNELS, "kernels not built by the constructor"
        loader = DataLoader(ds, batch_size=2, num_workers=2)
        for epoch in range(2):
            ds.set_epoch(epoch)
            for b in loader:
                (torch.randn(768, 768) @ torch.randn(768, 768)).sum()   # the parent uses OpenMP
        print("ok")
    """)
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=240)
    assert res.returncode == 0 and "ok" in res.stdout, res.stderr[-2000:]


def test_frozen_test_params_grow_without_changing_existing_draws(tmp_path):
    root = make_corpus(tmp_path / "c", n_scenes=5)
    one = LFMCaptureDataset(root, split="test", cache_dir=False)
    first = one[0]["meta"]["duty"].clone()
    three = LFMCaptureDataset(root, split="test", samples_per_scene=3, cache_dir=False)
    assert len(three) == 3 * len(one)
    assert torch.equal(three[0]["meta"]["duty"], first)
    assert len(json.loads((root / "test_params.json").read_text())["samples"]) == len(three)


def test_corpus_without_aux_serves_every_output_but_depth_and_light_index(tmp_path):
    """aux.exr is optional (docs/guide/corpus-format.md 6.3): read only for ``light_index`` / ``depth``."""
    root = tmp_path / "c"
    w = C.CorpusWriter(root)
    meta = fake_meta("scene00000", width=W, height=H, frames=2, bins=4)
    w.write_scene("scene00000", fake_scene("scene00000"), meta, fake_frames(meta, aux=False))
    w.write_splits(0)
    assert C.validate_corpus(root).ok
    assert not list(root.rglob("aux.exr"))
    for cache in (False, None):  # without and with the projection cache
        ds = LFMCaptureDataset(root, split="all", frames=2, outputs=("input_referred", "gt"), cache_dir=cache)
        s = ds[0]
        assert s["gt"].shape == (2, 1, H, W) and "depth" not in s and "light_index" not in s
    for out in ("depth", "light_index"):
        ds = LFMCaptureDataset(root, split="all", frames=2, outputs=("gt", out), cache_dir=False)
        with pytest.raises(C.CorpusFileError, match=rf"aux\.exr.*\['{out}'\]"):
            ds[0]


def test_max_lights_default_follows_the_corpus(corpus, monkeypatch):
    """The padded per-light ``meta`` arrays are long enough for every scene by default (a 640x360 night scene
    of lfmbench-v1 has 66 lights, more than the old fixed 64); an explicit value too small is refused at
    construction, naming the scene, instead of failing at that scene's first sample."""
    from lfmbench.datasets import capture

    most = max(len(C.Corpus(corpus).meta(s)["lights"]) for s in C.Corpus(corpus).scenes)
    assert LFMCaptureDataset(corpus, split="all").max_lights == max(64, most)
    monkeypatch.setattr(capture, "DEFAULT_MAX_LIGHTS", 1)
    ds = LFMCaptureDataset(corpus, split="all", outputs=["gt"])
    assert ds.max_lights == most > 1
    assert ds[0]["meta"]["light_id"].shape == (most,)
    with pytest.raises(ValueError, match=r"max_lights=1 but scene 'scene\d+' of .* has \d+ lights"):
        LFMCaptureDataset(corpus, split="all", max_lights=1)
