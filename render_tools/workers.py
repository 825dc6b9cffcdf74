"""Supervised render worker processes: a worker that dies is reported with its task and signal, the others go on.

Why not :class:`concurrent.futures.ProcessPoolExecutor`: when one of its workers is killed by a signal (a native
crash in Mitsuba, Dr.Jit or LLVM: SIGFPE, SIGSEGV; the kernel's out-of-memory killer: SIGKILL) the executor
breaks, and every pending task fails with "A process in the process pool was terminated abruptly", naming
neither the task that was running nor the signal. Here each worker is a ``spawn`` process fed one task at a time
through its own pipe, so the driver always knows which task a worker holds: when a worker's process ends
without an answer, that task fails with :class:`WorkerDied` (task, signal, a hint), a fresh worker takes the
next task, and the run goes on.

A worker ignores SIGINT (the driver decides: on Ctrl-C it stops every worker, SIGTERM then SIGKILL) and asks the
kernel to send it SIGTERM when the driver dies (Linux ``PR_SET_PDEATHSIG``), so no worker outlives its run.

Functions
- :func:`run_supervised` -> run tasks in ``workers`` processes; ``finished(task, result, exc)`` after each.
- :func:`exit_reason` -> "killed by SIGFPE (signal 8): <hint>" for a process exit code.
- :func:`crash_site` -> where in Python a crashed worker was (from its :mod:`faulthandler` dump).
"""
from __future__ import annotations

import collections
import contextlib
import ctypes
import faulthandler
import multiprocessing
import os
import pickle
import re
import signal
import sys
import tempfile
import threading
from multiprocessing.connection import wait as wait_any
from typing import Any, Callable, Sequence

from lfmbench.resources import docs_url

__all__ = ["SIGNAL_HINTS", "WorkerDied", "crash_site", "exit_reason", "run_supervised"]

#: What a worker killed by a signal most likely met (the hint of :class:`WorkerDied`'s message).
SIGNAL_HINTS = {
    signal.SIGFPE: "an integer division by zero in native code; on AVX-512 CPUs Dr.Jit kernels that divided by "
                   f"the 0 of masked lanes did this ({docs_url('guide/fault-catalogue.md')}): report it with your CPU "
                   "model "
                   "(lscpu) and libLLVM version",
    signal.SIGSEGV: "a crash in native code (Mitsuba, Dr.Jit or LLVM); libLLVM 15 crashes on AVX-512 CPUs: install "
                    f"Debian's libllvm19 ({docs_url('guide/install.md#system-dependency')})",
    signal.SIGBUS: "a crash in native code, or a file mapped into memory changed or the disk filled",
    signal.SIGILL: "an instruction this CPU lacks: a library built for another CPU",
    signal.SIGABRT: "a native library aborted (see its message above)",
    signal.SIGKILL: "killed from outside, most often by the kernel's out-of-memory killer (dmesg says): fewer "
                    "--workers or a smaller --profile",
    signal.SIGTERM: "stopped from outside (SIGTERM)",
}


def exit_reason(exitcode: int | None) -> str:
    """A worker's end in words, from :attr:`multiprocessing.Process.exitcode` (``-N``: killed by signal N).

    >>> exit_reason(-9).split(':')[0]
    'killed by SIGKILL (signal 9)'
    >>> exit_reason(3)
    'exited with status 3'
    """
    if exitcode is None:
        return "did not end"
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        hint = SIGNAL_HINTS.get(-exitcode)
        return f"killed by {name} (signal {-exitcode})" + (f": {hint}" if hint else "")
    return f"exited with status {exitcode}"


class WorkerDied(RuntimeError):
    """A worker process ended while it held ``task`` (``exitcode`` as :attr:`multiprocessing.Process.exitcode`;
    ``signal`` the number of the signal that killed it, or None)."""

    def __init__(self, task: str, exitcode: int | None, site: str | None = None):
        at = f" (Python frame: {site})" if site else ""
        super().__init__(f"the render worker process died while rendering {task}{at}: {exit_reason(exitcode)}")
        self.task = task
        self.exitcode = exitcode
        self.site = site
        self.signal = -exitcode if exitcode is not None and exitcode < 0 else None

    def __reduce__(self):
        return type(self), (self.task, self.exitcode, self.site)


def _die_with_parent() -> None:
    """Ask Linux to send this process SIGTERM when its parent dies (``prctl(PR_SET_PDEATHSIG)``); elsewhere a
    no-op (the worker then ends at its next read from the closed pipe)."""
    if not sys.platform.startswith("linux"):
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _portable(exc: BaseException) -> BaseException:
    """``exc`` if it survives pickling, else a ``RuntimeError`` carrying its type name and message."""
    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:  # noqa: BLE001 - any pickling failure
        return RuntimeError(f"{type(exc).__name__}: {exc}")


