"""The error targets of scene generator 2 (issue 23: LED pixels <= 2 % relative RMSE, all-pixel median <= 10 %)
on every time of day x weather the generator produces, against references that draw the LED dots as they are
(issue 40): writes the section "Error targets on every time of day and weather (issue 40)" of
docs/benchmarks/render.md. Part of the study :mod:`bench_render_v2_error` (its helpers; one command reruns it).

Cases: ``seed:time of day:weather`` (generator 2's times of day :data:`render_tools.scene.TIMES_OF_DAY` and
weathers :data:`lfmbench.vocabulary.WEATHERS`: day, dusk, night x dry, wet, rain; no fog). Every case is first
rendered with the flickering groups alone (``--lamp-cases``: the LED bins, a tenth of a whole frame's cost), then
the cases of ``--cases`` whole (every measure below). Each case renders frame 0 of the
generator-2 scene at 640x360 with the ``default`` profile (render_tools/configs/render_profiles.yaml; every other
field at its :class:`render_tools.render.RenderOptions` default, seed 11) and two references of other seeds
(:data:`REF_SEEDS`), all groups in one render: spp :data:`REF_SPP` (static full frames, a lamp's pad ring, a wet
road's reflections; spp 1 when the flickering groups are rendered alone, whose lamp boxes alone are measured),
light_spp :data:`REF_LIGHT_SPP` (every lamp's own box, static and flickering), the LED dots as they are
(``dots_lod_px`` 0), nothing denoised, a wet road's reflections traced per pixel (``reflection_block_px`` 1; their
time bins and light-level cut-off as the default: ``reflection_bins`` 1 and ``reflection_min_lux`` 2e-3, whose own
error was measured apart in "Scene generator 2" and "Light left out by the reflection cut-off").

Errors, on luminance Y (:mod:`bench_render`'s functions), with ``a``, ``b`` the references, ``m = (a + b) / 2``,
``t`` the setting:

- LED bins: every flickering light's LED pixels and bins, pooled (:func:`led_error_boxed`: as
  :func:`bench_render_v2_error.led_error`, the LED pixels taken inside the light's own box), corrected for the
  references' noise: (|t - m|^2 - |a - b|^2 / 4) / |m|^2 estimates the squared relative error against the
  expectation (E|t - m|^2 = bias^2 + var t + var a / 2, E|a - b|^2 = 2 var a);
- LED px: the same on the short-window composite (:func:`render_tools.preview.compose_window`: static groups plus
  every flickering light at its nominal level) over the references' light mask (``mask.light`` >= 0 in either);
- all-pixel median: median over pixels of |t - m| / m on the short composite (``raw``: an upper bound, the
  references' noise is in it) and that corrected in quadrature, sqrt(raw^2 - r^2), r = median |a - b| / 2 / m
  (the median error of m itself; exact when every pixel's errors scale alike, an estimate otherwise:
  :func:`median_corrected`); the long window's raw median too; beside it the 46th and 54th percentiles of the raw
  per-pixel error (:func:`rel_error_percentiles`: the raw median stays between them when under 4 % of the pixels
  change) and the median by what a pixel shows (:func:`median_by_region`: road, buildings, trees, sky, lamps ...);
  for a case scored against two, four (and eight, sixteen) references, the median extrapolated to noiseless
  references (:func:`median_extrapolated`, :func:`fit_extrapolated` through every count: three or more points also
  check the model, by the fit's residual).

``--ref4-cases``: cases scored again against four references (:data:`MORE_REF_SEEDS` too), a and b each the mean
of two (:func:`mean_frames`): the references' own median error / sqrt 2, so the raw median is a tighter bound.
``--ref-cases`` with ``--ref-count 2N [2M ...]``: the same against 2N references (:func:`ref_seeds`: 3001 .. 3000 +
2N), a and b each the mean of N (:func:`ref_halves`): the references' own median error / sqrt N; each count scored
in turn (rows ``default, 2N references``). With ``--cached-only`` a count whose references are not all in
``--cache`` is skipped, as a ``--gap`` setting whose frame is not.

Where a target is missed, ``--gap`` settings (:data:`GAP_SETTINGS`: the dots as they are at light_spp 32-128,
filled cells at ``filled_spp_factor`` 8, the sub-pixel dots as they are at ``dots_spp_factor`` 4 or 8, the dot
faces by their exact coverage, ``dots_coverage`` exact; static spp 2) are rendered for the cases given by
``--gap-cases`` (``--gap-settings`` chooses them by name) and scored the same way, with their CPU seconds: error
against run time. ``--section dots`` writes them as :data:`DOTS_SECTION` instead of the targets' section;
``--figure CASE`` draws the message signs of a case close up from the cached frames (docs/img/led-dot-faces.png).

CPU: user + system seconds of the frame in the process (after the references, which compile the kernels; frames
are rendered one at a time). References and frames are kept in ``--cache`` (pickles named with the render rules'
version, :func:`bench_render_v2_error.frame_path`) so a re-run renders only what changed.

Over 500 lines: the study's measures, its run loop, its tables and its figure kept in one rerunnable file.

Usage: ``python benchmarks/studies/bench_render_v2_targets.py [--cases 202:dusk:dry ...] [--gap-cases ...]
[--cache DIR] [--quick]``.
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
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH
from _timing import replace_section  # noqa: E402
from bench_render import lum  # noqa: E402
from bench_render_v2_error import (_frame, _light_canvases, _v2_scene, frame_path, lamp_boxes,  # noqa: E402
                                   rules_version)

from lfmbench.fileio import load_yaml  # noqa: E402

SECTION = "## Error targets on every time of day and weather (issue 40)"
#: The section ``--section dots`` writes instead: the LED dot-face settings (``--gap-settings``) on every case.
DOTS_SECTION = "## LED dot faces against the real dots: the measurements (issue 40)"
#: The command that rewrites :data:`DOTS_SECTION` (frames not in the cache are rendered; the references first).
DOTS_RERUN = ("nice -n 10 python benchmarks/studies/bench_render_v2_targets.py --section dots --warmup --cases "
              "--gap-cases 202:dusk:dry 101:night:dry 202:day:dry 202:dusk:wet 202:dusk:rain 101:night:rain "
              "202:day:wet 202:day:rain 101:night:wet --gap-settings \"dot faces exact\" \"sub-pixel dots as they are "
              "x4\" --cache bench_out/v2tgt")
#: The command that rewrites :data:`SECTION` as published (frames not in the cache are rendered; the references
#: first).
TARGETS_RERUN = ("nice -n 10 python benchmarks/studies/bench_render_v2_targets.py --lamp-cases --ref4-cases "
                 "202:dusk:dry 202:day:wet 202:day:dry 101:night:wet 101:night:rain --ref-count 8 16 --ref-cases "
                 "101:night:wet 101:night:rain --gap-cases 202:dusk:dry "
                 "101:night:wet 101:night:rain --gap-settings \"static spp 2\" --cache bench_out/v2tgt")
#: Cases rendered whole (every measure), in the order rendered: those never measured whole first (dusk wet and rain,
#: day wet and rain, night rain), then day dry, night dry and wet, dusk dry (issue 23's three measured against
#: filled-cell references in "Scene generator 2"; dusk dry whole before protocol version 4).
CASES = ("202:dusk:wet", "202:dusk:rain", "202:day:wet", "202:day:rain", "101:night:rain", "202:day:dry",
         "101:night:dry", "101:night:wet", "202:dusk:dry")
#: Cases rendered first with the flickering groups alone (LED bins only, a tenth of a whole frame's cost): every
#: time of day x weather.
LAMP_CASES = ("202:dusk:dry", "202:dusk:wet", "202:dusk:rain", "101:night:rain", "202:day:wet", "202:day:rain",
              "202:day:dry", "101:night:dry", "101:night:wet")
LAMP_GROUPS = ("otherlights", "signals")
#: Cases that also render :data:`GAP_SETTINGS` (the LED settings with the flickering groups alone, static spp 2
#: whole).
GAP_CASES = ("202:dusk:dry", "101:night:dry")
#: References: spp (static frames, pad rings, reflections), light_spp (lamp boxes), seeds.
REF_SPP, REF_LIGHT_SPP, REF_SEEDS = 8, 128, (3001, 3002)
#: Two more references for ``--ref4-cases``: those cases are also scored against a = mean of :data:`REF_SEEDS`' two,
#: b = mean of these two (each half the noise variance of one reference: the references' own median error / sqrt 2).
MORE_REF_SEEDS = (3003, 3004)


def ref_seeds(count: int) -> tuple:
    """The seeds of ``count`` references (``--ref-count``): 3001 .. 3000 + ``count`` (:data:`REF_SEEDS` and
    :data:`MORE_REF_SEEDS` their first four); ``count`` even and >= 2 (a ``ValueError`` naming ``--ref-count``
    otherwise)."""
    if count < 2 or count % 2:
        raise ValueError(f"--ref-count: {count} references; an even number >= 2 (two halves) is needed")
    return tuple(range(REF_SEEDS[0], REF_SEEDS[0] + count))
#: ``--gap`` settings: name -> RenderOptions fields over the ``default`` profile's.
GAP_SETTINGS = {
    "dots as they are, light_spp 32": {"dots_lod_px": 0.0},
    "dots as they are, light_spp 128": {"dots_lod_px": 0.0, "light_spp": 128},
    "filled cells x8": {"filled_spp_factor": 8},
    "sub-pixel dots as they are x4": {"dots_lod_px": 0.0, "dots_spp_factor": 4},
    "sub-pixel dots as they are x8": {"dots_lod_px": 0.0, "dots_spp_factor": 8},
    "dot faces exact": {"dots_coverage": "exact"},
    "static spp 2": {"spp": 2},
}
TARGET_LED, TARGET_MEDIAN = 0.02, 0.10


def corrected_rel_rmse(t: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Relative RMSE of ``t`` against the expectation of two independent references ``a``, ``b`` (arrays of one
    shape, any unit): sqrt(max(|t - m|^2 - |a - b|^2 / 4, 0) / |m|^2), m = (a + b) / 2 (module docstring)."""
    t, a, b = (np.asarray(x, np.float64) for x in (t, a, b))
    m = 0.5 * (a + b)
    num = float(np.sum((t - m) ** 2)) - float(np.sum((a - b) ** 2)) / 4.0
    den = float(np.sum(m ** 2))
    return float(np.sqrt(max(num, 0.0) / den)) if den > 0 else float("nan")


