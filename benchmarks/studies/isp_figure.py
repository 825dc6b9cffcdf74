"""The figure of docs/guide/isp.md: one frame of a real corpus scene through the ISP (docs/img/isp_pipeline.png).

    lfmbench demo                                       # renders demo_out/corpus (160x90)
    python benchmarks/studies/isp_figure.py --corpus demo_out/corpus --scene scene00002

Top row: the flicker-free ground truth of the frame as a linear mosaic (clipped at its 99th percentile), through the
default pipeline (Reinhard 2002, global) and through the local pipeline (Durand-Dorsey 2002). Bottom row: three
fusion estimates of the same sample through the default pipeline with the ground truth's statistics, each with its
display PSNR (psnr_srgb) and, for comparison, its linear LED score. Prints the numbers it shows.
"""
from __future__ import annotations

import argparse
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", required=True)
    ap.add_argument("--scene", default=None, help="scene id (default: the first of the corpus)")
    ap.add_argument("--frame", type=int, default=1)
    ap.add_argument("--out", default=str(ROOT / "docs" / "img" / "isp_pipeline.png"))
    a = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import torch

    from lfmbench.baselines import get_method
    from lfmbench.datasets import LFMCaptureDataset
    from lfmbench.datasets.loading import collate_samples
    from lfmbench.fileio import atomic_save_figure
    from lfmbench.isp import ISP
    from lfmbench.metrics import score_batch

    ds = LFMCaptureDataset(a.corpus, split="all", seed=0)
    idx = 0 if a.scene is None else list(ds.scene_ids).index(a.scene)
    batch = collate_samples([ds[idx]])
    sid = batch["meta"]["scene_id"][0]
    gt = batch["gt"]
    f = a.frame
    isp_g, isp_l = ISP("default", ds.preset), ISP("local", ds.preset)

    def show(x):  # (B, F, 3, H, W) display -> (H, W, 3) of the frame
        return x[0, f].permute(1, 2, 0).clamp(0, 1).numpy()

    lin = gt[0, f, 0]
    lin = (lin / torch.quantile(lin.flatten(), 0.99)).clamp(0, 1).numpy()
    panels = [("ground truth, linear mosaic\n(clipped at its 99th percentile)", lin, "gray"),
              ("ground truth, default ISP\n(Malvar 2004, CCM, Reinhard 2002)", show(isp_g(gt)), None),
              ("ground truth, local ISP\n(Durand-Dorsey 2002, guided base)", show(isp_l(gt)), None)]
    for m in ("lpd_only", "spd_only", "flicker_aware"):
        with torch.no_grad():
            pred = get_method(m)(dict(batch))
        p, _ = isp_g.pair(pred, gt)
        s = score_batch(pred, batch)[0]
        print(f"{sid} frame {f} {m}: psnr_srgb {s['psnr_srgb']:.2f} dB, ssim_srgb {s['ssim_srgb']:.3f}, "
              f"LED score {s.get('led_score', float('nan')):.3f}, psnr_mu {s['psnr_mu']:.2f} dB")
        led = s.get("led_score", float("nan"))
        panels.append((f"{m}, default ISP\nPSNR sRGB {s['psnr_srgb']:.1f} dB, LED score {led:.2f}", show(p), None))
    fig, axes = plt.subplots(2, 3, figsize=(13.5, 6.4))
    for ax, (title, img, cmap) in zip(axes.flat, panels):
        ax.imshow(img, cmap=cmap, interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    fig.suptitle(f"{sid} ({ds.preset.name}, {gt.shape[-1]}x{gt.shape[-2]}), frame {f}: one frame through the ISP",
                 fontsize=10)
    fig.tight_layout(h_pad=2.0)
    atomic_save_figure(fig, a.out, dpi=110)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
