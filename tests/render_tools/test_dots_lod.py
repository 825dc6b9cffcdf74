"""Sub-pixel LED dot faces drawn as filled cells (``RenderOptions.dots_lod_px``, :func:`render_tools.render.dots_lod`,
:func:`render_tools.led_matrix.filled_cells`): the same intensity per lamp, the rows of a multiplexed sign keep their
own phase, and scenes without dot faces (lfmbench-v1) or with resolved dots are drawn as before."""
from __future__ import annotations

import numpy as np
import pytest

from render_tools import led_matrix as LM
from render_tools import mitsuba_scene as MS
from render_tools import render as R
from render_tools import scene as S
from render_tools.lamp_closeup import closeup_scene, light_weights


def _brute_intensity(light: dict, per_pitch: int = 300) -> tuple[float, float]:
    """Luminous intensity (cd) of a ``dots`` light along its normal by brute force, and the bound of its error.

    The light's mesh (:func:`mitsuba_scene._plane_mesh`) is rasterised on a grid of points over the face's extent
    (in the in-plane axes of :mod:`mitsuba_scene`), ``per_pitch`` points per dot pitch: a point inside a triangle
    counts luminance x the grid cell's area. Independent of :func:`led_matrix.dots_area`. Every edge is parallel
    to an axis, so the counted area of each is off by at most half a step times its length: the bound is
    luminance x perimeter x step / 2."""
    u, v, _ = MS._frame(light["normal"])
    V, F = MS._plane_mesh(light, np.zeros(3))
    c = np.asarray(light["center"], float)
    P = np.stack([(V - c) @ u, (V - c) @ v], -1)  # (V, 2) m in the face plane
    (w, h), (cols, rows) = light["size"], light["grid"]
    s = min(w / cols, h / rows) / per_pitch
    nu, nv = int(np.ceil(w / s)), int(np.ceil(h / s))
    inside = np.zeros((nv, nu), bool)
    for tri in P[F]:
        lo, hi = tri.min(0), tri.max(0)
        i0, i1 = max(int((lo[0] + w / 2) / s) - 1, 0), min(int((hi[0] + w / 2) / s) + 2, nu)
        j0, j1 = max(int((lo[1] + h / 2) / s) - 1, 0), min(int((hi[1] + h / 2) / s) + 2, nv)
        X, Y = np.meshgrid((np.arange(i0, i1) + 0.5) * s - w / 2, (np.arange(j0, j1) + 0.5) * s - h / 2)
        a, b, d = tri
        e = [(q[0] - p[0]) * (Y - p[1]) - (q[1] - p[1]) * (X - p[0]) for p, q in ((a, b), (b, d), (d, a))]
        inside[j0:j1, i0:i1] |= ((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0))
    L = float(light["luminance_cd_m2"])
    per = len(light["cells"]) * 2 * light["dot"] * (w / cols + h / rows)  # m, every dot's edges
    return L * inside.sum() * s * s, L * per * s / 2


def test_filled_cells_keep_each_lamps_intensity():
    """A sign's scan line (text dots, dot 0.7), a signal's disk of dots and a segmented lamp: the filled cells
    (dot 1 at dot^2 of the luminance) send the same luminous intensity as the dots, by brute-force integration of
    both meshes (:func:`_brute_intensity`: within its error bound of each other and of luminance x dot area)."""
    sc = closeup_scene()
    line = next(lt for lt in sc["lights"] if lt["kind"] == "message_sign")
    signal = {"shape": "dots", "center": [0.0, 0.0, 5.0], "normal": [-1.0, 0.0, 0.0], "size": [0.3, 0.3],
              "grid": [13, 13], "dot": 0.7, "cells": LM.disk_cells(13), "luminance_cd_m2": 2e4}
    segs = {"shape": "dots", "center": [0.0, 0.0, 1.0], "normal": [-1.0, 0.0, 0.0], "size": [0.3, 0.1],
            "grid": [3, 1], "dot": 0.9, "cells": [[0, 0], [2, 0]], "luminance_cd_m2": 500.0}
    for lt in (line, signal, segs):
        f = LM.filled_cells(lt)
        assert f["dot"] == 1.0 and f["cells"] == lt["cells"]
        assert f["luminance_cd_m2"] * MS.plane_area(f) == pytest.approx(lt["luminance_cd_m2"] * MS.plane_area(lt),
                                                                         rel=1e-12)
        (i_dots, e_dots), (i_fill, e_fill) = _brute_intensity(lt), _brute_intensity(f)
        assert abs(i_dots - lt["luminance_cd_m2"] * MS.plane_area(lt)) <= e_dots
        assert abs(i_fill - i_dots) <= e_dots + e_fill
        assert e_dots + e_fill < 0.02 * i_dots        # the bound is tight enough to mean something


def _signs_far(width: int):
    """The close-up scene's sign and the options of a ``width`` x width*9/16 px render (its pitch: 0.05 m at 11 m,
    fov 40 deg: 0.00625 x width px); the dots traced (the stand-in is for traced faces; exact coverage has none)."""
    return closeup_scene(), R.RenderOptions(width=width, height=width * 9 // 16, spp=1, light_spp=16, frames=2,
                                             groups=("otherlights",), aux=False, dots_coverage="traced")


