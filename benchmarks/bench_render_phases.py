"""Where the wall time of `lfmbench render` goes outside the tracer: a phase timeline of the main thread.

The render-scale benchmark (bench_render_scale.py) times the whole command, which on this shared 2-core
machine moves by 30-50 % with the other jobs' load, mostly through the tracing (both cores). This script runs
the same command (`lfmbench render --scenes 1 --workers 1`, default profile, cold = new `HOME`, warm = the same
`HOME` again) in a child process whose functions are wrapped with timers, and reports the main thread's time
inside the tracer (`Tracer.render`, `Tracer.hits`) and outside it, split into: waiting for the back-end probe
(`select_variant`), scene generation and metadata, Mitsuba scene dicts and their loading, waiting for the
EXR writer thread (`ThreadedSceneWriter.put` / `close`: the last frame's encoding), and the rest (Python
start and imports, tile planning, AOV maps, ...). The EXR encoding done in writer threads is listed apart
(summed over threads; it overlaps the tracing). user / sys: CPU seconds of the child, less sensitive to load.
The child renders in its own process (``render_tools.jobs.ISOLATE_RENDERS`` off): the command's supervised worker
process, its start and its imports, are not in the timeline.

Usage: ``python benchmarks/bench_render_phases.py [--seeds 101,202] [--profile default] [--out docs]`` (writes
the section "Render phases" of docs/benchmarks/render-scale.md; about 3 minutes on a quiet machine).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH

from _timing import replace_section  # noqa: E402

#: Heading of this script's section of docs/benchmarks/render-scale.md.
SECTION = "## Render phases: the main thread outside the tracer"

#: (label, module path, attribute path) of the functions timed in the child.
TIMED = [("trace", "render_tools.tracer", "Tracer.render"), ("trace", "render_tools.tracer", "Tracer.hits"),
         ("probe_wait", "render_tools.backend", "select_variant"),
         ("scene", "render_tools.scene", "generate_scene"), ("scene", "render_tools.render", "scene_meta"),
         ("mitsuba_dict", "render_tools.mitsuba_scene", "mitsuba_dict"), ("load_dict", "mitsuba", "load_dict"),
         ("encode", "lfmbench.corpus.scene_files", "encode_static_exr"),
         ("encode", "lfmbench.corpus.scene_files", "encode_lights_exr"),
         ("encode", "lfmbench.corpus.scene_files", "encode_aux_exr"),
         ("write", "lfmbench.corpus.scene_files", "atomic_write_bytes"),
         ("writer_wait", "lfmbench.corpus.scene_files", "ThreadedSceneWriter.put"),
         ("writer_wait", "lfmbench.corpus.scene_files", "ThreadedSceneWriter.close")]


def child(out: str, seed: int, profile: str) -> None:
    """Run the command in this process with the functions of :data:`TIMED` wrapped; print the phases (JSON)."""
    import functools  # noqa: PLC0415
    import importlib  # noqa: PLC0415
    import threading  # noqa: PLC0415

    t0 = time.perf_counter()
    acc: dict[str, float] = {}
    depth = {"n": 0}  # load_dict inside mitsuba_dict counts as mitsuba_dict

    def wrap(owner, name: str, label: str) -> None:
        f = getattr(owner, name)

        @functools.wraps(f)
        def g(*a, **k):
            main = threading.current_thread() is threading.main_thread()
            nested = main and label == "load_dict" and depth["n"] > 0
            depth["n"] += main and label == "mitsuba_dict"
            t = time.perf_counter()
            try:
                return f(*a, **k)
            finally:
                depth["n"] -= main and label == "mitsuba_dict"
                if not nested:
                    key = label if main else f"thread:{label}"
                    acc[key] = acc.get(key, 0.0) + time.perf_counter() - t
        setattr(owner, name, g)

    for label, mod, attr in TIMED:
        try:
            owner = importlib.import_module(mod)
            *path, name = attr.split(".")
            for p in path:
                owner = getattr(owner, p)
            getattr(owner, name)
        except (ImportError, AttributeError):  # an older tree without the threaded writer
            continue
        wrap(owner, name, label)
    from lfmbench.cli import app  # noqa: PLC0415
    from render_tools import jobs  # noqa: PLC0415

    # `lfmbench render` renders in a supervised worker process (since e34fdab), where these timers are not: render
    # in this process instead, as the command did before (the worker's start and imports are not in the timeline)
    jobs.ISOLATE_RENDERS = False
    try:
        app(["render", "--out", out, "--scenes", "1", "--profile", profile, "--seed", str(seed), "--workers", "1"])
    except SystemExit as exc:
        if exc.code:
            raise
    acc["total"] = time.perf_counter() - t0
    print("PHASES " + json.dumps(acc))


def run_case(home: Path, out: Path, seed: int, profile: str) -> dict:
    env = dict(os.environ, HOME=str(home))
    env.pop("XDG_CACHE_HOME", None)
    load = os.getloadavg()[0]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    res = subprocess.run([sys.executable, __file__, "--child", str(out), str(seed), profile], env=env, capture_output=True,
                         text=True, cwd=str(ROOT))
    wall = time.perf_counter() - t
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    line = [ln for ln in res.stdout.splitlines() if ln.startswith("PHASES ")]
    if res.returncode or not line:
        raise RuntimeError(f"seed {seed} failed:\n{res.stdout[-2000:]}\n{res.stderr[-4000:]}")
    ph = json.loads(line[0][len("PHASES "):])
    ph.update(wall=wall, user=r1.ru_utime - r0.ru_utime, sys=r1.ru_stime - r0.ru_stime, load=load)
    return ph


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="101,202")
    ap.add_argument("--out", default=str(ROOT / "docs"))
    ap.add_argument("--profile", default="default", help="render profile (default: default, 640x360)")
    ap.add_argument("--child", nargs=3, metavar=("OUT", "SEED", "PROFILE"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        child(a.child[0], int(a.child[1]), a.child[2])
        return
    rows = []
    with tempfile.TemporaryDirectory(prefix="lfm_phases_") as tmp:
        tmp = Path(tmp)
        for seed in (int(s) for s in a.seeds.split(",")):
            home = tmp / f"home_{seed}"
            home.mkdir()
            for case in ("cold", "warm"):
                ph = run_case(home, tmp / f"{seed}_{case}", seed, a.profile)
                print(case, seed, {k: round(v, 2) for k, v in ph.items()}, flush=True)
                rows.append((seed, case, ph))
    lines = [SECTION, "",
             f"Generated by `benchmarks/bench_render_phases.py`: `lfmbench render --scenes 1 --profile {a.profile} "
             "--workers 1` (all groups, 3 frames) in a child process with timed functions, rendering in that process "
             "(`render_tools.jobs.ISOLATE_RENDERS` off: the command's supervised worker process, its start and "
             "imports, is not in these times); cold = new "
             "`HOME` (empty `~/.drjit`, no probe verdict), warm = the same scene again with the same `HOME`. "
             "Seconds of wall time of the main thread; *outside* = wall - tracing, split into the columns after "
             "it (*other*: Python start and imports, tile planning, AOV maps, ...). *encode (threads)*: EXR "
             "encoding in the writer's threads, wall time in them summed over threads, overlapping the tracing "
             "(on 2 cores the tracer's threads stretch it: one v1 night frame encodes in 1.0 CPU s alone, measured "
             "2026-11-26). user / sys: CPU "
             "seconds of the child. load: 1-minute load average of this shared 2-core machine before the case.", "",
             "| seed | case | wall | user | sys | tracing | outside | probe wait | scene + meta | Mitsuba dicts | "
             "load_dict | writer wait | other | encode (threads) | load |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for seed, case, p in rows:
        g = p.get
        outside = p["total"] - g("trace", 0.0)
        named = sum(g(k, 0.0) for k in ("probe_wait", "scene", "mitsuba_dict", "load_dict", "writer_wait",
                                         "encode", "write"))
        enc = g("thread:encode", 0.0) + g("thread:write", 0.0)
        wait = g("writer_wait", 0.0) + g("encode", 0.0) + g("write", 0.0)  # serial writer: encoding in main
        lines.append(f"| {seed} | {case} | {p['wall']:.1f} | {p['user']:.1f} | {p['sys']:.1f} | {g('trace', 0):.1f} | "
                     f"{outside:.1f} | {g('probe_wait', 0):.2f} | {g('scene', 0):.2f} | {g('mitsuba_dict', 0):.2f} | "
                     f"{g('load_dict', 0):.2f} | {wait:.2f} | {outside - named:.2f} | {enc:.1f} | {p['load']:.1f} |")
    lines += ["", "Run again with `python benchmarks/bench_render_phases.py` (about 3 minutes).", ""]
    out = Path(a.out) / "benchmarks" / "render-scale.md"
    replace_section(out, SECTION, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
