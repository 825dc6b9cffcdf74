"""Triton kernel modules imported on first use, with one fallback rule for every module that has such kernels
(:mod:`lfmbench.sensor.counter_noise`, :mod:`lfmbench.datasets.row_gather`).

A kernel module needs Triton and a GPU; where Triton is not importable it is absent, and where a kernel cannot be
compiled (an unsupported GPU or Triton version) the caller falls back to its torch form, which gives the same
numbers, after one warning.
"""
from __future__ import annotations

import importlib
import warnings
from typing import Any

__all__ = ["TritonKernels"]


class TritonKernels:
    """The kernels of module ``module`` (a dotted name), loaded on first use.

    Args:
        module: the kernel module. label: what the warning names. fallback: what the caller uses instead.
    """

    def __init__(self, module: str, label: str, fallback: str) -> None:
        self.module_name, self.label, self.fallback = module, label, fallback
        self._mod: Any = None
        #: False: the caller takes its fallback (after a kernel failed here, or set by hand, e.g. in a test).
        self.enabled = True

    def ready(self, t: Any) -> bool:
        """Whether the kernels run for tensors like ``t``: enabled, ``t`` on CUDA, the module importable."""
        return self.enabled and bool(getattr(t, "is_cuda", False)) and self.module() is not None

    def module(self) -> Any:
        """The kernel module, or None where it cannot be imported (no Triton)."""
        if self._mod is None:
            try:
                self._mod = importlib.import_module(self.module_name)
            except ImportError:
                self._mod = False
        return self._mod or None

    def call(self, name: str, *args) -> Any:
        """Kernel ``name`` applied to ``args``; None (after one warning) when it fails to compile or run here:
        the kernels are then disabled (:meth:`ready` is False) and the caller takes its fallback."""
        try:
            return getattr(self.module(), name)(*args)
        except Exception as exc:  # noqa: BLE001 - a compiler error of any kind: fall back, same numbers
            self.enabled = False
            first = str(exc).splitlines()[0][:200] if str(exc) else ""
            warnings.warn(f"{self.label}: the Triton kernel {name} failed ({type(exc).__name__}: {first}); using "
                          f"{self.fallback} (same numbers, slower)", RuntimeWarning, stacklevel=3)
            return None
