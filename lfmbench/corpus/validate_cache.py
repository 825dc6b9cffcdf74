"""What a previous ``lfmbench validate`` found, so that the next run re-checks only what changed
(:func:`lfmbench.corpus.validate_corpus`, ``cache=``; ``docs/benchmarks/validate.md``).

Two kinds of 16-byte keys (BLAKE2b, RFC 7693), kept as one set in one file that the program writes (atomically,
:func:`lfmbench.fileio.atomic_write_bytes`) and owns, by default ``<corpus>/.cache/validate.bin``:

- **file key** = H(path in the corpus, the file's state, the SHA-256 the manifest lists). Its presence says: the
  file in this state had this SHA-256 when a previous run hashed it, so it need not be read and hashed again.
- **scene key** = H(:func:`context` of the run, check level, scene id, the scene's file keys, the names and kinds
  of every entry in its folder). Its presence says: this scene, with exactly these files in these states, passed
  every check of this level, with this validator code and these limits.

A file's *state* is ``(size, mtime_ns, ctime_ns, inode, device)`` from ``lstat``. Any write to the file changes
its mtime and ctime (a program can set the mtime back, but not the ctime: the kernel sets it to the current time
on every change of the file's content or attributes); replacing it (rename, copy, restore from a backup) changes
the inode or the ctime. Any such change gives another key, so the file is hashed and its scene checked again.
A file changed within the timestamp resolution of the file system could keep its times; so a file whose mtime or
ctime is less than :data:`RACY_S` before the run started is never recorded (the "racily clean" rule of Git's
index). The context covers the source of every module that takes part in the checks, the OpenEXR and NumPy
versions and the limits (:mod:`lfmbench.limits`): a change of any of them voids every scene key at once.

The file is only a hint: a missing, unreadable, truncated or foreign file is an empty cache (never an error), it
is read only up to a size derived from the manifest (:func:`max_cache_bytes`), and a run writes back only the
keys it used or added, so the file never outgrows the corpus.
"""
from __future__ import annotations

import hashlib
import os
import struct
import time
from pathlib import Path
from typing import Iterable

from lfmbench.fileio import AtomicWriteError, atomic_write_bytes, read_bytes
from lfmbench.limits import LIMITS, limit

__all__ = ["ValidateCache", "context", "default_cache_path", "max_cache_bytes", "RACY_S", "KEY_BYTES"]

#: Bytes of one key.
KEY_BYTES = 16
#: A file whose mtime or ctime is less than this many seconds before the run started is not recorded (s).
RACY_S = 2.0
#: First bytes of a cache file (the format's name and version).
MAGIC = b"lfmbench-validate-cache 1\n"
#: The modules whose source takes part in the checks, as files of the package (their text is part of
#: :func:`context`).
CHECK_MODULES = ("corpus/validate.py", "corpus/validate_cache.py", "corpus/exr.py", "corpus/meta.py",
                 "corpus/naming.py", "corpus/storage.py", "corpus/errors.py", "check.py", "limits.py", "fileio.py",
                 "vocabulary.py")


def default_cache_path(root: str | os.PathLike) -> Path:
    """``<root>/.cache/validate.bin``: the corpus's own cache folder (also that of the dataset's projected
    radiance)."""
    return Path(root) / ".cache" / "validate.bin"


def max_cache_bytes(n_files: int, n_scenes: int) -> int:
    """The largest cache file a corpus of ``n_files`` files and ``n_scenes`` scenes can have (one file key per
    file, two scene keys per scene, plus the header): anything larger is not read."""
    return len(MAGIC) + 8 + KEY_BYTES * (n_files + 2 * n_scenes)


def context() -> bytes:
    """A digest of everything besides the files that decides a scene's verdict: the source of
    :data:`CHECK_MODULES`, the OpenEXR and NumPy versions, and the current limits."""
    import importlib.metadata as md  # noqa: PLC0415

    h = hashlib.blake2b(digest_size=KEY_BYTES)
    package = Path(__file__).resolve().parents[1]
    for name in CHECK_MODULES:
        h.update(name.encode() + b"\0" + (package / name).read_bytes() + b"\0")
    for dist in ("OpenEXR", "numpy"):
        try:
            h.update(f"{dist}={md.version(dist)}\0".encode())
        except md.PackageNotFoundError:  # pragma: no cover - both are dependencies
            h.update(f"{dist}=?\0".encode())
    h.update(repr(sorted((k, limit(k)) for k in LIMITS)).encode())
    return h.digest()


