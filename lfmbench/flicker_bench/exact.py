r"""Every PWM phase, exactly: the captured ON fraction and every merge as piecewise-linear functions of phase.

Why it is exact. For one window :math:`[a, a + n)` the ON time :math:`g(s) = \Phi(s, n, T, D)` of the pulse train
started at :math:`s = a - \varphi` has the derivative :math:`p(s + n) - p(s)` (:math:`p` the 0/1 pulse), which is
piecewise constant: :math:`g`, and any weighted sum of such terms (chopped windows, rolling-shutter rows), is
continuous and piecewise linear in :math:`\varphi`, with breakpoints only where a window edge meets a pulse edge,

.. math:: \varphi \equiv a,\quad a - DT,\quad a + n,\quad a + n - DT \pmod T

(4 per window). Between consecutive breakpoints every capture's mean electrons :math:`\mu_c(\varphi)` are linear;
its clipped value changes slope, and its saturated flag flips, only where :math:`\mu_c` crosses the clip or the
flag level (a linear equation per interval). A merge that selects, averages with fixed weights, or takes the
max/min of the captures according to their flags (``exposure_select``, ``exposure_select_bounded``,
``saturated_exposure_corrected``, ``lpd_only``, ``spd_only``, ``upstream_saturated``) is then linear on every
sub-interval once the crossings of any two captures' values are added as well. So the sub-intervals between

- the breakpoints of all windows,
- the clip and flag crossings of every capture, and
- the crossings of every pair of input-referred capture values (linear or clipped)

carry linear pieces, whose one-sided end values (the merge evaluated on the end values with the flags of the
interior) give min, max, mean, and the phase measure inside any band, in closed form. No phase is sampled.

Merges outside that class (the noise test of ``flicker_aware`` switches at a root of a quadratic) are checked for
linearity on every piece: where the value at the midpoint is not the mean of the end values (relative
:data:`LINEAR_RTOL`), the piece is halved, up to ``max_depth`` times. A switch is thereby located to
:math:`2^{-\text{depth}}` of its piece; the error against dense sampling and the run time per depth are in
docs/benchmarks/flicker-bench.md.

Shapes: ``cells`` = frequency x duty pairs (flattened), ``L`` luminances, per cell ``K`` breakpoint intervals.
Phases in s, measured from the frame start to an LED rising edge.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np
import torch

from lfmbench.flicker_bench.model import CaptureModel, SensorModel, grid_cells
from lfmbench.flicker import pwm_exposure

__all__ = ["EXACT_METHODS", "SEQUENCE_METHODS", "breakpoints", "on_fraction", "PhaseMap", "phase_map",
           "band_measure", "evaluate_panels", "capture_state", "off_values"]

#: Registered merges that are piecewise linear on the sub-intervals (module docstring): their maps are exact.
EXACT_METHODS = frozenset({"exposure_select", "exposure_select_bounded", "saturated_exposure_corrected", "lpd_only",
                           "spd_only", "upstream_saturated"})
#: Registered merges that need a sequence of frames (not one frame of a flat target): left out of the maps.
SEQUENCE_METHODS = frozenset({"temporal"})


def _group_windows(model: SensorModel) -> dict[str, CaptureModel]:
    """One capture per exposure group (captures of a group read the same charge, over the same windows)."""
    out: dict[str, CaptureModel] = {}
    for c in model.captures:
        out.setdefault(c.group, c)
    return out


def on_fraction(cap: CaptureModel, phase: np.ndarray, period: np.ndarray, duty: np.ndarray) -> np.ndarray:
    r"""Captured ON fraction :math:`f_c(\varphi)` (dimensionless, 0..1) of a capture, exact.

    Args:
        cap: the capture.
        phase: (..., K) LED rising-edge phases (s from the frame start).
        period, duty: (..., 1) PWM period (s) and duty (1), broadcastable to ``phase``.

    Returns:
        (..., K) ON time over the windows divided by the integration time, weighted over the ROI rows.
    """
    s = cap.starts_s - phase[..., None]                      # (..., K, W): window start relative to an edge
    # numpy's formula (the compiled kernel's arithmetic): importing and starting numba costs the bench more
    on = pwm_exposure(s, cap.lengths_s, period[..., None], duty[..., None], check=False, backend="numpy")
    return (on * cap.weights).sum(axis=-1) / cap.length_s


def breakpoints(model: SensorModel, period: np.ndarray, duty: np.ndarray) -> np.ndarray:
    """The phases (s) where some window edge meets a pulse edge, sorted in [0, T), with phase 0 and, last, the
    first breakpoint + T (closing the circle).

    Args:
        period, duty: (C, 1) per cell.

    Returns:
        (C, K + 1) with K = 1 + 4 x (windows of all exposure groups).
    """
    pts = [np.zeros_like(period)]
    dt = duty * period
    for cap in _group_windows(model).values():
        a = cap.starts_s[None, :]
        e = (cap.starts_s + cap.lengths_s)[None, :]
        pts += [a, a - dt, e, e - dt]
    b = np.concatenate([np.broadcast_to(p, (period.shape[0], p.shape[1])) for p in pts], axis=1)
    b = np.mod(b, period)
    b = np.where(b >= period, b - period, b)
    b.sort(axis=1)
    return np.concatenate([b, b[:, :1] + period], axis=1)


def capture_state(model: SensorModel, mu: Mapping[str, torch.Tensor]) -> tuple[dict, torch.Tensor]:
    """Noise-free read-out of mean electrons: ``{"<c>_e": input-referred value}`` and the saturated flags.

    Args:
        mu: per capture name, mean electrons of its photodiode over its windows (dark included), any shape S.

    Returns:
        (``{name_e: (S) reference e-}``, flags (N, *S) bool in plan order).
    """
    vals, flags = {}, []
    for c in model.captures:
        m = mu[c.name]
        vals[f"{c.name}_e"] = (m.clamp_max(c.clip_e) - c.dark_e) * c.refer
        flags.append(m >= c.sat_e)
    return vals, torch.stack(flags)


def _batch(model: SensorModel, vals: Mapping[str, torch.Tensor], flags: torch.Tensor) -> dict:
    """A flat-target batch for the fusion methods: every element one pixel, (1, 1, 1, 1, M)."""
    caps = model.names
    b = {f"{c}_e": vals[f"{c}_e"].reshape(1, 1, 1, 1, -1) for c in caps}
    b["saturated"] = flags.reshape(len(caps), -1).reshape(1, 1, len(caps), 1, -1)
    lens = {c.name: c.length_s for c in model.captures}
    ref = model.preset.reference
    long_s = lens.get("spd", max(lens.values()))
    b["meta"] = {"exposure_short_s": lens[ref], "exposure_long_s": long_s, "sensor": model.preset}
    b["gt"] = b[f"{caps[0]}_e"]
    return b


def evaluate_panels(model: SensorModel, methods: Mapping[str, Callable], vals: Mapping[str, torch.Tensor],
                    flags: torch.Tensor) -> dict[str, torch.Tensor]:
    """Every panel's value: each capture's input-referred value, then each method's output (same shape)."""
    shape = next(iter(vals.values())).shape
    out = {c: vals[f"{c}_e"] for c in model.names}
    if methods:
        batch = _batch(model, vals, flags)
        for name, fn in methods.items():
            with torch.no_grad():
                y = fn(batch)
            out[name] = y.reshape(shape).to(torch.float64)
    return out


