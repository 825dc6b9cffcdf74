"""The cross-sensor benchmark runner (:func:`lfmbench.evaluation.benchmark.benchmark_sensors`): every sensor's
methods scored into its own folder, one leaderboard of all of them, a U-Net checkpoint per sensor whose
environment variable is set for that sensor only."""
from __future__ import annotations

import json
import os

import pytest

from lfmbench.evaluation.benchmark import benchmark_sensors
from tests.data.evaluation.data import make_led_corpus

KW = dict(split="all", perceptual=False, repeats=1, isp=None, progress=False)


def test_every_sensor_is_scored_and_ranked_in_one_leaderboard(tmp_path, monkeypatch):
    import torch

    from lfmbench.baselines import unet as U

    corpus = make_led_corpus(tmp_path / "corpus", n_scenes=2)
    torch.manual_seed(0)
    cfg = U.config_from_dict({"model": {"base_channels": 2, "depth": 1}, "train": {"sensor": "lofic"}})
    ck = U.save_checkpoint(U.build_for_sensor(cfg), tmp_path / "unet_lofic.pt", cfg)
    monkeypatch.setenv(U.CHECKPOINT_ENV, str(tmp_path / "elsewhere.pt"))
    kw = KW
    rows = benchmark_sensors(corpus, {"ovt": ["lpd_only"], "lofic": ["exposure_select", "unet"]}, tmp_path / "runs",
                             checkpoints={"lofic": {"unet": ck}}, **kw)
    assert os.environ[U.CHECKPOINT_ENV] == str(tmp_path / "elsewhere.pt")        # restored after the lofic runs
    assert {r["method"] for r in rows} == {"lpd_only @ ovt", "exposure_select @ lofic", "unet @ lofic"}
    for sensor, method in (("ovt", "lpd_only"), ("lofic", "exposure_select"), ("lofic", "unet")):
        res = json.loads((tmp_path / "runs" / sensor / f"{method}.json").read_text())
        assert res["dataset"]["sensor"] == sensor and res["status"] == "complete"
        assert all(s["status"] == "ok" for s in res["scenes"])
    board = json.loads((tmp_path / "runs" / "leaderboard.json").read_text())
    assert len(board["rows"]) == 3
    assert (tmp_path / "runs" / "leaderboard.md").is_file() and (tmp_path / "runs" / "leaderboard.png").is_file()


def test_bad_checkpoint_arguments_are_refused_before_any_work(tmp_path):
    corpus = make_led_corpus(tmp_path / "corpus", n_scenes=1)
    kw = KW
    with pytest.raises(ValueError, match=r"checkpoints: sensors \['chopped'\]"):
        benchmark_sensors(corpus, {"ovt": ["lpd_only"]}, tmp_path / "r", checkpoints={"chopped": {"unet": "x"}}, **kw)
    with pytest.raises(ValueError, match=r"'lpd_only' is not a learned baseline"):
        benchmark_sensors(corpus, {"ovt": ["lpd_only"]}, tmp_path / "r", checkpoints={"ovt": {"lpd_only": "x"}}, **kw)
    with pytest.raises(ValueError, match="no such file"):
        benchmark_sensors(corpus, {"ovt": ["unet"]}, tmp_path / "r", checkpoints={"ovt": {"unet": tmp_path / "no"}},
                          **kw)
    assert not (tmp_path / "r").exists()


def test_max_scenes_counts_scenes_with_all_their_draws(tmp_path):
    """``max_scenes`` scores whole scenes: with 2 draws per scene, ``max_scenes=2`` is the first 2 scenes' 4 samples
    (it used to be the first 2 samples, i.e. one scene), in the API and in ``lfmbench evaluate``."""
    from typer.testing import CliRunner

    from lfmbench.cli import app

    corpus = make_led_corpus(tmp_path / "corpus", n_scenes=3)
    benchmark_sensors(corpus, {"ovt": ["lpd_only"]}, tmp_path / "runs", samples_per_scene=2, max_scenes=2, **KW)
    res = json.loads((tmp_path / "runs" / "ovt" / "lpd_only.json").read_text())
    ids = [(s["scene_id"], s["index"]) for s in res["scenes"]]
    assert len(ids) == 4 and len({sid for sid, _ in ids}) == 2 and [i for _, i in ids] == [0, 1, 2, 3]
    out = tmp_path / "cli.json"
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(corpus), "--split", "all",
                                 "--max-scenes", "2", "--samples-per-scene", "2", "--repeats", "1", "--warmup", "0",
                                 "--no-perceptual", "--isp", "none", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert [(s["scene_id"], s["index"]) for s in json.loads(out.read_text())["scenes"]] == ids
    # more scenes than the split holds: every sample, once
    benchmark_sensors(corpus, {"ovt": ["lpd_only"]}, tmp_path / "all", samples_per_scene=2, max_scenes=9, **KW)
    assert len(json.loads((tmp_path / "all" / "ovt" / "lpd_only.json").read_text())["scenes"]) == 6


def test_exact_static_windows_refuse_a_sensor_the_corpus_cannot_serve_before_any_work(tmp_path):
    """A published comparison asks for ``static_windows="exact"``: a sensor whose windows the corpus's static bins
    and layers do not give (here the staggered plan on a corpus without bins) is refused naming preset and field,
    and no run folder is written (``nearest``, the default, scores it: the other tests of this file)."""
    corpus = make_led_corpus(tmp_path / "corpus", n_scenes=1)
    with pytest.raises(ValueError, match=r"staggered\.yaml: field 'captures\.long\.exposure'.*static_windows"):
        benchmark_sensors(corpus, {"staggered": ["exposure_select"]}, tmp_path / "r", static_windows="exact", **KW)
    assert not (tmp_path / "r" / "staggered").exists()
