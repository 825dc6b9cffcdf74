"""Reproductions of the ISET-LFM paper's Figs. 3-7 with lfmbench (``lfmbench paper-figures``).

- Fig. 3: Phi[n] at 30 fps for 5 ms and 11.11 ms exposures (:mod:`lfmbench.paper.fig3`; no render).
- Fig. 4: a two-frame sequence (60 fps, 60 m/s, global shutter): the 5 ms LPD is sharp but a car's tail and
  brake lights vanish in one frame; the 11.11 ms SPD is steady but motion-blurred.
- Fig. 5: the simple (upstream input-referred) fusion prefers the unsaturated LPD, so the dropout of a light
  caught OFF propagates into the HDR output.
- Fig. 6: where a fusion takes the SPD next to sharp LPD content, the elongated SPD trail is attached to the
  sharp LPD head: a non-physical comet.
- Fig. 7: rolling-shutter banding of a static scene, single-exposure sensor, all vehicle lights synchronised
  at 105 Hz, D = 0.2: (a) a dark band above the tail lights, (b) the motorcycle's light occluded.

The figures of Figs. 4-7 are made from the paper-figure corpus (``lfmbench paper-figures --render --corpus
DIR`` renders the scene files of ``lfmbench/configs/paper_figures/`` into ``DIR/fig4_6`` and ``DIR/fig7``) or,
for a quick look, from any corpus (the scene and the lights are then picked automatically). Every figure goes
through the public functional core (:meth:`lfmbench.datasets.LFMCaptureDataset.simulate`, the registered
baselines) with PWM parameters chosen here (:func:`dropout_phase`, :func:`fig7_phases`), so it shows exactly
what a benchmark sample can contain.

This module is imported by the ``lfmbench`` CLI: torch, matplotlib and the dataset are imported inside the
functions only.
"""
from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np


#: Directory of the figure scene files and render profiles.
CONFIG_DIR = Path(__file__).resolve().parent.parent / "configs" / "paper_figures"
#: Sub-corpus name, scene file and render profile of each rendered figure scene.
RENDERS = {"fig4_6": ("fig4_6_scene.json", "fig4_6_render.yaml"),
           "fig7": ("fig7_scene.json", "fig7_render.yaml")}
#: Figures that ``--fig`` accepts.
FIGURES = ("3", "4", "5", "6", "7", "all")
#: mu of the mu-law display tone curve.
MU = 5000.0
#: PWM of the light that drops out (Figs. 4, 5): 100 Hz, D = 0.2 (2 ms ON, 8 ms OFF > the 5 ms LPD exposure).
DROPOUT_PWM = (100.0, 0.2)
#: PWM of the second dropout (Fig. 5, yellow): 95 Hz, D = 0.25.
DROPOUT2_PWM = (95.0, 0.25)
#: PWM of the comet light (Fig. 6): 90 Hz, D = 0.5 (5.6 ms ON: a long SPD trail).
COMET_PWM = (90.0, 0.5)
#: Paper ranges of the other vehicle lights: f in [90, 110] Hz, D in [0.1, 0.5].
FREQ_RANGE_HZ, DUTY_RANGE = (90.0, 110.0), (0.1, 0.5)
#: Fig. 7: all vehicle LEDs synchronised at 105 Hz, D = 0.2 (the paper's values).
FIG7_PWM = (105.0, 0.2)


class FigureInputError(ValueError):
    """Bad input of ``lfmbench paper-figures`` (the message names the argument)."""


# ------------------------------------------------------------------------------------------ PWM choices
def dropout_phase(freq_hz: float, duty: float, off_frame: int, frames: int, fps: float, lpd_start_s: float,
                  short_s: float, steps: int = 2000) -> float:
    """Phase (s, a rising edge after the start of frame 0) that puts a PWM light OFF for the whole short
    exposure of frame ``off_frame`` and ON for as much as possible of the other frames' short exposures.

    Global shutter: frame n's LPD window is ``[n / fps + lpd_start_s, + short_s)`` (s). Among the phases on a
    grid of ``steps`` points over one period whose ``off_frame`` window holds no ON time, the one with the
    largest margin to the nearest pulse edge is taken (ties: most ON time in the other frames).

    Args:
        freq_hz: PWM frequency (Hz). duty: duty cycle (1). off_frame: frame index (0-based) to put OFF.
        frames: frames in the sequence. fps: frame rate (1/s). lpd_start_s: LPD window start in a frame (s).
        short_s: LPD exposure (s).

    Returns:
        The phase in s, in [0, 1 / freq_hz).

    Raises:
        ValueError: no phase puts the light OFF (the OFF time ``(1 - duty) / freq_hz`` is shorter than ``short_s``).
    """
    from lfmbench.flicker import pwm_exposure

    T = 1.0 / freq_hz
    if (1.0 - duty) * T <= short_s:
        raise ValueError(f"duty {duty} at {freq_hz} Hz: OFF time {(1 - duty) * T * 1e3:.2f} ms is not longer than "
                         f"the short exposure {short_s * 1e3:.2f} ms; no phase can hide the light")
    phases = np.arange(steps) * (T / steps)
    starts = np.arange(frames) / fps + lpd_start_s                              # (F,) s
    phi = pwm_exposure(starts[None, :] - phases[:, None], short_s, T, duty)     # (steps, F) s of ON time
    off = phi[:, off_frame] == 0.0
    # margin: how far the phase can move either way and keep the window dark
    margin = np.zeros(steps)
    for i in np.flatnonzero(off):
        d = 1
        while d < steps // 2 and off[(i + d) % steps] and off[(i - d) % steps]:
            d += 1
        margin[i] = d
    others = np.delete(phi, off_frame, axis=1).min(axis=1) if frames > 1 else np.zeros(steps)
    score = np.where(off, margin * steps + others / (duty * T + 1e-30), -np.inf)
    return float(phases[int(np.argmax(score))])


