"""``lfmbench configs``: every configuration shipped with the installed package, by kind, and where it lives.

Each name listed is what the option of that kind takes (``lfmbench train --config unet_tiny``, ``--sensor lofic``,
``--isp local``, ``render --protocol lfmbench-v1-mini``, ``render --profile small``); a path to a YAML file of
one's own works in the same place. The kinds of the ``lfmbench`` package are :data:`lfmbench.resources.CONFIG_KINDS`;
the render protocols and profiles are ``render_tools``'.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

__all__ = ["register", "configs_cmd", "shipped"]


def shipped() -> list[tuple[str, str, list[str], Path]]:
    """``(kind, what it is, names, folder)`` of every kind of shipped configuration."""
    from lfmbench.resources import CONFIG_KINDS, config_dir, installed  # noqa: PLC0415
    from render_tools import jobs as J  # noqa: PLC0415
    from render_tools import protocol as P  # noqa: PLC0415

    out = [(k.name, k.what, list(installed(k.name)), config_dir(k.name)) for k in CONFIG_KINDS.values()]
    out.append(("protocols", "benchmark protocols (render --protocol; lfmbench protocols)", list(P.list_protocols()),
                P.PROTOCOL_DIR))
    out.append(("profiles", f"render profiles (render --profile), in {J.PROFILES_FILE.name}", J.profile_names(),
                J.PROFILES_FILE.parent))
    return out


def configs_cmd(kind: Optional[str] = typer.Argument(None, help="Show one kind only (training, sensors, isp, "
                                                                 "protocols, ...)."),
                paths: bool = typer.Option(False, "--paths", help="Print the full path of every file.")) -> None:
    """List the configs shipped with lfmbench (by name) and the folder each kind is installed in.

    An option that takes a config takes its name or a path to your own YAML file (copy one of these as a start).
    """
    rows = shipped()
    if kind is not None:
        rows = [r for r in rows if r[0] == kind]
        if not rows:
            typer.echo(f"error: unknown kind {kind[:40]!r}; kinds: {', '.join(r[0] for r in shipped())}", err=True)
            raise typer.Exit(2)
    for name, what, names, folder in rows:
        typer.echo(f"{name}: {what}")
        if paths and name != "profiles":
            for n in names:
                typer.echo(f"  {n}: {folder / (n + '.yaml')}")
        else:
            typer.echo(f"  {', '.join(names) or '(none)'}")
            typer.echo(f"  in {folder}")


def register(app: typer.Typer) -> None:
    """Add the ``configs`` command to the ``lfmbench`` app."""
    app.command("configs")(configs_cmd)
