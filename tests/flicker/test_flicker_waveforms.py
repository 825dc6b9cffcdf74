"""The light waveforms of lfmbench.flicker.waveforms: closed-form exposures against brute force.

Two independent references: fine time sampling of the instantaneous level (midpoint rule; its error is at most
one sample step per level edge inside the window), and the explicit list of every ON pulse of the waveform in
the window (each gate period, each ON interval, each PWM pulse: a Python loop, no cycle splitting).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from lfmbench.flicker import pwm_exposure
from lfmbench.flicker.waveforms import (PWM, SEVEN_SEGMENTS, WAVEFORMS, CountdownSegment, DestinationRow,
                                        GatedWaveform, Indicator, ScanRow, Strobe, gated_pwm_exposure,
                                        waveform_from_dict)

#: One instance per kind (the registry test checks that every kind is here).
CASES = {
    "pwm": PWM(),
    "scan_row": ScanRow(scan_lines=8, line=3),
    "indicator": Indicator(frequency_hz=1.5, on_fraction=0.5, phase_s=0.13),
    "strobe": Strobe(cycle_s=0.4, flashes=3, flash_s=0.03, gap_s=0.05, phase_s=0.011),
    "countdown": CountdownSegment(count_from=12, tick_s=0.25, blank_s=0.5, place="units", segment="e",
                                  phase_s=0.07),
    "destination_display": DestinationRow(scan_lines=4, line=1, pages=3, page=1, page_s=0.3, phase_s=0.02),
}


def pulses(w, start, length, period, duty, phase):
    """Exact exposure (level x s) from the explicit ON pulses of ``w`` that meet [start, start + length)."""
    end = start + length
    if isinstance(w, GatedWaveform):
        Tg, on = w.gate()
        T, D, ph = (float(x) for x in w.carrier(period, duty, phase))
        spans = []
        for k in range(math.floor((start - w.phase_s) / Tg) - 1, math.ceil((end - w.phase_s) / Tg) + 1):
            spans += [(w.phase_s + k * Tg + s, w.phase_s + k * Tg + e) for s, e in on]
    else:
        T, D, ph = ((float(x) for x in w.row_pwm(period, duty, phase)) if isinstance(w, ScanRow)
                    else (period, duty, phase))
        spans = [(start - 2 * T - ph, end + 2 * T)]   # a free-running PWM: one span with edges at ph + mT
        ph = ph - spans[0][0]
    total = 0.0
    for onset, stop in spans:
        lo, hi = max(onset, start), min(stop, end)
        if hi <= lo:
            continue
        m = np.arange(math.floor((lo - onset - ph) / T) - 1, math.ceil((hi - onset - ph) / T) + 1)
        rise = onset + ph + m * T
        # each pulse's overlap from differences to its own rising edge: an inner pulse counts exactly D * T
        total += float(np.clip(np.minimum(D * T, hi - rise) - np.maximum(0.0, lo - rise), 0.0, None).sum())
    return total


def sampled(w, start, length, period, duty, phase, n=200_000):
    """Midpoint-rule integral of ``w.level`` over the window with ``n`` samples: (value, step in s)."""
    dt = length / n
    t = start + (np.arange(n) + 0.5) * dt
    return float(w.level(t, period, duty, phase).sum() * dt), dt


def test_registry_one_entry_per_kind_and_round_trip():
    assert set(WAVEFORMS) == set(CASES)
    for kind, w in CASES.items():
        assert WAVEFORMS[kind] is type(w)
        assert waveform_from_dict(w.to_dict()) == w


@pytest.mark.parametrize("kind", sorted(CASES))
def test_exposure_against_fine_sampling(kind):
    """Random windows of 0.1 ms .. 1.5 s: the closed form within the sampling bound of the midpoint rule."""
    w = CASES[kind]
    rng = np.random.default_rng(7)
    for _ in range(6):
        start, length = rng.uniform(0.0, 3.0), float(np.exp(rng.uniform(math.log(1e-4), math.log(1.5))))
        period, duty, phase = 1 / rng.uniform(90, 400), rng.uniform(0.05, 0.95), 0.0
        phase = rng.uniform(0, period)
        got = float(w.exposure(start, length, period, duty, phase))
        ref, dt = sampled(w, start, length, period, duty, phase)
        edges = 2 * (length / period + 2) + 4 * (length / 0.05 + 2)   # PWM edges + gate edges, a bound
        assert abs(got - ref) <= edges * dt + 1e-12, (kind, start, length, got, ref)
        assert got == pytest.approx(pulses(w, start, length, period, duty, phase), rel=1e-9, abs=1e-13)


@pytest.mark.parametrize("kind", sorted(CASES))
def test_stiff_cases_against_the_pulse_list(kind):
    """Tiny duty, windows starting and ending on gate and PWM edges, tiny and very long windows."""
    w = CASES[kind]
    period, phase = 1 / 97.0, 0.0013
    starts = [0.0, 0.13, 0.13 + 1e-12, 0.13 - 1e-12, 0.011 + 0.03, 0.07 + 0.25, 0.02 + 0.3, 0.02 + 0.6, 5.3]
    if isinstance(w, GatedWaveform):
        Tg, on = w.gate()
        starts += [w.phase_s + 3 * Tg + s for s in on.ravel()]          # on the gate edges
        starts += [w.phase_s + Tg + on[0, 0] + phase + k * period for k in (0, 1)]  # on PWM rising edges
    for duty in (1e-6, 0.37, 1.0 - 1e-9, 1.0, 0.0):
        for start in starts:
            for length in (1e-9, 1e-5, 0.0113, 0.4, 3.7):
                got = float(w.exposure(start, length, period, duty, phase))
                ref = pulses(w, start, length, period, duty, phase)
                assert got == pytest.approx(ref, rel=1e-9, abs=1e-15 + 1e-12 * length), (duty, start, length)
                assert -1e-18 <= got <= length * (1 + 1e-12)


@pytest.mark.parametrize("kind", sorted(CASES))
def test_very_long_windows(kind):
    """10^3 s windows (hundreds of gate periods, ~10^5 PWM periods): closed form = explicit pulse list."""
    w = CASES[kind]
    for start, length, duty in ((0.4321, 1000.0, 0.3), (7.0, 777.7, 1e-4)):
        got = float(w.exposure(start, length, 1 / 113.0, duty, 0.002))
        assert got == pytest.approx(pulses(w, start, length, 1 / 113.0, duty, 0.002), rel=1e-9)
        # the exposure is the mean level x length up to at most one carrier pulse per ON interval (the pulse
        # train restarts at every onset, so each interval may end inside a pulse or a gap)
        runs = 2.0
        if isinstance(w, GatedWaveform):
            Tg, on = w.gate()
            runs = (length / Tg + 2) * len(on)
        bound = runs * duty / 113.0
        assert abs(got - float(w.mean_level(duty)) * length) <= bound


@pytest.mark.parametrize("kind", sorted(CASES))
def test_mean_exposure_is_the_gate_at_the_carrier_mean(kind):
    """The flicker-free exposure: brute force of the gate times the carrier's mean; over whole gate periods it
    is the mean level times the length; it is what the exposure averages to over carrier phases."""
    w = CASES[kind]
    duty = 0.4
    for start, length in ((0.05, 0.3), (1.234, 0.02), (0.0, 2.5)):
        got = float(w.mean_exposure(start, length, duty))
        t = start + (np.arange(200_000) + 0.5) * length / 200_000
        if isinstance(w, GatedWaveform):
            Tg, on = w.gate()
            u = np.mod(t - w.phase_s, Tg)[:, None]
            gate = ((u >= on[:, 0]) & (u < on[:, 1])).any(1)
            ref = float(gate.sum()) * length / 200_000 * float(w.carrier(1.0, duty, 0.0)[1])
            assert abs(got - ref) <= 20 * length / 200_000
        else:
            assert got == pytest.approx(float(w.mean_level(duty)) * length, rel=1e-12)
        # averaged over the carrier phase (uniform over a period) the PWM exposure equals the mean exposure
        T = 1 / 150.0
        phases = (np.arange(4000) + 0.5) * T / 4000
        avg = float(np.mean(w.exposure(start, length, T, duty, phases)))
        assert avg == pytest.approx(got, rel=1e-6, abs=1e-12)
    if isinstance(w, GatedWaveform):
        Tg, _ = w.gate()
        assert float(w.mean_exposure(0.3, 7 * Tg, duty)) == pytest.approx(float(w.mean_level(duty)) * 7 * Tg)


def test_scan_rows_tile_the_refresh_period_and_differ_in_a_short_exposure():
    """A 1/8 scan at full slot duty: the 8 scan lines together are ON all the time (their slots tile the
    period); an exposure shorter than a slot sees its own line lit and the others dark."""
    N, T = 8, 1 / 240.0
    rows = [ScanRow(scan_lines=N, line=k) for k in range(N)]
    for start, length in ((0.001, 0.0137), (0.3, 1e-4), (0.0, 2.0)):
        total = sum(float(r.exposure(start, length, T, 1.0, 0.0005)) for r in rows)
        assert total == pytest.approx(length, rel=1e-12)
    short = T / N / 4
    lit = [float(r.exposure(0.0005 + 3 * T / N + short, short, T, 1.0, 0.0005)) for r in rows]
    assert lit[3] == pytest.approx(short) and sum(lit) == pytest.approx(short)
    # the same sign dimmed to 30 %: each line ON for 0.3 of its slot, its own PWM shifted by line * T / N
    r5 = rows[5]
    assert float(r5.exposure(0.0, 1.0, T, 0.3, 0.0)) == pytest.approx(0.3 / N, rel=1e-9)
    assert float(r5.exposure(0.0, 1e-3, T, 0.3, 0.0)) == pytest.approx(
        float(pwm_exposure(-5 * T / N, 1e-3, T, 0.3 / N)))


def test_indicator_pwm_restarts_at_each_blink():
    """Every blink carries the same pulse train: its exposure over any ON interval is the PWM's from onset."""
    w = Indicator(frequency_hz=1.25, on_fraction=0.55, phase_s=0.2)
    on_len = 0.55 / 1.25
    per_blink = float(pwm_exposure(-0.003, on_len, 0.01, 0.25))
    for k in (0, 1, 17, 1000):
        assert float(w.exposure(0.2 + k / 1.25, on_len, 0.01, 0.25, 0.003)) == pytest.approx(per_blink, rel=1e-12)
        assert float(w.exposure(0.2 + k / 1.25 + on_len, 1 / 1.25 - on_len, 0.01, 0.25, 0.003)) == 0.0


