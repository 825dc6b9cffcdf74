"""``lfmbench evaluate`` and ``lfmbench leaderboard`` (lfmbench.cli.evaluate): a tiny corpus end to end, and the
errors of bad input (exit 2, the option named, nothing written)."""
from __future__ import annotations

import math

import torch
from typer.testing import CliRunner

from lfmbench import evaluation as ev
from lfmbench.cli.evaluate import register as register_evaluate
from tests.data.metrics.data import make_batch, noisy_batches as _batches, strict_load as _strict_load  # noqa: F401


def test_cli_leaderboard_and_evaluate_errors(tmp_path):
    import typer

    app = typer.Typer()
    register_evaluate(app)
    ev.evaluate("lpd_only", _batches(1), output=tmp_path / "a.json", repeats=1, progress=False)
    ev.evaluate("spd_only", _batches(1), output=tmp_path / "b.json", repeats=1, progress=False)
    r = CliRunner().invoke(app, ["leaderboard", str(tmp_path / "a.json"), str(tmp_path / "b.json"),
                                 "--markdown", str(tmp_path / "lb.md"), "--plot", str(tmp_path / "lb.png")])
    assert r.exit_code == 0, r.output
    assert "lpd_only" in r.output and (tmp_path / "lb.md").is_file() and (tmp_path / "lb.png").is_file()
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(tmp_path / "none"),
                                 "--output", str(tmp_path / "x.json")])
    assert r.exit_code == 2 and "does not exist" in r.output
    r = CliRunner().invoke(app, ["evaluate", "--method", "nope", "--corpus", str(tmp_path)])
    assert r.exit_code == 2 and "unknown method" in r.output


def test_cli_evaluate_on_tiny_corpus(tmp_path):
    """The CLI path end to end: LFMCaptureDataset over a generated corpus -> JSON -> leaderboard."""
    import typer

    from tests.data.corpus.data import make_corpus

    corpus = make_corpus(tmp_path / "corpus", n_scenes=3)
    app = typer.Typer()
    register_evaluate(app)
    out = tmp_path / "runs" / "fa.json"
    threads = torch.get_num_threads()
    try:
        r = CliRunner().invoke(app, ["evaluate", "--method", "flicker_aware", "--corpus", str(corpus), "--split",
                                     "all", "--output", str(out), "--repeats", "1", "--no-perceptual", "--threads", "1"])
    finally:
        torch.set_num_threads(threads)
    assert r.exit_code == 0, r.output
    d = _strict_load(out)
    assert d["status"] == "complete" and d["aggregate"]["scenes_ok"] == 3
    assert d["dataset"]["corpus"] == str(corpus) and d["seeds"] == {"dataset": 0}
    assert {s["scene_id"] for s in d["scenes"]} == {"scene00000", "scene00001", "scene00002"}
    assert math.isfinite(d["aggregate"]["psnr_mu"]) and d["runtime"]["ms_per_megapixel"] > 0
    assert math.isfinite(d["aggregate"]["psnr_srgb"]) and d["options"]["isp"]["name"] == "default"
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(corpus), "--split", "nope"])
    assert r.exit_code == 2 and "split" in r.output
    bad = tmp_path / "my_isp.yaml"
    bad.write_text("format: lfmbench-isp\nname: mine\nsteps: [{op: demosaic, methd: x}]\n")
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(corpus), "--split", "all",
                                 "--output", str(tmp_path / "x.json"), "--isp", str(bad)])
    assert r.exit_code == 2 and "--isp" in r.output and "my_isp.yaml" in r.output and "steps[0].methd" in r.output
    assert r.exception is None or isinstance(r.exception, SystemExit)
    assert not (tmp_path / "x.json").exists()  # refused before any work
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(corpus), "--split", "all",
                                 "--output", str(tmp_path / "y.json"), "--isp", "none", "--repeats", "1",
                                 "--no-perceptual"])
    assert r.exit_code == 0, r.output
    d = _strict_load(tmp_path / "y.json")
    assert "psnr_srgb" not in d["aggregate"] and "isp" not in d["options"]
