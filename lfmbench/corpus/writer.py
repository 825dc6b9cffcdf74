"""Writing a corpus: :func:`encode_scene` (pure encoding, usable in render workers), :func:`write_files`
(atomic writes: temporary name in the same directory, then :func:`os.replace`), :class:`ThreadedSceneWriter`
(both in a worker thread, fed one frame at a time while the caller renders the next) and :class:`CorpusWriter`
(finished scenes recorded in an append-only journal that is folded into the manifest, rewritten atomically, as
the corpus grows; resume support).
"""
from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import re
import socket
import threading
from concurrent.futures import Executor, ThreadPoolExecutor
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np

from lfmbench.check import check_scene_id
from lfmbench.corpus.exr import encode_aux_exr, encode_lights_exr, encode_static_exr
from lfmbench.corpus.meta import _check_manifest, _empty_manifest, _load_json, make_splits, sha256_file, validate_meta
from lfmbench.corpus.naming import (ATTR, FORMAT_VERSION, MANIFEST_NAME, SCENES_DIR, SPLITS_NAME, _group_bins,
                                    STATIC_BINS_VERSION, static_edges,
                                    frame_dir, group_storage)
from lfmbench.corpus.errors import CorpusError, CorpusLockedError
from lfmbench.corpus.storage import DEFAULT_STORAGE, Storage, StorageStats, resolve_storage
from lfmbench.fileio import TMP_PREFIX, atomic_write_bytes, atomic_write_json, json_default, pid_alive

__all__ = ["CorpusWriter", "prune_scene_dir", "encode_scene", "write_files", "ThreadedSceneWriter",
           "ENCODE_THREADS", "LOCK_NAME", "JOURNAL_NAME", "COMPACT_FRACTION", "CorpusLockedError", "CorpusLock",
           "check_ours", "is_own_file"]

log = logging.getLogger(__name__)

#: The writer lock of a corpus root: a file locked with ``flock`` while a :class:`CorpusWriter` has the corpus
#: open, holding ``pid <pid> host <host>`` of the holder (for the message a second writer gets). The kernel
#: releases the lock when the holder exits, however it exits: a lock file left by a dead process is taken over.
LOCK_NAME = ".lfmbench.lock"
#: The manifest journal of a corpus root: one JSON line per scene committed (``{"commit": id, "files": {path:
#: sha256}}``) or forgotten (``{"forget": id}``) since ``manifest.json`` was last written, appended and fsync'ed
#: per scene by :class:`CorpusWriter`, folded into the manifest (and removed) by
#: :meth:`CorpusWriter.write_manifest`.
#: Left behind only by a killed writer; the next writer replays it (a torn last line, from a kill in the middle
#: of an append, is a scene not committed).
JOURNAL_NAME = ".lfmbench.journal"
#: The manifest is rewritten once the journal holds this fraction of the manifest's scenes (at least one
#: scene): each rewrite costs O(scenes), so a scene costs O(1) amortized, whatever the size of the corpus.
COMPACT_FRACTION = 1 / 8
#: Files of a scene directory that the corpus format owns (``docs/guide/corpus-format.md``): only these are ever
#: deleted (when a re-render no longer writes them); anything else a user put there stays.
_OWN_SCENE_FILE = re.compile(r"(scene\.json|meta\.json|f\d{3,}/[A-Za-z][A-Za-z0-9_]*\.exr)")


#: Locks this process holds: resolved lock path -> [fd, number of CorpusLock objects sharing it]. The lock is
#: one writer *process* per corpus; writers of one process (a library user, a test) share it.
_HELD: dict[str, list] = {}
_HELD_LOCK = threading.Lock()


