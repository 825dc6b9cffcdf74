"""Motion between captures: the static groups' radiance of a staggered plan's windows, exact (static time bins aligned
to the windows' edges, ``RenderOptions.static_edges_s``, corpus format 4) against ``nearest`` (the stored short or long
window standing for every window), error against render cost and storage (issue 38 deliverable 4;
docs/benchmarks/motion-windows.md).

Scene: one generator-2 scene with moving vehicles (seed and time of day ``--case``), the ``default`` profile at
``--width x --height`` (default 320x180) and ``--frames`` frames. Each render runs in a child process (its CPU seconds,
user + system, from ``getrusage``: steadier than wall time on the shared machine; wall beside it) and encodes the
scene as the corpus writer does (``compact`` storage): the bytes are the scene's storage.

Schemes (rows):

- ``nearest`` (every corpus before format 4): the static groups stored as the short and long windows; a staggered
  window is served by the smallest stored window containing it (here the long one for all three);
- ``exact, staggered edges``: the static groups in the bins between 0, the short window's ends, T_L and the staggered
  preset's window edges (10 / 1 / 0.1 ms): every staggered, split-pixel and LOFIC window is a union of bins;
- ``exact, every shipped preset's edges`` (``--all-presets``): the chopped plan's 12 sub-windows too;
- ``masked, eps`` (evaluated on the truth renders, its cost estimated, not built): short and long stored as today,
  the other windows only where a pixel's surface point moves by >= eps px over the capture window
  (``render_tools.motion_bound``), the long window elsewhere: "no bins where nothing moves".

Each error cell is a bias with its resolution (jackknife over pixel blocks); a second pair of error renders at
``--check-spp`` (4) tells estimator scatter from bias. Error of a window's static radiance (all static groups, band
sums per pixel, relative RMS over the image), with the Monte Carlo noise removed as in ``bench_static_windows.py``: two independent renders (seeds 1, 2) of each scheme give
sqrt(max(0, sum (a1 - t1)(a2 - t2)) / sum t1 t2), whose expectation is the squared bias. Truth t: a brute-force render
whose bins are the staggered edges' bins cut into pieces of at most ``--fine-ms`` (0.5 ms: the moving vehicles
placed at 26 positions over the frame's 11.1 ms instead of 6). For ``nearest`` a = the long window; for ``exact``
a = the window's bins. Static denoising is off in the error renders (it is not independent between seeds: it would
hide noise as bias) and on (the profile's ``auto``) in the cost renders.

Usage: ``python benchmarks/bench_motion_windows.py [--case 11:night] [--width 320 --height 180] [--all-presets]
[--work DIR] [--out docs]``. About 30 minutes at 160x90 on the shared 2-core machine under load 20; ``--work`` keeps
the renders (and when they were made) so that a rerun only redoes the analysis.
"""
from __future__ import annotations

import argparse
import io
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH

from lfmbench.fileio import atomic_write_bytes, atomic_write_text  # noqa: E402

STAGGERED = ((0.0, 0.010), (0.010, 0.001), (0.011, 0.0001))
#: Scheme (b): the staggered windows as static window layers of their own (short and long stored as today).
STAG_LAYERS = tuple((n, ((a, d),)) for n, (a, d) in zip(("stag_long", "stag_medium", "stag_short"), STAGGERED))
LAYERS_ROW = "each needed window rendered as such (short + long + 3 staggered layers)"


def preset_edges(names) -> tuple:
    """Window edges (s from the frame start) of the captures of the named shipped presets (explicit windows only;
    ``short`` / ``long`` are added by the renderer)."""
    from lfmbench.sensor import load_preset  # noqa: PLC0415

    out = set()
    for n in names:
        for c in load_preset(n).captures.values():
            if not isinstance(c.exposure, str):
                for a, d in c.exposure:
                    out |= {float(a), float(a) + float(d)}
    return tuple(sorted(out))


