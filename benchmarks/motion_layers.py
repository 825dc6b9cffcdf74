"""Static window layers against static time bins on one scene of lfmbench-v1-mini-motion (docs/guide/rendering.md,
"Static window layers"; its figures: docs/benchmarks/rendering-measurements.md, "Static window layers"): render CPU
seconds and storage of the chopped layer against the protocol's 9 static bins, and the error of the ``nearest``
rule (a chopped sub-window served by the bins it overlaps, by overlap) against the layer, over the image and over
the moving objects' pixels.

    nice -n 10 python benchmarks/motion_layers.py CORPUS [SCENE [FRAMES]]   # CORPUS: lfmbench-v1-mini-motion v1

FRAMES (default 1): the first frames of the scene, each rendered as the protocol renders it (the costs are per
frame; the static groups only, without the AOVs).

Reads CORPUS (never writes it); prints one JSON line.
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np


def main(corpus: str, scene_id: str = "test_16", frames: str = "1") -> dict:
    from lfmbench.corpus import Corpus
    from lfmbench.corpus.exr_encode import encode_static_exr
    from lfmbench.corpus.window_layers import encode_layer
    from lfmbench.datasets.plan_frames import static_window_mix
    from lfmbench.sensor.preset import load_preset
    from render_tools import render, static_layers
    from render_tools.protocol import load_protocol

    proto = load_protocol("lfmbench-v1-mini-motion")
    ps = next(p for p in proto.scenes if p.scene_id == scene_id)
    rd = Corpus(corpus)
    meta = rd.meta(scene_id)
    scene = json.load(open(f"{corpus}/scenes/{scene_id}/scene.json"))
    wins = [list(w) for w in load_preset("chopped").captures["chopped"].exposure]
    layer = [{"name": "chopped", "windows_s": wins}]
    static = [g for g, i in meta["groups"].items() if not i.get("flicker")]
    base = dict({k: v for k, v in proto.render.items() if k != "static_layers"}, frames=int(frames))
    out = {"scene": scene_id, "static_groups": static, "frames": int(frames)}
    lays = []
    for seed in (ps.seed, ps.seed + 1):  # the second: the layer's own Monte Carlo noise
        opts = render.RenderOptions(**base, seed=seed, static_layers=layer)
        c0, w0 = time.process_time(), time.perf_counter()
        lays.append(list(static_layers.render_layer(scene, opts, opts.static_layers[0])))
        out.setdefault("layer_cpu_s", []).append(time.process_time() - c0)
        out.setdefault("layer_wall_s", []).append(time.perf_counter() - w0)
    opts = render.RenderOptions(**dict(base, groups=static, aux=False), seed=ps.seed)
    c0, w0 = time.process_time(), time.perf_counter()
    for _ in render.render_frames(scene, opts):
        pass
    out["bins_cpu_s"], out["bins_wall_s"] = time.process_time() - c0, time.perf_counter() - w0
    tm = meta["timing"]
    bands = meta["bands_nm"]
    lb = bb = 0
    num = den = num_m = den_m = noise = 0.0
    bnum = bden = bnoise = 0.0   # the same on 8 x 8 px block means (Monte Carlo noise averaged down, motion kept)

    def blocks(x):
        """(H, W) -> (H / 8, W / 8) block means (H, W multiples of 8 cropped)."""
        h, w = x.shape[0] // 8 * 8, x.shape[1] // 8 * 8
        return x[:h, :w].reshape(h // 8, 8, w // 8, 8).mean((1, 3))

    for f in range(int(frames)):
        ids = rd.read_aux(scene_id, f, ["mask.instance"])["mask.instance"]
        moving = [o["id"] for o in scene["objects"] if np.any(np.asarray(o.get("velocity_mps", [0, 0, 0])) != 0)]
        mask = np.isin(ids, moving)
        exact = sum(lays[0][f]["static"][g] for g in static)
        other = sum(lays[1][f]["static"][g] for g in static)
        near = 0.0
        for g in static:
            e, bins = rd.read_static_bins(scene_id, f, g)
            for a, n in wins:
                for lay, w in static_window_mix(a, n, tm)[0].items():
                    near = near + bins[int(lay[3:])] * (w / len(wins))
            lb += len(encode_layer(lays[0][f]["static"][g], bands, proto.storage, {}, "layer"))
            bb += len(encode_static_exr({"bins": bins}, bands, dtype=proto.storage))
        d2 = ((near - exact) ** 2).sum(0)
        num, den = num + d2.sum(), den + (exact ** 2).sum()
        num_m, den_m = num_m + d2[mask].sum(), den_m + (exact ** 2).sum(0)[mask].sum()
        noise += (((exact - other) ** 2).sum(0)).sum() / 2.0
        be, bo, bn = blocks(exact.sum(0)), blocks(other.sum(0)), blocks(near.sum(0))
        bnum, bden, bnoise = bnum + ((bn - be) ** 2).sum(), bden + (be ** 2).sum(), bnoise + ((be - bo) ** 2).sum() / 2
        np.savez_compressed(f"/tmp/motion_layers_{scene_id}_f{f}.npz", exact=exact, other=other, near=near, mask=mask)
        out.setdefault("moving_px", []).append(int(mask.sum()))
    out.update(layer_bytes=lb, bins_bytes=bb, nearest_rrmse_image=float(np.sqrt(num / den)),
               nearest_rrmse_moving=float(np.sqrt(num_m / den_m)) if den_m else None,
               layer_noise_rrmse_image=float(np.sqrt(noise / den)),
               nearest_rrmse_blocks8=float(np.sqrt(bnum / bden)), layer_noise_rrmse_blocks8=float(np.sqrt(bnoise / bden)))
    return out


if __name__ == "__main__":
    print(json.dumps(main(*sys.argv[1:])), flush=True)
