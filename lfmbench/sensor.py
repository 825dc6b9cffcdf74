"""Split-pixel HDR image sensor: spectral radiant exposure -> photo-electrons -> noise -> volts -> DN.

Functional core in torch (batched over any leading dimensions, CPU or CUDA, float32/float64 following the
input, no per-pixel Python loops) with a thin :class:`SplitPixelSensor` module. Defines:

- :class:`SensorPreset` (+ :class:`PhotodiodeSpec`, :class:`CaptureSpec`), loaded from YAML by
  :func:`load_preset` (``"ovt"``, ``"imx490"`` or a file path); invalid fields raise ``ValueError`` naming the
  field and file.
- :class:`CFAPattern`: Bayer layouts by their top-left 2x2 cell (``GRBG`` default), with the kornia mapping.
- :func:`spectral_qe`, :func:`electron_weights`, :func:`ideal_electrons`: mean photo-electrons,
  n = sum_lambda H(lambda) dlambda A FF QE_c(lambda) lambda / (h c)  [Janesick2007]_ (photon energy h c / lambda).
- :func:`shot_noise`, :func:`fixed_pattern`, :func:`read_capture`, :func:`simulate_split_pixel`: the
  three-capture split pixel of ISET-LFM (LPD read at high and low conversion gain from the same electrons during
  the short exposure, SPD at 1/100 sensitivity during the long exposure), with the EMVA 1288 linear noise model
  [EMVA1288]_: Poisson shot noise of signal and dark current, DSNU/PRNU, Gaussian read noise, full-well and
  voltage-swing clipping, uniform quantisation.
- :func:`silicon_qe`: a documented internal-QE model of a silicon photodiode from Green's optical constants.

Signal chain of one capture (per pixel, e- unless stated):

1. mu = PRNU_gain * ideal electrons (photodiode's fill factor) + dark_current * T.
2. n = Poisson(mu) (rounded Gaussian N(mu, mu) when mu >= ``shot_noise_gaussian_above_e``), clipped to
   [0, full_well]. HCG and LCG read the same n.
3. v = (n + DSNU offset + read noise N(0, sigma_r^2)) * conversion gain, in V, clipped at the voltage swing.
4. DN = round(black_level + v * dn_per_volt), clipped to [0, 2^bits - 1]; dn_per_volt maps the voltage swing to
   the top code, dn_per_volt = (2^bits - 1 - black_level) / swing. System gain K = conversion_gain * dn_per_volt
   in DN/e-.
5. saturated = v >= saturation_fraction * swing (upstream ISET-LFM rule, fraction 0.95).
6. Input-referred: (DN - black_level) / K - dark_current * T in e- (the mean dark signal is removed, as optical-black
   clamping does, so its expectation is :func:`ideal_electrons` below saturation); SPD additionally
   x sensitivity_ratio x T_short / T_long, i.e. LPD-equivalent electrons over the short exposure
   (docs/contracts.md, section 3).

References
----------
.. [EMVA1288] EMVA Standard 1288, "Standard for Characterization of Image Sensors and Cameras", Release 4.0
   Linear (2021): the linear camera model (sec. 2) and the photon-transfer method of the sensitivity, linearity
   and noise measurement.
.. [Janesick2007] J. R. Janesick, "Photon Transfer: DN -> lambda", SPIE Press (2007), ch. 2-5.
.. [Solhusvik2019] J. Solhusvik et al., "A 1280x960 2.8 um HDR CIS with DCG and Split-Pixel Combined",
   International Image Sensor Workshop (2019) - the 'ovt' preset, via ISETCam ``sensorCreate('ovt-large')``.
.. [Green2008] M. A. Green, "Self-consistent optical parameters of intrinsic silicon at 300 K including
   temperature coefficients", Sol. Energy Mater. Sol. Cells 92, 1305 (2008).
.. [Hecht2017] E. Hecht, "Optics", 5th ed. (2017), sec. 4.6: normal-incidence reflectance
   R = ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2).
"""
from __future__ import annotations

import functools
import math
import os
import threading
from dataclasses import dataclass, field, fields
from enum import Enum
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np
import torch
from torch import nn

from lfmbench import poisson as _poisson
from lfmbench.check import check_keys, get_number
from lfmbench.constants import M_PER_NM, PLANCK_TIMES_C_J_M
from lfmbench.optics import OpticsConfig, check_radiometric

__all__ = [
    "CAPTURES",
    "PHOTODIODES",
    "DATA_DIR",
    "PRESET_DIR",
    "CFAPattern",
    "PhotodiodeSpec",
    "CaptureSpec",
    "SensorPreset",
    "available_presets",
    "load_preset",
    "preset_from_dict",
    "read_spectral_csv",
    "band_widths_nm",
    "spectral_qe",
    "electron_weights",
    "mosaic",
    "ideal_electrons",
    "fixed_pattern",
    "shot_noise",
    "read_capture",
    "simulate_split_pixel",
    "simulate_split_pixel_electrons",
    "SplitPixelSensor",
    "silicon_qe",
]

#: Capture names in the order of the ``saturated`` channels (docs/contracts.md).
CAPTURES: tuple[str, ...] = ("lpd_hcg", "lpd_lcg", "spd")
#: Photodiode names.
PHOTODIODES: tuple[str, ...] = ("lpd", "spd")
#: Shipped spectral data (CSV with a source header).
DATA_DIR: Path = Path(__file__).resolve().parent / "data"
#: Shipped sensor presets (YAML).
PRESET_DIR: Path = Path(__file__).resolve().parent / "configs" / "sensors"
#: Mean electrons are capped at this multiple of the full well before noise: everything above the full well
#: clips anyway, and the cap keeps sun-in-view inputs finite in float32.
_MEAN_CAP_FULL_WELLS: float = 100.0


