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
