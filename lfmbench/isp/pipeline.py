"""ISP pipelines as plain data: a YAML list of stages (``lfmbench/configs/isp/<name>.yaml``), bound to a sensor
preset into an ``nn.Module``.

Defines
-------
- :data:`STAGES`: the registry of stage kinds (``black_level``, ``compand``, ``white_balance``, ``demosaic``,
  ``ccm``, ``tonemap``, ``srgb_encode``), each a small class that reads its parameters, validates them at once
  (errors name the file and the field, e.g. ``steps[3].method``) and registers by name (Mitsuba-plugin style).
- :class:`ISPPipeline`: a validated pipeline (name, description, stages, source file, content SHA-256);
  :func:`load_pipeline` (a shipped name or a YAML path), :func:`pipeline_from_dict`, :func:`available_pipelines`.
- :class:`ISP`: the pipeline bound to a preset (``ISPPipeline.bind(preset)``); ``forward(raw, reference=None)``
  and :meth:`ISP.pair` (an estimate and its ground truth through the same stages, every image statistic taken from
  the ground truth).

The stages read only the preset's public fields: the Bayer layout (``cfa``), the spectral QE curves
(:func:`lfmbench.sensor.response.spectral_qe`), the black level and the ADC bit depth; so a pipeline works for
every sensor architecture. Shapes: input ``(*, 1, H, W)`` (a Bayer mosaic in a linear unit: DN, or input-referred
e- as the samples' ``gt`` and a fusion estimate), output ``(*, 3, H, W)`` (encoded sRGB in [0, 1] when the last
stage is ``srgb_encode``). Image statistics (grey-world gains, the tone curve) are taken per item of the first
dim over all the other dims: a ``(B, F, 1, H, W)`` sample batch gets one tone curve per sample, fixed over its
frames. See ``docs/guide/isp.md``.
"""
from __future__ import annotations

import copy
import hashlib
import json
import math
from pathlib import Path
from typing import Any, ClassVar, Mapping

import torch
from torch import nn

from lfmbench.check import check_choice, check_keys, check_number, check_tensor, fail
from lfmbench.isp import color, raw as _raw
from lfmbench.isp.compand import Compander, check_knees
from lfmbench.isp.demosaic import DEMOSAIC, clamp_to_neighbours
from lfmbench.isp.tonemap import TONEMAP
from lfmbench.limits import brief
from lfmbench.registry import Registry

__all__ = ["STAGES", "Stage", "ISPPipeline", "ISP", "PIPELINE_DIR", "PIPELINE_FORMAT", "available_pipelines",
           "load_pipeline", "pipeline_from_dict"]

#: Shipped pipelines (YAML).
PIPELINE_DIR: Path = Path(__file__).resolve().parent.parent / "configs" / "isp"
#: ``format`` of a pipeline file.
PIPELINE_FORMAT = "lfmbench-isp"

#: name -> stage class (:class:`lfmbench.registry.Registry`); filled by :func:`_register`.
STAGES: Registry[type["Stage"]] = Registry("ISP stage")


def _register(cls: type["Stage"]) -> type["Stage"]:
    """Decorator: register a :class:`Stage` subclass under its ``op``."""
    return STAGES.register(cls.op, cls)


class Stage:
    """One stage of a pipeline. Subclasses set ``op`` (the registry name), ``domain`` (``mosaic``: works on the
    Bayer mosaic, ``rgb``: on full colour, ``demosaic``: turns the one into the other) and ``keys`` (parameter ->
    default), validate in ``__init__`` and implement ``apply`` (and ``stats`` when they read the reference)."""

    op: ClassVar[str] = ""
    domain: ClassVar[str] = "rgb"
    keys: ClassVar[Mapping[str, Any]] = {}

    def __init__(self, params: Mapping[str, Any], field: str, source: str | None) -> None:
        check_keys(params, field, source, optional=set(self.keys) | {"op"})
        self.params = {k: params.get(k, v) for k, v in self.keys.items()}
        self.field, self.source = field, source

    def bind(self, preset) -> None:
        """Read what the stage needs from the preset (public fields only)."""

    def _illuminant(self, fn, preset):
        """``fn(preset, illuminant)`` with an unknown illuminant named as this stage's field."""
        try:
            return fn(preset, self.params["illuminant"])
        except KeyError:
            fail(f"{self.field}.illuminant", f"is not a colour-science illuminant: {brief(self.params['illuminant'])}",
                 self.source)

    def stats(self, ref: torch.Tensor) -> dict[str, torch.Tensor] | None:
        """Statistics of the reference (the ground truth at this stage), applied to every image; None: none."""
        return None

    def apply(self, x: torch.Tensor, stats: dict[str, torch.Tensor] | None) -> torch.Tensor:
        """x: (N, M, C, H, W) -> (N, M, C', H, W)."""
        raise NotImplementedError


