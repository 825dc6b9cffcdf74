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

Precomputed table (:data:`TABLE_FILE`): importing colour-science costs 2-3 s (it imports matplotlib and
scipy), more than a render spends on all of its spectra. So the CIE 1931 colour-matching functions on the
1 nm grid and the relative spectra (:func:`relative_spectrum`) of every spectrum the scene generator's
default configuration uses (``render_tools/configs/scene_defaults.yaml``, and D65 of
:func:`render_tools.scene.empty_scene`) are stored in a small CSV file written from colour-science by
``python -m render_tools.spectra_table`` (:func:`render_tools.spectra_table.write_table`; exact float64 values). Any other spectrum, and the
name check of a model not in the table, falls back to colour-science; ``tests/render_tools/test_render_scene.py`` checks
the table against colour-science's own output.
"""
from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from lfmbench.limits import brief
from lfmbench.vocabulary import SPECTRUM_MODELS

#: Spectral range of Mitsuba's spectral variants (MI_CIE_MIN, MI_CIE_MAX), nm.
WL_MIN_NM = 360.0
WL_MAX_NM = 830.0
#: Grid step of emitted spectra, nm.
WL_STEP_NM = 1.0
#: Maximum luminous efficacy of photopic vision, lm/W (CIE 015:2018).
K_M_LM_PER_W = 683.0
#: Colour-matching functions used for luminance and XYZ.
CMFS_NAME = "CIE 1931 2 Degree Standard Observer"



def wavelengths() -> np.ndarray:
    """The 1 nm emission grid (N,) in nm, 360..830."""
    return np.arange(WL_MIN_NM, WL_MAX_NM + 0.5 * WL_STEP_NM, WL_STEP_NM)


#: Precomputed CMFs and relative spectra (see the module docstring); written by :func:`render_tools.spectra_table.write_table`.
TABLE_FILE = Path(__file__).with_name("data") / "spectra_1nm.csv"
#: Columns of :data:`TABLE_FILE` holding the CIE 1931 colour-matching functions xbar, ybar, zbar.
CMF_COLUMNS = ("cie1931_xbar", "cie1931_ybar", "cie1931_zbar")
#: Relative spectra computed through colour-science kept per process (spectra not in the table).
_FALLBACK_CACHE_SIZE = 64


def spectrum_key(spec: dict) -> str:
    """Canonical name of a spectrum dict, its column in :data:`TABLE_FILE`: ``model(field=value;...)``, fields
    sorted, numbers as floats (``{"model": "led", "peak_nm": 630, "fwhm_nm": 18}`` ->
    ``led(fwhm_nm=18.0;peak_nm=630.0)``)."""
    fields = []
    for k in sorted(k for k in spec if k != "model"):
        v = spec[k]
        fields.append(f"{k}={brief(float(v))}" if isinstance(v, (int, float)) and not isinstance(v, bool) else f"{k}={v}")
    return f"{spec.get('model')}({';'.join(fields)})"


@lru_cache(maxsize=1)
def _table() -> dict[str, np.ndarray]:
    """Columns of :data:`TABLE_FILE` ({name: (N,) float64}); empty when the file is missing or unreadable (every
    spectrum then comes from colour-science)."""
    try:
        with open(TABLE_FILE, encoding="utf-8") as fh:
            lines = [ln for ln in fh if not ln.startswith("#")]
        names = lines[0].rstrip("\n").split(",")
        data = np.loadtxt(lines[1:], delimiter=",", dtype=np.float64, ndmin=2)
    except (OSError, ValueError, IndexError):
        return {}
    if data.shape != (wavelengths().size, len(names)) or not np.array_equal(data[:, 0], wavelengths()):
        return {}
    return {n: np.ascontiguousarray(data[:, i]) for i, n in enumerate(names)}


def _cmfs_colour() -> np.ndarray:
    """(N, 3) CIE 1931 xbar, ybar, zbar on :func:`wavelengths` from colour-science (0 outside its range)."""
    import colour  # noqa: PLC0415

    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    wl = wavelengths()
    return np.stack([np.interp(wl, cmfs.wavelengths, cmfs.values[:, i], left=0.0, right=0.0) for i in range(3)], -1)


@lru_cache(maxsize=1)
def _xyz_bar() -> np.ndarray:
    """(N, 3) CIE 1931 colour-matching functions on :func:`wavelengths` (table, else colour-science)."""
    t = _table()
    if all(c in t for c in CMF_COLUMNS):
        return np.stack([t[c] for c in CMF_COLUMNS], -1)
    return _cmfs_colour()


def _ybar() -> np.ndarray:
    """(N,) photopic luminous efficiency V = ybar on :func:`wavelengths`."""
    return _xyz_bar()[:, 1]


def validate_spectrum(spec, where: str = "spectrum") -> dict:
    """Check a spectrum dict; returns it. Raises ``ValueError`` naming ``where`` and the field.

    A ``light_source`` / ``illuminant`` name is checked against colour-science's tables unless the spectrum is
    in :data:`TABLE_FILE` (written from those tables), which spares the colour-science import."""
    if not isinstance(spec, dict):
        raise ValueError(f"{where}: expected an object, got {type(spec).__name__}")
    model = spec.get("model")
    if model not in SPECTRUM_MODELS:
        raise ValueError(f"{where}.model: {brief(model)} not one of {sorted(SPECTRUM_MODELS)}")
    req, opt = SPECTRUM_MODELS[model]["required"], SPECTRUM_MODELS[model]["optional"]
    for k in spec:
        if k != "model" and k not in req and k not in opt:
            raise ValueError(f"{where}.{k}: unknown field for model {brief(model)} (allowed: {list(req + opt)})")
    for k in req:
        if k not in spec:
            raise ValueError(f"{where}.{k}: missing (required for model {brief(model)})")
    if model == "led":
        if not (isinstance(spec["peak_nm"], (int, float)) and 380 <= spec["peak_nm"] <= 780):
            raise ValueError(f"{where}.peak_nm: must be a number in [380, 780] nm, got {brief(spec['peak_nm'])}")
        if not (isinstance(spec["fwhm_nm"], (int, float)) and 1 <= spec["fwhm_nm"] <= 200):
            raise ValueError(f"{where}.fwhm_nm: must be a number in [1, 200] nm, got {brief(spec['fwhm_nm'])}")
    elif model in ("light_source", "illuminant") and spectrum_key(spec) not in _table():
        import colour  # noqa: PLC0415

        known = colour.SDS_LIGHT_SOURCES if model == "light_source" else colour.SDS_ILLUMINANTS
        if not isinstance(spec["name"], str) or spec["name"] not in known:
            raise ValueError(f"{where}.name: {brief(spec['name'])} is not in colour."
                             f"{'SDS_LIGHT_SOURCES' if model == 'light_source' else 'SDS_ILLUMINANTS'}")
    elif model == "daylight" and not (isinstance(spec["cct_k"], (int, float)) and 4000 <= spec["cct_k"] <= 25000):
        raise ValueError(f"{where}.cct_k: CIE D series needs 4000..25000 K, got {brief(spec['cct_k'])}")
    return spec


def relative_spectrum(spec: dict) -> np.ndarray:
    """Relative spectral distribution (N,) on :func:`wavelengths` (arbitrary scale, max 1): the column of
    :data:`TABLE_FILE` when the spectrum is there, else computed with colour-science (kept per process)."""
    validate_spectrum(spec)
    key = spectrum_key(spec)
    col = _table().get(key)
    if col is None:
        col = _relative_cached(key, _freeze(spec))
    return col.copy()


def _freeze(spec: dict) -> tuple:
    return tuple(sorted(spec.items()))


@lru_cache(maxsize=_FALLBACK_CACHE_SIZE)
def _relative_cached(key: str, frozen: tuple) -> np.ndarray:
    return relative_spectrum_colour(dict(frozen))


def relative_spectrum_colour(spec: dict) -> np.ndarray:
    """:func:`relative_spectrum` computed with colour-science (no table): (N,) on :func:`wavelengths`, max 1."""
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
        raise ValueError(f"spectrum: {brief(spec)} is zero on {WL_MIN_NM}..{WL_MAX_NM} nm")
    return v / v.max()


def luminance(values: np.ndarray, wl_nm: np.ndarray | None = None) -> np.ndarray:
    """Luminance (cd/m^2) of spectral radiance ``values`` (..., N) W sr^-1 m^-2 nm^-1 on ``wl_nm`` (N,) nm
    (default :func:`wavelengths`): ``683 * sum L ybar dlambda`` (trapezoid rule)."""
    values = np.asarray(values, dtype=np.float64)
    if wl_nm is None:
        wl_nm, yb = wavelengths(), _ybar()
    else:  # the CMFs are tabulated at exactly the 1 nm grid nodes, so this equals colour-science's interpolation
        wl_nm = np.asarray(wl_nm, dtype=np.float64)
        yb = np.interp(wl_nm, wavelengths(), _ybar(), left=0.0, right=0.0)
    if values.shape[-1] != wl_nm.shape[0]:
        raise ValueError(f"values: last axis {values.shape[-1]} != number of wavelengths {wl_nm.shape[0]}")
    return K_M_LM_PER_W * np.trapezoid(values * yb, wl_nm, axis=-1)


def absolute_spectrum(spec: dict, luminance_cd_m2: float) -> np.ndarray:
    """Spectral radiance (N,) W sr^-1 m^-2 nm^-1 on :func:`wavelengths` with luminance ``luminance_cd_m2``."""
    if not (isinstance(luminance_cd_m2, (int, float)) and math.isfinite(luminance_cd_m2) and luminance_cd_m2 >= 0):
        raise ValueError(f"luminance_cd_m2: must be finite and >= 0 cd/m^2, got {brief(luminance_cd_m2)}")
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
