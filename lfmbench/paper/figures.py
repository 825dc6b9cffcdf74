"""Reproductions of the ISET-LFM paper's Figs. 3-7 with lfmbench (``lfmbench paper-figures``).

- Fig. 3: Phi[n] at 30 fps for 5 ms and 11.11 ms exposures (:mod:`lfmbench.paper.fig3`; no render).
- Fig. 4: a two-frame sequence (60 fps, 60 m/s, global shutter): the 5 ms LPD is sharp but a car's tail and
  brake lights vanish in one frame; the 11.11 ms SPD is steady but motion-blurred.
- Fig. 5: the simple (upstream input-referred) fusion prefers the unsaturated LPD, so the dropout of a light
  caught OFF propagates into the HDR output.
- Fig. 6: where a fusion takes the SPD next to sharp LPD content, the elongated SPD trail is attached to the
  sharp LPD head: a non-physical comet.
- Fig. 7: rolling-shutter banding of a static scene, single-exposure sensor, all vehicle lights synchronised
  at 105 Hz, D = 0.2: (a) a dark band above the tail lights, (b) the motorcycle's light occluded.

The figures of Figs. 4-7 are made from the paper-figure corpus (``lfmbench paper-figures --render --corpus
DIR`` renders the scene files of ``lfmbench/configs/paper_figures/`` into ``DIR/fig4_6`` and ``DIR/fig7``) or,
for a quick look, from any corpus (the scene and the lights are then picked automatically). Every figure goes
through the public functional core (:meth:`lfmbench.datasets.LFMCaptureDataset.simulate`, the registered
baselines) with PWM parameters chosen here (:func:`dropout_phase`, :func:`fig7_phases`), so it shows exactly
what a benchmark sample can contain.

This module holds the driver (:func:`make_figures`, the render commands of the figure corpus) and re-exports the
figure modules: :mod:`~lfmbench.paper.common` (corpus layout, display, saving), :mod:`~lfmbench.paper.pwm_choices`,
:mod:`~lfmbench.paper.fig4_6`, :mod:`~lfmbench.paper.fig7`. It is imported by the ``lfmbench`` CLI: torch,
matplotlib and the dataset are imported inside the functions only.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from lfmbench.paper.common import CONFIG_DIR, FIGURES, FigureInputError, MU, RENDERS
from lfmbench.paper.fig4_6 import Sequence46, build_sequence46, fig4, fig5, fig6
from lfmbench.paper.fig7 import Setup7, build_fig7, fig7
from lfmbench.paper.pwm_choices import COMET_PWM, DROPOUT2_PWM, DROPOUT_PWM, DUTY_RANGE, FIG7_PWM, FREQ_RANGE_HZ, dropout_phase, fig7_phases, row_exposure

__all__ = ["COMET_PWM", "CONFIG_DIR", "DROPOUT2_PWM", "DROPOUT_PWM", "DUTY_RANGE", "FIG7_PWM", "FIGURES", "FREQ_RANGE_HZ", "FigureInputError", "MU", "RENDERS", "Sequence46", "Setup7", "build_fig7", "build_sequence46", "dropout_phase", "fig3", "fig4", "fig5", "fig6", "fig7", "fig7_phases", "make_all", "make_figures", "render_commands", "render_corpus", "row_exposure"]

def fig3(out_dir: str | Path) -> Path:
    """Fig. 3 (no corpus): ``out_dir/fig3_flicker.png``, 12 frames at 30 fps, 95 Hz, D = 0.2."""
    from lfmbench.paper.fig3 import plot_fig3

    return plot_fig3(Path(out_dir) / "fig3_flicker.png", frames=12)


def make_figures(fig: str, corpus: str | Path | None, out_dir: str | Path) -> list[Path]:
    """Write figure ``fig`` (one of :data:`FIGURES`) into ``out_dir``; returns the paths written.

    Raises:
        FigureInputError: unknown ``fig``, or a missing corpus for Figs. 4-7.
    """
    fig = str(fig)
    if fig not in FIGURES:
        raise FigureInputError(f"--fig must be one of {', '.join(FIGURES)}; got {fig!r}")
    out_dir = Path(out_dir)
    want = ["3", "4", "5", "6", "7"] if fig == "all" else [fig]
    if any(w != "3" for w in want) and corpus is None:
        raise FigureInputError(f"--corpus is needed for Fig. {fig} (only Fig. 3 is computed without a render)")
    paths = []
    seq = None
    for w in want:
        if w == "3":
            paths.append(fig3(out_dir))
        elif w in ("4", "5", "6"):
            seq = seq or build_sequence46(corpus)
            paths.append({"4": fig4, "5": fig5, "6": fig6}[w](corpus, out_dir, seq=seq))
        else:
            paths.append(fig7(corpus, out_dir))
    return paths


def make_all(corpus: str | Path, out_dir: str | Path) -> list[Path]:
    """Write every reproduced figure (Figs. 3-7) to ``out_dir`` and return the paths."""
    return make_figures("all", corpus, out_dir)


def render_commands(corpus: str | Path, workers: int = 1) -> list[list[str]]:
    """The ``lfmbench render`` command lines that render the paper-figure corpus into ``corpus`` (one
    sub-corpus per scene file: ``corpus/fig4_6``, ``corpus/fig7``); resumable: a finished scene is skipped."""
    root = Path(corpus)
    cmds = []
    for name, (scene, profile) in RENDERS.items():
        cmds.append([sys.executable, "-m", "lfmbench.cli", "render", "--out", str(root / name),
                     "--scene", str(CONFIG_DIR / scene), "--profile", str(CONFIG_DIR / profile),
                     "--workers", str(int(workers))])
    return cmds


def render_corpus(corpus: str | Path, workers: int = 1) -> None:
    """Run :func:`render_commands` (Mitsuba; about 1-3 min per scene on a CPU); raises ``RuntimeError`` naming
    the failed command."""
    for cmd in render_commands(corpus, workers):
        rc = subprocess.call(cmd)
        if rc != 0:
            raise RuntimeError(f"render failed (exit {rc}): {' '.join(cmd[2:])}")