def _flat(x: torch.Tensor) -> torch.Tensor:
    return x.reshape((-1,) + x.shape[-3:])


@_register
class BlackLevelStage(Stage):
    """``black_level``: subtract the pedestal. ``level``: ``preset`` (the preset's ``black_level_dn``) or a number
    in the input's unit (0 for input-referred e-, where the sensor model has removed it already)."""

    op, domain, keys = "black_level", "mosaic", {"level": "preset"}

    def __init__(self, params, field, source):
        super().__init__(params, field, source)
        lv = self.params["level"]
        if lv != "preset":
            check_number(lv, f"{field}.level", source, lo=0)

    def bind(self, preset) -> None:
        self.level = float(preset.black_level_dn) if self.params["level"] == "preset" else float(self.params["level"])

    def apply(self, x, stats):
        return _raw.subtract_black_level(x, self.level)


@_register
class CompandStage(Stage):
    """``compand``: send the signal through a piecewise-linear companded link and decompand it
    (:class:`lfmbench.isp.compand.Compander`). ``knees``: [[input_code, output_code], ...]; ``input_bits``,
    ``output_bits``; ``dn_per_unit``: input codes per unit of the signal (DN per e- for input-referred e-)."""

    op, domain = "compand", "mosaic"
    keys = {"knees": None, "input_bits": 24, "output_bits": 12, "dn_per_unit": 1.0, "straight_through": True}

    def __init__(self, params, field, source):
        super().__init__(params, field, source)
        if self.params["knees"] is None:
            fail(f"{field}.knees", "is missing", source)
        ib = self.params["input_bits"]
        ob = self.params["output_bits"]
        for k in ("input_bits", "output_bits"):
            check_number(self.params[k], f"{field}.{k}", source, lo=1, hi=32, integer=True)
        if not isinstance(self.params["straight_through"], bool):
            fail(f"{field}.straight_through", f"must be true or false, got {brief(self.params['straight_through'])}",
                 source)
        knees = check_knees(self.params["knees"], int(ib), int(ob), f"{field}.knees", source)
        dpu = check_number(self.params["dn_per_unit"], f"{field}.dn_per_unit", source, lo=0, lo_open=True)
        self.module = Compander(knees, int(ib), int(ob), dpu, self.params["straight_through"])

    def apply(self, x, stats):
        return self.module(x)


@_register
class WhiteBalanceStage(Stage):
    """``white_balance``: per-colour gains on the mosaic. ``method``: ``preset`` (a perfect white under
    ``illuminant`` becomes neutral, from the preset's QE), ``gray_world`` (from the reference's channel means),
    ``none``."""

    op, domain, keys = "white_balance", "mosaic", {"method": "preset", "illuminant": "D65"}

    def __init__(self, params, field, source):
        super().__init__(params, field, source)
        check_choice(self.params["method"], f"{field}.method", ("preset", "gray_world", "none"), source)
        if not isinstance(self.params["illuminant"], str):
            fail(f"{field}.illuminant", f"must be an illuminant name, got {brief(self.params['illuminant'])}", source)

    def bind(self, preset) -> None:
        self.pattern = preset.cfa
        if self.params["method"] == "preset":
            self.gains = torch.as_tensor(self._illuminant(color.white_balance_gains, preset))

    def stats(self, ref):
        if self.params["method"] != "gray_world":
            return None
        return {"gains": _raw.gray_world_gains(ref, self.pattern, dims=ref.ndim - 1)}

    def apply(self, x, stats):
        if self.params["method"] == "none":
            return x
        if stats is None:
            return _raw.white_balance_mosaic(x, self.gains, self.pattern)
        g = stats["gains"].repeat_interleave(x.shape[1], dim=0)  # (N, 3) -> (N*M, 3)
        return _raw.white_balance_mosaic(_flat(x), g, self.pattern).reshape(x.shape)


