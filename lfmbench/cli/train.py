"""The ``lfmbench train --method NAME`` command: any learned baseline of :data:`lfmbench.baselines.LEARNED`
through the one loop of :mod:`lfmbench.train`. The help and the choices read the registries and definitions that
own the names: the learned baselines, the shipped presets, :data:`lfmbench.train.DATA_SOURCES`,
:data:`~lfmbench.train.RESIDENT_DTYPES` and :data:`lfmbench.train_step.CUDA_GRAPH_MODES` (those three and the
baselines import torch: read when the help is shown or the option checked, :func:`lfmbench.cli._common.lazy`)."""
from __future__ import annotations

import statistics
from pathlib import Path

import typer

from lfmbench.cli._common import check_local_paths, check_minima, choice, fail, lazy, torch_setup
from lfmbench.resources import installed

__all__ = ["register", "train_cmd"]


def _learned() -> list[str]:
    from lfmbench.baselines import LEARNED  # noqa: PLC0415 - imports torch: when the command runs or shows help

    return list(LEARNED)


def _data_sources() -> tuple[str, ...]:
    from lfmbench.train import DATA_SOURCES  # noqa: PLC0415

    return DATA_SOURCES


def _resident_dtypes() -> tuple[str, ...]:
    from lfmbench.train import RESIDENT_DTYPES  # noqa: PLC0415

    return tuple(RESIDENT_DTYPES)


def _cuda_graph_modes() -> tuple[str, ...]:
    from lfmbench.train_step import CUDA_GRAPH_MODES  # noqa: PLC0415

    return CUDA_GRAPH_MODES


def train_cmd(
    corpus: Path = typer.Option(..., "--corpus", help="corpus root directory (its train split is used)"),
    method: str = typer.Option("unet", "--method", "-m", help=f"learned baseline: {lazy(lambda: ', '.join(_learned()))}"),
    config: str = typer.Option(None, "--config", help="the method's config: a YAML path or a shipped name "
                                                      "(`lfmbench configs`; default <method>, unet_tiny: the "
                                                      "demo's U-Net)"),
    out: Path = typer.Option(None, "--out", "-o", help="checkpoint path (default runs/<method>_fusion.pt)"),
    device: str = typer.Option("cpu", help="torch device: cpu, cuda, cuda:0 ..."),
    epochs: int = typer.Option(None, help="total epochs (overrides train.epochs of the config)"),
    workers: int = typer.Option(None, help="DataLoader workers (overrides train.workers)"),
    crop: int = typer.Option(None, help="square training crop in px, even (overrides train.crop)"),
    batch_size: int = typer.Option(None, "--batch-size", help="batch size (overrides train.batch_size)"),
    sensor: str = typer.Option(None, "--sensor",
                               help=f"sensor preset ({', '.join(installed('sensors'))}) or a preset YAML "
                                    "to train for (overrides train.sensor); the U-Net takes any capture plan, "
                                    "the checkpoint records the sensor and serves only it"),
    threads: int = typer.Option(None, help="torch CPU threads (default: torch's choice)"),
    resume: bool = typer.Option(True, help="continue from --out when it holds a checkpoint of this config"),
    data: str = typer.Option("auto", **choice(_data_sources),
                             help="where batches come from: loader (DataLoader workers on the CPU), "
                                  "device (the corpus resident on --device, batches simulated there), "
                                  "auto (device on CUDA for a split-pixel sensor, else loader)"),
    resident_dtype: str = typer.Option("float32", **choice(_resident_dtypes),
                                       help="device path: storage of the resident layers (float16: half the "
                                            "memory, 2^-11 relative error)"),
    chunk_scenes: int = typer.Option(None, help="device path: stream the split this many scenes at a time (a split "
                                                "that does not fit the device)"),
    cuda_graph: str = typer.Option("auto", "--cuda-graph", **choice(_cuda_graph_modes),
                                   help="auto: replay the training step as a CUDA graph on a CUDA device; off: "
                                        "never"),
) -> None:
    """Train a learned fusion baseline; checkpoint written atomically after every epoch (resumable).

    Evaluate it with LFMBENCH_<METHOD>_CHECKPOINT=OUT lfmbench evaluate --method <method> --corpus DIR (with the
    same --sensor it was trained for). Several processes or GPUs: torchrun --nproc_per_node N -m lfmbench.cli
    train ... (data-parallel, one model; --batch-size is the global batch; docs/guide/distributed.md).
    """
    from lfmbench.baselines.trainable import ConfigError, count_parameters  # noqa: PLC0415
    from lfmbench.datasets.loading import EmptyDataError  # noqa: PLC0415
    from lfmbench.train import load_config, train, trainable  # noqa: PLC0415

    check_local_paths((("--corpus", corpus), ("--out", out), ("--config", config)))
    if method not in _learned():
        fail(f"--method {method!r} is not a trainable baseline; trainable: {', '.join(_learned())}")
    check_minima((("--epochs", epochs, 1), ("--workers", workers, 0), ("--crop", crop, 8),
                  ("--batch-size", batch_size, 1), ("--chunk-scenes", chunk_scenes, 1)))
    torch_setup(device, threads)
    try:
        cfg = load_config(method, config)
        from lfmbench.baselines.checkpoint import check_model_size  # noqa: PLC0415

        spec = trainable(method)  # the network a config asks for is counted before anything is allocated
        check_model_size(lambda: spec.build_model(cfg), str(config or spec.default_config))
    except ValueError as exc:  # ConfigError, CheckpointError (above the limit model_parameters)
        fail(str(exc))
    out = out if out is not None else trainable(method).default_checkpoint
    if out.is_dir():
        fail(f"--out {out} is a directory; give a file path such as {out / f'{method}_fusion.pt'}")
    from lfmbench.fileio import OutputLock, OutputLockedError, writable_error  # noqa: PLC0415

    why = writable_error(out)  # before any training: the writer's own rule (a symlink is written through)
    if why is not None:
        fail(f"--out {out}: cannot write the checkpoint there ({why})")
    import contextlib  # noqa: PLC0415
    import os  # noqa: PLC0415

    # a torchrun launch (lfmbench.distributed): rank 0 holds the --out lock, writes and reports; the other ranks
    # train beside it and say nothing
    rank = int(os.environ.get("RANK", "0")) if int(os.environ.get("WORLD_SIZE", "1") or 1) > 1 else 0
    try:  # one training per --out: a second one is refused before any work (it said "saved" for the other's file)
        lock = OutputLock(out, "--out") if rank == 0 else contextlib.nullcontext()
    except OutputLockedError as exc:
        fail(str(exc))
    with lock:
        done = _train_locked(train, method, corpus, out, cfg, device, epochs, workers, resume, crop,
                             batch_size, sensor, data, resident_dtype, chunk_scenes, cuda_graph)
    if done is None:
        return
    model, hist, sha = done
    secs = hist["epoch_seconds"]
    typer.echo(f"saved {out}: {count_parameters(model):,} parameters, {len(secs)} epochs, "
               f"final loss {hist['epoch_loss'][-1] if hist['epoch_loss'] else float('nan'):.4f}"
               + (f", median {statistics.median(secs):.1f} s/epoch" if secs else "") + f", weights sha256 {sha[:12]}")


