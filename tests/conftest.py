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


def collected_test_files(config) -> list[Path]:
    """The test modules (``python_files`` patterns) under the run's path arguments, sorted: what collection will
    import. Arguments naming a test (``file.py::test``) count as their file."""
    import fnmatch

    pats = config.getini("python_files")
    files = set()
    for arg in config.args:
        p = Path(config.invocation_params.dir, arg.split("::", 1)[0]).resolve()
        found = p.rglob("*.py") if p.is_dir() else [p] if p.suffix == ".py" else []
        files.update(f for f in found if any(fnmatch.fnmatch(f.name, pat) for pat in pats))
    return sorted(files)


#: The folder where pytest-xdist workers share their rewritten test modules in a run that writes no bytecode
#: (``PYTHONDONTWRITEBYTECODE``): made by the controller (:func:`rewrite_dir_for_workers`), removed at its end.
REWRITE_DIR_ENV = "LFMBENCH_TEST_REWRITE_DIR"


def _shared_cache_dir(root: Path, tail: str, file_path: Path) -> Path:
    """pytest's ``get_cache_dir`` for :data:`REWRITE_DIR_ENV`: the usual ``__pycache__`` where it holds a rewritten
    pyc of the module (``tail``: pytest's ``PYC_TAIL``), else one subfolder of ``root`` per test folder."""
    import hashlib

    classic = file_path.parent / "__pycache__"
    if (classic / (file_path.name[:-3] + tail)).is_file():
        return classic
    return root / hashlib.sha256(str(file_path.parent).encode()).hexdigest()[:16]


def rewrite_dir_for_workers(config, environ=os.environ) -> str | None:
    """On the pytest-xdist controller of a run that writes no bytecode: a new temporary folder, named in
    ``environ[REWRITE_DIR_ENV]`` for the workers it starts (they inherit its environment), where
    :func:`share_assert_rewriting` puts the rewritten test modules; None elsewhere (a worker, no ``-n``, bytecode
    written next to the sources as usual). :func:`pytest_unconfigure` removes it."""
    if not sys.dont_write_bytecode or environ.get("PYTEST_XDIST_WORKER") or not getattr(config.option, "tx", None) \
            or getattr(config.option, "dist", "no") == "no":
        return None
    import tempfile

    environ[REWRITE_DIR_ENV] = tempfile.mkdtemp(prefix="lfmbench-rewritten-tests-")
    return environ[REWRITE_DIR_ENV]


def share_assert_rewriting(config, environ=os.environ) -> int:
    """Rewrite the asserts of this pytest-xdist worker's share of the test modules into pytest's pyc cache before
    collection; returns how many it rewrote (0 outside xdist, with ``--assert=plain``, without bytecode writing).

    Why: every xdist worker collects every test module and, on a fresh clone (no cached rewritten pycs), rewrites
    the asserts of all of them at once with the other worker: 7.1 s of CPU each for this suite's 112 modules (2,735
    asserts; pytest's AST rewrite, measured 2026-11-28), twice over. Worker k of n rewrites modules k, k + n, ...
    first, so by collection each finds the others' pycs written (pytest reads them as it reads its own; a module
    not yet written is rewritten as before). The rewriting is pytest's own (``_pytest.assertion.rewrite``, the
    steps of its import hook): assertion messages are unchanged. Its private functions may change with pytest:
    then this does nothing and collection rewrites every module itself, as it did.

    Where bytecode is not written (``PYTHONDONTWRITEBYTECODE=1``) pytest writes no pyc
    and each worker rewrote all modules on every run: then the pycs go to the controller's temporary folder
    (:data:`REWRITE_DIR_ENV`; pytest reads a cached pyc even when it writes none), nothing next to the sources."""
    worker, count = environ.get("PYTEST_XDIST_WORKER", ""), environ.get("PYTEST_XDIST_WORKER_COUNT", "")
    if not worker.startswith("gw") or not count.isdigit() or int(count) < 2:
        return 0
    if getattr(config.option, "assertmode", "rewrite") != "rewrite":
        return 0
    shared = environ.get(REWRITE_DIR_ENV, "")
    if sys.dont_write_bytecode and not (shared and os.path.isdir(shared)):
        return 0
    try:
        from _pytest.assertion import rewrite as rw

        if sys.dont_write_bytecode:  # nothing next to the sources: the pycs go to the controller's folder
            rw.get_cache_dir = functools.partial(_shared_cache_dir, Path(shared), rw.PYC_TAIL)
        state = config.stash[rw.assertstate_key]
        done = 0
        for fn in collected_test_files(config)[int(worker[2:])::int(count)]:
            cache = rw.get_cache_dir(fn)
            pyc = cache / (fn.name[:-3] + rw.PYC_TAIL)
            if not rw.try_makedirs(cache):
                return done
            if rw._read_pyc(fn, pyc, state.trace) is None:
                source_hash, co = rw._rewrite_test(fn, config)
                rw._write_pyc(state, co, source_hash, pyc)
                done += 1
        return done
    except Exception:  # noqa: BLE001 - a cache warm-up only: collection rewrites whatever is missing
        return 0


