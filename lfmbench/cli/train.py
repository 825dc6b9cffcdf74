"""The ``lfmbench train --method NAME`` command: any learned baseline of :data:`lfmbench.vocabulary.LEARNED_BASELINES`
through the one loop of :mod:`lfmbench.train` (torch is imported only when it runs, so registering it keeps
``lfmbench --help`` and ``lfmbench render`` fast)."""
from __future__ import annotations

import statistics
from pathlib import Path

import typer

from lfmbench.cli._common import check_local_paths, check_minima, fail, torch_setup
from lfmbench.vocabulary import LEARNED_BASELINES as LEARNED

__all__ = ["register", "train_cmd"]


def train_cmd(
    corpus: Path = typer.Option(..., "--corpus", help="corpus root directory (its train split is used)"),
    method: str = typer.Option("unet", "--method", "-m", help=f"learned baseline: {', '.join(LEARNED)}"),
    config: Path = typer.Option(None, "--config", help="the method's YAML config (default lfmbench/configs/"
                                                       "<method>.yaml; unet_tiny.yaml: the demo's U-Net)"),
    out: Path = typer.Option(None, "--out", "-o", help="checkpoint path (default runs/<method>_fusion.pt)"),
    device: str = typer.Option("cpu", help="torch device: cpu, cuda, cuda:0 ..."),
    epochs: int = typer.Option(None, help="total epochs (overrides train.epochs of the config)"),
    workers: int = typer.Option(None, help="DataLoader workers (overrides train.workers)"),
    crop: int = typer.Option(None, help="square training crop in px, even (overrides train.crop)"),
    batch_size: int = typer.Option(None, "--batch-size", help="batch size (overrides train.batch_size)"),
    sensor: str = typer.Option(None, "--sensor",
                               help="sensor preset (ovt, imx490, lofic, staggered, chopped, single) or a preset YAML "
                                    "to train for (overrides train.sensor); the U-Net takes any capture plan, "
                                    "the checkpoint records the sensor and serves only it"),
    threads: int = typer.Option(None, help="torch CPU threads (default: torch's choice)"),
    resume: bool = typer.Option(True, help="continue from --out when it holds a checkpoint of this config"),
    data: str = typer.Option("auto", help="where batches come from: loader (DataLoader workers on the CPU), "
                                          "device (the corpus resident on --device, batches simulated there), "
                                          "auto (device on CUDA for a split-pixel sensor, else loader)"),
    resident_dtype: str = typer.Option("float32", help="device path: storage of the resident layers, float32 or "
                                                       "float16 (half the memory, 2^-11 relative error)"),
    chunk_scenes: int = typer.Option(None, help="device path: stream the split this many scenes at a time (a split "
                                                "that does not fit the device)"),
    cuda_graph: str = typer.Option("auto", "--cuda-graph", help="auto: replay the training step as a CUDA graph on "
                                                               "a CUDA device; off: never"),
) -> None:
    """Train a learned fusion baseline; checkpoint written atomically after every epoch (resumable).

    Evaluate it with LFMBENCH_<METHOD>_CHECKPOINT=OUT lfmbench evaluate --method <method> --corpus DIR (with the
    same --sensor it was trained for). Several processes or GPUs: torchrun --nproc_per_node N -m lfmbench.cli
    train ... (data-parallel, one model; --batch-size is the global batch; docs/guide/distributed.md).
    """
    from lfmbench.baselines.trainable import ConfigError, count_parameters  # noqa: PLC0415
    from lfmbench.datasets.loading import EmptyDataError  # noqa: PLC0415
    from lfmbench.train import CUDA_GRAPH_MODES, RESIDENT_DTYPES, load_config, train, trainable  # noqa: PLC0415

    check_local_paths((("--corpus", corpus), ("--out", out), ("--config", config)))
    if method not in LEARNED:
        fail(f"--method {method!r} is not a trainable baseline; trainable: {', '.join(LEARNED)}")
    check_minima((("--epochs", epochs, 1), ("--workers", workers, 0), ("--crop", crop, 8),
                  ("--batch-size", batch_size, 1), ("--chunk-scenes", chunk_scenes, 1)))
    if resident_dtype not in RESIDENT_DTYPES:
        fail(f"--resident-dtype must be {' or '.join(RESIDENT_DTYPES)}, got {resident_dtype!r:.40}")
    if cuda_graph not in CUDA_GRAPH_MODES:
        fail(f"--cuda-graph must be {' or '.join(CUDA_GRAPH_MODES)}, got {cuda_graph!r:.40}")
    torch_setup(device, threads)
    try:
        cfg = load_config(method, config)
    except ConfigError as exc:
        fail(str(exc))
    out = out if out is not None else trainable(method).default_checkpoint
    if out.is_dir():
        fail(f"--out {out} is a directory; give a file path such as {out / f'{method}_fusion.pt'}")
    from lfmbench.fileio import writable_error  # noqa: PLC0415

    why = writable_error(out)  # before any training: the writer's own rule (a symlink is written through)
    if why is not None:
        fail(f"--out {out}: cannot write the checkpoint there ({why})")
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
            return
    secs = hist["epoch_seconds"]
    typer.echo(f"saved {out}: {count_parameters(model):,} parameters, {len(secs)} epochs, "
               f"final loss {hist['epoch_loss'][-1] if hist['epoch_loss'] else float('nan'):.4f}"
               + (f", median {statistics.median(secs):.1f} s/epoch" if secs else ""))


def register(app: typer.Typer) -> None:
    """Add the ``train`` command to the ``lfmbench`` app."""
    app.command("train")(train_cmd)
