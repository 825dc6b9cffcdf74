"""Hostile and unlucky input, second round (issue 27; docs/guide/fault-catalogue.md): outputs that are not regular files,
billion-laughs YAML, deep JSON, EXR bombs, foreign folders, two writers, untrustworthy scores, scale limits.

Tiny generated files only; nothing here renders, and nothing allocates more than a few MB.
"""
from __future__ import annotations

import errno
import json
import os
import stat
import threading
import time

import pytest
from typer.testing import CliRunner

from lfmbench import fileio, limits
from lfmbench.cli import app


def _one_line(r):
    """A refused CLI run: exit 2, no traceback, one non-empty line on stderr (rich may wrap it: joined)."""
    assert r.exit_code == 2, r.output
    assert "Traceback" not in r.output and isinstance(r.exception, SystemExit), r.output
    return " ".join(r.output.split())


# ------------------------------------------------------------ 1. outputs never replace what the path points at
def test_output_symlink_is_written_through_not_replaced(tmp_path):
    target = tmp_path / "real" / "result.json"
    target.parent.mkdir()
    target.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    fileio.atomic_write_json(link, {"v": 2})
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert json.loads(target.read_text()) == {"v": 2}
    assert sorted(p.name for p in target.parent.iterdir()) == ["result.json"]  # no temporary left


def test_output_fifo_is_written_directly_not_replaced(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()), daemon=True)
    reader.start()
    fileio.atomic_write_text(fifo, "hello")
    reader.join(10)
    assert got == [b"hello"]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)  # still the FIFO, not a regular file in its place
    t0 = time.monotonic()  # no reader: an error naming the path at once, not a hang
    with pytest.raises(fileio.AtomicWriteError, match="could not write .*pipe"):
        fileio.atomic_write_text(fifo, "again")
    assert time.monotonic() - t0 < fileio.FIFO_WAIT_S + 2 and stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert fileio.writable_error(fifo) is None


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs Linux /dev/full")
def test_write_error_of_a_device_reaches_the_exit_code(tmp_path):
    st = os.stat("/dev/full")
    with pytest.raises(fileio.AtomicWriteError, match="could not write /dev/full: disk full") as e:
        fileio.atomic_write_text("/dev/full", "x")
    assert e.value.errno == errno.ENOSPC
    assert os.stat("/dev/full").st_rdev == st.st_rdev and stat.S_ISCHR(os.stat("/dev/full").st_mode)
    assert not [p for p in os.listdir("/dev") if p.startswith(fileio.TMP_PREFIX)]
    # the CLI: the leaderboard's outputs
    from tests.data.evaluation.data import write_result

    run = write_result(tmp_path / "a.json")
    r = CliRunner().invoke(app, ["leaderboard", str(run), "--markdown", "/dev/full", "--plot",
                                 str(tmp_path / "p.png"), "--json", str(tmp_path / "l.json")])
    out = _one_line(r)
    assert "/dev/full" in out and "disk full" in out
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_evaluate_output_symlink_and_device(tmp_path, monkeypatch):
    """``evaluate -o`` a symbolic link writes through it; ``-o /dev/full`` exits 2 naming it (it exited 0)."""
    from tests.data.corpus.data import make_corpus

    corpus = make_corpus(tmp_path / "c", n_scenes=1)
    target = tmp_path / "keep" / "r.json"
    target.parent.mkdir()
    link = tmp_path / "r.json"
    link.symlink_to(target)
    base = ["evaluate", "--method", "lpd_only", "--corpus", str(corpus), "--split", "all", "--repeats", "1",
            "--warmup", "0", "--no-perceptual"]
    r = CliRunner().invoke(app, [*base, "-o", str(link)])
    assert r.exit_code == 0, r.output
    assert link.is_symlink() and json.loads(target.read_text())["status"] == "complete"
    if os.path.exists("/dev/full"):
        out = _one_line(CliRunner().invoke(app, [*base, "-o", "/dev/full"]))
        assert "/dev/full" in out and "disk full" in out
        assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs Linux /dev/full")
