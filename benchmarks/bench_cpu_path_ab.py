"""The CPU per-sample dataset path against an older commit, in one run (issue 41): samples per second of
:class:`lfmbench.datasets.LFMCaptureDataset` (generator noise streams, what a DataLoader worker runs) with this
tree and with a git worktree of ``--ref`` (default 0db2162, before the device path), alternating the two.

Each case is a child process per measurement (``PYTHONPATH`` the tree under test, one torch thread as in a
DataLoader worker): the dataset is built, one pass over its samples fills the in-memory layer cache, then
``--passes`` timed passes (epochs 1, 2, ...); the child reports the median pass as samples/s of wall time and of
CPU time (``time.process_time``, which a busy machine inflates less than wall time). Old and new alternate (old,
new, old, ...) ``--pairs`` times per case; the ratio is new / old of the medians. Both read the same corpus
(written by the *old* code's fake-corpus helper of ``tests/data/corpus``, so the old reader surely reads it; fake
radiance of 3 bands), each from its own copy (their on-disk layer caches apart). Cases: the test corpus's
16 x 24 px scenes with 12 x 16 crops, and 256 x 320 px scenes with 256 x 256 crops.

Like for like: the cost of the Poisson draws depends on the electron levels drawn, so both trees must simulate
the same samples. Each child hashes, untimed, every output tensor and the drawn crop and PWM values of the warm
pass (epoch 0) and of epoch 1 (SHA-256); the run stops if the two trees' hashes differ.

``--instructions`` adds, per case and tree, the instructions executed by one timed pass under valgrind's
callgrind (collection switched on around the pass only, through callgrind's client requests in a three-line C
helper built with ``cc``; needs valgrind and its headers): a count that does not depend on the machine's load.
About 2 min of CPU per child; the four children run at once after the timings (6-8 min of wall time at load 20).

Writes ``docs/benchmarks/cpu-path.md``. Run: ``python benchmarks/bench_cpu_path_ab.py [--ref 0db2162] [--pairs 5]
[--instructions]`` (about 5 min on 2 quiet cores without ``--instructions``).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
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

#: Timed in a child of the tree under test: median samples/s (wall and CPU) of ``passes`` passes after a warm one,
#: and the SHA-256 of the warm pass's and epoch 1's samples (untimed). With ``cg`` (a path) set, callgrind collects
#: instructions around each timed pass only.
TIME = """
import ctypes, hashlib, json, statistics, sys, time
import torch
torch.set_num_threads(1)
from lfmbench.datasets import LFMCaptureDataset
root, ch, cw, sps, passes, cg = (sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]),
                                 sys.argv[6])
cg = ctypes.CDLL(cg) if cg else None
ds = LFMCaptureDataset(root, split="all", frames=3, crop=(ch, cw), samples_per_scene=sps, seed=0, frame_start=0,
                       outputs=("raw", "input_referred", "saturated", "gt", "light_index", "depth"))
digest = hashlib.sha256()
def pass_digest():
    for i in range(len(ds)):
        s = ds[i]
        for k in sorted(s):
            if k != "meta":
                digest.update(f"{k}{s[k].dtype}{tuple(s[k].shape)}".encode())
                digest.update(s[k].contiguous().numpy().tobytes())
        for k in ("scene_id", "crop", "light_id", "freq_hz", "duty", "phase_s", "exposure_short_s", "exposure_long_s"):
            v = s["meta"][k]
            digest.update(v.numpy().tobytes() if torch.is_tensor(v) else repr(v).encode())
pass_digest()
rates, cpu = [], []
for p in range(passes):
    ds.set_epoch(p + 1)
    t, c = time.perf_counter(), time.process_time()
    if cg:
        cg.cg_start()
    for i in range(len(ds)):
        ds[i]
    if cg:
        cg.cg_stop()
    cpu.append(len(ds) / (time.process_time() - c))
    rates.append(len(ds) / (time.perf_counter() - t))
ds.set_epoch(1)
pass_digest()
print(json.dumps({"rate": statistics.median(rates), "cpu_rate": statistics.median(cpu), "n": len(ds),
                  "sha256": digest.hexdigest()}))
