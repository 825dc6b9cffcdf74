r"""Demosaicking: a Bayer mosaic ``(*, 1, H, W)`` -> full colour ``(*, 3, H, W)``.

Defines
-------
- :func:`demosaic_bilinear`: kornia's bilinear demosaic (``kornia.color.raw_to_rgb``).
- :func:`demosaic_malvar2004`: the gradient-corrected linear interpolation of Malvar, He and Cutler (2004): eight
  5x5 filters whose bilinear estimate is corrected by the Laplacian of the known channel (gains 1/2, 5/8, 3/4).
- :func:`clamp_to_neighbours`: limit every interpolated value to the range of the samples of its colour in the
  3x3 neighbourhood (the taps a bilinear estimate averages): removes the overshoot of a gradient-corrected
  demosaic next to a point light 1000x brighter than its surroundings (an lfmbench choice, ``docs/guide/isp.md``).
- :data:`DEMOSAIC`: the registry, name -> function; :func:`demosaic` dispatches by name (colour-science style).
- :class:`Demosaic`: the thin ``nn.Module`` wrapper.

Both are linear in the input and work in any linear unit; H and W may be odd (the mosaic is extended by one
mirrored row/column, which keeps the CFA phase, and cut back afterwards). Borders: mirror padding without edge
repetition (``reflect``), which keeps the CFA phase as well.

References
----------
- H. S. Malvar, L. He, R. Cutler, "High-quality linear interpolation for demosaicing of Bayer-patterned color
  images", IEEE ICASSP 2004, vol. 3, pp. 485-488 (Figure 2: the filter coefficients).
- E. Riba, D. Mishkin, D. Ponsa, E. Rublee, G. Bradski, "Kornia: an open source differentiable computer vision
  library for PyTorch", WACV 2020 (``kornia.color.raw_to_rgb``).
"""
from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F
from torch import nn

from lfmbench.check import check_tensor
from lfmbench.registry import Registry
from lfmbench.sensor.preset import CFAPattern

__all__ = ["demosaic_bilinear", "demosaic_malvar2004", "clamp_to_neighbours", "demosaic", "DEMOSAIC", "Demosaic"]


def _pattern(pattern: CFAPattern | str) -> CFAPattern:
    try:
        return CFAPattern(str(getattr(pattern, "value", pattern)).upper())
    except ValueError:
        raise ValueError(f"pattern must be one of {[c.value for c in CFAPattern]}, got {pattern!r}") from None


def _even(raw: torch.Tensor) -> tuple[torch.Tensor, int, int]:
    """Extend odd H/W by one mirrored row/column (same CFA phase); returns (x, H, W) of the original."""
    h, w = raw.shape[-2:]
    ph, pw = h % 2, w % 2
    if not (ph or pw):
        return raw, h, w
    if (ph and h < 2) or (pw and w < 2):
        raise ValueError(f"raw must be at least 2x2 to demosaic, got {h}x{w}")
    flat = raw.reshape(-1, 1, h, w)
    flat = F.pad(flat, (0, pw, 0, ph), mode="reflect")
    return flat.reshape(raw.shape[:-2] + flat.shape[-2:]), h, w


def demosaic_bilinear(raw: torch.Tensor, pattern: CFAPattern | str) -> torch.Tensor:
    """Bilinear demosaic: ``kornia.color.raw_to_rgb`` (bilinear upsampling of r and b, a fixed 3x3 filter for g).

    Args:
        raw: (*, 1, H, W) linear mosaic, any linear unit.
        pattern: Bayer layout of ``raw`` (top-left 2x2 cell).

    Returns:
        (*, 3, H, W) r, g, b in the unit of ``raw``.
    """
    from kornia.color import raw_to_rgb  # noqa: PLC0415 (kornia: a core dependency, imported where used)

    check_tensor(raw, "raw", "* 1 H W", what="a Bayer mosaic", floating=True)
    x, h, w = _even(raw)
    return raw_to_rgb(x, _pattern(pattern).to_kornia())[..., :h, :w]


# Malvar, He & Cutler 2004, Fig. 2 (coefficients x 1/8), as 5x5 kernels centred on the pixel being estimated.
_G_AT_RB = [[0, 0, -1, 0, 0], [0, 0, 2, 0, 0], [-1, 2, 4, 2, -1], [0, 0, 2, 0, 0], [0, 0, -1, 0, 0]]
# R at a green pixel in a red row (B at a green pixel in a blue row): the known colour lies left and right.
_RB_AT_G_ROW = [[0, 0, 0.5, 0, 0], [0, -1, 0, -1, 0], [-1, 4, 5, 4, -1], [0, -1, 0, -1, 0], [0, 0, 0.5, 0, 0]]
# R at a green pixel in a blue row (B at a green pixel in a red row): the known colour lies above and below.
_RB_AT_G_COL = [list(r) for r in zip(*_RB_AT_G_ROW)]
# R at a blue pixel (B at a red pixel): the known colour lies on the diagonals.
_RB_AT_BR = [[0, 0, -1.5, 0, 0], [0, 2, 0, 2, 0], [-1.5, 0, 6, 0, -1.5], [0, 2, 0, 2, 0], [0, 0, -1.5, 0, 0]]