@_register
class DemosaicStage(Stage):
    """``demosaic``: ``method`` a name of :data:`lfmbench.isp.demosaic.DEMOSAIC`; ``clamp`` (default true) limits
    every interpolated value to the range of its colour's samples in the 3x3 neighbourhood
    (:func:`lfmbench.isp.demosaic.clamp_to_neighbours`: no overshoot around lamps); ``clip_negative`` (default
    true) clips what is left below 0."""

    op, domain, keys = "demosaic", "demosaic", {"method": "malvar2004", "clamp": True, "clip_negative": True}

    def __init__(self, params, field, source):
        super().__init__(params, field, source)
        check_choice(self.params["method"], f"{field}.method", sorted(DEMOSAIC), source)
        for k in ("clamp", "clip_negative"):
            if not isinstance(self.params[k], bool):
                fail(f"{field}.{k}", f"must be true or false, got {brief(self.params[k])}", source)

    def bind(self, preset) -> None:
        self.pattern = preset.cfa

    def apply(self, x, stats):
        flat = _flat(x)
        rgb = DEMOSAIC[self.params["method"]](flat, self.pattern)
        if self.params["clamp"]:
            rgb = clamp_to_neighbours(rgb, flat, self.pattern)
        rgb = rgb.clamp_min(0.0) if self.params["clip_negative"] else rgb
        return rgb.reshape(x.shape[:2] + rgb.shape[-3:])


@_register
class CCMStage(Stage):
    """``ccm``: the colour-correction matrix. ``matrix``: ``fit`` (fitted from the preset's QE on the ColorChecker
    under ``illuminant``: :func:`lfmbench.isp.color.fit_ccm`) or a 3x3 list; ``illuminant`` of the fit."""

    op, domain, keys = "ccm", "rgb", {"matrix": "fit", "illuminant": "D65"}

    def __init__(self, params, field, source):
        super().__init__(params, field, source)
        m = self.params["matrix"]
        if m != "fit":
            if not isinstance(m, list) or len(m) != 3 or any(not isinstance(r, list) or len(r) != 3 for r in m):
                fail(f"{field}.matrix", f"must be 'fit' or a 3x3 list of numbers, got {brief(m)}", source)
            for i, r in enumerate(m):
                for j, v in enumerate(r):
                    check_number(v, f"{field}.matrix[{i}][{j}]", source)

    def bind(self, preset) -> None:
        if self.params["matrix"] == "fit":
            self.matrix = torch.as_tensor(self._illuminant(color.fit_ccm, preset).matrix)
        else:
            self.matrix = torch.tensor(self.params["matrix"], dtype=torch.float64)

    def apply(self, x, stats):
        return color.apply_ccm(x, self.matrix)


@_register
class ToneMapStage(Stage):
    """``tonemap``: ``method`` a name of :data:`lfmbench.isp.tonemap.TONEMAP`, plus that operator's parameters
    (e.g. ``key``, ``white`` for ``reinhard2002``; ``contrast``, ``radius``, ``eps`` for ``durand2002``)."""

    op, domain = "tonemap", "rgb"
    keys = {"method": "reinhard2002"}

    def __init__(self, params, field, source):
        method = params.get("method", "reinhard2002") if isinstance(params, Mapping) else None
        check_choice(method, f"{field}.method", sorted(TONEMAP), source)
        tm = TONEMAP[method]
        self.keys = {"method": method, **tm.stats_params, **tm.apply_params}
        super().__init__(params, field, source)
        self.operator = tm
        for k, v in self.params.items():
            if k == "method" or v is None or (k == "white" and isinstance(v, str)):
                continue
            check_number(v, f"{field}.{k}", source, lo=0, lo_open=k not in ("percentile",))
        w = self.params.get("white")
        if isinstance(w, str) and not (w == "max" or (w.startswith("p") and _is_percentile(w[1:]))):
            fail(f"{field}.white", f"must be 'max', 'p<percentile>' (e.g. p99.9) or a number, got {brief(w)}", source)

    def stats(self, ref):
        return self.operator.stats(ref, **{k: self.params[k] for k in self.operator.stats_params})

    def apply(self, x, stats):
        return self.operator.apply(x, **stats, **{k: self.params[k] for k in self.operator.apply_params})


