"""Errors outside the LED regions: the motion ghosts and comet artefacts of fusion (ISET-LFM Fig. 6).

Defines
-------
- :func:`led_mask`: the LED regions of a sample, dilated by a safety margin.
- :func:`ghost_zone`: a band around the LED regions, where a blurred long exposure fused with a sharp short one
  leaves trails ("comets") and double edges (ghosts).
- :func:`masked_psnr_mu`: mu-law PSNR restricted to a pixel mask.
- :func:`outside_led_metrics`: per-sample background PSNR-mu, ghost-zone mean absolute mu-law error and comet
  excess (mean positive mu-law error: light smeared where the GT is darker).

All errors are computed on the mu-law tone-mapped images normalised by the GT peak of the whole sample, the
PSNR-mu convention of :mod:`lfmbench.metrics.hdr` (Kalantari & Ramamoorthi 2017), so they are comparable with
the full-image PSNR-mu.

References
----------
- A. Jam et al., ISET-LFM (Fig. 6: comet artefact of fusing sharp LPD with the motion trail of the SPD).
- N. K. Kalantari and R. Ramamoorthi, ACM TOG 36(4), 2017 (mu-law, PSNR-mu).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from lfmbench.check import check_tensor
from lfmbench.metrics.hdr import MU_DEFAULT, mu_law, normalize_hdr

#: Margin (px) added around every LED region before a pixel counts as "outside".
LED_MARGIN_PX = 2
#: Width (px) of the band around the LED regions searched for ghosts and comets.
GHOST_RING_PX = 16


def dilate(mask: torch.Tensor, px: int) -> torch.Tensor:
    """Binary dilation by a (2 px + 1)^2 square, as two separable 1-D max-pools (rows, then columns).

    Args:
        mask: (*, H, W) bool.
        px: radius in px (0: unchanged).

    Returns:
        (*, H, W) bool.
    """
    if px <= 0:
        return mask
    shape = mask.shape
    m = mask.reshape(-1, 1, shape[-2], shape[-1]).float()
    m = F.max_pool2d(m, (1, 2 * px + 1), stride=1, padding=(0, px))
    m = F.max_pool2d(m, (2 * px + 1, 1), stride=1, padding=(px, 0))
    return (m > 0).reshape(shape)


def led_mask(light_index: torch.Tensor, margin_px: int = LED_MARGIN_PX) -> torch.Tensor:
    """LED regions (``light_index >= 0``) dilated by ``margin_px``.

    Args:
        light_index: (B, F, 1, H, W) int, -1 = no light.
        margin_px: dilation in px.

    Returns:
        (B, F, 1, H, W) bool.
    """
    check_tensor(light_index, "light_index", "B F 1 H W")
    return dilate(light_index >= 0, margin_px)


def ghost_zone(light_index: torch.Tensor, margin_px: int = LED_MARGIN_PX,
               ring_px: int = GHOST_RING_PX) -> torch.Tensor:
    """Band of pixels within ``ring_px`` of an LED region but outside its ``margin_px`` dilation.

    Args:
        light_index: (B, F, 1, H, W) int, -1 = no light.
        margin_px, ring_px: inner and outer distances in px (``ring_px > margin_px``).

    Returns:
        (B, F, 1, H, W) bool.
    """
    if ring_px <= margin_px:
        raise ValueError(f"ring_px must exceed margin_px, got ring_px={ring_px}, margin_px={margin_px}")
    check_tensor(light_index, "light_index", "B F 1 H W")
    base = light_index >= 0
    return dilate(base, ring_px) & ~dilate(base, margin_px)


def _tone_mapped(pred: torch.Tensor, gt: torch.Tensor, mu: float) -> tuple[torch.Tensor, torch.Tensor]:
    p, g = normalize_hdr(pred, gt, "max")
    return mu_law(p, mu), mu_law(g, mu)


def masked_psnr_mu(pred: torch.Tensor, gt: torch.Tensor, mask: torch.Tensor, mu: float = MU_DEFAULT) -> torch.Tensor:
    r"""PSNR-mu over the pixels of ``mask``: :math:`10\log_{10}(1/\mathrm{MSE}_{mask})` of mu-law images.

    Args:
        pred, gt: (B, F, 1, H, W), input-referred e-; normalised by the GT peak of each sample.
        mask: (B, F, 1, H, W) bool.
        mu: mu-law compression.

    Returns:
        (B,) in dB; NaN where the mask is empty, inf where the masked pixels agree exactly.
    """
    if mask.shape != pred.shape:
        raise ValueError(f"mask must have the shape of pred {tuple(pred.shape)}, got {tuple(mask.shape)}")
    tp, tg = _tone_mapped(pred, gt, mu)
    m = mask.double()
    se = ((tp - tg).double() ** 2 * m).reshape(pred.shape[0], -1).sum(1)
    n = m.reshape(pred.shape[0], -1).sum(1)
    mse = se / n
    return torch.where(n > 0, 10 * torch.log10(1.0 / mse), torch.full_like(mse, float("nan")))


def outside_led_metrics(pred: torch.Tensor, gt: torch.Tensor, light_index: torch.Tensor,
                        margin_px: int = LED_MARGIN_PX, ring_px: int = GHOST_RING_PX,
                        mu: float = MU_DEFAULT) -> list[dict]:
    r"""Per-sample errors away from the LEDs.

    - ``psnr_mu_outside``: :func:`masked_psnr_mu` over every pixel outside the dilated LED regions (dB).
    - ``ghost_mae_mu``: mean :math:`|T(p) - T(g)|` over :func:`ghost_zone` (mu-law units, [0, 1]).
    - ``comet_excess_mu``: mean :math:`\max(T(p) - T(g), 0)` over the ghost zone: light smeared outside the
      source, the comet of Fig. 6 (mu-law units).

    Args:
        pred, gt: (B, F, 1, H, W) input-referred e-.
        light_index: (B, F, 1, H, W) int, -1 = no light.
        margin_px, ring_px: see :func:`ghost_zone` (px).
        mu: mu-law compression.

    Returns:
        One dict per sample; NaN for an empty zone.
    """
    if pred.shape != gt.shape or light_index.shape != pred.shape:
        raise ValueError(f"pred, gt and light_index must share the shape (B, F, 1, H, W), got {tuple(pred.shape)}, "
                         f"{tuple(gt.shape)}, {tuple(light_index.shape)}")
    outside = ~led_mask(light_index, margin_px)
    zone = ghost_zone(light_index, margin_px, ring_px)
    psnr_out = masked_psnr_mu(pred, gt, outside, mu)
    tp, tg = _tone_mapped(pred, gt, mu)
    d = (tp - tg).double()
    b = pred.shape[0]
    z = zone.double().reshape(b, -1)
    nz = z.sum(1)
    mae = (d.abs().reshape(b, -1) * z).sum(1) / nz
    excess = (d.clamp_min(0).reshape(b, -1) * z).sum(1) / nz
    return [{"psnr_mu_outside": float(psnr_out[i]),
             "ghost_mae_mu": float(mae[i]) if nz[i] > 0 else float("nan"),
             "comet_excess_mu": float(excess[i]) if nz[i] > 0 else float("nan")} for i in range(b)]
