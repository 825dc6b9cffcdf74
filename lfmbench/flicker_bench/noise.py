r"""KPIs with the preset's noise chain: Monte Carlo over frames at uniformly drawn PWM phases.

Each draw is one frame: a phase :math:`\varphi \sim U[0, T)`, the exact mean electrons of every exposure group
(:mod:`~lfmbench.flicker_bench.model`), then the preset's own chain
:func:`lfmbench.sensor.simulate_plan_electrons` (PRNU, dark signal, shot noise, full-well clip, DSNU, read noise,
conversion gain, swing clip, ADC quantisation, saturated flags, input referral) on the ``roi_px`` pixels of the
ROI, the fusion methods per pixel, and the ROI mean. Over ``draws`` frames per cell the P2020 KPIs are computed with
:mod:`lfmbench.metrics.flicker` (the FDI's OFF level: the noise-free LED-OFF value), MMP with its Wilson 95 %
interval (E. B. Wilson, "Probable inference, the law of succession, and statistical inference", JASA 22 (1927)
209-212), beside the *noise floor*: the same KPIs of a steady light of the same mean (:math:`f_c = D`), so the
share of MMP lost to noise, not to flicker, is read off directly.

Approximation: every ROI pixel gets the CFA cell's mean response (:func:`~.model.luminance_rate`) instead of its
own channel's. Below saturation this changes nothing in the ROI mean's distribution up to quantisation: the sum of
independent Poisson counts is Poisson with the summed mean, and read noise does not depend on the signal. It does
matter near saturation, where a real Bayer ROI's channels clip at different luminances (over a range of the
channels' response ratio); there the noisy columns describe a grey ROI of the same mean response.
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np
import torch

from lfmbench.flicker_bench.exact import on_fraction
from lfmbench.flicker_bench.model import SensorModel, grid_cells
from lfmbench.metrics.flicker import fdi, fmi, mmp
from lfmbench.sensor import simulate_plan_electrons

__all__ = ["noise_kpis", "wilson_interval", "Z95"]

#: Two-sided 95 % standard normal quantile.
Z95 = 1.959963984540054


def wilson_interval(p: np.ndarray, n: int, z: float = Z95) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval of a binomial proportion ``p`` from ``n`` trials (95 % by default)."""
    p = np.asarray(p, np.float64)
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * np.sqrt(np.clip(p * (1 - p) / n + z * z / (4 * n * n), 0, None)) / den
    return centre - half, centre + half


def _roi_mean(x: torch.Tensor, m: int, roi_px: int) -> np.ndarray:
    """(M,) float64 ROI means of ``x`` (M x roi_px values, pixels fastest), summed in float64."""
    return x.reshape(m, roi_px).double().mean(dim=1).numpy()


def _readout(model: SensorModel, frac: Mapping[str, np.ndarray], lum: np.ndarray, roi_px: int,
             methods: Mapping[str, Callable], gen: torch.Generator) -> dict[str, np.ndarray]:
    """ROI means (reference e-) of every panel for ON fractions ``frac[group]`` (M,) at luminances ``lum`` (M,).

    The chain and the merges run in float32 (about 25 % less time than float64 on a 2-core AMD EPYC, and half the
    memory): its 24-bit significand resolves 1e-7 of a value, far below the shot noise of any pixel that is not
    dark (a count of 1e5 e- has a relative shot noise of 3e-3) and below one ADC code of the 10-20-bit read-outs;
    the ROI means and the KPIs are taken in float64."""
    bg = model.settings["background_cd_m2"]
    groups = {}
    for c in model.captures:
        groups.setdefault(c.group, c)
    mean_e, exp_s = {}, {}
    for g, c in groups.items():
        e = (c.rate * (lum * frac[g] + bg)).astype(np.float32)
        mean_e[g] = torch.from_numpy(np.ascontiguousarray(np.repeat(e[:, None], roi_px, axis=1))).reshape(-1, 1, 1,
                                                                                                           roi_px)
        exp_s[g] = c.length_s
    out = simulate_plan_electrons(mean_e, model.preset, exp_s, generator=gen, noise=True, check=False)
    M = lum.size
    names = model.names
    res = {c: _roi_mean(out[f"{c}_e"], M, roi_px) for c in names}
    if methods:
        batch = {f"{c}_e": out[f"{c}_e"].reshape(1, M, 1, 1, roi_px) for c in names}
        batch["saturated"] = out["saturated"].reshape(1, M, len(names), 1, roi_px)
        lens = {c.name: c.length_s for c in model.captures}
        batch["meta"] = {"exposure_short_s": lens[model.preset.reference],
                         "exposure_long_s": lens.get("spd", max(lens.values())), "sensor": model.preset}
        batch["gt"] = batch[f"{names[0]}_e"]
        for k, fn in methods.items():
            with torch.no_grad():
                res[k] = _roi_mean(fn(batch), M, roi_px)
    return res