def _train_locked(train, method, corpus, out, cfg, device, epochs, workers, resume, crop, batch_size, sensor, data,
                  resident_dtype, chunk_scenes, cuda_graph):
    """``train(...)`` under the --out lock, then the checkpoint read back: what is reported is what the file holds
    (its weights equal the trained model's, its content hash checked); returns (model, history, content hash), or
    None on a torchrun rank other than 0 (rank 0 wrote and reports)."""
    import torch  # noqa: PLC0415

    from lfmbench.baselines.checkpoint import CheckpointError  # noqa: PLC0415
    from lfmbench.datasets.loading import EmptyDataError  # noqa: PLC0415
    from lfmbench.train import trainable  # noqa: PLC0415

    try:
        model, hist = train(method, corpus, out, cfg, device=device, epochs=epochs, workers=workers, resume=resume,
                            crop=crop, batch_size=batch_size, sensor=sensor, data=data, resident_dtype=resident_dtype,
                            chunk_scenes=chunk_scenes, cuda_graph=cuda_graph)
    except (FileNotFoundError, EmptyDataError, ValueError) as exc:
        fail(str(exc))
    except OSError as exc:  # the checkpoint could not be written (disk full, ...): the message names the file
        fail(exc.strerror or str(exc))
    import torch.distributed as dist  # noqa: PLC0415

    if dist.is_available() and dist.is_initialized():  # a torchrun rank (lfmbench.distributed): rank 0 reports
        main = dist.get_rank() == 0
        dist.destroy_process_group()
        if not main:
            return None
    try:
        ck = trainable(method).read_checkpoint(out, map_location="cpu")
    except (CheckpointError, OSError) as exc:
        fail(f"--out {out}: the checkpoint written cannot be read back ({exc})")
    mine = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    saved = ck.get("state_dict") or {}
    if set(saved) != set(mine) or any(not torch.equal(saved[k], mine[k]) for k in mine):
        fail(f"--out {out}: the file no longer holds the weights this run trained (another process wrote it); "
             "nothing of this run is there")
    return model, hist, ck["content_sha256"]


def register(app: typer.Typer) -> None:
    """Add the ``train`` command to the ``lfmbench`` app."""
    app.command("train")(train_cmd)
