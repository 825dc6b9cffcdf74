"""The training data path end to end: DataLoader workers against the corpus resident on the device (issue 28).

Times, in samples/s (median of timed passes after a warm-up pass; CUDA synchronised), on ``--device``:

- ``loader``: ``LFMCaptureDataset`` in a ``DataLoader`` (``--workers`` processes, per-sample composition and noise
  on the CPU), each batch moved to the device: what ``train(data="loader")`` feeds the network;
- ``device``: :class:`lfmbench.datasets.device.DeviceBatches` (layers resident on the device, each batch cut,
  composed and simulated there with counter-based noise): what ``train(data="device")`` feeds it;
- ``step``: the U-Net (``unet_v1``) training step alone on a batch already on the device (the ceiling);
- ``train``: ``lfmbench.train.train`` end to end for ``--steps`` optimiser steps, per data source.

Workload: a synthetic corpus written here (``--scenes`` scenes of 640 x 360 px, 4 frames, 8 time bins, 24 lamps of
24 x 40 px each, 4 bands; random radiance: the throughput does not depend on the values), 3 frames per sample,
every output but ``rgb``; capture rows at a 256 x 256 crop, training rows at crop 128. Also reports the resident
bytes per scene and the peak device memory per batch.

Writes its section of ``docs/benchmarks/device-path.md`` (``--no-doc``: only print; ``--json PATH``: the rows,
written as they come): "GPU figures" on a GPU, "CPU figures" without one (the other section stays as it is).
Run: ``.venv/bin/python benchmarks/bench_device_path.py`` (``--device auto``: CUDA where there is one).
"""
from __future__ import annotations

import argparse
import json
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
from _timing import write_device_doc  # noqa: E402
from lfmbench.fileio import atomic_write_text  # noqa: E402
DOC = ROOT / "docs" / "benchmarks" / "device-path.md"
OUTS = ("raw", "input_referred", "saturated", "gt", "light_index", "depth")


def make_corpus(root: Path, scenes: int, width: int = 640, height: int = 360, frames: int = 4, bins: int = 8,
                lamps: int = 24) -> Path:
    """The synthetic throughput corpus (fake radiance in the corpus format; see module docstring)."""
    from lfmbench import corpus as C
    from tests.data.corpus.data import fake_frames, fake_meta, fake_scene, scale_frames

    if (root / "manifest.json").is_file():
        return root
    w = C.CorpusWriter(root)
    rng = np.random.default_rng(0)
    for i in range(scenes):
        meta = fake_meta(f"scene{i:05d}", width=width, height=height, frames=frames, bins=bins,
                         bands=[450.0, 530.0, 610.0, 690.0], n_lights=lamps)
        for lt in meta["lights"]:
            y0, x0 = int(rng.integers(0, height - 24)), int(rng.integers(0, width - 40))
            lt["bbox"] = [[y0, x0, y0 + 24, x0 + 40] for _ in range(frames)]
        fr = scale_frames(fake_frames(meta, seed=i), 1e-3, 1e-3, False)
        w.write_scene(meta["scene_id"], fake_scene(meta["scene_id"]), meta, fr)
    w.write_splits(0)
    return root


def _sync(dev: torch.device) -> None:
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)