def median_corrected(t: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[float, float, float]:
    """Median relative error of ``t`` (H, W luminance) against m = (a + b) / 2 over the pixels with m > 0: (raw,
    r, corrected), r = median |a - b| / 2 / m (the median error of m: |a - b| / 2 has m's standard deviation),
    corrected = sqrt(max(raw^2 - r^2, 0)) (errors of ``t`` and m independent, adding in quadrature; exact for
    medians when every pixel's two errors have the same shape and ratio of scales)."""
    m = 0.5 * (np.asarray(a, np.float64) + b)
    ok = m > 0
    raw = float(np.median(np.abs(np.asarray(t, np.float64)[ok] - m[ok]) / m[ok]))
    r = float(np.median(np.abs(np.asarray(a, np.float64)[ok] - b[ok]) / 2.0 / m[ok]))
    return raw, r, float(np.sqrt(max(raw * raw - r * r, 0.0)))


def rel_error_percentiles(t: np.ndarray, a: np.ndarray, b: np.ndarray, qs=(46.0, 54.0)) -> tuple[float, ...]:
    """Percentiles ``qs`` (in %) of the per-pixel relative error |t - m| / m of ``t`` (H, W luminance) against
    m = (a + b) / 2 over the pixels with m > 0, raw (the references' noise in it, as :func:`median_corrected`'s
    raw). When a share f of the pixels changes arbitrarily (a later render of some rows), the new raw median stays
    between the percentiles 50 - 100 f and 50 + 100 f of these errors (its rank among the pixels left as they
    were moves by at most f n): (46, 54) bound it for f <= 4 %. Returns one float per ``qs``."""
    m = 0.5 * (np.asarray(a, np.float64) + b)
    ok = m > 0
    e = np.abs(np.asarray(t, np.float64)[ok] - m[ok]) / m[ok]
    return tuple(float(v) for v in np.percentile(e, qs))


#: What a pixel shows, for :func:`median_by_region`: region -> object kinds of scene generator 2 (``objects[i]
#: ["kind"]`` of the first camera hit, ``mask.instance``); no hit is ``sky``, a light's face (``mask.light``) ``lamps``,
#: a kind not listed ``other``.
REGIONS = {"road": ("road", "marking"), "sidewalk, ground": ("sidewalk", "ground"), "buildings": ("building",),
           "vehicles": ("car", "bus", "truck", "van", "bicycle"), "people": ("pedestrian", "cyclist"),
           "trees": ("tree",), "poles, signs": ("streetlight_pole", "signal_pole", "traffic_sign", "bollard")}


def median_by_region(t: np.ndarray, a: np.ndarray, b: np.ndarray, instance: np.ndarray, light: np.ndarray,
                     kinds: list) -> dict:
    """:func:`median_corrected` per region of the frame (:data:`REGIONS`, ``sky``, ``lamps``, ``other``): ``t``,
    ``a``, ``b`` (H, W) luminance, ``instance`` (H, W) object index of the first hit (-1: none), ``light`` (H, W)
    light id of a lamp face (-1: none), ``kinds`` the objects' kinds. Returns {region: (share of the pixels with
    m > 0, raw, r, corrected)}, regions without such a pixel left out."""
    of_kind = {k: reg for reg, ks in REGIONS.items() for k in ks}
    names = np.array([of_kind.get(k, "other") for k in kinds] + ["sky"], dtype=object)
    inst = np.asarray(instance).astype(np.int64)
    reg = names[np.where(inst < 0, len(kinds), np.minimum(inst, len(kinds)))]
    reg[np.asarray(light) >= 0] = "lamps"
    ok = 0.5 * (np.asarray(a, np.float64) + b) > 0
    out = {}
    for r in [*REGIONS, "sky", "lamps", "other"]:
        sel = (reg == r) & ok
        if sel.any():
            out[r] = (float(sel.sum() / ok.sum()), *median_corrected(t[sel], a[sel], b[sel]))
    return out


def median_extrapolated(raw2: float, r2: float, raw4: float, r4: float) -> float:
    """The raw median a frame would measure against noiseless references, from its raw medians ``raw2``, ``raw4``
    against two reference sets whose means have the median errors ``r2`` > ``r4`` (fractions): the two points fix
    raw^2 = c^2 + k r^2 (issue 23's fit of the median against spp, "Scene generator 2"; k = 1 is
    :func:`median_corrected`'s quadrature, k > 1 when the references' noise weighs more in the median than its own
    median says), and c is returned (nan when r2 <= r4; 0 when c^2 < 0)."""
    if r2 <= r4:
        return float("nan")
    c2 = (raw4 ** 2 * r2 ** 2 - raw2 ** 2 * r4 ** 2) / (r2 ** 2 - r4 ** 2)
    return float(np.sqrt(max(c2, 0.0)))


def led_error_boxed(frame: dict, ref_a: dict, ref_b: dict, kinds: dict, boxes: dict) -> dict:
    """Relative RMSE of the LED bins of ``frame`` against the mean of two references, corrected for their noise
    (:func:`corrected_rel_rmse`'s sums pooled), over each light's LED pixels: the references' mean bin-mean above
    5 % of its maximum *inside the light's own box* ``boxes[id]`` (y0, x0, y1, x1 px; the crop's pad ring and a wet
    road's reflection are not LED pixels: their light, traced at spp, can exceed 5 % of an unlit face's, e.g. a
    billboard seen from behind). ``kinds``: light id -> kind. Returns {"all" or kind: (error, share of the pooled
    squared error)}; lights without a box or a lit pixel add nothing. Crops: ``frame["lights"][group]`` =
    [(id, (y0, x0, y1, x1), (K, C, h, w))]."""
    acc: dict = {}
    for lid, t, a, b, m, sel in _light_canvases(frame, ref_a, ref_b, boxes):
        if not sel.any():  # no lit pixel inside its own box
            continue
        sums = np.array([np.sum((t - m)[:, sel] ** 2), np.sum((a - b)[:, sel] ** 2) / 4.0, np.sum(m[:, sel] ** 2)])
        for k in ("all", kinds[lid]):
            acc[k] = acc.get(k, np.zeros(3)) + sums
    tot = acc["all"][0] - acc["all"][1] if acc else 0.0
    return {k: (float(np.sqrt(max(n - z, 0.0) / d)), float((n - z) / tot) if tot > 0 else float("nan"))
            for k, (n, z, d) in acc.items()}


def verdict(led_bins: float, led_px: float, med: float, med_raw: float) -> str:
    """Whether the targets are met: ``met`` / ``missed`` per target (LED: both LED measures <= 2 %; median: the
    raw median <= 10 %, or ``met (corrected)`` when only the noise-corrected one is)."""
    led = "met" if max(led_bins, led_px) <= TARGET_LED else "missed"
    mm = "met" if med_raw <= TARGET_MEDIAN else ("met (corrected)" if med <= TARGET_MEDIAN else "missed")
    return f"LED {led}, median {mm}"


def mean_frames(frames) -> dict:
    """The mean of frames of one scene and options but other seeds (dicts of
    :func:`render_tools.render.render_frames`, any iterable: one frame held at a time beside float64 sums): every
    static window image (C, H, W) and light crop (K, C, h, w) averaged, ``aux`` and ``frame`` taken from the first.
    The lights' ids and crop boxes must agree (a ``ValueError`` naming the light otherwise)."""
    out, n = None, 0
    for f in frames:
        if out is None:  # float64 sums shaped as the first frame's
            out = {"frame": f["frame"], "aux": f["aux"], "static": {g: {w: np.zeros(np.shape(x)) for w, x in v.items()}
                                                                   for g, v in f["static"].items()},
                   "lights": {g: [(lid, box, np.zeros(np.shape(b))) for lid, box, b in items]
                              for g, items in f["lights"].items()}}
        for g, v in out["static"].items():
            for w in v:
                v[w] += f["static"][g][w]
        for g, items in out["lights"].items():
            if len(f["lights"].get(g, ())) != len(items):
                raise ValueError(f"frames: group {g} has other lights in another frame")
            for (lid, box, acc), o in zip(items, f["lights"][g]):
                if o[0] != lid or tuple(o[1]) != tuple(box):
                    raise ValueError(f"frames: light {lid} of group {g} has other crops in another frame")
                acc += o[2]
        n += 1
    out["static"] = {g: {w: (x / n).astype(np.float32) for w, x in v.items()} for g, v in out["static"].items()}
    out["lights"] = {g: [(lid, box, (acc / n).astype(np.float32)) for lid, box, acc in items]
                     for g, items in out["lights"].items()}
    return out


def run_plan(lamp_cases, cases, ref4_cases, ref_cases, ref_counts) -> list:
    """What a run scores, in order: [(case, groups (None: whole frames), reference seeds)]: the flickering groups
    of ``lamp_cases``, then ``cases``, ``ref4_cases`` against four references and ``ref_cases`` against each count of
    ``ref_counts`` in turn (:func:`ref_seeds`: a ``ValueError`` naming ``--ref-count`` for an odd count or one under
    2; a count given twice is scored once; none when ``ref_cases`` is empty)."""
    more = [ref_seeds(n) for n in dict.fromkeys(ref_counts)] if ref_cases else []
    return ([(c, LAMP_GROUPS, REF_SEEDS) for c in lamp_cases] + [(c, None, REF_SEEDS) for c in cases]
            + [(c, None, REF_SEEDS + MORE_REF_SEEDS) for c in ref4_cases]
            + [(c, None, s) for s in more for c in ref_cases])


def ref_halves(load, seeds) -> list:
    """The two references a case is scored against, from the references of ``seeds`` (2N of them, N >= 1):
    a = the mean of the first N, b = the mean of the last N (:func:`mean_frames`; each has 1/N of one reference's
    noise variance, so the references' own median error falls as 1/sqrt N). ``load(seed)`` returns one reference
    frame; one frame is held at a time beside a half's sums (a whole 640x360 frame of a wet night is ~0.7 GB).
    Returns [a, b]."""
    n = len(seeds) // 2
    if n < 1 or len(seeds) != 2 * n:
        raise ValueError(f"references: {len(seeds)} seeds; an even number >= 2 (two halves) is needed")
    if n == 1:
        return [load(seeds[0]), load(seeds[1])]
    return [mean_frames(load(s) for s in half) for half in (seeds[:n], seeds[n:])]


def fit_extrapolated(raws, rs) -> tuple[float, float, float]:
    """Least-squares fit of raw^2 = c^2 + k r^2 (:func:`median_extrapolated`'s model) through the raw medians
    ``raws`` of one frame against reference sets whose means have the median errors ``rs`` (fractions, >= 2
    points, at least two distinct r). Returns (c, k, residual): c (0 when the fitted c^2 < 0), k, and the largest
    |sqrt(c^2 + k r^2) - raw| over the points (fraction; 0 up to rounding for two points: a check of the model
    needs three)."""
    x, y = np.asarray(rs, np.float64) ** 2, np.asarray(raws, np.float64) ** 2
    if x.size < 2 or np.ptp(x) <= 0:
        return float("nan"), float("nan"), float("nan")
    k, c2 = np.polyfit(x, y, 1)
    fit = np.sqrt(np.maximum(c2 + k * x, 0.0))
    return float(np.sqrt(max(c2, 0.0))), float(k), float(np.max(np.abs(fit - np.sqrt(y))))


def scores(sc, fr: dict, ra: dict, rb: dict, opts) -> dict:
    """The errors of frame ``fr`` against references ``ra``, ``rb`` (module docstring)."""
    from render_tools import preview, render  # noqa: PLC0415

    tm = render.frame_timing(sc, opts, 0)
    shape = (len(opts.bands_nm), opts.height, opts.width)
    le = led_error_boxed(fr, ra, rb, {lt["id"]: lt["kind"] for lt in sc["lights"]}, lamp_boxes(sc, opts))
    out = {"led_bins": le["all"][0], "kinds": {k: v for k, v in le.items() if k != "all"}}
    if not ra["static"]:  # the flickering groups alone: LED bins only
        return out
    for win in ("short", "long"):
        t, a, b = (lum(preview.compose_window(f, tm, win, shape)) for f in (fr, ra, rb))
        raw, r, med = median_corrected(t, a, b)
        out[f"median_{win}"], out[f"median_{win}_raw"], out[f"median_{win}_ref"] = med, raw, r
        out[f"p46_{win}_raw"], out[f"p54_{win}_raw"] = rel_error_percentiles(t, a, b)
        if win == "short":
            mask = (ra["aux"]["mask.light"] >= 0) | (rb["aux"]["mask.light"] >= 0)
            out["regions"] = median_by_region(t, a, b, ra["aux"]["mask.instance"], np.where(mask, 0, -1),
                                              [o["kind"] for o in sc["objects"]])
            out["led_px"] = corrected_rel_rmse(t[mask], a[mask], b[mask])
    return out


def main() -> None:
    from render_tools import render  # noqa: PLC0415

    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", nargs="*", default=list(CASES),
                    help="seed:time of day:weather (generator 2), rendered whole")
    ap.add_argument("--lamp-cases", nargs="*", default=list(LAMP_CASES),
                    help="cases rendered first with the flickering groups alone (LED bins only)")
    ap.add_argument("--ref4-cases", nargs="*", default=[],
                    help="cases (of --cases) also scored against four references (MORE_REF_SEEDS), two per half")
    ap.add_argument("--ref-cases", nargs="*", default=[],
                    help="cases (of --cases) also scored against --ref-count references (ref_seeds), half per side")
    ap.add_argument("--ref-count", type=int, nargs="+", default=[8],
                    help="reference counts of --ref-cases, each scored: 2N (seeds 3001 .. 3000 + 2N), a and b each "
                         "the mean of N")
    ap.add_argument("--gap-cases", nargs="*", default=list(GAP_CASES),
                    help="cases that also render the --gap settings (what closes a missed target)")
    ap.add_argument("--gap-settings", nargs="*", default=list(GAP_SETTINGS),
                    help="names of the --gap settings rendered (GAP_SETTINGS)")
    ap.add_argument("--warmup", action="store_true",
                    help="first render the first case's flickering groups once, uncached and unscored, so that no "
                         "timed frame compiles the kernels (when the references and the default come from --cache)")
    ap.add_argument("--figure", default=None, metavar="CASE",
                    help="only write docs/img/led-dot-faces.png: the message signs of CASE from the frames in --cache")
    ap.add_argument("--section", choices=("targets", "dots"), default="targets",
                    help="the section of docs/benchmarks/render.md written: the error targets, or the LED dot-face "
                         "settings (DOTS_SECTION)")
    ap.add_argument("--cached-only", action="store_true",
                    help="score only the --gap settings whose frames are in --cache and the --ref-count sets whose "
                         "references all are (render none of them)")
    ap.add_argument("--cache", default=None, help="folder for the rendered frames (pickles), reused when there")
    ap.add_argument("--out", default=str(ROOT / "docs"))
    ap.add_argument("--quick", action="store_true", help="160x90, references spp 2 / light_spp 32 (smoke run)")
    a = ap.parse_args()
    cache = Path(a.cache) if a.cache else None
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    prof = load_yaml(ROOT / "render_tools" / "configs" / "render_profiles.yaml")["default"]
    W, H = (160, 90) if a.quick else (prof["width"], prof["height"])
    ref_spp, ref_light_spp = (2, 32) if a.quick else (REF_SPP, REF_LIGHT_SPP)
    base = dict(width=W, height=H, frames=1, bins=prof["bins"], spp=prof["spp"], light_spp=prof["light_spp"])

    def ref_opts(seed, groups):
        spp = ref_spp if groups is None else 1  # the flickering groups alone: only their lamps' boxes are measured
        return render.RenderOptions(**{**base, "spp": spp, "light_spp": ref_light_spp, "seed": seed,
                                       "dots_lod_px": 0.0, "static_denoise": "off", "reflection_denoise": "off",
                                       "reflection_block_px": 1, "groups": groups})

    if a.warmup and (a.lamp_cases or a.cases):
        c0 = (a.lamp_cases or a.cases)[0]
        _frame(_v2_scene(c0), render.RenderOptions(**{**base, "seed": 11, "groups": LAMP_GROUPS}), None, "")
    if a.figure:
        figure(a.figure, cache, (W, H), ROOT / "docs" / "img" / "led-dot-faces.png")
        return
    load0, t0 = os.getloadavg()[0], time.time()
    rows = []
    try:
        todo = run_plan(a.lamp_cases, a.cases, a.ref4_cases, a.ref_cases, a.ref_count)
    except ValueError as e:
        ap.error(str(e))  # one line naming --ref-count, exit status 2
    for c, groups, seeds in todo:
        sc = _v2_scene(c)
        tag = f"{c.replace(':', '_')}_{W}" + ("" if groups is None else "_lamps")
        ref_cpu = 0.0
        if a.cached_only and cache is not None and not all(
                frame_path(cache, f"tgt_ref_{ref_opts(s, groups).spp}_{ref_light_spp}_{s}_{tag}").exists()
                for s in seeds):
            print(c, f"{len(seeds)} references not all in --cache: skipped", flush=True)
            continue

        def load(s):
            nonlocal ref_cpu
            o = ref_opts(s, groups)
            fr, cpu = _frame(sc, o, cache, f"tgt_ref_{o.spp}_{ref_light_spp}_{s}_{tag}")
            ref_cpu += cpu
            return fr

        refs = ref_halves(load, seeds)  # 2N references: two halves, each the mean of N
        print(c, f"references {ref_cpu:.0f} CPU s", flush=True)
        settings = {"default": {}, **{n: kw for n, kw in GAP_SETTINGS.items() if n in a.gap_settings
                                      and c in a.gap_cases and ("spp" in kw) == (groups is None)}}
        for name, kw in settings.items():
            opts = render.RenderOptions(**{**base, "seed": 11, "groups": groups, **kw})
            key = "_".join(f"{k}{v}" if isinstance(v, str) else f"{k}{v:g}" for k, v in sorted(kw.items())) \
                or "default"
            if a.cached_only and kw and not frame_path(cache, f"tgt_{key}_{tag}").exists():
                continue
            fr, cpu = _frame(sc, opts, cache, f"tgt_{key}_{tag}")
            r = {"case": c, "setting": name + (f", {len(seeds)} references" if len(seeds) != 2 else ""),
                 "cpu_s": cpu, "ref_cpu_s": ref_cpu, **scores(sc, fr, *refs, opts)}
            rows.append(r)
            print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items() if k != "kinds"},
                  flush=True)
            del fr
        del refs
        # after every case, so that a run stopped early leaves what it measured
        write_section(rows, Path(a.out), load0, os.getloadavg()[0], (W, H), (ref_spp, ref_light_spp),
                      (time.time() - t0) / 60, dots=a.section == "dots")


