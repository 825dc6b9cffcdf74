"""The user's own mesh files in a scene file (render_tools.assets, issue 23 item 5): OBJ, PLY and GLB read with
trimesh, lamps tagged by material name or a sidecar mapping, paths only inside the scene file's folder; bad input
is one line naming the scene file and field, and nothing is written."""
from __future__ import annotations

import copy
import json
import os

import numpy as np
import pytest
from typer.testing import CliRunner

from lfmbench.cli import app
from lfmbench.limits import set_limit
from render_tools import assets as A
from render_tools import scene as S

from tests.data.assets.data import LAMP, RED, asset_scene, write_glb, write_obj, write_ply, write_scene

TAIL = {"kind": "tail", "spectrum": RED, "luminance_cd_m2": 400.0}


def test_obj_with_a_tagged_lamp(tmp_path):
    write_obj(tmp_path / "assets")
    sc = asset_scene({"file": "assets/van.obj", "materials": {"Glass": "glass"}, "lamps": {"TailLamp": TAIL}})
    out = A.expand_assets(sc, tmp_path / "scene.json")
    assert out is not sc and "file" in sc["meshes"]["asset"]  # the input is not changed
    S.validate_scene(out)
    parts = out["objects"][0]["parts"]
    assert sorted((p["mesh"], p["material"]) for p in parts) == [("asset/Body", "paint"), ("asset/Glass", "glass")]
    assert "asset/TailLamp" not in out["meshes"]  # the lamp's triangles became the light's face
    assert len(out["meshes"]["asset/Body"]["faces"]) == 10 and len(out["meshes"]["asset/Glass"]["faces"]) == 2
    (lt,) = out["lights"]
    assert (lt["kind"], lt["group"], lt["instance"], lt["shape"]) == ("tail", "otherlights", 0, "rect")
    # placed 10 m ahead: the lamp quad (x = -1 m in the asset) is at x = 9 m, 1 mm in front, facing -x
    np.testing.assert_allclose(lt["center"], [9.0 - 0.001, LAMP["center"][1], LAMP["center"][2]], atol=1e-9)
    np.testing.assert_allclose(lt["normal"], LAMP["normal"], atol=1e-12)
    assert sorted(lt["size"]) == pytest.approx(sorted(LAMP["size"]))


def test_sidecar_mapping_ply_and_glb(tmp_path):
    write_obj(tmp_path)
    (tmp_path / "van.lamps.json").write_text(json.dumps({"TailLamp": TAIL}))
    out = A.expand_assets(asset_scene({"file": "van.obj", "lamps": "van.lamps.json"}), tmp_path / "s.json")
    assert len(out["lights"]) == 1 and S.validate_scene(out)
    for writer in (write_ply, write_glb):
        p = writer(tmp_path)
        out = A.expand_assets(asset_scene({"file": p.name}), tmp_path / "s.json")
        S.validate_scene(out)
        (name,) = out["meshes"]
        V = np.asarray(out["meshes"][name]["vertices"])
        assert len(out["meshes"][name]["faces"]) == 12 and np.ptp(V, axis=0) == pytest.approx([2, 2, 1.2])


@pytest.mark.parametrize("case,field", [
    ("missing", "scene.meshes.asset.file"),
    ("outside", "scene.meshes.asset.file"),
    ("link_out", "scene.meshes.asset.file"),
    ("absolute", "scene.meshes.asset.file"),
    ("malformed_ply", "scene.meshes.asset.file"),
    ("malformed_glb", "scene.meshes.asset.file"),
    ("huge", "scene.meshes.asset.file"),
    ("lamp_no_material", "scene.meshes.asset.lamps.Headlamp"),
    ("lamp_bad_kind", "scene.meshes.asset.lamps.TailLamp.kind"),
    ("mtl_outside", "scene.meshes.asset.file"),
    ("weather", "scene.weather"),
])
def test_bad_assets_are_one_line_and_write_nothing(tmp_path, case, field):
    folder = tmp_path / "scenes"
    write_obj(folder)
    entry = {"file": "van.obj", "lamps": {"TailLamp": TAIL}}
    sc = asset_scene(entry)
    if case == "missing":
        entry["file"] = "nope.obj"
    elif case == "outside":
        write_obj(tmp_path, "escape.obj")
        entry["file"] = "../escape.obj"
    elif case == "link_out":
        write_obj(tmp_path, "escape.obj")
        os.symlink(tmp_path / "escape.obj", folder / "link.obj")
        entry["file"] = "link.obj"
    elif case == "absolute":
        entry["file"] = str(folder / "van.obj")
    elif case == "malformed_ply":
        (folder / "bad.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n")
        entry.update(file="bad.ply", lamps={})
    elif case == "malformed_glb":
        (folder / "bad.glb").write_bytes(b"glTF\x02\x00\x00\x00" + b"\xff" * 40)
        entry.update(file="bad.glb", lamps={})
    elif case == "huge":  # 10^8 triangles declared by a 300-byte file: refused before anything is read
        write_ply(folder, "huge.ply", faces_declared=10 ** 8)
        entry.update(file="huge.ply", lamps={})
    elif case == "lamp_no_material":
        entry["lamps"] = {"Headlamp": TAIL}
    elif case == "lamp_bad_kind":
        entry["lamps"] = {"TailLamp": dict(TAIL, kind="laser")}
    elif case == "mtl_outside":
        text = (folder / "van.obj").read_text().replace("mtllib van.mtl", "mtllib ../secret.mtl")
        (tmp_path / "secret.mtl").write_text((folder / "van.mtl").read_text())
        (folder / "van.obj").write_text(text)
    elif case == "weather":
        sc["weather"] = "snow"
    p = write_scene(folder, sc)
    with pytest.raises(ValueError) as e:
        S.validate_scene(A.expand_assets(sc, p))
    msg = str(e.value)
    assert field in msg and "\n" not in msg, msg
    out = tmp_path / "corpus"
    r = CliRunner().invoke(app, ["render", "--out", str(out), "--scene", str(p), "--width", "32", "--height", "18",
                                 "--frames", "1"])
    assert r.exit_code == 2, r.output
    line = r.output.strip()
    assert "\n" not in line and str(p) in line and field in line and "Traceback" not in r.output
    assert not out.exists()  # nothing written


