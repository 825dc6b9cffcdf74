"""An 8-method evaluation with and without sharing the simulated samples across methods
(docs/benchmarks/evaluation-sharing.md).

    lfmbench demo                      # or any corpus; the demo's corpus and U-Net checkpoint are enough
    python benchmarks/bench_eval_sharing.py --corpus demo_out/corpus --checkpoint demo_out/unet_fusion.pt

Methods: the 7 rule-based baselines and the U-Net (the protocol leaderboard's set, lfmbench.evaluation.protocol_run).
Timed, one run each after a warm-up (a pass over the data that fills the projection cache, and both paths on two
samples: imports, checkpoint loading, plotting): (1) the data alone (every sample read and
simulated once, no method), (2) ``benchmark(share_samples=False)`` (one pass over the data per method: before),
(3) ``benchmark(share_samples=True)`` (each sample simulated once for all methods: after); with ``--repeats N`` each
path N times in the order ABBA, the fastest kept. Wall time and process CPU time are both recorded: with
``--threads 1`` the CPU time is what a shared machine's load hardly moves (the saving to compare with the
simulation's share). The per-sample scores of (2) and (3) are compared (they must be
equal). Prints a Markdown table and writes it as the section "Latest run" of docs/benchmarks/evaluation-sharing.md
(``--no-doc``: print only); ``--json`` writes the numbers.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path


#: The page whose section "Latest run" this script rewrites (the rest of the page is written by hand).
DOC = Path(__file__).resolve().parents[1] / "docs" / "benchmarks" / "evaluation-sharing.md"


def _runs(ts: list[float]) -> str:
    return ", ".join(f"{t:.1f}" for t in ts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", required=True, help="corpus root")
    ap.add_argument("--checkpoint", required=True, help="U-Net checkpoint (lfmbench train --out, or the demo's)")
    ap.add_argument("--split", default="all")
    ap.add_argument("--samples-per-scene", type=int, default=2)
    ap.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    ap.add_argument("--isp", default="default", help="ISP pipeline of the display columns, or 'none'")
    ap.add_argument("--repeats", type=int, default=1, help="timed runs of each path, in the order ABBA (min kept)")
    ap.add_argument("--json", default=None, help="write the numbers to this JSON file")
    ap.add_argument("--no-doc", action="store_true", help="do not write docs/benchmarks/evaluation-sharing.md")
    a = ap.parse_args()
    if not os.path.isfile(a.checkpoint):
        ap.error(f"--checkpoint {a.checkpoint}: no such file")
    os.environ["LFMBENCH_UNET_CHECKPOINT"] = a.checkpoint
    import torch

    if a.threads:
        torch.set_num_threads(a.threads)
    from torch.utils.data import DataLoader

    from lfmbench.baselines import REGISTRY
    from lfmbench.datasets.loading import collate_samples
    from lfmbench.evaluation.benchmark import benchmark, corpus_run_inputs
    from lfmbench.fileio import atomic_write_json

    methods = [m for m in REGISTRY if m != "learned"]
    ds, _, _ = corpus_run_inputs(a.corpus, a.split, 0, None, a.samples_per_scene, frames=3)
    n = len(ds)

    def data_pass() -> tuple[float, float]:
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in DataLoader(ds, batch_size=1, shuffle=False, num_workers=0, collate_fn=collate_samples):
            pass
        return time.perf_counter() - t0, time.process_time() - c0

    data_pass()  # warm-up: fills the projection cache, loads the sensor kernels
    t_data, c_data = data_pass()
    kw = dict(split=a.split, perceptual=False, repeats=1, progress=False, samples_per_scene=a.samples_per_scene,
              isp=None if a.isp == "none" else a.isp, resume=False)  # every repeat scores again
    times: dict[bool, list[float]] = {False: [], True: []}
    cpu: dict[bool, list[float]] = {False: [], True: []}   # process CPU time: what the machine's load hardly moves
    equal = True
    with tempfile.TemporaryDirectory() as tmp:
        for share in (False, True):  # warm-up of both paths on 2 samples: imports, checkpoint, plotting
            benchmark(a.corpus, methods, Path(tmp) / "warm", share_samples=share, max_scenes=2, **kw)
        order = [False, True, True, False] * ((a.repeats + 1) // 2)  # ABBA: a drifting machine load cancels
        for share in order[:2 * a.repeats]:
            out = Path(tmp) / ("shared" if share else "per_method")
            t0, c0 = time.perf_counter(), time.process_time()
            benchmark(a.corpus, methods, out, share_samples=share, **kw)
            times[share].append(time.perf_counter() - t0)
            cpu[share].append(time.process_time() - c0)
        for m in methods:
            old, new = (json.loads((Path(tmp) / d / f"{m}.json").read_text()) for d in ("per_method", "shared"))
            equal &= [(s["scene_id"], s.get("metrics")) for s in old["scenes"]] == \
                     [(s["scene_id"], s.get("metrics")) for s in new["scenes"]]
    t_old, t_new = min(times[False]), min(times[True])
    c_old, c_new = min(cpu[False]), min(cpu[True])
    k = len(methods)
    res = {
        "methods": methods, "samples": n, "isp": a.isp, "split": a.split, "samples_per_scene": a.samples_per_scene,
        "corpus": str(a.corpus), "torch_threads": torch.get_num_threads(),
        "cpu": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(), "load_avg_1min_after": os.getloadavg()[0],
        "data_pass_s": t_data, "per_method_s": t_old, "shared_s": t_new, "per_method_runs_s": times[False],
        "shared_runs_s": times[True], "ratio_shared_per_method": t_new / t_old,
        "simulation_share_of_per_method": k * t_data / t_old,
        "expected_shared_s": t_old - (k - 1) * t_data, "per_sample_scores_equal": equal,
        "cpu_data_pass_s": c_data, "cpu_per_method_s": c_old, "cpu_shared_s": c_new,
        "cpu_per_method_runs_s": cpu[False], "cpu_shared_runs_s": cpu[True],
        "cpu_saving": 1.0 - c_new / c_old, "cpu_simulation_share_of_per_method": k * c_data / c_old,
    }
    table = (f"| {k}-method evaluation, {n} samples | time (s) |\n|---|---|\n"
          f"| data alone (read + simulate every sample once) | {t_data:.1f} |\n"
          f"| before: one pass over the data per method | {t_old:.1f} (runs: {_runs(times[False])}) |\n"
          f"| after: each sample simulated once, shared | {t_new:.1f} (runs: {_runs(times[True])}) |\n"
          f"| ratio after / before | {t_new / t_old:.3f} |\n"
          f"| simulation share of the before run ({k} x data alone / before) | {100 * k * t_data / t_old:.1f} % |\n"
          f"| expected after (before - {k - 1} x data alone) | {t_old - (k - 1) * t_data:.1f} |\n"
             f"| per-sample scores equal | {equal} |")
    table += (f"\n\n| process CPU time (s) | data alone | before | after | saving | simulation share of before |\n"
          f"|---|---|---|---|---|---|\n| {k} methods, {n} samples | {c_data:.1f} | {c_old:.1f} "
          f"({_runs(cpu[False])}) | {c_new:.1f} ({_runs(cpu[True])}) | {100 * (1 - c_new / c_old):.1f} % | "
              f"{100 * k * c_data / c_old:.1f} % |")
    print(table)
    if not a.no_doc:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from _timing import load_line, replace_section  # noqa: PLC0415

        heading = "## Latest run"
        replace_section(DOC, heading, [heading, "", f"Run on {load_line()} at its end, {res['cpu']}, {res['cpus']} "
                                       f"CPU cores: `python benchmarks/bench_eval_sharing.py --corpus {a.corpus} "
                                       f"--checkpoint {a.checkpoint}` (split `{a.split}`, {a.samples_per_scene} "
                                       "samples per scene).", "", table, ""])
    if a.json:
        atomic_write_json(a.json, res)
    if not equal:
        sys.exit("per-sample scores differ between the two paths")


if __name__ == "__main__":
    main()
