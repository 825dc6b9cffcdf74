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

from lfmbench._triton_math import _d, rint
from lfmbench.constants import POISSON_EXACT_LIMIT
from lfmbench.counter_rng import GAMMA, MIX_MUL, STRIDE_LOG2

__all__ = ["poisson", "normal", "collect", "readout"]

_BLOCK = 256


@triton.jit
def _mix(z, m0, m1):
    z = (z ^ (z >> 30)) * m0
    z = (z ^ (z >> 27)) * m1
    return z ^ (z >> 31)


@triton.jit
def _unit(z):
    return ((z >> 11).to(tl.float64) + _d(0.5)) * _d(1.0 / 9007199254740992.0)


@triton.jit
def _box_muller(u1, u2):
    return tl.sqrt(_d(-2.0) * tl.log(u1)) * tl.cos(_d(2.0 * math.pi) * u2)


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
def _poisson_draw(mu, key, inside, table_ptr, n_table, limits_ptr, gamma, m0, m1, max_steps, max_rounds):
    """Poisson counts (float64) of float64 means ``mu`` from the streams ``key`` (one per pixel of the block;
    ``inside``: the block's pixels that exist): the algorithm of :func:`lfmbench.sensor.counter_noise.poisson`."""
    gaussian_above = tl.load(limits_ptr)          # float64 (a scalar argument would be float32)
    exact_limit = tl.load(limits_ptr + 1)
    gauss = (mu >= gaussian_above) | (mu >= exact_limit)
    small = (~gauss) & (mu < _d(10.0))
    big = (~gauss) & (~small)
    # rounded normal from draws 0 and 1 (also where a rejection loop gives up)
    u1 = _unit(_mix(key + gamma, m0, m1))
    u2 = _unit(_mix(key + gamma + gamma, m0, m1))
    z = _box_muller(u1, u2)
    res = tl.maximum(rint(mu + tl.sqrt(mu) * z), _d(0.0))
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
    return tl.where(big & (~todo), kr, res)


@triton.jit
def _poisson_kernel(mean_ptr, seed_ptr, out_ptr, table_ptr, n_table, limits_ptr, N, gamma, stride,
                    m0, m1, max_steps, max_rounds, BLOCK: tl.constexpr):
    b = tl.program_id(1)
    offs = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    inside = offs < N
    mu = tl.load(mean_ptr + b.to(tl.int64) * N + offs, mask=inside, other=0.0).to(tl.float64)
    seed = tl.load(seed_ptr + b).to(tl.uint64)
    key = _mix(seed, m0, m1) + offs.to(tl.uint64) * stride
    res = _poisson_draw(mu, key, inside, table_ptr, n_table, limits_ptr, gamma, m0, m1, max_steps, max_rounds)
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


@triton.jit
def _rint32(x):
    """Round half to even of float32 values, exactly (``torch.round``): floor, then the exact fraction decides."""
    r = tl.floor(x)
    d = x - r                                      # exact: the fraction bits of x
    odd = (r - 2.0 * tl.floor(r * 0.5)) != 0.0
    return tl.where((d > 0.5) | ((d == 0.5) & odd), r + 1.0, r)


