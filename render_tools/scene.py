"""The procedural scene generator: a driving scene (plain, editable JSON, :mod:`render_tools.scene_schema`) from
a seed, built in steps from parts (:mod:`render_tools.scene_templates`).

Steps, in the order they draw from the scene's one random generator: :func:`add_road` (ground, road, markings,
sidewalks), :func:`add_buildings` (windows, billboards after dark), :func:`place_camera` (ego lane and speed),
:func:`add_vehicles` (ahead, oncoming, parked; :func:`add_vehicle` builds one from its template),
:func:`add_streetlights`, :func:`add_signal`, :func:`make_sky` and the camera. A new vehicle kind is a template
entry; a new scene element is a step.

World frame: ISO 8855, metres: x forward along the road, y left, z up; the road surface is z = 0. Traffic
drives on the right: the ego direction uses lanes at y < 0.

Generators (:data:`GENERATORS`): generator 1 is the street of protocol lfmbench-v1 and stays as it is (its scenes
are frozen: tests/render_tools/test_scene_v2.py); generator 2 (protocol lfmbench-v2) is where new content goes:
the steps of generator 1, then those of :mod:`render_tools.street` (weather, trees, road furniture, people) on
the defaults of ``scene_defaults.yaml`` merged with ``scene_generator_v2.yaml``; its scenes are scene version 2.

Functions
- :func:`load_config` -> generator defaults (``render_tools/configs/scene_defaults.yaml``, + the v2 file).
- :func:`generate_scene` -> a validated scene dict from a seed (day / dusk / night), of generator 1 or 2.
- The scene file itself (re-exported from :mod:`render_tools.scene_schema`): :func:`validate_scene`,
  :func:`scene_groups`, :func:`load_scene`, :func:`save_scene`, :func:`empty_scene`.

Luminance ranges follow upstream (ISETHDR heuristic of the ISET-LFM code, https://github.com/AyushJam/iset-lfm): headlights 2e4-2e5 cd/m^2,
streetlights 1e4-5e4 cd/m^2, other lights 4e-4..1e-2 of the scene's headlight peak.

Size (about 600 lines): one job, the generator's steps in the order they draw from the scene's random
generator; the parts the steps build from live in :mod:`render_tools.scene_templates` and :mod:`render_tools.street`.
"""
from __future__ import annotations

import copy
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from lfmbench.limits import brief
from lfmbench.vocabulary import GROUPS, LIGHT_KINDS, VEHICLE_KINDS, WEATHERS

from .scene_schema import (SCENE_FORMAT, SCENE_VERSION, TIMES_OF_DAY, empty_scene, load_scene, plain_json, save_scene,
                           scene_groups, validate_scene)
from .scene_templates import (BASE_MATERIALS, PARKED_KIND, VEHICLE_MATERIALS, VEHICLE_TEMPLATES, box, cylinder,
                              local_offset, rect)
from . import street
from .lamps import add_displays, add_vehicle_lamps

__all__ = ["DEFAULT_CONFIG", "V2_CONFIG", "GENERATORS", "SIGNAL_STATES", "load_config", "check_config", "apply_overrides", "SceneBuilder",
           "Road", "add_road", "add_buildings", "place_camera", "add_vehicles", "add_vehicle", "add_streetlights",
           "add_signal", "make_sky", "generate_scene",
           # the scene file (render_tools.scene_schema)
           "SCENE_FORMAT", "SCENE_VERSION", "TIMES_OF_DAY", "validate_scene", "scene_groups", "load_scene",
           "save_scene", "empty_scene"]

#: Default generator configuration file.
DEFAULT_CONFIG = Path(__file__).with_name("configs") / "scene_defaults.yaml"
#: What generator 2 changes and adds to :data:`DEFAULT_CONFIG` (merged key by key; new sections allowed).
V2_CONFIG = Path(__file__).with_name("configs") / "scene_generator_v2.yaml"
#: Scene generators: 1 (protocol lfmbench-v1, frozen) and 2 (lfmbench-v2: new content goes here).
GENERATORS = (1, 2)
#: Sections only generator 2 has (:data:`V2_CONFIG`).
V2_SECTIONS = ("weather", "trees", "furniture", "people", "lamps")


# ----------------------------------------------------------------------------------------------- config
def _read_yaml(p: Path) -> Any:
    from lfmbench.fileio import load_yaml  # noqa: PLC0415

    try:
        return load_yaml(p, source=f"config file {p}")
    except OSError as exc:
        raise ValueError(f"config file {p}: cannot read ({exc.strerror or exc})") from None


