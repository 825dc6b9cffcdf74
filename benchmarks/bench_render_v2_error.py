"""Error of the ``default`` render profile on scene generator 2 (lfmbench-v2) scenes against a high-spp reference
(issue 23): writes the section "Scene generator 2 (issue 23)" of docs/render-benchmark.md.

For each case (seed, time of day, generator 2's weather, or ``v1`` for the generator-1 scene of that seed and time of
day, measured the same way for comparison; default: a day, a dry night and a wet night of generator 2) frame 0 is
rendered at 640x360 with the ``default`` profile's options (render_tools/configs/render_profiles.yaml, every other
field at its :class:`render_tools.render.RenderOptions` default, seed 11) and as a reference with spp
:data:`REF_SPP`, light_spp :data:`REF_LIGHT_SPP`, the same K, every reflection traced in all K bins
(``reflection_bins=None``, ``reflection_min_lux=0``: no approximation of the wet road). In a wet scene the default
options are also rendered with exact reflections, so that the error of the approximations
(``reflection_bins``, ``reflection_min_lux``) is seen apart from the Monte Carlo noise.

Errors, on luminance Y as :mod:`bench_render` computes them (the same functions):

- LED bins: relative RMSE over the LED pixels of every flickering light's bins, pooled (a pixel of a light's crop
  whose reference bin-mean exceeds 5 % of the crop maximum), the reference cut to the default's crop;
- short-window composite (static groups + every flickering light at its nominal level): relative RMSE over the
  reference's light mask (LED px), the all-pixel relMSE^0.5 and the median per-pixel relative error; the long
  window's median too (``reflection_bins`` 1 holds one noise draw over all bins, which the long window sums);
- wet scenes: the median relative error of the short composite over the *reflection pixels*: where the reference's
  flickering layers outside the lamps' own boxes bring more than 5 % of the pixel's luminance.

The reference has its own noise (spp 4 against 1: the static part's measured error is up to sqrt(1 + 1/4) = 1.12
times the true one, less for the LED pixels); the errors are upper bounds. References are kept in ``--cache`` (a
folder of pickles) so that a re-run only renders what changed.

Usage: ``python benchmarks/bench_render_v2_error.py [--cases 202:day:dry 101:night:dry 101:night:wet]
[--cache DIR] [--quick]``.
"""
from __future__ import annotations

import argparse
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH
from _timing import replace_section  # noqa: E402
from bench_render import V2_SECTION as SECTION  # noqa: E402
from bench_render import led_sel, lum, median_rel_error, rel_mse_pixels, rel_rmse  # noqa: E402

from lfmbench.fileio import atomic_write_bytes, load_yaml  # noqa: E402

#: Default cases: seed, time of day, generator 2's weather or v1 (the scenes of docs/render-scale-benchmark.md).
CASES = ("202:day:v1", "202:day:dry", "101:night:v1", "101:night:dry", "101:night:wet")
#: Reference sample counts (per band pass): full frames, lamp crops.
REF_SPP, REF_LIGHT_SPP = 4, 256
#: Share of a pixel's reference luminance above which the flickering layers' light outside the lamps' own boxes
#: makes it a reflection pixel.
REFLECTION_SHARE = 0.05
SIZE = (640, 360)


def _frame(sc, opts, cache: Path | None, tag: str):
    """Frame 0 of ``sc`` rendered with ``opts`` (from ``cache``/``tag``.pkl when there); returns (frame, CPU s)."""
    import resource  # noqa: PLC0415

    from render_tools import render  # noqa: PLC0415

    f = cache / f"{tag}.pkl" if cache is not None else None
    if f is not None and f.exists():
        with open(f, "rb") as fh:
            return pickle.load(fh)
    ru = lambda: (lambda r: r.ru_utime + r.ru_stime)(resource.getrusage(resource.RUSAGE_SELF))  # noqa: E731
    c = ru()
    out = (next(render.render_frames(sc, opts)), ru() - c)
    if f is not None:
        atomic_write_bytes(f, pickle.dumps(out))
    return out


