"""Captures from a corpus resident on the training device (issue 28): the projected layers of a split's scenes are
loaded onto the device once, and every batch is cut, drawn, composed and simulated there.

The per-sample DataLoader path builds each sample's pieces in CPU workers (4 MiB of crops and gathered rates per
3-frame 256 x 256 sample) and copies them to the device. Here (:class:`DeviceBatches`):

1. :class:`ResidentScenes` checks the split against a memory budget (:class:`ResidentMemoryError` before anything is
   copied) and packs it (:class:`SplitProgram`): static rates (nS, Fs, 2, H, W), ``light_index``, ``depth`` and
   every lamp pixel entry of every frame in one entry-major table sorted by tile, float32 or float16 (scaled per
   scene by a power of two). Splits that cannot be packed (scenes of several sizes, groups stored without bins)
   keep per-scene layers and take :func:`lfmbench.datasets.pieces.capture_pieces` sample by sample.
   ``chunk_scenes`` streams a split that does not fit. Lights with their own timing (scene version 2: drivers,
   message-sign scan rows, indicators, strobes, countdowns, destination displays) are packed like any light: their
   rules are tables of the program (below).
2. A batch is one program of tensor operations (:meth:`SplitProgram.pieces`): the draws of every sample from
   counter uniforms of (seed, epoch, index) (:mod:`lfmbench.datasets.counter_draws`: the numbers the per-sample
   path draws with ``noise_streams="counter"``; made on the host, a few small CPU operations, and copied with the
   batch's indices; a light on a shared ``driver`` gathers its driver's draw, a scan row's draw is made its row's
   PWM by :func:`lfmbench.datasets.pwm.scan_row_record`), slots for every lamp of every frame with a visibility
   mask, the slots of gated lights with their gates (``gate_slot``, ``gate_table``: the waveform's
   :class:`~lfmbench.flicker.waveforms.GateTable`, whose exposure :func:`~lfmbench.datasets.batch_compose.pwm_weights`
   applies), the
   crop's entries as runs of tiles, one gather per layer, ``meta`` as device tensors; no Python per sample and no
   host synchronisation.
3. The batch is composed and simulated on the device by :func:`lfmbench.datasets.batched.simulate_batch` with
   counter-based noise (:mod:`lfmbench.sensor.counter_noise`).

Memory: per pixel and frame 4 (or 2) bytes x 2 of static rates, 2 of light index, 4 of depth, plus (8 x K + 12)
bytes (float16: 4 x K + 12) per pixel inside a lamp's box; :meth:`ResidentScenes.estimate` gives the bytes of a split
before anything is loaded to the device (docs/guide/datasets.md, "Corpus on the device").

Over 500 lines for now: the resident split (:class:`ResidentScenes`), its packing (:class:`SplitProgram`, whose
``pieces`` alone is about 180 lines) and the batch loop live here while the device path is being reworked; the
packing is to move to a module of its own.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator

import numpy as np
import torch

from lfmbench.counter_rng import uniforms
from lfmbench.datasets.batched import collate_pieces, pieces_to, simulate_batch, tensor_leaves
from lfmbench.datasets.counter_draws import (PURPOSE_PWM, PWM_UNIFORMS, crop_origin, noise_seeds, place_uniforms,
                                             pwm_from_uniforms, sample_keys, start_frame)
from lfmbench.datasets.pieces import PWM_FIELDS, _SceneEntries, capture_pieces, gate_rows
from lfmbench.datasets.pwm import driver_sources, has_light_timing, light_waveforms, scan_row_record
from lfmbench.datasets.row_gather import gather_rows
from lfmbench.flicker.waveforms import GatedWaveform, ScanRow
from lfmbench.triton_kernels import TritonKernels
from lfmbench.vocabulary import PHOTODIODES

__all__ = ["STORAGE_DTYPES", "ResidentMemoryError", "ResidentScene", "ResidentScenes", "DeviceBatches", "epoch_order",
           "DEFAULT_BUDGET_FRACTION", "free_device_bytes"]

#: Storage types of the resident rates: float32, or float16 (scaled per scene by a power of two; half the memory,
#: relative error at most 2^-11 of a rate; docs/guide/datasets.md, "Corpus on the device").
STORAGE_DTYPES = (torch.float32, torch.float16)

#: Share of the device's free memory a resident split may take by default (the rest: the batch, the network).
DEFAULT_BUDGET_FRACTION = 0.5


class ResidentMemoryError(ValueError):
    """A split's layers do not fit the memory budget of the device (raised before anything is copied)."""


def epoch_order(n: int, seed: int, epoch: int) -> torch.Tensor:
    """The order of an epoch's ``n`` samples: a permutation that depends only on ``(seed, epoch)`` (the one
    :class:`lfmbench.train.EpochSampler` uses)."""
    g = torch.Generator().manual_seed(int(seed) * 1_000_003 + int(epoch))
    return torch.randperm(int(n), generator=g)


def free_device_bytes(device: torch.device) -> int:
    """Bytes free on CUDA ``device`` for new tensors: the driver's free memory plus what PyTorch's caching
    allocator holds without using (a freed tensor's memory stays reserved there, invisible to the driver)."""
    free, _total = torch.cuda.mem_get_info(device)
    return int(free + torch.cuda.memory_reserved(device) - torch.cuda.memory_allocated(device))


@dataclass
class ResidentScene:
    """One scene's layers on a device (float32 rates in e-/s; ``light_index`` int16/int32; ``depth`` m)."""

    static: torch.Tensor           # (Fs, 2, H, W)
    group_static: dict             # group -> pd -> (Fs, H, W)
    entries: list                  # per frame: (2, Kscene, N) rates of the pixel entries
    light_index: torch.Tensor | None
    depth: torch.Tensor | None
    #: per frame, where entry i of the scene's ``_SceneEntries`` frame is in ``entries`` (None: at i)
    entry_order: list | None = None

    def nbytes(self) -> int:
        ts = [self.static, self.light_index, self.depth, *self.entries,
              *(t for g in self.group_static.values() for t in g.values())]
        return sum(int(t.numel()) * t.element_size() for t in ts if t is not None)


