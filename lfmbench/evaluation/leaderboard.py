"""The leaderboard: rank evaluation results, with confidence intervals, paired tests and a breakdown by condition.

- :func:`load_runs` reads result files; :func:`check_comparable` refuses results computed on different corpora,
  with different metric versions or a different protocol (split, seed, crop, samples per scene, scoring
  options), naming the files and how they differ.
- :func:`leaderboard_rows` ranks them by one registered metric (default :data:`lfmbench.metrics.PRIMARY`, the
  LED score): per-scene values from each result's sample records, bootstrap CIs over scenes, each method
  against the best (Wilcoxon signed-rank, Holm-adjusted), the Pareto front of LED score against PSNR-mu
  outside the LED regions, and the breakdown by condition.
- :func:`leaderboard_markdown`, :func:`leaderboard_json`, :func:`print_leaderboard`,
  :func:`plot_quality_vs_runtime` present them. Columns, headers and directions come from the metric registry.
"""
from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from lfmbench.limits import brief
from lfmbench.evaluation import stats
from lfmbench.evaluation.conditions import bin_labels, load_bins
from lfmbench.evaluation.results import (COMPLETE, RESULT_FORMAT, breakdown, jsonable, metric_summary, num,
                                         per_scene, scene_means)
from lfmbench.fileio import atomic_save_figure, load_json_input

LEADERBOARD_FORMAT = "lfmbench-leaderboard"
LEADERBOARD_VERSION = 1
#: The two axes of the Pareto front: the lights, and the rest of the image.
PARETO_AXES = ("led_score", "psnr_mu_outside")


class IncomparableRunsError(ValueError):
    """Result files computed on different corpora, metric versions or protocols."""


def load_runs(paths: Iterable[str | Path], skipped: list[str] | None = None) -> list[dict]:
    """Read evaluation JSON files; raise ValueError naming a file that is not an lfmbench result.

    A leaderboard file this module wrote (format :data:`LEADERBOARD_FORMAT`, e.g. ``runs/leaderboard.json`` caught
    by ``runs/*.json``) is not a result: it is left out and its path appended to ``skipped`` (if given)."""
    runs = []
    for p in paths:
        p = Path(p)
        d = load_json_input(p, "run file")
        if isinstance(d, dict) and d.get("format") == LEADERBOARD_FORMAT:
            if skipped is not None:
                skipped.append(str(p))
            continue
        if not isinstance(d, dict) or d.get("format") != RESULT_FORMAT:
            fmt = d.get("format") if isinstance(d, dict) else None
            raise ValueError(f"run file {p}: not an {RESULT_FORMAT} result (format={brief(fmt)})")
        for key, typ in (("method", dict), ("runtime", dict), ("aggregate", dict), ("status", str)):
            if not isinstance(d.get(key), typ):
                raise ValueError(f"run file {p}: field {brief(key)} missing or not a{'n object' if typ is dict else ' string'}"
                                 " (a truncated or hand-made result?)")
        if not isinstance(d["method"].get("spec"), str):
            raise ValueError(f"run file {p}: field 'method.spec' missing")
        _check_numbers(d, p)
        d["_path"] = str(p)
        runs.append(d)
    if not runs:
        raise ValueError("no run files given")
    return runs


def _check_numbers(d: dict, p: Path) -> None:
    """Every number the leaderboard ranks or averages must be finite and within its metric's documented range
    (:meth:`lfmbench.metrics.MetricSpec.value_error`); ``ValueError`` naming the file and the field otherwise
    (a score of ``1e308`` or ``-3`` is not a result, whatever produced it)."""
    from lfmbench.metrics import REGISTRY

    def check(v: Any, field: str) -> None:
        name = field.rsplit(".", 1)[-1]
        spec = REGISTRY[name] if name in REGISTRY else None
        why = spec.value_error(v) if spec is not None else None
        if why is not None:
            raise ValueError(f"run file {p}: field {field} = {brief(v)} {why}")

    def weight(v: Any, field: str) -> None:
        if v is None or v == "nan":
            return
        ok = isinstance(v, (int, float)) and not isinstance(v, bool)
        try:
            ok = ok and math.isfinite(float(v)) and float(v) >= 0
        except OverflowError:
            ok = False
        if not ok:
            raise ValueError(f"run file {p}: field {field} = {brief(v)} must be a finite number >= 0")

    recs = d.get("scenes", [])
    if not isinstance(recs, list):
        raise ValueError(f"run file {p}: field 'scenes' must be a list of sample records")
    weights = {s.weight for s in REGISTRY.values() if s.weight}
    fast = {**{n: s.valid for n, s in REGISTRY.items()}, **{w: (0.0, math.inf) for w in weights}}
    for i, rec in enumerate(recs):
        if not isinstance(rec, dict):
            raise ValueError(f"run file {p}: field scenes[{i}] must be an object")
        m = rec.get("metrics")
        if m is None:
            continue
        if not isinstance(m, dict):
            raise ValueError(f"run file {p}: field scenes[{i}].metrics must be an object")
        for k, v in m.items():
            r = fast.get(k)  # a finite float inside the metric's range: valid, without the general checks
            if r is not None and type(v) is float and r[0] <= v <= r[1] and v - v == 0.0:
                continue
            (weight if k in weights else check)(v, f"scenes[{i}].metrics.{k}")
        weight(rec.get("call_ms"), f"scenes[{i}].call_ms")
    for k, v in d["aggregate"].items():
        if k in REGISTRY:
            check(v, f"aggregate.{k}")
    weight(d["runtime"].get("ms_per_megapixel"), "runtime.ms_per_megapixel")


