"""The unsimulated pieces of a sample (``LFMCaptureDataset(..., pieces=True)``), simulated in batches by
:mod:`lfmbench.datasets.batched` (docs/guide/datasets.md, "Captures on the GPU").

:func:`capture_pieces` reads the dataset only through its public view of a scene
(:meth:`lfmbench.datasets.LFMCaptureDataset.scene`), :meth:`~lfmbench.datasets.LFMCaptureDataset.first_frame`
and :meth:`~lfmbench.datasets.LFMCaptureDataset.sample_meta`, and the rules of :mod:`lfmbench.datasets.assembly`
(the lights a crop shows); it sits below the dataset module, which calls it for ``pieces=True``. A light with a
gated waveform (:func:`lfmbench.datasets.pwm.gated_lights`) keeps its carrier's draw in ``slot_pwm`` and its gate
in ``gate_table`` (:func:`gate_rows`), which the batched weights apply (:func:`lfmbench.datasets.batch_compose.pwm_weights`).
"""
from __future__ import annotations

from typing import Any, Mapping, NamedTuple

import numpy as np
import torch

from lfmbench.datasets.assembly import visible_lights
from lfmbench.datasets.pwm import gated_lights
from lfmbench.vocabulary import PHOTODIODES

__all__ = ["PWM_FIELDS", "GATE_FIELDS", "capture_pieces", "gate_rows", "gate_table"]

#: Columns of ``slot_pwm``: period (s), duty (1), phase of a rising edge after frame 0 (s), rise (s), fall (s).
PWM_FIELDS = ("period_s", "duty", "phase_s", "rise_s", "fall_s")
#: Leading columns of a ``gate_table`` row (:class:`lfmbench.flicker.waveforms.GateTable`): gate period (s), gate
#: phase (s), scan lines, scan line; then the ON intervals ``s_0, e_0, s_1, e_1, ...`` (s), padded with ``[0, 0)``.
GATE_FIELDS = ("period_s", "phase_s", "scan_lines", "line")


def gate_rows(tables, m: int | None = None) -> torch.Tensor:
    """(G, 4 + 2 M) float64 rows of gated waveforms' tables (:meth:`lfmbench.flicker.waveforms.GatedWaveform.table`,
    :data:`GATE_FIELDS` then the ON intervals in s, each set padded with empty intervals to ``m``, default the most
    any has)."""
    tables = list(tables)
    m = max([int(np.shape(t.on)[0]) for t in tables] + [0]) if m is None else int(m)
    out = np.zeros((len(tables), len(GATE_FIELDS) + 2 * m), dtype=np.float64)
    for i, t in enumerate(tables):
        on = np.asarray(t.on, dtype=np.float64).reshape(-1)
        out[i, :len(GATE_FIELDS)] = (t.period_s, t.phase_s, t.scan_lines, t.line)
        out[i, len(GATE_FIELDS):len(GATE_FIELDS) + on.shape[0]] = on
    return torch.from_numpy(out)


