"""Radiance of the static groups for any exposure window: error of each option against its storage and render cost
(issue 22 item 3; docs/results/sensor-architectures.md, "Static radiance for any window").

A corpus stores its static groups (headlights, streetlights, skymap: everything but the flickering lamps) as two
time averages per frame, over the short window (centred) and the long window [0, T_L); a staggered 0.1 ms exposure
or a chopped sub-window matches neither (the ego motion blur differs). Options:

- ``long`` / ``nearest``: use a stored average for any window: the long one, or the smallest stored window that
  contains the wanted one (the short one when it does, else the long one);
- ``bins K``: store the static groups in K time bins over the capture window (as the flickering lamps are) and
  average the bins a window overlaps (partial bins weighted by their overlap);
- ``stored windows``: render and store every window a plan needs (exact for those, nothing else).

Reference: one render of the static groups (all static groups traced together) in N_FINE = 64 time bins over the
long window (line time 0, so the capture window is the long one), the short window being bins 24..39 (T_S = T_L/4).
Each option is computed from these same fine bins (an option's estimate is a linear function of them), and the
error is the bias with the Monte Carlo noise removed: two independent renders give sum (a1 - t1)(a2 - t2), whose
expectation is the squared bias (the time discretisation and motion alone); one render's noise is stated beside. Windows tested: every length of 1, 2, 4, 8, 16,
32, 48 fine bins (0.17 to 8.3 ms) at the start, middle and end of the long window, and the staggered plan's windows
on the grid. Errors are relative RMS over the image (band sums per pixel).

Cost: the render time of the static groups for one frame with K bins (the same spp per bin, so equal noise per bin)
against today's short + rest windows, and the storage: K layers instead of 2 per static group and frame.

Usage: ``python benchmarks/studies/bench_static_windows.py [--width 320 --height 180 --spp 16 --seeds 3,7] [--out docs]``
(prints a markdown table; about a minute per scene on 2 cores).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH
from lfmbench.fileio import atomic_write_text  # noqa: E402

N_FINE = 64
SHORT = (24, 40)                 # fine bins of the short window (T_S = T_L / 4, centred)
LENGTHS = (1, 2, 4, 8, 16, 32, 48)
BINS = (2, 4, 8, 16, 32)


def render_static(scene: dict, width: int, height: int, spp: int, bins: int, seed: int, bands=(450.0, 550.0, 650.0)):
    """The static groups of frame 0, traced together, in ``bins`` time bins over [0, T_L): (bins, C, H, W) W sr^-1
    m^-2 nm^-1 (sum over the static groups) and the render time (s)."""
    import drjit as dr  # noqa: PLC0415
    import mitsuba as mi  # noqa: PLC0415

    from render_tools import backend, tracer  # noqa: PLC0415
    from render_tools import mitsuba_scene as ms  # noqa: PLC0415
    from render_tools.render import RenderOptions, SceneGeometry, _selected_groups, frame_timing  # noqa: PLC0415

    opts = RenderOptions(width=width, height=height, spp=spp, bins=8, bands_nm=bands, frames=1, line_time_s=0.0,
                         seed=seed, aux=False)
    backend.select_variant(None)
    groups = _selected_groups(scene, opts)
    static = [g for g, info in groups.items() if not info["flicker"]]
    tm = frame_timing(scene, opts, 0)
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    cache = ms.prepare_geometry(scene, {})
    loaded = mi.load_dict(ms.mitsuba_dict(scene, t_obj, emit="all", cache=cache, unit_sky=True))
    pad = tracer.pad_registry(mi, dr, loaded, cache["off_lens"])
    geo = SceneGeometry(scene, opts)
    sets = tracer.LightSets(mi, dr, loaded, scene, list(groups), union=static)
    tr = tracer.Tracer(mi, dr, loaded, sets, geo.ego, geo.fov, (width, height), opts.bands_nm, opts.band_width_nm,
                       sky_scale=ms.sky_scale(scene))
    (la, lb) = tm["long"]
    tile = tracer.Tile((0, 0, height, width), bins, la, (lb - la) / bins, spp, sets["union:static"],
                       slots=len(static), key=1)
    tr.render([tile], seed)                                   # compile (kernels are cached per size class)
    t = time.perf_counter()
    img = tr.render([tile], seed)[0]
    dt = time.perf_counter() - t
    del pad
    img = img.sum(0) if len(static) > 1 else img              # (bins, C, H, W)
    return img.astype(np.float64), dt


def averages(fine: np.ndarray, a: float, b: float) -> np.ndarray:
    """Time average over [a, b) in fine-bin units of (N, C, H, W) bin averages (partial bins by overlap)."""
    n = fine.shape[0]
    e = np.arange(n + 1, dtype=np.float64)
    w = np.clip(np.minimum(e[1:], b) - np.maximum(e[:-1], a), 0.0, None)
    return np.tensordot(w, fine, axes=1) / (b - a)


def coarse(fine: np.ndarray, k: int) -> np.ndarray:
    """K bins over the window from N fine bins (N a multiple of K): what a K-bin render stores."""
    n = fine.shape[0]
    return fine.reshape(k, n // k, *fine.shape[1:]).mean(1)


def bias(a1: np.ndarray, t1: np.ndarray, a2: np.ndarray, t2: np.ndarray) -> float:
    """Relative RMS bias of an approximation, free of Monte Carlo noise: from two independent renders (1, 2),
    sqrt(max(0, sum (a1 - t1)(a2 - t2)) / sum t1 t2) over pixels (band sums); the cross term's expectation is the
    squared bias, the noise of the two renders being independent."""
    d1, d2 = (a1 - t1).sum(0), (a2 - t2).sum(0)
    return float(np.sqrt(max(0.0, float((d1 * d2).sum())) / float((t1.sum(0) * t2.sum(0)).sum())))


def noise(t1: np.ndarray, t2: np.ndarray) -> float:
    """Relative RMS Monte Carlo noise of one render of a window: sqrt(sum (t1 - t2)^2 / 2 / sum t1 t2)."""
    d = (t1 - t2).sum(0)
    return float(np.sqrt(float((d * d).sum()) / 2.0 / float((t1.sum(0) * t2.sum(0)).sum())))


def windows() -> list[tuple[str, float, float]]:
    out = []
    for n in LENGTHS:
        for where, a in (("start", 0), ("mid", (N_FINE - n) // 2), ("end", N_FINE - n)):
            out.append((f"{n} bins {where}", float(a), float(a + n)))
    # the staggered plan (10 / 1 / 0.1 ms of 11.1 ms) on the grid: 57.6, 5.76, 0.576 bins
    f = N_FINE / 11.1
    out += [("staggered long", 0.0, 10 * f), ("staggered mid", 10 * f, 11 * f), ("staggered short", 11 * f, 11.1 * f)]
    return out


def nearest(a: float, b: float, short: np.ndarray, long: np.ndarray) -> np.ndarray:
    return short if (a >= SHORT[0] and b <= SHORT[1]) else long


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seeds", default="3,7")
    ap.add_argument("--speed", type=float, default=30.0, help="ego speed, m/s")
    ap.add_argument("--json", default=None, help="also write the raw numbers here")
    args = ap.parse_args(argv)
    from render_tools.scene import generate_scene  # noqa: PLC0415

    rows: dict[str, dict[str, list]] = {}
    costs: dict[int, list] = {}
    for s in (int(x) for x in args.seeds.split(",")):
        tod = "night" if s % 2 else "day"
        scene = generate_scene(s, tod, overrides={"camera": {"speed_mps": [args.speed, args.speed]}})
        scene["timing"]["short_exposure_s"] = (1.0 / 90.0) * (SHORT[1] - SHORT[0]) / N_FINE
        fine, t_fine = render_static(scene, args.width, args.height, args.spp, N_FINE, seed=1)
        fine2, _ = render_static(scene, args.width, args.height, args.spp, N_FINE, seed=2)
        for k in (1, 2, *BINS):
            # render cost: K bins at the same spp per bin (2: today's short + rest windows, same sample count)
            _, dt = render_static(scene, args.width, args.height, args.spp, k, seed=3)
            costs.setdefault(k, []).append(dt)
        pair = [(f, averages(f, *SHORT), averages(f, 0, N_FINE)) for f in (fine, fine2)]
        for name, a, b in windows():
            (f1, s1, l1), (f2, s2, l2) = pair
            t1, t2 = averages(f1, a, b), averages(f2, a, b)
            r = rows.setdefault(name, {})
            r.setdefault("noise", []).append(noise(t1, t2))
            r.setdefault("long", []).append(bias(l1, t1, l2, t2))
            r.setdefault("nearest", []).append(bias(nearest(a, b, s1, l1), t1, nearest(a, b, s2, l2), t2))
            for k in BINS:
                c1, c2 = (averages(coarse(f, k), a * k / N_FINE, b * k / N_FINE) for f in (f1, f2))
                r.setdefault(f"bins {k}", []).append(bias(c1, t1, c2, t2))
        print(f"scene {s} ({tod}): fine render {t_fine:.2f} s", file=sys.stderr)
    opts = ["long", "nearest", *(f"bins {k}" for k in BINS)]
    print(f"Relative RMS bias (%) of the static radiance of a window, {args.width}x{args.height}, ego "
          f"{args.speed:g} m/s, mean of {len(costs[1])} scenes; 'noise': one render's relative RMS Monte Carlo "
          f"noise over that window at {args.spp} spp per fine bin.\n")
    print("| window (fine bins of T_L/64 = 0.174 ms) | noise | " + " | ".join(opts) + " |")
    print("|---|---|" + "---|" * len(opts))
    for name, r in rows.items():
        print(f"| {name} | {100 * np.mean(r['noise']):.2f} | "
              + " | ".join(f"{100 * np.mean(r[o]):.2f}" for o in opts) + " |")
    base = np.mean(costs[2])
    print("\n| static layers per group and frame | render time (s) | x 2 bins | storage x today |")
    print("|---|---|---|---|")
    for k, v in costs.items():
        print(f"| {k} {'(the samples of today: short + rest)' if k == 2 else 'bins'} | {np.mean(v):.2f} | "
              f"{np.mean(v) / base:.2f} | {k / 2:.1f} |")
    if args.json:
        atomic_write_text(args.json, json.dumps({"rows": rows, "costs": costs}))


if __name__ == "__main__":
    main()
