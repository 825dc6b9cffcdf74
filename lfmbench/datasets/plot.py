"""A picture of one dataset sample: its captures, the ground truth and (optionally) methods' estimates, each
through the display ISP, frames side by side, the LED regions outlined (:func:`plot_sample`; also
``LFMCaptureDataset.plot`` and ``lfmbench plot``).

Every image is a (1, h, w) mosaic in the ``gt`` units (input-referred LPD-equivalent electrons over the short
exposure; the captures' ``<capture>_e`` outputs) and goes through the same ISP pipeline as the display-referred
metrics (:class:`lfmbench.isp.ISP`), with every statistic (white balance, tone curve) taken from the ground truth
of its frame (:meth:`lfmbench.isp.ISP.pair`), so that the rows are comparable: a dark LED in a capture is dark
on the same scale on which the ground truth shows it lit.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch

__all__ = ["plot_sample", "sample_images"]


def _unbatch(x: Any) -> Any:
    """A batch of one (B = 1, F, C, h, w) -> (F, C, h, w); anything else as it is."""
    if isinstance(x, torch.Tensor) and x.ndim == 5:
        if x.shape[0] != 1:
            raise ValueError(f"plot one sample: got a batch of {x.shape[0]}")
        return x[0]
    return x


def sample_images(sample: Mapping[str, Any], preset: Any, outputs: Mapping[str, torch.Tensor] | None = None
                  ) -> list[tuple[str, torch.Tensor]]:
    """The rows of the picture, in ``gt`` units: ``(title, (F, 1, h, w))`` for each capture of the preset's plan
    found in the sample (``<capture>_e``), the ground truth, then each of ``outputs`` (title -> estimate)."""
    from lfmbench.sensor import resolve

    preset = resolve(preset)
    if "gt" not in sample:
        raise ValueError("sample has no 'gt' (ask the dataset for outputs including 'gt')")
    rows = []
    for name in preset.captures:
        key = f"{name}_e"
        if key in sample:
            rows.append((f"{name} (capture)", _unbatch(sample[key])))
    gt = _unbatch(sample["gt"])
    rows.append(("ground truth", gt))
    for title, est in (outputs or {}).items():
        est = _unbatch(est)
        if tuple(est.shape) != tuple(gt.shape):
            raise ValueError(f"output {title!r}: shape {tuple(est.shape)}, expected {tuple(gt.shape)} (gt's)")
        rows.append((str(title), est))
    return rows


def plot_sample(sample: Mapping[str, Any], preset: Any = None, outputs: Mapping[str, torch.Tensor] | None = None,
                isp: Any = "default", frames: int | None = None, title: str | None = None):
    """A matplotlib Figure of one sample: a row per capture, the ground truth and each estimate of ``outputs``;
    a column per frame; every image through ``isp`` (display sRGB) with the ground truth's statistics, LED
    regions (``light_index >= 0``) outlined in yellow.

    Args:
        sample: a dataset sample (``(F, C, h, w)`` tensors, or a batch of one) with ``gt`` and ideally the
            ``<capture>_e`` outputs (``outputs`` of the dataset include ``"input_referred"``) and ``light_index``.
        preset: the sensor preset (name, YAML or :class:`lfmbench.sensor.SensorPreset`); default
            ``sample["meta"]["sensor"]``.
        outputs: title -> (F, 1, h, w) estimate in the ``gt`` units (a method's output).
        isp: ISP pipeline name or YAML (:func:`lfmbench.isp.load_pipeline`).
        frames: show at most this many frames (default all).
        title: the figure's title (default: scene, sensor, ISP).

    Returns:
        matplotlib.figure.Figure (save it with ``fig.savefig(path)``; close it with ``plt.close(fig)``).
    """
    import matplotlib.pyplot as plt  # (headless, matplotlib picks its Agg back-end itself)

    from lfmbench.isp import ISP

    meta = sample.get("meta", {}) if isinstance(sample.get("meta", {}), Mapping) else {}
    if preset is None:
        preset = meta.get("sensor")
        if isinstance(preset, (list, tuple)):
            preset = preset[0]
        if preset is None:
            raise ValueError("preset: the sample's meta names no sensor; pass preset=")
    isp_model = ISP(isp, preset)
    rows = sample_images(sample, isp_model.preset, outputs)
    gt = rows[[t for t, _ in rows].index("ground truth")][1].detach().float().cpu()
    n_frames = gt.shape[0] if frames is None else max(1, min(int(frames), gt.shape[0]))
    lidx = _unbatch(sample.get("light_index"))
    h, w = gt.shape[-2:]
    cell_w = 3.0
    cell_h = max(1.0, cell_w * h / w)
    fig, axes = plt.subplots(len(rows), n_frames, figsize=(cell_w * n_frames + 0.4, cell_h * len(rows) + 0.5),
                             squeeze=False)
    with torch.no_grad():
        for r, (name, img) in enumerate(rows):
            img = img.detach().float().cpu()
            for f in range(n_frames):
                shown, _ = isp_model.pair(img[f:f + 1], gt[f:f + 1])
                ax = axes[r, f]
                ax.imshow(shown[0].permute(1, 2, 0).clamp(0, 1).numpy(), interpolation="nearest")
                if isinstance(lidx, torch.Tensor):
                    mask = (lidx[f, 0] >= 0).float().numpy()
                    if 0 < mask.sum() < mask.size:
                        ax.contour(mask, levels=[0.5], colors="yellow", linewidths=0.6)
                ax.set_xticks([])
                ax.set_yticks([])
                if f == 0:
                    ax.set_ylabel(name, fontsize=8)
                if r == 0:
                    ax.set_title(f"frame {int(meta.get('frame_start', 0) or 0) + f}", fontsize=8)
    scene = meta.get("scene_id", "")
    scene = scene[0] if isinstance(scene, (list, tuple)) else scene
    fig.suptitle(title or f"{scene}: sensor {isp_model.preset.name}, ISP {isp_model.pipeline.name} "
                          "(statistics from the ground truth); LED regions outlined", fontsize=9)
    fig.tight_layout()
    return fig

