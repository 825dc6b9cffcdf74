"""The parts the scene generator (:mod:`render_tools.scene`) builds scenes from: the fixed materials, primitive
part constructors and one template per vehicle kind.

A vehicle kind is one entry of :data:`VEHICLE_TEMPLATES` (geometry, lamps, extra materials, lights by day) and its
name in :data:`lfmbench.vocabulary.VEHICLE_KINDS`; the generator has no kind-specific code. Lengths in metres in
the vehicle frame (x forward from the centre, y left, z up); lamp sizes (width, height) in metres.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["BASE_MATERIALS", "VEHICLE_TEMPLATES", "PARKED_KIND", "VEHICLE_MATERIALS", "box", "rect", "cylinder",
           "local_offset", "roof_z", "roof_mount", "gait", "posed_parts", "LEG_SWING_RAD"]

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
#: lamps, mirrored to both sides unless y = 0; ``cbrake``: a centre brake lamp (x, y, z, w, h) or None (generator 2
#: puts it where its body's ``chmsl`` says, :data:`VEHICLE_BODIES`); ``cargo``: a second drawn colour (a truck's box); ``lights_by_day``: lamps on whenever moving (motorcycles, buses);
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


# ------------------------------------------------------------------------------ scene generator 2: shapes
#: Scene generator 2's bodies (:func:`render_tools.shapes.body_meshes`): per kind the loft stations ``(x, z_bottom,
#: z_belt, z_top, width_scale, side_glass, top_glass)`` (m, vehicle frame, rear to front), width (m), roof inset
#: per side (m), extra boxes ((centre), (size), role) such as a truck's cargo box or a car's roof lip (over the
#: roof's rear edge and the top of the rear window), and ``chmsl``: the centre brake lamp (x, y, z, w, h) where it
#: differs from the template's ``cbrake`` (generator 1 keeps that one: lfmbench-v1's scenes do not change), its
#: top at least 1 cm under the roof line, on a body face. Motorcycles and bicycles are rigs of tubes and rings
#: (:func:`two_wheeler_parts`) with a small lofted body (motorcycle) and a rider. The lamps stay where
#: :data:`VEHICLE_TEMPLATES` puts them: each body's ends are at +-length / 2, just behind the lamp faces.
VEHICLE_BODIES = {
    "car": {"stations": [(-2.20, 0.32, 0.95, 0.96, 0.94, 0, 0), (-2.05, 0.25, 0.98, 1.00, 1.0, 0, 1),
                         (-1.45, 0.25, 0.98, 1.47, 1.0, 1, 0), (0.55, 0.25, 0.96, 1.45, 1.0, 1, 1),
                         (1.35, 0.25, 0.92, 0.93, 1.0, 0, 0), (2.05, 0.27, 0.82, 0.83, 0.98, 0, 0),
                         (2.20, 0.35, 0.78, 0.79, 0.92, 0, 0)],
            "width": 1.8, "roof_inset": 0.2, "boxes": [((-1.43, 0.0, 1.45), (0.14, 0.7, 0.08), "paint")],
            "chmsl": (-1.505, 0.0, 1.44, 0.5, 0.04)},
    "van": {"stations": [(-2.50, 0.35, 1.05, 1.88, 0.96, 0, 0), (-2.40, 0.30, 1.05, 1.95, 1.0, 1, 0),
                         (1.35, 0.30, 1.05, 1.95, 1.0, 1, 1), (2.10, 0.30, 1.00, 1.02, 1.0, 0, 0),
                         (2.50, 0.35, 0.92, 0.93, 0.95, 0, 0)],
            "width": 1.95, "roof_inset": 0.12, "boxes": [], "chmsl": (-2.505, 0.0, 1.84, 0.4, 0.05)},
    "bus": {"stations": [(-6.0, 0.40, 1.35, 3.0, 0.97, 0, 0), (-5.85, 0.35, 1.35, 3.1, 1.0, 1, 0),
                         (5.75, 0.35, 1.35, 3.1, 1.0, 1, 1), (6.0, 0.40, 1.30, 2.95, 0.97, 0, 0)],
            "width": 2.55, "roof_inset": 0.1,
            # window pillars across the side glass band, the two doors on the kerb side (-y), a dark skirt
            "boxes": [((px, sy * 1.22, 2.2), (0.14, 0.12, 1.7), "chassis") for px in (-4.55, -3.1, -1.65, -0.2, 1.25,
                                                                                       2.7, 4.15) for sy in (1, -1)]
            + [((5.0, -1.27, 1.55), (1.1, 0.04, 2.5), "chassis"), ((0.6, -1.27, 1.55), (1.1, 0.04, 2.5), "chassis"),
               ((0.0, 0.0, 0.47), (11.9, 2.58, 0.14), "chassis")],
            "panes": [((6.004, 0.0, 2.05), (2.2, 1.3), 1), ((-6.004, 0.0, 2.3), (2.0, 0.9), -1)]},
    "truck": {"stations": [(2.35, 0.55, 1.65, 3.0, 1.0, 0, 0), (3.40, 0.55, 1.65, 3.05, 1.0, 1, 0),
                           (4.35, 0.55, 1.65, 3.0, 1.0, 1, 1), (4.75, 0.60, 1.55, 2.7, 0.97, 0, 0)],
              "width": 2.4, "roof_inset": 0.08,
              # cargo box on a chassis; corner posts, the rear doors' seam and lock bars, under-run guards at the rear
              # and along the sides, a fuel tank
              "boxes": [((-1.2, 0.0, 2.35), (7.1, 2.5, 3.3), "cargo"), ((0.0, 0.0, 0.62), (8.6, 1.0, 0.3), "chassis")]
              + [((cx, sy * 1.235, 2.35), (0.07, 0.07, 3.32), "chassis") for cx in (-4.72, 2.32) for sy in (1, -1)]
              + [((-4.765, 0.0, 2.35), (0.03, 0.04, 3.1), "chassis"), ((-4.765, 0.62, 2.35), (0.03, 0.05, 3.0), "chassis"),
                 ((-4.765, -0.62, 2.35), (0.03, 0.05, 3.0), "chassis"), ((-4.62, 0.0, 0.5), (0.12, 2.3, 0.14), "chassis"),
                 ((0.15, 1.2, 0.62), (3.5, 0.04, 0.12), "chassis"), ((0.15, -1.2, 0.62), (3.5, 0.04, 0.12), "chassis"),
                 ((1.85, -0.95, 0.72), (0.9, 0.35, 0.45), "chassis")]},
    "motorcycle": {"stations": [(-0.85, 0.75, 0.90, 0.92, 0.6, 0, 0), (-0.35, 0.55, 0.85, 0.88, 0.8, 0, 0),
                                (0.05, 0.45, 0.95, 1.05, 1.0, 0, 0), (0.45, 0.50, 0.95, 1.00, 0.9, 0, 0),
                                (0.85, 0.75, 0.98, 1.00, 0.5, 0, 0)],
                   "width": 0.4, "roof_inset": 0.05, "boxes": []},
}


def roof_z(kind: str, x: float) -> float:
    """Height (m) of the roof of generator 2's lofted body of ``kind`` (:data:`VEHICLE_BODIES`) at ``x`` m along
    the vehicle frame: the loft's ``z_top``, linear between stations (the roof is flat across its width)."""
    st = VEHICLE_BODIES[kind]["stations"]
    return float(np.interp(x, [r[0] for r in st], [r[3] for r in st]))


