"""The Triton kernels under Triton's interpreter on the CPU, against the torch forms (``tests/data/triton/data.py``,
in a child process: ``TRITON_INTERPRET=1`` must be set before Triton is imported). Skips where Triton is not
installed (it is in the ``dev`` extra)."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.integration
@pytest.mark.skipif(importlib.util.find_spec("triton") is None, reason="Triton is not installed (the dev extra)")
def test_triton_kernels_under_the_interpreter_equal_the_torch_forms():
    env = {**os.environ, "TRITON_INTERPRET": "1", "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, "-m", "tests.data.triton.data"], cwd=ROOT, env=env, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-4000:]
    oks = [line for line in r.stdout.splitlines() if line.startswith("OK ")]
    assert len(oks) == 5, r.stdout
