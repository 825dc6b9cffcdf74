"""The dataset applies the timing of scene-version-2 lights (lfmbench.datasets.pwm.apply_light_timing and the
gated waveforms in assembly.compose_frame): drivers share a draw, a message-sign row is its own PWM, a strobe or
an indicator is composed with its gate; checked against the waveform's exposure over the capture windows."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from lfmbench.datasets.assembly import compose_frame
from lfmbench.datasets.projection import SceneLayers
from lfmbench.datasets.pwm import (PWMParams, SceneDraw, apply_light_timing, draw_scene_pwm, gated_lights,
                                   has_light_timing, load_pwm_config)
from lfmbench.flicker import pwm_exposure
from lfmbench.flicker.waveforms import ScanRow, Strobe, waveform_from_dict

STROBE = {"kind": "strobe", "cycle_s": 0.05, "flashes": 2, "flash_s": 0.004, "gap_s": 0.003, "phase_s": 0.0021}
ROW = {"kind": "scan_row", "scan_lines": 4, "line": 3}


def _meta(lights, fps=60.0, frames=4):
    return {"fps": fps, "frames": frames, "width": 4, "height": 3,
            "groups": {"otherlights": {"flicker": True}},
            "timing": {"short_exposure_s": 0.004, "long_exposure_s": 1 / 90.0, "line_time_s": 1e-4,
                       "capture_window_s": 1 / 90.0 + 3e-4, "bins": 8},
            "lights": [{"id": i, "group": "otherlights", "kind": "tail", **extra} for i, extra in enumerate(lights)]}


def _params(n, seed=0):
    rng = np.random.default_rng(seed)
    out = {}
    for i in range(n):
        f, d = rng.uniform(90, 400), rng.uniform(0.1, 0.9)
        out[i] = PWMParams(period_s=1 / f, duty=d, phase_s=rng.uniform(0, 1 / f), rise_s=0.0, fall_s=0.0, freq_hz=f)
    return out


def test_v1_lights_are_left_as_drawn():
    meta = _meta([{}, {}])
    draw = SceneDraw(_params(2), {})
    assert not has_light_timing(meta)
    assert apply_light_timing(draw, meta) is draw and gated_lights(meta) == {}


def test_drivers_share_the_first_lights_draw_and_rows_get_their_phase():
    meta = _meta([{"driver": "o1.tail"}, {"driver": "o1.tail"}, {}, {"driver": "sign", "waveform": ROW},
                  {"driver": "sign", "waveform": {**ROW, "line": 1}}, {"waveform": STROBE}])
    p = _params(6)
    out = apply_light_timing(SceneDraw(p, {}), meta).lights
    assert out[0] == out[1] == p[0] and out[2] == p[2] and out[5] == p[5]
    T, D, ph = p[3].period_s, p[3].duty, p[3].phase_s
    assert out[3].period_s == T and out[3].duty == pytest.approx(D / 4)
    assert out[3].phase_s == pytest.approx((ph + 3 * T / 4) % T) and out[4].phase_s == pytest.approx((ph + T / 4) % T)
    # the row's PWM exposes exactly as the scan row would
    w = ScanRow(scan_lines=4, line=3)
    for start in (0.0, 0.0123, 0.5):
        assert float(pwm_exposure(start - out[3].phase_s, 0.002, out[3].period_s, out[3].duty)) == pytest.approx(
            float(w.exposure(start, 0.002, T, D, ph)), rel=1e-9, abs=1e-15)
    assert set(gated_lights(meta)) == {5}


def test_ramps_scaled_for_the_rows_short_duty():
    meta = _meta([{"waveform": {**ROW, "scan_lines": 16, "line": 0}}])
    p = {0: PWMParams(period_s=0.01, duty=0.5, phase_s=0.0, rise_s=1e-3, fall_s=1e-3, freq_hz=100.0)}
    r = apply_light_timing(SceneDraw(p, {}), meta).lights[0]
    assert r.duty == pytest.approx(0.5 / 16)
    assert (r.rise_s + r.fall_s) / 2 <= min(r.duty, 1 - r.duty) * r.period_s * (1 + 1e-12)


def test_draw_scene_pwm_applies_the_timing():
    meta = _meta([{"driver": "d"}, {"driver": "d"}, {"waveform": ROW}])
    d = draw_scene_pwm(load_pwm_config(), meta, np.random.default_rng(1))
    assert d.lights[0] == d.lights[1] != d.lights[2]
    assert 0.1 / 4 <= d.lights[2].duty <= 0.5 / 4


@pytest.mark.parametrize("shutter", ["global", "rolling"])
def test_gated_light_composed_with_its_gate(shutter):
    """A 3 x 2 px layer of rate 1 e-/s in every bin: the composed LPD, SPD and ground truth of each row are
    the strobe's exposure (and flicker-free exposure) over that row's window, for frames on and between flashes."""
    meta = _meta([{"waveform": STROBE}, {}])
    K, H, W = 8, 3, 4
    ones = {pd: torch.ones((K, H, 2)) for pd in ("lpd", "spd")}
    frames = 4
    layers = SceneLayers("s", {pd: torch.zeros((frames, H, W)) for pd in ("lpd", "spd")}, {},
                         [[(0, "otherlights", (0, 0, H, 2), ones), (1, "otherlights", (0, 2, H, 4), ones)]
                          for _ in range(frames)])
    p = _params(2, seed=3)
    params = {k: v.to_dict() for k, v in p.items()}
    wf = Strobe(**{k: v for k, v in STROBE.items() if k != "kind"})
    tm = meta["timing"]
    seen_dark = seen_lit = False
    for n in range(frames):
        out = compose_frame(layers, meta, n, (0, 0, H, W), params, {}, shutter=shutter)
        t0 = n / meta["fps"]
        for r in range(H):
            shift = r * tm["line_time_s"] if shutter == "rolling" else 0.0
            a_l = t0 + (tm["long_exposure_s"] - tm["short_exposure_s"]) / 2 + shift
            pp = p[0]
            want = float(wf.exposure(a_l, tm["short_exposure_s"], pp.period_s, pp.duty, pp.phase_s))
            assert float(out["lpd"][r, 0]) == pytest.approx(want, rel=1e-5, abs=1e-9)
            want_spd = float(wf.exposure(t0 + shift, tm["long_exposure_s"], pp.period_s, pp.duty, pp.phase_s))
            assert float(out["spd"][r, 1]) == pytest.approx(want_spd, rel=1e-5, abs=1e-9)
            want_gt = float(wf.mean_exposure(a_l, tm["short_exposure_s"], pp.duty))
            assert float(out["gt"][r, 0]) == pytest.approx(want_gt, rel=1e-5, abs=1e-9)
            # the plain PWM light next to it is composed as before
            q = p[1]
            assert float(out["lpd"][r, 3]) == pytest.approx(float(pwm_exposure(a_l - q.phase_s, tm["short_exposure_s"],
                                                                               q.period_s, q.duty)), rel=1e-5)
            seen_dark |= want_gt == 0.0
            seen_lit |= want_gt > 0.0
    assert seen_dark and seen_lit   # frames between flashes are dark in the ground truth too (the gate is signal)


def test_waveforms_in_meta_are_checked():
    meta = _meta([{"waveform": {"kind": "strobe", "flashes": 99}}])
    with pytest.raises(ValueError, match=r"meta.json: field 'lights\[0\].waveform.flashes'"):
        gated_lights(meta)
    assert waveform_from_dict(STROBE).gate()[1].shape == (2, 2)


def test_corpus_with_a_strobe_composes_alike_on_the_per_sample_and_batched_paths(tmp_path):
    """End to end on a tiny written corpus whose meta.json lights carry a strobe and a driver: the batched (pieces)
    path carries the strobe's gate (gate_slot, gate_table) and composes what the per-sample path does (noise off:
    the same float64 weights, float32 sums in another order: within 15 eps of float32)."""
    from lfmbench import corpus as C
    from lfmbench.datasets import LFMCaptureDataset, collate_pieces, simulate_batch
    from tests.data.corpus.data import H, W, fake_frames, fake_meta, fake_scene, scale_frames

    w = C.CorpusWriter(tmp_path)
    meta = fake_meta("scene00000", width=W, height=H, frames=2, bins=4, n_lights=2)
    meta["lights"][0]["waveform"] = dict(STROBE)
    meta["lights"][1]["driver"] = "o3.tail"
    fr = scale_frames(fake_frames(meta, seed=0), 1e-3, 1e-3)
    w.write_scene(meta["scene_id"], fake_scene(meta["scene_id"]), meta, fr)
    w.write_splits(0)
    kw = dict(split="all", frames=2, outputs=("input_referred", "gt"), seed=0, noise=False, samples_per_scene=2)
    ref = LFMCaptureDataset(tmp_path, **kw)
    pieces = LFMCaptureDataset(tmp_path, pieces=True, **kw)
    batch = collate_pieces([pieces[i] for i in range(len(pieces))])
    assert batch["gate_slot"].shape[0] == 2 * 2 and batch["gate_table"].shape == (4, 4 + 2 * 2)   # 2 flashes
    out = simulate_batch(batch, ref.preset)
    for i in range(len(ref)):
        want = ref[i]
        assert torch.isfinite(want["gt"]).all()
        for k in ("gt", "lpd_hcg_e", "spd_e"):
            torch.testing.assert_close(out[k][i], want[k], rtol=15 * torch.finfo(torch.float32).eps, atol=0.0)


@pytest.mark.parametrize("rolling", [False, True])
def test_capture_plan_exposures_apply_the_gate(rolling):
    """A capture plan's chopped exposure (three sub-windows) of a strobe: the waveform's exposure summed over the
    sub-windows of each row (the plan path, plan_frames.compose_plan_frame)."""
    from lfmbench.datasets.plan_frames import PlanExposure, compose_plan_frame

    meta = _meta([{"waveform": STROBE}])
    K, H = 8, 3
    ones = {pd: torch.ones((K, H, 2)) for pd in ("lpd", "spd")}
    layers = SceneLayers("s", {pd: torch.zeros((4, H, 4)) for pd in ("lpd", "spd", "short", "long")}, {},
                         [[(0, "otherlights", (0, 0, H, 2), ones)] for _ in range(4)])
    chopped = ((0.0005, 0.0004), (0.0031, 0.0002), (0.0072, 0.0009))
    lt = meta["timing"]["line_time_s"]
    ex = [PlanExposure("a", 1.0, chopped, rolling, lt)]
    p = _params(1, seed=4)[0]
    wf = Strobe(**{k: v for k, v in STROBE.items() if k != "kind"})
    for n in range(4):
        out = compose_plan_frame(layers, meta, n, (0, 0, H, 4), {0: p.to_dict()}, {}, ex, "a")
        t0 = n / meta["fps"]
        for r in range(H):
            sh = r * lt if rolling else 0.0
            want = sum(float(wf.exposure(t0 + a + sh, ln, p.period_s, p.duty, p.phase_s)) for a, ln in chopped)
            gt = sum(float(wf.mean_exposure(t0 + a + sh, ln, p.duty)) for a, ln in chopped)
            assert float(out["a"][r, 0]) == pytest.approx(want, rel=1e-5, abs=1e-9)
            assert float(out["gt"][r, 1]) == pytest.approx(gt, rel=1e-5, abs=1e-9)
