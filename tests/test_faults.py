"""Fault catalogue (docs/guide/fault-catalogue.md): hostile or broken corpora, interrupted runs, absurd arguments.

Tiny generated corpora only (no rendering, no network, no GPU).
"""
from __future__ import annotations

import json
import os
import pickle
import signal
import warnings

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from lfmbench import corpus as C
from lfmbench.cli import app
from lfmbench.datasets import LFMCaptureDataset
from lfmbench.datasets import projection as P
from render_tools import jobs as J
from tests.data.corpus.data import make_corpus
from tests.data.render.data import ARGS, FAIL, mitsuba_sigint, run


@pytest.fixture
def one(tmp_path):
    return make_corpus(tmp_path / "c", n_scenes=1)


def _entry(root):
    files = list((root / ".cache").rglob("*.pt"))
    assert len(files) == 1, files
    return files[0]


# ----------------------------------------------------------------------------------- 1. cache runs no code
class _Evil:
    def __reduce__(self):
        return (os.system, ("touch PWNED_BY_CACHE",))


def test_crafted_cache_entry_runs_no_code_and_is_rebuilt(one, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    gt = LFMCaptureDataset(one, split="all", noise=False)[0]["gt"]
    p = _entry(one)
    p.write_bytes(pickle.dumps(_Evil(), protocol=2))  # what torch.load(weights_only=False) would execute
    P._warned.clear()
    with pytest.warns(P.CacheWarning, match="unreadable") as rec:
        again = LFMCaptureDataset(one, split="all", noise=False)[0]["gt"]
    assert not (tmp_path / "PWNED_BY_CACHE").exists()
    assert torch.equal(again, gt)
    assert len([w for w in rec if issubclass(w.category, P.CacheWarning)]) == 1
    # the broken entry was replaced by a good one: no warning the next time
    with warnings.catch_warnings():
        warnings.simplefilter("error", P.CacheWarning)
        assert torch.equal(LFMCaptureDataset(one, split="all", noise=False)[0]["gt"], gt)


def test_truncated_cache_entry_warns_once_and_rebuilds(one):
    LFMCaptureDataset(one, split="all", noise=False)[0]
    p = _entry(one)
    p.write_bytes(p.read_bytes()[:100])
    P._warned.clear()
    with pytest.warns(P.CacheWarning, match=str(p.name)):
        LFMCaptureDataset(one, split="all", noise=False)[0]
    torch.load(p, weights_only=True)  # rewritten whole


# ------------------------------------------------------------------------------------ 2. no stale cache
def test_rerendered_scene_invalidates_cache(tmp_path):
    root = make_corpus(tmp_path / "c", n_scenes=1, scale=1e-3)
    a = LFMCaptureDataset(root, split="all", noise=False)[0]["gt"].sum()
    make_corpus(tmp_path / "c", n_scenes=1, scale=2e-3)  # same ids, new radiance, new manifest hashes
    b = LFMCaptureDataset(root, split="all", noise=False)[0]["gt"].sum()
    assert float(b) == pytest.approx(2 * float(a), rel=1e-3)
    assert len(list((root / ".cache").rglob("*.pt"))) == 2  # a new key, the old entry is not used


def test_file_changed_on_disk_is_not_served_from_cache(one):
    LFMCaptureDataset(one, split="all", noise=False)[0]
    p = sorted((one / "scenes" / "scene00000" / "f000").glob("*.exr"))[0]
    data = bytearray(p.read_bytes())
    data[-5] ^= 0xFF  # corrupt the file without updating the manifest
    p.write_bytes(bytes(data))
    with pytest.raises(C.CorpusFileError, match=f"{p.name}: bad checksum"):
        LFMCaptureDataset(one, split="all", noise=False)[0]


# ----------------------------------------------------------------------------------- 8. read-only corpus
def test_cache_dir_outside_corpus_and_unwritable_cache(one, tmp_path, monkeypatch):
    cd = tmp_path / "elsewhere"
    gt = LFMCaptureDataset(one, split="all", noise=False, cache_dir=cd)[0]["gt"]
    assert list(cd.rglob("*.pt")) and not (one / ".cache").exists()
    # a read-only corpus: writing the default <root>/.cache fails (EROFS); the dataset goes on, one warning
    import errno

    def read_only(obj, path):
        raise C.CorpusWriteError(errno.EROFS, f"could not write {path}: Read-only file system")

    monkeypatch.setattr(P, "atomic_torch_save", read_only)
    P._warned.clear()
    with pytest.warns(P.CacheWarning, match="cannot write the projection cache") as rec:
        ds = LFMCaptureDataset(one, split="all", noise=False, cache_scenes=0)
        got = [ds[0]["gt"], ds[0]["gt"]]
    assert torch.equal(got[0], gt) and torch.equal(got[1], gt)
    assert len(rec) == 1


# ------------------------------------------------------------------------------ 4. paths stay in the root
def _manifest(root):
    return json.loads((root / "manifest.json").read_text())


def _set_manifest(root, man):
    (root / "manifest.json").write_text(json.dumps(man))


@pytest.mark.parametrize("entry", ["../../../etc/hostname", "/etc/hostname", "scenes/scene00000/../../x.exr"])
def test_manifest_file_entry_outside_root_is_refused(one, entry):
    man = _manifest(one)
    man["files"][entry] = C.sha256_file(one / "manifest.json")
    _set_manifest(one, man)
    rep = C.validate_corpus(one)
    assert not rep.ok
    assert any("manifest.json" in e and repr(entry) in e and "refused" in e for e in rep.errors), rep.errors
    with pytest.raises(C.CorpusFileError, match=r"manifest\.json: file entry .* refused"):
        C.Corpus(one)
    with pytest.raises(C.CorpusFileError, match="refused"):
        LFMCaptureDataset(one, split="all", cache_dir=False)


def test_manifest_scene_id_outside_root_is_refused(one, tmp_path):
    evil = tmp_path / "evil" / "sceneX"
    (evil / "f000").mkdir(parents=True)
    man = _manifest(one)
    man["scenes"].append("../../evil/sceneX")
    _set_manifest(one, man)
    with pytest.raises(C.CorpusFileError, match=r"manifest\.json: scene entry '\.\./\.\./evil/sceneX' refused"):
        LFMCaptureDataset(one, split="all")
    rep = C.validate_corpus(one)
    assert any("'../../evil/sceneX' refused" in e for e in rep.errors), rep.errors
    assert not list((tmp_path / "evil").rglob("*.pt"))


def test_scene_dir_symlinked_outside_root_is_refused(one, tmp_path):
    outside = tmp_path / "outside"
    (one / "scenes" / "scene00000").rename(outside)
    (one / "scenes" / "scene00000").symlink_to(outside, target_is_directory=True)
    with pytest.raises(C.CorpusFileError, match="outside the corpus root"):
        C.Corpus(one).meta("scene00000")
    assert any("outside the corpus root" in e for e in C.validate_corpus(one).errors)


def test_splits_entry_outside_root_is_refused(one):
    (one / "splits.json").write_text(json.dumps({"train": ["../../x"], "val": [], "test": []}))
    with pytest.raises(C.CorpusFileError, match=r"splits\.json: split 'train' entry '\.\./\.\./x' refused"):
        LFMCaptureDataset(one, split="train", cache_dir=False)
    assert any("'../../x' refused" in e for e in C.validate_corpus(one).errors)


def test_meta_scene_id_is_checked_on_read(one):
    p = one / "scenes" / "scene00000" / "meta.json"
    m = json.loads(p.read_text())
    m["scene_id"] = "../x"
    p.write_text(json.dumps(m))
    with pytest.raises(ValueError, match=r"meta\.json: field 'scene_id'"):
        C.Corpus(one).meta("scene00000")


# ------------------------------------------------------------------ 3, 5. Ctrl-C in a render, killed runs


def test_ctrl_c_inside_mitsuba_render_stops_with_130(tmp_path, fake):
    out = tmp_path / "c"
    FAIL["scene00001"] = mitsuba_sigint
    # an interactive start (Python's own SIGINT handler), also when the test run itself was started with SIGINT
    # ignored (``nohup make test &``), which the render keeps (test_sigint_ignored_at_start_stays_ignored)
    prev = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        r = run("--out", str(out), "--scenes", "4", *ARGS)
    finally:
        signal.signal(signal.SIGINT, prev)
    assert r.exit_code == 130, r.output
    assert "interrupted" in r.output and "failed" not in r.output
    assert fake == ["scene00000", "scene00001"]  # no further scene started
    rep = C.validate_corpus(out)
    assert rep.ok, rep.errors  # splits.json written although the run never reached its end
    assert C.Corpus(out).splits["test"] == ["scene00000"]


def test_sigint_ignored_at_start_stays_ignored():
    """A render started with SIGINT ignored (``nohup lfmbench render ... &``) keeps it ignored: the flag handler
    is not installed (it would record the signal but stop nothing); an ordinary start gets it."""
    prev = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        hit = []
        with J._sigint_flag(hit):
            assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
            signal.raise_signal(signal.SIGINT)
        assert hit == []
        signal.signal(signal.SIGINT, signal.default_int_handler)
        with J._sigint_flag(hit):
            with pytest.raises(KeyboardInterrupt):
                signal.raise_signal(signal.SIGINT)
        assert hit == [True] and signal.getsignal(signal.SIGINT) == signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, prev)


