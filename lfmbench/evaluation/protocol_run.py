"""Leaderboard of the classical baselines and the U-Net on a protocol corpus's test split (docs/results/leaderboard-v1.md,
docs/results/leaderboard-v1-mini.md, docs/results/leaderboard-v2-mini.md).

    lfmbench render --protocol lfmbench-v1-mini --out v1mini --workers 2
    lfmbench train --corpus v1mini --config lfmbench/configs/unet.yaml --out runs/unet_fusion.pt --epochs 16
    python -m lfmbench.evaluation.protocol_run --corpus v1mini --checkpoint runs/unet_fusion.pt --runs runs/v1mini

    lfmbench render --protocol lfmbench-v1 --out v1 --workers 2            # or --split test, then --split train
    lfmbench train --corpus v1 --config lfmbench/configs/unet_v1.yaml --out runs/unet_v1.pt --epochs 12
    python -m lfmbench.evaluation.protocol_run --corpus v1 --checkpoint runs/unet_v1.pt --runs runs/v1

    # a second U-Net (e.g. trained on another protocol's train split) scored on the same samples as `unet_v1trained`
    python -m lfmbench.evaluation.protocol_run --corpus v2mini --checkpoint runs/unet_v2mini.pt \\
        --unet-also unet_v1trained=runs/unet_v1mini.pt --runs runs/v2mini

Writes one result JSON per method, ``leaderboard.md``, ``leaderboard.json`` and ``leaderboard.png`` into ``--runs``
(8 frozen PWM draws per test scene, no perceptual metrics: PU21 / ColorVideoVDP add minutes and are secondary).
The tiny ``learned`` baseline is left out (its checkpoint is the demo's). ``scene_fields.md`` adds what the
condition bins of ``lfmbench/configs/conditions.yaml`` do not hold: the LED score by a scene-file field
(``weather`` of scene generator 2: dry, wet, rain), and every ``--unet-also`` network paired against ``unet``
(overall and per field value). A killed run is continued by the same command (only the missing samples are scored;
``--no-resume`` scores everything again).
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

#: Scene-file fields (scene.json) broken down in ``scene_fields.md`` when the scored scenes carry them.
SCENE_FIELDS = ("weather",)
#: Metrics of the ``scene_fields.md`` tables (registered metric names).
FIELD_METRICS = ("led_score", "psnr_mu")


def _fmt(summary: dict) -> str:
    lo, hi = summary["ci"]
    return f"{summary['value']:.3f} [{lo:.3f}, {hi:.3f}] ({summary['n']})"


def scene_field_tables(runs: list[dict], field_of: dict[str, dict], extra: list[str], reference: str = "unet"
                       ) -> str:
    """Markdown: per scene-file field (``field_of``: scene id -> {field: value}) and metric of
    :data:`FIELD_METRICS`, each method's value [95 % CI] (scenes) per field value; then every ``extra`` method
    paired against ``reference`` over the scenes both scored (mean difference [95 % CI], Wilcoxon p), overall and
    per field value. ``runs``: loaded result files (:func:`lfmbench.evaluation.leaderboard.load_runs`)."""
    from lfmbench.evaluation import stats
    from lfmbench.evaluation.results import metric_summary, per_scene

    scenes = {r["method"]["spec"]: per_scene(r.get("scenes") or []) for r in runs}
    order = sorted(scenes, key=lambda m: -metric_summary(scenes[m], "led_score", ci=False)["value"])
    fields = [f for f in SCENE_FIELDS if any(f in v for v in field_of.values())]
    metrics = [k for k in FIELD_METRICS if any(k in s["metrics"] for sc in scenes.values() for s in sc)]
    lines = []
    for f in fields:
        values = sorted({v[f] for v in field_of.values() if f in v})
        for metric in metrics:
            lines += [f"`{metric}` by scene `{f}` (value [95 % CI] (scenes)):", "",
                      f"| method | all | {' | '.join(values)} |", "|---|---|" + "---|" * len(values)]
            for m in order:
                cells = [_fmt(metric_summary(scenes[m], metric))]
                for v in values:
                    sub = [s for s in scenes[m] if field_of.get(s["scene_id"], {}).get(f) == v]
                    cells.append(_fmt(metric_summary(sub, metric)) if sub else "-")
                lines.append(f"| `{m}` | {' | '.join(cells)} |")
            lines.append("")
    if reference in scenes:
        groups = [("all", None)] + [(f"{f} = {v}", (f, v)) for f in fields
                                    for v in sorted({x[f] for x in field_of.values() if f in x})]
        for m in [e for e in extra if e in scenes]:
            for metric in metrics:
                lines += [f"`{m}` - `{reference}`, `{metric}` paired over scenes (mean diff [95 % CI], n, "
                          "Wilcoxon p):", "", "| scenes | mean diff [95 % CI] | n | p |", "|---|---|---|---|"]
                ref = {s["scene_id"]: s["metrics"].get(metric) for s in scenes[reference]}
                for label, sel in groups:
                    mine = [s for s in scenes[m] if sel is None or field_of.get(s["scene_id"], {}).get(sel[0]) == sel[1]]
                    t = stats.paired_by_scene({s["scene_id"]: s["metrics"].get(metric) for s in mine}, ref)
                    lo, hi = t["ci"]
                    lines.append(f"| {label} | {t['mean_diff']:+.3f} [{lo:+.3f}, {hi:+.3f}] | {t['n']} | {t['p']:.4f} |")
                lines.append("")
    return "\n".join(lines)


def scene_fields(corpus: str | os.PathLike, scene_ids) -> dict[str, dict]:
    """Scene id -> {field: value} of :data:`SCENE_FIELDS` read from the corpus's scene files (absent: left out)."""
    from lfmbench.corpus import Corpus

    c = Corpus(corpus)
    out = {}
    for sid in scene_ids:
        d = c.scene(sid)
        out[sid] = {f: str(d[f]) for f in SCENE_FIELDS if isinstance(d.get(f), str)}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", required=True, help="protocol corpus root")
    ap.add_argument("--checkpoint", required=True, help="U-Net checkpoint (lfmbench train --out)")
    ap.add_argument("--unet-also", action="append", default=[], metavar="NAME=CHECKPOINT",
                    help="another U-Net checkpoint, scored on the same samples as method NAME; repeatable")
    ap.add_argument("--runs", default="runs/protocol", help="output directory")
    ap.add_argument("--samples-per-scene", type=int, default=8)
    ap.add_argument("--no-resume", action="store_true",
                    help="score every method again (default: continue the result files in --runs of this "
                         "evaluation that a killed run left, scoring only the missing samples; skip complete ones)")
    ap.add_argument("--only-unets", action="store_true",
                    help="score only the U-Nets (--checkpoint as `unet`, and --unet-also), not the rule-based methods "
                         "(e.g. a second training seed on draws the rules were scored on already)")
    a = ap.parse_args()
    if not os.path.isfile(a.checkpoint):
        ap.error(f"--checkpoint {a.checkpoint}: no such file (make it with lfmbench train)")
    os.environ["LFMBENCH_UNET_CHECKPOINT"] = a.checkpoint
    from lfmbench.baselines import REGISTRY
    from lfmbench.baselines.unet import parse_named_checkpoints, register_unets
    from lfmbench.evaluation.benchmark import benchmark, safe_name  # the module, not the package's lazy name
    from lfmbench.evaluation.leaderboard import load_runs
    from lfmbench.evaluation.run import ResumeError
    from lfmbench.fileio import atomic_write_text

    try:
        extra = parse_named_checkpoints(a.unet_also, REGISTRY, "--unet-also")
    except ValueError as exc:
        ap.error(str(exc))
    methods = ["unet"] if a.only_unets else [m for m in REGISTRY if m != "learned"]
    register_unets(extra)
    t = time.perf_counter()
    try:
        benchmark(a.corpus, methods=[*methods, *extra], runs_dir=a.runs, split="test", seed=0,
                  perceptual=False, repeats=1, samples_per_scene=a.samples_per_scene, progress=False,
                  resume=not a.no_resume)
    except ResumeError as exc:
        ap.error(str(exc))
    print(f"evaluation took {time.perf_counter() - t:.0f} s")
    runs = load_runs([Path(a.runs) / f"{safe_name(m)}.json" for m in [*methods, *extra]])
    ids = {s.get("scene_id") for r in runs for s in (r.get("scenes") or []) if s.get("scene_id") is not None}
    text = scene_field_tables(runs, scene_fields(a.corpus, sorted(ids)), list(extra))
    if text:
        print(text)
        atomic_write_text(Path(a.runs) / "scene_fields.md", text + "\n")


if __name__ == "__main__":
    main()
