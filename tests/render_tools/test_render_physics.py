"""Physics of the renderer on tiny hand-made scenes, checked against analytic answers.

Runs with the JIT variant :mod:`render_tools.backend` selects (llvm_ad_spectral here); the renderer
(:mod:`render_tools.tracer`) refuses scalar_spectral with a clear error.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from render_tools import camera, reference, render, scene, spectra
from tests.data.render.data import HPS, LED
from tests.data.render.data import light as _light
from tests.data.render.data import wall_scene as _wall_scene


def _expected(spec, lum, opts):
    return spectra.band_means(spectra.absolute_spectrum(spec, lum), opts.bands_nm, opts.band_width_nm)


def test_scalar_variant_is_refused_with_a_clear_error():
    opts = render.RenderOptions(width=12, height=8, spp=1, bins=1, frames=1, aux=False, variant="scalar_spectral")
    with pytest.raises(RuntimeError, match="variant: rendering needs a JIT variant"):
        next(render.render_frames(_wall_scene(), opts))


@pytest.mark.jit
def test_directly_viewed_emitter_returns_its_spectral_radiance_per_nm():
    s = _wall_scene()
    opts = render.RenderOptions(width=12, height=8, spp=16, bins=2, frames=1, aux=False)
    fr = next(render.render_frames(s, opts))
    (lid, bb, bins), = fr["lights"]["otherlights"]
    assert lid == 0 and bins.shape[:2] == (2, 31)
    left = bins[:, :, :, : 6 - bb[1] - 1]  # columns fully on the LED panel (x < 5 of 12)
    exp = _expected(LED, 800.0, opts)
    peak = exp > 0.05 * exp.max()
    got = left.mean((0, 2, 3))
    assert np.allclose(got[peak], exp[peak], rtol=0.02)
    assert np.abs(got - exp).max() < 0.02 * exp.max()
    st = fr["static"]["streetlights"]["short"][:, :, 7:]
    exp1 = _expected(HPS, 2e4, opts)
    assert np.allclose(st.mean((1, 2)), exp1, rtol=0.02, atol=0.01 * exp1.max())
    assert "skymap" not in fr["static"]  # zero-luminance sky: the group is left out


@pytest.mark.jit
def test_lambertian_plane_under_uniform_sky():
    rho, lsky = 0.5, 1000.0
    s = scene.empty_scene(pitch_deg=-45.0, fov_x_deg=20.0, sky_luminance_cd_m2=lsky)
    s["materials"]["grey"] = {"type": "diffuse", "rgb": [rho, rho, rho]}
    s["objects"].append({"id": 0, "kind": "ground", "velocity_mps": [0, 0, 0],
                         "parts": [{"shape": "rect", "center": [0, 0, 0], "size": [4000, 4000], "normal": [0, 0, 1],
                                    "material": "grey"}]})
    opts = render.RenderOptions(width=8, height=6, spp=64, frames=1, aux=False)
    fr = next(render.render_frames(s, opts))
    img = fr["static"]["skymap"]["long"]
    # E = pi * L_sky on the plane; Lambertian radiance = rho * E / pi = rho * L_sky (per band)
    exp = rho * _expected({"model": "illuminant", "name": "D65"}, lsky, opts)
    assert np.allclose(img.mean((1, 2)), exp, rtol=0.04)


@pytest.mark.jit
def test_lambertian_plane_under_small_source():
    rho, lum, a, h = 0.5, 3e4, 0.2, 3.0
    s = scene.empty_scene(position_m=(3.0, 0.0, 2.0), pitch_deg=-89.0, fov_x_deg=4.0)
    s["materials"]["grey"] = {"type": "diffuse", "rgb": [rho, rho, rho]}
    s["objects"].append({"id": 0, "kind": "ground", "velocity_mps": [0, 0, 0],
                         "parts": [{"shape": "rect", "center": [0, 0, 0], "size": [200, 200], "normal": [0, 0, 1],
                                    "material": "grey"}]})
    s["lights"].append(_light(0, "streetlights", (3.0, 0.0, h), (0, 0, -1), (a, a), HPS, lum))
    opts = render.RenderOptions(width=6, height=4, spp=64, frames=1, aux=False)
    fr = next(render.render_frames(s, opts))
    img = fr["static"]["streetlights"]["short"]
    # small Lambertian source straight above: E = L A / h^2, reflected radiance rho E / pi
    exp = rho * _expected(HPS, lum, opts) * a * a / (math.pi * h * h)
    assert np.allclose(img.mean((1, 2)), exp, rtol=0.04, atol=0.02 * exp.max())


@pytest.mark.jit
def test_static_camera_gives_identical_time_bins():
    opts = render.RenderOptions(width=12, height=8, spp=4, bins=5, frames=2, aux=False, groups=("otherlights",))
    for fr in render.render_frames(_wall_scene(), opts):
        (_, _, bins), = fr["lights"]["otherlights"]
        assert bins.shape[0] == 5 and bins.max() > 0
        assert all(np.array_equal(bins[0], b) for b in bins[1:])


def _lamp_scene(speed):
    s = scene.empty_scene(speed_mps=speed)
    s["lights"].append(_light(0, "otherlights", (12.0, 1.0, 1.6), (-1, 0, 0), (0.4, 0.3), LED, 800.0))
    return scene.validate_scene(s)


@pytest.mark.jit
def test_bins_of_a_window_average_to_one_render_of_that_window():
    s = _lamp_scene(40.0)
    base = dict(width=48, height=32, spp=64, frames=1, aux=False, seed=3)
    f4 = next(render.render_frames(s, render.RenderOptions(bins=4, **base)))
    f1 = next(render.render_frames(s, render.RenderOptions(bins=1, **base)))
    (_, bb4, b4), = f4["lights"]["otherlights"]
    (_, bb1, b1), = f1["lights"]["otherlights"]
    assert bb4 == bb1
    assert not np.allclose(b4[0], b4[-1], rtol=0.2)  # the lamp moves across the bins
    mean4 = b4.mean(0)
    assert mean4.sum() == pytest.approx(b1[0].sum(), rel=0.02)  # Monte Carlo error of a 2 px lamp
    assert np.abs(mean4 - b1[0]).sum() < 0.1 * b1[0].sum()


def _x_moments(img):
    """Energy centroid (x, y) px and second central moment along x (px^2) of an image (C, h, w)."""
    e = img.sum(0)
    ys, xs = np.mgrid[0:e.shape[0], 0:e.shape[1]] + 0.5
    mx, my = (e * xs).sum() / e.sum(), (e * ys).sum() / e.sum()
    return mx, my, (e * (xs - mx) ** 2).sum() / e.sum()


@pytest.mark.jit
def test_continuous_blur_matches_average_of_instantaneous_subframes():
    """A 0.2 m lamp on a car crossing at 30 m/s, 4 m ahead of a stopped camera: during the long exposure its image
    moves ~5.5 px sideways at constant depth, i.e. uniformly along x. The continuous blur (one render over the
    exposure, ray times drawn by the camera) must equal (a) the mean of M instantaneous sub-frames (ray time fixed,
    independent of the camera's time sampling) and (b) the analytic streak: the lamp's box of projected width w
    swept from u(t0) to u(t0 + T) (``camera.project`` of the lamp centre), whose energy centroid is the midpoint
    and whose second moment along x is (L^2 + w^2)/12 + 1/12 (L = u(t0 + T) - u(t0); + 1/12: Sheppard's
    correction for moments taken at pixel centres of a trapezoid several px wide)."""
    velocity, centre = (0.0, -30.0, 0.0), np.array([4.0, 0.4, 1.4])
    s = _vehicle_lamp_scene(0.0, velocity, tuple(centre))
    opts = render.RenderOptions(width=48, height=16, spp=16, frames=1, aux=False)
    r = reference.ReferenceRenderer(s, opts)
    import mitsuba as mi

    from render_tools import mitsuba_scene as ms

    sc = mi.load_dict(ms.mitsuba_dict(s, 0.0, emit="otherlights"))   # car at its t = 0 position
    t0, T, M = 0.004, opts.long_exposure_s, 16                           # t0 != 0: the window's start counts
    blur = r.render(sc, t0, T, 64, 1, velocity=velocity)[0]
    subs = np.mean([r.render(sc, t0 + (i + 0.5) * T / M, 0.0, 16, 10 + i, velocity=velocity)[0]
                    for i in range(M)], axis=0)
    # (a) over 6 seeds: sum ratio - 1 = 0.004 +- 0.011 (std), L1 difference 0.098 +- 0.005 of the sum (the
    # noise of both renders); tolerances ~4.5 and ~10 std
    assert blur.sum() == pytest.approx(subs.sum(), rel=0.05)
    l1 = float(np.abs(blur - subs).sum() / blur.sum())
    assert l1 < 0.15, f"blur differs from the mean of {M} instantaneous sub-frames by {l1:.2f} of its energy (L1)"
    # (b) the analytic streak
    ego = camera.EgoMotion.from_scene(s)
    K = camera.intrinsics(opts.width, opts.height, float(s["camera"]["fov_x_deg"]))
    v = np.asarray(velocity)
    (u0, v0), = camera.project((centre + v * t0)[None], ego.pose_cv(t0), K)[0]
    (u1, _), = camera.project((centre + v * (t0 + T))[None], ego.pose_cv(t0 + T), K)[0]
    edges = camera.project(centre + v * t0 + np.array([[0.0, 0.1, 0.0], [0.0, -0.1, 0.0]]), ego.pose_cv(t0), K)[0]
    w, L = abs(edges[1, 0] - edges[0, 0]), u1 - u0
    assert abs(L) > 4.0 and w < 4.0                                       # a streak, not a wide lamp
    mx, my, var = _x_moments(blur)
    # Monte Carlo std over 6 seeds at 64 spp: centroid x 0.024 px, y 0.009 px, second moment 0.08 px^2 (2.3 %;
    # its mean 3.495 against 3.505 analytic); tolerances ~5-6 std, against a 2.7 px shift (window off by T/2)
    # and a 2.5 px^2 drop (no blur) for the time-sampling errors they catch
    want_var = (L * L + w * w + 1.0) / 12.0
    assert abs(mx - 0.5 * (u0 + u1)) < 0.15, f"streak centroid x {mx:.2f} px, path midpoint {0.5 * (u0 + u1):.2f} px"
    assert abs(my - v0) < 0.15, f"streak centroid y {my:.2f} px, lamp at {v0:.2f} px"
    assert abs(var - want_var) < 0.4, f"second moment along x {var:.2f} px^2, analytic {want_var:.2f} px^2"
    lo, hi = math.floor(min(u0, u1) - w / 2), math.ceil(max(u0, u1) + w / 2)
    inside = float(blur[..., lo:hi].sum() / blur.sum())
    assert inside > 0.99, f"{1 - inside:.1%} of the energy outside the swept columns [{lo}, {hi})"


@pytest.mark.jit
def test_group_left_out_changes_nothing_in_the_others():
    s = _wall_scene()
    base = dict(width=12, height=8, spp=4, bins=2, frames=1, aux=False, seed=5)
    both = next(render.render_frames(s, render.RenderOptions(**base)))
    one = next(render.render_frames(s, render.RenderOptions(groups=("streetlights",), **base)))
    assert set(one["static"]) == {"streetlights"} and one["lights"] == {}
    for w in ("short", "long"):
        assert np.array_equal(both["static"]["streetlights"][w], one["static"]["streetlights"][w])


@pytest.mark.jit
def test_light_crop_and_projection_agree_with_render():
    s = _lamp_scene(0.0)
    opts = render.RenderOptions(width=64, height=40, spp=16, frames=1, bins=1, aux=True)
    fr = next(render.render_frames(s, opts))
    (_, (y0, x0, y1, x1), b), = fr["lights"]["otherlights"]
    r = reference.ReferenceRenderer(s, opts)
    import mitsuba as mi

    from render_tools import mitsuba_scene as ms

    sc = mi.load_dict(ms.mitsuba_dict(s, 0.0, emit="otherlights"))
    full = r.render(sc, 0.0, opts.capture_window_s, 16, 9)[0]
    inside = full[:, y0:y1, x0:x1].sum()
    assert inside / full.sum() > 0.995  # no energy of a lone lamp falls outside its crop
    e = full.sum(0)
    ys, xs = np.mgrid[0:opts.height, 0:opts.width] + 0.5
    uv, _ = camera.project(np.array([[12.0, 1.0, 1.6]]), camera.EgoMotion.from_scene(s).pose_cv(0.0),
                           camera.intrinsics(64, 40, 40.0))
    assert (e * xs).sum() / e.sum() == pytest.approx(uv[0, 0], abs=0.3)
    assert (e * ys).sum() / e.sum() == pytest.approx(uv[0, 1], abs=0.3)
    mask = fr["aux"]["mask.light"]
    assert mask[int(uv[0, 1]), int(uv[0, 0])] == 0 and (mask == -1).mean() > 0.9


@pytest.mark.jit
def test_lamp_straddling_the_camera_plane_gets_the_crop_of_its_visible_part():
    """A light strip overhead from 2 m behind the camera to 8 m ahead: its crop holds all of its light in a
    Mitsuba render of it alone (the independent answer), and is the top of the image only (the strip is above
    the horizon), not the whole image."""
    s = scene.empty_scene()
    s["lights"].append(_light(0, "otherlights", (3.0, 0.0, 2.0), (0, 0, -1), (10.0, 0.4), LED, 800.0))
    s = scene.validate_scene(s)
    opts = render.RenderOptions(width=64, height=40, spp=16, frames=1, bins=1, aux=False)
    fr = next(render.render_frames(s, opts))
    (_, (y0, x0, y1, x1), b), = fr["lights"]["otherlights"]
    import mitsuba as mi

    from render_tools import mitsuba_scene as ms

    full = reference.ReferenceRenderer(s, opts).render(mi.load_dict(ms.mitsuba_dict(s, 0.0, emit="otherlights")),
                                                       0.0, opts.capture_window_s, 16, 9)[0].sum(0)
    assert full.sum() > 0 and full[y0:y1, x0:x1].sum() / full.sum() > 0.995
    assert y0 == 0 and y1 < opts.height // 2 and (y1 - y0) * (x1 - x0) < 0.5 * opts.width * opts.height
    assert float(b[0].sum()) == pytest.approx(float(full[y0:y1, x0:x1].sum()), rel=0.03)  # the same light


@pytest.mark.parametrize("seed", range(6))
def test_near_plane_clip_bounds_the_visible_part_of_a_face(seed):
    """render.clip_near against brute force: the bbox of the clipped face's points equals the bbox of the points
    of a dense grid over the face (its corners' convex hull) that lie in front of the plane."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    flat = rng.normal(size=(4, 2)) * 3.0  # a planar quad in its own (u, v) coordinates, corners in any order
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]  # tilted at random, 1 m off the origin
    to3 = lambda uv: np.column_stack([uv, np.ones(len(uv))]) @ rot.T  # noqa: E731
    corners = to3(flat)
    z, near = corners[:, 2], float(rng.uniform(corners[:, 2].min(), corners[:, 2].max()))
    got = render.clip_near(corners, z, near)
    assert np.all(got[:, 2] >= near - 1e-9)
    g = np.stack(np.meshgrid(*[np.linspace(flat[:, i].min(), flat[:, i].max(), 1200) for i in (0, 1)]), -1)
    g = g.reshape(-1, 2)
    dense = to3(g[Delaunay(flat).find_simplex(g) >= 0])
    dense = dense[dense[:, 2] > near]
    lo, hi = got.min(0), got.max(0)
    assert np.all(dense.min(0) >= lo - 1e-9) and np.all(dense.max(0) <= hi + 1e-9)  # nothing visible is cut
    assert np.allclose(dense.min(0), lo, atol=0.03) and np.allclose(dense.max(0), hi, atol=0.03)  # nor added


@pytest.mark.jit
def test_aux_depth_range_and_instance_mask():
    d = 10.0
    s = scene.empty_scene()
    s["materials"]["grey"] = {"type": "diffuse", "rgb": [0.3, 0.3, 0.3]}
    s["objects"].append({"id": 0, "kind": "building", "velocity_mps": [0, 0, 0],
                         "parts": [{"shape": "box", "center": [d + 1.0, 0, 1.4], "size": [2.0, 6.0, 2.0],
                                    "yaw_deg": 0.0, "material": "grey"}]})
    opts = render.RenderOptions(width=20, height=12, spp=1, frames=1, aux=True)
    aux = next(render.render_frames(s, opts))["aux"]
    hit = aux["mask.instance"] == 0
    assert hit[6, 10] and not hit[0, 0]
    assert np.allclose(aux["depth.Z"][hit], d, atol=1e-3)
    assert np.all(aux["depth.R"][hit] >= d - 1e-3) and aux["depth.R"][hit].max() > d
    assert np.all(np.isinf(aux["depth.Z"][~hit])) and np.all(aux["mask.instance"][~hit] == -1)
    assert np.all(aux["mask.light"] == -1)


def _vehicle_lamp_scene(ego_speed, vehicle_velocity, lamp_center=(6.0, 2.0, 1.4), yaw_rate=0.0):
    """A lamp (otherlights) on a small vehicle body with the given world velocity (m/s); ego heads +x."""
    s = scene.empty_scene(speed_mps=ego_speed, yaw_rate_rad_s=yaw_rate)
    s["materials"]["body"] = {"type": "diffuse", "rgb": [0.2, 0.2, 0.2]}
    cx, cy, _ = lamp_center
    s["objects"].append({"id": 0, "kind": "car", "velocity_mps": [float(v) for v in vehicle_velocity],
                         "parts": [{"shape": "box", "center": [cx + 1.0, cy, 0.6], "size": [1.5, 1.2, 1.0],
                                    "material": "body"}]})
    s["lights"].append(_light(0, "otherlights", lamp_center, (-1, 0, 0), (0.2, 0.15), LED, 800.0, instance=0))
    return scene.validate_scene(s)


def _bin_centroids(bins, bb):
    """(K, 2) energy centroids (x, y) in full-image px of per-light bins (K, C, h, w) with crop ``bb``."""
    y0, x0 = bb[0], bb[1]
    e = bins.sum(1)                                            # (K, h, w)
    ys, xs = np.mgrid[0:e.shape[1], 0:e.shape[2]] + 0.5
    tot = e.sum((1, 2))
    return np.stack([(e * xs).sum((1, 2)) / tot + x0, (e * ys).sum((1, 2)) / tot + y0], 1)


def _expected_centroids(s, opts, velocity, lamp_center):
    """Lamp centre projected at each bin's mid-time with the vehicle moving (the analytic answer)."""
    tm = render.frame_timing(s, opts, 0)
    edges, t_obj = tm["bin_edges"], 0.5 * (tm["window"][0] + tm["window"][1])
    ego = camera.EgoMotion.from_scene(s)
    K = camera.intrinsics(opts.width, opts.height, float(s["camera"]["fov_x_deg"]))
    out = []
    for t in 0.5 * (edges[:-1] + edges[1:]):
        c = np.asarray(lamp_center) + np.asarray(velocity) * t
        uv, _ = camera.project(c[None], ego.pose_cv(t), K)
        out.append(uv[0])
    return np.asarray(out), t_obj


@pytest.mark.parametrize("ego_speed, velocity, lamp, yaw_rate", [
    (30.0, (30.0, 0.0, 0.0), (6.0, 2.0, 1.4), 0.0),      # car ahead at the ego's speed
    (30.0, (-20.0, 0.0, 0.0), (10.0, 1.5, 1.4), 0.0),    # oncoming car
    (0.0, (0.0, -15.0, 0.0), (8.0, 0.5, 1.4), 0.0),      # crossing car, ego stopped
    (20.0, (10.0, -8.0, 0.0), (9.0, 0.5, 1.4), 0.6)])    # ego turning (0.6 rad/s), car drifting across
@pytest.mark.jit
def test_lamp_on_a_moving_vehicle_moves_with_it_inside_the_exposure(ego_speed, velocity, lamp, yaw_rate):
    """Per-light bins follow the lamp's true screen path (ego and vehicle motion), not the ego motion alone:
    bin centroids against the analytic projection of the moving lamp centre at each bin's mid-time."""
    s = _vehicle_lamp_scene(ego_speed, velocity, lamp, yaw_rate)
    opts = render.RenderOptions(width=128, height=80, spp=64, bins=4, frames=1, aux=False, seed=2)
    fr = next(render.render_frames(s, opts))
    (_, bb, bins), = fr["lights"]["otherlights"]
    got = _bin_centroids(bins, bb)
    want, _ = _expected_centroids(s, opts, velocity, lamp)
    assert np.abs(got - want).max() < 0.15
    ego_only, _ = _expected_centroids(s, opts, (0.0, 0.0, 0.0), lamp)
    travel = np.abs(want[-1] - want[0]).max()
    if travel < 0.05:   # the co-moving car: a sharp lamp, whereas the ego motion alone would smear it
        assert np.abs(ego_only[-1] - ego_only[0]).max() > 1.0
    else:
        assert travel > 1.0
    # the crop holds the whole moving lamp: the meta bbox is the rendered crop
    meta = render.scene_meta(s, opts)
    assert tuple(meta["lights"][0]["bbox"][0]) == tuple(bb)


@pytest.mark.parametrize("pixel_samples", ["strata", "sobol"])
@pytest.mark.jit
def test_each_bin_of_a_crossing_lamp_is_the_streak_of_its_own_time_interval(pixel_samples):
    """The production renderer's time sampling inside a bin: the crossing lamp of the continuous-blur test (a car at
    30 m/s, 4 m ahead of a stopped camera) in K = 2 per-light bins of 3.7 px of motion each, frames 0 and 1 (t0 = 0
    and 1/fps: the window's start counts). Each bin must be the analytic streak of its own interval [a, b): the
    lamp's box of projected width w swept uniformly from u(a) to u(b) (``camera.project`` of the lamp centre), so
    energy centroid x at the midpoint (u(a) + u(b)) / 2, y at the lamp's row, and second moment along x
    (L_k^2 + w^2 + 1) / 12 with L_k = u(b) - u(a) (+ 1/12: Sheppard's correction for moments at pixel centres).
    Ray times at the bin middle leave the second moment (w^2 + 1) / 12 (-1.15 px^2); times shifted by half a bin
    move the centroid by L_k / 2 = 1.9 px; times over the whole window put both bins' centroids at its middle.
    Both ways of placing a pixel's samples (strata: scene version 1; sobol: version 2)."""
    velocity, centre = np.array([0.0, -30.0, 0.0]), np.array([4.0, 0.4, 1.4])
    s = _vehicle_lamp_scene(0.0, tuple(velocity), tuple(centre))
    opts = render.RenderOptions(width=64, height=16, spp=16, bins=2, frames=2, aux=False, groups=("otherlights",),
                                pixel_samples=pixel_samples, seed=1)
    ego = camera.EgoMotion.from_scene(s)
    K = camera.intrinsics(opts.width, opts.height, float(s["camera"]["fov_x_deg"]))
    u = lambda t, off=(0.0, 0.0, 0.0): camera.project(centre + velocity * t + np.asarray(off),  # noqa: E731
                                                      ego.pose_cv(t), K)[0][0]
    for n, fr in enumerate(render.render_frames(s, opts)):
        (_, (y0, x0, _, _), bins), = fr["lights"]["otherlights"]
        edges = render.frame_timing(s, opts, n)["bin_edges"]
        for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
            (ua, va), (ub, _) = u(a), u(b)
            w, L = abs(u(a, (0.0, 0.1, 0.0))[0] - u(a, (0.0, -0.1, 0.0))[0]), ub - ua
            assert abs(L) >= 3.0 and w < 5.0                          # a streak in every bin
            where = f"frame {n} bin {k} ({pixel_samples})"
            assert bins[k].sum() > 0, f"{where}: no light in the lamp's crop"
            mx, my, var = _x_moments(bins[k])
            mx, my, want = mx + x0, my + y0, (L * L + w * w + 1.0) / 12.0
            # Monte Carlo spread over 8 seeds (spp 16; strata / sobol): centroid x std <= 0.045 / 0.023 px, y <=
            # 0.026 / 0.014 px, second moment std <= 0.094 / 0.055 px^2 about a mean 0.00-0.05 px^2 under the
            # analytic 2.84 px^2; largest deviations of 64 bins 0.071 px, 0.046 px, 0.17 px^2. Tolerances ~4.5 std,
            # against 1.9 px (half-bin shift) and 1.15 px^2 (times at the bin middle) for the errors they catch
            assert abs(mx - 0.5 * (ua + ub)) < 0.2, f"{where}: centroid x {mx:.2f} px, path midpoint " \
                                                    f"{0.5 * (ua + ub):.2f} px (from {ua:.2f} to {ub:.2f} px)"
            assert abs(my - va) < 0.12, f"{where}: centroid y {my:.2f} px, lamp at {va:.2f} px"
            assert abs(var - want) < 0.4, f"{where}: second moment along x {var:.2f} px^2, analytic {want:.2f} " \
                                          f"px^2 (streak {L:.2f} px, lamp {w:.2f} px)"


@pytest.mark.jit
def test_dusk_sky_with_negative_lobes_renders_non_negative():
    """Mitsuba's sunsky gives slightly negative spectral radiance near the horizon at low sun (measured here,
    independently of the tracer); the tracer cuts it at 0, so the dusk scene that the corpus writer refused
    (generator seed 4, sun 1.1 deg up) now renders with no negative pixel."""
    import drjit as dr
    import mitsuba as mi

    from render_tools import mitsuba_scene as ms

    sc = scene.generate_scene(4, "dusk")
    opts = render.RenderOptions(width=64, height=36, spp=2, bins=2, frames=1, groups=("skymap",), aux=False)
    fr = next(render.render_frames(sc, opts))
    for w in ("short", "long"):
        img = fr["static"]["skymap"][w]
        assert img.min() >= 0.0 and img.max() > 0.0
    em = mi.load_dict(ms.sky_dict(sc))
    rng = np.random.default_rng(0)
    n = 200_000
    v = rng.normal(size=(n, 3)).astype(np.float32)
    v[:, 2] *= 1e-3  # directions close to the horizon, where the fit goes negative
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(-v[:, 0], -v[:, 1], -v[:, 2])
    wl = rng.uniform(400, 460, size=n).astype(np.float32)
    si.wavelengths = mi.Spectrum(*[mi.Float(wl)] * 4)
    assert float(np.min(np.asarray(em.eval(si)[0]))) < 0.0  # the model's negative lobe (the reason for the floor)