def bins_error_cut(frame: dict, ref: dict) -> float:
    """Relative RMSE of luminance over the LED pixels of every light's bins, pooled; the reference's crop (which may
    hold a reflection the frame left out) is cut to the frame's crop. Same K in both."""
    num = den = 0.0
    for g, items in frame["lights"].items():
        refs = {lid: (bb, b) for lid, bb, b in ref["lights"][g]}
        for lid, (y0, x0, y1, x1), b in items:
            (ry0, rx0, _, _), rb = refs[lid]
            rb = rb[:, :, y0 - ry0:y1 - ry0, x0 - rx0:x1 - rx0]
            sel = led_sel(rb)
            num += float(np.sum((lum(b) - lum(rb))[:, sel].astype(np.float64) ** 2))
            den += float(np.sum(lum(rb)[:, sel].astype(np.float64) ** 2))
    return float(np.sqrt(num / den)) if den > 0 else float("nan")


def reflection_pixels(sc, ref: dict, opts, ref_short: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels where the reference's flickering layers outside the lamps' own boxes bring more than
    :data:`REFLECTION_SHARE` of the short composite's luminance."""
    from render_tools import render  # noqa: PLC0415

    tm = render.frame_timing(sc, opts, 0)
    geo = render.SceneGeometry(sc, opts)
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    acc = np.zeros(ref_short.shape[1:])
    lights = {lt["id"]: lt for lt in sc["lights"]}
    a, b = tm["short"]
    edges = np.asarray(tm["bin_edges"])
    ov = np.clip(np.minimum(edges[1:], b) - np.maximum(edges[:-1], a), 0, None) / (b - a)
    for items in ref["lights"].values():
        for lid, (y0, x0, y1, x1), bins in items:
            y = lum(np.tensordot(ov, bins, axes=(0, 0)))
            lamp = geo.light_bbox(lights[lid], t_obj, *tm["window"], moving=True, reflection=False)
            if lamp is not None:
                ly0, lx0, ly1, lx1 = lamp
                y[max(ly0 - y0, 0):max(ly1 - y0, 0), max(lx0 - x0, 0):max(lx1 - x0, 0)] = 0.0
            acc[y0:y1, x0:x1] += y
    return acc > REFLECTION_SHARE * np.maximum(lum(ref_short), 1e-30)


def evaluate(sc, frame: dict, ref: dict, opts, refl_px: np.ndarray | None) -> dict:
    from render_tools import preview, render  # noqa: PLC0415

    tm = render.frame_timing(sc, opts, 0)
    shape = (len(opts.bands_nm), opts.height, opts.width)
    out = {"led_bins": bins_error_cut(frame, ref)}
    for win in ("short", "long"):
        img, rimg = (preview.compose_window(f, tm, win, shape) for f in (frame, ref))
        out[f"median_{win}"] = median_rel_error(img, rimg)
        if win == "short":
            led = ref["aux"]["mask.light"] >= 0
            out["led_px"] = rel_rmse(img, rimg, led)
            out["relmse"] = rel_mse_pixels(img, rimg)
            if refl_px is not None and refl_px.any():
                y, yr = lum(img)[refl_px], lum(rimg)[refl_px]
                ok = yr > 0
                out["median_reflection_px"] = float(np.median(np.abs(y[ok] - yr[ok]) / yr[ok]))
                out["reflection_px"] = int(refl_px.sum())
    return out


def main() -> None:
    from render_tools import render, scene  # noqa: PLC0415

    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", nargs="+", default=list(CASES),
                    help="seed:time of day:generator 2's weather, or seed:time of day:v1 (a generator-1 scene)")
    ap.add_argument("--cache", default=None, help="folder for the rendered frames (pickles), reused when there")
    ap.add_argument("--out", default=str(ROOT / "docs"))
    ap.add_argument("--quick", action="store_true", help="160x90, reference spp 2 / light_spp 32 (smoke run)")
    a = ap.parse_args()
    cache = Path(a.cache) if a.cache else None
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    prof = load_yaml(ROOT / "render_tools" / "configs" / "render_profiles.yaml")["default"]
    W, H = (160, 90) if a.quick else SIZE
    ref_spp, ref_light_spp = (2, 32) if a.quick else (REF_SPP, REF_LIGHT_SPP)
    base = dict(width=W, height=H, frames=1, seed=11, bins=prof["bins"])
    default = render.RenderOptions(**{**base, "spp": prof["spp"], "light_spp": prof["light_spp"]})
    exact_default = render.RenderOptions(**{**base, "spp": prof["spp"], "light_spp": prof["light_spp"],
                                            "reflection_bins": None, "reflection_min_lux": 0.0})
    refo = render.RenderOptions(**{**base, "spp": ref_spp, "light_spp": ref_light_spp, "seed": 999,
                                   "reflection_bins": None, "reflection_min_lux": 0.0})
    rows = []
    load0 = os.getloadavg()[0]
    for c in a.cases:
        seed, tod, weather = c.split(":")
        kw = {} if weather == "v1" else {"generator": 2, "overrides": {"weather": {"conditions": [weather]}}}
        sc = scene.generate_scene(int(seed), tod, scene_id=f"{tod}_{seed}_{weather}", **kw)
        t = time.perf_counter()
        ref, ref_cpu = _frame(sc, refo, cache, f"ref_{c.replace(':', '_')}")
        print(c, "reference", f"{time.perf_counter() - t:.0f} s", flush=True)
        wet = render.SceneGeometry(sc, default).wet is not None
        tm = render.frame_timing(sc, refo, 0)
        ref_short = preview_short(sc, ref, refo, tm)
        refl_px = reflection_pixels(sc, ref, refo, ref_short) if wet else None
        settings = [("default", default)] + ([("default, exact reflections", exact_default)] if wet else [])
        for name, opts in settings:
            fr, cpu = _frame(sc, opts, cache, f"{name.split(',')[0]}{'_exact' if ',' in name else ''}_"
                                               f"{c.replace(':', '_')}")
            r = {"case": c, "setting": name, "cpu_s": cpu, "ref_cpu_s": ref_cpu, **evaluate(sc, fr, ref, opts,
                                                                                              refl_px)}
            rows.append(r)
            print(r, flush=True)
    load1 = os.getloadavg()[0]
    write_section(rows, Path(a.out), load0, load1, (W, H), (ref_spp, ref_light_spp))


