"""Training of the U-Net fusion baseline: ``lfmbench train`` (settings: a YAML config, ``lfmbench/configs/unet.yaml``).

Data flow: :class:`~lfmbench.datasets.LFMCaptureDataset` (random crops, PWM draws and noise per sample) ->
``torch.utils.data.DataLoader`` (``workers`` processes) -> :class:`~lfmbench.baselines.unet.UNetFusion` ->
:func:`~lfmbench.baselines.unet.led_weighted_loss` -> Adam with a cosine learning-rate schedule.

Deterministic given the seed: a sample depends only on ``(seed, epoch, index)`` (docs/datasets.md), the order of
the samples of epoch e only on ``(seed, e)`` (:class:`EpochSampler`), and the weights are initialised after
``torch.manual_seed(seed)``. The sampler hands ``(epoch, index)`` pairs to the workers, so persistent workers
(which keep their scene caches between epochs) still draw the right epoch. The checkpoint is written atomically
after every epoch with the optimiser state; running the same command again resumes after the last finished
epoch (and does nothing when all epochs are done), so a resumed run ends with the same weights as an
uninterrupted one.
"""
from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import torch
from torch.utils.data import DataLoader, Dataset, Sampler

from lfmbench.baselines.unet import (UNetConfig, UNetFusion, config_from_dict, count_parameters,
                                     led_weighted_loss, load_config, read_checkpoint, save_checkpoint)

#: Dataset outputs the training reads (no DN images, no depth).
TRAIN_OUTPUTS = ("input_referred", "saturated", "gt", "light_index")


class EpochSampler(Sampler):
    """Yields ``(epoch, index)`` for a permutation of ``range(n)`` that depends only on ``(seed, epoch)``."""

    def __init__(self, n: int, seed: int = 0):
        self.n, self.seed, self.epoch = int(n), int(seed), 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return self.n

    def __iter__(self) -> Iterator[tuple[int, int]]:
        g = torch.Generator().manual_seed(self.seed * 1_000_003 + self.epoch)
        return iter([(self.epoch, int(i)) for i in torch.randperm(self.n, generator=g)])


class EpochIndexed(Dataset):
    """Wraps a dataset with ``set_epoch``: item ``(epoch, index)`` is ``dataset[index]`` drawn for that epoch."""

    def __init__(self, dataset):
        self.dataset = dataset

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, key: tuple[int, int]) -> dict:
        epoch, index = key
        self.dataset.set_epoch(epoch)
        return self.dataset[index]


def make_loader(corpus: str | os.PathLike, cfg: UNetConfig, workers: int | None = None,
                device: torch.device | str = "cpu") -> tuple[DataLoader, EpochSampler]:
    """DataLoader of training batches over :class:`~lfmbench.datasets.LFMCaptureDataset` and its sampler."""
    from lfmbench.datasets.loading import collate_samples, make_dataset

    t = cfg.train
    ds = make_dataset(corpus, t.split, seed=t.seed, crop=t.crop, samples_per_scene=t.samples_per_scene,
                      frames=t.frames, sensor=t.sensor, outputs=TRAIN_OUTPUTS)
    sampler = EpochSampler(len(ds), t.seed)
    nw = t.workers if workers is None else int(workers)
    loader = DataLoader(EpochIndexed(ds), batch_size=t.batch_size, sampler=sampler, num_workers=nw,
                        collate_fn=collate_samples, persistent_workers=nw > 0,
                        pin_memory=torch.device(device).type == "cuda")
    return loader, sampler


def cosine_lr(step: int, total: int, lr: float, lr_min: float) -> float:
    """Learning rate of optimiser step ``step`` of ``total``: cosine from ``lr`` to ``lr_min``."""
    frac = min(step, total) / max(total, 1)
    return lr_min + 0.5 * (lr - lr_min) * (1.0 + math.cos(math.pi * frac))


def _to(batch: dict, device: torch.device) -> dict:
    return {k: (v.to(device, non_blocking=True) if isinstance(v, torch.Tensor) else v) for k, v in batch.items()}


