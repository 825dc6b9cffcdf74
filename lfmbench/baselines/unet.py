"""U-Net fusion baseline (0.3-3 M parameters at the default config): the network, its loss and checkpoints.

Input (per output frame f): the split-pixel captures of frame f and of ``context_frames`` neighbours on each side
(edge frames repeated), each as the three input-referred reads (LPD HCG, LPD LCG, SPD, in LPD-equivalent e- over
the short exposure) mapped to a log domain ``log1p(x / feature_scale_e) / log1p(feature_max_e / feature_scale_e)``
plus the three saturation flags; the log of the frame mean of the saturated fusion (a temporal LED level); and
``log(T_long / T_short) / log(100)`` (the exposure ratio, a constant plane). The Bayer mosaic is packed 2 x 2
(``pixel_unshuffle``), so the U-Net runs at half resolution and every packed pixel sees one whole RGGB quad.

Output: like the small :mod:`~lfmbench.baselines.learned` net, the U-Net does not regress radiance directly: per
pixel it predicts softmax weights over candidates in the GT units (``model.candidates``, from :data:`CANDIDATES`:
H = ``lpd_only`` (HCG where unsaturated, else LCG), L = exposure-corrected saturated fusion, S = ``spd_e``,
T = frame mean of L) and a bounded log-gain ``g`` (``|g| <= gain_range``): ``out = exp(g) * sum_k w_k C_k``.
The head starts with zero weights, logit ``init_bias`` for the first candidate (0 for the others) and ``g = 0``,
so an untrained model is a fixed blend leaning on the first candidate (weight 0.71 with 4 candidates at
``init_bias = 2``); the output stays non-negative and within a factor ``exp(gain_range)`` of the candidates'
range. The per-pixel gain, predicted from a neighbourhood, also lets the network denoise.

Other capture plans (LOFIC, staggered, chopped, single exposure; :data:`lfmbench.sensor.plan.ARCHITECTURES`): the
network is built for one sensor's plan (:func:`build_for_sensor`, what ``lfmbench train --method unet --sensor
NAME`` does). Its input per frame is the plan's captures in plan order, each input-referred to the plan's
reference exposure (``<capture>_e``, the ``gt`` units: the normalisation of every plan baseline,
:func:`lfmbench.baselines.plan_merge.plan_captures`), in the same log domain, plus one saturation flag per capture,
with the same temporal context, and the log of the frame mean of ``exposure_select`` (channel count
``2 N (2 context_frames + 1) + 1`` for N captures; no exposure-ratio plane: one network per plan). Its candidates
are :func:`plan_candidates`: E = ``exposure_select``, each capture (when the plan has more than one) and T = the
frame mean of E (``model.candidates`` names the split pixel's and is not used). The checkpoint records the sensor,
its architecture and captures; a batch of another sensor is refused (:class:`SensorMismatchError`, one line).

Loss (:func:`led_weighted_loss`): L1 of the mu-law images normalised by the GT peak (the PSNR-mu convention),
plus ``led_weight`` x the same L1 averaged over LED pixels only (``light_index >= 0``), plus ``region_weight`` x
the mean ``|log1p(P_j / s) - log1p(G_j / s)|`` of the region means P_j, G_j of every light and frame (what the
light-dropout and FMI metrics read).

Configuration: a plain YAML file (``lfmbench/configs/unet.yaml``; ``unet_tiny.yaml`` for the demo) with sections
``model``, ``loss`` and ``train`` (:func:`load_config`). Training: ``lfmbench train --method unet`` (:mod:`lfmbench.train`).
The registered method :func:`unet` reads the checkpoint at ``$LFMBENCH_UNET_CHECKPOINT`` or
:data:`DEFAULT_CHECKPOINT`.
"""
from __future__ import annotations

import math
import os
import re
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
import torch.nn as nn
import torch.nn.functional as F

from lfmbench.limits import brief
from lfmbench.baselines.checkpoint import (CONTENT_KEY, FILE_KEY, VERIFIED_KEY, CheckpointError, build_from_state,
                                           checkpointed_method, save_checkpoint_file, verify_content,
                                           read_trained_weights)