def _deep_merge(dst: dict, src: Mapping[str, Any]) -> dict:
    """``dst`` with ``src`` merged in key by key (new keys allowed; a non-mapping value replaces)."""
    for k, v in src.items():
        if isinstance(v, Mapping) and isinstance(dst.get(k), dict):
            _deep_merge(dst[k], v)
        else:
            dst[k] = copy.deepcopy(v)
    return dst


def load_config(path: str | os.PathLike | None = None, generator: int = 1) -> dict:
    """Generator defaults from YAML (default :data:`DEFAULT_CONFIG`); raises ``ValueError`` naming the file.
    ``generator`` 2: the file merged with :data:`V2_CONFIG` (generator 2's changes and new sections)."""
    if generator not in GENERATORS:
        raise ValueError(f"generator: {brief(generator)} is not one of {GENERATORS}")
    p = Path(path) if path is not None else DEFAULT_CONFIG
    cfg = _read_yaml(p)
    if generator == 2 and isinstance(cfg, dict):
        v2 = _read_yaml(V2_CONFIG)
        if not isinstance(v2, dict):
            raise ValueError(f"config file {V2_CONFIG}: expected a mapping")
        cfg = _deep_merge(cfg, v2)
    return check_config(cfg, f"config file {p}")


#: Traffic-signal states the generator knows (``lights.signal_states``).
SIGNAL_STATES = ("red", "amber", "green", "red_amber")


def check_config(cfg: Any, source: str = "config") -> dict:
    """Check generator defaults (a :func:`load_config` dict, possibly with overrides applied); returns ``cfg``.

    Raises ``ValueError`` starting with ``source`` (e.g. ``config file x.yaml``) for a missing section or an
    impossible value. Keys added after the first release (``vehicles.require_kinds``, ``lights.signal_states``)
    may be absent from an older edited copy; the generator then uses their defaults (none required, all four
    signal states).
    """
    need = ("time_of_day_weights", "timing", "camera", "road", "buildings", "vehicles", "lights", "sky", "groups")
    if not isinstance(cfg, dict):
        raise ValueError(f"{source}: expected a mapping")
    for k in need:
        if k not in cfg:
            raise ValueError(f"{source}: missing section {brief(k)}")
    for g in cfg["groups"]:
        if g not in GROUPS:
            raise ValueError(f"{source}: groups.{g} is not one of {GROUPS}")
    lo, hi = cfg["timing"]["short_exposure_s"]
    if not 0 < lo <= hi:
        raise ValueError(f"{source}: timing.short_exposure_s must be 0 < lo <= hi, got {[lo, hi]}")
    lo, hi = cfg["camera"]["speed_mps"]
    if not 0 <= lo <= hi:
        raise ValueError(f"{source}: camera.speed_mps must be 0 <= lo <= hi m/s, got {[lo, hi]}")
    for k in cfg["vehicles"]["kind_weights"]:
        if k not in VEHICLE_KINDS:
            raise ValueError(f"{source}: vehicles.kind_weights.{k} is not one of {VEHICLE_KINDS}")
    req = cfg["vehicles"].get("require_kinds", [])
    if not isinstance(req, list) or any(k not in VEHICLE_KINDS for k in req):
        raise ValueError(f"{source}: vehicles.require_kinds must be a list of {VEHICLE_KINDS}, got {brief(req)}")
    states = cfg["lights"].get("signal_states", list(SIGNAL_STATES))
    if not isinstance(states, list) or any(st not in SIGNAL_STATES for st in states):
        raise ValueError(f"{source}: lights.signal_states must be a list of {SIGNAL_STATES} "
                         f"([] = no traffic signal), got {brief(states)}")
    if "weather" in cfg:  # generator 2
        conds = cfg["weather"].get("conditions") if isinstance(cfg["weather"], dict) else None
        if not isinstance(conds, list) or not conds or any(c not in WEATHERS for c in conds):
            raise ValueError(f"{source}: weather.conditions must be a non-empty list of {WEATHERS}, got "
                             f"{brief(conds)}")
    return cfg


