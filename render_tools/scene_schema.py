"""The scene file: plain, editable JSON that fully describes what is rendered, and its validation.

A scene is a dict (saved as JSON): geometry made of primitive parts (boxes, cylinders, rectangles, disks,
spheres) and, from version 2, triangle meshes (part shape ``mesh``: an entry of the scene's ``meshes``, placed,
turned and scaled), materials, emitters (lights) with their group, spectrum model and luminance (cd/m^2), the sky, the ego
camera and the short-exposure time. Re-rendering a scene file gives the same images (up to Monte Carlo noise with
a different seed). The procedural generator that writes such files is :mod:`render_tools.scene`; hand-made scenes
start from :func:`empty_scene`.

World frame: ISO 8855, metres: x forward along the road, y left, z up; the road surface is z = 0. Traffic
drives on the right: the ego direction uses lanes at y < 0.

Functions
- :func:`validate_scene` -> the scene, or ``ValueError`` naming the offending field (``scene.lights[3].size``).
- :func:`scene_groups` -> the groups a scene has.
- :func:`load_scene` / :func:`save_scene` -> JSON on disk (atomic write).
- :func:`empty_scene` -> a valid scene with nothing in it.
"""
from __future__ import annotations

import os
from typing import Any

import numpy as np

from lfmbench.check import check_integer, check_keys, check_number, check_vector, fail, scene_id_error
from lfmbench.fileio import atomic_write_json
from lfmbench.limits import LimitError, brief, lights_cap_message, limit
from lfmbench.vocabulary import GROUPS, LIGHT_GROUPS, LIGHT_KINDS, OBJECT_KINDS, WEATHERS

from . import spectra

__all__ = ["SCENE_FORMAT", "SCENE_VERSION", "SCENE_VERSIONS", "TIMES_OF_DAY", "PART_SHAPES", "MATERIAL_TYPES",
           "MAX_COORD_M", "validate_scene", "validate_meshes", "mesh_triangles", "scene_groups", "load_scene", "save_scene", "empty_scene"]

#: Scene file format name and version.
SCENE_FORMAT = "lfmbench-scene"
SCENE_VERSION = 1
#: Versions this reader accepts. Version 2 (scene generator 2, protocol lfmbench-v2) adds ``weather``, ``meshes``
#: and the part shape ``mesh``; a version-1 file may not use them (an older reader would refuse them).
SCENE_VERSIONS = (1, 2)
TIMES_OF_DAY = ("day", "dusk", "night")
PART_SHAPES = ("box", "cylinder", "rect", "disk", "sphere", "mesh")
MATERIAL_TYPES = ("diffuse", "roughplastic", "roughconductor")
#: Largest coordinate magnitude accepted, m.
MAX_COORD_M = 1.0e4


# ------------------------------------------------------------------------------------------- validation
def _unit(v, path):
    x = np.array(check_vector(v, path, n=3, lo=-1e3, hi=1e3))
    if np.linalg.norm(x) < 1e-6:
        fail(path, "normal must be non-zero")
    return x


