"""Tests of lfmbench.metrics.regions (errors outside LED regions) and the metric registry / score_batch."""
from __future__ import annotations

import math

import pytest
import torch

from lfmbench.metrics import REGISTRY, ScoreOptions, hdr, metric_versions, regions, score_batch
from tests.data.metrics.data import make_batch


def _single_light(h=48, w=48):
    li = torch.full((1, 1, 1, h, w), -1)
    li[0, 0, 0, 24, 24] = 0
    return li


def test_led_mask_and_ghost_zone_pixel_counts():
    li = _single_light()
    assert int(regions.led_mask(li, 2).sum()) == 5 * 5
    assert int(regions.ghost_zone(li, 2, 16).sum()) == 33 * 33 - 5 * 5
    with pytest.raises(ValueError, match="ring_px"):
        regions.ghost_zone(li, 4, 4)
    with pytest.raises(ValueError, match="light_index"):
        regions.led_mask(li[0])


def test_masked_psnr_mu_known_mse():
    gt = torch.full((1, 1, 1, 4, 4), 1000.0, dtype=torch.float64)
    pred = gt.clone()
    pred[..., 0, 0] = 0.0  # T(1) - T(0) = 1 at one pixel
    mask = torch.zeros_like(gt, dtype=torch.bool)
    mask[..., 0, :] = True  # 4 pixels, one with error 1 -> MSE 0.25 -> 6.0206 dB
    assert float(regions.masked_psnr_mu(pred, gt, mask)[0]) == pytest.approx(10 * math.log10(4), rel=1e-12)
    assert math.isnan(float(regions.masked_psnr_mu(pred, gt, torch.zeros_like(mask))[0]))


def test_outside_led_metrics_comet():
    h = w = 48
    li = _single_light(h, w)
    gt = torch.full((1, 1, 1, h, w), 10.0, dtype=torch.float64)
    gt[..., 24, 24] = 10000.0
    pred = gt.clone()
    pred[..., 24, 24] = 0.0  # error inside the LED region only: outside stays perfect
    r = regions.outside_led_metrics(pred, gt, li)[0]
    assert math.isinf(r["psnr_mu_outside"]) and r["ghost_mae_mu"] == 0 and r["comet_excess_mu"] == 0
    # a comet: 10 trail pixels right of the LED (inside the ghost zone) brighter than the GT
    pred[..., 24, 30:40] = 5000.0
    r = regions.outside_led_metrics(pred, gt, li)[0]
    t = lambda x: math.log(1 + 5000 * x) / math.log(5001)  # noqa: E731
    excess = 10 * (t(0.5) - t(0.001)) / (33 * 33 - 25)
    assert r["comet_excess_mu"] == pytest.approx(excess, rel=1e-9)
    assert r["ghost_mae_mu"] == pytest.approx(excess, rel=1e-9)
    assert math.isfinite(r["psnr_mu_outside"])


def test_registry_has_versions_and_references():
    v = metric_versions()
    assert {"psnr_l", "psnr_mu", "ssim_mu", "pu21_psnr", "cvvdp_jod", "fmi_pred", "fdi_pred", "mmp_pred",
            "fsi_input", "series_rel_rmse", "dropout_rate", "psnr_mu_outside", "ghost_mae_mu"} <= set(v)
    assert all(s.version and s.reference and s.unit for s in REGISTRY.values())


def test_score_batch_keys_and_identity():
    b = make_batch(b=2)
    res = score_batch(b["gt"], b)
    assert len(res) == 2
    r = res[0]
    assert math.isinf(r["psnr_mu"]) and r["ssim_mu"] == pytest.approx(1.0) and r["mmp_pred"] == 1.0
    assert set(REGISTRY) - {"pu21_psnr", "cvvdp_jod"} <= set(r)
    with pytest.raises(ValueError, match="shape"):
        score_batch(b["gt"][:, :2], b)


def test_score_batch_perceptual_optional():
    try:
        hdr.load_pycvvdp()
    except hdr.CvvdpUnavailableError as exc:
        pytest.skip(f"cvvdp not importable here: {exc}")
    b = make_batch(h=32, w=32)
    r = score_batch(b["lpd_lcg_e"], b, ScoreOptions(perceptual=True))[0]
    assert 0 < r["cvvdp_jod"] < 10 and math.isfinite(r["pu21_psnr"])
