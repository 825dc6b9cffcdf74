r"""Captures simulated in batches on the training device (the GPU path of :class:`LFMCaptureDataset`).

The per-sample path (``LFMCaptureDataset.__getitem__``) composes and simulates every sample inside a DataLoader
worker on the CPU. Here the work is split in two:

1. **Pieces** (workers, CPU): ``LFMCaptureDataset(..., pieces=True)`` returns, per sample, only what is fixed per
   scene and crop plus the sample's draws (:func:`capture_pieces`): the crop of the projected static rates, the
   per-light time-bin rates of the lights the crop shows (as a sparse list of pixel entries), the PWM draws, the
   frame times, the noise seed, ``light_index`` and ``depth``, and the same ``meta`` as the per-sample path.
   :func:`collate_pieces` batches them (and refuses batches that mix sensors, frame counts, crops, shutters or
   output sets); :func:`pieces_to` moves a batch to a device.
2. **Simulation** (any device, whole batch): :func:`simulate_batch` (or the :class:`BatchedCaptureSimulator`
   module) computes the exact PWM weights of every light, bin, window and row, composes the mean electrons of
   both photodiodes and the ground truth, and runs the split-pixel sensor chain
   (:func:`lfmbench.sensor.simulate_split_pixel_electrons`) on the batch's device.

Every rule is the per-sample path's own function: bin edges (:func:`~lfmbench.datasets.capture.bin_edges`),
window timing (:func:`~lfmbench.datasets.capture.window_starts`), bin weights
(:func:`~lfmbench.datasets.capture.window_bin_exposure`, through :func:`lfmbench.flicker.pwm_exposure`), the
visible lights of a crop (:func:`~lfmbench.datasets.capture.visible_lights`), the sensor chain and its noise
(one ``torch.Generator`` per sample, seeded by the sample's own noise seed), the fixed pattern
(:func:`lfmbench.sensor.fixed_pattern`), ``light_index``, ``meta`` and the demosaic. The draws are made by
``LFMCaptureDataset.draws`` (functions of ``(seed, epoch, index)``). On the CPU the composition and the sensor
chain run as compiled passes of the same formulas (:mod:`lfmbench.datasets._compose_kernel`, the ``"numba"``
backend of :func:`lfmbench.sensor.simulate_split_pixel_electrons`), the samples of a batch in parallel threads;
:func:`prefetch` overlaps building the next batch's pieces with that.

Composition (the formula of :mod:`lfmbench.datasets.capture`), per sample b, frame f and photodiode pd:

.. math:: \bar e_{pd} = R^{static}_{pd}\,t_{pd} + \sum_{e \in \text{entries}} \delta_{p(e)}
          \sum_k V_{e,k,pd}\; W^{pd}_{s(e),\,y(e),\,k}

with entry e a pixel p(e) (row y(e)) of one light slot s(e) (a light in one frame), V its rates (e-/s) in the
slot's K bins and W the slot's PWM exposure (s) of bin k in that row's window. Flickering groups stored
without bins (imported data) are slots with one full-crop "bin" whose weight is the PWM exposure of the whole
window (the per-sample rule, ``K = 0`` in ``slot_K``).
"""
from __future__ import annotations

import queue
import threading
from typing import Any, Iterable, Iterator, Mapping, NamedTuple, Sequence

import numpy as np
import torch
from torch import nn
from torch.utils.data import default_collate

from lfmbench import sensor as _sensor
from lfmbench.sensor.fused import map_samples
from lfmbench.datasets.capture import (add_rgb, bin_edges, visible_lights,
                                       window_bin_exposure, window_starts)
from lfmbench.datasets.projection import PHOTODIODES
from lfmbench.flicker import pwm_exposure

__all__ = ["capture_pieces", "collate_pieces", "pieces_to", "prefetch", "simulate_batch", "BatchedCaptureSimulator",
           "piece_bytes", "pwm_weights", "compose_batch", "PWM_FIELDS"]