def incomplete_runs(runs: list[dict]) -> list[str]:
    """``"<path>: status <status>"`` for each run that is not complete (interrupted, failed, killed), and
    ``"<path>: shard i/n"`` for a shard of a split (``lfmbench evaluate --shard``: join the shards with
    ``lfmbench merge-results`` first; a shard ranked alone would score a part of the split as the whole)."""
    out = []
    for r in runs:
        sh = (r.get("dataset") or {}).get("shard") if isinstance(r.get("dataset"), dict) else None
        if r.get("status") != COMPLETE:
            out.append(f"{r.get('_path')}: status {brief(r.get('status'))}")
        elif sh is not None:
            out.append(f"{r.get('_path')}: shard {brief(sh.get('index') if isinstance(sh, dict) else sh)}/"
                       f"{brief(sh.get('count') if isinstance(sh, dict) else '?')} of a split (join the shards with "
                       "`lfmbench merge-results`)")
    return out


# ------------------------------------------------------------------------------------------- comparability
def identity(run: dict) -> dict[str, Any]:
    """What must agree between results ranked together: corpus (the scored scenes' files, or the manifest SHA-256
    in result files that do not record them; format version, frozen test draws), metric versions, split, dataset
    seed, crop, samples per scene, frames per sample (3, the dataset's default, in files that do not record it),
    scoring options, the sensor preset (its capture plan: :func:`run_sensor`), the sensor noise's streams
    (``generator``, the host simulation of every published result, in files that do not record it; ``counter``,
    ``lfmbench evaluate --simulate device``) and the display ISP (pipeline and
    secondary metric versions; compared only among the runs that scored display-referred columns)."""
    from lfmbench.metrics import REGISTRY, SECONDARY_GROUPS

    c = run.get("corpus") or {}
    d = run.get("dataset") or {}
    split = d.get("split")
    mv = (run.get("versions") or {}).get("metrics")
    if isinstance(mv, dict):  # secondary metrics (added after a protocol was published) are compared on their own
        mv = {k: v for k, v in mv.items() if k not in REGISTRY or REGISTRY[k].group not in SECONDARY_GROUPS}
    opts = run.get("options") or {}
    return {
        "corpus scenes sha256": (f"scenes {c['scenes_sha256']}" if c.get("scenes_sha256")
                                 else f"manifest {c['manifest_sha256']}" if c.get("manifest_sha256") else None),
        "corpus format version": c.get("format_version"),
        "corpus test draws sha256": _draws(c) if split == "test" else None,
        "metric versions": mv,
        "split": split, "dataset seed": (run.get("seeds") or {}).get("dataset"), "crop": d.get("crop"),
        "samples per scene": d.get("samples_per_scene", 1), "frames per sample": d.get("frames", 3),
        "scoring options": {k: v for k, v in opts.items() if k not in ("perceptual", "isp")},
        "sensor": run_sensor(run),
        "sensor noise": d.get("noise_streams", "generator"),
        "display ISP": _display_identity(run),
    }


def run_sensor(run: dict) -> str:
    """The sensor preset a result was simulated with (``dataset.sensor``; ``ovt``, the only one before issue 22, in
    files that do not record it)."""
    return str((run.get("dataset") or {}).get("sensor", "ovt"))


#: Fields of :func:`identity` compared only among the runs that record them: a result written before the
#: secondary columns existed has none (an empty cell in the table), which is no conflict.
_OPTIONAL_FIELDS = ("display ISP",)


def _display_identity(run: dict) -> dict | None:
    """The ISP pipeline and the secondary metrics' versions of a run that scored display-referred metrics, else
    None."""
    from lfmbench.metrics import REGISTRY, SECONDARY_GROUPS

    isp = (run.get("options") or {}).get("isp")
    if isp is None:
        return None
    mv = (run.get("versions") or {}).get("metrics") or {}
    sec = {k: v for k, v in mv.items() if k in REGISTRY and REGISTRY[k].group in SECONDARY_GROUPS} \
        if isinstance(mv, dict) else {}
    return {"pipeline": isp, "metric versions": sec}


def _draws(c: dict) -> str | None:
    """The test draws a result used: the fingerprint of the scored samples' frozen entries (results since issue
    27: unchanged when ``test_params.json`` gains entries for other scenes or samples), else the SHA-256 of the
    whole file (older results)."""
    if c.get("test_draws_sha256"):
        return f"draws {c['test_draws_sha256']}"
    return f"test_params.json {c['test_params_sha256']}" if c.get("test_params_sha256") else None


