"""The user's own mesh assets in a scene file (``--scene``): OBJ, PLY and glTF/GLB files read with trimesh, lamps
tagged by the file's material names, expanded into a plain version-2 scene (inline ``meshes``, ``mesh`` parts,
rectangular lights) before anything is rendered. docs/guide/rendering.md, "Your own meshes".

In the scene file, a ``meshes`` entry may name a file instead of holding vertices and faces::

    "meshes": {"van": {"file": "assets/van.obj",                     # inside the scene file's folder
                       "materials": {"Body": "red_paint", "Windows": "glass"},   # file material -> scene material
                       "lamps": {"TailLeft": {"kind": "tail", "spectrum": {...}, "luminance_cd_m2": 400.0},
                                 "Head": {"kind": "headlight", "spectrum": {...}, "luminance_cd_m2": 5e4,
                                          "spread_deg": 15.0}}}}
    "lamps": "assets/van.lamps.json"                                  # or: the same mapping in a sidecar file

Every ``mesh`` part that uses such an entry becomes one part per file material (the ``materials`` mapping, else the
part's own material) and one light per lamp-tagged material: a rectangle fitted to that material's triangles
(area-weighted centroid and normal, the triangles' extent in its plane), 1 mm in front of them, on the part's
object (``instance``), group ``group`` or the kind's default. The tagged triangles themselves are left out (the
light's face takes their place).

Checked before any array is read: the path (relative, inside the scene file's folder after resolving links, a
regular file of at most ``mesh_file_bytes``), the triangles the file declares (limit ``mesh_triangles``), every
lamp tag (a material the file has, a known light kind, spectrum, luminance). Any failure is one ``ValueError``
naming the field (``scene.meshes.van.file: ...``); :func:`expand_assets` callers add the scene file's name.
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


def declared_triangles(path: Path, kind: str) -> int:
    """Triangles a mesh file declares, read from its header (PLY, glTF/GLB) or its face lines (OBJ: an n-gon
    counts n - 2) without building any array; ``ValueError`` for a header that cannot be read."""
    if kind == "ply":
        with open(path, "rb") as f:
            head = f.read(65536)
        end = head.find(b"end_header")
        if not head.startswith(b"ply") or end < 0:
            raise ValueError("not a PLY file (no 'ply' ... 'end_header' header in its first 64 KiB)")
        m = re.search(rb"element\s+face\s+(\d+)", head[:end])
        return int(m.group(1)) if m else 0
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


def _load(path: Path, kind: str, folder: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(material name, V (n, 3) m, F (m, 3)) per material of a mesh file, node transforms applied; files the mesh
    file names (an OBJ's MTL, a glTF's buffers and images) are read only from inside ``folder``."""
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
    out: dict[str, list] = {}
    for g in loaded.dump(concatenate=False):
        mat = getattr(getattr(g.visual, "material", None), "name", None) or g.metadata.get("name") or "default"
        out.setdefault(str(mat), []).append((np.asarray(g.vertices, dtype=np.float64), np.asarray(g.faces)))
    from .mitsuba_scene import merge_meshes  # noqa: PLC0415

    return [(mat, *merge_meshes(parts)) for mat, parts in sorted(out.items())]


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
        fail(f"{field}.lamps", f"must map material names to lights, got {brief(tags)}")
    for mat, t in tags.items():
        f = f"{field}.lamps.{mat}"
        check_keys(t, f, required=("kind", "spectrum", "luminance_cd_m2"), optional=("group", "spread_deg"))
        if t["kind"] not in LIGHT_KINDS:
            fail(f"{f}.kind", f"{brief(t['kind'])} not one of {sorted(LIGHT_KINDS)}")
        if t.get("group", LIGHT_KINDS[t["kind"]]) not in LIGHT_GROUPS:
            fail(f"{f}.group", f"{brief(t.get('group'))} not one of {LIGHT_GROUPS}")
        spectra.validate_spectrum(t["spectrum"], f"{f}.spectrum")
        check_number(t["luminance_cd_m2"], f"{f}.luminance_cd_m2", lo=0.0, hi=1e9)
        check_number(t.get("spread_deg", 90.0), f"{f}.spread_deg", lo=0.0, hi=90.0, lo_open=True)
    return tags


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
        check_keys(e, f, required=("file",), optional=("materials", "lamps"))
        p = _inside(folder, e["file"], f"{f}.file")
        kind = MESH_SUFFIXES.get(p.suffix.lower())
        if kind is None:
            fail(f"{f}.file", f"{brief(e['file'])} is not one of the mesh types {sorted(MESH_SUFFIXES)}")
        if p.stat().st_size > limit("mesh_file_bytes"):
            raise LimitError(f"{f}.file ({p.name})", "bytes", p.stat().st_size, "mesh_file_bytes")
        try:
            tri = declared_triangles(p, kind)
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
            subs = _load(p, kind, folder)
        except ValueError as exc:
            fail(f"{f}.file", f"{brief(e['file'])}: {brief(str(exc), 160)}")
        except Exception as exc:  # noqa: BLE001 - a malformed file may raise anything inside trimesh
            fail(f"{f}.file", f"{brief(e['file'])} is not a readable {kind} file ({type(exc).__name__})")
        if not subs or sum(len(F) for _, _, F in subs) == 0:
            fail(f"{f}.file", f"{brief(e['file'])} holds no triangles")
        names = {m for m, _, _ in subs}
        for mat in tags:
            if mat not in names:
                fail(f"{f}.lamps.{mat}", f"names no material of {p.name} (its materials: {sorted(names)})")
        for mat in mats:
            if mat not in names:
                fail(f"{f}.materials.{mat}", f"names no material of {p.name} (its materials: {sorted(names)})")
        del meshes[name]
        for mat, V, F in subs:
            if mat not in tags:
                meshes[f"{name}/{mat}"] = {"vertices": np.round(V, 6).tolist(), "faces": F.astype(int).tolist()}
        loaded[name] = (subs, mats, tags)
    lights = sc["lights"]
    from .mitsuba_scene import part_mesh  # noqa: PLC0415

    for o in sc["objects"]:
        new_parts = []
        for part in o.get("parts", []):
            if not (isinstance(part, dict) and part.get("shape") == "mesh" and part.get("mesh") in loaded):
                new_parts.append(part)
                continue
            subs, mats, tags = loaded[part["mesh"]]
            for mat, V, F in subs:
                if mat in tags:
                    t = tags[mat]
                    Vw, Fw = part_mesh(dict(part, mesh="_"), np.zeros(3), {"_": {"vertices": V, "faces": F}})
                    try:
                        face = _fit_rect(Vw, Fw)
                    except ValueError as exc:
                        fail(f"scene.meshes.{part['mesh']}.lamps.{mat}", str(exc))
                    lights.append({"id": len(lights), "group": t.get("group", LIGHT_KINDS[t["kind"]]),
                                   "kind": t["kind"], "instance": o["id"], **face,
                                   "spread_deg": float(t.get("spread_deg", 90.0)),
                                   "spectrum": copy.deepcopy(t["spectrum"]),
                                   "luminance_cd_m2": float(t["luminance_cd_m2"])})
                else:
                    new_parts.append(dict(part, mesh=f"{part['mesh']}/{mat}", material=mats.get(mat, part["material"])))
        o["parts"] = new_parts
    return sc
