"""lfmbench.isp.demosaic: bilinear and Malvar-He-Cutler against colour-demosaicing and a smooth scene, shapes,
gradients, bad input."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from lfmbench.isp import DEMOSAIC, Demosaic, clamp_to_neighbours, demosaic_bilinear, demosaic_malvar2004
from lfmbench.sensor import load_preset, mosaic


# --------------------------------------------------------------------------------------------------- demosaic
def _smooth_scene(h: int, w: int, dtype=torch.float64) -> torch.Tensor:
    """(1, 3, H, W): a smooth analytic colour image as natural images are (Malvar et al. 2004's premise): a
    luminance pattern (a sinusoid of periods 11 and 13 px) shared by the channels, times a slowly varying chroma."""
    y, x = torch.meshgrid(torch.arange(h, dtype=dtype), torch.arange(w, dtype=dtype), indexing="ij")
    lum = 0.5 + 0.3 * torch.sin(2 * math.pi * (x / 11.0 + y / 13.0))
    chroma = torch.stack([0.9 + 0.1 * torch.cos(2 * math.pi * x / 61.0), torch.ones_like(x),
                          0.8 + 0.1 * torch.sin(2 * math.pi * y / 53.0)])
    return (chroma * lum)[None]


@pytest.mark.parametrize("pattern", ["RGGB", "GRBG", "GBRG", "BGGR"])
def test_malvar_beats_bilinear_on_a_smooth_image(pattern):
    img = _smooth_scene(64, 80)
    raw = mosaic(img, pattern)
    inner = (..., slice(4, -4), slice(4, -4))

    def psnr(a):
        return float(10 * torch.log10(1.0 / (a[inner] - img[inner]).pow(2).mean()))

    p_bil, p_mal = psnr(demosaic_bilinear(raw, pattern)), psnr(demosaic_malvar2004(raw, pattern))
    assert p_bil > 28.0  # both reconstruct a smooth image (measured: bilinear 31.5 dB, Malvar 36.1 dB)
    assert p_mal > p_bil + 3.0


@pytest.mark.parametrize("pattern", ["RGGB", "GRBG", "GBRG", "BGGR"])
def test_malvar_matches_colour_demosaicing(pattern):
    """Independent implementation: colour-demosaicing's ``demosaicing_CFA_Bayer_Malvar2004`` (NumPy/SciPy).
    Equal away from the 2-px border (SciPy's default border mode repeats the edge pixel, which shifts the CFA
    phase; lfmbench mirrors without repetition, which keeps it)."""
    cd = pytest.importorskip("colour_demosaicing")
    rng = np.random.default_rng(1)
    img = torch.tensor(rng.random((1, 3, 14, 18)))
    raw = mosaic(img, pattern)
    ref = cd.demosaicing_CFA_Bayer_Malvar2004(raw[0, 0].numpy(), pattern).transpose(2, 0, 1)
    ours = demosaic_malvar2004(raw, pattern)[0].numpy()
    assert np.abs(ours - ref)[:, 2:-2, 2:-2].max() < 1e-12
    refb = cd.demosaicing_CFA_Bayer_bilinear(raw[0, 0].numpy(), pattern).transpose(2, 0, 1)
    assert np.abs(demosaic_bilinear(raw, pattern)[0].numpy() - refb)[:, 2:-2, 2:-2].max() < 1e-12


@pytest.mark.parametrize("method", sorted(DEMOSAIC))
def test_demosaic_shapes_dtype_odd_sizes_and_measured_pixels(method):
    fn = DEMOSAIC[method]
    for shape in [(1, 8, 10), (2, 3, 1, 8, 10), (4, 1, 9, 11)]:
        raw = torch.rand(shape, dtype=torch.float64)
        out = fn(raw, "GRBG")
        assert out.shape == shape[:-3] + (3,) + shape[-2:] and out.dtype == torch.float64
    raw = torch.rand(1, 1, 9, 11)
    out = fn(raw, "GRBG")
    back = mosaic(out, "GRBG")
    if method == "malvar2004":
        assert torch.allclose(back, raw)  # a pixel keeps the colour it measured
    flat = fn(torch.full((1, 1, 9, 11), 0.3), "GRBG")
    assert torch.allclose(flat, torch.full_like(flat, 0.3), atol=1e-6)  # a grey field stays grey
    assert torch.allclose(Demosaic("GRBG", method)(raw), out)


def test_clamp_to_neighbours_removes_the_overshoot_around_a_lamp():
    """A lamp 1000x brighter than a flat grey road: Malvar's Laplacian correction puts negative values next to it;
    the clamp keeps every value within its colour's 3x3 sample range and leaves measured values as they were."""
    raw = torch.full((1, 1, 16, 16), 1.0, dtype=torch.float64)
    raw[0, 0, 7, 8] = 1000.0
    mal = demosaic_malvar2004(raw, "GRBG")
    assert float(mal.min()) < 0.0  # the overshoot
    out = clamp_to_neighbours(mal, raw, "GRBG")
    assert float(out.min()) >= 1.0 and float(out.max()) <= 1000.0
    assert torch.equal(mosaic(out, "GRBG"), raw)  # measured samples unchanged
    # an independent bound: every value lies between the min and max of its colour's samples in the 3x3 window
    idx = load_preset("ovt").cfa.index_map(16, 16)
    for c in range(3):
        for y in range(16):
            for x in range(16):
                ys, xs = slice(max(0, y - 1), y + 2), slice(max(0, x - 1), x + 2)
                vals = raw[0, 0, ys, xs][idx[ys, xs] == c]
                assert float(vals.min()) - 1e-12 <= float(out[0, c, y, x]) <= float(vals.max()) + 1e-12
    img = _smooth_scene(64, 80)
    m = mosaic(img, "RGGB")
    inner = (..., slice(4, -4), slice(4, -4))
    err = [float((a[inner] - img[inner]).pow(2).mean()) for a in
           (demosaic_malvar2004(m, "RGGB"), clamp_to_neighbours(demosaic_malvar2004(m, "RGGB"), m, "RGGB"))]
    assert err[1] <= err[0]  # on a smooth image the clamp does not hurt (measured: 38.4 dB against 36.1 dB)


def test_demosaic_gradient():
    raw = torch.rand(1, 1, 6, 6, dtype=torch.float64, requires_grad=True)
    torch.autograd.gradcheck(lambda r: demosaic_malvar2004(r, "RGGB"), (raw,))


def test_demosaic_bad_input():
    with pytest.raises(ValueError, match=r"\(\*, 1, H, W\)"):
        demosaic_malvar2004(torch.rand(1, 3, 8, 8), "RGGB")
    with pytest.raises(ValueError, match="pattern must be one of"):
        demosaic_malvar2004(torch.rand(1, 1, 8, 8), "XYZW")
