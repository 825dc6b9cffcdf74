"""The training loop (lfmbench.train) and ``lfmbench train``: a tiny corpus end to end, resume to the weights of an
uninterrupted run (U-Net and the learned baseline), bad input, the epoch sampler, one Trainable per learned baseline."""
from __future__ import annotations

import pytest
import torch
import yaml
from typer.testing import CliRunner

from lfmbench import baselines
from lfmbench import train as T
from lfmbench import train_step as S
from lfmbench.baselines import unet as U
from lfmbench.cli import app
from tests.data.metrics.data import make_batch

#: A U-Net small enough for the 16 x 24 px test corpus and a fast test.
TINY = {"model": {"base_channels": 2, "depth": 1},
        "train": {"epochs": 1, "batch_size": 2, "crop": 8, "samples_per_scene": 2, "workers": 0, "lr": 1e-2}}


def _write_cfg(path, data=TINY):
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture
def one_thread():
    """torch on one thread for the test (determinism of the resumed runs), the worker's setting restored after."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def test_train_command_writes_loadable_checkpoint_and_resumes_deterministically(corpus, tmp_path, one_thread):
    cfg = _write_cfg(tmp_path / "tiny.yaml")
    a, b = tmp_path / "a.pt", tmp_path / "b.pt"
    r = CliRunner().invoke(app, ["train", "--corpus", str(corpus), "--config", str(cfg), "--out", str(a),
                                 "--epochs", "2"])
    assert r.exit_code == 0, r.output
    assert "saved" in r.output and a.is_file()
    # its first line, before the first epoch's, says what it trains on and where the projections go
    from lfmbench.datasets.loading import make_dataset

    n = len(make_dataset(corpus, "train", samples_per_scene=2).scene_ids)
    steps = -(-n * 2 // 2)  # samples_per_scene 2, batch 2, last batch kept
    first = r.output.index(f"training on {n} scenes of {corpus} (split train, sensor ovt): {steps} steps of batch 2 "
                           "per epoch, epochs 1-2; a scene's first pass also projects")
    assert first < r.output.index("epoch 1/2") and str(corpus / ".cache") in r.output
    ck = U.read_checkpoint(a)
    assert ck["epochs_done"] == 2 and len(ck["history"]["epoch_loss"]) == 2 and ck["parameters"] > 0
    model = U.load_checkpoint(a)
    batch = make_batch(h=16, w=24)
    assert model(batch).shape == batch["gt"].shape
    # one epoch, then the same command with --epochs 2 resumes: the same weights as the uninterrupted run
    for n in ("1", "2"):
        r = CliRunner().invoke(app, ["train", "--corpus", str(corpus), "--config", str(cfg), "--out", str(b),
                                     "--epochs", n])
        assert r.exit_code == 0, r.output
    assert "resuming" in r.output and "epochs 2-2" in r.output
    # a new total of epochs reshapes the cosine schedule (lr 1e-2 -> lr_min 1e-4): said in one line
    assert "was trained for a total of 1 epochs, now 2" in r.output and r.output.count("cosine") == 1
    # all epochs done: nothing trained, no start line
    r = CliRunner().invoke(app, ["train", "--corpus", str(corpus), "--config", str(cfg), "--out", str(a),
                                 "--epochs", "2"])
    assert r.exit_code == 0 and "resuming" in r.output and "training on" not in r.output, r.output
    sa, sb = U.read_checkpoint(a)["state_dict"], U.read_checkpoint(b)["state_dict"]
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    # another config refuses to resume from that checkpoint
    other = _write_cfg(tmp_path / "other.yaml", {**TINY, "loss": {"led_weight": 1.0}})
    r = CliRunner().invoke(app, ["train", "--corpus", str(corpus), "--config", str(other), "--out", str(b)])
    assert r.exit_code == 2 and "another config" in r.output


def test_train_command_bad_input_exits_2(corpus, tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("model: {depth: -1}\n")
    r = CliRunner().invoke(app, ["train", "--corpus", str(corpus), "--config", str(p), "--out",
                                 str(tmp_path / "x.pt")])
    assert r.exit_code == 2 and "bad.yaml" in r.output and "model.depth" in r.output
    r = CliRunner().invoke(app, ["train", "--corpus", str(tmp_path / "none"), "--config",
                                 str(_write_cfg(tmp_path / "t.yaml")), "--out", str(tmp_path / "x.pt")])
    assert r.exit_code == 2 and "does not exist" in r.output
    r = CliRunner().invoke(app, ["train", "--corpus", str(corpus), "--epochs", "0"])
    assert r.exit_code == 2 and "--epochs" in r.output


def test_epoch_sampler_depends_only_on_seed_and_epoch():
    s = T.EpochSampler(10, seed=1)
    s.set_epoch(3)
    first = list(s)
    s.set_epoch(0)
    s.set_epoch(3)
    assert list(s) == first and sorted(i for _, i in first) == list(range(10)) and {e for e, _ in first} == {3}
    s.set_epoch(4)
    assert [i for _, i in s] != [i for _, i in first]
    assert S.cosine_lr(0, 10, 1e-2, 1e-4) == pytest.approx(1e-2) and S.cosine_lr(10, 10, 1e-2, 1e-4) == 1e-4


def test_train_command_trains_the_learned_baseline_and_resumes_its_shuffled_order(corpus, tmp_path, one_thread):
    """``lfmbench train --method learned`` goes through the same loop; its order is a DataLoader shuffled by one
    generator seeded once, whose state the checkpoint keeps, so a resumed run ends with the weights of an
    uninterrupted one (without it, a resumed epoch 2 would replay epoch 1's order)."""
    from lfmbench.baselines import learned as L

    cfg = _write_cfg(tmp_path / "learned.yaml", {"train": {"epochs": 2, "batch_size": 2, "crop": 8,
                                                           "samples_per_scene": 2, "workers": 0, "lr": 1e-2,
                                                           "lr_min": 1e-2, "grad_clip": 0.0}})
    a, b = tmp_path / "a.pt", tmp_path / "b.pt"
    base = ["train", "--method", "learned", "--corpus", str(corpus), "--config", str(cfg)]
    r = CliRunner().invoke(app, base + ["--out", str(a)])
    assert r.exit_code == 0, r.output
    for n in ("1", "2"):
        r = CliRunner().invoke(app, base + ["--out", str(b), "--epochs", n])
        assert r.exit_code == 0, r.output
    assert "resuming" in r.output
    sa, sb = L.load_checkpoint(a).state_dict(), L.load_checkpoint(b).state_dict()
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert not all(torch.equal(sa[k], L.LearnedFusion().state_dict()[k]) for k in sa)   # it did train
    r = CliRunner().invoke(app, ["train", "--method", "nope", "--corpus", str(corpus)])
    assert r.exit_code == 2 and "learned" in r.output and "unet" in r.output


def test_every_learned_baseline_is_registered_and_trainable():
    """One register_learned call makes a method: registered, with a Trainable."""
    for name in baselines.LEARNED:
        spec = T.trainable(name)
        assert spec.name == name and name in baselines.REGISTRY and spec.default_config.is_file()
        cfg = spec.load_config(None)
        assert cfg.train.epochs >= 1 and spec.build_model(cfg) is not None
