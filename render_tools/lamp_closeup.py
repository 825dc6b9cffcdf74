"""A close-up of a lamp cluster and an LED message sign, rendered and composed twice: flicker-free (every light at
its time-averaged level) and as one short exposure with each light's drawn PWM and waveform applied, where the
rows of the multiplexed sign differ (docs/img/lamp_closeup.png, docs/guide/rendering.md).

:func:`closeup_scene` is a hand-made scene version 2 (night, static camera): a car seen from behind at 5 m with
its rear cluster lit (segmented tail lamps on separate drivers, brake lamps, CHMSL strip, a blinking
indicator), and a message sign at 11 m (1/8 scan, amber). :func:`render_closeup` renders frame 0 and writes the
PNG; ``python -m render_tools.lamp_closeup --out docs/img`` re-makes it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from lfmbench.flicker.waveforms import waveform_from_dict

__all__ = ["closeup_scene", "light_weights", "render_closeup"]


def closeup_scene() -> dict:
    """The close-up scene (validated dict, scene version 2)."""
    from . import scene as scn  # noqa: PLC0415
    from .lamps import add_message_sign, add_vehicle_lamps  # noqa: PLC0415
    from .scene_templates import VEHICLE_TEMPLATES, box, rect  # noqa: PLC0415

    cfg = scn.load_config(generator=2)
    cfg["lamps"].update({"unsynchronised_segments": 1.0, "tail_segments": [3, 3], "led_strip_probability": 1.0,
                         "drl_probability": 0.0, "emergency_probability": 0.0})
    b = scn.SceneBuilder(np.random.default_rng(3), cfg, "night", generator=2)
    b.materials.update({"paint": {"type": "roughplastic", "rgb": [0.5, 0.52, 0.55], "alpha": 0.15}})
    b.obj("road", [rect((20.0, 0.0, 0.0), (80.0, 30.0), (0, 0, 1), "asphalt")])
    t = VEHICLE_TEMPLATES["car"]
    x, y = 7.0, -0.9
    parts = [box((x + cx, y + cy, cz), size, {"paint": "paint", "glass": "glass"}[m])
             for (cx, cy, cz), size, m in t["boxes"]]
    oid = b.obj("car", parts)
    add_vehicle_lamps(b, "car", t, oid, x, y, 0.0, 0.0, lights_on=True, braking=True, indicator=True)
    sign = b.obj("message_sign", [box((11.1, 1.2, 2.45), (0.12, 3.2, 0.65), "housing")])
    add_message_sign(b, sign, (11.035, 1.2, 2.45), (-1.0, 0.0, 0.0), "SLOW DOWN", grid=(60, 9), pitch_m=0.05,
                     scan_lines=8, luminance=8000.0)
    base = scn.empty_scene("lamp_closeup", short_exposure_s=0.004, position_m=(0.0, -0.3, 1.2), pitch_deg=-2.0,
                           fov_x_deg=40.0, sky_luminance_cd_m2=40.0)
    base.update({"version": 2, "materials": b.materials, "objects": b.objects, "lights": b.lights,
                 "weather": "dry"})
    return scn.validate_scene(base)


def light_weights(scene: dict, edges: np.ndarray, window: tuple[float, float], carrier: dict[int, tuple],
                  mean: bool) -> dict[int, np.ndarray]:
    """Per light, the share of each time bin ``[edges[k], edges[k+1])`` (s) that falls in ``window`` (s) weighted by
    the light's level: ``{light id: (K,) 1}``, the exposure of each bin over the window length, with the light's
    waveform (default ``pwm``) and carrier ``(period s, duty, phase s)``; ``mean``: flicker-free (carrier at its
    duty)."""
    a, b = window
    lo = np.maximum(edges[:-1], a)
    dur = np.maximum(np.minimum(edges[1:], b) - lo, 0.0)
    out = {}
    for lt in scene["lights"]:
        w = waveform_from_dict(lt.get("waveform", {"kind": "pwm"}))
        T, D, ph = carrier[lt["id"]]
        phi = w.mean_exposure(lo, dur, D) if mean else w.exposure(lo, dur, T, D, ph)
        out[lt["id"]] = np.asarray(phi) / (b - a)
    return out


def render_closeup(out_dir: str | Path, width: int = 640, height: int = 360, spp: int = 2, light_spp: int = 16,
                   exposure_s: float = 0.0012, seed: int = 5, white_cd_m2: float = 3000.0) -> Path:
    """Render frame 0 of :func:`closeup_scene` at the ``small`` profile's sample counts and write
    ``lamp_closeup.png`` (top: flicker-free; bottom: one ``exposure_s`` s exposure with PWM and waveforms) and
    ``lamp_closeup_scene.json`` to ``out_dir``. Carriers: every light 200 Hz, duty 0.5 (the sign's rows: 0.9 of
    their slot), phases drawn with ``seed``; lights of one driver share the draw. Returns the PNG path."""
    from . import render as rnd  # noqa: PLC0415
    from .preview import preview_png  # noqa: PLC0415
    from .scene_schema import save_scene  # noqa: PLC0415

    sc = closeup_scene()
    groups = {g: {"flicker": g != "skymap"} for g in sc["groups"]}
    sc["groups"] = groups
    opts = rnd.RenderOptions(width=width, height=height, spp=spp, light_spp=light_spp, frames=1, bins=16,
                             aux=False, seed=seed)
    frame = next(rnd.render_frames(sc, opts))
    tm = rnd.frame_timing(sc, opts, 0)
    edges = np.asarray(tm["bin_edges"])
    rng = np.random.default_rng(seed)
    T = 1 / 200.0
    draws: dict = {}
    carrier = {}
    for lt in sc["lights"]:
        key = lt.get("driver", f"light{lt['id']}")
        if key not in draws:
            draws[key] = float(rng.uniform(0.0, T))
        duty = 0.9 if lt["kind"] == "message_sign" else 0.5
        carrier[lt["id"]] = (T, duty, draws[key])
    a = tm["short"][0]
    C = len(opts.bands_nm)
    imgs = []
    for mean, win in ((True, (a, a + exposure_s)), (False, (a, a + exposure_s))):
        wts = light_weights(sc, edges, win, carrier, mean)
        acc = np.zeros((C, height, width))
        for v in frame["static"].values():
            acc += v["short"]
        for items in frame["lights"].values():
            for lid, (y0, x0, y1, x1), bins in items:
                acc[:, y0:y1, x0:x1] += np.tensordot(wts[lid], bins, axes=(0, 0))
        imgs.append(acc)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    p = out / "lamp_closeup.png"
    sep = np.zeros((C, 2, width))
    preview_png(np.concatenate([imgs[0], sep, imgs[1]], axis=1), opts.bands_nm, opts.band_width_nm, p,
                white_cd_m2=white_cd_m2)
    save_scene(sc, out / "lamp_closeup_scene.json")
    return p


if __name__ == "__main__":  # pragma: no cover - documentation helper
    import argparse

    ap = argparse.ArgumentParser(description="Render the lamp-cluster and message-sign close-up PNG.")
    ap.add_argument("--out", default="docs/img")
    ap.add_argument("--exposure-ms", type=float, default=1.2)
    a = ap.parse_args()
    print(render_closeup(a.out, exposure_s=a.exposure_ms * 1e-3))
