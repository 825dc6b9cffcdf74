"""Sensor presets: the schema of a split-pixel camera and its YAML files (``lfmbench/configs/sensors/``).

- :class:`SensorPreset` (+ :class:`PhotodiodeSpec`, :class:`CaptureSpec`), loaded from YAML by
  :func:`load_preset` (``"ovt"``, ``"imx490"`` or a file path); invalid fields raise ``ValueError`` naming the
  field and file.
- :class:`CFAPattern`: Bayer layouts by their top-left 2x2 cell (``GRBG`` default), with the kornia mapping.

References
----------
.. [EMVA1288] EMVA Standard 1288, "Standard for Characterization of Image Sensors and Cameras", Release 4.0
   Linear (2021): the linear camera model (sec. 2).
.. [Solhusvik2019] J. Solhusvik et al., "A 1280x960 2.8 um HDR CIS with DCG and Split-Pixel Combined",
   International Image Sensor Workshop (2019) - the 'ovt' preset, via ISETCam ``sensorCreate('ovt-large')``.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field, fields
from enum import Enum
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import torch

from lfmbench.limits import brief
from lfmbench.registry import Registry
from lfmbench.check import check_keys, check_number, get_number
from lfmbench.sensor.optics import OpticsConfig
from lfmbench.sensor.plan import ARCHITECTURES, Readout, check_plan, exposure_groups, parse_exposure, parse_readout
from lfmbench.sensor.spectral_data import DATA_DIR, read_spectral_csv
from lfmbench.vocabulary import CAPTURES, PHOTODIODES

__all__ = ["CAPTURES", "PHOTODIODES", "PRESET_DIR", "CFAPattern", "PhotodiodeSpec", "CaptureSpec", "SensorPreset",
           "Spectral", "Companding", "preset_registry",
           "available_presets", "load_preset", "resolve", "preset_from_dict"]

#: Shipped sensor presets (YAML).
PRESET_DIR: Path = Path(__file__).resolve().parent.parent / "configs" / "sensors"


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


@dataclass(frozen=True)
class PhotodiodeSpec:
    """One photodiode of the split pixel.

    Attributes:
        fill_factor: effective light-collecting fraction of the pixel area (dimensionless, (0, 1]).
        full_well_e: full-well capacity in e-.
        dark_current_e_per_s: mean dark current in e-/s.
        dsnu_e: dark-signal non-uniformity, standard deviation of a per-pixel offset in e-.
        prnu: photo-response non-uniformity, standard deviation of the per-pixel gain (fraction, 0.01 = 1 %).
        spectral: this photodiode's own spectral response (``None``: the preset's ``spectral``), e.g. the large
            and small photodiodes of a split pixel measured apart.
    """

    fill_factor: float
    full_well_e: float
    dark_current_e_per_s: float = 0.0
    dsnu_e: float = 0.0
    prnu: float = 0.0
    spectral: "Spectral | None" = None


@dataclass(frozen=True)
class Spectral:
    """A spectral response: relative r, g, b sensitivities and their peak QE.

    Attributes:
        filters_path: CSV of relative spectral sensitivities (columns wavelength_nm, r, g, b).
        peak_qe: scale of the relative curves to absolute QE (e- per photon).
    """

    filters_path: Path
    peak_qe: float


@dataclass(frozen=True)
class Companding:
    """On-sensor companding of a capture: the ADC digitises ``linear_bits`` bits, and a piecewise-linear curve
    (``knees``: (linear DN, output DN) points, both increasing, from (0, 0) to (2^linear_bits - 1, 2^adc_bits - 1))
    compresses them into the preset's ``adc_bits`` (e.g. the 20/24-bit HDR output of onsemi parts companded to
    12 bits). The black level is added before companding; ``*_e`` outputs undo it (:func:`decompand`).

    Attributes:
        linear_bits: bits of the linear ADC code.
        knees: ((linear DN, output DN), ...) float pairs.
    """

    linear_bits: int
    knees: tuple


@dataclass(frozen=True)
class CaptureSpec:
    """One read-out of a photodiode: what it reads, over which time windows, how.

    Attributes:
        photodiode: a key of ``SensorPreset.photodiodes``.
        conversion_gain_v_per_e: conversion gain in V/e-.
        voltage_swing_v: voltage swing (ADC input range) in V.
        read_noise_e: read noise standard deviation in e- (Gaussian).
        exposure: ``"short"`` / ``"long"`` (a window the corpus stores: the short exposure centred in the long
            one, or the long one) or a tuple of ``(start_s, length_s)`` windows relative to the frame start, s
            (several: a chopped exposure integrating their union); :mod:`lfmbench.sensor.plan`.
        readout: global or rolling shutter and line time (:class:`lfmbench.sensor.plan.Readout`; unset fields
            come from the preset's ``readout``, then from the dataset).
        companding: on-sensor companding of its code (:class:`Companding`; ``None``: linear ``adc_bits``).
    """

    photodiode: str
    conversion_gain_v_per_e: float
    voltage_swing_v: float
    read_noise_e: float
    exposure: Any = "short"
    readout: Readout = field(default_factory=Readout)
    companding: Companding | None = None


@dataclass(frozen=True)
class SensorPreset:
    """A camera: pixel, CFA, photodiodes, capture plan, ADC and lens. Load with :func:`load_preset`.

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
        photodiodes: ``{name: PhotodiodeSpec}`` (split pixel: ``lpd``, ``spd``).
        captures: ``{name: CaptureSpec}`` in read-out order, the capture plan (split pixel: ``lpd_hcg``,
            ``lpd_lcg``, ``spd``); names are the sample keys of the captures.
        optics: lens of the camera.
        source: file the preset was read from.
        architecture: one of :data:`lfmbench.sensor.plan.ARCHITECTURES` (``split_pixel``, ``lofic``,
            ``staggered``, ``chopped``, ``single``).
        reference: the capture whose photodiode and windows define the ground truth and the input-referred
            units of every ``*_e`` output.
        readout: the preset's default readout (a capture's own ``readout`` fields take precedence).
        frame_time_s: frame period the plan is made for, s (optional; windows must end within it).
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
    architecture: str = "split_pixel"
    reference: str = "lpd_hcg"
    readout: Readout = field(default_factory=Readout)
    frame_time_s: float | None = None

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
        """LPD / SPD sensitivity (dimensionless): ratio of the fill factors (both share the spectral curves).
        Split pixel only (``ValueError`` otherwise)."""
        if self.architecture != "split_pixel":
            raise ValueError(f"sensitivity_ratio is the LPD/SPD ratio of a split pixel; preset {self.name!r} is "
                             f"{self.architecture}")
        return self.photodiodes["lpd"].fill_factor / self.photodiodes["spd"].fill_factor

    @property
    def exposures(self) -> dict[str, tuple[str, ...]]:
        """``{exposure key: capture names}``: the captures grouped by the charge they read
        (:func:`lfmbench.sensor.plan.exposure_groups`); split pixel: ``{"lpd_hcg": ("lpd_hcg", "lpd_lcg"),
        "spd": ("spd",)}``."""
        return exposure_groups(self.captures)

    def capture_readout(self, capture: str) -> Readout:
        """The readout of ``capture``: its own fields, else the preset's (fields may stay ``None``)."""
        own, top = self.captures[capture].readout, self.readout
        return Readout(own.shutter or top.shutter,
                       own.line_time_s if own.line_time_s is not None else top.line_time_s)

    def linear_max_dn(self, capture: str) -> int:
        """Largest linear ADC code of ``capture`` (DN): 2^bits - 1, or 2^linear_bits - 1 before its companding."""
        comp = self.captures[capture].companding
        return self.max_dn if comp is None else 2 ** comp.linear_bits - 1

    def dn_per_volt(self, capture: str) -> float:
        """ADC gain of ``capture`` in DN/V: (2^bits - 1 - black_level) / voltage_swing (linear DN before any
        companding)."""
        return (self.linear_max_dn(capture) - self.black_level_dn) / self.captures[capture].voltage_swing_v

    def system_gain(self, capture: str) -> float:
        """Overall system gain K of ``capture`` in DN/e- [EMVA1288]_ (conversion gain x ADC gain)."""
        return self.captures[capture].conversion_gain_v_per_e * self.dn_per_volt(capture)

    def spectral_of(self, photodiode: str) -> Spectral:
        """The spectral response of ``photodiode``: its own, else the preset's."""
        own = self.photodiodes[photodiode].spectral
        return own if own is not None else Spectral(self.filters_path, self.peak_qe)

    def saturation_capacity_e(self, capture: str) -> float:
        """Electrons at which ``capture`` clips: min(full well, voltage swing / conversion gain), in e-."""
        spec = self.captures[capture]
        return min(self.photodiodes[spec.photodiode].full_well_e, spec.voltage_swing_v / spec.conversion_gain_v_per_e)


