"""The staggered (DOL) motion ghost on a vehicle crossing the view (issue 38 deliverable 7): one generator-2 night
scene with an oncoming car close to the camera, rendered twice at 640x360 with the ``default`` profile at spp 4
(its spp 1 looks the same; the static frames denoised), once with the static groups as the short and long windows
only (corpus format 3: every staggered capture is served by ``nearest``, the long window's average, so it sees the
car where the whole frame averages it) and once with static time bins at the staggered preset's window edges (format 4,
``RenderOptions.static_edges_s``: each capture integrates the scene over its own time). Frame 0 through the
``staggered`` preset (10 / 1 / 0.1 ms, noise on, the same PWM draws), its standard merge (``exposure_select``) and
the sample's ground truth (``gt``), demosaiced, with a crop on the car's headlights.

The scene is the one of ``--find`` (default seeds 0-119, night and dusk): the moving vehicle's headlight (a static
group: the lamps ``nearest`` misplaces; the flickering lamps are exact for every window) that moves farthest on the
screen between the long window's middle (5 ms) and the short one's (11.05 ms) while in view (pinhole projection of
the scene's ego and object motion, :mod:`render_tools.camera`).

Writes ``docs/img/staggered_ghost_motion.png`` and prints the render CPU seconds (this process and its render
workers). Run: ``python benchmarks/studies/staggered_ghost_motion_figure.py`` (``--find 0:120`` to redo the search).
"""
from __future__ import annotations

import argparse
import io
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import bench_dataset as bd  # noqa: E402  (DRJIT_LIBLLVM_PATH, _render)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from lfmbench.baselines import get_method  # noqa: E402
from lfmbench.datasets import LFMCaptureDataset  # noqa: E402
from lfmbench.datasets.loading import collate_samples  # noqa: E402
from lfmbench.fileio import atomic_save_figure, atomic_write_bytes  # noqa: E402
from lfmbench.sensor.plan import ARCHITECTURES  # noqa: E402

#: The staggered preset's window edges (s from the frame start): long [0, 10), medium [10, 11), short [11, 11.1) ms.
STAGGERED_EDGES = (0.0, 0.010, 0.011, 0.0111)
#: Each capture's middle (s): where the exact windows put a moving object on average.
MID_S = {"long": 0.005, "medium": 0.0105, "short": 0.01105}


def headlight_tracks(scene: dict, width: int, height: int) -> list[dict]:
    """The headlights (group ``headlights``) of the scene's moving objects in view at 5 ms: ``[{light, object,
    kind, depth_m, uv {capture: (2,) px}, shift_px}]``, ``uv`` the light's centre projected at each capture's middle
    (pinhole, the ego pose at that time, the object moved by its velocity), ``shift_px`` |uv short - uv long|."""
    from render_tools.camera import EgoMotion, intrinsics, project  # noqa: PLC0415

    ego = EgoMotion.from_scene(scene)
    k = intrinsics(width, height, scene["camera"]["fov_x_deg"])
    objs = {o["id"]: o for o in scene["objects"]}
    out = []
    for light in scene["lights"]:
        o = objs.get(light.get("instance"))
        if light["group"] != "headlights" or o is None or not any(o["velocity_mps"]):
            continue
        c, v = np.asarray(light["center"], float), np.asarray(o["velocity_mps"], float)
        uv, z = {}, None
        for cap, t in MID_S.items():
            p, d = project((c + v * t)[None], ego.pose_cv(t), k)
            uv[cap] = p[0]
            z = float(d[0]) if cap == "long" else z
        u0 = uv["long"]
        if z > 0 and 0 <= u0[0] < width and 0 <= u0[1] < height:
            out.append({"light": light["id"], "object": o["id"], "kind": o["kind"], "depth_m": z, "uv": uv,
                        "shift_px": float(np.linalg.norm(uv["short"] - u0))})
    return out


def _in_view(t: dict, width: int, height: int, margin: int = 16) -> bool:
    """Whether track ``t`` (:func:`headlight_tracks`) stays ``margin`` px inside the frame at every capture's middle."""
    p = np.array(list(t["uv"].values()))
    return bool((p >= margin).all() and (p[:, 0] < width - margin).all() and (p[:, 1] < height - margin).all())


def vehicle_shifts(tracks: list[dict], width: int, height: int, margin: int = 16) -> list[tuple]:
    """Per moving object with a headlight that stays ``margin`` px inside the frame at every capture's middle:
    ``(shift_px, object, kind, depth_m)``, the smallest shift of those headlights, largest first."""
    by: dict[int, list[dict]] = {}
    for t in tracks:
        if _in_view(t, width, height, margin):
            by.setdefault(t["object"], []).append(t)
    rows = [(min(t["shift_px"] for t in ts), oid, ts[0]["kind"], min(t["depth_m"] for t in ts))
            for oid, ts in by.items()]
    return sorted(rows, reverse=True)


