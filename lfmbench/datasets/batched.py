r"""Captures simulated in batches on the training device (the GPU path of :class:`LFMCaptureDataset`).

The per-sample path (``LFMCaptureDataset.__getitem__``) composes and simulates every sample inside a DataLoader
worker on the CPU. Here the work is split in two:

1. **Pieces** (workers, CPU): ``LFMCaptureDataset(..., pieces=True)`` returns, per sample, only what is fixed per
   scene and crop plus the sample's draws (:func:`~lfmbench.datasets.pieces.capture_pieces`): the crop of the projected static rates, the
   per-light time-bin rates of the lights the crop shows (as a sparse list of pixel entries), the PWM draws, the
   frame times, the noise seed, ``light_index`` and ``depth``, and the same ``meta`` as the per-sample path.
   :func:`collate_pieces` batches them (and refuses batches that mix sensors, frame counts, crops, shutters or
   output sets); :func:`pieces_to` moves a batch to a device.
2. **Simulation** (any device, whole batch): :func:`simulate_batch` (or the :class:`BatchedCaptureSimulator`
   module) computes the exact PWM weights of every light, bin, window and row, composes the mean electrons of
   both photodiodes and the ground truth, and runs the split-pixel sensor chain
   (:func:`lfmbench.sensor.simulate_split_pixel_electrons`) on the batch's device.

Every rule is the per-sample path's own function (:mod:`lfmbench.datasets.assembly`): bin edges
(:func:`~lfmbench.datasets.assembly.bin_edges`), window timing (:func:`~lfmbench.datasets.assembly.window_starts`),
bin weights (:func:`~lfmbench.datasets.assembly.window_bin_exposure`, through
:func:`lfmbench.flicker.pwm_exposure`), the visible lights of a crop
(:func:`~lfmbench.datasets.assembly.visible_lights`), the sample dict
(:func:`~lfmbench.datasets.assembly.assemble_sample`), the sensor chain and its noise
(one ``torch.Generator`` per sample, seeded by the sample's own noise seed), the fixed pattern
(:func:`lfmbench.sensor.fixed_pattern`), ``light_index``, ``meta`` and the demosaic. The draws are made by
``LFMCaptureDataset.draws`` (functions of ``(seed, epoch, index)``). On the CPU the composition and the sensor
chain run as compiled passes of the same formulas (:mod:`lfmbench.datasets._compose_kernel`, the ``"numba"``
backend of :func:`lfmbench.sensor.simulate_split_pixel_electrons`), the samples of a batch in parallel threads;
:func:`prefetch` overlaps building the next batch's pieces with that.

Composition (the formula of :mod:`lfmbench.datasets.assembly`), per sample b, frame f and photodiode pd:

.. math:: \bar e_{pd} = R^{static}_{pd}\,t_{pd} + \sum_{e \in \text{entries}} \delta_{p(e)}
          \sum_k V_{e,k,pd}\; W^{pd}_{s(e),\,y(e),\,k}

with entry e a pixel p(e) (row y(e)) of one light slot s(e) (a light in one frame), V its rates (e-/s) in the
slot's K bins and W the slot's PWM exposure (s) of bin k in that row's window. Flickering groups stored
without bins (imported data) are slots with one full-crop "bin" whose weight is the PWM exposure of the whole
window (the per-sample rule, ``K = 0`` in ``slot_K``).

The composition of stage 2 (:func:`~lfmbench.datasets.batch_compose.pwm_weights`,
:func:`~lfmbench.datasets.batch_compose.compose_batch` and their kernels) is :mod:`lfmbench.datasets.batch_compose`.
"""
from __future__ import annotations

import contextlib
import queue
import threading
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np
import torch
from torch import nn
from torch.utils.data import default_collate

from lfmbench import sensor as _sensor
from lfmbench.check import check_batch_keys, check_same_device, trusted_values
from lfmbench.datasets.assembly import NOISE_STREAMS, SENSOR_OUTPUTS, assemble_sample
from lfmbench.datasets.batch_compose import _DEVICE_HINT, _PIECE_HINT, _PIECE_KEYS, compose_batch
from lfmbench.datasets.pieces import PWM_FIELDS, capture_pieces
from lfmbench.sensor.fused import PatternCrops, map_samples

__all__ = ["capture_pieces", "collate_pieces", "pieces_to", "prefetch", "simulate_batch", "BatchedCaptureSimulator",
           "piece_bytes", "tensor_leaves", "batch_item", "PWM_FIELDS"]

