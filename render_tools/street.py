"""Street content of scene generator 2 (protocol lfmbench-v2): the steps :func:`render_tools.scene.generate_scene`
runs after the traffic signal when ``generator=2``, each drawing from the scene's one random generator, in the
order of :func:`add_street`.

- :func:`add_weather`: the road surface of ``weather.conditions`` (dry, wet, rain): a wet road is a rough
  dielectric water film (index ``water_ior``) over a darker diffuse asphalt (Mitsuba ``roughplastic``), with
  puddles (smoother film, irregular flat meshes) so that lamps reflect in it.
- :func:`add_textures` (last): seeded procedural albedo textures on asphalt, lane paint, sidewalks, facades, vehicle
  paint, bark and foliage (:mod:`render_tools.textures`; generated at render time from a few numbers).

The steps take the :class:`render_tools.scene.SceneBuilder` (``b``) and the :class:`render_tools.scene.Road`
(``road``) of the scene; lengths in metres, speeds in m/s, world frame as :mod:`render_tools.scene`.
"""
from __future__ import annotations

import math

import numpy as np

from . import shapes
from .scene_templates import (VEHICLE_BODIES, VEHICLE_TEMPLATES, box, cylinder, gait, local_offset, person_parts,
                              rect, two_wheeler_parts)

__all__ = ["add_street", "add_weather", "add_textures", "vehicle_parts", "person_materials", "WET_ROAD_MATERIAL", "PUDDLE_MATERIAL",
           "STREET_MATERIALS"]

#: Material names of the wet road film and of the puddles.
WET_ROAD_MATERIAL = "asphalt_wet"
PUDDLE_MATERIAL = "puddle"
#: Corners of a puddle outline (an irregular star-shaped polygon).
PUDDLE_CORNERS = 14
#: Materials generator 2 adds when a step needs them (rgb reflectance in [0, 1]).
STREET_MATERIALS = {
    "chassis": {"type": "diffuse", "rgb": [0.04, 0.04, 0.04]},
    "bark": {"type": "diffuse", "rgb": [0.16, 0.11, 0.07]},
    "foliage": {"type": "diffuse", "rgb": [0.07, 0.16, 0.05]},
    "foliage_dark": {"type": "diffuse", "rgb": [0.05, 0.11, 0.04]},
    "sign_red": {"type": "roughplastic", "rgb": [0.6, 0.05, 0.04], "alpha": 0.2},
    "sign_blue": {"type": "roughplastic", "rgb": [0.04, 0.15, 0.55], "alpha": 0.2},
    "sign_white": {"type": "roughplastic", "rgb": [0.8, 0.8, 0.78], "alpha": 0.2},
    "wood": {"type": "diffuse", "rgb": [0.3, 0.19, 0.1]},
    "helmet": {"type": "roughplastic", "rgb": [0.7, 0.7, 0.68], "alpha": 0.1},
}
#: Clothing and skin colours of people (drawn per person from these; a palette, so that people wearing one colour
#: share one material and a scene's material count stays bounded).
CLOTHES = ([0.05, 0.05, 0.06], [0.12, 0.14, 0.3], [0.45, 0.08, 0.07], [0.5, 0.48, 0.42], [0.1, 0.25, 0.12],
           [0.65, 0.55, 0.2], [0.2, 0.2, 0.22], [0.6, 0.6, 0.62], [0.08, 0.1, 0.16], [0.7, 0.25, 0.35],
           [0.25, 0.45, 0.6], [0.35, 0.22, 0.12], [0.75, 0.7, 0.6], [0.15, 0.3, 0.3], [0.55, 0.3, 0.08],
           [0.3, 0.12, 0.35])
SKIN = ([0.55, 0.38, 0.3], [0.4, 0.26, 0.18], [0.2, 0.13, 0.09])


def _material(b, name: str) -> str:
    """The name of material ``name`` of :data:`STREET_MATERIALS`, added to the scene the first time it is used."""
    if name not in b.materials:
        b.materials[name] = dict(STREET_MATERIALS[name])
    return name


def _mesh(b, name: str, build) -> str:
    """The scene mesh ``name``, built by ``build()`` the first time a scene needs it."""
    if name not in b.meshes:
        b.meshes[name] = build()
    return name


def person_materials(b) -> dict:
    """A person's materials {"top", "legs", "skin", "helmet"}: colours drawn from :data:`CLOTHES` and :data:`SKIN`,
    each a scene material shared by everyone wearing it."""
    rng = b.rng
    out = {}
    for role, table, prefix in (("top", CLOTHES, "cloth"), ("legs", CLOTHES, "cloth"), ("skin", SKIN, "skin")):
        k = int(rng.integers(0, len(table)))
        name = f"{prefix}{k}"
        if name not in b.materials:
            b.materials[name] = {"type": "diffuse", "rgb": list(table[k])}
        out[role] = name
    out["helmet"] = _material(b, "helmet")
    return out


