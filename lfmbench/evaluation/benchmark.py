"""Evaluate several methods on one corpus split and write the leaderboard (what ``make demo`` needs)."""
from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from lfmbench.fileio import atomic_write_text


def safe_name(spec: str) -> str:
    """A file name for a method spec (``pkg.mod:fn`` -> ``pkg.mod_fn``)."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", spec).strip("_") or "method"


def corpus_run_inputs(corpus: str | Path, split: str, seed: int, crop: int | None, samples_per_scene: int,
                      reference: str = "own", **dataset_kw):
    """(dataset, corpus identity, scene-conditions reader) of a corpus split; the identity is taken after the
    dataset has frozen the test draws (``test_params.json``), so it covers them. ``reference="common"``: the samples
    also carry ``gt_common`` (the truth of the cross-sensor columns, :data:`lfmbench.metrics.scoring.REFERENCES`;
    made on the host path only)."""
    from lfmbench.metrics.scoring import REFERENCES

    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r:.40}")
    if reference == "common":
        from lfmbench.datasets.options import DEFAULT_OUTPUTS

        if dataset_kw.get("noise_streams", "generator") != SIMULATE["host"]:
            raise ValueError("reference='common' needs simulate='host' (gt_common is made on the per-sample path)")
        dataset_kw["outputs"] = tuple(dict.fromkeys((*dataset_kw.get("outputs", DEFAULT_OUTPUTS), "gt_common")))
    from lfmbench.datasets.loading import make_dataset
    from lfmbench.evaluation.conditions import corpus_scene_conditions
    from lfmbench.evaluation.provenance import corpus_identity

    ds = make_dataset(corpus, split, seed=seed, crop=crop, samples_per_scene=samples_per_scene, **dataset_kw)
    ident = corpus_identity(corpus, list(ds.scene_ids))
    fp = getattr(ds, "draws_fingerprint", None)
    ident["test_draws_sha256"] = fp() if callable(fp) else None  # the draws used, not the whole file
    return ds, ident, corpus_scene_conditions(ds.corpus)


#: Where an evaluation simulates its samples: ``"host"``, the per-sample path on the CPU with the dataset's
#: generator noise (the numbers of every published result); ``"device"``, the device program
#: (:class:`lfmbench.datasets.device.DeviceBatches`) on the evaluation's device with counter-based noise: the same
#: frozen draws, other noise numbers from the same distribution, the same on any device. Results record it
#: (``dataset.noise_streams``), and the leaderboard ranks runs of one noise only.
SIMULATE = {"host": "generator", "device": "counter"}


def check_simulate(simulate: str) -> str:
    """``simulate`` if it is a key of :data:`SIMULATE`, else ValueError naming the choices."""
    if simulate not in SIMULATE:
        raise ValueError(f"simulate must be one of {tuple(SIMULATE)}, got {simulate!r:.40}")
    return simulate


def score_batches(ds, n: int, simulate: str = "host", device: str = "cpu", chunk: int = 16,
                  indices: list[int] | None = None, start: int = 0) -> Iterable[dict]:
    """The first ``n`` samples of ``ds`` (or the samples ``indices``, ascending: a shard,
    :func:`lfmbench.evaluation.shards.shard_samples`) from position ``start`` of that order on (a resumed
    evaluation, :data:`lfmbench.evaluation.run.Batches`) as batches of one, in order: simulated on the host by a
    DataLoader (no workers), or (``simulate="device"``; ``ds`` made with ``noise_streams="counter"``) cut and
    simulated on ``device`` by the device program, its split loaded there once, ``chunk`` samples per program call
    (each sample's numbers do not depend on the others of its call, nor on which samples are scored)."""
    from itertools import islice

    check_simulate(simulate)
    order = (list(range(n)) if indices is None else [int(k) for k in indices])[start:]
    if simulate == "host":
        from torch.utils.data import DataLoader, Subset

        from lfmbench.datasets.loading import collate_samples

        if indices is not None or start:
            return iter(DataLoader(Subset(ds, order), batch_size=1, shuffle=False, num_workers=0,
                                   collate_fn=collate_samples))
        return islice(DataLoader(ds, batch_size=1, shuffle=False, num_workers=0, collate_fn=collate_samples), n)
    if ds.noise_streams != SIMULATE[simulate]:
        raise ValueError(f"simulate='device' needs a dataset with noise_streams='counter', got "
                         f"{ds.noise_streams!r}")
    from lfmbench.datasets.device import DeviceBatches

    from lfmbench.datasets.batched import batch_item

    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"chunk must be an integer >= 1, got {chunk!r:.40}")
    db = DeviceBatches(ds, chunk, device)

    def batches():
        for a in range(0, len(order), chunk):
            part = order[a:a + chunk]
            big = db.batch(part)
            for j in range(len(part)):
                yield batch_item(big, j)

    return batches()


