"""Reproductions of the ISET-LFM paper's figures with lfmbench (``lfmbench paper-figures``).

- Fig. 3: Phi[n] at 30 fps for 5 ms and 11.11 ms exposures (:mod:`lfmbench.flicker_report`).
- Figs. 4 and 6: the sharp but flickering LPD against the steady but blurred SPD, and the comet artefact of
  the input-referred fusion.
- Fig. 5: a light extinguished in the LPD capture of one frame propagates through the upstream fusion.
- Fig. 7: rolling-shutter banding of synchronised LEDs at D = 0.2, 105 Hz, including total occlusion.

Every figure is made from a rendered corpus through the public functional core
(:meth:`lfmbench.datasets.LFMCaptureDataset.simulate`, :func:`lfmbench.datasets.compose_frame`) with chosen PWM
parameters, so the figure shows exactly what a benchmark sample can contain.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from lfmbench.fileio import atomic_save_figure
from lfmbench.flicker_report import plot_fig3

MU = 5000.0


def _tonemap(mosaic: torch.Tensor, cfa, peak: float, wb: torch.Tensor) -> np.ndarray:
    """(1, H, W) mosaic in e- -> (H, W, 3) display RGB: kornia demosaic, grey-world gains, mu-law on x/peak."""
    from kornia.color import raw_to_rgb

    rgb = raw_to_rgb(mosaic[None].float().clamp_min(0), cfa)[0] * wb[:, None, None]
    t = torch.log1p(MU * (rgb / peak).clamp(0, 1)) / np.log1p(MU)
    return t.permute(1, 2, 0).numpy()


def _display_scale(gt: torch.Tensor, cfa) -> tuple[float, torch.Tensor]:
    """Peak (99.9th percentile of the truth, e-) and grey-world white-balance gains from the truth."""
    from kornia.color import raw_to_rgb

    rgb = raw_to_rgb(gt[None].float().clamp_min(0), cfa)[0]
    med = rgb.flatten(1).median(dim=1).values.clamp_min(1e-6)
    wb = med[1] / med
    peak = float(torch.quantile((rgb * wb[:, None, None]).flatten()[::7], 0.999).clamp_min(1.0))
    return peak, wb


def _brightest_light(ds, scene_id: str) -> tuple[int, tuple[int, int, int, int]]:
    """Id and frame-0 box of the flickering light with the most projected LPD signal."""
    layers = ds._layers(scene_id)
    best = max(layers.lights[0], key=lambda t: float(t[3]["lpd"].sum()))
    return best[0], best[2]


def _pick_scene(ds) -> str:
    """The scene whose flickering lights carry the most LPD signal in frame 0."""
    def energy(sid):
        ls = ds._layers(sid).lights[0]
        return max((float(t[3]["lpd"].sum()) for t in ls), default=0.0)
    return max(ds.scene_ids, key=energy)


def _zoom(box, H, W, size: int = 40) -> tuple[slice, slice]:
    y0, x0, y1, x1 = box
    cy, cx = (y0 + y1) // 2, (x0 + x1) // 2
    h = max(size, 3 * (y1 - y0))
    w = max(int(size * 1.6), 3 * (x1 - x0))
    ya = int(np.clip(cy - h // 2, 0, max(H - h, 0)))
    xa = int(np.clip(cx - w // 2, 0, max(W - w, 0)))
    return slice(ya, ya + h), slice(xa, xa + w)


def _params(light_ids, freq_hz: float, duty: float, phases) -> dict:
    T = 1.0 / freq_hz
    return {int(i): {"period_s": T, "duty": duty, "phase_s": float(p) % T, "rise_s": 0.0, "fall_s": 0.0,
                     "freq_hz": freq_hz} for i, p in zip(light_ids, phases)}


def _batch(sample: dict) -> dict:
    b = {k: (v[None] if isinstance(v, torch.Tensor) else v) for k, v in sample.items() if k != "meta"}
    b["meta"] = {k: ([v] if not isinstance(v, torch.Tensor) else v[None]) for k, v in sample["meta"].items()}
    return b


def fig_dropout_and_comet(corpus: str | Path, out_dir: str | Path, seed: int = 0) -> list[Path]:
    """Figs. 4-6: one light extinguished in frame 1 (90 Hz, D = 0.2: frames alternate by half a period)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lfmbench.baselines import get_method
    from lfmbench.datasets import LFMCaptureDataset

    out_dir = Path(out_dir)
    ds = LFMCaptureDataset(corpus, split="all", frames=3, outputs=("raw", "input_referred", "saturated", "gt"))
    sid = _pick_scene(ds)
    meta = ds.corpus.meta(sid)
    H, W = meta["height"], meta["width"]
    tm = meta["timing"]
    a0 = (tm["long_exposure_s"] - tm["short_exposure_s"]) / 2          # LPD window start of frame 0 (s)
    target, box = _brightest_light(ds, sid)
    ids = [int(lt["id"]) for lt in ds._lights(sid) if meta["groups"][lt["group"]].get("flicker")]
    rng = np.random.default_rng(seed)
    phases = {i: rng.uniform(0, 1 / 90) for i in ids}
    # the target's pulse starts 0.1 ms into frame 0's short window: ON in frames 0 and 2, OFF in frame 1
    phases[target] = a0 + 1e-4
    params = _params(list(phases), 90.0, 0.2, list(phases.values()))
    s = ds.simulate(sid, params, crop=None, noise_seed=seed)
    b = _batch(s)
    fused = {m: get_method(m)(b)[0] for m in ("upstream_saturated", "flicker_aware")}
    cfa = ds.preset.cfa.to_kornia()
    peak, wb = _display_scale(s["gt"][1], cfa)
    ys, xs = _zoom(box, H, W)
    cols = [("lpd_lcg_e", "LPD (short, LCG)"), ("spd_e", "SPD (long 11.1 ms)"),
            ("upstream_saturated", "upstream fusion"), ("flicker_aware", "flicker-aware fusion"),
            ("gt", "ground truth")]
    fig, axes = plt.subplots(4, len(cols), figsize=(3.0 * len(cols), 8.2))
    for c, (k, title) in enumerate(cols):
        img = fused[k] if k in fused else s[k]
        for r, f in enumerate(range(3)):
            axes[r, c].imshow(_tonemap(img[f], cfa, peak, wb)[ys, xs], interpolation="nearest")
            axes[r, c].set_title(f"{title}, frame {f}", fontsize=8)
        axes[3, c].imshow(_tonemap(img[1], cfa, peak, wb), interpolation="nearest")
        axes[3, c].add_patch(plt.Rectangle((xs.start, ys.start), xs.stop - xs.start, ys.stop - ys.start,
                                           fill=False, ec="cyan", lw=1))
        axes[3, c].set_title(f"{title}, frame 1 (full)", fontsize=8)
    for ax in axes.flat:
        ax.set_axis_off()
    fig.suptitle(f"Figs. 4-6: light {target} (90 Hz, D = 0.2) is OFF during frame 1's short exposure. The LPD is "
                 f"sharp but loses it, the SPD keeps it but blurs;\nthe upstream fusion propagates the dropout "
                 f"(Fig. 5) and mixes sharp LPD with the SPD trail (Fig. 6). Scene {sid}, "
                 f"{meta['camera'].get('speed_mps', 0):.0f} m/s; mu-law display", fontsize=8)
    fig.tight_layout()
    p = _save(fig, out_dir / "fig5_dropout_fusion.png")
    plt.close(fig)
    return [p]


