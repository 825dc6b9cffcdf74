"""PWM parameter distributions: load, validate and draw (the one place they are defined).

The defaults live in ``lfmbench/configs/pwm.yaml`` (ISET-LFM: duty U[0.1, 0.5], frequency U[90, 120] Hz, phase
U[0, period)); a user passes a mapping or the path of an edited copy.

- :func:`load_pwm_config` -> :class:`PWMConfig` (the distributions);
- :func:`draw_pwm`: raw arrays for a list of lights;
- :func:`draw_scene_pwm` -> :class:`SceneDraw`: the PWM of every flickering light and group of a scene
  (:class:`PWMParams` records), the draw :class:`lfmbench.datasets.LFMCaptureDataset` and the benchmarks use;
- :data:`TEST_SPLIT_SEED`, :func:`frozen_test_rng`: the fixed streams the frozen test-split draws come from.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import torch

from lfmbench.limits import brief
from lfmbench.check import check_choice, check_keys, fail, where
from lfmbench.fileio import load_yaml

DEFAULT_PWM_PATH = Path(__file__).resolve().parents[1] / "configs" / "pwm.yaml"
_DISTS = ("uniform", "loguniform", "constant", "choice")
_KEYS = {"frequency_hz", "duty", "rise_time_s", "fall_time_s", "sync"}


@dataclass(frozen=True)
class Distribution:
    """One scalar distribution: ``uniform``/``loguniform`` on [low, high], ``constant`` or ``choice``."""

    dist: str
    low: float = 0.0
    high: float = 0.0
    values: tuple = ()

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Draw ``n`` values (float64)."""
        if self.dist == "uniform":
            return rng.uniform(self.low, self.high, n)
        if self.dist == "loguniform":
            return np.exp(rng.uniform(np.log(self.low), np.log(self.high), n))
        if self.dist == "constant":
            return np.full(n, self.low)
        return rng.choice(np.asarray(self.values, dtype=np.float64), n)

    def quantile(self, u):
        """The value at the uniform ``u`` in (0, 1) (the inverse CDF; numpy array or torch tensor, float64, any
        shape and device): what the counter-based draws (:mod:`lfmbench.datasets.counter_draws`) use. ``uniform``
        is ``low + (high - low) u``, the formula of ``numpy.random.Generator.uniform``."""
        lib = torch if torch.is_tensor(u) else np
        if self.dist == "uniform":
            return self.low + (self.high - self.low) * u
        if self.dist == "loguniform":
            lo, hi = np.log(self.low), np.log(self.high)
            return lib.exp(lo + (hi - lo) * u)
        if self.dist == "constant":
            return u * 0.0 + self.low
        vals = np.asarray(self.values, dtype=np.float64)
        n = len(vals)
        if lib is torch:
            i = (u * n).long().clamp(0, n - 1)
            return torch.as_tensor(vals, device=u.device)[i]
        return vals[np.minimum((u * n).astype(np.int64), n - 1)]

    def to_dict(self) -> dict:
        if self.dist == "constant":
            return {"dist": "constant", "value": self.low}
        if self.dist == "choice":
            return {"dist": "choice", "values": list(self.values)}
        return {"dist": self.dist, "low": self.low, "high": self.high}


def _dist(d: Any, key: str, source: str, lo: float, hi: float) -> Distribution:
    if not isinstance(d, Mapping) or d.get("dist") not in _DISTS:
        fail(key, f"must be a mapping with dist in {_DISTS}, got {brief(d)}", source)
    kind = d["dist"]
    try:
        if kind == "constant":
            vals = (float(d["value"]),)
            out = Distribution("constant", low=vals[0], high=vals[0])
        elif kind == "choice":
            vals = tuple(float(v) for v in d["values"])
            if not vals:
                raise ValueError
            out = Distribution("choice", values=vals)
        else:
            vals = (float(d["low"]), float(d["high"]))
            if not vals[0] <= vals[1] or (kind == "loguniform" and vals[0] <= 0):
                raise ValueError
            out = Distribution(kind, low=vals[0], high=vals[1])
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"{where(key, source)} has invalid parameters {brief(d)}") from None
    if not all(np.isfinite(v) and lo <= v <= hi for v in vals):
        fail(key, f"must stay within [{lo}, {hi}], got {brief(d)}", source)
    return out


