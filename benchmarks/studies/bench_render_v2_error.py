"""Error of the ``default`` render profile on scene generator 2 (lfmbench-v2) scenes against a high-spp reference
(issue 23): writes the section "Scene generator 2 (issue 23)" of docs/benchmarks/render.md.

For each case (seed, time of day, generator 2's weather, or ``v1`` for the generator-1 scene of that seed and time of
day, measured the same way for comparison; default: a day, a dry night and a wet night of generator 2) frame 0 is
rendered at 640x360 with the ``default`` profile's options (render_tools/configs/render_profiles.yaml, every other
field at its :class:`render_tools.render.RenderOptions` default, seed 11) and as a reference with spp
:data:`REF_SPP`, light_spp :data:`REF_LIGHT_SPP`, the same K, every reflection traced in all K bins
(``reflection_bins=None``, ``reflection_min_lux=0``, ``reflection_block_px=1``: no approximation of the wet road),
whose static groups are rendered again on their own at spp :data:`REF_STATIC_SPP` (none of it denoised:
``static_denoise="off"``). Generator-2 cases are also rendered with ``static_denoise="off"`` (the traced estimate,
what the denoiser is measured against).
In a wet scene the default options are also rendered with the reflections traced per pixel and with exact
reflections, so that the error of the approximations (``reflection_block_px``; ``reflection_bins``,
``reflection_min_lux``) is seen apart from the Monte Carlo noise.

Errors, on luminance Y as :mod:`bench_render` computes them (the same functions):

- LED bins: relative RMSE over the LED pixels of every flickering light's bins, pooled (a pixel of a light's own
  screen box, :func:`lamp_boxes`, whose reference bin-mean exceeds 5 % of the box's maximum), the reference cut to
  the default's crop. Until 2026-11-28 the rule ran over the whole crop: its pad ring and a wet road's reflection
  counted as LED pixels where their light exceeded 5 % of the crop maximum, which around an unlit or back-facing
  lamp (a crop maximum of stray light alone) is most of the crop; the tables written before may include them;
- short-window composite (static groups + every flickering light at its nominal level): relative RMSE over the
  reference's light mask (LED px), the all-pixel relMSE^0.5 and the median per-pixel relative error; the long
  window's median too (``reflection_bins`` 1 holds one noise draw over all bins, which the long window sums);
- wet scenes: the median relative error of the short composite over the *reflection pixels*: where the reference's
  flickering layers outside the lamps' own boxes bring more than 5 % of the pixel's luminance.

The reference has its own noise (its static frames spp 256 against 1: the traced static part's measured error is
sqrt(1 + 1/256) = 1.002 times the true one; its light crops spp 4 in the pad rings and reflections, light_spp 256
in the lamps); the errors are upper bounds. References are kept in ``--cache`` (a
folder of pickles) so that a re-run only renders what changed.

``--led`` writes the section "LED dot faces (issue 23)" instead: the error of the LED bins alone (the flickering
groups rendered on their own, so the references can afford light_spp :data:`LED_REF_LIGHT_SPP`) for the ways of
rendering generator 2's sub-pixel LED dots, against the dots themselves and against their filled cells
(:attr:`render_tools.render.RenderOptions.dots_lod_px`), with the CPU seconds of the lamp crops. Each truth is the
mean of two references of different seeds, and the error is corrected for their noise: with ``a``, ``b`` the two
references, ``m`` their mean and ``t`` the setting, E|t - m|^2 = bias^2 + var(t) + var(a) / 2 and
E|a - b|^2 = 2 var(a), so (|t - m|^2 - |a - b|^2 / 4) / |m|^2 estimates the squared relative error against the
expectation (pooled over the LED pixels of every light's bins, as above). The section also holds a model of the
third way the issue named (2-D stratified pixel positions in lamp tiles): the covered share of a pixel by a dot
pattern estimated with random, today's per-dimension (Latin hypercube) and 2-D jittered positions (numpy, no
rendering; :func:`stratification_model`).

Generator-2 cases are also rendered with ``--static-spp`` (default 2): the ``default`` profile with more
samples in the static full frames (light_spp unchanged, denoised), what more samples would buy against the
all-pixel median (the table's CPU column against the v1 scene of that seed and time of day).

``--pixel-samples`` writes the section "Pixel samples (issue 23)": the LED bins as ``--led`` (its filled-cells
references, shared through ``--cache``) with the pixel samples placed by per-dimension strata or by Sobol' points
(``RenderOptions.pixel_samples``) and more lamp samples for the lights drawn as filled cells
(``filled_spp_factor``), per light kind, with a numpy model of moving edges (:func:`edge_model`).

``--pad-samples`` writes the section "Pad ring samples (issue 23)": the flickering groups alone with a lamp's
``pad_px`` ring traced at ``light_spp`` (``RenderOptions.pad_samples`` "light") and at ``spp`` ("spp", scene
version 2's default), against two references of different seeds (light_spp :data:`PAD_REF_LIGHT_SPP`, the ring
at light_spp): the LED bins as above and the whole crops (every pixel of every light's bins, the ring included),
both corrected for the references' noise, with the ring's share of the crops' light and the lamp crops' CPU.

The error targets on every time of day and weather, against references that draw the LED dots as they are:
:mod:`bench_render_v2_targets` (issue 40; it uses this module's helpers).

Usage: ``python benchmarks/studies/bench_render_v2_error.py [--cases 202:day:dry 101:night:dry 101:night:wet]
[--cache DIR] [--quick] [--led | --pixel-samples | --pad-samples] [--static-spp 2]``.
"""
from __future__ import annotations