def test_figure_write_error_is_one_line():
    r = CliRunner().invoke(app, ["flicker-report", "--frames", "4", "--plot", "/dev/full"])
    out = _one_line(r)
    assert "could not write /dev/full: disk full" in out

# ------------------------------------------------------------------- 5. YAML: billion laughs, long values
def _laughs(levels: int, width: int = 10) -> str:
    """A YAML "billion laughs": ``width ** levels`` strings after alias expansion, ``levels * width`` aliases."""
    lines = ['a0: &a0 "lol"']
    for i in range(1, levels + 1):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * width) + "]")
    return "\n".join(lines) + "\n"


def _yaml_readers():
    from lfmbench import sensor
    from lfmbench.baselines import unet
    from lfmbench.datasets.pwm import load_pwm_config
    from lfmbench.evaluation.conditions import load_bins
    from render_tools import jobs, protocol, scene

    return {"sensor preset": sensor.load_preset, "PWM config": load_pwm_config, "condition bins": load_bins,
            "render profile": jobs.load_profile, "protocol": protocol.load_protocol,
            "U-Net config": unet.load_config, "scene config": scene.load_config}


def test_billion_laughs_yaml_is_refused_by_every_reader(tmp_path):
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(_laughs(6))  # 10^6 nodes after expansion, 60 aliases
    for what, read in _yaml_readers().items():
        t0 = time.monotonic()
        with pytest.raises(ValueError) as e:
            read(bomb)
        msg = str(e.value)
        assert time.monotonic() - t0 < 5, what
        assert "bomb.yaml" in msg and "yaml_nodes" in msg and len(msg) < 400 and "\n" not in msg, (what, msg)
    many = tmp_path / "aliases.yaml"
    many.write_text("a: &a 1\nb: [" + ", ".join(["*a"] * 150) + "]\n")
    with pytest.raises(fileio.InputFileError, match="aliases.yaml: .*yaml_aliases=100"):
        fileio.load_yaml(many)
    limits.set_limit("yaml_aliases", 200)
    try:
        assert len(fileio.load_yaml(many)["b"]) == 150  # raised explicitly: read
    finally:
        limits.set_limit("yaml_aliases", None)


def test_yaml_error_quotes_only_a_prefix_of_a_bad_value(tmp_path):
    from lfmbench import sensor

    data = fileio.load_yaml(sensor.PRESET_DIR / "ovt.yaml")
    data["pixel_pitch_m"] = "x" * 100_000
    p = tmp_path / "long.yaml"
    import yaml

    p.write_text(yaml.safe_dump(data))
    with pytest.raises(ValueError) as e:
        sensor.load_preset(p)
    assert "long.yaml" in str(e.value) and len(str(e.value)) < 400, str(e.value)[:500]


# ------------------------------------------------------------------------------------------ 10. deep JSON
def test_deep_json_manifest_and_results_are_one_line(tmp_path):
    from tests.data.corpus.data import make_corpus

    deep = "[" * 100_000 + "]" * 100_000
    corpus = make_corpus(tmp_path / "c", n_scenes=1)
    (corpus / "manifest.json").write_text(deep)
    r = CliRunner().invoke(app, ["validate", str(corpus)])
    assert r.exit_code == 1 and "Traceback" not in r.output and "json_depth" in r.output, r.output
    assert isinstance(r.exception, SystemExit)
    (tmp_path / "deep.json").write_text(deep)
    out = _one_line(CliRunner().invoke(app, ["leaderboard", str(tmp_path / "deep.json")]))
    assert "deep.json" in out and "json_depth" in out
    with pytest.raises(fileio.InputFileError, match="json_depth"):
        fileio.loads_json("[" * 70 + "]" * 70, "x.json")  # deeper than 64 but below Python's recursion limit
    for bad in ("[NaN]", "[Infinity]", "[1e400]", "[" + "9" * 5000 + "]"):
        with pytest.raises(fileio.InputFileError, match="x.json: cannot read JSON"):
            fileio.loads_json(bad, "x.json")


