"""Static window layers (``RenderOptions.static_layers``, :mod:`render_tools.static_layers`): a chopped capture's
static radiance rendered once over the union of its 12 sub-windows.

The brute force it is checked against is independent of the layer's sampling: the scene rendered in static time bins
cut at all 24 sub-window edges (each sub-window its own full frame at ``spp``, the existing, separately tested
scheme of tests/render_tools/test_motion_windows.py), the 12 sub-window bins averaged by length.
"""
from __future__ import annotations

import numpy as np
import pytest

from lfmbench.corpus import window_bin_weights
from lfmbench.corpus.window_layers import parse_layers
from render_tools import render, static_layers
from tests.render_tools.test_motion_windows import crossing_scene

#: The chopped preset's sub-windows (lfmbench/configs/sensors/chopped.yaml), [start, length] s from the frame start.
CHOPPED = tuple((0.00092 * i, 0.0001) for i in range(12))
LAYER = [{"name": "chopped", "windows_s": [list(w) for w in CHOPPED]}]


def test_bad_layers_are_refused_naming_the_field():
    cw = 1.0 / 90.0
    assert parse_layers(LAYER, cw) == (("chopped", CHOPPED),)
    for bad, field in [
            ([{"name": "c", "windows_s": [[0.0, 0.002], [0.001, 0.001]]}],
             r"static_layers\[0\]\.windows_s\[1\]: starts at 1 ms, before"),
            ([{"name": "c", "windows_s": [[0.011, 0.001]]}],
             r"static_layers\[0\]\.windows_s\[0\]: ends at 12 ms, after"),
            ([{"name": "c", "windows_s": [[0.0, 0.0]]}], r"windows_s\[0\]: needs start >= 0 s and length > 0"),
            ([{"name": "C!", "windows_s": [[0.0, 0.001]]}], r"static_layers\[0\]\.name"),
            ([LAYER[0], LAYER[0]], r"static_layers\[1\]\.name: 'chopped' is given twice")]:
        with pytest.raises(ValueError, match=field):
            render.RenderOptions(width=8, height=4, line_time_s=0.0, static_layers=bad)
    assert "static_layers" not in render.RenderOptions(width=8, height=4).to_dict()  # older corpora's options


def test_assignment_deals_every_sub_window_once_per_group_of_runs():
    run = static_layers.RUN_PX
    j0 = static_layers.assignment(6, 4 * run, 12, seed=3)
    runs = j0[:, ::run].ravel()                                  # one value per run of a row
    assert (np.repeat(j0[:, ::run], run, axis=1) == j0).all()
    assert all(sorted(g) == list(range(12)) for g in runs.reshape(2, 12))
    # every sample of a pixel in one sub-window, spread evenly over the sub-windows (stratified in time)
    counts = np.stack([static_layers.sample_counts(j0, 12, 16, j) for j in range(12)])
    assert (counts.sum(0) == 16).all() and set(np.unique(counts)) <= {1, 2}
    # over the random rotations each pixel's sub-window is uniform (what makes the layer unbiased)
    hist = np.bincount([int(static_layers.assignment(1, 1, 12, s)[0, 0]) for s in range(600)], minlength=12)
    assert hist.min() > 21 and hist.max() < 79     # 50 each; 4.2 sigma of the binomial (sd 6.8)


@pytest.mark.slow
@pytest.mark.jit
def test_chopped_layer_equals_the_sub_windows_integrated_and_not_the_nearest_window():
    """A car crossing the view at 60 m/s (its lamp moves about 1.4 px between sub-windows): the layer (one frame's
    samples: 24 per pixel spread over the 12 sub-windows) against the brute force (each sub-window a full frame at
    2 spp: the same 24 samples per pixel). Both are unbiased, so what differs is noise, and per pixel that noise is
    large (relative RMSE 0.20-0.21 between the two over seeds 1-3, measured 2026-11-28); the checks are on what
    averages it out: the column profile (radiance summed over rows and bands: relative RMSE 0.025-0.041), the lamp's
    centroid (0.005-0.043 px) and the energy (within 1.2 %); the bounds are 1.7-3x those. ``nearest`` (the long
    window, 0-11.1 ms, the smallest stored window containing the union) smears the lamp over 0.9 ms more and is
    centred 0.44 ms later: profile RMSE 0.14-0.15, centroid 0.63-0.67 px off on the same seeds."""
    s = crossing_scene(velocity=(0.0, -60.0, 0.0))
    opts = render.RenderOptions(width=40, height=8, spp=24, frames=1, aux=False, line_time_s=0.0,
                                static_layers=LAYER)
    lay = next(static_layers.render_layer(s, opts, opts.static_layers[0]))["static"]["headlights"]
    ob = render.RenderOptions(width=40, height=8, spp=2, frames=1, aux=False, line_time_s=0.0, seed=11,
                              static_edges_s=tuple(x for a, n in CHOPPED for x in (a, a + n)))
    fr = next(render.render_frames(s, ob))
    e, bins = np.asarray(fr["static_edges_s"]), fr["static"]["headlights"]["bins"]
    brute = sum(np.tensordot(window_bin_weights(e, a, n), bins, axes=1) for a, n in CHOPPED) / len(CHOPPED)
    nearest = fr["static"]["headlights"]["long"]

    def profile_rmse(x):
        p, q = x.sum((0, 1)), brute.sum((0, 1))
        return float(np.sqrt(((p - q) ** 2).mean() / (q ** 2).mean()))

    def cx(img):
        col = img.sum((0, 1))
        return float((col * (np.arange(col.size) + 0.5)).sum() / col.sum())

    assert abs(lay.sum() / brute.sum() - 1) < 0.02
    assert abs(cx(lay) - cx(brute)) < 0.15 and abs(cx(nearest) - cx(brute)) > 0.5
    assert profile_rmse(lay) < 0.07 and profile_rmse(nearest) > 0.1
