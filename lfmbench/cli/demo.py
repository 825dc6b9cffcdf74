"""``lfmbench demo``: the end-to-end demo behind ``make demo`` (settings: ``lfmbench/configs/demo.yaml``).

0. print the flicker model at the paper's Fig. 3 settings (no render);

1. render the small default corpus (fast Mitsuba path; resumable, so a second run reuses it);
2. train every learned baseline of :data:`lfmbench.baselines.LEARNED` (``lfmbench train --method
   NAME`` with its options under ``train`` of the demo config; the U-Net with ``lfmbench/configs/unet_tiny.yaml``),
   each skipped when its checkpoint exists;
3. evaluate every registered baseline on the test split and print the leaderboard;
4. reproduce the paper's figures from the corpus.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import typer


from lfmbench.paper.fig3 import FIG3_EXPOSURES_S, fig3_series

__all__ = ["CONFIG", "run", "main", "register"]

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "demo.yaml"


def _step(title: str) -> float:
    print(f"\n== {title}", flush=True)
    return time.perf_counter()


def _train(name: str, opts: dict, corpus: Path, out: Path) -> float:
    """Step 2 for one learned baseline: ``lfmbench train --method NAME`` with the demo's options, unless its
    checkpoint ``out/<name>_fusion.pt`` exists; its environment variable then points the evaluation at it.
    Returns the seconds taken."""
    from lfmbench.train import trainable

    spec = trainable(name)
    ckpt = out / spec.default_checkpoint.name
    os.environ[spec.checkpoint_env] = str(ckpt)
    t = _step(f"2. train the {name} baseline -> {ckpt}")
    if ckpt.is_file():
        print(f"   {ckpt} exists: reused (delete it to retrain)")
    else:
        cmd = [sys.executable, "-m", "lfmbench.cli", "train", "--method", name, "--corpus", str(corpus),
               "--out", str(ckpt)]
        if opts.get("config"):
            path = Path(opts["config"])
            cmd += ["--config", str(path if path.exists() else CONFIG.parent / path)]
        for key in ("epochs", "workers", "crop", "batch_size"):
            if opts.get(key) is not None:
                cmd += [f"--{key.replace('_', '-')}", str(opts[key])]
        subprocess.run(cmd, check=True)
    return time.perf_counter() - t


def run(out: str | Path | None = None, config: str | Path = CONFIG) -> dict:
    """Run the demo; returns ``{"rows": leaderboard rows, "figures": [paths], "seconds": {step: s}}``."""
    from lfmbench.fileio import load_yaml  # noqa: PLC0415

    cfg = load_yaml(config)
    out = Path(out or cfg["out_dir"])
    corpus, runs, figs = out / "corpus", out / "runs", out / "figures"
    secs: dict[str, float] = {}
    r = cfg["render"]
    t = _step(f"1. render {r['scenes']} scenes ({r['profile']} profile) into {corpus}")
    cmd = [sys.executable, "-m", "lfmbench.cli", "render", "--out", str(corpus), "--scenes", str(r["scenes"]),
           "--profile", r["profile"], "--seed", str(r["seed"]), "--workers", str(r["workers"])]
    subprocess.run(cmd, check=True)
    secs["render"] = time.perf_counter() - t

    from lfmbench.baselines import LEARNED  # noqa: PLC0415

    opts = cfg.get("train") or {}
    unknown = sorted(set(opts) - set(LEARNED))
    if unknown:
        raise ValueError(f"{config}: train: {unknown} are not learned baselines ({', '.join(LEARNED)})")
    for name in LEARNED:
        secs[f"train_{name}"] = _train(name, opts.get(name) or {}, corpus, out)

    from lfmbench.evaluation.benchmark import benchmark
    ev = cfg["evaluate"]
    t = _step(f"3. evaluate every baseline on the {ev['split']} split -> {runs}")
    rows = benchmark(corpus, runs_dir=runs, split=ev["split"], seed=ev["seed"], repeats=ev["repeats"],
                     perceptual=ev["perceptual"], samples_per_scene=ev["samples_per_scene"],
                     resume=False)  # scored afresh: a retrained network or an edited config must not stop the demo
    secs["evaluate"] = time.perf_counter() - t

    from lfmbench.paper.figures import make_all
    t = _step(f"4. reproduce the paper's figures -> {figs}")
    paths = make_all(corpus, figs)
    for p in paths:
        print(f"   {p}")
    secs["figures"] = time.perf_counter() - t
    print("\ndone in " + ", ".join(f"{k} {v:.0f} s" for k, v in secs.items()) +
          f". Leaderboard: {runs / 'leaderboard.md'} and {runs / 'leaderboard.png'}")
    return {"rows": rows, "figures": paths, "seconds": secs}


def main(out: str | Path | None = None, config: str | Path = CONFIG) -> dict:
    """The flicker model at the paper's Fig. 3 settings, then :func:`run`; returns what :func:`run` returns."""
    s = fig3_series(frames=12)
    print("Flicker model (paper Fig. 3 settings: 95 Hz, D = 0.2, 30 fps):")
    for te in FIG3_EXPOSURES_S:
        print(f"  te = {te * 1e3:5.2f} ms  Phi[n] (ms ON) = {' '.join(f'{v * 1e3:.3f}' for v in s[te][:6])} ...  "
              f"FSI = {s[('fsi', te)]:.3f}")
    return run(out, config)


def demo_cmd(
    out: Path = typer.Option(None, "--out", help="output directory (default: out_dir of the config)"),
    config: str = typer.Option("demo", "--config", help="demo settings: a YAML path or a shipped name "
                                                        "(lfmbench configs demo)"),
) -> None:
    """Render the small demo corpus, train the learned baselines, evaluate every baseline and reproduce the
    paper's figures (what ``make demo`` runs; resumable: a second run reuses the corpus and checkpoints)."""
    from lfmbench.cli._common import check_local_paths
    from lfmbench.resources import ConfigNotFoundError, find_config  # noqa: PLC0415

    check_local_paths((("--out", out),))
    try:
        path = find_config(config, "demo")
    except ConfigNotFoundError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    main(out, path)


def register(app: typer.Typer) -> None:
    """Add ``demo`` to the ``lfmbench`` app."""
    app.command("demo")(demo_cmd)
