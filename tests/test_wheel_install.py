"""The package as a user installs it: the wheel built from this tree, installed into a fresh virtual environment,
used from an empty folder with a fresh HOME (no source tree, no configs or docs next to it).

Steps (docs/guide/install.md's quick start): render 2 tiny scenes; evaluate two built-in methods and a method module
of the current folder in one call; the leaderboard; a PNG of a sample with a method's output; a 3-step DataLoader
training loop. The environment is created with ``--system-site-packages`` and a ``.pth`` line naming the running
interpreter's site-packages, so torch and the other dependencies are not downloaded again; lfmbench itself comes
from the wheel (checked: ``lfmbench.__file__`` lies inside the new environment), and ``PYTHONPATH`` is unset.
Cost: one wheel build, five short processes and the first compilation of the numba and Dr.Jit kernels in the new
environment and HOME (docs/guide/install.md states the time it took).
"""
from __future__ import annotations

import json
import os
import re
import resource
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = [pytest.mark.slow, pytest.mark.jit, pytest.mark.integration]

DOC = ROOT / "docs" / "guide" / "install.md"


def _doc_loop() -> str:
    """The DataLoader example of docs/guide/install.md ("Quick start"): its one ``python`` block."""
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    assert len(blocks) == 1, f"{DOC}: expected one python block, found {len(blocks)}"
    return blocks[0] + "\nimport lfmbench\nprint('lfmbench from', lfmbench.__file__)\n"


METHOD = "def fuse(batch):\n    return batch['spd_e'].clone()  # the SPD alone, in gt units\n"


def _run(cmd: list[str], cwd: Path, env: dict, what: str, timeout: float = 600) -> str:
    t0, c0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, f"{what} failed ({r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = c1.ru_utime - c0.ru_utime + c1.ru_stime - c0.ru_stime
    print(f"{what}: {time.perf_counter() - t0:.1f} s wall, {cpu:.1f} s CPU")
    return r.stdout + r.stderr


def test_wheel_in_a_fresh_environment_from_an_empty_folder(tmp_path):
    # the tree's package files only (no caches, no runs): what a clone holds
    src = tmp_path / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".cache")
    for name in ("lfmbench", "render_tools"):
        shutil.copytree(ROOT / name, src / name, ignore=ignore)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w",
          str(tmp_path / "wheels"), str(src)], tmp_path, env, "build the wheel")
    wheel, = (tmp_path / "wheels").glob("lfmbench-*.whl")
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", "--system-site-packages", str(venv)], tmp_path, env,
         "create the environment")
    py = venv / "bin" / "python"
    site = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, env=env, check=True).stdout.strip())
    # the dependencies this interpreter has (torch, mitsuba, ...), without the lfmbench installed here: a path
    # on sys.path, its .pth files (an editable install's finder) not run
    (site / "_lfmbench_test_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", "--no-index", str(wheel)],
         tmp_path, env, "install the wheel")
    work, home = tmp_path / "work", tmp_path / "home"
    work.mkdir()
    home.mkdir()
    env["HOME"] = str(home)
    lfm = str(venv / "bin" / "lfmbench")
    (work / "mymethod.py").write_text(METHOD)
    out = _run([lfm, "render", "--out", "corpus", "--scenes", "2", "--profile", "small", "--width", "48",
                "--height", "28", "--spp", "1", "--bins", "2"], work, env, "render 2 scenes")
    assert "2 rendered" in out and "\r" not in out  # progress in a log: plain lines
    out = _run([lfm, "evaluate", "--corpus", "corpus", "--split", "all", "-m", "lpd_only", "-m", "flicker_aware",
                "-m", "mymethod:fuse", "--no-perceptual", "--isp", "none", "--repeats", "2", "--crop", "16"], work, env,
               "evaluate 3 methods")
    for name in ("lpd_only", "flicker_aware", "mymethod_fuse"):
        res = json.loads((work / "runs" / f"{name}.json").read_text())
        assert res["status"] == "complete" and res["aggregate"]["scenes_ok"] == 2, name
    out = _run([lfm, "leaderboard", *sorted(str(p) for p in (work / "runs").glob("*.json"))], work, env,
               "leaderboard")
    assert "n = 2 scene(s)" in out and (work / "runs" / "leaderboard.md").is_file()
    _run([lfm, "plot", "--corpus", "corpus", "--split", "all", "-m", "flicker_aware", "--out", "sample.png"], work,
         env, "plot")
    assert (work / "sample.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (work / "loop.py").write_text(_doc_loop())
    out = _run([str(py), "loop.py"], work, env, "3-step DataLoader loop")
    assert out.count("step ") == 3 and (work / "mine.png").is_file()
    where = Path(out.split("lfmbench from", 1)[1].split()[0]).resolve()
    assert where.is_relative_to(venv.resolve()), f"lfmbench was imported from {where}, not the wheel"
    out = _run([lfm, "configs", "training"], work, env, "configs")
    assert "unet_tiny" in out and str(venv) in out  # the installed configs, where they live