def run_dataset_record(ds, corpus, split: str, n: int, crop, samples_per_scene: int, frames: int) -> dict:
    """The ``dataset`` field of a result: what was scored and how its samples were simulated."""
    return {"corpus": str(corpus), "split": split, "scenes": n, "crop": crop, "samples_per_scene": samples_per_scene,
            "frames": frames, "sensor": ds.sensor_name, "architecture": ds.architecture,
            "noise_streams": ds.noise_streams}


def samples_to_score(ds, max_scenes: int | None) -> int:
    """How many samples of ``ds`` an evaluation scores: all, or those of its first ``max_scenes`` scenes (a
    dataset serves its samples scene by scene, ``samples_per_scene`` each; ``max_scenes`` counts scenes, not
    samples, so every scene scored has all its draws)."""
    n = len(ds)
    return n if max_scenes is None else min(n, int(max_scenes) * int(getattr(ds, "samples_per_scene", 1)))


def write_leaderboard(rows: list[dict], runs: list[dict], sort_by: str | None, markdown: str | Path,
                      plot: str | Path, json_path: str | Path | None = None,
                      conditions_file: str | Path | None = None) -> list[Path]:
    """Write the Markdown table, the quality-vs-run-time plot and (``json_path``) the leaderboard JSON (indented up
    to :data:`~lfmbench.evaluation.leaderboard.rank.STATS_ROWS` rows; a sweep's is written compact, by the C encoder:
    the indented one took 70 % of a 1,000-file leaderboard's output time)."""
    from lfmbench.evaluation.leaderboard.rank import STATS_ROWS
    from lfmbench.evaluation.leaderboard.render import (leaderboard_json, leaderboard_json_text, leaderboard_markdown,
                                                        plot_quality_vs_runtime)
    from lfmbench.evaluation.results import write_json_atomic

    def write_sweep_json() -> None:  # json.dumps of leaderboard_json, per-scene texts spliced in
        atomic_write_text(json_path, leaderboard_json_text(rows, runs, sort_by, conditions_file) + "\n")

    # a sweep's JSON (seconds for 10,000 rows) is written by a forked process while this one writes the rest
    child = _forked(write_sweep_json) if json_path is not None and len(rows) > STATS_ROWS else None
    atomic_write_text(markdown, leaderboard_markdown(rows, sort_by))
    out = [Path(markdown), plot_quality_vs_runtime(rows, plot, sort_by)]
    if json_path is not None:
        if len(rows) <= STATS_ROWS:
            out.append(write_json_atomic(leaderboard_json(rows, runs, sort_by, conditions_file), json_path))
        else:
            child() if child is not None else write_sweep_json()
            out.append(Path(json_path))
    return out


def _forked(fn):
    """Start ``fn()``, the sweep JSON's writer, in a forked process (:func:`lfmbench.parallel.start_forked`)."""
    from lfmbench.parallel import start_forked  # noqa: PLC0415

    return start_forked(fn, "the process writing the leaderboard JSON")


