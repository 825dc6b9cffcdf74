"""The error measures of benchmarks/studies/bench_render_v2_targets.py (issue 40): noise-corrected relative RMSE
and median against two references, the LED pixels taken inside a light's own box. Checked against the errors
computed from the known truth the references are noisy draws of."""
import sys
from pathlib import Path

import numpy as np
import pytest


BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path[:0] = [str(BENCH / "studies"), str(BENCH)]
import bench_render_v2_error as E  # noqa: E402
import bench_render_v2_targets as T  # noqa: E402


def test_corrected_rel_rmse_removes_the_references_noise():
    rng = np.random.default_rng(0)
    truth = rng.uniform(1.0, 2.0, 200_000)
    t = truth * 1.01 + 0.03 * rng.standard_normal(truth.size)  # 1 % bias and noise
    a, b = (truth + 0.05 * rng.standard_normal(truth.size) for _ in range(2))  # noisier than t
    true = np.sqrt(np.sum((t - truth) ** 2) / np.sum(truth ** 2))
    naive = np.sqrt(np.sum((t - 0.5 * (a + b)) ** 2) / np.sum((0.5 * (a + b)) ** 2))
    assert naive > 1.3 * true  # the references' noise would be counted as the setting's error
    assert T.corrected_rel_rmse(t, a, b) == pytest.approx(true, rel=0.03)


def test_median_corrected_matches_the_median_against_the_truth():
    rng = np.random.default_rng(1)
    truth = rng.uniform(0.1, 10.0, 200_000)  # errors relative to the pixel's value, as a render's
    t = truth * (1 + 0.05 * rng.standard_normal(truth.size))
    a, b = (truth * (1 + 0.06 * rng.standard_normal(truth.size)) for _ in range(2))
    raw, r, corrected = T.median_corrected(t, a, b)
    true = np.median(np.abs(t - truth) / truth)  # 0.05 x 0.674
    assert raw > 1.15 * true
    assert r == pytest.approx(0.06 / np.sqrt(2) * 0.6745, rel=0.03)  # the mean's own median error
    assert corrected == pytest.approx(true, rel=0.03)


def _frame(crop: np.ndarray) -> dict:
    return {"lights": {"otherlights": [(7, (10, 20, 10 + crop.shape[2], 20 + crop.shape[3]), crop)]}}


def test_led_error_boxed_counts_only_the_lights_own_box():
    ref = np.zeros((2, 31, 4, 6))
    ref[:, :, 0:2, 0:2] = 1.0  # the lamp's face: rows 10-11, columns 20-21 of the frame
    ref[:, :, 3, 3:6] = 5.0  # brighter light outside the face (a reflection, a lit wall)
    boxes, kinds = {7: (10, 20, 12, 22)}, {7: "tail"}
    off_face = ref.copy()
    off_face[:, :, 3, 3:6] = 0.0  # wrong outside the box only
    err = T.led_error_boxed(_frame(off_face), _frame(ref), _frame(ref), kinds, boxes)
    assert err["all"][0] == err["tail"][0] == 0.0
    dim = ref.copy()
    dim[:, :, 0:2, 0:2] = 0.9  # the face 10 % too dark
    err = T.led_error_boxed(_frame(dim), _frame(ref), _frame(ref), kinds, boxes)
    assert err["all"] == pytest.approx((0.1, 1.0)) and err["tail"] == pytest.approx((0.1, 1.0))


