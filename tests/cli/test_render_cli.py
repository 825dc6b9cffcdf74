"""``lfmbench render`` orchestration (lfmbench.cli.render, render_tools.jobs): resume, atomicity, bad input, pool, Ray.

Most tests use the real scene generator, scene validation, RenderOptions and ``scene_meta`` (no Mitsuba) with a
fake ``render_frames`` that returns seeded random radiance of the right shapes, so the orchestration is tested
in milliseconds; one end-to-end test renders a tiny scene with Mitsuba.
"""
from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from lfmbench import corpus as C
from lfmbench.cli import app
from render_tools import jobs as J

from tests.data.corpus.data import disk_full_after
from tests.data.render.data import ARGS, CRASH_ENV, FAIL, fake_backend, run


def _line_of(text: str) -> int:
    """Line number of ``text`` in tests/data/render/data.py."""
    from tests.data.render import data

    return next(i for i, ln in enumerate(open(data.__file__).read().splitlines(), 1) if text in ln)


def _no_tmp(root):
    return not list(root.rglob(C.TMP_PREFIX + "*"))


# ------------------------------------------------------------------------------------------ resume
def test_render_resume_and_extend(tmp_path, fake):
    out = tmp_path / "c"
    r = run("--out", str(out), "--scenes", "2", "--seed", "7", *ARGS)
    assert r.exit_code == 0, r.output
    assert fake == ["scene00000", "scene00001"]
    rep = C.validate_corpus(out)
    assert rep.ok, rep.errors
    c = C.Corpus(out)
    m = c.meta("scene00000")
    assert (m["width"], m["height"], m["frames"], m["timing"]["bins"]) == (24, 16, 2, 2)
    assert json.loads((out / "manifest.json").read_text())["render"]["seed"] == 7
    splits = c.splits
    assert sorted(sum(splits.values(), [])) == ["scene00000", "scene00001"] and len(splits["test"]) == 1
    first = {p: p.read_bytes() for p in out.rglob("*.exr")}
    # same command: everything skipped
    r = run("--out", str(out), "--scenes", "2", "--seed", "7", *ARGS)
    assert r.exit_code == 0 and "2 skipped" in r.output
    assert fake == ["scene00000", "scene00001"]
    # extend to 3 scenes: only the new one renders; scene 0 and 1 are untouched
    r = run("--out", str(out), "--scenes", "3", "--seed", "7", *ARGS)
    assert r.exit_code == 0 and "1 rendered" in r.output
    assert fake[-1] == "scene00002" and len(fake) == 3
    assert all(p.read_bytes() == b for p, b in first.items())
    # a corrupted file: that scene (only) is rendered again
    p = out / "scenes/scene00001/f001/aux.exr"
    p.write_bytes(p.read_bytes()[:-10])
    r = run("--out", str(out), "--scenes", "3", "--seed", "7", *ARGS)
    assert r.exit_code == 0, r.output
    assert fake[-1] == "scene00001" and len(fake) == 4
    assert C.validate_corpus(out).ok


def test_scene_seeds_independent_of_count():
    assert J.scene_seed(7, 2) == J.scene_seed(7, 2)
    assert len({J.scene_seed(7, i) for i in range(50)}) == 50
    assert J.scene_seed(7, 0) != J.scene_seed(8, 0)
    a = J.make_jobs("o", n_scenes=2, seed=3, options={})
    b = J.make_jobs("o", n_scenes=5, seed=3, options={})
    assert [j.seed for j in a] == [j.seed for j in b[:2]]


# ------------------------------------------------------------------------------- crash / interrupt
def test_crash_in_one_scene(tmp_path, fake):
    out = tmp_path / "c"
    FAIL["scene00001"] = RuntimeError
    r = run("--out", str(out), "--scenes", "3", *ARGS)
    assert r.exit_code == 1
    assert "scene scene00001 failed" in r.output and "simulated failure" in r.output
    assert C.Corpus(out).scenes == ["scene00000", "scene00002"]
    assert C.validate_corpus(out).ok
    FAIL.clear()
    r = run("--out", str(out), "--scenes", "3", *ARGS)
    assert r.exit_code == 0 and "1 rendered" in r.output and "2 skipped" in r.output
    assert C.validate_corpus(out).ok


