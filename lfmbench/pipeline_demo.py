"""The end-to-end demo behind ``make demo`` (settings: ``lfmbench/configs/demo.yaml``).

1. render the small default corpus (fast Mitsuba path; resumable, so a second run reuses it);
2. train the learned baseline and the tiny U-Net (``unet.config`` of the demo config, by default
   ``lfmbench/configs/unet_tiny.yaml``) through the DataLoader (each skipped when its checkpoint exists);
3. evaluate every registered baseline on the test split and print the leaderboard;
4. reproduce the paper's figures from the corpus.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import yaml

CONFIG = Path(__file__).resolve().parent / "configs" / "demo.yaml"


def _step(title: str) -> float:
    print(f"\n== {title}", flush=True)
    return time.perf_counter()


def run(out: str | Path | None = None, config: str | Path = CONFIG) -> dict:
    """Run the demo; returns ``{"rows": leaderboard rows, "figures": [paths], "seconds": {step: s}}``."""
    cfg = yaml.safe_load(Path(config).read_text())
    out = Path(out or cfg["out_dir"])
    corpus, runs, figs = out / "corpus", out / "runs", out / "figures"
    secs: dict[str, float] = {}
    r = cfg["render"]
    t = _step(f"1. render {r['scenes']} scenes ({r['profile']} profile) into {corpus}")
    cmd = [sys.executable, "-m", "lfmbench.cli", "render", "--out", str(corpus), "--scenes", str(r["scenes"]),
           "--profile", r["profile"], "--seed", str(r["seed"]), "--workers", str(r["workers"])]
    subprocess.run(cmd, check=True)
    secs["render"] = time.perf_counter() - t

    ckpt = out / "learned_fusion.pt"
    os.environ["LFMBENCH_LEARNED_CHECKPOINT"] = str(ckpt)
    tr = cfg["train"]
    t = _step(f"2. train the learned baseline -> {ckpt}")
    if ckpt.is_file():
        print(f"   {ckpt} exists: reused (delete it to retrain)")
    else:
        subprocess.run([sys.executable, "-m", "lfmbench.baselines.learned", "--corpus", str(corpus),
                        "--checkpoint", str(ckpt), "--epochs", str(tr["epochs"]), "--crop", str(tr["crop"]),
                        "--batch-size", str(tr["batch_size"]), "--workers", str(tr["workers"])], check=True)
    secs["train"] = time.perf_counter() - t

    uck = out / "unet_fusion.pt"
    os.environ["LFMBENCH_UNET_CHECKPOINT"] = str(uck)
    un = cfg.get("unet", {})
    t = _step(f"2b. train the tiny U-Net baseline -> {uck}")
    if uck.is_file():
        print(f"   {uck} exists: reused (delete it to retrain)")
    else:
        from lfmbench.baselines.unet import TINY_CONFIG
        cmd = [sys.executable, "-m", "lfmbench.cli", "train", "--corpus", str(corpus), "--out", str(uck),
               "--config", str(un.get("config") or TINY_CONFIG)]
        for key in ("epochs", "workers"):
            if un.get(key) is not None:
                cmd += [f"--{key}", str(un[key])]
        subprocess.run(cmd, check=True)
    secs["train_unet"] = time.perf_counter() - t

    from lfmbench.evaluation import benchmark
    ev = cfg["evaluate"]
    t = _step(f"3. evaluate every baseline on the {ev['split']} split -> {runs}")
    rows = benchmark(corpus, runs_dir=runs, split=ev["split"], seed=ev["seed"], repeats=ev["repeats"],
                     perceptual=ev["perceptual"], samples_per_scene=ev["samples_per_scene"])
    secs["evaluate"] = time.perf_counter() - t

    from lfmbench.paper_figures import make_all
    t = _step(f"4. reproduce the paper's figures -> {figs}")
    paths = make_all(corpus, figs)
    for p in paths:
        print(f"   {p}")
    secs["figures"] = time.perf_counter() - t
    print("\ndone in " + ", ".join(f"{k} {v:.0f} s" for k, v in secs.items()) +
          f". Leaderboard: {runs / 'leaderboard.md'} and {runs / 'leaderboard.png'}")
    return {"rows": rows, "figures": paths, "seconds": secs}
