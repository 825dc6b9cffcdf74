"""Per-step overhead of data-parallel training (issue 41): the U-Net training step on one process against the same
step in each of ``--ranks`` DDP processes (``lfmbench.distributed.ddp_step``: gradient all-reduce in backward, the
loss all-reduce for the log), every process with the same per-process batch, so the difference is what DDP adds;
and, as the control, ``--ranks`` plain processes at once without a process group (what sharing the cores costs
by itself). The three cases alternate ``--rounds`` times in one run.

Workload: batches of the real training path (``lfmbench.train.make_loader`` over a synthetic corpus written here:
``tests/data/corpus`` scenes, 16 x 24 px, crop 16, 3 frames), the ``unet_tiny`` network; ``--batch`` samples per
process; torch with one thread per process. Timed: ``--steps`` steps after ``--warmup`` steps, median ms per step.
Backend: gloo on the CPU (``--device cpu``). ``--device cuda`` (one GPU): the plain step against the DDP step of
a one-rank NCCL group (NCCL takes one rank per GPU), ``unet_v1`` on a device-path batch of ``--batch`` (64)
samples at crop 128: what DDP's machinery (gradient buckets, their all-reduce, the loss all-reduce) adds per step.

Writes its section of ``docs/benchmarks/distributed.md`` ("CPU processes (gloo)" or "One GPU (NCCL)"; ``--no-doc``:
only print). Run: ``.venv/bin/python benchmarks/bench_ddp.py [--device cuda]``.
"""
from __future__ import annotations

import argparse
import os
import platform
import socket
import statistics
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

CFG = {"model": {"base_channels": 8, "depth": 2, "context_frames": 1},
       "train": {"epochs": 1, "crop": 16, "samples_per_scene": 8, "workers": 0, "lr": 3e-3}}


def _batches(corpus: Path, batch: int, n: int) -> list[dict]:
    from lfmbench import train as T

    spec = T.trainable("unet")
    cfg = spec.config_from_dict({**CFG, "train": {**CFG["train"], "batch_size": batch}}, "bench")
    loader, set_epoch = T.make_loader(corpus, spec, cfg, 0)
    out: list[dict] = []
    ep = 0
    while len(out) < n:
        set_epoch(ep)
        out += [b for b in loader if b["gt"].shape[0] == batch]
        ep += 1
    return out[:n]


def _time_steps(step, batches: list[dict], warmup: int) -> list[float]:
    ts = []
    for i, b in enumerate(batches):
        t0 = time.perf_counter()
        loss, _ = step(b, 3e-3)
        float(loss.detach())
        if i >= warmup:
            ts.append((time.perf_counter() - t0) * 1e3)
    return ts


def _model(batch: int):
    from lfmbench import train as T
    from lfmbench import train_step as S

    spec = T.trainable("unet")
    cfg = spec.config_from_dict({**CFG, "train": {**CFG["train"], "batch_size": batch}}, "bench")
    torch.manual_seed(0)
    model = spec.build_model(cfg)
    return spec, cfg, model, S.make_optimizer(model, cfg, torch.device("cpu"))


def plain(corpus: Path, batch: int, steps: int, warmup: int) -> list[float]:
    from lfmbench import train_step as S

    spec, cfg, model, opt = _model(batch)
    return _time_steps(lambda b, lr: S._eager_step(model, opt, spec, cfg, b, lr), _batches(corpus, batch, steps + warmup),
                       warmup)


