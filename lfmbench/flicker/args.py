"""Argument handling of the PWM model: checks (each error names the argument), broadcasting, numpy/torch promotion.

torch is not imported here: an argument can be a tensor only when the caller imported torch, so the numpy path
(the renderer's: scene checks, light timing) runs without loading it (seconds of every render worker's start).
"""
from __future__ import annotations

import sys
from typing import Any

import numpy as np

from lfmbench.check import check_array


ArrayLike = Any  # float, numpy array or torch tensor


def _is_tensor(x: Any) -> bool:
    """``isinstance(x, torch.Tensor)``, without importing torch (no tensor exists before it is imported)."""
    torch = sys.modules.get("torch")
    return torch is not None and isinstance(x, torch.Tensor)


def _is_torch(*xs: ArrayLike) -> bool:
    """Whether any of ``xs`` is a tensor (one module lookup for all: called for every light of every sample)."""
    torch = sys.modules.get("torch")
    if torch is None:
        return False
    tensor = torch.Tensor
    for x in xs:
        if isinstance(x, tensor):
            return True
    return False


def _np_view(x: ArrayLike) -> np.ndarray:
    if _is_tensor(x):
        return x.detach().cpu().numpy()
    return np.asarray(x)


def _check_broadcast(names: tuple[str, ...], values: tuple[ArrayLike, ...]) -> None:
    shapes = [tuple(np.shape(_np_view(v))) if not _is_tensor(v) else tuple(v.shape)
              for v in values]
    try:
        np.broadcast_shapes(*shapes)
    except ValueError:
        desc = ", ".join(f"{n}{s}" for n, s in zip(names, shapes))
        raise ValueError(f"shape mismatch: {desc} do not broadcast together") from None


def _check_pwm_args(phase, exposure, period, duty, amplitude, offset, rise_time, fall_time) -> None:
    check_array("phase", phase)
    check_array("exposure", exposure, lo=0.0)
    check_array("period", period, lo=0.0, lo_open=True)
    check_array("duty", duty, lo=0.0, hi=1.0)
    check_array("amplitude", amplitude, lo=0.0)
    check_array("offset", offset, lo=0.0)
    check_array("rise_time", rise_time, lo=0.0)
    check_array("fall_time", fall_time, lo=0.0)
    _check_broadcast(("phase", "exposure", "period", "duty", "amplitude", "offset", "rise_time", "fall_time"),
                     (phase, exposure, period, duty, amplitude, offset, rise_time, fall_time))
    ramps = (_np_view(rise_time) + _np_view(fall_time)) / 2.0
    T, D = _np_view(period), _np_view(duty)
    room = np.minimum(D, 1.0 - D) * T
    if (ramps > room * (1 + 1e-12)).any():
        raise ValueError("rise_time and fall_time too long for this duty and period: the ramps overlap; "
                         "need (rise_time + fall_time)/2 <= min(duty, 1 - duty) * period")


def _is_zero(x: ArrayLike) -> bool:
    if isinstance(x, (int, float)):
        return x == 0
    return not bool(_np_view(x).any())


def _as_tensors(*xs: ArrayLike) -> list:
    """Promote mixed numpy/torch/float arguments to tensors of one floating dtype on one device."""
    import torch  # noqa: PLC0415 - only called with a tensor among xs: torch is loaded

    tensors = [x for x in xs if isinstance(x, torch.Tensor)]
    device = tensors[0].device
    dtype = tensors[0].dtype if tensors[0].is_floating_point() else torch.get_default_dtype()
    for t in tensors[1:]:
        if t.is_floating_point():
            dtype = torch.promote_types(dtype, t.dtype)
    if dtype not in (torch.float32, torch.float64):
        dtype = torch.float32 if dtype in (torch.float16, torch.bfloat16) else torch.float64
    out = []
    for x in xs:
        if isinstance(x, torch.Tensor):
            out.append(x.to(device=device, dtype=dtype))
        elif isinstance(x, (int, float)) and not isinstance(x, bool):
            # a fill on the device, not a copy from the host (a copy would wait for the device's queue)
            out.append(torch.full((), float(x), dtype=dtype, device=device))
        else:
            out.append(torch.as_tensor(np.asarray(x, dtype=np.float64), device=device).to(dtype))
    return out
