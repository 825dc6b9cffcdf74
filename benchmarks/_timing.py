"""Timing helper shared by the benchmark scripts (run as ``python benchmarks/<script>.py``)."""
from __future__ import annotations

import statistics
import time
from typing import Callable


def median_time(fn: Callable[[], object], repeat: int = 9, warmup: int = 2) -> tuple[float, float]:
    """Median and minimum wall time (s) of ``repeat`` calls of ``fn`` after ``warmup`` untimed calls."""
    for _ in range(warmup):
        fn()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), min(ts)


def write_device_doc(text: str, device: str, gpu_doc, cpu_doc, root) -> None:
    """Write a device benchmark's report: to ``gpu_doc`` when it ran on a GPU, else to ``cpu_doc`` (so that a run
    without a GPU keeps the GPU figures of ``gpu_doc``) and say that the GPU figures were not run."""
    from lfmbench.fileio import atomic_write_text  # noqa: PLC0415 - the timing helpers need no lfmbench

    on_gpu = str(device).startswith("cuda")
    atomic_write_text(gpu_doc if on_gpu else cpu_doc, text)
    if not on_gpu:
        print(f"no GPU here: the GPU figures were not run; CPU figures in {cpu_doc.relative_to(root)}")


def replace_section(path, heading: str, lines: list[str]) -> None:
    """Write ``lines`` (starting with ``heading``, a ``## `` line) as that section of the Markdown file ``path``:
    what is before the heading stays, the old section (up to the next ``## `` heading) is replaced, later sections
    stay; a file without the heading gets the section at its end."""
    from pathlib import Path  # noqa: PLC0415

    from lfmbench.fileio import atomic_write_text  # noqa: PLC0415 - the timing helpers need no lfmbench

    path = Path(path)
    old = path.read_text() if path.exists() else ""
    head = old.split(heading)[0].rstrip() + "\n\n" if old else ""
    rest = old.split(heading, 1)[1] if heading in old else ""
    tail = rest[rest.index("\n## "):].lstrip("\n") if "\n## " in rest else ""
    atomic_write_text(path, head + "\n".join(lines) + ("\n" + tail if tail else ""))
