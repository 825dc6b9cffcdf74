"""The user's own mesh assets in a scene file (``--scene``): OBJ, PLY and glTF/GLB files read with trimesh, lamps
tagged by the file's material or node names, expanded into a plain version-2 scene (inline ``meshes``, ``mesh``
parts, rectangular lights) before anything is rendered. docs/guide/rendering.md, "Your own meshes".

In the scene file, a ``meshes`` entry may name a file instead of holding vertices and faces::

    "meshes": {"van": {"file": "assets/van.glb",                     # inside the scene file's folder
                       "up": "y", "unit_m": 1.0,                     # the file's frame (defaults: DEFAULT_UP, 1)
                       "materials": {"Body": "red_paint", "Windows": "glass"},   # file material -> scene material
                       "lamps": {"TailLamp": {"kind": "tail", "spectrum": {...}, "luminance_cd_m2": 400.0},
                                 "Blinker_L": {"kind": "indicator", "waveform": {...}, "driver": "left", ...},
                                 "Head": {"kind": "headlight", "spectrum": {...}, "luminance_cd_m2": 5e4,
                                          "spread_deg": 15.0}}}}
    "lamps": "assets/van.lamps.json"                                  # or: the same mapping in a sidecar file

The file's vertices are turned into the scene frame (x forward, y left, z up; glTF is y-up, :data:`Y_UP_TO_SCENE`)
and scaled by ``unit_m``. Every ``mesh`` part that uses such an entry becomes one part per file material (the
``materials`` mapping, else the part's own material) and, per lamp tag (a node name, else a material name), one
light per connected part of the tagged triangles (``split: components``; ``whole``: one light): a rectangle
fitted to its triangles (area-weighted centroid and normal, the triangles' extent in its plane), 1 mm in front of
them, on the part's object (``instance``), group ``group`` or the kind's default, with the tag's ``waveform`` and
``driver``. The tagged triangles themselves are left out (the light's face takes their place).

Checked before any array is read: the path (relative, inside the scene file's folder after resolving links, a
regular file of at most ``mesh_file_bytes``), the triangles the file declares (limit ``mesh_triangles``; PLY
polygons counted as the triangles they make), one glTF scene, every lamp tag (a material or node the file has, a
known light kind, spectrum, luminance, waveform). Any failure is one ``ValueError`` naming the field
(``scene.meshes.van.file: ...``); :func:`expand_assets` callers add the scene file's name.
"""
from __future__ import annotations

import copy
import io
import json
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from lfmbench.check import check_keys, check_number, fail
from lfmbench.limits import LimitError, brief, limit
from lfmbench.vocabulary import LIGHT_GROUPS, LIGHT_KINDS

from . import spectra

__all__ = ["MESH_SUFFIXES", "expand_assets", "declared_triangles", "has_assets"]

#: File types a scene may reference (lower-case suffix -> trimesh file type).
MESH_SUFFIXES = {".obj": "obj", ".ply": "ply", ".gltf": "gltf", ".glb": "glb"}
#: Offset of a fitted lamp face in front of its triangles, m.
LAMP_OFFSET_M = 0.001
#: Smallest side of a fitted lamp face, m.
LAMP_MIN_SIZE_M = 0.005


def has_assets(scene: Any) -> bool:
    """Whether a scene dict references mesh files (a ``meshes`` entry with ``file``)."""
    m = scene.get("meshes") if isinstance(scene, dict) else None
    return isinstance(m, dict) and any(isinstance(e, dict) and "file" in e for e in m.values())


def _inside(folder: Path, rel: Any, field: str) -> Path:
    """``folder / rel`` resolved, refused unless it is a regular file inside ``folder`` (links resolved)."""
    if not isinstance(rel, str) or not rel or os.path.isabs(rel) or "\0" in rel:
        fail(field, f"must be a path relative to the scene file's folder, got {brief(rel)}")
    base = folder.resolve()
    p = (base / rel).resolve()
    if p != base and base not in p.parents:
        fail(field, f"{brief(rel)} is outside the scene file's folder {base}")
    if not p.exists():
        fail(field, f"{brief(rel)} does not exist (in {base})")
    if not p.is_file():
        fail(field, f"{brief(rel)} is not a regular file")
    return p