class CorpusLock:
    """The one-writer lock of a corpus root (:data:`LOCK_NAME`): ``flock`` on the lock file, held until
    :meth:`release` or process exit. Where the file system has no ``flock`` (some network mounts), the pid and
    host in the file decide: a holder on this host whose pid is gone is stale and taken over. Writers in one
    process share the lock (it keeps other processes out)."""

    def __init__(self, root: str | os.PathLike) -> None:
        self.path = Path(root) / LOCK_NAME
        self.fd: int | None = None
        self._key = str(self.path.resolve())
        with _HELD_LOCK:
            held = _HELD.get(self._key)
            if held is not None:
                held[1] += 1
                self.fd = held[0]
                return
            self._acquire()
            _HELD[self._key] = [self.fd, 1]

    def _acquire(self) -> None:
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            import fcntl  # noqa: PLC0415 - POSIX only

            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise CorpusLockedError(self._busy(self._holder(fd))) from None
            except OSError as exc:
                if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS):
                    raise
                self._check_pid(fd)
        except BaseException:
            os.close(fd)
            raise
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} host {socket.gethostname()}\n".encode(), 0)
        self.fd = fd

    @staticmethod
    def _holder(fd: int) -> str:
        return os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "unknown holder"

    def _busy(self, holder: str) -> str:
        root = self.path.parent
        return (f"corpus {root} is being written by another lfmbench process ({holder}; lock {self.path}): "
                "wait for it to finish, or render into another --out folder")

    def _check_pid(self, fd: int) -> None:
        m = re.fullmatch(r"pid (\d+) host (\S+)", self._holder(fd))
        if m and int(m.group(1)) != os.getpid() and (m.group(2) != socket.gethostname()
                                                      or pid_alive(int(m.group(1)))):
            raise CorpusLockedError(self._busy(m.group(0)))

    def release(self) -> None:
        """Release the lock (the file stays; the next writer takes it over)."""
        if self.fd is None:
            return
        with _HELD_LOCK:
            fd, self.fd = self.fd, None
            held = _HELD.get(self._key)
            if held is not None and held[0] == fd:
                held[1] -= 1
                if held[1] > 0:
                    return
                del _HELD[self._key]
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
            os.close(fd)

    def __del__(self) -> None:
        self.release()


def check_ours(root: Path) -> None:
    """Refuse to write into a folder that is neither empty nor an lfmbench corpus: with no ``manifest.json``,
    only the lock file and temporary files of a killed first run (:data:`TMP_PREFIX`) may be there.
    ``CorpusError`` naming the folder and the first foreign entry."""
    if (root / MANIFEST_NAME).exists() or not root.is_dir():
        return
    for p in sorted(root.iterdir()):
        if p.name != LOCK_NAME and not p.name.startswith(TMP_PREFIX):
            raise CorpusError(f"{root} is not empty and is not an lfmbench corpus (no {MANIFEST_NAME}; first "
                              f"foreign entry: {p.name}): render into an empty or new folder, or into a corpus")


def is_own_file(rel: str, scene_id: str) -> bool:
    """True when ``rel`` (a path relative to the corpus root) is a file name the corpus format gives to files of
    scene ``scene_id``: ``scenes/<id>/scene.json``, ``meta.json`` or ``f<NNN>/<group>.exr``."""
    prefix = f"{SCENES_DIR}/{scene_id}/"
    return rel.startswith(prefix) and _OWN_SCENE_FILE.fullmatch(rel[len(prefix):]) is not None