# ----------------------------------------------------------------------------------------------------------
# colour filter array
# ----------------------------------------------------------------------------------------------------------
class CFAPattern(str, Enum):
    """Bayer layout named by its top-left 2x2 cell read row by row (``GRBG``: G R / B G)."""

    RGGB = "RGGB"
    GRBG = "GRBG"
    GBRG = "GBRG"
    BGGR = "BGGR"

    def cell(self, device: torch.device | str | None = None) -> torch.Tensor:
        """(2, 2) int64 channel indices (0 = r, 1 = g, 2 = b) of the top-left cell, on ``device``."""
        lut = {"R": 0, "G": 1, "B": 2}
        return torch.tensor([[lut[self.value[0]], lut[self.value[1]]], [lut[self.value[2]], lut[self.value[3]]]],
                            device=device)

    def index_map(self, height: int, width: int, device: torch.device | str | None = None) -> torch.Tensor:
        """(H, W) int64 channel index (0 = r, 1 = g, 2 = b) of every pixel."""
        cell = self.cell(device)
        return cell.repeat((height + 1) // 2, (width + 1) // 2)[:height, :width]

    def to_kornia(self):
        """The equivalent ``kornia.color.CFA`` member (kornia uses OpenCV names read from pixel (1, 1))."""
        from kornia.color import CFA  # lazy: kornia is only needed for demosaicing

        return {"RGGB": CFA.BG, "GRBG": CFA.GB, "BGGR": CFA.RG, "GBRG": CFA.GR}[self.value]


# ----------------------------------------------------------------------------------------------------------
# presets
# ----------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PhotodiodeSpec:
    """One photodiode of the split pixel.

    Attributes:
        fill_factor: effective light-collecting fraction of the pixel area (dimensionless, (0, 1]).
        full_well_e: full-well capacity in e-.
        dark_current_e_per_s: mean dark current in e-/s.
        dsnu_e: dark-signal non-uniformity, standard deviation of a per-pixel offset in e-.
        prnu: photo-response non-uniformity, standard deviation of the per-pixel gain (fraction, 0.01 = 1 %).
    """

    fill_factor: float
    full_well_e: float
    dark_current_e_per_s: float = 0.0
    dsnu_e: float = 0.0
    prnu: float = 0.0


@dataclass(frozen=True)
class CaptureSpec:
    """One read-out of a photodiode.

    Attributes:
        photodiode: ``"lpd"`` or ``"spd"``.
        conversion_gain_v_per_e: conversion gain in V/e-.
        voltage_swing_v: voltage swing (ADC input range) in V.
        read_noise_e: read noise standard deviation in e- (Gaussian).
    """

    photodiode: str
    conversion_gain_v_per_e: float
    voltage_swing_v: float
    read_noise_e: float


@dataclass(frozen=True)
class SensorPreset:
    """A split-pixel camera: pixel, CFA, photodiodes, captures, ADC and lens. Load with :func:`load_preset`.

    Attributes:
        name: preset name.
        description: one line.
        pixel_pitch_m: pixel pitch in m.
        cfa: Bayer layout.
        adc_bits: ADC resolution in bits.
        black_level_dn: black level (pedestal) in DN.
        saturation_fraction: a capture is flagged saturated at volts >= this fraction of its swing.
        filters_path: CSV of relative spectral sensitivities (columns wavelength_nm, r, g, b).
        peak_qe: scale of the relative curves to absolute QE (e- per photon).
        shot_noise_gaussian_above_e: mean (e-) from which shot noise is drawn as a rounded Gaussian.
        fpn_seed: seed of the fixed DSNU/PRNU pattern.
        photodiodes: ``{"lpd": PhotodiodeSpec, "spd": PhotodiodeSpec}``.
        captures: ``{"lpd_hcg": CaptureSpec, "lpd_lcg": ..., "spd": ...}``.
        optics: lens of the camera.
        source: file the preset was read from.
    """

    name: str
    description: str
    pixel_pitch_m: float
    cfa: CFAPattern
    adc_bits: int
    black_level_dn: float
    saturation_fraction: float
    filters_path: Path
    peak_qe: float
    shot_noise_gaussian_above_e: float
    fpn_seed: int
    photodiodes: Mapping[str, PhotodiodeSpec]
    captures: Mapping[str, CaptureSpec]
    optics: OpticsConfig = field(default_factory=OpticsConfig)
    source: str = "<dict>"

    def __hash__(self) -> int:
        # equal presets have equal scalar fields; the mappings are left out (unhashable)
        return hash((self.name, self.source, self.pixel_pitch_m, self.adc_bits, self.black_level_dn, self.fpn_seed,
                     self.peak_qe, str(self.filters_path)))

    def __reduce__(self):
        # the read-only mapping proxies do not pickle: rebuild from plain dicts (DataLoader workers, spawn)
        state = {f.name: getattr(self, f.name) for f in fields(self)}
        state["photodiodes"], state["captures"] = dict(self.photodiodes), dict(self.captures)
        return (_rebuild_preset, (state,))

    @property
    def max_dn(self) -> int:
        """Largest ADC code, 2^bits - 1 (DN)."""
        return 2 ** self.adc_bits - 1

    @property
    def pixel_area_m2(self) -> float:
        """Pixel area in m^2."""
        return self.pixel_pitch_m ** 2

    @property
    def sensitivity_ratio(self) -> float:
        """LPD / SPD sensitivity (dimensionless): ratio of the fill factors (both share the spectral curves)."""
        return self.photodiodes["lpd"].fill_factor / self.photodiodes["spd"].fill_factor

    def dn_per_volt(self, capture: str) -> float:
        """ADC gain of ``capture`` in DN/V: (2^bits - 1 - black_level) / voltage_swing."""
        return (self.max_dn - self.black_level_dn) / self.captures[capture].voltage_swing_v

    def system_gain(self, capture: str) -> float:
        """Overall system gain K of ``capture`` in DN/e- [EMVA1288]_ (conversion gain x ADC gain)."""
        return self.captures[capture].conversion_gain_v_per_e * self.dn_per_volt(capture)

    def saturation_capacity_e(self, capture: str) -> float:
        """Electrons at which ``capture`` clips: min(full well, voltage swing / conversion gain), in e-."""
        spec = self.captures[capture]
        return min(self.photodiodes[spec.photodiode].full_well_e, spec.voltage_swing_v / spec.conversion_gain_v_per_e)


def _rebuild_preset(state: dict[str, Any]) -> SensorPreset:
    state = dict(state)
    state["photodiodes"] = MappingProxyType(dict(state["photodiodes"]))
    state["captures"] = MappingProxyType(dict(state["captures"]))
    return SensorPreset(**state)


def available_presets() -> list[str]:
    """Names of the shipped presets (files ``lfmbench/configs/sensors/<name>.yaml``)."""
    return sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))


