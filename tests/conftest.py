"""Shared fixtures of the test suite. Fake data comes from ``tests/data/<name>/data.py`` (import those modules;
test modules never import each other)."""
from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

import pytest

# the repository root, so that ``tests.data`` imports the same way under ``pytest`` and ``python -m pytest``
_ROOT = str(Path(__file__).resolve().parents[1])
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)


#: What a render test says when this machine cannot run it (one line, also in CI's log).
NO_JIT = ("renders need a JIT variant of Mitsuba: no working libLLVM 19 here (install it as root with "
          "`apt-get install libllvm19`, which `make test` does; README 'System dependency')")


@functools.lru_cache(maxsize=1)
def jit_unavailable() -> str | None:
    """None when ``llvm_ad_spectral`` or ``cuda_ad_spectral`` renders on this machine (the probe verdicts of
    ``render_tools.backend`` are cached on disk, so this costs a child process once per machine), else why not."""
    from render_tools import backend

    if any(backend.probe_llvm(lib) for lib in backend.find_libllvm()) or backend.probe_cuda():
        return None
    return NO_JIT


def torch_threads_per_worker(environ=os.environ) -> int | None:
    """Torch threads for one pytest-xdist worker: this machine's cores shared out between the workers (at least
    1), or None outside xdist and where the caller chose (``OMP_NUM_THREADS`` set).

    Why: each worker's torch otherwise starts one OpenMP thread per core, so ``-n 2`` on 2 cores runs 4 busy
    threads whose spin-waits compete for 2 cores; on this suite's tiny tensors that tripled the CPU time of the
    torch-heavy tests (measured 2026-11-26: tests/datasets, evaluation, sensor, baselines 187 s of CPU -> 55 s). Tests that
    need several threads ask for them (``threads=3``, ``--threads``) and still get them."""
    workers = environ.get("PYTEST_XDIST_WORKER_COUNT")
    if not workers or environ.get("OMP_NUM_THREADS"):
        return None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, cores // max(1, int(workers)))


def pytest_configure(config):
    config.addinivalue_line("markers", "jit: renders with Mitsuba's JIT back end (skipped, with one line saying "
                                       "why, where no libLLVM 19 works; never skipped in CI)")
    threads = torch_threads_per_worker()
    if threads is not None:
        import torch

        torch.set_num_threads(threads)


def pytest_runtest_setup(item):
    """Tests marked ``jit`` skip where no JIT variant works, all under one reported line (the skip is raised
    here, so pytest groups them by this location). CI (``CI`` set) installs libllvm19 and must run them: there
    they are not skipped, and fail with the renderer's own error if the set-up did not work."""
    if item.get_closest_marker("jit") is not None and not os.environ.get("CI"):
        reason = jit_unavailable()
        if reason:
            pytest.skip(reason)


@pytest.fixture
def fake(monkeypatch):
    """``render_tools.jobs.default_backend`` replaced by the fake renderer of ``tests/data/render/data.py``, run
    in this process (``workers=1``); yields the list of scene ids it was called for."""
    from render_tools import jobs as J
    from tests.data.render.data import CALLS, FAIL, fake_backend

    CALLS.clear()
    FAIL.clear()
    monkeypatch.setattr(J, "default_backend", fake_backend)
    monkeypatch.setattr(J, "ISOLATE_RENDERS", False)  # the fake and its CALLS / FAIL live in this process
    yield CALLS
    FAIL.clear()


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """A 3-scene fake corpus (``tests.data.corpus.data.make_corpus``, 16 x 24 px, 3 frames), shared by the tests
    of a module (a module may define its own ``corpus``)."""
    from tests.data.corpus.data import make_corpus

    return make_corpus(tmp_path_factory.mktemp("corpus"))
