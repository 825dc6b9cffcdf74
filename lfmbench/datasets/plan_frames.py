r"""The frames of a capture plan other than the split pixel (``staggered``, ``chopped``, ``single``, ``lofic``, a
user's windows): each exposure of the plan resolved for a scene (:class:`PlanExposure`, :func:`plan_exposures`),
which stored static window stands for a plan window (:func:`static_window_source`, :func:`static_window_mix`,
:data:`STATIC_WINDOW_RULES`), and one frame of every exposure (:func:`compose_plan_frame`), with the bin grid and
the bin weights of :mod:`lfmbench.datasets.assembly` (the composition formula is stated there).
"""
from __future__ import annotations

from typing import Any, Mapping, NamedTuple, Sequence

import numpy as np
import torch

from lfmbench.corpus import bin_prefix, window_bin_weights
from lfmbench.datasets.assembly import _box_rows, _rolling_bin_exposure, _visible_by_bins, bin_edges, window_bin_exposure
from lfmbench.datasets.projection import SceneLayers, layer_key
from lfmbench.datasets.pwm import gated_lights
from lfmbench.flicker import pwm_exposure
from lfmbench.resources import docs_url
from lfmbench.sensor.plan import resolve_windows, total_length_s

__all__ = ["PlanExposure", "STORED_WINDOW_LAYER", "STATIC_WINDOW_RULES", "static_window_source",
           "static_window_mix", "exposure_static_layer", "exposure_static_exact", "layer_key", "plan_exposures",
           "compose_plan_frame"]


class PlanExposure(NamedTuple):
    """One exposure of a capture plan, resolved for a scene (:func:`plan_exposures`).

    key: the exposure key (:attr:`lfmbench.sensor.SensorPreset.exposures`). fill_factor: its photodiode's, 1.
    windows: ``((start_s, length_s), ...)`` relative to the frame start, s. rolling: rows start ``y * line_time_s``
    later. line_time_s: s.
    """

    key: str
    fill_factor: float
    windows: tuple
    rolling: bool
    line_time_s: float

    @property
    def length_s(self) -> float:
        """Integration time, s (the summed window lengths)."""
        return total_length_s(self.windows)


#: Static windows a corpus stores, and the photodiode key under which a plan's projected layers hold each (the
#: layers of a plan are projected with a unit fill factor: ``lpd`` the short window, ``spd`` the long one).
STORED_WINDOW_LAYER = {"short": "lpd", "long": "spd"}


def static_window_source(start_s: float, length_s: float, timing: Mapping[str, Any]) -> tuple[str, bool]:
    """Which stored static window stands for the window ``[start_s, start_s + length_s)`` (s, from the frame start):
    ``(name, exact)``. A window equal to the short or long one (to 1e-9 of its length) is exact; any other gets the
    smallest stored window that contains it, else the long one (the ``nearest`` rule measured in
    docs/results/sensor-architectures.md, "Static radiance for any window")."""
    ts, tl = float(timing["short_exposure_s"]), float(timing["long_exposure_s"])
    sa = (tl - ts) / 2.0
    tol = 1e-9 * max(length_s, 1e-12)
    if abs(start_s - sa) <= tol and abs(length_s - ts) <= tol:
        return "short", True
    if abs(start_s) <= tol and abs(length_s - tl) <= tol:
        return "long", True
    if start_s >= sa - tol and start_s + length_s <= sa + ts + tol:
        return "short", False
    return "long", False