def row_exposure(rows, phase_s: float, freq_hz: float, duty: float, lpd_start_s: float, short_s: float,
                 line_time_s: float) -> np.ndarray:
    """ON time (s) of a PWM light in each row's short exposure under a rolling shutter (frame 0).

    Row r opens at ``lpd_start_s + r * line_time_s`` (s). rows: (R,) row indices. Returns (R,) s.
    """
    from lfmbench.flicker import pwm_exposure

    rows = np.asarray(rows, dtype=np.float64)
    return np.asarray(pwm_exposure(lpd_start_s + rows * line_time_s - phase_s, short_s, 1.0 / freq_hz, duty))


def fig7_phases(upper_rows: tuple[int, int], lower_rows: tuple[int, int], target_rows: tuple[int, int],
                freq_hz: float, duty: float, lpd_start_s: float, short_s: float, line_time_s: float
                ) -> tuple[float, float]:
    """Phases (s) of Fig. 7 for a rolling shutter (rows open ``line_time_s`` apart).

    Phase A puts the start of the lit band of rows (E > 0) half-way between the ``upper_rows`` (e.g. high-mount
    brake lights, then dark) and the ``lower_rows`` (tail lights, then lit): a dark band above the tail
    lights. Phase B starts the lit band just below ``target_rows`` (the motorcycle's light), so its rows,
    ending ``target_rows[1]`` (exclusive), hold no ON time at all.

    Args:
        upper_rows, lower_rows, target_rows: (first, last + 1) row ranges (px). freq_hz (Hz), duty (1).
        lpd_start_s: row 0's window start in the frame (s). short_s: exposure (s). line_time_s: row delay (s).

    Returns:
        ``(phase_a, phase_b)`` in s, each in [0, 1 / freq_hz).
    """
    T = 1.0 / freq_hz
    # a row's window [s, s + te) first touches the pulse [phase, phase + DT) when s = phase - te: rows opening
    # at or before that (mod T, back to the previous pulse's end) are dark
    edge_a = 0.5 * (upper_rows[1] - 1 + lower_rows[0])
    phase_a = lpd_start_s + edge_a * line_time_s + short_s
    phase_b = lpd_start_s + (target_rows[1] - 1 + 0.5) * line_time_s + short_s
    return phase_a % T, phase_b % T


# ------------------------------------------------------------------------------------------ corpus, display
def _corpus(corpus: str | Path, name: str) -> tuple[Path, str | None]:
    """The corpus directory of figure scene ``name`` (``DIR/name`` if rendered there, else ``DIR``) and the
    scene id to use (None: pick one)."""
    root = Path(corpus)
    sub = root / name
    if (sub / "manifest.json").is_file():
        return sub, f"paper_{name}"
    if (root / "manifest.json").is_file():
        return root, None
    raise FigureInputError(f"--corpus {root}: no lfmbench corpus there (no manifest.json in {root} or {sub}); "
                           f"render it with `lfmbench paper-figures --render --corpus {root}`")


def _tonemap(mosaic, cfa, peak: float, wb) -> np.ndarray:
    """(1, H, W) mosaic in e- -> (H, W, 3) display RGB in [0, 1]: kornia demosaic, white-balance gains ``wb``
    (3,), mu-law on x / ``peak`` (e-)."""
    import torch
    from kornia.color import raw_to_rgb

    rgb = raw_to_rgb(mosaic[None].float().clamp_min(0), cfa)[0] * wb[:, None, None]
    t = torch.log1p(MU * (rgb / peak).clamp(0, 1)) / np.log1p(MU)
    return t.permute(1, 2, 0).numpy()


def _display_scale(gt, cfa) -> tuple[float, object]:
    """Peak (99.9th percentile of the white-balanced truth, e-) and grey-world gains (3,) from the truth
    ``gt`` (1, H, W) e-."""
    import torch
    from kornia.color import raw_to_rgb

    rgb = raw_to_rgb(gt[None].float().clamp_min(0), cfa)[0]
    med = rgb.flatten(1).median(dim=1).values.clamp_min(1e-6)
    wb = med[1] / med
    peak = float(torch.quantile((rgb * wb[:, None, None]).flatten()[::7], 0.999).clamp_min(1.0))
    return peak, wb


def _batch(sample: dict) -> dict:
    import torch

    b = {k: (v[None] if isinstance(v, torch.Tensor) else v) for k, v in sample.items() if k != "meta"}
    b["meta"] = {k: ([v] if not isinstance(v, torch.Tensor) else v[None]) for k, v in sample["meta"].items()}
    return b


def _params(pwm: dict) -> dict:
    """light id -> (freq Hz, duty, phase s) as the dataset's PWM dicts."""
    return {int(i): {"period_s": 1.0 / f, "duty": float(d), "phase_s": float(p) % (1.0 / f), "rise_s": 0.0,
                     "fall_s": 0.0, "freq_hz": float(f)} for i, (f, d, p) in pwm.items()}


def _box_union(boxes) -> tuple[int, int, int, int]:
    boxes = list(boxes)
    return (min(b[0] for b in boxes), min(b[1] for b in boxes), max(b[2] for b in boxes), max(b[3] for b in boxes))