import argparse
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH
from _timing import replace_section  # noqa: E402
from bench_render import V2_SECTION as SECTION  # noqa: E402
from bench_render import led_sel, lum, median_rel_error, rel_mse_pixels, rel_rmse  # noqa: E402

from lfmbench.fileio import atomic_write_bytes, load_yaml  # noqa: E402

#: Default cases: seed, time of day, generator 2's weather or v1 (the scenes of docs/benchmarks/render-scale.md).
CASES = ("202:day:v1", "202:day:dry", "101:night:v1", "101:night:dry", "101:night:wet")
#: Reference sample counts (per band pass): full frames, lamp crops.
REF_SPP, REF_LIGHT_SPP = 4, 256
#: spp of the reference's static full frames (the static groups rendered on their own, not denoised): at spp 64 a
#: wet night's road still sparkled (its median per-pixel error against spp 256: 6.8 %), and so did the measured
#: error of a denoised frame (11.9 % against it, 9.4 % against spp 256); spp 4 (before) left up to half of the
#: measured error of the traced frames (the fit of 2026-11-26).
REF_STATIC_SPP = 256
#: Share of a pixel's reference luminance above which the flickering layers' light outside the lamps' own boxes
#: makes it a reflection pixel.
REFLECTION_SHARE = 0.05
SIZE = (640, 360)
#: The LED-pixel rule as each section this script writes states it.
LED_PX_RULE = ("LED pixels: a light's pixels inside its own screen box (no pad ring, no reflection) whose reference "
               "bin-mean exceeds 5 % of the box's maximum (since 2026-11-28; tables written before took them over "
               "the whole crop, and may include light around unlit or back-facing lamps).")
#: ``--led``: cases, reference light_spp and seeds, and the section written.
LED_CASES = ("202:day:dry", "101:night:dry")
LED_REF_LIGHT_SPP, LED_REF_SEEDS = 1024, (1001, 1002)
LED_SECTION = "## LED dot faces (issue 23)"
#: ``--led`` settings: name, light_spp, dots_lod_px, lamp_pass_spp.
LED_SETTINGS = (("dots (before)", 32, 0.0, "uniform"), ("dots, light_spp x4", 128, 0.0, "uniform"),
                ("dots, passes by spectrum", 32, 0.0, "spectrum"), ("filled cells", 32, 1.0, "uniform"),
                ("filled cells, passes by spectrum (default)", 32, 1.0, "spectrum"))


def _v2_scene(case: str) -> dict:
    """The generator-2 scene of a case ``seed:time of day:weather``."""
    from render_tools import scene  # noqa: PLC0415

    seed, tod, weather = case.split(":")
    return scene.generate_scene(int(seed), tod, scene_id=f"{tod}_{seed}_{weather}", generator=2,
                                overrides={"weather": {"conditions": [weather]}})


def rules_version() -> int:
    """The render rules a cached frame was made with: ``lfmbench-v2``'s protocol version (it changes whenever a
    render rule changes a generator-2 scene's radiance, render_tools/configs/protocols/lfmbench-v2.yaml)."""
    from render_tools.protocol import load_protocol  # noqa: PLC0415

    return int(load_protocol("lfmbench-v2").version)


def frame_path(cache: Path, tag: str) -> Path:
    """The cached frame ``tag`` of today's render rules: ``cache``/``tag``_p<:func:`rules_version`>.pkl."""
    return cache / f"{tag}_p{rules_version()}.pkl"


def _frame(sc, opts, cache: Path | None, tag: str):
    """Frame 0 of ``sc`` rendered with ``opts`` (from ``cache``/``tag``_p<version>.pkl when there: the file name
    carries :func:`rules_version`, so a frame of older rules is never scored beside newer ones); returns (frame,
    CPU s)."""
    import resource  # noqa: PLC0415

    from render_tools import render  # noqa: PLC0415

    f = frame_path(cache, tag) if cache is not None else None
    if f is not None and f.exists():
        with open(f, "rb") as fh:
            return pickle.load(fh)
    ru = lambda: (lambda r: r.ru_utime + r.ru_stime)(resource.getrusage(resource.RUSAGE_SELF))  # noqa: E731
    c = ru()
    out = (next(render.render_frames(sc, opts)), ru() - c)
    if f is not None:
        atomic_write_bytes(f, pickle.dumps(out))
    return out


def lamp_boxes(sc, opts) -> dict:
    """{light id: (y0, x0, y1, x1)} px: each light's own screen box over frame 0's capture window (its face as it
    moves, no pad ring, no reflection: :meth:`render_tools.render.SceneGeometry.light_bbox`); lights off screen
    are left out."""
    from render_tools import render  # noqa: PLC0415

    tm = render.frame_timing(sc, opts, 0)
    geo = render.SceneGeometry(sc, opts)
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    boxes = {lt["id"]: geo.light_bbox(lt, t_obj, *tm["window"], moving=True, reflection=False)
             for lt in sc["lights"]}
    return {k: tuple(int(v) for v in b) for k, b in boxes.items() if b is not None}


def in_box(shape, origin, box) -> np.ndarray:
    """(h, w) bool: the pixels of a crop of ``shape`` (h, w) at frame pixel ``origin`` (y0, x0) that lie inside
    ``box`` (y0, x0, y1, x1 px, frame coordinates)."""
    out = np.zeros(shape, bool)
    y0, x0, y1, x1 = (int(v) for v in box)
    out[max(y0 - origin[0], 0):max(y1 - origin[0], 0), max(x0 - origin[1], 0):max(x1 - origin[1], 0)] = True
    return out