def benchmark(corpus: str | Path, methods: Iterable[str] | None = None, runs_dir: str | Path = "runs",
              split: str = "test", seed: int = 0, crop: int | None = None, max_scenes: int | None = None,
              perceptual: bool = True, repeats: int = 5, device: str = "cpu", sort_by: str | None = None,
              progress: bool = True, samples_per_scene: int = 1, cache_dir: str | Path | None = None,
              frames: int = 3, sensor: Any = "ovt", share_samples: bool = True, isp: str | None = "default",
              simulate: str = "host", reference: str = "own", static_windows: str = "nearest",
              resume: bool = True) -> list[dict]:
    """Evaluate several methods on one corpus split and build the leaderboard.

    Writes ``runs_dir/<method>.json`` per method, ``runs_dir/leaderboard.md``, ``leaderboard.json`` and
    ``leaderboard.png``, prints the table and returns the ranked rows (default ranking: the LED score).
    ``methods`` defaults to every registered baseline of the sensor's architecture (``sensor``: a preset name,
    YAML or an already-resolved :class:`lfmbench.sensor.SensorPreset`, :func:`lfmbench.baselines.methods_for`). ``cache_dir``: the dataset's projection cache (default
    ``<corpus>/.cache``; any writable directory for a read-only corpus). ``frames``: consecutive frames per
    sample, as ``lfmbench evaluate --frames`` (24 or more for the IEEE P2020 flicker metrics; <= the corpus's).
    ``share_samples`` (default): every sample is simulated once and scored for all methods
    (:func:`lfmbench.evaluation.run.evaluate_methods`, one sample in memory at a time; the scores equal those of
    one pass per method, docs/benchmarks/evaluation-sharing.md); False: one pass over the data per method (the
    path before sharing, kept for comparison). ``isp``: the ISP pipeline (name or YAML path) of the
    display-referred secondary columns, None for none (docs/guide/isp.md). ``max_scenes``: score only the first N scenes
    of the split, each with all its ``samples_per_scene`` draws (:func:`samples_to_score`). ``simulate``:
    ``"host"`` (the published results' generator noise) or ``"device"`` (the device program on ``device``, counter
    noise; :data:`SIMULATE`). ``reference``: ``"own"`` (every column against the sensor's own ``gt``) or
    ``"common"`` (the cross-sensor columns against ``gt_common``, the one truth of every sensor;
    :data:`lfmbench.metrics.scoring.REFERENCES`; host only). ``static_windows``: how a capture window the corpus
    does not store for its static groups is served (:class:`~lfmbench.datasets.LFMCaptureDataset`): ``"nearest"``
    (the named approximation) or ``"exact"`` (such a sensor is refused before any work; a published comparison).
    ``resume`` (default): a ``runs_dir/<method>.json`` of this evaluation that a killed run left is continued (only
    its missing samples are simulated and scored), a complete one is kept and its method skipped, another
    evaluation's is refused (:class:`lfmbench.evaluation.run.ResumeError`); False: every method scored again.
    """
    from lfmbench.baselines import methods_for
    from lfmbench.evaluation.leaderboard import check_comparable, leaderboard_rows, load_runs, print_leaderboard
    from lfmbench.evaluation.run import evaluate, evaluate_methods
    from lfmbench.metrics import ScoreOptions

    runs_dir = Path(runs_dir)
    extra = {"frames": frames, "sensor": sensor, "noise_streams": SIMULATE[check_simulate(simulate)],
             "static_windows": static_windows}
    if cache_dir is not None:
        extra["cache_dir"] = cache_dir
    ds, ident, cond = corpus_run_inputs(corpus, split, seed, crop, samples_per_scene, reference, **extra)
    n = samples_to_score(ds, max_scenes)
    names = list(methods) if methods is not None else methods_for(ds.architecture)
    paths = [runs_dir / f"{safe_name(m)}.json" for m in names]
    common = dict(options=ScoreOptions(perceptual=perceptual, isp=isp, sensor=ds.preset, reference=reference),
                  repeats=repeats,
                  device=device, seeds={"dataset": seed},
                  dataset=run_dataset_record(ds, corpus, split, n, crop, samples_per_scene, frames),
                  progress=progress, total=n, corpus=ident, scene_conditions=cond, resume=resume)

    def loader(start: int = 0):
        return score_batches(ds, n, simulate, device, start=start)

    if share_samples:
        evaluate_methods(names, loader, method_specs=names, outputs=paths, **common)
    else:
        for m, out in zip(names, paths):
            evaluate(m, loader, method_spec=m, output=out, **common)
    runs = load_runs(paths)
    check_comparable(runs)
    rows = leaderboard_rows(runs, sort_by)
    write_leaderboard(rows, runs, sort_by, runs_dir / "leaderboard.md", runs_dir / "leaderboard.png",
                      runs_dir / "leaderboard.json")
    print_leaderboard(rows, sort_by, note=f"all columns in {runs_dir / 'leaderboard.md'}")
    return rows