def noise_kpis(model: SensorModel, freqs_hz: np.ndarray, duties: np.ndarray, lums: np.ndarray,
               methods: Mapping[str, Callable], off: Mapping[str, float], draws: int = 1000, roi_px: int = 4,
               seed: int = 0, delta: float = 0.1, contrast: float = 0.1, chunk_draws: int = 2_000_000
               ) -> dict[str, dict[str, np.ndarray]]:
    """Noisy KPIs per panel: ``{panel: {"fmi", "mmp", "mmp_lo", "mmp_hi", "fdi", "mmp_floor", "fmi_floor"}}``,
    each (C, L) for cells = ``freqs_hz`` x ``duties`` (duty fastest); floors are the steady light's.

    Args:
        off: per panel the LED-OFF value (the FDI's x_off), e.g. ``PhaseMap.off``.
        draws: frames per cell (each at an independent uniform phase).
        roi_px: pixels averaged into the ROI mean.
        seed: seed of the phases and of the noise (torch.Generator); the result depends on it only.
        chunk_draws: frames simulated at once (bounds the memory).
    """
    f, d = grid_cells(freqs_hz, duties)
    lums = np.asarray(lums, np.float64)
    C, L = f.size, lums.size
    panels = model.names + list(methods)
    rng = np.random.default_rng(seed)
    gen = torch.Generator().manual_seed(int(seed))
    keys = ("fmi", "mmp", "mmp_lo", "mmp_hi", "fdi", "mmp_floor", "fmi_floor")
    out = {p: {k: np.empty((C, L)) for k in keys} for p in panels}
    groups = {}
    for c in model.captures:
        groups.setdefault(c.group, c)
    per_chunk = max(1, chunk_draws // (draws * L))

    def kpis(series: dict[str, np.ndarray], n_cells: int) -> dict[str, dict[str, np.ndarray]]:
        r = {}
        for p, x in series.items():
            t = torch.from_numpy(x.reshape(n_cells, L, draws))
            r[p] = {"fmi": fmi(t).numpy(), "mmp": mmp(t, delta=delta).numpy(),
                    "fdi": fdi(t, x_off=float(off[p]), contrast_threshold=contrast).numpy()}
        return r

    # noise floor: a steady light of the same mean, per (duty, luminance) (no phase dependence)
    ud, inv = np.unique(d, return_inverse=True)
    frac_s = {g: np.repeat(ud, L * draws) for g in groups}
    lum_s = np.tile(np.repeat(lums, draws), ud.size)
    floor = kpis(_readout(model, frac_s, lum_s, roi_px, methods, gen), ud.size)
    for i0 in range(0, C, per_chunk):
        sl = slice(i0, min(C, i0 + per_chunk))
        n = sl.stop - sl.start
        T = 1.0 / f[sl]
        phase = rng.random((n, draws)) * T[:, None]                                      # (n, draws)
        frac = {g: on_fraction(c, phase, T[:, None], d[sl][:, None]) for g, c in groups.items()}
        frac = {g: np.repeat(v[:, None, :], L, axis=1).reshape(-1) for g, v in frac.items()}  # (n, L, draws)
        lum = np.broadcast_to(lums[None, :, None], (n, L, draws)).reshape(-1)
        r = kpis(_readout(model, frac, lum, roi_px, methods, gen), n)
        for p in panels:
            for k in ("fmi", "mmp", "fdi"):
                out[p][k][sl] = r[p][k]
            lo, hi = wilson_interval(r[p]["mmp"], draws)
            out[p]["mmp_lo"][sl], out[p]["mmp_hi"][sl] = lo, hi
            out[p]["mmp_floor"][sl] = floor[p]["mmp"][inv[sl]]
            out[p]["fmi_floor"][sl] = floor[p]["fmi"][inv[sl]]
    return out
