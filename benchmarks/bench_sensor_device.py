"""Sensor simulation alone, on the CPU and (where one is) a GPU: per-sample generators against counter seeds.

The split-pixel chain of a batch of 3-frame 256 x 256 captures (:func:`lfmbench.sensor.simulate_split_pixel_electrons`,
mean electrons already on the device, FPN maps on, every capture), timed three ways:

- ``generators``: one ``torch.Generator`` per sample (what the batched dataset path does today: on a GPU one
  ``torch.poisson`` / ``torch.randn`` launch per sample and capture);
- ``seeds``: one int64 noise seed per sample, noise from counter-based streams (:mod:`lfmbench.sensor.counter_noise`):
  the batch in one set of tensor operations,
  on CUDA the fused Triton chain (:func:`lfmbench.sensor.fused.chain_triton`: one pass per photodiode, one per
  capture, noise drawn inside the kernels of :mod:`lfmbench.sensor._counter_triton`);
- ``seeds-unfused`` (CUDA): the same numbers from the torch element-wise chain with only the Poisson and normal
  draws as Triton kernels (the chain before the fused kernels);
- ``seeds-torch`` (CUDA): the same numbers from the torch form (every branch and rejection round for every pixel);
- ``seeds+compile`` (CUDA, ``--compile``): the torch form fused by ``torch.compile``.

``--sweep-launch`` (CUDA) first times the fused chain at batch 256 with each candidate launch shape of its two
kernels (pixels per program, warps; :data:`lfmbench.sensor._counter_triton.COLLECT_LAUNCH` / ``READOUT_LAUNCH``:
the counts do not depend on them), takes the fastest for the rows that follow, and reports the sweep.

Reports samples/s (median of ``--repeats`` timed calls after two warm-up calls; CUDA synchronised) and the peak
device memory of a call, per batch size, and writes its section of ``docs/benchmarks/sensor-device.md``
(``--no-doc``: only print). The CPU rows are always measured (on a GPU machine: on its host CPU); a run on a GPU
writes the section "GPU figures", one without a GPU the section "CPU figures" (the other section stays as it is).

Run: ``.venv/bin/python benchmarks/bench_sensor_device.py [--device cuda] [--quick]``.
"""
from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from _timing import write_device_doc  # noqa: E402
from lfmbench.fileio import atomic_write_text  # noqa: E402
DOC = ROOT / "docs" / "benchmarks" / "sensor-device.md"
FRAMES, H, W = 3, 256, 256


def _inputs(batch: int, device: str):
    g = torch.Generator().manual_seed(0)
    # a night-street-like mix of means: most pixels below 10 e-, a tail of lamps up to saturation
    lpd = (torch.rand(batch, FRAMES, 1, H, W, generator=g) ** 6 * 4e4).to(device)
    spd = (lpd * 0.05).contiguous()
    return lpd, spd


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def time_mode(mode: str, batch: int, device: str, repeats: int) -> dict:
    from lfmbench.counter_rng import derive_key
    from lfmbench.sensor import counter_noise as CN
    from lfmbench.sensor import fixed_pattern, load_preset, simulate_split_pixel_electrons

    preset = load_preset("ovt")
    lpd, spd = _inputs(batch, device)
    fpn = fixed_pattern(preset, H, W, device=device)
    orig = (CN.poisson, CN.normal, CN.USE_TRITON)
    if mode == "seeds+compile":  # the torch form fused by torch.compile (what Triton kernels replace)
        CN.USE_TRITON = False
        CN.poisson, CN.normal = torch.compile(CN.poisson, dynamic=True), torch.compile(CN.normal, dynamic=True)
    elif mode == "seeds-torch":  # the torch form, every branch and round for every pixel
        CN.USE_TRITON = False
    try:
        def call(i: int):
            if mode == "generators":
                gens = [torch.Generator(device=device).manual_seed(1000 * i + b) for b in range(batch)]
                return simulate_split_pixel_electrons(lpd, spd, preset, 4e-3, 11e-3, gens, fpn=fpn, check=False)
            seeds = derive_key(i, torch.arange(batch)).to(device)
            backend = "torch" if mode == "seeds-unfused" else "auto"
            return simulate_split_pixel_electrons(lpd, spd, preset, 4e-3, 11e-3, fpn=fpn, check=False, seeds=seeds,
                                                  backend=backend)

        t0 = time.perf_counter()
        call(0)
        _sync(device)
        first = time.perf_counter() - t0
        call(1)
        _sync(device)
        if device.startswith("cuda"):
            torch.cuda.reset_peak_memory_stats()
            base = torch.cuda.memory_allocated()
        times = []
        for i in range(repeats):
            t0 = time.perf_counter()
            call(2 + i)
            _sync(device)
            times.append(time.perf_counter() - t0)
        peak = (torch.cuda.max_memory_allocated() - base) if device.startswith("cuda") else None
    finally:
        CN.poisson, CN.normal, CN.USE_TRITON = orig
    med = statistics.median(times)
    return {"mode": mode, "batch": batch, "device": device, "samples_per_s": batch / med, "median_s": med,
            "first_call_s": first, "peak_bytes": peak}


