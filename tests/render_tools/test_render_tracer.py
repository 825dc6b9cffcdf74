"""The light-set tracer (render_tools.tracer) against Mitsuba's own path integrator and against exact answers.

The reference (render_tools.reference) is independent code: Mitsuba's C++ ``path`` integrator, its film and
sampler, the MotionCamera plugin, one Mitsuba scene per group with only that group's emitters (or one light
switched on by parameter updates). Both are unbiased estimates of the same image, so their means agree within
Monte Carlo error.
"""
from __future__ import annotations

import numpy as np
import pytest

from render_tools import reference, render, scene, tracer
from tests.data.render.data import HPS, LED, street as _street

@pytest.fixture(scope="module")
def street():
    s = _street()
    opts = render.RenderOptions(width=48, height=32, spp=32, light_spp=64, bins=4, frames=1, aux=False, seed=3)
    return s, opts, next(render.render_frames(s, opts))


@pytest.mark.jit
def test_static_group_matches_mitsuba_path_integrator(street):
    import mitsuba as mi

    from render_tools import mitsuba_scene as ms

    import drjit as dr

    s, opts, fr = street
    ref = reference.ReferenceRenderer(s, opts)
    tm = render.frame_timing(s, opts, 0)
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    sc = mi.load_dict(ms.mitsuba_dict(s, t_obj, emit="streetlights"))
    kernels = []
    for win in ("short", "long"):
        a, b = tm[win]
        dr.kernel_history()  # empties the history
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        try:
            want = ref.render(sc, a, b - a, 32, 11)[0]
            ks = [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]
        finally:
            dr.set_flag(dr.JitFlag.KernelHistory, False)
        kernels.append(max(ks, key=lambda k: k["operation_count"])["hash"])
        got = fr["static"]["streetlights"][win]
        # the directly seen lamp covers a few pixels partly (its pixel sums carry a few % of coverage noise);
        # the ground and wall it lights are smooth: compare them tightly, per band (the HPS spectrum's shape)
        lamp = want.sum(0) > 20 * np.median(want.sum(0))
        lamp = np.pad(lamp, 1)[:-2, 1:-1] | np.pad(lamp, 1)[2:, 1:-1] | np.pad(lamp, 1)[1:-1, :-2] | \
            np.pad(lamp, 1)[1:-1, 2:] | lamp
        assert 0 < lamp.sum() < 40
        gb, wb = got[:, ~lamp].sum(1), want[:, ~lamp].sum(1)
        assert gb.sum() == pytest.approx(wb.sum(), rel=0.02)
        big = wb > 0.05 * wb.max()
        assert np.allclose(gb[big], wb[big], rtol=0.05)
        assert got.sum() == pytest.approx(want.sum(), rel=0.1)
    # the window length is kernel data (camera.MotionCamera), not a literal: both windows ran one kernel
    assert kernels[0] == kernels[1], "the reference camera compiled a kernel per window length"


@pytest.mark.jit
def test_light_set_matches_solo_render_with_object_motion(street):
    import mitsuba as mi

    from render_tools import mitsuba_scene as ms

    s, opts, fr = street
    (lid, bb, bins), = fr["lights"]["otherlights"]
    assert lid == 0 and bins.shape[0] == 4
    ref = reference.ReferenceRenderer(s, opts)
    tm = render.frame_timing(s, opts, 0)
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    sc = mi.load_dict(ms.mitsuba_dict(s, t_obj, emit="otherlights"))
    ms.set_solo(mi.traverse(sc), s, "otherlights", 0, {})
    e = tm["bin_edges"]
    want = ref.render(sc, e[0], (e[-1] - e[0]) / 4, 64, 5, crop=bb, bins=4, velocity=ref.object_velocity(s["lights"][0]),
                      t_ref=t_obj)
    assert bins.sum() == pytest.approx(want.sum(), rel=0.03)
    for k in range(4):  # every bin, and where its light is (the lamp moves across the bins)
        assert bins[k].sum() == pytest.approx(want[k].sum(), rel=0.05)
        ys, xs = np.mgrid[0:bins.shape[2], 0:bins.shape[3]]
        g, w = bins[k].sum(0), want[k].sum(0)
        assert (g * xs).sum() / g.sum() == pytest.approx((w * xs).sum() / w.sum(), abs=0.2)


