"""``validate_corpus(cache=...)`` (lfmbench.corpus.validate_cache) and the single-read paths of validate: an
unchanged corpus is not hashed or checked again, and every change (content, times restored, manifest, a new
file, the limits) is seen; the header-only EXR description equals OpenEXR's."""
from __future__ import annotations

import hashlib
import json
import os

import numpy as np
import OpenEXR
import pytest
from typer.testing import CliRunner

from lfmbench import corpus as C
from lfmbench import limits
from lfmbench.cli import app
from lfmbench.corpus import validate as V
from lfmbench.corpus import validate_cache as VC
from tests.data.corpus.data import make_corpus


def _report(rep):
    d = rep.to_dict()
    return {k: d[k] for k in ("ok", "n_scenes", "n_files", "errors", "warnings")}


@pytest.fixture
def settled(monkeypatch):
    """Files written a moment ago count as settled (the racy rule is tested on its own below)."""
    monkeypatch.setattr(VC, "RACY_S", 0.0)


def test_header_only_parts_equal_openexrs_header(tmp_path):
    bands = [500.0, 600.0]
    files = {
        "static": C.encode_static_exr({w: np.full((2, 4, 6), 0.5, np.float32) for w in ("short", "long")}, bands,
                                      attrs={"my_float": 0.1, "my_int": 3, "my_text": "x"}),
        "lights": C.encode_lights_exr([(3, (0, 0, 2, 2), np.ones((2, 2, 2, 2), np.float32)),
                                       (5, (1, 2, 4, 6), np.ones((2, 2, 3, 4), np.float32))], bands, 2, 4, 6),
        "empty": C.encode_lights_exr([], bands, 2, 4, 6),
        "aux": C.encode_aux_exr({k: np.zeros((4, 6), np.float32) for k in C.AUX_CHANNELS}, 4, 6),
    }
    for name, data in files.items():
        p = tmp_path / f"{name}.exr"
        p.write_bytes(data)
        ours = C.read_exr(p, header_only=True)
        theirs = OpenEXR.File(str(p), header_only=True).parts
        assert len(ours) == len(theirs) >= 1
        for a, b in zip(ours, theirs):
            h = b.header
            (x0, y0), (x1, y1) = (tuple(int(v) for v in c) for c in h["dataWindow"])
            (_, _), (wx1, wy1) = (tuple(int(v) for v in c) for c in h["displayWindow"])
            assert (a.name, a.window, a.size) == (b.name(), (y0, x0, y1 + 1, x1 + 1), (wy1 + 1, wx1 + 1))
            assert a.channel_names == [c.name for c in h["channels"]]
            simple = {k: v for k, v in h.items() if type(v) in (int, float, str)}
            assert {k: v for k, v in a.header.items() if not k.endswith("Window")} == simple
            assert {type(v) for v in a.header.values()} <= {int, float, str, tuple}
    full = C.read_exr(tmp_path / "lights.exr")  # the full read agrees on the parts it names
    # every bin the same (format version 3): each light's bins shrink to one pixel, its steady part holds the rest
    assert [p.name for p in full] == ["light3", "steady3", "light5", "steady5"]
    assert full[2].channels["bin01.600nm"].shape == (1, 1) and full[3].channels["steady.600nm"].shape == (3, 4)
    with pytest.raises(C.CorpusFileError, match="EXR file is missing"):
        C.read_exr(tmp_path / "nothing.exr")


@pytest.mark.parametrize("size", [0, 1, 4095, (1 << 20) - 1, 1 << 20, (1 << 20) + 1, 3 << 20])
def test_hash_in_one_pass_equals_sha256(tmp_path, size):
    data = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8).tobytes()
    p = tmp_path / "f"
    p.write_bytes(data)
    digest, head = V._hash_head(str(p), size, 1000)
    assert digest == hashlib.sha256(data).hexdigest() == C.sha256_file(p)
    assert head == data[:1000]


