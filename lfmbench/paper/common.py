"""What the paper figures share: the figure scene files and sub-corpora (:data:`CONFIG_DIR`, :data:`RENDERS`),
the display of a capture (mu-law tone curve, zoom boxes, arrows) and saving a figure (torch and matplotlib are
imported inside the functions)."""
from __future__ import annotations

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


class FigureInputError(ValueError):
    """Bad input of ``lfmbench paper-figures`` (the message names the argument)."""


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