def test_led_pixels_of_the_v2_error_study_stay_inside_the_lights_own_box():
    """An unlit lamp (its face at 1 % of the light around it) whose crop holds brighter stray light outside its
    face (a reflection, a lit wall): the LED pixels of bench_render_v2_error are the face's, so an error outside
    the face counts for nothing and one of the face counts in full (both selections: bins_error_cut, led_error)."""
    ref = np.zeros((2, 31, 4, 6))
    ref[:, :, 0:2, 0:2] = 0.01  # the unlit face: rows 10-11, columns 20-21 of the frame
    ref[:, :, 3, 3:6] = 5.0  # stray light outside it, 500 x brighter
    boxes, sc = {7: (10, 20, 12, 22)}, {"lights": [{"kind": "tail"}] * 8}
    off_face = ref.copy()
    off_face[:, :, 3, 3:6] = 0.0
    assert E.bins_error_cut(_frame(off_face), _frame(ref), boxes) == 0.0
    assert E.led_error(_frame(off_face), _frame(ref), _frame(ref), sc, boxes)["all"][0] == 0.0
    dim = ref.copy()
    dim[:, :, 0:2, 0:2] *= 0.9  # the face 10 % too dark
    assert E.bins_error_cut(_frame(dim), _frame(ref), boxes) == pytest.approx(0.1)
    assert E.led_error(_frame(dim), _frame(ref), _frame(ref), sc, boxes)["tail"][0] == pytest.approx(0.1)
    assert np.isnan(E.bins_error_cut(_frame(dim), _frame(ref), {}))  # a light without a box adds nothing


def test_verdict():
    assert T.verdict(0.015, 0.019, 0.08, 0.12) == "LED met, median met (corrected)"
    assert T.verdict(0.015, 0.021, 0.11, 0.12) == "LED missed, median missed"
    assert T.verdict(0.01, 0.01, 0.05, 0.09) == "LED met, median met"


def test_rel_error_percentiles_bound_the_median_when_a_few_pixels_change():
    rng = np.random.default_rng(2)
    m = rng.uniform(0.5, 2.0, (90, 160))
    t = m * (1 + rng.uniform(-0.2, 0.2, m.shape))  # |relative error| uniform on [0, 0.2]
    p46, p54 = T.rel_error_percentiles(t, m, m)
    assert p46 == pytest.approx(0.092, abs=0.003) and p54 == pytest.approx(0.108, abs=0.003)
    raw, _, _ = T.median_corrected(t, m, m)
    assert p46 < raw < p54
    for v in (0.0, 1e3):  # the bottom 3 of 90 rows (3.3 %) re-rendered: far off, or exact
        t2 = t.copy()
        t2[-3:] = m[-3:] * (1 + v)
        assert p46 <= T.median_corrected(t2, m, m)[0] <= p54


def test_median_by_region_splits_the_frame_by_what_it_shows():
    rng = np.random.default_rng(3)
    m = rng.uniform(0.5, 2.0, (40, 50))
    inst = np.full(m.shape, -1)  # sky above
    inst[20:, :25], inst[20:, 25:] = 0, 1  # road, a building
    light = np.full(m.shape, -1)
    light[30:32, 30:34] = 4  # a lamp's face on the building
    err = np.where(inst == 0, 0.3, np.where(inst == 1, 0.02, 0.1))
    t = m * (1 + err * rng.choice([-1, 1], m.shape))
    out = T.median_by_region(t, m, m, inst, light, ["road", "building"])
    assert set(out) == {"road", "buildings", "sky", "lamps"}
    assert out["road"][0] == pytest.approx(0.25) and out["road"][1] == pytest.approx(0.3)
    assert out["buildings"][1] == pytest.approx(0.02) and out["sky"][1] == pytest.approx(0.1)
    assert out["lamps"][0] == pytest.approx(8 / 2000)
    assert sum(v[0] for v in out.values()) == pytest.approx(1.0)


