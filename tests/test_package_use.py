"""What a user of the installed package meets: shipped configs by name (``lfmbench.resources``, ``lfmbench
configs``), documentation URLs instead of source-tree paths, progress readable in a log, help readable at 80
columns. (The wheel itself, installed into a fresh environment: tests/test_wheel_install.py.)"""
from __future__ import annotations

import io
import re

import pytest
from typer.testing import CliRunner

from lfmbench import docs_url
from lfmbench.resources import CONFIG_KINDS, ConfigNotFoundError, config_dir, find_config, installed


def test_find_config_by_name_source_path_or_own_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no source tree here: names must resolve against the installed package
    tiny = config_dir("training") / "unet_tiny.yaml"
    assert find_config("unet_tiny", "training") == tiny
    assert find_config("unet_tiny.yaml", "training") == tiny
    assert find_config("lfmbench/configs/unet_tiny.yaml", "training") == tiny  # the README's path, outside a checkout
    own = tmp_path / "mine.yaml"
    own.write_text("x: 1\n")
    assert find_config(own, "training") == own
    assert find_config("mine.yaml", "training") == own.relative_to(tmp_path)
    with pytest.raises(ConfigNotFoundError, match=r"--config 'nope': no such file.*installed: learned, unet, "
                                                  r"unet_tiny, unet_v1 \(in .*configs"):
        find_config("nope", "training")
    with pytest.raises(ConfigNotFoundError):  # a shipped name of another kind is not a training config
        find_config("conditions", "training")
    assert list(installed("sensors")) == sorted(p.stem for p in (config_dir("sensors")).glob("*.yaml"))
    assert all(installed(k) for k in CONFIG_KINDS)


def test_train_config_and_conditions_by_name(tmp_path, monkeypatch):
    from lfmbench.baselines.trainable import ConfigError
    from lfmbench.evaluation.conditions import load_bins
    from lfmbench.train import load_config

    monkeypatch.chdir(tmp_path)
    assert load_config("unet", "unet_tiny").model.base_channels == 8  # unet_tiny.yaml's value
    with pytest.raises(ConfigError, match="installed: "):
        load_config("unet", "unet_huge")
    assert load_bins("conditions") == load_bins()


def test_docs_url():
    assert docs_url("guide/fault-catalogue.md") == \
        "https://github.com/lfmbench/lfmbench/blob/main/docs/guide/fault-catalogue.md"
    assert docs_url("docs/guide/isp.md#stages").endswith("/docs/guide/isp.md#stages")


def test_configs_command_lists_every_kind_and_folder():
    from lfmbench.cli import app

    r = CliRunner().invoke(app, ["configs"])
    assert r.exit_code == 0, r.output
    for kind in (*CONFIG_KINDS, "protocols", "profiles"):
        assert re.search(rf"^{kind}: ", r.output, re.M), kind
    assert "unet_tiny" in r.output and "lfmbench-v1-mini" in r.output and str(config_dir("isp")) in r.output
    r = CliRunner().invoke(app, ["configs", "sensors", "--paths"])
    assert r.exit_code == 0 and f"ovt: {config_dir('sensors') / 'ovt.yaml'}" in r.output
    r = CliRunner().invoke(app, ["configs", "nope"])
    assert r.exit_code == 2 and "kinds: training" in r.output


def test_progress_in_a_log_is_a_few_plain_lines():
    """Off a terminal a bar writes a line per tenth of the total and the last one: no carriage returns."""
    from rich.console import Console

    from lfmbench.progress import LOG_LINES, Bar, track

    buf = io.StringIO()
    with Bar(250, "evaluate m", "batch", console=Console(file=buf, force_terminal=False)) as bar:
        for _ in range(250):
            bar.advance()
    lines = buf.getvalue().splitlines()
    assert "\r" not in buf.getvalue() and len(lines) == LOG_LINES
    assert lines[0].startswith("evaluate m: 25/250 batches (10 %,") and lines[-1].startswith("evaluate m: 250/250")
    buf = io.StringIO()
    with Bar(None, "validating", "scene", console=Console(file=buf, force_terminal=False)) as bar:
        bar.update(5, 7)
        bar.update(7)
    assert buf.getvalue().splitlines()[-1].startswith("validating: 7/7 scenes (100 %")
    assert list(track(range(3), enabled=False)) == [0, 1, 2]


