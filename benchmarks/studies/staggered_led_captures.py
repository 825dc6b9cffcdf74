"""Which capture the staggered plan's merge takes on the LEDs, and which captures drop them
(docs/results/sensor-architectures.md, "Why staggered drops in daylight").

    python benchmarks/studies/staggered_led_captures.py --corpus v1 --scenes test_00 test_03 test_08 test_16 [--json out.json]

For each sample of the given scenes (the evaluation's frozen draws: seed 0, ``--samples-per-scene`` draws, 3 frames,
the ``staggered`` preset with its rolling readout) and each LED region-frame (``light_index``, as the metrics take
it), it records:

- the share of the region's pixels that ``exposure_select`` takes from each capture (the first unsaturated one
  in plan order ``long``, ``medium``, ``short``; the last where all are saturated);
- the region mean of the merge, of each capture alone (input-referred ``<capture>_e``, the ``gt`` units; the
  ``long`` one clipped where saturated) and of ``gt``, and the regions' peak ``gt`` against the ``long``
  capture's saturation level (how far the lamp overexposes the 10 ms exposure);
- the share of the region's ``gt`` signal on the pixels taken from each capture (a lamp's bright core, where
  ``long`` saturates, carries most of its light on few pixels);
- a dropout as the metric counts it (region mean < 0.5 x ``gt``, :data:`lfmbench.metrics.flicker.DROPOUT_FRACTION`),
  attributed to the capture that supplies most of the region's ``gt`` signal.

Prints per time of day: region-frames, the share where ``long`` is saturated on >= 1 region pixel, the pixel and
signal shares of the three captures, the dropout share, per capture supplying most of the signal its dropout share;
as checks of the cause, the dropout share each capture alone would give, and that of the merge bounded below by the
saturated ``long`` level (``max(exposure_select, long_e)``: a saturated 10 ms exposure says the lamp is at least
that bright, a bound the standard merge ignores). Then per lamp kind (the scene's ``lights[j]["kind"]``) and time of
day: region-frames, long saturated, dropout.
"""
from __future__ import annotations

import argparse
import time
from collections import defaultdict

CAPS = ("long", "medium", "short")


def region_records(sample: dict, pred, tod: str, lights: list[dict]) -> list[dict]:
    """One record per LED region-frame of a sample (see the module docstring); ``pred`` is (F, 1, H, W) e-,
    ``lights`` the scene's light list in the order of ``light_index`` (:attr:`SceneView.lights`)."""
    import torch

    from lfmbench.metrics.flicker import DROPOUT_FRACTION

    li = sample["light_index"][:, 0]                        # (F, H, W), -1 = no light
    sat = sample["saturated"].bool()                        # (F, 3, H, W)
    gt = sample["gt"][:, 0]
    caps = [sample[f"{c}_e"][:, 0] for c in CAPS]
    bounded = torch.maximum(pred[:, 0], caps[0])            # never below the saturated long exposure's level
    flicker = sample["meta"]["flicker"]
    # the capture exposure_select takes per pixel: first unsaturated, else the last
    first_ok = torch.full(li.shape, len(CAPS) - 1, dtype=torch.long)
    for i in range(len(CAPS) - 2, -1, -1):
        first_ok = torch.where(~sat[:, i], torch.full_like(first_ok, i), first_ok)
    out = []
    for f in range(li.shape[0]):
        for j in torch.unique(li[f]).tolist():
            if j < 0:
                continue
            m = li[f] == j
            g = float(gt[f][m].mean())
            if not g > 0:
                continue
            share = [float((first_ok[f][m] == i).double().mean()) for i in range(len(CAPS))]
            gm = gt[f][m].double()
            signal = [float(gm[first_ok[f][m] == i].sum() / gm.sum()) for i in range(len(CAPS))]
            alone = [float(c[f][m].mean()) / g for c in caps]
            out.append({
                "scene_id": sample["meta"]["scene_id"], "index": int(sample["meta"]["index"]), "frame": f,
                "light": int(j), "time_of_day": tod, "pixels": int(m.sum()), "kind": lights[j].get("kind", "?"),
                "flickering": bool(flicker[j]), "luminance_cd_m2": float(lights[j].get("luminance_cd_m2", "nan")),
                "share": share, "signal_share": signal, "long_sat_any": bool(sat[f, 0][m].any()),
                "ratio": float(pred[f, 0][m].mean()) / g, "alone_ratio": alone,
                "dropout": float(pred[f, 0][m].mean()) < DROPOUT_FRACTION * g,
                "bounded_dropout": float(bounded[f][m].mean()) < DROPOUT_FRACTION * g,
                "alone_dropout": [a < DROPOUT_FRACTION for a in alone],
                "majority": CAPS[max(range(len(CAPS)), key=lambda i: signal[i])],
            })
    return out


