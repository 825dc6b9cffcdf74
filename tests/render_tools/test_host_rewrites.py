"""Host-side rewrites of the renderer's planning arithmetic (issue 40: v2 render cost) give what the plain forms
they replaced give: the polygon clip's kept points gathered without a sort (the same points, a gather has no
rounding), the glossy reflection test per component (the same products and sums per value, so the same mask), a
wet lamp's reflection bands from all time samples at once (minima and maxima, so the same crops)."""
from __future__ import annotations

import numpy as np
import pytest

from render_tools import dot_coverage, reflections


def _clip_plain(poly, axis, bound, keep_below):
    """The polygon clip as it was: the kept points ordered by a stable argsort of ``~ok``, then two gathers."""
    N, V, _ = poly.shape
    p, q = poly, np.roll(poly, -1, axis=1)
    s = 1.0 if keep_below else -1.0
    dp = s * (p[..., axis] - bound[:, None])
    dq = s * (q[..., axis] - bound[:, None])
    inside_p, inside_q = dp <= 0, dq <= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(dp != dq, dp / (dp - dq), 0.0)
    cross = p + f[..., None] * (q - p)
    pts = np.stack([p, cross], axis=2).reshape(N, 2 * V, 2)
    ok = np.stack([inside_p, inside_p != inside_q], axis=2).reshape(N, 2 * V)
    order = np.argsort(~ok, axis=1, kind="stable")
    cnt = ok.sum(1)
    idx = np.minimum(np.arange(V + 1)[None, :], np.maximum(cnt - 1, 0)[:, None])
    out = np.take_along_axis(pts, np.take_along_axis(order, idx, axis=1)[..., None], axis=1)
    out[cnt == 0] = 0.0
    return out


