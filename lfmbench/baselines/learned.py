"""A small learned fusion network (about 3.6 k parameters) trained through a DataLoader, with checkpoints.

The network does not regress radiance directly: per pixel and frame it predicts softmax weights over three
physically meaningful candidates in the GT units (input-referred e-), so it stays in range and trains on CPU in
minutes:

1. ``L``: the exposure-corrected saturated fusion (sharp, flickers),
2. ``S``: the SPD, ``spd_e`` (flicker-free up to the long exposure, blurred, noisier),
3. ``T``: the frame mean of ``L`` (temporal average of the LED level, ghosts on motion).

Features (per frame, per pixel): log1p of L, S and T over :data:`FEATURE_SCALE_E`, and the three saturation
flags. Loss: L1 between the mu-law tone-mapped output and GT, both normalised by the GT peak
(:func:`lfmbench.metrics.hdr.normalize_hdr`, :func:`~lfmbench.metrics.hdr.mu_law`; Kalantari & Ramamoorthi 2017).

Defines :class:`LearnedFusion` (``nn.Module``, input the batch dict), :func:`save_checkpoint`, :func:`load_checkpoint`, the registered method :func:`learned`, which reads the
checkpoint at ``$LFMBENCH_LEARNED_CHECKPOINT`` or :data:`DEFAULT_CHECKPOINT` and raises
:class:`CheckpointNotFoundError` with the training command when there is none, and :data:`TRAINING`.

Training: ``lfmbench train --method learned --corpus DIR --out runs/learned_fusion.pt`` (settings:
``lfmbench/configs/learned.yaml``; the loop of :mod:`lfmbench.train`; on any iterable of batches:
``lfmbench.train.train_batches("learned", batches, cfg)``).
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
import torch.nn as nn

from lfmbench.baselines.checkpoint import (CONTENT_KEY, FILE_KEY, VERIFIED_KEY, CheckpointError, build_from_state,
                                           checkpointed_method, save_checkpoint_file, verify_content,
                                           read_trained_weights)
from lfmbench.baselines.classic import _captures, saturated_fusion
from lfmbench.baselines.trainable import Trainable, TrainConfig, read_sections, read_yaml_config
from lfmbench.metrics.hdr import mu_law, normalize_hdr

#: The editable default training configuration.
DEFAULT_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "learned.yaml"
#: Where :func:`learned` looks for weights unless ``$LFMBENCH_LEARNED_CHECKPOINT`` is set.
DEFAULT_CHECKPOINT = Path("runs") / "learned_fusion.pt"
CHECKPOINT_ENV = "LFMBENCH_LEARNED_CHECKPOINT"
#: Scale (input-referred e-) inside the log1p feature transform.
FEATURE_SCALE_E = 100.0
#: Checkpoint format version (bump when the architecture changes).
FORMAT_VERSION = 1


class CheckpointNotFoundError(FileNotFoundError):
    """No trained weights for the learned baseline."""


@dataclass
class ModelConfig:
    """Architecture: hidden channels of the conv net (12 -> 3.6 k parameters)."""

    width: int = 12


@dataclass
class LearnedConfig:
    """The two sections of ``lfmbench/configs/learned.yaml``."""

    model: ModelConfig = field(default_factory=ModelConfig)
    train: TrainConfig = field(default_factory=TrainConfig)

    def to_dict(self) -> dict:
        return asdict(self)


def config_from_dict(data: Any, source: str = "<dict>") -> LearnedConfig:
    """A :class:`LearnedConfig` from nested mappings (missing keys: the defaults); :class:`ConfigError` names
    ``source`` and the key."""
    return LearnedConfig(**read_sections(data, {"model": ModelConfig, "train": TrainConfig}, source))


def load_config(path: str | os.PathLike | None = None) -> LearnedConfig:
    """Read a learned-fusion YAML configuration (default :data:`DEFAULT_CONFIG`)."""
    return read_yaml_config(DEFAULT_CONFIG if path is None else path, config_from_dict, "learned-fusion")


class LearnedFusion(nn.Module):
    """Per-pixel softmax blend of (L, S, T) predicted by a 4-layer 3x3 conv net.

    Args:
        width: hidden channels (12 -> 3.6 k parameters).

    Input: batch dict with ``lpd_hcg_e``, ``lpd_lcg_e``, ``spd_e`` (B, F, 1, H, W) e- and ``saturated``
    (B, F, 3, H, W). Output: (B, F, 1, H, W) e-.
    """

    def __init__(self, width: int = 12):
        super().__init__()
        self.width = width
        self.net = nn.Sequential(
            nn.Conv2d(6, width, 3, padding=1), nn.ReLU(),
            nn.Conv2d(width, width, 3, padding=2, dilation=2), nn.ReLU(),
            nn.Conv2d(width, width, 3, padding=1), nn.ReLU(),
            nn.Conv2d(width, 3, 3, padding=1),
        )
        with torch.no_grad():  # start as the plain saturated fusion: weight on L
            self.net[-1].bias.copy_(torch.tensor([2.0, 0.0, 0.0]))

    @staticmethod
    def candidates(batch: dict) -> tuple[torch.Tensor, torch.Tensor]:
        """Candidates (B, F, 3, H, W) e- = (L, S, T) and saturation flags (B, F, 3, H, W) float."""
        hcg, lcg, spd, sat = _captures(batch)
        lo = saturated_fusion(hcg, lcg, spd, sat)
        t = lo.mean(dim=1, keepdim=True).expand_as(lo)
        return torch.cat([lo, spd, t], dim=2), sat.to(lo.dtype)

    def forward(self, batch: dict) -> torch.Tensor:
        cand, sat = self.candidates(batch)
        b, f, _, h, w = cand.shape
        feats = torch.cat([torch.log1p(cand.clamp_min(0.0) / FEATURE_SCALE_E), sat], dim=2)
        logits = self.net(feats.reshape(b * f, 6, h, w).float()).reshape(b, f, 3, h, w)
        wts = torch.softmax(logits, dim=2).to(cand.dtype)
        return (wts * cand).sum(dim=2, keepdim=True)


def fusion_loss(pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """Mean L1 of mu-law tone-mapped, GT-peak-normalised images (scalar, dimensionless)."""
    p, g = normalize_hdr(pred, gt, "max")
    return (mu_law(p) - mu_law(g)).abs().mean()


def save_checkpoint(model: LearnedFusion, path: str | Path, extra: dict | None = None) -> Path:
    """Write ``{'format_version', 'width', 'state_dict', ...extra, 'content_sha256'}`` atomically (temp file + ``os.replace``)."""
    return save_checkpoint_file({"format_version": FORMAT_VERSION, "width": model.width,
                              "state_dict": model.state_dict(), **(extra or {})}, path)


def read_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict:
    """The checkpoint dict (tensors and plain data only); :class:`CheckpointNotFoundError` with the training command
    for a missing file, :class:`CheckpointError` for a foreign one."""
    ck = read_trained_weights(path, map_location, method="learned", env=CHECKPOINT_ENV, what="learned-fusion",
                              not_found=CheckpointNotFoundError)
    if not isinstance(ck, dict) or ck.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(f"checkpoint {path} is not a lfmbench learned-fusion checkpoint of format "
                              f"{FORMAT_VERSION}")
    ck[CONTENT_KEY], ck[VERIFIED_KEY] = verify_content(ck, path)
    return ck


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> LearnedFusion:
    """Build a :class:`LearnedFusion` from a checkpoint; clear errors for a missing or foreign file."""
    ck = read_checkpoint(path, map_location)
    model = build_from_state(path, lambda: LearnedFusion(int(ck["width"])), ck.get("state_dict"),
                             "fit the learned-fusion network")
    model.content_sha256, model.content_verified, model.file_sha256 = (ck[CONTENT_KEY], ck[VERIFIED_KEY],
                                                                        ck.get(FILE_KEY))
    return model


def _loss(model: LearnedFusion, batch: dict, cfg: LearnedConfig) -> tuple[torch.Tensor, dict]:
    """The training loss of a batch: :func:`fusion_loss` of the model's output."""
    return fusion_loss(model(batch), batch["gt"]), {}