class CorpusWriter:
    """Write an lfmbench corpus atomically, scene by scene.

    Every file goes through :func:`atomic_write_bytes` (temp file in the same directory + :func:`os.replace`);
    a scene is committed only after all its files are on disk, so a crash or Ctrl-C leaves the corpus valid: the
    unfinished scene is simply absent and is redone on resume. Stray temporary files of a killed run are removed
    when a writer opens the corpus.

    A commit appends one line to the journal :data:`JOURNAL_NAME` (fsync'ed); ``manifest.json`` is rewritten
    (atomically, then ``on_compact()`` is called, e.g. to rewrite ``splits.json``) when the journal holds
    :data:`COMPACT_FRACTION` of the manifest's scenes, and by :meth:`write_manifest` / :meth:`close`. So a
    scene costs the same whatever the corpus's size (the manifest of a 100,000-scene corpus is not rewritten per
    scene), and small corpora still get a manifest rewrite per scene. A writer killed at any point leaves
    ``manifest.json`` describing complete scenes (at most 1/8 of the corpus behind) and the journal with the
    rest; the next writer (a resume) replays the journal first.

    Args:
        root: corpus directory (created if needed).
        dtype: storage of the radiance layers: a name of :data:`STORAGES` or a :class:`Storage`. Default
            ``"compact"`` (HALF x per-layer 2^e, mantissas rounded to 5 bits: <= 2^-6 ~ 1.6 % relative per value,
            PIZ); ``"float16"`` (HALF x 2^e, 10 bits, <= 2^-11); ``"float32"`` (lossless FLOAT, as version 1).
        render: optional dict of the options the corpus is rendered with, stored in the manifest as
            ``"render"``; re-opening with different options raises ``ValueError`` (resume safety).
    """

    def __init__(self, root: str | os.PathLike, *, dtype: str | Storage = DEFAULT_STORAGE,
                 render: Mapping[str, Any] | None = None) -> None:
        self.root = Path(root)
        self.storage = resolve_storage(dtype)
        self.dtype = dtype
        if self.root.exists() and not self.root.is_dir():
            raise ValueError(f"corpus root {self.root} exists and is not a directory")
        check_ours(self.root)
        self.root.mkdir(parents=True, exist_ok=True)
        self._lock = CorpusLock(self.root)  # one writer per corpus; released by close() or at exit
        check_ours(self.root)  # again under the lock: a folder filled meanwhile is still refused
        mpath = self.root / MANIFEST_NAME
        self.on_compact: Any = None
        self._journal = self.root / JOURNAL_NAME
        self._pending = 0  # journal lines since the manifest was written
        if mpath.exists():
            man = _check_manifest(_load_json(mpath, "manifest"), mpath)
            # version-2 readers read version-1 files: new scenes may join an old corpus, which becomes version 2
            man["version"] = FORMAT_VERSION
        else:
            man = _empty_manifest()
        self._head = {k: v for k, v in man.items() if k not in ("scenes", "files")}  # format, version, render
        self._index: dict[str, dict[str, str]] = {sid: {} for sid in man["scenes"]}  # scene -> its files
        for rel, digest in man["files"].items():
            self._index.setdefault(rel.split("/", 2)[1], {})[rel] = digest
        replayed = self._replay()
        if replayed or not mpath.exists():
            self.write_manifest()  # an empty corpus is a valid corpus; a killed writer's journal is folded in
        if render is not None:
            render = json.loads(json.dumps(dict(render), default=json_default))
            old = self._head.get("render")
            if old is not None and old != render:
                diff = sorted(k for k in set(old) | set(render) if old.get(k) != render.get(k))
                raise ValueError(f"corpus {self.root} was rendered with different options ({', '.join(diff)}); "
                                 "use a new --out directory or the original options to resume")
            if old is None:
                self._head["render"] = render
                self.write_manifest()
        self.notes: list[str] = []
        self.cleanup_temp()

    def close(self) -> None:
        """Fold the journal into the manifest (:meth:`flush`) and release the writer lock (the lock is also
        released at process exit; a journal left then is replayed by the next writer)."""
        try:
            self.flush()
        finally:
            self._lock.release()

    def flush(self) -> None:
        """:meth:`write_manifest` if the journal holds scenes the manifest does not."""
        if self._pending:
            self.write_manifest()

    @property
    def manifest(self) -> dict:
        """The manifest as :meth:`write_manifest` writes it now (scenes and files sorted; a new dict)."""
        files = {rel: d for sid in self._index for rel, d in self._index[sid].items()}
        return {**self._head, "scenes": sorted(self._index), "files": dict(sorted(files.items()))}

    def _replay(self) -> int:
        """Apply the journal of a killed writer to the scene index; returns the number of lines applied. A torn
        last line is dropped (its scene was not committed); a bad line before it is a ``CorpusError`` naming the
        journal (the file is kept for inspection)."""
        if not self._journal.is_file() or self._journal.is_symlink():
            return 0
        from lfmbench.corpus.meta import _file_entry_error  # noqa: PLC0415
        from lfmbench.fileio import InputFileError, loads_json, read_bytes  # noqa: PLC0415
        from lfmbench.limits import LimitError  # noqa: PLC0415

        try:
            raw = read_bytes(self._journal, "manifest journal", "manifest_bytes")
        except (OSError, LimitError) as exc:
            raise CorpusError(f"{self._journal}: cannot read the manifest journal of an earlier run ({exc})") \
                from None
        lines = raw.split(b"\n")
        complete, torn = lines[:-1], lines[-1]  # a last line without its newline was cut by a kill
        n = 0
        for k, line in enumerate(complete):
            try:
                e = loads_json(line, f"{self._journal} line {k + 1}")
                sid = e.get("commit", e.get("forget")) if isinstance(e, dict) else None
                check_scene_id(sid, "scene id", f"{self._journal} line {k + 1}")
                if "commit" in e:
                    files = e.get("files")
                    bad = next((f"{rel}: {why}" for rel, d in (files.items() if isinstance(files, dict) else ())
                                if (why := _file_entry_error(rel, d, {sid})) is not None
                                or not rel.startswith(f"{SCENES_DIR}/{sid}/")), None)
                    if not isinstance(files, dict) or not files or bad:
                        raise ValueError(f"{self._journal} line {k + 1}: bad file entries ({bad or files!r:.80})")
                    self._index[sid] = dict(files)
                else:
                    self._index.pop(sid, None)
            except (ValueError, InputFileError) as exc:
                raise CorpusError(f"{exc} (the manifest journal of a killed writer; move it away to start the "
                                  "scenes it lists again)") from None
            n += 1
        return n + (1 if torn else 0)

    def _log(self, entry: Mapping[str, Any]) -> None:
        """Append ``entry`` to the journal (one line, fsync'ed), then rewrite the manifest when the journal holds
        :data:`COMPACT_FRACTION` of its scenes."""
        from lfmbench.fileio import AtomicWriteError, _why  # noqa: PLC0415

        line = (json.dumps(entry, separators=(",", ":")) + "\n").encode()
        try:
            fd = os.open(self._journal, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o644)
            try:
                os.write(fd, line)  # one write of a few KB: appended whole, or torn (a kill) and dropped on replay
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError as exc:
            raise AtomicWriteError(exc.errno, f"could not write {self._journal}: {_why(exc)}") from None
        self._pending += 1
        if self._pending >= max(1, int(len(self._index) * COMPACT_FRACTION)):
            self.write_manifest()

    def __enter__(self) -> "CorpusWriter":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def cleanup_temp(self, scene_id: str | None = None) -> int:
        """Remove temporary files (our :data:`TMP_PREFIX` names) that an interrupted run left in the corpus root,
        its scene directories and its cache (``scene_id``: only those of that scene's folder, e.g. after its render
        worker died while others still write theirs); returns how many were removed. Nothing else is touched."""
        n = 0
        if scene_id is None:
            where = [self.root.glob(TMP_PREFIX + "*")] + [(self.root / d).rglob(TMP_PREFIX + "*")
                                                          for d in (SCENES_DIR, ".cache") if (self.root / d).is_dir()]
        else:
            where = [(self.root / SCENES_DIR / check_scene_id(scene_id)).rglob(TMP_PREFIX + "*")]
        for it in where:
            for p in it:
                if p.is_file() and not p.is_symlink():
                    with contextlib.suppress(OSError):
                        p.unlink()
                        n += 1
        return n

    @property
    def scenes(self) -> list[str]:
        return sorted(self._index)

    def _rel(self, path: Path) -> str:
        return path.relative_to(self.root).as_posix()

    def is_complete(self, scene_id: str, *, verify: bool = True) -> bool:
        """True when the scene is committed and (``verify``) all its files exist with their SHA-256."""
        files = self._index.get(scene_id)
        if not files:
            return False
        if not verify:
            return True
        for rel, digest in files.items():
            p = self.root / rel
            if not p.is_file() or sha256_file(p) != digest:
                return False
        return True

    def write_manifest(self) -> None:
        """Rewrite ``manifest.json`` atomically (scenes and files sorted) from the committed scenes, remove the
        journal it now holds, then call ``on_compact()`` if set. A kill between the rewrite and the removal
        leaves a journal whose replay changes nothing (each line sets or drops one scene)."""
        atomic_write_json(self.root / MANIFEST_NAME, self.manifest)
        if self._pending or self._journal.is_file():
            with contextlib.suppress(FileNotFoundError):
                if not self._journal.is_symlink():
                    self._journal.unlink()
        self._pending = 0
        if self.on_compact is not None:
            self.on_compact()

    def encode_scene(self, scene_id: str, scene: Mapping[str, Any], meta: Mapping[str, Any],
                     frames: Iterable[Mapping[str, Any]]) -> Iterator[tuple[str, bytes]]:
        """:func:`encode_scene` with this writer's storage (HALF -> FLOAT fallback notes go to ``self.notes``)."""
        return encode_scene(scene_id, scene, meta, frames, dtype=self.storage, notes=self.notes)

    def write_files(self, files: Iterable[tuple[str, bytes]]) -> dict[str, str]:
        """:func:`write_files` under this corpus root."""
        return write_files(self.root, files)

    def commit_scene(self, scene_id: str, hashes: Mapping[str, str]) -> None:
        """Record a finished scene and its files' SHA-256 (a journal line; the manifest follows, see the class)."""
        check_scene_id(scene_id)
        prefix = f"{SCENES_DIR}/{scene_id}/"
        if not hashes or any(not k.startswith(prefix) for k in hashes):
            raise ValueError(f"commit_scene: file paths must lie under {prefix}")
        self._index[scene_id] = dict(hashes)
        self._log({"commit": scene_id, "files": dict(hashes)})

    def forget_scene(self, scene_id: str) -> None:
        """Drop a scene from the manifest (before re-rendering it); its files stay until overwritten."""
        if scene_id in self._index:
            del self._index[scene_id]
            self._log({"forget": scene_id})

    def write_scene(self, scene_id: str, scene: Mapping[str, Any], meta: Mapping[str, Any],
                    frames: Iterable[Mapping[str, Any]]) -> dict[str, str]:
        """Encode, write and commit one scene (files as they are rendered, manifest last); returns the hashes.

        Removes files of the scene that a previous, different run left and that this run did not write
        (:func:`prune_scene_dir`).
        """
        self.forget_scene(scene_id)
        hashes = self.write_files(self.encode_scene(scene_id, scene, meta, frames))
        prune_scene_dir(self.root, scene_id, hashes)
        self.commit_scene(scene_id, hashes)
        return hashes

    def write_splits(self, seed: int, fractions: Sequence[float] = (0.6, 0.2, 0.2)) -> dict[str, list[str]]:
        """Write ``splits.json`` from the manifest's scenes (see :func:`make_splits`; the manifest is brought up to
        date first, :meth:`flush`)."""
        self.flush()
        splits = make_splits(self._index, seed, fractions)
        atomic_write_json(self.root / SPLITS_NAME, splits)
        return splits


