"""Statistics of the leaderboard against independent answers: the bootstrap CI of a mean against the t-interval,
the Wilcoxon p-value against brute-force enumeration of sign patterns, Holm against a hand computation, and
the per-scene / pooled aggregation and breakdown against explicit sums."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import stats as sps

from lfmbench.evaluation import stats
from lfmbench.evaluation.conditions import bin_label, bin_labels, load_bins, sample_conditions
from lfmbench.evaluation.results import aggregate, breakdown, per_scene


def test_bootstrap_ci_of_normal_mean_matches_t_interval():
    x = np.random.default_rng(3).normal(10.0, 2.0, 400)
    lo, hi = stats.bootstrap_ci(x)
    tlo, thi = sps.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=sps.sem(x))
    half = (thi - tlo) / 2
    # the bootstrap's sampling error at 10^4 resamples and n = 400 is a few % of the half-width
    assert lo == pytest.approx(tlo, abs=0.06 * half) and hi == pytest.approx(thi, abs=0.06 * half)
    assert stats.bootstrap_ci(x) == (lo, hi)  # seeded: reproducible


def test_bootstrap_ci_pooled_equal_weights_is_the_mean_ci_and_edge_cases():
    x = np.random.default_rng(4).normal(0.3, 0.1, 30)
    assert stats.bootstrap_ci(x, np.full(30, 7.0)) == pytest.approx(stats.bootstrap_ci(x), rel=1e-9)
    lo, hi = stats.bootstrap_ci([0.0, 1.0, 0.0, 1.0], [1, 1, 3, 3])  # pooled ratio of a 2-valued sample
    assert 0.0 <= lo < 0.5 < hi <= 1.0
    assert all(math.isnan(v) for v in stats.bootstrap_ci([1.0]))
    assert stats.bootstrap_ci([2.5, 2.5, 2.5]) == (2.5, 2.5)
    assert stats.bootstrap_ci([1.0, float("nan"), 3.0, 2.0]) == stats.bootstrap_ci([1.0, 3.0, 2.0])
    with pytest.raises(ValueError, match="confidence"):
        stats.bootstrap_ci([1, 2, 3], confidence=95)


def _brute_force_signed_rank_p(d):
    """Exact two-sided p of the signed-rank statistic by enumerating all 2^n sign patterns of the ranks."""
    d = np.asarray([v for v in d if v != 0], dtype=float)
    r = sps.rankdata(np.abs(d))  # average ranks for ties
    mu = r.sum() / 2
    obs = abs(r[d > 0].sum() - mu)
    hits = sum(abs(sum(ri for ri, s in zip(r, signs) if s) - mu) >= obs - 1e-9
               for signs in itertools.product([0, 1], repeat=len(r)))
    return hits / 2 ** len(r)


@pytest.mark.parametrize("d", [
    [0.3, -0.1, 0.25, 0.4, 0.05],
    [1.2, 0.7, 0.9, -0.2, 1.5, 0.3, 0.8, 1.1],
    [0.1, 0.1, -0.1, 0.2, 0.3, 0.3, 0.0, 0.4, -0.2],  # ties and a zero: permutation distribution
    [-0.5, -0.4, -0.6, -0.1, -0.3, -0.2],
])
def test_wilcoxon_p_equals_brute_force_enumeration(d):
    assert stats.wilcoxon_p(d) == pytest.approx(_brute_force_signed_rank_p(d), rel=1e-9)


def test_wilcoxon_edge_cases_and_paired_test():
    assert stats.wilcoxon_p([0.0, 0.0]) == 1.0 and math.isnan(stats.wilcoxon_p([]))
    assert stats.wilcoxon_p([0.1, 0.2]) == pytest.approx(0.5)  # 2 scenes can never be significant
    r = stats.paired_test([1.0, 2.0, 4.0, float("nan")], [0.5, 1.0, 1.0, 9.0])
    assert r["n"] == 3 and r["mean_diff"] == pytest.approx((0.5 + 1 + 3) / 3)
    assert r["p"] == pytest.approx(_brute_force_signed_rank_p([0.5, 1.0, 3.0]))
    assert r["ci"][0] <= r["mean_diff"] <= r["ci"][1]
    with pytest.raises(ValueError, match="paired"):
        stats.paired_test([1.0, 2.0], [1.0])


def test_holm_by_hand():
    # sorted p: 0.01 (x4), 0.02 (x3), 0.03 (x2), 0.04 (x1) -> 0.04, 0.06, 0.06 (monotone), 0.06
    assert stats.holm([0.03, 0.01, 0.04, 0.02]) == pytest.approx([0.06, 0.04, 0.06, 0.06])
    assert stats.holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])
    out = stats.holm([float("nan"), 0.2])
    assert math.isnan(out[0]) and out[1] == pytest.approx(0.2)


def _rec(sid, led, drop, rf, **cond):
    return {"scene_id": sid, "status": "ok", "conditions": cond,
            "metrics": {"led_score": led, "dropout_rate": drop, "region_frames": rf, "psnr_mu": "inf"}}


def test_per_scene_pooled_and_breakdown_by_hand():
    recs = [_rec("a", 0.8, 0.5, 2, time_of_day="night", pwm_duty=0.1),
            _rec("a", 0.6, 0.0, 6, time_of_day="night", pwm_duty=0.3),
            _rec("b", 0.9, 0.25, 4, time_of_day="day", pwm_duty=0.3),
            {"scene_id": "c", "status": "error", "error": "boom", "conditions": {}}]
    sc = {s["scene_id"]: s for s in per_scene(recs)}
    assert set(sc) == {"a", "b"} and sc["a"]["samples"] == 2
    assert sc["a"]["metrics"]["led_score"] == pytest.approx(0.7)  # mean of the scene's samples
    assert sc["a"]["metrics"]["dropout_rate"] == pytest.approx((0.5 * 2 + 0) / 8)  # pooled over region-frames
    assert sc["a"]["weights"]["region_frames"] == 8 and sc["a"]["conditions"]["pwm_duty"] == pytest.approx(0.2)
    agg = aggregate(recs, ci=True)
    assert agg["scenes"] == 4 and agg["scenes_ok"] == 3 and agg["distinct_scenes"] == 2
    assert agg["led_score"] == pytest.approx((0.7 + 0.9) / 2)  # scenes weigh equally
    assert agg["dropout_rate"] == pytest.approx((1 + 0 + 1) / 12)  # every region-frame weighs equally
    assert agg["psnr_mu"] == math.inf and agg["ci"]["led_score"] == pytest.approx([0.7, 0.9])
    bins = load_bins()
    bins = dict(bins, pwm_duty={"edges": [0.0, 0.2, 0.35, 1.0]})
    bd = breakdown(recs, "led_score", bins)
    assert bd["time_of_day"]["night"]["value"] == pytest.approx(0.7) and bd["time_of_day"]["night"]["n"] == 1
    assert bd["pwm_duty"]["[0, 0.2)"]["value"] == pytest.approx(0.8)
    assert bd["pwm_duty"]["[0.2, 0.35)"]["value"] == pytest.approx((0.6 + 0.9) / 2)
    assert bd["pwm_duty"]["[0.2, 0.35)"]["n"] == 2 and "dusk" not in bd["time_of_day"]


def test_condition_bins_and_sample_conditions(tmp_path):
    import torch

    spec = {"edges": [0.0, 5.0, float("inf")]}
    assert [bin_label(v, spec) for v in (0, 4.99, 5, 1e9, -1, None, "x")] == \
        ["[0, 5)", "[0, 5)", "[5, inf)", "[5, inf)", "n/a", "n/a", "n/a"]
    assert bin_labels(spec) == ["[0, 5)", "[5, inf)", "n/a"]
    batch = {"gt": torch.zeros(2, 3, 1, 4, 4),
             "meta": {"duty": torch.tensor([[0.2, 0.4, 1.0], [0.3, 1.0, 1.0]], dtype=torch.float64),
                      "freq_hz": torch.tensor([[100.0, 200.0, 0.0], [90.0, 0.0, 0.0]], dtype=torch.float64),
                      "flicker": torch.tensor([[True, True, False], [False, False, False]])}}
    c = sample_conditions(batch)
    assert c[0] == {"pwm_duty": pytest.approx(0.3), "pwm_freq_hz": pytest.approx(150.0)} and c[1] == {}
    # with the short exposure: the mean miss probability, 4 ms at (0.2, 100 Hz) -> 0.4, at (0.4, 200 Hz) -> 0
    batch["meta"]["exposure_short_s"] = torch.tensor([4e-3, 4e-3], dtype=torch.float64)
    c = sample_conditions(batch)
    assert c[0]["pwm_miss_prob"] == pytest.approx(0.2) and c[1] == {}
    bad = tmp_path / "b.yaml"
    bad.write_text("speed: {edges: [3, 1]}\n")
    with pytest.raises(ValueError, match=r"b\.yaml: speed\.edges"):
        load_bins(bad)


def test_load_bins_reads_a_changed_file_again_and_returns_copies(tmp_path):
    import os

    f = tmp_path / "c.yaml"
    f.write_text("speed: {edges: [0, 5, 10]}\n")
    first = load_bins(f)
    first["speed"]["edges"].append(99)            # a caller's edit does not reach the next reader
    assert load_bins(f) == {"speed": {"edges": [0, 5, 10]}}
    f.write_text("speed: {edges: [0, 7]}\n")      # same name, new content (another size and mtime)
    os.utime(f, ns=(1, 1))
    assert load_bins(f) == {"speed": {"edges": [0, 7]}}
    f.write_text("speed: {edges: [7, 0]}\n")      # a file turned bad is checked again, not served from before
    os.utime(f, ns=(2, 2))
    with pytest.raises(ValueError, match=r"c\.yaml: speed\.edges"):
        load_bins(f)