# ------------------------------------------------------------------- 2. only touch what is ours
def _snapshot(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_render_into_a_foreign_folder_is_refused_and_nothing_is_touched(tmp_path, fake):
    from tests.data.render.data import ARGS, run

    home = tmp_path / "home"
    (home / "scenes" / "scene00000").mkdir(parents=True)
    (home / "scenes" / "scene00000" / "holiday.jpg").write_bytes(b"\xff\xd8 my photo")
    (home / "splits.json").write_text("my own splits")
    (home / ".lfmtmp-notes").write_text("a file that only looks like ours")
    before = _snapshot(home)
    out = _one_line(run("--out", str(home), "--scenes", "1", *ARGS))
    assert str(home) in out and "not an lfmbench corpus" in out and "first foreign entry" in out
    assert _snapshot(home) == before and not fake
    # an empty folder, and a folder holding only a stale lock, are fine
    (tmp_path / "empty").mkdir()
    assert run("--out", str(tmp_path / "empty"), "--scenes", "1", *ARGS).exit_code == 0


def test_prune_and_cleanup_remove_only_our_files(tmp_path):
    from lfmbench import corpus as C
    from tests.data.corpus.data import fake_frames, fake_meta, fake_scene

    root = tmp_path / "c"
    with C.CorpusWriter(root) as w:
        m3 = fake_meta("scene00000", frames=3)
        w.write_scene("scene00000", fake_scene(), m3, fake_frames(m3))
    sdir = root / "scenes" / "scene00000"
    mine = {sdir / "notes.txt": b"mine", sdir / "f002" / "sketch.png": b"png", root / "README": b"mine too",
            sdir / "f002" / "My Group.exr": b"not a group name of ours"}
    for p, b in mine.items():
        p.write_bytes(b)
    with C.CorpusWriter(root) as w:  # re-render with 2 frames: f002/*.exr are stale and ours
        m2 = fake_meta("scene00000", frames=2)
        w.write_scene("scene00000", fake_scene(), m2, fake_frames(m2))
        w.write_splits(0)
    assert all(p.read_bytes() == b for p, b in mine.items())
    assert not list((sdir / "f002").glob("[a-z]*.exr"))
    rep = C.validate_corpus(root)
    assert rep.ok, rep.errors


# ------------------------------------------------------------------- 3. one writer per corpus
def test_second_writer_is_refused_and_a_stale_lock_is_taken_over(tmp_path, fake):
    import socket
    import subprocess
    import sys

    from lfmbench import corpus as C
    from tests.data.render.data import ARGS, run

    root = tmp_path / "c"
    holder = subprocess.Popen(  # another process with the corpus open for writing
        [sys.executable, "-c", "import sys; from lfmbench import corpus as C; w = C.CorpusWriter(sys.argv[1]); "
                               "print('locked', flush=True); sys.stdin.read()", str(root)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(C.CorpusLockedError, match=f"pid {holder.pid} host {socket.gethostname()}"):
            C.CorpusWriter(root)
        out = _one_line(run("--out", str(root), "--scenes", "1", *ARGS))  # a second render: exit 2, names it
        assert "being written by another lfmbench process" in out and f"pid {holder.pid}" in out
        assert not fake and C.Corpus(root).scenes == []
    finally:
        holder.stdin.close()
        holder.wait(30)
    # the holder is gone (the kernel released its flock); its pid is still in the file: taken over
    assert f"pid {holder.pid}" in (root / C.LOCK_NAME).read_text() or (root / C.LOCK_NAME).read_text() == ""
    (root / C.LOCK_NAME).write_text(f"pid {holder.pid} host {socket.gethostname()}\n")
    r = run("--out", str(root), "--scenes", "1", *ARGS)
    assert r.exit_code == 0, r.output
    assert C.Corpus(root).scenes == ["scene00000"]


# ------------------------------------------------------------------- 8. unique, disjoint scene ids
def test_duplicate_and_shared_scene_ids_fail_validate_and_evaluate(tmp_path):
    from lfmbench.datasets import LFMCaptureDataset
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=3)
    man = json.loads((root / "manifest.json").read_text())
    good_man, good_splits = (root / "manifest.json").read_text(), (root / "splits.json").read_text()
    man["scenes"].append(man["scenes"][0])
    (root / "manifest.json").write_text(json.dumps(man))
    r = CliRunner().invoke(app, ["validate", str(root)])
    assert r.exit_code == 1 and "scene id 'scene00000' is listed twice" in " ".join(r.output.split()), r.output
    with pytest.raises(ValueError, match="scene00000' is listed twice"):
        LFMCaptureDataset(root, split="all", cache_dir=False)
    (root / "manifest.json").write_text(good_man)
    sp = json.loads(good_splits)
    sp["test"].append(sp["train"][0])
    (root / "splits.json").write_text(json.dumps(sp))
    r = CliRunner().invoke(app, ["validate", str(root)])
    assert r.exit_code == 1 and "is in split 'train' and in split 'test'" in " ".join(r.output.split())
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(root), "--split", "test",
                                 "--no-perceptual", "-o", str(tmp_path / "r.json")])
    assert "is in split 'train' and in split 'test'" in _one_line(r)
    assert not (tmp_path / "r.json").exists()


