"""``lfmbench plot``: a PNG of one dataset sample: its captures, the ground truth, (``--method``, repeatable)
methods' outputs and (``--unet NAME=CHECKPOINT``, repeatable) trained U-Nets' outputs, through the display ISP,
frames side by side, LED regions outlined (:func:`lfmbench.datasets.plot.plot_sample`). The choices and help name
the registered splits, presets and ISP pipelines; the dataset is imported when the command runs."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from lfmbench.cli._common import check_minima, choice, fail
from lfmbench.resources import installed
from lfmbench.vocabulary import SPLITS

__all__ = ["register", "plot_cmd"]


def plot_cmd(
    corpus: Path = typer.Option(..., "--corpus", help="corpus root directory"),
    out: Path = typer.Option(Path("sample.png"), "--out", "-o", help="PNG file to write"),
    split: str = typer.Option("test", help="corpus split", **choice(SPLITS)),
    index: int = typer.Option(0, help="sample index in the split"),
    scene: Optional[str] = typer.Option(None, "--scene", help="a scene id of the split instead of --index "
                                                              "(its first sample)"),
    method: Optional[List[str]] = typer.Option(None, "--method", "-m", metavar="METHOD",
                                               help="repeatable: also show this method's output (a baseline or "
                                                    "module:function, as lfmbench evaluate)"),
    unet: Optional[List[str]] = typer.Option(None, "--unet", metavar="NAME=CHECKPOINT",
                                             help="repeatable: also show the output of the U-Net with the weights "
                                                  "CHECKPOINT (lfmbench train --out), labelled NAME (snake_case), "
                                                  "after the --method ones"),
    sensor: str = typer.Option("ovt", "--sensor", help=f"sensor preset: a shipped name "
                                                        f"({', '.join(installed('sensors'))}) or a YAML path"),
    isp: str = typer.Option("default", "--isp", help=f"ISP pipeline: a shipped name ({', '.join(installed('isp'))}) "
                                                      "or a YAML path"),
    frames: int = typer.Option(3, help="consecutive frames per sample"),
    crop: Optional[int] = typer.Option(None, help="square crop in px (default: the whole frame)"),
    seed: int = typer.Option(0, help="dataset seed (PWM draws, noise)"),
    dpi: int = typer.Option(150, help="resolution of the PNG"),
) -> None:
    """Write a PNG of one sample: captures, ground truth and methods' outputs (``--method``, then each ``--unet``
    network in the order given) through the ISP, frames side by side, LED regions outlined."""
    check_minima((("--index", index, 0), ("--frames", frames, 1), ("--crop", crop, 2), ("--dpi", dpi, 10)))
    import torch  # noqa: PLC0415

    from lfmbench.baselines import REGISTRY, MethodNotFoundError  # noqa: PLC0415
    from lfmbench.baselines.checkpoint import CheckpointError  # noqa: PLC0415
    from lfmbench.baselines.unet import named_unets, parse_named_checkpoints  # noqa: PLC0415
    from lfmbench.cli.evaluate import resolve_methods  # noqa: PLC0415
    from lfmbench.datasets.loading import EmptyDataError, collate_samples, make_dataset  # noqa: PLC0415
    from lfmbench.fileio import atomic_save_figure, writable_error  # noqa: PLC0415
    from lfmbench.isp import load_pipeline  # noqa: PLC0415

    why = writable_error(out)
    if why is not None:
        fail(f"--out {out}: cannot write the PNG there ({why})")
    try:
        load_pipeline(isp)
    except ValueError as exc:
        fail(f"--isp: {exc}")
    methods = list(dict.fromkeys(method or []))
    try:
        nets = parse_named_checkpoints(unet or [], REGISTRY, "--unet")  # a --method is registered
    except ValueError as exc:
        fail(str(exc))
    try:
        fns = resolve_methods(methods) + list(named_unets(nets).values())
        ds = make_dataset(corpus, split, seed=seed, crop=crop, samples_per_scene=1, frames=frames, sensor=sensor)
    except (MethodNotFoundError, FileNotFoundError, EmptyDataError, RuntimeError, ValueError) as exc:
        fail(str(exc))
    if scene is not None:
        if scene not in ds.scene_ids:
            fail(f"--scene {scene[:80]!r} is not in split {split!r} of {corpus} (its scenes: "
                 f"{', '.join(ds.scene_ids[:8])}{' ...' if len(ds.scene_ids) > 8 else ''})")
        index = ds.scene_ids.index(scene) * ds.samples_per_scene
    if index >= len(ds):
        fail(f"--index {index}: split {split!r} of {corpus} has {len(ds)} samples")
    sample = ds[index]
    outputs = {}
    if fns:
        batch = collate_samples([sample])
        with torch.no_grad():
            for name, fn in zip([*methods, *nets], fns):
                try:
                    outputs[name] = fn(dict(batch))[0]
                except CheckpointError as exc:  # weights that cannot be used: bad input
                    fail(f"--unet {name}={nets[name]}: {exc}" if name in nets else f"--method {name}: {exc}")
                except Exception as exc:  # noqa: BLE001 - the user's method failing is named, not a traceback
                    fail(f"{'--unet' if name in nets else '--method'} {name}: {type(exc).__name__}: {exc}", 1)
    try:
        fig = ds.plot(sample, outputs, isp=isp)
    except ValueError as exc:
        fail(str(exc))
    import matplotlib.pyplot as plt  # noqa: PLC0415

    try:
        atomic_save_figure(fig, out, dpi=dpi)
    except OSError as exc:
        fail(f"--out {out}: {exc.strerror or exc}")
    finally:
        plt.close(fig)
    typer.echo(f"wrote {out}: {sample['meta']['scene_id']} (sample {index} of split {split}), "
               f"{len(ds.preset.captures)} captures, ground truth" + "".join(f", {name}" for name in outputs))


def register(app: typer.Typer) -> None:
    """Add the ``plot`` command to the ``lfmbench`` app."""
    app.command("plot")(plot_cmd)
