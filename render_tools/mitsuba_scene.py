"""Scene dict (:mod:`render_tools.scene`) -> Mitsuba 3 scene dicts, one per light group.

Every group is rendered with the *whole* geometry but only its own emitters, so group images add up to the
full scene (light transport is linear in the emission). Lights of other groups keep their lamp geometry with
a non-emissive lens material, so they still occlude and reflect as in the full scene.

Emitters
- Lamp faces are ``area`` emitters on ``rectangle`` / ``disk`` shapes with an absolute spectral radiance
  (W sr^-1 m^-2 nm^-1) from :mod:`render_tools.spectra`; Mitsuba's ``area`` emitter is Lambertian and
  one-sided, so the camera sees the lamp's luminance from every direction in front of it.
- Beam-angle control (upstream "spread" < 90 deg, i.e. headlights 7.5-22.5 deg half-angle): the *illumination*
  a beam throws on the scene is a ``spot`` emitter 2 cm in front of the face with cutoff angle = spread,
  smooth fall-off from 0.75 * spread, and on-axis spectral intensity I = L * A (W sr^-1 nm^-1; the on-axis
  intensity of the face itself, A = face area in m^2). The face stays Lambertian for direct view (a camera
  looking into a beam from outside its cone sees the face slightly too bright; documented in
  docs/rendering.md). A spread of 90 deg (tail lamps, streetlights, signals) is the face alone.
- Sky (group ``skymap``): Mitsuba's ``sunsky`` (Hosek-Wilkie sky + sun; z-up, matches the scene frame) scaled
  by ``sky.scale``, or a ``constant`` environment with an absolute spectrum (night).

Moving objects are placed at their position at the time given (object motion is not blurred inside an
exposure; the ego-motion blur is continuous, see :mod:`render_tools.camera`).
"""
from __future__ import annotations

import math

import numpy as np

from . import spectra
from .scene import LIGHT_GROUPS

#: Path-tracing depth: Mitsuba ``max_depth`` 5 = 4 indirect bounces (upstream renders with 4 bounces).
MAX_DEPTH = 5
#: Offset of a beam's spot emitter in front of its lamp face, m.
BEAM_OFFSET_M = 0.02
#: Fall-off start of a beam as a fraction of its cutoff (spread) angle.
BEAM_WIDTH_FRACTION = 0.75
#: Lens material of a lamp that is not emitting in the current render (dark, slightly glossy).
OFF_LENS = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.03, 0.03, 0.03]}}


def shape_id(obj_id: int, part: int) -> str:
    """Mitsuba id of part ``part`` of object ``obj_id``."""
    return f"o{obj_id}_p{part}"


def light_shape_id(light_id: int) -> str:
    """Mitsuba id of the lamp face of light ``light_id`` (its emitter's parameters live under this key)."""
    return f"light{light_id}"


def beam_id(light_id: int) -> str:
    """Mitsuba id of the spot emitter carrying light ``light_id``'s beam."""
    return f"beam{light_id}"