def roof_mount(kind: str, length_m: float) -> tuple[float, float]:
    """Where a flat roof-mounted part ``length_m`` long goes on the body of ``kind``: ``(x, z)`` m in the vehicle
    frame, x the middle of the highest stretch of roof between two stations, z the roof's highest point under the
    part (so its base rests on the roof: no gap over ``|dz/dx| * length_m``, no overlap)."""
    st = VEHICLE_BODIES[kind]["stations"]
    a, b = max(zip(st, st[1:]), key=lambda ab: min(ab[0][3], ab[1][3]))
    x = 0.5 * (a[0] + b[0])
    return x, max(roof_z(kind, x - length_m / 2), roof_z(kind, x + length_m / 2))


def _lift(pts, x, y, heading, z0=0.0):
    """Vehicle-frame points (n, 3) m -> world (n, 3) m for a body at (x, y) heading ``heading`` (rad), raised z0."""
    out = []
    for px, py, pz in pts:
        dx, dy = local_offset(px, py, heading)
        out.append((x + dx, y + dy, pz + z0))
    return out


def person_parts(x, y, heading, height, phase, mats, riding=None) -> list:
    """A person as parts (articulated: limbs are tubes between joints, joints spheres), feet at (x, y, 0) m, facing
    ``heading`` (rad), ``height`` m tall, gait ``phase`` (rad). ``mats``: {"top", "legs", "skin"} material names.
    ``riding``: None (walking; torso the shared mesh ``torso``) or ``{"hip": (x, z), "hands": (x, z), "pedal":
    (x, z), "lean": rad}`` in the vehicle frame (m) for a rider (torso a tube from hip to shoulders)."""
    h = float(height)
    parts = []
    tube = lambda a, b, r, m: parts.append(cylinder(a, b, r, m))  # noqa: E731
    ball = lambda c, r, m: parts.append({"shape": "sphere", "center": [float(v) for v in c], "radius": float(r),  # noqa: E731
                                         "material": m})
    s = LEG_SWING_RAD * math.sin(phase)
    if riding is None:
        hipz, shz = 0.50 * h, 0.80 * h
        hip_x, sh_x = 0.0, 0.0
        legs = []
        for side, sw in ((1, s), (-1, -s)):
            hy = side * 0.085 * h
            knee = (hip_x + 0.24 * h * math.sin(sw), hy, hipz - 0.24 * h * math.cos(sw))
            bend = 0.35 * max(0.0, math.sin(phase + (0 if side > 0 else math.pi) + 1.2))
            ankle = (knee[0] + 0.23 * h * math.sin(sw - bend), hy, knee[2] - 0.23 * h * math.cos(sw - bend))
            legs.append(((hip_x, hy, hipz), knee, ankle))
        P = _lift([(0, 0, 0)], x, y, heading)[0]
        parts.append({"shape": "mesh", "mesh": "torso", "center": [P[0], P[1], 0.0], "yaw_deg": math.degrees(heading),
                      "scale": [h, h, h], "material": mats["top"]})
        arm_swing = [-0.7 * s, 0.7 * s]
    else:
        hx, hz = riding["hip"]
        lean = riding["lean"]
        hipz, hip_x = hz, hx
        sh_x, shz = hx + 0.30 * h * math.sin(lean), hz + 0.30 * h * math.cos(lean)
        legs = []
        px, pz = riding["pedal"]
        for side, ph in ((1, phase), (-1, phase + math.pi)):
            hy = side * 0.1 * h
            foot = (px + 0.17 * math.cos(ph), hy + side * 0.05, pz + 0.17 * math.sin(ph))
            d = math.dist((hip_x, hipz), (foot[0], foot[2]))
            lt = 0.245 * h
            mid = ((hip_x + foot[0]) / 2, (hipz + foot[2]) / 2)
            up = math.sqrt(max(lt * lt - (d / 2) ** 2, 0.0))  # the knee bends forward and up
            ux, uz = (foot[2] - hipz) / max(d, 1e-6), -(foot[0] - hip_x) / max(d, 1e-6)
            if ux < 0:
                ux, uz = -ux, -uz
            knee = (mid[0] + up * ux, hy, mid[1] + up * uz)
            legs.append(((hip_x, hy, hipz), knee, foot))
        tube(*_lift([(hip_x, 0, hipz), (sh_x, 0, shz)], x, y, heading), 0.085 * h, mats["top"])
        arm_swing = None
    for hip, knee, ankle in legs:
        a, k, an = _lift([hip, knee, ankle], x, y, heading)
        tube(a, k, 0.038 * h, mats["legs"])
        tube(k, an, 0.03 * h, mats["legs"])
        ball(k, 0.03 * h, mats["legs"])
        foot = _lift([(ankle[0] + 0.08 * h, ankle[1], ankle[2] - 0.01 * h)], x, y, heading)[0]
        tube(an, foot, 0.025 * h, mats["legs"])
    for k, side in enumerate((1, -1)):
        sh = (sh_x, side * 0.125 * h, shz - 0.02 * h)
        if arm_swing is not None:
            a = arm_swing[k]
            elbow = (sh[0] + 0.17 * h * math.sin(a), sh[1], sh[2] - 0.17 * h * math.cos(a))
            wrist = (elbow[0] + 0.16 * h * math.sin(a + 0.35), sh[1], elbow[2] - 0.16 * h * math.cos(a + 0.35))
        else:
            hx2, hz2 = riding["hands"]
            wrist = (hx2, side * 0.2 * h, hz2)
            elbow = ((sh[0] + wrist[0]) / 2, side * 0.17 * h, (sh[2] + wrist[2]) / 2 - 0.03 * h)
        s0, e0, w0 = _lift([sh, elbow, wrist], x, y, heading)
        tube(s0, e0, 0.026 * h, mats["top"])
        tube(e0, w0, 0.022 * h, mats["skin"])
        ball(s0, 0.03 * h, mats["top"])
    neck = _lift([(sh_x, 0, shz)], x, y, heading)[0]
    head = _lift([(sh_x + (0.03 * h if riding else 0.0), 0, shz + 0.11 * h)], x, y, heading)[0]
    tube(neck, (head[0], head[1], head[2] - 0.04 * h), 0.025 * h, mats["skin"])
    ball(head, 0.065 * h, mats["helmet"] if riding and "helmet" in mats else mats["skin"])
    return parts


