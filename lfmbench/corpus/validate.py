""":func:`validate_corpus`: a full check of a corpus (missing files, checksums, channels, NaN/inf/negative
radiance, metadata consistency), used by ``lfmbench validate``.

Size (about 530 lines): one job, the corpus check, in the order it runs (manifest and listing, per-scene files,
channels, storage attributes, pixels, the parallel chunking of a large corpus); the format's own rules it applies
are imported (:mod:`lfmbench.corpus.meta`, :mod:`lfmbench.corpus.exr`), not restated.
"""
from __future__ import annotations

import hashlib
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from lfmbench.limits import brief
from lfmbench.corpus.errors import CorpusError, CorpusFileError, CorpusValueError
from lfmbench.corpus.exr import HEAD_BYTES, ExrPart, _check_aux, layer_scale, read_exr
from lfmbench.corpus.meta import (_check_manifest, _check_meta_storage, _load_json, _scene_id_error, check_splits,
                                  inside_root, load_meta, manifest_entry_errors)
from lfmbench.corpus.naming import (ATTR, AUX_CHANNELS, EMPTY_PART, MANIFEST_NAME, RADIANCE_MAX, RADIANCE_UNIT,
                                    SCENES_DIR, SPLITS_NAME, STATIC_WINDOWS, _group_bins, bin_channels, frame_dir,
                                    box_inside, group_storage, parse_light_part, static_channels, steady_channels,
                                    static_layers)
from lfmbench.fileio import TMP_PREFIX
from lfmbench.limits import LIMITS, limit, set_limit

__all__ = ["ValidationReport", "validate_corpus"]


@dataclass
class ValidationReport:
    """Result of :func:`validate_corpus`: ``errors`` (each names a file), ``warnings``, counters (``cached_files``:
    files not hashed again, ``cached_scenes``: scenes not checked again, as an earlier run found them in the
    same state: :mod:`lfmbench.corpus.validate_cache`)."""

    root: str
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    n_scenes: int = 0
    n_files: int = 0
    cached_files: int = 0
    cached_scenes: int = 0

    @property
    def ok(self) -> bool:
        return not self.errors

    def to_dict(self) -> dict:
        return {"root": self.root, "ok": self.ok, "n_scenes": self.n_scenes, "n_files": self.n_files,
                "cached_files": self.cached_files, "cached_scenes": self.cached_scenes,
                "errors": self.errors, "warnings": self.warnings}


#: Corpora of at least this many scenes are checked by several processes (``workers``); smaller ones in this
#: process (starting a worker costs ~0.5 s).
PARALLEL_FROM_SCENES = 2000
#: Scenes per task of a worker process.
CHUNK_SCENES = 500
#: Hash in chunks of this many bytes (files larger than the first chunk are read in several).
_CHUNK = 1 << 20


