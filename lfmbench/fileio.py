"""File I/O of user-facing files: the one implementation every lfmbench module uses for writing any file and
for reading JSON and YAML.

Writing (:func:`atomic_write_bytes` and its wrappers): a file is written to a temporary name in its own
directory (prefix :data:`TMP_PREFIX`), flushed and fsync'ed, then renamed over the target with
:func:`os.replace` (atomic on POSIX): readers see the old file or the new one, never half of one, and an
interrupted or failed write leaves the old file untouched and no temporary behind. What is at the path is never
replaced by something else: a symbolic link is written through (its target is replaced, the link stays), and a
path that exists and is not a regular file (``/dev/null``, ``/dev/stdout``, a FIFO) is written directly. Every
write error (disk full, read-only file system, I/O error, a FIFO without reader) is an :class:`AtomicWriteError`
whose message names the path.

Reading (:func:`load_json`, :func:`loads_json`, :func:`load_yaml`): bounded by :mod:`lfmbench.limits` (file
size, JSON nesting depth, YAML aliases and expanded nodes) and strict (no ``NaN``/``Infinity``, no number that
overflows to inf); every refusal is an :class:`InputFileError` (a ``ValueError``) naming the file.

Size (about 590 lines): one job, the project's one implementation of safe file reading and writing (atomic
writes, regular-file checks, bounded JSON and YAML); split, it would invite a second copy of a rule.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import io
import json
import math
import os
import re
import socket
import stat
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from lfmbench.limits import LimitError, limit

#: Prefix of temporary files; stray ones (after a crash) can be found and removed by this prefix.
TMP_PREFIX = ".lfmtmp-"


class AtomicWriteError(OSError):
    """Writing a file failed (disk full, permissions, ...); the message names the file; nothing was changed."""


class InputFileError(ValueError):
    """A JSON or YAML file that is malformed or above a limit of :mod:`lfmbench.limits`; the message names it."""


class NotRegularFileError(InputFileError, OSError):
    """A path given to read that is not a regular file once its symbolic links are resolved (a FIFO, a character
    or block device, a socket, a directory): refused before anything is read, because reading a FIFO or a
    terminal waits forever and a device never ends. Both a ``ValueError`` (bad input) and an ``OSError``
    (``errno.EINVAL``; what callers that catch unreadable files expect); the message names the path."""

    def __init__(self, msg: str):
        OSError.__init__(self, errno.EINVAL, msg)

    def __str__(self) -> str:
        return self.strerror


def file_kind(mode: int) -> str:
    """``"a FIFO"``, ``"a character device"``, ... for an ``st_mode``."""
    for test, name in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a directory"),
                       (stat.S_ISREG, "a regular file")):
        if test(mode):
            return name
    return "not a regular file"


def open_regular(path: str | os.PathLike, what: str = "file"):
    """Open ``path`` for binary reading, refusing what is not a regular file after its links are resolved.

    The file is opened with ``O_NONBLOCK`` first (opening a FIFO for reading blocks until a writer comes) and
    checked with ``fstat`` on the open descriptor (no race between the check and the read); blocking mode is
    restored for a regular file. ``what`` names the file's role in the message.

    Raises:
        NotRegularFileError: a FIFO, device, socket or directory (one line naming ``path`` and what it is).
        OSError: missing or unreadable (``FileNotFoundError``, ``PermissionError``), as ``open`` raises them.
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise NotRegularFileError(f"{path}: {what} is {file_kind(mode)}, not a regular file; lfmbench reads "
                                      "only regular files (a FIFO or device would wait or never end)")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def check_regular(path: str | os.PathLike, what: str = "file") -> None:
    """:func:`open_regular` without reading: raises its errors for ``path``."""
    open_regular(path, what).close()
#: A URL's start (RFC 3986 scheme, 2+ characters so that a drive letter ``C:/`` is not one, then ``:/``; a
#: ``pathlib.Path`` has already folded ``s3://`` to ``s3:/``).
_URL = re.compile(r"^([A-Za-z][A-Za-z0-9+.-]+):/")