def vehicle_parts(b, kind: str, x: float, y: float, heading: float, roles: dict) -> list:
    """Generator 2's parts of a vehicle of ``kind`` at (x, y) m, heading (rad): a lofted body (paint and glass
    meshes shared by the kind, :data:`render_tools.scene_templates.VEHICLE_BODIES`) with its extra boxes and panes,
    wheels with hubs; motorcycles and bicycles as rigs with a rider. ``roles``: material role -> material name."""
    deg = math.degrees(heading)
    if kind in ("motorcycle", "bicycle"):
        if kind == "motorcycle":
            _body_meshes(b, kind)
        t = VEHICLE_TEMPLATES[kind]
        r = t["wheels"][0][1]
        _mesh(b, f"wheel_{kind}", lambda: shapes.ring_mesh(r - (0.06 if kind == "motorcycle" else 0.025),
                                                             0.06 if kind == "motorcycle" else 0.025))
        _material(b, "helmet")
        return two_wheeler_parts(kind, x, y, heading, roles, person_materials(b), b.u((0.0, 2 * math.pi)))
    names = _body_meshes(b, kind)
    body = VEHICLE_BODIES[kind]
    parts = [{"shape": "mesh", "mesh": names[k], "center": [x, y, 0.0], "yaw_deg": deg,
              "material": roles["paint"] if k == "paint" else "glass"} for k in sorted(names)]
    for (cx, cy, cz), size, role in body["boxes"]:
        dx, dy = local_offset(cx, cy, heading)
        parts.append(box((x + dx, y + dy, cz), size, _material(b, "chassis") if role == "chassis" else roles[role],
                         deg))
    for (cx, cy, cz), size, sgn in body.get("panes", []):
        dx, dy = local_offset(cx, cy, heading)
        parts.append(rect((x + dx, y + dy, cz), size, (sgn * math.cos(heading), sgn * math.sin(heading), 0.0),
                          "glass"))
    t = VEHICLE_TEMPLATES[kind]
    for wx, r, wy in t["wheels"]:
        for side in (1, -1):
            yy = side * wy
            a0, b0 = local_offset(wx, yy - t["wheel_w"] / 2, heading)
            a1, b1 = local_offset(wx, yy + t["wheel_w"] / 2, heading)
            parts.append(cylinder((x + a0, y + b0, r), (x + a1, y + b1, r), r, "rubber"))
            h0, g0 = local_offset(wx, yy + side * (t["wheel_w"] / 2 - 0.02), heading)
            h1, g1 = local_offset(wx, yy + side * (t["wheel_w"] / 2 + 0.01), heading)
            parts.append(cylinder((x + h0, y + g0, r), (x + h1, y + g1, r), 0.6 * r, "metal"))
    return parts


def _body_meshes(b, kind: str) -> dict:
    """Names of the kind's body meshes {"paint": name, "glass": name} (built once per scene)."""
    body = VEHICLE_BODIES[kind]
    key = f"body_{kind}_paint"
    if key not in b.meshes:
        m = shapes.body_meshes(body["stations"], body["width"], body["roof_inset"])
        for k, entry in m.items():
            b.meshes[f"body_{kind}_{k}"] = entry
    return {k: f"body_{kind}_{k}" for k in ("paint", "glass") if f"body_{kind}_{k}" in b.meshes}


def add_street(b, road, cam_y: float, dark: bool) -> str:
    """All steps of generator 2, in order; returns the scene's weather (``scene.weather``)."""
    weather = add_weather(b, road)
    add_trees(b, road)
    add_furniture(b, road)
    add_people(b, road, dark)
    add_textures(b, road)
    return weather


#: Length of the road's asphalt tile along the road, m (the tile spans the road's width).
ASPHALT_TILE_M = 6.0
#: Object kinds whose ``paint*`` materials get the ``paint`` texture.
PAINTED_KINDS = ("car", "van", "truck", "bus", "motorcycle", "bicycle", "cyclist")


