import errno
import json
import os

import pytest

from lfmbench import fileio


def test_failed_write_keeps_old_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    p = tmp_path / "a.json"
    fileio.atomic_write_json(p, {"v": 1})

    def full_disk(fd):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(os, "fsync", full_disk)
    with pytest.raises(fileio.AtomicWriteError, match="a.json: disk full"):
        fileio.atomic_write_json(p, {"v": 2})
    assert json.loads(p.read_text()) == {"v": 1}
    assert [q.name for q in tmp_path.iterdir()] == ["a.json"]


def test_strict_json_and_mode_bits(tmp_path):
    with pytest.raises(ValueError):
        fileio.atomic_write_json(tmp_path / "nan.json", {"x": float("nan")})
    assert not list(tmp_path.iterdir())
    p = tmp_path / "ok.txt"
    digest = fileio.atomic_write_text(p, "hello")
    assert digest == "2cf24dba5fb0a30e26e83b2ac5b9e29e1b161e5c1fa7425e73043362938b9824"
    mask = os.umask(0)
    os.umask(mask)
    assert (p.stat().st_mode & 0o777) == (0o666 & ~mask)


def test_figure_and_torch_round_trip(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import torch

    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    png = fileio.atomic_save_figure(fig, tmp_path / "f.png", dpi=50)
    assert png.read_bytes()[:4] == b"\x89PNG"
    pt = fileio.atomic_torch_save({"w": torch.arange(3)}, tmp_path / "x.pt")
    assert torch.equal(torch.load(pt)["w"], torch.arange(3))


#: Writes in benchmarks/ that are not reports: (script, function) -> why the safe writer is not used there.
SCRATCH_WRITES = {
    ("bench_validate.py", "make_corpus"): "the 300,000-file fixture corpus in the benchmark's own temporary "
                                          "folder (an fsync per file would be most of the run)",
    ("bench_leaderboard.py", "make_results"): "the 10,000 generated result files in the benchmark's own temporary "
                                              "folder",
    ("bench_motion_windows.py", "worker"): "the worker process's frames and timings, handed to the driver in the "
                                           "benchmark's own temporary folder",
    ("bench_leaderboard.py", "time_cli"): "the argument list of the timed command, in the same temporary folder",
    ("reflection_speckle.py", "main"): "np.savez into an in-memory buffer (io.BytesIO), whose bytes then go to "
                                       "lfmbench.fileio.atomic_write_bytes",
    ("staggered_ghost_motion_figure.py", "_captures"): "torch.save into an in-memory buffer (io.BytesIO), whose "
                                                       "bytes then go to lfmbench.fileio.atomic_write_bytes",
}


def _unsafe_writes(source: str) -> list[tuple[str, int, str]]:
    """``(function, line, call)`` of each file write in ``source`` that bypasses :mod:`lfmbench.fileio`."""
    import ast  # noqa: PLC0415

    dumps = {("json", "dump"), ("pickle", "dump"), ("torch", "save"), ("np", "save"), ("np", "savez")}
    out = []

    def visit(node, fn):
        for child in ast.iter_child_nodes(node):
            name = child.name if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) else fn
            if isinstance(child, ast.Call):
                f, bad = child.func, None
                if isinstance(f, ast.Attribute) and f.attr in ("write_text", "write_bytes", "savefig"):
                    bad = f.attr
                elif isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and (f.value.id, f.attr) in dumps:
                    bad = f"{f.value.id}.{f.attr}"
                elif isinstance(f, ast.Name) and f.id == "open":
                    mode = child.args[1] if len(child.args) > 1 else next(
                        (k.value for k in child.keywords if k.arg == "mode"), None)
                    if isinstance(mode, ast.Constant) and set(str(mode.value)) & set("wax+"):
                        bad = "open"
                if bad:
                    out.append((fn, child.lineno, bad))
            visit(child, name)

    visit(ast.parse(source), "<module>")
    return out


def test_unsafe_write_scan_sees_every_form():
    src = ("def f(p, fig):\n    p.write_text('x')\n    fig.savefig(p)\n    open(p, 'wb')\n    json.dump(1, p)\n"
           "    open(p)\n    fileio.atomic_write_text(p, 'x')\n")
    assert [(fn, call) for fn, _, call in _unsafe_writes(src)] == [("f", "write_text"), ("f", "savefig"),
                                                                     ("f", "open"), ("f", "json.dump")]


def test_benchmarks_write_their_reports_through_the_safe_writer():
    """Every report, figure and results file a benchmark writes goes through lfmbench.fileio (temporary name, then
    rename; never replaces a link or a device; write errors name the file): issue 27."""
    from pathlib import Path  # noqa: PLC0415

    bench = Path(__file__).resolve().parents[1] / "benchmarks"
    found = [f"{p.name}:{line} {call} (in {fn})" for p in sorted(bench.rglob("*.py"))
             for fn, line, call in _unsafe_writes(p.read_text()) if (p.name, fn) not in SCRATCH_WRITES]
    assert found == []