def test_countdown_segments_by_hand():
    """12, 11, ..., 1: the units digit's segment e is lit for 2, 0, 8, 6 (digits with e: 0 2 6 8) -> values 12,
    10, 8, 6, 2; the tens digit's b for 12, 11, 10 (then blank)."""
    w = CountdownSegment(count_from=12, tick_s=1.0, blank_s=3.0, place="units", segment="e")
    lit_values = [v for v in range(12, 0, -1) if "e" in SEVEN_SEGMENTS[v % 10]]
    assert lit_values == [12, 10, 8, 6, 2]
    Tg, on = w.gate()
    assert Tg == 15.0
    np.testing.assert_array_equal(on, [[0, 1], [2, 3], [4, 5], [6, 7], [10, 11]])
    tens = CountdownSegment(count_from=12, tick_s=1.0, blank_s=3.0, place="tens", segment="b")
    np.testing.assert_array_equal(tens.gate()[1], [[0, 3]])          # adjacent seconds merged: one PWM run
    assert float(tens.mean_exposure(0.0, 15.0, 0.5)) == pytest.approx(1.5)
    never = CountdownSegment(count_from=9, tick_s=1.0, place="tens", segment="a")
    assert never.gate()[1].shape == (0, 2)
    assert float(never.exposure(0.3, 20.0, 0.01, 0.5, 0.0)) == 0.0


