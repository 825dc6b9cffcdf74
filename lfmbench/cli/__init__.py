"""Command-line interface: ``lfmbench <command>``, the one layer that joins the renderer and the data stages.

One module per command family, each with a ``register(app)`` that adds its commands, in the order of the
pipeline: :mod:`~lfmbench.cli.render` (``render``, ``protocols``), :mod:`~lfmbench.cli.corpus` (``validate``,
``import-isetlfm``), :mod:`~lfmbench.cli.train` (``train``), :mod:`~lfmbench.cli.evaluate` (``evaluate``,
``leaderboard``), :mod:`~lfmbench.cli.paper` (``flicker-report``, ``paper-figures``) and
:mod:`~lfmbench.cli.demo` (``demo``). Heavy dependencies (torch, Mitsuba, Ray, cvvdp) are imported inside the
command bodies, so ``lfmbench --help`` stays fast.
"""
from __future__ import annotations

import os
from typing import List, Optional

import typer

from lfmbench.cli import corpus, demo, evaluate, paper, render, train

app = typer.Typer(help="LED-flicker datasets and flicker-mitigation benchmark.", no_args_is_help=True,
                  add_completion=False)


@app.callback()
def _root(limit: Optional[List[str]] = typer.Option(
        None, "--limit", metavar="NAME=N",
        help="Raise an input limit for this run (repeatable), e.g. --limit exr_bytes=8e9; names and defaults: "
             "docs/fault-catalogue.md (\"Limits\"). Only for files you trust.")) -> None:
    """LED-flicker datasets and flicker-mitigation benchmark."""
    # a callback keeps ``lfmbench`` a command group even while only one command is registered
    from lfmbench import limits  # noqa: PLC0415

    try:
        env = limits.parse_overrides(os.environ.get(limits.ENV, ""))
        env.update(limits.parse_overrides(",".join(limit or []), "--limit"))
    except ValueError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    if limit:  # through the environment, so that render and data-loader worker processes see them too
        os.environ[limits.ENV] = ",".join(f"{k}={v}" for k, v in env.items())


#: Command modules, in the order their commands appear in ``--help``.
COMMAND_MODULES = (paper, render, corpus, train, evaluate, demo)

for _mod in COMMAND_MODULES:
    _mod.register(app)


def main() -> None:  # pragma: no cover - thin entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
