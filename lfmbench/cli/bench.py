"""``lfmbench flicker-bench``: the virtual IEEE P2020 flicker test bench (:mod:`lfmbench.flicker_bench`,
docs/guide/flicker-bench.md). torch, numpy and matplotlib are imported when the command runs."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from lfmbench.cli._common import fail

__all__ = ["register", "parse_exposure_option"]

_EXIT_FREEZE: list = []    # whether gc.freeze is registered to run at exit (once per process)


def parse_exposure_option(items: List[str]) -> dict:
    """``CAPTURE=START:LENGTH[,START:LENGTH...]`` (s) options into ``{capture: [[start, length], ...]}``."""
    out: dict = {}
    for it in items or []:
        name, sep, rest = it.partition("=")
        if not sep or not name or not rest:
            raise ValueError(f"--exposure must be CAPTURE=START:LENGTH[,START:LENGTH...] (s), got {it[:60]!r}")
        wins = []
        for w in rest.split(","):
            a, sep2, n = w.partition(":")
            if not sep2:
                raise ValueError(f"--exposure {name}: window {w[:40]!r} must be START:LENGTH (s)")
            try:
                wins.append([float(a), float(n)])
            except ValueError:
                raise ValueError(f"--exposure {name}: window {w[:40]!r}: START and LENGTH must be numbers (s)") from None
        out[name.strip()] = wins
    return out


def register(app: typer.Typer) -> None:
    """Add ``flicker-bench`` to the ``lfmbench`` app."""

    @app.command("flicker-bench")
    def flicker_bench(
            sensor: str = typer.Option(..., "--sensor", help="sensor preset: a shipped name or a YAML path"),
            out: Path = typer.Option(None, "--out", help="output directory (default flicker_bench/<preset>)"),
            freq: Optional[List[float]] = typer.Option(None, "--freq", help="extra PWM frequency, Hz (repeatable)"),
            n_freq: int = typer.Option(200, "--n-freq", help="log-spaced frequencies 50 Hz - 2 kHz (0: only --freq)"),
            duty: Optional[List[float]] = typer.Option(None, "--duty", help="duty cycle in (0, 1] (repeatable; "
                                                                            "replaces the 20 defaults)"),
            luminance: Optional[List[float]] = typer.Option(None, "--luminance",
                                                            help="LED ON luminance, cd/m^2 (repeatable; replaces "
                                                                 "the 10 defaults spanning every saturation)"),
            fps: Optional[float] = typer.Option(None, "--fps", help="frame rate, 1/s (default: the preset's, else 30)"),
            short_exposure: Optional[float] = typer.Option(None, "--short-exposure",
                                                           help="the corpus window 'short', s (default 5 ms)"),
            long_exposure: Optional[float] = typer.Option(None, "--long-exposure",
                                                          help="the corpus window 'long', s (default 1/90 s)"),
            exposure: Optional[List[str]] = typer.Option(None, "--exposure", metavar="CAP=START:LEN[,...]",
                                                         help="override a capture's windows, s (repeatable)"),
            line_time: Optional[float] = typer.Option(None, "--line-time", help="rolling-shutter line time, s"),
            roi_rows: int = typer.Option(1, "--roi-rows", help="rows of the ROI (rolling shutter: shifted copies)"),
            background: float = typer.Option(1.0, "--background", help="target background (LED OFF), cd/m^2"),
            frames: int = typer.Option(100, "--frames", help="frames of the sequence KPIs"),
            phase0: float = typer.Option(0.0, "--phase0", help="LED phase in frame 0 of the sequence, s"),
            cover_tol: float = typer.Option(0.01, "--cover-tol", help="phase gap (share of the period) for the "
                                                                     "frames-to-cover column"),
            noise_draws: int = typer.Option(0, "--noise-draws", help="Monte Carlo frames per cell through the "
                                                                     "preset's noise chain (0: noise-free only)"),
            roi_px: int = typer.Option(4, "--roi-px", help="pixels in the ROI mean of the noise Monte Carlo"),
            seed: int = typer.Option(0, "--seed", help="seed of the Monte Carlo"),
            method: Optional[List[str]] = typer.Option(None, "--method", help="extra fusion method: registered name "
                                                                              "or package.module:function"),
            capture_series: Optional[Path] = typer.Option(None, "--capture-series",
                                                          help="real captures: ROI-mean CSV (CARpublic layout)"),
            capture_meta: Optional[Path] = typer.Option(None, "--capture-meta",
                                                        help="real captures: per-ROI frequency_hz, duty, "
                                                             "start_index CSV"),
            tables: str = typer.Option("worst", "--tables", metavar="worst|full|none",
                                       help="CSV/JSON tables: each KPI's worst over the luminances (one row per "
                                            "panel, frequency, duty), every luminance (10x the rows), or none"),
            report: Optional[Path] = typer.Option(None, "--report", help="also write the one-page markdown report "
                                                                          "here (maps linked relative to it)")) -> None:
        """Flicker KPIs (P2020 FMI, MMP, FDI) of a sensor's captures and merges over PWM frequency, duty, luminance
        and every phase, exactly; sequences, noise and real captures beside them (docs/guide/flicker-bench.md)."""
        import gc
        import time

        t0 = time.perf_counter()
        # The imports (torch: about 250,000 objects) live as long as the process: no collection walks them while
        # they load, and frozen afterwards none walks them again (Python's gc.freeze, meant for processes that
        # fork, as this one does). Each full collection of them costs about 0.2 s.
        gc.disable()
        try:
            from lfmbench.flicker_bench import model as fbm
            from lfmbench.flicker_bench import run as fbr
            from lfmbench.fileio import AtomicWriteError
        finally:
            gc.freeze()
            gc.enable()
        if not _EXIT_FREEZE:   # the interpreter's collections at exit need not walk what is left either (about 1 s
            import atexit      # of the command on 2 cores, more than its tables): frozen once every output is closed

            atexit.register(gc.freeze)
            _EXIT_FREEZE.append(True)

        stages = {"imports_s": time.perf_counter() - t0}          # the command's wall time per stage (s)

        if (capture_series is None) != (capture_meta is None):
            fail("--capture-series and --capture-meta go together")
        if tables not in fbr.TABLE_MODES:
            fail(f"--tables must be one of {', '.join(fbr.TABLE_MODES)}, got {tables!r}")
        try:
            model = fbm.build_model(sensor, short_exposure_s=short_exposure, long_exposure_s=long_exposure,
                                    exposures=parse_exposure_option(exposure or []), fps=fps, line_time_s=line_time,
                                    roi_rows=roi_rows, background_cd_m2=background)
            if n_freq < 0:
                raise fbm.BenchError(f"--n-freq must be >= 0, got {n_freq}")
            if n_freq == 0 and not freq:
                raise fbm.BenchError("--freq: no frequency (--n-freq 0 needs at least one --freq)")
            grid = fbr.default_grid(model, n_freq, freq or (), duty or None, luminance or None)
            grid = fbr.check_grid(grid)
            captures = []
            if capture_series is not None:
                from lfmbench.flicker_bench.realcap import read_captures

                captures = read_captures(capture_series, capture_meta)
            methods = fbr.bench_methods(model, method or ())
            stages["model_s"] = time.perf_counter() - t0 - stages["imports_s"]
            res = fbr.run_bench(model, grid, methods, frames=frames, phase0_s=phase0, cover_tol=cover_tol,
                                noise_draws=noise_draws, roi_px=roi_px, seed=seed)
            if captures:
                res.measured = fbr.compare_captures(model, methods, captures, float(grid.lums[0]))
        except ValueError as exc:
            fail(str(exc))
        out_dir = out or Path("flicker_bench") / model.preset.name
        try:
            t1 = time.perf_counter()
            tab: dict = {}

            def write_tables():           # while the second map is drawn in a forked process
                t = time.perf_counter()
                tab["paths"] = fbr.write_tables(res, out_dir, tables)
                tab["s"] = time.perf_counter() - t

            images, _ = fbr.plot_maps(res, out_dir, measured=res.measured, meanwhile=write_tables)
            paths = tab["paths"] + images
            t3 = time.perf_counter()
            if report is not None:
                paths.append(fbr.write_report(res, report, images))
            # tables_s: writing the tables; maps_s: the maps stage with the tables written inside it
            stages.update(tables_s=tab["s"], maps_s=t3 - t1, report_s=time.perf_counter() - t3)
        except (AtomicWriteError, OSError) as exc:
            fail(exc.strerror or str(exc) if isinstance(exc, OSError) and not isinstance(exc, AtomicWriteError)
                 else str(exc))
        for p in paths:
            typer.echo(f"wrote {p}")
        stages["command_s"] = time.perf_counter() - t0
        typer.echo("timings: " + ", ".join(f"{k} {v:.2f}" for k, v in {**stages, **res.timings_s}.items()))