def validate_corpus(root: str | os.PathLike, *, check_pixels: bool = True,
                    progress: Any = None, workers: int | None = None,
                    cache: bool | str | os.PathLike = False) -> ValidationReport:
    """Check a whole corpus; never raises for corpus problems, collects them in the report.

    Checks: manifest format; ``splits.json`` (ids known, disjoint); per scene ``scene.json`` / ``meta.json``
    (:func:`validate_meta`); every expected EXR present (each frame x group, ``aux.exr`` all or none) and in
    the manifest; every manifest file present with the right SHA-256; files on disk not in the manifest
    (warning); per EXR: display window = meta size, parts / channels exactly as meta.json announces
    (``short``/``long`` x bands, or ``light<id>`` parts with K bins x bands and optional ``steady<id>`` parts
    with the bands, data windows inside the light's meta.json bbox and the image, ids of that group), and (``check_pixels``) NaN / inf / negative radiance and invalid aux values.

    Args:
        root: corpus directory.
        check_pixels: decode pixel data (slow for big corpora) in addition to headers.
        progress: optional callable ``progress(done, total)`` called after each scene (each chunk of
            :data:`CHUNK_SCENES` scenes with several workers).
        workers: processes that check scenes (default: the CPU count, at most 8, from
            :data:`PARALLEL_FROM_SCENES` scenes on; 1 below). The report is the same whatever the number. The
            workers are spawned processes: a script that calls this with several workers needs the usual
            ``if __name__ == "__main__":`` guard (or ``workers=1``).
        cache: re-check only what changed since an earlier run (:mod:`lfmbench.corpus.validate_cache`): True
            for the corpus's own cache file ``<root>/.cache/validate.bin``, a path for another one (a read-only
            corpus), False for none (every file hashed and every scene checked). The report is the same.

    Every step is linear in the number of scenes and files (sets and dicts for every lookup, one directory
    listing per folder, each file read once): ``docs/benchmarks/validate.md``.
    """
    from lfmbench.corpus import validate_cache as VC  # noqa: PLC0415

    root = Path(root)
    rep = ValidationReport(str(root))
    err = rep.errors.append
    mpath = root / MANIFEST_NAME
    if not mpath.is_file():
        err(f"{mpath}: manifest missing (not an lfmbench corpus)")
        return rep
    try:
        man = _check_manifest(_load_json(mpath, "manifest"), mpath, entries=False)
    except CorpusError as exc:
        err(str(exc))
        return rep
    files: dict[str, str] = {}  # the well-formed file entries
    rep.errors.extend(manifest_entry_errors(man, mpath, files))
    scenes = list(dict.fromkeys(s for s in man["scenes"] if _scene_id_error(s) is None))  # unique, in order
    scene_set = set(scenes)  # every membership test below is O(1): validate is linear in scenes and files
    rep.n_scenes = len(scenes)
    rep.n_files = len(man["files"])
    by_scene: dict[str, dict[str, str]] = {s: {} for s in scenes}  # the listed files of each scene
    for rel, digest in files.items():
        by_scene[rel.split("/", 2)[1]][rel] = digest
    # splits
    spath = root / SPLITS_NAME
    if not spath.is_file():
        err(f"{spath}: missing")
    else:
        try:
            sp = check_splits(_load_json(spath, "splits file"), spath, disjoint=False)
            ids = [s for k in ("train", "val", "test") for s in sp.get(k, [])]
            if set(sp) != {"train", "val", "test"}:
                err(f"{spath}: keys must be train, val, test; got {sorted(sp)}")
            if len(ids) != len(set(ids)):
                try:
                    check_splits(sp, spath)  # names the first scene listed twice, and its splits
                except CorpusError as exc:
                    err(str(exc))
            unknown = sorted(set(ids) - scene_set)
            if unknown:
                err(f"{spath}: scenes not in the manifest: {unknown[:5]}")
            unsplit = sorted(scene_set - set(ids))
            if unsplit:
                rep.warnings.append(f"{spath}: scenes in no split: {unsplit[:5]}")
        except CorpusError as exc:
            err(str(exc))
    # files on disk not in the manifest, outside the scene folders of the manifest (those: per scene, below)
    sroot = root / SCENES_DIR
    if sroot.is_dir():
        with os.scandir(sroot) as it:
            top = sorted(it, key=lambda e: e.name)
        for e in top:
            if e.is_dir(follow_symlinks=False) and e.name in scene_set:
                continue
            if e.is_dir(follow_symlinks=False):
                for rel, kind in _walk(e.path, f"{SCENES_DIR}/{e.name}"):
                    if kind in "fl" and rel.rpartition("/")[2].startswith(TMP_PREFIX) and \
                            os.path.isfile(root / rel):
                        rep.warnings.append(f"{root / rel}: temporary file of an interrupted run")
            elif e.is_file():
                if e.name.startswith(TMP_PREFIX):
                    rep.warnings.append(f"{e.path}: temporary file of an interrupted run")
                elif e.name in scene_set:
                    rep.warnings.append(f"{e.path}: not in manifest")
        for e in top:
            if e.is_dir() and e.name not in scene_set:
                rep.warnings.append(f"{e.path}: incomplete scene (not in manifest; re-run the render to finish it)")
    # per scene: checksums of its listed files, then its own checks (in scene order, whatever the workers)
    order = sorted(scenes)
    n_workers = workers if workers is not None else (min(os.cpu_count() or 1, 8)
                                                     if len(order) >= PARALLEL_FROM_SCENES else 1)
    cpath = None if cache is False else (VC.default_cache_path(root) if cache is True else Path(cache))
    vc = VC.ValidateCache(cpath, VC.max_cache_bytes(len(files), len(scenes)))
    ctx = VC.context() if cpath is not None else b""
    if n_workers <= 1:
        dirs: dict[str, Path] = {}  # resolved directories, shared by every inside_root call of this pass
        for i, sid in enumerate(order):
            _check_scene(root, mpath, sid, by_scene[sid], rep, check_pixels, dirs, vc if cpath else None, ctx)
            if progress is not None:
                progress(i + 1, len(order))
        vc.save()
        return rep
    import multiprocessing  # noqa: PLC0415
    from concurrent.futures import ProcessPoolExecutor  # noqa: PLC0415

    chunks = [order[k:k + CHUNK_SCENES] for k in range(0, len(order), CHUNK_SCENES)]
    lim = {name: limit(name) for name in LIMITS}  # limits raised in this process hold in the workers too
    with ProcessPoolExecutor(n_workers, mp_context=multiprocessing.get_context("spawn"), initializer=_init_worker,
                             initargs=(lim, vc.keys if cpath else None, vc.fresh_ns, ctx)) as ex:
        futs = [ex.submit(_check_chunk, str(root), ch, {s: by_scene[s] for s in ch}, check_pixels)
                for ch in chunks]
        done = 0
        for ch, fut in zip(chunks, futs):
            errors, warnings, used, added, counts = fut.result()
            rep.errors.extend(errors)
            rep.warnings.extend(warnings)
            rep.cached_files += counts[0]
            rep.cached_scenes += counts[1]
            vc.merge(used, added)
            done += len(ch)
            if progress is not None:
                progress(done, len(order))
    vc.save()
    return rep


