"""How much of scene generator 2's procedural textures (issue 40) the ``default`` profile's static-frame denoiser
keeps: writes docs/benchmarks/textures.md.

Frame 0 of a generator-2 scene (default: seed 7 by day, dry: the gallery's day street) is rendered at the
``default`` profile (640x360, render_tools/configs/render_profiles.yaml) three times: as the profile renders it
(static frames denoised, ``static_denoise: auto``) and twice traced (``static_denoise: off``) with two Monte Carlo
seeds, A and B. The same is done for the scene with every ``texture`` removed from its materials (flat colours, as
before issue 40), to tell texture from edges.

Measure (luminance Y of the short-window composite, :func:`bench_render.lum`): the *texture signal* of an image is its
high-pass part ``hp(x) = x - G_3(x)`` (``G_3`` a Gaussian of sigma 3 px, scipy.ndimage). A and B carry independent
noise, so ``cov(hp A, hp B)`` over a region estimates the variance of the high-pass signal of the expected image,
noise excluded; ``kept = cov(hp D, hp A) / cov(hp A, hp B)`` is the share of that signal the denoised image D
reproduces (1: all of it, in phase; 0: erased), also noise excluded (D's residual noise is independent of A's).
The RMS local contrast of the expectation is ``sqrt(cov(hp A, hp B)) / mean(A)``; with flat materials it is the
edges' alone. Regions: the road (rows below the horizon, 62-100 % of the height, the middle 60 % of the columns) and
the upper frame (rows 0-45 %: facades, windows, trees, sky).

With ``--texture-filter nearest`` (``RenderOptions.texture_filter``) the textured scene is measured with
nearest-texel lookups instead (the flat scene has no textures: not rendered again), written to its own section
("Nearest-texel lookups: ..."), and docs/img/texture_filter_near_camera.png shows the road nearest the camera
(rows 62-100 % of the height, the middle half of the columns, 3x enlarged), denoised, bilinear (top: the textured
scene measured again with bilinear lookups, the same seeds) and nearest (bottom), tone-mapped alike
(:func:`render_tools.preview.tonemap_srgb` of the pair).

Usage: ``python benchmarks/studies/texture_contrast.py [--seed 7] [--tod day] [--weather dry] [--texture-filter
bilinear|nearest] [--out docs]`` (26 minutes on the shared 2-core machine at load 20-25).
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH
from _timing import replace_section  # noqa: E402
from bench_render import lum  # noqa: E402

from lfmbench.fileio import atomic_write_text  # noqa: E402

#: This script's section of docs/benchmarks/textures.md, and the page's head when the page does not exist yet.
SECTION = "## Texture contrast kept by the denoiser"
PAGE_HEAD = ("# Procedural textures: what the denoiser keeps, what they cost (issue 40)\n\nSections: \"Texture contrast kept "
             "by the denoiser\" (`benchmarks/studies/texture_contrast.py`), \"What textures cost\" "
             "(`benchmarks/studies/texture_cost.py`); \"Reading the numbers\": by hand.\n")
#: Sigma of the Gaussian whose residual is the texture signal, px.
SIGMA_PX = 3.0
#: Regions: (name, rows as fractions of the height, columns as fractions of the width).
REGIONS = (("road", (0.62, 1.0), (0.2, 0.8)), ("upper frame", (0.0, 0.45), (0.0, 1.0)))


def _hp(y: np.ndarray) -> np.ndarray:
    from scipy.ndimage import gaussian_filter  # noqa: PLC0415

    return y - gaussian_filter(y, SIGMA_PX, mode="nearest")


def _cov(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean((a - a.mean()) * (b - b.mean())))


def _render(sc: dict, spectral: bool = False, **kw) -> tuple[np.ndarray, float]:
    """Luminance (H, W) cd/m^2 of frame 0's short composite at the default profile with ``kw`` (``spectral``: the
    composite (C, H, W) W sr^-1 m^-2 nm^-1 instead); CPU seconds."""
    import resource  # noqa: PLC0415

    from render_tools import render as rnd  # noqa: PLC0415
    from render_tools.jobs import load_profile  # noqa: PLC0415
    from render_tools.preview import compose_window  # noqa: PLC0415

    opts = rnd.RenderOptions(**dict(load_profile("default"), frames=1, aux=False, **kw))
    cpu = lambda: (lambda r: r.ru_utime + r.ru_stime)(resource.getrusage(resource.RUSAGE_SELF))  # noqa: E731
    c = cpu()
    fr = next(rnd.render_frames(sc, opts))
    img = compose_window(fr, rnd.frame_timing(sc, opts, 0), "short", shape=(len(opts.bands_nm), opts.height, opts.width))
    img = np.asarray(img, dtype=np.float64)
    return (img if spectral else lum(img)), cpu() - c


def measure(sc: dict, **kw) -> dict:
    """{region: (rms contrast of the expectation, kept share)} and the CPU seconds of the three renders; ``kw``:
    more RenderOptions. ``"D"``: the denoised render's spectral composite (C, H, W)."""
    Ds, c0 = _render(sc, spectral=True, seed=11, **kw)
    D = lum(Ds)
    A, c1 = _render(sc, seed=11, static_denoise="off", **kw)
    B, c2 = _render(sc, seed=12, static_denoise="off", **kw)
    H, W = A.shape
    out = {}
    for name, (r0, r1), (q0, q1) in REGIONS:
        s = (slice(int(r0 * H), int(r1 * H)), slice(int(q0 * W), int(q1 * W)))
        hd, ha, hb = _hp(D)[s], _hp(A)[s], _hp(B)[s]
        sig = _cov(ha, hb)
        out[name] = (float(np.sqrt(max(sig, 0.0)) / A[s].mean()), _cov(hd, ha) / sig if sig > 0 else float("nan"))
    out["cpu_s"] = (c0, c1, c2)
    out["D"] = Ds
    return out


