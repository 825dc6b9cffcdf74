"""The package layout: data flows one way (scene -> corpus -> captures -> estimate -> scores), with no import cycle.

The imports are read from the source (``ast``), at module level and inside functions alike, so an import hidden
in a function body counts as much as one at the top. A module that loads modules by name
(``importlib.import_module``) is taken to import every module of the tree that it names in a string.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("lfmbench", "render_tools")

#: Layers from the bottom up; a module may import modules of its own layer's package or of a lower layer only.
#: Each entry is a module or a package prefix (``lfmbench.sensor`` covers ``lfmbench.sensor.noise``), except the
#: top-level ``lfmbench``, which names only its ``__init__``: a new module must be placed here.
LAYERS = (
    ("lfmbench.limits",),  # the input limits every reader checks (check and fileio quote and bound with it)
    ("lfmbench.resources",),  # shipped configs by name, documentation URLs (lfmbench.docs_url)
    ("lfmbench", "lfmbench.progress", "lfmbench.constants", "lfmbench.check", "lfmbench.fileio",
     "lfmbench.parallel", "lfmbench.vocabulary", "lfmbench.registry", "lfmbench.counter_rng", "lfmbench.triton_kernels",
     "lfmbench._triton_math"),
    ("lfmbench.flicker",),
    ("lfmbench.corpus",),
    ("render_tools", "lfmbench.sensor"),
    ("lfmbench.isp",),  # a sensor's mosaic -> display sRGB (reads the preset's public fields)
    ("lfmbench.datasets",),
    ("lfmbench.metrics",),
    ("lfmbench.baselines",),
    ("lfmbench.distributed",),  # the ranks of a DDP training (their batches, step, process group)
    ("lfmbench.train_step",),  # one optimiser step of the training loop (Adam, schedule, CUDA-graph replay)
    ("lfmbench.train",),
    ("lfmbench.evaluation",),
    ("lfmbench.flicker_bench",),  # the virtual P2020 flicker bench: sensor plans, merges and P2020 metrics on a target
    ("lfmbench.paper",),
    ("lfmbench.cli",),
)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for p in sorted((ROOT / pkg).rglob("*.py")):
            out[_module_name(p)] = p
    return out


MODULES = _modules()


def _target(name: str) -> str | None:
    """The module of the tree that ``import name`` loads last (``a.b.c`` -> ``a.b.c`` or its package)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(mod: str, path: Path) -> set[str]:
    """Modules of the tree that ``mod`` imports anywhere in its body."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    is_pkg = path.name == "__init__.py"
    found: set[str] = set()
    by_name = False
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(filter(None, (_target(a.name) for a in node.names)))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = mod if is_pkg else mod.rpartition(".")[0]
                for _ in range(node.level - 1):
                    base = base.rpartition(".")[0]
                src = f"{base}.{node.module}" if node.module else base
            else:
                src = node.module or ""
            for a in node.names:
                t = _target(f"{src}.{a.name}") if f"{src}.{a.name}" in MODULES else _target(src)
                if t:
                    found.add(t)
        elif isinstance(node, ast.Attribute) and node.attr == "import_module":
            by_name = True
    if by_name:
        found.update(n.value for n in ast.walk(tree)
                     if isinstance(n, ast.Constant) and isinstance(n.value, str) and n.value in MODULES)
    found.discard(mod)
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    """Module -> the modules of the tree it imports; read when a test asks (about 2 s of one core to parse every
    module: not paid at collection by every pytest-xdist worker)."""
    return {m: _imports(m, p) for m, p in MODULES.items()}


def _layer(mod: str) -> tuple[int, str]:
    """(layer index, the entry of :data:`LAYERS` that holds ``mod``): the longest matching prefix."""
    best = None
    for i, entries in enumerate(LAYERS):
        for e in entries:
            covers = mod == e or (e != "lfmbench" and mod.startswith(e + "."))
            if covers and (best is None or len(e) > len(best[1])):
                best = (i, e)
    if best is None:
        raise AssertionError(f"{mod} is in no layer: add it to LAYERS in tests/test_layout.py")
    return best


def _is_parent(a: str, b: str) -> bool:
    """``b`` is a package that holds ``a`` (importing ``a`` runs ``b``'s ``__init__`` first anyway)."""
    return a.startswith(b + ".")


def test_every_module_has_a_layer():
    for m in MODULES:
        _layer(m)


def test_no_import_cycle(graph):
    """Depth-first search for a back edge; an edge from a module to a package holding it is not followed (the
    package's ``__init__`` runs before the module whatever the module imports)."""
    state: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph[m]):
            if _is_parent(m, n):
                continue
            if state.get(n) == 1:
                cycles.append(stack[stack.index(n):] + [n])
            elif n not in state:
                visit(n)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_imports_point_down_the_pipeline(graph):
    """Every import goes to the module's own package entry or to a lower layer: no stage imports a later stage,
    no stage of lfmbench imports render_tools (only lfmbench.cli and lfmbench.paper join them), and render_tools
    imports from lfmbench only what lies below it."""
    bad = []
    for m, targets in graph.items():
        lm, em = _layer(m)
        for t in targets:
            lt, et = _layer(t)
            if lt > lm or (lt == lm and em != et):
                bad.append(f"{m} -> {t}")
    assert not bad, "imports against the flow: " + ", ".join(sorted(bad))


def test_no_library_module_of_lfmbench_imports_render_tools(graph):
    joins = ("lfmbench.cli", "lfmbench.paper")
    bad = sorted(m for m, targets in graph.items()
                 if m.startswith("lfmbench") and not any(m == j or m.startswith(j + ".") for j in joins)
                 and any(t.split(".")[0] == "render_tools" for t in targets))
    assert not bad, f"library modules importing render_tools: {bad}"


