"""Tests of lfmbench.sensor.optics against analytic answers (camera equation, Airy pattern) and brute force."""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate as si
import scipy.special as ss
import torch

from lfmbench.sensor.optics import (
    DiffractionOptics,
    OpticsConfig,
    airy_encircled_energy,
    airy_first_zero_m,
    airy_kernel,
    airy_psf,
    apply_psf,
    cos4_falloff,
    radiance_to_irradiance,
    simulate_optics,
)

WL = [400.0, 550.0, 700.0]
N = 17.19 / 3.0      # upstream f-number
PITCH = 2.8e-6


def test_camera_equation_hand_checked():
    L = torch.full((1, 2, 3, 3), 2.0, dtype=torch.float64)
    E = radiance_to_irradiance(L, f_number=2.0, transmittance=0.5)
    assert torch.allclose(E, torch.full_like(L, math.pi * 2.0 * 0.5 / 16.0))
    # working f-number N (1 + m): magnification 1 quarters the irradiance
    E1 = radiance_to_irradiance(L, f_number=2.0, transmittance=0.5, magnification=1.0)
    assert torch.allclose(E1, E / 4)
    assert radiance_to_irradiance(L.float(), 2.0).dtype == torch.float32


@pytest.mark.parametrize("bad, what", [(float("nan"), "NaN"), (float("inf"), "inf"), (-1.0, "negative")])
def test_camera_equation_rejects_bad_radiance(bad, what):
    L = torch.ones(1, 1, 2, 2)
    L[0, 0, 1, 1] = bad
    with pytest.raises(ValueError, match="radiance"):
        radiance_to_irradiance(L, 5.7)


def test_airy_psf_matches_scipy_and_integrates_to_one():
    lam = 550e-9
    r = torch.linspace(0, 20e-6, 401, dtype=torch.float64)
    x = np.pi * r.numpy() / (lam * N)
    with np.errstate(invalid="ignore", divide="ignore"):
        ref = np.where(x == 0, 1.0, (2 * ss.j1(x) / x) ** 2) * np.pi / (4 * lam ** 2 * N ** 2)
    # torch.special.bessel_j1 is accurate to ~5e-7 absolute in float64 (measured against scipy): compare the
    # PSF relative to its peak with that allowance, and the peak (analytic prefactor) exactly
    got = airy_psf(r, lam, N).numpy()
    assert got[0] == pytest.approx(ref[0], rel=1e-12)
    assert np.allclose(got / got[0], ref / ref[0], rtol=0, atol=2e-6)

    # encircled energy by quadrature of the PSF vs Rayleigh's closed form 1 - J0^2 - J1^2 (independent answer)
    def ring(rr):
        return float(airy_psf(torch.tensor([rr], dtype=torch.float64), lam, N)[0]) * 2 * np.pi * rr

    for r_max in (2e-6, 5e-6, 30e-6):
        num, _ = si.quad(ring, 0, r_max, limit=400)
        x = np.pi * r_max / (lam * N)
        assert num == pytest.approx(1 - ss.j0(x) ** 2 - ss.j1(x) ** 2, abs=1e-8)
    # total power -> 1 (the closed form tends to 1; at x = 1e5 the remainder is < 1e-5)
    ee = airy_encircled_energy(torch.tensor([1e5 * lam * N / np.pi], dtype=torch.float64), lam, N)
    assert float(ee) == pytest.approx(1.0, abs=1e-5)


def test_airy_first_zero_at_1_22_lambda_n():
    for lam in (400e-9, 550e-9, 700e-9):
        r0 = airy_first_zero_m(lam, N)
        assert r0 == pytest.approx(ss.jn_zeros(1, 1)[0] / np.pi * lam * N, rel=1e-12)
        assert r0 == pytest.approx(1.22 * lam * N, rel=1e-3)
        # brute force: the minimum of the PSF between 0.9 and 1.6 lambda N lies at r0 and is ~0
        r = torch.linspace(0.9 * lam * N, 1.6 * lam * N, 70001, dtype=torch.float64)
        psf = airy_psf(r, lam, N)
        assert float(r[torch.argmin(psf)]) == pytest.approx(r0, rel=1e-4)
        assert float(psf.min()) < 1e-9 * float(airy_psf(torch.zeros(1, dtype=torch.float64), lam, N)[0])


