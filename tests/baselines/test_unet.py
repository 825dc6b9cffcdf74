"""Tests of the U-Net fusion baseline (lfmbench.baselines.unet): parameter budget, forward contract, a tiny
overfit, checkpoints, bad configs (its training: tests/test_train.py)."""
from __future__ import annotations

import pytest
import torch
import yaml

from lfmbench import baselines
from lfmbench.baselines import unet as U
from lfmbench.baselines.trainable import count_parameters
from tests.data.metrics.data import make_batch

#: A U-Net small enough for the 16 x 24 px test corpus and a fast test.
TINY = {"model": {"base_channels": 2, "depth": 1},
        "train": {"epochs": 1, "batch_size": 2, "crop": 8, "samples_per_scene": 2, "workers": 0, "lr": 1e-2}}


def test_default_config_parameter_budget_and_tiny_demo_config():
    n = count_parameters(U.UNetFusion(U.load_config()))
    assert 300_000 <= n <= 3_000_000, n
    tiny = count_parameters(U.UNetFusion(U.load_config(U.TINY_CONFIG)))
    assert tiny < 100_000 < n
    # the 640x360 protocol's config: the same network (its checkpoint loads into the default model), other crops
    v1 = U.load_config(U.DEFAULT_CONFIG.with_name("unet_v1.yaml"))
    assert v1.model == U.load_config().model and (v1.train.crop, v1.train.samples_per_scene) == (128, 8)


@pytest.mark.parametrize("dtype,h,w", [(torch.float32, 32, 32), (torch.float64, 22, 30)])
def test_forward_shape_dtype_and_range(dtype, h, w):
    b = make_batch(b=2, h=32, w=32, noise=True)
    b = {k: (v[..., :h, :w].to(dtype) if torch.is_tensor(v) and v.is_floating_point() else
             (v[..., :h, :w] if torch.is_tensor(v) else v)) for k, v in b.items()}
    m = U.UNetFusion(U.config_from_dict(TINY).model)
    out = m(b)
    assert out.shape == b["gt"].shape and out.dtype == dtype and out.device == b["gt"].device
    assert bool(torch.isfinite(out).all()) and bool((out >= 0).all())
    cand, feats = m.candidates(b)
    assert cand.shape == (2, 3, 4, h, w) and feats.shape == (2, 3, m.in_channels, h, w)
    # candidates H, L, S, T in the configured order
    assert torch.equal(cand[:, :, 0:1], baselines.lpd_only(b))
    assert torch.equal(cand[:, :, 1:2], baselines.saturated_exposure_corrected(b))
    assert torch.equal(cand[:, :, 2:3], b["spd_e"])
    # untrained: a fixed blend leaning on the first candidate, no gain
    wl = torch.softmax(torch.tensor([2.0, 0.0, 0.0, 0.0]), 0)
    assert torch.allclose(out, (cand * wl.to(dtype).reshape(1, 1, 4, 1, 1)).sum(2, keepdim=True), rtol=1e-5)
    m3 = U.UNetFusion(U.config_from_dict({"model": {"base_channels": 2, "depth": 1, "candidates": ["S", "L"]}}).model)
    c3, _ = m3.candidates(b)
    assert c3.shape[2] == 2 and torch.equal(c3[:, :, 0:1], b["spd_e"]) and m3(b).shape == b["gt"].shape


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_forward_on_cuda():
    b = {k: (v.cuda() if torch.is_tensor(v) else v) for k, v in make_batch().items()}
    out = U.UNetFusion(U.config_from_dict(TINY).model).cuda()(b)
    assert out.device.type == "cuda" and out.shape == b["gt"].shape


def test_tiny_overfit_reduces_loss():
    torch.manual_seed(0)
    b = make_batch(b=2, noise=True, seed=1)
    cfg = U.config_from_dict({"model": {"base_channels": 4, "depth": 1}})
    m = U.UNetFusion(cfg)
    opt = torch.optim.Adam(m.parameters(), lr=5e-3)
    losses = []
    for _ in range(25):
        loss, terms = U.led_weighted_loss(m(b), b["gt"], b["light_index"], cfg.loss)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert set(terms) == {"mu_l1", "led_l1", "region_log"}
    assert losses[-1] < 0.6 * losses[0], losses


def test_loss_weights_the_led_regions():
    b = make_batch()
    gt, li = b["gt"], b["light_index"]
    led = li >= 0
    off_led = torch.where(led, gt, gt * 0.5)   # error off the lights
    on_led = torch.where(led, gt * 0.5, gt)    # the same relative error on the lights
    cfg = U.LossConfig(led_weight=4.0, region_weight=1.0)
    assert U.led_weighted_loss(on_led, gt, li, cfg)[0] > 2 * U.led_weighted_loss(off_led, gt, li, cfg)[0]
    plain = U.LossConfig(led_weight=0.0, region_weight=0.0)
    assert U.led_weighted_loss(gt, gt, li, plain)[0] == 0.0