def _rebuild_preset(state: dict[str, Any]) -> SensorPreset:
    state = dict(state)
    state["photodiodes"] = MappingProxyType(dict(state["photodiodes"]))
    state["captures"] = MappingProxyType(dict(state["captures"]))
    return SensorPreset(**state)


def preset_registry() -> Registry:
    """The registry of shipped presets: name -> its YAML file (``lfmbench/configs/sensors/<name>.yaml``; adding a
    preset is adding its file). Built from the directory on each call, so a file added at run time is found."""
    reg = Registry("sensor preset")
    for f in sorted(PRESET_DIR.glob("*.yaml")):
        reg.register(f.stem, f)
    return reg


def available_presets() -> list[str]:
    """Names of the shipped presets (:func:`preset_registry`), sorted."""
    return list(preset_registry().names())


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
        # A shipped name is its file in PRESET_DIR (the registry's rule): looked up directly, so resolving a name
        # per batch costs one stat, not a directory listing; the listing is made only to name the choices.
        shipped = PRESET_DIR / f"{text}.yaml"
        if path.name != text or not shipped.is_file():
            raise ValueError(f"preset: unknown sensor preset {brief(text)}; shipped presets are "
                             f"{preset_registry().names()} or give a path to a YAML file")
        path = shipped
    resolved = path.resolve()
    if not resolved.is_file():
        raise ValueError(f"preset: file {resolved} does not exist")
    return _load_preset_file(str(resolved), resolved.stat().st_mtime_ns)


