"""Real-capture CSV import (CARpublic ROI-mean layout), noise Monte Carlo sanity, and the command end to end."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from lfmbench.cli import app
from lfmbench.flicker_bench.model import BenchError, build_model
from lfmbench.flicker_bench.noise import noise_kpis, wilson_interval
from lfmbench.flicker_bench.realcap import measured_kpis, read_captures
from lfmbench.flicker_bench.sequence import sequence_series
from lfmbench.metrics.flicker import fdi, fmi, mmp


def _write(tmp_path, series: dict, meta_rows: list[str], index=True):
    n = len(next(iter(series.values())))
    lines = [("," if index else "") + ",".join(series)]
    for i in range(n):
        lines.append((f"{i}," if index else "") + ",".join(repr(float(series[k][i])) for k in series))
    sp = tmp_path / "series.csv"
    sp.write_text("\n".join(lines) + "\n")
    mp = tmp_path / "meta.csv"
    mp.write_text("\n".join(meta_rows) + "\n")
    return sp, mp


def test_measured_kpis_equal_metrics_with_baseline_frames(tmp_path):
    rng = np.random.default_rng(3)
    x = np.concatenate([np.full(8, 10.0), 10.0 + 100.0 * rng.random(40)])
    sp, mp = _write(tmp_path, {"ROI_0": x, "ROI_1": x[::-1]},
                    ["roi,frequency_hz,duty,start_index", "ROI_0,95,0.2,8"])
    caps = read_captures(sp, mp)
    assert len(caps) == 1 and caps[0].roi == "ROI_0"
    k = measured_kpis(caps[0])
    t = torch.from_numpy(x)
    assert k["fmi"] == float(fmi(t, start_index=8))
    assert k["mmp"] == float(mmp(t, start_index=8))
    assert k["fdi"] == float(fdi(t, start_index=8))  # OFF level: mean of the first 8 // 4 frames, as the reference


@pytest.mark.parametrize("meta,series_bad,match", [
    (["roi,frequency_hz,start_index", "ROI_0,95,4"], False, r"meta\.csv: missing column 'duty'"),
    (["roi,frequency_hz,duty,start_index", "ROI_0,abc,0.2,4"], False, r"meta\.csv: field 'frequency_hz' row 2: not a number"),
    (["roi,frequency_hz,duty,start_index", "ROI_0,95,1.5,4"], False, r"field 'duty' row 2"),
    (["roi,frequency_hz,duty,start_index", "ROI_9,95,0.2,4"], False, r"series\.csv: no column 'ROI_9'"),
    (["roi,frequency_hz,duty,start_index", "ROI_0,95,0.2,4"], True, r"series\.csv: field 'ROI_0' row 4: not a number"),
])
def test_bad_capture_files_name_file_and_field(tmp_path, meta, series_bad, match):
    x = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    sp, mp = _write(tmp_path, {"ROI_0": x}, meta)
    if series_bad:
        lines = sp.read_text().splitlines()
        lines[3] = "2,oops"
        sp.write_text("\n".join(lines) + "\n")
    with pytest.raises(BenchError, match=match):
        read_captures(sp, mp)


def test_noise_mc_steady_light_and_floor():
    """A bright steady light (duty 1) has no flicker: MMP is 1 with noise and equals its noise floor; a dim one
    is limited by noise alone (floor < 1), and the noisy MMP lies in its own Wilson interval."""
    model = build_model("single")
    sat = model.saturation_luminance()["main"]
    off = {"main": 0.0}
    out = noise_kpis(model, np.array([100.0]), np.array([1.0]), np.array([sat * 1e-4, sat * 0.5]), {}, off,
                     draws=400, roi_px=1, seed=1)["main"]
    assert out["mmp"][0, 1] == 1.0 and out["mmp_floor"][0, 1] == 1.0
    assert out["mmp_floor"][0, 0] < 0.9
    assert out["mmp_lo"][0, 0] <= out["mmp"][0, 0] <= out["mmp_hi"][0, 0]
    lo, hi = wilson_interval(np.array([0.5]), 100)
    assert hi[0] - lo[0] == pytest.approx(0.1924, abs=1e-3)  # Wilson 95 % half-width ~0.096 at p = 0.5, n = 100


def test_command_end_to_end_and_bad_input_writes_nothing(tmp_path):
    runner = CliRunner()
    out = tmp_path / "out"
    model = build_model("single")
    lum = 500.0
    # a "measured" ROI: the bench's own noise-free sequence behind 8 baseline frames (LED OFF)
    s = sequence_series(model, np.array([95.0]), np.array([0.3]), np.array([lum]), {}, 30)["main"][0, 0]
    off = (model.captures[0].rate * 1.0 + model.captures[0].dark_e - model.captures[0].dark_e) * model.captures[0].refer
    x = np.concatenate([np.full(8, off), s])
    sp, mp = _write(tmp_path, {"ROI_0": x}, ["roi,frequency_hz,duty,start_index,luminance_cd_m2,panel",
                                             f"ROI_0,95,0.3,8,{lum},main"])
    args = ["flicker-bench", "--sensor", "single", "--n-freq", "0", "--freq", "95", "--freq", "300", "--duty", "0.3",
            "--duty", "0.6", "--luminance", str(lum), "--frames", "30", "--out", str(out), "--capture-series", str(sp),
            "--capture-meta", str(mp), "--report", str(out / "report.md")]
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    doc = json.loads((out / "flicker_bench.json").read_text())
    assert len(doc["preset_sha256"]) == 64
    assert (out / "flicker_bench.csv").read_text().startswith("# lfmbench flicker-bench")
    meas = doc["measured"][0]
    assert meas["fmi_measured"] == pytest.approx(meas["fmi_seq_sim"], rel=1e-12)
    assert math.isfinite(meas["fmi_sim"]) and meas["fmi_sim"] >= meas["fmi_seq_sim"] - 1e-12
    assert (out / "flicker_bench_miss.png").stat().st_size < 300_000
    # bad input: one line naming the option, no output directory made
    out2 = tmp_path / "out2"
    for bad, name in ((["--freq", "0"], "--freq"), (["--duty", "1.5"], "--duty"), (["--fps", "1000"], "--fps")):
        a = ["flicker-bench", "--sensor", "single", "--n-freq", "0", "--out", str(out2)] + bad
        if "--freq" not in bad:
            a += ["--freq", "95"]
        r = runner.invoke(app, a)
        assert r.exit_code == 2 and name in r.output and len(r.output.strip().splitlines()) == 1, r.output
    assert not out2.exists()


@pytest.mark.parametrize("series,meta,match", [
    ("", ["roi,frequency_hz,duty,start_index", "ROI_0,95,0.2,0"], r"series\.csv: empty file"),
    (",ROI_0\n0,1.0\n1,inf\n", ["roi,frequency_hz,duty,start_index", "ROI_0,95,0.2,0"],
     r"series\.csv: field 'ROI_0' row 3: not a finite number"),
    (",ROI_0,ROI_1\n0,1.0,2.0\n1,2.0\n", ["roi,frequency_hz,duty,start_index", "ROI_1,95,0.2,0"],
     r"series\.csv: field 'ROI_1' row 3: missing value"),
    (",ROI_0\n0,1.0\n1,2.0\n", ["roi,duty,start_index", "ROI_0,0.2,0"], r"meta\.csv: missing column 'frequency_hz'"),
    (",ROI_0\n0,1.0\n1,2.0\n", ["frequency_hz,duty,start_index", "95,0.2,0"], r"meta\.csv: missing column 'roi'"),
    (",ROI_0\n0,1.0\n1,2.0\n", ["roi,frequency_hz,duty,start_index", "ROI_0,95,0.2"], r"meta\.csv: row 2 has 3 fields"),
    (",ROI_0\n0,1.0\n1,2.0\n", ["roi,frequency_hz,duty,start_index", "ROI_0,0,0.2,0"],
     r"meta\.csv: field 'frequency_hz' row 2: 0 Hz outside"),
    (",ROI_0\n0,1.0\n1,2.0\n", ["roi,frequency_hz,duty,start_index", "ROI_0,2e6,0.2,0"],
     r"meta\.csv: field 'frequency_hz' row 2: 2e\+06 Hz outside"),
    (",ROI_0\n0,1.0\n1,2.0\n", ["roi,frequency_hz,duty,start_index", "ROI_0,95,0,0"], r"meta\.csv: field 'duty' row 2"),
    (",ROI_0\n0,1.0\n1,2.0\n", ["roi,frequency_hz,duty,start_index", "ROI_0,95,0.2,x"],
     r"meta\.csv: field 'start_index' row 2: not a number"),
    (",ROI_0\n0,1.0\n1,2.0\n", ["roi,frequency_hz,duty,start_index"], r"meta\.csv: no ROI row"),
])
def test_more_bad_capture_files_one_line(tmp_path, series, meta, match):
    """Empty files, non-finite and missing values, missing meta columns, short rows, frequencies outside the
    model, zero duty: one line naming the file and the field."""
    sp, mp = tmp_path / "series.csv", tmp_path / "meta.csv"
    sp.write_text(series)
    mp.write_text("\n".join(meta) + "\n")
    with pytest.raises(BenchError, match=match) as exc:
        read_captures(sp, mp)
    assert "\n" not in str(exc.value)


def test_command_bad_capture_csv_and_grid_one_line_nothing_written(tmp_path):
    """Through the command: a CSV with a missing column or a non-numeric value, a frequency that is not a finite
    number: exit code 2, one line naming the file / option, no output directory."""
    sp, mp = _write(tmp_path, {"ROI_0": [1.0, 2.0, 3.0]}, ["roi,frequency_hz,start_index", "ROI_0,95,0"])
    bad_meta = tmp_path / "bad_meta.csv"
    bad_meta.write_text("roi,frequency_hz,duty,start_index\nROI_0,95,half,0\n")
    out = tmp_path / "out"
    base = ["flicker-bench", "--sensor", "single", "--n-freq", "0", "--out", str(out)]
    cases = [(["--freq", "95", "--capture-series", str(sp), "--capture-meta", str(mp)], "missing column 'duty'"),
             (["--freq", "95", "--capture-series", str(sp), "--capture-meta", str(bad_meta)],
              "field 'duty' row 2: not a number"),
             (["--freq", "nan"], "--freq")]
    runner = CliRunner()
    for extra, text in cases:
        r = runner.invoke(app, base + extra)
        assert r.exit_code == 2 and text in r.output and len(r.output.strip().splitlines()) == 1, (extra, r.output)
    assert not out.exists()
