"""Fake render data: a ``render_frames`` stand-in (seeded random radiance of the right shapes, from the real
``scene_meta``) for testing the render orchestration without Mitsuba, the options of a tiny render, and a small
hand-made scene (two lamp panels) for the physics tests, and :func:`street` (a ground and wall lit by a tail lamp and a
streetlight) for the tracer tests.
"""
from __future__ import annotations

import os
import signal

import numpy as np

from lfmbench import corpus as C
from render_tools import jobs as J
from render_tools import scene

CALLS: list[str] = []
FAIL: dict[str, type] = {}  # scene_id -> exception type raised after its first frame

def mitsuba_sigint(msg):
    """What Mitsuba does with Ctrl-C, for :data:`FAIL`: the SIGINT handler raises KeyboardInterrupt inside the
    render, and the render loop turns it into a RuntimeError whose message does not say so."""
    try:
        signal.raise_signal(signal.SIGINT)
    except KeyboardInterrupt:
        return RuntimeError("drjit: render loop aborted")
    raise AssertionError("SIGINT did not raise")

#: Environment variable ``scene_id:SIGNAME[,scene_id:SIGNAME...]``: the fake render of each named scene kills its
#: process with that signal after the first frame (a native crash, as Dr.Jit's SIGFPE; reaches spawned worker
#: processes too).
CRASH_ENV = "LFMBENCH_TEST_CRASH"


def fake_render_frames(scene, opts):
    """Frames with the shapes ``render_tools.render.render_frames`` yields, from the real ``scene_meta``."""
    from render_tools.render import scene_meta

    CALLS.append(scene["scene_id"])
    meta = scene_meta(scene, opts)
    rng = np.random.default_rng(opts.seed)
    C_, H, W, K = len(opts.bands_nm), opts.height, opts.width, opts.bins
    for n in range(opts.frames):
        if n == 1 and scene["scene_id"] in FAIL:
            raise FAIL[scene["scene_id"]]("simulated failure")
        crash = dict(c.split(":") for c in os.environ.get(CRASH_ENV, "").split(",") if c)
        if n == 1 and scene["scene_id"] in crash:
            os.kill(os.getpid(), getattr(signal, crash[scene["scene_id"]]))
        static, lights = {}, {}
        for g, v in meta["groups"].items():
            if v["flicker"]:
                lights[g] = [(lt["id"], tuple(lt["bbox"][n]),
                              rng.random((K, C_, lt["bbox"][n][2] - lt["bbox"][n][0],
                                          lt["bbox"][n][3] - lt["bbox"][n][1])).astype(np.float32))
                             for lt in meta["lights"] if lt["group"] == g and lt["bbox"][n] is not None]
            else:
                static[g] = {w: rng.random((C_, H, W)).astype(np.float32) for w in ("short", "long")}
        aux = {k: np.full((H, W), -1.0 if k.startswith("mask") else 5.0, np.float32) for k in C.AUX_CHANNELS}
        yield {"frame": n, "static": static, "lights": lights, "aux": aux}


LAYER_CALLS: list[tuple[str, str]] = []


def fake_render_layer(scene, opts, layer):
    """Static window layer frames with the shapes ``render_tools.static_layers.render_layer`` yields: seeded random
    radiance per static group; a scene in :data:`FAIL` raises before its first frame."""
    from render_tools.render import scene_meta

    LAYER_CALLS.append((scene["scene_id"], layer[0]))
    if scene["scene_id"] in FAIL:
        raise FAIL[scene["scene_id"]]("simulated failure")
    meta = scene_meta(scene, opts)
    rng = np.random.default_rng(opts.seed + 7)
    for n in range(opts.frames):
        yield {"frame": n, "static": {g: rng.random((len(opts.bands_nm), opts.height, opts.width)).astype(np.float32)
                                      for g, v in meta["groups"].items() if not v["flicker"]}}


def fake_backend():
    from render_tools import render, scene

    return J.Backend(scene.generate_scene, render.RenderOptions, render.scene_meta, fake_render_frames,
                     scene.validate_scene, fake_render_layer)


ARGS = ["--width", "24", "--height", "16", "--spp", "2", "--frames", "2", "--bins", "2", "--profile", "small"]


def run(*args):
    """``lfmbench render ARGS`` in this process (CliRunner). The command layer (which imports torch) is imported
    here, not at the top: spawned render workers import this module for :func:`fake_backend` and start faster
    without it."""
    from typer.testing import CliRunner  # noqa: PLC0415

    from lfmbench.cli import app  # noqa: PLC0415

    return CliRunner().invoke(app, ["render", *args])