def _part_or_light_shape(p, path, extra_req, extra_opt, materials=None, meshes=None):
    shape = p.get("shape") if isinstance(p, dict) else None
    allowed = PART_SHAPES if materials is not None else ("rect", "disk")
    if shape not in allowed:
        fail(f"{path}.shape", f"{brief(shape)} not one of {allowed}")
    geo = {"box": (("center", "size"), ("yaw_deg",)), "cylinder": (("p0", "p1", "radius"), ()),
           "rect": (("center", "size", "normal"), ()), "disk": (("center", "radius", "normal"), ()),
           "sphere": (("center", "radius"), ()), "mesh": (("mesh", "center"), ("yaw_deg", "scale"))}[shape]
    check_keys(p, path, required=("shape",) + geo[0] + extra_req, optional=geo[1] + extra_opt)
    for k in ("center", "p0", "p1"):
        if k in p:
            check_vector(p[k], f"{path}.{k}", lo=-MAX_COORD_M, hi=MAX_COORD_M)
    if shape == "mesh":
        if p["mesh"] not in (meshes or {}):
            fail(f"{path}.mesh", f"{brief(p['mesh'])} is not defined in scene.meshes")
        if "scale" in p:
            check_vector(p["scale"], f"{path}.scale", lo=1e-3, hi=1e3)
    if "size" in p:
        check_vector(p["size"], f"{path}.size", n=3 if shape == "box" else 2, lo=0.0, hi=MAX_COORD_M)
        if min(p["size"]) <= 0:
            fail(f"{path}.size", f"all sizes must be > 0 m, got {p['size']}")
    if "radius" in p:
        check_number(p["radius"], f"{path}.radius", lo=0.0, hi=1e3, lo_open=True)
    if "normal" in p:
        _unit(p["normal"], f"{path}.normal")
    if "yaw_deg" in p:
        check_number(p["yaw_deg"], f"{path}.yaw_deg", lo=-720.0, hi=720.0)
    if shape == "cylinder" and np.allclose(p["p0"], p["p1"]):
        fail(f"{path}.p1", "cylinder end points coincide")
    if materials is not None and p.get("material") not in materials:
        fail(f"{path}.material", f"{brief(p.get('material'))} is not defined in scene.materials")