# ------------------------------------------------------------------- 11. scale: light cap, linear validate
def test_scene_with_too_many_lights_is_refused_naming_the_cap(tmp_path):
    from lfmbench import corpus as C
    from render_tools import scene as S
    from tests.data.corpus.data import fake_meta

    cap = limits.limit("lights_per_scene")
    m = fake_meta("scene00000")
    m["lights"] = [{"id": i, "group": m["lights"][0]["group"]} for i in range(cap + 1)]
    with pytest.raises(ValueError, match=f"meta.json: field 'lights' has {cap + 1:,} lights, above the cap of "
                                         f"{cap:,} lights per scene"):
        C.validate_meta(m)
    sc = S.generate_scene(3, scene_id="s")
    sc["lights"] = [sc["lights"][0]] * (cap + 1)
    with pytest.raises(ValueError, match=f"scene.lights' has {cap + 1:,} lights, above the cap"):
        S.validate_scene(sc)


def test_meta_json_with_too_many_lights_is_refused_while_it_is_parsed(tmp_path):
    """The light cap is counted during the parse: a meta.json whose light cap+1 is followed by a broken tail is
    refused for its lights (the parser never reached the tail); before, the whole file was parsed first (10^6
    lights: 431 MB, 5 s) and here the tail's JSON error was all the user saw."""
    from lfmbench import corpus as C
    from tests.data.corpus.data import fake_meta, make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1)
    sid = C.Corpus(root).scenes[0]
    mp = root / "scenes" / sid / "meta.json"
    limits.set_limit("lights_per_scene", 8)
    try:
        m = fake_meta(sid)
        m["lights"] = [{"id": i, "group": "otherlights"} for i in range(9)]
        text = json.dumps(m)
        mp.write_text(text[:text.index('{"id": 8')] + '{"id": 8, "group": "x"}, {"id": ')  # broken after light 9
        r = CliRunner().invoke(app, ["validate", "--headers-only", str(root)])
        out = " ".join(r.output.split())
        assert r.exit_code == 1 and "meta.json: field 'lights' has more than 8 lights, above the cap of 8" in out
        assert "cannot read JSON" not in out
        with pytest.raises(C.CorpusFileError, match="has more than 8 lights"):
            C.Corpus(root).meta(sid)
        m = fake_meta(sid)  # objects that are no lights count too: 4 per light of the cap, plus 1,024
        m["camera"]["junk"] = [{} for _ in range(4 * 8 + 1024)] + [{}]
        mp.write_text(json.dumps(m))
        with pytest.raises(C.CorpusFileError, match=r"more than 1,056 JSON objects"):
            C.load_meta(mp)
    finally:
        limits.set_limit("lights_per_scene", None)


# ------------------------------------------------------------------- 6. EXR bombs
def _patch_window(path, name: bytes, box):
    import struct

    raw = bytearray(path.read_bytes())
    key = name + b"\0box2i\0" + struct.pack("<i", 16)
    i = raw.index(key) + len(key)
    raw[i:i + 16] = struct.pack("<iiii", *box)
    path.write_bytes(bytes(raw))