def test_mean_frames_averages_images_and_crops_and_refuses_other_crops():
    def fr(v, box=(1, 2, 3, 4)):
        return {"frame": 0, "aux": {"mask.light": np.full((4, 5), -1.0)},
                "static": {"sky": {"short": np.full((2, 4, 5), v, np.float32), "long": np.full((2, 4, 5), 2 * v)}},
                "lights": {"signals": [(3, box, np.full((8, 2, 2, 2), v, np.float32))]}}
    m = T.mean_frames([fr(1.0), fr(2.0)])
    assert m["static"]["sky"]["short"] == pytest.approx(np.full((2, 4, 5), 1.5))
    assert m["static"]["sky"]["long"] == pytest.approx(np.full((2, 4, 5), 3.0))
    lid, box, crop = m["lights"]["signals"][0]
    assert (lid, box) == (3, (1, 2, 3, 4)) and crop == pytest.approx(np.full((8, 2, 2, 2), 1.5))
    with pytest.raises(ValueError, match="light 3 of group signals"):
        T.mean_frames([fr(1.0), fr(2.0, box=(1, 2, 3, 5))])
    fewer = fr(2.0)
    fewer["lights"]["signals"] = []
    with pytest.raises(ValueError, match="group signals has other lights"):
        T.mean_frames([fr(1.0), fewer])
    held = []  # frames from a generator, summed one at a time: the mean of 1, 2, 6
    m = T.mean_frames(held.append(v) or fr(v) for v in (1.0, 2.0, 6.0))
    assert held == [1.0, 2.0, 6.0] and m["static"]["sky"]["short"] == pytest.approx(np.full((2, 4, 5), 3.0))
    assert m["static"]["sky"]["short"].dtype == np.float32 and m["lights"]["signals"][0][2] == pytest.approx(3.0)


def test_median_extrapolated_recovers_the_frames_own_median():
    c, k = 0.08, 1.9  # raw^2 = c^2 + k r^2 at two reference noises
    raw = lambda r: np.sqrt(c * c + k * r * r)  # noqa: E731
    assert T.median_extrapolated(raw(0.065), 0.065, raw(0.05), 0.05) == pytest.approx(c)
    assert np.isnan(T.median_extrapolated(0.1, 0.05, 0.09, 0.05))
    # the quadrature case (k = 1): the same as median_corrected's correction at either noise
    assert T.median_extrapolated(np.hypot(0.07, 0.06), 0.06, np.hypot(0.07, 0.04), 0.04) == pytest.approx(0.07)


def test_ref_seeds_and_halves_generalise_the_four_references():
    assert T.ref_seeds(4) == T.REF_SEEDS + T.MORE_REF_SEEDS  # --ref4-cases is the N = 2 case
    assert T.ref_seeds(8) == tuple(range(3001, 3009))
    with pytest.raises(ValueError, match="--ref-count"):
        T.ref_seeds(3)
    rng = np.random.default_rng(2)
    truth = rng.uniform(1.0, 2.0, (1, 120, 120))
    noisy = {s: truth * (1 + 0.02 * rng.standard_normal(truth.shape)) for s in T.ref_seeds(8)}

    def load(s):
        return {"frame": 0, "aux": {}, "static": {"g": {"short": noisy[s].astype(np.float32)}}, "lights": {}}

    a, b = (h["static"]["g"]["short"] for h in T.ref_halves(load, T.ref_seeds(8)))
    assert a == pytest.approx(np.mean([noisy[s] for s in (3001, 3002, 3003, 3004)], axis=0), rel=1e-5)
    assert b == pytest.approx(np.mean([noisy[s] for s in (3005, 3006, 3007, 3008)], axis=0), rel=1e-5)
    _, r8, _ = T.median_corrected(truth[0], a[0], b[0])  # each half 1/4 of one reference's noise variance
    _, r2, _ = T.median_corrected(truth[0], noisy[3001][0], noisy[3002][0])
    assert r8 == pytest.approx(r2 / 2, rel=0.05)
    one = T.ref_halves(load, (3001, 3002))  # N = 1: the references themselves
    assert one[0]["static"]["g"]["short"] is not None and np.array_equal(one[1]["static"]["g"]["short"],
                                                                          noisy[3002].astype(np.float32))