def near_camera_figure(bilinear: np.ndarray, nearest: np.ndarray, path: Path) -> None:
    """docs/img/texture_filter_near_camera.png (module docstring) of two spectral composites (C, H, W)."""
    from render_tools import render as rnd  # noqa: PLC0415
    from render_tools.preview import tonemap_srgb, write_png  # noqa: PLC0415

    C, H, W = bilinear.shape
    r0, q0, q1 = int(0.62 * H), W // 4, 3 * W // 4
    pair = np.concatenate([bilinear[:, r0:, q0:q1], np.zeros((C, 4, q1 - q0)), nearest[:, r0:, q0:q1]], axis=1)
    rgb = tonemap_srgb(pair, rnd.DEFAULT_BANDS_NM, 10.0)
    write_png(np.repeat(np.repeat(rgb, 3, axis=0), 3, axis=1), path)


def tonemap_pair(bilinear: np.ndarray, nearest: np.ndarray) -> np.ndarray:
    """The difference (nearest - bilinear) of the figure's two halves, 8-bit sRGB levels (h, w, 3)."""
    from render_tools import render as rnd  # noqa: PLC0415
    from render_tools.preview import tonemap_srgb  # noqa: PLC0415

    C, H, W = bilinear.shape
    r0, q0, q1 = int(0.62 * H), W // 4, 3 * W // 4
    rgb = tonemap_srgb(np.concatenate([bilinear[:, r0:, q0:q1], nearest[:, r0:, q0:q1]], axis=1),
                       rnd.DEFAULT_BANDS_NM, 10.0).astype(float)
    return rgb[H - r0:] - rgb[:H - r0]


