"""The paper's 1920 x 1080 (capture window longer than the frame time) and long sequences (24, 100 frames):
options, metadata, streaming corpus writes, windows of F frames in the dataset, and `lfmbench evaluate --frames 24`."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from lfmbench import corpus as C
from lfmbench.cli import app
from lfmbench.datasets import LFMCaptureDataset, compose_frame
from lfmbench.datasets.assembly import row_window_starts, window_bin_exposure
from lfmbench.datasets.pwm import draw_scene_pwm
from lfmbench.datasets.projection import build_layers
from lfmbench.sensor import load_preset
from render_tools import jobs as J
from render_tools import render, scene
from tests.data.corpus.data import fake_frames, fake_meta, fake_scene
from tests.data.corpus.data import make_corpus

LLVM = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"


# ---------------------------------------------------------------------------------------- 1920 x 1080
def test_paper_resolution_capture_window_longer_than_frame_time_is_accepted():
    opts = render.RenderOptions(width=1920, height=1080, fps=60.0, line_time_s=10e-6, frames=2)
    assert opts.readout_s == pytest.approx(1080 * 10e-6)
    assert opts.capture_window_s == pytest.approx(1 / 90 + 0.0108) and opts.capture_window_s > 1 / 60
    meta = render.scene_meta(scene.generate_scene(3, "night"), opts)
    C.validate_meta(meta)  # the corpus format accepts it
    assert meta["timing"]["capture_window_s"] == pytest.approx(opts.capture_window_s)
    tm1 = render.frame_timing(scene.empty_scene(short_exposure_s=0.004), opts, 1)
    assert tm1["window"] == pytest.approx((1 / 60, 1 / 60 + opts.capture_window_s))
    assert tm1["bin_edges"][-1] == pytest.approx(1 / 60 + opts.capture_window_s)
    # an exposure still cannot be longer than the frame
    with pytest.raises(ValueError, match=r"long_exposure_s.*frame time"):
        render.RenderOptions(width=1920, height=1080, long_exposure_s=0.02)
    with pytest.raises(ValueError, match="long_exposure_s"):
        C.validate_meta({**meta, "timing": {**meta["timing"], "long_exposure_s": 0.02,
                                            "capture_window_s": 0.02 + meta["timing"]["readout_s"]}})


@pytest.mark.slow
@pytest.mark.jit
def test_tiny_render_with_overlapping_capture_windows_loads_with_rolling_shutter(tmp_path, monkeypatch):
    """16 x 8 px with a 2 ms line time: readout 16 ms, capture window 27.1 ms > 1/60 s. Rendered by the real
    renderer, validated, and simulated with a rolling shutter; row windows checked against the analytic timing."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(LLVM):
        monkeypatch.setenv("DRJIT_LIBLLVM_PATH", LLVM)
    # rendered in this process like the other render tests: a worker process would import the renderer again
    # (about 4 s of CPU); the worker isolation has its own tests (tests/cli/test_render_cli.py)
    monkeypatch.setattr(J, "ISOLATE_RENDERS", False)
    prof = tmp_path / "p.yaml"
    prof.write_text("width: 16\nheight: 8\nspp: 1\nlight_spp: 1\nbins: 2\nframes: 2\nline_time_s: 0.002\n"
                    "groups: [headlights, otherlights]\n")
    out = tmp_path / "c"
    r = CliRunner().invoke(app, ["render", "--out", str(out), "--scenes", "1", "--seed", "2", "--profile", str(prof)])
    assert r.exit_code == 0, r.output
    assert CliRunner().invoke(app, ["validate", str(out)]).exit_code == 0
    c = C.Corpus(out)
    sid = c.scenes[0]
    meta = c.meta(sid)
    fps, tl, td = meta["fps"], meta["timing"]["long_exposure_s"], meta["timing"]["line_time_s"]
    cw = meta["timing"]["capture_window_s"]
    assert td == 0.002 and cw == pytest.approx(1 / 90 + 8 * 0.002) and cw > 1 / fps
    rows = np.arange(8.0)
    s1 = row_window_starts(meta, 1, rows, "rolling")["spd"]
    np.testing.assert_allclose(s1, 1 / 60 + rows * 0.002, rtol=0, atol=1e-15)  # analytic row starts
    end0 = 0 / 60 + cw  # frame 0's capture window ends at t_0 + T_L + H * line_time
    assert s1[0] < end0 and np.sum(s1 < end0) == 6  # rows 0..5 of frame 1 open before frame 0's window closes
    for n in range(2):  # every row's windows lie inside frame n's bins (exact coverage: overlap = length)
        edges = n / fps + np.linspace(0.0, cw, 3)
        st = row_window_starts(meta, n, rows, "rolling")
        for pd, length in (("lpd", meta["timing"]["short_exposure_s"]), ("spd", tl)):
            cover = window_bin_exposure(edges, st[pd], length, 1.0, 1.0, 0.0, level="mean").sum(1)
            np.testing.assert_allclose(cover, length, rtol=1e-12)
    ds = LFMCaptureDataset(out, split="all", frames=2, shutter="rolling", noise=False, cache_dir=False)
    s = ds[0]
    assert s["gt"].shape == (2, 1, 8, 16) and torch.isfinite(s["gt"]).all() and float(s["gt"].sum()) > 0
    assert torch.isfinite(s["spd_e"]).all()


