"""The crop's lamp entries of the device program (:meth:`lfmbench.datasets.device.SplitProgram.pieces`) as one
Triton kernel (CUDA; imported lazily).

The torch form makes each entry's table row, pixel, slot and visibility with about twenty passes over the E
entries (1.8 M in a 128 x 128 batch of 64 three-frame samples), each an indexed gather or an integer operation,
and then gathers and masks the rates (E x 2 x K floats) in two more. Here one pass per entry does all of it: the
same integer arithmetic and the same gathered values (a gather copies; the mask multiplies by 1.0 or 0.0 as the
torch form does), so the outputs are equal bit for bit.
"""
from __future__ import annotations

import torch
import triton
import triton.language as tl

_BLOCK = 256


@triton.jit
def _entries_kernel(run_ptr, first_ptr, before_ptr, ey_ptr, ex_ptr, epos_ptr, shown_ptr, y0_ptr, x0_ptr, vals_ptr,
                    pix_ptr, slot_ptr, out_ptr, E, NR, F, LF, h, w, C: tl.constexpr, CP: tl.constexpr,
                    BLOCK: tl.constexpr):
    e = tl.program_id(0).to(tl.int64) * BLOCK + tl.arange(0, BLOCK)
    m = e < E
    r = tl.load(run_ptr + e, mask=m, other=0)
    gid = tl.load(first_ptr + r, mask=m, other=0) + e - tl.load(before_ptr + r, mask=m, other=0)
    ey = tl.load(ey_ptr + gid, mask=m, other=0).to(tl.int64)
    ex = tl.load(ex_ptr + gid, mask=m, other=0).to(tl.int64)
    pair = r // NR
    b = pair // F
    f = pair % F
    slot = pair * LF + tl.load(epos_ptr + gid, mask=m, other=0).to(tl.int64)
    y0 = tl.load(y0_ptr + b, mask=m, other=0)
    x0 = tl.load(x0_ptr + b, mask=m, other=0)
    ok = (tl.load(shown_ptr + slot, mask=m, other=0) != 0) & (ey >= y0) & (ey < y0 + h) & (ex >= x0) & (ex < x0 + w)
    pix = f * (h * w) + (ey - y0) * w + (ex - x0)
    tl.store(pix_ptr + e, tl.where(ok, pix, 0).to(tl.int32), mask=m)
    tl.store(slot_ptr + e, slot.to(tl.int32), mask=m)
    c = tl.arange(0, CP)
    mc = m[:, None] & (c[None, :] < C)
    v = tl.load(vals_ptr + gid[:, None] * C + c[None, :], mask=mc, other=0.0)
    okf = tl.where(ok, 1.0, 0.0).to(tl.float32)
    tl.store(out_ptr + e[:, None] * C + c[None, :], v * okf[:, None], mask=mc)


def crop_entries(run: torch.Tensor, first: torch.Tensor, before: torch.Tensor, e_y: torch.Tensor, e_x: torch.Tensor,
                 e_pos: torch.Tensor, shown: torch.Tensor, y0: torch.Tensor, x0: torch.Tensor, e_vals: torch.Tensor,
                 NR: int, F: int, lf: int, h: int, w: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The entries of a batch's crops.

    Args:
        run: (E,) int64 run of each entry (a run: the entries of one tile row of one (sample, frame)).
        first, before: (B * F * NR,) int64 first table row of each run, and the entries of the runs before it.
        e_y, e_x, e_pos: (N,) int32 pixel row, column (px) and light position of every table row.
        shown: (B * F * lf,) bool, whether each slot's light is shown. y0, x0: (B,) int64 crop origins (px).
        e_vals: (N, 2, Kall) float32 rates (e-/s), contiguous.

    Returns:
        ``entry_pix`` (E,) int32 (``f * h * w + y * w + x`` in the crop, 0 where masked), ``entry_slot`` (E,) int32,
        the rates (E, 2, Kall) float32, zero where the entry is outside its crop or its light is not shown.
    """
    E = int(run.shape[0])
    C = int(e_vals.shape[1] * e_vals.shape[2])
    dev = run.device
    pix = torch.empty(E, dtype=torch.int32, device=dev)
    slot = torch.empty(E, dtype=torch.int32, device=dev)
    out = torch.empty((E,) + tuple(e_vals.shape[1:]), dtype=torch.float32, device=dev)
    if E:
        _entries_kernel[(triton.cdiv(E, _BLOCK),)](
            run, first.contiguous(), before.contiguous(), e_y, e_x, e_pos, shown.contiguous().view(torch.uint8),
            y0.contiguous(), x0.contiguous(), e_vals.contiguous(), pix, slot, out, E, NR, F, lf, h, w,
            C=C, CP=triton.next_power_of_2(C), BLOCK=_BLOCK)
    return pix, slot, out
