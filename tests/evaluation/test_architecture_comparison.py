"""benchmarks/studies/architecture_comparison.py: the U-Net training step of the cross-sensor comparison keeps a
complete checkpoint and trains a missing one; its options are checked before any work."""
from __future__ import annotations

import json
import sys

import pytest


@pytest.fixture(scope="module")
def study(load_study):
    return load_study("architecture_comparison")


def test_complete_checkpoint_is_kept_and_a_missing_one_trained(study, tmp_path):
    ck, rec = tmp_path / "unet_ovt.pt", tmp_path / "unet_ovt.json"
    ck.write_bytes(b"weights")
    rec.write_text(json.dumps({"sensor": "ovt", "epochs": 20}))
    missing = tmp_path / "no_corpus"
    assert study.train_unet(missing, "ovt", 20, tmp_path) == ck      # same budget: nothing trained, nothing read
    assert ck.read_bytes() == b"weights"
    ck.unlink()                                                          # the record alone is no checkpoint: trains,
    with pytest.raises(FileNotFoundError, match="no_corpus"):           # and the absent corpus stops it
        study.train_unet(missing, "ovt", 20, tmp_path)
    assert not ck.exists()


@pytest.mark.parametrize("args, message", [
    (["--corpus", "c", "--unet-only"], "--unet-only needs --unet or --train-epochs"),
    (["--corpus", "c", "--train-epochs", "0"], "--train-epochs must be >= 1"),
    (["--corpus", "c", "--unet", "nosuch=x.pt"], "SENSOR one of"),
])
def test_bad_options_stop_before_any_work(study, monkeypatch, capsys, args, message):
    monkeypatch.setattr(sys, "argv", ["architecture_comparison.py", *args])
    with pytest.raises(SystemExit) as exc:
        study.main()
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
