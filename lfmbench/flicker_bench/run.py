"""The bench run: grid checks, all KPIs of every panel, tables (CSV, JSON with the preset's hash), heat maps and
the one-page report (``lfmbench flicker-bench``; docs/guide/flicker-bench.md).

Panels: every capture of the plan, then every applicable fusion method: the architecture's standard merge and the
other registered rule-based methods of :func:`lfmbench.baselines.methods_for` that run on one frame of a flat
target (the sequence method ``temporal`` and the learned ones, which need a trained checkpoint, are left out),
plus any method the user names.

Over 500 lines as one job: a bench run and the outputs that read its result (tables, maps, report), which share
the result's layout (cells frequency-major, duty fastest; the worst over the luminances) and are tested together.
"""
from __future__ import annotations

import json
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import torch

from lfmbench.flicker_bench.exact import EXACT_METHODS, SEQUENCE_METHODS, capture_state, evaluate_panels, \
    off_values, phase_map
from lfmbench.flicker_bench.model import BenchError, MAX_FREQUENCY_HZ, MIN_FREQUENCY_HZ, SensorModel
from lfmbench.flicker_bench.sequence import frames_to_cover, sequence_kpis, sequence_series
from lfmbench.fileio import atomic_save_figure, atomic_write_text, json_default

__all__ = ["BENCH_VERSION", "Grid", "default_grid", "check_grid", "bench_methods", "BenchResult", "run_bench",
           "write_tables", "worst_columns", "format_values", "WORST_RULES", "TABLE_MODES", "plot_maps", "write_report",
           "DROPOUT_FRACTION"]

#: Version of the bench's definitions (grid defaults, KPI columns, table layout); bumped when any changes. v2: the
#: default tables hold each KPI's worst over the luminances (``--tables worst``); v1's per-luminance rows are
#: ``--tables full``.
BENCH_VERSION = "2"
#: A light counts as missed at a phase when the output is below this share of its steady-light value
#: (the dropout threshold of lfmbench.metrics.flicker, ISET-LFM Fig. 5).
DROPOUT_FRACTION = 0.5
#: A merge whose steady-light value exceeds the ground truth by more than this factor gets a note in the report
#: (its "missed" cells can be a drop from that too-bright value to about the truth).
STEADY_BIAS = 1.5
#: Most grid values per axis (bounds time and memory).
MAX_AXIS = 2000


@dataclass
class Grid:
    """The bench grid: PWM frequencies (Hz), duties (1), LED ON luminances (cd/m^2)."""

    freqs_hz: np.ndarray
    duties: np.ndarray
    lums: np.ndarray


def default_grid(model: SensorModel, n_freq: int = 200, extra_freqs: Sequence[float] = (),
                 duties: Sequence[float] | None = None, lums: Sequence[float] | None = None, n_lum: int = 10) -> Grid:
    """200 log-spaced frequencies 50 Hz - 2 kHz plus ``extra_freqs``; duties 1, 2, 5, 10, 15, ..., 90 % (20);
    10 luminances log-spaced from 1/100 of the first capture saturation to 10x the last (steady light), so that
    every capture's saturation lies inside the range."""
    f = np.geomspace(50.0, 2000.0, n_freq) if n_freq else np.zeros(0)
    f = np.unique(np.concatenate([f, np.asarray(list(extra_freqs), np.float64)]))
    d = np.asarray(duties if duties is not None else [0.01, 0.02, 0.05, *np.round(np.arange(0.1, 0.901, 0.05), 2)],
                   np.float64)
    if lums is None:
        sat = [v for v in model.saturation_luminance().values() if math.isfinite(v) and v > 0]
        lo, hi = (min(sat) / 100.0, max(sat) * 10.0) if sat else (1.0, 1e5)
        lv = np.geomspace(lo, hi, n_lum)
    else:
        lv = np.asarray(list(lums), np.float64)
    return Grid(f, d, lv)


def check_grid(grid: Grid) -> Grid:
    """Frequencies in the model's range (> 0 and within [1 Hz, 1 MHz], :data:`MIN_FREQUENCY_HZ`), duties in
    (0, 1], luminances > 0, every axis non-empty and at most :data:`MAX_AXIS` long; :class:`BenchError` names the
    option."""
    for name, arr in (("--freq", grid.freqs_hz), ("--duty", grid.duties), ("--luminance", grid.lums)):
        a = np.asarray(arr, np.float64)
        if a.size == 0:
            raise BenchError(f"{name}: no value")
        if a.size > MAX_AXIS:
            raise BenchError(f"{name}: {a.size} values, at most {MAX_AXIS}")
        if not np.all(np.isfinite(a)):
            raise BenchError(f"{name}: every value must be a finite number")
    f = np.asarray(grid.freqs_hz, np.float64)
    if np.any(f <= 0):
        raise BenchError(f"--freq: frequencies must be > 0 Hz, got {f[f <= 0][0]:g}")
    if np.any(f < MIN_FREQUENCY_HZ) or np.any(f > MAX_FREQUENCY_HZ):
        bad = f[(f < MIN_FREQUENCY_HZ) | (f > MAX_FREQUENCY_HZ)][0]
        raise BenchError(f"--freq: {bad:g} Hz is outside what the PWM model supports, [{MIN_FREQUENCY_HZ:g}, "
                         f"{MAX_FREQUENCY_HZ:g}] Hz (periods 1 us to 1 s)")
    d = np.asarray(grid.duties, np.float64)
    if np.any(d <= 0) or np.any(d > 1):
        raise BenchError(f"--duty: duty cycles must be in (0, 1], got {d[(d <= 0) | (d > 1)][0]:g}")
    if np.any(np.asarray(grid.lums) <= 0):
        raise BenchError("--luminance: luminances must be > 0 cd/m^2")
    return Grid(np.unique(f), np.unique(d), np.unique(np.asarray(grid.lums, np.float64)))


