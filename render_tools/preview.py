"""sRGB PNG previews of rendered spectral frames (for looking at scenes, not for measurement).

Pipeline: spectral radiance (C, H, W) W sr^-1 m^-2 nm^-1 -> CIE XYZ (Y in cd/m^2, 1931 2-degree observer,
:func:`render_tools.spectra.spectral_to_xyz`) -> global photographic tone mapping on Y (Reinhard, Stark,
Shirley, Ferwerda, "Photographic tone reproduction for digital images", SIGGRAPH 2002, eqs. 1-4 with white
point; the key value by time of day, :data:`KEY_BY_TIME_OF_DAY`) -> linear sRGB (IEC 61966-2-1, D65, ``colour.XYZ_to_sRGB`` without chromatic adaptation) -> clip ->
sRGB transfer function -> 8-bit PNG, written atomically.
"""
from __future__ import annotations

import io
import json
import math
import os
from pathlib import Path

import numpy as np

from lfmbench.fileio import atomic_write_bytes

from . import spectra

#: Reinhard key value (middle grey) of the tone mapping: an average-key scene.
KEY_VALUE = 0.18
#: Key value by the scene's time of day. Reinhard et al. 2002 (section 3.1, figure 4) map the log-average luminance
#: of an average-key scene to 0.18 and of a low-key (subjectively dark) one to 0.09 or 0.045. A night street is
#: low-key: lamps in a dark field. At 0.18 a night frame's log-average (about 0.9 cd/m^2 on the wet night of seed
#: 7, half of it sky at 0.004 cd/m^2) became mid-grey and the lit road (median 1.7 cd/m^2) a bright sheet; at
#: 0.045 it is dark with the lamps and their reflections standing out, as a night street looks.
KEY_BY_TIME_OF_DAY = {"day": KEY_VALUE, "dusk": KEY_VALUE, "night": 0.045}


def key_for(scene: dict) -> float:
    """The tone mapping's key value for a scene file's ``time_of_day`` (:data:`KEY_BY_TIME_OF_DAY`; a scene
    without one: :data:`KEY_VALUE`)."""
    return KEY_BY_TIME_OF_DAY.get(scene.get("time_of_day"), KEY_VALUE)
#: Small luminance floor for the log-average, cd/m^2.
LUM_EPS = 1e-6


def compose_window(frame: dict, timing: dict, window: str = "short", shape=None) -> np.ndarray:
    """Full-scene radiance (C, H, W) over ``window`` ("short" or "long") of a frame from
    :func:`render_tools.render.render_frames`, every LED at its nominal (always-on) level.

    Static groups add their window image; each flickering light adds its bins weighted by their overlap with
    the window (``timing`` = :func:`render_tools.render.frame_timing` of that frame): the time average over
    [a, b) is sum_k L_k |bin_k ∩ [a, b)| / (b - a).
    """
    if window not in ("short", "long"):
        raise ValueError(f"window: {window!r} not 'short' or 'long'")
    acc = None
    for g, v in frame["static"].items():
        acc = v[window].astype(np.float64) if acc is None else acc + v[window]
    a, b = timing[window]
    edges = np.asarray(timing["bin_edges"])
    ov = np.clip(np.minimum(edges[1:], b) - np.maximum(edges[:-1], a), 0, None) / (b - a)
    for items in frame["lights"].values():
        for _, (y0, x0, y1, x1), bins in items:
            if acc is None:
                if shape is None:
                    raise ValueError("shape: needed when the frame has no static group")
                acc = np.zeros(shape)
            acc[:, y0:y1, x0:x1] += np.tensordot(ov, bins, axes=(0, 0))
    if acc is None:
        raise ValueError("frame: has no groups to compose")
    return acc


def tonemap_srgb(img: np.ndarray, bands_nm, band_width_nm: float, key: float = KEY_VALUE,
                 white_cd_m2: float | None = None) -> np.ndarray:
    """Spectral radiance (C, H, W) -> display sRGB (H, W, 3) uint8 (see module docstring). ``white_cd_m2``: a
    fixed linear exposure instead (luminance ``white_cd_m2`` cd/m^2 maps to display white), for close-ups of
    lamps whose luminance the scene-adaptive mapping would clip."""
    import colour  # noqa: PLC0415

    xyz = spectra.spectral_to_xyz(img, bands_nm, band_width_nm)  # (3, H, W), Y in cd/m^2
    y = np.maximum(xyz[1], 0.0)
    if white_cd_m2 is not None:
        ld = np.minimum(y / float(white_cd_m2), 1.0)
    else:
        lw = float(np.exp(np.mean(np.log(LUM_EPS + y))))
        lm = key * y / lw
        lwhite = max(float(np.percentile(lm, 99.9)), 1e-9)
        ld = lm * (1 + lm / lwhite**2) / (1 + lm)
    scale = np.where(y > 0, ld / np.maximum(y, 1e-30), 0.0)
    xyz_d = (xyz * scale).transpose(1, 2, 0)
    rgb = colour.XYZ_to_sRGB(xyz_d, apply_cctf_encoding=False, chromatic_adaptation_transform=None)
    rgb = np.clip(rgb, 0.0, 1.0)
    enc = colour.cctf_encoding(rgb, function="sRGB")
    return np.clip(np.rint(enc * 255), 0, 255).astype(np.uint8)


