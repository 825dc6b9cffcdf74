"""The ``lfmbench evaluate`` and ``lfmbench leaderboard`` commands (thin wrappers of the library modules).

The help and the choices are read from the registries and definitions that own the names
(:data:`lfmbench.baselines.REGISTRY`, the shipped sensor presets and ISP pipelines of
:func:`lfmbench.resources.installed`, the metrics of :data:`lfmbench.metrics.REGISTRY` (``--sort-by``),
:data:`lfmbench.vocabulary.SPLITS`, :data:`lfmbench.evaluation.benchmark.SIMULATE`), so they name every registered
entry; the rest of the library (the dataset, the evaluation) is imported inside the command bodies, and the
baselines (which import torch) when the help of ``evaluate`` is shown, so that ``lfmbench leaderboard`` runs
without torch."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from lfmbench.cli._common import check_local_paths, check_minima, choice, fail, lazy, lock_output, torch_setup
from lfmbench.evaluation.benchmark import SIMULATE
from lfmbench.metrics import REGISTRY as METRICS
from lfmbench.resources import installed
from lfmbench.vocabulary import REFERENCES, SPLITS

__all__ = ["register", "evaluate_cmd", "leaderboard_cmd", "resolve_methods"]


def evaluate_cmd(
    ctx: typer.Context,
    method: Optional[List[str]] = typer.Option(None, "--method", "-m", metavar="METHOD",
                                               help="repeatable: a baseline (listed below) or "
                                                    "module:function, a module of the current folder included; "
                                                    "several methods are scored on one simulation of each sample"),
    unet: Optional[List[str]] = typer.Option(None, "--unet", metavar="NAME=CHECKPOINT",
                                             help="repeatable: also score the U-Net with the weights CHECKPOINT "
                                                  "(lfmbench train --out) as method NAME (snake_case), written to "
                                                  "<runs-dir>/NAME.json, after the --method ones"),
    corpus: Path = typer.Option(..., "--corpus", help="corpus root directory"),
    sensor: str = typer.Option("ovt", "--sensor",
                               help="sensor preset (lfmbench configs sensors) or a preset YAML; its name and "
                                    "architecture are recorded in the result"),
    split: str = typer.Option("test", help="corpus split", **choice(SPLITS)),
    output: Path = typer.Option(None, "--output", "-o", help="result JSON of a single --method or --unet "
                                                            "(default <runs-dir>/<method>.json)"),
    runs_dir: Path = typer.Option(Path("runs"), "--runs-dir", help="folder of the result files "
                                                                  "<method>.json"),
    seed: int = typer.Option(0, help="dataset seed (PWM draws, noise)"),
    max_scenes: int = typer.Option(None, help="evaluate the first N scenes (all their --samples-per-scene draws)"),
    crop: int = typer.Option(None, help="square crop in px passed to the dataset"),
    frames: int = typer.Option(3, help="consecutive frames per sample (e.g. 24 or 100; <= the corpus frames)"),
    samples_per_scene: int = typer.Option(1, help="PWM draws per scene (test draws frozen in the corpus)"),
    repeats: int = typer.Option(5, help="timed calls after warm-up (median and spread recorded)"),
    warmup: int = typer.Option(1, help="untimed warm-up calls"),
    perceptual: bool = typer.Option(True, help="also PU21-PSNR and ColorVideoVDP (needs cvvdp)"),
    device: str = typer.Option("cpu", help="torch device, e.g. cpu or cuda"),
    simulate: str = typer.Option("host", "--simulate", **choice(SIMULATE),
                                 help="where the captures are simulated: host (the per-sample path, generator noise: "
                                      "the published lfmbench-v1 numbers) or device (the device program on --device, "
                                      "counter noise: the same draws, other noise numbers; ranked apart)"),
    threads: int = typer.Option(None, help="torch CPU threads (default: torch's choice); recorded"),
    cache_dir: Path = typer.Option(None, "--cache-dir",
                                   help="projected-radiance cache directory (default <corpus>/.cache; "
                                        "any writable directory for a read-only corpus)"),
    isp: str = typer.Option("default", "--isp",
                            help="ISP pipeline of the display-referred columns psnr_srgb, ssim_srgb: a shipped name "
                                 f"({', '.join(installed('isp'))}) or a YAML path; 'none' skips them"),
    reference: str = typer.Option("own", "--reference", **choice(REFERENCES),
                                  help="truth of the full-image and ghost columns: own (the sensor's own reference "
                                       "exposure) or common (gt_common, one window through one reference sensor, "
                                       "the same for every sensor: needed by leaderboard --cross-sensor); the LED "
                                       "columns always use the sensor's own"),
    shard: str = typer.Option(None, "--shard", metavar="INDEX/COUNT",
                              help="score only shard INDEX of COUNT (scene s goes to shard s mod COUNT; e.g. "
                                   "$SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT or $RANK/$WORLD_SIZE); join the "
                                   "shard files with `lfmbench merge-results` (docs/guide/distributed.md)"),
    resume: bool = typer.Option(True, help="continue the result files (--output or <runs-dir>/<method>.json) when "
                                           "they hold a killed or interrupted run of this evaluation: only the "
                                           "missing samples are scored, a complete one is skipped"),
) -> None:
    """Score fusion methods (``--method``, then each ``--unet`` network in the order given) on a corpus split;
    write per-scene and aggregate metrics as JSON, one file per method.

    Exit status: 0 every scene scored, 1 some scenes failed or the data source failed (the result file
    says which), 2 bad input, 130 interrupted (the result file has status "interrupted"; run the same command
    again to resume: only the missing samples are scored).
    """
    from lfmbench.datasets.loading import EmptyDataError  # noqa: PLC0415
    from lfmbench.evaluation.benchmark import (corpus_run_inputs,  # noqa: PLC0415
                                               run_dataset_record, safe_name, samples_to_score, score_batches)
    from lfmbench.evaluation.leaderboard import _fmt  # noqa: PLC0415
    from lfmbench.evaluation.run import (DataSourceError, EvaluationInterrupted, ResumeError,  # noqa: PLC0415
                                         evaluate_methods)

    methods = list(dict.fromkeys(method or []))  # a method named twice is scored once
    if threads is not None and threads < 1:
        fail(f"--threads must be >= 1, got {threads}")
    check_local_paths((("--corpus", corpus), ("--output", output), ("--cache-dir", cache_dir)))
    if shard is not None:
        from lfmbench.evaluation.shards import parse_shard  # noqa: PLC0415

        try:
            shard_at = parse_shard(shard)
        except ValueError as exc:
            fail(str(exc))
    check_minima((("--max-scenes", max_scenes, 1), ("--samples-per-scene", samples_per_scene, 1),
                  ("--frames", frames, 1), ("--repeats", repeats, 1), ("--warmup", warmup, 0), ("--crop", crop, 2)))
    nets = _named_unets(methods, unet or [])  # before anything is written: a bad item writes nothing
    specs = [*methods, *nets]
    if not specs:
        fail("give at least one --method METHOD or --unet NAME=CHECKPOINT")
    if output is not None and len(specs) > 1:
        fail(f"--output names the result file of one method; {len(specs)} methods write "
             f"<runs-dir>/<method>.json (--runs-dir, default runs)")
    torch_setup(device, threads)
    outs = [output] if output is not None else [runs_dir / f"{safe_name(m)}.json" for m in specs]
    if len(set(outs)) != len(outs):
        fail(f"--method, --unet: two methods map to one result file name ({', '.join(map(str, outs))})")
    from lfmbench.fileio import writable_error  # noqa: PLC0415

    for out in outs:
        why = writable_error(out)  # an unwritable --output is found before any work is done (the writer's own rule)
        if why is not None:
            fail(f"--output {out}: cannot write the result file there ({why})")
    for out in outs:
        lock_output(ctx, out, "--output")  # one evaluation per result file
    from lfmbench.baselines import MethodNotFoundError
    from lfmbench.baselines.checkpoint import CheckpointError
    from lfmbench.isp import load_pipeline
    from lfmbench.metrics import ScoreOptions

    isp_name = None if isp.lower() == "none" else isp
    if isp_name is not None:
        try:
            load_pipeline(isp_name)  # a bad pipeline file is named before any work
        except ValueError as exc:
            fail(f"--isp: {exc}")
    from lfmbench.sensor import resolve  # noqa: PLC0415

    try:
        fns = resolve_methods(methods) + list(nets.values())
        preset = resolve(sensor)  # the one resolution of --sensor: the object travels to the dataset and metrics
        extra = {"frames": frames, "sensor": preset, "noise_streams": SIMULATE[simulate]}
        if cache_dir is not None:
            extra["cache_dir"] = cache_dir
        ds, ident, cond = corpus_run_inputs(corpus, split, seed, crop, samples_per_scene, reference, **extra)
    except (MethodNotFoundError, FileNotFoundError, EmptyDataError, RuntimeError, ValueError) as exc:
        fail(str(exc))
    from lfmbench.baselines import REGISTRY, methods_for

    for m, fn in zip(specs, fns):
        if m in REGISTRY and m not in methods_for(ds.architecture):
            fail(f"--method {m} does not apply to --sensor {sensor} ({ds.architecture}); its baselines: "
                 f"{', '.join(methods_for(ds.architecture))}")
        check = _checkpoint_sensor_check(fn)
        if check is not None:  # a network trained for another sensor is refused before any work
            try:
                check(ds.sensor_name, list(ds.preset.captures))
            except CheckpointError as exc:
                fail(str(exc))
    n = samples_to_score(ds, max_scenes)
    record = run_dataset_record(ds, corpus, split, n, crop, samples_per_scene, frames)
    indices = None
    if shard is not None:
        from lfmbench.evaluation.shards import shard_record, shard_samples  # noqa: PLC0415

        indices = shard_samples(n, samples_per_scene, *shard_at)
        if not indices:
            fail(f"--shard {shard_at[0]}/{shard_at[1]}: the split has only {-(-n // samples_per_scene)} scene(s) to "
                 f"score; use at most that many shards")
        record["shard"] = shard_record(*shard_at, indices, n)

    def source(start: int):  # the samples from position start on: a resumed run reads only those it misses
        return score_batches(ds, n, simulate, device, indices=indices, start=start)

    try:
        results = evaluate_methods(fns, source, method_specs=specs, outputs=outs,
                                   options=ScoreOptions(perceptual=perceptual, isp=isp_name, sensor=ds.preset,
                                                        reference=reference),
                                   warmup=warmup, repeats=repeats, device=device, seeds={"dataset": seed},
                                   dataset=record, total=n if indices is None else len(indices), corpus=ident,
                                   scene_conditions=cond, resume=resume, log=typer.echo)
    except EvaluationInterrupted as exc:
        n_done = len(exc.result["scenes"])
        typer.secho(f"interrupted: {n_done} scene(s) scored; {', '.join(map(str, outs))} marked status "
                    "\"interrupted\" (the leaderboard skips them); run the same command again to resume",
                    fg=typer.colors.YELLOW, err=True)
        raise typer.Exit(130) from None
    except ResumeError as exc:  # another evaluation's file where this one writes: nothing written
        fail(str(exc))
    except (DataSourceError, EmptyDataError) as exc:
        fail(f"{exc} (partial results in {', '.join(map(str, outs))})", 1)
    except CheckpointError as exc:  # a hostile or broken weights file: bad input, named
        fail(f"{exc}; nothing was scored")
    except OSError as exc:  # the result file could not be written (disk full, ...)
        fail(f"{exc.filename}: {exc.strerror or exc}" if exc.filename else (exc.strerror or str(exc)))
    failed = []
    for m, out, res in zip(specs, outs, results):
        agg = res["aggregate"]
        ci = agg.get("ci", {}).get("led_score") or [None, None]
        rt = res["runtime"]
        spread = rt.get("iqr_ms_per_megapixel")
        typer.echo(f"{m}: {agg.get('scenes_ok', 0)}/{agg.get('scenes', 0)} scenes ok, LED score "
                   f"{_fmt(agg.get('led_score'))} [{_fmt(ci[0])}, {_fmt(ci[1])}], dropout "
                   f"{_fmt(agg.get('dropout_rate'))}, PSNR-mu {_fmt(agg.get('psnr_mu'), 2)} dB, "
                   f"{_fmt(rt['ms_per_megapixel'], 1)}"
                   + (f" (IQR {_fmt(spread[0], 1)}-{_fmt(spread[1], 1)})" if spread else "")
                   + f" ms/MP -> {out}")
        bad = [sc for sc in res["scenes"] if sc.get("status") != "ok"]
        if bad:
            failed.append(f"{m}: {len(bad)} of {len(res['scenes'])} scenes failed (first: scene "
                          f"{bad[0].get('scene_id')}: {bad[0].get('error', bad[0].get('status'))}); see {out}")
    if failed:
        fail("; ".join(failed), 1)


def resolve_methods(specs: list[str]) -> list:
    """The callables of method specs (:func:`lfmbench.baselines.get_method`), found as ``python -m`` would: the
    current folder is searched for a ``module:function`` module (put first on ``sys.path``, once). A module that
    is not found gets a message saying where it was looked for and what to do."""
    import os
    import sys

    from lfmbench.baselines import MethodNotFoundError, get_method

    if "" not in sys.path and os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())
    out = []
    for spec in specs:
        try:
            out.append(get_method(spec))
        except MethodNotFoundError as exc:
            mod = spec.partition(":")[0] if ":" in spec else None
            if mod and isinstance(exc.__cause__, ModuleNotFoundError) and exc.__cause__.name == mod.split(".")[0]:
                raise MethodNotFoundError(
                    f"--method {spec!r}: no module {mod!r} in the current folder ({os.getcwd()}) or on the Python "
                    f"path; run from the folder holding {mod.replace('.', '/')}.py, or add its folder to "
                    "PYTHONPATH, or pip install the package that holds it") from exc
            raise
    return out


def _named_unets(methods: list[str], items: list[str]) -> dict:
    """The ``--unet NAME=CHECKPOINT`` items as U-Net methods of their own names ({name: method}, in the order given,
    :func:`lfmbench.baselines.unet.named_unets`: the result records each one's checkpoint path and SHA-256 as for
    ``unet``), their weights read now. A NAME that is not snake_case, is registered, names the result file of a
    ``--method`` (``-m mod:fn`` writes ``mod_fn.json``) or is an earlier item, a CHECKPOINT that is no file or
    cannot be read as U-Net weights: one line naming ``--unet`` and the item, exit 2."""
    if not items:
        return {}
    from lfmbench.baselines import REGISTRY  # noqa: PLC0415
    from lfmbench.baselines.checkpoint import CheckpointError  # noqa: PLC0415
    from lfmbench.baselines.unet import named_unets, parse_named_checkpoints  # noqa: PLC0415
    from lfmbench.evaluation.benchmark import safe_name  # noqa: PLC0415

    try:
        # a --method is registered or module:function: its result file's name is taken too
        paths = parse_named_checkpoints(items, {*REGISTRY, *map(safe_name, methods)}, "--unet")
    except ValueError as exc:
        fail(str(exc))
    nets = named_unets(paths)
    for name, fn in nets.items():
        try:
            fn.torch_module()
        except (CheckpointError, OSError) as exc:
            fail(f"--unet {name}={paths[name]}: {exc}")
    return nets


def _checkpoint_sensor_check(fn):
    """``check_sensor(sensor, captures)`` of a checkpoint-backed method's network (the U-Net), or None: no such
    method, or its weights are missing or unreadable (the evaluation reports that as before)."""
    module = getattr(fn, "torch_module", None)
    if module is None:
        return None
    try:
        return getattr(module(), "check_sensor", None)
    except (OSError, ValueError):
        return None


def leaderboard_cmd(
    runs: list[str] = typer.Argument(..., help="evaluation JSON files, e.g. runs/*.json"),
    sort_by: str = typer.Option("led_score", **choice(METRICS, "METRIC"),
                                help=f"registered metric to rank by: {', '.join(METRICS)} (default: the LED score, "
                                     "docs/guide/metrics.md)"),
    markdown: Path = typer.Option(Path("runs/leaderboard.md"), help="Markdown table output"),
    plot: Path = typer.Option(Path("runs/leaderboard.png"), help="quality-vs-run-time PNG output"),
    json_out: Path = typer.Option(Path("runs/leaderboard.json"), "--json",
                                  help="leaderboard JSON output (rows, CIs, paired tests, breakdown)"),
    conditions: Path = typer.Option(None, "--conditions",
                                    help="condition bins: a YAML path or a shipped name (lfmbench "
                                         "configs conditions; default conditions)"),
    include_incomplete: bool = typer.Option(False, "--include-incomplete",
                                            help="rank interrupted or failed runs too (marked in the table)"),
    cross_sensor: bool = typer.Option(False, "--cross-sensor",
                                      help="rank results of different sensors (architectures) together; each row "
                                           "then names its sensor"),
) -> None:
    """Rank evaluation results; print a table, write Markdown and a quality-vs-run-time plot.

    Runs whose status is not "complete" (interrupted, failed, or killed while "running") are refused unless
    --include-incomplete, which ranks them after the complete ones and marks them. Runs computed on
    different corpora (manifest SHA-256, format version, test draws), with different metric versions, a
    different protocol (split, seed, crop, samples per scene, scoring options) or, without --cross-sensor, different
    sensor presets are refused.
    """
    from lfmbench.evaluation.benchmark import write_leaderboard  # noqa: PLC0415
    from lfmbench.evaluation.leaderboard import (check_comparable, digest_run, incomplete_runs,  # noqa: PLC0415
                                                 leaderboard_rows, load_runs, print_leaderboard)

    skipped: list[str] = []
    paths = [Path(p) for p in runs]  # strings from typer: its Path coercion cost 2 s of CPU for 10,000 files
    try:
        # each file's per-scene work where it is read (a sweep's files in 2 processes)
        loaded = load_runs((p for p in paths if p.suffix == ".json"), skipped, digest=digest_run)
        if skipped:
            typer.echo(f"left out {len(skipped)} leaderboard file(s), not results: {', '.join(skipped[:3])}")
        bad = incomplete_runs(loaded)
        if bad and not include_incomplete:
            raise ValueError(f"{len(bad)} run file(s) are not complete results ({'; '.join(bad[:3])}"
                             f"{' ...' if len(bad) > 3 else ''}); re-run them, leave them out, or pass "
                             "--include-incomplete to rank them marked")
        check_comparable(loaded, cross_sensor)
        rows = leaderboard_rows(loaded, sort_by, conditions_file=conditions)
    except ValueError as exc:
        typer.secho(f"error: {exc}", fg=typer.colors.RED, err=True)
        raise typer.Exit(2) from None
    print_leaderboard(rows, sort_by, note=f"all columns in {markdown}")
    try:
        write_leaderboard(rows, loaded, sort_by, markdown, plot, json_out, conditions)
    except OSError as exc:
        typer.secho(f"error: {exc}", fg=typer.colors.RED, err=True)
        raise typer.Exit(2) from None
    typer.echo(f"wrote {markdown}, {json_out} and {plot}")


def merge_results_cmd(
    shards: list[Path] = typer.Argument(..., help="the shard result files of one evaluation (every INDEX of "
                                                  "`lfmbench evaluate --shard INDEX/COUNT`)"),
    output: Path = typer.Option(..., "--output", "-o", help="merged result JSON"),
) -> None:
    """Join the shard results of one evaluation into the result one run over the whole split writes.

    The shards' sample records are put back in sample order and the aggregates, confidence intervals, per-scene
    values and the breakdown recomputed, so every score equals the one-run file's; the run time is the shard's
    holding the first sample. Refused (nothing written, exit 2): a shard missing or given twice, a sample in two
    shards, a shard not finished, shards of another protocol, method or corpus.
    """
    from lfmbench.evaluation.shards import ShardError, merge_files  # noqa: PLC0415

    check_local_paths([("--output", output)] + [("SHARDS", p) for p in shards])
    try:
        res = merge_files(shards, output)
    except (ShardError, ValueError) as exc:
        fail(str(exc))
    except OSError as exc:
        fail(f"{exc.filename or output}: {exc.strerror or exc}")
    agg = res["aggregate"]
    typer.echo(f"{res['method']['spec']}: {res['shards']['count']} shards, {agg.get('scenes_ok', 0)}/"
               f"{agg.get('scenes', 0)} samples ok, status {res['status']} -> {output}")
    if res["status"] != "complete":
        raise typer.Exit(1)


def _baselines() -> str:
    from lfmbench.baselines import REGISTRY  # noqa: PLC0415 - imports torch: only for the help of evaluate

    return ", ".join(REGISTRY)


def register(app: typer.Typer) -> None:
    """Add the ``evaluate``, ``merge-results`` and ``leaderboard`` commands to the typer ``app``."""
    app.command("evaluate", epilog=f"Baselines: {lazy(_baselines)}. Sensor presets: "
                                   f"{', '.join(installed('sensors'))}.")(evaluate_cmd)
    app.command("merge-results")(merge_results_cmd)
    app.command("leaderboard")(leaderboard_cmd)
