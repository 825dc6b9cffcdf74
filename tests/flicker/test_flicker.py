"""Tests of lfmbench.flicker against independent answers.

References used here, none of which shares code with the implementation:
- ``exact_phi``: the cumulative-ON-time formula F(t) = floor(t/T) D T + min(t mod T, D T) evaluated in exact
  rational arithmetic (``fractions.Fraction``) on the exact binary values of the float inputs;
- ``brute_phi``: enumeration of every ON interval that meets the exposure, also exact;
- midpoint quadrature of the sampled waveform and mpmath quadrature (trapezoidal pulses).
"""
from __future__ import annotations

import math
from fractions import Fraction as Fr

import mpmath
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from lfmbench.flicker import (bin_weights, flicker_severity, frame_phase, miss_probability, pwm_exposure, pwm_level,
                              row_phase)

REL = 1e-12


def exact_phi(phase, exposure, period, duty, amplitude=1.0, offset=0.0) -> Fr:
    ph, te, T, D = Fr(phase), Fr(exposure), Fr(period), Fr(duty)

    def F(t):
        k = math.floor(t / T)
        return k * D * T + min(t - k * T, D * T)

    return Fr(amplitude) * (F(ph + te) - F(ph)) + Fr(offset) * te


def brute_phi(phase, exposure, period, duty) -> Fr:
    ph, te, T, D = Fr(phase), Fr(exposure), Fr(period), Fr(duty)
    a, b = ph, ph + te
    total = Fr(0)
    for k in range(math.floor(a / T) - 1, math.floor(b / T) + 2):
        lo, hi = max(a, k * T), min(b, k * T + D * T)
        if hi > lo:
            total += hi - lo
    return total


def rel_err(got, ref: Fr) -> float:
    # relative error; values below 1e-290 (near the subnormal range, no relative precision) count absolutely
    got = Fr(float(got))
    return float(abs(got - ref) / max(abs(ref), Fr(1e-290)))


# ---------------------------------------------------------------------------------------------------------
# Exactness on the extreme grid of the issue
# ---------------------------------------------------------------------------------------------------------
DUTIES = [0.0, 1e-12, 0.5, 1 - 1e-12, 1.0, 0.7, 0.2]
PERIODS = [1e-6, 1 / 90, 1 / 105, 1.0]
EXPOSURE_FACTORS = [0.0, 1e-9, 1.0, 2.5, 3.0, 10.0, 1e4, 1e4 + 0.37]


@pytest.mark.parametrize("period", PERIODS)
@pytest.mark.parametrize("duty", DUTIES)
def test_extreme_grid_matches_exact_rational(period, duty):
    eps = np.spacing(period)
    phases = [0.0, duty * period, period - eps, -eps, 0.3 * period, -0.7 * period, 1e3 * period + 0.1 * period,
              duty * period - 0.5e-9 * period]
    worst = 0.0
    for k in EXPOSURE_FACTORS:
        te = k * period
        for ph in phases:
            got = pwm_exposure(ph, te, period, duty)
            ref = exact_phi(ph, te, period, duty)
            worst = max(worst, rel_err(got, ref))
            assert got >= 0.0 and got <= te * (1 + 1e-15)
    assert worst <= REL, worst


def test_numba_numpy_and_torch_paths_agree():
    rng = np.random.default_rng(0)
    T = rng.uniform(1e-6, 1.0, 2000)
    ph = rng.uniform(-5, 5, 2000) * T
    te = rng.uniform(0, 30, 2000) * T
    D = rng.uniform(0, 1, 2000)
    fast = pwm_exposure(ph, te, T, D)
    tt = pwm_exposure(torch.tensor(ph), torch.tensor(te), torch.tensor(T), torch.tensor(D)).numpy()
    # trapezoid code path with vanishing ramps: the generic numpy formula
    ramp = pwm_exposure(ph, te, T, D, rise_time=1e-300, fall_time=1e-300)
    for i in range(0, 2000, 97):
        ref = exact_phi(ph[i], te[i], T[i], D[i])
        assert rel_err(fast[i], ref) <= REL
        assert rel_err(tt[i], ref) <= REL
    np.testing.assert_allclose(tt, fast, rtol=1e-13, atol=1e-300)
    np.testing.assert_allclose(ramp, fast, rtol=1e-12, atol=1e-18)