def _rank(rank: int, world: int, port: int, corpus: Path, batch: int, steps: int, warmup: int, out: Path) -> None:
    os.environ.update(RANK=str(rank), LOCAL_RANK=str(rank), WORLD_SIZE=str(world), MASTER_ADDR="127.0.0.1",
                      MASTER_PORT=str(port))
    torch.set_num_threads(1)
    import torch.distributed as dist
    from torch.nn.parallel import DistributedDataParallel

    from lfmbench import distributed as D
    from lfmbench import train_step as S

    group = D.from_env("cpu")
    spec, cfg, model, opt = _model(batch)
    step = D.ddp_step(DistributedDataParallel(model), opt, spec, cfg, group, S._set_lr)
    bs = _batches(corpus, batch, steps + warmup)
    group.barrier()
    ts = _time_steps(step, bs, warmup)
    from lfmbench.fileio import atomic_torch_save

    atomic_torch_save(ts, out / f"rank{rank}.pt")
    dist.destroy_process_group()


def _solo(rank: int, corpus: Path, batch: int, steps: int, warmup: int, out: Path) -> None:
    """One of ``--ranks`` independent plain processes run at once (no process group): the control for DDP."""
    torch.set_num_threads(1)
    from lfmbench.fileio import atomic_torch_save

    atomic_torch_save(plain(corpus, batch, steps, warmup), out / f"solo{rank}.pt")


def ddp(corpus: Path, batch: int, steps: int, warmup: int, world: int, tmp: Path) -> list[float]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    torch.multiprocessing.start_processes(_rank, args=(world, port, corpus, batch, steps, warmup, tmp), nprocs=world,
                                          start_method="spawn")  # fork after torch ran here can hang a child
    per = [torch.load(tmp / f"rank{r}.pt") for r in range(world)]
    return [max(ts) for ts in zip(*per)]  # a step ends when the slowest rank ends it


def solo(corpus: Path, batch: int, steps: int, warmup: int, world: int, tmp: Path) -> list[float]:
    """``world`` plain processes at once, each its own model: step k's time is the slowest process's k-th step
    (the rule of :func:`ddp`), so the two rows differ by what DDP adds to processes that share the cores."""
    torch.multiprocessing.start_processes(_solo, args=(corpus, batch, steps, warmup, tmp), nprocs=world,
                                          start_method="spawn")
    per = [torch.load(tmp / f"solo{r}.pt") for r in range(world)]
    return [max(ts) for ts in zip(*per)]


def _gpu_batch(batch: int, crop: int, tmp: Path, device: str = "cuda:0") -> tuple:
    """(spec, cfg, one training batch on cuda:0): ``unet_v1`` and a device-path batch of ``batch`` samples at
    ``crop`` px from :func:`_device_corpus.make_corpus` (2 synthetic 640 x 360 scenes), as that page's step rows."""
    from _device_corpus import make_corpus
    from bench_device_path import _dataset

    from lfmbench.datasets.device import DeviceBatches
    from lfmbench.train import load_config, trainable

    spec = trainable("unet")
    cfg = load_config("unet", ROOT / "lfmbench" / "configs" / "unet_v1.yaml")
    root = make_corpus(tmp / "gpu_corpus", 2)
    kw = {} if spec.outputs is None else {"outputs": spec.outputs}
    ds = _dataset(root, crop, noise_streams="counter", **kw)
    return spec, cfg, next(iter(DeviceBatches(ds, batch, device, seed=0)))


def _gpu_steps(step, batch: dict, steps: int, warmup: int, dev: torch.device) -> float:
    """ms per step over ``steps`` steps queued back to back (one synchronisation at the end, as ``train()`` runs
    them: it reads each loss later without waiting), after ``warmup`` steps."""
    for _ in range(warmup):
        step(batch, 1e-3)
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)
    t0 = time.perf_counter()
    for _ in range(steps):
        step(batch, 1e-3)
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)
    return (time.perf_counter() - t0) * 1e3 / steps