#: Consistency fields of ``info``: a batch must agree on all of them.
_INFO_FIELDS = ("sensor", "frames", "crop_hw", "shutter", "noise", "outputs")


# ----------------------------------------------------------------------------------------------------------
# pieces (DataLoader workers, CPU)
# ----------------------------------------------------------------------------------------------------------
def piece_bytes(pieces: Mapping[str, Any]) -> int:
    """Bytes of the tensors of one sample's (or one batch's) pieces, ``meta`` and ``info`` excluded: what
    :func:`pieces_to` copies host to device."""
    return int(sum(v.numel() * v.element_size() for k, v in pieces.items() if torch.is_tensor(v)))


def collate_pieces(samples: Sequence[Mapping[str, Any]]) -> dict:
    """Batch the pieces of B samples (a ``collate_fn`` for ``DataLoader``).

    Returns:
        the fields of :func:`capture_pieces` with a leading B for the per-sample ones (``static`` (B, F, 2, h, w),
        ``t0`` (B, F), ``timing`` (B, 4), ``crop`` (B, 4), ``scene_hw`` (B, 2), ``noise_seed`` (B,),
        ``light_index``/``depth`` (B, F, 1, h, w)), the slots and entries of all samples concatenated
        (``entry_slot`` and ``gate_slot`` into the batch's slots, ``slot_sample`` (S,) int64 their sample,
        ``entry_values`` padded to the batch's Kmax, ``gate_table`` to its most ON intervals with empty ones),
        ``meta`` collated as the per-sample path's DataLoader does, and ``info``.

    Raises:
        ValueError: ``samples`` empty, not pieces (``pieces=True`` missing), or mixing sensors, frame counts,
            crop sizes, shutters, noise settings or output sets (the message names the field and the values).
    """
    if not samples:
        raise ValueError("samples: an empty batch")
    for i, s in enumerate(samples):
        if not isinstance(s, Mapping) or "info" not in s or "entry_values" not in s:
            raise ValueError(f"samples[{i}] is not a pieces dict (build the dataset with pieces=True)")
    info0 = samples[0]["info"]
    for f in _INFO_FIELDS:
        vals = sorted({repr(s["info"][f]) for s in samples})
        if len(vals) > 1:
            raise ValueError(f"samples: a batch must share one {f}; this one mixes {', '.join(vals)}")
    out: dict[str, Any] = {}
    shared = torch.utils.data.get_worker_info() is not None

    def cat(ts: list[torch.Tensor], dim: int = 0, stack: bool = False) -> torch.Tensor:
        # in a DataLoader worker, straight into shared memory (as default_collate does): no second copy when the
        # batch is sent to the main process
        if not shared:
            return torch.stack(ts, dim) if stack else torch.cat(ts, dim)
        shape = list(ts[0].shape)
        if stack:
            shape.insert(dim, len(ts))
        else:
            shape[dim] = sum(int(t.shape[dim]) for t in ts)
        res = ts[0].new(ts[0]._typed_storage()._new_shared(int(np.prod(shape)), device=ts[0].device))
        res = res.resize_(shape)
        return torch.stack(ts, dim, out=res) if stack else torch.cat(ts, dim, out=res)

    for k in ("static", "t0", "timing", "crop", "scene_hw", "noise_seed", "light_index", "depth"):
        if k in samples[0]:
            out[k] = cat([s[k] for s in samples], stack=True)
    kmax = max(int(s["entry_values"].shape[1]) for s in samples)
    out["entry_values"] = cat([v if v.shape[1] == kmax else torch.nn.functional.pad(v, (0, 0, 0, kmax - v.shape[1]))
                               for v in (s["entry_values"] for s in samples)], 2)
    n_slots = [int(s["slot_K"].shape[0]) for s in samples]
    offs = np.concatenate([[0], np.cumsum(n_slots)[:-1]])
    out["entry_slot"] = cat([s["entry_slot"] + int(o) for s, o in zip(samples, offs)])
    out["entry_pix"] = cat([s["entry_pix"] for s in samples])
    for k in ("slot_pwm", "slot_frame", "slot_K"):
        out[k] = torch.cat([s[k] for s in samples])
    if any("gate_slot" in s for s in samples):     # gated lights: their slots and gates, padded to the most intervals
        gs = [(s["gate_slot"] + int(o), s["gate_table"]) for s, o in zip(samples, offs) if "gate_slot" in s]
        cols = max(int(t.shape[1]) for _, t in gs)
        out["gate_slot"] = torch.cat([g for g, _ in gs])
        out["gate_table"] = torch.cat([torch.nn.functional.pad(t, (0, cols - int(t.shape[1]))) for _, t in gs])
        if all("gate_span" in s for s in samples if "gate_slot" in s):   # the rows of each gated box
            out["gate_span"] = torch.cat([s["gate_span"] for s in samples if "gate_slot" in s])
    out["slot_sample"] = torch.repeat_interleave(torch.arange(len(samples)), torch.tensor(n_slots, dtype=torch.long))
    out["meta"] = default_collate([s["meta"] for s in samples])
    out["info"] = dict(info0)
    if out["slot_pwm"].device.type == "cpu":
        # decided here on the host, so that pwm_weights never has to ask a device (the same formulas either way)
        out["info"]["ideal_pulses"] = not bool(out["slot_pwm"][:, 3:5].any())
        out["info"]["group_slots"] = bool((out["slot_K"] == 0).any())
    if "gate_span" in out and out["gate_span"].device.type == "cpu":   # rows of the tallest gated box (host)
        sp = out["gate_span"]
        out["info"]["gate_height"] = int((sp[:, 1] - sp[:, 0]).max()) if sp.shape[0] else 0
    return out