def _is_percentile(text: str) -> bool:
    try:
        return 0 < float(text) <= 100
    except ValueError:
        return False


@_register
class SRGBEncodeStage(Stage):
    """``srgb_encode``: the IEC 61966-2-1 transfer function (values clipped to [0, 1])."""

    op, domain, keys = "srgb_encode", "rgb", {}

    def apply(self, x, stats):
        return color.srgb_encode(x)


class ISPPipeline:
    """A validated pipeline: ``name``, ``description``, ``stages`` (unbound :class:`Stage` objects), ``source``
    (the file) and ``sha256`` (of the content as canonical JSON: comments and layout do not change it)."""

    def __init__(self, data: Mapping[str, Any], source: str = "<dict>") -> None:
        check_keys(data, "", source, required=("format", "name", "steps"), optional=("version", "description"))
        if data["format"] != PIPELINE_FORMAT:
            fail("format", f"must be {PIPELINE_FORMAT!r}, got {brief(data['format'])}", source)
        if not isinstance(data["name"], str) or not data["name"]:
            fail("name", f"must be a non-empty string, got {brief(data['name'])}", source)
        steps = data["steps"]
        if not isinstance(steps, list) or not steps:
            fail("steps", f"must be a non-empty list of stages, got {brief(steps)}", source)
        self.name, self.description, self.source = data["name"], str(data.get("description", "")), source
        self.stages: list[Stage] = []
        domain = "mosaic"
        for i, st in enumerate(steps):
            field = f"steps[{i}]"
            if not isinstance(st, Mapping):
                fail(field, f"must be a mapping with an 'op' key, got {brief(st)}", source)
            op = check_choice(st.get("op"), f"{field}.op", sorted(STAGES), source)
            cls = STAGES[op]
            if cls.domain == "demosaic":
                if domain != "mosaic":
                    fail(field, "demosaics a second time (there is one demosaic stage)", source)
                domain = "rgb"
            elif cls.domain != domain:
                fail(field, f"works on the {cls.domain} but the image is a {domain} here "
                            f"({'put it before' if cls.domain == 'mosaic' else 'add'} a demosaic stage)", source)
            self.stages.append(cls(st, field, source))
        if domain != "rgb":
            fail("steps", "has no demosaic stage (the output must be colour)", source)
        self.sha256 = hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()

    def bind(self, preset) -> "ISP":
        """The pipeline bound to a sensor preset (or name): an :class:`ISP` module."""
        return ISP(self, preset)

    def identity(self) -> dict[str, str]:
        """``{"name", "sha256"}``: what a result records of the pipeline."""
        return {"name": self.name, "sha256": self.sha256}