def train(corpus: str | os.PathLike, out: str | os.PathLike, cfg: UNetConfig, *, device: str = "cpu",
          epochs: int | None = None, workers: int | None = None, resume: bool = True, max_steps: int | None = None,
          progress: bool = True, log: Callable[[str], None] | None = print) -> tuple[UNetFusion, dict]:
    """Train :class:`UNetFusion` on ``corpus`` and write the checkpoint ``out`` after every epoch (atomically).

    Args:
        corpus: corpus directory.
        out: checkpoint path (resumed from when it exists and ``resume``).
        cfg: configuration (:func:`lfmbench.baselines.unet.load_config`).
        device: torch device of the network.
        epochs: overrides ``cfg.train.epochs`` (the total, counting epochs done before a resume).
        workers: overrides ``cfg.train.workers``.
        resume: continue from ``out`` when it holds a checkpoint of the same model and training config.
        max_steps: stop after this many optimiser steps in this call (tests); the checkpoint is still written.
        progress: show a tqdm bar per epoch.
        log: callback for one line per epoch (None: silent).

    Returns:
        (model in eval mode, the checkpoint's ``history`` dict: per-epoch mean losses and seconds, steps).
    """
    dev = torch.device(device)
    if epochs is not None:
        if epochs < 1:
            raise ValueError(f"epochs must be >= 1, got {epochs}")
        cfg = config_from_dict({**cfg.to_dict(), "train": {**cfg.to_dict()["train"], "epochs": int(epochs)}})
    t = cfg.train
    out = Path(out)
    torch.manual_seed(t.seed)
    model = UNetFusion(cfg).to(dev)
    opt = torch.optim.Adam(model.parameters(), lr=t.lr, weight_decay=t.weight_decay)
    history = {"epoch_loss": [], "epoch_seconds": [], "steps": 0, "terms": []}
    start = 0
    if resume and out.exists():
        ck = read_checkpoint(out, map_location=dev)
        same = {k: v for k, v in (ck.get("config") or {}).get("train", {}).items() if k not in ("epochs", "workers")}
        want = {k: v for k, v in cfg.to_dict()["train"].items() if k not in ("epochs", "workers")}
        if ck.get("model_config") != cfg.to_dict()["model"] or (ck.get("config") or {}).get("loss") != \
                cfg.to_dict()["loss"] or same != want:
            raise ValueError(f"checkpoint {out} was trained with another config; pass --no-resume to start again "
                             "(it is overwritten) or choose another --out")
        model.load_state_dict(ck["state_dict"])
        opt.load_state_dict(ck["optimizer"])
        history = ck["history"]
        start = int(ck["epochs_done"])
        if log:
            log(f"resuming {out} after epoch {start}/{t.epochs}")
    loader, sampler = make_loader(corpus, cfg, workers, dev)
    total_steps = t.epochs * len(loader)
    scale = cfg.model.feature_scale_e
    steps_this_call = 0
    for ep in range(start, t.epochs):
        model.train()
        sampler.set_epoch(ep)
        t0 = time.perf_counter()
        it = loader
        if progress:
            from tqdm import tqdm

            it = tqdm(loader, desc=f"train epoch {ep + 1}/{t.epochs}", unit="batch", leave=False)
        sums: dict[str, float] = {}
        lr = cosine_lr(history["steps"], total_steps, t.lr, t.lr_min)
        n = 0
        for batch in it:
            batch = _to(batch, dev)
            loss, terms = led_weighted_loss(model(batch), batch["gt"], batch.get("light_index"), cfg.loss, scale)
            lr = cosine_lr(history["steps"], total_steps, t.lr, t.lr_min)
            for g in opt.param_groups:
                g["lr"] = lr
            opt.zero_grad(set_to_none=True)
            loss.backward()
            if t.grad_clip > 0:
                torch.nn.utils.clip_grad_norm_(model.parameters(), t.grad_clip)
            opt.step()
            history["steps"] += 1
            steps_this_call += 1
            n += 1
            for k, v in {"loss": float(loss.detach()), **terms}.items():
                sums[k] = sums.get(k, 0.0) + v
            if progress:
                it.set_postfix(loss=f"{sums['loss'] / n:.4f}")
            if max_steps is not None and steps_this_call >= max_steps:
                break
        secs = time.perf_counter() - t0
        means = {k: v / max(n, 1) for k, v in sums.items()}
        history["epoch_loss"].append(means.get("loss", float("nan")))
        history["terms"].append(means)
        history["epoch_seconds"].append(secs)
        save_checkpoint(model, out, cfg, {"optimizer": opt.state_dict(), "epochs_done": ep + 1,
                                          "history": history, "parameters": count_parameters(model),
                                          "corpus": str(corpus)})
        if log:
            log(f"epoch {ep + 1}/{t.epochs}: loss {means.get('loss', float('nan')):.4f} "
                f"(mu-L1 {means.get('mu_l1', float('nan')):.4f}, LED {means.get('led_l1', float('nan')):.4f}, "
                f"region {means.get('region_log', float('nan')):.4f}), {n} steps, {secs:.1f} s, "
                f"lr {lr:.2e} -> {out}")
        if max_steps is not None and steps_this_call >= max_steps:
            break
    return model.eval(), history

