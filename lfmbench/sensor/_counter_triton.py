"""The counter-based noise of :mod:`lfmbench.sensor.counter_noise` as Triton kernels (CUDA; imported lazily).

The torch form evaluates every branch and every round for every pixel (no data-dependent control flow), which a
GPU pays for in full: 64 search steps and 24 rejection rounds per draw. Here each block of pixels loops only
until its own pixels are done (a sequential search stops at the block's largest count, PTRS after its last
acceptance: one or two rounds for most blocks), with the same arithmetic in the same order on the same streams,
so the counts equal the torch form's (and the compiled CPU sampler's) wherever the float64 library functions
agree (tests/sensor/test_counter_noise.py compares them on a GPU).

Kernels take the 64-bit constants as arguments (Python ints above 2^63 are passed as uint64).
"""
from __future__ import annotations

import math

import torch
import triton
import triton.language as tl

from lfmbench.constants import POISSON_EXACT_LIMIT
from lfmbench.counter_rng import GAMMA, MIX_MUL, STRIDE_LOG2

__all__ = ["poisson", "normal"]

_BLOCK = 256


@triton.jit
def _mix(z, m0, m1):
    z = (z ^ (z >> 30)) * m0
    z = (z ^ (z >> 27)) * m1
    return z ^ (z >> 31)


@triton.jit
def _d(x: tl.constexpr):
    """The float64 constant ``x`` (a bare Python float would be a float32 constant)."""
    return tl.full([], x, tl.float64)


@triton.jit
def _unit(z):
    return ((z >> 11).to(tl.float64) + _d(0.5)) * _d(1.0 / 9007199254740992.0)


@triton.jit
def _box_muller(u1, u2):
    return tl.sqrt(_d(-2.0) * tl.log(u1)) * tl.cos(_d(2.0 * math.pi) * u2)


@triton.jit
def _rint(x):
    """Round half to even (``numpy.rint``, ``torch.round``)."""
    r = tl.floor(x + _d(0.5))
    tie = (r - x) == _d(0.5)
    odd = (r - _d(2.0) * tl.floor(r * _d(0.5))) != _d(0.0)
    return tl.where(tie & odd, r - _d(1.0), r)


@triton.jit
def _log_factorial(k, table_ptr, n_table):
    """:func:`lfmbench.sensor.counter_noise.log_factorial`: the table below ``n_table``, Stirling's series above."""
    idx = tl.minimum(tl.maximum(k, _d(0.0)), (n_table - 1).to(tl.float64)).to(tl.int32)
    t = tl.load(table_ptr + idx)
    x = tl.maximum(k, _d(0.0)) + _d(1.0)
    x2 = x * x
    st = ((x - _d(0.5)) * tl.log(x) - x + _d(0.5 * math.log(2.0 * math.pi))
          + (_d(1.0 / 12.0) - (_d(1.0 / 360.0) - _d(1.0) / (_d(1260.0) * x2)) / x2) / x)
    return tl.where(k < n_table.to(tl.float64), t, st)


