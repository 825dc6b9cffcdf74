"""Reading the result files a leaderboard ranks: :func:`load_runs` (each file an ``lfmbench-eval`` result whose
every ranked number is finite and inside its metric's documented range, else one line naming the file and the
field) and :func:`incomplete_runs` (interrupted runs and shards, which the command refuses unless told). A sweep's
files are read in a forked pool of 2 processes (:func:`map_forked`), each file's per-scene work done there too
(``digest``)."""
from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from lfmbench.evaluation.results import COMPLETE, RESULT_FORMAT
from lfmbench.fileio import load_json_input
from lfmbench.limits import brief
from lfmbench.parallel import can_fork, map_forked  # noqa: F401 - can_fork re-exported

LEADERBOARD_FORMAT = "lfmbench-leaderboard"
LEADERBOARD_VERSION = 1


#: Result files from which :func:`load_runs` reads them (and runs its ``digest``) in a forked pool of 2 processes
#: (where :func:`can_fork`): reading and checking 10,000 files took 5.4 s and their per-scene values 4 s on one
#: core of a 2-core machine.
PARALLEL_READ_FILES = 256


def _read_one(p: Path, digest=None, quiet: bool = False) -> tuple[str, Any]:
    """``("run", run)`` (``digest(run)`` when given), ``("skip", path)`` for a leaderboard file, or (``quiet``: in a
    worker process) ``("error", None)`` where reading raised: the caller reads that file again in its own process,
    which raises the error itself (an exception need not pickle)."""
    try:
        d = _load_one(p)
    except Exception:
        if not quiet:
            raise
        return "error", None
    if d is None:
        return "skip", str(p)
    return "run", (digest(d) if digest is not None else d)


def _read_in_worker(args: tuple) -> tuple[str, Any]:
    p, digest = args
    try:
        return _read_one(p, digest, quiet=True)
    except Exception:  # noqa: BLE001 - digest failed: the caller's own process reports it
        return "error", None


def load_runs(paths: Iterable[str | Path], skipped: list[str] | None = None, digest=None) -> list[dict]:
    """Read evaluation JSON files; raise ValueError naming a file that is not an lfmbench result.

    A leaderboard file this module wrote (format :data:`LEADERBOARD_FORMAT`, e.g. ``runs/leaderboard.json`` caught
    by ``runs/*.json``) is not a result: it is left out and its path appended to ``skipped`` (if given).

    ``digest``: a function applied to each run where it was read (module level, so that it pickles), e.g.
    :func:`lfmbench.evaluation.leaderboard.render.digest_run`; :data:`PARALLEL_READ_FILES` or more files are read
    in a forked pool of 2 processes (:func:`map_forked`), the runs in the order given and the first bad file (in
    that order) raising its error, as in one process."""
    paths = [Path(p) for p in paths]
    if len(paths) >= PARALLEL_READ_FILES and can_fork():
        got = map_forked(_read_in_worker, [(p, digest) for p in paths], PARALLEL_READ_FILES,
                         chunksize=max(1, len(paths) // 64))
    else:
        got = None
    runs = []
    for i, p in enumerate(paths):
        kind, v = got[i] if got is not None else _read_one(p, digest)
        if kind == "error":
            kind, v = _read_one(p, digest)  # raises the error in this process (or reads a file repaired since)
        if kind == "skip":
            if skipped is not None:
                skipped.append(v)
            continue
        runs.append(v)
    if not runs:
        raise ValueError("no run files given")
    return runs


def _load_one(p: Path) -> dict | None:
    """One result file read and checked (None: a leaderboard file, not a result); ValueError naming the file."""
    d = load_json_input(p, "run file")
    if isinstance(d, dict) and d.get("format") == LEADERBOARD_FORMAT:
        return None
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
    return d


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
