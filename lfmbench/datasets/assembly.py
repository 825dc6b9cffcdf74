r"""Sample assembly: the composition and timing rules of a capture, and the sample dict, for the per-sample path
(:class:`lfmbench.datasets.LFMCaptureDataset`) and the batched path (:mod:`lfmbench.datasets.batched`) alike.

Exposure composition (timing of ``docs/guide/contracts.md``; frame n starts at :math:`t_n = n/\text{fps}`):

.. math:: \bar e_{pd}(y,x) = R^{static}_{pd}(y,x)\,t_{pd}
          + \sum_j \sum_k R^{j}_{pd,k}(y,x)\;\Phi_j\big([t_k, t_{k+1}) \cap [a_{pd}(y), a_{pd}(y) + t_{pd})\big)

with :math:`R` the projected rates (e-/s), :math:`t_k` the K bin edges of the frame's capture window, and
:math:`\Phi_j` the exact PWM exposure of light j (:func:`lfmbench.flicker.pwm_exposure`) over the overlap. The
LPD window is the short exposure :math:`[t_n + (T_L - T_S)/2, +T_S)`, the SPD window the long one
:math:`[t_n, t_n + T_L)`; under a rolling shutter row y starts ``y * line_time`` later (flickering layers
only; static layers keep their global-shutter motion, a documented approximation).

Ground truth ``gt`` (docs/guide/datasets.md): the mean LPD electrons of the short exposure with every LED at its
time-averaged level (duty cycle x ON level), noise-free and unclipped, in the input-referred units of the
``*_e`` outputs (LPD-equivalent e- over the short exposure).

One definition each: the bin grid (:func:`bin_edges`), the window timing (:func:`window_starts`,
:func:`row_window_starts`), the bin weights (:func:`window_bin_exposure`), the lights a crop shows
(:func:`visible_lights`), the composition of one frame (:func:`compose_frame`), the per-pixel light index
(:func:`light_index`) and the sample dict built from the sensor chain's result (:func:`assemble_sample`). The
frames of the other capture plans (their own windows) are :mod:`lfmbench.datasets.plan_frames`.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np
import torch

from lfmbench.datasets.projection import SceneLayers
from lfmbench.datasets.pwm import gated_lights
from lfmbench.flicker import pwm_exposure
from lfmbench.vocabulary import PHOTODIODES

__all__ = ["NOISE_STREAMS", "SENSOR_OUTPUTS", "bin_edges", "window_bin_exposure",
           "window_starts", "row_window_starts", "check_line_time", "visible_lights", "compose_frame", "light_index",
           "add_rgb", "assemble_sample"]

#: Where a sample's sensor noise comes from: ``"generator"``, ``torch.Generator().manual_seed(noise_seed)`` (the
#: numbers of every published benchmark result); ``"counter"``, counter-based streams of the noise seed
#: (:mod:`lfmbench.sensor.counter_noise`: the same numbers per sample on any device and in any batch, what the
#: device path :mod:`lfmbench.datasets.device` draws). Same distribution, different numbers.
NOISE_STREAMS = ("generator", "counter")
#: Outputs that need the sensor chain (the others come from the composition and the aux layers alone).
SENSOR_OUTPUTS = frozenset({"raw", "input_referred", "saturated", "rgb"})


def _is_tensor(*xs) -> bool:
    return any(isinstance(x, torch.Tensor) for x in xs)


def bin_edges(window_s, bins: int, like=None, kmax: int | None = None):
    r"""Edges (s) of ``bins`` equal time bins over ``[0, window_s]``, relative to the frame start.

    The one definition of the bin grid (``np.linspace(0, window_s, bins + 1)``, bit for bit: ``i * (window_s /
    bins)`` with the last edge set to ``window_s``), for numpy (``like=None``) or on the device of tensor
    ``like``: there ``window_s`` and ``bins`` may be (S,) tensors (one grid per slot) and the result is (S, Kmax + 1)
    with ``Kmax = bins.max()``; the edges past a slot's own K repeat its last edge (zero-length bins).

    Args:
        window_s: capture window (s), scalar or (S,). bins: K >= 1, int or (S,) int tensor.
        like: ``None`` for numpy, else a tensor whose device is used (float64).
        kmax: with tensors, a bound >= ``bins.max()`` known to the caller (the grid is then (S, kmax + 1), and
            the device is not asked for the maximum: no host synchronisation).

    Returns:
        (K + 1,) float64 numpy array, or an (S, Kmax + 1) float64 tensor.
    """
    if like is None:
        return np.linspace(0.0, float(window_s), int(bins) + 1)
    dev = like.device
    K = torch.as_tensor(bins, device=dev).reshape(-1).long()
    win = torch.as_tensor(window_s, dtype=torch.float64, device=dev).reshape(-1).expand(K.shape[0])
    if kmax is None:
        kmax = int(K.max()) if K.numel() else 1
    i = torch.arange(kmax + 1, device=dev, dtype=torch.float64)
    step = win / K.clamp_min(1).to(torch.float64)                                  # (S,) s
    edges = i[None, :] * step[:, None] + 0.0                                       # numpy's linspace: i * step + 0
    last = i[None, :] >= K[:, None].to(torch.float64)
    return torch.where(last, win[:, None], edges)


def window_bin_exposure(edges, start, length, period, duty, led_phase, rise=0.0, fall=0.0, level: str = "pwm",
                        check: bool = True, waveform=None):
    r"""Time (s) at PWM level 1 that each bin contributes to an exposure window.

    Array-agnostic: numpy inputs take :func:`lfmbench.flicker.pwm_exposure`'s compiled kernel, torch tensors its
    array formula on their device (bit-identical to the kernel in float64 on the CPU); the batched path of
    :mod:`lfmbench.datasets.batched` calls this same function.

    Args:
        edges: (*, K+1) bin edges (s); the per-sample path passes (K+1,). start: (*, R) window start per row (s).
        length: window length (s), a scalar or broadcastable to (*, 1, 1).
        period, duty, led_phase, rise, fall: PWM parameters (s, 1, s, s, s): scalars for one light, or arrays of
            shape (L, 1, 1) for L lights at once (generally: broadcastable to (*, R, K)).
        level: ``"pwm"`` (the modulated source) or ``"mean"`` (constant at its duty cycle: ground truth).
        check: validate the PWM parameters (``False`` when they were validated when drawn).
        waveform: a gated waveform of :mod:`lfmbench.flicker.waveforms` (one light, numpy only): the bins of its
            exposure (carrier = the PWM parameters; ``level="mean"``: the gate with the carrier at its duty).

    Returns:
        (*, R, K), e.g. (R, K) or (L, R, K), float64:
        :math:`\int_{[t_k, t_{k+1}) \cap [a, a + t_e)} s(t)\,dt` in s.
    """
    if _is_tensor(edges, start):
        lo = torch.maximum(edges[..., None, :-1], start[..., :, None])
        hi = torch.minimum(edges[..., None, 1:], start[..., :, None] + length)
        dur = (hi - lo).clamp_min(0.0)
    else:
        lo = np.maximum(edges[..., None, :-1], start[..., :, None])
        hi = np.minimum(edges[..., None, 1:], start[..., :, None] + length)
        dur = np.maximum(hi - lo, 0.0)
    if waveform is not None:
        if level == "mean":
            return waveform.mean_exposure(lo, dur, duty)
        return waveform.exposure(lo, dur, period, duty, led_phase, rise, fall)
    if level == "mean":
        return dur * (duty if _is_tensor(duty) else np.asarray(duty))
    return pwm_exposure(lo - led_phase, dur, period, duty, rise_time=rise, fall_time=fall, check=check)


def window_starts(t0, t_short, t_long, shift) -> dict:
    """Window start times (s) of the LPD (short, centred in the long one) and SPD (long) windows.

    The one definition of the capture timing (docs/guide/contracts.md), array-agnostic (numpy or torch, broadcasting).

    Args:
        t0: frame start(s) (s). t_short, t_long: exposure times (s). shift: per-row delay ``row * line_time``
            (s), zeros for a global shutter.

    Returns:
        ``{"lpd": t0 + (t_long - t_short) / 2 + shift, "spd": t0 + shift}`` in s.
    """
    return {"lpd": t0 + (t_long - t_short) / 2.0 + shift, "spd": t0 + shift}


def row_window_starts(meta: dict, frame: int, rows: np.ndarray, shutter: str,
                   line_time_s: float | None = None) -> dict[str, np.ndarray]:
    """Window start times (s) per row for the LPD (short) and SPD (long) windows of ``frame``."""
    tm = meta["timing"]
    t0 = frame / float(meta["fps"])
    ts, tl = float(tm["short_exposure_s"]), float(tm["long_exposure_s"])
    td = float(tm.get("line_time_s", 0.0)) if line_time_s is None else float(line_time_s)
    shift = rows * td if shutter == "rolling" else np.zeros(len(rows))
    return window_starts(t0, ts, tl, shift)


def check_line_time(meta: dict, line_time_s: float, rows: int) -> None:
    """Raise ``ValueError`` (naming ``line_time_s``) if the last row's windows leave the rendered bins."""
    tm = meta["timing"]
    last = (rows - 1) * float(line_time_s)
    if not (np.isfinite(line_time_s) and line_time_s >= 0):
        raise ValueError(f"line_time_s must be finite and >= 0 (s), got {line_time_s!r}")
    if float(tm["long_exposure_s"]) + last > float(tm["capture_window_s"]) * (1 + 1e-9):
        raise ValueError(f"line_time_s = {line_time_s} s: row {rows - 1} ends at "
                         f"{(float(tm['long_exposure_s']) + last) * 1e3:.3f} ms, after the rendered capture window "
                         f"({float(tm['capture_window_s']) * 1e3:.3f} ms); at most "
                         f"{(float(tm['capture_window_s']) - float(tm['long_exposure_s'])) / max(rows - 1, 1):.3g} s")


