"""Scene dict (:mod:`render_tools.scene`) -> Mitsuba 3 scene dicts, one per light group.

Every group is rendered with the *whole* geometry but only its own emitters, so group images add up to the
full scene (light transport is linear in the emission). Lights of other groups keep their lamp geometry with
a non-emissive lens material, so they still occlude and reflect as in the full scene.

Emitters
- Lamp faces are ``area`` emitters on ``rectangle`` / ``disk`` / ``dots`` (an LED matrix's lit dots,
  :mod:`render_tools.led_matrix`) shapes with an absolute spectral radiance
  (W sr^-1 m^-2 nm^-1) from :mod:`render_tools.spectra`; Mitsuba's ``area`` emitter is Lambertian and
  one-sided, so the camera sees the lamp's luminance from every direction in front of it.
- Beam-angle control (upstream "spread" < 90 deg, i.e. headlights 7.5-22.5 deg half-angle): the *illumination*
  a beam throws on the scene is a ``spot`` emitter 2 cm in front of the face with cutoff angle = spread,
  smooth fall-off from 0.75 * spread, and on-axis spectral intensity I = L * A (W sr^-1 nm^-1; the on-axis
  intensity of the face itself, A = face area in m^2). The face stays Lambertian for direct view (a camera
  looking into a beam from outside its cone sees the face slightly too bright; documented in
  docs/guide/rendering.md). A spread of 90 deg (tail lamps, streetlights, signals) is the face alone.
- Sky (group ``skymap``): Mitsuba's ``sunsky`` (Hosek-Wilkie sky + sun; z-up, matches the scene frame) scaled
  by ``sky.scale``, or a ``constant`` environment with an absolute spectrum (night).

Moving objects are placed at their position at the time given (object motion is not blurred inside an
exposure; the ego-motion blur is continuous, see :mod:`render_tools.camera`); :func:`place_moving` moves them in a
loaded scene to another time (static time bins).

Over 500 lines: :func:`mitsuba_dict` and :func:`place_moving` must build the same arrays from the same helpers (a
bin's images equal those of a scene loaded at its time, bit for bit), so they stay in one module.
"""
from __future__ import annotations

import functools
import json
import math

import numpy as np

from lfmbench.vocabulary import LIGHT_GROUPS

from . import led_matrix, spectra
from .scene_schema import scene_groups
from .scene_templates import posed_parts

#: Path-tracing depth: Mitsuba ``max_depth`` 5 = 4 indirect bounces (upstream renders with 4 bounces).
MAX_DEPTH = 5
#: Offset of a beam's spot emitter in front of its lamp face, m.
BEAM_OFFSET_M = 0.02
#: Fall-off start of a beam as a fraction of its cutoff (spread) angle.
BEAM_WIDTH_FRACTION = 0.75
#: Tessellation: segments of cylinders and disks, (longitude, latitude) segments of spheres.
CIRCLE_SEGMENTS = 24
SPHERE_SEGMENTS = (16, 8)
#: Lens material of a lamp that is not emitting in the current render (dark, slightly glossy).
OFF_LENS = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.03, 0.03, 0.03]}}


def shape_id(obj_id: int, k: int) -> str:
    """Mitsuba id of mesh ``k`` (one per material, sorted by name) of object ``obj_id``."""
    return f"o{obj_id}_m{k}"


def light_shape_id(light_id: int) -> str:
    """Mitsuba id of the lamp face of light ``light_id`` (its emitter's parameters live under this key)."""
    return f"light{light_id}"


