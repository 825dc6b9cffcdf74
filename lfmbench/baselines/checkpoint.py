"""Learned baselines backed by a checkpoint file: one rule for where the weights are, loading them once, running
them (:func:`checkpointed_method`, the one registration helper of every checkpoint-backed baseline), and
registering them lazily (:func:`lazy_method`, so that importing :mod:`lfmbench.baselines` imports no network
module).

Integrity: every checkpoint carries the SHA-256 of its own content (:data:`CONTENT_KEY`, :func:`content_sha256`:
every tensor's dtype, shape and bytes and every plain value, in a canonical order) written by
:func:`save_checkpoint_file` and checked by :func:`verify_content` on every load, so a weight changed after
training (a flipped bit on disk, an edit, a torn copy) is refused with one line naming the file instead of
giving another score; the evaluation records the hash with the result (``method.checkpoint``).
"""
from __future__ import annotations

import hashlib
import importlib
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch


class CheckpointError(ValueError):
    """A checkpoint file that cannot be used: unreadable, truncated, a pickle of code that ``weights_only``
    refuses, another format, or content that no longer matches its hash. Bad input (``lfmbench evaluate`` exits 2
    naming the file), not a scene failure."""


#: Key of a checkpoint dict holding the SHA-256 (hex) of the rest of its content (:func:`content_sha256`).
CONTENT_KEY = "content_sha256"
#: Key :func:`read_weights` adds to a loaded dict: the SHA-256 of the file's bytes as read (not stored in files).
FILE_KEY = "_file_sha256"
#: Key the checkpoint readers add to a loaded dict: whether its content hash was recorded and matched.
VERIFIED_KEY = "_content_verified"


def _feed(h: Any, o: object) -> None:
    """Feed ``o`` to the hash ``h`` canonically: a tag and length per container, dict keys sorted by (type,
    repr), tensors as dtype, shape and their bytes in C order (device and strides do not matter)."""
    if isinstance(o, torch.Tensor):
        t = o.detach().to("cpu").contiguous()
        h.update(f"T{t.dtype}|{tuple(t.shape)}|".encode())
        if t.numel():
            h.update(t.reshape(-1).view(torch.uint8).numpy())
    elif isinstance(o, dict):
        h.update(f"D{len(o)}|".encode())
        for k in sorted(o, key=lambda k: (type(k).__name__, repr(k))):
            _feed(h, k)
            _feed(h, o[k])
    elif isinstance(o, (list, tuple)):
        h.update(f"{'L' if isinstance(o, list) else 'U'}{len(o)}|".encode())
        for v in o:
            _feed(h, v)
    else:  # None, bool, int, float (repr is exact), str, bytes, torch.dtype, ...
        h.update(f"S{type(o).__name__}:{o!r}|".encode())


def content_sha256(ck: dict) -> str:
    """SHA-256 (hex) of a checkpoint dict's content except :data:`CONTENT_KEY`: the same for the same tensors and
    values, whatever device they were loaded on."""
    h = hashlib.sha256()
    _feed(h, {k: v for k, v in ck.items() if k not in (CONTENT_KEY, FILE_KEY, VERIFIED_KEY)})
    return h.hexdigest()


def save_checkpoint_file(ck: dict, path: str | os.PathLike) -> Path:
    """Write the checkpoint dict ``ck`` atomically (:func:`lfmbench.fileio.atomic_torch_save`) with its
    :func:`content_sha256` under :data:`CONTENT_KEY`."""
    from lfmbench.fileio import atomic_torch_save  # noqa: PLC0415

    ck = {k: v for k, v in ck.items() if k not in (CONTENT_KEY, FILE_KEY, VERIFIED_KEY)}
    return atomic_torch_save({**ck, CONTENT_KEY: content_sha256(ck)}, path)


class UnverifiedCheckpointWarning(UserWarning):
    """A checkpoint without :data:`CONTENT_KEY` (written before checkpoints carried their hash, e.g. a published
    one): loaded, its hash computed now and recorded with ``verified: false``; warned once per file."""


_warned_unverified: set[str] = set()


