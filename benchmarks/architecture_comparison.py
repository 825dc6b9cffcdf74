"""Every sensor architecture on the same test scenes, ranked together (docs/sensor-architectures.md): the split
pixel (``ovt``) with three of its rule-based fusions, LOFIC, staggered, chopped and single exposure with their
standard merge (``exposure_select``), and each with a U-Net trained for that sensor when its checkpoint is given.

    lfmbench render --protocol lfmbench-v1 --split test --out v1 --workers 1
    lfmbench render --out demo --scenes 8 --profile small --seed 0          # the demo's corpus: its train split
    for s in ovt lofic staggered chopped single; do
      lfmbench train --method unet --sensor $s --corpus demo --config lfmbench/configs/unet_tiny.yaml --epochs 6 \
          --out runs/unet_$s.pt
    done
    python benchmarks/architecture_comparison.py --corpus v1 --runs runs/arch_v1 --samples-per-scene 2 \
        --unet ovt=runs/unet_ovt.pt --unet lofic=runs/unet_lofic.pt ...      # [--max-scenes 24]

One :func:`lfmbench.evaluation.benchmark.benchmark_sensors` call: per sensor its methods share each simulated
sample (runs in ``--runs/<sensor>/``), then one cross-sensor leaderboard (``--runs/leaderboard.{md,json,png}``);
no perceptual metrics and no ISP columns (secondary; minutes at 640x360). ``--max-scenes N`` scores the first N
scenes of the split (the first 24 of ``lfmbench-v1``'s test split are 8 day, 8 dusk, 8 night).
"""
from __future__ import annotations

import argparse
import time

#: The methods of each sensor (the U-Net is added where a checkpoint is given).
METHODS = {"ovt": ["saturated_exposure_corrected", "flicker_aware_two_sided", "lpd_only"],
           "lofic": ["exposure_select"], "staggered": ["exposure_select"], "chopped": ["exposure_select"],
           "single": ["exposure_select"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", required=True, help="corpus root (a protocol's test split)")
    ap.add_argument("--runs", default="runs/architectures", help="output directory")
    ap.add_argument("--samples-per-scene", type=int, default=2, help="frozen PWM draws per test scene")
    ap.add_argument("--max-scenes", type=int, default=None, help="score the first N scenes of the split")
    ap.add_argument("--unet", action="append", default=[], metavar="SENSOR=CHECKPOINT",
                    help="a U-Net trained for SENSOR (lfmbench train --method unet --sensor SENSOR); repeatable")
    a = ap.parse_args()
    unets = {}
    for item in a.unet:
        sensor, sep, path = item.partition("=")
        if not sep or sensor not in METHODS:
            ap.error(f"--unet {item!r}: give SENSOR=CHECKPOINT with SENSOR one of {', '.join(METHODS)}")
        unets[sensor] = path
    from lfmbench.evaluation.benchmark import benchmark_sensors

    sensors = {s: [*m, *(["unet"] if s in unets else [])] for s, m in METHODS.items()}
    t = time.perf_counter()
    try:
        benchmark_sensors(a.corpus, sensors, a.runs, checkpoints={s: {"unet": p} for s, p in unets.items()},
                          split="test", seed=0, perceptual=False, repeats=1, isp=None,
                          samples_per_scene=a.samples_per_scene, max_scenes=a.max_scenes, progress=False)
    except ValueError as exc:
        ap.error(str(exc))
    print(f"evaluation took {time.perf_counter() - t:.0f} s")


if __name__ == "__main__":
    main()
