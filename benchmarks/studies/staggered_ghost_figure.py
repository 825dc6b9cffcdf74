"""The staggered (DOL) motion ghost, seen (issue 38 deliverable 7): one generator-2 scene with moving vehicles,
rendered twice into corpora, once with the static groups as the short and long windows (format 3: the staggered
captures served by ``nearest``, every capture sees the vehicles where the long window puts them) and once with
static time bins at the staggered preset's window edges (format 4, ``RenderOptions.static_edges_s``: each capture
integrates the scene over its own time). Frame 0 through the ``staggered`` preset (noise on, the same PWM draws),
its standard merge (``exposure_select``), demosaiced; the crop is centred where the merges of the two corpora
differ most on a moving vehicle (aux ``mask.instance``), with each capture and the differences.

Writes ``docs/img/staggered_ghost.png``. Run: ``python benchmarks/studies/staggered_ghost_figure.py [--seed 8 --tod day
--width 320 --height 180]``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import bench_dataset as bd  # noqa: E402  (DRJIT_LIBLLVM_PATH, _render)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from lfmbench.baselines import get_method  # noqa: E402
from lfmbench.datasets import LFMCaptureDataset  # noqa: E402
from lfmbench.datasets.loading import collate_samples  # noqa: E402
from lfmbench.fileio import atomic_save_figure  # noqa: E402
from lfmbench.sensor.plan import ARCHITECTURES  # noqa: E402

STAGGERED_EDGES = (0.0, 0.010, 0.011, 0.0111)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    ap.add_argument("--seed", type=int, default=8, help="8 (day): an oncoming truck and car, ego 26.7 m/s")
    ap.add_argument("--tod", default="day")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--out", type=Path, default=bd.ROOT / "bench_out" / "ghostfig")
    ap.add_argument("--png", type=Path, default=bd.IMG / "staggered_ghost.png")
    a = ap.parse_args(argv)
    from kornia.color import raw_to_rgb  # noqa: PLC0415

    from render_tools.scene import generate_scene  # noqa: PLC0415

    scene = generate_scene(a.seed, a.tod, generator=2)
    base = {"width": a.width, "height": a.height, "spp": a.spp, "light_spp": 32, "bins": 8, "frames": 1}
    res = {}
    for label, extra in (("nearest", {}), ("exact", {"static_edges_s": list(STAGGERED_EDGES)})):
        root = a.out.resolve() / f"{label}_{a.width}x{a.height}_{a.seed}_{a.tod}"
        bd._render(root, {**base, **extra}, a.seed, scene=scene)
        ds = LFMCaptureDataset(root, split="all", sensor="staggered", frames=1, seed=0,
                               outputs=("input_referred", "saturated", "gt", "rgb"))
        s = ds[0]
        batch = collate_samples([{k: v for k, v in s.items() if k != "meta"}])
        est = get_method(ARCHITECTURES[ds.architecture].baseline)(batch)[0]          # (F, 1, H, W) e-
        cfa = ds.preset.cfa.to_kornia()
        res[label] = {"merge": raw_to_rgb(est.float(), cfa)[0],
                      **{c: s[f"{c}_rgb"][0] for c in ds.preset.captures}, "sw": s["meta"]["static_windows"]}
    # where the captures differ most between the two corpora: the moving vehicles' ghost
    d = (res["exact"]["merge"] - res["nearest"]["merge"]).abs().sum(0)
    # only on a moving vehicle (aux mask.instance of the objects with a velocity, pedestrians left out)
    from lfmbench.corpus import Corpus  # noqa: PLC0415

    inst = torch.from_numpy(Corpus(root).read_aux(scene["scene_id"], 0, ["mask.instance"])["mask.instance"])
    moving = [o["id"] for o in scene["objects"] if any(o["velocity_mps"]) and o["kind"] != "pedestrian"]
    on = torch.isin(inst.round().long(), torch.tensor(moving)).float()
    d = d * torch.nn.functional.max_pool2d(on[None, None], 5, stride=1, padding=2)[0, 0]
    k = torch.nn.functional.avg_pool2d(d[None, None], 15, stride=1, padding=7)[0, 0]
    cy, cx = np.unravel_index(int(torch.argmax(k)), k.shape)
    h, w = a.height // 2, a.width // 3
    y0, x0 = int(np.clip(cy - h // 2, 0, a.height - h)), int(np.clip(cx - w // 2, 0, a.width - w))
    crop = (slice(None), slice(y0, y0 + h), slice(x0, x0 + w))
    ref = float(res["nearest"]["long"].mean(0).median()) or 1.0

    def tone(x):
        y = torch.log1p(x.clamp_min(0) / ref)
        return (y / max(float(torch.quantile(y.flatten()[::7], 0.995)), 1e-9)).clamp(0, 1).permute(1, 2, 0).numpy()

    cols = [("long", "long 10 ms"), ("medium", "medium 1 ms"), ("short", "short 0.1 ms"), ("merge", "merge")]
    fig, axes = plt.subplots(3, 4, figsize=(4 * 3.0, 3 * 3.0 * h / w + 0.9), squeeze=False)
    for i, label in enumerate(("nearest", "exact")):
        for j, (key, title) in enumerate(cols):
            axes[i, j].imshow(tone(res[label][key][crop]))
            axes[i, j].set_title(f"{title}, {label} ({res[label]['sw']})", fontsize=7)
    for j, (key, title) in enumerate(cols):
        diff = (res["exact"][key] - res["nearest"][key])[crop].sum(0)
        m = float(diff.abs().max()) or 1.0
        axes[2, j].imshow(diff.numpy(), cmap="coolwarm", vmin=-m, vmax=m)
        axes[2, j].set_title(f"{title}: exact - nearest", fontsize=7)
    for ax in axes.flat:
        ax.set_axis_off()
    fig.suptitle(f"staggered preset, generator-2 scene seed {a.seed} ({a.tod}), frame 0, crop ({y0}, {x0}) "
                 f"{h}x{w} px of {a.width}x{a.height}: log tone curve (row 3: linear difference)", fontsize=8)
    fig.tight_layout()
    atomic_save_figure(fig, a.png, dpi=120)
    print(f"wrote {a.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