def test_only_sub_pixel_dot_faces_are_filled():
    sc, opts = _signs_far(96)           # pitch ~0.6 px: the sign's lines are filled
    drawn, ids = R.dots_lod(sc, opts)
    sign = [lt["id"] for lt in sc["lights"] if lt["kind"] == "message_sign"]
    assert set(sign) <= set(ids)
    assert all(drawn["lights"][i]["dot"] == 1.0 for i in sign)
    assert sc["lights"][sign[0]]["dot"] == 0.7            # the scene itself is left as it was
    geo = R.SceneGeometry(sc, opts)
    p = geo.dots_pitch_px(sc["lights"][sign[0]], [0.0])
    assert p == pytest.approx(0.0344 * 96 * 0.05 / 11 * 40.0, rel=0.15)  # f = 1.374 W px at fov 40 deg
    # at 640 px the sign's dots are 4 px apart: drawn as dots; 0 turns the stand-in off
    assert not set(sign) & set(R.dots_lod(sc, R.RenderOptions(width=640, height=360, frames=1))[1])
    assert R.dots_lod(sc, R.RenderOptions(width=96, height=54, frames=1, dots_lod_px=0.0)) == (sc, [])
    with pytest.raises(ValueError, match="dots_lod_px"):
        R.RenderOptions(dots_lod_px=-1.0)


def test_v1_scenes_are_drawn_and_described_as_before():
    """No lfmbench-v1 scene has a dot face: the scene is handed on untouched and meta.json has no new key."""
    opts = R.RenderOptions(width=160, height=90, frames=2)
    for seed, tod in ((3, "night"), (202, "day")):
        sc = S.generate_scene(seed, time_of_day=tod)
        assert R.dots_lod(sc, opts) == (sc, []) and R.dots_lod(sc, opts)[0] is sc
        assert "dots_lod_px" not in R.scene_meta(sc, opts)["render"]
    v2 = S.generate_scene(101, time_of_day="night", generator=2)
    meta = R.scene_meta(v2, opts)["render"]
    assert meta["dots_lod_px"] == 1.0 and meta["dots_lod"] == R.dots_lod(v2, opts)[1]


def test_filled_sign_rows_keep_their_own_phase():
    """A 1/8-scan sign drawn as filled cells: each line is still its own light with its scan-row waveform and the
    sign's driver; every emitting point of a line's filled face lies in a row that line drives (brute force over
    its triangles); in a 1.2 ms exposure some lines get light and some none, as with the dots."""
    sc, opts = _signs_far(96)
    drawn, ids = R.dots_lod(sc, opts)
    rows = [(a, b) for a, b in zip(sc["lights"], drawn["lights"]) if a["kind"] == "message_sign"]
    assert len(rows) >= 5
    for a, b in rows:
        assert {k: b[k] for k in ("id", "waveform", "driver", "group", "spectrum")} == \
            {k: a[k] for k in ("id", "waveform", "driver", "group", "spectrum")}
        u, v, _ = MS._frame(b["normal"])
        V, F = MS._plane_mesh(b, np.zeros(3))
        h, n_rows = b["size"][1], b["grid"][1]
        # barycentric points of every triangle -> the sign row they fall in (row 0 at the top)
        w = np.random.default_rng(0).dirichlet(np.ones(3), 64)
        pts = np.einsum("sk,fkd->fsd", w, V[F]) - np.asarray(b["center"])
        row = np.floor((h / 2 - pts @ v) / (h / n_rows)).astype(int)
        assert set(np.unique(row) % a["waveform"]["scan_lines"]) == {a["waveform"]["line"]}
        assert set(np.unique(row)) == {c[1] for c in a["cells"]}
    edges = np.linspace(0.0, 0.016, 17)
    carrier = {lt["id"]: (1 / 200.0, 0.9, 0.001) for lt in drawn["lights"]}
    short = light_weights(drawn, edges, (0.003, 0.0042), carrier, mean=False)
    lit = [short[b["id"]].sum() for _, b in rows]
    assert min(lit) == 0.0 and max(lit) > 0.0


@pytest.mark.jit
def test_rendered_sign_lines_send_the_same_light_filled_or_dotted():
    """End to end: the close-up's sign at 96 x 54 px (pitch ~0.6 px) rendered with its dots and as filled cells:
    each scan line's crop holds the same light (sum over pixels and bands of the radiance; by linearity, the
    intensity x solid-angle factor) within the Monte Carlo noise. Tolerances: 12 % per line and 4 % over the
    sign's 7 lines, about 3 standard deviations of the difference (light_spp 16 gave 1-15 % per line; 128 has
    1/sqrt(8) of that: 0-3 % per line, 0.5 % over the sign, measured 2026-11-26)."""
    sc, opts = _signs_far(96)
    opts = R.RenderOptions(**{**opts.to_dict(), "light_spp": 128, "frames": 1})
    opts_dots = R.RenderOptions(**{**opts.to_dict(), "dots_lod_px": 0.0})
    out = {}
    for name, o in (("fill", opts), ("dots", opts_dots)):
        fr = next(R.render_frames(sc, o))
        out[name] = {lid: float(b.sum()) for lid, _, b in fr["lights"]["otherlights"]}
    sign = [lt["id"] for lt in sc["lights"] if lt["kind"] == "message_sign"]
    for lid in sign:
        assert out["fill"][lid] == pytest.approx(out["dots"][lid], rel=0.12), lid
    tot = [sum(out[k][i] for i in sign) for k in ("fill", "dots")]
    assert tot[0] == pytest.approx(tot[1], rel=0.04)