@pytest.mark.slow
@pytest.mark.parametrize("workers,crashes", [(2, {"scene00001": ("SIGFPE", "integer division by zero"),
                                                  "scene00002": ("SIGSEGV", "native code")}),
                                             (1, {"scene00001": ("SIGFPE", "integer division by zero"),
                                                  "scene00002": ("SIGKILL", "out-of-memory")})],
                         ids=["2-SIGFPE-SIGSEGV", "1-SIGFPE-SIGKILL"])
def test_a_worker_killed_by_a_signal_is_reported_and_the_others_go_on(tmp_path, fake, monkeypatch, workers, crashes):
    """A render whose process dies (a native crash: SIGFPE as Dr.Jit's masked-lane division did, SIGSEGV; the
    OOM killer's SIGKILL) fails its own scene, named with the signal and a hint; the other scenes render in a
    fresh worker; exit 1; the same command again renders only those scenes. Also with --workers 1 (the render
    runs in one worker process, never in the CLI's own). Two crashes per run: each worker start imports the
    renderer's modules (about 2 s of CPU), so the signals share runs instead of starting four of their own."""
    monkeypatch.setattr(J, "ISOLATE_RENDERS", True)  # the fake renders in spawned workers (it pickles by reference)
    monkeypatch.setenv(CRASH_ENV, ",".join(f"{sid}:{sig}" for sid, (sig, _) in crashes.items()))
    out = tmp_path / "c"
    r = run("--out", str(out), "--scenes", "4", "--workers", str(workers), *ARGS)
    assert r.exit_code == 1, r.output
    msg = " ".join(r.output.split())
    for sid, (sig, words) in crashes.items():
        # where in Python it died, from the worker's faulthandler dump (none for SIGKILL, which no handler sees)
        at = "" if sig == "SIGKILL" else f" (Python frame: data.py:{_line_of('os.kill(')} in fake_render_frames)"
        own = re.split(r"scene scene\d+ failed: ", msg.split(f"scene {sid} failed: ", 1)[-1])[0]  # its message
        assert own.startswith(f"WorkerDied: the render worker process died while rendering scene {sid}{at}: "
                              f"killed by {sig}") and words in own, msg
    assert "scene00000 failed" not in msg and "scene00003 failed" not in msg
    assert C.Corpus(out).scenes == ["scene00000", "scene00003"] and C.validate_corpus(out).ok
    assert _no_tmp(out)  # nothing half-written left behind
    monkeypatch.delenv(CRASH_ENV)
    r = run("--out", str(out), "--scenes", "4", "--workers", str(workers), *ARGS)
    assert r.exit_code == 0 and "2 rendered" in r.output and "2 skipped" in r.output
    assert C.validate_corpus(out).ok


def test_ctrl_c_leaves_valid_corpus_and_resumes(tmp_path, fake):
    out = tmp_path / "c"
    FAIL["scene00001"] = KeyboardInterrupt
    r = run("--out", str(out), "--scenes", "3", *ARGS)
    assert r.exit_code == 130
    assert "interrupted" in r.output and "Run the same command again to resume" in r.output
    assert fake == ["scene00000", "scene00001"]  # stopped at once
    man = json.loads((out / "manifest.json").read_text())
    assert man["scenes"] == ["scene00000"]
    assert not any(k.startswith("scenes/scene00001") for k in man["files"])
    assert _no_tmp(out)
    FAIL.clear()
    r = run("--out", str(out), "--scenes", "3", *ARGS)
    assert r.exit_code == 0, r.output
    assert fake[2:] == ["scene00001", "scene00002"]
    rep = C.validate_corpus(out)
    assert rep.ok and rep.warnings == [], (rep.errors, rep.warnings)


def test_disk_full(tmp_path, fake, monkeypatch):
    out = tmp_path / "c"
    assert run("--out", str(out), "--scenes", "1", *ARGS).exit_code == 0
    before = (out / "manifest.json").read_bytes()
    real = disk_full_after(monkeypatch, 2)
    r = run("--out", str(out), "--scenes", "2", *ARGS)
    monkeypatch.setattr(os, "fsync", real)
    assert r.exit_code == 2
    assert "disk full" in r.output and "re-run to resume" in r.output
    assert (out / "manifest.json").read_bytes() == before
    assert _no_tmp(out)
    assert C.validate_corpus(out).ok
    assert run("--out", str(out), "--scenes", "2", *ARGS).exit_code == 0
    assert C.Corpus(out).scenes == ["scene00000", "scene00001"]


