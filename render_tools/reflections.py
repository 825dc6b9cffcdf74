"""Where a lamp's reflection in a wet road lands on screen (numpy only, no Mitsuba).

A flickering light is rendered alone inside its own crop (:mod:`render_tools.render`), in time bins, so that the
dataset can apply the light's PWM to every pixel of the crop. Its reflection in a wet road (scene ``weather``
``wet`` or ``rain``: a rough dielectric water film, :mod:`render_tools.street`) is light of the same lamp, so it
flickers with it: the crop must hold it too, or the light would be lost (it is in no other image). The crop of a
flickering light in a wet scene is therefore grown by the glossy streak of its reflection: the road points ``R``
whose half vector between the directions to the lamp and to the camera is tilted from the road normal by
``tan theta_h <= GLOSS_TAN_FACTOR * alpha`` (``alpha``: the roughest GGX roughness of the road's wet materials).
A GGX distribution puts the fraction ``1 / (1 + GLOSS_TAN_FACTOR**2)`` (20 % at 2) of its microfacet normals
beyond that tilt, but the light they send to the camera is spread thinly over the rest of the road: measured
(tests/render_tools/test_reflections.py, alpha 0.06), the region holds 99.2 / 99.4 / 99.5 / 99.75 % of the
reflection at factors 1.5 / 2 / 3 / 5, with crops of 1,508 / 1,740 / 1,972 / 3,364 px at 160x90. The rest is left
out of the crop, as the diffuse light a lamp throws on its surroundings outside its crop always was
(docs/guide/rendering.md). A road without a glossy film (a diffuse asphalt: every generated dry scene) has no
reflection region; a glossy road (a ``roughplastic`` road material with an ``ior``) reflects in any weather.
Reflections of flickering lamps in other glossy surfaces (vehicle paint, glass, a mesh road) are not traced in
their crops: :func:`untraced_glossy` names those surfaces, and a render notes them once (one line per run).
"""
from __future__ import annotations

import numpy as np

__all__ = ["GLOSS_TAN_FACTOR", "GLOSSY_ALPHA", "wet_road", "untraced_glossy", "untraced_note", "glossy_grid",
           "glossy_points", "glossy_cells"]

#: Half-vector tilt bound of the reflection region, in units of the wet film's GGX roughness (module docstring:
#: 99.4 % of the reflection at 2, at half the crop of 5).
GLOSS_TAN_FACTOR = 2.0
#: GGX roughness at or below which a non-road surface counts as glossy for :func:`untraced_glossy` (a mirror-like
#: streak of a lamp shows in it; rougher coats spread a lamp's reflection over a wide lobe).
GLOSSY_ALPHA = 0.3
#: Light groups whose lights are rendered in their own crops (flickering; render_tools.render's default).
FLICKERING_GROUPS = ("otherlights", "signals")
#: Grid of road points searched for the reflection region: along x (towards the lamp) and y.
GRID = (64, 32)


def wet_road(scene: dict) -> dict | None:
    """The glossy road of a scene: ``{"alpha": roughest GGX roughness of its glossy materials, "x": (x0, x1) m, "y":
    (y0, y1) m}`` (the road surface is z = 0), or None for a scene without a road box or without a glossy film
    (``roughplastic`` with an ``ior``: a wet road, or a user's glossy road in any weather) on its road."""
    mats = scene["materials"]
    alphas, box = [], None
    for o in scene["objects"]:
        if o["kind"] != "road":
            continue
        for p in o["parts"]:
            m = mats[p["material"]]
            if m["type"] == "roughplastic" and "ior" in m:
                alphas.append(float(m["alpha"]))
            if p["shape"] == "box" and box is None:
                box = p
    if not alphas or box is None:
        return None
    (cx, cy, _), (sx, sy, _) = box["center"], box["size"]
    return {"alpha": max(alphas), "x": (cx - sx / 2, cx + sx / 2), "y": (cy - sy / 2, cy + sy / 2)}


def glossy_grid(lamp_points: np.ndarray, camera: np.ndarray, road: dict):
    """The :data:`GRID` of road points (GX, GY, 3) m searched for the reflection region and the mask (GX, GY) of
    the points in it, grown by one grid cell (:func:`glossy_points`); None when the lamps are below the road or
    nothing qualifies."""
    L = np.asarray(lamp_points, dtype=np.float64).reshape(-1, 3)
    C = np.asarray(camera, dtype=np.float64).reshape(3)
    L = L[L[:, 2] > 0.0]
    if not len(L) or C[2] <= 0.0:
        return None
    k = GLOSS_TAN_FACTOR * road["alpha"]
    x0, x1 = road["x"]
    y0, y1 = road["y"]
    far = float(L[:, 0].max())
    xa, xb = max(x0, min(C[0], L[:, 0].min()) - 1.0), min(x1, far + max(far - C[0], 1.0))
    spread = k * (float(L[:, 2].max()) + C[2]) * 2.0 + 1.0
    ya, yb = max(y0, min(C[1], L[:, 1].min()) - spread), min(y1, max(C[1], L[:, 1].max()) + spread)
    if xb <= xa or yb <= ya:
        return None
    gx, gy = np.linspace(xa, xb, GRID[0]), np.linspace(ya, yb, GRID[1])
    X, Y = np.meshgrid(gx, gy, indexing="ij")
    G = np.stack([X, Y, np.zeros_like(X)], -1)
    R = G.reshape(-1, 3)
    wo = C - R
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    keep = np.zeros(len(R), dtype=bool)
    # the half vector h = wi / |wi| + wo of every (lamp point, road point) pair, one component at a time: the same
    # arithmetic per value as on (P, N, 3) arrays (|wi|^2 summed x, y, then z, numpy's order for a length-3 axis;
    # the road points' z is +0, so wi's z is the lamp point's), without the strided length-3 reductions (half
    # the CPU; tests/render_tools/test_host_rewrites.py)
    Rx, Ry = R[:, 0], R[:, 1]
    wox, woy, woz = wo[:, 0], wo[:, 1], wo[:, 2]
    for i in range(0, len(L), 32):  # 32 lamp points at a time
        Lc = L[i:i + 32]
        dx = Lc[:, 0, None] - Rx
        dy = Lc[:, 1, None] - Ry
        dz = Lc[:, 2, None] - 0.0
        n = dx * dx
        n += dy * dy
        n += dz * dz
        np.sqrt(n, out=n)
        dx /= n
        dx += wox
        dy /= n
        dy += woy
        hz = dz / n
        hz += woz
        hz *= k
        keep |= (np.hypot(dx, dy) <= hz).any(axis=0)
    if not keep.any():
        return None
    k2 = keep.reshape(GRID)
    grown = k2.copy()  # grown by one grid cell: the streak's edge lies between a kept point and the next one
    grown[1:] |= k2[:-1]
    grown[:-1] |= k2[1:]
    grown[:, 1:] |= grown[:, :-1].copy()
    grown[:, :-1] |= grown[:, 1:].copy()
    return G, grown


