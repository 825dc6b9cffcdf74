"""The registered metrics (:data:`REGISTRY`, one :class:`~lfmbench.metrics.spec.MetricSpec` each, in leaderboard
column order), the multi-metric blocks (:data:`BLOCKS`), the primary score :func:`led_score` and :data:`PRIMARY`,
and the readers of the registry that tables use (:func:`columns`, :func:`metric_versions`).

Torch-free at import: the modules that compute the metrics (:mod:`~lfmbench.metrics.hdr`, ``flicker``,
``regions``, ``display``) are imported when a metric is computed, so the leaderboard and the command line read the
registry (names, versions, ranges, directions) without loading torch."""
from __future__ import annotations

import importlib
import math
from typing import TYPE_CHECKING

from lfmbench.metrics.spec import MetricBlock, MetricSpec
from lfmbench.registry import Registry

if TYPE_CHECKING:
    import torch

__all__ = ["REGISTRY", "BLOCKS", "PRIMARY", "SECONDARY_GROUPS", "register_metric", "led_score", "columns",
           "metric_versions"]


_KR17 = "Kalantari & Ramamoorthi, ACM TOG 36(4) 2017"
_P2020 = "IEEE P2020; CARpublic/P2020-flicker metrics/flicker.py; Deegan EI 2018 AVM-146"
_DS80 = "Derringer & Suich, J. Quality Technology 12(4) 1980 (desirability, geometric mean)"


def led_score(dropout_rate: float, fmi_abs_err: float, led_rel_err: float) -> float:
    r"""The primary ranking score: geometric mean of three desirabilities of the LED regions, in [0, 1].

    :math:`S = \left[(1 - D)\,(1 - \min(1, |\Delta FMI|))\,(1 - E)\right]^{1/3}` with D = light dropout rate
    (ISET-LFM Fig. 5), :math:`|\Delta FMI|` = |FMI(output) - FMI(GT)| (IEEE P2020) and E = truncated relative
    brightness error of the lights (:func:`lfmbench.metrics.flicker.truncated_rel_err`); each factor is 1 for a
    perfect reproduction and 0 for the worst (Derringer & Suich 1980: an unacceptable criterion zeroes the
    score). NaN when an input is NaN (no LED region).

    >>> round(led_score(0.0, 0.0, 0.0), 6), round(led_score(0.5, 0.0, 0.0), 6), led_score(1.0, 0.1, 0.1)
    (1.0, 0.793701, 0.0)
    """
    d = [1.0 - float(dropout_rate), 1.0 - min(1.0, float(fmi_abs_err)), 1.0 - float(led_rel_err)]
    if not all(math.isfinite(x) for x in d):
        return float("nan")
    return float(max(0.0, d[0]) * max(0.0, d[1]) * max(0.0, d[2])) ** (1.0 / 3.0)


def _m(name: str):
    """The metric module ``lfmbench.metrics.<name>`` (imported on first use: it imports torch)."""
    return importlib.import_module(f"lfmbench.metrics.{name}")


def _psnr_mu_led(pred: torch.Tensor, batch: dict, o) -> torch.Tensor:
    """PSNR-mu over the LED region pixels (``light_index >= 0``) of every frame, (B,) dB."""
    return _m("regions").masked_psnr_mu(pred, batch["gt"], batch["light_index"] >= 0)


def _flicker_block(pred: torch.Tensor, batch: dict, o) -> list[dict]:
    return _m("flicker").region_flicker_metrics(pred, batch["gt"], batch["light_index"], batch.get("saturated"),
                                                batch.get("lpd_lcg_e"), o.region)


def _region_block(pred: torch.Tensor, batch: dict, o) -> list[dict]:
    """Ghost and comet errors around the LED regions and PSNR-mu outside them (group ``region``: a cross-sensor
    column, scored against ``gt_common`` with ``ScoreOptions(reference="common")``, so a block of its own)."""
    return _m("regions").outside_led_metrics(pred, batch["gt"], batch["light_index"], o.margin_px, o.ring_px)


def _perceptual_block(pred: torch.Tensor, batch: dict, o) -> list[dict]:
    v = _m("hdr").perceptual_metrics(pred, batch["gt"], o.cd_per_unit, o.fps)
    return [{k: x[i] for k, x in v.items()} for i in range(pred.shape[0])]


def _display_block(pred: torch.Tensor, batch: dict, o) -> list[dict]:
    display = _m("display")
    sensor = o.sensor if o.sensor is not None else display.sensor_of_batch(batch)
    v = display.display_metrics(pred, batch["gt"], sensor, o.isp)
    return [{k: x[i] for k, x in v.items()} for i in range(pred.shape[0])]


