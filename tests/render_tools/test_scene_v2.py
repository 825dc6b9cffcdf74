"""Scene generator 2 and protocol lfmbench-v2 (issue 23): generator 1 (lfmbench-v1) keeps generating the scenes
it always did (hashes frozen from main before generator 2 existed), generator 2's scenes are scene version 2
with their pinned weather, and the scene file's new fields are checked with one clear error each."""
from __future__ import annotations

import copy
import hashlib
import json

import numpy as np
import pytest

from lfmbench.limits import set_limit
from render_tools import protocol as P
from render_tools import scene as S
from render_tools import street

#: SHA-256 (first 16 hex digits) of canonical scene JSON (floats to 9 significant digits: portable across CPUs
#: and libm builds), computed on main at 3b10a67, before generator 2 existed.
V1_PROTOCOL_HASHES = (("train_000", "2a6a3f80b9b5090b"), ("train_004", "84b5855b1e576a7a"),
                      ("val_04", "45d249ae1f3d48ae"), ("test_00", "44b378800f5f4ef2"),
                      ("test_17", "8f62c7cb7e7081e2"), ("test_47", "e4ef7b124069bd44"))
V1_PLAIN_HASHES = ((0, "day", "e154d1c728d7f146"), (7, "night", "61dbd1046cc426e7"))


def _canon(x):
    if isinstance(x, float):
        return float(f"{x:.9g}")
    if isinstance(x, list):
        return [_canon(v) for v in x]
    if isinstance(x, dict):
        return {k: _canon(v) for k, v in x.items()}
    return x