def fine_edges(edges, step: float) -> tuple:
    """``edges`` with every interval cut into equal pieces of at most ``step`` s."""
    out = [edges[0]]
    for a, b in zip(edges[:-1], edges[1:]):
        k = max(1, int(np.ceil((b - a) / step - 1e-9)))
        out += list(a + (b - a) * np.arange(1, k + 1) / k)
    return tuple(out)


def worker(args) -> None:
    """Render one scheme in this (child) process; write the static windows / bins (npz) and cost (json)."""
    from lfmbench.corpus import encode_scene  # noqa: PLC0415
    from lfmbench.corpus.window_layers import encode_layer  # noqa: PLC0415
    from render_tools import render as R  # noqa: PLC0415
    from render_tools import static_layers  # noqa: PLC0415
    from render_tools.scene import generate_scene  # noqa: PLC0415

    seed, tod = args.case.split(":")
    sc = generate_scene(int(seed), tod, generator=2)
    edges = tuple(json.loads(args.edges))
    opts = R.RenderOptions(width=args.width, height=args.height, spp=args.spp, light_spp=32, bins=8,
                           frames=args.frames, seed=args.seed, static_edges_s=edges, aux=args.aux,
                           static_denoise="off" if args.no_denoise else "auto",
                           static_bin_samples=args.bin_samples)
    layers = [(n, tuple(map(tuple, w))) for n, w in json.loads(args.layers)]
    t, c = time.perf_counter(), time.process_time()
    frames = list(R.render_frames(sc, opts))
    # scheme (b): each needed window beyond short and long rendered as a static window layer of its own
    lay_imgs = [list(static_layers.render_layer(sc, opts, lay)) for lay in layers]
    render_wall, render_cpu = time.perf_counter() - t, time.process_time() - c
    meta = R.scene_meta(sc, opts)
    nbytes = sum(len(b) for _, b in encode_scene(sc["scene_id"], sc, meta, frames, dtype="compact"))
    static_bytes = sum(len(b) for rel, b in encode_scene(sc["scene_id"], sc, meta, frames, dtype="compact")
                       if any(rel.endswith(f"/{g}.exr") for g in frames[0]["static"]))
    lay_bytes = sum(len(encode_layer(img, opts.bands_nm, "compact", {}, "layer"))
                    for fr in (fr for imgs in lay_imgs for fr in imgs) for img in fr["static"].values())
    nbytes, static_bytes = nbytes + lay_bytes, static_bytes + lay_bytes
    f0 = frames[0]
    save = {"short": sum(w["short"] for w in f0["static"].values()),
            "long": sum(w["long"] for w in f0["static"].values())}
    if layers:
        save["layers"] = np.stack([sum(imgs[0]["static"].values()) for imgs in lay_imgs])
    if "bins" in next(iter(f0["static"].values())):
        save["bins"] = sum(w["bins"] for w in f0["static"].values())
        save["edges"] = np.asarray(f0["static_edges_s"])
    if args.aux:  # the AOVs (mid short window; objects at mid capture window) and the motion bound's times
        tm = R.frame_timing(sc, opts, 0)
        save.update(depth=f0["aux"]["depth.Z"], instance=f0["aux"]["mask.instance"],
                    times=np.array([tm["t_aux"], 0.5 * (tm["window"][0] + tm["window"][1]), *tm["long"]]))
    buf = io.BytesIO()
    np.savez(buf, **save)
    atomic_write_bytes(args.npz, buf.getvalue())
    Path(args.json).write_text(json.dumps({
        "render_wall_s": render_wall, "render_cpu_s": render_cpu, "bytes": nbytes, "static_bytes": static_bytes,
        "moving": [o["kind"] for o in sc["objects"] if any(o["velocity_mps"])],
        "speed_mps": sc["camera"]["speed_mps"], "layers": (len(f0["static_edges_s"]) - 1 if "static_edges_s" in f0
                                                           else 2) + len(layers), "layer_bytes": lay_bytes}))


