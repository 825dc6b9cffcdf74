"""Tests of lfmbench.evaluation: result files, bad methods reported per scene, MAC counting, leaderboard, CLI."""
from __future__ import annotations

import math

import pytest
import torch

from lfmbench import evaluation as ev
from lfmbench.evaluation.benchmark import benchmark as run_benchmark
from lfmbench.metrics import ScoreOptions
from tests.data.metrics.data import make_batch, noisy_batches as _batches, strict_load as _strict_load  # noqa: F401


def test_evaluate_writes_complete_result(tmp_path):
    out = tmp_path / "runs" / "fa.json"
    res = ev.evaluate("flicker_aware", _batches(2), output=out, repeats=3, seeds={"dataset": 7},
                      dataset={"corpus": "synthetic"}, progress=False)
    d = _strict_load(out)
    assert d["format"] == ev.RESULT_FORMAT and d["status"] == "complete"
    assert d["method"]["spec"] == "flicker_aware" and d["method"]["params"] is None
    assert len(d["scenes"]) == 2 and all(s["status"] == "ok" for s in d["scenes"])
    assert d["scenes"][0]["scene_id"] == "synth0_0"
    rt = d["runtime"]
    assert len(rt["times_ms"]) == 3 and rt["ms_per_megapixel"] == pytest.approx(
        rt["median_ms"] / (3 * 32 * 32 / 1e6))
    assert rt["device"] and d["seeds"] == {"dataset": 7}
    assert set(d["versions"]) >= {"lfmbench", "torch", "metrics", "cvvdp"} and "psnr_mu" in d["versions"]["metrics"]
    assert "commit" in d["git"]
    agg = d["aggregate"]
    per = [s["metrics"]["psnr_mu"] for s in d["scenes"]]
    assert agg["psnr_mu"] == pytest.approx(sum(per) / 2) and agg["scenes_ok"] == 2
    assert res["aggregate"]["psnr_mu"] == pytest.approx(agg["psnr_mu"])


def test_bad_methods_are_reported_per_scene_and_run_saves(tmp_path):
    calls = {"n": 0}

    def flaky(batch):
        calls["n"] += 1
        sid = batch["meta"]["scene_id"][0]
        if sid.startswith("synth0"):
            raise RuntimeError("boom")
        if sid.startswith("synth1"):
            return batch["gt"][:, :2]
        if sid.startswith("synth2"):
            return batch["gt"] * float("nan")
        if sid.startswith("synth3"):
            return batch["gt"].clone().fill_(float("inf"))
        return batch["gt"].clone()

    out = tmp_path / "flaky.json"
    res = ev.evaluate(flaky, _batches(5), method_spec="flaky", output=out, repeats=2, progress=False)
    st = [(s["status"], s.get("error", "")) for s in res["scenes"]]
    assert st[0][0] == "error" and "boom" in st[0][1]
    assert st[1][0] == "bad_output" and "shape" in st[1][1]
    assert st[2][0] == "bad_output" and "NaN" in st[2][1]
    assert st[3][0] == "bad_output" and "inf" in st[3][1]
    assert st[4][0] == "ok"
    d = _strict_load(out)
    assert d["aggregate"]["scenes_failed"] == 4 and d["aggregate"]["scenes_ok"] == 1
    assert d["aggregate"]["psnr_mu"] == "inf"  # identical output: PSNR is +inf, stored as a string
    assert ev.num(d["aggregate"]["psnr_mu"]) == math.inf


def test_evaluate_empty_source_and_unknown_method(tmp_path):
    with pytest.raises(ev.EmptyDataError):
        ev.evaluate("lpd_only", [], progress=False)
    from lfmbench.baselines import MethodNotFoundError

    with pytest.raises(MethodNotFoundError, match="nope"):
        ev.evaluate("nope", _batches(1), progress=False)


def test_count_params_macs_conv_and_linear():
    net = torch.nn.Sequential(torch.nn.Conv2d(1, 2, 3, padding=1), torch.nn.Flatten(), torch.nn.Linear(128, 4))
    x = torch.zeros(1, 1, 8, 8)
    params, macs = ev.count_params_macs(net, lambda: net(x))
    assert params == (2 * 9 + 2) + (128 * 4 + 4)
    assert macs == 2 * 64 * 9 + 4 * 128  # conv: out elements x k^2 x C_in; linear: out x in_features


def test_count_macs_transposed_conv():
    """A 2x2 stride-2 transposed convolution (the U-Net's up-sampling): each output element receives exactly one
    kernel tap per input channel, so MACs = out elements x C_in (counted from the output side, independently of
    the input-side formula in count_params_macs)."""
    net = torch.nn.ConvTranspose2d(2, 4, 2, stride=2)
    x = torch.zeros(1, 2, 3, 5)
    out_elems = 1 * 4 * 6 * 10
    params, macs = ev.count_params_macs(net, lambda: net(x))
    assert params == 2 * 4 * 4 + 4 and macs == out_elems * 2