def validate_scene(scene: dict) -> dict:
    """Validate a scene dict; returns it unchanged. Raises ``ValueError`` naming the first bad field.

    Schema (all lengths m, times s, angles deg unless named ``_rad``):
    ``format`` ("lfmbench-scene"), ``version`` (1 or 2; 2 only: ``weather``, ``meshes``, mesh parts), ``scene_id`` (str, :func:`lfmbench.check.check_scene_id`),
    ``seed`` (int >= 0),
    ``time_of_day`` (day|dusk|night), ``timing.short_exposure_s`` (> 0),
    ``camera`` {position_m [3], yaw_deg, pitch_deg (-89, 89), fov_x_deg (0, 180), speed_mps >= 0,
    yaw_rate_rad_s}, ``sky`` {model: sunsky {sun_elevation_deg [-5, 90], sun_azimuth_deg, turbidity [1, 10],
    scale > 0} | constant {spectrum, luminance_cd_m2 >= 0}}, ``groups`` {name in GROUPS: {flicker: bool}},
    ``materials`` {name: {type: diffuse|roughplastic|roughconductor, rgb [3] in [0, 1], alpha (0, 1], ior (1, 3]
    (roughplastic only: the coating's index of refraction, default 1.49; water 1.33)}},
    ``weather`` (optional, dry|wet|rain; absent = dry), ``meshes`` (optional) {name: {vertices [[x, y, z], ...] m
    in the mesh's own frame, faces [[i, j, k], ...] counter-clockwise seen from outside}},
    ``objects`` [{id (= index), kind, velocity_mps [3], parts [shape ...]}] (a ``mesh`` part: {mesh: name, center
    [3] m: where the mesh's origin goes, yaw_deg: turn about z, scale [3]: per axis before the turn, material}), ``lights`` [{id (= index),
    group, kind, instance (object id), shape rect|disk, center, normal, size | radius, spread_deg (0, 90],
    spectrum (see :mod:`render_tools.spectra`), luminance_cd_m2 >= 0}].
    """
    check_keys(scene, "scene", required=("format", "version", "scene_id", "seed", "time_of_day", "timing", "camera",
                                         "sky", "groups", "materials", "objects", "lights"),
               optional=("weather", "meshes"))
    if scene["format"] != SCENE_FORMAT:
        fail("scene.format", f"expected {brief(SCENE_FORMAT)}, got {brief(scene['format'])}")
    if scene["version"] not in SCENE_VERSIONS or isinstance(scene["version"], bool):
        fail("scene.version", f"unsupported version {brief(scene['version'])} (this reader: {SCENE_VERSIONS})")
    for k in ("weather", "meshes"):
        if k in scene and scene["version"] < 2:
            fail(f"scene.{k}", "needs scene version 2 (set scene.version to 2)")
    if "weather" in scene and scene["weather"] not in WEATHERS:
        fail("scene.weather", f"{brief(scene['weather'])} is not one of {WEATHERS}")
    meshes = validate_meshes(scene.get("meshes", {}), "scene.meshes")
    why = scene_id_error(scene["scene_id"])  # the corpus rule: the id becomes a corpus directory name
    if why is not None:
        fail("scene.scene_id", why)
    check_integer(scene["seed"], "scene.seed")
    if scene["time_of_day"] not in TIMES_OF_DAY:
        fail("scene.time_of_day", f"{brief(scene['time_of_day'])} not one of {TIMES_OF_DAY}")
    check_keys(scene["timing"], "scene.timing", required=("short_exposure_s",))
    check_number(scene["timing"]["short_exposure_s"], "scene.timing.short_exposure_s", lo=0.0, hi=1.0, lo_open=True)
    c = scene["camera"]
    check_keys(c, "scene.camera", required=("position_m", "yaw_deg", "pitch_deg", "fov_x_deg", "speed_mps",
                                            "yaw_rate_rad_s"))
    check_vector(c["position_m"], "scene.camera.position_m", lo=-MAX_COORD_M, hi=MAX_COORD_M)
    check_number(c["yaw_deg"], "scene.camera.yaw_deg", lo=-720, hi=720)
    check_number(c["pitch_deg"], "scene.camera.pitch_deg", lo=-89, hi=89)
    check_number(c["fov_x_deg"], "scene.camera.fov_x_deg", lo=0.0, hi=179.0, lo_open=True)
    check_number(c["speed_mps"], "scene.camera.speed_mps", lo=0.0, hi=200.0)
    check_number(c["yaw_rate_rad_s"], "scene.camera.yaw_rate_rad_s", lo=-10.0, hi=10.0)
    s = scene["sky"]
    model = s.get("model") if isinstance(s, dict) else None
    if model == "sunsky":
        check_keys(s, "scene.sky", required=("model", "sun_elevation_deg", "sun_azimuth_deg", "turbidity", "scale"))
        check_number(s["sun_elevation_deg"], "scene.sky.sun_elevation_deg", lo=-5.0, hi=90.0)
        check_number(s["sun_azimuth_deg"], "scene.sky.sun_azimuth_deg", lo=-360.0, hi=360.0)
        check_number(s["turbidity"], "scene.sky.turbidity", lo=1.0, hi=10.0)
        check_number(s["scale"], "scene.sky.scale", lo=0.0, hi=1e3, lo_open=True)
    elif model == "constant":
        check_keys(s, "scene.sky", required=("model", "spectrum", "luminance_cd_m2"))
        spectra.validate_spectrum(s["spectrum"], "scene.sky.spectrum")
        check_number(s["luminance_cd_m2"], "scene.sky.luminance_cd_m2", lo=0.0, hi=1e6)
    else:
        fail("scene.sky.model", f"{brief(model)} not one of ('sunsky', 'constant')")
    g = scene["groups"]
    if not isinstance(g, dict):
        fail("scene.groups", "expected an object")
    for name, v in g.items():
        if name not in GROUPS:
            fail(f"scene.groups.{name}", f"unknown group (allowed: {GROUPS})")
        check_keys(v, f"scene.groups.{name}", required=("flicker",))
        if not isinstance(v["flicker"], bool):
            fail(f"scene.groups.{name}.flicker", f"expected true/false, got {brief(v['flicker'])}")
    if g.get("skymap", {}).get("flicker"):
        fail("scene.groups.skymap.flicker", "the sky cannot flicker")
    mats = scene["materials"]
    if not isinstance(mats, dict):
        fail("scene.materials", "expected an object")
    for name, m in mats.items():
        p = f"scene.materials.{name}"
        t = m.get("type") if isinstance(m, dict) else None
        if t not in MATERIAL_TYPES:
            fail(f"{p}.type", f"{brief(t)} not one of {MATERIAL_TYPES}")
        req = {"diffuse": ("type", "rgb"), "roughplastic": ("type", "rgb", "alpha"),
               "roughconductor": ("type", "alpha")}[t]
        check_keys(m, p, required=req, optional=("ior",) if t == "roughplastic" else ())
        if "ior" in m:
            check_number(m["ior"], f"{p}.ior", lo=1.0, hi=3.0, lo_open=True)
        if "rgb" in m:
            check_vector(m["rgb"], f"{p}.rgb", n=3, lo=0.0, hi=1.0)
        if "alpha" in m:
            check_number(m["alpha"], f"{p}.alpha", lo=0.0, hi=1.0, lo_open=True)
    objs = scene["objects"]
    if not isinstance(objs, list):
        fail("scene.objects", "expected a list")
    for i, o in enumerate(objs):
        p = f"scene.objects[{i}]"
        check_keys(o, p, required=("id", "kind", "velocity_mps", "parts"))
        if check_integer(o["id"], f"{p}.id") != i:
            fail(f"{p}.id", f"must equal its index {i}, got {o['id']}")
        if o["kind"] not in OBJECT_KINDS:
            fail(f"{p}.kind", f"{brief(o['kind'])} not one of {OBJECT_KINDS}")
        check_vector(o["velocity_mps"], f"{p}.velocity_mps", n=3, lo=-200.0, hi=200.0)
        if not isinstance(o["parts"], list) or not o["parts"]:
            fail(f"{p}.parts", "expected a non-empty list")
        for j, part in enumerate(o["parts"]):
            _part_or_light_shape(part, f"{p}.parts[{j}]", ("material",), (), materials=mats, meshes=meshes)
    lights = scene["lights"]
    if not isinstance(lights, list):
        fail("scene.lights", "expected a list")
    if len(lights) > limit("lights_per_scene"):
        fail("scene.lights", lights_cap_message(len(lights)))
    for i, lt in enumerate(lights):
        p = f"scene.lights[{i}]"
        _part_or_light_shape(lt, p, ("id", "group", "kind", "instance", "spread_deg", "spectrum",
                                     "luminance_cd_m2"), ())
        if check_integer(lt["id"], f"{p}.id") != i:
            fail(f"{p}.id", f"must equal its index {i}, got {lt['id']}")
        if lt["group"] not in LIGHT_GROUPS:
            fail(f"{p}.group", f"{brief(lt['group'])} not one of {LIGHT_GROUPS}")
        if lt["group"] not in g:
            fail(f"{p}.group", f"group {brief(lt['group'])} is not declared in scene.groups")
        if lt["kind"] not in LIGHT_KINDS:
            fail(f"{p}.kind", f"{brief(lt['kind'])} not one of {sorted(LIGHT_KINDS)}")
        if check_integer(lt["instance"], f"{p}.instance", lo=-1) >= len(objs):
            fail(f"{p}.instance", f"object {lt['instance']} does not exist (-1 = none)")
        check_number(lt["spread_deg"], f"{p}.spread_deg", lo=0.0, hi=90.0, lo_open=True)
        spectra.validate_spectrum(lt["spectrum"], f"{p}.spectrum")
        check_number(lt["luminance_cd_m2"], f"{p}.luminance_cd_m2", lo=0.0, hi=1e9)
    return scene


