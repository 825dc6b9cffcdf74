"""Display-referred secondary metrics (lfmbench/metrics/display.py): values against an independent computation,
the primary metrics untouched, the leaderboard ranking old and new result files together."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from lfmbench import evaluation as ev
from lfmbench.isp import ISP
from lfmbench.metrics import REGISTRY, SECONDARY_GROUPS, ScoreOptions, display, hdr, score_batch
from tests.data.metrics.data import make_batch


def test_display_metrics_against_numpy_and_skimage():
    skm = pytest.importorskip("skimage.metrics")
    b = make_batch(seed=3, noise=True)
    pred = b["gt"] * 1.3 + 5.0
    v = display.display_metrics(pred, b["gt"], "ovt")
    p, g = ISP("default", "ovt").pair(pred, b["gt"])
    pn, gn = p.double().numpy()[0], g.double().numpy()[0]  # (F, 3, H, W)
    mse = np.mean((pn - gn) ** 2)
    assert float(v["psnr_srgb"][0]) == pytest.approx(10 * math.log10(1.0 / mse), rel=1e-4)
    # scikit-image SSIM with kornia's settings (Gaussian sigma 1.5, population covariance), away from the border
    sk = [skm.structural_similarity(pn[f, c], gn[f, c], data_range=1.0, gaussian_weights=True, sigma=1.5,
                                    use_sample_covariance=False, full=True)[1][5:-5, 5:-5].mean()
          for f in range(pn.shape[0]) for c in range(3)]
    smap = hdr.ssim_map(p, g)  # (1, F*3, H, W): what ssim_srgb averages
    assert np.allclose(smap[0, :, 5:-5, 5:-5].mean(dim=(-1, -2)).double().numpy(), sk, atol=2e-4)
    assert float(display.ssim_srgb(p, g)[0]) == pytest.approx(float(smap.mean()), rel=1e-6)


def test_identical_images_and_a_brighter_estimate():
    b = make_batch(seed=0)
    same = score_batch(b["gt"].clone(), b)[0]
    assert math.isinf(same["psnr_srgb"]) and same["ssim_srgb"] == pytest.approx(1.0, abs=1e-6)
    worse = score_batch(b["gt"] * 3.0, b)[0]
    assert 0 < worse["psnr_srgb"] < 40 and worse["ssim_srgb"] < 1.0


def test_primary_metrics_do_not_change_with_the_display_columns():
    """The published protocol's numbers: every metric outside the secondary groups is the same with the display
    columns on (default) and off (isp=None), bit for bit (they are computed from the same tensors)."""
    b = make_batch(seed=2, noise=True)
    pred = b["lpd_hcg_e"] if "lpd_hcg_e" in b else b["gt"] * 0.8
    on = score_batch(pred, b)[0]
    off = score_batch(pred, b, ScoreOptions(isp=None))[0]
    secondary = {n for n, s in REGISTRY.items() if s.group in SECONDARY_GROUPS}
    assert secondary == {"psnr_srgb", "ssim_srgb"} and secondary <= set(on) and not secondary & set(off)
    assert {k: v for k, v in on.items() if k not in secondary} == off


def test_no_sensor_is_an_error_note_not_a_crash():
    b = make_batch(seed=0)
    b["meta"] = {k: v for k, v in b["meta"].items() if k != "sensor"}
    r = score_batch(b["gt"] * 2, b)[0]
    assert math.isnan(r["psnr_srgb"]) and any("names no sensor" in e for e in r["errors"])
    assert not math.isnan(r["psnr_mu"])
    r = score_batch(b["gt"] * 2, b, ScoreOptions(sensor="imx490"))[0]  # the sensor given explicitly
    assert math.isfinite(r["psnr_srgb"])


def test_result_records_the_pipeline_and_old_results_still_rank(tmp_path):
    batches = [make_batch(seed=i) for i in range(2)]
    new = ev.evaluate(lambda x: x["gt"] * 0.9, batches, method_spec="a", output=tmp_path / "a.json", repeats=1,
                      progress=False)
    assert new["options"]["isp"]["name"] == "default" and len(new["options"]["isp"]["sha256"]) == 64
    assert "psnr_srgb" in new["aggregate"] and "ssim_srgb" in new["aggregate"]
    # a result written before the display columns existed: no isp option, no secondary metric versions
    ev.evaluate(lambda x: x["gt"] * 0.5, batches, method_spec="b", output=tmp_path / "b.json", repeats=1,
                progress=False, options=ScoreOptions(isp=None))
    old = json.loads((tmp_path / "b.json").read_text())
    for k in ("psnr_srgb", "ssim_srgb"):
        old["versions"]["metrics"].pop(k)
    assert "isp" not in old["options"]
    (tmp_path / "b.json").write_text(json.dumps(old))
    runs = ev.load_runs([tmp_path / "a.json", tmp_path / "b.json"])
    ev.check_comparable(runs)
    rows = ev.leaderboard_rows(runs)
    assert [r["method"] for r in rows] == ["a", "b"]
    md = ev.leaderboard_markdown(rows)
    assert "PSNR sRGB dB" in md and "SSIM sRGB" in md
    # two results with different ISP pipelines are not ranked together
    ev.evaluate(lambda x: x["gt"] * 0.5, batches, method_spec="c", output=tmp_path / "c.json", repeats=1,
                progress=False, options=ScoreOptions(isp="local"))
    with pytest.raises(ev.IncomparableRunsError, match="display ISP differs"):
        ev.check_comparable(ev.load_runs([tmp_path / "a.json", tmp_path / "c.json"]))


def test_bad_pipeline_is_refused_before_any_data(tmp_path):
    bad = tmp_path / "isp.yaml"
    bad.write_text("format: lfmbench-isp\nname: x\nsteps: [{op: demosaic, method: vng}]\n")

    def never():
        raise AssertionError("the data source must not be read")
        yield

    with pytest.raises(ValueError, match=r"isp\.yaml: field 'steps\[0\]\.method'"):
        ev.evaluate("lpd_only", never(), options=ScoreOptions(isp=str(bad)), progress=False)