_WORKER: dict[str, Any] = {}


def _init_worker(lim: dict[str, int], keys: set[bytes] | None, fresh_ns: int, ctx: bytes) -> None:
    """A worker process of :func:`validate_corpus`: the run's limits, and its cache keys (None: no cache)."""
    from lfmbench.corpus.validate_cache import ValidateCache  # noqa: PLC0415

    for name, v in lim.items():
        set_limit(name, v)
    vc = None
    if keys is not None:
        vc = ValidateCache(None, keys=keys)
        vc.fresh_ns = fresh_ns
    _WORKER.update(cache=vc, ctx=ctx)


def _check_chunk(root: str, sids: list[str], listed: dict[str, dict[str, str]],
                 check_pixels: bool) -> tuple[list[str], list[str], list[bytes], list[bytes], tuple[int, int]]:
    """:func:`_check_scene` of scenes ``sids`` in a worker process: ``(errors, warnings, used keys, added keys,
    (cached files, cached scenes))``."""
    rep = ValidationReport(root)
    dirs: dict[str, Path] = {}
    vc = _WORKER.get("cache")
    if vc is not None:
        vc.used, vc.added = set(), set()
    for sid in sids:
        _check_scene(Path(root), Path(root) / MANIFEST_NAME, sid, listed[sid], rep, check_pixels, dirs, vc,
                     _WORKER.get("ctx", b""))
    return (rep.errors, rep.warnings, list(vc.used) if vc else [], list(vc.added) if vc else [],
            (rep.cached_files, rep.cached_scenes))


def _walk(top: str, rel: str) -> list[tuple[str, str]]:
    """Every entry under folder ``top`` (corpus path ``rel``) as ``(corpus path, kind)``, kind ``d`` folder, ``f``
    regular file, ``l`` symbolic link, ``o`` anything else; in path order (as a sort by path components), one
    directory listing per folder, no ``stat``. Folders behind symbolic links are not entered."""
    out: list[tuple[str, str]] = []
    try:
        with os.scandir(top) as it:
            entries = sorted(it, key=lambda e: e.name)
    except OSError:
        return out
    for e in entries:
        r = f"{rel}/{e.name}"
        if e.is_dir(follow_symlinks=False):
            out.append((r, "d"))
            out.extend(_walk(e.path, r))
        else:
            out.append((r, "l" if e.is_symlink() else "f" if e.is_file(follow_symlinks=False) else "o"))
    return out


def _hash_head(path: str, size: int, keep: int) -> tuple[str, bytes]:
    """SHA-256 (hex) of the file ``path`` of ``size`` bytes and its first ``keep`` bytes, in one pass over it (one
    ``read`` call for a file of at most 1 MiB)."""
    h = hashlib.sha256()
    head = b""
    with open(path, "rb", buffering=0) as fh:
        b = fh.read(size + 1 if size < _CHUNK else _CHUNK)
        while b:
            h.update(b)
            if len(head) < keep:
                head += b[:keep - len(head)]
            if len(b) == size < _CHUNK:  # asked for one byte more than its size: the end of the file
                break
            b = fh.read(_CHUNK)
    return h.hexdigest(), head


