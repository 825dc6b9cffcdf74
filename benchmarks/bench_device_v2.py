"""The device program (:class:`lfmbench.datasets.device.SplitProgram`) on scenes with the light kinds of scene
version 2 against the same scenes with plain PWM lamps (issue 40): the cost of drivers, message-sign scan rows and
gated waveforms (indicators, strobes, countdowns, destination displays).

Workload ("v2-mini-like"): the first ``--scenes`` test scenes of protocol ``lfmbench-v2-mini`` are generated (scene
descriptions only, :func:`render_tools.scene.generate_scene`; nothing is rendered); their flickering lights (group,
kind, ``waveform``, ``driver``: the real mix and parameters) are written into a synthetic corpus at the protocol's
size (160 x 90 px, 3 frames, 4 time bins, 4 bands) with random radiance in random boxes of 2-6 x 3-12 px. The "v1"
corpus is the same scenes, the same boxes and radiance, the lights without ``waveform`` and ``driver``. Samples: 3
frames, the full frame, every output but ``rgb``; batches of ``--batch``; global and rolling shutter (``--shutters``:
under a rolling shutter every slot has a weight per row, so a gate is evaluated per row).

Times (median of ``--passes`` after a warm-up; process CPU time and wall time), per batch: the program's cut
(``SplitProgram.pieces``), the PWM weights of that cut (``batch_compose.pwm_weights``: where the gates are evaluated)
and the whole batch (cut, composition, sensor chain: ``DeviceBatches.batch``), v2 and v1 corpora alternating in
one run, and their ratio. Writes the section "Scene version 2 light kinds: CPU figures" (or "... GPU figures" on CUDA) of
``docs/benchmarks/device-path.md`` (``--no-doc``: print only).
Run: ``.venv/bin/python benchmarks/bench_device_v2.py [--device cpu|cuda] [--quick]``.
"""
from __future__ import annotations

import argparse
import collections
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from _timing import load_line, replace_section  # noqa: E402

DOC = ROOT / "docs" / "benchmarks" / "device-path.md"
OUTS = ("raw", "input_referred", "saturated", "gt", "light_index", "depth")


def scene_lights(n: int) -> list[tuple[str, list[dict], dict]]:
    """(scene id, flickering lights, groups) of the first ``n`` test scenes of lfmbench-v2-mini."""
    from render_tools.protocol import load_protocol
    from render_tools.scene import generate_scene

    proto = load_protocol("lfmbench-v2-mini")
    out = []
    for sc in [s for s in proto.scenes if s.split == "test"][:n]:
        spec = generate_scene(sc.seed, scene_id=sc.scene_id, **sc.scene_kw())
        groups = spec["groups"]
        lights = [{k: lt[k] for k in ("id", "group", "kind", "waveform", "driver") if k in lt}
                  for lt in spec["lights"] if groups[lt["group"]]["flicker"]]
        out.append((sc.scene_id, lights, groups))
    return out


def make_corpora(root: Path, scenes, frames: int = 3, bins: int = 4, width: int = 160, height: int = 90):
    """The v2 and v1 corpora of ``scenes`` (see module docstring): (v2 root, v1 root)."""
    from lfmbench import corpus as C
    from tests.data.corpus.data import fake_frames, fake_meta, fake_scene, scale_frames

    roots = {}
    for tag, timed in (("v2", True), ("v1", False)):
        roots[tag] = root / tag
        if (root / tag / "manifest.json").is_file():      # written by an earlier run (--corpus)
            continue
        w = C.CorpusWriter(root / tag)
        for i, (sid, lights, groups) in enumerate(scenes):
            rng = np.random.default_rng(i)
            meta = fake_meta(f"scene{i:05d}", width=width, height=height, frames=frames, bins=bins,
                             bands=[450.0, 530.0, 610.0, 690.0], groups={g: {"flicker": d["flicker"]}
                                                                         for g, d in groups.items()}, n_lights=0)
            meta["lights"] = []
            for lt in lights:
                h, wd = int(rng.integers(2, 7)), int(rng.integers(3, 13))
                y0, x0 = int(rng.integers(0, height - h)), int(rng.integers(0, width - wd))
                d = {"id": int(lt["id"]), "group": lt["group"], "kind": lt["kind"], "instance": 10,
                     "luminance_cd_m2": 100.0, "spectrum": {"model": "led", "peak_nm": 625.0, "fwhm_nm": 20.0},
                     "bbox": [[y0, x0, y0 + h, x0 + wd] for _ in range(frames)]}
                if timed:
                    d.update({k: lt[k] for k in ("waveform", "driver") if k in lt})
                meta["lights"].append(d)
            fr = scale_frames(fake_frames(meta, seed=i), 1e-3, 1e-3)
            w.write_scene(meta["scene_id"], fake_scene(meta["scene_id"]), meta, fr)
        w.write_splits(0)
    return roots["v2"], roots["v1"]