def apply_overrides(cfg: dict, overrides: Mapping[str, Any] | None, source: str = "overrides") -> dict:
    """A copy of generator defaults ``cfg`` with ``overrides`` merged in, checked with :func:`check_config`.

    Nested mappings merge key by key; any other value (a range, a list) replaces the default. To replace a
    whole mapping (e.g. ``vehicles.kind_weights``) give every key of it: ``{car: 0, truck: 1, motorcycle: 0}``.

    Only keys the defaults have may be overridden (plus the optional ``vehicles.require_kinds`` and
    ``lights.signal_states``): a typo raises ``ValueError`` naming ``source`` and the dotted key.

    >>> cfg = apply_overrides(load_config(), {"camera": {"speed_mps": [30.0, 30.0]}})
    >>> cfg["camera"]["speed_mps"], cfg["camera"]["fov_x_deg"]
    ([30.0, 30.0], 40.0)
    >>> apply_overrides(load_config(), {"camera": {"sped_mps": [1, 1]}})
    Traceback (most recent call last):
    ...
    ValueError: overrides: unknown key 'camera.sped_mps'
    """
    out = copy.deepcopy(cfg)
    if not overrides:
        return out
    optional = {("vehicles", "require_kinds"), ("lights", "signal_states")}

    def merge(dst: dict, src: Any, path: tuple) -> None:
        if not isinstance(src, Mapping):
            raise ValueError(f"{source}: {'.'.join(path) or '(top level)'} must be a mapping, got {brief(src)}")
        for k, v in src.items():
            key = path + (str(k),)
            if k not in dst and key not in optional:
                raise ValueError(f"{source}: unknown key {brief('.'.join(key))}")
            if isinstance(dst.get(k), dict):
                merge(dst[k], v, key)
            else:
                dst[k] = copy.deepcopy(v)

    merge(out, overrides, ())
    return check_config(out, source)


# ------------------------------------------------------------------------------------------- generator
class SceneBuilder:
    """Accumulates the objects, lights and materials of a scene while its steps run, with the scene's one random
    generator ``rng`` (every draw of a scene comes from it, in the order of the steps).

    Args:
        rng: ``numpy.random.default_rng(seed)``. cfg: the generator configuration. tod: time of day.
    """

    def __init__(self, rng: np.random.Generator, cfg: dict, tod: str, generator: int = 1):
        self.rng, self.cfg, self.tod, self.generator = rng, cfg, tod, generator
        self.meshes: dict = {}  # generator 2: the scene's ``meshes`` (shared by the parts that use them)
        self.objects: list[dict] = []
        self.lights: list[dict] = []
        self.materials: dict = copy.deepcopy(BASE_MATERIALS)
        lc = cfg["lights"]
        self.head_peak = self.u(lc["headlight_luminance_cd_m2"])

    def u(self, r):
        """A uniform draw in [r[0], r[1])."""
        return float(self.rng.uniform(r[0], r[1]))

    def ulog(self, r):
        """A log-uniform draw in [r[0], r[1])."""
        return float(math.exp(self.rng.uniform(math.log(r[0]), math.log(r[1]))))

    def ui(self, r):
        """A uniform integer in [r[0], r[1]]."""
        return int(self.rng.integers(r[0], r[1] + 1))

    def obj(self, kind, parts, velocity=(0.0, 0.0, 0.0)) -> int:
        """Add an object of ``kind`` (its parts, velocity in m/s); returns its id."""
        oid = len(self.objects)
        self.objects.append({"id": oid, "kind": kind, "velocity_mps": [float(v) for v in velocity], "parts": parts})
        return oid

    def light(self, kind, instance, shape, spectrum, luminance, spread=90.0, group=None) -> int:
        """Add a light of ``kind`` on object ``instance`` (shape dict, spectrum, luminance in cd/m^2, spread in
        deg; group by default the kind's); returns its id."""
        lid = len(self.lights)
        d = {"id": lid, "group": group or LIGHT_KINDS[kind], "kind": kind, "instance": instance}
        d.update(shape)
        d.update({"spread_deg": float(spread), "spectrum": copy.deepcopy(spectrum),
                  "luminance_cd_m2": float(luminance)})
        self.lights.append(d)
        return lid

    def other_luminance(self) -> float:
        """Luminance (cd/m^2) of a tail, brake, indicator or billboard lamp: a log-uniform fraction of the
        scene's headlight peak."""
        return self.head_peak * self.ulog(self.cfg["lights"]["other_ratio_log"])