#: Half-amplitude of a walker's leg swing about the hip, rad (:func:`person_parts`: thigh at +-0.45 rad).
LEG_SWING_RAD = 0.45
#: Hip-to-ankle length of a straight leg as a fraction of body height (thigh 0.24 + shank 0.23, :func:`person_parts`).
LEG_FRACTION = 0.47


def gait(x, y, heading, height, phase, mats, speed_mps: float) -> dict:
    """An object's ``gait`` (scene version 2): what :func:`posed_parts` needs to pose a walking person at any time.
    The gait cycle (two steps) lasts ``2 * step / speed`` with step length ``2 * LEG_FRACTION * height *
    sin(LEG_SWING_RAD)`` (0.41 x height: the distance the feet cover between the two extreme poses of
    :func:`person_parts`; close to the 0.41-0.45 x height of adult walking steps, Grieve and Gear 1966), so the
    feet do not slide over the ground at the walking speed. Lengths m, angles rad, frequency Hz."""
    step = 2.0 * LEG_FRACTION * float(height) * math.sin(LEG_SWING_RAD)
    return {"position_m": [float(x), float(y)], "heading_rad": float(heading), "height_m": float(height),
            "phase_rad": float(phase), "cycle_hz": abs(float(speed_mps)) / (2.0 * step),
            "materials": {k: mats[k] for k in ("top", "legs", "skin")}}