def test_airy_kernel_sum_bounded_by_encircled_energy():
    R = 6
    k = airy_kernel(WL, N, PITCH, radius_px=R, oversample=9, normalize=False, dtype=torch.float64)
    assert k.shape == (3, 2 * R + 1, 2 * R + 1)
    s = k.sum(dim=(-2, -1))
    half = (R + 0.5) * PITCH   # the window is a square of half-side (R + 1/2) pixels
    lam = torch.tensor(WL, dtype=torch.float64) * 1e-9
    inner = airy_encircled_energy(torch.full_like(lam, half), lam, N)
    outer = airy_encircled_energy(torch.full_like(lam, half * math.sqrt(2)), lam, N)
    assert torch.all(s >= inner) and torch.all(s <= outer)
    # a large window holds nearly all the power; normalised kernels sum to 1 and are symmetric
    big = airy_kernel([550.0], N, PITCH, radius_px=60, oversample=3, normalize=False, dtype=torch.float64)
    assert float(big.sum()) == pytest.approx(1.0, abs=5e-3)
    kn = airy_kernel(WL, N, PITCH, radius_px=R)
    assert torch.allclose(kn.sum(dim=(-2, -1)), torch.ones(3), atol=1e-6)
    assert torch.allclose(kn, kn.flip(-1)) and torch.allclose(kn, kn.transpose(-1, -2))
    # longer wavelength -> wider PSF -> less power in the centre pixel
    assert kn[0, R, R] > kn[1, R, R] > kn[2, R, R]


def test_airy_kernel_oversampling_converges_second_order():
    """Midpoint-rule pixel integration: error ~ 1/s^2, so tripling s divides the error by ~9."""
    ks = {s: airy_kernel([550.0], N, PITCH, 4, oversample=s, normalize=False, dtype=torch.float64)
          for s in (5, 15, 135)}
    e5 = (ks[5] - ks[135]).abs().max()
    e15 = (ks[15] - ks[135]).abs().max()
    assert 7.0 < float(e5 / e15) < 11.0
    # the preset default (11 sub-samples) is within 0.3 % of the converged centre tap
    k11 = airy_kernel([550.0], N, PITCH, 4, oversample=11, normalize=False, dtype=torch.float64)
    assert float(k11[0, 4, 4]) == pytest.approx(float(ks[135][0, 4, 4]), rel=3e-3)


def test_apply_psf_fft_equals_conv_and_delta_gives_kernel():
    torch.manual_seed(0)
    k = airy_kernel(WL, N, PITCH, radius_px=5, dtype=torch.float64)
    x = torch.rand(2, 3, 23, 31, dtype=torch.float64)
    a = apply_psf(x, k, method="fft")
    b = apply_psf(x, k, method="conv")
    assert torch.allclose(a, b, atol=1e-12)
    d = torch.zeros(1, 3, 21, 21, dtype=torch.float64)
    d[..., 10, 10] = 1.0
    out = apply_psf(d, k, method="fft", padding="zeros")
    assert torch.allclose(out[0, :, 5:16, 5:16], k, atol=1e-12)
    # brute-force direct sum at one pixel of an asymmetric kernel (checks convolution, not correlation)
    ka = torch.rand(3, 5, 5, dtype=torch.float64)
    y = apply_psf(x, ka, method="fft", padding="zeros")
    i, j = 11, 13
    ref = sum(x[0, :, i - u, j - v] * ka[:, u + 2, v + 2] for u in range(-2, 3) for v in range(-2, 3))
    assert torch.allclose(y[0, :, i, j], ref, atol=1e-12)
    assert torch.allclose(apply_psf(x, ka, method="conv", padding="zeros"), y, atol=1e-12)