def url_scheme(path: str | os.PathLike) -> str | None:
    """The scheme of a URL-like path (``s3://bucket/corpus`` -> ``"s3"``), None for a file-system path.

    lfmbench reads and writes corpora, checkpoints and results on a POSIX file system only; without this check a
    path such as ``s3://bucket/corpus`` is a local folder named ``s3:`` (docs/guide/distributed.md, "Storage")."""
    m = _URL.match(os.fspath(path))
    return m.group(1).lower() if m else None


def url_error(name: str, path: str | os.PathLike | None) -> str | None:
    """One line refusing a URL given as the path argument ``name`` (e.g. ``--out``), None for a local path."""
    if path is None:
        return None
    scheme = url_scheme(path)
    if scheme is None:
        return None
    return (f"{name} {os.fspath(path)}: a {scheme}:// URL, not a file-system path; lfmbench reads and writes "
            "POSIX paths only (mount the storage, e.g. a shared NFS folder or an s3fs / gcsfuse mount, and give "
            "the mount point; docs/guide/distributed.md)")


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


def _why(exc: OSError) -> str:
    return "disk full" if exc.errno == errno.ENOSPC else (exc.strerror or str(exc))


def write_target(path: str | os.PathLike) -> tuple[Path, bool]:
    """Where a write of ``path`` goes and how: ``(target, direct)``.

    A symbolic link is followed to its final target (the link itself is never replaced); a target that exists and
    is not a regular file (character device, FIFO, socket) is written directly (``direct`` True), never replaced;
    a directory raises ``IsADirectoryError`` naming ``path``.
    """
    path = Path(path)
    try:
        st = os.stat(path)  # follows symbolic links
    except FileNotFoundError:
        st = None
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError(errno.EISDIR, f"{path} is a directory")
    if st is not None and not stat.S_ISREG(st.st_mode):
        return path, True
    if path.is_symlink():
        return Path(os.path.realpath(path)), False
    return path, False


def writable_error(path: str | os.PathLike) -> str | None:
    """Why ``path`` cannot be written by :func:`atomic_write_bytes` (checked before long work starts), or None."""
    try:
        target, direct = write_target(path)
        if direct:
            return None if os.access(target, os.W_OK) else "permission denied"
        target.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=target.parent):
            pass
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


#: How long a write waits for a process to open a FIFO for reading, s.
FIFO_WAIT_S = 3.0


