"""CPU cost of the static-frame and reflection denoiser's numpy work (issue 40, deliverable 5: the v2 render within
1.5x of v1): writes the section "Denoiser numpy work: CPU per call" of docs/benchmarks/render-scale.md.

Generator 2's renders denoise each frame's two static windows (:func:`render_tools.denoise.denoise_static`, 640x360
px, 31 bands, one image per static group) and, on wet roads, every flickering lamp's reflection crop
(:func:`render_tools.denoise.denoise_reflection`, 75 crops per scene on the wet night of seed 101); generator 1
renders neither, so this work is all v2 excess. The Open Image Denoise call is replaced by a copy here (its cost is
not numpy's and is unchanged); what is timed is the split of the denoised broad bands among groups and bands: box
and block means, bilinear upsampling, masks.

Two forms of the block mean and the upsampling are timed, alternating: the form shipped in
:mod:`render_tools.denoise` (blocks that tile the image summed without a zero-padded copy; the bilinear gathers by
``np.take`` and computed in place) and the form before it (kept below, :func:`_block_mean_before` and
:func:`_upsample_before`: a zero-padded float64 copy; fancy-indexed gathers with a temporary per product). The
script first checks that both give the same bits on the inputs it times (same float32 products and sums in the same
order: the corpus files stay byte-identical). Thread CPU seconds (``time.thread_time``) of the calling thread,
median over ``--repeats`` calls of each form.

Usage: ``python benchmarks/studies/denoise_cost.py [--repeats 7] [--out docs]`` (about a minute on a quiet machine).
"""
from __future__ import annotations

import argparse
import datetime
import os
import statistics
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _timing import replace_section  # noqa: E402

SECTION = "## Denoiser numpy work: CPU per call (issue 40)"


def _block_mean_before(x: np.ndarray, f: int) -> np.ndarray:
    """The block mean as it was before 2026-11-28 (a zero-padded float64 copy for every shape)."""
    x = np.asarray(x, np.float32)
    N, H, W = x.shape
    h, w = -(-H // f), -(-W // f)
    pad = np.zeros((N, h * f, w * f), np.float64)
    pad[:, :H, :W] = x
    cnt = np.zeros((h * f, w * f), np.float64)
    cnt[:H, :W] = 1.0
    sums = pad.reshape(N, h, f, w, f).sum(axis=(2, 4))
    return (sums / cnt.reshape(h, f, w, f).sum(axis=(1, 3))).astype(np.float32)


def _upsample_before(x: np.ndarray, f: int, shape: tuple) -> np.ndarray:
    """The bilinear upsampling as it was before 2026-11-28 (fancy-indexed gathers, a temporary per product)."""
    x = np.asarray(x, np.float32)

    def taps(n_out: int, n_in: int):
        src = np.maximum((np.arange(n_out) + 0.5) / f - 0.5, 0.0)
        i0 = np.minimum(np.floor(src).astype(int), n_in - 1)
        i1 = np.minimum(i0 + 1, n_in - 1)
        return i0, i1, (src - i0).astype(np.float32)

    y0, y1, ly = taps(shape[0], x.shape[1])
    x0, x1, lx = taps(shape[1], x.shape[2])
    rows = x[:, y0, :] * (1 - ly)[None, :, None] + x[:, y1, :] * ly[None, :, None]
    return (rows[:, :, x0] * (1 - lx) + rows[:, :, x1] * lx).astype(np.float32)


@contextmanager
def _before(D):
    """:mod:`render_tools.denoise` with the forms before 2026-11-28 in place (restored on exit)."""
    saved = D._block_mean, D._upsample
    D._block_mean, D._upsample = _block_mean_before, _upsample_before
    try:
        yield
    finally:
        D._block_mean, D._upsample = saved


def _inputs(rng: np.random.Generator, C: int = 31, H: int = 360, W: int = 640, groups: int = 3):
    """A static window as the tracer leaves it at the ``default`` profile: ``groups`` images (C, H, W) >= 0 with
    dark regions, 30 lamp boxes; a reflection crop (C, 96, 64) with its lamp box and traced mask."""
    imgs = {}
    for g in range(groups):
        x = rng.gamma(0.5, 1e-3, (C, H, W)) * (rng.random((C, H, W)) > 0.2)
        x[:, : H // 3, : W // 4] = 0.0
        imgs[g] = x.astype(np.float32)
    boxes = [(12 * i, 20 * i + 3, 12 * i + 9, 20 * i + 15) for i in range(30)]
    crop = (rng.gamma(0.5, 1e-4, (C, 96, 64)) * np.linspace(1, 0.1, 96)[None, :, None]).astype(np.float32)
    traced = np.zeros((96, 64), bool)
    traced[:, 16:48] = True
    return imgs, boxes, crop, traced, [(2, 20, 14, 44)]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7, help="calls of each form (median reported)")
    ap.add_argument("--out", default=str(ROOT / "docs"))
    a = ap.parse_args()
    from render_tools import denoise as D  # noqa: PLC0415

    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    load0 = os.getloadavg()[0]
    t_start = time.perf_counter()
    imgs, boxes, crop, traced, crop_boxes = _inputs(np.random.default_rng(0))

    def copy(x):
        return np.array(x, np.float32, copy=True)

    calls = {"static window (3 groups, 640x360 px, 31 bands)": lambda: D.denoise_static(imgs, boxes, denoiser=copy),
             "reflection crop (96x64 px, 31 bands)": lambda: D.denoise_reflection(crop, traced, crop_boxes,
                                                                                   denoiser=copy)}
    for name, fn in calls.items():  # the same bits both ways, or nothing is timed
        new = fn()
        with _before(D):
            old = fn()
        same = all(np.array_equal(new[g], old[g]) for g in new) if isinstance(new, dict) else np.array_equal(new, old)
        if not same:
            raise SystemExit(f"{name}: the two forms differ: the comparison would be meaningless")
    rows = []
    for name, fn in calls.items():
        t_new, t_old = [], []
        for _ in range(a.repeats):  # alternating, so that a change of load hits both alike
            t = time.thread_time()
            fn()
            t_new.append(time.thread_time() - t)
            with _before(D):
                t = time.thread_time()
                fn()
                t_old.append(time.thread_time() - t)
        ratio = statistics.median(n / o for n, o in zip(t_new, t_old))
        rows.append(f"| {name} | {1e3 * statistics.median(t_old):.0f} | {1e3 * statistics.median(t_new):.0f} | "
                    f"{ratio:.2f} |")
    load1 = os.getloadavg()[0]
    lines = [SECTION, "",
             f"Generated by `benchmarks/studies/denoise_cost.py` on {date}, the project's shared 2-core AMD EPYC "
             f"(AVX2), 1-minute load average {load0:.1f} at the start and {load1:.1f} at the end "
             f"({time.perf_counter() - t_start:.0f} s): the denoiser's numpy work (Open Image Denoise replaced by a "
             f"copy) on synthetic inputs of the `default` profile's shapes, thread CPU milliseconds per call, median of "
             f"{a.repeats} calls of each form, alternating (module docstring). Before: the block mean and bilinear "
             "upsampling as they were until 2026-11-28; now: as shipped. Both give the same bits (checked by the "
             "script on these inputs before timing).", "",
             "| call | before (ms) | now (ms) | now / before (median of call-by-call ratios) |",
             "|---|---|---|---|", *rows, "",
             "Run again with `python benchmarks/studies/denoise_cost.py`.", ""]
    replace_section(Path(a.out) / "benchmarks" / "render-scale.md", SECTION, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