def figure(case: str, cache: Path, size, out: Path, kind: str = "message_sign") -> None:
    """Close-up PNG of the lights of ``kind`` in ``case``'s flickering groups (frame 0, mean over the bins, every
    light's crop summed; luminance, log scale, one colour scale for all panels, each pixel drawn as a block): the
    ``default`` profile (filled cells), the dots as they are at light_spp x 4, their exact coverage
    (``dots_coverage`` exact) and the references' mean, from the frames in ``cache``."""
    import pickle  # noqa: PLC0415

    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    sc = _v2_scene(case)
    tag = f"{case.replace(':', '_')}_{size[0]}_lamps"
    ids = {lt["id"] for lt in sc["lights"] if lt["kind"] == kind}

    def load(name):
        with open(frame_path(cache, f"{name}_{tag}"), "rb") as fh:
            return pickle.load(fh)[0]

    def canvas(fr):
        img = np.zeros((size[1], size[0]))
        for items in fr["lights"].values():
            for lid, (y0, x0, y1, x1), b in items:
                img[y0:y1, x0:x1] += lum(np.asarray(b)).mean(0)
        return img

    refs = [canvas(load(f"tgt_ref_1_{REF_LIGHT_SPP}_{s}")) for s in REF_SEEDS]
    panels = [("default (filled cells)", canvas(load("tgt_default"))),
              ("dots as they are, light_spp x 4", canvas(load("tgt_dots_lod_px0_dots_spp_factor4"))),
              ("exact coverage (dots_coverage: exact)", canvas(load("tgt_dots_coverageexact"))),
              (f"reference (dots as they are, light_spp {REF_LIGHT_SPP}, 2 seeds)", 0.5 * (refs[0] + refs[1]))]
    boxes = [b for lid, b in lamp_boxes(sc, render_opts(size)).items() if lid in ids]
    y0, x0 = min(b[0] for b in boxes) - 2, min(b[1] for b in boxes) - 2
    y1, x1 = max(b[2] for b in boxes) + 2, max(b[3] for b in boxes) + 2
    top = max(p[y0:y1, x0:x1].max() for _, p in panels)
    ref = panels[-1][1][y0:y1, x0:x1]
    fig, axs = plt.subplots(len(panels), 2, figsize=(11, 1.5 * len(panels)), squeeze=False)
    for (ax, dx), (name, p) in zip(axs, panels):
        ax.imshow(np.log10(np.maximum(p[y0:y1, x0:x1], top * 1e-3)), cmap="inferno", vmin=np.log10(top) - 3,
                  vmax=np.log10(top), interpolation="nearest")
        ax.set_title(name, fontsize=8)
        lit = ref > 1e-2 * ref.max()  # relative difference where the reference is lit
        d = np.where(lit, (p[y0:y1, x0:x1] - ref) / np.where(lit, ref, 1.0), 0.0)
        dx.imshow(d, cmap="RdBu_r", vmin=-0.3, vmax=0.3, interpolation="nearest")
        dx.set_title("(this - reference) / reference, lit pixels (+-30 %)" if p is not panels[-1][1] else
                     "(the reference)", fontsize=8)
        for a_ in (ax, dx):
            a_.set_xticks([])
            a_.set_yticks([])
    fig.suptitle(f"{kind.replace('_', ' ')}s, {case}, frame 0 at {size[0]}x{size[1]}, mean of 8 bins: log luminance "
                 f"(3 decades; px {x0}-{x1} x {y0}-{y1}) and the difference to the reference", fontsize=9)
    fig.tight_layout()
    from lfmbench.fileio import atomic_save_figure  # noqa: PLC0415

    atomic_save_figure(fig, out, dpi=110)
    plt.close(fig)