def _check_scene(root: Path, mpath: Path, sid: str, listed: Mapping[str, str], rep: ValidationReport,
                 check_pixels: bool, dirs: dict[str, Path], cache: Any = None, ctx: bytes = b"") -> None:
    """Scene ``sid``: its folder listed once (files not in the manifest: warnings), its listed files (inside the
    root, present, their SHA-256: skipped for a file whose key ``cache`` holds), then its own checks (skipped
    when ``cache`` holds the scene's key: nothing in its folder changed since a run found it clean)."""
    err = rep.errors.append
    n_err = len(rep.errors)
    rel0 = f"{SCENES_DIR}/{sid}"
    rs = str(root)  # paths as text: the same names as Path gives, without its cost per scene
    sdir = f"{rs}/{SCENES_DIR}/{sid}"
    tree: dict[str, str] | None = None  # corpus path -> kind, for a scene folder that is a real folder
    try:
        if stat.S_ISDIR(os.lstat(sdir).st_mode):
            inside_root(root, rel0, str(mpath), dirs)  # (the root or scenes/ may be links)
            tree = dict(_walk(sdir, rel0))
    except (OSError, CorpusFileError):
        pass  # the slow path below reports it, file by file as before
    if tree is not None:
        for rel, kind in tree.items():
            if kind in "fl" and (kind == "f" or os.path.isfile(f"{rs}/{rel}")):
                if rel.rpartition("/")[2].startswith(TMP_PREFIX):
                    rep.warnings.append(f"{rs}/{rel}: temporary file of an interrupted run")
                elif rel not in listed:
                    rep.warnings.append(f"{rs}/{rel}: not in manifest")
    heads: dict[str, bytes] = {}  # corpus path -> the bytes read while hashing (JSON whole, EXR the first 64 KiB)
    keys: list[bytes] | None = [] if cache is not None and tree is not None else None
    json_cap = limit("json_bytes")
    for rel, digest in listed.items():
        p = f"{rs}/{rel}"
        if tree is not None and tree.get(rel) == "f":  # found by the listing: inside the checked scene folder
            try:
                st = os.lstat(p)
            except OSError:
                st = None
        else:
            keys = None  # a link, or not there: the slow path, and no scene verdict from the cache
            try:
                inside_root(root, rel, str(mpath), dirs)
            except CorpusFileError as exc:
                err(str(exc))
                continue
            st = os.stat(p) if os.path.isfile(p) else None
        if st is None:
            err(f"{p}: missing (listed in manifest)")
            keys = None
            continue
        key = cache.file_key(rel, st, digest) if cache is not None else None
        if key is not None and cache.has(key):
            rep.cached_files += 1
            if keys is not None:
                keys.append(key)
            continue
        try:
            got, head = _hash_head(p, st.st_size, json_cap if rel.endswith(".json") else HEAD_BYTES)
        except OSError as exc:
            err(f"{p}: cannot be read ({exc.strerror or exc})")
            keys = None
            continue
        if got != digest:
            err(f"{p}: bad checksum (SHA-256 differs from manifest)")
            keys = None
            continue
        if rel.endswith(".exr") or len(head) == st.st_size:  # a JSON file: only whole (and within json_bytes)
            heads[rel] = head
        if key is not None and cache.settled(st):
            cache.add(key)
            if keys is not None:
                keys.append(key)
        else:
            keys = None
    try:
        inside_root(root, rel0, str(mpath), dirs)
    except CorpusFileError as exc:
        err(str(exc))
        return
    level = "pixels" if check_pixels else "headers"
    skey = None
    if keys is not None and len(rep.errors) == n_err:
        skey = cache.scene_key(ctx, level, sid, keys, (f"{r}\0{k}" for r, k in tree.items()))
        if cache.has(skey) or (not check_pixels and cache.has(cache.scene_key(ctx, "pixels", sid, keys, (
                f"{r}\0{k}" for r, k in tree.items())))):
            rep.cached_scenes += 1
            return
    _validate_scene(root, sid, listed, rep, check_pixels, tree, heads)
    if skey is not None and len(rep.errors) == n_err:
        cache.add(skey)