def beam_id(light_id: int) -> str:
    """Mitsuba id of the spot emitter carrying light ``light_id``'s beam."""
    return f"beam{light_id}"


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two (3,) vectors: the same products and differences as ``np.cross`` (bit for bit), without
    its ~30 us of overhead per call (thousands of calls per scene)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _frame(normal, horizontal_if_up=(1.0, 0.0, 0.0)):
    """Orthonormal (u, v, n) with u x v = n; v is 'up' in the plane (world z projected), or, for horizontal
    planes, u follows world x."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    if abs(n[2]) > 0.9:
        u = np.asarray(horizontal_if_up, dtype=float)
        u = u - n * (u @ n)
        u /= np.linalg.norm(u)
        v = _cross(n, u)
    else:
        v = np.array([0.0, 0.0, 1.0]) - n * n[2]
        v /= np.linalg.norm(v)
        u = _cross(v, n)
    return u, v, n


def plane_corners(shape: dict) -> np.ndarray:
    """World corners (4, 3) m of a rect, 8 points on the rim of a disk (8, 3) m, or the corners of every lit dot
    of a ``dots`` face (4P, 3) m."""
    u, v, n = _frame(shape["normal"])
    if shape["shape"] == "dots":
        return led_matrix.dots_mesh(shape, u, v, np.zeros(3))[0]
    c = np.asarray(shape["center"], dtype=float)
    if shape["shape"] == "rect":
        a, b = shape["size"][0] / 2, shape["size"][1] / 2
        return np.array([c + su * a * u + sv * b * v for su in (-1, 1) for sv in (-1, 1)])
    r = shape["radius"]
    ang = np.linspace(0, 2 * math.pi, 8, endpoint=False)
    return np.array([c + r * (math.cos(t) * u + math.sin(t) * v) for t in ang])


def plane_area(shape: dict) -> float:
    """Area of a rect/disk/dots lamp face, m^2."""
    if shape["shape"] == "rect":
        return shape["size"][0] * shape["size"][1]
    if shape["shape"] == "dots":
        return led_matrix.dots_area(shape)
    n = CIRCLE_SEGMENTS  # area of the inscribed polygon the disk is tessellated into
    return 0.5 * n * shape["radius"] ** 2 * math.sin(2 * math.pi / n)


def _plane_mesh(shape: dict, offset) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of a rect / disk / dots face (normal side counter-clockwise, i.e. emitting towards ``normal``)."""
    u, v, n = _frame(shape["normal"])
    if shape["shape"] == "dots":
        return led_matrix.dots_mesh(shape, u, v, offset)
    c = np.asarray(shape["center"], dtype=float) + offset
    if shape["shape"] == "rect":
        a, b = shape["size"][0] / 2, shape["size"][1] / 2
        V = np.array([c - a * u - b * v, c + a * u - b * v, c + a * u + b * v, c - a * u + b * v])
        return V, np.array([[0, 1, 2], [0, 2, 3]])
    r, m = shape["radius"], CIRCLE_SEGMENTS
    ang = 2 * math.pi * np.arange(m) / m
    ring = c + r * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * v)
    V = np.vstack([c[None], ring])
    F = np.array([[0, 1 + i, 1 + (i + 1) % m] for i in range(m)])
    return V, F


def part_rotation(part: dict) -> np.ndarray:
    """The rotation (3, 3) of a ``box`` or ``mesh`` part: ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (z-y'-x'' Tait-Bryan
    angles, the vehicle convention of ISO 8855 "Road vehicles - Vehicle dynamics and road-holding ability -
    Vocabulary": roll about the forward x axis, then pitch about y, then yaw about the vertical z axis), from the
    part's ``roll_deg``, ``pitch_deg``, ``yaw_deg`` (degrees, each 0 when absent). Only yaw: ``Rz(yaw)`` exactly."""
    def rot(axis: int, deg: float) -> np.ndarray:
        t = math.radians(deg)
        c, s_ = math.cos(t), math.sin(t)
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        r = np.eye(3)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s_, s_, c
        return r

    R = rot(2, part.get("yaw_deg", 0.0))
    if part.get("pitch_deg", 0.0) or part.get("roll_deg", 0.0):
        R = R @ rot(1, part.get("pitch_deg", 0.0)) @ rot(0, part.get("roll_deg", 0.0))
    return R


