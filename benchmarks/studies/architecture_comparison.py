"""Every sensor architecture on the same test scenes, ranked together (docs/results/sensor-architectures.md): the
generic plans (the split pixel ``ovt`` with three of its rule-based fusions, LOFIC, staggered, chopped, single
exposure) and the presets of shipped parts (``imx490_4read``, ``ox03c10``, ``ar0132at``, ``mt9v024``,
``lofic_akahane2006``), each with its standard merge (``exposure_select``; staggered also bounded below by its
saturated captures, ``exposure_select_bounded``; the split pixels with the same three fusions), and each with a U-Net
trained for that sensor when its checkpoint is given.

Exact motion between captures needs a corpus whose static groups are stored in time bins at the presets' window
edges: the protocol ``lfmbench-v1-mini-motion`` (``lfmbench-v1-mini`` plus those edges)::

    lfmbench render --protocol lfmbench-v1-mini-motion --split test --out v1mm --workers 2
    python benchmarks/studies/architecture_comparison.py --corpus v1mm --runs runs/arch_v1mm --samples-per-scene 2
    # with a U-Net per sensor, trained with one budget (unet_tiny.yaml, 20 epochs of the 32 training scenes x 8
    # draws: 1,280 steps of batch 4) on the training split, then scored and ranked with the merges above:
    lfmbench render --protocol lfmbench-v1-mini-motion --split train --out v1mm --workers 2
    python benchmarks/studies/architecture_comparison.py --corpus v1mm --runs runs/arch_v1mm --samples-per-scene 2 \
        --train-epochs 20 --checkpoints runs/unet_v1mm --unet-only --sensor ovt --sensor ox03c10 ...  # two halves
    lfmbench leaderboard runs/arch_v1mm/*/<method>.json --cross-sensor --json runs/arch_v1mm/leaderboard.json

``--train-epochs E`` trains each selected sensor's U-Net first (one process, one torch thread, no DataLoader
worker; a checkpoint already complete is kept, an unfinished one resumed) into ``--checkpoints/unet_<sensor>.pt``
with its times in ``unet_<sensor>.json`` (wall and CPU seconds, steps, load average before and after), then
scores them as ``--unet`` would; ``--unet-only`` scores only the U-Nets (the merges' result files already in
``--runs`` are kept and ranked with them).

The earlier comparison on the 640x360 ``lfmbench-v1`` test split (static windows served by ``nearest``)::

    lfmbench render --protocol lfmbench-v1 --split test --out v1 --workers 1
    python benchmarks/studies/architecture_comparison.py --corpus v1 --runs runs/arch_v1 --samples-per-scene 2 \
        --static-windows nearest --sensor ovt --sensor lofic --sensor staggered --sensor chopped --sensor single \
        --unet ovt=runs/unet_ovt.pt ...

One :func:`lfmbench.evaluation.benchmark.benchmark_sensors` call: per sensor its methods share each simulated
sample (runs in ``--runs/<sensor>/``), then one cross-sensor leaderboard (``--runs/leaderboard.{md,json,png}``);
no perceptual metrics and no ISP columns (secondary; minutes at 640x360). ``--max-scenes N`` scores the first N
scenes of the split, each with all its draws (the first 24 of ``lfmbench-v1``'s test split are 8 day, 8 dusk,
8 night). The whole ``lfmbench-v1`` test split (48 scenes x 2 draws, 12 method runs) took 50 min wall, 34 min CPU on
the shared 2-core machine (docs/results/sensor-architectures.md).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

#: The methods of each sensor (the U-Net is added where a checkpoint is given).
#: The generic plans first, then the presets of shipped parts (docs/guide/sensors.md): the Sony IMX490 with its four
#: reads, the OmniVision OX03C10 split pixel, the onsemi AR0132AT (staggered), the onsemi MT9V024 (single) and the
#: LOFIC sensor of Akahane et al. 2006.
METHODS = {"ovt": ["saturated_exposure_corrected", "flicker_aware_two_sided", "lpd_only"],
           "lofic": ["exposure_select"], "staggered": ["exposure_select", "exposure_select_bounded"],
           "chopped": ["exposure_select"],
           "single": ["exposure_select"],
           "imx490_4read": ["exposure_select"],
           "ox03c10": ["saturated_exposure_corrected", "flicker_aware_two_sided", "lpd_only"],
           "ar0132at": ["exposure_select", "exposure_select_bounded"],
           "mt9v024": ["exposure_select"],
           "lofic_akahane2006": ["exposure_select"]}


def _f(v, nd=3) -> str:
    """A number with ``nd`` decimals; "-" for None, NaN and the JSON's "nan" (an interval over one scene)."""
    if isinstance(v, str):
        v = float(v) if v.strip().lower() in ("nan", "inf", "-inf") else None
    return "-" if v is None or v != v else f"{v:.{nd}f}"


