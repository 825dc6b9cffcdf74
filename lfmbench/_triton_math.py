"""Float64 helpers shared by the Triton kernels (imported only by kernel modules: it needs Triton).

Each helper computes what the array form (torch/numpy) computes, bit for bit, when the kernel is compiled
without fused multiply-adds (``enable_fp_fusion=False``): float64 add, subtract, multiply and divide round as IEEE
754 says on every device (Triton divides float64 values with ``div.rn.f64`` on NVIDIA GPUs; only float32 division
is approximate by default); ``floor`` is exact.
"""
from __future__ import annotations

import triton
import triton.language as tl


@triton.jit
def _d(x: tl.constexpr):
    """The float64 constant ``x`` (a bare Python float would be a float32 constant)."""
    return tl.full([], x, tl.float64)


@triton.jit
def rint(x):
    """Round half to even (``numpy.rint``, ``torch.round``) of float64 values below 2^52 in magnitude."""
    r = tl.floor(x + _d(0.5))
    tie = (r - x) == _d(0.5)
    odd = (r - _d(2.0) * tl.floor(r * _d(0.5))) != _d(0.0)
    return tl.where(tie & odd, r - _d(1.0), r)


@triton.jit
def two_prod(x, y):
    """Dekker's TwoProduct (:func:`lfmbench.flicker.exact._two_prod` with the float64 split 2^27 + 1): ``x*y == p + e``
    exactly; the same operations in the same order."""
    p = x * y
    cx = _d(134217729.0) * x
    xh = cx - (cx - x)
    xl = x - xh
    cy = _d(134217729.0) * y
    yh = cy - (cy - y)
    yl = y - yh
    e = ((xh * yh - p) + xh * yl + xl * yh) + xl * yl
    return p, e


@triton.jit
def two_sum(x, y):
    """Knuth's TwoSum (:func:`lfmbench.flicker.exact._two_sum`): ``x + y == s + e`` exactly."""
    s = x + y
    bb = s - x
    e = (x - (s - bb)) + (y - bb)
    return s, e


@triton.jit
def fmod(x, y):
    """C's ``fmod(x, y)`` (``torch.fmod``: the remainder with the sign of ``x``, always exact) for finite ``x`` and
    ``y > 0`` with ``|x| / y < 2^53``, from exact operations: ``q = floor(|x| / y)`` (the quotient correctly rounded, so the
    true quotient's integer part or one more), ``|x| - q y`` exactly by TwoProduct (``|x| - p`` is exact by
    Sterbenz's lemma where ``q >= 1``), then ``+ y`` where ``q`` was one too many (exact: the result is the
    remainder, a float64)."""
    ax = tl.abs(x)
    q = tl.floor(ax / y)
    p, e = two_prod(q, y)
    r = (ax - p) - e
    r = tl.where(r < _d(0.0), r + y, r)
    return tl.where(x < _d(0.0), -r, r)