def verify_content(ck: dict, path: str | os.PathLike) -> tuple[str, bool]:
    """``(content hash, verified)`` of a loaded checkpoint dict. With a recorded :data:`CONTENT_KEY` the content
    must match it (:class:`CheckpointError` naming ``path`` otherwise: a weight changed after the file was
    written); without one (an older file) the hash is computed now, ``verified`` is False and one
    :class:`UnverifiedCheckpointWarning` per file says how to seal it."""
    want = ck.get(CONTENT_KEY)
    got = content_sha256(ck)
    if want is None:
        if str(path) not in _warned_unverified:
            _warned_unverified.add(str(path))
            import warnings  # noqa: PLC0415

            warnings.warn(f"checkpoint {path}: no {CONTENT_KEY} (written before checkpoints carried their hash): "
                          f"its weights cannot be verified; if you trust it, `python -m lfmbench.baselines."
                          f"checkpoint seal {path}`", UnverifiedCheckpointWarning, stacklevel=3)
        return got, False
    if not isinstance(want, str) or got != want:
        raise CheckpointError(f"checkpoint {path}: content does not match its {CONTENT_KEY} (recorded "
                              f"{str(want)[:12]}..., now {got[:12]}...): the weights changed after training (a "
                              "damaged or edited file); nothing from it is used")
    return got, True


def read_weights(path: str | os.PathLike, map_location: str | torch.device = "cpu") -> object:
    """``torch.load(path, weights_only=True)`` (tensors and plain data only: no code from a file runs); any failure
    (also a path that is not a regular file: a FIFO would wait forever) is a :class:`CheckpointError` naming
    ``path``. A dict gets :data:`FILE_KEY`, the SHA-256 of the bytes read."""
    from lfmbench.fileio import NotRegularFileError, open_regular  # noqa: PLC0415

    import io  # noqa: PLC0415

    try:
        with open_regular(path, "checkpoint") as fh:
            raw = fh.read()
        ck = torch.load(io.BytesIO(raw), map_location=map_location, weights_only=True)
        if isinstance(ck, dict):
            ck[FILE_KEY] = hashlib.sha256(raw).hexdigest()
        return ck
    except NotRegularFileError as exc:
        raise CheckpointError(f"checkpoint {exc}") from None
    except Exception as exc:  # noqa: BLE001 - truncated file, pickle of code, not a zip, ...
        why = " ".join(str(exc).split())[:200]
        raise CheckpointError(f"checkpoint {path}: cannot be read as weights ({type(exc).__name__}: {why})") \
            from None


def read_trained_weights(path: str | os.PathLike, map_location: str | torch.device, *, method: str, env: str,
                         what: str, not_found: type[Exception] = FileNotFoundError) -> object:
    """:func:`read_weights` of the checkpoint of a learned baseline; a missing file raises ``not_found`` naming the
    training command (``lfmbench train --method METHOD``) and the environment variable ``env`` (``what``: the
    network's name in the message)."""
    path = Path(path)
    if not path.exists():
        raise not_found(f"no {what} checkpoint at {path}; train one with `lfmbench train --method {method} "
                        f"--corpus DIR --out {path}` (or set ${env})")
    return read_weights(path, map_location)


def check_model_size(build: Callable[[], torch.nn.Module], source: str) -> int:
    """The parameter count of ``build()`` built on torch's meta device (no weight allocated); above the limit
    ``model_parameters`` a :class:`CheckpointError` naming ``source`` (a config or checkpoint asking for a network of
    10^12 weights is refused before the allocator is asked). A build that fails on the meta device is left to the
    real build to report. Returns the count (-1 when unknown)."""
    from lfmbench.limits import LimitError, limit  # noqa: PLC0415

    try:
        with torch.device("meta"):
            n = sum(p.numel() for p in build().parameters())
    except (KeyError, RuntimeError, TypeError, ValueError, NotImplementedError):
        return -1
    if n > limit("model_parameters"):
        raise CheckpointError(str(LimitError(source, "network (field 'model') of", n, "model_parameters")))
    return n


def build_from_state(path: str | os.PathLike, build: Callable[[], torch.nn.Module], state_dict: object,
                     what: str) -> torch.nn.Module:
    """``build()`` with the weights ``state_dict`` of the checkpoint ``path``, in eval mode; weights that do not fit
    the network (missing or unexpected keys, wrong shapes, a config it cannot build) are a :class:`CheckpointError`
    naming ``path`` and ``what`` they do not fit."""
    check_model_size(build, f"checkpoint {path}")
    try:
        model = build()
        model.load_state_dict(state_dict)
    except (KeyError, RuntimeError, TypeError, ValueError) as exc:
        why = " ".join(str(exc).split())[:200]
        raise CheckpointError(f"checkpoint {path}: weights do not {what} ({why})") from None
    return model.eval()


