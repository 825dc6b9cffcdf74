"""Emission spectra in absolute units, from colour-science's physical models and measured tables.

A scene stores each emitter's spectrum as a small dict (plain JSON) plus a target luminance (cd/m^2); this
module turns it into a spectral radiance L(lambda) in W sr^-1 m^-2 nm^-1 on a 1 nm grid over
[:data:`WL_MIN_NM`, :data:`WL_MAX_NM`] (Mitsuba's spectral range), scaled so that

    Lv = K_m * integral L(lambda) V(lambda) dlambda,   K_m = 683 lm/W              (CIE 015:2018, eq. 7.1)

equals the target, with V(lambda) = ybar of the CIE 1931 2-degree observer (colour-science
``MSDS_CMFS['CIE 1931 2 Degree Standard Observer']``). No other normalisation is applied anywhere.

Spectrum models (``spec["model"]``), dispatched through :data:`SPECTRUM_MODELS`:
- ``"led"``: single-colour LED, Ohno (2005) model ``colour.sd_single_led(peak_nm, half_spectral_width=fwhm_nm)``
  (Y. Ohno, "Spectral design considerations for white LED color rendering", Opt. Eng. 44(11), 2005).
- ``"light_source"``: a measured table of ``colour.SDS_LIGHT_SOURCES[name]`` (e.g. ``"Phosphor LED YAG"``,
  ``"HPS"``, ``"LPS"``).
- ``"illuminant"``: ``colour.SDS_ILLUMINANTS[name]`` (e.g. CIE ``"LED-B3"``, ``"HP1"``, ``"D65"``).
- ``"daylight"``: CIE D-series daylight at correlated colour temperature ``cct_k`` (K)
  (``colour.sd_CIE_illuminant_D_series``; CIE 015:2018 sec. 4.1.2).
Tables are interpolated linearly onto the 1 nm grid and set to 0 outside their measured range.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

#: Spectral range of Mitsuba's spectral variants (MI_CIE_MIN, MI_CIE_MAX), nm.
WL_MIN_NM = 360.0
WL_MAX_NM = 830.0
#: Grid step of emitted spectra, nm.
WL_STEP_NM = 1.0
#: Maximum luminous efficacy of photopic vision, lm/W (CIE 015:2018).
K_M_LM_PER_W = 683.0
#: Colour-matching functions used for luminance and XYZ.
CMFS_NAME = "CIE 1931 2 Degree Standard Observer"

#: Spectrum models and their required (and optional) parameters.
SPECTRUM_MODELS = {
    "led": {"required": ("peak_nm", "fwhm_nm"), "optional": ()},
    "light_source": {"required": ("name",), "optional": ()},
    "illuminant": {"required": ("name",), "optional": ()},
    "daylight": {"required": ("cct_k",), "optional": ()},
}


def wavelengths() -> np.ndarray:
    """The 1 nm emission grid (N,) in nm, 360..830."""
    return np.arange(WL_MIN_NM, WL_MAX_NM + 0.5 * WL_STEP_NM, WL_STEP_NM)


@lru_cache(maxsize=1)
def _ybar() -> np.ndarray:
    import colour  # noqa: PLC0415

    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    wl = wavelengths()
    return np.interp(wl, cmfs.wavelengths, cmfs.values[:, 1], left=0.0, right=0.0)


@lru_cache(maxsize=1)
def _xyz_bar() -> np.ndarray:
    import colour  # noqa: PLC0415

    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    wl = wavelengths()
    return np.stack([np.interp(wl, cmfs.wavelengths, cmfs.values[:, i], left=0.0, right=0.0) for i in range(3)], -1)


def validate_spectrum(spec, where: str = "spectrum") -> dict:
    """Check a spectrum dict; returns it. Raises ``ValueError`` naming ``where`` and the field."""
    import colour  # noqa: PLC0415

    if not isinstance(spec, dict):
        raise ValueError(f"{where}: expected an object, got {type(spec).__name__}")
    model = spec.get("model")
    if model not in SPECTRUM_MODELS:
        raise ValueError(f"{where}.model: {model!r} not one of {sorted(SPECTRUM_MODELS)}")
    req, opt = SPECTRUM_MODELS[model]["required"], SPECTRUM_MODELS[model]["optional"]
    for k in spec:
        if k != "model" and k not in req and k not in opt:
            raise ValueError(f"{where}.{k}: unknown field for model {model!r} (allowed: {list(req + opt)})")
    for k in req:
        if k not in spec:
            raise ValueError(f"{where}.{k}: missing (required for model {model!r})")
    if model == "led":
        if not (isinstance(spec["peak_nm"], (int, float)) and 380 <= spec["peak_nm"] <= 780):
            raise ValueError(f"{where}.peak_nm: must be a number in [380, 780] nm, got {spec['peak_nm']!r}")
        if not (isinstance(spec["fwhm_nm"], (int, float)) and 1 <= spec["fwhm_nm"] <= 200):
            raise ValueError(f"{where}.fwhm_nm: must be a number in [1, 200] nm, got {spec['fwhm_nm']!r}")
    elif model == "light_source" and spec["name"] not in colour.SDS_LIGHT_SOURCES:
        raise ValueError(f"{where}.name: {spec['name']!r} is not in colour.SDS_LIGHT_SOURCES")
    elif model == "illuminant" and spec["name"] not in colour.SDS_ILLUMINANTS:
        raise ValueError(f"{where}.name: {spec['name']!r} is not in colour.SDS_ILLUMINANTS")
    elif model == "daylight" and not (isinstance(spec["cct_k"], (int, float)) and 4000 <= spec["cct_k"] <= 25000):
        raise ValueError(f"{where}.cct_k: CIE D series needs 4000..25000 K, got {spec['cct_k']!r}")
    return spec


def relative_spectrum(spec: dict) -> np.ndarray:
    """Relative spectral distribution (N,) on :func:`wavelengths` (arbitrary scale, max 1)."""
    import colour  # noqa: PLC0415

    validate_spectrum(spec)
    wl = wavelengths()
    m = spec["model"]
    if m == "led":
        shape = colour.SpectralShape(WL_MIN_NM, WL_MAX_NM, WL_STEP_NM)
        sd = colour.sd_single_led(float(spec["peak_nm"]), half_spectral_width=float(spec["fwhm_nm"]), shape=shape)
    elif m == "light_source":
        sd = colour.SDS_LIGHT_SOURCES[spec["name"]]
    elif m == "illuminant":
        sd = colour.SDS_ILLUMINANTS[spec["name"]]
    else:  # daylight
        xy = colour.temperature.CCT_to_xy_CIE_D(float(spec["cct_k"]))
        sd = colour.sd_CIE_illuminant_D_series(xy)
    v = np.interp(wl, sd.wavelengths, np.clip(sd.values, 0.0, None), left=0.0, right=0.0)
    if not np.any(v > 0):
        raise ValueError(f"spectrum: {spec!r} is zero on {WL_MIN_NM}..{WL_MAX_NM} nm")
    return v / v.max()


def luminance(values: np.ndarray, wl_nm: np.ndarray | None = None) -> np.ndarray:
    """Luminance (cd/m^2) of spectral radiance ``values`` (..., N) W sr^-1 m^-2 nm^-1 on ``wl_nm`` (N,) nm
    (default :func:`wavelengths`): ``683 * sum L ybar dlambda`` (trapezoid rule)."""
    values = np.asarray(values, dtype=np.float64)
    if wl_nm is None:
        wl_nm, yb = wavelengths(), _ybar()
    else:
        import colour  # noqa: PLC0415

        cm = colour.MSDS_CMFS[CMFS_NAME]
        wl_nm = np.asarray(wl_nm, dtype=np.float64)
        yb = np.interp(wl_nm, cm.wavelengths, cm.values[:, 1], left=0.0, right=0.0)
    if values.shape[-1] != wl_nm.shape[0]:
        raise ValueError(f"values: last axis {values.shape[-1]} != number of wavelengths {wl_nm.shape[0]}")
    return K_M_LM_PER_W * np.trapezoid(values * yb, wl_nm, axis=-1)


def absolute_spectrum(spec: dict, luminance_cd_m2: float) -> np.ndarray:
    """Spectral radiance (N,) W sr^-1 m^-2 nm^-1 on :func:`wavelengths` with luminance ``luminance_cd_m2``."""
    if not (isinstance(luminance_cd_m2, (int, float)) and math.isfinite(luminance_cd_m2) and luminance_cd_m2 >= 0):
        raise ValueError(f"luminance_cd_m2: must be finite and >= 0 cd/m^2, got {luminance_cd_m2!r}")
    rel = relative_spectrum(spec)
    return rel * (float(luminance_cd_m2) / float(luminance(rel)))


def band_means(values: np.ndarray, bands_nm, band_width_nm: float) -> np.ndarray:
    """Mean of a spectrum (..., N) on :func:`wavelengths` over box bands [c - w/2, c + w/2] -> (..., C).

    This is what a ``specfilm`` box band returns after division by its width (the expected per-nm value).
    """
    wl = wavelengths()
    fine = np.arange(WL_MIN_NM, WL_MAX_NM, 0.05) + 0.025
    vals = np.asarray(values, dtype=np.float64)
    f = np.apply_along_axis(lambda v: np.interp(fine, wl, v), -1, vals)
    out = []
    for c in bands_nm:
        sel = (fine >= c - band_width_nm / 2) & (fine < c + band_width_nm / 2)
        out.append(f[..., sel].mean(-1))
    return np.stack(out, -1)


def mitsuba_spectrum(values: np.ndarray, scale: float = 1.0) -> dict:
    """Mitsuba ``regular`` spectrum dict for values (N,) on :func:`wavelengths` (units kept), times ``scale``."""
    v = np.asarray(values, dtype=np.float64) * scale
    if v.shape != wavelengths().shape or not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError("values: expected a finite, non-negative spectrum on the 360..830 nm 1 nm grid")
    return {"type": "regular", "wavelength_min": WL_MIN_NM, "wavelength_max": WL_MAX_NM,
            "values": ", ".join(f"{x:.9g}" for x in v)}


def spectral_to_xyz(img: np.ndarray, bands_nm, band_width_nm: float) -> np.ndarray:
    """CIE XYZ (3, H, W) (Y in cd/m^2) of a band image (C, H, W) W sr^-1 m^-2 nm^-1 with box bands.

    X = 683 * sum_c L_c * integral over band c of xbar (same for Y, Z); bands are assumed disjoint.
    """
    img = np.asarray(img, dtype=np.float64)
    if img.ndim != 3 or img.shape[0] != len(bands_nm):
        raise ValueError(f"img: expected (C={len(bands_nm)}, H, W), got {img.shape}")
    wl, cmf = wavelengths(), _xyz_bar()
    w = np.zeros((len(bands_nm), 3))
    for i, c in enumerate(bands_nm):
        fine = np.linspace(c - band_width_nm / 2, c + band_width_nm / 2, 41)
        for j in range(3):
            w[i, j] = np.trapezoid(np.interp(fine, wl, cmf[:, j]), fine)
    return K_M_LM_PER_W * np.einsum("chw,cj->jhw", img, w)