def resolve(preset: "SensorPreset | str | Path | Mapping[str, Any]") -> SensorPreset:
    """The one helper below the commands that turns a preset name, path or mapping into a :class:`SensorPreset`
    (:func:`load_preset`); a ``SensorPreset`` is returned unchanged, no file looked at. The commands resolve
    ``--sensor`` once and pass the object on. Raises ``ValueError`` as :func:`load_preset`."""
    if isinstance(preset, SensorPreset):
        return preset
    return load_preset(preset)


@functools.lru_cache(maxsize=32)
def _load_preset_file(path: str, mtime_ns: int = 0) -> SensorPreset:
    """Parse one preset file (cached per path and modification time, so edits are picked up)."""
    from lfmbench.fileio import load_yaml

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"preset: file {path} does not exist")
    try:
        data = load_yaml(p, source=f"preset {path}")
    except OSError as exc:
        raise ValueError(f"preset: cannot read {path}: {exc.strerror or exc}") from None
    return preset_from_dict(data, path)


def _entries(data: Mapping[str, Any], section: str, names: Sequence[str] | None, spec: type, source: str):
    """Yield ``(name, fields, prefix)`` for each entry of ``data[section]`` (``names``: the entries required, in
    this order, and no others; None: any non-empty set of string-named entries, in file order), after checking
    that the section and every entry exist and hold only known keys (the fields of dataclass ``spec``)."""
    raw = data.get(section)
    if raw is None:
        raise ValueError(f"{source}: missing field '{section}'")
    if names is None:
        check_keys(raw, section, source, optional=None)
        if not raw or len(raw) > MAX_ENTRIES:
            raise ValueError(f"{source}: field '{section}' must hold 1 to {MAX_ENTRIES} entries, got {len(raw)}")
        names = [str(k) for k in raw]
    check_keys(raw, section, source, optional=set(names))
    for name in names:
        if name not in raw:
            raise ValueError(f"{source}: missing field '{section}.{name}'")
        check_keys(raw[name], f"{section}.{name}", source, optional={f.name for f in fields(spec)})
        yield name, raw[name], f"{section}.{name}."


#: Most photodiodes or captures of one preset.
MAX_ENTRIES = 8