def prune_scene_dir(root: str | os.PathLike, scene_id: str, keep: Iterable[str]) -> list[str]:
    """Delete files under ``scenes/<scene_id>/`` whose relpath is not in ``keep`` (stale files of an earlier,
    different render of the scene) and that the corpus format owns (:func:`is_own_file`: ``scene.json``,
    ``meta.json``, ``f<NNN>/<group>.exr``); returns the removed relpaths. Any other file (a user's) stays; frame
    directories left empty are removed."""
    root = Path(root)
    sdir = root / SCENES_DIR / scene_id
    keep = set(keep)
    removed = []
    if sdir.is_dir() and not sdir.is_symlink():
        for p in sorted(sdir.rglob("*"), reverse=True):
            rel = p.relative_to(root).as_posix()
            if p.is_symlink():
                continue
            if p.is_file() and rel not in keep and is_own_file(rel, scene_id):
                p.unlink()
                removed.append(rel)
            elif p.is_dir() and re.fullmatch(r"f\d{3,}", p.name) and not any(p.iterdir()):
                p.rmdir()
    return removed


def _json_bytes(obj: Any) -> bytes:
    return (json.dumps(obj, indent=1, allow_nan=False, default=json_default) + "\n").encode("utf-8")


def _attrs(scene_id: str, frame: int, group: str) -> dict:
    return {ATTR["scene"]: scene_id, ATTR["frame"]: int(frame), ATTR["group"]: group}