# ------------------------------------------------------------------------------------- long sequences
def test_encode_and_job_stream_frames_without_collecting_them(tmp_path):
    """run_job streams: frame n is written (in the writer thread) while frame n + 1 renders, and frame n + 2 is
    not rendered before frame n is on disk: nothing collects the frames (at most one frame is pending)."""
    from tests.data.render import data as T

    pulled = []
    out = tmp_path / "c"

    def streaming_render(scene_, opts):
        for fr in T.fake_render_frames(scene_, opts):
            n = fr["frame"]
            if n > 1:  # the frame before the previous one is already on disk
                assert (out / "scenes" / "scene00000" / C.frame_dir(n - 2) / "aux.exr").is_file()
            pulled.append(n)
            yield fr

    from render_tools import render as R, scene as S

    be = J.Backend(S.generate_scene, R.RenderOptions, R.scene_meta, streaming_render, S.validate_scene)
    opts = {"width": 8, "height": 6, "spp": 1, "bins": 2, "frames": 24, "groups": ["headlights", "otherlights"]}
    w = C.CorpusWriter(out, render=J.render_record(0, opts, "float32", {}))
    # in this process: the local renderer does not pickle, and ``pulled`` must be this process's list
    s = J.run_jobs(J.make_jobs(out, n_scenes=1, seed=0, options=opts, backend=be), w, isolate=False)
    assert s.rendered == ["scene00000"] and pulled == list(range(24))
    assert C.Corpus(out).meta("scene00000")["frames"] == 24


def test_hundred_frame_corpus_validates_and_loads(tmp_path):
    root = tmp_path / "c"
    w = C.CorpusWriter(root)
    meta = fake_meta("scene00000", width=8, height=4, frames=100, bins=2, n_lights=1)
    w.write_scene("scene00000", fake_scene("scene00000"), meta, iter(fake_frames(meta)))
    w.write_splits(0)
    rep = C.validate_corpus(root, check_pixels=False)
    assert not rep.errors, rep.errors
    ds = LFMCaptureDataset(root, split="all", frames=100, crop=None, noise=False, optics=False, cache_dir=False,
                           outputs=("gt",))
    assert ds[0]["gt"].shape == (100, 1, 4, 8)


@pytest.fixture(scope="module")
def long_corpus(tmp_path_factory):
    return make_corpus(tmp_path_factory.mktemp("long"), n_scenes=2, frames=24, bins=3)


def _expected_gt(root, sid, start, F, params):
    c = C.Corpus(root)
    layers = build_layers(c, sid, load_preset("ovt"), None, start + F, optics=False)
    meta = c.meta(sid)
    H, W = meta["height"], meta["width"]
    return torch.stack([compose_frame(layers, meta, f, (0, 0, H, W), params, {})["gt"]
                        for f in range(start, start + F)])[:, None]


