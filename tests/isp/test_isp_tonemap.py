"""lfmbench.isp.tonemap: Reinhard by hand, the reference statistics, Durand's detail, bad input."""
from __future__ import annotations

import math

import pytest
import torch

from lfmbench.isp import TONEMAP, ToneMap, luminance, reinhard2002, reinhard2002_stats, tonemap


# ------------------------------------------------------------------------------------------------ tone mapping
def test_reinhard_against_hand_computation():
    lum = torch.tensor([0.5, 2.0, 8.0], dtype=torch.float64)
    rgb = lum.reshape(1, 1, 3).expand(1, 3, 3).reshape(1, 3, 1, 3).clone()  # grey pixels: luminance = value
    st = reinhard2002_stats(rgb)
    log_avg = math.exp(sum(math.log(1e-6 + v) for v in lum.tolist()) / 3)
    assert float(st["log_avg"]) == pytest.approx(log_avg, rel=1e-9)
    lw = 8.0 / log_avg
    assert float(st["white"]) == pytest.approx(lw, rel=1e-9)
    out = reinhard2002(rgb, st["log_avg"], st["white"])
    for i, v in enumerate(lum.tolist()):
        L = 0.18 / log_avg * v
        want = L * (1 + L / (lw * lw)) / (1 + L)
        assert out[0, 1, 0, i].item() == pytest.approx(want, rel=1e-9)
    # the reference's maximum maps to 1 only when it is the white point scaled by the key: L_white = max
    st2 = {"log_avg": st["log_avg"], "white": 0.18 / st["log_avg"] * 8.0}
    assert reinhard2002(rgb, **st2)[0, 1, 0, 2].item() == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("method", sorted(TONEMAP))
def test_tonemap_uses_the_reference_statistics(method):
    gen = torch.Generator().manual_seed(0)
    gt = torch.rand(2, 3, 3, 24, 32, generator=gen, dtype=torch.float64) ** 4 * 1e4 + 1.0
    same = tonemap(gt, gt, method)
    assert torch.equal(same, tonemap(gt, None, method))
    brighter = tonemap(2.0 * gt, gt, method)  # an estimate twice too bright looks brighter, not the same
    assert bool((luminance(brighter) >= luminance(same) - 1e-12).all())
    assert float((luminance(brighter) - luminance(same)).mean()) > 0.01
    assert same.shape == gt.shape and same.dtype == gt.dtype
    assert torch.allclose(ToneMap(method)(2.0 * gt, gt), brighter)
    # monotone: a brighter reference pixel stays brighter (global operators; local ones up to the detail layer)
    if method != "durand2002":
        for i in range(gt.shape[0]):  # one tone curve per item
            lum, out = luminance(gt[i]).flatten(), luminance(same[i]).flatten()
            order = torch.argsort(lum)
            assert bool((torch.diff(out[order]) >= -1e-12).all())


def test_durand_keeps_detail_and_compresses_base():
    """Two flat halves 1000x apart with a small texture: the output range of the halves shrinks to about the
    target contrast, the texture's relative amplitude is kept (Durand & Dorsey 2002: detail untouched)."""
    h, w = 32, 64
    y, x = torch.meshgrid(torch.arange(h), torch.arange(w), indexing="ij")
    base = torch.where(x < w // 2, 1.0, 1000.0).double()
    tex = 1.0 + 0.1 * torch.sin(2 * math.pi * y / 4.0).double()
    lum = base * tex
    rgb = lum.expand(1, 3, h, w).clone()
    out = luminance(tonemap(rgb, method="durand2002", contrast=10.0, radius=3, eps=0.01, percentile=0.0))[0, 0]
    left, right = out[:, 4:24], out[:, 40:60]
    ratio = float(right.mean() / left.mean())
    assert 5.0 < ratio < 20.0  # 1000:1 scene, 10:1 target contrast of the base
    rel_amp = float((right.amax() - right.amin()) / right.mean())
    assert 0.12 < rel_amp < 0.3  # the texture's +-10 % (0.2 peak to peak) survives


def test_tonemap_bad_method_and_params():
    with pytest.raises(ValueError, match="must be one of"):
        tonemap(torch.rand(1, 3, 4, 4), method="nope")
    with pytest.raises(ValueError, match="unknown parameter"):
        tonemap(torch.rand(1, 3, 4, 4), method="reinhard2002", contrast=3)