def bench_methods(model: SensorModel, extra: Sequence[str] = ()) -> dict[str, Callable]:
    """The applicable fusion methods (module docstring) by name, resolved through the baselines registry."""
    from lfmbench.baselines import LEARNED, REGISTRY, MethodNotFoundError, get_method, methods_for

    rule_based = {m for m in REGISTRY if m not in LEARNED}  # the rules; learned ones need a checkpoint
    names = [m for m in methods_for(model.preset.architecture) if m in rule_based and m not in SEQUENCE_METHODS]
    out = {m: REGISTRY[m] for m in names}
    for spec in extra:
        try:
            out[spec] = get_method(spec)
        except MethodNotFoundError as exc:
            raise BenchError(f"--method: {exc}") from None
    return out


@dataclass
class BenchResult:
    """All KPIs of one bench run; arrays (C, L) per panel with C = frequencies x duties (duty fastest).

    ``timings_s`` per stage: wall time (``<stage>_s``) and CPU time, user + system of this process over all its
    threads (``<stage>_cpu_s``), both in s."""

    model: SensorModel
    grid: Grid
    panels: list[str]
    exact: dict[str, bool]
    columns: dict[str, dict[str, np.ndarray]]
    cover: np.ndarray
    timings_s: dict[str, float] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)
    measured: list[dict] = field(default_factory=list)


def steady_values(model: SensorModel, duties: np.ndarray, lums: np.ndarray, methods) -> dict[str, np.ndarray]:
    """Each panel's value for a steady light of the same mean (ON fraction = D at every phase): (ND, L)."""
    bg = model.settings["background_cd_m2"]
    mu = {c.name: torch.from_numpy(c.rate * (lums[None, :] * duties[:, None] + bg) + c.dark_e)
          for c in model.captures}
    vals, flags = capture_state(model, mu)
    return {k: v.numpy() for k, v in evaluate_panels(model, methods, vals, flags).items()}


def sequences(model: SensorModel, grid: Grid, methods: Mapping[str, Callable], frames: int, phase0_s: float,
              off: Mapping[str, float], delta: float, contrast: float) -> tuple[dict, dict[str, float]]:
    """The sequence KPIs of every panel (``sequence_kpis`` of ``sequence_series``: {panel: {kpi: (C, L)}}) and
    their wall and CPU time in s (``sequence_s``, ``sequence_cpu_s``; CPU of the process running them)."""
    t0, c0 = time.perf_counter(), time.process_time()
    series = sequence_series(model, grid.freqs_hz, grid.duties, grid.lums, methods, frames, phase0_s)
    seq = sequence_kpis(series, off, delta, contrast)
    return seq, {"sequence_s": time.perf_counter() - t0, "sequence_cpu_s": time.process_time() - c0}


def start_sequences(*args):
    """:func:`sequences` (same arguments) started in a forked process beside the caller, which meanwhile computes
    the phase map on its other core(s) (:func:`lfmbench.parallel.start_forked`); returns the function that waits
    for ``sequences``' result, or None where no process started.

    The child computes with one torch thread: then torch enters no OpenMP parallel region in it (a forked child
    must not where the parent has already run one: GNU OpenMP's thread pool does not survive ``fork``)."""
    from lfmbench.parallel import start_forked  # noqa: PLC0415

    def child():
        torch.set_num_threads(1)
        return sequences(*args)

    return start_forked(child, "the process computing the flicker-bench sequences")


