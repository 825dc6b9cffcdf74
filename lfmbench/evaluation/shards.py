"""Sharded evaluation: score a deterministic part of a split (``lfmbench evaluate --shard i/n``) on several
machines, then join the parts (``lfmbench merge-results``) into the result one run over the whole split gives.

Why it is exact: every sample's numbers depend only on (dataset seed, sample index) (the dataset's draws and noise
are keyed by the index, ``docs/guide/contracts.md``), and every statistic of a result (aggregates, bootstrap CIs,
per-scene values, the breakdown by condition; the leaderboard's paired tests read the per-scene values) is a
function of the ordered list of sample records (:func:`lfmbench.evaluation.run._finish`). The merge puts the
shards' records back in sample order and recomputes those statistics with the same code and seeds, so the merged
file equals the one-run file in every score (a test compares them). Only measurements differ: ``call_ms`` per
record, and ``runtime``, which is the timing of the shard holding sample 0 (a single run times its first batch).

How the split is cut: by scene, round robin: scene ``s`` (all its ``samples_per_scene`` draws) belongs to shard
``s mod n``. Nothing is padded (unlike ``torch.utils.data.DistributedSampler``, which repeats samples so that every
rank gets as many), so no sample is scored twice; the merge refuses a sample that appears in two shard files, or a
missing one. Shards run anywhere: a job array (``--shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT``),
torchrun ranks (``--shard $RANK/$WORLD_SIZE``), or Ray tasks (``docs/guide/distributed.md``).
"""
from __future__ import annotations

import copy
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

from lfmbench.evaluation.results import SAME_FIELDS, differing_field, without_shard  # noqa: F401 - one definition

__all__ = ["ShardError", "parse_shard", "shard_samples", "shard_record", "merge_results", "merge_files",
           "differing_field"]

class ShardError(ValueError):
    """Shard files that do not make one evaluation (another protocol, a sample twice or missing, a shard not
    finished); the message names the file and the field."""


def parse_shard(text: str) -> tuple[int, int]:
    """``"i/n"`` -> ``(i, n)`` with ``0 <= i < n``; ValueError naming the form otherwise."""
    m = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", str(text))
    if not m:
        raise ValueError(f"--shard must be INDEX/COUNT (e.g. 0/4), got {str(text)!r:.40}")
    i, n = int(m.group(1)), int(m.group(2))
    if n < 1 or i >= n:
        raise ValueError(f"--shard {i}/{n}: need COUNT >= 1 and 0 <= INDEX < COUNT")
    return i, n