def bins_error_cut(frame: dict, ref: dict, boxes: dict) -> float:
    """Relative RMSE of luminance over the LED pixels of every light's bins, pooled; the reference's crop (which may
    hold a reflection the frame left out) is cut to the frame's crop. Same K in both. LED pixels: inside the light's
    own box ``boxes[id]`` (:func:`lamp_boxes`), the reference's bin-mean over 5 % of its maximum there
    (bench_render.led_sel); a light without a box adds nothing."""
    num = den = 0.0
    for g, items in frame["lights"].items():
        refs = {lid: (bb, b) for lid, bb, b in ref["lights"][g]}
        for lid, (y0, x0, y1, x1), b in items:
            if lid not in boxes:
                continue
            (ry0, rx0, _, _), rb = refs[lid]
            rb = rb[:, :, y0 - ry0:y1 - ry0, x0 - rx0:x1 - rx0]
            sel = led_sel(np.where(in_box(rb.shape[2:], (y0, x0), boxes[lid]), rb, 0.0))
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
    out = {"led_bins": bins_error_cut(frame, ref, lamp_boxes(sc, opts))}
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
    ap.add_argument("--led", action="store_true", help="the section \"LED dot faces\" (lamp crops alone)")
    ap.add_argument("--pixel-samples", action="store_true",
                    help="the section \"Pixel samples\": strata against Sobol' points, more samples for filled cells "
                         f"(cases default {' '.join(PXS_CASES)})")
    ap.add_argument("--pad-samples", action="store_true",
                    help="the section \"Pad ring samples\": a lamp's pad ring at light_spp against spp (cases default "
                         f"{' '.join(PAD_CASES)})")
    ap.add_argument("--static-spp", nargs="*", type=int, default=[2],
                    help="also render generator-2 cases with these spp (the static full frames; light_spp as the "
                         "default) to see what the all-pixel median would cost")
    a = ap.parse_args()
    cache = Path(a.cache) if a.cache else None
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    if a.led:
        return led_main(cache, Path(a.out), a.quick)
    if a.pixel_samples:
        cases = a.cases if a.cases != list(CASES) else list(PXS_CASES)
        return pixel_samples_main(cases, cache, Path(a.out), a.quick)
    if a.pad_samples:
        cases = a.cases if a.cases != list(CASES) else list(PAD_CASES)
        return pad_samples_main(cases, cache, Path(a.out), a.quick)
    prof = load_yaml(ROOT / "render_tools" / "configs" / "render_profiles.yaml")["default"]
    W, H = (160, 90) if a.quick else SIZE
    ref_spp, ref_light_spp, ref_static_spp = (2, 32, 8) if a.quick else (REF_SPP, REF_LIGHT_SPP, REF_STATIC_SPP)
    base = dict(width=W, height=H, frames=1, seed=11, bins=prof["bins"])
    default = render.RenderOptions(**{**base, "spp": prof["spp"], "light_spp": prof["light_spp"]})
    exact = {"reflection_bins": None, "reflection_min_lux": 0.0, "reflection_block_px": 1}
    exact_default = render.RenderOptions(**{**base, "spp": prof["spp"], "light_spp": prof["light_spp"], **exact})
    blocks1 = render.RenderOptions(**{**base, "spp": prof["spp"], "light_spp": prof["light_spp"],
                                      "reflection_block_px": 1})
    not_denoised = render.RenderOptions(**{**base, "spp": prof["spp"], "light_spp": prof["light_spp"],
                                           "static_denoise": "off"})
    refo = render.RenderOptions(**{**base, "spp": ref_spp, "light_spp": ref_light_spp, "seed": 999, **exact,
                                   "static_denoise": "off"})
    rows = []
    load0 = os.getloadavg()[0]
    for c in a.cases:
        seed, tod, weather = c.split(":")
        kw = {} if weather == "v1" else {"generator": 2, "overrides": {"weather": {"conditions": [weather]}}}
        sc = scene.generate_scene(int(seed), tod, scene_id=f"{tod}_{seed}_{weather}", **kw)
        t = time.perf_counter()
        ref, ref_cpu = _frame(sc, refo, cache, f"ref_{c.replace(':', '_')}")
        static = [g for g, i in render.scene_groups(sc).items() if not i["flicker"]]
        ref_static, cpu_s = _frame(sc, render.RenderOptions(**{**base, "spp": ref_static_spp, "seed": 998,
                                                                "light_spp": ref_light_spp, "groups": static,
                                                                "static_denoise": "off"}),
                                   cache, f"refstatic_{c.replace(':', '_')}")
        ref = {**ref, "static": ref_static["static"]}
        ref_cpu += cpu_s
        print(c, "reference", f"{time.perf_counter() - t:.0f} s", flush=True)
        wet = render.SceneGeometry(sc, default).wet is not None
        tm = render.frame_timing(sc, refo, 0)
        ref_short = preview_short(sc, ref, refo, tm)
        refl_px = reflection_pixels(sc, ref, refo, ref_short) if wet else None
        settings = [("default", default)] + ([("default, not denoised", not_denoised)] if weather != "v1" else []) + \
            ([("default, reflections per pixel", blocks1),
                                              ("default, exact reflections", exact_default)] if wet else []) + \
            [(f"default, spp {n}", render.RenderOptions(**{**base, "spp": n, "light_spp": prof["light_spp"]}))
             for n in (a.static_spp if weather != "v1" else ())]
        for name, opts in settings:
            tag = {"default": "default", "default, exact reflections": "default_exact",
                   "default, reflections per pixel": "default_blocks1",
                   "default, not denoised": "default_noden"}.get(
                name, name.replace(", ", "_").replace(" ", ""))
            fr, cpu = _frame(sc, opts, cache, f"{tag}_{c.replace(':', '_')}")
            r = {"case": c, "setting": name, "cpu_s": cpu, "ref_cpu_s": ref_cpu, **evaluate(sc, fr, ref, opts,
                                                                                              refl_px)}
            rows.append(r)
            print(r, flush=True)
    load1 = os.getloadavg()[0]
    write_section(rows, Path(a.out), load0, load1, (W, H), (ref_spp, ref_light_spp, ref_static_spp))