def _state(st: os.stat_result) -> bytes:
    return struct.pack("<qqqQQ", st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino, st.st_dev)


class ValidateCache:
    """The key set of one run: :meth:`has` (a key recorded by an earlier run; counted as used), :meth:`add`,
    :meth:`save` (the used and added keys, atomically). ``keys`` may be given (a worker process gets the set
    of the run) instead of read from ``path``.

    Args:
        path: the cache file, or None (nothing is read or written).
        max_bytes: read at most this many bytes (:func:`max_cache_bytes`); a larger file is ignored.
        keys: the recorded keys, when already loaded.
    """

    def __init__(self, path: str | os.PathLike | None, max_bytes: int = 0, keys: set[bytes] | None = None):
        self.path = None if path is None else Path(path)
        self.started_ns = time.time_ns()
        self.fresh_ns = self.started_ns - int(RACY_S * 1e9)
        self.keys = keys if keys is not None else self._load(max_bytes)
        self.used: set[bytes] = set()
        self.added: set[bytes] = set()

    def _load(self, max_bytes: int) -> set[bytes]:
        if self.path is None:
            return set()
        try:
            st = os.stat(self.path)
            if st.st_size > max_bytes:  # not one of ours for this corpus: too large to be
                return set()
            raw = read_bytes(self.path, "validate cache", "manifest_bytes", max_bytes=max_bytes)
        except (OSError, ValueError):
            return set()
        n = len(raw) - len(MAGIC) - 8
        if not raw.startswith(MAGIC) or n < 0 or n % KEY_BYTES:
            return set()
        (count,) = struct.unpack_from("<Q", raw, len(MAGIC))
        if count * KEY_BYTES != n:
            return set()
        base = len(MAGIC) + 8
        return {raw[i:i + KEY_BYTES] for i in range(base, len(raw), KEY_BYTES)}

    def settled(self, st: os.stat_result) -> bool:
        """True when the file of stat ``st`` was last changed at least :data:`RACY_S` before the run started."""
        return max(st.st_mtime_ns, st.st_ctime_ns) < self.fresh_ns

    @staticmethod
    def file_key(rel: str, st: os.stat_result, digest: str) -> bytes:
        """The key of file ``rel`` (path in the corpus) in state ``st`` with SHA-256 ``digest`` (hex)."""
        return hashlib.blake2b(b"F" + rel.encode("utf-8", "surrogateescape") + b"\0" + _state(st)
                               + digest.encode("ascii", "replace"), digest_size=KEY_BYTES).digest()

    @staticmethod
    def scene_key(ctx: bytes, level: str, sid: str, file_keys: Iterable[bytes], listing: Iterable[str]) -> bytes:
        """The key of scene ``sid`` checked at ``level`` ("headers" or "pixels") in context ``ctx``, with its
        listed files' keys and the names and kinds of every entry in its folder (``listing``)."""
        h = hashlib.blake2b(b"S" + ctx + level.encode() + b"\0" + sid.encode() + b"\0", digest_size=KEY_BYTES)
        for k in sorted(file_keys):
            h.update(k)
        for name in listing:
            h.update(name.encode("utf-8", "surrogateescape") + b"\0")
        return h.digest()

    def has(self, key: bytes) -> bool:
        if key in self.keys:
            self.used.add(key)
            return True
        return key in self.added

    def add(self, key: bytes) -> None:
        self.added.add(key)

    def merge(self, used: Iterable[bytes], added: Iterable[bytes]) -> None:
        """Take over the used and added keys of a worker process."""
        self.used.update(used)
        self.added.update(added)

    def save(self) -> bool:
        """Write the used and added keys to :attr:`path` (atomically; the folder is made if needed). False, and
        nothing changed, when it cannot be written (a read-only corpus): the cache is only a hint."""
        if self.path is None or (not self.added and self.used == self.keys):
            return False
        keys = sorted(self.used | self.added)
        data = MAGIC + struct.pack("<Q", len(keys)) + b"".join(keys)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(self.path, data)
        except (OSError, AtomicWriteError):
            return False
        return True