def test_apply_psf_conserves_constant_and_flux():
    k = airy_kernel(WL, N, PITCH, radius_px=4)
    c = torch.full((1, 3, 16, 16), 3.0)
    assert torch.allclose(apply_psf(c, k), c, atol=1e-5)
    x = torch.zeros(1, 3, 40, 40, dtype=torch.float64)
    x[..., 15:25, 15:25] = 1.0
    y = apply_psf(x, airy_kernel(WL, N, PITCH, radius_px=4, dtype=torch.float64), padding="zeros")
    assert torch.allclose(y.sum(dim=(-2, -1)), x.sum(dim=(-2, -1)), rtol=1e-10)


def test_apply_psf_gradcheck():
    k = airy_kernel([550.0, 650.0], N, PITCH, radius_px=2, dtype=torch.float64)
    x = torch.rand(1, 2, 6, 7, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda t: apply_psf(t, k, method="fft"), (x,))


def test_cos4_falloff_analytic():
    f = 17.19e-3
    m = cos4_falloff(5, 7, PITCH, f, dtype=torch.float64)
    assert m.shape == (5, 7)
    assert float(m[2, 3]) == pytest.approx(1.0)
    rho = math.hypot(2 * PITCH, 3 * PITCH)
    assert float(m[0, 0]) == pytest.approx(math.cos(math.atan(rho / f)) ** 4, rel=1e-12)


def test_simulate_optics_and_module():
    wl = list(range(400, 701, 10))
    L = torch.rand(2, 31, 12, 14, dtype=torch.float64)
    cfg = OpticsConfig(psf=False)
    E = simulate_optics(L, wl, cfg, PITCH)
    assert torch.allclose(E, L * math.pi / (4 * 5.73 ** 2))
    cfg2 = OpticsConfig(psf_radius_px=3)
    E2 = simulate_optics(L, wl, cfg2, PITCH)
    mod = DiffractionOptics(wl, cfg2, PITCH)
    assert torch.allclose(mod(L), E2)
    assert mod(L.float()).dtype == torch.float32
    # blur preserves the mean of the interior approximately and changes the image
    assert not torch.allclose(E2, E)
    with pytest.raises(ValueError, match="wavelengths_nm"):
        simulate_optics(L, wl[:-1], cfg, PITCH)


def test_optics_config_validation_names_field():
    with pytest.raises(ValueError, match="optics.f_number.*cam.yaml|cam.yaml.*optics.f_number"):
        OpticsConfig.from_mapping({"f_number": -1.0}, "cam.yaml")
    with pytest.raises(ValueError, match="optics.focal"):
        OpticsConfig.from_mapping({"focal": 1.0}, "cam.yaml")
    with pytest.raises(ValueError, match="optics.psf_radius_px"):
        OpticsConfig.from_mapping({"psf_radius_px": 2.5}, "cam.yaml")
    assert OpticsConfig.from_mapping({"f_number": 2.0}).f_number == 2.0


def test_kernel_bad_arguments():
    with pytest.raises(ValueError, match="radius_px"):
        airy_kernel(WL, N, PITCH, radius_px=-1)
    with pytest.raises(ValueError, match="wavelengths_nm"):
        airy_kernel([float("nan")], N, PITCH)
    with pytest.raises(ValueError, match="kernel"):
        apply_psf(torch.ones(1, 3, 4, 4), torch.ones(3, 4, 4))


def test_fft_blur_of_nonnegative_image_has_no_negative_roundoff():
    k = airy_kernel(WL, N, PITCH, radius_px=8)
    x = torch.zeros(1, 3, 64, 64)
    x[..., 30:33, 30:33] = 1e6                      # a bright LED on black: round-off would go below 0
    y = apply_psf(x, k, method="fft")
    assert float(y.min()) >= 0.0
    assert float(y.sum()) == pytest.approx(float(x.sum()), rel=1e-4)
