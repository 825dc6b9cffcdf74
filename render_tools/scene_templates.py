"""The parts the scene generator (:mod:`render_tools.scene`) builds scenes from: the fixed materials, primitive
part constructors and one template per vehicle kind.

A vehicle kind is one entry of :data:`VEHICLE_TEMPLATES` (geometry, lamps, extra materials, lights by day) and its
name in :data:`lfmbench.vocabulary.VEHICLE_KINDS`; the generator has no kind-specific code. Lengths in metres in
the vehicle frame (x forward from the centre, y left, z up); lamp sizes (width, height) in metres.
"""
from __future__ import annotations

import math

__all__ = ["BASE_MATERIALS", "VEHICLE_TEMPLATES", "PARKED_KIND", "VEHICLE_MATERIALS", "box", "rect", "cylinder",
           "local_offset"]

#: Materials every generated scene has (name -> Mitsuba-style material; rgb reflectance in [0, 1]).
BASE_MATERIALS = {
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

#: Material roles of a template's parts: ``paint`` and ``cargo`` are drawn per vehicle (``cargo`` only for a
#: template with ``cargo: True``), the others are base materials.
VEHICLE_MATERIALS = {"glass": "glass", "rider": "rubber"}

#: Vehicle templates. ``boxes``: ((centre), (size), material role); ``spheres``: ((centre), radius, role);
#: ``wheels``: (x, radius, half track: 0 = one wheel on the axis); ``tail``/``head``/``ind``: ((centre), (w, h))
#: lamps, mirrored to both sides unless y = 0; ``cbrake``: a centre brake lamp (x, y, z, w, h) or None; ``cargo``:
#: a second drawn colour (a truck's box); ``lights_by_day``: lamps on whenever moving (motorcycles, buses);
#: ``max_speed_mps`` (optional): the kind's top speed, m/s (a bicycle's drawn speed is capped at it).
VEHICLE_TEMPLATES = {
    "car": {"length": 4.4, "boxes": [((0.0, 0.0, 0.68), (4.4, 1.8, 0.66), "paint"),
                                     ((-0.35, 0.0, 1.28), (2.3, 1.6, 0.56), "glass")],
            "spheres": [], "wheels": [(1.35, 0.33, 0.8), (-1.35, 0.33, 0.8)], "wheel_w": 0.22,
            "tail": [((-2.205, 0.62, 0.86), (0.32, 0.12))], "head": [((2.205, 0.62, 0.72), (0.26, 0.11))],
            "cbrake": (-1.52, 0.0, 1.54, 0.5, 0.06), "ind": [((-2.205, 0.82, 0.72), (0.1, 0.07))],
            "cargo": False, "lights_by_day": False},
    "truck": {"length": 9.5, "boxes": [((3.55, 0.0, 1.85), (2.4, 2.4, 2.6), "paint"),
                                       ((-1.2, 0.0, 2.35), (7.1, 2.5, 3.3), "cargo"),
                                       ((4.56, 0.0, 2.35), (0.4, 2.2, 1.0), "glass")],
              "spheres": [], "wheels": [(3.4, 0.5, 1.0), (-2.5, 0.5, 1.0), (-3.8, 0.5, 1.0)], "wheel_w": 0.3,
              "tail": [((-4.755, 1.0, 1.0), (0.3, 0.15))], "head": [((4.755, 0.9, 1.0), (0.3, 0.14))],
              "cbrake": None, "ind": [((-4.755, 1.15, 1.25), (0.12, 0.1))], "cargo": True, "lights_by_day": False},
    "motorcycle": {"length": 2.1, "boxes": [((0.0, 0.0, 0.72), (1.7, 0.35, 0.45), "paint"),
                                           ((-0.2, 0.0, 1.3), (0.4, 0.45, 0.7), "rider")],
                   "spheres": [((-0.2, 0.0, 1.8), 0.15, "paint")],
                   "wheels": [(0.75, 0.32, 0.0), (-0.75, 0.32, 0.0)], "wheel_w": 0.12,
                   "tail": [((-0.865, 0.0, 0.9), (0.14, 0.07))], "head": [((0.865, 0.0, 0.95), (0.16, 0.1))],
                   "cbrake": None, "ind": [], "cargo": False, "lights_by_day": True},
    "van": {"length": 5.0, "boxes": [((0.0, 0.0, 1.15), (5.0, 1.95, 1.6), "paint"),
                                     ((0.6, 0.0, 1.55), (3.0, 2.0, 0.5), "glass")],
            "spheres": [], "wheels": [(1.7, 0.35, 0.85), (-1.7, 0.35, 0.85)], "wheel_w": 0.24,
            "tail": [((-2.505, 0.8, 1.0), (0.2, 0.3))], "head": [((2.505, 0.72, 0.8), (0.3, 0.12))],
            "cbrake": (-2.505, 0.0, 1.88, 0.4, 0.05), "ind": [((-2.505, 0.86, 0.72), (0.1, 0.08))],
            "cargo": False, "lights_by_day": False},
    "bus": {"length": 12.0, "boxes": [((0.0, 0.0, 1.75), (12.0, 2.55, 2.8), "paint"),
                                      ((0.2, 0.0, 2.35), (11.2, 2.6, 1.0), "glass")],
            "spheres": [], "wheels": [(3.9, 0.5, 1.05), (-3.4, 0.5, 1.05)], "wheel_w": 0.3,
            "tail": [((-6.005, 1.05, 1.1), (0.2, 0.35))], "head": [((6.005, 0.95, 0.75), (0.3, 0.15))],
            "cbrake": (-6.005, 0.0, 2.9, 0.6, 0.06), "ind": [((-6.005, 1.15, 1.45), (0.12, 0.1))],
            "cargo": False, "lights_by_day": True},
    "bicycle": {"length": 1.8, "boxes": [((0.0, 0.0, 0.75), (1.0, 0.06, 0.06), "paint"),
                                         ((-0.15, 0.0, 1.2), (0.35, 0.4, 0.6), "rider")],
                "spheres": [((-0.1, 0.0, 1.65), 0.12, "rider")],
                "wheels": [(0.55, 0.34, 0.0), (-0.55, 0.34, 0.0)], "wheel_w": 0.04,
                "tail": [((-0.905, 0.0, 0.75), (0.06, 0.04))], "head": [((0.905, 0.0, 0.95), (0.06, 0.05))],
                "cbrake": None, "ind": [], "cargo": False, "lights_by_day": False, "max_speed_mps": 8.0},
}

#: The kind of the parked vehicles along the kerbs.
PARKED_KIND = "car"


def box(center, size, material, yaw_deg=0.0) -> dict:
    """A box part: centre (m), size (m, along x, y, z before the yaw), yaw (deg)."""
    return {"shape": "box", "center": [float(c) for c in center], "size": [float(s) for s in size],
            "yaw_deg": float(yaw_deg), "material": material}


def rect(center, size, normal, material) -> dict:
    """A rectangle part: centre (m), size (m, w x h), normal (unit vector)."""
    return {"shape": "rect", "center": [float(c) for c in center], "size": [float(s) for s in size],
            "normal": [float(n) for n in normal], "material": material}


def cylinder(p0, p1, radius, material) -> dict:
    """A cylinder part between end points p0, p1 (m) of ``radius`` (m)."""
    return {"shape": "cylinder", "p0": [float(c) for c in p0], "p1": [float(c) for c in p1],
            "radius": float(radius), "material": material}


def local_offset(x, y, heading):
    """Vehicle-local (x fwd, y left) offset (m) -> world xy offset (m) for ``heading`` (rad)."""
    c, s = math.cos(heading), math.sin(heading)
    return c * x - s * y, s * x + c * y