class ResidentScenes:
    """The projected layers of the scenes of ``ds`` (an :class:`~lfmbench.datasets.LFMCaptureDataset`) on ``device``.

    Args:
        ds: the dataset (its sensor, frames, groups and optics define the layers).
        device: torch device.
        budget_bytes: the most the layers may take (default: :data:`DEFAULT_BUDGET_FRACTION` of the device's free
            memory on CUDA; no limit on the CPU).

    Raises:
        ResidentMemoryError: the layers of the split need more than ``budget_bytes`` (the message gives both, the
            bytes per scene and how many scenes would fit); nothing has been copied to the device then.
    """

    def __init__(self, ds, device: torch.device | str, budget_bytes: int | None = None,
                 dtype: torch.dtype = torch.float32, scenes: list | None = None) -> None:
        self.device = torch.device(device)
        self.ds = ds
        if dtype not in STORAGE_DTYPES:
            raise ValueError(f"dtype must be one of {STORAGE_DTYPES}, got {dtype!r:.40}")
        want = set(ds.outputs)
        sids = list(dict.fromkeys(ds.scene_ids if scenes is None else scenes))
        packed = SplitProgram.supports(ds, sids)
        if dtype != torch.float32 and not packed:
            raise ValueError(f"dtype={dtype}: float16 layers need a split whose scenes share one size and frame "
                             "count and store every flickering group in time bins; this one does not (use float32)")
        need = self.estimate(ds, packed, dtype, sids)
        if budget_bytes is None and self.device.type == "cuda":
            budget_bytes = int(DEFAULT_BUDGET_FRACTION * free_device_bytes(self.device))
        if budget_bytes is not None and need > budget_bytes:
            per = need / max(len(sids), 1)
            raise ResidentMemoryError(
                f"split {ds.split!r} of {ds.root}: its {len(sids)} scenes need {need / 2**30:.2f} GiB on {self.device} "
                f"({per / 2**20:.0f} MiB per scene), the budget is {budget_bytes / 2**30:.2f} GiB (about "
                f"{int(budget_bytes // per)} scenes): pass budget_bytes, stream the split in chunks "
                f"(DeviceBatches(..., chunk_scenes={max(1, int(budget_bytes // per))})), store float16 layers "
                f"(dtype=torch.float16), or train from the DataLoader path (data='loader')")
        #: the scenes held
        self.scene_ids = sids
        self.bytes = 0
        self._scenes: dict[str, ResidentScene] = {}
        #: the batched program over the packed layers (None: the split cannot be packed; per-sample pieces)
        self.program = SplitProgram(ds, self.device, dtype, sids) if packed else None
        if self.program is not None and dtype != torch.float32:
            self.bytes = self.program.nbytes()      # scaled float16 layers: only the program reads them
            return
        if self.program is not None:
            pr = self.program
            for i, sid in enumerate(pr.sids):
                self._scenes[sid] = ResidentScene(
                    static=pr.static[i], group_static={}, entries=[pr.entries(i, f) for f in range(pr.Fs)],
                    light_index=None if pr.light_index is None else pr.light_index[i],
                    depth=None if pr.depth is None else pr.depth[i], entry_order=pr.order[i])
            self.bytes = pr.nbytes()
            return
        for sid in sids:
            view = ds.scene(sid)
            layers = view.layers
            dev = self.device
            ent = view.cached("pieces_entries", _SceneEntries)
            sc = ResidentScene(
                static=view.static_rates().to(dev),
                group_static={g: {pd: r[pd].to(dev) for pd in PHOTODIODES} for g, r in layers.group_static.items()},
                entries=[torch.from_numpy(fe.vals).to(dev) for fe in ent.frames],
                light_index=view.light_index().to(dev) if "light_index" in want else None,
                depth=layers.aux["depth.Z"].to(dev) if "depth" in want else None)
            self._scenes[sid] = sc
            self.bytes += sc.nbytes()

    @staticmethod
    def estimate(ds, packed: bool | None = None, dtype: torch.dtype = torch.float32, scenes: list | None = None) -> int:
        """Bytes the resident layers of the split of ``ds`` take (``packed``: as :class:`SplitProgram` holds them,
        entries padded to the split's most bins plus 12 bytes of coordinates each; default: whether the split
        can be packed; ``dtype``: of the rates, float32 or float16; ``scenes``: only these)."""
        sids = list(dict.fromkeys(ds.scene_ids if scenes is None else scenes))
        packed = SplitProgram.supports(ds, sids) if packed is None else packed
        kall = None
        if packed:
            kall = max([int(fe.vals.shape[1]) for sid in sids
                        for fe in ds.scene(sid).cached("pieces_entries", _SceneEntries).frames] + [1])
        return sum(ResidentScenes.estimate_scene(ds, sid, kall, dtype) for sid in sids)

    @staticmethod
    def estimate_scene(ds, scene_id: str, kall: int | None = None, dtype: torch.dtype = torch.float32) -> int:
        """Bytes one scene's resident layers take (from its projected layers on the host); ``kall``: its entries
        padded to ``kall`` bins with their coordinates (packed, :class:`SplitProgram`); ``dtype``: of the rates."""
        rb = torch.empty((), dtype=dtype).element_size()
        view = ds.scene(scene_id)
        layers = view.layers
        want = set(ds.outputs)
        fs, _two, H, W = (int(n) for n in view.static_rates().shape)
        n = rb * 2 * fs * H * W
        n += sum(4 * int(r[pd].numel()) for r in layers.group_static.values() for pd in PHOTODIODES)
        frames = view.cached("pieces_entries", _SceneEntries).frames
        if kall is None:
            n += sum(int(fe.vals.nbytes) for fe in frames)
        else:
            n += sum((2 * rb * kall + 12) * int(fe.y.shape[0]) for fe in frames)
        if "light_index" in want:
            n += int(view.light_index().numel()) * view.light_index().element_size()
        if "depth" in want:
            n += 4 * fs * H * W
        return n

    def scene(self, scene_id: str) -> ResidentScene:
        """The resident layers of ``scene_id`` (``KeyError`` naming it when it is not resident)."""
        try:
            return self._scenes[scene_id]
        except KeyError:
            if self.program is not None and self.program.dtype != torch.float32:
                raise KeyError(f"scene {scene_id!r}: float16 layers (scaled per scene) are read only by the batched "
                               "program (DeviceBatches), not per scene") from None
            raise KeyError(f"scene {scene_id!r} is not resident on {self.device}") from None