@functools.lru_cache(maxsize=1)
def _unit_sphere() -> tuple[np.ndarray, np.ndarray]:
    """The :data:`SPHERE_SEGMENTS` tessellation of the unit sphere: the ring vertices U (n, 3) (without the poles)
    and the faces F (m, 3), pole 0 first and the other pole last (a sphere mesh of centre c, radius r is
    [c + (0, 0, r), c + r U, c - (0, 0, r)]); computed once (thousands of sphere parts per scene)."""
    nl, nt = SPHERE_SEGMENTS
    U = []
    for i in range(1, nt):
        th = math.pi * i / nt
        for j in range(nl):
            ph = 2 * math.pi * j / nl
            U.append(np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)]))
    F = [[0, 1 + j, 1 + (j + 1) % nl] for j in range(nl)]
    for i in range(nt - 2):
        b0, b1 = 1 + i * nl, 1 + (i + 1) * nl
        for j in range(nl):
            j1 = (j + 1) % nl
            F += [[b0 + j, b1 + j, b1 + j1], [b0 + j, b1 + j1, b0 + j1]]
    last = len(U) + 1
    b0 = 1 + (nt - 2) * nl
    F += [[last, b0 + (j + 1) % nl, b0 + j] for j in range(nl)]
    U, F = np.array(U), np.array(F)
    U.flags.writeable = False
    F.flags.writeable = False
    return U, F


def part_mesh(part: dict, offset=np.zeros(3), meshes: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Triangle mesh (V (n, 3) m, F (m, 3) int, outward counter-clockwise) of one primitive part, moved by
    ``offset`` (3,) m. Analytic Mitsuba shapes are slow in the LLVM backend (Embree user geometry), so every
    primitive is tessellated and the parts of one object and material are merged into one mesh. ``meshes``: the
    scene's ``meshes`` (needed by a ``mesh`` part: its vertices scaled per axis, turned by ``yaw_deg`` about z and
    moved to ``center``); a box or mesh part turns by :func:`part_rotation`."""
    s = part["shape"]
    if s in ("rect", "disk"):
        return _plane_mesh(part, offset)
    if s == "mesh":
        m = (meshes or {})[part["mesh"]]
        V = (np.asarray(m["vertices"], dtype=float) * np.asarray(part.get("scale", (1.0, 1.0, 1.0)), dtype=float))
        return (V @ part_rotation(part).T + (np.asarray(part["center"], dtype=float) + offset),
                np.asarray(m["faces"], dtype=np.int64))
    if s == "box":
        c = np.asarray(part["center"], dtype=float) + offset
        hx, hy, hz = (x / 2 for x in part["size"])
        corners = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        V = corners @ part_rotation(part).T + c
        # vertex index = 4*(sx>0) + 2*(sy>0) + (sz>0); faces wound outward
        F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5],      # -x, +x
                      [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],      # -y, +y
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])     # -z, +z
        return V, F
    if s == "sphere":
        c = np.asarray(part["center"], dtype=float) + offset
        r = part["radius"]
        U, F = _unit_sphere()
        # elementwise as the per-vertex sum c + r * u: the same float64 values
        V = np.vstack([(c + [0, 0, r])[None], c + r * U, (c + [0, 0, -r])[None]])
        return V, F.copy()
    # cylinder with caps
    p0 = np.asarray(part["p0"], dtype=float) + offset
    p1 = np.asarray(part["p1"], dtype=float) + offset
    axis = p1 - p0
    u, v, n = _frame(axis / np.linalg.norm(axis))
    r, m = part["radius"], CIRCLE_SEGMENTS
    ang = 2 * math.pi * np.arange(m) / m
    ring = r * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * v)
    V = np.vstack([p0 + ring, p1 + ring, p0[None], p1[None]])
    F = []
    for i in range(m):
        i1 = (i + 1) % m
        F += [[i, i1, m + i1], [i, m + i1, m + i]]
        F += [[2 * m, i1, i], [2 * m + 1, m + i, m + i1]]
    return V, np.array(F)


def _moves(scene: dict, instance: int) -> bool:
    """Whether object ``instance`` (-1: none, static) has a non-zero velocity."""
    return instance >= 0 and any(float(v) != 0.0 for v in scene["objects"][instance]["velocity_mps"])


def _object_meshes(obj: dict, offset: np.ndarray, meshes: dict | None = None,
                   materials: dict | None = None, t: float = 0.0) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray | None]]:
    """Meshes of one object moved by ``offset`` (3,) m, one per material sorted by name (the order of
    :func:`shape_id`): ``[(material, V (n, 3) m, F (m, 3), UV (n, 2) or None)]``, parts of a material merged.
    ``meshes``: the scene's ``meshes`` (for ``mesh`` parts). ``materials``: the scene's materials; the mesh of a
    material with a ``texture`` (scene version 2) is unwelded and gets box-projected texture coordinates taken at
    offset 0 (:func:`render_tools.textures.box_uv`: the texture moves with the object); the others are as before,
    ``UV`` None. ``t``: time, s, of a walker's pose (an object with a ``gait``, scene version 2:
    :func:`render_tools.scene_templates.posed_parts`); other objects' parts do not depend on it."""
    by_mat: dict = {}
    for part in (posed_parts(obj, t) if "gait" in obj else obj["parts"]):
        by_mat.setdefault(part["material"], []).append(part)
    out = []
    for mat, parts in sorted(by_mat.items()):
        tex = (materials or {}).get(mat, {}).get("texture")
        if tex is None:
            out.append((mat, *merge_meshes([part_mesh(p, offset, meshes) for p in parts]), None))
            continue
        from .textures import box_uv  # noqa: PLC0415
        V0, F0 = merge_meshes([part_mesh(p, np.zeros(3), meshes) for p in parts])
        V, F, UV = box_uv(V0, F0, tex)
        out.append((mat, V + np.asarray(offset, dtype=float), F, UV))
    return out


