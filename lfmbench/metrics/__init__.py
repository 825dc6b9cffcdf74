"""Metrics that score a fusion output against the flicker-free ground truth, and the one metric registry.

Modules: :mod:`~lfmbench.metrics.hdr` (PSNR-L, PSNR-mu, SSIM-mu, PU21-PSNR, ColorVideoVDP),
:mod:`~lfmbench.metrics.flicker` (IEEE P2020 FMI / FDI / MMP per LED region, FSI, series error, light dropout,
LED brightness error, saturation flag), :mod:`~lfmbench.metrics.regions` (errors inside and outside the LED
regions: ghosts and comets) and :mod:`~lfmbench.metrics.display` (display-referred PSNR / SSIM after the ISP:
secondary columns, group ``display``; the primary metrics stay on linear values).

Every metric is ONE entry of :data:`REGISTRY` (a :class:`MetricSpec` given to :func:`register_metric`): name, version (bumped whenever its
definition or defaults change, so results stay comparable), reference, unit, ranking direction, column
header, aggregation over scenes, and how it is computed: its own function ``fn(pred, batch, options)``, a
``derive(values)`` of other metrics of the same sample, or (``fn`` and ``derive`` both None) a
:class:`MetricBlock` of :data:`BLOCKS` that computes several metrics in one pass (the P2020 region block,
the perceptual block: pycvvdp is loaded and luminance converted once per batch). :func:`score_batch`,
``lfmbench evaluate`` and ``lfmbench leaderboard`` all read this registry; :func:`metric_versions` is stored
with every result. The primary ranking score is :data:`PRIMARY` (``led_score``). See ``docs/guide/metrics.md``.

This package face only re-exports: :mod:`~lfmbench.metrics.spec` (what a metric is),
:mod:`~lfmbench.metrics.registry` (the registered metrics and blocks), :mod:`~lfmbench.metrics.scoring`
(:func:`score_batch`). The registry is torch-free; the modules that compute metrics (and :func:`score_batch`,
:class:`ScoreOptions`) are imported on first access (PEP 562), so ``lfmbench leaderboard`` and the command line's
start-up read the registry without loading torch.
"""
import importlib

from lfmbench.metrics.registry import (BLOCKS, PRIMARY, REGISTRY, SECONDARY_GROUPS, columns, led_score,
                                       metric_versions, register_metric)
from lfmbench.metrics.spec import MetricBlock, MetricSpec

#: Names imported on first access: the metric modules and the scoring entry points (they import torch).
_LAZY = {"display": None, "flicker": None, "hdr": None, "regions": None, "ScoreOptions": "scoring",
         "score_batch": "scoring"}


def __getattr__(name: str):
    if name in _LAZY:
        mod = importlib.import_module(f"lfmbench.metrics.{_LAZY[name] or name}")
        value = mod if _LAZY[name] is None else getattr(mod, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'lfmbench.metrics' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(_LAZY))

__all__ = ["MetricSpec", "MetricBlock", "REGISTRY", "BLOCKS", "PRIMARY", "SECONDARY_GROUPS", "metric_versions",
           "register_metric", "score_batch", "ScoreOptions", "led_score", "columns", "display", "flicker", "hdr", "regions"]