def write_png(rgb8: np.ndarray, path: str | os.PathLike) -> None:
    """Write an (H, W, 3) uint8 image as PNG atomically (temp file in the same directory, then replace)."""
    import matplotlib.image as mpimg  # noqa: PLC0415

    rgb8 = np.asarray(rgb8)
    if rgb8.ndim != 3 or rgb8.shape[2] != 3 or rgb8.dtype != np.uint8:
        raise ValueError(f"rgb8: expected (H, W, 3) uint8, got {rgb8.shape} {rgb8.dtype}")
    buf = io.BytesIO()
    mpimg.imsave(buf, rgb8, format="png")
    atomic_write_bytes(path, buf.getvalue())


def preview_png(img: np.ndarray, bands_nm, band_width_nm: float, path: str | os.PathLike,
                key: float = KEY_VALUE, white_cd_m2: float | None = None) -> np.ndarray:
    """Tone-map a spectral image (C, H, W) (:func:`tonemap_srgb`) and write it to ``path``; returns the
    (H, W, 3) uint8 image."""
    rgb = tonemap_srgb(img, bands_nm, band_width_nm, key, white_cd_m2)
    write_png(rgb, path)
    return rgb


def render_previews(out_dir: str | os.PathLike, seed: int = 7, width: int = 640, height: int = 360,
                    spp: int = 8, times=("day", "dusk", "night")) -> list[Path]:
    """Render frame 0 of one generated scene per time of day and write ``preview_<tod>.png`` to ``out_dir``
    (plus ``preview_<tod>_scene.json``, the scene it came from). Returns the PNG paths."""
    from . import render as rnd  # noqa: PLC0415
    from . import scene as scn  # noqa: PLC0415

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for tod in times:
        sc = scn.generate_scene(seed, tod)
        opts = rnd.RenderOptions(width=width, height=height, spp=spp, light_spp=max(spp, 16), frames=1, bins=4,
                                 aux=False, seed=seed)
        frame = next(rnd.render_frames(sc, opts))
        img = compose_window(frame, rnd.frame_timing(sc, opts, 0), "short", shape=(len(opts.bands_nm), height, width))
        p = out / f"preview_{tod}.png"
        preview_png(img, opts.bands_nm, opts.band_width_nm, p, key=key_for(sc))
        scn.save_scene(sc, out / f"preview_{tod}_scene.json")
        paths.append(p)
    return paths


#: The gallery of docs/guide/scenes.md: (file stem, time of day, weather, streetlight spectrum or None) of the street
#: scenes. A spectrum replaces every kind the generator draws streetlights from (the same draws: the same street).
GALLERY = (("v2_day", "day", "dry", None), ("v2_dusk", "dusk", "dry", None), ("v2_night", "night", "dry", None),
           ("v2_wet_night", "night", "wet", None),
           ("v2_wet_night_led", "night", "wet", {"model": "illuminant", "name": "LED-B3"}))


def gallery_scene(entry: tuple, seed: int) -> dict:
    """The generator-2 scene of a :data:`GALLERY` entry at ``seed``: its time of day and weather, and (a spectrum
    given) every streetlight kind the generator draws from replaced by that spectrum, so the draws, and with them
    the street, stay those of the entry without one."""
    from . import scene as scn  # noqa: PLC0415

    _, tod, weather, streetlight = entry
    over = {"weather": {"conditions": [weather]}}
    if streetlight is not None:
        kinds = len(scn.load_config(generator=2)["lights"]["streetlight_spectra"])
        over["lights"] = {"streetlight_spectra": [streetlight] * kinds}
    return scn.generate_scene(seed, tod, generator=2, overrides=over)


