"""The row gather of :mod:`lfmbench.datasets.row_gather` as a Triton kernel (CUDA; imported lazily)."""
from __future__ import annotations

import torch
import triton
import triton.language as tl

_BLOCK = 128


@triton.jit
def _rows_kernel(src, idx, out, E, C: tl.constexpr, CP: tl.constexpr, BLOCK: tl.constexpr):
    # BLOCK rows of C values per program; CP: C rounded up to a power of two (masked)
    r = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    m = r < E
    i = tl.load(idx + r, mask=m, other=0).to(tl.int64)
    c = tl.arange(0, CP)
    mc = m[:, None] & (c[None, :] < C)
    v = tl.load(src + i[:, None] * C + c[None, :], mask=mc, other=0.0)
    tl.store(out + r.to(tl.int64)[:, None] * C + c[None, :], v, mask=mc)


def gather_rows(table: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``table[index]`` for a contiguous (N, C) ``table`` and an (E,) integer ``index`` on one device: (E, C)."""
    E, C = int(index.shape[0]), int(table.shape[1])
    out = torch.empty(E, C, device=table.device, dtype=table.dtype)
    if E and C:
        _rows_kernel[(triton.cdiv(E, _BLOCK),)](table, index.contiguous(), out, E, C=C,
                                                CP=triton.next_power_of_2(C), BLOCK=_BLOCK)
    return out