@dataclass(frozen=True)
class PWMConfig:
    """PWM distributions. Frequencies in Hz, duty in [0, 1], rise/fall times in s; ``sync`` is ``"light"``
    (every LED its own draw) or ``"group"`` (one draw per light group, as upstream's Option B)."""

    frequency_hz: Distribution
    duty: Distribution
    rise_time_s: Distribution
    fall_time_s: Distribution
    sync: str = "light"

    def to_dict(self) -> dict:
        return {"frequency_hz": self.frequency_hz.to_dict(), "duty": self.duty.to_dict(),
                "rise_time_s": self.rise_time_s.to_dict(), "fall_time_s": self.fall_time_s.to_dict(),
                "sync": self.sync}


def load_pwm_config(pwm: "PWMConfig | Mapping | str | Path | None" = None) -> PWMConfig:
    """Load PWM distributions from a mapping, a YAML path, or the shipped defaults (``None``).

    A mapping may override some fields only; the rest come from the defaults.

    Raises:
        ValueError: unknown field or invalid distribution; the message names the field and the source.
    """
    if isinstance(pwm, PWMConfig):
        return pwm
    base = load_yaml(DEFAULT_PWM_PATH)
    source = str(DEFAULT_PWM_PATH)
    if isinstance(pwm, (str, Path)):
        path = Path(pwm)
        if not path.is_file():
            raise ValueError(f"pwm: no PWM config file at {path}")
        try:
            user = load_yaml(path)
        except OSError as exc:
            raise ValueError(f"pwm: cannot read {path}: {exc.strerror or exc}") from None
        source = str(path)
    elif pwm is None:
        user = {}
    elif isinstance(pwm, Mapping):
        user, source = dict(pwm), "pwm"
    else:
        raise ValueError(f"pwm must be None, a mapping, a YAML path or a PWMConfig, got {type(pwm).__name__}")
    if not isinstance(user, Mapping):
        raise ValueError(f"{source}: must hold a mapping of fields")
    check_keys(user, "", source, optional=_KEYS)
    cfg = {**base, **user}
    sync = cfg.get("sync", "light")
    check_choice(sync, "sync", ("light", "group"), source)
    return PWMConfig(frequency_hz=_dist(cfg["frequency_hz"], "frequency_hz", source, 1.0, 1e6),
                     duty=_dist(cfg["duty"], "duty", source, 0.0, 1.0),
                     rise_time_s=_dist(cfg["rise_time_s"], "rise_time_s", source, 0.0, 1.0),
                     fall_time_s=_dist(cfg["fall_time_s"], "fall_time_s", source, 0.0, 1.0),
                     sync=sync)


def draw_pwm(cfg: PWMConfig, rng: np.random.Generator, groups: list[str]) -> dict[str, np.ndarray]:
    """Draw PWM parameters for lights belonging to ``groups`` (one entry per light, in order).

    With ``sync == "group"`` lights of one group share a draw. Rise and fall times are clipped so the ramps
    never overlap (``lfmbench.flicker`` requires (t_r + t_f)/2 <= min(D, 1 - D) T).

    Returns:
        ``{"freq_hz": (L,), "period_s": (L,), "duty": (L,), "phase_s": (L,), "rise_s": (L,), "fall_s": (L,)}``;
        ``phase_s`` is the time (s) of a rising edge after the start of frame 0, in [0, period).
    """
    n = len(groups)
    if cfg.sync == "group":
        names = sorted(set(groups))
        idx = np.array([names.index(g) for g in groups], dtype=np.int64)
        m = len(names)
    else:
        idx, m = np.arange(n), n
    f = cfg.frequency_hz.sample(rng, m)[idx]
    d = cfg.duty.sample(rng, m)[idx]
    u = rng.uniform(0.0, 1.0, m)[idx]
    rise = cfg.rise_time_s.sample(rng, m)[idx]
    fall = cfg.fall_time_s.sample(rng, m)[idx]
    return pwm_record(f, d, u, rise, fall)