def test_progress_lines_say_the_time_left_from_this_runs_rate(monkeypatch):
    """The time left extrapolates the steps done in this run (a resumed job's skipped steps do not count)."""
    from rich.console import Console

    import lfmbench.progress as P

    now = [0.0]
    monkeypatch.setattr(P.time, "perf_counter", lambda: now[0])
    buf = io.StringIO()
    with P.Bar(40, "rendering", "scene", console=Console(file=buf, force_terminal=False)) as bar:
        bar.set(10)                                            # resumed: 10 scenes skipped, 30 to render
        for _ in range(30):
            now[0] += 10.0                                     # every scene takes 10 s
            bar.advance()
    lines = buf.getvalue().splitlines()
    # 12 of 40 after 2 rendered in 20 s: 28 left at 10 s each
    assert lines[0] == "rendering: 12/40 scenes (30 %, 20.0 s, about 5 min left)"
    assert lines[-2] == "rendering: 36/40 scenes (90 %, 260.0 s, about 40 s left)"
    assert lines[-1] == "rendering: 40/40 scenes (100 %, 300.0 s)"
    assert P.time_left(600.0, 10, 40) == "about 30 min left" and P.time_left(3600.0, 1, 4) == "about 3.0 h left"
    assert P.time_left(5.0, 0, 40) == "" == P.time_left(5.0, 4, 4)


def _commands():
    from lfmbench.cli import app

    import typer.main

    group = typer.main.get_command(app)
    return app, group


@pytest.mark.parametrize("name", [None, "render", "evaluate", "leaderboard", "train", "plot", "configs", "validate",
                                  "protocols", "demo", "paper-figures", "flicker-report", "import-isetlfm"])
def test_help_is_readable_at_80_columns(name):
    """``COLUMNS=80 lfmbench CMD --help``: no line wider than 80 characters and every option name whole."""
    app, group = _commands()
    args = ["--help"] if name is None else [name, "--help"]
    r = CliRunner().invoke(app, args, env={"COLUMNS": "80"}, terminal_width=80)
    assert r.exit_code == 0, r.output
    assert max(len(line) for line in r.output.splitlines()) <= 80
    cmd = group if name is None else group.commands[name]
    for p in cmd.params:
        for opt in getattr(p, "opts", []) + getattr(p, "secondary_opts", []):
            if opt.startswith("-"):
                assert re.search(rf"(^|[\s,/]){re.escape(opt)}([\s,=]|$)", r.output, re.M), opt


def test_plot_command_and_dataset_defaults(tmp_path, monkeypatch):
    """``lfmbench plot`` writes a PNG of a sample with a method's output; a crop larger than the scenes says what
    fits; the train split serves 16 draws per scene by default, the others one."""
    from lfmbench.cli import app
    from lfmbench.datasets import LFMCaptureDataset
    from lfmbench.datasets.capture import DEFAULT_SAMPLES_PER_SCENE
    from tests.data.corpus.data import H, W, make_corpus

    corpus = make_corpus(tmp_path / "c", n_scenes=3)
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(app, ["plot", "--corpus", str(corpus), "--split", "all", "-m", "lpd_only", "--out",
                                 "s.png", "--frames", "2"])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "s.png").read_bytes()[:4] == b"\x89PNG" and "lpd_only" in r.output
    r = CliRunner().invoke(app, ["plot", "--corpus", str(corpus), "--split", "all", "--crop", "64"])
    side = min(H, W) // 2 * 2
    assert r.exit_code == 2 and f"at most crop={side}" in " ".join(r.output.split()) and "crop=None" in r.output
    r = CliRunner().invoke(app, ["plot", "--corpus", str(corpus), "--split", "all", "--scene", "nope"])
    assert r.exit_code == 2 and "scene00000" in r.output
    train = LFMCaptureDataset(corpus, split="train", cache_dir=False)
    assert train.samples_per_scene == DEFAULT_SAMPLES_PER_SCENE == 16
    assert len(train) == 16 * len(train.scene_ids)
    assert LFMCaptureDataset(corpus, split="all", cache_dir=False).samples_per_scene == 1