_PLY_SIZES = {"char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2, "ushort": 2, "uint16": 2,
              "int": 4, "int32": 4, "uint": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}
_PLY_UNSIGNED = {"uchar": "B", "uint8": "B", "char": "b", "int8": "b", "ushort": "H", "uint16": "H", "short": "h",
                 "int16": "h", "uint": "I", "uint32": "I", "int": "i", "int32": "i"}


def _ply_triangles(path: Path, cap: int | None = None) -> int:
    """Triangles a PLY file's faces make (a polygon of k corners: k - 2, as trimesh triangulates it), read from the
    header and the face records' corner counts without building any array: an ASCII file's face lines are read one
    at a time; a binary file's face block is measured (one list property: sum of corners = (block bytes - faces x
    count bytes) / index bytes) or its counts read one record at a time. ``ValueError`` for a header or body that
    does not hold what it declares. ``cap``: a face count over it is returned at once (nothing read past the header). Format: "PLY - Polygon File Format", P. Bourke,
    https://paulbourke.net/dataformats/ply/."""
    import struct  # noqa: PLC0415

    with open(path, "rb") as f:
        head = f.read(65536)
        end = head.find(b"end_header")
        if not head.startswith(b"ply") or end < 0:
            raise ValueError("not a PLY file (no 'ply' ... 'end_header' header in its first 64 KiB)")
        nl = head.find(b"\n", end)
        body_at = (nl + 1) if nl >= 0 else len(head)
        fmt, elements = None, []  # [name, count, [(kind, types...)]]
        for line in head[:end].decode("ascii", "replace").splitlines():
            t = line.split()
            if not t:
                continue
            if t[0] == "format" and len(t) >= 2:
                fmt = t[1]
            elif t[0] == "element" and len(t) == 3:
                if not t[2].isdigit():
                    raise ValueError(f"element {t[1]!r} declares {t[2]!r} items")
                elements.append([t[1], int(t[2]), []])
            elif t[0] == "property" and elements:
                if t[1] == "list" and len(t) == 5 and t[2] in _PLY_SIZES and t[3] in _PLY_SIZES:
                    elements[-1][2].append(("list", t[2], t[3]))
                elif len(t) == 3 and t[1] in _PLY_SIZES:
                    elements[-1][2].append(("scalar", t[1]))
                else:
                    raise ValueError(f"unreadable property line {line.strip()[:60]!r}")
        if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
            raise ValueError(f"unknown PLY format {fmt!r}")
        faces = [e for e in elements if e[0] == "face"]
        if not faces:
            return 0
        if cap is not None and faces[0][1] > cap:  # each face is at least one triangle: over the cap unread
            return faces[0][1]
        f.seek(body_at)
        if fmt == "ascii":
            tri = 0
            for name, count, props in elements:
                for _ in range(count):
                    line = f.readline()
                    if not line:
                        raise ValueError(f"the file ends inside element {name!r}")
                    if name == "face":
                        tok = line.split(None, 1)
                        if not tok or not tok[0].isdigit():
                            raise ValueError("a face line does not start with its corner count")
                        tri += max(int(tok[0]) - 2, 1)
                if name == "face":
                    return tri
        order = "<" if fmt == "binary_little_endian" else ">"
        size = path.stat().st_size
        pos = body_at
        for i, (name, count, props) in enumerate(elements):
            lists = [p for p in props if p[0] == "list"]
            if name != "face":
                if lists:
                    raise ValueError(f"element {name!r} before the faces has list properties")
                pos += count * sum(_PLY_SIZES[p[1]] for p in props)
                continue
            rest = elements[i + 1:]
            if len(lists) == 1 and len(props) == 1 and all(not any(p[0] == "list" for p in e[2]) for e in rest):
                csize, isize = _PLY_SIZES[lists[0][1]], _PLY_SIZES[lists[0][2]]
                block = size - pos - sum(e[1] * sum(_PLY_SIZES[p[1]] for p in e[2]) for e in rest)
                corners, r = divmod(block - count * csize, isize)
                if block < 0 or r or corners < 3 * count:
                    raise ValueError(f"its face block ({block} bytes) does not hold the {count} faces it declares")
                return corners - 2 * count
            f.seek(pos)
            tri = 0
            for _ in range(count):  # several list properties: each record's counts read in turn
                for p in props:
                    if p[0] == "scalar":
                        f.seek(_PLY_SIZES[p[1]], 1)
                        continue
                    raw = f.read(_PLY_SIZES[p[1]])
                    if len(raw) < _PLY_SIZES[p[1]] or p[1] not in _PLY_UNSIGNED:
                        raise ValueError("the file ends inside its faces")
                    k = struct.unpack(order + _PLY_UNSIGNED[p[1]], raw)[0]
                    if p is lists[0]:
                        tri += max(k - 2, 1)
                    f.seek(k * _PLY_SIZES[p[2]], 1)
            return tri
    return 0


