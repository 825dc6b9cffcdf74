"""Figs. 4-6 of the ISET-LFM paper: a two-frame sequence (:func:`build_sequence46`), the dropout of a light in the
LPD (:func:`fig4`) and in the simple fusion (:func:`fig5`), and the comet of a fusion that takes the SPD next to
sharp LPD content (:func:`fig6`)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfmbench.paper.common import FigureInputError, _arrow, _batch, _box_union, _corpus, _display_scale, _finish, _object_kinds, _params, _plt, _rect, _tonemap, _vehicle_lights, _zoom
from lfmbench.paper.pwm_choices import COMET_PWM, DROPOUT2_PWM, DROPOUT_PWM, DUTY_RANGE, FREQ_RANGE_HZ, dropout_phase


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
