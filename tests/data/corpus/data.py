"""Fake corpus data: tiny seeded renderer output in the exact shape of ``render_tools.render``, and whole corpora.

``fake_meta`` / ``fake_frames`` build a ``meta.json`` dict and frame dicts as documented in
``docs/guide/contracts.md`` and ``docs/guide/corpus-format.md``; the radiance is random but known, so tests can compare
what the reader returns with what went in. ``make_corpus`` writes a corpus of such scenes with
:class:`lfmbench.corpus.CorpusWriter` (for the dataset, evaluation and fault tests).

Run as a script to write an example corpus: ``python -m tests.data.corpus.data OUT_DIR``.
"""
from __future__ import annotations

import errno
import os

import numpy as np

from lfmbench import corpus as C

BANDS = [400.0, 550.0, 700.0]


def fake_meta(scene_id="scene00000", *, width=12, height=8, frames=2, bins=3, bands=BANDS, fps=60.0,
              short_s=0.004, long_s=1 / 90, line_time_s=10e-6, groups=None, n_lights=2):
    """A ``meta.json`` dict: static groups headlights + skymap, flickering group otherlights."""
    readout = height * line_time_s
    groups = groups or {"headlights": {"flicker": False}, "skymap": {"flicker": False},
                        "otherlights": {"flicker": True}}
    lights = []
    flick = [g for g, v in groups.items() if v["flicker"]]
    for i in range(n_lights if flick else 0):
        lights.append({"id": i, "group": flick[i % len(flick)], "kind": "tail", "instance": 10 + i,
                       "luminance_cd_m2": 100.0, "spectrum": {"model": "led", "peak_nm": 625.0, "fwhm_nm": 20.0},
                       "bbox": [[1, 1 + 3 * i, 4, 3 + 3 * i] for _ in range(frames)]})
    return {
        "scene_id": scene_id, "width": width, "height": height, "bands_nm": list(bands), "band_width_nm": 10.0,
        "fps": fps, "frames": frames,
        "timing": {"short_exposure_s": short_s, "long_exposure_s": long_s, "alignment": "center",
                   "line_time_s": line_time_s, "readout_s": readout, "capture_window_s": long_s + readout,
                   "bins": bins},
        "camera": {"fov_x_deg": 40.0, "K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "speed_mps": 30.0,
                   "yaw_rate_rad_s": 0.0, "poses": [[np.eye(4).tolist(), np.eye(4).tolist()]] * frames},
        "groups": groups, "lights": lights,
    }


def fake_frames(meta, seed=0, aux=True):
    """Frame dicts matching ``meta`` (random radiance in [0, 5) W sr^-1 m^-2 nm^-1)."""
    rng = np.random.default_rng(seed)
    C, H, W = len(meta["bands_nm"]), meta["height"], meta["width"]
    K = meta["timing"]["bins"]
    out = []
    for n in range(meta["frames"]):
        static, lights = {}, {}
        for g, v in meta["groups"].items():
            if v["flicker"] and v.get("bins", K) > 0:
                ls = []
                for lt in meta["lights"]:
                    if lt["group"] != g:
                        continue
                    y0, x0, y1, x1 = lt["bbox"][n]
                    ls.append((lt["id"], (y0, x0, y1, x1),
                               (5 * rng.random((K, C, y1 - y0, x1 - x0))).astype(np.float32)))
                lights[g] = ls
            else:
                static[g] = {w: (5 * rng.random((C, H, W))).astype(np.float32) for w in ("short", "long")}
        fr = {"frame": n, "static": static, "lights": lights}
        if aux:
            z = (1 + 50 * rng.random((H, W))).astype(np.float32)
            z[0, 0] = np.inf  # sky: no surface
            fr["aux"] = {"depth.Z": z, "depth.R": z * 1.1, "mask.instance": np.full((H, W), -1, np.float32),
                         "mask.light": np.full((H, W), -1, np.float32)}
            fr["aux"]["mask.light"][1:4, 1:3] = 0
        out.append(fr)
    return out


def fake_scene(scene_id="scene00000"):
    """A scene.json stand-in (the corpus stores it verbatim)."""
    return {"scene_id": scene_id, "seed": 1, "note": "fake scene for tests"}


#: Image size of the scenes of :func:`make_corpus` (px).
H, W = 16, 24


def scale_frames(frames, static_scale, light_scale, static_camera=False):
    """Scale fake frames in place: static layers by ``static_scale``, light bins by ``light_scale`` (both
    W sr^-1 m^-2 nm^-1 per unit); ``static_camera``: every bin equal to the first (a static scene). Marks a small
    light-mask patch. Returns ``frames``."""
    for f in frames:
        for g in f["static"].values():
            for k in g:
                g[k] *= static_scale
        for g, ls in f["lights"].items():
            new = []
            for lid, box, arr in ls:
                arr = arr * light_scale
                if static_camera:
                    arr[:] = arr[:1]  # every bin identical: a static scene
                new.append((lid, box, arr))
            f["lights"][g] = new
        f["aux"]["mask.light"][1:4, 4:6] = 1
    return frames


