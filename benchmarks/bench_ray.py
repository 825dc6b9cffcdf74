"""Scenes per hour: one process against a local process pool and a local Ray cluster (issue 9).

Each case runs ``lfmbench render --scenes N --profile P`` in a child process, as a user would, into a new corpus,
with a warm Dr.Jit kernel cache (one scene rendered first into a scratch corpus, so that every case meets the
same cache; the first scene of each case still compiles the kernel of its own scene layouts if they are new).
Cases: ``--workers 1`` (one process, Dr.Jit's thread pool on every core), ``--workers W`` (a process pool) and
``--ray-address local --workers W`` (Ray starts a local instance with W CPUs). Reports wall time, scenes per hour
and the ratio to the one-process run, and writes docs/benchmarks/ray.md.

Usage: ``python benchmarks/bench_ray.py [--scenes 6] [--profile small] [--workers 2] [--out docs]``.

``--cluster``: instead, two Ray clusters on loopback started here (``ray start --block`` processes, one CPU per
node), one of 1 node and one of 2 nodes, both up for the whole run: ``lfmbench render --ray-address HOST:PORT``
of the same tiny scenes (default 64 x 36 px, 2 spp) on each in turn, ``--repeats`` times; the ratio of the medians
is the 2-node scaling (issue 41). Writes ``docs/benchmarks/ray-cluster.md``.
"""
from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH

from lfmbench.fileio import atomic_write_text  # noqa: E402


def render(out: Path, scenes: int, profile: str, seed: int, extra=()) -> float:
    """Wall seconds of one ``lfmbench render`` run (raises with its output on failure)."""
    cmd = [sys.executable, "-m", "lfmbench.cli", "render", "--out", str(out), "--scenes", str(scenes), "--profile",
           profile, "--seed", str(seed), *extra]
    t = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, cwd=str(ROOT), env=dict(os.environ))
    dt = time.perf_counter() - t
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{res.stdout[-2000:]}\n{res.stderr[-4000:]}")
    return dt


def _start_node(args: list[str], log: Path, env: dict) -> subprocess.Popen:
    """A ``ray start --block`` node (stopped by terminating it), once it says it started."""
    cmd = [str(Path(sys.executable).with_name("ray")), "start", "--block", "--disable-usage-stats", *args]
    p = subprocess.Popen(cmd, stdout=log.open("w"), stderr=subprocess.STDOUT, env=env, start_new_session=True)
    for _ in range(1200):
        if "Ray runtime started" in log.read_text() or p.poll() is not None:
            break
        time.sleep(0.25)
    if p.poll() is not None:
        raise RuntimeError(f"ray start failed:\n{log.read_text()[-2000:]}")
    return p


def _port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cluster(n: int, tmp: Path, env: dict) -> tuple[str, list[subprocess.Popen]]:
    """A loopback Ray cluster of ``n`` nodes of one CPU each (its own ports and temp folder): address, nodes."""
    port = _port()
    nodes = [_start_node(["--head", f"--port={port}", "--num-cpus=1", "--include-dashboard=false",
                          f"--ray-client-server-port={_port()}", f"--dashboard-agent-listen-port={_port()}",
                          f"--temp-dir={tmp / f't{n}'}"], tmp / f"head{n}.log", env)]
    for k in range(1, n):
        nodes.append(_start_node([f"--address=127.0.0.1:{port}", "--num-cpus=1",
                                  f"--dashboard-agent-listen-port={_port()}"], tmp / f"node{n}-{k}.log", env))
    return f"127.0.0.1:{port}", nodes