def pieces_to(batch: Mapping[str, Any], device: torch.device | str, non_blocking: bool = False) -> dict:
    """``batch`` (from :func:`collate_pieces`) with its tensors on ``device`` (``meta`` stays where it is)."""
    return {k: (v.to(device, non_blocking=non_blocking) if torch.is_tensor(v) else v) for k, v in batch.items()}


def tensor_leaves(batch: Mapping[str, Any], prefix: tuple = ()) -> Iterator[tuple[tuple, torch.Tensor]]:
    """``(path, tensor)`` of every tensor of a batch dict, nested dicts (``meta``) included; ``path`` is the tuple
    of keys."""
    for k, v in batch.items():
        if isinstance(v, torch.Tensor):
            yield prefix + (k,), v
        elif isinstance(v, dict):
            yield from tensor_leaves(v, prefix + (k,))


def batch_item(batch: Mapping[str, Any], j: int) -> dict:
    """Sample ``j`` of a batch dict as a batch of one: every tensor (and list) with a leading B sliced to
    ``[j:j+1]`` (views), nested dicts (``meta``) alike, other values as they are."""
    def cut(v):
        if isinstance(v, torch.Tensor) or isinstance(v, list):
            return v[j:j + 1]
        if isinstance(v, Mapping):
            return {k: cut(x) for k, x in v.items()}
        return v
    return {k: cut(v) for k, v in batch.items()}


def prefetch(iterable: Iterable, depth: int = 1) -> Iterator:
    """The items of ``iterable`` in order, the next ``depth`` of them produced by a background thread.

    For a ``DataLoader`` with ``num_workers=0`` on the CPU: the next batch's pieces are built (Python and numpy,
    partly under the GIL) while the current batch is simulated (compiled kernels in the simulation threads, no
    GIL), instead of one after the other; no process boundary, so no shared-memory copy of the pieces. The
    iterable is only touched by that thread. An exception raised there is raised here, at the item it replaced;
    leaving the loop early stops the thread after its current item.

    Args:
        iterable: e.g. ``DataLoader(ds, ..., num_workers=0, collate_fn=collate_pieces)``.
        depth: items produced ahead (>= 1).
    """
    if int(depth) < 1:
        raise ValueError(f"depth must be >= 1, got {depth!r}")
    q: queue.Queue = queue.Queue(maxsize=int(depth))
    stop = threading.Event()
    end = object()

    def put(item) -> bool:
        while not stop.is_set():
            try:
                q.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in iterable:
                if not put((item, None)):
                    return
            put((end, None))
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer
            put((end, exc))

    worker = threading.Thread(target=produce, name="lfmbench-prefetch", daemon=True)
    worker.start()
    try:
        while True:
            item, exc = q.get()
            if item is end:
                if exc is not None:
                    raise exc
                return
            yield item
    finally:
        stop.set()
        worker.join()


