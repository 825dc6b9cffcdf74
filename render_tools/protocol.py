"""Benchmark protocols: a fixed, versioned list of scenes (seed + pinned conditions per split) and render
settings, as plain YAML files in ``render_tools/configs/protocols/`` (see docs/guide/protocols.md).

A protocol pins everything that decides the radiance corpus: the render options (a profile), the storage, the
scene generator (``generator``: 1, the default, for lfmbench-v1; 2 for lfmbench-v2, :data:`render_tools.scene.
GENERATORS`) and for every scene its id, split, seed and the conditions the scene generator must meet (time of
day, ego speed in m/s, vehicle kinds present ahead, traffic-signal state; generator 2: the weather). The conditions become generator overrides
(:func:`render_tools.scene.apply_overrides`), so a protocol's coverage holds by construction, whatever a seed
would have drawn. It also records the PWM distributions and the seed of the frozen test-split draws
(:mod:`lfmbench.datasets.pwm`), so a change of either is a new protocol version.

- :func:`list_protocols` -> names and paths of the shipped protocols.
- :func:`load_protocol` -> a validated :class:`Protocol` (``ValueError`` naming the file and the field).
- :func:`coverage` -> counts per time of day, vehicle kind, signal state and ego-speed bin of a split.
- :func:`check_scene` -> the ways a generated scene misses its pinned conditions (empty: none).

``lfmbench render --protocol NAME --out DIR`` renders a protocol; ``lfmbench protocols`` lists them.
"""
from __future__ import annotations

import copy
import hashlib
import json
import os
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Mapping

from lfmbench.limits import brief
from lfmbench.check import check_integer, check_keys, check_number, fail, scene_id_error
from lfmbench.vocabulary import VEHICLE_KINDS, WEATHERS

from .scene import GENERATORS, SIGNAL_STATES, TIMES_OF_DAY, apply_overrides, load_config

__all__ = ["PROTOCOL_FORMAT", "PROTOCOL_DIR", "SPLITS", "SPEED_BINS_MPS", "ProtocolScene", "Protocol",
           "list_protocols", "resolve_protocol", "load_protocol", "coverage", "coverage_table", "check_scene"]

#: ``format`` field of a protocol file.
PROTOCOL_FORMAT = "lfmbench-protocol"
#: Folder of the shipped protocols (``<name>.yaml``).
PROTOCOL_DIR = Path(__file__).with_name("configs") / "protocols"
#: Splits of a protocol, in file order.
SPLITS = ("train", "val", "test")
#: Signal values of a scene: a state of :data:`render_tools.scene.SIGNAL_STATES` or ``none`` (no signal).
SIGNALS = SIGNAL_STATES + ("none",)
#: Ego-speed bins of the coverage table, m/s: [lo, hi).
SPEED_BINS_MPS = ((0.0, 20.0), (20.0, 35.0), (35.0, 1000.0))
#: RenderOptions fields a protocol may not set: the Monte Carlo seed is the scene's seed, the Mitsuba variant
#: belongs to the machine (``--variant``), not to the protocol.
_NOT_IN_PROTOCOL = ("seed", "variant")
#: Generator keys the pinned conditions set; a scene's ``overrides`` may not set them too.
_PINNED_KEYS = (("camera", "speed_mps"), ("vehicles", "require_kinds"), ("lights", "signal_states"),
                ("weather", "conditions"))
_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9._-]{0,63}$")