"""

#: Callgrind's client requests, called from the timed child through ctypes (``--instructions``).
CG_C = """#include <valgrind/callgrind.h>
void cg_start(void) { CALLGRIND_START_INSTRUMENTATION; CALLGRIND_TOGGLE_COLLECT; }
void cg_stop(void) { CALLGRIND_TOGGLE_COLLECT; CALLGRIND_STOP_INSTRUMENTATION; }
"""

#: (name, scene width, height, crop h, crop w, scenes, samples per scene)
CASES = [("16 x 24 px scenes, 12 x 16 crops", 24, 16, 12, 16, 3, 8),
         ("256 x 320 px scenes, 256 x 256 crops", 320, 256, 256, 256, 2, 3)]


def _run(tree: Path, code: str, *args, prefix: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"}
    r = subprocess.run([*prefix, sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True,
                       env=env, cwd=str(tree))
    if r.returncode != 0:
        raise RuntimeError(f"{tree}: {r.stderr[-3000:]}")
    return r


def _callgrind_helper(tmp: Path) -> Path:
    """Builds the client-request helper into ``tmp``; one-line error when valgrind or cc is missing."""
    if shutil.which("valgrind") is None or shutil.which("cc") is None:
        raise SystemExit("--instructions: needs valgrind (with its headers) and cc on PATH")
    atomic_write_text(tmp / "cg.c", CG_C)
    r = subprocess.run(["cc", "-O2", "-shared", "-fPIC", str(tmp / "cg.c"), "-o", str(tmp / "libcg.so")],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"--instructions: cannot build the callgrind helper: {r.stderr.strip().splitlines()[-1]}")
    return tmp / "libcg.so"


def _instructions(tree: Path, root: Path, ch: int, cw: int, sps: int, lib: Path, stem: Path) -> tuple[int, str]:
    """Instructions of one timed pass of ``tree`` under callgrind (its output file ``stem``.out, removed after),
    and the samples' SHA-256."""
    out = stem.with_suffix(".out")
    r = _run(tree, TIME, root, ch, cw, sps, 1, lib, prefix=(
        "valgrind", "--tool=callgrind", "--instr-atstart=no", "--collect-atstart=no", f"--callgrind-out-file={out}"))
    out.unlink(missing_ok=True)
    m = re.search(r"Collected\s*:\s*([0-9]+)", r.stderr)
    if m is None:
        raise RuntimeError(f"{tree}: no instruction count in callgrind's output: {r.stderr[-1000:]}")
    return int(m.group(1)), json.loads(r.stdout.strip().splitlines()[-1])["sha256"]