def shard_samples(total: int, samples_per_scene: int, index: int, count: int) -> list[int]:
    """The sample indices (ascending) of shard ``index`` of ``count`` among the first ``total`` samples of a split
    whose samples come scene by scene, ``samples_per_scene`` each: scene ``s`` goes to shard ``s mod count``. The
    shards are disjoint and together hold every sample once (no padding); a shard may be empty when there are
    fewer scenes than shards."""
    if samples_per_scene < 1 or count < 1 or not 0 <= index < count or total < 0:
        raise ValueError(f"shard {index}/{count} of {total} samples ({samples_per_scene} per scene): bad arguments")
    return [k for k in range(total) if (k // samples_per_scene) % count == index]


def shard_record(index: int, count: int, samples: Sequence[int], total: int) -> dict:
    """The ``dataset.shard`` field of a shard's result: which part of the ``total`` samples it scored."""
    return {"index": int(index), "count": int(count), "samples": [int(k) for k in samples], "total": int(total)}


def _name(res: dict, k: int) -> str:
    return str(res.get("_path") or f"shard file {k}")


def merge_results(results: Sequence[dict]) -> dict:
    """Join the result dicts of the shards of one evaluation into the result of one run over the whole split.

    Checks (:class:`ShardError`, naming the file): every input is a shard (``dataset.shard``) of the same count and
    total; protocol, method, corpus identity, seeds, options and versions (:data:`SAME_FIELDS`) equal; each shard
    finished (``complete``, or ``failed`` with every sample recorded: a method that failed on all of a shard's
    scenes) and holds one record per sample it was given; every shard index present once, every sample once.

    Returns:
        the merged result: records in sample order, ``index`` renumbered, aggregates, CIs, per-scene values and the
        breakdown recomputed (the breakdown's bins are those the shards recorded); ``runtime`` and ``method``
        costs of the shard holding sample 0; ``dataset`` without ``shard``; ``shards`` says what was merged.
    """
    from lfmbench.evaluation.results import COMPLETE, num
    from lfmbench.evaluation.run import _finish
    from lfmbench.metrics import PRIMARY

    if not results:
        raise ShardError("no shard files given")
    heads = []
    for k, r in enumerate(results):
        sh = (r.get("dataset") or {}).get("shard") if isinstance(r, dict) else None
        if not isinstance(sh, dict) or not all(isinstance(sh.get(f), int) for f in ("index", "count", "total")) \
                or not isinstance(sh.get("samples"), list):
            raise ShardError(f"{_name(r, k)}: not a shard result (no dataset.shard; made without "
                             "`lfmbench evaluate --shard`)")
        heads.append(sh)
    first, h0 = results[0], heads[0]
    count, total = h0["count"], h0["total"]
    for k, (r, sh) in enumerate(zip(results, heads)):
        for f in ("count", "total"):
            if sh[f] != h0[f]:
                raise ShardError(f"{_name(r, k)}: dataset.shard.{f} = {sh[f]}, but {_name(first, 0)} has {h0[f]}")
        f = differing_field(r, first, shard=False)
        if f is not None:
            raise ShardError(f"{_name(r, k)}: field {f!r} differs from {_name(first, 0)}"
                             + (" (another split, seed, crop or sensor)" if f.startswith("dataset") else ""))
        if r.get("status") not in (COMPLETE, "failed") or len(r.get("scenes") or []) != len(sh["samples"]):
            raise ShardError(f"{_name(r, k)}: shard {sh['index']}/{count} is not finished (status "
                             f"{r.get('status')!r}, {len(r.get('scenes') or [])} of {len(sh['samples'])} samples "
                             "recorded); run it again")
    by_index: dict[int, int] = {}
    for k, sh in enumerate(heads):
        if sh["index"] in by_index:
            raise ShardError(f"{_name(results[k], k)}: shard {sh['index']}/{count} given twice (also "
                             f"{_name(results[by_index[sh['index']]], by_index[sh['index']])})")
        by_index[sh["index"]] = k
    missing = sorted(set(range(count)) - set(by_index))
    if missing:
        raise ShardError(f"shards {', '.join(f'{i}/{count}' for i in missing[:5])} missing "
                         f"({len(by_index)} of {count} given)")
    seen: dict[int, int] = {}
    records: list[tuple[int, dict]] = []
    for k, (r, sh) in enumerate(zip(results, heads)):
        for j, (idx, rec) in enumerate(zip(sh["samples"], r["scenes"])):
            if not isinstance(idx, int) or not 0 <= idx < total:
                raise ShardError(f"{_name(r, k)}: dataset.shard.samples[{j}] = {idx!r:.20} is not a sample index "
                                 f"in [0, {total})")
            if idx in seen:
                raise ShardError(f"{_name(r, k)}: sample {idx} also scored in {_name(results[seen[idx]], seen[idx])}"
                                 " (a sample would count twice)")
            seen[idx] = k
            records.append((idx, rec))
    if len(seen) != total:
        gap = sorted(set(range(total)) - set(seen))
        raise ShardError(f"samples {gap[:5]} of {total} are in no shard file")
    base_k = seen[0] if total else 0
    out = copy.deepcopy({k: v for k, v in results[base_k].items() if k != "_path"})
    out["dataset"] = without_shard(out["dataset"])
    out["created"] = min(str(r.get("created", "")) for r in results)
    scenes = []
    for i, (_, rec) in enumerate(sorted(records, key=lambda t: t[0])):
        rec = copy.deepcopy(rec)
        rec["index"] = i
        scenes.append(rec)
    out["scenes"] = scenes
    notes: list[str] = []
    for r in results:
        for n in r.get("notes") or []:
            if n not in notes and not n.startswith("no scene was scored"):
                notes.append(n)
    out["notes"] = notes
    bins = (first.get("breakdown") or {}).get("bins")
    if isinstance(bins, dict):  # as the shards recorded them: JSON holds an infinite edge as the string "inf"
        bins = {c: (dict(b, edges=[num(x) for x in b["edges"]]) if isinstance(b, dict) and "edges" in b else b)
                for c, b in bins.items()}
    else:
        from lfmbench.evaluation.conditions import load_bins

        bins = load_bins(None)
    _finish(out, bins, (first.get("breakdown") or {}).get("metric") or PRIMARY)
    out["status"] = COMPLETE if out["aggregate"]["scenes_ok"] else "failed"
    if out["status"] == "failed":
        out["notes"].append("no scene was scored: the method failed on every scene")
    out["shards"] = {"count": count, "files": [str(r.get("_path", "")) for r in results],
                     "runtime_from_shard": heads[base_k]["index"],
                     "commands": [r.get("command") for r in results]}
    return out


def merge_files(paths: Iterable[str | Path], output: str | Path) -> dict:
    """Read shard result files, :func:`merge_results` them and write the merged result atomically to ``output``
    (nothing is written when a check fails)."""
    from lfmbench.evaluation.results import RESULT_FORMAT, write_json_atomic
    from lfmbench.fileio import load_json_input

    results = []
    for p in paths:
        d = load_json_input(Path(p), "shard file")
        if not isinstance(d, dict) or d.get("format") != RESULT_FORMAT:
            raise ShardError(f"shard file {p}: not an {RESULT_FORMAT} result")
        d["_path"] = str(p)
        results.append(d)
    merged = merge_results(results)
    write_json_atomic(merged, output)
    return merged
