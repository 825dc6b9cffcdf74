"""A sweep's leaderboard (``lfmbench leaderboard`` over many result files): the files read, checked and reduced to
their per-scene values in a forked pool of 2 processes (``load_runs(..., digest=digest_run)``), the per-scene JSON
made there and spliced into the leaderboard JSON. Everything it writes equals the one-process path, byte for byte,
on results with several samples per scene, NaN, infinite and missing values, zero weights and an incomplete run; a
bad file is reported as in one process (the first in the order given); a file that changes between the two reads
of a row with statistics is refused."""
from __future__ import annotations

import json
import random

import pytest

from lfmbench.evaluation.leaderboard import read
from lfmbench.evaluation.leaderboard import (digest_run, leaderboard_json, leaderboard_json_text, leaderboard_markdown,
                                             leaderboard_rows, load_runs)
from lfmbench.metrics import REGISTRY, columns


def _results(d, n: int = 12, scenes: int = 7) -> list:
    """``n`` varied result files of one protocol in ``d`` (and one leaderboard file among them)."""
    rng = random.Random(5)
    names = [s.name for s in columns("table")]
    weights = sorted({s.weight for s in REGISTRY.values() if s.weight})
    paths = []
    for k in range(n):
        recs = []
        for i in range(scenes):
            m = {}
            for name in names:
                lo, hi = REGISTRY[name].valid
                m[name] = rng.uniform(max(lo, 0.0), min(hi, 1.0 if hi <= 1 else 40.0))
            m.update({w: float(rng.randint(0, 9)) for w in weights})   # zero weights too
            recs.append({"scene_id": f"scene{i:05d}", "index": i, "status": "ok", "metrics": m,
                         "conditions": {"time_of_day": ("day", "dusk", "night")[i % 3], "ego_speed_mps": 5.0 * i,
                                        "pwm_duty": rng.uniform(0.1, 0.5)}})
        if k % 3 == 0:   # several samples of a scene
            recs += [dict(json.loads(json.dumps(r)), index=scenes + j) for j, r in enumerate(recs[:3])]
        recs[1]["metrics"]["psnr_mu"] = "nan"
        recs[2]["metrics"].pop("ssim_mu")
        if k % 4 == 1:
            recs[3]["metrics"]["psnr_mu_outside"] = "inf"
        doc = {"format": "lfmbench-eval", "version": 2, "method": {"spec": f"sweep:run{k:03d}", "params": 10 + k},
               "status": "interrupted" if k == 5 else "complete",
               "runtime": {"device": "cpu", "ms_per_megapixel": rng.uniform(1, 100)},
               "aggregate": {"scenes": len(recs), "scenes_ok": len(recs)}, "scenes": recs,
               "dataset": {"split": "test", "samples_per_scene": 1}, "seeds": {"dataset": 0},
               "corpus": {"scenes_sha256": "0" * 64, "format_version": 2}}
        p = d / f"run{k:03d}.json"
        p.write_text(json.dumps(doc))
        paths.append(p)
    lb = d / "leaderboard.json"
    lb.write_text(json.dumps({"format": "lfmbench-leaderboard", "rows": []}))
    return paths[:4] + [lb] + paths[4:]


def test_sweep_path_writes_the_bytes_of_one_process(tmp_path, monkeypatch):
    paths = _results(tmp_path)
    skipped: list[str] = []
    runs = load_runs(paths, skipped)
    rows = leaderboard_rows(runs, stats_rows=3, ci=False)

    pooled = []
    real = read.map_forked
    monkeypatch.setattr(read, "PARALLEL_READ_FILES", 4)
    monkeypatch.setattr(read, "map_forked", lambda fn, items, n, chunksize=1: pooled.append(len(items)) or
                        real(fn, items, n, chunksize))
    skipped2: list[str] = []
    runs2 = load_runs(paths, skipped2, digest=digest_run)
    rows2 = leaderboard_rows(runs2, stats_rows=3, ci=False)
    assert pooled == [len(paths)] or not read.can_fork()
    assert skipped == skipped2 == [str(tmp_path / "leaderboard.json")]
    assert all("scenes" not in r for r in runs2)                    # the records stayed in the workers
    assert sum(r["_scenes"] is None for r in rows2) == len(rows2) - 3  # only the stats rows read again
    assert leaderboard_markdown(rows2) == leaderboard_markdown(rows)
    one = json.dumps(leaderboard_json(rows, runs), allow_nan=False, separators=(",", ":"))
    assert leaderboard_json_text(rows2, runs2) == one == leaderboard_json_text(rows, runs)
    assert json.dumps(leaderboard_json(rows2, runs2), allow_nan=False, separators=(",", ":")) == one


def test_sweep_path_reports_the_first_bad_file_and_a_changed_file(tmp_path, monkeypatch):
    paths = _results(tmp_path)
    paths[7].write_text(json.dumps({"format": "lfmbench-eval"}))
    paths[3].write_text(json.dumps({"format": "something else"}))
    with pytest.raises(ValueError) as one:
        load_runs(paths)
    monkeypatch.setattr(read, "PARALLEL_READ_FILES", 4)
    with pytest.raises(ValueError) as two:
        load_runs(paths, digest=digest_run)
    assert str(one.value) == str(two.value) and "run003.json" in str(two.value)

    (tmp_path / "good").mkdir()
    runs = load_runs(_results(tmp_path / "good"), digest=digest_run)
    with open(runs[0]["_path"], "a") as f:   # changed after it was read: every row (stats_rows) reads it again
        f.write(" ")
    with pytest.raises(ValueError, match=r"run000\.json: changed while the leaderboard was computed"):
        leaderboard_rows(runs, stats_rows=len(runs), ci=False)
