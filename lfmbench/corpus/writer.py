"""Writing a corpus: :class:`CorpusWriter` (finished scenes recorded in an append-only journal that is folded into
the manifest, rewritten atomically, as the corpus grows; resume support), its one-writer lock
(:class:`CorpusLock`) and the rule of which files of a scene directory are the format's (:func:`is_own_file`,
:func:`prune_scene_dir`). The files of one scene are encoded and written by :mod:`lfmbench.corpus.scene_files`.
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
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence

from lfmbench.check import check_scene_id
from lfmbench.corpus.meta import _check_manifest, _empty_manifest, _load_json, make_splits, sha256_file
from lfmbench.corpus.naming import FORMAT_VERSION, MANIFEST_NAME, SCENES_DIR, SPLITS_NAME
from lfmbench.corpus.errors import CorpusError, CorpusLockedError
from lfmbench.corpus.scene_files import encode_scene, write_files
from lfmbench.corpus.storage import DEFAULT_STORAGE, Storage, resolve_storage
from lfmbench.fileio import TMP_PREFIX, atomic_write_json, json_default, pid_alive

__all__ = ["CorpusWriter", "prune_scene_dir", "LOCK_NAME", "JOURNAL_NAME", "COMPACT_FRACTION", "CorpusLockedError", "CorpusLock",
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
_OWN_SCENE_FILE = re.compile(r"(scene\.json|meta\.json|window_layers\.json|"
                             r"f\d{3,}/[A-Za-z][A-Za-z0-9_]*(\.layer_[a-z][a-z0-9_]*)?\.exr)")


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
    scene ``scene_id``: ``scenes/<id>/scene.json``, ``meta.json``, ``window_layers.json``, ``f<NNN>/<group>.exr`` or
    a static window layer's ``f<NNN>/<group>.layer_<name>.exr`` (:mod:`lfmbench.corpus.window_layers`)."""
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

    def scene_files(self, scene_id: str) -> dict[str, str]:
        """``{relpath: sha256}`` of a committed scene's files (empty for a scene not in the manifest)."""
        return dict(self._index.get(scene_id, {}))

    @property
    def render(self) -> dict | None:
        """The manifest's ``"render"`` record (the options the corpus was rendered with), or None."""
        r = self._head.get("render")
        return None if r is None else json.loads(json.dumps(r))

    def set_render(self, render: Mapping[str, Any]) -> None:
        """Replace the manifest's ``"render"`` record: only after the corpus was brought up to what ``render`` asks
        for (static window layers added to every scene, :func:`render_tools.jobs.add_layers`); the manifest is
        rewritten."""
        self._head["render"] = json.loads(json.dumps(dict(render), default=json_default))
        self.write_manifest()

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
