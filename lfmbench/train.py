"""The one training loop of every trainable baseline: ``lfmbench train --method NAME`` (a registered learned
baseline, :data:`lfmbench.baselines.LEARNED`; settings: its YAML config, e.g. ``lfmbench/configs/unet.yaml``).

Data flow: :class:`~lfmbench.datasets.LFMCaptureDataset` (random crops, PWM draws and noise per sample) ->
``torch.utils.data.DataLoader`` (``workers`` processes) -> the baseline's network -> its loss
(:class:`lfmbench.baselines.trainable.Trainable`) -> Adam with a cosine learning-rate schedule (constant when
``lr_min = lr``) after an optional linear warm-up (``train.warmup_steps``) and optional gradient clipping.

Deterministic given the seed: a sample depends only on ``(seed, epoch, index)`` (docs/guide/datasets.md), the weights are
initialised after ``torch.manual_seed(seed)``, and the order of an epoch's samples is either a permutation that
depends only on ``(seed, epoch)`` (:class:`EpochSampler`; the sampler hands ``(epoch, index)`` pairs to the
workers, so persistent workers still draw the right epoch) or a DataLoader shuffled by one generator seeded once
whose state is kept in the checkpoint. The checkpoint is written atomically after every epoch with the optimiser
state; running the same command again resumes after the last finished epoch (and does nothing when all epochs
are done), so a resumed run ends with the same weights as an uninterrupted one. The optimiser step itself (Adam,
the schedule, the CUDA-graph replay) is :mod:`lfmbench.train_step`.
"""
from __future__ import annotations

import importlib
import os
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import torch
from torch.utils.data import DataLoader, Dataset, Sampler

from lfmbench.baselines import LEARNED
from lfmbench.datasets.device import epoch_order
from lfmbench.baselines.trainable import Trainable, count_parameters
from lfmbench.train_step import (CUDA_GRAPH_MODES, GraphedStep, _eager_step, _set_lr, _stash, _unstash,
                                 clip_gradients, collapse_warning, cosine_lr, make_optimizer)

__all__ = ["trainable", "load_config", "make_loader", "make_device_batches", "fit", "train", "train_batches",
           "EpochSampler", "EpochIndexed", "DATA_SOURCES", "RESIDENT_DTYPES"]


def trainable(method: str | Trainable) -> Trainable:
    """The :class:`Trainable` of a registered learned baseline (``TRAINING`` of its module).

    Raises:
        ValueError: ``method`` is not one of :data:`lfmbench.baselines.LEARNED` (the message lists them).
    """
    if isinstance(method, Trainable):
        return method
    if method not in LEARNED:
        raise ValueError(f"--method {method!r} is not a trainable baseline; trainable: {', '.join(LEARNED)}")
    return importlib.import_module(LEARNED[method]).TRAINING


def load_config(method: str | Trainable, path: str | os.PathLike | None = None) -> Any:
    """The training configuration of ``method`` from ``path``: a YAML file, or the name of a shipped training config
    (``"unet_tiny"``, :func:`lfmbench.resources.find_config`); default: the method's own config file.

    Raises:
        ConfigError: unreadable or invalid file; an unknown name (the message lists the installed configs).
    """
    from lfmbench.baselines.trainable import ConfigError
    from lfmbench.resources import ConfigNotFoundError, find_config

    if path is not None:
        try:
            path = find_config(path, "training")
        except ConfigNotFoundError as exc:
            raise ConfigError(str(exc)) from None
    return trainable(method).load_config(path)


class EpochSampler(Sampler):
    """Yields ``(epoch, index)`` for a permutation of ``range(n)`` that depends only on ``(seed, epoch)``."""

    def __init__(self, n: int, seed: int = 0):
        self.n, self.seed, self.epoch = int(n), int(seed), 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return self.n

    def __iter__(self) -> Iterator[tuple[int, int]]:
        return iter([(self.epoch, int(i)) for i in epoch_order(self.n, self.seed, self.epoch)])


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