def _show(field: str, v: Any, run: dict) -> str:
    if v is None:
        return "none (not evaluated on a corpus, or a result file older than format version 2)" \
            if field.startswith("corpus scenes") else "none"
    if field == "corpus scenes sha256":  # "scenes <sha>" (the scored scenes' files) or "manifest <sha>" (older)
        kind, sha = v.split(" ", 1)
        return f"{kind} {sha[:12]}... (corpus {(run.get('corpus') or {}).get('path')})"
    return json.dumps(v, sort_keys=True) if isinstance(v, (dict, list)) else str(v)


def _names(paths: list[str], k: int = 3) -> str:
    return ", ".join(Path(p).name if len({Path(q).name for q in paths}) == len(paths) else p for p in paths[:k]) + \
        (f" (+{len(paths) - k} more)" if len(paths) > k else "")


def comparability_problems(runs: list[dict], cross_sensor: bool = False) -> list[str]:
    """One line per field on which the runs differ, naming the files of each value (empty: comparable).
    ``cross_sensor``: results of different sensors (architectures) may be ranked together (a cross-architecture
    comparison; everything else must still agree)."""
    ids = [identity(r) for r in runs]
    problems = []
    for field in ids[0]:
        if cross_sensor and field == "sensor":
            continue
        vals = [i[field] for i in ids]
        if field in _OPTIONAL_FIELDS:
            present = [v for v in vals if v is not None]
            if all(v == present[0] for v in present):
                continue
        elif all(v == vals[0] for v in vals):
            continue
        if field == "metric versions":
            names = sorted(set().union(*[set(v or {}) for v in vals]))
            diff = []
            for n in names:
                per = [(v or {}).get(n) for v in vals]
                if any(x != per[0] for x in per):
                    groups: dict[str, list[str]] = {}
                    for r, x in zip(runs, per):
                        groups.setdefault(x if x is not None else "missing", []).append(r["_path"])
                    diff.append(f"{n}: " + "; ".join(f"{x} in {_names(p)}" for x, p in groups.items()))
            problems.append("metric versions differ (" + " | ".join(diff[:4]) + (" | ..." if len(diff) > 4 else "")
                            + ")")
            continue
        groups2: dict[str, list[str]] = {}
        for r, v in zip(runs, vals):
            groups2.setdefault(_show(field, v, r), []).append(r["_path"])
        problems.append(f"{field} differs: " + "; ".join(f"{k} in {_names(p)}" for k, p in groups2.items()))
    if cross_sensor and len({run_sensor(r) for r in runs}) > 1:
        own = [r["_path"] for r in runs if run_reference(r) != "common"]
        if own:  # each scored against its own reference exposure: the cross-sensor columns would not compare
            problems.append(f"scored against their own sensor's gt, not the common reference: {_names(own)} "
                            "(rank sensors together on results of `lfmbench evaluate --reference common` or "
                            "lfmbench.evaluation.benchmark.benchmark_sensors)")
    return problems


def run_reference(run: dict) -> str:
    """What a result's cross-sensor columns were scored against: ``options.reference`` (result version 3), ``"own"``
    in files that do not record it (:data:`lfmbench.metrics.scoring.REFERENCES`)."""
    return str((run.get("options") or {}).get("reference", "own"))


def check_comparable(runs: list[dict], cross_sensor: bool = False) -> None:
    """Raise :class:`IncomparableRunsError` (one message, one clause per differing field) unless every run was
    computed on the same corpus, with the same metric versions, protocol and sensor (``cross_sensor``: sensors may
    differ, for a cross-architecture comparison)."""
    problems = comparability_problems(runs, cross_sensor)
    if problems:
        hint = "" if cross_sensor or not any(p.startswith("sensor differs") for p in problems) else \
            " (to compare sensor architectures on purpose: lfmbench leaderboard --cross-sensor)"
        raise IncomparableRunsError("these results cannot be ranked together: " + "; ".join(problems)
                                    + ". Re-evaluate every method on one corpus with one lfmbench version, or rank "
                                      "the groups separately" + hint)


# --------------------------------------------------------------------------------------------------- ranking
def _check_sort_by(sort_by: str) -> Any:
    from lfmbench.metrics import REGISTRY

    if sort_by not in REGISTRY:
        raise ValueError(f"sort_by must be a registered metric ({', '.join(REGISTRY)}), got {brief(sort_by)}")
    return REGISTRY[sort_by]


