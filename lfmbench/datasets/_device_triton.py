"""The crops of the device program (:meth:`lfmbench.datasets.device.SplitProgram.pieces`) as Triton kernels (CUDA;
imported lazily): the lamp entries (:func:`crop_entries`) and the crops of the whole-frame layers
(:func:`crop_planes`: one program per output row copies it; torch's four-index gather moved these bytes at about a
tenth of the device's bandwidth: 4.1 ms for the static, light-index and depth crops of a 256 x 256 batch of 256
three-frame samples on an H100).

**Entries.**
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
def _crop_entries_kernel(run_ptr, first_ptr, before_ptr, ey_ptr, ex_ptr, epos_ptr, shown_ptr, y0_ptr, x0_ptr, vals_ptr,
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
        _crop_entries_kernel[(triton.cdiv(E, _BLOCK),)](
            run, first.contiguous(), before.contiguous(), e_y, e_x, e_pos, shown.contiguous().view(torch.uint8),
            y0.contiguous(), x0.contiguous(), e_vals.contiguous(), pix, slot, out, E, NR, F, lf, h, w,
            C=C, CP=triton.next_power_of_2(C), BLOCK=_BLOCK)
    return pix, slot, out


@triton.jit
def _crop_kernel(src, sc_ptr, fr_ptr, y0_ptr, x0_ptr, out, F, C, h, w, s_s, s_f, s_c, s_y, BW: tl.constexpr):
    row = tl.program_id(0).to(tl.int64)          # (b, f, c, y) of the output, row-major
    y = row % h
    t = row // h
    c = t % C
    t = t // C
    f = t % F
    b = t // F
    s = tl.load(sc_ptr + b)
    fr = tl.load(fr_ptr + b * F + f)
    x = tl.program_id(1) * BW + tl.arange(0, BW)
    m = x < w
    base = s * s_s + fr * s_f + c * s_c + (tl.load(y0_ptr + b) + y) * s_y + tl.load(x0_ptr + b)
    tl.store(out + row * w + x, tl.load(src + base + x, mask=m), mask=m)


def crop_planes(full: torch.Tensor, sc: torch.Tensor, fr: torch.Tensor, y0: torch.Tensor, x0: torch.Tensor,
                h: int, w: int) -> torch.Tensor:
    """Crops of whole-frame layers, one (sample, frame) each: ``out[b, f] = full[sc[b], fr[b, f], :, y0[b]:y0[b] + h,
    x0[b]:x0[b] + w]`` (a copy, any dtype).

    Args:
        full: (nS, Fs, C, H, W) layers (unit-stride rows). sc: (B,) int64 scene. fr: (B, F) int64 frames.
        y0, x0: (B,) int64 crop origins (px), the crops inside the frame.

    Returns:
        (B, F, C, h, w) tensor of ``full``'s dtype.
    """
    B, F = (int(n) for n in fr.shape)
    C = int(full.shape[2])
    out = torch.empty((B, F, C, h, w), dtype=full.dtype, device=full.device)
    if out.numel():
        BW = min(triton.next_power_of_2(w), 1024)
        s = full.stride()
        _crop_kernel[(B * F * C * h, triton.cdiv(w, BW))](
            full, sc.contiguous(), fr.contiguous(), y0.contiguous(), x0.contiguous(), out, F, C, h, w,
            s[0], s[1], s[2], s[3], BW=BW)
    return out