#: Columns of ``slot_pwm``: period (s), duty (1), phase of a rising edge after frame 0 (s), rise (s), fall (s).
PWM_FIELDS = ("period_s", "duty", "phase_s", "rise_s", "fall_s")
#: Consistency fields of ``info``: a batch must agree on all of them.
_INFO_FIELDS = ("sensor", "frames", "crop_hw", "shutter", "noise", "outputs")


# ----------------------------------------------------------------------------------------------------------
# pieces (DataLoader workers, CPU)
# ----------------------------------------------------------------------------------------------------------
class _FrameEntries(NamedTuple):
    """The per-light layers of one frame as pixel entries, in the stored light order, row-major in each box
    (numpy arrays: a sample takes a few small gathers of them, where torch's per-call overhead would dominate)."""

    lights: list       # [(light_id, K, (y0, x0, y1, x1))] px, half-open
    y: np.ndarray      # (N,) int32 absolute row, px
    x: np.ndarray      # (N,) int32 absolute column, px
    pos: np.ndarray    # (N,) int64 position of the entry's light in ``lights``
    vals: np.ndarray   # (2, Kscene, N) float32 rates (LPD, SPD) per bin, e-/s, zero past the light's K


class _SceneEntries:
    """Every frame's per-light layers of one scene flattened into pixel entries (:class:`_FrameEntries`), built
    once per scene (``LFMCaptureDataset._scene_cached``) so that a sample's entries are a mask of them, not a
    Python loop over its lights."""

    def __init__(self, layers) -> None:
        kmax = max([int(r["lpd"].shape[0]) for fr in layers.lights for *_, r in fr] + [1])
        self.frames: list[_FrameEntries] = []
        for fr in layers.lights:
            lights, ys, xs, ps, vs = [], [], [], [], []
            for i, (lid, _g, (by0, bx0, by1, bx1), rates) in enumerate(fr):
                K, hh, ww = (int(n) for n in rates["lpd"].shape)
                if (hh, ww) != (by1 - by0, bx1 - bx0):
                    raise ValueError(f"light {lid}: layer of {hh}x{ww} px in a box of {by1 - by0}x{bx1 - bx0} px")
                lights.append((int(lid), K, (int(by0), int(bx0), int(by1), int(bx1))))
                ys.append(np.repeat(np.arange(by0, by1, dtype=np.int32), ww))
                xs.append(np.tile(np.arange(bx0, bx1, dtype=np.int32), hh))
                ps.append(np.full(hh * ww, i, dtype=np.int64))
                v = torch.stack([rates[pd].reshape(K, -1) for pd in PHOTODIODES])          # (2, K, n) e-/s
                vs.append(torch.nn.functional.pad(v, (0, 0, 0, kmax - K)).numpy())
            if lights:
                self.frames.append(_FrameEntries(lights, np.concatenate(ys), np.concatenate(xs), np.concatenate(ps),
                                                 np.ascontiguousarray(np.concatenate(vs, 2), dtype=np.float32)))
            else:
                z = np.zeros(0, dtype=np.int32)
                self.frames.append(_FrameEntries([], z, z, z.astype(np.int64), np.zeros((2, kmax, 0), np.float32)))