def test_triangle_budget_counts_the_scene(tmp_path):
    write_obj(tmp_path)
    set_limit("mesh_triangles", 11)  # the OBJ declares 13 triangles (12 + the lamp quad's 2 - 1 per n-gon rule)
    try:
        with pytest.raises(ValueError, match="mesh_triangles"):
            A.expand_assets(asset_scene({"file": "van.obj"}), tmp_path / "s.json")
    finally:
        set_limit("mesh_triangles", None)
    assert A.declared_triangles(tmp_path / "van.obj", "obj") == 14


def test_scene_without_assets_is_returned_as_is(tmp_path):
    sc = S.generate_scene(1, "night", generator=2)
    assert A.expand_assets(sc, tmp_path / "s.json") is sc and not A.has_assets(sc)
    assert copy.deepcopy(sc) == sc


# --- second round (issue 40): lamps per part, node tags with timing, glTF's frame, polygon PLY counts, 3-D turns

def test_lamps_sharing_a_material_are_one_light_each(tmp_path):
    """Two tail-lamp quads of one material become two lights (one per connected part), each fitted to its own
    quad; ``split: whole`` keeps the old single light over both; an indicator tag carries its waveform."""
    from tests.data.assets.data import write_two_lamp_obj

    write_two_lamp_obj(tmp_path)
    blink = {"kind": "indicator", "frequency_hz": 1.5, "on_fraction": 0.5, "phase_s": 0.1}
    ind = {"kind": "indicator", "spectrum": RED, "luminance_cd_m2": 300.0, "waveform": blink, "driver": "turn_l"}
    out = A.expand_assets(asset_scene({"file": "pair.obj", "lamps": {"TailLamp": TAIL, "Indicator": ind}}),
                          tmp_path / "s.json")
    S.validate_scene(out)
    tails = [lt for lt in out["lights"] if lt["kind"] == "tail"]
    assert len(tails) == 2
    ys = sorted(lt["center"][1] for lt in tails)
    np.testing.assert_allclose(ys, [-0.7, 0.7], atol=1e-9)
    for lt in tails:
        assert sorted(lt["size"]) == pytest.approx([0.2, 0.3]) and "waveform" not in lt
    (i,) = [lt for lt in out["lights"] if lt["kind"] == "indicator"]
    assert i["waveform"] == blink and i["driver"] == "turn_l"
    whole = A.expand_assets(asset_scene({"file": "pair.obj", "lamps": {"TailLamp": dict(TAIL, split="whole")}}),
                            tmp_path / "s.json")
    (bar,) = whole["lights"]
    assert max(bar["size"]) == pytest.approx(1.7)  # the old behaviour: one bar over both lamps


def test_gltf_car_arrives_upright_at_its_real_size_with_node_lamps(tmp_path):
    """glTF is y-up with its front towards +z and a node scale (here cm -> m): the car stands on the road (z from
    0 to 1.4 m), 4.4 m long along x (its front ahead, +x), 1.8 m wide; its two tail-lamp nodes (one material)
    become two lights tagged by node name, on its rear face facing -x."""
    from tests.data.assets.data import write_gltf_car

    write_gltf_car(tmp_path)
    tags = {"TailLamp_L": TAIL, "TailLamp_R": dict(TAIL, driver="tails")}
    out = A.expand_assets(asset_scene({"file": "car.glb", "lamps": tags}), tmp_path / "s.json")
    S.validate_scene(out)
    (body,) = [m for m in out["meshes"] if m.endswith("/Paint")]
    V = np.asarray(out["meshes"][body]["vertices"])
    np.testing.assert_allclose(V.min(0), [-2.2, -0.9, 0.0], atol=1e-6)
    np.testing.assert_allclose(V.max(0), [2.2, 0.9, 1.4], atol=1e-6)
    lights = sorted(out["lights"], key=lambda lt: lt["center"][1])
    assert len(lights) == 2 and [lt.get("driver") for lt in lights] == ["tails", None]
    for lt, y in zip(lights, (-0.65, 0.65)):
        np.testing.assert_allclose(lt["normal"], [-1.0, 0.0, 0.0], atol=1e-9)
        np.testing.assert_allclose(lt["center"], [10.0 - 2.205 - 0.001, y, 1.0], atol=1e-6)
        assert sorted(lt["size"]) == pytest.approx([0.2, 0.3])
    # up: z keeps the file's own frame (the old reading): the car lies on its side, 4.4 m tall
    flat = A.expand_assets(asset_scene({"file": "car.glb", "up": "z"}), tmp_path / "s.json")
    Vz = np.asarray(flat["meshes"][body]["vertices"])
    assert np.ptp(Vz[:, 2]) == pytest.approx(4.4)


