"""The U-Net for every capture plan (issue 22, item 5): one network per sensor, its input the plan's captures in
plan order (input-referred, the ``gt`` units) with one flag each; shapes and keys per plan, a tiny training run per
architecture that lowers the loss, checkpoints that record the sensor and refuse another's samples (one line, also
from ``lfmbench evaluate``), and the split-pixel network unchanged."""
from __future__ import annotations

import math

import pytest
import torch
from typer.testing import CliRunner

from lfmbench import baselines
from lfmbench.baselines import unet as U
from lfmbench.baselines.checkpoint import save_checkpoint_file
from lfmbench.cli import app
from lfmbench.datasets.loading import collate_samples, make_dataset
from lfmbench.sensor import load_preset
from tests.data.metrics.data import make_batch

PLANS = ("lofic", "staggered", "chopped", "single")
TINY = {"model": {"base_channels": 4, "depth": 1},
        "train": {"epochs": 1, "batch_size": 2, "crop": 16, "samples_per_scene": 2, "workers": 0, "lr": 1e-2,
                  "split": "all"}}


def _cfg(sensor: str, **model) -> U.UNetConfig:
    return U.config_from_dict({"model": {**TINY["model"], **model}, "train": {**TINY["train"], "sensor": sensor}})


def _batch(corpus, sensor: str, crop: int = 16, n: int = 2) -> dict:
    ds = make_dataset(corpus, "all", seed=0, crop=crop, samples_per_scene=2, frames=3, sensor=sensor,
                      outputs=U.TRAINING.outputs)
    return collate_samples([ds[i] for i in range(n)])


@pytest.mark.parametrize("sensor", PLANS)
def test_plan_network_takes_the_plans_captures_in_plan_order(corpus, sensor):
    preset = load_preset(sensor)
    caps = list(preset.captures)
    b = _batch(corpus, sensor)
    assert [k[:-2] for k in b if k.endswith("_e")] == caps
    m = U.build_for_sensor(_cfg(sensor, context_frames=1))
    assert (m.captures, m.sensor, m.architecture) == (caps, preset.name, preset.architecture)
    n = len(caps)
    assert m.in_channels == 2 * n * 3 + 1                     # (log + flag) per capture and frame of context, + T
    cand, feats = m.candidates(b)
    k = n + 2 if n > 1 else 2
    assert m.candidate_names == (["E", *caps, "T"] if n > 1 else ["E", "T"])
    assert cand.shape == (2, 3, k, 16, 16) and feats.shape == (2, 3, m.in_channels, 16, 16)
    e = baselines.exposure_select(b)
    assert torch.equal(cand[:, :, 0:1], e)
    assert torch.allclose(cand[:, :, -1:], e.mean(dim=1, keepdim=True).expand_as(e))
    if n > 1:
        for i, c in enumerate(caps):
            assert torch.equal(cand[:, :, 1 + i:2 + i], b[f"{c}_e"])
    # the centre frame's features: log1p(x / s) / log1p(max / s) of each capture in plan order, then its flags
    s, top = m.config.feature_scale_e, m.config.feature_max_e
    centre = feats[:, :, 2 * n:4 * n]
    for i, c in enumerate(caps):
        want = torch.log1p(b[f"{c}_e"].clamp_min(0) / s).float() / math.log1p(top / s)
        assert torch.allclose(centre[:, :, i:i + 1], want, rtol=1e-6, atol=1e-7)
    assert torch.equal(centre[:, :, n:], b["saturated"].float())
    # untrained: a fixed blend leaning on E, no gain, the gt's shape (read noise leaves some inputs below 0)
    out = m(b)
    w = torch.softmax(torch.tensor([2.0] + [0.0] * (k - 1)), 0).to(out.dtype)
    assert torch.allclose(out, (cand * w.reshape(1, 1, k, 1, 1)).sum(2, keepdim=True), rtol=1e-5, atol=1e-4)
    assert out.shape == b["gt"].shape and bool(torch.isfinite(out).all())


@pytest.mark.parametrize("sensor", ("ovt", *PLANS))
def test_a_tiny_training_run_lowers_the_loss_for_every_architecture(corpus, sensor):
    """25 Adam steps on one batch of that sensor's captures: the loss falls (the network can use its input)."""
    torch.manual_seed(0)
    cfg = _cfg(sensor)
    b = _batch(corpus, sensor, crop=16, n=2)
    m = U.build_for_sensor(cfg)
    opt = torch.optim.Adam(m.parameters(), lr=5e-3)
    losses = []
    for _ in range(25):
        loss, _terms = U.TRAINING.loss(m, b, cfg)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert all(math.isfinite(x) for x in losses)
    assert min(losses[-5:]) < 0.9 * losses[0], losses