def visible_lights(layers: SceneLayers, frame: int, crop: tuple[int, int, int, int], params: Mapping[int, dict]):
    """The per-light layers of ``frame`` that a crop shows, for lights with PWM parameters.

    Yields:
        ``(light_id, pwm_dict, (by0, bx0), (iy0, iy1, ix0, ix1), {pd: (K, hh, ww) e-/s})``: the layer's box
        origin and its intersection with the crop (absolute pixels, half-open), in the stored order.
    """
    y0, x0, h, w = crop
    for light_id, _g, (by0, bx0, by1, bx1), rates in layers.lights[frame]:
        iy0, iy1 = max(by0, y0), min(by1, y0 + h)
        ix0, ix1 = max(bx0, x0), min(bx1, x0 + w)
        p = params.get(light_id)
        if p is None or iy0 >= iy1 or ix0 >= ix1:  # light left out, or outside the crop
            continue
        yield light_id, p, (by0, bx0), (iy0, iy1, ix0, ix1), rates


def _visible_by_bins(layers: SceneLayers, frame: int, crop: tuple[int, int, int, int],
                     params: Mapping[int, dict]) -> tuple[dict[int, list], dict[int, list]]:
    """The lights of :func:`visible_lights` grouped by their bin count K: ``({K: [(pwm, box origin, intersection,
    rates)]}, {K: [light id]})`` in the stored order."""
    visible: dict[int, list] = {}
    ids: dict[int, list] = {}
    for light_id, p, box0, inter, rates in visible_lights(layers, frame, crop, params):
        visible.setdefault(int(rates["lpd"].shape[0]), []).append((p, box0, inter, rates))
        ids.setdefault(int(rates["lpd"].shape[0]), []).append(int(light_id))
    return visible, ids


