"""The ``lfmbench`` command group itself: ``--limit`` raises an input limit (and refuses nonsense), ``--debug``
shows the traceback behind a one-line error."""
from __future__ import annotations

from typer.testing import CliRunner

from lfmbench.cli import app


def _one_line(r):
    """A refused CLI run: exit 2, no traceback, one non-empty line on stderr (rich may wrap it: joined)."""
    assert r.exit_code == 2, r.output
    assert "Traceback" not in r.output and isinstance(r.exception, SystemExit), r.output
    return " ".join(r.output.split())


def test_cli_limit_option_raises_a_limit_and_refuses_nonsense(tmp_path):
    r = CliRunner().invoke(app, ["--limit", "nonsense=3", "protocols"])
    assert r.exit_code == 2 and "--limit" in r.output and "json_bytes" in r.output
    r = CliRunner().invoke(app, ["--limit", "yaml_nodes=-1", "protocols"])
    assert r.exit_code == 2 and "positive integer" in r.output


def test_debug_flag_shows_the_traceback_behind_a_one_line_error(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format":')
    r = CliRunner().invoke(app, ["leaderboard", str(bad)])
    assert "cannot read JSON" in _one_line(r)  # without --debug: one line, no traceback
    r = CliRunner().invoke(app, ["--debug", "leaderboard", str(bad)])
    assert r.exit_code == 2 and "error: run file" in r.output
    assert "Traceback (most recent call last)" in r.output and "load_runs" in r.output  # where it failed
    assert "InputFileError" in r.output  # hidden behind ``raise ... from None``, shown with --debug
    assert r.output.index("error: run file") < r.output.index("Traceback")  # the one line stays first
    r = CliRunner().invoke(app, ["--debug", "--limit", "nonsense=3", "protocols"])  # a check, no exception:
    assert r.exit_code == 2 and "Traceback" in r.output and "_root" in r.output  # where the check failed
    r = CliRunner().invoke(app, ["--debug", "protocols"])
    assert r.exit_code == 0 and "Traceback" not in r.output