class CheckpointedModel:
    """The weights of a registered learned method: the file named by environment variable ``env`` (default
    ``default``), loaded by ``load(path) -> torch.nn.Module`` (which raises a clear error naming the training
    command when the file is missing) and kept until the file changes (path, mtime)."""

    def __init__(self, env: str, default: str | os.PathLike, load: Callable[[Path], torch.nn.Module]):
        self.env, self.default, self.load = env, Path(default), load
        self._cache: dict[tuple[str, float], torch.nn.Module] = {}

    def path(self) -> Path:
        """``$env`` or the default checkpoint path."""
        return Path(os.environ.get(self.env, self.default))

    def model(self) -> torch.nn.Module:
        """The module with the current checkpoint's weights (eval mode)."""
        path = self.path()
        if not path.is_file():
            self.load(path)  # raises its CheckpointNotFoundError with the training command
        key = (str(path.resolve()), path.stat().st_mtime)
        if key not in self._cache:
            self._cache.clear()
            self._cache[key] = self.load(path)
        return self._cache[key]

    def provenance(self) -> dict | None:
        """``{"path", "content_sha256", "verified", "file_sha256"}`` of the checkpoint the loaded module came from (None before
        it was loaded): what a result records so that a published number names the weights it was made with."""
        if not self._cache:
            return None
        (path, _), model = next(iter(self._cache.items()))
        return {"path": path, "content_sha256": getattr(model, "content_sha256", None),
                "verified": getattr(model, "content_verified", None),
                "file_sha256": getattr(model, "file_sha256", None)}

    def run(self, batch: dict) -> torch.Tensor:
        """The module on ``batch`` (on the batch's device, no gradients): (B, F, 1, H, W) e-."""
        model = self.model()
        dev = next((v.device for k, v in batch.items() if k.endswith("_e") and isinstance(v, torch.Tensor)), None)
        with torch.no_grad():
            return (model if dev is None else model.to(dev))(batch)


def checkpointed_method(name: str, env: str, default: str | os.PathLike,
                        load: Callable[[Path], torch.nn.Module]) -> Callable[[dict], torch.Tensor]:
    """The registered method of a checkpoint-backed baseline: ``method(batch)`` runs the module that ``load`` builds
    from the file ``$env`` (default ``default``) on the batch's device without gradients, (B, F, 1, H, W) e-.

    The method carries ``torch_module()`` (the loaded module: the evaluation counts its parameters and MACs),
    ``checkpoint_path()``, ``weights`` (the :class:`CheckpointedModel`) and ``checkpoint_provenance()`` (what the
    result records: :meth:`CheckpointedModel.provenance`).
    """
    weights = CheckpointedModel(env, default, load)

    def method(batch: dict) -> torch.Tensor:
        return weights.run(batch)

    method.__name__ = method.__qualname__ = name
    method.__doc__ = (f"Registered method ``{name}``: the network with the weights at ``${env}`` or {default}; "
                      "(B, F, 1, H, W) e-.")
    method.torch_module = weights.model  # type: ignore[attr-defined]
    method.checkpoint_path = weights.path  # type: ignore[attr-defined]
    method.weights = weights  # type: ignore[attr-defined]
    method.checkpoint_provenance = weights.provenance  # type: ignore[attr-defined]
    return method


def lazy_method(module: str, name: str) -> Callable[[dict], torch.Tensor]:
    """A registry entry for ``module.name`` that imports the module on first use; its ``torch_module`` (what the
    evaluation counts parameters and MACs of) is the method's own."""
    def method(batch: dict) -> torch.Tensor:
        return getattr(importlib.import_module(module), name)(batch)

    method.__name__ = name
    method.__doc__ = f"``{module}.{name}``, imported on first use."
    method.torch_module = lambda: getattr(importlib.import_module(module), name).torch_module()  # type: ignore[attr-defined]
    method.checkpoint_provenance = lambda: getattr(  # type: ignore[attr-defined]
        getattr(importlib.import_module(module), name), "checkpoint_provenance", lambda: None)()
    return method


def seal(path: str | os.PathLike) -> str:
    """Give a checkpoint written before checkpoints carried their hash its :data:`CONTENT_KEY` (rewritten
    atomically); returns the hash. Only for a file you trust: the hash vouches for what is in it now. A file that
    has a hash is checked against it first (a damaged file is not sealed)."""
    ck = read_weights(path)
    if isinstance(ck, dict) and CONTENT_KEY in ck:
        verify_content(ck, path)
    if not isinstance(ck, dict):
        raise CheckpointError(f"checkpoint {path}: not a dict of weights")
    save_checkpoint_file(ck, path)
    return content_sha256(ck)


if __name__ == "__main__":  # python -m lfmbench.baselines.checkpoint seal FILE
    if len(sys.argv) != 3 or sys.argv[1] != "seal":
        sys.exit("usage: python -m lfmbench.baselines.checkpoint seal CHECKPOINT.pt")
    try:
        print(f"{sys.argv[2]}: {CONTENT_KEY} {seal(sys.argv[2])}")
    except (CheckpointError, OSError) as exc:
        sys.exit(f"error: {exc}")