from lfmbench.baselines.classic import _CAPTURES as _CAPTURE_KEYS, _captures, exposures_s, saturated_fusion
from lfmbench.baselines.plan_merge import exposure_select, plan_captures
from lfmbench.baselines.trainable import ConfigError, Trainable, TrainConfig, read_sections, read_yaml_config
from lfmbench.metrics.flicker import region_series
from lfmbench.metrics.hdr import MU_DEFAULT, mu_law, normalize_hdr

#: The editable default configuration (about 1 M parameters).
DEFAULT_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "unet.yaml"
#: The demo's configuration (a few thousand parameters).
TINY_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "unet_tiny.yaml"
#: Where :func:`unet` looks for weights unless ``$LFMBENCH_UNET_CHECKPOINT`` is set.
DEFAULT_CHECKPOINT = Path("runs") / "unet_fusion.pt"
CHECKPOINT_ENV = "LFMBENCH_UNET_CHECKPOINT"
CHECKPOINT_FORMAT = "lfmbench-unet-fusion"
FORMAT_VERSION = 1
#: Blend candidates the config may list (``model.candidates``; the split pixel's).
CANDIDATES = {"H": "lpd_only: HCG where unsaturated, else LCG", "L": "saturated_exposure_corrected",
              "S": "spd_only (spd_e)", "T": "frame mean of L"}
#: Blend candidates of a network for another capture plan (:func:`plan_candidates`), besides the captures.
PLAN_CANDIDATES = {"E": "exposure_select (the plan's standard merge)", "T": "frame mean of E"}


def plan_candidates(captures: list[str] | tuple[str, ...]) -> list[str]:
    """Candidate names of a plan network: ``E``, then every capture of the plan in plan order (only when there are
    several: with one capture E is that capture), then ``T`` (:data:`PLAN_CANDIDATES`)."""
    return ["E", *captures, "T"] if len(captures) > 1 else ["E", "T"]


class CheckpointNotFoundError(FileNotFoundError):
    """No trained U-Net weights."""


class SensorMismatchError(CheckpointError):
    """A U-Net built (trained) for one sensor was given the samples of another sensor (other captures, or another
    preset of the same architecture): its weights do not apply. Bad input, one line."""


# --------------------------------------------------------------------------------------------- configuration
@dataclass
class ModelConfig:
    """Architecture. Channels count feature maps; ``feature_*_e`` are input-referred e-."""

    base_channels: int = 24        #: channels of the first U-Net level (doubled per level)
    depth: int = 3                 #: number of 2x down-samplings inside the U-Net (after the 2x2 packing)
    context_frames: int = 1        #: neighbouring frames each side given as temporal context
    gain_range: float = 1.0        #: bound of the learned natural-log gain on the blend
    candidates: list = field(default_factory=lambda: ["H", "L", "S", "T"])  #: blend candidates (CANDIDATES)
    init_bias: float = 2.0         #: starting logit of the first candidate (others 0)
    feature_scale_e: float = 100.0  #: e-, scale inside log1p of the input transform
    feature_max_e: float = 1.0e6   #: e-, value mapped to 1 by the input transform


@dataclass
class LossConfig:
    """Loss weights (dimensionless) and the mu of the mu-law (PSNR-mu uses 5000)."""

    led_weight: float = 4.0
    region_weight: float = 1.0
    mu: float = MU_DEFAULT


