"""Exact Poisson sampling of shot noise on the CPU: a compiled, counter-based sampler (numba).

``torch.poisson`` costs about 13-60 ns a draw on this machine's CPU and was half of a dataset sample's time
(docs/dataset-benchmark.md). This module draws the same distribution 1.2-1.7x faster at a fixed mean and
1.6-2.3x faster on a dataset sample's mixed means (docs/sensor.md), in one compiled loop:

- mean ``mu < 10``: **inversion** by sequential search from ``k = 0`` [Devroye1986]_ (X.3.3): one uniform ``u``,
  ``p_0 = exp(-mu)``, ``p_k = p_{k-1} mu / k``, the smallest ``k`` with ``F(k) >= u``. Exact up to float64 rounding
  of the cumulative sum (about 1e-16); shot-noise means are mostly below 1 e-, where this costs one ``exp``.
- ``10 <= mu < gaussian_above``: **PTRS**, the transformed rejection with squeeze of [Hormann1993]_, the method
  of numpy's legacy ``random_poisson_ptrs`` (valid for mu >= 10, O(1) uniforms per draw, exact).
- ``mu >= gaussian_above``: the rounded normal ``max(0, rint(mu + sqrt(mu) z))`` with ``z`` by Box-Muller,
  the same approximation as :func:`lfmbench.sensor.shot_noise`'s torch path.

Randomness is **counter-based**: pixel ``i`` reads its own SplitMix64 stream [Steele2014]_ that starts at
``mix(seed) + i * 2^20 * gamma`` (gamma the golden-ratio increment), a disjoint 2^20-draw slice of one SplitMix64
sequence. A pixel's value therefore depends only on ``(seed, i, mu_i)``: not on the array length, the thread
count or the order of evaluation, and the seed is drawn from the caller's ``torch.Generator`` so a sample
stays a function of its own generator (the dataset's determinism contract, docs/datasets.md).

The distribution is tested against the Poisson pmf (chi-square) for means from 1e-6 to 1e6 and on the branch
edges in ``tests/test_poisson.py``; speed against ``torch.poisson`` in ``benchmarks/bench_sensor.py``.

References
----------
.. [Devroye1986] L. Devroye, "Non-Uniform Random Variate Generation", Springer (1986), ch. X.3: inversion by
   sequential search for the Poisson distribution.
.. [Hormann1993] W. Hormann, "The transformed rejection method for generating Poisson random variables",
   Insurance: Mathematics and Economics 12, 39-45 (1993): algorithm PTRS.
.. [Steele2014] G. L. Steele, D. Lea, C. H. Flood, "Fast splittable pseudorandom number generators",
   OOPSLA 2014: SplitMix64 (increment 0x9E3779B97F4A7C15 and the variant-13 finaliser).
"""
from __future__ import annotations

import math

import numpy as np
import torch

__all__ = ["poisson", "available", "INVERSION_BELOW"]

#: Means below this use inversion, at or above it PTRS (which [Hormann1993]_ derives for mu >= 10).
INVERSION_BELOW: float = 10.0

_GAMMA = 0x9E3779B97F4A7C15
#: Distance between two pixels' stream starts: 2^20 SplitMix64 steps (a draw uses at most a few dozen).
_STRIDE = (_GAMMA << 20) & 0xFFFFFFFFFFFFFFFF
_KERNEL = None


