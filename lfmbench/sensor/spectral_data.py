"""Shipped spectral data of the sensor model: the CSV reader, band widths and a silicon photodiode QE model.

- :func:`read_spectral_csv`: a spectral CSV (``#`` comment header with the source, then ``wavelength_nm,...``).
- :func:`band_widths_nm`: the width in nm each spectral sample stands for.
- :func:`silicon_qe`: a documented internal-QE model of a silicon photodiode from Green's optical constants.

References
----------
.. [Green2008] M. A. Green, "Self-consistent optical parameters of intrinsic silicon at 300 K including
   temperature coefficients", Sol. Energy Mater. Sol. Cells 92, 1305 (2008).
.. [Hecht2017] E. Hecht, "Optics", 5th ed. (2017), sec. 4.6: normal-incidence reflectance
   R = ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2).
"""
from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from lfmbench.constants import M_PER_NM

__all__ = ["DATA_DIR", "read_spectral_csv", "band_widths_nm", "silicon_qe"]

#: Shipped spectral data (CSV with a source header).
DATA_DIR: Path = Path(__file__).resolve().parent.parent / "data"


@functools.lru_cache(maxsize=16)
def _read_csv_cached(path: str) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    p = Path(path)
    from lfmbench.fileio import read_bytes  # noqa: PLC0415 - bounded, regular files only

    try:
        lines = [ln.strip() for ln in read_bytes(p, "spectral file", "spectral_file_bytes").decode(
            "utf-8", "replace").splitlines()]
    except OSError as exc:
        raise ValueError(f"cannot read spectral file {path}: {exc.strerror or exc}") from None
    lines = [ln for ln in lines if ln and not ln.startswith("#")]
    if len(lines) < 3:
        raise ValueError(f"spectral file {path} has no data rows")
    header = [h.strip() for h in lines[0].split(",")]
    if header[0] != "wavelength_nm" or len(header) < 2:
        raise ValueError(f"spectral file {path}: first column must be 'wavelength_nm', got header {header}")
    try:
        arr = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]], dtype=np.float64)
    except ValueError as exc:
        raise ValueError(f"spectral file {path}: non-numeric data ({exc})") from exc
    if arr.ndim != 2 or arr.shape[1] != len(header):
        raise ValueError(f"spectral file {path}: every row must have {len(header)} values")
    if not np.all(np.isfinite(arr)) or np.any(np.diff(arr[:, 0]) <= 0):
        raise ValueError(f"spectral file {path}: values must be finite and wavelengths strictly increasing")
    return arr[:, 0], tuple(header[1:]), arr[:, 1:]


def read_spectral_csv(path: str | Path) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Read a spectral CSV (``#`` comment header with the source, then ``wavelength_nm,<names...>``).

    Returns:
        wavelengths in nm (N,), column names, values (N, K) (units as the file's header states).
    """
    wl, names, vals = _read_csv_cached(str(Path(path).resolve()))
    return wl.copy(), list(names), vals.copy()


def band_widths_nm(wavelengths_nm: Sequence[float] | torch.Tensor) -> np.ndarray:
    """Width in nm of the band each spectral sample stands for: the local spacing (``numpy.gradient``).

    On the corpus grid 400:10:700 every band is 10 nm wide (the renderer integrates 10 nm boxes). A single
    wavelength has no spacing: pass ``bandwidths_nm`` explicitly then.
    """
    wl = np.asarray(torch.as_tensor(wavelengths_nm, dtype=torch.float64, device="cpu"), dtype=np.float64).reshape(-1)
    if wl.size < 2:
        raise ValueError("bandwidths_nm must be given for a single wavelength (no spacing to infer a width from)")
    if np.any(np.diff(wl) <= 0):
        raise ValueError("wavelengths_nm must be strictly increasing")
    return np.gradient(wl)


def wavelengths_array(wavelengths_nm: Sequence[float] | torch.Tensor) -> np.ndarray:
    wl = np.asarray(torch.as_tensor(wavelengths_nm, dtype=torch.float64, device="cpu"), dtype=np.float64).reshape(-1)
    if wl.size == 0 or not np.all(np.isfinite(wl)) or np.any(wl <= 0):
        raise ValueError("wavelengths_nm must be a non-empty sequence of finite values > 0 (nm)")
    return wl


def silicon_qe(wavelengths_nm: Sequence[float] | np.ndarray, depth_m: float = 3e-6,
               reflectance: float | None = None) -> np.ndarray:
    r"""Internal quantum efficiency model of a silicon photodiode of collection depth ``depth_m`` (m).

    .. math:: QE(\lambda) = (1 - R(\lambda))\,(1 - e^{-\alpha(\lambda) d})

    with the absorption coefficient alpha and refractive index n of [Green2008]_ (shipped in
    ``data/silicon_green2008.csv``, linearly interpolated, 380-780 nm), and R the normal-incidence Fresnel
    reflectance of bare silicon R = ((n-1)^2 + k^2)/((n+1)^2 + k^2), k = alpha lambda / (4 pi) [Hecht2017]_, or a
    fixed ``reflectance`` (e.g. 0.05 for an anti-reflection-coated sensor). Assumes every electron generated
    within ``depth_m`` is collected and none deeper (a first-order model; no microlens, colour filter or
    crosstalk).

    Returns:
        (C,) QE in e- per photon, dimensionless.
    """
    wl = wavelengths_array(wavelengths_nm)
    if not depth_m > 0:
        raise ValueError(f"depth_m must be > 0 (m), got {depth_m!r}")
    swl, _, vals = read_spectral_csv(DATA_DIR / "silicon_green2008.csv")
    if wl.min() < swl[0] or wl.max() > swl[-1]:
        raise ValueError(f"wavelengths_nm must lie in [{swl[0]:g}, {swl[-1]:g}] nm for the silicon model")
    alpha_per_m = np.interp(wl, swl, vals[:, 0]) * 100.0
    if reflectance is None:
        n = np.interp(wl, swl, vals[:, 1])
        k = alpha_per_m * wl * M_PER_NM / (4 * math.pi)
        R = ((n - 1) ** 2 + k ** 2) / ((n + 1) ** 2 + k ** 2)
    else:
        if not 0 <= reflectance < 1:
            raise ValueError(f"reflectance must be in [0, 1), got {reflectance!r}")
        R = np.full_like(wl, float(reflectance))
    return (1.0 - R) * (1.0 - np.exp(-alpha_per_m * depth_m))
