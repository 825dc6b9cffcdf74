"""Cross-training: the U-Net trained on each of two protocols' train splits, each network scored on both test splits.

    python benchmarks/studies/cross_training.py --out xt                                   # v1-mini x v2-mini
    python benchmarks/studies/cross_training.py --out xt --seeds 0 1                       # a second training seed
    python benchmarks/studies/cross_training.py --out xt --protocols lfmbench-v1 lfmbench-v2 --config unet_v1 --epochs 12

Does the content of a corpus matter for what a network learns? For protocols ``A`` and ``B`` (default
``lfmbench-v1-mini`` and ``lfmbench-v2-mini``, whose scenes share ids, times of day, speeds and signals) protocol by
protocol it renders the test and train splits (``lfmbench render``), trains the U-Net on the train split (``lfmbench
train``, one network per seed) and scores, on the test split, every rule-based method and every
network trained so far on the same frozen PWM draws (the earlier test splits are scored again for the later
networks; :mod:`lfmbench.evaluation.protocol_run`; the network trained on the test
protocol's own train split is ``unet``, the others ``unet_<name>trained``, further seeds ``..._seed<k>``). It writes
``cross_training.md`` into ``--out``: the 2 x 2 table (training protocol x test protocol) of the LED score and
PSNR-mu with 95 % bootstrap CIs over scenes, and on each test split the network trained on the other protocol
paired against the one trained on the split's own, seed by seed and (several seeds) as the mean of each corpus's
networks (mean difference, its CI, Wilcoxon p; :func:`lfmbench.evaluation.stats.paired_test`); with several seeds
also each network against its corpus's first seed, the training noise the corpora's differences are to be read
against. ``steps.json`` holds every step's wall time.

It also draws ``fig_<split>.png`` per test split (``lfmbench plot``, run in this process: :func:`figure_step`): one
test scene through the display ISP, frames side by side: the captures, the ground truth, the seed-``--seeds[0]``
network of each training corpus (labelled ``unet_<name>trained``) and the rule-based method with the best mean LED
score on that split. The scene is the one where those two networks' PSNR-mu (mean over the scene's scored draws)
differ most, the first in scene-id order on a tie (:func:`figure_choice`); the plot shows its first sample (dataset
seed 0).

Every step is resumable and skipped when done: the renderer, the training and the scoring resume by themselves (a
killed scoring keeps the samples it scored; networks added later are scored alone), and a scoring whose result
files are all complete is not started, and a figure newer than its split's result files and networks is not drawn
again. Run it again after a kill. Used to report numbers
(docs/results/leaderboard-v2-mini.md), not a timed test.
"""
from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

#: Metrics of the tables (registered metric names): the primary score and the image-quality one.
METRICS = ("led_score", "psnr_mu")


def short(protocol: str) -> str:
    """``lfmbench-v2-mini`` -> ``v2mini`` (the corpus folder and method-name part of a protocol)."""
    s = re.sub(r"[^a-z0-9]+", "", Path(protocol).stem.lower().removeprefix("lfmbench-"))
    if not s:
        raise ValueError(f"protocol {protocol!r:.60}: no usable name")
    return s


def net_name(train_short: str, test_short: str, seed: int, seed0: int) -> str:
    """Method name of the network trained on ``train_short`` (seed ``seed``) when scored on ``test_short``."""
    base = "unet" if train_short == test_short else f"unet_{train_short}trained"
    return base if seed == seed0 else f"{base}_seed{seed}"


def _log(msg: str) -> None:
    print(f"{time.strftime('%H:%M:%S')} {msg}", flush=True)


