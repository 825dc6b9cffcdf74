"""Camera optics: scene spectral radiance -> spectral irradiance at the sensor, diffraction-limited blur.

Functional core (torch, batched, any device, float32/float64 following the input) plus thin ``nn.Module``
wrappers. Defines:

- :func:`radiance_to_irradiance` - the camera equation, E = pi L T / (4 N^2 (1 + m)^2) [Smith2008]_.
- :func:`cos4_falloff` - natural vignetting cos^4(theta) of an ideal lens [Smith2008]_.
- :func:`airy_psf`, :func:`airy_encircled_energy` - diffraction pattern of a circular pupil [BornWolf1999]_.
- :func:`airy_kernel` - the Airy PSF integrated over square pixels, one kernel per wavelength, truncated.
- :func:`apply_psf` - per-band convolution by FFT or direct ``conv2d``.
- :func:`simulate_optics` - radiance -> blurred irradiance in one call; :class:`DiffractionOptics` wraps it.
- :class:`OpticsConfig` - the optics part of a sensor preset (YAML ``optics:`` section).

Units: wavelengths in nm at the API (the corpus' band centres), lengths in m, spectral radiance in
W sr^-1 m^-2 nm^-1, spectral irradiance in W m^-2 nm^-1.

References
----------
.. [Smith2008] W. J. Smith, "Modern Optical Engineering", 4th ed., McGraw-Hill (2008), radiometry chapter (radiometry of
   imaging systems): image irradiance of an aplanatic lens E = pi L T sin^2(u') ~ pi L T / (4 N_w^2) with the
   working f-number N_w = N (1 + |m|); off-axis irradiance falls as cos^4(theta).
.. [BornWolf1999] M. Born, E. Wolf, "Principles of Optics", 7th ed., Cambridge (1999), sec. 8.5.2: intensity
   of the Fraunhofer pattern of a circular aperture I(x) = I0 [2 J1(x) / x]^2, x = pi r / (lambda N); fraction of
   the power inside radius r (Lord Rayleigh) L(r) = 1 - J0(x)^2 - J1(x)^2.
.. [ISETCam] B. Wandell, J. Farrell et al., ISETCam ``oiCalculateIrradiance`` / ``opticsDLCompute``: the
   upstream diffraction-limited optics of ISET-LFM (3 mm pupil, 17.19 mm focal length, f/5.73).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Literal, Mapping, Sequence

import torch
import torch.nn.functional as F
from torch import nn

from lfmbench.check import check_integer, check_keys, check_number, check_tensor, value_checks
from lfmbench.constants import AIRY_FIRST_ZERO_FACTOR, M_PER_NM

__all__ = [
    "OpticsConfig",
    "check_radiometric",
    "radiance_to_irradiance",
    "cos4_falloff",
    "airy_psf",
    "airy_encircled_energy",
    "airy_first_zero_m",
    "airy_kernel",
    "apply_psf",
    "simulate_optics",
    "DiffractionOptics",
]

PsfMethod = Literal["auto", "fft", "conv"]

#: Kernel size (2R+1) from which ``apply_psf(method="auto")`` switches from direct convolution to FFT
#: (measured crossover on 2 CPU cores, see docs/guide/sensors.md).
FFT_CROSSOVER_KERNEL_SIZE: int = 25


# ----------------------------------------------------------------------------------------------------------
# configuration
# ----------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class OpticsConfig:
    """Diffraction-limited lens of a camera preset.

    Attributes:
        f_number: focal length / entrance-pupil diameter (dimensionless); upstream 17.19 mm / 3 mm = 5.73.
        focal_length_m: focal length in m (used with the pixel pitch for the field angle of cos^4 falloff).
        transmittance: lens transmittance T (dimensionless, 0 < T <= 1), spectrally flat.
        magnification: lateral magnification m (dimensionless, 0 for an object at infinity).
        psf: ``True`` to apply the Airy PSF, ``False`` to switch diffraction off.
        psf_radius_px: truncation radius R of the PSF kernel in pixels (kernel is (2R+1)^2).
        psf_oversample: sub-samples per pixel side for the pixel-area integration of the PSF.
        cos4: ``True`` to apply cos^4 off-axis falloff (relative illumination).
    """

    f_number: float = 5.73
    focal_length_m: float = 17.19e-3
    transmittance: float = 1.0
    magnification: float = 0.0
    psf: bool = True
    psf_radius_px: int = 8
    psf_oversample: int = 11
    cos4: bool = False

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], source: str = "<dict>") -> "OpticsConfig":
        """Build from a plain mapping (the ``optics:`` section of a preset file), validating every field.

        Raises:
            ValueError: unknown or invalid field; the message names the field and ``source``.
        """
        check_keys(data, "optics", source, optional={f.name for f in fields(cls)})
        kw: dict[str, Any] = {}
        for name, value in data.items():
            field_name = f"optics.{name}"
            if name in ("psf", "cos4"):
                if not isinstance(value, bool):
                    raise ValueError(f"{source}: field '{field_name}' must be true or false, got {value!r}")
                kw[name] = value
            elif name in ("psf_radius_px", "psf_oversample"):
                least = 0 if name == "psf_radius_px" else 1
                kw[name] = check_integer(value, field_name, source, lo=least)
            else:
                kw[name] = check_number(value, field_name, source)
        cfg = cls(**kw)
        if not (cfg.f_number > 0 and math.isfinite(cfg.f_number)):
            raise ValueError(f"{source}: field 'optics.f_number' must be > 0, got {cfg.f_number!r}")
        if not cfg.focal_length_m > 0:
            raise ValueError(f"{source}: field 'optics.focal_length_m' must be > 0 (m), got {cfg.focal_length_m!r}")
        if not 0 < cfg.transmittance <= 1:
            raise ValueError(f"{source}: field 'optics.transmittance' must be in (0, 1], got {cfg.transmittance!r}")
        if not cfg.magnification >= 0:
            raise ValueError(f"{source}: field 'optics.magnification' must be >= 0, got {cfg.magnification!r}")
        from lfmbench.limits import LimitError, limit  # noqa: PLC0415 - sizes checked before any kernel exists

        if cfg.psf_radius_px > limit("psf_radius_px"):
            raise LimitError(source, "field 'optics.psf_radius_px' =", cfg.psf_radius_px, "psf_radius_px")
        n = ((2 * cfg.psf_radius_px + 1) * cfg.psf_oversample) ** 2
        if n > limit("psf_samples"):
            raise LimitError(source, "fields 'optics.psf_radius_px' and 'optics.psf_oversample' ask for a PSF grid "
                             "of", n, "psf_samples")
        return cfg


# ----------------------------------------------------------------------------------------------------------
# input checks
# ----------------------------------------------------------------------------------------------------------
def check_radiometric(x: torch.Tensor, name: str, min_dim: int = 3) -> None:
    """Raise naming ``name`` unless ``x`` is a floating tensor of at least ``min_dim`` dims, finite and >= 0.

    The type, dims and dtype are checked by :func:`lfmbench.check.check_tensor` (``TypeError`` for a non-tensor,
    ``ValueError`` otherwise); the values here (``ValueError`` counting the NaN and inf, or giving the minimum).

    Args:
        x: tensor of shape (*, C, H, W) (at least ``min_dim`` dimensions) of a radiometric quantity.
        name: argument name quoted in the error message.
        min_dim: minimum number of dimensions.
    """
    check_tensor(x, name, "* C H W" if min_dim == 3 else None, min_dim=min_dim, floating=True)
    if x.numel() == 0 or not value_checks():
        return
    lo, hi = torch.aminmax(x.detach())          # one pass; NaN propagates to both
    lo, hi = float(lo), float(hi)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        n_nan = int(torch.isnan(x).sum())
        raise ValueError(f"{name} contains non-finite values ({n_nan} NaN, {int(torch.isinf(x).sum())} inf)")
    if lo < 0:
        raise ValueError(f"{name} contains negative values (min {lo:.3g}); radiometric inputs must be >= 0")


# ----------------------------------------------------------------------------------------------------------
# radiometry
# ----------------------------------------------------------------------------------------------------------
def radiance_to_irradiance(radiance: torch.Tensor, f_number: float, transmittance: float = 1.0,
                           magnification: float = 0.0, check: bool = True) -> torch.Tensor:
    r"""On-axis image-plane spectral irradiance from scene spectral radiance (camera equation).

    .. math:: E = \frac{\pi L T}{4 N^2 (1 + m)^2}

    [Smith2008]_ (paraxial, aplanatic lens, small angles; ISETCam uses the same form with ``1 + 4N^2(1+m)^2`` in
    the denominator, which differs by < 1 % for N >= 5).

    Args:
        radiance: spectral radiance L in W sr^-1 m^-2 nm^-1, shape (*, C, H, W).
        f_number: N (dimensionless).
        transmittance: lens transmittance T (dimensionless).
        magnification: lateral magnification m (dimensionless; 0 at infinity focus).
        check: validate ``radiance`` (finite, >= 0).

    Returns:
        spectral irradiance E in W m^-2 nm^-1, same shape, dtype and device as ``radiance``.

    Example:
        >>> float(radiance_to_irradiance(torch.ones(1, 1, 1, 1), f_number=2.0))  # pi / 16
        0.19634954631328583
    """
    if check:
        check_radiometric(radiance, "radiance")
    if not f_number > 0:
        raise ValueError(f"f_number must be > 0, got {f_number!r}")
    if not 0 < transmittance <= 1:
        raise ValueError(f"transmittance must be in (0, 1], got {transmittance!r}")
    factor = math.pi * transmittance / (4.0 * f_number ** 2 * (1.0 + abs(magnification)) ** 2)
    return radiance * factor


def cos4_falloff(height: int, width: int, pixel_pitch_m: float, focal_length_m: float,
                 device: torch.device | str | None = None, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    r"""Relative illumination cos^4(theta) of an ideal lens at every pixel centre [Smith2008]_.

    theta is the field angle of the pixel centre: tan(theta) = rho / f, rho the distance (m) from the optical
    axis (image centre). Args: ``pixel_pitch_m`` and ``focal_length_m`` in m.

    Returns:
        factor in (0, 1], shape (H, W).
    """
    if height < 1 or width < 1:
        raise ValueError(f"height and width must be >= 1, got {height}x{width}")
    y = (torch.arange(height, device=device, dtype=torch.float64) - (height - 1) / 2) * pixel_pitch_m
    x = (torch.arange(width, device=device, dtype=torch.float64) - (width - 1) / 2) * pixel_pitch_m
    rho2 = y[:, None] ** 2 + x[None, :] ** 2
    cos2 = focal_length_m ** 2 / (focal_length_m ** 2 + rho2)
    return (cos2 * cos2).to(dtype)


# ----------------------------------------------------------------------------------------------------------
# diffraction
# ----------------------------------------------------------------------------------------------------------
def airy_first_zero_m(wavelength_m: float, f_number: float) -> float:
    """Radius of the first dark ring, r = 1.21967 lambda N, in m [BornWolf1999]_ (wavelength in m)."""
    return AIRY_FIRST_ZERO_FACTOR * wavelength_m * f_number


def airy_psf(radius_m: torch.Tensor, wavelength_m: torch.Tensor | float, f_number: float) -> torch.Tensor:
    r"""Airy point-spread function of an aberration-free circular pupil, normalised to unit volume.

    .. math:: I(r) = \frac{\pi}{4 \lambda^2 N^2}\left[\frac{2 J_1(x)}{x}\right]^2, \quad x = \frac{\pi r}{\lambda N}

    [BornWolf1999]_; the prefactor makes :math:`\int_0^\infty I(r)\,2\pi r\,dr = 1` (uses
    :math:`\int_0^\infty J_1^2(x)/x\,dx = 1/2`).

    Args:
        radius_m: distance from the PSF centre in m, any shape.
        wavelength_m: wavelength in m, broadcastable with ``radius_m``.
        f_number: N (dimensionless; image-side, i.e. working f-number).

    Returns:
        PSF in 1/m^2 (fraction of the power per unit area), broadcast shape of the inputs.
    """
    lam = torch.as_tensor(wavelength_m, dtype=radius_m.dtype, device=radius_m.device)
    x = math.pi * radius_m / (lam * f_number)
    x_safe = torch.where(x == 0, torch.ones_like(x), x)
    amp = torch.where(x == 0, torch.ones_like(x), 2.0 * torch.special.bessel_j1(x_safe) / x_safe)
    return (math.pi / (4.0 * lam ** 2 * f_number ** 2)) * amp * amp


def airy_encircled_energy(radius_m: torch.Tensor, wavelength_m: torch.Tensor | float, f_number: float) -> torch.Tensor:
    """Fraction of the Airy power inside a circle of radius r: 1 - J0(x)^2 - J1(x)^2 (Rayleigh, [BornWolf1999]_).

    Args: radius and wavelength in m (broadcastable tensors). Returns: dimensionless fraction in [0, 1].
    """
    lam = torch.as_tensor(wavelength_m, dtype=radius_m.dtype, device=radius_m.device)
    x = math.pi * radius_m / (lam * f_number)
    return 1.0 - torch.special.bessel_j0(x) ** 2 - torch.special.bessel_j1(x) ** 2


def airy_kernel(wavelengths_nm: Sequence[float] | torch.Tensor, f_number: float, pixel_pitch_m: float,
                radius_px: int = 8, oversample: int = 11, normalize: bool = True,
                dtype: torch.dtype = torch.float32, device: torch.device | str | None = None) -> torch.Tensor:
    """Pixel-integrated Airy PSF per wavelength, truncated to a (2R+1) x (2R+1) pixel window.

    Each tap is the PSF power falling on one square pixel of side ``pixel_pitch_m`` (100 % aperture),
    integrated by the midpoint rule on ``oversample`` x ``oversample`` sub-pixels. Without ``normalize`` the taps
    sum to the PSF power inside the window (< 1: the truncated Airy tail, see ``benchmarks/bench_sensor.py``); with
    ``normalize`` (default) each kernel is rescaled to sum to 1 so the blur conserves flux.

    Args:
        wavelengths_nm: band centres in nm, C values.
        f_number: N (dimensionless).
        pixel_pitch_m: pixel pitch in m.
        radius_px: truncation radius R in pixels (0 gives the identity kernel).
        oversample: sub-samples per pixel side (>= 1).
        normalize: rescale each kernel to unit sum.

    Returns:
        kernels of shape (C, 2R+1, 2R+1), dimensionless power fractions.
    """
    if radius_px < 0 or int(radius_px) != radius_px:
        raise ValueError(f"radius_px must be an integer >= 0, got {radius_px!r}")
    if oversample < 1 or int(oversample) != oversample:
        raise ValueError(f"oversample must be an integer >= 1, got {oversample!r}")
    if not pixel_pitch_m > 0:
        raise ValueError(f"pixel_pitch_m must be > 0 (m), got {pixel_pitch_m!r}")
    if not f_number > 0:
        raise ValueError(f"f_number must be > 0, got {f_number!r}")
    wl = torch.as_tensor(wavelengths_nm, dtype=torch.float64, device=device).reshape(-1)
    if wl.numel() == 0 or not bool(torch.isfinite(wl).all()) or bool((wl <= 0).any()):
        raise ValueError("wavelengths_nm must be a non-empty sequence of finite values > 0 (nm)")
    R = int(radius_px)
    s = int(oversample)
    # sub-pixel centre offsets inside one pixel, in pixel units: (j + 0.5)/s - 0.5
    sub = (torch.arange(s, dtype=torch.float64, device=device) + 0.5) / s - 0.5
    taps = torch.arange(-R, R + 1, dtype=torch.float64, device=device)
    coord = (taps[:, None] + sub[None, :]).reshape(-1) * pixel_pitch_m          # (K*s,) in m
    r = torch.sqrt(coord[:, None] ** 2 + coord[None, :] ** 2)                    # (K*s, K*s)
    lam = (wl * M_PER_NM)[:, None, None]                                         # (C, 1, 1)
    psf = airy_psf(r[None], lam, f_number)                                       # (C, K*s, K*s) in 1/m^2
    K = 2 * R + 1
    sub_area = (pixel_pitch_m / s) ** 2
    kern = psf.reshape(-1, K, s, K, s).sum(dim=(2, 4)) * sub_area              # (C, K, K)
    if normalize:
        kern = kern / kern.sum(dim=(-2, -1), keepdim=True)
    return kern.to(dtype)


def apply_psf(image: torch.Tensor, kernel: torch.Tensor, method: PsfMethod = "auto",
              padding: Literal["replicate", "reflect", "zeros"] = "replicate") -> torch.Tensor:
    """Convolve every band of ``image`` with its own PSF kernel (same-size output).

    Direct ``conv2d`` (groups = C) and FFT convolution give the same result up to rounding; ``"auto"`` picks
    direct convolution for kernels smaller than :data:`FFT_CROSSOVER_KERNEL_SIZE`. For a non-negative image and
    kernel (and no autograd), round-off negatives are clipped to 0.

    Args:
        image: (*, C, H, W) spectral irradiance (any linear quantity).
        kernel: (C, k, k) or (1, k, k) kernels, k odd, dtype/device converted to the image's.
        method: ``"auto"``, ``"fft"`` or ``"conv"``.
        padding: how the border is extended ("replicate": edge pixels continue outside the field of view).

    Returns:
        blurred image, shape (*, C, H, W), dtype and device of ``image``.
    """
    if image.dim() < 3:
        raise ValueError(f"image must have shape (*, C, H, W), got {tuple(image.shape)}")
    if kernel.dim() != 3 or kernel.shape[-1] != kernel.shape[-2] or kernel.shape[-1] % 2 != 1:
        raise ValueError(f"kernel must have shape (C, k, k) with k odd, got {tuple(kernel.shape)}")
    C, H, W = image.shape[-3:]
    if kernel.shape[0] not in (1, C):
        raise ValueError(f"kernel has {kernel.shape[0]} bands but image has C={C}")
    if method not in ("auto", "fft", "conv"):
        raise ValueError(f"method must be 'auto', 'fft' or 'conv', got {method!r}")
    k = kernel.shape[-1]
    R = k // 2
    if R == 0:
        return image * kernel.to(image.dtype).to(image.device).reshape(-1, 1, 1)
    lead = image.shape[:-3]
    x = image.reshape(-1, C, H, W)
    kern = kernel.to(device=image.device, dtype=image.dtype).expand(C, k, k)
    mode = "constant" if padding == "zeros" else padding
    if mode == "reflect" and (R >= H or R >= W):
        mode = "replicate"
    xp = F.pad(x, (R, R, R, R), mode=mode)
    if method == "auto":
        method = "conv" if k < FFT_CROSSOVER_KERNEL_SIZE else "fft"
    if method == "conv":
        # conv2d is a cross-correlation: flip the kernel to convolve
        y = F.conv2d(xp, kern.flip(-1, -2)[:, None], groups=C)
    else:
        Hp, Wp = H + 2 * R, W + 2 * R
        n = (Hp + k - 1, Wp + k - 1)                                             # full linear-convolution size
        Y = torch.fft.rfft2(xp, s=n) * torch.fft.rfft2(kern, s=n)
        y = torch.fft.irfft2(Y, s=n)[..., 2 * R:2 * R + H, 2 * R:2 * R + W]
    # FFT (and Winograd-type conv) round-off leaves tiny negative values (~1e-7 of the peak in float32) where the
    # true convolution of a non-negative image and kernel is >= 0; remove them so radiometric checks downstream hold
    if not image.requires_grad and float(kern.min()) >= 0 and float(x.min()) >= 0:
        y = y.clamp_min(0.0)
    return y.reshape(*lead, C, H, W)


def simulate_optics(radiance: torch.Tensor, wavelengths_nm: Sequence[float] | torch.Tensor, config: OpticsConfig,
                    pixel_pitch_m: float, psf: bool | None = None, kernel: torch.Tensor | None = None,
                    check: bool = True) -> torch.Tensor:
    """Scene spectral radiance -> spectral irradiance at the pixels (camera equation, cos^4, Airy blur).

    Args:
        radiance: (*, C, H, W) spectral radiance in W sr^-1 m^-2 nm^-1, sampled at the pixel grid.
        wavelengths_nm: C band centres in nm.
        config: lens parameters.
        pixel_pitch_m: pixel pitch in m.
        psf: override ``config.psf`` (``False`` switches diffraction off).
        kernel: precomputed (C, k, k) kernel from :func:`airy_kernel` (saves recomputing it per call).
        check: validate ``radiance``.

    Returns:
        (*, C, H, W) spectral irradiance in W m^-2 nm^-1.
    """
    if check:
        check_radiometric(radiance, "radiance")
    C = radiance.shape[-3]
    wl = torch.as_tensor(wavelengths_nm, dtype=torch.float64, device=radiance.device).reshape(-1)
    if wl.numel() != C:
        raise ValueError(f"wavelengths_nm has {wl.numel()} values but radiance has C={C} bands")
    E = radiance_to_irradiance(radiance, config.f_number, config.transmittance, config.magnification, check=False)
    if config.cos4:
        E = E * cos4_falloff(E.shape[-2], E.shape[-1], pixel_pitch_m, config.focal_length_m,
                             device=E.device, dtype=E.dtype)
    use_psf = config.psf if psf is None else psf
    if use_psf and config.psf_radius_px > 0:
        if kernel is None:
            n_w = config.f_number * (1.0 + abs(config.magnification))
            kernel = airy_kernel(wl, n_w, pixel_pitch_m, config.psf_radius_px, config.psf_oversample,
                                 dtype=E.dtype, device=E.device)
        E = apply_psf(E, kernel)
    return E


class DiffractionOptics(nn.Module):
    """``nn.Module`` wrapper of :func:`simulate_optics`; caches the PSF kernels per device and dtype.

    Args:
        wavelengths_nm: C band centres in nm.
        config: :class:`OpticsConfig` (lens).
        pixel_pitch_m: pixel pitch in m.

    Shape:
        input (*, C, H, W) spectral radiance in W sr^-1 m^-2 nm^-1; output (*, C, H, W) irradiance in W m^-2 nm^-1.
    """

    def __init__(self, wavelengths_nm: Sequence[float], config: OpticsConfig | None = None,
                 pixel_pitch_m: float = 2.8e-6) -> None:
        super().__init__()
        self.wavelengths_nm = [float(w) for w in wavelengths_nm]
        self.config = config if config is not None else OpticsConfig()
        self.pixel_pitch_m = float(pixel_pitch_m)
        self._kernels: dict[tuple[str, torch.dtype], torch.Tensor] = {}

    def kernel(self, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
        """(C, 2R+1, 2R+1) PSF kernels for ``device``/``dtype`` (computed once)."""
        key = (str(device), dtype)
        if key not in self._kernels:
            c = self.config
            self._kernels[key] = airy_kernel(self.wavelengths_nm, c.f_number * (1.0 + abs(c.magnification)),
                                             self.pixel_pitch_m, c.psf_radius_px, c.psf_oversample,
                                             dtype=dtype, device=device)
        return self._kernels[key]

    def forward(self, radiance: torch.Tensor) -> torch.Tensor:
        kern = None
        if self.config.psf and self.config.psf_radius_px > 0:
            kern = self.kernel(radiance.device, radiance.dtype)
        return simulate_optics(radiance, self.wavelengths_nm, self.config, self.pixel_pitch_m, kernel=kern)
