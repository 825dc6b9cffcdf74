"""Tests of lfmbench.metrics.flicker: P2020 FMI / FDI / MMP on hand-worked series (the definitions of the
CARpublic/P2020-flicker reference implementation), region series, dropout and the per-light summary."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from lfmbench.metrics import flicker as fm
from tests.data.metrics.data import make_batch


def test_fmi_hand_values():
    assert float(fm.fmi([1.0, 3.0])) == pytest.approx(0.5)
    assert float(fm.fmi([2.0, 2.0, 2.0])) == 0.0
    assert float(fm.fmi([0.0, 5.0, 1.0])) == 1.0
    # frames along dim 0, two ROIs (as the reference: roi_means rows = frames)
    x = torch.tensor([[1.0, 4.0], [3.0, 4.0], [2.0, 1.0]])
    assert torch.allclose(fm.fmi(x, dim=0), torch.tensor([0.5, 0.6]))
    # start_index drops the first frames: [3, 2] -> 1/5
    assert float(fm.fmi([1.0, 3.0, 2.0], start_index=1)) == pytest.approx(0.2)
    with pytest.raises(ValueError, match="start_index"):
        fm.fmi([1.0, 2.0], start_index=2)


def test_mmp_hand_values():
    assert float(fm.mmp([7.0, 7.0, 7.0])) == 1.0  # constant series
    assert float(fm.mmp([1.0, 1.0, 1.0, 1.2])) == pytest.approx(0.75)  # mean 1.05, band (0.945, 1.155)
    assert float(fm.mmp([1.0, 1.0, 1.0, 2.0])) == 0.0  # mean 1.25, band (1.125, 1.375) holds none
    # band edges are strict: mean 1, delta 0.5 -> (0.5, 1.5); 0.5 and 1.5 are outside
    assert float(fm.mmp([0.5, 1.5, 1.0, 1.0], delta=0.5)) == pytest.approx(0.5)


def test_fdi_hand_values_and_reference_baseline():
    # s = [0, 0.05, 1, 2] -> two of four frames above 0.1
    assert float(fm.fdi([1.0, 1.05, 2.0, 3.0], x_off=1.0)) == pytest.approx(0.5)
    assert float(fm.fdi([1.0, 1.05, 2.0, 3.0], x_off=1.0, contrast_threshold=1.5)) == pytest.approx(0.25)
    # reference mode: x_off = mean of the first start_index // 4 frames (light OFF baseline)
    series = [2.0, 2.0, 9.0, 9.0, 9.0, 9.0, 9.0, 9.0, 2.0, 4.0, 2.1, 3.0]
    # start 8 -> x_off = mean([2, 2]) = 2; measured [2, 4, 2.1, 3] -> s = [0, 1, 0.05, 0.5] -> 2/4
    assert float(fm.fdi(series, start_index=8)) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="start_index"):
        fm.fdi([1.0, 2.0])
    # per-ROI x_off along the non-frame dim
    x = torch.tensor([[1.0, 10.0], [2.0, 10.5]])
    assert torch.allclose(fm.fdi(x, x_off=torch.tensor([1.0, 10.0]), dim=0), torch.tensor([0.5, 0.0]))
    # zero OFF level: positive frames are detected (inf), zero frames are not (NaN), as numpy
    assert float(fm.fdi([0.0, 1.0], x_off=0.0)) == pytest.approx(0.5)


def test_saturation_warning_compares_in_float64():
    # the P2020 reference (NumPy float64) flags 0.1000000001 > 0.1; float32 rounds both to the same value
    assert fm.saturation_warning([0.1000000001], 0.1)[0] is True
    assert fm.saturation_warning(torch.tensor([0.1000000001], dtype=torch.float64), 0.1)[0] is True
    assert fm.saturation_warning([0.1], 0.1)[0] is False
    flag, idx = fm.saturation_warning(torch.tensor([[0.3, 0.1]], dtype=torch.float32), 0.2)
    assert flag is True and idx.tolist() == [[True, False]]


def test_saturation_warning_strictly_above():
    flag, idx = fm.saturation_warning([100.0, 240.0, 241.0], 240.0)
    assert flag is True and idx.tolist() == [False, False, True]
    assert fm.saturation_warning([1.0], 2.0)[0] is False


def test_fsi_equals_fmi_through_lfmbench_flicker():
    x = torch.tensor([[0.2, 0.9, 0.5], [1.0, 1.0, 1.0]], dtype=torch.float64)
    assert torch.allclose(fm.fsi(x), fm.fmi(x))
    assert float(fm.fsi([0.0, 0.0])) == 0.0  # all dark: defined 0 by flicker_severity
    assert float(fm.fsi([-1.0, 1.0])) == 1.0  # negative noise clipped to 0


def test_series_error_and_dropout():
    p, g = torch.tensor([1.0, 3.0]), torch.tensor([2.0, 2.0])
    assert float(fm.series_rel_rmse(p, g)) == pytest.approx(0.5)  # rms 1 / mean 2
    assert fm.dropout_mask(torch.tensor([0.9, 1.1, 5.0]), torch.tensor([2.0, 2.0, 2.0])).tolist() == [True, False, False]


def test_region_series_hand_built():
    img = torch.arange(16, dtype=torch.float32).reshape(1, 1, 1, 4, 4).repeat(1, 2, 1, 1, 1)
    img[:, 1] += 100
    li = torch.full((1, 2, 1, 4, 4), -1)
    li[0, 0, 0, 0, :2] = 0  # pixels 0, 1
    li[0, 0, 0, 3, 3] = 2  # pixel 15
    li[0, 1, 0, 1, 1] = 0  # pixel 5 (+100)
    means, cnt = fm.region_series(img, li)
    assert means.shape == (1, 3, 2)
    assert means[0, 0].tolist() == [0.5, 105.0]
    assert math.isnan(float(means[0, 1, 0])) and cnt[0, 1].tolist() == [0.0, 0.0]
    assert float(means[0, 2, 0]) == 15.0 and math.isnan(float(means[0, 2, 1]))
    with pytest.raises(ValueError, match="light_index"):
        fm.region_series(img, li[:, :1])


def _roi_mean(img: torch.Tensor, mask: torch.Tensor) -> float:
    return float(img[mask].double().mean())


def test_region_flicker_metrics_lpd_vs_gt():
    b = make_batch(lpd_on=(0.0, 0.5, 1.0), static_on=(1.0, 0.0, 0.4))
    lpd = b["lpd_lcg_e"]
    res = fm.region_flicker_metrics(lpd, b["gt"], b["light_index"], b["saturated"], lpd)[0]
    assert res["n_lights"] == 2 and res["region_frames"] == 6
    # extinguished: light 0 in frame 0, light 1 in frame 1 (output far below half the GT)
    assert res["dropout_rate"] == pytest.approx(2 / 6)
    l0 = res["lights"][0]
    # independent ROI means with boolean masks
    mask = lambda t, j: b["light_index"][0, t, 0] == j  # noqa: E731
    ser = [_roi_mean(lpd[0, t, 0], mask(t, 0)) for t in range(3)]
    assert l0["series_pred"] == pytest.approx(ser, rel=1e-6)
    assert l0["fmi_pred"] == pytest.approx((max(ser) - min(ser)) / (max(ser) + min(ser)), rel=1e-6)
    # the GT light is steady; its ROI mean moves only with the background gradient under it
    assert l0["fmi_gt"] < 0.01 and l0["mmp_gt"] == 1.0
    assert l0["fsi_input"] == pytest.approx(l0["fmi_pred"], rel=1e-6)
    gts = [_roi_mean(b["gt"][0, t, 0], mask(t, 0)) for t in range(3)]
    rmse = math.sqrt(np.mean((np.array(ser) - np.array(gts)) ** 2)) / np.mean(gts)
    assert l0["series_rel_rmse"] == pytest.approx(rmse, rel=1e-6)
    # FDI: the OFF frame of light 0 is not detected, the other two are
    assert l0["fdi_pred"] == pytest.approx(2 / 3) and l0["fdi_gt"] == 1.0
    assert res["saturation_flag"] is False


def test_region_flicker_metrics_gt_is_perfect_and_saturation():
    b = make_batch()
    r = fm.region_flicker_metrics(b["gt"], b["gt"], b["light_index"])[0]
    assert r["dropout_rate"] == 0 and r["series_rel_rmse"] == 0 and r["fmi_abs_err"] == 0 and r["mmp_pred"] == 1
    hot = make_batch(led_level=1e9)  # beyond every capture's full well
    r = fm.region_flicker_metrics(hot["gt"], hot["gt"], hot["light_index"], hot["saturated"])[0]
    # every capture clips wherever the LPD saw the light ON: frames 1, 2 of light 0 (frame 0 is OFF)
    assert r["saturation_flag"] is True and r["lights"][0]["saturated_frames"] == 2


def test_region_metrics_no_lights():
    b = make_batch()
    li = torch.full_like(b["light_index"], -1)
    r = fm.region_flicker_metrics(b["gt"], b["gt"], li)[0]
    assert r["n_lights"] == 0 and math.isnan(r["dropout_rate"]) and math.isnan(r["fmi_pred"])


def test_fdi_without_off_reference_is_nan():
    b = make_batch()
    li = b["light_index"].clone()
    li[li < 0] = 1  # every pixel belongs to a light: no ring, no OFF reference
    r = fm.region_flicker_metrics(b["gt"], b["gt"], li)[0]
    assert all(math.isnan(x["fdi_pred"]) for x in r["lights"])


def test_ring_series_matches_full_image_rings():
    """The per-light box shortcut of the FDI OFF rings equals rings built on the whole image (brute force:
    dilate every light's mask over the full frame), for several images at once, lights touching the border,
    a light id without pixels and lights moving between frames."""
    from lfmbench.metrics.flicker import _ring_series
    from lfmbench.metrics.regions import dilate

    g = torch.Generator().manual_seed(3)
    b, f, h, w, n, ring = 2, 3, 40, 56, 6, 3
    li = torch.full((b, f, 1, h, w), -1, dtype=torch.long)
    for bi in range(b):
        for fi in range(f):
            for j in (0, 1, 2, 4, 5):  # id 3 has no pixel
                y = int(torch.randint(0, h - 4, (1,), generator=g))
                x = int(torch.randint(-2, w - 3, (1,), generator=g))
                li[bi, fi, 0, y:y + 4, max(x, 0):x + 5] = j
    imgs = [torch.rand(b, f, 2, h, w, generator=g, dtype=torch.float64) * 100 for _ in range(2)]
    got = _ring_series(imgs, li, n, ring)
    idx = li.reshape(b * f, h, w)
    for im, out in zip(imgs, got):
        x = im.mean(dim=2).reshape(b * f, h, w)
        for j in range(n):
            if not bool((idx == j).any()):
                assert torch.isnan(out[:, j]).all()
                continue
            rg = dilate(idx == j, ring) & ~dilate(idx >= 0, 1)
            cnt = rg.sum(dim=(1, 2)).double()
            ref = torch.where(cnt > 0, (x * rg).sum(dim=(1, 2)) / cnt.clamp_min(1), torch.tensor(float("nan")))
            torch.testing.assert_close(out[:, j, :].reshape(-1), ref, equal_nan=True, rtol=1e-12, atol=1e-12)
