"""Triangle meshes of scene generator 2 (protocol lfmbench-v2): parametric vehicle bodies, a person's torso, tree
crowns and bicycle wheels, as scene ``meshes`` entries (``{"vertices": [[x, y, z], ...] m, "faces": [[i, j, k],
...]}``, counter-clockwise seen from outside) that ``mesh`` parts place, turn and scale
(:func:`render_tools.mitsuba_scene.part_mesh`).

Plain numpy, no random draws of their own (a crown takes the scene's generator): the same arguments give the
same mesh on every machine. Coordinates are rounded to 0.1 mm (:data:`ROUND_DIGITS`) to keep scene files small.

- :func:`body_meshes` -> a vehicle body lofted through cross-sections along its length, split into paint and
  glass (windscreen, side and rear windows).
- :func:`torso_mesh`, :func:`crown_mesh`, :func:`ring_mesh` -> a person's tapered torso, a lumpy tree crown, a
  wheel rim (torus).
"""
from __future__ import annotations

import functools
import math

import numpy as np

__all__ = ["ROUND_DIGITS", "body_meshes", "torso_mesh", "crown_mesh", "ring_mesh", "icosphere", "signed_volume"]

#: Decimal digits of mesh coordinates in a scene file (m): 0.1 mm.
ROUND_DIGITS = 4


def _entry(V: np.ndarray, F: np.ndarray) -> dict:
    """A scene ``meshes`` entry with only the vertices ``F`` uses (renumbered), coordinates rounded."""
    used, inv = np.unique(F.ravel(), return_inverse=True)
    return {"vertices": np.round(V[used], ROUND_DIGITS).tolist(), "faces": inv.reshape(-1, 3).astype(int).tolist()}