class ISP(nn.Module):
    """A pipeline bound to a preset. ``forward(raw, reference=None)``: ``(*, 1, H, W)`` -> ``(*, 3, H, W)``;
    image statistics from ``reference`` (same shape; default: ``raw`` itself). :meth:`pair` processes an estimate
    and its reference together.

    Args:
        pipeline: :class:`ISPPipeline`, or a name / path for :func:`load_pipeline`.
        preset: :class:`lfmbench.sensor.SensorPreset` or its name.
    """

    def __init__(self, pipeline: "ISPPipeline | str | Path", preset) -> None:
        super().__init__()
        from lfmbench.sensor.preset import resolve  # noqa: PLC0415

        self.pipeline = pipeline if isinstance(pipeline, ISPPipeline) else load_pipeline(pipeline)
        self.preset = resolve(preset)
        self.stages = [copy.copy(st) for st in self.pipeline.stages]  # bound copies: one pipeline, many presets
        for st in self.stages:
            st.bind(self.preset)

    @staticmethod
    def _shape(x: torch.Tensor, name: str) -> torch.Tensor:
        check_tensor(x, name, "* 1 H W", what="a Bayer mosaic", floating=True)
        n = x.shape[0] if x.ndim > 3 else 1
        return x.reshape((n, max(1, math.prod(x.shape[1:-3]) if x.ndim > 3 else 1)) + x.shape[-3:])

    def pair(self, pred: torch.Tensor, gt: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """An estimate and its ground truth through the same stages, every statistic taken from ``gt``.

        Args:
            pred, gt: (*, 1, H, W) mosaics of one shape, in one linear unit.

        Returns:
            (pred_out, gt_out): (*, 3, H, W) each.
        """
        if pred.shape != gt.shape:
            raise ValueError(f"pred and gt must have one shape, got {tuple(pred.shape)} and {tuple(gt.shape)}")
        lead = pred.shape[:-3]
        p, g = self._shape(pred, "pred"), self._shape(gt, "gt")
        for st in self.stages:
            s = st.stats(g)
            p, g = st.apply(p, s), st.apply(g, s)
        return p.reshape(lead + p.shape[-3:]), g.reshape(lead + g.shape[-3:])

    def forward(self, raw: torch.Tensor, reference: torch.Tensor | None = None) -> torch.Tensor:
        """(*, 1, H, W) mosaic -> (*, 3, H, W); statistics from ``reference`` (default ``raw``)."""
        if reference is None:
            lead = raw.shape[:-3]
            x = self._shape(raw, "raw")
            for st in self.stages:
                x = st.apply(x, st.stats(x))
            return x.reshape(lead + x.shape[-3:])
        return self.pair(raw, reference)[0]


def available_pipelines() -> list[str]:
    """Names of the shipped pipelines (``lfmbench/configs/isp/<name>.yaml``)."""
    return sorted(p.stem for p in PIPELINE_DIR.glob("*.yaml"))


def pipeline_from_dict(data: Mapping[str, Any], source: str = "<dict>") -> ISPPipeline:
    """Validate a mapping (the YAML structure) into an :class:`ISPPipeline`; errors name ``source`` and the
    field."""
    return ISPPipeline(data, source)


def load_pipeline(pipeline: "str | Path | ISPPipeline | Mapping[str, Any]" = "default") -> ISPPipeline:
    """A pipeline by shipped name (``default``, ``local``, ...), YAML path, or mapping.

    Raises:
        ValueError: unknown name, unreadable file or an invalid field (the message names file and field).
    """
    if isinstance(pipeline, ISPPipeline):
        return pipeline
    if isinstance(pipeline, Mapping):
        return pipeline_from_dict(pipeline)
    if not isinstance(pipeline, (str, Path)):
        raise ValueError(f"isp pipeline must be a name, a path or a mapping, got {type(pipeline).__name__}")
    path = Path(pipeline)
    if path.suffix.lower() not in (".yaml", ".yml") and not path.exists():
        cand = PIPELINE_DIR / f"{pipeline}.yaml"
        if not cand.is_file():
            raise ValueError(f"isp pipeline: unknown pipeline {brief(str(pipeline))}; shipped pipelines are "
                             f"{available_pipelines()} or give a path to a YAML file")
        path = cand
    if not path.is_file():
        raise ValueError(f"isp pipeline: file {path} does not exist")
    return _load_file(str(path.resolve()), path.stat().st_mtime_ns)


def _load_file(path: str, mtime_ns: int) -> ISPPipeline:
    from lfmbench.fileio import load_yaml  # noqa: PLC0415

    try:
        data = load_yaml(path, source=f"isp pipeline {path}")
    except OSError as exc:
        raise ValueError(f"isp pipeline: cannot read {path}: {exc.strerror or exc}") from None
    return pipeline_from_dict(data if data is not None else {}, path)
