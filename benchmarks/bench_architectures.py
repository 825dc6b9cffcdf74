"""Per-sample dataset cost of every sensor architecture against the split pixel (issue 22, target: within 1.5x).

Same workload as section 1 of ``benchmarks/bench_dataset.py`` (the 2-scene 320 x 256 throughput corpus it renders,
3 frames, 256 x 256 crops, every output but ``rgb``, noise on, layers warm in memory), one process, one torch thread
(what a DataLoader worker runs): the median wall time of ``LFMCaptureDataset.__getitem__`` per sensor preset, its
ratio to ``ovt`` (split pixel) and where it goes (composition of the exposures vs the sensor chain). Every shipped
preset is timed, in interleaved passes (ovt, ovt rolling, then the others by name, then again), so the load of the
shared machine falls on all of them alike.

Writes its section of ``docs/benchmarks/dataset.md`` (between the ``architectures`` markers; the rest of the file is
``bench_dataset.py``'s). Run: ``.venv/bin/python benchmarks/bench_architectures.py [--passes 5] [--samples 16]``;
``--presets a,b`` times only those (beside ``ovt``) and prints their rows without writing the page.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import bench_dataset as bd  # noqa: E402  (sets DRJIT_LIBLLVM_PATH, renders the throughput corpus)
import torch  # noqa: E402

from lfmbench.datasets import LFMCaptureDataset  # noqa: E402
from lfmbench.datasets import capture as _capture  # noqa: E402
from lfmbench.fileio import atomic_write_text  # noqa: E402

from lfmbench.sensor import available_presets  # noqa: E402

#: (label, preset, dataset shutter): ``ovt`` with both readouts, then every other shipped preset (a preset's own
#: readout, e.g. staggered's rolling one, takes precedence over the shutter).
RUNS = (("ovt", "ovt", "global"), ("ovt rolling", "ovt", "rolling"),
        *((n, n, "global") for n in available_presets() if n != "ovt"))
PRESETS = tuple(r[0] for r in RUNS)
TARGET = 1.5
BEGIN, END = "<!-- architectures:begin -->", "<!-- architectures:end -->"


def _cpu() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else the platform's machine name."""
    info = Path("/proc/cpuinfo")
    names = [ln.split(":", 1)[1].strip() for ln in info.read_text().splitlines()
             if ln.startswith("model name")] if info.is_file() else []
    return names[0] if names else platform.machine()


