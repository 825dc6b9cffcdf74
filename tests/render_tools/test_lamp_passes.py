"""A flickering lamp's samples shared among the band passes by its spectrum (``RenderOptions.lamp_pass_spp``,
:func:`render_tools.render.lamp_pass_spp`, :class:`render_tools.tracer.Tile` ``pass_spp``): the counts follow the
spectrum, every band stays the unbiased mean of its pass, v1 scenes keep light_spp in every pass."""
from __future__ import annotations

import numpy as np
import pytest

from render_tools import camera, render, scene, spectra
from tests.data.render.data import HPS, LED
from tests.data.render.data import wall_scene as _wall_scene


def _passes_of(nm: float, opts) -> int:
    return int(np.argmin(np.abs(np.asarray(opts.bands_nm) - nm))) % camera.n_passes(len(opts.bands_nm))


def test_counts_follow_the_spectrum():
    """A red LED (630 nm): the pass holding 630 nm gets the cap (4 x light_spp), the bluest passes the floor
    (light_spp / 8); an HPS lamp (broad): light_spp in every pass; powers of two, never more than light_spp x P in
    all; light_spp not a power of two (unstratified samples): none."""
    opts = render.RenderOptions(light_spp=32)
    red = render.lamp_pass_spp({"spectrum": LED, "luminance_cd_m2": 800.0}, opts)
    assert len(red) == 8 and sum(red) <= 8 * 32 and all(n & (n - 1) == 0 for n in red)
    assert red[_passes_of(630.0, opts)] == 128 and min(red) == 4
    assert red[_passes_of(630.0, opts)] > red[_passes_of(450.0, opts)]
    broad = render.lamp_pass_spp({"spectrum": HPS, "luminance_cd_m2": 2e4}, opts)
    assert sum(broad) <= 256 and max(broad) <= 64 and min(broad) >= 4
    assert render.lamp_pass_spp({"spectrum": LED, "luminance_cd_m2": 800.0}, render.RenderOptions(light_spp=24)) \
        is None
    with pytest.raises(ValueError, match="lamp_pass_spp"):
        render.RenderOptions(lamp_pass_spp="by colour")


def _lamp_tiles(sc, opts):
    sets = {f"light:{lt['id']}": i for i, lt in enumerate(sc["lights"])}
    sets.update({f"group:{g}": 100 + i for i, g in enumerate(("headlights", "streetlights", "skymap"))})
    tiles, plan, _ = render.plan_frame(sc, opts, 0, sets)
    return [(p[0], tiles[p[4]]) for p in plan if p[4] is not None and p[0] in ("light", "light_part")]


def test_v1_scenes_keep_light_spp_in_every_pass():
    opts = render.RenderOptions(width=160, height=90, spp=2, light_spp=16, frames=1)
    v1 = scene.generate_scene(3, time_of_day="night")
    assert all(t.pass_spp is None for _, t in _lamp_tiles(v1, opts))
    assert "lamp_pass_spp" not in render.scene_meta(v1, opts)["render"]
    v2 = scene.generate_scene(101, time_of_day="night", generator=2, overrides={"weather": {"conditions": ["wet"]}})
    tiles = _lamp_tiles(v2, opts)
    assert any(t.pass_spp is not None for _, t in tiles)
    # a wet road's reflection bands (traced at spp) keep spp in every pass; the lamp's own box is shared out
    assert all(t.pass_spp is None for k, t in tiles if t.spp == opts.spp and k == "light_part")
    assert render.scene_meta(v2, opts)["render"]["lamp_pass_spp"] == "spectrum"
    uni = render.RenderOptions(width=160, height=90, spp=2, light_spp=16, frames=1, lamp_pass_spp="uniform")
    assert all(t.pass_spp is None for _, t in _lamp_tiles(v2, uni))