def run(a, tmp: Path, name: str, edges: tuple, seed: int, no_denoise: bool, spp: int = 1,
        aux: bool = False, bin_samples: str = "independent", layers: tuple = ()) -> tuple[dict, dict]:
    stem = f"{name.split(',')[0].split(' ')[0]}-{len(edges)}-{seed}-{int(no_denoise)}-{spp}" + (
        "" if bin_samples == "independent" else f"-{bin_samples}") + (f"-L{len(layers)}" if layers else "")
    npz, js = tmp / f"{stem}.npz", tmp / f"{stem}.json"
    if a.work and npz.exists() and js.exists():  # --work: a render of an earlier run with the same arguments
        d = np.load(npz)
        return json.loads(js.read_text()), {k: d[k] for k in d.files}
    cmd = [sys.executable, __file__, "--worker", "--case", a.case, "--width", str(a.width), "--height",
           str(a.height), "--frames", str(a.frames), "--seed", str(seed), "--edges", json.dumps(list(edges)),
           "--npz", str(npz), "--json", str(js), "--spp", str(spp)] + (["--no-denoise"] if no_denoise else []) + (
           ["--aux"] if aux else []) + ["--bin-samples", bin_samples, "--layers", json.dumps(layers)]

    def cpu():
        r = resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime
    t, c = time.perf_counter(), cpu()
    res = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    if res.returncode:
        raise RuntimeError(f"{name}: {res.stderr[-3000:]}")
    info = json.loads(js.read_text())
    info.update(child_wall_s=time.perf_counter() - t, child_cpu_s=cpu() - c)
    d = np.load(npz)
    print(f"{name} seed {seed} spp {spp} denoise {not no_denoise}: {info}", file=sys.stderr, flush=True)
    return info, {k: d[k] for k in d.files}


def window(d: dict, a: float, n: float, exact: bool) -> np.ndarray:
    from lfmbench.corpus import window_bin_weights  # noqa: PLC0415

    if not exact:
        return d["long"].astype(np.float64)
    w = window_bin_weights(d["edges"], a, n)
    return np.tensordot(w, d["bins"].astype(np.float64), axes=1)


def bias(a1, t1, a2, t2, block: int = 8) -> tuple[float, float]:
    """(bias, resolution), relative RMS: bias = sqrt(max(0, b2)) with b2 = sum (a1 - t1)(a2 - t2) / sum t1 t2 over
    pixels (band sums), an unbiased estimate of the squared bias from two independent renders; resolution =
    sqrt(2 SE(b2)), SE by the delete-one jackknife over ``block`` x ``block`` pixel blocks (Efron & Tibshirani, An
    Introduction to the Bootstrap, 1993, ch. 11): a bias below it is not told apart from 0."""
    d1, d2 = (a1 - t1).sum(0), (a2 - t2).sum(0)
    tt = t1.sum(0) * t2.sum(0)
    H, W = tt.shape
    hb, wb = H // block, W // block
    num = (d1 * d2)[:hb * block, :wb * block].reshape(hb, block, wb, block).sum((1, 3)).ravel()
    den = tt[:hb * block, :wb * block].reshape(hb, block, wb, block).sum((1, 3)).ravel()
    b2 = float(num.sum() / den.sum())
    jk = (num.sum() - num) / (den.sum() - den)
    n = len(jk)
    se = float(np.sqrt((n - 1) / n * ((jk - jk.mean()) ** 2).sum()))
    return float(np.sqrt(max(0.0, b2))), float(np.sqrt(2.0 * se))


def noise(t1, t2) -> float:
    d = (t1 - t2).sum(0)
    return float(np.sqrt(float((d * d).sum()) / 2.0 / float((t1.sum(0) * t2.sum(0)).sum())))