def _validate_scene(root: Path, sid: str, files: Mapping[str, str], rep: ValidationReport,
                    check_pixels: bool, tree: Mapping[str, str] | None = None,
                    heads: Mapping[str, bytes] | None = None) -> None:
    """The checks of one scene against its ``meta.json``. ``tree``: its folder's entries (corpus path -> kind,
    :func:`_walk`), so that a present file costs no ``stat``; ``heads``: bytes of its files read already."""
    err = rep.errors.append
    heads = heads or {}
    rs = str(root)
    sdir = f"{rs}/{SCENES_DIR}/{sid}"
    rel0 = f"{SCENES_DIR}/{sid}"

    def present(rel: str) -> bool:
        kind = tree.get(rel) if tree is not None else "?"
        return kind == "f" or (kind in ("l", "?") and os.path.isfile(f"{rs}/{rel}"))

    for name in ("scene.json", "meta.json"):
        if f"{rel0}/{name}" not in files:
            err(f"{sdir}/{name}: not in manifest")
    if not present(f"{rel0}/scene.json"):
        err(f"{sdir}/scene.json: missing")
    else:
        try:
            sc = _load_json(Path(f"{sdir}/scene.json"), "scene description", raw=heads.get(f"{rel0}/scene.json"))
            if not isinstance(sc, dict):
                err(f"{sdir}/scene.json: must hold a JSON object (free-form content), got a {type(sc).__name__}")
        except CorpusError as exc:
            err(str(exc))
    mp = f"{sdir}/meta.json"
    try:
        meta = load_meta(mp, heads.get(f"{rel0}/meta.json"))
        _check_meta_storage(meta, mp)
    except (CorpusError, ValueError) as exc:
        err(str(exc))
        return
    if meta["scene_id"] != sid:
        err(f"{mp}: scene_id {brief(meta['scene_id'])} != directory name {brief(sid)}")
    H, W, bands = meta["height"], meta["width"], meta["bands_nm"]
    aux_frames = [n for n in range(meta["frames"]) if f"{rel0}/{frame_dir(n)}/aux.exr" in files
                  or present(f"{rel0}/{frame_dir(n)}/aux.exr")]
    if aux_frames and len(aux_frames) != meta["frames"]:
        miss = sorted(set(range(meta["frames"])) - set(aux_frames))
        err(f"{sdir}: aux.exr missing for frames {miss}")
    light_ids = {}
    bbox_of = {}  # light id -> per-frame box (half-open) or None, where meta.json gives one
    for lt in meta.get("lights", []):
        light_ids.setdefault(lt["group"], set()).add(lt["id"])
        if "bbox" in lt:
            bbox_of[lt["id"]] = lt["bbox"]
    for n in range(meta["frames"]):
        for g in list(meta["groups"]) + (["aux"] if n in aux_frames else []):
            rel = f"{rel0}/{frame_dir(n)}/{g}.exr"
            p = f"{rs}/{rel}"
            if not present(rel):
                if rel not in files:  # listed-but-missing files were already reported
                    err(f"{p}: missing")
                continue
            if rel not in files:
                err(f"{p}: not in manifest")
            try:
                parts = read_exr(p, header_only=not check_pixels, head=heads.get(rel))
            except CorpusError as exc:
                err(str(exc))
                continue
            for part in parts:
                if part.size != (H, W):
                    err(f"{p} part {brief(part.name)}: display window {part.size} != meta.json ({H}, {W})")
            if g == "aux":
                _validate_channels(p, parts[0], set(AUX_CHANNELS), rep)
                if check_pixels and parts[0].channels is not None:
                    for name in AUX_CHANNELS:
                        if name in parts[0].channels:
                            try:
                                _check_aux(name, np.asarray(parts[0].channels[name]), str(p))
                            except CorpusValueError as exc:
                                err(str(exc))
                continue
            if group_storage(meta, g) == "static":
                if len(parts) != 1:
                    err(f"{p}: static group must have exactly one part, has {len(parts)}")
                layers = static_layers(meta)  # short / long, or the static time bins (format version 4)
                want = {c for w in layers for c in static_channels(w, bands)}
                _validate_channels(p, parts[0], want, rep)
                if parts[0].window != (0, 0, H, W):
                    err(f"{p}: data window {parts[0].window} must cover the whole image")
                for w in layers:
                    _validate_storage_attrs(p, parts[0], w, rep)
                _validate_pixels(p, parts[0], rep, check_pixels)
            else:
                K = _group_bins(meta, g)
                want = {c for row in bin_channels(K, bands) for c in row}
                ids = light_ids.get(g, set())
                if len(parts) == 1 and parts[0].name == EMPTY_PART:
                    shown = [lid for lid in sorted(ids) if bbox_of.get(lid, [None] * (n + 1))[n] is not None]
                    if shown:
                        err(f"{p}: no light is stored but meta.json bbox[{n}] of lights {shown} is not null")
                    continue
                have_parts, have_steady = set(), set()
                for part in parts:
                    kind = parse_light_part(part.name)
                    if kind is None:
                        err(f"{p}: unexpected part name {brief(part.name)} (want light<id> or steady<id>)")
                        continue
                    lid, steady = kind
                    if lid not in ids:
                        err(f"{p}: part {brief(part.name)} is not a light of group {brief(g)} in meta.json")
                    (have_steady if steady else have_parts).add(lid)
                    bbs = bbox_of.get(lid)
                    y0, x0, y1, x1 = part.window
                    if bbs is not None and bbs[n] is None:
                        err(f"{p}: part {brief(part.name)} is stored but meta.json bbox[{n}] is null (not visible)")
                    elif bbs is not None and not box_inside(part.window, bbs[n]):
                        err(f"{p}: part {brief(part.name)} data window {part.window} is not inside meta.json "
                            f"bbox[{n}] {bbs[n]} (half-open (y0, x0, y1, x1))")
                    if not (0 <= y0 < y1 <= H and 0 <= x0 < x1 <= W):
                        err(f"{p}: part {brief(part.name)} data window {part.window} outside the {H}x{W} image")
                    _validate_channels(p, part, set(steady_channels(bands)) if steady else want, rep)
                    _validate_storage_attrs(p, part, None, rep)
                    _validate_pixels(p, part, rep, check_pixels)
                for lid in sorted(have_steady - have_parts):
                    err(f"{p}: part 'steady{lid}' without its part 'light{lid}'")
                for lid in sorted(ids - have_parts):
                    bb = bbox_of.get(lid, [None] * (n + 1))[n]
                    if bb is not None:
                        err(f"{p}: meta.json bbox[{n}] of light {lid} is {bb} but the file has no part "
                            f"'light{lid}' (null bbox = not visible)")