def _pareto(rows: list[dict], axes: tuple[str, str]) -> None:
    """Mark ``row["pareto"]``: no other complete row is at least as good on both axes and better on one (None for
    an incomplete row or one without both values).

    O(n log n) (it was pairwise, O(n^2): 33 s of a 2,000-file leaderboard): the points (both axes oriented so that
    larger is better) sorted by the first axis, best first, and swept in groups of equal first value; a point is
    dominated exactly when a point of a strictly better group is at least as good on the second axis, or a point
    of its own group is strictly better on it (equal points do not dominate each other).
    """
    from lfmbench.metrics import REGISTRY

    sign = [1.0 if REGISTRY[a].higher_is_better else -1.0 for a in axes]
    pts = []
    for r in rows:
        x, y = (s * num(r.get(a, float("nan"))) for s, a in zip(sign, axes))
        if r["status"] != COMPLETE or math.isnan(x) or math.isnan(y):
            r["pareto"] = None
        else:
            pts.append((x, y, r))
    pts.sort(key=lambda p: -p[0])
    best_before = None  # the best second value among strictly better first values (None: no such point)
    i = 0
    while i < len(pts):
        j = i
        while j < len(pts) and pts[j][0] == pts[i][0]:
            j += 1
        group_best = max(p[1] for p in pts[i:j])
        for x, y, r in pts[i:j]:
            r["pareto"] = not ((best_before is not None and best_before >= y) or group_best > y)
        best_before = group_best if best_before is None else max(best_before, group_best)
        i = j


def _pareto_pairwise(rows: list[dict], axes: tuple[str, str]) -> dict[int, bool | None]:
    """The definition of :func:`_pareto`, pairwise (O(n^2)): ``{id(row): on the front}`` (tests compare them)."""
    from lfmbench.metrics import REGISTRY

    sign = [1.0 if REGISTRY[a].higher_is_better else -1.0 for a in axes]

    def pt(r):
        return [s * num(r.get(a, float("nan"))) for s, a in zip(sign, axes)]

    out: dict[int, bool | None] = {}
    for r in rows:
        p = pt(r)
        if r["status"] != COMPLETE or any(math.isnan(x) for x in p):
            out[id(r)] = None
            continue
        out[id(r)] = not any(
            o is not r and o["status"] == COMPLETE and all(a >= b for a, b in zip(pt(o), p))
            and any(a > b for a, b in zip(pt(o), p)) for o in rows if not any(math.isnan(x) for x in pt(o)))
    return out


#: Rows (best first) the quality-vs-run-time plot shows with their own marker, CI bar and legend entry; the others
#: are small grey points (a sweep's 10,000 legend entries took minutes to draw and could not be read).
PLOT_LABELLED = 20
#: Rows (best first) that get the bootstrap statistics (CIs, breakdown with CIs, the paired test against the
#: best); a sweep of 10,000 results gets them for its best rows only (about 35 bootstraps of 10,000 resamples per
#: row: seconds per row on 2 cores), every row its values, rank and Pareto flag. Leaderboards of up to this many
#: results are computed exactly as before.
STATS_ROWS = 50
#: Rows (best first) the console table shows; a line counts the others (every row is in the Markdown and JSON
#: files). Drawing a sweep's 10,000 rows with rich took about half of a 10,000-file leaderboard's time.
PRINT_ROWS = 50