def _many_streetlights():
    """One group of six streetlights at 3-40 m, four with downward beams (spot cones of 50 deg), one facing
    away from everything (its selection weight is floored, never 0), over a grey ground and a glossy wall."""
    s = scene.empty_scene(speed_mps=0.0, fov_x_deg=60.0)
    s["materials"]["grey"] = {"type": "diffuse", "rgb": [0.4, 0.4, 0.4]}
    s["materials"]["gloss"] = {"type": "roughplastic", "rgb": [0.3, 0.3, 0.5], "alpha": 0.2}
    s["objects"].append({"id": 0, "kind": "ground", "velocity_mps": [0, 0, 0],
                         "parts": [{"shape": "rect", "center": [25, 0, 0], "size": [60, 30], "normal": [0, 0, 1],
                                    "material": "grey"},
                                   {"shape": "rect", "center": [20, -4, 2], "size": [40, 4], "normal": [0, 1, 0],
                                    "material": "gloss"}]})
    for i, (x, y, spread, normal) in enumerate([(3, 2, 50, [0, 0, -1]), (8, -2, 50, [0, 0, -1]), (15, 2, 90, [0, 0, -1]),
                                               (25, -2, 50, [0, 0, -1]), (40, 2, 50, [0, 0, -1]),
                                               (12, 3, 90, [0, 0, 1])]):
        s["lights"].append({"shape": "rect", "id": i, "group": "streetlights", "kind": "streetlight", "instance": -1,
                            "center": [x, y, 5.0], "normal": normal, "size": [0.4, 0.4], "spread_deg": float(spread),
                            "spectrum": HPS, "luminance_cd_m2": 5e4})
    return scene.validate_scene(s)


@pytest.mark.jit
def test_light_choice_by_estimated_contribution_is_unbiased():
    """Next-event estimation picks among many lamps in proportion to an estimate of their light at the point
    (distance, beam cone, face orientation): the image must equal Mitsuba's (uniform or flux-proportional
    choice; its own C++ path integrator) within Monte Carlo error, on the ground and on a glossy wall."""
    import mitsuba as mi

    from render_tools import mitsuba_scene as ms

    s = _many_streetlights()
    opts = render.RenderOptions(width=48, height=32, spp=32, bins=1, frames=1, aux=False, seed=4,
                                groups=("streetlights",))
    fr = next(render.render_frames(s, opts))
    ref = reference.ReferenceRenderer(s, opts)
    tm = render.frame_timing(s, opts, 0)
    sc = mi.load_dict(ms.mitsuba_dict(s, 0.5 * (tm["window"][0] + tm["window"][1]), emit="streetlights"))
    a, b = tm["long"]
    want = ref.render(sc, a, b - a, 64, 12)[0]
    got = fr["static"]["streetlights"]["long"]
    lamp = want.sum(0) > 20 * np.median(want.sum(0))  # lamp faces seen directly (pixel-coverage noise), grown
    for _ in range(2):
        lamp = lamp | np.pad(lamp, 1)[:-2, 1:-1] | np.pad(lamp, 1)[2:, 1:-1] | np.pad(lamp, 1)[1:-1, :-2] | \
            np.pad(lamp, 1)[1:-1, 2:]
    assert lamp.sum() < 150
    g2, w2 = np.where(lamp, 0, got.sum(0)), np.where(lamp, 0, want.sum(0))
    # the ground (lower half, lit by all six lamps at 3-40 m) tightly; the glossy wall's highlights of the lamps
    # are rare bright paths (+-15 % between seeds of either renderer), so the whole image loosely
    assert g2[16:].sum() == pytest.approx(w2[16:].sum(), rel=0.02)
    assert g2.sum() == pytest.approx(w2.sum(), rel=0.06)
    gblk, wblk = g2[16:].reshape(2, 8, 6, 8).sum((1, 3)), w2[16:].reshape(2, 8, 6, 8).sum((1, 3))
    big = wblk > 0.05 * wblk.max()
    assert big.sum() >= 8
    assert np.allclose(gblk[big], wblk[big], rtol=0.06)


