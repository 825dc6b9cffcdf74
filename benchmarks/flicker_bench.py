"""Flicker bench: the shipped presets' reports and the speed targets of ``lfmbench flicker-bench``.

    python benchmarks/flicker_bench.py --reports   # docs/results/flicker-bench/<preset>.md + docs/img/flicker_bench/
    python benchmarks/flicker_bench.py --timing    # docs/benchmarks/flicker-bench.md

Targets (issue "virtual IEEE P2020 flicker test bench"): one full noise-free map (200 frequencies x 20 duties x 10
luminances, every phase exact) of one sensor in < 10 s on 2 cores; with noise (1,000 draws per cell at 10
luminances) < 2 min. The timing page states date, machine and load; approximations (the merges outside the exact
class, located by bisection up to a depth) get their error against dense phase sampling beside their run time.
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lfmbench.flicker_bench import run as fbr  # noqa: E402
from lfmbench.flicker_bench.exact import phase_map  # noqa: E402
from lfmbench.flicker_bench.model import build_model  # noqa: E402
from lfmbench.fileio import atomic_write_text  # noqa: E402
from lfmbench.sensor import available_presets  # noqa: E402


def _machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical CPUs visible"


def _load() -> str:
    try:
        return Path("/proc/loadavg").read_text().split(" ")[0]
    except OSError:
        return "n/a"


def reports(presets: list[str], n_freq: int) -> None:
    for name in presets:
        t0 = time.perf_counter()
        model = build_model(name)
        grid = fbr.check_grid(fbr.default_grid(model, n_freq))
        methods = fbr.bench_methods(model)
        res = fbr.run_bench(model, grid, methods)
        img_dir = ROOT / "docs" / "img" / "flicker_bench"
        ims = fbr.plot_maps(res, img_dir, stem=name)
        page = ROOT / "docs" / "results" / "flicker-bench" / f"{name}.md"
        fbr.write_report(res, page, ims)
        print(f"{name}: {time.perf_counter() - t0:.1f} s, wrote {page} and {[str(i) for i in ims]}", flush=True)


def _dense_error(model, method, cells, lums, depth):
    """Max |error| of rel_min and of MMP of ``method`` at bisection ``depth`` against 8192-point phase sampling."""
    from lfmbench.baselines import REGISTRY
    from lfmbench.flicker_bench.exact import capture_state, evaluate_panels
    from lfmbench.flicker import pwm_exposure
    import torch

    e_rel, e_mmp = 0.0, 0.0
    for f, d in cells:
        pm = phase_map(model, np.array([f]), np.array([d]), lums, {method: REGISTRY[method]}, max_depth=depth)
        st = fbr.steady_values(model, np.array([d]), lums, {method: REGISTRY[method]})[method][0]
        T = 1 / f
        ph = np.linspace(0, T, 8192, endpoint=False)
        bg = model.settings["background_cd_m2"]
        mu = {}
        for c in model.captures:
            fr = (pwm_exposure(c.starts_s[None, :] - ph[:, None], c.lengths_s, T, d) * c.weights).sum(1) / c.length_s
            mu[c.name] = torch.from_numpy(c.rate * (lums[:, None] * fr[None, :] + bg) + c.dark_e)
        vals, flags = capture_state(model, mu)
        y = evaluate_panels(model, {method: REGISTRY[method]}, vals, flags)[method].numpy()   # (L, 8192)
        m = y.mean(1, keepdims=True)
        share = np.mean((y > 0.9 * m) & (y < 1.1 * m), axis=1)
        e_rel = max(e_rel, float(np.max(np.abs(y.min(1) / st - pm.vmin[method][0] / st))))
        e_mmp = max(e_mmp, float(np.max(np.abs(share - pm.mmp[method][0]))))
    return e_rel, e_mmp


def approx_section() -> list[str]:
    lines = ["", "## Merges outside the exact class: error against dense sampling vs run time", "",
             "`flicker_aware` switches to the SPD at a root of a quadratic in phase (its noise test), so it is not "
             "linear on the exact pieces; a piece whose midpoint value is not the mean of its end values is halved, "
             "up to `max_depth` times (depth 0: end values only). Error: max over 6 cells x 10 luminances of "
             "|worst output/steady| and |MMP| against 8,192-phase sampling (which itself resolves the phase only to "
             "1/8192 of the period, so errors near 1e-3 are the sampling's); time: the ovt full map (200 x 20 x 10) "
             f"with `flicker_aware` alone. Measured {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC.",
             "", "| max_depth | max error worst/steady | max error MMP | full map [s] | load |", "|---|---|---|---|---|"]
    from lfmbench.baselines import REGISTRY

    model = build_model("ovt")
    grid = fbr.check_grid(fbr.default_grid(model, 200))
    cells = [(60.0, 0.1), (95.0, 0.2), (137.0, 0.35), (220.0, 0.05), (400.0, 0.5), (1000.0, 0.1)]
    for depth in (0, 4, 12, 40):
        er, em = _dense_error(model, "flicker_aware", cells, grid.lums, depth)
        t0 = time.perf_counter()
        phase_map(model, grid.freqs_hz, grid.duties, grid.lums, {"flicker_aware": REGISTRY["flicker_aware"]},
                  max_depth=depth)
        dt = time.perf_counter() - t0
        lines.append(f"| {depth} | {er:.2e} | {em:.2e} | {dt:.1f} | {_load()} |")
        print(lines[-1], flush=True)
    return lines


def timing(out: Path, sensors: list[str], noise_cells: int) -> None:
    lines = ["# Flicker bench: speed and approximation error", "",
             f"Measured {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC on {_machine()}, "
             f"1-min load average at start {_load()}. "
             "Rerun: `python benchmarks/flicker_bench.py --timing`.", "",
             "The machine was shared with other jobs (load well above its 2 cores): absolute times are upper bounds; "
             "ratios between rows of one run are comparable.", ""]
    lines += ["## Noise-free map, every phase exact (target < 10 s)", "",
              "Grid 200 frequencies x 20 duties x 10 luminances, all panels (captures and merges); median of 3 runs "
              "after one warm-up (numba compilation excluded).", "",
              "| sensor | panels | phase map [s] | + 100-frame sequences [s] | load |", "|---|---|---|---|---|"]
    for name in sensors:
        model = build_model(name)
        grid = fbr.check_grid(fbr.default_grid(model, 200))
        methods = fbr.bench_methods(model)
        phase_map(model, grid.freqs_hz[:5], grid.duties, grid.lums, methods)
        ts, tq = [], []
        for _ in range(3):
            r = fbr.run_bench(model, grid, methods)
            ts.append(r.timings_s["phase_map_s"])
            tq.append(r.timings_s["sequence_s"])
        lines.append(f"| {name} | {len(model.names)} captures + {list(methods)} | {statistics.median(ts):.1f} | "
                     f"{statistics.median(tq):.1f} | {_load()} |")
        print(lines[-1], flush=True)
    lines += ["", "## With noise (target < 2 min for 1,000 draws per cell at 10 luminances)", "",
              f"Monte Carlo through the preset's chain, roi_px = 4, 1,000 draws per cell, 10 luminances, on "
              f"{noise_cells} of the 4,000 cells (frequencies x duties); the full-grid time is that x "
              f"{4000 / noise_cells:g} (the work is linear in the cells).", "",
              "| sensor | cells | time [s] | full grid, extrapolated [s] | load |", "|---|---|---|---|---|"]
    for name in sensors:
        model = build_model(name)
        grid = fbr.check_grid(fbr.default_grid(model, 200))
        methods = fbr.bench_methods(model)
        nf = max(1, noise_cells // grid.duties.size)
        sub = fbr.Grid(grid.freqs_hz[::max(1, grid.freqs_hz.size // nf)][:nf], grid.duties, grid.lums)
        t0 = time.perf_counter()
        fbr.run_bench(model, sub, methods, noise_draws=1000, frames=2)
        dt = time.perf_counter() - t0
        cells = sub.freqs_hz.size * sub.duties.size
        lines.append(f"| {name} | {cells} | {dt:.1f} | {dt * 4000 / cells:.0f} | {_load()} |")
        print(lines[-1], flush=True)
    lines += approx_section()
    lines.append("")
    atomic_write_text(out, "\n".join(lines))
    print(f"wrote {out}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reports", action="store_true", help="write the shipped presets' report pages")
    ap.add_argument("--timing", action="store_true", help="write docs/benchmarks/flicker-bench.md")
    ap.add_argument("--approx-only", action="store_true", help="rerun only the last section of the timing page")
    ap.add_argument("--presets", nargs="*", default=None, help="presets for --reports (default: all shipped)")
    ap.add_argument("--n-freq", type=int, default=200, help="frequencies of the report maps")
    ap.add_argument("--sensors", nargs="*", default=["ovt", "chopped"], help="sensors for --timing")
    ap.add_argument("--noise-cells", type=int, default=100, help="cells of the noise timing")
    a = ap.parse_args()
    if a.reports:
        reports(a.presets or available_presets(), a.n_freq)
    page = ROOT / "docs" / "benchmarks" / "flicker-bench.md"
    if a.timing:
        timing(page, a.sensors, a.noise_cells)
    elif a.approx_only:  # rerun the last section only, keeping the rest of the page
        text = page.read_text(encoding="utf-8")
        head = text.split("\n## Merges outside the exact class")[0].split("\n## Approximate merges")[0].rstrip("\n")
        atomic_write_text(page, head + "\n" + "\n".join(approx_section()) + "\n")


if __name__ == "__main__":
    main()
