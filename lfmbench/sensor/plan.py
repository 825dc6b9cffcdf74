r"""Capture plans: which photodiode each capture reads, over which time windows, with which readout, and the
registry of sensor architectures (``SensorPreset.architecture``).

A capture's *exposure* is one or more time windows relative to the frame start (a chopped exposure is one
capture integrating the union of its sub-windows), or the name of a window the corpus stores (``"short"``: the
short exposure centred in the long one; ``"long"``: ``[0, T_L)``; docs/guide/contracts.md), resolved against a scene's
``meta.json`` timing by :func:`resolve_windows`. Captures that read the same photodiode over the same windows read
the same collected charge (dual conversion gain: split-pixel LPD-HCG/LCG, LOFIC); captures of one photodiode over
different windows are separate integrations, which must not overlap in time (one photodiode holds one charge).

Readout: ``global`` (every row integrates the same windows) or ``rolling`` (row y's windows start
``y * line_time_s`` later; ``line_time_s`` of the capture, else of the preset, else the corpus's).

The registry :data:`ARCHITECTURE_REGISTRY` (:data:`ARCHITECTURES`, its read-only mapping view): one :class:`Architecture` entry per sensor architecture (its structural rule, the capture
used as the ground-truth reference by default, its standard HDR merge baseline). Adding an architecture is one
``ARCHITECTURE_REGISTRY.register`` call plus its preset YAML.

References
----------
.. [Solhusvik2019] J. Solhusvik et al., "A 1280x960 2.8 um HDR CIS with DCG and Split-Pixel Combined", IISW 2019.
.. [Sakano2020] Y. Sakano et al., "A 132dB Single-Exposure-Dynamic-Range CMOS Image Sensor with High Temperature
   Tolerance", ISSCC 2020 (LOFIC automotive sensor).
.. [Iida2018] S. Iida et al., "A 0.68e-rms Random-Noise 121dB Dynamic-Range Sub-pixel architecture CMOS Image Sensor
   with LED Flicker Mitigation", IEDM 2018.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

from lfmbench.check import check_choice, check_keys, check_number
from lfmbench.limits import brief
from lfmbench.registry import Registry

__all__ = ["CORPUS_WINDOWS", "SHUTTERS", "Readout", "Architecture", "ARCHITECTURES", "parse_exposure",
           "parse_readout", "resolve_windows", "exposure_groups", "check_plan", "windows_overlap",
           "CAPTURE_NAME_PATTERN", "RESERVED_KEYS", "MAX_WINDOWS", "total_length_s", "ARCHITECTURE_REGISTRY"]

#: Windows a corpus stores for its static groups, by name (docs/guide/corpus-format.md section 4).
CORPUS_WINDOWS = ("short", "long")
#: Readout modes.
SHUTTERS = ("global", "rolling")
#: Capture names become sample keys (``name``, ``name_e``): lower-case identifiers.
CAPTURE_NAME_PATTERN = r"[a-z][a-z0-9_]{0,31}"
#: Sample keys a capture may not take.
RESERVED_KEYS = frozenset({"gt", "saturated", "meta", "light_index", "depth", "gt_rgb"})
#: Most sub-windows of one capture (a chopped exposure; bounds the per-sample work a preset can ask for).
MAX_WINDOWS = 64


@dataclass(frozen=True)
class Readout:
    """How a capture is read out.

    Attributes:
        shutter: ``"global"`` or ``"rolling"`` (``None``: the dataset's ``shutter`` argument decides).
        line_time_s: rolling-shutter row delay in s (``None``: the dataset's or the corpus's).
    """

    shutter: str | None = None
    line_time_s: float | None = None


def parse_readout(raw: Any, field: str, source: str) -> Readout:
    """A ``readout`` mapping (``shutter``, ``line_time_s``) of a preset, checked; errors name ``field``."""
    if raw is None:
        return Readout()
    check_keys(raw, field, source, optional={"shutter", "line_time_s"})
    sh = raw.get("shutter")
    if sh is not None:
        check_choice(sh, f"{field}.shutter", SHUTTERS, source)
    lt = raw.get("line_time_s")
    if lt is not None:
        lt = check_number(lt, f"{field}.line_time_s", source, lo=0, hi=1e-3)
    return Readout(sh, lt)


def parse_exposure(raw: Any, field: str, source: str, frame_time_s: float | None = None):
    """A capture's ``exposure``: a corpus window name, or a list of ``[start_s, length_s]`` windows relative to the
    frame start (s), sorted, non-overlapping, inside ``[0, frame_time_s]`` when given.

    Returns:
        ``"short"`` / ``"long"``, or a tuple of ``(start_s, length_s)`` float pairs.

    Raises:
        ValueError: ``<source>: field '<field>' ...`` (unknown name, bad window, overlap, out of frame).
    """
    if isinstance(raw, str):
        check_choice(raw, field, CORPUS_WINDOWS, source)
        return raw
    if not isinstance(raw, (list, tuple)) or not raw:
        raise ValueError(f"{source}: field '{field}' must be 'short', 'long' or a list of [start_s, length_s] "
                         f"windows, got {brief(raw)}")
    if len(raw) > MAX_WINDOWS:
        raise ValueError(f"{source}: field '{field}' has {len(raw)} windows, at most {MAX_WINDOWS}")
    wins = []
    for i, w in enumerate(raw):
        if not isinstance(w, (list, tuple)) or len(w) != 2:
            raise ValueError(f"{source}: field '{field}[{i}]' must be [start_s, length_s], got {brief(w)}")
        a = check_number(w[0], f"{field}[{i}][0]", source, lo=0.0, hi=1.0)
        n = check_number(w[1], f"{field}[{i}][1]", source, lo=0.0, lo_open=True, hi=1.0)
        if frame_time_s is not None and a + n > frame_time_s * (1 + 1e-9):
            raise ValueError(f"{source}: field '{field}[{i}]' ends at {(a + n) * 1e3:.6g} ms, after the frame time "
                             f"frame_time_s = {frame_time_s * 1e3:.6g} ms (out of frame)")
        wins.append((a, n))
    for i in range(1, len(wins)):
        if wins[i][0] < wins[i - 1][0] + wins[i - 1][1] * (1 - 1e-12):
            raise ValueError(f"{source}: field '{field}[{i}]' starts at {wins[i][0] * 1e3:.6g} ms, before window "
                             f"{i - 1} ends ({(wins[i - 1][0] + wins[i - 1][1]) * 1e3:.6g} ms): windows must be "
                             "sorted and must not overlap")
    return tuple(wins)


def resolve_windows(exposure, timing: Mapping[str, Any]) -> tuple[tuple[float, float], ...]:
    """The ``(start_s, length_s)`` windows of an exposure for a scene's ``meta["timing"]`` (s).

    ``"short"``: ``((T_L - T_S) / 2, T_S)`` (centred in the long window); ``"long"``: ``((0, T_L),)``; explicit
    windows unchanged. Same expressions as :func:`lfmbench.datasets.assembly.window_starts`.
    """
    if isinstance(exposure, str):
        ts, tl = float(timing["short_exposure_s"]), float(timing["long_exposure_s"])
        return (((tl - ts) / 2.0, ts),) if exposure == "short" else ((0.0, tl),)
    return tuple((float(a), float(n)) for a, n in exposure)


def windows_overlap(a: Sequence[tuple[float, float]], b: Sequence[tuple[float, float]]) -> bool:
    """Whether two window lists share any time (s); touching ends do not overlap."""
    return any(min(s0 + n0, s1 + n1) - max(s0, s1) > 1e-12 * max(n0, n1) for s0, n0 in a for s1, n1 in b)


def exposure_groups(captures: Mapping[str, Any]) -> dict[str, tuple[str, ...]]:
    """Captures grouped by the charge they read: ``{exposure key: (capture names)}`` in plan order. The key is
    the first capture's name; captures with the same photodiode and the same exposure share a key."""
    out: dict[str, list[str]] = {}
    seen: dict[tuple, str] = {}
    for name, spec in captures.items():
        k = (spec.photodiode, spec.exposure)
        if k not in seen:
            seen[k] = name
            out[name] = []
        out[seen[k]].append(name)
    return {k: tuple(v) for k, v in out.items()}


# ------------------------------------------------------------------------------------------------ registry
@dataclass(frozen=True)
class Architecture:
    """One sensor architecture.

    Attributes:
        name: its name (``SensorPreset.architecture``).
        description: one line.
        check: ``check(photodiodes, captures) -> str | None``: why a plan does not have this architecture's
            structure (None: it does).
        reference: the capture whose photodiode and windows define the ground truth by default.
        baseline: the registered fusion baseline that is this architecture's standard HDR merge.
        others: further registered rule-based baselines that apply (the capture-plan ones; the split pixel's are
            all of the rule baselines of :data:`lfmbench.baselines.REGISTRY`).
    """

    name: str
    description: str
    check: Callable[[Mapping[str, Any], Mapping[str, Any]], str | None]
    reference: Callable[[Mapping[str, Any]], str]
    baseline: str
    others: tuple[str, ...] = ()


def _one_pd(pds, caps) -> str | None:
    if len(pds) != 1:
        return f"needs exactly one photodiode, got {sorted(pds)}"
    return None


def _gains_descending(caps) -> str | None:
    """Captures of one charge (same photodiode, same windows) are listed highest conversion gain first."""
    for key, names in exposure_groups(caps).items():
        cgs = [caps[n].conversion_gain_v_per_e for n in names]
        if any(b >= a for a, b in zip(cgs, cgs[1:])):
            return (f"captures {list(names)} read one charge and must be listed highest conversion gain first, "
                    f"got conversion_gain_v_per_e {cgs}")
    return None


def _split_pixel(pds, caps) -> str | None:
    if set(pds) != {"lpd", "spd"} or list(caps) != ["lpd_hcg", "lpd_lcg", "spd"]:
        return ("needs photodiodes lpd and spd and the captures lpd_hcg, lpd_lcg, spd in this order, got "
                f"photodiodes {sorted(pds)} and captures {list(caps)} (any other photodiodes, reads or windows: "
                "architecture 'multi_photodiode')")
    if caps["lpd_hcg"].photodiode != "lpd" or caps["lpd_lcg"].photodiode != "lpd" or caps["spd"].photodiode != "spd":
        return "lpd_hcg and lpd_lcg must read photodiode 'lpd' and spd must read photodiode 'spd'"
    if caps["lpd_hcg"].exposure != caps["lpd_lcg"].exposure:
        return "lpd_hcg and lpd_lcg read the same charge and need the same exposure"
    # the split pixel's dataset path composes the corpus's stored windows (docs/guide/contracts.md): anything else
    # would be accepted and not simulated, so it is refused here (architecture 'multi_photodiode' honours it)
    for cap, want in (("lpd_hcg", "short"), ("lpd_lcg", "short"), ("spd", "long")):
        if caps[cap].exposure != want:
            return (f"reads the corpus's windows (lpd: 'short', spd: 'long'); capture {cap} asks for "
                    f"{caps[cap].exposure!r:.80}: give explicit windows with architecture 'multi_photodiode'")
    return None


def _multi_photodiode(pds, caps) -> str | None:
    if len({c.photodiode for c in caps.values()}) != len(pds):
        return f"reads every photodiode: photodiodes {sorted(pds)}, read {sorted({c.photodiode for c in caps.values()})}"
    return _gains_descending(caps)


def _lofic(pds, caps) -> str | None:
    bad = _one_pd(pds, caps)
    if bad:
        return bad
    if not 2 <= len(caps) <= 3 or len({c.exposure for c in caps.values()}) != 1:
        return f"needs 2-3 captures (conversion gains, highest first) of one exposure, got {list(caps)}"
    cgs = [c.conversion_gain_v_per_e for c in caps.values()]
    if any(b >= a for a, b in zip(cgs, cgs[1:])):
        return ("the captures are the reads of one charge, the high-conversion-gain read first: "
                f"conversion_gain_v_per_e must decrease, got {cgs}")
    return None


def _staggered(pds, caps) -> str | None:
    bad = _one_pd(pds, caps)
    if bad:
        return bad
    groups = exposure_groups(caps)
    if not 2 <= len(groups) <= 4 or any(isinstance(c.exposure, str) or len(c.exposure) != 1 for c in caps.values()):
        return (f"needs 2-4 exposures with one explicit window each (an exposure may be read at several conversion "
                f"gains), got {list(caps)}")
    lens = [caps[k].exposure[0][1] for k in groups]
    if any(b >= a for a, b in zip(lens, lens[1:])):
        return f"exposures must be listed longest exposure first, got lengths {lens} s"
    return _gains_descending(caps)


def _chopped(pds, caps) -> str | None:
    bad = _one_pd(pds, caps)
    if bad:
        return bad
    if not any(not isinstance(c.exposure, str) and len(c.exposure) >= 2 for c in caps.values()):
        return "needs at least one capture whose exposure is two or more sub-windows"
    return None


def _single(pds, caps) -> str | None:
    bad = _one_pd(pds, caps)
    if bad:
        return bad
    if len(caps) != 1:
        return f"needs exactly one capture, got {list(caps)}"
    c = next(iter(caps.values()))
    if not isinstance(c.exposure, str) and len(c.exposure) != 1:
        return "its capture needs one window"
    return None


def _first(caps) -> str:
    return next(iter(caps))


#: The registry of sensor architectures (``SensorPreset.architecture``): adding one is one ``register`` call.
ARCHITECTURE_REGISTRY = Registry("sensor architecture")
for _a in (
    Architecture("split_pixel", "large (LPD) and small (SPD) photodiode, LPD read at two conversion gains",
                 _split_pixel, lambda caps: "lpd_hcg", "saturated_exposure_corrected"),
    Architecture("lofic", "one photodiode with a lateral overflow capacitor, read at 2-3 conversion gains",
                 _lofic, _first, "exposure_select"),
    Architecture("staggered", "2-4 sequential exposures of one photodiode (DOL), each read at one or more "
                 "conversion gains, line-interleaved readout", _staggered, _first, "exposure_select",
                 ("exposure_select_bounded",)),
    Architecture("chopped", "one photodiode integrating a union of sub-windows spread over the frame",
                 _chopped, _first, "exposure_select"),
    Architecture("single", "one conventional exposure of one photodiode", _single, _first, "exposure_select"),
    Architecture("multi_photodiode", "any number of photodiodes (sub-pixels), each read at one or more conversion "
                 "gains over its own windows (IMX490: two photodiodes x two gains; a split pixel beside a very "
                 "short exposure)", _multi_photodiode, _first, "exposure_select"),
):
    ARCHITECTURE_REGISTRY.register(_a.name, _a)


class _RegistryView(Mapping):
    """Read-only mapping view of a :class:`lfmbench.registry.Registry` (``ARCHITECTURES[name]``, ``.items()``)."""

    def __init__(self, registry: Registry) -> None:
        self._r = registry

    def __getitem__(self, name):
        if name not in self._r:
            raise KeyError(name)
        return self._r.get(name)

    def __iter__(self):
        return iter(self._r)

    def __len__(self) -> int:
        return len(self._r.names())


#: The sensor architectures by name (``SensorPreset.architecture``), a read-only view of the registry.
ARCHITECTURES: Mapping[str, Architecture] = _RegistryView(ARCHITECTURE_REGISTRY)


def check_plan(architecture: str, photodiodes: Mapping[str, Any], captures: Mapping[str, Any], source: str) -> None:
    """The plan-wide rules (errors ``<source>: field '...' ...``): a known architecture whose structure the plan
    has, capture names usable as sample keys, and no two integrations of one photodiode overlapping in time."""
    check_choice(architecture, "architecture", list(ARCHITECTURES), source)
    for name in captures:
        if not re.fullmatch(CAPTURE_NAME_PATTERN, str(name)) or name in RESERVED_KEYS or str(name).endswith("_e"):
            raise ValueError(f"{source}: field 'captures.{str(name)[:40]}': a capture name must match "
                             f"{CAPTURE_NAME_PATTERN}, not end in '_e' and not be one of {sorted(RESERVED_KEYS)}")
    why = ARCHITECTURES[architecture].check(photodiodes, captures)
    if why:
        raise ValueError(f"{source}: field 'captures': architecture '{architecture}' {why}")
    groups = list(exposure_groups(captures).items())
    for pd in {c.photodiode for c in captures.values()}:   # a named window's time is the scene's: not comparable
        mine = [k for k, _ in groups if captures[k].photodiode == pd]
        named = [k for k in mine if isinstance(captures[k].exposure, str)]
        if len(mine) > 1 and named:
            raise ValueError(f"{source}: field 'captures.{named[0]}.exposure': photodiode '{pd}' has {len(mine)} "
                             "integrations; give each explicit [start_s, length_s] windows (a corpus window's time "
                             "is the scene's, so its overlap with the others could not be checked)")
    for i, (ka, _) in enumerate(groups):
        for kb, _ in groups[i + 1:]:
            a, b = captures[ka], captures[kb]
            if a.photodiode != b.photodiode or isinstance(a.exposure, str) or isinstance(b.exposure, str):
                continue
            if windows_overlap(a.exposure, b.exposure):
                raise ValueError(f"{source}: field 'captures.{kb}.exposure' overlaps the exposure of capture "
                                 f"'{ka}' on the same photodiode '{a.photodiode}' (one photodiode holds one "
                                 "charge: give each integration its own time)")


def total_length_s(windows: Sequence[tuple[float, float]]) -> float:
    """Integration time (s) of a window list: the sum of the lengths."""
    return math.fsum(n for _, n in windows)