def _box_rows(group: Sequence, y0: int) -> tuple[np.ndarray, np.ndarray]:
    """(light, row) index pairs (two (P,) arrays): every crop row (from the crop's top ``y0``) that the box of each
    light of ``group`` (:func:`_visible_by_bins`) covers."""
    boxes = [(i, iy0 - y0, iy1 - y0) for i, (_p, _b, (iy0, iy1, _x0, _x1), _r) in enumerate(group)]
    li = np.concatenate([np.full(b - a, i, dtype=np.int64) for i, a, b in boxes] + [np.zeros(0, np.int64)])
    ri = np.concatenate([np.arange(a, b, dtype=np.int64) for _i, a, b in boxes] + [np.zeros(0, np.int64)])
    return li, ri


def _rolling_bin_exposure(edges, starts, length, pa: dict, level: str, rows: tuple[np.ndarray, np.ndarray],
                          n_lights: int) -> np.ndarray:
    """:func:`window_bin_exposure` of ``n_lights`` lights for a rolling readout, computed only at the (light, row)
    pairs ``rows`` (:func:`_box_rows`: the rows a light can reach), zero elsewhere: the same numbers there (an
    element-wise formula of the same inputs), at the cost of the lamps' rows instead of every row of the crop.

    Args:
        edges: (K+1,) bin edges (s). starts: (*W, R) window starts per row (s). length: window length(s) (s),
            broadcastable to (*W, 1, 1). pa: PWM parameters, each (n_lights, 1, ...) (s, 1, s, s, s).
        level: ``"pwm"`` or ``"mean"``. rows: (P,) light and (P,) row indices.

    Returns:
        (n_lights, *W, R, K) float64 s.
    """
    li, ri = rows
    lead = starts.shape[:-1]
    shape = (1,) * len(lead) + (li.shape[0], 1)
    p = {k: np.asarray(v, dtype=np.float64).reshape(n_lights)[li].reshape(shape) for k, v in pa.items()}
    wp = window_bin_exposure(edges, starts[..., ri], length, p["period_s"], p["duty"], p["phase_s"], p["rise_s"],
                             p["fall_s"], level, check=False)                             # (*W, P, K)
    out = np.zeros((n_lights,) + tuple(starts.shape) + (wp.shape[-1],), dtype=np.float64)
    idx = (li,) + (slice(None),) * len(lead) + (ri,)
    out[idx] = np.moveaxis(wp, -2, 0)
    return out


