"""Timing and report writing shared by the benchmark scripts (run as ``python benchmarks/<script>.py``)."""
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


def load_line() -> str:
    """``"YYYY-MM-DD, 1-minute load average L"``: the date (UTC) and load a benchmark page states for its figures."""
    import datetime  # noqa: PLC0415
    import os  # noqa: PLC0415

    day = datetime.datetime.now(datetime.timezone.utc).date().isoformat()
    return f"{day}, 1-minute load average {os.getloadavg()[0]:.1f}"


def write_device_doc(text: str, device: str, doc, root) -> None:
    """Write a device benchmark's report as one section of its page ``doc``: "GPU figures" when it ran on a GPU,
    else "CPU figures" (so that a run without a GPU keeps the page's GPU figures, and the other way round). The
    report's title line is dropped (the page has its own header); the section states the date and load."""
    on_gpu = str(device).startswith("cuda")
    body = text.splitlines()
    if body and body[0].startswith("# "):
        body = body[1:]
    body = [("#" + ln if ln.startswith("## ") else ln) for ln in body]
    heading = "## GPU figures" if on_gpu else "## CPU figures"
    replace_section(doc, heading, [heading, "", f"Run on {load_line()} at its end.", *body, ""])
    if not on_gpu:
        print(f"no GPU here: the GPU figures were not run; CPU figures in {doc.relative_to(root)}")


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
