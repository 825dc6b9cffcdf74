"""``lfmbench evaluate`` with several ``--method``s: one simulation of each sample scores them all; a method module
of the current folder is found as ``python -m`` would find it; and the run-time record a leaderboard can trust
(median and interquartile range of the timed calls, threads, a time that moved flagged)."""
from __future__ import annotations

import json
import math
import sys

import pytest
import torch
import typer
from typer.testing import CliRunner

from lfmbench.cli.evaluate import register as register_evaluate
from lfmbench.evaluation.cost import TIME_MOVED_FACTOR, quartiles, time_moved
from tests.data.evaluation.data import make_led_corpus, write_result


@pytest.fixture(scope="module")
def led_corpus(tmp_path_factory):
    return make_led_corpus(tmp_path_factory.mktemp("c") / "corpus", n_scenes=3)


def _app():
    app = typer.Typer()
    register_evaluate(app)
    return app


def test_several_methods_share_one_simulation_and_a_module_of_the_current_folder(led_corpus, tmp_path, monkeypatch):
    """Three methods (two built-in, one module in the current folder, not on the path) in one call: every sample
    is simulated once (the dataset's ``__getitem__`` counted), three complete result files."""
    from lfmbench.datasets.capture import LFMCaptureDataset

    calls = []
    orig = LFMCaptureDataset.__getitem__

    def counted(self, i):
        calls.append(i)
        return orig(self, i)

    monkeypatch.setattr(LFMCaptureDataset, "__getitem__", counted)
    work = tmp_path / "work"
    work.mkdir()
    (work / "my_fusion_43.py").write_text("def fuse(batch):\n    return batch['spd_e'].clone()\n")
    monkeypatch.chdir(work)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(work))])
    threads = torch.get_num_threads()
    try:
        r = CliRunner().invoke(_app(), ["evaluate", "--corpus", str(led_corpus), "--split", "all", "--method",
                                        "lpd_only", "-m", "spd_only", "-m", "my_fusion_43:fuse", "--no-perceptual",
                                        "--isp", "none", "--repeats", "2", "--threads", "1"])
    finally:
        torch.set_num_threads(threads)
    assert r.exit_code == 0, r.output
    assert sorted(calls) == [0, 1, 2]  # 3 samples, each simulated once for the 3 methods (9 with a pass each)
    res = {m: json.loads((work / "runs" / f"{m}.json").read_text())
           for m in ("lpd_only", "spd_only", "my_fusion_43_fuse")}
    assert all(d["status"] == "complete" and d["aggregate"]["scenes_ok"] == 3 for d in res.values())
    assert res["my_fusion_43_fuse"]["method"]["spec"] == "my_fusion_43:fuse"
    # the user's method returns the SPD: its scores are spd_only's, sample by sample
    assert [s["metrics"]["led_score"] for s in res["my_fusion_43_fuse"]["scenes"]] == \
        [s["metrics"]["led_score"] for s in res["spd_only"]["scenes"]]
    rt = res["lpd_only"]["runtime"]
    assert rt["threads"] == 1 and len(rt["times_ms"]) == 2
    lo, hi = rt["iqr_ms"]
    assert min(rt["times_ms"]) <= lo <= rt["median_ms"] <= hi <= max(rt["times_ms"])
    assert isinstance(rt["time_moved"], bool) and rt["scored_ms_per_megapixel"] > 0


def test_method_module_not_found_says_what_to_do_and_output_needs_one_method(led_corpus, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(_app(), ["evaluate", "--corpus", str(led_corpus), "--method", "no_such_mod_43:fn"])
    assert r.exit_code == 2
    out = " ".join(r.output.split())
    assert "no module 'no_such_mod_43' in the current folder" in out and "PYTHONPATH" in out
    r = CliRunner().invoke(_app(), ["evaluate", "--corpus", str(led_corpus), "-m", "lpd_only", "-m", "spd_only",
                                    "--output", str(tmp_path / "x.json")])
    assert r.exit_code == 2 and "--runs-dir" in r.output and not (tmp_path / "x.json").exists()


def test_time_moved_rule():
    timed = [10.0, 11.0, 12.0]
    assert not time_moved(timed, [11.5, 30.0, 9.0])                     # median 11.5: inside the range
    assert not time_moved(timed, [12.0 * TIME_MOVED_FACTOR] * 3)       # on the edge: kept
    assert time_moved(timed, [12.0 * TIME_MOVED_FACTOR * 1.01] * 3)    # beyond: moved
    assert time_moved(timed, [10.0 / TIME_MOVED_FACTOR * 0.99] * 3)
    assert quartiles([1.0, 2.0, 3.0, 4.0, 5.0]) == (2.0, 4.0)           # numpy's linear interpolation


def test_leaderboard_shows_spread_flags_moved_times_and_warns_about_few_scenes(tmp_path):
    from lfmbench.evaluation.leaderboard import (MIN_SCENES_FOR_CI, few_scenes, leaderboard_markdown,
                                                 leaderboard_rows, load_runs)

    a = write_result(tmp_path / "a.json", scores=(0.5, 0.6), method="m",
                     extra={"runtime": {"device": "cpu", "ms_per_megapixel": 1.8, "iqr_ms_per_megapixel": [1.7, 2.0],
                                        "threads": 2, "time_moved": False}})
    b = write_result(tmp_path / "b.json", scores=(0.5, 0.6), method="m",  # the same method, 600x slower
                     extra={"runtime": {"device": "cpu", "ms_per_megapixel": 1107.0, "threads": 2}})
    c = write_result(tmp_path / "c.json", scores=(0.4, 0.5), method="old")  # a file from before: no spread
    rows = leaderboard_rows(load_runs([a, b, c]), ci=False)
    by = {(r["method"], r["ms_per_megapixel"]): r for r in rows}
    assert by[("m", 1.8)]["time_moved"] and by[("m", 1107.0)]["time_moved"]
    assert by[("m", 1.8)]["ms_iqr"] == [1.7, 2.0] and by[("old", 1.0)]["ms_iqr"] is None
    assert not by[("old", 1.0)]["time_moved"]
    md = leaderboard_markdown(rows)
    assert "1.8 [1.7, 2.0] !" in md and "torch CPU threads: 2" in md
    assert "n = 2 scene(s)" in md and str(MIN_SCENES_FOR_CI) in md
    assert few_scenes([dict(r, n_scenes=MIN_SCENES_FOR_CI) for r in rows]) is None
    assert math.isfinite(by[("old", 1.0)]["ms_per_megapixel"])