@settings(max_examples=300, deadline=None)
@given(
    period=st.floats(1e-6, 1.0),
    duty=st.floats(0.0, 1.0),
    phase_f=st.floats(-50.0, 50.0),
    exp_f=st.floats(0.0, 25.0),
    # levels of 0 or >= 1e-100: products below the float64 normal range (subnormals) carry no relative precision
    amplitude=st.one_of(st.just(0.0), st.floats(1e-100, 1e6)),
    offset=st.one_of(st.just(0.0), st.floats(1e-100, 1e3)),
)
def test_random_against_brute_force(period, duty, phase_f, exp_f, amplitude, offset):
    ph, te = phase_f * period, exp_f * period
    got = pwm_exposure(ph, te, period, duty, amplitude, offset)
    on = brute_phi(ph, te, period, duty)
    assert on == exact_phi(ph, te, period, duty)  # two independent exact references agree
    ref = Fr(amplitude) * on + Fr(offset) * Fr(te)
    assert rel_err(got, ref) <= REL
    assert 0.0 <= got <= (amplitude + offset) * te * (1 + 1e-12) + 1e-300


def test_fine_quadrature_converges_to_closed_form():
    # midpoint rule over the sampled waveform: error O(T/N) at each edge; N = 2e6 samples per exposure
    T, D, ph, te = 1 / 97, 0.31, 0.0043, 0.037
    t = ph + (np.arange(2_000_000) + 0.5) * (te / 2_000_000)
    quad = pwm_level(t, T, D).sum() * (te / 2_000_000)
    assert abs(quad - pwm_exposure(ph, te, T, D)) <= 4 * te / 2_000_000


# ---------------------------------------------------------------------------------------------------------
# Invariants
# ---------------------------------------------------------------------------------------------------------
def test_monotone_in_exposure_and_bounded():
    T, D = 1 / 93, 0.37
    te = np.linspace(0, 20 * T, 20001)
    for ph in (0.0, 0.2 * T, D * T, 0.99 * T):
        phi = pwm_exposure(ph, te, T, D, amplitude=2.0, offset=0.5)
        assert np.all(np.diff(phi) >= 0)
        assert np.all(phi <= 2.5 * te * (1 + 1e-15)) and np.all(phi >= 0.5 * te * (1 - 1e-15))


def test_periodic_in_phase():
    T, D = 1 / 110, 0.45
    ph = np.linspace(-T, T, 1001)
    a = pwm_exposure(ph, 0.004, T, D)
    for k in (1, 7, 1000):
        np.testing.assert_allclose(pwm_exposure(ph + k * T, 0.004, T, D), a, rtol=0, atol=1e-15 * k)


def test_whole_periods_give_exact_mean():
    # T = 2^-7 s makes k*T exact in binary, so te is exactly k periods and Phi must be k*(A*D + offset)*T,
    # the same for every phase, to within 2 ulp of the exact rational value
    T = 2.0 ** -7
    for D in (0.0, 0.1, 0.5, 0.9, 1.0):
        for k in (1, 2, 17, 10_000):
            ph = np.linspace(-3 * T, 3 * T, 257)
            phi = pwm_exposure(ph, k * T, T, D, amplitude=3.0, offset=0.25)
            exact = float(k * (3 * Fr(D) + Fr(0.25)) * Fr(T))
            assert np.all(np.abs(phi - exact) <= 2 * np.spacing(exact))


def test_fsi_one_inside_off_time_zero_for_whole_periods():
    T, D = 1 / 100, 0.2  # OFF time 8 ms
    frames = frame_phase(0.0021, np.arange(12), 1 / 60, T)
    phi_short = pwm_exposure(frames, 0.005, T, D)
    # frame phases visit [2.1 ms, 2.9 ms] (inside the OFF time with 5 ms to spare): the LED vanishes
    assert phi_short.min() == 0.0 and flicker_severity(phi_short) == 1.0
    phi_whole = pwm_exposure(frames, 3 * T, T, D)
    assert float(flicker_severity(phi_whole)) <= 1e-15