def run_bench(model: SensorModel, grid: Grid, methods: Mapping[str, Callable], *, frames: int = 100,
              phase0_s: float = 0.0, cover_tol: float = 0.01, noise_draws: int = 0, roi_px: int = 4, seed: int = 0,
              delta: float = 0.1, contrast: float = 0.1, max_depth: int = 24, fork: bool = True) -> BenchResult:
    """Every KPI of every panel over the grid (module docstrings of ``exact``, ``sequence``, ``noise``).

    The sequences are computed in a forked process beside the phase map where two or more CPUs are usable
    (:func:`start_sequences`; ``fork=False``: all in this process); the results are the same.

    Args:
        frames: N frames of the sequence KPIs (>= 2); phase0_s: the LED phase in frame 0 (s).
        cover_tol: phase gap (share of the period) for the frames-to-cover column.
        noise_draws: Monte Carlo frames per cell (0: no noise columns); roi_px: pixels in the ROI mean.
    """
    grid = check_grid(grid)
    if not isinstance(frames, int) or frames < 2:
        raise BenchError(f"--frames must be an integer >= 2, got {frames!r}")
    if not 0 < cover_tol <= 1:
        raise BenchError(f"--cover-tol must be in (0, 1], got {cover_tol!r}")
    if noise_draws < 0 or roi_px < 1:
        raise BenchError("--noise-draws must be >= 0 and --roi-px >= 1")
    t = {}
    off = off_values(model, methods)
    seq_args = (model, grid, methods, frames, phase0_s, off, delta, contrast)
    wait = start_sequences(*seq_args) if fork else None
    threads = torch.get_num_threads()
    if wait is not None:                  # the child holds one core: the map's torch operations the others
        torch.set_num_threads(max(1, threads - 1))
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        pm = phase_map(model, grid.freqs_hz, grid.duties, grid.lums, methods, delta, contrast, max_depth)
        t["phase_map_s"], t["phase_map_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
        panels = model.names + list(methods)
        L = grid.lums.size
        steady = steady_values(model, grid.duties, grid.lums, methods)
        t0 = time.perf_counter()
        seq, seq_t = wait() if wait is not None else sequences(*seq_args)
        t["sequence_wait_s"] = time.perf_counter() - t0
        t.update(seq_t)
    finally:
        torch.set_num_threads(threads)
    t0 = time.perf_counter()
    cover = np.array([np.nan if (n := frames_to_cover(model.frame_time_s, f, cover_tol)) is None else n
                      for f in grid.freqs_hz], np.float64)
    t["cover_s"] = time.perf_counter() - t0
    cols: dict[str, dict[str, np.ndarray]] = {}
    for p in panels:
        st = np.tile(steady[p], (grid.freqs_hz.size, 1))                                  # (C, L)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = {"gt_e": pm.gt, "steady_e": st, "min_e": pm.vmin[p], "max_e": pm.vmax[p],
                 "rel_min": pm.vmin[p] / st, "rel_max": pm.vmax[p] / st,
                 "worst_phase_s": pm.phase_min[p], "best_phase_s": pm.phase_max[p],
                 "fmi_all": (pm.vmax[p] - pm.vmin[p]) / (pm.vmax[p] + pm.vmin[p]),
                 "mmp_all": pm.mmp[p], "fdi_all": pm.fdi[p],
                 "fmi_seq": seq[p]["fmi"], "mmp_seq": seq[p]["mmp"], "fdi_seq": seq[p]["fdi"]}
        if p in pm.on_min:
            c["on_frac_min"] = np.repeat(pm.on_min[p][:, None], L, axis=1)
            c["on_frac_max"] = np.repeat(pm.on_max[p][:, None], L, axis=1)
        cols[p] = c
    if noise_draws:
        from lfmbench.flicker_bench.noise import noise_kpis

        t0, c0 = time.perf_counter(), time.process_time()
        nk = noise_kpis(model, grid.freqs_hz, grid.duties, grid.lums, methods, pm.off, noise_draws, roi_px, seed,
                        delta, contrast)
        t["noise_s"], t["noise_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
        for p in panels:
            for k, v in nk[p].items():
                cols[p][f"{k}_noisy" if k in ("fmi", "mmp", "fdi") else k] = v
    exact = {p: (p in model.names or p in EXACT_METHODS) for p in panels}
    opts = {"frames": frames, "phase0_s": phase0_s, "cover_tol": cover_tol, "noise_draws": noise_draws,
            "roi_px": roi_px, "seed": seed, "delta": delta, "contrast": contrast, "max_depth": max_depth,
            "off_e": pm.off}
    return BenchResult(model, grid, panels, exact, cols, cover, t, opts)


# ------------------------------------------------------------------------------------------------- tables
def _header(res: BenchResult) -> dict[str, Any]:
    m = res.model
    return {"bench_version": BENCH_VERSION, "preset": m.preset.name, "preset_source": str(m.preset.source),
            "preset_sha256": m.preset_sha256, "architecture": m.preset.architecture, "settings": dict(m.settings),
            "options": res.options, "units": {"*_e": "e- of the reference capture (the gt units)",
                                              "frequency_hz": "Hz", "luminance_cd_m2": "cd/m^2",
                                              "*_phase_s": "s from the frame start to an LED rising edge"},
            "panels": {p: ("exact" if res.exact[p] else f"bisected (max_depth={res.options['max_depth']})")
                       for p in res.panels}}


def _quote(s: str) -> str:
    """A CSV field: quoted (RFC 4180) where it holds a comma, a quote or a line break."""
    return '"' + s.replace('"', '""') + '"' if any(ch in s for ch in ',"\n\r') else s


def format_values(a: np.ndarray, sep: str = ",", nonfinite: str = "") -> list[str]:
    """Rows of a 2-D float array as text, ``"%.7g"`` per value joined by ``sep``, non-finite values as
    ``nonfinite``: formatted by one C-level ``%`` over the whole array (one call per value, or ``np.savetxt``, is
    about 10x slower for the bench's millions of values). Returns one string per row."""
    a = np.asarray(a, np.float64)
    n, k = a.shape
    if not n:
        return []
    if not k:
        return [""] * n
    text = ((sep.join(["%.7g"] * k) + "\n") * n) % tuple(a.ravel().tolist())
    # "%.7g" writes NaN as "nan" and the infinities as "inf"/"-inf"; the other tokens are digits, '.', 'e', signs
    text = text.replace("-inf", "inf").replace("inf", nonfinite).replace("nan", nonfinite)
    return text.split("\n")[:-1]


def _json_array(a: np.ndarray) -> str:
    """Compact JSON text of a 1-D or 2-D float array: 7 significant digits, non-finite values as null."""
    a = np.asarray(a, np.float64)
    if a.ndim == 1:
        return "[" + (format_values(a[None, :], nonfinite="null")[0] if a.size else "") + "]"
    return "[" + ",".join("[" + r + "]" for r in format_values(a, nonfinite="null")) + "]"


#: Worst over the luminances, per KPI of the compact table: "min" (lower is worse), "max" (higher is worse), or
#: the name of the KPI whose worst luminance the value is taken at.
WORST_RULES: dict[str, str] = {
    "rel_min": "min", "rel_max": "max", "worst_phase_s": "rel_min",
    "fmi_all": "max", "mmp_all": "min", "fdi_all": "min", "fmi_seq": "max", "mmp_seq": "min", "fdi_seq": "min",
    "on_frac_min": "min", "on_frac_max": "max",
    "fmi_noisy": "max", "mmp_noisy": "min", "mmp_lo": "mmp_noisy", "mmp_hi": "mmp_noisy", "mmp_floor": "mmp_noisy",
    "fdi_noisy": "min", "fmi_floor": "max"}
#: Output tables of ``write_tables``: ``worst`` (default), ``full`` (every luminance) or ``none``.
TABLE_MODES = ("worst", "full", "none")


def worst_columns(res: BenchResult, p: str) -> dict[str, np.ndarray]:
    """Panel ``p``'s KPIs reduced over the luminances by :data:`WORST_RULES`, each (C,) (cells frequency-major,
    duty fastest), plus ``worst_luminance_cd_m2``: the luminance (cd/m^2) of the lowest ``rel_min`` (the first
    where several tie). NaN where a KPI is NaN at every luminance."""
    cols = res.columns[p]
    lums = res.grid.lums
    out: dict[str, np.ndarray] = {}

    def arg(key: str, rule: str) -> np.ndarray:
        a = np.asarray(cols[key], np.float64)
        fill = np.inf if rule == "min" else -np.inf
        z = np.where(np.isfinite(a), a, fill)
        return np.argmin(z, axis=1) if rule == "min" else np.argmax(z, axis=1)

    rows = np.arange(res.grid.freqs_hz.size * res.grid.duties.size)
    for key, rule in WORST_RULES.items():
        if key not in cols:
            continue
        a = np.asarray(cols[key], np.float64)
        if rule in ("min", "max"):
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)          # all-NaN rows stay NaN, quietly
                out[key] = np.nanmin(a, axis=1) if rule == "min" else np.nanmax(a, axis=1)
        else:
            out[key] = a[rows, arg(rule, WORST_RULES[rule])]
    out["worst_luminance_cd_m2"] = lums[arg("rel_min", "min")]
    return out


