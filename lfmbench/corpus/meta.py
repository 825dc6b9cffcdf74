"""The JSON side of the corpus: ``meta.json`` checks (:func:`validate_meta`), ``manifest.json`` checks
(:func:`manifest_entry_errors`, :func:`inside_root`), ``splits.json`` (:func:`make_splits`,
:func:`check_splits`) and file checksums (:func:`sha256_file`, SHA-256 of FIPS PUB 180-4).

Units: times in s, wavelengths in nm, speeds in m/s, luminance in cd/m^2, bounding boxes in pixels as half-open
``[y0, x0, y1, x1]``.
"""
from __future__ import annotations

import hashlib
import math
import os
import re
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from lfmbench.limits import brief, lights_cap_message, limit
from lfmbench import check
from lfmbench.check import scene_id_error
from lfmbench.corpus.errors import CorpusFileError
from lfmbench.corpus.naming import FORMAT_NAME, FORMAT_VERSION, SCENES_DIR, _check_version, window_bin_weights
from lfmbench.vocabulary import LIGHT_KINDS, SPECTRUM_MODELS
from lfmbench.fileio import InputFileError, load_json, loads_json

__all__ = ["TIMING_RTOL", "sha256_file", "make_splits", "validate_meta", "load_meta", "LIGHT_KINDS", "SPECTRUM_MODELS",
           "manifest_entry_errors", "inside_root", "check_splits"]

#: Relative tolerance of the timing consistency checks (s / s).
TIMING_RTOL = 1e-6


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """SHA-256 hex digest (FIPS 180-4) of a file, read in 1 MiB chunks; a path that is not a regular file is a
    :class:`lfmbench.fileio.NotRegularFileError`."""
    from lfmbench.fileio import open_regular  # noqa: PLC0415

    h = hashlib.sha256()
    with open_regular(path, "corpus file") as fh:  # a FIFO or device is refused, never waited on
        while True:
            b = fh.read(chunk)
            if not b:
                break
            h.update(b)
    return h.hexdigest()