def test_runtime_error_naming_keyboardinterrupt_is_an_interrupt():
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as e:
            raise RuntimeError("wrapped") from e
    except RuntimeError as exc:
        assert J._is_interrupt(exc)
    assert J._is_interrupt(RuntimeError("KeyboardInterrupt: "))
    assert not J._is_interrupt(RuntimeError("out of memory"))


class _Killed(BaseException):
    """Stands for SIGKILL / power loss: nothing after it runs."""


def test_killed_render_leaves_valid_corpus_with_splits(tmp_path, fake, monkeypatch):
    out = tmp_path / "c"
    real = C.CorpusWriter.write_splits
    n = {"splits": 0}

    def write_splits(self, *a, **k):
        n["splits"] += 1
        res = real(self, *a, **k)
        if n["splits"] == 3:  # after the resume check, scene 0 and scene 1: killed before scene 2
            raise _Killed
        return res

    monkeypatch.setattr(C.CorpusWriter, "write_splits", write_splits)
    with pytest.raises(_Killed):
        CliRunner().invoke(app, ["render", "--out", str(out), "--scenes", "3", *ARGS], catch_exceptions=False)
    rep = C.validate_corpus(out)
    assert rep.ok, rep.errors
    assert sorted(sum(C.Corpus(out).splits.values(), [])) == ["scene00000", "scene00001"]


