"""Per-step overhead of data-parallel training (issue 41): the U-Net training step on one process against the same
step in each of ``--ranks`` DDP processes (``lfmbench.distributed.ddp_step``: gradient all-reduce in backward, the
loss all-reduce for the log), every process with the same per-process batch, so the difference is what DDP adds;
and, as the control, ``--ranks`` plain processes at once without a process group (what sharing the cores costs
by itself). The three cases alternate ``--rounds`` times in one run.

Workload: batches of the real training path (``lfmbench.train.make_loader`` over a synthetic corpus written here:
``tests/data/corpus`` scenes, 16 x 24 px, crop 16, 3 frames), the ``unet_tiny`` network; ``--batch`` samples per
process; torch with one thread per process. Timed: ``--steps`` steps after ``--warmup`` steps, median ms per step.
Backend: gloo on the CPU (``--device cpu``), NCCL with one GPU per rank on CUDA (not run here: no GPU).

Writes ``docs/benchmarks/distributed.md`` (``--no-doc``: only print). Run: ``.venv/bin/python benchmarks/bench_ddp.py``.
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


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3, help="rounds of (plain, DDP, independent processes)")
    ap.add_argument("--no-doc", action="store_true")
    a = ap.parse_args()
    from tests.data.corpus.data import make_corpus

    torch.set_num_threads(1)
    load0 = open("/proc/loadavg").read().split()[:3]
    med: dict[str, list[float]] = {"plain": [], "ddp": [], "solo": []}
    with tempfile.TemporaryDirectory() as d:
        corpus = make_corpus(Path(d) / "c", n_scenes=5)
        for r in range(a.rounds):  # alternating, so that the machine's drifting load meets every case
            med["plain"].append(statistics.median(plain(corpus, a.batch, a.steps, a.warmup)))
            med["ddp"].append(statistics.median(ddp(corpus, a.batch, a.steps, a.warmup, a.ranks, Path(d))))
            med["solo"].append(statistics.median(solo(corpus, a.batch, a.steps, a.warmup, a.ranks, Path(d))))
            print(f"round {r + 1}: " + ", ".join(f"{k} {v[-1]:.1f} ms" for k, v in med.items()), flush=True)
    load1 = open("/proc/loadavg").read().split()[:3]
    m = {k: statistics.median(v) for k, v in med.items()}
    when = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")),
               platform.machine())
    rows = [("one process (plain step)", "plain"),
            (f"{a.ranks} plain processes at once, no DDP (each its own model and batch)", "solo"),
            (f"DDP, {a.ranks} processes (gloo), each the same batch", "ddp")]
    text = (f"# Data-parallel training: per-step overhead\n\n"
            f"Measured {when}; machine: {cpu}, {os.cpu_count()} cores, "
            f"torch {torch.__version__}; load average before {' '.join(load0)}, after {' '.join(load1)} (a shared, "
            f"loaded machine: {a.ranks} ranks compete with other work for {os.cpu_count()} cores). Rerun: "
            f"`.venv/bin/python benchmarks/bench_ddp.py`.\n\n"
            f"U-Net (`unet_tiny` widths), {a.batch} samples of 16 x 16 px (3 frames) per process per step, one torch "
            f"thread per process; each case the median of {a.steps} steps after {a.warmup} warm-up steps (with "
            f"several processes, step k lasts until the slowest process ends its k-th step); {a.rounds} rounds of "
            "the three cases in turn (plain, DDP, independent processes), the median of the rounds' medians.\n\n"
            "| step | ms per step (median) | rounds, ms | vs one process |\n|---|---|---|---|\n"
            + "".join(f"| {n} | {m[k]:.1f} | {', '.join(f'{x:.1f}' for x in med[k])} | {m[k] / m['plain']:.2f} |\n"
                      for n, k in rows)
            + f"\nDDP overhead per step: {m['ddp'] - m['plain']:+.1f} ms against one process "
              f"({m['ddp'] / m['plain']:.2f}x), "
              f"{m['ddp'] - m['solo']:+.1f} ms ({m['ddp'] / m['solo']:.2f}x) against {a.ranks} independent processes "
              "on the same cores. The second is what DDP itself adds (the gradient all-reduce over gloo on "
              "loopback, the all-reduce of the logged loss, the ranks waiting for each other); the rest is "
              f"{a.ranks} processes sharing {os.cpu_count()} cores with the machine's other work. The GPU figure "
              "(NCCL, one GPU per rank) is open: no GPU here.\n")
    print(text)
    if not a.no_doc:
        from lfmbench.fileio import atomic_write_text

        atomic_write_text(ROOT / "docs" / "benchmarks" / "distributed.md", text)


if __name__ == "__main__":
    main()