def pwm_record(f, d, u, rise, fall) -> dict:
    """The PWM fields from drawn frequency ``f`` (Hz), duty ``d`` (1), phase fraction ``u`` in [0, 1), rise and
    fall times (s): numpy arrays or torch tensors of one shape (the one rule both kinds of draws follow).

    Rise and fall are scaled down together where they would overlap: ``(rise + fall) / 2 <= min(d, 1 - d) T``.

    Returns:
        ``{"freq_hz", "period_s" (s), "duty", "phase_s" (s, in [0, T)), "rise_s" (s), "fall_s" (s)}``.
    """
    lib = torch if torch.is_tensor(f) else np
    T = 1.0 / f
    room = 2.0 * lib.minimum(d, 1.0 - d) * T
    total = rise + fall
    scale = lib.where(total > room, room / lib.where(total > 0, total, lib.ones_like(total)), lib.ones_like(total))
    return {"freq_hz": f, "period_s": T, "duty": d, "phase_s": u * T, "rise_s": rise * scale, "fall_s": fall * scale}


# ----------------------------------------------------------------------------------------------------------
# one scene's draw
# ----------------------------------------------------------------------------------------------------------
#: Keys of a PWM record in dicts and JSON (``test_params.json``), in this order.
PWM_KEYS = ("period_s", "duty", "phase_s", "rise_s", "fall_s", "freq_hz")


@dataclass(frozen=True)
class PWMParams:
    """The PWM waveform of one light or group: frequency ``freq_hz`` (Hz) = 1 / ``period_s`` (s), ``duty`` in
    [0, 1], ``phase_s`` (s): a rising edge after the start of frame 0, in [0, period), ramp times ``rise_s`` and
    ``fall_s`` (s; ``(rise_s + fall_s) / 2 <= min(duty, 1 - duty) * period_s``)."""

    period_s: float
    duty: float
    phase_s: float
    rise_s: float
    fall_s: float
    freq_hz: float

    def to_dict(self) -> dict[str, float]:
        """``{key: float}`` in :data:`PWM_KEYS` order (the form ``LFMCaptureDataset.simulate`` takes)."""
        return {k: float(getattr(self, k)) for k in PWM_KEYS}     # (not asdict: it deep-copies)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "PWMParams":
        return cls(**{k: float(d[k]) for k in PWM_KEYS})


@dataclass(frozen=True)
class SceneDraw:
    """One PWM draw for a scene: ``lights`` (light id -> :class:`PWMParams`, the flickering lights of the
    groups in use) and ``groups`` (flickering group name -> :class:`PWMParams`, used by groups stored without
    time bins, ``docs/guide/corpus-format.md`` section 4)."""

    lights: dict[int, PWMParams]
    groups: dict[str, PWMParams]

    def to_dicts(self) -> tuple[dict[int, dict[str, float]], dict[str, dict[str, float]]]:
        """``(per_light, per_group)`` plain dicts (``LFMCaptureDataset.simulate(params, group_params)``)."""
        return ({k: v.to_dict() for k, v in self.lights.items()}, {k: v.to_dict() for k, v in self.groups.items()})


def flicker_groups(meta: Mapping[str, Any], groups: Sequence[str] | None = None) -> list[str]:
    """Sorted names of the scene's flickering groups (``meta.json`` ``groups[g].flicker``), limited to
    ``groups`` when given."""
    return sorted(g for g, d in meta["groups"].items() if d.get("flicker") and (groups is None or g in groups))


