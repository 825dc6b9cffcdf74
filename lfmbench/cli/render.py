"""``lfmbench render``: render procedural driving scenes into an lfmbench corpus (see docs/corpus-format.md);
``lfmbench render --protocol NAME`` renders a benchmark protocol, ``lfmbench protocols`` lists and checks them
(docs/benchmark-protocol.md).

``register(app)`` adds the command to :mod:`lfmbench.cli`; Mitsuba and Ray are imported only when it runs.
Exit status: 0 all scenes done, 1 some scenes failed (the others are in the corpus), 2 bad input or write
error (e.g. disk full), 130 interrupted (Ctrl-C; re-run the same command to resume).
"""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

__all__ = ["register", "render_cmd", "protocols_cmd", "CONFIRM_ABOVE", "MAX_SCENES", "PROTOCOL_FIXED"]

#: Sizes above which ``lfmbench render`` asks for ``--yes`` (a typo such as ``--frames 1000`` would start a
#: render of many hours per scene; ``--scenes 100000000`` would build a job list of gigabytes first).
CONFIRM_ABOVE = {"scenes": 10_000, "frames": 300, "width": 7680, "height": 4320, "spp": 4096, "bins": 256}
#: Largest ``--scenes`` accepted at all (even with ``--yes``).
MAX_SCENES = 1_000_000
#: Options that a protocol fixes: given together with ``--protocol`` they are refused (edit a copy of the
#: protocol file instead, which changes its hash). ``--variant``, ``--workers``, ``--ray-address``,
#: ``--no-resume`` and ``--yes`` change how, not what, is rendered and stay allowed.
PROTOCOL_FIXED = ("scenes", "width", "height", "spp", "seed", "bins", "frames", "groups", "profile", "scene",
                  "storage", "half")

def _split_groups(groups: Optional[List[str]]) -> list[str] | None:
    if not groups:
        return None
    out = [g.strip() for item in groups for g in item.split(",") if g.strip()]
    return out or None


