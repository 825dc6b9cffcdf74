"""The ISP stage (lfmbench/isp): each operator against an independent answer, shapes, dtypes, gradients, and the
pipeline files (errors name the file and the field)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from lfmbench.isp import (DEMOSAIC, ISP, TONEMAP, ColorCorrection, Compander, Demosaic, SRGBEncode, ToneMap,
                          apply_ccm, camera_rgb, check_knees, clamp_to_neighbours, compand, decompand,
                          demosaic_bilinear, demosaic_malvar2004, fit_ccm, gray_world_gains, load_pipeline, luminance,
                          pipeline_from_dict, reinhard2002, reinhard2002_stats, srgb_decode, srgb_encode,
                          subtract_black_level, tonemap, white_balance_gains, white_balance_mosaic)
from lfmbench.isp.pipeline import available_pipelines
from lfmbench.sensor import available_presets, load_preset, mosaic

KNEES = [[0, 0], [1024, 1024], [8192, 1920], [65536, 2816], [524288, 3712], [16777215, 4095]]


# ------------------------------------------------------------------------------------------------------- sRGB
def test_srgb_encode_matches_colour_science():
    colour = pytest.importorskip("colour")
    x = np.concatenate([np.linspace(0, 0.01, 501), np.linspace(0.01, 1, 991), [0.0031308, 0.0031309]])
    ours = srgb_encode(torch.tensor(x, dtype=torch.float64)).numpy()
    ref = colour.models.eotf_inverse_sRGB(x)
    assert np.abs(ours - ref).max() < 1e-12
    v = np.linspace(0, 1, 1001)
    assert np.abs(srgb_decode(torch.tensor(v, dtype=torch.float64)).numpy() - colour.models.eotf_sRGB(v)).max() < 1e-12


def test_srgb_round_trip_clip_and_gradient():
    x = torch.linspace(0, 1, 2001, dtype=torch.float64)
    assert torch.allclose(srgb_decode(srgb_encode(x)), x, atol=1e-12)
    assert srgb_encode(torch.tensor([-1.0, 2.0])).tolist() == pytest.approx([0.0, 1.0], abs=1e-7)
    g = torch.tensor([0.0, 0.0031308, 0.5, 1.0], dtype=torch.float64, requires_grad=True)
    srgb_encode(g).sum().backward()
    assert torch.isfinite(g.grad).all() and g.grad[0] == pytest.approx(12.92)
    torch.autograd.gradcheck(srgb_encode, (torch.tensor([0.001, 0.2, 0.7], dtype=torch.float64, requires_grad=True),))
    assert torch.equal(SRGBEncode()(x), srgb_encode(x))


# ------------------------------------------------------------------------------------------------- companding
def test_compand_round_trip_within_one_code():
    k = check_knees(KNEES, 24, 12)
    codes = torch.arange(4096, dtype=torch.float64)
    assert torch.equal(compand(decompand(codes, k), k), codes)  # every output code survives the round trip
    gen = torch.Generator().manual_seed(0)
    x = torch.cat([torch.arange(0, 70000, dtype=torch.float64),
                   torch.randint(0, 2 ** 24, (200_000,), generator=gen).double(),
                   k[:, 0], k[:, 0] - 1, k[:, 0] + 1]).clamp(0, 2 ** 24 - 1)
    y = compand(x, k)
    assert y.min() >= 0 and y.max() <= 4095 and torch.equal(y, y.round())
    back = decompand(y, k)
    slope = torch.tensor([float((k[i + 1, 1] - k[i, 1]) / (k[i + 1, 0] - k[i, 0])) for i in range(len(k) - 1)],
                         dtype=torch.float64)
    seg = torch.bucketize(x, k[1:-1, 0].contiguous(), right=True)
    half_code = 0.5 / slope[seg]  # half an output code, in input codes, on the segment of x (and its neighbour)
    half_code = torch.maximum(half_code, 0.5 / slope[(seg - 1).clamp_min(0)])
    assert bool(((back - x).abs() <= half_code + 1e-6).all())
    assert torch.equal(compand(back, k), y)  # within one code: re-companding gives the same code
    assert torch.equal(back[x < 1024], x[x < 1024])  # slope 1: lossless


def test_compand_monotone_and_hand_checked():
    k = check_knees(KNEES, 24, 12)
    assert compand(torch.tensor([1024.0, 1032.0, 8192.0, 16777215.0]), k).tolist() == [1024.0, 1025.0, 1920.0, 4095.0]
    x = torch.linspace(0, 2 ** 24 - 1, 100_001, dtype=torch.float64)
    assert bool((torch.diff(compand(x, k)) >= 0).all())


@pytest.mark.parametrize("knees, match", [
    ([[0, 0]], "at least 2"),
    ([[1, 0], [16777215, 4095]], r"knees\[0\]"),
    ([[0, 0], [1000, 4095]], r"knees\[1\].*must end at input code"),
    ([[0, 0], [10, 20], [16777215, 4095]], r"knees\[1\].*slope 2 > 1"),
    ([[0, 0], [10, 5], [5, 6], [16777215, 4095]], r"knees\[2\].*strictly greater"),
    ([[0, 0], [16777215, 5000]], r"exceeds the top code"),
    ([[0, 0], ["a", 1], [16777215, 4095]], r"knees\[1\].*pair"),
])
def test_check_knees_errors_name_the_field(knees, match):
    with pytest.raises(ValueError, match=match):
        check_knees(knees, 24, 12, source="link.yaml")


def test_compander_module_quantises_and_passes_gradient():
    m = Compander(KNEES, 24, 12, dn_per_unit=2.0)
    x = torch.tensor([0.2, 100.0, 1.0e5, 1e9], dtype=torch.float64, requires_grad=True)
    y = m(x)
    assert y[0].item() == 0.0 and y[1].item() == 100.0  # 0.2 e- -> code 0; 100 e- = code 200, slope 1: exact
    assert abs(y[2].item() - 1.0e5) <= 0.5 * 512 / 2.0  # half an output code of the 1/512 segment, in e-
    assert y[2].item() != 1.0e5  # ... and the link did lose something there
    assert y[3].item() == pytest.approx((2 ** 24 - 1) / 2.0)  # clipped at the top input code
    y.sum().backward()
    assert torch.equal(x.grad, torch.ones(4, dtype=torch.float64))  # straight-through


# ----------------------------------------------------------------------------------------------- colour, CCM
def test_ccm_fit_error_on_colorchecker_is_bounded():
    """docs/guide/isp.md states the fit's error: mean CIE dE2000 1.09, max 4.15 on the 24 patches (ovt, imx490 share
    the Nikon D5100 curves). Bounds with some room for colour-science data updates."""
    fit = fit_ccm("ovt")
    assert fit.de2000.shape == (24,) and len(fit.patches) == 24
    assert fit.mean_de2000 < 1.5 and fit.max_de2000 < 5.0
    assert np.allclose(fit.matrix.sum(axis=1), 1.0, atol=1e-12)  # white preserved
    assert fit.wb_gains[1] == 1.0


def test_ccm_of_a_luther_sensor_is_exact(tmp_path):
    """Independent answer: a sensor whose photon-counting responses are the CIE 1931 colour-matching functions
    (the Luther-Ives condition) is colorimetric, so its fitted CCM reproduces every patch: dE2000 ~ 0."""
    colour = pytest.importorskip("colour")
    shape = colour.SpectralShape(380, 780, 5)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    wl = shape.wavelengths
    qe = cmfs.values / wl[:, None]  # photon counting multiplies by lambda: QE = cmf / lambda gives c ~ XYZ
    qe = qe / qe.max(axis=0)
    csv = tmp_path / "luther.csv"
    csv.write_text("# CIE 1931 CMFs / lambda (test data)\nwavelength_nm,r,g,b\n"
                   + "\n".join(f"{w:g},{a:.12g},{b:.12g},{c:.12g}" for w, (a, b, c) in zip(wl, qe)))
    import yaml
    from lfmbench.sensor.preset import PRESET_DIR

    data = yaml.safe_load((PRESET_DIR / "ovt.yaml").read_text())
    data["spectral"]["filters"] = str(csv)
    data["name"] = "luther"
    fit = fit_ccm(load_preset(data))
    assert fit.max_de2000 < 0.05


def test_white_balance_gains_make_white_neutral():
    gains = white_balance_gains("ovt")
    w = camera_rgb("ovt", np.ones((1, 81)))[0]
    assert np.allclose(w * gains, w[1], rtol=1e-12)


def test_apply_ccm_and_module_and_shapes():
    m = torch.tensor([[1.0, 2, 0], [0, 1, 0], [0, 0, 3]])
    x = torch.rand(2, 4, 3, 5, 6)
    out = apply_ccm(x, m)
    assert out.shape == x.shape
    assert torch.allclose(out[:, :, 0], x[:, :, 0] + 2 * x[:, :, 1])
    assert torch.allclose(ColorCorrection(m)(x), out)
    with pytest.raises(ValueError, match=r"\(\*, 3, H, W\)"):
        apply_ccm(torch.rand(2, 5, 6), m)


def test_luminance_bt709():
    x = torch.zeros(1, 3, 1, 1)
    x[0, :, 0, 0] = torch.tensor([1.0, 1.0, 1.0])
    assert luminance(x).item() == pytest.approx(1.0)
    x[0, :, 0, 0] = torch.tensor([1.0, 0.0, 0.0])
    assert luminance(x).item() == pytest.approx(0.2126)


# -------------------------------------------------------------------------------------------- black level, WB
def test_black_level_and_white_balance():
    raw = torch.full((2, 1, 4, 4), 164.0)
    assert torch.equal(subtract_black_level(raw, 64), torch.full_like(raw, 100.0))
    assert torch.allclose(subtract_black_level(raw, 64, 4095), torch.full_like(raw, 100 / 4031))
    wb = white_balance_mosaic(torch.ones(1, 1, 2, 2), [2.0, 1.0, 3.0], "GRBG")
    assert wb[0, 0].tolist() == [[1.0, 2.0], [3.0, 1.0]]  # G R / B G


def test_gray_world_gains_equalise_channel_means():
    rgb = torch.tensor([0.5, 1.0, 0.25]).reshape(1, 3, 1, 1).expand(2, 3, 8, 8)
    raw = mosaic(rgb, "RGGB")
    g = gray_world_gains(raw, "RGGB")
    assert torch.allclose(g, torch.tensor([[2.0, 1.0, 4.0]] * 2))
    balanced = white_balance_mosaic(raw, g, "RGGB")
    assert torch.allclose(balanced, torch.ones_like(balanced))


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


# -------------------------------------------------------------------------------------------------- pipelines
def _pipe(**override) -> dict:
    d = {"format": "lfmbench-isp", "name": "t", "steps": [
        {"op": "black_level", "level": 0}, {"op": "white_balance"}, {"op": "demosaic"}, {"op": "ccm"},
        {"op": "tonemap"}, {"op": "srgb_encode"}]}
    d.update(override)
    return d


@pytest.mark.parametrize("steps, match", [
    ([{"op": "frobnicate"}], r"t\.yaml: field 'steps\[0\]\.op' must be one of"),
    ([{"op": "demosaic"}, {"op": "white_balance"}], r"field 'steps\[1\]' works on the mosaic"),
    ([{"op": "tonemap"}, {"op": "demosaic"}], r"field 'steps\[0\]' works on the rgb"),
    ([{"op": "white_balance"}], r"field 'steps' has no demosaic"),
    ([{"op": "demosaic", "methd": "x"}], r"unknown field 'steps\[0\]\.methd'"),
    ([{"op": "demosaic", "method": "vng"}], r"field 'steps\[0\]\.method' must be one of"),
    ([{"op": "demosaic"}, {"op": "tonemap", "method": "durand2002", "key": 1}], r"unknown field 'steps\[1\]\.key'"),
    ([{"op": "demosaic"}, {"op": "tonemap", "white": "brightest"}], r"field 'steps\[1\]\.white'"),
    ([{"op": "compand", "knees": [[0, 0], [5, 9]]}, {"op": "demosaic"}], r"steps\[0\]\.knees\[1\]"),
    ([{"op": "demosaic"}, {"op": "ccm", "matrix": [[1, 0], [0, 1]]}], r"steps\[1\]\.matrix"),
    ([{"op": "demosaic", "clamp": "yes"}], r"steps\[0\]\.clamp' must be true or false"),
])
def test_pipeline_errors_name_file_and_field(steps, match):
    with pytest.raises(ValueError, match=match):
        pipeline_from_dict(_pipe(steps=steps), "t.yaml")


def test_pipeline_file_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown pipeline"):
        load_pipeline("no_such_pipeline")
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: lfmbench-isp\nname: x\nsteps: []\n")
    with pytest.raises(ValueError, match=r"bad\.yaml: field 'steps' must be a non-empty list"):
        load_pipeline(bad)
    with pytest.raises(ValueError, match="field 'format'"):
        pipeline_from_dict(_pipe(format="other"), "t.yaml")


def test_shipped_pipelines_load_and_hash():
    assert {"default", "local"} <= set(available_pipelines())
    p = load_pipeline("default")
    assert [s.op for s in p.stages] == ["black_level", "compand", "white_balance", "demosaic", "ccm", "tonemap",
                                       "srgb_encode"]
    assert len(p.sha256) == 64 and p.sha256 != load_pipeline("local").sha256
    assert load_pipeline("default").sha256 == p.sha256


@pytest.mark.parametrize("preset", available_presets())
@pytest.mark.parametrize("name", ["default", "local"])
def test_isp_runs_for_every_preset_and_maps_pairs_the_same_way(preset, name):
    isp = ISP(name, preset)
    gen = torch.Generator().manual_seed(2)
    gt = torch.rand(2, 3, 1, 20, 24, generator=gen) ** 3 * 5e4
    p, g = isp.pair(gt.clone(), gt)
    assert p.shape == (2, 3, 3, 20, 24) and torch.equal(p, g)
    assert float(g.min()) >= 0.0 and float(g.max()) <= 1.0
    assert torch.equal(isp(gt), g)  # forward without reference: the image is its own reference
    p2, g2 = isp.pair(gt * 4.0, gt)
    assert torch.equal(g2, g) and float(p2.mean()) > float(g.mean())
    one = isp(gt[0, 0])  # (1, H, W) works too
    assert one.shape == (3, 20, 24)


def test_isp_gradient_flows_to_the_estimate():
    isp = ISP("default", "ovt")
    gt = torch.rand(1, 2, 1, 16, 16, dtype=torch.float64) * 1e3 + 10
    pred = (gt * 1.3).requires_grad_(True)
    p, g = isp.pair(pred, gt)
    (p - g).pow(2).mean().backward()
    assert pred.grad is not None and torch.isfinite(pred.grad).all() and float(pred.grad.abs().sum()) > 0


def test_isp_black_level_preset_for_dn_input():
    pipe = _pipe(steps=[{"op": "black_level", "level": "preset"}, {"op": "demosaic"}])
    isp = ISP(pipeline_from_dict(pipe), "ovt")
    raw = torch.full((1, 1, 4, 4), 64.0 + 10.0)
    assert torch.allclose(isp(raw), torch.full((1, 3, 4, 4), 10.0))