def test_dataset_windows_of_a_24_frame_corpus(long_corpus):
    kw = dict(split="all", noise=False, cache_dir=False, optics=False)
    first = LFMCaptureDataset(long_corpus, frames=3, **kw)  # default: frames 0..2
    s = first[0]
    assert s["meta"]["frame_start"] == 0 and s["gt"].shape[0] == 3
    sid = first.scene_ids[0]
    params = {int(k): v for k, v in draw_scene_pwm(first.pwm, first.corpus.meta(sid), np.random.default_rng([0, 0, 0]), first.groups).to_dicts()[0].items()}
    torch.testing.assert_close(s["gt"], _expected_gt(long_corpus, sid, 0, 3, params))
    later = LFMCaptureDataset(long_corpus, frames=3, frame_start=20, **kw)
    t = later[0]
    assert t["meta"]["frame_start"] == 20
    torch.testing.assert_close(t["meta"]["duty"], s["meta"]["duty"])  # same draws, later frames
    torch.testing.assert_close(t["gt"], _expected_gt(long_corpus, sid, 20, 3, params))
    assert not torch.equal(t["gt"], s["gt"])
    # the aux outputs follow the window
    aux = C.Corpus(long_corpus).read_aux(sid, 21)
    assert torch.equal(t["depth"][1, 0], torch.from_numpy(aux["depth.Z"]))
    full = LFMCaptureDataset(long_corpus, frames=24, **kw)[0]
    assert full["gt"].shape == (24, 1, 16, 24)
    torch.testing.assert_close(full["gt"][20:23], t["gt"])
    with pytest.raises(ValueError, match="frame_start"):
        LFMCaptureDataset(long_corpus, frames=3, frame_start=22, **kw)
    with pytest.raises(ValueError, match="frame_start"):
        LFMCaptureDataset(long_corpus, frames=3, frame_start="middle", **kw)
    with pytest.raises(ValueError, match="frames"):
        LFMCaptureDataset(long_corpus, frames=25, **kw)


