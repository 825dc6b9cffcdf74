"""Tests of lfmbench.metrics.hdr: hand-checked PSNR numbers, mu-law, SSIM against scikit-image, cvvdp offline."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from lfmbench.metrics import hdr


def _pair(seed=0, shape=(2, 3, 1, 16, 16)):
    g = torch.Generator().manual_seed(seed)
    gt = 10.0 + 990.0 * torch.rand(shape, generator=g, dtype=torch.float64)
    gt.view(shape[0], -1)[:, 0] = 1000.0  # peak exactly 1000 in every sample
    return gt


def test_psnr_known_mse():
    # MSE = 0.1^2 = 0.01 with peak 1 -> 20 dB; peak 2 -> 10 log10(400) = 26.0206 dB
    p, g = torch.full((3, 5), 0.1), torch.zeros(3, 5)
    assert torch.allclose(hdr.psnr(p, g), torch.full((3,), 20.0), atol=1e-5)
    assert float(hdr.psnr(p, g, 2.0)[0]) == pytest.approx(10 * math.log10(400.0), abs=1e-5)
    assert math.isinf(float(hdr.psnr(g, g)[0]))


def test_psnr_l_normalises_by_gt_peak():
    gt = _pair()
    pred = gt - 10.0  # normalised error 10 / 1000 = 0.01 everywhere -> MSE 1e-4 -> 40 dB
    assert torch.allclose(hdr.psnr_l(pred, gt), torch.full((2,), 40.0, dtype=torch.float64), atol=1e-9)


def test_mu_law_values():
    h = torch.tensor([0.0, 0.5, 1.0], dtype=torch.float64)
    t = hdr.mu_law(h)
    assert t[0] == 0 and t[2] == pytest.approx(1.0)
    assert float(t[1]) == pytest.approx(math.log(1 + 2500) / math.log(5001), rel=1e-12)
    with pytest.raises(ValueError, match="mu"):
        hdr.mu_law(h, mu=0.0)


def test_psnr_mu_hand_computed():
    gt = torch.tensor([[1000.0, 500.0]], dtype=torch.float64)
    pred = torch.tensor([[1000.0, 250.0]], dtype=torch.float64)
    t = lambda x: math.log(1 + 5000 * x) / math.log(5001)  # noqa: E731
    mse = (t(0.25) - t(0.5)) ** 2 / 2
    assert float(hdr.psnr_mu(pred, gt)[0]) == pytest.approx(10 * math.log10(1 / mse), rel=1e-10)
    assert math.isinf(float(hdr.psnr_mu(gt, gt)[0]))


def test_normalize_modes_and_errors():
    gt = _pair()
    p, g = hdr.normalize_hdr(gt * 2, gt, "max")
    assert float(g.amax()) == 1.0 and float(p.amax()) == 1.0  # prediction clipped to [0, 1]
    p, g = hdr.normalize_hdr(gt, gt, "p99_tanh")
    assert float(g.amax()) < 1.0 and torch.equal(p, g)
    with pytest.raises(ValueError, match="mode"):
        hdr.normalize_hdr(gt, gt, "bogus")
    with pytest.raises(ValueError, match="same shape"):
        hdr.psnr_mu(gt[:, :2], gt)
    with pytest.raises(TypeError, match="pred"):
        hdr.psnr_mu(np.zeros((2, 2)), gt)


def test_ssim_mu_matches_scikit_image_interior():
    from skimage.metrics import structural_similarity

    gt = _pair(1, (1, 1, 1, 40, 40))
    noise = torch.randn(gt.shape, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    pred = (gt * (1 + 0.2 * noise)).clamp_min(0)
    smap = hdr.ssim_mu_map(pred, gt)
    assert smap.shape == (1, 1, 40, 40)
    p, g = hdr.normalize_hdr(pred, gt)
    tp, tg = hdr.mu_law(p)[0, 0, 0].numpy(), hdr.mu_law(g)[0, 0, 0].numpy()
    ref, full = structural_similarity(tp, tg, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                      data_range=1.0, full=True)
    pad = 5  # skimage's mean crops (win_size - 1) // 2 = 5 px with sigma 1.5 (win 11)
    assert float(smap[0, 0, pad:-pad, pad:-pad].mean()) == pytest.approx(ref, abs=1e-6)
    assert float(hdr.ssim_mu(gt, gt)[0]) == pytest.approx(1.0, abs=1e-12)
    assert float(hdr.ssim_mu(pred, gt)[0]) < 0.99


def test_ssim_too_small_raises():
    x = torch.ones(1, 1, 4, 4)
    with pytest.raises(ValueError, match="too small"):
        hdr.ssim_mu(x, x)


def test_bayer_luminance_quad_mean():
    x = torch.tensor([[1.0, 2.0, 5.0, 5.0], [3.0, 6.0, 5.0, 5.0]])
    assert torch.equal(hdr.bayer_luminance(x), torch.tensor([[3.0, 5.0]]))
    with pytest.raises(ValueError, match="even"):
        hdr.bayer_luminance(torch.ones(3, 4))


def test_display_luminance_maps_p99_to_peak():
    gt = torch.linspace(0, 100, 10001)
    lum, scale = hdr.to_display_luminance(gt, gt)
    assert float(torch.quantile(lum, 0.99)) == pytest.approx(hdr.CVVDP_DISPLAY_PEAK_CD_M2, rel=1e-4)
    lum2, s2 = hdr.to_display_luminance(gt, gt, cd_per_unit=2.0)
    assert s2 == 2.0 and float(lum2[-1]) == 200.0
    with pytest.raises(ValueError, match="cd_per_unit"):
        hdr.to_display_luminance(gt, gt, cd_per_unit=-1.0)


def test_cvvdp_and_pu21_offline_on_tensors():
    try:
        hdr.load_pycvvdp()
    except hdr.CvvdpUnavailableError as exc:  # optional dependency
        pytest.skip(f"cvvdp not importable here: {exc}")
    import sys

    gt = _pair(3, (1, 3, 1, 64, 64)).float()
    noisy = gt * (1 + 0.3 * torch.randn(gt.shape, generator=torch.Generator().manual_seed(4)))
    jod_same, jod_noisy = float(hdr.cvvdp_jod(gt, gt)[0]), float(hdr.cvvdp_jod(noisy.clamp_min(0), gt)[0])
    assert jod_same == pytest.approx(10.0, abs=1e-3)
    assert jod_noisy < jod_same - 0.1
    pu_noisy = float(hdr.pu21_psnr(noisy.clamp_min(0), gt)[0])
    assert pu_noisy < float(hdr.pu21_psnr(gt * 1.001, gt)[0])
    assert "standard_hdr_linear" in hdr.cvvdp_config()
    # the torchvision shim (if it was needed) must not leak into sys.modules
    tv = sys.modules.get("torchvision")
    assert tv is None or hasattr(tv, "__file__")


def test_quantile_subsamples_beyond_torch_limit(monkeypatch):
    x = torch.arange(1000, dtype=torch.float64)
    monkeypatch.setattr(hdr, "_QUANTILE_MAX", 100)  # forces a stride of 10
    assert float(hdr._quantile(x, 0.5)) == pytest.approx(495.0, abs=1.0)
    q = hdr._quantile(torch.stack([x, 2 * x]), 0.99, dim=1)
    assert q.shape == (2,) and float(q[1]) == pytest.approx(2 * float(q[0]))