def render_gallery(out_dir: str | os.PathLike, seed: int = 7, profile: str = "default",
                   closeup_size=(320, 180), closeup_spp: int = 4, only=None) -> list[Path]:
    """docs/guide/scenes.md's pictures: frame 0 (short exposure, every LED on) of scene generator 2's street at
    ``seed`` for each entry of :data:`GALLERY` (:func:`gallery_scene`), rendered with the render ``profile``'s options (frames and AOVs
    aside), and ``v2_vehicles.png``, a sheet of :func:`closeup_scene` renders (every vehicle kind, rear then
    front, lamps lit; ``closeup_size`` px each at ``closeup_spp``). ``only``: the file stems to render (None: all;
    ``v2_vehicles`` for the sheet). Returns the PNG paths; prints seconds."""
    import time  # noqa: PLC0415

    from . import render as rnd  # noqa: PLC0415
    from .jobs import load_profile  # noqa: PLC0415
    from lfmbench.vocabulary import VEHICLE_KINDS  # noqa: PLC0415

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    prof = dict(load_profile(profile), frames=1, aux=False, seed=seed)
    paths = []

    def shot(sc, opts, path):
        t = time.perf_counter()
        frame = next(rnd.render_frames(sc, opts))
        img = compose_window(frame, rnd.frame_timing(sc, opts, 0), "short",
                             shape=(len(opts.bands_nm), opts.height, opts.width))
        print(f"{path.name}: {time.perf_counter() - t:.1f} s", flush=True)
        return tonemap_srgb(img, opts.bands_nm, opts.band_width_nm, key=key_for(sc))

    stems = [g[0] for g in GALLERY] + ["v2_vehicles"]
    bad = sorted(set(only or ()) - set(stems))
    if bad:
        raise ValueError(f"only: unknown gallery picture(s) {bad}; known: {stems}")
    for entry in GALLERY:
        stem = entry[0]
        if only is not None and stem not in only:
            continue
        sc = gallery_scene(entry, seed)
        p = out / f"{stem}.png"
        write_png(shot(sc, rnd.RenderOptions(**prof), p), p)
        paths.append(p)
    if only is not None and "v2_vehicles" not in only:
        return paths
    w, h = closeup_size
    opts = rnd.RenderOptions(width=w, height=h, spp=closeup_spp, light_spp=max(16, closeup_spp), frames=1, bins=4,
                             aux=False, seed=seed)
    tiles = [shot(closeup_scene(k, v), opts, Path(f"{k}_{v}")) for k in VEHICLE_KINDS for v in ("rear", "front")]
    cols = 4
    rows = -(-len(tiles) // cols)
    sheet = np.zeros((rows * h, cols * w, 3), dtype=np.uint8)
    for i, t in enumerate(tiles):
        sheet[(i // cols) * h:(i // cols + 1) * h, (i % cols) * w:(i % cols + 1) * w] = t
    p = out / "v2_vehicles.png"
    write_png(sheet, p)
    paths.append(p)
    return paths


def closeup_scene(kind: str, view: str = "rear", seed: int = 5) -> dict:
    """A dusk scene (scene generator 2) for looking at one vehicle of ``kind`` from close by: the vehicle stands
    in the camera's lane, ``view`` ``"rear"`` (heading away: tail, brake, indicator lamps) or ``"front"`` (facing
    the camera: headlights), every lamp lit, 6 m of road between camera and vehicle; a pedestrian walks on the
    sidewalk beside it and trees line the street."""
    import numpy as np  # noqa: PLC0415

    from . import scene as scn  # noqa: PLC0415
    from . import street  # noqa: PLC0415
    from .scene_templates import VEHICLE_TEMPLATES  # noqa: PLC0415

    if view not in ("rear", "front"):
        raise ValueError(f"view: {view!r} not 'rear' or 'front'")
    cfg = scn.load_config(generator=2)
    b = scn.SceneBuilder(np.random.default_rng(seed), cfg, "dusk", generator=2)
    road = scn.add_road(b)
    length = VEHICLE_TEMPLATES[kind]["length"]
    x = 6.0 + length / 2
    scn.add_vehicle(b, kind, x, -1.75, 0.0 if view == "rear" else math.pi, 0.0, lights_on=True, braking=True,
                    indicator=True)
    street.add_trees(b, road)
    street.add_people(b, road, dark=True)
    street.add_textures(b, road)
    sky = scn.make_sky(b)
    sky["scale"] = 0.05
    sky["sun_elevation_deg"] = 3.0
    sc = {"format": scn.SCENE_FORMAT, "version": 2, "scene_id": f"closeup_{kind}_{view}", "seed": seed,
          "time_of_day": "dusk", "weather": "dry", "timing": {"short_exposure_s": 0.004},
          "camera": {"position_m": [0.0, -1.75, 1.4], "yaw_deg": 0.0, "pitch_deg": -4.0, "fov_x_deg": 45.0,
                     "speed_mps": 0.0, "yaw_rate_rad_s": 0.0},
          "sky": sky, "groups": cfg["groups"], "materials": b.materials, "objects": b.objects, "lights": b.lights,
          "meshes": b.meshes}
    return scn.validate_scene(json.loads(json.dumps(sc)))


if __name__ == "__main__":  # pragma: no cover - documentation helper
    import argparse

    ap = argparse.ArgumentParser(description="Render day/dusk/night preview PNGs of generated scenes.")
    ap.add_argument("--out", default="docs/img")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--gallery", action="store_true", help="docs/guide/scenes.md's scene generator 2 gallery instead")
    ap.add_argument("--only", nargs="+", default=None, help="with --gallery: these pictures only (file stems)")
    a = ap.parse_args()
    for path in (render_gallery(a.out, a.seed, only=a.only) if a.gallery else
                 render_previews(a.out, a.seed, a.width, a.height, a.spp)):
        print(path)
