"""Fig. 7 of the ISET-LFM paper: rolling-shutter banding of a static scene, all vehicle lights synchronised
(:func:`build_fig7`, :func:`fig7`)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfmbench.paper.common import FigureInputError, _arrow, _batch, _box_union, _corpus, _display_scale, _object_kinds, _params, _plt, _rect, _save, _signal_box, _tonemap, _vehicle_lights
from lfmbench.paper.pwm_choices import FIG7_PWM, fig7_phases, row_exposure


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
