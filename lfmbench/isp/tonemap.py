r"""HDR tone mapping: linear scene-referred sRGB ``(*, 3, H, W)`` -> linear display-referred sRGB in [0, 1].

Every operator is two functions: ``stats(reference)`` reads the image statistics the operator needs (log-average
luminance, white point, base-layer range) from the *reference* image, and the operator applies them. The ISP
applies an estimate's tone curve with the statistics of the ground truth, so that the two are mapped the same way
(an estimate that is too bright looks too bright).

Defines
-------
- :func:`reinhard2002`, :func:`reinhard2002_stats`: the global photographic operator of Reinhard et al. (2002),
  eqs. 1-4: key scaling by the log-average luminance and the extended curve L (1 + L / L_white^2) / (1 + L).
- :func:`durand2002`, :func:`durand2002_stats`: the local base/detail operator of Durand and Dorsey (2002): the
  log luminance is split into an edge-preserving base layer and a detail layer, only the base is compressed (to a
  target contrast), the detail is kept. The base is computed with the guided filter of He et al. (2013), O(N) and
  free of the bilateral filter's memory cost, as an edge-preserving smoother in place of the bilateral filter.
- :func:`exposure_clip`, :func:`exposure_clip_stats`: no compression: scale the reference's percentile to 1 and
  clip (what a linear display shows).
- :data:`TONEMAP`: registry name -> :class:`ToneMapOperator` (``stats``, ``apply``, documented parameters).
- :class:`ToneMap`: the thin ``nn.Module`` wrapper.

Colour is kept by scaling the three channels with the luminance ratio ``L_out / L_in`` (Reinhard et al. 2002 sec. 3;
Durand and Dorsey 2002 sec. 5). Statistics are computed per leading item over all the other dims: for a
``(B, F, 3, H, W)`` sequence the curve is fixed over the F frames of a sample (no flicker of the tone curve).

References
----------
- E. Reinhard, M. Stark, P. Shirley, J. Ferwerda, "Photographic tone reproduction for digital images", ACM
  Transactions on Graphics 21(3) (SIGGRAPH 2002), pp. 267-276.
- F. Durand, J. Dorsey, "Fast bilateral filtering for the display of high-dynamic-range images", ACM Transactions on
  Graphics 21(3) (SIGGRAPH 2002), pp. 257-266.
- K. He, J. Sun, X. Tang, "Guided image filtering", IEEE TPAMI 35(6), 2013, pp. 1397-1409 (``kornia.filters.
  guided_blur``).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Mapping

import torch
from torch import nn

from lfmbench.check import check_tensor
from lfmbench.isp.color import luminance
from lfmbench.registry import Registry

__all__ = ["reinhard2002", "reinhard2002_stats", "durand2002", "durand2002_stats", "exposure_clip",
           "exposure_clip_stats", "ToneMapOperator", "TONEMAP", "tonemap", "ToneMap"]

#: Floor of the luminance in logarithms (Reinhard et al. 2002, eq. 1: the small delta), in the unit of the input.
_DELTA = 1e-6


def _per_item(v: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """A (N,) statistic shaped to broadcast against x (N, ...)."""
    return v.reshape((x.shape[0],) + (1,) * (x.ndim - 1))


def _quantile_per_item(x: torch.Tensor, q: float) -> torch.Tensor:
    flat = x.reshape(x.shape[0], -1)
    step = max(1, -(-flat.shape[1] // 4_000_000))  # torch.quantile's size limit: a regular subsample
    return torch.quantile(flat[:, ::step].float(), q, dim=1).to(x.dtype)


def _scale_colour(rgb: torch.Tensor, lum_in: torch.Tensor, lum_out: torch.Tensor) -> torch.Tensor:
    return rgb * (lum_out / lum_in.clamp_min(_DELTA))


# ---------------------------------------------------------------------------------------------- Reinhard 2002
def reinhard2002_stats(reference: torch.Tensor, white: str | float = "max") -> dict[str, torch.Tensor]:
    """Statistics of the photographic operator from a reference image.

    Args:
        reference: (N, ..., 3, H, W) linear sRGB (scene-referred, any linear unit).
        white: ``"max"`` (the paper: the largest luminance, after key scaling, maps to white), a percentile
            ``"p99.9"``, or a number: the white luminance in units of the key-scaled luminance.

    Returns:
        ``{"log_avg": (N,), "white": (N,)}``: the log-average luminance (eq. 1, unit of the input) and the white
        luminance in key-scaled units (dimensionless).
    """
    check_tensor(reference, "reference", "N * 3 H W")
    lum = luminance(reference).clamp_min(0.0)
    flat = lum.reshape(lum.shape[0], -1)
    log_avg = torch.exp(torch.log(_DELTA + flat).mean(dim=1))  # eq. 1
    if isinstance(white, (int, float)) and not isinstance(white, bool):
        lw = torch.full_like(log_avg, float(white))
    elif white == "max":
        lw = flat.amax(dim=1) / log_avg
    elif isinstance(white, str) and white.startswith("p"):
        lw = _quantile_per_item(lum, float(white[1:]) / 100.0) / log_avg
    else:
        raise ValueError(f"white must be 'max', 'p<percentile>' or a number, got {white!r}")
    return {"log_avg": log_avg, "white": lw.clamp_min(_DELTA)}


def reinhard2002(rgb: torch.Tensor, log_avg: torch.Tensor | float, white: torch.Tensor | float,
                 key: float = 0.18) -> torch.Tensor:
    r"""Global photographic tone reproduction (Reinhard et al. 2002, eqs. 2 and 4).

    .. math:: L = \frac{a}{\bar L_w} L_w, \qquad L_d = \frac{L\,(1 + L / L_{white}^2)}{1 + L}

    Args:
        rgb: (N, ..., 3, H, W) linear sRGB, scene-referred (any linear unit).
        log_avg: log-average luminance :math:`\bar L_w`, (N,) or scalar, unit of ``rgb``
            (:func:`reinhard2002_stats`).
        white: :math:`L_{white}`, (N,) or scalar, in key-scaled units (dimensionless).
        key: the key a (0.18: "normal-key", the paper's default).

    Returns:
        (N, ..., 3, H, W) display-referred linear sRGB; luminance in [0, 1] up to the white point (colours may
        exceed 1 in one channel: the encoder clips).

    Example (a pixel at the log-average maps to a (1 + a / Lw^2) / (1 + a)):
        >>> x = torch.ones(1, 3, 1, 1)
        >>> round(float(reinhard2002(x, 1.0, 1e9)[0, 0, 0, 0]), 6)
        0.152542
    """
    check_tensor(rgb, "rgb", "N * 3 H W")
    la = torch.as_tensor(log_avg, dtype=rgb.dtype, device=rgb.device)
    lw = torch.as_tensor(white, dtype=rgb.dtype, device=rgb.device)
    la = _per_item(la.expand(rgb.shape[0]), rgb) if la.ndim == 0 else _per_item(la, rgb)
    lw = _per_item(lw.expand(rgb.shape[0]), rgb) if lw.ndim == 0 else _per_item(lw, rgb)
    lum = luminance(rgb).clamp_min(0.0)
    scaled = key / la.clamp_min(_DELTA) * lum
    ld = scaled * (1.0 + scaled / (lw * lw)) / (1.0 + scaled)
    return _scale_colour(rgb, lum, ld)


# ----------------------------------------------------------------------------------------- Durand-Dorsey 2002
def _base_layer(log_lum: torch.Tensor, radius: int, eps: float) -> torch.Tensor:
    """Guided-filter (self-guided) smoothing of (N, ..., 1, H, W) log luminance; edge-preserving for edges whose
    local variance exceeds ``eps`` (He et al. 2013)."""
    from kornia.filters import guided_blur  # noqa: PLC0415

    h, w = log_lum.shape[-2:]
    flat = log_lum.reshape(-1, 1, h, w)
    k = 2 * int(radius) + 1
    k = min(k, 2 * ((min(h, w) - 1) // 2) + 1)  # the box must fit the image for reflect padding
    base = guided_blur(flat, flat, k, eps, separable=True) if k >= 3 else flat
    return base.reshape(log_lum.shape)


def durand2002_stats(reference: torch.Tensor, radius: int | None = None, eps: float = 0.16,
                     percentile: float = 0.5) -> dict[str, torch.Tensor]:
    """Range of the reference's base layer (log10 luminance), from which :func:`durand2002` takes its compression.

    Args:
        reference: (N, ..., 3, H, W) linear sRGB (any linear unit).
        radius: guided-filter radius in px (default 2 % of the larger image side, Durand and Dorsey's spatial
            sigma).
        eps: guided-filter regularisation in (log10 units)^2 (0.16 = 0.4^2, the paper's range sigma of 0.4).
        percentile: the base range is taken between this percentile and 100 - it (robust min/max), in percent.

    Returns:
        ``{"base_max": (N,), "base_min": (N,)}`` in log10 of the input unit.
    """
    check_tensor(reference, "reference", "N * 3 H W")
    base = _base_layer(torch.log10(luminance(reference).clamp_min(0.0) + _DELTA), _radius(reference, radius), eps)
    if percentile <= 0:
        flat = base.reshape(base.shape[0], -1)
        return {"base_max": flat.amax(1), "base_min": flat.amin(1)}
    return {"base_max": _quantile_per_item(base, 1.0 - percentile / 100.0),
            "base_min": _quantile_per_item(base, percentile / 100.0)}


def _radius(x: torch.Tensor, radius: int | None) -> int:
    return max(1, round(0.02 * max(x.shape[-2:]))) if radius is None else int(radius)


def durand2002(rgb: torch.Tensor, base_max: torch.Tensor | float, base_min: torch.Tensor | float,
               contrast: float = 50.0, radius: int | None = None, eps: float = 0.16) -> torch.Tensor:
    r"""Local base/detail tone mapping (Durand and Dorsey 2002, sec. 5), base layer by the guided filter.

    .. math:: B = \mathrm{GF}(\log_{10} L), \quad D = \log_{10} L - B, \quad
              \log_{10} L_d = s\,(B - B_{max}) + D, \quad s = \frac{\log_{10} c}{B_{max} - B_{min}}

    so the base range of the reference spans the target contrast c, the brightest base maps to 1, and the detail
    layer is kept unchanged.

    Args:
        rgb: (N, ..., 3, H, W) linear sRGB, scene-referred (any linear unit).
        base_max, base_min: the reference's base range, (N,) or scalar, log10 of the unit of ``rgb``
            (:func:`durand2002_stats`).
        contrast: target contrast c of the base layer (the paper uses 5; 50 keeps night scenes' lamps distinct).
        radius: guided-filter radius in px (default 2 % of the larger side).
        eps: guided-filter regularisation, (log10 units)^2.

    Returns:
        (N, ..., 3, H, W) display-referred linear sRGB (luminance <= 1 where the detail is <= 0 at the top base).
    """
    check_tensor(rgb, "rgb", "N * 3 H W")
    if not contrast > 1:
        raise ValueError(f"contrast must be > 1, got {contrast!r}")
    bmax = torch.as_tensor(base_max, dtype=rgb.dtype, device=rgb.device)
    bmin = torch.as_tensor(base_min, dtype=rgb.dtype, device=rgb.device)
    bmax = _per_item(bmax.expand(rgb.shape[0]) if bmax.ndim == 0 else bmax, rgb)
    bmin = _per_item(bmin.expand(rgb.shape[0]) if bmin.ndim == 0 else bmin, rgb)
    lum = luminance(rgb).clamp_min(0.0)
    log_l = torch.log10(lum + _DELTA)
    base = _base_layer(log_l, _radius(rgb, radius), eps)
    s = math.log10(contrast) / (bmax - bmin).clamp_min(1e-3)
    ld = torch.pow(10.0, s * (base - bmax) + (log_l - base))
    return _scale_colour(rgb, lum, ld)


# -------------------------------------------------------------------------------------------- linear + clip
def exposure_clip_stats(reference: torch.Tensor, percentile: float = 99.0) -> dict[str, torch.Tensor]:
    """``{"scale": (N,)}``: the reference luminance at ``percentile`` (unit of the input)."""
    check_tensor(reference, "reference", "N * 3 H W")
    return {"scale": _quantile_per_item(luminance(reference).clamp_min(0.0), percentile / 100.0).clamp_min(_DELTA)}


def exposure_clip(rgb: torch.Tensor, scale: torch.Tensor | float) -> torch.Tensor:
    """No compression: ``rgb / scale`` (the reference's percentile -> 1); the encoder clips at 1.

    Args:
        rgb: (N, ..., 3, H, W) linear sRGB (any linear unit). scale: (N,) or scalar, the unit of ``rgb``.

    Returns:
        (N, ..., 3, H, W) display-referred linear sRGB.
    """
    check_tensor(rgb, "rgb", "N * 3 H W")
    sc = torch.as_tensor(scale, dtype=rgb.dtype, device=rgb.device)
    return rgb / _per_item(sc.expand(rgb.shape[0]) if sc.ndim == 0 else sc, rgb)


@dataclass(frozen=True)
class ToneMapOperator:
    """A registered tone-mapping operator.

    Attributes:
        name: registry key. reference: its source.
        stats: ``stats(reference, **stats_params) -> dict`` of (N,) tensors.
        apply: ``apply(rgb, **stats, **apply_params) -> rgb``.
        stats_params, apply_params: the parameters each part takes, with their defaults (what a pipeline YAML may
            set).
    """

    name: str
    reference: str
    stats: Callable[..., dict[str, torch.Tensor]]
    apply: Callable[..., torch.Tensor]
    stats_params: Mapping[str, Any]
    apply_params: Mapping[str, Any]


#: name -> tone-mapping operator.
TONEMAP: Registry[ToneMapOperator] = Registry("tone-mapping operator")
for _op in [
    ToneMapOperator("reinhard2002", "Reinhard et al., ACM TOG 21(3) 2002 (global, extended)", reinhard2002_stats,
                    reinhard2002, MappingProxyType({"white": "max"}), MappingProxyType({"key": 0.18})),
    ToneMapOperator("durand2002", "Durand & Dorsey, ACM TOG 21(3) 2002 (local base/detail; guided-filter base, "
                    "He et al. TPAMI 2013)", durand2002_stats, durand2002,
                    MappingProxyType({"radius": None, "eps": 0.16, "percentile": 0.5}),
                    MappingProxyType({"contrast": 50.0, "radius": None, "eps": 0.16})),
    ToneMapOperator("clip", "linear: reference percentile -> 1, clipped", exposure_clip_stats, exposure_clip,
                    MappingProxyType({"percentile": 99.0}), MappingProxyType({})),
]:
    TONEMAP.register(_op.name, _op)


def tonemap(rgb: torch.Tensor, reference: torch.Tensor | None = None, method: str = "reinhard2002",
            **params: Any) -> torch.Tensor:
    """Tone-map ``rgb`` with the statistics of ``reference`` (default: ``rgb`` itself).

    Args:
        rgb: (N, ..., 3, H, W) linear sRGB, scene-referred. reference: same shape (the ground truth).
        method: a name of :data:`TONEMAP`. params: the operator's ``stats_params`` / ``apply_params``.

    Returns:
        (N, ..., 3, H, W) display-referred linear sRGB.
    """
    if method not in TONEMAP:
        raise ValueError(f"tone-mapping method must be one of {sorted(TONEMAP)}, got {method!r}")
    op = TONEMAP[method]
    unknown = sorted(set(params) - set(op.stats_params) - set(op.apply_params))
    if unknown:
        raise ValueError(f"tone-mapping method {method!r}: unknown parameter(s) {unknown} "
                         f"(allowed: {sorted(set(op.stats_params) | set(op.apply_params))})")
    st = op.stats(rgb if reference is None else reference,
                  **{k: params.get(k, v) for k, v in op.stats_params.items()})
    return op.apply(rgb, **st, **{k: params.get(k, v) for k, v in op.apply_params.items()})


class ToneMap(nn.Module):
    """``nn.Module`` of :func:`tonemap`: ``forward(rgb, reference=None)``.

    Args:
        method: a name of :data:`TONEMAP`. params: its parameters.
    """

    def __init__(self, method: str = "reinhard2002", **params: Any) -> None:
        super().__init__()
        if method not in TONEMAP:
            raise ValueError(f"tone-mapping method must be one of {sorted(TONEMAP)}, got {method!r}")
        self.method, self.params = method, dict(params)

    def forward(self, rgb: torch.Tensor, reference: torch.Tensor | None = None) -> torch.Tensor:
        """(N, ..., 3, H, W) -> (N, ..., 3, H, W)."""
        return tonemap(rgb, reference, self.method, **self.params)