def merge_meshes(meshes) -> tuple[np.ndarray, np.ndarray]:
    """One mesh (V (n, 3), F (m, 3)) of several ``[(V_i, F_i), ...]``: vertices stacked, faces renumbered."""
    Vs, Fs, base = [], [], 0
    for V, F in meshes:
        Vs.append(V)
        Fs.append(F + base)
        base += len(V)
    return np.vstack(Vs), np.vstack(Fs)


def _mesh(mi, name: str, V: np.ndarray, F: np.ndarray, bsdf, emitter=None, UV: np.ndarray | None = None):
    props = mi.Properties()
    props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    if UV is None:
        m = mi.Mesh(name, len(V), len(F), props=props)
    else:
        m = mi.Mesh(name, len(V), len(F), props=props, has_vertex_texcoords=True)
    p = mi.traverse(m)
    _write_mesh(p, "", V, F, UV)
    p.update()
    return m


def _write_mesh(params, prefix: str, V: np.ndarray, F: np.ndarray, UV: np.ndarray | None) -> None:
    """Write a mesh's arrays into Mitsuba parameters ``params`` under ``prefix`` ("" for a mesh's own, or
    ``"<shape id>."`` in a scene's): vertices (n, 3) m and texture coordinates (n, 2) as float32, faces (m, 3) as
    uint32. The one conversion :func:`_mesh` and :func:`place_moving` share, so a moved mesh holds the arrays a
    newly loaded one would, bit for bit. The caller runs ``params.update()``."""
    params[f"{prefix}vertex_positions"] = type(params[f"{prefix}vertex_positions"])(
        np.asarray(V, dtype=np.float32).ravel())
    params[f"{prefix}faces"] = type(params[f"{prefix}faces"])(np.asarray(F, dtype=np.uint32).ravel())
    if UV is not None:
        params[f"{prefix}vertex_texcoords"] = type(params[f"{prefix}vertex_texcoords"])(
            np.asarray(UV, dtype=np.float32).ravel())


