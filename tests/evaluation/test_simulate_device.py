"""``lfmbench evaluate --simulate device``: the evaluation's captures from the device program (counter noise).

The device program on the CPU gives the per-sample path's samples with counter noise (tests/datasets/
test_device_path.py); here: the evaluation's batches from either source agree, an evaluation scores the same from
both, the result records its noise, and the leaderboard ranks generator- and counter-noise runs apart.
"""
from __future__ import annotations

import json
import math

import pytest
import torch
from typer.testing import CliRunner

from lfmbench.cli.evaluate import register as register_evaluate
from lfmbench.evaluation.benchmark import SIMULATE, corpus_run_inputs, run_dataset_record, score_batches
from lfmbench.evaluation.leaderboard import comparability_problems
from lfmbench.evaluation.run import evaluate
from lfmbench.metrics import ScoreOptions
from tests.data.corpus.data import make_corpus


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return make_corpus(tmp_path_factory.mktemp("simdev"), n_scenes=3)


def _ds(corpus, noise="counter"):
    return corpus_run_inputs(corpus, "all", 0, None, 2, frames=3, noise_streams=noise)


def test_device_batches_are_the_host_batches(corpus):
    """The same samples in the same order: the draws (meta), the layers and the captures (counter noise on both
    sides; float32 sums in another order may move a DN by one, as in the device-path tests)."""
    ds, _, _ = _ds(corpus)
    host = list(score_batches(ds, 4, "host"))
    dev = list(score_batches(ds, 4, "device", "cpu"))
    assert len(host) == len(dev) == 4
    for h, d in zip(host, dev):
        assert h["meta"]["scene_id"] == d["meta"]["scene_id"]
        for k in ("gt", "light_index", "depth"):
            torch.testing.assert_close(d[k].to(h[k].dtype), h[k], rtol=1e-5, atol=1e-6 * float(h[k].abs().max()))
        assert (d["lpd_hcg"] != h["lpd_hcg"]).double().mean() <= 2e-3


def test_device_batches_do_not_depend_on_the_chunk(corpus):
    """The device program simulates ``chunk`` samples per call and hands them out one by one: the same samples
    bit for bit for any chunk (on the CPU each sample is composed and simulated on its own), a last partial chunk
    included; a bad chunk is refused."""
    from lfmbench.datasets.batched import tensor_leaves

    ds, _, _ = _ds(corpus)
    n = len(ds) - 1
    one = list(score_batches(ds, n, "device", "cpu", chunk=1))
    four = list(score_batches(ds, n, "device", "cpu", chunk=4))
    assert len(one) == len(four) == n and n % 4
    for a, b in zip(one, four):
        ta, tb = dict(tensor_leaves(a)), dict(tensor_leaves(b))
        assert ta.keys() == tb.keys() and a["meta"]["scene_id"] == b["meta"]["scene_id"]
        for k in ta:
            assert ta[k].shape[0] == 1 and torch.equal(ta[k], tb[k]), k
    with pytest.raises(ValueError, match="chunk"):
        score_batches(ds, n, "device", "cpu", chunk=0)


def test_an_evaluation_scores_the_same_from_both_sources(corpus, tmp_path):
    ds, ident, cond = _ds(corpus)
    n = len(ds)
    res = {}
    for sim in SIMULATE:
        res[sim] = evaluate("flicker_aware", score_batches(ds, n, sim, "cpu"), output=tmp_path / f"{sim}.json",
                            options=ScoreOptions(perceptual=False), repeats=1, progress=False,
                            dataset=run_dataset_record(ds, corpus, "all", n, None, 2, 3), total=n, corpus=ident,
                            scene_conditions=cond)
    a, b = res["host"]["aggregate"], res["device"]["aggregate"]
    assert a["scenes_ok"] == b["scenes_ok"] == n
    for k in ("led_score", "psnr_mu", "dropout_rate"):
        assert math.isclose(a[k], b[k], rel_tol=1e-3, abs_tol=1e-4), (k, a[k], b[k])


def test_cli_simulate_device_records_its_noise_and_is_ranked_apart(corpus, tmp_path):
    app = __import__("typer").Typer()
    register_evaluate(app)
    threads = torch.get_num_threads()
    base = ["evaluate", "--method", "flicker_aware", "--corpus", str(corpus), "--split", "all", "--repeats", "1",
            "--no-perceptual", "--threads", "1", "--isp", "none"]
    try:
        r_dev = CliRunner().invoke(app, base + ["--simulate", "device", "--output", str(tmp_path / "dev.json")])
        r_host = CliRunner().invoke(app, base + ["--output", str(tmp_path / "host.json")])
        r_bad = CliRunner().invoke(app, base + ["--simulate", "gpu", "--output", str(tmp_path / "bad.json")])
    finally:
        torch.set_num_threads(threads)
    assert r_dev.exit_code == 0, r_dev.output
    assert r_host.exit_code == 0, r_host.output
    dev, host = (json.loads((tmp_path / f).read_text()) for f in ("dev.json", "host.json"))
    assert dev["dataset"]["noise_streams"] == "counter" and host["dataset"]["noise_streams"] == "generator"
    assert dev["status"] == "complete" and dev["aggregate"]["scenes_ok"] == 3
    dev["_path"], host["_path"] = "dev.json", "host.json"
    problems = comparability_problems([host, dev])
    assert len(problems) == 1 and problems[0].startswith("sensor noise differs"), problems
    old = dict(host, dataset={k: v for k, v in host["dataset"].items() if k != "noise_streams"})
    assert comparability_problems([host, old]) == []      # files from before the field: generator noise
    assert r_bad.exit_code == 2 and "--simulate" in r_bad.output and not (tmp_path / "bad.json").exists()


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_simulate_device_scores_as_the_cpu_device_program(corpus, tmp_path):
    """On a GPU the device program gives the CPU program's samples (counter noise: the same numbers but for
    float32 sums in another order), so the scores agree within that."""
    ds, ident, cond = _ds(corpus)
    n = len(ds)
    aggs = []
    for dev in ("cpu", "cuda"):
        res = evaluate("flicker_aware", score_batches(ds, n, "device", dev), output=tmp_path / f"{dev}.json",
                       options=ScoreOptions(perceptual=False), repeats=1, progress=False, device=dev,
                       dataset=run_dataset_record(ds, corpus, "all", n, None, 2, 3), total=n, corpus=ident,
                       scene_conditions=cond)
        aggs.append(res["aggregate"])
    assert aggs[0]["scenes_ok"] == aggs[1]["scenes_ok"] == n
    for k in ("led_score", "psnr_mu", "dropout_rate"):
        assert math.isclose(aggs[0][k], aggs[1][k], rel_tol=1e-3, abs_tol=1e-4), (k, aggs[0][k], aggs[1][k])