def add_vehicle(b: SceneBuilder, kind: str, x: float, y: float, heading: float, speed: float, lights_on: bool,
                braking: bool, indicator: bool) -> None:
    """Add a vehicle of ``kind`` (:data:`render_tools.scene_templates.VEHICLE_TEMPLATES`) at (x, y) m, heading
    (rad), speed (m/s), with its lamps: head and tail lights when ``lights_on``, brake lights when ``braking``,
    one indicator when ``indicator``."""
    t = VEHICLE_TEMPLATES[kind]
    rng = b.rng
    paint = f"paint{len(b.objects)}"
    col = rng.uniform(0.05, 0.75, 3) if rng.random() < 0.7 else np.full(3, rng.uniform(0.03, 0.8))
    b.materials[paint] = {"type": "roughplastic", "rgb": [round(float(c), 4) for c in col], "alpha": 0.15}
    if t["cargo"]:
        b.materials[paint + "c"] = {"type": "diffuse", "rgb": [round(float(c), 4) for c in rng.uniform(0.3, 0.8, 3)]}
    roles = {"paint": paint, "cargo": paint + "c", **VEHICLE_MATERIALS}
    deg = math.degrees(heading)
    parts = street.vehicle_parts(b, kind, x, y, heading, roles) if b.generator >= 2 else []
    for (cx, cy, cz), size, mat in t["boxes"] if b.generator < 2 else ():
        dx, dy = local_offset(cx, cy, heading)
        parts.append(box((x + dx, y + dy, cz), size, roles[mat], deg))
    for (cx, cy, cz), radius, mat in t["spheres"] if b.generator < 2 else ():
        dx, dy = local_offset(cx, cy, heading)
        parts.append({"shape": "sphere", "center": [x + dx, y + dy, cz], "radius": radius, "material": roles[mat]})
    for wx, r, wy in t["wheels"] if b.generator < 2 else ():
        for side in ((1, -1) if wy > 0 else (0,)):
            yy = side * wy
            a0, b0 = local_offset(wx, yy - t["wheel_w"] / 2, heading)
            a1, b1 = local_offset(wx, yy + t["wheel_w"] / 2, heading)
            parts.append(cylinder((x + a0, y + b0, r), (x + a1, y + b1, r), r, "rubber"))
    fwd = (math.cos(heading), math.sin(heading), 0.0)
    back = (-fwd[0], -fwd[1], 0.0)
    speed_v = (speed * fwd[0], speed * fwd[1], 0.0)
    oid = b.obj(kind, parts, speed_v)
    if b.generator >= 2:  # lamp clusters, each lamp with its own timing (render_tools.lamps)
        add_vehicle_lamps(b, kind, t, oid, x, y, heading, speed, lights_on, braking, indicator)
        return
    lc = b.cfg["lights"]

    def lamps(spec, where, normal, lamp_kind, lum, spread):
        for (lx, ly, lz), (w, h) in where:
            for side in ((1, -1) if ly != 0 else (0,)):
                dx, dy = local_offset(lx, side * ly, heading)
                b.light(lamp_kind, oid, {"shape": "rect", "center": [x + dx, y + dy, lz], "normal": list(normal),
                                         "size": [w, h]}, spec, lum, spread)

    if lights_on:
        lamps(lc["led_white"], t["head"], fwd, "headlight", b.u(lc["headlight_luminance_cd_m2"]),
              b.u(lc["headlight_spread_deg"]))
        lamps(lc["led_red"], t["tail"], back, "tail", b.other_luminance(), lc["tail_spread_deg"])
    if braking:
        lum = max(b.other_luminance(), b.other_luminance()) * 3.0
        lum = min(lum, b.head_peak * lc["other_ratio_log"][1])
        if t["cbrake"] is not None:
            cx, cy, cz, w, h = t["cbrake"]
            dx, dy = local_offset(cx, cy, heading)
            b.light("brake", oid, {"shape": "rect", "center": [x + dx, y + dy, cz], "normal": list(back),
                                   "size": [w, h]}, lc["led_red"], lum, lc["tail_spread_deg"])
        lamps(lc["led_red"], [((p[0] - 0.003, p[1], p[2] + 0.1), (s[0], 0.06)) for p, s in t["tail"]], back,
              "brake", lum, lc["tail_spread_deg"])
    if indicator and t["ind"]:
        (lx, ly, lz), (w, h) = t["ind"][0]
        side = 1 if b.rng.random() < 0.5 else -1
        dx, dy = local_offset(lx - 0.003, side * ly, heading)
        b.light("indicator", oid, {"shape": "rect", "center": [x + dx, y + dy, lz], "normal": list(back),
                                   "size": [w, h]}, lc["led_amber"], b.other_luminance(), lc["tail_spread_deg"])


