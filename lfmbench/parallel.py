"""Forked processes for work that would leave the second core of a small machine idle: a pool that maps a
function over items (:func:`map_forked`) and one function run beside the caller (:func:`start_forked`); both fall
back to the caller's own process where ``fork`` is missing, only one CPU is usable or no process can start.

Used by the leaderboard (reading a sweep's result files, the rows' bootstrap statistics, the sweep JSON written
beside the Markdown) and the flicker bench (its sequences beside its phase map, its two heat-map figures drawn at
once).
"""
from __future__ import annotations

__all__ = ["can_fork", "map_forked", "start_forked"]


def can_fork() -> bool:
    """Whether forked processes may be used: ``fork`` exists and 2 or more CPUs are usable."""
    import multiprocessing  # noqa: PLC0415
    import os  # noqa: PLC0415

    ncpu = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return ncpu >= 2 and "fork" in multiprocessing.get_all_start_methods()


def map_forked(fn, items: list, min_items: int, chunksize: int = 1) -> list:
    """``[fn(x) for x in items]``, in a forked pool of 2 processes when there are ``min_items`` or more items and
    :func:`can_fork` (in order; a pool that cannot start falls back to one process). ``fn`` and its results must
    pickle."""
    import multiprocessing  # noqa: PLC0415

    if len(items) < min_items or not can_fork():
        return [fn(x) for x in items]
    try:
        with multiprocessing.get_context("fork").Pool(2) as pool:
            return pool.map(fn, items, chunksize=chunksize)
    except (OSError, RuntimeError, AssertionError):  # no process could start (limits, sandbox, a daemonic process)
        return [fn(x) for x in items]


def start_forked(fn, what: str):
    """Start ``fn()`` in a forked process (where :func:`can_fork`; the child sees the caller's memory, nothing is
    pickled but ``fn``'s return value or exception); returns a function that waits for it and returns what ``fn``
    returned (it must pickle) or raises what it raised, or None where no process started (the caller runs ``fn``
    itself). ``what``: what ``fn`` does, for the message of a child that dies without a word (e.g. "the process
    writing the leaderboard JSON")."""
    import multiprocessing  # noqa: PLC0415

    if not can_fork():
        return None
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)

    def run() -> None:
        try:
            send.send((True, fn()))
        except BaseException as e:  # noqa: BLE001 - handed to the parent, which raises it
            try:
                send.send((False, e))
            except Exception:  # noqa: BLE001 - an exception (or a result) that does not pickle
                send.send((False, RuntimeError(f"{type(e).__name__}: {e}")))

    try:
        proc = ctx.Process(target=run, daemon=True)
        proc.start()
    except (OSError, RuntimeError):
        return None
    send.close()    # the child's copy stays open: a child that dies without a word ends the pipe (EOFError)

    def wait():
        try:
            ok, value = recv.recv()
        except EOFError:
            ok, value = False, RuntimeError(f"{what} ended without a result (killed?); run the command again")
        recv.close()
        proc.join()
        if not ok:
            raise value
        if proc.exitcode:
            raise RuntimeError(f"{what} exited with code {proc.exitcode}")
        return value

    return wait