def mesh_triangles(mesh: Any) -> int:
    """Triangles a mesh entry declares (``len(faces)``; 0 when it has none), without reading its arrays."""
    f = mesh.get("faces") if isinstance(mesh, dict) else None
    return len(f) if isinstance(f, list) else 0


def validate_meshes(meshes: Any, path: str = "scene.meshes") -> dict:
    """Check a scene's ``meshes`` ({name: {vertices (n, 3) m, faces (m, 3) vertex indices}}); returns it.

    The triangles of all meshes together are bounded by the limit ``mesh_triangles`` (:mod:`lfmbench.limits`),
    counted before any array is converted. Raises ``ValueError`` naming the field (``scene.meshes.body_car.faces``).
    """
    if not isinstance(meshes, dict):
        fail(path, "expected an object {name: {vertices, faces}}")
    total = sum(mesh_triangles(m) for m in meshes.values())
    if total > limit("mesh_triangles"):
        raise LimitError(path, "triangles", total, "mesh_triangles")
    for name, m in meshes.items():
        p = f"{path}.{name}"
        check_keys(m, p, required=("vertices", "faces"))
        V, F = m["vertices"], m["faces"]
        if not isinstance(V, list) or not V or not isinstance(F, list) or not F:
            fail(p, "vertices and faces must be non-empty lists")
        if len(V) > 3 * len(F) + 3:
            fail(f"{p}.vertices", f"{len(V)} vertices for {len(F)} triangles (unused vertices)")
        try:
            va = np.asarray(V, dtype=np.float64)
            fa = np.asarray(F, dtype=np.int64)
        except (TypeError, ValueError, OverflowError):
            fail(p, "vertices must be [[x, y, z], ...] numbers and faces [[i, j, k], ...] integers")
        if va.shape != (len(V), 3) or not np.all(np.isfinite(va)) or np.abs(va).max() > MAX_COORD_M:
            fail(f"{p}.vertices", f"must be [[x, y, z], ...] finite, |x| <= {MAX_COORD_M:g} m")
        if fa.shape != (len(F), 3) or fa.min() < 0 or fa.max() >= len(V) or \
                not all(isinstance(i, int) and not isinstance(i, bool) for i in F[0]):
            fail(f"{p}.faces", f"must be [[i, j, k], ...] integer indices in [0, {len(V)})")
    return meshes