def start_line(batches: Any, corpus: str | os.PathLike, t: Any, start: int) -> str:
    """The first line of a training's log, before its first batch: what it trains on (scenes, steps per epoch,
    epochs) and, on the loader path, where the first pass over each scene caches that scene's radiance projected
    for the sensor (built once per scene and sensor; on a CPU at 640x360 it is most of the first epoch, which
    otherwise runs silent until its end-of-epoch line). ``t``: the config's ``train`` section."""
    ds = getattr(batches, "dataset", None)
    ds = getattr(ds, "dataset", ds)         # EpochIndexed / RankIndexed hold the dataset
    n = len(getattr(ds, "scene_ids", None) or getattr(batches, "scene_ids", None) or ())
    steps = f"{len(batches)} steps of batch {t.batch_size}" if hasattr(batches, "__len__") else f"batch {t.batch_size}"
    line = (f"training on {n} scenes of {corpus} (split {t.split}, sensor {t.sensor}): {steps} per epoch, "
            f"epochs {start + 1}-{t.epochs}")
    cache = getattr(ds, "cache_dir", None)
    if cache:
        line += f"; a scene's first pass also projects its radiance for the sensor into {cache} (once)"
    return line


def _check_batch_memory(ds, t: Any, cfg: Any) -> None:
    """:func:`lfmbench.limits.check_batch_bytes` of the config's batch: one sample's bytes from the dataset's sample
    0 (bounded by one scene's files), times ``train.batch_size`` (or the dataset's length, when it holds fewer
    samples: no batch is larger)."""
    from lfmbench.limits import check_batch_bytes
    from lfmbench.datasets.device import DeviceBatches

    if len(ds):
        check_batch_bytes(min(t.batch_size, len(ds)), DeviceBatches.batch_bytes(ds, 1), "train config (--config, --batch-size)",
                          f"crop {t.crop}, frames {t.frames}")


def make_loader(corpus: str | os.PathLike, spec: Trainable, cfg: Any, workers: int | None = None,
                device: torch.device | str = "cpu", group=None, preset: Any = None
                ) -> tuple[DataLoader, Callable[[int], None]]:
    """DataLoader of training batches over :class:`~lfmbench.datasets.LFMCaptureDataset` and the function that
    selects an epoch's draws and order (``set_epoch(epoch)``), for ``spec.data_order``; with ``group`` (a
    :class:`lfmbench.distributed.Group`) the rank's part of every batch of the epoch order, whatever
    ``spec.data_order`` (:class:`lfmbench.distributed.RankBatchSampler`). ``preset``: the
    :class:`lfmbench.sensor.SensorPreset` of ``cfg.train.sensor`` already resolved (None: the dataset resolves
    the name)."""
    from lfmbench.datasets.loading import collate_samples, make_dataset

    t = cfg.train
    extra = {} if spec.outputs is None else {"outputs": spec.outputs}
    ds = make_dataset(corpus, t.split, seed=t.seed, crop=t.crop, samples_per_scene=t.samples_per_scene,
                      frames=t.frames, sensor=t.sensor if preset is None else preset, cache_scenes=t.cache_scenes,
                      **extra)
    _check_batch_memory(ds, t, cfg)
    nw = t.workers if workers is None else int(workers)
    if group is not None:
        from lfmbench import distributed as D

        bs = D.RankBatchSampler(len(ds), t.batch_size, t.seed, group.rank, group.world)
        loader = DataLoader(D.RankIndexed(ds), batch_sampler=bs, num_workers=nw,
                            collate_fn=D.RankCollate(collate_samples), persistent_workers=nw > 0,
                            pin_memory=torch.device(device).type == "cuda")
        return loader, bs.set_epoch
    if spec.data_order == "shuffle":
        loader = DataLoader(ds, batch_size=t.batch_size, shuffle=True, num_workers=nw, collate_fn=collate_samples,
                            generator=torch.Generator().manual_seed(t.seed))
        return loader, ds.set_epoch
    sampler = EpochSampler(len(ds), t.seed)
    loader = DataLoader(EpochIndexed(ds), batch_size=t.batch_size, sampler=sampler, num_workers=nw,
                        collate_fn=collate_samples, persistent_workers=nw > 0,
                        pin_memory=torch.device(device).type == "cuda")
    return loader, sampler.set_epoch


#: Where training batches come from (``train(data=...)``): ``"loader"``, the per-sample dataset in a DataLoader
#: (CPU workers; generator noise); ``"device"``, :class:`lfmbench.datasets.device.DeviceBatches` (the corpus
#: resident on the training device, batches cut and simulated there; counter noise); ``"auto"``: ``"device"`` on
#: CUDA for a split-pixel sensor (the only plan that path serves), else ``"loader"``.
DATA_SOURCES = ("auto", "loader", "device")


