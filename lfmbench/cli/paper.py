"""The paper's commands: ``lfmbench flicker-report`` (Fig. 3 with the exact model) and ``lfmbench paper-figures``
(Figs. 3-7, :mod:`lfmbench.paper`). torch, matplotlib and the dataset are imported when a command runs."""
from __future__ import annotations

from pathlib import Path

import typer

from lfmbench.cli._common import check_local_paths, choice, fail
from lfmbench.paper.fig3 import FIG3_EXPOSURES_S, fig3_series, plot_fig3
from lfmbench.paper.figures import FIGURES, FigureInputError, make_figures, render_corpus

__all__ = ["register"]


def _register_fig3(app) -> None:
    @app.command("flicker-report", short_help="The paper's Fig. 3: Phi[n] of a PWM LED for two exposures.")
    def flicker_report(freq_hz: float = typer.Option(95.0, help="PWM frequency (Hz)"),
                       duty: float = typer.Option(0.2, help="duty cycle (0..1)"),
                       fps: float = typer.Option(30.0, help="frame rate (1/s)"),
                       frames: int = typer.Option(12, help="number of frames"),
                       plot: Path = typer.Option(None, help="write the Fig. 3 plot to this PNG")) -> None:
        """Reproduce the paper's Fig. 3: Phi[n] of a PWM LED for 5 ms and 11.11 ms exposures."""
        from rich.console import Console
        from rich.table import Table

        try:
            s = fig3_series(freq_hz, duty, fps, frames)
        except ValueError as exc:
            raise typer.BadParameter(str(exc)) from None
        t = Table(title=f"PWM flicker: f = {freq_hz:g} Hz, D = {duty:g}, {fps:g} fps (exact model)")
        t.add_column("frame")
        t.add_column("phase [ms]")
        for te in FIG3_EXPOSURES_S:
            t.add_column(f"Phi, te={te * 1e3:.2f} ms [ms ON]")
        for i in range(frames):
            t.add_row(str(i), f"{s['phase_s'][i] * 1e3:.3f}", *(f"{s[te][i] * 1e3:.3f}" for te in FIG3_EXPOSURES_S))
        t.add_row("FSI", "", *(f"{s[('fsi', te)]:.3f}" for te in FIG3_EXPOSURES_S))
        Console().print(t)
        if plot:
            try:
                typer.echo(f"wrote {plot_fig3(plot, freq_hz=freq_hz, duty=duty, fps=fps, frames=frames)}")
            except OSError as exc:  # the PNG could not be written: one line naming it
                typer.echo(f"error: {exc.strerror or exc}", err=True)
                raise typer.Exit(2) from None


def _register_figures(app) -> None:
    @app.command("paper-figures", short_help="Reproduce the ISET-LFM paper's Figs. 3-7.")
    def paper_figures(fig: str = typer.Option("all", "--fig", help="figure", **choice(FIGURES)),
                      corpus: Path = typer.Option(None, "--corpus",
                                                  help="paper-figure corpus (DIR with fig4_6/ and fig7/, from "
                                                       "--render) or any rendered corpus; not needed for --fig 3"),
                      out: Path = typer.Option(Path("paper_figures"), "--out",
                                               help="directory for the PNG files (docs/img in a source "
                                                    "checkout re-makes the documentation's)"),
                      render: bool = typer.Option(False, "--render",
                                                  help="first render the figure scenes into --corpus (skips "
                                                       "scenes already there)"),
                      workers: int = typer.Option(1, "--workers", help="render processes (with --render)")) -> None:
        """Reproduce the ISET-LFM paper's Figs. 3-7 (docs/guide/paper-figures.md)."""
        check_local_paths((("--corpus", corpus), ("--out", out)))
        if render:
            if corpus is None:
                fail("--render needs --corpus DIR (where the figure corpus is rendered)")
            try:
                render_corpus(corpus, workers)
            except RuntimeError as exc:
                fail(str(exc))
        try:
            paths = make_figures(fig, corpus, out)
        except FigureInputError as exc:
            fail(str(exc))
        except OSError as exc:  # a figure could not be written (disk full, ...): the message names the file
            fail(exc.strerror or str(exc))
        for p in paths:
            typer.echo(f"wrote {p}")


def register(app: typer.Typer) -> None:
    """Add ``flicker-report`` and ``paper-figures`` to the ``lfmbench`` app."""
    _register_fig3(app)
    _register_figures(app)
