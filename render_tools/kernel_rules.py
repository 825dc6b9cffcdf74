"""Rules that every Dr.Jit kernel of lfmbench obeys, one definition each.

Integer division in a kernel
----------------------------
Dr.Jit's LLVM back end runs a kernel over packets of 8 or 16 lanes (AVX2 / AVX-512). In the last packet of a
launch whose lane count is not a multiple of the packet width, the lanes past the end are masked: a
``dr.gather`` returns 0 there. An integer ``//`` or ``%`` by such a value is compiled, on some CPUs and LLVM
versions, into a scalar x86 ``div`` per lane that executes for the masked lanes too and traps: the process dies
with SIGFPE ("Floating point exception"), with no Python error (seen on Intel Xeon with AVX-512 and Debian's
libLLVM 19.1.7; ``lane // w`` with ``w`` gathered dies, ``lane // dr.maximum(w, 1)`` works). Whether a machine
crashes depends on its CPU and on LLVM's code generation, so a green run on one machine proves nothing.

Hence, in every function that builds a kernel, the divisor of an integer ``//`` or ``%`` is one of:

- a literal number, or an UPPER_CASE name or attribute (a host-side constant, e.g. ``MAX_LANES``, ``W * H``),
- a call of :func:`lane_divisor` (clamps the divisor to >= 1: a no-op on every active lane whose divisor is a
  count, which is >= 1 by construction),
- a host integer: a call of ``int`` or ``len``,
- a name bound in the same function from one of the above (``w = lane_divisor(g("w"))``),
- an arithmetic expression of such operands.

``tests/render_tools/test_kernel_rules.py`` checks this over the abstract syntax tree of every module that imports
``drjit`` (:data:`HOST_INT_CALLS`, :data:`DIVISOR_HELPER` are what it accepts). Floating-point division needs no
guard: IEEE division by 0 gives inf or NaN without a trap (floating-point exceptions are masked in Dr.Jit's
kernels), and the kernels mask or ``dr.select`` such lanes away.

Host arrays read by a kernel
----------------------------
Dr.Jit reads a numpy array where it lies and compiles its loads with the alignment it finds at that address (and
a 1-entry array as a literal scalar). An array placed wherever numpy's allocator puts it therefore gives another
kernel hash in each process: the on-disk kernel cache misses and every render compiles again (measured on the
exact dot coverage's visibility rays: 41 of 57 kernels compiled again in a second process; none with
:func:`kernel_input`). Hence a per-call numpy array handed to a kernel goes through :func:`kernel_input` (a copy
in a 64-byte-aligned buffer of at least 2 entries), or through a table whose layout is fixed in another way
(the tracer's tables end in a dummy row).
"""
from __future__ import annotations

__all__ = ["lane_divisor", "kernel_input", "DIVISOR_HELPER", "HOST_INT_CALLS", "KERNEL_INPUT_ALIGN"]

#: Name of the helper that makes a divisor safe in every lane.
DIVISOR_HELPER = "lane_divisor"
#: Calls whose result is a Python integer (host side), never a Dr.Jit array.
HOST_INT_CALLS = ("int", "len")
#: Byte alignment of the buffers :func:`kernel_input` returns (an AVX-512 register; a cache line).
KERNEL_INPUT_ALIGN = 64


def lane_divisor(v):
    """``v`` clamped to >= 1, for use as the divisor of an integer ``//`` or ``%`` in a Dr.Jit kernel.

    Args:
        v: an unsigned or signed Dr.Jit integer array (one value per lane), or a Python int.

    Returns:
        ``dr.maximum(v, 1)`` (same type as ``v``): equal to ``v`` on every lane where ``v >= 1`` (every active
        lane, where ``v`` is a count: pixels, bins, samples), 1 on the masked tail lanes that gather 0.

    >>> lane_divisor(0), lane_divisor(7)
    (1, 7)
    """
    if isinstance(v, int):
        return max(v, 1)
    import drjit as dr  # noqa: PLC0415 - imported where a kernel is built (the module stays importable without)

    return dr.maximum(v, 1)


def kernel_input(x, dtype=None):
    """``x`` flattened into a buffer aligned to :data:`KERNEL_INPUT_ALIGN` bytes, at least 2 entries long (the
    tail repeats the last entry, 0 for an empty ``x``), for a Dr.Jit array built from it (section "Host arrays
    read by a kernel" above): the same kernel hash in every process.

    Args:
        x: array-like of any shape.
        dtype: numpy dtype of the result (default float32, Dr.Jit's ``Float``).

    Returns:
        1-D numpy array (max(x.size, 2),) of ``dtype``, its first x.size entries ``x.ravel()`` (cast).

    >>> a = kernel_input([1.5]); (a.tolist(), a.ctypes.data % KERNEL_INPUT_ALIGN)
    ([1.5, 1.5], 0)
    """
    import numpy as np  # noqa: PLC0415 - as lane_divisor's drjit: the module's rules stay importable alone

    dt = np.dtype(np.float32 if dtype is None else dtype)
    x = np.asarray(x, dt).ravel()
    if x.size < 2:
        x = np.concatenate([x, np.repeat(x[-1:] if x.size else np.zeros(1, dt), 2 - x.size)])
    buf = np.empty(x.nbytes + KERNEL_INPUT_ALIGN, np.uint8)
    off = (-buf.ctypes.data) % KERNEL_INPUT_ALIGN
    out = buf[off:off + x.nbytes].view(dt)
    out[:] = x
    return out
