"""Street content of scene generator 2 (protocol lfmbench-v2): the steps :func:`render_tools.scene.generate_scene`
runs after the traffic signal when ``generator=2``, each drawing from the scene's one random generator, in the
order of :func:`add_street`.

- :func:`add_weather`: the road surface of ``weather.conditions`` (dry, wet, rain): a wet road is a rough
  dielectric water film (index ``water_ior``) over a darker diffuse asphalt (Mitsuba ``roughplastic``), with
  puddles (smoother film, irregular flat meshes) so that lamps reflect in it.

The steps take the :class:`render_tools.scene.SceneBuilder` (``b``) and the :class:`render_tools.scene.Road`
(``road``) of the scene; lengths in metres, speeds in m/s, world frame as :mod:`render_tools.scene`.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["add_street", "add_weather", "WET_ROAD_MATERIAL", "PUDDLE_MATERIAL"]

#: Material names of the wet road film and of the puddles.
WET_ROAD_MATERIAL = "asphalt_wet"
PUDDLE_MATERIAL = "puddle"
#: Corners of a puddle outline (an irregular star-shaped polygon).
PUDDLE_CORNERS = 14


def add_street(b, road, cam_y: float, dark: bool) -> str:
    """All steps of generator 2, in order; returns the scene's weather (``scene.weather``)."""
    return add_weather(b, road)


def _puddle_mesh(rng: np.random.Generator) -> dict:
    """A flat, irregular, unit-size puddle outline (star-shaped, radius 0.5 +- 0.15) as a triangle fan in the
    plane z = 0, facing +z: ``{"vertices": (n + 1, 3) m, "faces": (n, 3)}``."""
    ang = 2 * math.pi * (np.arange(PUDDLE_CORNERS) + rng.uniform(-0.3, 0.3, PUDDLE_CORNERS)) / PUDDLE_CORNERS
    r = 0.5 * (1.0 + rng.uniform(-0.3, 0.3, PUDDLE_CORNERS))
    V = [[0.0, 0.0, 0.0]] + [[round(float(ri * math.cos(a)), 4), round(float(ri * math.sin(a)), 4), 0.0]
                             for ri, a in zip(r, ang)]
    F = [[0, 1 + i, 1 + (i + 1) % PUDDLE_CORNERS] for i in range(PUDDLE_CORNERS)]
    return {"vertices": V, "faces": F}


def add_weather(b, road) -> str:
    """The weather of the scene, drawn from ``weather.conditions``; for ``wet`` and ``rain`` the road's asphalt
    becomes :data:`WET_ROAD_MATERIAL` and puddles (``weather.puddles`` of the condition, ``puddle_size_m`` across,
    on the road ahead) are added to the road object. Returns the condition."""
    wc = b.cfg["weather"]
    rng = b.rng
    cond = wc["conditions"][int(rng.integers(0, len(wc["conditions"])))]
    if cond == "dry":
        return cond
    alpha = b.u(wc["rain_alpha"] if cond == "rain" else wc["wet_alpha"])
    b.materials[WET_ROAD_MATERIAL] = {"type": "roughplastic", "rgb": [float(c) for c in wc["wet_rgb"]],
                                      "alpha": round(alpha, 4), "ior": float(wc["water_ior"])}
    b.materials[PUDDLE_MATERIAL] = {"type": "roughplastic", "rgb": [float(c) for c in wc["wet_rgb"]],
                                    "alpha": float(wc["puddle_alpha"]), "ior": float(wc["water_ior"])}
    road_obj = next(o for o in b.objects if o["kind"] == "road")
    for part in road_obj["parts"]:
        if part["material"] == "asphalt":
            part["material"] = WET_ROAD_MATERIAL
    shapes = [f"puddle{k}" for k in range(3)]
    for name in shapes:
        b.meshes[name] = _puddle_mesh(rng)
    half = road.half_width_m - road.park_m
    for _ in range(b.ui(wc["puddles"][cond])):
        size = b.u(wc["puddle_size_m"])
        road_obj["parts"].append({"shape": "mesh", "mesh": shapes[int(rng.integers(0, len(shapes)))],
                                  "center": [round(b.u((2.0, 120.0)), 3), round(b.u((-half, half)), 3), 0.002],
                                  "yaw_deg": round(b.u((0.0, 180.0)), 2),
                                  "scale": [round(size, 3), round(size * b.u((0.4, 0.9)), 3), 1.0],
                                  "material": PUDDLE_MATERIAL})
    return cond
