"""The names every stage shares: light groups and kinds, object and vehicle kinds, spectrum models, photodiodes,
captures and the learned baselines.

One definition each: the scene generator and the renderer (``render_tools``), the corpus format
(:mod:`lfmbench.corpus`), the sensor (:mod:`lfmbench.sensor`) and the datasets import them from here. Adding a
kind means adding it here (and, for scene content, a template entry of ``render_tools``); nothing else lists
them. Names only: no units, no numbers.
"""
from __future__ import annotations

from types import MappingProxyType
from typing import Mapping

__all__ = ["GROUPS", "LIGHT_GROUPS", "LIGHT_KINDS", "VEHICLE_KINDS", "OBJECT_KINDS", "WEATHERS", "SPECTRUM_MODELS",
           "PHOTODIODES", "CAPTURES", "CLASSIC_BASELINES", "PLAN_BASELINES", "LEARNED_BASELINES",
           "PLAN_LEARNED_BASELINES"]

#: Light groups (upstream ISET-LFM names + traffic signals); each group is one radiance layer of a corpus.
GROUPS: tuple[str, ...] = ("headlights", "streetlights", "otherlights", "skymap", "signals")
#: Groups that hold emitters placed in the scene (skymap is the sky emitter).
LIGHT_GROUPS: tuple[str, ...] = ("headlights", "streetlights", "otherlights", "signals")
#: Light kinds the renderer writes, and the group each belongs to by default (other corpus writers may use
#: other kind names: ``meta.json`` treats ``kind`` as informative).
LIGHT_KINDS: Mapping[str, str] = MappingProxyType({
    "headlight": "headlights", "streetlight": "streetlights", "tail": "otherlights", "brake": "otherlights",
    "indicator": "otherlights", "billboard": "otherlights", "signal": "signals",
    # lamp clusters and the flickering sources of issue 23 (their timing: lfmbench.flicker.waveforms)
    "drl": "otherlights", "chmsl": "otherlights", "strobe": "otherlights", "message_sign": "otherlights",
    "destination_display": "otherlights", "countdown": "signals"})
#: Vehicle kinds of the scene generator (``vehicles.kind_weights``, ``vehicles.require_kinds`` of a scene config).
VEHICLE_KINDS: tuple[str, ...] = ("car", "truck", "motorcycle", "van", "bus", "bicycle")
#: Object kinds of a scene file: the static scene parts, the vehicles, the poles; people, trees and road
#: furniture (scene generator 2, protocol lfmbench-v2) and a user's own mesh asset.
OBJECT_KINDS: tuple[str, ...] = ("ground", "road", "marking", "sidewalk", "building", *VEHICLE_KINDS,
                                 "streetlight_pole", "signal_pole", "pedestrian", "cyclist", "tree", "bollard",
                                 "traffic_sign", "bench", "asset", "message_sign")
#: Road-surface weather of a scene (``scene.weather``): ``wet`` and ``rain`` put a water film (a rough dielectric
#: over the asphalt) and puddles on the road, so lamps reflect in it.
WEATHERS: tuple[str, ...] = ("dry", "wet", "rain")
#: Emission-spectrum models (``spectrum["model"]`` of a scene light and of ``meta.json``) and their required and
#: optional parameters (the models themselves: :mod:`render_tools.spectra`).
SPECTRUM_MODELS: Mapping[str, Mapping[str, tuple[str, ...]]] = MappingProxyType({
    "led": MappingProxyType({"required": ("peak_nm", "fwhm_nm"), "optional": ()}),
    "light_source": MappingProxyType({"required": ("name",), "optional": ()}),
    "illuminant": MappingProxyType({"required": ("name",), "optional": ()}),
    "daylight": MappingProxyType({"required": ("cct_k",), "optional": ()}),
})
#: Photodiodes of the split pixel: large (LPD, short exposure) and small (SPD, long exposure).
PHOTODIODES: tuple[str, ...] = ("lpd", "spd")
#: Captures of the split pixel, in the order of the ``saturated`` channels (docs/guide/contracts.md).
CAPTURES: tuple[str, ...] = ("lpd_hcg", "lpd_lcg", "spd")
#: Rule-based baselines, in leaderboard order: each a function of that name in :mod:`lfmbench.baselines.classic`
#: (:data:`lfmbench.baselines.REGISTRY` is built from this list). Here, without torch, so that the command line can
#: list them in its help.
CLASSIC_BASELINES: tuple[str, ...] = ("lpd_only", "spd_only", "upstream_saturated", "saturated_exposure_corrected",
                                      "flicker_aware", "flicker_aware_two_sided", "temporal")
#: Rule-based baselines of the other capture plans (LOFIC, staggered, chopped, single exposure): each a function of
#: that name in :mod:`lfmbench.baselines.plan_merge`; the architecture registry
#: (:data:`lfmbench.sensor.plan.ARCHITECTURES`) names the one that is each architecture's standard HDR merge.
PLAN_BASELINES: tuple[str, ...] = ("exposure_select", "exposure_select_bounded")
#: Learned baselines: name -> the module that defines the registered method ``name`` (backed by a checkpoint) and
#: ``TRAINING`` (how ``lfmbench train --method NAME`` trains it); :data:`lfmbench.baselines.LEARNED`. Here, without
#: torch, so that the command line can list them in its help.
LEARNED_BASELINES: Mapping[str, str] = MappingProxyType({
    "learned": "lfmbench.baselines.learned",
    "unet": "lfmbench.baselines.unet",
})
#: The learned baselines whose network takes any capture plan (trained per sensor: ``lfmbench train --method NAME
#: --sensor PRESET``); the others read the split pixel's captures only.
PLAN_LEARNED_BASELINES: tuple[str, ...] = ("unet",)
