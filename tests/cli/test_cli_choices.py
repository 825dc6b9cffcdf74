"""The commands' closed choice lists are read from the registries and definitions that own the names
(``lfmbench.cli._common.choice``): the help lists every entry, a value outside them exits 2 naming the option, and
the check reads the owner when the command runs (an entry registered at run time is accepted)."""
from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from lfmbench.cli import app
from lfmbench.corpus import STORAGES
from lfmbench.datasets.options import SPLITS
from lfmbench.evaluation.benchmark import SIMULATE
from lfmbench.isp import available_pipelines
from lfmbench.metrics import REGISTRY as METRICS
from lfmbench.paper.common import FIGURES
from lfmbench.train import DATA_SOURCES, RESIDENT_DTYPES
from lfmbench.train_step import CUDA_GRAPH_MODES
from render_tools.backend import SUPPORTED_VARIANTS

_ANSI = re.compile(r"\x1b\[[0-9;]*m")
#: The arguments each command requires besides the option under test.
_REQUIRED = {"leaderboard": ("x.json",), "evaluate": ("--method", "lpd_only", "--corpus", "x"),
             "plot": ("--corpus", "x"), "train": ("--corpus", "x"), "paper-figures": (),
             "render": ("--out", "x")}


def _run(*args: str):
    r = CliRunner().invoke(app, list(args), env={"COLUMNS": "400", "NO_COLOR": "1", "TERM": "dumb"})
    return r.exit_code, " ".join(_ANSI.sub("", r.output).split())


@pytest.mark.parametrize("command,option,names", [
    ("leaderboard", "--sort-by", tuple(METRICS)),
    ("evaluate", "--simulate", tuple(SIMULATE)),
    ("evaluate", "--split", SPLITS),
    ("plot", "--split", SPLITS),
    ("train", "--data", DATA_SOURCES),
    ("train", "--resident-dtype", tuple(RESIDENT_DTYPES)),
    ("train", "--cuda-graph", CUDA_GRAPH_MODES),
    ("paper-figures", "--fig", FIGURES),
    ("render", "--storage", tuple(STORAGES)),
    ("render", "--variant", SUPPORTED_VARIANTS),
])
def test_help_lists_the_owners_names_and_other_values_are_refused(command, option, names):
    code, out = _run(command, "--help")
    assert code == 0
    listed = out.replace(" ", "")
    assert f"[{'|'.join(names)}]" in listed or all(n in listed for n in names), out
    code, out = _run(command, *_REQUIRED[command], option, "no-such-entry")
    assert code == 2 and option in out and "no-such-entry" in out, out


def test_open_lists_name_every_shipped_pipeline():
    for command in ("evaluate", "plot"):
        code, out = _run(command, "--help")
        assert code == 0 and all(p in out for p in available_pipelines()), out


def test_a_metric_registered_at_run_time_is_accepted(tmp_path):
    METRICS.register("zz_registered_here", METRICS["led_score"])
    try:
        code, out = _run("leaderboard", str(tmp_path / "none.json"), "--sort-by", "zz_registered_here")
        assert "Invalid value" not in out  # accepted by the option; refused later for the missing run file
    finally:
        METRICS.unregister("zz_registered_here")
    code, out = _run("leaderboard", str(tmp_path / "none.json"), "--sort-by", "zz_registered_here")
    assert code == 2 and "--sort-by" in out and "Invalid value" in out


def test_a_misspelled_option_is_a_usage_error():
    """typer parses with its own copy of click: its usage errors are still exit 2 with click's message, not an
    'unexpected' error (exit 1)."""
    code, out = _run("leaderboard", "x.json", "--srot-by", "led_score")
    assert code == 2 and "No such option: --srot-by" in out and "unexpected" not in out, out