def static_window_mix(start_s: float, length_s: float, timing: Mapping[str, Any]) -> tuple[dict[str, float], bool]:
    """The projected static layers and weights whose weighted sum is the static radiance of the window
    ``[start_s, start_s + length_s)`` (s, from the frame start), and whether that is exact: ``({layer: weight},
    exact)``. With static time bins (``timing["static_edges_s"]``, corpus format version 4) a window that is a union
    of bins is their length-weighted mean (``{"bin03": 0.4, ...}``, exact: every capture window sees the scene, its
    ego motion and moving vehicles, over its own time); another window overlaps bins partly and gets each bin by its
    overlap (not exact). Without bins: :func:`static_window_source` (``{"lpd": 1.0}`` for the short window,
    ``{"spd": 1.0}`` for the long one, :data:`STORED_WINDOW_LAYER`)."""
    edges = timing.get("static_edges_s")
    if edges is not None:
        e = np.asarray(edges, dtype=np.float64)
        w = window_bin_weights(e, start_s, length_s, tol=1e-6)
        exact = w is not None
        if w is None:  # partial bins by their overlap with the window
            w = np.clip(np.minimum(e[1:], start_s + length_s) - np.maximum(e[:-1], start_s), 0.0, None) / length_s
        nb = len(e) - 1
        return {bin_prefix(k, nb): float(x) for k, x in enumerate(w) if x > 0}, exact
    name, exact = static_window_source(start_s, length_s, timing)
    return {STORED_WINDOW_LAYER[name]: 1.0}, exact


def exposure_static_layer(windows, timing: Mapping[str, Any]) -> tuple[str, bool] | None:
    """The stored static window layer (``timing["window_layers"]``, :mod:`lfmbench.corpus.window_layers`) whose
    windows are exactly ``windows`` ([(start_s, length_s)], s from the frame start; to 1e-6 of each length), as
    ``(name, moves)``; None when no layer matches. ``moves`` False: nothing in the scene moves and the layer is the
    long window (``spd``), exactly."""
    ws = [(float(a), float(n)) for a, n in windows]
    for lay in timing.get("window_layers") or ():
        lw = lay["windows_s"]
        if len(lw) == len(ws) and all(abs(a - la) <= 1e-6 * n and abs(n - ln) <= 1e-6 * n
                                      for (a, n), (la, ln) in zip(ws, lw)):
            return lay["name"], bool(lay["moves"])
    return None


def exposure_static_exact(windows, timing: Mapping[str, Any]) -> bool:
    """Whether the static radiance of a capture with ``windows`` ([(start_s, length_s)]) is exact: a stored static
    window layer is exactly its windows (:func:`exposure_static_layer`), or each window is a stored window or a union
    of static time bins (:func:`static_window_mix`)."""
    return exposure_static_layer(windows, timing) is not None or all(static_window_mix(a, n, timing)[1]
                                                                       for a, n in windows)


#: How a plan's window that a corpus does not store for its static groups is served (``LFMCaptureDataset``
#: ``static_windows``): ``"nearest"``, the smallest stored window containing it (:func:`static_window_source`;
#: error measured in docs/results/sensor-architectures.md), or ``"exact"``, an error naming preset and corpus.
STATIC_WINDOW_RULES = ("nearest", "exact")


