"""Lamp clusters and LED displays of scene generator 2 (protocol lfmbench-v2), each lamp a light with its own
timing (:mod:`lfmbench.flicker.waveforms`).

- :func:`add_vehicle_lamps`: a vehicle's lamp cluster as real lamps build it: segmented tail lamps and an LED
  strip, separate brake lamps, a centre high-mounted stop lamp (``chmsl``, an LED strip), a blinking
  ``indicator`` (1-2 Hz on top of its PWM), daytime-running lights (``drl``, lit whenever the vehicle moves),
  matrix (a row of segments, each a headlight with its beam) or projector headlights, an emergency light bar
  (``strobe``: multi-flash patterns, the two sides half a cycle apart) and, on a bus, destination displays.
  A lamp's segments share one ``driver`` (one PWM draw) unless the vehicle's segments are unsynchronised
  (``lamps.unsynchronised_segments``): then each segment draws its own PWM.
- :func:`add_displays`: the street's LED sources: message signs (``message_sign``: a pixel matrix showing a
  text, one light per scan line (the rows it drives) with that line's phase,
  :class:`lfmbench.flicker.waveforms.ScanRow`),
  a countdown display under the traffic signal (``countdown``: a light per seven-segment bar) and the signal
  aspects as LED arrays (a disk of LED dots).
- :func:`add_message_sign`, :func:`add_destination_display`, :func:`add_countdown`: the single elements, also for
  hand-made scenes.

Settings: section ``lamps`` of ``render_tools/configs/scene_generator_v2.yaml``. Lengths in metres in the
vehicle frame (x forward from the centre, y left, z up), luminances in cd/m^2 at the lamp's ON level, times in s.
Every draw comes from the scene's one random generator ``b.rng``.
"""
from __future__ import annotations

import math

import numpy as np

from lfmbench.flicker.waveforms import CountdownSegment

from . import led_matrix
from .scene_templates import VEHICLE_BODIES, box, local_offset, roof_mount

__all__ = ["add_vehicle_lamps", "add_displays", "add_message_sign", "add_destination_display", "add_countdown",
           "led_array_signals", "segment_faces"]

#: Seven-segment bars of a digit of height 1 (width 0.55): segment -> (centre x, centre z, width, height) with x
#: to the right seen from the front and z up from the digit's centre.
_SEGMENT_BARS = {"a": (0.0, 0.45, 0.4, 0.08), "b": (0.22, 0.22, 0.08, 0.38), "c": (0.22, -0.22, 0.08, 0.38),
                 "d": (0.0, -0.45, 0.4, 0.08), "e": (-0.22, -0.22, 0.08, 0.38), "f": (-0.22, 0.22, 0.08, 0.38),
                 "g": (0.0, 0.0, 0.4, 0.08)}


def _light(b, kind, oid, shape, spectrum, luminance, spread=90.0, waveform=None, driver=None) -> int:
    """``b.light`` plus the version-2 fields ``waveform`` and ``driver`` (left out when None); returns the id."""
    lid = b.light(kind, oid, shape, spectrum, luminance, spread)
    if waveform is not None:
        b.lights[lid]["waveform"] = waveform
    if driver is not None:
        b.lights[lid]["driver"] = driver
    return lid


