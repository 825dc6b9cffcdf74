"""Scene generator, scene schema, spectra, camera geometry, options and metadata (no rendering)."""
from __future__ import annotations

import copy
import json
import math
import os
import warnings

import numpy as np
import pytest

from render_tools import backend, camera, mitsuba_scene, render, scene, spectra, spectra_table


@pytest.fixture(scope="module")
def night():
    return scene.generate_scene(3, "night")


# ------------------------------------------------------------------------------------------------ spectra
@pytest.mark.parametrize("spec", [{"model": "led", "peak_nm": 630.0, "fwhm_nm": 18.0},
                                  {"model": "light_source", "name": "HPS"},
                                  {"model": "illuminant", "name": "LED-B3"},
                                  {"model": "daylight", "cct_k": 6500.0}])
def test_absolute_spectrum_has_target_luminance_per_colour_science(spec):
    import colour

    L = spectra.absolute_spectrum(spec, 1234.0)
    # independent check: colour-science's own photometry (683 lm/W x sum L V dlambda) on the 1 nm grid
    sd = colour.SpectralDistribution(dict(zip(spectra.wavelengths(), L)))
    assert colour.luminous_flux(sd) == pytest.approx(1234.0, rel=2e-3)
    assert np.all(L >= 0)


def test_led_peak_and_band_means():
    L = spectra.absolute_spectrum({"model": "led", "peak_nm": 590.0, "fwhm_nm": 15.0}, 100.0)
    assert spectra.wavelengths()[np.argmax(L)] == pytest.approx(590.0)
    bands = np.arange(400.0, 701.0, 10.0)
    bm = spectra.band_means(L, bands, 10.0)
    assert bands[np.argmax(bm)] == 590.0
    # a flat spectrum has band means equal to its value
    assert np.allclose(spectra.band_means(np.full(spectra.wavelengths().shape, 2.5), bands, 10.0), 2.5)


def test_spectrum_validation_names_field():
    with pytest.raises(ValueError, match=r"lamp\.peak_nm"):
        spectra.validate_spectrum({"model": "led", "peak_nm": 100.0, "fwhm_nm": 10.0}, "lamp")
    with pytest.raises(ValueError, match=r"x\.name"):
        spectra.validate_spectrum({"model": "light_source", "name": "Candle of Doom"}, "x")
    with pytest.raises(ValueError, match=r"luminance_cd_m2"):
        spectra.absolute_spectrum({"model": "daylight", "cct_k": 6500.0}, -1.0)


def test_spectra_table_equals_colour_science():
    """The precomputed table (render_tools/data/spectra_1nm.csv) holds exactly what colour-science computes."""
    table = spectra._table()
    specs = spectra_table.table_spectra()
    assert len(specs) >= 8  # 3 LEDs, YAG, HPS, LPS, LED-B3 of the generator's config, D65 of empty_scene
    for spec in specs:
        np.testing.assert_allclose(table[spectra.spectrum_key(spec)], spectra.relative_spectrum_colour(spec),
                                   rtol=1e-14, atol=1e-300, err_msg=spectra.spectrum_key(spec))
    np.testing.assert_allclose(np.stack([table[c] for c in spectra.CMF_COLUMNS], -1), spectra._cmfs_colour(),
                               rtol=1e-14, atol=1e-300)


def test_spectra_outside_the_table_come_from_colour_science(monkeypatch):
    other = [{"model": "led", "peak_nm": 600.0, "fwhm_nm": 20.0}, {"model": "illuminant", "name": "HP1"},
             {"model": "daylight", "cct_k": 6500.0}]
    for spec in other:
        assert spectra.spectrum_key(spec) not in spectra._table()
        np.testing.assert_array_equal(spectra.relative_spectrum(spec), spectra.relative_spectrum_colour(spec))
    # no table at all (a missing or broken file): every spectrum from colour-science, same numbers
    hps = {"model": "light_source", "name": "HPS"}
    with_table = spectra.absolute_spectrum(hps, 50.0)
    monkeypatch.setattr(spectra, "TABLE_FILE", spectra.TABLE_FILE.with_name("missing.csv"))
    spectra._table.cache_clear()
    spectra._xyz_bar.cache_clear()
    try:
        assert spectra._table() == {}
        np.testing.assert_allclose(spectra.absolute_spectrum(hps, 50.0), with_table, rtol=1e-14)
        with pytest.raises(ValueError, match=r"x\.name"):
            spectra.validate_spectrum({"model": "illuminant", "name": "HPS"}, "x")  # a light source, not a CIE illuminant
    finally:
        monkeypatch.undo()
        spectra._table.cache_clear()
        spectra._xyz_bar.cache_clear()


