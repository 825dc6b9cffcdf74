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


def to_gltf_frame(V):
    """Scene-frame points (n, 3) (x forward, y left, z up) in glTF's frame (y up, front +z, x left)."""
    import numpy as np

    V = np.asarray(V, dtype=float)
    return np.stack([V[:, 1], V[:, 2], V[:, 0]], axis=1)


def write_glb(folder: Path, name: str = "box.glb") -> Path:
    """The box as binary glTF (trimesh's exporter) in glTF's own frame (y up, front +z), one material 'Body'."""
    import numpy as np
    import trimesh

    folder.mkdir(parents=True, exist_ok=True)
    m = trimesh.Trimesh(to_gltf_frame(_BOX_V), np.array(_BOX_F) - 1, process=False)
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


def write_two_lamp_obj(folder: Path, name: str = "pair.obj") -> Path:
    """The box with two separate tail-lamp quads sharing one material 'TailLamp' (left y = +0.7, right y = -0.7
    on the rear face x = -1 m, each 0.3 x 0.2 m) and one quad 'Indicator' (y = 0 m)."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = [f"v {x} {y} {z}" for x, y, z in _BOX_V]
    quads = []
    for yc in (0.7, -0.7, 0.0):
        base = 1 + len(lines)
        lines += [f"v -1.0 {yc - 0.15} 0.6", f"v -1.0 {yc + 0.15} 0.6", f"v -1.0 {yc + 0.15} 0.8",
                  f"v -1.0 {yc - 0.15} 0.8"]
        quads.append(f"f {base} {base + 3} {base + 2} {base + 1}")
    lines += ["o Body"] + [f"f {a} {b} {c}" for a, b, c in _BOX_F]
    lines += ["o TailLamp", "usemtl TailLamp"] + quads[:2] + ["usemtl Indicator"] + quads[2:]
    (folder / "pair.mtl").write_text("newmtl TailLamp\nKd 1 0 0\nnewmtl Indicator\nKd 1 0.5 0\n")
    p = folder / name
    p.write_text("mtllib pair.mtl\n" + "\n".join(lines) + "\n")
    return p


def write_gltf_car(folder: Path, name: str = "car.glb", scenes: int = 1) -> Path:
    """A 'car' as a glTF author writes one: modelled in centimetres, y up, its front towards +z, a node scale of
    0.01 to metres: body 440 x 180 x 140 cm (length along z, height along y, wheels on y = 0), and two tail-lamp
    nodes 'TailLamp_L' / 'TailLamp_R' (one material 'LampRed') on its rear face (z = -220 cm). ``scenes``: how
    many glTF scenes the file declares (a second one lists the same root node)."""
    import json as _json
    import struct

    import numpy as np
    import trimesh

    folder.mkdir(parents=True, exist_ok=True)
    body = trimesh.creation.box(extents=(180.0, 140.0, 440.0))
    body.apply_translation((0.0, 70.0, 0.0))
    body.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(name="Paint"))
    sc = trimesh.Scene()
    root = "CarRoot"
    sc.graph.update(frame_to=root, frame_from=sc.graph.base_frame, matrix=np.diag([0.01, 0.01, 0.01, 1.0]))
    sc.add_geometry(body, node_name="Body", geom_name="body", parent_node_name=root)
    for side, x in (("L", 65.0), ("R", -65.0)):
        quad = trimesh.Trimesh(np.array([[x - 15, 90, -220.5], [x + 15, 90, -220.5], [x + 15, 110, -220.5],
                                         [x - 15, 110, -220.5]]), np.array([[0, 2, 1], [0, 3, 2]]), process=False)
        quad.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(name="LampRed"))
        sc.add_geometry(quad, node_name=f"TailLamp_{side}", geom_name=f"lamp_{side}", parent_node_name=root)
    data = sc.export(file_type="glb")
    if scenes > 1:  # rewrite the JSON chunk with extra scenes
        jlen = struct.unpack("<I", data[12:16])[0]
        doc = _json.loads(data[20:20 + jlen])
        doc["scenes"] = doc["scenes"] * scenes
        js = _json.dumps(doc).encode()
        js += b" " * (-len(js) % 4)
        rest = data[20 + jlen:]
        data = b"glTF" + struct.pack("<II", 2, 12 + 8 + len(js) + len(rest)) + struct.pack("<I", len(js)) + b"JSON" \
            + js + rest
    p = folder / name
    p.write_bytes(data)
    return p


def write_quad_ply(folder: Path, name: str = "quads.ply", quads: int = 50, binary: bool = True) -> Path:
    """A strip of ``quads`` unit quads as PLY (binary little-endian or ASCII): 2 x ``quads`` triangles."""
    import numpy as np

    folder.mkdir(parents=True, exist_ok=True)
    n = quads + 1
    V = np.array([(i, y, 0.0) for i in range(n) for y in (0.0, 1.0)], dtype="<f4")
    Fq = np.array([(2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1) for i in range(quads)], dtype="<i4")
    fmt = "binary_little_endian" if binary else "ascii"
    head = ("ply\nformat %s 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\n"
            "element face %d\nproperty list uchar int vertex_indices\nend_header\n" % (fmt, len(V), quads)).encode()
    if binary:
        rec = np.zeros(quads, dtype=[("n", "u1"), ("i", "<i4", 4)])
        rec["n"], rec["i"] = 4, Fq
        body = V.tobytes() + rec.tobytes()
    else:
        body = ("\n".join(" ".join(map(str, v)) for v in V) + "\n"
                + "\n".join("4 " + " ".join(map(str, q)) for q in Fq) + "\n").encode()
    p = folder / name
    p.write_bytes(head + body)
    return p