def _cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else the platform's."""
    try:
        for ln in Path("/proc/cpuinfo").read_text().splitlines():
            if ln.startswith("model name"):
                return ln.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--scenes", type=int, default=8)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--passes", type=int, default=7)
    ap.add_argument("--shutters", default="global,rolling", help="comma-separated: global, rolling")
    ap.add_argument("--quick", action="store_true", help="4 scenes, 3 passes")
    ap.add_argument("--corpus", type=Path, default=None, help="where the two corpora are written / reused")
    ap.add_argument("--no-doc", action="store_true")
    args = ap.parse_args(argv)
    if args.quick:
        args.scenes, args.passes = 4, 3
    from lfmbench.datasets import LFMCaptureDataset
    from lfmbench.datasets.batch_compose import pwm_weights
    from lfmbench.datasets.device import DeviceBatches

    dev = torch.device(args.device)
    scenes = scene_lights(args.scenes)
    mix = collections.Counter(lt.get("waveform", {}).get("kind", "pwm") for _s, ls, _g in scenes for lt in ls)
    drivers = sum("driver" in lt for _s, ls, _g in scenes for lt in ls)
    n_lights = sum(mix.values())
    root = args.corpus or Path(tempfile.mkdtemp())
    v2, v1 = make_corpora(root, scenes)
    progs = {}
    shutters = args.shutters.split(",")
    for sh in shutters:
        for tag, r in (("v2", v2), ("v1", v1)):
            ds = LFMCaptureDataset(r, split="all", frames=3, crop=None, samples_per_scene=args.batch, outputs=OUTS,
                                   shutter=sh)
            progs[(tag, sh)] = DeviceBatches(ds, args.batch, dev, seed=0)
            assert progs[(tag, sh)].resident.program is not None
    # a batch of samples of every scene in turn (sample j of the batch: scene j mod n)
    n_sc = len(scenes)
    idx = [(j % n_sc) * args.batch + j // n_sc for j in range(args.batch)]
    keys = ("pieces", "weights", "batch")
    times: dict = {(t, k, c): [] for t in progs for k in keys for c in ("wall", "cpu")}
    cut = {t: db.resident.program.pieces(idx) for t, db in progs.items()}

    def sync():
        if dev.type == "cuda":
            torch.cuda.synchronize(dev)
    for p in range(args.passes + 1):           # pass 0: warm-up; v2 and v1 alternate
        for tag, db in progs.items():
            for key, fn in (("pieces", lambda: db.resident.program.pieces(idx)),
                            ("weights", lambda: pwm_weights(cut[tag])), ("batch", lambda: db.batch(idx))):
                sync()
                t0, c0 = time.perf_counter(), time.process_time()
                fn()
                sync()
                if p:
                    times[(tag, key, "wall")].append(time.perf_counter() - t0)
                    times[(tag, key, "cpu")].append(time.process_time() - c0)
    med = {k: statistics.median(v) for k, v in times.items()}
    gates = progs[("v2", shutters[0])].resident.program.gates
    name = torch.cuda.get_device_name(dev) if dev.type == "cuda" else _cpu_name()
    lines = [f"Written by `benchmarks/bench_device_v2.py` (rerun: `.venv/bin/python benchmarks/bench_device_v2.py"
             f"{' --device cuda' if dev.type == 'cuda' else ''}`). Run on {load_line()} at its start; {name}, "
             f"torch {torch.__version__}, {os.cpu_count()} CPU cores.", "",
             f"Workload: the flickering lights of the first {len(scenes)} test scenes of lfmbench-v2-mini (scene "
             f"descriptions, not rendered), {n_lights / len(scenes):.1f} per scene: "
             + ", ".join(f"{k} {v / len(scenes):.1f}" for k, v in sorted(mix.items()))
             + f"; {drivers / len(scenes):.1f} on a shared driver; gates of up to {(gates.shape[1] - 4) // 2} ON "
             f"intervals. Synthetic radiance at 160 x 90 px, 3 frames of 4 bins, full-frame samples, batch "
             f"{args.batch} of samples of every scene in turn; the v1 corpus has the same lights without waveform and driver. Medians of "
             f"{args.passes} passes, v2 and v1 alternating; process CPU time (all threads) beside wall time: on a "
             "shared machine the CPU time is the steadier of the two.", "",
             "| shutter | per batch | v1 lights: CPU / wall (ms) | v2 lights: CPU / wall (ms) | v2 / v1 CPU | "
             "v2 / v1 wall |", "|---|---|---|---|---|---|"]
    for sh in shutters:
        for key, what in (("pieces", "program's cut (`SplitProgram.pieces`)"),
                          ("weights", "PWM weights of the cut (`pwm_weights`)"),
                          ("batch", "whole batch (cut, composition, sensor chain)")):
            a, b = (med[((t, sh), key, "cpu")] for t in ("v1", "v2"))
            aw, bw = (med[((t, sh), key, "wall")] for t in ("v1", "v2"))
            lines.append(f"| {sh} | {what} | {1e3 * a:.1f} / {1e3 * aw:.1f} | {1e3 * b:.1f} / {1e3 * bw:.1f} | "
                         f"{b / a:.2f} | {bw / aw:.2f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if not args.no_doc:
        heading = f"## Scene version 2 light kinds: {'GPU' if dev.type == 'cuda' else 'CPU'} figures"
        replace_section(DOC, heading, [heading, "", *text.splitlines(), ""])
    return 0


if __name__ == "__main__":
    sys.exit(main())