def _save(model: LearnedFusion, path: str | Path, cfg: LearnedConfig | None = None, extra: dict | None = None) -> Path:
    return save_checkpoint(model, path, {"config": cfg.to_dict() if cfg is not None else None, **(extra or {})})




#: The registered method: :class:`LearnedFusion` with the weights at ``$LFMBENCH_LEARNED_CHECKPOINT`` or
#: :data:`DEFAULT_CHECKPOINT`, (B, F, 1, H, W) e-; :class:`CheckpointNotFoundError` when there are none.
learned = checkpointed_method("learned", CHECKPOINT_ENV, DEFAULT_CHECKPOINT, load_checkpoint)
checkpoint_path = learned.checkpoint_path

#: How ``lfmbench train --method learned`` trains it (:mod:`lfmbench.train`): a DataLoader shuffled by one
#: generator seeded once (the order the published demo checkpoints were trained with).
TRAINING = Trainable(name="learned", default_config=DEFAULT_CONFIG, load_config=load_config,
                     config_from_dict=config_from_dict, build_model=lambda cfg, preset=None: LearnedFusion(cfg.model.width),
                     loss=_loss, save_checkpoint=_save, read_checkpoint=read_checkpoint, default_checkpoint=DEFAULT_CHECKPOINT,
                     checkpoint_env=CHECKPOINT_ENV, data_order="shuffle")
