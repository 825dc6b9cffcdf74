"""``validate_corpus`` / ``lfmbench validate`` on good and deliberately broken corpora."""
from __future__ import annotations

import json

import numpy as np
import OpenEXR
import pytest
from tests.data.corpus.data import fake_frames, fake_meta, fake_scene
from typer.testing import CliRunner

from lfmbench import corpus as C
from lfmbench.cli import app


@pytest.fixture
def good(tmp_path):
    root = tmp_path / "c"
    w = C.CorpusWriter(root)
    for i in range(2):
        m = fake_meta(f"scene{i:05d}")
        w.write_scene(m["scene_id"], fake_scene(m["scene_id"]), m, fake_frames(m, seed=i))
    w.write_splits(0)
    return root


def _rehash(root, path):
    """Update the manifest checksum of ``path`` (to isolate a content error from a checksum error)."""
    man = json.loads((root / "manifest.json").read_text())
    man["files"][path.relative_to(root).as_posix()] = C.sha256_file(path)
    (root / "manifest.json").write_text(json.dumps(man))


def _rewrite_part(path, part_index, fn):
    f = OpenEXR.File(str(path), separate_channels=True)
    parts = []
    for i, p in enumerate(f.parts):
        ch = {k: np.array(v.pixels) for k, v in p.channels.items()}
        if i == part_index:
            ch = fn(ch)
        h = {k: p.header[k] for k in ("compression", "type", "dataWindow", "displayWindow")}
        parts.append(OpenEXR.Part(h, ch, p.name()))
    OpenEXR.File(parts).write(str(path))


def _errors(root):
    rep = C.validate_corpus(root)
    assert not rep.ok
    return "\n".join(rep.errors)


def test_good_corpus_is_ok(good):
    rep = C.validate_corpus(good)
    assert rep.ok, rep.errors
    assert rep.n_scenes == 2 and rep.n_files == 2 * (2 + 2 * 4)
    assert rep.warnings == []
    res = CliRunner().invoke(app, ["validate", str(good)])
    assert res.exit_code == 0, res.output
    assert "OK" in res.output
    res = CliRunner().invoke(app, ["validate", str(good), "--json"])
    assert json.loads(res.output)["ok"] is True


def test_missing_file(good):
    p = good / "scenes/scene00001/f001/headlights.exr"
    p.unlink()
    assert "scene00001/f001/headlights.exr: missing" in _errors(good)
    res = CliRunner().invoke(app, ["validate", str(good)])
    assert res.exit_code == 1
    assert "headlights.exr" in res.output and "1 error" in res.output


def test_bad_checksum(good):
    p = good / "scenes/scene00000/meta.json"
    m = json.loads(p.read_text())
    m["camera"]["speed_mps"] = 31.0  # still a valid meta, but not what was recorded
    p.write_text(json.dumps(m))
    assert "meta.json: bad checksum" in _errors(good)


def test_missing_and_extra_channels(good):
    p = good / "scenes/scene00000/f000/skymap.exr"

    def edit(ch):
        ch["short.555nm"] = ch.pop("short.550nm")
        return ch
    _rewrite_part(p, 0, edit)
    _rehash(good, p)
    e = _errors(good)
    assert "skymap.exr part 'static': missing channels ['short.550nm']" in e
    assert "unexpected channels ['short.555nm']" in e
    assert "checksum" not in e


def test_channels_vs_meta_bins(good):
    """meta.json announces 4 bins, the file has 3: every bin03 channel is missing."""
    p = good / "scenes/scene00001/meta.json"
    m = json.loads(p.read_text())
    m["timing"]["bins"] = 4
    p.write_text(json.dumps(m))
    _rehash(good, p)
    e = _errors(good)
    assert "otherlights.exr part 'light0': missing channels ['bin03.400nm'" in e