# ------------------------------------------------------------- 3, 6, 8, 9. evaluate and leaderboard faults
METHODS = '''
import sys
import torch
CALLS = []

def always_fail(batch):
    raise RuntimeError("nothing works")

def exits(batch):
    sys.exit(3)

def interrupt_second(batch):
    CALLS.append(1)
    if len(CALLS) >= 3:  # first scene: call + timing warm-up + 1 repeat; then Ctrl-C
        raise KeyboardInterrupt
    return batch["gt"].clone()
'''


@pytest.fixture(scope="module")
def eval_env(tmp_path_factory):
    d = tmp_path_factory.mktemp("eval")
    make_corpus(d / "corpus", n_scenes=2)
    (d / "lfm_fault_methods.py").write_text(METHODS)
    (d / "lfm_exit_on_import.py").write_text("import sys\nsys.exit('no GPU here')\n")
    return d


def _evaluate(env, monkeypatch, method, *extra):
    monkeypatch.syspath_prepend(str(env))
    return CliRunner().invoke(app, ["evaluate", "--method", method, "--corpus", str(env / "corpus"), "--split", "all",
                                    "--repeats", "1", "--no-perceptual", *extra])


def test_evaluate_all_scenes_failed_exits_1(eval_env, monkeypatch, tmp_path):
    out = tmp_path / "f.json"
    r = _evaluate(eval_env, monkeypatch, "lfm_fault_methods:always_fail", "--output", str(out))
    assert r.exit_code == 1, r.output
    assert "2 of 2 scenes failed" in r.output and "nothing works" in r.output
    d = json.loads(out.read_text())
    assert d["status"] == "failed" and d["aggregate"]["scenes_ok"] == 0