@pytest.mark.jit
def test_union_of_static_groups_matches_mitsuba_per_group():
    """Static groups traced together (``static_pass="union"``: one camera path records every static group, one
    next-event estimation over all their lamps) give each group's own image: each equals Mitsuba's path
    integrator on a scene where only that group emits, and the per-group pass (an independent estimator of ours)."""
    import mitsuba as mi

    from render_tools import mitsuba_scene as ms

    s = _street()
    s["sky"] = {"model": "constant", "spectrum": {"model": "illuminant", "name": "D65"}, "luminance_cd_m2": 30.0}
    s = scene.validate_scene(s)
    opts = render.RenderOptions(width=48, height=32, spp=32, light_spp=32, bins=1, frames=1, aux=False, seed=5,
                                groups=("streetlights", "skymap"))
    assert render.static_union(render._selected_groups(s, opts), opts) == ["streetlights", "skymap"]
    fr = next(render.render_frames(s, opts))
    per = next(render.render_frames(s, render.RenderOptions(**{**opts.to_dict(), "static_pass": "per_group"})))
    ref = reference.ReferenceRenderer(s, opts)
    tm = render.frame_timing(s, opts, 0)
    a, b = tm["long"]
    for g in ("streetlights", "skymap"):
        sc = mi.load_dict(ms.mitsuba_dict(s, 0.5 * (tm["window"][0] + tm["window"][1]), emit=g))
        want = ref.render(sc, a, b - a, 32, 21)[0].sum(0)
        got, other = fr["static"][g]["long"].sum(0), per["static"][g]["long"].sum(0)
        assert want.sum() > 0
        lamp = want > 20 * np.median(want)  # the lamp face seen directly: pixel-coverage noise
        assert lamp.sum() < 40
        assert got[~lamp].sum() == pytest.approx(want[~lamp].sum(), rel=0.03)
        assert got[~lamp].sum() == pytest.approx(other[~lamp].sum(), rel=0.03)
        blk = lambda x: np.where(lamp, 0, x).reshape(4, 8, 6, 8).sum((1, 3))  # noqa: E731 - 8x8 px blocks
        big = blk(want) > 0.05 * blk(want).max()
        assert big.sum() >= 8 and np.allclose(blk(got)[big], blk(want)[big], rtol=0.08)
    # the union traced one path per sample for both groups: the sky image is not the per-group one
    assert not np.array_equal(fr["static"]["skymap"]["long"], per["static"]["skymap"]["long"])


def test_static_pass_is_checked():
    with pytest.raises(ValueError, match="static_pass"):
        render.RenderOptions(static_pass="together")


@pytest.mark.jit
def test_tiles_are_independent_of_the_other_tiles_in_the_launch(street):
    """A tile's random numbers depend on (seed, key, index in the tile) only: the same tile rendered alone, or
    after other tiles, or with another MAX_LANES split of the launch, is bit-identical."""
    import drjit as dr
    import mitsuba as mi

    from render_tools import mitsuba_scene as ms

    s, opts, _ = street
    geo = render.SceneGeometry(s, opts)
    loaded = mi.load_dict(ms.mitsuba_dict(s, 0.0, emit="all"))
    sets = tracer.LightSets(mi, dr, loaded, s, ["streetlights", "otherlights"])
    tr = tracer.Tracer(mi, dr, loaded, sets, geo.ego, geo.fov, (opts.width, opts.height), opts.bands_nm,
                       opts.band_width_nm)
    a = tracer.Tile((4, 4, 20, 30), 2, 0.0, 0.004, 4, sets["group:streetlights"], key=7)
    b = tracer.Tile((0, 0, 32, 48), 1, 0.0, 0.008, 2, sets["light:0"], key=9)
    alone = tr.render([a], 5)[0]
    both = tr.render([b, a], 5)[1]
    assert np.array_equal(alone, both) and alone.sum() > 0
    assert not np.array_equal(alone, tr.render([a], 6)[0])  # another seed, another estimate


@pytest.mark.jit
def test_bad_tile_is_refused_naming_it(street):
    import drjit as dr
    import mitsuba as mi

    from render_tools import mitsuba_scene as ms

    s, opts, _ = street
    geo = render.SceneGeometry(s, opts)
    loaded = mi.load_dict(ms.mitsuba_dict(s, 0.0, emit="all"))
    sets = tracer.LightSets(mi, dr, loaded, s, ["streetlights"])
    tr = tracer.Tracer(mi, dr, loaded, sets, geo.ego, geo.fov, (opts.width, opts.height), opts.bands_nm,
                       opts.band_width_nm)
    with pytest.raises(ValueError, match=r"tiles\[0\]"):
        tr.render([tracer.Tile((4, 4, 4, 30), 1, 0.0, 0.004, 4, 0)], 1)