def declared_triangles(path: Path, kind: str, cap: int | None = None) -> int:
    """Triangles a mesh file declares, read from its header (PLY, glTF/GLB) or its face lines (OBJ: an n-gon
    counts n - 2) without building any array; ``ValueError`` for a header that cannot be read."""
    if kind == "ply":
        return _ply_triangles(path, cap)
    if kind == "obj":
        n = 0
        with open(path, "rb") as f:
            for line in f:
                if line.startswith(b"f ") or line.startswith(b"f\t"):
                    n += max(len(line.split()) - 3, 1)
        return n
    if kind == "glb":
        with open(path, "rb") as f:
            head = f.read(20)
            if len(head) < 20 or head[:4] != b"glTF":
                raise ValueError("not a GLB file (no 'glTF' magic)")
            size = int.from_bytes(head[12:16], "little")
            if size > limit("json_bytes"):
                raise LimitError("its glTF JSON chunk", "bytes", size, "json_bytes")
            doc = json.loads(f.read(size))
    else:
        if path.stat().st_size > limit("json_bytes"):
            raise LimitError("its glTF JSON", "bytes", path.stat().st_size, "json_bytes")
        doc = json.loads(path.read_bytes())
    if not isinstance(doc, dict):
        raise ValueError("its glTF JSON is not an object")
    if len(doc.get("scenes", [])) > 1:
        raise ValueError(f"it holds {len(doc['scenes'])} scenes (one glTF scene per mesh entry)")
    acc = doc.get("accessors", [])
    per_mesh = []
    for mesh in doc.get("meshes", []):
        t = 0
        for prim in mesh.get("primitives", []):
            idx = prim.get("indices", prim.get("attributes", {}).get("POSITION"))
            if isinstance(idx, int) and 0 <= idx < len(acc):
                t += int(acc[idx].get("count", 0)) // 3
        per_mesh.append(t)
    uses = [n["mesh"] for n in doc.get("nodes", []) if isinstance(n.get("mesh"), int) and n["mesh"] < len(per_mesh)]
    return sum(per_mesh[i] for i in uses) if uses else sum(per_mesh)