def scene_groups(scene: dict) -> dict:
    """Groups the scene *has*: {name: {"flicker": bool}}; a light group with no lights and a sky of zero
    luminance are left out."""
    have = {lt["group"] for lt in scene["lights"]}
    sky = scene["sky"]
    sky_on = sky["model"] == "sunsky" or sky["luminance_cd_m2"] > 0
    out = {}
    for name in GROUPS:
        if name not in scene["groups"]:
            continue
        if (name == "skymap" and sky_on) or name in have:
            out[name] = dict(scene["groups"][name])
    return out


# -------------------------------------------------------------------------------------------------- I/O
def load_scene(path: str | os.PathLike) -> dict:
    """Read and validate a scene JSON file; errors name the file."""
    from lfmbench.fileio import load_json_input  # noqa: PLC0415

    scene = load_json_input(path, "scene file")
    try:
        return validate_scene(scene)
    except ValueError as exc:
        raise ValueError(f"scene file {path}: {exc}") from exc


def save_scene(scene: dict, path: str | os.PathLike) -> None:
    """Validate and write ``scene`` as JSON atomically (temp file in the same directory, then ``os.replace``)."""
    validate_scene(scene)
    atomic_write_json(path, scene)


def empty_scene(scene_id: str = "empty", short_exposure_s: float = 0.004, speed_mps: float = 0.0,
                yaw_rate_rad_s: float = 0.0, position_m=(0.0, 0.0, 1.4), pitch_deg: float = 0.0,
                fov_x_deg: float = 40.0, sky_luminance_cd_m2: float = 0.0) -> dict:
    """A valid scene with no objects, no lights and a constant (CIE D65) sky of the given luminance: a start
    for hand-made scenes and tests; append to ``objects``, ``lights`` and ``materials``."""
    scene = {"format": SCENE_FORMAT, "version": SCENE_VERSION, "scene_id": scene_id, "seed": 0,
             "time_of_day": "night", "timing": {"short_exposure_s": float(short_exposure_s)},
             "camera": {"position_m": [float(v) for v in position_m], "yaw_deg": 0.0, "pitch_deg": float(pitch_deg),
                        "fov_x_deg": float(fov_x_deg), "speed_mps": float(speed_mps),
                        "yaw_rate_rad_s": float(yaw_rate_rad_s)},
             "sky": {"model": "constant", "spectrum": {"model": "illuminant", "name": "D65"},
                     "luminance_cd_m2": float(sky_luminance_cd_m2)},
             "groups": {g: {"flicker": g in ("otherlights", "signals")} for g in GROUPS},
             "materials": {}, "objects": [], "lights": []}
    return validate_scene(scene)
