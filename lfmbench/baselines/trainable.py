"""What a trainable baseline declares so that the one training loop (:mod:`lfmbench.train`, ``lfmbench train
--method NAME``) can train it: a :class:`Trainable` (its config file, network, loss and checkpoint format) with
the common :class:`TrainConfig` section, and a config reader shared by every such baseline.

A new learned baseline is one module (network, loss, checkpoints, a ``TRAINING = Trainable(...)`` and the
registered method from :func:`lfmbench.baselines.checkpoint.checkpointed_method`) plus one entry of
:data:`lfmbench.baselines.LEARNED`.
"""
from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any
from lfmbench.limits import brief

__all__ = ["TrainConfig", "Trainable", "ConfigError", "read_sections", "read_yaml_config", "DATA_ORDERS",
           "count_parameters"]

#: How an epoch's samples are ordered: ``"epoch_permutation"`` (a permutation that depends only on (seed, epoch),
#: :class:`lfmbench.train.EpochSampler`) or ``"shuffle"`` (a DataLoader shuffled by one generator seeded once, its
#: state kept in the checkpoint so that a resumed run continues the same sequence).
DATA_ORDERS = ("epoch_permutation", "shuffle")


class ConfigError(ValueError):
    """A training configuration file is missing, unreadable or holds a bad value (the message names the file)."""


@dataclass
class TrainConfig:
    """Optimisation and data settings of ``lfmbench train`` (the ``train`` section of every trainable baseline's
    config). Pixels for ``crop``; seconds nowhere; the learning rate in Adam's units."""

    epochs: int = 20
    batch_size: int = 4
    crop: int | None = 64          #: square training crop, pixels (even); None: full frames
    samples_per_scene: int = 16    #: PWM draws and crops per scene per epoch
    frames: int = 3                #: frames per sample
    lr: float = 2.0e-3             #: Adam learning rate (cosine-annealed to lr_min over the run)
    lr_min: float = 1.0e-4
    warmup_steps: int = 0          #: optimiser steps of linear learning-rate warm-up before the cosine (0: none)
    weight_decay: float = 0.0
    grad_clip: float = 1.0         #: max gradient norm (0: off)
    workers: int = 1               #: DataLoader worker processes
    cache_scenes: int = 8          #: scenes whose projections each loader process keeps in memory (same samples)
    seed: int = 0
    split: str = "train"
    sensor: str = "ovt"


#: Smallest values of integer keys (any section); keys that must be > 0 or >= 0 (floats).
MINIMA = {"base_channels": 1, "depth": 0, "context_frames": 0, "epochs": 1, "batch_size": 1, "crop": 8,
          "samples_per_scene": 1, "frames": 1, "workers": 0, "width": 1, "warmup_steps": 0}
POSITIVE = {"gain_range", "feature_scale_e", "feature_max_e", "mu", "lr"}
NONNEG = {"led_weight", "region_weight", "lr_min", "weight_decay", "grad_clip"}


def _value(name: str, v: Any, default: Any, where: str, check_list: Callable[[str, Any], list] | None) -> Any:
    if isinstance(default, list):
        if check_list is None:
            raise ConfigError(f"{where}: no list values are allowed here")
        return check_list(where, v)
    if isinstance(default, (bool, str)):
        if type(v) is not type(default):
            raise ConfigError(f"{where} must be a {type(default).__name__}, got {brief(v)}")
        return v
    if isinstance(default, int) or name == "crop":
        if name == "crop" and v is None:  # full frames
            return None
        if isinstance(v, bool) or not isinstance(v, int):
            raise ConfigError(f"{where} must be an integer, got {brief(v)}")
        if v < MINIMA.get(name, 0):
            raise ConfigError(f"{where} must be >= {MINIMA.get(name, 0)}, got {v}")
        return v
    if isinstance(v, str):  # PyYAML reads 1.0e6 (no exponent sign) as a string
        try:
            v = float(v)
        except ValueError:
            pass
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise ConfigError(f"{where} must be a finite number, got {brief(v)}")
    v = float(v)
    if name in POSITIVE and v <= 0:
        raise ConfigError(f"{where} must be > 0, got {v}")
    if name in NONNEG and v < 0:
        raise ConfigError(f"{where} must be >= 0, got {v}")
    return v


