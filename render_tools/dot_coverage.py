"""Exact pixel coverage of an LED dot face: each lit dot of a ``dots`` face (:mod:`render_tools.led_matrix`) is a
rectangle on a plane, whose pinhole image is a convex quad (the projection of its four corners); the share of a
pixel square [j, j + 1) x [i, i + 1) it covers is the area of the quad clipped to the square (Sutherland-Hodgman
clipping, I. E. Sutherland and G. W. Hodgman, "Reentrant polygon clipping", Communications of the ACM 17(1),
1974; the area by the shoelace formula). Summed over the dots, that is the exact box-filtered image of the face's
emission, which the tracer's camera samples (uniform over the pixel square, :mod:`render_tools.tracer`) estimate.

Over a time bin the face and the camera move: the coverage is averaged over :data:`TIME_SAMPLES` midpoints of
equal parts of the bin (the midpoint rule, exact for a still face). What it leaves out: anything in front of the
face (an occluder is not seen), and light the face throws on what is next to it (none inside its own box: the
dots lie on the face's plane and emit to its front). A study of the error of drawing sub-pixel dot faces this
way instead of by Monte Carlo samples (docs/benchmarks/render.md, "LED dot faces against the real dots").
"""
from __future__ import annotations

import numpy as np

from . import camera as cam_mod
from . import led_matrix
from . import mitsuba_scene as ms
from .kernel_rules import kernel_input

__all__ = ["clip_area", "quad_coverage", "dots_coverage", "TIME_SAMPLES"]

#: Time samples (midpoints of equal parts) per bin of :func:`dots_coverage`.
TIME_SAMPLES = 8
#: Visibility rays per dot and time sample (n x n, :func:`ray_visibility`): a coarse test of every dot, then the
#: dots it finds partly hidden again at the fine count, their parts clipped one by one (message signs behind a
#: signal head at dusk: LED-bin error 3.3 % with 4 x 4 alone, 1.1 % with 8 x 8, under the references' noise with
#: 16 x 16; docs/benchmarks/render.md, "LED dot faces against the real dots").
VIS_POINTS = (8, 16)


def _clip(poly: np.ndarray, axis: int, bound: np.ndarray, keep_below: bool) -> np.ndarray:
    """Clip polygons (N, V, 2) (vertices in order; repeated vertices allowed) by the half-plane
    ``p[axis] <= bound`` (``keep_below``) or ``>= bound`` (N,). Returns (N, V + 1, 2), the polygon's vertices
    first, the rest filled with its last vertex (a degenerate edge of zero area)."""
    N, V, _ = poly.shape
    p, q = poly, np.roll(poly, -1, axis=1)
    s = 1.0 if keep_below else -1.0
    dp = s * (p[..., axis] - bound[:, None])  # <= 0 inside
    dq = s * (q[..., axis] - bound[:, None])
    inside_p, inside_q = dp <= 0, dq <= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(dp != dq, dp / (dp - dq), 0.0)
    cross = p + f[..., None] * (q - p)
    # per edge: p (if inside), then the crossing (if the edge crosses the line)
    pts = np.stack([p, cross], axis=2).reshape(N, 2 * V, 2)
    ok = np.stack([inside_p, inside_p != inside_q], axis=2).reshape(N, 2 * V)
    # the first V + 1 kept points in order, the last repeated: the kept points' flat indices (row by row, in
    # order), each row's m-th one read at its row's start + min(m, cnt - 1); one gather of the points (the same
    # values as a stable argsort of ~ok and two gathers, tests/render_tools/test_host_rewrites.py, without the sort)
    cnt = ok.sum(1)
    flat = np.flatnonzero(ok)  # (sum cnt,) indices into the (N * 2V) points
    start = np.cumsum(cnt) - cnt
    idx = np.minimum(np.arange(V + 1)[None, :], np.maximum(cnt - 1, 0)[:, None]) + start[:, None]
    out = pts.reshape(N * 2 * V, 2)[flat[np.minimum(idx, max(len(flat) - 1, 0))]] if len(flat) else \
        np.zeros((N, V + 1, 2))
    out[cnt == 0] = 0.0  # nothing left: a point (zero area)
    return out


