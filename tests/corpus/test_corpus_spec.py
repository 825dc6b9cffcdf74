"""docs/guide/corpus-format.md is enough to write a compatible corpus: an independent writer (bare OpenEXR + json +
hashlib, no lfmbench code) following only that document produces a corpus that validates and reads back."""
from __future__ import annotations

import hashlib
import json

import numpy as np
import OpenEXR

import pytest

from lfmbench.corpus import Corpus, make_splits, validate_corpus, validate_meta

W, H, K = 9, 5, 2
BANDS = [450, 500.5]


def _exr(path, parts):
    path.parent.mkdir(parents=True, exist_ok=True)
    OpenEXR.File(parts).write(str(path))


def _part(name, channels, box=None):
    y0, x0, y1, x1 = box or (0, 0, H, W)
    h = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
         "displayWindow": ((0, 0), (W - 1, H - 1)), "dataWindow": ((x0, y0), (x1 - 1, y1 - 1))}
    return OpenEXR.Part(h, channels, name)


def test_independent_writer_following_the_spec(tmp_path):
    rng = np.random.default_rng(5)
    root = tmp_path / "corpus"
    sdir = root / "scenes" / "ext-1"
    fps, tl, ts, line = 30.0, 0.02, 0.005, 1e-5
    meta = {"scene_id": "ext-1", "width": W, "height": H, "bands_nm": BANDS, "band_width_nm": 5.0, "fps": fps,
            "frames": 1,
            "timing": {"short_exposure_s": ts, "long_exposure_s": tl, "alignment": "center", "line_time_s": line,
                       "readout_s": H * line, "capture_window_s": tl + H * line, "bins": K},
            "camera": {"fov_x_deg": 50.0, "K": [[9, 0, 4.5], [0, 9, 2.5], [0, 0, 1]], "speed_mps": 0.0,
                       "yaw_rate_rad_s": 0.0, "poses": [[np.eye(4).tolist(), np.eye(4).tolist()]]},
            "groups": {"sky": {"flicker": False}, "leds": {"flicker": True}},
            "lights": [{"id": 12, "group": "leds", "kind": "tail", "instance": 3, "luminance_cd_m2": 50.0,
                        "spectrum": {"model": "led", "peak_nm": 620, "fwhm_nm": 18}, "bbox": [[1, 2, 3, 5]]}]}
    sdir.mkdir(parents=True)
    (sdir / "meta.json").write_text(json.dumps(meta))
    (sdir / "scene.json").write_text(json.dumps({"made_by": "another tool"}))
    sky = {w: rng.random((2, H, W)).astype(np.float32) for w in ("short", "long")}
    _exr(sdir / "f000" / "sky.exr", [_part("static", {
        f"{w}.{format(b, '.6g')}nm": sky[w][c].copy() for w in ("short", "long") for c, b in enumerate(BANDS)})])
    led = rng.random((K, 2, 2, 3)).astype(np.float16)  # HALF is allowed
    _exr(sdir / "f000" / "leds.exr", [_part("light12", {
        f"bin{k:02d}.{format(b, '.6g')}nm": led[k, c].copy() for k in range(K) for c, b in enumerate(BANDS)},
        box=(1, 2, 3, 5))])
    aux = {"depth.Z": np.full((H, W), np.inf, np.float32), "depth.R": np.full((H, W), np.inf, np.float32),
           "mask.instance": np.full((H, W), -1, np.float32), "mask.light": np.full((H, W), -1, np.float32)}
    _exr(sdir / "f000" / "aux.exr", [_part("aux", dict(aux))])
    files = {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
             for p in sdir.rglob("*") if p.is_file()}
    (root / "manifest.json").write_text(json.dumps({"format": "lfmbench-corpus", "version": 1,
                                                    "scenes": ["ext-1"], "files": files}))
    (root / "splits.json").write_text(json.dumps({"train": [], "val": [], "test": ["ext-1"]}))

    rep = validate_corpus(root)
    assert rep.ok, rep.errors
    assert rep.warnings == []
    c = Corpus(root)
    np.testing.assert_array_equal(c.read_static("ext-1", 0, "sky", "long", bands=[500.5]), sky["long"][1:])
    [(lid, box, arr)] = c.read_light_bins("ext-1", 0, "leds")
    assert (lid, box) == (12, (1, 2, 3, 5))
    np.testing.assert_array_equal(arr, led.astype(np.float32))
    assert arr.dtype == np.float32

    # version 3 (section 6.2): the bins over part of the box, a steady part (the same in every bin) overlapping it
    bins = rng.random((K, 2, 1, 2)).astype(np.float32)       # window (1, 3, 2, 5)
    steady = rng.random((2, 2, 2)).astype(np.float32)        # window (1, 2, 3, 4)
    _exr(sdir / "f000" / "leds.exr", [
        _part("light12", {f"bin{k:02d}.{format(b, '.6g')}nm": bins[k, c].copy() for k in range(K)
                          for c, b in enumerate(BANDS)}, box=(1, 3, 2, 5)),
        _part("steady12", {f"steady.{format(b, '.6g')}nm": steady[c].copy() for c, b in enumerate(BANDS)},
              box=(1, 2, 3, 4))])
    files["scenes/ext-1/f000/leds.exr"] = hashlib.sha256((sdir / "f000" / "leds.exr").read_bytes()).hexdigest()
    (root / "manifest.json").write_text(json.dumps({"format": "lfmbench-corpus", "version": 3,
                                                    "scenes": ["ext-1"], "files": files}))
    rep = validate_corpus(root)
    assert rep.ok, rep.errors
    want = np.zeros((K, 2, 2, 3), np.float32)                # the box (1, 2, 3, 5)
    want[:, :, 0:1, 1:3] += bins
    want[:, :, 0:2, 0:2] += steady
    [(lid, box, arr)] = Corpus(root).read_light_bins("ext-1", 0, "leds")
    assert (lid, box) == (12, (1, 2, 3, 5))
    np.testing.assert_array_equal(arr, want)