def gate_table(rows: torch.Tensor, trailing: int = 2):
    """The :class:`lfmbench.flicker.waveforms.GateTable` of (G, 4 + 2 M) ``rows`` (:func:`gate_rows`; any device):
    each field (G, 1, ..., 1) with ``trailing`` unit axes (2: to broadcast with (G, R, K) windows), ``on``
    (G, 1, ..., 1, M, 2) s."""
    from lfmbench.flicker.waveforms import GateTable  # noqa: PLC0415

    G, n = int(rows.shape[0]), len(GATE_FIELDS)
    ones = (1,) * int(trailing)
    cols = [rows[:, i].reshape(G, *ones) for i in range(n)]
    return GateTable(*cols, rows[:, n:].reshape(G, *ones, -1, 2))


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
    once per scene (:meth:`lfmbench.datasets.capture.SceneView.cached`) so that a sample's entries are a mask of them, not a
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
                   frame_start: int | None = None, resident: Any = None) -> dict:
    """The unsimulated pieces of one sample of ``ds`` (an :class:`LFMCaptureDataset`) with the given draws.

    Args: as :meth:`LFMCaptureDataset.simulate` (``crop`` required). ``resident``: a
    :class:`lfmbench.datasets.device.ResidentScenes` holding the scene's layers on a device: the pieces are then
    cut from those (on that device: crops, gathers of the entries' rates) by the same rules, and only the small
    per-sample tables (slots, entry positions) are made on the host.

    Returns (F frames, crop h x w, S light slots, E pixel entries, Kmax bins; all CPU tensors; ``static``,
    ``light_index`` and ``depth`` are views into the dataset's scene cache, copied once by :func:`collate_pieces`:
    copy them before changing them in place):
        ``static``: (F, 2, h, w) float32, static rates of LPD and SPD, e-/s.
        ``t0``: (F,) float64 frame start times (s). ``timing``: (4,) float64: short and long exposure, line time,
        capture window (s). ``crop``: (4,) int64 (y0, x0, h, w) px. ``scene_hw``: (2,) int64 px.
        ``noise_seed``: () int64.
        ``slot_pwm``: (S, 5) float64 PWM parameters (:data:`PWM_FIELDS`); ``slot_frame``: (S,) int64 frame
        within the sample; ``slot_K``: (S,) int64 bins (0: a group stored without bins, whole-window weight).
        ``gate_slot``: (G,) int64 the slots of lights with a gated waveform (indicator, strobe, countdown,
        destination display), ``gate_table``: (G, 4 + 2 M) float64 their gates (:func:`gate_rows`),
        ``gate_span``: (G, 2) int64 the crop rows [r0, r1) their boxes cover (a rolling shutter's gates are
        evaluated on those rows only).
        ``entry_values``: (2, Kmax, E) float32 rates (LPD, SPD) per bin, e-/s (zero past the slot's K);
        ``entry_slot``: (E,) int32; ``entry_pix``: (E,) int32 flat index into (F, h, w).
        ``light_index``: (F, 1, h, w) int16 and ``depth``: (F, 1, h, w) float32 m, when requested.
        ``meta``: the per-sample ``meta`` dict. ``info``: the batch-consistency fields (sensor, frames, ...).
    """
    view = ds.scene(scene_id)
    meta = view.meta
    params = {int(k): v for k, v in params.items()}
    gates = gated_lights(meta)      # indicators, strobes, countdowns, destination displays: their own waveform
    group_params = dict(group_params or {})
    F = ds.frames
    s0 = ds.first_frame(scene_id, frame_start)
    y0, x0, h, w = (int(c) for c in crop)
    layers = view.layers
    tm = meta["timing"]
    t_s, t_l = float(tm["short_exposure_s"]), float(tm["long_exposure_s"])
    td = float(tm.get("line_time_s", 0.0)) if ds.line_time_s is None else float(ds.line_time_s)
    fps = float(meta["fps"])
    want = set(ds.outputs)
    src = None if resident is None else resident.scene(scene_id)
    out: dict[str, Any] = {
        "static": (view.static_rates() if src is None else src.static)[s0:s0 + F, :, y0:y0 + h, x0:x0 + w],
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
    for g, rates in (layers.group_static if src is None else src.group_static).items():
        p = group_params[g]
        for f in range(F):
            slots.append((f, 0, p))
            for pd in PHOTODIODES:
                vals[pd].append(rates[pd][s0 + f, y0:y0 + h, x0:x0 + w].reshape(1, -1))
            pix.append(torch.arange(f * hw, (f + 1) * hw, dtype=torch.int32))
            slot_of.append(torch.full((hw,), len(slots) - 1, dtype=torch.int32))
    # per-light layers: the scene's entries (fixed per scene) masked to the crop and the lights with PWM draws
    ent = view.cached("pieces_entries", _SceneEntries)
    picks = []
    gated: list = []                 # (slot, waveform)
    for f in range(F):
        fe = ent.frames[s0 + f]
        shown = {id(rates) for *_, rates in visible_lights(layers, s0 + f, (y0, x0, h, w), params)}
        vis = [i for i, (*_, rates) in enumerate(layers.lights[s0 + f]) if id(rates) in shown]
        if not vis:
            continue
        rank = np.full(len(fe.lights), -1, dtype=np.int32)
        rank[vis] = np.arange(len(slots), len(slots) + len(vis), dtype=np.int32)
        gated.extend((len(slots) + j, gates[fe.lights[i][0]], fe.lights[i][2]) for j, i in enumerate(vis)
                     if fe.lights[i][0] in gates)
        slots.extend((f, fe.lights[i][1], params[fe.lights[i][0]]) for i in vis)
        keep = (fe.y >= y0) & (fe.y < y0 + h) & (fe.x >= x0) & (fe.x < x0 + w)
        if len(vis) < len(fe.lights):
            keep &= rank[fe.pos] >= 0
        idx = np.flatnonzero(keep)
        picks.append((f, fe, idx, len(pix)))
        pix.append(torch.from_numpy((f * hw + (fe.y[idx] - y0) * w + (fe.x[idx] - x0)).astype(np.int32)))
        slot_of.append(torch.from_numpy(rank[fe.pos[idx]]))
    kmax = max([max(s[1], 1) for s in slots] + [1])
    out["slot_pwm"] = torch.tensor([[float(s[2][k]) for k in PWM_FIELDS] for s in slots],
                                   dtype=torch.float64).reshape(len(slots), len(PWM_FIELDS))
    out["slot_frame"] = torch.tensor([s[0] for s in slots], dtype=torch.int64)
    out["slot_K"] = torch.tensor([s[1] for s in slots], dtype=torch.int64)
    out["gate_slot"] = torch.tensor([g[0] for g in gated], dtype=torch.int64)
    out["gate_table"] = gate_rows(wf.table() for _, wf, _ in gated)
    out["gate_span"] = torch.tensor([[min(max(b[0] - y0, 0), h), min(max(b[2] - y0, 0), h)] for *_, b in gated],
                                    dtype=torch.int64).reshape(len(gated), 2)
    if pix and src is not None:
        # on the resident layers' device: the groups' crops and a gather of the lights' entries
        dev = src.static.device
        parts = [torch.nn.functional.pad(torch.stack([vals[pd][j].reshape(-1) for pd in PHOTODIODES])[:, None],
                                         (0, 0, 0, kmax - 1)) for j in range(len(vals[PHOTODIODES[0]]))]
        for f, fe, idx, j in picks:
            if src.entry_order is not None:        # the resident entries are stored in another order
                idx = src.entry_order[s0 + f][idx]
            parts.append(src.entries[s0 + f][:, :kmax].index_select(2, torch.from_numpy(idx).to(dev)))
        out["entry_values"] = torch.cat(parts, 2)
        out["entry_slot"] = torch.cat(slot_of).to(dev)
        out["entry_pix"] = torch.cat(pix).to(dev)
    elif pix:
        n_all = [int(p_.shape[0]) for p_ in pix]
        o = np.concatenate([[0], np.cumsum(n_all)])
        ev = np.empty((2, kmax, int(o[-1])), dtype=np.float32)
        for pd_i, pd in enumerate(PHOTODIODES):
            for j, v in enumerate(vals[pd]):                                  # groups: (1, hw), zero past bin 0
                ev[pd_i, 0, o[j]:o[j + 1]] = v.reshape(-1).numpy()
                ev[pd_i, 1:, o[j]:o[j + 1]] = 0.0
        for _f, fe, idx, j in picks:
            np.take(fe.vals[:, :kmax], idx, axis=2, out=ev[:, :, o[j]:o[j + 1]], mode="clip")
        out["entry_values"] = torch.from_numpy(ev)
        out["entry_slot"] = torch.cat(slot_of)
        out["entry_pix"] = torch.cat(pix)
    else:
        dev = None if src is None else src.static.device
        out["entry_values"] = torch.zeros(2, kmax, 0, device=dev)
        out["entry_slot"] = torch.zeros(0, dtype=torch.int32, device=dev)
        out["entry_pix"] = torch.zeros(0, dtype=torch.int32, device=dev)
    meta_out = ds.sample_meta(view, index, params, (y0, x0, h, w), s0)
    if "light_index" in want:
        out["light_index"] = (view.light_index() if src is None else src.light_index)[s0:s0 + F, :, y0:y0 + h,
                                                                                          x0:x0 + w]
    if "depth" in want:
        out["depth"] = (layers.aux["depth.Z"] if src is None else src.depth)[s0:s0 + F, y0:y0 + h, x0:x0 + w][:, None]
    out["meta"] = meta_out
    out["info"] = {"sensor": ds.sensor_name, "frames": F, "crop_hw": (h, w), "shutter": ds.shutter,
                   "noise": ds.noise, "outputs": tuple(ds.outputs), "noise_streams": ds.noise_streams}
    return out