# ----------------------------------------------------------------------------------------------------------
# simulation (any device)
# ----------------------------------------------------------------------------------------------------------
class _FPNCache:
    """Full-frame fixed-pattern maps per (preset, H, W, device, dtype), built once (:func:`sensor.fixed_pattern`)."""

    def __init__(self) -> None:
        self.maps: dict = {}

    def crops(self, preset, scene_hw: torch.Tensor, crop: torch.Tensor, dev, dtype,
              keys: Sequence[str] | None = None, uniform_hw: tuple[int, int] | None = None,
              crop_hw: tuple[int, int] | None = None) -> dict[str, torch.Tensor]:
        """(B, 1, 1, h, w) crops of each sample's full-frame pattern (only the maps ``keys``; default all).

        ``uniform_hw``: the (H, W) px every sample's scene has, and ``crop_hw`` (h, w) px, when the caller knows
        them: the crops are then a :class:`lfmbench.sensor.fused.PatternCrops` (one gather on the device when a
        map is read, no read of ``crop`` on the host; the Triton chain reads the whole frame in place)."""
        if keys is not None and not keys:
            return {}
        if uniform_hw is not None and crop_hw is not None:
            H, W = (int(n) for n in uniform_hw)
            h, w = (int(n) for n in crop_hw)
            key = (preset.name, preset.fpn_seed, repr(preset), H, W, str(dev), dtype)
            if key not in self.maps:
                self.maps[key] = _sensor.fixed_pattern(preset, H, W, device=dev, dtype=dtype)
            # cut when read (the torch and numba chains); the Triton chain reads the whole frame at each origin
            return PatternCrops({k: v for k, v in self.maps[key].items() if keys is None or k in keys},
                                crop[:, :2], (h, w))
        hw = scene_hw.tolist()
        cr = crop.tolist()
        out: dict[str, list] = {}
        for (H, W), (y0, x0, h, w) in zip(hw, cr):
            key = (preset.name, preset.fpn_seed, repr(preset), H, W, str(dev), dtype)
            if key not in self.maps:
                self.maps[key] = _sensor.fixed_pattern(preset, H, W, device=dev, dtype=dtype)
            for k, v in self.maps[key].items():
                if keys is None or k in keys:
                    out.setdefault(k, []).append(v[y0:y0 + h, x0:x0 + w])
        return {k: torch.stack(v)[:, None, None] for k, v in out.items()}


_DEFAULT_FPN = _FPNCache()