#: The frame of each file type's vertices, as the file type's specification states it: glTF 2.0 is y-up with the
#: asset's front towards +z and metres ("glTF 2.0 Specification", Khronos Group, section 3.4 "Coordinate System
#: and Units", https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html); OBJ and PLY state no frame, and are read
#: in the scene frame (x forward, y left, z up) unless the entry's ``up`` says otherwise.
DEFAULT_UP = {"obj": "z", "ply": "z", "gltf": "y", "glb": "y"}
#: Rotation of a y-up, front +z file (glTF) into the scene frame: x <- z (front), y <- x (left), z <- y (up).
Y_UP_TO_SCENE = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _load(path: Path, kind: str, folder: Path) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """(node name, material name, V (n, 3), F (m, 3)) per geometry of a mesh file, node transforms applied, in
    the file's own frame and units; files the mesh file names (an OBJ's MTL, a glTF's buffers and images) are read
    only from inside ``folder``."""
    try:
        import trimesh  # noqa: PLC0415
    except ImportError:  # an optional dependency: only scenes with mesh files need it
        raise ValueError("mesh files need the optional package trimesh: pip install 'lfmbench[render]' "
                         "(or pip install 'trimesh>=4')") from None

    base = folder.resolve()

    class _Resolver(trimesh.resolvers.Resolver):
        def __init__(self):
            pass

        def keys(self):
            return iter(())

        def namespaced(self, namespace):
            raise ValueError(f"{brief(namespace)}: nested resources are not read")

        def get(self, name):
            p = (path.parent / name).resolve()
            if base not in p.parents or not p.is_file():
                refused.append(name)  # trimesh may catch this and go on without the file: re-raised below
                raise ValueError(f"{brief(name)}, which it names, is not a file inside the scene file's folder")
            return p.read_bytes()

        def write(self, name, data):  # pragma: no cover - never called when loading
            raise ValueError("mesh files are read, never written")

    refused: list = []
    loaded = trimesh.load(io.BytesIO(path.read_bytes()), file_type=kind, resolver=_Resolver(), force="scene")
    if refused:
        raise ValueError(f"{brief(refused[0])}, which it names, is not a file inside the scene file's folder")
    out = []
    for g in loaded.dump(concatenate=False):
        if not hasattr(g, "faces") or len(g.faces) == 0:
            continue
        mat = getattr(getattr(g.visual, "material", None), "name", None) or g.metadata.get("name") or "default"
        node = g.metadata.get("node") or g.metadata.get("name") or str(mat)
        out.append((str(node), str(mat), np.asarray(g.vertices, dtype=np.float64), np.asarray(g.faces)))
    return out


def _components(V: np.ndarray, F: np.ndarray) -> list[np.ndarray]:
    """The connected parts of triangles (V (n, 3) m, F (m, 3)): lists of face indices, triangles that share a
    corner position (within 1 um) in one part, ordered by their first face. Two lamps of one material (a left and
    a right tail lamp) are two parts."""
    import scipy.sparse as sp  # noqa: PLC0415
    from scipy.sparse.csgraph import connected_components  # noqa: PLC0415

    key = np.round(V / 1e-6).astype(np.int64)
    _, vid = np.unique(key, axis=0, return_inverse=True)
    vid = vid.reshape(-1)
    tri = vid[F]  # (m, 3) merged corner ids
    m, n = len(F), int(vid.max()) + 1 if len(vid) else 0
    rows = np.repeat(np.arange(m), 3)
    inc = sp.csr_matrix((np.ones(3 * m), (rows, tri.reshape(-1))), shape=(m, n))
    _, labels = connected_components(inc @ inc.T, directed=False)
    first = {}
    for i, lab in enumerate(labels):
        first.setdefault(int(lab), i)
    return [np.flatnonzero(labels == lab) for lab in sorted(first, key=first.get)]


def _lamp_tags(entry: dict, folder: Path, field: str) -> dict:
    tags = entry.get("lamps", {})
    if isinstance(tags, str):  # a sidecar JSON file with the mapping
        from lfmbench.fileio import load_json  # noqa: PLC0415

        p = _inside(folder, tags, f"{field}.lamps")
        try:
            tags = load_json(p, "lamp mapping")
        except (OSError, ValueError) as exc:
            fail(f"{field}.lamps", f"cannot read the lamp mapping {brief(str(p))}: {exc}")
    if not isinstance(tags, dict):
        fail(f"{field}.lamps", f"must map material or node names to lights, got {brief(tags)}")
    from lfmbench.flicker.waveforms import waveform_from_dict  # noqa: PLC0415

    for mat, t in tags.items():
        f = f"{field}.lamps.{mat}"
        check_keys(t, f, required=("kind", "spectrum", "luminance_cd_m2"),
                   optional=("group", "spread_deg", "waveform", "driver", "split"))
        if t["kind"] not in LIGHT_KINDS:
            fail(f"{f}.kind", f"{brief(t['kind'])} not one of {sorted(LIGHT_KINDS)}")
        if t.get("group", LIGHT_KINDS[t["kind"]]) not in LIGHT_GROUPS:
            fail(f"{f}.group", f"{brief(t.get('group'))} not one of {LIGHT_GROUPS}")
        spectra.validate_spectrum(t["spectrum"], f"{f}.spectrum")
        check_number(t["luminance_cd_m2"], f"{f}.luminance_cd_m2", lo=0.0, hi=1e9)
        check_number(t.get("spread_deg", 90.0), f"{f}.spread_deg", lo=0.0, hi=90.0, lo_open=True)
        if "waveform" in t:
            waveform_from_dict(t["waveform"], f"{f}.waveform")
        if "driver" in t and (not isinstance(t["driver"], str) or not 1 <= len(t["driver"]) <= 64):
            fail(f"{f}.driver", f"must be a name of 1 to 64 characters, got {brief(t['driver'])}")
        if t.get("split", "components") not in SPLITS:
            fail(f"{f}.split", f"{brief(t.get('split'))} not one of {SPLITS}")
    return tags