@pytest.mark.jit
@pytest.mark.parametrize("split", [False, True])
def test_every_band_stays_its_radiance(monkeypatch, split):
    """A red-LED panel filling the left of the view, its samples shared by spectrum (floor 2 of light_spp 16 in
    the blue passes, 64 in the red one): every band of the fully covered pixels is the panel's band radiance
    (W sr^-1 m^-2 nm^-1, within 2 % where it emits, as with light_spp in each pass). ``split``: launches cut to
    so few lanes that the tile is split by samples into parts some passes have no sample in (weight 0); a part
    then holds 1 sample of a thin pass, whose wavelengths lose their strata: the LED's edge bands (610, 650 nm,
    11 % of the peak) vary by 1.8 % per run (8 seeds, mean -0.6 %, 2026-11-26), so only the bands above 30 % of
    the peak are held to 2 % there; every band to 2 % of the peak."""
    from render_tools import tracer

    if split:
        monkeypatch.setattr(tracer, "MAX_LANES", 4000)
    s = _wall_scene()
    opts = render.RenderOptions(width=12, height=8, spp=1, light_spp=16, bins=2, frames=1, aux=False,
                                groups=("otherlights",), lamp_pass_spp="spectrum")
    assert min(render.lamp_pass_spp(s["lights"][0], opts)) == 2
    fr = next(render.render_frames(s, opts))
    (lid, bb, bins), = fr["lights"]["otherlights"]
    got = bins[:, :, :, : 6 - bb[1] - 1].mean((0, 2, 3))
    exp = spectra.band_means(spectra.absolute_spectrum(LED, 800.0), opts.bands_nm, opts.band_width_nm)
    peak = exp > (0.3 if split else 0.05) * exp.max()
    assert np.allclose(got[peak], exp[peak], rtol=0.02)
    assert np.abs(got - exp).max() < 0.02 * exp.max()


@pytest.mark.jit
def test_equal_counts_per_pass_render_the_old_tiles_bit_for_bit(monkeypatch):
    """Tiles that give every pass light_spp through the per-pass tables render exactly (bit for bit) what tiles
    without ``pass_spp`` render: the tables carry the same counts and weights to the same kernel, so a lamp's
    passes by spectrum change nothing but its counts (and lfmbench-v1, which never has them, renders as before)."""
    s = _wall_scene()
    base = dict(width=12, height=8, spp=1, light_spp=16, bins=2, frames=1, aux=False, groups=("otherlights",))
    old = next(render.render_frames(s, render.RenderOptions(**base, lamp_pass_spp="uniform")))
    monkeypatch.setattr(render, "lamp_pass_spp", lambda light, opts, n=None: (16,) * camera.n_passes(31))
    new = next(render.render_frames(s, render.RenderOptions(**base, lamp_pass_spp="spectrum")))
    (_, bb0, a), = old["lights"]["otherlights"]
    (_, bb1, b), = new["lights"]["otherlights"]
    assert bb0 == bb1 and np.array_equal(a, b)


# ----------------------------------------------------------------------------- pad ring at spp (pad_samples)
def test_ring_boxes_cover_the_outer_box_less_the_inner():
    outer, inner = (3, 5, 20, 30), (6, 9, 11, 27)
    boxes = render.ring_boxes(outer, inner)
    m = np.zeros((40, 40), int)
    for y0, x0, y1, x1 in boxes:
        m[y0:y1, x0:x1] += 1
    want = np.zeros((40, 40), int)
    want[3:20, 5:30] = 1
    want[6:11, 9:27] = 0
    np.testing.assert_array_equal(m, want)  # disjoint (no 2) and exactly the ring
    assert render.ring_boxes(outer, outer) == [] and render.ring_boxes(outer, None) == [outer]
    with pytest.raises(ValueError, match="pad_samples"):
        render.RenderOptions(pad_samples="ring")


def _plan(sc, opts):
    sets = {f"light:{lt['id']}": i for i, lt in enumerate(sc["lights"])}
    sets.update({f"group:{g}": 100 + i for i, g in enumerate(sc["groups"])})
    tiles, plan, _ = render.plan_frame(sc, opts, 0, sets)
    return tiles, plan