@triton.jit
def _map_at(ptr, row_off_ptr, row, j, stride, w, inside):
    """Pixel j (of rows w px wide) of row ``row`` of a fixed-pattern map: ``ptr[row_off[row] + (j // w) stride +
    j % w]``: a whole-frame map read at a crop's origin, or one plane per row, without cutting crops first."""
    base = tl.load(row_off_ptr + row)
    return tl.load(ptr + base + (j // w).to(tl.int64) * stride + (j % w), mask=inside, other=0.0)


@triton.jit
def _collect_kernel(mu_ptr, out_ptr, seed_ptr, gain_ptr, goff_ptr, gstride, dark_ptr, cap, full_well, per, P, w,
                    table_ptr, n_table, limits_ptr, gamma, stride, m0, m1, max_steps, max_rounds,
                    USE_GAIN: tl.constexpr, BLOCK: tl.constexpr):
    row = tl.program_id(1)
    j = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    inside = j < P
    at = row.to(tl.int64) * P + j
    x = tl.load(mu_ptr + at, mask=inside, other=0.0)
    x = tl.where(x != x, 0.0, x)                   # nan_to_num(nan=0, posinf=cap), clamp(0, cap)
    x = tl.minimum(tl.maximum(x, 0.0), cap)
    if USE_GAIN:
        x = x * _map_at(gain_ptr, goff_ptr, row, j, gstride, w, inside)
    x = x + tl.load(dark_ptr + row)
    b = row // per
    seed = tl.load(seed_ptr + b).to(tl.uint64)
    i = (row - b * per).to(tl.uint64) * P + j.to(tl.uint64)          # pixel index within the sample
    key = _mix(seed, m0, m1) + i * stride
    n = _poisson_draw(x.to(tl.float64), key, inside, table_ptr, n_table, limits_ptr, gamma, m0, m1, max_steps,
                      max_rounds).to(tl.float32)
    n = tl.minimum(tl.maximum(n, 0.0), full_well)
    tl.store(out_ptr + at, n, mask=inside)


@triton.jit
def _readout_kernel(n_ptr, dn_ptr, e_ptr, sat_ptr, seed_ptr, rn, off_ptr, ooff_ptr, ostride, cg, swing, dpv, bl,
                    max_dn, sat_v, gain_k, sub_ptr, mul_ptr, c, n_caps, per, P, w, gamma, stride, m0, m1,
                    USE_Z: tl.constexpr, USE_OFF: tl.constexpr, USE_MUL: tl.constexpr, BLOCK: tl.constexpr):
    row = tl.program_id(1)
    j = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    inside = j < P
    at = row.to(tl.int64) * P + j
    v = tl.load(n_ptr + at, mask=inside, other=0.0)
    if USE_Z:
        b = row // per
        seed = tl.load(seed_ptr + b).to(tl.uint64)
        i = (row - b * per).to(tl.uint64) * P + j.to(tl.uint64)
        key = _mix(seed, m0, m1) + i * stride
        z = _box_muller(_unit(_mix(key + gamma, m0, m1)), _unit(_mix(key + gamma + gamma, m0, m1)))
        v = z.to(tl.float32) * rn + v
    if USE_OFF:
        v = v + _map_at(off_ptr, ooff_ptr, row, j, ostride, w, inside)
    v = tl.minimum(v * cg, swing)
    d = tl.minimum(tl.maximum(_rint32(v * dpv + bl), 0.0), max_dn)
    tl.store(dn_ptr + at, d, mask=inside)
    tl.store(sat_ptr + (row.to(tl.int64) * n_caps + c) * P + j, v >= sat_v, mask=inside)
    e = tl.div_rn(d - bl, gain_k) - tl.load(sub_ptr + row)
    if USE_MUL:
        e = e * tl.load(mul_ptr + row)
    tl.store(e_ptr + at, e, mask=inside)


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


#: Launch shape of the chain kernels (pixels per program, warps per program). The counts do not depend on it (each
#: pixel's draw is its own stream's; a block only decides how long its loops run), only the speed does:
#: benchmarks/bench_sensor_device.py --sweep-launch measures the candidates. One warp of 32 px for the collection
#: (its search and rejection loops run until the slowest pixel of a block is done, and a warp needs no barrier to
#: know that): 24,398 samples/s on an H100 against 16,352 with 256 px / 4 warps (docs/benchmarks/sensor-device.md).
COLLECT_LAUNCH = {"BLOCK": 32, "num_warps": 1}
READOUT_LAUNCH = {"BLOCK": 256, "num_warps": 4}

#: Compile option of the chain kernels: no fused multiply-adds, so that every float32 step rounds as the torch
#: chain's separate element-wise passes do.
_EXACT = {"enable_fp_fusion": False}


def collect(mu: torch.Tensor, seed: torch.Tensor, per: int, gain, dark: torch.Tensor, cap: float, full_well: float,
            width: int, gaussian_above: float, max_steps: int, max_rounds: int, log_factorial) -> torch.Tensor:
    """One photodiode's collected charge in one pass: clip to [0, cap], x PRNU gain, + dark signal, Poisson from
    the counter streams of the sample's shot seed, clip to the full well.

    Args: ``mu`` (L, P) float32 mean e-, rows of P px (crops ``width`` px wide), ``per`` rows per sample;
    ``seed`` (B,) int64 shot seeds; ``gain`` None or ``(map, row_offsets (L,) int64, row_stride)``; ``dark``
    (L,) float32 mean dark signal per row, e-; ``cap``, ``full_well`` e-. Returns (L, P) float32 e-.
    """
    L, P = mu.shape
    out = torch.empty_like(mu)
    if L and P:
        g, s, m0, m1 = _consts()
        table, limits = _tables(mu.device, log_factorial, float(gaussian_above))
        gmap, goff, gstride = gain if gain is not None else (mu, dark, 0)
        lc = COLLECT_LAUNCH
        _collect_kernel[(triton.cdiv(P, lc["BLOCK"]), L)](
            mu, out, seed, gmap, goff, gstride, dark, cap, full_well, per, P, width, table, table.numel(), limits,
            g, s, m0, m1, max_steps, max_rounds, USE_GAIN=gain is not None, **lc, **_EXACT)
    return out


def readout(n: torch.Tensor, seed, per: int, read_noise_e: float, offset, conversion_gain: float, swing: float,
            dn_per_volt: float, black: float, max_dn: float, sat_v: float, gain_k: float, sub: torch.Tensor, mul,
            width: int, dn: torch.Tensor, e: torch.Tensor, sat: torch.Tensor, c: int) -> bool:
    """One capture's read-out in one pass: read noise (counter normals of the sample's read seed, or none when
    ``seed`` is None), DSNU offset, conversion gain, swing, ADC, saturation flag, input referral.

    Args: ``n`` (L, P) float32 collected e-; ``offset`` None or ``(map, row_offsets, row_stride)`` e-; ``sub``
    (L,) float32 mean dark signal e-; ``mul`` None or (L,) float32 LPD-equivalence factor; outputs ``dn``, ``e``
    (L, P) float32 and ``sat`` (L, C, P) bool, written in channel ``c``; scalars in V, DN, e- as the preset's.
    Returns True (a caller's sign that the kernel ran).
    """
    L, P = n.shape
    if not (L and P):
        return True
    g, s, m0, m1 = _consts()
    omap, ooff, ostride = offset if offset is not None else (n, sub, 0)
    lc = READOUT_LAUNCH
    _readout_kernel[(triton.cdiv(P, lc["BLOCK"]), L)](
        n, dn, e, sat, seed if seed is not None else sub, read_noise_e, omap, ooff, ostride, conversion_gain, swing,
        dn_per_volt, black, max_dn, sat_v, gain_k, sub, mul if mul is not None else sub, c, sat.shape[1], per, P,
        width, g, s, m0, m1, USE_Z=seed is not None, USE_OFF=offset is not None, USE_MUL=mul is not None,
        **lc, **_EXACT)
    return True
