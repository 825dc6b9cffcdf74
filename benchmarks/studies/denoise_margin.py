"""The denoiser's mirrored margin sized by the crop (issue 40, deliverable 5: the v2 render within 1.5x of v1): writes
the section "Denoiser margin by crop" of docs/benchmarks/render-scale.md.

Protocol version 6 of ``lfmbench-v2`` gave Open Image Denoise every image mirrored :data:`render_tools.denoise.
OIDN_MARGIN_PX` (32) px beyond every edge (its own zero fill darkened the edges), a flickering lamp's small
reflection crop too, which grew several times over. Version 7 mirrors only the sides of a crop that are the image's
own edge (:func:`render_tools.denoise.crop_edges`); a side inside the image gets no margin: beyond it the lamp's
layer is 0 (nothing of it is traced or composed outside its grown crop), as the filter's zero padding assumes.
Three parts, each printed and (``--write``) written:

- ``cost``: process CPU seconds (every thread: the filter's own threads too) of one :func:`render_tools.denoise.
  oidn_rgb` call on exponential noise, (3, h, w) px, with 32 px on every side (version 6), none (a crop inside the
  image, version 7) and 32 px at the bottom only (a crop meeting the image's last row), median of ``--repeats``
  calls, the variants alternating.
- ``crops``: frame 0 of the generator-2 wet night of seed ``--seed`` (101) at ``--size`` (640x360), ``default``
  profile, every group, rendered once (the render's denoising timed: the static frames' calls and the reflection
  crops'); each reflection crop's inputs are kept and denoised again three ways, alternating, ``--repeats`` rounds:
  ``v6`` (32 px on every side), ``v7`` (32 px on the image's edges only) and ``context`` (the crop inside its
  zero-extended frame: up to 32 block px of the layer's real neighbours, zeros, on every side inside the image,
  clipped to the image, mirrored where it ends: what the filter would see denoising the layer as a whole frame).
  Over the crops with a side inside the image, pooled over their reflection pixels (traced, outside the lamp box),
  band sums: ``diff`` = RMS(v - context) / mean(context), the same for the traced input (``noise``, the scale the
  filter removes), and ``ring`` = the light of the outermost 4 px on the sides inside the image over context's.
  Each crop's summed light is the traced light in every variant (:func:`render_tools.denoise.denoise_reflection`
  scales it back), printed as a check.
- ``edges``: the composed short window (:func:`render_tools.preview.compose_window`) of frame 0 of that wet night at
  ``--edge-size`` (160x90), ``default`` profile's sample counts, denoised with version 6's margins and version 7's
  (the same samples: one process, the same seed), and a reference without any denoising (reflections traced per
  pixel, spp ``--ref-spp``, 32): each edge row and column's mean over all bands over the reference's (the table of
  docs/benchmarks/rendering-measurements.md, "Denoiser at the image edge").

Usage: ``python benchmarks/studies/denoise_margin.py [--parts cost crops edges] [--repeats 5] [--seed 101]
[--size 640 360] [--edge-size 160 90] [--ref-spp 32] [--write]`` (about 10 minutes on the 2-core machine, loaded).
"""
from __future__ import annotations

import argparse
import datetime
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH
from _timing import replace_section  # noqa: E402

SECTION = "## Denoiser margin by crop (issue 40)"
SIZES = ((16, 24), (90, 160), (360, 640))
RING_PX = 4


def _cpu(fn):
    c = time.process_time()
    out = fn()
    return time.process_time() - c, out


def part_cost(repeats: int) -> list[str]:
    from render_tools import denoise as D  # noqa: PLC0415

    m = D.OIDN_MARGIN_PX
    variants = {"every side (v6)": m, "none (inside, v7)": 0, "bottom only": (0, m, 0, 0)}
    rng = np.random.default_rng(0)
    lines = ["| crop (h x w px) | " + " | ".join(f"margin {k}: ms" for k in variants) + " | v7 / v6 |",
             "|---|" + "---|" * (len(variants) + 1)]
    for h, w in SIZES:
        x = rng.exponential(1.0, (3, h, w)).astype(np.float32)
        D.oidn_rgb(x)  # the filter's first call builds its device and network
        t = {k: [] for k in variants}
        for _ in range(repeats):
            for k, mg in variants.items():
                t[k].append(_cpu(lambda mg=mg: D.oidn_rgb(x, mg))[0])
        med = {k: 1e3 * statistics.median(v) for k, v in t.items()}
        ratio = med["none (inside, v7)"] / med["every side (v6)"]
        lines.append(f"| {h} x {w} | " + " | ".join(f"{v:.1f}" for v in med.values()) + f" | {ratio:.2f} |")
        print(lines[-1], flush=True)
    return lines


