r"""Piecewise-linear (PWL) companding: the knee-point compression with which automotive HDR sensors send a wide
linear code (e.g. 24 bit) over a narrow link (e.g. 12 bit), and its inverse in the ISP.

Defines
-------
- :func:`check_knees`: validate knee points ``(K, 2)`` (input code, output code) as data.
- :func:`compand`: linear input codes -> companded output codes (rounded to the nearest integer code).
- :func:`decompand`: output codes -> linear input codes (the inverse PWL curve: the centre of each code's input
  interval, so the round trip ``decompand(compand(x))`` is within half an output code's input width of ``x``).
- :class:`Compander`: the thin ``nn.Module`` wrapper (quantise, compand, decompand; a straight-through
  gradient).

Units: codes are dimensionless integers (DN of the respective bit depth); :class:`Compander` maps a linear signal
(e.g. input-referred e-) to input codes with ``dn_per_unit``.

References
----------
- Automotive HDR image sensors send a 20-24-bit linear HDR value companded to 12-16 bits by a programmable
  piecewise-linear curve and expect the ISP to decompand it; see the data sheets and product briefs of e.g.
  onsemi AR0820AT ("HDR companding") and Sony IMX490. The knee points are therefore data (the shipped curve is an
  lfmbench choice, ``lfmbench/configs/isp/default.yaml``, ``docs/guide/isp.md``).
"""
from __future__ import annotations

from typing import Any, Sequence

import torch
from torch import nn

from lfmbench.check import check_integer, fail
from lfmbench.limits import brief

__all__ = ["check_knees", "compand", "decompand", "Compander"]


def check_knees(knees: Any, input_bits: int, output_bits: int, field: str = "knees",
                source: str | None = None) -> torch.Tensor:
    """Validate knee points of a companding curve and return them as a ``(K, 2)`` float64 tensor.

    The curve starts at (0, 0), ends at input ``2^input_bits - 1``, is strictly increasing in both columns, never
    exceeds output ``2^output_bits - 1`` and has slopes <= 1 (a compression: every output code then has inputs,
    so ``compand(decompand(y)) == y`` for every code y).

    Args:
        knees: sequence of ``[input_code, output_code]`` pairs, K >= 2.
        input_bits, output_bits: bit depths of the linear input and the companded output.
        field, source: named in error messages.

    Raises:
        ValueError: naming ``field`` (and ``source``) and what is wrong.
    """
    ib = check_integer(input_bits, "input_bits", source, lo=1, hi=32)
    ob = check_integer(output_bits, "output_bits", source, lo=1, hi=ib)
    if isinstance(knees, torch.Tensor):
        knees = knees.tolist()
    if not isinstance(knees, (list, tuple)) or len(knees) < 2:
        fail(field, f"must be a list of at least 2 [input, output] pairs, got {brief(knees)}", source)
    rows = []
    for i, k in enumerate(knees):
        if not isinstance(k, (list, tuple)) or len(k) != 2 or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) for v in k):
            fail(f"{field}[{i}]", f"must be a pair [input_code, output_code] of numbers, got {brief(k)}", source)
        rows.append((float(k[0]), float(k[1])))
    t = torch.tensor(rows, dtype=torch.float64)
    if not bool(torch.isfinite(t).all()):
        fail(field, "must hold finite numbers", source)
    if rows[0] != (0.0, 0.0):
        fail(f"{field}[0]", f"must be [0, 0] (the curve starts at code 0), got {brief(list(knees[0]))}", source)
    top_in, top_out = float(2 ** ib - 1), float(2 ** ob - 1)
    if rows[-1][0] != top_in:
        fail(f"{field}[{len(rows) - 1}]", f"must end at input code 2^{ib} - 1 = {top_in:.0f}, got {rows[-1][0]:g}",
             source)
    d = t[1:] - t[:-1]
    for i in range(d.shape[0]):
        if d[i, 0] <= 0 or d[i, 1] <= 0:
            fail(f"{field}[{i + 1}]", "must be strictly greater than the knee before it in both input and output",
                 source)
        if d[i, 1] > d[i, 0] * (1 + 1e-12):
            fail(f"{field}[{i + 1}]", f"gives a slope {float(d[i, 1] / d[i, 0]):g} > 1 (a compander compresses)",
                 source)
    if rows[-1][1] > top_out:
        fail(f"{field}[{len(rows) - 1}]", f"output {rows[-1][1]:g} exceeds the top code 2^{ob} - 1 = {top_out:.0f}",
             source)
    return t