LED = {"model": "led", "peak_nm": 630.0, "fwhm_nm": 18.0}
HPS = {"model": "light_source", "name": "HPS"}


def light(lid, group, center, normal, size, spec, lum, kind=None, instance=-1):
    """A rectangular lamp of a scene file (m, cd/m^2)."""
    kind = kind or {"otherlights": "tail", "streetlights": "streetlight", "headlights": "headlight",
                    "signals": "signal"}[group]
    return {"id": lid, "group": group, "kind": kind, "instance": instance, "shape": "rect",
            "center": list(center), "normal": list(normal), "size": list(size), "spread_deg": 90.0,
            "spectrum": spec, "luminance_cd_m2": float(lum)}


def wall_scene(speed=0.0):
    """A red-LED panel (otherlights) filling the left of the view and an HPS panel (streetlights) the right."""
    s = scene.empty_scene(speed_mps=speed)
    s["lights"].append(light(0, "otherlights", (5.0, 2.0, 1.4), (-1, 0, 0), (4.0, 6.0), LED, 800.0))
    s["lights"].append(light(1, "streetlights", (5.0, -2.0, 1.4), (-1, 0, 0), (4.0, 6.0), HPS, 2e4))
    return scene.validate_scene(s)


def street():
    """A grey ground and wall lit by a tail lamp (otherlights, on a moving car) and an HPS streetlight."""
    s = scene.empty_scene(speed_mps=10.0, fov_x_deg=50.0)
    s["materials"]["grey"] = {"type": "diffuse", "rgb": [0.4, 0.4, 0.4]}
    s["objects"].append({"id": 0, "kind": "ground", "velocity_mps": [0, 0, 0],
                         "parts": [{"shape": "rect", "center": [10, 0, 0], "size": [60, 30], "normal": [0, 0, 1],
                                    "material": "grey"},
                                   {"shape": "rect", "center": [14, 0, 2], "size": [30, 6], "normal": [-1, 0, 0],
                                    "material": "grey"}]})
    s["objects"].append({"id": 1, "kind": "car", "velocity_mps": [8.0, 0, 0],
                         "parts": [{"shape": "box", "center": [9.0, 0.8, 0.7], "size": [1.0, 1.6, 1.0],
                                    "yaw_deg": 0.0, "material": "grey"}]})
    base = {"shape": "rect", "normal": [-1, 0, 0], "spread_deg": 90.0}
    s["lights"].append({**base, "id": 0, "group": "otherlights", "kind": "tail", "instance": 1,
                        "center": [8.49, 0.4, 0.9], "size": [0.3, 0.2], "spectrum": LED, "luminance_cd_m2": 3e3})
    s["lights"].append({**base, "id": 1, "group": "streetlights", "kind": "streetlight", "instance": -1,
                        "center": [9.0, -2.0, 4.0], "normal": [0, 0, -1], "size": [0.4, 0.4], "spectrum": HPS,
                        "luminance_cd_m2": 5e4})
    return scene.validate_scene(s)


#: Image size (width, height) px the wet_scene tests render and project at.
WET_SIZE = (160, 90)


def wet_scene(lamp_m, version: int = 2, speed_mps: float = 0.0) -> dict:
    """A 0.4 x 0.4 m lamp (otherlights, 2000 cd/m^2) at ``lamp_m``, facing the camera (x = 0, 1.4 m high,
    pitch -4 deg, 40 deg wide), over a wet road (water film: GGX alpha 0.06, index 1.33), 200 x 40 m."""
    from render_tools import scene as S  # noqa: PLC0415

    sc = S.empty_scene("edges", speed_mps=speed_mps, pitch_deg=-4.0)
    sc["version"] = version
    if version >= 2:
        sc["weather"] = "wet"
    sc["materials"]["road"] = {"type": "roughplastic", "rgb": [0.05, 0.05, 0.052], "alpha": 0.06, "ior": 1.33}
    sc["objects"].append({"id": 0, "kind": "road", "velocity_mps": [0, 0, 0],
                          "parts": [{"shape": "box", "center": [90, 0, -0.05], "size": [200, 40, 0.1],
                                     "material": "road"}]})
    sc["lights"].append({"id": 0, "group": "otherlights", "kind": "tail", "instance": -1, "shape": "rect",
                         "center": [float(v) for v in lamp_m], "normal": [-1, 0, 0], "size": [0.4, 0.4],
                         "spread_deg": 90.0, "spectrum": {"model": "led", "peak_nm": 630.0, "fwhm_nm": 18.0},
                         "luminance_cd_m2": 2000.0})
    return S.validate_scene(sc)