def add_signal(b: SceneBuilder, road: "Road", states: list) -> None:
    """A traffic signal over the ego lanes (facing the camera) and a second head on its pole, in a state drawn
    from ``states``."""
    rng = b.rng
    lc = b.cfg["lights"]
    half, n, lw = road.half_width_m, road.lanes, road.lane_width_m
    sx = b.u(lc["signal_distance_m"])
    state = states[int(rng.integers(0, len(states)))]
    py = -(half + 0.4)
    arm_y = -max(0.0, (n - 0.5) * lw) * 0.5 - 0.5 * lw
    ph = 5.6
    parts = [cylinder((sx, py, 0.0), (sx, py, ph + 0.6), 0.12, "metal"),
             box((sx, (py + arm_y) / 2, ph + 0.5), (0.12, abs(py - arm_y) + 0.4, 0.12), "metal")]
    heads = [(sx, arm_y, ph - 0.2), (sx - 0.15, py, 3.0)]
    lamps = {"red": (0.33, lc["led_red"]), "amber": (0.0, lc["led_amber"]), "green": (-0.33, lc["led_green"])}
    on = {"red": ["red"], "amber": ["amber"], "green": ["green"], "red_amber": ["red", "amber"]}[state]
    off_parts = []
    for hx, hy, hz in heads:
        parts.append(box((hx + 0.15, hy, hz), (0.3, 0.38, 1.05), "housing"))
        for name, (dz, _) in lamps.items():
            if name not in on:
                off_parts.append({"shape": "disk", "center": [hx - 0.005, hy, hz + dz], "radius": 0.1,
                                  "normal": [-1.0, 0.0, 0.0], "material": "lamp_off"})
    oid = b.obj("signal_pole", parts + off_parts)
    sig_lum = b.u(lc["signal_luminance_cd_m2"])
    for hx, hy, hz in heads:
        for name in on:
            dz, spec = lamps[name]
            b.light("signal", oid, {"shape": "disk", "center": [hx - 0.005, hy, hz + dz], "normal": [-1, 0, 0],
                                    "radius": 0.1}, spec, sig_lum, 90.0)


@dataclass(frozen=True)
class Road:
    """The road the other steps place things along (m): lanes per direction, lane width, half width (lanes and
    a parking strip), extent along x, sidewalk width."""

    lanes: int
    lane_width_m: float
    park_m: float
    half_width_m: float
    x0_m: float
    x1_m: float
    sidewalk_m: float

    @property
    def mid_m(self) -> float:
        return (self.x0_m + self.x1_m) / 2

    @property
    def length_m(self) -> float:
        return self.x1_m - self.x0_m


def add_road(b: SceneBuilder) -> Road:
    """Step 1: ground, road, markings (dashed between lanes), sidewalks."""
    rc = b.cfg["road"]
    rng = b.rng
    n = b.ui(rc["lanes_per_direction"])
    lw = float(rc["lane_width_m"])
    park = 2.2
    half = n * lw + park
    x0, x1 = -float(rc["behind_m"]), float(rc["length_m"])
    sw = b.u(rc["sidewalk_width_m"])
    road = Road(n, lw, park, half, x0, x1, sw)
    xm, xl = road.mid_m, road.length_m
    ch = float(rc["curb_height_m"])
    b.obj("ground", [rect((xm, 0.0, -0.02), (xl + 400.0, 600.0), (0, 0, 1), "ground")])
    b.obj("road", [box((xm, 0.0, -0.05), (xl, 2 * half, 0.1), "asphalt")])
    mw = float(rc["marking_width_m"])
    marks = [rect((xm, 0.12, 0.003), (xl, mw), (0, 0, 1), "marking"),
             rect((xm, -0.12, 0.003), (xl, mw), (0, 0, 1), "marking"),
             rect((xm, n * lw, 0.003), (xl, mw), (0, 0, 1), "marking"),
             rect((xm, -n * lw, 0.003), (xl, mw), (0, 0, 1), "marking")]
    dl, dg = float(rc["dash_length_m"]), float(rc["dash_gap_m"])
    for k in range(1, n):
        for side in (1, -1):
            xx = x0 + rng.uniform(0, dl + dg)
            while xx < x1:
                marks.append(rect((xx + dl / 2, side * k * lw, 0.003), (dl, mw), (0, 0, 1), "marking"))
                xx += dl + dg
    b.obj("marking", marks)
    for side in (1, -1):
        b.obj("sidewalk", [box((xm, side * (half + sw / 2), ch / 2), (xl, sw, ch), "concrete")])
    return road