def test_fit_extrapolated_checks_the_model_on_three_or_more_points():
    c, k = 0.08, 1.9
    rs = np.array([0.065, 0.046, 0.0325, 0.023])  # 2, 4, 8, 16 references
    raws = np.sqrt(c * c + k * rs ** 2)
    for n in (3, 4):
        fc, fk, res = T.fit_extrapolated(raws[:n], rs[:n])
        assert (fc, fk) == pytest.approx((c, k)) and res < 1e-9
    bent = raws.copy()
    bent[3] -= 0.003  # the fourth point off the line the first three lie on
    assert T.fit_extrapolated(bent, rs)[2] > 0.0005 and T.fit_extrapolated(bent[:3], rs[:3])[2] < 1e-9
    raws, rs = raws[:3], rs[:3]
    # two points: the same c as median_extrapolated's
    assert T.fit_extrapolated(raws[:2], rs[:2])[0] == pytest.approx(T.median_extrapolated(raws[0], rs[0], raws[1],
                                                                                           rs[1]))
    off = raws.copy()
    off[1] += 0.004  # a middle point off the model
    assert T.fit_extrapolated(off, rs)[2] > 0.001
    assert np.isnan(T.fit_extrapolated([0.1, 0.09], [0.05, 0.05])[0])
    assert T.ref_count_of("dots as they are, light_spp 32, 8 references") == ("dots as they are, light_spp 32", 8)
    assert T.ref_count_of("dots as they are, light_spp 32") == ("dots as they are, light_spp 32", 2)


def test_run_plan_scores_every_reference_count_in_turn(tmp_path, monkeypatch, capsys):
    s8, s16 = T.ref_seeds(8), T.ref_seeds(16)
    assert s16 == tuple(range(3001, 3017)) and s16[:8] == s8
    plan = T.run_plan(["101:night:dry"], ["x"], ["x"], ["x", "y"], [8, 16, 8])
    assert plan == [("101:night:dry", T.LAMP_GROUPS, T.REF_SEEDS), ("x", None, T.REF_SEEDS),
                    ("x", None, T.REF_SEEDS + T.MORE_REF_SEEDS), ("x", None, s8), ("y", None, s8), ("x", None, s16),
                    ("y", None, s16)]
    assert T.run_plan([], [], [], [], [3]) == []  # no --ref-cases: the counts are not used
    monkeypatch.setattr(sys, "argv", ["bench", "--cases", "--lamp-cases", "--ref-cases", "x", "--ref-count", "8",
                                      "6", "3", "--out", str(tmp_path)])
    with pytest.raises(SystemExit) as e:
        T.main()
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and err[-1].endswith("error: --ref-count: 3 references; an even number >= 2 (two "
                                                  "halves) is needed")
    assert not any(tmp_path.iterdir())  # nothing written


def test_cached_frames_of_other_render_rules_are_not_reused(tmp_path, monkeypatch):
    """A frame cached under one protocol version of lfmbench-v2 (the render rules) is rendered again, not read, once
    the version changes: the night cases' published rows once mixed frames of versions 4 and 5."""
    from render_tools import render

    calls = []

    def fake_frames(sc, opts):
        calls.append(opts)
        yield {"n": len(calls)}

    monkeypatch.setattr(render, "render_frames", fake_frames)
    monkeypatch.setattr(E, "rules_version", lambda: 5)
    first, _ = E._frame({}, "opts", tmp_path, "tgt_default_x")
    again, _ = E._frame({}, "opts", tmp_path, "tgt_default_x")
    assert first == again == {"n": 1} and len(calls) == 1  # read back under the same rules
    assert E.frame_path(tmp_path, "tgt_default_x").name == "tgt_default_x_p5.pkl"
    monkeypatch.setattr(E, "rules_version", lambda: 6)
    newer, _ = E._frame({}, "opts", tmp_path, "tgt_default_x")
    assert newer == {"n": 2} and len(calls) == 2  # other rules: rendered again, the old file kept
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tgt_default_x_p5.pkl", "tgt_default_x_p6.pkl"]


def test_rules_version_is_the_v2_protocols():
    from render_tools.protocol import load_protocol

    assert E.rules_version() == load_protocol("lfmbench-v2").version >= 5