def _dataset(root: Path, crop: int, samples: int = 128, **kw):
    """The benchmark's dataset with at least ``samples`` samples (3 frames, crop ``crop``)."""
    from lfmbench.datasets import LFMCaptureDataset
    from lfmbench.corpus import Corpus

    kw.setdefault("outputs", OUTS)
    scenes = len(Corpus(root).scenes)
    return LFMCaptureDataset(root, split="all", frames=3, crop=crop, samples_per_scene=max(64, -(-samples // scenes)),
                             **kw)


def _timed(fn, passes: int, dev: torch.device) -> tuple[float, float]:
    fn()
    _sync(dev)
    ts = []
    for _ in range(passes):
        t0 = time.perf_counter()
        fn()
        _sync(dev)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), ts[0]


def time_loader(root, dev, batch, workers, batches, passes):
    from torch.utils.data import DataLoader

    from lfmbench.datasets.loading import collate_samples

    ds = _dataset(root, 256, batch * batches)
    dl = DataLoader(ds, batch_size=batch, shuffle=False, num_workers=workers, collate_fn=collate_samples,
                    persistent_workers=workers > 0, pin_memory=dev.type == "cuda")

    def run():
        for i, b in enumerate(dl):
            {k: v.to(dev, non_blocking=True) for k, v in b.items() if torch.is_tensor(v)}
            if i + 1 >= batches:
                break
        assert i + 1 == batches, "the dataset is too small for the timed batches"
    med, _ = _timed(run, passes, dev)
    return batch * batches / med


def time_device(root, dev, batch, batches, passes, program=True):
    """The device path; ``program=False``: its per-sample pieces (``capture_pieces`` from the resident layers, one
    sample at a time on the host: the path before the batched program) for the ratio."""
    from lfmbench.datasets.device import DeviceBatches

    t0 = time.perf_counter()
    db = DeviceBatches(_dataset(root, 256, batch * batches), batch, dev, seed=0)
    load_s = time.perf_counter() - t0
    if not program:
        db.resident.program = None
    if dev.type == "cuda":
        torch.cuda.reset_peak_memory_stats(dev)
        base = torch.cuda.memory_allocated(dev)

    def run():
        for i, b in enumerate(db):
            if i + 1 >= batches:
                break
        assert i + 1 == batches and b["gt"].shape[0] == batch, "the dataset is too small for the timed batches"
    med, _ = _timed(run, passes, dev)
    peak = (torch.cuda.max_memory_allocated(dev) - base) if dev.type == "cuda" else None
    scenes = len(dict.fromkeys(db.ds.scene_ids))
    return batch * batches / med, load_s, db.resident.bytes / scenes, peak, count_syncs(db, dev)


def count_syncs(db, dev) -> list | None:
    """Host synchronisations of one device-path batch on CUDA."""
    return _probe_syncs(lambda: db.batch(range(db.batch_size)), dev)


def time_step(root, dev, batch, crop, passes, graph: bool = False):
    """The U-Net (unet_v1) optimiser step alone on one device-path batch already on the device: the step
    ``train()`` runs (its optimiser, :func:`lfmbench.train.make_optimizer`; ``graph``: replayed as a CUDA graph,
    :class:`lfmbench.train.GraphedStep`)."""
    from lfmbench.datasets.device import DeviceBatches
    from lfmbench.train import GraphedStep, _eager_step, load_config, make_optimizer, trainable

    spec = trainable("unet")
    cfg = load_config("unet", ROOT / "lfmbench" / "configs" / "unet_v1.yaml")
    model = spec.build_model(cfg).to(dev)
    opt = make_optimizer(model, cfg, dev, graph)
    kw = {} if spec.outputs is None else {"outputs": spec.outputs}
    ds = _dataset(root, crop, noise_streams="counter", **kw)
    sample = next(iter(DeviceBatches(ds, batch, dev, seed=0)))
    step = GraphedStep(model, opt, spec, cfg) if graph else None

    def one_step():
        if step is not None:
            return step(sample, 1e-3)
        return _eager_step(model, opt, spec, cfg, sample, 1e-3)

    def run():
        for _ in range(5):
            one_step()
    med, _ = _timed(run, passes, dev)
    assert step is None or step.replays > 0, "the step was not captured"
    return 5 * batch / med, _probe_syncs(one_step, dev)


def _probe_syncs(fn, dev) -> list | None:
    """Host synchronisations of ``fn()`` on CUDA (``torch.cuda.set_sync_debug_mode``): [(count, where), ...]."""
    if dev.type != "cuda":
        return None
    import collections
    import warnings

    torch.cuda.synchronize(dev)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        torch.cuda.set_sync_debug_mode("warn")
        try:
            fn()
        finally:
            torch.cuda.set_sync_debug_mode("default")
    where = collections.Counter(f"{Path(w.filename).name}:{w.lineno}" for w in caught
                                if "synchroniz" in str(w.message))
    return sorted(((n, k) for k, n in where.items()), reverse=True)


def measure_fp16(root, dev, batch: int) -> dict:
    """float16 against float32 residency on one batch (crop 256, noise off): the error of the composed ground
    truth (relative, over pixels with signal), the DN that moved in the LPD-LCG capture, the bytes per scene."""
    from lfmbench.datasets.device import DeviceBatches

    out = {}
    res = {}
    for name, dt in (("float32", torch.float32), ("float16", torch.float16)):
        db = DeviceBatches(_dataset(root, 256, batch, noise=False), batch, dev, seed=0, dtype=dt)
        res[name] = db.batch(range(batch))
        out[f"bytes_per_scene_{name}"] = db.resident.bytes / len(dict.fromkeys(db.ds.scene_ids))
    a, h = res["float32"], res["float16"]
    pos = a["gt"] > 0
    rel = ((h["gt"] - a["gt"]).abs() / a["gt"].abs().clamp_min(1e-30))[pos].double()
    out.update(gt_rel_max=float(rel.max()), gt_rel_rms=float(rel.square().mean().sqrt()),
               lcg_dn_moved=float((h["lpd_lcg"] != a["lpd_lcg"]).double().mean()),
               lcg_dn_max=float((h["lpd_lcg"].double() - a["lpd_lcg"].double()).abs().max()))
    return out


def profile_device(root, dev, batch: int, out: Path | None) -> None:
    """Where the device path's GPU time goes: torch.profiler over one batch (after a warm-up), the top kernels."""
    from torch.profiler import ProfilerActivity, profile

    from lfmbench.datasets.device import DeviceBatches

    db = DeviceBatches(_dataset(root, 256, batch), batch, dev, seed=0)
    db.batch(range(batch))
    _sync(dev)
    with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
        db.batch(range(batch))
        _sync(dev)
    table = prof.key_averages().table(sort_by="cuda_time_total", row_limit=25, max_name_column_width=60)
    print(table)
    if out is not None:
        atomic_write_text(out, table)


def time_train(root, dev, data, steps, batch, crop, workers, cuda_graph: str = "auto") -> tuple[float, float]:
    """``train()`` for 3 epochs of ``steps`` optimiser steps: (samples/s of the whole call, start-up included;
    samples/s of its later epochs, the median of epochs 2 and 3: the steady state, from ``epoch_seconds``)."""
    from lfmbench.corpus import Corpus
    from lfmbench.train import train

    scenes = len(Corpus(root).scenes)
    per_scene = -(-steps * batch // scenes)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        _model, hist = train("unet", root, Path(tmp) / "u.pt", device=str(dev), data=data, epochs=3,
                             crop=crop, batch_size=batch, split="all", samples_per_scene=per_scene, workers=workers,
                             progress=False, log=None, cuda_graph=cuda_graph)
        _sync(dev)
        total = time.perf_counter() - t0
    n = scenes * per_scene
    assert hist["steps"] >= 3 * steps, (hist["steps"], steps)
    return 3 * n / total, n / statistics.median(hist["epoch_seconds"][1:])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--device", default="auto", help="auto (cuda where there is one), cpu or cuda")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--scenes", type=int, default=2)
    ap.add_argument("--workers", type=int, default=None, help="DataLoader workers (default: cores - 2, at least 1)")
    ap.add_argument("--corpus", type=Path, default=None, help="where the synthetic corpus is written / reused")
    ap.add_argument("--rows", default="loader,device,device-samplewise,fp16,step,step-graph,train-loader,train-device,"
                                      "train-device-eager",
                    help="comma-separated rows to measure (default: all)")
    ap.add_argument("--no-doc", action="store_true")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--profile", type=Path, default=None,
                    help="also profile one batch of 256 on the device and write the kernel table here")
    args = ap.parse_args(argv)
    if args.device == "auto":
        args.device = "cuda" if torch.cuda.is_available() else "cpu"
    dev = torch.device(args.device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        print("error: --device cuda: no CUDA device here", file=sys.stderr)
        return 2
    workers = args.workers if args.workers is not None else max(1, (os.cpu_count() or 2) - 2)
    root = make_corpus(args.corpus or Path(tempfile.mkdtemp()) / "corpus", args.scenes)
    gpu = dev.type == "cuda"
    batches = (64, 256, 1024) if gpu else (8, 64)
    n_b, passes = (2, 2) if args.quick else (4, 3)
    rows: list[dict] = []

    def add(**r):
        rows.append(r)
        print(json.dumps(r), flush=True)
        if args.json:
            atomic_write_text(args.json, json.dumps({"rows": rows}, indent=1))

    wanted = set(args.rows.split(","))
    for b in batches:
        if "loader" in wanted and b <= 256:
            add(path="loader", batch=b, workers=workers,
                samples_per_s=time_loader(root, dev, b, workers, n_b, passes))
        if "device" in wanted:
            sps, load_s, per_scene, peak, syncs = time_device(root, dev, b, n_b, passes)
            add(path="device", batch=b, samples_per_s=sps, load_s=load_s, resident_bytes_per_scene=per_scene,
                peak_bytes=peak, syncs=syncs)
        if "device-samplewise" in wanted:
            sps, load_s, per_scene, peak, syncs = time_device(root, dev, b, n_b, passes, program=False)
            add(path="device (pieces per sample)", batch=b, samples_per_s=sps, load_s=load_s,
                resident_bytes_per_scene=per_scene, peak_bytes=peak)
    if "fp16" in wanted:
        add(path="fp16", batch=64 if gpu else 8, samples_per_s=float("nan"), **measure_fp16(root, dev, 64 if gpu else 8))
    if args.profile is not None:
        profile_device(root, dev, 256 if gpu else 8, args.profile)
    step_b = 64 if gpu else 4
    if "step" in wanted:
        sps, syncs = time_step(root, dev, step_b, 128, passes)
        add(path="step", batch=step_b, crop=128, samples_per_s=sps, syncs=syncs)
    if "step-graph" in wanted and gpu:
        sps, syncs = time_step(root, dev, step_b, 128, passes, graph=True)
        add(path="step (CUDA graph)", batch=step_b, crop=128, samples_per_s=sps, syncs=syncs)
    # epochs of 64 steps on a GPU: an epoch's start and end (the queue drains) cost about one step each
    steps = 8 if args.quick else (64 if gpu else 16)
    for data in ("loader", "device"):
        if f"train-{data}" in wanted:
            first, steady = time_train(root, dev, data, steps, step_b, 128, workers)
            add(path=f"train({data})", batch=step_b, crop=128, steps=steps, samples_per_s=steady,
                with_startup=first)
    if "train-device-eager" in wanted and gpu:
        first, steady = time_train(root, dev, "device", steps, step_b, 128, workers, cuda_graph="off")
        add(path="train(device, no CUDA graph)", batch=step_b, crop=128, steps=steps, samples_per_s=steady,
            with_startup=first)
    name = torch.cuda.get_device_name(dev) if gpu else (platform.processor() or platform.machine())
    text = report(rows, f"{name}, torch {torch.__version__}, {os.cpu_count()} CPU cores, {workers} loader workers",
                  gpu)
    print(text)
    if not args.no_doc:
        write_device_doc(text, args.device, DOC, ROOT)
    return 0


def report(rows, machine, gpu) -> str:
    lines = ["# The training data path: DataLoader workers against the corpus resident on the device", "",
             "Written by `benchmarks/bench_device_path.py` (rerun: `.venv/bin/python benchmarks/bench_device_path.py "
             "--device cuda`). Synthetic corpus (640 x 360, 4 frames, 8 bins, 24 lamps of 24 x 40 px), 3 frames "
             "per sample, every output but `rgb`; capture rows at crop 256, training rows at crop 128. Medians of "
             "timed passes after a warm-up pass.", "", f"Machine: {machine}", ""]
    if not gpu:
        lines += ["**GPU rows not run**: no CUDA device on the machine that wrote this file.", ""]
    lines += ["| path | batch | samples/s | notes |", "|---|---|---|---|"]
    for r in rows:
        notes = []
        if "load_s" in r:
            notes.append(f"layers loaded in {r['load_s']:.1f} s, {r['resident_bytes_per_scene'] / 2**20:.0f} MiB "
                         "per scene resident")
        if r.get("peak_bytes"):
            notes.append(f"peak {r['peak_bytes'] / 2**20:.0f} MiB per batch")
        if r.get("syncs") is not None:
            notes.append(f"{sum(n for n, _ in r['syncs'])} host synchronisations per batch")
        if "workers" in r:
            notes.append(f"{r['workers']} workers")
        if "steps" in r:
            notes.append(f"steady state (median of epochs 2-3 of {r['steps']} steps); the whole call of 3 epochs "
                         f"with its start-up: {r['with_startup']:.0f} samples/s")
        if r["path"] == "fp16":
            notes.append(f"float16 residency against float32: ground truth relative error max {r['gt_rel_max']:.2e}, "
                         f"rms {r['gt_rel_rms']:.2e}; LPD-LCG DN moved in {100 * r['lcg_dn_moved']:.3f} % of pixels "
                         f"(at most {r['lcg_dn_max']:.0f} DN); {r['bytes_per_scene_float32'] / 2**20:.1f} -> "
                         f"{r['bytes_per_scene_float16'] / 2**20:.1f} MiB per scene")
            lines.append(f"| fp16 | {r['batch']} | - | {'; '.join(notes)} |")
            continue
        lines.append(f"| {r['path']} | {r['batch']} | {r['samples_per_s']:.0f} | {'; '.join(notes)} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