def clip_area(quads: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Area of each convex polygon ``quads`` (N, V, 2) (vertices in order, either winding; px) inside the
    axis-aligned box ``boxes`` (N, 4) = (x0, y0, x1, y1) px. Returns (N,) px^2 (exact up to rounding)."""
    poly = np.asarray(quads, dtype=np.float64)
    b = np.asarray(boxes, dtype=np.float64)
    for axis, col, below in ((0, 0, False), (0, 2, True), (1, 1, False), (1, 3, True)):
        poly = _clip(poly, axis, b[:, col], below)
    x, y = poly[..., 0], poly[..., 1]
    return 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1))


def quad_coverage(quads: np.ndarray, crop: tuple, layer: np.ndarray | None = None, layers: int = 1) -> np.ndarray:
    """Covered share (layers, h, w) of each pixel of ``crop`` (y0, x0, y1, x1) px by the disjoint convex quads
    ``quads`` (N, 4, 2) px, quad i adding to layer ``layer[i]`` (None: all to layer 0): every pixel a quad's
    bounding box touches gets the area of the quad clipped to it (:func:`clip_area`)."""
    y0, x0, y1, x1 = crop
    out = np.zeros((layers, y1 - y0, x1 - x0))
    q = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2)
    lay = np.zeros(len(q), np.int64) if layer is None else np.asarray(layer, np.int64)
    lo, hi = np.floor(q.min(1)).astype(np.int64), np.floor(q.max(1)).astype(np.int64)
    lo = np.maximum(lo, [x0, y0])
    hi = np.minimum(hi, [x1 - 1, y1 - 1])
    n = np.maximum(hi - lo + 1, 0)  # (N, 2) pixels of each bounding box, x and y
    cnt = n[:, 0] * n[:, 1]
    if not cnt.sum():
        return out
    qi = np.repeat(np.arange(len(q)), cnt)  # quad of each (quad, pixel) pair
    j = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)  # pixel's index inside its quad's box
    px, py = lo[qi, 0] + j % n[qi, 0], lo[qi, 1] + j // n[qi, 0]
    box = np.stack([px, py, px + 1, py + 1], axis=1).astype(np.float64)
    np.add.at(out, (lay[qi], py - y0, px - x0), clip_area(q[qi], box))
    return out


def dots_coverage(scene: dict, light: dict, K: np.ndarray, pose_at, crop: tuple, edges, visible=None) -> np.ndarray:
    """Time-averaged covered share (B, h, w) of the pixels of ``crop`` (y0, x0, y1, x1) px by the lit dots of the
    ``dots`` light ``light`` in each of the B bins between ``edges`` (B + 1,) s, the light moving with its object
    (:func:`render_tools.mitsuba_scene.object_offset`), at :data:`TIME_SAMPLES` midpoint times per bin.
    ``K``: intrinsics (3, 3); ``pose_at``: t (s) -> camera-to-world pose (4, 4)
    (:meth:`render_tools.render.SceneGeometry.pose_cv`). ``visible``: None (nothing in front of the face), or
    (times (T,) s, dot corners (T, P, 4, 3) m, camera centres (T, 3) m, n) -> (T, P, n * n) bool, whether each
    of the n x n parts of each dot (:func:`_sub_quads`) is seen (:func:`ray_visibility`): a dot seen whole at the
    coarse count (:data:`VIS_POINTS`) counts whole, one seen in part counts by its parts seen at the fine count. Dots at or behind the camera plane, and a
    face whose back is to the camera, add nothing (the emitter is one-sided)."""
    u, v, normal = ms._frame(light["normal"])
    V, _F = led_matrix.dots_mesh(light, u, v, np.zeros(3))
    V = V.reshape(-1, 4, 3)  # (P, 4, 3) m: each dot's corners, in order
    centre = np.asarray(light["center"], dtype=np.float64)
    edges = np.asarray(edges, dtype=np.float64)
    B, M = len(edges) - 1, TIME_SAMPLES
    times = (edges[:-1, None] + (np.arange(M) + 0.5)[None, :] / M * np.diff(edges)[:, None]).reshape(-1)
    poses = np.stack([pose_at(t) for t in times])  # (T, 4, 4)
    offs = np.stack([ms.object_offset(scene, light["instance"], t) for t in times])  # (T, 3)
    W = V[None] + offs[:, None, None, :]  # (T, P, 4, 3)
    facing = np.einsum("tj,j->t", poses[:, :3, 3] - centre - offs, normal) > 0
    uv = np.zeros(W.shape[:3] + (2,))
    front = np.zeros(W.shape[:2], bool)
    for i in range(len(times)):
        uvi, z = cam_mod.project(W[i].reshape(-1, 3), poses[i], K)
        uv[i] = uvi.reshape(-1, 4, 2)
        front[i] = (z > 0).reshape(-1, 4).all(1) & facing[i]
    tb = np.repeat(np.arange(B), M)[:, None] * np.ones(front.shape, np.int64)  # bin of each (time, dot)
    if visible is None:
        out = quad_coverage(uv[front], crop, tb[front], B)
        return out / M
    cams = poses[:, :3, 3]
    vis = visible(times, W, cams, VIS_POINTS[0])  # (T, P, n * n): the coarse test
    full = front & vis.all(2)
    part = front & vis.any(2) & ~vis.all(2)
    out = quad_coverage(uv[full], crop, tb[full], B)
    if part.any():  # dots an occluder's edge crosses: their n x n parts (the fine count), each seen or not
        n = VIS_POINTS[1]
        ti, di = np.nonzero(part)
        # every (time, dot) pair as its own time of one visibility call: one ray test for all of them instead of
        # one per time (the same rays; 500 ray-test launches per wet generator-2 night at 640x360 before)
        keep = visible(times[ti], W[ti, di][:, None], cams[ti], n)[:, 0]  # (Q, n * n)
        suv = np.zeros((len(ti), n * n, 4, 2))
        for i in np.unique(ti):
            sel = ti == i
            sub = _sub_quads(W[i][di[sel]], n)  # (Q, n * n, 4, 3)
            suv[sel] = cam_mod.project(sub.reshape(-1, 3), poses[i], K)[0].reshape(-1, n * n, 4, 2)
        out += quad_coverage(suv[keep], crop, np.repeat(tb[ti, di], n * n).reshape(-1, n * n)[keep], B)
    return out / M


def _sub_quads(corners: np.ndarray, n: int) -> np.ndarray:
    """The n x n parts (P, n * n, 4, 3) of planar quads ``corners`` (P, 4, 3) (in order: (0, 0), (1, 0), (1, 1),
    (0, 1) in the quad's own coordinates), row-major over (b, a)."""
    g = np.arange(n + 1) / n
    A, Bg = np.meshgrid(g, g)  # (n + 1, n + 1): [b, a]
    w = np.stack([(1 - A) * (1 - Bg), A * (1 - Bg), A * Bg, (1 - A) * Bg], axis=-1)  # bilinear weights
    P = np.einsum("bac,pcj->pbaj", w, corners)  # (P, n + 1, n + 1, 3) grid points
    q = np.stack([P[:, :-1, :-1], P[:, :-1, 1:], P[:, 1:, 1:], P[:, 1:, :-1]], axis=3)  # (P, n, n, 4, 3)
    return q.reshape(len(corners), n * n, 4, 3)


def _sub_centres(corners: np.ndarray, n: int) -> np.ndarray:
    """The centres (P, n * n, 3) of the n x n parts of planar quads ``corners`` (P, 4, 3): the same numbers as
    ``_sub_quads(corners, n).mean(2)`` (the four corners added in order, then divided by 4: numpy's mean over an
    axis of 4, tested bit for bit), without the (P, n * n, 4, 3) corner array (half the CPU time of a
    visibility test of a wet generator-2 night's dot faces went to it)."""
    g = np.arange(n + 1) / n
    A, Bg = np.meshgrid(g, g)  # (n + 1, n + 1): [b, a]
    w = np.stack([(1 - A) * (1 - Bg), A * (1 - Bg), A * Bg, (1 - A) * Bg], axis=-1)  # bilinear weights
    P = np.einsum("bac,pcj->pbaj", w, corners)  # (P, n + 1, n + 1, 3) grid points, as _sub_quads
    c = P[:, :-1, :-1] + P[:, :-1, 1:]
    c += P[:, 1:, 1:]
    c += P[:, 1:, :-1]
    c /= 4.0
    return c.reshape(len(corners), n * n, 3)


def ray_visibility(mi, loaded, shift=None, eps_m: float = 1e-3):
    """A ``visible`` function for :func:`dots_coverage`: for each time, dot (corners (T, P, 4, 3) m) and each of
    its n x n parts (:func:`_sub_quads`), whether the segment from the camera centre (T, 3) m to the part's centre,
    shortened by ``eps_m`` m at the dot, meets nothing in the Mitsuba scene ``loaded`` (``Scene.ray_test``, one
    call for all): (T, P, n * n) bool, ``n`` the last argument. ``shift``: times (T,) s -> (T, 3) m subtracted from both ends (a light's
    object velocity x (t - t_obj): the scene loaded with the objects at ``t_obj`` and the camera moving relative
    to the light's object, as the tracer's tiles draw a moving light)."""
    def visible(times, corners, cams, n):
        T, P = corners.shape[:2]
        if not T * P:
            return np.zeros((T, P, n * n), bool)
        pts = _sub_centres(corners.reshape(-1, 4, 3), n).reshape(T, P * n * n, 3)
        cams = np.asarray(cams, dtype=np.float64)
        if shift is not None:
            s = np.asarray(shift(np.asarray(times)), dtype=np.float64).reshape(T, 3)
            pts, cams = pts - s[:, None, :], cams - s
        o = np.broadcast_to(cams[:, None, :], pts.shape).reshape(-1, 3)
        d = pts.reshape(-1, 3) - o
        dist = np.linalg.norm(d, axis=1)
        d = d / dist[:, None]
        m = len(dist)
        ray = mi.Ray3f(mi.Point3f(*[kernel_input(o[:, j]) for j in range(3)]),
                       mi.Vector3f(*[kernel_input(d[:, j]) for j in range(3)]))
        ray.maxt = mi.Float(kernel_input(dist - eps_m))
        return ~np.asarray(loaded.ray_test(ray), dtype=bool)[:m].reshape(T, P, n * n)
    return visible
