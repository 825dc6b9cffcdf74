"""``lfmbench leaderboard`` at sweep scale: seconds to rank 1,000 to 10,000 result files (docs/benchmarks/leaderboard.md).

Each file is a complete result of the same corpus and protocol (what a hyper-parameter sweep writes): ``--scenes``
sample records (default 8) with every table metric (random values within each metric's range) and the conditions
the breakdown bins, about 20 KB. Timed, in one process: the whole command (``lfmbench leaderboard`` through the CLI,
table, Markdown, JSON and plot written), and its phases (reading and checking the files and their per-scene values,
in a forked pool of 2 processes for a sweep, as the command does; comparability, rows with their statistics, the
Pareto front, the outputs). The pairwise Pareto front (the definition, O(n^2)) is timed on the
same rows for comparison, up to 2,000 files.

Usage: ``python benchmarks/bench_leaderboard.py [--files 1000 10000] [--scenes 8] [--work DIR] [--no-doc]
[--before DIR --before-label COMMIT]``.
"""
from __future__ import annotations

import argparse
import contextlib
import cProfile
import io
import json
import os
import platform
import pstats
import random
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DOC = ROOT / "docs" / "benchmarks" / "leaderboard.md"
#: The target of issue 42: this many result files ranked in under TARGET_S seconds on 2 cores.
TARGET_FILES, TARGET_S = 10_000, 30.0
TIMES = ("day", "dusk", "night")


def _value(spec, rng: random.Random) -> float:
    """A random value inside the documented range of a metric (the leaderboard refuses values outside)."""
    for v in (rng.uniform(0.0, 1.0), rng.uniform(10.0, 40.0), rng.uniform(0.0, 10.0)):
        if spec.value_error(v) is None:
            return v
    return 0.5


def make_results(work: Path, n: int, scenes: int, seed: int = 0) -> list[Path]:
    """``n`` result files of one corpus and protocol in ``work``; returns their paths."""
    from lfmbench.evaluation.stats import settings
    from lfmbench.metrics import REGISTRY, columns, metric_versions

    rng = random.Random(seed)
    names = [s.name for s in columns("table")]
    weights = {s.weight for s in REGISTRY.values() if s.weight}
    out = []
    for k in range(n):
        recs = []
        for i in range(scenes):
            m = {name: _value(REGISTRY[name], rng) for name in names}
            m.update({w: float(rng.randint(1, 50)) for w in weights})
            recs.append({"scene_id": f"scene{i:05d}", "index": i, "status": "ok", "call_ms": 1.0, "megapixels": 0.1,
                         "metrics": m, "conditions": {"time_of_day": TIMES[i % 3], "ego_speed_mps": 5.0 * (i % 5),
                                                      "pwm_duty": rng.uniform(0.1, 0.5),
                                                      "pwm_freq_hz": rng.uniform(90, 130),
                                                      "pwm_miss_prob": rng.uniform(0, 0.6)}})
        doc = {"format": "lfmbench-eval", "version": 2, "method": {"spec": f"sweep:run{k:05d}", "params": 1000},
               "status": "complete", "runtime": {"device": "cpu", "ms_per_megapixel": rng.uniform(1, 100)},
               "aggregate": {"scenes": scenes, "scenes_ok": scenes}, "scenes": recs,
               "dataset": {"split": "test", "samples_per_scene": 1, "frames": 3}, "seeds": {"dataset": 0},
               "corpus": {"scenes_sha256": "0" * 64, "format_version": 2, "test_draws_sha256": "1" * 64},
               "versions": {"metrics": metric_versions()}, "statistics": settings(), "options": {}}
        p = work / f"run{k:05d}.json"
        p.write_text(json.dumps(doc))
        out.append(p)
    return out


