"""A sensor preset from EMVA 1288 results: ``lfmbench sensor fit`` (docs/guide/sensors.md, "Your own sensor").

An EMVA 1288 Release 4 data sheet [EMVA1288]_ gives, per camera and gain setting, the linear camera model's
parameters; with an exposure plan they are a preset:

============================  ==========================================  =============================================
EMVA 1288 result (file field)  unit                                        preset field
============================  ==========================================  =============================================
``system_gain_dn_per_e``       K, DN/e-                                    conversion gain = K x swing / (2^bits - 1 - black)
``temporal_dark_noise_e``      sigma_d, e- (at ``dark_noise_exposure_s``)  read_noise_e = sqrt(sigma_d^2 - dark current x t)
``saturation_capacity_e``      mu_e.sat, e-                                full_well_e
``qe_curve``                   CSV wavelength_nm, r, g, b (absolute QE)     spectral (peak_qe 1)
``dsnu_e``                     DSNU1288, e-                                dsnu_e
``prnu_percent``               PRNU1288, %                                 prnu = PRNU1288 / 100
``dark_current_e_per_s``       e-/s                                        dark_current_e_per_s
``adc_bits``, ``black_level_dn``, ``pixel_pitch_m``  (camera)              same names
============================  ==========================================  =============================================

The photodiode's fill factor is 1 (the EMVA QE is that of the whole pixel), the voltage swing 1 V (only K enters the
model). Exposures: one window list per capture (:func:`lfmbench.sensor.plan.parse_exposure`); one capture of one
window is architecture ``single``, one of several windows ``chopped``, several captures ``staggered`` (longest
first).

References
----------
.. [EMVA1288] EMVA Standard 1288, "Standard for Characterization of Image Sensors and Cameras", Release 4.0 Linear
   (2021): sec. 2 (linear model), sec. 6 (photon transfer), sec. 8 (DSNU, PRNU).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

from lfmbench.check import check_keys, get_number
from lfmbench.limits import brief
from lfmbench.sensor.plan import parse_exposure, resolve_windows, total_length_s
from lfmbench.sensor.preset import preset_from_dict
from lfmbench.sensor.spectral_data import read_spectral_csv

__all__ = ["EMVA_FIELDS", "read_emva", "preset_from_emva"]

#: Fields of an EMVA 1288 results file: required, then optional (with defaults).
EMVA_FIELDS = {"required": ("emva1288_release", "pixel_pitch_m", "adc_bits", "system_gain_dn_per_e",
                            "temporal_dark_noise_e", "saturation_capacity_e", "qe_curve"),
               "optional": ("name", "black_level_dn", "dsnu_e", "prnu_percent", "dark_current_e_per_s",
                            "dark_noise_exposure_s", "cfa", "description")}


def read_emva(data: Mapping[str, Any], source: str) -> dict[str, Any]:
    """Check an EMVA 1288 results mapping (fields of :data:`EMVA_FIELDS`); errors ``<source>: field '...' ...``.

    Returns:
        the values (numbers as floats, ``qe_curve`` resolved to a path next to ``source``).
    """
    check_keys(data, "", source, optional=set(EMVA_FIELDS["required"]) | set(EMVA_FIELDS["optional"]))
    for k in EMVA_FIELDS["required"]:
        if k not in data:
            raise ValueError(f"{source}: missing field '{k}'")
    rel = data["emva1288_release"]
    if rel not in (4, "4", "4.0", 4.0):
        raise ValueError(f"{source}: field 'emva1288_release' must be 4 (Release 4.0 Linear), got {brief(rel)}")
    out: dict[str, Any] = {
        "pixel_pitch_m": get_number(data, "pixel_pitch_m", source, lo=0, lo_open=True, hi=1e-3),
        "adc_bits": get_number(data, "adc_bits", source, lo=1, hi=24, integer=True),
        "K": get_number(data, "system_gain_dn_per_e", source, lo=0, lo_open=True, hi=1e3),
        "sigma_d": get_number(data, "temporal_dark_noise_e", source, lo=0, hi=1e4),
        "sat": get_number(data, "saturation_capacity_e", source, lo=0, lo_open=True, hi=1e9),
        "dsnu": get_number(data, "dsnu_e", source, lo=0, hi=1e4, default=0.0),
        "prnu": get_number(data, "prnu_percent", source, lo=0, hi=50, default=0.0) / 100.0,
        "dark": get_number(data, "dark_current_e_per_s", source, lo=0, hi=1e9, default=0.0),
        "t_dark": get_number(data, "dark_noise_exposure_s", source, lo=0, hi=10.0, default=0.0),
    }
    out["black"] = get_number(data, "black_level_dn", source, lo=0, hi=2 ** out["adc_bits"] - 2, default=0.0)
    for k in ("name", "description", "cfa"):
        v = data.get(k)
        if v is not None and (not isinstance(v, str) or not v or len(v) > 200):
            raise ValueError(f"{source}: field '{k}' must be a non-empty string, got {brief(v)}")
        out[k] = v
    shot2 = out["dark"] * out["t_dark"]
    if shot2 > out["sigma_d"] ** 2:
        raise ValueError(f"{source}: field 'temporal_dark_noise_e' ({out['sigma_d']:g} e-) is below the dark-current "
                         f"shot noise sqrt({out['dark']:g} e-/s x {out['t_dark']:g} s) it includes")
    out["read"] = math.sqrt(out["sigma_d"] ** 2 - shot2)
    if out["K"] * out["sat"] > 2 ** out["adc_bits"] - 1 - out["black"] + 1e-9 * out["K"] * out["sat"] + 1.0:
        raise ValueError(f"{source}: field 'saturation_capacity_e': {out['sat']:g} e- x K {out['K']:g} DN/e- = "
                         f"{out['K'] * out['sat']:.6g} DN exceeds the {out['adc_bits']}-bit range above the black level")
    qe = data["qe_curve"]
    if not isinstance(qe, str) or not qe:
        raise ValueError(f"{source}: field 'qe_curve' must be a CSV file name, got {brief(qe)}")
    qpath = Path(qe) if Path(qe).is_absolute() else Path(source).parent / qe
    if not qpath.is_file():
        raise ValueError(f"{source}: field 'qe_curve': file {brief(qe)} not found (relative to the EMVA file)")
    try:
        _, names, vals = read_spectral_csv(qpath)
    except ValueError as exc:
        raise ValueError(f"{source}: field 'qe_curve': {exc}") from None
    if [n.lower() for n in names] != ["r", "g", "b"]:
        raise ValueError(f"{source}: field 'qe_curve': {qpath.name} must have columns wavelength_nm,r,g,b, got {names}")
    if float(vals.max()) > 1.0 or float(vals.min()) < 0.0:
        raise ValueError(f"{source}: field 'qe_curve': {qpath.name} holds QE {float(vals.max()):.4g} / "
                         f"{float(vals.min()):.4g}: an absolute QE lies in [0, 1] (e- per photon)")
    out["qe_path"] = qpath.resolve()
    return out


def preset_from_emva(data: Mapping[str, Any], exposures: Sequence[Any], source: str,
                     qe_ref: str | None = None) -> dict[str, Any]:
    """The preset mapping (the YAML structure of ``configs/sensors/*.yaml``) of an EMVA 1288 result and a plan.

    Args:
        data: the EMVA 1288 results mapping (:data:`EMVA_FIELDS`). source: its file (errors name it).
        exposures: per capture, ``"short"`` / ``"long"`` or a list of ``[start_s, length_s]`` windows.
        qe_ref: how the preset names the QE file (default: its absolute path).

    Returns:
        a plain mapping that :func:`lfmbench.sensor.preset_from_dict` loads (checked by loading it).

    Raises:
        ValueError: a missing or non-physical EMVA field, or a bad exposure (one line naming file and field).
    """
    v = read_emva(data, source)
    if not exposures:
        raise ValueError(f"{source}: no exposure given (--exposure): a preset needs an exposure plan")
    bits, black = v["adc_bits"], v["black"]
    swing = 1.0
    cg = v["K"] * swing / (2 ** bits - 1 - black)            # K = cg x dn_per_volt (lfmbench.sensor.SensorPreset)
    parsed = [parse_exposure(e, f"exposure[{i}]", "--exposure") for i, e in enumerate(exposures)]
    timing = {"short_exposure_s": 0.004, "long_exposure_s": 1 / 90}
    if len(parsed) == 1:
        arch = "single" if isinstance(parsed[0], str) or len(parsed[0]) == 1 else "chopped"
        names = ["main"]
    else:
        arch = "staggered"
        names = [f"e{i + 1}" for i in range(len(parsed))]
        lens = [total_length_s(resolve_windows(p, timing)) for p in parsed]
        order = sorted(range(len(parsed)), key=lambda i: -lens[i])
        parsed = [parsed[i] for i in order]
    caps = {}
    for n, e in zip(names, parsed):
        caps[n] = {"photodiode": "pd", "exposure": e if isinstance(e, str) else [list(w) for w in e],
                   "conversion_gain_v_per_e": cg, "voltage_swing_v": swing, "read_noise_e": v["read"]}
    name = v["name"] or Path(source).stem
    preset = {
        "name": name,
        "description": v["description"] or f"from EMVA 1288 results {Path(source).name}: K {v['K']:.4g} DN/e-, "
                                            f"dark noise {v['sigma_d']:.3g} e-, saturation {v['sat']:.5g} e-",
        "architecture": arch, "pixel_pitch_m": v["pixel_pitch_m"], "cfa": v["cfa"] or "GRBG", "adc_bits": bits,
        "black_level_dn": black, "saturation_fraction": 0.95,
        "spectral": {"filters": qe_ref or str(v["qe_path"]), "peak_qe": 1.0},
        "shot_noise_gaussian_above_e": 1000.0, "fpn_seed": 1288,
        "photodiodes": {"pd": {"fill_factor": 1.0, "full_well_e": v["sat"], "dark_current_e_per_s": v["dark"],
                               "dsnu_e": v["dsnu"], "prnu": v["prnu"]}},
        "captures": caps,
    }
    check = dict(preset, spectral={"filters": str(v["qe_path"]), "peak_qe": 1.0})
    preset_from_dict(check, source)
    return preset
