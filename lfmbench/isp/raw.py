"""Raw-domain stages of the ISP, on the Bayer mosaic: black-level subtraction and white balance.

Defines
-------
- :func:`subtract_black_level`: ``x - black_level`` (DN), optionally rescaled so the white level maps to 1.
- :func:`cfa_channel_map`: the (H, W) colour index (0 r, 1 g, 2 b) of a Bayer layout.
- :func:`white_balance_mosaic`: multiply each pixel by the gain of its colour.
- :func:`gray_world_gains`: gains that equalise the channel means of a mosaic (grey-world assumption).
- :class:`BlackLevel`, :class:`WhiteBalance`: the thin ``nn.Module`` wrappers.

Shapes: a mosaic is ``(*, 1, H, W)`` (one value per pixel, the colour given by the CFA layout).

References
----------
- EMVA Standard 1288, Release 4.0 Linear (2021), sec. 2: the dark signal (offset) of the linear camera model.
- G. Buchsbaum, "A spatial processor model for object colour perception", J. Franklin Institute 310(1), 1980
  (grey-world white balance).
"""
from __future__ import annotations

import math
from typing import Sequence

import torch
from torch import nn

from lfmbench.check import check_tensor
from lfmbench.sensor.preset import CFAPattern

__all__ = ["subtract_black_level", "cfa_channel_map", "white_balance_mosaic", "gray_world_gains", "BlackLevel",
           "WhiteBalance"]


def subtract_black_level(raw: torch.Tensor, black_level: float, white_level: float | None = None) -> torch.Tensor:
    """Remove the dark offset: ``raw - black_level``, and with ``white_level`` divide by
    ``white_level - black_level`` so the top code maps to 1. Negative results (read noise below the pedestal) are
    kept: clipping them would bias dark regions (EMVA 1288 linear model).

    Args:
        raw: (*, 1, H, W) mosaic in DN.
        black_level: pedestal in DN.
        white_level: top code in DN (e.g. ``2^adc_bits - 1``), or None.

    Returns:
        (*, 1, H, W): DN above black, or dimensionless (fraction of the range) with ``white_level``.
    """
    check_tensor(raw, "raw", "* 1 H W", what="a Bayer mosaic", floating=True)
    out = raw - float(black_level)
    if white_level is not None:
        span = float(white_level) - float(black_level)
        if not span > 0:
            raise ValueError(f"white_level ({white_level}) must exceed black_level ({black_level})")
        out = out / span
    return out


def cfa_channel_map(pattern: CFAPattern | str, height: int, width: int,
                    device: torch.device | str | None = None) -> torch.Tensor:
    """(H, W) int64 colour of every pixel of a Bayer layout (0 r, 1 g, 2 b)."""
    return CFAPattern(str(getattr(pattern, "value", pattern)).upper()).index_map(height, width, device)


def white_balance_mosaic(raw: torch.Tensor, gains: torch.Tensor | Sequence[float],
                         pattern: CFAPattern | str) -> torch.Tensor:
    """Multiply every pixel of a mosaic by the gain of its colour.

    Args:
        raw: (*, 1, H, W) linear mosaic (any linear unit).
        gains: (3,) r, g, b gains (dimensionless), or (N, 3) with N the product of the leading dims (per image).
        pattern: Bayer layout of ``raw``.

    Returns:
        (*, 1, H, W), same unit, dtype and device.
    """
    check_tensor(raw, "raw", "* 1 H W", what="a Bayer mosaic", floating=True)
    g = torch.as_tensor(gains, dtype=raw.dtype, device=raw.device)
    h, w = raw.shape[-2:]
    idx = cfa_channel_map(pattern, h, w, raw.device)
    if g.ndim == 1:
        if g.shape != (3,):
            raise ValueError(f"gains must have shape (3,) or (N, 3), got {tuple(g.shape)}")
        return raw * g[idx]
    lead = raw.shape[:-3]
    n = math.prod(lead)
    if g.shape != (n, 3):
        raise ValueError(f"gains must have shape (3,) or ({n}, 3) for raw of shape {tuple(raw.shape)}, "
                         f"got {tuple(g.shape)}")
    return (raw.reshape(n, 1, h, w) * g[:, idx].unsqueeze(1)).reshape(raw.shape)


def gray_world_gains(raw: torch.Tensor, pattern: CFAPattern | str, dims: int = 3) -> torch.Tensor:
    """Grey-world gains (Buchsbaum 1980): g_c = mean(green) / mean(c) over the mosaic, green gain 1.

    Args:
        raw: (*, 1, H, W) linear mosaic.
        pattern: its Bayer layout.
        dims: reduce over the last ``dims`` dims (3: each image; 4 with (B, F, 1, H, W): each sequence).

    Returns:
        (N, 3) gains (dimensionless), N the product of the remaining leading dims; 1 where a channel mean is not
        positive.
    """
    check_tensor(raw, "raw", "* 1 H W", what="a Bayer mosaic", floating=True)
    h, w = raw.shape[-2:]
    idx = cfa_channel_map(pattern, h, w, raw.device)
    onehot = torch.stack([(idx == c) for c in range(3)]).to(raw.dtype)  # (3, H, W)
    lead = raw.shape[:raw.ndim - dims]
    x = raw.reshape((-1,) + raw.shape[raw.ndim - dims:]).clamp_min(0.0)  # (N, ..., 1, H, W)
    flat = x.reshape(x.shape[0], -1, h * w)  # (N, M, H*W)
    sums = torch.einsum("nmp,cp->nc", flat, onehot.reshape(3, -1))
    means = sums / onehot.reshape(3, -1).sum(1).clamp_min(1.0) / flat.shape[1]
    gains = means[:, 1:2] / means
    gains = torch.where(means > 0, gains, torch.ones_like(gains))
    return gains.reshape(math.prod(lead), 3)


class BlackLevel(nn.Module):
    """``nn.Module`` of :func:`subtract_black_level` with fixed levels (DN)."""

    def __init__(self, black_level: float, white_level: float | None = None) -> None:
        super().__init__()
        self.black_level, self.white_level = float(black_level), white_level

    def forward(self, raw: torch.Tensor) -> torch.Tensor:
        """(*, 1, H, W) DN -> (*, 1, H, W)."""
        return subtract_black_level(raw, self.black_level, self.white_level)


class WhiteBalance(nn.Module):
    """``nn.Module`` of :func:`white_balance_mosaic` with fixed gains.

    Args:
        gains: (3,) r, g, b gains, e.g. :func:`lfmbench.isp.color.white_balance_gains`.
        pattern: Bayer layout.
    """

    def __init__(self, gains: Sequence[float], pattern: CFAPattern | str) -> None:
        super().__init__()
        self.register_buffer("gains", torch.as_tensor(gains, dtype=torch.float32), persistent=False)
        self.pattern = CFAPattern(str(getattr(pattern, "value", pattern)).upper())

    def forward(self, raw: torch.Tensor) -> torch.Tensor:
        """(*, 1, H, W) -> (*, 1, H, W)."""
        return white_balance_mosaic(raw, self.gains, self.pattern)
