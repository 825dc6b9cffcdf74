r"""Colour stages of the ISP: white balance from the preset's QE, the colour-correction matrix (CCM) fitted from
the preset's QE curves, and sRGB encoding.

Defines
-------
- :func:`camera_rgb`: mean photo-electron response (relative) of the preset's r, g, b pixels to reflectances under
  an illuminant, from the preset's spectral QE (photon counting).
- :func:`white_balance_gains`: per-channel gains that make a perfect white under an illuminant neutral.
- :func:`fit_ccm`: the 3x3 matrix from white-balanced camera RGB to linear sRGB (IEC 61966-2-1 primaries, D65),
  fitted on the 24 ColorChecker patches under D65 by white-preserving least squares, with its CIE dE2000 error.
- :func:`apply_ccm`: ``(*, 3, H, W)`` linear camera RGB -> linear sRGB.
- :func:`srgb_encode`, :func:`srgb_decode`: the sRGB transfer function of IEC 61966-2-1.
- :func:`luminance`: relative luminance Y of linear sRGB (ITU-R BT.709 coefficients).

Units: camera RGB and linear sRGB are linear, relative (the scale of the input: e.g. input-referred e-); encoded
sRGB is the dimensionless display code value in [0, 1].

References
----------
- IEC 61966-2-1:1999, "Multimedia systems and equipment - Colour measurement and management - Part 2-1: Colour
  management - Default RGB colour space - sRGB" (transfer function, primaries, D65 white).
- ITU-R Recommendation BT.709-6 (2015): luminance coefficients 0.2126, 0.7152, 0.0722.
- CIE 015:2018 "Colorimetry", 4th ed.: CIE 1931 standard observer, illuminant D65, CIELAB.
- G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula: implementation notes, supplementary
  test data, and mathematical observations", Color Research & Application 30(1), 2005 (dE2000).
- Y. Ohta, ColorChecker spectral reflectances as shipped by colour-science (``SDS_COLOURCHECKERS['ColorChecker N
  Ohta']``); C. S. McCamy, H. Marcus, J. G. Davidson, "A color-rendition chart", J. Applied Photographic
  Engineering 2(3), 1976.
- G. D. Finlayson, M. S. Drew, "Constrained least-squares regression in color spaces", Journal of Electronic
  Imaging 6(4), 1997 (white-point preserving least squares).
- T. Mansencal et al., colour-science (Colour Science for Python), https://www.colour-science.org/ (spectral data,
  ``sd_to_XYZ``, ``XYZ_to_Lab``, ``delta_E``, ``eotf_inverse_sRGB``).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

__all__ = ["CCMFit", "camera_rgb", "white_balance_gains", "fit_ccm", "apply_ccm", "srgb_encode", "srgb_decode",
           "luminance", "ColorCorrection", "SRGBEncode", "SPECTRAL_RANGE_NM", "BT709_LUMA"]

#: Spectral grid of the colorimetric fits: start, end, step in nm (the ColorChecker data's 380-780 nm at 5 nm).
SPECTRAL_RANGE_NM = (380.0, 780.0, 5.0)
#: Relative luminance of linear sRGB / BT.709 primaries (ITU-R BT.709-6).
BT709_LUMA = (0.2126, 0.7152, 0.0722)
#: sRGB transfer function constants (IEC 61966-2-1): linear segment below 0.0031308 (slope 12.92), else
#: 1.055 x^(1/2.4) - 0.055.
_SRGB_THRESHOLD, _SRGB_SLOPE, _SRGB_GAMMA, _SRGB_A = 0.0031308, 12.92, 2.4, 0.055


def _colour():
    try:
        import colour  # noqa: PLC0415 (colour-science; a core dependency, imported when a fit is needed)
    except ImportError as exc:  # pragma: no cover - a core dependency
        raise ImportError("the CCM fit needs colour-science: pip install colour-science") from exc
    return colour


def _grid():
    colour = _colour()
    lo, hi, step = SPECTRAL_RANGE_NM
    return colour, colour.SpectralShape(lo, hi, step)


def _qe(preset, wl: np.ndarray) -> np.ndarray:
    """(3, N) absolute QE of the preset's r, g, b pixels (its public spectral curves) on ``wl`` (nm)."""
    from lfmbench.sensor.response import spectral_qe  # noqa: PLC0415

    return spectral_qe(preset, wl)


