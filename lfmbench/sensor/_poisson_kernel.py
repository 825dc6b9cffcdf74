"""The compiled part of :mod:`lfmbench.sensor.poisson` (imported lazily: it needs numba at import time).

Module-level jitted functions and constant arrays, so that numba's on-disk cache (``cache=True``) is reused by
every process and DataLoader worker instead of compiling again (a closure over arrays is compiled anew in each
process: 0.5-0.8 s per worker start). The algorithm and its references are in :mod:`lfmbench.sensor.poisson`.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from lfmbench.constants import POISSON_EXACT_LIMIT
from lfmbench.counter_rng import GAMMA, MIX_MUL, STRIDE_LOG2
from lfmbench.sensor.counter_noise import LOG_FACTORIAL

_u64 = numba.uint64
#: SplitMix64 increment and finaliser multipliers: the streams of :mod:`lfmbench.counter_rng`, [Steele2014]_.
_GAMMA = np.uint64(GAMMA)
_MUL0, _MUL1 = np.uint64(MIX_MUL[0]), np.uint64(MIX_MUL[1])
#: Distance between two pixels' stream starts: 2^20 SplitMix64 steps (a draw uses at most a few dozen).
_STRIDE = np.uint64((GAMMA << STRIDE_LOG2) & 0xFFFFFFFFFFFFFFFF)
#: 1/k for k < 64 (k = 0 unused): a multiply instead of a divide in the sequential search.
_INV_K = 1.0 / np.maximum(np.arange(64, dtype=np.float64), 1.0)
#: log k! for k < 4096 (the PTRS draws below the 1000 e- switch-over), libm lgamma beyond: a table lookup
#: instead of lgamma on the draws that leave the squeeze.
_LOG_FACTORIAL = LOG_FACTORIAL
_EXACT_LIMIT = POISSON_EXACT_LIMIT


@numba.njit(inline="always", cache=True)
def _mix(z):
    """SplitMix64 finaliser (variant 13)."""
    z = (z ^ (z >> _u64(30))) * _MUL0
    z = (z ^ (z >> _u64(27))) * _MUL1
    return z ^ (z >> _u64(31))


@numba.njit(inline="always", cache=True)
def _uniform(state):
    """(u in (0, 1) with 53 random bits, next state)."""
    state = state + _GAMMA
    return (np.float64(_mix(state) >> _u64(11)) + 0.5) * (1.0 / 9007199254740992.0), state


@numba.njit(inline="always", cache=True)
def _inv_k(k):
    """1 / k (k >= 1): a table lookup below 64."""
    return _INV_K[k] if k < 64 else 1.0 / k


@numba.njit(inline="always", cache=True, error_model="numpy")
def _draw(mu, st, gaussian_above):  # pragma: no cover - compiled by numba
    """One draw ~ Poisson(mu) (float64 mu > 0, finite) from the stream starting at state ``st``, as a float64
    count: rounded normal from ``gaussian_above`` or 2^52 on, inversion below 10, PTRS between."""
    if mu >= gaussian_above or mu >= _EXACT_LIMIT:
        u1, st = _uniform(st)
        u2, st = _uniform(st)
        z = math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)
        return max(0.0, np.rint(mu + math.sqrt(mu) * z))
    if mu < 10.0:
        # sequential search: the smallest k with u <= F(k) or p_k == 0 (p_k = p_{k-1} mu / k, F(k) = F(k-1) + p_k;
        # F reaches 1 - 1e-16 by k ~ 40 for mu < 10, p underflows or rounding stalls F beyond). Both conditions
        # only switch from false to true as k grows, so k is also the number of terms where neither holds: the
        # terms are evaluated four at a time without a branch per term (the same products and sums, so the same
        # k; a mispredicted loop exit per term cost more than the arithmetic), after a k = 0 test (most means
        # are < 1 e-).
        u, st = _uniform(st)
        # k = 0 without the exp where u is below a lower bound of exp(-mu): the alternating series cut after its
        # third term, exp(-mu) - bound = O(mu^4 / 24) >= 4e-14 for mu >= 1e-3, far above the bound's rounding
        # (1e-15), so u <= bound implies u <= exp(-mu) as computed: the same k (most means are below 1 e-)
        if mu >= 1e-3 and u <= 1.0 - mu * (1.0 - mu * (0.5 - mu * (1.0 / 6.0))):
            return 0.0
        p = math.exp(-mu)
        if u <= p:
            return 0.0
        f = p
        k = 0
        while True:
            p1 = p * (mu * _inv_k(k + 1))
            f1 = f + p1
            p2 = p1 * (mu * _inv_k(k + 2))
            f2 = f1 + p2
            p3 = p2 * (mu * _inv_k(k + 3))
            f3 = f2 + p3
            p4 = p3 * (mu * _inv_k(k + 4))
            f4 = f3 + p4
            c = (np.int64((u > f) & (p > 0.0)) + np.int64((u > f1) & (p1 > 0.0))
                 + np.int64((u > f2) & (p2 > 0.0)) + np.int64((u > f3) & (p3 > 0.0)))
            if c < 4:
                return np.float64(k + c)
            k += 4
            p = p4
            f = f4
    # PTRS; the logs of the exact test are only needed off the squeeze (24-65 % of first tries)
    b = 0.931 + 2.53 * math.sqrt(mu)
    a = -0.059 + 0.02483 * b
    vr = 0.9277 - 3.6224 / (b - 2.0)
    while True:
        u, st = _uniform(st)
        v, st = _uniform(st)
        u -= 0.5
        us = 0.5 - abs(u)
        k = math.floor((2.0 * a / us + b) * u + mu + 0.43)
        if us >= 0.07 and v <= vr:
            return np.float64(k)
        if k < 0.0 or (us < 0.013 and v > us):
            continue
        invalpha = 1.1239 + 1.1328 / (b - 3.4)
        logfact = _LOG_FACTORIAL[k] if k < _LOG_FACTORIAL.size else math.lgamma(k + 1.0)
        if math.log(v * invalpha / (a / (us * us) + b)) <= -mu + k * math.log(mu) - logfact:
            return np.float64(k)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def kernel(mean, out, seed, gaussian_above):  # pragma: no cover - compiled by numba
    """Draw ``out[i] ~ Poisson(mean[i])`` (rounded normal from ``gaussian_above`` or 2^52 on).

    Args: ``mean`` (N,) float32/float64 means (e.g. e-), ``out`` (N,) array written in place (counts, same
    unit), ``seed`` uint64, ``gaussian_above`` float switch-over mean. Returns -1, or the first index whose mean
    is negative, NaN or infinite (``out`` is then incomplete and the caller raises).
    """
    base = _mix(seed)
    for i in range(mean.size):
        mu = np.float64(mean[i])
        if not mu > 0.0:
            if mu == 0.0:
                out[i] = 0.0
                continue
            return i  # negative or NaN: the caller raises, naming the element
        if mu == math.inf:
            return i
        out[i] = _draw(mu, base + _u64(i) * _STRIDE, gaussian_above)
    return -1


@numba.njit(cache=True, nogil=True, error_model="numpy")
def collect(mean, gain, gain_row, add, cap, full_well, seed, gaussian_above, noise, out):  # pragma: no cover
    """The collected electrons of one photodiode: input clipping, PRNU, dark signal, shot noise and the full
    well in one pass (the CPU form of the loop in :func:`lfmbench.sensor.simulate_split_pixel_electrons`).

    Per pixel j of row r (same dtype arithmetic as the torch chain, constants in the arrays' dtype):
    ``m = min(max(nan_to_num(mean, nan=0), 0), cap)``; ``m = m * gain[gain_row[r], j]`` when ``gain`` has rows;
    ``m = m + add[r]``; ``n = Poisson(m)`` (pixel index ``r * W + j``, as :func:`kernel` on the flattened rows,
    when ``noise``) else ``m``; ``out = min(max(n, 0), full_well)``.

    Args: ``mean`` (R, P) mean e- (float32/float64, C-contiguous), ``gain`` (G, P) PRNU gains (1) or (0, P),
    ``gain_row`` (R,) int64 row of ``gain`` per row, ``add`` (R,) e- added per row (dark signal), ``cap`` and
    ``full_well`` e- (dtype of ``mean``), ``seed`` uint64, ``gaussian_above`` e- (float64), ``noise`` bool,
    ``out`` (R, P) written. Returns -1, or the first flat index whose Poisson mean was invalid.
    """
    base = _mix(seed)
    zero = cap - cap
    use_gain = gain.shape[0] > 0
    R, P = mean.shape
    for r in range(R):
        a = add[r]
        g = gain_row[r] if use_gain else 0
        for j in range(P):
            x = mean[r, j]
            if x != x:
                x = zero
            x = min(max(x, zero), cap)
            if use_gain:
                x = x * gain[g, j]
            x = x + a
            if noise:
                # counts are integers, exact in either float type: clipping before or after the cast agrees
                mu = np.float64(x)
                i = r * P + j
                if not mu > 0.0:
                    if mu != 0.0:
                        return i
                    n = 0.0
                elif mu == math.inf:
                    return i
                else:
                    n = _draw(mu, base + _u64(i) * _STRIDE, gaussian_above)
                out[r, j] = min(max(n, 0.0), np.float64(full_well))
            else:
                out[r, j] = min(max(x, zero), full_well)
    return -1


@numba.njit(cache=True, nogil=True, error_model="numpy")
def normals(seed, out):  # pragma: no cover - compiled by numba
    """Standard normals of the counter streams (:func:`lfmbench.sensor.counter_noise.normal` for one sample):
    ``out[i] = sqrt(-2 ln u0) cos(2 pi u1)`` with u0, u1 draws 0 and 1 of pixel i's stream of ``seed`` (uint64);
    ``out`` (N,) float32 or float64 is written in place."""
    base = _mix(seed)
    for i in range(out.size):
        u1, st = _uniform(base + _u64(i) * _STRIDE)
        u2, st = _uniform(st)
        out[i] = math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)
