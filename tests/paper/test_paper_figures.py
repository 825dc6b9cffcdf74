"""``lfmbench paper-figures``: the PWM choices of Figs. 4-7 against independent computations, the figure scene
files, every figure on a tiny generated corpus, and the command's input errors."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import yaml

from lfmbench.paper import common, figures as P
from lfmbench.flicker import pwm_exposure

FPS = 60.0


def _paper_timing():
    """(short exposure s, long exposure s, fps) of the Figs. 4-6 scene file and render profile."""
    scene = json.loads((P.CONFIG_DIR / "fig4_6_scene.json").read_text())
    prof = yaml.safe_load((P.CONFIG_DIR / "fig4_6_render.yaml").read_text())
    return scene["timing"]["short_exposure_s"], prof["long_exposure_s"], prof["fps"]


def _on_time_sampled(t0, length, phase, freq, duty, n=200_001):
    """ON time (s) of a PWM square wave over [t0, t0 + length), by sampling it densely (midpoint rule)."""
    t = t0 + (np.arange(n) + 0.5) * (length / n)
    on = np.mod(t - phase, 1.0 / freq) < duty / freq
    return on.mean() * length


# ------------------------------------------------------------------------------------ PWM choices
def test_dropout_phase_puts_the_light_off_for_the_whole_short_exposure():
    ts, tl, fps = _paper_timing()
    assert (ts, fps) == (0.005, 60.0) and tl == pytest.approx(1 / 90)
    a0 = (tl - ts) / 2
    f, d = P.DROPOUT_PWM
    ph = P.dropout_phase(f, d, 1, 3, fps, a0, ts)
    starts = np.arange(3) / fps + a0
    phi = pwm_exposure(starts - ph, ts, 1 / f, d)
    assert phi[1] == 0.0                                   # frame 1: OFF for all of the 5 ms
    assert min(phi[0], phi[2]) > 0.5 * d / f              # frames 0, 2: most of a pulse
    # independent: sample the square wave; and the window can move 0.3 ms either way and stay dark
    assert _on_time_sampled(starts[1], ts, ph, f, d) == 0.0
    assert _on_time_sampled(starts[1] - 3e-4, ts + 6e-4, ph, f, d) == 0.0
    assert _on_time_sampled(starts[0], ts, ph, f, d) == pytest.approx(phi[0], abs=1e-7)
    # the second dropout of Fig. 5 (frame 2)
    f2, d2 = P.DROPOUT2_PWM
    ph2 = P.dropout_phase(f2, d2, 2, 3, fps, a0, ts)
    assert _on_time_sampled(starts[2], ts, ph2, f2, d2) == 0.0
    assert _on_time_sampled(starts[1], ts, ph2, f2, d2) > 0.0


def test_dropout_phase_refuses_a_duty_that_cannot_hide_the_light():
    with pytest.raises(ValueError, match="OFF time"):
        P.dropout_phase(100.0, 0.6, 1, 3, 60.0, 0.003, 0.005)   # 4 ms OFF < 5 ms exposure


def test_fig7_phases_occlude_the_target_rows_and_band_above_the_tail_lights():
    scene = json.loads((P.CONFIG_DIR / "fig7_scene.json").read_text())
    prof = yaml.safe_load((P.CONFIG_DIR / "fig7_render.yaml").read_text())
    ts, tl, td = scene["timing"]["short_exposure_s"], prof["long_exposure_s"], prof["line_time_s"]
    f, d = P.FIG7_PWM
    assert (f, d) == (105.0, 0.2)
    a0 = (tl - ts) / 2
    upper, lower, target = (146, 160), (185, 233), (190, 201)
    pa, pb = P.fig7_phases(upper, lower, target, f, d, a0, ts, td)
    rows = np.arange(360)

    def expo(phase, r):  # row r's window opens r * td later
        return pwm_exposure(a0 + r * td - phase, ts, 1 / f, d)

    # phase B: no ON time at all on the target's rows, the rows just below are lit
    assert np.all(expo(pb, np.arange(*target)) == 0.0)
    assert all(_on_time_sampled(a0 + r * td, ts, pb, f, d) == 0.0 for r in (target[0], target[1] - 1))
    assert expo(pb, target[1] + 5) > 0
    # phase A: the high brake-light rows are dark, the tail-light rows lit: a band with its edge between them
    assert np.all(expo(pa, np.arange(*upper)) == 0.0)
    assert np.all(expo(pa, np.arange(lower[0], lower[0] + 20)) > 0)
    assert expo(pa, lower[1]) > 0.5 * d * ts
    # the two phases differ and both leave some rows fully dark and some lit (banding, not a global dimming)
    assert abs(pa - pb) > 1e-4
    for ph in (pa, pb):
        e = expo(ph, rows)
        assert (e == 0).sum() > 30 and (e > 0).sum() > 30
    assert np.allclose(P.row_exposure(rows, pb, f, d, a0, ts, td), expo(pb, rows))


# ------------------------------------------------------------------------------------ scene files
def test_figure_scene_files_have_the_papers_settings():
    from render_tools.scene import load_scene

    s46 = load_scene(P.CONFIG_DIR / "fig4_6_scene.json")
    s7 = load_scene(P.CONFIG_DIR / "fig7_scene.json")
    p46 = yaml.safe_load((P.CONFIG_DIR / "fig4_6_render.yaml").read_text())
    p7 = yaml.safe_load((P.CONFIG_DIR / "fig7_render.yaml").read_text())
    assert s46["camera"]["speed_mps"] == 60.0 and s7["camera"]["speed_mps"] == 0.0
    assert all(o["velocity_mps"] == [0.0, 0.0, 0.0] for o in s7["objects"])        # static scene
    assert p46["fps"] == 60.0 and p46["long_exposure_s"] == pytest.approx(1 / 90)
    for p in (p46, p7):
        assert p["width"] >= 640 and p["height"] >= 360
    kinds = [o["kind"] for o in s7["objects"]]
    assert "motorcycle" in kinds and kinds.count("car") >= 2
    assert s7["groups"]["headlights"]["flicker"] and s7["groups"]["otherlights"]["flicker"]
    assert {lt["kind"] for lt in s46["lights"]} >= {"tail", "brake"}
    # p7's capture window covers every row: long exposure + 360 rows x line time
    assert p7["line_time_s"] * p7["height"] > 0.5 * (1 / P.FIG7_PWM[0])


def test_render_commands_use_the_scene_files(tmp_path):
    cmds = P.render_commands(tmp_path)
    assert [c[c.index("--out") + 1] for c in cmds] == [str(tmp_path / n) for n in P.RENDERS]
    for c in cmds:
        assert (P.CONFIG_DIR / c[c.index("--scene") + 1]).is_file()
        assert (P.CONFIG_DIR / c[c.index("--profile") + 1]).is_file()


# ------------------------------------------------------------------------------------ figures, tiny corpus
@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    from tests.data.corpus.data import make_corpus

    return make_corpus(tmp_path_factory.mktemp("pf"), n_scenes=1)


def test_every_figure_writes_a_png(tiny, tmp_path):
    paths = P.make_figures("all", tiny, tmp_path)
    assert [p.name for p in paths] == ["fig3_flicker.png", "fig4_lpd_spd_sequence.png", "fig5_dropout_fusion.png",
                                       "fig6_comet.png", "fig7_rolling_shutter.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size < 1_000_000
    assert not list(tmp_path.glob("*.tmp*"))


def test_dropout_light_adds_nothing_to_the_lpd_of_its_frame(tiny):
    seq = P.build_sequence46(tiny, noise=False)
    from lfmbench.datasets import LFMCaptureDataset

    ds = LFMCaptureDataset(tiny, split="all", frames=3, noise=False, outputs=("input_referred", "saturated", "gt"))
    drop_ids = set(seq.dropout[1])
    without = common._params({k: v for k, v in seq.pwm.items() if k not in drop_ids})
    s = ds.simulate(seq.scene_id, without, crop=None, noise_seed=0)
    lpd, ref = seq.sample["lpd_lcg_e"], s["lpd_lcg_e"]
    assert seq.dropout[3] == 1
    assert np.array_equal(lpd[1].numpy(), ref[1].numpy())            # OFF for the whole short exposure
    assert (lpd[0] - ref[0]).sum() > 0 and (lpd[2] - ref[2]).sum() > 0  # ON in the other frames
    assert (seq.sample["gt"][1] - s["gt"][1]).sum() > 0             # the truth still has it


def test_fig7_phase_b_removes_the_target_light(tiny):
    st = P.build_fig7(tiny, noise=False)
    f, d = P.FIG7_PWM
    rows = np.arange(st.target_rows[0], st.target_rows[1])
    assert np.all(pwm_exposure(st.lpd_start_s + rows * st.line_time_s - st.phase_b, st.short_s, 1 / f, d) == 0)
    from lfmbench.datasets import LFMCaptureDataset
    from lfmbench.baselines import get_method

    ds = LFMCaptureDataset(tiny, split="all", frames=1, noise=False, shutter="rolling", line_time_s=st.line_time_s,
                           outputs=("raw", "input_referred", "saturated", "gt"))
    # the target (the brightest light: the fake corpus has no motorcycle) at phase B adds nothing to its rows
    assert len(st.target_ids) == 1
    tgt = st.target_ids[0]
    rest = {i: (f, d, st.phase_b) for i in st.light_ids if i != tgt}
    s = ds.simulate(st.scene_id, common._params(rest), crop=None, noise_seed=0)
    ref = get_method("lpd_only")(common._batch(s))[0, 0]
    y0, y1 = st.target_rows
    assert np.array_equal(st.images["B"][:, y0:y1].numpy(), ref[:, y0:y1].numpy())


def test_module_does_not_import_torch():
    code = "import sys, lfmbench.paper.figures, lfmbench.paper.scenes; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
