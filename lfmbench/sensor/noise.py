"""The noise chain of the split-pixel sensor: mean photo-electrons -> noise -> volts -> DN.

Functional core in torch (batched over any leading dimensions, CPU or CUDA, float32/float64 following the
input, no per-pixel Python loops) with a thin :class:`SplitPixelSensor` module:
:func:`shot_noise`, :func:`fixed_pattern`, :func:`read_capture`, :func:`simulate_split_pixel_electrons`,
:func:`simulate_split_pixel` (the signal chain is listed in :mod:`lfmbench.sensor`), and
:func:`simulate_plan_electrons` for any capture plan. On the CPU both chains run compiled
(:mod:`lfmbench.sensor.fused`, bit-identical); the torch operations here are their reference and the path of every
other device. Size (about 520 lines): the two chains' torch reference with their argument checks and backends.

References
----------
.. [EMVA1288] EMVA Standard 1288, "Standard for Characterization of Image Sensors and Cameras", Release 4.0
   Linear (2021): the linear camera model (sec. 2) and the photon-transfer method of the sensitivity, linearity
   and noise measurement.
"""
from __future__ import annotations

import functools
from typing import Mapping, Sequence

import torch
from torch import nn

from lfmbench.check import check_same_shape, value_checks
from lfmbench.sensor import counter_noise as _cn
from lfmbench.sensor import poisson as _poisson
from lfmbench.sensor.fused import (MEAN_CAP_FULL_WELLS, PatternCrops, chain_fused, chain_plan_fused, chain_triton,
                                   per_generator)
from lfmbench.sensor.optics import check_radiometric
from lfmbench.sensor.preset import CAPTURES, PHOTODIODES, SensorPreset, load_preset
from lfmbench.sensor.response import ideal_electrons

__all__ = ["fixed_pattern", "photodiode_order", "shot_noise", "read_capture", "compand", "decompand",
           "simulate_split_pixel_electrons",
           "simulate_split_pixel", "simulate_plan_electrons", "SplitPixelSensor"]


@functools.lru_cache(maxsize=8)
def _fixed_pattern_cpu(seed: int, height: int, width: int, n_photodiodes: int = 2) -> tuple[torch.Tensor, ...]:
    g = torch.Generator(device="cpu").manual_seed(int(seed))
    # fixed draw order: per photodiode its gain, then its offset (standard normal, float64); split pixel: lpd, spd
    return tuple(torch.randn(height, width, generator=g, dtype=torch.float64) for _ in range(2 * n_photodiodes))


def photodiode_order(preset: SensorPreset) -> tuple[str, ...]:
    """The photodiodes of ``preset`` in their fixed-pattern draw order: ``PHOTODIODES`` for a split pixel (whatever
    the order in its file), the file's order otherwise."""
    return PHOTODIODES if preset.architecture == "split_pixel" else tuple(preset.photodiodes)


def fixed_pattern(preset: SensorPreset | str, height: int, width: int, device: torch.device | str | None = None,
                  dtype: torch.dtype = torch.float32) -> dict[str, torch.Tensor]:
    """Per-sensor fixed-pattern noise maps, identical on every call, device and dtype for the same preset and size.

    Drawn from ``torch.Generator().manual_seed(preset.fpn_seed)`` on the CPU in float64 (so CPU and CUDA agree).
    For crops of one sensor, build the full-frame pattern once and crop it.

    Returns:
        ``{"<pd>_gain"}``: PRNU gain maps 1 + prnu z (clipped >= 0), dimensionless, and ``{"<pd>_offset_e"}``:
        DSNU offset maps dsnu_e z in e-, for every photodiode ``<pd>`` (split pixel: lpd, spd); each (H, W).
    """
    preset = load_preset(preset)
    order = photodiode_order(preset)
    z = _fixed_pattern_cpu(preset.fpn_seed, int(height), int(width), len(order))
    out = {}
    for i, pd in enumerate(order):
        spec = preset.photodiodes[pd]
        out[f"{pd}_gain"] = (1.0 + spec.prnu * z[2 * i]).clamp_min(0.0).to(device=device, dtype=dtype)
        out[f"{pd}_offset_e"] = (spec.dsnu_e * z[2 * i + 1]).to(device=device, dtype=dtype)
    return out


