"""``lfmbench paper-figures``: bad input exits 2 naming the option, Fig. 3 needs no corpus."""
from __future__ import annotations


def _cli(*args):
    from typer.testing import CliRunner

    from lfmbench.cli import app

    return CliRunner().invoke(app, ["paper-figures", *args])


def test_cli_rejects_unknown_figure_and_missing_corpus(tmp_path):
    r = _cli("--fig", "9", "--out", str(tmp_path))
    assert r.exit_code == 2 and "--fig" in r.output and "9" in r.output
    r = _cli("--fig", "5", "--corpus", str(tmp_path / "nope"), "--out", str(tmp_path))
    assert r.exit_code == 2 and "--corpus" in r.output and "manifest.json" in r.output
    r = _cli("--fig", "4", "--out", str(tmp_path))
    assert r.exit_code == 2 and "--corpus" in r.output
    assert not list(tmp_path.glob("*.png"))


def test_cli_fig3_needs_no_corpus(tmp_path):
    r = _cli("--fig", "3", "--out", str(tmp_path))
    assert r.exit_code == 0, r.output
    assert (tmp_path / "fig3_flicker.png").is_file()