def simulate_batch(batch: Mapping[str, Any], preset: Any, outputs: Sequence[str] | None = None,
                   noise: bool | None = None, fpn_cache: _FPNCache | None = None, threads: int | None = None,
                   noise_streams: str | None = None) -> dict:
    """Simulate a batch of pieces on their device: the batched equivalent of ``LFMCaptureDataset.simulate``.

    Args:
        batch: from :func:`collate_pieces`, every tensor on one device (:func:`pieces_to`).
        preset: the sensor preset (name, path or :class:`lfmbench.sensor.SensorPreset`) the pieces were
            projected for (checked against the batch's sensor name).
        outputs: subset of the batch's outputs (default: the dataset's). noise: default the dataset's.
        fpn_cache: where full-frame fixed-pattern maps are kept (default: a module-level cache).
        threads: on the CPU, Python threads simulating the samples' noise and read-out in parallel (default
            ``torch.get_num_threads()``; see :func:`lfmbench.sensor.simulate_split_pixel_electrons`).
        noise_streams: ``"generator"``: sample b's noise from ``torch.Generator().manual_seed(noise_seed[b])`` (the
            per-sample path's default); ``"counter"``: from counter-based streams of ``noise_seed[b]``
            (:mod:`lfmbench.sensor.counter_noise`: the whole batch in one set of tensor operations, no host
            synchronisation); default: the batch's (its dataset's ``noise_streams``).

    Returns:
        the per-sample path's sample dict with a leading B (B, F, C, h, w): ``lpd_hcg``, ``lpd_lcg``, ``spd``
        DN; ``*_e`` input-referred LPD-equivalent e- over the short exposure; ``saturated`` bool; ``gt`` e-;
        ``light_index`` int64; ``depth`` m; ``*_rgb`` on request; ``meta`` (collated, on the CPU).

    Raises:
        ValueError: a tensor of the batch on another device than ``batch['static']``, a preset other than the
            batch's sensor, outputs the batch was not made for, or not a pieces batch.
    """
    check_batch_keys(batch, _PIECE_KEYS, hint=_PIECE_HINT)
    dev = check_same_device(batch, "static", hint=_DEVICE_HINT)
    info = batch["info"]
    preset = _sensor.resolve(preset)
    if preset.name != info["sensor"]:
        raise ValueError(f"preset: the batch was projected for sensor {info['sensor']!r}, not {preset.name!r}")
    want = set(info["outputs"] if outputs is None else outputs)
    missing = want - set(info["outputs"])
    if missing:
        raise ValueError(f"outputs: {sorted(missing)} were not requested from the dataset (it has "
                         f"{list(info['outputs'])})")
    noise = bool(info["noise"]) if noise is None else bool(noise)
    comp = compose_batch(batch, threads=threads)
    t_s, t_l = batch["timing"][:, 0], batch["timing"][:, 1]
    cap = None
    if want & SENSOR_OUTPUTS:
        lpd, spd = comp["lpd"][:, :, None], comp["spd"][:, :, None]                 # (B, F, 1, h, w) e-
        fpn = None
        gens = None
        if noise:
            # only the maps the chain reads (a PRNU gain where prnu > 0, a DSNU offset where dsnu > 0)
            used = [f"{pd}_{m}" for pd, spec in preset.photodiodes.items()
                    for m, on in (("gain", spec.prnu > 0), ("offset_e", spec.dsnu_e > 0)) if on]
            fpn = (fpn_cache or _DEFAULT_FPN).crops(preset, batch["scene_hw"], batch["crop"], dev, lpd.dtype, used,
                                                    info.get("scene_hw"), info["crop_hw"])
        streams = info.get("noise_streams", "generator") if noise_streams is None else noise_streams
        if streams not in NOISE_STREAMS:
            raise ValueError(f"noise_streams must be one of {NOISE_STREAMS}, got {streams!r}")
        seeds = batch["noise_seed"] if noise and streams == "counter" else None
        if noise and seeds is None:
            gens = [torch.Generator(device=dev).manual_seed(int(s)) for s in batch["noise_seed"].tolist()]
        # pieces from the device program are composed by this package (finite, >= 0): their values are not read
        # back for checks, which would wait for the device
        with trusted_values() if info.get("trusted") else contextlib.nullcontext():
            cap = _sensor.simulate_split_pixel_electrons(lpd, spd, preset, t_s[:, None], t_l[:, None],
                                                         generator=gens, noise=noise, fpn=fpn, threads=threads,
                                                         seeds=seeds)
    li = None
    if "light_index" in want:
        li = batch["light_index"]
        if dev.type == "cpu":       # int16 -> int64 per sample in the threads (6 MiB of a batch of 8)
            li64 = torch.empty(li.shape, dtype=torch.long, device=dev)
            map_samples(lambda b: li64[b].copy_(li[b]), li.shape[0], threads)
            li = li64
        else:
            li = li.long()
    sample = assemble_sample(want, cap, comp["gt"][:, :, None], preset, li, batch.get("depth"))
    if "meta" in batch:
        sample["meta"] = batch["meta"]
    return sample


class BatchedCaptureSimulator(nn.Module):
    """``nn.Module`` wrapper of :func:`simulate_batch`: holds the preset, outputs, noise flag and the fixed-pattern
    maps; runs on the device of the batch it is given (no parameters).

    Args:
        preset: sensor preset, name or YAML path. outputs: default subset of outputs (None: the batch's).
        noise: default noise flag (None: the batch's). threads: CPU threads per batch (see :func:`simulate_batch`).
    """

    def __init__(self, preset: Any = "ovt", outputs: Sequence[str] | None = None, noise: bool | None = None,
                 threads: int | None = None) -> None:
        super().__init__()
        self.preset = _sensor.resolve(preset)
        self.outputs = None if outputs is None else tuple(outputs)
        self.noise = noise
        self.threads = threads
        self._fpn = _FPNCache()

    @classmethod
    def from_dataset(cls, ds, threads: int | None = None) -> "BatchedCaptureSimulator":
        """The simulator matching an :class:`LFMCaptureDataset` (its preset, outputs and noise setting)."""
        return cls(ds.preset, ds.outputs, ds.noise, threads)

    def forward(self, batch: Mapping[str, Any]) -> dict:
        """``simulate_batch(batch, ...)``; see there for shapes and units."""
        return simulate_batch(batch, self.preset, self.outputs, self.noise, self._fpn, self.threads)