def posed_parts(obj: dict, t: float) -> list:
    """The parts of object ``obj`` at time ``t`` s, before its motion (``velocity_mps * t``) is applied: a walker
    (``gait``) in the pose of gait phase ``phase_rad + 2 pi cycle_hz t``; any other object its ``parts``."""
    g = obj.get("gait")
    if g is None:
        return obj["parts"]
    x, y = g["position_m"]
    return person_parts(x, y, g["heading_rad"], g["height_m"],
                        g["phase_rad"] + 2.0 * math.pi * g["cycle_hz"] * float(t), g["materials"])


def two_wheeler_parts(kind, x, y, heading, roles, rider_mats, phase) -> list:
    """Scene generator 2's motorcycle or bicycle with its rider, as parts in world coordinates (m): two wheel rings
    (shared meshes ``wheel_<kind>``), frame tubes, for a motorcycle its lofted body, and the rider."""
    w = VEHICLE_TEMPLATES[kind]["wheels"]
    parts = []
    for wx, r, _ in w:
        c = _lift([(wx, 0.0, r)], x, y, heading)[0]
        parts.append({"shape": "mesh", "mesh": f"wheel_{kind}", "center": list(c), "yaw_deg": math.degrees(heading),
                      "material": "rubber"})
        parts.append(cylinder(*_lift([(wx, -0.03, r), (wx, 0.03, r)], x, y, heading), 0.05, "metal"))
    tube = lambda pts, rad, m: parts.append(cylinder(*_lift(pts, x, y, heading), rad, m))  # noqa: E731
    if kind == "bicycle":
        rear, front = (w[1][0], w[1][1]), (w[0][0], w[0][1])
        bb, seat, head_t, bar = (-0.05, 0.32), (-0.22, 0.95), (0.38, 0.95), (0.42, 1.05)
        for a, b in ((rear, bb), (rear, seat), (bb, seat), (seat, head_t), (bb, head_t), (head_t, front),
                     (head_t, bar)):
            tube([(a[0], 0, a[1]), (b[0], 0, b[1])], 0.018, roles["paint"])
        tube([(bar[0], -0.25, bar[1]), (bar[0], 0.25, bar[1])], 0.014, "metal")
        parts.append(box(_lift([(-0.7, 0.0, 0.8)], x, y, heading)[0], (0.4, 0.12, 0.02), "metal", math.degrees(heading)))
        parts.append(box(_lift([(-0.885, 0.0, 0.75)], x, y, heading)[0], (0.02, 0.08, 0.12), "housing",
                         math.degrees(heading)))
        tube([(bar[0], 0, bar[1] - 0.05), (0.885, 0, 0.95)], 0.012, "metal")
        parts.append(box(_lift([(0.89, 0.0, 0.95)], x, y, heading)[0], (0.02, 0.08, 0.07), "housing",
                         math.degrees(heading)))
        riding = {"hip": (seat[0] - 0.02, seat[1] + 0.07), "hands": (bar[0], bar[1]), "pedal": bb, "lean": 0.45}
        height = 1.75
    else:
        rear, front = (w[1][0], w[1][1]), (w[0][0], w[0][1])
        tube([(front[0], 0.08, front[1]), (0.55, 0.08, 1.0)], 0.025, "metal")
        tube([(front[0], -0.08, front[1]), (0.55, -0.08, 1.0)], 0.025, "metal")
        tube([(0.55, -0.35, 1.08), (0.55, 0.35, 1.08)], 0.015, "metal")
        tube([(rear[0], 0.0, rear[1]), (-0.1, 0.0, 0.55)], 0.04, "metal")
        tube([(-0.3, 0.12, 0.35), (-0.8, 0.12, 0.45)], 0.04, "metal")  # exhaust
        parts.append({"shape": "mesh", "mesh": "body_motorcycle_paint", "center": [x, y, 0.0],
                      "yaw_deg": math.degrees(heading), "material": roles["paint"]})
        riding = {"hip": (-0.3, 1.0), "hands": (0.55, 1.08), "pedal": (0.0, 0.45), "lean": 0.35}
        height = 1.78
        phase = 0.0
    return parts + person_parts(x, y, heading, height, phase, rider_mats, riding)
