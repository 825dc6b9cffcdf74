"""Static window layers (:mod:`lfmbench.corpus.window_layers`): a chopped capture is served from the layer of exactly
its windows, the sample's meta says ``static_windows: exact``; without the layer it is ``nearest``.

The layer holds a known image times one spectrum, the long window another, so the chopped capture's noise-free
electrons over the long capture's (each divided by its exposure time) is the ratio of the two images pixel by pixel,
whatever the colour filter: an answer written here from the layer's definition."""
from __future__ import annotations

import json

import numpy as np
import pytest

from lfmbench import corpus as C
from lfmbench.corpus import window_layers as WL
from lfmbench.datasets import LFMCaptureDataset
from lfmbench.datasets.plan_frames import compose_plan_frame, plan_exposures
from lfmbench.datasets.projection import build_layers, unit_projection_preset
from lfmbench.sensor import load_preset
from lfmbench.sensor.plan import resolve_windows
from tests.datasets.test_static_bins import GROUPS, H, W, _write

SID = "scene00000"


def _add_layer(root, meta, rng, moves=True):
    wins = resolve_windows(load_preset("chopped").captures["chopped"].exposure, meta["timing"])
    spec = np.array([1.0, 0.6, 0.3], np.float32)[:, None, None]
    imgs = {f: (rng.random((H, W)) * 2e-3 + 1e-4).astype(np.float32) for f in range(2)}
    frames = [(f, {g: imgs[f] * spec * (1.0 if g == "headlights" else 0.5) for g in GROUPS}) for f in range(2)]
    m = json.loads((root / f"scenes/{SID}/meta.json").read_text())
    before = {p: p.stat().st_mtime_ns for p in (root / "scenes").rglob("*") if p.is_file()}
    hashes = WL.write_layer(root, SID, m, "chopped", wins, moves, frames, "float32", {"spp": 2})
    assert {p: p.stat().st_mtime_ns for p in before} == before          # no file it had was touched
    w = C.CorpusWriter(root, dtype="float32")
    w.commit_scene(SID, {**w.scene_files(SID), **hashes})
    w.close()
    return imgs


def test_chopped_capture_is_served_exactly_from_its_layer(tmp_path):
    rng = np.random.default_rng(3)
    meta, _edges, bins, _spec = _write(tmp_path / "c", rng)
    p = load_preset("chopped")
    ds = LFMCaptureDataset(tmp_path / "c", split="all", sensor="chopped", frames=1, cache_dir=False, outputs=("gt",))
    assert ds[0]["meta"]["static_windows"] == "nearest"      # the bins do not cut the sub-windows
    with pytest.raises(ValueError, match=r"chopped\.yaml: field 'captures\.chopped\.exposure' window 0"):
        plan_exposures(p, meta, "global", static_windows="exact")
    layer = _add_layer(tmp_path / "c", meta, rng)
    assert C.validate_corpus(tmp_path / "c").ok
    c = C.Corpus(tmp_path / "c")
    tm = c.meta(SID)["timing"]
    assert [x["name"] for x in tm["window_layers"]] == ["chopped"]
    ds = LFMCaptureDataset(tmp_path / "c", split="all", sensor="chopped", frames=1, cache_dir=False,
                           static_windows="exact", outputs=("gt",))
    assert ds[0]["meta"]["static_windows"] == "exact"
    exposures = plan_exposures(p, c.meta(SID), "global", static_windows="exact")
    lay = build_layers(c, SID, unit_projection_preset(p), None, 2, optics=False, aux=())
    t = c.meta(SID)["timing"]
    wgt = C.window_bin_weights(_edges, 0.0, t["long_exposure_s"])    # the long window: a union of the bins
    for f in range(2):
        ch = compose_plan_frame(lay, c.meta(SID), f, (0, 0, H, W), {}, {}, exposures, p.reference)["chopped"]
        got = (ch / exposures[0].fill_factor / 1.2e-3 / lay.static["spd"][f]).double().numpy()  # over the long one
        want = layer[f] / np.tensordot(wgt, bins[f].astype(np.float64), axes=1)
        assert np.allclose(got, want, rtol=1e-4), f


def test_layer_where_nothing_moves_is_the_long_window_and_bad_layers_write_nothing(tmp_path):
    rng = np.random.default_rng(4)
    meta, *_ = _write(tmp_path / "c", rng)
    m = json.loads((tmp_path / f"c/scenes/{SID}/meta.json").read_text())
    with pytest.raises(ValueError, match=r"static_layers\[0\]\.windows_s\[1\]: starts at 0\.5 ms, before"):
        WL.write_layer(tmp_path / "c", SID, m, "c", [(0.0, 0.001), (0.0005, 0.001)], True, [], "float32")
    with pytest.raises(ValueError, match=r"windows_s\[0\]: ends at 20 ms, after the capture window"):
        WL.write_layer(tmp_path / "c", SID, m, "c", [(0.019, 0.001)], True, [], "float32")
    assert not (tmp_path / f"c/scenes/{SID}/{WL.LAYERS_FILE}").exists()
    assert not list((tmp_path / "c/scenes").rglob("*.layer_*"))
    _add_layer(tmp_path / "c", meta, rng, moves=False)
    assert not list((tmp_path / "c/scenes").rglob("*.layer_*"))
    ds = LFMCaptureDataset(tmp_path / "c", split="all", sensor="chopped", frames=1, cache_dir=False,
                           static_windows="exact", outputs=("gt",))
    assert ds[0]["meta"]["static_windows"] == "exact"
    # a malformed layers file: one line naming the file and the field
    (tmp_path / f"c/scenes/{SID}/{WL.LAYERS_FILE}").write_text(json.dumps(
        {"format": "lfmbench-window-layers", "version": 1, "layers": [{"name": "x", "windows_s": [[0, -1]],
                                                                      "moves": True}]}))
    with pytest.raises(C.CorpusFileError, match=r"window_layers\.json: layers\[0\]\.windows_s\[0\]: needs start"):
        C.Corpus(tmp_path / "c").meta(SID)
