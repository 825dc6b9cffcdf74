"""benchmarks/studies/cross_training.py: the 2 x 2 table and the paired tests read the right result files and agree
with an independent computation; a scoring counts as done only when every result file is complete; a failed step
stops the study naming it and is recorded; bad options are refused before any work; the steps run protocol by
protocol."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest


@pytest.fixture(scope="module")
def study(load_study):
    return load_study("cross_training")


def _result(path: Path, led: list[float], psnr: list[float], status: str = "complete") -> None:
    """A result file with one sample per scene ``s00``, ``s01``, ... holding both metrics."""
    recs = [{"scene_id": f"s{i:02d}", "index": i, "status": "ok", "metrics": {"led_score": a, "psnr_mu": b},
             "conditions": {}} for i, (a, b) in enumerate(zip(led, psnr))]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"format": "lfmbench-eval", "version": 2, "method": {"spec": path.stem},
                                "status": status, "scenes": recs}))


def test_names_and_short_protocol_names(study):
    assert study.short("lfmbench-v2-mini") == "v2mini" and study.short("configs/my-proto.yaml") == "myproto"
    assert study.net_name("v1mini", "v1mini", 0, 0) == "unet"
    assert study.net_name("v1mini", "v2mini", 0, 0) == "unet_v1minitrained"
    assert study.net_name("v2mini", "v2mini", 1, 0) == "unet_seed1"
    assert study.net_name("v1mini", "v2mini", 1, 0) == "unet_v1minitrained_seed1"


def test_table_and_paired_tests_agree_with_an_independent_computation(study, tmp_path):
    rng = np.random.default_rng(3)
    n = 9
    files = {}
    for te in ("a", "b"):
        for name in ("unet", f"unet_{'b' if te == 'a' else 'a'}trained"):
            led, psnr = rng.uniform(0.6, 0.95, n).round(4), rng.uniform(25, 40, n).round(2)
            _result(tmp_path / "scores" / te / f"{name}.json", led.tolist(), psnr.tolist())
            files[(te, name)] = (led, psnr)
    text = study.summary(tmp_path, ["a", "b"], [0])
    # the cell "trained on a, tested on b" is the mean over scenes of unet_atrained's file on b
    led, psnr = files[("b", "unet_atrained")]
    row = next(ln for ln in text.splitlines() if ln.startswith("| a | 0 |"))
    assert f"{led.mean():.3f} [" in row.split("|")[5] and f"{psnr.mean():.2f} [" in row.split("|")[6]
    # paired on test split b: unet_atrained - unet, per scene, against numpy and scipy
    from scipy.stats import wilcoxon

    ref_led = files[("b", "unet")][0]
    d = led - ref_led
    line = next(ln for ln in text.splitlines() if ln.startswith("| b | a - b, seed 0 |"))
    cells = [c.strip() for c in line.split("|")]
    assert cells[3].startswith(f"{d.mean():+.3f} [") and cells[-2] == str(n)
    assert float(cells[4]) == pytest.approx(wilcoxon(led, ref_led).pvalue, abs=1e-4)
    # a network is never paired against itself; one seed: no mean and no training-noise rows
    assert "| a | a - a" not in text and ", mean |" not in text and "Training noise" not in text


def test_with_two_seeds_the_corpora_are_paired_seed_by_seed_and_as_the_mean_of_their_networks(study, tmp_path):
    rng = np.random.default_rng(5)
    n, files = 7, {}
    for te in ("a", "b"):
        for tr in ("a", "b"):
            for seed in (0, 1):
                name = study.net_name(tr, te, seed, 0)
                led, psnr = rng.uniform(0.6, 0.95, n).round(4), rng.uniform(25, 40, n).round(2)
                _result(tmp_path / "scores" / te / f"{name}.json", led.tolist(), psnr.tolist())
                files[(tr, seed, te)] = (led, psnr)
    text = study.summary(tmp_path, ["a", "b"], [0, 1])
    for seed, label in ((1, "seed 1"), (None, "mean")):
        line = next(ln for ln in text.splitlines() if ln.startswith(f"| b | a - b, {label} |"))
        cells = [c.strip() for c in line.split("|")]
        k = [0, 1] if seed is None else [seed]
        mine = np.mean([files[("a", s, "b")][1] for s in k], axis=0)
        ref = np.mean([files[("b", s, "b")][1] for s in k], axis=0)
        assert cells[5].startswith(f"{(mine - ref).mean():+.2f} ["), line      # PSNR-mu column
    # training noise: each seed-1 network against its own corpus's seed-0 network, on the split named
    line = next(ln for ln in text.splitlines() if ln.startswith("| a | b, seed 1 - seed 0 |"))
    diff = files[("b", 1, "a")][1] - files[("b", 0, "a")][1]
    assert [c.strip() for c in line.split("|")][5].startswith(f"{diff.mean():+.2f} ["), line


def test_scores_complete_needs_every_file_complete(study, tmp_path):
    _result(tmp_path / "unet.json", [0.5], [30.0])
    assert study.scores_complete(tmp_path, ["unet"])
    assert not study.scores_complete(tmp_path, ["unet", "lpd_only"])          # missing
    _result(tmp_path / "lpd_only.json", [0.5], [30.0], status="running")         # killed
    assert not study.scores_complete(tmp_path, ["unet", "lpd_only"])
    (tmp_path / "lpd_only.json").write_text("{")                                 # half-written
    assert not study.scores_complete(tmp_path, ["lpd_only"])


def test_a_failed_step_stops_naming_it_and_is_recorded(study, tmp_path):
    import sys

    steps = study.Steps(tmp_path)
    steps.run("ok step", [sys.executable, "-c", "pass"])
    with pytest.raises(SystemExit, match="train x seed 0 failed \\(exit 3\\)"):
        steps.run("train x seed 0", [sys.executable, "-c", "raise SystemExit(3)"])
    rows = json.loads((tmp_path / "steps.json").read_text())
    assert [(r["step"], r["rc"]) for r in rows] == [("ok step", 0), ("train x seed 0", 3)]
    assert study.Steps(tmp_path).rows == rows                                    # a rerun appends to them


@pytest.mark.parametrize("args, message", [
    (["--protocols", "lfmbench-v1-mini", "lfmbench-v1-mini"], "two different protocols"),
    (["--seeds", "0", "0"], "each seed once"),
])
def test_bad_options_are_refused_before_any_work(study, tmp_path, capsys, args, message):
    out = tmp_path / "xt"
    with pytest.raises(SystemExit):
        study.main(["--out", str(out), *args])
    assert message in capsys.readouterr().err and not out.exists()


def test_protocol_by_protocol_each_test_split_scored_with_the_networks_trained_so_far(study, tmp_path, monkeypatch):
    """The steps run protocol by protocol (a run stopped half-way leaves the first protocol's whole results), and
    the first test split is scored again once the second protocol's networks exist."""
    ran = []
    monkeypatch.setattr(study.Steps, "run", lambda self, name, cmd: ran.append((name, cmd)))
    monkeypatch.setattr(study, "summary", lambda out, shorts, seeds: "table\n")
    figures = []
    monkeypatch.setattr(study, "figure_step", lambda steps, cli, out, corpus, test, *rest: figures.append(test))
    out = tmp_path / "xt"
    study.main(["--out", str(out), "--seeds", "0", "1"])
    assert [n for n, _ in ran] == ["render v1mini test", "render v1mini train", "train v1mini seed 0",
                                   "train v1mini seed 1", "score v1mini", "render v2mini test",
                                   "render v2mini train", "train v2mini seed 0", "train v2mini seed 1",
                                   "score v2mini", "score v1mini"]

    def extra(cmd):
        return [cmd[i + 1].split("=")[0] for i, c in enumerate(cmd) if c == "--unet-also"]

    scores = [(n, cmd) for n, cmd in ran if n.startswith("score")]
    assert extra(scores[0][1]) == ["unet_seed1"]
    assert extra(scores[1][1]) == ["unet_v1minitrained", "unet_v1minitrained_seed1", "unet_seed1"]
    assert extra(scores[2][1]) == ["unet_seed1", "unet_v2minitrained", "unet_v2minitrained_seed1"]
    for (_, cmd), own in zip(scores, ("v1mini", "v2mini", "v1mini")):
        assert cmd[cmd.index("--checkpoint") + 1] == str(out / "nets" / f"unet_{own}_seed0.pt")
    assert (out / "cross_training.md").read_text() == "table\n" and figures == ["v1mini", "v2mini"]


def test_the_figure_shows_the_scene_where_the_networks_differ_most_and_the_best_rule(study, tmp_path):
    runs = tmp_path / "scores" / "b"
    _result(runs / "unet.json", [0.9, 0.9, 0.9, 0.9], [30.0, 31.0, 28.0, 33.0])           # trained on b
    _result(runs / "unet_atrained.json", [0.8, 0.8, 0.8, 0.8], [30.5, 35.0, 24.0, 29.0])  # gaps 0.5, 4, 4, 4
    _result(runs / "lpd_only.json", [0.5, 0.6, 0.7, 0.8], [20.0] * 4)                     # mean 0.65
    _result(runs / "spd_only.json", [0.7, 0.7, 0.6, 0.8], [20.0] * 4)                     # mean 0.70: the best
    _result(runs / "leaderboard.json", [0.99] * 4, [50.0] * 4)                             # no method
    assert study.figure_choice(runs, ["a", "b"], "b", 0) == ("s01", "spd_only")           # a tie: the first id
    (runs / "spd_only.json").unlink()
    assert study.figure_choice(runs, ["a", "b"], "b", 0) == ("s01", "lpd_only")
    (runs / "lpd_only.json").unlink()
    with pytest.raises(SystemExit, match="figure b: no rule-based method scored"):
        study.figure_choice(runs, ["a", "b"], "b", 0)


def test_the_figure_step_plots_the_networks_of_both_corpora_once(study, tmp_path, monkeypatch):
    """The figure of a test split is ``lfmbench plot`` of the chosen scene and rule with the seed-0 network of each
    corpus by name (run in this process and recorded in steps.json); drawn again only when its inputs change."""
    import os

    import torch

    from lfmbench.baselines import unet as U
    from tests.data.evaluation.data import make_led_corpus

    corpus = make_led_corpus(tmp_path / "corpus", n_scenes=3)
    test_ids = json.loads((corpus / "splits.json").read_text())["test"]
    cfg = U.config_from_dict({"model": {"base_channels": 2, "depth": 1}})
    nets = {}
    for seed, tr in enumerate(("a", "b")):
        torch.manual_seed(seed)
        nets[(tr, 0)] = U.save_checkpoint(U.build_for_sensor(cfg), tmp_path / f"unet_{tr}.pt", cfg)
    runs = tmp_path / "scores" / "b"
    n = len(test_ids)
    for name, psnr in (("unet", [30.0] * n), ("unet_atrained", [30.0] * (n - 1) + [20.0]),
                       ("lpd_only", [20.0] * n)):
        _result(runs / f"{name}.json", [0.5] * n, psnr)
        recs = json.loads((runs / f"{name}.json").read_text())               # the corpus's test scene ids
        for r, sid in zip(recs["scenes"], test_ids):
            r["scene_id"] = sid
        (runs / f"{name}.json").write_text(json.dumps(recs))
    for env in ("LFMBENCH_UNET_ATRAINED_CHECKPOINT", "LFMBENCH_UNET_BTRAINED_CHECKPOINT"):
        monkeypatch.setenv(env, "")                                           # set by the plot; restored afterwards
    steps = study.Steps(tmp_path)
    cli = ["python", "-m", "lfmbench.cli"]
    png = study.figure_step(steps, cli, tmp_path, corpus, "b", ["a", "b"], 0, nets)
    assert png == tmp_path / "fig_b.png" and png.read_bytes()[:4] == b"\x89PNG"
    (row,) = json.loads((tmp_path / "steps.json").read_text())
    cmd = row["cmd"]
    assert row["step"] == "figure b" and row["rc"] == 0 and cmd[:4] == [*cli, "plot"]
    assert cmd[cmd.index("--scene") + 1] == test_ids[-1] and cmd[cmd.index("--method") + 1] == "lpd_only"
    assert [cmd[i + 1] for i, c in enumerate(cmd) if c == "--unet"] == [f"unet_atrained={nets[('a', 0)]}",
                                                                         f"unet_btrained={nets[('b', 0)]}"]
    calls = []
    monkeypatch.setattr(study, "cli_in_process", lambda c: calls.append(c) or 0)
    study.figure_step(steps, cli, tmp_path, corpus, "b", ["a", "b"], 0, nets)
    assert calls == []                                                        # up to date: not drawn again
    t = png.stat().st_mtime + 10
    os.utime(runs / "lpd_only.json", (t, t))                                  # a rescored rule: drawn again
    study.figure_step(steps, cli, tmp_path, corpus, "b", ["a", "b"], 0, nets)
    assert len(calls) == 1 and calls[0] == cmd