def leaderboard_rows(runs: list[dict], sort_by: str | None = None, *, ci: bool = True,
                     conditions_file: str | Path | None = None, stats_rows: int | None = None) -> list[dict]:
    """One row per run, ranked by ``sort_by`` (default the LED score; direction from the metric registry; missing
    values and incomplete runs last), with statistics.

    Every row holds each registered metric's value over scenes (recomputed from the run's sample records),
    ``ci`` (metric -> [low, high], bootstrap over scenes, for the table metrics and ``sort_by``),
    ``n_scenes``, ``vs_best`` (the paired comparison with rank 1 on ``sort_by``: ``n``, ``mean_diff``, ``ci``,
    ``p`` (Wilcoxon), ``p_holm``; None for rank 1), ``pareto`` (on the front of :data:`PARETO_AXES`) and
    ``breakdown`` (``sort_by`` by condition). The bootstrap statistics (``ci``, the breakdown's CIs,
    ``vs_best``; Holm over the rows compared) and the breakdown by condition are computed for the first
    ``stats_rows`` rows of the ranking (default :data:`STATS_ROWS`; below them ``ci`` and ``breakdown`` are
    empty, ``vs_best`` None and ``stats`` False).
    """
    from lfmbench.metrics import PRIMARY, REGISTRY, columns

    sort_by = sort_by or PRIMARY
    spec = _check_sort_by(sort_by)
    known = [r for r in runs if isinstance((r.get("versions") or {}).get("metrics"), dict)]
    if known and not any(sort_by in r["versions"]["metrics"] for r in known):
        raise ValueError(f"no run file was scored with {brief(sort_by)} ({_names([r['_path'] for r in known])}: made by "
                         f"an older lfmbench?); re-run lfmbench evaluate, or rank with --sort-by psnr_mu")
    bins = load_bins(conditions_file)
    want_ci = {s.name for s in columns("table")} | {sort_by}
    rows = []
    several = len({run_sensor(r) for r in runs}) > 1   # a cross-sensor ranking names each row's sensor
    for r in runs:
        agg = r.get("aggregate", {})
        records = r.get("scenes") if isinstance(r.get("scenes"), list) else []
        scenes = per_scene(records)
        name = r["method"]["spec"] + (f" @ {run_sensor(r)}" if several else "")
        row = {"method": name, "sensor": run_sensor(r),
               "architecture": (r.get("dataset") or {}).get("architecture", "split_pixel"), "path": r.get("_path"), "device": r["runtime"].get("device"),
               "ms_per_megapixel": num(r["runtime"].get("ms_per_megapixel")),
               "ms_iqr": _pair(r["runtime"].get("iqr_ms_per_megapixel")),
               "time_moved": r["runtime"].get("time_moved") is True, "threads": r["runtime"].get("threads"),
               "params": r["method"].get("params"), "macs_per_megapixel": r["method"].get("macs_per_megapixel"),
               "scenes": agg.get("scenes", 0), "failed": agg.get("scenes_failed", 0), "status": r.get("status"),
               "checkpoint_sha256": _checkpoint_sha(r),
               "n_scenes": len(scenes), "ci": {}, "_scenes": scenes}
        means = scene_means(scenes)  # metric_summary(scenes, k, ci=False)["value"] of each metric, one pass
        for k in REGISTRY:
            # a metric no scene holds (a hand-made or truncated result without sample records): its stored aggregate
            row[k] = means[k] if k in means else num(agg.get(k))
        row["_records"] = records
        rows.append(row)

    def key(row):
        v = row[sort_by]
        if math.isnan(v):
            return (1, 0.0)
        return (0, -v if spec.higher_is_better else v)

    _flag_moved_times(rows)
    rows.sort(key=lambda row: (row["status"] != COMPLETE, *key(row)))  # incomplete runs after complete ones
    n_stats = STATS_ROWS if stats_rows is None else stats_rows
    jobs = []
    for i, row in enumerate(rows):
        row["rank"] = i + 1
        row["stats"] = i < n_stats
        records = row.pop("_records")
        if row["stats"]:
            ks = [k for k in REGISTRY if k in want_ci] if ci else []
            jobs.append((row, (row["_scenes"], records, ks, sort_by, bins, ci)))
        else:
            row["breakdown"] = {}
    for (row, _), (cis, bd) in zip(jobs, _map_stats(_row_stats, [a for _, a in jobs])):
        row["ci"].update(cis)
        row["breakdown"] = bd
    _compare_with_best(rows, sort_by)
    if all(a in REGISTRY for a in PARETO_AXES):
        _pareto(rows, PARETO_AXES)
    return rows


def _row_stats(args: tuple) -> tuple[dict, dict]:
    """The bootstrap statistics of one row: ``(ci, breakdown)``; the bootstrap CIs are the same calls as the
    values' (:func:`~lfmbench.evaluation.results.metric_summary` with ``ci``), each seeded on its own."""
    scenes, records, ks, sort_by, bins, ci = args
    cis = {k: metric_summary(scenes, k, ci=True)["ci"] for k in ks
           if scenes and any(k in s["metrics"] for s in scenes)}
    return cis, (breakdown(records, sort_by, bins, ci=ci) if records else {})


#: Stats rows from which :func:`leaderboard_rows` computes them in two processes (each bootstrap is seeded on its
#: own, so the numbers are those of one process; a sweep's 50 rows took 8 of 35 s on one core).
PARALLEL_STATS_ROWS = 8


def can_fork() -> bool:
    """Whether the leaderboard's outputs may use forked processes: ``fork`` exists and 2 or more CPUs are usable."""
    import multiprocessing
    import os

    ncpu = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return ncpu >= 2 and "fork" in multiprocessing.get_all_start_methods()


def _map_stats(fn, items: list) -> list:
    """``[fn(x) for x in items]``, in a forked pool of 2 processes when there are :data:`PARALLEL_STATS_ROWS` or
    more items and :func:`can_fork` (in order; any failure of the pool falls back to one process)."""
    import multiprocessing

    if len(items) < PARALLEL_STATS_ROWS or not can_fork():
        return [fn(x) for x in items]
    try:
        with multiprocessing.get_context("fork").Pool(2) as pool:
            return pool.map(fn, items, chunksize=1)
    except (OSError, RuntimeError):   # no process could be started (limits, sandbox): one process
        return [fn(x) for x in items]


def _checkpoint_sha(run: dict) -> str | None:
    """The content SHA-256 of the weights a run's method used (``method.checkpoint``, recorded by the evaluation
    for checkpoint-backed methods), or None."""
    ck = run["method"].get("checkpoint")
    sha = ck.get("content_sha256") if isinstance(ck, dict) else None
    return sha if isinstance(sha, str) else None
#: Fewer scenes than this in the ranked runs and the leaderboard says its intervals and tests are not to be trusted
#: (a bootstrap over 1 scene has no interval, over a few an interval far too narrow; Wilcoxon's exact test
#: cannot reach p < 0.05 below 6 paired scenes).
MIN_SCENES_FOR_CI = 6


