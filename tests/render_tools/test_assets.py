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
