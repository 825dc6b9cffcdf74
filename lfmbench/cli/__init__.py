"""Command-line interface: ``lfmbench <command>``, the one layer that joins the renderer and the data stages.

One module per command family, each with a ``register(app)`` that adds its commands, in the order of the
pipeline: :mod:`~lfmbench.cli.render` (``render``, ``protocols``), :mod:`~lfmbench.cli.corpus` (``validate``,
``import-isetlfm``), :mod:`~lfmbench.cli.train` (``train``), :mod:`~lfmbench.cli.evaluate` (``evaluate``,
``leaderboard``), :mod:`~lfmbench.cli.paper` (``flicker-report``, ``paper-figures``), :mod:`~lfmbench.cli.plot`
(``plot``), :mod:`~lfmbench.cli.configs` (``configs``) and :mod:`~lfmbench.cli.demo` (``demo``). Heavy
dependencies (torch, Mitsuba, Ray, cvvdp) are imported inside the command bodies, and help texts that list the
names of a registry importing torch are made when that help is shown (:func:`~lfmbench.cli._common.lazy`), so
``lfmbench --help`` and ``lfmbench leaderboard`` never import torch (tests/cli/test_cli_startup.py). Help is click's plain format (:class:`_Formatter`): wrapped at any terminal width, nothing cut off.
"""
from __future__ import annotations

import os
import re
import sys
import traceback
from typing import Any, List, Optional

import typer
from typer.core import TyperGroup

from lfmbench.resources import PROJECT_URL
from lfmbench.cli import bench, configs, corpus, demo, evaluate, paper, plot, render, sensor, train

#: Where the ``docs/...`` pages that help texts name are read (they are not installed with the package).
DOCS_ROOT = f"{PROJECT_URL}/tree/main/docs"

#: Key of ``ctx.meta`` set by ``--debug``.
DEBUG_KEY = "lfmbench.debug"
#: Environment variable that has the effect of ``--debug`` (also for commands run by scripts and worker processes).
DEBUG_ENV = "LFMBENCH_DEBUG"


def _debug(ctx: Any) -> bool:
    return bool(ctx.meta.get(DEBUG_KEY)) or os.environ.get(DEBUG_ENV, "") not in ("", "0")


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


#: Stands in for the hyphen of a path while help text is wrapped (click breaks lines at hyphens).
_NB_HYPHEN = "\u2011"
_PATHLIKE = re.compile(r"\S*[/.]\S*")


class _Formatter(TyperGroup.context_class.formatter_class):  # click's (typer >= 0.23 vendors its own click)
    """click's plain help formatter (wrapped at the terminal width, nothing cut off) that never breaks a line
    inside a path or file name such as ``docs/guide/fault-catalogue.md``."""

    @staticmethod
    def _protect(text: str) -> str:
        return _PATHLIKE.sub(lambda m: m.group(0).replace("-", _NB_HYPHEN), text) if text else text

    def _restore(self, start: int) -> None:
        self.buffer[start:] = [s.replace(_NB_HYPHEN, "-") for s in self.buffer[start:]]

    def write_text(self, text: str) -> None:
        n = len(self.buffer)
        super().write_text(self._protect(text))
        self._restore(n)

    def write_dl(self, rows, *args, **kwargs) -> None:
        n = len(self.buffer)
        super().write_dl([(a, self._protect(b)) for a, b in rows], *args, **kwargs)
        self._restore(n)


class _Context(TyperGroup.context_class):
    formatter_class = _Formatter

    def get_help(self) -> str:
        """The help page, its :func:`~lfmbench.cli._common.lazy` texts made first (only help pages import what they
        list)."""
        from lfmbench.cli._common import resolve_lazy  # noqa: PLC0415

        resolve_lazy(self.command)
        return super().get_help()


class _Group(TyperGroup):
    """The ``lfmbench`` group: with ``--debug`` (or ``LFMBENCH_DEBUG=1``), a command that ends in a one-line error
    also prints the traceback behind it (:func:`debug_traceback`) on stderr. An exception no command turned into
    its one line (a DataLoader worker that died, an error re-raised from one, a bug) is one line too, exit 1
    (:func:`lfmbench.limits.one_line`), never a wall of traceback. Help of the group and of every command is
    formatted by :class:`_Formatter`."""

    context_class = _Context

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        cmd = super().get_command(ctx, cmd_name)
        if cmd is not None:
            cmd.context_class = _Context
        return cmd

    def invoke(self, ctx: Any) -> Any:
        import click  # noqa: PLC0415

        try:
            return super().invoke(ctx)
        except typer.Exit as exc:
            if exc.exit_code not in (0, None) and _debug(ctx):
                sys.stderr.write("--debug: the traceback behind the error above:\n" + debug_traceback(exc))
                sys.stderr.flush()
            raise
        except (click.exceptions.ClickException, click.exceptions.Abort, click.exceptions.Exit, *_typer_click_errors()):
            raise  # a usage error (unknown option, bad value): click prints it, exit 2
        except Exception as exc:  # noqa: BLE001 - the last line of defence: one line, the traceback on request
            from lfmbench.limits import one_line  # noqa: PLC0415

            text = one_line(str(exc))
            known = text != " / ".join(ln.strip() for ln in str(exc).splitlines() if ln.strip())  # worker cases
            line = text if known else (f"{type(exc).__name__}: {text} (unexpected: `lfmbench --debug ...` or "
                                       f"{DEBUG_ENV}=1 prints the traceback for a bug report)")
            typer.secho(f"error: {line}", fg=typer.colors.RED, err=True)
            if _debug(ctx):
                sys.stderr.write("--debug: the traceback behind the error above:\n" + "".join(
                    traceback.format_exception(type(exc), exc, exc.__traceback__)))
                sys.stderr.flush()
            raise typer.Exit(1) from exc


def _typer_click_errors() -> tuple[type, ...]:
    """The usage-error classes of the click that typer parses with: typer 0.2x carries its own copy of click
    (``typer._click``), whose ``ClickException`` is not click's, so a misspelled option was reported as an
    unexpected error (exit 1) instead of a usage error (exit 2)."""
    return tuple(c for c in typer.BadParameter.__mro__ if c.__name__ == "ClickException") + (typer.Abort,)


app = typer.Typer(cls=_Group, help="LED-flicker datasets and flicker-mitigation benchmark.", no_args_is_help=True,
                  epilog=f"Documentation (the docs/... pages named in the help texts): {DOCS_ROOT}",
                  rich_markup_mode=None,  # click's plain help: wrapped at any width, nothing cut off
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
    if not _debug(ctx):  # a warning is one line ("warning: ..."), not file:line and the source line
        import warnings  # noqa: PLC0415

        before = warnings.formatwarning
        warnings.formatwarning = lambda message, *a, **k: f"warning: {message}\n"
        ctx.call_on_close(lambda: setattr(warnings, "formatwarning", before))  # an embedding program keeps its own

    try:
        env = limits.parse_overrides(os.environ.get(limits.ENV, ""))
        env.update(limits.parse_overrides(",".join(limit or []), "--limit"))
    except ValueError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    if limit:  # through the environment, so that render and data-loader worker processes see them too
        os.environ[limits.ENV] = ",".join(f"{k}={v}" for k, v in env.items())


#: Command modules, in the order their commands appear in ``--help``.
COMMAND_MODULES = (paper, bench, render, corpus, train, evaluate, plot, configs, demo, sensor)

for _mod in COMMAND_MODULES:
    _mod.register(app)


def main() -> None:  # pragma: no cover - thin entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