def add_textures(b, road) -> None:
    """Procedural albedo textures (:mod:`render_tools.textures`) on the materials already in the scene: asphalt
    (dry and wet base), lane paint, paving slabs of the sidewalks, each building's facade (its windows where its
    glass panes are), vehicle paint, bark and foliage. The texture seeds come from a child generator spawned from
    the scene's (``numpy.random.Generator.spawn``: a new stream from the seed sequence), which leaves the scene's own
    random stream where it was, so every later step draws what it drew without textures."""
    rng = b.rng.spawn(1)[0]
    mats = b.materials
    half = road.half_width_m

    def put(name: str, tex: dict) -> None:
        if name in mats and mats[name]["type"] in ("diffuse", "roughplastic"):
            mats[name]["texture"] = {"kind": tex.pop("kind"), "seed": int(rng.integers(0, 2 ** 31)), **tex}

    road_tex = {"size_m": [ASPHALT_TILE_M, round(2 * half, 4)], "origin_m": [0.0, round(-half, 4), 0.0],
                "lanes": int(road.lanes), "lane_width_m": float(road.lane_width_m)}
    put("asphalt", {"kind": "asphalt", **road_tex})
    put(WET_ROAD_MATERIAL, {"kind": "asphalt", **road_tex})
    put("marking", {"kind": "marking", "size_m": [4.0, 0.5]})
    put("concrete", {"kind": "paving", "size_m": [3.6, 3.6], "slab_m": 0.6})
    for o in b.objects:
        if o["kind"] != "building":
            continue
        wall = o["parts"][0]
        (cx, cy, _), (w, d, h) = wall["center"], wall["size"]
        panes = [p for p in o["parts"][1:] if p["shape"] == "rect" and p["material"] == "glass"]
        zs = sorted({round(p["center"][2], 4) for p in panes})
        bays = max(1, len(panes) // max(len(zs), 1))
        win = panes[0]["size"] if panes else [1.0, 1.5]
        z0 = (zs[0] if zs else 1.8) - win[1] / 2
        put(wall["material"], {"kind": "facade", "size_m": [round(w, 4), round(h, 4)],
                               "origin_m": [round(cx - w / 2, 4), round(cy - d / 2, 4), 0.0], "bays": bays,
                               "floors": max(len(zs), 1), "window_m": [round(float(win[0]), 4), round(float(win[1]), 4)],
                               "sill_z_m": round(z0, 4), "floor_m": round(zs[1] - zs[0], 4) if len(zs) > 1 else 3.2})
    painted = sorted({p["material"] for o in b.objects if o["kind"] in PAINTED_KINDS for p in o["parts"]
                      if p["material"].startswith("paint")})
    for name in painted:
        put(name, {"kind": "paint", "size_m": [4.0, 4.0]})
    put("bark", {"kind": "bark", "size_m": [0.4, 1.2]})
    put("foliage", {"kind": "foliage", "size_m": [1.6, 1.6]})
    put("foliage_dark", {"kind": "foliage", "size_m": [1.6, 1.6]})


def _clear(b, x: float, y: float, r: float) -> bool:
    """Whether no part centre of a pole, tree, vehicle or person lies within ``r`` m of (x, y) (a cheap test
    that keeps new objects out of the ones already placed)."""
    for o in b.objects:
        if o["kind"] in ("ground", "road", "marking", "sidewalk", "building"):
            continue
        for p in o["parts"][:3]:
            c = p.get("center") or p.get("p0")
            if c is not None and (c[0] - x) ** 2 + (c[1] - y) ** 2 < r * r:
                return False
    return True


def add_trees(b, road) -> None:
    """Trees along both sidewalks (``trees``): a bark trunk (two tapering tubes, a fork) and a lumpy crown (one of
    three crown meshes of the scene, scaled by ``crown_radius_m``), every ``spacing_m`` along the outer third of the
    sidewalk, where nothing stands."""
    tc = b.cfg["trees"]
    rng = b.rng
    crowns = [_mesh(b, f"crown{k}", lambda: shapes.crown_mesh(rng)) for k in range(3)]
    _material(b, "bark")
    for side in (1, -1):
        xx = road.x0_m + b.u((0.0, 10.0))
        while xx < 160.0:
            y = side * (road.half_width_m + road.sidewalk_m * b.u((0.6, 0.8)))
            h, cr = b.u(tc["height_m"]), b.u(tc["crown_radius_m"])
            if _clear(b, xx, y, 1.5):
                trunk_top = max(h - 1.6 * cr, 1.8)
                lean = rng.uniform(-0.3, 0.3, 2)
                top = (xx + lean[0], y + lean[1], trunk_top)
                parts = [cylinder((xx, y, 0.0), top, 0.09 + 0.02 * h / 5, "bark"),
                         cylinder(top, (top[0] - 0.6 * lean[1] + 0.4, top[1] + 0.5 * side * 0.3, trunk_top + 0.9 * cr),
                                  0.06, "bark"),
                         {"shape": "mesh", "mesh": crowns[int(rng.integers(0, 3))],
                          "center": [round(top[0], 3), round(top[1], 3), round(trunk_top + 0.85 * cr, 3)],
                          "yaw_deg": round(b.u((0.0, 360.0)), 1),
                          "scale": [round(cr, 3), round(cr * b.u((0.85, 1.15)), 3), round(cr * b.u((0.9, 1.25)), 3)],
                          "material": _material(b, "foliage" if rng.random() < 0.6 else "foliage_dark")}]
                b.obj("tree", parts)
            xx += b.u(tc["spacing_m"])


def add_furniture(b, road) -> None:
    """Road furniture (``furniture``): bollards at the kerb near the camera, traffic signs on posts facing the
    traffic of their side (a red-rimmed round sign or a blue square one), benches on the sidewalks."""
    fc = b.cfg["furniture"]
    rng = b.rng
    half = road.half_width_m
    for side in (1, -1):
        x0 = b.u((3.0, 20.0))
        parts = []
        for k in range(b.ui(fc["bollards"])):
            x, y = x0 + 1.6 * k, side * (half + 0.35)
            if _clear(b, x, y, 0.6):
                parts += [cylinder((x, y, 0.0), (x, y, 0.95), 0.08, "metal"),
                          cylinder((x, y, 0.75), (x, y, 0.82), 0.085, _material(b, "sign_white"))]
        if parts:
            b.obj("bollard", parts)
    for _ in range(b.ui(fc["signs"])):
        side = 1 if rng.random() < 0.5 else -1
        x, y = b.u((8.0, 110.0)), side * (half + 0.45)
        if not _clear(b, x, y, 1.0):
            continue
        n = (1.0, 0.0, 0.0) if side > 0 else (-1.0, 0.0, 0.0)  # facing the traffic of its side
        z = 2.3
        parts = [cylinder((x, y, 0.0), (x, y, z + 0.35), 0.035, "metal")]
        if rng.random() < 0.6:
            parts += [{"shape": "disk", "center": [x + 0.02 * n[0], y, z], "radius": 0.35, "normal": list(n),
                       "material": _material(b, "sign_red")},
                      {"shape": "disk", "center": [x + 0.025 * n[0], y, z], "radius": 0.27, "normal": list(n),
                       "material": _material(b, "sign_white")}]
        else:
            parts.append(rect((x + 0.02 * n[0], y, z), (0.6, 0.6), n, _material(b, "sign_blue")))
        parts.append(rect((x - 0.005 * n[0], y, z), (0.7, 0.7), (-n[0], 0.0, 0.0), "metal"))
        b.obj("traffic_sign", parts)
    for _ in range(b.ui(fc["benches"])):
        side = 1 if rng.random() < 0.5 else -1
        x, y = b.u((5.0, 90.0)), side * (half + road.sidewalk_m * 0.5)
        if not _clear(b, x, y, 1.5):
            continue
        wood = _material(b, "wood")
        parts = [box((x, y, 0.45), (1.8, 0.45, 0.05), wood), box((x, y + side * 0.22, 0.75), (1.8, 0.05, 0.4), wood)]
        for dx in (-0.8, 0.8):
            parts.append(box((x + dx, y, 0.22), (0.06, 0.4, 0.44), "metal"))
        b.obj("bench", parts)


def add_people(b, road, dark: bool) -> None:
    """People (``people``): pedestrians walking along both sidewalks (either way, at ``walk_speed_mps``) and
    cyclists riding at the right edge of the ego lanes (at ``cycle_speed_mps``), each cyclist with a rear LED
    (a ``tail`` light, otherlights) lit after dark."""
    pc = b.cfg["people"]
    rng = b.rng
    half, sw = road.half_width_m, road.sidewalk_m
    _mesh(b, "torso", shapes.torso_mesh)
    for _ in range(b.ui(pc["pedestrians"])):
        side = 1 if rng.random() < 0.5 else -1
        x, y = b.u((4.0, 70.0)), side * (half + b.u((0.5, max(sw - 0.6, 0.6))))
        if not _clear(b, x, y, 0.8):
            continue
        heading = 0.0 if rng.random() < 0.5 else math.pi
        v = b.u(pc["walk_speed_mps"])
        h, phase, mats = b.u(pc["height_m"]), b.u((0.0, 2 * math.pi)), person_materials(b)
        oid = b.obj("pedestrian", person_parts(x, y, heading, h, phase, mats),
                    (v * math.cos(heading), v * math.sin(heading), 0.0))
        b.objects[oid]["gait"] = gait(x, y, heading, h, phase, mats, v)  # the pose changes with time (walk cycle)
    lane_edge = road.lanes * road.lane_width_m
    for _ in range(b.ui(pc["cyclists"])):
        x, y = b.u((10.0, 80.0)), -(lane_edge - 0.6)
        if not _clear(b, x, y, 3.5):
            continue
        v = b.u(pc["cycle_speed_mps"])
        _mesh(b, "wheel_bicycle", lambda: shapes.ring_mesh(VEHICLE_TEMPLATES["bicycle"]["wheels"][0][1] - 0.025, 0.025))
        roles = {"paint": _paint(b)}
        parts = two_wheeler_parts("bicycle", x, y, 0.0, roles, person_materials(b), b.u((0.0, 2 * math.pi)))
        oid = b.obj("cyclist", parts, (v, 0.0, 0.0))
        if dark:
            (lx, ly, lz), (w, h) = VEHICLE_TEMPLATES["bicycle"]["tail"][0]
            lc = b.cfg["lights"]
            b.light("tail", oid, {"shape": "rect", "center": [x + lx, y + ly, lz], "normal": [-1.0, 0.0, 0.0],
                                  "size": [w, h]}, lc["led_red"], b.other_luminance(), lc["tail_spread_deg"])


def _paint(b) -> str:
    """A new drawn frame colour (roughplastic) for a cyclist's bicycle."""
    name = f"paint{len(b.objects)}"
    b.materials[name] = {"type": "roughplastic", "rgb": [round(float(c), 4) for c in b.rng.uniform(0.05, 0.75, 3)],
                         "alpha": 0.15}
    return name


def _puddle_mesh(rng: np.random.Generator) -> dict:
    """A flat, irregular, unit-size puddle outline (star-shaped, radius 0.5 +- 0.15) as a triangle fan in the
    plane z = 0, facing +z: ``{"vertices": (n + 1, 3) m, "faces": (n, 3)}``."""
    ang = 2 * math.pi * (np.arange(PUDDLE_CORNERS) + rng.uniform(-0.3, 0.3, PUDDLE_CORNERS)) / PUDDLE_CORNERS
    r = 0.5 * (1.0 + rng.uniform(-0.3, 0.3, PUDDLE_CORNERS))
    V = [[0.0, 0.0, 0.0]] + [[round(float(ri * math.cos(a)), 4), round(float(ri * math.sin(a)), 4), 0.0]
                             for ri, a in zip(r, ang)]
    F = [[0, 1 + i, 1 + (i + 1) % PUDDLE_CORNERS] for i in range(PUDDLE_CORNERS)]
    return {"vertices": V, "faces": F}


def add_weather(b, road) -> str:
    """The weather of the scene, drawn from ``weather.conditions``; for ``wet`` and ``rain`` the road's asphalt
    becomes :data:`WET_ROAD_MATERIAL` and puddles (``weather.puddles`` of the condition, ``puddle_size_m`` across,
    on the road ahead) are added to the road object. Returns the condition."""
    wc = b.cfg["weather"]
    rng = b.rng
    cond = wc["conditions"][int(rng.integers(0, len(wc["conditions"])))]
    if cond == "dry":
        return cond
    alpha = b.u(wc["rain_alpha"] if cond == "rain" else wc["wet_alpha"])
    b.materials[WET_ROAD_MATERIAL] = {"type": "roughplastic", "rgb": [float(c) for c in wc["wet_rgb"]],
                                      "alpha": round(alpha, 4), "ior": float(wc["water_ior"])}
    b.materials[PUDDLE_MATERIAL] = {"type": "roughplastic", "rgb": [float(c) for c in wc["wet_rgb"]],
                                    "alpha": float(wc["puddle_alpha"]), "ior": float(wc["water_ior"])}
    road_obj = next(o for o in b.objects if o["kind"] == "road")
    for part in road_obj["parts"]:
        if part["material"] == "asphalt":
            part["material"] = WET_ROAD_MATERIAL
    shapes = [f"puddle{k}" for k in range(3)]
    for name in shapes:
        b.meshes[name] = _puddle_mesh(rng)
    half = road.half_width_m - road.park_m
    for _ in range(b.ui(wc["puddles"][cond])):
        size = b.u(wc["puddle_size_m"])
        road_obj["parts"].append({"shape": "mesh", "mesh": shapes[int(rng.integers(0, len(shapes)))],
                                  "center": [round(b.u((2.0, 120.0)), 3), round(b.u((-half, half)), 3), 0.002],
                                  "yaw_deg": round(b.u((0.0, 180.0)), 2),
                                  "scale": [round(size, 3), round(size * b.u((0.4, 0.9)), 3), 1.0],
                                  "material": PUDDLE_MATERIAL})
    return cond