#: Storage of the resident rates on the device path (``train(resident_dtype=...)``).
RESIDENT_DTYPES = {"float32": torch.float32, "float16": torch.float16}


def make_device_batches(corpus: str | os.PathLike, spec: Trainable, cfg: Any, device: torch.device | str,
                        resident_dtype: str = "float32",
                        chunk_scenes: int | None = None, prefetch: bool = True,
                        group=None, preset: Any = None) -> tuple[Any, Callable[[int], None]]:
    """:class:`~lfmbench.datasets.device.DeviceBatches` of the training split on ``device`` (epoch order
    :func:`~lfmbench.datasets.device.epoch_order` of ``(seed, epoch)``; ``resident_dtype`` a key of
    :data:`RESIDENT_DTYPES`; ``chunk_scenes``: stream the split that many scenes at a time; ``prefetch``: on CUDA
    each batch is made on a side stream while the previous step runs) and its ``set_epoch``. ``preset``: as in
    :func:`make_loader`."""
    from lfmbench.datasets.device import DeviceBatches
    from lfmbench.datasets.loading import make_dataset

    t = cfg.train
    extra = {} if spec.outputs is None else {"outputs": spec.outputs}
    ds = make_dataset(corpus, t.split, seed=t.seed, crop=t.crop, samples_per_scene=t.samples_per_scene,
                      frames=t.frames, sensor=t.sensor if preset is None else preset, noise_streams="counter",
                      cache_scenes=t.cache_scenes, **extra)
    if resident_dtype not in RESIDENT_DTYPES:
        raise ValueError(f"resident_dtype must be one of {tuple(RESIDENT_DTYPES)}, got {resident_dtype!r:.40}")
    if group is not None:  # the rank's part of every batch (lfmbench.distributed)
        from lfmbench.distributed import RankDeviceBatches

        batches = RankDeviceBatches(ds, t.batch_size, device, rank=group.rank, world=group.world, seed=t.seed,
                                    dtype=RESIDENT_DTYPES[resident_dtype], chunk_scenes=chunk_scenes,
                                    prefetch=prefetch)
        return batches, batches.set_epoch
    batches = DeviceBatches(ds, t.batch_size, device, seed=t.seed, dtype=RESIDENT_DTYPES[resident_dtype],
                            chunk_scenes=chunk_scenes, prefetch=prefetch)
    return batches, batches.set_epoch


def _to(batch: dict, device: torch.device) -> dict:
    return {k: (v.to(device, non_blocking=True) if isinstance(v, torch.Tensor) else v) for k, v in batch.items()}