@dataclass
class UNetConfig:
    """The three sections of a U-Net configuration file."""

    model: ModelConfig = field(default_factory=ModelConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    train: TrainConfig = field(default_factory=TrainConfig)

    def to_dict(self) -> dict:
        return asdict(self)


def _candidates(where: str, v: Any) -> list:
    if (not isinstance(v, list) or not v or len(set(v)) != len(v)
            or not all(isinstance(c, str) and c in CANDIDATES for c in v)):
        raise ConfigError(f"{where} must be a non-empty list of distinct names from {sorted(CANDIDATES)}, got {brief(v)}")
    return list(v)


def config_from_dict(data: Any, source: str = "<dict>") -> UNetConfig:
    """Build a :class:`UNetConfig` from nested mappings; missing keys take the defaults.

    Raises:
        ConfigError: naming ``source`` and the offending key for an unknown section or key, a wrong type or an
            out-of-range value.
    """
    cfg = UNetConfig(**read_sections(data, {"model": ModelConfig, "loss": LossConfig, "train": TrainConfig}, source,
                                     _candidates))
    if cfg.model.feature_max_e <= cfg.model.feature_scale_e:
        raise ConfigError(f"{source}: model.feature_max_e must exceed model.feature_scale_e")
    return cfg


def load_config(path: str | os.PathLike | None = None) -> UNetConfig:
    """Read a U-Net YAML configuration (default :data:`DEFAULT_CONFIG`); :class:`ConfigError` names the file."""
    return read_yaml_config(DEFAULT_CONFIG if path is None else path, config_from_dict, "U-Net")


# --------------------------------------------------------------------------------------------------- network
def _block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, padding=1), nn.LeakyReLU(0.1, inplace=True),
                         nn.Conv2d(cout, cout, 3, padding=1), nn.LeakyReLU(0.1, inplace=True))