@dataclass(frozen=True)
class ProtocolScene:
    """One scene of a protocol: id, split, generator seed and the pinned conditions.

    ``ego_speed_mps``: ego speed, m/s. ``vehicle_kinds``: kinds that must be among the moving vehicles ahead
    (parked cars are always there too). ``signal``: traffic-signal state or ``"none"``. ``overrides``: any other
    generator defaults changed for this scene (:func:`render_tools.scene.apply_overrides`). ``generator``: the
    scene generator of the protocol (1 or 2). ``weather``: road weather (generator 2 only; None for generator 1).
    """

    scene_id: str
    split: str
    seed: int
    time_of_day: str
    ego_speed_mps: float
    vehicle_kinds: tuple[str, ...]
    signal: str
    overrides: dict = field(default_factory=dict)
    generator: int = 1
    weather: str | None = None

    def generator_overrides(self) -> dict:
        """The overrides of :func:`render_tools.scene.generate_scene` that pin this scene's conditions."""
        out = copy.deepcopy(self.overrides)
        v = float(self.ego_speed_mps)
        out.setdefault("camera", {})["speed_mps"] = [v, v]
        out.setdefault("vehicles", {})["require_kinds"] = list(self.vehicle_kinds)
        out.setdefault("lights", {})["signal_states"] = [] if self.signal == "none" else [self.signal]
        if self.weather is not None:
            out.setdefault("weather", {})["conditions"] = [self.weather]
        return out

    def scene_kw(self) -> dict:
        """Keyword arguments of ``generate_scene(seed, scene_id=..., **scene_kw)`` (plain data, JSON-able; a
        generator-1 scene's have no ``generator`` key, as before generator 2 existed)."""
        kw = {"time_of_day": self.time_of_day, "overrides": self.generator_overrides()}
        if self.generator != 1:
            kw["generator"] = self.generator
        return kw


@dataclass(frozen=True)
class Protocol:
    """A loaded, validated protocol file.

    ``render``: RenderOptions fields (width / height px, spp, light_spp, bins, frames, ...). ``storage``: corpus
    radiance storage. ``pwm``: ``{"test_split_seed": int, "distributions": {...}}`` (the frozen test draws).
    ``sha256``: SHA-256 of the file's content as canonical JSON (sorted keys), so comments and layout do not
    change it but any value does. ``scenes``: all scenes, train then val then test.
    """

    name: str
    version: int
    description: str
    path: Path
    sha256: str
    render: dict
    storage: str
    pwm: dict
    coverage_rules: dict
    scenes: tuple[ProtocolScene, ...]
    generator: int = 1

    @property
    def splits(self) -> dict[str, list[str]]:
        """``{"train": [ids], "val": [ids], "test": [ids]}`` (sorted, as ``splits.json``)."""
        return {s: sorted(sc.scene_id for sc in self.scenes if sc.split == s) for s in SPLITS}

    def record(self) -> dict:
        """What a corpus records about its protocol (manifest ``render.protocol``, scene ``meta.json``)."""
        return {"name": self.name, "version": self.version, "sha256": self.sha256}


# ---------------------------------------------------------------------------------------------- loading
def list_protocols() -> dict[str, Path]:
    """Shipped protocols: ``{name: path}`` of every ``*.yaml`` in :data:`PROTOCOL_DIR`, sorted by name."""
    return {p.stem: p for p in sorted(PROTOCOL_DIR.glob("*.yaml"))}