def draw_scene_pwm(cfg: PWMConfig, meta: Mapping[str, Any], rng: np.random.Generator,
                   groups: Sequence[str] | None = None) -> SceneDraw:
    """Draw the PWM of every flickering light (sorted by id) and flickering group of a scene.

    One :func:`draw_pwm` call over the lights then the groups (that order fixes the random stream); with
    ``cfg.sync == "group"`` the lights of a group share the group's draw.

    Args:
        cfg: the distributions. meta: the scene's ``meta.json``. rng: the random stream.
        groups: groups in use (None: all the scene has).
    """
    fl = flicker_groups(meta, groups)
    lights = sorted((lt for lt in meta.get("lights", []) if lt["group"] in fl), key=lambda lt: int(lt["id"]))
    d = draw_pwm(cfg, rng, [lt["group"] for lt in lights] + fl)
    rec = [PWMParams(**{k: float(d[k][i]) for k in PWM_KEYS}) for i in range(len(lights) + len(fl))]
    n = len(lights)
    per_group = {g: rec[n + i] for i, g in enumerate(fl)}
    if cfg.sync == "group":  # lights of a group share the group's draw
        per_light = {int(lt["id"]): per_group[lt["group"]] for lt in lights}
    else:
        per_light = {int(lt["id"]): rec[i] for i, lt in enumerate(lights)}
    return apply_light_timing(SceneDraw(per_light, per_group), meta)


# ----------------------------------------------------------------------------------------------------------
# the timing of lamp clusters and LED displays (scene version 2: meta.json lights with driver / waveform)
# ----------------------------------------------------------------------------------------------------------
def has_light_timing(meta: Mapping[str, Any]) -> bool:
    """Whether any ``meta.json`` light states a ``driver`` or a ``waveform`` (scene version 2)."""
    return any("driver" in lt or "waveform" in lt for lt in meta.get("lights", []))


def light_waveforms(meta: Mapping[str, Any]) -> dict[int, Any]:
    """``{light id: waveform}`` (:mod:`lfmbench.flicker.waveforms`) of the ``meta.json`` lights that state one
    (scene version 2); a light without ``waveform`` is a plain PWM lamp and is left out."""
    from lfmbench.flicker.waveforms import waveform_from_dict  # noqa: PLC0415

    return {int(lt["id"]): waveform_from_dict(lt["waveform"], f"lights[{i}].waveform", "meta.json")
            for i, lt in enumerate(meta.get("lights", [])) if "waveform" in lt}


def gated_lights(meta: Mapping[str, Any]) -> dict[int, Any]:
    """The lights whose waveform has a gate (indicator, strobe, countdown, destination display): ``{id:
    waveform}``. Their exposure is not a PWM's alone, so the composition applies the waveform itself
    (:func:`lfmbench.datasets.assembly.compose_frame`)."""
    from lfmbench.flicker.waveforms import GatedWaveform  # noqa: PLC0415

    if not has_light_timing(meta):
        return {}
    return {k: w for k, w in light_waveforms(meta).items() if isinstance(w, GatedWaveform)}


def driver_sources(meta: Mapping[str, Any], light_ids) -> dict[int, int]:
    """``{light id: the light whose draw it takes}`` for the drawn lights ``light_ids``: a light with a ``driver``
    takes the draw of the driver's drawn light of lowest id; any other light its own (the rule of
    :func:`apply_light_timing`, also read by the device program, :mod:`lfmbench.datasets.device`)."""
    lights = {int(lt["id"]): lt for lt in meta.get("lights", [])}
    first: dict[str, int] = {}
    for lid in sorted(int(i) for i in light_ids):
        d = lights.get(lid, {}).get("driver")
        if d is not None:
            first.setdefault(d, lid)
    return {int(lid): first.get(lights.get(int(lid), {}).get("driver"), int(lid)) for lid in light_ids}