@pytest.mark.parametrize("binary", [True, False])
def test_polygon_ply_is_counted_in_triangles_before_loading(tmp_path, binary):
    """A PLY of quads declares half the triangles it makes: the header check counts 2 per quad (binary: from the
    face block's size; ASCII: from each face line's corner count) and refuses over the limit before loading."""
    from tests.data.assets.data import write_quad_ply

    p = write_quad_ply(tmp_path, quads=50, binary=binary)
    assert A.declared_triangles(p, "ply") == 100
    out = A.expand_assets(asset_scene({"file": p.name}), tmp_path / "s.json")
    assert sum(len(m["faces"]) for m in out["meshes"].values()) == 100
    set_limit("mesh_triangles", 99)
    try:
        with pytest.raises(ValueError, match="scene.meshes.asset.file.*mesh_triangles"):
            A.expand_assets(asset_scene({"file": p.name}), tmp_path / "s.json")
    finally:
        set_limit("mesh_triangles", None)


def test_ply_face_block_that_lies_is_refused(tmp_path):
    from tests.data.assets.data import write_quad_ply

    p = write_quad_ply(tmp_path, quads=5)
    p.write_bytes(p.read_bytes()[:-7])  # the last face cut short
    with pytest.raises(ValueError, match="face block"):
        A.declared_triangles(p, "ply")


@pytest.mark.parametrize("case,field", [
    ("two_scenes", "scene.meshes.asset.file"),
    ("no_node", "scene.meshes.asset.lamps.TailLamp_X"),
    ("bad_waveform", "scene.meshes.asset.lamps.TailLamp_L.waveform"),
    ("bad_up", "scene.meshes.asset.up"),
    ("bad_split", "scene.meshes.asset.lamps.TailLamp_L.split"),
])
def test_bad_gltf_tags_are_one_line(tmp_path, case, field):
    from tests.data.assets.data import write_gltf_car

    write_gltf_car(tmp_path, scenes=2 if case == "two_scenes" else 1)
    entry = {"file": "car.glb", "lamps": {"TailLamp_L": TAIL}}
    if case == "no_node":
        entry["lamps"] = {"TailLamp_X": TAIL}
    elif case == "bad_waveform":
        entry["lamps"] = {"TailLamp_L": dict(TAIL, waveform={"kind": "sawtooth"})}
    elif case == "bad_up":
        entry["up"] = "x"
    elif case == "bad_split":
        entry["lamps"] = {"TailLamp_L": dict(TAIL, split="halves")}
    with pytest.raises(ValueError) as e:
        S.validate_scene(A.expand_assets(asset_scene(entry), tmp_path / "s.json"))
    assert field in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_parts_turn_in_three_dimensions():
    """Yaw alone is the old turn about z, bit for bit; roll 90 deg turns a box's y extent into z (ISO 8855 order:
    roll, then pitch, then yaw); the rotation is orthonormal with determinant 1."""
    from render_tools.mitsuba_scene import part_mesh, part_rotation

    t = np.radians(30.0)
    rz = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
    assert np.array_equal(part_rotation({"yaw_deg": 30.0}), rz)
    R = part_rotation({"yaw_deg": 40.0, "pitch_deg": -15.0, "roll_deg": 70.0})
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    V, _ = part_mesh({"shape": "box", "center": [0, 0, 1], "size": [4.0, 2.0, 0.5], "roll_deg": 90.0})
    np.testing.assert_allclose(np.ptp(V, axis=0), [4.0, 0.5, 2.0], atol=1e-12)
    V, _ = part_mesh({"shape": "box", "center": [0, 0, 1], "size": [4.0, 2.0, 0.5], "pitch_deg": 90.0})
    np.testing.assert_allclose(np.ptp(V, axis=0), [0.5, 2.0, 4.0], atol=1e-12)
    sc = S.empty_scene("turn")
    sc["version"] = 2
    sc["materials"]["m"] = {"type": "diffuse", "rgb": [0.5, 0.5, 0.5]}
    sc["objects"].append({"id": 0, "kind": "traffic_sign", "velocity_mps": [0.0, 0.0, 0.0],
                          "parts": [{"shape": "box", "center": [5, 0, 1], "size": [1, 1, 1], "roll_deg": 800.0,
                                     "material": "m"}]})
    with pytest.raises(ValueError, match=r"parts\[0\]\.roll_deg"):
        S.validate_scene(sc)
