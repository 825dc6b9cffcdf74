"""Exact pixel coverage of LED dot faces (render_tools.dot_coverage) against independent answers: areas by dense
point sampling and by hand, a fronto-parallel face's projected area (pinhole: f x size / depth), a half-hidden
face."""
from __future__ import annotations

import numpy as np

from render_tools import dot_coverage


def test_clip_area_equals_dense_sampling_and_hand_areas():
    rng = np.random.default_rng(5)
    c = rng.uniform(0.0, 2.0, (24, 2))
    a, b = rng.uniform(0.1, 1.2, (24, 2)) * rng.choice([-1, 1], (24, 2)), rng.uniform(0.1, 1.2, (24, 2))
    quads = np.stack([c, c + a, c + a + b, c + b], 1)  # parallelograms, either winding
    box = np.array([0.5, 0.5, 1.5, 1.5])
    got = dot_coverage.clip_area(quads, np.tile(box, (24, 1)))
    g = 0.5 + (np.arange(200) + 0.5) / 200  # 200 x 200 points of the box: area to ~1/200 (edges)
    X, Y = np.meshgrid(g, g)
    P = np.stack([X.ravel(), Y.ravel()], 1)
    for q, area in zip(quads, got):
        e = np.roll(q, -1, 0) - q
        side = e[:, 0][None] * (P[:, 1][:, None] - q[:, 1][None]) - e[:, 1][None] * (P[:, 0][:, None] - q[:, 0][None])
        inside = np.all(side >= 0, 1) | np.all(side <= 0, 1)
        assert abs(area - inside.mean()) < 5e-3
    # by hand: a rectangle half over the box's left edge; a quad holding the box; one outside it
    hand = dot_coverage.clip_area(np.array([[[0.25, 0.5], [1.75, 0.5], [1.75, 0.8], [0.25, 0.8]],
                                            [[-1, -1], [3, -1], [3, 3], [-1, 3]],
                                            [[2, 2], [3, 2], [3, 3], [2, 3]]], float),
                                  np.array([[1.0, 0.0, 2.0, 1.0]] * 3))
    assert np.allclose(hand, [0.75 * 0.3, 1.0, 0.0], atol=1e-12)


def _face(cols=6, rows=4, dot=0.5):
    return {"shape": "dots", "center": [0.0, 0.0, 10.0], "normal": [0.0, 0.0, -1.0], "size": [0.6, 0.4],
            "grid": [cols, rows], "dot": dot, "cells": [[c, r] for r in range(rows) for c in range(cols)],
            "instance": -1}


def test_fronto_parallel_face_covers_its_projected_area_and_a_hidden_half_is_left_out():
    f = 100.0
    K = np.array([[f, 0.0, 20.0], [0.0, f, 20.0], [0.0, 0.0, 1.0]])
    pose = np.eye(4)  # camera at the origin looking along +z (OpenCV axes)
    face = _face()
    crop = (0, 0, 40, 40)
    cov = dot_coverage.dots_coverage({}, face, K, lambda t: pose, crop, [0.0, 1e-3, 2e-3])
    # each dot 0.05 x 0.05 m at 10 m: (f x 0.005)^2 = 0.25 px^2; 24 dots; both bins alike (nothing moves)
    assert cov.shape == (2, 40, 40)
    assert np.allclose(cov.sum((1, 2)), 24 * 0.25, rtol=1e-9)
    assert cov.max() <= 1.0 + 1e-12 and cov.min() >= 0.0
    # dot pitch 1 px, dots 0.5 px wide: no pixel holds more than one dot's 0.25 px^2
    assert cov.max() <= 0.25 + 1e-12

    # an occluder hiding x < 0 (world): the 3 left columns whole; with the cut through the middle of a column,
    # its dots' right halves stay (the fine parts resolve a cut at a multiple of 1/16 of a dot)
    def hide_left(cut):
        def visible(times, corners, cams, n):
            parts = dot_coverage._sub_quads(corners.reshape(-1, 4, 3), n).mean(2)
            return (parts[..., 0] > cut).reshape(corners.shape[0], corners.shape[1], n * n)
        return visible

    half = dot_coverage.dots_coverage({}, face, K, lambda t: pose, crop, [0.0, 1e-3], hide_left(0.0))
    assert np.isclose(half.sum(), 12 * 0.25, rtol=1e-9)
    mid = dot_coverage.dots_coverage({}, face, K, lambda t: pose, crop, [0.0, 1e-3], hide_left(0.05))
    assert np.isclose(mid.sum(), (8 + 2) * 0.25, rtol=1e-9)  # columns 4, 5 whole, column 3's right halves
    # a face with its back to the camera emits nothing towards it
    back = dict(face, normal=[0.0, 0.0, 1.0])
    assert dot_coverage.dots_coverage({}, back, K, lambda t: pose, crop, [0.0, 1e-3]).sum() == 0.0


def _clip_two_gathers(poly, axis, bound, keep_below):
    """The clip step as written before its gathers were joined: the sorted points gathered, then those (the
    reference of :func:`test_joined_gathers_and_part_centres_equal_the_plain_computation_bit_for_bit`)."""
    N, V, _ = poly.shape
    p, q = poly, np.roll(poly, -1, axis=1)
    s = 1.0 if keep_below else -1.0
    dp, dq = s * (p[..., axis] - bound[:, None]), s * (q[..., axis] - bound[:, None])
    inside_p, inside_q = dp <= 0, dq <= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(dp != dq, dp / (dp - dq), 0.0)
    pts = np.stack([p, p + f[..., None] * (q - p)], axis=2).reshape(N, 2 * V, 2)
    ok = np.stack([inside_p, inside_p != inside_q], axis=2).reshape(N, 2 * V)
    pts = np.take_along_axis(pts, np.argsort(~ok, axis=1, kind="stable")[..., None], axis=1)
    cnt = ok.sum(1)
    idx = np.minimum(np.arange(2 * V)[None, :], np.maximum(cnt - 1, 0)[:, None])
    out = np.take_along_axis(pts, idx[..., None], axis=1)
    out[cnt == 0] = 0.0
    return out[:, :V + 1]


def test_joined_gathers_and_part_centres_equal_the_plain_computation_bit_for_bit():
    """The render's shortcuts give the very same numbers (corpus files byte-identical): the clip step with one
    gather equals the two-gather version, and the visibility test's part centres (:func:`dot_coverage._sub_centres`)
    equal the mean of the parts' corners (:func:`dot_coverage._sub_quads`), zeros' signs included."""
    rng = np.random.default_rng(11)
    for t in range(8):
        poly = rng.uniform(-2.0, 3.0, (300, int(rng.integers(3, 8)), 2))
        if t % 2:
            poly = np.round(poly)  # vertices on the clip lines
        bound = rng.uniform(-1.0, 2.0, 300)
        for axis in (0, 1):
            for below in (True, False):
                assert dot_coverage._clip(poly, axis, bound, below).tobytes() == \
                    _clip_two_gathers(poly, axis, bound, below).tobytes()
        corners = rng.normal(size=(50, 4, 3)) * 10.0 ** rng.uniform(-3, 3)
        corners[:, :2, t % 3] = -0.0 if t % 2 else 0.0
        for n in (8, 16):
            want = dot_coverage._sub_quads(corners, n).mean(2)
            got = dot_coverage._sub_centres(corners, n)
            assert got.shape == want.shape and got.tobytes() == want.tobytes()