def pytest_collection_modifyitems(config, items):
    """Modules with long tests first (a test marked ``slow`` or ``jit``: renders that compile kernels), each module's
    tests kept together and in order (module-scoped fixtures are set up once). pytest-xdist hands tests out in
    collection order (``worksteal``, :func:`work_stealing`: the first half to one worker, and a worker that runs dry
    takes the tail of the other's queue), so the long render tests of tests/render_tools and
    tests/test_hostile_input_3 run first and what is left to share at the end is short."""
    heavy = {it.module.__name__ for it in items if getattr(it, "module", None) is not None
             and (it.get_closest_marker("slow") or it.get_closest_marker("jit"))}
    items.sort(key=lambda it: 0 if getattr(it, "module", None) is not None and it.module.__name__ in heavy else 1)


def work_stealing(config) -> bool:
    """Under ``-n N`` with no ``--dist`` given, schedule with pytest-xdist's ``worksteal`` instead of its default
    ``load``; returns whether it did. Another ``--dist`` on the command line is kept.

    Why: ``load`` queues up to a quarter of the remaining tests on each worker, in alternation, and a queued test
    cannot move, so the worker that drew the longer tests ran on alone: 60 s at the end of a 355 s cold run
    (measured 2026-11-28, 2-core AMD EPYC, load ~5: one worker busy 331 s, the other 271 s). ``worksteal`` gives
    each worker one contiguous half of the collection (the modules stay together, so a module's fixtures and
    first imports are paid once) and a worker that runs dry takes half of the other's queue."""
    args = config.invocation_params.args
    explicit = any(a == "-d" or a.startswith("--dist") for a in args)
    if explicit or getattr(config.option, "dist", "no") != "load" or not getattr(config.option, "tx", None):
        return False
    config.option.dist = "worksteal"
    return True


def pytest_configure(config):
    config.addinivalue_line("markers", "jit: renders with Mitsuba's JIT back end (skipped, with one line saying "
                                       "why, where no libLLVM 19 works; never skipped in CI)")
    work_stealing(config)
    rewrite_dir_for_workers(config)
    threads = torch_threads_per_worker()
    if threads is not None:
        import torch

        torch.set_num_threads(threads)
    share_assert_rewriting(config)


def pytest_unconfigure(config):
    shared = os.environ.get(REWRITE_DIR_ENV)
    if shared and not os.environ.get("PYTEST_XDIST_WORKER"):  # the controller made it: the workers are done
        import shutil

        shutil.rmtree(shared, ignore_errors=True)
        os.environ.pop(REWRITE_DIR_ENV, None)


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


@pytest.fixture(scope="module")
def load_study():
    """``load_study(name)`` -> ``benchmarks/studies/<name>.py`` as a module (that folder is no package), under a
    module name of its own."""
    import importlib.util

    def load(name: str):
        path = Path(__file__).resolve().parents[1] / "benchmarks" / "studies" / f"{name}.py"
        spec = importlib.util.spec_from_file_location(f"{name}_study", path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod

    return load