def band_measure(yl: np.ndarray, yr: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Share of [0, 1] where the linear function from ``yl`` (at 0) to ``yr`` (at 1) lies strictly inside
    (lo, hi); ``lo = -inf`` or ``hi = inf`` for one-sided bands. Exact up to rounding; all broadcast."""
    d = yr - yl
    with np.errstate(divide="ignore", invalid="ignore"):
        t_lo = (lo - yl) / d
        t_hi = (hi - yl) / d
    up = d > 0
    a = np.where(up, t_lo, t_hi)              # d < 0: the line enters the band at hi; d == 0 is answered below
    b = np.where(up, t_hi, t_lo)
    # fmax / fmin read a NaN end (0/0) as -inf / +inf, i.e. no bound
    inside = np.minimum(np.maximum(np.fmin(b, 1.0) - np.fmax(a, 0.0), 0.0), 1.0)
    flat = (yl > lo) & (yl < hi)
    return np.where(d == 0, flat.astype(np.float64), inside)


@dataclass
class PhaseMap:
    """Per panel (capture or method), per cell and luminance, the exact functions of phase reduced to KPIs.

    Arrays are (C, L) unless stated (C cells, L luminances); values in reference e- (the ``gt`` units).

    Attributes:
        gt: (C, L) flicker-free ground truth.
        off: {panel: scalar} the value with the LED OFF (background only): the FDI's x_off.
        vmin, vmax: {panel: (C, L)} infimum / supremum over phase.
        phase_min, phase_max: {panel: (C, L)} phase (s) where they are reached (a one-sided limit there).
        mean: {panel: (C, L)} mean over phase.
        mmp, fdi: {panel: (C, L)} share of phases inside the MMP band around the mean / above the FDI threshold.
        on_min, on_max: {capture: (C,)} captured ON fraction's min / max over phase (luminance-independent).
    """

    gt: np.ndarray
    off: dict
    vmin: dict
    vmax: dict
    phase_min: dict
    phase_max: dict
    mean: dict
    mmp: dict
    fdi: dict
    on_min: dict
    on_max: dict


def _crossing(yl, yr, level):
    """t in (0, 1) where the line yl -> yr meets ``level``; 1 where it does not (a zero-length piece)."""
    d = yr - yl
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (level - yl) / d
    return np.where((t > 0) & (t < 1) & np.isfinite(t), t, 1.0)


#: Relative tolerance of the linearity test of the methods outside :data:`EXACT_METHODS`.
LINEAR_RTOL = 1e-9
#: Merges that take the max or min of two captures: their maps need the crossings of capture pairs as well.
PAIRWISE_METHODS = frozenset({"exposure_select_bounded"})


def reduce_pieces(a: np.ndarray, b: np.ndarray, h: np.ndarray, pha: np.ndarray, phb: np.ndarray, g: np.ndarray,
                  n: int, delta: float, thr: float) -> tuple[np.ndarray, ...]:
    """KPIs of linear pieces grouped by (cell, luminance), in numpy (no compiled kernel: numba's import and
    start-up cost the command more than the whole reduction).

    Args:
        a, b: (P,) a piece's values at its start / end; h: (P,) its share of the period; pha, phb: (P,) the phases
            (s) of its ends; g: (P,) its group in [0, n); delta: MMP band; thr: FDI level (value units).

    Returns:
        (vmin, vmax, pmin, pmax, mean, mmp, fdi), each (n,): min / max over the pieces (the first piece's end where
        several reach it) and their phases, the phase mean, the MMP and FDI phase measures (:func:`band_measure`
        inside +-delta x mean and above ``thr``). A group without pieces: min inf, max -inf, measures 0, phases NaN.
    """
    g = np.asarray(g, np.int64)
    if g.size > 1 and np.any(g[1:] < g[:-1]):                  # group order; the pieces keep theirs inside a group
        o = np.argsort(g, kind="stable")
        a, b, h, pha, phb, g = a[o], b[o], h[o], pha[o], phb[o], g[o]
    out = [np.full(n, np.inf), np.full(n, -np.inf), np.full(n, np.nan), np.full(n, np.nan)] + [np.zeros(n)
                                                                                            for _ in range(3)]
    if g.size == 0:
        return tuple(out)
    first = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])       # each group's first piece
    grp = g[first]
    seg = np.repeat(np.arange(first.size), np.diff(np.r_[first, g.size]))   # piece -> its segment
    lo_a = a <= b
    hi_a = a >= b
    idx = np.arange(g.size)
    for k, (v, ph, red, fill) in enumerate(((np.where(lo_a, a, b), np.where(lo_a, pha, phb), np.fmin, np.inf),
                                            (np.where(hi_a, a, b), np.where(hi_a, pha, phb), np.fmax, -np.inf))):
        ext = red.reduceat(v, first)                            # NaN values are skipped, as the loop's < skipped them
        at = np.minimum.reduceat(np.where(v == ext[seg], idx, g.size), first)
        ok = at < g.size
        out[k][grp] = np.where(np.isnan(ext), fill, ext)
        out[k + 2][grp[ok]] = ph[at[ok]]
    mean = np.add.reduceat(h * (0.5 * (a + b)), first)
    out[4][grp] = mean
    m = mean[seg]
    out[5][grp] = np.add.reduceat(h * band_measure(a, b, m - delta * m, m + delta * m), first)
    out[6][grp] = np.add.reduceat(h * band_measure(a, b, np.float64(thr), np.float64(np.inf)), first)
    return tuple(out)


def _reduce(model, ya, yb, keep, h, pha, phb, g, n, off, delta, contrast, out, sl, L):
    """KPIs of the pieces (1-D arrays, grouped by ``g``) into ``out[...][p][sl]`` (shape (c, L))."""
    g = np.asarray(g, np.int64)
    # the panels share the pieces: put them in group order once (stable, as reduce_pieces would per panel)
    o = np.argsort(g, kind="stable") if g.size > 1 and np.any(g[1:] < g[:-1]) else None
    if o is not None:
        h, pha, phb, g = h[o], pha[o], phb[o], g[o]
    for p in keep:
        a = ya[p].numpy().reshape(-1).astype(np.float64, copy=False)
        b = yb[p].numpy().reshape(-1).astype(np.float64, copy=False)
        if o is not None:
            a, b = a[o], b[o]
        # s = (x - x_off) / x_off > c  <=>  x > x_off (1 + c) for x_off > 0; x_off = 0: x > 0 (s = inf)
        res = reduce_pieces(a, b, h, pha, phb, g, n, float(delta), float(off[p] * (1 + contrast)))
        for key, v in zip(("vmin", "vmax", "pmin", "pmax", "mean", "mmp", "fdi"), res):
            out[key][p][sl] = v.reshape(-1, L)


def off_values(model: SensorModel, methods: Mapping[str, Callable]) -> dict[str, float]:
    """Every panel's value with the LED OFF (background only, phase-independent; reference e-): the FDI's
    x_off, ``{panel: value}``."""
    bg = model.settings["background_cd_m2"]
    mu_off = {c.name: torch.tensor([c.rate * bg + c.dark_e], dtype=torch.float64) for c in model.captures}
    v_off, fl_off = capture_state(model, mu_off)
    return {k: float(v) for k, v in evaluate_panels(model, methods, v_off, fl_off).items()}


def phase_map(model: SensorModel, freqs_hz: np.ndarray, duties: np.ndarray, lums: np.ndarray,
              methods: Mapping[str, Callable], delta: float = 0.1, contrast: float = 0.1, max_depth: int = 24,
              chunk_cells: int = 1000) -> PhaseMap:
    """KPIs over every phase, exact (module docstring), for cells = ``freqs_hz`` x ``duties`` (flattened with the
    duty varying fastest) and each of ``lums`` (cd/m^2).

    Args:
        delta: MMP band (P2020 default 0.1). contrast: FDI threshold (P2020 default 0.1).
        max_depth: bisection depth for the methods outside :data:`EXACT_METHODS` (module docstring).
        chunk_cells: cells processed at once (bounds the memory).
    """
    f, d = grid_cells(freqs_hz, duties)
    lums = np.asarray(lums, np.float64)
    C, L = f.size, lums.size
    panels = model.names + list(methods)
    bg = model.settings["background_cd_m2"]
    off = off_values(model, methods)
    out = {k: {p: np.empty((C, L)) for p in panels} for k in ("vmin", "vmax", "pmin", "pmax", "mean", "mmp", "fdi")}
    on_min = {c.name: np.empty(C) for c in model.captures}
    on_max = {c.name: np.empty(C) for c in model.captures}
    groups = _group_windows(model)
    caps = model.captures
    n_caps = len(caps)
    pairwise = any(m in PAIRWISE_METHODS for m in methods)
    other_methods = {k: v for k, v in methods.items() if k not in EXACT_METHODS}
    for i0 in range(0, C, chunk_cells):
        sl = slice(i0, min(C, i0 + chunk_cells))
        T = 1.0 / f[sl][:, None]
        D = d[sl][:, None]
        B = breakpoints(model, T, D)                                     # (c, K+1)
        frac = {g: on_fraction(cap, B, T, D) for g, cap in groups.items()}
        for c in caps:
            fr = frac[c.group][:, :-1]
            on_min[c.name][sl] = fr.min(axis=1)
            on_max[c.name][sl] = fr.max(axis=1)
        lum = lums[None, :, None]
        mu = {c.name: c.rate * (lum * frac[c.group][:, None, :] + bg) + c.dark_e for c in caps}  # (c, L, K+1)
        ml = {k: v[..., :-1] for k, v in mu.items()}
        mr = {k: v[..., 1:] for k, v in mu.items()}
        cand = []
        for c in caps:
            cand += [_crossing(ml[c.name], mr[c.name], c.clip_e), _crossing(ml[c.name], mr[c.name], c.sat_e)]
        if pairwise:
            lin_l = {c.name: (ml[c.name] - c.dark_e) * c.refer for c in caps}
            lin_r = {c.name: (mr[c.name] - c.dark_e) * c.refer for c in caps}
            clip = {c.name: (c.clip_e - c.dark_e) * c.refer for c in caps}
            for i in range(n_caps):
                for j in range(i + 1, n_caps):
                    a, b = caps[i].name, caps[j].name
                    cand.append(_crossing(lin_l[a] - lin_l[b], lin_r[a] - lin_r[b], 0.0))
                    cand.append(_crossing(lin_l[a], lin_r[a], clip[b]))
                    cand.append(_crossing(lin_l[b], lin_r[b], clip[a]))
        shp = ml[caps[0].name].shape                                      # (c, L, K)
        ts = np.concatenate([np.zeros(shp + (1,)), *(x[..., None] for x in cand), np.ones(shp + (1,))], axis=-1)
        ts.sort(axis=-1)
        ta, tb = ts[..., :-1], ts[..., 1:]
        width = np.broadcast_to((B[:, 1:] - B[:, :-1])[:, None, :, None], ta.shape)
        live = (tb > ta) & (width > 0)
        ci, li, ki, _ = np.nonzero(live)                                  # pieces in (cell, lum, interval) order
        ta, tb = ta[live], tb[live]
        nc = B.shape[0]
        g = ci * L + li
        Tc = T[ci, 0]
        w = (B[ci, ki + 1] - B[ci, ki])
        start = B[ci, ki]
        mlf = {k: v[ci, li, ki] for k, v in ml.items()}
        mrf = {k: v[ci, li, ki] for k, v in mr.items()}
        rep0 = np.arange(ta.size)

        def state(t, rep):
            v, fl = capture_state(model, {c.name: torch.from_numpy(mlf[c.name][rep] + (mrf[c.name][rep]
                                                                                        - mlf[c.name][rep]) * t)
                                          for c in caps})
            return v, fl

        _, flags0 = state(0.5 * (ta + tb), rep0)           # the flags are constant on every exact piece

        def reduce(ya, yb, keep, ta2, tb2, rep):
            h = (tb2 - ta2) * w[rep] / Tc[rep]                                            # share of the period
            pha = np.mod(start[rep] + ta2 * w[rep], Tc[rep])
            phb = np.mod(start[rep] + tb2 * w[rep], Tc[rep])
            _reduce(model, ya, yb, keep, h, pha, phb, g[rep], nc * L, off, delta, contrast, out, sl, L)

        va, _ = state(ta, rep0)
        vb, _ = state(tb, rep0)
        # every panel on the end values at once; the bisected merges then share the capture states of each depth
        ya = evaluate_panels(model, methods, va, flags0)
        yb = evaluate_panels(model, methods, vb, flags0)
        reduce(ya, yb, [p for p in ya if p not in other_methods], ta, tb, rep0)
        if other_methods:
            _bisect(model, other_methods, state, flags0, ta, tb, rep0, ya, yb, max_depth, reduce)
    gt = model.gt_rate * (lums[None, :] * d[:, None] + bg)
    return PhaseMap(gt, off, out["vmin"], out["vmax"], out["pmin"], out["pmax"], out["mean"], out["mmp"], out["fdi"],
                    on_min, on_max)


def _bisect(model, methods, state, flags0, ta, tb, rep, ya, yb, max_depth, reduce):
    """Pieces of the merges outside :data:`EXACT_METHODS`, halved where not linear (module docstring), reduced.

    All merges are bisected together: one capture state per depth, at the midpoints of the pieces that some merge
    still finds non-linear (their union); each merge is evaluated there and keeps only its own non-linear pieces.

    Args:
        methods: the merges to bisect. state: ``state(t, rows) -> (values, flags)`` of the chunk.
        flags0: (N, P) saturated flags of the pieces (constant on every piece).
        ta, tb: (P,) piece ends (share of the breakpoint interval); rep: (P,) the pieces' rows in the chunk.
        ya, yb: {merge: (P,) tensor} the values at ``ta`` / ``tb``.
        reduce: ``reduce(ya, yb, panels, ta, tb, rows)`` of :func:`phase_map`.
    """
    names = list(methods)
    live = {m: np.arange(ta.size) for m in names}                 # per merge: its pieces among (ta, tb, rep)
    ends = {m: (ya[m].numpy(), yb[m].numpy()) for m in names}     # and their end values
    done = {m: [] for m in names}                                 # pieces found linear
    for depth in range(max_depth + 1):
        mark = np.zeros(ta.size, bool)                            # the union of the sorted index sets, sorted
        for m in names:
            mark[live[m]] = True
        union = np.flatnonzero(mark)
        if union.size == 0:
            break
        if depth == max_depth:
            for m in names:
                done[m].append((ta[live[m]], tb[live[m]], *ends[m], rep[live[m]]))
            break
        tm = 0.5 * (ta[union] + tb[union])
        vm, _ = state(tm, rep[union])
        ym_all = evaluate_panels(model, methods, vm, flags0[:, rep[union]])
        n_u = union.size
        for m in names:
            idx = live[m]
            j = np.searchsorted(union, idx)                       # the piece's place in the union
            ym = ym_all[m].numpy()[j]
            ya_, yb_ = ends[m]
            scale = np.maximum(np.maximum(np.abs(ya_), np.abs(yb_)), np.maximum(np.abs(ym), 1.0))
            lin = np.abs(ym - 0.5 * (ya_ + yb_)) <= LINEAR_RTOL * scale
            done[m].append((ta[idx[lin]], tb[idx[lin]], ya_[lin], yb_[lin], rep[idx[lin]]))
            nl = ~lin
            live[m] = np.concatenate([j[nl], j[nl] + n_u])        # left halves, then right halves
            ends[m] = (np.concatenate([ya_[nl], ym[nl]]), np.concatenate([ym[nl], yb_[nl]]))
        ta = np.concatenate([ta[union], tm])
        tb = np.concatenate([tm, tb[union]])
        rep = np.concatenate([rep[union], rep[union]])
    for m in names:
        cat = [np.concatenate([x[k] for x in done[m]]) for k in range(5)]
        reduce({m: torch.from_numpy(cat[2])}, {m: torch.from_numpy(cat[3])}, [m], cat[0], cat[1], cat[4])
