from typer.testing import CliRunner

from lfmbench.cli import app


def test_flicker_report_prints_fig3_values(tmp_path):
    png = tmp_path / "fig3.png"
    res = CliRunner().invoke(app, ["flicker-report", "--frames", "6", "--plot", str(png)])
    assert res.exit_code == 0, res.output
    # hand-worked values of tests/flicker/test_flicker.py::test_paper_fig3_values_by_hand
    assert "0.351" in res.output and "2.690" in res.output and "0.122" in res.output
    assert png.stat().st_size > 5000 and png.read_bytes()[:4] == b"\x89PNG"


def test_flicker_report_bad_duty_is_a_clear_error():
    res = CliRunner().invoke(app, ["flicker-report", "--duty", "1.5"])
    assert res.exit_code != 0
    assert "duty" in res.output
