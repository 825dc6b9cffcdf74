"""The lamp-entry pass of :func:`lfmbench.datasets.batched.compose_batch` as one Triton kernel (CUDA; imported
lazily).

The torch form gathers each entry's three weight rows, multiplies them with the entry's rates, sums over the bins
and scatters with three ``index_add_`` calls: about a dozen passes over E x Kmax values (E entries, 1.8 M in a
128 x 128 batch of 64 three-frame samples). Here one pass reads each entry's rates and weight rows once and adds its
three sums to the composed frames with atomic adds: the same products, summed over the bins in order (float32);
torch's reduction and scatter sum in other orders, so the two agree to float32 rounding of the sums.
"""
from __future__ import annotations

import torch
import triton
import triton.language as tl

_BLOCK = 256


@triton.jit
def _entries_kernel(lpd, spd, gt, slot_sample, entry_slot, entry_pix, vals, sv_c, sv_k, sv_e, w_lpd, w_spd, w_gt,
                    E, R, w, hw, fhw, K: tl.constexpr, BLOCK: tl.constexpr):
    e = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    m = e < E
    slot = tl.load(entry_slot + e, mask=m, other=0).to(tl.int64)
    pix = tl.load(entry_pix + e, mask=m, other=0).to(tl.int64)
    smp = tl.load(slot_sample + slot, mask=m, other=0).to(tl.int64)
    dest = smp * fhw + pix
    row = tl.where(R > 1, (pix % hw) // w, 0)
    at = (slot * R + row) * K
    eo = e.to(tl.int64) * sv_e
    a0 = tl.zeros([BLOCK], dtype=tl.float32)
    a1 = tl.zeros([BLOCK], dtype=tl.float32)
    a2 = tl.zeros([BLOCK], dtype=tl.float32)
    for k in tl.static_range(K):
        v0 = tl.load(vals + eo + k * sv_k, mask=m, other=0.0)
        v1 = tl.load(vals + sv_c + eo + k * sv_k, mask=m, other=0.0)
        a0 += v0 * tl.load(w_lpd + at + k, mask=m, other=0.0).to(tl.float32)
        a1 += v1 * tl.load(w_spd + at + k, mask=m, other=0.0).to(tl.float32)
        a2 += v0 * tl.load(w_gt + at + k, mask=m, other=0.0).to(tl.float32)
    tl.atomic_add(lpd + dest, a0, mask=m)
    tl.atomic_add(spd + dest, a1, mask=m)
    tl.atomic_add(gt + dest, a2, mask=m)


def compose_entries(comp: dict, slot_sample: torch.Tensor, entry_slot: torch.Tensor, entry_pix: torch.Tensor,
                    values: torch.Tensor, weights: dict, h: int, w: int) -> dict:
    """Add every lamp entry's light to the composed frames, in place (returns ``comp``).

    Args:
        comp: ``{"lpd", "spd", "gt"}`` (B, F, h, w) float32 e-, contiguous (the static part already in them).
        slot_sample: (S,) sample of each slot. entry_slot, entry_pix: (E,) slot and pixel ``f * h * w + y * w + x``
            of each entry. values: (2, Kmax, E) float32 e-/s (LPD, SPD rates per bin), any strides.
        weights: ``{"lpd", "spd", "gt"}`` (S, R, Kmax) float64 s (:func:`~lfmbench.datasets.batched.pwm_weights`).
    """
    E = int(entry_pix.shape[0])
    if E == 0:
        return comp
    S, R, K = (int(n) for n in weights["lpd"].shape)
    B, F = (int(n) for n in comp["lpd"].shape[:2])
    wl, ws, wg = (weights[k].contiguous() for k in ("lpd", "spd", "gt"))
    _entries_kernel[(triton.cdiv(E, _BLOCK),)](
        comp["lpd"], comp["spd"], comp["gt"], slot_sample.contiguous(), entry_slot.contiguous(),
        entry_pix.contiguous(), values, values.stride(0), values.stride(1), values.stride(2), wl, ws, wg,
        E, R, w, h * w, F * h * w, K=K, BLOCK=_BLOCK)
    return comp