def disk_full_after(monkeypatch, n_ok: int):
    """Make ``os.fsync`` succeed ``n_ok`` times, then raise ``ENOSPC`` (a disk that fills up mid-write); returns
    the real ``os.fsync`` so a test can restore it before it goes on."""
    real = os.fsync
    calls = {"n": 0}

    def full(fd):
        calls["n"] += 1
        if calls["n"] > n_ok:
            raise OSError(errno.ENOSPC, "No space left on device")
        real(fd)
    monkeypatch.setattr(os, "fsync", full)
    return real


def make_corpus(root, n_scenes=3, frames=3, bins=4, scale=1e-3, static_camera=False, seed=0, groups=None):
    """A corpus of ``n_scenes`` fake scenes; radiance scaled by ``scale`` (W sr^-1 m^-2 nm^-1) to stay unclipped."""
    w = C.CorpusWriter(root)
    for i in range(n_scenes):
        meta = fake_meta(f"scene{i:05d}", width=W, height=H, frames=frames, bins=bins, groups=groups, n_lights=2)
        fr = scale_frames(fake_frames(meta, seed=seed + i), scale, scale, static_camera)
        w.write_scene(meta["scene_id"], fake_scene(meta["scene_id"]), meta, fr)
    w.write_splits(0)
    return root


#: Scene-version-2 light timing for the lights of :func:`make_v2_corpus` (one entry per light; fps 60, so frames
#: start every 16.7 ms): each gate switches inside the first frames, a sign's two scan rows share one driver, and
#: two plain lamps share another.
V2_LIGHTS = (
    {"kind": "indicator", "waveform": {"kind": "indicator", "frequency_hz": 2.0, "on_fraction": 0.5,
                                       "phase_s": 0.0301}},
    {"kind": "strobe", "waveform": {"kind": "strobe", "cycle_s": 0.05, "flashes": 2, "flash_s": 0.004,
                                    "gap_s": 0.003, "phase_s": 0.0021}},
    {"kind": "countdown", "waveform": {"kind": "countdown", "count_from": 3, "tick_s": 0.05, "blank_s": 0.02,
                                       "place": "units", "segment": "c", "phase_s": 0.011}},
    {"kind": "destination_display", "driver": "bus.display",
     "waveform": {"kind": "destination_display", "scan_lines": 4, "line": 2, "pages": 2, "page": 1, "page_s": 0.1,
                  "phase_s": 0.04}},
    {"kind": "message_sign", "driver": "sign", "waveform": {"kind": "scan_row", "scan_lines": 4, "line": 3}},
    {"kind": "message_sign", "driver": "sign", "waveform": {"kind": "scan_row", "scan_lines": 4, "line": 1}},
    {"kind": "tail", "driver": "car.tail"},
    {"kind": "tail", "driver": "car.tail"},
)


def make_v2_corpus(root, n_scenes=3, frames=6, bins=4, scale=1e-3, seed=0, n_plain=0):
    """A corpus like :func:`make_corpus` whose scenes each have the 8 lights of :data:`V2_LIGHTS` (indicator,
    strobe, countdown segment, destination-display row, two message-sign scan rows and two lamps on shared drivers;
    boxes 3 px wide side by side, so a crop shows some of them), the gates shifted by 7 ms per scene; the first
    ``n_plain`` scenes have 8 plain PWM lights instead (scene version 1)."""
    w = C.CorpusWriter(root)
    for i in range(n_scenes):
        meta = fake_meta(f"scene{i:05d}", width=W, height=H, frames=frames, bins=bins, n_lights=len(V2_LIGHTS))
        for lt, extra in zip(meta["lights"], V2_LIGHTS if i >= n_plain else ()):
            lt.update({k: (dict(v) if isinstance(v, dict) else v) for k, v in extra.items()})
            if "phase_s" in lt.get("waveform", {}):
                lt["waveform"]["phase_s"] = round(lt["waveform"]["phase_s"] + 0.007 * i, 6)
        fr = scale_frames(fake_frames(meta, seed=seed + i), scale, scale)
        w.write_scene(meta["scene_id"], fake_scene(meta["scene_id"]), meta, fr)
    w.write_splits(0)
    return root


if __name__ == "__main__":  # pragma: no cover - a helper for looking at the data by hand
    import sys
    from pathlib import Path

    print(make_corpus(Path(sys.argv[1])))
