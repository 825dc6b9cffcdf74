"""Sensor noise from counter-based streams, as tensor operations: the same numbers for a sample on any device and
in a batch of any size, without a generator object per sample.

The compiled CPU sampler of :mod:`lfmbench.sensor.poisson` already draws pixel ``i`` of a call seeded ``s`` from
its own SplitMix64 stream (key ``mix64(s) + i STRIDE``, :mod:`lfmbench.counter_rng`). :func:`poisson` here is the
same algorithm on the same streams written as element-wise torch operations, so it runs on a GPU for a whole
batch at once (one 64-bit seed per sample), and agrees with the compiled sampler draw for draw wherever the
float64 ``exp``/``log``/``lgamma`` of the two libraries agree (they may differ in the last bit, which can move a
draw across a decision boundary: tests/sensor/test_counter_noise.py bounds how often). :func:`normal` gives the standard
normals of the read noise from the same kind of streams (Box-Muller).

Algorithm (:mod:`lfmbench.sensor.poisson` for its references): mean ``mu < 10``: inversion by sequential search,
written as a fixed number of steps (:data:`INVERSION_STEPS`; the compiled sampler stops where the search ends,
which is before step 64 except with probability < 1e-15 per draw); ``10 <= mu < gaussian_above``: PTRS, written
as :data:`PTRS_ROUNDS` rounds of the rejection loop (a draw that no round accepts, probability < 1e-15, takes the
rounded normal); ``mu >= gaussian_above`` or ``mu >= 2^52``: the rounded normal ``max(0, rint(mu + sqrt(mu) z))``.
Every branch is evaluated for every pixel and selected by masks: no data-dependent control flow, no host
synchronisation, so ``torch.compile`` can fuse it into one kernel.

Functions
- :func:`pixel_keys` -> (B, N) stream keys of N pixels of B samples.
- :func:`poisson` -> (B, N) Poisson counts.
- :func:`normal` -> (B, N) standard normals.
  On CUDA both run as Triton kernels (:mod:`lfmbench.sensor._counter_triton`) where Triton is importable: the same
  draws, but each block of pixels loops only until its own draws are done.
- :func:`shot_seed`, :func:`read_seed` -> the seeds of a sample's shot noise (per photodiode) and read noise (per
  capture), derived from its one noise seed, so that every path draws a capture's noise from the same streams;
  :func:`chain_seeds` -> all of them at once.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from lfmbench.constants import POISSON_EXACT_LIMIT
from lfmbench.counter_rng import GAMMA, STRIDE_LOG2, _signed, derive_key, mix64, uniform_at
from lfmbench.triton_kernels import TritonKernels

__all__ = ["INVERSION_STEPS", "PTRS_ROUNDS", "LOG_FACTORIAL", "log_factorial", "pixel_keys", "poisson", "normal",
           "shot_seed", "read_seed", "chain_seeds", "check_seeds"]

#: Steps of the sequential search (means below 10): the search ends by step 64 except with probability < 1e-15.
INVERSION_STEPS = 64
#: Rounds of PTRS's rejection loop: each accepts with probability > 0.85 at mu >= 10, so 24 rounds all reject
#: with probability < 1e-19.
PTRS_ROUNDS = 24
_STRIDE_S = _signed(GAMMA << STRIDE_LOG2)
#: log k! for k < 4096, from the C library's ``lgamma`` (Python's ``math.lgamma``): PTRS's exact test reads this
#: table (as the compiled sampler does) so that every form agrees on it bit for bit; beyond it (means above about
#: 3,000 e- with ``gaussian_above = inf``) :func:`log_factorial` uses Stirling's series.
LOG_FACTORIAL = np.array([math.lgamma(k + 1.0) for k in range(4096)])


def log_factorial(k: torch.Tensor) -> torch.Tensor:
    """log k! of float64 integer values k >= 0: the table :data:`LOG_FACTORIAL` below 4096, else Stirling's series
    (k + 1/2) ln(k + 1) - (k + 1) + ln(2 pi) / 2 + 1 / (12 (k + 1)) - 1 / (360 (k + 1)^3) + 1 / (1260 (k + 1)^5),
    whose truncation error at k >= 4096 is below 1e-23 (M. Abramowitz, I. A. Stegun, Handbook of Mathematical
    Functions, 1964, 6.1.41)."""
    table = torch.as_tensor(LOG_FACTORIAL, device=k.device)
    idx = torch.clamp(k, 0, LOG_FACTORIAL.size - 1).to(torch.int64)
    x = torch.clamp_min(k, 0.0) + 1.0
    x2 = x * x
    stirling = ((x - 0.5) * torch.log(x) - x + 0.5 * math.log(2.0 * math.pi)
                + (1.0 / 12.0 - (1.0 / 360.0 - 1.0 / (1260.0 * x2)) / x2) / x)
    return torch.where(k < LOG_FACTORIAL.size, table[idx], stirling)
#: On CUDA, draw with the Triton kernels of :mod:`lfmbench.sensor._counter_triton` (each block of pixels stops
#: when its own draws are done) where Triton is importable; False: the torch form everywhere (tests compare them).
USE_TRITON = True
_KERNELS = TritonKernels("lfmbench.sensor._counter_triton", "counter noise", "the torch form")


def kernels_ready(t: torch.Tensor) -> bool:
    """Whether the Triton kernels of this module (and of the fused chain, :func:`lfmbench.sensor.fused.chain_triton`)
    run for tensors like ``t``: CUDA, Triton importable, not turned off."""
    return USE_TRITON and t.is_cuda and _KERNELS.module() is not None


def run_kernel(name: str, *args):
    """Kernel ``name`` of :mod:`lfmbench.sensor._counter_triton` applied to ``args``, or None after turning the
    kernels off (one warning) where it cannot be compiled here: the torch form then gives the same numbers."""
    global USE_TRITON
    out = _KERNELS.call(name, *args)
    if out is None:
        USE_TRITON = False
    return out


#: Purpose words of :func:`lfmbench.counter_rng.derive_key` for the two kinds of sensor noise.
SHOT_PURPOSE, READ_PURPOSE = 0x53484F54, 0x52454144  # "SHOT", "READ"


def check_seeds(seeds, batch: int) -> torch.Tensor:
    """``seeds`` as a (B,) int64 tensor of per-sample noise seeds, checked against the batch size ``batch``."""
    if not isinstance(seeds, torch.Tensor) or seeds.dtype != torch.int64 or seeds.dim() != 1:
        raise ValueError(f"seeds must be a (B,) int64 tensor of per-sample noise seeds, got {seeds!r:.80}")
    if seeds.shape[0] != batch:
        raise ValueError(f"seeds: {seeds.shape[0]} seeds for a batch of {batch} samples (leading dimension)")
    return seeds


def shot_seed(seeds: torch.Tensor, photodiode: int) -> torch.Tensor:
    """(B,) seeds of the shot noise of photodiode ``photodiode`` (its index in ``PHOTODIODES``)."""
    return derive_key(seeds, SHOT_PURPOSE, photodiode)


def read_seed(seeds: torch.Tensor, capture: int) -> torch.Tensor:
    """(B,) seeds of the read noise of capture ``capture`` (its index in ``CAPTURES``)."""
    return derive_key(seeds, READ_PURPOSE, capture)


def chain_seeds(seeds: torch.Tensor, photodiodes: int, captures: int) -> tuple[torch.Tensor, torch.Tensor]:
    """All the noise seeds of a capture set at once: ``(shot, read)``, (P, B) seeds of :func:`shot_seed` for
    photodiodes 0..P-1 and (C, B) of :func:`read_seed` for captures 0..C-1, element for element their values, as
    one broadcast :func:`~lfmbench.counter_rng.derive_key` (a GPU runs one set of element-wise kernels, not one
    per seed)."""
    key = (str(seeds.device), photodiodes, captures)
    if key not in _SEED_WORDS:      # made once per device: a copy to a GPU in every batch would wait for its queue
        _SEED_WORDS[key] = (
            torch.tensor([SHOT_PURPOSE] * photodiodes + [READ_PURPOSE] * captures, device=seeds.device)[:, None],
            torch.tensor([*range(photodiodes), *range(captures)], device=seeds.device)[:, None])
    purpose, which = _SEED_WORDS[key]
    k = derive_key(seeds[None, :], purpose, which).contiguous()                          # (P + C, B)
    return k[:photodiodes], k[photodiodes:]


#: The purpose and index words of :func:`chain_seeds` per (device, photodiodes, captures).
_SEED_WORDS: dict = {}


def pixel_keys(seed: torch.Tensor, n: int) -> torch.Tensor:
    """Stream keys of pixels 0..n-1 of each sample: ``mix64(seed) + i STRIDE`` (the compiled sampler's).

    Args:
        seed: (B,) int64 per-sample seeds (64-bit patterns). n: pixels per sample.

    Returns:
        (B, n) int64 keys on ``seed``'s device.
    """
    i = torch.arange(n, dtype=torch.int64, device=seed.device)
    return mix64(seed).unsqueeze(-1) + i * _STRIDE_S


_u = uniform_at


def _inv_k(k: int) -> float:
    """1 / k as the compiled sampler computes it (a float64 table below 64, a division above)."""
    return 1.0 / float(max(k, 1))


def normal(seed: torch.Tensor, n: int) -> torch.Tensor:
    """Standard normals of ``n`` pixels per sample: ``sqrt(-2 ln u1) cos(2 pi u2)`` from draws 0 and 1 of each
    pixel's stream (Box-Muller, G. E. P. Box, M. E. Muller, Ann. Math. Statist. 29, 610-611, 1958).

    Args:
        seed: (B,) int64 per-sample seeds (use another seed than the shot noise's: :func:`lfmbench.counter_rng.
            derive_key` with a purpose word). n: pixels per sample.

    Returns:
        (B, n) float64 standard normals.
    """
    if kernels_ready(seed):
        out = run_kernel("normal", seed, n)
        if out is not None:
            return out
    keys = pixel_keys(seed, n)
    u1, u2 = _u(keys, 0), _u(keys, 1)
    return torch.sqrt(-2.0 * torch.log(u1)) * torch.cos(2.0 * math.pi * u2)


def poisson(mean: torch.Tensor, seed: torch.Tensor, gaussian_above: float = math.inf) -> torch.Tensor:
    """Poisson draws, pixel i of sample b from the stream of (``seed[b]``, i), rounded normal from
    ``gaussian_above`` on.

    Args:
        mean: (B, N) means >= 0 and finite (e.g. e-; the caller clips), float32 or float64, any device.
        seed: (B,) int64 per-sample seeds, on ``mean``'s device.
        gaussian_above: mean from which the rounded normal N(mu, mu) is used (``inf``: exact up to 2^52).

    Returns:
        (B, N) float64 counts; equal to :func:`lfmbench.sensor.poisson.poisson` of sample b's means with seed
        ``seed[b]`` but where the two libraries' transcendental functions round differently.
    """
    if mean.dim() != 2 or seed.shape != mean.shape[:1]:
        raise ValueError(f"mean must be (B, N) and seed (B,), got {tuple(mean.shape)} and {tuple(seed.shape)}")
    if kernels_ready(mean):
        out = run_kernel("poisson", mean, seed, gaussian_above, INVERSION_STEPS, PTRS_ROUNDS, LOG_FACTORIAL)
        if out is not None:
            return out
    mu = mean.to(torch.float64)
    keys = pixel_keys(seed, mu.shape[1])
    gauss = (mu >= gaussian_above) | (mu >= POISSON_EXACT_LIMIT)
    small = ~gauss & (mu < 10.0)

    # rounded normal (also the fallback of the other branches)
    z = torch.sqrt(-2.0 * torch.log(_u(keys, 0))) * torch.cos(2.0 * math.pi * _u(keys, 1))
    out = torch.clamp_min(torch.round(mu + torch.sqrt(mu) * z), 0.0)

    # inversion (mu < 10): k = the number of leading j with u > F(j) and p_j > 0
    u = _u(keys, 0)
    mus = torch.where(small, mu, torch.zeros_like(mu))
    p = torch.exp(-mus)
    f = p
    k = torch.zeros_like(mu)
    go = (u > f) & (p > 0.0)
    for j in range(1, INVERSION_STEPS + 1):
        k = k + go.to(mu.dtype)
        p = p * (mus * _inv_k(j))
        f = f + p
        go = go & (u > f) & (p > 0.0)
    # the zero shortcut of the compiled sampler gives the same k (it only skips the exp)
    out = torch.where(small, k, out)

    # PTRS (10 <= mu < gaussian_above), W. Hormann (1993)
    big = ~gauss & ~small
    mub = torch.where(big, mu, torch.full_like(mu, 10.0))
    b = 0.931 + 2.53 * torch.sqrt(mub)
    a = -0.059 + 0.02483 * b
    vr = 0.9277 - 3.6224 / (b - 2.0)
    invalpha = 1.1239 + 1.1328 / (b - 3.4)
    log_mu = torch.log(mub)
    done = ~big
    res = torch.zeros_like(mu)
    for r in range(PTRS_ROUNDS):
        uu = _u(keys, 2 * r) - 0.5
        v = _u(keys, 2 * r + 1)
        us = 0.5 - torch.abs(uu)
        kk = torch.floor((2.0 * a / us + b) * uu + mub + 0.43)
        quick = (us >= 0.07) & (v <= vr)
        reject = (kk < 0.0) | ((us < 0.013) & (v > us))
        kc = torch.clamp_min(kk, 0.0)
        exact = torch.log(v * invalpha / (a / (us * us) + b)) <= -mub + kc * log_mu - log_factorial(kc)
        acc = ~done & (quick | (~reject & exact))
        res = torch.where(acc, kk, res)
        done = done | acc
    out = torch.where(big & done, res, out)
    return out
