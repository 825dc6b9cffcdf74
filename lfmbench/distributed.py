"""Data-parallel training (``torchrun --nproc_per_node N -m lfmbench.cli train ...``): one model trained by N
processes, each on its share of every batch, gradients averaged by ``torch.nn.parallel.DistributedDataParallel``.

What each process does (:func:`lfmbench.train.train` with a :class:`Group`):

- the process group comes from the environment torchrun sets (``RANK``, ``LOCAL_RANK``, ``WORLD_SIZE``,
  ``MASTER_ADDR``, ``MASTER_PORT``; :func:`from_env`): NCCL on CUDA, where rank ``r`` uses ``cuda:LOCAL_RANK``;
  gloo on the CPU;
- the batch is the same as in one process: global batch ``k`` of an epoch holds the samples
  ``epoch_order(n, seed, epoch)[k*B:(k+1)*B]`` (``B = train.batch_size``, the same config on any number of
  processes, the same number of optimiser steps and learning-rate schedule), and rank ``r`` takes the ``r``-th of
  ``N`` near-equal contiguous parts of it (:func:`rank_share`); so the ranks see every sample of an epoch once
  between them, the same samples one process sees (a test checks it);
- its loss is weighted by ``w_r = b_r N / b`` (``b_r`` its part, ``b`` the global batch): DDP averages the
  gradients over the ranks, so the step follows ``sum_r b_r grad L_r / b``, the gradient of the global batch's
  mean of per-sample losses (exactly so for a loss that is a mean over samples; the U-Net's LED term pools its
  pixels over the batch, so there it is the per-rank pooled term weighted by the rank's samples). A rank whose
  part of a short last batch is empty gets a copy of one sample with weight 0: it takes part in the gradient
  average without counting (no sample counts twice);
- the logged loss is ``sum_r w_r L_r / N`` (one extra all-reduce of a few numbers per step), the same on every
  rank;
- rank 0 alone writes the checkpoint after every epoch; every rank then waits at a barrier (the next epoch, or a
  resume, never reads a half-written file); on resume every rank reads it (the checkpoint's folder must be shared
  by the processes: one machine, or a shared file system).

The device path (``--data device``) shards the split's scenes (:class:`RankDeviceBatches`): rank ``r`` loads only
the scenes ``r, r + N, ...`` (:func:`rank_scenes`) onto its device and serves only their samples; every global
batch of ``B`` samples takes from each rank in proportion to its samples (:func:`rank_step_sizes`), with the same
loss weights, so the ranks again see every sample once an epoch (streaming by chunks is not sharded: refused).
"""
from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import torch
from torch.utils.data import Dataset, Sampler

from lfmbench.datasets.device import DeviceBatches, epoch_order

__all__ = ["Group", "from_env", "rank_share", "RankBatchSampler", "RankIndexed", "RankCollate", "RankDeviceBatches",
           "rank_scenes", "rank_step_sizes", "ddp_step", "LOSS_WEIGHT"]

#: Key of a batch dict that carries the rank's loss weight ``w_r`` (removed by :func:`ddp_step`).
LOSS_WEIGHT = "_rank_loss_weight"


@dataclass
class Group:
    """This process's place in the process group: ``rank`` of ``world``, ``local_rank`` on its machine, its
    ``device``."""

    rank: int
    world: int
    local_rank: int
    device: torch.device

    @property
    def main(self) -> bool:
        """Rank 0: the one that writes files and prints."""
        return self.rank == 0

    def barrier(self) -> None:
        import torch.distributed as dist

        if self.device.type == "cuda":
            dist.barrier(device_ids=[self.device.index])
        else:
            dist.barrier()


def from_env(device: str | torch.device, environ=os.environ) -> Group | None:
    """The process group of a torchrun launch (``WORLD_SIZE`` > 1 in ``environ``), initialised here once; None for
    a plain run. ``device``: the device asked for; ``cuda`` becomes ``cuda:LOCAL_RANK`` (one GPU per process).

    Raises:
        ValueError: a torchrun variable that is not an integer, or ``cuda:K`` asked for under torchrun (each rank
            must use its own GPU).
    """
    try:
        world = int(environ.get("WORLD_SIZE", "1"))
        if world <= 1:
            return None
        rank, local = int(environ["RANK"]), int(environ.get("LOCAL_RANK", environ["RANK"]))
    except (KeyError, ValueError) as exc:
        raise ValueError(f"torchrun environment: RANK, LOCAL_RANK and WORLD_SIZE must be integers ({exc})") from None
    import torch.distributed as dist

    dev = torch.device(device)
    if dev.type == "cuda":
        if dev.index is not None:
            raise ValueError(f"--device {device}: under torchrun give --device cuda (rank r uses cuda:LOCAL_RANK)")
        dev = torch.device("cuda", local)
        torch.cuda.set_device(dev)
    if not dist.is_initialized():
        dist.init_process_group("nccl" if dev.type == "cuda" else "gloo", rank=rank, world_size=world)
    return Group(rank=rank, world=world, local_rank=local, device=dev)