# ---------------------------------------------------------------------------------------------------------
# The paper's Fig. 3 settings (30 fps, D = 0.2, te = 5 ms and 11.11 ms), worked out by hand
# ---------------------------------------------------------------------------------------------------------
def test_paper_fig3_values_by_hand():
    # f = 95 Hz: T = 1/95 s = 10.526 ms, ON time D*T = 1/475 s = 2.105 ms; frame time 1/30 s.
    # (1/30) mod T = 1/30 - 3/95 = 1/570 s = 1.754 ms, and 6/570 = 1/95 = T: the phase pattern repeats every
    # 6 frames: ts = 0, 1.754, 3.509, 5.263, 7.018, 8.772 ms.
    # te = 5 ms:  [0,5): 2.105 | [1.754,6.754): ON 1.754..2.105 = 0.351 | [3.509,8.509): 0 | [5.263,..): 0 |
    #             [7.018,12.018): ON 10.526..12.018 = 1.491 | [8.772,13.772): 10.526..12.632 = 2.105 ms
    #             -> FSI = 1 (the light vanishes in 2 of 6 frames).
    # te = 11.11 ms = T + 0.585 ms: each frame gets one whole ON time (2.105) plus the overlap of the
    #             0.585 ms remainder: 0.585 at ts = 0, 0.351 at ts = 1.754, 0 otherwise ->
    #             Phi = 2.690, 2.456, 2.105, 2.105, 2.105, 2.105 ms; FSI = 0.585 / 4.795 = 0.122 (residual flicker).
    T, D, tf = 1 / 95, 0.2, 1 / 30
    ts = frame_phase(0.0, np.arange(6), tf, T)
    np.testing.assert_allclose(ts * 1e3, [0, 1.7544, 3.5088, 5.2632, 7.0175, 8.7719], atol=1e-4)
    short = pwm_exposure(ts, 0.005, T, D) * 1e3
    np.testing.assert_allclose(short, [2.1053, 0.3509, 0, 0, 1.4912, 2.1053], atol=1e-4)
    assert flicker_severity(short) == 1.0
    long_ = pwm_exposure(ts, 1 / 90, T, D) * 1e3
    np.testing.assert_allclose(long_, [2.6901, 2.4561, 2.1053, 2.1053, 2.1053, 2.1053], atol=1e-4)
    assert abs(float(flicker_severity(long_)) - (1 / 90 - 1 / 95) / (2 / 475 + 1 / 90 - 1 / 95)) < 1e-12


def test_upstream_case_table_bug_is_absent():
    # ISET-LFM code (flicker_model.py): D = 0.7, te = 25 ms, 90 Hz gives 348.5 upstream instead of ~18.3 ms
    T = 1 / 90
    for ph in np.linspace(0, T, 50, endpoint=False):
        assert rel_err(pwm_exposure(ph, 0.025, T, 0.7), exact_phi(ph, 0.025, T, 0.7)) <= REL
    assert abs(pwm_exposure(0.0, 0.025, T, 0.7) - 0.018333333333333333) < 1e-15


# ---------------------------------------------------------------------------------------------------------
# Frame and row phases
# ---------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [0, 1, 59, 10**6, 10**9, 2**40])
def test_frame_phase_exact_for_huge_frame_index(n):
    ph0, tf, T = 0.00123, 1 / 60, 1 / 97
    got = frame_phase(ph0, n, tf, T)
    ref = (Fr(ph0) + n * Fr(tf)) % Fr(T)
    assert abs(Fr(float(got)) - ref) <= 4 * Fr(np.spacing(T))


def test_frame_phase_recursion_drifts_but_closed_form_does_not():
    ph0, tf, T = 0.0, 1 / 60, 1 / 97
    ts = 0.0
    for _ in range(200_000):
        ts = math.fmod(ts + tf, T)
    ref = (200_000 * Fr(tf)) % Fr(T)
    closed = frame_phase(ph0, 200_000, tf, T)
    assert abs(Fr(float(closed)) - ref) < abs(Fr(ts) - ref)


def test_row_phase_vectorised():
    T, td = 1 / 105, 10e-6
    rows = np.arange(540)
    ph = row_phase(np.array([0.0, 0.003])[:, None], rows, td, T)
    assert ph.shape == (2, 540)
    for i in (0, 1, 333, 539):
        ref = (Fr(0.003) + i * Fr(td)) % Fr(T)
        assert abs(Fr(float(ph[1, i])) - ref) <= 4 * Fr(np.spacing(T))
    assert np.all((ph >= 0) & (ph < T))