def _validate_channels(p: str | Path, part: ExrPart, want: set[str], rep: ValidationReport) -> None:
    have = set(part.channel_names)
    missing, extra = sorted(want - have), sorted(have - want)
    if missing:
        rep.errors.append(f"{p} part {brief(part.name)}: missing channels {missing[:4]}"
                          f"{' ...' if len(missing) > 4 else ''} ({len(missing)} in all)")
    if extra:
        rep.errors.append(f"{p} part {brief(part.name)}: unexpected channels {extra[:4]}"
                          f"{' ...' if len(extra) > 4 else ''} ({len(extra)} in all)")


def _validate_storage_attrs(p: str | Path, part: ExrPart, window: str | None, rep: ValidationReport) -> None:
    """Format-version-2 attributes: the layer's scale (a power of two) and ``lfmbench_mantissa_bits``."""
    try:
        layer_scale(part, window, p)
    except CorpusFileError as exc:
        rep.errors.append(str(exc))
    mb = part.header.get(ATTR["mantissa"])
    if mb is not None and (isinstance(mb, bool) or not isinstance(mb, int) or not 1 <= mb <= 23):
        rep.errors.append(f"{p} part {brief(part.name)}: attribute {ATTR['mantissa']} = {brief(mb)} must be an integer "
                          "in [1, 23]")


def _validate_pixels(p: str | Path, part: ExrPart, rep: ValidationReport, check_pixels: bool) -> None:
    if not check_pixels or part.channels is None:
        return
    n_nan = n_inf = n_neg = n_big = 0
    peak = 0.0
    for name, a in part.channels.items():
        a = np.asarray(a, dtype=np.float32)
        n_nan += int(np.isnan(a).sum())
        n_inf += int(np.isinf(a).sum())
        n_neg += int((a < 0).sum())
        window = name.split(".", 1)[0]
        try:
            scale = layer_scale(part, window if window in STATIC_WINDOWS else None, p)
        except CorpusFileError:  # reported by _validate_storage_attrs
            continue
        fin = a[np.isfinite(a)]
        if fin.size:
            big = fin.astype(np.float64) / scale > RADIANCE_MAX
            n_big += int(big.sum())
            peak = max(peak, float(fin.max()) / scale)
    for n, what in ((n_nan, "NaN"), (n_inf, "inf"), (n_neg, "negative")):
        if n:
            rep.errors.append(f"{p} part {brief(part.name)}: {n} {what} radiance values")
    if n_big:
        rep.errors.append(f"{p} part {brief(part.name)}: {n_big} radiance values above the plausibility ceiling "
                          f"RADIANCE_MAX = {RADIANCE_MAX:.0e} {RADIANCE_UNIT} (max {peak:.3g}): a unit or scale "
                          "error")
