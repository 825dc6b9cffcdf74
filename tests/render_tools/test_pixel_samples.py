"""Where a pixel's samples lie in x, y and time (``RenderOptions.pixel_samples``, :class:`render_tools.tracer.Tile`
``sobol``): randomly shifted Sobol' points for scene version 2, per-dimension strata (frozen) for version 1.

Checked against independent answers: scipy's Sobol' generator (the same Joe-Kuo direction numbers), the net's
strata counted by brute force, uniformity over random shifts, the kernel's points equal to the numpy reference,
and a rendered moving lamp edge: both placements estimate the same light (unbiased), the Sobol' one with less
spread over seeds.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import qmc

from render_tools import mitsuba_scene, render, scene, spectra, tracer


def test_sobol_points_are_scipys_sequence():
    """Unshifted, point i is scipy's unscrambled Sobol' point (scipy enumerates in Gray-code order: its i-th
    point is the sequence's point i ^ (i >> 1)); 24 bits kept as the kernel's float32."""
    n = 256
    ref = qmc.Sobol(d=3, scramble=False).random(n)
    i = np.arange(n)
    got = tracer.sobol_points(i ^ (i >> 1), np.zeros(3, np.uint64))
    np.testing.assert_array_equal(got.T, np.floor(ref * 2 ** 24) / 2 ** 24)


@pytest.mark.parametrize("m", [1, 3, 5, 7])
def test_shifted_points_keep_the_nets_strata(m):
    """Any random digital shift: of the first 2^m points, each cell of every elementary grid of (x, y) (2^a x 2^b
    cells, a + b = m) holds exactly one, and each dimension alone (x, y, time) is stratified into 2^m."""
    rng = np.random.default_rng(m)
    n = 1 << m
    for _ in range(5):
        p = tracer.sobol_points(np.arange(n), rng.integers(0, 2 ** 32, 3, dtype=np.uint64))
        for a in range(m + 1):
            cells = np.floor(p[0] * 2 ** a).astype(int) * 2 ** (m - a) + np.floor(p[1] * 2 ** (m - a)).astype(int)
            assert np.array_equal(np.sort(cells), np.arange(n)), (m, a)
        for d in range(3):
            assert np.array_equal(np.sort(np.floor(p[d] * n).astype(int)), np.arange(n))


def test_each_pass_block_is_a_net():
    """The kernel gives sample s of band pass p the point p * nmax + s (nmax: the most samples of any of the tile's
    passes): a pass with n | nmax samples holds a block of n points starting at a multiple of n, stratified in
    each axis and in (x, y) as the sequence's first n points are; with equal counts the passes together hold the
    first P nmax points (the static frames: 8 passes x 1 sample, stratified over the pixel)."""
    rng = np.random.default_rng(7)
    nmax = 16
    for p in range(8):
        for n in (1, 4, 16):
            pts = tracer.sobol_points(p * nmax + np.arange(n), rng.integers(0, 2 ** 32, 3, dtype=np.uint64))
            for d in range(3):
                assert np.array_equal(np.sort(np.floor(pts[d] * n).astype(int)), np.arange(n)), (p, n, d)
    every = tracer.sobol_points(np.arange(8) * 1, rng.integers(0, 2 ** 32, 3, dtype=np.uint64))  # nmax 1
    for a in range(4):
        cells = np.floor(every[0] * 2 ** a).astype(int) * 2 ** (3 - a) + np.floor(every[1] * 2 ** (3 - a)).astype(int)
        assert np.array_equal(np.sort(cells), np.arange(8))


def test_shifted_points_are_uniform():
    """Over random shifts each point is uniform on [0, 1): mean 1/2, variance 1/12 and a flat histogram
    (binomial bounds, 5 standard deviations) for a few point indices."""
    rng = np.random.default_rng(0)
    trials = 20000
    for idx in (0, 1, 5, 37):
        p = tracer.sobol_points(np.full(trials, idx), rng.integers(0, 2 ** 32, (3, trials), dtype=np.uint64))
        for d in range(3):
            assert abs(p[d].mean() - 0.5) < 5 * np.sqrt(1 / 12 / trials)
            assert abs(p[d].var() - 1 / 12) < 5 * np.sqrt(1 / 180 / trials)
            h = np.histogram(p[d], bins=10, range=(0, 1))[0]
            assert np.all(np.abs(h - trials / 10) < 5 * np.sqrt(trials * 0.09))


def test_version_1_keeps_strata_version_2_takes_sobol():
    opts = render.RenderOptions(width=160, height=90, spp=1, light_spp=16, frames=1)
    sets = type("Sets", (dict,), {"__missing__": lambda self, k: 0, "union": []})()
    v1 = scene.generate_scene(3, time_of_day="night")
    v2 = scene.generate_scene(101, time_of_day="night", generator=2)
    assert not any(t.sobol for t in render.plan_frame(v1, opts, 0, sets)[0])
    assert all(t.sobol for t in render.plan_frame(v2, opts, 0, sets)[0])
    strata = render.RenderOptions(width=160, height=90, spp=1, light_spp=16, frames=1, pixel_samples="strata")
    assert not any(t.sobol for t in render.plan_frame(v2, strata, 0, sets)[0])
    assert render.scene_meta(v2, opts)["render"]["pixel_samples"] == "sobol"
    assert "pixel_samples" not in render.scene_meta(v1, opts)["render"]
    with pytest.raises(ValueError, match="pixel_samples"):
        render.RenderOptions(pixel_samples="halton")
    with pytest.raises(ValueError, match="filled_spp_factor"):
        render.RenderOptions(filled_spp_factor=3)


@pytest.mark.jit
def test_kernel_points_equal_the_reference():
    import drjit as dr
    import mitsuba as mi

    from render_tools import backend

    if mi.variant() is None:
        backend.select_variant()
    rng = np.random.default_rng(4)
    idx = rng.integers(0, 1 << tracer.SOBOL_BITS, 4096).astype(np.uint32)
    sh = rng.integers(0, 2 ** 32, (3, 4096), dtype=np.uint64)
    ref = tracer.sobol_points(idx, sh)
    for d in range(3):
        got = tracer._sobol_dim(mi.UInt32(idx), mi.UInt32(sh[d].astype(np.uint32)), d)
        dr.eval(got)
        np.testing.assert_array_equal(np.asarray(got, dtype=np.float64), ref[d])


def _edge_scene():
    """A lit rectangle (a lamp on a building) whose edges cross pixels while the camera drives by at 30 m/s: at
    64 x 36 px the lamp's box is a few pixels, every one of them on a moving edge. Only the lamp, the object that
    carries it and that object's materials are kept: the street's other objects add nothing to the lamp's box but
    a load of their meshes and BSDFs to each of the 12 renders (2/3 of the test's time)."""
    sc = scene.generate_scene(7, time_of_day="night", generator=2)
    lamp = next(lt for lt in sc["lights"] if lt["shape"] == "rect" and lt["group"] == "otherlights")
    host = next(o for o in sc["objects"] if o["id"] == lamp["instance"])
    used = {p["material"] for p in host["parts"]}
    return scene.validate_scene({**sc, "lights": [{**lamp, "instance": 0}], "objects": [{**host, "id": 0}],
                                 "materials": {k: v for k, v in sc["materials"].items() if k in used}}), lamp["id"]


@pytest.mark.jit
def test_moving_edge_same_light_less_spread():
    """The lamp's bins summed over its box (the light it sends) from 6 seeds with each placement: the means agree
    within 4 standard errors (both unbiased), and the Sobol' points' spread per pixel is below 0.85 of the
    strata's (numpy model of such edges in docs/benchmarks/render.md "Pixel samples": 0.5-0.7)."""
    sc, lid = _edge_scene()
    res = {}
    for mode in ("strata", "sobol"):
        px = []
        for seed in range(6):
            o = render.RenderOptions(width=64, height=36, spp=1, light_spp=16, bins=4, frames=1, seed=seed,
                                     groups=("otherlights",), aux=False, pixel_samples=mode,
                                     dots_coverage="traced")  # a small rect: its exact coverage takes no sample
            fr = next(render.render_frames(sc, o))
            [(i, _, b)] = [x for x in fr["lights"]["otherlights"] if x[0] == lid]
            px.append(b.sum(axis=1))  # (K, h, w): each bin's pixels, bands summed
        res[mode] = np.stack(px)
    tot = {m: r.sum(axis=(1, 2, 3)) for m, r in res.items()}
    se = np.sqrt(tot["strata"].var(ddof=1) / 6 + tot["sobol"].var(ddof=1) / 6)
    assert abs(tot["strata"].mean() - tot["sobol"].mean()) < 4 * se + 1e-6 * tot["strata"].mean()
    spread = {m: float(np.sqrt(r.var(axis=0, ddof=1).sum())) for m, r in res.items()}
    assert spread["sobol"] < 0.85 * spread["strata"], spread


# ------------------------------------------------------------------------------------ reflection blocks
def test_wet_reflection_bands_are_traced_in_blocks():
    """Plan: a wet scene's reflection bands (traced at spp) get block 2, lamps' own boxes block 1; 1 turns it off;
    a dry scene has no block tile; meta.json records it for wet scenes."""
    # the lamps' pad rings (also at spp on scene version 2, block 1) left at light_spp: the bands alone at spp
    opts = render.RenderOptions(width=160, height=90, spp=1, light_spp=16, frames=1, pad_samples="light")
    sets = type("Sets", (dict,), {"__missing__": lambda self, k: 0, "union": []})()
    wet = scene.generate_scene(101, time_of_day="night", generator=2, overrides={"weather": {"conditions": ["wet"]}})
    tiles, plan, _ = render.plan_frame(wet, opts, 0, sets)
    refl = [tiles[p[4]] for p in plan if p[0] == "light_part" and tiles[p[4]].spp == opts.spp]
    assert refl and all(t.block == tracer.BLOCK for t in refl)
    assert all(t.block == 1 for t in tiles if t not in refl)
    one = render.RenderOptions(width=160, height=90, spp=1, light_spp=16, frames=1, reflection_block_px=1)
    assert all(t.block == 1 for t in render.plan_frame(wet, one, 0, sets)[0])
    dry = scene.generate_scene(101, time_of_day="night", generator=2, overrides={"weather": {"conditions": ["dry"]}})
    assert all(t.block == 1 for t in render.plan_frame(dry, opts, 0, sets)[0])
    assert render.scene_meta(wet, opts)["render"]["reflection_block_px"] == 2
    assert "reflection_block_px" not in render.scene_meta(dry, opts)["render"]
    with pytest.raises(ValueError, match="reflection_block_px"):
        render.RenderOptions(reflection_block_px=3)


@pytest.mark.jit
def test_block_tile_is_the_box_average_of_the_pixels():
    """A tile traced in 2 x 2 blocks (crop of odd width and height, so edge blocks are 1 px wide or tall) against
    the same tile per pixel, both at high spp: each block holds one value, the block tile's light summed over the
    crop equals the per-pixel tile's within 2 % (both unbiased for it: 3 standard deviations of the sum at these
    spp), and each block's value is the per-pixel tile's mean over the block within 10 % where it is lit."""
    import drjit as dr
    import mitsuba as mi

    from render_tools import backend
    from render_tools import mitsuba_scene as ms
    from tests.data.render.data import street

    if mi.variant() is None:
        backend.select_variant()
    s = street()
    opts = render.RenderOptions(width=48, height=32, spp=1, light_spp=16, bins=1, frames=1, aux=False)
    geo = render.SceneGeometry(s, opts)
    loaded = mi.load_dict(ms.mitsuba_dict(s, 0.0, emit="all"))
    sets = tracer.LightSets(mi, dr, loaded, s, ["streetlights"])
    tr = tracer.Tracer(mi, dr, loaded, sets, geo.ego, geo.fov, (opts.width, opts.height), opts.bands_nm,
                       opts.band_width_nm)
    crop = (11, 6, 26, 31)  # 15 x 25 px
    per_px, blocks = (tr.render([tracer.Tile(crop, 1, 0.0, 0.004, 256, sets["group:streetlights"], key=3,
                                             block=b)], 5)[0][0].sum(axis=0) for b in (1, tracer.BLOCK))
    h, w = per_px.shape
    for y in range(0, h, 2):
        for x in range(0, w, 2):
            blk = blocks[y:y + 2, x:x + 2]
            assert np.all(blk == blk.flat[0])
            want = per_px[y:y + 2, x:x + 2].mean()
            if want > 0.2 * per_px.max():
                assert blk.flat[0] == pytest.approx(want, rel=0.10), (y, x)
    assert blocks.sum() == pytest.approx(per_px.sum(), rel=0.02)



def test_dots_spp_factor_multiplies_only_sub_pixel_dots_drawn_as_they_are():
    """``dots_spp_factor`` gives light_spp x that factor to the own boxes of the lights whose dots are under a pixel
    and drawn as they are; lamps with larger dots (or no dots) keep light_spp, and meta.json records the factor
    only when it is not 1 (today's bytes)."""
    sc = scene.generate_scene(101, time_of_day="night", generator=2)
    keep = {"message_sign", "signal", "tail", "indicator"}  # sub-pixel dots, larger dots, no dots (a rectangle)
    sc["lights"] = [{**lt, "id": i} for i, lt in enumerate(lt for lt in sc["lights"] if lt["kind"] in keep)]
    sets = type("Sets", (dict,), {"__missing__": lambda self, k: 0, "union": []})()
    kw = dict(width=160, height=90, spp=1, light_spp=16, frames=1, groups=("signals", "otherlights"),
              pad_samples="light", dots_lod_px=0.0, dots_coverage="traced")
    base, more = render.RenderOptions(**kw), render.RenderOptions(**kw, dots_spp_factor=4)
    dense = frozenset(render.dense_dots(sc, more))
    assert render.dense_dots(sc, base) == []
    geo = render.SceneGeometry(sc, more)
    times = np.linspace(*render.frame_timing(sc, more, 0)["window"], render.BBOX_TIME_SAMPLES)
    pitch = {lt["id"]: geo.dots_pitch_px(lt, times) for lt in sc["lights"] if lt["shape"] == "dots"}
    assert dense == {i for i, p in pitch.items() if p < 1.0}
    own = []
    for o, d in ((base, frozenset()), (more, dense)):
        tiles, plan, _ = render.plan_frame(sc, o, 0, sets, dense=d)
        own.append({p[2]: tiles[p[4]].spp for p in plan if p[0] == "light"})
    assert own[0].keys() == own[1].keys() and all(v == 16 for v in own[0].values())
    assert {i for i, v in own[1].items() if v == 64} == dense & own[1].keys() != set()
    assert set(own[1].values()) == {16, 64}  # lamps with dots over a pixel, or no dots, keep 16
    assert not {"dots_spp_factor", "dots_coverage"} & render.scene_meta(sc, base)["render"].keys()
    with pytest.raises(ValueError, match="dots_spp_factor"):
        render.RenderOptions(dots_spp_factor=3)
    # dots_coverage exact: the same sub-pixel dot faces get no tile (exact_face makes their own box), the others
    # keep theirs, and no light is both exact and drawn with more samples
    ex = render.RenderOptions(**{**kw, "dots_coverage": "exact"}, dots_spp_factor=4)
    exact = frozenset(render.exact_faces(sc, ex))
    assert exact >= dense and render.dense_dots(sc, ex) == []
    tiles, plan, _ = render.plan_frame(sc, ex, 0, sets, exact=exact)
    marked = {p[2] for p in plan if isinstance(p[4], tuple)}
    assert marked == exact & own[1].keys() and all(p[4] == ("exact", p[2]) for p in plan if p[2] in marked)
    assert len(tiles) == len(plan) - len(marked)
    meta = render.scene_meta(sc, ex)["render"]
    assert meta["dots_coverage"] == "exact" and meta["dots_exact"] == sorted(exact) and meta["dots_spp_factor"] == 4
    # auto (the default): exact on scene version 2, traced on version 1 (its renders are frozen)
    auto = render.RenderOptions(**{**kw, "dots_coverage": "auto"})
    assert render.exact_faces(sc, auto) == sorted(exact) and render.RenderOptions().dots_coverage == "auto"
    assert not render.exact_coverage({**sc, "version": 1}, auto)
    with pytest.raises(ValueError, match="dots_coverage"):
        render.RenderOptions(dots_coverage="analytic")


def test_shared_exact_faces_pitches_and_band_means_equal_recomputation():
    """What one render now computes once (:func:`render.drawn_faces`: the exact faces with the dot pitches shared
    by both thresholds; :func:`render.light_bands`: a lamp's band means) equals computing it anew, and the
    drawn (filled) scene has the same exact faces as the scene."""
    sc = scene.generate_scene(101, time_of_day="night", generator=2)
    kinds: dict = {}  # at most 3 lamps of each kind: sub-pixel dots, larger dots, rectangles
    sc["lights"] = [{**lt, "id": i} for i, lt in enumerate(
        lt for lt in sc["lights"] if lt["kind"] in {"message_sign", "signal", "tail", "indicator", "countdown"}
        and kinds.setdefault(lt["kind"], []).append(1) is None and len(kinds[lt["kind"]]) <= 3)]
    opts = render.RenderOptions(width=160, height=90, frames=1, groups=("signals", "otherlights"))
    drawn, lod, _geo, exact = render.drawn_faces(sc, opts)
    assert exact == render.exact_faces(sc, opts) == render.exact_faces(drawn, opts) != []
    assert (drawn, lod) == render.dots_lod(sc, opts)
    assert render.dots_pitches(sc, opts) == render.dots_pitches(drawn, opts)
    assert render.scene_meta(sc, opts)["render"]["dots_exact"] == exact
    traced = render.RenderOptions(width=160, height=90, frames=1, dots_coverage="traced")  # sub-pixel dots filled
    d1, lod1, _g, ex1 = render.drawn_faces(sc, traced)
    assert (d1, lod1) == render.dots_lod(sc, traced) and lod1 != [] and ex1 == []
    more = render.RenderOptions(width=160, height=90, frames=1, dots_spp_factor=4, dots_lod_px=0.0,
                                dots_coverage="traced")
    d2, lod2, _g, ex2 = render.drawn_faces(sc, more)
    assert render.dense_dots(d2, more, lod2, ex2) == render.dense_dots(d2, more, lod2) != []
    for lt in sc["lights"][:6]:
        want = spectra.band_means(mitsuba_scene.light_spectrum(lt), opts.bands_nm, opts.band_width_nm)
        got = render.light_bands(lt, opts)
        assert got.tobytes() == np.asarray(want).tobytes() and render.light_bands(dict(lt), opts) is got
        assert not got.flags.writeable