#: Candidate launch shapes (pixels per program, warps per program) of the fused chain's kernels.
COLLECT_CANDIDATES = ((256, 4), (256, 8), (128, 4), (128, 2), (64, 2), (64, 1), (32, 1))
READOUT_CANDIDATES = ((256, 4), (512, 4), (1024, 8), (128, 2))


def sweep_launch(device: str, repeats: int) -> list[dict]:
    """Time the fused chain (``seeds``, batch 256) with each candidate launch shape, one kernel at a time (the
    other at its current shape); leaves the fastest of each set in the kernel module. Returns the sweep rows."""
    from lfmbench.sensor import _counter_triton as T

    rows = []
    for name, cands, table in (("collect", COLLECT_CANDIDATES, T.COLLECT_LAUNCH),
                               ("readout", READOUT_CANDIDATES, T.READOUT_LAUNCH)):
        best = None
        for block, warps in cands:
            table.update(BLOCK=block, num_warps=warps)
            r = time_mode("seeds", 256, device, repeats)
            rows.append({"kernel": name, "BLOCK": block, "num_warps": warps, "samples_per_s": r["samples_per_s"]})
            print(f"launch {name} BLOCK {block:4d} warps {warps}: {r['samples_per_s']:9.1f} samples/s", flush=True)
            if best is None or r["samples_per_s"] > best[0]:
                best = (r["samples_per_s"], block, warps)
        table.update(BLOCK=best[1], num_warps=best[2])
    return rows


