r"""The bench's sensor model: a preset's capture plan reduced to what a flat PWM LED target needs.

A P2020-style flicker target is a uniform LED patch of luminance :math:`\ell` (cd/m^2) while ON, PWM-driven
(frequency :math:`f = 1/T`, duty :math:`D`), over a constant background :math:`b` (cd/m^2). The region of
interest (ROI) is a span of ``roi_rows`` sensor rows (default one row) of whole CFA cells.

For capture :math:`c` (windows :math:`[a_j, a_j + n_j)` relative to the frame start, s; total integration time
:math:`L_c = \sum_j n_j`) and an LED whose rising edges fall at :math:`\varphi + kT` (the *phase*
:math:`\varphi\in[0, T)`, s, measured from the frame start), the captured ON fraction is

.. math:: f_c(\varphi) = \frac{1}{R\,L_c}\sum_{r=0}^{R-1}\sum_j \Phi(a_j + r\,t_d - \varphi,\ n_j,\ T,\ D)

with :math:`\Phi` the exact PWM exposure of :func:`lfmbench.flicker.pwm_exposure` (ISET-LFM eq. 1, ON time in
s of a unit pulse), :math:`R` the rows of the ROI and :math:`t_d` the line time (0 for a global shutter; row r
of a rolling shutter starts :math:`r t_d` later, ISET-LFM eq. 4). The mean photo-electrons of the capture's
photodiode are :math:`\mu_c = k_c (\ell f_c + b) L_c + I_{dark} L_c` with :math:`k_c` (e- s^-1 per cd m^-2)
from the preset's spectral response, fill factor, pixel area and lens (:func:`luminance_rate`).

Noise-free read-out (the preset's chain without noise and without quantisation, :mod:`lfmbench.sensor.noise`):
clip at :math:`\min(\text{full well}, \text{swing}/\text{CG})`, saturation flag where
:math:`\mu_c \ge \text{saturation\_fraction}\cdot\text{swing}/\text{CG}`, input-referred value
:math:`(\min(\mu_c, \text{clip}) - I_{dark}L_c)\,(FF_{ref}/FF_c)(L_{ref}/L_c)` in electrons of the reference
capture (the ``gt`` units of ``docs/guide/contracts.md``); the flicker-free ground truth of every capture is then
:math:`k_{ref}(\ell D + b)L_{ref}`.

The model is read from the plan's public API only (captures in plan order, each with its photodiode and
windows), so every architecture of :data:`lfmbench.sensor.plan.ARCHITECTURES` works, and so will new ones.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from lfmbench.sensor import load_preset
from lfmbench.sensor.plan import resolve_windows, total_length_s, windows_overlap

__all__ = ["BenchError", "CaptureModel", "SensorModel", "build_model", "luminance_rate", "preset_sha256",
           "DEFAULT_SHORT_EXPOSURE_S", "DEFAULT_LONG_EXPOSURE_S", "DEFAULT_LINE_TIME_S", "MAX_ROI_ROWS",
           "MIN_FREQUENCY_HZ", "MAX_FREQUENCY_HZ"]

#: The corpus windows ``short`` / ``long`` when no scene timing is given (s): the ISET-LFM split pixel's 5 ms
#: LPD and 1/90 s SPD exposures (the paper's Fig. 3).
DEFAULT_SHORT_EXPOSURE_S = 5e-3
DEFAULT_LONG_EXPOSURE_S = 1.0 / 90.0
#: Rolling-shutter line time when neither the preset nor the command gives one (s).
DEFAULT_LINE_TIME_S = 10e-6
#: Most rows in the ROI (the work grows with the rows of a rolling-shutter ROI).
MAX_ROI_ROWS = 64
#: The PWM periods the flicker model is validated for, 1 us to 1 s (:func:`lfmbench.flicker.pwm_exposure`), as
#: frequencies (Hz).
MIN_FREQUENCY_HZ = 1.0
MAX_FREQUENCY_HZ = 1.0e6


#: CIE 1924 photopic luminous efficiency V(lambda) at 400, 410, ..., 700 nm (1), the values of colour-science's
#: ``SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"]`` (CIE 018:2019 / ISO 23539:2005 table), held here
#: because importing colour-science also imports its plotting package (about 1 s of CPU, a tenth of the bench's
#: 10 s target); tests/flicker_bench compares them with colour-science.
CIE1924_V_400_700_10NM = (0.000396, 0.00121, 0.004, 0.0116, 0.023, 0.038, 0.06, 0.09098, 0.13902, 0.20802, 0.323,
                          0.503, 0.71, 0.862, 0.954, 0.9949501, 0.995, 0.952, 0.87, 0.757, 0.631, 0.503, 0.381,
                          0.265, 0.175, 0.107, 0.061, 0.032, 0.017, 0.00821, 0.004102)


class BenchError(ValueError):
    """Bad bench input; the message is one line naming the argument or the file and field."""


@dataclass(frozen=True)
class CaptureModel:
    """One capture of the plan as the bench sees it.

    Attributes:
        name: capture name (plan order).
        group: exposure key (captures reading the same charge share it).
        photodiode: photodiode name.
        starts_s, lengths_s, weights: (W,) window starts (s, frame time), lengths (s) and weights (1/R per row
            copy of a rolling-shutter ROI of R rows).
        length_s: integration time of one row, :math:`L_c` (s).
        rate: :math:`k_c L_c`, mean e- per cd/m^2 of steady light over the capture.
        dark_e: mean dark electrons :math:`I_{dark} L_c` (e-).
        clip_e: electrons where the capture clips (e-).
        sat_e: electrons from which the saturated flag is set (e-; inf when it never is).
        refer: factor from the capture's electrons to the reference units, :math:`(FF_{ref}/FF_c)(L_{ref}/L_c)`.
    """

    name: str
    group: str
    photodiode: str
    starts_s: np.ndarray
    lengths_s: np.ndarray
    weights: np.ndarray
    length_s: float
    rate: float
    dark_e: float
    clip_e: float
    sat_e: float
    refer: float

    @property
    def end_s(self) -> float:
        """Where the capture's last window of the last ROI row ends (s after the frame start)."""
        return float(np.max(self.starts_s + self.lengths_s))


