"""The result file of one evaluation: format constants, JSON safety, per-scene values, aggregates with
confidence intervals, and the breakdown by condition.

Every aggregation reads the metric registry (:data:`lfmbench.metrics.REGISTRY`): a metric's ``aggregate`` says
whether it is a mean over scenes or pooled with a weight (``dropout_rate`` over region-frames). The unit of
every statistic is the scene: a scene's samples (PWM draws) are combined first (:func:`per_scene`).
"""
from __future__ import annotations

import math
import statistics
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any


from lfmbench.evaluation import stats
from lfmbench.fileio import atomic_write_json

RESULT_FORMAT = "lfmbench-eval"
#: Version 2: per-scene values, confidence intervals, conditions, breakdown, corpus identity. Version 3
#: (2026-11-28): ``options.reference`` (``"common"``: the cross-sensor columns scored against ``gt_common``,
#: :data:`lfmbench.metrics.scoring.REFERENCES`; absent: against the sensor's own ``gt``, as every version-2 file).
RESULT_VERSION = 3
#: ``status`` of a finished result file; anything else (``running``: killed, ``interrupted``, ``failed``) is
#: not a result the leaderboard ranks without ``--include-incomplete``.
COMPLETE = "complete"


def num(x: Any) -> float:
    """A metric value read back from a result file as float ('nan'/'inf' strings and None -> float)."""
    if x is None or isinstance(x, bool):
        return float("nan")
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def jsonable(x: Any) -> Any:
    """Floats that JSON cannot hold (NaN, +-inf) become the strings 'nan', 'inf', '-inf'; tensors become lists."""
    t = type(x)  # the common exact types first (a sweep's leaderboard JSON holds millions of values)
    if t is str or t is int or t is bool or x is None:
        return x
    if t is float:
        return x if x - x == 0.0 else ("nan" if x != x else ("inf" if x > 0 else "-inf"))
    if t is dict:
        return {str(k): jsonable(v) for k, v in x.items()}
    if t is list:
        return [jsonable(v) for v in x]
    if isinstance(x, float):
        return x if math.isfinite(x) else ("nan" if math.isnan(x) else ("inf" if x > 0 else "-inf"))
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    torch = sys.modules.get("torch")  # a tensor exists only where torch was imported: not imported here for it
    if torch is not None and isinstance(x, torch.Tensor):
        return jsonable(x.tolist())
    if isinstance(x, Path):
        return str(x)
    return x


#: Fields that must be equal in every shard of one evaluation (what a single run writes once); with ``dataset``,
#: what makes two result files parts of one evaluation (:func:`differing_field`).
SAME_FIELDS = ("format", "version", "method", "corpus", "seeds", "options", "versions", "statistics")


def without_shard(dataset: dict) -> dict:
    """A result's ``dataset`` record without its ``shard`` (which part of the split a shard scored)."""
    return {k: v for k, v in dataset.items() if k != "shard"}


def differing_field(result: dict, other: dict, shard: bool = True) -> str | None:
    """The first field in which two results are not of one evaluation, None when they are: ``dataset`` (corpus
    path, split, samples, crop, samples per scene, frames, sensor, noise; with ``shard`` also ``dataset.shard``, which
    part of the split), then those of :data:`SAME_FIELDS` (``method`` by its spec: parameters and MACs are
    measured); in a field that holds a dict, its first differing key (``"dataset.samples_per_scene"``,
    ``"seeds.dataset"``). Values are compared as a result file holds them (:func:`jsonable`), so a result in memory
    and one read back compare equal. Used by :func:`lfmbench.evaluation.shards.merge_results` (``shard=False``:
    shards of one split differ there) and by a resumed evaluation (:func:`lfmbench.evaluation.run.evaluate_methods`).
    """
    for f in ("dataset", *SAME_FIELDS):
        a, b = result.get(f), other.get(f)
        if f == "dataset" and not shard:
            a, b = without_shard(a or {}), without_shard(b or {})
        elif f == "method":  # parameters and MACs are measured; the method is its spec
            a, b = (a or {}).get("spec"), (b or {}).get("spec")
        a, b = jsonable(a), jsonable(b)
        if a != b:
            if isinstance(a, dict) and isinstance(b, dict):
                return f + "." + next(k for k in [*a, *(k for k in b if k not in a)]
                                      if k not in a or k not in b or a[k] != b[k])
            return f
    return None


def write_json_atomic(obj: dict, path: str | Path) -> Path:
    """Write JSON to ``path`` atomically (temporary file in the same directory, then ``os.replace``)."""
    path = Path(path)
    atomic_write_json(path, jsonable(obj))
    return path