def _parse_spectral(raw: Any, field: str, source: str) -> Spectral:
    """A ``spectral`` mapping (``filters``: a CSV in lfmbench/data or next to the preset, ``peak_qe``), checked."""
    check_keys(raw, field, source, optional={"filters", "peak_qe"})
    peak_qe = get_number(raw, "peak_qe", source, f"{field}.", lo=0, lo_open=True, hi=1.0)
    filters = raw.get("filters")
    if not isinstance(filters, str) or not filters:
        raise ValueError(f"{source}: field '{field}.filters' must be a file name, got {brief(filters)}")
    fpath = Path(filters)
    if not fpath.is_absolute():
        here = Path(source).parent if source != "<dict>" else None
        cands = ([here / fpath] if here is not None else []) + [DATA_DIR / fpath]
        fpath = next((c for c in cands if c.is_file()), cands[-1])
    if not fpath.is_file():
        raise ValueError(f"{source}: field '{field}.filters': file {brief(filters)} not found (looked next to the "
                         f"preset and in {DATA_DIR})")
    try:
        _, names, vals = read_spectral_csv(fpath)
    except ValueError as exc:
        raise ValueError(f"{source}: field '{field}.filters': {exc}") from exc
    if [n.lower() for n in names] != ["r", "g", "b"]:
        raise ValueError(f"{source}: field '{field}.filters': {fpath} must have columns wavelength_nm,r,g,b, "
                         f"got {names}")
    if float(vals.max()) * peak_qe > 1.0 + 1e-9:
        raise ValueError(f"{source}: field '{field}.peak_qe': peak_qe x the largest relative sensitivity "
                         f"{float(vals.max()):.4g} = {float(vals.max()) * peak_qe:.4g} is a QE above 1")
    return Spectral(fpath, peak_qe)


def _parse_companding(raw: Any, field: str, source: str, bits: int, black: float) -> Companding | None:
    """A capture's ``companding`` mapping (``linear_bits``, ``knees``), checked; ``None`` when absent."""
    if raw is None:
        return None
    check_keys(raw, field, source, optional={"linear_bits", "knees"})
    lb = get_number(raw, "linear_bits", source, f"{field}.", lo=bits, hi=32, integer=True)
    knees = raw.get("knees")
    if not isinstance(knees, (list, tuple)) or not 2 <= len(knees) <= 32:
        raise ValueError(f"{source}: field '{field}.knees' must be a list of 2 to 32 [linear_dn, output_dn] "
                         f"points, got {brief(knees)}")
    pts = []
    for i, k in enumerate(knees):
        if not isinstance(k, (list, tuple)) or len(k) != 2:
            raise ValueError(f"{source}: field '{field}.knees[{i}]' must be [linear_dn, output_dn], got {brief(k)}")
        pts.append((float(check_number(k[0], f"{field}.knees[{i}][0]", source, lo=0, hi=2 ** lb - 1)),
                    float(check_number(k[1], f"{field}.knees[{i}][1]", source, lo=0, hi=2 ** bits - 1))))
    if pts[0] != (0.0, 0.0) or pts[-1] != (float(2 ** lb - 1), float(2 ** bits - 1)):
        raise ValueError(f"{source}: field '{field}.knees' must run from [0, 0] to [{2 ** lb - 1}, {2 ** bits - 1}] "
                         f"(the linear and the output code ranges), got {pts[0]} .. {pts[-1]}")
    for i in range(1, len(pts)):
        if not (pts[i][0] > pts[i - 1][0] and pts[i][1] > pts[i - 1][1]):
            raise ValueError(f"{source}: field '{field}.knees[{i}]' must be above knee {i - 1} in both codes "
                             "(companding is strictly increasing)")
    if black > 0 and not pts[1][0] >= black:
        raise ValueError(f"{source}: field '{field}.knees[1]' must lie at or above black_level_dn = {black:g}")
    return Companding(int(lb), tuple(pts))