@pytest.mark.parametrize("weather", ["dry", "wet"])
def test_v2_lamps_trace_the_ring_at_spp_and_their_own_box_at_light_spp(weather):
    """Scene version 2 (pad_samples auto = spp): every visible flickering lamp's padded box is its unpadded box at
    light_spp plus the pad ring at spp (K bins, uniform passes), disjoint and covering it; version 1 keeps one crop
    at light_spp (pad_samples auto = light), and its meta does not name the option."""
    opts = render.RenderOptions(width=320, height=180, spp=1, light_spp=32, frames=1, bins=8)
    v2 = scene.generate_scene(101, time_of_day="night", generator=2, overrides={"weather": {"conditions": [weather]}})
    geo = render.SceneGeometry(v2, opts)
    tm = render.frame_timing(v2, opts, 0)
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    lights = {lt["id"]: lt for lt in v2["lights"]}
    tiles, plan = _plan(v2, opts)
    parts: dict = {}
    for kind, g, key, bb, ti, rep in plan:
        if kind == "light_part":
            parts.setdefault(key, []).append((bb, tiles[ti]))
        assert kind != "light" or tiles[ti].spp == 32  # a lamp with no pixel of ring left (clipped) keeps one crop
    assert len(parts) > 10
    n_ring = 0
    for lid, ps in parts.items():
        lt = lights[lid]
        padded = geo.light_bbox(lt, t_obj, *tm["window"], moving=True, reflection=False)
        inner = geo.light_bbox(lt, t_obj, *tm["window"], moving=True, reflection=False, pad=0)
        if padded is None:  # only the lamp's reflection is in view: its bands alone
            assert all(t.block > 1 for _, t in ps)
            continue
        m = np.zeros((opts.height, opts.width), int)
        for (y0, x0, y1, x1), t in ps:
            if t.block > 1:  # a wet road's reflection band (render_tools.reflections)
                continue
            m[y0:y1, x0:x1] += 1
            if (y0, x0, y1, x1) == inner:
                assert t.spp == 32 and t.bins == 8
            else:  # a ring strip: inside the padded box, outside the lamp's own
                n_ring += 1
                assert t.spp == 1 and t.pass_spp is None and t.bins == 8
                assert padded[0] <= y0 and padded[1] <= x0 and y1 <= padded[2] and x1 <= padded[3]
                assert y1 <= inner[0] or y0 >= inner[2] or x1 <= inner[1] or x0 >= inner[3]
        y0, x0, y1, x1 = padded
        assert m.max() == 1 and m[y0:y1, x0:x1].all() and m.sum() == (y1 - y0) * (x1 - x0)
    assert n_ring > 20
    assert render.scene_meta(v2, opts)["render"]["pad_samples"] == "spp"
    v1 = scene.generate_scene(101, time_of_day="night")
    _, plan1 = _plan(v1, opts)
    assert not any(p[0] in ("light_part", "light_box") for p in plan1)
    assert "pad_samples" not in render.scene_meta(v1, opts)["render"]


@pytest.mark.jit
def test_ring_at_spp_renders_the_same_light():
    """One flickering lamp over a dry road (scene version 2): its crop rendered with the ring at light_spp and at
    spp holds the same light (independent estimates: within 3 %), its own box too; the SteadyBins form of the
    ring-and-lamp crop (several varying parts) is the array bit for bit."""
    from lfmbench.corpus import SteadyBins

    sc = _lamp_over_road()
    base = dict(width=160, height=90, spp=4, light_spp=64, bins=4, frames=1, aux=False, seed=3)
    out = {}
    for pad in ("light", "spp"):
        (lid, bb, arr), = next(render.render_frames(sc, render.RenderOptions(**base, pad_samples=pad)))[
            "lights"]["otherlights"]
        out[pad] = (bb, arr)
    (bb1, a1), (bb2, a2) = out["light"], out["spp"]
    assert bb1 == bb2 and a1.sum() > 0
    assert a2.sum() == pytest.approx(a1.sum(), rel=0.03)
    opts = render.RenderOptions(**base, pad_samples="spp")
    geo = render.SceneGeometry(sc, opts)
    tm = render.frame_timing(sc, opts, 0)
    y0, x0, y1, x1 = geo.light_bbox(sc["lights"][0], 0.5 * sum(tm["window"]), *tm["window"], moving=True, pad=0)
    inner = (slice(None), slice(None), slice(y0 - bb1[0], y1 - bb1[0]), slice(x0 - bb1[1], x1 - bb1[1]))
    assert a2[inner].sum() == pytest.approx(a1[inner].sum(), rel=0.03)
    assert a2[inner].sum() > 0.9 * a2.sum()  # the ring holds little of the light
    (_, _, sb), = next(render.render_frames(sc, opts, steady_bins=True))["lights"]["otherlights"]
    assert isinstance(sb, SteadyBins)
    np.testing.assert_array_equal(np.asarray(sb), a2)


def _lamp_over_road():
    """test_reflections' lamp over a dry road, moving (scene version 2)."""
    sc = scene.empty_scene("ring", speed_mps=8.0, pitch_deg=-4.0)
    sc["version"] = 2
    sc["materials"]["road"] = {"type": "diffuse", "rgb": [0.09, 0.09, 0.095]}
    sc["objects"].append({"id": 0, "kind": "road", "velocity_mps": [0, 0, 0],
                          "parts": [{"shape": "box", "center": [50, 0, -0.05], "size": [120, 14, 0.1],
                                     "material": "road"}]})
    sc["lights"].append({"id": 0, "group": "otherlights", "kind": "tail", "instance": -1, "shape": "rect",
                         "center": [15.0, 0.0, 1.0], "normal": [-1, 0, 0], "size": [0.4, 0.2], "spread_deg": 90.0,
                         "spectrum": {"model": "led", "peak_nm": 630.0, "fwhm_nm": 18.0}, "luminance_cd_m2": 1000.0})
    return scene.validate_scene(sc)