# ---------------------------------------------------------------------------------------------------------
# Time-bin weights
# ---------------------------------------------------------------------------------------------------------
def test_bin_weights_compose_any_window():
    T, D, led_phase = 1 / 90, 0.3, 0.0017
    edges = np.linspace(0.0, 0.02, 17)
    w = bin_weights(edges, T, D, led_phase)
    assert w.shape == (16,)
    total = (w * np.diff(edges)).sum()
    assert abs(total - pwm_exposure(-led_phase, 0.02, T, D)) < 1e-17
    # hand value: bin 0 covers [0, 1.25 ms); the LED rose at 1.7 ms - T = -9.41 ms and fell at -9.41 + 3.33 ms,
    # so it is OFF until its next rise at 1.7 ms: weight 0; bin 1 [1.25, 2.5) ms is ON from 1.7 ms: 0.8/1.25
    assert w[0] == 0.0
    assert abs(w[1] - (2.5e-3 - 1.7e-3) / 1.25e-3) < 1e-12


def test_bin_weights_per_light_broadcast_and_torch():
    edges = np.tile(np.linspace(0, 0.011, 9), (4, 1))
    T = np.array([1 / 90, 1 / 100, 1 / 110, 1 / 120])
    D = np.array([0.1, 0.2, 0.3, 0.4])
    w = bin_weights(edges, T, D, led_phase=np.zeros(4))
    wt = bin_weights(torch.tensor(edges), torch.tensor(T), torch.tensor(D))
    assert w.shape == (4, 8)
    np.testing.assert_allclose(wt.numpy(), w, rtol=1e-14)
    for i in range(4):
        ref = [float(exact_phi(edges[i, k], edges[i, k + 1] - edges[i, k], T[i], D[i]))
               / (edges[i, k + 1] - edges[i, k]) for k in range(8)]
        np.testing.assert_allclose(w[i], ref, rtol=1e-12, atol=1e-15)


def test_bin_weights_rejects_bad_edges():
    with pytest.raises(ValueError, match="edges"):
        bin_weights(np.array([0.0, 0.002, 0.001]), 0.01, 0.2)
    with pytest.raises(ValueError, match="edges"):
        bin_weights(np.array([0.0]), 0.01, 0.2)


# ---------------------------------------------------------------------------------------------------------
# Trapezoidal pulses
# ---------------------------------------------------------------------------------------------------------
def _mp_trapezoid(ph, te, T, D, tr, tf):
    mpmath.mp.dps = 30
    T_, D_, tr_, tf_ = map(mpmath.mpf, (T, D, tr, tf))

    def level(t):
        u = t - mpmath.floor(t / T_) * T_

        def step(x, w):
            if w == 0:
                return mpmath.mpf(1) if x >= 0 else mpmath.mpf(0)
            return min(max(mpmath.mpf(0.5) + x / w, 0), 1)
        return step(u, tr_) + step(u - T_, tr_) - step(u - D_ * T_, tf_)

    a, b = mpmath.mpf(ph), mpmath.mpf(ph) + mpmath.mpf(te)
    pts = [a]
    for k in range(int(mpmath.floor(a / T_)) - 1, int(mpmath.floor(b / T_)) + 2):
        for e in (k * T_ - tr_ / 2, k * T_ + tr_ / 2, k * T_ + D_ * T_ - tf_ / 2, k * T_ + D_ * T_ + tf_ / 2):
            if a < e < b:
                pts.append(e)
    pts = sorted(pts) + [b]
    return mpmath.quad(level, pts)


@settings(max_examples=60, deadline=None)
@given(duty=st.floats(0.05, 0.95), phase_f=st.floats(-3, 3), exp_f=st.floats(0, 4.5),
       rise_f=st.floats(0, 1), fall_f=st.floats(0, 1))
def test_trapezoid_against_mpmath(duty, phase_f, exp_f, rise_f, fall_f):
    T = 1 / 100
    room = min(duty, 1 - duty) * T
    tr, tf = rise_f * room, fall_f * room
    ph, te = phase_f * T, exp_f * T
    got = pwm_exposure(ph, te, T, duty, rise_time=tr, fall_time=tf)
    ref = _mp_trapezoid(ph, te, T, duty, tr, tf)
    assert abs(got - float(ref)) <= 1e-12 * max(float(ref), T)


