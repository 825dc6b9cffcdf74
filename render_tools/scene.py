"""Procedural driving scenes as plain, editable JSON, and their validation.

A scene is a dict (saved as JSON) that fully describes what is rendered: geometry made of primitive parts
(boxes, cylinders, rectangles, disks, spheres), materials, emitters (lights) with their group, spectrum
model and luminance (cd/m^2), the sky, the ego camera and the short-exposure time. Re-rendering a scene file
gives the same images (up to Monte Carlo noise with a different seed).

World frame: ISO 8855, metres: x forward along the road, y left, z up; the road surface is z = 0. Traffic
drives on the right: the ego direction uses lanes at y < 0.

Functions
- :func:`load_config` -> generator defaults (``render_tools/configs/scene_defaults.yaml``).
- :func:`generate_scene` -> a validated scene dict from a seed (day / dusk / night).
- :func:`validate_scene` -> the scene, or ``ValueError`` naming the offending field (``scene.lights[3].size``).
- :func:`load_scene` / :func:`save_scene` -> JSON on disk (atomic write).

Luminance ranges follow upstream (ISETHDR heuristic, ``upstream.md``): headlights 2e4-2e5 cd/m^2,
streetlights 1e4-5e4 cd/m^2, other lights 4e-4..1e-2 of the scene's headlight peak.
"""
from __future__ import annotations

import copy
import json
import math
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from lfmbench.limits import brief, lights_cap_message, limit
from lfmbench.check import check_integer, check_keys, check_number, check_vector, fail, scene_id_error
from lfmbench.fileio import atomic_write_json
from lfmbench.vocabulary import GROUPS, LIGHT_GROUPS, LIGHT_KINDS, OBJECT_KINDS, VEHICLE_KINDS

from . import spectra

#: Scene file format name and version.
SCENE_FORMAT = "lfmbench-scene"
SCENE_VERSION = 1
TIMES_OF_DAY = ("day", "dusk", "night")
PART_SHAPES = ("box", "cylinder", "rect", "disk", "sphere")
MATERIAL_TYPES = ("diffuse", "roughplastic", "roughconductor")
#: Default generator configuration file.
DEFAULT_CONFIG = Path(__file__).with_name("configs") / "scene_defaults.yaml"
#: Largest coordinate magnitude accepted, m.
MAX_COORD_M = 1.0e4


# ----------------------------------------------------------------------------------------------- config
def load_config(path: str | os.PathLike | None = None) -> dict:
    """Generator defaults from YAML (default :data:`DEFAULT_CONFIG`); raises ``ValueError`` naming the file."""
    from lfmbench.fileio import load_yaml  # noqa: PLC0415

    p = Path(path) if path is not None else DEFAULT_CONFIG
    try:
        cfg = load_yaml(p, source=f"config file {p}")
    except OSError as exc:
        raise ValueError(f"config file {p}: cannot read ({exc.strerror or exc})") from None
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
class _Builder:
    """Accumulates objects, lights and materials while generating (internal)."""

    def __init__(self, rng: np.random.Generator, cfg: dict, tod: str):
        self.rng, self.cfg, self.tod = rng, cfg, tod
        self.objects: list[dict] = []
        self.lights: list[dict] = []
        self.materials: dict = {
            "asphalt": {"type": "diffuse", "rgb": [0.09, 0.09, 0.095]},
            "marking": {"type": "diffuse", "rgb": [0.65, 0.65, 0.62]},
            "concrete": {"type": "diffuse", "rgb": [0.32, 0.31, 0.29]},
            "ground": {"type": "diffuse", "rgb": [0.12, 0.13, 0.09]},
            "glass": {"type": "roughplastic", "rgb": [0.02, 0.025, 0.03], "alpha": 0.05},
            "rubber": {"type": "diffuse", "rgb": [0.03, 0.03, 0.03]},
            "metal": {"type": "roughconductor", "alpha": 0.3},
            "lamp_off": {"type": "roughplastic", "rgb": [0.05, 0.05, 0.05], "alpha": 0.1},
            "housing": {"type": "diffuse", "rgb": [0.04, 0.04, 0.04]},
            "lens_red": {"type": "roughplastic", "rgb": [0.25, 0.02, 0.02], "alpha": 0.1},
            "lens_clear": {"type": "roughplastic", "rgb": [0.5, 0.5, 0.5], "alpha": 0.1},
        }
        lc = cfg["lights"]
        self.head_peak = self.u(lc["headlight_luminance_cd_m2"])

    def u(self, r):
        return float(self.rng.uniform(r[0], r[1]))

    def ulog(self, r):
        return float(math.exp(self.rng.uniform(math.log(r[0]), math.log(r[1]))))

    def ui(self, r):
        return int(self.rng.integers(r[0], r[1] + 1))

    def obj(self, kind, parts, velocity=(0.0, 0.0, 0.0)) -> int:
        oid = len(self.objects)
        self.objects.append({"id": oid, "kind": kind, "velocity_mps": [float(v) for v in velocity], "parts": parts})
        return oid

    def light(self, kind, instance, shape, spectrum, luminance, spread=90.0, group=None) -> int:
        lid = len(self.lights)
        d = {"id": lid, "group": group or LIGHT_KINDS[kind], "kind": kind, "instance": instance}
        d.update(shape)
        d.update({"spread_deg": float(spread), "spectrum": copy.deepcopy(spectrum),
                  "luminance_cd_m2": float(luminance)})
        self.lights.append(d)
        return lid

    def other_luminance(self) -> float:
        return self.head_peak * self.ulog(self.cfg["lights"]["other_ratio_log"])