def _pct(k: int, n: int) -> str:
    return f"{k / n:.0%} ({k}/{n})" if n else "-"


def summary(recs: list[dict]) -> str:
    """The Markdown tables of the module docstring: by time of day, then by lamp kind and time of day."""
    tods = list(dict.fromkeys(r["time_of_day"] for r in recs))
    lines = ["| time of day | region-frames | long saturated on the region | pixels from long / medium / short | "
             "gt signal from long / medium / short | dropout | dropout where most signal is from long / medium / "
             "short | dropout: long alone (clipped) / medium alone / short alone | dropout of the merge bounded "
             "below by the saturated long |", "|---" * 9 + "|"]
    for tod in tods:
        rs = [r for r in recs if r["time_of_day"] == tod]
        n = len(rs)
        sh = [sum(r["share"][i] * r["pixels"] for r in rs) / sum(r["pixels"] for r in rs) for i in range(3)]
        sg = [sum(r["signal_share"][i] for r in rs) / n for i in range(3)]
        maj = [_pct(sum(r["dropout"] for r in rs if r["majority"] == c), sum(r["majority"] == c for r in rs))
               for c in CAPS]
        alone = [f"{sum(r['alone_dropout'][i] for r in rs) / n:.1%}" for i in range(3)]
        lines.append(f"| {tod} | {n} | {sum(r['long_sat_any'] for r in rs) / n:.0%} | "
                     f"{' / '.join(f'{x:.1%}' for x in sh)} | {' / '.join(f'{x:.1%}' for x in sg)} | "
                     f"{_pct(sum(r['dropout'] for r in rs), n)} | {' / '.join(maj)} | {' / '.join(alone)} | "
                     f"{_pct(sum(r['bounded_dropout'] for r in rs), n)} |")
    lines += ["", "| lamp kind | flickering | " + " | ".join(f"{t}: region-frames, long saturated, dropout"
                                                          for t in tods) + " |", "|---" * (2 + len(tods)) + "|"]
    for kind in sorted({r["kind"] for r in recs}):
        rk = [r for r in recs if r["kind"] == kind]
        cells = []
        for tod in tods:
            rs = [r for r in rk if r["time_of_day"] == tod]
            cells.append(f"{len(rs)}, {_pct(sum(r['long_sat_any'] for r in rs), len(rs))}, "
                         f"{_pct(sum(r['dropout'] for r in rs), len(rs))}" if rs else "-")
        fl = {r["flickering"] for r in rk}
        lines.append(f"| {kind} | {'yes' if fl == {True} else 'no' if fl == {False} else 'some'} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", required=True, help="corpus root (the lfmbench-v1 test split)")
    ap.add_argument("--scenes", nargs="+", required=True, help="test scene ids")
    ap.add_argument("--samples-per-scene", type=int, default=2, help="frozen PWM draws per scene (as evaluated)")
    ap.add_argument("--json", default=None, help="write every region-frame record to this JSON file")
    a = ap.parse_args()
    import torch

    from lfmbench.baselines.plan_merge import exposure_select
    from lfmbench.datasets.loading import make_dataset
    from lfmbench.evaluation.conditions import corpus_scene_conditions
    from lfmbench.fileio import atomic_write_json

    ds = make_dataset(a.corpus, "test", seed=0, samples_per_scene=a.samples_per_scene, frames=3, sensor="staggered")
    cond = corpus_scene_conditions(ds.corpus)
    unknown = sorted(set(a.scenes) - set(ds.scene_ids))
    if unknown:
        ap.error(f"--scenes: {unknown} are not test scenes of {a.corpus}")
    recs, t0 = [], time.perf_counter()
    for sid in a.scenes:
        i0 = list(ds.scene_ids).index(sid) * a.samples_per_scene
        for i in range(i0, i0 + a.samples_per_scene):
            s = ds[i]
            if s["meta"]["scene_id"] != sid:
                raise RuntimeError(f"sample {i} is scene {s['meta']['scene_id']}, expected {sid}")
            with torch.no_grad():
                pred = exposure_select({k: v.unsqueeze(0) for k, v in s.items() if torch.is_tensor(v)})[0]
            recs += region_records(s, pred, cond(sid).get("time_of_day", "?"), list(ds.scene(sid).lights))
    print(summary(recs))
    print(f"\n{len(recs)} region-frames, {time.perf_counter() - t0:.0f} s")
    if a.json:
        atomic_write_json(a.json, {"corpus": str(a.corpus), "scenes": a.scenes, "records": recs})


if __name__ == "__main__":
    main()