def test_count_macs_matches_torch_flop_counter_on_the_unet():
    """The hook count on the tiny U-Net (convolutions, transposed convolutions, 1x1 head) equals PyTorch's own
    ``torch.utils.flop_counter`` (FLOPs / 2), an independent count."""
    from torch.utils.flop_counter import FlopCounterMode

    from lfmbench.baselines import unet

    net = unet.UNetFusion(unet.load_config(unet.TINY_CONFIG)).unet
    x = torch.zeros(1, net.down[0][0].in_channels, 16, 24)
    _, macs = ev.count_params_macs(net, lambda: net(x))
    with FlopCounterMode(display=False) as fc, torch.no_grad():
        net(x)
    assert macs == fc.get_total_flops() // 2 > 0


def test_learned_module_costs_recorded(tmp_path, monkeypatch):
    from lfmbench.baselines import learned

    ck = tmp_path / "l.pt"
    learned.save_checkpoint(learned.LearnedFusion(), ck)
    monkeypatch.setenv(learned.CHECKPOINT_ENV, str(ck))
    res = ev.evaluate("learned", _batches(1, h=16, w=16), repeats=1, progress=False)
    m = res["method"]
    assert m["params"] == sum(p.numel() for p in learned.LearnedFusion().parameters())
    per_px = 6 * 12 * 9 + 12 * 12 * 9 * 2 + 12 * 3 * 9
    assert m["macs_per_call"] == per_px * 3 * 16 * 16
    assert m["macs_per_megapixel"] == pytest.approx(per_px * 1e6)


