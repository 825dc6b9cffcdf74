"""The sensor chain in compiled passes (CPU: numba; CUDA: Triton), and the Python threads that run per-sample work.

:func:`chain_fused` is :func:`lfmbench.sensor.noise.simulate_split_pixel_electrons` (backend ``"numba"``) as one
compiled pass per photodiode (:func:`lfmbench.sensor._poisson_kernel.collect`) and one per capture
(:func:`lfmbench.sensor._readout_kernel.readout`); :func:`chain_plan_fused` is the same two kinds of pass for any
capture plan (:func:`lfmbench.sensor.noise.simulate_plan_electrons`: one pass per exposure, one per capture);
:func:`chain_triton` is the same two kinds of pass as Triton
kernels for a batch on a GPU with counter-based noise (:func:`lfmbench.sensor._counter_triton.collect` and
``readout``: no float64 noise tensors, no fixed-pattern crops cut, ~5 passes over the batch instead of ~40);
:func:`map_samples` runs ``fn(b)`` for every sample by a pool of threads (the kernels and torch's samplers release
the GIL); :func:`warm_fused` compiles the kernels ahead of a fork.
"""
from __future__ import annotations

import os
import threading
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from lfmbench.sensor import poisson as _poisson
from lfmbench.sensor import counter_noise as _cn
from lfmbench.sensor.preset import CAPTURES, PHOTODIODES, SensorPreset, load_preset

__all__ = ["MEAN_CAP_FULL_WELLS", "PatternCrops", "map_samples", "per_generator", "chain_fused", "chain_plan_fused",
           "chain_triton", "warm_fused"]

#: Mean electrons are capped at this multiple of the full well before noise: everything above the full well
#: clips anyway, and the cap keeps sun-in-view inputs finite in float32 (both backends of the chain).
MEAN_CAP_FULL_WELLS: float = 100.0


_DRAW_POOL: dict[tuple, Any] = {}


def map_samples(fn, count: int, threads: int | None = None) -> None:
    """``fn(b)`` for b in range(count), by ``min(threads, count)`` Python threads (default
    ``torch.get_num_threads()``; the compiled kernels and torch's samplers release the GIL); in order in this
    thread when that is 1."""
    n = min(torch.get_num_threads() if threads is None else int(threads), count)
    if n < 2:
        for b in range(count):
            fn(b)
        return
    key = (os.getpid(), n)   # a forked child (DataLoader worker) builds its own pool: threads do not survive fork
    if key not in _DRAW_POOL:
        from concurrent.futures import ThreadPoolExecutor
        _DRAW_POOL[key] = ThreadPoolExecutor(n, thread_name_prefix="lfmbench-draw")
    list(_DRAW_POOL[key].map(fn, range(count)))


def per_generator(draw, x: torch.Tensor, generator, threads: int | None = None) -> torch.Tensor:
    """``draw(x, generator)``, or with a sequence of generators ``draw(x[b], generator[b])`` stacked over b.

    On the CPU the samples are drawn by ``threads`` Python threads (:func:`map_samples`); each
    sample still reads only its own generator, so the result does not depend on the thread count.
    """
    if not isinstance(generator, (list, tuple)):
        return draw(x, generator)
    out = torch.empty_like(x)

    def one(b: int) -> None:
        out[b] = draw(x[b], generator[b])

    if x.device.type != "cpu":
        for b in range(len(generator)):
            one(b)
    else:
        map_samples(one, len(generator), threads)
    return out


_SCRATCH = threading.local()
#: Work arrays up to this many bytes are kept per thread between calls (fresh pages cost a fault each).
_SCRATCH_MAX_BYTES = 16 * 2 ** 20


def _scratch(name: str, rows: int, cols: int, dtype) -> np.ndarray:
    """A (rows, cols) work array of this thread, reused from call to call when small enough (contents undefined)."""
    n = rows * cols
    dt = np.dtype(dtype)
    if n * dt.itemsize > _SCRATCH_MAX_BYTES:
        return np.empty((rows, cols), dt)
    bufs = _SCRATCH.__dict__.setdefault("bufs", {})
    b = bufs.get((name, dt))
    if b is None or b.size < n:
        b = bufs[(name, dt)] = np.empty(n, dt)
    return b[:n].reshape(rows, cols)


