"""A flickering lamp's reflection region that leaves the image (issue 40, item 3): its grown crop
(:meth:`render_tools.render.SceneGeometry.light_bbox`) must reach the image's edge where a region cell crosses it
(``RenderOptions.reflection_edges`` ``clip``, auto on scene version 2), or the streak's last rows or columns
hold no flickering light (docs/guide/scenes.md, "Crop edges").

Independent answer: brute force. Each cell of the region (:func:`render_tools.reflections.glossy_cells`, whole)
is sampled densely on the road, every sample projected with the camera at every time sample the box is made
from; every image pixel a sample lands in must lie inside the box and inside the reflection's row bands
(:meth:`~render_tools.render.SceneGeometry.reflection_tiles`), and the box may exceed the samples' box by its
padding only. The region's own definition is checked too: road points sampled densely across the road that meet
the half-vector criterion (the streak, :mod:`render_tools.reflections`) land inside the box."""
from __future__ import annotations

import numpy as np
import pytest

from render_tools import reflections as RF
from render_tools import render as R
from tests.data.render.data import WET_SIZE, wet_scene

W, H = WET_SIZE


def _pixels(geo, lt, t_obj, window, pts):
    """Image pixels (N, 2) (row, column) that road points ``pts`` (P, 3) m land in at the box's time samples."""
    hit = np.zeros((H, W), bool)
    for t in np.linspace(*window, R.BBOX_TIME_SAMPLES):
        uv, z = R.cam_mod.project(pts + geo.object_velocity(lt) * (t - t_obj), geo.pose_cv(t), geo.K)
        ok = (z > R.MIN_DEPTH_M) & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
        hit[np.floor(uv[ok, 1]).astype(int), np.floor(uv[ok, 0]).astype(int)] = True
    return np.argwhere(hit)


def _cell_samples(cells, n: int = 12):
    """``n`` x ``n`` points (M n^2, 3) m on each rectangular cell, its sides included."""
    s = np.linspace(0.0, 1.0, n)
    a, b = (g.ravel() for g in np.meshgrid(s, s, indexing="ij"))
    x = cells[:, 0, 0, None] + (cells[:, 1, 0] - cells[:, 0, 0])[:, None] * a
    y = cells[:, 0, 1, None] + (cells[:, 2, 1] - cells[:, 0, 1])[:, None] * b
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)


def _streak_samples(sc, lt, geo, t_obj, step_m: float = 0.1):
    """Road points (P, 3) m on a ``step_m`` lattice meeting the reflection criterion of
    :mod:`render_tools.reflections` (half vector tilted by at most GLOSS_TAN_FACTOR * alpha from the normal)
    for any corner of the lamp's face (as the module tests them), written out from its definition."""
    L = R.ms.light_points(sc, lt, t_obj)
    C = geo.ego.position(t_obj)
    x, y = np.meshgrid(np.arange(C[0] + 0.5, L[:, 0].max(), step_m), np.arange(-3.0, L[:, 1].max() + 3.0, step_m),
                       indexing="ij")
    P = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    wo = (C - P) / np.linalg.norm(C - P, axis=1, keepdims=True)
    keep = np.zeros(len(P), bool)
    for l in L:
        wi = (l - P) / np.linalg.norm(l - P, axis=1, keepdims=True)
        h = wi + wo
        keep |= np.hypot(h[:, 0], h[:, 1]) <= RF.GLOSS_TAN_FACTOR * geo.wet["alpha"] * h[:, 2]
    return P[keep]


def _inside(px, box):
    y0, x0, y1, x1 = box
    return (px[:, 0] >= y0) & (px[:, 0] < y1) & (px[:, 1] >= x0) & (px[:, 1] < x1)


@pytest.mark.parametrize("lamp_m, edge", [((40.0, 0.0, 1.0), "bottom"), ((25.0, 7.0, 5.0), "side")])
def test_reflection_box_reaches_the_image_edge(lamp_m, edge):
    """The grown box holds every pixel of the reflection region, also where it crosses the image's bottom edge
    (a lamp ahead on the road: the streak runs on under the camera) or a side (a high lamp near the left edge: its
    streak widens towards the camera and leaves by the left column); the row bands hold them too; ``drop`` (scene
    version 1's rule) leaves pixels of that edge out. The bottom case's region runs on behind the camera."""
    sc = wet_scene(lamp_m, speed_mps=10.0)
    lt = sc["lights"][0]
    geo = R.SceneGeometry(sc, R.RenderOptions(width=W, height=H, frames=1))
    old = R.SceneGeometry(sc, R.RenderOptions(width=W, height=H, frames=1, reflection_edges="drop"))
    assert geo.clip_edges and not old.clip_edges
    tm = R.frame_timing(sc, geo.opts, 0)
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    cells = RF.glossy_cells(None, None, geo.wet, grid=geo._glossy_grid(lt, t_obj), whole=True)
    px = _pixels(geo, lt, t_obj, tm["window"], _cell_samples(cells))
    bb = geo.light_bbox(lt, t_obj, *tm["window"], moving=True)
    ob = old.light_bbox(lt, t_obj, *tm["window"], moving=True)
    at_edge = px[px[:, 0] == H - 1] if edge == "bottom" else px[px[:, 1] == 0]
    assert len(at_edge) and _inside(px, bb).all() and not _inside(at_edge, ob).all()
    lamp = geo.light_bbox(lt, t_obj, *tm["window"], moving=True, reflection=False)  # padded lamp face
    p = geo.opts.pad_px  # tight: no more than the padding beyond the region's pixels and the lamp's box
    lo = np.minimum(px.min(0) - p, lamp[:2])
    hi = np.maximum(px.max(0) + 1 + p, lamp[2:])
    assert bb[0] >= lo[0] and bb[1] >= lo[1] and bb[2] <= hi[0] and bb[3] <= hi[1], (bb, lo, hi)
    m = np.zeros((H, W), bool)
    for a, b, c, d in geo.reflection_tiles(lt, t_obj, *tm["window"], bb):
        m[a:c, b:d] = True
    m[lamp[0]:lamp[2], lamp[1]:lamp[3]] = True
    assert m[px[:, 0], px[:, 1]].all()
    streak = _pixels(geo, lt, t_obj, tm["window"], _streak_samples(sc, lt, geo, t_obj))
    assert len(streak) > 50 and _inside(streak, bb).all()


def test_reflection_edges_option_and_version_1():
    """``auto`` clips on scene version 2 only; a version-1 scene's box is the points' box as before; a bad value
    is refused naming the field."""
    v1 = wet_scene((40.0, 0.0, 1.0), version=1)
    lt = v1["lights"][0]
    auto = R.SceneGeometry(v1, R.RenderOptions(width=W, height=H, frames=1))
    drop = R.SceneGeometry(v1, R.RenderOptions(width=W, height=H, frames=1, reflection_edges="drop"))
    clip = R.SceneGeometry(v1, R.RenderOptions(width=W, height=H, frames=1, reflection_edges="clip"))
    assert not auto.clip_edges and clip.clip_edges
    box = [g.light_bbox(lt, 0.005, 0.0, 0.01, moving=True) for g in (auto, drop, clip)]
    assert box[0] == box[1] and box[2][2] == H > box[1][2]
    assert "reflection_edges" not in R.RenderOptions().to_dict()
    assert R.RenderOptions(reflection_edges="clip").to_dict()["reflection_edges"] == "clip"
    with pytest.raises(ValueError, match="reflection_edges"):
        R.RenderOptions(reflection_edges="edge")
