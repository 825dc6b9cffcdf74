"""Results of every sensor architecture: ``lfmbench evaluate --sensor NAME`` records sensor and architecture, the
leaderboard refuses to rank different sensors together unless asked (``--cross-sensor``)."""
from __future__ import annotations

import json

import pytest
import typer
from typer.testing import CliRunner

from lfmbench.cli.evaluate import register as register_evaluate
from lfmbench.evaluation import leaderboard as lb
from tests.data.evaluation.data import make_led_corpus


def _app():
    app = typer.Typer()
    register_evaluate(app)
    return app


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("sensors")
    corpus = make_led_corpus(d / "corpus", n_scenes=2)
    out = {}
    for sensor, method in (("lofic", "exposure_select"), ("ovt", "flicker_aware")):
        out[sensor] = d / f"{sensor}.json"
        r = CliRunner().invoke(_app(), ["evaluate", "--sensor", sensor, "--method", method, "--corpus", str(corpus),
                                        "--split", "all", "--output", str(out[sensor]), "--repeats", "1",
                                        "--warmup", "0", "--no-perceptual", "--reference", "common"])
        assert r.exit_code == 0, r.output
    return d, corpus, out


def test_results_record_sensor_and_architecture(runs):
    _, _, out = runs
    a = json.loads(out["lofic"].read_text())
    assert a["dataset"]["sensor"] == "lofic" and a["dataset"]["architecture"] == "lofic"
    assert json.loads(out["ovt"].read_text())["dataset"]["architecture"] == "split_pixel"
    assert lb.run_sensor({"dataset": {}}) == "ovt"                   # results from before: the ovt preset


def test_leaderboard_refuses_mixed_sensors_unless_asked(runs, tmp_path):
    d, _, out = runs
    args = ["--markdown", str(tmp_path / "l.md"), "--plot", str(tmp_path / "l.png"), "--json", str(tmp_path / "l.json")]
    r = CliRunner().invoke(_app(), ["leaderboard", str(out["lofic"]), str(out["ovt"]), *args])
    assert r.exit_code == 2 and "sensor differs: lofic in lofic.json; ovt in ovt.json" in r.output
    assert "--cross-sensor" in r.output and not (tmp_path / "l.md").exists()
    r = CliRunner().invoke(_app(), ["leaderboard", str(out["lofic"]), str(out["ovt"]), *args, "--cross-sensor"])
    assert r.exit_code == 0, r.output
    md = (tmp_path / "l.md").read_text()
    assert "`exposure_select @ lofic`" in md and "`flicker_aware @ ovt`" in md
    own = json.loads(out["ovt"].read_text())
    own["options"].pop("reference")          # as scored against its own gt (a result before version 3)
    (tmp_path / "own.json").write_text(json.dumps(own))
    r = CliRunner().invoke(_app(), ["leaderboard", str(out["lofic"]), str(tmp_path / "own.json"), *args,
                                    "--cross-sensor"])
    assert r.exit_code == 2 and "not the common reference: own.json" in r.output


def test_evaluate_refuses_a_baseline_of_another_architecture(runs, tmp_path):
    _, corpus, _ = runs
    r = CliRunner().invoke(_app(), ["evaluate", "--sensor", "lofic", "--method", "lpd_only", "--corpus", str(corpus),
                                    "--split", "all", "--output", str(tmp_path / "x.json")])
    assert r.exit_code == 2 and "does not apply to --sensor lofic (lofic); its baselines: exposure_select" in r.output
    assert not (tmp_path / "x.json").exists()
    r = CliRunner().invoke(_app(), ["evaluate", "--sensor", "nosuch", "--method", "lpd_only", "--corpus", str(corpus),
                                    "--split", "all", "--output", str(tmp_path / "y.json")])
    assert r.exit_code == 2 and "unknown sensor preset" in r.output and "Traceback" not in r.output
