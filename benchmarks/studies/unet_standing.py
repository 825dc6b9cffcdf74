"""Standing of one method against others from ``lfmbench evaluate`` result files, with scene-bootstrap 95 % CIs.

    python benchmarks/studies/unet_standing.py RUNS_DIR/*.json [--against unet]

For every run: PSNR-mu (dB), light dropout rate, mean |FMI - FMI_gt| and series_rel_rmse (relative RMS error of
the LED-region series, an LED-region quality), each combined over scenes as the leaderboard combines it (a scene's
frozen draws first, then the mean over scenes, or for ``dropout_rate`` the ratio pooled over region-frames:
:func:`lfmbench.evaluation.results.per_scene` and :func:`~lfmbench.evaluation.results.metric_summary`), with the
leaderboard's bootstrap CI over scenes (:func:`lfmbench.evaluation.stats.bootstrap_ci`). Every run must cover the
same scenes. Prints a Markdown table (docs/guide/baselines.md, "U-Net baseline"); with ``--against NAME`` also the
paired differences ``NAME - other`` of the per-scene values of each metric (:func:`lfmbench.evaluation.stats.
paired_test`: mean difference, its bootstrap CI and the Wilcoxon signed-rank p over scenes, so scene difficulty
cancels). Used to report numbers, not a timed test.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

METRICS = ("psnr_mu", "dropout_rate", "fmi_abs_err", "series_rel_rmse")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--against", default=None, help="run name (file stem) to compare with every other run")
    a = ap.parse_args(argv)
    from lfmbench.evaluation import stats  # noqa: PLC0415 - --help without torch
    from lfmbench.evaluation.results import metric_summary, per_scene  # noqa: PLC0415

    runs = {p.stem: per_scene(json.loads(p.read_text()).get("scenes") or [], METRICS)
            for p in a.runs if p.stem != "leaderboard"}
    if not runs:
        raise SystemExit("no result files given")
    scenes = sorted(s["scene_id"] for s in next(iter(runs.values())))
    for name, r in runs.items():
        if sorted(s["scene_id"] for s in r) != scenes:
            raise SystemExit(f"{name}: scored scenes {sorted(s['scene_id'] for s in r)} differ from {scenes}")
    settings = stats.settings()
    print(f"{len(scenes)} scenes, {sum(s['samples'] for s in next(iter(runs.values())))} samples, 95 % CIs: "
          f"{settings['ci']}, {settings['n_resamples']} resamples\n")
    print("| method | " + " | ".join(METRICS) + " |")
    print("|---|" + "---|" * len(METRICS))
    for name, r in sorted(runs.items(), key=lambda kv: -metric_summary(kv[1], "psnr_mu", ci=False)["value"]):
        cells = []
        for m in METRICS:
            s = metric_summary(r, m)
            (lo, hi), d = s["ci"], (2 if m == "psnr_mu" else 3)
            cells.append(f"{s['value']:.{d}f} [{lo:.{d}f}, {hi:.{d}f}]")
        print(f"| {name} | " + " | ".join(cells) + " |")
    if a.against:
        if a.against not in runs:
            raise SystemExit(f"--against {a.against}: no such run ({sorted(runs)})")
        ref = {s["scene_id"]: s["metrics"] for s in runs[a.against]}
        print(f"\npaired differences {a.against} - other over scenes: mean [95 % CI], Wilcoxon p\n")
        print("| other | " + " | ".join(METRICS) + " |")
        print("|---|" + "---|" * len(METRICS))
        for name, r in sorted(runs.items()):
            if name == a.against:
                continue
            other = {s["scene_id"]: s["metrics"] for s in r}
            cells = []
            for m in METRICS:
                pairs = [(ref[s].get(m), other[s].get(m)) for s in scenes]
                pairs = [(x, y) for x, y in pairs if x is not None and y is not None]
                t = stats.paired_test([x for x, _ in pairs], [y for _, y in pairs])
                lo, hi = t["ci"]
                cells.append(f"{t['mean_diff']:+.3f} [{lo:+.3f}, {hi:+.3f}] p {t['p']:.3f}")
            print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