def load_preset(preset: "str | Path | SensorPreset | Mapping[str, Any]") -> SensorPreset:
    """Load a preset by name (``"ovt"``, ``"imx490"``), from a YAML file path, or from a mapping.

    Raises:
        ValueError: unknown name, missing/unreadable file, or an invalid field (the message names the field and
            the file).
    """
    if isinstance(preset, SensorPreset):
        return preset
    if isinstance(preset, Mapping):
        return preset_from_dict(preset, "<dict>")
    if not isinstance(preset, (str, Path)):
        raise ValueError(f"preset must be a name, a path or a mapping, got {type(preset).__name__}")
    text = str(preset)
    path = Path(text)
    if path.suffix.lower() not in (".yaml", ".yml", ".json") and not path.exists():
        candidate = PRESET_DIR / f"{text}.yaml"
        if not candidate.exists():
            raise ValueError(f"preset: unknown sensor preset {text!r}; shipped presets are {available_presets()} "
                             "or give a path to a YAML file")
        path = candidate
    resolved = path.resolve()
    if not resolved.is_file():
        raise ValueError(f"preset: file {resolved} does not exist")
    return _load_preset_file(str(resolved), resolved.stat().st_mtime_ns)


@functools.lru_cache(maxsize=32)
def _load_preset_file(path: str, mtime_ns: int = 0) -> SensorPreset:
    """Parse one preset file (cached per path and modification time, so edits are picked up)."""
    import yaml

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"preset: file {path} does not exist")
    try:
        data = yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"preset: cannot read {path}: {exc}") from exc
    return preset_from_dict(data, path)


def _entries(data: Mapping[str, Any], section: str, names: Sequence[str], spec: type, source: str):
    """Yield ``(name, fields, prefix)`` for each required entry ``name`` of ``data[section]``, after checking
    that the section and every entry exist and hold only known keys (the fields of dataclass ``spec``)."""
    raw = data.get(section)
    if raw is None:
        raise ValueError(f"{source}: missing field '{section}'")
    check_keys(raw, section, source, optional=set(names))
    for name in names:
        if name not in raw:
            raise ValueError(f"{source}: missing field '{section}.{name}'")
        check_keys(raw[name], f"{section}.{name}", source, optional={f.name for f in fields(spec)})
        yield name, raw[name], f"{section}.{name}."