def _box(center, size, material, yaw_deg=0.0):
    return {"shape": "box", "center": [float(c) for c in center], "size": [float(s) for s in size],
            "yaw_deg": float(yaw_deg), "material": material}


def _rect(center, size, normal, material):
    return {"shape": "rect", "center": [float(c) for c in center], "size": [float(s) for s in size],
            "normal": [float(n) for n in normal], "material": material}


def _cyl(p0, p1, radius, material):
    return {"shape": "cylinder", "p0": [float(c) for c in p0], "p1": [float(c) for c in p1],
            "radius": float(radius), "material": material}


def _local(x, y, heading):
    """Vehicle-local (x fwd, y left) offset -> world xy offset for heading (rad)."""
    c, s = math.cos(heading), math.sin(heading)
    return c * x - s * y, s * x + c * y


# Vehicle templates in the vehicle frame (x forward from the centre, y left, z up), metres.
_TEMPLATES = {
    "car": {"length": 4.4, "boxes": [((0.0, 0.0, 0.68), (4.4, 1.8, 0.66), "paint"),
                                     ((-0.35, 0.0, 1.28), (2.3, 1.6, 0.56), "glass")],
            "wheels": [(1.35, 0.33, 0.8), (-1.35, 0.33, 0.8)], "wheel_w": 0.22,
            "tail": [((-2.205, 0.62, 0.86), (0.32, 0.12))], "head": [((2.205, 0.62, 0.72), (0.26, 0.11))],
            "cbrake": (-1.52, 0.0, 1.54, 0.5, 0.06), "ind": [((-2.205, 0.82, 0.72), (0.1, 0.07))]},
    "truck": {"length": 9.5, "boxes": [((3.55, 0.0, 1.85), (2.4, 2.4, 2.6), "paint"),
                                       ((-1.2, 0.0, 2.35), (7.1, 2.5, 3.3), "cargo"),
                                       ((4.56, 0.0, 2.35), (0.4, 2.2, 1.0), "glass")],
              "wheels": [(3.4, 0.5, 1.0), (-2.5, 0.5, 1.0), (-3.8, 0.5, 1.0)], "wheel_w": 0.3,
              "tail": [((-4.755, 1.0, 1.0), (0.3, 0.15))], "head": [((4.755, 0.9, 1.0), (0.3, 0.14))],
              "cbrake": None, "ind": [((-4.755, 1.15, 1.25), (0.12, 0.1))]},
    "motorcycle": {"length": 2.1, "boxes": [((0.0, 0.0, 0.72), (1.7, 0.35, 0.45), "paint"),
                                           ((-0.2, 0.0, 1.3), (0.4, 0.45, 0.7), "rider")],
                   "wheels": [(0.75, 0.32, 0.0), (-0.75, 0.32, 0.0)], "wheel_w": 0.12,
                   "tail": [((-0.865, 0.0, 0.9), (0.14, 0.07))], "head": [((0.865, 0.0, 0.95), (0.16, 0.1))],
                   "cbrake": None, "ind": []},
}