class Steps:
    """Runs commands, each once: its wall time and return code go to ``steps.json`` (appended across reruns)."""

    def __init__(self, out: Path):
        self.path = out / "steps.json"
        self.rows = json.loads(self.path.read_text()) if self.path.is_file() else []

    def run(self, name: str, cmd: list[str], call: Callable[[list[str]], int] | None = None) -> None:
        """Run ``cmd`` as a subprocess, or (``call``) as ``call(cmd)`` in this process, which returns the exit code;
        a non-zero code stops the study naming the step."""
        _log(f"{name}: {' '.join(cmd)}")
        t = time.time()
        rc = subprocess.call(cmd) if call is None else call(cmd)
        self.rows.append({"step": name, "cmd": cmd, "wall_s": round(time.time() - t, 1), "rc": rc,
                          "ended_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())})
        from lfmbench.fileio import atomic_write_text  # noqa: PLC0415

        atomic_write_text(self.path, json.dumps(self.rows, indent=1) + "\n")
        if rc != 0:
            raise SystemExit(f"{name} failed (exit {rc}): {' '.join(cmd)}")


def cli_in_process(cmd: list[str]) -> int:
    """The exit code of ``cmd`` (``[python, -m, lfmbench.cli, *ARGS]``) run as ``lfmbench ARGS`` in this process
    (the same parsing and one-line errors as the command, without a second start of Python and torch)."""
    from lfmbench.cli import app  # noqa: PLC0415

    try:
        app(cmd[3:], prog_name="lfmbench")
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    return 0


def seed_config(config: str, seed: int, out: Path) -> str:
    """The training config ``config`` (a shipped name or a path) with ``train.seed = seed``, as a file in ``out``."""
    import yaml  # noqa: PLC0415

    from lfmbench.resources import find_config  # noqa: PLC0415

    data = yaml.safe_load(find_config(config, "training").read_text())
    if (data.get("train") or {}).get("seed", 0) == seed:
        return config
    data.setdefault("train", {})["seed"] = seed
    from lfmbench.fileio import atomic_write_text  # noqa: PLC0415

    path = out / f"{Path(config).stem}_seed{seed}.yaml"
    atomic_write_text(path, yaml.safe_dump(data, sort_keys=False))
    return str(path)


def scores_complete(runs: Path, methods: list[str]) -> bool:
    """Whether every method's result file in ``runs`` exists and says ``complete``."""
    from lfmbench.evaluation.benchmark import safe_name  # noqa: PLC0415
    from lfmbench.evaluation.results import COMPLETE  # noqa: PLC0415

    for m in methods:
        p = runs / f"{safe_name(m)}.json"
        try:
            if json.loads(p.read_text()).get("status") != COMPLETE:
                return False
        except (OSError, ValueError):
            return False
    return True


def _mean(values: list) -> float | None:
    """The mean of ``values``, None when one of them is missing (a scene one network did not score)."""
    return None if any(v is None for v in values) else sum(values) / len(values)


def summary(out: Path, shorts: list[str], seeds: list[int]) -> str:
    """Markdown of the 2 x 2 table and the paired tests, from the result files under ``out/scores``."""
    from lfmbench.evaluation import stats  # noqa: PLC0415
    from lfmbench.evaluation.results import metric_summary, per_scene  # noqa: PLC0415

    def load(test: str, name: str) -> list[dict]:
        r = json.loads((out / "scores" / test / f"{name}.json").read_text())
        return per_scene(r.get("scenes") or [], METRICS)

    def cell(rows: list[dict], metric: str) -> str:
        s = metric_summary(rows, metric)
        (lo, hi), d = s["ci"], (3 if metric == "led_score" else 2)
        return f"{s['value']:.{d}f} [{lo:.{d}f}, {hi:.{d}f}]"

    lines = ["LED score and PSNR-mu (dB) [95 % CI over scenes]; rows: the network's training split and seed, "
             "columns: the test split", "",
             "| trained on | seed | " + " | ".join(f"{t}: LED score | {t}: PSNR-mu dB" for t in shorts) + " |",
             "|---|---|" + "---|---|" * len(shorts)]
    table = {}
    for tr in shorts:
        for seed in seeds:
            cells = []
            for te in shorts:
                rows = load(te, net_name(tr, te, seed, seeds[0]))
                table[(tr, seed, te)] = rows
                cells += [cell(rows, "led_score"), cell(rows, "psnr_mu")]
            lines.append(f"| {tr} | {seed} | " + " | ".join(cells) + " |")

    def paired(mine: dict, ref: dict) -> str:
        """Cells "diff [CI] | p" per metric and n: per-scene values ``mine`` minus ``ref`` ({scene: metrics})."""
        cells, n = [], 0
        for m in METRICS:
            t = stats.paired_by_scene({sid: v.get(m) for sid, v in mine.items()},
                                      {sid: v.get(m) for sid, v in ref.items()})
            (lo, hi), d, n = t["ci"], (3 if m == "led_score" else 2), t["n"]
            cells.append(f"{t['mean_diff']:+.{d}f} [{lo:+.{d}f}, {hi:+.{d}f}] | {t['p']:.4f}")
        return " | ".join(cells) + f" | {n} |"

    by_scene = {key: {s["scene_id"]: s["metrics"] for s in rows} for key, rows in table.items()}

    def scenes(tr: str, seed: int, te: str) -> dict:
        return by_scene[(tr, seed, te)]

    head = ["| test split | network | " + " | ".join(f"{m}: diff [CI] | p" for m in METRICS) + " | n |",
            "|---|---|" + "---|---|" * len(METRICS) + "---|"]
    lines += ["", "Paired over the test split's scenes, the network trained on the other protocol minus the one "
              "trained on the test split's, of the same seed" + (" and (`mean`) the mean of each corpus's networks"
                                                                 if len(seeds) > 1 else "")
              + " (mean diff [95 % CI], Wilcoxon p, n scenes):", "", *head]
    for te in shorts:
        for tr in (t for t in shorts if t != te):
            for seed in seeds:
                lines.append(f"| {te} | {tr} - {te}, seed {seed} | "
                             + paired(scenes(tr, seed, te), scenes(te, seed, te)))
            if len(seeds) > 1:
                mean = [{sid: {m: _mean([scenes(t, k, te).get(sid, {}).get(m) for k in seeds]) for m in METRICS}
                         for sid in scenes(t, seeds[0], te)} for t in (tr, te)]
                lines.append(f"| {te} | {tr} - {te}, mean | " + paired(*mean))
    if len(seeds) > 1:  # training noise: the scale the corpora's differences are to be read against
        lines += ["", f"Training noise: each network minus the network of seed {seeds[0]} trained on the same "
                  "protocol, on each test split (mean diff [95 % CI], Wilcoxon p, n scenes):", "", *head]
        for te in shorts:
            for tr in shorts:
                for seed in seeds[1:]:
                    lines.append(f"| {te} | {tr}, seed {seed} - seed {seeds[0]} | "
                                 + paired(scenes(tr, seed, te), scenes(tr, seeds[0], te)))
    return "\n".join(lines) + "\n"


def figure_choice(runs: Path, shorts: list[str], test: str, seed0: int) -> tuple[str, str]:
    """``(scene id, rule-based method)`` of the figure of test split ``test`` from its result files in ``runs``: the
    scene where the seed-``seed0`` networks of the two training corpora differ most in PSNR-mu (dB, the mean over
    the scene's scored draws; on a tie the first in scene-id order), and the registered rule-based method (not a
    learned one) with the highest mean LED score over the split's scenes (on a tie the first in registry order).

    Raises:
        SystemExit: naming the split when no scene has both networks' PSNR-mu or no rule-based method was scored.
    """
    from lfmbench.baselines import LEARNED, REGISTRY  # noqa: PLC0415
    from lfmbench.evaluation.benchmark import safe_name  # noqa: PLC0415
    from lfmbench.evaluation.results import metric_summary, per_scene  # noqa: PLC0415

    def scenes(name: str) -> list[dict]:
        return per_scene(json.loads((runs / f"{safe_name(name)}.json").read_text()).get("scenes") or [], METRICS)

    a, b = ({s["scene_id"]: s["metrics"].get("psnr_mu") for s in scenes(net_name(tr, test, seed0, seed0))}
            for tr in shorts)
    gaps = {sid: abs(a[sid] - b[sid]) for sid in sorted(a)
            if a[sid] is not None and b.get(sid) is not None and math.isfinite(a[sid] - b[sid])}
    rules = [m for m in REGISTRY if m not in LEARNED and (runs / f"{safe_name(m)}.json").is_file()]
    if not gaps or not rules:
        why = "no scene with the PSNR-mu of both networks" if not gaps else "no rule-based method scored"
        raise SystemExit(f"figure {test}: {why} in {runs}")
    led = {m: metric_summary(scenes(m), "led_score", ci=False)["value"] for m in rules}
    return max(gaps, key=gaps.__getitem__), max(rules, key=lambda m: -math.inf if led[m] is None else led[m])


def figure_step(steps: Steps, cli: list[str], out: Path, corpus: Path, test: str, shorts: list[str], seed0: int,
                nets: dict[tuple[str, int], Path]) -> Path:
    """Write ``out/fig_<test>.png`` (:func:`figure_choice`'s scene and rule, the seed-``seed0`` network of each
    training corpus as ``unet_<name>trained``) with ``lfmbench plot`` run in this process, recorded in ``steps``;
    skipped when the PNG is newer than the split's result files and those networks."""
    png = out / f"fig_{test}.png"
    runs = out / "scores" / test
    inputs = [*runs.glob("*.json"), *(nets[(tr, seed0)] for tr in shorts)]
    if png.is_file() and png.stat().st_mtime >= max(p.stat().st_mtime for p in inputs):
        _log(f"figure {test}: up to date, skipped")
        return png
    scene, rule = figure_choice(runs, shorts, test, seed0)
    cmd = [*cli, "plot", "--corpus", str(corpus), "--split", "test", "--scene", scene, "--method", rule]
    for tr in shorts:
        cmd += ["--unet", f"unet_{tr}trained={nets[(tr, seed0)]}"]
    steps.run(f"figure {test}", cmd + ["--out", str(png)], call=cli_in_process)
    return png


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="work folder: corpora, networks, scores, summary")
    ap.add_argument("--protocols", nargs=2, default=["lfmbench-v1-mini", "lfmbench-v2-mini"],
                    help="two protocols (names or YAML paths) with test and train splits")
    ap.add_argument("--config", default="unet", help="training config (shipped name or YAML path)")
    ap.add_argument("--epochs", type=int, default=16)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0], help="training seeds (one network each)")
    ap.add_argument("--samples-per-scene", type=int, default=8, help="frozen PWM draws scored per test scene")
    ap.add_argument("--threads", type=int, default=None, help="torch CPU threads of the trainings")
    ap.add_argument("--workers", type=int, default=1, help="render and DataLoader workers")
    a = ap.parse_args(argv)
    shorts = [short(p) for p in a.protocols]
    if shorts[0] == shorts[1]:
        ap.error(f"--protocols: two different protocols needed, got {a.protocols}")
    if len(set(a.seeds)) != len(a.seeds):
        ap.error(f"--seeds: each seed once, got {a.seeds}")
    out = a.out
    out.mkdir(parents=True, exist_ok=True)
    steps = Steps(out)
    cli = [sys.executable, "-m", "lfmbench.cli"]
    corpus = {s: out / "corpus" / s for s in shorts}
    nets = {(s, seed): out / "nets" / f"unet_{s}_seed{seed}.pt" for s in shorts for seed in a.seeds}

    def score(te: str, trained: list[str]) -> None:
        """Score test split ``te``: every rule-based method, and the networks of the protocols in ``trained``."""
        runs = out / "scores" / te
        extra = {net_name(tr, te, seed, a.seeds[0]): nets[(tr, seed)]
                 for tr in trained for seed in a.seeds if (tr, seed) != (te, a.seeds[0])}
        from lfmbench.baselines import REGISTRY  # noqa: PLC0415

        methods = [m for m in REGISTRY if m != "learned"] + list(extra)
        if scores_complete(runs, methods):
            _log(f"score {te}: complete, skipped")
            return
        cmd = [sys.executable, "-m", "lfmbench.evaluation.protocol_run", "--corpus", str(corpus[te]),
               "--checkpoint", str(nets[(te, a.seeds[0])]), "--runs", str(runs),
               "--samples-per-scene", str(a.samples_per_scene)]
        for name, path in extra.items():
            cmd += ["--unet-also", f"{name}={path}"]
        steps.run(f"score {te}", cmd)

    # Protocol by protocol (render, train, score with the networks trained so far), then each earlier test split
    # again for the later networks (a resumed scoring scores only those): every step's result is usable as soon
    # as it ends, and a long run stopped half-way leaves whole results of the first protocol.
    for i, (p, s) in enumerate(zip(a.protocols, shorts)):
        for split in ("test", "train"):
            steps.run(f"render {s} {split}", [*cli, "render", "--protocol", p, "--split", split, "--out",
                                              str(corpus[s]), "--workers", str(a.workers)])
        for seed in a.seeds:
            nets[(s, seed)].parent.mkdir(parents=True, exist_ok=True)
            cmd = [*cli, "train", "--corpus", str(corpus[s]), "--config", seed_config(a.config, seed, out),
                   "--out", str(nets[(s, seed)]), "--epochs", str(a.epochs), "--workers", str(a.workers)]
            steps.run(f"train {s} seed {seed}", cmd + (["--threads", str(a.threads)] if a.threads else []))
        score(s, shorts[:i + 1])
    for te in shorts[:-1]:
        score(te, shorts)
    text = summary(out, shorts, a.seeds)
    from lfmbench.fileio import atomic_write_text  # noqa: PLC0415

    atomic_write_text(out / "cross_training.md", text)
    print(text)
    for te in shorts:
        figure_step(steps, cli, out, corpus[te], te, shorts, a.seeds[0], nets)


if __name__ == "__main__":
    main()