def _page(a: argparse.Namespace, head: str, ref: str, rows: list, load0, load1) -> str:
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), "?") if Path("/proc/cpuinfo").exists() else "?"
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    flags = f"--ref {a.ref} --pairs {a.pairs} --passes {a.passes}" + (" --instructions" if a.instructions else "")
    lines = ["# The CPU per-sample path against an older commit", "",
             f"Generated by `python benchmarks/bench_cpu_path_ab.py {flags}` on {stamp} ({cpu}, {os.cpu_count()} "
             f"CPUs; load average {load0[0]:.1f} at the start, {load1[0]:.1f} at the end: a shared machine). "
             f"`{head}` (this tree) against `{ref}` (a git worktree), one torch thread (as a DataLoader worker), "
             "`LFMCaptureDataset(split='all', frames=3, frame_start=0)` with every output but rgb, generator noise, "
             f"layers cached in memory after a warm pass; samples/s of the median of {a.passes} passes (epochs 1 to "
             f"{a.passes}, the same in both trees), measured {a.pairs} times per tree, old and new alternating; "
             "medians of those. Wall: samples per second of elapsed time; CPU: per second of the process's CPU "
             "time (less inflated by other processes on the machine, not immune: they share caches and cores).",
             "", "Like for like: both trees simulated bit-identical samples in every case (SHA-256 of every output "
             "tensor and of the drawn crops and PWM values, epochs 0 and 1, equal in every run).", "",
             "| case | samples per pass | old wall samples/s | new wall samples/s | wall new / old | "
             "old CPU samples/s | new CPU samples/s | CPU new / old | runs old (wall) | runs new (wall) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, n, med, got, _ in rows:
        lines.append(
            f"| {name} | {n} | {med['old']['rate']:.1f} | {med['new']['rate']:.1f} | "
            f"{med['new']['rate'] / med['old']['rate']:.2f} | {med['old']['cpu_rate']:.1f} | "
            f"{med['new']['cpu_rate']:.1f} | {med['new']['cpu_rate'] / med['old']['cpu_rate']:.2f} | "
            f"{', '.join(f'{x:.1f}' for x in got['old']['rate'])} | "
            f"{', '.join(f'{x:.1f}' for x in got['new']['rate'])} |")
    if a.instructions:
        lines += ["", "Instructions executed by one timed pass (epoch 1) under valgrind's callgrind, collected around "
                  "the pass only: independent of the machine's load (it counts work, not cache misses or waits).", "",
                  "| case | old instructions per sample | new instructions per sample | new / old |",
                  "|---|---|---|---|"]
        for name, n, _, _, ins in rows:
            lines.append(f"| {name} | {ins['old'] / n / 1e6:.2f} M | {ins['new'] / n / 1e6:.2f} M | "
                         f"{ins['new'] / ins['old']:.4f} |")
    lines += ["", "The fake corpus (3 wavelength bands, written by the old tree's test helper) is not a rendered "
              "one: the per-sample work is the same code path, with fewer bands to project.", ""]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ref", default="0db2162")
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--passes", type=int, default=3)
    ap.add_argument("--instructions", action="store_true",
                    help="also count the instructions of one pass per tree under valgrind's callgrind")
    a = ap.parse_args()
    ref = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", a.ref], capture_output=True, text=True,
                         check=True).stdout.strip()
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()
    tmp = Path(tempfile.mkdtemp(prefix="lfm_ab_"))
    old = tmp / "old"
    rows, jobs = [], []
    try:
        lib = _callgrind_helper(tmp) if a.instructions else ""
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(old), ref], check=True,
                       capture_output=True)
        load0 = os.getloadavg()
        for name, W, H, ch, cw, n, sps in CASES:
            base = tmp / f"c{W}x{H}"
            _run(old, MAKE, base, W, H, n)
            trees = {"old": old, "new": ROOT}
            roots = {}
            for k in trees:
                roots[k] = tmp / f"c{W}x{H}-{k}"
                shutil.copytree(base, roots[k])
            got = {k: {"rate": [], "cpu_rate": []} for k in trees}
            hashes: set[str] = set()
            for p in range(a.pairs):
                for k in trees:
                    r = json.loads(_run(trees[k], TIME, roots[k], ch, cw, sps, a.passes, "").stdout)
                    got[k]["rate"].append(r["rate"])
                    got[k]["cpu_rate"].append(r["cpu_rate"])
                    hashes.add(r["sha256"])
                if len(hashes) != 1:
                    raise SystemExit(f"{name}: the two trees simulated different samples (hashes {sorted(hashes)}); "
                                     "their speeds are not comparable")
                print(f"{name}: pair {p + 1}: old {got['old']['rate'][-1]:.1f} (CPU {got['old']['cpu_rate'][-1]:.1f}),"
                      f" new {got['new']['rate'][-1]:.1f} (CPU {got['new']['cpu_rate'][-1]:.1f}) samples/s; "
                      "samples equal", flush=True)
            med = {k: {m: statistics.median(v) for m, v in got[k].items()} for k in trees}
            rows.append((name, n * sps, med, got, {}))
            h = hashes.pop()
            jobs += [(len(rows) - 1, k, trees[k], roots[k], ch, cw, sps, h) for k in trees]
        load1 = os.getloadavg()
        if a.instructions:
            # After the timings (so as not to disturb them), all at once: a count does not depend on the load.
            with ThreadPoolExecutor(len(jobs)) as pool:
                counts = list(pool.map(lambda j: _instructions(*j[2:7], lib, tmp / f"cg-{j[0]}-{j[1]}"), jobs))
            for (row, k, *_, h), (count, h2) in zip(jobs, counts):
                if h2 != h:
                    raise SystemExit(f"{rows[row][0]}: under callgrind, {k} simulated other samples")
                rows[row][4][k] = count
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old)], capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)
    out = ROOT / "docs" / "benchmarks" / "cpu-path.md"
    text = _page(a, head, ref, rows, load0, load1)
    # A hand-written section below the generated part (from "## Notes" on) is kept.
    if out.is_file() and "\n## Notes" in (prev := out.read_text()):
        text += "\n" + prev[prev.index("\n## Notes") + 1:]
    atomic_write_text(out, text)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