def _plane_rows(m: torch.Tensor, lead: torch.Size, H: int, W: int) -> tuple[torch.Tensor, torch.Tensor]:
    """A map (..., H, W) broadcastable to inputs ``lead + (1, H, W)`` as ``(base, row)``: ``base`` (M, H*W) its
    distinct planes (C-contiguous), ``row`` (L,) int64 the plane each of the L = prod(lead) input planes reads (no
    copy of the map per input plane)."""
    base = m.reshape(-1, H * W).contiguous()
    idx = torch.arange(base.shape[0], device=m.device).reshape(m.shape[:-2])
    return base, torch.broadcast_to(idx, (*lead, 1)).reshape(-1).contiguous()


def _map_rows(m: torch.Tensor, lead: torch.Size, H: int, W: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_plane_rows` as numpy arrays (the numba kernels' arguments)."""
    base, row = _plane_rows(m, lead, H, W)
    return base.numpy(), row.numpy()


def _row_scalars(preset: SensorPreset, t_s: torch.Tensor, t_l: torch.Tensor, lead: torch.Size,
                 L: int) -> tuple[dict, torch.Tensor]:
    """Per input row (L = prod(lead) planes) the mean dark signal of each photodiode, ``{pd: (L,)}`` e-, and the
    SPD's LPD-equivalence factor (L,), by the torch chain's own expressions (so every compiled chain reads the
    same float values)."""
    def per_row(v: torch.Tensor) -> torch.Tensor:
        return torch.broadcast_to(v, (*lead, 1, 1, 1)).reshape(L).contiguous()

    t_pd = {"lpd": t_s, "spd": t_l}
    return ({pd: per_row(preset.photodiodes[pd].dark_current_e_per_s * t_pd[pd]) for pd in PHOTODIODES},
            per_row(preset.sensitivity_ratio * t_s / t_l))


def chain_fused(lpd_e: torch.Tensor, spd_e: torch.Tensor, preset: SensorPreset, t_s: torch.Tensor,
                 t_l: torch.Tensor, generator, noise: bool, fpn: Mapping[str, torch.Tensor] | None,
                 threads: int | None = None, seeds: torch.Tensor | None = None) -> dict:
    """The CPU chain of :func:`simulate_split_pixel_electrons` in compiled passes (backend ``"numba"``).

    Args: ``lpd_e``, ``spd_e`` (*, 1, H, W) mean e- (float32/float64, CPU); ``t_s``, ``t_l`` (*, 1, 1, 1)
    exposures in s (dtype of the inputs); ``generator`` one CPU generator or B of them (one per index of the
    leading dimension); ``fpn`` maps (..., H, W) already on the inputs' dtype, or None. Every generator is drawn
    in the torch chain's order (LPD Poisson seed, SPD Poisson seed, HCG, LCG, SPD read noise), and every
    per-row scalar is computed by the torch chain's own expressions, so the outputs are bit-identical to it.
    With ``seeds`` ((B,) int64, instead of generators) sample b's shot noise comes from the compiled sampler
    seeded with its counter shot seed and its read noise from its counter read streams
    (:mod:`lfmbench.sensor.counter_noise`): the numbers of the torch chain with ``seeds``, on any device.
    """
    from lfmbench.sensor._poisson_kernel import collect, normals
    from lfmbench.sensor._readout_kernel import readout

    lead, (H, W) = lpd_e.shape[:-3], lpd_e.shape[-2:]
    P = H * W
    L = int(np.prod(lead, dtype=np.int64)) if len(lead) else 1
    dtype = lpd_e.dtype
    nt = np.float32 if dtype == torch.float32 else np.float64
    rows = {pd: (lpd_e if pd == "lpd" else spd_e).detach().reshape(L, P).contiguous().numpy() for pd in PHOTODIODES}
    dark, spd_factor = _row_scalars(preset, t_s, t_l, lead, L)
    dark, spd_factor = {pd: v.numpy() for pd, v in dark.items()}, spd_factor.numpy()
    empty = np.zeros((0, P), dtype=nt)
    no_factor = np.zeros(0, dtype=nt)
    none_row = np.zeros(L, dtype=np.int64)
    maps = {}
    for pd in PHOTODIODES:
        spec = preset.photodiodes[pd]
        use = noise and fpn is not None
        maps[f"{pd}_gain"] = _map_rows(fpn[f"{pd}_gain"], lead, H, W) if use and spec.prnu > 0 else (empty, none_row)
        maps[f"{pd}_offset_e"] = (_map_rows(fpn[f"{pd}_offset_e"], lead, H, W) if use and spec.dsnu_e > 0
                                  else (empty, none_row))
    dev = lpd_e.device
    out = {k: torch.empty(*lead, 1, H, W, dtype=dtype, device=dev) for k in (*CAPTURES, *(f"{c}_e" for c in CAPTURES))}
    sat = torch.empty(*lead, 3, H, W, dtype=torch.bool, device=dev)
    flat = {k: v.view(L, P).numpy() for k, v in out.items()}
    sat_np = sat.view(L, 3, P).numpy()
    gsw = float(preset.shot_noise_gaussian_above_e)

    def run(r0: int, r1: int, g, shape: torch.Size, b: int = -1) -> None:
        """Rows r0..r1 (one generator's inputs, or sample ``b``'s with ``seeds``, of shape ``shape``)."""
        collected = {pd: _scratch(pd, r1 - r0, P, nt) for pd in PHOTODIODES}            # e-
        for i_pd, pd in enumerate(PHOTODIODES):
            spec = preset.photodiodes[pd]
            gain, grow = maps[f"{pd}_gain"]
            if not noise:
                seed = np.uint64(0)
            elif seeds is not None:
                seed = np.uint64(int(_cn.shot_seed(seeds[b:b + 1], i_pd)) & 0xFFFFFFFFFFFFFFFF)
            else:
                seed = _poisson.draw_seed(g)
            bad = collect(rows[pd][r0:r1], gain, grow[r0:r1], dark[pd][r0:r1],
                          nt(MEAN_CAP_FULL_WELLS * spec.full_well_e), nt(spec.full_well_e), seed, gsw, noise,
                          collected[pd])
            if bad >= 0:  # pragma: no cover - the clipped means are finite and >= 0
                raise ValueError(f"shot noise: invalid mean at flat index {bad} of {pd}")
        z_all = _scratch("z", r1 - r0, P, nt)
        for c, cap in enumerate(CAPTURES):
            spec = preset.captures[cap]
            pd = spec.photodiode
            z = empty
            if noise and spec.read_noise_e > 0 and seeds is not None:
                normals(np.uint64(int(_cn.read_seed(seeds[b:b + 1], c)) & 0xFFFFFFFFFFFFFFFF), z_all.reshape(-1))
                z = z_all
            elif noise and spec.read_noise_e > 0:
                # into a reused buffer: the same draws as a new tensor
                torch.randn(shape, generator=g, dtype=dtype, device=dev, out=torch.from_numpy(z_all).view(shape))
                z = z_all
            off, orow = maps[f"{pd}_offset_e"]
            readout(collected[pd], z, nt(spec.read_noise_e), off, orow[r0:r1],
                    nt(spec.conversion_gain_v_per_e), nt(spec.voltage_swing_v), nt(preset.dn_per_volt(cap)),
                    nt(preset.black_level_dn), nt(preset.max_dn), nt(preset.saturation_fraction * spec.voltage_swing_v),
                    nt(preset.system_gain(cap)), dark[pd][r0:r1], spd_factor[r0:r1] if pd == "spd" else no_factor,
                    flat[cap][r0:r1], flat[f"{cap}_e"][r0:r1], sat_np[r0:r1], c)

    if seeds is not None:
        per = L // len(seeds)
        map_samples(lambda b: run(b * per, (b + 1) * per, None, lpd_e.shape[1:], b), len(seeds), threads)
    elif isinstance(generator, (list, tuple)):
        per = L // len(generator)
        map_samples(lambda b: run(b * per, (b + 1) * per, generator[b], lpd_e.shape[1:]), len(generator), threads)
    else:
        run(0, L, generator, lpd_e.shape)
    out["saturated"] = sat
    return out


def chain_plan_fused(mean_e: Mapping[str, torch.Tensor], preset: SensorPreset, exposure_s: Mapping[str, float],
                     generator: torch.Generator | None, noise: bool,
                     fpn: Mapping[str, torch.Tensor] | None) -> tuple[dict, dict]:
    """The CPU chain of :func:`lfmbench.sensor.noise.simulate_plan_electrons` (any capture plan) in compiled passes:
    one :func:`lfmbench.sensor._poisson_kernel.collect` per exposure (clipping, PRNU, dark signal, shot noise, full
    well) and one :func:`lfmbench.sensor._readout_kernel.readout` per capture (DSNU offset, read noise, conversion
    gain, swing, ADC, saturation flag, input referral).

    The generator is drawn in the torch chain's order (one shot-noise seed per exposure in plan order, then the read
    noise of each exposure's captures), and every scalar is the torch chain's Python float cast to the inputs'
    dtype, as the torch operations cast it, so the outputs are bit-identical to the torch chain
    (tests/sensor/test_plan_fused.py).

    Args: ``mean_e`` ``{exposure key: (*, 1, H, W)}`` mean e- (float32/float64, CPU, one shape), in the order of
    ``preset.exposures``; ``exposure_s`` ``{exposure key: s}``; ``generator`` a CPU generator (when ``noise``);
    ``fpn`` maps (..., H, W) of :func:`lfmbench.sensor.fixed_pattern` broadcastable to the inputs, on their dtype,
    or None.

    Returns: ``(out, linear)``: ``out`` as the torch chain's result, except that a companded capture's entries
    hold its *linear* code (DN) and nothing meaningful in ``f"{capture}_e"``; ``linear`` ``{capture: True}`` for
    those captures (the caller companding them with the torch chain's own operations).
    """
    from lfmbench.sensor._poisson_kernel import collect
    from lfmbench.sensor._readout_kernel import readout

    groups = preset.exposures
    first = mean_e[next(iter(groups))]
    lead, (H, W) = first.shape[:-3], first.shape[-2:]
    P = H * W
    L = int(np.prod(lead, dtype=np.int64)) if len(lead) else 1
    dtype, dev = first.dtype, first.device
    nt = np.float32 if dtype == torch.float32 else np.float64
    order = list(preset.captures)
    empty = np.zeros((0, P), dtype=nt)
    none_row = np.zeros(L, dtype=np.int64)
    use_fpn = noise and fpn is not None
    ref_key = next(k for k, caps in groups.items() if preset.reference in caps)
    ff_ref = preset.photodiodes[preset.captures[preset.reference].photodiode].fill_factor
    t_ref = float(exposure_s[ref_key])
    out = {k: torch.empty(*lead, 1, H, W, dtype=dtype, device=dev) for k in (*order, *(f"{c}_e" for c in order))}
    sat = torch.empty(*lead, len(order), H, W, dtype=torch.bool, device=dev)
    sat_np = sat.view(L, len(order), P).numpy()
    gsw = float(preset.shot_noise_gaussian_above_e)
    collected = {}
    for i, key in enumerate(groups):                                     # shot seeds first, in plan order
        pd = preset.captures[key].photodiode
        spec = preset.photodiodes[pd]
        gain, grow = (_map_rows(fpn[f"{pd}_gain"], lead, H, W) if use_fpn and spec.prnu > 0 else (empty, none_row))
        dark = np.full(L, spec.dark_current_e_per_s * float(exposure_s[key]), dtype=nt)     # e-
        seed = _poisson.draw_seed(generator) if noise else np.uint64(0)
        collected[key] = _scratch(f"plan{i}", L, P, nt)
        bad = collect(mean_e[key].detach().reshape(L, P).contiguous().numpy(), gain, grow, dark,
                      nt(MEAN_CAP_FULL_WELLS * spec.full_well_e), nt(spec.full_well_e), seed, gsw, noise,
                      collected[key])
        if bad >= 0:  # pragma: no cover - the clipped means are finite and >= 0
            raise ValueError(f"shot noise: invalid mean at flat index {bad} of exposure {key!r}")
    z = _scratch("z", L, P, nt)
    linear = {}
    for key, caps in groups.items():
        pd = preset.captures[key].photodiode
        spec = preset.photodiodes[pd]
        off, orow = (_map_rows(fpn[f"{pd}_offset_e"], lead, H, W) if use_fpn and spec.dsnu_e > 0
                     else (empty, none_row))
        t = float(exposure_s[key])
        dark = np.full(L, spec.dark_current_e_per_s * t, dtype=nt)                          # e-
        mul = np.full(L, (ff_ref / spec.fill_factor) * (t_ref / t), dtype=nt)                # 1
        for c in caps:
            cs = preset.captures[c]
            zc = empty
            if noise and cs.read_noise_e > 0:    # into a reused buffer: the same draws as a new tensor
                torch.randn(first.shape, generator=generator, dtype=dtype, device=dev,
                            out=torch.from_numpy(z).view(first.shape))
                zc = z
            if cs.companding is not None:
                linear[c] = True
            readout(collected[key], zc, nt(cs.read_noise_e), off, orow, nt(cs.conversion_gain_v_per_e),
                    nt(cs.voltage_swing_v), nt(preset.dn_per_volt(c)), nt(preset.black_level_dn),
                    nt(preset.linear_max_dn(c)), nt(preset.saturation_fraction * cs.voltage_swing_v),
                    nt(preset.system_gain(c)), dark, mul, out[c].view(L, P).numpy(),
                    out[f"{c}_e"].view(L, P).numpy(), sat_np, order.index(c))
    out["saturated"] = sat
    return out, linear


class PatternCrops(Mapping):
    """Per-sample crops of whole-frame fixed-pattern maps, cut only when a map is read.

    A mapping ``{key: (B, 1, 1, h, w)}`` like the crops it stands for (the torch and numba chains read it so);
    :func:`chain_triton` reads the whole-frame maps at each sample's origin instead, without cutting crops.

    Args:
        maps: ``{key: (H, W)}`` whole-frame maps (:func:`lfmbench.sensor.fixed_pattern`).
        origin: (B, 2) int64 crop origins (row, column) in px, on the maps' device.
        hw: (h, w) crop size in px.
    """

    def __init__(self, maps: Mapping[str, torch.Tensor], origin: torch.Tensor, hw: tuple[int, int]) -> None:
        self.maps = dict(maps)
        self.origin = origin
        self.hw = (int(hw[0]), int(hw[1]))
        self._cut: dict[str, torch.Tensor] = {}

    def __getitem__(self, key: str) -> torch.Tensor:
        if key not in self._cut:
            m = self.maps[key]
            h, w = self.hw
            rows = (self.origin[:, 0:1] + torch.arange(h, device=m.device))[:, :, None]     # (B, h, 1)
            cols = (self.origin[:, 1:2] + torch.arange(w, device=m.device))[:, None, :]     # (B, 1, w)
            self._cut[key] = m[rows, cols][:, None, None]
        return self._cut[key]

    def __iter__(self):
        return iter(self.maps)

    def __len__(self) -> int:
        return len(self.maps)

    def to(self, device, dtype) -> "PatternCrops":
        """The same crops with the maps on ``device`` in ``dtype``."""
        return PatternCrops({k: v.to(device=device, dtype=dtype) for k, v in self.maps.items()},
                            self.origin.to(device), self.hw)


def _map_reader(m, key: str, lead: torch.Size, H: int, W: int, L: int):
    """``(map, row_offsets (L,) int64, row_stride)``: where the Triton kernels read map ``key`` for each of the L
    input rows (planes of H x W px): a whole-frame map at the sample's crop origin (:class:`PatternCrops`), or
    the plane of a map broadcastable to the inputs."""
    if isinstance(m, PatternCrops):
        full = m.maps[key].contiguous()
        off = m.origin[:, 0] * full.shape[-1] + m.origin[:, 1]                              # (B,)
        return full, off.repeat_interleave(L // off.shape[0]), full.shape[-1]
    base, row = _plane_rows(m[key], lead, H, W)
    return base, row * (H * W), W


def chain_triton(lpd_e: torch.Tensor, spd_e: torch.Tensor, preset: SensorPreset, t_s: torch.Tensor,
                 t_l: torch.Tensor, seeds: torch.Tensor, fpn: Mapping[str, torch.Tensor] | None) -> dict | None:
    """The chain of :func:`simulate_split_pixel_electrons` with counter noise (``seeds``) as Triton kernels on a
    GPU: one pass per photodiode, one per capture; None where the kernels cannot run here (the caller then takes
    the torch chain: the same numbers).

    Args: ``lpd_e``, ``spd_e`` (B, *, 1, H, W) float32 mean e- on a CUDA device; ``t_s``, ``t_l`` (B, *, 1, 1, 1)
    exposures in s; ``seeds`` (B,) int64 noise seeds; ``fpn`` maps broadcastable to the inputs or a
    :class:`PatternCrops`, or None. Returns what the torch chain returns, equal to it but where the float64
    library functions of the noise round differently (tests/sensor/test_counter_noise.py).
    """
    lead, (H, W) = lpd_e.shape[:-3], lpd_e.shape[-2:]
    P = H * W
    L = int(np.prod(lead, dtype=np.int64)) if len(lead) else 1
    B = seeds.shape[0]
    per = L // max(B, 1)
    dark, spd_factor = _row_scalars(preset, t_s, t_l, lead, L)
    use_fpn = fpn is not None
    # where each photodiode's DSNU offsets are read (shared by the captures of one photodiode)
    offsets = {pd: (_map_reader(fpn, f"{pd}_offset_e", lead, H, W, L) if use_fpn and spec.dsnu_e > 0 else None)
               for pd, spec in preset.photodiodes.items()}
    shot_seeds, read_seeds = _cn.chain_seeds(seeds, len(PHOTODIODES), len(CAPTURES))
    collected = {}
    for i_pd, pd in enumerate(PHOTODIODES):
        spec = preset.photodiodes[pd]
        gain = _map_reader(fpn, f"{pd}_gain", lead, H, W, L) if use_fpn and spec.prnu > 0 else None
        mu = (lpd_e if pd == "lpd" else spd_e).reshape(L, P).contiguous()
        n = _cn.run_kernel("collect", mu, shot_seeds[i_pd], per, gain, dark[pd],
                           MEAN_CAP_FULL_WELLS * spec.full_well_e, spec.full_well_e, W,
                           float(preset.shot_noise_gaussian_above_e), _cn.INVERSION_STEPS, _cn.PTRS_ROUNDS,
                           _cn.LOG_FACTORIAL)
        if n is None:
            return None
        collected[pd] = n
    dev, dtype = lpd_e.device, lpd_e.dtype
    out = {k: torch.empty(*lead, 1, H, W, dtype=dtype, device=dev) for k in (*CAPTURES, *(f"{c}_e" for c in CAPTURES))}
    sat = torch.empty(*lead, len(CAPTURES), H, W, dtype=torch.bool, device=dev)
    for c, cap in enumerate(CAPTURES):
        spec = preset.captures[cap]
        pd = spec.photodiode
        done = _cn.run_kernel(
            "readout", collected[pd], read_seeds[c] if spec.read_noise_e > 0 else None, per,
            float(spec.read_noise_e), offsets[pd], float(spec.conversion_gain_v_per_e), float(spec.voltage_swing_v),
            float(preset.dn_per_volt(cap)), float(preset.black_level_dn), float(preset.max_dn),
            float(preset.saturation_fraction * spec.voltage_swing_v), float(preset.system_gain(cap)), dark[pd],
            spd_factor if pd == "spd" else None, W, out[cap].view(L, P), out[f"{cap}_e"].view(L, P),
            sat.view(L, len(CAPTURES), P), c)
        if done is None:
            return None
    out["saturated"] = sat
    return out


def warm_fused(preset: SensorPreset | str, noise: bool) -> None:
    """Compile (or load from numba's cache) the compiled CPU chain's kernels for float32 inputs, in this process
    (what a DataLoader's parent does before forking its workers), through the chain of ``preset``'s plan."""
    if not _poisson.available():  # pragma: no cover - numba is a dependency
        return
    preset = load_preset(preset)
    z = torch.zeros(1, 1, 2, 2, device="cpu")
    g = torch.Generator().manual_seed(0) if noise else None
    if preset.architecture != "split_pixel":
        chain_plan_fused({k: z for k in preset.exposures}, preset, {k: 1e-3 for k in preset.exposures}, g, noise, None)
        return
    t = torch.full((1, 1, 1), 1e-3, device="cpu")
    chain_fused(z, z, preset, t, 10 * t, g, noise, None)
