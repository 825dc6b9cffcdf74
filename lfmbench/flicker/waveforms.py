r"""Emission waveforms of the flickering light kinds beyond a plain PWM lamp, each with its exposure integral in
closed form: indicators, emergency strobes, multiplexed LED message signs and bus destination displays, and the
countdown digits of traffic signals.

Defines
-------
- :data:`WAVEFORMS`: the registry, waveform kind -> class (one entry per kind); :func:`waveform_from_dict` reads
  the ``waveform`` object of a scene light (or of a ``meta.json`` light) into one, with errors naming the field.
- Each waveform ``w`` has ``w.exposure(start, length, period, duty, phase)`` (the radiant exposure
  :math:`\int_{t_s}^{t_s+t_e} I(t)\,dt`, level x s), ``w.mean_exposure(start, length, duty)`` (the same with the
  carrier replaced by its mean: the flicker-free ground truth), ``w.level(t, period, duty, phase)`` (the
  instantaneous level, for plots and brute-force checks) and ``w.to_dict()``.
- :func:`gated_pwm_exposure`: the closed form every gated kind uses; :class:`GateTable`: a gated waveform as
  numbers (:meth:`GatedWaveform.table`), whose ``exposure`` and ``mean_exposure`` are the waveform's own, for one
  light (numpy) or for a batch of lights of different kinds (torch tensors of one row per light, any device: the
  batched and device paths of :mod:`lfmbench.datasets`); :func:`scan_row_pwm`: a multiplexed row's PWM.

Model
-----
A waveform is a *gate* :math:`g(t) \in \{0, 1\}` times a *carrier* :math:`p(t)` of unit ON level:

- The **gate** is what the light is meant to show and what a camera should reproduce: an indicator's 1-2 Hz
  blink, a strobe's flash pattern, a countdown digit's segment switching every second, a destination display's
  pages. It is periodic with period :math:`T_g` (s), ON on the intervals :math:`[s_i, e_i) \subset [0, T_g)`
  (sorted, disjoint; adjacent ones merged), shifted by the waveform's ``phase_s`` (s): ON on
  :math:`[\text{phase\_s} + kT_g + s_i,\ \text{phase\_s} + kT_g + e_i)`. The gate is fixed by the scene.
- The **carrier** is the flicker an LFM method must remove: the LED driver's PWM (period :math:`T`, duty
  :math:`D`, ``phase`` :math:`\varphi`: the time of a rising edge, s) or a display's multiplexed scan. Its
  parameters are drawn by the dataset like any PWM light's (:mod:`lfmbench.datasets.pwm`). In a gated kind the
  driver's PWM is enabled by the gate, so it **restarts at each ON interval's onset**: rising edges at
  :math:`\text{onset} + \varphi + mT`, :math:`\varphi \in [0, T)`. (This is what makes the exposure exact in
  closed form for any window: every ON interval of the gate carries the same pulse train.)

Multiplexed displays (LED message signs, destination displays): the pixel matrix is driven row by row; with a
1/N scan (``scan_lines`` N) the rows of scan line :math:`l = y \bmod N` are driven during slot :math:`l` of every
refresh period :math:`T` and dark otherwise, and ON for the fraction :math:`D` of their slot. Row :math:`y` is a
PWM of period :math:`T`, duty :math:`D/N` and rising edges at :math:`\varphi + lT/N + mT`: a PWM per row with a
phase offset, so different rows are ON at different times and a short exposure shows some rows lit and others
dark.

Exposure of a gated waveform (the window :math:`[t_s, t_s + t_e)`, gate time :math:`u = t - \text{phase\_s}`):
split :math:`t_e = nT_g + r` (:math:`n` whole gate periods, each contributing :math:`W = \sum_i
\Phi_{PWM}(0, e_i - s_i)`) and the remainder :math:`[a, a + r)`, :math:`a = u_s \bmod T_g`, which lies in
:math:`[0, 2T_g)` and meets at most the intervals of gate periods 0 and 1:

.. math:: \Phi = nW + \sum_{k \in \{0, 1\}} \sum_i \Phi_{PWM}\big(\max(a - s_i - kT_g, 0) - \varphi,\
          |[a, a + r) \cap [s_i + kT_g, e_i + kT_g)|\big)

with :math:`\Phi_{PWM}` the exact PWM exposure of :func:`lfmbench.flicker.pwm_exposure`. No loop over the
window's length: a window of :math:`10^6` gate periods costs what one of a millisecond does. The flicker-free
exposure is the same sum with :math:`\Phi_{PWM}(\cdot, d) = D d`.

All times in s, levels relative to the lamp's ON level (1 = the luminance of the scene light, cd m^-2, while
the LED is ON). numpy float64, or torch tensors (float64 for the dataset paths) on any device: the same
operations in the same order (:class:`lfmbench.flicker.exact._Ops`), so a batch of lights on the CPU gets each
light's numpy numbers up to the last bits of float64.

References
----------
- UN ECE Regulation No. 48, para. 6.5.7 (and Regulation No. 6): direction indicators flash at 90 +- 30 flashes
  per minute, i.e. 1-2 Hz.
- A. Jam et al., "ISET-LFM: A Physics-based Simulation Framework and Dataset for LED Flicker in Automotive
  Imaging" (the PWM model and its exposure integral, eq. 1).
- Row-multiplexed LED matrix driving (1/N scan): e.g. Texas Instruments, "LED display multiplexing" application
  notes for the TLC59xx / TLC6C5xxx drivers; a multiplexed display is a PWM per scan line with phase offsets.

Size (about 540 lines): one job, the one definition of each gated waveform (the per-sample, batched and
device paths all call it); one class per light kind and their shared gate table.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from types import MappingProxyType
from typing import Any, ClassVar, Mapping, NamedTuple

import numpy as np

from lfmbench.check import check_integer, check_keys, check_number, fail
from lfmbench.flicker import pwm_exposure, pwm_level
from lfmbench.flicker.args import _as_tensors, _is_tensor, _is_torch
from lfmbench.flicker.exact import _mod_period, _Ops
from lfmbench.limits import brief

__all__ = ["WAVEFORMS", "SEVEN_SEGMENTS", "Waveform", "PWM", "ScanRow", "GatedWaveform",
           "Indicator", "Strobe", "CountdownSegment", "DestinationRow", "GateTable", "gated_pwm_exposure",
           "fit_ramps", "scan_row_pwm", "waveform_from_dict"]

#: Segments lit per decimal digit on a seven-segment display (segments a-g clockwise from the top, g the middle).
SEVEN_SEGMENTS: Mapping[int, str] = MappingProxyType({0: "abcdef", 1: "bc", 2: "abdeg", 3: "abcdg", 4: "bcfg",
                                                      5: "acdfg", 6: "acdefg", 7: "abc", 8: "abcdefg", 9: "abcdfg"})


def _arrays(*xs):
    return [np.asarray(x, dtype=np.float64) for x in xs]


def _floats(*xs):
    """``(arrays, ops)``: the arguments as float64 numpy arrays, or, when any is a torch tensor, as tensors of one
    dtype on its device (:func:`lfmbench.flicker.args._as_tensors`); ``ops`` the matching array functions."""
    if _is_torch(*xs):
        return _as_tensors(*xs), _Ops(True)
    return [np.asarray(x, dtype=np.float64) for x in xs], _Ops(False)


def _zero_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and x == 0


def _mod(x, period):
    """``x mod period`` in [0, period) (numpy or torch; :func:`lfmbench.flicker.exact._mod_period`)."""
    (x, period), ops = _floats(x, period)
    return _mod_period(x, period, ops)


def fit_ramps(period, duty, rise, fall):
    """Rise and fall times (s) scaled down together where their ramps would overlap in a PWM of ``period`` (s) and
    ``duty``: ``(rise + fall) / 2 <= min(duty, 1 - duty) * period`` (the rule of
    :func:`lfmbench.datasets.pwm.pwm_record`, here for a carrier whose duty a waveform changes). numpy or torch
    (broadcasting); with tensors, ramps given as the number 0 are returned as they are (ideal pulses: no tensor
    is made, so :func:`lfmbench.flicker.pwm_exposure` need not read one back from the device)."""
    if _is_torch(period, duty, rise, fall) and _zero_number(rise) and _zero_number(fall):
        return rise, fall
    (period, duty, rise, fall), ops = _floats(period, duty, rise, fall)
    room = 2.0 * ops.minimum(duty, 1.0 - duty) * period
    total = rise + fall
    one = 1.0 + 0.0 * total
    scale = ops.where(total > room, room / ops.where(total > 0, total, one), one)
    return rise * scale, fall * scale


def scan_row_pwm(period, duty, phase, scan_lines, line):
    r"""The PWM of scan line ``line`` of a 1/N-scan display (``scan_lines`` N) driven by a carrier of period
    :math:`T` (s), duty :math:`D` and rising edges at ``phase`` (s): ``(T, D / N, phase + line * T / N)`` (module
    docstring). Array-agnostic (numbers, numpy or torch, broadcasting); N = 1, line = 0 is the carrier itself."""
    return period, duty / scan_lines, phase + line * period / scan_lines


def gated_pwm_exposure(start, length, gate_period, on, period, duty, phase, rise=0.0, fall=0.0, *,
                       mean: bool = False):
    r"""Exposure of a PWM enabled by a periodic gate, restarting at each ON interval's onset (module docstring).

    Args:
        start: window start in gate time (s; the gate's period begins at 0), any shape broadcasting with the rest.
        length: window length :math:`t_e \ge 0` (s).
        gate_period: :math:`T_g > 0` (s), a number or an array broadcasting with ``start`` (one per light).
        on: (..., M, 2) ON intervals ``[s_i, e_i)`` of one gate period (s), ``0 <= s_i <= e_i <= gate_period``,
            sorted, disjoint; leading axes, if any, broadcast with ``start`` (one set per light; empty intervals
            ``[0, 0)`` pad a set to M and add nothing).
        period, duty, phase: the carrier PWM: period :math:`T > 0` (s), duty :math:`D \in [0, 1]`, rising edges at
            ``onset + phase + m T`` (s). rise, fall: its ramp times (s, :func:`lfmbench.flicker.pwm_exposure`;
            scaled by :func:`fit_ramps` where they would overlap).
        mean: the flicker-free exposure (carrier at its mean level :math:`D`).

    Returns:
        :math:`\Phi` (level x s), the broadcast shape of the inputs: float64 numpy, or a tensor when any input is
        one (on its device, in its floating dtype).
    """
    rise, fall = fit_ramps(period, duty, rise, fall)
    (start, length, Tg, on, period, duty, phase), ops = _floats(start, length, gate_period, on, period, duty, phase)
    if on.ndim < 2:
        on = on.reshape(-1, 2)
    s, e = on[..., 0], on[..., 1]                      # (..., M) s
    a = _mod_period(start, Tg, ops)[..., None]         # (..., 1) s
    r = ops.fmod(length, Tg)
    n = ops.round((length - r) / Tg)                   # whole gate periods (an integer value)
    r = r[..., None]
    T, D, ph, Tg1 = period[..., None], duty[..., None], phase[..., None], Tg[..., None]
    tr, tf = (x if _zero_number(x) else x[..., None] for x in (rise, fall))

    def carrier(since, dur):                           # exposure of the restarted PWM over [since, since + dur)
        if mean:
            return D * dur
        return pwm_exposure(since - ph, dur, T, D, rise_time=tr, fall_time=tf, check=False)

    zero = 0.0 * a
    whole = carrier(0.0 * s, e - s).sum(-1)            # W: one gate period
    part = 0.0
    for k in (0.0, Tg1):
        # |[a, a + r) & [s + k, e + k)| from differences to a, so a window inside an interval keeps its exact r
        since = a - (s + k)
        dur = ops.maximum(ops.minimum(r, (e + k) - a) - ops.maximum(-since, zero), zero)
        part = part + carrier(ops.maximum(since, zero), dur).sum(-1)
    out = n * whole + part
    return out if _is_tensor(out) else np.asarray(out)


class GateTable(NamedTuple):
    """A gated waveform as numbers (:meth:`GatedWaveform.table`): what its exposure needs besides the carrier's
    draw. For one light the fields are numbers and ``on`` an (M, 2) array; for a batch of lights each field is an
    array with one entry per light, shaped to broadcast with the windows (e.g. (G, 1, 1)), and ``on`` (G, 1, 1, M,
    2), numpy or torch. :meth:`exposure` and :meth:`mean_exposure` are the waveform's (its methods call them)."""

    period_s: Any       #: gate period T_g (s)
    phase_s: Any        #: the gate's ``phase_s`` (s): its periods start there
    scan_lines: Any     #: N of a multiplexed carrier (1: the plain PWM)
    line: Any           #: the row's scan line (0 for N = 1)
    on: Any             #: (..., M, 2) ON intervals of one gate period (s)

    def exposure(self, start, length, period, duty, phase, rise=0.0, fall=0.0):
        """Radiant exposure (level x s) over ``[start, start + length)`` (s, waveform time) for the carrier's draw:
        period (s), duty, phase (s, a rising edge after each ON onset), ramp times (s). Arrays broadcast."""
        start = start if _is_tensor(start) else np.asarray(start, dtype=np.float64)
        T, D, ph = scan_row_pwm(period, duty, phase, self.scan_lines, self.line)
        return gated_pwm_exposure(start - self.phase_s, length, self.period_s, self.on, T, D, ph, rise, fall)

    def mean_exposure(self, start, length, duty):
        """Flicker-free exposure (level x s): the gate with the carrier at its mean level."""
        start = start if _is_tensor(start) else np.asarray(start, dtype=np.float64)
        T, D, ph = scan_row_pwm(1.0, duty, 0.0, self.scan_lines, self.line)
        return gated_pwm_exposure(start - self.phase_s, length, self.period_s, self.on, T, D, ph, mean=True)


def _gate_level(t, gate_period: float, on: np.ndarray, period, duty, phase, rise=0.0, fall=0.0, *,
                mean: bool = False) -> np.ndarray:
    """Instantaneous level of the gated PWM at gate time ``t`` (s): (broadcast shape)."""
    t, period, duty, phase = _arrays(t, period, duty, phase)
    rise, fall = fit_ramps(period, duty, rise, fall)
    on = np.asarray(on, dtype=np.float64).reshape(-1, 2)
    u = _mod(t, float(gate_period))[..., None]
    inside = (u >= on[:, 0]) & (u < on[:, 1])          # (..., M)
    if mean:
        lv = np.broadcast_to(duty[..., None], inside.shape)
    else:
        lv = pwm_level(u - on[:, 0] - phase[..., None], period[..., None], duty[..., None],
                       rise_time=rise[..., None], fall_time=fall[..., None])
    return np.where(inside, lv, 0.0).sum(-1)


# ----------------------------------------------------------------------------------------------------------
# the waveform kinds
# ----------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Waveform:
    """Base of the waveform kinds: the fields of a kind are its dataclass fields (the keys of its ``waveform``
    object besides ``kind``); ``_FIELDS`` gives each field's check: ``(lo, hi, integer)`` for a number, a tuple of
    names for a choice."""

    kind: ClassVar[str] = ""
    _FIELDS: ClassVar[dict] = {}

    @classmethod
    def from_dict(cls, d: Any, field: str = "waveform", source: str | None = None) -> "Waveform":
        """Read and check a ``waveform`` object (``{"kind": ..., fields}``); errors name ``field.key`` and
        ``source``."""
        names = [f.name for f in fields(cls)]
        optional = [n for n in names if n in cls._defaults()]
        check_keys(d, field, source, required=["kind"] + [n for n in names if n not in optional],
                   optional=optional)
        vals = {}
        for n in names:
            if n not in d:
                continue
            rule = cls._FIELDS[n]
            if isinstance(rule[0], str):
                if d[n] not in rule:
                    fail(f"{field}.{n}", f"must be one of {list(rule)}, got {brief(d[n])}", source)
                vals[n] = d[n]
            elif rule[2]:
                vals[n] = check_integer(d[n], f"{field}.{n}", source, lo=rule[0], hi=rule[1])
            else:
                vals[n] = check_number(d[n], f"{field}.{n}", source, lo=rule[0], hi=rule[1])
        w = cls(**vals)
        why = w._consistency()
        if why is not None:
            fail(f"{field}.{why[0]}", why[1], source)
        return w

    @classmethod
    def _defaults(cls) -> dict:
        from dataclasses import MISSING  # noqa: PLC0415
        return {f.name: f.default for f in fields(cls) if f.default is not MISSING}

    def _consistency(self) -> tuple[str, str] | None:
        """(field, message) of a combination of fields that cannot be, else None."""
        return None

    def to_dict(self) -> dict:
        """The ``waveform`` object: ``{"kind": ..., field: value}`` (JSON types)."""
        return {"kind": self.kind, **{f.name: getattr(self, f.name) for f in fields(self)}}

    def mean_level(self, duty) -> np.ndarray:
        """Time-averaged level (1) for carrier duty ``duty``: the flicker-free level times the gate's ON share."""
        raise NotImplementedError

    def exposure(self, start, length, period, duty, phase, rise=0.0, fall=0.0) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def mean_exposure(self, start, length, duty) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def level(self, t, period, duty, phase, rise=0.0, fall=0.0) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError


@dataclass(frozen=True)
class PWM(Waveform):
    r"""A plain PWM lamp (headlights, tail and brake lamps, daytime-running lights, a signal's LED array): ON on
    :math:`[\varphi + mT, \varphi + mT + DT)`; the exposure is :func:`lfmbench.flicker.pwm_exposure`."""

    kind: ClassVar[str] = "pwm"

    def exposure(self, start, length, period, duty, phase, rise=0.0, fall=0.0):
        """Radiant exposure (level x s) over ``[start, start + length)`` (s); carrier period (s), duty, phase:
        a rising edge (s), ramp times (s, scaled by :func:`fit_ramps`). Arrays broadcast."""
        start, phase = _arrays(start, phase)
        rise, fall = fit_ramps(period, duty, rise, fall)
        return np.asarray(pwm_exposure(start - phase, length, period, duty, rise_time=rise, fall_time=fall,
                                       check=False))

    def mean_exposure(self, start, length, duty):
        """Flicker-free exposure (level x s): duty x length."""
        return np.asarray(np.asarray(duty, dtype=np.float64) * np.asarray(length, dtype=np.float64)
                          + 0.0 * np.asarray(start, dtype=np.float64))

    def level(self, t, period, duty, phase, rise=0.0, fall=0.0):
        """Level (1) at time ``t`` (s)."""
        t, phase = _arrays(t, phase)
        rise, fall = fit_ramps(period, duty, rise, fall)
        return np.asarray(pwm_level(t - phase, period, duty, rise_time=rise, fall_time=fall))

    def mean_level(self, duty):
        return np.asarray(duty, dtype=np.float64)


@dataclass(frozen=True)
class ScanRow(PWM):
    r"""One pixel row of a row-multiplexed LED message sign (kind ``message_sign``): a 1/N scan (``scan_lines``
    N) drives scan line ``line`` (= the row index mod N) during slot ``line`` of every refresh period :math:`T`.
    The carrier's duty :math:`D` is the row's ON share of its slot, so the row is a PWM of duty :math:`D/N`
    whose rising edges fall at :math:`\varphi + \text{line}\,T/N + mT` (module docstring)."""

    kind: ClassVar[str] = "scan_row"
    _FIELDS: ClassVar[dict] = {"scan_lines": (1, 64, True), "line": (0, 63, True)}
    scan_lines: int = 1
    line: int = 0

    def _consistency(self):
        if self.line >= self.scan_lines:
            return "line", f"must be < scan_lines = {self.scan_lines}, got {self.line}"
        return None

    def row_pwm(self, period, duty, phase):
        """The row's own PWM (period s, duty 1, phase s of a rising edge) for the sign's carrier."""
        return scan_row_pwm(*_arrays(period, duty, phase), self.scan_lines, self.line)

    def exposure(self, start, length, period, duty, phase, rise=0.0, fall=0.0):
        return super().exposure(start, length, *self.row_pwm(period, duty, phase), rise, fall)

    def mean_exposure(self, start, length, duty):
        return super().mean_exposure(start, length, np.asarray(duty, dtype=np.float64) / self.scan_lines)

    def level(self, t, period, duty, phase, rise=0.0, fall=0.0):
        return super().level(t, *self.row_pwm(period, duty, phase), rise, fall)

    def mean_level(self, duty):
        return np.asarray(duty, dtype=np.float64) / self.scan_lines


@dataclass(frozen=True)
class GatedWaveform(Waveform):
    """A carrier PWM enabled by a periodic gate (module docstring); a kind defines :meth:`gate` and, if its
    carrier is not the plain PWM, :meth:`carrier`."""

    def gate(self) -> tuple[float, np.ndarray]:  # pragma: no cover - abstract
        """(gate period T_g in s, (M, 2) ON intervals [s_i, e_i) in s within [0, T_g), sorted, disjoint)."""
        raise NotImplementedError

    def scan(self) -> tuple[int, int]:
        """(scan_lines N, line) of the carrier: (1, 0), the plain PWM, unless the kind multiplexes its rows."""
        return 1, 0

    def carrier(self, period, duty, phase):
        """The PWM under the gate (period s, duty 1, phase after the onset s) for the drawn carrier
        (:func:`scan_row_pwm` of :meth:`scan`)."""
        return scan_row_pwm(*_arrays(period, duty, phase), *self.scan())

    def table(self) -> GateTable:
        """The waveform as numbers (:class:`GateTable`); its exposures are this table's."""
        Tg, on = self.gate()
        return GateTable(float(Tg), float(self.phase_s), *self.scan(), on)

    def exposure(self, start, length, period, duty, phase, rise=0.0, fall=0.0):
        """Radiant exposure (level x s) over ``[start, start + length)`` (s, waveform time); carrier period (s),
        duty, phase (s, a rising edge after each ON onset), ramp times (s). Arrays broadcast."""
        return self.table().exposure(start, length, period, duty, phase, rise, fall)

    def mean_exposure(self, start, length, duty):
        """Flicker-free exposure (level x s): the gate with the carrier at its mean level."""
        return self.table().mean_exposure(start, length, duty)

    def level(self, t, period, duty, phase, rise=0.0, fall=0.0):
        """Level (1) at time ``t`` (s)."""
        Tg, on = self.gate()
        return _gate_level(np.asarray(t, dtype=np.float64) - self.phase_s, Tg, on,
                           *self.carrier(period, duty, phase), rise, fall)

    def mean_level(self, duty):
        Tg, on = self.gate()
        _, D, _ = self.carrier(1.0, duty, 0.0)
        return D * float((on[:, 1] - on[:, 0]).sum()) / Tg


def _merged(intervals: list[tuple[float, float]]) -> np.ndarray:
    """Sorted intervals with touching ones merged, (M, 2)."""
    out: list[list[float]] = []
    for s, e in sorted(intervals):
        if out and s <= out[-1][1]:
            out[-1][1] = max(out[-1][1], e)
        else:
            out.append([s, e])
    return np.array(out, dtype=np.float64).reshape(-1, 2)


@dataclass(frozen=True)
class Indicator(GatedWaveform):
    """A direction indicator (kind ``indicator``): blinking at ``frequency_hz`` (1-2 Hz, UN R48), ON for the share
    ``on_fraction`` of each blink period, the first onset at ``phase_s`` (s); PWM-driven while ON."""

    kind: ClassVar[str] = "indicator"
    _FIELDS: ClassVar[dict] = {"frequency_hz": (1.0, 2.0, False), "on_fraction": (0.05, 0.95, False),
                               "phase_s": (0.0, 1e6, False)}
    frequency_hz: float = 1.5
    on_fraction: float = 0.5
    phase_s: float = 0.0

    def gate(self):
        Tg = 1.0 / self.frequency_hz
        return Tg, np.array([[0.0, self.on_fraction * Tg]])


@dataclass(frozen=True)
class Strobe(GatedWaveform):
    """An emergency-vehicle strobe (kind ``strobe``): ``flashes`` flashes of ``flash_s`` (s) separated by
    ``gap_s`` (s) at the start of every ``cycle_s`` (s) (a double flash: 2, a triple flash: 3), the first at
    ``phase_s`` (s; the other side of a light bar: half a cycle later); PWM-driven inside each flash."""

    kind: ClassVar[str] = "strobe"
    _FIELDS: ClassVar[dict] = {"cycle_s": (0.05, 10.0, False), "flashes": (1, 16, True),
                               "flash_s": (1e-4, 1.0, False), "gap_s": (0.0, 1.0, False),
                               "phase_s": (0.0, 1e6, False)}
    cycle_s: float = 0.5
    flashes: int = 2
    flash_s: float = 0.04
    gap_s: float = 0.04
    phase_s: float = 0.0

    def _consistency(self):
        busy = self.flashes * self.flash_s + (self.flashes - 1) * self.gap_s
        if busy > self.cycle_s:
            return "cycle_s", (f"{self.flashes} flashes of {self.flash_s} s with gaps of {self.gap_s} s take "
                               f"{busy:.6g} s, longer than the cycle of {self.cycle_s} s")
        return None

    def gate(self):
        step = self.flash_s + self.gap_s
        return self.cycle_s, _merged([(i * step, i * step + self.flash_s) for i in range(self.flashes)])


@dataclass(frozen=True)
class CountdownSegment(GatedWaveform):
    """One segment of a traffic signal's countdown display (kind ``countdown``): the display counts
    ``count_from``, ``count_from - 1``, ..., 1, one number per ``tick_s`` (s), then stays dark for ``blank_s``
    (s), and repeats from ``phase_s`` (s); this light is segment ``segment`` (a-g, :data:`SEVEN_SEGMENTS`) of the
    ``place`` digit (a tens digit of 0 is blank). The segment's PWM runs while it stays lit."""

    kind: ClassVar[str] = "countdown"
    _FIELDS: ClassVar[dict] = {"count_from": (1, 99, True), "tick_s": (0.05, 10.0, False),
                               "blank_s": (0.0, 600.0, False), "place": ("units", "tens"),
                               "segment": tuple("abcdefg"), "phase_s": (0.0, 1e6, False)}
    count_from: int = 9
    tick_s: float = 1.0
    blank_s: float = 0.0
    place: str = "units"
    segment: str = "a"
    phase_s: float = 0.0

    def shown(self, value: int) -> bool:
        """Whether this segment is lit while the display shows ``value``."""
        digit = value % 10 if self.place == "units" else value // 10
        if self.place == "tens" and digit == 0:
            return False
        return self.segment in SEVEN_SEGMENTS[digit]

    def gate(self):
        Tg = self.count_from * self.tick_s + self.blank_s
        lit = [(k * self.tick_s, (k + 1) * self.tick_s) for k in range(self.count_from)
               if self.shown(self.count_from - k)]
        return Tg, _merged(lit)


@dataclass(frozen=True)
class DestinationRow(GatedWaveform):
    """One pixel row of a bus destination display (kind ``destination_display``): a row-multiplexed matrix like
    :class:`ScanRow` (``scan_lines``, ``line``) that shows ``pages`` texts in turn, ``page_s`` (s) each, from
    ``phase_s`` (s); this light is the row's lit pixels of page ``page``. The scan restarts with each page."""

    kind: ClassVar[str] = "destination_display"
    _FIELDS: ClassVar[dict] = {"scan_lines": (1, 64, True), "line": (0, 63, True), "pages": (1, 16, True),
                               "page": (0, 15, True), "page_s": (0.1, 60.0, False), "phase_s": (0.0, 1e6, False)}
    scan_lines: int = 1
    line: int = 0
    pages: int = 1
    page: int = 0
    page_s: float = 3.0
    phase_s: float = 0.0

    def _consistency(self):
        why = ScanRow(scan_lines=self.scan_lines, line=self.line)._consistency()
        if why is not None:
            return why
        if self.page >= self.pages:
            return "page", f"must be < pages = {self.pages}, got {self.page}"
        return None

    def gate(self):
        return self.pages * self.page_s, np.array([[self.page * self.page_s, (self.page + 1) * self.page_s]])

    def scan(self):
        return self.scan_lines, self.line


#: The waveform kinds: ``waveform.kind`` of a light -> its class (one entry per kind).
WAVEFORMS: Mapping[str, type] = MappingProxyType({c.kind: c for c in (PWM, ScanRow, Indicator, Strobe,
                                                                       CountdownSegment, DestinationRow)})


def waveform_from_dict(d: Any, field: str = "waveform", source: str | None = None) -> Waveform:
    """The waveform of a ``waveform`` object ``{"kind": <a key of WAVEFORMS>, ...}``; ``ValueError`` naming
    ``field`` (e.g. ``scene.lights[3].waveform.flashes``) and ``source`` for anything else.

    >>> waveform_from_dict({"kind": "strobe", "flashes": 3}).gate()[1].shape
    (3, 2)
    """
    if not isinstance(d, Mapping):
        fail(field, f"must be an object with a 'kind', got {brief(d)}", source)
    kind = d.get("kind")
    if kind not in WAVEFORMS:
        fail(f"{field}.kind", f"{brief(kind)} not one of {sorted(WAVEFORMS)}", source)
    return WAVEFORMS[kind].from_dict(d, field, source)
