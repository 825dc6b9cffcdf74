"""The compiled CPU form of :func:`lfmbench.datasets.batch_compose.compose_batch` (numba; imported lazily).

One pass over the static rates and one over the light-pixel entries instead of about fifteen torch passes
(products, a copy for the ground truth, the transposed entry values, three gathers, products, sums and
scatter-adds). Module-level and ``cache=True`` so DataLoader workers load it from numba's on-disk cache.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, error_model="numpy")
def compose(static, t_s, t_l, slot_sample, entry_slot, entry_pix, vals, w_lpd, w_spd, w_gt, width, out_lpd,
            out_spd, out_gt, b0, b1, e0, e1):  # pragma: no cover - compiled by numba
    """Mean electrons of a batch (all float arrays float32; the torch formula's products, and its summation order
    per pixel).

    Args:
        static: (B, F, 2, P) static rates of LPD and SPD, e-/s (P = h * w pixels of a crop).
        t_s, t_l: (B,) short and long exposure, s.
        slot_sample: (S,) int64 sample of each light slot. entry_slot: (E,) int32 slot of each entry.
        entry_pix: (E,) int32 flat pixel of each entry in its sample's (F, h, w).
        vals: (2, K, E) rates of each entry (LPD, SPD) per bin, e-/s.
        w_lpd, w_spd, w_gt: (S, R, K) PWM exposure per slot, row and bin, s (R = h rows, or 1 when the weights do
            not depend on the row).
        width: w, the crop width in pixels (the row of pixel p is (p mod P) div w).
        out_lpd, out_spd, out_gt: (B, F, P) written: e-.
        b0, b1, e0, e1: the samples b0..b1-1 and their entries e0..e1-1 (a part of the batch, for threads).

    ``out_lpd = static_lpd * t_s`` and ``out_spd = static_spd * t_l`` per pixel, ``out_gt = out_lpd``; then entry by
    entry in order, ``out[dest] += sum_k vals[k] * w[slot, row, k]`` (k ascending).
    """
    _, F, _, P = static.shape
    for b in range(b0, b1):
        ts = t_s[b]
        tl = t_l[b]
        for f in range(F):
            for j in range(P):
                x = static[b, f, 0, j] * ts
                out_lpd[b, f, j] = x
                out_gt[b, f, j] = x
                out_spd[b, f, j] = static[b, f, 1, j] * tl
    R = w_lpd.shape[1]
    K = vals.shape[1]
    for e in range(e0, e1):
        s = entry_slot[e]
        b = slot_sample[s]
        p = entry_pix[e]
        f = p // P
        j = p - f * P
        r = j // width if R > 1 else 0
        a_l = np.float32(0.0)
        a_s = np.float32(0.0)
        a_g = np.float32(0.0)
        for k in range(K):
            v_l = vals[0, k, e]
            v_s = vals[1, k, e]
            a_l += v_l * w_lpd[s, r, k]
            a_g += v_l * w_gt[s, r, k]
            a_s += v_s * w_spd[s, r, k]
        out_lpd[b, f, j] += a_l
        out_spd[b, f, j] += a_s
        out_gt[b, f, j] += a_g
