"""A Ray scene task uses the CPUs it asked for (render_tools.ray_jobs.task_threads: Dr.Jit's thread pool at
ceil(cpus)), and the render path loads no torch (the PWM model's numpy path; seconds of every worker's start)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from render_tools.ray_jobs import _ray_job, task_threads

ROOT = Path(__file__).resolve().parents[2]


def test_task_threads_are_the_cpus_asked_for():
    assert [task_threads(c) for c in (1.0, 0.5, 2, 2.5, 0)] == [1, 1, 2, 3, None]


def test_the_scene_task_renders_on_its_threads(tmp_path):
    dr = pytest.importorskip("drjit")
    before = dr.thread_count()
    seen = []

    class Job:
        out = str(tmp_path)

    def run_job(job):
        seen.append(dr.thread_count())
        (tmp_path / "f.bin").write_bytes(b"abc")
        return {"hashes": {"f.bin": "x"}}

    try:
        res = _ray_job(Job(), run_job, threads=1)
        assert seen == [1] and res["sizes"] == {"f.bin": 3}
        _ray_job(Job(), run_job, threads=None)  # a GPU scene (no CPUs asked for): the pool is left as it is
        assert seen[-1] == 1
    finally:
        dr.set_thread_count(before)


def test_the_render_path_imports_no_torch():
    """Rendering, the closed PWM forms and the static denoiser (Open Image Denoise on a uniform frame) run without
    torch in the process (its import costs a render worker seconds of CPU)."""
    code = ("import sys; import render_tools.jobs, render_tools.render, render_tools.ray_jobs; "
            "from lfmbench.flicker import pwm_exposure, flicker_severity; import numpy as np; "
            "x = pwm_exposure(np.array([0.001]), 0.004, 0.01, 0.3, backend='numpy'); "
            "f = flicker_severity(np.array([1.0, 3.0])); "
            "from render_tools.denoise import denoise_static; "
            "d = denoise_static({'a': np.ones((4, 24, 32), np.float32)}, boxes=[(2, 2, 6, 6)]); "
            "print('torch' in sys.modules, round(float(x[0]), 12), float(f))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=str(ROOT),
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0, r.stderr[-2000:]
    # no torch; the closed forms' numbers: ON over [0, 0.003) of each 0.01 s, 0.002 s of it inside [0.001, 0.005);
    # FSI (3 - 1) / (3 + 1)
    assert r.stdout.split() == ["False", "0.002", "0.5"], r.stdout
