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
import sys
import traceback
from typing import Any, List, Optional

import typer
from typer.core import TyperGroup

from lfmbench.cli import bench, corpus, demo, evaluate, paper, render, train

#: Key of ``ctx.meta`` set by ``--debug``.
DEBUG_KEY = "lfmbench.debug"


def debug_traceback(exc: BaseException) -> str:
    """The traceback behind a failed command's ``typer.Exit`` ``exc``: the exception it was raised while handling
    (with every exception chained to it, including those a ``raise ... from None`` hides), or, for a check that
    failed without an exception, where the ``Exit`` itself was raised."""
    inner = exc.__context__ or exc.__cause__
    shown = inner if inner is not None else exc
    e, seen = shown, set()
    while e is not None and id(e) not in seen:  # show what ``from None`` suppressed, too
        seen.add(id(e))
        e.__suppress_context__ = False
        e = e.__cause__ or e.__context__
    return "".join(traceback.format_exception(type(shown), shown, shown.__traceback__))


class _Group(TyperGroup):
    """The ``lfmbench`` group: with ``--debug``, a command that ends in a one-line error also prints the
    traceback behind it (:func:`debug_traceback`) on stderr."""

    def invoke(self, ctx: Any) -> Any:
        try:
            return super().invoke(ctx)
        except typer.Exit as exc:
            if exc.exit_code not in (0, None) and ctx.meta.get(DEBUG_KEY):
                sys.stderr.write("--debug: the traceback behind the error above:\n" + debug_traceback(exc))
                sys.stderr.flush()
            raise


app = typer.Typer(cls=_Group, help="LED-flicker datasets and flicker-mitigation benchmark.", no_args_is_help=True,
                  add_completion=False)


@app.callback()
def _root(ctx: typer.Context, limit: Optional[List[str]] = typer.Option(
        None, "--limit", metavar="NAME=N",
        help="Raise an input limit for this run (repeatable), e.g. --limit exr_bytes=8e9; names and defaults: "
             "docs/guide/fault-catalogue.md (\"Limits\"). Only for files you trust."),
        debug: bool = typer.Option(False, "--debug", help="After a one-line error, also print the traceback "
                                                         "behind it (for bug reports).")) -> None:
    """LED-flicker datasets and flicker-mitigation benchmark."""
    # a callback keeps ``lfmbench`` a command group even while only one command is registered
    from lfmbench import limits  # noqa: PLC0415

    ctx.meta[DEBUG_KEY] = debug

    try:
        env = limits.parse_overrides(os.environ.get(limits.ENV, ""))
        env.update(limits.parse_overrides(",".join(limit or []), "--limit"))
    except ValueError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    if limit:  # through the environment, so that render and data-loader worker processes see them too
        os.environ[limits.ENV] = ",".join(f"{k}={v}" for k, v in env.items())


#: Command modules, in the order their commands appear in ``--help``.
COMMAND_MODULES = (paper, bench, render, corpus, train, evaluate, demo)

for _mod in COMMAND_MODULES:
    _mod.register(app)


def main() -> None:  # pragma: no cover - thin entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