def encode_scene(scene_id: str, scene: Mapping[str, Any], meta: Mapping[str, Any],
                 frames: Iterable[Mapping[str, Any]], *, dtype: str | Storage = DEFAULT_STORAGE,
                 notes: list[str] | None = None, executor: Executor | None = None) -> Iterator[tuple[str, bytes]]:
    """Yield ``(relpath, bytes)`` for every file of a scene, frame by frame (checks shapes vs ``meta``).

    Pure encoding (no disk access), so that render workers can call it; ``dtype`` (the storage) as in
    :class:`CorpusWriter`. ``meta.json`` gets a ``storage`` entry (format version, pixel type, compression,
    mantissa bits). ``notes`` receives at most one message per scene: the layers stored FLOAT instead of HALF
    (if any) with the largest measured errors; the error summary of every scene is logged at INFO level.
    ``executor``: a ``concurrent.futures`` executor (threads: numpy and OpenEXR release the GIL) that encodes the
    files of a frame in parallel; they are yielded in the same order, with the same bytes, as without it.

    ``frames`` yields the renderer's frame dicts (``render_tools.render.render_frames``)::

        {"frame": n, "static": {group: {"short": (C,H,W), "long": (C,H,W)}},  # or {"bins": (B,C,H,W)}: static
         "lights": {group: [(light_id, (y0,x0,y1,x1), (K,C,h,w))]},
         "aux": {"depth.Z": (H,W), "depth.R": (H,W), "mask.instance": (H,W), "mask.light": (H,W)}}
    """
    check_scene_id(scene_id)
    st = resolve_storage(dtype)
    meta = dict(meta)
    if meta.get("scene_id") != scene_id:
        raise ValueError(f"meta.json scene_id {meta.get('scene_id')!r} != scene id {scene_id!r}")
    validate_meta(meta, f"meta.json of scene {scene_id}")
    edges = static_edges(meta)  # static time bins: the scene is format version 4
    meta["storage"] = {"format_version": FORMAT_VERSION if edges is None else STATIC_BINS_VERSION, **st.to_dict()}
    stats = StorageStats()
    sdir = f"{SCENES_DIR}/{scene_id}"
    yield f"{sdir}/scene.json", _json_bytes(scene)
    yield f"{sdir}/meta.json", _json_bytes(meta)
    bands = meta["bands_nm"]
    H, W = meta["height"], meta["width"]
    seen: list[int] = []
    with_aux: list[int] = []

    def static_file(g: str, wins: Mapping[str, Any], what: str, n: int) -> tuple[bytes, StorageStats]:
        fstats = StorageStats()
        if (edges is None) != ("bins" not in wins):
            raise ValueError(f"{what}: static time bins given {'without' if edges is None else 'but not'} "
                             "meta.json timing.static_edges_s")
        if edges is not None:
            if np.asarray(wins["bins"]).shape[0] != len(edges) - 1:
                raise ValueError(f"{what}: {np.asarray(wins['bins']).shape[0]} static bins, meta.json "
                                 f"timing.static_edges_s has {len(edges) - 1}")
            wins = {"bins": wins["bins"]}
        data = encode_static_exr(wins, bands, dtype=st, what=what, notes=notes, stats=fstats,
                                 attrs=_attrs(scene_id, n, g))
        size = np.asarray(wins["bins" if edges is not None else "short"]).shape[-2:]
        if (H, W) != tuple(size):
            raise ValueError(f"{what}: image size {tuple(size)} != meta.json ({H}, {W})")
        return data, fstats

    def lights_file(g: str, ls: Sequence, what: str, n: int) -> tuple[bytes, StorageStats]:
        fstats = StorageStats()
        return encode_lights_exr(ls, bands, _group_bins(meta, g), H, W, dtype=st, what=what, notes=notes,
                                 stats=fstats, attrs=_attrs(scene_id, n, g)), fstats

    def aux_file(aux: Mapping[str, Any], what: str, n: int) -> tuple[bytes, None]:
        return encode_aux_exr(aux, H, W, what=what, attrs=_attrs(scene_id, n, "aux")), None

    for fr in frames:
        n = fr.get("frame")
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 0 <= n < meta["frames"] \
                or n in seen:
            raise ValueError(f"scene {scene_id}: frame index {n!r} is invalid or repeated "
                             f"(meta.json frames = {meta['frames']})")
        seen.append(int(n))
        fdir = f"{sdir}/{frame_dir(n)}"
        static = fr.get("static", {}) or {}
        lights = fr.get("lights", {}) or {}
        got = set(static) | set(lights)
        if got != set(meta["groups"]) or set(static) & set(lights):
            raise ValueError(f"scene {scene_id} frame {n}: groups rendered {sorted(got)} do not match "
                             f"meta.json groups {sorted(meta['groups'])}")
        tasks: list[tuple[str, Any, tuple]] = []  # (relpath, function, arguments): the frame's files in order
        for g, wins in static.items():
            what = f"{fdir}/{g}.exr"
            if group_storage(meta, g) != "static":
                raise ValueError(f"{what}: group {g!r} is flickering with bins > 0 in meta.json but was "
                                 "rendered as static windows")
            tasks.append((what, static_file, (g, wins, what, n)))
        for g, ls in lights.items():
            what = f"{fdir}/{g}.exr"
            if group_storage(meta, g) != "lights":
                raise ValueError(f"{what}: group {g!r} is static in meta.json but was rendered per light")
            known = {lt["id"] for lt in meta.get("lights", []) if lt.get("group") == g}
            bad = [lid for lid, _, _ in ls if int(lid) not in known]
            if bad:
                raise ValueError(f"{what}: light ids {bad} are not lights of group {g!r} in meta.json")
            tasks.append((what, lights_file, (g, ls, what, n)))
        if fr.get("aux"):
            with_aux.append(int(n))
            tasks.append((f"{fdir}/aux.exr", aux_file, (fr["aux"], f"{fdir}/aux.exr", n)))
        if executor is None:
            for what, fn, args in tasks:
                data, fstats = fn(*args)
                if fstats is not None:
                    stats.merge(fstats)
                yield what, data
            continue
        futures = [executor.submit(fn, *args) for _, fn, args in tasks]
        try:
            for (what, _, _), fut in zip(tasks, futures):
                data, fstats = fut.result()
                if fstats is not None:
                    stats.merge(fstats)
                yield what, data
        finally:  # an error, or the consumer stopped: the frame's files not started yet are not encoded
            for fut in futures:
                fut.cancel()
    if sorted(seen) != list(range(meta["frames"])):
        raise ValueError(f"scene {scene_id}: got frames {sorted(seen)}, meta.json announces "
                         f"{meta['frames']}")
    if with_aux and len(with_aux) != len(seen):
        raise ValueError(f"scene {scene_id}: aux given for frames {sorted(with_aux)} only (all frames or none)")
    summary = stats.summary(f"scene {scene_id}", st)
    log.info("%s", summary)
    if stats.fallbacks and notes is not None:
        notes.append(summary)


