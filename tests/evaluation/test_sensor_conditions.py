"""Condition bins from each sensor's own windows: the miss probability of a union of windows (a chopped exposure)
against a brute-force phase sweep of the PWM pulse, and the dataset's per-sensor windows in the sample meta."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from lfmbench.evaluation.conditions import sample_conditions
from lfmbench.flicker import miss_probability, windows_miss_probability
from lfmbench.sensor import load_preset
from lfmbench.sensor.plan import resolve_windows


def _sweep(windows, period, duty, n=20000):
    """Share of n uniform phases at which no window meets an ON interval [phi + m T, phi + m T + D T), from the
    definition (each window against every pulse of the frame)."""
    phi = (np.arange(n) + 0.5) / n * period
    hit = np.zeros(n, bool)
    for a, length in windows:
        for m in range(-2, int((a + length) / period) + 3):
            lo = phi + m * period
            hit |= (lo < a + length) & (lo + duty * period > a)
    return 1.0 - hit.mean()


@pytest.mark.parametrize("freq, duty", [(90.0, 0.1), (123.0, 0.1), (1087.0, 0.1), (300.0, 0.5), (2000.0, 0.05)])
def test_union_miss_probability_matches_a_phase_sweep(freq, duty):
    chopped = resolve_windows(load_preset("chopped").captures[next(iter(load_preset("chopped").captures))].exposure,
                              {"short_exposure_s": 0.004, "long_exposure_s": 1 / 90})
    for wins in (chopped, [(0.011, 0.0001)], [(0.0, 0.011)]):
        got = windows_miss_probability(wins, 1 / freq, duty)
        assert got == pytest.approx(_sweep(wins, 1 / freq, duty), abs=2e-4), wins
    assert windows_miss_probability([(0.003, 0.0001)], 1 / freq, duty) == pytest.approx(
        float(miss_probability(0.0001, 1 / freq, duty)), abs=1e-12)


def test_conditions_use_each_sensors_own_windows():
    meta = {"duty": torch.tensor([[0.1, 0.5]]), "freq_hz": torch.tensor([[1087.0, 90.0]]),
            "flicker": torch.tensor([[True, False]]), "exposure_short_s": torch.tensor([0.004])}
    batch = {"gt": torch.zeros(1, 1, 1, 2, 2), "meta": dict(meta)}
    split = sample_conditions(batch)[0]["pwm_miss_prob"]
    assert split == pytest.approx(float(miss_probability(0.004, 1 / 1087.0, 0.1)))      # 0: 4 ms > a period
    batch["meta"]["miss_windows_s"] = torch.tensor([[[0.011, 0.0001]]], dtype=torch.float64)   # staggered short
    stag = sample_conditions(batch)[0]["pwm_miss_prob"]
    assert stag == pytest.approx(1 - 0.1 - 0.0001 * 1087.0, abs=1e-7)  # duty held as float32 and stag > 0.7 > split


def test_gt_common_is_the_same_for_every_sensor(tmp_path):
    """``gt_common``: one reference window through one reference projection, so datasets of different sensors give
    the same tensor for the same draw, while each sensor's own ``gt`` (its reference exposure) differs."""
    from lfmbench.datasets import LFMCaptureDataset
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1, frames=2)
    kw = dict(split="all", frames=2, cache_dir=False, noise=False, optics=False, outputs=("gt", "gt_common"), seed=3)
    got = {n: LFMCaptureDataset(root, sensor=n, **kw)[0] for n in ("staggered", "ovt")}
    base = got["staggered"]["gt_common"]
    assert base.shape == got["staggered"]["gt"].shape and float(base.min()) > 0
    torch.testing.assert_close(got["ovt"]["gt_common"], base)
    assert not torch.allclose(got["staggered"]["gt"], got["ovt"]["gt"], rtol=0.05)
    assert "miss_windows_s" in got["staggered"]["meta"] and "miss_windows_s" not in got["ovt"]["meta"]
    with pytest.raises(ValueError, match="gt_common"):
        LFMCaptureDataset(root, sensor="ovt", pieces=True, **kw)
