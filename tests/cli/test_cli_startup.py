"""The command line's start-up does not import torch: ``lfmbench --help`` and a whole ``lfmbench leaderboard`` run
(reading, ranking, Markdown, JSON and plot) leave ``torch`` out of ``sys.modules`` (torch's import was 5 of the
33 s of a 10,000-file leaderboard, docs/benchmarks/leaderboard.md); the help of a command that lists a registry
importing torch still lists it (``lfmbench.cli._common.lazy``)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from tests.data.evaluation.data import write_result

ROOT = Path(__file__).resolve().parents[2]

_PROBE = """
import json, sys
from lfmbench.cli import app
seen = {}
for name, argv in (("help", ["--help"]), ("leaderboard", sys.argv[1:])):
    try:
        app(argv, prog_name="lfmbench")
    except SystemExit as exc:
        seen[name] = [exc.code, "torch" in sys.modules]
print("PROBE " + json.dumps(seen))
"""


def test_help_and_leaderboard_do_not_import_torch(tmp_path):
    a = write_result(tmp_path / "a.json", scores=(0.5, 0.6, 0.7), method="a")
    b = write_result(tmp_path / "b.json", scores=(0.4, 0.5, 0.9), method="b")
    args = ["leaderboard", str(a), str(b), "--markdown", str(tmp_path / "lb.md"), "--plot", str(tmp_path / "lb.png"),
            "--json", str(tmp_path / "lb.json")]
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    r = subprocess.run([sys.executable, "-c", _PROBE, *args], capture_output=True, text=True, cwd=str(tmp_path),
                       env=env, timeout=120)
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("PROBE ")]
    assert r.returncode == 0 and line, r.stdout[-2000:] + r.stderr[-2000:]
    seen = json.loads(line[0][len("PROBE "):])
    assert seen["help"] == [0, False], seen
    assert seen["leaderboard"] == [0, False], (seen, r.stderr[-2000:])
    assert json.loads((tmp_path / "lb.json").read_text())["rows"][0]["method"] == "a"


def test_help_that_lists_a_torch_registry_still_lists_it():
    """``evaluate --help`` names every registered baseline and ``train --help`` the learned ones and the training
    options' choices, made when the help is shown."""
    from typer.testing import CliRunner

    from lfmbench.baselines import LEARNED, REGISTRY
    from lfmbench.cli import app
    from lfmbench.train import DATA_SOURCES

    env = {"COLUMNS": "400", "NO_COLOR": "1", "TERM": "dumb"}
    ev = " ".join(CliRunner().invoke(app, ["evaluate", "--help"], env=env).output.split())
    assert all(n in ev for n in REGISTRY) and "{lazy:" not in ev, ev
    tr = " ".join(CliRunner().invoke(app, ["train", "--help"], env=env).output.split())
    assert all(n in tr for n in LEARNED) and f"[{'|'.join(DATA_SOURCES)}]" in tr and "{lazy:" not in tr, tr