def _frame(normal, horizontal_if_up=(1.0, 0.0, 0.0)):
    """Orthonormal (u, v, n) with u x v = n; v is 'up' in the plane (world z projected), or, for horizontal
    planes, u follows world x."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    if abs(n[2]) > 0.9:
        u = np.asarray(horizontal_if_up, dtype=float)
        u = u - n * (u @ n)
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
    else:
        v = np.array([0.0, 0.0, 1.0]) - n * n[2]
        v /= np.linalg.norm(v)
        u = np.cross(v, n)
    return u, v, n


def plane_corners(shape: dict) -> np.ndarray:
    """World corners (4, 3) m of a rect, or 8 points on the rim of a disk (8, 3) m."""
    u, v, n = _frame(shape["normal"])
    c = np.asarray(shape["center"], dtype=float)
    if shape["shape"] == "rect":
        a, b = shape["size"][0] / 2, shape["size"][1] / 2
        return np.array([c + su * a * u + sv * b * v for su in (-1, 1) for sv in (-1, 1)])
    r = shape["radius"]
    ang = np.linspace(0, 2 * math.pi, 8, endpoint=False)
    return np.array([c + r * (math.cos(t) * u + math.sin(t) * v) for t in ang])


def plane_area(shape: dict) -> float:
    """Area of a rect/disk lamp face, m^2."""
    return shape["size"][0] * shape["size"][1] if shape["shape"] == "rect" else math.pi * shape["radius"] ** 2


def _plane_transform(mi, shape, offset):
    u, v, n = _frame(shape["normal"])
    c = np.asarray(shape["center"], dtype=float) + offset
    if shape["shape"] == "rect":
        su, sv = shape["size"][0] / 2, shape["size"][1] / 2
    else:
        su = sv = shape["radius"]
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = u * su, v * sv, n, c
    return mi.ScalarTransform4f(m.tolist())


def _bsdf(m: dict) -> dict:
    t = m["type"]
    if t == "diffuse":
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(m["rgb"])}}
    if t == "roughplastic":
        return {"type": "roughplastic", "distribution": "ggx", "alpha": float(m["alpha"]),
                "diffuse_reflectance": {"type": "rgb", "value": list(m["rgb"])}}
    return {"type": "roughconductor", "material": "Al", "distribution": "ggx", "alpha": float(m["alpha"])}


def _part_dict(mi, part: dict, offset: np.ndarray, bsdf: dict) -> dict:
    s = part["shape"]
    if s == "box":
        c = np.asarray(part["center"], dtype=float) + offset
        half = [x / 2 for x in part["size"]]
        tf = (mi.ScalarTransform4f().translate(c.tolist()).rotate([0, 0, 1], part.get("yaw_deg", 0.0))
              .scale(half))
        return {"type": "cube", "to_world": tf, "bsdf": bsdf}
    if s == "cylinder":
        return {"type": "cylinder", "p0": (np.asarray(part["p0"]) + offset).tolist(),
                "p1": (np.asarray(part["p1"]) + offset).tolist(), "radius": float(part["radius"]), "bsdf": bsdf}
    if s == "sphere":
        return {"type": "sphere", "center": (np.asarray(part["center"]) + offset).tolist(),
                "radius": float(part["radius"]), "bsdf": bsdf}
    return {"type": "rectangle" if s == "rect" else "disk", "to_world": _plane_transform(mi, part, offset),
            "bsdf": bsdf}


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


def sky_dict(scene: dict) -> dict:
    """Mitsuba emitter dict of the scene's sky (group ``skymap``)."""
    s = scene["sky"]
    if s["model"] == "sunsky":
        el, az = math.radians(s["sun_elevation_deg"]), math.radians(s["sun_azimuth_deg"])
        d = [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
        return {"type": "sunsky", "sun_direction": d, "turbidity": float(s["turbidity"]),
                "sun_scale": float(s["scale"]), "sky_scale": float(s["scale"])}
    return {"type": "constant",
            "radiance": spectra.mitsuba_spectrum(spectra.absolute_spectrum(s["spectrum"], s["luminance_cd_m2"]))}


def mitsuba_dict(scene: dict, t: float, emit: str | None = None, lights: list[int] | None = None,
                 integrator: dict | None = None) -> dict:
    """Mitsuba scene dict (no sensor) of ``scene`` at time ``t`` (s, places moving objects).

    Args:
        emit: which emitters are on: a light group name (its lights), ``"skymap"`` (the sky), ``"all"``
            (every light and the sky) or ``None`` (no emitter: geometry only, e.g. for AOVs).
        lights: optional subset of light ids of ``emit`` to include as emitters (default all of the group).
        integrator: Mitsuba integrator dict (default ``path`` with :data:`MAX_DEPTH`).
    Returns:
        dict for ``mi.load_dict``; shape ids follow :func:`shape_id`, :func:`light_shape_id`, :func:`beam_id`.
    """
    import mitsuba as mi  # noqa: PLC0415

    if emit is not None and emit not in LIGHT_GROUPS + ("skymap", "all"):
        raise ValueError(f"emit: {emit!r} not a light group, 'skymap', 'all' or None")
    d: dict = {"type": "scene",
               "integrator": integrator or {"type": "path", "max_depth": MAX_DEPTH, "hide_emitters": False}}
    bsdfs = {name: _bsdf(m) for name, m in scene["materials"].items()}
    for o in scene["objects"]:
        off = object_offset(scene, o["id"], t)
        for j, part in enumerate(o["parts"]):
            d[shape_id(o["id"], j)] = _part_dict(mi, part, off, bsdfs[part["material"]])
    wanted = None if lights is None else set(int(i) for i in lights)
    for lt in scene["lights"]:
        off = object_offset(scene, lt["instance"], t)
        on = emit == "all" or (emit == lt["group"] and (wanted is None or lt["id"] in wanted))
        face = {"type": "rectangle" if lt["shape"] == "rect" else "disk",
                "to_world": _plane_transform(mi, lt, off), "bsdf": OFF_LENS}
        if on:
            rad = light_spectrum(lt)
            face["emitter"] = {"type": "area", "radiance": spectra.mitsuba_spectrum(rad)}
            if lt["spread_deg"] < 90.0:
                n = np.asarray(lt["normal"], dtype=float)
                n /= np.linalg.norm(n)
                pos = np.asarray(lt["center"], dtype=float) + off + BEAM_OFFSET_M * n
                up = [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0]
                d[beam_id(lt["id"])] = {
                    "type": "spot", "to_world": mi.ScalarTransform4f().look_at(pos.tolist(), (pos + n).tolist(), up),
                    "intensity": spectra.mitsuba_spectrum(rad, scale=plane_area(lt)),
                    "cutoff_angle": float(lt["spread_deg"]),
                    "beam_width": BEAM_WIDTH_FRACTION * float(lt["spread_deg"])}
        d[light_shape_id(lt["id"])] = face
    if emit in ("skymap", "all"):
        d["sky"] = sky_dict(scene)
    return d


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
            if key in params:
                params[key] = 1.0 if on else 0.0
    params.update()