def gpu_rounds(batch: int, crop: int, steps: int, warmup: int, rounds: int, device: str = "cuda"
               ) -> dict[str, list[float]]:
    """One GPU: the plain step (``train_step._eager_step``) against the DDP step of a one-rank NCCL group
    (``lfmbench.distributed.ddp_step`` through ``DistributedDataParallel``: gradient buckets, their all-reduce and
    the loss all-reduce), each its own model from the same seed, alternating ``rounds`` times. ``device="cpu"``:
    the same with gloo (a check of this code without a GPU)."""
    import torch.distributed as dist
    from torch.nn.parallel import DistributedDataParallel

    from lfmbench import distributed as D
    from lfmbench import train_step as S

    with socket.socket() as sk:
        sk.bind(("127.0.0.1", 0))
        port = sk.getsockname()[1]
    dev = torch.device("cuda", 0) if device == "cuda" else torch.device("cpu")
    if dev.type == "cuda":
        torch.cuda.set_device(dev)
    dist.init_process_group("nccl" if dev.type == "cuda" else "gloo", init_method=f"tcp://127.0.0.1:{port}", rank=0,
                            world_size=1)
    try:
        with tempfile.TemporaryDirectory() as d:
            spec, cfg, b = _gpu_batch(batch, crop, Path(d), str(dev))
        models = {}
        for name in ("plain", "ddp"):
            torch.manual_seed(0)
            m = spec.build_model(cfg).to(dev)
            models[name] = (m, S.make_optimizer(m, cfg, dev))
        m, opt = models["plain"]
        plain_step = lambda bb, lr: S._eager_step(m, opt, spec, cfg, bb, lr)  # noqa: E731
        dm, dopt = models["ddp"]
        group = D.Group(rank=0, world=1, local_rank=0, device=dev)
        wrapped = DistributedDataParallel(dm, device_ids=[0] if dev.type == "cuda" else None)
        ddp = D.ddp_step(wrapped, dopt, spec, cfg, group, S._set_lr)
        out: dict[str, list[float]] = {"plain": [], "ddp": []}
        for r in range(rounds):
            out["plain"].append(_gpu_steps(plain_step, b, steps, warmup, dev))
            out["ddp"].append(_gpu_steps(ddp, b, steps, warmup, dev))
            print(f"round {r + 1}: plain {out['plain'][-1]:.2f} ms, ddp {out['ddp'][-1]:.2f} ms", flush=True)
        return out
    finally:
        dist.destroy_process_group()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cpu", help="cpu (gloo, --ranks processes) or cuda (one GPU: a one-rank "
                                                  "NCCL group against the plain step)")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--batch", type=int, default=None, help="samples per process per step (default 4; cuda: 64)")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3, help="rounds of (plain, DDP, independent processes)")
    ap.add_argument("--no-doc", action="store_true")
    a = ap.parse_args()
    from _timing import replace_section

    from tests.data.corpus.data import make_corpus

    when = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")),
               platform.machine())
    load0 = open("/proc/loadavg").read().split()[:3]
    if a.device.startswith("cuda"):
        if not torch.cuda.is_available():
            print("error: --device cuda: no CUDA device here", file=sys.stderr)
            sys.exit(2)
        batch = a.batch or 64
        med = gpu_rounds(batch, 128, a.steps, a.warmup, a.rounds)
        load1 = open("/proc/loadavg").read().split()[:3]
        m = {k: statistics.median(v) for k, v in med.items()}
        heading = "## One GPU (NCCL)"
        lines = [heading, "",
                 f"Measured {when}; machine: {torch.cuda.get_device_name(0)}, host {cpu}, {os.cpu_count()} cores, "
                 f"torch {torch.__version__}; load average before {' '.join(load0)}, after {' '.join(load1)}. Rerun: "
                 "`.venv/bin/python benchmarks/bench_ddp.py --device cuda`.", "",
                 f"U-Net `unet_v1`, {batch} samples of 128 x 128 px (3 frames) per step from the device path (one "
                 f"batch, resident); {a.steps} steps queued back to back after {a.warmup} warm-up steps, one "
                 "synchronisation at the end (as `train()` runs them); the DDP step is `lfmbench.distributed."
                 "ddp_step` through `DistributedDataParallel` in a one-rank NCCL group (one GPU: NCCL takes one "
                 f"rank per GPU), so the difference is what DDP's machinery adds per step; {a.rounds} rounds "
                 "alternating, the median of the rounds.", "",
                 "| step | ms per step (median) | rounds, ms | vs plain |", "|---|---|---|---|",
                 *(f"| {n} | {m[k]:.2f} | {', '.join(f'{x:.2f}' for x in med[k])} | {m[k] / m['plain']:.3f} |"
                   for n, k in (("plain step (`train()` on one GPU)", "plain"), ("DDP step, one rank (NCCL)", "ddp"))),
                 "", f"DDP overhead per step on one GPU: {m['ddp'] - m['plain']:+.2f} ms "
                     f"({100 * (m['ddp'] / m['plain'] - 1):+.1f} %).", ""]
    else:
        batch = a.batch or 4
        torch.set_num_threads(1)
        med = {"plain": [], "ddp": [], "solo": []}
        with tempfile.TemporaryDirectory() as d:
            corpus = make_corpus(Path(d) / "c", n_scenes=5)
            for r in range(a.rounds):  # alternating, so that the machine's drifting load meets every case
                med["plain"].append(statistics.median(plain(corpus, batch, a.steps, a.warmup)))
                med["ddp"].append(statistics.median(ddp(corpus, batch, a.steps, a.warmup, a.ranks, Path(d))))
                med["solo"].append(statistics.median(solo(corpus, batch, a.steps, a.warmup, a.ranks, Path(d))))
                print(f"round {r + 1}: " + ", ".join(f"{k} {v[-1]:.1f} ms" for k, v in med.items()), flush=True)
        load1 = open("/proc/loadavg").read().split()[:3]
        m = {k: statistics.median(v) for k, v in med.items()}
        rows = [("one process (plain step)", "plain"),
                (f"{a.ranks} plain processes at once, no DDP (each its own model and batch)", "solo"),
                (f"DDP, {a.ranks} processes (gloo), each the same batch", "ddp")]
        heading = "## CPU processes (gloo)"
        lines = [heading, "",
                 f"Measured {when}; machine: {cpu}, {os.cpu_count()} cores, torch {torch.__version__}; load average "
                 f"before {' '.join(load0)}, after {' '.join(load1)} (a shared, loaded machine: {a.ranks} ranks "
                 f"compete with other work for {os.cpu_count()} cores). Rerun: `.venv/bin/python "
                 "benchmarks/bench_ddp.py`.", "",
                 f"U-Net (`unet_tiny` widths), {batch} samples of 16 x 16 px (3 frames) per process per step, one "
                 f"torch thread per process; each case the median of {a.steps} steps after {a.warmup} warm-up steps "
                 "(with several processes, step k lasts until the slowest process ends its k-th step); "
                 f"{a.rounds} rounds of the three cases in turn (plain, DDP, independent processes), the median of "
                 "the rounds' medians.", "",
                 "| step | ms per step (median) | rounds, ms | vs one process |", "|---|---|---|---|",
                 *(f"| {n} | {m[k]:.1f} | {', '.join(f'{x:.1f}' for x in med[k])} | {m[k] / m['plain']:.2f} |"
                   for n, k in rows),
                 "", f"DDP overhead per step: {m['ddp'] - m['plain']:+.1f} ms against one process "
                     f"({m['ddp'] / m['plain']:.2f}x), {m['ddp'] - m['solo']:+.1f} ms ({m['ddp'] / m['solo']:.2f}x) "
                     f"against {a.ranks} independent processes on the same cores. The second is what DDP itself adds "
                     "(the gradient all-reduce over gloo on loopback, the all-reduce of the logged loss, the ranks "
                     f"waiting for each other); the rest is {a.ranks} processes sharing {os.cpu_count()} cores with "
                     "the machine's other work.", ""]
    print("\n".join(lines))
    if not a.no_doc:
        replace_section(ROOT / "docs" / "benchmarks" / "distributed.md", heading, lines)


if __name__ == "__main__":
    main()