def test_loss_equals_its_compacted_form_and_stays_finite_without_leds():
    """The loss is written without host synchronisations (masked sums, not boolean indexing): it equals the
    straightforward form (the LED terms over the LED pixels and the lights that have pixels) within float rounding;
    a batch without LED pixels gives the mu-law L1 alone and finite gradients; num_lights larger than needed
    changes nothing."""
    from lfmbench.metrics.hdr import mu_law, normalize_hdr
    from lfmbench.metrics.flicker import region_series

    b = make_batch(b=2, noise=True, seed=3)
    cfg = U.LossConfig(led_weight=4.0, region_weight=2.0)
    pred = (b["gt"] * (0.7 + 0.6 * torch.rand_like(b["gt"]))).requires_grad_()
    total, terms = U.led_weighted_loss(pred, b["gt"], b["light_index"], cfg)
    p, g = normalize_hdr(pred, b["gt"], "max")
    err = (mu_law(p, cfg.mu) - mu_law(g, cfg.mu)).abs()
    led = b["light_index"] >= 0
    pm, cnt = region_series(pred, b["light_index"])
    gm, _ = region_series(b["gt"], b["light_index"])
    ok = cnt > 0
    reg = (torch.log1p(pm[ok].clamp_min(0) / 100.0) - torch.log1p(gm[ok].clamp_min(0) / 100.0)).abs().mean()
    want = err.mean() + 4.0 * err[led].mean() + 2.0 * reg.float()
    assert torch.isclose(total, want, rtol=1e-5), (float(total), float(want))
    assert float(terms["led_l1"].detach()) == pytest.approx(float(err[led].mean().detach()), rel=1e-5)
    more, _ = U.led_weighted_loss(pred, b["gt"], b["light_index"], cfg, num_lights=int(b["light_index"].max()) + 9)
    assert torch.isclose(more, total, rtol=1e-6)
    none = torch.full_like(b["light_index"], -1)
    alone, t2 = U.led_weighted_loss(pred, b["gt"], none, cfg)
    assert float(alone.detach()) == float(t2["mu_l1"].detach())
    assert float(t2["led_l1"]) == 0.0 and float(t2["region_log"]) == 0.0
    alone.backward()
    assert torch.isfinite(pred.grad).all()


def test_checkpoint_roundtrip_and_registered_method(tmp_path, monkeypatch):
    cfg = U.config_from_dict(TINY)
    torch.manual_seed(3)
    m = U.UNetFusion(cfg)
    with torch.no_grad():
        for p in m.parameters():
            p.add_(0.05 * torch.randn_like(p))
    ck = U.save_checkpoint(m, tmp_path / "u.pt", cfg, {"epochs_done": 1})
    b = make_batch(noise=True)
    back = U.load_checkpoint(ck)
    assert torch.equal(back(b), m.eval()(b))
    monkeypatch.setenv(U.CHECKPOINT_ENV, str(ck))
    out = baselines.get_method("unet")(b)
    assert torch.equal(out, m(b))
    assert isinstance(baselines.REGISTRY["unet"].torch_module(), U.UNetFusion)
    monkeypatch.setenv(U.CHECKPOINT_ENV, str(tmp_path / "missing.pt"))
    with pytest.raises(U.CheckpointNotFoundError, match="lfmbench train"):
        baselines.get_method("unet")(b)
    bad = tmp_path / "bad.pt"
    torch.save({"format_version": 1}, bad)
    with pytest.raises(ValueError, match="bad.pt"):
        U.load_checkpoint(bad)


@pytest.mark.parametrize("text,match", [
    ("model: {base_chanels: 8}\n", r"unknown key\(s\) \['base_chanels'\] in section 'model'"),
    ("model: {depth: two}\n", "model.depth must be an integer"),
    ("loss: {led_weight: -1}\n", "loss.led_weight must be >= 0"),
    ("train: {crop: 63}\n", "train.crop must be even"),
    ("optimizer: {}\n", r"unknown section\(s\)"),
    ("model: {candidates: [L, X]}\n", "model.candidates must be a non-empty list"),
    ("model: [1, 2\n", "cannot read YAML"),
])
def test_bad_config_names_the_file(tmp_path, text, match):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    with pytest.raises(U.ConfigError, match=match) as exc:
        U.load_config(p)
    assert str(p) in str(exc.value)
    with pytest.raises(U.ConfigError, match="missing.yaml"):
        U.load_config(tmp_path / "missing.yaml")