def read_sections(data: Any, sections: Mapping[str, type], source: str = "<dict>",
                  check_list: Callable[[str, Any], list] | None = None) -> dict[str, Any]:
    """Build one dataclass per section from nested mappings; missing keys take the dataclass defaults.

    Args:
        data: the parsed file (a mapping of sections, or None).
        sections: section name -> dataclass.
        source: file name for the messages.
        check_list: validates and returns a list value (``check_list(where, value)``); None: lists refused.

    Raises:
        ConfigError: naming ``source`` and the offending key: an unknown section or key, a wrong type or an
            out-of-range value; ``train.crop`` must be even.
    """
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping with sections {', '.join(sections)}; got "
                          f"{type(data).__name__}")
    unknown = sorted(set(data) - set(sections))
    if unknown:
        raise ConfigError(f"{source}: unknown section(s) {unknown}; expected {sorted(sections)}")
    built = {}
    for sec, cls in sections.items():
        raw = data.get(sec) or {}
        if not isinstance(raw, dict):
            raise ConfigError(f"{source}: section {brief(sec)} must be a mapping, got {type(raw).__name__}")
        defaults = cls()
        names = [f.name for f in fields(cls)]
        bad = sorted(set(raw) - set(names))
        if bad:
            raise ConfigError(f"{source}: unknown key(s) {bad} in section {brief(sec)}; known: {sorted(names)}")
        built[sec] = cls(**{n: _value(n, raw.get(n, getattr(defaults, n)), getattr(defaults, n),
                                      f"{source}: {sec}.{n}", check_list) for n in names})
    train = built.get("train")
    if isinstance(train, TrainConfig) and train.crop is not None and train.crop % 2:
        raise ConfigError(f"{source}: train.crop must be even (keeps the Bayer phase), got {train.crop}")
    return built


def read_yaml_config(path: str | os.PathLike, build: Callable[[Any, str], Any], what: str) -> Any:
    """``build(data, str(path))`` of a YAML file; :class:`ConfigError` names the file (``what``: e.g. "U-Net")."""
    from lfmbench.fileio import InputFileError, load_yaml

    path = Path(path)
    try:
        data = load_yaml(path)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the {what} config ({exc.strerror or exc})") from None
    except InputFileError as exc:
        raise ConfigError(str(exc)) from None
    return build(data, str(path))


def count_parameters(model: Any) -> int:
    """Number of trainable parameters of an ``nn.Module``."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


@dataclass(frozen=True)
class Trainable:
    """A trainable baseline, as the training loop sees it.

    Attributes:
        name: the registered method name.
        default_config: its YAML config file (sections ``model``, ``train`` and, where it has one, ``loss``).
        load_config: ``load_config(path or None) -> cfg``; ``cfg.train`` a :class:`TrainConfig`, ``cfg.to_dict()``
            plain data (compared on resume).
        config_from_dict: ``config_from_dict(data, source) -> cfg``.
        build_model: ``build_model(cfg, preset=None) -> nn.Module`` (called after
            ``torch.manual_seed(cfg.train.seed)``; ``preset``: the :class:`lfmbench.sensor.SensorPreset` of
            ``cfg.train.sensor`` already resolved by the caller, None: resolve it from the config).
        loss: ``loss(model, batch, cfg) -> (scalar tensor, {term: float})``.
        save_checkpoint: ``save_checkpoint(model, path, cfg, extra) -> Path`` (atomic).
        read_checkpoint: ``read_checkpoint(path, map_location) -> dict`` (with ``state_dict``).
        default_checkpoint: where the registered method reads its weights unless ``checkpoint_env`` is set.
        checkpoint_env: the environment variable naming its checkpoint.
        outputs: dataset outputs the loss reads (None: the dataset's defaults).
        data_order: one of :data:`DATA_ORDERS`.
    """

    name: str
    default_config: Path
    load_config: Callable[[Any], Any]
    config_from_dict: Callable[[Any, str], Any]
    build_model: Callable[..., Any]
    loss: Callable[[Any, dict, Any], tuple]
    save_checkpoint: Callable[..., Path]
    read_checkpoint: Callable[..., dict]
    default_checkpoint: Path
    checkpoint_env: str
    outputs: tuple[str, ...] | None = None
    data_order: str = "epoch_permutation"

    def __post_init__(self) -> None:
        if self.data_order not in DATA_ORDERS:
            raise ValueError(f"data_order must be one of {DATA_ORDERS}, got {brief(self.data_order)}")
