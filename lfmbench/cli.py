"""Command-line interface: ``lfmbench <command>``.

Each pipeline stage owns its commands: the modules listed in :data:`COMMAND_MODULES` expose a
``register(app)`` function that adds them. Heavy dependencies (Mitsuba, Ray, cvvdp) are imported inside the
command bodies, so ``lfmbench --help`` stays fast.
"""
from __future__ import annotations

import importlib

import typer

app = typer.Typer(help="LED-flicker datasets and flicker-mitigation benchmark.", no_args_is_help=True,
                  add_completion=False)



@app.callback()
def _root() -> None:
    """LED-flicker datasets and flicker-mitigation benchmark."""
    # a callback keeps ``lfmbench`` a command group even while only one command is registered


#: Modules that contribute sub-commands, in the order they appear in ``--help``.
COMMAND_MODULES = (
    "lfmbench.flicker_report",
    "lfmbench.paper_figures",
    "render_tools.cli",
    "lfmbench.corpus_cli",
    "lfmbench.train_cli",
    "lfmbench.evaluation.cli",
)

for _name in COMMAND_MODULES:
    try:
        _mod = importlib.import_module(_name)
    except ModuleNotFoundError as exc:  # a stage not built yet must not break the others
        if exc.name != _name:
            raise
        continue
    _mod.register(app)


def main() -> None:  # pragma: no cover - thin entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
