"""The names every stage shares: light groups and kinds, object and vehicle kinds, spectrum models, photodiodes
and captures (the baselines, metrics and ISP stages are registered where they are defined:
:mod:`lfmbench.registry`).

One definition each: the scene generator and the renderer (``render_tools``), the corpus format
(:mod:`lfmbench.corpus`), the sensor (:mod:`lfmbench.sensor`) and the datasets import them from here. Adding a
kind means adding it here (and, for scene content, a template entry of ``render_tools``); nothing else lists
them. Names only: no units, no numbers.
"""
from __future__ import annotations

from types import MappingProxyType
from typing import Mapping

__all__ = ["GROUPS", "LIGHT_GROUPS", "LIGHT_KINDS", "VEHICLE_KINDS", "OBJECT_KINDS", "WEATHERS", "SPECTRUM_MODELS",
           "PHOTODIODES", "CAPTURES", "SPLITS"]

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
#: Corpus splits a dataset reads (``all``: every complete scene); :data:`lfmbench.datasets.options.SPLITS`.
SPLITS: tuple[str, ...] = ("train", "val", "test", "all")

#: What the full-image and ghost columns of a result are scored against (``ScoreOptions.reference``, ``lfmbench
#: evaluate --reference``): ``own`` (the sensor's own reference exposure, ``gt``) or ``common`` (``gt_common``: one
#: fixed window through one reference sensor, the same for every sensor; needed to rank sensors together).
REFERENCES = ("own", "common")