def camera_rgb(preset, reflectances: np.ndarray, illuminant: str = "D65") -> np.ndarray:
    r"""Relative mean photo-electrons of the r, g, b pixels for surfaces under an illuminant.

    .. math:: c_k = \sum_\lambda \rho(\lambda)\, E(\lambda)\, QE_k(\lambda)\, \lambda\, \Delta\lambda

    (photon count: energy x lambda / (h c); constant factors dropped), with E the illuminant's relative spectral
    power (colour-science ``SDS_ILLUMINANTS``) and QE the preset's spectral QE.

    Args:
        preset: a :class:`lfmbench.sensor.SensorPreset` or preset name.
        reflectances: (N, W) spectral reflectances (dimensionless) on :data:`SPECTRAL_RANGE_NM`.
        illuminant: a colour-science illuminant name.

    Returns:
        (N, 3) relative responses (arbitrary linear unit, same for every row).
    """
    colour, shape = _grid()
    wl = shape.wavelengths
    e = colour.SDS_ILLUMINANTS[illuminant].copy().align(shape).values
    return (np.asarray(reflectances, dtype=np.float64) * (e * wl)) @ _qe(preset, wl).T


def white_balance_gains(preset, illuminant: str = "D65") -> np.ndarray:
    """Gains (r, g, b) that make a perfect white under ``illuminant`` neutral, green gain 1 (dimensionless).

    Args:
        preset: sensor preset or name (only its spectral QE is read).
        illuminant: colour-science illuminant name.

    Returns:
        (3,) float64.
    """
    _, shape = _grid()
    w = camera_rgb(preset, np.ones((1, len(shape.wavelengths))), illuminant)[0]
    if not np.all(w > 0):
        raise ValueError(f"white balance: the preset's QE gives no response to white in channel(s) "
                         f"{[c for c, v in zip('rgb', w) if not v > 0]}")
    return w[1] / w


@dataclass(frozen=True)
class CCMFit:
    """A fitted colour-correction matrix and its error on the ColorChecker.

    Attributes:
        matrix: (3, 3) white-balanced camera RGB -> linear sRGB (rows sum to 1: white preserved).
        wb_gains: (3,) the white-balance gains the matrix expects to have been applied (green 1).
        de2000: (24,) CIE dE2000 of each patch (predicted vs true colour, CIELAB under D65).
        patches: the 24 patch names.
        illuminant: the illuminant of the fit.
    """

    matrix: np.ndarray
    wb_gains: np.ndarray
    de2000: np.ndarray
    patches: tuple[str, ...]
    illuminant: str

    @property
    def mean_de2000(self) -> float:
        """Mean CIE dE2000 over the 24 patches."""
        return float(np.mean(self.de2000))

    @property
    def max_de2000(self) -> float:
        """Largest CIE dE2000 over the 24 patches."""
        return float(np.max(self.de2000))


def _white_preserving_lstsq(cam: np.ndarray, target: np.ndarray) -> np.ndarray:
    """argmin_M sum ||M c_i - t_i||^2 subject to M 1 = 1 (Finlayson & Drew 1997), one row at a time by the KKT
    system [2 C^T C, 1; 1^T, 0] [m; l] = [2 C^T t; 1]. cam, target: (N, 3). Returns (3, 3)."""
    a = np.zeros((4, 4))
    a[:3, :3] = 2.0 * cam.T @ cam
    a[:3, 3] = 1.0
    a[3, :3] = 1.0
    rows = [np.linalg.solve(a, np.r_[2.0 * cam.T @ target[:, r], 1.0])[:3] for r in range(3)]
    return np.stack(rows)