def test_strobe_triple_flash_by_hand():
    """Three 30 ms flashes 50 ms apart every 0.4 s at DC (duty 1): 90 ms of light per cycle."""
    w = Strobe(cycle_s=0.4, flashes=3, flash_s=0.03, gap_s=0.05, phase_s=0.0)
    assert float(w.exposure(0.0, 0.4, 0.01, 1.0, 0.0)) == pytest.approx(0.09)
    assert float(w.exposure(0.0, 4.0, 0.01, 1.0, 0.0)) == pytest.approx(0.9)
    assert float(w.exposure(0.031, 0.048, 0.01, 1.0, 0.0)) == 0.0                 # between flashes 1 and 2
    assert float(w.exposure(0.07, 0.02, 0.01, 1.0, 0.0)) == pytest.approx(0.01)   # the start of flash 2


def test_destination_display_is_a_scan_row_during_its_page():
    w = DestinationRow(scan_lines=4, line=2, pages=2, page=1, page_s=2.0, phase_s=0.0)
    row = ScanRow(scan_lines=4, line=2)
    T = 1 / 300.0
    # inside page 1 (which starts at 2 s, where the scan restarts): the scan row shifted to the page onset
    assert float(w.exposure(2.5, 0.01, T, 0.6, 0.0)) == pytest.approx(float(row.exposure(0.5, 0.01, T, 0.6, 0.0)))
    assert float(w.exposure(0.5, 1.0, T, 0.6, 0.0)) == 0.0                         # page 0: this text is dark


@pytest.mark.parametrize("kind", sorted(CASES))
def test_trapezoidal_carrier_against_fine_sampling(kind):
    """Ramped PWM edges (the draw's rise and fall times): the closed form against sampling the ramped level;
    ramps too long for a row's duty D/N are scaled down (fit_ramps) the same way in both."""
    w = CASES[kind]
    T, D, ph, tr, tf = 1 / 110.0, 0.35, 0.002, 4e-4, 9e-4
    for start, length in ((0.1234, 0.05), (1.0, 0.6)):
        got = float(w.exposure(start, length, T, D, ph, tr, tf))
        dt = length / 200_000
        t = start + (np.arange(200_000) + 0.5) * dt
        ref = float(w.level(t, T, D, ph, tr, tf).sum() * dt)
        assert abs(got - ref) <= 4 * (length / 0.05 + 2) * dt + 1e-12
    if kind == "pwm":
        assert float(w.exposure(0.3, 0.02, T, D, ph, tr, tf)) == pytest.approx(
            float(pwm_exposure(0.3 - ph, 0.02, T, D, rise_time=tr, fall_time=tf)))


