"""Speckle of the flickering lamps' reflections on a wet road, traced and denoised (``reflection_denoise``): writes
the section "Reflection speckle" of docs/benchmarks/render.md and crops (PNG) of the flickering layers.

A generator-2 wet night (``--seed``, default 7: the gallery's) renders frame 0 of its flickering groups only (the
lamps' crops: boxes and reflections) at ``--size`` (default 320x180) with the ``default`` profile's sample counts,
four ways, one process, the same Monte Carlo seed:

- ``traced``: the reflections as traced (``reflection_denoise: off``, 2 x 2 px blocks at spp 1);
- ``denoised``: the same samples, each light's reflection denoised alone (``reflection_denoise: oidn``);
- ``per pixel``: ``reflection_block_px: 1`` (every pixel traced at spp 1, 4x the reflection's samples);
- ``reference``: per pixel at spp ``--ref-spp`` (default 16: 64x the traced reflection's samples per pixel).

Over the reflection pixels of every grown crop (outside the lamp's padded box, where the reference or the
variant is non-zero), summed over the crops, each variant's (mean over its K bins) CIE Y against the
reference's: ``rel RMS`` = RMS(Y - Y_ref) / mean(Y_ref); ``light`` = sum Y / sum Y_ref; ``grain`` = RMS of
the error's fine part, E - G(E) with E = Y - Y_ref and G a Gaussian blur of sigma 1.5 px, over mean(Y_ref) (the
2 x 2 px speckle: noise at 1-4 px; the streaks' own sharp structure, which the reference has, cancels in E);
``colour`` = the luminance-weighted RMS difference of the three broad bands'
shares (400-500, 500-600, 600-700 nm) from the reference's (0: the reference's hue everywhere). Wall seconds of
each render in the process (the kernels compiled by the first; the rest cache hits).

Usage: ``python benchmarks/studies/reflection_speckle.py [--seed 7] [--size 320 180] [--ref-spp 16]
[--png DIR] [--write]``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH
from _timing import load_line, replace_section  # noqa: E402

SECTION = "## Reflection speckle (issue 40)"
FLICKER_GROUPS = ("otherlights", "signals")


def _crops(frame: dict) -> dict:
    """light id -> (bbox, (C, h, w) float64 mean over the light's bins)."""
    out = {}
    for items in frame["lights"].values():
        for lid, bb, arr in items:
            out[lid] = (bb, np.asarray(arr, np.float64).mean(0))
    return out


def _blur(y: np.ndarray, sigma: float = 1.5) -> np.ndarray:
    from scipy.ndimage import gaussian_filter  # noqa: PLC0415

    return gaussian_filter(y, sigma, mode="nearest")


def metrics(var: dict, ref: dict, lamp_boxes: dict, bands_nm, width_nm: float) -> dict:
    """Pooled speckle metrics of ``var`` against ``ref`` (module docstring) over the reflection pixels."""
    from render_tools import denoise, spectra  # noqa: PLC0415

    parts = denoise.broad_bands(len(bands_nm))
    d2 = yr_sum = yv_sum = hp2 = n = col2 = ywt = 0.0
    for lid, (bb, r) in ref.items():
        if lid not in var:
            continue
        v = var[lid][1]
        y0, x0, _, _ = bb
        m = (r.sum(0) > 0) | (v.sum(0) > 0)
        lb = lamp_boxes.get(lid)
        if lb is not None:
            m[max(lb[0] - y0, 0):max(lb[2] - y0, 0), max(lb[1] - x0, 0):max(lb[3] - x0, 0)] = False
        if not m.any():
            continue
        Yr = spectra.spectral_to_xyz(r, bands_nm, width_nm)[1]
        Yv = spectra.spectral_to_xyz(v, bands_nm, width_nm)[1]
        d2 += float(((Yv - Yr)[m] ** 2).sum())
        yr_sum += float(Yr[m].sum())
        yv_sum += float(Yv[m].sum())
        E = Yv - Yr
        hp2 += float(((E - _blur(E))[m] ** 2).sum())
        n += int(m.sum())
        br = np.stack([r[p].sum(0) for p in parts])
        bv = np.stack([v[p].sum(0) for p in parts])
        sr, sv = br / np.maximum(br.sum(0), 1e-30), bv / np.maximum(bv.sum(0), 1e-30)
        w = Yr * m
        col2 += float((((sv - sr) ** 2).sum(0) * w).sum())
        ywt += float(w.sum())
    mean_r = yr_sum / max(n, 1)
    return {"rel_rms": np.sqrt(d2 / max(n, 1)) / mean_r, "light": yv_sum / yr_sum,
            "grain": np.sqrt(hp2 / max(n, 1)) / mean_r, "colour": np.sqrt(col2 / max(ywt, 1e-30)),
            "pixels": n}


def _layers_png(crops: dict, shape: tuple, bands_nm, width_nm, path: Path, window=None, scale=None) -> float:
    """The flickering layers summed into the frame (``shape`` (C, H, W)), tone-mapped with a fixed exposure
    ``scale`` (None: the 99th percentile of Y maps to white), cut to ``window`` (y0, x0, y1, x1), enlarged 4x;
    returns the scale used."""
    from render_tools import preview, spectra  # noqa: PLC0415

    img = np.zeros(shape, np.float64)
    for bb, a in crops.values():
        y0, x0, y1, x1 = bb
        img[:, y0:y1, x0:x1] += a
    if window is not None:
        a, b, c, d = window
        img = img[:, a:c, b:d]
    xyz = spectra.spectral_to_xyz(img, bands_nm, width_nm)
    if scale is None:
        scale = float(np.percentile(xyz[1], 99)) or 1.0
    import colour  # noqa: PLC0415

    rgb = colour.XYZ_to_sRGB(np.moveaxis(xyz / scale, 0, -1))
    rgb8 = (np.clip(rgb, 0, 1) ** (1 / 1.0) * 255 + 0.5).astype(np.uint8)
    rgb8 = np.repeat(np.repeat(rgb8, 4, axis=0), 4, axis=1)
    preview.write_png(rgb8, path)
    return scale


def main() -> None:
    from render_tools import render as rnd  # noqa: PLC0415
    from render_tools import scene as S  # noqa: PLC0415
    from render_tools.jobs import load_profile  # noqa: PLC0415

    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--size", type=int, nargs=2, default=(320, 180))
    ap.add_argument("--ref-spp", type=int, default=16)
    ap.add_argument("--png", default=None, help="folder for the crops (PNG) of the flickering layers")
    ap.add_argument("--window", type=int, nargs=4, default=None, help="y0 x0 y1 x1 px of the PNG crops")
    ap.add_argument("--cache", default=None, help="folder keeping each variant's crops (.npz) between runs")
    ap.add_argument("--write", action="store_true", help="write the section into docs/benchmarks/render.md")
    a = ap.parse_args()
    sc = S.generate_scene(a.seed, "night", generator=2, overrides={"weather": {"conditions": ["wet"]}})
    prof = dict(load_profile("default"), frames=1, aux=False, seed=a.seed, width=a.size[0], height=a.size[1],
                groups=FLICKER_GROUPS)
    variants = {"traced": dict(reflection_denoise="off"), "denoised": dict(reflection_denoise="oidn"),
                "per pixel": dict(reflection_denoise="off", reflection_block_px=1),
                "reference": dict(reflection_denoise="off", reflection_block_px=1, spp=a.ref_spp)}
    from render_tools import denoise  # noqa: PLC0415

    res, secs, dn = {}, {}, {}
    inner = denoise.denoise_reflection
    spent = [0.0]

    def timed(*args, **kw):  # CPU seconds of the reflection denoiser, call by call
        c = time.process_time()
        try:
            return inner(*args, **kw)
        finally:
            spent[0] += time.process_time() - c

    denoise.denoise_reflection = timed
    for name, kw in variants.items():
        opts = rnd.RenderOptions(**{**prof, **kw})
        cached = Path(a.cache) / f"{a.seed}_{a.size[0]}x{a.size[1]}_{a.ref_spp}_{name.replace(' ', '_')}.npz" \
            if a.cache else None
        if cached is not None and cached.exists():
            z = np.load(cached)
            secs[name], dn[name] = float(z["secs"]), float(z["dn_cpu"]) if "dn_cpu" in z.files else 0.0
            res[name] = {int(k[1:]): (tuple(int(v) for v in z["b" + k[1:]]), z[k]) for k in z.files if k[0] == "a"}
        else:
            t, spent[0] = time.perf_counter(), 0.0
            res[name] = _crops(next(rnd.render_frames(sc, opts)))
            secs[name], dn[name] = time.perf_counter() - t, spent[0]
            if cached is not None:
                import io  # noqa: PLC0415

                from lfmbench.fileio import atomic_write_bytes  # noqa: PLC0415

                cached.parent.mkdir(parents=True, exist_ok=True)
                buf = io.BytesIO()
                np.savez(buf, secs=secs[name], dn_cpu=dn[name], **{f"a{k}": v[1] for k, v in res[name].items()},
                         **{f"b{k}": np.array(v[0]) for k, v in res[name].items()})
                atomic_write_bytes(cached, buf.getvalue())  # temporary name, then rename
        print(f"{name}: {secs[name]:.1f} s, {len(res[name])} crops", flush=True)
    opts = rnd.RenderOptions(**prof)
    geo = rnd.SceneGeometry(sc, opts)
    tm = rnd.frame_timing(sc, opts, 0)
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    by_id = {lt["id"]: lt for lt in sc["lights"]}
    lamp_boxes = {lid: geo.light_bbox(by_id[lid], t_obj, *tm["window"], moving=True, reflection=False)
                  for lid in res["reference"]}
    ref = res["reference"]
    rows = []
    for name in ("traced", "denoised", "per pixel", "reference"):
        m = metrics(res[name], ref, lamp_boxes, opts.bands_nm, opts.band_width_nm)
        rows.append((name, m, secs[name], dn[name]))
        print(name, {k: round(float(v), 4) for k, v in m.items()}, flush=True)
    if a.png:
        out = Path(a.png)
        out.mkdir(parents=True, exist_ok=True)
        shape = (len(opts.bands_nm), opts.height, opts.width)
        scale = None
        for name in ("reference", "traced", "denoised", "per pixel"):
            scale = _layers_png(res[name], shape, opts.bands_nm, opts.band_width_nm,
                                out / f"refl_{name.replace(' ', '_')}.png", a.window, scale)
    lines = [SECTION, "",
             f"`python benchmarks/studies/reflection_speckle.py --seed {a.seed} --size {a.size[0]} {a.size[1]} "
             f"--ref-spp {a.ref_spp} --write`; {load_line()} (2-core AMD EPYC, AVX2, shared with other jobs: the "
             f"seconds are one run each, in one process, the first with the kernels' compilation). Generator-2 wet "
             f"night seed {a.seed}, frame 0, flickering groups only, the `default` profile's samples; reflection "
             f"pixels of all grown crops ({int(rows[0][1]['pixels']):,} px) against a per-pixel render at spp "
             f"{a.ref_spp} (module docstring of the script for the metrics).", "",
             "| reflections | rel RMS of Y | light / reference | grain (1-4 px) | colour error | render wall s | "
             "of it denoising, CPU s |",
             "|---|---|---|---|---|---|---|"]
    for name, m, s, d in rows:
        lines.append(f"| {name} | {m['rel_rms']:.3f} | {m['light']:.3f} | {m['grain']:.3f} | "
                     f"{m['colour']:.3f} | {s:.1f} | {d:.2f} |")
    lines.append("")
    print("\n".join(lines))
    if a.write:
        replace_section(ROOT / "docs" / "benchmarks" / "render.md", SECTION, lines)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "2")
    main()