def render_cmd(
    out: Path = typer.Option(..., "--out", help="Corpus directory (created, or resumed when it exists)."),
    scenes: Optional[int] = typer.Option(None, "--scenes",
                                         help="Number of procedural scenes to generate and render [default: 1]."),
    width: Optional[int] = typer.Option(None, "--width", help="Image width, pixels (default: profile)."),
    height: Optional[int] = typer.Option(None, "--height", help="Image height, pixels (default: profile)."),
    spp: Optional[int] = typer.Option(None, "--spp", help="Samples per pixel (default: profile)."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Run seed: scene i uses a seed derived from it "
                                                            "(reproducible) [default: 0]."),
    bins: Optional[int] = typer.Option(None, "--bins", help="Time bins K per capture window for flickering groups."),
    frames: Optional[int] = typer.Option(None, "--frames", help="Frames per sequence (default: profile, 3)."),
    groups: Optional[List[str]] = typer.Option(None, "--groups",
                                               help="Light groups to render (repeatable or comma separated; "
                                                    "default: all a scene has)."),
    profile: Optional[str] = typer.Option(None, "--profile",
                                          help="small | default | path to a YAML profile [default: default]."),
    protocol: Optional[str] = typer.Option(None, "--protocol",
                                           help="Render a benchmark protocol (name from `lfmbench protocols` or a "
                                                "YAML path): its scenes, splits and settings; resumable."),
    split: Optional[List[str]] = typer.Option(None, "--split",
                                              help="With --protocol: render only these splits (train, val, "
                                                   "test; repeatable or comma separated), e.g. the test split "
                                                   "first; a later run without --split adds the rest."),
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
    from render_tools import backend as B  # noqa: PLC0415

    # a cold Mitsuba back-end probe (a child process, ~1.3 s of one core) runs while this process imports its
    # modules and generates the scene; nothing is started when the verdict is cached (render_tools.backend)
    B.start_probes(variant)
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from lfmbench.corpus import DEFAULT_STORAGE, STORAGES, CorpusError, CorpusWriteError, CorpusWriter
    from lfmbench.fileio import InputFileError, load_json
    from render_tools import jobs as J

    console = Console(stderr=True, soft_wrap=True)

    def fail(msg: str, code: int = 2) -> None:
        console.print(f"[red]error[/]: {msg}", highlight=False)
        raise typer.Exit(code)

    proto = None
    splits_wanted = _split_groups(split)
    if splits_wanted is not None:
        if protocol is None:
            fail("--split needs --protocol (a plain render's split is drawn from --seed after rendering)")
        from render_tools.protocol import SPLITS  # noqa: PLC0415

        bad = [s for s in splits_wanted if s not in SPLITS]
        if bad:
            fail(f"--split {bad[0]!r} is not a split; choose from {', '.join(SPLITS)}")
    if protocol is not None:
        given = {"scenes": scenes, "width": width, "height": height, "spp": spp, "seed": seed, "bins": bins,
                 "frames": frames, "groups": groups, "profile": profile, "scene": scene_file, "storage": storage,
                 "half": half or None}
        clash = [f"--{k}" for k in PROTOCOL_FIXED if given[k] not in (None, [])]
        if clash:
            fail(f"{', '.join(clash)} cannot be combined with --protocol: the protocol fixes the scenes, splits "
                 "and render settings (edit a copy of the protocol file with a new name or version and pass its "
                 "path instead)")
    scenes = 1 if scenes is None else scenes
    seed = 0 if seed is None else seed
    profile = "default" if profile is None else profile
    try:
        if protocol is not None:
            from render_tools.protocol import load_protocol  # noqa: PLC0415

            proto = load_protocol(protocol)
        options = dict(proto.render) if proto is not None else J.load_profile(profile)
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
                    sc = load_json(p, "scene file")
                except OSError as exc:
                    fail(f"--scene {p}: cannot read scene JSON: {exc.strerror or exc}")
                except InputFileError as exc:
                    fail(f"--scene {p}: cannot read scene JSON: {str(exc).removeprefix(f'{p}: cannot read JSON: ')}")
                if not isinstance(sc, dict):
                    fail(f"--scene {p}: a scene file must hold a JSON object")
                scene_dicts.append(sc)
        backend = J.default_backend()
        # check options and scene files before anything is written (unknown fields, impossible values)
        try:
            backend.RenderOptions(**options, seed=0)
        except TypeError as exc:  # an unknown field in the profile
            if proto is not None:
                fail(f"protocol file {proto.path}: render: {exc}")
            fail(f"{profile if Path(profile).is_file() else J.PROFILES_FILE} (profile {profile!r}): {exc}")
        # a forced variant (--variant, profile or LFMBENCH_VARIANT) that cannot run here: one line, exit 2
        B.start_probes(options.get("variant"))  # the profile or protocol may name another variant
        B.check_variant(options.get("variant"))
        if scene_dicts and backend.validate_scene is not None:
            for p, sc in zip(scene_file, scene_dicts):
                try:
                    backend.validate_scene(sc)
                except ValueError as exc:
                    fail(f"--scene {p}: {exc}")
        if half and storage not in (None, "float16"):
            fail(f"--half means --storage float16, but --storage {storage} was given")
        dtype = "float16" if half else storage
        if proto is not None:
            dtype = proto.storage
        if dtype is None:  # resume with the corpus's own storage, else the default of new corpora
            try:
                old = load_json(Path(out) / "manifest.json", "manifest", "manifest_bytes").get("render") or {}
            except (OSError, ValueError, AttributeError):
                old = {}
            dtype = old.get("dtype") if old.get("dtype") in STORAGES else DEFAULT_STORAGE
        if dtype not in STORAGES:
            fail(f"--storage must be one of {', '.join(sorted(STORAGES))}, got {dtype!r}")
        ids = [str(sc.get("scene_id") or Path(p).stem) for p, sc in zip(scene_file, scene_dicts)] \
            if scene_dicts else None
        if proto is not None:
            job_list = J.protocol_jobs(out, proto, options=options, backend=backend, splits=splits_wanted)
        else:
            job_list = J.make_jobs(out, n_scenes=scenes, seed=seed, options=options, scenes=scene_dicts,
                                   scene_ids=ids, dtype=dtype, backend=backend)
        writer = CorpusWriter(out, dtype=dtype, render=J.render_record(
            seed, options, dtype, {}, protocol=None if proto is None else proto.record()))
        fixed_splits = None if proto is None else proto.splits
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

        B.finish_probes()  # the scenes render in worker processes: they read the cached verdict
        try:
            summary = J.run_jobs(job_list, writer, workers=workers, ray_address=ray_address, on_start=on_start,
                                 on_done=on_done, resume=not no_resume, split_seed=seed, splits=fixed_splits)
        except J.RenderInterrupted as exc:
            s = exc.summary
            console.print(f"[yellow]interrupted[/]: {len(s.rendered) + len(s.skipped)} complete scene(s) are in "
                          f"{out}/manifest.json; no partial file was kept. Run the same command again to resume.")
            raise typer.Exit(130) from None
        except CorpusWriteError as exc:
            fail(f"{exc.strerror or exc}; the corpus still holds only complete scenes (re-run to resume)")
        except ValueError as exc:
            fail(str(exc))
    J.write_splits(writer, seed, fixed_splits)
    for n in summary.notes:
        console.print(f"[yellow]note[/]: {n}", highlight=False)
    for sid, msg in summary.failed.items():
        console.print(f"[red]scene {sid} failed[/]: {msg}", highlight=False)
    secs = sum(summary.seconds.values())
    typer.echo(f"{out}: {len(summary.rendered)} rendered ({secs:.1f} s), {len(summary.skipped)} skipped, "
               f"{len(summary.failed)} failed")
    if summary.failed:
        raise typer.Exit(1)


def protocols_cmd(
    name: Optional[str] = typer.Argument(None, help="A protocol (name or YAML path): show its coverage."),
    check: bool = typer.Option(False, "--check", help="Also generate every scene of NAME (no rendering) and "
                                                      "check that it meets its pinned conditions."),
) -> None:
    """List the benchmark protocols, or show one protocol's splits and test-split coverage."""
    from render_tools import protocol as P  # noqa: PLC0415

    def fail(msg: str) -> None:
        typer.echo(f"error: {msg}", err=True)
        raise typer.Exit(2)

    if name is None:
        if check:
            fail("--check needs a protocol NAME")
        for n, path in P.list_protocols().items():
            try:
                p = P.load_protocol(path)
            except ValueError as exc:
                typer.echo(f"{n}: INVALID: {exc}")
                continue
            r = p.render
            typer.echo(f"{p.name} v{p.version}  {r.get('width')}x{r.get('height')}  "
                       + "  ".join(f"{k} {len(v)}" for k, v in p.splits.items()) + f"  sha256 {p.sha256[:12]}")
        typer.echo(f"render one with: lfmbench render --protocol NAME --out DIR  (files: {P.PROTOCOL_DIR})")
        return
    try:
        p = P.load_protocol(name)
    except ValueError as exc:
        fail(str(exc))
    typer.echo(f"{p.path}\n{p.description}\nsha256 {p.sha256}\nrender {p.render}, storage {p.storage}\n"
               + ", ".join(f"{k} {len(v)} scenes" for k, v in p.splits.items()) + "\n")
    typer.echo(P.coverage_table(p, "test"))
    if check:
        from render_tools.scene import generate_scene, load_config  # noqa: PLC0415

        cfg, bad = load_config(), 0
        for ps in p.scenes:
            try:
                miss = P.check_scene(generate_scene(ps.seed, scene_id=ps.scene_id, config=cfg, **ps.scene_kw()),
                                     ps, cfg)
            except ValueError as exc:
                miss = [str(exc)]
            if miss:
                bad += 1
                typer.echo(f"{ps.scene_id}: " + "; ".join(miss))
        typer.echo(f"\n{len(p.scenes) - bad} of {len(p.scenes)} scenes meet their pinned conditions")
        if bad:
            raise typer.Exit(1)


def register(app: typer.Typer) -> None:
    """Add ``render`` and ``protocols`` to the ``lfmbench`` app."""
    app.command("render")(render_cmd)
    app.command("protocols")(protocols_cmd)