def _vehicle(b: _Builder, kind: str, x: float, y: float, heading: float, speed: float, lights_on: bool,
             braking: bool, indicator: bool) -> None:
    t = _TEMPLATES[kind]
    rng = b.rng
    paint = f"paint{len(b.objects)}"
    col = rng.uniform(0.05, 0.75, 3) if rng.random() < 0.7 else np.full(3, rng.uniform(0.03, 0.8))
    b.materials[paint] = {"type": "roughplastic", "rgb": [round(float(c), 4) for c in col], "alpha": 0.15}
    if kind == "truck":
        b.materials[paint + "c"] = {"type": "diffuse", "rgb": [round(float(c), 4) for c in rng.uniform(0.3, 0.8, 3)]}
    deg = math.degrees(heading)
    parts = []
    for (cx, cy, cz), size, mat in t["boxes"]:
        dx, dy = _local(cx, cy, heading)
        m = {"paint": paint, "cargo": paint + "c", "glass": "glass", "rider": "rubber"}[mat]
        parts.append(_box((x + dx, y + dy, cz), size, m, deg))
    if kind == "motorcycle":
        dx, dy = _local(-0.2, 0.0, heading)
        parts.append({"shape": "sphere", "center": [x + dx, y + dy, 1.8], "radius": 0.15, "material": paint})
    for wx, r, wy in t["wheels"]:
        for side in ((1, -1) if wy > 0 else (0,)):
            yy = side * wy
            a0, b0 = _local(wx, yy - t["wheel_w"] / 2, heading)
            a1, b1 = _local(wx, yy + t["wheel_w"] / 2, heading)
            parts.append(_cyl((x + a0, y + b0, r), (x + a1, y + b1, r), r, "rubber"))
    fwd = (math.cos(heading), math.sin(heading), 0.0)
    back = (-fwd[0], -fwd[1], 0.0)
    speed_v = (speed * fwd[0], speed * fwd[1], 0.0)
    oid = b.obj(kind, parts, speed_v)
    lc = b.cfg["lights"]

    def lamps(spec, where, normal, lamp_kind, lum, spread):
        for (lx, ly, lz), (w, h) in where:
            for side in ((1, -1) if ly != 0 else (0,)):
                dx, dy = _local(lx, side * ly, heading)
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
            dx, dy = _local(cx, cy, heading)
            b.light("brake", oid, {"shape": "rect", "center": [x + dx, y + dy, cz], "normal": list(back),
                                   "size": [w, h]}, lc["led_red"], lum, lc["tail_spread_deg"])
        lamps(lc["led_red"], [((p[0] - 0.003, p[1], p[2] + 0.1), (s[0], 0.06)) for p, s in t["tail"]], back,
              "brake", lum, lc["tail_spread_deg"])
    if indicator and t["ind"]:
        (lx, ly, lz), (w, h) = t["ind"][0]
        side = 1 if b.rng.random() < 0.5 else -1
        dx, dy = _local(lx - 0.003, side * ly, heading)
        b.light("indicator", oid, {"shape": "rect", "center": [x + dx, y + dy, lz], "normal": list(back),
                                   "size": [w, h]}, lc["led_amber"], b.other_luminance(), lc["tail_spread_deg"])


def _signal(b: _Builder, lc: dict, half: float, n: int, lw: float, states: list) -> None:
    """A traffic signal over the ego lanes (facing the camera) and a second head on its pole, in a state drawn
    from ``states``; ``half``: road half-width (m), ``n`` lanes per direction of width ``lw`` (m)."""
    rng = b.rng
    sx = b.u(lc["signal_distance_m"])
    state = states[int(rng.integers(0, len(states)))]
    py = -(half + 0.4)
    arm_y = -max(0.0, (n - 0.5) * lw) * 0.5 - 0.5 * lw
    ph = 5.6
    parts = [_cyl((sx, py, 0.0), (sx, py, ph + 0.6), 0.12, "metal"),
             _box((sx, (py + arm_y) / 2, ph + 0.5), (0.12, abs(py - arm_y) + 0.4, 0.12), "metal")]
    heads = [(sx, arm_y, ph - 0.2), (sx - 0.15, py, 3.0)]
    lamps = {"red": (0.33, lc["led_red"]), "amber": (0.0, lc["led_amber"]), "green": (-0.33, lc["led_green"])}
    on = {"red": ["red"], "amber": ["amber"], "green": ["green"], "red_amber": ["red", "amber"]}[state]
    off_parts = []
    for hx, hy, hz in heads:
        parts.append(_box((hx + 0.15, hy, hz), (0.3, 0.38, 1.05), "housing"))
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