def _reflectance(m: dict, texture_filter: str = "bilinear") -> dict:
    """The diffuse reflectance of material ``m``: its flat ``rgb``, or (scene version 2) the bitmap of its
    ``texture`` (:func:`render_tools.textures.texture_array`, generated here, repeating), looked up with Mitsuba's
    ``texture_filter`` (``bilinear``: four texels each upsampled to the path's wavelengths; ``nearest``: one)."""
    if "texture" not in m:
        return {"type": "rgb", "value": list(m["rgb"])}
    import mitsuba as mi  # noqa: PLC0415

    from .textures import texture_array  # noqa: PLC0415
    return {"type": "bitmap", "bitmap": mi.Bitmap(texture_array(m["texture"], m["rgb"])),
            "filter_type": texture_filter, "wrap_mode": "repeat"}


def _bsdf(m: dict, texture_filter: str = "bilinear") -> dict:
    t = m["type"]
    if t == "diffuse":
        return {"type": "diffuse", "reflectance": _reflectance(m, texture_filter)}
    if t == "roughplastic":  # a rough dielectric coating (index ``ior``) over a diffuse base
        return {"type": "roughplastic", "distribution": "ggx", "alpha": float(m["alpha"]),
                "diffuse_reflectance": _reflectance(m, texture_filter),
                **({"int_ior": float(m["ior"])} if "ior" in m else {})}
    return {"type": "roughconductor", "material": "Al", "distribution": "ggx", "alpha": float(m["alpha"])}


def object_offset(scene: dict, instance: int, t: float) -> np.ndarray:
    """Displacement (3,) m of object ``instance`` at time ``t`` (s): velocity_mps * t (-1 = static)."""
    if instance < 0:
        return np.zeros(3)
    return np.asarray(scene["objects"][instance]["velocity_mps"], dtype=float) * float(t)


def light_points(scene: dict, light: dict, t: float) -> np.ndarray:
    """World points (P, 3) m outlining light ``light``'s face at time ``t`` (s)."""
    return plane_corners(light) + object_offset(scene, light["instance"], t)


def light_spectrum(light: dict) -> np.ndarray:
    """Absolute spectral radiance (N,) W sr^-1 m^-2 nm^-1 of a light's face on :func:`spectra.wavelengths`."""
    return spectra.absolute_spectrum(light["spectrum"], light["luminance_cd_m2"])


def sky_scale(scene: dict) -> float:
    """The factor on Mitsuba's ``sunsky`` radiance of the scene's sky (``sky.scale``; 1 for other skies)."""
    s = scene["sky"]
    return float(s["scale"]) if s["model"] == "sunsky" else 1.0