# ---------------------------------------------------------------------------------------- bad input
def test_bad_options(tmp_path, fake):
    out = tmp_path / "c"
    r = run("--out", str(out), "--width", "0", "--profile", "small")
    assert r.exit_code == 2 and "--width must be an integer >= 1" in r.output
    r = run("--out", str(out), "--bins", "0", "--profile", "small")  # no bins cannot cover the windows
    assert r.exit_code == 2 and "--bins must be an integer >= 1" in r.output
    r = run("--out", str(out), "--profile", "huge")
    assert r.exit_code == 2 and "profile: 'huge'" in r.output
    prof = tmp_path / "p.yaml"
    prof.write_text("width: 16\nheight: 8\nspp: 1\nlong_exposure_s: 0.02\n")  # exposure > frame time 1/60 s
    r = run("--out", str(out), "--profile", str(prof))
    assert r.exit_code == 2 and "long_exposure_s" in r.output and "frame time" in r.output
    prof.write_text("width: 16\nwarp: 9\n")
    r = run("--out", str(out), "--profile", str(prof))
    assert r.exit_code == 2 and "warp" in r.output
    r = run("--out", str(out), "--groups", "headlights,moonlight", *ARGS)
    assert r.exit_code == 2 and "moonlight" in r.output
    assert fake == []
    # resuming with different options is refused (the corpus would mix renders)
    assert run("--out", str(out), "--scenes", "1", *ARGS).exit_code == 0
    r = run("--out", str(out), "--scenes", "1", *ARGS[:-4], "--bins", "3", "--profile", "small")
    assert r.exit_code == 2 and "different options" in r.output


def test_scene_files(tmp_path, fake):
    from render_tools.scene import generate_scene

    sc = generate_scene(3, scene_id="my_street")
    good = tmp_path / "good.json"
    good.write_text(json.dumps(sc))
    out = tmp_path / "c"
    r = run("--out", str(out), "--scene", str(good), *ARGS)
    assert r.exit_code == 0, r.output
    c = C.Corpus(out)
    assert c.scenes == ["my_street"] and c.scene("my_street") == sc
    bad = dict(sc, colour="blue")  # unknown field
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(bad))
    r = run("--out", str(tmp_path / "d"), "--scene", str(p), *ARGS)
    assert r.exit_code == 2 and "colour" in r.output and "bad.json" in r.output
    neg = json.loads(json.dumps(sc))
    neg["camera"]["speed_mps"] = -5.0
    p.write_text(json.dumps(neg))
    r = run("--out", str(tmp_path / "d"), "--scene", str(p), *ARGS)
    assert r.exit_code == 2 and "speed_mps" in r.output
    p.write_text("{not json")
    r = run("--out", str(tmp_path / "d"), "--scene", str(p), *ARGS)
    assert r.exit_code == 2 and "cannot read scene JSON" in r.output
    assert fake == ["my_street"]


# ------------------------------------------------------------------------- encoding overlaps rendering
def test_frame_is_encoded_while_the_next_one_renders(tmp_path, monkeypatch):
    """run_job: frame 0's EXR encoding (worker thread) is still running when frame 1's render starts (main
    thread); a serial loop would only render frame 1 after frame 0's files are written (here: a timeout)."""
    import threading

    from lfmbench.corpus import scene_files as W
    from tests.data.render import data as R

    started_1 = threading.Event()
    seen = {}
    real_frames, real_encode = R.fake_render_frames, W.encode_static_exr

    def frames(scene, opts):
        for fr in real_frames(scene, opts):
            if fr["frame"] == 1:
                started_1.set()
            seen.setdefault("render_thread", threading.current_thread().name)
            yield fr

    def encode(*a, **k):
        if k["attrs"][C.ATTR["frame"]] == 0:
            seen["overlap"] = started_1.wait(20)  # frame 0 is being encoded: does frame 1 render meanwhile?
            seen["encode_thread"] = threading.current_thread().name
        return real_encode(*a, **k)
    monkeypatch.setattr(W, "encode_static_exr", encode)
    be = fake_backend()
    be = J.Backend(be.generate_scene, be.RenderOptions, be.scene_meta, frames, be.validate_scene)
    job = J.make_jobs(tmp_path / "c", n_scenes=1, seed=1, options={"width": 24, "height": 16, "spp": 2,
                                                                   "frames": 2, "bins": 2}, backend=be)[0]
    res = J.run_job(job)
    assert seen["overlap"] is True
    assert seen["render_thread"] == "MainThread" and seen["encode_thread"].startswith("lfmbench-writer")
    assert res["hashes"] and all((tmp_path / "c" / rel).is_file() for rel in res["hashes"])