def generate_scene(seed: int, time_of_day: str | None = None, config: dict | str | None = None,
                   scene_id: str | None = None, overrides: Mapping[str, Any] | None = None) -> dict:
    """Generate a driving scene.

    Args:
        seed: integer seed; every random draw of the scene comes from ``numpy.random.default_rng(seed)``.
        time_of_day: ``"day"``, ``"dusk"``, ``"night"`` or None (drawn with the config's weights).
        config: generator defaults (dict or YAML path); default :data:`DEFAULT_CONFIG`.
        scene_id: identifier stored in the scene (default ``"scene_<seed>"``).
        overrides: per-scene changes of ``config`` (see :func:`apply_overrides`), e.g. ``{"camera":
            {"speed_mps": [30.0, 30.0]}, "vehicles": {"require_kinds": ["truck"]}, "lights": {"signal_states":
            ["red"]}}`` pins the ego speed (m/s), a truck among the vehicles ahead and a red signal (the benchmark
            protocols of :mod:`render_tools.protocol` pin their conditions this way).
    Returns:
        A validated scene dict (see :func:`validate_scene` for the schema).

    Raises ``ValueError`` for a bad argument, and when a kind of ``vehicles.require_kinds`` finds no free place
    ahead (rare; another seed places it).
    """
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed: must be a non-negative integer, got {brief(seed)}")
    cfg = config if isinstance(config, dict) else load_config(config)
    if overrides:
        cfg = apply_overrides(cfg, overrides)
    rng = np.random.default_rng(int(seed))
    if time_of_day is None:
        names = list(cfg["time_of_day_weights"])
        p = np.array([cfg["time_of_day_weights"][n] for n in names], dtype=float)
        time_of_day = names[int(rng.choice(len(names), p=p / p.sum()))]
    if time_of_day not in TIMES_OF_DAY:
        raise ValueError(f"time_of_day: {brief(time_of_day)} not one of {TIMES_OF_DAY}")
    b = _Builder(rng, cfg, time_of_day)
    rc, bc, vc, lc = cfg["road"], cfg["buildings"], cfg["vehicles"], cfg["lights"]
    dark = time_of_day != "day"

    # --- road, markings, sidewalks, ground
    n = b.ui(rc["lanes_per_direction"])
    lw = float(rc["lane_width_m"])
    park = 2.2
    half = n * lw + park
    x0, x1 = -float(rc["behind_m"]), float(rc["length_m"])
    xm, xl = (x0 + x1) / 2, x1 - x0
    sw = b.u(rc["sidewalk_width_m"])
    ch = float(rc["curb_height_m"])
    b.obj("ground", [_rect((xm, 0.0, -0.02), (xl + 400.0, 600.0), (0, 0, 1), "ground")])
    b.obj("road", [_box((xm, 0.0, -0.05), (xl, 2 * half, 0.1), "asphalt")])
    mw = float(rc["marking_width_m"])
    marks = [_rect((xm, 0.12, 0.003), (xl, mw), (0, 0, 1), "marking"),
             _rect((xm, -0.12, 0.003), (xl, mw), (0, 0, 1), "marking"),
             _rect((xm, n * lw, 0.003), (xl, mw), (0, 0, 1), "marking"),
             _rect((xm, -n * lw, 0.003), (xl, mw), (0, 0, 1), "marking")]
    dl, dg = float(rc["dash_length_m"]), float(rc["dash_gap_m"])
    for k in range(1, n):
        for side in (1, -1):
            xx = x0 + rng.uniform(0, dl + dg)
            while xx < x1:
                marks.append(_rect((xx + dl / 2, side * k * lw, 0.003), (dl, mw), (0, 0, 1), "marking"))
                xx += dl + dg
    b.obj("marking", marks)
    for side in (1, -1):
        b.obj("sidewalk", [_box((xm, side * (half + sw / 2), ch / 2), (xl, sw, ch), "concrete")])

    # --- buildings (with windows and, after dark, LED billboards)
    n_board = b.ui(lc["billboards"]) if dark else 0
    bi = 0
    facades = []
    for side in (1, -1):
        xx = x0
        while xx < float(bc["max_extent_m"]):
            w, d, h = b.u(bc["width_m"]), b.u(bc["depth_m"]), b.u(bc["height_m"])
            y_in = half + sw + b.u(bc["setback_m"])
            yc = side * (y_in + d / 2)
            mat = f"building{bi}"
            bi += 1
            g = rng.uniform(0.15, 0.55)
            tint = rng.uniform(0.85, 1.15, 3) * g
            b.materials[mat] = {"type": "diffuse", "rgb": [round(float(c), 4) for c in np.clip(tint, 0, 0.9)]}
            parts = [_box((xx + w / 2, yc, h / 2), (w, d, h), mat)]
            nwin = b.ui(bc["windows_per_row"])
            floors = max(1, int((h - 1.5) // 3.2))
            face_y = side * (y_in - 0.01)
            for f in range(min(floors, 8)):
                for k in range(nwin):
                    cx = xx + (k + 0.5) * w / nwin
                    parts.append(_rect((cx, face_y, 1.8 + 3.2 * f), (min(1.4, 0.6 * w / nwin), 1.5),
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

    # --- camera
    cam_lane = int(rng.integers(0, n))
    cam_y = -(cam_lane + 0.5) * lw
    speed = b.u(cfg["camera"]["speed_mps"])

    # --- vehicles
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
                kind = kinds[int(rng.choice(len(kinds), p=kp))] if moving else "car"
                if i < len(require):
                    kind = require[i]
                ln = _TEMPLATES[kind]["length"]
                ly = lane_ys[int(rng.integers(0, len(lane_ys)))]
                x = rng.uniform(r0, r1)
                if abs(ly - cam_y) < 0.1 and x < 12.0:
                    continue
                if free(ly, x, ln):
                    occupied.setdefault(ly, []).append((x, ln))
                    yy = ly + (rng.uniform(-0.25, 0.25) if moving else 0.0)
                    sp = b.u(vc["speed_mps"]) if moving else 0.0
                    _vehicle(b, kind, x, yy, heading, sp, lights_on=moving and (dark or kind == "motorcycle"),
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

    # --- streetlights (poles always, lamps after dark)
    spacing = b.u(lc["streetlight_spacing_m"])
    sl_spec = lc["streetlight_spectra"][int(rng.integers(0, len(lc["streetlight_spectra"])))]
    sl_h = b.u(lc["streetlight_height_m"])
    sl_lum = b.u(lc["streetlight_luminance_cd_m2"])
    for side in (1, -1):
        xx = x0 + rng.uniform(0, spacing)
        while xx < 200.0:
            py = side * (half + 0.5)
            ay = side * (half - 1.5)
            parts = [_cyl((xx, py, 0.0), (xx, py, sl_h + 0.1), 0.09, "metal"),
                     _box((xx, (py + ay) / 2, sl_h), (0.12, abs(py - ay), 0.1), "metal"),
                     _box((xx, ay, sl_h - 0.05), (0.7, 0.35, 0.15), "housing")]
            oid = b.obj("streetlight_pole", parts)
            if dark:
                b.light("streetlight", oid, {"shape": "rect", "center": [xx, ay, sl_h - 0.13], "normal": [0, 0, -1],
                                             "size": [0.6, 0.25]}, sl_spec, sl_lum, 90.0)
            xx += spacing

    # --- traffic signal ahead (over the ego lanes, facing the camera) and one on the pole; its state is drawn
    # from lights.signal_states (an empty list: no signal)
    states = list(lc.get("signal_states", SIGNAL_STATES))
    if states:
        _signal(b, lc, half, n, lw, states)
    # --- sky
    sc = cfg["sky"][time_of_day]
    if time_of_day == "night":
        sky = {"model": "constant", "spectrum": copy.deepcopy(sc["spectrum"]),
               "luminance_cd_m2": b.ulog(sc["luminance_cd_m2_log"])}
    else:
        sky = {"model": "sunsky", "sun_elevation_deg": b.u(sc["sun_elevation_deg"]),
               "sun_azimuth_deg": float(rng.uniform(-150.0, 150.0)), "turbidity": b.u(sc["turbidity"]),
               "scale": b.ulog(sc["scale_log"]) if "scale_log" in sc else b.u(sc["scale"])}

    cc = cfg["camera"]
    yaw_rate = b.u(cc["yaw_rate_rad_s"])
    scene = {
        "format": SCENE_FORMAT, "version": SCENE_VERSION,
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
    return validate_scene(json.loads(json.dumps(scene)))


# ------------------------------------------------------------------------------------------- validation
def _unit(v, path):
    x = np.array(check_vector(v, path, n=3, lo=-1e3, hi=1e3))
    if np.linalg.norm(x) < 1e-6:
        fail(path, "normal must be non-zero")
    return x


def _part_or_light_shape(p, path, extra_req, extra_opt, materials=None):
    shape = p.get("shape") if isinstance(p, dict) else None
    allowed = PART_SHAPES if materials is not None else ("rect", "disk")
    if shape not in allowed:
        fail(f"{path}.shape", f"{brief(shape)} not one of {allowed}")
    geo = {"box": (("center", "size"), ("yaw_deg",)), "cylinder": (("p0", "p1", "radius"), ()),
           "rect": (("center", "size", "normal"), ()), "disk": (("center", "radius", "normal"), ()),
           "sphere": (("center", "radius"), ())}[shape]
    check_keys(p, path, required=("shape",) + geo[0] + extra_req, optional=geo[1] + extra_opt)
    for k in ("center", "p0", "p1"):
        if k in p:
            check_vector(p[k], f"{path}.{k}", lo=-MAX_COORD_M, hi=MAX_COORD_M)
    if "size" in p:
        check_vector(p["size"], f"{path}.size", n=3 if shape == "box" else 2, lo=0.0, hi=MAX_COORD_M)
        if min(p["size"]) <= 0:
            fail(f"{path}.size", f"all sizes must be > 0 m, got {p['size']}")
    if "radius" in p:
        check_number(p["radius"], f"{path}.radius", lo=0.0, hi=1e3, lo_open=True)
    if "normal" in p:
        _unit(p["normal"], f"{path}.normal")
    if "yaw_deg" in p:
        check_number(p["yaw_deg"], f"{path}.yaw_deg", lo=-720.0, hi=720.0)
    if shape == "cylinder" and np.allclose(p["p0"], p["p1"]):
        fail(f"{path}.p1", "cylinder end points coincide")
    if materials is not None and p.get("material") not in materials:
        fail(f"{path}.material", f"{brief(p.get('material'))} is not defined in scene.materials")


def validate_scene(scene: dict) -> dict:
    """Validate a scene dict; returns it unchanged. Raises ``ValueError`` naming the first bad field.

    Schema (all lengths m, times s, angles deg unless named ``_rad``):
    ``format`` ("lfmbench-scene"), ``version`` (1), ``scene_id`` (str, :func:`lfmbench.check.check_scene_id`),
    ``seed`` (int >= 0),
    ``time_of_day`` (day|dusk|night), ``timing.short_exposure_s`` (> 0),
    ``camera`` {position_m [3], yaw_deg, pitch_deg (-89, 89), fov_x_deg (0, 180), speed_mps >= 0,
    yaw_rate_rad_s}, ``sky`` {model: sunsky {sun_elevation_deg [-5, 90], sun_azimuth_deg, turbidity [1, 10],
    scale > 0} | constant {spectrum, luminance_cd_m2 >= 0}}, ``groups`` {name in GROUPS: {flicker: bool}},
    ``materials`` {name: {type: diffuse|roughplastic|roughconductor, rgb [3] in [0, 1], alpha (0, 1]}},
    ``objects`` [{id (= index), kind, velocity_mps [3], parts [shape ...]}], ``lights`` [{id (= index),
    group, kind, instance (object id), shape rect|disk, center, normal, size | radius, spread_deg (0, 90],
    spectrum (see :mod:`render_tools.spectra`), luminance_cd_m2 >= 0}].
    """
    check_keys(scene, "scene", required=("format", "version", "scene_id", "seed", "time_of_day", "timing", "camera",
                                         "sky", "groups", "materials", "objects", "lights"))
    if scene["format"] != SCENE_FORMAT:
        fail("scene.format", f"expected {brief(SCENE_FORMAT)}, got {brief(scene['format'])}")
    if scene["version"] != SCENE_VERSION:
        fail("scene.version", f"unsupported version {brief(scene['version'])} (this reader: {SCENE_VERSION})")
    why = scene_id_error(scene["scene_id"])  # the corpus rule: the id becomes a corpus directory name
    if why is not None:
        fail("scene.scene_id", why)
    check_integer(scene["seed"], "scene.seed")
    if scene["time_of_day"] not in TIMES_OF_DAY:
        fail("scene.time_of_day", f"{brief(scene['time_of_day'])} not one of {TIMES_OF_DAY}")
    check_keys(scene["timing"], "scene.timing", required=("short_exposure_s",))
    check_number(scene["timing"]["short_exposure_s"], "scene.timing.short_exposure_s", lo=0.0, hi=1.0, lo_open=True)
    c = scene["camera"]
    check_keys(c, "scene.camera", required=("position_m", "yaw_deg", "pitch_deg", "fov_x_deg", "speed_mps",
                                            "yaw_rate_rad_s"))
    check_vector(c["position_m"], "scene.camera.position_m", lo=-MAX_COORD_M, hi=MAX_COORD_M)
    check_number(c["yaw_deg"], "scene.camera.yaw_deg", lo=-720, hi=720)
    check_number(c["pitch_deg"], "scene.camera.pitch_deg", lo=-89, hi=89)
    check_number(c["fov_x_deg"], "scene.camera.fov_x_deg", lo=0.0, hi=179.0, lo_open=True)
    check_number(c["speed_mps"], "scene.camera.speed_mps", lo=0.0, hi=200.0)
    check_number(c["yaw_rate_rad_s"], "scene.camera.yaw_rate_rad_s", lo=-10.0, hi=10.0)
    s = scene["sky"]
    model = s.get("model") if isinstance(s, dict) else None
    if model == "sunsky":
        check_keys(s, "scene.sky", required=("model", "sun_elevation_deg", "sun_azimuth_deg", "turbidity", "scale"))
        check_number(s["sun_elevation_deg"], "scene.sky.sun_elevation_deg", lo=-5.0, hi=90.0)
        check_number(s["sun_azimuth_deg"], "scene.sky.sun_azimuth_deg", lo=-360.0, hi=360.0)
        check_number(s["turbidity"], "scene.sky.turbidity", lo=1.0, hi=10.0)
        check_number(s["scale"], "scene.sky.scale", lo=0.0, hi=1e3, lo_open=True)
    elif model == "constant":
        check_keys(s, "scene.sky", required=("model", "spectrum", "luminance_cd_m2"))
        spectra.validate_spectrum(s["spectrum"], "scene.sky.spectrum")
        check_number(s["luminance_cd_m2"], "scene.sky.luminance_cd_m2", lo=0.0, hi=1e6)
    else:
        fail("scene.sky.model", f"{brief(model)} not one of ('sunsky', 'constant')")
    g = scene["groups"]
    if not isinstance(g, dict):
        fail("scene.groups", "expected an object")
    for name, v in g.items():
        if name not in GROUPS:
            fail(f"scene.groups.{name}", f"unknown group (allowed: {GROUPS})")
        check_keys(v, f"scene.groups.{name}", required=("flicker",))
        if not isinstance(v["flicker"], bool):
            fail(f"scene.groups.{name}.flicker", f"expected true/false, got {brief(v['flicker'])}")
    if g.get("skymap", {}).get("flicker"):
        fail("scene.groups.skymap.flicker", "the sky cannot flicker")
    mats = scene["materials"]
    if not isinstance(mats, dict):
        fail("scene.materials", "expected an object")
    for name, m in mats.items():
        p = f"scene.materials.{name}"
        t = m.get("type") if isinstance(m, dict) else None
        if t not in MATERIAL_TYPES:
            fail(f"{p}.type", f"{brief(t)} not one of {MATERIAL_TYPES}")
        req = {"diffuse": ("type", "rgb"), "roughplastic": ("type", "rgb", "alpha"),
               "roughconductor": ("type", "alpha")}[t]
        check_keys(m, p, required=req)
        if "rgb" in m:
            check_vector(m["rgb"], f"{p}.rgb", n=3, lo=0.0, hi=1.0)
        if "alpha" in m:
            check_number(m["alpha"], f"{p}.alpha", lo=0.0, hi=1.0, lo_open=True)
    objs = scene["objects"]
    if not isinstance(objs, list):
        fail("scene.objects", "expected a list")
    for i, o in enumerate(objs):
        p = f"scene.objects[{i}]"
        check_keys(o, p, required=("id", "kind", "velocity_mps", "parts"))
        if check_integer(o["id"], f"{p}.id") != i:
            fail(f"{p}.id", f"must equal its index {i}, got {o['id']}")
        if o["kind"] not in OBJECT_KINDS:
            fail(f"{p}.kind", f"{brief(o['kind'])} not one of {OBJECT_KINDS}")
        check_vector(o["velocity_mps"], f"{p}.velocity_mps", n=3, lo=-200.0, hi=200.0)
        if not isinstance(o["parts"], list) or not o["parts"]:
            fail(f"{p}.parts", "expected a non-empty list")
        for j, part in enumerate(o["parts"]):
            _part_or_light_shape(part, f"{p}.parts[{j}]", ("material",), (), materials=mats)
    lights = scene["lights"]
    if not isinstance(lights, list):
        fail("scene.lights", "expected a list")
    if len(lights) > limit("lights_per_scene"):
        fail("scene.lights", lights_cap_message(len(lights)))
    for i, lt in enumerate(lights):
        p = f"scene.lights[{i}]"
        _part_or_light_shape(lt, p, ("id", "group", "kind", "instance", "spread_deg", "spectrum",
                                     "luminance_cd_m2"), ())
        if check_integer(lt["id"], f"{p}.id") != i:
            fail(f"{p}.id", f"must equal its index {i}, got {lt['id']}")
        if lt["group"] not in LIGHT_GROUPS:
            fail(f"{p}.group", f"{brief(lt['group'])} not one of {LIGHT_GROUPS}")
        if lt["group"] not in g:
            fail(f"{p}.group", f"group {brief(lt['group'])} is not declared in scene.groups")
        if lt["kind"] not in LIGHT_KINDS:
            fail(f"{p}.kind", f"{brief(lt['kind'])} not one of {sorted(LIGHT_KINDS)}")
        if check_integer(lt["instance"], f"{p}.instance", lo=-1) >= len(objs):
            fail(f"{p}.instance", f"object {lt['instance']} does not exist (-1 = none)")
        check_number(lt["spread_deg"], f"{p}.spread_deg", lo=0.0, hi=90.0, lo_open=True)
        spectra.validate_spectrum(lt["spectrum"], f"{p}.spectrum")
        check_number(lt["luminance_cd_m2"], f"{p}.luminance_cd_m2", lo=0.0, hi=1e9)
    return scene


def scene_groups(scene: dict) -> dict:
    """Groups the scene *has*: {name: {"flicker": bool}}; a light group with no lights and a sky of zero
    luminance are left out."""
    have = {lt["group"] for lt in scene["lights"]}
    sky = scene["sky"]
    sky_on = sky["model"] == "sunsky" or sky["luminance_cd_m2"] > 0
    out = {}
    for name in GROUPS:
        if name not in scene["groups"]:
            continue
        if (name == "skymap" and sky_on) or name in have:
            out[name] = dict(scene["groups"][name])
    return out


# -------------------------------------------------------------------------------------------------- I/O
def load_scene(path: str | os.PathLike) -> dict:
    """Read and validate a scene JSON file; errors name the file."""
    from lfmbench.fileio import InputFileError, load_json  # noqa: PLC0415

    try:
        scene = load_json(path, "scene file")
    except OSError as exc:
        raise ValueError(f"scene file {path}: cannot read JSON ({exc.strerror or exc})") from None
    except InputFileError as exc:
        raise ValueError(f"scene file {exc}") from None
    try:
        return validate_scene(scene)
    except ValueError as exc:
        raise ValueError(f"scene file {path}: {exc}") from exc


def save_scene(scene: dict, path: str | os.PathLike) -> None:
    """Validate and write ``scene`` as JSON atomically (temp file in the same directory, then ``os.replace``)."""
    validate_scene(scene)
    atomic_write_json(path, scene)


def empty_scene(scene_id: str = "empty", short_exposure_s: float = 0.004, speed_mps: float = 0.0,
                yaw_rate_rad_s: float = 0.0, position_m=(0.0, 0.0, 1.4), pitch_deg: float = 0.0,
                fov_x_deg: float = 40.0, sky_luminance_cd_m2: float = 0.0) -> dict:
    """A valid scene with no objects, no lights and a constant (CIE D65) sky of the given luminance: a start
    for hand-made scenes and tests; append to ``objects``, ``lights`` and ``materials``."""
    scene = {"format": SCENE_FORMAT, "version": SCENE_VERSION, "scene_id": scene_id, "seed": 0,
             "time_of_day": "night", "timing": {"short_exposure_s": float(short_exposure_s)},
             "camera": {"position_m": [float(v) for v in position_m], "yaw_deg": 0.0, "pitch_deg": float(pitch_deg),
                        "fov_x_deg": float(fov_x_deg), "speed_mps": float(speed_mps),
                        "yaw_rate_rad_s": float(yaw_rate_rad_s)},
             "sky": {"model": "constant", "spectrum": {"model": "illuminant", "name": "D65"},
                     "luminance_cd_m2": float(sky_luminance_cd_m2)},
             "groups": {g: {"flicker": g in ("otherlights", "signals")} for g in GROUPS},
             "materials": {}, "objects": [], "lights": []}
    return validate_scene(scene)