def main() -> None:
    from render_tools import scene as S  # noqa: PLC0415
    from render_tools.textures import untextured  # noqa: PLC0415

    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--tod", default="day")
    ap.add_argument("--weather", default="dry")
    ap.add_argument("--texture-filter", default="bilinear", choices=("bilinear", "nearest"))
    ap.add_argument("--out", default=str(ROOT / "docs"))
    a = ap.parse_args()
    load0, t0 = os.getloadavg()[0], time.time()
    sc = S.generate_scene(a.seed, a.tod, generator=2, overrides={"weather": {"conditions": [a.weather]}})
    if a.texture_filter == "nearest":
        return _nearest(a, sc, load0, t0)
    flat = untextured(sc)
    # bilinear lookups, as measured before `auto` became nearest (--texture-filter nearest: both)
    res = {"textured": measure(sc, texture_filter="bilinear"), "flat": measure(flat)}
    load1 = os.getloadavg()[0]
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [SECTION, "",
             f"Generated by `benchmarks/studies/texture_contrast.py` on {date}, {platform.machine()} "
             f"({os.cpu_count()} cores; the project's shared 2-core AMD EPYC, AVX2), 1-minute load average "
             f"{load0:.1f} at the start and {load1:.1f} at the end ({(time.time() - t0) / 60:.0f} min): scene "
             f"generator 2, seed {a.seed}, {a.tod}, {a.weather}, frame 0 at the `default` profile (640x360). "
             "Texture signal: the high-pass part of luminance (residual of a Gaussian of sigma 3 px); its RMS over "
             "the region relative to the region's mean luminance, noise excluded (the covariance of two traced renders "
             "of independent seeds); kept: the share of that signal the denoised render reproduces (module "
             "docstring). Flat: the same scene with every texture removed (what remains is edges).", "",
             "| materials | region | RMS local contrast of the expectation | kept by the denoiser |", "|---|---|---|---|"]
    for kind in ("textured", "flat"):
        for name, *_ in REGIONS:
            c, k = res[kind][name]
            lines.append(f"| {kind} | {name} | {100 * c:.1f} % | {100 * k:.0f} % |")
    cd, ca, cb = res["textured"]["cpu_s"]
    fd, fa, fb = res["flat"]["cpu_s"]
    lines += ["", f"CPU seconds of one frame (this process, loaded machine): textured {cd:.1f} denoised / "
              f"{ca:.1f} and {cb:.1f} traced; flat {fd:.1f} / {fa:.1f} and {fb:.1f} (the first render of a kind "
              "also compiles its kernels).", "",
              "Run again with `python benchmarks/studies/texture_contrast.py`.", ""]
    path = Path(a.out) / "benchmarks" / "textures.md"
    if not path.exists():
        atomic_write_text(path, PAGE_HEAD)
    replace_section(path, SECTION, lines)
    print("\n".join(lines))


def _nearest(a, sc: dict, load0: float, t0: float) -> None:
    """``--texture-filter nearest``: the textured scene measured with nearest-texel lookups, its own section, and
    the figure of the road near the camera (module docstring)."""
    res = measure(sc, texture_filter="nearest")
    bil = measure(sc, texture_filter="bilinear")  # the same scene and seeds: the figures compare like with like
    near_camera_figure(bil["D"], res["D"], Path(a.out) / "img" / "texture_filter_near_camera.png")
    load1 = os.getloadavg()[0]
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    section = "## Nearest-texel lookups: texture contrast kept, the road near the camera"
    lines = [section, "",
             f"Generated by `benchmarks/studies/texture_contrast.py --texture-filter nearest` on {date}, the "
             f"project's shared 2-core AMD EPYC (AVX2), 1-minute load average {load0:.1f} at the start and "
             f"{load1:.1f} at the end ({(time.time() - t0) / 60:.0f} min): as \"Texture contrast kept by the "
             "denoiser\", the textured scene rendered with `texture_filter: nearest` and again with `bilinear` (seed "
             f"{a.seed}, {a.tod}, {a.weather}, frame 0, 640x360).", "",
             "| materials | region | RMS local contrast of the expectation | kept by the denoiser |",
             "|---|---|---|---|"]
    for kind, r in (("nearest", res), ("bilinear", bil)):
        for name, *_ in REGIONS:
            c, k = r[name]
            lines.append(f"| textured, {kind} | {name} | {100 * c:.1f} % | {100 * k:.0f} % |")
    d = np.abs(tonemap_pair(bil["D"], res["D"]))
    lines += ["", "CPU seconds of one frame (this process, loaded machine): " + "; ".join(
        f"{kind} {r['cpu_s'][0]:.1f} denoised / {r['cpu_s'][1]:.1f} and {r['cpu_s'][2]:.1f} traced"
        for kind, r in (("nearest", res), ("bilinear", bil))) + " (the first render of a kind also compiles its "
              f"kernels). The figure's two halves (8-bit sRGB) differ by {d.mean():.2f} on average, "
              f"{np.percentile(d, 99):.0f} at the 99th percentile.", "",
              "![The road nearest the camera, denoised: bilinear (top) and nearest-texel (bottom) lookups]"
              "(../img/texture_filter_near_camera.png)", "",
              "Run again with `python benchmarks/studies/texture_contrast.py --texture-filter nearest`.", ""]
    replace_section(Path(a.out) / "benchmarks" / "textures.md", section, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