def _meta_with_light(**light):
    meta = {"scene_id": "s", "width": W, "height": H, "bands_nm": BANDS, "fps": 30.0, "frames": 2,
            "timing": {"short_exposure_s": 0.005, "long_exposure_s": 0.02, "capture_window_s": 0.02, "bins": K},
            "groups": {"leds": {"flicker": True}},
            "lights": [{"id": 0, "group": "leds", **light}]}
    return meta


@pytest.mark.parametrize("field,value", [
    ("kind", ""), ("kind", 3), ("instance", -2), ("instance", 1.0), ("luminance_cd_m2", -1.0),
    ("luminance_cd_m2", float("nan")), ("spectrum", "led_red"), ("spectrum", {"peak_nm": 600}),
    ("bbox", [[0, 0, 1, 1]]),                      # one box for two frames
    ("bbox", [[0, 0, 0, 1], None]),                # empty (half-open: y1 > y0)
    ("bbox", [[0, 0, H + 1, 1], None]),            # outside the image
    ("bbox", [[0.0, 0, 1, 1], None]),              # not integers
])
def test_light_fields_have_the_documented_types(field, value):
    with pytest.raises(ValueError, match=rf"meta\.json: field 'lights\[0\]\.{field}"):
        validate_meta(_meta_with_light(**{field: value}), "meta.json")


def test_light_fields_valid_and_optional():
    validate_meta(_meta_with_light(), "meta.json")  # all optional
    validate_meta(_meta_with_light(kind="tail", instance=-1, luminance_cd_m2=0, bbox=[None, [0, 0, H, W]],
                                   spectrum={"model": "illuminant", "name": "D65"}), "meta.json")


def test_empty_groups_refused():
    meta = _meta_with_light()
    meta["groups"], meta["lights"] = {}, []
    with pytest.raises(ValueError, match="groups"):
        validate_meta(meta, "meta.json")


@pytest.mark.parametrize("n", [0, 1, 2, 3, 5, 10])
def test_split_rule_as_documented(n):
    ids = [f"s{i}" for i in range(n)]
    sp = make_splits(ids, 0)
    n_test = min(n, max(1, round(0.2 * n))) if n else 0
    n_val = min(round(0.2 * n), max(0, n - n_test - 1))
    assert [len(sp["test"]), len(sp["val"]), len(sp["train"])] == [n_test, n_val, n - n_test - n_val]
    assert sorted(sp["train"] + sp["val"] + sp["test"]) == sorted(ids)
    if n == 1:
        assert sp == {"train": [], "val": [], "test": ["s0"]}