def shot_noise(mean_e: torch.Tensor, generator: torch.Generator, gaussian_above_e: float = 1000.0,
               backend: str = "auto") -> torch.Tensor:
    """Photon (and dark-current) shot noise: a Poisson sample of the mean electron count.

    Means >= ``gaussian_above_e`` use the normal approximation N(mu, mu) rounded to integers (Poisson's skewness
    1/sqrt(mu) is < 3 % there; the distribution error is measured in ``benchmarks/bench_sensor.py``); smaller
    means are exact Poisson. ``gaussian_above_e = inf`` forces exact Poisson everywhere below 2^52 e-
    (:data:`lfmbench.sensor.poisson.EXACT_LIMIT`, where float64 stops holding counts exactly).

    Backends: ``"numba"`` (CPU only) is the compiled counter-based sampler of :mod:`lfmbench.sensor.poisson`
    (inversion below 10 e-, PTRS above; 1.6-2.3x faster than ``torch.poisson`` on a sample's means);
    ``"torch"`` uses ``torch.poisson`` and ``torch.randn`` (any device); ``"auto"`` picks ``"numba"`` for CPU
    tensors when numba is importable, else ``"torch"``. Both draw the same distribution, not the same numbers.

    Args:
        mean_e: (*) mean electrons, >= 0, e-.
        generator: random generator on the device of ``mean_e``.
        gaussian_above_e: switch-over mean in e-.
        backend: ``"auto"``, ``"numba"`` or ``"torch"``.

    Returns:
        (*) integer-valued electron counts, e-, dtype of ``mean_e``.
    """
    if backend not in ("auto", "numba", "torch"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'torch', got {backend!r}")
    if backend == "numba" or (backend == "auto" and mean_e.device.type == "cpu" and _poisson.available()):
        return _poisson.poisson(mean_e, generator, gaussian_above_e)
    # torch.poisson overflows int64 for huge means (1e20 -> -2^63): those take the rounded normal too
    small = mean_e < min(gaussian_above_e, _poisson.EXACT_LIMIT)
    n_small = int(small.sum())
    if n_small == mean_e.numel():
        return torch.poisson(mean_e, generator=generator)
    z = torch.randn(mean_e.shape, generator=generator, device=mean_e.device, dtype=mean_e.dtype)
    out = torch.round(mean_e + torch.sqrt(mean_e) * z).clamp_min(0.0)
    if n_small:
        # Poisson where the mean is small; a masked gather/scatter costs more than drawing Poisson(0) elsewhere
        # (14.5 -> 10.5 ms for a 3-frame 256x256 split-pixel sample, docs/benchmarks/dataset.md)
        pois = torch.poisson(torch.where(small, mean_e, torch.zeros_like(mean_e)), generator=generator)
        out = torch.where(small, pois, out)
    return out


def _exposure(value: float | torch.Tensor, name: str, lead: torch.Size, ref: torch.Tensor) -> torch.Tensor:
    t = torch.as_tensor(value, dtype=ref.dtype, device=ref.device)
    if value_checks() and (not bool(torch.isfinite(t).all()) or bool((t <= 0).any())):
        raise ValueError(f"{name} must be finite and > 0 (s), got {value!r}")
    if t.dim() > len(lead):
        raise ValueError(f"{name} must be a scalar or broadcastable to the leading shape {tuple(lead)}")
    try:
        t = t.reshape(*t.shape, 1, 1, 1).expand(*lead, 1, 1, 1) if t.dim() else t.reshape(1, 1, 1)
    except RuntimeError:
        raise ValueError(f"{name} with shape {tuple(t.shape)} does not broadcast to the leading shape "
                         f"{tuple(lead)}") from None
    return t


def read_capture(electrons: torch.Tensor, preset: SensorPreset, capture: str, generator: torch.Generator | None,
                 noise: bool = True, offset_e: torch.Tensor | None = None,
                 normals: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """Read one capture of collected photodiode electrons: offset, read noise, conversion gain, swing, ADC.

    Args:
        electrons: (*, 1, H, W) collected electrons (already clipped to the full well), e-.
        preset: sensor preset.
        capture: one of :data:`CAPTURES`.
        generator: random generator for the read noise (needed when ``noise``), or a sequence of B generators,
            one per index of the leading dimension of ``electrons`` (each draws its own slice).
        noise: add Gaussian read noise.
        offset_e: (H, W) DSNU offset map in e- (or ``None``).
        normals: (*, 1, H, W) standard normals to use for the read noise instead of drawing them from
            ``generator`` (the counter-based streams of :mod:`lfmbench.sensor.counter_noise`).

    Returns:
        ``{"dn": (*, 1, H, W) DN, "volts": (*, 1, H, W) V (clipped at the swing), "saturated": bool (*, 1, H, W)}``.
    """
    spec = preset.captures[capture]
    # in-place on tensors made here (never on ``electrons``): a 3-frame 256x256 capture is 0.75 MiB per temporary
    if noise and spec.read_noise_e > 0:
        volts = normals.to(electrons.dtype) if normals is not None else per_generator(
            lambda x, g: torch.randn(x.shape, generator=g, device=x.device, dtype=x.dtype), electrons, generator)
        volts.mul_(spec.read_noise_e).add_(electrons)
    else:
        volts = electrons.clone()
    if offset_e is not None:
        volts.add_(offset_e)
    volts.mul_(spec.conversion_gain_v_per_e).clamp_max_(spec.voltage_swing_v)
    dn = (volts * preset.dn_per_volt(capture)).add_(preset.black_level_dn).round_().clamp_(
        0.0, float(preset.linear_max_dn(capture)))
    if spec.companding is not None:
        dn = compand(dn, spec.companding).round_().clamp_(0.0, float(preset.max_dn))
    saturated = volts >= preset.saturation_fraction * spec.voltage_swing_v
    return {"dn": dn, "volts": volts, "saturated": saturated}


def _piecewise_linear(x: torch.Tensor, knots: Sequence[tuple[float, float]], inverse: bool = False) -> torch.Tensor:
    """``numpy.interp`` through increasing ``knots`` ((x, y) pairs; ``inverse``: read as (y, x)), clamped at the
    ends, in ``x``'s dtype: f(x) = y_0 + sum_i s_i clamp(x - x_i, 0, x_{i+1} - x_i) with s_i the slope of segment i
    (a few element-wise passes per segment; a curve has at most 32 knots)."""
    pts = [(b, a) for a, b in knots] if inverse else list(knots)
    out = torch.full_like(x, float(pts[0][1]))
    for (x0, y0), (x1, y1) in zip(pts, pts[1:]):
        out.add_((x - x0).clamp_(0.0, x1 - x0).mul_((y1 - y0) / (x1 - x0)))
    return out


def compand(dn_linear: torch.Tensor, companding) -> torch.Tensor:
    """On-sensor companding: linear codes (*) in DN through the piecewise-linear ``companding.knees`` (linear DN ->
    output DN), not rounded. :class:`lfmbench.sensor.preset.Companding`."""
    return _piecewise_linear(dn_linear, companding.knees)


def decompand(dn: torch.Tensor, companding) -> torch.Tensor:
    """The inverse of :func:`compand` (output DN -> linear DN, the knees read backwards), (*) in DN."""
    return _piecewise_linear(dn, companding.knees, inverse=True)


def _check_pair(lpd: torch.Tensor, spd: torch.Tensor, lpd_name: str, spd_name: str, check: bool) -> None:
    """The LPD and SPD inputs of a capture set: radiometric (if ``check``), one shape, one dtype
    (:func:`lfmbench.check.check_same_shape`)."""
    if check:
        check_radiometric(lpd, lpd_name)
        check_radiometric(spd, spd_name)
    check_same_shape(lpd, spd, lpd_name, spd_name, dtype=True)


def simulate_split_pixel_electrons(lpd_electrons: torch.Tensor, spd_electrons: torch.Tensor,
                                   preset: SensorPreset | str, exposure_short_s: float | torch.Tensor,
                                   exposure_long_s: float | torch.Tensor, generator: torch.Generator | None = None,
                                   noise: bool = True, fpn: Mapping[str, torch.Tensor] | None = None,
                                   check: bool = True, backend: str = "auto",
                                   threads: int | None = None,
                                   seeds: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """The three captures from mean photo-electrons (the noise and read-out part of :func:`simulate_split_pixel`).

    Use this when the spectral projection (:func:`ideal_electrons` or a cached equivalent) is done elsewhere.

    Args:
        lpd_electrons: (*, 1, H, W) mean photo-electrons of the LPD over the short exposure (CFA mosaic, LPD fill
            factor included, no dark current, no PRNU), e-.
        spd_electrons: (*, 1, H, W) the same for the SPD over the long exposure (SPD fill factor included), e-.
        preset: sensor preset or name.
        exposure_short_s, exposure_long_s: exposure times in s, scalars or shape (*).
        generator: ``torch.Generator`` on the inputs' device; required when ``noise`` is true. Or a sequence of B
            generators for inputs (B, *, 1, H, W): sample b then draws all its noise from its own generator, in the
            same order as a call on that sample alone, so its output does not depend on the other samples or on
            B (the batched dataset path, :mod:`lfmbench.datasets.batched`).
        noise: ``False``: noise-free chain (dark current mean kept, no FPN, clipping and quantisation kept).
        fpn: fixed-pattern maps (H, W) from :func:`fixed_pattern` (default: built for (H, W) from the preset),
            or maps broadcastable to the inputs whose last two dimensions are (H, W) (e.g. (B, 1, 1, H, W): one
            crop of the pattern per sample), or a :class:`lfmbench.sensor.fused.PatternCrops` (whole-frame maps
            and per-sample crop origins: the Triton chain reads them in place).
        check: validate the inputs (finite, >= 0, matching shapes).
        backend: ``"torch"``: the chain as torch element-wise operations (any device; shot noise by
            :func:`shot_noise`'s ``"auto"`` backend); ``"numba"`` (CPU, float32/float64, needs numba): the same
            operations compiled into one pass per photodiode (clipping, PRNU, dark signal, shot noise, full
            well: :func:`lfmbench.sensor._poisson_kernel.collect`) and one per capture (the read-out:
            :func:`lfmbench.sensor._readout_kernel.readout`), bit-identical to ``"torch"`` on the CPU with a fraction of
            its memory passes (docs/benchmarks/dataset.md); ``"auto"``: ``"numba"`` where it applies, on a GPU
            with ``seeds`` the Triton chain (:func:`lfmbench.sensor.fused.chain_triton`: the same passes as
            Triton kernels, the numbers of ``"torch"`` but where float64 library functions round differently),
            else ``"torch"``.
        seeds: instead of ``generator``: a (B,) int64 tensor, one noise seed per index of the leading (sample)
            dimension. Sample b then draws its shot and read noise from counter-based streams of ``seeds[b]``
            (:mod:`lfmbench.sensor.counter_noise`): the same numbers on the CPU (compiled or torch) and on a GPU,
            alone or in a batch of any size, with no generator object per sample; the whole batch is one set of
            tensor operations on a GPU.
        threads: with one generator per sample on the CPU, the samples are simulated by this many Python threads
            (default ``torch.get_num_threads()``; the result does not depend on it). The threads do not spin while
            they wait, unlike OpenMP's: on a machine shared with other jobs use ``torch.set_num_threads(1)`` and
            ``threads`` = the cores to use.

    Returns:
        as :func:`simulate_split_pixel`.
    """
    if backend not in ("auto", "numba", "torch"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'torch', got {backend!r}")
    _check_pair(lpd_electrons, spd_electrons, "lpd_electrons", "spd_electrons", check)
    if lpd_electrons.shape[-3] != 1:
        raise ValueError(f"lpd_electrons must have shape (*, 1, H, W) (a CFA mosaic), got {tuple(lpd_electrons.shape)}")
    preset = load_preset(preset)
    x = lpd_electrons
    if noise and seeds is not None:
        if generator is not None:
            raise ValueError("give either generator or seeds, not both")
        if x.dim() < 4:
            raise ValueError(f"seeds need inputs (B, *, 1, H, W) with a sample dimension, got {tuple(x.shape)}")
        seeds = _cn.check_seeds(seeds, x.shape[0]).to(x.device)
    elif noise:
        gens = list(generator) if isinstance(generator, (list, tuple)) else [generator]
        if not gens or not all(isinstance(g, torch.Generator) for g in gens):
            raise ValueError("generator must be a torch.Generator (or a sequence of them, one per sample) when "
                             "noise=True (no hidden global randomness)")
        if isinstance(generator, (list, tuple)) and (x.dim() < 4 or len(gens) != x.shape[0]):
            raise ValueError(f"generator: {len(gens)} generators for inputs of shape {tuple(x.shape)}; a sequence "
                             "needs one generator per index of the leading (sample) dimension")
        for g in gens:
            if g.device.type != x.device.type:
                raise ValueError(f"generator is on {g.device} but the inputs are on {x.device}")
    lead = x.shape[:-3]
    H, W = x.shape[-2:]
    t_s = _exposure(exposure_short_s, "exposure_short_s", lead, x)
    t_l = _exposure(exposure_long_s, "exposure_long_s", lead, x)
    if fpn is None and noise and any(p.prnu > 0 or p.dsnu_e > 0 for p in preset.photodiodes.values()):
        fpn = fixed_pattern(preset, H, W, device=x.device, dtype=x.dtype)
    elif isinstance(fpn, PatternCrops):
        if fpn.hw != (H, W) or fpn.origin.shape != (x.shape[0], 2):
            raise ValueError(f"fpn: crops of {fpn.hw} px at {tuple(fpn.origin.shape)} origins, expected ({H}, {W}) "
                             f"and ({x.shape[0]}, 2)")
        fpn = fpn.to(x.device, x.dtype)
    elif fpn is not None:
        fpn = {k: v.to(device=x.device, dtype=x.dtype) for k, v in fpn.items()}
        for k, v in fpn.items():
            if v.shape[-2:] != (H, W):
                raise ValueError(f"fpn[{k!r}] has shape {tuple(v.shape)}, expected (..., {H}, {W})")
    fused = x.device.type == "cpu" and x.dtype in (torch.float32, torch.float64) and _poisson.available()
    if backend == "numba" and not fused:
        raise ValueError(f"backend='numba' needs float32/float64 CPU inputs and numba (got {x.dtype} on {x.device})")
    if fused and backend != "torch":
        return chain_fused(lpd_electrons, spd_electrons, preset, t_s, t_l, generator, noise, fpn, threads,
                           seeds if noise else None)
    counter = noise and seeds is not None
    if counter and backend != "torch" and x.dtype == torch.float32 and x.dim() >= 4 and _cn.kernels_ready(x):
        out = chain_triton(lpd_electrons, spd_electrons, preset, t_s, t_l, seeds, fpn)
        if out is not None:
            return out

    pd_inputs = {"lpd": (lpd_electrons, t_s), "spd": (spd_electrons, t_l)}
    collected: dict[str, torch.Tensor] = {}
    for pd, (mu, t) in pd_inputs.items():
        spec = preset.photodiodes[pd]
        cap = MEAN_CAP_FULL_WELLS * spec.full_well_e
        mu = torch.nan_to_num(mu, nan=0.0, posinf=cap).clamp_(0.0, cap)         # overflow-safe, exact after clip
        if noise and fpn is not None and spec.prnu > 0:
            mu.mul_(fpn[f"{pd}_gain"])
        mu.add_(spec.dark_current_e_per_s * t)
        if counter:  # sample b's pixels from the streams of its shot seed (the compiled sampler's streams)
            B = mu.shape[0]
            n = _cn.poisson(mu.reshape(B, -1), _cn.shot_seed(seeds, PHOTODIODES.index(pd)),
                            preset.shot_noise_gaussian_above_e).to(mu.dtype).reshape(mu.shape)
        else:
            n = per_generator(lambda m, g: shot_noise(m, g, preset.shot_noise_gaussian_above_e), mu, generator,
                               threads) if noise else mu
        collected[pd] = n.clamp_(0.0, spec.full_well_e)

    out: dict[str, torch.Tensor] = {}
    sats = []
    for cap in CAPTURES:
        pd = preset.captures[cap].photodiode
        offset = fpn[f"{pd}_offset_e"] if (noise and fpn is not None and preset.photodiodes[pd].dsnu_e > 0) else None
        z = None
        if counter and preset.captures[cap].read_noise_e > 0:
            z = _cn.normal(_cn.read_seed(seeds, CAPTURES.index(cap)), collected[pd][0].numel()).reshape(
                collected[pd].shape)
        r = read_capture(collected[pd], preset, cap, generator, noise, offset, normals=z)
        out[cap] = r["dn"]
        # DN -> e-, minus the mean dark signal (what optical-black clamping removes), so that the expectation
        # of the input-referred value equals ideal_electrons() below saturation
        e_ref = (r["dn"] - preset.black_level_dn).div_(preset.system_gain(cap)) \
            .sub_(preset.photodiodes[pd].dark_current_e_per_s * pd_inputs[pd][1])
        if pd == "spd":
            e_ref.mul_(preset.sensitivity_ratio * t_s / t_l)
        out[f"{cap}_e"] = e_ref
        sats.append(r["saturated"])
    out["saturated"] = torch.cat(sats, dim=-3)
    return out


def _refer(dn: torch.Tensor, preset: SensorPreset, capture: str, key: str,
           exposure_s: Mapping[str, float]) -> torch.Tensor:
    """Input referral of one capture of a plan: (*, 1, H, W) DN (companded where the capture is) -> e- of the
    reference capture's photodiode over its windows, (decompand(DN) - black) / K - dark_current x T, then
    x (FF_ref / FF_pd) x (T_ref / T) (:func:`simulate_plan_electrons`)."""
    spec = preset.photodiodes[preset.captures[capture].photodiode]
    ref_key = next(k for k, caps in preset.exposures.items() if preset.reference in caps)
    ff_ref = preset.photodiodes[preset.captures[preset.reference].photodiode].fill_factor
    t, t_ref = float(exposure_s[key]), float(exposure_s[ref_key])
    comp = preset.captures[capture].companding
    lin = decompand(dn, comp) if comp is not None else dn
    e = (lin - preset.black_level_dn).div_(preset.system_gain(capture)).sub_(spec.dark_current_e_per_s * t)
    return e.mul_((ff_ref / spec.fill_factor) * (t_ref / t))


def simulate_plan_electrons(mean_e: Mapping[str, torch.Tensor], preset: SensorPreset | str,
                            exposure_s: Mapping[str, float], generator: torch.Generator | None = None,
                            noise: bool = True, fpn: Mapping[str, torch.Tensor] | None = None,
                            check: bool = True, backend: str = "auto") -> dict[str, torch.Tensor]:
    """Every capture of a preset's plan from the mean photo-electrons of its exposures (any architecture).

    An *exposure* is one integration of one photodiode over its windows (:attr:`SensorPreset.exposures`: the
    captures that read the same charge share it). Per exposure, in plan order: PRNU gain, dark signal
    dark_current x T, shot noise (:func:`shot_noise`), full-well clip; then per capture, in plan order:
    :func:`read_capture` (DSNU offset, read noise, conversion gain, swing, ADC) of its exposure's charge. A split
    pixel goes through :func:`simulate_split_pixel_electrons` (its compiled CPU chain; same numbers as before).

    Input referral (the ``*_e`` outputs): (DN - black) / K - dark_current x T, then x (FF_ref / FF_pd) x
    (T_ref / T): electrons of the reference capture's photodiode over its windows (``preset.reference``), the units of
    the ground truth; for the split pixel LPD-equivalent e- over the short window, as before.

    Args:
        mean_e: ``{exposure key: (*, 1, H, W)}`` mean photo-electrons of each exposure (CFA mosaic, the
            photodiode's fill factor included, no dark current, no PRNU), e-.
        preset: sensor preset or name.
        exposure_s: ``{exposure key: integration time}`` in s (the summed window lengths): dark signal and input
            referral.
        generator: ``torch.Generator`` on the inputs' device (required when ``noise``).
        noise: ``False``: noise-free chain (dark mean kept, no FPN, clipping and quantisation kept).
        fpn: maps of :func:`fixed_pattern` (default: built for (H, W) from the preset when it has PRNU or DSNU).
        check: validate the inputs (finite, >= 0, same shape).
        backend: ``"torch"``: the chain as torch element-wise operations (the reference; shot noise by
            :func:`shot_noise`'s ``"auto"`` backend); ``"numba"`` (float32/float64 CPU inputs, needs numba): the same
            operations compiled into one pass per exposure and one per capture
            (:func:`lfmbench.sensor.fused.chain_plan_fused`; on-sensor companding then in torch), bit-identical to
            ``"torch"`` with a fraction of its passes over the image (docs/benchmarks/dataset.md); ``"auto"``:
            ``"numba"`` where it applies, else ``"torch"``. A split pixel takes
            :func:`simulate_split_pixel_electrons` with this backend.

    Returns:
        ``{capture: (*, 1, H, W) DN, f"{capture}_e": (*, 1, H, W) input-referred e-, "saturated": (*, N, H, W)
        bool}`` for the N captures in plan order.
    """
    preset = load_preset(preset)
    groups = preset.exposures
    if set(mean_e) != set(groups) or set(exposure_s) != set(groups):
        raise ValueError(f"mean_e and exposure_s need the exposures {list(groups)} of preset {preset.name!r}, got "
                         f"{sorted(mean_e)} and {sorted(exposure_s)}")
    first = mean_e[next(iter(groups))]
    for k, x in mean_e.items():
        if check:
            check_radiometric(x, f"mean_e[{k!r}]")
        if x.shape != first.shape or x.dtype != first.dtype or x.shape[-3] != 1:
            raise ValueError(f"mean_e[{k!r}] must have the shape (*, 1, H, W) and dtype of the others, got "
                             f"{tuple(x.shape)} {x.dtype}")
    if backend not in ("auto", "numba", "torch"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'torch', got {backend!r}")
    if preset.architecture == "split_pixel":
        return simulate_split_pixel_electrons(mean_e["lpd_hcg"], mean_e["spd"], preset, exposure_s["lpd_hcg"],
                                              exposure_s["spd"], generator, noise, fpn, check=False, backend=backend)
    if noise and not isinstance(generator, torch.Generator):
        raise ValueError("generator must be a torch.Generator when noise=True (no hidden global randomness)")
    H, W = first.shape[-2:]
    if fpn is None and noise and any(p.prnu > 0 or p.dsnu_e > 0 for p in preset.photodiodes.values()):
        fpn = fixed_pattern(preset, H, W, device=first.device, dtype=first.dtype)
    # the compiled chain reads the maps in the inputs' dtype (the torch chain would multiply in a wider one)
    fused = (first.device.type == "cpu" and first.dtype in (torch.float32, torch.float64) and _poisson.available()
             and (not noise or generator.device.type == "cpu")
             and (fpn is None or not noise or all(v.dtype == first.dtype and v.device == first.device
                                                  for v in fpn.values())))
    if backend == "numba" and not fused:
        raise ValueError(f"backend='numba' needs float32/float64 CPU inputs, a CPU generator, fixed-pattern maps in "
                         f"the inputs' dtype and numba (got {first.dtype} on {first.device})")
    if fused and backend != "torch":
        out, linear = chain_plan_fused({k: mean_e[k] for k in groups}, preset, exposure_s, generator, noise, fpn)
        for c in linear:   # on-sensor companding of the linear codes: the torch chain's operations
            key = next(k for k, caps in groups.items() if c in caps)
            out[c] = compand(out[c], preset.captures[c].companding).round_().clamp_(0.0, float(preset.max_dn))
            out[f"{c}_e"] = _refer(out[c], preset, c, key, exposure_s)
        return out
    collected: dict[str, torch.Tensor] = {}
    for key in groups:
        pd = preset.captures[key].photodiode
        spec = preset.photodiodes[pd]
        cap = MEAN_CAP_FULL_WELLS * spec.full_well_e
        mu = torch.nan_to_num(mean_e[key], nan=0.0, posinf=cap).clamp(0.0, cap)
        if noise and fpn is not None and spec.prnu > 0:
            mu.mul_(fpn[f"{pd}_gain"])
        mu.add_(spec.dark_current_e_per_s * float(exposure_s[key]))
        n = shot_noise(mu, generator, preset.shot_noise_gaussian_above_e) if noise else mu
        collected[key] = n.clamp_(0.0, spec.full_well_e)
    out: dict[str, torch.Tensor] = {}
    sats = []
    for key, caps in groups.items():
        pd = preset.captures[key].photodiode
        spec = preset.photodiodes[pd]
        offset = fpn[f"{pd}_offset_e"] if (noise and fpn is not None and spec.dsnu_e > 0) else None
        for c in caps:
            r = read_capture(collected[key], preset, c, generator, noise, offset)
            out[c] = r["dn"]
            out[f"{c}_e"] = _refer(r["dn"], preset, c, key, exposure_s)
            sats.append((c, r["saturated"]))
    order = list(preset.captures)
    sats.sort(key=lambda cs: order.index(cs[0]))
    out["saturated"] = torch.cat([s for _, s in sats], dim=-3)
    return {**{c: out[c] for c in order}, **{f"{c}_e": out[f"{c}_e"] for c in order}, "saturated": out["saturated"]}


def simulate_split_pixel(lpd_radiant_exposure: torch.Tensor, spd_radiant_exposure: torch.Tensor,
                         preset: SensorPreset | str, wavelengths_nm: Sequence[float] | torch.Tensor,
                         exposure_short_s: float | torch.Tensor, exposure_long_s: float | torch.Tensor,
                         generator: torch.Generator | None = None, noise: bool = True,
                         bandwidths_nm: Sequence[float] | None = None,
                         fpn: Mapping[str, torch.Tensor] | None = None, check: bool = True,
                         seeds: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """Simulate the three captures (LPD-HCG, LPD-LCG, SPD) of a split-pixel sensor.

    Args:
        lpd_radiant_exposure: (*, C, H, W) spectral radiant exposure at the pixel over the short (LPD) exposure,
            J m^-2 nm^-1 (spectral irradiance W m^-2 nm^-1 x s, flicker weights included by the caller).
        spd_radiant_exposure: (*, C, H, W) the same over the long (SPD) exposure, J m^-2 nm^-1.
        preset: sensor preset or name (``"ovt"``, ``"imx490"``, a YAML path).
        wavelengths_nm: C band centres in nm.
        exposure_short_s: LPD exposure time in s, scalar or shape (*) (per sample); used for dark current.
        exposure_long_s: SPD exposure time in s, scalar or shape (*); used for dark current and input referral.
        generator: ``torch.Generator`` on the inputs' device; required when ``noise`` is true.
        noise: ``False`` gives the noise-free chain (mean electrons incl. dark current, no FPN, clipping and
            quantisation kept).
        bandwidths_nm: band widths in nm (default: local spacing of ``wavelengths_nm``).
        fpn: fixed-pattern maps from :func:`fixed_pattern` (default: built for (H, W) from the preset's seed).
        check: validate the inputs (finite, >= 0, matching shapes).
        seeds: (B,) int64 per-sample noise seeds instead of ``generator`` (counter-based noise, see
            :func:`simulate_split_pixel_electrons`).

    Returns:
        dict with ``lpd_hcg``, ``lpd_lcg``, ``spd``: (*, 1, H, W) raw DN (black level included);
        ``lpd_hcg_e``, ``lpd_lcg_e``, ``spd_e``: (*, 1, H, W) input-referred LPD-equivalent e- over the short
        exposure, mean dark signal removed (same units and expectation as :func:`ideal_electrons` of the LPD);
        ``saturated``: (*, 3, H, W) bool (hcg, lcg, spd), volts >= saturation_fraction x swing.
        Floating outputs have the dtype of the inputs.
    """
    _check_pair(lpd_radiant_exposure, spd_radiant_exposure, "lpd_radiant_exposure", "spd_radiant_exposure", check)
    preset = load_preset(preset)
    lpd_e = ideal_electrons(lpd_radiant_exposure, preset, wavelengths_nm, "lpd", bandwidths_nm, check=False)
    spd_e = ideal_electrons(spd_radiant_exposure, preset, wavelengths_nm, "spd", bandwidths_nm, check=False)
    return simulate_split_pixel_electrons(lpd_e, spd_e, preset, exposure_short_s, exposure_long_s, generator,
                                          noise, fpn, check=False, seeds=seeds)


class SplitPixelSensor(nn.Module):
    """``nn.Module`` wrapper of :func:`simulate_split_pixel` holding the preset and the band grid.

    Args:
        preset: preset, name or YAML path.
        wavelengths_nm: C band centres in nm (default 400:10:700).
        noise: default for the ``noise`` argument.

    Shape:
        inputs (*, C, H, W) spectral radiant exposure in J m^-2 nm^-1; outputs as :func:`simulate_split_pixel`.
    """

    def __init__(self, preset: SensorPreset | str = "ovt", wavelengths_nm: Sequence[float] | None = None,
                 noise: bool = True) -> None:
        super().__init__()
        self.preset = load_preset(preset)
        wl = range(400, 701, 10) if wavelengths_nm is None else wavelengths_nm
        self.wavelengths_nm = [float(w) for w in wl]
        self.noise = noise

    def forward(self, lpd_radiant_exposure: torch.Tensor, spd_radiant_exposure: torch.Tensor,
                exposure_short_s: float | torch.Tensor, exposure_long_s: float | torch.Tensor,
                generator: torch.Generator | None = None, noise: bool | None = None) -> dict[str, torch.Tensor]:
        return simulate_split_pixel(lpd_radiant_exposure, spd_radiant_exposure, self.preset, self.wavelengths_nm,
                                    exposure_short_s, exposure_long_s, generator=generator,
                                    noise=self.noise if noise is None else noise)