def preset_from_dict(data: Mapping[str, Any], source: str = "<dict>") -> SensorPreset:
    """Validate a plain mapping (the YAML structure of ``configs/sensors/ovt.yaml``) into a :class:`SensorPreset`.

    Raises:
        ValueError: naming the offending field and ``source``.
    """
    top = {"name", "description", "pixel_pitch_m", "cfa", "adc_bits", "black_level_dn", "saturation_fraction",
           "spectral", "shot_noise_gaussian_above_e", "fpn_seed", "photodiodes", "captures", "optics"}
    check_keys(data, "", source, optional=top)
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise ValueError(f"{source}: field 'name' must be a non-empty string, got {name!r}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ValueError(f"{source}: field 'description' must be a string")
    pitch = get_number(data, "pixel_pitch_m", source, lo=0, lo_open=True, hi=1e-3)
    try:
        cfa = CFAPattern(str(data.get("cfa", "GRBG")).upper())
    except ValueError:
        raise ValueError(f"{source}: field 'cfa' must be one of {[c.value for c in CFAPattern]}, "
                         f"got {data.get('cfa')!r}") from None
    bits = get_number(data, "adc_bits", source, lo=1, hi=24, integer=True)
    black = get_number(data, "black_level_dn", source, lo=0, hi=2 ** bits - 2, default=0.0)
    sat_frac = get_number(data, "saturation_fraction", source, lo=0, lo_open=True, hi=1.0, default=0.95)
    gauss = get_number(data, "shot_noise_gaussian_above_e", source, lo=0, default=1000.0, allow_inf=True)
    seed = get_number(data, "fpn_seed", source, lo=0, integer=True, default=0)

    spectral = data.get("spectral")
    if spectral is None:
        raise ValueError(f"{source}: missing field 'spectral'")
    check_keys(spectral, "spectral", source, optional={"filters", "peak_qe"})
    peak_qe = get_number(spectral, "peak_qe", source, "spectral.", lo=0, lo_open=True, hi=1.0)
    filters = spectral.get("filters")
    if not isinstance(filters, str) or not filters:
        raise ValueError(f"{source}: field 'spectral.filters' must be a file name, got {filters!r}")
    fpath = Path(filters)
    if not fpath.is_absolute():
        here = Path(source).parent if source != "<dict>" else None
        cands = ([here / fpath] if here is not None else []) + [DATA_DIR / fpath]
        fpath = next((c for c in cands if c.is_file()), cands[-1])
    if not fpath.is_file():
        raise ValueError(f"{source}: field 'spectral.filters': file {filters!r} not found (looked next to the "
                         f"preset and in {DATA_DIR})")
    try:
        _, names, _ = read_spectral_csv(fpath)
    except ValueError as exc:
        raise ValueError(f"{source}: field 'spectral.filters': {exc}") from exc
    if [n.lower() for n in names] != ["r", "g", "b"]:
        raise ValueError(f"{source}: field 'spectral.filters': {fpath} must have columns wavelength_nm,r,g,b, "
                         f"got {names}")

    pds: dict[str, PhotodiodeSpec] = {}
    for pd, d, pre in _entries(data, "photodiodes", PHOTODIODES, PhotodiodeSpec, source):
        pds[pd] = PhotodiodeSpec(
            fill_factor=get_number(d, "fill_factor", source, pre, lo=0, lo_open=True, hi=1.0),
            full_well_e=get_number(d, "full_well_e", source, pre, lo=0, lo_open=True),
            dark_current_e_per_s=get_number(d, "dark_current_e_per_s", source, pre, lo=0, default=0.0),
            dsnu_e=get_number(d, "dsnu_e", source, pre, lo=0, default=0.0),
            prnu=get_number(d, "prnu", source, pre, lo=0, hi=0.5, default=0.0),
        )

    caps: dict[str, CaptureSpec] = {}
    for cap, d, pre in _entries(data, "captures", CAPTURES, CaptureSpec, source):
        pd = d.get("photodiode")
        if pd not in PHOTODIODES:
            raise ValueError(f"{source}: field '{pre}photodiode' must be one of {list(PHOTODIODES)}, got {pd!r}")
        caps[cap] = CaptureSpec(
            photodiode=pd,
            conversion_gain_v_per_e=get_number(d, "conversion_gain_v_per_e", source, pre, lo=0, lo_open=True, hi=1e-2),
            voltage_swing_v=get_number(d, "voltage_swing_v", source, pre, lo=0, lo_open=True, hi=100.0),
            read_noise_e=get_number(d, "read_noise_e", source, pre, lo=0),
        )
    if caps["lpd_hcg"].photodiode != "lpd" or caps["lpd_lcg"].photodiode != "lpd" or caps["spd"].photodiode != "spd":
        raise ValueError(f"{source}: field 'captures': lpd_hcg and lpd_lcg must read photodiode 'lpd' and spd "
                         "must read photodiode 'spd'")
    optics = OpticsConfig.from_mapping(data["optics"], source) if "optics" in data else OpticsConfig()
    return SensorPreset(name=name, description=description, pixel_pitch_m=pitch, cfa=cfa, adc_bits=bits,
                        black_level_dn=black, saturation_fraction=sat_frac, filters_path=fpath, peak_qe=peak_qe,
                        shot_noise_gaussian_above_e=gauss, fpn_seed=seed, photodiodes=MappingProxyType(pds),
                        captures=MappingProxyType(caps),
                        optics=optics, source=source)


# ----------------------------------------------------------------------------------------------------------
# spectral response
# ----------------------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=16)
def _read_csv_cached(path: str) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    p = Path(path)
    try:
        lines = [ln.strip() for ln in p.read_text().splitlines()]
    except OSError as exc:
        raise ValueError(f"cannot read spectral file {path}: {exc}") from exc
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


def _wavelengths(wavelengths_nm: Sequence[float] | torch.Tensor) -> np.ndarray:
    wl = np.asarray(torch.as_tensor(wavelengths_nm, dtype=torch.float64, device="cpu"), dtype=np.float64).reshape(-1)
    if wl.size == 0 or not np.all(np.isfinite(wl)) or np.any(wl <= 0):
        raise ValueError("wavelengths_nm must be a non-empty sequence of finite values > 0 (nm)")
    return wl


def spectral_qe(preset: SensorPreset | str, wavelengths_nm: Sequence[float] | torch.Tensor) -> np.ndarray:
    """Absolute spectral QE of the r, g, b pixels (e- per incident photon, colour filter included).

    QE_c(lambda) = peak_qe x S_c(lambda), S_c the preset's relative sensitivity curves linearly interpolated to
    ``wavelengths_nm`` (0 outside the measured range).

    Returns:
        (3, C) float64 array, dimensionless.
    """
    preset = load_preset(preset)
    wl = _wavelengths(wavelengths_nm)
    fwl, _, vals = read_spectral_csv(preset.filters_path)
    rel = np.stack([np.interp(wl, fwl, vals[:, k], left=0.0, right=0.0) for k in range(3)])
    return preset.peak_qe * np.clip(rel, 0.0, None)


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
    if photodiode not in PHOTODIODES:
        raise ValueError(f"photodiode must be one of {list(PHOTODIODES)}, got {photodiode!r}")
    wl = _wavelengths(wavelengths_nm)
    if bandwidths_nm is None:
        dl = band_widths_nm(wl)
    else:
        dl = np.asarray(bandwidths_nm, dtype=np.float64).reshape(-1)
        if dl.size == 1 and wl.size > 1:
            dl = np.full(wl.size, float(dl[0]))
        if dl.size != wl.size or not np.all(np.isfinite(dl)) or np.any(dl <= 0):
            raise ValueError(f"bandwidths_nm must hold {wl.size} finite values > 0 (nm)")
    qe = spectral_qe(preset, wl)
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
        photodiode: ``"lpd"`` or ``"spd"``.
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


# ----------------------------------------------------------------------------------------------------------
# noise
# ----------------------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=8)
def _fixed_pattern_cpu(seed: int, height: int, width: int) -> tuple[torch.Tensor, ...]:
    g = torch.Generator(device="cpu").manual_seed(int(seed))
    # fixed draw order: lpd gain, lpd offset, spd gain, spd offset (standard normal, float64)
    return tuple(torch.randn(height, width, generator=g, dtype=torch.float64) for _ in range(4))


def fixed_pattern(preset: SensorPreset | str, height: int, width: int, device: torch.device | str | None = None,
                  dtype: torch.dtype = torch.float32) -> dict[str, torch.Tensor]:
    """Per-sensor fixed-pattern noise maps, identical on every call, device and dtype for the same preset and size.

    Drawn from ``torch.Generator().manual_seed(preset.fpn_seed)`` on the CPU in float64 (so CPU and CUDA agree).
    For crops of one sensor, build the full-frame pattern once and crop it.

    Returns:
        ``{"lpd_gain", "spd_gain"}``: PRNU gain maps 1 + prnu z (clipped >= 0), dimensionless;
        ``{"lpd_offset_e", "spd_offset_e"}``: DSNU offset maps dsnu_e z in e-; each (H, W).
    """
    preset = load_preset(preset)
    z = _fixed_pattern_cpu(preset.fpn_seed, int(height), int(width))
    out = {}
    for i, pd in enumerate(PHOTODIODES):
        spec = preset.photodiodes[pd]
        out[f"{pd}_gain"] = (1.0 + spec.prnu * z[2 * i]).clamp_min(0.0).to(device=device, dtype=dtype)
        out[f"{pd}_offset_e"] = (spec.dsnu_e * z[2 * i + 1]).to(device=device, dtype=dtype)
    return out


def shot_noise(mean_e: torch.Tensor, generator: torch.Generator, gaussian_above_e: float = 1000.0,
               backend: str = "auto") -> torch.Tensor:
    """Photon (and dark-current) shot noise: a Poisson sample of the mean electron count.

    Means >= ``gaussian_above_e`` use the normal approximation N(mu, mu) rounded to integers (Poisson's skewness
    1/sqrt(mu) is < 3 % there; the distribution error is measured in ``benchmarks/bench_sensor.py``); smaller
    means are exact Poisson. ``gaussian_above_e = inf`` forces exact Poisson everywhere below 2^52 e-
    (:data:`lfmbench.poisson.EXACT_LIMIT`, where float64 stops holding counts exactly).

    Backends: ``"numba"`` (CPU only) is the compiled counter-based sampler of :mod:`lfmbench.poisson`
    (inversion below 10 e-, PTRS above; 1.6-2.3x faster than ``torch.poisson`` on a sample's means);
    ``"torch"`` uses ``torch.poisson`` and ``torch.randn`` (any device); ``"auto"`` picks ``"numba"`` for CPU
    tensors when numba is importable, else ``"torch"``. Both draw the same distribution, not the same numbers.

    Args:
        mean_e: (*) mean electrons, >= 0, e-.
        generator: random generator on the device of ``mean_e``.
        gaussian_above_e: switch-over mean in e-.
        backend: ``"auto"``, ``"numba"`` or ``"torch"``.

    Returns:
        (*) integer-valued electron counts, e-, dtype of ``mean_e``.
    """
    if backend not in ("auto", "numba", "torch"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'torch', got {backend!r}")
    if backend == "numba" or (backend == "auto" and mean_e.device.type == "cpu" and _poisson.available()):
        return _poisson.poisson(mean_e, generator, gaussian_above_e)
    # torch.poisson overflows int64 for huge means (1e20 -> -2^63): those take the rounded normal too
    small = mean_e < min(gaussian_above_e, _poisson.EXACT_LIMIT)
    n_small = int(small.sum())
    if n_small == mean_e.numel():
        return torch.poisson(mean_e, generator=generator)
    z = torch.randn(mean_e.shape, generator=generator, device=mean_e.device, dtype=mean_e.dtype)
    out = torch.round(mean_e + torch.sqrt(mean_e) * z).clamp_min(0.0)
    if n_small:
        # Poisson where the mean is small; a masked gather/scatter costs more than drawing Poisson(0) elsewhere
        # (14.5 -> 10.5 ms for a 3-frame 256x256 split-pixel sample, docs/dataset-benchmark.md)
        pois = torch.poisson(torch.where(small, mean_e, torch.zeros_like(mean_e)), generator=generator)
        out = torch.where(small, pois, out)
    return out


_DRAW_POOL: dict[tuple, Any] = {}


def _map_samples(fn, count: int, threads: int | None = None) -> None:
    """``fn(b)`` for b in range(count), by ``min(threads, count)`` Python threads (default
    ``torch.get_num_threads()``; the compiled kernels and torch's samplers release the GIL); in order in this
    thread when that is 1."""
    n = min(torch.get_num_threads() if threads is None else int(threads), count)
    if n < 2:
        for b in range(count):
            fn(b)
        return
    key = (os.getpid(), n)   # a forked child (DataLoader worker) builds its own pool: threads do not survive fork
    if key not in _DRAW_POOL:
        from concurrent.futures import ThreadPoolExecutor
        _DRAW_POOL[key] = ThreadPoolExecutor(n, thread_name_prefix="lfmbench-draw")
    list(_DRAW_POOL[key].map(fn, range(count)))


def _per_generator(draw, x: torch.Tensor, generator, threads: int | None = None) -> torch.Tensor:
    """``draw(x, generator)``, or with a sequence of generators ``draw(x[b], generator[b])`` stacked over b.

    On the CPU the samples are drawn by ``threads`` Python threads (:func:`_map_samples`); each
    sample still reads only its own generator, so the result does not depend on the thread count.
    """
    if not isinstance(generator, (list, tuple)):
        return draw(x, generator)
    out = torch.empty_like(x)

    def one(b: int) -> None:
        out[b] = draw(x[b], generator[b])

    if x.device.type != "cpu":
        for b in range(len(generator)):
            one(b)
    else:
        _map_samples(one, len(generator), threads)
    return out


_SCRATCH = threading.local()
#: Work arrays up to this many bytes are kept per thread between calls (fresh pages cost a fault each).
_SCRATCH_MAX_BYTES = 16 * 2 ** 20


def _scratch(name: str, rows: int, cols: int, dtype) -> np.ndarray:
    """A (rows, cols) work array of this thread, reused from call to call when small enough (contents undefined)."""
    n = rows * cols
    dt = np.dtype(dtype)
    if n * dt.itemsize > _SCRATCH_MAX_BYTES:
        return np.empty((rows, cols), dt)
    bufs = _SCRATCH.__dict__.setdefault("bufs", {})
    b = bufs.get((name, dt))
    if b is None or b.size < n:
        b = bufs[(name, dt)] = np.empty(n, dt)
    return b[:n].reshape(rows, cols)


def _map_rows(m: torch.Tensor, lead: torch.Size, H: int, W: int) -> tuple[np.ndarray, np.ndarray]:
    """A map (..., H, W) broadcastable to inputs ``lead + (1, H, W)`` as ``(base, row)``: ``base`` (M, H*W) its
    distinct planes (C-contiguous numpy), ``row`` (L,) int64 the plane each of the L = prod(lead) input planes
    reads (no copy of the map per input plane)."""
    base = m.reshape(-1, H * W).contiguous()
    idx = torch.arange(base.shape[0], device=m.device).reshape(m.shape[:-2])
    row = torch.broadcast_to(idx, (*lead, 1)).reshape(-1).contiguous()
    return base.numpy(), row.numpy()


def _chain_fused(lpd_e: torch.Tensor, spd_e: torch.Tensor, preset: SensorPreset, t_s: torch.Tensor,
                 t_l: torch.Tensor, generator, noise: bool, fpn: Mapping[str, torch.Tensor] | None,
                 threads: int | None = None) -> dict:
    """The CPU chain of :func:`simulate_split_pixel_electrons` in compiled passes (backend ``"numba"``).

    Args: ``lpd_e``, ``spd_e`` (*, 1, H, W) mean e- (float32/float64, CPU); ``t_s``, ``t_l`` (*, 1, 1, 1)
    exposures in s (dtype of the inputs); ``generator`` one CPU generator or B of them (one per index of the
    leading dimension); ``fpn`` maps (..., H, W) already on the inputs' dtype, or None. Every generator is drawn
    in the torch chain's order (LPD Poisson seed, SPD Poisson seed, HCG, LCG, SPD read noise), and every
    per-row scalar is computed by the torch chain's own expressions, so the outputs are bit-identical to it.
    """
    from lfmbench._poisson_kernel import collect
    from lfmbench._readout_kernel import readout

    lead, (H, W) = lpd_e.shape[:-3], lpd_e.shape[-2:]
    P = H * W
    L = int(np.prod(lead, dtype=np.int64)) if len(lead) else 1
    dtype = lpd_e.dtype
    nt = np.float32 if dtype == torch.float32 else np.float64
    t_pd = {"lpd": t_s, "spd": t_l}
    rows = {pd: (lpd_e if pd == "lpd" else spd_e).detach().reshape(L, P).contiguous().numpy() for pd in PHOTODIODES}
    def per_row(v: torch.Tensor) -> np.ndarray:
        return torch.broadcast_to(v, (*lead, 1, 1, 1)).reshape(L).contiguous().numpy()

    dark = {pd: per_row(preset.photodiodes[pd].dark_current_e_per_s * t_pd[pd]) for pd in PHOTODIODES}
    spd_factor = per_row(preset.sensitivity_ratio * t_s / t_l)
    empty = np.zeros((0, P), dtype=nt)
    no_factor = np.zeros(0, dtype=nt)
    none_row = np.zeros(L, dtype=np.int64)
    maps = {}
    for pd in PHOTODIODES:
        spec = preset.photodiodes[pd]
        use = noise and fpn is not None
        maps[f"{pd}_gain"] = _map_rows(fpn[f"{pd}_gain"], lead, H, W) if use and spec.prnu > 0 else (empty, none_row)
        maps[f"{pd}_offset_e"] = (_map_rows(fpn[f"{pd}_offset_e"], lead, H, W) if use and spec.dsnu_e > 0
                                  else (empty, none_row))
    dev = lpd_e.device
    out = {k: torch.empty(*lead, 1, H, W, dtype=dtype, device=dev) for k in (*CAPTURES, *(f"{c}_e" for c in CAPTURES))}
    sat = torch.empty(*lead, 3, H, W, dtype=torch.bool, device=dev)
    flat = {k: v.view(L, P).numpy() for k, v in out.items()}
    sat_np = sat.view(L, 3, P).numpy()
    gsw = float(preset.shot_noise_gaussian_above_e)

    def run(r0: int, r1: int, g, shape: torch.Size) -> None:
        """Rows r0..r1 (one generator's inputs, of shape ``shape``)."""
        collected = {pd: _scratch(pd, r1 - r0, P, nt) for pd in PHOTODIODES}            # e-
        for pd in PHOTODIODES:
            spec = preset.photodiodes[pd]
            gain, grow = maps[f"{pd}_gain"]
            seed = _poisson.draw_seed(g) if noise else np.uint64(0)
            bad = collect(rows[pd][r0:r1], gain, grow[r0:r1], dark[pd][r0:r1],
                          nt(_MEAN_CAP_FULL_WELLS * spec.full_well_e), nt(spec.full_well_e), seed, gsw, noise,
                          collected[pd])
            if bad >= 0:  # pragma: no cover - the clipped means are finite and >= 0
                raise ValueError(f"shot noise: invalid mean at flat index {bad} of {pd}")
        z_all = _scratch("z", r1 - r0, P, nt)
        for c, cap in enumerate(CAPTURES):
            spec = preset.captures[cap]
            pd = spec.photodiode
            z = empty
            if noise and spec.read_noise_e > 0:
                # into a reused buffer: the same draws as a new tensor
                torch.randn(shape, generator=g, dtype=dtype, device=dev, out=torch.from_numpy(z_all).view(shape))
                z = z_all
            off, orow = maps[f"{pd}_offset_e"]
            readout(collected[pd], z, nt(spec.read_noise_e), off, orow[r0:r1],
                    nt(spec.conversion_gain_v_per_e), nt(spec.voltage_swing_v), nt(preset.dn_per_volt(cap)),
                    nt(preset.black_level_dn), nt(preset.max_dn), nt(preset.saturation_fraction * spec.voltage_swing_v),
                    nt(preset.system_gain(cap)), dark[pd][r0:r1], spd_factor[r0:r1] if pd == "spd" else no_factor,
                    flat[cap][r0:r1], flat[f"{cap}_e"][r0:r1], sat_np[r0:r1], c)

    if isinstance(generator, (list, tuple)):
        per = L // len(generator)
        _map_samples(lambda b: run(b * per, (b + 1) * per, generator[b], lpd_e.shape[1:]), len(generator), threads)
    else:
        run(0, L, generator, lpd_e.shape)
    out["saturated"] = sat
    return out


def _warm_fused(preset: SensorPreset | str, noise: bool) -> None:
    """Compile (or load from numba's cache) the compiled CPU chain's kernels for float32 inputs, in this process
    (what a DataLoader's parent does before forking its workers)."""
    if not _poisson.available():  # pragma: no cover - numba is a dependency
        return
    preset = load_preset(preset)
    z = torch.zeros(1, 1, 2, 2, device="cpu")
    t = torch.full((1, 1, 1), 1e-3, device="cpu")
    _chain_fused(z, z, preset, t, 10 * t, torch.Generator().manual_seed(0) if noise else None, noise, None)


def _exposure(value: float | torch.Tensor, name: str, lead: torch.Size, ref: torch.Tensor) -> torch.Tensor:
    t = torch.as_tensor(value, dtype=ref.dtype, device=ref.device)
    if not bool(torch.isfinite(t).all()) or bool((t <= 0).any()):
        raise ValueError(f"{name} must be finite and > 0 (s), got {value!r}")
    if t.dim() > len(lead):
        raise ValueError(f"{name} must be a scalar or broadcastable to the leading shape {tuple(lead)}")
    try:
        t = t.reshape(*t.shape, 1, 1, 1).expand(*lead, 1, 1, 1) if t.dim() else t.reshape(1, 1, 1)
    except RuntimeError:
        raise ValueError(f"{name} with shape {tuple(t.shape)} does not broadcast to the leading shape "
                         f"{tuple(lead)}") from None
    return t


def read_capture(electrons: torch.Tensor, preset: SensorPreset, capture: str, generator: torch.Generator | None,
                 noise: bool = True, offset_e: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """Read one capture of collected photodiode electrons: offset, read noise, conversion gain, swing, ADC.

    Args:
        electrons: (*, 1, H, W) collected electrons (already clipped to the full well), e-.
        preset: sensor preset.
        capture: one of :data:`CAPTURES`.
        generator: random generator for the read noise (needed when ``noise``), or a sequence of B generators,
            one per index of the leading dimension of ``electrons`` (each draws its own slice).
        noise: add Gaussian read noise.
        offset_e: (H, W) DSNU offset map in e- (or ``None``).

    Returns:
        ``{"dn": (*, 1, H, W) DN, "volts": (*, 1, H, W) V (clipped at the swing), "saturated": bool (*, 1, H, W)}``.
    """
    spec = preset.captures[capture]
    # in-place on tensors made here (never on ``electrons``): a 3-frame 256x256 capture is 0.75 MiB per temporary
    if noise and spec.read_noise_e > 0:
        volts = _per_generator(lambda x, g: torch.randn(x.shape, generator=g, device=x.device, dtype=x.dtype),
                               electrons, generator)
        volts.mul_(spec.read_noise_e).add_(electrons)
    else:
        volts = electrons.clone()
    if offset_e is not None:
        volts.add_(offset_e)
    volts.mul_(spec.conversion_gain_v_per_e).clamp_max_(spec.voltage_swing_v)
    dn = (volts * preset.dn_per_volt(capture)).add_(preset.black_level_dn).round_().clamp_(0.0, float(preset.max_dn))
    saturated = volts >= preset.saturation_fraction * spec.voltage_swing_v
    return {"dn": dn, "volts": volts, "saturated": saturated}


def _check_pair(lpd: torch.Tensor, spd: torch.Tensor, lpd_name: str, spd_name: str, check: bool) -> None:
    """The LPD and SPD inputs of a capture set: radiometric (if ``check``), same shape, same dtype."""
    if check:
        check_radiometric(lpd, lpd_name)
        check_radiometric(spd, spd_name)
    if lpd.shape != spd.shape:
        raise ValueError(f"{spd_name} shape {tuple(spd.shape)} differs from {lpd_name} shape {tuple(lpd.shape)}")
    if spd.dtype != lpd.dtype:
        raise ValueError(f"{spd_name} and {lpd_name} must have the same dtype")


def simulate_split_pixel_electrons(lpd_electrons: torch.Tensor, spd_electrons: torch.Tensor,
                                   preset: SensorPreset | str, exposure_short_s: float | torch.Tensor,
                                   exposure_long_s: float | torch.Tensor, generator: torch.Generator | None = None,
                                   noise: bool = True, fpn: Mapping[str, torch.Tensor] | None = None,
                                   check: bool = True, backend: str = "auto",
                                   threads: int | None = None) -> dict[str, torch.Tensor]:
    """The three captures from mean photo-electrons (the noise and read-out part of :func:`simulate_split_pixel`).

    Use this when the spectral projection (:func:`ideal_electrons` or a cached equivalent) is done elsewhere.

    Args:
        lpd_electrons: (*, 1, H, W) mean photo-electrons of the LPD over the short exposure (CFA mosaic, LPD fill
            factor included, no dark current, no PRNU), e-.
        spd_electrons: (*, 1, H, W) the same for the SPD over the long exposure (SPD fill factor included), e-.
        preset: sensor preset or name.
        exposure_short_s, exposure_long_s: exposure times in s, scalars or shape (*).
        generator: ``torch.Generator`` on the inputs' device; required when ``noise`` is true. Or a sequence of B
            generators for inputs (B, *, 1, H, W): sample b then draws all its noise from its own generator, in the
            same order as a call on that sample alone, so its output does not depend on the other samples or on
            B (the batched dataset path, :mod:`lfmbench.datasets.batched`).
        noise: ``False``: noise-free chain (dark current mean kept, no FPN, clipping and quantisation kept).
        fpn: fixed-pattern maps (H, W) from :func:`fixed_pattern` (default: built for (H, W) from the preset),
            or maps broadcastable to the inputs whose last two dimensions are (H, W) (e.g. (B, 1, 1, H, W): one
            crop of the pattern per sample).
        check: validate the inputs (finite, >= 0, matching shapes).
        backend: ``"torch"``: the chain as torch element-wise operations (any device; shot noise by
            :func:`shot_noise`'s ``"auto"`` backend); ``"numba"`` (CPU, float32/float64, needs numba): the same
            operations compiled into one pass per photodiode (clipping, PRNU, dark signal, shot noise, full
            well: :func:`lfmbench._poisson_kernel.collect`) and one per capture (the read-out:
            :func:`lfmbench._readout_kernel.readout`), bit-identical to ``"torch"`` on the CPU with a fraction of
            its memory passes (docs/dataset-benchmark.md); ``"auto"``: ``"numba"`` where it applies, else
            ``"torch"``.
        threads: with one generator per sample on the CPU, the samples are simulated by this many Python threads
            (default ``torch.get_num_threads()``; the result does not depend on it). The threads do not spin while
            they wait, unlike OpenMP's: on a machine shared with other jobs use ``torch.set_num_threads(1)`` and
            ``threads`` = the cores to use.

    Returns:
        as :func:`simulate_split_pixel`.
    """
    if backend not in ("auto", "numba", "torch"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'torch', got {backend!r}")
    _check_pair(lpd_electrons, spd_electrons, "lpd_electrons", "spd_electrons", check)
    if lpd_electrons.shape[-3] != 1:
        raise ValueError(f"lpd_electrons must have shape (*, 1, H, W) (a CFA mosaic), got {tuple(lpd_electrons.shape)}")
    preset = load_preset(preset)
    x = lpd_electrons
    if noise:
        gens = list(generator) if isinstance(generator, (list, tuple)) else [generator]
        if not gens or not all(isinstance(g, torch.Generator) for g in gens):
            raise ValueError("generator must be a torch.Generator (or a sequence of them, one per sample) when "
                             "noise=True (no hidden global randomness)")
        if isinstance(generator, (list, tuple)) and (x.dim() < 4 or len(gens) != x.shape[0]):
            raise ValueError(f"generator: {len(gens)} generators for inputs of shape {tuple(x.shape)}; a sequence "
                             "needs one generator per index of the leading (sample) dimension")
        for g in gens:
            if g.device.type != x.device.type:
                raise ValueError(f"generator is on {g.device} but the inputs are on {x.device}")
    lead = x.shape[:-3]
    H, W = x.shape[-2:]
    t_s = _exposure(exposure_short_s, "exposure_short_s", lead, x)
    t_l = _exposure(exposure_long_s, "exposure_long_s", lead, x)
    if fpn is None and noise and any(p.prnu > 0 or p.dsnu_e > 0 for p in preset.photodiodes.values()):
        fpn = fixed_pattern(preset, H, W, device=x.device, dtype=x.dtype)
    elif fpn is not None:
        fpn = {k: v.to(device=x.device, dtype=x.dtype) for k, v in fpn.items()}
        for k, v in fpn.items():
            if v.shape[-2:] != (H, W):
                raise ValueError(f"fpn[{k!r}] has shape {tuple(v.shape)}, expected (..., {H}, {W})")
    fused = x.device.type == "cpu" and x.dtype in (torch.float32, torch.float64) and _poisson.available()
    if backend == "numba" and not fused:
        raise ValueError(f"backend='numba' needs float32/float64 CPU inputs and numba (got {x.dtype} on {x.device})")
    if fused and backend != "torch":
        return _chain_fused(lpd_electrons, spd_electrons, preset, t_s, t_l, generator, noise, fpn, threads)

    pd_inputs = {"lpd": (lpd_electrons, t_s), "spd": (spd_electrons, t_l)}
    collected: dict[str, torch.Tensor] = {}
    for pd, (mu, t) in pd_inputs.items():
        spec = preset.photodiodes[pd]
        cap = _MEAN_CAP_FULL_WELLS * spec.full_well_e
        mu = torch.nan_to_num(mu, nan=0.0, posinf=cap).clamp_(0.0, cap)         # overflow-safe, exact after clip
        if noise and fpn is not None and spec.prnu > 0:
            mu.mul_(fpn[f"{pd}_gain"])
        mu.add_(spec.dark_current_e_per_s * t)
        n = _per_generator(lambda m, g: shot_noise(m, g, preset.shot_noise_gaussian_above_e), mu, generator,
                           threads) if noise else mu
        collected[pd] = n.clamp_(0.0, spec.full_well_e)

    out: dict[str, torch.Tensor] = {}
    sats = []
    for cap in CAPTURES:
        pd = preset.captures[cap].photodiode
        offset = fpn[f"{pd}_offset_e"] if (noise and fpn is not None and preset.photodiodes[pd].dsnu_e > 0) else None
        r = read_capture(collected[pd], preset, cap, generator, noise, offset)
        out[cap] = r["dn"]
        # DN -> e-, minus the mean dark signal (what optical-black clamping removes), so that the expectation
        # of the input-referred value equals ideal_electrons() below saturation
        e_ref = (r["dn"] - preset.black_level_dn).div_(preset.system_gain(cap)) \
            .sub_(preset.photodiodes[pd].dark_current_e_per_s * pd_inputs[pd][1])
        if pd == "spd":
            e_ref.mul_(preset.sensitivity_ratio * t_s / t_l)
        out[f"{cap}_e"] = e_ref
        sats.append(r["saturated"])
    out["saturated"] = torch.cat(sats, dim=-3)
    return out


def simulate_split_pixel(lpd_radiant_exposure: torch.Tensor, spd_radiant_exposure: torch.Tensor,
                         preset: SensorPreset | str, wavelengths_nm: Sequence[float] | torch.Tensor,
                         exposure_short_s: float | torch.Tensor, exposure_long_s: float | torch.Tensor,
                         generator: torch.Generator | None = None, noise: bool = True,
                         bandwidths_nm: Sequence[float] | None = None,
                         fpn: Mapping[str, torch.Tensor] | None = None, check: bool = True) -> dict[str, torch.Tensor]:
    """Simulate the three captures (LPD-HCG, LPD-LCG, SPD) of a split-pixel sensor.

    Args:
        lpd_radiant_exposure: (*, C, H, W) spectral radiant exposure at the pixel over the short (LPD) exposure,
            J m^-2 nm^-1 (spectral irradiance W m^-2 nm^-1 x s, flicker weights included by the caller).
        spd_radiant_exposure: (*, C, H, W) the same over the long (SPD) exposure, J m^-2 nm^-1.
        preset: sensor preset or name (``"ovt"``, ``"imx490"``, a YAML path).
        wavelengths_nm: C band centres in nm.
        exposure_short_s: LPD exposure time in s, scalar or shape (*) (per sample); used for dark current.
        exposure_long_s: SPD exposure time in s, scalar or shape (*); used for dark current and input referral.
        generator: ``torch.Generator`` on the inputs' device; required when ``noise`` is true.
        noise: ``False`` gives the noise-free chain (mean electrons incl. dark current, no FPN, clipping and
            quantisation kept).
        bandwidths_nm: band widths in nm (default: local spacing of ``wavelengths_nm``).
        fpn: fixed-pattern maps from :func:`fixed_pattern` (default: built for (H, W) from the preset's seed).
        check: validate the inputs (finite, >= 0, matching shapes).

    Returns:
        dict with ``lpd_hcg``, ``lpd_lcg``, ``spd``: (*, 1, H, W) raw DN (black level included);
        ``lpd_hcg_e``, ``lpd_lcg_e``, ``spd_e``: (*, 1, H, W) input-referred LPD-equivalent e- over the short
        exposure, mean dark signal removed (same units and expectation as :func:`ideal_electrons` of the LPD);
        ``saturated``: (*, 3, H, W) bool (hcg, lcg, spd), volts >= saturation_fraction x swing.
        Floating outputs have the dtype of the inputs.
    """
    _check_pair(lpd_radiant_exposure, spd_radiant_exposure, "lpd_radiant_exposure", "spd_radiant_exposure", check)
    preset = load_preset(preset)
    lpd_e = ideal_electrons(lpd_radiant_exposure, preset, wavelengths_nm, "lpd", bandwidths_nm, check=False)
    spd_e = ideal_electrons(spd_radiant_exposure, preset, wavelengths_nm, "spd", bandwidths_nm, check=False)
    return simulate_split_pixel_electrons(lpd_e, spd_e, preset, exposure_short_s, exposure_long_s, generator,
                                          noise, fpn, check=False)


class SplitPixelSensor(nn.Module):
    """``nn.Module`` wrapper of :func:`simulate_split_pixel` holding the preset and the band grid.

    Args:
        preset: preset, name or YAML path.
        wavelengths_nm: C band centres in nm (default 400:10:700).
        noise: default for the ``noise`` argument.

    Shape:
        inputs (*, C, H, W) spectral radiant exposure in J m^-2 nm^-1; outputs as :func:`simulate_split_pixel`.
    """

    def __init__(self, preset: SensorPreset | str = "ovt", wavelengths_nm: Sequence[float] | None = None,
                 noise: bool = True) -> None:
        super().__init__()
        self.preset = load_preset(preset)
        wl = range(400, 701, 10) if wavelengths_nm is None else wavelengths_nm
        self.wavelengths_nm = [float(w) for w in wl]
        self.noise = noise

    def forward(self, lpd_radiant_exposure: torch.Tensor, spd_radiant_exposure: torch.Tensor,
                exposure_short_s: float | torch.Tensor, exposure_long_s: float | torch.Tensor,
                generator: torch.Generator | None = None, noise: bool | None = None) -> dict[str, torch.Tensor]:
        return simulate_split_pixel(lpd_radiant_exposure, spd_radiant_exposure, self.preset, self.wavelengths_nm,
                                    exposure_short_s, exposure_long_s, generator=generator,
                                    noise=self.noise if noise is None else noise)


# ----------------------------------------------------------------------------------------------------------
# silicon photodiode model
# ----------------------------------------------------------------------------------------------------------
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
    wl = _wavelengths(wavelengths_nm)
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