@pytest.mark.parametrize("n", [1, 2, 5, 7, 10, 16, 32, 33, 64, 100])
def test_multijitter_count_is_what_mitsuba_uses_without_a_warning(n, capfd):
    import mitsuba as mi

    from render_tools import backend, camera

    if mi.variant() is None:
        backend.select_variant()
    k = camera.multijitter_count(n)
    assert k >= n
    assert mi.load_dict({"type": camera.DEFAULT_SAMPLER, "sample_count": n}).sample_count() == k
    capfd.readouterr()
    assert mi.load_dict({"type": camera.DEFAULT_SAMPLER, "sample_count": k}).sample_count() == k
    assert "rounded up" not in "".join(capfd.readouterr())


def _with_more_lights(s: dict, n: int) -> dict:
    """``s`` with ``n`` more streetlights along the street (another scene of the same kind and size class)."""
    s = {**s, "lights": list(s["lights"])}
    for i in range(n):
        s["lights"].append({"shape": "rect", "id": len(s["lights"]), "group": "streetlights", "kind": "streetlight",
                            "instance": -1, "center": [14.0 + 6 * i, 2.5, 5.0], "normal": [0, 0, -1],
                            "size": [0.4, 0.4], "spread_deg": 90.0, "spectrum": HPS, "luminance_cd_m2": 4e4})
    return scene.validate_scene(s)