def preview_short(sc, frame, opts, tm) -> np.ndarray:
    from render_tools import preview  # noqa: PLC0415

    return preview.compose_window(frame, tm, "short", (len(opts.bands_nm), opts.height, opts.width))


def write_section(rows: list, out: Path, load0: float, load1: float, size=SIZE,
                  ref=(REF_SPP, REF_LIGHT_SPP, REF_STATIC_SPP)) -> None:
    def f(r, k):
        return f"{r[k]:.3f}" if k in r else "-"

    lines = [SECTION, "",
             f"Generated by `benchmarks/studies/bench_render_v2_error.py` (1-minute load average {load0:.1f} at the start, "
             f"{load1:.1f} at the end; CPU seconds of the frame in the process, user + system): frame 0 of scene "
             f"generator 2 scenes at {size[0]}x{size[1]} with the `default` profile (spp 1, light_spp 32, K 8, "
             "reflection_bins 1, reflection_min_lux 2e-3, reflection_block_px 2, dots_lod_px 1, filled_spp_factor "
             "2, pixel samples from Sobol' points on generator 2, per-dimension strata on generator 1), and in wet "
             "scenes the same with the reflections traced per pixel (reflection_block_px 1) and with exact "
             "reflections (also reflection_bins = K, reflection_min_lux 0), against a reference of spp "
             f"{ref[0]}, light_spp {ref[1]}, K 8 with exact reflections whose static groups are rendered on their own "
             f"at spp {ref[2]} (light_spp {ref[1]} in their lamps' boxes), none of it denoised (errors are upper "
             "bounds: the reference's own noise is in them). Scene version 2 frames have their static full frames "
             "denoised (`static_denoise` auto, docs/guide/rendering.md); `default, not denoised`: `static_denoise` off, "
             "the traced estimate. Both draw LED dot faces whose pitch projects under 1 px as filled cells "
             "(`dots_lod_px`; the error this leaves out, the dots' moire, is in \"LED dot faces\" below). "
             "`default, spp N`: the same with spp N in the static full frames (`--static-spp`), denoised. "
             "Targets (issue 23): LED pixels <= 2 % relative RMSE, all-pixel "
             "median <= 10 %. Reflection px: where the reference's flickering layers outside the lamps' own boxes "
             f"bring more than {REFLECTION_SHARE:.0%} of the pixel's luminance. " + LED_PX_RULE, "",
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
    lines += ["", "Run again with `python benchmarks/studies/bench_render_v2_error.py --cache /tmp/v2err` (references "
              "are the bulk of the time).", ""]
    replace_section(out / "benchmarks" / "render.md", SECTION, lines)
    print("\n".join(lines))


def _led_canvas(items: dict, lid: int, box) -> np.ndarray:
    """(K, h, w) luminance of light ``lid``'s bins (``items``: id -> (bbox, (K, C, h, w))) on the crop ``box``
    (zeros where the light's own crop does not reach)."""
    y0, x0, y1, x1 = box
    bb, b = items[lid]
    out = np.zeros((b.shape[0], y1 - y0, x1 - x0))
    out[:, bb[0] - y0:bb[2] - y0, bb[1] - x0:bb[3] - x0] = lum(b)
    return out


def _light_canvases(frame: dict, ref_a: dict, ref_b: dict, own: dict):
    """Per light of the references with an own box ``own[id]`` (:func:`lamp_boxes`): (id, t, a, b, m, sel): the
    (K, h, w) luminance of ``frame``, the two references and their mean on the union of the light's three crops (a
    filled face's crop may be a pixel larger; zeros where a crop does not reach), and its LED pixels (h, w): inside
    its own box, the mean's bin-mean over 5 % of its maximum there (bench_render.led_sel's rule)."""
    T, A, B = ({lid: (bb, b) for items in f["lights"].values() for lid, bb, b in items} for f in (frame, ref_a, ref_b))
    for lid in A:
        if lid not in own or lid not in B:
            continue
        boxes = [X[lid][0] for X in (T, A, B) if lid in X]
        box = (min(b[0] for b in boxes), min(b[1] for b in boxes), max(b[2] for b in boxes), max(b[3] for b in boxes))
        a, b = _led_canvas(A, lid, box), _led_canvas(B, lid, box)
        t = _led_canvas(T, lid, box) if lid in T else np.zeros_like(a)
        m = 0.5 * (a + b)
        e = np.where(in_box(m.shape[1:], box[:2], own[lid]), m.mean(0), 0.0)
        yield lid, t, a, b, m, (e > 0.05 * e.max() if e.max() > 0 else np.zeros(e.shape, bool))


def led_error(frame: dict, ref_a: dict, ref_b: dict, sc: dict, own: dict) -> dict:
    """Relative RMSE of the LED bins of ``frame`` against the mean of two references of different seeds,
    corrected for the references' noise (module docstring), pooled over every light (``all``) and per light kind:
    {kind: (error, share of the squared error)}. Each light's crops are compared on the union of its three
    crops (a filled face's crop may be a pixel larger), over its LED pixels inside its own box ``own[id]``
    (:func:`lamp_boxes`; :func:`_light_canvases`)."""
    acc: dict = {}
    for lid, t, a, b, m, sel in _light_canvases(frame, ref_a, ref_b, own):
        num, noise, den = (float(np.sum(x[:, sel] ** 2)) for x in (t - m, 0.5 * (a - b), m))
        for k in ("all", sc["lights"][lid]["kind"]):
            acc[k] = acc.get(k, np.zeros(3)) + (num, noise, den)
    tot = acc["all"][0] - acc["all"][1] if acc else 0.0
    return {k: (float(np.sqrt(max(n - z, 0.0) / d)), float((n - z) / tot) if tot > 0 else float("nan"))
            for k, (n, z, d) in acc.items()}


def stratification_model(seed: int = 1, trials: int = 400, grid: int = 400) -> list[tuple]:
    """The covered share of a pixel by LED dots estimated from n uniform positions (random), from today's
    per-dimension stratification (x and y each over n strata, paired at random: :meth:`render_tools.tracer.
    Tracer._pixel`) and from 2-D jittered strata (a 2^a x 2^b grid): the RMS error of each over random dot offsets
    relative to that of random positions at n = 32. Patterns (pitch px, dot share, rows lit): a signal's LED array
    at 0.31 px (dot 0.7), a sign's scan line at 0.56 px (every 8th row), an LED strip at 0.26 px (dot 0.6).
    Returns rows (pattern, method, n, relative error)."""
    rng = np.random.default_rng(seed)

    def lit(x, y, p, d, ox, oy, every):
        cx, cy = np.mod(x - ox, p) / p, np.mod(y - oy, p) / p
        a = (1 - d) / 2
        on = (cx >= a) & (cx < a + d) & (cy >= a) & (cy < a + d)
        return on & (np.floor((y - oy) / p) % every == 0)

    def positions(method, n):
        if method == "random":
            return rng.random(n), rng.random(n)
        if method == "per-dimension strata (today)":
            return (rng.permutation(n) + rng.random(n)) / n, (rng.permutation(n) + rng.random(n)) / n
        a = 2 ** int(np.log2(n) // 2)
        i = np.arange(n)
        return (i % a + rng.random(n)) / a, (i // a + rng.random(n)) / (n // a)

    g = (np.arange(grid) + 0.5) / grid
    X, Y = np.meshgrid(g, g)
    rows = []
    for name, p, d, every in (("signal LED array, 0.31 px", 0.31, 0.7, 1), ("sign scan line, 0.56 px", 0.56, 0.7, 8),
                              ("LED strip, 0.26 px", 0.26, 0.6, 1)):
        res = {}
        for method in ("random", "per-dimension strata (today)", "2-D jittered strata"):
            for n in (32, 128):
                err = []
                for _ in range(trials):
                    ox, oy = rng.random() * p, rng.random() * p * every
                    true = lit(X, Y, p, d, ox, oy, every).mean()
                    if true > 0:
                        err.append((lit(*positions(method, n), p, d, ox, oy, every).mean() - true) ** 2)
                res[(method, n)] = float(np.sqrt(np.mean(err)))
        rows += [(name, m, n, v / res[("random", 32)]) for (m, n), v in res.items()]
    return rows


def _lamp_study(quick: bool, ref_light_spp: int):
    """Frame size (W, H), reference light_spp and a RenderOptions maker of the lamp-crop studies (``--led``,
    ``--pixel-samples``, ``--pad-samples``): frame 0, the flickering groups alone (otherlights, signals), spp 1, K 8,
    no AOVs; ``--quick``: 160x90 and references of light_spp 64."""
    from render_tools import render  # noqa: PLC0415

    W, H = (160, 90) if quick else SIZE

    def opts(light_spp: int, seed: int, **kw):
        return render.RenderOptions(width=W, height=H, spp=1, light_spp=light_spp, bins=8, frames=1, seed=seed,
                                    groups=("otherlights", "signals"), aux=False, **kw)

    return (W, H), 64 if quick else ref_light_spp, opts


def led_main(cache: Path | None, out: Path, quick: bool) -> None:
    """``--led``: render, measure and write the section "LED dot faces (issue 23)"."""
    from render_tools import render  # noqa: PLC0415

    (W, H), ref_spp, study = _lamp_study(quick, LED_REF_LIGHT_SPP)
    load0 = os.getloadavg()[0]
    rows = []
    for c in LED_CASES:
        sc = _v2_scene(c)

        def opts(light_spp, lod, s, passes="auto"):  # the samples as when this section was made (strata, x1, ring)
            return study(light_spp, s, dots_lod_px=lod, lamp_pass_spp=passes, pixel_samples="strata",
                         filled_spp_factor=1, pad_samples="light")

        tag = c.replace(":", "_")
        refs = {lod: [_frame(sc, opts(ref_spp, lod, s), cache, f"led_ref{lod:g}_{ref_spp}_{s}_{W}_{tag}")[0]
                      for s in LED_REF_SEEDS] for lod in (0.0, 1.0)}
        n_lod = len(render.dots_lod(sc, opts(32, 1.0, 0))[1])
        own = lamp_boxes(sc, opts(32, 1.0, 0))
        next(render.render_frames(sc, opts(1, 1.0, 0)))  # warm-up: the timed settings find their kernels compiled
        settings = [(n, o, lod, ps, 11) for n, o, lod, ps in LED_SETTINGS] + \
            [("filled cells, reference", ref_spp, 1.0, "auto", 0)]
        for name, light_spp, lod, passes, s in settings:
            if s == 0:  # the filled-cells reference itself against the dots: the moire alone
                fr, cpu = refs[1.0][0], float("nan")
            else:
                fr, cpu = _frame(sc, opts(light_spp, lod, s, passes), cache,
                                 f"led_{lod:g}_{light_spp}_{passes}_{W}_{tag}")
            r = {"case": c, "setting": name, "light_spp": light_spp, "cpu_s": cpu, "n_lod": n_lod,
                 "vs_dots": led_error(fr, *refs[0.0], sc, own),
                 "vs_fill": led_error(fr, *refs[1.0], sc, own) if lod and s else None}
            rows.append(r)
            print(c, name, {k: v for k, v in r.items() if k in ("cpu_s",)}, r["vs_dots"]["all"],
                  r["vs_fill"]["all"] if r["vs_fill"] else "", flush=True)
    model = stratification_model()
    write_led_section(rows, model, out, load0, os.getloadavg()[0], (W, H), ref_spp)


#: ``--pixel-samples``: cases, the section written, and the settings (name, pixel_samples, filled_spp_factor).
PXS_CASES = ("101:night:dry", "202:day:dry", "101:night:wet")
PXS_SECTION = "## Pixel samples (issue 23)"
PXS_SETTINGS = (("strata, x1 (before)", "strata", 1), ("strata, filled x4", "strata", 4),
                ("strata, filled x8", "strata", 8), ("Sobol', x1", "sobol", 1),
                ("Sobol', filled x2 (default)", "sobol", 2))


def pixel_samples_main(cases, cache: Path | None, out: Path, quick: bool) -> None:
    """``--pixel-samples``: the LED bins of the flickering groups alone (as ``--led``) with the pixel samples
    placed by per-dimension strata or by Sobol' points (``RenderOptions.pixel_samples``) and more samples for the
    lights drawn as filled cells (``filled_spp_factor``), against the two light_spp-1024 filled-cells references
    of ``--led`` (shared through ``--cache``); error per light kind and its share of the squared error; CPU of the
    lamp crops. Writes the section "Pixel samples (issue 23)" with the numpy model of :func:`edge_model`."""
    from render_tools import render  # noqa: PLC0415

    (W, H), ref_spp, study = _lamp_study(quick, LED_REF_LIGHT_SPP)
    load0 = os.getloadavg()[0]
    rows = []
    for c in cases:
        sc = _v2_scene(c)

        def opts(light_spp, s, mode="strata", factor=1):  # the lamps' pad rings as when this section was made
            return study(light_spp, s, dots_lod_px=1.0, pixel_samples=mode, filled_spp_factor=factor,
                         pad_samples="light")

        tag = c.replace(":", "_")
        refs = [_frame(sc, opts(ref_spp, s), cache, f"led_ref1_{ref_spp}_{s}_{W}_{tag}")[0] for s in LED_REF_SEEDS]
        next(render.render_frames(sc, opts(1, 0, "sobol")))  # warm-up: both placements' kernel compiled
        own = lamp_boxes(sc, opts(32, 11))
        for name, mode, factor in PXS_SETTINGS:
            fr, cpu = _frame(sc, opts(32, 11, mode, factor), cache, f"pxs_{mode}_{factor}_{W}_{tag}")
            rows.append({"case": c, "setting": name, "cpu_s": cpu, "err": led_error(fr, *refs, sc, own)})
            print(c, name, f"{cpu:.1f} s", rows[-1]["err"]["all"], flush=True)
    write_pxs_section(rows, edge_model(), out, load0, os.getloadavg()[0], (W, H), ref_spp)


PAD_CASES = ("101:night:dry", "101:night:wet")
PAD_SECTION = "## Pad ring samples (issue 23)"
PAD_REF_LIGHT_SPP, PAD_REF_SEEDS = 256, (2001, 2002)


def crop_error(frame: dict, ref_a: dict, ref_b: dict, own: dict) -> tuple[float, float]:
    """Relative RMSE of every pixel of every light's bins (the whole crops, pooled; lights with an own box
    ``own[id]``) against the mean of two references, corrected for their noise as :func:`led_error`; and the share
    of the references' crop light (luminance summed over bins and pixels) outside the LED pixels (:func:`led_error`'s
    selection)."""
    num = noise = den = led_light = light = 0.0
    for _, t, a, b, m, sel in _light_canvases(frame, ref_a, ref_b, own):
        num += float(np.sum((t - m) ** 2))
        noise += float(np.sum((0.5 * (a - b)) ** 2))
        den += float(np.sum(m ** 2))
        light += float(m.sum())
        led_light += float(m[:, sel].sum())
    return float(np.sqrt(max(num - noise, 0.0) / den)), 1.0 - led_light / light


def pad_samples_main(cases, cache: Path | None, out: Path, quick: bool) -> None:
    """``--pad-samples``: the flickering groups alone with the pad ring at light_spp and at spp, against two
    references; writes the section "Pad ring samples (issue 23)" of docs/benchmarks/render.md."""
    from render_tools import render  # noqa: PLC0415

    (W, H), ref_spp, study = _lamp_study(quick, PAD_REF_LIGHT_SPP)
    load0 = os.getloadavg()[0]
    rows = []
    for c in cases:
        sc = _v2_scene(c)

        def opts(light_spp, s, pad="spp"):
            return study(light_spp, s, pad_samples=pad)

        tag = c.replace(":", "_")
        refs = [_frame(sc, opts(ref_spp, s, "light"), cache, f"pad_ref_{ref_spp}_{s}_{W}_{tag}")[0]
                for s in PAD_REF_SEEDS]
        next(render.render_frames(sc, opts(1, 0)))  # warm-up: the timed settings find their kernels compiled
        own = lamp_boxes(sc, opts(32, 11))
        for name, pad in (("ring at light_spp (before)", "light"), ("ring at spp (default)", "spp")):
            fr, cpu = _frame(sc, opts(32, 11, pad), cache, f"pad_{pad}_{W}_{tag}")
            crop, ring_share = crop_error(fr, *refs, own)
            rows.append({"case": c, "setting": name, "cpu_s": cpu, "led": led_error(fr, *refs, sc, own)["all"][0],
                         "crop": crop, "ring_share": ring_share})
            print(rows[-1], flush=True)
    lines = [PAD_SECTION, "",
             f"Generated by `benchmarks/studies/bench_render_v2_error.py --pad-samples` (1-minute load average {load0:.1f} at "
             f"the start, {os.getloadavg()[0]:.1f} at the end): frame 0 at {W}x{H}, the flickering groups alone "
             "(otherlights, signals; K 8, light_spp 32, the `default` profile's other options), a lamp's `pad_px` "
             "ring traced at light_spp (`pad_samples` \"light\", scene version 1's way and version 2's before) or at "
             "spp 1 (\"spp\", version 2's default), against two references of other seeds (light_spp "
             f"{ref_spp}, ring at light_spp). LED bins: relative RMSE of the LED pixels' bins, pooled; whole crops: "
             "the same over every pixel of the crops (the ring included); both corrected for the references' noise "
             "(module docstring). Light outside the LED pixels: its share of the crops' light in the references. "
             "CPU: the lamp crops of the frame, user + system s, one process after a warm-up render. " + LED_PX_RULE,
             "", "| scene | setting | CPU s (lamp crops) | LED bins | whole crops | light outside the LED pixels |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {r['case']} | {r['setting']} | {r['cpu_s']:.1f} | {r['led']:.3f} | {r['crop']:.3f} | "
              f"{r['ring_share']:.3f} |" for r in rows]
    lines += ["", "Run again with `python benchmarks/studies/bench_render_v2_error.py --pad-samples`.", ""]
    replace_section(out / "benchmarks" / "render.md", PAD_SECTION, lines)
    print("\n".join(lines))


def edge_model(seed: int = 0, trials: int = 300, ref_n: int = 1 << 18) -> list[tuple]:
    """Relative RMS error of a pixel's lit share estimated from n samples in (x, y, t) (pixel x, y in [0, 1),
    time in the bin [0, 1)), per-dimension strata paired at random and Sobol' points with a random digital shift
    (:func:`render_tools.tracer.sobol_points`), both divided by random sampling's: a lit row 0.4 px tall at
    rest and moving 0.5 px over the bin (a sign's scan line), a disk of radius 0.8 px moving (a signal's lamp),
    filled cells 0.4 px apart moving 0.3 px. Each trial draws the feature's position and velocity; the truth is
    a 2^18-sample estimate. Returns (n, feature, strata, Sobol')."""
    from render_tools.tracer import sobol_points  # noqa: PLC0415

    rng = np.random.default_rng(seed)

    def strata(n):
        return np.stack([(rng.permutation(n) + rng.random(n)) / n for _ in range(3)])

    feats = {
        "row 0.4 px, at rest": lambda: (lambda P, y0=rng.random(): np.abs(P[1] - y0) < 0.2),
        "row 0.4 px, moving 0.5 px": lambda: (lambda P, y0=rng.random(), v=0.5 * rng.standard_normal():
                                              np.abs(P[1] - v * (P[2] - 0.5) - y0) < 0.2),
        "disk r 0.8 px, moving": lambda: (lambda P, c=rng.random(2) * 2 - 0.5, v=0.5 * rng.standard_normal(2):
                                          (P[0] - v[0] * (P[2] - 0.5) - c[0]) ** 2
                                          + (P[1] - v[1] * (P[2] - 0.5) - c[1]) ** 2 < 0.64),
        "cells 0.4 px, moving": lambda: (lambda P, o=rng.random(2), v=0.3 * rng.standard_normal(2):
                                         (np.mod((P[0] - v[0] * (P[2] - 0.5) - o[0]) / 0.4, 1) < 0.5)
                                         & (np.mod((P[1] - v[1] * (P[2] - 0.5) - o[1]) / 0.4, 1) < 0.5)),
    }
    out = []
    for n in (32, 128):
        for name, mk in feats.items():
            e = {"random": [], "strata": [], "sobol": []}
            for _ in range(trials):
                f = mk()
                truth = f(rng.random((3, ref_n))).mean()
                e["random"].append(f(rng.random((3, n))).mean() - truth)
                e["strata"].append(f(strata(n)).mean() - truth)
                e["sobol"].append(f(sobol_points(np.arange(n), rng.integers(0, 2 ** 32, 3, dtype=np.uint64))).mean()
                                  - truth)
            r = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in e.items()}
            out.append((n, name, r["strata"] / r["random"], r["sobol"] / r["random"]))
    return out


def write_pxs_section(rows, model, out: Path, load0: float, load1: float, size, ref_spp: int) -> None:
    kinds = ("message_sign", "signal", "countdown", "chmsl", "brake", "tail")

    def cell(d, k):
        return f"{d[k][0]:.3f} ({d[k][1]:.2f})" if k in d else "-"

    lines = [PXS_SECTION, "",
             f"Generated by `benchmarks/studies/bench_render_v2_error.py --pixel-samples` (1-minute load average {load0:.1f} "
             f"at the start, {load1:.1f} at the end): frame 0 at {size[0]}x{size[1]}, the flickering groups alone "
             "(otherlights, signals; K 8 bins, light_spp 32, lamp samples by spectrum, sub-pixel dot faces as filled "
             f"cells), against the two light_spp-{ref_spp} filled-cells references of \"LED dot faces\" (error "
             "corrected for their noise, as there). `strata`: each of pixel x, y and time stratified on its own, the "
             "strata paired at random (scene version 1, and version 2 before); `Sobol'`: the first N points of a "
             "Sobol' sequence in (x, y, t) with a random digital shift per pixel (`RenderOptions.pixel_samples`, "
             "`render_tools.tracer.sobol_points`); `filled xF`: light_spp x F for the lights drawn as filled cells "
             "(`filled_spp_factor`). LED bins: relative RMSE over every light's LED pixels and bins, pooled; per "
             "kind: error (share of the squared error). CPU: the lamp crops of the frame, user + system s, one "
             "process after a warm-up render. " + LED_PX_RULE, "",
             "| scene | setting | CPU s (lamp crops) | LED bins | " + " | ".join(kinds) + " |",
             "|---|---|---|---|" + "---|" * len(kinds)]
    for r in rows:
        lines.append(f"| {r['case']} | {r['setting']} | {r['cpu_s']:.1f} | {r['err']['all'][0]:.3f} | "
                     + " | ".join(cell(r["err"], k) for k in kinds) + " |")
    lines += ["", "Model (numpy, no rendering; `edge_model`): relative RMS error of a pixel's lit share from n "
              "samples, against random sampling's.", "",
              "| n | feature | strata | Sobol' |", "|---|---|---|---|"]
    lines += [f"| {n} | {name} | {a:.2f} | {b:.2f} |" for n, name, a, b in model]
    replace_section(out / "benchmarks" / "render.md", PXS_SECTION, lines)
    print("\n".join(lines))


def write_led_section(rows, model, out: Path, load0: float, load1: float, size, ref_spp: int) -> None:
    def err(d, k="all"):
        return f"{d[k][0]:.3f}" if d is not None and k in d else "-"

    lines = [LED_SECTION, "",
             f"Generated by `benchmarks/studies/bench_render_v2_error.py --led` (1-minute load average {load0:.1f} at the "
             f"start, {load1:.1f} at the end): frame 0 at {size[0]}x{size[1]}, the flickering groups alone "
             "(otherlights, signals: every light in its crop, K 8 bins), against two references of light_spp "
             f"{ref_spp} (seeds {LED_REF_SEEDS[0]}, {LED_REF_SEEDS[1]}) with the dots as they are "
             "(`dots_lod_px` 0) and two with sub-pixel dot faces as filled cells (`dots_lod_px` 1), the error "
             "corrected for the references' noise (module docstring). Passes by spectrum: `lamp_pass_spp` "
             "`spectrum` (a lamp box's light_spp x 8 samples shared among the band passes by its spectrum), else "
             "`uniform` (light_spp in each). LED bins: relative RMSE of luminance over "
             "the LED pixels of every light's bins, pooled; per kind: the lights of one kind pooled. CPU: the "
             "lamp crops of the frame (user + system s, in one process after a warm-up render of the scene, so no "
             "kernel compilation is in them). " + LED_PX_RULE, "",
             "| scene | setting | light_spp | CPU s (lamp crops) | LED bins vs the dots | signals | message signs "
             "| LED bins vs the filled cells | signals | message signs |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        cpu = "-" if r["cpu_s"] != r["cpu_s"] else f"{r['cpu_s']:.1f}"
        lines.append(f"| {r['case']} | {r['setting']} | {r['light_spp']} | {cpu} | {err(r['vs_dots'])} | "
                     f"{err(r['vs_dots'], 'signal')} | {err(r['vs_dots'], 'message_sign')} | {err(r['vs_fill'])} | "
                     f"{err(r['vs_fill'], 'signal')} | {err(r['vs_fill'], 'message_sign')} |")
    lines += ["", "Filled cells, reference: the light_spp-" f"{ref_spp} filled-cells render against the dots, the "
              "moire the filled cells leave out (no noise left to speak of).", "",
              "Stratification model (`stratification_model`, numpy): RMS error of a pixel's covered share, "
              "relative to random positions at n = 32.", "",
              "| pattern | positions | n = 32 | n = 128 |", "|---|---|---|---|"]
    for name in dict.fromkeys(m[0] for m in model):
        for meth in dict.fromkeys(m[1] for m in model):
            v = {n: e for p, mm, n, e in model if p == name and mm == meth}
            lines.append(f"| {name} | {meth} | {v[32]:.2f} | {v[128]:.2f} |")
    lines += ["", "Run again with `python benchmarks/studies/bench_render_v2_error.py --led --cache /tmp/v2err` "
              "(the light_spp-1024 references are the bulk of the time).", ""]
    replace_section(out / "benchmarks" / "render.md", LED_SECTION, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