def timed_split(ds: LFMCaptureDataset, n: int) -> tuple[float, float, float]:
    """(median s per sample, median s in composition, median s in the sensor chain) over ``n`` samples."""
    comp, chain, tot = [], [], []
    fns = {"compose": (_capture, ("compose_frame", "compose_plan_frame")),
           "chain": (_capture._sensor, ("simulate_split_pixel_electrons", "simulate_plan_electrons"))}
    acc = {"compose": 0.0, "chain": 0.0}
    saved = []
    depth = {"chain": 0}

    def wrap(mod, name, key):
        f = getattr(mod, name)

        def g(*a, **k):
            if key == "chain" and depth["chain"]:
                return f(*a, **k)               # the plan chain calls the split-pixel one: count it once
            t = time.perf_counter()
            depth[key] = depth.get(key, 0) + 1
            try:
                return f(*a, **k)
            finally:
                depth[key] -= 1
                acc[key] += time.perf_counter() - t
        saved.append((mod, name, f))
        setattr(mod, name, g)

    for key, (mod, names) in fns.items():
        for name in names:
            wrap(mod, name, key)
    try:
        for i in range(n):
            acc["compose"] = acc["chain"] = 0.0
            t = time.perf_counter()
            ds[i % len(ds)]
            tot.append(time.perf_counter() - t)
            comp.append(acc["compose"])
            chain.append(acc["chain"])
    finally:
        for mod, name, f in saved:
            setattr(mod, name, f)
    return statistics.median(tot), statistics.median(comp), statistics.median(chain)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passes", type=int, default=5)
    ap.add_argument("--samples", type=int, default=16, help="samples per preset and pass")
    ap.add_argument("--out", type=Path, default=bd.ROOT / "bench_out" / "dsbench")
    ap.add_argument("--presets", default="", help="comma list: time only these presets (beside ovt global and "
                    "rolling) and print their rows; the docs page is written only by a run of every preset")
    a = ap.parse_args(argv)
    only = [n for n in a.presets.split(",") if n]
    unknown = sorted(set(only) - set(PRESETS))
    if unknown:
        ap.error(f"--presets: unknown preset(s) {unknown}; shipped: {', '.join(PRESETS)}")
    runs = RUNS if not only else tuple(r for r in RUNS if r[0] in ("ovt", "ovt rolling") or r[0] in only)
    presets = tuple(r[0] for r in runs)
    torch.set_num_threads(1)
    root = a.out.resolve() / "tp"
    load0 = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    bd._render(root, {"width": bd.TP_SIZE[1], "height": bd.TP_SIZE[0], "spp": bd.TP_SPP, "bins": bd.TP_BINS,
                      "frames": bd.TP_FRAMES}, bd.TP_SEED, scenes=2)
    outputs = tuple(o for o in _capture.DEFAULT_OUTPUTS)
    dss = {}
    for name, preset, shutter in runs:
        ds = LFMCaptureDataset(root, split="all", sensor=preset, frames=bd.TP_FRAMES, crop=bd.TP_CROP, outputs=outputs,
                               samples_per_scene=a.samples, seed=1, shutter=shutter)
        for i in range(len(ds)):               # warm: layers projected and held, kernels compiled
            ds[i]
            if i >= 3:
                break
        dss[name] = ds
    res = {n: [] for n in presets}
    for p in range(a.passes):
        for name in presets:
            res[name].append(timed_split(dss[name], a.samples))
        bd._log(f"pass {p + 1}/{a.passes}: " + ", ".join(f"{n} {res[n][-1][0] * 1e3:.1f} ms" for n in presets))
    load1 = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    med = {n: tuple(statistics.median(r[i] for r in res[n]) for i in range(3)) for n in presets}
    base = med["ovt"][0]
    L = [BEGIN, "", "## Every shipped preset (issues 22, 38)", "",
         f"Generated by `benchmarks/bench_architectures.py --passes {a.passes} --samples {a.samples}` on "
         f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} ({_cpu()}, {os.cpu_count()} CPUs, torch "
         f"{torch.__version__}, one torch thread). Load average {load0} at the start, {load1} at the end (shared "
         f"machine). Workload of section 1: 3 frames, 256 x 256 crops of the 2-scene 320 x 256 corpus, every output "
         "but `rgb`, noise on, layers warm; `LFMCaptureDataset.__getitem__` in one process. Medians over "
         f"{a.passes} interleaved passes of the per-pass median of {a.samples} samples.", "",
         "| preset | architecture | readout | captures | ms / sample | x ovt global | x ovt, same readout | "
         "composition ms | sensor chain ms |",
         "|---|---|---|---|---|---|---|---|---|"]
    same = {}
    for n in presets:
        ds = dss[n]
        p = ds.preset
        rolling = any((p.capture_readout(c).shutter or ds.shutter) == "rolling" for c in p.captures)
        ref = med["ovt rolling" if rolling else "ovt"][0]
        t, c, s = med[n]
        same[n] = t / ref
        L.append(f"| `{n}` | {p.architecture} | {'rolling' if rolling else 'global'} | {len(p.captures)} | "
                 f"{t * 1e3:.1f} | {t / base:.2f} | {t / ref:.2f} | {c * 1e3:.1f} | {s * 1e3:.1f} |")
    worst = max(presets, key=lambda n: same[n])
    ok = same[worst] <= TARGET
    worst_g = max(presets, key=lambda n: med[n][0] / base)
    L += ["", f"Target: every shipped preset within {TARGET}x of the split pixel (`ovt`) with the same readout: "
          + ("**reached**" if ok else "**not reached**") + f"; the largest ratio `{worst}` at {same[worst]:.2f}x "
          "(a rolling readout composes the flickering lamps per row, for every architecture alike). Against `ovt` "
          f"global: largest `{worst_g}` at {med[worst_g][0] / base:.2f}x.",
          "Every plan runs its compiled sensor chain on the CPU (`lfmbench.sensor.fused`: `chain_fused` for the split "
          "pixel, `chain_plan_fused` for any other plan; one pass per exposure and one per capture, bit-identical to "
          "the torch chain of `simulate_plan_electrons`, which stays as `backend=\"torch\"`).", "", END]
    sec = "\n".join(L)
    if only:                                    # a subset: printed, the page keeps the run of every preset
        print(sec.replace(f"--passes {a.passes}", f"--passes {a.passes} --presets {a.presets}"))
        return 0
    doc = bd.DOC.read_text() if bd.DOC.is_file() else ""
    if BEGIN in doc and END in doc:
        doc = doc[:doc.index(BEGIN)] + sec + doc[doc.index(END) + len(END):]
    else:
        doc = doc.rstrip("\n") + "\n\n" + sec + "\n"
    atomic_write_text(bd.DOC, doc)
    print(sec)
    return 0


if __name__ == "__main__":
    sys.exit(main())
