"""The virtual P2020 flicker bench (lfmbench.flicker_bench) against independent answers.

- All-phase extremes: against exact rational integration of the pulse train (``fractions.Fraction`` on the binary
  values of the float inputs, evaluated at every rational breakpoint, written here independently of the bench)
  within 1e-9, and against dense brute-force phase sampling (the sampled min can only be above the exact one, by at
  most the largest slope times the step).
- Merges: min/max and the MMP phase share of a max-type merge against dense sampling of the merge itself.
- Sequences: KPIs equal :mod:`lfmbench.metrics.flicker` on series computed here from ``pwm_exposure`` at phases
  computed in rationals.
- Frames to cover every phase: the three-distance formula against brute force over the visited phases.
"""
from __future__ import annotations

import math
from fractions import Fraction as Fr

import numpy as np
import pytest
import torch

from lfmbench.baselines import REGISTRY
from lfmbench.flicker_bench.exact import band_measure, phase_map
from lfmbench.flicker_bench.model import BenchError, build_model
from lfmbench.flicker_bench.run import Grid, check_grid
from lfmbench.flicker_bench.sequence import frames_to_cover, max_gap, sequence_kpis, sequence_series
from lfmbench.flicker import pwm_exposure
from lfmbench.metrics.flicker import fdi, fmi, mmp


def on_time(phase: Fr, start: Fr, length: Fr, T: Fr, D: Fr) -> Fr:
    """Exact ON time of [start, start + length) for rising edges at phase + kT (rationals)."""
    def F(t):  # ON time in [0, t) of the train with an edge at 0
        k = math.floor(t / T)
        return k * D * T + min(t - k * T, D * T)

    s = start - phase
    return F(s + length) - F(s)


def exact_extremes(cap, T: float, D: float) -> tuple[Fr, Fr]:
    """Min and max over phase of the capture's ON fraction, exactly: the function is piecewise linear between the
    points where a window edge meets a pulse edge, so its extremes are among them."""
    Tf, Df = Fr(T), Fr(D)
    starts = [Fr(float(a)) for a in cap.starts_s]
    lens = [Fr(float(n)) for n in cap.lengths_s]
    w = [Fr(float(x)) for x in cap.weights]
    pts = {Fr(0)}
    for a, n in zip(starts, lens):
        for p in (a, a - Df * Tf, a + n, a + n - Df * Tf):
            pts.add(p - math.floor(p / Tf) * Tf)
    L = Fr(cap.length_s)
    vals = [sum(wi * on_time(p, a, n, Tf, Df) for wi, a, n in zip(w, starts, lens)) / L for p in pts]
    return min(vals), max(vals)


CELLS = [(95.0, 0.1), (137.3, 0.37), (400.0, 0.05), (51.0, 0.9)]


@pytest.mark.parametrize("sensor,kw", [("chopped", {}), ("staggered", {"roi_rows": 3, "line_time_s": 2e-4}),
                                       ("ovt", {})])
def test_capture_extremes_equal_rational_and_brute_force(sensor, kw):
    model = build_model(sensor, **kw)
    f = np.array([c[0] for c in CELLS])
    for fi, di in CELLS:
        pm = phase_map(model, np.array([fi]), np.array([di]), np.array([10.0]), {})
        for cap in model.captures:
            lo, hi = exact_extremes(cap, 1 / fi, di)
            assert abs(pm.on_min[cap.name][0] - float(lo)) < 1e-9
            assert abs(pm.on_max[cap.name][0] - float(hi)) < 1e-9
            # dense brute force: phases on a grid of 4001 points
            T = 1 / fi
            ph = np.linspace(0, T, 4001)
            on = pwm_exposure(cap.starts_s[None, :] - ph[:, None], cap.lengths_s, T, di)
            fr = (on * cap.weights).sum(1) / cap.length_s
            slope = 2 * cap.weights.sum() * 2 / cap.length_s  # |d f / d phase| <= 2 per window edge pair / L
            step = T / 4000
            assert fr.min() >= float(lo) - 1e-12 and fr.min() <= float(lo) + slope * step
            assert fr.max() <= float(hi) + 1e-12 and fr.max() >= float(hi) - slope * step
    assert f.size == 4