def cluster(a) -> None:
    """The 2-node case (``--cluster``): a 1-node and a 2-node cluster on loopback, both up for the whole run, the
    same render on each in turn (1, 2, 1, 2, ...), ``--repeats`` times; medians and their ratio."""
    import shutil
    import statistics

    env = {**os.environ, "RAY_AUTH_MODE": "disabled", "PYTHONPATH": str(ROOT)}
    os.environ["RAY_AUTH_MODE"] = "disabled"
    size = ["--width", str(a.width), "--height", str(a.height), "--spp", str(a.spp)]
    times: dict[int, list[float]] = {1: [], 2: []}
    nodes: list[subprocess.Popen] = []
    load0 = os.getloadavg()
    tmp = Path(tempfile.mkdtemp(prefix="lfr", dir="/tmp"))  # short: Ray's socket paths must fit 107 bytes
    try:
        render(tmp / "warm", 1, a.profile, 999, ["--workers", "1", *size])  # the kernel cache, the probe verdict
        addr = {}
        for n in (1, 2):
            addr[n], started = _cluster(n, tmp, env)
            nodes += started
        time.sleep(3.0)
        for r in range(a.repeats):
            for n in (1, 2):
                dt = render(tmp / f"n{n}r{r}", a.scenes, a.profile, 1000, ["--ray-address", addr[n], *size])
                times[n].append(dt)
                print(f"{n} node(s), repeat {r + 1}: {dt:.1f} s", flush=True)
    finally:
        for p in reversed(nodes):
            p.terminate()
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()
        shutil.rmtree(tmp, ignore_errors=True)
    load1 = os.getloadavg()
    med = {n: statistics.median(v) for n, v in times.items()}
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), platform.machine()) if Path("/proc/cpuinfo").exists() else \
        platform.machine()
    cmd = (f"benchmarks/bench_ray.py --cluster --scenes {a.scenes} --profile {a.profile} --width {a.width} "
           f"--height {a.height} --spp {a.spp} --repeats {a.repeats}")
    lines = ["# Scenes per hour on a 2-node Ray cluster (loopback)", "",
             f"Generated by `{cmd}` on {stamp} ({cpu}, {os.cpu_count()} CPUs; load average {load0[0]:.1f} at the "
             f"start, {load1[0]:.1f} at the end: a shared machine, the other jobs' load included). Two clusters run "
             "on this machine for the whole run (`ray start`, one CPU per node): one of 1 node, one of 2 nodes. "
             f"Each case renders the same {a.scenes} new scenes ({a.width} x {a.height} px, {a.spp} spp, profile "
             f"`{a.profile}`) with `lfmbench render --ray-address` into a new corpus (the shared-folder check "
             "included), warm Dr.Jit kernel cache; wall time of the whole command, the driver's start included. The "
             f"cases alternate (1 node, 2 nodes, 1 node, ...), {a.repeats} times each; medians.", "",
             "| case | wall s (median) | runs, s | scenes / h | vs 1 node |", "|---|---|---|---|---|"]
    for n in (1, 2):
        lines.append(f"| {n} node{'s' if n > 1 else ''} (1 CPU each) | {med[n]:.1f} | "
                     f"{', '.join(f'{t:.1f}' for t in times[n])} | {a.scenes / med[n] * 3600:.0f} | "
                     f"{med[1] / med[n]:.2f} |")
    lines += ["", "A scene task runs Dr.Jit's kernels on as many threads as CPUs it asked Ray for (1 here; "
              "render_tools/ray_jobs.py, `task_threads`), so each node uses its one CPU, as a 1-CPU machine would; "
              "before that every task ran a thread per core of the machine and the second node added only the "
              "overlap of the single-threaded parts (1.39x at load 15-20 on 2026-11-28, 4 scenes of the `small` "
              "profile). The render worker no longer imports torch (the PWM model's numpy path loads it only when "
              "given a tensor): a worker's first scene starts seconds sooner, on every node and in every pool "
              "worker. The fixed part of the command (the driver's imports and connection, the shared-folder check, "
              "each node's first task starting its worker process) is paid once per run whatever the number of "
              "nodes; it is what keeps the ratio under 2.", ""]
    out = ROOT / "docs" / "benchmarks" / "ray-cluster.md"
    atomic_write_text(out, "\n".join(lines))
    print(f"1 node {med[1]:.1f} s, 2 nodes {med[2]:.1f} s: {med[1] / med[2]:.2f}x; wrote {out}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", type=int, default=6)
    ap.add_argument("--profile", default="small")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "docs"))
    ap.add_argument("--cluster", action="store_true", help="the 2-node loopback cluster case (ray-cluster.md)")
    ap.add_argument("--width", type=int, default=64, help="--cluster: scene width, px")
    ap.add_argument("--height", type=int, default=36, help="--cluster: scene height, px")
    ap.add_argument("--spp", type=int, default=2, help="--cluster: samples per pixel")
    ap.add_argument("--repeats", type=int, default=3, help="--cluster: runs of each case (alternating)")
    a = ap.parse_args()
    if a.cluster:
        cluster(a)
        return
    try:
        import ray  # noqa: F401,PLC0415
        have_ray = True
    except ImportError:
        have_ray = False
    cases = [("one process", ["--workers", "1"]), (f"process pool, {a.workers} workers", ["--workers", str(a.workers)])]
    if have_ray:
        cases.append((f"Ray local, {a.workers} workers", ["--ray-address", "local", "--workers", str(a.workers)]))
    rows = []
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="lfm_ray_") as tmp:
        tmp = Path(tmp)
        render(tmp / "warm", 1, a.profile, 999, ["--workers", "1"])  # warm the kernel cache and the probe verdict
        for i, (name, extra) in enumerate(cases):
            # the same scenes (seeds) in every case, each into its own new corpus
            dt = render(tmp / f"case{i}", a.scenes, a.profile, 1000, extra)
            rows.append((name, dt, a.scenes / dt * 3600.0))
            print(f"{name}: {dt:.1f} s, {rows[-1][2]:.0f} scenes/h", flush=True)
    load1 = os.getloadavg()
    base = rows[0][2]
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = ["# Scenes per hour: one process, a process pool, a local Ray cluster", "",
             f"Generated by `benchmarks/bench_ray.py --scenes {a.scenes} --profile {a.profile} --workers {a.workers}` "
             f"on {stamp} ({platform.machine()}, {os.cpu_count()} CPUs; load average {load0[0]:.1f} at the start, "
             f"{load1[0]:.1f} at the end). Each case renders the same {a.scenes} new scenes (seeds 1000..) with "
             "`lfmbench render` into a new corpus, warm Dr.Jit kernel cache; wall time of the whole command, "
             "start-up (and Ray's) included.", "",
             "| case | wall s | scenes / h | vs one process |", "|---|---|---|---|"]
    lines += [f"| {n} | {dt:.1f} | {sph:.0f} | {sph / base:.2f} |" for n, dt, sph in rows]
    if not have_ray:
        lines += ["", "Ray is not installed here (`pip install 'lfmbench[distributed]'`): its row is missing."]
    lines += ["", "One process runs Dr.Jit's kernels on every core, but part of a small new scene is single-threaded: scene generation, Mitsuba scene loading, the last frame's encoding, and the LLVM compile of a kernel class's first scene (docs/guide/rendering.md; until 2026-11-24 every new scene compiled its own kernel, and the process pool was 2.2x one process, as two workers overlapped those compiles; with the compiles gone the rendering, which already uses both cores, is most of the time). Ray pays for its start-up (a local instance, a few s) and task dispatch. On a cluster, Ray's scenes per hour scale with its nodes: each worker renders whole scenes and writes them atomically into the shared corpus folder (which every node must see).", ""]
    out = Path(a.out) / "benchmarks" / "ray.md"
    atomic_write_text(out, "\n".join(lines))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
