"""Learned baselines backed by a checkpoint file: one rule for where the weights are, loading them once, running
them (:func:`checkpointed_method`, the one registration helper of every checkpoint-backed baseline), and
registering them lazily (:func:`lazy_method`, so that importing :mod:`lfmbench.baselines` imports no network
module)."""
from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from pathlib import Path

import torch


class CheckpointError(ValueError):
    """A checkpoint file that cannot be used: unreadable, truncated, a pickle of code that ``weights_only``
    refuses, or another format. Bad input (``lfmbench evaluate`` exits 2 naming the file), not a scene failure."""


def read_weights(path: str | os.PathLike, map_location: str | torch.device = "cpu") -> object:
    """``torch.load(path, weights_only=True)`` (tensors and plain data only: no code from a file runs); any failure
    is a :class:`CheckpointError` naming ``path``."""
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
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
    if not path.is_file():
        raise not_found(f"no {what} checkpoint at {path}; train one with `lfmbench train --method {method} "
                        f"--corpus DIR --out {path}` (or set ${env})")
    return read_weights(path, map_location)


def build_from_state(path: str | os.PathLike, build: Callable[[], torch.nn.Module], state_dict: object,
                     what: str) -> torch.nn.Module:
    """``build()`` with the weights ``state_dict`` of the checkpoint ``path``, in eval mode; weights that do not fit
    the network (missing or unexpected keys, wrong shapes, a config it cannot build) are a :class:`CheckpointError`
    naming ``path`` and ``what`` they do not fit."""
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
    ``checkpoint_path()`` and ``weights`` (the :class:`CheckpointedModel`).
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
    return method


def lazy_method(module: str, name: str) -> Callable[[dict], torch.Tensor]:
    """A registry entry for ``module.name`` that imports the module on first use; its ``torch_module`` (what the
    evaluation counts parameters and MACs of) is the method's own."""
    def method(batch: dict) -> torch.Tensor:
        return getattr(importlib.import_module(module), name)(batch)

    method.__name__ = name
    method.__doc__ = f"``{module}.{name}``, imported on first use."
    method.torch_module = lambda: getattr(importlib.import_module(module), name).torch_module()  # type: ignore[attr-defined]
    return method
