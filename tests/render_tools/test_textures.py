"""Scene generator 2's looks (issue 40): seeded procedural textures, walkers posed at render time, the light bar on
the roof; generator 1 untouched (its scene hashes: tests/render_tools/test_scene_v2.py)."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from render_tools import mitsuba_scene as ms
from render_tools import scene as S
from render_tools import scene_templates as T
from render_tools import textures as X
from render_tools.scene_schema import empty_scene, validate_scene


@pytest.fixture(scope="module")
def v2_day():
    return S.generate_scene(7, "day", generator=2)


def _lum(a: np.ndarray) -> np.ndarray:
    return a @ np.array([0.2126, 0.7152, 0.0722])


def test_texture_is_a_function_of_its_seed(v2_day):
    m = v2_day["materials"]["asphalt"]
    a = X.texture_array(m["texture"], m["rgb"])
    b = X.texture_array(copy.deepcopy(m["texture"]), list(m["rgb"]))
    c = X.texture_array(dict(m["texture"], seed=m["texture"]["seed"] + 1), m["rgb"])
    assert a.dtype == np.float32 and a.shape == X.RESOLUTION["asphalt"] + (3,)
    np.testing.assert_array_equal(a, b)
    assert np.mean(np.abs(a - c)) > 0.1 * float(a.mean())


def test_textures_on_every_surface_kind_and_not_flat(v2_day):
    mats = v2_day["materials"]
    kinds = {m["texture"]["kind"] for m in mats.values() if "texture" in m}
    assert {"asphalt", "marking", "paving", "facade", "paint", "bark", "foliage"} <= kinds
    facades = [m for n, m in mats.items() if n.startswith("building")]
    assert facades and all("texture" in m for m in facades)
    for m in facades[:3] + [mats["asphalt"]]:
        L = _lum(X.texture_array(m["texture"], m["rgb"]).astype(np.float64))
        assert L.std() / L.mean() > 0.15, m["texture"]["kind"]  # a flat colour has 0
        assert L.max() <= X.ALBEDO_MAX
    # windows sit where the building's glass panes are: the texels under an upper-floor pane are the colour of
    # the frame just outside it
    o = next(o for o in v2_day["objects"] if o["kind"] == "building")
    tex = v2_day["materials"][o["parts"][0]["material"]]["texture"]
    arr = X.texture_array(tex, v2_day["materials"][o["parts"][0]["material"]]["rgb"])
    pane = max((p for p in o["parts"][1:] if p["material"] == "glass"), key=lambda p: p["center"][2])
    H, W = X.RESOLUTION["facade"]
    u = (pane["center"][0] - tex["origin_m"][0]) / tex["size_m"][0]
    v = pane["center"][2] / tex["size_m"][1]
    ring_u = (pane["center"][0] + pane["size"][0] / 2 + 0.04 - tex["origin_m"][0]) / tex["size_m"][0]
    np.testing.assert_allclose(arr[int(v * H), int(u * W)], arr[int(v * H), int(ring_u * W)], atol=1e-6)


def test_v1_scenes_have_no_textures_and_refuse_them():
    sc = S.generate_scene(7, "night", generator=1)
    assert not any("texture" in m for m in sc["materials"].values())
    assert not any("gait" in o for o in sc["objects"])
    sc["materials"]["asphalt"]["texture"] = {"kind": "asphalt", "seed": 1, "size_m": [6.0, 10.0]}
    with pytest.raises(ValueError, match=r"scene.materials.asphalt.texture"):
        validate_scene(sc)


@pytest.mark.parametrize("bad,field", [({"kind": "marble"}, "kind"), ({"seed": -1}, "seed"),
                                       ({"size_m": [0.0, 1.0]}, "size_m"), ({"origin_m": [1, 2]}, "origin_m")])
def test_bad_texture_named(v2_day, bad, field):
    sc = copy.deepcopy(v2_day)
    sc["materials"]["asphalt"]["texture"].update(bad)
    with pytest.raises(ValueError, match=rf"scene.materials.asphalt.texture.{field}"):
        validate_scene(sc)


def test_box_uv_mesh_sanity():
    part = {"shape": "box", "center": [5.0, 0.0, -0.05], "size": [10.0, 8.0, 0.1], "material": "asphalt"}
    V, F = ms.part_mesh(part)
    tex = {"kind": "asphalt", "seed": 3, "size_m": [6.0, 8.0], "origin_m": [0.0, -4.0, 0.0]}
    Vu, Fu, UV = X.box_uv(V, F, tex)
    assert Fu.shape == F.shape and Vu.shape == (3 * len(F), 3) and UV.shape == (3 * len(F), 2)
    np.testing.assert_array_equal(Vu[Fu], V[F])  # same triangles, same winding
    assert np.isfinite(UV).all()
    top = np.repeat((np.abs(Vu[Fu][:, :, 2]) < 1e-9).all(1), 3)  # the vertices of the faces of the top (z = 0)
    assert top.sum() == 6
    np.testing.assert_allclose(UV[top], np.stack([Vu[top, 0] / 6.0, (Vu[top, 1] + 4.0) / 8.0], 1))
    area = lambda V, F: 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()  # noqa: E731
    assert area(Vu, Fu) == pytest.approx(area(V, F))


def test_mitsuba_hit_reads_the_box_projected_uv():
    """Independent check of the whole texture path: Mitsuba's own ray intersection on the mesh that
    mitsuba_dict builds returns the texture coordinate (x - ox) / su, (y - oy) / sv of the hit point."""
    from render_tools import backend

    backend.select_variant()
    import drjit as dr
    import mitsuba as mi

    sc = empty_scene()
    sc["version"] = 2
    sc["materials"]["asphalt"] = {"type": "diffuse", "rgb": [0.1, 0.1, 0.1],
                                  "texture": {"kind": "asphalt", "seed": 5, "size_m": [6.0, 8.0],
                                              "origin_m": [0.0, -4.0, 0.0]}}
    sc["objects"].append({"id": 0, "kind": "road", "velocity_mps": [0.0, 0.0, 0.0],
                          "parts": [{"shape": "box", "center": [10.0, 0.0, -0.05], "size": [20.0, 8.0, 0.1],
                                     "material": "asphalt"}]})
    sc = validate_scene(sc)
    loaded = mi.load_dict(ms.mitsuba_dict(sc, 0.0, emit=None))
    x, y = 9.3, 1.1
    ray = mi.Ray3f(mi.Point3f(x, y, 2.0), mi.Vector3f(0.0, 0.0, -1.0))
    si = loaded.ray_intersect(ray)
    uv = np.array([dr.slice(si.uv.x), dr.slice(si.uv.y)], dtype=float).ravel()
    np.testing.assert_allclose(uv, [x / 6.0, (y + 4.0) / 8.0], atol=1e-4)
    bsdf = si.bsdf(ray)
    assert "BitmapTexture" in str(bsdf)


def test_walk_cycle_changes_with_time_and_repeats(v2_day):
    walkers = [o for o in v2_day["objects"] if "gait" in o]
    assert walkers and all(o["kind"] == "pedestrian" for o in walkers)
    o = walkers[0]
    g = o["gait"]
    # a stride (two steps, 2 * 0.47 h * sin 0.45 each) per cycle at the walking speed: feet do not slide
    speed = math.hypot(*o["velocity_mps"][:2])
    assert g["cycle_hz"] == pytest.approx(speed / (4 * 0.47 * g["height_m"] * math.sin(0.45)), rel=1e-9)
    mesh = lambda t: ms._object_meshes(o, np.zeros(3), v2_day["meshes"], v2_day["materials"], t)  # noqa: E731
    at0, later = mesh(0.0), mesh(0.25 / g["cycle_hz"])
    period = mesh(1.0 / g["cycle_hz"])
    assert [m[0] for m in at0] == [m[0] for m in later]  # same materials, same mesh sizes: only the pose moves
    moved = max(np.abs(a[1] - b[1]).max() for a, b in zip(at0, later))
    assert moved > 0.1  # a quarter cycle swings a foot by tens of cm
    for a, b in zip(at0, period):
        np.testing.assert_allclose(a[1], b[1], atol=1e-6)
    assert T.posed_parts(o, 0.0) == o["parts"]  # the stored parts are the pose at t = 0


@pytest.mark.parametrize("kind", ["car", "van"])
def test_light_bar_rests_on_the_roof(kind):
    cfg = S.load_config(generator=2)
    cfg["lamps"]["emergency_probability"] = 1.0
    b = S.SceneBuilder(np.random.default_rng(3), cfg, "night", generator=2)
    S.add_vehicle(b, kind, 20.0, -1.75, 0.3, 10.0, lights_on=True, braking=False, indicator=False)
    sc = {"objects": b.objects, "lights": b.lights}
    strobes = [lt for lt in sc["lights"] if lt["kind"] == "strobe"]
    assert len(strobes) == 4
    obj = sc["objects"][strobes[0]["instance"]]
    housing = obj["parts"][-1]
    assert housing["material"] == "housing"
    _, roof = T.roof_mount(obj["kind"], housing["size"][0])
    bottom = housing["center"][2] - housing["size"][2] / 2
    # the roof under the housing (the loft's z_top at its two ends, independent of roof_mount's choice)
    heading = math.radians(housing["yaw_deg"])
    body = next(p for p in obj["parts"] if p.get("mesh", "").startswith("body_"))
    along = ((housing["center"][0] - body["center"][0]) * math.cos(heading)
             + (housing["center"][1] - body["center"][1]) * math.sin(heading))
    under = max(T.roof_z(obj["kind"], along + s * housing["size"][0] / 2) for s in (-1, 1))
    assert bottom == pytest.approx(roof) and 0.0 <= bottom - under < 0.01
    for lt in strobes:
        z = ms.plane_corners(lt)[:, 2]
        assert bottom <= z.min() < bottom + 0.01 and z.max() <= bottom + housing["size"][2]


def test_textures_leave_the_rest_of_the_scene_as_it_was(v2_day, monkeypatch):
    """The texture seeds come from a spawned generator: without the texture step the scene (displays, camera and
    exposure drawn after the street included) is the same but for the materials' ``texture`` entries."""
    from render_tools import street

    monkeypatch.setattr(street, "add_textures", lambda b, road: None)
    bare = S.generate_scene(7, "day", generator=2)
    stripped = copy.deepcopy(v2_day)
    for m in stripped["materials"].values():
        m.pop("texture", None)
    assert stripped == bare