def _pair(v: Any) -> list[float] | None:
    """A stored ``[low, high]`` as two floats, or None (a result file written before it was recorded)."""
    if isinstance(v, (list, tuple)) and len(v) == 2:
        lo, hi = num(v[0]), num(v[1])
        if math.isfinite(lo) and math.isfinite(hi):
            return [lo, hi]
    return None


def _flag_moved_times(rows: list[dict]) -> None:
    """``time_moved`` of rows whose run time cannot be trusted: moved during its own run (``runtime.time_moved``),
    or one method ranked twice (two result files) with run times outside each other's range widened by
    :data:`lfmbench.evaluation.cost.TIME_MOVED_FACTOR` (the interquartile range, or the median alone for an
    older file)."""
    from lfmbench.evaluation.cost import TIME_MOVED_FACTOR as F

    by_method: dict[str, list[dict]] = {}
    for r in rows:
        by_method.setdefault(r["method"], []).append(r)
    for same in by_method.values():
        for a in same:
            for b in same:
                if a is b or math.isnan(a["ms_per_megapixel"]) or math.isnan(b["ms_per_megapixel"]):
                    continue
                lo, hi = b["ms_iqr"] or [b["ms_per_megapixel"]] * 2
                if not lo / F <= a["ms_per_megapixel"] <= hi * F:
                    a["time_moved"] = b["time_moved"] = True


def few_scenes(rows: list[dict]) -> str | None:
    """A warning when a ranked run has fewer than :data:`MIN_SCENES_FOR_CI` scenes (None otherwise)."""
    n = min((r["n_scenes"] for r in rows), default=0)
    if not rows or n >= MIN_SCENES_FOR_CI:
        return None
    return (f"warning: n = {n} scene(s) per method; confidence intervals and paired tests need at least "
            f"{MIN_SCENES_FOR_CI} scenes (a test split of more scenes: render more, e.g. a protocol)")


def _ms(row: dict) -> str:
    """The run-time cell: median ms/MP, its interquartile range, ``!`` when the time moved."""
    iqr = row.get("ms_iqr")
    return (_fmt(row["ms_per_megapixel"], 1) + (f" [{_fmt(iqr[0], 1)}, {_fmt(iqr[1], 1)}]" if iqr else "")
            + (" !" if row.get("time_moved") else ""))


def _compare_with_best(rows: list[dict], sort_by: str) -> None:
    """``vs_best`` of every row: paired over the scenes both the row and rank 1 scored."""
    for r in rows:
        r["vs_best"] = None
    if not rows or rows[0]["status"] != COMPLETE or math.isnan(rows[0][sort_by]):
        return
    best = {s["scene_id"]: num(s["metrics"].get(sort_by)) for s in rows[0]["_scenes"]}
    tested = []
    for r in rows[1:]:
        if not r.get("stats", True):
            continue
        mine = {s["scene_id"]: num(s["metrics"].get(sort_by)) for s in r["_scenes"]}
        common = [k for k in mine if k in best]
        if not common:
            continue
        r["vs_best"] = stats.paired_test([mine[k] for k in common], [best[k] for k in common])
        tested.append(r)
    for r, p in zip(tested, stats.holm([r["vs_best"]["p"] for r in tested])):
        r["vs_best"]["p_holm"] = p


# ------------------------------------------------------------------------------------------------ formatting
def _status_mark(row: dict) -> str:
    """`` (interrupted)`` etc. after the method name of a run whose status is not ``complete``."""
    return "" if row.get("status") == COMPLETE else f" ({row.get('status')}: not a complete result)"


def _fmt(v: Any, nd: int = 3) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    v = float(v)
    if math.isnan(v):
        return "-"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{nd}f}" if abs(v) < 1e4 else f"{v:.3g}"


def _ci(ci: list | None, nd: int) -> str:
    if not ci or any(math.isnan(num(x)) for x in ci):
        return "-"
    return f"[{_fmt(ci[0], nd)}, {_fmt(ci[1], nd)}]"


def _columns(rows: list[dict], where: str = "table") -> list:
    from lfmbench.metrics import columns

    return [s for s in columns(where) if any(not math.isnan(r[s.name]) for r in rows)]


def _vs_best(row: dict, nd: int) -> tuple[str, str]:
    vb = row.get("vs_best")
    if row["rank"] == 1:
        return "best", "-"
    if not vb:
        return "-", "-"
    sig = " *" if num(vb.get("p_holm")) < stats.ALPHA else ""
    return (f"{_fmt(vb['mean_diff'], nd)} {_ci(vb['ci'], nd)}", f"{_fmt(vb['p'])} / {_fmt(vb.get('p_holm'))}{sig}")


