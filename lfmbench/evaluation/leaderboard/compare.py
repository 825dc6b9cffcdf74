"""Comparability of the results ranked together: :func:`identity` (what must agree: corpus, metric versions,
protocol, sensor, display ISP), :func:`comparability_problems` (one line per differing field, naming the files)
and :func:`check_comparable` (raises :class:`IncomparableRunsError`)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any


class IncomparableRunsError(ValueError):
    """Result files computed on different corpora, metric versions or protocols."""


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