def test_random_windows_cover_the_sequence_and_keep_the_other_draws(long_corpus):
    kw = dict(split="all", frames=3, noise=False, optics=False, cache_dir=False, samples_per_scene=8,
              outputs=("gt",))
    rnd = LFMCaptureDataset(long_corpus, frame_start="random", **kw)
    starts = set()
    for epoch in range(2):
        rnd.set_epoch(epoch)
        for i in range(len(rnd)):
            a = rnd[i]
            s0 = int(a["meta"]["frame_start"])
            assert 0 <= s0 <= 21
            starts.add(s0)
            b = rnd.simulate(rnd.scene_ids[i // 8], *_draws(rnd, i), frame_start=s0)
            torch.testing.assert_close(a["gt"], b["gt"])  # same PWM and crop as frame_start=0, frames s0..
    assert len(starts) >= 8  # 32 draws over 22 possible starts
    # reproducible per (seed, epoch, index)
    rnd.set_epoch(1)
    assert rnd[3]["meta"]["frame_start"] == rnd[3]["meta"]["frame_start"]


def _draws(ds, index):
    """The (params, group_params, crop, noise_seed, index) that __getitem__ of ``ds`` uses for ``index``."""
    sid = ds.scene_ids[index // ds.samples_per_scene]
    m = ds.corpus.meta(sid)
    rng = np.random.default_rng([ds.seed, ds.epoch, index])
    per_light, per_group = draw_scene_pwm(ds.pwm, m, rng, ds.groups).to_dicts()
    noise_seed = int(rng.integers(2**62))
    H, W = m["height"], m["width"]
    return per_light, per_group, (0, 0, H, W), noise_seed, index


def test_random_windows_of_the_test_split_are_frozen(tmp_path):
    root = make_corpus(tmp_path / "c", n_scenes=5, frames=12, bins=2)
    kw = dict(split="test", frames=3, noise=False, optics=False, cache_dir=False, samples_per_scene=4,
              outputs=("gt",))
    a = LFMCaptureDataset(root, frame_start="random", **kw)
    data = json.loads((root / "test_params.json").read_text())["samples"]
    assert all(0.0 <= v["frame_u"] < 1.0 for v in data.values())
    starts = [int(a[i]["meta"]["frame_start"]) for i in range(len(a))]
    assert len(set(starts)) > 1
    b = LFMCaptureDataset(root, frame_start="random", seed=7, **kw)
    b.set_epoch(3)
    assert [int(b[i]["meta"]["frame_start"]) for i in range(len(b))] == starts
    # the fixed-start test split is unchanged by the added field (PWM draws as before)
    c = LFMCaptureDataset(root, **kw)
    assert torch.equal(c[0]["meta"]["duty"], a[0]["meta"]["duty"]) and c[0]["meta"]["frame_start"] == 0


def test_evaluate_cli_scores_24_frame_sequences_end_to_end(long_corpus, tmp_path):
    """``lfmbench evaluate --frames 24`` on the 24-frame corpus: every light's P2020 series spans the 24 frames and
    its FMI / MMP / FDI are those of :mod:`lfmbench.metrics.flicker` (checked against the public reference in
    test_p2020_reference.py) on the stored series; asking for more frames than the corpus holds is refused, and a
    3-frame run is not ranked with it."""
    from lfmbench.metrics import flicker as fm

    out = tmp_path / "runs" / "fa.json"
    threads = torch.get_num_threads()
    try:
        r = CliRunner().invoke(app, ["evaluate", "--method", "flicker_aware", "--corpus", str(long_corpus), "--split",
                                     "all", "--frames", "24", "--max-scenes", "1", "--output", str(out),
                                     "--repeats", "1", "--warmup", "0", "--no-perceptual", "--threads", "1"])
    finally:
        torch.set_num_threads(threads)
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    assert d["status"] == "complete" and d["dataset"]["frames"] == 24
    sc = d["scenes"][0]
    assert sc["status"] == "ok"
    m = sc["metrics"]
    assert m["n_lights"] >= 1 and m["region_frames"] == 24 * m["n_lights"]
    for light in m["lights"]:
        p, g = light["series_pred"], light["series_gt"]
        assert light["frames"] == len(p) == len(g) == 24
        assert light["fmi_pred"] == pytest.approx(float(fm.fmi(p)), rel=1e-12)
        assert light["fmi_gt"] == pytest.approx(float(fm.fmi(g)), rel=1e-12)
        assert light["mmp_pred"] == float(fm.mmp(p)) and light["mmp_gt"] == float(fm.mmp(g))
        assert 0.0 <= light["fdi_pred"] <= 1.0
    assert sc["megapixels"] == pytest.approx(24 * 16 * 24 / 1e6)  # F x H x W of one sample
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(long_corpus), "--split", "all",
                                 "--frames", "25", "--output", str(tmp_path / "x.json"), "--no-perceptual"])
    assert r.exit_code == 2 and "frames=25" in r.output
    # a run over 3-frame samples is another protocol: the leaderboard refuses to rank the two together
    three = tmp_path / "runs" / "fa3.json"
    r = CliRunner().invoke(app, ["evaluate", "--method", "flicker_aware", "--corpus", str(long_corpus), "--split",
                                 "all", "--max-scenes", "1", "--output", str(three), "--repeats", "1", "--warmup", "0",
                                 "--no-perceptual", "--threads", "1"])
    torch.set_num_threads(threads)
    assert r.exit_code == 0, r.output
    assert json.loads(three.read_text())["dataset"]["frames"] == 3
    r = CliRunner().invoke(app, ["leaderboard", str(out), str(three), "--markdown", str(tmp_path / "l.md"),
                                 "--plot", str(tmp_path / "l.png"), "--json", str(tmp_path / "l.json")])
    assert r.exit_code == 2 and "frames per sample differs" in r.output, r.output


def test_benchmark_scores_24_frame_sequences(long_corpus, tmp_path):
    """``benchmark(frames=24)`` (the library call behind a leaderboard run) scores 24-frame series like
    ``evaluate --frames 24``, and records the frame count, so that its runs are not ranked with 3-frame ones."""
    from lfmbench.evaluation.benchmark import benchmark

    rows = benchmark(long_corpus, ["lpd_only"], tmp_path / "runs", split="all", perceptual=False, repeats=1,
                        progress=False, max_scenes=1, frames=24)
    assert [r["method"] for r in rows] == ["lpd_only"]
    d = json.loads((tmp_path / "runs" / "lpd_only.json").read_text())
    assert d["dataset"]["frames"] == 24
    assert all(light["frames"] == 24 for light in d["scenes"][0]["metrics"]["lights"])