def _write_direct(path: Path, data: bytes) -> None:
    """Write into an existing non-regular file (device, FIFO) in place; a FIFO that no process opens for reading
    within :data:`FIFO_WAIT_S` is an error (ENXIO), not a hang."""
    fifo = stat.S_ISFIFO(os.stat(path).st_mode)
    if fifo:
        t_end = time.monotonic() + FIFO_WAIT_S
        while True:
            try:
                fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
                break
            except OSError as exc:
                if exc.errno != errno.ENXIO or time.monotonic() > t_end:
                    raise
                time.sleep(0.02)
        os.set_blocking(fd, True)
    else:
        fd = os.open(path, os.O_WRONLY)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
        fh.flush()


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> str:
    """Write ``data`` to ``path`` atomically and return its SHA-256 hex digest.

    A symbolic link is written through; a path that is not a regular file is written directly
    (:func:`write_target`).

    Raises:
        AtomicWriteError: naming ``path`` (``errno.ENOSPC``: "disk full"); the temporary file is removed.
    """
    path = Path(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        target, direct = write_target(path)
        if direct:
            try:
                _write_direct(target, data)
            except OSError as exc:
                raise AtomicWriteError(exc.errno, f"could not write {path}: {_why(exc)}") from exc
            return hashlib.sha256(data).hexdigest()
        tmp = _tmp_path(target)
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
        tmp = None
    except AtomicWriteError:
        raise
    except OSError as exc:
        raise AtomicWriteError(exc.errno, f"could not write {path}: {_why(exc)}; nothing was changed") from exc
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


# --------------------------------------------------------------------------------------------------- reading
def read_bytes(path: str | os.PathLike, what: str = "file", limit_name: str = "json_bytes",
               max_bytes: int | None = None) -> bytes:
    """The bytes of ``path``, refused (:class:`lfmbench.limits.LimitError`, naming it) above limit ``limit_name``
    (or ``max_bytes``, a tighter bound the caller derives, e.g. from a manifest) before they are read; a path
    that is not a regular file is a :class:`NotRegularFileError` (:func:`open_regular`). ``OSError`` (missing,
    unreadable) propagates."""
    cap = limit(limit_name) if max_bytes is None else min(max_bytes, limit(limit_name))
    with open_regular(path, what) as fh:
        size = os.fstat(fh.fileno()).st_size
        if size > cap:
            raise LimitError(str(path), f"{what} of {size:,} bytes", size, limit_name)
        chunks, total = [], 0
        while True:  # the stated size first; a growing or non-regular file: never more than the limit
            b = fh.read(max(size + 1, 1 << 16) if not chunks else 1 << 20)
            if not b:
                break
            total += len(b)
            if total > cap:
                raise LimitError(str(path), f"{what} of more than {cap:,} bytes", total, limit_name)
            chunks.append(b)
    return b"".join(chunks) if len(chunks) != 1 else chunks[0]


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number (non-finite values are not allowed)")


def _finite_float(text: str) -> float:
    v = float(text)
    if not math.isfinite(v):
        raise ValueError(f"number {text[:40]}{'...' if len(text) > 40 else ''} is out of the float range")
    return v


def json_depth_exceeds(obj: Any, cap: int) -> bool:
    """True when ``obj`` (parsed JSON) nests lists / objects deeper than ``cap`` levels (iterative)."""
    return _json_tree_check(obj, cap) == "deep"


def _json_tree_check(obj: Any, cap: int) -> str | None:
    """``"deep"`` when ``obj`` (parsed JSON) nests lists / objects deeper than ``cap`` levels, else ``"inf"``
    when it holds an infinite float (JSON text has none: a number that overflowed in the parser), else None.
    One iterative walk over every value."""
    stack = [(obj, 1)]
    inf = type(obj) is float and obj - obj != 0.0
    while stack:
        o, d = stack.pop()
        if d > cap:
            return "deep"
        for v in (o.values() if isinstance(o, dict) else o if isinstance(o, list) else ()):
            t = type(v)
            if t is float:
                if v - v != 0.0:
                    inf = True
            elif t is dict or t is list:
                stack.append((v, d + 1))
    return "inf" if inf else None


def loads_json(raw: bytes | str, source: str, object_hook: Any = None) -> Any:
    """Parse JSON text from ``source`` (a file name, for the messages) strictly and within the depth limit:
    ``NaN``, ``Infinity`` and numbers that overflow to inf are refused; every refusal is an
    :class:`InputFileError` naming ``source``.

    ``object_hook(dict) -> dict`` is called on each object as the parser completes it (:func:`json.loads`): a
    reader can count what a file declares while it is parsed and stop it early by raising an exception that is
    not a ``ValueError`` (which passes through unchanged)."""
    cap = limit("json_depth")
    # parsed with the C parser's own float conversion, then checked: an infinite float in the tree is a number
    # that overflowed (JSON has no other), and only then is the text parsed again with the per-number hook, for
    # its message naming the number (the hook on every number was a third of a 10,000-file leaderboard's reading)
    # (a reader's object_hook may count what it sees: its file is parsed once, with the hook on every number)
    for hook in ((None, _finite_float) if object_hook is None else (_finite_float,)):
        try:
            obj = json.loads(raw, parse_constant=_no_constant, parse_float=hook, object_hook=object_hook)
        except RecursionError:
            raise InputFileError(f"{source}: JSON nested deeper than the limit json_depth={cap} (raise it with "
                                 f"`lfmbench --limit json_depth=N` if the file is trusted)") from None
        except (ValueError, UnicodeDecodeError) as exc:  # JSONDecodeError, int digit limit, our hooks
            msg = " ".join(str(exc).split())
            raise InputFileError(f"{source}: cannot read JSON: {msg[:200]}") from None
        verdict = _json_tree_check(obj, cap)
        if verdict == "deep":
            raise InputFileError(f"{source}: JSON nested deeper than the limit json_depth={cap} (raise it with "
                                 f"`lfmbench --limit json_depth=N` if the file is trusted)")
        if verdict is None:
            break
    else:  # pragma: no cover - the hook refuses the overflowing number in the second pass
        raise InputFileError(f"{source}: cannot read JSON: a number is out of the float range")
    return obj


def load_json(path: str | os.PathLike, what: str = "JSON file", limit_name: str = "json_bytes",
              object_hook: Any = None) -> Any:
    """Read and parse the JSON file ``path`` within the limits (:func:`read_bytes`, :func:`loads_json`, which
    passes ``object_hook`` on).

    Raises:
        InputFileError: malformed, too deep or too large (a ``ValueError`` naming ``path``).
        OSError: missing or unreadable (``FileNotFoundError`` for a missing file).
    """
    try:
        raw = read_bytes(path, what, limit_name)
    except LimitError as exc:
        raise InputFileError(str(exc)) from None
    return loads_json(raw, str(path), object_hook)


def load_json_input(path: str | os.PathLike, what: str) -> Any:
    """:func:`load_json` of a user's input file (``what``: e.g. "run file", "scene file"), every failure a
    ``ValueError`` whose one line names ``what`` and the file: unreadable, missing, malformed or above a limit."""
    try:
        return load_json(path, what)
    except OSError as exc:
        raise ValueError(f"{what} {path}: cannot read JSON ({exc.strerror or exc})") from None
    except InputFileError as exc:
        raise ValueError(f"{what} {exc}") from None


def _yaml_loader():
    import yaml  # noqa: PLC0415

    class BoundedLoader(yaml.SafeLoader):
        """``yaml.SafeLoader`` that counts aliases while composing (limit ``yaml_aliases``)."""

        n_aliases = 0

        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                self.n_aliases += 1
                if self.n_aliases > limit("yaml_aliases"):
                    raise LimitError(self.source, f"YAML document with more than {limit('yaml_aliases')} aliases",
                                     None, "yaml_aliases")
            return super().compose_node(parent, index)

    return yaml, BoundedLoader


def _expanded_nodes(node: Any, cap: int) -> int:
    """Nodes of a composed YAML graph with every alias expanded (memoised per node: linear in the graph);
    stops counting above ``cap``."""
    import yaml  # noqa: PLC0415

    memo: dict[int, int] = {}

    def size(n) -> int:
        k = id(n)
        if k in memo:
            return memo[k]
        if isinstance(n, yaml.SequenceNode):
            total = 1 + sum(size(c) for c in n.value)
        elif isinstance(n, yaml.MappingNode):
            total = 1 + sum(size(a) + size(b) for a, b in n.value)
        else:
            total = 1
        memo[k] = total = min(total, cap + 1)
        return total

    return size(node)


def load_yaml(path: str | os.PathLike | None = None, *, text: str | None = None, source: str | None = None) -> Any:
    """Parse a YAML file (or ``text``) safely and within the limits: ``yaml.safe_load`` semantics, the file size
    (``yaml_bytes``), aliases (``yaml_aliases``) and nodes after alias expansion (``yaml_nodes``, the "billion
    laughs" bound) are checked before any Python object is built.

    Raises:
        InputFileError: malformed or above a limit (a ``ValueError`` whose single line names the file and, for
            a syntax error, the position; quoted text is cut short).
        OSError: the file is missing or unreadable.
    """
    source = str(source or path or "<yaml>")
    try:
        if text is None:
            raw = read_bytes(path, "YAML file", "yaml_bytes")
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise InputFileError(f"{source}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
        elif len(text) > limit("yaml_bytes"):
            raise LimitError(source, f"YAML text of {len(text):,} characters", len(text), "yaml_bytes")
        yaml, Loader = _yaml_loader()
        loader = Loader(text)
        loader.source = loader.name = source  # positions in messages name the file
        try:
            node = loader.get_single_node()
            if node is None:
                return None
            cap = limit("yaml_nodes")
            n = _expanded_nodes(node, cap)
            if n > cap:
                raise LimitError(source, "YAML document of more nodes (after alias expansion)", None, "yaml_nodes")
            return loader.construct_document(node)
        finally:
            loader.dispose()
    except LimitError as exc:
        raise InputFileError(str(exc)) from None
    except RecursionError:
        raise InputFileError(f"{source}: YAML nested too deeply") from None
    except Exception as exc:  # yaml.YAMLError (syntax, unknown tag): one line, position included, cut short
        import yaml  # noqa: PLC0415

        if not isinstance(exc, yaml.YAMLError):
            raise
        msg = " ".join(str(exc).split())
        raise InputFileError(f"{source}: cannot read YAML: {msg[:300]}{'...' if len(msg) > 300 else ''}") from None


# ------------------------------------------------------------------------------------------ one writer per output
class OutputLockedError(ValueError):
    """Another process is writing the same output file (its lock is held); the message names the file, the
    holder and what to do."""


def pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists on this machine (one that another user owns counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class OutputLock:
    """One writer per output file: an exclusive ``flock`` on a hidden lock file beside the (link-resolved) target,
    ``.<name>.lock``, holding ``pid <pid> host <host>`` of its holder, taken before any work and held until
    :meth:`release` (or the ``with`` block's end, or process exit: the kernel releases a dead holder's lock, so a
    lock file left by a killed run is taken over). Where the file system has no ``flock``, a holder on this host
    whose pid is gone is stale and taken over. The lock file is removed on release (under the lock; a process that
    opened it meanwhile sees the file replaced and takes the lock again). A path that is not a regular file
    (``/dev/null``, a FIFO) is written in place and not locked.

    Raises:
        OutputLockedError: another process holds the lock (one line naming ``path``, the holder and ``option``).
    """

    def __init__(self, path: str | os.PathLike, option: str = "output") -> None:
        self.path, self.option, self.fd, self.lock = Path(path), option, None, None
        target, direct = write_target(path)
        if direct:
            return
        self.lock = target.parent / f".{target.name}.lock"
        for _ in range(10):
            fd = os.open(self.lock, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
            try:
                self._take(fd)
                same = os.fstat(fd).st_ino == os.stat(self.lock).st_ino
            except FileNotFoundError:  # removed by the holder releasing it: take the new file
                same = False
            except BaseException:
                os.close(fd)
                raise
            if same:
                break
            os.close(fd)
        else:  # pragma: no cover - ten releases in a row while we tried
            raise OutputLockedError(f"{self.option} {self.path}: its lock {self.lock} keeps changing; try again")
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} host {socket.gethostname()}\n".encode(), 0)
        self.fd = fd

    def _busy(self, holder: str) -> OutputLockedError:
        return OutputLockedError(f"{self.option} {self.path} is being written by another lfmbench process ({holder}; "
                                 f"lock {self.lock}): wait for it to finish, or choose another {self.option}")

    def _take(self, fd: int) -> None:
        import fcntl  # noqa: PLC0415 - POSIX only

        holder = lambda: os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "unknown holder"  # noqa: E731
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise self._busy(holder()) from None
        except OSError as exc:
            if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS):
                raise
            m = re.fullmatch(r"pid (\d+) host (\S+)", holder())
            if m and int(m.group(1)) != os.getpid() and (m.group(2) != socket.gethostname()
                                                          or pid_alive(int(m.group(1)))):
                raise self._busy(m.group(0)) from None

    def release(self) -> None:
        """Remove the lock file and release the lock (idempotent)."""
        fd, self.fd = self.fd, None
        if fd is None:
            return
        with contextlib.suppress(OSError):
            if os.fstat(fd).st_ino == os.stat(self.lock).st_ino:
                os.unlink(self.lock)
        os.close(fd)

    def __enter__(self) -> "OutputLock":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:
        self.release()