def write_tables(res: BenchResult, out_dir: Path, mode: str = "worst") -> list[Path]:
    """The bench's tables in ``out_dir``, written atomically (the layout: docs/guide/flicker-bench.md).

    ``mode="worst"`` (default): ``flicker_bench.csv`` with one row per panel, frequency and duty, each KPI its worst
    over the luminances (:func:`worst_columns`), and ``flicker_bench.json`` with the same as (C,) arrays per
    panel and KPI. ``mode="full"``: one CSV row per panel, frequency, duty and luminance, and every KPI as a
    (C, L) array in the JSON. ``mode="none"``: nothing. Both files begin with the preset's name and SHA-256 (the
    CSV in a ``#`` comment line); values have 7 significant digits, empty (CSV) or null (JSON) where not finite.
    """
    if mode not in TABLE_MODES:
        raise BenchError(f"--tables must be one of {', '.join(TABLE_MODES)}, got {mode!r}")
    if mode == "none":
        return []
    full = mode == "full"
    head = _header(res)
    F, D = res.grid.freqs_hz.size, res.grid.duties.size
    data = {p: (res.columns[p] if full else worst_columns(res, p)) for p in res.panels}
    keys = sorted({k for c in data.values() for k in c})
    f_txt = [f"{v:.9g}" for v in np.repeat(res.grid.freqs_hz, D)]
    d_txt = [f"{v:.6g}" for v in np.tile(res.grid.duties, F)]
    c_txt = ["" if math.isnan(v) else str(int(v)) for v in np.repeat(res.cover, D)]
    cells = [f"{a},{b},{c}" for a, b, c in zip(f_txt, d_txt, c_txt)]          # frequency, duty, frames_to_cover
    if full:
        l_txt = [f"{v:.6g}" for v in res.grid.lums]
        cells = [f"{a},{b},{lt},{c}" for a, b, c in zip(f_txt, d_txt, c_txt) for lt in l_txt]
    n_rows = len(cells)
    parts = [f"# lfmbench flicker-bench v{BENCH_VERSION}: preset {head['preset']} sha256 {head['preset_sha256']} "
             f"tables {mode}\n",
             ",".join(["panel", "frequency_hz", "duty", *(["luminance_cd_m2"] if full else []), "frames_to_cover",
                       *keys]) + "\n"]
    for p in res.panels:
        c = data[p]
        vals = np.stack([np.asarray(c[k], np.float64).reshape(n_rows) if k in c else np.full(n_rows, math.nan)
                         for k in keys], axis=1)                                        # (rows, keys)
        q = _quote(p)
        parts.append("".join([f"{q},{a},{b}\n" for a, b in zip(cells, format_values(vals))]))
    out = [out_dir / "flicker_bench.csv", out_dir / "flicker_bench.json"]
    atomic_write_text(out[0], "".join(parts))
    doc = {**head, "tables": mode,
           "grid": {"frequency_hz": res.grid.freqs_hz, "duty": res.grid.duties, "luminance_cd_m2": res.grid.lums,
                    "cells": "frequency-major, duty fastest"},
           "frames_to_cover": [None if math.isnan(v) else int(v) for v in res.cover],
           "measured": res.measured, "timings_s": res.timings_s}
    if not full:
        doc["worst_over_luminance"] = {k: ("lowest" if r == "min" else "highest" if r == "max"
                                           else f"at the luminance of the worst {r}") for k, r in WORST_RULES.items()}
        doc["worst_over_luminance"]["worst_luminance_cd_m2"] = "the luminance of the lowest rel_min"
    # compact; the header by the C encoder (strict: no NaN or inf), the KPI arrays formatted in bulk
    kpis = "{" + ",".join(json.dumps(p) + ":{" + ",".join(json.dumps(k) + ":" + _json_array(v)
                                                           for k, v in data[p].items()) + "}"
                          for p in res.panels) + "}"
    text = json.dumps(doc, allow_nan=False, separators=(",", ":"), default=json_default)
    atomic_write_text(out[1], text[:-1] + ',"kpis":' + kpis + "}\n")
    return out


