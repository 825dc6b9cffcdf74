"""The ``lfmbench evaluate`` and ``lfmbench leaderboard`` commands (thin wrappers of the library modules).

The library (torch, the dataset) is imported inside the command bodies: the ``lfmbench`` CLI imports this module
to register the commands, and ``lfmbench render`` or ``--help`` must not pay for torch."""
from __future__ import annotations

from pathlib import Path

import typer

from lfmbench.cli._common import check_local_paths, check_minima, fail, torch_setup
from lfmbench.vocabulary import CLASSIC_BASELINES, LEARNED_BASELINES, PLAN_BASELINES

__all__ = ["register", "evaluate_cmd", "leaderboard_cmd"]


def evaluate_cmd(
    method: str = typer.Option(..., "--method", "-m",
                               help=f"a baseline ({', '.join((*CLASSIC_BASELINES, *LEARNED_BASELINES, *PLAN_BASELINES))}) or "
                                    "package.module:function"),
    corpus: Path = typer.Option(..., "--corpus", help="corpus root directory"),
    sensor: str = typer.Option("ovt", "--sensor",
                               help="sensor preset (ovt, imx490, lofic, staggered, chopped, single) or a preset YAML; "
                                    "its name and architecture are recorded in the result"),
    split: str = typer.Option("test", help="corpus split"),
    output: Path = typer.Option(None, "--output", "-o", help="result JSON (default runs/<method>.json)"),
    seed: int = typer.Option(0, help="dataset seed (PWM draws, noise)"),
    max_scenes: int = typer.Option(None, help="evaluate the first N scenes (all their --samples-per-scene draws)"),
    crop: int = typer.Option(None, help="square crop in px passed to the dataset"),
    frames: int = typer.Option(3, help="consecutive frames per sample (e.g. 24 or 100; <= the corpus frames)"),
    samples_per_scene: int = typer.Option(1, help="PWM draws per scene (test draws frozen in the corpus)"),
    repeats: int = typer.Option(5, help="timed calls after warm-up"),
    warmup: int = typer.Option(1, help="untimed warm-up calls"),
    perceptual: bool = typer.Option(True, help="also PU21-PSNR and ColorVideoVDP (needs cvvdp)"),
    device: str = typer.Option("cpu", help="torch device, e.g. cpu or cuda"),
    simulate: str = typer.Option("host", "--simulate",
                                 help="where the captures are simulated: host (the per-sample path, generator noise: "
                                      "the published lfmbench-v1 numbers) or device (the device program on --device, "
                                      "counter noise: the same draws, other noise numbers; ranked apart)"),
    threads: int = typer.Option(None, help="torch CPU threads (default: torch's choice); recorded"),
    cache_dir: Path = typer.Option(None, "--cache-dir",
                                   help="projected-radiance cache directory (default <corpus>/.cache; "
                                        "any writable directory for a read-only corpus)"),
    isp: str = typer.Option("default", "--isp",
                            help="ISP pipeline of the display-referred columns psnr_srgb, ssim_srgb: a shipped name "
                                 "(default, local) or a YAML path; 'none' skips them (docs/guide/isp.md)"),
    shard: str = typer.Option(None, "--shard", metavar="INDEX/COUNT",
                              help="score only shard INDEX of COUNT (scene s goes to shard s mod COUNT; e.g. "
                                   "$SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT or $RANK/$WORLD_SIZE); join the "
                                   "shard files with `lfmbench merge-results` (docs/guide/distributed.md)"),
) -> None:
    """Score a fusion method on a corpus split; write per-scene and aggregate metrics as JSON.

    Exit status: 0 every scene scored, 1 some scenes failed or the data source failed (the result file
    says which), 2 bad input, 130 interrupted (the result file has status "interrupted").
    """
    from lfmbench.datasets.loading import EmptyDataError  # noqa: PLC0415
    from lfmbench.evaluation.benchmark import (SIMULATE, check_simulate, corpus_run_inputs,  # noqa: PLC0415
                                               run_dataset_record, safe_name, samples_to_score, score_batches)
    from lfmbench.evaluation.leaderboard import _fmt  # noqa: PLC0415
    from lfmbench.evaluation.run import DataSourceError, EvaluationInterrupted, evaluate  # noqa: PLC0415

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
    try:
        check_simulate(simulate)
    except ValueError as exc:
        fail(f"--{exc}")
    torch_setup(device, threads)
    out = output or Path("runs") / f"{safe_name(method)}.json"
    from lfmbench.fileio import writable_error  # noqa: PLC0415

    why = writable_error(out)  # an unwritable --output is found before any work is done (the writer's own rule)
    if why is not None:
        fail(f"--output {out}: cannot write the result file there ({why})")
    from lfmbench.baselines import MethodNotFoundError, get_method
    from lfmbench.baselines.checkpoint import CheckpointError
    from lfmbench.isp import load_pipeline
    from lfmbench.metrics import ScoreOptions

    isp_name = None if isp.lower() == "none" else isp
    if isp_name is not None:
        try:
            load_pipeline(isp_name)  # a bad pipeline file is named before any work
        except ValueError as exc:
            fail(f"--isp: {exc}")
    try:
        fn = get_method(method)
        extra = {"frames": frames, "sensor": sensor, "noise_streams": SIMULATE[simulate]}
        if cache_dir is not None:
            extra["cache_dir"] = cache_dir
        ds, ident, cond = corpus_run_inputs(corpus, split, seed, crop, samples_per_scene, **extra)
    except (MethodNotFoundError, FileNotFoundError, EmptyDataError, RuntimeError, ValueError) as exc:
        fail(str(exc))
    from lfmbench.baselines import REGISTRY, methods_for

    if method in REGISTRY and method not in methods_for(ds.architecture):
        fail(f"--method {method} does not apply to --sensor {sensor} ({ds.architecture}); its baselines: "
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
    try:
        res = evaluate(fn, score_batches(ds, n, simulate, device, indices=indices), method_spec=method, output=out,
                       options=ScoreOptions(perceptual=perceptual, isp=isp_name, sensor=ds.preset), warmup=warmup,
                       repeats=repeats, device=device,
                       seeds={"dataset": seed}, dataset=record,
                       total=n if indices is None else len(indices), corpus=ident, scene_conditions=cond)
    except EvaluationInterrupted as exc:
        n_done = len(exc.result["scenes"])
        typer.secho(f"interrupted: {n_done} scene(s) scored; {out} is marked status \"interrupted\" "
                    "(the leaderboard skips it); run the command again for a complete result",
                    fg=typer.colors.YELLOW, err=True)
        raise typer.Exit(130) from None
    except (DataSourceError, EmptyDataError) as exc:
        fail(f"{exc} (partial results in {out})", 1)
    except CheckpointError as exc:  # a hostile or broken weights file: bad input, named
        fail(f"{exc}; nothing was scored")
    except OSError as exc:  # the result file could not be written (disk full, ...)
        fail(f"{exc.filename}: {exc.strerror or exc}" if exc.filename else (exc.strerror or str(exc)))
    agg = res["aggregate"]
    ci = agg.get("ci", {}).get("led_score") or [None, None]
    typer.echo(f"{method}: {agg.get('scenes_ok', 0)}/{agg.get('scenes', 0)} scenes ok, LED score "
               f"{_fmt(agg.get('led_score'))} [{_fmt(ci[0])}, {_fmt(ci[1])}], dropout "
               f"{_fmt(agg.get('dropout_rate'))}, PSNR-mu {_fmt(agg.get('psnr_mu'), 2)} dB, "
               f"{_fmt(res['runtime']['ms_per_megapixel'], 1)} ms/MP -> {out}")
    bad = [sc for sc in res["scenes"] if sc.get("status") != "ok"]
    if bad:
        fail(f"{len(bad)} of {len(res['scenes'])} scenes failed (first: scene {bad[0].get('scene_id')}: "
             f"{bad[0].get('error', bad[0].get('status'))}); see {out}", 1)



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
    runs: list[Path] = typer.Argument(..., help="evaluation JSON files, e.g. runs/*.json"),
    sort_by: str = typer.Option("led_score", help="registered metric to rank by (default: the LED score, "
                                                  "docs/guide/metrics.md)"),
    markdown: Path = typer.Option(Path("runs/leaderboard.md"), help="Markdown table output"),
    plot: Path = typer.Option(Path("runs/leaderboard.png"), help="quality-vs-run-time PNG output"),
    json_out: Path = typer.Option(Path("runs/leaderboard.json"), "--json",
                                  help="leaderboard JSON output (rows, CIs, paired tests, breakdown)"),
    conditions: Path = typer.Option(None, "--conditions",
                                    help="condition bins YAML (default lfmbench/configs/conditions.yaml)"),
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
    from lfmbench.evaluation.leaderboard import (check_comparable, incomplete_runs,  # noqa: PLC0415
                                                 leaderboard_rows, load_runs, print_leaderboard)

    skipped: list[str] = []
    try:
        loaded = load_runs((p for p in runs if p.suffix == ".json"), skipped)
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


def register(app: typer.Typer) -> None:
    """Add the ``evaluate``, ``merge-results`` and ``leaderboard`` commands to the typer ``app``."""
    app.command("evaluate")(evaluate_cmd)
    app.command("merge-results")(merge_results_cmd)
    app.command("leaderboard")(leaderboard_cmd)