def _value(v: Any) -> float | None:
    """A sample's metric value as float, None when it is not a number (NaN counts as missing)."""
    if isinstance(v, (bool, list, dict)) or v is None:
        return None
    x = num(v)
    return None if math.isnan(x) else x


def combine(values: list[float | None], weights: list[float] | None, spec) -> float:
    """Combine values (of samples, or of scenes) by the registry spec: mean, or pooled with the weights."""
    if spec.aggregate == "pooled":
        pairs = [(v, w) for v, w in zip(values, weights or []) if v is not None and math.isfinite(v) and w > 0]
        tot = sum(w for _, w in pairs)
        return sum(v * w for v, w in pairs) / tot if tot else float("nan")
    fin = [v for v in values if v is not None]
    return statistics.fmean(fin) if fin else float("nan")


def _scene_key(rec: dict) -> str:
    sid = rec.get("scene_id")
    return str(sid) if sid is not None else f"#{rec.get('index')}"


def per_scene(records: Iterable[dict], metrics: Iterable[str] | None = None) -> list[dict]:
    """One entry per scene from the ``ok`` sample records of a result (``scenes``), in first-seen order.

    Returns:
        ``[{"scene_id", "samples", "metrics": {name: value}, "weights": {name: total}, "conditions"}]``: a
        metric's scene value is the mean over the scene's samples, or (``aggregate="pooled"``) the pooled
        ratio; ``conditions`` holds the scene-level conditions (time of day, ego speed) and the means of the
        sample-level ones (PWM duty, frequency).

    The values are those of :func:`combine` over :func:`_value` of each sample (a metric no sample holds is
    skipped without building its lists; a finite or infinite float is taken as it is): a leaderboard of 10,000
    results calls this once per result.
    """
    from lfmbench.metrics import REGISTRY

    names = list(metrics) if metrics is not None else list(REGISTRY)
    specs = [(n, REGISTRY[n]) for n in names if n in REGISTRY]
    groups: dict[str, list[dict]] = {}
    for r in records:
        if r.get("status") == "ok" and isinstance(r.get("metrics"), dict):
            groups.setdefault(_scene_key(r), []).append(r)
    out = []
    for key, recs in groups.items():
        ms = [r["metrics"] for r in recs]
        if len(ms) == 1:  # one sample: a mean is its value (fsum([v]) / 1 == v), the rest as below
            out.append(_one_sample_scene(recs[0], specs))
            continue
        held = set().union(*ms)
        vals, weights = {}, {}
        for n, spec in specs:
            if n not in held:  # no sample holds it: every value None, as combine would skip it
                continue
            vs = [v if type(v) is float and v == v else _value(v) for v in (m.get(n) for m in ms)]
            if all(v is None for v in vs):
                continue
            if spec.weight:
                w = [num(m.get(spec.weight)) for m in ms]
                w = [x if math.isfinite(x) else 0.0 for x in w]
                vals[n] = combine(vs, w, spec)
                weights[spec.weight] = sum(x for x, v in zip(w, vs) if v is not None)
            else:
                vals[n] = combine(vs, [1.0] * len(vs), spec)
        cond: dict[str, Any] = {}
        for r in recs:
            for k, v in (r.get("conditions") or {}).items():
                cond.setdefault(k, []).append(v)
        cond = {k: (v[0] if isinstance(v[0], str) else statistics.fmean(num(x) for x in v)) for k, v in cond.items()}
        out.append({"scene_id": recs[0].get("scene_id"), "samples": len(recs), "metrics": vals, "weights": weights,
                    "conditions": cond})
    return out


def _one_sample_scene(rec: dict, specs: list) -> dict:
    """:func:`per_scene`'s entry of a scene with one ``ok`` sample record (the same values, fewer steps)."""
    m = rec["metrics"]
    vals, weights = {}, {}
    for n, spec in specs:
        if n not in m:
            continue
        v = m[n]
        v = v if type(v) is float and v == v else _value(v)
        if v is None:
            continue
        if spec.weight:
            w = num(m.get(spec.weight))
            w = w if math.isfinite(w) else 0.0
            vals[n] = combine([v], [w], spec)
            weights[spec.weight] = w
        elif spec.aggregate == "pooled":
            vals[n] = combine([v], [1.0], spec)
        else:
            vals[n] = v
    cond = {k: (v if isinstance(v, str) else statistics.fmean([num(v)]))
            for k, v in (rec.get("conditions") or {}).items()}
    return {"scene_id": rec.get("scene_id"), "samples": 1, "metrics": vals, "weights": weights, "conditions": cond}