def test_rolling_rows_shift_the_phase_only():
    """One row of a rolling shutter: the same extremes as a global shutter (the row only shifts the phase)."""
    a = build_model("staggered", roi_rows=1, line_time_s=1e-4)
    pm = phase_map(a, np.array([123.0]), np.array([0.2]), np.array([10.0]), {})
    lo, _ = exact_extremes(a.captures[1], 1 / 123.0, 0.2)
    assert abs(pm.on_min["medium"][0] - float(lo)) < 1e-9


def _dense_panel(model, method, f, d, lum, n=8001):
    """The merge output at n phases, by brute force through the same read-out."""
    from lfmbench.flicker_bench.exact import capture_state, evaluate_panels

    T = 1 / f
    ph = np.linspace(0, T, n, endpoint=False)
    bg = model.settings["background_cd_m2"]
    mu = {}
    for c in model.captures:
        on = pwm_exposure(c.starts_s[None, :] - ph[:, None], c.lengths_s, T, d)
        fr = (on * c.weights).sum(1) / c.length_s
        mu[c.name] = torch.from_numpy(c.rate * (lum * fr + bg) + c.dark_e)
    vals, flags = capture_state(model, mu)
    return evaluate_panels(model, {method: REGISTRY[method]}, vals, flags)[method].numpy()


@pytest.mark.parametrize("sensor,method,f,d", [("staggered", "exposure_select_bounded", 97.0, 0.12),
                                              ("ovt", "saturated_exposure_corrected", 151.0, 0.3),
                                              ("lofic", "exposure_select", 60.0, 0.2),
                                              ("ovt", "flicker_aware", 95.0, 0.2)])
def test_merge_map_equals_dense_sampling(sensor, method, f, d):
    model = build_model(sensor)
    sat = sorted(model.saturation_luminance().values())
    for lum in (sat[0] * 0.5, sat[0] * 3.0, sat[-1] * 0.7):
        pm = phase_map(model, np.array([f]), np.array([d]), np.array([lum]), {method: REGISTRY[method]})
        y = _dense_panel(model, method, f, d, lum)
        scale = max(abs(y).max(), 1.0)
        # sampled extremes lie inside the exact ones, and close to them (a jump is hit within one step)
        assert y.min() >= pm.vmin[method][0, 0] - 1e-9 * scale
        assert y.max() <= pm.vmax[method][0, 0] + 1e-9 * scale
        assert y.min() - pm.vmin[method][0, 0] <= 5e-3 * scale
        assert pm.vmax[method][0, 0] - y.max() <= 5e-3 * scale
        assert abs(y.mean() - pm.mean[method][0, 0]) <= 2e-3 * scale
        m = pm.mean[method][0, 0]
        share = np.mean((y > 0.9 * m) & (y < 1.1 * m))
        assert abs(share - pm.mmp[method][0, 0]) < 3e-3


def test_band_measure_by_hand():
    assert band_measure(np.array(0.0), np.array(1.0), np.array(0.25), np.array(0.5)) == pytest.approx(0.25)
    assert band_measure(np.array(1.0), np.array(0.0), np.array(0.25), np.array(np.inf)) == pytest.approx(0.75)
    assert band_measure(np.array(2.0), np.array(2.0), np.array(1.0), np.array(3.0)) == 1.0
    assert band_measure(np.array(2.0), np.array(2.0), np.array(2.0), np.array(3.0)) == 0.0  # strict band