def report(rows: list[dict], machine: dict, gpu_run: bool, sweep: list[dict] | None = None) -> str:
    lines = ["# Sensor simulation alone: per-sample generators against counter seeds", "",
             "Written by `benchmarks/bench_sensor_device.py` (rerun: `.venv/bin/python "
             "benchmarks/bench_sensor_device.py --device cuda`, and without `--device` for the CPU rows). "
             f"Workload: {FRAMES} frames of {H} x {W} px per sample, `ovt` preset, FPN on, every capture, mean "
             "electrons already on the device (no composition, no data loading). Median of timed calls after two "
             "warm-up calls; `first call` includes compilation where there is one.", "",
             f"Machine: {machine}", ""]
    if not gpu_run:
        lines += ["**GPU rows not run**: no CUDA device on the machine that wrote this file.", ""]
    lines += ["| device | noise | batch | samples/s | first call (s) | peak device memory (MiB) | MiB per sample |",
              "|---|---|---|---|---|---|---|"]
    for r in rows:
        pk = "" if r["peak_bytes"] is None else f"{r['peak_bytes'] / 2**20:.0f}"
        per = "" if r["peak_bytes"] is None else f"{r['peak_bytes'] / 2**20 / r['batch']:.1f}"
        lines.append(f"| {r['device']} | {r['mode']} | {r['batch']} | {r['samples_per_s']:.0f} | "
                     f"{r['first_call_s']:.2f} | {pk} | {per} |")
    if sweep:
        from lfmbench.sensor import _counter_triton as T

        lines += ["", "Launch shapes of the fused chain's kernels (`--sweep-launch`; `seeds`, batch 256, one kernel "
                  "varied at a time; the rows above ran with collect "
                  f"{T.COLLECT_LAUNCH['BLOCK']} px / {T.COLLECT_LAUNCH['num_warps']} warps, read-out "
                  f"{T.READOUT_LAUNCH['BLOCK']} px / {T.READOUT_LAUNCH['num_warps']} warps):", "",
                  "| kernel | px per program | warps | samples/s |", "|---|---|---|---|"]
        lines += [f"| {r['kernel']} | {r['BLOCK']} | {r['num_warps']} | {r['samples_per_s']:.0f} |" for r in sweep]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--device", default="auto", help="auto (cuda where there is one), cpu or cuda")
    ap.add_argument("--quick", action="store_true", help="smaller batches, fewer repeats")
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--compile", action="store_true", help="also time the torch form under torch.compile (CUDA; "
                                                           "about 100 s of compilation)")
    ap.add_argument("--no-doc", action="store_true")
    ap.add_argument("--json", type=Path, help="also write the rows as JSON here")
    ap.add_argument("--sweep-launch", action="store_true", help="CUDA: time the fused chain's candidate launch "
                                                                 "shapes first and use the fastest")
    ap.add_argument("--modes", default=None, help="comma-separated GPU modes (default: all)")
    args = ap.parse_args(argv)
    if args.device == "auto":
        args.device = "cuda" if torch.cuda.is_available() else "cpu"
    gpu = args.device.startswith("cuda")
    if gpu and not torch.cuda.is_available():
        print("error: --device cuda: no CUDA device here", file=sys.stderr)
        return 2
    repeats = args.repeats or (3 if args.quick else 5)
    # the CPU rows always (on a GPU machine: its host CPU), the GPU rows with --device cuda
    plan = [("cpu", b, m) for b in ((2,) if args.quick else (2, 8)) for m in ("generators", "seeds")]
    if gpu:
        modes = ("generators", "seeds", "seeds-unfused", "seeds-torch") + (("seeds+compile",) if args.compile else ())
        plan += [(args.device, b, m) for b in (64, 256) for m in modes]
    if gpu and args.modes:
        keep = set(args.modes.split(","))
        plan = [p for p in plan if p[0] == "cpu" or p[2] in keep]
    sweep = sweep_launch(args.device, repeats) if gpu and args.sweep_launch else None
    rows = []
    for dev, b, m in plan:
        r = time_mode(m, b, dev, repeats)
        rows.append(r)
        peak = "-" if r["peak_bytes"] is None else f"{r['peak_bytes'] / 2**20:.0f} MiB"
        print(f"{r['device']} {m:14s} batch {b:4d}: {r['samples_per_s']:9.1f} samples/s "
              f"(first call {r['first_call_s']:.2f} s, peak {peak})", flush=True)
        if args.json:  # after every row: a run stopped by a time limit keeps what it measured
            atomic_write_text(args.json, json.dumps({"rows": rows}, indent=1))
    name = torch.cuda.get_device_name() if gpu else platform.processor() or platform.machine()
    machine = f"{name}, torch {torch.__version__}, {torch.get_num_threads()} CPU threads"
    if args.json:
        atomic_write_text(args.json, json.dumps({"machine": machine, "rows": rows, "sweep": sweep}, indent=1))
    text = report(rows, machine, gpu, sweep)
    print(text)
    if not args.no_doc:
        write_device_doc(text, args.device, DOC, ROOT)
    return 0


if __name__ == "__main__":
    sys.exit(main())