def glossy_points(lamp_points: np.ndarray, camera: np.ndarray, road: dict, grid=False) -> np.ndarray:
    """Road points (M, 3) m (z = 0) whose glossy reflection of any of ``lamp_points`` (P, 3) m is seen from
    ``camera`` (3,) m: the half vector's tilt ``tan theta_h <= GLOSS_TAN_FACTOR * road["alpha"]`` (:func:`wet_road`),
    on a :data:`GRID` of road points, grown by one grid cell (so the points' screen box holds the streak; a
    caller keeps the points that project into the image: the streak runs under the camera, where its projection
    would span the whole width; where the region leaves the image, the cells of :func:`glossy_cells` clipped to
    it carry the box to the image's edge, :meth:`render_tools.render.SceneGeometry.light_bbox`). Empty (0, 3) when
    the lamps are below the road or nothing qualifies. ``grid``:
    :func:`glossy_grid` of the same arguments when the caller has it already (None included)."""
    g = glossy_grid(lamp_points, camera, road) if grid is False else grid
    if g is None:
        return np.zeros((0, 3))
    G, grown = g
    return G[grown]


def glossy_cells(lamp_points: np.ndarray, camera: np.ndarray, road: dict, grid=False,
                 whole: bool = False) -> np.ndarray:
    """The grid cells (M, 4, 3) m (their corners, z = 0; axis-aligned rectangles, corners in the order (x0, y0),
    (x1, y0), (x1, y1), (x0, y1)) that make up the reflection region of :func:`glossy_points`: every cell of the
    :data:`GRID` with a corner in it. Together they cover the region without gaps (the points alone are samples
    of it, up to metres apart near the camera), so the screen rows a reflection covers can be bounded cell by
    cell (:meth:`render_tools.render.SceneGeometry.reflection_tiles`). ``whole``: only the cells with all four
    corners in it (every grown point is a corner of one: each lies next to a kept point, whose eight neighbours
    are all grown), whose footprint bounds the grown box where the region leaves the image
    (:meth:`render_tools.render.SceneGeometry.light_bbox`). Empty (0, 4, 3) when there is no region. ``grid``: as
    for :func:`glossy_points`."""
    g = glossy_grid(lamp_points, camera, road) if grid is False else grid
    if g is None:
        return np.zeros((0, 4, 3))
    G, m = g
    cell = (m[:-1, :-1] & m[1:, :-1] & m[:-1, 1:] & m[1:, 1:]) if whole else \
        (m[:-1, :-1] | m[1:, :-1] | m[:-1, 1:] | m[1:, 1:])
    i, j = np.nonzero(cell)
    return np.stack([G[i, j], G[i + 1, j], G[i + 1, j + 1], G[i, j + 1]], axis=1)


def untraced_glossy(scene: dict) -> list[str]:
    """Kinds of the objects (sorted) with a glossy surface (``roughplastic`` or ``roughconductor`` of GGX alpha <=
    :data:`GLOSSY_ALPHA`, or a road part that is not the road box :func:`wet_road` traces, e.g. a mesh road) in
    which the reflections of flickering lamps are not traced; empty when the scene has no light of a flickering
    group."""
    if not any(lt.get("group") in FLICKERING_GROUPS for lt in scene.get("lights", [])):
        return []
    mats = scene.get("materials", {})
    kinds = set()
    for o in scene.get("objects", []):
        for p in o.get("parts", []):
            m = mats.get(p.get("material"), {})
            glossy = m.get("type") in ("roughplastic", "roughconductor") and float(m.get("alpha", 1.0)) <= GLOSSY_ALPHA
            if o["kind"] == "road":
                glossy = glossy and p.get("shape") != "box"
            if glossy:
                kinds.add(o["kind"])
    return sorted(kinds)


def untraced_note(scene: dict) -> list[str]:
    """The render note (a list of 0 or 1 line) when :func:`untraced_glossy` finds glossy surfaces: one text for
    every such scene, so a run of many scenes prints it once (with their count); the kinds are the scene's own
    (:func:`untraced_glossy`)."""
    if not untraced_glossy(scene):
        return []
    from lfmbench.resources import docs_url  # noqa: PLC0415

    return [f"reflections of flickering lamps in glossy surfaces other than a road box (vehicle paint, glass, poles: "
            f"GGX alpha <= {GLOSSY_ALPHA}) are not traced: that light is left out of the lamps' crops "
            f"({docs_url('guide/rendering.md')}, 'Wet roads and reflections')"]