class UNet(nn.Module):
    """Plain U-Net: ``depth`` max-pool levels, two 3x3 convs per level, transposed-conv up-sampling, skip concat.

    Input (N, cin, H, W) with H, W multiples of ``2**depth``; output (N, cout, H, W).
    """

    def __init__(self, cin: int, cout: int, base: int, depth: int):
        super().__init__()
        chans = [base * 2 ** i for i in range(depth + 1)]
        self.down = nn.ModuleList([_block(cin, chans[0])] + [_block(chans[i - 1], chans[i])
                                                              for i in range(1, depth + 1)])
        self.up = nn.ModuleList([nn.ConvTranspose2d(chans[i], chans[i - 1], 2, stride=2)
                                 for i in range(depth, 0, -1)])
        self.dec = nn.ModuleList([_block(2 * chans[i - 1], chans[i - 1]) for i in range(depth, 0, -1)])
        self.head = nn.Conv2d(chans[0], cout, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = []
        for i, blk in enumerate(self.down):
            if i:
                x = F.max_pool2d(x, 2)
            x = blk(x)
            skips.append(x)
        for up, dec, skip in zip(self.up, self.dec, reversed(skips[:-1])):
            x = dec(torch.cat([up(x), skip], dim=1))
        return self.head(x)


class UNetFusion(nn.Module):
    """Fusion network: features of a sensor's captures -> blend weights and gain (see the module doc).

    Args:
        config: :class:`ModelConfig` (or a :class:`UNetConfig`, whose ``model`` is used).
        captures: the capture names of the plan in plan order, for a plan other than the split pixel; None: the
            split pixel (``lpd_hcg``, ``lpd_lcg``, ``spd``; the network of format 1, unchanged).
        sensor, architecture: the preset the network is for (recorded in its checkpoint; a batch whose
            ``meta["sensor"]`` names another preset is refused); None: not recorded, not checked.

    Input: batch dict. Split pixel: ``lpd_hcg_e``, ``lpd_lcg_e``, ``spd_e`` (B, F, 1, H, W) input-referred e-,
    ``saturated`` (B, F, 3, H, W) bool and ``meta`` exposures (s). Another plan: ``<capture>_e`` (B, F, 1, H, W) e-
    for its N captures in plan order and ``saturated`` (B, F, N, H, W). Output: (B, F, 1, H, W) e-, dtype of the
    captures.
    """

    def __init__(self, config: ModelConfig | UNetConfig | None = None, captures: list[str] | None = None,
                 sensor: str | None = None, architecture: str | None = None):
        super().__init__()
        cfg = config.model if isinstance(config, UNetConfig) else (config or ModelConfig())
        self.config = cfg
        self.captures = None if captures is None else list(captures)
        self.sensor, self.architecture = sensor, architecture
        self.source: str | None = None      # the checkpoint it was loaded from (messages)
        if self.captures is None:
            self.candidate_names = list(cfg.candidates)
            self.in_channels = 6 * (2 * cfg.context_frames + 1) + 2
        else:
            if not self.captures:
                raise ValueError("captures: a plan network needs at least one capture")
            self.candidate_names = plan_candidates(self.captures)
            self.in_channels = 2 * len(self.captures) * (2 * cfg.context_frames + 1) + 1
        self.n_candidates = k = len(self.candidate_names)
        self.unet = UNet(4 * self.in_channels, 4 * (k + 1), cfg.base_channels, cfg.depth)
        with torch.no_grad():  # start as a fixed blend leaning on L, gain 1
            self.unet.head.weight.zero_()
            bias = torch.zeros(k + 1, 4)
            bias[0] = cfg.init_bias
            self.unet.head.bias.copy_(bias.reshape(-1))  # pixel_shuffle order: channel-major, 2x2 minor

    def _log(self, x: torch.Tensor) -> torch.Tensor:
        c = self.config
        return torch.log1p(x.clamp_min(0.0) / c.feature_scale_e) / math.log1p(c.feature_max_e / c.feature_scale_e)

    def _context(self, per_frame: torch.Tensor) -> list[torch.Tensor]:
        """``per_frame`` (B, F, C, H, W) of each frame's ``context_frames`` neighbours on each side (edges
        repeated), in order -context .. +context."""
        nf = per_frame.shape[1]
        ctx = self.config.context_frames
        at = torch.arange(nf, device=per_frame.device)
        return [per_frame[:, (at + d).clamp(0, nf - 1)] for d in range(-ctx, ctx + 1)]

    def check_sensor(self, sensor: str | None, captures: list[str] | tuple[str, ...]) -> None:
        """Refuse the samples of another sensor: :class:`SensorMismatchError` (one line naming the checkpoint, the
        sensor it was trained for and the one given) when ``captures`` (plan order) are not this network's, or
        ``sensor`` is not the preset it was built for (both known)."""
        want = [c[:-2] for c in _CAPTURE_KEYS] if self.captures is None else self.captures
        if list(captures) == want and (sensor is None or self.sensor is None or sensor == self.sensor):
            return
        src = f"U-Net checkpoint {self.source}" if self.source else "this U-Net"
        mine = (f"sensor {self.sensor!r} ({self.architecture})" if self.sensor else
                ("a split-pixel sensor" if self.captures is None else "a sensor"))
        other = f"sensor {sensor!r}" if sensor else "a sensor"
        raise SensorMismatchError(
            f"{src} was trained for {mine}, captures {', '.join(want)}; the data is from {other}, captures "
            f"{', '.join(captures) or '(none)'}: evaluate it with --sensor {self.sensor or 'ovt'}, or train one for "
            f"this sensor with `lfmbench train --method unet --sensor {sensor or 'NAME'}`")

    def _check_sensor_of(self, batch: dict) -> None:
        """The batch comes from the sensor (and capture plan) this network was trained for (not a tensor check:
        the shapes are checked where the captures are read)."""
        meta = batch.get("meta")
        sensor = meta.get("sensor") if isinstance(meta, dict) else None
        if isinstance(sensor, (list, tuple)):
            sensor = sensor[0] if sensor and all(s == sensor[0] for s in sensor) else None
        have = [k[:-2] for k in batch if k.endswith("_e")]
        if self.captures is None and all(k in batch for k in _CAPTURE_KEYS):
            have = [c[:-2] for c in _CAPTURE_KEYS]   # split pixel: the three reads (other keys may ride along)
        self.check_sensor(sensor if isinstance(sensor, str) else None, have)

    def candidates(self, batch: dict) -> tuple[torch.Tensor, torch.Tensor]:
        """Blend candidates (B, F, K, H, W) e- (``candidate_names`` in order) and input features
        (B, F, C_in, H, W) float32."""
        self._check_sensor_of(batch)
        if self.captures is not None:
            return self._plan_candidates(batch)
        hcg, lcg, spd, sat = _captures(batch)
        lo = saturated_fusion(hcg, lcg, spd, sat)
        t = lo.mean(dim=1, keepdim=True).expand_as(lo)
        pool = {"L": lo, "S": spd, "T": t, "H": torch.where(sat[:, :, 0:1], lcg, hcg)}
        cand = torch.cat([pool[c] for c in self.config.candidates], dim=2)
        per_frame = torch.cat([self._log(hcg), self._log(lcg), self._log(spd), sat.to(hcg.dtype)], dim=2).float()
        nf = per_frame.shape[1]
        frames = self._context(per_frame)
        ts, tl = exposures_s(batch)
        ratio = (torch.log(tl / ts) / math.log(100.0)).float().to(per_frame.device)
        ratio = ratio.reshape(-1, 1, 1, 1, 1).expand(per_frame.shape[0], nf, 1, *per_frame.shape[-2:])
        feats = torch.cat(frames + [self._log(t).float(), ratio], dim=2)
        return cand, feats

    def _plan_candidates(self, batch: dict) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`candidates` of a plan network: E, the captures (several), T; features of the captures."""
        e = exposure_select(batch)                  # checks the captures' and flags' shapes
        xs = [batch[f"{c}_e"] for c in plan_captures(batch)]
        t = e.mean(dim=1, keepdim=True).expand_as(e)
        cand = torch.cat([e, *(xs if len(xs) > 1 else []), t], dim=2)
        sat = batch["saturated"].to(e.dtype)
        per_frame = torch.cat([*(self._log(x) for x in xs), sat], dim=2).float()
        feats = torch.cat(self._context(per_frame) + [self._log(t).float()], dim=2)
        return cand, feats

    def forward(self, batch: dict) -> torch.Tensor:
        cand, feats = self.candidates(batch)
        b, nf, c, h, w = feats.shape
        m = 2 * 2 ** self.config.depth
        ph, pw = (-h) % m, (-w) % m
        x = feats.reshape(b * nf, c, h, w)
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="replicate")
        y = F.pixel_shuffle(self.unet(F.pixel_unshuffle(x, 2)), 2)[..., :h, :w]
        k = self.n_candidates
        y = y.reshape(b, nf, k + 1, h, w)
        wts = torch.softmax(y[:, :, :k], dim=2).to(cand.dtype)
        gain = torch.exp(self.config.gain_range * torch.tanh(y[:, :, k:])).to(cand.dtype)
        return (wts * cand).sum(dim=2, keepdim=True) * gain


# ------------------------------------------------------------------------------------------------------ loss
def led_weighted_loss(pred: torch.Tensor, gt: torch.Tensor, light_index: torch.Tensor | None,
                      loss: LossConfig | None = None, feature_scale_e: float = 100.0,
                      num_lights: int | None = None) -> tuple[torch.Tensor, dict]:
    """Training loss favouring the LED regions (scalar, dimensionless) and its terms.

    Written without a host synchronisation (no ``float()`` of a device value, no boolean indexing), so that a
    training loop on a GPU can queue the next batch while this one runs.

    Args:
        pred, gt: (B, F, 1, H, W) e-.
        light_index: (B, F, 1, H, W) int, -1 off the lights (None: no LED terms).
        loss: weights and mu (:class:`LossConfig`).
        feature_scale_e: e-, scale of the log1p in the region term.
        num_lights: length of the per-light arrays (at least the largest light index + 1; default: read from
            ``light_index``, which waits for the device).

    Returns:
        (total, {"mu_l1", "led_l1", "region_log"}: detached 0-d tensors). Without LED pixels in the batch the LED
        terms are 0 and the total is the mu-law L1 alone.
    """
    lc = loss or LossConfig()
    p, g = normalize_hdr(pred, gt, "max")
    err = (mu_law(p, lc.mu) - mu_law(g, lc.mu)).abs()
    total = err.mean()
    terms = {"mu_l1": total.detach()}
    if light_index is not None and (lc.led_weight or lc.region_weight):
        led = (light_index >= 0).to(err.dtype)
        led_l1 = (err * led).sum() / led.sum().clamp_min(1)          # 0 without LED pixels (the sum is a count)
        pm, cnt = region_series(pred, light_index, num_lights)
        gm, _ = region_series(gt, light_index, num_lights)
        ok = cnt > 0
        zero = torch.zeros_like(pm)
        d = (torch.log1p(torch.where(ok, pm, zero).clamp_min(0) / feature_scale_e)
             - torch.log1p(torch.where(ok, gm, zero).clamp_min(0) / feature_scale_e)).abs()   # 0 where not ok
        reg = (d.sum() / ok.sum().clamp_min(1)).to(err.dtype)
        total = total + lc.led_weight * led_l1 + lc.region_weight * reg
        terms.update(led_l1=led_l1.detach(), region_log=reg.detach())
    return total, terms


# ----------------------------------------------------------------------------------------------- checkpoints
def save_checkpoint(model: UNetFusion, path: str | os.PathLike, config: UNetConfig | None = None,
                    extra: dict | None = None) -> Path:
    """Write ``{format, format_version, model_config, config, state_dict, sensor, architecture, captures,
    **extra, content_sha256}`` atomically (temp + rename; :func:`~lfmbench.baselines.checkpoint.save_checkpoint_file`); ``captures`` None: the split-pixel network (``sensor`` and
    ``architecture`` None: not recorded, as in checkpoints written before they were)."""
    return save_checkpoint_file({"format": CHECKPOINT_FORMAT, "format_version": FORMAT_VERSION,
                              "model_config": asdict(model.config),
                              "config": config.to_dict() if config is not None else None,
                              "state_dict": model.state_dict(), "sensor": model.sensor,
                              "architecture": model.architecture, "captures": model.captures, **(extra or {})}, path)


def read_checkpoint(path: str | os.PathLike, map_location: str | torch.device = "cpu") -> dict:
    """The checkpoint dict (tensors and plain data only: ``weights_only=True``); clear errors for a missing or
    foreign file."""
    ck = read_trained_weights(path, map_location, method="unet", env=CHECKPOINT_ENV, what="U-Net",
                              not_found=CheckpointNotFoundError)
    if not isinstance(ck, dict) or ck.get("format") != CHECKPOINT_FORMAT or ck.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(f"checkpoint {path} is not a {CHECKPOINT_FORMAT} checkpoint of format {FORMAT_VERSION}")
    ck[CONTENT_KEY], ck[VERIFIED_KEY] = verify_content(ck, path)
    return ck


def load_checkpoint(path: str | os.PathLike, map_location: str | torch.device = "cpu") -> UNetFusion:
    """Build a :class:`UNetFusion` (eval mode) from a checkpoint written by :func:`save_checkpoint`."""
    ck = read_checkpoint(path, map_location)
    caps, sensor, arch = ck.get("captures"), ck.get("sensor"), ck.get("architecture")
    if (caps is not None and not (isinstance(caps, list) and caps and all(isinstance(c, str) for c in caps))) \
            or not all(v is None or isinstance(v, str) for v in (sensor, arch)):
        raise CheckpointError(f"checkpoint {path}: 'captures' must be a list of capture names and 'sensor', "
                              f"'architecture' names (got {brief(caps)}, {brief(sensor)}, {brief(arch)})")
    model = build_from_state(
        path, lambda: UNetFusion(config_from_dict({"model": ck["model_config"]}, f"checkpoint {path}").model,
                                 caps, sensor, arch),
        ck.get("state_dict"), "match its model config")
    model.source = str(path)
    model.content_sha256, model.content_verified, model.file_sha256 = (ck[CONTENT_KEY], ck[VERIFIED_KEY],
                                                                        ck.get(FILE_KEY))
    return model


def build_for_sensor(cfg: UNetConfig, preset=None) -> UNetFusion:
    """The network for ``cfg.train.sensor`` (a preset name or YAML): the split-pixel network for a split pixel,
    else a plan network over that preset's captures; both record the preset's name and architecture.
    ``preset``: that sensor's :class:`lfmbench.sensor.SensorPreset` already resolved by the caller (None: resolved
    here from the config)."""
    from lfmbench.sensor import resolve  # noqa: PLC0415

    preset = resolve(cfg.train.sensor if preset is None else preset)
    caps = None if preset.architecture == "split_pixel" else list(preset.captures)
    return UNetFusion(cfg.model, caps, preset.name, preset.architecture)


def _loss(model: UNetFusion, batch: dict, cfg: UNetConfig) -> tuple[torch.Tensor, dict]:
    """The training loss of a batch: :func:`led_weighted_loss` of the model's output."""
    meta = batch.get("meta")
    lights = meta.get("light_id") if isinstance(meta, dict) else None
    return led_weighted_loss(model(batch), batch["gt"], batch.get("light_index"), cfg.loss,
                             cfg.model.feature_scale_e, None if lights is None else int(lights.shape[-1]))