# --------------------------------------------------------------------------------------- pool / Ray
@pytest.mark.slow
def test_process_pool(tmp_path):
    """Two spawn workers write their scenes; the driver's manifest matches what a serial run in this process
    gives (``isolate=False``: the reference needs no third worker process)."""
    out = tmp_path / "c"
    from render_tools import render

    opts = {"width": 24, "height": 16, "spp": 2, "frames": 2, "bins": 2}
    jobs = J.make_jobs(out, n_scenes=2, seed=1, options=opts, backend=fake_backend())
    w = C.CorpusWriter(out)
    s = J.run_jobs(jobs, w, workers=2)
    assert sorted(s.rendered) == ["scene00000", "scene00001"] and not s.failed
    w.write_splits(1)
    assert C.validate_corpus(out).ok
    out2 = tmp_path / "serial"
    w2 = C.CorpusWriter(out2)
    J.run_jobs(J.make_jobs(out2, n_scenes=2, seed=1, options=opts, backend=fake_backend()), w2, workers=1,
               isolate=False)
    assert json.loads((out / "manifest.json").read_text())["files"] == \
        json.loads((out2 / "manifest.json").read_text())["files"]  # deterministic, worker-independent
    assert render.RenderOptions(**opts).bins == 2


@pytest.mark.slow
def test_ray_local(tmp_path):
    ray = pytest.importorskip("ray")
    from ray import cloudpickle

    from tests.data.render import data as render_data

    cloudpickle.register_pickle_by_value(render_data)  # workers need not import the tests package
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        out = tmp_path / "c"
        opts = {"width": 24, "height": 16, "spp": 2, "frames": 2, "bins": 2}
        jobs = J.make_jobs(out, n_scenes=2, seed=4, options=opts, backend=fake_backend())
        FAIL["scene00001"] = RuntimeError  # pickled by value with the function: fails on the worker
        w = C.CorpusWriter(out)
        s = J.run_jobs(jobs, w, ray_address="local")
        assert s.rendered == ["scene00000"]
        assert "simulated failure" in s.failed["scene00001"]
        FAIL.clear()
        jobs = J.make_jobs(out, n_scenes=2, seed=4, options=opts, backend=fake_backend())
        s = J.run_jobs(jobs, w, ray_address="local")
        assert s.rendered == ["scene00001"] and s.skipped == ["scene00000"]
        w.write_splits(4)
        assert C.validate_corpus(out).ok
    finally:
        ray.shutdown()
        cloudpickle.unregister_pickle_by_value(render_data)
        FAIL.clear()


# ----------------------------------------------------------------------------------------- end to end
@pytest.mark.slow
@pytest.mark.jit
def test_render_end_to_end_mitsuba(tmp_path, monkeypatch):
    """The real renderer: 32x18 px, 4 spp, 1 scene, 2 frames, through the CLI; then validate and read."""
    llvm = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"
    if "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(llvm):
        monkeypatch.setenv("DRJIT_LIBLLVM_PATH", llvm)  # fast path; render_tools.backend falls back otherwise
    out = tmp_path / "c"
    r = run("--out", str(out), "--scenes", "1", "--width", "32", "--height", "18", "--spp", "4", "--frames", "2",
            "--bins", "2", "--seed", "1", "--profile", "small")
    assert r.exit_code == 0, r.output
    assert CliRunner().invoke(app, ["validate", str(out)]).exit_code == 0
    c = C.Corpus(out)
    sid = c.scenes[0]
    m = c.meta(sid)
    assert m["frames"] == 2 and m["bands_nm"][0] == 400.0 and len(m["bands_nm"]) == 31
    total = 0.0
    for g, v in m["groups"].items():
        if C.group_storage(m, g) == "static":
            a = c.read_static(sid, 1, g, "long")
            assert a.shape == (31, 18, 32)
            total += float(a.sum())
        else:
            for lid, (y0, x0, y1, x1), a in c.read_light_bins(sid, 1, g):
                assert a.shape == (2, 31, y1 - y0, x1 - x0)
                assert any(lt["id"] == lid and lt["group"] == g for lt in m["lights"])
    assert total > 0  # something is lit
    aux = c.read_aux(sid, 0)
    assert aux["depth.Z"].shape == (18, 32) and np.nanmin(aux["depth.Z"]) > 0


