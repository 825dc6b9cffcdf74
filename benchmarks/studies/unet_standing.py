"""Standing of one method against others from ``lfmbench evaluate`` result files, with scene-bootstrap 95 % CIs.

    python benchmarks/unet_standing.py RUNS_DIR/*.json [--resamples 2000] [--seed 0]

For every run: mean PSNR-mu (dB), light dropout rate (pooled over region-frames), mean |FMI - FMI_gt| and mean
series_rel_rmse (relative RMS error of the LED-region series, an LED-region quality), each with a percentile
bootstrap CI that resamples *scenes* (all frozen draws of a resampled scene go together, since draws of one
scene are correlated). Every run must cover the same scenes; the same resampled scene sets are used for all
runs. Prints a Markdown table (docs/guide/baselines.md, "U-Net baseline"); with ``--against NAME`` also the paired
differences ``NAME - other`` per metric (same resampled scenes for both, so scene difficulty cancels) with their
CIs. Used to report numbers, not a timed test.
"""
from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

METRICS = ("psnr_mu", "dropout_rate", "fmi_abs_err", "series_rel_rmse")


def _per_scene(run: dict) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = defaultdict(list)
    for s in run["scenes"]:
        if s.get("status") == "ok":
            out[s["scene_id"]].append(s["metrics"])
    return out


def _stat(groups: list[list[dict]], metric: str) -> float:
    rows = [m for g in groups for m in g]
    if metric == "dropout_rate":  # pooled over region-frames, as the evaluation aggregates it
        num = sum(m["dropout_rate"] * m["region_frames"] for m in rows if m.get("region_frames"))
        den = sum(m["region_frames"] for m in rows if m.get("region_frames"))
        return num / den if den else float("nan")
    vals = [m[metric] for m in rows if m.get(metric) is not None and np.isfinite(m[metric])]
    return float(np.mean(vals)) if vals else float("nan")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--resamples", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--against", default=None, help="run name (file stem) to compare with every other run")
    a = ap.parse_args(argv)
    runs = {p.stem: _per_scene(json.loads(p.read_text())) for p in a.runs if p.stem != "leaderboard"}
    scenes = sorted(next(iter(runs.values())))
    for name, r in runs.items():
        if sorted(r) != scenes:
            raise SystemExit(f"{name}: scored scenes {sorted(r)} differ from {scenes}")
    rng = np.random.default_rng(a.seed)
    picks = rng.integers(0, len(scenes), size=(a.resamples, len(scenes)))
    print(f"{len(scenes)} scenes, {sum(len(v) for v in next(iter(runs.values())).values())} samples, "
          f"{a.resamples} scene-bootstrap resamples, 95 % percentile CIs\n")
    print("| method | " + " | ".join(METRICS) + " |")
    print("|---|" + "---|" * len(METRICS))
    for name, r in sorted(runs.items(), key=lambda kv: -_stat(list(kv[1].values()), "psnr_mu")):
        cells = []
        for m in METRICS:
            point = _stat([r[s] for s in scenes], m)
            boot = [_stat([r[scenes[i]] for i in row], m) for row in picks]
            lo, hi = np.nanpercentile(boot, [2.5, 97.5])
            cells.append(f"{point:.3f} [{lo:.3f}, {hi:.3f}]" if m != "psnr_mu" else
                         f"{point:.2f} [{lo:.2f}, {hi:.2f}]")
        print(f"| {name} | " + " | ".join(cells) + " |")
    if a.against:
        if a.against not in runs:
            raise SystemExit(f"--against {a.against}: no such run ({sorted(runs)})")
        ref = runs[a.against]
        print(f"\npaired differences {a.against} - other, 95 % scene-bootstrap CI\n")
        print("| other | " + " | ".join(METRICS) + " |")
        print("|---|" + "---|" * len(METRICS))
        for name, r in sorted(runs.items()):
            if name == a.against:
                continue
            cells = []
            for m in METRICS:
                d = _stat([ref[s] for s in scenes], m) - _stat([r[s] for s in scenes], m)
                boot = [_stat([ref[scenes[i]] for i in row], m) - _stat([r[scenes[i]] for i in row], m)
                        for row in picks]
                lo, hi = np.nanpercentile(boot, [2.5, 97.5])
                cells.append(f"{d:+.3f} [{lo:+.3f}, {hi:+.3f}]")
            print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