def scene_hash(scene: dict) -> str:
    return hashlib.sha256(json.dumps(_canon(scene), sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:16]


@pytest.fixture(scope="module")
def v1():
    return P.load_protocol("lfmbench-v1")


@pytest.mark.parametrize("sid,want", V1_PROTOCOL_HASHES)
def test_v1_protocol_scenes_unchanged(v1, sid, want):
    ps = next(s for s in v1.scenes if s.scene_id == sid)
    assert "generator" not in ps.scene_kw()  # what v1 corpora recorded as scene_kw stays the same
    assert scene_hash(S.generate_scene(ps.seed, scene_id=ps.scene_id, **ps.scene_kw())) == want


@pytest.mark.parametrize("seed,tod,want", V1_PLAIN_HASHES)
def test_v1_plain_scenes_unchanged(seed, tod, want):
    assert scene_hash(S.generate_scene(seed, time_of_day=tod)) == want
    assert scene_hash(S.generate_scene(seed, time_of_day=tod, generator=1)) == want


def _typed(x):
    """``x`` with every leaf as (type name, repr): 1, 1.0 and True, or 0.0 and -0.0, do not pass for each other."""
    if isinstance(x, dict):
        return {(type(k).__name__, k): _typed(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_typed(v) for v in x]
    return type(x).__name__, repr(x)


def test_plain_json_is_the_json_round_trip():
    """scene_schema.plain_json (generate_scene's last step) gives what json.loads(json.dumps(x)) gives, to the type
    and bit of every value, in new containers; what it does not handle takes the round trip, result or error."""
    from render_tools.scene_schema import plain_json

    obj = {"a": (1, 2.5, np.float64(0.1) + np.float64(0.2), True, None, "s"), "b": [[np.float64(-0.0), 1e308, -3]],
           "c": {"d": (), "e": [{"f": float("inf"), "g": False}]}, "h": list(np.random.default_rng(0).random(4))}
    assert _typed(plain_json(obj)) == _typed(json.loads(json.dumps(obj)))
    sc = S.generate_scene(3, "night", generator=2)
    out = plain_json(sc)
    assert _typed(out) == _typed(json.loads(json.dumps(sc))) and out["objects"][0] is not sc["objects"][0]
    assert _typed(plain_json({1: (2.0,)})) == _typed({"1": [2.0]})  # a key that is not a str: JSON's answer
    with pytest.raises(TypeError, match="float32"):
        plain_json({"x": [np.float32(1.0)]})  # and JSON's error


def test_v2_protocols_use_generator_2():
    for name in ("lfmbench-v2", "lfmbench-v2-mini"):
        p = P.load_protocol(name)
        assert p.generator == 2 and all(s.generator == 2 and s.weather in ("dry", "wet", "rain") for s in p.scenes)
        cov = P.coverage(p, "test")
        assert all(n >= 3 for n in cov["weather"].values()), cov
        assert all(cov["vehicle_kinds"][k] >= 3 for k in ("van", "bus", "bicycle")), cov
        assert all(s.scene_kw()["generator"] == 2 for s in p.scenes)
    v2, mini = P.load_protocol("lfmbench-v2"), P.load_protocol("lfmbench-v2-mini")
    for split in P.SPLITS:
        a = [s for s in v2.scenes if s.split == split]
        b = [s for s in mini.scenes if s.split == split]
        assert b == a[:len(b)]


def test_v2_pinned_conditions_hold():
    """Every 4th test scene of lfmbench-v2-mini: its generated scene meets its pinned conditions, weather too."""
    p = P.load_protocol("lfmbench-v2-mini")
    cfg = S.load_config(generator=2)
    for ps in [s for s in p.scenes if s.split == "test"][::4]:
        sc = S.generate_scene(ps.seed, scene_id=ps.scene_id, **ps.scene_kw())
        assert sc["version"] == 2 and sc["weather"] == ps.weather
        assert P.check_scene(sc, ps, cfg) == []
        wrong = copy.deepcopy(sc)
        wrong["weather"] = "dry" if ps.weather != "dry" else "wet"
        assert any("weather" in b for b in P.check_scene(wrong, ps, cfg))


def test_weather_road_surface():
    """A dry scene has no water film, puddles or meshes it does not need; wet and rain lay the film (a rough
    dielectric of water's index over the asphalt) and puddles on the road."""
    scenes = {w: S.generate_scene(11, "night", generator=2, overrides={"weather": {"conditions": [w]}})
              for w in ("dry", "wet", "rain")}
    dry = scenes["dry"]
    assert dry["weather"] == "dry" and street.WET_ROAD_MATERIAL not in dry["materials"]
    assert not any(p["material"] == street.PUDDLE_MATERIAL for o in dry["objects"] for p in o["parts"])
    for w in ("wet", "rain"):
        sc = scenes[w]
        m = sc["materials"][street.WET_ROAD_MATERIAL]
        assert m["type"] == "roughplastic" and m["ior"] == pytest.approx(1.33)
        road = next(o for o in sc["objects"] if o["kind"] == "road")
        assert road["parts"][0]["material"] == street.WET_ROAD_MATERIAL
        puddles = [p for p in road["parts"] if p["material"] == street.PUDDLE_MATERIAL]
        assert puddles and all(p["shape"] == "mesh" and p["mesh"] in sc["meshes"] for p in puddles)
    assert sc["materials"][street.WET_ROAD_MATERIAL]["alpha"] < scenes["wet"]["materials"][
        street.WET_ROAD_MATERIAL]["alpha"]  # rain: a smoother standing film (the configured ranges do not overlap)


def test_generator_arguments():
    with pytest.raises(ValueError, match="generator"):
        S.generate_scene(1, generator=3)
    with pytest.raises(ValueError, match="generator 2 needs"):
        S.generate_scene(1, generator=2, config=S.load_config())
    with pytest.raises(ValueError, match="unknown key 'weather"):
        S.generate_scene(1, overrides={"weather": {"conditions": ["wet"]}})  # generator 1 has no weather
    with pytest.raises(ValueError, match="weather.conditions"):
        S.generate_scene(1, generator=2, overrides={"weather": {"conditions": ["snow"]}})


# ------------------------------------------------------------------------------------------- scene file
def _v2_scene():
    sc = S.empty_scene("mesh_test")
    sc["version"] = 2
    sc["weather"] = "wet"
    sc["materials"]["m"] = {"type": "roughplastic", "rgb": [0.1, 0.1, 0.1], "alpha": 0.1, "ior": 1.33}
    sc["meshes"] = {"tri": {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 2]]}}
    sc["objects"].append({"id": 0, "kind": "asset", "velocity_mps": [0, 0, 0],
                          "parts": [{"shape": "mesh", "mesh": "tri", "center": [5, 0, 0], "yaw_deg": 90.0,
                                     "scale": [2, 2, 2], "material": "m"}]})
    return S.validate_scene(sc)


@pytest.mark.parametrize("edit,field", [
    (lambda s: s.update(version=1), "scene.weather"),
    (lambda s: s.update(weather="snow"), "scene.weather"),
    (lambda s: s["objects"][0]["parts"][0].update(mesh="nope"), "scene.objects[0].parts[0].mesh"),
    (lambda s: s["meshes"]["tri"].update(faces=[[0, 1, 3]]), "scene.meshes.tri.faces"),
    (lambda s: s["meshes"]["tri"].update(vertices=[[0, 0], [1, 0], [0, 1]]), "scene.meshes.tri.vertices"),
    (lambda s: s["meshes"]["tri"].update(faces=[[0.5, 1, 2]]), "scene.meshes.tri.faces"),
    (lambda s: s["materials"]["m"].update(ior=0.5), "scene.materials.m.ior"),
    (lambda s: s["objects"][0]["parts"][0].update(scale=[0, 1, 1]), "scene.objects[0].parts[0].scale"),
])
def test_scene_v2_fields_checked(edit, field):
    sc = _v2_scene()
    edit(sc)
    with pytest.raises(ValueError) as e:
        S.validate_scene(sc)
    assert field in str(e.value) and "\n" not in str(e.value)