#: Multi-metric blocks, by group name (each computed once per batch).
BLOCKS: Registry[MetricBlock] = Registry("metric block")
for _b in (MetricBlock("perceptual", _perceptual_block, on_error="record"),
           MetricBlock("flicker", _flicker_block, needs=("light_index",)),
           MetricBlock("region", _region_block, needs=("light_index",)),
           MetricBlock("display", _display_block, on_error="record")):
    BLOCKS.register(_b.name, _b)

#: Groups of secondary metrics, added after a protocol was published: they never enter the primary score, and a
#: result file written before they existed lacks them (the leaderboard shows an empty cell, not a conflict).
SECONDARY_GROUPS: tuple[str, ...] = ("display",)

#: The metric the leaderboard ranks by unless told otherwise.
PRIMARY = "led_score"

#: name -> spec of every metric :func:`lfmbench.metrics.score_batch` can report, in leaderboard column order;
#: :func:`register_metric` adds one.
REGISTRY: Registry[MetricSpec] = Registry("metric")

#: The block that produces each block-computed group's metrics.
_BLOCK_OF_GROUP = {"perceptual": "perceptual", "flicker": "flicker", "region": "region", "display": "display"}


def _spec_error(s: MetricSpec) -> str | None:
    """What is wrong with a spec (inputs of ``derive`` aside), or None."""
    kinds = (s.fn is not None) + (s.derive is not None)
    if kinds > 1:
        return "give fn or derive, not both"
    if kinds == 0 and s.group not in _BLOCK_OF_GROUP:
        return f"no fn, no derive and no block for group {s.group!r}"
    if s.aggregate not in ("mean", "pooled") or (s.aggregate == "pooled") != (s.weight is not None):
        return "aggregate must be 'mean', or 'pooled' with a weight"
    if s.show not in ("console", "table", "none"):
        return f"show must be console, table or none, got {s.show!r}"
    if not s.header:
        return "a column header is needed"
    return None


def _inputs_error(s: MetricSpec) -> str | None:
    missing = [i for i in s.inputs if i not in REGISTRY]
    return f"derive inputs {missing} are not registered" if missing else None


def register_metric(spec: MetricSpec, *, check_inputs: bool = True) -> MetricSpec:
    """Register ``spec`` under ``spec.name`` (appended to the columns), after checking it: one of ``fn`` and
    ``derive`` (or a group computed by a block), a known aggregation and display, a header, and (``check_inputs``)
    the metrics ``derive`` reads registered already. Raises ``ValueError`` naming the metric."""
    if not isinstance(spec, MetricSpec):
        raise ValueError(f"a metric must be a MetricSpec, got {type(spec).__name__}")
    why = _spec_error(spec) or (_inputs_error(spec) if check_inputs else None)
    if why:
        raise ValueError(f"metric {spec.name!r}: {why}")
    return REGISTRY.register(spec.name, spec)


