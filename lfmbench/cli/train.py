"""The ``lfmbench train`` command (a thin wrapper of :mod:`lfmbench.train`; torch is imported only when it runs,
so registering it keeps ``lfmbench --help`` and ``lfmbench render`` fast)."""
from __future__ import annotations

import statistics
from pathlib import Path


def register(app) -> None:
    """Add the ``train`` command to the typer ``app``."""
    import typer

    @app.command("train")
    def train_cmd(
        corpus: Path = typer.Option(..., "--corpus", help="corpus root directory (its train split is used)"),
        config: Path = typer.Option(None, "--config", help="U-Net YAML config (default "
                                                           "lfmbench/configs/unet.yaml; unet_tiny.yaml: demo size)"),
        out: Path = typer.Option(Path("runs") / "unet_fusion.pt", "--out", "-o", help="checkpoint path"),
        device: str = typer.Option("cpu", help="torch device: cpu, cuda, cuda:0 ..."),
        epochs: int = typer.Option(None, help="total epochs (overrides train.epochs of the config)"),
        workers: int = typer.Option(None, help="DataLoader workers (overrides train.workers)"),
        threads: int = typer.Option(None, help="torch CPU threads (default: torch's choice)"),
        resume: bool = typer.Option(True, help="continue from --out when it holds a checkpoint of this config"),
    ) -> None:
        """Train the U-Net fusion baseline; checkpoint written atomically after every epoch (resumable).

        Evaluate it with LFMBENCH_UNET_CHECKPOINT=OUT lfmbench evaluate --method unet --corpus DIR.
        """
        import torch  # noqa: PLC0415 - heavy: only when the command runs

        from lfmbench.check import torch_device  # noqa: PLC0415

        from lfmbench.baselines.unet import ConfigError, count_parameters  # noqa: PLC0415
        from lfmbench.datasets.loading import EmptyDataError  # noqa: PLC0415
        from lfmbench.train import load_config, train  # noqa: PLC0415

        def fail(msg: str, code: int = 2) -> None:
            typer.secho(f"error: {msg}", fg=typer.colors.RED, err=True)
            raise typer.Exit(code)

        for name, v, lo in (("--epochs", epochs, 1), ("--workers", workers, 0), ("--threads", threads, 1)):
            if v is not None and v < lo:
                fail(f"{name} must be an integer >= {lo}, got {v}")
        try:
            torch_device(device)
        except ValueError as exc:
            fail(str(exc))
        if threads is not None:
            torch.set_num_threads(threads)
        try:
            cfg = load_config(config)
        except ConfigError as exc:
            fail(str(exc))
        if out.is_dir():
            fail(f"--out {out} is a directory; give a file path such as {out / 'unet_fusion.pt'}")
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            fail(f"--out {out}: cannot create its directory ({exc.strerror or exc})")
        try:
            model, hist = train(corpus, out, cfg, device=device, epochs=epochs, workers=workers, resume=resume)
        except (FileNotFoundError, EmptyDataError, ValueError) as exc:
            fail(str(exc))
        secs = hist["epoch_seconds"]
        typer.echo(f"saved {out}: {count_parameters(model):,} parameters, {len(secs)} epochs, "
                   f"final loss {hist['epoch_loss'][-1] if hist['epoch_loss'] else float('nan'):.4f}"
                   + (f", median {statistics.median(secs):.1f} s/epoch" if secs else ""))
