r"""Spectral response: spectral radiant exposure -> mean photo-electrons of the r, g, b pixels, and the CFA.

- :func:`spectral_qe`, :func:`electron_weights`, :func:`ideal_electrons`: mean photo-electrons,
  n = sum_lambda H(lambda) dlambda A FF QE_c(lambda) lambda / (h c)  [Janesick2007]_ (photon energy h c / lambda).
- :func:`mosaic`: sampling through the Bayer colour filter array.

References
----------
.. [Janesick2007] J. R. Janesick, "Photon Transfer: DN -> lambda", SPIE Press (2007), ch. 2-5.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import torch

from lfmbench.constants import M_PER_NM, PLANCK_TIMES_C_J_M
from lfmbench.sensor.optics import check_radiometric
from lfmbench.sensor.preset import CFAPattern, SensorPreset, load_preset
from lfmbench.sensor.spectral_data import band_widths_nm, read_spectral_csv, wavelengths_array

__all__ = ["spectral_qe", "electron_weights", "mosaic", "ideal_electrons"]


def spectral_qe(preset: SensorPreset | str, wavelengths_nm: Sequence[float] | torch.Tensor,
                photodiode: str | None = None) -> np.ndarray:
    """Absolute spectral QE of the r, g, b pixels (e- per incident photon, colour filter included).

    QE_c(lambda) = peak_qe x S_c(lambda), S_c the preset's relative sensitivity curves (``photodiode``'s own when
    it has them, :meth:`SensorPreset.spectral_of`) linearly interpolated to ``wavelengths_nm`` (0 outside the
    measured range).

    Returns:
        (3, C) float64 array, dimensionless.
    """
    preset = load_preset(preset)
    wl = wavelengths_array(wavelengths_nm)
    sp = preset.spectral_of(photodiode) if photodiode is not None else None
    path, peak = (sp.filters_path, sp.peak_qe) if sp is not None else (preset.filters_path, preset.peak_qe)
    fwl, _, vals = read_spectral_csv(path)
    rel = np.stack([np.interp(wl, fwl, vals[:, k], left=0.0, right=0.0) for k in range(3)])
    return peak * np.clip(rel, 0.0, None)


def electron_weights(preset: SensorPreset | str, wavelengths_nm: Sequence[float] | torch.Tensor,
                     photodiode: str = "lpd", bandwidths_nm: Sequence[float] | None = None,
                     dtype: torch.dtype = torch.float64, device: torch.device | str | None = None) -> torch.Tensor:
    r"""Mean photo-electrons per unit spectral radiant exposure, per colour channel and band.

    .. math:: w_{c,\lambda} = QE_c(\lambda)\, A\, FF\, \Delta\lambda\, \frac{\lambda}{h c}

    (photon count = energy / (h c / lambda) [Janesick2007]_; A pixel area in m^2, FF fill factor, Delta lambda in
    nm, lambda in m).

    Returns:
        (3, C) tensor in e- per (J m^-2 nm^-1).
    """
    preset = load_preset(preset)
    if photodiode not in preset.photodiodes:
        raise ValueError(f"photodiode must be one of {list(preset.photodiodes)}, got {photodiode!r:.40}")
    wl = wavelengths_array(wavelengths_nm)
    if bandwidths_nm is None:
        dl = band_widths_nm(wl)
    else:
        dl = np.asarray(bandwidths_nm, dtype=np.float64).reshape(-1)
        if dl.size == 1 and wl.size > 1:
            dl = np.full(wl.size, float(dl[0]))
        if dl.size != wl.size or not np.all(np.isfinite(dl)) or np.any(dl <= 0):
            raise ValueError(f"bandwidths_nm must hold {wl.size} finite values > 0 (nm)")
    qe = spectral_qe(preset, wl, photodiode)
    ff = preset.photodiodes[photodiode].fill_factor
    w = qe * (preset.pixel_area_m2 * ff) * dl[None, :] * (wl[None, :] * M_PER_NM) / PLANCK_TIMES_C_J_M
    return torch.as_tensor(w, dtype=dtype, device=device)


def mosaic(channels: torch.Tensor, pattern: CFAPattern | str = CFAPattern.GRBG) -> torch.Tensor:
    """Sample a (*, 3, H, W) r, g, b image through a Bayer CFA.

    Returns:
        (*, 1, H, W) mosaic, same dtype and device.
    """
    if channels.dim() < 3 or channels.shape[-3] != 3:
        raise ValueError(f"channels must have shape (*, 3, H, W), got {tuple(channels.shape)}")
    pattern = CFAPattern(str(pattern.value if isinstance(pattern, CFAPattern) else pattern).upper())
    H, W = channels.shape[-2:]
    idx = pattern.index_map(H, W, channels.device)
    return torch.gather(channels, -3, idx.expand(*channels.shape[:-3], 1, H, W))


def ideal_electrons(radiant_exposure: torch.Tensor, preset: SensorPreset | str,
                    wavelengths_nm: Sequence[float] | torch.Tensor, photodiode: str = "lpd",
                    bandwidths_nm: Sequence[float] | None = None, mosaic_output: bool = True,
                    check: bool = True) -> torch.Tensor:
    """Noise-free, unclipped mean photo-electrons (no dark current, no PRNU): the ground-truth signal.

    Args:
        radiant_exposure: (*, C, H, W) spectral radiant exposure at the pixel in J m^-2 nm^-1 (spectral irradiance
            in W m^-2 nm^-1 integrated over the exposure in s).
        preset: sensor preset or its name.
        wavelengths_nm: C band centres in nm.
        photodiode: a photodiode of the preset (split pixel: ``"lpd"`` or ``"spd"``).
        bandwidths_nm: band widths in nm (default: local spacing, see :func:`band_widths_nm`).
        mosaic_output: ``True``: (*, 1, H, W) through the CFA; ``False``: (*, 3, H, W) r, g, b electrons.
        check: validate the input (finite, >= 0).

    Returns:
        electrons in e-, dtype and device of ``radiant_exposure``.
    """
    if check:
        check_radiometric(radiant_exposure, "radiant_exposure")
    preset = load_preset(preset)
    C = radiant_exposure.shape[-3]
    w = electron_weights(preset, wavelengths_nm, photodiode, bandwidths_nm, radiant_exposure.dtype,
                         radiant_exposure.device)
    if w.shape[1] != C:
        raise ValueError(f"wavelengths_nm has {w.shape[1]} values but radiant_exposure has C={C} bands")
    rgb = torch.einsum("...chw,kc->...khw", radiant_exposure, w)
    return mosaic(rgb, preset.cfa) if mosaic_output else rgb