def plan_exposures(preset, meta: Mapping[str, Any], shutter: str, line_time_s: float | None = None,
                   source: str = "corpus", static_windows: str = "nearest") -> list[PlanExposure]:
    """The exposures of ``preset``'s plan for a scene: windows resolved against ``meta["timing"]``, readout from the
    capture, else the preset, else ``shutter`` / ``line_time_s`` (else the corpus's line time).

    Raises:
        ValueError: a window (with the rolling rows' delay) leaves the corpus's capture window, or
            (``static_windows="exact"``) is not one the corpus stores for its static groups: naming the preset
            file, the capture's field and ``source`` (the corpus).
    """
    if static_windows not in STATIC_WINDOW_RULES:
        raise ValueError(f"static_windows must be one of {STATIC_WINDOW_RULES}, got {static_windows!r:.40}")
    tm = meta["timing"]
    cw = float(tm["capture_window_s"])
    out = []
    for key, caps in preset.exposures.items():
        spec = preset.captures[key]
        ro = preset.capture_readout(key)
        rolling = (ro.shutter or shutter) == "rolling"
        lt = ro.line_time_s if ro.line_time_s is not None else (
            float(tm.get("line_time_s", 0.0)) if line_time_s is None else float(line_time_s))
        wins = resolve_windows(spec.exposure, tm)
        last = (int(meta["height"]) - 1) * lt if rolling else 0.0
        for i, (a, n) in enumerate(wins):
            if a + n + last > cw * (1 + 1e-9):
                raise ValueError(f"{preset.source}: field 'captures.{key}.exposure' window {i} ends at "
                                 f"{(a + n + last) * 1e3:.4g} ms{' (last row)' if rolling else ''}, after the capture "
                                 f"window of {source} ({cw * 1e3:.4g} ms): the corpus has no radiance there")
            if static_windows == "exact" and not static_window_mix(a, n, tm)[1] \
                    and exposure_static_layer(wins, tm) is None:
                raise ValueError(f"{preset.source}: field 'captures.{key}.exposure' window {i} "
                                 f"[{a * 1e3:.4g}, {(a + n) * 1e3:.4g}) ms is not a window {source} stores for its "
                                 "static groups (short, long, a union of its static time bins or, with its "
                                 "capture's other windows, a static window layer); use "
                                 "static_windows='nearest' (the measured approximation, "
                                 f"{docs_url('benchmarks/motion-windows.md')}) or a corpus rendered with these "
                                 "window edges")
        out.append(PlanExposure(key, preset.photodiodes[spec.photodiode].fill_factor, wins, rolling, lt))
    return out