def _ci(row: dict, key: str, nd: int = 3) -> str:
    lo, hi = (row.get("ci") or {}).get(key) or [None, None]
    return f"{_f(row.get(key), nd)} [{_f(lo, nd)}, {_f(hi, nd)}]"


def _bin_low(label: str) -> float:
    """The lower edge of a condition bin's label ``"[0.2, 0.3)"`` (its sort key; a label without one sorts last)."""
    try:
        return float(label.strip("[(").split(",")[0])
    except ValueError:
        return float("inf")


def tables(leaderboard_json: str | Path) -> str:
    """The comparison's Markdown tables (docs/results/sensor-architectures.md) from a cross-sensor ``leaderboard.json``: the
    ranking with 95 % intervals, then the LED score by condition (time of day with its interval; PWM miss probability
    and ego speed: value and scenes), then each U-Net against its sensor's merges (:func:`unet_table`)."""
    import json

    d = json.loads(Path(leaderboard_json).read_text())
    rows = d["rows"]
    out = ["| # | sensor: method | LED score [95 % CI] | diff vs best [95 % CI] | p Holm | dropout [95 % CI] | "
           "abs dFMI | LED err | PSNR-mu dB [95 % CI] | ghost [95 % CI] | ms/MP |", "|---" * 11 + "|"]
    for r in rows:
        vb = r.get("vs_best")
        diff = "best" if not vb else f"{_f(vb['mean_diff'])} [{_f(vb['ci'][0])}, {_f(vb['ci'][1])}]"
        p = "-" if not vb else ("< 0.001" if vb["p_holm"] < 1e-3 else _f(vb["p_holm"]))
        method, _, sensor = r["method"].partition(" @ ")
        out.append(f"| {r['rank']} | {sensor}: `{method}` | {_ci(r, 'led_score')} | {diff} | {p} | "
                   f"{_ci(r, 'dropout_rate')} | {_f(r.get('fmi_abs_err'))} | {_f(r.get('led_rel_err'))} | "
                   f"{_ci(r, 'psnr_mu', 2)} | {_ci(r, 'ghost_mae_mu')} | {_f(r.get('ms_per_megapixel'), 1)} |")
    heads, cols = [], []
    for cond in ("time_of_day", "pwm_miss_prob", "ego_speed_mps"):
        bins: list = []  # the union over the rows: a sensor's miss-probability bins come from its own windows
        for r in rows:
            bins += [b for b in (r.get("breakdown") or {}).get(cond, {}) if b not in bins]
        for b in sorted(bins, key=_bin_low) if cond != "time_of_day" else bins:
            heads.append(b if cond == "time_of_day" else f"{cond} {b}")
            cols.append((cond, b))
    out += ["", "| sensor: method | " + " | ".join(heads) + " |", "|---" * (len(heads) + 1) + "|"]
    for r in rows:
        cells = []
        for cond, b in cols:
            x = (r.get("breakdown") or {}).get(cond, {}).get(b)
            if x is None:
                cells.append("-")
            elif cond == "time_of_day":
                cells.append(f"{_f(x['value'])} [{_f(x['ci'][0])}, {_f(x['ci'][1])}] ({x['n']})")
            else:
                cells.append(f"{_f(x['value'])} ({x['n']})")
        method, _, sensor = r["method"].partition(" @ ")
        out.append(f"| {sensor}: `{method}` | " + " | ".join(cells) + " |")
    return "\n".join(out + unet_table(d)) + "\n"