def fit_ccm(preset, illuminant: str = "D65", chart: str = "ColorChecker N Ohta") -> CCMFit:
    """Fit the CCM of a preset from its QE curves: white-balanced camera RGB -> linear sRGB.

    The 24 patches' camera responses (:func:`camera_rgb`, white-balanced with :func:`white_balance_gains`, so a
    perfect white gives (1, 1, 1)) are regressed onto their linear sRGB values (CIE 1931 2-degree XYZ under
    ``illuminant`` -> sRGB primaries, D65 white; a perfect white gives Y = 1) by white-preserving least squares.
    The error is CIE dE2000 between the CIELAB colours (D65 white) of the prediction and of the truth.

    Args:
        preset: sensor preset or name (only its spectral QE is read).
        illuminant: colour-science illuminant name (default D65).
        chart: colour-science ``SDS_COLOURCHECKERS`` name.

    Returns:
        :class:`CCMFit`.
    """
    from lfmbench.sensor.preset import resolve  # noqa: PLC0415

    preset = resolve(preset)
    return _fit_ccm_cached(preset, illuminant, chart)


@functools.lru_cache(maxsize=16)
def _fit_ccm_cached(preset, illuminant: str, chart: str) -> CCMFit:
    colour, _ = _grid()
    # colour-science warns that the 5 nm data cannot be interpolated to its 1 nm default grid: expected, silenced
    with colour.utilities.suppress_warnings(colour_runtime_warnings=True):
        return _fit(preset, illuminant, chart)


def _fit(preset, illuminant: str, chart: str) -> CCMFit:
    colour, shape = _grid()
    cc = colour.SDS_COLOURCHECKERS[chart]
    names = tuple(cc)
    refl = np.stack([sd.copy().align(shape).values for sd in cc.values()])
    gains = white_balance_gains(preset, illuminant)
    white = camera_rgb(preset, np.ones((1, refl.shape[1])), illuminant)[0]
    cam = camera_rgb(preset, refl, illuminant) / white  # white-balanced: a perfect white -> (1, 1, 1)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    ill = colour.SDS_ILLUMINANTS[illuminant].copy().align(shape)
    xyz_white = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(shape.wavelengths, np.ones(refl.shape[1])))),
                                 cmfs, ill)
    xyz = np.stack([colour.sd_to_XYZ(sd.copy().align(shape), cmfs, ill) for sd in cc.values()]) / xyz_white[1]
    wp = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    target = colour.XYZ_to_RGB(xyz, "sRGB", illuminant=wp)  # linear sRGB (no transfer function)
    m = _white_preserving_lstsq(cam, target)
    lab_true = colour.XYZ_to_Lab(xyz, wp)
    lab_pred = colour.XYZ_to_Lab(colour.RGB_to_XYZ(cam @ m.T, "sRGB", illuminant=wp), wp)
    de = np.asarray(colour.delta_E(lab_pred, lab_true, method="CIE 2000"), dtype=np.float64)
    return CCMFit(matrix=m, wb_gains=gains, de2000=de, patches=names, illuminant=illuminant)


def apply_ccm(rgb: torch.Tensor, matrix: torch.Tensor | np.ndarray) -> torch.Tensor:
    """Multiply every pixel's colour by a 3x3 matrix: ``out[..., i, y, x] = sum_j M[i, j] rgb[..., j, y, x]``.

    Args:
        rgb: (*, 3, H, W) linear colour (any linear unit).
        matrix: (3, 3).

    Returns:
        (*, 3, H, W), same unit, dtype and device as ``rgb``.
    """
    if rgb.ndim < 3 or rgb.shape[-3] != 3:
        raise ValueError(f"rgb must have shape (*, 3, H, W), got {tuple(rgb.shape)}")
    m = torch.as_tensor(np.asarray(matrix) if not isinstance(matrix, torch.Tensor) else matrix,
                        dtype=rgb.dtype, device=rgb.device)
    if m.shape != (3, 3):
        raise ValueError(f"matrix must have shape (3, 3), got {tuple(m.shape)}")
    return torch.einsum("ij,...jhw->...ihw", m, rgb)


