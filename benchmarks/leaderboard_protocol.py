"""Leaderboard of the classical baselines and the U-Net on a protocol corpus's test split (docs/leaderboard-v1.md,
docs/leaderboard-v1-mini.md).

    lfmbench render --protocol lfmbench-v1-mini --out v1mini --workers 2
    lfmbench train --corpus v1mini --config lfmbench/configs/unet.yaml --out runs/unet_fusion.pt --epochs 16
    python benchmarks/leaderboard_protocol.py --corpus v1mini --checkpoint runs/unet_fusion.pt --runs runs/v1mini

    lfmbench render --protocol lfmbench-v1 --out v1 --workers 2            # or --split test, then --split train
    lfmbench train --corpus v1 --config lfmbench/configs/unet_v1.yaml --out runs/unet_v1.pt --epochs 12
    python benchmarks/leaderboard_protocol.py --corpus v1 --checkpoint runs/unet_v1.pt --runs runs/v1

Writes one result JSON per method, ``leaderboard.md``, ``leaderboard.json`` and ``leaderboard.png`` into ``--runs``
(8 frozen PWM draws per test scene, no perceptual metrics: PU21 / ColorVideoVDP add minutes and are secondary).
The tiny ``learned`` baseline is left out (its checkpoint is the demo's).
"""
from __future__ import annotations

import argparse
import os
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", required=True, help="protocol corpus root")
    ap.add_argument("--checkpoint", required=True, help="U-Net checkpoint (lfmbench train --out)")
    ap.add_argument("--runs", default="runs/protocol", help="output directory")
    ap.add_argument("--samples-per-scene", type=int, default=8)
    a = ap.parse_args()
    if not os.path.isfile(a.checkpoint):
        ap.error(f"--checkpoint {a.checkpoint}: no such file (make it with lfmbench train)")
    os.environ["LFMBENCH_UNET_CHECKPOINT"] = a.checkpoint
    from lfmbench.baselines import REGISTRY
    from lfmbench.evaluation import benchmark

    t = time.perf_counter()
    benchmark(a.corpus, methods=[m for m in REGISTRY if m != "learned"], runs_dir=a.runs, split="test", seed=0,
              perceptual=False, repeats=1, samples_per_scene=a.samples_per_scene, progress=False)
    print(f"evaluation took {time.perf_counter() - t:.0f} s")


if __name__ == "__main__":
    main()
