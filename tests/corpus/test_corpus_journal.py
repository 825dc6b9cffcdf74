"""The manifest journal of ``CorpusWriter`` (``docs/guide/corpus-format.md`` section 7): a commit costs the same
whatever the corpus's size, and a writer killed at any point leaves a corpus that validates and resumes."""
from __future__ import annotations

import json
import os
import types

import pytest
from typer.testing import CliRunner

from lfmbench import corpus as C
from lfmbench.cli import app
from lfmbench.corpus import writer as W
from tests.data.corpus.data import fake_frames, fake_meta, fake_scene


def _hashes(sid: str) -> dict[str, str]:
    """Fake file entries of a scene (commit_scene does not read the files)."""
    return {f"scenes/{sid}/{n}": f"{i:064x}" for i, n in enumerate(("scene.json", "meta.json", "f000/sky.exr"))}


def test_commit_cost_does_not_grow_with_the_corpus(tmp_path, monkeypatch):
    """Bytes written to manifest.json per commit, counted (not timed): the same for 64 and 512 scenes (it was a
    whole manifest per commit: 8 times more per commit at 512 scenes than at 64)."""
    written = {"manifest": 0, "rewrites": 0}
    real = W.atomic_write_json

    def counting(path, obj):
        written["manifest"] += len(json.dumps(obj))
        written["rewrites"] += 1
        return real(path, obj)

    monkeypatch.setattr(W, "atomic_write_json", counting)
    per_commit = {}
    for n in (64, 512):
        root = tmp_path / f"c{n}"
        with C.CorpusWriter(root) as w:
            written.update(manifest=0, rewrites=0)
            for i in range(n):
                w.commit_scene(f"s{i:05d}", _hashes(f"s{i:05d}"))
                assert w.is_complete(f"s{i:05d}", verify=False)
            per_commit[n] = written["manifest"] / n
        man = json.loads((root / "manifest.json").read_text())
        assert len(man["scenes"]) == n and len(man["files"]) == 3 * n  # all there once the writer closed
        assert not (root / W.JOURNAL_NAME).exists()
    scene_bytes = len(json.dumps(_hashes("s00000"))) + 10
    assert per_commit[512] < 1.3 * per_commit[64] and per_commit[512] < 12 * scene_bytes, per_commit


def _write(w, sid):
    m = fake_meta(sid, frames=1, n_lights=1)
    w.write_scene(sid, fake_scene(sid), m, fake_frames(m, seed=int(sid[-2:])))


class _Killed(BaseException):
    """Stands for SIGKILL: nothing after it runs (the test abandons the writer without closing it)."""


def _kill_plan(point: str, at: int):
    """A stand-in for ``os`` and ``atomic_write_json`` in the writer module that kills at the ``at``-th
    ``point``: "torn" (half a journal line written), "fsync" (line written, not synced), "manifest" (before
    the manifest's rewrite), "unlink" (manifest rewritten, journal not yet removed)."""
    count = {"n": 0}

    def hit(p):
        if p == point:
            count["n"] += 1
            if count["n"] == at:
                raise _Killed

    def write(fd, data):
        if point == "torn":
            try:
                hit("torn")
            except _Killed:
                os.write(fd, data[:len(data) // 2])
                raise
        return os.write(fd, data)

    def fsync(fd):
        hit("fsync")
        return os.fsync(fd)

    fake_os = types.SimpleNamespace(**{k: getattr(os, k) for k in dir(os) if not k.startswith("__")})
    fake_os.write, fake_os.fsync = write, fsync

    def manifest(path, obj):
        if path.name == "manifest.json":
            hit("manifest")
        res = W.__dict__["_real_atomic_write_json"](path, obj)
        if path.name == "manifest.json":
            hit("unlink")
        return res
    return fake_os, manifest


@pytest.mark.parametrize("point,at", [("torn", 5), ("fsync", 5), ("manifest", 4), ("unlink", 4), ("torn", 11),
                                      ("manifest", 6), ("unlink", 6)])
def test_a_writer_killed_at_any_point_leaves_a_corpus_that_resumes(tmp_path, monkeypatch, point, at):
    root = tmp_path / "c"
    monkeypatch.setattr(W, "COMPACT_FRACTION", 1 / 2)  # a manifest that lags, with few scenes
    ids = [f"scene{i:05d}" for i in range(14)]
    done = []
    fake_os, manifest = _kill_plan(point, at)
    monkeypatch.setattr(W, "_real_atomic_write_json", W.atomic_write_json, raising=False)
    monkeypatch.setattr(W, "atomic_write_json", manifest)
    monkeypatch.setattr(W, "os", fake_os)
    w = C.CorpusWriter(root)
    w.on_compact = lambda: w.write_splits(0)  # as render does: splits.json follows the manifest
    with pytest.raises(_Killed):
        for sid in ids:
            _write(w, sid)
            done.append(sid)
    monkeypatch.undo()  # the process is gone: its lock with it (a writer of this process would share it)
    w._lock.release()
    rep = C.validate_corpus(root)  # what the killed writer left: complete scenes only, and it validates
    assert rep.ok, rep.errors
    listed = C.Corpus(root).scenes
    assert set(listed) <= set(done) | {ids[len(done)]}  # the scene being committed: either way
    w2 = C.CorpusWriter(root)  # the resume: replays the journal (a torn last line is a scene not committed)
    assert not (root / W.JOURNAL_NAME).exists()
    have = [s for s in ids if w2.is_complete(s)]
    assert set(done) <= set(have) <= set(done) | {ids[len(done)]}, (done, have)
    for sid in ids:
        if sid not in have:
            _write(w2, sid)
    w2.write_splits(0)
    w2.close()
    rep = C.validate_corpus(root)
    assert rep.ok and not rep.warnings and C.Corpus(root).scenes == ids, (rep.errors, rep.warnings)


def test_a_damaged_journal_is_one_line_naming_it(tmp_path):
    root = tmp_path / "c"
    with C.CorpusWriter(root) as w:
        _write(w, "scene00000")
    good = (root / "manifest.json").read_bytes()
    (root / W.JOURNAL_NAME).write_text('{"commit": "scene00001", "files": {}}\n{"forget": "scene00000"}\n')
    with pytest.raises(C.CorpusError, match=r"\.lfmbench\.journal line 1: bad file entries"):
        C.CorpusWriter(root)
    (root / W.JOURNAL_NAME).write_text('{"commit": "../x", "files": {"a": "b"}}\n')
    r = CliRunner().invoke(app, ["render", "--out", str(root), "--scenes", "1", "--profile", "small"])
    out = " ".join(r.output.split())
    assert r.exit_code == 2 and "Traceback" not in r.output and ".lfmbench.journal line 1" in out, r.output
    assert (root / "manifest.json").read_bytes() == good and (root / W.JOURNAL_NAME).exists()  # kept, as it was