#: The registered method: :class:`UNetFusion` with the weights at ``$LFMBENCH_UNET_CHECKPOINT`` or
#: :data:`DEFAULT_CHECKPOINT` (B, F, 1, H, W) e-; :class:`CheckpointNotFoundError` when there are none.
unet = checkpointed_method("unet", CHECKPOINT_ENV, DEFAULT_CHECKPOINT, load_checkpoint)
checkpoint_path = unet.checkpoint_path


# ------------------------------------------------------------------------------- further networks by name
def parse_named_checkpoints(items: list[str], taken, option: str) -> dict[str, str]:
    """``NAME=CHECKPOINT`` items (the values of the caller's repeatable option ``option``, e.g. ``--unet``) ->
    {name: path}, in the order given.

    Raises:
        ValueError: one line naming ``option`` and the item, when NAME is not a snake_case method name new to
            ``taken`` (names in use: a registry, the other methods of the caller) and to the earlier items, or
            CHECKPOINT is no file.
    """
    out: dict[str, str] = {}
    for item in items:
        name, sep, path = item.partition("=")
        if not sep or not re.fullmatch(r"[a-z][a-z0-9_]{0,63}", name) or name in taken or name in out:
            raise ValueError(f"{option} {item!r:.80}: give NAME=CHECKPOINT with NAME a new snake_case method name")
        if not os.path.isfile(path):
            raise ValueError(f"{option} {item!r:.80}: {path!r:.80}: no such file (make it with lfmbench train)")
        out[name] = path
    return out


