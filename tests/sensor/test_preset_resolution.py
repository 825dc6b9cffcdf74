"""A sensor preset is resolved once and the object travels on: ``lfmbench evaluate --sensor X`` and one training
step read the preset's YAML once and turn its name into a :class:`lfmbench.sensor.SensorPreset` once
(:func:`lfmbench.sensor.resolve` is the one helper below the commands; an object passes it unchanged)."""
from __future__ import annotations

import collections

import pytest
import torch
import typer
from typer.testing import CliRunner

from lfmbench import fileio
from lfmbench.sensor import preset as P


@pytest.fixture
def counted(monkeypatch):
    """Counts per preset: ``loads`` (load_preset calls, i.e. a name or path turned into an object) and ``reads``
    (the preset YAML parsed from disk; the parse cache is emptied first, so the first use reads it)."""
    loads, reads = collections.Counter(), collections.Counter()
    real_load, real_yaml = P.load_preset, fileio.load_yaml

    def load(preset):
        loads[str(preset)] += 1
        return real_load(preset)

    def load_yaml(path=None, **kw):
        if str(kw.get("source", "")).startswith("preset "):
            reads[str(path)] += 1
        return real_yaml(path, **kw)

    P._load_preset_file.cache_clear()
    monkeypatch.setattr(P, "load_preset", load)
    monkeypatch.setattr(fileio, "load_yaml", load_yaml)
    yield loads, reads
    P._load_preset_file.cache_clear()


def test_resolve_passes_an_object_unchanged_and_loads_a_name(counted):
    loads, reads = counted
    p = P.resolve("ovt")
    assert p.name == "ovt" and loads == {"ovt": 1} and sum(reads.values()) == 1
    assert P.resolve(p) is p and loads == {"ovt": 1} and sum(reads.values()) == 1  # no second look at the file
    with pytest.raises(ValueError, match="unknown sensor preset 'nope'"):
        P.resolve("nope")


def test_evaluate_command_resolves_the_sensor_once(counted, tmp_path):
    from lfmbench.cli.evaluate import register
    from tests.data.corpus.data import make_corpus

    loads, reads = counted
    corpus = make_corpus(tmp_path / "corpus", n_scenes=1)
    app = typer.Typer()
    register(app)
    threads = torch.get_num_threads()
    try:
        r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(corpus), "--split", "all",
                                     "--output", str(tmp_path / "r.json"), "--repeats", "1", "--warmup", "0",
                                     "--no-perceptual", "--threads", "1", "--sensor", "ovt", "--crop", "8"])
    finally:
        torch.set_num_threads(threads)
    assert r.exit_code == 0, r.output
    # the dataset, the display-referred metrics (ISP bound to the preset) all got the object the command made
    assert loads == {"ovt": 1}, loads
    assert len(reads) == 1 and sum(reads.values()) == 1 and next(iter(reads)).endswith("ovt.yaml"), reads


def test_one_training_step_resolves_the_sensor_once(counted, tmp_path):
    from lfmbench import train as T
    from tests.data.corpus.data import make_corpus

    loads, reads = counted
    corpus = make_corpus(tmp_path / "corpus", n_scenes=1)
    spec = T.trainable("unet")
    cfg = spec.config_from_dict({"model": {"base_channels": 2, "depth": 1},
                                 "train": {"epochs": 1, "batch_size": 1, "crop": 8, "workers": 0, "sensor": "ovt",
                                           "split": "all"}}, "test")
    loads.clear()
    reads.clear()
    T.train("unet", corpus, tmp_path / "u.pt", cfg, max_steps=1, progress=False, log=None, data="loader",
            cuda_graph="off")
    # the size check, the network and the dataset all got the object train() made from cfg.train.sensor
    assert loads == {"ovt": 1}, loads
    assert sum(reads.values()) == 1, reads