def srgb_encode(x: torch.Tensor) -> torch.Tensor:
    """Linear sRGB -> encoded sRGB (IEC 61966-2-1): ``12.92 x`` for x <= 0.0031308, else
    ``1.055 x^(1/2.4) - 0.055``; input clipped to [0, 1] first (a display cannot show more).

    Args:
        x: linear sRGB, any shape, relative to the display white (1).

    Returns:
        Encoded values in [0, 1], same shape/dtype. Differentiable inside (0, 1) (finite gradient everywhere).

    Example:
        >>> [round(v, 6) for v in srgb_encode(torch.tensor([0.0, 0.001, 0.18, 1.0], dtype=torch.float64)).tolist()]
        [0.0, 0.01292, 0.461356, 1.0]
    """
    x = x.clamp(0.0, 1.0)
    hi = _SRGB_A + 1.0
    safe = torch.clamp(x, min=_SRGB_THRESHOLD)  # keeps the unused branch's gradient finite below the threshold
    return torch.where(x <= _SRGB_THRESHOLD, _SRGB_SLOPE * x, hi * safe.pow(1.0 / _SRGB_GAMMA) - _SRGB_A)


def srgb_decode(v: torch.Tensor) -> torch.Tensor:
    """Encoded sRGB -> linear sRGB (IEC 61966-2-1 EOTF): ``v / 12.92`` for v <= 0.04045, else
    ``((v + 0.055) / 1.055)^2.4``; input clipped to [0, 1].

    Args:
        v: encoded values, any shape, in [0, 1].

    Returns:
        Linear values in [0, 1], same shape/dtype.
    """
    v = v.clamp(0.0, 1.0)
    knee = _SRGB_THRESHOLD * _SRGB_SLOPE
    safe = torch.clamp(v, min=knee)
    return torch.where(v <= knee, v / _SRGB_SLOPE, ((safe + _SRGB_A) / (1.0 + _SRGB_A)).pow(_SRGB_GAMMA))


def luminance(rgb: torch.Tensor) -> torch.Tensor:
    """Relative luminance Y = 0.2126 R + 0.7152 G + 0.0722 B of linear sRGB (ITU-R BT.709-6).

    Args:
        rgb: (*, 3, H, W) linear sRGB.

    Returns:
        (*, 1, H, W) in the unit of ``rgb``.
    """
    if rgb.ndim < 3 or rgb.shape[-3] != 3:
        raise ValueError(f"rgb must have shape (*, 3, H, W), got {tuple(rgb.shape)}")
    w = torch.tensor(BT709_LUMA, dtype=rgb.dtype, device=rgb.device)
    return torch.einsum("j,...jhw->...hw", w, rgb).unsqueeze(-3)


class ColorCorrection(nn.Module):
    """``nn.Module`` of :func:`apply_ccm` with a fixed matrix (a buffer, moves with ``.to(device)``).

    Args:
        matrix: (3, 3) camera RGB -> linear sRGB, e.g. ``fit_ccm(preset).matrix``.
    """

    def __init__(self, matrix) -> None:
        super().__init__()
        self.register_buffer("matrix", torch.as_tensor(np.asarray(matrix), dtype=torch.float32), persistent=False)

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        """(*, 3, H, W) -> (*, 3, H, W)."""
        return apply_ccm(rgb, self.matrix)


class SRGBEncode(nn.Module):
    """``nn.Module`` of :func:`srgb_encode`."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Any shape, linear in [0, 1] -> encoded in [0, 1]."""
        return srgb_encode(x)