def preview_short(sc, frame, opts, tm) -> np.ndarray:
    from render_tools import preview  # noqa: PLC0415

    return preview.compose_window(frame, tm, "short", (len(opts.bands_nm), opts.height, opts.width))


def write_section(rows: list, out: Path, load0: float, load1: float, size=SIZE,
                  ref=(REF_SPP, REF_LIGHT_SPP)) -> None:
    def f(r, k):
        return f"{r[k]:.3f}" if k in r else "-"

    lines = [SECTION, "",
             f"Generated by `benchmarks/bench_render_v2_error.py` (1-minute load average {load0:.1f} at the start, "
             f"{load1:.1f} at the end; CPU seconds of the frame in the process, user + system): frame 0 of scene "
             f"generator 2 scenes at {size[0]}x{size[1]} with the `default` profile (spp 1, light_spp 32, K 8, "
             "reflection_bins 1, reflection_min_lux 2e-3), and in wet scenes the same with exact reflections "
             f"(reflection_bins = K, reflection_min_lux 0), against a reference of spp {ref[0]}, light_spp "
             f"{ref[1]}, K 8 with exact reflections (errors are upper bounds: the reference's own noise is in them). Targets (issue 23): LED pixels <= 2 % relative RMSE, all-pixel "
             "median <= 10 %. Reflection px: where the reference's flickering layers outside the lamps' own boxes "
             f"bring more than {REFLECTION_SHARE:.0%} of the pixel's luminance.", "",
             "| scene (seed:time:weather or v1) | setting | CPU s / frame (reference) | rel. RMSE LED bins | rel. RMSE LED px "
             "(short composite) | all px relMSE^0.5 | all px median rel. error (short) | (long) | reflection px: "
             "median rel. error (count) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        refl = (f"{r['median_reflection_px']:.3f} ({r['reflection_px']})" if "median_reflection_px" in r else "-")
        lines.append(f"| {r['case']} | {r['setting']} | {r['cpu_s']:.1f} ({r['ref_cpu_s']:.0f}) | "
                     f"{f(r, 'led_bins')} | "
                     f"{f(r, 'led_px')} | {f(r, 'relmse')} | {f(r, 'median_short')} | {f(r, 'median_long')} | "
                     f"{refl} |")
    lines += ["", "Run again with `python benchmarks/bench_render_v2_error.py --cache /tmp/v2err` (references "
              "are the bulk of the time).", ""]
    replace_section(out / "render-benchmark.md", SECTION, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
