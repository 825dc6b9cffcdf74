"""The composition of :mod:`lfmbench.datasets.batched` on CUDA as Triton kernels (imported lazily): the PWM
weights of every slot, row and bin (:func:`pwm_weights`), and the lamp-entry pass (:func:`compose_entries`).

**Weights.** The torch form of :func:`lfmbench.datasets.batch_compose.pwm_weights` is about 180 small element-wise
launches (the window starts, the bin grid and, per window, :func:`lfmbench.flicker.pwm_exposure`'s compensated
arithmetic). Here one kernel computes the three windows of an element from the slot's draws: the same float64
operations in the same order (compiled without fused multiply-adds; ``fmod`` from exact operations,
:mod:`lfmbench._triton_math`), so the weights equal the torch form's (zeros may differ in sign).

**Entries.**
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

from lfmbench._triton_math import _d, fmod, rint, two_prod, two_sum

_BLOCK = 256
#: Compile option of the weights kernel: no fused multiply-adds (each float64 step rounds as torch's does).
_EXACT = {"enable_fp_fusion": False}


@triton.jit
def _pulse(ph, te, T, D):
    """ON time (s) of an ideal PWM pulse over ``[ph, ph + te)`` (:func:`lfmbench.flicker.exact._pulse_core`, ideal)."""
    r = fmod(te, T)
    n = rint((te - r) / T)
    p, e = two_prod(D, T)
    full = n * p + n * e
    a = fmod(ph, T)
    zero = r * _d(0.0)
    s, se = two_sum(T, -a)
    o1 = tl.maximum(tl.minimum(r, (p - a) + e), zero)
    o2 = tl.maximum(tl.minimum((r - s) - se, p + e), zero)
    q, qe = two_sum(p, -T)
    m1 = tl.maximum(tl.minimum(r, (q - a) + (qe + e)), zero)
    m2 = tl.maximum(tl.minimum(r + a, p + e), zero)
    return full + tl.where(a < _d(0.0), m1 + m2, o1 + o2)


@triton.jit
def _window(e_lo, e_hi, start, length, ph0, T, D):
    """A bin's overlap (s) with a window, and its time at PWM level 1 (s): :func:`window_bin_exposure`."""
    lo = tl.maximum(e_lo, start)
    hi = tl.minimum(e_hi, start + length)
    dur = tl.maximum(hi - lo, _d(0.0))
    return dur, _d(1.0) * _pulse(lo - ph0, dur, T, D) + _d(0.0) * dur


@triton.jit
def _weights_kernel(sample_ptr, frame_ptr, k_ptr, pwm_ptr, timing_ptr, t0_ptr, crop_ptr, lpd_ptr, spd_ptr, gt_ptr,
                    N, R, F, KMAX, ROLLING: tl.constexpr, BLOCK: tl.constexpr):
    i = tl.program_id(0).to(tl.int64) * BLOCK + tl.arange(0, BLOCK)
    m = i < N
    k = i % KMAX
    t = i // KMAX
    r = t % R
    s = t // R
    sb = tl.load(sample_ptr + s, mask=m, other=0)
    fr = tl.load(frame_ptr + s, mask=m, other=0)
    ks = tl.load(k_ptr + s, mask=m, other=1)
    t_s = tl.load(timing_ptr + sb * 4, mask=m, other=1.0)
    t_l = tl.load(timing_ptr + sb * 4 + 1, mask=m, other=1.0)
    td = tl.load(timing_ptr + sb * 4 + 2, mask=m, other=0.0)
    cw = tl.load(timing_ptr + sb * 4 + 3, mask=m, other=1.0)
    t0 = tl.load(t0_ptr + sb * F + fr, mask=m, other=0.0)
    T = tl.load(pwm_ptr + s * 5, mask=m, other=1.0)
    D = tl.load(pwm_ptr + s * 5 + 1, mask=m, other=0.5)
    ph0 = tl.load(pwm_ptr + s * 5 + 2, mask=m, other=0.0)
    if ROLLING:
        shift = (tl.load(crop_ptr + sb * 4, mask=m, other=0).to(tl.float64) + r.to(tl.float64)) * td
    else:
        shift = tl.zeros_like(t0)
    st_l = (t0 + (t_l - t_s) / _d(2.0)) + shift          # window_starts
    st_s = t0 + shift
    kc = tl.maximum(ks, 1).to(tl.float64)                         # bin_edges of K.clamp_min(1)
    step = cw / kc
    kf = k.to(tl.float64)
    k1 = kf + _d(1.0)
    e_lo = t0 + tl.where(kf >= kc, cw, kf * step + _d(0.0))
    e_hi = t0 + tl.where(k1 >= kc, cw, k1 * step + _d(0.0))
    dur_l, w_l = _window(e_lo, e_hi, st_l, t_s, ph0, T, D)
    _dur_s, w_s = _window(e_lo, e_hi, st_s, t_l, ph0, T, D)
    tl.store(lpd_ptr + i, w_l, mask=m)
    tl.store(spd_ptr + i, w_s, mask=m)
    tl.store(gt_ptr + i, dur_l * D, mask=m)


def pwm_weights(batch: dict, R: int, kmax: int) -> dict:
    """:func:`lfmbench.datasets.batch_compose.pwm_weights` of a batch of ideal pulses without group slots, on CUDA.

    Args:
        batch: a :func:`~lfmbench.datasets.batched.collate_pieces` batch (float64 ``slot_pwm``, ``timing``, ``t0``).
        R: rows (the crop's height for a rolling shutter, else 1). kmax: bins.

    Returns:
        ``{"lpd", "spd", "gt"}``: (S, R, kmax) float64 s.
    """
    S = int(batch["slot_sample"].shape[0])
    dev = batch["slot_pwm"].device
    out = {k: torch.empty(S, R, kmax, dtype=torch.float64, device=dev) for k in ("lpd", "spd", "gt")}
    N = S * R * kmax
    if N:
        F = int(batch["t0"].shape[1])
        _weights_kernel[(triton.cdiv(N, _BLOCK),)](
            batch["slot_sample"].contiguous(), batch["slot_frame"].contiguous(), batch["slot_K"].contiguous(),
            batch["slot_pwm"].contiguous(), batch["timing"].contiguous(), batch["t0"].contiguous(),
            batch["crop"].contiguous(), out["lpd"], out["spd"], out["gt"], N, R, F, kmax,
            ROLLING=R > 1, BLOCK=_BLOCK, **_EXACT)
    return out


@triton.jit
def _compose_entries_kernel(lpd, spd, gt, slot_sample, entry_slot, entry_pix, vals, sv_c, sv_k, sv_e, w_lpd, w_spd, w_gt,
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
        weights: ``{"lpd", "spd", "gt"}`` (S, R, Kmax) float64 s (:func:`~lfmbench.datasets.batch_compose.pwm_weights`).
    """
    E = int(entry_pix.shape[0])
    if E == 0:
        return comp
    S, R, K = (int(n) for n in weights["lpd"].shape)
    B, F = (int(n) for n in comp["lpd"].shape[:2])
    wl, ws, wg = (weights[k].contiguous() for k in ("lpd", "spd", "gt"))
    _compose_entries_kernel[(triton.cdiv(E, _BLOCK),)](
        comp["lpd"], comp["spd"], comp["gt"], slot_sample.contiguous(), entry_slot.contiguous(),
        entry_pix.contiguous(), values, values.stride(0), values.stride(1), values.stride(2), wl, ws, wg,
        E, R, w, h * w, F * h * w, K=K, BLOCK=_BLOCK)
    return comp
