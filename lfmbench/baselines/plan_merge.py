"""Fusion baselines of the capture plans other than the split pixel (LOFIC, staggered, chopped, single exposure).

Every capture of a plan arrives input-referred to the plan's reference exposure (``<capture>_e``: electrons of the
reference photodiode over the reference windows, the ``gt`` units; :func:`lfmbench.sensor.simulate_plan_electrons`),
in plan order, most sensitive first (the architecture registry, :data:`lfmbench.sensor.plan.ARCHITECTURES`,
requires it: LOFIC high conversion gain first, staggered longest exposure first). Their standard HDR merge is then
one rule, exposure selection: per pixel, the first capture that is not saturated (the one with the most signal
electrons below saturation, hence the best SNR), the last one where all are.

- LOFIC: HCG below its saturation, LCG above (the gain switch of S. Sugawa et al., ISSCC 2005).
- Staggered (DOL): the longest unsaturated exposure, scaled by the exposure ratio (the selection merge of
  multi-exposure HDR, e.g. P. Debevec and J. Malik, "Recovering High Dynamic Range Radiance Maps from Photographs",
  SIGGRAPH 1997, with hat weights reduced to 0/1).
- Chopped, single: the one capture (clipped where saturated).

Plans whose captures integrate different windows (staggered) also have :func:`exposure_select_bounded`: exposure
selection bounded below by every saturated capture. A saturated capture's input-referred value is a lower bound
of its exposure (the charge was at least the saturation level); where the longest exposure saturates on a bright
LED and selection falls back to a short window that missed the PWM pulse, the bound keeps the lamp lit. It is the
capture-plan counterpart of the split pixel's ``flicker_aware`` (the SPD bounds the LPD from below; docs/guide/baselines.md).
"""
from __future__ import annotations

import torch

from lfmbench.baselines.base import register_plan_merge
from lfmbench.baselines.classic import BatchError, _get

__all__ = ["plan_captures", "exposure_select", "exposure_select_bounded"]


def plan_captures(batch: dict) -> list[str]:
    """The capture names of a batch in plan order: its ``<capture>_e`` keys, in the order the dataset wrote them
    (:func:`lfmbench.datasets.assembly.assemble_sample`), which is the plan's (and that of ``saturated``)."""
    caps = [k[:-2] for k in batch if k.endswith("_e")]
    if not caps:
        raise BatchError(f"batch has no input-referred capture (keys ending in '_e'; keys: {sorted(batch)}): ask the "
                         "dataset for the 'input_referred' output")
    return caps


@register_plan_merge
def exposure_select(batch: dict) -> torch.Tensor:
    """Exposure selection: per pixel, the first unsaturated capture of the plan (all saturated: the last).

    Args:
        batch: ``<capture>_e`` (B, F, 1, H, W) e- for N captures in plan order and ``saturated`` (B, F, N, H, W).

    Returns:
        (B, F, 1, H, W) estimate in the ``gt`` units (e-).
    """
    caps = plan_captures(batch)
    xs = [_get(batch, f"{c}_e") for c in caps]
    sat = _get(batch, "saturated").bool()
    if sat.shape[2] != len(caps) or any(x.shape != xs[0].shape or x.shape[2] != 1 for x in xs):
        raise BatchError(f"saturated must have one channel per capture ({caps}) and the captures the shape "
                         f"(B, F, 1, H, W); got saturated {tuple(sat.shape)}, captures "
                         f"{[tuple(x.shape) for x in xs]}")
    out = xs[-1].clone()
    for i in range(len(xs) - 2, -1, -1):                       # earlier (more sensitive) captures win
        out = torch.where(sat[:, :, i:i + 1], out, xs[i])
    return out


@register_plan_merge
def exposure_select_bounded(batch: dict) -> torch.Tensor:
    """Exposure selection bounded below by the saturated captures: per pixel ``max(exposure_select, max over the
    saturated captures c of c_e)`` (a saturated capture's input-referred value is a lower bound of its exposure).

    Args:
        batch: as :func:`exposure_select`.

    Returns:
        (B, F, 1, H, W) estimate in the ``gt`` units (e-); equal to :func:`exposure_select` where no capture
        saturates, never below it.
    """
    out = exposure_select(batch)                                # checks the shapes
    sat = _get(batch, "saturated").bool()
    for i, c in enumerate(plan_captures(batch)):
        x = _get(batch, f"{c}_e")
        out = torch.where(sat[:, :, i:i + 1], torch.maximum(out, x), out)
    return out