def _multipart_header(n_parts: int) -> bytes:
    """A multi-part EXR header of ``n_parts`` tiny parts (and no pixel data): what OpenEXR reads first."""
    import struct

    def attr(name, typ, val):
        return name + b"\0" + typ + b"\0" + struct.pack("<i", len(val)) + val

    ch = b"R\0" + struct.pack("<iB3xii", 1, 0, 1, 1) + b"\0"
    box = struct.pack("<iiii", 0, 0, 7, 7)
    out = [struct.pack("<iI", 20000630, 2 | 0x1000)]
    for i in range(n_parts):
        out.append(attr(b"channels", b"chlist", ch) + attr(b"compression", b"compression", b"\0")
                   + attr(b"dataWindow", b"box2i", box) + attr(b"displayWindow", b"box2i", box)
                   + attr(b"name", b"string", f"light{i}".encode()) + attr(b"type", b"string", b"scanlineimage")
                   + b"\0")
    return b"".join(out) + b"\0"


def test_exr_bombs_are_refused_from_the_header(tmp_path):
    from lfmbench import corpus as C
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1)
    p = root / "scenes" / "scene00000" / "f000" / "skymap.exr"
    size = p.stat().st_size
    _patch_window(p, b"dataWindow", (0, 0, 29_999, 29_999))  # 6 HALF channels of 30000^2: 10.8 GB declared
    _patch_window(p, b"displayWindow", (0, 0, 29_999, 29_999))
    assert p.stat().st_size == size
    with pytest.raises(C.CorpusFileError, match=r"skymap.exr.*decoded pixel bytes.*exr_bytes="):
        C.read_exr(p)
    bomb = root / "scenes" / "scene00000" / "f000" / "otherlights.exr"
    bomb.write_bytes(_multipart_header(limits.limit("exr_parts") + 1))
    with pytest.raises(C.CorpusFileError, match=r"otherlights.exr: EXR file with more than 4,200 parts.*exr_parts="):
        C.read_exr(bomb)
    r = CliRunner().invoke(app, ["validate", str(root)])
    out = r.output
    assert r.exit_code == 1 and "exr_bytes" in out and "exr_parts" in out and len(out.splitlines()) < 30, out
    # raised explicitly for a trusted file: read (here: the header passes and OpenEXR reports the missing pixels)
    limits.set_limit("exr_parts", 10_000)
    try:
        with pytest.raises(C.CorpusFileError) as e:
            C.read_exr(bomb)
        assert "exr_parts" not in str(e.value)
    finally:
        limits.set_limit("exr_parts", None)


# ------------------------------------------------------------------- 7. numbers that can be ranked
def _leaderboard(tmp_path, *files):
    return CliRunner().invoke(app, ["leaderboard", *map(str, files), "--markdown", str(tmp_path / "lb.md"),
                                    "--plot", str(tmp_path / "lb.png"), "--json", str(tmp_path / "lb.json")])


