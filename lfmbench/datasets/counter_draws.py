"""A sample's random draws from counter-based streams of ``(seed, epoch, index)``: the same numbers one sample at a
time on the host and for a whole batch as tensors on any device (``LFMCaptureDataset(..., noise_streams="counter")``
and :class:`lfmbench.datasets.device.DeviceBatches`).

Every draw is a uniform of :mod:`lfmbench.counter_rng` at a fixed position of a stream whose key is
``derive_key(seed, epoch, index, purpose)``:

- ``PURPOSE_PWM``: draw ``5 e + q`` is field ``q`` (frequency, duty, phase, rise, fall) of PWM entity ``e``
  (:class:`SceneEntities`: the scene's flickering lights sorted by id, then its flickering groups; with
  ``sync: group`` the lights of a group share their group's entity), turned into values by each distribution's
  inverse CDF (:meth:`lfmbench.datasets.pwm.Distribution.quantile`) and :func:`lfmbench.datasets.pwm.pwm_record`;
- ``PURPOSE_PLACE``: draw 0 the crop row, draw 1 the crop column, draw 2 the first frame of ``frame_start="random"``;
- ``PURPOSE_NOISE``: the sample's noise seed, ``mix64(key) mod 2^62``.

A sample's draws do not depend on the batch it is drawn in, its size or its device: the uniforms are exact integer
arithmetic; the values from them are the same float64 formulas (on a GPU, a compiler may fuse ``low + (high - low) u``
into one rounding: at most 1 ulp of float64, far below the float32 the simulation runs in).

The frozen draws of the test split (``test_params.json``) are not drawn here: they stay what they are.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
import torch

from lfmbench.counter_rng import derive_key, mix64, uniforms
from lfmbench.datasets.pwm import PWMConfig, PWMParams, PWM_KEYS, SceneDraw, flicker_groups, pwm_record

__all__ = ["PURPOSE_PWM", "PURPOSE_PLACE", "PURPOSE_NOISE", "PWM_UNIFORMS", "SceneEntities", "sample_keys",
           "pwm_from_uniforms", "counter_scene_draw", "place_uniforms", "noise_seeds", "crop_origin", "start_frame"]

PURPOSE_PWM, PURPOSE_PLACE, PURPOSE_NOISE = 1, 2, 3
#: Uniforms per PWM entity: frequency, duty, phase, rise time, fall time.
PWM_UNIFORMS = 5
_NOISE_SEED_MASK = (1 << 62) - 1


@dataclass(frozen=True)
class SceneEntities:
    """The PWM entities of a scene (fixed per scene and group selection).

    Attributes:
        light_ids: ids of the flickering lights (sorted). groups: the flickering groups (sorted).
        entity: (len(light_ids) + len(groups),) int64: the uniform entity of each light then each group (``j`` with
            ``sync: light``; the index of its group among the sorted group names with ``sync: group``).
        n_entities: entities that draw uniforms.
    """

    light_ids: tuple
    groups: tuple
    entity: np.ndarray
    n_entities: int

    @classmethod
    def of(cls, cfg: PWMConfig, meta: Mapping[str, Any], groups: Sequence[str] | None = None) -> "SceneEntities":
        fl = flicker_groups(meta, groups)
        lights = sorted((lt for lt in meta.get("lights", []) if lt["group"] in fl), key=lambda lt: int(lt["id"]))
        names = [lt["group"] for lt in lights] + fl
        if cfg.sync == "group":
            order = sorted(set(names))
            ent = np.array([order.index(g) for g in names], dtype=np.int64)
            m = len(order)
        else:
            ent, m = np.arange(len(names), dtype=np.int64), len(names)
        return cls(tuple(int(lt["id"]) for lt in lights), tuple(fl), ent, m)


def sample_keys(seed: int, epoch: int, index, purpose: int) -> torch.Tensor:
    """Stream keys of samples ``index`` (an int or an int64 tensor (B,), any device) for one purpose: int64 of
    ``index``'s shape."""
    return derive_key(int(seed), int(epoch), index if torch.is_tensor(index) else int(index), int(purpose))


def pwm_from_uniforms(cfg: PWMConfig, u: torch.Tensor) -> dict[str, torch.Tensor]:
    """PWM fields from uniforms.

    Args:
        cfg: the distributions. u: (..., 5) float64 uniforms in (0, 1) (:data:`PWM_UNIFORMS` per entity).

    Returns:
        :data:`lfmbench.datasets.pwm.PWM_KEYS` -> (...) float64 (Hz, s, 1, s, s, s).
    """
    return pwm_record(cfg.frequency_hz.quantile(u[..., 0]), cfg.duty.quantile(u[..., 1]), u[..., 2],
                      cfg.rise_time_s.quantile(u[..., 3]), cfg.fall_time_s.quantile(u[..., 4]))


def counter_scene_draw(cfg: PWMConfig, ents: SceneEntities, seed: int, epoch: int, index: int) -> SceneDraw:
    """The PWM draw of one sample (the per-sample path; the batched path gathers the same numbers)."""
    u = uniforms(sample_keys(seed, epoch, index, PURPOSE_PWM), PWM_UNIFORMS * ents.n_entities)
    rec = pwm_from_uniforms(cfg, u.reshape(ents.n_entities, PWM_UNIFORMS))
    cols = {k: rec[k].tolist() for k in PWM_KEYS}
    per = [PWMParams(**{k: cols[k][int(e)] for k in PWM_KEYS}) for e in ents.entity]
    n = len(ents.light_ids)
    return SceneDraw(dict(zip(ents.light_ids, per[:n])), dict(zip(ents.groups, per[n:])))


def place_uniforms(seed: int, epoch: int, index) -> torch.Tensor:
    """(..., 3) float64 uniforms of crop row, crop column and first frame of samples ``index``."""
    return uniforms(sample_keys(seed, epoch, index, PURPOSE_PLACE), 3)


def noise_seeds(seed: int, epoch: int, index) -> torch.Tensor:
    """Noise seeds in [0, 2^62) of samples ``index``: int64 of ``index``'s shape."""
    return mix64(sample_keys(seed, epoch, index, PURPOSE_NOISE)) & _NOISE_SEED_MASK


def crop_origin(u, size: int, crop: int):
    """An even crop origin (px) from a uniform: ``2 floor(u n)``, n = (size - crop) // 2 + 1 even origins
    (float or tensor ``u``)."""
    n = (int(size) - int(crop)) // 2 + 1
    if torch.is_tensor(u):
        return 2 * (u * n).long().clamp(0, n - 1)
    return 2 * min(int(u * n), n - 1)


def start_frame(u, n_starts):
    """First frame of a ``frame_start="random"`` window from ``u``: uniform over ``n_starts`` starts (the rule of
    ``LFMCaptureDataset``; float/int or tensors)."""
    if torch.is_tensor(u):
        return torch.minimum((u * n_starts).long(), torch.as_tensor(n_starts, device=u.device) - 1)
    return min(int(u * n_starts), int(n_starts) - 1)
