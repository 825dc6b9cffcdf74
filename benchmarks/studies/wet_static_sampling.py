"""A wet road's static light, traced and denoised, with the old and the new lamp choice on the water film
(``glossy_light_choice`` plain / lobe) and the two splits of the denoised frame among the static groups
(``static_split`` box / oidn): writes the section "Wet road: static light sampled by the film's lobe" of
docs/benchmarks/render.md.

A generator-2 wet night (``--seed``, default 7: the gallery's) renders frame 0 of its static groups (headlights,
streetlights, sky) at ``--size`` (default 320x180) with the ``default`` profile's samples, ``static_denoise: off``,
once per lamp choice, and a reference with ``lobe`` at spp ``--ref-spp`` (default 32; both choices are unbiased, the
lobe one has far less variance). Each spp-1 frame is denoised both ways (:func:`render_tools.denoise.denoise_static`).
Short window, outside the static lamps' boxes, CIE Y: ``light`` = sum / reference's; ``median err`` = median of
|Y - Y_ref| / Y_ref over the frame and over the road (the lower 42 % of rows); per group its light and median error
(pixels where the group's reference is over 1e-3 of its peak); ``colour`` = the luminance-weighted RMS distance of
CIE xy from the reference's on the road; ``p90/p10`` = the road's contrast (reference's in the first row).

Usage: ``python benchmarks/studies/wet_static_sampling.py [--seed 7] [--size 320 180] [--ref-spp 32] [--write]``.
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

SECTION = "## Wet road: static light sampled by the film's lobe (issue 40)"
STATIC = ("headlights", "streetlights", "skymap")


def _stats(out: dict, ref: dict, keep: np.ndarray, road: np.ndarray, Y) -> dict:
    """Light, median errors, per-group figures, road colour error and contrast of ``out`` (group -> (C, H, W))."""
    yr = {g: Y(v) for g, v in ref.items()}
    yo = {g: Y(v) for g, v in out.items()}
    tr, to = sum(yr.values()), sum(yo.values())
    e = np.abs(to - tr) / np.maximum(tr, 1e-6)
    xyz_r, xyz_o = Y(sum(ref.values()), full=True), Y(sum(out.values()), full=True)
    xy = lambda X: X[:2] / np.maximum(X.sum(0), 1e-30)  # noqa: E731
    d2 = ((xy(xyz_o) - xy(xyz_r)) ** 2).sum(0)
    w = tr * (keep & road)
    p10, p90 = np.percentile(to[road], [10, 90])
    groups = {}
    for g in yr:
        if yr[g][keep].sum() <= 0:
            continue
        m = keep & (yr[g] > 1e-3 * yr[g].max())
        groups[g] = (yo[g][keep].sum() / yr[g][keep].sum(),
                     float(np.median(np.abs(yo[g] - yr[g])[m] / yr[g][m])))
    return {"light": to[keep].sum() / tr[keep].sum(), "err": float(np.median(e[keep])),
            "road": float(np.median(e[keep & road])), "colour": float(np.sqrt((d2 * w).sum() / w.sum())),
            "contrast": p90 / p10, "groups": groups}


def main() -> None:
    from render_tools import denoise, spectra  # noqa: PLC0415
    from render_tools import render as rnd  # noqa: PLC0415
    from render_tools import scene as S  # noqa: PLC0415
    from render_tools.jobs import load_profile  # noqa: PLC0415

    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--size", type=int, nargs=2, default=(320, 180))
    ap.add_argument("--ref-spp", type=int, default=32)
    ap.add_argument("--write", action="store_true", help="write the section into docs/benchmarks/render.md")
    a = ap.parse_args()
    sc = S.generate_scene(a.seed, "night", generator=2, overrides={"weather": {"conditions": ["wet"]}})
    prof = dict(load_profile("default"), frames=1, aux=False, seed=a.seed, width=a.size[0], height=a.size[1],
                groups=STATIC, static_denoise="off")
    frames, secs = {}, {}
    for name, kw in (("plain", dict(glossy_light_choice="plain")), ("lobe", dict(glossy_light_choice="lobe")),
                     ("reference", dict(glossy_light_choice="lobe", spp=a.ref_spp))):
        opts = rnd.RenderOptions(**{**prof, **kw})
        t = time.perf_counter()
        frames[name] = {g: v["short"] for g, v in next(rnd.render_frames(sc, opts))["static"].items()}
        secs[name] = time.perf_counter() - t
        print(f"{name}: {secs[name]:.1f} s", flush=True)
    opts = rnd.RenderOptions(**prof)
    boxes = rnd.static_lamp_boxes(sc, opts, 0)
    H, W = a.size[1], a.size[0]
    keep = denoise.keep_mask((H, W), boxes)
    road = np.zeros((H, W), bool)
    road[int(H * 0.58):] = True

    def Y(x, full=False):
        xyz = spectra.spectral_to_xyz(np.asarray(x, np.float64), opts.bands_nm, opts.band_width_nm)
        return xyz if full else xyz[1]

    ref = frames["reference"]
    rows = [("reference", f"lobe, spp {a.ref_spp}", ref)]
    for choice in ("plain", "lobe"):
        rows.append((choice, "traced", frames[choice]))
        for split in ("box", "oidn"):
            rows.append((choice, f"denoised, {split}", denoise.denoise_static(frames[choice], boxes, split=split)))
    lines = [SECTION, "",
             f"`python benchmarks/studies/wet_static_sampling.py --seed {a.seed} --size {a.size[0]} {a.size[1]} "
             f"--ref-spp {a.ref_spp} --write`; {load_line()} (2-core AMD EPYC, AVX2, shared with other jobs). "
             f"Generator-2 wet night seed {a.seed}, frame 0, static groups only, short window, the `default` "
             f"profile's samples, against a `lobe` render at spp {a.ref_spp} (module docstring of the script for the "
             f"figures). Render wall s (one run each, one process): plain {secs['plain']:.1f}, lobe "
             f"{secs['lobe']:.1f}, reference {secs['reference']:.1f}.", "",
             "| lamp choice | image | light / ref | median err | road median err | headlights light, err | "
             "streetlights light, err | sky light, err | road colour err | road p90/p10 |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for choice, what, out in rows:
        s = _stats(out, ref, keep, road, Y)
        g = [f"{s['groups'][k][0]:.3f}, {100 * s['groups'][k][1]:.1f} %" if k in s["groups"] else "-" for k in STATIC]
        lines.append(f"| {choice} | {what} | {s['light']:.3f} | {100 * s['err']:.1f} % | {100 * s['road']:.1f} % | "
                     f"{' | '.join(g)} | {s['colour']:.4f} | {s['contrast']:.1f} |")
    lines.append("")
    print("\n".join(lines))
    if a.write:
        replace_section(ROOT / "docs" / "benchmarks" / "render.md", SECTION, lines)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "2")
    main()
