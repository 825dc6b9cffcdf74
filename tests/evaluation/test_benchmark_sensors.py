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