def render_opts(size):
    """RenderOptions of the cases' geometry (``default`` profile's, the flickering groups) at ``size``."""
    from render_tools import render  # noqa: PLC0415

    return render.RenderOptions(width=size[0], height=size[1], frames=1, groups=LAMP_GROUPS)


def ref_count_of(setting: str) -> tuple[str, int]:
    """(name, references) of a row's setting: ``"default, 8 references"`` -> ("default", 8); no such suffix: 2."""
    head, _, tail = setting.rpartition(", ")
    if head and tail.endswith(" references") and tail.split()[0].isdigit():
        return head, int(tail.split()[0])
    return setting, 2


def write_section(rows: list, out: Path, load0: float, load1: float, size, ref, minutes: float,
                  dots: bool = False) -> None:
    """Write the rows as :data:`SECTION` of docs/benchmarks/render.md under ``out`` (``dots``: as
    :data:`DOTS_SECTION`, with its rerun command)."""
    import datetime  # noqa: PLC0415

    day = datetime.datetime.now(datetime.timezone.utc).date().isoformat()
    lines = [SECTION, "",
             f"Generated by `benchmarks/studies/bench_render_v2_targets.py` on {day}, the project's shared 2-core AMD "
             f"EPYC (AVX2), 1-minute load average {load0:.1f} at the start and {load1:.1f} at the end "
             f"({minutes:.0f} min; other jobs shared the cores: CPU seconds are upper bounds). Frame 0 of scene "
             f"generator 2 scenes at {size[0]}x{size[1]}, the `default` profile (spp 1, light_spp 32, K 8) with every "
             "other field at its default, on scene version 2 the render rules of `lfmbench-v2` protocol version "
             f"{rules_version()} (the cache's file names carry it; docs/guide/protocols.md), against two references "
             "of seeds "
             f"{REF_SEEDS[0]}, {REF_SEEDS[1]} that draw the LED dots as they are (`dots_lod_px` 0): spp {ref[0]}, "
             f"light_spp {ref[1]}, nothing denoised, a wet road's reflections per pixel (module docstring). Rows "
             "`(lamps)`: the flickering groups rendered alone (references at spp 1, light_spp as above; CPU: the lamp "
             "crops): LED bins only. LED bins "
             "(every flickering light's LED pixels inside its own box, all bins) and LED px (the short composite over "
             "the references' light mask): relative RMSE corrected for the references' noise; median: all-pixel "
             "median relative error of the short window, corrected in quadrature for the references' own median "
             "error (raw: upper bound; ref: the references' mean's own; p46-p54: the 46th and 54th percentiles of the "
             "raw per-pixel error, between which the raw median stays when under 4 % of the pixels change). "
             "Targets (issue 23): LED pixels <= 2 % "
             "(both LED columns), "
             "all-pixel median <= 10 % (`met (corrected)`: only the corrected median is under it). CPU: user + "
             "system s of the frame in the process (references: all the row's references; rows `N references`: scored "
             "against N, each side the mean of N / 2).", "",
             "| scene (seed:time:weather) | setting | CPU s / frame (references) | LED bins | LED px (short) | "
             "median (short) | raw | p46-p54 raw | ref | median long, raw | targets |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "led_px" in r:
            rest = (f"{r['led_px']:.3f} | {r['median_short']:.3f} | {r['median_short_raw']:.3f} | "
                    f"{r['p46_short_raw']:.3f}-{r['p54_short_raw']:.3f} | {r['median_short_ref']:.3f} | "
                    f"{r['median_long_raw']:.3f} | "
                    f"{verdict(r['led_bins'], r['led_px'], r['median_short'], r['median_short_raw'])} |")
        else:
            rest = f"- | - | - | - | - | - | LED {'met' if r['led_bins'] <= TARGET_LED else 'missed'} (LED bins) |"
        lines.append(f"| {r['case']}{'' if 'led_px' in r else ' (lamps)'} | {r['setting']} | {r['cpu_s']:.1f} "
                     f"({r['ref_cpu_s']:.0f}) | {r['led_bins']:.3f} | " + rest)
    kinds = sorted({k for r in rows for k in r["kinds"]})
    lines += ["", "LED bins per light kind: the same corrected relative RMSE, the lights of one kind pooled (its share "
              "of the pooled squared error). A kind whose lamps are dim or unlit in frame 0 (an indicator off, a "
              "billboard or display seen edge-on or from behind) has a large relative error and no weight.", "",
              "| scene | setting | " + " | ".join(kinds) + " |", "|---|---|" + "---|" * len(kinds)]
    for r in rows:
        lines.append(f"| {r['case']} | {r['setting']} | "
                     + " | ".join(f"{r['kinds'][k][0]:.3f} ({r['kinds'][k][1]:.2f})" if k in r["kinds"] else "-"
                                  for k in kinds) + " |")
    regs = [r for r in [*REGIONS, "sky", "lamps", "other"] if any(r in x.get("regions", {}) for x in rows)]
    if regs:
        lines += ["", "All-pixel median of the short window by what a pixel shows (:data:`REGIONS` of the script: the "
                  "first camera hit's object kind; no hit: sky; the references' light mask: lamps): share of the "
                  "frame's pixels, median relative error raw / corrected for the references' noise (%).", "",
                  "| scene | setting | " + " | ".join(regs) + " |", "|---|---|" + "---|" * len(regs)]
        for r in rows:
            if "regions" in r:
                g = r["regions"]
                lines.append(f"| {r['case']} | {r['setting']} | " + " | ".join(
                    f"{100 * g[k][0]:.0f} %: {100 * g[k][1]:.1f} / {100 * g[k][3]:.1f}" if k in g else "-"
                    for k in regs) + " |")
    sets = {}  # (case, setting) -> [row against 2, 2N ... references], fewest first
    for r in rows:
        if "median_short_raw" in r:
            name, n = ref_count_of(r["setting"])
            sets.setdefault((r["case"], name), []).append((n, r))
    sets = {k: sorted(v, key=lambda x: x[0]) for k, v in sets.items() if len(v) > 1}
    if sets:
        lines += ["", "The median against noiseless references, extrapolated (:func:`fit_extrapolated`: raw^2 = c^2 + "
                  "k r^2 fitted by least squares through the raw medians against every reference count measured (2, "
                  "4, 8, 16), r their means' own median error): c, k (k 1: the quadrature correction's assumption) "
                  "and, with three or more points, the fit's largest residual (|fitted - measured raw|; two points fit "
                  "exactly).", "",
                  "| scene | setting | references | raw | r | median corrected | c (short) | k | residual |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for (case, name), rs in sets.items():
            n, rs = [x[0] for x in rs], [x[1] for x in rs]
            c, k, res = fit_extrapolated([x["median_short_raw"] for x in rs], [x["median_short_ref"] for x in rs])
            lines.append(f"| {case} | {name} | {' / '.join(map(str, n))} | "
                         + " | ".join(" / ".join(f"{x[f]:.3f}" for x in rs) for f in
                                      ("median_short_raw", "median_short_ref", "median_short"))
                         + f" | {c:.3f} | {k:.2f} | " + (f"{res:.4f}" if len(rs) > 2 else "-") + " |")
    if dots:
        lines[0] = DOTS_SECTION
        lines += ["", f"Run again with `{DOTS_RERUN}` (the references are the bulk of the time; add `--gap-cases "
                  "202:dusk:dry 101:night:dry --gap-settings \"sub-pixel dots as they are x8\"` for the x8 rows, and "
                  "`--cached-only` to score what the cache holds).", ""]
    else:
        lines += ["", f"Run again with `{TARGETS_RERUN}` (the whole frames of the 9 cases, four, eight and sixteen "
                  "references and `static spp 2` where the tables have them; the references are the bulk of the "
                  "time; `--cases`, `--ref4-cases`, `--ref-cases`, `--lamp-cases` and `--gap-cases` choose the "
                  "cases).", ""]
    replace_section(out / "benchmarks" / "render.md", lines[0], lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
