"""One progress style for every command (rich), readable in a log file.

On a terminal a rich progress bar redraws itself in place. When stderr is not a terminal (a log file, a pipe, a
CI job) nothing is redrawn: a plain line ``description: done/total (percent, elapsed, about T left)`` is printed
when a step crosses each tenth of the total (at most :data:`LOG_LINES` + 1 lines per bar) and at the end, so a log
holds a few readable lines and no carriage-return flood. The time left (:func:`time_left`) extrapolates the steps
done in this run (a resumed job's skipped steps do not count) at their mean rate. Used by ``render``, ``evaluate`` and ``train``
(:func:`track` for an iterable, :class:`Bar` where the steps come from callbacks).
"""
from __future__ import annotations

import time
from collections.abc import Iterable, Iterator
from typing import Any, Generic, TypeVar

__all__ = ["Bar", "Tracked", "track", "time_left", "LOG_LINES"]

T = TypeVar("T")

#: Progress lines a bar writes to a log (one per tenth of the total), plus the final one.
LOG_LINES = 10


def time_left(elapsed_s: float, done: int, total: int) -> str:
    """``"about 12 min left"``: the ``total - done`` steps still to do at the mean rate of the ``done`` steps taken in
    ``elapsed_s`` seconds; ``""`` when nothing is done yet or nothing is left. Seconds under 2 minutes, minutes under
    2 hours, hours above."""
    if done <= 0 or total <= done:
        return ""
    s = elapsed_s / done * (total - done)
    if s < 120:
        return f"about {s:.0f} s left"
    return f"about {s / 60:.0f} min left" if s < 7200 else f"about {s / 3600:.1f} h left"


class Bar:
    """A progress bar on stderr: ``with Bar(total, "evaluate") as bar: ... bar.advance()``.

    Args:
        total: number of steps (None: unknown; the log then gets a line at 1, 10, 100, ... steps).
        description: what is counted (``"evaluate lpd_only"``).
        unit: the step's name in the log lines (``"batch"``).
        enabled: False: no output at all.
        log: False: no log lines off a terminal (where the caller logs its own, e.g. one per training epoch).
        console: the rich console to draw on (default: a new one on stderr).
    """

    def __init__(self, total: int | None, description: str, unit: str = "", enabled: bool = True,
                 console: Any = None, log: bool = True) -> None:
        from rich.console import Console

        self.total, self.description, self.unit = total, description, unit
        self.console = console if console is not None else Console(stderr=True, soft_wrap=True)
        self.enabled = enabled and (log or self.console.is_terminal)
        self.done, self._logged, self._t0 = 0, -1, time.perf_counter()
        self._skipped = 0                   # steps done before this run (resumed), left out of the rate
        self._live = None
        self._task = None

    @property
    def live(self) -> bool:
        """True when the bar redraws in place (an interactive terminal), False when it writes log lines."""
        return self.enabled and self.console.is_terminal

    def __enter__(self) -> "Bar":
        self._t0 = time.perf_counter()
        if self.live:
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                                       TimeRemainingColumn)

            self._live = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                                  TimeElapsedColumn(), TimeRemainingColumn(), console=self.console)
            self._live.__enter__()
            self._task = self._live.add_task(self.description, total=self.total, completed=self.done)
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._live is not None:
            self._live.__exit__(*exc)
            self._live = None
        elif self.enabled and exc[0] is None and self._logged != self.done:
            self._log()

    def _log(self) -> None:
        self._logged = self.done
        secs = time.perf_counter() - self._t0
        of = f"/{self.total}" if self.total else ""
        pct = f" ({100 * self.done / self.total:.0f} %" if self.total else " ("
        plural = "" if (self.total or self.done) == 1 else ("es" if self.unit.endswith("h") else "s")
        unit = f" {self.unit}{plural}" if self.unit else ""
        left = time_left(secs, self.done - self._skipped, self.total - self._skipped) if self.total else ""
        self.console.print(f"{self.description}: {self.done}{of}{unit}{pct}{', ' if self.total else ''}"
                           f"{secs:.1f} s{', ' + left if left else ''})", highlight=False, markup=False)

    def advance(self, n: int = 1) -> None:
        """``n`` more steps done."""
        before, self.done = self.done, self.done + n
        if not self.enabled:
            return
        if self._live is not None:
            self._live.update(self._task, completed=self.done)
            return
        if self.total:
            step = max(1, -(-self.total // LOG_LINES))  # a line per tenth of the total
            if self.done // step != before // step or self.done == self.total:
                self._log()
        elif self.done == 1 or len(str(self.done)) != len(str(before)):  # 1, 10, 100, ... steps
            self._log()

    def update(self, done: int, total: int | None = None) -> None:
        """``done`` steps of ``total`` (None: the total stays) done, for a callback ``progress(done, total)``."""
        if total is not None and total != self.total:
            self.total = total
            if self._live is not None:
                self._live.update(self._task, total=total)
        self.advance(done - self.done)

    def set(self, done: int) -> None:
        """Set the steps done (a resumed job's skipped steps), without a log line; they do not count towards the
        rate of the time left."""
        self.done = self._logged = self._skipped = done
        if self._live is not None:  # a reset: the jump is no progress of the bar's speed (its time left)
            self._live.reset(self._task, completed=done)

    def print(self, message: str) -> None:
        """Print a line above the bar (a plain line in a log)."""
        self.console.print(message, highlight=False)


def track(iterable: Iterable[T], total: int | None = None, description: str = "", unit: str = "",
          enabled: bool = True, log: bool = True) -> "Tracked[T]":
    """The items of ``iterable``, advancing a :class:`Bar` by one per item (arguments as :class:`Bar`)."""
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)  # type: ignore[arg-type]
    return Tracked(iterable, Bar(total, description, unit, enabled, log=log))


class Tracked(Generic[T]):
    """An iterable with a progress bar (:func:`track`); :meth:`set_postfix` shows running values next to it."""

    def __init__(self, iterable: Iterable[T], bar: Bar) -> None:
        self.iterable, self.bar, self._description = iterable, bar, bar.description

    def __iter__(self) -> Iterator[T]:
        with self.bar as bar:
            for item in self.iterable:
                yield item
                bar.advance()

    def set_postfix(self, **values: Any) -> None:
        """Show ``key=value`` after the description (on a terminal; log lines carry them too)."""
        self.bar.description = self._description + " " + " ".join(f"{k}={v}" for k, v in values.items())
        if self.bar._live is not None:
            self.bar._live.update(self.bar._task, description=self.bar.description)