def benchmark_sensors(corpus: str | Path, sensors: Mapping[str, Iterable[str] | None], runs_dir: str | Path = "runs",
                      *, checkpoints: Mapping[str, Mapping[str, str | Path]] | None = None,
                      sort_by: str | None = None, conditions_file: str | Path | None = None,
                      progress: bool = True, **kw) -> list[dict]:
    """The cross-sensor benchmark (``lfmbench leaderboard --cross-sensor`` as one call): :func:`benchmark` of every
    sensor (its methods share each simulated sample) into ``runs_dir/<sensor>/``, then one leaderboard of all
    their runs, sensors mixed on purpose, in ``runs_dir/leaderboard.{md,json,png}``. The full-image and ghost
    columns of every sensor are scored against one truth, ``gt_common`` (``reference="common"``,
    :data:`lfmbench.metrics.scoring.CROSS_SENSOR_GROUPS`); the LED columns against each sensor's own ``gt``; the
    condition bins from each sensor's own windows (``pwm_miss_prob``).

    Args:
        sensors: preset name (or YAML) -> its methods (None: every registered baseline of its architecture,
            :func:`lfmbench.baselines.methods_for`).
        checkpoints: preset -> {learned method: checkpoint file} for that sensor's runs (a U-Net is trained per
            sensor; each file's environment variable is set for that sensor only, then restored).
        kw: the other arguments of :func:`benchmark` (split, seed, samples_per_scene, perceptual, repeats, isp ...),
            the same for every sensor (not ``reference``: always ``"common"``).

    Returns:
        the ranked rows of the cross-sensor leaderboard.
    """
    import importlib
    import os

    from lfmbench.baselines import LEARNED, methods_for
    from lfmbench.evaluation.leaderboard import check_comparable, leaderboard_rows, load_runs, print_leaderboard
    from lfmbench.sensor import resolve

    runs_dir = Path(runs_dir)
    checkpoints = checkpoints or {}
    unknown = sorted(set(checkpoints) - set(sensors))
    if unknown:
        raise ValueError(f"checkpoints: sensors {unknown} are not among the sensors {list(sensors)}")
    envs: dict[str, dict[str, str]] = {}
    for sensor, given in checkpoints.items():           # every argument checked before any work
        for method, path in given.items():
            if method not in LEARNED:
                raise ValueError(f"checkpoints[{sensor!r}]: {method!r} is not a learned baseline ({', '.join(LEARNED)})")
            if not Path(path).is_file():
                raise ValueError(f"checkpoints[{sensor!r}][{method!r}]: no such file {path}")
            env = importlib.import_module(LEARNED[method]).TRAINING.checkpoint_env
            envs.setdefault(sensor, {})[env] = str(path)
    paths: list[Path] = []
    for sensor, methods in sensors.items():
        env = envs.get(sensor, {})
        before = {k: os.environ.get(k) for k in env}
        os.environ.update(env)
        try:
            preset = resolve(sensor)       # once per sensor: the object travels into the dataset and metrics
            names = list(methods) if methods is not None else methods_for(preset.architecture)
            sub = runs_dir / safe_name(sensor)
            benchmark(corpus, names, sub, sensor=preset, sort_by=sort_by, progress=progress, reference="common",
                      **kw)
        finally:
            for k, v in before.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        paths += [sub / f"{safe_name(m)}.json" for m in names]
    runs = load_runs(paths)
    check_comparable(runs, cross_sensor=True)
    rows = leaderboard_rows(runs, sort_by, conditions_file=conditions_file)
    write_leaderboard(rows, runs, sort_by, runs_dir / "leaderboard.md", runs_dir / "leaderboard.png",
                      runs_dir / "leaderboard.json", conditions_file)
    print_leaderboard(rows, sort_by, note=f"all columns in {runs_dir / 'leaderboard.md'}")
    return rows
