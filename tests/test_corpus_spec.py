"""docs/corpus-format.md is enough to write a compatible corpus: an independent writer (bare OpenEXR + json +
hashlib, no lfmbench code) following only that document produces a corpus that validates and reads back."""
from __future__ import annotations

import hashlib
import json

import numpy as np
import OpenEXR

from lfmbench.corpus import Corpus, validate_corpus

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
                        "spectrum": "x", "bbox": [[1, 2, 3, 5]]}]}
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