# ------------------------------------------------------------------------------------------ storage
def test_render_storage_default_and_resume(tmp_path, fake):
    """New corpora default to the compact storage; a resume without --storage keeps the corpus's own."""
    out = tmp_path / "c"
    r = run("--out", str(out), "--scenes", "1", *ARGS)
    assert r.exit_code == 0, r.output
    man = json.loads((out / "manifest.json").read_text())
    assert man["render"]["dtype"] == C.DEFAULT_STORAGE and man["version"] == C.FORMAT_VERSION
    assert C.Corpus(out).meta("scene00000")["storage"]["compression"] == C.STORAGES[C.DEFAULT_STORAGE].compression
    # a float32 corpus (as rendered before format 2) resumes as float32 when --storage is not given
    old = tmp_path / "old"
    assert run("--out", str(old), "--scenes", "1", "--storage", "float32", *ARGS).exit_code == 0
    r = run("--out", str(old), "--scenes", "2", *ARGS)
    assert r.exit_code == 0 and "1 rendered" in r.output, r.output
    assert C.Corpus(old).meta("scene00001")["storage"]["dtype"] == "float32"
    r = run("--out", str(old), "--scenes", "2", "--storage", "compact", *ARGS)
    assert r.exit_code == 2 and "dtype" in r.output  # different options on an existing corpus
    # a storage outside lfmbench.corpus.STORAGES: tests/cli/test_cli_choices.py


def test_a_job_that_does_not_pickle_is_refused_before_any_worker_starts(tmp_path):
    be = fake_backend()
    local = J.Backend(be.generate_scene, be.RenderOptions, be.scene_meta, lambda s, o: be.render_frames(s, o))
    out = tmp_path / "c"
    w = C.CorpusWriter(out)
    with pytest.raises(ValueError, match=r"job scene00000 does not pickle.*isolate=False"):
        J.run_jobs(J.make_jobs(out, n_scenes=1, seed=0, options={"width": 8, "height": 6}, backend=local), w)
    assert C.Corpus(out).scenes == []
    s = J.run_jobs(J.make_jobs(out, n_scenes=1, seed=0, options={"width": 8, "height": 6}, backend=local), w,
                   isolate=False)
    assert s.rendered == ["scene00000"]


def test_render_request_is_planned_without_the_command_line(tmp_path):
    """``render_tools.jobs.plan_render`` turns a request into its jobs (seeds derived from the run seed, the
    profile's options with the given ones on top) and refuses a bad request with a one-line error naming the
    option, before any corpus is opened (the storage on resume: test_render_storage_default_and_resume)."""
    be = fake_backend()
    req = J.RenderRequest(out=tmp_path / "c", scenes=3, seed=7, width=24, height=16, profile="small",
                          groups=["headlights"])
    plan = J.plan_render(req, be)
    assert [j.seed for j in plan.jobs] == [J.scene_seed(7, i) for i in range(3)]
    assert [j.scene_id for j in plan.jobs] == [J.scene_id_for(i) for i in range(3)]
    assert plan.options == {**J.load_profile("small"), "width": 24, "height": 16, "groups": ["headlights"]}
    assert plan.seed == 7 and plan.splits is None and plan.dtype == C.DEFAULT_STORAGE
    for bad, match in ((dict(scenes=0), "--scenes must be an integer >= 1"),
                       (dict(width=0), "--width must be an integer >= 1"),
                       (dict(frames=301), "--frames 301 is above the sanity limit"),
                       (dict(splits=["test"]), "--split needs --protocol"),
                       (dict(protocol="lfmbench-v1-mini", seed=1), "--seed cannot be combined with --protocol"),
                       (dict(storage="nope"), "--storage must be one of")):
        with pytest.raises(J.RenderRequestError, match=match):
            J.plan_render(J.RenderRequest(out=tmp_path / "d", **bad), be)
    assert J.plan_render(J.RenderRequest(out=tmp_path / "e", profile="small", half=True), be).dtype == "float16"
    assert set(J.profile_names()) >= {"small", "default", "hq"}