@pytest.mark.parametrize("value, word", [(np.nan, "NaN"), (np.inf, "inf"), (-2.0, "negative")])
def test_bad_radiance_values(good, value, word):
    p = good / "scenes/scene00001/f000/otherlights.exr"

    def edit(ch):
        ch["bin01.700nm"][0, 0] = value
        return ch
    _rewrite_part(p, 1, edit)
    _rehash(good, p)
    assert f"otherlights.exr part 'light1': 1 {word} radiance values" in _errors(good)
    # headers-only validation does not decode pixels
    assert C.validate_corpus(good, check_pixels=False).ok


def test_unknown_light_part_and_bad_aux(good):
    meta_p = good / "scenes/scene00000/meta.json"
    m = json.loads(meta_p.read_text())
    m["lights"] = m["lights"][:1]  # light 1 no longer announced
    meta_p.write_text(json.dumps(m))
    _rehash(good, meta_p)
    aux = good / "scenes/scene00000/f001/aux.exr"

    def edit(ch):
        ch["mask.light"][0, 0] = 2.5
        return ch
    _rewrite_part(aux, 0, edit)
    _rehash(good, aux)
    e = _errors(good)
    assert "part 'light1' is not a light of group 'otherlights'" in e
    assert "aux.exr [mask.light]: ids must be integers" in e


def test_corrupt_exr_and_unlisted_files(good):
    p = good / "scenes/scene00000/f001/skymap.exr"
    p.write_bytes(b"\x76\x2f\x31\x01" + b"\0" * 50)  # EXR magic number, garbage after it
    _rehash(good, p)
    (good / "scenes/scene00000/f001/extra.txt").write_text("x")
    (good / "scenes/scene00000" / f"{C.TMP_PREFIX}foo").write_text("x")
    rep = C.validate_corpus(good)
    assert any("cannot read EXR file" in e and "skymap.exr" in e for e in rep.errors)
    assert any("extra.txt: not in manifest" in w for w in rep.warnings)
    assert any("temporary file" in w for w in rep.warnings)


def test_manifest_and_splits_problems(good, tmp_path):
    (good / "splits.json").write_text(json.dumps({"train": ["scene00000", "ghost"], "val": [],
                                                  "test": ["scene00000"]}))
    e = _errors(good)
    assert "more than one split" in e and "ghost" in e
    (good / "splits.json").unlink()
    assert "splits.json: missing" in _errors(good)
    rep = C.validate_corpus(tmp_path / "none")
    assert not rep.ok and "manifest missing" in rep.errors[0]
    (good / "manifest.json").write_text(json.dumps({"format": "other"}))
    assert "not an lfmbench corpus manifest" in _errors(good)
    res = CliRunner().invoke(app, ["validate", str(tmp_path / "none")])
    assert res.exit_code == 1


def test_invalid_meta_reported(good):
    p = good / "scenes/scene00001/meta.json"
    m = json.loads(p.read_text())
    m["timing"]["short_exposure_s"] = 0.05  # longer than the frame time
    p.write_text(json.dumps(m))
    _rehash(good, p)
    assert "short_exposure_s = 0.05 s is longer than long_exposure_s" in _errors(good)


def test_bbox_must_hold_the_part_data_window(good):
    mp = good / "scenes" / "scene00000" / "meta.json"
    meta = json.loads(mp.read_text())
    meta["lights"][0]["bbox"][1] = [1, 1, 4, 2]  # the part light0 of frame 1 is (1, 1, 4, 3): not inside
    meta["lights"][1]["bbox"][0] = None           # the part light1 of frame 0 exists
    mp.write_text(json.dumps(meta))
    _rehash(good, mp)
    errs = C.validate_corpus(good).errors
    assert any("f001/otherlights.exr" in e and "'light0'" in e and "bbox[1]" in e for e in errs), errs
    assert any("f000/otherlights.exr" in e and "'light1'" in e and "bbox[0] is null" in e for e in errs), errs
    assert len(errs) == 2, errs


def test_scene_json_must_be_an_object(good):
    sp = good / "scenes" / "scene00001" / "scene.json"
    sp.write_text("[1, 2]")
    _rehash(good, sp)
    errs = C.validate_corpus(good).errors
    assert len(errs) == 1 and "scene00001/scene.json" in errs[0] and "JSON object" in errs[0], errs