def test_leaderboard_refuses_numbers_that_cannot_be_ranked(tmp_path):
    from tests.data.evaluation.data import write_result

    good = write_result(tmp_path / "good.json", (0.5, 0.6), method="good")
    assert _leaderboard(tmp_path, good).exit_code == 0
    cases = {"inf.json": ((float("inf"), 0.5), "cannot read JSON"),
             "huge.json": ((1e308, 0.5), "field scenes[0].metrics.led_score = 1e+308 is outside the range of "
                                         "led_score, [0, 1]"),
             "neg.json": ((0.5, -0.25), "field scenes[1].metrics.led_score = -0.25 is outside the range"),
             "digits.json": ('{"format": "lfmbench-eval", "x": ' + "7" * 5000 + "}", "cannot read JSON")}
    for name, (scores, msg) in cases.items():
        bad = write_result(tmp_path / name, scores, method=name)
        out = _one_line(_leaderboard(tmp_path, good, bad))
        assert f"{name}" in out and msg in out and len(out) < 600, (name, out[:700])
        assert not (tmp_path / "lb.md").exists() or name  # nothing new written (checked below for one case)
    agg = write_result(tmp_path / "agg.json", (0.5,), extra={"aggregate": {"led_score": 7.0}})
    assert "aggregate.led_score = 7.0" in _one_line(_leaderboard(tmp_path, agg))
    rt = write_result(tmp_path / "rt.json", (0.5,), extra={"runtime": {"ms_per_megapixel": -1}})
    assert "runtime.ms_per_megapixel = -1 must be a finite number >= 0" in _one_line(_leaderboard(tmp_path, rt))
    # a result file far larger than any real one: refused from its size, before it is parsed
    limits.set_limit("json_bytes", 2000)
    try:
        big = write_result(tmp_path / "big.json", tuple([0.5] * 100), method="big")
        out = _one_line(_leaderboard(tmp_path, big))
        assert "big.json" in out and "json_bytes=2,000" in out
    finally:
        limits.set_limit("json_bytes", None)


# ------------------------------------------------------------------- 9. identity = the draws used
def test_results_with_identical_draws_stay_comparable_when_test_params_gains_draws(tmp_path):
    from lfmbench.datasets import LFMCaptureDataset
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=3)

    def evaluate(out, method="lpd_only"):
        r = CliRunner().invoke(app, ["evaluate", "--method", method, "--corpus", str(root), "--split", "test",
                                     "--repeats", "1", "--warmup", "0", "--no-perceptual", "-o", str(out)])
        assert r.exit_code == 0, r.output
        return json.loads(out.read_text())

    a = evaluate(tmp_path / "a.json")
    before = (root / "test_params.json").read_bytes()
    LFMCaptureDataset(root, split="test", samples_per_scene=3, cache_dir=False)  # another study: more draws
    assert (root / "test_params.json").read_bytes() != before
    b = evaluate(tmp_path / "b.json", "spd_only")
    assert a["corpus"]["test_params_sha256"] != b["corpus"]["test_params_sha256"]
    assert a["corpus"]["test_draws_sha256"] == b["corpus"]["test_draws_sha256"]
    r = _leaderboard(tmp_path, tmp_path / "a.json", tmp_path / "b.json")
    assert r.exit_code == 0, r.output
    # different draws are still refused: 2 samples per scene use draws the 1-sample results did not
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(root), "--split", "test",
                                 "--samples-per-scene", "2", "--repeats", "1", "--warmup", "0", "--no-perceptual",
                                 "-o", str(tmp_path / "c2.json")])
    assert r.exit_code == 0, r.output
    out = _one_line(_leaderboard(tmp_path, tmp_path / "a.json", tmp_path / "c2.json"))
    assert "corpus test draws sha256 differs" in out


# ------------------------------------------------------------------- 13. hostile checkpoint
class _Payload:
    def __reduce__(self):
        return (os.system, ("touch PWNED_BY_CHECKPOINT",))


def test_hostile_checkpoint_is_bad_input_naming_the_file(tmp_path, monkeypatch):
    import pickle

    from lfmbench.baselines import learned
    from tests.data.corpus.data import make_corpus

    monkeypatch.chdir(tmp_path)
    root = make_corpus(tmp_path / "c", n_scenes=1)
    ck = tmp_path / "evil.pt"
    ck.write_bytes(pickle.dumps({"format_version": 1, "w": _Payload()}))
    monkeypatch.setenv(learned.CHECKPOINT_ENV, str(ck))
    r = CliRunner().invoke(app, ["evaluate", "--method", "learned", "--corpus", str(root), "--split", "all",
                                 "--repeats", "1", "--warmup", "0", "--no-perceptual", "-o", str(tmp_path / "r.json")])
    out = _one_line(r)
    assert "evil.pt" in out and "checkpoint" in out
    assert not (tmp_path / "PWNED_BY_CHECKPOINT").exists() and not (tmp_path / "r.json").exists()