def crash_site(fault_log: str) -> str | None:
    """``"tracer.py:447 in _launch"``: the innermost frame of the worker's main thread (where the render runs;
    a native crash is often raised in one of Dr.Jit's own threads) in a :mod:`faulthandler` dump whose first
    line is ``main 0x<thread id>`` (:func:`_worker_main`), or None."""
    try:
        with open(fault_log, encoding="utf-8", errors="replace") as fh:
            text = fh.read(1 << 20)
    except OSError:
        return None
    head = re.match(r"main (0x[0-9a-f]+)\n", text)
    if head is None:
        return None
    block = re.search(r"hread " + head.group(1) + r"[^\n]*\n((?:\s+File[^\n]*\n?)+)", text)
    m = re.search(r'File "([^"]+)", line (\d+) in (\S+)', block.group(1)) if block else None
    return f"{os.path.basename(m.group(1))}:{m.group(2)} in {m.group(3)}" if m else None


def _worker_main(conn, fn: Callable[[Any], Any], fault_log: str) -> None:
    """A worker's loop: receive a task, send ``("ok", fn(task))`` or ``("error", exception)``; ``None`` or a
    closed pipe ends it. A native crash writes the Python stack to ``fault_log`` (:mod:`faulthandler`), which
    the driver reads for the message (:func:`crash_site`) instead of flooding the terminal with it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the driver's to handle: it stops the workers
    _die_with_parent()
    fault_fh = open(fault_log, "w", encoding="utf-8")  # noqa: SIM115 - open for the life of the process
    fault_fh.write(f"main 0x{threading.main_thread().ident:016x}\n")  # faulthandler's spelling of thread ids
    fault_fh.flush()
    faulthandler.enable(file=fault_fh, all_threads=True)
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        try:
            msg = ("ok", fn(task))
        except BaseException as exc:  # noqa: BLE001 - every failure of a task goes back to the driver
            msg = ("error", _portable(exc))
        try:
            conn.send(msg)
        except Exception as exc:  # noqa: BLE001 - e.g. a result that does not pickle
            conn.send(("error", RuntimeError(f"result could not be sent back: {type(exc).__name__}: {exc}")))


class _Worker:
    def __init__(self, ctx, fn):
        fd, self.fault_log = tempfile.mkstemp(prefix="lfmbench-worker-", suffix=".txt")
        os.close(fd)
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child, fn, self.fault_log), name="lfmbench-render-worker")
        self.proc.start()
        child.close()
        self.task = None

    def give(self, task) -> None:
        self.task = task
        self.conn.send(task)

    def stop(self, now: bool, timeout: float = 10.0) -> None:
        """End the process: ask it to (``now`` False, an idle worker), else SIGTERM; SIGKILL after ``timeout`` s."""
        if self.proc.is_alive() and not now:
            try:
                self.conn.send(None)
            except OSError:
                pass
            self.proc.join(timeout)
        if self.proc.is_alive():
            self.proc.terminate()
            self.proc.join(timeout)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()
        with contextlib.suppress(OSError):
            os.unlink(self.fault_log)


def run_supervised(tasks: Sequence[Any], fn: Callable[[Any], Any], workers: int,
                   finished: Callable[[Any, Any, BaseException | None], None],
                   label: Callable[[Any], str] = str) -> None:
    """Run ``fn(task)`` for every task in at most ``workers`` spawn processes, one task per process at a time.

    Args:
        tasks: picklable tasks, run in this order.
        fn: a picklable (module-level) function of one task; its result must pickle.
        workers: processes at once (>= 1; at most ``len(tasks)`` are started).
        finished: ``finished(task, result, None)`` after a task, ``finished(task, None, exc)`` when it raised
            (``exc`` the worker's exception) or its worker died (``exc`` a :class:`WorkerDied`; a fresh worker
            takes over). An exception raised by ``finished`` (or Ctrl-C) stops every worker and propagates.
        label: a task's name in messages (e.g. ``scene scene00003``).
    """
    if not tasks:
        return
    ctx = multiprocessing.get_context("spawn")  # no fork of a process that may hold Dr.Jit / LLVM state
    queue = collections.deque(tasks)
    pool = [_Worker(ctx, fn) for _ in range(min(workers, len(queue)))]
    clean = False
    try:
        for w in pool:
            w.give(queue.popleft())
        while any(w.task is not None for w in pool):
            busy = [w for w in pool if w.task is not None]
            ready = set(wait_any([w.conn for w in busy] + [w.proc.sentinel for w in busy]))
            for i, w in enumerate(pool):
                if w.task is None or (w.conn not in ready and w.proc.sentinel not in ready):
                    continue
                task, w.task = w.task, None
                try:
                    if not w.conn.poll():
                        raise EOFError  # only the sentinel fired: the process ended without an answer
                    kind, payload = w.conn.recv()
                except (EOFError, OSError):
                    w.proc.join(5.0)
                    exc: BaseException = WorkerDied(label(task), w.proc.exitcode, crash_site(w.fault_log))
                    w.stop(now=True)
                    pool[i] = w = _Worker(ctx, fn) if queue else w
                    finished(task, None, exc)
                else:
                    finished(task, payload, None) if kind == "ok" else finished(task, None, payload)
                if queue and w.proc.is_alive():
                    w.give(queue.popleft())
        clean = True
    finally:
        for w in pool:
            if w.proc.pid is not None:
                w.stop(now=not clean or w.task is not None)