@pytest.mark.parametrize("n,v", [(0, 4), (1, 4), (300, 4), (300, 7)])
def test_clip_gathers_the_points_the_sorted_form_kept(n, v):
    rng = np.random.default_rng(n + v)
    poly = rng.uniform(0.0, 4.0, (n, v, 2))
    poly[: n // 5] += 10.0  # wholly outside every bound below: rows with nothing kept
    bound = rng.uniform(0.0, 4.0, n)
    for axis in (0, 1):
        for below in (False, True):
            got = dot_coverage._clip(poly, axis, bound, below)
            want = _clip_plain(poly, axis, bound, below)
            assert got.shape == want.shape == (n, v + 1, 2)
            assert np.array_equal(got, want)  # a gather of the same points: no rounding involved
    # and the area through the whole clip against an analytic case: a unit square shifted by 0.25 px in x and y
    sq = np.array([[[0.25, 0.25], [1.25, 0.25], [1.25, 1.25], [0.25, 1.25]]])
    assert dot_coverage.clip_area(sq, np.array([[0.0, 0.0, 1.0, 1.0]]))[0] == pytest.approx(0.5625, abs=1e-12)


def _glossy_keep_plain(L, R, wo, k):
    """The reflection test as it was, on (P, N, 3) arrays."""
    wi = L[:, None, :] - R[None]
    wi /= np.sqrt(np.add.reduce(wi * wi, axis=-1))[..., None]
    h = wi + wo
    return (np.hypot(h[..., 0], h[..., 1]) <= k * h[..., 2]).any(axis=0)


def test_glossy_grid_marks_the_points_of_the_plain_half_vector_test():
    rng = np.random.default_rng(7)
    road = {"alpha": 0.08, "x": (-50.0, 200.0), "y": (-10.0, 10.0)}
    seen = 0
    for _ in range(6):
        L = rng.uniform([5.0, -6.0, 0.3], [120.0, 6.0, 6.0], (int(rng.integers(1, 80)), 3))
        C = np.array([0.0, rng.uniform(-2.0, 2.0), 1.5])
        g = reflections.glossy_grid(L, C, road)
        assert g is not None
        G, grown = g
        R = G.reshape(-1, 3)
        wo = C - R
        wo /= np.linalg.norm(wo, axis=1, keepdims=True)
        k2 = _glossy_keep_plain(L, R, wo, reflections.GLOSS_TAN_FACTOR * road["alpha"]).reshape(reflections.GRID)
        want = k2.copy()
        want[1:] |= k2[:-1]
        want[:-1] |= k2[1:]
        want[:, 1:] |= want[:, :-1].copy()
        want[:, :-1] |= want[:, 1:].copy()
        assert np.array_equal(grown, want)
        seen += int(k2.sum())
    assert seen > 0  # the test saw kept points, not only empty masks



def _reflection_tiles_plain(geo, light, t_obj, t_a, t_b, bbox):
    """:meth:`SceneGeometry.reflection_tiles` as it was: the bands' extents updated once per time sample."""
    import math  # noqa: PLC0415

    from render_tools import camera as cam_mod  # noqa: PLC0415
    from render_tools import render as R  # noqa: PLC0415

    if not geo.reflected(light, t_obj):
        return []
    cells = reflections.glossy_cells(None, None, geo.wet, grid=geo._glossy_grid(light, t_obj))
    if not len(cells):
        return []
    y0, x0, y1, x1 = bbox
    B, p = R.REFLECTION_BAND_PX, geo.opts.pad_px
    nb = -(-(y1 - y0) // B)
    lo, hi = np.full(nb, np.inf), np.full(nb, -np.inf)
    v = geo.object_velocity(light)
    flat = cells.reshape(-1, 3)
    band = np.arange(nb)
    for t in np.linspace(t_a, t_b, R.BBOX_TIME_SAMPLES):
        uv, z = cam_mod.project(flat + v * (t - t_obj), geo.pose_cv(t), geo.K)
        uv, z = uv.reshape(-1, 4, 2), z.reshape(-1, 4)
        front = z > R.MIN_DEPTH_M
        some, every = front.any(1), front.all(1)
        u, w = np.where(front, uv[..., 0], np.nan), np.where(front, uv[..., 1], np.nan)
        with np.errstate(invalid="ignore"):
            ya, yb = np.nanmin(w[some], 1), np.nanmax(w[some], 1)
            xa, xb = np.nanmin(u[some], 1), np.nanmax(u[some], 1)
        part = ~every[some]
        yb[part], xa[part], xb[part] = math.inf, -math.inf, math.inf
        ba = np.maximum(np.floor((ya - y0) / B) - 1, 0)
        bz = np.where(np.isfinite(yb), np.floor((yb - y0) / B) + 1, nb - 1)
        hit = (ba[None, :] <= band[:, None]) & (band[:, None] <= bz[None, :])
        lo = np.minimum(lo, np.where(hit, xa[None, :], np.inf).min(1, initial=np.inf))
        hi = np.maximum(hi, np.where(hit, xb[None, :], -np.inf).max(1, initial=-np.inf))
    out = []
    for i in range(nb):
        if not hi[i] >= lo[i]:
            continue
        a = max(x0, int(math.floor(lo[i])) - p) if math.isfinite(lo[i]) else x0
        b = min(x1, int(math.ceil(hi[i])) + p) if math.isfinite(hi[i]) else x1
        if b > a:
            out.append((y0 + i * B, a, min(y1, y0 + (i + 1) * B), b))
    return out


@pytest.mark.parametrize("lamp_m,speed", [((30.0, 0.0, 1.0), 10.0), ((12.0, 5.0, 4.0), 0.0), ((8.0, -1.0, 0.8), 15.0)])
def test_reflection_tiles_equal_the_per_time_sample_form(lamp_m, speed):
    from render_tools import render as R  # noqa: PLC0415
    from tests.data.render.data import WET_SIZE, wet_scene  # noqa: PLC0415

    W, H = WET_SIZE

    sc = wet_scene(lamp_m, speed_mps=speed)
    lt = sc["lights"][0]
    geo = R.SceneGeometry(sc, R.RenderOptions(width=W, height=H, frames=1))
    tm = R.frame_timing(sc, geo.opts, 0)
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    bb = geo.light_bbox(lt, t_obj, *tm["window"], moving=True)
    got = geo.reflection_tiles(lt, t_obj, *tm["window"], bb)
    assert got and got == _reflection_tiles_plain(geo, lt, t_obj, *tm["window"], bb)
    whole = (0, 0, H, W)  # a box the region does not fill: bands it misses are left out by both
    assert geo.reflection_tiles(lt, t_obj, *tm["window"], whole) == _reflection_tiles_plain(geo, lt, t_obj,
                                                                                            *tm["window"], whole)
