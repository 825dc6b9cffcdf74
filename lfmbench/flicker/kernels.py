"""numba kernels of :func:`lfmbench.flicker.pwm_exposure` for float64 numpy inputs (ideal pulse): the arithmetic of
:func:`lfmbench.flicker.exact._pulse_core`, fused and threaded."""
from __future__ import annotations

import math
import os
import threading

import numpy as np


__all__ = ["PARALLEL_MIN_SIZE"]


_NUMBA_KERNELS: dict | None = None


#: Process that imported this module: only there (and in its main thread) is the threaded kernel used.
_IMPORT_PID = os.getpid()


def _kernel_scalar(phase, exposure, period, duty, amplitude, offset):  # pragma: no cover - compiled by numba
    """Ideal-pulse exposure of one element: the arithmetic of :func:`_pulse_core`, for numba."""
    T = period
    D = duty
    if not (T > 0.0 and exposure >= 0.0 and D >= 0.0 and D <= 1.0
            and math.isfinite(phase) and math.isfinite(exposure) and math.isfinite(T)):
        return math.nan  # the caller re-checks and names the argument
    a = np.fmod(phase, T)  # in (-T, T), exact
    r = np.fmod(exposure, T)
    n = np.rint((exposure - r) / T)
    # TwoProduct D*T = p + e
    p = D * T
    c = 134217729.0 * D
    dh = c - (c - D)
    dl = D - dh
    c = 134217729.0 * T
    th = c - (c - T)
    tl = T - th
    e = ((dh * th - p) + dh * tl + dl * th) + dl * tl
    if a >= 0.0:
        # TwoSum T - a = s + se; the window meets [0, DT) and [T, T + DT)
        s = T - a
        bb = s - T
        se = (T - (s - bb)) + (-a - bb)
        o1 = min(r, (p - a) + e)
        o2 = min((r - s) - se, p + e)
    else:
        # TwoSum p - T = q + qe; the window meets [-T, -T + DT) and [0, DT)
        q = p - T
        bb = q - p
        qe = (p - (q - bb)) + (-T - bb)
        o1 = min(r, (q - a) + (qe + e))
        o2 = min(r + a, p + e)
    if o1 < 0.0:
        o1 = 0.0
    if o2 < 0.0:
        o2 = 0.0
    return amplitude * ((n * p + n * e) + (o1 + o2)) + offset * exposure


#: Elements from which the threaded kernel pays off (its launch costs far more than a small serial loop).
PARALLEL_MIN_SIZE = 100_000


def _numba_kernel(size: int = PARALLEL_MIN_SIZE):
    """The compiled ideal-pulse ufunc for this call site, or None when numba is unavailable.

    Two builds of :func:`_kernel_scalar`: ``target="parallel"`` (both cores) for calls of at least
    :data:`PARALLEL_MIN_SIZE` elements in the importing process's main thread, ``target="cpu"`` otherwise. Each is compiled only when first needed: building the parallel one loads
    numba's threading layer, which sets the OpenMP thread count; in a forked DataLoader worker whose parent has
    used OpenMP (torch does) that makes torch's next parallel region deadlock. So workers only ever build the
    serial kernel; their parallelism is the workers.
    """
    global _NUMBA_KERNELS
    if _NUMBA_KERNELS is None:
        try:
            __import__("numba")  # only whether it imports: the kernels import it where they are built
        except ImportError:  # pragma: no cover - numba is a dependency; the numpy path still works without it
            _NUMBA_KERNELS = {}
            return None
        _NUMBA_KERNELS = {"available": True}
    if not _NUMBA_KERNELS:
        return None
    main = os.getpid() == _IMPORT_PID and threading.current_thread() is threading.main_thread()
    target = "parallel" if (main and size >= PARALLEL_MIN_SIZE) else "cpu"
    if target not in _NUMBA_KERNELS:
        import numba

        if target == "parallel" and "NUMBA_THREADING_LAYER" not in os.environ:
            # numba's fork-safe layer: its OpenMP layer aborts or deadlocks forked children (DataLoader workers);
            # the parallel kernel is only ever called from the main thread, so workqueue's lack of thread
            # safety does not matter. A user's NUMBA_THREADING_LAYER wins.
            numba.config.THREADING_LAYER = "workqueue"
        sig = ["float64(float64, float64, float64, float64, float64, float64)"]
        _NUMBA_KERNELS[target] = numba.vectorize(sig, target=target, cache=target == "cpu")(_kernel_scalar)
    return _NUMBA_KERNELS[target]