def test_gated_core_broadcasts():
    """(F, R) windows against (L, 1, 1) lights: one call, the shape of the broadcast."""
    starts = np.linspace(0.0, 1.0, 6)[:, None] + 1e-5 * np.arange(4)[None, :]       # (6, 4)
    T = np.array([0.01, 0.008, 0.005])[:, None, None]                              # (3, 1, 1)
    out = gated_pwm_exposure(starts, 0.004, 0.5, np.array([[0.0, 0.2], [0.3, 0.35]]), T, 0.3, 0.0)
    assert out.shape == (3, 6, 4)
    one = gated_pwm_exposure(starts[2, 1], 0.004, 0.5, np.array([[0.0, 0.2], [0.3, 0.35]]), 0.008, 0.3, 0.0)
    assert out[1, 2, 1] == pytest.approx(float(one), rel=1e-15)


def test_a_batch_of_gate_tables_in_torch_equals_each_waveform():
    """Every gated kind in one torch batch (GateTable rows padded with empty intervals, as the dataset's batched
    and device paths carry them) against each waveform's own numpy exposure and mean exposure, with and without
    ramps: the same float64 operations, so equal to a few units in the last place (1e-12 relative)."""
    import torch

    from lfmbench.datasets.pieces import gate_rows, gate_table

    kinds = [w for w in CASES.values() if isinstance(w, GatedWaveform)]
    rows = gate_rows(w.table() for w in kinds)                                  # (G, 4 + 2 M)
    assert rows.shape[1] > 4 + 2 * min(w.gate()[1].shape[0] for w in kinds)    # some tables are padded
    tab = gate_table(rows)                                                      # fields (G, 1, 1)
    rng = np.random.default_rng(5)
    start = rng.uniform(0.0, 6.0, (len(kinds), 7, 4))
    length = rng.uniform(0.0, 0.03, (len(kinds), 7, 4))
    T, D, ph = 1 / 130.0, 0.4, 0.003
    for rise, fall in ((0.0, 0.0), (3e-4, 5e-4)):
        tt = lambda x: torch.full((len(kinds), 1, 1), x, dtype=torch.float64)  # noqa: E731
        r, f = (x if x == 0.0 else tt(x) for x in (rise, fall))
        got = tab.exposure(torch.from_numpy(start), torch.from_numpy(length), tt(T), tt(D), tt(ph), r, f)
        mean = tab.mean_exposure(torch.from_numpy(start), torch.from_numpy(length), tt(D))
        for g, w in enumerate(kinds):
            want = w.exposure(start[g], length[g], T, D, ph, rise, fall)
            assert want.max() > 0
            np.testing.assert_allclose(got[g].numpy(), want, rtol=1e-12, atol=1e-18)
            np.testing.assert_allclose(mean[g].numpy(), w.mean_exposure(start[g], length[g], D), rtol=1e-12,
                                       atol=1e-18)


@pytest.mark.parametrize("d, message", [
    ({"kind": "laser"}, "scene.json: field 'w.kind' 'laser' not one of"),
    ({"kind": "indicator", "frequency_hz": 5.0}, "field 'w.frequency_hz' must be in [1.0, 2.0]"),
    ({"kind": "strobe", "flashes": 4, "flash_s": 0.1, "gap_s": 0.1, "cycle_s": 0.5},
     "field 'w.cycle_s' 4 flashes of 0.1 s"),
    ({"kind": "scan_row", "scan_lines": 8, "line": 8}, "field 'w.line' must be < scan_lines = 8"),
    ({"kind": "scan_row", "scan_lines": 10**6}, "field 'w.scan_lines' must be an integer in [1, 64]"),
    ({"kind": "countdown", "segment": "h"}, "field 'w.segment' must be one of"),
    ({"kind": "destination_display", "pages": 2, "page": 2}, "field 'w.page' must be < pages = 2"),
    ({"kind": "pwm", "duty": 0.5}, "unknown field 'w.duty'"),
    ("strobe", "field 'w' must be an object"),
])
def test_bad_waveforms_name_the_field_and_file(d, message):
    with pytest.raises(ValueError) as err:
        waveform_from_dict(d, "w", "scene.json")
    assert message in str(err.value) and "\n" not in str(err.value)
    assert str(err.value).startswith("scene.json:")
