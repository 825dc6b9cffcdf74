"""Static time bins (``RenderOptions.static_edges_s``): every capture window integrates the scene over its own time.

A headlight on a car crossing the view (a static group: before the bins its full frames held the car at the
middle of the capture window for every exposure) is rendered with the staggered preset's window edges; each
staggered capture, the exact sum of its bins, must put the lamp where the analytic answer puts it: the time
average of the lamp centre's projection over that capture's window (ego and car motion, :mod:`render_tools.camera`).
"""
from __future__ import annotations

import numpy as np
import pytest

from lfmbench.corpus import window_bin_weights
from render_tools import camera, motion_bound, render, scene
from tests.data.render.data import HPS
from tests.data.render.data import light as _light

#: The staggered preset's windows (lfmbench/configs/sensors/staggered.yaml), s from the frame start.
STAGGERED = ((0.0, 0.010), (0.010, 0.001), (0.011, 0.0001))
LAMP = (8.0, 0.0, 1.4)
VELOCITY = (0.0, -15.0, 0.0)     # crossing left to right, m/s


def crossing_scene(ego_speed=10.0, velocity=VELOCITY):
    s = scene.empty_scene(speed_mps=ego_speed, fov_x_deg=10.0)
    s["materials"]["body"] = {"type": "diffuse", "rgb": [0.2, 0.2, 0.2]}
    s["objects"].append({"id": 0, "kind": "car", "velocity_mps": list(velocity),
                         "parts": [{"shape": "box", "center": [9.0, 0.0, 1.4], "size": [1.5, 1.2, 1.0],
                                    "material": "body"}]})
    s["lights"].append(_light(0, "headlights", LAMP, (-1, 0, 0), (0.2, 0.15), HPS, 2e4, instance=0))
    return scene.validate_scene(s)


def _centroid(img):
    e = img.sum(0)
    ys, xs = np.mgrid[0:e.shape[0], 0:e.shape[1]] + 0.5
    return np.array([(e * xs).sum() / e.sum(), (e * ys).sum() / e.sum()])


def _analytic(s, opts, a, n, samples=201):
    """Time-averaged screen position (x, y) px of the lamp centre over [a, a + n) s (brute force in time)."""
    ego = camera.EgoMotion.from_scene(s)
    K = camera.intrinsics(opts.width, opts.height, float(s["camera"]["fov_x_deg"]))
    uv = [camera.project((np.asarray(LAMP) + np.asarray(VELOCITY) * t)[None], ego.pose_cv(t), K)[0][0]
          for t in a + (np.arange(samples) + 0.5) / samples * n]
    return np.mean(uv, 0)


def test_static_edges_are_left_out_where_nothing_moves():
    opts = render.RenderOptions(width=8, height=4, frames=1, static_edges_s=(0.010, 0.011, 0.0111))
    assert render.static_bin_edges(crossing_scene(0.0, (0, 0, 0)), opts) is None
    assert "static_edges_s" not in render.scene_meta(crossing_scene(0.0, (0, 0, 0)), opts)["timing"]
    e = render.static_bin_edges(crossing_scene(), opts)
    ts, tl = 0.004, opts.long_exposure_s
    assert np.allclose(e, [0, (tl - ts) / 2, (tl + ts) / 2, 0.010, 0.011, 0.0111, tl])
    with pytest.raises(ValueError, match="static_edges_s"):
        render.RenderOptions(width=8, height=4, static_edges_s=(0.5,))


