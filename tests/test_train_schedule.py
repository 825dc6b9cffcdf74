"""The training loop's learning-rate warm-up (``train.warmup_steps``) and its warning for a collapsed training (a
network saturated so that every gradient is 0), on a tiny U-Net."""
from __future__ import annotations

import math

import pytest
import torch

from lfmbench import train as T
from lfmbench import train_step as S
from lfmbench.baselines import unet as U
from lfmbench.baselines.trainable import ConfigError
from tests.data.metrics.data import make_batch

TINY = {"model": {"base_channels": 2, "depth": 1},
        "train": {"epochs": 2, "batch_size": 2, "crop": 8, "samples_per_scene": 2, "workers": 0, "lr": 1e-2,
                  "lr_min": 1e-3, "warmup_steps": 4}}


def _cosine(step: int, total: int, lr: float, lr_min: float) -> float:
    """SGDR's one cycle written out again (Loshchilov & Hutter 2017, eq. 5 with T_cur = step, T_i = total)."""
    return lr_min + (lr - lr_min) * (1 + math.cos(math.pi * step / total)) / 2


def test_warm_up_rises_linearly_then_joins_the_cosine():
    total, w = 20, 5
    got = [S.cosine_lr(i, total, 1e-2, 1e-4, w) for i in range(total + 1)]
    want = [_cosine(i, total, 1e-2, 1e-4) * min(1.0, (i + 1) / w) for i in range(total + 1)]
    assert got == pytest.approx(want, rel=1e-12)
    assert got[0] == pytest.approx(_cosine(0, total, 1e-2, 1e-4) / w)          # a fifth of the rate on step 0
    assert all(a < b for a, b in zip(got[:w], got[1:w]))                        # rising through the warm-up
    assert got[w - 1:] == pytest.approx([_cosine(i, total, 1e-2, 1e-4) for i in range(w - 1, total + 1)])
    assert [S.cosine_lr(i, total, 1e-2, 1e-4) for i in range(total + 1)] == pytest.approx(
        [_cosine(i, total, 1e-2, 1e-4) for i in range(total + 1)])              # warmup 0: the cosine alone


def test_fit_steps_at_the_warmed_up_rate_across_epochs():
    cfg = U.config_from_dict(TINY, "tiny")
    seen: list[float] = []

    def step(batch, lr):
        seen.append(lr)
        return torch.tensor(1.0), {"grad_norm": torch.tensor(1.0)}

    model = torch.nn.Linear(1, 1)
    T.fit(model, torch.optim.Adam(model.parameters()), T.trainable("unet"), cfg, [{}] * 3, step=step,
          progress=False, log=None)
    total = 2 * 3
    assert seen == pytest.approx([_cosine(i, total, 1e-2, 1e-3) * min(1.0, (i + 1) / 4) for i in range(total)])


def test_warmup_steps_must_not_be_negative():
    with pytest.raises(ConfigError, match="warmup_steps"):
        U.config_from_dict({**TINY, "train": {**TINY["train"], "warmup_steps": -1}}, "tiny.yaml")
    assert U.config_from_dict({"model": TINY["model"]}, "tiny").train.warmup_steps == 0


def _saturated(cfg) -> U.UNetFusion:
    """A U-Net whose blend logits and gain sit far beyond float32's reach (the state the full lfmbench-v1 training
    fell into at step 68 without a warm-up): a one-hot softmax and tanh = 1 exactly, so every gradient is 0."""
    model = U.build_for_sensor(cfg)
    with torch.no_grad():
        model.unet.head.weight.zero_()
        bias = torch.zeros(model.n_candidates + 1, 4)
        bias[0] = 1e6                   # first candidate's logit: softmax one-hot
        bias[-1] = 1e6                  # gain: tanh(1e6) = 1, derivative 0
        model.unet.head.bias.copy_(bias.reshape(-1))
    return model


def test_a_saturated_network_reports_a_zero_gradient_and_the_epoch_warns():
    torch.manual_seed(0)
    cfg = U.config_from_dict(TINY, "tiny")
    batch = make_batch(h=16, w=24)
    healthy = U.build_for_sensor(cfg)
    dead = _saturated(cfg)
    for model, zero in ((healthy, False), (dead, True)):
        opt = torch.optim.Adam(model.parameters(), lr=1e-3)
        loss, terms = S._eager_step(model, opt, T.trainable("unet"), cfg, batch, 1e-3)
        assert torch.isfinite(loss)
        assert (float(terms["grad_norm"]) == 0.0) is zero
        lines: list[str] = []
        T.fit(model, opt, T.trainable("unet"), cfg, [batch] * 3, progress=False, log=lines.append)
        warned = [ln for ln in lines if "the gradient was 0" in ln]
        assert len(warned) == (2 if zero else 0), lines      # once per epoch of the collapsed run, never else
        if zero:
            assert warned[0].startswith("warning: epoch 1: the gradient was 0 on 3 of 3 steps")
            assert "train.warmup_steps" in warned[0]
        assert all("grad_norm" in ln for ln in lines if ln.startswith("epoch "))


def test_collapse_warning_threshold():
    assert S.collapse_warning(0, 10, 1) is None and S.collapse_warning(5, 10, 1) is None
    assert S.collapse_warning(6, 10, 3).startswith("warning: epoch 3: the gradient was 0 on 6 of 10 steps")
    assert S.collapse_warning(0, 0, 1) is None