def sky_dict(scene: dict, unit_scale: bool = False) -> dict:
    """Mitsuba emitter dict of the scene's sky (group ``skymap``). ``unit_scale``: a ``sunsky`` without its
    :func:`sky_scale` (the renderer applies it: Mitsuba compiles the scale into kernels as a literal)."""
    s = scene["sky"]
    if s["model"] == "sunsky":
        el, az = math.radians(s["sun_elevation_deg"]), math.radians(s["sun_azimuth_deg"])
        d = [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
        k = 1.0 if unit_scale else sky_scale(scene)
        return {"type": "sunsky", "sun_direction": d, "turbidity": float(s["turbidity"]),
                "sun_scale": k, "sky_scale": k}
    return {"type": "constant",
            "radiance": spectra.mitsuba_spectrum(spectra.absolute_spectrum(s["spectrum"], s["luminance_cd_m2"]))}


def _emission(light: dict, emission: dict) -> tuple[dict, dict]:
    """Mitsuba spectrum dicts of a lamp's face (radiance) and beam (intensity = radiance x face area), kept in
    ``emission`` (a cache dict) by light id, spectrum and luminance."""
    key = (light["id"], json.dumps(light["spectrum"], sort_keys=True), float(light["luminance_cd_m2"]))
    if key not in emission:
        rad = light_spectrum(light)
        emission[key] = (spectra.mitsuba_spectrum(rad), spectra.mitsuba_spectrum(rad, scale=plane_area(light)))
    return emission[key]


def prepare_geometry(scene: dict, cache: dict) -> dict:
    """Fill ``cache`` (the ``cache`` of :func:`mitsuba_dict`) with what does not need Mitsuba: the meshes of the
    objects and lamps that do not move (numpy vertices and faces, offset 0) and every lamp's emission spectrum
    dicts. :func:`mitsuba_dict` calls it; a renderer may call it earlier, e.g. while the Mitsuba back end is
    still being probed. Returns ``cache``."""
    rest = cache.setdefault("rest_meshes", {})  # geometry of objects and lamps that never move (numpy arrays)
    emission = cache.setdefault("emission", {})  # per light: spectrum dicts of its face and beam (strings)
    for o in scene["objects"]:
        if ("object", o["id"]) not in rest and not _moves(scene, o["id"]) and "gait" not in o:
            rest[("object", o["id"])] = _object_meshes(o, np.zeros(3), scene.get("meshes"), scene["materials"])
    for lt in scene["lights"]:
        if ("light", lt["id"]) not in rest and not _moves(scene, lt["instance"]):
            rest[("light", lt["id"])] = _plane_mesh(lt, np.zeros(3))
        _emission(lt, emission)
    return cache


def mitsuba_dict(scene: dict, t: float, emit: str | None = None, lights: list[int] | None = None,
                 integrator: dict | None = None, cache: dict | None = None, unit_sky: bool = False,
                 texture_filter: str = "bilinear") -> dict:
    """Mitsuba scene dict (no sensor) of ``scene`` at time ``t`` (s, places moving objects).

    Args:
        emit: which emitters are on: a light group name (its lights), ``"skymap"`` (the sky), ``"all"``
            (every light, and the sky unless it emits nothing) or ``None`` (no emitter: geometry only, e.g. for AOVs).
        lights: optional subset of light ids of ``emit`` to include as emitters (default all of the group).
        integrator: Mitsuba integrator dict (default ``path`` with :data:`MAX_DEPTH`).
        cache: optional dict reused across calls for the same scene and variant: keeps the loaded BSDFs, the
            meshes (numpy vertices and faces) of objects and lamps that do not move, and every lamp's spectrum
            dicts, so the frames after the first rebuild only what moves (the result is the same).
        unit_sky: the sky without its :func:`sky_scale` (``sky_dict(unit_scale=True)``), for a renderer that
            applies the scale itself.
        texture_filter: ``filter_type`` of the texture bitmaps, ``bilinear`` or ``nearest``
            (``RenderOptions.texture_filter``).
    Returns:
        dict for ``mi.load_dict`` holding instantiated meshes (one per object and material, one per lamp
        face); shape ids follow :func:`shape_id`, :func:`light_shape_id`, :func:`beam_id`.
    """
    import mitsuba as mi  # noqa: PLC0415

    if emit is not None and emit not in LIGHT_GROUPS + ("skymap", "all"):
        raise ValueError(f"emit: {emit!r} not a light group, 'skymap', 'all' or None")
    d: dict = {"type": "scene",
               "integrator": integrator or {"type": "path", "max_depth": MAX_DEPTH, "hide_emitters": False}}
    cache = {} if cache is None else cache
    if texture_filter not in ("bilinear", "nearest"):
        raise ValueError(f"texture_filter: {texture_filter!r} not 'bilinear' or 'nearest'")
    # Mitsuba objects belong to a variant (numpy arrays do not); the BSDFs also to the texture filter
    if cache.get("variant") != mi.variant() or cache.get("texture_filter", "bilinear") != texture_filter:
        for k in ("bsdfs", "off_lens", "sky", "sky_unit"):
            cache.pop(k, None)
        cache["variant"], cache["texture_filter"] = mi.variant(), texture_filter
        cache["bsdfs"] = {name: mi.load_dict(_bsdf(m, texture_filter)) for name, m in scene["materials"].items()}
        cache["off_lens"] = mi.load_dict(OFF_LENS)
    bsdfs, off_lens = cache["bsdfs"], cache["off_lens"]
    prepare_geometry(scene, cache)
    rest, emission = cache["rest_meshes"], cache["emission"]
    for o in scene["objects"]:
        # a static object's arrays are the same every frame (offset 0, bit for bit what would be rebuilt)
        meshes = rest.get(("object", o["id"])) or _object_meshes(o, object_offset(scene, o["id"], t),
                                                                 scene.get("meshes"), scene["materials"], t)
        for k, (mat, V, F, UV) in enumerate(meshes):
            name = shape_id(o["id"], k)
            d[name] = _mesh(mi, name, V, F, bsdfs[mat], UV=UV)
    wanted = None if lights is None else set(int(i) for i in lights)
    for lt in scene["lights"]:
        off = object_offset(scene, lt["instance"], t)
        on = emit == "all" or (emit == lt["group"] and (wanted is None or lt["id"] in wanted))
        VF = rest.get(("light", lt["id"])) or _plane_mesh(lt, off)
        emitter = None
        if on:
            face_spec, beam_spec = _emission(lt, emission)
            # light sampling in proportion to luminous flux (pi * Lv * A for a Lambertian face) instead of
            # uniformly over the emitters, so dim tail lamps do not take samples from bright headlights
            flux = math.pi * float(lt["luminance_cd_m2"]) * plane_area(lt)
            emitter = mi.load_dict({"type": "area", "radiance": dict(face_spec), "sampling_weight": max(flux, 1e-12)})
            if lt["spread_deg"] < 90.0:
                d[beam_id(lt["id"])] = {
                    "type": "spot", "to_world": _beam_to_world(mi, lt, off),
                    "intensity": dict(beam_spec),
                    "cutoff_angle": float(lt["spread_deg"]),
                    # flux of a cone of intensity I: ~ I * 2 pi (1 - cos cutoff)
                    "sampling_weight": max(2 * math.pi * (1 - math.cos(math.radians(lt["spread_deg"])))
                                           * float(lt["luminance_cd_m2"]) * plane_area(lt), 1e-12),
                    "beam_width": BEAM_WIDTH_FRACTION * float(lt["spread_deg"])}
        name = light_shape_id(lt["id"])
        d[name] = _mesh(mi, name, VF[0], VF[1], off_lens, emitter)
    if emit == "skymap" or (emit == "all" and "skymap" in scene_groups(scene)):
        # one sky object per scene: Mitsuba bakes the environment emitter's registry id into kernels as a
        # literal, so a new sky object per frame would force a recompile per frame
        key = "sky_unit" if unit_sky else "sky"
        if key not in cache:
            cache[key] = mi.load_dict(sky_dict(scene, unit_scale=unit_sky))
        d["sky"] = cache[key]
    return d


def _beam_to_world(mi, light: dict, off: np.ndarray):
    """Mitsuba ``ScalarTransform4f`` placing light ``light``'s beam (spot) :data:`BEAM_OFFSET_M` in front of its face,
    the face moved by ``off`` (3,) m, looking along the face normal."""
    n = np.asarray(light["normal"], dtype=float)
    n /= np.linalg.norm(n)
    pos = np.asarray(light["center"], dtype=float) + off + BEAM_OFFSET_M * n
    up = [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0]
    return mi.ScalarTransform4f().look_at(pos.tolist(), (pos + n).tolist(), up)


def place_moving(params, scene: dict, t: float, cache: dict) -> bool:
    """Move what moves in a scene loaded from :func:`mitsuba_dict` (``params = mi.traverse(loaded)``) to time ``t``
    (s): the vertices (and texture coordinates) of every object and lamp face that is not in ``cache``'s static
    meshes (:func:`prepare_geometry`: moving objects, walkers) and the beams of the moving lamps, with the same
    float32 arrays :func:`mitsuba_dict` would build at ``t``; then ``params.update()`` (Mitsuba refreshes the
    meshes' bounding boxes and its ray-tracing acceleration structure). The static meshes stay as loaded: a bin's
    scene without rebuilding them (docs/benchmarks/motion-storage.md). Returns False, changing nothing, when a
    mesh's vertex or face count at ``t`` differs from the loaded one (the caller then loads the scene anew)."""
    import drjit as dr  # noqa: PLC0415
    import mitsuba as mi  # noqa: PLC0415

    prepare_geometry(scene, cache)
    rest = cache["rest_meshes"]
    sets: dict = {}
    for o in scene["objects"]:
        if ("object", o["id"]) in rest:
            continue
        meshes = _object_meshes(o, object_offset(scene, o["id"], t), scene.get("meshes"), scene["materials"], t)
        for k, (_mat, V, F, UV) in enumerate(meshes):
            sets[shape_id(o["id"], k)] = (V, F, UV)
        if f"{shape_id(o['id'], len(meshes))}.vertex_positions" in params:
            return False    # the loaded scene holds more parts of this object than it has at t: load anew
    beams = {}
    for lt in scene["lights"]:
        if ("light", lt["id"]) in rest:
            continue
        off = object_offset(scene, lt["instance"], t)
        sets[light_shape_id(lt["id"])] = (*_plane_mesh(lt, off), None)
        if f"{beam_id(lt['id'])}.to_world" in params:
            beams[f"{beam_id(lt['id'])}.to_world"] = _beam_to_world(mi, lt, off)
    for name, (V, F, UV) in sets.items():
        key = f"{name}.vertex_positions"
        if key not in params or dr.width(params[key]) != 3 * len(V) or dr.width(params[f"{name}.faces"]) != 3 * len(F):
            return False
    for name, (V, F, UV) in sets.items():
        _write_mesh(params, f"{name}.", V, F, UV)
    for key, tf in beams.items():
        params[key] = type(params[key])(tf)
    params.update()
    return True


def pad_emitter_dict() -> dict:
    """Mitsuba dict of an emitter of the same plugin and spectrum type as a lamp's beam (a ``spot`` with a
    ``regular`` spectrum), for the inert registry padding of :func:`render_tools.tracer.pad_registry`."""
    return {"type": "spot", "intensity": spectra.mitsuba_spectrum(np.ones(len(spectra.wavelengths())))}


def _off_values(values):
    """Zero emission that Mitsuba accepts: a spectrum that is exactly 0 on 360..829 nm (every band we render)
    with a tiny value at the last 830 nm node, because a ``regular`` spectrum must have some mass to build
    its sampling distribution."""
    import drjit as dr  # noqa: PLC0415

    n = dr.width(values)
    idx = np.zeros(n, dtype=np.float32)
    idx[-1] = 1e-30
    return type(values)(idx)


def set_solo(params, scene: dict, group: str, light_id: int | None, radiance_cache: dict) -> None:
    """Switch the emitters of ``group`` in a loaded scene (``params = mi.traverse(loaded)``) so that only
    ``light_id`` emits (``None``: all of the group emit). Changes radiance values and emitter sampling weights
    (a switched-off emitter gets weight 0, so no light samples are wasted on it); ``params.update()`` is
    called. ``radiance_cache`` keeps the original values keyed by parameter name."""
    for lt in scene["lights"]:
        if lt["group"] != group:
            continue
        on = light_id is None or lt["id"] == light_id
        for key in (f"{light_shape_id(lt['id'])}.emitter.radiance.values", f"{beam_id(lt['id'])}.intensity.values"):
            if key not in params:
                continue
            if key not in radiance_cache:
                radiance_cache[key] = type(params[key])(params[key])
            params[key] = radiance_cache[key] if on else _off_values(radiance_cache[key])
        for key in (f"{light_shape_id(lt['id'])}.emitter.sampling_weight", f"{beam_id(lt['id'])}.sampling_weight"):
            if key not in params:
                continue
            if key not in radiance_cache:
                radiance_cache[key] = float(params[key])
            params[key] = radiance_cache[key] if on else 0.0
    params.update()