def compose_plan_frame(layers: SceneLayers, meta: dict, frame: int, crop: tuple[int, int, int, int],
                       params: dict[int, dict], group_params: dict[str, dict], exposures: Sequence[PlanExposure],
                       reference: str) -> dict:
    r"""Mean photo-electrons of every exposure of a capture plan in one frame's crop, and the ground truth.

    .. math:: \bar e_x(y, x) = FF_x \Big[\sum_w R^{static}_{s(w)}(y, x)\,|w|
              + \sum_j \sum_k R^j_k(y, x) \sum_w \Phi_j\big([t_k, t_{k+1}) \cap (w + \delta_x(y))\big)\Big]

    over the windows w of exposure x (a chopped exposure: the union), :math:`\delta_x(y) = y\,t_{line}` for a
    rolling readout (0 global), :math:`s(w)` the stored static window standing for w
    (:func:`static_window_source`), :math:`\Phi_j` the exact PWM exposure of light j. ``layers`` are projected with a
    unit fill factor (:data:`STORED_WINDOW_LAYER`). Ground truth: the reference exposure with every light at its
    time-averaged level (duty x ON), noise-free, unclipped.

    Args:
        layers, meta, frame, crop, params, group_params: as :func:`compose_frame`.
        exposures: :func:`plan_exposures` of the scene. reference: the key of the reference exposure.

    Returns:
        ``{exposure key: (h, w), "gt": (h, w)}`` float32 tensors in e-.
    """
    tm = meta["timing"]
    y0, x0, h, w = crop
    t0 = frame / float(meta["fps"])
    rows = np.arange(y0, y0 + h, dtype=np.float64)
    crop_of = (slice(y0, y0 + h), slice(x0, x0 + w))
    src = {x.key: [static_window_source(a, n, tm)[0] for a, n in x.windows] for x in exposures}
    out: dict[str, torch.Tensor] = {}
    for x in exposures:
        acc = torch.zeros(h, w)
        lay = exposure_static_layer(x.windows, tm)
        if lay is not None:  # a static window layer: exactly this capture's windows (e.g. a chopped union)
            total = float(sum(n for _, n in x.windows))
            acc += layers.static[layer_key(lay[0]) if lay[1] else STORED_WINDOW_LAYER["long"]][frame][crop_of] * total
            out[x.key] = acc
            continue
        for a_, n in x.windows:
            for layer, wgt in static_window_mix(a_, n, tm)[0].items():  # static time bins, else a stored window
                acc += layers.static[layer][frame][crop_of] * float(wgt * n)
        out[x.key] = acc
    ref = next(x for x in exposures if x.key == reference)
    out["gt"] = out[reference].clone()

    def starts(x: PlanExposure) -> np.ndarray:
        """(Wn, R) window starts (s, absolute): one row for a global readout."""
        a = np.array([t0 + a_ for a_, _ in x.windows])[:, None]
        return a + (rows[None, :] - 0.0) * x.line_time_s if x.rolling else a

    for g, rates in layers.group_static.items():
        p = group_params[g]
        for x in exposures:
            st = starts(x)
            for i, ((_a, n), s_) in enumerate(zip(x.windows, src[x.key])):
                wgt = pwm_exposure(st[i] - p["phase_s"], n, p["period_s"], p["duty"], rise_time=p["rise_s"],
                                   fall_time=p["fall_s"])
                r = rates[STORED_WINDOW_LAYER[s_]][frame][crop_of]
                out[x.key] += r * torch.from_numpy(np.asarray(wgt, dtype=np.float64)).float().reshape(-1, 1)
                if x.key == reference:
                    out["gt"] += r * float(p["duty"] * n)
    visible, ids = _visible_by_bins(layers, frame, crop, params)
    gates = gated_lights(meta)   # indicators, strobes, countdowns, destination displays: their own waveform
    for K, group in visible.items():
        edges = t0 + bin_edges(float(tm["capture_window_s"]), K)
        pa = {k: np.array([g_[0][k] for g_ in group], dtype=np.float64)[:, None, None, None]
              for k in ("period_s", "duty", "phase_s", "rise_s", "fall_s")}
        # weights of every output (exposures, then gt) by readout: one einsum / tensordot per light and readout
        by_mode: dict[bool, tuple[list, list]] = {}
        pairs = _box_rows(group, y0)
        for key, x, level in [*((x.key, x, "pwm") for x in exposures), ("gt", ref, "mean")]:
            length = np.array([n for _, n in x.windows], dtype=np.float64)[:, None, None]
            if x.rolling:   # only the rows each lamp covers (the einsum below reads no others)
                wgt = _rolling_bin_exposure(edges, starts(x), length, pa, level, pairs, len(group))  # (L, Wn, R, K)
            else:
                wgt = window_bin_exposure(edges, starts(x), length, pa["period_s"], pa["duty"], pa["phase_s"],
                                          pa["rise_s"], pa["fall_s"], level, check=False)  # (L, Wn, 1, K) s
            wsum = wgt.sum(1)                                                              # (L, R, K)
            for i, lid in enumerate(ids[K]):
                if lid in gates:
                    p = group[i][0]
                    wg = window_bin_exposure(edges, starts(x), length, p["period_s"], p["duty"], p["phase_s"],
                                             p["rise_s"], p["fall_s"], level, waveform=gates[lid])  # (Wn, R, K)
                    wsum[i] = wg.sum(0)
            keys, ws = by_mode.setdefault(x.rolling, ([], []))
            keys.append(key)
            ws.append(wsum)
        stacked = {m: (keys, torch.from_numpy(np.ascontiguousarray(np.stack(ws, 1))).float())  # (L, E, R, K)
                   for m, (keys, ws) in by_mode.items()}
        for i, (_p, (by0, bx0), (iy0, iy1, ix0, ix1), rates) in enumerate(group):
            win = (slice(iy0 - y0, iy1 - y0), slice(ix0 - x0, ix1 - x0))
            sub = rates["lpd"][:, iy0 - by0:iy1 - by0, ix0 - bx0:ix1 - bx0]               # (K, hh, ww) e-/s
            for rolling, (keys, wt) in stacked.items():
                if rolling:
                    add = torch.einsum("kyx,eyk->eyx", sub, wt[i, :, iy0 - y0:iy1 - y0])    # (E, hh, ww) e-
                else:
                    add = torch.tensordot(wt[i, :, 0], sub, dims=1)
                for j, key in enumerate(keys):
                    out[key][win] += add[j]
    for x in exposures:
        out[x.key].mul_(x.fill_factor)
    out["gt"].mul_(ref.fill_factor)
    return out