# ------------------------------------------------------------------------------------------------- figures
def panel_worst(res: BenchResult, p: str, key: str, lum_index: int | None = None) -> np.ndarray:
    """(frequencies, duties) map of ``key`` for panel ``p``: its worst value over the luminances (lowest for
    ``rel_min`` / ``mmp*``, highest for ``fmi*``), or at one luminance."""
    a = res.columns[p][key].reshape(res.grid.freqs_hz.size, res.grid.duties.size, -1)
    if lum_index is not None:
        return a[..., lum_index]
    with np.errstate(invalid="ignore"):
        return np.nanmax(a, axis=-1) if key.startswith("fmi") else np.nanmin(a, axis=-1)


def never_missed(res: BenchResult, p: str, min_duty: float = 0.1) -> np.ndarray:
    """Per frequency, whether panel ``p`` never misses the light (output >= DROPOUT_FRACTION of its steady value
    at every phase, every luminance and every duty >= ``min_duty``)."""
    m = panel_worst(res, p, "rel_min")[:, res.grid.duties >= min_duty - 1e-12]
    return np.all(m >= DROPOUT_FRACTION, axis=1)


def freq_ranges(freqs: np.ndarray, ok: np.ndarray) -> str:
    """``"90-2000 Hz"``-style text of the frequencies where ``ok`` holds."""
    parts, i = [], 0
    while i < ok.size:
        if ok[i]:
            j = i
            while j + 1 < ok.size and ok[j + 1]:
                j += 1
            parts.append(f"{freqs[i]:.0f}" if i == j else f"{freqs[i]:.0f}-{freqs[j]:.0f}")
            i = j + 1
        else:
            i += 1
    return (", ".join(parts) + " Hz") if parts else "none"