def scene_values(scenes: list[dict], name: str) -> tuple[list[float], list[float] | None]:
    """(per-scene values, per-scene weights or None) of one metric, as :func:`stats.bootstrap_ci` takes them."""
    from lfmbench.metrics import REGISTRY

    spec = REGISTRY[name]
    rows = [s for s in scenes if name in s["metrics"]]
    vals = [num(s["metrics"][name]) for s in rows]
    if spec.weight:
        return vals, [num(s["weights"].get(spec.weight, 0.0)) for s in rows]
    return vals, None


def metric_summary(scenes: list[dict], name: str, ci: bool = True) -> dict:
    """``{"value", "ci": [low, high], "n"}`` of one metric over per-scene entries (:func:`per_scene`)."""
    from lfmbench.metrics import REGISTRY

    vals, w = scene_values(scenes, name)
    v = combine([None if math.isnan(x) else x for x in vals], w, REGISTRY[name])
    lo, hi = stats.bootstrap_ci(vals, w) if ci else (float("nan"), float("nan"))
    return {"value": v, "ci": [lo, hi], "n": len(vals)}


def scene_means(scenes: list[dict]) -> dict[str, float]:
    """``{name: value}`` of every registered metric some scene holds: ``metric_summary(scenes, name,
    ci=False)["value"]`` of each, the scenes' lists gathered in one pass (a sweep's leaderboard computes this for
    10,000 results)."""
    from lfmbench.metrics import REGISTRY

    weight_of = {n: REGISTRY[n].weight for n in REGISTRY if REGISTRY[n].weight}
    vals: dict[str, list[float]] = {}
    wts: dict[str, list[float]] = {}
    for s in scenes:
        for n, v in s["metrics"].items():
            vals.setdefault(n, []).append(num(v))
            if n in weight_of:
                wts.setdefault(n, []).append(num(s["weights"].get(weight_of[n], 0.0)))
    out = {}
    for n, vs in vals.items():
        if n in REGISTRY:
            spec = REGISTRY[n]
            out[n] = combine([None if math.isnan(x) else x for x in vs], wts.get(n) if spec.weight else None, spec)
    return out


def aggregate(records: list[dict], ci: bool = False) -> dict:
    """The ``aggregate`` block of a result: counts, the value of every registered metric over scenes (mean of
    per-scene values, or pooled), and with ``ci`` a bootstrap confidence interval of each (``ci`` block)."""
    from lfmbench.metrics import REGISTRY

    ok = [s for s in records if s.get("status") == "ok"]
    agg: dict[str, Any] = {"scenes": len(records), "scenes_ok": len(ok), "scenes_failed": len(records) - len(ok)}
    scenes = per_scene(ok)
    agg["distinct_scenes"] = len(scenes)
    intervals = {}
    for name in REGISTRY:
        if not any(name in s["metrics"] for s in scenes):
            continue
        m = metric_summary(scenes, name, ci=ci)
        if math.isnan(m["value"]):
            continue
        agg[name] = m["value"]
        if ci:
            intervals[name] = m["ci"]
    flags = [s["metrics"].get("saturation_flag") for s in ok if "saturation_flag" in s["metrics"]]
    if flags:
        agg["saturation_flag_scenes"] = int(sum(bool(f) for f in flags))
    if ci:
        agg["ci"] = intervals
    return agg


def breakdown(records: list[dict], metric: str, bins: dict[str, dict], ci: bool = True) -> dict:
    """``metric`` by condition: ``{condition: {bin label: {"value", "ci", "n"}}}`` over the ``ok`` sample
    records; the unit is a scene's samples that fall in the bin (a scene's PWM draws may fall in several bins).

    Args:
        records: sample records (``scenes`` of a result) with ``conditions``.
        metric: a registered metric name.
        bins: :func:`lfmbench.evaluation.conditions.load_bins`.
    """
    from lfmbench.evaluation.conditions import bin_label, bin_labels

    ok = [r for r in records if r.get("status") == "ok"]
    out: dict[str, dict] = {}
    for cond, spec in bins.items():
        by: dict[str, list[dict]] = {}
        for r in ok:
            lab = bin_label((r.get("conditions") or {}).get(cond), spec)
            by.setdefault(lab, []).append(r)
        out[cond] = {}
        for lab in bin_labels(spec):
            if lab in by:
                sc = per_scene(by[lab], [metric])
                if any(metric in s["metrics"] for s in sc):
                    out[cond][lab] = metric_summary(sc, metric, ci=ci)
    return out
