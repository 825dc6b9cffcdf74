"""Render cost of scene generator 2 (protocol lfmbench-v2: shaped vehicles, people, trees, lamp clusters, wet
roads) against generator 1 (lfmbench-v1), same seed and time of day, cold and warm (issue 23: at most 1.5x).

Each case renders one scene file (``lfmbench render --scene FILE --profile default --workers 1``) in a child
process, as :mod:`bench_render_scale` does: cold with ``HOME`` a new empty folder (empty Dr.Jit kernel cache),
warm the same scene again with that ``HOME``. Generator 1 and generator 2 alternate, so a change of the machine's
load hits both alike; wall and CPU seconds (user + system of the child) are both reported, CPU seconds being the
steadier under load. A generator-1 scene of the same seed and time of day is rendered once and compared with every
generator-2 weather of it. Writes the section "Scene generator 2 against generator 1" of
docs/benchmarks/render-scale.md (what is before it is :mod:`bench_render_scale`'s; later sections are kept).

Warm renders are repeated (``--repeats``, default 3), generator 1 and 2 alternating, and their medians reported: one
render's CPU seconds moved by 5-10 % from run to run on the 2-core machine (measured 2026-11-26).

A one-scene command also pays the command's fixed cost (Python start, imports, the worker process, the probe: about
5 s wall and 4-6 CPU s on the 2-core machine, the same for both generators), which a corpus of many scenes pays
once: ``--marginal N`` (default 3) also renders N copies of each scene (other scene ids) in one command with the warm
``HOME`` and reports the cost of each scene after the first, (t_N - t_1) / (N - 1), t_1 the warm median.

Usage: ``python benchmarks/bench_render_v2.py [--profile default] [--cases 101:night:wet 101:night:dry
202:day:dry] [--repeats 3] [--marginal 3] [--variant cuda_ad_spectral] [--texture-filter nearest]`` (seed:time of
day:generator 2's weather; ``--variant`` is passed to ``lfmbench render``, default auto; ``--marginal 0``: no N-scene
runs; ``--texture-filter``: the profile with that ``RenderOptions.texture_filter``, written to a temporary file).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH
from _timing import replace_section  # noqa: E402
from bench_render_scale import run_case  # noqa: E402

from lfmbench.fileio import atomic_write_text  # noqa: E402

#: Heading of this script's section of docs/benchmarks/render-scale.md.
SECTION = "## Scene generator 2 against generator 1 (issue 23)"
#: The default cases: seed, time of day, generator 2's weather.
CASES = ("101:night:wet", "101:night:dry", "202:day:dry")


def _objects(sc: dict) -> str:
    return f"{len(sc['objects'])} objects, {len(sc['lights'])} lights"


def main() -> None:
    from render_tools import scene as S  # noqa: PLC0415

    ap = argparse.ArgumentParser()
    ap.add_argument("--profile", default="default")
    ap.add_argument("--cases", nargs="+", default=list(CASES), help="seed:time of day:generator 2's weather")
    ap.add_argument("--out", default=str(ROOT / "docs"))
    ap.add_argument("--repeats", type=int, default=3, help="warm renders per scene (median reported)")
    ap.add_argument("--variant", default=None, help="Mitsuba variant passed to lfmbench render (default: auto)")
    ap.add_argument("--marginal", type=int, default=3, help="scenes of the N-scene runs (0: none)")
    ap.add_argument("--texture-filter", default=None, choices=("auto", "bilinear", "nearest"),
                    help="RenderOptions.texture_filter of the profile (default: the profile's)")
    a = ap.parse_args()
    if a.repeats < 1:
        ap.error("--repeats must be >= 1")
    if a.marginal == 1 or a.marginal < 0:
        ap.error("--marginal must be 0 or >= 2")
    cases = []
    for c in a.cases:
        seed, tod, weather = c.split(":")
        cases.append((int(seed), tod, weather))
    rows, v1 = [], {}
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="lfm_v2_") as tmp:
        tmp = Path(tmp)

        extra_v = ("--variant", a.variant) if a.variant else ()
        profile = a.profile
        if a.texture_filter:  # the profile with that texture filter, as a profile file
            from render_tools.jobs import load_profile  # noqa: PLC0415

            profile = str(tmp / "profile.yaml")
            atomic_write_text(Path(profile), json.dumps({**load_profile(a.profile), "texture_filter": a.texture_filter}))

        def prepare(gen, seed, tod, weather):
            kw = {"generator": 2, "overrides": {"weather": {"conditions": [weather]}}} if gen == 2 else {}
            sc = S.generate_scene(seed, tod, scene_id=f"g{gen}_{tod}_{seed}", **kw)
            tag = f"g{gen}_{seed}_{tod}_{weather if gen == 2 else 'v1'}"
            f = tmp / f"{tag}.json"
            atomic_write_text(f, json.dumps(sc))
            home = tmp / f"home_{tag}"
            home.mkdir()
            copies = []
            for i in range(a.marginal):  # the same scene under other ids, for the N-scene run
                g = tmp / f"{tag}_copy{i}.json"
                atomic_write_text(g, json.dumps({**sc, "scene_id": f"{sc['scene_id']}_{i}"}))
                copies += ["--scene", str(g)]
            return {"tag": tag, "home": home, "extra": ("--scene", str(f), *extra_v), "seed": seed,
                    "objects": _objects(sc), "warm": [], "copies": (*copies, *extra_v)}

        def render(case, kind):
            out = tmp / f"{kind}_{case['tag']}"
            extra = case["copies"] if kind == "many" else case["extra"]
            r = run_case(case["home"], out, profile, case["seed"], extra=extra)
            shutil.rmtree(out)  # a 640x360 corpus is 50-130 MB
            print(case["tag"], kind, r, f"load {os.getloadavg()[0]:.1f}", flush=True)
            return r

        def median(runs):
            return {"seconds": statistics.median(r["seconds"] for r in runs),
                    "cpu_s": statistics.median(r["cpu_s"] for r in runs), "kernels": runs[0]["kernels"],
                    "mb": runs[0]["mb"]}

        for seed, tod, weather in cases:
            new1 = (seed, tod) not in v1
            if new1:
                v1[seed, tod] = prepare(1, seed, tod, None)
            c1, c2 = v1[seed, tod], prepare(2, seed, tod, weather)
            if new1:
                c1["cold"] = render(c1, "cold")
            c2["cold"] = render(c2, "cold")
            for _ in range(a.repeats):  # alternating, so that a change of load hits both alike
                if new1:
                    c1["warm"].append(render(c1, "warm"))
                c2["warm"].append(render(c2, "warm"))
            for c in (c1, c2) if new1 else (c2,):
                c["many"] = render(c, "many") if a.marginal else None
            rows.append((seed, tod, weather, (c1["cold"], median(c1["warm"]), c1["objects"], c1["many"]),
                         (c2["cold"], median(c2["warm"]), c2["objects"], c2["many"])))
    load1 = os.getloadavg()[0]
    lines = [SECTION, "",
             f"Generated by `benchmarks/bench_render_v2.py` (1-minute load average {load0:.1f} at the start, "
             f"{load1:.1f} at the end): the same seed and time of day from generator 1 (lfmbench-v1) and generator 2 "
             "(lfmbench-v2), one scene file each, `lfmbench render --scene FILE --profile "
             f"{a.profile} --workers 1{' --variant ' + a.variant if a.variant else ''}`"
             f"{' with texture_filter ' + a.texture_filter if a.texture_filter else ''} in a child process; cold: a "
             "new empty `HOME` (kernel cache), warm: the same scene again with that `HOME`, the median of "
             f"{a.repeats} renders (generators alternating). Seconds: wall (CPU of the child, user + system). "
             + (f" Per extra scene: (t_{a.marginal} - t_1) / {a.marginal - 1} of a {a.marginal}-scene run of copies "
                "of the scene (warm), t_1 the warm median: what each scene of a corpus costs." if a.marginal else "")
             + " Target (issue 23): v2 at most 1.5x v1.", "",
             "| seed | time of day | v2 weather | v1 scene | v2 scene | v1 cold (s) | v2 cold (s) | cold ratio wall "
             "(CPU) | v1 warm (s) | v2 warm (s) | warm ratio wall (CPU) | per extra scene v1 / v2 (s) | its ratio "
             "wall (CPU) | kernels cold v1 / v2 | corpus MB v1 / v2 |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]

    def extra_scene(w, many):
        if many is None:
            return None
        return {k: (many[k] - w[k]) / (a.marginal - 1) for k in ("seconds", "cpu_s")}

    for seed, tod, weather, (c1, w1, o1, n1), (c2, w2, o2, n2) in rows:
        m1, m2 = extra_scene(w1, n1), extra_scene(w2, n2)
        marg = (f"{m1['seconds']:.1f} ({m1['cpu_s']:.1f}) / {m2['seconds']:.1f} ({m2['cpu_s']:.1f}) | "
                f"{m2['seconds'] / m1['seconds']:.2f} ({m2['cpu_s'] / m1['cpu_s']:.2f})") if m1 else "- | -"
        lines.append(
            f"| {seed} | {tod} | {weather} | {o1} | {o2} | {c1['seconds']:.1f} ({c1['cpu_s']:.1f}) | "
            f"{c2['seconds']:.1f} ({c2['cpu_s']:.1f}) | {c2['seconds'] / c1['seconds']:.2f} "
            f"({c2['cpu_s'] / c1['cpu_s']:.2f}) | {w1['seconds']:.1f} ({w1['cpu_s']:.1f}) | "
            f"{w2['seconds']:.1f} ({w2['cpu_s']:.1f}) | {w2['seconds'] / w1['seconds']:.2f} "
            f"({w2['cpu_s'] / w1['cpu_s']:.2f}) | {marg} | {c1['kernels']} / {c2['kernels']} | "
            f"{c1['mb']:.0f} / {c2['mb']:.0f} |")
    lines += ["", "Run again with `python benchmarks/bench_render_v2.py`.", ""]
    replace_section(Path(a.out) / "benchmarks" / "render-scale.md", SECTION, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