def plot_maps(res: BenchResult, out_dir: Path, stem: str = "flicker_bench", measured: Sequence[dict] = (),
              meanwhile: Callable[[], Any] | None = None) -> tuple[list[Path], Any]:
    """Two heat-map PNGs (frequency x duty, one panel per capture or method, worst case over the luminances and
    marked): ``<stem>_miss.png`` (worst output over phase / steady value; hatched where the light is missed, a bar
    under each panel for the frequencies never missed at duty >= 10 %) and ``<stem>_mmp.png`` (noise-free MMP over
    every phase). Measured captures are drawn as circles in their measured value's colour.

    ``meanwhile()`` runs in this process while the second figure is drawn in a forked one (the command writes its
    tables there). Returns (the two paths, what ``meanwhile`` returned, or None)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm
    from matplotlib.ticker import FixedFormatter, FixedLocator, NullLocator

    f, d = res.grid.freqs_hz, res.grid.duties
    n = len(res.panels)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    specs = [("miss", "rel_min", "worst output over phase / steady value (min over luminance)",
              [0, 0.1, 0.25, 0.5, 0.75, 0.9, 0.97, 1.0001], "RdYlGn"),
             ("mmp", "mmp_all", "MMP over every phase, noise-free (min over luminance)",
              [0, 0.1, 0.25, 0.5, 0.75, 0.9, 0.99, 1.0001], "viridis")]
    fe = np.geomspace(f[0], f[-1], f.size + 1) if f.size > 1 else np.array([f[0] * 0.9, f[0] * 1.1])
    if f.size > 1:
        lf = np.log(f)
        mid = np.exp(0.5 * (lf[1:] + lf[:-1]))
        fe = np.concatenate([[np.exp(2 * lf[0] - np.log(mid[0]))], mid, [np.exp(2 * lf[-1] - np.log(mid[-1]))]])
    de = np.concatenate([[d[0] - (d[1] - d[0]) / 2 if d.size > 1 else d[0] * 0.5],
                         (d[1:] + d[:-1]) / 2, [d[-1] + (d[-1] - d[-2]) / 2 if d.size > 1 else d[0] * 1.5]])
    de = np.clip(de, 0.0, 1.0)
    xt = [v for v in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 1e4, 2e4, 5e4, 1e5, 2e5, 5e5, 1e6)
          if fe[0] <= v <= fe[-1]] or [float(f[0])]
    def draw(spec) -> Path:
        stem_key, key, title, bounds, cmap_name = spec
        # fixed margins in inches (tight_layout measured every text of every panel: seconds per figure): 1.15 in
        # for the titles above, 0.5 in for the axis labels below, panels 1.6 in high with gaps for their titles
        gap = 1.0 if stem_key == "miss" else 0.8
        height = 1.15 + 0.5 + rows * 1.6 + (rows - 1) * gap
        fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, height), squeeze=False, sharex=True, sharey=True)
        cmap = plt.get_cmap(cmap_name, len(bounds) - 1)
        norm = BoundaryNorm(bounds, cmap.N)
        im = None
        for k, p in enumerate(res.panels):
            ax = axes[k // cols][k % cols]
            z = panel_worst(res, p, key)                                                 # (F, D)
            im = ax.pcolormesh(fe, de, z.T, cmap=cmap, norm=norm, shading="flat", rasterized=True)
            if stem_key == "miss":
                ax.contourf(f, d, (z < DROPOUT_FRACTION).T.astype(float), levels=[0.5, 1.5], colors="none",
                            hatches=["////"])
                # the never-missed bar: one rectangle per run of equal frequencies (not one per frequency)
                ok = never_missed(res, p)
                cut = np.flatnonzero(np.diff(ok.astype(np.int8))) + 1
                for a, b in zip(np.r_[0, cut], np.r_[cut, ok.size]):
                    ax.axvspan(fe[a], fe[b], ymin=1.0, ymax=1.07, color="tab:green" if ok[a] else "black",
                               clip_on=False, lw=0)
            zz = np.where(np.isfinite(z), z, np.inf if stem_key != "fmi" else -np.inf)
            i, j = np.unravel_index(np.argmin(zz), zz.shape)
            ax.plot(f[i], d[j], marker="*", ms=11, mfc="white", mec="black")
            ax.set_xscale("log")
            # labelled frequencies, no minor ticks (matplotlib builds every log-axis minor tick of every panel)
            ax.xaxis.set_major_locator(FixedLocator(xt))
            ax.xaxis.set_major_formatter(FixedFormatter([f"{v:g}" for v in xt]))
            ax.xaxis.set_minor_locator(NullLocator())
            kind = "capture" if p in res.model.names else ("merge" if res.exact[p] else "merge, bisected")
            ax.set_title(f"{p} ({kind})\nworst {z[i, j]:.2f} at {f[i]:.0f} Hz, D={d[j]:.2f}", fontsize=8,
                         y=1.08 if stem_key == "miss" else 1.0, pad=3)   # a fixed y: no automatic placement
            for mrec in measured:
                if mrec.get("panel") == p:
                    v = mrec["rel_min_measured"] if stem_key == "miss" else mrec["mmp_measured"]
                    ax.scatter([mrec["frequency_hz"]], [mrec["duty"]], c=[v], cmap=cmap, norm=norm, s=55,
                               edgecolors="black", linewidths=1.2, zorder=5)
            ax.tick_params(labelsize=7)
        for k in range(n, rows * cols):
            axes[k // cols][k % cols].axis("off")
        for k in range(max(0, n - cols), n):            # the lowest panel of each column carries the frequency axis
            ax = axes[k // cols][k % cols]
            ax.xaxis.set_tick_params(labelbottom=True)
            ax.set_xlabel("PWM frequency [Hz]", fontsize=8)
        for ax in axes[:, 0]:
            ax.set_ylabel("duty", fontsize=8)
        note = ("\nhatched: missed (output < 0.5 x steady at some phase); bar above a panel: green = never missed "
                "at any duty >= 10 %" if stem_key == "miss" else "")
        fig.suptitle(f"{res.model.preset.name} ({res.model.preset.architecture}): {title}{note}\n"
                     f"star = worst cell; {res.model.frame_time_s * 1e3:.2f} ms frames, "
                     f"luminance {res.grid.lums[0]:.3g}-{res.grid.lums[-1]:.3g} cd/m^2", fontsize=7)
        fig.subplots_adjust(left=0.07 if cols > 1 else 0.15, right=0.91 if cols > 1 else 0.85, bottom=0.5 / height,
                            top=1.0 - 1.15 / height, wspace=0.12, hspace=gap / 1.6)
        cax = fig.add_axes((0.93, 0.15, 0.015, 0.7))
        fig.colorbar(im, cax=cax).ax.tick_params(labelsize=7)
        path = atomic_save_figure(fig, out_dir / f"{stem}_{stem_key}.png", dpi=80)
        plt.close(fig)
        return path

    # the second figure drawn in a forked process beside the first (1.5 s of the command's 10 s on 2 cores)
    from lfmbench.parallel import start_forked  # noqa: PLC0415

    waits = [(spec, start_forked(lambda spec=spec: draw(spec), "the process drawing the flicker-bench maps"))
             for spec in specs[1:]]
    other = meanwhile() if meanwhile is not None else None
    paths = [draw(specs[0])]
    for spec, wait in waits:
        if wait is None:
            paths.append(draw(spec))
        else:
            wait()
            paths.append(out_dir / f"{stem}_{spec[0]}.png")
    return paths, other


# ------------------------------------------------------------------------------------------------- report
def write_report(res: BenchResult, path: Path, images: Sequence[Path], image_base: Path | None = None) -> Path:
    """The one-page markdown report: settings, the maps, per panel the frequencies never missed and the worst
    cell, frames to cover every phase, measured captures; ``image_base``: the directory the image links are
    relative to (default the report's)."""
    import os

    m = res.model
    base = image_base or path.parent
    lines = [f"# Flicker bench: `{m.preset.name}` ({m.preset.architecture})", "",
             f"Generated by `lfmbench flicker-bench --sensor {m.preset.name}` (bench v{BENCH_VERSION}); preset SHA-256 "
             f"`{m.preset_sha256[:16]}...`. {m.preset.description}.", "",
             f"Grid: {res.grid.freqs_hz.size} PWM frequencies {res.grid.freqs_hz[0]:.0f}-{res.grid.freqs_hz[-1]:.0f} Hz "
             f"(log), {res.grid.duties.size} duties {res.grid.duties[0]:.2f}-{res.grid.duties[-1]:.2f}, "
             f"{res.grid.lums.size} LED luminances {res.grid.lums[0]:.3g}-{res.grid.lums[-1]:.3g} cd/m^2 "
             f"(background {m.settings['background_cd_m2']:g} cd/m^2); frame time {m.frame_time_s * 1e3:.3f} ms; "
             f"ROI {m.settings['roi_rows']} row(s). Every phase is covered exactly (breakpoints of the piecewise-linear "
             "exposure-vs-phase function); each map shows the worst luminance.", ""]
    lines += ["| capture | windows (ms from frame start) |", "|---|---|"]
    for c, w in m.settings["windows_s"].items():
        lines.append(f"| {c} | " + ", ".join(f"[{a * 1e3:.6g}, {(a + n) * 1e3:.6g})" for a, n in w) + " |")
    lines += ["", "## Which frequencies are never missed", "",
              "Never missed: at every phase, luminance and duty >= 10 % the output stays >= 50 % of its steady-light "
              "value (the dropout threshold).", "",
              "| panel | kind | never missed | worst output / steady (cell) | min MMP (all phases) |", "|---|---|---|---|---|"]
    for p in res.panels:
        z = panel_worst(res, p, "rel_min")
        i, j = np.unravel_index(np.nanargmin(z), z.shape)
        kind = "capture" if p in m.names else ("merge" if res.exact[p] else "merge (bisected)")
        mm = np.nanmin(res.columns[p]["mmp_all"])
        lines.append(f"| {p} | {kind} | {freq_ranges(res.grid.freqs_hz, never_missed(res, p))} | {z[i, j]:.2f} "
                     f"({res.grid.freqs_hz[i]:.0f} Hz, D={res.grid.duties[j]:.2f}) | {mm:.2f} |")
    lines.append("")
    biased = []
    for p in res.panels:
        if p in m.names:
            continue
        with np.errstate(invalid="ignore", divide="ignore"):
            r = res.columns[p]["steady_e"] / res.columns[p]["gt_e"]
        if np.any(r[np.isfinite(r)] > STEADY_BIAS):
            biased.append(f"{p} (up to {np.nanmax(r[np.isfinite(r)]):.2f}x)")
    if biased:
        lines += [f"Steady value above the ground truth: {', '.join(biased)}. Where such a merge's steady light lies "
                  "just above a capture's saturation flag, the phases that catch a little less light fall below the "
                  "flag and the merge answers from the other branch: its output drops to about the truth, below 0.5 x "
                  "the too-bright steady value, and the cell is marked missed though the output is not dark (a "
                  "stripe at one duty across many frequencies; the jump is a real flicker of the output).", ""]
    for im in images:
        lines += [f"![{im.stem}]({os.path.relpath(im, base)})", ""]
    cov = res.cover
    fin = np.isfinite(cov)
    seq_text = (f"median {np.median(cov[fin]):.0f}, max {np.max(cov[fin]):.0f} over the {int(fin.sum())} frequencies "
                "where it happens; " if fin.any() else "")
    lines += ["## Sequences", "",
              f"At {1 / m.frame_time_s:.2f} fps, frames to visit every phase within {res.options['cover_tol'] * 100:g} % "
              f"of the period: {seq_text}never (commensurate, or > 10^6 frames) at {int((~fin).sum())} frequencies"
              + (f" (e.g. {res.grid.freqs_hz[~fin][0]:.1f} Hz)" if (~fin).any() else "") + ".", ""]
    if res.measured:
        lines += ["## Measured captures", "", "| ROI | panel | f [Hz] | D | FMI meas. / sim. | MMP meas. / sim. |",
                  "|---|---|---|---|---|---|"]
        for r in res.measured:
            lines.append(f"| {r['roi']} | {r['panel']} | {r['frequency_hz']:g} | {r['duty']:g} | "
                         f"{r['fmi_measured']:.3f} / {r['fmi_sim']:.3f} | {r['mmp_measured']:.3f} / {r['mmp_sim']:.3f} |")
        lines.append("")
    atomic_write_text(path, "\n".join(lines))
    return path


def compare_captures(model: SensorModel, methods: Mapping[str, Callable], captures, default_lum: float,
                     delta: float = 0.1, contrast: float = 0.1) -> list[dict]:
    """Measured KPIs of real captures (:mod:`~.realcap`) beside the simulation at the same frequency, duty and
    luminance: all-phase exact FMI / MMP and the worst output over phase / steady value, and the KPIs of a
    simulated sequence of as many frames from phase 0. The measured ``rel_min`` is min / mean of the frames."""
    from lfmbench.flicker_bench.realcap import measured_kpis

    std = next((m for m in methods), model.names[0])
    out = []
    for cap in captures:
        panel = cap.panel or std
        if panel not in model.names and panel not in methods:
            raise BenchError(f"--capture-meta: field 'panel' of ROI {cap.roi!r}: {panel!r} is neither a capture "
                             f"nor a method of this bench ({model.names + list(methods)})")
        lum = cap.luminance_cd_m2 or default_lum
        meth = {panel: methods[panel]} if panel in methods else {}
        g = check_grid(Grid(np.array([cap.frequency_hz]), np.array([cap.duty]), np.array([lum])))
        pm = phase_map(model, g.freqs_hz, g.duties, g.lums, meth, delta, contrast)
        st = steady_values(model, g.duties, g.lums, meth)[panel][0, 0]
        n = max(2, cap.series.size - cap.start_index)
        seq = sequence_kpis(sequence_series(model, g.freqs_hz, g.duties, g.lums, meth, n), pm.off, delta, contrast)
        meas = measured_kpis(cap, delta, contrast)
        x = cap.series[cap.start_index:]
        vmin, vmax = pm.vmin[panel][0, 0], pm.vmax[panel][0, 0]
        out.append({"roi": cap.roi, "panel": panel, "frequency_hz": cap.frequency_hz, "duty": cap.duty,
                    "luminance_cd_m2": lum, "frames": meas["frames"],
                    "fmi_measured": meas["fmi"], "mmp_measured": meas["mmp"], "fdi_measured": meas["fdi"],
                    "rel_min_measured": float(x.min() / x.mean()) if x.mean() > 0 else math.nan,
                    "fmi_sim": float((vmax - vmin) / (vmax + vmin)), "mmp_sim": float(pm.mmp[panel][0, 0]),
                    "rel_min_sim": float(vmin / st), "fmi_seq_sim": float(seq[panel]["fmi"][0, 0]),
                    "mmp_seq_sim": float(seq[panel]["mmp"][0, 0])})
    return out