def test_trapezoid_keeps_mean_and_tends_to_ideal():
    T, D = 1 / 90, 0.25
    ph = np.linspace(0, T, 101)
    for tr, tf in ((1e-4, 3e-4), (2e-3, 0.0)):
        np.testing.assert_allclose(pwm_exposure(ph, 5 * T, T, D, rise_time=tr, fall_time=tf), 5 * D * T, rtol=1e-12)
    ideal = pwm_exposure(ph, 0.004, T, D)
    near = pwm_exposure(ph, 0.004, T, D, rise_time=1e-9, fall_time=1e-9)
    assert np.abs(near - ideal).max() <= 1e-9  # the ramps shift at most w/8 of ON time per edge
    with pytest.raises(ValueError, match="rise_time"):
        pwm_exposure(0.0, 0.001, T, 0.01, rise_time=1e-3)


# ---------------------------------------------------------------------------------------------------------
# torch: dtype, device, gradients
# ---------------------------------------------------------------------------------------------------------
def test_torch_gradcheck_float64():
    # away from pulse edges the exposure is differentiable in every argument
    ph = torch.tensor([0.0013, 0.0061, -0.0023], dtype=torch.float64, requires_grad=True)
    te = torch.tensor([0.0042, 0.0251, 0.0111], dtype=torch.float64, requires_grad=True)
    T = torch.tensor([0.0101, 0.0093, 0.0087], dtype=torch.float64, requires_grad=True)
    D = torch.tensor([0.35, 0.71, 0.22], dtype=torch.float64, requires_grad=True)
    A = torch.tensor([1.5, 0.5, 2.0], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda *a: pwm_exposure(*a), (ph, te, T, D, A), eps=1e-8, atol=1e-7)


def test_torch_float32_error_is_documented_bound():
    rng = np.random.default_rng(3)
    T = rng.uniform(1 / 120, 1 / 90, 5000)
    ph = rng.uniform(0, 1, 5000) * T
    te = rng.uniform(0, 3, 5000) * T
    D = rng.uniform(0, 1, 5000)
    got = pwm_exposure(*(torch.tensor(x, dtype=torch.float32) for x in (ph, te, T, D)))
    assert got.dtype == torch.float32
    ref = pwm_exposure(*(np.float32(x).astype(np.float64) for x in (ph, te, T, D)))
    err = np.abs(got.double().numpy() - ref) / np.maximum(te, T)
    assert err.max() <= 2e-6  # docs/guide/flicker.md: float32 error is of order 1e-6 of max(te, T)


# ---------------------------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, name", [
    (dict(period=0.0), "period"), (dict(period=-0.01), "period"), (dict(period=float("nan")), "period"),
    (dict(period=float("inf")), "period"), (dict(exposure=-1e-3), "exposure"),
    (dict(exposure=float("nan")), "exposure"), (dict(duty=1.2), "duty"), (dict(duty=-0.1), "duty"),
    (dict(duty=float("nan")), "duty"), (dict(phase=float("inf")), "phase"), (dict(amplitude=-1.0), "amplitude"),
    (dict(offset=float("nan")), "offset"), (dict(phase=np.zeros(3), exposure=np.zeros(4)), "shape"),
])
def test_bad_input_names_argument(kwargs, name):
    args = dict(phase=0.0, exposure=0.005, period=0.01, duty=0.2)
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        pwm_exposure(**args)
    if name != "shape":  # the torch path checks the same things
        targs = {k: torch.as_tensor(v, dtype=torch.float64) for k, v in args.items()}
        with pytest.raises(ValueError, match=name):
            pwm_exposure(**targs)


def test_unchecked_call_still_never_returns_silent_nan():
    with pytest.raises(ValueError, match="period"):
        pwm_exposure(np.zeros(3), 0.005, np.array([0.01, -1.0, 0.01]), 0.2, check=False)


