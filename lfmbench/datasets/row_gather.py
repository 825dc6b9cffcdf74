"""Gathering rows of a table by index, the operation the device path does most (entries' rates, weights).

On a GPU, torch's row gathers (``index_select``, ``table[index]``, ``embedding``) moved 212 GB/s for rows of 64
bytes on an H200 (torch 2.11, CUDA 13), a plain Triton kernel 5.4 TB/s (5.7 M rows from a 12.8 MB table;
docs/benchmarks/device-path.md). :func:`gather_rows` takes the Triton kernel
(:mod:`lfmbench.datasets._row_gather_triton`) on CUDA where Triton is importable and ``index_select`` elsewhere:
the same values (a gather copies, it does not compute).
"""
from __future__ import annotations

import torch

from lfmbench.triton_kernels import TritonKernels

__all__ = ["gather_rows", "USE_TRITON"]

#: On CUDA, gather with the Triton kernel where Triton is importable (False: ``index_select`` everywhere).
USE_TRITON = True
_KERNELS = TritonKernels("lfmbench.datasets._row_gather_triton", "gather_rows", "index_select")


def gather_rows(table: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """Rows ``index`` of ``table``.

    Args:
        table: (N, *C) tensor, any dtype and device. index: (E,) int32/int64 row numbers in [0, N), same device.

    Returns:
        (E, *C) tensor: ``table.index_select(0, index)``.
    """
    global USE_TRITON
    if (USE_TRITON and table.is_cuda and table.is_floating_point() and index.dim() == 1 and table.dim() >= 1
            and _KERNELS.module() is not None):
        flat = table.contiguous().reshape(table.shape[0], -1)
        out = _KERNELS.call("gather_rows", flat, index)
        if out is not None:
            return out.reshape(index.shape[0], *table.shape[1:])
        USE_TRITON = False
    return table.index_select(0, index)
