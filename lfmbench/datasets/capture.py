r"""Split-pixel captures simulated on the fly: :class:`LFMCaptureDataset`.

For every sample the dataset draws PWM parameters (per light or per group, :mod:`lfmbench.datasets.pwm`), a
crop and a noise seed from ``(seed, epoch, index)``, composes the mean photo-electrons of each capture from the
scene's camera-projected layers (:mod:`lfmbench.datasets.projection`) and runs the split-pixel sensor model.

The composition and timing rules and the sample dict are those of :mod:`lfmbench.datasets.assembly` (shared with
the batched path :mod:`lfmbench.datasets.batched`); :meth:`LFMCaptureDataset.scene` gives a scene as the dataset
holds it (:class:`SceneView`: layers, lights, static rates, light index, meta) to figures and the batched path.

Size (about 720 lines): one class, the dataset, whose methods are the steps of one sample (split and scenes,
frozen test draws, the sample's draws, composition, sensor chain, ``gt_common``); the rules they apply live in
:mod:`~lfmbench.datasets.options`, :mod:`~lfmbench.datasets.assembly`, :mod:`~lfmbench.datasets.plan_frames`,
:mod:`~lfmbench.datasets.pieces` and :mod:`~lfmbench.datasets.counter_draws`.
"""
from __future__ import annotations

import hashlib
import json

import os
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import torch
from torch.utils.data import Dataset

from lfmbench.check import check_int_arg
from lfmbench.limits import brief
from lfmbench import sensor as _sensor
from lfmbench.corpus import Corpus
from lfmbench.datasets.counter_draws import (SceneEntities, counter_scene_draw, crop_origin, noise_seeds,
                                             place_uniforms, start_frame)
from lfmbench.datasets.assembly import SENSOR_OUTPUTS, assemble_sample, check_line_time, compose_frame, light_index
from lfmbench.datasets.options import (DEFAULT_MAX_LIGHTS, DEFAULT_OUTPUTS, DEFAULT_SAMPLES_PER_SCENE,  # noqa: F401
                                       CacheOptions, SampleOptions, SimulationOptions)
from lfmbench.datasets.pieces import capture_pieces
from lfmbench.datasets.plan_frames import PlanExposure, compose_plan_frame, exposure_static_exact, plan_exposures
from lfmbench.datasets.projection import SceneLayers, aux_channels, load_or_build, unit_projection_preset
from lfmbench.datasets.pwm import PWMConfig, apply_light_timing, draw_scene_pwm, frozen_test_rng, load_pwm_config
from lfmbench.fileio import atomic_write_json, load_json
from lfmbench.flicker import pwm_exposure
from lfmbench.sensor.fused import warm_fused
from lfmbench.vocabulary import PHOTODIODES

#: The sensor behind ``gt_common`` (its CFA, QE and optics at unit fill factor), the same for every dataset sensor.
COMMON_REFERENCE_SENSOR = "single"
TEST_PARAMS_NAME = "test_params.json"


class DatasetNotFoundError(FileNotFoundError):
    """The corpus directory holds no (complete) lfmbench corpus."""


class SceneView:
    """One scene as an :class:`LFMCaptureDataset` holds it (for its sensor, groups, optics and frames): what
    figures, the batched path (:func:`lfmbench.datasets.pieces.capture_pieces`) and sensor plans read, without
    reaching into the dataset. Made by :meth:`LFMCaptureDataset.scene`; the layers are loaded on first use.

    Attributes:
        scene_id: the scene's id. meta: its ``meta.json`` (a dict; read-only by convention).
    """

    def __init__(self, ds: "LFMCaptureDataset", scene_id: str) -> None:
        self._ds = ds
        self.scene_id = scene_id
        self.meta = ds.corpus.meta(scene_id)

    @property
    def layers(self) -> SceneLayers:
        """The projected layers (e-/s per pixel, :class:`lfmbench.datasets.projection.SceneLayers`) of the frames
        a sample can use, from the dataset's cache."""
        return self._ds._layers(self.scene_id)

    @property
    def lights(self) -> list[dict]:
        """The ``meta.json`` lights of the dataset's groups, sorted by id: the order of the per-light ``meta``
        arrays of a sample (``light_id``, ``flicker``, ``freq_hz``, ...) and of ``light_index``."""
        return self._ds._lights(self.scene_id)

    def static_rates(self) -> torch.Tensor:
        """(Fs, 2, H, W) float32 static rates of the LPD and SPD, e-/s, kept once per scene (the layers'
        ``static[pd]`` become views of it: the rates are not held twice)."""
        def build(layers: SceneLayers) -> torch.Tensor:
            both = torch.stack([layers.static[pd] for pd in PHOTODIODES], 1)
            layers.static = {**layers.static, **{pd: both[:, i] for i, pd in enumerate(PHOTODIODES)}}
            return both

        return self.cached("static_both", build)

    def light_index(self) -> torch.Tensor:
        """(Fs, 1, H, W) full-frame :func:`lfmbench.datasets.assembly.light_index` of the scene (int16; int32 from
        2^15 lights on), computed once per scene."""
        lights = self.lights

        def build(layers: SceneLayers) -> torch.Tensor:
            dt = torch.int16 if len(lights) < 2 ** 15 else torch.int32
            return light_index(layers.aux["mask.light"], lights).to(dt)

        return self.cached("light_index", build)

    def cached(self, key: str, build: Callable[[SceneLayers], Any]) -> Any:
        """``build(layers)``: something fixed per scene (not per crop or draw), computed once and kept as long as
        the scene's layers stay in the dataset's in-memory cache (recomputed per call without it)."""
        return self._ds._scene_cached(self.scene_id, key, build)