def compose_frame(layers: SceneLayers, meta: dict, frame: int, crop: tuple[int, int, int, int],
                  params: dict[int, dict], group_params: dict[str, dict], shutter: str = "global",
                  line_time_s: float | None = None) -> dict:
    """Mean photo-electrons of one frame in a crop, and the ground truth.

    Args:
        layers: projected scene layers. meta: the scene's meta.json. frame: frame index.
        crop: (y0, x0, h, w) in pixels. params: light_id -> PWM dict (period_s, duty, phase_s, rise_s, fall_s);
            lights without an entry are left out.
        group_params: group -> PWM dict, for flickering groups stored without time bins.
        shutter: ``"global"`` or ``"rolling"``. line_time_s: row delay (s), default ``meta["timing"]``.

    Returns:
        ``{"lpd": (h, w), "spd": (h, w), "gt": (h, w)}`` float32 tensors in e- (mean, noise-free, unclipped).
    """
    tm = meta["timing"]
    t_len = {"lpd": float(tm["short_exposure_s"]), "spd": float(tm["long_exposure_s"])}
    y0, x0, h, w = crop
    rows = np.arange(y0, y0 + h, dtype=np.float64)
    starts = row_window_starts(meta, frame, rows, shutter, line_time_s)
    out = {pd: layers.static[pd][frame, y0:y0 + h, x0:x0 + w] * t_len[pd] for pd in PHOTODIODES}
    out["gt"] = out["lpd"].clone()
    # flickering groups without time bins: one weight per frame (per row for a rolling shutter)
    for g, rates in layers.group_static.items():
        p = group_params[g]
        for pd in PHOTODIODES:
            wgt = pwm_exposure(starts[pd] - p["phase_s"], t_len[pd], p["period_s"], p["duty"],
                               rise_time=p["rise_s"], fall_time=p["fall_s"])
            out[pd] = out[pd] + rates[pd][frame, y0:y0 + h, x0:x0 + w] * torch.from_numpy(wgt).float()[:, None]
        out["gt"] = out["gt"] + rates["lpd"][frame, y0:y0 + h, x0:x0 + w] * float(p["duty"] * t_len["lpd"])
    # flickering lights stored per light in K time bins (K from the stored layer: a group may override it).
    # All visible lights with the same K share one pwm_exposure call per capture: (L, R, K) weights.
    visible, ids = _visible_by_bins(layers, frame, crop, params)
    gates = gated_lights(meta)   # indicators, strobes, countdowns, destination displays: their own waveform
    rolling = shutter == "rolling"
    for K, group in visible.items():
        edges = frame / float(meta["fps"]) + bin_edges(float(tm["capture_window_s"]), K)
        pa = {k: np.array([g[0][k] for g in group], dtype=np.float64)[:, None, None]
              for k in ("period_s", "duty", "phase_s", "rise_s", "fall_s")}
        wts = {}
        pairs = _box_rows(group, y0) if rolling else None
        for key, pd, level in (("lpd", "lpd", "pwm"), ("spd", "spd", "pwm"), ("gt", "lpd", "mean")):
            st = starts[pd] if rolling else starts[pd][:1]
            if rolling:     # only the rows each lamp covers (the einsum below reads no others)
                w = _rolling_bin_exposure(edges, st, t_len[pd], pa, level, pairs, len(group))    # (L, R, K) s
            else:
                w = window_bin_exposure(edges, st, t_len[pd], pa["period_s"], pa["duty"], pa["phase_s"],
                                        pa["rise_s"], pa["fall_s"], level, check=False)    # (L, 1, K) s
            wts[key] = torch.from_numpy(np.ascontiguousarray(w)).float()
            for i, lid in enumerate(ids[K]):
                if lid in gates:
                    p = group[i][0]
                    w = window_bin_exposure(edges, st, t_len[pd], p["period_s"], p["duty"], p["phase_s"],
                                            p["rise_s"], p["fall_s"], level, waveform=gates[lid])  # (R, K) s
                    wts[key][i] = torch.from_numpy(np.ascontiguousarray(w)).float()
        if not rolling:
            # one weight vector per light and window: LPD and gt share the LPD bins, one (2, K) x (K, hh, ww)
            w_lpd_gt = torch.stack([wts["lpd"][:, 0], wts["gt"][:, 0]], dim=1)              # (L, 2, K) s
        for i, (_p, (by0, bx0), (iy0, iy1, ix0, ix1), rates) in enumerate(group):
            win = (slice(iy0 - y0, iy1 - y0), slice(ix0 - x0, ix1 - x0))
            sub = {pd: rates[pd][:, iy0 - by0:iy1 - by0, ix0 - bx0:ix1 - bx0] for pd in PHOTODIODES}  # (K, hh, ww)
            if rolling:
                for key, pd in (("lpd", "lpd"), ("spd", "spd"), ("gt", "lpd")):
                    out[key][win] += torch.einsum("kyx,yk->yx", sub[pd], wts[key][i, iy0 - y0:iy1 - y0])
            else:
                both = torch.tensordot(w_lpd_gt[i], sub["lpd"], dims=1)                     # (2, hh, ww) e-
                out["lpd"][win] += both[0]
                out["gt"][win] += both[1]
                out["spd"][win] += torch.tensordot(wts["spd"][i, 0], sub["spd"], dims=1)
    return out