def test_method_calling_sys_exit_is_a_recorded_failure(eval_env, monkeypatch, tmp_path):
    out = tmp_path / "x.json"
    r = _evaluate(eval_env, monkeypatch, "lfm_fault_methods:exits", "--output", str(out))
    assert r.exit_code == 1, r.output
    assert "sys.exit(3)" in r.output
    d = json.loads(out.read_text())
    assert [s["status"] for s in d["scenes"]] == ["error", "error"] and "sys.exit(3)" in d["scenes"][0]["error"]
    r = _evaluate(eval_env, monkeypatch, "lfm_exit_on_import:f", "--output", str(out))
    assert r.exit_code == 2 and "called sys.exit('no GPU here')" in r.output


def test_evaluate_ctrl_c_exits_130_and_leaderboard_refuses_it(eval_env, monkeypatch, tmp_path):
    out = tmp_path / "i.json"
    r = _evaluate(eval_env, monkeypatch, "lfm_fault_methods:interrupt_second", "--output", str(out))
    assert r.exit_code == 130, r.output
    assert "interrupted" in r.output
    d = json.loads(out.read_text())
    assert d["status"] == "interrupted" and len(d["scenes"]) == 1
    good = tmp_path / "g.json"  # a complete run on the same corpus (the leaderboard refuses mixed corpora)
    assert _evaluate(eval_env, monkeypatch, "lpd_only", "--output", str(good)).exit_code == 0
    lb = ["leaderboard", str(good), str(out), "--markdown", str(tmp_path / "lb.md"), "--plot", str(tmp_path / "p.png")]
    r = CliRunner().invoke(app, lb)
    assert r.exit_code == 2 and "i.json: status 'interrupted'" in r.output and "--include-incomplete" in r.output
    r = CliRunner().invoke(app, lb + ["--include-incomplete"])
    assert r.exit_code == 0, r.output
    md = (tmp_path / "lb.md").read_text()
    assert "(interrupted: not a complete result)" in md
    assert md.index("lpd_only") < md.index("interrupt_second")  # incomplete runs ranked after complete ones
    (tmp_path / "run.json").write_text(json.dumps(dict(d, status="running")))  # a killed run
    r = CliRunner().invoke(app, ["leaderboard", str(tmp_path / "run.json"), str(good)])
    assert r.exit_code == 2 and "'running'" in r.output


def test_evaluate_cache_dir_keeps_the_corpus_untouched(eval_env, monkeypatch, tmp_path):
    corpus = tmp_path / "ro"
    make_corpus(corpus, n_scenes=1)
    before = sorted(p.relative_to(corpus) for p in corpus.rglob("*"))
    env = tmp_path
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(corpus), "--split", "all",
                                 "--repeats", "1", "--no-perceptual", "--output", str(env / "o.json"),
                                 "--cache-dir", str(env / "cache")])
    assert r.exit_code == 0, r.output
    assert sorted(p.relative_to(corpus) for p in corpus.rglob("*")) == before
    assert list((env / "cache").rglob("*.pt"))