def _zero_context(bb, shape, block):
    """A denoiser for one crop's block image: the crop inside its zero-extended frame (module docstring)."""
    from render_tools import denoise as D  # noqa: PLC0415

    y0, x0, y1, x1 = bb
    H, W = shape
    m = D.OIDN_MARGIN_PX
    room = (y0 // block, -(-(H - y1) // block), x0 // block, -(-(W - x1) // block))  # block px to the image edge
    ctx = tuple(min(m, r) for r in room)
    mirror = tuple(m - c if c < m else 0 for c in ctx)  # the rest mirrored where the image ends

    def den(b):
        z = np.pad(b, ((0, 0), (ctx[0], ctx[1]), (ctx[2], ctx[3])))
        y = D.oidn_rgb(z, mirror)
        return y[:, ctx[0]:ctx[0] + b.shape[1], ctx[2]:ctx[2] + b.shape[2]]

    return den


def _capture(sc, opts):
    """Render frame 0 once: each reflection crop's inputs and the CPU of the static frames' and the crops' denoising."""
    from render_tools import denoise as D  # noqa: PLC0415
    from render_tools import render as rnd  # noqa: PLC0415

    calls, spent, box = [], {"static": 0.0, "reflection": 0.0, "n_static": 0, "in": False}, [None]
    inner_refl, inner_static, inner_edges = D.denoise_reflection, D.denoise_static, D.crop_edges

    def edges(bb, shape):
        box[0] = (tuple(int(v) for v in bb), tuple(shape))
        return inner_edges(bb, shape)

    def refl(img, traced, boxes, **kw):
        calls.append((img.copy(), traced.copy(), list(boxes), kw.get("edges"), box[0]))
        spent["in"] = True
        try:
            c, out = _cpu(lambda: inner_refl(img, traced, boxes, **kw))
        finally:
            spent["in"] = False
        spent["reflection"] += c
        return out

    def static(*a, **kw):
        if spent["in"]:  # a reflection crop's own call: counted with the crop
            return inner_static(*a, **kw)
        c, out = _cpu(lambda: inner_static(*a, **kw))
        spent["static"] += c
        spent["n_static"] += 1
        return out

    D.crop_edges, D.denoise_reflection, D.denoise_static = edges, refl, static
    try:
        wall = time.perf_counter()
        next(rnd.render_frames(sc, opts))
        spent["wall"] = time.perf_counter() - wall
    finally:
        D.crop_edges, D.denoise_reflection, D.denoise_static = inner_edges, inner_refl, inner_static
    return calls, spent


def _rel(a, b, m, mean):
    return float(np.sqrt((((a - b)[m]) ** 2).mean()) / mean)


def part_crops(seed: int, size, repeats: int) -> list[str]:
    from render_tools import denoise as D  # noqa: PLC0415
    from render_tools import render as rnd  # noqa: PLC0415
    from render_tools import scene as S  # noqa: PLC0415
    from render_tools.jobs import load_profile  # noqa: PLC0415

    sc = S.generate_scene(seed, "night", generator=2, overrides={"weather": {"conditions": ["wet"]}})
    prof = dict(load_profile("default"), frames=1, aux=False, seed=seed, width=size[0], height=size[1])
    calls, spent = _capture(sc, rnd.RenderOptions(**prof))
    other, _ = _capture(sc, rnd.RenderOptions(**{**prof, "seed": seed + 1}))  # the same crops, other samples
    print(f"render {spent['wall']:.1f} s wall; static denoise {spent['n_static']} calls {spent['static']:.2f} CPU s; "
          f"{len(calls)} reflection crops {spent['reflection']:.2f} CPU s", flush=True)
    every = (True,) * 4
    variants = {"v6": lambda c: D.denoise_reflection(c[0], c[1], c[2], edges=every),
                "v7": lambda c: D.denoise_reflection(c[0], c[1], c[2], edges=c[3]),
                "context": lambda c: D.denoise_reflection(c[0], c[1], c[2], denoiser=_zero_context(
                    c[4][0], c[4][1], D.REFLECTION_BLOCK_PX))}
    cpu = {k: [] for k in variants}
    outs = {}
    for _ in range(repeats):
        for k, fn in variants.items():
            tot, res = 0.0, []
            for c in calls:
                dt, y = _cpu(lambda fn=fn, c=c: fn(c))
                tot += dt
                res.append(y)
            cpu[k].append(tot)
            outs[k] = res
    pair = [i for i, c in enumerate(calls) if i < len(other) and other[i][4] == c[4]]  # same crop, other seed
    outs["v6 other seed"] = {i: variants["v6"](other[i]) for i in pair}
    med = {k: statistics.median(v) for k, v in cpu.items()}
    at_edge = sum(any(c[3]) for c in calls)
    d2 = {k: 0.0 for k in ("v7", "context", "traced", "v6 other seed")}
    ring_l = {k: 0.0 for k in ("v6", "v7", "context")}
    tot_l = n = 0.0
    light = {k: [] for k in variants}
    for i, (img, traced, boxes, e, _) in enumerate(calls):
        m = traced & D.keep_mask(traced.shape, boxes)
        for k in variants:
            got, want = outs[k][i][:, m].sum(dtype=np.float64), img[:, m].sum(dtype=np.float64)
            light[k].append(got / want if want > 0 else 1.0)
        if i not in pair or not m.any():
            continue
        ring = np.zeros(m.shape, bool)
        for side, sl in zip(e, ((slice(0, RING_PX), slice(None)), (slice(-RING_PX, None), slice(None)),
                                (slice(None), slice(0, RING_PX)), (slice(None), slice(-RING_PX, None)))):
            if not side:
                ring[sl] = True
        ring &= m
        ref = outs["v6"][i].sum(0)
        tot_l += float(ref[m].sum())
        n += float(m.sum())
        for k in ring_l:
            ring_l[k] += float(outs[k][i].sum(0)[ring].sum())
        for k, y in (("v7", outs["v7"][i]), ("context", outs["context"][i]), ("traced", img),
                     ("v6 other seed", outs["v6 other seed"][i])):
            d2[k] += float(((y.sum(0) - ref)[m] ** 2).sum())
    mean = tot_l / max(n, 1)
    rel = {k: np.sqrt(v / max(n, 1)) / mean for k, v in d2.items()}
    print({k: round(v, 3) for k, v in med.items()}, {k: round(float(v), 4) for k, v in rel.items()}, flush=True)
    hs = [c[0].shape[1] for c in calls]
    ws = [c[0].shape[2] for c in calls]
    lines = [f"Frame 0 of the generator-2 wet night of seed {seed} at {size[0]}x{size[1]}, `default` profile, every "
             f"group, rendered with version 7's margins: its denoising {spent['static'] + spent['reflection']:.2f} "
             f"CPU s ({spent['n_static']} calls on the static frames {spent['static']:.2f} CPU s, whole frames: the "
             f"same margins in both versions; {len(calls)} reflection crops {spent['reflection']:.2f} CPU s). The "
             f"crops ({min(hs)}-{max(hs)} x {min(ws)}-{max(ws)} px, their block images half that; {at_edge} meet the "
             f"image's edge on some side, every one has a side inside the image) denoised again, {repeats} rounds of "
             "the three rules alternating, CPU s of all crops (median) and that frame's denoising with them:",
             "",
             "| margins | reflection crops: CPU s | the frame's denoising: CPU s |",
             "|---|---|---|"]
    for k, label in (("v6", "32 px on every side (version 6)"), ("v7", "32 px on the image's edges only (version 7)"),
                     ("context", "crop inside its zero-extended frame")):
        lines.append(f"| {label} | {med[k]:.2f} | {med[k] + spent['static']:.2f} |")
    lines += ["", f"Against version 6, over the reflection pixels (traced, outside the lamp box) of the {len(pair)} "
              f"crops rendered with a second Monte Carlo seed too ({int(n)} px; band sums), RMS difference over the "
              f"mean: version 7 {rel['v7']:.4f}; the zero-extended frame {rel['context']:.4f}; version 6 with the "
              f"other seed's samples {rel['v6 other seed']:.3f} (the denoised crop's own noise); the traced input "
              f"{rel['traced']:.3f}. Light of the outermost {RING_PX} px on the sides inside the image (they hold "
              f"{ring_l['v6'] / tot_l:.2%} of the crops' light) over version 6's: version 7 "
              f"{ring_l['v7'] / ring_l['v6']:.4f}, zero-extended frame {ring_l['context'] / ring_l['v6']:.4f}. Each "
              "crop's summed light over its traced light (the denoiser scales it back): "
              + ", ".join(f"{k} {min(v):.6f}-{max(v):.6f}" for k, v in light.items()) + "."]
    for ln in lines:
        print(ln, flush=True)
    return lines


def part_edges(seed: int, size, ref_spp: int) -> list[str]:
    from render_tools import denoise as D  # noqa: PLC0415
    from render_tools import preview  # noqa: PLC0415
    from render_tools import render as rnd  # noqa: PLC0415
    from render_tools import scene as S  # noqa: PLC0415
    from render_tools.jobs import load_profile  # noqa: PLC0415

    sc = S.generate_scene(seed, "night", generator=2, overrides={"weather": {"conditions": ["wet"]}})
    base = dict(load_profile("default"), frames=1, aux=False, seed=seed, width=size[0], height=size[1])
    inner = D.crop_edges
    rows = {}
    for name, kw, every in (("version 6 margins", {}, True), ("version 7 margins", {}, False),
                            ("reference", dict(static_denoise="off", reflection_denoise="off",
                                               reflection_block_px=1, spp=ref_spp), False)):
        opts = rnd.RenderOptions(**{**base, **kw})
        D.crop_edges = (lambda bb, shape: (True,) * 4) if every else inner
        try:
            t = time.perf_counter()
            fr = next(rnd.render_frames(sc, opts))
        finally:
            D.crop_edges = inner
        img = preview.compose_window(fr, rnd.frame_timing(sc, opts, 0), "short").sum(0)
        rows[name] = np.array([img[-1].mean(), img[-2].mean(), img[0].mean(), img[:, 0].mean(), img[:, -1].mean()])
        print(name, f"{time.perf_counter() - t:.0f} s", rows[name], flush=True)
    ref = rows["reference"]
    lines = [f"| {seed} night wet, {size[0]}x{size[1]} | last row | row above | first row | first column | "
             "last column |", "|---|---|---|---|---|---|"]
    for name in ("version 6 margins", "version 7 margins"):
        lines.append(f"| {name} | " + " | ".join(f"{v:.3f}" for v in rows[name] / ref) + " |")
    for ln in lines:
        print(ln, flush=True)
    return lines


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--parts", nargs="+", default=["cost", "crops", "edges"], choices=["cost", "crops", "edges"])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seed", type=int, default=101)
    ap.add_argument("--size", type=int, nargs=2, default=(640, 360))
    ap.add_argument("--edge-size", type=int, nargs=2, default=(160, 90))
    ap.add_argument("--ref-spp", type=int, default=32)
    ap.add_argument("--write", action="store_true", help="write the section into docs/benchmarks/render-scale.md")
    a = ap.parse_args()
    start, load0, t0 = datetime.datetime.now(datetime.timezone.utc), os.getloadavg()[0], time.perf_counter()
    out = {}
    if "cost" in a.parts:
        out["cost"] = part_cost(a.repeats)
    if "crops" in a.parts:
        out["crops"] = part_crops(a.seed, a.size, a.repeats)
    if "edges" in a.parts:
        out["edges"] = part_edges(a.seed, a.edge_size, a.ref_spp)
    if not a.write:
        return
    lines = [SECTION, "", f"Generated by `benchmarks/studies/denoise_margin.py --parts {' '.join(a.parts)}` on "
             f"{start:%Y-%m-%d %H:%M} UTC, the project's shared 2-core AMD EPYC (AVX2), 1-minute load average "
             f"{load0:.1f} at the start and {os.getloadavg()[0]:.1f} at the end ({time.perf_counter() - t0:.0f} s; "
             "other jobs running), CPU: process seconds (all threads).", ""]
    if "cost" in out:
        lines += ["One `oidn_rgb` call on exponential noise, CPU ms, median of "
                  f"{a.repeats} alternating calls each:", "", *out["cost"], ""]
    if "crops" in out:
        lines += [*out["crops"], ""]
    if "edges" in out:
        lines += ["The composed short window's edge rows and columns (mean over all bands) over an undenoised "
                  f"reference (reflections per pixel, spp {a.ref_spp}), the same samples with either margin rule:",
                  "", *out["edges"], ""]
    lines += ["Run again with `python benchmarks/studies/denoise_margin.py --write`.", ""]
    replace_section(ROOT / "docs" / "benchmarks" / "render-scale.md", SECTION, lines)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "2")
    main()
