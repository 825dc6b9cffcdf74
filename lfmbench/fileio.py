"""Atomic file writes: the one implementation every lfmbench module uses.

A file is written to a temporary name in its own directory (prefix :data:`TMP_PREFIX`), flushed and fsync'ed,
then renamed over the target with :func:`os.replace` (atomic on POSIX): readers see the old file or the new one,
never half of one, and an interrupted or failed write leaves the old file untouched and no temporary behind.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import io
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

#: Prefix of temporary files; stray ones (after a crash) can be found and removed by this prefix.
TMP_PREFIX = ".lfmtmp-"


class AtomicWriteError(OSError):
    """Writing a file failed (disk full, permissions, ...); the message names the file; nothing was changed."""


def _file_mode() -> int:
    """Permission bits of a new file under the current umask (mkstemp alone would give 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _tmp_path(path: Path) -> Path:
    fd, name = tempfile.mkstemp(prefix=TMP_PREFIX + path.name + ".", dir=path.parent)
    try:
        os.fchmod(fd, _file_mode())
    finally:
        os.close(fd)
    return Path(name)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> str:
    """Write ``data`` to ``path`` atomically and return its SHA-256 hex digest.

    Raises:
        AtomicWriteError: naming ``path`` (``errno.ENOSPC``: "disk full"); the temporary file is removed.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = None
    try:
        tmp = _tmp_path(path)
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        tmp = None
    except OSError as exc:
        why = "disk full" if exc.errno == errno.ENOSPC else (exc.strerror or str(exc))
        raise AtomicWriteError(exc.errno, f"could not write {path}: {why}; nothing was changed") from exc
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
    return hashlib.sha256(data).hexdigest()


def json_default(o: Any) -> Any:
    """JSON encoding of numpy arrays and scalars and of paths (for ``json.dumps(default=...)``)."""
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"object of type {type(o).__name__} is not JSON serialisable")


def atomic_write_text(path: str | os.PathLike, text: str) -> str:
    """Write UTF-8 ``text`` atomically; returns its SHA-256."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | os.PathLike, obj: Any) -> str:
    """Write ``obj`` as indented, strict JSON (no NaN/inf) atomically; returns its SHA-256."""
    return atomic_write_text(path, json.dumps(obj, indent=1, allow_nan=False, default=json_default) + "\n")


def atomic_save_figure(fig, path: str | os.PathLike, **savefig_kw) -> Path:
    """Save a matplotlib figure atomically (format from the suffix); returns ``path``."""
    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip(".") or "png", **savefig_kw)
    atomic_write_bytes(path, buf.getvalue())
    return path


def atomic_torch_save(obj: Any, path: str | os.PathLike) -> Path:
    """``torch.save`` atomically; returns ``path``."""
    import torch

    path = Path(path)
    buf = io.BytesIO()
    torch.save(obj, buf)
    atomic_write_bytes(path, buf.getvalue())
    return path
