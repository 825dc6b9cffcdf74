"""The compiled part of :mod:`lfmbench.poisson` (imported lazily: it needs numba at import time).

Module-level jitted functions and constant arrays, so that numba's on-disk cache (``cache=True``) is reused by
every process and DataLoader worker instead of compiling again (a closure over arrays is compiled anew in each
process: 0.5-0.8 s per worker start). The algorithm and its references are in :mod:`lfmbench.poisson`.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from lfmbench.constants import POISSON_EXACT_LIMIT

_u64 = numba.uint64
#: SplitMix64 increment (the golden-ratio constant), [Steele2014]_.
_GAMMA = np.uint64(0x9E3779B97F4A7C15)
#: Distance between two pixels' stream starts: 2^20 SplitMix64 steps (a draw uses at most a few dozen).
_STRIDE = np.uint64((0x9E3779B97F4A7C15 << 20) & 0xFFFFFFFFFFFFFFFF)
#: 1/k for k < 64 (k = 0 unused): a multiply instead of a divide in the sequential search.
_INV_K = 1.0 / np.maximum(np.arange(64, dtype=np.float64), 1.0)
#: log k! for k < 4096 (the PTRS draws below the 1000 e- switch-over), libm lgamma beyond: a table lookup
#: instead of lgamma on the draws that leave the squeeze.
_LOG_FACTORIAL = np.array([math.lgamma(k + 1.0) for k in range(4096)])
_EXACT_LIMIT = POISSON_EXACT_LIMIT


@numba.njit(inline="always", cache=True)
def _mix(z):
    """SplitMix64 finaliser (variant 13)."""
    z = (z ^ (z >> _u64(30))) * _u64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> _u64(27))) * _u64(0x94D049BB133111EB)
    return z ^ (z >> _u64(31))


@numba.njit(inline="always", cache=True)
def _uniform(state):
    """(u in (0, 1) with 53 random bits, next state)."""
    state = state + _GAMMA
    return (np.float64(_mix(state) >> _u64(11)) + 0.5) * (1.0 / 9007199254740992.0), state


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
        st = base + _u64(i) * _STRIDE
        if mu >= gaussian_above or mu >= _EXACT_LIMIT:
            u1, st = _uniform(st)
            u2, st = _uniform(st)
            z = math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)
            out[i] = max(0.0, np.rint(mu + math.sqrt(mu) * z))
        elif mu < 10.0:
            u, st = _uniform(st)
            p = math.exp(-mu)
            f = p
            k = 0
            # F(k) reaches 1 - 1e-16 by k ~ 40 for mu < 10; stop where p underflows or rounding stalls F
            while u > f and p > 0.0:
                k += 1
                p *= mu * (_INV_K[k] if k < 64 else 1.0 / k)
                f += p
            out[i] = k
        else:
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
                    break
                if k < 0.0 or (us < 0.013 and v > us):
                    continue
                invalpha = 1.1239 + 1.1328 / (b - 3.4)
                logfact = _LOG_FACTORIAL[k] if k < _LOG_FACTORIAL.size else math.lgamma(k + 1.0)
                if math.log(v * invalpha / (a / (us * us) + b)) <= -mu + k * math.log(mu) - logfact:
                    break
            out[i] = k
    return -1

