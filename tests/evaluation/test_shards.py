"""Sharded evaluation: ``evaluate --shard i/n`` parts joined by ``merge-results`` equal one run over the split."""
from __future__ import annotations

import copy
import json

import pytest
import torch
import typer
from typer.testing import CliRunner

from lfmbench.cli.evaluate import register as register_evaluate
from lfmbench.evaluation import shards as S
from lfmbench.evaluation.benchmark import corpus_run_inputs, run_dataset_record, score_batches
from lfmbench.evaluation.run import evaluate
from lfmbench.metrics import ScoreOptions

#: Fields of a result that are measurements (times, dates, the command line), not scores.
MEASURED = {"created", "runtime", "command", "shards", "method"}


def _app():
    app = typer.Typer()
    register_evaluate(app)
    return app


def test_shards_partition_every_sample_once_without_padding():
    from torch.utils.data import DistributedSampler

    for total, spp, n in ((10, 2, 3), (7, 1, 4), (6, 3, 4), (0, 1, 2)):
        parts = [S.shard_samples(total, spp, i, n) for i in range(n)]
        flat = [k for p in parts for k in p]
        assert sorted(flat) == list(range(total))  # each sample once: none dropped, none repeated
        for p in parts:  # a scene's draws stay in one shard
            assert all(set(range(k - k % spp, k - k % spp + spp)) <= set(p) for k in p)
    # what the distributed sampler would do on 7 samples over 4 ranks: pad to 8 by repeating one sample
    drawn = [k for r in range(4) for k in DistributedSampler(range(7), num_replicas=4, rank=r, shuffle=False)]
    assert len(drawn) == 8 and len(set(drawn)) == 7
    assert S.parse_shard(" 2/5") == (2, 5)
    for bad in ("5/5", "1", "-1/2", "a/b", "0/0"):
        with pytest.raises(ValueError, match="--shard"):
            S.parse_shard(bad)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One run over a 3-scene split (2 draws per scene) and its two shards, by the library, like the CLI."""
    from tests.data.corpus.data import make_corpus

    tmp = tmp_path_factory.mktemp("shards")
    corpus = make_corpus(tmp / "corpus", n_scenes=3)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        ds, ident, cond = corpus_run_inputs(corpus, "all", 0, None, 2, frames=3, sensor="ovt",
                                            noise_streams="generator")
        n = len(ds)
        opts = ScoreOptions(perceptual=False, isp=None, sensor=ds.preset)  # no ISP: 15 s of colour set-up

        def run(indices, out, shard=None):
            rec = run_dataset_record(ds, corpus, "all", n, None, 2, 3)
            if shard is not None:
                rec["shard"] = S.shard_record(*shard, indices, n)
            return evaluate("flicker_aware", score_batches(ds, n, indices=indices), method_spec="flicker_aware",
                            output=out, options=opts, repeats=1, seeds={"dataset": 0}, dataset=rec,
                            progress=False, corpus=ident, scene_conditions=cond)

        one = run(None, tmp / "one.json")
        files = []
        for i in range(2):
            files.append(tmp / f"shard{i}.json")
            run(S.shard_samples(n, 2, i, 2), files[-1], (i, 2))
    finally:
        torch.set_num_threads(threads)
    return tmp, json.loads((tmp / "one.json").read_text()), files, one


def test_merged_shards_equal_one_run(runs):
    tmp, one, files, _ = runs
    r = CliRunner().invoke(_app(), ["merge-results", str(files[1]), str(files[0]), "-o", str(tmp / "merged.json")])
    assert r.exit_code == 0, r.output
    merged = json.loads((tmp / "merged.json").read_text())
    assert merged["shards"]["count"] == 2 and "shard" not in merged["dataset"]
    assert one["aggregate"]["scenes_ok"] == 6 and one["aggregate"]["ci"]["led_score"]
    for key in set(one) | set(merged):
        if key in MEASURED:
            continue
        a, b = one.get(key), merged.get(key)
        if key == "scenes":  # the per-record call time is a measurement
            a = [{k: v for k, v in s.items() if k != "call_ms"} for s in a]
            b = [{k: v for k, v in s.items() if k != "call_ms"} for s in b]
        assert a == b, key  # scores, CIs, per-scene values, breakdown: identical, not close
    assert merged["method"]["spec"] == one["method"]["spec"]
    # the timing of the shard holding sample 0; the scored calls' median and its check are of all merged records
    rescored = ("scored_ms_per_megapixel", "time_moved")
    head = json.loads(files[0].read_text())["runtime"]
    assert {k: v for k, v in merged["runtime"].items() if k not in rescored} == \
        {k: v for k, v in head.items() if k not in rescored}


def test_merge_refuses_missing_twice_and_foreign_shards(runs, tmp_path):
    _, _, files, _ = runs
    out = tmp_path / "m.json"
    app = _app()
    r = CliRunner().invoke(app, ["merge-results", str(files[0]), "-o", str(out)])
    assert r.exit_code == 2 and "shards 1/2 missing" in r.output
    r = CliRunner().invoke(app, ["merge-results", str(files[0]), str(files[0]), str(files[1]), "-o", str(out)])
    assert r.exit_code == 2 and "given twice" in r.output
    sh1 = json.loads(files[1].read_text())
    forged = copy.deepcopy(sh1)  # a shard that claims a sample of shard 0: it would count twice
    forged["dataset"]["shard"]["samples"][0] = 0
    (tmp_path / "forged.json").write_text(json.dumps(forged))
    r = CliRunner().invoke(app, ["merge-results", str(files[0]), str(tmp_path / "forged.json"), "-o", str(out)])
    assert r.exit_code == 2 and "sample 0 also scored" in r.output
    other = copy.deepcopy(sh1)
    other["seeds"] = {"dataset": 1}
    (tmp_path / "other.json").write_text(json.dumps(other))
    r = CliRunner().invoke(app, ["merge-results", str(files[0]), str(tmp_path / "other.json"), "-o", str(out)])
    assert r.exit_code == 2 and "other.json" in r.output and "'seeds.dataset'" in r.output
    cut = copy.deepcopy(sh1)
    cut["status"], cut["scenes"] = "interrupted", cut["scenes"][:1]
    (tmp_path / "cut.json").write_text(json.dumps(cut))
    r = CliRunner().invoke(app, ["merge-results", str(files[0]), str(tmp_path / "cut.json"), "-o", str(out)])
    assert r.exit_code == 2 and "not finished" in r.output
    r = CliRunner().invoke(app, ["merge-results", str(runs[0] / "one.json"), "-o", str(out)])
    assert r.exit_code == 2 and "not a shard result" in r.output
    assert not out.exists()  # nothing written by a refused merge


def test_leaderboard_refuses_a_shard(runs, tmp_path):
    _, _, files, _ = runs
    r = CliRunner().invoke(_app(), ["leaderboard", str(files[0]), "--markdown", str(tmp_path / "l.md"),
                                    "--plot", str(tmp_path / "l.png"), "--json", str(tmp_path / "l.json")])
    assert r.exit_code == 2 and "merge-results" in r.output


def test_cli_shard_option_and_url_refusal(tmp_path):
    app = _app()
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(tmp_path), "--shard", "3/3"])
    assert r.exit_code == 2 and "--shard" in r.output
    for url in ("s3://bucket/corpus", "gs://b/c", "http://host/c", "file:///x"):
        r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", url])
        assert r.exit_code == 2 and "--corpus" in r.output and "URL" in r.output, r.output
        assert len(r.output.strip().splitlines()) == 1
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(tmp_path), "-o",
                                 "s3://bucket/x.json"])
    assert r.exit_code == 2 and "--output" in r.output