def test_sequence_kpis_equal_metrics_on_independent_series():
    model = build_model("single", fps=60.0)
    f, d, lum, n = 97.0, 0.25, 200.0, 24
    s = sequence_series(model, np.array([f]), np.array([d]), np.array([lum]), {}, n, phase0_s=1e-3)
    cap = model.captures[0]
    tf, T = Fr(model.frame_time_s), Fr(1 / f)
    ref = []
    for k in range(n):
        ph = Fr(1e-3) - k * tf
        ph -= math.floor(ph / T) * T
        on = sum(on_time(ph, Fr(float(a)), Fr(float(w)), T, Fr(d)) for a, w in zip(cap.starts_s, cap.lengths_s))
        mu = cap.rate * (lum * float(on / Fr(cap.length_s)) + model.settings["background_cd_m2"]) + cap.dark_e
        ref.append((min(mu, cap.clip_e) - cap.dark_e) * cap.refer)
    ref = np.array(ref)
    assert np.allclose(s["main"][0, 0], ref, rtol=1e-12, atol=0)
    off = {"main": 5.0}
    k = sequence_kpis({"main": ref[None, None, :]}, off)
    x = torch.from_numpy(ref)
    assert k["main"]["fmi"][0, 0] == float(fmi(x))
    assert k["main"]["mmp"][0, 0] == float(mmp(x))
    assert k["main"]["fdi"][0, 0] == float(fdi(x, x_off=5.0))


@pytest.mark.parametrize("f", [95.0, 137.0, 200.0, 61.7])
def test_frames_to_cover_against_brute_force(f):
    tf = 1 / 30.0
    a = Fr(tf) * Fr(f)
    a -= math.floor(a)
    def gap(n):
        pts = sorted({(k * a) % 1 for k in range(n)})
        return max([pts[i + 1] - pts[i] for i in range(len(pts) - 1)] + [1 - pts[-1] + pts[0]])
    for n in (1, 2, 3, 7, 30, 61):
        assert max_gap(tf, f, n) == float(gap(n))
    for tol in (0.5, 0.1, 0.04):
        got = frames_to_cover(tf, f, tol, n_max=80)
        want = next((n for n in range(1, 81) if gap(n) <= tol), None)
        assert got == want


def test_frames_to_cover_commensurate_never():
    assert frames_to_cover(1 / 90.0, 90.0, 0.01) is None or frames_to_cover(1 / 90.0, 90.0, 0.01) > 10 ** 5
    assert frames_to_cover(0.5, 1.0, 0.4) is None  # exactly half a period per frame: two phases only


@pytest.mark.parametrize("grid,field", [((np.array([-5.0]), [0.5], [1.0]), "--freq"),
                                        ((np.array([0.0]), [0.5], [1.0]), "--freq"),
                                        ((np.array([2e6]), [0.5], [1.0]), "--freq"),
                                        ((np.array([100.0]), [0.0], [1.0]), "--duty"),
                                        ((np.array([100.0]), [1.2], [1.0]), "--duty"),
                                        ((np.array([100.0]), [0.5], [-1.0]), "--luminance"),
                                        ((np.array([np.nan]), [0.5], [1.0]), "--freq"),
                                        ((np.array([np.inf]), [0.5], [1.0]), "--freq"),
                                        ((np.array([100.0]), [-0.2], [1.0]), "--duty"),
                                        ((np.array([100.0]), [np.nan], [1.0]), "--duty"),
                                        ((np.array([0.5]), [0.5], [1.0]), "--freq")])
def test_bad_grid_names_the_option(grid, field):
    with pytest.raises(BenchError, match=f"^{field}") as exc:
        check_grid(Grid(*(np.asarray(g, float) for g in grid)))
    assert "\n" not in str(exc.value)


def test_frame_time_shorter_than_plan_is_refused():
    with pytest.raises(BenchError, match="^--fps: the frame time .* shorter than the exposure plan"):
        build_model("staggered", fps=120.0)
    with pytest.raises(BenchError, match="^--fps: the frame time .* shorter than the exposure plan"):
        build_model("ovt", fps=1.0 / 0.01)  # 10 ms frames, the default 1/90 s SPD window is longer
    with pytest.raises(BenchError, match="^--exposure"):
        build_model("ovt", exposures={"nope": [[0, 1e-3]]})
    with pytest.raises(BenchError, match="^--exposure: the windows of capture 'short' overlap"):
        build_model("staggered", exposures={"short": [[0.0105, 2e-4]]})
    with pytest.raises(BenchError, match="^--exposure: captures"):
        build_model("ovt", exposures={"lpd_hcg": [[0, 1e-3]]})