def test_evaluate_and_leaderboard_bad_arguments_are_one_line(eval_env, monkeypatch, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    cases = [(["--max-scenes", "-1"], "--max-scenes must be an integer >= 1"),
             (["--device", "banana"], "--device must be a torch device"),
             (["--output", str(blocker / "r.json")], "--output"),
             (["--output", str(tmp_path)], "--output")]
    for extra, msg in cases:
        r = _evaluate(eval_env, monkeypatch, "lpd_only", *extra)
        assert r.exit_code == 2 and msg in r.output, (extra, r.output)
        assert "Traceback" not in r.output and isinstance(r.exception, SystemExit)
    (tmp_path / "bin.json").write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe")
    (tmp_path / "fmt.json").write_text(json.dumps({"format": "lfmbench-eval"}))
    for name, msg in (("bin.json", "cannot read JSON"), ("fmt.json", "field 'method' missing")):
        r = CliRunner().invoke(app, ["leaderboard", str(tmp_path / name)])
        assert r.exit_code == 2 and f"{name}: " in r.output and msg in r.output, r.output
        assert isinstance(r.exception, SystemExit)


# ------------------------------------------------------------------------------------- 7. silent nonsense
def test_unknown_group_names_group_and_available(one):
    with pytest.raises(ValueError, match=r"groups: \['nonsense'\] are not light groups.*available: "
                                         r"\['headlights', 'otherlights', 'skymap'\]"):
        LFMCaptureDataset(one, split="all", groups=["nonsense"], cache_dir=False)
    ds = LFMCaptureDataset(one, split="all", groups="headlights", cache_dir=False)  # a bare string is one group
    assert ds.groups == ["headlights"]


def _float32_corpus(root):
    from tests.data.corpus.data import fake_frames, fake_meta, fake_scene

    w = C.CorpusWriter(root, dtype="float32")
    m = fake_meta("scene00000", width=24, height=16)
    w.write_scene("scene00000", fake_scene("scene00000"), m, fake_frames(m))
    w.write_splits(0)
    return root


def _set_radiance(path, value):
    import OpenEXR

    f = OpenEXR.File(str(path), separate_channels=True)
    parts = []
    for p in f.parts:
        ch = {k: np.array(v.pixels) for k, v in p.channels.items()}
        k0 = sorted(ch)[0]
        ch[k0] = ch[k0].copy()
        ch[k0].flat[0] = value
        parts.append(OpenEXR.Part(dict(p.header), ch, p.name()))
    OpenEXR.File(parts).write(str(path))


@pytest.mark.parametrize("value", [1e30, 3e38])
def test_implausible_radiance_is_named_by_validate_and_reader(tmp_path, value):
    root = _float32_corpus(tmp_path / "c")
    p = root / "scenes" / "scene00000" / "f000" / "headlights.exr"
    _set_radiance(p, value)
    man = _manifest(root)
    man["files"][p.relative_to(root).as_posix()] = C.sha256_file(p)
    _set_manifest(root, man)
    errs = "\n".join(C.validate_corpus(root).errors)
    assert str(p) in errs and "plausibility ceiling" in errs
    with pytest.raises(C.CorpusValueError, match=f"{p}.*exceeds the plausibility ceiling"):
        LFMCaptureDataset(root, split="all", frames=2, cache_dir=False)[0]


def test_writer_refuses_implausible_radiance(tmp_path):
    from tests.data.corpus.data import fake_frames, fake_meta, fake_scene

    m = fake_meta("scene00000")
    fr = fake_frames(m)
    fr[0]["static"]["headlights"]["short"][0, 0, 0] = 1e12
    with pytest.raises(C.CorpusValueError, match="plausibility ceiling"):
        C.CorpusWriter(tmp_path / "c", dtype="float32").write_scene("scene00000", fake_scene("scene00000"), m, fr)


def test_non_finite_sensor_output_names_the_scene(one, monkeypatch):
    from lfmbench import sensor

    def boom(*a, **k):
        raise ValueError("lpd_electrons contains non-finite values (0 NaN, 3 inf)")

    for name in ("simulate_split_pixel_electrons", "simulate_plan_electrons"):   # the chains a sample may take
        monkeypatch.setattr(sensor, name, boom)
    with pytest.raises(ValueError, match=r"scene 'scene00000' of .*lpd_electrons contains non-finite"):
        LFMCaptureDataset(one, split="all", cache_dir=False)[0]


# ---------------------------------------------------------------------------- 9. one-line clear errors
@pytest.mark.parametrize("field,value,msg", [
    ("lights", ["x"], r"lights\[0\] must be an object"),
    ("lights", "x", r"field 'lights' must be a list"),
    ("camera", [1, 2], r"field 'camera' must be an object"),
])
def test_bad_meta_json_is_named(one, field, value, msg):
    p = one / "scenes" / "scene00000" / "meta.json"
    m = json.loads(p.read_text())
    m[field] = value
    p.write_text(json.dumps(m))
    with pytest.raises(ValueError, match=msg):
        LFMCaptureDataset(one, split="all", cache_dir=False)
    assert any(str(p) in e and field in e for e in C.validate_corpus(one).errors)


@pytest.mark.parametrize("content,msg", [(["scene00000"], "must be a JSON object"),
                                         ({"train": "scene00000", "val": [], "test": []},
                                          "split 'train' must be a list")])
def test_bad_splits_json_is_named(one, content, msg):
    (one / "splits.json").write_text(json.dumps(content))
    with pytest.raises(C.CorpusFileError, match=f"splits.json: {msg}"):
        LFMCaptureDataset(one, split="train", cache_dir=False)
    assert any(msg in e for e in C.validate_corpus(one).errors)


@pytest.mark.parametrize("crop", ["abc", 2.7, (4,), (4, "x"), True])
def test_bad_crop_is_named(one, crop):
    with pytest.raises(ValueError, match=r"^crop must be None, an int or \(h, w\)"):
        LFMCaptureDataset(one, split="all", crop=crop, cache_dir=False)


def test_render_bad_out_and_profile_are_one_line(tmp_path, fake):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    r = run("--out", str(blocker / "c"), "--scenes", "1", *ARGS)
    assert r.exit_code == 2 and f"--out {blocker / 'c'}: cannot create or write" in r.output, r.output
    assert isinstance(r.exception, SystemExit)
    prof = tmp_path / "p.yaml"
    prof.write_text("width: [16\nheight: 8\n")
    r = run("--out", str(tmp_path / "c"), "--profile", str(prof))
    assert r.exit_code == 2 and f"{prof}: cannot read the profile" in r.output and "line" in r.output, r.output
    assert isinstance(r.exception, SystemExit) and fake == []


# -------------------------------------------------------------------------------------------- 10. bounds
@pytest.mark.parametrize("args,msg", [(["--scenes", "100000000"], "--scenes 100000000 is above the limit"),
                                      (["--scenes", "20000"], "--scenes 20000 is above the sanity limit"),
                                      (["--frames", "1000"], "--frames 1000 is above the sanity limit")])
def test_render_absurd_sizes_need_yes(tmp_path, fake, args, msg):
    out = tmp_path / "c"
    r = run("--out", str(out), *ARGS, *args)
    assert r.exit_code == 2 and msg in r.output, r.output
    assert not out.exists() and fake == []  # refused before anything was written or allocated


def test_render_large_run_with_yes_goes_ahead(tmp_path, fake, monkeypatch):
    seen = {}
    monkeypatch.setattr(J, "run_jobs", lambda jobs, writer, **kw: seen.setdefault("n", len(jobs)) and J.RunSummary())
    r = run("--out", str(tmp_path / "c"), *ARGS, "--scenes", "20000", "--yes")
    assert r.exit_code == 0, r.output
    assert seen["n"] == 20000


def test_bad_test_params_file_is_named(one):
    (one / "test_params.json").write_text("[]")
    with pytest.raises(ValueError, match=r"test_params\.json: not a valid test-parameter file.*delete it"):
        LFMCaptureDataset(one, split="test", cache_dir=False)