def test_flicker_severity_conventions():
    assert float(flicker_severity(np.array([1.0, 3.0]))) == 0.5
    assert float(flicker_severity(np.zeros(5))) == 0.0  # all dark: 0/0 defined as 0
    t = flicker_severity(torch.tensor([[0.0, 0.0], [2.0, 2.0], [0.0, 1.0]]), dim=-1)
    assert t.tolist() == [0.0, 0.0, 1.0]
    with pytest.raises(ValueError, match="phi"):
        flicker_severity(np.array([1.0, -1.0]))
    with pytest.raises(ValueError, match="phi"):
        flicker_severity(np.array([1.0, np.nan]))


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_tiny_negative_phase_stays_before_the_rising_edge(backend):
    # found by hypothesis: fmod(-1.6e-164, 1) + 1 rounds to 1, which moved the window onto the ON pulse
    assert pwm_exposure(-1.5750754303861668e-164, 1.6570902878237335e-187, 1.0, 0.5, backend=backend) == 0.0
    got = pwm_exposure(-1e-20, 1e-19, 1.0, 0.5, backend=backend)  # OFF for 1e-20 s, then ON
    assert rel_err(got, exact_phi(-1e-20, 1e-19, 1.0, 0.5)) <= REL
    t = pwm_exposure(torch.tensor(-1e-20, dtype=torch.float64), 1e-19, 1.0, 0.5)
    assert rel_err(t, exact_phi(-1e-20, 1e-19, 1.0, 0.5)) <= REL


def test_forked_worker_after_openmp_use_does_not_hang():
    # numba's parallel layer is not fork-safe once the parent used OpenMP (torch does): workers use the serial build
    import multiprocessing as mp
    torch.randn(512, 512) @ torch.randn(512, 512)  # parent enters OpenMP
    pwm_exposure(np.zeros(10_000), 0.004, 0.01, 0.3)
    ctx = mp.get_context("fork")
    with ctx.Pool(1) as pool:
        res = pool.apply_async(float, (pwm_exposure(0.0, 0.005, 0.01, 0.2),))
        assert res.get(timeout=60) == 0.002
        res = pool.apply_async(_sum_in_child)
        assert abs(res.get(timeout=60) - 10_000 * 0.003) < 1e-9


def _sum_in_child():
    return float(pwm_exposure(np.zeros(10_000), 0.004, 0.01, 0.3).sum())


@pytest.mark.parametrize("exposure, period, duty, rise, fall", [
    (4e-3, 1 / 100, 0.25, 0.0, 0.0),        # the docstring's case
    (3e-3, 1 / 90, 0.1, 0.0, 0.0),          # long dark gap: most phases miss
    (5e-3, 1 / 120, 0.5, 0.0, 0.0),         # exposure longer than the gap: never missed
    (2e-3, 1 / 95, 0.3, 4e-4, 1e-4),        # trapezoid: the ramps shorten the gap
    (1e-9, 1 / 100, 0.999, 0.0, 0.0),       # stiff: a 10 us gap and a 1 ns exposure
    (1e-3, 1 / 100, 0.0, 0.0, 0.0),         # no pulse at all: always missed
    (0.0, 1 / 100, 0.5, 0.0, 0.0),          # empty exposure receives nothing
])
def test_miss_probability_against_phase_sweep(exposure, period, duty, rise, fall):
    """Share of 200,001 evenly spaced phases over one period at which the exact pulse integral
    (:func:`pwm_exposure`, trapezoid included) is 0, against the closed form; torch gives the same."""
    n = 200_001
    phases = (np.arange(n) + 0.5) / n * period
    phi = pwm_exposure(phases, exposure, period, duty, rise_time=rise, fall_time=fall)
    brute = float(np.mean(phi <= 0.0))
    p = float(miss_probability(exposure, period, duty, rise, fall))
    assert p == pytest.approx(brute, abs=2.0 / n + 1e-12)
    t = miss_probability(torch.tensor(exposure, dtype=torch.float64), torch.tensor(period, dtype=torch.float64),
                         torch.tensor(duty, dtype=torch.float64), rise, fall)
    assert float(t) == pytest.approx(p, abs=1e-15)


def test_miss_probability_rejects_bad_input():
    with pytest.raises(ValueError, match="duty"):
        miss_probability(1e-3, 0.01, 1.5)
    with pytest.raises(ValueError, match="period"):
        miss_probability(1e-3, 0.0, 0.5)