def rank_share(batch: list[int], rank: int, world: int) -> tuple[list[int], float]:
    """Rank ``rank``'s part of the global batch ``batch`` (sample indices) and its loss weight ``b_r N / b``.

    The parts are contiguous, in rank order, of sizes differing by at most one; together they are ``batch``. An
    empty part (a batch shorter than ``world``) becomes ``[batch[0]]`` with weight 0 (it counts nothing)."""
    b = len(batch)
    lo, hi = rank * b // world, (rank + 1) * b // world
    part = batch[lo:hi]
    if not part:
        return [batch[0]], 0.0
    return part, len(part) * world / b


def _global_batches(n: int, batch_size: int, seed: int, epoch: int) -> list[list[int]]:
    order = epoch_order(n, seed, epoch).tolist()
    return [order[i:i + batch_size] for i in range(0, n, batch_size)]


class RankBatchSampler(Sampler):
    """Batch sampler of one rank: for each global batch of the epoch (:func:`epoch_order` of ``(seed, epoch)``,
    ``batch_size`` at a time, the last one shorter) the list ``[(epoch, index, weight), ...]`` of its part
    (:func:`rank_share`)."""

    def __init__(self, n: int, batch_size: int, seed: int, rank: int, world: int) -> None:
        self.n, self.batch_size, self.seed, self.rank, self.world = int(n), int(batch_size), int(seed), rank, world
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return -(-self.n // self.batch_size)

    def __iter__(self) -> Iterator[list[tuple[int, int, float]]]:
        for batch in _global_batches(self.n, self.batch_size, self.seed, self.epoch):
            part, w = rank_share(batch, self.rank, self.world)
            yield [(self.epoch, i, w) for i in part]


class RankIndexed(Dataset):
    """Item ``(epoch, index, weight)``: ``(dataset[index] drawn for that epoch, weight)``."""

    def __init__(self, dataset) -> None:
        self.dataset = dataset

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, key: tuple[int, int, float]) -> tuple[dict, float]:
        epoch, index, w = key
        self.dataset.set_epoch(epoch)
        return self.dataset[index], w


class RankCollate:
    """Collate ``(sample, weight)`` items: the samples by ``collate`` and the weight under :data:`LOSS_WEIGHT`."""

    def __init__(self, collate: Callable) -> None:
        self.collate = collate

    def __call__(self, items: list[tuple[dict, float]]) -> dict:
        return {**self.collate([s for s, _ in items]), LOSS_WEIGHT: float(items[0][1])}


def rank_scenes(scene_ids: list, rank: int, world: int) -> list:
    """Rank ``rank``'s scenes of a split: positions ``rank, rank + world, ...`` of ``scene_ids`` (duplicates
    dropped), as ``torch.utils.data.DistributedSampler`` strides indices; the ranks' shares are disjoint and
    together the split.

    Raises:
        ValueError: fewer scenes than ranks (a rank would hold nothing)."""
    sids = list(dict.fromkeys(scene_ids))
    if len(sids) < world:
        raise ValueError(f"the split has {len(sids)} scene(s) for {world} torchrun ranks: the device path gives "
                         "each rank its own scenes; use fewer ranks or the DataLoader path (--data loader)")
    return sids[rank::world]


def rank_step_sizes(counts: list[int], batch_size: int) -> list[list[int]]:
    """How many of each rank's samples every global batch takes: ``sizes[k][r]``.

    The ranks' samples (``counts[r]`` of rank ``r``) are interleaved in proportion (rank ``r``'s ``i``-th sample at
    the position ``(i + 1/2) / counts[r]`` of the epoch, ties by rank) and cut ``batch_size`` at a time, so that
    every global batch but the last holds ``batch_size`` samples (as in one process) and each rank's share of it
    is near ``batch_size * counts[r] / sum(counts)``."""
    keys = sorted(((2 * i + 1) / (2 * n), r) for r, n in enumerate(counts) for i in range(n))
    out = []
    for k in range(0, len(keys), batch_size):
        row = [0] * len(counts)
        for _key, r in keys[k:k + batch_size]:
            row[r] += 1
        out.append(row)
    return out


