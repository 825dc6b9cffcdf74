"""lfmbench.datasets.pwm: the PWM distributions, the scene draw record and the frozen test-split streams."""
from __future__ import annotations

import numpy as np
import pytest

from lfmbench.datasets import pwm as P
from tests.data.corpus.data import fake_meta

GROUPS = {"headlights": {"flicker": False}, "otherlights": {"flicker": True}, "signals": {"flicker": True}}


def _meta(n_lights=5):
    m = fake_meta(groups=GROUPS, n_lights=n_lights)
    m["lights"][0], m["lights"][1] = m["lights"][1], m["lights"][0]  # not in id order
    return m


def test_default_config_is_isetlfm():
    cfg = P.load_pwm_config(None)
    assert (cfg.duty.dist, cfg.duty.low, cfg.duty.high) == ("uniform", 0.1, 0.5)
    assert (cfg.frequency_hz.low, cfg.frequency_hz.high) == (90.0, 120.0)
    assert cfg.sync == "light"
    assert P.load_pwm_config(cfg) is cfg


@pytest.mark.parametrize("bad,match", [
    ({"duty": {"dist": "uniform", "low": 0.2, "high": 1.5}}, "duty"),
    ({"duty": {"dist": "normal"}}, "duty"),
    ({"frequency_hz": {"dist": "loguniform", "low": 0.0, "high": 10.0}}, "frequency_hz"),
    ({"rise_time_s": {"dist": "choice", "values": []}}, "rise_time_s"),
    ({"sync": "scene"}, "sync"),
    ({"dutty": 1}, "unknown field 'dutty'"),
])
def test_bad_config_names_field_and_source(bad, match):
    with pytest.raises(ValueError, match=rf"^pwm: .*{match}"):
        P.load_pwm_config(bad)


def test_config_file_named_in_errors(tmp_path):
    f = tmp_path / "my_pwm.yaml"
    f.write_text("duty: {dist: constant, value: 2.0}\n")
    with pytest.raises(ValueError, match="my_pwm.yaml: field 'duty'"):
        P.load_pwm_config(f)


def test_scene_draw_record_ranges_and_keys():
    meta = _meta()
    draw = P.draw_scene_pwm(P.load_pwm_config(None), meta, np.random.default_rng(1))
    assert isinstance(draw, P.SceneDraw)
    assert sorted(draw.lights) == [lt["id"] for lt in sorted(meta["lights"], key=lambda lt: lt["id"])]
    assert sorted(draw.groups) == ["otherlights", "signals"]  # flickering groups only
    for r in list(draw.lights.values()) + list(draw.groups.values()):
        assert isinstance(r, P.PWMParams)
        assert 90 <= r.freq_hz <= 120 and r.period_s == pytest.approx(1 / r.freq_hz)
        assert 0.1 <= r.duty <= 0.5 and 0 <= r.phase_s < r.period_s
        assert (r.rise_s + r.fall_s) / 2 <= min(r.duty, 1 - r.duty) * r.period_s + 1e-15
    lights, groups = draw.to_dicts()
    assert set(lights[0]) == set(P.PWM_KEYS) and P.PWMParams.from_dict(lights[0]) == draw.lights[0]
    assert len({r.phase_s for r in draw.lights.values()}) == len(draw.lights)  # independent per light


def test_scene_draw_is_a_function_of_the_stream_and_the_groups_in_use():
    cfg, meta = P.load_pwm_config(None), _meta()
    a = P.draw_scene_pwm(cfg, meta, np.random.default_rng(3))
    assert a == P.draw_scene_pwm(cfg, meta, np.random.default_rng(3))
    assert a != P.draw_scene_pwm(cfg, meta, np.random.default_rng(4))
    only = P.draw_scene_pwm(cfg, meta, np.random.default_rng(3), groups=["signals"])
    assert set(only.groups) == {"signals"}
    assert {lt["id"] for lt in meta["lights"] if lt["group"] == "signals"} == set(only.lights)


def test_group_sync_shares_the_group_draw():
    cfg = P.load_pwm_config({"sync": "group"})
    meta = _meta()
    d = P.draw_scene_pwm(cfg, meta, np.random.default_rng(0))
    for lt in meta["lights"]:
        assert d.lights[lt["id"]] == d.groups[lt["group"]]


def test_draw_pwm_clips_ramps_into_the_period():
    cfg = P.load_pwm_config({"rise_time_s": {"dist": "constant", "value": 0.01},
                             "fall_time_s": {"dist": "constant", "value": 0.01}})
    d = P.draw_pwm(cfg, np.random.default_rng(0), ["a"] * 50)
    room = 2 * np.minimum(d["duty"], 1 - d["duty"]) * d["period_s"]
    assert np.all(d["rise_s"] + d["fall_s"] <= room * (1 + 1e-12))
    assert np.all(d["rise_s"] < 0.01)  # every period here is < 20 ms: clipped


def test_frozen_test_streams():
    a = P.frozen_test_rng("scene00000", 0).random(3)
    np.testing.assert_array_equal(a, P.frozen_test_rng("scene00000", 0).random(3))
    assert not np.array_equal(a, P.frozen_test_rng("scene00000", 1).random(3))
    assert not np.array_equal(a, P.frozen_test_rng("1112201236", 0).random(3))
    assert not np.array_equal(a, P.frozen_test_rng("scene00000", 0, stream=1).random(3))
    word = int.from_bytes(b"scene000", "little")
    np.testing.assert_array_equal(a, np.random.default_rng([P.TEST_SPLIT_SEED, 0, word]).random(3))