def test_scene_generation_and_spectra_do_not_import_colour_science():
    """colour-science costs 2-3 s to import; a generated scene's spectra come from the table alone."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from render_tools import render, scene, spectra\n"
            "for seed in (101, 202):\n"
            "    s = scene.generate_scene(seed)\n"
            "    render.scene_meta(s, render.RenderOptions(width=32, height=18))\n"
            "    [spectra.absolute_spectrum(lt['spectrum'], lt['luminance_cd_m2']) for lt in s['lights']]\n"
            "    spectra.absolute_spectrum(scene.empty_scene()['sky']['spectrum'], 1.0)\n"
            "assert 'colour' not in sys.modules, 'colour was imported'\n")
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # this checkout's render_tools
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root)
    assert r.returncode == 0, r.stderr[-2000:]


def test_xyz_of_flat_band_image_matches_cmf_integral():
    bands = np.arange(400.0, 701.0, 10.0)
    img = np.full((31, 2, 3), 0.01)
    xyz = spectra.spectral_to_xyz(img, bands, 10.0)
    # Y = 683 * 0.01 * integral of ybar over 395..705 nm (~106.8 nm for the CIE 1931 observer)
    assert 683 * 0.01 * 100 < xyz[1, 0, 0] < 683 * 0.01 * 110
    assert np.allclose(xyz[:, 0, 0], xyz[:, 1, 2])


# ------------------------------------------------------------------------------------------------- scenes
def test_generator_is_deterministic_and_json_roundtrips(tmp_path, night):
    again = scene.generate_scene(3, "night")
    assert json.dumps(night, sort_keys=True) == json.dumps(again, sort_keys=True)
    p = tmp_path / "s.json"
    scene.save_scene(night, p)
    assert scene.load_scene(p) == night
    assert scene.generate_scene(4, "night") != night


@pytest.mark.parametrize("tod", scene.TIMES_OF_DAY)
def test_generated_scene_has_a_street(tod):
    s = scene.generate_scene(11, tod)
    kinds = [o["kind"] for o in s["objects"]]
    for k in ("road", "marking", "sidewalk", "building", "car", "signal_pole", "streetlight_pole"):
        assert k in kinds, k
    cars = [o for o in s["objects"] if o["kind"] in ("car", "truck", "motorcycle")]
    assert all(len(o["parts"]) >= 4 for o in cars)  # bodies, cabins, wheels: not single boxes
    groups = scene.scene_groups(s)
    assert "signals" in groups and groups["signals"]["flicker"]
    assert "skymap" in groups
    if tod == "day":
        assert "streetlights" not in groups  # streetlights off by day: group left out
    else:
        assert "streetlights" in groups and "otherlights" in groups
        tails = [lt for lt in s["lights"] if lt["kind"] == "tail"]
        assert tails and all(lt["spectrum"]["peak_nm"] == 630.0 for lt in tails)
    heads = [lt for lt in s["lights"] if lt["group"] == "headlights"]
    for lt in heads:
        assert 2e4 <= lt["luminance_cd_m2"] <= 2e5 and 7.5 <= lt["spread_deg"] <= 22.5
    assert 0.003 <= s["timing"]["short_exposure_s"] <= 0.005
    assert 20.0 <= s["camera"]["speed_mps"] <= 50.0


def test_other_lights_in_upstream_ratio_range():
    s = scene.generate_scene(5, "night")
    cfg = scene.load_config()
    lo, hi = cfg["lights"]["headlight_luminance_cd_m2"]
    for lt in s["lights"]:
        if lt["group"] == "otherlights":
            assert 4e-4 * lo * 0.999 <= lt["luminance_cd_m2"] <= 1e-2 * hi * 1.001


@pytest.mark.parametrize("path,value,match", [
    (("camera", "speed_mps"), -3.0, r"scene\.camera\.speed_mps"),
    (("camera", "wings"), 2, r"unknown field 'scene\.camera\.wings'"),
    (("timing", "short_exposure_s"), 0.0, r"scene\.timing\.short_exposure_s"),
    (("lights", 0, "luminance_cd_m2"), float("nan"), r"scene\.lights\[0\]\.luminance_cd_m2"),
    (("lights", 0, "group"), "disco", r"scene\.lights\[0\]\.group"),
    (("objects", 2, "parts", 0, "material"), "unobtainium", r"scene\.objects\[2\]\.parts\[0\]\.material"),
    (("objects", 2, "parts", 0, "size"), [1.0, -1.0, 1.0], r"scene\.objects\[2\]\.parts\[0\]\.size"),
    (("groups", "skymap", "flicker"), True, r"scene\.groups\.skymap\.flicker"),
    (("sky", "model"), "hdri", r"scene\.sky\.model"),
])
def test_bad_scene_fields_raise_naming_the_field(night, path, value, match):
    s = copy.deepcopy(night)
    d = s
    for k in path[:-1]:
        d = d[k]
    d[path[-1]] = value
    with pytest.raises(ValueError, match=match):
        scene.validate_scene(s)


def test_load_scene_error_names_file(tmp_path):
    p = tmp_path / "broken.json"
    p.write_text("{not json")
    with pytest.raises(ValueError, match="broken.json"):
        scene.load_scene(p)


def test_config_and_seed_errors(tmp_path):
    p = tmp_path / "cfg.yaml"
    p.write_text("camera: {}\n")
    with pytest.raises(ValueError, match="cfg.yaml"):
        scene.load_config(p)
    with pytest.raises(ValueError, match="seed"):
        scene.generate_scene(-1)
    with pytest.raises(ValueError, match="time_of_day"):
        scene.generate_scene(1, "noon")


def test_part_meshes_are_closed_and_outward():
    parts = [{"shape": "box", "center": [1, 2, 3], "size": [2, 4, 6], "yaw_deg": 30.0, "material": "m"},
             {"shape": "cylinder", "p0": [0, 0, 0], "p1": [0, 1, 0], "radius": 0.5, "material": "m"},
             {"shape": "sphere", "center": [0, 0, 0], "radius": 2.0, "material": "m"}]
    exact = [48.0, math.pi * 0.25, 4 / 3 * math.pi * 8]
    for part, vol in zip(parts, exact):
        V, F = mitsuba_scene.part_mesh(part)
        tri = V[F]
        # divergence theorem: signed volume > 0 iff faces wind outward; close to the analytic volume
        signed = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
        assert signed == pytest.approx(vol, rel=0.1)
    V, F = mitsuba_scene.part_mesh({"shape": "rect", "center": [0, 0, 0], "size": [2, 1], "normal": [-1, 0, 0]})
    n = np.cross(V[F[0, 1]] - V[F[0, 0]], V[F[0, 2]] - V[F[0, 0]])
    assert n @ np.array([-1, 0, 0]) > 0


# -------------------------------------------------------------------------------------- camera and timing
def test_ctrv_pose_is_the_integral_of_the_velocity():
    ego = camera.EgoMotion(p0=(1.0, 2.0, 1.4), yaw0_rad=0.3, speed_mps=30.0, yaw_rate_rad_s=0.5)
    t = np.linspace(0, 0.2, 20001)
    psi = 0.3 + 0.5 * t
    vel = 30.0 * np.stack([np.cos(psi), np.sin(psi)], -1)
    steps = (vel[1:] + vel[:-1]) / 2 * np.diff(t)[:, None]  # trapezoid rule
    num = np.array([1.0, 2.0]) + np.concatenate([[[0, 0]], np.cumsum(steps, 0)])
    assert np.allclose(ego.position(t)[:, :2], num, atol=1e-6)
    R = ego.pose_cv(0.1)[:3, :3]
    assert np.allclose(R.T @ R, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    # optical axis (OpenCV +z) points along the heading
    assert np.allclose(R[:, 2], [math.cos(0.35), math.sin(0.35), 0.0])


def test_projection_of_a_point_on_the_axis_hits_the_principal_point():
    ego = camera.EgoMotion(p0=(0.0, 0.0, 1.4))
    K = camera.intrinsics(640, 360, 40.0)
    uv, z = camera.project(np.array([[10.0, 0.0, 1.4], [10.0, 10 * math.tan(math.radians(20)), 1.4]]),
                           ego.pose_cv(0.0), K)
    assert np.allclose(uv[0], [320, 180]) and z[0] == pytest.approx(10.0)
    assert uv[1, 0] == pytest.approx(0.0, abs=1e-9)  # a point 20 deg to the left lies on the left edge


def test_options_and_timing_validation():
    with pytest.raises(ValueError, match="long_exposure_s"):
        render.RenderOptions(long_exposure_s=0.02)  # longer than 1/60 s
    with pytest.raises(ValueError, match="bins"):
        render.RenderOptions(bins=0)
    with pytest.raises(ValueError, match="bands_nm"):
        render.RenderOptions(bands_nm=(350.0, 360.0))
    with pytest.raises(ValueError, match="groups"):
        render.RenderOptions(groups=("partylights",))
    s = scene.empty_scene(short_exposure_s=0.02)
    with pytest.raises(ValueError, match="short_exposure_s"):
        render.frame_timing(s, render.RenderOptions(), 0)
    opts = render.RenderOptions(height=360, bins=8)
    tm = render.frame_timing(scene.empty_scene(short_exposure_s=0.004), opts, 2)
    t0 = 2 / 60
    assert tm["long"] == pytest.approx((t0, t0 + 1 / 90))
    assert np.mean(tm["short"]) == pytest.approx(np.mean(tm["long"]))  # centre-aligned
    assert tm["bin_edges"][0] == pytest.approx(t0) and tm["bin_edges"][-1] == pytest.approx(t0 + 1 / 90 + 360e-5)


def test_scene_meta_content(night):
    opts = render.RenderOptions(width=320, height=180, frames=3)
    meta = render.scene_meta(night, opts)
    assert meta["timing"]["readout_s"] == pytest.approx(180 * 10e-6)
    assert meta["timing"]["alignment"] == "center"
    assert set(meta["groups"]) == set(scene.scene_groups(night))
    assert len(meta["camera"]["poses"]) == 3 and np.array(meta["camera"]["poses"]).shape == (3, 2, 4, 4)
    # the camera moves v * W forward during a capture window
    p = np.array(meta["camera"]["poses"])
    d = np.linalg.norm(p[0, 1, :3, 3] - p[0, 0, :3, 3])
    assert d == pytest.approx(night["camera"]["speed_mps"] * opts.capture_window_s, rel=1e-6)
    lt = meta["lights"][0]
    assert {"id", "group", "kind", "instance", "luminance_cd_m2", "spectrum", "bbox"} <= set(lt)
    assert len(lt["bbox"]) == 3
    json.dumps(meta)  # plain data
    only = render.scene_meta(night, render.RenderOptions(width=320, height=180, groups=("signals",)))
    assert set(only["groups"]) == {"signals"} and {x["group"] for x in only["lights"]} == {"signals"}


def test_backend_falls_back_to_scalar_with_warning(monkeypatch):
    import mitsuba as mi

    before = mi.variant()
    monkeypatch.setattr(backend, "_chosen", None)
    monkeypatch.setattr(backend, "find_libllvm", lambda: [])
    monkeypatch.setattr(backend, "probe_cuda", lambda use_cache=True: False)  # also on a GPU machine
    monkeypatch.setattr(mi, "variant", lambda: None)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        v = backend.select_variant()
    assert v == "scalar_spectral"
    assert any(issubclass(x.category, RuntimeWarning) and "libLLVM" in str(x.message) for x in w)
    monkeypatch.undo()
    backend._chosen = None
    if before:
        mi.set_variant(before)
    with pytest.raises(ValueError, match="variant"):
        backend.select_variant("cuda_rgb")


def test_llvm_library_discovery_skips_llvm15(monkeypatch, tmp_path):
    for name in ("libLLVM-15.so.1", "libLLVM.so.19.1", "libLLVM-14.so.1"):
        (tmp_path / name).write_bytes(b"")
    monkeypatch.setattr(backend, "LLVM_SEARCH_DIRS", (str(tmp_path),))
    monkeypatch.delenv("DRJIT_LIBLLVM_PATH", raising=False)
    found = [p.split("/")[-1] for p in backend.find_libllvm()]
    assert found == ["libLLVM.so.19.1", "libLLVM-14.so.1"]


# ------------------------------------------------------------------------------- Mitsuba scene dict cache
def _mesh_arrays(mesh):
    import mitsuba as mi

    p = mi.traverse(mesh)
    out = [np.array(p["vertex_positions"]), np.array(p["faces"])]
    if mesh.emitter() is not None:
        out.append(np.array(mi.traverse(mesh.emitter())["radiance.values"]))
    return out


def test_mitsuba_dict_cache_rebuilds_what_moves_and_equals_a_fresh_build():
    """Frames after the first reuse the static geometry and the lamp spectra (render_frames' cache): every
    mesh, emitter spectrum and beam equals what a build without the cache gives, and moving objects move."""
    import mitsuba as mi

    if mi.variant() is None:
        backend.select_variant()
    s = scene.generate_scene(101, "night")
    moving = [o["id"] for o in s["objects"] if any(v != 0 for v in o["velocity_mps"])]
    assert moving and len(moving) < len(s["objects"])  # premise: both kinds present
    cache: dict = {}
    first = mitsuba_scene.mitsuba_dict(s, 0.0, emit="all", cache=cache)
    rest = dict(cache["rest_meshes"])
    for t in (1 / 60, 2 / 60):
        a = mitsuba_scene.mitsuba_dict(s, t, emit="all", cache=cache)
        b = mitsuba_scene.mitsuba_dict(s, t, emit="all")
        assert a.keys() == b.keys()
        for k in a:
            if k.startswith(("o", "light")):
                for x, y in zip(_mesh_arrays(a[k]), _mesh_arrays(b[k])):
                    np.testing.assert_array_equal(x, y, err_msg=k)
            elif k.startswith("beam"):
                assert {q: v for q, v in a[k].items() if q != "to_world"} == \
                    {q: v for q, v in b[k].items() if q != "to_world"}
                np.testing.assert_array_equal(np.array(a[k]["to_world"].matrix), np.array(b[k]["to_world"].matrix))
        oid = moving[0]
        assert not np.array_equal(_mesh_arrays(a[mitsuba_scene.shape_id(oid, 0)])[0],
                                  _mesh_arrays(first[mitsuba_scene.shape_id(oid, 0)])[0])
    assert cache["rest_meshes"].keys() == rest.keys()  # nothing moving was cached
    assert all(cache["rest_meshes"][k] is v for k, v in rest.items())  # built once
    assert not any(("object", oid) in rest for oid in moving)
    # what render_frames prepares before the back end is chosen (no Mitsuba) is the same geometry
    prepared = mitsuba_scene.prepare_geometry(s, {})["rest_meshes"]
    assert prepared.keys() == rest.keys()
    for k, v in rest.items():
        for x, y in zip(prepared[k] if k[0] == "light" else sum((m[1:] for m in prepared[k]), ()),
                        v if k[0] == "light" else sum((m[1:] for m in v), ())):
            np.testing.assert_array_equal(x, y, err_msg=str(k))


def test_scene_parts_a_vehicle_kind_is_a_template_entry():
    """Every vehicle kind of the vocabulary has exactly one template, and the generator's steps build any of them
    with no kind-specific code: each kind gets its parts, lamps (head, tail, brake, indicator where the template
    has one) and a validated scene."""
    from lfmbench.vocabulary import VEHICLE_KINDS
    from render_tools import scene_templates as T

    assert set(T.VEHICLE_TEMPLATES) == set(VEHICLE_KINDS) and T.PARKED_KIND in VEHICLE_KINDS
    cfg = scene.load_config()
    for kind, t in T.VEHICLE_TEMPLATES.items():
        b = scene.SceneBuilder(np.random.default_rng(0), cfg, "night")
        road = scene.add_road(b)
        n_obj = len(b.objects)
        scene.add_vehicle(b, kind, 20.0, -road.lane_width_m / 2, 0.0, 10.0, lights_on=True, braking=True,
                          indicator=True)
        veh = b.objects[n_obj]
        assert veh["kind"] == kind and veh["velocity_mps"] == [10.0, 0.0, 0.0]
        n_wheels = sum(2 if wy > 0 else 1 for _, _, wy in t["wheels"])
        assert len(veh["parts"]) == len(t["boxes"]) + len(t["spheres"]) + n_wheels
        kinds = [lt["kind"] for lt in b.lights if lt["instance"] == veh["id"]]
        sides = lambda lamps: sum(2 if p[1] != 0 else 1 for p, _ in lamps)  # noqa: E731
        assert kinds.count("headlight") == sides(t["head"]) and kinds.count("tail") == sides(t["tail"])
        assert kinds.count("brake") == sides(t["tail"]) + (t["cbrake"] is not None)
        assert kinds.count("indicator") == (1 if t["ind"] else 0)
    sc = scene.generate_scene(2, "night", overrides={"vehicles": {"require_kinds": list(VEHICLE_KINDS)}})
    assert set(VEHICLE_KINDS) <= {o["kind"] for o in sc["objects"]}


def test_texture_filter_option_reaches_the_bitmaps():
    """``RenderOptions.texture_filter``: checked, left out of the stored options when ``auto`` (as before it
    existed), ``auto`` resolves to nearest on scene version 2 only, and the chosen filter is the textured BSDF's bitmap
    filter."""
    with pytest.raises(ValueError, match="texture_filter"):
        render.RenderOptions(texture_filter="cubic")
    assert "texture_filter" not in render.RenderOptions().to_dict()
    assert render.RenderOptions(texture_filter="nearest").to_dict()["texture_filter"] == "nearest"
    assert render.texture_filter({}, render.RenderOptions()) == "bilinear"  # scene version 1: no textures anyway
    assert render.texture_filter({"version": 2}, render.RenderOptions()) == "nearest"
    assert render.texture_filter({"version": 2}, render.RenderOptions(texture_filter="bilinear")) == "bilinear"
    m = {"type": "roughplastic", "alpha": 0.1, "ior": 1.33, "rgb": [0.1, 0.1, 0.1],
         "texture": {"kind": "asphalt", "seed": 1, "size_m": [6.0, 18.4], "origin_m": [0.0, -9.2, 0.0], "lanes": 2,
                     "lane_width_m": 3.5}}
    for f in ("bilinear", "nearest"):
        assert mitsuba_scene._bsdf(m, f)["diffuse_reflectance"]["filter_type"] == f
    assert mitsuba_scene._bsdf({"type": "diffuse", "rgb": [0.2, 0.2, 0.2]}, "nearest")["reflectance"]["type"] == "rgb"
    with pytest.raises(ValueError, match="texture_filter"):
        mitsuba_scene.mitsuba_dict(scene.empty_scene(), 0.0, texture_filter="cubic")
    small = render.RenderOptions(width=32, height=18, frames=1)
    v2 = dict(scene.empty_scene(), version=2)
    assert render.scene_meta(v2, small)["render"]["texture_filter"] == "nearest"  # what the corpus was rendered with
    assert "texture_filter" not in render.scene_meta(scene.empty_scene(), small)["render"]


def test_scene_meta_and_render_share_the_geometry_of_equal_scenes_only(night):
    """:func:`render.drawn_geometry` is made once for equal scenes and options (scene_meta and render_frames of a
    render), and anew when the scene's content changes in place: the moved lamp's boxes then equal a fresh
    computation's, not the kept ones."""
    opts = render.RenderOptions(width=160, height=90, groups=("signals",))  # a few lamps: 0.04 CPU s a scene_meta
    s = copy.deepcopy(night)
    a = render.drawn_geometry(s, opts)
    assert render.drawn_geometry(copy.deepcopy(s), opts)[2] is a[2]
    assert render.drawn_geometry(s, render.RenderOptions(width=160, height=90, pad_px=3))[2] is not a[2]
    before = render.scene_meta(s, opts)["lights"]
    i = next(k for k, b in enumerate(before) if b["bbox"][0] is not None)
    lt = next(x for x in s["lights"] if x["id"] == before[i]["id"])
    lt["center"] = [c + d for c, d in zip(lt["center"], (0.0, 1.5, 0.5))]
    after = render.scene_meta(s, opts)["lights"]
    render._DRAWN.clear()
    fresh = render.scene_meta(s, opts)["lights"]
    assert after == fresh and after[i]["bbox"] != before[i]["bbox"]