def _signal_box(rates, box, frac: float = 0.2) -> tuple[int, int, int, int]:
    """Tight (y0, x0, y1, x1) box (px) of the pixels of a light layer ``rates`` (K, h, w) e-/s placed at ``box``
    whose time-summed signal exceeds ``frac`` of its maximum."""
    s = np.asarray(rates.sum(0))
    ys, xs = np.nonzero(s > frac * s.max()) if s.max() > 0 else (np.array([0]), np.array([0]))
    return box[0] + int(ys.min()), box[1] + int(xs.min()), box[0] + int(ys.max()) + 1, box[1] + int(xs.max()) + 1


def _zoom(box, H: int, W: int, aspect: float = 1.6, pad: float = 1.0, min_h: int = 24) -> tuple[slice, slice]:
    """Rows and columns (slices) of a zoom window of aspect w/h around ``box`` (y0, x0, y1, x1), padded by
    ``pad`` times the box size on each side, clipped to the H x W image."""
    y0, x0, y1, x1 = box
    h = max(min_h, int((y1 - y0) * (1 + 2 * pad)))
    w = max(int((x1 - x0) * (1 + 2 * pad)), int(h * aspect))
    h = max(h, int(w / aspect))
    h, w = min(h, H), min(w, W)
    cy, cx = (y0 + y1) // 2, (x0 + x1) // 2
    ya = int(np.clip(cy - h // 2, 0, H - h))
    xa = int(np.clip(cx - w // 2, 0, W - w))
    return slice(ya, ya + h), slice(xa, xa + w)


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _arrow(ax, box, color: str, ys: slice | None = None, xs: slice | None = None, from_side: str = "left") -> None:
    """Draw an arrow pointing at ``box`` (y0, x0, y1, x1, image px) in axes showing the window ys, xs."""
    oy = ys.start if ys is not None else 0
    ox = xs.start if xs is not None else 0
    y = (box[0] + box[2]) / 2 - oy
    x = (box[1] if from_side == "left" else box[3]) - ox
    h = (ys.stop - ys.start) if ys is not None else 100
    d = -0.22 * h if from_side == "left" else 0.22 * h
    ax.annotate("", xy=(x + (-1.0 if from_side == "left" else 1.0), y), xytext=(x + d, y - 0.18 * h),
                arrowprops={"arrowstyle": "-|>", "color": color, "lw": 2.0})


def _rect(ax, ys: slice, xs: slice, color: str = "cyan", lw: float = 1.2) -> None:
    import matplotlib.patches as mpatches

    ax.add_patch(mpatches.Rectangle((xs.start - 0.5, ys.start - 0.5), xs.stop - xs.start, ys.stop - ys.start,
                                    fill=False, ec=color, lw=lw))


def _save(fig, path: Path, colors: int = 256) -> Path:
    """Write ``fig`` as a PNG at 100 dpi, quantised to ``colors`` palette colours (the noisy captures would
    otherwise make files of several MB), atomically; closes the figure and returns ``path``."""
    import io

    from PIL import Image

    from lfmbench.fileio import atomic_write_bytes

    plt = _plt()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    img = Image.open(io.BytesIO(buf.getvalue())).convert("RGB").quantize(colors, method=Image.Quantize.MEDIANCUT)
    out = io.BytesIO()
    img.save(out, format="PNG", optimize=True)
    atomic_write_bytes(path, out.getvalue())
    return Path(path)


def _finish(fig, title: str, path: Path, top: float, bottom: float = 0.01, right: float = 0.995) -> Path:
    """A figure of Figs. 4-6: every axis off, the caption above (fontsize 10.5), tight margins, saved (:func:`_save`)."""
    for ax in fig.axes:
        ax.set_axis_off()
    fig.suptitle(title, fontsize=10.5)
    fig.subplots_adjust(left=0.005, right=right, top=top, bottom=bottom)
    return _save(fig, path)


# ------------------------------------------------------------------------------------------ Figs. 4-6
@dataclass
class Sequence46:
    """The simulated three-frame sequence of Figs. 4-6 and the choices behind it.

    Attributes:
        scene_id, meta: the scene. sample: the dataset sample ((F, 1, H, W) e- captures). fused: method name ->
        (F, 1, H, W) e-. pwm: light id -> (freq Hz, duty, phase s). dropout, dropout2, comet: (instance id,
        light ids, (y0, x0, y1, x1) signal box px in the off / shown frame, frame index). cfa, peak, wb:
        display settings. lpd_start_s: LPD window start in a frame (s). boxes: instance id -> per-frame
        (y0, x0, y1, x1) px of its lights (None where not visible). kinds: instance id -> object kind ("car",
        "motorcycle", ...; empty when the corpus's scene.json holds no objects).
    """

    scene_id: str
    meta: dict
    sample: dict
    fused: dict
    pwm: dict
    dropout: tuple
    dropout2: tuple | None
    comet: tuple | None
    cfa: object
    peak: float
    wb: object
    lpd_start_s: float
    boxes: dict
    kinds: dict


def _object_kinds(ds, sid: str) -> dict:
    """Object id -> kind from the corpus's copy of the scene file ({} for corpora whose scene.json has none)."""
    try:
        return {int(o["id"]): str(o["kind"]) for o in ds.corpus.scene(sid).get("objects", [])}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


def _vehicle_lights(ds, sid: str, frame: int) -> dict:
    """instance id -> list of (light id, (y0, x0, y1, x1) signal box px, LPD rate sum e-/s) of the flickering
    lights visible in ``frame``."""
    view = ds.scene(sid)
    layers = view.layers
    inst = {int(lt["id"]): int(lt.get("instance", -1)) for lt in view.lights}
    out: dict = {}
    for lid, _g, box, rates in layers.lights[frame]:
        lpd = rates["lpd"]
        tot = float(lpd.sum())
        if tot <= 0:
            continue
        out.setdefault(inst.get(int(lid), -1), []).append((int(lid), _signal_box(lpd, box), tot))
    return out


def build_sequence46(corpus: str | Path, seed: int = 0, noise: bool = True) -> Sequence46:
    """Simulate the Figs. 4-6 sequence on the paper-figure corpus (or any corpus with 3 frames).

    PWM: the vehicle whose lights carry the most LPD signal near the image centre drops out in frame 1
    (:data:`DROPOUT_PWM`, :func:`dropout_phase`); the vehicle whose lights move most on screen from frame 0 to
    1 relative to their size is the comet (:data:`COMET_PWM`, one pulse ending as frame 1's SPD window closes,
    so the LPD sees its start only); a third vehicle drops out
    in frame 2 (:data:`DROPOUT2_PWM`); every other flickering light gets f, D drawn from the paper's ranges
    with a random phase (``seed``). All lights of one vehicle share one PWM.
    """
    from lfmbench.baselines import get_method
    from lfmbench.datasets import LFMCaptureDataset

    root, sid = _corpus(corpus, "fig4_6")
    ds = LFMCaptureDataset(root, split="all", frames=3, noise=noise,
                           outputs=("raw", "input_referred", "saturated", "gt"))
    if sid is None or sid not in ds.scene_ids:
        def energy(s):
            return max((t for v in _vehicle_lights(ds, s, 1).values() for _i, _b, t in v), default=0.0)
        sid = max(ds.scene_ids, key=energy)
    meta = ds.corpus.meta(sid)
    W, fps = meta["width"], float(meta["fps"])
    tm = meta["timing"]
    ts, tl = float(tm["short_exposure_s"]), float(tm["long_exposure_s"])
    a0 = (tl - ts) / 2
    veh = _vehicle_lights(ds, sid, 1)
    if not veh:
        raise FigureInputError(f"--corpus {root}: scene {sid} has no flickering light in frame 1")
    tot = {i: sum(t for _l, _b, t in v) for i, v in veh.items()}

    def centrality(i):
        b = _box_union(bb for _l, bb, _t in veh[i])
        cx = (b[1] + b[3]) / 2 / W
        return tot[i] * (1.0 - abs(cx - 0.5))

    veh0 = _vehicle_lights(ds, sid, 0)

    def sweep(i):  # image motion of the vehicle's lights from frame 0 to 1 over their size (px / px)
        if not veh0.get(i):
            return 0.0
        a = _box_union(bb for _l, bb, _t in veh0[i])
        b = _box_union(bb for _l, bb, _t in veh[i])
        shift = np.hypot((b[0] + b[2] - a[0] - a[2]) / 2, (b[1] + b[3] - a[1] - a[3]) / 2)
        return float(shift / np.sqrt(max((a[2] - a[0]) * (a[3] - a[1]), 1)))

    drop = max(veh, key=centrality)
    rest = [i for i in veh if i != drop]
    comet = max(rest, key=sweep) if rest else None
    rest2 = [i for i in rest if i != comet]
    drop2 = max(rest2, key=lambda i: tot[i]) if rest2 else None
    rng = np.random.default_rng(seed)
    pwm: dict = {}
    lights = ds.scene(sid).lights
    for lt in lights:
        if meta["groups"].get(lt["group"], {}).get("flicker"):
            T = 1.0 / rng.uniform(*FREQ_RANGE_HZ)
            pwm[int(lt["id"])] = (1.0 / T, float(rng.uniform(*DUTY_RANGE)), float(rng.uniform(0, T)))
    inst_of = {int(lt["id"]): int(lt.get("instance", -1)) for lt in lights}

    def set_inst(i, f, d, ph):
        for lid, inst in inst_of.items():
            if inst == i and lid in pwm:
                pwm[lid] = (f, d, ph)

    f, d = DROPOUT_PWM
    set_inst(drop, f, d, dropout_phase(f, d, 1, 3, fps, a0, ts))
    if drop2 is not None:
        f2, d2 = DROPOUT2_PWM
        set_inst(drop2, f2, d2, dropout_phase(f2, d2, 2, 3, fps, a0, ts))
    if comet is not None:
        fc, dc = COMET_PWM
        # one pulse that ends as frame 1's long exposure closes: the short exposure sees only its start (the
        # sharp head), the long one the rest of it too (one contiguous trail, no second pulse)
        set_inst(comet, fc, dc, (1.0 / fps + tl - dc / fc) % (1.0 / fc))
    s = ds.simulate(sid, _params(pwm), crop=None, noise_seed=seed)
    b = _batch(s)
    fused = {m: get_method(m)(b)[0] for m in ("upstream_saturated", "flicker_aware")}
    cfa = ds.preset.cfa.to_kornia()
    peak, wb = _display_scale(s["gt"][1], cfa)

    def info(i, frame):
        if i is None:
            return None
        v = _vehicle_lights(ds, sid, frame).get(i) or veh[i]
        return (i, [l_ for l_, _b, _t in v], _box_union(bb for _l, bb, _t in v), frame)

    per_frame = [_vehicle_lights(ds, sid, f) for f in range(3)]
    boxes = {i: [(_box_union(bb for _l, bb, _t in pf[i]) if pf.get(i) else None) for pf in per_frame]
             for i in (drop, drop2, comet) if i is not None}
    return Sequence46(sid, meta, s, fused, pwm, info(drop, 1), info(drop2, 2), info(comet, 1), cfa, peak, wb, a0,
                      boxes, _object_kinds(ds, sid))


def _img(seq: Sequence46, key: str, frame: int) -> np.ndarray:
    x = seq.fused[key] if key in seq.fused else seq.sample[key]
    return _tonemap(x[frame], seq.cfa, seq.peak, seq.wb)


def fig4(corpus: str | Path, out_dir: str | Path, seq: Sequence46 | None = None) -> Path:
    """Fig. 4: frames 0 and 1, LPD (short) and SPD (long): full frame, zoom on the dropout vehicle and zoom on
    the fastest-moving (most blurred) vehicle.

    Writes ``out_dir/fig4_lpd_spd_sequence.png`` and returns its path.
    """
    plt = _plt()
    seq = seq or build_sequence46(corpus)
    H, W = seq.meta["height"], seq.meta["width"]
    f_hz, duty = DROPOUT_PWM
    ts, tl = seq.meta["timing"]["short_exposure_s"], seq.meta["timing"]["long_exposure_s"]
    drop = seq.dropout[0]
    moving = seq.comet[0] if seq.comet else None
    ncol = 3 if moving is not None else 2
    fig = plt.figure(figsize=(15.0, 13.6))
    gs = fig.add_gridspec(4, ncol, width_ratios=[W / H, 1.25, 1.25][:ncol], wspace=0.03, hspace=0.13)
    rows = [("lpd_lcg_e", 0, f"LPD (short, {ts * 1e3:.2f} ms)"), ("lpd_lcg_e", 1, f"LPD (short, {ts * 1e3:.2f} ms)"),
            ("spd_e", 0, f"SPD (long, {tl * 1e3:.2f} ms)"), ("spd_e", 1, f"SPD (long, {tl * 1e3:.2f} ms)")]
    for r, (key, frame, name) in enumerate(rows):
        img = _img(seq, key, frame)
        ax = fig.add_subplot(gs[r, 0])
        ax.imshow(img, interpolation="nearest")
        ax.set_title(f"{name}, frame {frame}", fontsize=10)
        zooms = [(drop, "cyan", seq.kinds.get(drop, "vehicle")), (moving, "yellow", seq.kinds.get(moving, "vehicle"))]
        for c, (inst, color, what) in enumerate(zooms[:ncol - 1]):
            box = seq.boxes[inst][frame] or seq.boxes[inst][1]
            ys, xs = _zoom(box, H, W, pad=0.6 if c == 0 else 1.0, aspect=1.25, min_h=40)
            _rect(ax, ys, xs, color)
            z = fig.add_subplot(gs[r, c + 1])
            z.imshow(img[ys, xs], interpolation="nearest")
            if c == 0 and key == "lpd_lcg_e":
                _arrow(z, box, "cyan", ys, xs)
            note = ": its lights OFF" if (c == 0 and key == "lpd_lcg_e" and frame == 1) else ""
            if c == 1:
                note = ": sharp" if key == "lpd_lcg_e" else ": smeared over 11.1 ms"
            z.set_title(f"zoom, {what}{note}", fontsize=10)
    cam = seq.meta["camera"]
    title = (f"Fig. 4: two-frame sequence, {seq.meta['fps']:g} fps, ego {cam.get('speed_mps', 0):.0f} m/s, "
             f"global shutter (scene {seq.scene_id}).\nThe short LPD is sharp, but the braking car's lights "
             f"(cyan arrows; {f_hz:g} Hz, D = {duty:g}) are OFF for all of frame 1's exposure.\nThe long SPD "
             f"holds every light in every frame but smears what moves across the image (the "
             f"{seq.kinds.get(moving, 'vehicle')} near the edge, yellow). mu-law display, one scale.")
    return _finish(fig, title, Path(out_dir) / "fig4_lpd_spd_sequence.png", top=0.925, bottom=0.005)


def fig5(corpus: str | Path, out_dir: str | Path, seq: Sequence46 | None = None) -> Path:
    """Fig. 5: frames 0-2 of the LPD, the simple (upstream) fusion and the truth, zoomed on the dropouts.

    Writes ``out_dir/fig5_dropout_fusion.png`` and returns its path.
    """
    plt = _plt()
    seq = seq or build_sequence46(corpus)
    H, W = seq.meta["height"], seq.meta["width"]
    boxes = [seq.dropout[2]] + ([seq.dropout2[2]] if seq.dropout2 else [])
    ys, xs = _zoom(_box_union(boxes), H, W, pad=0.35, aspect=1.8)
    rows = [("lpd_lcg_e", "LPD (short exposure)"), ("upstream_saturated", "simple fusion (upstream)"),
            ("gt", "ground truth")]
    fig = plt.figure(figsize=(16.0, 9.6))
    gs = fig.add_gridspec(3, 4, width_ratios=[1, 1, 1, 1.25], wspace=0.04, hspace=0.14)
    for r, (key, name) in enumerate(rows):
        for frame in range(3):
            ax = fig.add_subplot(gs[r, frame])
            ax.imshow(_img(seq, key, frame)[ys, xs], interpolation="nearest")
            note = ""
            if key != "gt":
                if frame == seq.dropout[3]:
                    _arrow(ax, seq.dropout[2], "cyan", ys, xs)
                    note = ": car's lights OFF"
                if seq.dropout2 and frame == seq.dropout2[3]:
                    _arrow(ax, seq.dropout2[2], "yellow", ys, xs, from_side="right")
                    note = ": lights OFF"
            ax.set_title(f"{name}, frame {frame}{note}", fontsize=10)
        ax = fig.add_subplot(gs[r, 3])
        ax.imshow(_img(seq, key, 1), interpolation="nearest")
        _rect(ax, ys, xs)
        ax.set_title(f"{name}, frame 1 (full frame)", fontsize=10)
    f1, d1 = DROPOUT_PWM
    txt = (f"Fig. 5: the simple fusion prefers the unsaturated LPD, so a light caught OFF by the short exposure is "
           f"extinguished in the HDR output. Cyan: brake and tail lights ({f1:g} Hz, D = {d1:g}) OFF in frame 1")
    if seq.dropout2:
        f2, d2 = DROPOUT2_PWM
        txt += f";\nyellow: another car's tail lights ({f2:g} Hz, D = {d2:g}) OFF in frame 2"
    txt += (f". Scene {seq.scene_id}, {seq.meta['camera'].get('speed_mps', 0):.0f} m/s, {seq.meta['fps']:g} fps; "
            "mu-law display.")
    return _finish(fig, txt, Path(out_dir) / "fig5_dropout_fusion.png", top=0.91)


def fig6(corpus: str | Path, out_dir: str | Path, seq: Sequence46 | None = None) -> Path:
    """Fig. 6: frame 1 of the comet vehicle: LPD, SPD, both fusions and the truth (zoom), plus the full frame.

    Writes ``out_dir/fig6_comet.png`` and returns its path.
    """
    plt = _plt()
    seq = seq or build_sequence46(corpus)
    if seq.comet is None:
        raise FigureInputError("--corpus: the scene has no second flickering vehicle to show the comet with")
    H, W = seq.meta["height"], seq.meta["width"]
    frame = seq.comet[3]
    ys, xs = _zoom(seq.comet[2], H, W, pad=0.5, aspect=1.3, min_h=40)
    panels = [("lpd_lcg_e", "LPD (short)"), ("spd_e", "SPD (long)"),
              ("upstream_saturated", "simple fusion (upstream): LPD kept"),
              ("flicker_aware", "flicker-aware fusion: the comet"), ("gt", "ground truth")]
    fig = plt.figure(figsize=(16.0, 7.8))
    gs = fig.add_gridspec(2, 5, height_ratios=[1, 1.05], wspace=0.04, hspace=0.14)
    for c, (key, name) in enumerate(panels):
        ax = fig.add_subplot(gs[0, c])
        ax.imshow(_img(seq, key, frame)[ys, xs], interpolation="nearest")
        ax.set_title(name, fontsize=10)
    ax = fig.add_subplot(gs[1, 0:2])
    ax.imshow(_img(seq, "spd_e", frame), interpolation="nearest")
    _rect(ax, ys, xs)
    ax.set_title(f"SPD (long), frame {frame} (full frame)", fontsize=10)
    # where the flicker-aware fusion took the SPD: its output differs from the exposure-corrected LPD fusion
    from lfmbench.baselines import get_method

    base = get_method("saturated_exposure_corrected")(_batch(seq.sample))[0]
    took = (seq.fused["flicker_aware"][frame, 0] != base[frame, 0]).numpy()
    ax = fig.add_subplot(gs[1, 2])
    show = _img(seq, "lpd_lcg_e", frame)[ys, xs] * 0.6
    show[took[ys, xs]] = (1.0, 0.0, 1.0)
    ax.imshow(show, interpolation="nearest")
    ax.set_title("flicker-aware: pixels taken\nfrom the SPD (magenta) on the LPD", fontsize=10)
    ax = fig.add_subplot(gs[1, 3:5])
    ax.imshow(_img(seq, "flicker_aware", frame), interpolation="nearest")
    _rect(ax, ys, xs)
    ax.set_title(f"flicker-aware fusion, frame {frame} (full frame)", fontsize=10)
    fc, dc = COMET_PWM
    title = (f"Fig. 6: motion-flicker trade-off, frame {frame}, the {seq.kinds.get(seq.comet[0], 'vehicle')} "
             f"near the image edge "
             f"({fc:g} Hz, D = {dc:g}; one pulse, ending as the long exposure closes).\n"
             f"The LPD records a short sharp head, the SPD a trail smeared over its 11.1 ms. A fusion that takes "
             f"the SPD where the LPD reads below it (flicker-aware) pastes\nthe trail onto the sharp LPD head: a "
             f"comet that no exposure of the scene shows. The simple fusion keeps the unsaturated LPD here. "
             f"Scene {seq.scene_id}, {seq.meta['camera'].get('speed_mps', 0):.0f} m/s.")
    return _finish(fig, title, Path(out_dir) / "fig6_comet.png", top=0.87)


# ------------------------------------------------------------------------------------------ Fig. 7
@dataclass
class Setup7:
    """Choices and images of Fig. 7 (see :func:`build_fig7`).

    Attributes:
        scene_id, meta: the scene. line_time_s, short_s, lpd_start_s: row delay, exposure, row 0's window start
        in the frame (s). phase_a, phase_b: PWM phases (s). upper_rows, lower_rows, target_rows: (first, last + 1)
        image rows (px) of the high-mount brake lights, of the other lights and of the occluded target.
        target_box, zoom_box: (y0, x0, y1, x1) px. light_ids: the synchronised lights; target_ids: the occluded
        ones; target_name: what they are ("the motorcycle" or "the brightest light"). images: "mean", "A", "B" ->
        (1, H, W) e- (the truth; the single-exposure captures). cfa, peak, wb: display settings.
    """

    scene_id: str
    meta: dict
    line_time_s: float
    short_s: float
    lpd_start_s: float
    phase_a: float
    phase_b: float
    upper_rows: tuple
    lower_rows: tuple
    target_rows: tuple
    target_box: tuple
    zoom_box: tuple
    light_ids: list
    target_ids: list
    target_name: str
    images: dict
    cfa: object
    peak: float
    wb: object


def build_fig7(corpus: str | Path, seed: int = 0, line_time_s: float | None = None, noise: bool = True) -> Setup7:
    """Simulate Fig. 7: every flickering light at :data:`FIG7_PWM` with one phase, rolling shutter, the LPD
    alone as a single-exposure sensor (HCG, LCG where HCG saturates: the ``lpd_only`` baseline).

    The target of phase B (occluded) is the motorcycle's light when the scene has one, else the brightest
    light; its rows include its halo (1 % of its peak). Phase A starts the lit band of rows half-way between
    the high-mount brake lights (or the top third of the lights) and the other lights below them.
    ``line_time_s`` defaults to the corpus's (30 us in the paper-figure corpus: a 1080-row sensor at 10 us per
    row rendered with 360 rows); on another corpus, the largest line time its rendered bins cover.
    """
    from lfmbench.baselines import get_method
    from lfmbench.datasets import LFMCaptureDataset

    root, sid = _corpus(corpus, "fig7")
    probe = LFMCaptureDataset(root, split="all", frames=1, outputs=("gt",))
    if sid is None or sid not in probe.scene_ids:
        sid = max(probe.scene_ids, key=lambda s: len(_vehicle_lights(probe, s, 0)))
    meta = probe.corpus.meta(sid)
    H = meta["height"]
    tm = meta["timing"]
    if line_time_s is None:
        line_time_s = float(tm.get("line_time_s", 0.0)) if sid.startswith("paper_") else \
            0.98 * (tm["capture_window_s"] - tm["long_exposure_s"]) / max(H - 1, 1)
    ds = LFMCaptureDataset(root, split="all", frames=1, noise=noise, shutter="rolling", line_time_s=line_time_s,
                           outputs=("raw", "input_referred", "saturated", "gt"))
    ts, tl = float(tm["short_exposure_s"]), float(tm["long_exposure_s"])
    a0 = (tl - ts) / 2
    view = ds.scene(sid)
    lights = {int(lt["id"]): lt for lt in view.lights}
    layers = view.layers
    vis = [(int(lid), _signal_box(r["lpd"], box), float(r["lpd"].sum()), _signal_box(r["lpd"], box, 0.01))
           for lid, _g, box, r in layers.lights[0] if float(r["lpd"].sum()) > 0]
    if not vis:
        raise FigureInputError(f"--corpus {root}: scene {sid} has no flickering light")
    objs = _object_kinds(ds, sid)
    kind_of = {lid: objs.get(lt.get("instance"), "") for lid, lt in lights.items()}
    moto = [v for v in vis if kind_of.get(v[0]) == "motorcycle"]
    target = moto or [max(vis, key=lambda v: v[2])]
    tbox = _box_union(v[3] for v in target)
    tids = {v[0] for v in target}
    others = [v for v in vis if v[0] not in tids and v[2] > 1e-3 * max(t[2] for t in target)]
    hi = [v for v in others if lights[v[0]].get("kind") == "brake" and lights[v[0]].get("size", [0, 1])[0] >= 0.4]
    if not hi and others:
        cut = np.percentile([(v[1][0] + v[1][2]) / 2 for v in others], 34)
        hi = [v for v in others if (v[1][0] + v[1][2]) / 2 <= cut]
    lo = [v for v in others if v not in hi] or target
    up_rows = (min(v[1][0] for v in hi), max(v[1][2] for v in hi)) if hi else (0, 1)
    lo_rows = (min(v[1][0] for v in lo), max(v[1][2] for v in lo))
    f_hz, duty = FIG7_PWM
    pa, pb = fig7_phases(up_rows, lo_rows, (tbox[0], tbox[2] + 1), f_hz, duty, a0, ts, line_time_s)
    ids = [lid for lid, lt in lights.items() if meta["groups"].get(lt["group"], {}).get("flicker")]
    lpd_only = get_method("lpd_only")
    images = {}
    for name, ph in (("mean", 0.0), ("A", pa), ("B", pb)):
        s = ds.simulate(sid, _params({i: (f_hz, duty, ph) for i in ids}), crop=None, noise_seed=seed)
        images[name] = s["gt"][0] if name == "mean" else lpd_only(_batch(s))[0, 0]
    cfa = ds.preset.cfa.to_kornia()
    peak, wb = _display_scale(images["mean"], cfa)
    # zoom: the target and the vehicle with the most light signal (the nearest car)
    inst = {lid: lt.get("instance", -1) for lid, lt in lights.items()}
    sig: dict = {}
    for v in others:
        sig[inst[v[0]]] = sig.get(inst[v[0]], 0.0) + v[2]
    near = max(sig, key=sig.get) if sig else None
    zoom = _box_union([tbox] + [v[1] for v in others if inst[v[0]] == near])
    return Setup7(sid, meta, float(line_time_s), ts, a0, pa, pb, up_rows, lo_rows, (tbox[0], tbox[2] + 1), tbox,
                  zoom, ids, sorted(tids), "the motorcycle" if moto else "the brightest light", images, cfa, peak, wb)


def fig7(corpus: str | Path, out_dir: str | Path, setup: Setup7 | None = None) -> Path:
    """Fig. 7: the truth and phases A and B, full frame and zoom, and the exact per-row LED exposure.

    Writes ``out_dir/fig7_rolling_shutter.png`` and returns its path.
    """
    plt = _plt()
    st = setup or build_fig7(corpus)
    H, W = st.meta["height"], st.meta["width"]
    f_hz, duty = FIG7_PWM
    rows = np.arange(H)
    zb = st.zoom_box
    ys = slice(max(0, zb[0] - 14), min(H, zb[2] + 14))
    xs = slice(max(0, zb[1] - 24), min(W, zb[3] + 24))
    zr = (xs.stop - xs.start) / (ys.stop - ys.start)
    panels = [("mean", "ground truth (LEDs at their mean level)"),
              ("A", "(a) phase A: dark band above the tail lights"),
              ("B", f"(b) phase B: {st.target_name} is not recorded")]
    fig = plt.figure(figsize=(16.0, 10.0))
    gs = fig.add_gridspec(3, 3, width_ratios=[W / H, zr, 0.55], wspace=0.03, hspace=0.14)
    for r, (key, name) in enumerate(panels):
        img = _tonemap(st.images[key], st.cfa, st.peak, st.wb)
        ax = fig.add_subplot(gs[r, 0])
        ax.imshow(img, interpolation="nearest")
        _rect(ax, ys, xs)
        ax.set_title(name, fontsize=10)
        ax.set_axis_off()
        ax = fig.add_subplot(gs[r, 1])
        ax.imshow(img[ys, xs], interpolation="nearest")
        _arrow(ax, st.target_box, "yellow", ys, xs)
        ax.set_title(f"zoom (arrow: {st.target_name})", fontsize=10)
        ax.set_axis_off()
    ax = fig.add_subplot(gs[:, 2])
    for key, ph, col in (("A", st.phase_a, "tab:blue"), ("B", st.phase_b, "tab:orange")):
        e = row_exposure(rows, ph, f_hz, duty, st.lpd_start_s, st.short_s, st.line_time_s)
        ax.plot(e / (duty * st.short_s), rows, color=col, lw=2, label=f"phase {key}")
    ax.axhspan(st.upper_rows[0], st.upper_rows[1], color="cyan", alpha=0.35, label="high brake lights")
    ax.axhspan(st.target_rows[0], st.target_rows[1], color="gold", alpha=0.6, label=st.target_name.replace("the ", ""))
    ax.axhspan(st.lower_rows[0], st.lower_rows[1], color="red", alpha=0.15, label="other lights")
    ax.set_ylim(H, 0)
    ax.set_xlabel("LED exposure of the row / its mean", fontsize=10)
    ax.set_ylabel("image row", fontsize=10)
    ax.yaxis.set_label_position("right")
    ax.yaxis.tick_right()
    ax.legend(fontsize=8.5, loc="lower right")
    ax.tick_params(labelsize=9)
    fig.suptitle(f"Fig. 7: rolling-shutter banding, static scene, single exposure of {st.short_s * 1e3:g} ms, all "
                 f"vehicle lights synchronised at {f_hz:g} Hz, D = {duty:g}, line time {st.line_time_s * 1e6:.0f} us "
                 f"({H} rows; scene {st.scene_id}).\nPhase A = {st.phase_a * 1e3:.2f} ms, phase B = "
                 f"{st.phase_b * 1e3:.2f} ms (first rising edge after the frame start); right: the exact LED "
                 f"exposure of each row. mu-law display.", fontsize=10.5)
    fig.subplots_adjust(left=0.005, right=0.955, top=0.92, bottom=0.06)
    return _save(fig, Path(out_dir) / "fig7_rolling_shutter.png")


# ------------------------------------------------------------------------------------------ driver
def fig3(out_dir: str | Path) -> Path:
    """Fig. 3 (no corpus): ``out_dir/fig3_flicker.png``, 12 frames at 30 fps, 95 Hz, D = 0.2."""
    from lfmbench.paper.fig3 import plot_fig3

    return plot_fig3(Path(out_dir) / "fig3_flicker.png", frames=12)


def make_figures(fig: str, corpus: str | Path | None, out_dir: str | Path) -> list[Path]:
    """Write figure ``fig`` (one of :data:`FIGURES`) into ``out_dir``; returns the paths written.

    Raises:
        FigureInputError: unknown ``fig``, or a missing corpus for Figs. 4-7.
    """
    fig = str(fig)
    if fig not in FIGURES:
        raise FigureInputError(f"--fig must be one of {', '.join(FIGURES)}; got {fig!r}")
    out_dir = Path(out_dir)
    want = ["3", "4", "5", "6", "7"] if fig == "all" else [fig]
    if any(w != "3" for w in want) and corpus is None:
        raise FigureInputError(f"--corpus is needed for Fig. {fig} (only Fig. 3 is computed without a render)")
    paths = []
    seq = None
    for w in want:
        if w == "3":
            paths.append(fig3(out_dir))
        elif w in ("4", "5", "6"):
            seq = seq or build_sequence46(corpus)
            paths.append({"4": fig4, "5": fig5, "6": fig6}[w](corpus, out_dir, seq=seq))
        else:
            paths.append(fig7(corpus, out_dir))
    return paths


def make_all(corpus: str | Path, out_dir: str | Path) -> list[Path]:
    """Write every reproduced figure (Figs. 3-7) to ``out_dir`` and return the paths."""
    return make_figures("all", corpus, out_dir)


def render_commands(corpus: str | Path, workers: int = 1) -> list[list[str]]:
    """The ``lfmbench render`` command lines that render the paper-figure corpus into ``corpus`` (one
    sub-corpus per scene file: ``corpus/fig4_6``, ``corpus/fig7``); resumable: a finished scene is skipped."""
    root = Path(corpus)
    cmds = []
    for name, (scene, profile) in RENDERS.items():
        cmds.append([sys.executable, "-m", "lfmbench.cli", "render", "--out", str(root / name),
                     "--scene", str(CONFIG_DIR / scene), "--profile", str(CONFIG_DIR / profile),
                     "--workers", str(int(workers))])
    return cmds


def render_corpus(corpus: str | Path, workers: int = 1) -> None:
    """Run :func:`render_commands` (Mitsuba; about 1-3 min per scene on a CPU); raises ``RuntimeError`` naming
    the failed command."""
    for cmd in render_commands(corpus, workers):
        rc = subprocess.call(cmd)
        if rc != 0:
            raise RuntimeError(f"render failed (exit {rc}): {' '.join(cmd[2:])}")