def _frame(normal) -> tuple[np.ndarray, np.ndarray]:
    """(right, up) unit vectors in a vertical face with horizontal ``normal``, seen from the front (the frame of
    :mod:`render_tools.mitsuba_scene` for faces that are not horizontal)."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    up = np.array([0.0, 0.0, 1.0])
    return np.cross(up, n), up


def segment_faces(center, size, normal, segments: int, together: bool, gap: float = 0.1) -> list[dict]:
    """A lamp of ``size`` (w, h) m centred on ``center`` (3,) m facing ``normal``, split into ``segments`` side by
    side (each ``1 - gap`` of its share of the width, the full height): one ``dots`` face holding every segment
    when ``together`` (one light: segments on one driver), else one face per segment (a light each)."""
    w, h = size
    dot = 1.0 - gap
    face = {"shape": "dots", "center": [float(v) for v in center], "normal": [float(v) for v in normal],
            "size": [float(w), float(h) / dot], "grid": [int(segments), 1], "dot": dot}
    if together:
        return [{**face, "cells": [[k, 0] for k in range(segments)]}]
    return [{**face, "cells": [[k, 0]]} for k in range(segments)]


def _strip(center, width, height, normal, pitch=0.025, dot=0.6) -> dict:
    """A one-row LED strip of dots every ``pitch`` m across ``width`` m (a ``dots`` face, all dots lit)."""
    n = max(2, int(round(width / pitch)))
    return {"shape": "dots", "center": [float(v) for v in center], "normal": [float(v) for v in normal],
            "size": [float(width), float(height)], "grid": [n, 1], "dot": dot, "cells": [[c, 0] for c in range(n)]}


def _at(x, y, heading, lx, ly, lz) -> list[float]:
    dx, dy = local_offset(lx, ly, heading)
    return [float(x + dx), float(y + dy), float(lz)]


def add_vehicle_lamps(b, kind: str, t: dict, oid: int, x: float, y: float, heading: float, speed: float,
                      lights_on: bool, braking: bool, indicator: bool) -> None:
    """The lamp cluster of vehicle ``oid`` of ``kind`` (template ``t`` of
    :data:`render_tools.scene_templates.VEHICLE_TEMPLATES`: its ``tail``, ``head``, ``ind`` and ``cbrake`` lamp
    places) at (x, y) m, heading (rad), speed (m/s): tail segments, LED strip and headlights when ``lights_on``,
    brake lamps and CHMSL when ``braking``, one blinking indicator when ``indicator``, DRLs whenever it moves, a
    strobe light bar on some cars and vans, destination displays on a bus."""
    kc, lc = b.cfg["lamps"], b.cfg["lights"]
    rng = b.rng
    fwd = (math.cos(heading), math.sin(heading), 0.0)
    back = (-fwd[0], -fwd[1], 0.0)
    sync = not rng.random() < kc["unsynchronised_segments"]
    segs = b.ui(kc["tail_segments"])
    tail_spread = lc["tail_spread_deg"]

    def drv(name):
        return f"o{oid}.{name}" if sync else None

    def sides(ly):
        return (1, -1) if ly != 0 else (0,)

    if lights_on:
        lum = b.other_luminance()
        for (lx, ly, lz), (w, h) in t["tail"]:
            for s in sides(ly):
                for face in segment_faces(_at(x, y, heading, lx, s * ly, lz), (w, h * 0.45), back,
                                          segs if w >= 0.1 else 1, sync):
                    _light(b, "tail", oid, face, lc["led_red"], lum, tail_spread, driver=drv("tail"))
        if len(t["tail"]) and t["tail"][0][0][1] > 0.3 and rng.random() < kc["led_strip_probability"]:
            (lx, ly, lz), (w, h) = t["tail"][0]
            _light(b, "tail", oid, _strip(_at(x, y, heading, lx - 0.002, 0.0, lz + h * 0.1),
                                          2 * ly - w, 0.02, back), lc["led_red"], lum, tail_spread,
                   driver=drv("tail"))
        head_lum = b.u(lc["headlight_luminance_cd_m2"])
        spread = b.u(lc["headlight_spread_deg"])
        matrix = rng.random() < kc["matrix_headlight_probability"]
        n_matrix = b.ui(kc["matrix_segments"])
        for (lx, ly, lz), (w, h) in t["head"]:
            for s in sides(ly):
                c = _at(x, y, heading, lx, s * ly, lz)
                if matrix and w >= 0.15:
                    for face in segment_faces(c, (w, h * 0.6), fwd, n_matrix, sync, gap=0.15):
                        _light(b, "headlight", oid, face, lc["led_white"], head_lum, spread, driver=drv("head"))
                else:
                    _light(b, "headlight", oid, {"shape": "disk", "center": c, "normal": list(fwd),
                                                 "radius": 0.45 * min(w, h)}, lc["led_white"], head_lum, spread,
                           driver=drv("head"))
    if speed > 0 and rng.random() < kc["drl_probability"]:
        lum = b.other_luminance() * kc["drl_luminance_factor"]
        for (lx, ly, lz), (w, h) in t["head"]:
            for s in sides(ly):
                _light(b, "drl", oid, _strip(_at(x, y, heading, lx + 0.002, s * ly, lz + 0.55 * h + 0.02),
                                             w, 0.018, fwd), lc["led_white"], lum, tail_spread, driver=drv("drl"))
    if braking:
        lum = min(max(b.other_luminance(), b.other_luminance()) * 3.0, b.head_peak * lc["other_ratio_log"][1])
        for (lx, ly, lz), (w, h) in t["tail"]:
            for s in sides(ly):
                for face in segment_faces(_at(x, y, heading, lx - 0.003, s * ly, lz + h * 0.3), (w, h * 0.3),
                                          back, segs if w >= 0.1 else 1, sync):
                    _light(b, "brake", oid, face, lc["led_red"], lum, tail_spread, driver=drv("brake"))
        cbrake = VEHICLE_BODIES.get(kind, {}).get("chmsl", t["cbrake"])  # on generator 2's body
        if cbrake is not None:
            cx, cy, cz, w, h = cbrake
            _light(b, "chmsl", oid, _strip(_at(x, y, heading, cx, cy, cz), w, h, back), lc["led_red"], lum,
                   tail_spread, driver=drv("brake"))
    if indicator and t["ind"]:
        (lx, ly, lz), (w, h) = t["ind"][0]
        side = 1 if rng.random() < 0.5 else -1
        f = b.u(kc["indicator_hz"])
        wf = {"kind": "indicator", "frequency_hz": round(f, 4), "on_fraction": round(b.u(kc["indicator_on_fraction"]), 4),
              "phase_s": round(float(rng.uniform(0.0, 1.0 / f)), 6)}
        lum = b.other_luminance()
        for end, normal in ((lx - 0.003, back), (-lx + 0.003, fwd)):   # rear and front repeater of that side
            _light(b, "indicator", oid, {"shape": "rect", "center": _at(x, y, heading, end, side * ly, lz),
                                         "normal": list(normal), "size": [w, h]}, lc["led_amber"], lum,
                   tail_spread, waveform=wf, driver=f"o{oid}.indicator")
    if kind in ("car", "van") and speed > 0 and rng.random() < kc["emergency_probability"]:
        _light_bar(b, t, oid, x, y, heading, fwd, back, kind)
    if kind == "bus" and speed > 0:
        texts = kc["bus_texts"][int(rng.integers(0, len(kc["bus_texts"])))]
        half = t["length"] / 2 + 0.006
        top = max(c[2] + s[2] / 2 for c, s, _ in t["boxes"])
        lum = b.other_luminance() * kc["display_luminance_factor"]
        for end, normal, name in ((-half, back, "rear_display"), (half, fwd, "front_display")):
            add_destination_display(b, oid, _at(x, y, heading, end, 0.0, top - 0.3), normal, list(texts),
                                    grid=(96, 8), pitch_m=0.014 if end > 0 else 0.01, scan_lines=4,
                                    luminance=lum, name=name)


#: Emergency light bar: (length along the vehicle, width, height) m of its housing; height of its lamp faces, m.
LIGHT_BAR_M = (0.26, 1.2, 0.1)
LIGHT_BAR_FACE_H_M = 0.09


def _light_bar(b, t, oid, x, y, heading, fwd, back, kind: str) -> None:
    """An emergency light bar on the roof: a housing resting on the lofted body's roof
    (:func:`render_tools.scene_templates.roof_mount`) with a red (left) and a blue (right) strobe head on its back
    and front faces, the two sides half a cycle apart."""
    kc, lc = b.cfg["lamps"], b.cfg["lights"]
    bl, bw, bh = LIGHT_BAR_M
    xs, roof = roof_mount(kind, bl)
    b.objects[oid]["parts"].append(box(_at(x, y, heading, xs, 0.0, roof + bh / 2), (bl, bw, bh), "housing",
                                       math.degrees(heading)))
    cyc = b.u(kc["strobe_cycle_s"])
    flashes = b.ui(kc["strobe_flashes"])
    flash = b.u(kc["strobe_flash_s"])
    gap = min(flash, (cyc / 2 - flashes * flash) / max(flashes - 1, 1))
    phase = float(b.rng.uniform(0.0, cyc))
    lum = b.head_peak * kc["strobe_luminance_factor"]
    for side, spec, shift in ((1, kc["strobe_blue"], 0.0), (-1, lc["led_red"], cyc / 2)):
        wf = {"kind": "strobe", "cycle_s": round(cyc, 4), "flashes": flashes, "flash_s": round(flash, 4),
              "gap_s": round(max(gap, 0.0), 4), "phase_s": round((phase + shift) % cyc, 6)}
        for end, normal in ((xs - bl / 2 - 0.002, back), (xs + bl / 2 + 0.002, fwd)):
            _light(b, "strobe", oid, {"shape": "rect", "center": _at(x, y, heading, end, side * 0.3, roof + bh / 2),
                                      "normal": list(normal), "size": [0.45, LIGHT_BAR_FACE_H_M]}, spec, lum, 90.0,
                   waveform=wf, driver=f"o{oid}.strobe{side}")


def _matrix_face(center, normal, grid, pitch_m) -> dict:
    return {"center": [float(v) for v in center], "normal": [float(v) for v in normal],
            "size": [grid[0] * pitch_m, grid[1] * pitch_m], "grid": [int(grid[0]), int(grid[1])]}


def add_message_sign(b, oid: int, center, normal, text: str, grid=(60, 9), pitch_m: float = 0.05,
                     scan_lines: int = 8, luminance: float = 5000.0, spectrum=None, dot: float = 0.7) -> list[int]:
    """A row-multiplexed LED message sign on object ``oid`` showing ``text``: the object gets its ``display``
    (texts, grid, scan_lines), and each scan line with lit dots becomes one ``message_sign`` light (a ``dots``
    face of the dots of the rows it drives, rows ``line``, ``line + scan_lines``, ...: they are ON at the same
    times; waveform ``scan_row``; one driver: the lines share the sign's PWM draw and differ in phase).

    Args:
        center: (3,) m centre of the matrix. normal: (3,) horizontal facing direction. grid: (columns, rows).
        pitch_m: dot pitch, m. luminance: cd/m^2 of a dot while ON. spectrum: default the config's amber LED.
    Returns:
        The light ids, scan line 0 first.
    """
    spectrum = spectrum or b.cfg["lights"]["led_amber"]
    b.objects[oid]["display"] = {"texts": [text], "grid": [int(grid[0]), int(grid[1])], "scan_lines": int(scan_lines)}
    return _scan_lights(b, "message_sign", oid, led_matrix.text_cells(text, grid),
                        _matrix_face(center, normal, grid, pitch_m), dot, int(scan_lines), spectrum, luminance,
                        lambda line: {"kind": "scan_row", "scan_lines": int(scan_lines), "line": line},
                        f"o{oid}.sign")


def _scan_lights(b, kind, oid, cells, face, dot, scan_lines, spectrum, luminance, waveform, driver) -> list[int]:
    """One light per scan line of a multiplexed matrix: the lit ``cells`` of the rows that line drives (row mod
    ``scan_lines``), waveform ``waveform(line)``, all on ``driver``. Returns the light ids."""
    ids = []
    for line in sorted({r % scan_lines for _, r in cells}):
        shape = {"shape": "dots", **face, "dot": dot, "cells": [c for c in cells if c[1] % scan_lines == line]}
        ids.append(_light(b, kind, oid, shape, spectrum, luminance, waveform=waveform(line), driver=driver))
    return ids


def add_destination_display(b, oid: int, center, normal, texts: list[str], grid=(96, 8), pitch_m: float = 0.012,
                            scan_lines: int = 4, luminance: float = 2000.0, page_s: float = 3.0,
                            spectrum=None, dot: float = 0.7, name: str = "display") -> list[int]:
    """A bus destination display on object ``oid``: an LED matrix like :func:`add_message_sign` showing
    ``texts`` in turn, ``page_s`` s each (waveform ``destination_display``); one light per page and scan line, all on
    driver ``o<oid>.<name>``. Texts that do not fit the grid are shortened at the end; the object's ``display``
    records the first display placed on it. Returns the light ids."""
    spectrum = spectrum or b.cfg["lights"]["led_amber"]
    fit = (grid[0] + 1) // (led_matrix.GLYPH_W + 1)
    texts = [tx[:fit].strip() or tx[:fit] for tx in texts]
    disp = {"texts": texts, "grid": [int(grid[0]), int(grid[1])], "scan_lines": int(scan_lines)}
    b.objects[oid].setdefault("display", disp)
    face = _matrix_face(center, normal, grid, pitch_m)
    ids = []
    for page, text in enumerate(texts):
        ids += _scan_lights(b, "destination_display", oid, led_matrix.text_cells(text, grid), face, dot,
                            int(scan_lines), spectrum, luminance,
                            lambda line, page=page: {"kind": "destination_display", "scan_lines": int(scan_lines),
                                                     "line": line, "pages": len(texts), "page": page,
                                                     "page_s": float(page_s), "phase_s": 0.0},
                            f"o{oid}.{name}")
    return ids


def add_countdown(b, oid: int, center, normal, digit_h: float, count_from: int, phase_s: float,
                  luminance: float, spectrum, tick_s: float = 1.0, blank_s: float = 0.0) -> list[int]:
    """A two-digit seven-segment countdown display on object ``oid`` (centre (3,) m, facing ``normal``, digits
    ``digit_h`` m high) counting ``count_from`` .. 1 every ``tick_s`` s, dark for ``blank_s`` s, from
    ``phase_s`` s: one ``countdown`` light per bar that is ever lit, all on one driver. Returns the light ids."""
    right, up = _frame(normal)
    ids = []
    for place, dx in (("tens", -0.35), ("units", 0.35)):
        for seg, (sx, sz, sw, sh) in _SEGMENT_BARS.items():
            wf = {"kind": "countdown", "count_from": int(count_from), "tick_s": float(tick_s),
                  "blank_s": float(blank_s), "place": place, "segment": seg, "phase_s": float(phase_s)}
            if not any(_lit(place, seg, v) for v in range(1, count_from + 1)):
                continue
            c = np.asarray(center, dtype=float) + digit_h * ((dx + sx) * right + sz * up)
            ids.append(_light(b, "countdown", oid, {"shape": "rect", "center": [float(v) for v in c],
                                                   "normal": [float(v) for v in normal],
                                                   "size": [sw * digit_h, sh * digit_h]}, spectrum, luminance,
                              waveform=wf, driver=f"o{oid}.countdown"))
    return ids


def _lit(place: str, seg: str, value: int) -> bool:
    return CountdownSegment(place=place, segment=seg).shown(value)


def led_array_signals(b, n: int = 13, dot: float = 0.7) -> None:
    """The traffic-signal aspects as LED arrays: each ``signal`` light's disk becomes a disk of ``n`` x ``n`` LED
    dots (:func:`render_tools.led_matrix.disk_cells`) of the same luminous flux (the dots' luminance scaled by the
    disk's area over the dots' area)."""
    cells = led_matrix.disk_cells(n)
    for lt in b.lights:
        if lt["kind"] != "signal" or lt["shape"] != "disk":
            continue
        r = lt.pop("radius")
        face = {"shape": "dots", "size": [2 * r, 2 * r], "grid": [n, n], "dot": dot, "cells": cells}
        disk_area = math.pi * r * r
        lt.update(face)
        lt["luminance_cd_m2"] = float(lt["luminance_cd_m2"] * disk_area / led_matrix.dots_area(lt))


def add_displays(b, road, dark: bool) -> None:
    """Street step of generator 2: the signal aspects as LED arrays, a countdown display under the signal's low
    head (``lamps.countdown_probability``), and ``lamps.message_signs`` LED message signs at the kerbs ahead,
    facing the camera."""
    kc, lc = b.cfg["lamps"], b.cfg["lights"]
    rng = b.rng
    led_array_signals(b)
    pole = next((o for o in b.objects if o["kind"] == "signal_pole"), None)
    if pole is not None and rng.random() < kc["countdown_probability"]:
        sx, py, _ = pole["parts"][0]["p0"]
        count_from = b.ui(kc["countdown_from"])
        tick = 1.0
        period = count_from * tick + b.u(kc["countdown_blank_s"])
        spec = lc["led_red"] if rng.random() < 0.5 else lc["led_green"]
        lum = b.u(lc["signal_luminance_cd_m2"]) * 0.5
        parts = [{"shape": "box", "center": [sx - 0.1, py, 2.2], "size": [0.12, 0.5, 0.4], "yaw_deg": 0.0,
                  "material": "housing"}]
        pole["parts"].extend(parts)
        add_countdown(b, pole["id"], (sx - 0.165, py, 2.2), (-1.0, 0.0, 0.0), 0.3, count_from,
                      float(rng.uniform(0.0, period)), lum, spec, tick, period - count_from * tick)
    for _ in range(b.ui(kc["message_signs"])):
        side = 1 if rng.random() < 0.5 else -1
        sx = b.u(kc["message_sign_distance_m"])
        cols, rows = kc["message_sign_grids"][int(rng.integers(0, len(kc["message_sign_grids"])))]
        pitch = b.u(kc["message_sign_pitch_m"])
        fit = (cols + 1) // (led_matrix.GLYPH_W + 1)
        texts = [tx for tx in kc["message_texts"] if len(tx) <= fit] or [kc["message_texts"][0][:fit]]
        text = texts[int(rng.integers(0, len(texts)))]
        scan = int(kc["message_scan_lines"][int(rng.integers(0, len(kc["message_scan_lines"])))])
        w, h = cols * pitch, rows * pitch
        sy = side * (road.half_width_m + road.sidewalk_m * 0.5)
        z = 2.5 + h / 2
        parts = [{"shape": "box", "center": [sx + 0.08, sy, z], "size": [0.14, w + 0.2, h + 0.2], "yaw_deg": 0.0,
                  "material": "housing"},
                 {"shape": "cylinder", "p0": [sx + 0.1, sy, 0.0], "p1": [sx + 0.1, sy, z - h / 2], "radius": 0.08,
                  "material": "metal"}]
        oid = b.obj("message_sign", parts)
        lum = b.u(kc["message_sign_luminance_cd_m2"]) * scan
        spec = lc["led_amber"] if rng.random() < 0.7 else lc["led_white"]
        add_message_sign(b, oid, (sx - 0.002, sy, z), (-1.0, 0.0, 0.0), text, (cols, rows), pitch, min(scan, rows),
                         lum, spec)