def preset_from_dict(data: Mapping[str, Any], source: str = "<dict>") -> SensorPreset:
    """Validate a plain mapping (the YAML structure of ``configs/sensors/ovt.yaml``) into a :class:`SensorPreset`.

    Raises:
        ValueError: naming the offending field and ``source``.
    """
    top = {"name", "description", "pixel_pitch_m", "cfa", "adc_bits", "black_level_dn", "saturation_fraction",
           "spectral", "shot_noise_gaussian_above_e", "fpn_seed", "photodiodes", "captures", "optics",
           "architecture", "reference", "readout", "frame_time_s"}
    check_keys(data, "", source, optional=top)
    arch = data.get("architecture", "split_pixel")
    if arch not in ARCHITECTURES:
        raise ValueError(f"{source}: field 'architecture' must be one of {list(ARCHITECTURES)}, got {brief(arch)}")
    split = arch == "split_pixel"
    frame_time = get_number(data, "frame_time_s", source, lo=0, lo_open=True, hi=1.0, default=None)
    readout = parse_readout(data.get("readout"), "readout", source)
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise ValueError(f"{source}: field 'name' must be a non-empty string, got {brief(name)}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ValueError(f"{source}: field 'description' must be a string")
    pitch = get_number(data, "pixel_pitch_m", source, lo=0, lo_open=True, hi=1e-3)
    try:
        cfa = CFAPattern(str(data.get("cfa", "GRBG")).upper())
    except ValueError:
        raise ValueError(f"{source}: field 'cfa' must be one of {[c.value for c in CFAPattern]}, "
                         f"got {brief(data.get('cfa'))}") from None
    bits = get_number(data, "adc_bits", source, lo=1, hi=24, integer=True)
    black = get_number(data, "black_level_dn", source, lo=0, hi=2 ** bits - 2, default=0.0)
    sat_frac = get_number(data, "saturation_fraction", source, lo=0, lo_open=True, hi=1.0, default=0.95)
    gauss = get_number(data, "shot_noise_gaussian_above_e", source, lo=0, default=1000.0, allow_inf=True)
    seed = get_number(data, "fpn_seed", source, lo=0, integer=True, default=0)

    spectral = data.get("spectral")
    if spectral is None:
        raise ValueError(f"{source}: missing field 'spectral'")
    top_spectral = _parse_spectral(spectral, "spectral", source)
    fpath, peak_qe = top_spectral.filters_path, top_spectral.peak_qe

    pds: dict[str, PhotodiodeSpec] = {}
    for pd, d, pre in _entries(data, "photodiodes", PHOTODIODES if split else None, PhotodiodeSpec, source):
        pds[pd] = PhotodiodeSpec(
            fill_factor=get_number(d, "fill_factor", source, pre, lo=0, lo_open=True, hi=1.0),
            full_well_e=get_number(d, "full_well_e", source, pre, lo=0, lo_open=True),
            dark_current_e_per_s=get_number(d, "dark_current_e_per_s", source, pre, lo=0, default=0.0),
            dsnu_e=get_number(d, "dsnu_e", source, pre, lo=0, default=0.0),
            prnu=get_number(d, "prnu", source, pre, lo=0, hi=0.5, default=0.0),
            spectral=_parse_spectral(d["spectral"], f"{pre}spectral", source) if d.get("spectral") is not None
            else None,
        )

    caps: dict[str, CaptureSpec] = {}
    for cap, d, pre in _entries(data, "captures", CAPTURES if split else None, CaptureSpec, source):
        pd = d.get("photodiode")
        if pd not in pds:
            raise ValueError(f"{source}: field '{pre}photodiode' must be one of {list(pds)}, got {brief(pd)}")
        if "exposure" in d:
            exposure = parse_exposure(d["exposure"], f"{pre}exposure", source, frame_time)
        elif split:  # the split pixel's timing (docs/guide/contracts.md): LPD the short window, SPD the long one
            exposure = "short" if pd == "lpd" else "long"
        else:
            raise ValueError(f"{source}: missing field '{pre}exposure'")
        caps[cap] = CaptureSpec(
            photodiode=pd,
            conversion_gain_v_per_e=get_number(d, "conversion_gain_v_per_e", source, pre, lo=0, lo_open=True, hi=1e-2),
            voltage_swing_v=get_number(d, "voltage_swing_v", source, pre, lo=0, lo_open=True, hi=100.0),
            read_noise_e=get_number(d, "read_noise_e", source, pre, lo=0),
            exposure=exposure,
            readout=parse_readout(d.get("readout"), f"{pre}readout", source),
            companding=_parse_companding(d.get("companding"), f"{pre}companding", source, bits, black),
        )
        if split and caps[cap].companding is not None:
            raise ValueError(f"{source}: field '{pre}companding': the split pixel's chain reads linear codes; a "
                             "companded plan needs architecture 'multi_photodiode'")
    check_plan(arch, pds, caps, source)
    reference = data.get("reference", ARCHITECTURES[arch].reference(caps))
    if reference not in caps:
        raise ValueError(f"{source}: field 'reference' must name a capture ({list(caps)}), got {brief(reference)}")
    optics = OpticsConfig.from_mapping(data["optics"], source) if "optics" in data else OpticsConfig()
    return SensorPreset(name=name, description=description, pixel_pitch_m=pitch, cfa=cfa, adc_bits=bits,
                        black_level_dn=black, saturation_fraction=sat_frac, filters_path=fpath, peak_qe=peak_qe,
                        shot_noise_gaussian_above_e=gauss, fpn_seed=seed, photodiodes=MappingProxyType(pds),
                        captures=MappingProxyType(caps),
                        optics=optics, source=source, architecture=arch, reference=reference, readout=readout,
                        frame_time_s=frame_time)