def named_unets(named: dict[str, str]) -> dict[str, Callable[[dict], torch.Tensor]]:
    """Each checkpoint of ``named`` ({name: path}, :func:`parse_named_checkpoints`) as a U-Net method of its own
    name, (B, F, 1, H, W) e-, weights read at first use: :func:`~lfmbench.baselines.checkpoint.checkpointed_method`
    with the environment variable ``LFMBENCH_<NAME>_CHECKPOINT`` set to the path (so a variable inherited by that
    name does not swap the weights). Nothing is registered."""
    out = {}
    for name, path in named.items():
        env = f"LFMBENCH_{name.upper()}_CHECKPOINT"
        os.environ[env] = path
        out[name] = checkpointed_method(name, env, path, load_checkpoint)
    return out


def register_unets(named: dict[str, str]) -> None:
    """Register each checkpoint of ``named`` ({name: path}) as a U-Net method of its own name
    (:func:`named_unets`) in :data:`lfmbench.baselines.REGISTRY`, so an evaluation scores it by that name."""
    from lfmbench import baselines  # noqa: PLC0415 - the registry as it is now (a test may swap it)

    for name, method in named_unets(named).items():
        baselines.REGISTRY.register(name, method)

#: How ``lfmbench train --method unet`` trains it (:mod:`lfmbench.train`).
TRAINING = Trainable(name="unet", default_config=DEFAULT_CONFIG, load_config=load_config,
                     config_from_dict=config_from_dict, build_model=build_for_sensor, loss=_loss,
                     save_checkpoint=save_checkpoint, read_checkpoint=read_checkpoint,
                     default_checkpoint=DEFAULT_CHECKPOINT, checkpoint_env=CHECKPOINT_ENV,
                     outputs=("input_referred", "saturated", "gt", "light_index"))