def test_unchanged_scenes_are_not_checked_again_and_every_change_is_seen(tmp_path, settled):
    root = make_corpus(tmp_path / "c", n_scenes=3)
    cache = root / ".cache" / "validate.bin"
    first = C.validate_corpus(root, cache=True)
    n_listed = first.n_files
    assert first.ok and (first.cached_files, first.cached_scenes) == (0, 0) and cache.is_file()
    again = C.validate_corpus(root, cache=True)
    assert _report(again) == _report(first) and (again.cached_files, again.cached_scenes) == (n_listed, 3)
    assert _report(C.validate_corpus(root, cache=False)) == _report(first)

    # the same bytes length, its times set back: the ctime (set by the kernel) still changes the key
    exr = root / "scenes/scene00001/f000/skymap.exr"
    good, st = exr.read_bytes(), exr.stat()
    exr.write_bytes(good[:-1] + bytes([good[-1] ^ 1]))
    os.utime(exr, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert exr.stat().st_mtime_ns == st.st_mtime_ns and exr.stat().st_size == st.st_size
    rep = C.validate_corpus(root, cache=True)
    assert any(f"{exr}: bad checksum" in e for e in rep.errors) and rep.cached_scenes == 2
    exr.write_bytes(good)
    assert C.validate_corpus(root, cache=True).ok

    # manifest and file changed together (a consistent edit): the scene is checked again and its error seen
    mp = root / "scenes/scene00002/meta.json"
    m = json.loads(mp.read_text())
    m["fps"] = -1
    mp.write_text(json.dumps(m))
    man = json.loads((root / "manifest.json").read_text())
    man["files"]["scenes/scene00002/meta.json"] = C.sha256_file(mp)
    (root / "manifest.json").write_text(json.dumps(man))
    rep = C.validate_corpus(root, cache=True)
    assert any("scene00002/meta.json" in e and "fps" in e for e in rep.errors), rep.errors

    # a file the manifest does not list: warned every time, and its scene checked again
    (root / "scenes/scene00000/f000/notes.txt").write_text("mine")
    rep = C.validate_corpus(root, cache=True)
    assert any("scene00000/f000/notes.txt: not in manifest" in w for w in rep.warnings)
    assert rep.cached_scenes == 1  # only scene00001: scene00000 has a new entry, scene00002 an error
    rep = C.validate_corpus(root, cache=True)
    assert any("notes.txt: not in manifest" in w for w in rep.warnings) and rep.cached_scenes == 2

    # other limits, other verdicts: a limit that the files now break is reported from the cache's scenes too
    limits.set_limit("exr_channels", 1)
    try:
        rep = C.validate_corpus(root, cache=True)
    finally:
        limits.set_limit("exr_channels", None)
    assert rep.cached_scenes == 0 and any("exr_channels" in e for e in rep.errors)


def test_a_bad_cache_file_is_an_empty_cache(tmp_path, settled):
    root = make_corpus(tmp_path / "c", n_scenes=2)
    ref = _report(C.validate_corpus(root))
    own = tmp_path / "elsewhere" / "v.bin"
    for junk in (b"junk", VC.MAGIC + b"\xff" * 8 + b"x" * 16, VC.MAGIC + (10 ** 6).to_bytes(8, "little")):
        own.parent.mkdir(exist_ok=True)
        own.write_bytes(junk)
        rep = C.validate_corpus(root, cache=own)
        assert _report(rep) == ref and rep.cached_files == 0
    big = VC.max_cache_bytes(ref["n_files"], 2) + 16
    own.write_bytes(VC.MAGIC + b"\0" * big)  # larger than this corpus can have: not read
    rep = C.validate_corpus(root, cache=own)
    assert _report(rep) == ref and rep.cached_files == 0
    assert C.validate_corpus(root, cache=own).cached_scenes == 2  # rewritten by the run before
    assert not (root / ".cache" / "validate.bin").exists()


def test_files_changed_just_before_the_run_are_not_recorded(tmp_path):
    """The racy rule: a file changed less than RACY_S before the run started may still change within the same
    timestamp; it is hashed again next time."""
    root = make_corpus(tmp_path / "c", n_scenes=1)
    for p in (root / "scenes").rglob("*"):
        if p.is_file():
            os.utime(p)  # (the ctime is now, too)
    assert C.validate_corpus(root, cache=True).ok
    rep = C.validate_corpus(root, cache=True)
    assert rep.ok and (rep.cached_files, rep.cached_scenes) == (0, 0)


def test_cache_with_worker_processes_and_the_cli(tmp_path, settled):
    root = make_corpus(tmp_path / "c", n_scenes=3)
    one = C.validate_corpus(root, workers=1)
    chunk = V.CHUNK_SCENES
    V.CHUNK_SCENES = 1  # three tasks over two processes
    try:
        cold = C.validate_corpus(root, workers=2, cache=True)
        warm = C.validate_corpus(root, workers=2, cache=True)
    finally:
        V.CHUNK_SCENES = chunk
    assert _report(cold) == _report(warm) == _report(one) and (cold.cached_scenes, warm.cached_scenes) == (0, 3)
    r = CliRunner().invoke(app, ["validate", "--headers-only", str(root)])  # a pixel verdict covers headers
    assert r.exit_code == 0 and "3 scenes unchanged since an earlier validate" in " ".join(r.output.split())
    r = CliRunner().invoke(app, ["validate", "--no-cache", "--json", str(root)])
    assert r.exit_code == 0 and json.loads(r.output)["cached_scenes"] == 0
    own = tmp_path / "own.bin"
    r = CliRunner().invoke(app, ["validate", "--cache-file", str(own), str(root)])
    assert r.exit_code == 0 and own.is_file() and "unchanged" not in r.output