def unet_table(d: dict) -> list[str]:
    """Markdown lines: each sensor's U-Net against its standard merge (the first method of :data:`METHODS`) and
    against its best rule-based method in this leaderboard, paired over scenes on the LED score (mean difference with
    its 95 % bootstrap interval, Wilcoxon p Holm-adjusted over the sensors, :mod:`lfmbench.evaluation.stats`).
    Empty without U-Net rows."""
    from lfmbench.evaluation.stats import holm, paired_test

    rows = {r["method"]: r for r in d["rows"]}
    per = {m: {s["scene_id"]: s["metrics"].get("led_score") for s in v} for m, v in (d.get("per_scene") or {}).items()}
    found = []
    for sensor, methods in METHODS.items():
        unet = f"unet @ {sensor}"
        merges = [f"{m} @ {sensor}" for m in methods if f"{m} @ {sensor}" in rows]
        if unet not in rows or not merges:
            continue
        best = max(merges, key=lambda m: rows[m]["led_score"])
        tests = []
        for other in (merges[0], best):
            ids = sorted(set(per.get(unet, {})) & set(per.get(other, {})))
            tests.append(paired_test([per[unet][i] for i in ids], [per[other][i] for i in ids]))
        found.append((sensor, unet, merges[0], best, tests))
    if not found:
        return []
    adj = [holm([f[4][k]["p"] for f in found]) for k in (0, 1)]

    def diff(t: dict, p: float) -> str:
        return (f"{_f(t['mean_diff'])} [{_f(t['ci'][0])}, {_f(t['ci'][1])}] | "
                + ("< 0.001" if p < 1e-3 else _f(p)))

    out = ["", "| sensor | U-Net LED score [95 % CI] | rank | standard merge: LED score [95 % CI] | rank | "
           "U-Net - merge [95 % CI] | p Holm | best rule-based | U-Net - best [95 % CI] | p Holm |", "|---" * 10 + "|"]
    for i, (sensor, unet, merge, best, tests) in enumerate(found):
        out.append(f"| {sensor} | {_ci(rows[unet], 'led_score')} | {rows[unet]['rank']} | `{merge.partition(' @ ')[0]}` "
                   f"{_ci(rows[merge], 'led_score')} | {rows[merge]['rank']} | {diff(tests[0], adj[0][i])} | "
                   f"`{best.partition(' @ ')[0]}` | {diff(tests[1], adj[1][i])} |")
    return out


#: The U-Net configuration of the comparison: one budget for every sensor (lfmbench/configs/unet_tiny.yaml: batch 4,
#: 64 px crops, 8 draws per scene per epoch, seed 0).
TRAIN_CONFIG = "unet_tiny"
#: Training scenes whose projections a training keeps in memory (160x90: about 2.4 MB each).
TRAIN_CACHE_SCENES = 64


def _load() -> list[float]:
    """The 1-, 5- and 15-minute load averages (Linux ``/proc/loadavg``; empty elsewhere)."""
    try:
        return [float(x) for x in Path("/proc/loadavg").read_text().split()[:3]]
    except OSError:
        return []