def light_index(mask: torch.Tensor, lights: Sequence[Mapping]) -> torch.Tensor:
    """Index into the sample's light list per pixel, -1 where no listed light.

    Args:
        mask: (F, h, w) float ``mask.light`` aux channel (light id per pixel, -1 none).
        lights: the sample's lights (``meta["lights"]`` entries with ``"id"``), in the order of the meta arrays.

    Returns:
        (F, 1, h, w) int64.
    """
    ids = mask.round().long()
    lut = torch.full((int(max([int(lt["id"]) for lt in lights] + [0])) + 2,), -1, dtype=torch.long)
    for i, lt in enumerate(lights):
        lut[int(lt["id"])] = i
    valid = (ids >= 0) & (ids < len(lut) - 1)
    return torch.where(valid, lut[ids.clamp(0, len(lut) - 1)], -1)[:, None]


def add_rgb(sample: dict, preset, want: set) -> None:
    """Add ``lpd_lcg_rgb``, ``spd_rgb``, ``gt_rgb`` (*, 3, h, w) to ``sample`` (in place) from its (*, 1, h, w)
    ``lpd_lcg_e``, ``spd_e``, ``gt`` (any leading shape; another capture plan: ``<capture>_rgb`` of every capture),
    then drop those the caller did not ask for."""
    from kornia.color import raw_to_rgb
    cfa = preset.cfa.to_kornia()
    # split pixel: LPD-LCG and SPD (as always); other plans: every capture
    caps = ("lpd_lcg", "spd") if preset.architecture == "split_pixel" else tuple(preset.captures)
    # kornia's bilinear demosaic; crops start at even offsets, so the Bayer phase is the preset's
    for src, dst in (*((f"{c}_e", f"{c}_rgb") for c in caps), ("gt", "gt_rgb")):
        x = sample[src].float()
        sample[dst] = raw_to_rgb(x.reshape(-1, *x.shape[-3:]), cfa).reshape(*x.shape[:-3], 3, *x.shape[-2:])
    if "input_referred" not in want:
        for k in preset.captures:
            del sample[f"{k}_e"]
    if "gt" not in want:
        del sample["gt"]