def find_scene(seeds: range, tods=("night", "dusk"), width: int = 640, height: int = 360) -> list[tuple]:
    """(shift_px, tod, seed, kind, depth_m) of the vehicle of :func:`vehicle_shifts` per scene, largest first."""
    from render_tools.scene import generate_scene  # noqa: PLC0415

    rows = []
    for tod in tods:
        for seed in seeds:
            v = vehicle_shifts(headlight_tracks(generate_scene(seed, tod, generator=2), width, height), width, height)
            if v:
                rows.append((round(v[0][0], 2), tod, seed, v[0][2], round(v[0][3], 1)))
    return sorted(rows, reverse=True)


def _cpu() -> float:
    """CPU seconds of this process and its finished children (user + system)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _captures(root: Path, cache: Path) -> dict:
    """Frame 0 of the corpus at ``root`` through the staggered preset (noise on, dataset seed 0): ``{capture name,
    "merge", "gt": (3, H, W) e- demosaiced, "sw": meta static_windows}``; kept in ``cache`` (beside the corpus)."""
    if cache.is_file():
        return torch.load(cache)
    from kornia.color import raw_to_rgb  # noqa: PLC0415

    ds = LFMCaptureDataset(root, split="all", sensor="staggered", frames=1, seed=0,
                           outputs=("input_referred", "saturated", "gt", "rgb"))
    s = ds[0]
    batch = collate_samples([{k: v for k, v in s.items() if k != "meta"}])
    est = get_method(ARCHITECTURES[ds.architecture].baseline)(batch)[0]          # (F, 1, H, W) e-
    out = {"merge": raw_to_rgb(est.float(), ds.preset.cfa.to_kornia())[0], "gt": s["gt_rgb"][0],
           **{c: s[f"{c}_rgb"][0] for c in ds.preset.captures}, "sw": s["meta"]["static_windows"]}
    buf = io.BytesIO()
    torch.save(out, buf)
    atomic_write_bytes(cache, buf.getvalue())
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--seed", type=int, default=34, help="34 (night): an oncoming car at 11 m, closing at 73 m/s")
    ap.add_argument("--tod", default="night")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--find", default=None, help="search seeds A:B (night, dusk) for the largest headlight shift")
    ap.add_argument("--out", type=Path, default=bd.ROOT / "bench_out" / "ghostmotion")
    ap.add_argument("--png", type=Path, default=bd.IMG / "staggered_ghost_motion.png")
    a = ap.parse_args(argv)
    if a.find:
        lo, hi = (int(x) for x in a.find.split(":"))
        for row in find_scene(range(lo, hi), width=a.width, height=a.height)[:10]:
            print(row)
        return 0
    from render_tools.scene import generate_scene  # noqa: PLC0415

    scene = generate_scene(a.seed, a.tod, generator=2)
    tracks = headlight_tracks(scene, a.width, a.height)
    shift, oid, kind, depth = vehicle_shifts(tracks, a.width, a.height)[0]
    base = {"width": a.width, "height": a.height, "spp": a.spp, "light_spp": 32, "bins": 8, "frames": 1}
    res = {}
    for label, extra in (("exact", {"static_edges_s": list(STAGGERED_EDGES)}), ("nearest", {})):
        root = a.out.resolve() / f"{label}_{a.width}x{a.height}_{a.seed}_{a.tod}_spp{a.spp}"
        c0, w0 = _cpu(), time.perf_counter()
        bd._render(root, {**base, **extra}, a.seed, scene=scene)
        print(f"{label}: render CPU {_cpu() - c0:.1f} s, wall {time.perf_counter() - w0:.1f} s", flush=True)
        res[label] = _captures(root, root.with_suffix(".figure.pt"))
    _figure(res, [t for t in tracks if t["object"] == oid and _in_view(t, a.width, a.height)], a,
            f"{kind} at {depth:.1f} m, its headlight moves {shift:.1f} px between the long and short captures' middles")
    return 0


def _centroid(img: torch.Tensor, x0: int, y0: int) -> tuple[float, float]:
    """(x, y) px in the frame, continuous coordinates as :func:`render_tools.camera.project` (pixel i spans [i, i + 1)):
    the intensity-weighted centroid of the pixels of ``img`` (3, h, w) whose channel mean exceeds half its maximum (a
    crop whose top-left pixel is (x0, y0))."""
    x = img.mean(0)
    m = x > 0.5 * x.max()
    ys, xs = torch.nonzero(m, as_tuple=True)
    w = x[m].double()
    return float((xs * w).sum() / w.sum()) + x0 + 0.5, float((ys * w).sum() / w.sum()) + y0 + 0.5


def _figure(res: dict, lamps: list[dict], a, what: str) -> None:
    """The crops (exact and nearest rows: each capture, the merge, long / short overlaid), the ground truth and the
    whole frame with the crop, written to ``a.png``."""
    lamps = list({tuple(np.round(t["uv"]["long"], 3)): t for t in lamps}.values())  # one per lamp position
    pts = np.array([t["uv"][c] for t in lamps for c in MID_S])
    (x0, y0), (x1, y1) = pts.min(0), pts.max(0)
    ch = int(max(y1 - y0 + 48, (x1 - x0 + 48) * 9 / 16))
    cw = int(ch * 16 / 9)
    ty = int(np.clip((y0 + y1) / 2 - ch / 2, 0, a.height - ch))
    tx = int(np.clip((x0 + x1) / 2 - cw / 2, 0, a.width - cw))
    crop = (slice(None), slice(ty, ty + ch), slice(tx, tx + cw))
    for label in ("exact", "nearest"):  # where each capture puts the lamp: its centroid over half its crop maximum
        xy = {k: _centroid(res[label][k][crop], tx, ty) for k in ("long", "medium", "short", "merge", "gt")}
        print(f"{label}: lamp centroid (x, y) px " + ", ".join(f"{k} ({x:.1f}, {y:.1f})" for k, (x, y) in xy.items())
              + f"; short - long {float(np.hypot(*(np.subtract(xy['short'], xy['long'])))):.1f} px")
    print("projected headlight centres (x, y) px: " + "; ".join(
        ", ".join(f"{c} ({t['uv'][c][0]:.1f}, {t['uv'][c][1]:.1f})" for c in MID_S) for t in lamps))
    # one log tone curve for every panel: the ground truth's brightest crop pixels at 1, 1/300 of them at ~0.2
    peak = float(torch.quantile(res["exact"]["gt"][crop].mean(0).flatten(), 0.995)) or 1.0
    ref = peak / 300.0

    def tone(x, rgb=True):
        y = (torch.log1p(x.clamp_min(0) / ref) / np.log1p(peak / ref)).clamp(0, 1)
        return y.permute(1, 2, 0).numpy() if rgb else y.mean(0).numpy()

    cols = [("long", "long [0, 10) ms"), ("medium", "medium [10, 11) ms"), ("short", "short [11, 11.1) ms"),
            ("merge", "merge (exposure_select)")]
    fig, axes = plt.subplots(2, 6, figsize=(6 * 2.7, 2 * 2.7 * ch / cw + 1.5), squeeze=False)
    ext = (tx - 0.5, tx + cw - 0.5, ty + ch - 0.5, ty - 0.5)
    for i, label in enumerate(("exact", "nearest")):
        r = res[label]
        for j, (key, title) in enumerate(cols):
            axes[i, j].imshow(tone(r[key][crop]), interpolation="nearest", extent=ext)
            axes[i, j].set_title(f"{label}: {title}", fontsize=8)
        lo, sh = tone(r["long"][crop], False), tone(r["short"][crop], False)
        axes[i, 4].imshow(np.stack([lo, sh, sh], -1), interpolation="nearest", extent=ext)
        axes[i, 4].set_title(f"{label}: long (red) over short (cyan)", fontsize=8)
        for j in range(5):
            for t in lamps:
                for cap, c in (("long", "yellow"), ("short", "magenta")):
                    axes[i, j].axvline(t["uv"][cap][0], color=c, lw=0.7, ls=(0, (3, 3)), alpha=0.8)
    axes[0, 5].imshow(tone(res["exact"]["gt"][crop]), interpolation="nearest", extent=ext)
    axes[0, 5].set_title("ground truth (gt: [0, 10) ms, exact, no noise)", fontsize=8)
    full = res["exact"]["gt"]
    fpeak = float(torch.quantile(full.mean(0).flatten()[::7], 0.999)) or 1.0
    axes[1, 5].imshow((torch.log1p(full.clamp_min(0) * 3000 / fpeak) / np.log1p(3000)).clamp(0, 1).permute(1, 2, 0),
                      interpolation="nearest")
    axes[1, 5].add_patch(Rectangle((tx - 0.5, ty - 0.5), cw, ch, fill=False, ec="cyan", lw=1))
    axes[1, 5].set_title("ground truth, whole frame (crop in cyan)", fontsize=8)
    for ax in axes.flat:
        ax.set_axis_off()
    fig.suptitle(f"staggered preset (10 / 1 / 0.1 ms), generator-2 scene seed {a.seed} ({a.tod}), frame 0, "
                 f"{a.width}x{a.height}, spp {a.spp}: {what}.\nRow 1: static time bins at the captures' edges "
                 "(exact windows); row 2: nearest (every capture sees the scene over the long window). "
                 f"Crop ({ty}, {tx}) {ch}x{cw} px; dashed: the headlight's centre at the long window's middle "
                 "(yellow, 5 ms) and the short's (magenta, 11.05 ms)",
                 fontsize=8.5)
    fig.tight_layout()
    atomic_save_figure(fig, a.png, dpi=120)
    print(f"wrote {a.png}")


if __name__ == "__main__":
    sys.exit(main())