#: How a lamp tag's triangles become lights: one light per connected part (``components``, the default: two tail
#: lamps sharing a material are two lights) or one light for all of them (``whole``).
SPLITS = ("components", "whole")


def _fit_rect(V: np.ndarray, F: np.ndarray) -> dict:
    """A rectangle lamp face fitted to triangles (V (n, 3), F (m, 3), world m): area-weighted centroid and unit
    normal, the triangles' extent along the in-plane axes, 1 mm in front."""
    from .mitsuba_scene import _frame  # noqa: PLC0415

    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cr = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    if area.sum() <= 0:
        raise ValueError("its triangles have no area")
    n = cr.sum(0)
    n = n / np.linalg.norm(n) if np.linalg.norm(n) > 0 else np.array([0.0, 0.0, 1.0])
    ctr = ((a + b + c) / 3 * area[:, None]).sum(0) / area.sum()
    u, v, n = _frame(n)
    P = V[np.unique(F)] - ctr
    su, sv = np.ptp(P @ u), np.ptp(P @ v)
    return {"shape": "rect", "center": (ctr + LAMP_OFFSET_M * n).tolist(), "normal": n.tolist(),
            "size": [max(float(su), LAMP_MIN_SIZE_M), max(float(sv), LAMP_MIN_SIZE_M)]}