def train_unet(corpus: str | Path, sensor: str, epochs: int, folder: Path) -> Path:
    """Train the U-Net of ``sensor`` (:data:`TRAIN_CONFIG`, ``epochs`` epochs of the corpus's training split, one
    torch thread, no DataLoader worker) into ``folder/unet_<sensor>.pt`` (resumed when unfinished, kept when
    complete), its times into ``folder/unet_<sensor>.json`` (wall and CPU seconds of this call, steps, seconds per
    epoch, load averages before and after). Returns the checkpoint path."""
    import json

    folder.mkdir(parents=True, exist_ok=True)
    out, record = folder / f"unet_{sensor}.pt", folder / f"unet_{sensor}.json"
    if out.is_file() and record.is_file() and json.loads(record.read_text()).get("epochs") == epochs:
        print(f"[{sensor}] kept {out} (trained for {epochs} epochs: {record})", flush=True)
        return out
    if not Path(corpus).is_dir():
        raise FileNotFoundError(f"corpus directory {corpus} does not exist (render its training split first)")
    import torch

    from lfmbench.fileio import atomic_write_text
    from lfmbench.train import load_config, train

    torch.set_num_threads(1)
    load0, t, c = _load(), time.perf_counter(), time.process_time()
    # every training scene's projection kept in memory (the default keeps 8 and reads the others back from the disk
    # cache per sample, 0.035 CPU s each): the same samples, less time
    _, hist = train("unet", corpus, out, load_config("unet", TRAIN_CONFIG), epochs=epochs, workers=0,
                    cache_scenes=TRAIN_CACHE_SCENES, sensor=sensor, progress=False,
                    log=lambda m: print(f"[{sensor}] {m}", flush=True))
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    info = {"sensor": sensor, "config": TRAIN_CONFIG, "epochs": epochs, "steps": hist["steps"],
            "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "epoch_seconds": [round(x, 2) for x in
                                                                                 hist["epoch_seconds"]],
            "final_loss": hist["epoch_loss"][-1] if hist["epoch_loss"] else None,
            "load_before": load0, "load_after": _load(),
            "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(time.time() - wall))}
    atomic_write_text(record, json.dumps(info, indent=1) + "\n")
    print(f"[{sensor}] trained: {hist['steps']} steps, {wall:.0f} s wall, {cpu:.0f} CPU s -> {out}", flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", help="corpus root (a protocol's test split; required unless --tables-only)")
    ap.add_argument("--runs", default="runs/architectures", help="output directory")
    ap.add_argument("--samples-per-scene", type=int, default=2, help="frozen PWM draws per test scene")
    ap.add_argument("--max-scenes", type=int, default=None, help="score the first N scenes of the split")
    ap.add_argument("--tables-only", action="store_true", help="only rewrite --runs/tables.md from its leaderboard")
    ap.add_argument("--static-windows", choices=["exact", "nearest"], default="exact",
                    help="exact (default): a sensor whose windows the corpus's static bins and layers do not give "
                         "exactly is refused before any work; nearest: the named approximation (a corpus without "
                         "bins, e.g. lfmbench-v1)")
    ap.add_argument("--sensor", action="append", default=[], choices=list(METHODS),
                    help="only these sensors (repeatable; default all): parts run in parallel, ranked together by "
                         "lfmbench leaderboard RUNS/*/*.json --cross-sensor")
    ap.add_argument("--unet", action="append", default=[], metavar="SENSOR=CHECKPOINT",
                    help="a U-Net trained for SENSOR (lfmbench train --method unet --sensor SENSOR); repeatable")
    ap.add_argument("--train-epochs", type=int, default=None, metavar="E",
                    help="first train a U-Net per selected sensor for E epochs of the corpus's training split "
                         f"({TRAIN_CONFIG}.yaml, the same budget for every sensor) into --checkpoints")
    ap.add_argument("--checkpoints", default="runs/unet_checkpoints",
                    help="with --train-epochs: the folder of the checkpoints and their timing files")
    ap.add_argument("--unet-only", action="store_true",
                    help="score only the U-Nets (the merges' result files already in --runs are kept)")
    a = ap.parse_args()
    unets = {}
    for item in a.unet:
        sensor, sep, path = item.partition("=")
        if not sep or sensor not in METHODS:
            ap.error(f"--unet {item!r}: give SENSOR=CHECKPOINT with SENSOR one of {', '.join(METHODS)}")
        unets[sensor] = path
    if a.tables_only:
        print(tables(Path(a.runs) / "leaderboard.json"))
        return
    if not a.corpus:
        ap.error("--corpus is required")
    if a.train_epochs is not None and a.train_epochs < 1:
        ap.error(f"--train-epochs must be >= 1, got {a.train_epochs}")
    selected = [s for s in METHODS if s in (a.sensor or METHODS)]
    if a.train_epochs is not None:
        for s in selected:
            unets[s] = str(train_unet(a.corpus, s, a.train_epochs, Path(a.checkpoints)))
    if a.unet_only and not unets:
        ap.error("--unet-only needs --unet or --train-epochs")
    from lfmbench.evaluation.benchmark import benchmark_sensors

    sensors = {s: [*([] if a.unet_only else METHODS[s]), *(["unet"] if s in unets else [])] for s in selected}
    sensors = {s: m for s, m in sensors.items() if m}
    t = time.perf_counter()
    try:
        benchmark_sensors(a.corpus, sensors, a.runs, checkpoints={s: {"unet": p} for s, p in unets.items()},
                          split="test", seed=0, perceptual=False, repeats=1, isp=None,
                          samples_per_scene=a.samples_per_scene, max_scenes=a.max_scenes, progress=False,
                          static_windows=a.static_windows)
    except ValueError as exc:
        ap.error(str(exc))
    print(f"evaluation took {time.perf_counter() - t:.0f} s")
    from lfmbench.fileio import atomic_write_text

    md = Path(a.runs) / "tables.md"
    atomic_write_text(md, tables(Path(a.runs) / "leaderboard.json"))
    print(f"tables for docs/results/sensor-architectures.md: {md}")


if __name__ == "__main__":
    main()