def assemble_sample(want: set, cap: Mapping[str, torch.Tensor] | None, gt: torch.Tensor | None, preset: Any,
                    light_index: torch.Tensor | None = None, depth: torch.Tensor | None = None) -> dict:
    """The sample dict of the requested outputs (both paths; leading dimensions ``*`` are (F,) or (B, F)).

    Args:
        want: the requested outputs (a subset of ``OUTPUTS`` of :mod:`lfmbench.datasets.capture`).
        cap: the result of :func:`lfmbench.sensor.simulate_plan_electrons` (or, split pixel,
            :func:`lfmbench.sensor.simulate_split_pixel_electrons`) on (*, 1, h, w) inputs, or None when no output
            in :data:`SENSOR_OUTPUTS` is requested.
        gt: (*, 1, h, w) ground truth, e-, or None when neither ``gt`` nor ``rgb`` is requested.
        preset: the sensor preset (its captures name the keys; its CFA for ``rgb``).
        light_index: (*, 1, h, w) int64, when requested. depth: (*, 1, h, w) m, when requested.

    Returns:
        the captures by name (split pixel: ``lpd_hcg``, ``lpd_lcg``, ``spd``; DN), ``*_e`` (e-), ``saturated``,
        ``gt``, ``light_index``, ``depth``, ``*_rgb``: those the request implies (``meta`` is added by the caller).
    """
    sample: dict[str, Any] = {}
    if cap is not None:
        if "raw" in want:
            sample.update({k: cap[k] for k in preset.captures})
        if want & {"input_referred", "rgb"}:
            sample.update({f"{k}_e": cap[f"{k}_e"] for k in preset.captures})
        if "saturated" in want:
            sample["saturated"] = cap["saturated"]
    if "gt" in want or "rgb" in want:
        sample["gt"] = gt
    if "light_index" in want:
        sample["light_index"] = light_index
    if "depth" in want:
        sample["depth"] = depth
    if "rgb" in want:
        add_rgb(sample, preset, want)
    return sample
