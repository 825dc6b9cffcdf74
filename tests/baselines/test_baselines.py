"""Tests of lfmbench.baselines: the upstream fusion truth table, exposure-ratio handling, the flicker-aware noise
test, temporal fusion, the registry and the learned network (training, checkpoint, missing checkpoint)."""
from __future__ import annotations

import math

import pytest
import torch

from lfmbench import baselines
from lfmbench.baselines import classic, learned
from tests.data.metrics.data import SPD_GAIN, T_LONG_S, T_SHORT_S, make_batch


def _tiny(hcg, lcg, spd, sat):
    t = lambda v: torch.tensor(v, dtype=torch.float64).reshape(1, 1, 1, 1, -1)  # noqa: E731
    s = torch.tensor(sat, dtype=torch.bool).T.reshape(1, 1, 3, 1, -1)
    return t(hcg), t(lcg), t(spd), s


def test_saturated_fusion_truth_table():
    # pixels: both LPD ok | HCG sat only | both sat | HCG ok but LCG sat (upstream: 0)
    hcg, lcg, spd, sat = _tiny([100, 5000, 5000, 7], [110, 9000, 22000, 8], [1, 2, 30000, 4],
                               [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    out = classic.saturated_fusion(hcg, lcg, spd, sat).flatten().tolist()
    assert out == [105.0, 9000.0, 30000.0, 0.0]


def test_lpd_and_spd_only():
    b = make_batch(led_level=10000.0)  # HCG clips on the light, LCG does not
    lp = baselines.lpd_only(b)
    hot = b["saturated"][:, :, 0:1]
    assert torch.equal(lp[hot], b["lpd_lcg_e"][hot]) and torch.equal(lp[~hot], b["lpd_hcg_e"][~hot])
    assert bool(hot.any())
    assert torch.equal(baselines.spd_only(b), b["spd_e"])


def test_upstream_omits_exposure_ratio():
    b = make_batch(led_level=60000.0)  # both LPD reads saturate on the lit LED
    both = b["saturated"][:, :, 0:1] & b["saturated"][:, :, 1:2]
    assert bool(both.any())
    up, corr = baselines.upstream_saturated(b), baselines.saturated_exposure_corrected(b)
    ratio = up[both] / corr[both]
    assert torch.allclose(ratio, torch.full_like(ratio, T_LONG_S / T_SHORT_S), rtol=1e-5)
    assert torch.equal(up[~both], corr[~both])


def test_flicker_aware_replaces_dark_led_only():
    b = make_batch(noise=True, lpd_on=(0.0, 0.25, 0.25), static_on=(0.25, 0.25, 0.25), seed=3)
    nm = classic.NoiseModel.from_preset("ovt")
    out = baselines.flicker_aware(b, noise=nm)
    li = b["light_index"]
    led0_f0 = (li[:, 0:1] == 0)
    # frame 0: light 0 OFF in the LPD -> the SPD (steady) is used on the whole region
    assert torch.equal(out[:, 0:1][led0_f0], b["spd_e"][:, 0:1][led0_f0])
    # background (no light, no motion edge): noise alone rarely trips a 3-sigma one-sided test
    far = (li < 0) & (torch.arange(32).reshape(1, 1, 1, 1, 32) > 16) & (torch.arange(32).reshape(1, 1, 1, 32, 1) < 16)
    changed = (out != baselines.saturated_exposure_corrected(b)) & far
    assert changed.double().sum() / far.sum() < 0.01


def test_flicker_aware_two_sided_and_temporal():
    b = make_batch(lpd_on=(1.0, 1.0, 0.0))  # light 0 caught fully ON in frames 0, 1: 4x the GT level
    one, two = classic.flicker_aware(b), classic.flicker_aware(b, two_sided=True)
    m = b["light_index"][:, 0:1] == 0
    # one-sided keeps the (too bright) LPD: HCG clips there, so the LCG read
    assert torch.equal(one[:, 0:1][m], b["lpd_lcg_e"][:, 0:1][m])
    assert torch.equal(two[:, 0:1][m], b["spd_e"][:, 0:1][m])
    t = classic.temporal(b)
    base = classic.saturated_exposure_corrected(b)
    # the static light 1 region is flicker-prone: every frame gets the frame mean of the fusion there
    m1 = (b["light_index"] == 1).all(dim=1, keepdim=True).expand_as(base)
    assert torch.allclose(t[m1], base.mean(dim=1, keepdim=True).expand_as(base)[m1])
    # static background far from the lights is untouched
    assert torch.equal(t[..., 28:, :6], base[..., 28:, :6])
    med = classic.temporal(b, reducer="median")
    assert torch.allclose(med[m1], base.median(dim=1, keepdim=True).values.expand_as(base)[m1])
    with pytest.raises(ValueError, match="reducer"):
        classic.temporal(b, reducer="mode")


def test_noise_model_from_preset_and_batch():
    nm = classic.NoiseModel.from_preset("ovt")
    assert (nm.read_noise_hcg_e, nm.read_noise_lcg_e, nm.read_noise_spd_e, nm.sensitivity_ratio) == (
        0.83, 3.05, 0.83, 100.0)
    assert classic.NoiseModel.from_batch(make_batch()) == nm
    with pytest.raises(ValueError, match="preset"):
        classic.NoiseModel.from_preset("no_such_sensor")
    # SPD variance: gain x S + (gain x read)^2
    v = nm.spd_variance(torch.tensor([100.0]), torch.tensor(SPD_GAIN))
    assert float(v) == pytest.approx(SPD_GAIN * 100 + (SPD_GAIN * 0.83) ** 2, rel=1e-6)


def test_noise_model_resolves_a_named_preset_without_listing_presets_and_uses_a_travelling_one_as_is(
        monkeypatch):
    """Batches naming ``ovt`` resolve it without listing the preset folder (one stat per batch; the file is parsed
    once per process by ``load_preset``'s cache); a ``SensorPreset`` object in the batch (as flicker_bench sends it)
    is used as it is, no name looked up: a preset that differs from the file only in its SPD read noise gives that
    read noise."""
    import dataclasses

    import lfmbench.sensor.preset as P

    listed = []
    real_registry = P.preset_registry
    P._load_preset_file.cache_clear()
    monkeypatch.setattr(P, "preset_registry", lambda: listed.append(1) or real_registry())
    nms = [classic.NoiseModel.from_batch(make_batch(seed=i)) for i in range(3)]
    assert listed == [] and P._load_preset_file.cache_info().misses == 1
    assert nms[0] == nms[1] == nms[2] == classic.NoiseModel.from_preset("ovt")
    real = P.resolve
    ovt = real("ovt")
    own = dataclasses.replace(ovt, captures={**ovt.captures, "spd": dataclasses.replace(ovt.captures["spd"],
                                                                                         read_noise_e=7.5)})
    b = make_batch()
    b["meta"]["sensor"] = own
    assert classic.NoiseModel.from_batch(b) == dataclasses.replace(nms[0], read_noise_spd_e=7.5)
    b["meta"]["sensor"] = ["no_such_sensor"]
    for _ in range(2):  # a bad name is not remembered: every batch naming it raises
        with pytest.raises(ValueError, match="no_such_sensor"):
            classic.NoiseModel.from_batch(b)


def test_bad_batches_raise_named_errors():
    b = make_batch()
    del b["meta"]["exposure_long_s"]
    with pytest.raises(classic.BatchError, match="exposure"):
        baselines.upstream_saturated(b)
    b = make_batch()
    del b["spd_e"]
    with pytest.raises(classic.BatchError, match="spd_e"):
        baselines.spd_only(b)
    b = make_batch()
    b["saturated"] = b["saturated"][:, :, :2]
    with pytest.raises(classic.BatchError, match="saturated"):
        baselines.lpd_only(b)


def test_registry_and_method_specs():
    assert list(baselines.REGISTRY)[:7] == ["lpd_only", "spd_only", "upstream_saturated",
                                            "saturated_exposure_corrected", "flicker_aware",
                                            "flicker_aware_two_sided", "temporal"]
    assert baselines.get_method("lpd_only") is classic.lpd_only
    assert baselines.get_method("lfmbench.baselines.classic:spd_only") is classic.spd_only
    for bad in ("nope", "lfmbench.nope:f", "lfmbench.baselines.classic:nope", ""):
        with pytest.raises(baselines.MethodNotFoundError):
            baselines.get_method(bad)
    b = make_batch(b=2, noise=True)
    for name, fn in baselines.REGISTRY.items():
        if name in ("learned", "unet"):  # need checkpoints (tests/baselines/test_unet.py)
            continue
        out = fn(b)
        assert out.shape == b["gt"].shape and bool(torch.isfinite(out).all()), name


def test_learned_train_checkpoint_roundtrip(tmp_path, monkeypatch):
    batches = [make_batch(b=1, h=16, w=16, noise=True, seed=i, lpd_on=(0.1 * i, 1.0 - 0.1 * i, 0.5))
               for i in range(3)]
    ck = tmp_path / "lf.pt"
    from lfmbench.train import train_batches

    cfg = learned.config_from_dict({"train": {"epochs": 4, "lr": 1e-2, "lr_min": 1e-2, "grad_clip": 0.0}})
    model, hist = train_batches("learned", batches, cfg, out=ck)
    losses = hist["step_loss"]
    n_params = sum(p.numel() for p in model.parameters())
    assert 1000 < n_params < 10000
    assert ck.is_file() and len(losses) == 12 and losses[-1] < losses[0]
    monkeypatch.setenv(learned.CHECKPOINT_ENV, str(ck))
    out = learned.learned(batches[0])
    with torch.no_grad():
        assert torch.allclose(out, model(batches[0]))
    assert out.shape == batches[0]["gt"].shape
    assert isinstance(learned.learned.torch_module(), learned.LearnedFusion)
    # candidates are the saturated fusion, SPD and the frame mean
    cand, sat = learned.LearnedFusion.candidates(batches[0])
    assert torch.allclose(cand[:, :, 0:1], classic.saturated_exposure_corrected(batches[0]))


def test_learned_without_checkpoint_has_clear_error(tmp_path, monkeypatch):
    monkeypatch.setenv(learned.CHECKPOINT_ENV, str(tmp_path / "missing.pt"))
    with pytest.raises(learned.CheckpointNotFoundError, match="lfmbench train --method learned"):
        learned.learned(make_batch())
    bad = tmp_path / "bad.pt"
    torch.save({"something": 1}, bad)
    with pytest.raises(ValueError, match="not a lfmbench"):
        learned.load_checkpoint(bad)
    assert math.isfinite(float(learned.fusion_loss(torch.ones(1, 4), torch.ones(1, 4))))


def test_registry_and_help_list_the_same_baselines():
    """Each baseline is registered once, beside its definition (lfmbench.baselines.REGISTRY, in leaderboard order:
    split-pixel rules, learned, capture-plan merges), and the help of `lfmbench evaluate --method` lists every
    registered baseline."""
    from typer.testing import CliRunner

    from lfmbench.cli import app
    rules = ["lpd_only", "spd_only", "upstream_saturated", "saturated_exposure_corrected", "flicker_aware",
             "flicker_aware_two_sided", "temporal"]
    assert list(baselines.REGISTRY) == [*rules, "learned", "unet", "exposure_select", "exposure_select_bounded"]
    assert all(baselines.REGISTRY[n] is getattr(baselines.classic, n) for n in rules)
    assert list(baselines.LEARNED) == ["learned", "unet"] and list(baselines.PLAN_LEARNED) == ["unet"]
    assert list(baselines.PLAN_MERGES) == ["exposure_select", "exposure_select_bounded"]
    assert baselines.methods_for("split_pixel") == [*rules, "learned", "unet"]
    text = " ".join(CliRunner().invoke(app, ["evaluate", "--help"], env={"COLUMNS": "400"}).output.split())
    assert all(name in text for name in baselines.REGISTRY), text