def leaderboard_markdown(rows: list[dict], sort_by: str | None = None) -> str:
    """The ranked table as GitHub Markdown, then the CIs of the main metrics and the breakdown by condition."""
    from lfmbench.metrics import PRIMARY

    sort_by = sort_by or PRIMARY
    spec = _check_sort_by(sort_by)
    nd = spec.digits
    cols = [s for s in _columns(rows) if s.name != sort_by]
    st = stats.settings()
    head = (["#", "method", f"{spec.header} [95 % CI]", "diff vs best [95 % CI]", "p / p Holm", "n"]
            + [s.header for s in cols] + ["Pareto", "ms/MP [IQR]", "params", "MACs/MP", "failed"])
    lines = [f"Ranked by `{sort_by}` ({spec.direction} is better; {spec.reference}). Intervals: "
             f"{int(st['confidence'] * 100)} % {st['ci']}, {st['n_resamples']} resamples, seed {st['seed']}; "
             f"n = scenes. Each method against the best: {st['paired_test']} (`*`: p Holm < {st['alpha']}). "
             f"Pareto: not dominated on ({', '.join(PARETO_AXES)}). Run time = median ms per output megapixel "
             "of the repeated calls after warm-up [interquartile range]; `!`: the time moved (the scored calls' "
             "median, or another run of the method, more than a factor 2 outside that range): not to be trusted.",
             "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        d, p = _vs_best(r, nd)
        cells = [str(r["rank"]), f"`{r['method']}`" + _status_mark(r),
                 f"{_fmt(r[sort_by], nd)} {_ci(r['ci'].get(sort_by), nd)}", d, p, str(r["n_scenes"])]
        cells += [_fmt(r[s.name], s.digits) for s in cols]
        cells += ["yes" if r.get("pareto") else ("no" if r.get("pareto") is False else "-"),
                  _ms(r), _fmt(r["params"]), _fmt(r["macs_per_megapixel"], 0),
                  f"{r['failed']}/{r['scenes']}"]
        lines.append("| " + " | ".join(cells) + " |")
    ci_cols = [s for s in _columns(rows, "console") if s.name != sort_by]
    if any(r["ci"] for r in rows) and ci_cols:
        lines += ["", f"{int(st['confidence'] * 100)} % confidence intervals over scenes:", "",
                  "| method | " + " | ".join(s.header for s in ci_cols) + " |", "|---|" + "---|" * len(ci_cols)]
        for r in rows:
            lines.append(f"| `{r['method']}` | " + " | ".join(_ci(r["ci"].get(s.name), s.digits) for s in ci_cols)
                         + " |")
    bd = [r for r in rows if r.get("breakdown")]
    if bd:
        lines += ["", f"`{sort_by}` by condition (value [95 % CI] (scenes); bins: `lfmbench/configs/conditions.yaml`):"]
        conds = list(bd[0]["breakdown"])
        for cond in conds:
            labels = [lab for lab in _all_labels(cond, bd) if any(lab in r["breakdown"].get(cond, {}) for r in bd)]
            if not labels:
                continue
            lines += ["", f"| {cond} | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
            for r in bd:
                c = r["breakdown"].get(cond, {})
                lines.append(f"| `{r['method']}` | " + " | ".join(
                    f"{_fmt(c[lab]['value'], nd)} {_ci(c[lab]['ci'], nd)} ({c[lab]['n']})" if lab in c else "-"
                    for lab in labels) + " |")
    weights = [r for r in rows if r.get("checkpoint_sha256")]
    if weights:
        lines += ["", "Weights (content SHA-256 of each checkpoint, verified when it was loaded): " + "; ".join(
            f"`{r['method']}` {r['checkpoint_sha256'][:12]}" for r in weights) + "."]
    devs = sorted({str(r["device"]) for r in rows})
    threads = sorted({str(r["threads"]) for r in rows if r.get("threads") is not None})
    lines += ["", f"Device: {'; '.join(devs)}" + (f"; torch CPU threads: {', '.join(threads)}" if threads else "")
              + "."]
    few = few_scenes(rows)
    if few:
        lines += ["", few[0].upper() + few[1:] + "."]
    return "\n".join(lines) + "\n"


def _all_labels(cond: str, rows: list[dict]) -> list[str]:
    seen: list[str] = []
    for r in rows:
        for lab in r["breakdown"].get(cond, {}):
            if lab not in seen:
                seen.append(lab)
    try:
        order = bin_labels(load_bins()[cond])
        return sorted(seen, key=lambda x: order.index(x) if x in order else len(order))
    except (KeyError, ValueError):
        return seen


def leaderboard_json(rows: list[dict], runs: list[dict], sort_by: str | None = None,
                     conditions_file: str | Path | None = None) -> dict:
    """The leaderboard as a JSON-ready dict: settings, corpus identity, metric versions and every row."""
    from lfmbench.metrics import PRIMARY, REGISTRY

    sort_by = sort_by or PRIMARY
    spec = REGISTRY[sort_by]
    ident = identity(runs[0]) if runs else {}
    doc = jsonable({
        "format": LEADERBOARD_FORMAT, "version": LEADERBOARD_VERSION, "sort_by": sort_by,
        "metric": {"name": spec.name, "version": spec.version, "unit": spec.unit, "direction": spec.direction,
                   "reference": spec.reference},
        "statistics": stats.settings(), "pareto_axes": list(PARETO_AXES),
        "corpus": (runs[0].get("corpus") if runs else None), "protocol": ident,
        "bins": load_bins(conditions_file),
        "rows": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows],
    })
    doc["per_scene"] = {str(r["method"]): [_scene_jsonable(s) for s in r["_scenes"]] for r in rows}
    return doc


def _scene_jsonable(scene: dict) -> dict:
    """``jsonable(scene)`` of one :func:`~lfmbench.evaluation.results.per_scene` entry, its metric and weight
    values (finite floats as they are) without a call per value: a sweep's JSON holds millions of them."""
    out = {}
    for k, v in scene.items():
        if (k == "metrics" or k == "weights") and type(v) is dict:
            out[str(k)] = {str(n): (x if type(x) is float and x - x == 0.0 else jsonable(x)) for n, x in v.items()}
        else:
            out[str(k)] = jsonable(v)
    return out


def plot_quality_vs_runtime(rows: list[dict], path: str | Path, metric: str | None = None) -> Path:
    """Scatter of ``metric`` (default the LED score) against run time (ms per megapixel, log axis), one point
    per method (legend), with the bootstrap CI of the metric as a vertical error bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lfmbench.metrics import PRIMARY, REGISTRY

    metric = metric or PRIMARY
    fig, ax = plt.subplots(figsize=(7.6, 4.4), dpi=120)
    markers = "osD^vP*Xh<>p"
    rest = []
    for i, r in enumerate(rows):
        x, y = r["ms_per_megapixel"], r[metric]
        if math.isnan(x) or math.isnan(y) or math.isinf(y) or x <= 0:
            continue
        if i >= PLOT_LABELLED:  # a sweep: the rest as small grey points, one artist for all of them
            rest.append((x, y))
            continue
        lo, hi = (num(v) for v in (r.get("ci", {}).get(metric) or (float("nan"), float("nan"))))
        err = [[max(0.0, y - lo)], [max(0.0, hi - y)]] if math.isfinite(lo) and math.isfinite(hi) else None
        # a legend rather than text labels: methods of similar cost and quality overlap
        ax.errorbar([x], [y], yerr=err, fmt=markers[i % len(markers)], ms=6, capsize=3,
                    label=f"{r.get('rank', i + 1)}. {r['method']}")
    if rest:
        ax.scatter(*zip(*rest), s=4, c="0.6", zorder=0, label=f"{len(rest):,} more runs (ranks > {PLOT_LABELLED})")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    ax.set_xscale("log")
    ax.margins(x=0.25, y=0.1)
    ax.set_xlabel("run time [ms per megapixel] (log)")
    spec = REGISTRY[metric] if metric in REGISTRY else None
    ax.set_ylabel(f"{spec.header if spec else metric} [{spec.unit if spec else ''}]")
    ax.set_title(f"Quality vs run time ({'higher' if spec is None or spec.higher_is_better else 'lower'} is better; "
                 f"bars: {int(stats.CONFIDENCE * 100)} % CI over scenes)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    path = atomic_save_figure(fig, path)
    plt.close(fig)
    return path


def print_leaderboard(rows: list[dict], sort_by: str | None = None, note: str = "") -> None:
    """Print the ranked rows as a rich table (the console metrics of the first :data:`PRINT_ROWS` rows; the Markdown
    file has every row and column)."""
    from rich.console import Console
    from rich.table import Table

    from lfmbench.metrics import PRIMARY

    sort_by = sort_by or PRIMARY
    spec = _check_sort_by(sort_by)
    cols = [s for s in _columns(rows, "console") if s.name != sort_by]
    console = Console()
    if not console.is_terminal:
        console = Console(width=180)
    table = Table(title=f"lfmbench leaderboard (ranked by {sort_by}{'; ' + note if note else ''})")
    heads = ["#", "method", f"{spec.header} [95% CI]", "p Holm vs best"] + [s.header for s in cols] + \
        ["ms/MP [IQR]", "params", "failed"]
    for h in heads:
        table.add_column(h, justify="left" if h == "method" else "right", no_wrap=h == "method")
    for r in rows[:PRINT_ROWS]:
        p = "best" if r["rank"] == 1 else (_fmt((r.get("vs_best") or {}).get("p_holm")))
        table.add_row(str(r["rank"]), r["method"] + _status_mark(r),
                      f"{_fmt(r[sort_by], spec.digits)} {_ci(r['ci'].get(sort_by), spec.digits)}", p,
                      *[_fmt(r[s.name], s.digits) for s in cols],
                      _ms(r), _fmt(r["params"]), f"{r['failed']}/{r['scenes']}")
    console.print(table)
    if len(rows) > PRINT_ROWS:
        console.print(f"{len(rows) - PRINT_ROWS:,} more rows (ranks > {PRINT_ROWS}): every row is in the Markdown "
                      "and JSON files", highlight=False)
    if any(r.get("time_moved") for r in rows[:PRINT_ROWS]):
        console.print("!: the run time moved (more than a factor 2 outside its timed range): not to be trusted",
                      highlight=False)
    few = few_scenes(rows)
    if few:
        console.print(few, style="yellow", highlight=False)