def band_tiles(mask: np.ndarray, rows: int = 8) -> float:
    """Fraction of the image covered by row-band tiles over ``mask`` (H, W) bool: per band of ``rows`` rows the
    columns from its first to its last masked pixel (how the renderer tiles a reflection's footprint)."""
    H, W = mask.shape
    area = 0
    for y in range(0, H, rows):
        cols = np.flatnonzero(mask[y:y + rows].any(0))
        if len(cols):
            area += (cols[-1] + 1 - cols[0]) * min(rows, H - y)
    return area / (H * W)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="11:night", help="seed:time of day of the generator-2 scene")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    ap.add_argument("--frames", type=int, default=1)
    ap.add_argument("--fine-ms", type=float, default=0.5)
    ap.add_argument("--check-spp", type=int, default=4, help="spp of the second pair of error renders per scheme")
    ap.add_argument("--eps", default="0.05,0.25,1", help="motion thresholds (px) of the masked scheme")
    ap.add_argument("--all-presets", action="store_true")
    ap.add_argument("--out", default=None, help="docs folder: write benchmarks/motion-windows.md there")
    ap.add_argument("--work", default=None, help="folder that keeps the renders (reused by a rerun with the same "
                    "arguments; default: a temporary folder)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--spp", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--aux", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--edges", default="[]", help=argparse.SUPPRESS)
    ap.add_argument("--npz", help=argparse.SUPPRESS)
    ap.add_argument("--json", help=argparse.SUPPRESS)
    ap.add_argument("--no-denoise", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--bin-samples", default="independent", help=argparse.SUPPRESS)
    ap.add_argument("--layers", default="[]", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        worker(a)
        return
    load0 = os.getloadavg()
    eps = [float(x) for x in a.eps.split(",")]
    stag = tuple(sorted({x for s, n in STAGGERED for x in (s, s + n)}))
    schemes = [("nearest (short + long windows)", (), "independent", ()),
               ("exact, staggered edges", stag, "independent", ()),
               ("exact, staggered edges, common random numbers", stag, "common", ()),
               (LAYERS_ROW, (), "independent", STAG_LAYERS)]
    if a.all_presets:
        schemes.append(("exact, every shipped preset's edges", preset_edges(
            ("staggered", "lofic", "chopped", "single", "ovt", "imx490")), "independent", ()))
    from render_tools import motion_bound  # noqa: PLC0415
    from render_tools import render as R  # noqa: PLC0415
    from render_tools.scene import generate_scene  # noqa: PLC0415

    seed, tod = a.case.split(":")
    sc = generate_scene(int(seed), tod, generator=2)
    opts = R.RenderOptions(width=a.width, height=a.height, static_edges_s=stag)
    fine = fine_edges(tuple(R.static_bin_edges(sc, opts)), a.fine_ms * 1e-3)
    with tempfile.TemporaryDirectory(prefix="lfm_motion_") as tmp:
        tmp = Path(a.work or tmp)
        tmp.mkdir(parents=True, exist_ok=True)
        stamp = tmp / "run.json"  # when and under which load the renders were made (kept with them for a rerun)
        made = json.loads(stamp.read_text()) if stamp.exists() else {
            "start": f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M}", "load_start": load0[0]}
        cost = {}
        for name, edges, bs, lay in schemes:  # cost (profile as shipped: denoised); twice, the first compiles kernels
            run(a, tmp, name, edges, 3, False, bin_samples=bs, layers=lay)
            cost[name] = run(a, tmp, name, edges, 4, False, bin_samples=bs, layers=lay)[0]
        # error renders: two seeds of each, denoising off; truth = the staggered edges cut into fine pieces
        truth = [run(a, tmp, "truth", fine, s, True, aux=True)[1] for s in (1, 2)]
        err = {}
        for spp in (1, a.check_spp):
            err["nearest", spp] = [run(a, tmp, "nearest", (), s, True, spp)[1] for s in (1, 2)]
            err["exact", spp] = [run(a, tmp, "exact", stag, s, True, spp)[1] for s in (1, 2)]
        err["common", 1] = [run(a, tmp, "exact", stag, s, True, 1, bin_samples="common")[1] for s in (1, 2)]
        err["layers", 1] = [run(a, tmp, "layers", (), s, True, 1, layers=STAG_LAYERS)[1] for s in (1, 2)]
        if "end" not in made:
            made.update(end=f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M}", load_end=os.getloadavg()[0])
            atomic_write_text(stamp, json.dumps(made))
    ts, tl = float(sc["timing"]["short_exposure_s"]), 1 / 90
    wins = [("staggered long [0, 10) ms", 0.0, 0.010), ("staggered medium [10, 11) ms", 0.010, 0.001),
            ("staggered short [11, 11.1) ms", 0.011, 0.0001),
            (f"split pixel short (centred {ts * 1e3:.2f} ms)", (tl - ts) / 2, ts), ("long [0, 11.1) ms", 0.0, tl)]
    # the masked scheme, evaluated on the truth renders: where a pixel's surface point moves less than eps px over
    # the capture window, every window is the long one; elsewhere the window itself (render_tools.motion_bound)
    d0 = truth[0]
    t_aux, t_obj, la, lb = (float(x) for x in d0["times"])
    motion = motion_bound.screen_motion_px(sc, a.width, a.height, d0["depth"], d0["instance"], t_aux, t_obj, la, lb)
    masks = {e: motion_bound.motion_mask(motion, e, grow_px=1) for e in eps}
    rows = []
    for label, s0, n in wins:
        t1, t2 = (window(d, s0, n, True) for d in truth)
        stored = abs(n - tl) < 1e-9 or (abs(s0 - (tl - ts) / 2) < 1e-9 and abs(n - ts) < 1e-9)

        def near_w(d):  # nearest: the long window for the staggered ones; the stored window for short and long
            if abs(s0 - (tl - ts) / 2) < 1e-9 and abs(n - ts) < 1e-9:
                return d["short"].astype(np.float64)
            return d["long"].astype(np.float64)
        row = [label, 100 * noise(t1, t2)]
        for spp in (1, a.check_spp):
            nr, ex = err["nearest", spp], err["exact", spp]
            row += [tuple(100 * x for x in bias(near_w(nr[0]), t1, near_w(nr[1]), t2)),
                    tuple(100 * x for x in bias(window(ex[0], s0, n, True), t1, window(ex[1], s0, n, True), t2))]
        for e in eps:
            if stored:
                row.append(None)
                continue
            m = masks[e]
            am = [np.where(m, t, window(d, 0.0, tl, True)) for t, d in zip((t1, t2), truth)]
            row.append(tuple(100 * x for x in bias(am[0], t1, am[1], t2)))
        cr = err["common", 1]
        row.append(tuple(100 * x for x in bias(window(cr[0], s0, n, True), t1, window(cr[1], s0, n, True), t2)))
        rows.append(row)
    base = cost[schemes[0][0]]
    info = next(iter(cost.values()))
    ex = cost[schemes[1][0]]
    layer_bytes = (ex["static_bytes"]) / ex["layers"]            # one static layer of every group, full frame
    per_layer_cpu = (ex["render_cpu_s"] - base["render_cpu_s"]) / (ex["layers"] - base["layers"])
    extra = len(wins) - 2                                         # the needed windows beyond short and long
    fmt = (lambda c: "stored" if c is None else f"{c[0]:.2f} ({c[1]:.2f})")
    md = ["# Motion between captures: exact static windows against `nearest` (`benchmarks/bench_motion_windows.py`)",
          "",
          f"Renders made {made['start']} to {made['end'][-5:]} UTC on the shared 2-core AMD EPYC (AVX2), load "
          f"{made['load_start']:.1f} / {made['load_end']:.1f} (1-min average at start / end: other jobs ran beside "
          "it, so "
          "wall seconds are upper bounds; CPU seconds are the steadier measure). Rerun: "
          f"`python benchmarks/bench_motion_windows.py --case {a.case} --width {a.width} --height {a.height}"
          f"{' --all-presets' if a.all_presets else ''} --out docs`.",
          "",
          f"Scene: generator 2, seed {a.case.split(':')[0]}, {tod}, ego {info['speed_mps']:.1f} m/s, moving objects: "
          f"{', '.join(info['moving']) or 'none'}; `default` profile (spp 1, light_spp 32, K = 8) at "
          f"{a.width}x{a.height}, {a.frames} frame(s).",
          "",
          "## Error",
          "",
          "Relative RMS bias of a window's static radiance (all static groups, band sums per pixel) against a "
          f"brute-force truth (the staggered edges' bins cut into pieces of <= {a.fine_ms:g} ms, "
          f"{len(fine) - 1} bins, the moving objects placed in each), Monte Carlo noise removed with two independent "
          "renders per scheme (seeds 1, 2; static denoising off); each cell is `bias (resolution)` in %: the "
          "resolution, sqrt(2 SE) of the squared-bias estimate (delete-one jackknife over 8x8 pixel blocks), is the "
          "smallest bias the two renders tell apart from 0. `noise`: one truth render's relative RMS noise over "
          f"that window. `masked, eps` (evaluated on the truth renders): the window where a pixel's surface point "
          f"moves by >= eps px over the capture window (`render_tools.motion_bound`, grown by 1 px), the long "
          "window elsewhere; short and long are stored as such (`stored`). `exact spp 1, common`: the bins with "
          "common random numbers (`RenderOptions.static_bin_samples=\"common\"`: every bin of a frame draws the "
          "same per-pixel sample sequence).",
          "",
          "| window | noise | nearest spp 1 | exact spp 1 | nearest spp " f"{a.check_spp} | exact spp {a.check_spp} | "
          + " | ".join(f"masked, eps {e:g} px" for e in eps) + " | exact spp 1, common |",
          "|---|---|---|---|---|---|" + "---|" * (len(eps) + 1)]
    for r in rows:
        md.append(f"| {r[0]} | {r[1]:.1f} | " + " | ".join(fmt(c) for c in r[2:]) + " |")
    md += ["", "## Cost", "",
           "Measured (the renders with the profile's static denoising, second of two runs, kernels cached): render "
           "CPU seconds of the child process (user + system of every thread), its wall seconds, storage of the "
           "encoded scene (`compact`) and of its static group files.", "",
           "| scheme | static layers per group and frame | render CPU s | x nearest | render wall s | scene MB | "
           "x nearest | static files MB |", "|---|---|---|---|---|---|---|---|"]
    for name, _e, _bs, _l in schemes:
        c = cost[name]
        md.append(f"| {name} | {c['layers']} | {c['render_cpu_s']:.1f} | {c['render_cpu_s'] / base['render_cpu_s']:.2f}"
                  f" | {c['render_wall_s']:.1f} | {c['bytes'] / 1e6:.2f} | {c['bytes'] / base['bytes']:.2f} | "
                  f"{c['static_bytes'] / 1e6:.2f} |")
    md += ["", f"Estimated for the masked scheme (not built): short and long full frames as today plus the {extra} "
           "other needed windows (the staggered ones) traced and stored only in row-band tiles of 8 rows over the "
           "mask (`tiles`: their share of the image). Storage: today's scene plus tiles x one full static layer "
           f"({layer_bytes / 1e6:.2f} MB, the exact scheme's static bytes per layer) per extra window. Render CPU: "
           f"today's plus, per extra window, one full static layer's CPU ({per_layer_cpu:.2f} s, from the two "
           "measured rows) times tiles (lower end: tracing scales with area) or times 1 (upper end: a launch per "
           "window for the moving objects, as the bins have, with its fixed costs).", "",
           "| eps px | masked pixels % | tiles % | scene MB | x nearest | render CPU x nearest |", "|---|---|---|---|---|---|"]
    masked_cost = {}
    for e in eps:
        tf = band_tiles(masks[e])
        mb_ = base["bytes"] + extra * tf * layer_bytes
        lo = (base["render_cpu_s"] + extra * tf * per_layer_cpu) / base["render_cpu_s"]
        hi = (base["render_cpu_s"] + extra * per_layer_cpu) / base["render_cpu_s"]
        masked_cost[e] = (tf, mb_ / base["bytes"], lo, hi)
        md.append(f"| {e:g} | {100 * masks[e].mean():.0f} | {100 * tf:.0f} | {mb_ / 1e6:.2f} | "
                  f"{mb_ / base['bytes']:.2f} | {lo:.2f}-{hi:.2f} |")
    rc, rs = ex["render_cpu_s"] / base["render_cpu_s"], ex["bytes"] / base["bytes"]
    md += ["", "## Reading", "",
           "Scheme (a), static time bins aligned to the capture windows' edges, is the one implemented: exact for "
           "every window that is a union of bins, with the moving objects placed per bin, so each staggered capture "
           "sees the vehicles over its own time. Scheme (b), each needed window rendered and stored as such, holds "
           "one layer per distinct window (5 for split pixel + staggered) instead of the bins between their edges "
           "(6 here) and cannot serve a window it was not rendered for. `nearest` stays a named option for corpora "
           "without bins (format 3), recorded in every sample's `meta[\"static_windows\"]`.",
           "",
           f"Target (issue 38: render cost and storage within 1.5x of today's generator-2 scene): the bins took "
           f"{rc:.2f}x the CPU seconds and {rs:.2f}x the storage: {'met' if max(rc, rs) <= 1.5 else 'not met'}. The "
           f"static groups' full frames are {base['static_bytes'] / base['bytes'] * 100:.0f} % of today's scene, and "
           "each bin is one more full frame per static group. A sparse scheme must find pixels where nothing moves; "
           "with the ego camera moving every pixel of the static world moves, and the masked columns measure how "
           "much of the frame moves by more than eps over the capture window and what leaving the rest to the long "
           "window costs in error."]
    # the long-window question: estimator noise or bias? (the row of the long window, both spp)
    lw = rows[-1]
    tt = (window(truth[0], 0.0, tl, True).sum(0) * window(truth[1], 0.0, tl, True).sum(0)).ravel()
    ntop = max(1, tt.size // 1000)
    top1 = float(np.sort(tt)[::-1][:ntop].sum() / tt.sum())
    e1, e4 = lw[3], lw[5]
    md += ["", f"Long window, exact bins: {e1[0]:.2f} % (resolution {e1[1]:.2f} %) at spp 1, {e4[0]:.2f} % "
           f"(resolution {e4[1]:.2f} %) at spp {a.check_spp}; nearest {lw[2][0]:.2f} ({lw[2][1]:.2f}) and "
           f"{lw[4][0]:.2f} ({lw[4][1]:.2f}). "
           + ("Every long-window value lies below its resolution: what an earlier run of this page printed as 1.7-2.0 "
              "% for the bins against 0.00 for `nearest` was the squared-bias estimate's scatter (its sign decides "
              "between a positive value and 0), not a bias."
              if all(c[0] <= c[1] for c in (e1, e4, lw[2], lw[4])) else
              "Not every long-window value lies below its resolution: see the cells above.")
           + f" Raising the schemes' spp from 1 to {a.check_spp} does not lower the resolution ({e1[1]:.2f} -> "
           f"{e4[1]:.2f} %): it is set by what both columns share, the truth renders (spp 1 per piece), and by the "
           f"few bright pixels that dominate the sums (the brightest 0.1 % of the pixels, {ntop}, hold "
           f"{100 * top1:.1f} % of sum t1 t2 over the long window: a night scene's lamps; this relative RMS measures "
           "the lamps); resolving a smaller bias needs a truth at higher "
           "spp, not the schemes."]
    near_med = rows[1][2][0]
    md += ["", "Resolved cells (bias above its resolution), spp 1: `nearest` " + (", ".join(
        r[0] for r in rows if r[2][0] > r[2][1]) or "none") + "; exact " + (", ".join(
        r[0] for r in rows if r[3][0] > r[3][1]) or "none") + ". The other cells are within the scatter of this "
        "estimate at this size; the crossing-car test "
        "(`tests/render_tools/test_motion_windows.py`) is the sharper check that `nearest` misplaces a moving "
        "lamp in the short captures (2-3 px) and the bins do not (< 0.15 px)."]
    ex1, cr1 = err["exact", 1], err["common", 1]
    nz = [(label, 100 * noise(window(ex1[0], s0, n, True), window(ex1[1], s0, n, True)),
           100 * noise(window(cr1[0], s0, n, True), window(cr1[1], s0, n, True))) for label, s0, n in wins]
    md += ["", "Common random numbers (`exact spp 1, common`): each window's bias " + ", ".join(
        f"{r[0].split(' [')[0].split(' (')[0]} {r[-1][0]:.2f} ({r[-1][1]:.2f})" for r in rows)
        + " %; the relative RMS noise of one spp-1 render (the two seeds' difference) with independent / common "
        "bins: " + ", ".join(f"{lb.split(' [')[0].split(' (')[0]} {a_:.1f} / {c_:.1f}" for lb, a_, c_ in nz)
        + " %. A window of one bin keeps its noise; a window summing bins loses the averaging of their independent "
        "noise (the largest of the long window's bins is {:.0f} % of it)."
        .format(100 * max(np.diff(np.asarray(err["exact", 1][0]["edges"]))) / tl)]
    md += ["", "Where `nearest` goes wrong: the masked staggered medium window's error is " + " / ".join(
        f"{rows[1][6 + i][0]:.1f}" for i in range(len(eps))) + " % with eps " + " / ".join(f"{e:g}" for e in eps)
        + f" px, against `nearest`'s {near_med:.1f} %: most of it is in pixels whose surface point moves by less than "
        "a pixel over the capture window (sub-pixel lamps of the static world sliding across pixel borders under "
        "the ego motion), so bins left out where the motion is below a pixel give back most of the error, and at "
        f"{info['speed_mps']:.0f} m/s only the sky and the far middle of the road stay within 0.05 px (median "
        f"motion {np.median(motion[np.isfinite(motion)]):.2f} px at {a.width}x{a.height}; it scales with the "
        "focal length in px, so it doubles at twice the width)."]
    best = [e for e in eps if masked_cost[e][1] <= 1.5 and masked_cost[e][3] <= 1.5]
    md += ["", "Masked scheme: " + "; ".join(
        f"eps {e:g} px: {100 * masks[e].mean():.0f} % of the pixels masked (motion >= eps, grown by 1 px), tiles {100 * masked_cost[e][0]:.0f} %, "
        f"storage {masked_cost[e][1]:.2f}x, CPU {masked_cost[e][2]:.2f}-{masked_cost[e][3]:.2f}x, staggered "
        f"medium / short error {rows[1][6 + i][0]:.2f} / {rows[2][6 + i][0]:.2f} %"
        for i, e in enumerate(eps)) + ". " + (
        f"eps {best[-1]:g} px would meet the 1.5x target at its upper CPU estimate." if best else
        "No eps meets the 1.5x target at the upper CPU estimate.")]
    md += ["", "What the 1.5x target would need, measured (where the exact scheme's render time goes, and the bins' "
           "storage against the error of fewer mantissa bits): [motion-storage.md](motion-storage.md)."]
    text = "\n".join(md) + "\n"
    print(text)
    print(json.dumps({"rows": rows, "cost": cost, "masked_cost": {str(k): v for k, v in masked_cost.items()},
               "motion_px_quantiles": np.quantile(np.where(np.isfinite(motion), motion, 1e9),
                                                  [0.1, 0.25, 0.5, 0.75, 0.9]).tolist()},
              indent=1, default=float), file=sys.stderr)
    if a.out:
        atomic_write_text(Path(a.out) / "benchmarks" / "motion-windows.md", text)


if __name__ == "__main__":
    main()
