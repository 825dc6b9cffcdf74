"""Render time of a benchmark protocol as a new user meets it: ``lfmbench render --protocol NAME`` in a child
process with ``HOME`` at a fresh temporary folder (empty Dr.Jit kernel cache ``~/.drjit``, no LLVM probe
verdict), the 1-minute load average sampled every 10 s (other jobs on a shared machine slow a render down).

Per-scene times come from the corpus itself: scene k's time is the modification time of its ``meta.json``
minus that of the scene finished before it (the first scene includes Python start, the LLVM probe and the
first kernel compilations). ``--analyze DIR`` reports on an already rendered corpus without rendering.

Usage: ``python benchmarks/bench_protocol.py [--protocol lfmbench-v1-mini] [--corpus DIR] [--no-doc]`` (writes the
section "Latest run: NAME" of docs/benchmarks/protocol.md); ``python benchmarks/bench_protocol.py --analyze
/tmp/v1mini`` (prints only).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH
from _timing import load_line, replace_section  # noqa: E402

DOC = ROOT / "docs" / "benchmarks" / "protocol.md"


def _load1() -> float:
    return float(Path("/proc/loadavg").read_text().split()[0])


def scene_times(corpus: Path) -> list[tuple[str, str, float]]:
    """(scene id, time of day, seconds) per complete scene, in the order they finished (from meta.json mtimes);
    the first scene's time is unknown without the start time and is left out."""
    man = json.loads((corpus / "manifest.json").read_text())
    done = sorted((corpus / "scenes" / s / "meta.json").stat().st_mtime for s in man["scenes"])
    rows = []
    by_t = {(corpus / "scenes" / s / "meta.json").stat().st_mtime: s for s in man["scenes"]}
    for a, b in zip(done, done[1:]):
        sid = by_t[b]
        tod = json.loads((corpus / "scenes" / sid / "scene.json").read_text())["time_of_day"]
        rows.append((sid, tod, b - a))
    return rows


def report(corpus: Path, wall_s: float | None, loads: list[float]) -> str:
    rows = scene_times(corpus)
    man = json.loads((corpus / "manifest.json").read_text())
    lines = [f"corpus {corpus}: {len(man['scenes'])} complete scenes, protocol "
             f"{(man.get('render') or {}).get('protocol')}"]
    if wall_s is not None:
        lines.append(f"wall time {wall_s:.0f} s ({wall_s / 60:.1f} min), 1-minute load average min / median / max "
                     f"{min(loads):.1f} / {statistics.median(loads):.1f} / {max(loads):.1f}")
    lines += ["", "| time of day | scenes | median s per scene | mean s per scene |", "|---|---|---|---|"]
    for tod in ("day", "dusk", "night", None):
        t = [r[2] for r in rows if tod is None or r[1] == tod]
        if t:
            lines.append(f"| {tod or 'all'} | {len(t)} | {statistics.median(t):.1f} | {statistics.mean(t):.1f} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--protocol", default="lfmbench-v1-mini")
    ap.add_argument("--corpus", default=None, help="output corpus (default: a temporary folder)")
    ap.add_argument("--analyze", default=None, help="only report on this rendered corpus")
    ap.add_argument("--no-doc", action="store_true", help="do not write docs/benchmarks/protocol.md")
    a = ap.parse_args()
    if a.analyze:
        print(report(Path(a.analyze), None, []))
        return
    with tempfile.TemporaryDirectory() as home, tempfile.TemporaryDirectory() as tmp:
        out = Path(a.corpus or Path(tmp) / "corpus")
        loads, stop = [_load1()], threading.Event()

        def sample():
            while not stop.wait(10.0):
                loads.append(_load1())

        th = threading.Thread(target=sample, daemon=True)
        th.start()
        env = dict(os.environ, HOME=home, PYTHONUNBUFFERED="1")
        cmd = [sys.executable, "-m", "lfmbench.cli", "render", "--protocol", a.protocol, "--out", str(out)]
        t = time.perf_counter()
        res = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=str(ROOT))
        wall = time.perf_counter() - t
        stop.set()
        print(f"$ {' '.join(cmd[1:])}  (exit status {res.returncode}; {res.stdout.strip().splitlines()[-1:]})")
        text = report(out, wall, loads)
        print(text)
    if not a.no_doc and res.returncode == 0:
        heading = f"## Latest run: {a.protocol}"
        replace_section(DOC, heading, [heading, "", f"Run on {load_line()} at its end; this project's machine "
                                       f"({os.cpu_count()} CPU cores), `HOME` a new empty folder.", "",
                                       f"`lfmbench render --protocol {a.protocol} --out DIR`:", "",
                                       text.split("\n", 1)[1].strip(), ""])


if __name__ == "__main__":
    main()