# ------------------------------------------------------------------- 4. set_epoch reaches persistent workers
def test_set_epoch_reaches_persistent_dataloader_workers(tmp_path):
    import torch
    from torch.utils.data import DataLoader

    from lfmbench.datasets import LFMCaptureDataset
    from lfmbench.datasets.loading import collate_samples
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1)
    ds = LFMCaptureDataset(root, split="all", outputs=("gt",), noise=False, cache_dir=False)
    loader = DataLoader(ds, batch_size=1, num_workers=1, persistent_workers=True, collate_fn=collate_samples)
    seen = []
    for epoch in range(3):
        ds.set_epoch(epoch)
        (batch,) = list(loader)
        seen.append((batch["meta"]["epoch"], batch["meta"]["phase_s"][0].tolist()))
    assert [int(torch.as_tensor(e).reshape(-1)[0]) for e, _ in seen] == [0, 1, 2]
    assert seen[0][1] != seen[1][1] != seen[2][1]  # new PWM phases every epoch, as in the main process
    ds.set_epoch(1)
    assert ds[0]["meta"]["phase_s"].tolist() == seen[1][1]


# ------------------------------------------------------------------- 12. arguments checked at the door
@pytest.mark.parametrize("kw,exc,match", [
    ({"seed": -1}, ValueError, "seed must be an integer >= 0, got -1"),
    ({"seed": 1.5}, TypeError, "seed must be an integer, got 1.5"),
    ({"cache_scenes": -1}, ValueError, "cache_scenes must be an integer >= 0, got -1"),
    ({"max_lights": 10 ** 9}, ValueError, r"max_lights must be an integer in \[0, 4,096\], got 1000000000"),
    ({"samples_per_scene": 2.5}, TypeError, "samples_per_scene must be an integer, got 2.5"),
    ({"samples_per_scene": 0}, ValueError, "samples_per_scene must be an integer >= 1"),
    ({"noise": "no"}, TypeError, "noise must be True or False"),
    ({"line_time_s": -1e-5}, ValueError, "line_time_s must be None or a finite number > 0"),
])
def test_dataset_arguments_are_checked_at_construction(tmp_path_factory, kw, exc, match):
    from lfmbench.datasets import LFMCaptureDataset
    from tests.data.corpus.data import make_corpus

    root = tmp_path_factory.getbasetemp() / "args-corpus"
    if not (root / "manifest.json").exists():
        make_corpus(root, n_scenes=1)
    with pytest.raises(exc, match=match):
        LFMCaptureDataset(root, split="all", cache_dir=False, **kw)


def test_set_epoch_checks_its_argument(tmp_path):
    from lfmbench.datasets import LFMCaptureDataset
    from tests.data.corpus.data import make_corpus

    ds = LFMCaptureDataset(make_corpus(tmp_path / "c", n_scenes=1), split="all", cache_dir=False)
    for bad, exc in ((-5, ValueError), (1.5, TypeError), ("3", TypeError)):
        with pytest.raises(exc, match="epoch must be an integer"):
            ds.set_epoch(bad)
    assert ds.epoch == 0


def test_validate_report_is_the_same_with_worker_processes(tmp_path):
    """Big corpora are validated by several processes; the report (errors, warnings, their order) must not
    depend on it. The 100,000-scene timing is benchmarks/bench_validate.py (docs/benchmarks/validate.md)."""
    from lfmbench import corpus as C
    from lfmbench.corpus import validate as V
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=3)
    (root / "scenes/scene00001/f001/skymap.exr").write_bytes(b"v/1\x01" + b"\0" * 40)  # bad checksum, corrupt
    (root / "scenes/scene00002/f000/aux.exr").unlink()
    (root / "scenes/scene00000/notes.txt").write_text("mine")
    one = C.validate_corpus(root, workers=1)
    assert not one.ok and len(one.errors) >= 3 and one.warnings
    chunk = V.CHUNK_SCENES
    V.CHUNK_SCENES = 1  # three tasks over two processes
    try:
        two = C.validate_corpus(root, workers=2)
    finally:
        V.CHUNK_SCENES = chunk
    assert two.to_dict() == one.to_dict()