def signed_volume(V, F) -> float:
    """Signed volume (m^3) enclosed by a closed mesh: > 0 when its faces wind counter-clockwise seen from outside."""
    V, F = np.asarray(V, dtype=float), np.asarray(F)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _orient(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``F`` wound outward (the loft's winding depends on the ring order)."""
    return F if signed_volume(V, F) >= 0 else F[:, ::-1].copy()


def body_meshes(stations, width_m: float, roof_inset_m: float, chamfer_m: float = 0.08) -> dict:
    """A vehicle body lofted through cross-sections, in the vehicle frame (x forward, y left, z up; m).

    Args:
        stations: rows ``(x, z_bottom, z_belt, z_top, width_scale, side_glass, top_glass)`` from the rear to the
            front: at ``x`` the section spans ``z_bottom``..``z_top``; below the belt line ``z_belt`` it is
            ``width_m * width_scale`` wide, above it narrows by ``roof_inset_m`` per side towards the roof.
            ``side_glass`` / ``top_glass``: the upper sides / the top between this station and the next are glass
            (side windows; windscreen, rear window).
        width_m: body width below the belt, m. roof_inset_m: inset of the roof edge per side, m.
        chamfer_m: bevel of the lower edges, m.
    Returns:
        ``{"paint": entry, "glass": entry}`` (scene ``meshes`` entries; ``glass`` absent when no interval has glass).
        The two together form one closed surface (ends capped).
    """
    st = np.asarray(stations, dtype=float)
    rings = []
    for x, zb, zbelt, ztop, ws, _, _ in st:
        w = 0.5 * width_m * ws
        wr = max(w - roof_inset_m, 0.05)
        ztop = max(ztop, zbelt + 0.01)
        c = min(chamfer_m, 0.4 * (zbelt - zb))
        # section corners, counter-clockwise seen from the front (+x): left (+y) side down, bottom, right side up
        yz = [(w, zbelt), (w, zb + c), (w - c, zb), (-(w - c), zb), (-w, zb + c), (-w, zbelt), (-wr, ztop),
              (wr, ztop)]
        rings.append([(x, y, z) for y, z in yz])
    V = np.array(rings, dtype=float).reshape(-1, 3)
    n = 8  # points per ring; segments k = (k, k+1): 5 = right upper side, 6 = roof, 7 = left upper side
    glass_seg = {5: 5, 6: 6, 7: 5}  # segment -> column of the station row that makes it glass
    paint, glass = [], []
    for i in range(len(st) - 1):
        for k in range(n):
            a, b = i * n + k, i * n + (k + 1) % n
            c2, d = a + n, b + n
            quad = [[a, b, d], [a, d, c2]]
            col = glass_seg.get(k)
            (glass if col is not None and st[i, col] > 0.5 else paint).extend(quad)
    # end caps: fans around each end ring's centre
    for i, sgn in ((0, -1), (len(st) - 1, 1)):
        ctr = len(V)
        V = np.vstack([V, V[i * n:(i + 1) * n].mean(0)])
        for k in range(n):
            paint.append([ctr, i * n + k, i * n + (k + 1) % n])
    Fp, Fg = np.array(paint), np.array(glass, dtype=int).reshape(-1, 3)
    Fall = np.vstack([Fp, Fg]) if len(Fg) else Fp
    if signed_volume(V, Fall) < 0:
        Fp, Fg = Fp[:, ::-1], Fg[:, ::-1]
    # the caps were wound by ring order only: fix each cap to face outward (-x at the rear, +x at the front)
    out = {"paint": _entry(V, _fix_caps(V, Fp))}
    if len(Fg):
        out["glass"] = _entry(V, Fg)
    return out


def _fix_caps(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Flip any face whose normal points into the body along x at the two ends (the caps)."""
    x0, x1 = V[:, 0].min(), V[:, 0].max()
    F = F.copy()
    xs = V[F, 0]  # (faces, 3): np.allclose per face, all faces at once (the same comparisons)
    at0 = np.isclose(xs, x0).all(axis=1)
    cap = at0 | np.isclose(xs, x1).all(axis=1)
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    nx = np.cross(V[b] - V[a], V[c] - V[a])[:, 0]
    flip = cap & (nx * np.where(at0, -1.0, 1.0) < 0)
    F[flip] = F[flip][:, [0, 2, 1]]
    return F


def _loft_closed(rings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed mesh through rings (R, P, 3) with the two ends capped by fans; outward winding."""
    R, P = rings.shape[:2]
    V = rings.reshape(-1, 3)
    F = []
    for i in range(R - 1):
        for k in range(P):
            a, b = i * P + k, i * P + (k + 1) % P
            F += [[a, b, b + P], [a, b + P, a + P]]
    for i in (0, R - 1):
        ctr = len(V)
        V = np.vstack([V, rings[i].mean(0)])
        for k in range(P):
            F.append([ctr, i * P + (k + 1) % P, i * P + k] if i == 0 else [ctr, i * P + k, i * P + (k + 1) % P])
    F = np.array(F)
    return V, _orient(V, F)


def torso_mesh(segments: int = 12) -> dict:
    """A person's torso for a 1 m tall person (scale it by the height): an elliptical tube from the hip (z = 0.50)
    to the shoulders (z = 0.82), 0.17 m wide at the waist, 0.22 m at the chest, 0.12 m deep; x forward."""
    ang = 2 * math.pi * np.arange(segments) / segments
    levels = [(0.50, 0.095, 0.060), (0.58, 0.085, 0.055), (0.70, 0.110, 0.065), (0.80, 0.115, 0.060),
              (0.82, 0.080, 0.045)]
    rings = np.array([[(d * math.cos(a), w * math.sin(a), z) for a in ang] for z, w, d in levels])
    V, F = _loft_closed(rings)
    return _entry(V, F)


def icosphere(subdivisions: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere: vertices (n, 3) on the unit sphere, faces (m, 3) outward (new arrays each call, built once
    per process: each generator-2 scene's three tree crowns ask for it)."""
    V, F = _icosphere(int(subdivisions))
    return V.copy(), F.copy()


@functools.lru_cache(maxsize=4)
def _icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    t = (1 + 5 ** 0.5) / 2
    V = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
         (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    V = [np.array(v, dtype=float) / np.linalg.norm(v) for v in V]
    for _ in range(subdivisions):
        mid: dict = {}
        F2 = []

        def m(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = V[a] + V[b]
                V.append(p / np.linalg.norm(p))
                mid[key] = len(V) - 1
            return mid[key]

        for a, b, c in F:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            F2 += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        F = F2
    V, F = np.array(V), np.array(F)
    return V, _orient(V, F)


def crown_mesh(rng: np.random.Generator, lumps: int = 4) -> dict:
    """A tree crown of unit radius around the origin: a subdivided icosphere pushed in and out by ``lumps``
    random bumps (radius 0.75-1.1) and flattened below (z >= -0.6). Draws from ``rng``."""
    V, F = icosphere(2)
    centres = rng.normal(size=(lumps, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    amp = rng.uniform(0.08, 0.2, lumps)
    r = 0.85 + (amp[None, :] * np.exp(-4.0 * (1 - V @ centres.T))).sum(1) - 0.05 * np.abs(V[:, 2])
    W = V * r[:, None]
    W[:, 2] = np.maximum(W[:, 2], -0.6)
    return _entry(W, F)


def ring_mesh(radius_m: float, tube_m: float, segments: int = 20, sides: int = 6) -> dict:
    """A torus (a wheel rim and tyre) of ``radius_m`` around the y axis with tube radius ``tube_m`` (m)."""
    u = 2 * math.pi * np.arange(segments) / segments
    v = 2 * math.pi * np.arange(sides) / sides
    V = np.array([((radius_m + tube_m * math.cos(b)) * math.cos(a), tube_m * math.sin(b),
                   (radius_m + tube_m * math.cos(b)) * math.sin(a)) for a in u for b in v])
    F = []
    for i in range(segments):
        for j in range(sides):
            a = i * sides + j
            b = ((i + 1) % segments) * sides + j
            c = ((i + 1) % segments) * sides + (j + 1) % sides
            d = i * sides + (j + 1) % sides
            F += [[a, b, c], [a, c, d]]
    F = np.array(F)
    return _entry(V, _orient(V, F))