def capture_pieces(ds, scene_id: str, params: Mapping[int, Mapping], group_params: Mapping[str, Mapping] | None,
                   crop: tuple[int, int, int, int], noise_seed: int, index: int = -1,
                   frame_start: int | None = None) -> dict:
    """The unsimulated pieces of one sample of ``ds`` (an :class:`LFMCaptureDataset`) with the given draws.

    Args: as :meth:`LFMCaptureDataset.simulate` (``crop`` required).

    Returns (F frames, crop h x w, S light slots, E pixel entries, Kmax bins; all CPU tensors; ``static``,
    ``light_index`` and ``depth`` are views into the dataset's scene cache, copied once by :func:`collate_pieces`:
    copy them before changing them in place):
        ``static``: (F, 2, h, w) float32, static rates of LPD and SPD, e-/s.
        ``t0``: (F,) float64 frame start times (s). ``timing``: (4,) float64: short and long exposure, line time,
        capture window (s). ``crop``: (4,) int64 (y0, x0, h, w) px. ``scene_hw``: (2,) int64 px.
        ``noise_seed``: () int64.
        ``slot_pwm``: (S, 5) float64 PWM parameters (:data:`PWM_FIELDS`); ``slot_frame``: (S,) int64 frame
        within the sample; ``slot_K``: (S,) int64 bins (0: a group stored without bins, whole-window weight).
        ``entry_values``: (2, Kmax, E) float32 rates (LPD, SPD) per bin, e-/s (zero past the slot's K);
        ``entry_slot``: (E,) int32; ``entry_pix``: (E,) int32 flat index into (F, h, w).
        ``light_index``: (F, 1, h, w) int16 and ``depth``: (F, 1, h, w) float32 m, when requested.
        ``meta``: the per-sample ``meta`` dict. ``info``: the batch-consistency fields (sensor, frames, ...).
    """
    meta = ds.corpus.meta(scene_id)
    params = {int(k): v for k, v in params.items()}
    group_params = dict(group_params or {})
    F = ds.frames
    s0 = ds._first_frame(scene_id, frame_start)
    y0, x0, h, w = (int(c) for c in crop)
    layers = ds._layers(scene_id)
    tm = meta["timing"]
    t_s, t_l = float(tm["short_exposure_s"]), float(tm["long_exposure_s"])
    td = float(tm.get("line_time_s", 0.0)) if ds.line_time_s is None else float(ds.line_time_s)
    fps = float(meta["fps"])
    want = set(ds.outputs)
    out: dict[str, Any] = {
        "static": ds._static_both(scene_id, layers)[s0:s0 + F, :, y0:y0 + h, x0:x0 + w],
        "t0": torch.tensor([(s0 + f) / fps for f in range(F)], dtype=torch.float64),
        "timing": torch.tensor([t_s, t_l, td, float(tm["capture_window_s"])], dtype=torch.float64),
        "crop": torch.tensor([y0, x0, h, w], dtype=torch.int64),
        "scene_hw": torch.tensor([meta["height"], meta["width"]], dtype=torch.int64),
        "noise_seed": torch.tensor(int(noise_seed), dtype=torch.int64),
    }
    slots: list[tuple] = []          # (frame, K, pwm)
    vals: dict[str, list] = {pd: [] for pd in PHOTODIODES}    # pd -> [(K, n)]
    pix: list[torch.Tensor] = []     # (n,)
    slot_of: list[torch.Tensor] = []  # (n,)
    hw = h * w
    for g, rates in layers.group_static.items():
        p = group_params[g]
        for f in range(F):
            slots.append((f, 0, p))
            for pd in PHOTODIODES:
                vals[pd].append(rates[pd][s0 + f, y0:y0 + h, x0:x0 + w].reshape(1, -1))
            pix.append(f * hw + torch.arange(hw, dtype=torch.int32))
            slot_of.append(torch.full((hw,), len(slots) - 1, dtype=torch.int32))
    # per-light layers: the scene's entries (fixed per scene) masked to the crop and the lights with PWM draws
    ent = ds._scene_cached(scene_id, "pieces_entries", _SceneEntries, layers)
    picks = []
    for f in range(F):
        fe = ent.frames[s0 + f]
        shown = {id(rates) for *_, rates in visible_lights(layers, s0 + f, (y0, x0, h, w), params)}
        vis = [i for i, (*_, rates) in enumerate(layers.lights[s0 + f]) if id(rates) in shown]
        if not vis:
            continue
        rank = np.full(len(fe.lights), -1, dtype=np.int32)
        rank[vis] = np.arange(len(slots), len(slots) + len(vis), dtype=np.int32)
        slots.extend((f, fe.lights[i][1], params[fe.lights[i][0]]) for i in vis)
        keep = (fe.y >= y0) & (fe.y < y0 + h) & (fe.x >= x0) & (fe.x < x0 + w)
        if len(vis) < len(fe.lights):
            keep &= rank[fe.pos] >= 0
        idx = np.flatnonzero(keep)
        picks.append((fe, idx, len(pix)))
        pix.append(torch.from_numpy((f * hw + (fe.y[idx] - y0) * w + (fe.x[idx] - x0)).astype(np.int32)))
        slot_of.append(torch.from_numpy(rank[fe.pos[idx]]))
    kmax = max([max(s[1], 1) for s in slots] + [1])
    out["slot_pwm"] = torch.tensor([[float(s[2][k]) for k in PWM_FIELDS] for s in slots],
                                   dtype=torch.float64).reshape(len(slots), len(PWM_FIELDS))
    out["slot_frame"] = torch.tensor([s[0] for s in slots], dtype=torch.int64)
    out["slot_K"] = torch.tensor([s[1] for s in slots], dtype=torch.int64)
    if pix:
        n_all = [int(p_.shape[0]) for p_ in pix]
        o = np.concatenate([[0], np.cumsum(n_all)])
        ev = np.empty((2, kmax, int(o[-1])), dtype=np.float32)
        for pd_i, pd in enumerate(PHOTODIODES):
            for j, v in enumerate(vals[pd]):                                  # groups: (1, hw), zero past bin 0
                ev[pd_i, 0, o[j]:o[j + 1]] = v.reshape(-1).numpy()
                ev[pd_i, 1:, o[j]:o[j + 1]] = 0.0
        for fe, idx, j in picks:
            np.take(fe.vals[:, :kmax], idx, axis=2, out=ev[:, :, o[j]:o[j + 1]], mode="clip")
        out["entry_values"] = torch.from_numpy(ev)
        out["entry_slot"] = torch.cat(slot_of)
        out["entry_pix"] = torch.cat(pix)
    else:
        out["entry_values"] = torch.zeros(2, kmax, 0)
        out["entry_slot"] = torch.zeros(0, dtype=torch.int32)
        out["entry_pix"] = torch.zeros(0, dtype=torch.int32)
    lights = ds._lights(scene_id)
    if len(lights) > ds.max_lights:
        raise ValueError(f"max_lights={ds.max_lights} but scene {scene_id!r} has {len(lights)} lights")
    if "light_index" in want:
        out["light_index"] = ds._light_index(scene_id, lights, s0, (y0, x0, h, w), layers)
    if "depth" in want:
        out["depth"] = layers.aux["depth.Z"][s0:s0 + F, y0:y0 + h, x0:x0 + w][:, None]
    out["meta"] = ds._meta(scene_id, index, lights, params, (y0, x0, h, w), t_s, t_l, layers)
    out["meta"]["frame_start"] = s0
    out["info"] = {"sensor": ds.sensor_name, "frames": F, "crop_hw": (h, w), "shutter": ds.shutter,
                   "noise": ds.noise, "outputs": tuple(ds.outputs)}
    return out


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
        (``entry_slot`` into the batch's slots, ``slot_sample`` (S,) int64 their sample, ``entry_values`` padded
        to the batch's Kmax), ``meta`` collated as the per-sample path's DataLoader does, and ``info``.

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
    out["slot_sample"] = torch.repeat_interleave(torch.arange(len(samples)), torch.tensor(n_slots, dtype=torch.long))
    out["meta"] = default_collate([s["meta"] for s in samples])
    out["info"] = dict(info0)
    return out


def pieces_to(batch: Mapping[str, Any], device: torch.device | str, non_blocking: bool = False) -> dict:
    """``batch`` (from :func:`collate_pieces`) with its tensors on ``device`` (``meta`` stays where it is)."""
    return {k: (v.to(device, non_blocking=non_blocking) if torch.is_tensor(v) else v) for k, v in batch.items()}


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
def _check_batch(batch: Mapping[str, Any]) -> torch.device:
    for k in ("static", "t0", "timing", "crop", "scene_hw", "noise_seed", "slot_pwm", "slot_frame", "slot_K",
              "slot_sample", "entry_values", "entry_slot", "entry_pix", "info"):
        if k not in batch:
            raise ValueError(f"batch: missing {k!r}; pass the output of collate_pieces (datasets built with "
                             "pieces=True)")
    dev = batch["static"].device
    for k, v in batch.items():
        if torch.is_tensor(v) and v.device != dev:
            raise ValueError(f"batch[{k!r}] is on {v.device} but batch['static'] is on {dev}; move the whole batch "
                             "with pieces_to(batch, device)")
    return dev


def pwm_weights(batch: Mapping[str, Any]) -> dict[str, torch.Tensor]:
    """PWM exposure (s) of every slot, row and bin in the LPD and SPD windows, and the ground-truth weights.

    Args:
        batch: from :func:`collate_pieces` (on any one device).

    Returns:
        ``{"lpd", "spd", "gt"}``: (S, R, Kmax) float64 s; R = h rows for a rolling shutter, 1 for a global one
        (row-independent). Bins past a slot's own K weigh 0; a ``K = 0`` slot (a group without bins) has its
        whole-window weight in bin 0. These are the per-sample path's numbers (same functions, same order of
        operations; bit-identical on the CPU).
    """
    dev = _check_batch(batch)
    info = batch["info"]
    h = int(info["crop_hw"][0])
    sb = batch["slot_sample"]
    S = int(sb.shape[0])
    K = batch["slot_K"]
    tim = batch["timing"][sb]                                                     # (S, 4) s
    t_s, t_l, td, cw = tim.unbind(-1)
    t0 = batch["t0"][sb, batch["slot_frame"]]                                     # (S,) s
    if info["shutter"] == "rolling":
        rows = batch["crop"][sb, 0:1].to(torch.float64) + torch.arange(h, device=dev, dtype=torch.float64)
        shift = rows * td[:, None]                                                # (S, h) s
    else:
        shift = torch.zeros(S, 1, dtype=torch.float64, device=dev)
    starts = window_starts(t0[:, None], t_s[:, None], t_l[:, None], shift)       # pd -> (S, R) s
    length = {"lpd": t_s, "spd": t_l}
    pw = {k: batch["slot_pwm"][:, i] for i, k in enumerate(PWM_FIELDS)}
    pw3 = {k: v[:, None, None] for k, v in pw.items()}
    kmax = int(batch["entry_values"].shape[1])
    if S == 0:
        z = torch.zeros(0, shift.shape[1], kmax, dtype=torch.float64, device=dev)
        return {"lpd": z, "spd": z, "gt": z}
    edges = t0[:, None] + bin_edges(cw, K.clamp_min(1), like=shift)              # (S, K'+1) s
    if edges.shape[1] < kmax + 1:
        edges = torch.cat([edges, edges[:, -1:].expand(S, kmax + 1 - edges.shape[1])], 1)
    out = {}
    for key, pd, level in (("lpd", "lpd", "pwm"), ("spd", "spd", "pwm"), ("gt", "lpd", "mean")):
        out[key] = window_bin_exposure(edges, starts[pd], length[pd][:, None, None], pw3["period_s"], pw3["duty"],
                                       pw3["phase_s"], pw3["rise_s"], pw3["fall_s"], level, check=False)
    grp = K == 0
    if bool(grp.any()):
        gi = grp.nonzero()[:, 0]
        p = {k: v[gi, None] for k, v in pw.items()}
        for key, pd in (("lpd", "lpd"), ("spd", "spd")):
            wg = pwm_exposure(starts[pd][gi] - p["phase_s"], length[pd][gi, None], p["period_s"], p["duty"],
                              rise_time=p["rise_s"], fall_time=p["fall_s"])                    # (G, R) s
            out[key][gi] = 0.0
            out[key][gi, :, 0] = wg
        out["gt"][gi] = 0.0
        out["gt"][gi, :, 0] = (p["duty"] * length["lpd"][gi, None]).expand(-1, out["gt"].shape[1])
    return out


def compose_batch(batch: Mapping[str, Any], backend: str = "auto", threads: int | None = None) -> dict[str, torch.Tensor]:
    """Mean photo-electrons of every frame of a batch, and the ground truth (the batched :func:`compose_frame`).

    Args:
        batch: from :func:`collate_pieces`, on one device.
        backend: ``"torch"`` (any device), ``"numba"`` (CPU, numba: one pass over the static rates and one
            over the entries, :mod:`lfmbench.datasets._compose_kernel`; the same products, sums in float32 in
            another order, so equal to ``"torch"`` up to float32 rounding) or ``"auto"`` (``"numba"`` on the CPU
            when numba is importable).
        threads: CPU threads composing samples in parallel (``"numba"`` backend; default
            ``torch.get_num_threads()``; the result does not depend on it).

    Returns:
        ``{"lpd", "spd", "gt"}``: (B, F, h, w) float32 e- (mean, noise-free, unclipped): LPD over the short
        window, SPD over the long one, ``gt`` the LPD with every LED at its duty cycle.
    """
    if backend not in ("auto", "torch", "numba"):
        raise ValueError(f"backend must be 'auto', 'torch' or 'numba', got {backend!r}")
    dev = _check_batch(batch)
    B, F, _, h, w = batch["static"].shape
    t_s, t_l = batch["timing"][:, 0], batch["timing"][:, 1]
    compiled = dev.type == "cpu" and batch["static"].dtype == torch.float32 and _numba_available()
    if backend == "numba" and not compiled:
        raise ValueError("backend='numba' needs a float32 batch on the CPU and numba")
    if compiled and backend != "torch":
        from lfmbench.datasets._compose_kernel import compose

        E = int(batch["entry_pix"].shape[0])
        if E:
            wts = {k: v.float().contiguous() for k, v in pwm_weights(batch).items()}
        else:
            wts = {k: torch.zeros(0, 1, 1, device=dev) for k in ("lpd", "spd", "gt")}
        comp = {k: torch.empty(B, F, h, w, device=dev) for k in ("lpd", "spd", "gt")}
        n = lambda x: x.contiguous().numpy()  # noqa: E731
        args = (n(batch["static"].reshape(B, F, 2, h * w)), n(t_s.float()), n(t_l.float()), n(batch["slot_sample"]),
                n(batch["entry_slot"]), n(batch["entry_pix"]), n(batch["entry_values"]), wts["lpd"].numpy(),
                wts["spd"].numpy(), wts["gt"].numpy(), w, *(comp[k].view(B, F, h * w).numpy()
                                                            for k in ("lpd", "spd", "gt")))
        # one task per sample: its entries are a contiguous run when they come in sample order (as collate_pieces
        # concatenates them); otherwise one task for the whole batch
        ent_sample = args[3][args[4]] if E else np.zeros(0, dtype=np.int64)
        if E and bool((np.diff(ent_sample) < 0).any()):
            compose(*args, 0, B, 0, E)
        else:
            e_at = np.searchsorted(ent_sample, np.arange(B + 1), side="left")
            map_samples(lambda b: compose(*args, b, b + 1, int(e_at[b]), int(e_at[b + 1])), B, threads)
        return comp
    comp = {"lpd": batch["static"][:, :, 0] * t_s.float()[:, None, None, None],
            "spd": batch["static"][:, :, 1] * t_l.float()[:, None, None, None]}
    comp["gt"] = comp["lpd"].clone()
    if int(batch["entry_pix"].shape[0]):
        wts = pwm_weights(batch)
        slot = batch["entry_slot"].long()
        pix = batch["entry_pix"].long()
        dest = batch["slot_sample"][slot] * (F * h * w) + pix
        R = wts["lpd"].shape[1]
        at = slot * R + (pix % (h * w)) // w if R > 1 else slot                      # (E,) row of (S * R, Kmax)
        vals = batch["entry_values"].transpose(1, 2).contiguous()                    # (2, E, Kmax) e-/s
        for key, c in (("lpd", 0), ("spd", 1), ("gt", 0)):
            wk = wts[key].float().reshape(-1, wts[key].shape[-1]).index_select(0, at)  # (E, Kmax) s
            contrib = (vals[c] * wk).sum(-1)                                          # (E,) e-
            comp[key].view(-1).index_add_(0, dest, contrib)
    return comp


def _numba_available() -> bool:
    """Whether numba is importable (the compiled CPU backends)."""
    from lfmbench.sensor import poisson

    return poisson.available()


class _FPNCache:
    """Full-frame fixed-pattern maps per (preset, H, W, device, dtype), built once (:func:`sensor.fixed_pattern`)."""

    def __init__(self) -> None:
        self.maps: dict = {}

    def crops(self, preset, scene_hw: torch.Tensor, crop: torch.Tensor, dev, dtype,
              keys: Sequence[str] | None = None) -> dict[str, torch.Tensor]:
        """(B, 1, 1, h, w) crops of each sample's full-frame pattern (only the maps ``keys``; default all)."""
        if keys is not None and not keys:
            return {}
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
                   noise: bool | None = None, fpn_cache: _FPNCache | None = None, threads: int | None = None) -> dict:
    """Simulate a batch of pieces on their device: the batched equivalent of ``LFMCaptureDataset.simulate``.

    Args:
        batch: from :func:`collate_pieces`, every tensor on one device (:func:`pieces_to`).
        preset: the sensor preset (name, path or :class:`lfmbench.sensor.SensorPreset`) the pieces were
            projected for (checked against the batch's sensor name).
        outputs: subset of the batch's outputs (default: the dataset's). noise: default the dataset's.
        fpn_cache: where full-frame fixed-pattern maps are kept (default: a module-level cache).
        threads: on the CPU, Python threads simulating the samples' noise and read-out in parallel (default
            ``torch.get_num_threads()``; see :func:`lfmbench.sensor.simulate_split_pixel_electrons`).

    Returns:
        the per-sample path's sample dict with a leading B (B, F, C, h, w): ``lpd_hcg``, ``lpd_lcg``, ``spd``
        DN; ``*_e`` input-referred LPD-equivalent e- over the short exposure; ``saturated`` bool; ``gt`` e-;
        ``light_index`` int64; ``depth`` m; ``*_rgb`` on request; ``meta`` (collated, on the CPU).

    Raises:
        ValueError: a tensor of the batch on another device than ``batch['static']``, a preset other than the
            batch's sensor, outputs the batch was not made for, or not a pieces batch.
    """
    dev = _check_batch(batch)
    info = batch["info"]
    preset = _sensor.load_preset(preset)
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
    sample: dict[str, Any] = {}
    if want & {"raw", "input_referred", "saturated", "rgb"}:
        lpd, spd = comp["lpd"][:, :, None], comp["spd"][:, :, None]                 # (B, F, 1, h, w) e-
        fpn = None
        gens = None
        if noise:
            # only the maps the chain reads (a PRNU gain where prnu > 0, a DSNU offset where dsnu > 0)
            used = [f"{pd}_{m}" for pd, spec in preset.photodiodes.items()
                    for m, on in (("gain", spec.prnu > 0), ("offset_e", spec.dsnu_e > 0)) if on]
            fpn = (fpn_cache or _DEFAULT_FPN).crops(preset, batch["scene_hw"], batch["crop"], dev, lpd.dtype, used)
            gens = [torch.Generator(device=dev).manual_seed(int(s)) for s in batch["noise_seed"].tolist()]
        cap = _sensor.simulate_split_pixel_electrons(lpd, spd, preset, t_s[:, None], t_l[:, None], generator=gens,
                                                     noise=noise, fpn=fpn, threads=threads)
        if "raw" in want:
            sample.update({k: cap[k] for k in ("lpd_hcg", "lpd_lcg", "spd")})
        if want & {"input_referred", "rgb"}:
            sample.update({k: cap[k] for k in ("lpd_hcg_e", "lpd_lcg_e", "spd_e")})
        if "saturated" in want:
            sample["saturated"] = cap["saturated"]
    if "gt" in want or "rgb" in want:
        sample["gt"] = comp["gt"][:, :, None]
    if "light_index" in want:
        li = batch["light_index"]
        if dev.type == "cpu":       # int16 -> int64 per sample in the threads (6 MiB of a batch of 8)
            sample["light_index"] = torch.empty(li.shape, dtype=torch.long, device=dev)
            map_samples(lambda b: sample["light_index"][b].copy_(li[b]), li.shape[0], threads)
        else:
            sample["light_index"] = li.long()
    if "depth" in want:
        sample["depth"] = batch["depth"]
    if "rgb" in want:
        add_rgb(sample, preset, want)
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
        self.preset = _sensor.load_preset(preset)
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