@pytest.mark.jit
def test_each_staggered_capture_sees_the_crossing_car_where_it_is_during_that_capture():
    s = crossing_scene()
    opts = render.RenderOptions(width=40, height=16, spp=4, frames=1, aux=True, line_time_s=0.0,
                                static_edges_s=tuple(x for a, n in STAGGERED for x in (a, a + n)))
    fr = next(render.render_frames(s, opts))
    edges, bins = np.asarray(fr["static_edges_s"]), fr["static"]["headlights"]["bins"]
    long = fr["static"]["headlights"]["long"]
    assert np.allclose(long, np.tensordot(window_bin_weights(edges, 0.0, opts.long_exposure_s), bins, axes=1),
                       rtol=1e-5, atol=1e-6 * long.max())
    for a, n in STAGGERED:
        img = np.tensordot(window_bin_weights(edges, a, n), bins, axes=1)
        want = _analytic(s, opts, a, n)
        assert np.abs(_centroid(img) - want).max() < 0.15, (a, n, _centroid(img), want)
        if n < 0.005:  # the former rule (the long window for these): the lamp ~2-3 px off
            assert np.abs(_centroid(long) - want)[0] > 1.0
    # the masked scheme (docs/benchmarks/motion-windows.md): a window's bins only where a surface point moves by
    # >= 0.25 px over the capture window (render_tools.motion_bound), the long window elsewhere; the car and its lamp
    # move, so each staggered capture still puts the lamp where the analytic answer does, and the sky is left out
    tm = render.frame_timing(s, opts, 0)
    motion = motion_bound.screen_motion_px(s, opts.width, opts.height, fr["aux"]["depth.Z"],
                                           fr["aux"]["mask.instance"], tm["t_aux"], 0.5 * sum(tm["window"]),
                                           *tm["long"])
    mask = motion_bound.motion_mask(motion, 0.25)
    assert 0.0 < mask.mean() < 1.0 and not mask[~np.isfinite(fr["aux"]["depth.Z"])].all()
    for a, n in STAGGERED:
        img = np.where(mask, np.tensordot(window_bin_weights(edges, a, n), bins, axes=1), long)
        assert np.abs(_centroid(img) - _analytic(s, opts, a, n)).max() < 0.15, (a, n)


@pytest.mark.jit
def test_bins_move_only_what_moves_and_equal_a_scene_load_per_bin(monkeypatch):
    """The bins reuse the frame's Mitsuba scene, moving only the moving meshes and beams
    (``mitsuba_scene.place_moving``); a scene loaded anew per bin (the path taken when a mesh changes size) is the
    independent answer: the same float32 vertices, so the same images bit for bit, and the AOVs (traced after the
    bins) see the objects back at the frame's time. A beam (spread < 90 deg) rides on the car, a static wall behind."""
    s = crossing_scene()
    s["lights"][0]["spread_deg"] = 20.0
    s["objects"].append({"id": 1, "kind": "building", "velocity_mps": [0.0, 0.0, 0.0],
                         "parts": [{"shape": "box", "center": [14.0, 0.0, 1.4], "size": [0.2, 8.0, 4.0],
                                    "material": "body"}]})
    s = scene.validate_scene(s)
    opts = render.RenderOptions(width=16, height=8, spp=2, frames=1, aux=True,
                                static_edges_s=tuple(x for a, n in STAGGERED for x in (a, a + n)))
    calls = []
    place = render.ms.place_moving
    monkeypatch.setattr(render.ms, "place_moving", lambda *a, **k: calls.append(a[2]) or place(*a, **k))
    fa = next(render.render_frames(s, opts))
    assert len(calls) == 7  # six bins and the frame's time
    monkeypatch.setattr(render.ms, "place_moving", lambda *a, **k: False)
    fb = next(render.render_frames(s, opts))
    assert fa["static"]["headlights"]["bins"].max() > 0
    for w in ("bins", "short", "long"):
        assert np.array_equal(fa["static"]["headlights"][w], fb["static"]["headlights"][w]), w
    for k in fa["aux"]:
        assert np.array_equal(fa["aux"][k], fb["aux"][k], equal_nan=True), k


@pytest.mark.jit
def test_common_random_numbers_make_bins_differ_only_by_what_moves():
    """``static_bin_samples="common"``: every bin draws the same per-pixel samples, so with the scene all but still
    (ego 1 mm/s: bins exist, the image moves by ~1e-5 px over the frame) the bins are the same image up to that
    motion, where independent bins differ by their sampling noise (the lamp's edges at spp 1); the option is
    recorded in the scene's meta and left out of the options of the default."""
    s = crossing_scene(ego_speed=1e-3, velocity=(0.0, 0.0, 0.0))
    edges = tuple(x for a, n in STAGGERED for x in (a, a + n))
    spread = {}
    for mode in ("independent", "common"):
        opts = render.RenderOptions(width=24, height=12, spp=1, frames=1, aux=False, static_edges_s=edges,
                                    static_bin_samples=mode)
        b = next(render.render_frames(s, opts))["static"]["headlights"]["bins"].astype(np.float64)
        assert b.max() > 0
        spread[mode] = float(np.abs(b - b[0]).max() / b.max())
        meta = render.scene_meta(s, opts)["render"]
        assert meta.get("static_bin_samples") == (None if mode == "independent" else "common")
        assert ("static_bin_samples" in opts.to_dict()) == (mode == "common")
    assert spread["independent"] > 0.05, spread
    assert spread["common"] < 1e-3, spread
    with pytest.raises(ValueError, match="static_bin_samples"):
        render.RenderOptions(width=8, height=4, static_bin_samples="shared")