class RankDeviceBatches(DeviceBatches):
    """:class:`~lfmbench.datasets.device.DeviceBatches` of one rank that holds only its own scenes
    (:func:`rank_scenes`): global batch ``k`` of an epoch takes ``sizes[k][r]`` (:func:`rank_step_sizes`) of rank
    ``r``'s samples, in an order of ``(seed, rank, epoch)`` (:func:`~lfmbench.datasets.device.epoch_order`), so
    the ranks see every sample of the split once an epoch between them and the global batch is ``batch_size``
    (the last one shorter). The loss weight ``b_r N / b`` goes under :data:`LOSS_WEIGHT`; a rank with no sample
    in a step gets a copy of one of its own with weight 0. Not with ``chunk_scenes``.

    The batches are not those of one process (a global batch mixes the ranks' scenes in proportion, not the
    single-process order); each sample is drawn as in one process, from ``(seed, epoch, index)``."""

    def __init__(self, ds, batch_size: int, device, *, rank: int, world: int, **kw: Any) -> None:
        if kw.get("chunk_scenes") is not None:
            raise ValueError("--chunk-scenes: streaming the split by chunks is not sharded across torchrun ranks; "
                             "leave it out (each rank holds its share of the split) or train in one process")
        kw.pop("chunk_scenes", None)
        shares = [rank_scenes(ds.scene_ids, r, world) for r in range(world)]
        super().__init__(ds, batch_size, device, scenes=shares[rank], **kw)
        self.rank, self.world = rank, world
        self.sizes = rank_step_sizes([len(s) * ds.samples_per_scene for s in shares], batch_size)

    def __len__(self) -> int:
        return len(self.sizes)

    def _batches(self) -> Iterator[dict]:
        r, N = self.rank, self.world
        order = [self.own[j] for j in epoch_order(len(self.own), self.seed + 104_729 * (r + 1), self.epoch).tolist()]
        at = 0
        for row in self.sizes:
            n = row[r]
            if n == 0:  # nothing of this rank in the step: one of its samples, counting nothing
                yield {**self.batch(order[:1]), LOSS_WEIGHT: 0.0}
                continue
            yield {**self.batch(order[at:at + n]), LOSS_WEIGHT: n * N / sum(row)}
            at += n


def ddp_step(ddp_model: torch.nn.Module, opt: torch.optim.Optimizer, spec, cfg, group: Group,
             set_lr: Callable[[torch.optim.Optimizer, float], None],
             clip_gradients: Callable[[Any, float], torch.Tensor]) -> Callable[[dict, float], tuple]:
    """The training step of one rank: ``step(batch, lr) -> (loss, terms)`` as :func:`lfmbench.train.fit` takes.
    ``set_lr`` and ``clip_gradients`` are the training loop's (:mod:`lfmbench.train_step`, a stage above this one);
    ``terms["grad_norm"]`` is the norm of the averaged gradient before clipping, equal on every rank.

    The loss of the rank's part (``spec.loss`` through the DDP wrapper, whose backward all-reduces the gradients)
    is weighted by the batch's :data:`LOSS_WEIGHT`; the returned loss and terms are the weighted means over the
    ranks (all-reduced, equal on every rank)."""
    import torch.distributed as dist

    def step(batch: dict, lr: float):
        batch = dict(batch)
        w = float(batch.pop(LOSS_WEIGHT, 1.0))
        loss, terms = spec.loss(ddp_model, batch, cfg)
        set_lr(opt, lr)
        opt.zero_grad(set_to_none=True)
        (loss * w).backward()
        norm = clip_gradients(ddp_model.parameters(), cfg.train.grad_clip)
        opt.step()
        keys = [k for k, v in terms.items() if isinstance(v, (torch.Tensor, float, int))]
        vals = torch.stack([loss.detach().double().reshape(())]
                           + [torch.as_tensor(terms[k], dtype=torch.float64, device=loss.device).detach().reshape(())
                              for k in keys]) * w
        dist.all_reduce(vals)
        vals = vals / group.world
        return vals[0], {**{k: vals[1 + j] for j, k in enumerate(keys)}, "grad_norm": norm.detach()}

    return step