def _warm_cpu_kernels(noise: bool, preset) -> None:
    """Compile (or load from numba's cache) the serial CPU kernels a sample uses, in this process.

    DataLoader workers are forked from here and inherit them, instead of each worker loading them at its first
    sample (0.3-0.8 s per worker and epoch with the default ``persistent_workers=False``). Only the serial
    kernels: they start no threading layer, so forking after them is safe (docs/guide/flicker.md).
    """
    pwm_exposure(np.zeros(1), 1e-3, 1e-2, 0.5, check=False)
    if noise:
        _sensor.shot_noise(torch.zeros(1), torch.Generator().manual_seed(0))
    warm_fused(preset, noise)         # the sensor chain's compiled passes (float32, the dataset's dtype), any plan


# ----------------------------------------------------------------------------------------------------------
# dataset
# ----------------------------------------------------------------------------------------------------------
class LFMCaptureDataset(Dataset):
    r"""Split-pixel HDR captures of an lfmbench corpus with random LED PWM, and flicker-free ground truth.

    Args:
        root: corpus directory (``lfmbench render --out DIR`` or ``lfmbench import-isetlfm``).
        split: ``"train"``, ``"val"``, ``"test"`` (PWM draws frozen in ``<root>/test_params.json``) or ``"all"``.
        sensor: preset name (one of :func:`lfmbench.sensor.available_presets`: the files of
            ``lfmbench/configs/sensors/``), YAML path or :class:`lfmbench.sensor.SensorPreset`: its capture plan
            (docs/guide/sensors.md) names the sample's capture keys. Architectures other than the split pixel run on the per-sample path (not ``pieces``).
        frames: number of consecutive frames F per sample (<= the corpus frames).
        frame_start: which F consecutive frames of a longer sequence a sample shows: an int s (frames
            s .. s + F - 1 of every scene; default 0, the first F; only frames < s + F are read) or
            ``"random"`` (a uniform start in [0, N - F] per sample, N the scene's frames; train/val/all draw it
            after the other draws, so PWM, crop and noise are those of ``frame_start=0``; the test split
            freezes it in ``test_params.json`` like its PWM draws). ``"random"`` keeps all N frames of a
            cached scene in memory.
        crop: ``None`` (full frame), ``int`` or ``(h, w)`` in pixels (even offsets keep the Bayer phase);
            random for train/val/all, centred for test.
        pwm: PWM distributions: ``None`` (``lfmbench/configs/pwm.yaml``), a mapping of overrides or a YAML path.
        shutter: ``"global"`` or ``"rolling"`` (row y starts ``y * line_time`` later; line time from meta).
        seed: base seed; sample randomness comes from ``(seed, epoch, index)`` only, so results do not depend
            on ``num_workers`` or the sampler (``DistributedSampler`` just selects indices).
        outputs: subset of :data:`OUTPUTS`; only what is asked for is read and simulated.
        groups: light groups to include (None = all the scene has); others are never read.
        samples_per_scene: samples per scene per epoch (each its own PWM draw and crop). Default (None):
            :data:`DEFAULT_SAMPLES_PER_SCENE` = 16 for ``train``, so that an epoch of a small corpus is more than
            one batch (4 training scenes at batch size 8: 8 batches of fresh draws and crops; the shipped training
            configs use the same 16); 1 for ``val``, ``test`` and ``all`` (one draw per scene: index i is scene i;
            the test draws frozen as ``lfmbench evaluate`` scores them by default).
        noise: simulate temporal noise (False: mean electrons through clipping and quantisation).
        optics: apply the lens PSF.
        max_lights: length of the padded per-light metadata arrays (``meta`` ``light_id``, ``flicker``, ``duty``,
            ...); default: 64, or the most lights of one of the dataset's scenes when that is more (a 640x360
            night scene can hold 66). An explicit value below that is refused here, naming the scene.
        line_time_s: rolling-shutter row delay (s); default the corpus's. Must keep every row's windows inside
            the rendered capture window (checked).
        cache_dir: directory of the per-sensor projected-radiance cache (default ``<root>/.cache``; ``False``
            keeps it in memory only; any writable directory for a read-only corpus). Entries are keyed by the
            manifest SHA-256 of the files they come from and read with ``torch.load(weights_only=True)``
            (:func:`lfmbench.datasets.projection.load_or_build`). cache_scenes: scenes kept in memory per worker.
        transforms: callable applied to the sample dict.
        pieces: return the unsimulated pieces of a sample instead (projected rates of the crop, per-light time
            bins, PWM draws, noise seed, masks, depth, meta; :func:`lfmbench.datasets.batched.capture_pieces`),
            to be batched by :func:`~lfmbench.datasets.batched.collate_pieces` and simulated on the training
            device by :func:`~lfmbench.datasets.batched.simulate_batch` (docs/guide/datasets.md, "Captures on the GPU").
        static_windows: how a capture plan's window that the corpus does not store for its static groups (it
            stores the short and long windows, and from format version 4 static time bins whose unions are exact:
            docs/benchmarks/motion-windows.md) is served: ``"nearest"`` (default: the smallest stored window
            containing it, else the long one; error measured in docs/results/sensor-architectures.md; samples record it in
            ``meta["static_windows"]``) or ``"exact"`` (such a plan is refused, naming preset and corpus).
        noise_streams: where a sample's random numbers come from (:data:`lfmbench.datasets.assembly.NOISE_STREAMS`):
            ``"generator"`` (default; the numbers of the published results): PWM, crop and window start from a
            numpy generator seeded ``(seed, epoch, index)``, the sensor noise from a torch generator seeded by the
            noise seed; ``"counter"``: all of them from counter-based streams of ``(seed, epoch, index)``
            (:mod:`lfmbench.datasets.counter_draws`, :mod:`lfmbench.sensor.counter_noise`), the numbers the
            device path (:class:`lfmbench.datasets.device.DeviceBatches`) gives on any device and batch size.
            The frozen draws of the test split are the same in both.

    Sample (F frames, crop h x w; batches add a leading B; see docs/guide/contracts.md):
        ``lpd_hcg``, ``lpd_lcg``, ``spd``: (F, 1, h, w) DN; ``lpd_hcg_e``, ``lpd_lcg_e``, ``spd_e``: (F, 1, h, w)
        input-referred LPD-equivalent e- over the short exposure; ``saturated``: (F, 3, h, w) bool;
        ``gt``: (F, 1, h, w) e-; ``light_index``: (F, 1, h, w) int64 (index into the ``meta`` light arrays,
        -1 none); ``depth``: (F, 1, h, w) m; ``rgb`` (on request): ``lpd_lcg_rgb``, ``spd_rgb``, ``gt_rgb``
        (F, 3, h, w) demosaiced (kornia bilinear); ``gt_common`` (on request): (F, 1, h, w) e-, the ground truth
        common to all sensors (the long window [0, T_L) through :data:`COMMON_REFERENCE_SENSOR`, lights at their
        mean level; ``_gt_common``); ``meta``: scene_id, index, epoch, num_lights, light_id,
        flicker, freq_hz, duty, phase_s (L,) padded, exposure_short_s, exposure_long_s (s), crop (y0, x0, h, w),
        sensor, shutter, flicker_mode ("bins" or "per_frame_weight"), frame_start (index of the sample's first
        frame in the scene's sequence); another capture plan adds architecture, static_windows ("exact" or
        "nearest"), miss_windows_s ((W, 2) s: its shortest capture's windows, the condition ``pwm_miss_prob``) and
        readout ({capture: "global" or "rolling"}, what each capture was read with: its own or the
        preset's readout, else ``shutter``, the dataset's argument).
        Another capture plan (``sensor="lofic"``, ...): its captures by name instead of ``lpd_hcg``, ``lpd_lcg``,
        ``spd`` (DN), ``<capture>_e`` (e-, input-referred to the plan's reference capture, the ``gt`` units),
        ``saturated`` (F, N, h, w) with one channel per capture in plan order, ``gt``: the reference capture's
        photodiode over its windows with every LED at its time-averaged level.
    """

    def __init__(self, root: str | os.PathLike, split: str = "train", sensor: Any = "ovt", frames: int = 3,
                 crop: int | tuple[int, int] | None = None, pwm: Any = None, shutter: str = "global", seed: int = 0,
                 outputs: Sequence[str] = DEFAULT_OUTPUTS, groups: Sequence[str] | None = None,
                 samples_per_scene: int | None = None, noise: bool = True, optics: bool = True,
                 max_lights: int | None = None,
                 cache_dir: str | os.PathLike | bool | None = None, cache_scenes: int = 8,
                 line_time_s: float | None = None, transforms: Callable[[dict], dict] | None = None,
                 frame_start: int | str = 0, pieces: bool = False, noise_streams: str = "generator",
                 static_windows: str = "nearest") -> None:
        self.root = Path(root)
        sim = SimulationOptions.checked(shutter=shutter, line_time_s=line_time_s, noise=noise, optics=optics,
                                        pieces=pieces, noise_streams=noise_streams, static_windows=static_windows)
        opts = SampleOptions.checked(split=split, frames=frames, frame_start=frame_start, crop=crop, outputs=outputs,
                                     groups=groups, samples_per_scene=samples_per_scene, seed=seed,
                                     max_lights=max_lights)
        cache = CacheOptions.checked(self.root, cache_dir=cache_dir, cache_scenes=cache_scenes)
        #: the checked options (:mod:`lfmbench.datasets.options`); the attributes below repeat them
        self.options, self.simulation, self.cache_options = opts, sim, cache
        self.pieces, self.noise_streams, self.static_windows = sim.pieces, sim.noise_streams, sim.static_windows
        self._entities: dict[str, SceneEntities] = {}
        if not (self.root / "manifest.json").is_file():
            raise DatasetNotFoundError(
                f"root: no lfmbench corpus at {self.root} (manifest.json missing). Render one with "
                f"`lfmbench render --out {self.root}` or import ISET-LFM data with `lfmbench import-isetlfm`.")
        self.corpus = Corpus(self.root)
        self.frame_start = opts.frame_start
        self.split, self.shutter, self.seed = opts.split, sim.shutter, opts.seed
        self.frames, self.outputs = opts.frames, opts.outputs
        self.groups = None if opts.groups is None else list(opts.groups)
        self.samples_per_scene, self.noise, self.optics = opts.samples_per_scene, sim.noise, sim.optics
        self.transforms = transforms
        self.preset = _sensor.resolve(sensor)
        self.sensor_name = self.preset.name
        self.architecture = self.preset.architecture
        # a capture plan other than the split pixel reads layers projected at unit fill factor (its own windows)
        self._layer_preset = unit_projection_preset(self.preset)
        # gt_common: one reference window through one fixed reference projection, whatever the sensor
        self._common_preset = unit_projection_preset(_sensor.resolve(COMMON_REFERENCE_SENSOR)) \
            if "gt_common" in self.outputs else None
        self._common_cache: OrderedDict = OrderedDict()
        if self.pieces and "gt_common" in self.outputs:
            raise ValueError("outputs: 'gt_common' is made on the per-sample path only (pieces=False)")
        if self.architecture != "split_pixel" and (self.pieces or self.noise_streams != "generator"):
            raise ValueError(f"sensor: preset {self.sensor_name!r} ({self.architecture}) runs on the per-sample path "
                             "only: pieces=True and noise_streams='counter' (simulate_batch, DeviceBatches) serve "
                             "the split pixel")
        self.pwm: PWMConfig = load_pwm_config(pwm)
        self.crop = opts.crop
        self.scene_ids = self._split_scenes()
        if not self.scene_ids:
            raise DatasetNotFoundError(f"root: corpus {self.root} has no scenes in split {brief(split)}")
        if self.groups is not None:
            have = sorted({g for sid in self.scene_ids for g in self.corpus.meta(sid)["groups"]})
            unknown = [g for g in self.groups if g not in have]
            if unknown:
                raise ValueError(f"groups: {unknown} are not light groups of any scene in split {brief(split)} of "
                                 f"{self.root}; available: {have}")
        most = max([len(self._lights(sid)) for sid in self.scene_ids] + [0])
        if max_lights is None:
            max_lights = max(DEFAULT_MAX_LIGHTS, most)
        elif isinstance(max_lights, bool) or not isinstance(max_lights, (int, np.integer)) or max_lights < most:
            worst = max(self.scene_ids, key=lambda sid: len(self._lights(sid)))
            raise ValueError(f"max_lights={brief(max_lights)} but scene {brief(worst)} of {self.root} has {most} lights; pass "
                             f"max_lights >= {most} or leave it at None")
        self.max_lights = int(max_lights)
        for sid in self.scene_ids:
            m = self.corpus.meta(sid)
            first = 0 if frame_start == "random" else frame_start
            if first + frames > m["frames"]:
                raise ValueError(f"frames={frames}, frame_start={frame_start} but scene {brief(sid)} of {self.root} has "
                                 f"only {m['frames']} frames")
            if self.crop is not None and (self.crop[0] > m["height"] or self.crop[1] > m["width"]):
                side = min(m["height"], m["width"]) // 2 * 2
                raise ValueError(f"crop {self.crop} is larger than scene {brief(sid)} ({m['height']}x{m['width']} px): "
                                 f"pass crop=None for whole frames, or at most crop={side} (or (h, w) with h <= "
                                 f"{m['height']}, w <= {m['width']})")
            if line_time_s is not None and shutter == "rolling":
                check_line_time(m, line_time_s, m["height"])
            if self.architecture != "split_pixel":  # every window inside the corpus's capture window
                plan_exposures(self.preset, m, shutter, line_time_s, f"corpus {self.root} (scene {sid})",
                               static_windows)
        self.line_time_s = line_time_s
        self.cache_dir = cache.cache_dir
        self._cache: OrderedDict[str, SceneLayers] = OrderedDict()
        self._cache_scenes = cache.cache_scenes
        self._derived: dict[str, tuple[SceneLayers, dict]] = {}
        self._fpn: dict | None = None
        # the epoch lives in shared memory: DataLoader workers (also persistent ones, which keep their copy of the
        # dataset across epochs) read the value set_epoch writes in the main process
        self._epoch = torch.zeros((), dtype=torch.int64).share_memory_()
        self._frozen = self._load_or_freeze_test_params() if split == "test" else None
        _warm_cpu_kernels(self.noise, self.preset)

    # -- bookkeeping
    def _split_scenes(self) -> list[str]:
        if self.split == "all":
            return list(self.corpus.scenes)
        splits = self.corpus.splits
        if self.split not in splits:
            raise ValueError(f"split {brief(self.split)} is not in {self.root / 'splits.json'} ({sorted(splits)})")
        complete = set(self.corpus.scenes)
        return [s for s in splits[self.split] if s in complete]

    def set_epoch(self, epoch: int) -> None:
        """Select the epoch whose draws ``__getitem__`` makes (call before iterating, like DistributedSampler).

        The value is kept in shared memory, so DataLoader workers see it, also with ``persistent_workers=True``."""
        self._epoch.fill_(check_int_arg("epoch", epoch, 0))

    @property
    def epoch(self) -> int:
        """The epoch set by :meth:`set_epoch` (0 at first)."""
        return int(self._epoch)

    def __len__(self) -> int:
        return len(self.scene_ids) * self.samples_per_scene

    def _lights(self, sid: str) -> list[dict]:
        m = self.corpus.meta(sid)
        use = set(m["groups"]) if self.groups is None else set(self.groups)
        return sorted((lt for lt in m.get("lights", []) if lt["group"] in use), key=lambda lt: int(lt["id"]))

    def _draw(self, sid: str, rng: np.random.Generator) -> tuple[dict, dict]:
        """PWM parameters for the scene's flickering lights (by id) and flickering groups (by name):
        :func:`lfmbench.datasets.pwm.draw_scene_pwm` as plain dicts."""
        return draw_scene_pwm(self.pwm, self.corpus.meta(sid), rng, self.groups).to_dicts()

    def _frozen_copy_path(self) -> Path | None:
        """Where the frozen draws of a corpus that cannot be written are kept: ``<cache_dir>/test_params/<first
        16 hex of the manifest's SHA-256>.json`` (None without a cache directory)."""
        if self.cache_dir is None:
            return None
        man = hashlib.sha256((self.root / "manifest.json").read_bytes()).hexdigest()[:16]
        return self.cache_dir / "test_params" / f"{man}.json"

    def _read_test_params(self, path: Path) -> dict:
        try:
            data = load_json(path, "test-parameter file")
            if not isinstance(data, dict) or not isinstance(data.get("samples"), dict):
                raise ValueError("'samples' must be an object")
        except (OSError, ValueError) as exc:
            why = str(exc).removeprefix(f"{path}: ")
            raise ValueError(f"{path}: not a valid test-parameter file ({why}); delete it to re-freeze") from None
        return data

    def _load_or_freeze_test_params(self) -> dict:
        """Frozen PWM draws and noise seeds of the test split (``<root>/test_params.json``).

        Entries are keyed ``"<scene_id>/<sample>"`` and never change once written, whatever the dataset's seed
        or the code's later draw procedure; entries a larger ``samples_per_scene`` (or a new scene) needs are
        drawn from the key alone and appended (atomic rewrite).

        A corpus that cannot be written (read-only, shared): the entries it lacks are kept in the cache directory
        (:meth:`_frozen_copy_path`, read back next time) or, without a writable one, in memory for this run with
        one warning. They are drawn from the key alone, so every run draws the same ones.
        """
        path = self.root / TEST_PARAMS_NAME
        data = {"format": 1, "pwm": self.pwm.to_dict(), "samples": {},
                "note": "frozen PWM draws of the test split; delete to re-draw (changes every test score)"}
        if path.exists():
            data = self._read_test_params(path)
        copy = None
        try:
            copy = self._frozen_copy_path()
        except OSError:
            pass
        if copy is not None and copy.exists():
            for k, v in self._read_test_params(copy)["samples"].items():
                data["samples"].setdefault(k, v)
        samples = data["samples"]
        added = False
        for sid in self.scene_ids:
            for s in range(self.samples_per_scene):
                key = f"{sid}/{s}"
                if key not in samples:
                    rng = frozen_test_rng(sid, s)
                    per_light, per_group = self._draw(sid, rng)
                    samples[key] = {"lights": {str(k): v for k, v in per_light.items()}, "groups": per_group,
                                    "noise_seed": int(rng.integers(2**62))}
                    added = True
                if self.frame_start == "random" and "frame_u" not in samples[key]:
                    # the window start, as a fraction of the possible starts (any F), from its own stream:
                    # added to older entries without changing their draws
                    samples[key]["frame_u"] = float(frozen_test_rng(sid, s, stream=1).random())
                    added = True
        if added:
            self._save_test_params(path, copy, data)
        return samples

    def _save_test_params(self, path: Path, copy: Path | None, data: dict) -> None:
        """Write the frozen draws into the corpus; where it cannot be written, into ``copy`` (the cache
        directory), else keep them in memory with one warning."""
        import errno  # noqa: PLC0415
        import warnings  # noqa: PLC0415

        from lfmbench.fileio import AtomicWriteError  # noqa: PLC0415

        read_only = (errno.EACCES, errno.EPERM, errno.EROFS)
        try:
            atomic_write_json(path, data)
            return
        except AtomicWriteError as exc:
            if exc.errno not in read_only:
                raise
        if copy is not None:
            try:
                atomic_write_json(copy, data)
                return
            except AtomicWriteError as exc:
                if exc.errno not in read_only:
                    raise
        warnings.warn(f"{path}: the corpus cannot be written and there is no writable cache directory: the frozen "
                      "test draws of this run are kept in memory only (they are drawn from the scene and sample "
                      "alone, so the next run draws the same ones); pass --cache-dir DIR to keep them",
                      RuntimeWarning, stacklevel=3)

    def draws_fingerprint(self) -> str | None:
        """What a test result's draws were: SHA-256 of the canonical JSON of the frozen entries
        (``test_params.json``) of exactly the samples this dataset serves (its scenes x ``samples_per_scene``;
        PWM per light and group, noise seed, and the window start when ``frame_start="random"``). Results made
        with identical draws keep the same fingerprint when the file gains entries for other scenes or samples.
        None outside the test split."""
        if self._frozen is None:
            return None
        used = {}
        for sid in self.scene_ids:
            for s in range(self.samples_per_scene):
                e = self._frozen[f"{sid}/{s}"]
                rec = {k: e.get(k) for k in ("lights", "groups", "noise_seed")}
                if self.frame_start == "random":
                    rec["frame_u"] = e.get("frame_u")
                used[f"{sid}/{s}"] = rec
        return hashlib.sha256(json.dumps(used, sort_keys=True).encode("utf-8")).hexdigest()

    def _layers(self, sid: str) -> SceneLayers:
        if sid in self._cache:
            self._cache.move_to_end(sid)
            return self._cache[sid]
        layers = load_or_build(self.corpus, sid, self._layer_preset, self.groups, self._frames_to_load(sid), self.optics,
                               self.cache_dir, aux=aux_channels(self.outputs))
        if self._cache_scenes:
            self._cache[sid] = layers
            while len(self._cache) > self._cache_scenes:
                self._cache.popitem(last=False)
        return layers

    def _scene_cached(self, sid: str, key: str, build: Callable[[SceneLayers], Any],
                      layers: SceneLayers | None = None) -> Any:
        """``build(layers)`` of scene ``sid``: something fixed per scene (not per crop or draw), computed once and
        kept as long as the scene's layers stay in the in-memory cache (recomputed per call without it).
        ``layers``: the scene's layers if the caller has them (``self._layers(sid)`` otherwise)."""
        layers = self._layers(sid) if layers is None else layers
        if sid not in self._cache:
            return build(layers)
        held = self._derived.get(sid)
        if held is None or held[0] is not layers:
            for s in [s for s in self._derived if s not in self._cache]:
                del self._derived[s]
            held = self._derived[sid] = (layers, {})
        if key not in held[1]:
            held[1][key] = build(layers)
        return held[1][key]

    def _frames_to_load(self, sid: str) -> int:
        """Leading frames of scene ``sid`` a sample can use: s + F for a fixed start s, all for ``"random"``."""
        if self.frame_start == "random":
            return int(self.corpus.meta(sid)["frames"])
        return self.frame_start + self.frames

    def _start(self, sid: str, u: float) -> int:
        """First frame of a ``"random"`` window from ``u`` in [0, 1): uniform over the N - F + 1 starts."""
        return start_frame(u, int(self.corpus.meta(sid)["frames"]) - self.frames + 1)

    def _fixed_pattern(self, H: int, W: int) -> dict | None:
        if not self.noise:
            return None
        if self._fpn is None or next(iter(self._fpn.values())).shape[-2:] != (H, W):
            self._fpn = _sensor.fixed_pattern(self.preset, H, W)
        return self._fpn

    # -- sample
    def __getitem__(self, index: int) -> dict:
        sid, per_light, per_group, crop, noise_seed, start = self.draws(index)
        if self.pieces:
            sample = capture_pieces(self, sid, per_light, per_group, crop, noise_seed, index, start)
        else:
            sample = self.simulate(sid, per_light, per_group, crop, noise_seed, index, start)
        return self.transforms(sample) if self.transforms else sample

    def draws(self, index: int, streams: str | None = None) -> tuple:
        """The random draws of sample ``index`` (functions of ``(seed, epoch, index)``; frozen for ``test``).

        ``streams``: ``"generator"`` (a numpy generator seeded ``(seed, epoch, index)``) or ``"counter"``
        (:mod:`lfmbench.datasets.counter_draws`); default the dataset's ``noise_streams``.

        Returns:
            ``(scene_id, per_light, per_group, crop, noise_seed, frame_start)``: PWM dicts by light id and by
            flickering group, crop (y0, x0, h, w) in pixels, the sensor-noise seed and the first frame.
        """
        if not 0 <= index < len(self):
            raise IndexError(f"index {index} out of range for a dataset of {len(self)} samples")
        sid = self.scene_ids[index // self.samples_per_scene]
        sub = index % self.samples_per_scene
        meta = self.corpus.meta(sid)
        H, W = meta["height"], meta["width"]
        counter = (self.noise_streams if streams is None else streams) == "counter"
        rng = None if counter else np.random.default_rng([self.seed, self.epoch, index])
        if self._frozen is not None:
            fr = self._frozen.get(f"{sid}/{sub}")
            if fr is None:
                raise ValueError(f"{self.root / TEST_PARAMS_NAME} has no entry for {sid}/{sub}; delete it to re-freeze")
            per_light = {int(k): v for k, v in fr["lights"].items()}
            per_group = fr["groups"]
            noise_seed = int(fr["noise_seed"])
            u = float(fr.get("frame_u", 0.0))
        elif counter:
            draw = counter_scene_draw(self.pwm, self.entities(sid), self.seed, self.epoch, index)
            per_light, per_group = apply_light_timing(draw, meta).to_dicts()   # drivers, scan rows (v2 scenes)
            noise_seed = int(noise_seeds(self.seed, self.epoch, index))
            u = None
        else:
            per_light, per_group = self._draw(sid, rng)
            noise_seed = int(rng.integers(2**62))
            u = None
        ch, cw = self.crop if self.crop is not None else (H, W)
        place = place_uniforms(self.seed, self.epoch, index).tolist() if counter else None
        if self.crop is None or self.split == "test":
            y0, x0 = ((H - ch) // 2) & ~1, ((W - cw) // 2) & ~1
        elif counter:
            y0, x0 = crop_origin(place[0], H, ch), crop_origin(place[1], W, cw)
        else:
            y0 = 2 * int(rng.integers(0, (H - ch) // 2 + 1))
            x0 = 2 * int(rng.integers(0, (W - cw) // 2 + 1))
        if self.frame_start == "random":
            if u is None:
                u = place[2] if counter else float(rng.random())  # drawn last: other draws unchanged
            start = self._start(sid, u)
        else:
            start = self.frame_start
        return sid, per_light, per_group, (y0, x0, ch, cw), noise_seed, start

    def entities(self, scene_id: str) -> SceneEntities:
        """The PWM entities of scene ``scene_id`` under this dataset's PWM config and groups (the order of the
        counter-based PWM draws; :class:`lfmbench.datasets.counter_draws.SceneEntities`)."""
        ents = self._entities.get(scene_id)
        if ents is None:
            ents = self._entities[scene_id] = SceneEntities.of(self.pwm, self.corpus.meta(scene_id), self.groups)
        return ents

    def simulate(self, scene_id: str, params: Mapping[int, Mapping], group_params: Mapping[str, Mapping] | None = None,
                 crop: tuple[int, int, int, int] | None = None, noise_seed: int = 0, index: int = -1,
                 frame_start: int | None = None) -> dict:
        """One sample with given PWM parameters (what ``__getitem__`` does after its draws).

        Args:
            scene_id: a scene of the corpus.
            params: light id -> ``{"period_s", "duty", "phase_s", "rise_s", "fall_s", "freq_hz"}`` (s, 1, s, s, s,
                Hz) for the flickering lights (``phase_s``: a rising edge after the start of frame 0).
            group_params: the same per flickering group stored without bins (imported data).
            crop: (y0, x0, h, w) in pixels, even offsets; None = full frame.
            noise_seed: seed of the sensor noise. index: recorded in ``meta``.
            frame_start: first frame of the F frames (None: the dataset's ``frame_start``, 0 for ``"random"``).

        Returns:
            the sample dict (see the class docstring), without ``transforms``.
        """
        view = self.scene(scene_id)
        meta = view.meta
        H, W = meta["height"], meta["width"]
        y0, x0, ch, cw = (0, 0, H, W) if crop is None else crop
        crop = (y0, x0, ch, cw)
        params = {int(k): v for k, v in params.items()}
        group_params = dict(group_params or {})
        F = self.frames
        s0 = self.first_frame(scene_id, frame_start)
        layers = view.layers
        tm = meta["timing"]
        want = set(self.outputs)
        if self.architecture == "split_pixel":  # the split pixel's timing (docs/guide/contracts.md), its exposures
            frames = [compose_frame(layers, meta, f, crop, params, group_params, self.shutter, self.line_time_s)
                      for f in range(s0, s0 + F)]
            layer_of = {"lpd_hcg": "lpd", "spd": "spd"}
            exposure_s = {"lpd_hcg": float(tm["short_exposure_s"]), "spd": float(tm["long_exposure_s"])}
        else:                                    # any other capture plan: its exposures over their windows
            exposures = plan_exposures(self.preset, meta, self.shutter, self.line_time_s, f"corpus {self.root}",
                                       self.static_windows)
            ref = next(k for k, caps in self.preset.exposures.items() if self.preset.reference in caps)
            frames = [compose_plan_frame(layers, meta, f, crop, params, group_params, exposures, ref)
                      for f in range(s0, s0 + F)]
            layer_of = {x.key: x.key for x in exposures}
            exposure_s = {x.key: x.length_s for x in exposures}
        cap = None
        if want & SENSOR_OUTPUTS:
            mean_e = {k: torch.stack([fr_[v] for fr_ in frames])[:, None] for k, v in layer_of.items()}  # (F,1,h,w)
            fpn = self._fixed_pattern(H, W)
            if fpn is not None:
                fpn = {k: v[..., y0:y0 + ch, x0:x0 + cw] for k, v in fpn.items()}
            counter = self.noise and self.noise_streams == "counter"
            gen = torch.Generator().manual_seed(int(noise_seed)) if self.noise and not counter else None
            try:
                if counter:  # a batch of one: the sample's counter streams (what the device path draws)
                    cap = _sensor.simulate_split_pixel_electrons(
                        mean_e["lpd_hcg"][None], mean_e["spd"][None], self.preset, exposure_s["lpd_hcg"],
                        exposure_s["spd"], noise=True, fpn=None if fpn is None else {k: v[None] for k, v in fpn.items()},
                        seeds=torch.tensor([int(noise_seed)]))
                    cap = {k: v[0] for k, v in cap.items()}
                else:
                    cap = _sensor.simulate_plan_electrons(mean_e, self.preset, exposure_s, gen, self.noise, fpn)
            except ValueError as exc:  # e.g. non-finite electrons from implausible radiance: name the scene
                raise ValueError(f"scene {brief(scene_id)} of {self.root} (frames {s0}..{s0 + F - 1}): {exc}; check "
                                 f"the corpus with `lfmbench validate {self.root}`") from None
        gt = torch.stack([fr_["gt"] for fr_ in frames])[:, None] if want & {"gt", "rgb"} else None
        meta_out = self.sample_meta(view, index, params, crop, s0)
        li = view.light_index()[s0:s0 + F, :, y0:y0 + ch, x0:x0 + cw].long() if "light_index" in want else None
        depth = layers.aux["depth.Z"][s0:s0 + F, y0:y0 + ch, x0:x0 + cw][:, None] if "depth" in want else None
        sample = assemble_sample(want, cap, gt, self.preset, li, depth)
        if "gt_common" in want:
            sample["gt_common"] = self._gt_common(scene_id, meta, crop, params, group_params, s0)
        sample["meta"] = meta_out
        return sample

    def _gt_common(self, scene_id: str, meta: dict, crop: tuple, params: dict, group_params: dict,
                   s0: int) -> torch.Tensor:
        """(F, 1, h, w) e-: the ground truth common to every sensor (output ``gt_common``): the scene over one fixed
        reference window, the corpus's long window [0, T_L) of each frame (static groups exact, every light at its
        time-averaged level, as ``gt``), projected through one reference sensor (:data:`COMMON_REFERENCE_SENSOR`, unit
        fill factor, global readout) instead of the dataset's own. Two datasets of different sensors on the same
        corpus, crop, draws and frames give the same tensor: the reference of cross-sensor columns, beside each
        sensor's own ``gt`` (its reference exposure) for its LED metrics."""
        if scene_id in self._common_cache:
            layers = self._common_cache[scene_id]
            self._common_cache.move_to_end(scene_id)
        else:
            layers = load_or_build(self.corpus, scene_id, self._common_preset, self.groups,
                                   self._frames_to_load(scene_id), self.optics, self.cache_dir, aux=())
            self._common_cache[scene_id] = layers
            while len(self._common_cache) > max(1, self._cache_scenes):
                self._common_cache.popitem(last=False)
        ref = [PlanExposure("common", 1.0, ((0.0, float(meta["timing"]["long_exposure_s"])),), False, 0.0)]
        return torch.stack([compose_plan_frame(layers, meta, f, crop, params, group_params, ref, "common")["gt"]
                            for f in range(s0, s0 + self.frames)])[:, None]

    def scene(self, scene_id: str) -> SceneView:
        """The scene ``scene_id`` as this dataset holds it (:class:`SceneView`)."""
        return SceneView(self, scene_id)

    def first_frame(self, scene_id: str, frame_start: int | None) -> int:
        """The first of a sample's F frames (``None``: the dataset's ``frame_start``, 0 for ``"random"``), checked
        against the frames the dataset holds of ``scene_id``."""
        if frame_start is None:
            frame_start = 0 if self.frame_start == "random" else self.frame_start
        s0, F = int(frame_start), self.frames
        if s0 < 0 or s0 + F > self._frames_to_load(scene_id):
            raise ValueError(f"frame_start: frames {s0}..{s0 + F - 1} are not all available for scene {brief(scene_id)} "
                             f"(dataset frame_start={brief(self.frame_start)}, frames={F}, scene frames "
                             f"{self.corpus.meta(scene_id)['frames']})")
        return s0

    def sample_meta(self, view: SceneView, index: int, per_light: Mapping[int, Mapping],
                    crop: tuple[int, int, int, int], frame_start: int) -> dict:
        """The ``meta`` of a sample of scene ``view`` (class docstring): the per-light arrays padded to
        ``max_lights`` in the order of ``view.lights``, exposures (s), crop (px), sensor, shutter, flicker mode.

        Raises:
            ValueError: the scene has more lights than ``max_lights``.
        """
        lights = view.lights
        L, n = self.max_lights, len(lights)
        if n > L:
            raise ValueError(f"max_lights={L} but scene {brief(view.scene_id)} has {n} lights")
        tm = view.meta["timing"]
        ids = [int(lt["id"]) for lt in lights]
        ps = [per_light.get(i) for i in ids]
        light_id = torch.tensor(ids + [-1] * (L - n), dtype=torch.long)
        flick = torch.tensor([p is not None for p in ps] + [False] * (L - n), dtype=torch.bool)
        arr = {k: torch.tensor([(d if p is None else p[k]) for p in ps] + [0.0] * (L - n), dtype=torch.float64)
               for k, d in (("freq_hz", 0.0), ("duty", 1.0), ("phase_s", 0.0))}
        mode = "per_frame_weight" if view.layers.group_static else "bins"
        out = {"scene_id": view.scene_id, "index": index, "epoch": self.epoch, "num_lights": n,
               "light_id": light_id, "flicker": flick, **arr, "exposure_short_s": float(tm["short_exposure_s"]),
               "exposure_long_s": float(tm["long_exposure_s"]), "crop": torch.tensor(crop),
               "sensor": self.sensor_name, "shutter": self.shutter, "flicker_mode": mode,
               "frame_start": int(frame_start)}
        if self.architecture != "split_pixel":  # (the split pixel's meta is unchanged: the batched paths share it)
            out.update(miss_windows_s=self._miss_windows(tm))
            out.update(architecture=self.architecture, static_windows=self._static_window_mode(tm),
                       readout={k: self.preset.capture_readout(k).shutter or self.shutter
                                for k in self.preset.captures})
        return out

    def _miss_windows(self, timing: Mapping[str, Any]) -> torch.Tensor:
        """(W, 2) float64 ``(start_s, length_s)`` windows of the plan's shortest capture (least integration time: the
        one that carries the brightest lamps, and the one that misses a PWM light first), from which the condition
        ``pwm_miss_prob`` of this sensor is computed (:func:`lfmbench.evaluation.conditions.sample_conditions`,
        :func:`lfmbench.flicker.windows_miss_probability`): each sensor binned by its own windows."""
        from lfmbench.sensor.plan import resolve_windows, total_length_s  # noqa: PLC0415

        wins = [resolve_windows(c.exposure, timing) for c in self.preset.captures.values()]
        return torch.tensor(min(wins, key=total_length_s), dtype=torch.float64).reshape(-1, 2)

    def _static_window_mode(self, timing: Mapping[str, Any]) -> str:
        """``"exact"`` when every capture's windows are ones the corpus stores for its static groups (always for
        the split pixel; a chopped union where the corpus has its static window layer), else ``"nearest"`` (served by the measured approximation, :data:`STATIC_WINDOW_RULES`)."""
        from lfmbench.sensor.plan import resolve_windows  # noqa: PLC0415

        exact = all(exposure_static_exact(resolve_windows(c.exposure, timing), timing)
                    for c in self.preset.captures.values())
        return "exact" if exact else "nearest"

    # -- display
    def plot(self, sample: Mapping[str, Any], outputs: Mapping[str, torch.Tensor] | None = None,
             isp: Any = "default", frames: int | None = None, prediction: torch.Tensor | None = None):
        """A matplotlib Figure of ``sample`` (one of this dataset's, or a batch of one): a row per capture of the
        sensor's plan, the ground truth and each of ``outputs`` (title -> (F, 1, h, w) estimate in ``gt`` units,
        e.g. a method's output), a column per frame, every image through the ISP ``isp`` with the ground truth's
        statistics, LED regions outlined (:func:`lfmbench.datasets.plot.plot_sample`). ``prediction``: one
        estimate, shown as "prediction". Save it with ``fig.savefig("sample.png")``.
        """
        from lfmbench.datasets.plot import plot_sample  # noqa: PLC0415

        outs = dict(outputs or {})
        if prediction is not None:
            outs["prediction"] = prediction
        return plot_sample(sample, self.preset, outs, isp=isp, frames=frames)