def time_phases(paths: list[Path], out: Path, profile: bool = False) -> dict:
    """Seconds (wall and CPU) of each phase of the command, run as the CLI runs it; with ``profile`` (which slows
    every phase) the top of a cProfile."""
    from lfmbench.evaluation import leaderboard as L
    from lfmbench.evaluation.benchmark import write_leaderboard

    t = {}
    prof = cProfile.Profile()
    if profile:
        prof.enable()
    c0 = time.process_time()
    t0 = time.perf_counter()
    runs = L.load_runs(paths, digest=L.digest_run)  # as the command: per-scene values where each file is read
    t["read, check, per-scene values (2 processes)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    L.check_comparable(runs)
    t["comparability"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    rows = L.leaderboard_rows(runs)
    t["rows and statistics"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    L._pareto(rows, L.PARETO_AXES)
    t["Pareto front (sweep)"] = time.perf_counter() - t0
    if len(rows) <= 2000:
        t0 = time.perf_counter()
        L._pareto_pairwise(rows, L.PARETO_AXES)
        t["Pareto front (pairwise, before)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        L.print_leaderboard(rows, "led_score")
    t["console table"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    write_leaderboard(rows, runs, "led_score", out / "lb.md", out / "lb.png", out / "lb.json", None)
    t["outputs (Markdown, JSON, plot)"] = time.perf_counter() - t0
    cpu = time.process_time() - c0
    s = io.StringIO()
    if profile:
        prof.disable()
        pstats.Stats(prof, stream=s).sort_stats("cumulative").print_stats(18)
    return {"phases": t, "cpu": cpu, "profile": s.getvalue()}


def time_imports(root: Path = ROOT) -> tuple[float, float]:
    """(wall, CPU) seconds of a fresh process importing ``lfmbench.cli`` from ``root`` (the CLI's start-up)."""
    import subprocess

    c0 = _child_cpu()
    t0 = time.perf_counter()
    # run in ``root``: ``python -c`` puts the current folder first on sys.path
    subprocess.run([sys.executable, "-c", "import lfmbench.cli"], check=True, cwd=str(root),
                   env=dict(os.environ, PYTHONPATH=str(root)))
    return time.perf_counter() - t0, _child_cpu() - c0


def _child_cpu() -> float:
    import resource

    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def time_cli(paths: list[Path], out: Path, root: Path = ROOT) -> tuple[float, float]:
    """(wall, CPU) seconds of ``lfmbench leaderboard FILES ...`` run from the tree ``root`` (a fresh process,
    imports included; CPU: user + system of that process)."""
    import subprocess

    lst = out / "files.txt"
    cmd = [sys.executable, "-c", "import sys; from lfmbench.cli import app; sys.argv = ['lfmbench'] + "
           f"open({str(lst)!r}).read().split('\\n'); app()"]
    lst.write_text("\n".join(["leaderboard", *map(str, paths), "--markdown", str(out / "c.md"), "--plot",
                              str(out / "c.png"), "--json", str(out / "c.json")]))
    c0 = _child_cpu()
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=str(root), env=dict(os.environ, PYTHONPATH=str(root)))
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"leaderboard failed: {r.stderr[-2000:]}")
    return dt, _child_cpu() - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, nargs="+", default=[1000, 10000])
    ap.add_argument("--scenes", type=int, default=8)
    ap.add_argument("--work", type=Path, default=None)
    ap.add_argument("--no-doc", action="store_true")
    ap.add_argument("--profile", action="store_true", help="also profile the phases (slower; printed)")
    ap.add_argument("--before", type=Path, default=None,
                    help="a source tree of an earlier commit (`git archive COMMIT | tar -x -C DIR`): its CLI is "
                         "timed on the same files in the same run, for a before/after comparison")
    ap.add_argument("--before-label", default="before", help="what --before is (e.g. a commit), for the page")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="lfm-lb-", dir=args.work))
    load = open("/proc/loadavg").read().split()[:3] if os.path.exists("/proc/loadavg") else ["?"] * 3
    res = []
    imports = {"this tree": time_imports()}
    if args.before:
        imports[args.before_label] = time_imports(args.before.resolve())
    try:
        for n in args.files:
            d = work / f"n{n}"
            d.mkdir()
            paths = make_results(d, n, args.scenes)
            size = sum(p.stat().st_size for p in paths)
            cli = {"this tree": time_cli(paths, d)}
            if args.before:
                cli[args.before_label] = time_cli(paths, d, args.before.resolve())
            ph = time_phases(paths, d, args.profile)
            res.append((n, size, cli, ph))
            print(f"{n} files ({size / 1e6:.0f} MB): CLI (wall, CPU) {cli}; phases CPU {ph['cpu']:.1f} s; " +
                  "; ".join(f"{k} {v:.2f} s" for k, v in ph["phases"].items()), flush=True)
            print(ph["profile"][:6000], flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    load_after = open("/proc/loadavg").read().split()[:3] if os.path.exists("/proc/loadavg") else ["?"] * 3
    if args.no_doc:
        return
    phases = list(dict.fromkeys(k for r in res for k in r[3]["phases"]))  # every phase of any run, in order
    trees = list(res[0][2])
    lines = ["# Leaderboard at sweep scale", "",
             f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {platform.processor() or platform.machine()}, "
             f"{os.cpu_count()} cores shared with other jobs (load average {' '.join(load)} before, "
             f"{' '.join(load_after)} after): a loaded machine, so wall times are upper bounds and the CPU seconds "
             "(user + system of the process) say more. Rerun: `python benchmarks/bench_leaderboard.py` (with "
             "`--before DIR` to time an earlier commit's tree on the same files in the same run).", "",
             f"Each file: a complete result of {args.scenes} scenes with every table metric (random values in each "
             "metric's range) and the conditions the breakdown bins; all of one corpus and protocol. "
             f"Target (issue 42): {TARGET_FILES:,} files in under {TARGET_S:g} s on 2 cores.", "",
             "`lfmbench leaderboard FILES` as a user runs it (a fresh process: imports, reading, ranking, console "
             "table, Markdown, JSON and plot), wall and CPU seconds:", "",
             "| files | MB | " + " | ".join(f"{t}: wall, s | {t}: CPU, s" for t in trees) + " |",
             "|---:|---:|" + "---:|---:|" * len(trees)]
    for n, size, cli, _ in res:
        lines.append(f"| {n:,} | {size / 1e6:.0f} | " + " | ".join(f"{cli[t][0]:.1f} | {cli[t][1]:.1f}" for t in trees)
                     + " |")
    lines += ["", "Start-up (a fresh process importing `lfmbench.cli`, part of every CLI time above): " + "; ".join(
        f"{t} {w:.1f} s wall, {c:.1f} s CPU" for t, (w, c) in imports.items()) + ".", "",
        "The phases of this tree, run again in one process after the CLI runs (wall seconds; their total CPU "
        "seconds beside them):", "",
        "| files | phases CPU, s | " + " | ".join(f"{p}, s" for p in phases) + " |",
        "|---:|---:|" + "---:|" * len(phases)]
    for n, size, cli, ph in res:
        lines.append(f"| {n:,} | {ph['cpu']:.1f} | " + " | ".join(
            f"{ph['phases'][p]:.2f}" if p in ph["phases"] else "-" for p in phases) + " |")
    if res[-1][3]["profile"]:
        lines += ["", "Profile of the largest run (cumulative seconds, top entries):", "", "```",
                  res[-1][3]["profile"].strip()[:5000], "```"]
    lines.append("")
    if DOC.exists() and "\n## Reading" in DOC.read_text():  # the hand-written reading of the numbers is kept
        lines.append("## Reading" + DOC.read_text().split("\n## Reading", 1)[1].rstrip() + "\n")
    from lfmbench.fileio import atomic_write_text

    atomic_write_text(DOC, "\n".join(lines))
    print(f"wrote {DOC}")


if __name__ == "__main__":
    main()
