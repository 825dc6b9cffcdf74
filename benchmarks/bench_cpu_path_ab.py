"""The CPU per-sample dataset path against an older commit, in one run (issue 41): samples per second of
:class:`lfmbench.datasets.LFMCaptureDataset` (generator noise streams, what a DataLoader worker runs) with this
tree and with a git worktree of ``--ref`` (default 0db2162, before the device path), alternating the two.

Each case is a child process per measurement (``PYTHONPATH`` the tree under test, one torch thread as in a
DataLoader worker): the dataset is built, one pass over its samples fills the in-memory layer cache, then
``--passes`` timed passes; the child reports the median pass as samples/s. Old and new alternate (old, new, old,
...) ``--pairs`` times per case; the ratio is new / old of the medians. Both read the same corpus (written by the
*old* code's fake-corpus helper of ``tests/data/corpus``, so the old reader surely reads it; fake radiance of 3
bands), each from its own copy (their on-disk layer caches apart). Cases: the test corpus's 16 x 24 px scenes
with 12 x 16 crops, and 256 x 320 px scenes with 256 x 256 crops.

Writes ``docs/benchmarks/cpu-path.md``. Run: ``python benchmarks/bench_cpu_path_ab.py [--ref 0db2162] [--pairs 5]``
(about 5 min on 2 quiet cores).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lfmbench.fileio import atomic_write_text  # noqa: E402

#: Written by the old tree: ``make(root, width, height, n_scenes)`` as ``tests.data.corpus.data.make_corpus``,
#: at any size.
MAKE = """
import sys
from lfmbench import corpus as C
from tests.data.corpus import data as d
root, W, H, n = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
w = C.CorpusWriter(root)
for i in range(n):
    meta = d.fake_meta(f"scene{i:05d}", width=W, height=H, frames=3, bins=4, n_lights=2)
    fr = d.scale_frames(d.fake_frames(meta, seed=i), 1e-3, 1e-3, False)
    w.write_scene(meta["scene_id"], d.fake_scene(meta["scene_id"]), meta, fr)
w.write_splits(0)
"""

#: Timed in a child of the tree under test: median samples/s of ``passes`` passes after a warm one.
TIME = """
import json, statistics, sys, time
import torch
torch.set_num_threads(1)
from lfmbench.datasets import LFMCaptureDataset
root, ch, cw, sps, passes = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
ds = LFMCaptureDataset(root, split="all", frames=3, crop=(ch, cw), samples_per_scene=sps, seed=0, frame_start=0,
                       outputs=("raw", "input_referred", "saturated", "gt", "light_index", "depth"))
for i in range(len(ds)):
    ds[i]
rates = []
for p in range(passes):
    ds.set_epoch(p + 1)
    t = time.perf_counter()
    for i in range(len(ds)):
        ds[i]
    rates.append(len(ds) / (time.perf_counter() - t))
print(json.dumps({"rate": statistics.median(rates), "n": len(ds)}))
"""

#: (name, scene width, height, crop h, crop w, scenes, samples per scene)
CASES = [("16 x 24 px scenes, 12 x 16 crops", 24, 16, 12, 16, 3, 8),
         ("256 x 320 px scenes, 256 x 256 crops", 320, 256, 256, 256, 2, 3)]


def _run(tree: Path, code: str, *args) -> str:
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"}
    r = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, env=env,
                       cwd=str(tree))
    if r.returncode != 0:
        raise RuntimeError(f"{tree}: {r.stderr[-3000:]}")
    return r.stdout


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ref", default="0db2162")
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--passes", type=int, default=3)
    a = ap.parse_args()
    ref = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", a.ref], capture_output=True, text=True,
                         check=True).stdout.strip()
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()
    tmp = Path(tempfile.mkdtemp(prefix="lfm_ab_"))
    old = tmp / "old"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(old), ref], check=True,
                   capture_output=True)
    load0 = os.getloadavg()
    rows = []
    try:
        for name, W, H, ch, cw, n, sps in CASES:
            base = tmp / f"c{W}x{H}"
            _run(old, MAKE, base, W, H, n)
            trees = {"old": old, "new": ROOT}
            roots = {}
            for k in trees:
                roots[k] = tmp / f"c{W}x{H}-{k}"
                shutil.copytree(base, roots[k])
            got: dict[str, list[float]] = {"old": [], "new": []}
            for p in range(a.pairs):
                for k in ("old", "new"):
                    got[k].append(json.loads(_run(trees[k], TIME, roots[k], ch, cw, sps, a.passes))["rate"])
                print(f"{name}: pair {p + 1}: old {got['old'][-1]:.1f}, new {got['new'][-1]:.1f} samples/s",
                      flush=True)
            med = {k: statistics.median(v) for k, v in got.items()}
            rows.append((name, n * sps, med, got))
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old)], capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)
    load1 = os.getloadavg()
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), "?") if Path("/proc/cpuinfo").exists() else "?"
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = ["# The CPU per-sample path against an older commit", "",
             f"Generated by `benchmarks/bench_cpu_path_ab.py --ref {a.ref} --pairs {a.pairs} --passes {a.passes}` on "
             f"{stamp} ({cpu}, {os.cpu_count()} CPUs; load average {load0[0]:.1f} at the start, {load1[0]:.1f} at "
             f"the end: a shared machine). `{head}` (this tree) against `{ref}` (a git worktree), one torch thread "
             "(as a DataLoader worker), `LFMCaptureDataset(split='all', frames=3, frame_start=0)` with every output "
             "but rgb, generator noise, layers cached in memory after a warm pass; samples/s of the median of "
             f"{a.passes} passes, measured {a.pairs} times per tree, old and new alternating; medians of those.", "",
             "| case | samples per pass | old samples/s | new samples/s | new / old | runs old | runs new |",
             "|---|---|---|---|---|---|---|"]
    for name, n, med, got in rows:
        lines.append(f"| {name} | {n} | {med['old']:.1f} | {med['new']:.1f} | {med['new'] / med['old']:.2f} | "
                     f"{', '.join(f'{x:.1f}' for x in got['old'])} | {', '.join(f'{x:.1f}' for x in got['new'])} |")
    lines += ["", "The fake corpus (3 wavelength bands, written by the old tree's test helper) is not a rendered "
              "one: the per-sample work is the same code path, with fewer bands to project.", ""]
    out = ROOT / "docs" / "benchmarks" / "cpu-path.md"
    atomic_write_text(out, "\n".join(lines))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
