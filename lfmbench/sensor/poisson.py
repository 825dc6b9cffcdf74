"""Exact Poisson sampling of shot noise on the CPU: a compiled, counter-based sampler (numba).

``torch.poisson`` costs about 13-60 ns a draw on this machine's CPU and was half of a dataset sample's time
(docs/benchmarks/dataset.md). This module draws the same distribution 1.4-1.8x faster at a fixed mean and
1.6-2.3x faster on a dataset sample's mixed means (docs/guide/sensors.md), in one compiled loop:

- mean ``mu < 10``: **inversion** by sequential search from ``k = 0`` [Devroye1986]_ (X.3.3): one uniform ``u``,
  ``p_0 = exp(-mu)``, ``p_k = p_{k-1} mu / k``, the smallest ``k`` with ``F(k) >= u``. Exact up to float64 rounding
  of the cumulative sum (about 1e-16); shot-noise means are mostly below 1 e-, where this costs one ``exp`` or
  none (``k = 0`` when ``u`` is below the lower bound ``1 - mu + mu^2/2 - mu^3/6`` of ``exp(-mu)``); the terms are
  evaluated four at a time (the same products and sums, so the same ``k`` as one at a time: tests/sensor/test_poisson.py).
- ``10 <= mu < gaussian_above``: **PTRS**, the transformed rejection with squeeze of [Hormann1993]_, the method
  of numpy's legacy ``random_poisson_ptrs`` (valid for mu >= 10, O(1) uniforms per draw, exact).
- ``mu >= gaussian_above``: the rounded normal ``max(0, rint(mu + sqrt(mu) z))`` with ``z`` by Box-Muller,
  the same approximation as :func:`lfmbench.sensor.shot_noise`'s torch path; also for every mean >= 2^52
  (4.5e15), where float64 cannot hold the counts exactly (relative s.d. < 2e-8 there).

Randomness is **counter-based**: pixel ``i`` reads its own SplitMix64 stream [Steele2014]_ that starts at
``mix(seed) + i * 2^20 * gamma`` (gamma the golden-ratio increment), a disjoint 2^20-draw slice of one SplitMix64
sequence. A pixel's value therefore depends only on ``(seed, i, mu_i)``: not on the array length, the thread
count or the order of evaluation, and the seed is drawn from the caller's ``torch.Generator`` so a sample
stays a function of its own generator (the dataset's determinism contract, docs/guide/datasets.md).

``tests/sensor/test_poisson.py`` tests the distribution against the Poisson pmf (chi-square, 200 000 draws) at means
from 0.01 to 1e5 including both sides of the branch edge at 10, the moments of mixed means (3e-4 to 1e5 e- in one
call), independence of neighbouring pixels and seeds, and means from 5e-324 to 1e300; it also runs the EMVA 1288
photon-transfer test of the sensor on both samplers. Speed against ``torch.poisson``: ``benchmarks/bench_sensor.py``.

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

from lfmbench.constants import POISSON_EXACT_LIMIT

__all__ = ["poisson", "draw_seed", "available", "INVERSION_BELOW", "EXACT_LIMIT"]

#: Means below this use inversion, at or above it PTRS (which [Hormann1993]_ derives for mu >= 10).
INVERSION_BELOW: float = 10.0
#: Means from 2^52 on always take the rounded normal (defined in :mod:`lfmbench.constants`, shared with the
#: compiled kernel :mod:`lfmbench.sensor._poisson_kernel`).
EXACT_LIMIT: float = POISSON_EXACT_LIMIT

_KERNEL = None


def _build():
    """Load the compiled kernel (lazily: importing lfmbench must not need numba); None without numba."""
    try:
        from lfmbench.sensor._poisson_kernel import kernel
    except ImportError:  # pragma: no cover - numba is a dependency
        return None
    return kernel


def _kernel():
    """The compiled kernel, loaded on first use; None without numba."""
    global _KERNEL
    if _KERNEL is None:
        _KERNEL = _build() or False
    return _KERNEL or None


def available() -> bool:
    """Whether the compiled sampler can be used (numba importable)."""
    return _kernel() is not None


def draw_seed(generator: torch.Generator) -> np.uint64:
    """The 64-bit seed of one call, drawn from the caller's CPU ``generator`` (advances it by one draw)."""
    return np.uint64(int(torch.randint(-(2 ** 63), 2 ** 63 - 1, (), generator=generator, dtype=torch.int64,
                                       device="cpu")) & (2 ** 64 - 1))


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
    kernel = _kernel()
    if kernel is None:  # pragma: no cover - numba is a dependency
        raise RuntimeError("numba is not available; use torch.poisson")
    seed = draw_seed(generator)
    m = mean.detach()
    if m.dtype not in (torch.float32, torch.float64):
        m = m.to(torch.float32)
    m = m.contiguous()
    out = torch.empty_like(m)
    bad = kernel(m.view(-1).numpy(), out.view(-1).numpy(), seed, float(gaussian_above))
    if bad >= 0:
        raise ValueError(f"mean must be finite and >= 0, got {float(m.view(-1)[bad])!r} at flat index {bad}")
    return out.to(mean.dtype)