@triton.jit
def _poisson_kernel(mean_ptr, seed_ptr, out_ptr, table_ptr, n_table, limits_ptr, N, gamma, stride,
                    m0, m1, max_steps, max_rounds, BLOCK: tl.constexpr):
    b = tl.program_id(1)
    offs = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    inside = offs < N
    mu = tl.load(mean_ptr + b.to(tl.int64) * N + offs, mask=inside, other=0.0).to(tl.float64)
    seed = tl.load(seed_ptr + b).to(tl.uint64)
    key = _mix(seed, m0, m1) + offs.to(tl.uint64) * stride
    gaussian_above = tl.load(limits_ptr)          # float64 (a scalar argument would be float32)
    exact_limit = tl.load(limits_ptr + 1)
    gauss = (mu >= gaussian_above) | (mu >= exact_limit)
    small = (~gauss) & (mu < _d(10.0))
    big = (~gauss) & (~small)
    # rounded normal from draws 0 and 1 (also where a rejection loop gives up)
    u1 = _unit(_mix(key + gamma, m0, m1))
    u2 = _unit(_mix(key + gamma + gamma, m0, m1))
    z = _box_muller(u1, u2)
    res = tl.maximum(_rint(mu + tl.sqrt(mu) * z), _d(0.0))
    # inversion by sequential search (mu < 10), draw 0
    zero = _d(0.0)
    mus = tl.where(small, mu, zero)
    p = tl.exp(-mus)
    f = p
    k = tl.zeros_like(mu)
    go = small & inside & (u1 > f) & (p > zero)
    j = tl.full([], 1, tl.int32)
    while (tl.max(go.to(tl.int32), axis=0) > 0) & (j <= max_steps):
        k = k + go.to(tl.float64)
        p = p * (mus * (_d(1.0) / j))
        f = f + p
        go = go & (u1 > f) & (p > zero)
        j += 1
    res = tl.where(small, k, res)
    # PTRS (10 <= mu < gaussian_above), draws 2r and 2r + 1 of round r
    mub = tl.where(big, mu, _d(10.0))
    bb = _d(0.931) + _d(2.53) * tl.sqrt(mub)
    a = _d(-0.059) + _d(0.02483) * bb
    vr = _d(0.9277) - _d(3.6224) / (bb - _d(2.0))
    invalpha = _d(1.1239) + _d(1.1328) / (bb - _d(3.4))
    log_mu = tl.log(mub)
    todo = big & inside
    kr = tl.zeros_like(mu)
    r = tl.full([], 0, tl.uint64)
    while (tl.max(todo.to(tl.int32), axis=0) > 0) & (r < max_rounds):
        uu = _unit(_mix(key + (2 * r + 1) * gamma, m0, m1)) - _d(0.5)
        v = _unit(_mix(key + (2 * r + 2) * gamma, m0, m1))
        us = _d(0.5) - tl.abs(uu)
        kk = tl.floor((_d(2.0) * a / us + bb) * uu + mub + _d(0.43))
        quick = (us >= _d(0.07)) & (v <= vr)
        reject = (kk < zero) | ((us < _d(0.013)) & (v > us))
        kc = tl.maximum(kk, zero)
        exact = tl.log(v * invalpha / (a / (us * us) + bb)) <= \
            -mub + kc * log_mu - _log_factorial(kc, table_ptr, n_table)
        acc = todo & (quick | ((~reject) & exact))
        kr = tl.where(acc, kk, kr)
        todo = todo & (~acc)
        r += 1
    res = tl.where(big & (~todo), kr, res)
    tl.store(out_ptr + b.to(tl.int64) * N + offs, res, mask=inside)


@triton.jit
def _normal_kernel(seed_ptr, out_ptr, N, gamma, stride, m0, m1, BLOCK: tl.constexpr):
    b = tl.program_id(1)
    offs = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    inside = offs < N
    seed = tl.load(seed_ptr + b).to(tl.uint64)
    key = _mix(seed, m0, m1) + offs.to(tl.uint64) * stride
    u1 = _unit(_mix(key + gamma, m0, m1))
    u2 = _unit(_mix(key + gamma + gamma, m0, m1))
    z = _box_muller(u1, u2)
    tl.store(out_ptr + b.to(tl.int64) * N + offs, z, mask=inside)


def _consts():
    return (GAMMA, (GAMMA << STRIDE_LOG2) & ((1 << 64) - 1), MIX_MUL[0], MIX_MUL[1])


_TABLES: dict = {}


def _tables(device: torch.device, log_factorial, gaussian_above: float) -> tuple[torch.Tensor, torch.Tensor]:
    """The log-factorial table and the limits on ``device``, copied there once (a copy per call would wait for
    the device's queue)."""
    key = (str(device), id(log_factorial), gaussian_above)
    if key not in _TABLES:
        _TABLES[key] = (torch.as_tensor(log_factorial, dtype=torch.float64, device=device),
                        torch.tensor([gaussian_above, float(POISSON_EXACT_LIMIT)], dtype=torch.float64,
                                     device=device))
    return _TABLES[key]


def poisson(mean: torch.Tensor, seed: torch.Tensor, gaussian_above: float, max_steps: int, max_rounds: int,
            log_factorial) -> torch.Tensor:
    """:func:`lfmbench.sensor.counter_noise.poisson` for (B, N) means and (B,) int64 seeds on one device
    (``log_factorial``: its table of log k!, a float64 array)."""
    B, N = mean.shape
    mean = mean.contiguous()
    out = torch.empty(B, N, dtype=torch.float64, device=mean.device)
    if B and N:
        g, s, m0, m1 = _consts()
        table, limits = _tables(mean.device, log_factorial, float(gaussian_above))
        _poisson_kernel[(triton.cdiv(N, _BLOCK), B)](mean, seed.contiguous(), out, table, table.numel(), limits, N,
                                                     g, s, m0, m1, max_steps, max_rounds, BLOCK=_BLOCK)
    return out


def normal(seed: torch.Tensor, n: int) -> torch.Tensor:
    """:func:`lfmbench.sensor.counter_noise.normal` for (B,) int64 seeds on a CUDA device."""
    B = seed.shape[0]
    out = torch.empty(B, n, dtype=torch.float64, device=seed.device)
    if B and n:
        g, s, m0, m1 = _consts()
        _normal_kernel[(triton.cdiv(n, _BLOCK), B)](seed.contiguous(), out, n, g, s, m0, m1, BLOCK=_BLOCK)
    return out