def scan_row_record(period, duty, phase, rise, fall, scan_lines, line):
    """The PWM record of a multiplexed display row (waveform ``scan_row``) from its sign's drawn carrier: period
    (s), duty ``D / N``, the row's rising edge ``phase + line * T / N`` reduced to [0, T) (s), ramps (s) scaled to
    fit the row's duty (:func:`lfmbench.flicker.waveforms.scan_row_pwm`, :func:`~lfmbench.flicker.waveforms.fit_ramps`).
    Array-agnostic (numbers, numpy, or torch tensors on any device: the device program applies it per light)."""
    from lfmbench.flicker.waveforms import _mod, fit_ramps, scan_row_pwm  # noqa: PLC0415

    T, D, ph = scan_row_pwm(period, duty, phase, scan_lines, line)
    rise, fall = fit_ramps(T, D, rise, fall)
    return T, D, _mod(ph, T), rise, fall


def apply_light_timing(draw: SceneDraw, meta: Mapping[str, Any]) -> SceneDraw:
    """The draw with the timing that ``meta.json`` states per light (identity for lights without ``driver`` and
    ``waveform``, e.g. every scene of protocol lfmbench-v1):

    - lights of one ``driver`` share one PWM: the draw of the driver's light of lowest id (the segments of a
      lamp, the rows of a message sign, the bars of a countdown display);
    - a multiplexed display row (waveform ``scan_row``) is its row's own PWM: duty ``D / N``, rising edges
      ``line * T / N`` after the sign's, ramps scaled to fit (:meth:`lfmbench.flicker.waveforms.ScanRow.row_pwm`),
      so every composition path applies it like any PWM light (:func:`scan_row_record`);
    - a gated waveform keeps its carrier's draw here; the composition applies the gate (:func:`gated_lights`).
    """
    from lfmbench.flicker.waveforms import ScanRow  # noqa: PLC0415

    if not has_light_timing(meta):
        return draw
    source = driver_sources(meta, draw.lights)
    wfs = light_waveforms(meta)
    out = {}
    for lid in draw.lights:
        p = draw.lights[source[lid]]
        w = wfs.get(lid)
        if isinstance(w, ScanRow):
            T, D, ph, rise, fall = (float(x) for x in scan_row_record(p.period_s, p.duty, p.phase_s, p.rise_s,
                                                                      p.fall_s, w.scan_lines, w.line))
            p = PWMParams(period_s=T, duty=D, phase_s=ph, rise_s=rise, fall_s=fall, freq_hz=p.freq_hz)
        out[lid] = p
    return SceneDraw(out, dict(draw.groups))


# ----------------------------------------------------------------------------------------------------------
# the frozen test split
# ----------------------------------------------------------------------------------------------------------
#: Seed of the test split's frozen draws (``<corpus>/test_params.json``): every entry ``<scene_id>/<sample>``
#: is drawn from ``(TEST_SPLIT_SEED, sample, scene id)`` alone, whatever the dataset's seed. Changing it changes
#: every test score of a corpus whose test_params.json is re-created.
TEST_SPLIT_SEED = 20261121


def frozen_test_rng(scene_id: str, sample: int, stream: int | None = None) -> np.random.Generator:
    """The random stream of test entry ``<scene_id>/<sample>``: ``stream=None`` for the PWM draw and noise seed,
    ``stream=1`` for the window start of ``frame_start="random"`` (added later without changing the first).

    The scene id enters as its first 8 UTF-8 bytes only, little-endian. Known limitation, kept so that new
    entries of existing corpora stay what they were: ids that share their first 8 bytes (``scene00000`` ..
    ``scene00099`` all start with ``scene000``) share the stream of a sample index.
    """
    sid_word = int.from_bytes(scene_id.encode()[:8].ljust(8, b"\0"), "little")
    key = [TEST_SPLIT_SEED, int(sample), sid_word] + ([] if stream is None else [int(stream)])
    return np.random.default_rng(key)