@dataclass(frozen=True)
class SensorModel:
    """A preset's captures for the bench, plus the settings they were built with.

    Attributes:
        preset: the :class:`lfmbench.sensor.SensorPreset`.
        captures: :class:`CaptureModel` per capture, plan order.
        gt_rate: e- (reference units) per cd/m^2 of steady light: the ground truth is ``gt_rate * (l D + b)``.
        frame_time_s: frame period (s).
        settings: the options (exposures, line time, rows, background) as plain data.
        preset_sha256: :func:`preset_sha256` of the preset.
    """

    preset: Any
    captures: tuple[CaptureModel, ...]
    gt_rate: float
    frame_time_s: float
    settings: Mapping[str, Any] = field(default_factory=dict)
    preset_sha256: str = ""

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.captures]

    def saturation_luminance(self) -> dict[str, float]:
        """Per capture, the steady luminance (cd/m^2, background included) at which it reaches its saturation
        flag (its clip where it is never flagged)."""
        out = {}
        for c in self.captures:
            lim = min(c.sat_e, c.clip_e)
            out[c.name] = max(lim - c.dark_e, 0.0) / c.rate
        return out


def grid_cells(freqs_hz: Sequence[float], duties: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """The cells of a frequency x duty map, frequency-major (cell ``i * len(duties) + j`` is frequency ``i``, duty
    ``j``): their frequencies (C,) Hz and duties (C,), float64. The one cell order of the exact, noise and
    sequence maps."""
    f = np.repeat(np.asarray(freqs_hz, np.float64), len(duties))
    d = np.tile(np.asarray(duties, np.float64), len(freqs_hz))
    return f, d


def preset_sha256(preset) -> str:
    """SHA-256 of a preset: of its file's bytes when it was read from one, else of its canonical JSON."""
    src = getattr(preset, "source", "<dict>")
    try:
        with open(src, "rb") as fh:
            return hashlib.sha256(fh.read()).hexdigest()
    except OSError:
        pass
    from dataclasses import asdict

    d = asdict(preset)
    return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()


def luminance_rate(preset, photodiode: str) -> float:
    r"""Mean photo-electrons per second per cd/m^2 of an equal-energy white target, for one photodiode.

    .. math:: k = \frac{\pi\,\tau}{4N^2(1+m)^2}\;\frac{\overline{\sum_\lambda w_{c,\lambda} S(\lambda)}}
              {683\ \mathrm{lm/W}\ \sum_\lambda V(\lambda) S(\lambda)\,\Delta\lambda}

    camera equation (:func:`lfmbench.sensor.optics.radiance_to_irradiance`), :math:`w_{c,\lambda}` the e- per
    J m^-2 nm^-1 of :func:`lfmbench.sensor.electron_weights` averaged over the 2x2 CFA cell (the ROI mean over whole
    cells), :math:`S` flat over 400-700 nm (10 nm bands), :math:`V` the CIE 1924 photopic luminous efficiency
    (:data:`CIE1924_V_400_700_10NM`), 683 lm/W the SI luminous efficacy. The lens's PSF is left out: the target is larger than it.

    Returns:
        k in e- s^-1 per cd m^-2.
    """
    import torch

    from lfmbench.constants import LUMINOUS_EFFICACY_KCD_LM_PER_W
    from lfmbench.sensor import electron_weights
    from lfmbench.sensor.optics import radiance_to_irradiance

    wl = np.arange(400.0, 701.0, 10.0)
    vl = np.asarray(CIE1924_V_400_700_10NM)
    lum_per_unit = LUMINOUS_EFFICACY_KCD_LM_PER_W * float(np.sum(vl * 10.0))  # cd/m^2 per W sr^-1 m^-2 nm^-1
    o = preset.optics
    irr = float(radiance_to_irradiance(torch.ones(1, 1, 1, 1, dtype=torch.float64), o.f_number, o.transmittance,
                                       o.magnification))
    w = electron_weights(preset, wl, photodiode).numpy()            # (3, C) e- per J m^-2 nm^-1
    cell = preset.cfa.cell().reshape(-1).numpy()                   # the 4 channels of the 2x2 cell
    per_unit = float(np.mean([w[k].sum() for k in cell])) * irr    # e- per s per unit flat radiance
    return per_unit / lum_per_unit


def _num(x: Any, name: str, lo: float | None = None, lo_open: bool = False, hi: float | None = None) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise BenchError(f"{name} must be a number, got {str(x)[:40]!r}") from None
    if not math.isfinite(v) or (lo is not None and (v < lo or (lo_open and v == lo))) or (hi is not None and v > hi):
        rng = f"{'(' if lo_open else '['}{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
        raise BenchError(f"{name} must be a finite number in {rng}, got {x!r}")
    return v


def build_model(sensor, *, short_exposure_s: float | None = None, long_exposure_s: float | None = None,
                exposures: Mapping[str, Sequence[Sequence[float]]] | None = None, fps: float | None = None,
                line_time_s: float | None = None, roi_rows: int = 1, background_cd_m2: float = 1.0) -> SensorModel:
    """The bench model of a preset (name, YAML path or :class:`lfmbench.sensor.SensorPreset`).

    Args:
        sensor: the preset.
        short_exposure_s, long_exposure_s: the corpus windows ``short`` / ``long`` (s) for captures that name
            them (default 5 ms and 1/90 s); the short one is centred in the long one, as in the corpus.
        exposures: ``{capture: [[start_s, length_s], ...]}`` overriding a capture's windows (s).
        fps: frame rate (1/s); default ``1 / preset.frame_time_s``, else 30.
        line_time_s: rolling-shutter line time (s); default the capture's or preset's, else 10 us.
        roi_rows: rows of the ROI (1 to :data:`MAX_ROI_ROWS`); under a rolling shutter each row is one more
            shifted copy of the windows, all of equal weight.
        background_cd_m2: the target's background luminance (cd/m^2), the light-OFF level of the FDI.

    Raises:
        BenchError: one line naming the argument (``--fps``, ``--exposure``, ...).
    """
    try:
        preset = load_preset(sensor)
    except ValueError as exc:
        raise BenchError(f"--sensor: {exc}") from None
    ts = _num(DEFAULT_SHORT_EXPOSURE_S if short_exposure_s is None else short_exposure_s, "--short-exposure",
              0.0, True, 1.0)
    tl = _num(DEFAULT_LONG_EXPOSURE_S if long_exposure_s is None else long_exposure_s, "--long-exposure",
              0.0, True, 1.0)
    if ts > tl:
        raise BenchError(f"--short-exposure ({ts:g} s) must not be longer than --long-exposure ({tl:g} s)")
    if not isinstance(roi_rows, (int, np.integer)) or not 1 <= roi_rows <= MAX_ROI_ROWS:
        raise BenchError(f"--roi-rows must be an integer in [1, {MAX_ROI_ROWS}], got {roi_rows!r}")
    bg = _num(background_cd_m2, "--background", 0.0, False, 1e9)
    timing = {"short_exposure_s": ts, "long_exposure_s": tl}
    exposures = dict(exposures or {})
    unknown = sorted(set(exposures) - set(preset.captures))
    if unknown:
        raise BenchError(f"--exposure: no capture {unknown[0]!r} in preset {preset.name!r} (captures: "
                         f"{list(preset.captures)})")
    wins: dict[str, tuple[tuple[float, float], ...]] = {}
    for name, spec in preset.captures.items():
        if name in exposures:
            raw = exposures[name]
            if not raw:
                raise BenchError(f"--exposure {name}: give at least one START:LENGTH window")
            w = tuple((_num(a, f"--exposure {name} start", 0.0, False, 1.0),
                       _num(n, f"--exposure {name} length", 0.0, True, 1.0)) for a, n in raw)
            for i in range(1, len(w)):
                if w[i][0] < w[i - 1][0] + w[i - 1][1]:
                    raise BenchError(f"--exposure {name}: windows must be sorted and must not overlap")
        else:
            w = resolve_windows(spec.exposure, timing)
        wins[name] = w
    # captures of one photodiode group must keep reading the same charge: an override moves the whole group
    groups = preset.exposures
    key_of = {c: k for k, cs in groups.items() for c in cs}
    for k, cs in groups.items():
        if len({wins[c] for c in cs}) > 1:
            raise BenchError(f"--exposure: captures {list(cs)} read the same charge and need the same windows")
    keys = list(groups)
    for i, ka in enumerate(keys):
        for kb in keys[i + 1:]:
            if preset.captures[ka].photodiode == preset.captures[kb].photodiode and windows_overlap(wins[ka], wins[kb]):
                raise BenchError(f"--exposure: the windows of capture '{kb}' overlap those of '{ka}' on the same "
                                 f"photodiode '{preset.captures[ka].photodiode}' (one photodiode holds one charge)")
    if fps is None:
        frame_time = preset.frame_time_s if preset.frame_time_s else 1.0 / 30.0
    else:
        frame_time = 1.0 / _num(fps, "--fps", 0.0, True, 1e6)
    plan_end = 0.0
    rates: dict[str, float] = {}
    caps = []
    line_times: dict[str, float] = {}
    ref = preset.reference
    ref_spec = preset.captures[ref]
    ref_len = total_length_s(wins[ref])
    for name, spec in preset.captures.items():
        ro = preset.capture_readout(name)
        rolling = ro.shutter == "rolling"
        lt = 0.0
        if rolling:
            lt = line_time_s if line_time_s is not None else (ro.line_time_s if ro.line_time_s is not None
                                                               else DEFAULT_LINE_TIME_S)
            lt = _num(lt, "--line-time", 0.0, False, 1e-3)
        line_times[name] = lt
        rows = np.arange(roi_rows, dtype=np.float64) * lt
        a = np.array([s for s, _ in wins[name]], dtype=np.float64)
        n = np.array([x for _, x in wins[name]], dtype=np.float64)
        starts = (a[None, :] + rows[:, None]).reshape(-1)
        lengths = np.broadcast_to(n[None, :], (roi_rows, n.size)).reshape(-1).copy()
        weights = np.full(starts.size, 1.0 / roi_rows)
        pd = spec.photodiode
        if pd not in rates:
            rates[pd] = luminance_rate(preset, pd)
        length = total_length_s(wins[name])
        pds = preset.photodiodes[pd]
        clip = preset.saturation_capacity_e(name)
        sat_v = preset.saturation_fraction * spec.voltage_swing_v
        sat = sat_v / spec.conversion_gain_v_per_e
        if min(pds.full_well_e, spec.voltage_swing_v / spec.conversion_gain_v_per_e) * spec.conversion_gain_v_per_e \
                < sat_v:
            sat = math.inf
        refer = (preset.photodiodes[ref_spec.photodiode].fill_factor / pds.fill_factor) * (ref_len / length)
        caps.append(CaptureModel(name, key_of[name], pd, starts, lengths, weights, length, rates[pd] * length,
                                 pds.dark_current_e_per_s * length, clip, sat, refer))
        plan_end = max(plan_end, float(np.max(a + n)))
    if frame_time < plan_end * (1 - 1e-12):
        raise BenchError(f"--fps: the frame time {frame_time * 1e3:.6g} ms is shorter than the exposure plan of "
                         f"{preset.name!r}, which ends {plan_end * 1e3:.6g} ms after the frame start")
    gt_rate = rates[ref_spec.photodiode] * ref_len
    settings = {"short_exposure_s": ts, "long_exposure_s": tl, "frame_time_s": frame_time, "roi_rows": int(roi_rows),
                "background_cd_m2": bg, "windows_s": {k: [list(w) for w in v] for k, v in wins.items()},
                "line_time_s": line_times}
    return SensorModel(preset, tuple(caps), gt_rate, frame_time, settings, preset_sha256(preset))