def _build():
    """Compile the kernel (lazily: importing lfmbench must not need a compiler); None without numba."""
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency
        return None
    u64 = numba.uint64
    gamma = np.uint64(_GAMMA)
    stride = np.uint64(_STRIDE)
    inv_k = 1.0 / np.maximum(np.arange(64, dtype=np.float64), 1.0)  # 1/k, a multiply instead of a divide
    # log k! for k < 4096 (the PTRS draws below the 1000 e- switch-over), libm lgamma beyond: a table lookup
    # instead of lgamma on the draws that leave the squeeze
    log_factorial = np.array([math.lgamma(k + 1.0) for k in range(4096)])
    n_log_factorial = log_factorial.size

    @numba.njit(inline="always")
    def mix(z):
        z = (z ^ (z >> u64(30))) * u64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> u64(27))) * u64(0x94D049BB133111EB)
        return z ^ (z >> u64(31))

    @numba.njit(inline="always")
    def uniform(state):
        """(u in (0, 1) with 53 random bits, next state)."""
        state = state + gamma
        return (np.float64(mix(state) >> u64(11)) + 0.5) * (1.0 / 9007199254740992.0), state

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def kernel(mean, out, seed, gaussian_above):  # pragma: no cover - compiled by numba
        base = mix(seed)
        for i in range(mean.size):
            mu = np.float64(mean[i])
            if not mu > 0.0:
                if mu == 0.0:
                    out[i] = 0.0
                    continue
                return i  # negative or NaN: the caller raises, naming the element
            if mu == math.inf:
                return i
            st = base + u64(i) * stride
            if mu >= gaussian_above:
                u1, st = uniform(st)
                u2, st = uniform(st)
                z = math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)
                out[i] = max(0.0, np.rint(mu + math.sqrt(mu) * z))
            elif mu < 10.0:
                u, st = uniform(st)
                p = math.exp(-mu)
                f = p
                k = 0
                # F(k) reaches 1 - 1e-16 by k ~ 40 for mu < 10; stop where p underflows or rounding stalls F
                while u > f and p > 0.0:
                    k += 1
                    p *= mu * (inv_k[k] if k < 64 else 1.0 / k)
                    f += p
                out[i] = k
            else:
                # PTRS; the logs of the exact test are only needed off the squeeze (24-65 % of first tries)
                b = 0.931 + 2.53 * math.sqrt(mu)
                a = -0.059 + 0.02483 * b
                vr = 0.9277 - 3.6224 / (b - 2.0)
                while True:
                    u, st = uniform(st)
                    v, st = uniform(st)
                    u -= 0.5
                    us = 0.5 - abs(u)
                    k = math.floor((2.0 * a / us + b) * u + mu + 0.43)
                    if us >= 0.07 and v <= vr:
                        break
                    if k < 0.0 or (us < 0.013 and v > us):
                        continue
                    invalpha = 1.1239 + 1.1328 / (b - 3.4)
                    logfact = log_factorial[k] if k < n_log_factorial else math.lgamma(k + 1.0)
                    if math.log(v * invalpha / (a / (us * us) + b)) <= -mu + k * math.log(mu) - logfact:
                        break
                out[i] = k
        return -1

    return kernel


def available() -> bool:
    """Whether the compiled sampler can be used (numba importable)."""
    global _KERNEL
    if _KERNEL is None:
        _KERNEL = _build() or False
    return _KERNEL is not False


def poisson(mean: torch.Tensor, generator: torch.Generator, gaussian_above: float = math.inf) -> torch.Tensor:
    """Poisson draws with the given means (CPU), rounded-normal from ``gaussian_above`` on.

    Args:
        mean: (*) means >= 0 (e.g. e-), float32 or float64, on the CPU; finite (the caller clips).
        generator: CPU ``torch.Generator``; one 64-bit seed is drawn from it per call, so repeated calls give
            new draws and the result is a function of the generator's state.
        gaussian_above: mean from which the rounded normal N(mu, mu) is used instead (``inf``: exact everywhere).

    Returns:
        (*) integer-valued counts, dtype of ``mean``, a new tensor.

    Raises:
        ValueError: ``mean`` not on the CPU or not floating point, negative, NaN or infinite; ``generator`` not a
            CPU generator.
        RuntimeError: numba is not available.
    """
    if not isinstance(mean, torch.Tensor) or mean.device.type != "cpu" or not mean.is_floating_point():
        raise ValueError("mean must be a floating-point CPU tensor (use torch.poisson on other devices)")
    if not isinstance(generator, torch.Generator) or generator.device.type != "cpu":
        raise ValueError("generator must be a CPU torch.Generator")
    if not available():  # pragma: no cover - numba is a dependency
        raise RuntimeError("numba is not available; use torch.poisson")
    seed = int(torch.randint(-(2 ** 63), 2 ** 63 - 1, (), generator=generator, dtype=torch.int64,
                             device="cpu")) & (2 ** 64 - 1)
    m = mean.detach()
    if m.dtype not in (torch.float32, torch.float64):
        m = m.to(torch.float32)
    m = m.contiguous()
    out = torch.empty_like(m)
    bad = _KERNEL(m.view(-1).numpy(), out.view(-1).numpy(), np.uint64(seed), float(gaussian_above))
    if bad >= 0:
        raise ValueError(f"mean must be finite and >= 0, got {float(m.view(-1)[bad])!r} at flat index {bad}")
    return out.to(mean.dtype)
