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