def test_mesh_triangle_limit():
    sc = _v2_scene()
    sc["meshes"]["big"] = {"vertices": [[0, 0, 0]] * 3, "faces": [[0, 1, 2]] * 50}
    set_limit("mesh_triangles", 40)
    try:
        with pytest.raises(ValueError, match="mesh_triangles"):
            S.validate_scene(sc)
    finally:
        set_limit("mesh_triangles", None)


def test_mesh_part_placement():
    """A mesh part's vertices are scaled per axis, turned by yaw about z and moved to its centre."""
    import numpy as np

    from render_tools import mitsuba_scene as ms

    sc = _v2_scene()
    V, F = ms.part_mesh(sc["objects"][0]["parts"][0], np.array([0.0, 0.0, 1.0]), sc["meshes"])
    np.testing.assert_allclose(V, [[5, 0, 1], [5, 2, 1], [3, 0, 1]], atol=1e-12)
    assert F.tolist() == [[0, 1, 2]]


# ------------------------------------------------------------------------------------------------ shapes
def _closed_outward(V, F):
    """Every edge shared by exactly two faces in opposite directions (closed, consistently wound) and a positive
    enclosed volume (outward)."""
    import numpy as np

    from render_tools import shapes

    edges = {}
    for a, b, c in F:
        for e in ((a, b), (b, c), (c, a)):
            edges[e] = edges.get(e, 0) + 1
    assert all(n == 1 and edges.get((e[1], e[0])) == 1 for e, n in edges.items())
    assert shapes.signed_volume(np.asarray(V), np.asarray(F)) > 0


def test_shape_meshes_closed_and_outward():
    import numpy as np

    from render_tools import shapes
    from render_tools.scene_templates import VEHICLE_BODIES

    t = shapes.torso_mesh()
    _closed_outward(t["vertices"], t["faces"])
    r = shapes.ring_mesh(0.3, 0.03)
    _closed_outward(r["vertices"], r["faces"])
    c = shapes.crown_mesh(np.random.default_rng(0))
    _closed_outward(c["vertices"], c["faces"])
    V, F = shapes.icosphere(2)
    assert np.allclose(np.linalg.norm(V, axis=1), 1) and shapes.signed_volume(V, F) == pytest.approx(4 * np.pi / 3, rel=0.04)  # inscribed: 3 % less
    for kind, body in VEHICLE_BODIES.items():
        m = shapes.body_meshes(body["stations"], body["width"], body["roof_inset"])
        # paint and glass together: one closed surface (merge the two vertex lists by coordinate)
        pts, faces = {}, []
        for entry in m.values():
            for f in entry["faces"]:
                faces.append([pts.setdefault(tuple(entry["vertices"][i]), len(pts)) for i in f])
        V = [p for p, _ in sorted(pts.items(), key=lambda kv: kv[1])]
        _closed_outward(V, faces)
        xs = np.asarray(V)[:, 0]
        from render_tools.scene_templates import VEHICLE_TEMPLATES
        L = VEHICLE_TEMPLATES[kind]["length"]
        if kind in ("car", "van", "bus"):  # a truck body is its cab (cargo: a box), a motorcycle its tank and seat
            assert xs.min() == pytest.approx(-L / 2, abs=0.06) and xs.max() == pytest.approx(L / 2, abs=0.06)
        assert ("glass" in m) == (kind != "motorcycle")


def test_v2_content_present():
    """A generator-2 night scene has shaped vehicles (mesh bodies, no box bodies), people, trees and road
    furniture; cyclists carry a lit rear LED on their own (moving) object."""
    sc = S.generate_scene(3, "night", generator=2, overrides={
        "vehicles": {"require_kinds": ["car", "van", "bus", "truck", "motorcycle", "bicycle"]},
        "people": {"cyclists": [2, 2], "pedestrians": [6, 6]}})
    kinds = [o["kind"] for o in sc["objects"]]
    for k in ("pedestrian", "tree", "traffic_sign", "car", "van", "bus", "truck", "motorcycle", "bicycle"):
        assert k in kinds, k
    for o in sc["objects"]:
        if o["kind"] in ("car", "van", "bus"):
            assert any(p["shape"] == "mesh" and p["mesh"].startswith("body_") for p in o["parts"])
            # no box body (a bus's skirt, a long strip 0.14 m high, is trim)
            assert not any(p["shape"] == "box" and p["size"][0] > 3 and p["size"][2] > 0.5 for p in o["parts"])
        if o["kind"] == "pedestrian":
            assert any(p["shape"] == "mesh" and p["mesh"] == "torso" for p in o["parts"]) and any(o["velocity_mps"])
    for lt in sc["lights"]:
        if sc["objects"][lt["instance"]]["kind"] == "cyclist":
            assert lt["kind"] == "tail" and lt["group"] == "otherlights"
    assert S.validate_scene(sc) is sc
