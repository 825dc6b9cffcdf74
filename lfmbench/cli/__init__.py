"""Command-line interface: ``lfmbench <command>``, the one layer that joins the renderer and the data stages.

One module per command family, each with a ``register(app)`` that adds its commands, in the order of the
pipeline: :mod:`~lfmbench.cli.render` (``render``, ``protocols``), :mod:`~lfmbench.cli.corpus` (``validate``,
``import-isetlfm``), :mod:`~lfmbench.cli.train` (``train``), :mod:`~lfmbench.cli.evaluate` (``evaluate``,
``leaderboard``), :mod:`~lfmbench.cli.paper` (``flicker-report``, ``paper-figures``) and
:mod:`~lfmbench.cli.demo` (``demo``). Heavy dependencies (torch, Mitsuba, Ray, cvvdp) are imported inside the
command bodies, so ``lfmbench --help`` stays fast.
"""
from __future__ import annotations

import typer

from lfmbench.cli import corpus, demo, evaluate, paper, render, train

app = typer.Typer(help="LED-flicker datasets and flicker-mitigation benchmark.", no_args_is_help=True,
                  add_completion=False)


@app.callback()
def _root() -> None:
    """LED-flicker datasets and flicker-mitigation benchmark."""
    # a callback keeps ``lfmbench`` a command group even while only one command is registered


#: Command modules, in the order their commands appear in ``--help``.
COMMAND_MODULES = (paper, render, corpus, train, evaluate, demo)

for _mod in COMMAND_MODULES:
    _mod.register(app)


def main() -> None:  # pragma: no cover - thin entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
