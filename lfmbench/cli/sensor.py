"""Sensor commands: ``lfmbench sensor fit`` (a preset from EMVA 1288 results) and ``lfmbench sensor flicker-table``
(each preset's captured PWM fraction, written into docs). torch is imported only when a command runs."""
from __future__ import annotations

import os
from pathlib import Path
from typing import List

import typer

from lfmbench.cli._common import fail

__all__ = ["register"]

sensor_app = typer.Typer(help="Sensor presets: fit one from EMVA 1288 results; tabulate PWM flicker.",
                         no_args_is_help=True)


@sensor_app.command("fit")
def fit(emva: Path = typer.Argument(..., help="EMVA 1288 Release 4 results (YAML; docs/guide/sensors.md)"),
        out: Path = typer.Option(..., "--out", help="preset YAML to write"),
        exposure: List[str] = typer.Option(..., "--exposure",
                                           help="a capture's exposure: short, long or YAML windows "
                                                "'[[start_s, length_s], ...]' (repeat: one per capture)")) -> None:
    """Build a sensor preset from EMVA 1288 results and an exposure plan (nothing written on bad input)."""
    import yaml  # noqa: PLC0415

    from lfmbench.fileio import atomic_write_text, load_yaml  # noqa: PLC0415
    from lfmbench.sensor.emva import preset_from_emva  # noqa: PLC0415

    if not emva.is_file():
        fail(f"{emva}: not a file")
    if out.exists() and not out.is_file():
        fail(f"--out {out}: exists and is not a regular file")
    try:
        data = load_yaml(emva, source=str(emva))
    except (OSError, ValueError) as exc:
        fail(str(exc).splitlines()[0] if str(exc) else f"{emva}: unreadable")
    plans = []
    for i, e in enumerate(exposure):
        try:
            plans.append(e if e in ("short", "long") else yaml.safe_load(e))
        except yaml.YAMLError:
            fail(f"--exposure[{i}]: not 'short', 'long' or a YAML list of [start_s, length_s] windows: {e[:60]!r}")
    qe = data.get("qe_curve") if isinstance(data, dict) else None
    ref = None
    if isinstance(qe, str):   # the preset names the QE file relative to itself when it can
        q = (emva.parent / qe).resolve() if not Path(qe).is_absolute() else Path(qe)
        try:
            ref = os.path.relpath(q, out.resolve().parent)
        except ValueError:
            ref = str(q)
    try:
        preset = preset_from_emva(data, plans, str(emva), qe_ref=ref)
    except ValueError as exc:
        fail(str(exc))
    header = (f"# Sensor preset fitted by 'lfmbench sensor fit' from the EMVA 1288 results {emva.name}\n"
              "# (docs/guide/sensors.md, 'Your own sensor'); load with load_preset(path).\n")
    atomic_write_text(out, header + yaml.safe_dump(preset, sort_keys=False))
    typer.echo(f"wrote {out}")


@sensor_app.command("flicker-table")
def flicker_table(out: Path = typer.Option(Path("docs/results/preset-flicker.md"), "--out",
                                           help="markdown page to write"),
                  presets: List[str] = typer.Option(None, "--preset", help="preset names (default: every shipped)")
                  ) -> None:
    """Each preset's captured fraction of a PWM light (lowest and highest over all phases, per frequency and duty)
    from the exact model, written as a markdown page."""
    from lfmbench.fileio import atomic_write_text  # noqa: PLC0415
    from lfmbench.sensor.flicker_table import flicker_markdown  # noqa: PLC0415

    if out.exists() and not out.is_file():
        fail(f"--out {out}: exists and is not a regular file")
    try:
        text = flicker_markdown(presets or None)
    except ValueError as exc:
        fail(str(exc))
    atomic_write_text(out, text)
    typer.echo(f"wrote {out}")


def register(app: typer.Typer) -> None:
    """Add the ``sensor`` command group to the ``lfmbench`` app."""
    app.add_typer(sensor_app, name="sensor")