def _frame_and_main_kernel(s: dict, opts) -> tuple[dict, dict]:
    """Render frame 0 of ``s``; returns it and the Dr.Jit kernel-history entry of its biggest kernel (the
    tracer's launch)."""
    import drjit as dr

    dr.kernel_history()  # empties the history
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        fr = next(render.render_frames(s, opts))
        ks = [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    return fr, max(ks, key=lambda k: k["operation_count"])


def _same_arrays(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same_arrays(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same_arrays(x, y) for x, y in zip(a, b))
    return np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b


@pytest.mark.parametrize("n", [0, 1, 63, 64, 65, 100, 300, 513])
@pytest.mark.parametrize("kind", ["shape", "emitter", "bsdf"])
def test_registry_class_is_the_next_power_of_two_from_the_kinds_floor(n, kind):
    c, lo = tracer.registry_class(n, kind), tracer.REGISTRY_CLASS_MIN[kind]
    assert c >= max(n, lo) and c & (c - 1) == 0 and (c == lo or c // 2 < n)


@pytest.mark.jit
def test_registry_padding_changes_no_pixel_and_a_new_scene_reuses_the_kernel(monkeypatch):
    """Padding the registry (tracer.pad_registry) with objects outside the scene leaves every image and map bit
    for bit as without it; a new scene with three more lights (other shape and emitter counts, same size class)
    then runs the same kernel (the same hash: a cache hit), which without the padding it does not (the mutation
    check). Hashes, not cache hits, are compared: ~/.drjit may hold the unpadded kernels of an earlier run."""
    opts = render.RenderOptions(width=32, height=24, spp=2, light_spp=8, bins=2, frames=1, seed=5)
    a, b = _street(), _with_more_lights(_street(), 3)
    fr_a, k_a = _frame_and_main_kernel(a, opts)
    _, k_b = _frame_and_main_kernel(b, opts)
    assert k_b["hash"] == k_a["hash"], "a new scene of the same size class compiled a new kernel"
    monkeypatch.setattr(tracer, "pad_registry", lambda *args: [])
    plain_a, k_plain_a = _frame_and_main_kernel(a, opts)
    assert _same_arrays(plain_a, fr_a) and plain_a["aux"] and plain_a["lights"]["otherlights"]
    _, k_plain_b = _frame_and_main_kernel(b, opts)
    assert k_plain_b["hash"] != k_plain_a["hash"]


@pytest.mark.jit
def test_glossy_light_choice_weights_follow_the_coat_lobe():
    """``glossy_light_choice``: at a point of a wet road's water film, a lamp's selection weight is multiplied by
    the coat's specular-to-diffuse ratio towards it, ``1 + c D(h) / (cos_i cos_o)`` with GGX D (Walter et al. 2007,
    eq. 33, written out here) and ``c = F0 pi eta^2 / (4 rho)``; a lamp far from the mirror direction keeps its
    weight (D ~ 0), and a point without a coat (alpha 0) gets the plain weights bit for bit."""
    from types import SimpleNamespace

    from render_tools import backend

    backend.select_variant()
    import drjit as dr
    import mitsuba as mi

    cam, p = np.array([0.0, 0.0, 1.5]), np.array([10.0, 0.0, 0.0])
    mirror = p + (p - cam) * np.array([1, 1, -1]) * 3.0  # on the mirror ray of the camera about the road
    aside = mirror + np.array([0.0, 25.0, 0.0])
    # rows of LightSets.geo: position, face normal (towards the point), beam cut-off (none), intensity
    rows = []
    for q in (mirror, aside):
        nrm = (p - q) / np.linalg.norm(p - q)
        rows.append([*q, *nrm, tracer.NO_BEAM, 1000.0])
    geo = np.asarray(rows, np.float32).T
    fake = SimpleNamespace(mi=mi, dr=dr, sets=SimpleNamespace(geo=[mi.Float(c) for c in geo]))
    wi = (cam - p) / np.linalg.norm(cam - p)
    P, N, WI = mi.Point3f(*[[v, v] for v in p]), mi.Vector3f([0, 0], [0, 0], [1, 1]), mi.Vector3f(*[[v, v] for v in wi])
    row = mi.UInt32([0, 1])
    plain = np.asarray(tracer.Tracer._lamp_weights(fake, row, P, N)[0])
    alpha, eta, rho = 0.05, 1.33, 0.05
    c = ((eta - 1) / (eta + 1)) ** 2 * np.pi * eta ** 2 / (4 * rho)
    got = np.asarray(tracer.Tracer._lamp_weights(fake, row, P, N, WI, (mi.Float(alpha), mi.Float(c)))[0])
    off = np.asarray(tracer.Tracer._lamp_weights(fake, row, P, N, WI, (mi.Float(0.0), mi.Float(c)))[0])
    np.testing.assert_array_equal(off, plain)
    for i, q in enumerate((mirror, aside)):
        wl = (q - p) / np.linalg.norm(q - p)
        h = (wi + wl) / np.linalg.norm(wi + wl)
        D = alpha ** 2 / (np.pi * (h[2] ** 2 * (alpha ** 2 - 1) + 1) ** 2)
        want = plain[i] * (1 + c * D / max(wi[2] * wl[2], tracer.GLOSS_COS_FLOOR))
        assert got[i] == pytest.approx(want, rel=1e-4)
    assert got[0] / plain[0] > 1e3 and got[1] / plain[1] < 1.1


@pytest.mark.jit
def test_glossy_choice_table_holds_every_coat_with_mitsubas_index_where_none_is_given():
    """Every ``roughplastic`` coat steers the light choice (glass, paint, lenses, not only a water film): a coat
    without ``ior`` gets Mitsuba's own default index (the loaded BSDF's eta, read back), one with ``ior`` its own;
    ``c = F0 pi eta^2 / (4 rho)``; diffuse materials are left out."""
    from render_tools import backend

    backend.select_variant()
    import drjit as dr
    import mitsuba as mi

    mats = {"glass": {"type": "roughplastic", "alpha": 0.05, "rgb": [0.02, 0.02, 0.02]},
            "film": {"type": "roughplastic", "alpha": 0.04, "ior": 1.33, "rgb": [0.1, 0.1, 0.1]},
            "wall": {"type": "diffuse", "rgb": [0.5, 0.5, 0.5]}}
    bsdfs = {"glass": mi.load_dict({"type": "roughplastic", "distribution": "ggx", "alpha": 0.05}),
             "film": mi.load_dict({"type": "roughplastic", "distribution": "ggx", "alpha": 0.04, "int_ior": 1.33}),
             "wall": mi.load_dict({"type": "diffuse"})}
    table = tracer.glossy_choice_table(mi, dr, bsdfs, mats)
    assert len(table) == 2  # both coats, not the wall
    eta_default = float(mi.traverse(bsdfs["glass"])["eta"][0])  # the plugin's int_ior / ext_ior
    for name, eta in (("glass", tracer.ROUGHPLASTIC_IOR), ("film", 1.33)):
        alpha, c = table[tracer.registry_id(mi, dr, mi.BSDFPtr, bsdfs[name])]
        rho = float(np.mean(mats[name]["rgb"]))
        assert alpha == mats[name]["alpha"]
        assert c == pytest.approx(((eta - 1) / (eta + 1)) ** 2 * np.pi * eta ** 2 / (4 * rho), rel=1e-6)
    assert eta_default == pytest.approx(tracer.ROUGHPLASTIC_IOR, rel=1e-3)  # 1.49 over air's 1.000277