def _interp(x: torch.Tensor, xp: torch.Tensor, fp: torch.Tensor) -> torch.Tensor:
    """Piecewise-linear interpolation of the increasing knots (xp, fp) at x, clamped to [xp[0], xp[-1]], any shape:
    ``fp[0] + sum_k slope_k * clamp(x - xp[k], 0, xp[k+1] - xp[k])`` (K elementwise passes; K is a handful)."""
    xp = xp.to(device=x.device, dtype=x.dtype)
    fp = fp.to(device=x.device, dtype=x.dtype)
    slope = (fp[1:] - fp[:-1]) / (xp[1:] - xp[:-1])
    out = torch.full_like(x, 0.0) + fp[0]
    for k in range(slope.shape[0]):
        out = out + slope[k] * (x - xp[k]).clamp(0.0, float(xp[k + 1] - xp[k]))
    return out


def compand(codes: torch.Tensor, knees: torch.Tensor | Sequence[Sequence[float]]) -> torch.Tensor:
    """Compress linear input codes with the PWL curve and round to the nearest output code.

    Args:
        codes: linear input codes, any shape (DN of the input bit depth; clamped to the curve's input range).
        knees: ``(K, 2)`` knee points (input code, output code), see :func:`check_knees`.

    Returns:
        Output codes (integral values), shape and floating dtype of ``codes`` (float32 for integer input).

    Example (slope 1 up to 1024, then 1/8):
        >>> k = [[0, 0], [1024, 1024], [2**24 - 1, 1024 + (2**24 - 1 - 1024) / 8]]
        >>> compand(torch.tensor([10.0, 1024.0, 1032.0, 1036.0]), k).tolist()
        [10.0, 1024.0, 1025.0, 1026.0]
    """
    k = torch.as_tensor(knees, dtype=torch.float64)
    x = codes if codes.is_floating_point() else codes.float()
    # float64 inside (device-agnostic, no platform-dependent rounding at the .5 boundaries); round half up
    y = torch.floor(_interp(x.to(torch.float64), k[:, 0], k[:, 1]) + 0.5)
    return y.to(x.dtype)


def decompand(codes: torch.Tensor, knees: torch.Tensor | Sequence[Sequence[float]]) -> torch.Tensor:
    """Expand output codes back to linear input codes with the inverse PWL curve.

    On a linear segment of slope s the inputs that round to output code y form an interval of width 1/s centred
    on the inverse curve at y, so ``|decompand(compand(x)) - x| <= 1 / (2 s)`` (half an output code, in input
    codes) and ``compand(decompand(y)) == y`` for every code y the curve reaches.

    Args:
        codes: output codes, any shape (DN of the output bit depth; clamped to the curve's output range).
        knees: ``(K, 2)`` knee points, see :func:`check_knees`.

    Returns:
        Linear input codes (not rounded), shape and floating dtype of ``codes``.

    Example:
        >>> k = [[0, 0], [1024, 1024], [2**24 - 1, 1024 + (2**24 - 1 - 1024) / 8]]
        >>> decompand(torch.tensor([10.0, 1025.0]), k).tolist()
        [10.0, 1032.0]
    """
    k = torch.as_tensor(knees, dtype=torch.float64)
    y = codes if codes.is_floating_point() else codes.float()
    return _interp(y.to(torch.float64), k[:, 1], k[:, 0]).to(y.dtype)


class Compander(nn.Module):
    """Transmission of a linear signal through a companded link: quantise, compand, decompand.

    ``forward(x)``: ``x`` (any shape, linear units, e.g. input-referred e-) -> input codes
    ``clamp(round(x * dn_per_unit), 0, 2^input_bits - 1)`` -> :func:`compand` -> :func:`decompand` -> back to the
    units of ``x``. Values lose what the link loses (quantisation of both codes, the clip at the top input code).
    With ``straight_through`` the gradient passes as the identity (the quantisation has none), so the stage can sit
    inside a trained pipeline.

    Args:
        knees: ``(K, 2)`` knee points (input code, output code).
        input_bits, output_bits: bit depths of the link.
        dn_per_unit: input codes per unit of ``x`` (DN per e- for input-referred electrons).
        straight_through: identity gradient through the quantisation.
    """

    def __init__(self, knees, input_bits: int = 24, output_bits: int = 12, dn_per_unit: float = 1.0,
                 straight_through: bool = True) -> None:
        super().__init__()
        self.register_buffer("knees", check_knees(knees, input_bits, output_bits), persistent=False)
        self.input_bits, self.output_bits = int(input_bits), int(output_bits)
        if not dn_per_unit > 0:
            raise ValueError(f"dn_per_unit must be > 0, got {dn_per_unit!r}")
        self.dn_per_unit = float(dn_per_unit)
        self.straight_through = bool(straight_through)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        top = float(2 ** self.input_bits - 1)
        q = torch.clamp(torch.floor(x.detach() * self.dn_per_unit + 0.5), 0.0, top)
        out = decompand(compand(q, self.knees), self.knees) / self.dn_per_unit
        return x + (out - x).detach() if self.straight_through else out