def demosaic_malvar2004(raw: torch.Tensor, pattern: CFAPattern | str) -> torch.Tensor:
    """Gradient-corrected bilinear demosaic of Malvar, He and Cutler (ICASSP 2004).

    Each missing colour is the bilinear estimate plus a scaled Laplacian of the colour known at the pixel; the
    eight cases reduce to four 5x5 filters (Fig. 2 of the paper), applied by one convolution. Linear, so it can
    overshoot (negative values near strong edges): the caller decides whether to clip.

    Args:
        raw: (*, 1, H, W) linear mosaic, any linear unit; H, W >= 3.
        pattern: Bayer layout of ``raw``.

    Returns:
        (*, 3, H, W) r, g, b in the unit of ``raw``; at a pixel the colour it measured is returned unchanged.
    """
    check_tensor(raw, "raw", "* 1 H W", what="a Bayer mosaic", floating=True)
    pat = _pattern(pattern)
    x, h, w = _even(raw)
    H, W = x.shape[-2:]
    if min(H, W) < 3:
        raise ValueError(f"raw must be at least 3x3 for the 5x5 Malvar filters, got {h}x{w}")
    flat = x.reshape(-1, 1, H, W)
    k = torch.tensor([_G_AT_RB, _RB_AT_G_ROW, _RB_AT_G_COL, _RB_AT_BR], dtype=flat.dtype, device=flat.device) / 8.0
    est = F.conv2d(F.pad(flat, (2, 2, 2, 2), mode="reflect"), k.unsqueeze(1))  # (N, 4, H, W)
    g_rb, rb_row, rb_col, rb_diag = est.unbind(1)
    m = flat[:, 0]
    idx = pat.index_map(H, W, flat.device)  # 0 r, 1 g, 2 b
    is_r, is_g, is_b = idx == 0, idx == 1, idx == 2
    # a green pixel's row holds red or blue: red rows are the rows whose red pixels exist
    row_has_r = is_r.any(dim=1, keepdim=True).expand(H, W)
    g = torch.where(is_g, m, g_rb)
    r = torch.where(is_r, m, torch.where(is_b, rb_diag, torch.where(row_has_r, rb_row, rb_col)))
    b = torch.where(is_b, m, torch.where(is_r, rb_diag, torch.where(row_has_r, rb_col, rb_row)))
    rgb = torch.stack([r, g, b], dim=1)[..., :h, :w]
    return rgb.reshape(raw.shape[:-3] + (3, h, w))


def clamp_to_neighbours(rgb: torch.Tensor, raw: torch.Tensor, pattern: CFAPattern | str) -> torch.Tensor:
    """Clamp each channel of a demosaicked image to the [min, max] of the mosaic samples of that colour in the
    pixel's 3x3 neighbourhood (its own sample included: a measured value is unchanged).

    A linear demosaic with gradient correction (Malvar et al. 2004) overshoots where the scene has a contrast far
    beyond a natural image's, e.g. a lamp 1000x brighter than the road next to it: the Laplacian term puts dark and
    coloured dots around the lamp (negative values clipped to black, or a channel pushed above its neighbours).
    The clamp keeps every estimate inside the range of the samples a bilinear estimate would average. On the smooth
    test image of ``tests/isp/test_isp_demosaic.py`` it also raises Malvar's PSNR (38.4 dB against 36.1 dB, bilinear 31.5 dB).

    Args:
        rgb: (*, 3, H, W) demosaicked image. raw: (*, 1, H, W) the mosaic it came from. pattern: its Bayer layout.

    Returns:
        (*, 3, H, W), unit of ``rgb``.
    """
    check_tensor(raw, "raw", "* 1 H W", what="a Bayer mosaic", floating=True)
    h, w = raw.shape[-2:]
    if rgb.shape[-3:] != (3, h, w) or rgb.shape[:-3] != raw.shape[:-3]:
        raise ValueError(f"rgb {tuple(rgb.shape)} must be the demosaic of raw {tuple(raw.shape)}")
    idx = _pattern(pattern).index_map(h, w, raw.device)
    flat = raw.reshape(-1, 1, h, w)
    out = []
    for c in range(3):
        mine = idx == c
        hi = F.max_pool2d(torch.where(mine, flat, torch.full_like(flat, -torch.inf)), 3, 1, 1)
        lo = -F.max_pool2d(torch.where(mine, -flat, torch.full_like(flat, -torch.inf)), 3, 1, 1)
        out.append(torch.minimum(torch.maximum(rgb.reshape(-1, 3, h, w)[:, c:c + 1], lo), hi))
    return torch.cat(out, dim=1).reshape(rgb.shape)


#: name -> demosaic function ``(raw (*, 1, H, W), pattern) -> (*, 3, H, W)``.
DEMOSAIC: Registry[Callable[[torch.Tensor, CFAPattern | str], torch.Tensor]] = Registry("demosaic method")
DEMOSAIC.register("bilinear", demosaic_bilinear)
DEMOSAIC.register("malvar2004", demosaic_malvar2004)


def demosaic(raw: torch.Tensor, pattern: CFAPattern | str, method: str = "malvar2004") -> torch.Tensor:
    """Demosaic with a registered method (:data:`DEMOSAIC`): ``(*, 1, H, W)`` -> ``(*, 3, H, W)``."""
    if method not in DEMOSAIC:
        raise ValueError(f"demosaic method must be one of {sorted(DEMOSAIC)}, got {method!r}")
    return DEMOSAIC[method](raw, pattern)


class Demosaic(nn.Module):
    """``nn.Module`` of :func:`demosaic`.

    Args:
        pattern: Bayer layout.
        method: a name of :data:`DEMOSAIC`.
    """

    def __init__(self, pattern: CFAPattern | str, method: str = "malvar2004") -> None:
        super().__init__()
        if method not in DEMOSAIC:
            raise ValueError(f"demosaic method must be one of {sorted(DEMOSAIC)}, got {method!r}")
        self.pattern, self.method = _pattern(pattern), method

    def forward(self, raw: torch.Tensor) -> torch.Tensor:
        """(*, 1, H, W) -> (*, 3, H, W)."""
        return DEMOSAIC[self.method](raw, self.pattern)
