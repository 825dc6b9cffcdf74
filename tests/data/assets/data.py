"""Tiny user mesh assets for the scene-file tests: a box 'vehicle' in OBJ (with an MTL: materials Body, Glass and
TailLamp, the lamp a 0.4 x 0.2 m quad on the rear face), the same box in PLY and GLB, and a scene file using one."""
from __future__ import annotations

import json
from pathlib import Path

from render_tools import scene as S

#: The lamp quad of the OBJ asset: rear face x = -1 m, y in [0.5, 0.9] m, z in [0.6, 0.8] m, facing -x.
LAMP = {"center": (-1.0, 0.7, 0.7), "size": (0.4, 0.2), "normal": (-1.0, 0.0, 0.0)}
RED = {"model": "led", "peak_nm": 630.0, "fwhm_nm": 18.0}

_BOX_V = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0), (-1, -1, 1.2), (1, -1, 1.2), (1, 1, 1.2), (-1, 1, 1.2)]
_BOX_F = [(1, 3, 2), (1, 4, 3), (5, 6, 7), (5, 7, 8), (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6), (3, 4, 8),
          (3, 8, 7), (4, 1, 5), (4, 5, 8)]  # 1-based, outward


def write_obj(folder: Path, name: str = "van.obj") -> Path:
    """The box with materials Body (sides, roof), Glass (front face) and a TailLamp quad on the rear face."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "van.mtl").write_text("newmtl Body\nKd 0.6 0.1 0.1\nnewmtl Glass\nKd 0.05 0.05 0.05\n"
                                    "newmtl TailLamp\nKd 1 0 0\n")
    lines = ["mtllib van.mtl"] + [f"v {x} {y} {z}" for x, y, z in _BOX_V]
    lines += ["v -1.0 0.5 0.6", "v -1.0 0.9 0.6", "v -1.0 0.9 0.8", "v -1.0 0.5 0.8"]  # 9..12: the lamp
    lines.append("usemtl Body")
    lines += [f"f {a} {b} {c}" for a, b, c in _BOX_F[:4] + _BOX_F[6:10]] + [f"f {a} {b} {c}" for a, b, c in _BOX_F[10:]]
    lines.append("usemtl Glass")
    lines += [f"f {a} {b} {c}" for a, b, c in _BOX_F[4:6]]
    lines += ["usemtl TailLamp", "f 9 12 11 10"]  # a quad, wound to face -x
    p = folder / name
    p.write_text("\n".join(lines) + "\n")
    return p


def write_ply(folder: Path, name: str = "box.ply", faces_declared: int | None = None) -> Path:
    """The box as ASCII PLY; ``faces_declared``: a header that claims this many faces (the body is not changed)."""
    folder.mkdir(parents=True, exist_ok=True)
    n = len(_BOX_F) if faces_declared is None else faces_declared
    head = ["ply", "format ascii 1.0", f"element vertex {len(_BOX_V)}", "property float x", "property float y",
            "property float z", f"element face {n}", "property list uchar int vertex_indices", "end_header"]
    body = [f"{x} {y} {z}" for x, y, z in _BOX_V] + [f"3 {a - 1} {b - 1} {c - 1}" for a, b, c in _BOX_F]
    p = folder / name
    p.write_text("\n".join(head + body) + "\n")
    return p


def write_glb(folder: Path, name: str = "box.glb") -> Path:
    """The box as binary glTF (trimesh's exporter), one material 'Body'."""
    import numpy as np
    import trimesh

    folder.mkdir(parents=True, exist_ok=True)
    m = trimesh.Trimesh(np.array(_BOX_V, dtype=float), np.array(_BOX_F) - 1, process=False)
    m.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(name="Body"))
    p = folder / name
    p.write_bytes(trimesh.Scene([m]).export(file_type="glb"))
    return p


def asset_scene(mesh_entry: dict, scene_id: str = "asset_scene") -> dict:
    """A version-2 night scene with one object: the mesh entry ``asset`` placed 10 m ahead, heading 0 (its rear,
    -x, towards the camera), default material 'paint' (scene materials 'paint' and 'glass')."""
    sc = S.empty_scene(scene_id)
    sc["version"] = 2
    sc["materials"].update({"paint": {"type": "roughplastic", "rgb": [0.3, 0.3, 0.35], "alpha": 0.2},
                            "glass": {"type": "roughplastic", "rgb": [0.02, 0.02, 0.03], "alpha": 0.05}})
    sc["meshes"] = {"asset": mesh_entry}
    sc["objects"].append({"id": 0, "kind": "asset", "velocity_mps": [0.0, 0.0, 0.0],
                          "parts": [{"shape": "mesh", "mesh": "asset", "center": [10.0, 0.0, 0.0], "yaw_deg": 0.0,
                                     "material": "paint"}]})
    return sc


def write_scene(folder: Path, scene: dict, name: str = "scene.json") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / name
    p.write_text(json.dumps(scene))
    return p
