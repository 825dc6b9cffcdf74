"""Ranking: :func:`leaderboard_rows` (one row per run: each metric's value over scenes, rank, bootstrap CIs
and breakdown by condition for the best rows, each against the best with Wilcoxon and Holm, run-time flags)
and the Pareto front of :data:`PARETO_AXES` (:func:`_pareto`, O(n log n); :func:`_pareto_pairwise`, the
definition, for tests)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from lfmbench.evaluation import stats
from lfmbench.evaluation.conditions import load_bins
from lfmbench.evaluation.leaderboard.compare import _names, run_sensor
from lfmbench.evaluation.leaderboard.read import can_fork, map_forked  # noqa: F401 - can_fork re-exported
from lfmbench.evaluation.results import COMPLETE, breakdown, metric_summary, num, per_scene, scene_means
from lfmbench.limits import brief


#: The two axes of the Pareto front: the lights, and the rest of the image.
PARETO_AXES = ("led_score", "psnr_mu_outside")


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


#: Rows (best first) that get the bootstrap statistics (CIs, breakdown with CIs, the paired test against the
#: best); a sweep of 10,000 results gets them for its best rows only (about 35 bootstraps of 10,000 resamples per
#: row: seconds per row on 2 cores), every row its values, rank and Pareto flag. Leaderboards of up to this many
#: results are computed exactly as before.
STATS_ROWS = 50


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
        dg = r.get("_digest")   # its per-scene values computed where it was read (render.digest_run), or None
        if dg is None:
            records = r.get("scenes") if isinstance(r.get("scenes"), list) else []
            scenes = per_scene(records)
        else:
            records = scenes = None  # read again for a stats row (_reread)
        name = r["method"]["spec"] + (f" @ {run_sensor(r)}" if several else "")
        row = {"method": name, "sensor": run_sensor(r),
               "architecture": (r.get("dataset") or {}).get("architecture", "split_pixel"), "path": r.get("_path"), "device": r["runtime"].get("device"),
               "ms_per_megapixel": num(r["runtime"].get("ms_per_megapixel")),
               "ms_iqr": _pair(r["runtime"].get("iqr_ms_per_megapixel")),
               "time_moved": r["runtime"].get("time_moved") is True, "threads": r["runtime"].get("threads"),
               "params": r["method"].get("params"), "macs_per_megapixel": r["method"].get("macs_per_megapixel"),
               "scenes": agg.get("scenes", 0), "failed": agg.get("scenes_failed", 0), "status": r.get("status"),
               "checkpoint_sha256": _checkpoint_sha(r),
               "n_scenes": len(scenes) if dg is None else dg["n_scenes"], "ci": {}, "_scenes": scenes}
        # metric_summary(scenes, k, ci=False)["value"] of each metric, one pass
        means = scene_means(scenes) if dg is None else dg["means"]
        if dg is not None:
            row["_scenes_json"], row["_stat"] = dg["scenes_json"], dg["stat"]
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
        if row["_scenes"] is None and (row["stats"] or i == 0):   # a digested run: its records read again
            records, row["_scenes"] = _reread(row)
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


def _reread(row: dict) -> tuple[list, list]:
    """(sample records, per-scene entries) of a row whose run was digested where it was read
    (:func:`lfmbench.evaluation.leaderboard.render.digest_run` keeps neither): its file read and checked again,
    refused when its size or modification time differs from the first read."""
    from lfmbench.evaluation.leaderboard.read import _load_one

    p = Path(row["path"])
    st = p.stat()
    run = _load_one(p)
    if run is None or [st.st_size, st.st_mtime_ns] != list(row["_stat"]):
        raise ValueError(f"run file {p}: changed while the leaderboard was computed (size or modification time); "
                         "rerun lfmbench leaderboard")
    records = run.get("scenes") if isinstance(run.get("scenes"), list) else []
    return records, per_scene(records)


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


def _map_stats(fn, items: list) -> list:
    """``[fn(x) for x in items]``, in a forked pool of 2 processes when there are :data:`PARALLEL_STATS_ROWS` or
    more items and :func:`can_fork` (:func:`~lfmbench.evaluation.leaderboard.read.map_forked`)."""
    return map_forked(fn, items, PARALLEL_STATS_ROWS)


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