def _load_json(path: Path, what: str, object_hook: Any = None, raw: bytes | None = None) -> Any:
    """A corpus JSON file through the one bounded reader (:func:`lfmbench.fileio.load_json`; a manifest has its
    own size limit ``manifest_bytes``); ``CorpusFileError`` naming the file. ``raw``: the file's bytes, when the
    caller has read them already (within the same size limit)."""
    try:
        if raw is not None:
            return loads_json(raw, str(path), object_hook)
        return load_json(path, what, "manifest_bytes" if what == "manifest" else "json_bytes", object_hook)
    except FileNotFoundError:
        raise CorpusFileError(f"{what} is missing: {path}") from None
    except OSError as exc:
        raise CorpusFileError(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    except InputFileError as exc:
        raise CorpusFileError(f"{what} {exc}") from None


#: JSON objects a ``meta.json`` may hold per light of the cap ``lights_per_scene``, plus
#: :data:`META_OBJECTS_BASE` (a light is one object and its ``spectrum`` another; top level, timing, camera,
#: storage and the groups are a few dozen): the bound :func:`load_meta` checks while it parses.
META_OBJECTS_PER_LIGHT = 4
META_OBJECTS_BASE = 1024


class _TooMany(Exception):
    """Raised inside the JSON parser to stop it (not a ``ValueError``: :func:`loads_json` lets it through)."""


def load_meta(path: Path | str, raw: bytes | None = None) -> dict:
    """A scene's ``meta.json``, read through the bounded reader and checked (:func:`validate_meta`); ``raw``: its
    bytes, when the caller has read them already (within the limit ``json_bytes``).

    The light cap (limit ``lights_per_scene``) is counted while the file is parsed: the parser stops at the first
    light (an object with an ``id`` or a ``group``) above the cap, or at the first object above
    ``META_OBJECTS_PER_LIGHT * cap + META_OBJECTS_BASE``, so a file of 10^6 lights is refused after about
    ``cap`` of them are built (its bytes are read first: ``json_bytes`` bounds them), not after all.

    Raises:
        CorpusFileError: missing, unreadable, malformed, above a limit, or more lights than the cap (naming
            ``path``).
        ValueError: content that :func:`validate_meta` refuses (naming ``path`` and the field).
    """
    cap = limit("lights_per_scene")
    cap_objects = META_OBJECTS_PER_LIGHT * cap + META_OBJECTS_BASE
    n = [0, 0]  # lights, objects

    def count(obj: dict) -> dict:
        n[1] += 1
        if "id" in obj or "group" in obj:
            n[0] += 1
            if n[0] > cap:
                raise _TooMany(f"{path}: field 'lights' {lights_cap_message(cap, more=True)}")
        if n[1] > cap_objects:
            raise _TooMany(f"{path}: more than {cap_objects:,} JSON objects, more than a scene within the cap "
                           f"of {cap:,} lights per scene holds (raise the cap with `lfmbench --limit "
                           "lights_per_scene=N` if you mean it)")
        return obj

    try:
        m = _load_json(path, "scene metadata", count, raw)
    except _TooMany as exc:
        raise CorpusFileError(str(exc)) from None
    validate_meta(m, str(path))
    return m


def make_splits(scene_ids: Iterable[str], seed: int,
                fractions: Sequence[float] = (0.6, 0.2, 0.2)) -> dict[str, list[str]]:
    """Deterministic train / val / test split of scene ids.

    The sorted ids are shuffled with ``numpy.random.default_rng(seed)``; test gets ``round(f_test * n)``
    scenes but at least one, val ``round(f_val * n)`` (only while train keeps >= 1 scene), train the rest.

    Args:
        scene_ids: the ids (order does not matter).
        seed: integer seed.
        fractions: (train, val, test), each >= 0, summing to 1.
    """
    fr = [float(f) for f in fractions]
    if len(fr) != 3 or any(f < 0 for f in fr) or abs(sum(fr) - 1) > 1e-9:
        raise ValueError(f"fractions must be three numbers >= 0 summing to 1, got {brief(fractions)}")
    ids = sorted(set(scene_ids))
    n = len(ids)
    order = np.random.default_rng(seed).permutation(n)
    ids = [ids[i] for i in order]
    n_test = min(n, max(1, round(fr[2] * n))) if n else 0
    n_val = min(round(fr[1] * n), max(0, n - n_test - 1))
    test, val, train = ids[:n_test], ids[n_test:n_test + n_val], ids[n_test + n_val:]
    return {"train": sorted(train), "val": sorted(val), "test": sorted(test)}


_META_REQUIRED = ("scene_id", "width", "height", "bands_nm", "fps", "frames", "timing", "groups")
_TIMING_REQUIRED = ("short_exposure_s", "long_exposure_s", "capture_window_s")


def validate_meta(meta: Mapping[str, Any], where: str = "meta.json") -> None:
    """Check a scene's ``meta.json`` content; raise ``ValueError`` naming ``where`` and the field.

    Checks: required fields; image size > 0; bands strictly increasing and positive (nm); fps > 0; frames >= 1;
    ``0 < short_exposure_s <= long_exposure_s <= 1/fps`` (an exposure cannot be longer than the frame time);
    ``capture_window_s == long_exposure_s + readout_s`` (the bins must cover both windows; the capture window
    may exceed 1/fps with a rolling shutter, since row i of frame n+1 starts at t_(n+1) + i * line_time);
    bins >= 1 for per-light groups; camera ``speed_mps >= 0``; groups known by name with a boolean
    ``flicker``; lights with unique integer ids >= 0 whose group exists.
    """
    if not isinstance(meta, Mapping):
        raise ValueError(f"{where}: must be a JSON object")
    for k in _META_REQUIRED:
        if k not in meta:
            raise ValueError(f"{where}: missing field {brief(k)}")
    why = _scene_id_error(meta["scene_id"])
    if why is not None:
        raise ValueError(f"{where}: field 'scene_id': {why}")
    for k in ("width", "height", "frames"):
        v = meta[k]
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ValueError(f"{where}: field {brief(k)} must be an integer >= 1, got {brief(v)}")
    bands = meta["bands_nm"]
    if not isinstance(bands, list) or not bands:
        raise ValueError(f"{where}: field 'bands_nm' must be a non-empty list of wavelengths (nm)")
    try:
        b = np.asarray(bands, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: field 'bands_nm' must hold numbers (nm), got {brief(bands)}") from None
    if not np.isfinite(b).all() or (b <= 0).any() or (np.diff(b) <= 0).any():
        raise ValueError(f"{where}: field 'bands_nm' must be positive and strictly increasing, got {brief(bands)}")
    fps = check.get_number(meta, "fps", where, lo=0.0, lo_open=True)
    frame_time = 1.0 / fps
    t = meta["timing"]
    if not isinstance(t, Mapping):
        raise ValueError(f"{where}: field 'timing' must be an object")
    tw = f"{where} timing"
    for k in _TIMING_REQUIRED:
        check.get_number(t, k, where, "timing.", lo=0.0, lo_open=True)
    ts, tl, cw = t["short_exposure_s"], t["long_exposure_s"], t["capture_window_s"]
    readout = check.get_number(t, "readout_s", where, "timing.", lo=0.0, default=0.0)
    tol = TIMING_RTOL * frame_time
    if tl > frame_time + tol:
        raise ValueError(f"{tw}: long_exposure_s = {tl} s is longer than the frame time 1/fps = {frame_time:.6g} s")
    if ts > tl + tol:
        raise ValueError(f"{tw}: short_exposure_s = {ts} s is longer than long_exposure_s = {tl} s")
    if abs(cw - (tl + readout)) > tol:
        raise ValueError(f"{tw}: capture_window_s = {cw} s must equal long_exposure_s + readout_s = "
                         f"{tl + readout} s so that the time bins cover the exposure windows")
    if "alignment" in t and t["alignment"] != "center":
        raise ValueError(f"{tw}: alignment must be 'center', got {brief(t['alignment'])}")
    if "static_edges_s" in t:  # static time bins (format version 4): edges from 0 over both stored windows
        e = t["static_edges_s"]
        ok = isinstance(e, list) and 2 <= len(e) <= 4097 and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in e)
        if not ok or abs(e[0]) > tol or e[-1] > cw + tol or any(b <= a for a, b in zip(e[:-1], e[1:])):
            raise ValueError(f"{tw}: static_edges_s must be 2-4097 strictly increasing times (s) from 0 to at most "
                             f"capture_window_s = {cw} s, got {brief(e)}")
        sa = (tl - ts) / 2.0
        for name, a, n in (("short", sa, ts), ("long", 0.0, tl)):
            if window_bin_weights(e, a, n, tol=max(TIMING_RTOL * frame_time / n, 1e-9)) is None:
                raise ValueError(f"{tw}: static_edges_s must hold the {name} window's ends "
                                 f"({a:.6g} s, {a + n:.6g} s), got {brief(e)}")
    groups = meta["groups"]
    if not isinstance(groups, Mapping) or not groups:
        raise ValueError(f"{where}: field 'groups' must be a non-empty object")
    for name, g in groups.items():
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", str(name)) or name == "aux":
            raise ValueError(f"{where}: group name {brief(name)} must be an identifier other than 'aux'")
        if not isinstance(g, Mapping) or not isinstance(g.get("flicker"), bool):
            raise ValueError(f"{where}: groups[{brief(name)}] must be an object with a boolean 'flicker'")
        if "bins" in g and (isinstance(g["bins"], bool) or not isinstance(g["bins"], int) or g["bins"] < 0):
            raise ValueError(f"{where}: groups[{brief(name)}].bins must be an integer >= 0, got {brief(g['bins'])}")
        if g["flicker"] and "bins" not in g:
            kb = t.get("bins")
            if isinstance(kb, bool) or not isinstance(kb, int) or kb < 1:
                raise ValueError(f"{tw}: field 'bins' must be an integer >= 1 for flickering group {brief(name)}, "
                                 f"got {brief(kb)}")
    cam = meta.get("camera", {}) or {}
    if not isinstance(cam, Mapping):
        raise ValueError(f"{where}: field 'camera' must be an object, got {brief(cam)}")
    if cam.get("speed_mps") is not None:
        check.get_number(cam, "speed_mps", where, "camera.", lo=0.0)
    ids = set()
    lights = meta.get("lights", [])
    if not isinstance(lights, list):
        raise ValueError(f"{where}: field 'lights' must be a list of objects, got {brief(lights)}")
    if len(lights) > limit("lights_per_scene"):
        raise ValueError(f"{where}: field 'lights' {lights_cap_message(len(lights))}")
    for i, light in enumerate(lights):
        if not isinstance(light, Mapping):
            raise ValueError(f"{where}: lights[{i}] must be an object with 'id' and 'group', got {brief(light)}")
        lid = light.get("id")
        if isinstance(lid, bool) or not isinstance(lid, int) or lid < 0 or lid in ids:
            raise ValueError(f"{where}: lights[{i}].id must be a unique integer >= 0, got {brief(lid)}")
        ids.add(lid)
        if light.get("group") not in groups:
            raise ValueError(f"{where}: lights[{i}].group {brief(light.get('group'))} is not in groups")
        _check_light_fields(light, f"lights[{i}]", where, meta["frames"], meta["height"], meta["width"])




def _check_light_fields(light: Mapping[str, Any], name: str, where: str, frames: int, H: int, W: int) -> None:
    """The optional, informative fields of a ``meta.json`` light (``docs/guide/corpus-format.md`` section 4):
    ``kind`` non-empty str, ``instance`` int >= -1, ``luminance_cd_m2`` finite number >= 0 (cd/m^2),
    ``spectrum`` object with a str ``model``, ``bbox`` list of ``frames`` entries, each null or a half-open
    ``[y0, x0, y1, x1]`` of ints with ``0 <= y0 < y1 <= H`` and ``0 <= x0 < x1 <= W`` (px)."""
    if "kind" in light and (not isinstance(light["kind"], str) or not light["kind"]):
        check.fail(f"{name}.kind", f"must be a non-empty string, got {brief(light['kind'])}", where)
    if "instance" in light:
        check.check_integer(light["instance"], f"{name}.instance", where, lo=-1)
    if "luminance_cd_m2" in light:
        check.check_number(light["luminance_cd_m2"], f"{name}.luminance_cd_m2", where, lo=0.0)
    if "spectrum" in light:
        sp = light["spectrum"]
        if not isinstance(sp, Mapping) or not isinstance(sp.get("model"), str):
            check.fail(f"{name}.spectrum", f"must be an object with a string 'model', got {brief(sp)}", where)
    if "bbox" in light:
        bb = light["bbox"]
        if not isinstance(bb, list) or len(bb) != frames:
            check.fail(f"{name}.bbox", f"must be a list of {frames} boxes (one per frame, null = not visible), "
                       f"got {brief(bb)}", where)
        for n, b in enumerate(bb):
            if b is None:
                continue
            ok = (isinstance(b, list) and len(b) == 4
                  and all(isinstance(v, int) and not isinstance(v, bool) for v in b)
                  and 0 <= b[0] < b[2] <= H and 0 <= b[1] < b[3] <= W)
            if not ok:
                check.fail(f"{name}.bbox[{n}]", f"must be null or [y0, x0, y1, x1] integers with 0 <= y0 < y1 <= "
                           f"{H} and 0 <= x0 < x1 <= {W} (half-open, px), got {brief(b)}", where)


def _check_meta_storage(meta: Mapping[str, Any], path: Path | str) -> None:
    """Check the optional ``storage`` entry of a ``meta.json`` (format version 2); raise naming ``path``."""
    sto = meta.get("storage")
    if sto is None:
        return
    if not isinstance(sto, Mapping):
        raise CorpusFileError(f"{path}: field 'storage' must be an object")
    _check_version(sto.get("format_version"), f"{path} storage.format_version")


def _empty_manifest() -> dict:
    return {"format": FORMAT_NAME, "version": FORMAT_VERSION, "scenes": [], "files": {}}


def _check_manifest(man: Any, path: Path, *, entries: bool = True) -> dict:
    """The manifest if its format, version and (``entries``) every scene id and file entry are valid; else
    ``CorpusFileError`` naming ``path`` and the first bad entry (:func:`manifest_entry_errors`)."""
    if not isinstance(man, dict) or man.get("format") != FORMAT_NAME:
        raise CorpusFileError(f"{path}: not an lfmbench corpus manifest (format must be {brief(FORMAT_NAME)})")
    _check_version(man.get("version"), str(path))
    if not isinstance(man.get("scenes"), list) or not isinstance(man.get("files"), dict):
        raise CorpusFileError(f"{path}: 'scenes' must be a list and 'files' an object")
    if entries:
        bad = manifest_entry_errors(man, path)
        if bad:
            more = f" (and {len(bad) - 1} more bad entries)" if len(bad) > 1 else ""
            raise CorpusFileError(bad[0] + more)
    return man


def _scene_id_error(scene_id: Any) -> str | None:
    why = scene_id_error(scene_id)
    return None if why is None else f"scene_id {why}"


_DRIVE = re.compile(r"[A-Za-z]:")
_SHA256_HEX = re.compile(r"[0-9a-f]{64}")


def _file_entry_error(rel: Any, digest: Any, scenes: set, good_ids: set | None = None) -> str | None:
    """Why a manifest file entry is refused (None if it is fine): a relative POSIX path
    ``scenes/<scene id>/...`` without ``.``/``..`` components, of a listed scene, with a SHA-256 hex digest.
    ``good_ids``: scene ids found valid by earlier calls of one pass (each id is checked once)."""
    if not isinstance(rel, str) or not rel:
        return "file path must be a non-empty string"
    if rel.startswith("/") or "\\" in rel or _DRIVE.match(rel):
        return "absolute file path (must be relative to the corpus root)"
    parts = rel.split("/")
    if any(p in ("", ".", "..") for p in parts):
        return "file path with an empty, '.' or '..' component (must stay inside the corpus root)"
    if len(parts) < 3 or parts[0] != SCENES_DIR or (
            (good_ids is None or parts[1] not in good_ids) and _scene_id_error(parts[1]) is not None):
        return f"file path must lie under {SCENES_DIR}/<scene id>/"
    if good_ids is not None:
        good_ids.add(parts[1])
    if parts[1] not in scenes:
        return f"file of scene {brief(parts[1])}, which is not in 'scenes'"
    if not isinstance(digest, str) or not _SHA256_HEX.fullmatch(digest):
        return "SHA-256 must be 64 lowercase hex digits"
    return None


def manifest_entry_errors(man: Mapping[str, Any], path: Path | str, valid: dict[str, str] | None = None) -> list[str]:
    """Errors (each naming ``path`` and the entry) for manifest scene ids that are not safe directory names
    (:func:`check_scene_id`, the rule used when writing) and file entries that could leave the corpus root
    (absolute, ``..``) or are malformed. Used by :class:`Corpus` (raises on the first) and
    :func:`validate_corpus` (reports all; ``valid`` receives the file entries that are fine)."""
    out = []
    seen: dict[str, str] = {}  # casefolded id -> id: ids that one case-insensitive file system cannot tell apart
    for sid in man["scenes"]:
        why = _scene_id_error(sid)
        if why is not None:
            out.append(f"{path}: scene entry {brief(sid)} refused: {why}")
            continue
        other = seen.setdefault(sid.casefold(), sid)
        if other is not sid:
            out.append(f"{path}: scene id {brief(sid)} is listed twice" if other == sid else
                       f"{path}: scene ids {brief(other)} and {brief(sid)} differ only in case (one folder on a "
                       "case-insensitive file system)")
    scenes = {s for s in man["scenes"] if isinstance(s, str)}
    good_ids: set[str] = set()  # ids checked once (a scene has several files)
    for rel, digest in man["files"].items():
        why = _file_entry_error(rel, digest, scenes, good_ids)
        if why is not None:
            out.append(f"{path}: file entry {brief(rel)} refused: {why}")
        elif valid is not None:
            valid[rel] = digest
    return out


def inside_root(root: Path, rel: str, what: str, dirs: dict[str, Path] | None = None) -> Path:
    """``root / rel`` resolved (symbolic links followed); ``CorpusFileError`` naming ``what`` and ``rel`` when it
    leaves the resolved corpus root. ``dirs``: a cache of resolved paths (relative path -> resolved path) shared
    by the calls of one pass over a corpus: each directory is resolved once, from its resolved parent, and a
    component costs one ``lstat`` (a pass over a corpus stays linear in its files)."""
    if dirs is None:
        dirs = {}
    base = dirs.get("")
    if base is None:
        base = dirs[""] = Path(root).resolve()
    p = _resolved(base, rel, dirs)
    s, b = str(p), str(base)
    if s != b and not s.startswith(b.rstrip(os.sep) + os.sep):
        raise CorpusFileError(f"{what}: entry {brief(rel)} resolves to {p}, outside the corpus root {base}")
    return p


def _resolved(base: Path, rel: str, dirs: dict[str, Path]) -> Path:
    """``base / rel`` with symbolic links resolved, component by component from the cached parents."""
    got = dirs.get(rel)
    if got is not None:
        return got
    parent, _, name = rel.rpartition("/")
    p = (_resolved(base, parent, dirs) if parent else base) / name
    if name in ("", ".", "..") or p.is_symlink():
        p = p.resolve()
    dirs[rel] = p
    return p


def check_splits(sp: Any, path: Path | str, *, disjoint: bool = True) -> dict[str, list[str]]:
    """``splits.json`` content checked: an object whose ``train``/``val``/``test`` are lists of scene ids
    (:func:`check_scene_id`), each id in one split once (``disjoint``; :func:`validate_corpus` reports that
    itself, with the other problems); ``CorpusFileError`` naming ``path`` and the entry otherwise."""
    if not isinstance(sp, dict):
        raise CorpusFileError(f"{path}: must be a JSON object {{\"train\": [...], \"val\": [...], \"test\": "
                              f"[...]}}, got a {type(sp).__name__}")
    where: dict[str, str] = {}
    for k, ids in sp.items():
        if not isinstance(ids, list):
            raise CorpusFileError(f"{path}: split {brief(k)} must be a list of scene ids, got a {type(ids).__name__}")
        for sid in ids:
            why = _scene_id_error(sid)
            if why is not None:
                raise CorpusFileError(f"{path}: split {brief(k)} entry {brief(sid)} refused: {why}")
            first = where.get(sid) if disjoint else None
            if first == k:
                raise CorpusFileError(f"{path}: scene {brief(sid)} is listed twice in split {brief(k)}")
            if first is not None:
                raise CorpusFileError(f"{path}: a scene appears in more than one split: {brief(sid)} is in split "
                                      f"{brief(first)} and in split {brief(k)} (scored where it was trained)")
            where[sid] = k
    return sp
