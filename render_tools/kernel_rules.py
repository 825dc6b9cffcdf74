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
"""
from __future__ import annotations

__all__ = ["lane_divisor", "DIVISOR_HELPER", "HOST_INT_CALLS"]

#: Name of the helper that makes a divisor safe in every lane.
DIVISOR_HELPER = "lane_divisor"
#: Calls whose result is a Python integer (host side), never a Dr.Jit array.
HOST_INT_CALLS = ("int", "len")


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