def test_train_for_a_sensor_records_it_and_evaluate_refuses_another_sensor(corpus, tmp_path):
    """``lfmbench train --sensor lofic`` writes a checkpoint for lofic; ``lfmbench evaluate --sensor lofic`` scores
    it, ``--sensor staggered`` (other captures) is refused with one line before any work."""
    import yaml

    torch.set_num_threads(1)
    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(yaml.safe_dump({"model": TINY["model"], "train": TINY["train"]}))
    ck = tmp_path / "unet_lofic.pt"
    r = CliRunner().invoke(app, ["train", "--corpus", str(corpus), "--config", str(cfg), "--out", str(ck),
                                 "--sensor", "lofic"])
    assert r.exit_code == 0, r.output
    raw = U.read_checkpoint(ck)
    assert (raw["sensor"], raw["architecture"], raw["captures"]) == ("lofic", "lofic", ["hcg", "lcg"])
    assert raw["config"]["train"]["sensor"] == "lofic"
    base = ["evaluate", "--method", "unet", "--corpus", str(corpus), "--split", "all", "--max-scenes", "1",
            "--repeats", "1", "--warmup", "0", "--no-perceptual", "--isp", "none"]
    env = {U.CHECKPOINT_ENV: str(ck)}
    out = tmp_path / "r.json"
    r = CliRunner().invoke(app, base + ["--sensor", "staggered", "-o", str(out)], env=env)
    assert r.exit_code == 2, r.output
    msg = " ".join(r.output.split())
    assert "trained for sensor 'lofic'" in msg and "'staggered'" in msg and "--sensor lofic" in msg
    assert not out.exists()
    r = CliRunner().invoke(app, base + ["--sensor", "lofic", "-o", str(out)], env=env)
    assert r.exit_code == 0, r.output
    assert "1/1 scenes ok" in r.output


def test_a_checkpoint_refuses_the_samples_of_another_sensor(corpus, tmp_path):
    torch.manual_seed(1)
    lofic = U.build_for_sensor(_cfg("lofic"))
    path = U.save_checkpoint(lofic, tmp_path / "l.pt", _cfg("lofic"))
    back = U.load_checkpoint(path)
    b = _batch(corpus, "lofic")
    assert torch.equal(back(b), lofic.eval()(b))
    for other in ("staggered", "ovt"):
        with pytest.raises(U.SensorMismatchError, match=r"l\.pt was trained for sensor 'lofic'.*hcg, lcg") as exc:
            back(_batch(corpus, other))
        assert "\n" not in str(exc.value) and f"--sensor {other}" in str(exc.value)
    # a split-pixel network trained for ovt: imx490 (same captures, another preset) is refused too
    ovt = U.save_checkpoint(U.build_for_sensor(_cfg("ovt")), tmp_path / "o.pt")
    pix = make_batch(noise=True)
    pix["meta"]["sensor"] = ["imx490"]
    with pytest.raises(U.SensorMismatchError, match="'ovt'.*'imx490'"):
        U.load_checkpoint(ovt)(pix)
    with pytest.raises(U.SensorMismatchError, match="a split-pixel sensor"):
        U.UNetFusion(_cfg("ovt").model)(b)                    # no sensor recorded: the captures still decide
    pix["meta"]["sensor"] = ["ovt"]
    assert U.load_checkpoint(ovt)(pix).shape == pix["gt"].shape
    bad = tmp_path / "bad.pt"
    raw = U.read_checkpoint(path)
    save_checkpoint_file({**raw, "captures": "hcg"}, bad)  # sealed: the captures check, not the hash, refuses it
    with pytest.raises(U.CheckpointError, match="bad.pt.*captures"):
        U.load_checkpoint(bad)


def test_split_pixel_unet_outputs_are_those_of_before_the_plan_networks(tmp_path):
    """The split-pixel U-Net is the network it was (lfmbench-v1 and the demo's numbers stand): fixed weights on a
    fixed batch give the outputs main gave before plan networks existed (commit bdff0b3; float32 network, so a
    relative tolerance of 1e-5 for another CPU's summation order), and a checkpoint written without the sensor
    fields (the published ones) loads and runs."""
    torch.manual_seed(0)
    m = U.UNetFusion(U.config_from_dict({"model": {"base_channels": 4, "depth": 2, "context_frames": 1}}))
    with torch.no_grad():
        g = torch.Generator().manual_seed(5)
        for p in m.parameters():
            p.add_(0.1 * torch.randn(p.shape, generator=g))
    b = make_batch(b=2, h=32, w=32, noise=True, seed=1)
    with torch.no_grad():
        out = m(b).double()
    assert out.sum().item() == pytest.approx(4187331.7285232544, rel=1e-5)
    assert out[0, 1, 0, 10, 12].item() == pytest.approx(8333.537109375, rel=1e-5)
    assert out[1, 2, 0, 22, 22].item() == pytest.approx(6910.83203125, rel=1e-5)
    assert out.std().item() == pytest.approx(2241.8010527338583, rel=1e-5)
    old = {k: v for k, v in torch.load(U.save_checkpoint(m, tmp_path / "u.pt"), weights_only=True).items()
           if k not in ("sensor", "architecture", "captures", "content_sha256")}
    torch.save(old, tmp_path / "old.pt")  # an older file: no content hash either, loaded with one warning
    with pytest.warns(UserWarning, match="old.pt: no content_sha256"):
        back = U.load_checkpoint(tmp_path / "old.pt")
    assert back.captures is None and back.sensor is None
    with torch.no_grad():
        assert torch.equal(back(b), m.eval()(b))


def test_methods_for_lists_the_unet_for_every_architecture():
    from lfmbench.sensor.plan import ARCHITECTURES

    for arch in ARCHITECTURES:
        assert "unet" in baselines.methods_for(arch)
    assert "learned" not in baselines.methods_for("lofic")