def fit(model: torch.nn.Module, opt: torch.optim.Optimizer, spec: Trainable, cfg: Any, batches: Iterable[dict], *,
        device: str | torch.device = "cpu", out: str | os.PathLike | None = None, start: int = 0,
        history: dict | None = None, set_epoch: Callable[[int], None] | None = None,
        checkpoint_extra: Callable[[], dict] | None = None, max_steps: int | None = None, progress: bool = True,
        log: Callable[[str], None] | None = print, corpus: str | os.PathLike | None = None,
        step: Callable[[dict, float], tuple] | None = None,
        after_epoch: Callable[[int], None] | None = None) -> dict:
    """The training loop: epochs ``start .. cfg.train.epochs - 1`` over ``batches``, the checkpoint ``out`` written
    (atomically, by ``spec.save_checkpoint``) after every epoch with the optimiser state and the history.

    Args:
        model, opt: the network (on ``device``) and its optimiser.
        spec: the baseline's :class:`Trainable` (its loss and checkpoint format). cfg: its configuration.
        batches: iterable of batch dicts, re-iterated once per epoch.
        out: checkpoint path, or None (nothing written).
        start, history: the epochs already done and their history (a resume).
        set_epoch: called with the epoch before it starts (fresh draws, crops, noise and order per epoch).
        checkpoint_extra: more fields for every checkpoint (e.g. the data order's generator state).
        max_steps: stop after this many optimiser steps in this call; the checkpoint is still written.
        progress: show a progress bar per epoch on a terminal (:mod:`lfmbench.progress`). log: one line per epoch (None: silent).
        step: ``step(batch, lr) -> (loss, terms)`` instead of the eager step (e.g. a :class:`GraphedStep`).
        after_epoch: called with the epoch after its checkpoint is written (the ranks' barrier of a DDP run).

    Returns:
        the history: ``epoch_loss`` and ``epoch_seconds`` per epoch, ``terms`` (mean loss terms per epoch),
        ``step_loss`` per optimiser step, ``steps`` in all.
    """
    dev = torch.device(device)
    t = cfg.train
    history = history or {"epoch_loss": [], "epoch_seconds": [], "steps": 0, "terms": [], "step_loss": []}
    history.setdefault("step_loss", [])
    total_steps = t.epochs * len(batches) if hasattr(batches, "__len__") else 0
    steps_this_call = 0
    for ep in range(start, t.epochs):
        model.train()
        if set_epoch is not None:
            set_epoch(ep)
        t0 = time.perf_counter()
        it = batches
        if progress:  # a live bar on a terminal; off one, ``log``'s line per epoch says it all
            from lfmbench.progress import track

            it = track(batches, total=len(batches) if hasattr(batches, "__len__") else None,
                       description=f"train epoch {ep + 1}/{t.epochs}", unit="batch", log=False)
        sums: dict[str, float] = {}
        lr = cosine_lr(history["steps"], total_steps, t.lr, t.lr_min, t.warmup_steps)
        n = 0
        pending: list = []      # losses of steps not read yet: read one step late, each from its own copy and
        #                         event (_stash), so that reading never waits for the step just queued on a GPU
        #                         (the host goes on to make the next batch)

        done = [0]
        zero = [0]              # steps whose gradient was exactly 0 (collapse_warning)

        def read(loss_t, terms) -> None:
            value, terms = _unstash(loss_t, terms)
            history["step_loss"].append(value)
            for k, v in {"loss": value, **terms}.items():
                sums[k] = sums.get(k, 0.0) + float(v)
            done[0] += 1
            zero[0] += terms.get("grad_norm", 1.0) == 0.0
            if progress:
                it.set_postfix(loss=f"{sums['loss'] / done[0]:.4f}")

        for batch in it:
            batch = _to(batch, dev)
            lr = cosine_lr(history["steps"], total_steps, t.lr, t.lr_min, t.warmup_steps)
            loss, terms = (step(batch, lr) if step is not None
                           else _eager_step(model, opt, spec, cfg, batch, lr))
            history["steps"] += 1
            steps_this_call += 1
            n += 1
            pending.append(_stash(loss, terms))
            if len(pending) > 1:
                read(*pending.pop(0))
            if max_steps is not None and steps_this_call >= max_steps:
                break
        for p in pending:
            read(*p)
        secs = time.perf_counter() - t0
        means = {k: v / max(n, 1) for k, v in sums.items()}
        history["epoch_loss"].append(means.get("loss", float("nan")))
        history["terms"].append(means)
        history["epoch_seconds"].append(secs)
        if out is not None:
            spec.save_checkpoint(model, out, cfg, {"optimizer": opt.state_dict(), "epochs_done": ep + 1,
                                                   "history": history, "parameters": count_parameters(model),
                                                   "corpus": None if corpus is None else str(corpus),
                                                   **(checkpoint_extra() if checkpoint_extra else {})})
        if after_epoch is not None:
            after_epoch(ep)
        if log:
            extra = ", ".join(f"{k} {v:.4f}" for k, v in means.items() if k != "loss")
            log(f"epoch {ep + 1}/{t.epochs}: loss {means.get('loss', float('nan')):.4f}"
                + (f" ({extra})" if extra else "") + f", {n} steps, {secs:.1f} s, lr {lr:.2e}"
                + (f" -> {out}" if out is not None else ""))
        warn = collapse_warning(zero[0], done[0], ep + 1)
        if warn and log:
            log(warn)
        if max_steps is not None and steps_this_call >= max_steps:
            break
    return history