for _s in [
    MetricSpec("led_score", "1.0", _DS80 + " of 1 - dropout (ISET-LFM Fig. 5), 1 - |dFMI| (IEEE P2020) and "
               "1 - LED brightness error", "1", True, "led", "LED score",
               derive=lambda v: led_score(v["dropout_rate"], v["fmi_abs_err"], v["led_rel_err"]),
               inputs=("dropout_rate", "fmi_abs_err", "led_rel_err"), show="console", valid=(0.0, 1.0)),
    MetricSpec("dropout_rate", "1.0", "ISET-LFM Fig. 5: region-frames with output < 0.5 GT", "1", False, "flicker",
               "dropout", aggregate="pooled", weight="region_frames", show="console", valid=(0.0, 1.0)),
    MetricSpec("fmi_abs_err", "1.0", "|FMI(output) - FMI(GT)| per light", "1", False, "flicker", "abs dFMI",
               show="console", valid=(0.0, math.inf)),
    MetricSpec("led_rel_err", "1.0", "min(1, |p - g| / g) of LED ROI means, mean over region-frames", "1", False,
               "flicker", "LED err", aggregate="pooled", weight="region_frames", show="console", valid=(0.0, 1.0)),
    MetricSpec("psnr_mu_led", "1.0", _KR17 + " over the LED region pixels", "dB", True, "led", "PSNR-mu LED",
               fn=_psnr_mu_led, needs=("light_index",), digits=2, valid=(0.0, 1000.0), inf_ok=True),
    MetricSpec("psnr_mu", "1.0", _KR17 + " (mu = 5000)", "dB", True, "hdr", "PSNR-mu dB",
               fn=lambda p, b, o: _m("hdr").psnr_mu(p, b["gt"]), digits=2, show="console", valid=(0.0, 1000.0), inf_ok=True),
    MetricSpec("psnr_l", "1.0", _KR17 + " (normalised by GT peak)", "dB", True, "hdr", "PSNR-L dB",
               fn=lambda p, b, o: _m("hdr").psnr_l(p, b["gt"]), digits=2, valid=(0.0, 1000.0), inf_ok=True),
    MetricSpec("ssim_mu", "1.0", "Wang et al. IEEE TIP 2004 via kornia.metrics.ssim, on mu-law images", "1", True,
               "hdr", "SSIM-mu", fn=lambda p, b, o: _m("hdr").ssim_mu(p, b["gt"]), valid=(-1.0, 1.0)),
    MetricSpec("pu21_psnr", "1.0", "Mantiuk & Azimi PCS 2021 via pycvvdp.pu_psnr_y", "dB", True, "perceptual",
               "PU21 dB", digits=2, valid=(-1000.0, 1000.0), inf_ok=True),
    MetricSpec("cvvdp_jod", "1.0", "Mantiuk et al. ACM TOG 2024 (ColorVideoVDP) via pycvvdp", "JOD", True,
               "perceptual", "JOD", show="console", valid=(-1000.0, 10.0)),
    MetricSpec("mmp_pred", "1.0", _P2020 + " (MMP, delta 0.1)", "1", True, "flicker", "MMP", valid=(0.0, 1.0)),
    MetricSpec("fdi_pred", "1.0", _P2020 + " (FDI, threshold 0.1, OFF level from a ring)", "1", True, "flicker",
               "FDI", valid=(0.0, 1.0)),
    MetricSpec("series_rel_rmse", "1.0", "relative RMS error of the ROI series vs GT", "1", False, "flicker",
               "series err", valid=(0.0, math.inf)),
    MetricSpec("psnr_mu_outside", "1.0", _KR17 + " outside dilated LED regions", "dB", True, "region",
               "PSNR-mu out", digits=2, valid=(0.0, 1000.0), inf_ok=True),
    MetricSpec("ghost_mae_mu", "1.0", "ISET-LFM Fig. 6: mean |mu-law error| in a band around LEDs", "1", False,
               "region", "ghost", show="console", valid=(0.0, 1.0)),
    MetricSpec("comet_excess_mu", "1.0", "ISET-LFM Fig. 6: mean positive mu-law error around LEDs", "1", False,
               "region", "comet", show="none", valid=(0.0, 1.0)),
    MetricSpec("fmi_pred", "1.0", _P2020 + " (FMI)", "1", False, "flicker", "FMI", show="none", valid=(-math.inf, math.inf)),
    MetricSpec("fmi_gt", "1.0", _P2020 + " (FMI of the GT)", "1", False, "flicker", "FMI GT", show="none", valid=(0.0, 1.0)),
    MetricSpec("mmp_gt", "1.0", _P2020 + " (MMP of the GT)", "1", True, "flicker", "MMP GT", show="none", valid=(0.0, 1.0)),
    MetricSpec("fdi_gt", "1.0", _P2020 + " (FDI of the GT)", "1", True, "flicker", "FDI GT", show="none", valid=(0.0, 1.0)),
    MetricSpec("fsi_input", "1.0", "ISET-LFM eq. 2 via lfmbench.flicker.flicker_severity, LPD input", "1", False,
               "flicker", "FSI in", show="none", valid=(-math.inf, math.inf)),
    MetricSpec("psnr_srgb", "1.0", "PSNR (peak 1) of display sRGB (IEC 61966-2-1) after the ISP pipeline of "
               "ScoreOptions.isp (docs/guide/isp.md), tone curve from the GT", "dB", True, "display", "PSNR sRGB dB",
               digits=2, valid=(0.0, 1000.0), inf_ok=True),
    MetricSpec("ssim_srgb", "1.0", "Wang et al. IEEE TIP 2004 via kornia.metrics.ssim, per channel and frame of "
               "display sRGB after the ISP pipeline of ScoreOptions.isp", "1", True, "display", "SSIM sRGB",
               valid=(-1.0, 1.0)),
]:
    register_metric(_s, check_inputs=False)  # led_score leads the columns but derives from later entries
for _s in REGISTRY.values():
    if _inputs_error(_s):
        raise ValueError(f"metric {_s.name!r}: {_inputs_error(_s)}")


def columns(where: str = "table") -> list[MetricSpec]:
    """Registered metrics shown in a table: ``where="table"`` (Markdown: console and table metrics) or
    ``"console"`` (the terminal table), in registry order."""
    keep = ("console",) if where == "console" else ("console", "table")
    return [s for s in REGISTRY.values() if s.show in keep]


def metric_versions() -> dict[str, str]:
    """name -> version of every registered metric (stored with every evaluation result)."""
    return {k: v.version for k, v in REGISTRY.items()}
