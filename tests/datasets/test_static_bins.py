"""Static time bins (corpus format version 4, ``meta.json`` ``timing.static_edges_s``): written, validated, read back,
and each capture of a plan served by the exact sum of the bins its windows cover (docs/benchmarks/motion-windows.md).

The static radiance is a known image per bin times one spectrum, so a capture's noise-free electrons divided by
another's is the ratio of the two windows' time averages of those images, pixel by pixel, whatever the colour filter:
an answer written here from the bins' definition, independent of the dataset's code."""
from __future__ import annotations

import json

import numpy as np
import pytest

from lfmbench import corpus as C
from lfmbench.datasets import LFMCaptureDataset
from lfmbench.datasets.plan_frames import compose_plan_frame, plan_exposures
from lfmbench.datasets.projection import build_layers, unit_projection_preset
from lfmbench.sensor import load_preset
from lfmbench.sensor.plan import resolve_windows
from tests.data.corpus.data import fake_meta, fake_scene

H, W = 16, 24
GROUPS = {"headlights": {"flicker": False}, "skymap": {"flicker": False}}


def _edges(meta):
    t = meta["timing"]
    ts, tl = t["short_exposure_s"], t["long_exposure_s"]
    stag = [x for a, n in ((0.0, 0.010), (0.010, 0.001), (0.011, 0.0001)) for x in (a, a + n)]
    return sorted({0.0, (tl - ts) / 2, (tl + ts) / 2, tl, *stag})


def _write(root, rng):
    meta = fake_meta("scene00000", width=W, height=H, frames=2, groups=GROUPS, n_lights=0)
    edges = _edges(meta)
    meta["timing"]["static_edges_s"] = edges
    B = len(edges) - 1
    spec = np.array([1.0, 0.6, 0.3], np.float32)[:, None, None]
    imgs = {}
    frames = []
    for n in range(2):
        a = (rng.random((B, H, W)) * 2e-3 + 1e-4).astype(np.float32)               # per-bin image
        imgs[n] = a
        st = {g: {"bins": (a[:, None] * spec * (1.0 if g == "headlights" else 0.5)).astype(np.float32)}
              for g in GROUPS}
        frames.append({"frame": n, "static": st, "lights": {}})
    w = C.CorpusWriter(root, dtype="float32")
    w.write_scene("scene00000", fake_scene(), meta, frames)
    w.write_splits(0)
    w.close()
    return meta, np.asarray(edges), imgs, spec


def test_static_bins_round_trip_and_validate(tmp_path):
    meta, edges, imgs, spec = _write(tmp_path / "c", np.random.default_rng(1))
    c = C.Corpus(tmp_path / "c")
    assert C.validate_corpus(tmp_path / "c").ok
    m = json.loads((tmp_path / "c/scenes/scene00000/meta.json").read_text())
    assert m["storage"]["format_version"] == C.STATIC_BINS_VERSION
    e, bins = c.read_static_bins("scene00000", 1, "headlights")
    assert np.allclose(e, edges) and np.array_equal(bins, imgs[1][:, None] * spec)
    t = meta["timing"]
    sa, ts = (t["long_exposure_s"] - t["short_exposure_s"]) / 2, t["short_exposure_s"]
    k = (edges[:-1] >= sa - 1e-12) & (edges[1:] <= sa + ts + 1e-12)                # the bins of the short window
    want = (np.diff(edges)[k, None, None, None] * bins[k]).sum(0) / ts
    assert np.allclose(c.read_static("scene00000", 1, "headlights", "short"), want, rtol=1e-6)
    # a layer missing from the file is reported by validate, naming the file
    bad = dict(meta, timing=dict(meta["timing"], static_edges_s=[0.0, 0.001]))
    with pytest.raises(ValueError, match=r"static_edges_s must hold the short window's ends"):
        C.validate_meta(bad)


def test_each_staggered_capture_is_the_exact_average_of_its_bins(tmp_path):
    meta, edges, imgs, _ = _write(tmp_path / "c", np.random.default_rng(2))
    c = C.Corpus(tmp_path / "c")
    p = load_preset("staggered")
    layers = build_layers(c, "scene00000", unit_projection_preset(p), None, 2, optics=False, aux=())
    exposures = plan_exposures(p, meta, "global", static_windows="exact")
    ds = LFMCaptureDataset(tmp_path / "c", split="all", sensor="staggered", frames=2, cache_dir=False,
                           static_windows="exact", outputs=("gt",))
    assert ds[0]["meta"]["static_windows"] == "exact"

    def mean_over(a, n, f):
        """Time average over [a, a + n) s of the bin images, from the bins' definition (overlap of [a, a + n)
        with each bin, by brute force on a fine grid of the window)."""
        t = a + (np.arange(20000) + 0.5) / 20000 * n
        k = np.searchsorted(edges, t, side="right") - 1
        return imgs[f][k].astype(np.float64).mean(0)

    for f in range(2):
        out = compose_plan_frame(layers, meta, f, (0, 0, H, W), {}, {}, exposures, p.reference)
        (la, ln), = resolve_windows(p.captures["long"].exposure, meta["timing"])
        for cap in ("medium", "short"):
            (a, n), = resolve_windows(p.captures[cap].exposure, meta["timing"])
            want = (mean_over(a, n, f) * n) / (mean_over(la, ln, f) * ln)
            got = (out[cap] / out["long"]).double().numpy()
            assert np.allclose(got, want, rtol=1e-3), cap
    # the former rule (nearest: the long window for these) is far off: the test can tell them apart
    assert not np.allclose(imgs[0][4], imgs[0][:3].mean(0), rtol=0.1)