def test_leaderboard_rank_markdown_plot(tmp_path):
    for name in ("lpd_only", "flicker_aware", "spd_only"):
        ev.evaluate(name, _batches(2), output=tmp_path / f"{name}.json", repeats=1, progress=False)
    runs = ev.load_runs(sorted(tmp_path.glob("*.json")))
    rows = ev.leaderboard_rows(runs, "psnr_mu")
    vals = [r["psnr_mu"] for r in rows]
    assert vals == sorted(vals, reverse=True) and [r["rank"] for r in rows] == [1, 2, 3]
    rows_l = ev.leaderboard_rows(runs, "dropout_rate")  # lower is better
    d = [r["dropout_rate"] for r in rows_l]
    assert d == sorted(d)
    md = ev.leaderboard_markdown(rows)
    assert "| 1 | `" in md and all(f"`{n}`" in md for n in ("lpd_only", "flicker_aware", "spd_only"))
    png = ev.plot_quality_vs_runtime(rows, tmp_path / "lb.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="sort_by"):
        ev.leaderboard_rows(runs, "bogus")
    (tmp_path / "junk.json").write_text("{\"format\": \"other\"}")
    with pytest.raises(ValueError, match="junk.json"):
        ev.load_runs([tmp_path / "junk.json"])


def test_collate_samples_keeps_meta():
    s = make_batch(b=1)
    sample = {k: (v[0] if isinstance(v, torch.Tensor) else v) for k, v in s.items()}
    sample["meta"] = {"scene_id": "a", "exposure_short_s": 0.004, "exposure_long_s": 1 / 90, "sensor": "ovt"}
    b = ev.collate_samples([sample, dict(sample, meta=dict(sample["meta"], scene_id="b"))])
    assert b["gt"].shape[0] == 2 and b["meta"]["scene_id"] == ["a", "b"]
    from lfmbench.baselines import upstream_saturated

    assert upstream_saturated(b).shape == b["gt"].shape


def test_perceptual_metrics_in_evaluate():
    from lfmbench.metrics import hdr

    try:
        hdr.load_pycvvdp()
    except hdr.CvvdpUnavailableError as exc:
        pytest.skip(f"cvvdp not importable here: {exc}")
    res = ev.evaluate("lpd_only", _batches(1), options=ScoreOptions(perceptual=True), repeats=1, progress=False)
    assert 0 < res["aggregate"]["cvvdp_jod"] <= 10 and "standard_hdr_linear" in res["versions"]["cvvdp"]


def test_method_editing_its_input_cannot_change_the_reference():
    def vandal(batch):
        out = batch["gt"].clone()
        batch["gt"].mul_(0)  # in place
        batch["gt"] = None  # and replaced
        return out

    res = ev.evaluate(vandal, _batches(1), repeats=1, progress=False)
    assert res["scenes"][0]["status"] == "ok" and math.isinf(res["scenes"][0]["metrics"]["psnr_mu"])


def test_missing_cvvdp_is_a_note_not_a_crash(monkeypatch):
    import sys

    from lfmbench.metrics import hdr

    monkeypatch.setitem(sys.modules, "pycvvdp", None)  # as if cvvdp were not installed
    monkeypatch.setattr(hdr, "_PYCVVDP", None)
    with pytest.raises(hdr.CvvdpUnavailableError, match="pip install"):
        hdr.load_pycvvdp()
    res = ev.evaluate("lpd_only", _batches(1), options=ScoreOptions(perceptual=True), repeats=1, progress=False)
    assert res["scenes"][0]["status"] == "ok" and "cvvdp_jod" not in res["aggregate"]
    assert any("perceptual metrics skipped" in n for n in res["notes"])


def test_failing_data_source_saves_partial_result(tmp_path):
    def source():
        yield make_batch(seed=0)
        raise OSError("corrupt EXR scenes/x/f000/otherlights.exr")

    out = tmp_path / "partial.json"
    with pytest.raises(ev.DataSourceError, match="corrupt EXR"):
        ev.evaluate("lpd_only", source(), output=out, repeats=1, progress=False)
    d = _strict_load(out)
    assert d["status"] == "failed" and d["aggregate"]["scenes_ok"] == 1 and "corrupt EXR" in d["notes"][-1]


def test_benchmark_runs_methods_and_writes_leaderboard(tmp_path, capsys):
    from tests.data.corpus.data import make_corpus

    corpus = make_corpus(tmp_path / "corpus", n_scenes=3)
    rows = run_benchmark(corpus, ["lpd_only", "spd_only"], tmp_path / "runs", split="all", perceptual=False,
                        repeats=1, progress=False)
    assert [r["rank"] for r in rows] == [1, 2] and {r["method"] for r in rows} == {"lpd_only", "spd_only"}
    for f in ("lpd_only.json", "spd_only.json", "leaderboard.md", "leaderboard.png"):
        assert (tmp_path / "runs" / f).is_file(), f
    assert "lpd_only" in capsys.readouterr().out


def _scores(result: dict) -> list[tuple]:
    """(scene, index, status, metrics) of every sample record: what must not depend on sharing the samples."""
    return [(s["scene_id"], s["index"], s["status"], s.get("metrics"), s["conditions"]) for s in result["scenes"]]


def test_shared_samples_give_the_per_method_scores(tmp_path):
    """benchmark(share_samples=True) simulates each sample once for all methods; every method's per-sample scores
    equal those of one pass over the data per method (the path before sharing), so do the aggregates."""
    from tests.data.corpus.data import make_corpus

    corpus = make_corpus(tmp_path / "corpus", n_scenes=3)
    methods = ["lpd_only", "flicker_aware", "temporal"]
    kw = dict(split="all", perceptual=False, repeats=1, progress=False, samples_per_scene=2)
    run_benchmark(corpus, methods, tmp_path / "old", share_samples=False, **kw)
    run_benchmark(corpus, methods, tmp_path / "new", share_samples=True, **kw)
    for m in methods:
        old, new = (_strict_load(tmp_path / d / f"{m}.json") for d in ("old", "new"))
        assert len(old["scenes"]) == 6 and _scores(old) == _scores(new), m
        agg = {k: v for k, v in old["aggregate"].items()}
        assert {k: v for k, v in new["aggregate"].items()} == agg, m
        assert new["status"] == "complete" and new["dataset"] == old["dataset"] and new["corpus"] == old["corpus"]


def test_shared_batch_is_not_changed_by_a_method_that_edits_it():
    """A method that zeroes its input in place, evaluated first, must not change what the next method sees."""
    def vandal(batch):
        out = batch["gt"].clone()
        for v in batch.values():
            if isinstance(v, torch.Tensor) and v.is_floating_point():
                v.mul_(0)
        batch["meta"]["scene_id"] = ["x"]
        return out

    batches = _batches(2)
    alone = ev.evaluate("lpd_only", [dict(b) for b in _batches(2)], repeats=1, progress=False)
    both = ev.evaluate_methods([vandal, "lpd_only"], batches, method_specs=["vandal", "lpd_only"], repeats=1,
                               progress=False)
    assert _scores(both[1]) == _scores(alone)
    assert both[0]["method"]["spec"] == "vandal" and both[0]["scenes"][0]["status"] == "ok"


def test_shared_evaluation_failures_and_interrupts_reach_every_result(tmp_path):
    def source():
        yield make_batch(seed=0)
        raise OSError("corrupt EXR scenes/x/f000/otherlights.exr")

    outs = [tmp_path / "a.json", tmp_path / "b.json"]
    with pytest.raises(ev.DataSourceError, match="corrupt EXR"):
        ev.evaluate_methods(["lpd_only", "spd_only"], source(), outputs=outs, repeats=1, progress=False)
    for o in outs:
        d = _strict_load(o)
        assert d["status"] == "failed" and d["aggregate"]["scenes_ok"] == 1

    def interrupted():
        yield make_batch(seed=0)
        raise KeyboardInterrupt

    with pytest.raises(ev.EvaluationInterrupted) as info:
        ev.evaluate_methods(["lpd_only", "spd_only"], interrupted(), outputs=outs, repeats=1, progress=False)
    assert [r["status"] for r in info.value.results] == ["interrupted", "interrupted"]
    assert all(_strict_load(o)["status"] == "interrupted" for o in outs)
    with pytest.raises(ValueError, match="one entry per method"):
        ev.evaluate_methods(["lpd_only", "spd_only"], [make_batch(seed=0)], outputs=outs[:1], progress=False)
    with pytest.raises(ev.EmptyDataError):
        ev.evaluate_methods(["lpd_only", "spd_only"], [], progress=False)