@pytest.mark.parametrize("source, expected", [
    ("from lfmbench.sensor import noise\n", {"lfmbench.sensor.noise"}),
    ("def f():\n    from lfmbench.sensor import load_preset\n", {"lfmbench.sensor"}),
    ("import lfmbench.sensor.poisson as P\n", {"lfmbench.sensor.poisson"}),
    ("from .scene import load_config\n", {"render_tools.scene"}),
    ("import importlib\nimportlib.import_module('lfmbench.flicker')\n", {"lfmbench.flicker"}),
    ("x = 'lfmbench.flicker'\n", set()),
])
def test_import_reader(tmp_path, source, expected):
    """The reader itself, on small sources standing in for ``render_tools/spectra.py``."""
    p = tmp_path / "spectra.py"
    p.write_text(source)
    assert _imports("render_tools.spectra", p) == expected


def test_tests_mirror_the_packages():
    """Tests of a package live in the folder of that name (tests/sensor/ for lfmbench/sensor/, tests/render_tools/
    for render_tools/); the cross-cutting ones (layout, checks, files, the flicker model, faults) at the top."""
    tests = ROOT / "tests"
    for d in sorted(p for p in tests.iterdir() if p.is_dir() and p.name not in ("data", "__pycache__")):
        assert d.name in MODULES or f"lfmbench.{d.name}" in MODULES, f"tests/{d.name}/ names no package"
        assert any(d.glob("test_*.py")), f"tests/{d.name}/ holds no test module"


def test_xdist_workers_share_the_cores_as_torch_threads():
    """tests/conftest.py: under pytest-xdist each worker's torch gets this machine's cores // workers threads (at
    least 1), so `make test`'s 2 workers on 2 cores do not run 4 spinning OpenMP threads; outside xdist, or with
    OMP_NUM_THREADS set by the caller, torch keeps its own choice."""
    import os

    from conftest import torch_threads_per_worker

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    assert torch_threads_per_worker({}) is None
    assert torch_threads_per_worker({"PYTEST_XDIST_WORKER_COUNT": "2", "OMP_NUM_THREADS": "3"}) is None
    assert torch_threads_per_worker({"PYTEST_XDIST_WORKER_COUNT": "2"}) == max(1, cores // 2)
    assert torch_threads_per_worker({"PYTEST_XDIST_WORKER_COUNT": "1"}) == cores
    assert torch_threads_per_worker({"PYTEST_XDIST_WORKER_COUNT": str(cores + 5)}) == 1


def test_xdist_workers_steal_work_unless_told_how_to_share_it():
    """tests/conftest.py: ``-n N`` alone schedules with pytest-xdist's ``worksteal`` (a worker that runs dry takes
    half of the other's queue); a ``--dist`` given on the command line, or a run without workers, is left alone."""
    from types import SimpleNamespace as NS

    from conftest import work_stealing

    def config(args, dist, tx):
        return NS(invocation_params=NS(args=tuple(args)), option=NS(dist=dist, tx=tx))

    c = config(["-q", "-n", "2", "tests"], "load", ["popen"] * 2)
    assert work_stealing(c) and c.option.dist == "worksteal"
    for args in (["-n", "2", "--dist", "load"], ["-n", "2", "--dist=load"], ["-n", "2", "-d"]):
        c = config(args, "load", ["popen"] * 2)
        assert not work_stealing(c) and c.option.dist == "load"
    c = config(["tests"], "no", [])
    assert not work_stealing(c) and c.option.dist == "no"


def test_xdist_workers_share_rewritten_test_modules_in_a_temporary_folder_without_bytecode(tmp_path, monkeypatch):
    """tests/conftest.py: where no bytecode is written (``PYTHONDONTWRITEBYTECODE=1``) the xdist controller, and
    only it, makes one temporary folder for the workers' rewritten test modules; a module keeps the pyc of its own
    ``__pycache__`` where one is there, else gets the folder's subfolder of its test folder."""
    import shutil
    import sys
    from types import SimpleNamespace as NS

    from conftest import REWRITE_DIR_ENV, _shared_cache_dir, rewrite_dir_for_workers

    cfg = NS(option=NS(dist="worksteal", tx=["popen"] * 2))
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    env = {}
    made = rewrite_dir_for_workers(cfg, env)
    try:
        assert made and env[REWRITE_DIR_ENV] == made and Path(made).is_dir() and not any(Path(made).iterdir())
    finally:
        shutil.rmtree(made, ignore_errors=True)
    assert rewrite_dir_for_workers(cfg, {"PYTEST_XDIST_WORKER": "gw0"}) is None  # a worker uses the controller's
    assert rewrite_dir_for_workers(NS(option=NS(dist="no", tx=[])), {}) is None  # no workers
    monkeypatch.setattr(sys, "dont_write_bytecode", False)
    assert rewrite_dir_for_workers(cfg, {}) is None  # bytecode next to the sources, as usual
    root, a, b = tmp_path / "shared", tmp_path / "t" / "a" / "test_x.py", tmp_path / "t" / "b" / "test_x.py"
    assert _shared_cache_dir(root, "-t.pyc", a).parent == root
    assert _shared_cache_dir(root, "-t.pyc", a) != _shared_cache_dir(root, "-t.pyc", b)  # same name, two folders
    (a.parent / "__pycache__").mkdir(parents=True)
    (a.parent / "__pycache__" / "test_x-t.pyc").write_bytes(b"")
    assert _shared_cache_dir(root, "-t.pyc", a) == a.parent / "__pycache__"