def train(method: str | Trainable, corpus: str | os.PathLike, out: str | os.PathLike, cfg: Any = None, *,
          device: str = "cpu", epochs: int | None = None, workers: int | None = None, resume: bool = True,
          max_steps: int | None = None, progress: bool = True,
          log: Callable[[str], None] | None = print, data: str = "auto", resident_dtype: str = "float32",
          chunk_scenes: int | None = None, cuda_graph: str = "auto",
          **train_overrides: Any) -> tuple[torch.nn.Module, dict]:
    """Train the baseline ``method`` on ``corpus`` and write the checkpoint ``out`` after every epoch (atomically).

    Args:
        method: a name of :data:`lfmbench.baselines.LEARNED` (or its :class:`Trainable`).
        corpus: corpus directory.
        out: checkpoint path (resumed from when it exists and ``resume``).
        cfg: configuration (default: the method's config file, :func:`load_config`).
        device: torch device of the network.
        epochs: overrides ``cfg.train.epochs`` (the total, counting epochs done before a resume).
        workers: overrides ``cfg.train.workers``.
        resume: continue from ``out`` when it holds a checkpoint of the same model and training config.
        max_steps: stop after this many optimiser steps in this call (tests); the checkpoint is still written.
        progress: show a progress bar per epoch on a terminal.
        log: callback for one line per epoch (None: silent).
        data: where the batches come from, one of :data:`DATA_SOURCES` (``"device"``: the corpus resident on
            ``device``, sample order :func:`~lfmbench.datasets.device.epoch_order`, counter-based noise; a split
            that does not fit raises :class:`~lfmbench.datasets.device.ResidentMemoryError`).
        resident_dtype, chunk_scenes: the device path's storage (``"float32"`` or ``"float16"``, docs/guide/datasets.md)
            and streaming (that many scenes resident at a time; None: the whole split).
        cuda_graph: one of :data:`CUDA_GRAPH_MODES`: ``"auto"`` replays the training step as a CUDA graph on a
            CUDA device (:class:`GraphedStep`; the same training, less host time per step), ``"off"`` never.
            Not under torchrun.

    Under torchrun (``WORLD_SIZE`` > 1 in the environment) this process is one rank of a data-parallel training
    (:mod:`lfmbench.distributed`): its part of every batch, gradients averaged by DDP, rank 0 writing ``out``,
    ``device`` ``cuda`` meaning ``cuda:LOCAL_RANK``.
        train_overrides: other keys of the ``train`` section (``crop``, ``batch_size``, ``seed``, ...).

    Returns:
        (model in eval mode, the checkpoint's ``history`` dict: per-epoch mean losses and seconds, steps).
    """
    spec = trainable(method)
    if data not in DATA_SOURCES:
        raise ValueError(f"data must be one of {DATA_SOURCES}, got {data!r:.40}")
    cfg = spec.load_config(None) if cfg is None else cfg
    over = {k: v for k, v in {"epochs": epochs, **train_overrides}.items() if v is not None}
    if "epochs" in over and over["epochs"] < 1:
        raise ValueError(f"epochs must be >= 1, got {over['epochs']}")
    if over:
        d = cfg.to_dict()
        cfg = spec.config_from_dict({**d, "train": {**d["train"], **over}}, "the command-line options")
    t = cfg.train
    from lfmbench.baselines import methods_for  # noqa: PLC0415
    from lfmbench.sensor import resolve  # noqa: PLC0415

    preset = resolve(t.sensor)  # once: the object goes to the network and the dataset (the config keeps the name)
    arch = preset.architecture
    if spec.name not in methods_for(arch):
        fits = [m for m in methods_for(arch) if m in LEARNED]
        raise ValueError(f"train.sensor: {spec.name} reads split-pixel captures, and sensor {t.sensor!r} is a "
                         f"{arch} sensor; its baselines are {methods_for(arch)} (trainable: {', '.join(fits)})")
    if cuda_graph not in CUDA_GRAPH_MODES:
        raise ValueError(f"cuda_graph must be one of {CUDA_GRAPH_MODES}, got {cuda_graph!r:.40}")
    from lfmbench import distributed as D  # noqa: PLC0415

    group = D.from_env(device)  # a torchrun launch: one rank of a DDP training (lfmbench.distributed)
    dev = torch.device(device) if group is None else group.device
    graph = cuda_graph == "auto" and dev.type == "cuda" and group is None
    if group is not None and not group.main:
        log, progress = None, False
    out = Path(out)
    torch.manual_seed(t.seed)
    from lfmbench.baselines.checkpoint import check_model_size  # noqa: PLC0415

    check_model_size(lambda: spec.build_model(cfg, preset), f"the {spec.name} training config")  # before allocating
    model = spec.build_model(cfg, preset).to(dev)
    opt = make_optimizer(model, cfg, dev, graph)
    history, start, data_rng = None, 0, None
    if resume and out.exists():
        ck = spec.read_checkpoint(out, map_location=dev)
        mine = {k: v for k, v in cfg.to_dict().items() if k != "train"}
        theirs = {k: v for k, v in (ck.get("config") or {}).items() if k != "train"}
        free = ("epochs", "workers", "cache_scenes")     # change how long or how fast, not what is trained
        same = {k: v for k, v in (ck.get("config") or {}).get("train", {}).items() if k not in free}
        want = {k: v for k, v in cfg.to_dict()["train"].items() if k not in free}
        if mine != theirs or same != want or "optimizer" not in ck:
            raise ValueError(f"checkpoint {out} was trained with another config; pass --no-resume to start again "
                             "(it is overwritten) or choose another --out")
        model.load_state_dict(ck["state_dict"])
        opt.load_state_dict(ck["optimizer"])
        if graph:       # a checkpoint of an uncaptured run holds the rate as a number: the graph reads a tensor
            for g in opt.param_groups:
                g["lr"] = torch.as_tensor(g["lr"], dtype=torch.float32).to(dev)
        history = ck["history"]
        start = int(ck["epochs_done"])
        data_rng = ck.get("data_rng")
        if log:
            log(f"resuming {out} after epoch {start}/{t.epochs}")
            before = int(((ck.get("config") or {}).get("train") or {}).get("epochs", t.epochs))
            if before != t.epochs and t.lr_min != t.lr:
                # the cosine schedule spans the total epochs: a new total reshapes the rest of it
                log(f"note: {out} was trained for a total of {before} epochs, now {t.epochs}: the cosine learning "
                    f"rate is recomputed over {t.epochs} epochs from here, so the weights can differ from an "
                    "uninterrupted run of either length")
    # auto: the device path on CUDA for the split pixel (the other plans run on the per-sample path only)
    on_device = data == "device" or (data == "auto" and dev.type == "cuda" and arch == "split_pixel")
    if on_device:
        loader, set_epoch = make_device_batches(corpus, spec, cfg, dev, resident_dtype, chunk_scenes, group=group,
                                                preset=preset)
    else:
        loader, set_epoch = make_loader(corpus, spec, cfg, workers, dev, group=group, preset=preset)
    if log and start < t.epochs:
        log(start_line(loader, corpus, t, start))
    gen = loader.generator if spec.data_order == "shuffle" and not on_device and group is None else None
    if gen is not None and data_rng is not None:
        gen.set_state(data_rng)
    step = GraphedStep(model, opt, spec, cfg) if graph else None
    if group is not None:
        from torch.nn.parallel import DistributedDataParallel  # noqa: PLC0415

        ddp = DistributedDataParallel(model, device_ids=[dev.index] if dev.type == "cuda" else None)
        step = D.ddp_step(ddp, opt, spec, cfg, group, _set_lr, clip_gradients)
    history = fit(model, opt, spec, cfg, loader, device=dev, out=out if group is None or group.main else None,
                  start=start, history=history, set_epoch=set_epoch,
                  checkpoint_extra=(lambda: {"data_rng": gen.get_state()}) if gen else None,
                  max_steps=max_steps, progress=progress, log=log, corpus=corpus, step=step,
                  after_epoch=(lambda ep: group.barrier()) if group is not None else None)
    return model.eval(), history


def train_batches(method: str | Trainable, batches: Iterable[dict], cfg: Any = None, *,
                  out: str | os.PathLike | None = None, device: str | torch.device = "cpu",
                  max_steps: int | None = None, progress: bool = False,
                  log: Callable[[str], None] | None = None) -> tuple[torch.nn.Module, dict]:
    """Train a fresh ``method`` network on any iterable of batch dicts (re-iterated once per epoch;
    ``batches.dataset.set_epoch`` is called when it exists), by :func:`fit`; no resume.

    Returns:
        (model in eval mode, history: ``step_loss`` per optimiser step, ``epoch_loss`` per epoch, ...).
    """
    spec = trainable(method)
    cfg = spec.load_config(None) if cfg is None else cfg
    torch.manual_seed(cfg.train.seed)
    model = spec.build_model(cfg).to(device)
    opt = make_optimizer(model, cfg, torch.device(device))
    dataset = getattr(batches, "dataset", None)
    history = fit(model, opt, spec, cfg, batches, device=device, out=out,
                  set_epoch=getattr(dataset, "set_epoch", None), max_steps=max_steps, progress=progress, log=log)
    return model.eval(), history