def write_files(root: str | os.PathLike, files: Iterable[tuple[str, bytes]]) -> dict[str, str]:
    """Write ``(relpath, bytes)`` pairs under ``root`` atomically (safe in parallel workers).

    Returns ``{relpath: sha256}``; the manifest is not touched (see :meth:`CorpusWriter.commit_scene`).
    """
    root = Path(root)
    out = {}
    for rel, data in files:
        p = (root / rel).resolve()
        if root.resolve() not in p.parents:
            raise ValueError(f"file path {rel!r} escapes the corpus root")
        out[rel] = atomic_write_bytes(p, data)
    return out


#: Threads of :class:`ThreadedSceneWriter` that encode the files of one frame in parallel: 2 halves the time of
#: the last frame's encoding, which nothing else overlaps (while a frame renders, the render uses every core
#: and more threads would only take turns with it).
ENCODE_THREADS = 2


class _Stopped(Exception):
    """Raised inside the worker of :class:`ThreadedSceneWriter` by :meth:`ThreadedSceneWriter.abort`."""


_EMPTY = object()


class ThreadedSceneWriter:
    """:func:`encode_scene` + :func:`write_files` of one scene in a worker thread, fed frame by frame.

    The caller (e.g. a render loop in the main thread) hands each frame dict to :meth:`put` and goes on
    producing the next one while the worker encodes and writes the previous one: encoding (numpy, OpenEXR
    compression) and rendering (Dr.Jit releases the GIL while its kernels run) overlap. The hand-over has
    depth 1: :meth:`put` returns once the worker has *taken* the frame, i.e. finished the frame before, so
    at most one frame is being encoded while the next is produced (memory about one frame more than a
    serial loop). Files are written as :func:`write_files` writes them (temporary name, then rename), one at a
    time by the worker; the files of a frame are encoded by ``encode_threads`` threads in parallel (the same
    bytes as one thread).

    Errors: an exception in the worker (a bad frame, disk full: :class:`lfmbench.corpus.CorpusWriteError`)
    is raised again, the same object with its message, by the next :meth:`put` or by :meth:`close`. Used as
    a context manager, any exception in the block (including ``KeyboardInterrupt``) stops the worker at the
    next file boundary and joins it (:meth:`abort`) before it propagates; files already written stay
    complete, nothing is half-written, and the scene is not committed to any manifest.

    Example::

        with ThreadedSceneWriter(root, scene_id, scene, meta, dtype="compact", notes=notes) as w:
            for frame in render_frames(scene, opts):
                w.put(frame)
            hashes = w.close()          # {relpath: sha256}, as write_files returns

    Args:
        root: corpus root (files go under ``scenes/<scene_id>/``).
        scene_id, scene, meta, dtype, notes: as for :func:`encode_scene`.
        encode_threads: threads encoding a frame's files (default :data:`ENCODE_THREADS`; 1: the worker alone).
    """

    def __init__(self, root: str | os.PathLike, scene_id: str, scene: Mapping[str, Any], meta: Mapping[str, Any],
                 *, dtype: str | Storage = DEFAULT_STORAGE, notes: list[str] | None = None,
                 encode_threads: int = ENCODE_THREADS) -> None:
        if isinstance(encode_threads, bool) or not isinstance(encode_threads, int) or encode_threads < 1:
            raise ValueError(f"encode_threads must be an integer >= 1, got {encode_threads!r}")
        self.root = Path(root)
        self._args = (scene_id, scene, meta)
        self._dtype, self._notes = dtype, notes
        self._encode_threads = encode_threads
        self._cv = threading.Condition()
        self._slot: Any = _EMPTY
        self._end = self._stop = self._finished = False
        self._exc: BaseException | None = None
        self._hashes: dict[str, str] | None = None
        self._thread = threading.Thread(target=self._run, name=f"lfmbench-writer-{scene_id}", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------------------------------- worker
    def _frames(self) -> Iterator[Mapping[str, Any]]:
        while True:
            with self._cv:
                while self._slot is _EMPTY and not (self._end or self._stop):
                    self._cv.wait()
                if self._stop:
                    raise _Stopped
                if self._slot is _EMPTY:  # end of frames
                    return
                frame, self._slot = self._slot, _EMPTY
                self._cv.notify_all()
            yield frame

    def _files(self, executor: Executor | None) -> Iterator[tuple[str, bytes]]:
        scene_id, scene, meta = self._args
        files = encode_scene(scene_id, scene, meta, self._frames(), dtype=self._dtype, notes=self._notes,
                             executor=executor)
        try:
            for item in files:
                if self._stop:
                    raise _Stopped
                yield item
        finally:
            files.close()  # cancels the frame's files not yet being encoded

    def _run(self) -> None:
        try:
            if self._encode_threads == 1:
                self._hashes = write_files(self.root, self._files(None))
            else:
                with ThreadPoolExecutor(self._encode_threads, thread_name_prefix=self._thread.name) as pool:
                    self._hashes = write_files(self.root, self._files(pool))
        except _Stopped:
            pass
        except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
            self._exc = exc
        finally:
            with self._cv:
                self._finished = True
                self._cv.notify_all()

    # ------------------------------------------------------------------------------------------- caller
    def _raise_if_failed(self) -> None:
        if self._exc is not None:
            raise self._exc
        if self._finished:
            raise RuntimeError("ThreadedSceneWriter: the writer has already finished (put after close/abort)")

    def put(self, frame: Mapping[str, Any]) -> None:
        """Hand one frame dict (as :func:`encode_scene` reads them) to the worker; returns once it has taken it.
        Raises the worker's exception if it failed."""
        with self._cv:
            if self._end:
                raise RuntimeError("ThreadedSceneWriter.put: called after close()")
            self._raise_if_failed()
            self._slot = frame
            self._cv.notify_all()
            while self._slot is not _EMPTY and not self._finished:
                self._cv.wait()
            if self._slot is not _EMPTY:  # the worker ended without taking it
                self._slot = _EMPTY
                self._raise_if_failed()

    def close(self) -> dict[str, str]:
        """No more frames: wait for the worker to write the rest; returns ``{relpath: sha256}``. Raises the
        worker's exception if it failed (e.g. the frames do not match ``meta``)."""
        with self._cv:
            self._end = True
            self._cv.notify_all()
        self._thread.join()
        if self._exc is not None:
            raise self._exc
        if self._hashes is None:
            raise RuntimeError("ThreadedSceneWriter.close: the writer was aborted")
        return self._hashes

    def abort(self) -> None:
        """Stop the worker at its next file boundary and join it (a file being written is finished or, if
        its write fails, not there; no temporary file is left by :func:`write_files`)."""
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        self._thread.join()

    @property
    def alive(self) -> bool:
        """Whether the worker thread is still running."""
        return self._thread.is_alive()

    def __enter__(self) -> "ThreadedSceneWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.abort()
        elif not self._end:  # the block ended without close(): finish the scene (errors propagate)
            self.close()