def fig_rolling_shutter(corpus: str | Path, out_dir: str | Path, freq_hz: float = 105.0, duty: float = 0.2,
                        line_time_s: float | None = None) -> list[Path]:
    """Fig. 7: rolling-shutter banding of synchronised LEDs (all at ``freq_hz``, ``duty``, one phase).

    Only the short LPD exposure is shown (a single-exposure sensor, as in the paper). ``line_time_s`` defaults
    to the largest line time whose short windows stay inside the rendered capture window, so the banding
    spans many rows even on a small render.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lfmbench.datasets import LFMCaptureDataset, compose_frame
    from lfmbench.flicker import pwm_exposure

    out_dir = Path(out_dir)
    ds = LFMCaptureDataset(corpus, split="all", frames=1, outputs=("gt",))
    sid = _pick_scene(ds)
    meta = ds.corpus.meta(sid)
    H, W = meta["height"], meta["width"]
    tm = meta["timing"]
    ts, tl = tm["short_exposure_s"], tm["long_exposure_s"]
    a0 = (tl - ts) / 2
    if line_time_s is None:  # last row's short window must end inside the capture window
        line_time_s = 0.98 * (tm["capture_window_s"] - a0 - ts) / (H - 1)
    target, box = _brightest_light(ds, sid)
    layers = ds._layers(sid)
    ids = [t[0] for t in layers.lights[0]]
    T = 1.0 / freq_hz
    rows = np.arange(H)
    # phase B: the pulse ends just before the target's first row opens and the next starts after its last
    # row closes -> the light is not recorded at all; phase A: the pulse ends as the target's centre row opens
    # -> its lower half is dark (a band across the light)
    phase_b = a0 + box[0] * line_time_s - duty * T - 2e-5
    phase_a = a0 + ((box[0] + box[2]) // 2) * line_time_s - duty * T
    cfa = ds.preset.cfa.to_kornia()
    full = (0, 0, H, W)
    gt = compose_frame(layers, meta, 0, full, _params(ids, freq_hz, duty, [0.0] * len(ids)), {}, "rolling",
                       line_time_s)["gt"]
    peak, wb = _display_scale(gt[None], cfa)
    panels = [("ground truth (time-averaged LEDs)", gt)]
    fracs = []
    for name, ph in (("rolling shutter, phase A: banding", phase_a), ("phase B: light occluded", phase_b)):
        out = compose_frame(layers, meta, 0, full, _params(ids, freq_hz, duty, [ph] * len(ids)), {}, "rolling",
                            line_time_s)
        panels.append((name, out["lpd"]))
        fracs.append((name, pwm_exposure(a0 + rows * line_time_s - ph, ts, T, duty) / (duty * ts)))
    fig = plt.figure(figsize=(13, 3.6))
    gs = fig.add_gridspec(1, 4, width_ratios=[1, 1, 1, 0.45])
    for c, (name, img) in enumerate(panels):
        ax = fig.add_subplot(gs[0, c])
        ax.imshow(_tonemap(img[None], cfa, peak, wb), interpolation="nearest")
        ax.add_patch(plt.Rectangle((box[1] - 2, box[0] - 2), box[3] - box[1] + 4, box[2] - box[0] + 4,
                                   fill=False, ec="cyan", lw=0.8))
        ax.set_title(name, fontsize=8)
        ax.set_axis_off()
    ax = fig.add_subplot(gs[0, 3])
    for name, fr in fracs:
        ax.plot(fr, rows, label=name.split(":")[0].replace("rolling shutter, ", ""))
    ax.axhspan(box[0], box[2], color="cyan", alpha=0.3)
    ax.set_ylim(H, 0)
    ax.set_xlabel("LED exposure / mean", fontsize=8)
    ax.set_ylabel("row", fontsize=8)
    ax.legend(fontsize=7)
    ax.tick_params(labelsize=7)
    fig.suptitle(f"Fig. 7: rolling-shutter banding, all LEDs synchronised at {freq_hz:g} Hz, D = {duty:g}; "
                 f"short exposure {ts * 1e3:.2f} ms, line time {line_time_s * 1e6:.1f} us ({H} rows, scene {sid})",
                 fontsize=9)
    fig.tight_layout()
    p = _save(fig, out_dir / "fig7_rolling_shutter.png")
    plt.close(fig)
    return [p]


def _save(fig, path: Path) -> Path:
    return atomic_save_figure(fig, path, dpi=110)


def make_all(corpus: str | Path, out_dir: str | Path) -> list[Path]:
    """Write every reproduced figure to ``out_dir`` and return the paths."""
    out_dir = Path(out_dir)
    paths = [plot_fig3(out_dir / "fig3_flicker.png")]
    paths += fig_dropout_and_comet(corpus, out_dir)
    paths += fig_rolling_shutter(corpus, out_dir)
    return paths


def register(app) -> None:
    import typer

    @app.command("paper-figures")
    def paper_figures(corpus: Path = typer.Option(..., "--corpus", help="rendered corpus directory"),
                      out: Path = typer.Option(Path("docs/img"), "--out", help="directory for the PNG files")) -> None:
        """Reproduce the ISET-LFM paper's Figs. 3-7 from a corpus."""
        for p in make_all(corpus, out):
            typer.echo(f"wrote {p}")
