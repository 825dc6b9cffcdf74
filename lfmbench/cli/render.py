"""``lfmbench render``: render procedural driving scenes into an lfmbench corpus (see docs/guide/corpus-format.md);
``lfmbench render --protocol NAME`` renders a benchmark protocol, ``lfmbench protocols`` lists and checks them
(docs/guide/protocols.md).

``register(app)`` adds the command to :mod:`lfmbench.cli`; Mitsuba and Ray are imported only when it runs.
Exit status: 0 all scenes done, 1 some scenes failed (the others are in the corpus), 2 bad input or write
error (e.g. disk full), 130 interrupted (Ctrl-C; re-run the same command to resume).
"""
from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import List, Optional

import typer

from lfmbench.cli._common import check_local_paths, choice
from lfmbench.corpus.storage import DEFAULT_STORAGE, STORAGES
from render_tools import jobs as J
from render_tools.backend import SUPPORTED_VARIANTS
from render_tools.protocol import list_protocols

__all__ = ["register", "render_cmd", "protocols_cmd"]

def _storage_help() -> str:
    """Each storage of :data:`lfmbench.corpus.storage.STORAGES` with its pixel type, mantissa bits and compression."""
    return ", ".join(f"{n} ({'HALF x 2^e' if s.dtype == 'float16' else 'FLOAT'}, {s.bits} mantissa bits, "
                     f"{s.compression.upper()})" for n, s in STORAGES.items())


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
                                          help=f"{' | '.join(J.profile_names())} | path to a YAML profile "
                                               "[default: default]."),
    protocol: Optional[str] = typer.Option(None, "--protocol",
                                           help=f"Render a benchmark protocol ({', '.join(list_protocols())} or a "
                                                "YAML path): its scenes, splits and settings; resumable."),
    split: Optional[List[str]] = typer.Option(None, "--split",
                                              help="With --protocol: render only these splits (train, val, "
                                                   "test; repeatable or comma separated), e.g. the test split "
                                                   "first; a later run without --split adds the rest."),
    workers: int = typer.Option(1, "--workers", help="Scenes rendered in parallel (local process pool)."),
    ray_address: Optional[str] = typer.Option(None, "--ray-address",
                                              help="Run on Ray: 'local', 'auto', HOST:PORT or ray://HOST:PORT (Ray "
                                                   "Client). Every node must mount --out at the same path "
                                                   "(checked before any scene starts; docs/guide/distributed.md)."),
    ray_cpus_per_scene: float = typer.Option(1.0, "--ray-cpus-per-scene",
                                             help="With --ray-address: CPUs each scene task asks Ray for."),
    ray_gpus_per_scene: float = typer.Option(0.0, "--ray-gpus-per-scene",
                                             help="With --ray-address: GPUs each scene task asks Ray for (1: each "
                                                  "concurrent scene gets its own GPU; 0: CPU rendering)."),
    scene_file: Optional[List[Path]] = typer.Option(None, "--scene",
                                                    help="Render this scene JSON file instead of generating "
                                                         "(repeatable; overrides --scenes)."),
    variant: Optional[str] = typer.Option(None, "--variant", **choice(SUPPORTED_VARIANTS),
                                          help="Mitsuba variant (default: auto, CUDA > LLVM > scalar; "
                                               "LFMBENCH_VARIANT=cpu skips CUDA)."),
    storage: Optional[str] = typer.Option(None, "--storage", **choice(STORAGES),
                                          help=f"Radiance storage: {_storage_help()}; {DEFAULT_STORAGE} for a new "
                                               "corpus. Default on resume: the corpus's own "
                                               "(docs/guide/corpus-format.md, docs/benchmarks/storage.md)."),
    half: bool = typer.Option(False, "--half", help="Same as --storage float16."),
    no_resume: bool = typer.Option(False, "--no-resume", help="Re-render scenes that are already complete."),
    yes: bool = typer.Option(False, "--yes", help="Confirm sizes above the sanity limits (e.g. --frames > 300, "
                                                  "--scenes > 10000)."),
    add_layers: bool = typer.Option(False, "--add-layers",
                                    help="With --protocol, on a corpus of an earlier version of it that differs only "
                                         "by static window layers: render just the missing layers and add them "
                                         "(no written file changes; docs/guide/rendering.md)."),
) -> None:
    """Render driving scenes (Mitsuba 3, spectral, light groups, time bins) into a corpus; resumable.

    --out is a POSIX path (local, or a folder every Ray node mounts at the same path): a URL (s3://, gs://, ...)
    is refused (docs/guide/distributed.md)."""

    check_local_paths([("--out", out)] + [("--scene", p) for p in scene_file or []])
    from render_tools import backend as B  # noqa: PLC0415

    # a cold Mitsuba back-end probe (a child process, ~1.3 s of one core) runs while this process imports its
    # modules and generates the scene; nothing is started when the verdict is cached (render_tools.backend)
    B.start_probes(variant)
    from rich.console import Console

    from lfmbench.corpus import CorpusError, CorpusWriteError
    from lfmbench.progress import Bar

    console = Console(stderr=True, soft_wrap=True)

    def fail(msg: str, code: int = 2) -> None:
        console.print(f"[red]error[/]: {msg}", highlight=False)
        raise typer.Exit(code)

    if add_layers:
        if protocol is None:
            fail("--add-layers needs --protocol (the protocol whose static window layers to add)")
        from render_tools.protocol import load_protocol  # noqa: PLC0415

        try:
            proto = load_protocol(protocol)
            if not (Path(out) / "manifest.json").is_file():
                fail(f"--add-layers: no corpus at {out} (manifest.json missing)")
            B.finish_probes()  # the layers render in worker processes (--workers): they read the cached verdict
            done = J.add_layers(out, proto, workers=workers, on_done=lambda sid, sec: console.print(
                f"{sid}: static window layers added ({sec:.1f} s)", highlight=False))
        except J.RenderInterrupted as exc:
            console.print(f"[yellow]interrupted[/]: {len(exc.summary.rendered)} scene(s) got their static window "
                          f"layers in {out}/manifest.json; no partial file was kept. Run the same command again to "
                          "add the rest.")
            raise typer.Exit(130) from None
        except CorpusWriteError as exc:
            fail(f"{exc.strerror or exc}; the corpus still holds only complete scenes (re-run to resume)")
        except (ValueError, CorpusError, J.WorkerDied) as exc:
            fail(str(exc))
        console.print(f"{len(done)} scene(s) got static window layers; the corpus is now {proto.name} "
                      f"v{proto.version}", highlight=False)
        return
    req = J.RenderRequest(out=out, scenes=scenes, width=width, height=height, spp=spp, seed=seed, bins=bins,
                          frames=frames, groups=_split_groups(groups), profile=profile, protocol=protocol,
                          splits=_split_groups(split), workers=workers, scene_files=scene_file, variant=variant,
                          storage=storage, half=half, yes=yes)
    try:
        ray_options = J.RayOptions(cpus_per_scene=ray_cpus_per_scene, gpus_per_scene=ray_gpus_per_scene)
    except ValueError as exc:
        fail(str(exc))
    try:
        plan = J.plan_render(req)
    except (ValueError, CorpusError) as exc:
        fail(str(exc))
    except CorpusWriteError as exc:
        fail(f"{exc.strerror or exc}")
    except OSError as exc:  # --out cannot be created or written (permissions, a file in the way, read-only)
        fail(f"--out {out}: cannot create or write the corpus there ({exc.strerror or exc})")
    job_list, writer, seed, fixed_splits = plan.jobs, plan.writer, plan.seed, plan.splits

    with Bar(len(job_list), "rendering", "scene", console=console) as prog:

        def on_start(n_todo: int, n_skip: int) -> None:
            prog.set(n_skip)
            if n_skip:
                prog.print(f"resuming: {n_skip} complete scene(s) skipped, {n_todo} to render")

        def on_done(sid: str, status: str) -> None:
            prog.advance()
            if status != "rendered":
                prog.print(f"[red]scene {sid} failed[/]")

        B.finish_probes()  # the scenes render in worker processes: they read the cached verdict
        try:
            summary = J.run_jobs(job_list, writer, workers=workers, ray_address=ray_address, on_start=on_start,
                                 on_done=on_done, resume=not no_resume, split_seed=seed, splits=fixed_splits,
                                 ray_options=ray_options)
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
    for n, k in Counter(summary.notes).items():  # a note many scenes share is printed once, with their count
        console.print(f"[yellow]note[/]: {n}" + (f" ({k} scenes)" if k > 1 else ""), highlight=False)
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

        cfg, bad = load_config(generator=p.generator), 0
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
