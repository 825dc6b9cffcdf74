"""The training data path end to end: DataLoader workers against the corpus resident on the device (issue 28).

Times, in samples/s (median of timed passes after a warm-up pass; CUDA synchronised), on ``--device``:

- ``loader``: ``LFMCaptureDataset`` in a ``DataLoader`` (``--workers`` processes, per-sample composition and noise
  on the CPU), each batch moved to the device: what ``train(data="loader")`` feeds the network;
- ``device``: :class:`lfmbench.datasets.device.DeviceBatches` (layers resident on the device, each batch cut,
  composed and simulated there with counter-based noise): what ``train(data="device")`` feeds it;
- ``step``: the U-Net (``unet_v1``) training step alone on a batch already on the device (the ceiling);
- ``train``: ``lfmbench.train.train`` end to end for ``--steps`` optimiser steps, per data source.

Workload: a corpus written here (``--scenes`` scenes, 4 frames, 4 bands), 3 frames per sample, every output but
``rgb``; capture rows at a 256 x 256 crop, training rows at crop 128. Its radiance: ``--levels`` the radiance of
rendered scenes (an npz of :func:`_device_corpus.extract_levels`, made by ``--levels CORPUS --save-levels FILE``
from a rendered 31-band corpus, e.g. ``lfmbench render --protocol lfmbench-v1 --split test``: templates taken in
turn from each time of day, their 31 bands summed into 4 with the wavelength integral kept, their lights' boxes and
bins; scene i is template i mod T at its size, 640 x 360 for the protocols), so that the electron levels, on which
the Poisson sampler's cost depends (search under ~10 e-, rejection to ~1,000 e-, Gaussian above), are a real
corpus's; without it random radiance (640 x 360, 8 time bins, 24 lamps of 24 x 40 px, levels all within 10-1,000
e-). Use at least 64 scenes on a GPU (21 / 11 MiB resident per scene: far beyond the 50-60 MB L2 cache of an H100 /
H200).

Rows ``split``: the device path's halves on the same batches, ``pieces`` (draws, crops, composition) and the sensor
chain alone, with the distribution of the chain's electron levels; ``--profile``: the GPU kernel time of one batch
of 256, to set against the end-to-end ms per batch. Every scene's layers are projected into the corpus's cache
before the first timed row (:func:`prewarm`). The corpus itself: ``benchmarks/_device_corpus.py``. Also reports
the resident bytes per scene and the peak device memory per batch.

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
from _device_corpus import extract_levels, make_corpus  # noqa: E402
from _timing import write_device_doc  # noqa: E402
from lfmbench.fileio import atomic_write_text  # noqa: E402
DOC = ROOT / "docs" / "benchmarks" / "device-path.md"
OUTS = ("raw", "input_referred", "saturated", "gt", "light_index", "depth")


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


def prewarm(root: Path, crops=(256, 128)) -> float:
    """Build every scene's projected layers into the corpus's on-disk cache (:func:`lfmbench.datasets.projection.
    load_or_build`) in threads, for the datasets of the capture rows and of the training rows, so that no timed row
    and no "layers loaded" figure includes the first projection of a scene. Returns the seconds it took."""
    from concurrent.futures import ThreadPoolExecutor

    from lfmbench.datasets.projection import aux_channels, load_or_build
    from lfmbench.train import trainable

    spec = trainable("unet")
    t0 = time.perf_counter()
    for crop, kw in ((crops[0], {}), (crops[1], {"noise_streams": "counter",
                                               **({} if spec.outputs is None else {"outputs": spec.outputs})})):
        ds = _dataset(root, crop, **kw)

        def one(sid, ds=ds):
            load_or_build(ds.corpus, sid, ds._layer_preset, ds.groups, ds._frames_to_load(sid), ds.optics,
                          ds.cache_dir, aux=aux_channels(ds.outputs))
        with ThreadPoolExecutor(max(1, min(16, os.cpu_count() or 1))) as ex:
            list(ex.map(one, dict.fromkeys(ds.scene_ids)))
    return time.perf_counter() - t0


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


def time_split(root, dev, batch, batches, passes) -> dict:
    """The device path's two halves at ``batch`` on the same batches: ``pieces`` (the counter draws, the crops and
    the composition of the mean electron rates: :meth:`DeviceBatches.pieces`) and ``chain`` (the sensor chain alone,
    :func:`lfmbench.datasets.batched.simulate_batch`, on pieces made beforehand), in samples/s and ms per batch;
    and the electron levels the chain sees (``gt``: LPD-equivalent mean e- over the short exposure, noise-free)
    as fractions under 10 e- (the Poisson sampler's search), 10-1,000 e- (rejection) and above (Gaussian)."""
    from lfmbench.datasets.batched import simulate_batch
    from lfmbench.datasets.device import DeviceBatches

    from lfmbench.datasets.device import epoch_order

    db = DeviceBatches(_dataset(root, 256, batch * batches), batch, dev, seed=0)
    order = epoch_order(len(db.ds), 0, 0).tolist()  # as the device rows: each batch mixes the scenes
    idx = [order[k * batch:(k + 1) * batch] for k in range(batches)]

    def run_pieces():
        for i in idx:
            db.pieces(i)
    med_p, _ = _timed(run_pieces, passes, dev)
    made = [db.pieces(i) for i in idx]

    def run_chain():
        for p in made:
            simulate_batch(p, db.ds.preset, noise_streams="counter")
    med_c, _ = _timed(run_chain, passes, dev)
    gt = torch.cat([simulate_batch(p, db.ds.preset, noise_streams="counter")["gt"].double().flatten()
                    for p in made])
    qs = torch.quantile(gt[torch.randperm(gt.numel(), generator=torch.Generator().manual_seed(0))[:1 << 20]
                           .to(gt.device)], torch.tensor([0.5, 0.99], dtype=torch.float64, device=gt.device))
    return {"pieces_sps": batch * batches / med_p, "pieces_ms": 1e3 * med_p / batches,
            "chain_sps": batch * batches / med_c, "chain_ms": 1e3 * med_c / batches,
            "e_under_10": float((gt < 10).double().mean()),
            "e_10_1000": float(((gt >= 10) & (gt < 1000)).double().mean()),
            "e_over_1000": float((gt >= 1000).double().mean()), "e_median": float(qs[0]), "e_p99": float(qs[1])}


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


def profile_device(root, dev, batch: int, out: Path | None) -> dict:
    """Where the device path's GPU time goes: torch.profiler over one batch (after a warm-up), the top kernels;
    returns the batch's summed GPU kernel time (ms) and its wall time under the profiler (ms)."""
    from torch.profiler import ProfilerActivity, profile

    from lfmbench.datasets.device import DeviceBatches

    db = DeviceBatches(_dataset(root, 256, batch), batch, dev, seed=0)
    db.batch(range(batch))
    _sync(dev)
    acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if dev.type == "cuda" else [])
    with profile(activities=acts) as prof:
        t0 = time.perf_counter()
        db.batch(range(batch))
        _sync(dev)
        wall = time.perf_counter() - t0
    table = prof.key_averages().table(sort_by="cuda_time_total" if dev.type == "cuda" else "cpu_time_total",
                                      row_limit=25, max_name_column_width=60)
    print(table)
    # the table's "Self CUDA time total": the device-side events only (a CPU event that launches a kernel carries
    # the same time again), as torch.autograd.profiler_util._build_table sums them
    dev_events = [e for e in prof.key_averages() if getattr(e, "device_type", None) == torch.autograd.DeviceType.CUDA
                  and not getattr(e, "is_user_annotation", False)]
    kernel_us = sum(e.self_device_time_total for e in dev_events)
    kernels = sum(e.count for e in dev_events)
    if out is not None:
        atomic_write_text(out, table + f"\nGPU kernel time of the batch: {kernel_us / 1e3:.2f} ms in {kernels} "
                               f"kernel launches; wall time under the profiler {1e3 * wall:.2f} ms\n")
    return {"kernel_ms": kernel_us / 1e3, "kernels": kernels, "profiled_wall_ms": 1e3 * wall}


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
    ap.add_argument("--levels", type=Path, default=None,
                    help="radiance of rendered scenes for the corpus: an npz written by --save-levels, or a rendered "
                         "corpus of 31 bands (its first --templates scenes); default: random radiance")
    ap.add_argument("--templates", type=int, default=4, help="rendered scenes taken from a --levels corpus")
    ap.add_argument("--save-levels", type=Path, default=None,
                    help="write the --levels corpus's templates to this npz (a few MiB) and stop")
    ap.add_argument("--rows", default="loader,device,split,device-samplewise,fp16,step,step-graph,train-loader,"
                                      "train-device,train-device-eager",
                    help="comma-separated rows to measure (default: all)")
    ap.add_argument("--no-doc", action="store_true")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--profile", type=Path, default=None,
                    help="also profile one batch of 256 on the device and write the kernel table here")
    ap.add_argument("--batches", default=None, help="comma-separated batch sizes of the capture rows (default: "
                                                   "64,256,1024 on a GPU, 8,64 on the CPU)")
    args = ap.parse_args(argv)
    if args.levels is not None and args.levels.is_dir():
        out = args.save_levels or Path(tempfile.mkdtemp()) / "levels.npz"
        args.levels = extract_levels(args.levels, args.templates, out)
        if args.save_levels is not None:
            print(f"wrote {out} ({out.stat().st_size / 2**20:.1f} MiB)")
            return 0
    elif args.save_levels is not None:
        print("error: --save-levels needs --levels CORPUS (a rendered corpus folder)", file=sys.stderr)
        return 2
    if args.levels is not None and not args.levels.is_file():
        print(f"error: --levels {args.levels}: no such file or corpus folder", file=sys.stderr)
        return 2
    if args.device == "auto":
        args.device = "cuda" if torch.cuda.is_available() else "cpu"
    dev = torch.device(args.device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        print("error: --device cuda: no CUDA device here", file=sys.stderr)
        return 2
    workers = args.workers if args.workers is not None else max(1, (os.cpu_count() or 2) - 2)
    t0 = time.perf_counter()
    root = make_corpus(args.corpus or Path(tempfile.mkdtemp()) / "corpus", args.scenes, levels=args.levels)
    print(f"corpus {root}: {args.scenes} scenes in {time.perf_counter() - t0:.1f} s", flush=True)
    print(f"layers projected into the corpus's cache in {prewarm(root):.1f} s", flush=True)
    gpu = dev.type == "cuda"
    batches = (64, 256, 1024) if gpu else (8, 64)
    if args.batches:
        batches = tuple(int(b) for b in args.batches.split(","))
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
        if "split" in wanted:
            add(path="split", batch=b, samples_per_s=float("nan"), **time_split(root, dev, b, n_b, passes))
        if "device-samplewise" in wanted:
            sps, load_s, per_scene, peak, syncs = time_device(root, dev, b, n_b, passes, program=False)
            add(path="device (pieces per sample)", batch=b, samples_per_s=sps, load_s=load_s,
                resident_bytes_per_scene=per_scene, peak_bytes=peak)
    if "fp16" in wanted:
        fb = 64 if gpu else 8
        add(path="fp16", batch=fb, samples_per_s=float("nan"), **measure_fp16(root, dev, fb))
    if args.profile is not None:
        pb = 256 if gpu else 8
        add(path="profile", batch=pb, samples_per_s=float("nan"), **profile_device(root, dev, pb, args.profile))
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
    from lfmbench.corpus import Corpus

    nbytes = sum(f.stat().st_size for f in root.rglob("*") if f.is_file())
    c = Corpus(root)
    m0 = c.meta(c.scenes[0])
    if args.levels is not None:
        lv = np.load(args.levels)
        times = ", ".join(str(lv[f"s{t}_time"]) for t in range(int(lv["templates"])))
        radiance = f"radiance of {int(lv['templates'])} rendered scenes (`--levels`: {times})"
    else:
        radiance = "random radiance"
    workload = (f"{len(c.scenes)} scenes of {m0['width']} x {m0['height']} px, 4 frames, {nbytes / 2**20:.0f} MiB on "
                f"disk, {radiance}")
    text = report(rows, f"{name}, torch {torch.__version__}, {os.cpu_count()} CPU cores, {workers} loader workers",
                  gpu, workload)
    print(text)
    if not args.no_doc:
        write_device_doc(text, args.device, DOC, ROOT)
    return 0


def report(rows, machine, gpu, workload: str = "") -> str:
    lines = ["# The training data path: DataLoader workers against the corpus resident on the device", "",
             "Written by `benchmarks/bench_device_path.py` (rerun: `.venv/bin/python benchmarks/bench_device_path.py "
             "--device cuda`). A corpus written by the script (below), 3 frames per sample, every output but `rgb`; "
             "capture rows at crop 256, training rows at crop 128. Medians of timed passes after a warm-up pass.", "",
             f"Machine: {machine}", "", f"Corpus: {workload}", ""]
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
        if r["path"] == "split":
            lines.append(f"| pieces (draws, crops, composition) | {r['batch']} | {r['pieces_sps']:.0f} | "
                         f"{r['pieces_ms']:.2f} ms per batch |")
            lines.append(f"| sensor chain alone | {r['batch']} | {r['chain_sps']:.0f} | {r['chain_ms']:.2f} ms per "
                         f"batch; electron levels (`gt`, LPD-equivalent mean e- over the short exposure): "
                         f"{100 * r['e_under_10']:.1f} % < 10 e-, {100 * r['e_10_1000']:.1f} % 10-1,000 e-, "
                         f"{100 * r['e_over_1000']:.1f} % >= 1,000 e-; median {r['e_median']:.3g}, "
                         f"p99 {r['e_p99']:.3g} e- |")
            continue
        if r["path"] == "profile":
            lines.append(f"| profile (one batch) | {r['batch']} | - | GPU kernel time {r['kernel_ms']:.2f} ms in "
                         f"{r['kernels']} launches; wall time under the profiler {r['profiled_wall_ms']:.2f} ms |")
            continue
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