class DeviceBatches:
    """Simulated training batches of ``ds`` cut from its layers resident on ``device`` (see module docstring).

    Args:
        ds: an :class:`~lfmbench.datasets.LFMCaptureDataset` (not ``pieces=True``; its draws, sensor and outputs).
        batch_size: samples per batch (the last batch of an epoch may be smaller unless ``drop_last``).
        device: torch device of the layers, the simulation and the yielded tensors.
        seed: the order of an epoch's samples is :func:`epoch_order` ``(len(ds), seed, epoch)``.
        budget_bytes: the most the resident layers (with ``chunk_scenes``: one chunk's) and the batches in memory
            may take together: the layers get ``budget_bytes`` less the batch's bytes (twice that with
            ``prefetch`` on CUDA; :meth:`batch_bytes`); default: on CUDA :data:`DEFAULT_BUDGET_FRACTION` of the
            free memory (:func:`free_device_bytes`), asked once here, so that a later chunk is not refused for
            memory the previous chunk's layers held; no limit on the CPU.
        drop_last: drop an epoch's last incomplete batch (of each chunk, when streaming).
        dtype: storage of the resident rates, float32 or float16 (:data:`STORAGE_DTYPES`).
        chunk_scenes: stream the split ``chunk_scenes`` scenes at a time (for a split that does not fit): per epoch
            the scenes are taken in the order :func:`epoch_order` ``(n_scenes, seed, epoch)``, a chunk is loaded,
            its samples are served in an order of ``(seed, epoch, chunk)``, then the next chunk replaces it. The
            samples themselves (draws of ``(seed, epoch, index)``) are the same as without chunks.
        prefetch: on CUDA, make each batch on a side stream one batch ahead, so that its program runs on the GPU
            while the caller's work on the previous batch (a training step) runs (the same batches; one batch more
            in memory). Ignored on other devices.
        scenes: hold and serve only these scene ids of the split (a torchrun rank's share,
            :class:`lfmbench.distributed.RankDeviceBatches`): only their layers are loaded, an epoch is their
            samples (dataset indices as in the whole split) in the order :func:`epoch_order` of their number.
            Not with ``chunk_scenes``.

    Iterating yields the per-sample path's sample dicts with a leading B (on ``device``, ``meta`` too when the
    batched program makes them), noise from counter-based streams. ``set_epoch(e)`` selects the draws and the order
    of epoch ``e``.
    """

    def __init__(self, ds, batch_size: int, device: torch.device | str, seed: int = 0,
                 budget_bytes: int | None = None, drop_last: bool = False, dtype: torch.dtype = torch.float32,
                 chunk_scenes: int | None = None, prefetch: bool = False, scenes: list | None = None) -> None:
        if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
            raise ValueError(f"batch_size must be an integer >= 1, got {batch_size!r}")
        if getattr(ds, "pieces", False):
            raise ValueError("ds: DeviceBatches builds the pieces itself; make the dataset without pieces=True")
        self.ds = ds
        self.batch_size = batch_size
        self.device = torch.device(device)
        self.seed = int(seed)
        self.drop_last = bool(drop_last)
        self.prefetch = bool(prefetch)
        self.epoch = 0
        if chunk_scenes is not None and (isinstance(chunk_scenes, bool) or not isinstance(chunk_scenes, int)
                                         or chunk_scenes < 1):
            raise ValueError(f"chunk_scenes must be None or an integer >= 1, got {chunk_scenes!r:.40}")
        self.chunk_scenes = chunk_scenes
        self.dtype = dtype
        if budget_bytes is None and self.device.type == "cuda":
            budget_bytes = int(DEFAULT_BUDGET_FRACTION * free_device_bytes(self.device))
        self.budget_bytes = budget_bytes
        self.layer_budget = None        # the layers' part of the budget (None: no limit)
        if budget_bytes is not None:
            reserve = self.batch_bytes(ds, batch_size) * (2 if self.prefetch and self.device.type == "cuda" else 1)
            self.layer_budget = int(budget_bytes - reserve)
            if self.layer_budget <= 0:
                raise ResidentMemoryError(
                    f"budget {budget_bytes / 2**20:.1f} MiB on {self.device}: the batches alone take "
                    f"{reserve / 2**20:.1f} MiB (batch_size {batch_size}"
                    f"{', twice for the prefetched batch' if reserve > self.batch_bytes(ds, batch_size) else ''}); "
                    "pass a larger budget or a smaller batch")
        self._sids = list(dict.fromkeys(ds.scene_ids))
        if chunk_scenes is not None and len(self._sids) != len(ds.scene_ids):
            raise ValueError(f"ds: the split lists a scene twice ({len(ds.scene_ids)} ids, {len(self._sids)} scenes)")
        #: the dataset indices served (None: every sample of the split)
        self.own = None
        if scenes is not None:
            if chunk_scenes is not None:
                raise ValueError("scenes and chunk_scenes: a share of the split is not streamed by chunks")
            pos = {sid: p for p, sid in enumerate(ds.scene_ids)}
            missing = [s for s in scenes if s not in pos]
            if missing or not scenes:
                raise ValueError(f"scenes: {missing[0] if missing else 'none given'!r:.60} is not a scene of split "
                                 f"{ds.split!r} of {ds.root}")
            sps = ds.samples_per_scene
            self.own = [pos[s] * sps + k for s in dict.fromkeys(scenes) for k in range(sps)]
        # the whole split (or the given scenes), or (chunks) the first chunk of epoch 0, which iterating that epoch
        # then starts from
        first = (None if scenes is None else list(dict.fromkeys(scenes))) if chunk_scenes is None else [
            self._sids[p] for p in self._chunks()[0]]
        self.resident = ResidentScenes(ds, self.device, self.layer_budget, dtype, first)

    @staticmethod
    def batch_bytes(ds, batch_size: int) -> int:
        """Bytes of one batch's tensors: ``batch_size`` times those of the dataset's sample 0 (every output, as the
        per-sample path makes it; the batched program's temporaries are not counted)."""
        return int(batch_size) * sum(t.numel() * t.element_size() for _p, t in tensor_leaves(ds[0]))

    def set_epoch(self, epoch: int) -> None:
        self.ds.set_epoch(epoch)
        self.epoch = int(epoch)

    def __len__(self) -> int:
        n = len(self.ds) if self.own is None else len(self.own)
        sizes = [n] if self.chunk_scenes is None else [
            len(c) * self.ds.samples_per_scene for c in self._chunks()]
        return sum(n // self.batch_size if self.drop_last else -(-n // self.batch_size) for n in sizes)

    def _chunks(self) -> list[list[int]]:
        """The scene positions of each chunk of the current epoch (scenes in the order ``epoch_order`` of the
        number of scenes, ``chunk_scenes`` at a time)."""
        order = epoch_order(len(self._sids), self.seed, self.epoch).tolist()
        c = self.chunk_scenes
        return [order[i:i + c] for i in range(0, len(order), c)]

    def pieces(self, indices) -> dict:
        """The collated pieces of the dataset's samples ``indices`` (counter draws of the current epoch) on the
        device: by the batched program (:class:`SplitProgram`) when the split is packed, else sample by sample
        (:func:`capture_pieces` from the resident layers)."""
        if self.resident.program is not None:
            return self.resident.program.pieces(indices)
        pieces = [capture_pieces(self.ds, sid, pl, pg, crop, ns, int(i), start, resident=self.resident)
                  for i in indices for sid, pl, pg, crop, ns, start in (self.ds.draws(int(i), streams="counter"),)]
        return pieces_to(collate_pieces(pieces), self.device)

    def batch(self, indices) -> dict:
        """The simulated batch of the dataset's samples ``indices`` (drawn for the current epoch)."""
        return simulate_batch(self.pieces(indices), self.ds.preset, noise_streams="counter")

    def __iter__(self) -> Iterator[dict]:
        if not (self.prefetch and self.device.type == "cuda"):
            yield from self._batches()
            return
        # one batch ahead on a side stream: the main stream waits only for the batch it takes, and each of the
        # batch's tensors is marked as used there (its memory is not reused before that work is done)
        side, main = torch.cuda.Stream(self.device), torch.cuda.current_stream(self.device)
        side.wait_stream(main)          # the layers, loaded on the main stream (a new chunk loads on the side one)
        it = self._batches()

        def ahead():
            with torch.cuda.stream(side):
                b = next(it, None)
                return None if b is None else (b, side.record_event())

        nxt = ahead()
        while nxt is not None:
            cur, ready = nxt
            nxt = ahead()
            main.wait_event(ready)
            for _path, t in tensor_leaves(cur):
                t.record_stream(main)
            yield cur

    def _batches(self) -> Iterator[dict]:
        B = self.batch_size
        if self.chunk_scenes is None:
            order = epoch_order(len(self.ds) if self.own is None else len(self.own), self.seed, self.epoch).tolist()
            if self.own is not None:
                order = [self.own[j] for j in order]
            for b in range(len(self)):
                yield self.batch(order[b * B:(b + 1) * B])
            return
        # streamed: one chunk of scenes resident at a time, its samples in an order of (seed, epoch, chunk)
        sps = self.ds.samples_per_scene
        for c, chunk in enumerate(self._chunks()):
            sids = [self._sids[p] for p in chunk]
            if set(self.resident.scene_ids) != set(sids):
                self.resident = None            # free the previous chunk before loading the next
                if self.device.type == "cuda":  # and hand its memory back from PyTorch's cache
                    torch.cuda.synchronize(self.device)
                    torch.cuda.empty_cache()
                self.resident = ResidentScenes(self.ds, self.device, self.layer_budget, self.dtype, sids)
            idx = [p * sps + s for p in chunk for s in range(sps)]
            perm = epoch_order(len(idx), self.seed + 7919 * (c + 1), self.epoch).tolist()
            n = len(idx) // B if self.drop_last else -(-len(idx) // B)
            for b in range(n):
                yield self.batch([idx[j] for j in perm[b * B:(b + 1) * B]])


#: On CUDA, the crops and their lamp entries by Triton kernels (:mod:`lfmbench.datasets._device_triton`) where
#: Triton is importable (``_ENTRY_KERNELS.enabled = False``: the torch form everywhere; the same numbers).
_ENTRY_KERNELS = TritonKernels("lfmbench.datasets._device_triton", "the device program", "the torch form")


#: PWM (PWM_FIELDS) of a padded slot (no light, or a light the crop does not show): any valid waveform; its
#: entries are zero.
_PAD_PWM = (0.01, 0.5, 0.0, 0.0, 0.0)


class SplitProgram:
    """A split's layers packed on one device, and the batched program that cuts, draws and composes a whole batch
    from them with no Python per sample: the pieces of :func:`lfmbench.datasets.batched.collate_pieces` for
    ``indices`` (the per-sample path's numbers, :func:`capture_pieces` with counter draws), made by a fixed number
    of tensor operations.

    Made by :class:`ResidentScenes` when the split allows it (:meth:`supports`): every scene of one size and one
    number of loaded frames, and no flickering group stored without time bins (imported data; those take the
    per-sample pieces path). Every light kind of scene version 2 is packed: drivers as the entity a light draws
    from, scan rows and gates as the tables below (the rules of :func:`lfmbench.datasets.pwm.apply_light_timing`
    and :mod:`lfmbench.flicker.waveforms`, called on the batch's tensors).

    Tables (on ``device``; nS scenes, Fs frames, H x W px, Lf lights per frame at most, L = ``max_lights``,
    N pixel entries of all lights of all frames, Kall bins):
        ``static`` (nS, Fs, 2, H, W) float32 e-/s; ``light_index`` (nS, Fs, 1, H, W); ``depth`` (nS, Fs, H, W) m;
        ``e_y``, ``e_x`` (N,) int32 px, ``e_pos`` (N,) int32 position of the entry's light in its frame's list,
        ``e_vals`` (N, 2, Kall) float32 e-/s (entry-major); ``off`` (nS, Fs + 1) first entry of each (scene, frame) (host);
        ``lt_lpos`` (nS, Fs, Lf) the light's position in the scene's ``meta`` light arrays (-1: padding),
        ``lt_K`` (nS, Fs, Lf) bins, ``lt_box`` (nS, Fs, Lf, 4) (y0, x0, y1, x1) px half-open;
        ``ids`` (nS, L) light ids (-1: padding), ``ent`` (nS, L) the light's PWM entity
        (:class:`lfmbench.datasets.counter_draws.SceneEntities`; the entity of its driver's first light,
        :func:`lfmbench.datasets.pwm.driver_sources`; -1: not flickering); ``scan`` (nS, L, 2) float64 (scan
        lines N, line) of a message-sign row (``is_scan`` (nS, L)); ``gates`` (nG, 4 + 2 M) float64 the gated
        waveforms' rows (:func:`lfmbench.datasets.pieces.gate_rows`), ``lt_gate`` (nS, Fs, Lf) a slot's row there
        (-1: not gated; host);
        ``timing`` (nS, 4) float64 (short, long exposure, line time, capture window; s), ``fps`` (nS,) Hz.
    """

    #: Tile size (px) of the entry order.
    TILE = 16

    @staticmethod
    def supports(ds, scenes: list | None = None) -> bool:
        """Whether the scenes of ``ds`` (or ``scenes`` of them) can be packed (one size, one number of frames, no
        groups without bins)."""
        shapes = set()
        for sid in dict.fromkeys(ds.scene_ids if scenes is None else scenes):
            view = ds.scene(sid)
            if view.layers.group_static:
                return False
            shapes.add(tuple(view.static_rates().shape))
        return len(shapes) == 1

    def __init__(self, ds, device: torch.device, dtype: torch.dtype = torch.float32, scenes: list | None = None) -> None:
        self.ds = ds
        self.device = dev = torch.device(device)
        self.dtype = dtype
        self.sids = list(dict.fromkeys(ds.scene_ids if scenes is None else scenes))
        pos = {sid: i for i, sid in enumerate(self.sids)}
        # ds.scene_ids -> packed scene (-1: not held, a chunk of the split)
        self.scene_of = np.array([pos.get(s, -1) for s in ds.scene_ids], dtype=np.int64)
        want = set(ds.outputs)
        views = [ds.scene(s) for s in self.sids]
        nS = len(views)
        Fs, _two, H, W = (int(n) for n in views[0].static_rates().shape)
        self.H, self.W, self.Fs = H, W, Fs
        self.static = torch.empty((nS, Fs, 2, H, W), dtype=dtype, device=dev)
        # float16: each scene's rates divided by a power of two (exact) so that its largest is at most 2^14
        self.scale = np.ones(nS, dtype=np.float32)
        li_dt = max((v.light_index().dtype for v in views), key=lambda d: torch.iinfo(d).bits) \
            if "light_index" in want else None
        self.light_index = torch.empty((nS, Fs, 1, H, W), dtype=li_dt, device=dev) if li_dt else None
        self.depth = torch.empty((nS, Fs, H, W), dtype=torch.float32, device=dev) if "depth" in want else None
        ents = [v.cached("pieces_entries", _SceneEntries) for v in views]
        self.kall = max([int(fe.vals.shape[1]) for e in ents for fe in e.frames] + [1])
        lf = max([len(fe.lights) for e in ents for fe in e.frames] + [1])
        L = ds.max_lights
        self.lt_lpos = np.full((nS, Fs, lf), -1, dtype=np.int64)
        self.lt_K = np.ones((nS, Fs, lf), dtype=np.int64)
        self.lt_box = np.zeros((nS, Fs, lf, 4), dtype=np.int64)
        self.ids = np.full((nS, L), -1, dtype=np.int64)
        self.ent = np.full((nS, L), -1, dtype=np.int64)
        self.scan = np.tile(np.array([1.0, 0.0]), (nS, L, 1))         # (N, line): 1/1 scan, the carrier itself
        self.is_scan = np.zeros((nS, L), dtype=bool)
        l_gate = np.full((nS, L), -1, dtype=np.int64)
        tables: list = []
        self.num_lights = np.zeros(nS, dtype=np.int64)
        self.timing = np.zeros((nS, 4), dtype=np.float64)
        self.fps = np.zeros(nS, dtype=np.float64)
        self.n_frames = np.zeros(nS, dtype=np.int64)
        counts = np.zeros((nS, Fs), dtype=np.int64)
        self.n_entities = 1
        for i, (sid, view, e) in enumerate(zip(self.sids, views, ents)):
            if dtype != torch.float32:
                top = max([float(view.static_rates().max())] + [float(fe.vals.max()) for fe in e.frames if fe.vals.size])
                self.scale[i] = 2.0 ** max(0, math.ceil(math.log2(max(top, 1.0) / 2.0 ** 14)))
            self.static[i].copy_(view.static_rates() / float(self.scale[i]))
            if self.light_index is not None:
                self.light_index[i].copy_(view.light_index())
            if self.depth is not None:
                self.depth[i].copy_(view.layers.aux["depth.Z"])
            lights = view.lights
            lpos = {int(lt["id"]): j for j, lt in enumerate(lights)}
            self.ids[i, :len(lights)] = [int(lt["id"]) for lt in lights]
            self.num_lights[i] = len(lights)
            se = ds.entities(sid)
            self.n_entities = max(self.n_entities, se.n_entities)
            meta = view.meta
            timed = has_light_timing(meta)
            src = driver_sources(meta, se.light_ids) if timed else {}
            ent_of = dict(zip(se.light_ids, se.entity))
            for lid in se.light_ids:
                if lid in lpos:
                    self.ent[i, lpos[lid]] = ent_of[src.get(lid, lid)]
            for lid, wf in (light_waveforms(meta) if timed else {}).items():
                if lid not in lpos:
                    continue
                if isinstance(wf, GatedWaveform):   # indicator, strobe, countdown, destination-display row
                    l_gate[i, lpos[lid]] = len(tables)
                    tables.append(wf.table())
                elif isinstance(wf, ScanRow):       # a message-sign row
                    self.scan[i, lpos[lid]] = (wf.scan_lines, wf.line)
                    self.is_scan[i, lpos[lid]] = True
            tm = meta["timing"]
            td = float(tm.get("line_time_s", 0.0)) if ds.line_time_s is None else float(ds.line_time_s)
            self.timing[i] = (float(tm["short_exposure_s"]), float(tm["long_exposure_s"]), td,
                              float(tm["capture_window_s"]))
            self.fps[i] = float(meta["fps"])
            self.n_frames[i] = int(meta["frames"])
            for fr, fe in enumerate(e.frames):
                counts[i, fr] = fe.y.shape[0]
                for k, (lid, K, box) in enumerate(fe.lights):
                    self.lt_lpos[i, fr, k] = lpos.get(lid, -1)
                    self.lt_K[i, fr, k] = K
                    self.lt_box[i, fr, k] = box
        #: per slot of each scene's frame, its gate's row in ``gates`` (-1: not gated)
        self.lt_gate = np.where(self.lt_lpos >= 0, np.take_along_axis(
            l_gate, self.lt_lpos.clip(0).reshape(nS, -1), 1).reshape(self.lt_lpos.shape), -1)
        self.gates = gate_rows(tables).numpy()
        self.off = np.zeros((nS, Fs + 1), dtype=np.int64)
        self.off[:, 1:] = np.cumsum(counts, 1)
        self.off += np.concatenate([[0], np.cumsum(counts.sum(1))[:-1]])[:, None]
        n_all = int(counts.sum())
        # entries sorted by 16 x 16 px tile in each (scene, frame): a crop's entries are then one run per tile row
        T = self.TILE
        self.nty, self.ntx = -(-H // T), -(-W // T)
        nt = self.nty * self.ntx
        self.tile_off = np.zeros((nS, Fs, nt + 1), dtype=np.int64)
        self.order: list[list[np.ndarray]] = []        # per scene and frame: _SceneEntries position -> run position
        # entry-major (N, 2, Kall): a batch gathers whole rows of 2 x Kall rates (coalesced on a GPU)
        self.e_vals = torch.zeros((n_all, 2, self.kall), dtype=dtype, device=dev)
        ey, ex, ep = (np.empty(n_all, dtype=np.int32) for _ in range(3))
        for i, e in enumerate(ents):
            self.order.append([])
            for fr, fe in enumerate(e.frames):
                a, b = int(self.off[i, fr]), int(self.off[i, fr + 1])
                tile = (fe.y // T).astype(np.int64) * self.ntx + fe.x // T
                srt = np.argsort(tile, kind="stable")
                inv = np.empty_like(srt)
                inv[srt] = np.arange(srt.shape[0])
                self.order[i].append(inv)
                self.tile_off[i, fr] = a + np.concatenate([[0], np.cumsum(np.bincount(tile, minlength=nt))])
                ey[a:b], ex[a:b], ep[a:b] = fe.y[srt], fe.x[srt], fe.pos[srt]
                self.e_vals[a:b, :, :fe.vals.shape[1]].copy_(
                    torch.from_numpy(fe.vals[:, :, srt]).permute(2, 0, 1) / float(self.scale[i]))
        t = lambda a: torch.from_numpy(a).to(dev)  # noqa: E731
        self.e_y, self.e_x, self.e_pos = t(ey), t(ex), t(ep)
        self.t_lpos, self.t_K, self.t_box = t(self.lt_lpos), t(self.lt_K), t(self.lt_box)
        self.t_ids, self.t_ent, self.t_nl = t(self.ids), t(self.ent), t(self.num_lights)
        self.t_timing, self.t_fps, self.t_scale = t(self.timing), t(self.fps), t(self.scale)
        self.t_scan, self.t_is_scan = t(self.scan), t(self.is_scan)
        self.any_scan = bool(self.is_scan.any())
        self.frozen = self._freeze() if ds.split == "test" else None
        # constants made once: a tensor made from host values inside a step would wait for the device's queue
        self._pad = torch.tensor(_PAD_PWM, dtype=torch.float64, device=dev)
        ch, cw = ds.crop if ds.crop is not None else (H, W)
        self._hw = torch.tensor([H, W, ch, cw], dtype=torch.int64, device=dev)
        #: no light of the split has ramps (the PWM config draws rise and fall times of constant 0)
        self.ideal_pulses = all(d.dist == "constant" and d.low == 0.0 for d in (ds.pwm.rise_time_s, ds.pwm.fall_time_s))
        if self.frozen is not None:
            self.ideal_pulses = self.ideal_pulses and not bool(self.frozen["ramps"])

    def nbytes(self) -> int:
        ts = [self.static, self.light_index, self.depth, self.e_vals, self.e_y, self.e_x, self.e_pos]
        return sum(int(t.numel()) * t.element_size() for t in ts if t is not None)

    def entries(self, scene: int, frame: int) -> torch.Tensor:
        """(2, Kall, n) view of the rates of the entries of one scene's frame (what :class:`ResidentScene` holds),
        in tile order (``order[scene][frame]`` maps a :class:`~lfmbench.datasets.pieces._SceneEntries` position
        to its position here)."""
        return self.e_vals[int(self.off[scene, frame]):int(self.off[scene, frame + 1])].permute(1, 2, 0)

    def _freeze(self) -> dict:
        """The frozen draws of every sample of a test split as tables (read once through ``ds.draws``)."""
        ds, n, L = self.ds, len(self.ds), self.ids.shape[1]
        pwm = np.tile(np.asarray(_PAD_PWM + (100.0,)), (n, L, 1))            # PWM_FIELDS + freq_hz
        valid = np.zeros((n, L), dtype=bool)
        place = np.zeros((n, 3), dtype=np.int64)           # y0, x0, first frame
        seeds = np.zeros(n, dtype=np.int64)
        for i in range(n):
            k = self.scene_of[i // ds.samples_per_scene]
            if k < 0:          # a scene another chunk holds
                continue
            sid, per_light, _pg, crop, ns, start = ds.draws(i)
            for j, lid in enumerate(self.ids[k, :self.num_lights[k]]):
                p = per_light.get(int(lid))
                if p is not None:
                    valid[i, j] = True
                    pwm[i, j] = [float(p[f]) for f in PWM_FIELDS + ("freq_hz",)]
            place[i] = (crop[0], crop[1], start)
            seeds[i] = ns
        t = lambda a: torch.from_numpy(a).to(self.device)  # noqa: E731
        return {"pwm": t(pwm), "valid": t(valid), "place": t(place), "place_host": place, "seeds": t(seeds),
                "ramps": bool((pwm[..., 3:5][valid] > 0).any())}

    def pieces(self, indices) -> dict:
        """The collated pieces of samples ``indices`` (their draws for the dataset's current epoch) on the device.

        Args:
            indices: B sample indices of the dataset (ints).

        Returns:
            :func:`~lfmbench.datasets.batched.collate_pieces`'s fields (slots B x F x Lf, padded slots with zero
            entries; ``meta`` tensors on the device), ``info`` with ``noise_streams="counter"``.
        """
        ds, dev = self.ds, self.device
        F = ds.frames
        idx = np.asarray([int(i) for i in indices], dtype=np.int64)
        B = int(idx.shape[0])
        if B == 0 or idx.min() < 0 or idx.max() >= len(ds):
            raise IndexError(f"indices: {B} sample indices, each must be in [0, {len(ds)})")
        sc = self.scene_of[idx // ds.samples_per_scene]
        if (sc < 0).any():
            raise IndexError(f"indices: sample {int(idx[sc < 0][0])} is of a scene this chunk does not hold")
        fz = self.frozen
        H, W = self.H, self.W
        h, w = ds.crop if ds.crop is not None else (H, W)
        # where the crops and windows are (host: they fix how many entries the batch has; counter draws on the
        # CPU are the same numbers as on any device)
        if fz is not None:
            y0h, x0h, start = (fz["place_host"][idx, k] for k in range(3))
        else:
            place = place_uniforms(ds.seed, ds.epoch, torch.from_numpy(idx))                   # (B, 3)
            if ds.crop is None or ds.split == "test":
                y0h = np.full(B, ((H - h) // 2) & ~1, dtype=np.int64)
                x0h = np.full(B, ((W - w) // 2) & ~1, dtype=np.int64)
            else:
                y0h = crop_origin(place[:, 0], H, h).numpy()
                x0h = crop_origin(place[:, 1], W, w).numpy()
            if ds.frame_start == "random":
                start = start_frame(place[:, 2], torch.from_numpy(self.n_frames[sc] - F + 1)).numpy()
            else:
                start = np.full(B, ds.frame_start, dtype=np.int64)
        fr = start[:, None] + np.arange(F)                                          # (B, F)
        # the crop's entries: per (sample, frame) one run of tiles per tile row the crop touches
        T = self.TILE
        NR = -(-h // T) + 1
        rows = y0h[:, None] // T + np.arange(NR)                                    # (B, NR) tile rows
        live = (rows <= ((y0h + h - 1) // T)[:, None]) & (rows < self.nty)
        rows = np.minimum(rows, self.nty - 1)
        tx0, tx1 = x0h // T, (x0h + w - 1) // T
        S3, F3, R3 = sc[:, None, None], fr[:, :, None], rows[:, None, :]
        first = self.tile_off[S3, F3, R3 * self.ntx + tx0[:, None, None]]            # (B, F, NR)
        cnt = (self.tile_off[S3, F3, R3 * self.ntx + tx1[:, None, None] + 1] - first) * live[:, None, :]
        E = int(cnt.sum())
        # the draws on the host too (B x M x 5 uniforms: a few dozen small CPU operations instead of ~100
        # kernel launches; the same functions, on the CPU as the per-sample path runs them)
        rec_h = None        # a frozen test split's draws are tables on the device already
        seeds_h = np.zeros(B, dtype=np.int64)
        if fz is None:
            M = self.n_entities
            idx_c = torch.from_numpy(idx)
            u = uniforms(sample_keys(ds.seed, ds.epoch, idx_c, PURPOSE_PWM), PWM_UNIFORMS * M)
            rec = pwm_from_uniforms(ds.pwm, u.view(B, M, PWM_UNIFORMS))                      # (B, M) each
            rec_h = torch.stack([rec[k] for k in PWM_FIELDS + ("freq_hz",)], -1)             # (B, M, 6)
            seeds_h = noise_seeds(ds.seed, ds.epoch, idx_c).numpy()
        host = torch.from_numpy(np.concatenate([idx, sc, y0h, x0h, seeds_h, fr.reshape(-1), first.reshape(-1),
                                                cnt.reshape(-1)]))

        def to_device(t: torch.Tensor) -> torch.Tensor:
            # pinned on CUDA: an asynchronous copy, the host goes on to queue the rest
            return (t.pin_memory() if dev.type == "cuda" else t).to(dev, non_blocking=True)

        host = to_device(host)
        idx_t, sc_t, y0, x0, seeds = (host[k * B:(k + 1) * B] for k in range(5))
        fr_t = host[5 * B:5 * B + B * F].view(B, F)
        first_t, cnt_t = (host[5 * B + B * F + k * B * F * NR:5 * B + B * F + (k + 1) * B * F * NR] for k in range(2))
        # draws
        if fz is not None:
            pwm, valid = fz["pwm"][idx_t], fz["valid"][idx_t]                    # (B, L, 6), (B, L)
            seeds = fz["seeds"][idx_t]
        else:
            ent = self.t_ent[sc_t]                                                           # (B, L)
            valid = ent >= 0
            pwm = to_device(rec_h).gather(1, ent.clamp_min(0)[..., None].expand(-1, -1, 6))  # (B, L, 6)
            if self.any_scan:       # message-sign rows: the row's own PWM (apply_light_timing's rule)
                sn = self.t_scan[sc_t]                                                       # (B, L, 2)
                row = scan_row_record(*pwm[..., :5].unbind(-1), sn[..., 0], sn[..., 1])
                pwm = torch.where(self.t_is_scan[sc_t][..., None], torch.stack([*row, pwm[..., 5]], -1), pwm)
        pad = self._pad
        # slots: every light of every frame of a sample, shown or not (B, F, Lf)
        at = (sc_t[:, None], fr_t)
        lpos, K, box = self.t_lpos[at], self.t_K[at], self.t_box[at]
        lp = lpos.clamp_min(0).view(B, -1)
        shown = (lpos >= 0) & valid.gather(1, lp).view(lpos.shape)
        Y0, X0 = y0[:, None, None], x0[:, None, None]
        shown &= (torch.maximum(box[..., 0], Y0) < torch.minimum(box[..., 2], Y0 + h)) & \
                 (torch.maximum(box[..., 1], X0) < torch.minimum(box[..., 3], X0 + w))
        slot_pwm = torch.where(shown[..., None],
                               pwm[..., :5].gather(1, lp[..., None].expand(-1, -1, 5)).view(*lpos.shape, 5), pad)
        lf = lpos.shape[2]
        out: dict = {
            "slot_pwm": slot_pwm.view(-1, 5),
            "slot_K": torch.where(shown, K, torch.ones_like(K)).view(-1),
            "slot_frame": torch.arange(F, device=dev).view(1, F, 1).expand(B, F, lf).reshape(-1),
            "slot_sample": torch.arange(B, device=dev).view(B, 1, 1).expand(B, F, lf).reshape(-1),
        }
        # gated lights' slots (known on the host from the scene and frame tables) and their gates
        g_of = self.lt_gate[sc[:, None], fr].reshape(-1)                               # (B * F * Lf,)
        g_slot = np.flatnonzero(g_of >= 0)
        gate_height = None
        if g_slot.shape[0]:
            out["gate_slot"] = to_device(torch.from_numpy(g_slot))
            out["gate_table"] = to_device(torch.from_numpy(self.gates[g_of[g_slot]]))
            # the crop rows each gated lamp's box covers (host numbers: a rolling shutter's gates are evaluated
            # there only, batch_compose.pwm_weights)
            gb = self.lt_box[sc[:, None], fr].reshape(-1, 4)[g_slot]                   # (G, 4) px
            gy0 = np.repeat(y0h, F * self.lt_box.shape[2])[g_slot]
            span = np.stack([np.clip(gb[:, 0] - gy0, 0, h), np.clip(gb[:, 2] - gy0, 0, h)], 1).astype(np.int64)
            out["gate_span"] = to_device(torch.from_numpy(span))
            gate_height = int((span[:, 1] - span[:, 0]).max())
        # entries: the runs of the global table, masked to the crop and the shown lights
        run = torch.repeat_interleave(torch.arange(B * F * NR, device=dev), cnt_t, output_size=E)
        before = torch.cumsum(cnt_t, 0) - cnt_t
        fused = None
        if self.dtype == torch.float32 and _ENTRY_KERNELS.ready(self.e_vals):
            # one kernel for all of the below (the same numbers, bit for bit; None: it failed, the torch form)
            fused = _ENTRY_KERNELS.call("crop_entries", run, first_t, before, self.e_y, self.e_x, self.e_pos,
                                        shown.view(-1), y0, x0, self.e_vals, NR, F, lf, h, w)
        if fused is not None:
            out["entry_pix"], out["entry_slot"], ev = fused
        else:
            gid = first_t[run] + torch.arange(E, device=dev) - before[run]
            ey, ex = self.e_y[gid].long(), self.e_x[gid].long()
            pair = run // NR
            b, f = pair // F, pair % F
            slot = pair * lf + self.e_pos[gid].long()
            ok = shown.view(-1)[slot]
            ok &= (ey >= y0[b]) & (ey < y0[b] + h) & (ex >= x0[b]) & (ex < x0[b] + w)
            pix = f * (h * w) + (ey - y0[b]) * w + (ex - x0[b])
            out["entry_pix"] = torch.where(ok, pix, torch.zeros_like(pix)).int()
            out["entry_slot"] = slot.int()
            ev = gather_rows(self.e_vals, gid).float() * ok.to(torch.float32)[:, None, None]
            if self.dtype != torch.float32:
                ev = ev * self.t_scale[sc_t][b][:, None, None]
        # (2, Kall, E) as a view of entry-major rows (compose_batch reads it without a copy)
        out["entry_values"] = ev.permute(1, 2, 0)
        # crops of the full-frame layers: on a GPU one row-copy kernel each (Triton; else one indexed gather each);
        # slices on the CPU, where copying B x F rectangles is faster than an indexed gather (the same numbers)
        layers = [("static", self.static), ("light_index", self.light_index), ("depth", self.depth)]
        crops = None
        if dev.type == "cpu":
            for key, full in layers:
                if full is not None:
                    out[key] = torch.stack([torch.stack([full[s_, f_, ..., a:a + h, c:c + w] for f_ in fs])
                                            for s_, fs, a, c in zip(sc.tolist(), fr.tolist(), y0h.tolist(),
                                                                    x0h.tolist())])
        elif _ENTRY_KERNELS.ready(self.static):
            crops = {}
            for key, full in layers:
                if full is not None and crops is not None:
                    crops[key] = _ENTRY_KERNELS.call("crop_planes", full if full.dim() == 5 else full[:, :, None],
                                                     sc_t, fr_t, y0, x0, h, w)
                    if crops[key] is None:      # failed to compile here: the torch form below
                        crops = None
            if crops is not None:
                out.update(crops)
        if dev.type != "cpu" and crops is None:
            rr = (y0[:, None] + torch.arange(h, device=dev))[:, None, :, None]                # (B, 1, h, 1)
            cc = (x0[:, None] + torch.arange(w, device=dev))[:, None, None, :]                # (B, 1, 1, w)
            S4, F4 = sc_t[:, None, None, None], fr_t[:, :, None, None]
            out["static"] = self.static.permute(0, 1, 3, 4, 2)[S4, F4, rr, cc].permute(0, 1, 4, 2, 3).contiguous()
            if self.light_index is not None:
                out["light_index"] = self.light_index[:, :, 0][S4, F4, rr, cc][:, :, None]
            if self.depth is not None:
                out["depth"] = self.depth[S4, F4, rr, cc][:, :, None]
        if dev.type == "cpu" and self.depth is not None:
            out["depth"] = out["depth"][:, :, None]
        if self.dtype != torch.float32:
            out["static"] = out["static"].float() * self.t_scale[sc_t][:, None, None, None, None]
        fps = self.t_fps[sc_t]
        out["t0"] = fr_t.to(torch.float64) / fps[:, None]
        tim = self.t_timing[sc_t]
        out["timing"] = tim
        hw = self._hw[None, 2:].expand(B, 2)
        out["crop"] = torch.cat([y0[:, None], x0[:, None], hw], 1)
        out["scene_hw"] = self._hw[None, :2].expand(B, 2).contiguous()
        out["noise_seed"] = seeds
        # meta, as default_collate makes it of the per-sample metas (tensors on the device)
        ids = self.t_ids[sc_t]
        inside = ids >= 0
        flick = valid & inside
        meta = {"scene_id": [self.sids[k] for k in sc.tolist()], "index": idx_t,
                "epoch": torch.full((B,), int(ds.epoch), dtype=torch.int64, device=dev),
                "num_lights": self.t_nl[sc_t], "light_id": ids, "flicker": flick}
        for name, col, default in (("freq_hz", 5, 0.0), ("duty", 1, 1.0), ("phase_s", 2, 0.0)):
            meta[name] = torch.where(flick, pwm[..., col], torch.where(inside, default, 0.0))
        meta.update({"exposure_short_s": tim[:, 0], "exposure_long_s": tim[:, 1], "crop": out["crop"],
                     "sensor": [ds.sensor_name] * B, "shutter": [ds.shutter] * B,
                     "flicker_mode": ["bins"] * B, "frame_start": fr_t[:, 0]})
        out["meta"] = meta
        out["info"] = {"sensor": ds.sensor_name, "frames": F, "crop_hw": (h, w), "shutter": ds.shutter,
                       "noise": ds.noise, "outputs": tuple(ds.outputs), "noise_streams": "counter",
                       "group_slots": False, "scene_hw": (H, W), "ideal_pulses": self.ideal_pulses, "trusted": True,
                       "gate_height": gate_height}
        return out
