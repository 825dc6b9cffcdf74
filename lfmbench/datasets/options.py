"""The options of :class:`lfmbench.datasets.LFMCaptureDataset`, grouped into small validated objects.

The dataset's constructor keeps its keyword arguments; it hands them to these groups, each checked at once with
the argument checks of :mod:`lfmbench.check` (a ``TypeError`` for a wrong type, a ``ValueError`` for a wrong
value, each naming the argument):

- :class:`SampleOptions`: what one sample is (split, frames, crop, outputs, light groups, draws, seed);
- :class:`SimulationOptions`: how the sensor is simulated (shutter, line time, noise, optics, noise streams,
  the static-window rule, the pieces path);
- :class:`CacheOptions`: where projected layers are cached and how many scenes stay in memory.

What can only be checked against the corpus (frames and crop against each scene, groups against the scenes'
groups, ``max_lights`` against their lights) stays in the dataset.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from lfmbench import vocabulary
from lfmbench.check import check_arg_choice, check_flag, check_int_arg
from lfmbench.datasets.assembly import NOISE_STREAMS
from lfmbench.datasets.plan_frames import STATIC_WINDOW_RULES
from lfmbench.limits import brief, limit
from lfmbench.sensor.plan import SHUTTERS

__all__ = ["OUTPUTS", "DEFAULT_OUTPUTS", "DEFAULT_MAX_LIGHTS", "DEFAULT_SAMPLES_PER_SCENE", "SPLITS", "SampleOptions",
           "SimulationOptions", "CacheOptions"]

#: Every output a sample can hold (``LFMCaptureDataset(outputs=...)``).
OUTPUTS = ("raw", "input_referred", "saturated", "gt", "light_index", "depth", "rgb", "gt_common")
#: The outputs of a sample unless told otherwise.
DEFAULT_OUTPUTS = ("raw", "input_referred", "saturated", "gt", "light_index", "depth")
#: Smallest default length of the padded per-light ``meta`` arrays (``LFMCaptureDataset(max_lights=None)``).
DEFAULT_MAX_LIGHTS = 64
#: Samples per scene per epoch of a training split by default (``LFMCaptureDataset(samples_per_scene=None)``).
DEFAULT_SAMPLES_PER_SCENE = 16
#: Corpus splits a dataset reads (``all``: every complete scene); defined with the other shared names (the command
#: line lists them without importing the dataset).
SPLITS = vocabulary.SPLITS


@dataclass(frozen=True)
class SampleOptions:
    """What one sample is, checked without the corpus.

    Attributes:
        split: one of :data:`SPLITS`. frames: F consecutive frames (>= 1). frame_start: an int >= 0 or
            ``"random"``. crop: ``None`` or ``(h, w)`` in pixels (sides >= 2). outputs: a subset of
            :data:`OUTPUTS`. groups: light-group names or ``None`` (all). samples_per_scene: draws per scene per
            epoch (>= 1; ``None``: :data:`DEFAULT_SAMPLES_PER_SCENE` for ``train``, 1 for the other splits).
            seed: base seed (>= 0). max_lights: ``None`` or an int in ``[0, lights_per_scene]``.
    """

    split: str
    frames: int
    frame_start: int | str
    crop: tuple[int, int] | None
    outputs: tuple[str, ...]
    groups: tuple[str, ...] | None
    samples_per_scene: int
    seed: int
    max_lights: int | None

    @classmethod
    def checked(cls, *, split: str = "train", frames: int = 3, frame_start: int | str = 0,
                crop: int | tuple[int, int] | None = None, outputs: Sequence[str] = DEFAULT_OUTPUTS,
                groups: Sequence[str] | str | None = None, samples_per_scene: int | None = None, seed: int = 0,
                max_lights: int | None = None) -> "SampleOptions":
        """The options, each checked (errors name the argument); ``crop=n`` becomes ``(n, n)``, a group name a
        one-name list."""
        if split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {brief(split)}")
        bad = [o for o in outputs if o not in OUTPUTS]
        if bad:
            raise ValueError(f"outputs: unknown {bad} (known: {OUTPUTS})")
        if isinstance(frames, bool) or not isinstance(frames, int) or frames < 1:
            raise ValueError(f"frames must be a positive integer, got {brief(frames)}")
        if frame_start != "random" and (isinstance(frame_start, bool) or not isinstance(frame_start, int)
                                        or frame_start < 0):
            raise ValueError(f"frame_start must be an integer >= 0 or 'random', got {brief(frame_start)}")
        if samples_per_scene is None:  # DEFAULT_SAMPLES_PER_SCENE for train (an epoch of a small corpus is more
            samples_per_scene = DEFAULT_SAMPLES_PER_SCENE if split == "train" else 1  # than one batch), else 1
        samples_per_scene = check_int_arg("samples_per_scene", samples_per_scene, 1)
        seed = check_int_arg("seed", seed, 0)
        if max_lights is not None:
            check_int_arg("max_lights", max_lights, 0, limit("lights_per_scene"))
        if isinstance(groups, str):
            groups = [groups]
        if groups is not None and (not all(isinstance(g, str) for g in groups)):
            raise ValueError(f"groups must be None or a list of light-group names, got {brief(groups)}")
        return cls(split, frames, frame_start, _crop(crop), tuple(outputs), None if groups is None else tuple(groups),
                   samples_per_scene, seed, None if max_lights is None else int(max_lights))


def _crop(crop: Any) -> tuple[int, int] | None:
    import numpy as np  # noqa: PLC0415

    def is_int(v: Any) -> bool:
        return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

    if crop is None:
        return None
    if is_int(crop):
        out = (int(crop), int(crop))
    elif isinstance(crop, (tuple, list)) and len(crop) == 2 and all(is_int(c) for c in crop):
        out = (int(crop[0]), int(crop[1]))
    else:
        raise ValueError(f"crop must be None, an int or (h, w) of ints (pixels), got {brief(crop)}")
    if min(out) < 2:
        raise ValueError(f"crop must be None, an int or (h, w) with sides >= 2, got {brief(crop)}")
    return out


@dataclass(frozen=True)
class SimulationOptions:
    """How a sample is simulated, checked without the corpus.

    Attributes:
        shutter: one of :data:`lfmbench.sensor.plan.SHUTTERS`. line_time_s: ``None`` (from the corpus) or a
            finite time > 0, s. noise, optics, pieces: flags. noise_streams: one of
            :data:`lfmbench.datasets.assembly.NOISE_STREAMS`. static_windows: one of
            :data:`lfmbench.datasets.plan_frames.STATIC_WINDOW_RULES`.
    """

    shutter: str
    line_time_s: float | None
    noise: bool
    optics: bool
    pieces: bool
    noise_streams: str
    static_windows: str

    @classmethod
    def checked(cls, *, shutter: str = "global", line_time_s: float | None = None, noise: bool = True,
                optics: bool = True, pieces: bool = False, noise_streams: str = "generator",
                static_windows: str = "nearest") -> "SimulationOptions":
        """The options, each checked (errors name the argument)."""
        check_arg_choice("noise_streams", noise_streams, NOISE_STREAMS)
        check_arg_choice("static_windows", static_windows, STATIC_WINDOW_RULES)
        check_arg_choice("shutter", shutter, SHUTTERS)
        flags = [check_flag(name, v) for name, v in (("noise", noise), ("optics", optics), ("pieces", pieces))]
        if line_time_s is not None and (isinstance(line_time_s, bool) or not isinstance(line_time_s, (int, float))
                                        or not math.isfinite(line_time_s) or line_time_s <= 0):
            raise ValueError(f"line_time_s must be None or a finite number > 0 (s), got {brief(line_time_s)}")
        return cls(shutter, line_time_s, *flags, noise_streams, static_windows)


@dataclass(frozen=True)
class CacheOptions:
    """The projected-radiance cache: ``cache_dir`` (``None``: no disk cache) and ``cache_scenes`` (scenes kept
    in memory, >= 0)."""

    cache_dir: Path | None
    cache_scenes: int

    @classmethod
    def checked(cls, root: Path, *, cache_dir: str | os.PathLike | bool | None = None,
                cache_scenes: int = 8) -> "CacheOptions":
        """``cache_dir=None``: ``<root>/.cache``; ``False``: none."""
        cache_scenes = check_int_arg("cache_scenes", cache_scenes, 0)
        if cache_dir is None:
            cache_dir = Path(root) / ".cache"
        return cls(None if cache_dir is False else Path(cache_dir), cache_scenes)
