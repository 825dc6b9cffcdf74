"""``lfmbench render``: render procedural driving scenes into an lfmbench corpus (see docs/corpus-format.md).

``register(app)`` adds the command to :mod:`lfmbench.cli`; Mitsuba and Ray are imported only when it runs.
Exit status: 0 all scenes done, 1 some scenes failed (the others are in the corpus), 2 bad input or write
error (e.g. disk full), 130 interrupted (Ctrl-C; re-run the same command to resume).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import List, Optional

import typer

__all__ = ["register", "render_cmd", "CONFIRM_ABOVE", "MAX_SCENES"]

#: Sizes above which ``lfmbench render`` asks for ``--yes`` (a typo such as ``--frames 1000`` would start a
#: render of many hours per scene; ``--scenes 100000000`` would build a job list of gigabytes first).
CONFIRM_ABOVE = {"scenes": 10_000, "frames": 300, "width": 7680, "height": 4320, "spp": 4096, "bins": 256}
#: Largest ``--scenes`` accepted at all (even with ``--yes``).
MAX_SCENES = 1_000_000

def _split_groups(groups: Optional[List[str]]) -> list[str] | None:
    if not groups:
        return None
    out = [g.strip() for item in groups for g in item.split(",") if g.strip()]
    return out or None


def render_cmd(
    out: Path = typer.Option(..., "--out", help="Corpus directory (created, or resumed when it exists)."),
    scenes: int = typer.Option(1, "--scenes", help="Number of procedural scenes to generate and render."),
    width: Optional[int] = typer.Option(None, "--width", help="Image width, pixels (default: profile)."),
    height: Optional[int] = typer.Option(None, "--height", help="Image height, pixels (default: profile)."),
    spp: Optional[int] = typer.Option(None, "--spp", help="Samples per pixel (default: profile)."),
    seed: int = typer.Option(0, "--seed", help="Run seed: scene i uses a seed derived from it (reproducible)."),
    bins: Optional[int] = typer.Option(None, "--bins", help="Time bins K per capture window for flickering groups."),
    frames: Optional[int] = typer.Option(None, "--frames", help="Frames per sequence (default: profile, 3)."),
    groups: Optional[List[str]] = typer.Option(None, "--groups",
                                               help="Light groups to render (repeatable or comma separated; "
                                                    "default: all a scene has)."),
    profile: str = typer.Option("default", "--profile", help="small | default | path to a YAML profile."),
    workers: int = typer.Option(1, "--workers", help="Scenes rendered in parallel (local process pool)."),
    ray_address: Optional[str] = typer.Option(None, "--ray-address",
                                              help="Run on Ray: 'local', 'auto' or ray://host:port."),
    scene_file: Optional[List[Path]] = typer.Option(None, "--scene",
                                                    help="Render this scene JSON file instead of generating "
                                                         "(repeatable; overrides --scenes)."),
    variant: Optional[str] = typer.Option(None, "--variant",
                                          help="Mitsuba variant: cuda_ad_spectral, llvm_ad_spectral or "
                                               "scalar_spectral (default: auto, CUDA > LLVM > scalar; "
                                               "LFMBENCH_VARIANT=cpu skips CUDA)."),
    storage: Optional[str] = typer.Option(None, "--storage",
                                          help="Radiance storage: compact (HALF x 2^e, 5 mantissa bits, PIZ; "
                                               "default for a new corpus), float16 (HALF x 2^e, ZIP) or float32 "
                                               "(lossless FLOAT, format version 1). Default on resume: the "
                                               "corpus's own (docs/corpus-format.md, docs/storage-benchmark.md)."),
    half: bool = typer.Option(False, "--half", help="Same as --storage float16."),
    no_resume: bool = typer.Option(False, "--no-resume", help="Re-render scenes that are already complete."),
    yes: bool = typer.Option(False, "--yes", help="Confirm sizes above the sanity limits (e.g. --frames > 300, "
                                                  "--scenes > 10000)."),
) -> None:
    """Render driving scenes (Mitsuba 3, spectral, light groups, time bins) into a corpus; resumable."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from lfmbench.corpus import DEFAULT_STORAGE, STORAGES, CorpusError, CorpusWriteError, CorpusWriter
    from render_tools import jobs as J

    console = Console(stderr=True, soft_wrap=True)

    def fail(msg: str, code: int = 2) -> None:
        console.print(f"[red]error[/]: {msg}", highlight=False)
        raise typer.Exit(code)

    try:
        options = J.load_profile(profile)
        given = {"width": width, "height": height, "spp": spp, "bins": bins, "frames": frames, "variant": variant}
        options.update({k: v for k, v in given.items() if v is not None})
        gl = _split_groups(groups)
        if gl is not None:
            options["groups"] = gl
        for k in ("width", "height", "spp", "bins", "frames"):
            v = options.get(k)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
                fail(f"--{k} must be an integer >= 1, got {v!r}")
        if seed < 0:
            fail(f"--seed must be >= 0, got {seed}")
        if not scene_file and scenes < 1:
            fail(f"--scenes must be an integer >= 1, got {scenes}")
        if not scene_file and scenes > MAX_SCENES:
            fail(f"--scenes {scenes} is above the limit of {MAX_SCENES:,} scenes per run")
        sizes = dict(options, scenes=None if scene_file else scenes)
        for k, limit in CONFIRM_ABOVE.items():
            v = sizes.get(k)
            if isinstance(v, int) and v > limit and not yes:
                fail(f"--{k} {v} is above the sanity limit {limit:,} (a render of this size takes very long or "
                     f"needs much memory); pass --yes if you mean it")
        if workers < 1:
            fail(f"--workers must be >= 1, got {workers}")
        scene_dicts = None
        if scene_file:
            scene_dicts = []
            for p in scene_file:
                try:
                    sc = json.loads(Path(p).read_text())
                except (OSError, json.JSONDecodeError) as exc:
                    fail(f"--scene {p}: cannot read scene JSON: {exc}")
                if not isinstance(sc, dict):
                    fail(f"--scene {p}: a scene file must hold a JSON object")
                scene_dicts.append(sc)
        backend = J.default_backend()
        # check options and scene files before anything is written (unknown fields, impossible values)
        try:
            backend.RenderOptions(**options, seed=0)
        except TypeError as exc:  # an unknown field in the profile
            fail(f"{profile if Path(profile).is_file() else J.PROFILES_FILE} (profile {profile!r}): {exc}")
        # a forced variant (--variant, profile or LFMBENCH_VARIANT) that cannot run here: one line, exit 2
        from render_tools.backend import check_variant  # noqa: PLC0415

        check_variant(options.get("variant"))
        if scene_dicts and backend.validate_scene is not None:
            for p, sc in zip(scene_file, scene_dicts):
                try:
                    backend.validate_scene(sc)
                except ValueError as exc:
                    fail(f"--scene {p}: {exc}")
        if half and storage not in (None, "float16"):
            fail(f"--half means --storage float16, but --storage {storage} was given")
        dtype = "float16" if half else storage
        if dtype is None:  # resume with the corpus's own storage, else the default of new corpora
            try:
                old = json.loads((Path(out) / "manifest.json").read_text()).get("render") or {}
            except (OSError, json.JSONDecodeError, AttributeError):
                old = {}
            dtype = old.get("dtype") if old.get("dtype") in STORAGES else DEFAULT_STORAGE
        if dtype not in STORAGES:
            fail(f"--storage must be one of {', '.join(sorted(STORAGES))}, got {dtype!r}")
        ids = [str(sc.get("scene_id") or Path(p).stem) for p, sc in zip(scene_file, scene_dicts)] \
            if scene_dicts else None
        job_list = J.make_jobs(out, n_scenes=scenes, seed=seed, options=options, scenes=scene_dicts,
                               scene_ids=ids, dtype=dtype, backend=backend)
        writer = CorpusWriter(out, dtype=dtype, render=J.render_record(seed, options, dtype, {}))
    except typer.Exit:
        raise
    except (ValueError, CorpusError) as exc:
        fail(str(exc))
    except CorpusWriteError as exc:
        fail(f"{exc.strerror or exc}")
    except OSError as exc:  # --out cannot be created or written (permissions, a file in the way, read-only)
        fail(f"--out {out}: cannot create or write the corpus there ({exc.strerror or exc})")

    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console) as prog:
        task = prog.add_task("rendering", total=len(job_list))

        def on_start(n_todo: int, n_skip: int) -> None:
            prog.update(task, completed=n_skip)
            if n_skip:
                prog.console.print(f"resuming: {n_skip} complete scene(s) skipped, {n_todo} to render")

        def on_done(sid: str, status: str) -> None:
            prog.advance(task)
            if status != "rendered":
                prog.console.print(f"[red]scene {sid} failed[/]")

        try:
            summary = J.run_jobs(job_list, writer, workers=workers, ray_address=ray_address, on_start=on_start,
                                 on_done=on_done, resume=not no_resume, split_seed=seed)
        except J.RenderInterrupted as exc:
            s = exc.summary
            console.print(f"[yellow]interrupted[/]: {len(s.rendered) + len(s.skipped)} complete scene(s) are in "
                          f"{out}/manifest.json; no partial file was kept. Run the same command again to resume.")
            raise typer.Exit(130) from None
        except CorpusWriteError as exc:
            fail(f"{exc.strerror or exc}; the corpus still holds only complete scenes (re-run to resume)")
        except ValueError as exc:
            fail(str(exc))
    writer.write_splits(seed, J.SPLIT_FRACTIONS)
    for n in summary.notes:
        console.print(f"[yellow]note[/]: {n}", highlight=False)
    for sid, msg in summary.failed.items():
        console.print(f"[red]scene {sid} failed[/]: {msg}", highlight=False)
    secs = sum(summary.seconds.values())
    typer.echo(f"{out}: {len(summary.rendered)} rendered ({secs:.1f} s), {len(summary.skipped)} skipped, "
               f"{len(summary.failed)} failed")
    if summary.failed:
        raise typer.Exit(1)


def register(app: typer.Typer) -> None:
    """Add ``render`` to the ``lfmbench`` app."""
    app.command("render")(render_cmd)