def expand_assets(scene: dict, scene_path: str | os.PathLike) -> dict:
    """The scene with every file mesh expanded (module docstring): a new dict, ``scene`` is not changed. Paths are
    resolved inside the folder of ``scene_path``. A scene without file meshes is returned as it is. Raises
    ``ValueError`` naming the field for any bad reference, file or tag (the caller adds the scene file)."""
    if not has_assets(scene):
        return scene
    from .mitsuba_scene import merge_meshes, part_mesh  # noqa: PLC0415

    folder = Path(scene_path).parent
    sc = copy.deepcopy(scene)
    meshes = sc["meshes"]
    budget = limit("mesh_triangles") - sum(len(e.get("faces", [])) for e in meshes.values()
                                           if isinstance(e, dict) and isinstance(e.get("faces"), list))
    loaded: dict[str, tuple[list, dict, dict]] = {}
    for name, e in list(meshes.items()):
        if not (isinstance(e, dict) and "file" in e):
            continue
        f = f"scene.meshes.{name}"
        check_keys(e, f, required=("file",), optional=("materials", "lamps", "up", "unit_m"))
        p = _inside(folder, e["file"], f"{f}.file")
        kind = MESH_SUFFIXES.get(p.suffix.lower())
        if kind is None:
            fail(f"{f}.file", f"{brief(e['file'])} is not one of the mesh types {sorted(MESH_SUFFIXES)}")
        up = e.get("up", DEFAULT_UP[kind])
        if up not in ("y", "z"):
            fail(f"{f}.up", f"{brief(up)} not one of ['y', 'z'] (the file's up axis)")
        unit = check_number(e.get("unit_m", 1.0), f"{f}.unit_m", lo=1e-4, hi=1e3)
        if p.stat().st_size > limit("mesh_file_bytes"):
            raise LimitError(f"{f}.file ({p.name})", "bytes", p.stat().st_size, "mesh_file_bytes")
        try:
            tri = declared_triangles(p, kind, cap=budget)
        except (ValueError, OSError, UnicodeDecodeError) as exc:
            fail(f"{f}.file", f"{brief(e['file'])} is not a readable {kind} file ({brief(str(exc), 160)})")
        if tri > budget:
            raise LimitError(f"{f}.file ({p.name})", "triangles (with the scene's other meshes)",
                             tri + limit("mesh_triangles") - budget, "mesh_triangles")
        budget -= tri
        mats = e.get("materials", {})
        if not isinstance(mats, dict) or not all(isinstance(v, str) and v in sc["materials"] for v in mats.values()):
            fail(f"{f}.materials", f"must map file material names to materials of scene.materials, got {brief(mats)}")
        tags = _lamp_tags(e, folder, f)
        try:
            geos = _load(p, kind, folder)
        except ValueError as exc:
            fail(f"{f}.file", f"{brief(e['file'])}: {brief(str(exc), 160)}")
        except Exception as exc:  # noqa: BLE001 - a malformed file may raise anything inside trimesh
            fail(f"{f}.file", f"{brief(e['file'])} is not a readable {kind} file ({type(exc).__name__})")
        if not geos or sum(len(F) for *_, F in geos) == 0:
            fail(f"{f}.file", f"{brief(e['file'])} holds no triangles")
        rot = Y_UP_TO_SCENE if up == "y" else np.eye(3)
        geos = [(node, mat, (V * unit) @ rot.T, F) for node, mat, V, F in geos]
        nodes, names = {g[0] for g in geos}, {g[1] for g in geos}
        for key in tags:
            if key not in nodes and key not in names:
                fail(f"{f}.lamps.{key}", f"names no material or node of {p.name} (its materials: {sorted(names)}; "
                     f"its nodes: {sorted(nodes)[:20]})")
        for mat in mats:
            if mat not in names:
                fail(f"{f}.materials.{mat}", f"names no material of {p.name} (its materials: {sorted(names)})")
        by_mat: dict[str, list] = {}
        by_tag: dict[str, list] = {}
        for node, mat, V, F in geos:
            key = node if node in tags else mat if mat in tags else None
            (by_tag.setdefault(key, []) if key is not None else by_mat.setdefault(mat, [])).append((V, F))
        del meshes[name]
        for mat, parts in sorted(by_mat.items()):
            V, F = merge_meshes(parts)
            meshes[f"{name}/{mat}"] = {"vertices": np.round(V, 6).tolist(), "faces": F.astype(int).tolist()}
        lamps = {}
        for key, parts in by_tag.items():
            V, F = merge_meshes(parts)
            comps = _components(V, F) if tags[key].get("split", "components") == "components" else [np.arange(len(F))]
            lamps[key] = [(V, F[c]) for c in comps]
        loaded[name] = (sorted(by_mat), mats, tags, lamps)
    lights = sc["lights"]
    for o in sc["objects"]:
        new_parts = []
        for part in o.get("parts", []):
            if not (isinstance(part, dict) and part.get("shape") == "mesh" and part.get("mesh") in loaded):
                new_parts.append(part)
                continue
            mat_names, mats, tags, lamps = loaded[part["mesh"]]
            for mat in mat_names:
                new_parts.append(dict(part, mesh=f"{part['mesh']}/{mat}", material=mats.get(mat, part["material"])))
            for key, comps in lamps.items():
                t = tags[key]
                for V, F in comps:
                    Vw, Fw = part_mesh(dict(part, mesh="_"), np.zeros(3), {"_": {"vertices": V, "faces": F}})
                    try:
                        face = _fit_rect(Vw, Fw)
                    except ValueError as exc:
                        fail(f"scene.meshes.{part['mesh']}.lamps.{key}", str(exc))
                    lt = {"id": len(lights), "group": t.get("group", LIGHT_KINDS[t["kind"]]), "kind": t["kind"],
                          "instance": o["id"], **face, "spread_deg": float(t.get("spread_deg", 90.0)),
                          "spectrum": copy.deepcopy(t["spectrum"]), "luminance_cd_m2": float(t["luminance_cd_m2"])}
                    for k in ("waveform", "driver"):
                        if k in t:
                            lt[k] = copy.deepcopy(t[k])
                    lights.append(lt)
        o["parts"] = new_parts
    return sc