def resolve_protocol(name_or_path: str | os.PathLike) -> Path:
    """Path of a protocol given by name (:func:`list_protocols`) or as a path to a YAML file."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") and p.is_file():
        return p
    known = list_protocols()
    if str(name_or_path) in known:
        return known[str(name_or_path)]
    raise ValueError(f"protocol: {brief(str(name_or_path))} is neither a protocol of {PROTOCOL_DIR} "
                     f"(known: {sorted(known)}) nor a YAML file")


def content_sha256(data: Any) -> str:
    """SHA-256 hex digest of ``data`` as canonical JSON (sorted keys, no spaces)."""
    return hashlib.sha256(json.dumps(data, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _render_fields() -> set[str]:
    from .render import RenderOptions  # noqa: PLC0415 - no Mitsuba import: plain dataclass

    return {f.name for f in fields(RenderOptions)} - set(_NOT_IN_PROTOCOL)


def _scene(entry: Any, split: str, i: int, src: str, cfg: dict, generator: int = 1) -> ProtocolScene:
    f = f"scenes.{split}[{i}]"
    check_keys(entry, f, src, required=("id", "seed", "time_of_day", "ego_speed_mps", "vehicle_kinds", "signal")
               + (("weather",) if generator >= 2 else ()), optional=("overrides",))
    why = scene_id_error(entry["id"])
    if why is not None:
        fail(f"{f}.id", why, src)
    seed = check_integer(entry["seed"], f"{f}.seed", src, lo=0)
    if entry["time_of_day"] not in TIMES_OF_DAY:
        fail(f"{f}.time_of_day", f"{brief(entry['time_of_day'])} is not one of {TIMES_OF_DAY}", src)
    speed = check_number(entry["ego_speed_mps"], f"{f}.ego_speed_mps", src, lo=0.0, hi=200.0)
    kinds = entry["vehicle_kinds"]
    if not isinstance(kinds, list) or any(k not in VEHICLE_KINDS for k in kinds) or len(set(kinds)) != len(kinds):
        fail(f"{f}.vehicle_kinds", f"must be a list of distinct kinds of {VEHICLE_KINDS}, got {brief(kinds)}", src)
    if entry["signal"] not in SIGNALS:
        fail(f"{f}.signal", f"{brief(entry['signal'])} is not one of {SIGNALS}", src)
    ov = entry.get("overrides") or {}
    if not isinstance(ov, Mapping):
        fail(f"{f}.overrides", f"must be a mapping of generator defaults, got {brief(ov)}", src)
    for a, b in _PINNED_KEYS:
        if b in (ov.get(a) or {}):
            fail(f"{f}.overrides", f"must not set {a}.{b}: the scene's pinned conditions set it", src)
    weather = entry.get("weather")
    if generator >= 2 and weather not in WEATHERS:
        fail(f"{f}.weather", f"{brief(weather)} is not one of {WEATHERS}", src)
    sc = ProtocolScene(str(entry["id"]), split, int(seed), entry["time_of_day"], float(speed), tuple(kinds),
                       entry["signal"], copy.deepcopy(dict(ov)), generator, weather)
    apply_overrides(cfg, sc.generator_overrides(), f"{src}: {f}")  # unknown keys, impossible values
    return sc


def load_protocol(name_or_path: str | os.PathLike) -> Protocol:
    """Load and validate a protocol (a name of :func:`list_protocols` or a YAML path).

    Raises ``ValueError`` starting with ``protocol file <path>`` and naming the field for malformed YAML, a
    missing or unknown key, an impossible value, duplicate scene ids or seeds, or a coverage rule of the file's
    ``coverage`` section that its scenes do not meet.
    """
    from lfmbench.fileio import load_yaml  # noqa: PLC0415

    path = resolve_protocol(name_or_path)
    src = f"protocol file {path}"
    try:
        data = load_yaml(path, source=src)
    except OSError as exc:
        raise ValueError(f"{src}: cannot read YAML: {exc.strerror or exc}") from None
    check_keys(data, "", src, required=("format", "name", "version", "render", "storage", "pwm", "coverage",
                                        "scenes"), optional=("description", "generator"))
    if data["format"] != PROTOCOL_FORMAT:
        fail("format", f"must be {brief(PROTOCOL_FORMAT)}, got {brief(data['format'])}", src)
    name = data["name"]
    if not isinstance(name, str) or not _NAME_RE.match(name):
        fail("name", f"must be lower-case letters, digits, '.', '_' or '-', got {brief(name)}", src)
    version = check_integer(data["version"], "version", src, lo=1)
    generator = data.get("generator", 1)
    if generator not in GENERATORS or isinstance(generator, bool):
        fail("generator", f"{brief(generator)} is not a scene generator of {GENERATORS}", src)
    render = data["render"]
    check_keys(render, "render", src, optional=sorted(_render_fields()))
    from .render import RenderOptions  # noqa: PLC0415

    try:
        RenderOptions(**render)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{src}: render: {exc}") from None
    from lfmbench.corpus import STORAGES  # noqa: PLC0415

    if data["storage"] not in STORAGES:
        fail("storage", f"{brief(data['storage'])} is not one of {sorted(STORAGES)}", src)
    pwm = data["pwm"]
    check_keys(pwm, "pwm", src, required=("test_split_seed", "distributions"))
    check_integer(pwm["test_split_seed"], "pwm.test_split_seed", src, lo=0)
    if not isinstance(pwm["distributions"], Mapping):
        fail("pwm.distributions", "must be a mapping (the content of lfmbench/configs/pwm.yaml)", src)
    check_keys(data["scenes"], "scenes", src, required=SPLITS)
    cfg = load_config(generator=generator)
    scenes: list[ProtocolScene] = []
    for split in SPLITS:
        entries = data["scenes"][split]
        if not isinstance(entries, list):
            fail(f"scenes.{split}", f"must be a list of scenes, got {type(entries).__name__}", src)
        scenes += [_scene(e, split, i, src, cfg, generator) for i, e in enumerate(entries)]
    if not any(s.split == "test" for s in scenes):
        fail("scenes.test", "must hold at least one scene", src)
    seen_id: dict[str, str] = {}
    seen_seed: dict[int, str] = {}
    for s in scenes:
        if s.scene_id in seen_id:
            fail("scenes", f"scene id {brief(s.scene_id)} appears twice ({seen_id[s.scene_id]} and {s.split})", src)
        if s.seed in seen_seed:
            fail("scenes", f"seed {s.seed} is used by {brief(seen_seed[s.seed])} and {brief(s.scene_id)} "
                           "(one seed, one scene: no scene may appear in two splits)", src)
        seen_id[s.scene_id], seen_seed[s.seed] = s.split, s.scene_id
    proto = Protocol(name, int(version), str(data.get("description", "")), path, content_sha256(data),
                     dict(render), data["storage"], copy.deepcopy(pwm), copy.deepcopy(data["coverage"]),
                     tuple(scenes), int(generator))
    _check_coverage(proto, src)
    return proto


# --------------------------------------------------------------------------------------------- coverage
def _bin_label(lo: float, hi: float) -> str:
    return f"{lo:g}-{hi:g}" if hi < 1000 else f">={lo:g}"


def coverage(protocol: Protocol, split: str = "test") -> dict:
    """Counts of the pinned conditions of ``split``'s scenes: ``{"scenes": n, "time_of_day": {name: n},
    "vehicle_kinds": {kind: scenes with it}, "signal": {state: n}, "ego_speed_mps": {bin: n}, "speed_range_mps":
    [min, max]}`` (speeds in m/s; bins :data:`SPEED_BINS_MPS`), and for a generator-2 protocol ``"weather":
    {condition: n}``."""
    sc = [s for s in protocol.scenes if s.split == split]
    speeds = [s.ego_speed_mps for s in sc]
    bins = {_bin_label(lo, hi): sum(lo <= v < hi for v in speeds) for lo, hi in SPEED_BINS_MPS}
    out = {"scenes": len(sc),
           "time_of_day": {t: sum(s.time_of_day == t for s in sc) for t in TIMES_OF_DAY},
           "vehicle_kinds": {k: sum(k in s.vehicle_kinds for s in sc) for k in VEHICLE_KINDS},
           "signal": {g: sum(s.signal == g for s in sc) for g in SIGNALS},
           "ego_speed_mps": bins,
           "speed_range_mps": [min(speeds), max(speeds)] if speeds else None}
    if protocol.generator >= 2:
        out["weather"] = {w: sum(s.weather == w for s in sc) for w in WEATHERS}
    return out


def _check_coverage(p: Protocol, src: str) -> None:
    rules = p.coverage_rules
    check_keys(rules, "coverage", src, optional=SPLITS)
    for split, r in rules.items():
        f = f"coverage.{split}"
        check_keys(r, f, src, optional=("min_scenes", "times_of_day", "vehicle_kinds", "signals",
                                        "ego_speed_range_mps") + (("weathers",) if p.generator >= 2 else ()))
        cov = coverage(p, split)
        if cov["scenes"] < check_integer(r.get("min_scenes", 0), f"{f}.min_scenes", src):
            fail(f"{f}.min_scenes", f"needs {r['min_scenes']} scenes, the split has {cov['scenes']}", src)
        for key, have in (("times_of_day", cov["time_of_day"]), ("vehicle_kinds", cov["vehicle_kinds"]),
                          ("signals", cov["signal"]), ("weathers", cov.get("weather", {}))):
            want = r.get(key, [])
            if not isinstance(want, list) or any(w not in have for w in want):
                fail(f"{f}.{key}", f"must be a list of {sorted(have)}, got {brief(want)}", src)
            missing = [w for w in want if not have[w]]
            if missing:
                fail(f"{f}.{key}", f"no {split} scene has {missing}", src)
        if "ego_speed_range_mps" in r:
            lo, hi = r["ego_speed_range_mps"]
            got = cov["speed_range_mps"] or [None, None]
            if got[0] is None or got[0] > lo or got[1] < hi:
                fail(f"{f}.ego_speed_range_mps", f"the {split} speeds must reach {lo} and {hi} m/s, they span "
                                                 f"{got} m/s", src)


def coverage_table(protocol: Protocol, split: str = "test") -> str:
    """Markdown table of :func:`coverage` (one row per condition)."""
    cov = coverage(protocol, split)
    rows = [("time of day", cov["time_of_day"]), ("vehicle kinds ahead (scenes with)", cov["vehicle_kinds"]),
            ("traffic signal", cov["signal"]), ("ego speed, m/s", cov["ego_speed_mps"])]
    if "weather" in cov:
        rows.append(("weather", cov["weather"]))
    lines = [f"{protocol.name} v{protocol.version}, {split} split: {cov['scenes']} scenes, ego speeds "
             f"{cov['speed_range_mps'][0]:g}-{cov['speed_range_mps'][1]:g} m/s", "",
             "| condition | counts |", "|---|---|"]
    for name, d in rows:
        lines.append(f"| {name} | " + ", ".join(f"{k} {v}" for k, v in d.items()) + " |")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------ scene check
def check_scene(scene: Mapping[str, Any], ps: ProtocolScene, config: dict | None = None) -> list[str]:
    """The pinned conditions of ``ps`` that the generated ``scene`` (a scene dict) does not meet; empty when
    it meets all: time of day, camera speed (m/s, to 1e-9), vehicle kinds among the moving objects, the
    signal state (lit signal lamps: red, amber, green) or no signal, the weather (generator 2). ``config``: the
    generator defaults the scene was made with (default: :func:`render_tools.scene.load_config` of the scene's
    generator)."""
    bad = []
    if ps.weather is not None and scene.get("weather", "dry") != ps.weather:
        bad.append(f"weather {scene.get('weather', 'dry')} != {ps.weather}")
    if scene["time_of_day"] != ps.time_of_day:
        bad.append(f"time_of_day {scene['time_of_day']} != {ps.time_of_day}")
    if abs(scene["camera"]["speed_mps"] - ps.ego_speed_mps) > 1e-9:
        bad.append(f"ego speed {scene['camera']['speed_mps']} != {ps.ego_speed_mps} m/s")
    moving = {o["kind"] for o in scene["objects"] if any(v != 0 for v in o["velocity_mps"])}
    for k in ps.vehicle_kinds:
        if k not in moving:
            bad.append(f"no moving {k}")
    cfg = load_config(generator=ps.generator) if config is None else config
    lc = apply_overrides(cfg, ps.generator_overrides())["lights"]
    colours = {"red": lc["led_red"], "amber": lc["led_amber"], "green": lc["led_green"]}
    lit = {next((c for c, spec in colours.items() if lt["spectrum"] == spec), "?")
           for lt in scene["lights"] if lt["kind"] == "signal"}
    has_pole = any(o["kind"] == "signal_pole" for o in scene["objects"])
    want = {"none": set(), "red": {"red"}, "amber": {"amber"}, "green": {"green"},
            "red_amber": {"red", "amber"}}[ps.signal]
    if lit != want or has_pole != (ps.signal != "none"):
        bad.append(f"signal lamps {sorted(lit)} (pole: {has_pole}) != {ps.signal}")
    return bad