def add_buildings(b: SceneBuilder, road: Road, dark: bool) -> None:
    """Step 2: buildings along both sides, with windows and, after dark, LED billboards on facades ahead."""
    bc, lc = b.cfg["buildings"], b.cfg["lights"]
    rng = b.rng
    n_board = b.ui(lc["billboards"]) if dark else 0
    bi = 0
    facades = []
    for side in (1, -1):
        xx = road.x0_m
        while xx < float(bc["max_extent_m"]):
            w, d, h = b.u(bc["width_m"]), b.u(bc["depth_m"]), b.u(bc["height_m"])
            y_in = road.half_width_m + road.sidewalk_m + b.u(bc["setback_m"])
            yc = side * (y_in + d / 2)
            mat = f"building{bi}"
            bi += 1
            g = rng.uniform(0.15, 0.55)
            tint = rng.uniform(0.85, 1.15, 3) * g
            b.materials[mat] = {"type": "diffuse", "rgb": [round(float(c), 4) for c in np.clip(tint, 0, 0.9)]}
            parts = [box((xx + w / 2, yc, h / 2), (w, d, h), mat)]
            nwin = b.ui(bc["windows_per_row"])
            floors = max(1, int((h - 1.5) // 3.2))
            face_y = side * (y_in - 0.01)
            for f in range(min(floors, 8)):
                for k in range(nwin):
                    cx = xx + (k + 0.5) * w / nwin
                    parts.append(rect((cx, face_y, 1.8 + 3.2 * f), (min(1.4, 0.6 * w / nwin), 1.5),
                                      (0, -side, 0), "glass"))
            oid = b.obj("building", parts)
            facades.append((oid, xx, w, face_y, side, h))
            xx += w + b.u(bc["gap_m"])
    ahead = [f for f in facades if 15.0 < f[1] < 120.0 and f[2] > 7.0]
    for j in rng.permutation(len(ahead))[:n_board]:
        oid, xx, w, face_y, side, h = ahead[int(j)]
        bw, bh = rng.uniform(3.0, min(6.0, w - 1.0)), rng.uniform(1.5, 3.0)
        spec = [lc["led_white"], lc["led_red"], lc["led_green"], lc["led_amber"]][int(rng.integers(0, 4))]
        b.light("billboard", oid, {"shape": "rect", "center": [xx + w / 2, face_y - side * 0.05, 3.0 + bh / 2 + 1.0],
                                   "normal": [0.0, -side, 0.0], "size": [bw, bh]}, spec, b.other_luminance())


def place_camera(b: SceneBuilder, road: Road) -> tuple[float, float]:
    """Step 3: the ego lane and speed: (camera y in m, speed in m/s)."""
    cam_lane = int(b.rng.integers(0, road.lanes))
    return -(cam_lane + 0.5) * road.lane_width_m, b.u(b.cfg["camera"]["speed_mps"])


def add_vehicles(b: SceneBuilder, road: Road, cam_y: float, dark: bool, seed: int) -> None:
    """Step 4: vehicles ahead in the ego direction (the kinds of ``vehicles.require_kinds`` first), oncoming and
    parked along both kerbs, with their lamps; none within 12 m ahead of the camera in its lane."""
    vc = b.cfg["vehicles"]
    rng = b.rng
    lw, n, park = road.lane_width_m, road.lanes, road.park_m
    r0, r1 = vc["range_m"]
    kinds = list(vc["kind_weights"])
    kp = np.array([vc["kind_weights"][k] for k in kinds], dtype=float)
    kp /= kp.sum()
    occupied: dict[float, list[tuple[float, float]]] = {}

    def free(lane_y, x, length):
        for (a, c) in occupied.get(lane_y, []):
            if abs(x - a) < (length + c) / 2 + 4.0:
                return False
        return True

    def place(lane_ys, count, heading, moving, require=()):
        """Place ``count`` vehicles; the first ones take the kinds of ``require`` (one each); returns the kinds
        placed."""
        placed = []
        for i in range(max(count, len(require))):
            for _try in range(20):
                kind = kinds[int(rng.choice(len(kinds), p=kp))] if moving else PARKED_KIND
                if i < len(require):
                    kind = require[i]
                ln = VEHICLE_TEMPLATES[kind]["length"]
                ly = lane_ys[int(rng.integers(0, len(lane_ys)))]
                x = rng.uniform(r0, r1)
                if abs(ly - cam_y) < 0.1 and x < 12.0:
                    continue
                if free(ly, x, ln):
                    occupied.setdefault(ly, []).append((x, ln))
                    yy = ly + (rng.uniform(-0.25, 0.25) if moving else 0.0)
                    sp = b.u(vc["speed_mps"]) if moving else 0.0
                    sp = min(sp, VEHICLE_TEMPLATES[kind].get("max_speed_mps", sp))
                    add_vehicle(b, kind, x, yy, heading, sp,
                                lights_on=moving and (dark or VEHICLE_TEMPLATES[kind]["lights_by_day"]),
                                braking=moving and rng.random() < vc["brake_probability"],
                                indicator=moving and rng.random() < vc["indicator_probability"])
                    placed.append(kind)
                    break
        return placed

    same = [-(k + 0.5) * lw for k in range(n)]
    onc = [(k + 0.5) * lw for k in range(n)]
    require = list(vc.get("require_kinds", []))
    placed = place(same, b.ui(vc["ahead_same_dir"]), 0.0, True, require)
    missing = [k for k in require if k not in placed]
    if missing:
        raise ValueError(f"vehicles.require_kinds: no free place ahead for {missing} with seed {int(seed)}; "
                         "choose another seed")
    place(onc, b.ui(vc["oncoming"]), math.pi, True)
    place([-(n * lw + park / 2)], b.ui(vc["parked_per_side"]), 0.0, False)
    place([n * lw + park / 2], b.ui(vc["parked_per_side"]), math.pi, False)


def add_streetlights(b: SceneBuilder, road: Road, dark: bool) -> None:
    """Step 5: streetlight poles along both sides (lamps lit after dark)."""
    lc = b.cfg["lights"]
    rng = b.rng
    half = road.half_width_m
    spacing = b.u(lc["streetlight_spacing_m"])
    sl_spec = lc["streetlight_spectra"][int(rng.integers(0, len(lc["streetlight_spectra"])))]
    sl_h = b.u(lc["streetlight_height_m"])
    sl_lum = b.u(lc["streetlight_luminance_cd_m2"])
    for side in (1, -1):
        xx = road.x0_m + rng.uniform(0, spacing)
        while xx < 200.0:
            py = side * (half + 0.5)
            ay = side * (half - 1.5)
            parts = [cylinder((xx, py, 0.0), (xx, py, sl_h + 0.1), 0.09, "metal"),
                     box((xx, (py + ay) / 2, sl_h), (0.12, abs(py - ay), 0.1), "metal"),
                     box((xx, ay, sl_h - 0.05), (0.7, 0.35, 0.15), "housing")]
            oid = b.obj("streetlight_pole", parts)
            if dark:
                b.light("streetlight", oid, {"shape": "rect", "center": [xx, ay, sl_h - 0.13], "normal": [0, 0, -1],
                                             "size": [0.6, 0.25]}, sl_spec, sl_lum, 90.0)
            xx += spacing


def make_sky(b: SceneBuilder) -> dict:
    """Step 7: the sky of the time of day (a constant night sky, else Hosek-Wilkie sun and sky)."""
    sc = b.cfg["sky"][b.tod]
    rng = b.rng
    if b.tod == "night":
        return {"model": "constant", "spectrum": copy.deepcopy(sc["spectrum"]),
                "luminance_cd_m2": b.ulog(sc["luminance_cd_m2_log"])}
    return {"model": "sunsky", "sun_elevation_deg": b.u(sc["sun_elevation_deg"]),
            "sun_azimuth_deg": float(rng.uniform(-150.0, 150.0)), "turbidity": b.u(sc["turbidity"]),
            "scale": b.ulog(sc["scale_log"]) if "scale_log" in sc else b.u(sc["scale"])}


def generate_scene(seed: int, time_of_day: str | None = None, config: dict | str | None = None,
                   scene_id: str | None = None, overrides: Mapping[str, Any] | None = None,
                   generator: int = 1) -> dict:
    """Generate a driving scene: road, buildings, camera lane, vehicles, streetlights, signal, sky, camera
    (the steps above, in that order, all drawing from one generator); generator 2 adds the steps of
    :mod:`render_tools.street` after the signal.

    Args:
        seed: integer seed; every random draw of the scene comes from ``numpy.random.default_rng(seed)``.
        time_of_day: ``"day"``, ``"dusk"``, ``"night"`` or None (drawn with the config's weights).
        config: generator defaults (dict or YAML path); default :data:`DEFAULT_CONFIG`.
        scene_id: identifier stored in the scene (default ``"scene_<seed>"``).
        overrides: per-scene changes of ``config`` (see :func:`apply_overrides`), e.g. ``{"camera":
            {"speed_mps": [30.0, 30.0]}, "vehicles": {"require_kinds": ["truck"]}, "lights": {"signal_states":
            ["red"]}}`` pins the ego speed (m/s), a truck among the vehicles ahead and a red signal (the benchmark
            protocols of :mod:`render_tools.protocol` pin their conditions this way).
        generator: 1 (protocol lfmbench-v1; frozen) or 2 (lfmbench-v2; :data:`GENERATORS`).
    Returns:
        A validated scene dict (see :func:`render_tools.scene_schema.validate_scene` for the schema).

    Raises ``ValueError`` for a bad argument, and when a kind of ``vehicles.require_kinds`` finds no free place
    ahead (rare; another seed places it).
    """
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed: must be a non-negative integer, got {brief(seed)}")
    if generator not in GENERATORS or isinstance(generator, bool):
        raise ValueError(f"generator: {brief(generator)} is not one of {GENERATORS}")
    cfg = config if isinstance(config, dict) else load_config(config, generator=generator)
    if generator == 2 and not all(k in cfg for k in V2_SECTIONS):
        raise ValueError(f"config: generator 2 needs the sections {V2_SECTIONS} (load_config(generator=2))")
    if overrides:
        cfg = apply_overrides(cfg, overrides)
    rng = np.random.default_rng(int(seed))
    if time_of_day is None:
        names = list(cfg["time_of_day_weights"])
        p = np.array([cfg["time_of_day_weights"][n] for n in names], dtype=float)
        time_of_day = names[int(rng.choice(len(names), p=p / p.sum()))]
    if time_of_day not in TIMES_OF_DAY:
        raise ValueError(f"time_of_day: {brief(time_of_day)} not one of {TIMES_OF_DAY}")
    b = SceneBuilder(rng, cfg, time_of_day, generator)
    dark = time_of_day != "day"
    road = add_road(b)
    add_buildings(b, road, dark)
    cam_y, speed = place_camera(b, road)
    add_vehicles(b, road, cam_y, dark, int(seed))
    add_streetlights(b, road, dark)
    # step 6: a traffic signal, its state drawn from lights.signal_states (an empty list: no signal)
    states = list(cfg["lights"].get("signal_states", SIGNAL_STATES))
    if states:
        add_signal(b, road, states)
    weather = street.add_street(b, road, cam_y, dark) if generator == 2 else None
    if generator == 2:  # LED signal arrays, countdown, message signs (render_tools.lamps)
        add_displays(b, road, dark)
    sky = make_sky(b)
    # step 8: the camera
    cc = cfg["camera"]
    yaw_rate = b.u(cc["yaw_rate_rad_s"])
    scene = {
        "format": SCENE_FORMAT, "version": generator,
        "scene_id": scene_id or f"scene_{int(seed):06d}", "seed": int(seed), "time_of_day": time_of_day,
        "timing": {"short_exposure_s": b.u(cfg["timing"]["short_exposure_s"])},
        "camera": {"position_m": [0.0, cam_y, float(cc["height_m"])], "yaw_deg": 0.0,
                   "pitch_deg": b.u(cc["pitch_deg"]), "fov_x_deg": float(cc["fov_x_deg"]), "speed_mps": speed,
                   "yaw_rate_rad_s": yaw_rate},
        "sky": sky,
        "groups": copy.deepcopy(cfg["groups"]),
        "materials": b.materials,
        "objects": b.objects,
        "lights": b.lights,
    }
    if generator == 2:
        scene["weather"] = weather
        if b.meshes:  # a scene leaves out what it does not need
            scene["meshes"] = b.meshes
    return validate_scene(plain_json(scene))

