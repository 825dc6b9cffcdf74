"""One scene, one frame, through every sensor architecture and the ground truth (issue 22 item 6's figure).

Renders one night scene (640 x 360 by default, one frame, moving ego camera) into ``<out>/corpus`` (reused when
complete), simulates frame 0 with every shipped preset (noise on, the same PWM draws: the dataset's seed and index),
fuses each with its architecture's standard merge (split pixel: ``saturated_exposure_corrected``; others
``exposure_select``), demosaics (kornia bilinear) and shows every estimate and each sensor's ground truth with the
same global tone curve, log(1 + x / s) with s the median of the split pixel's ground truth, so the LED dropouts,
clipping and motion blur can be compared. Writes ``docs/img/sensor_architectures.png``.

Run: ``.venv/bin/python benchmarks/studies/architecture_figure.py [--width 640 --height 360 --seed 101]``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import bench_dataset as bd  # noqa: E402  (DRJIT_LIBLLVM_PATH, _render)
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402

from lfmbench.baselines import get_method  # noqa: E402
from lfmbench.datasets import LFMCaptureDataset  # noqa: E402
from lfmbench.datasets.loading import collate_samples  # noqa: E402
from lfmbench.fileio import atomic_save_figure  # noqa: E402
from lfmbench.sensor.plan import ARCHITECTURES  # noqa: E402

PRESETS = ("ovt", "lofic", "staggered", "chopped", "single")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--seed", type=int, default=101, help="scene seed of the generator (101: a night street)")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--out", type=Path, default=bd.ROOT / "bench_out" / "archfig")
    ap.add_argument("--png", type=Path, default=bd.IMG / "sensor_architectures.png")
    a = ap.parse_args(argv)
    from render_tools.scene import generate_scene  # noqa: PLC0415

    root = a.out.resolve() / f"corpus_{a.width}x{a.height}_{a.seed}"
    scene = generate_scene(a.seed, "night", overrides={"camera": {"speed_mps": [25.0, 25.0]}})
    bd._render(root, {"width": a.width, "height": a.height, "spp": a.spp, "bins": 8, "frames": 1}, a.seed,
               scene=scene)
    rows = []
    for name in PRESETS:
        ds = LFMCaptureDataset(root, split="all", sensor=name, frames=1, seed=0,
                               outputs=("input_referred", "saturated", "gt", "rgb"))
        s = ds[0]
        batch = collate_samples([{k: v for k, v in s.items() if k != "meta"}])
        method = ARCHITECTURES[ds.architecture].baseline
        est = get_method(method)(batch)[0]                                         # (F, 1, H, W) e-
        from kornia.color import raw_to_rgb  # noqa: PLC0415

        rgb = raw_to_rgb(est.float(), ds.preset.cfa.to_kornia())[0]
        rows.append((name, ds.architecture, method, rgb, s["gt_rgb"][0], s["meta"].get("static_windows", "exact")))
    scale = float(rows[0][4].mean(0).median()) or 1.0

    def tone(x: torch.Tensor, ref: float):
        y = torch.log1p(x.clamp_min(0) / ref)
        return (y / max(float(torch.quantile(y.flatten()[::97], 0.999)), 1e-9)).clamp(0, 1).permute(1, 2, 0).numpy()

    fig, axes = plt.subplots(len(rows), 2, figsize=(2 * 4.8, len(rows) * 4.8 * a.height / a.width + 0.6),
                             squeeze=False)
    for i, (name, arch, method, rgb, gt, sw) in enumerate(rows):
        ref = scale * float(gt.mean()) / float(rows[0][4].mean())   # each sensor's gt units, same exposure look
        axes[i, 0].imshow(tone(rgb, ref))
        axes[i, 0].set_title(f"{name} ({arch}), {method}", fontsize=7)
        axes[i, 1].imshow(tone(gt, ref))
        axes[i, 1].set_title(f"ground truth of {name} (static windows: {sw})", fontsize=7)
    for ax in axes.flat:
        ax.set_axis_off()
    fig.suptitle(f"scene seed {a.seed}, night, ego 25 m/s, frame 0, {a.width}x{a.height}: log tone curve", fontsize=8)
    fig.tight_layout()
    atomic_save_figure(fig, a.png, dpi=110)
    print(f"wrote {a.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
