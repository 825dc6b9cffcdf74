"""Format constants and channel / file naming of the lfmbench corpus (``docs/guide/corpus-format.md``).

Format name and versions (:func:`_check_version`), file and directory names, the header attribute names
(:data:`ATTR`), the radiance unit and plausibility ceiling, channel names (:func:`band_channel`,
:func:`bin_prefix`, :func:`static_channels`, :func:`bin_channels`), frame directories (:func:`frame_dir`) and how
a group is stored (:func:`group_storage`).

Units: wavelengths in nm, spectral radiance in W sr^-1 m^-2 nm^-1.
"""
from __future__ import annotations

import math
import re
from typing import Any, Mapping, Sequence

from lfmbench.limits import brief
from lfmbench.corpus.errors import CorpusFileError

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "STATIC_BINS_VERSION", "static_edges", "static_layers",
           "window_bin_weights", "READABLE_VERSIONS", "MANIFEST_NAME", "SPLITS_NAME", "SCENES_DIR",
           "STATIC_WINDOWS", "AUX_CHANNELS", "RADIANCE_UNIT", "RADIANCE_MAX", "EMPTY_PART", "STEADY_PREFIX", "ATTR",
           "band_channel", "bin_prefix", "static_channels", "bin_channels", "steady_channels", "light_part_name",
           "parse_light_part", "box_inside", "frame_dir", "group_storage"]

#: ``manifest.json`` "format" value and format version written by this module. Version 2 (HALF x 2^e layers,
#: codecs and mantissa rounding, ``docs/guide/corpus-format.md``) reads every version-1 file unchanged; version 3 (a
#: light's bins stored over the pixels that change from bin to bin, plus an optional ``steady<id>`` part for the
#: pixels that are the same in every bin, section 6.2) reads every version-2 file unchanged.
FORMAT_NAME = "lfmbench-corpus"
FORMAT_VERSION = 3
#: Format version of a scene whose static groups are stored in time bins (``meta.json``
#: ``timing.static_edges_s``, section 6.1 of ``docs/guide/corpus-format.md``): its ``meta.json`` ``storage`` and its
#: static EXR files say 4; every other scene is written as version 3, as before.
STATIC_BINS_VERSION = 4
#: Format versions this module reads.
READABLE_VERSIONS = (1, 2, 3, 4)
MANIFEST_NAME = "manifest.json"
SPLITS_NAME = "splits.json"
SCENES_DIR = "scenes"
#: Exposure windows stored for static (non-flickering) groups, in this channel-prefix order.
STATIC_WINDOWS = ("short", "long")
#: Channels of ``aux.exr``: z-depth and range (m) and instance / light ids (float32, -1 = none).
AUX_CHANNELS = ("depth.Z", "depth.R", "mask.instance", "mask.light")
RADIANCE_UNIT = "W sr^-1 m^-2 nm^-1"
#: Plausibility ceiling of spectral radiance (W sr^-1 m^-2 nm^-1), checked on write, on read and by
#: :func:`validate_corpus`. The sun's disc seen from the ground peaks near 2e7 W sr^-1 m^-2 nm^-1
#: (a 5800 K black body: B_lambda(500 nm) ~ 2.6e7); an LED die is far dimmer. 1e9 is fifty times the sun, so a
#: value above it is a unit or scale error (e.g. a corrupted ``lfmbench_scale`` attribute), never a scene.
RADIANCE_MAX = 1e9
#: Name and channel of the placeholder part of a flickering-group EXR in which no light is visible.
EMPTY_PART = "empty"
#: Channel prefix of a light's steady part (format version 3): radiance that is the same in every time bin.
STEADY_PREFIX = "steady"
#: Part names of a flickering-group EXR: ``light<id>`` (the K bins) and ``steady<id>`` (version 3, optional).
_LIGHT_PART = re.compile(r"(light|steady)(\d+)")
#: Header attribute names (all prefixed ``lfmbench_``).
ATTR = {
    "kind": "lfmbench_kind", "scene": "lfmbench_scene_id", "frame": "lfmbench_frame",
    "group": "lfmbench_group", "units": "lfmbench_units", "light": "lfmbench_light_id",
    "nparts": "lfmbench_nparts", "bins": "lfmbench_bins", "stored": "lfmbench_stored_as",
    "version": "lfmbench_format_version", "mantissa": "lfmbench_mantissa_bits", "scale": "lfmbench_scale",
}


def _fmt_nm(wl: float) -> str:
    """Wavelength (nm) as written in channel names: ``400`` -> ``"400"``, ``402.5`` -> ``"402.5"``."""
    wl = float(wl)
    if not math.isfinite(wl) or wl <= 0:
        raise ValueError(f"wavelength must be a positive number of nm, got {brief(wl)}")
    return f"{wl:.6g}"


def band_channel(prefix: str, wl_nm: float) -> str:
    """Channel name of one band: ``band_channel("short", 400) == "short.400nm"``.

    Args:
        prefix: ``"short"``, ``"long"`` or a bin prefix from :func:`bin_prefix`.
        wl_nm: band centre wavelength (nm).
    """
    return f"{prefix}.{_fmt_nm(wl_nm)}nm"


def bin_prefix(k: int, bins: int) -> str:
    """Prefix of time bin ``k`` of ``bins``: ``bin00`` .. ``bin{K-1}``, zero-padded to max(2, digits(K-1))."""
    width = max(2, len(str(max(bins - 1, 0))))
    return f"bin{k:0{width}d}"


_STATIC_BIN = re.compile(r"bin\d{2,}")


def static_channels(window: str, bands_nm: Sequence[float]) -> list[str]:
    """Channel names of one exposure window (``short`` / ``long``) or time bin (``bin00`` ...: format version 4) of a
    static group, band order."""
    if window not in STATIC_WINDOWS and not (isinstance(window, str) and _STATIC_BIN.fullmatch(window)):
        raise ValueError(f"window must be one of {STATIC_WINDOWS} or a bin prefix, got {brief(window)}")
    return [band_channel(window, wl) for wl in bands_nm]


def static_edges(meta: Mapping[str, Any]) -> list[float] | None:
    """The edges (B + 1,) s from the frame start of a scene's static time bins (``meta.json``
    ``timing.static_edges_s``, format version 4), None when its static groups are stored as the short and long
    windows."""
    e = (meta.get("timing") or {}).get("static_edges_s")
    return None if e is None else [float(x) for x in e]


def static_layers(meta: Mapping[str, Any]) -> tuple[str, ...]:
    """The layers of a static group's file: :data:`STATIC_WINDOWS`, or the bin prefixes ``bin00`` ... of its static
    time bins (:func:`static_edges`)."""
    e = static_edges(meta)
    return STATIC_WINDOWS if e is None else tuple(bin_prefix(k, len(e) - 1) for k in range(len(e) - 1))


def window_bin_weights(edges: Sequence[float], start_s: float, length_s: float, tol: float = 1e-9):
    """Weights (B,) of the time bins between ``edges`` (s) whose weighted sum is the time average over the window
    [start_s, start_s + length_s) (s): ``|bin_k| / length_s`` for the bins inside it, 0 elsewhere (the exact
    average: the bins tile it). None when an end of the window is not an edge (to ``tol`` of its length): the
    window is not a union of bins."""
    import numpy as np  # noqa: PLC0415

    e = np.asarray(edges, dtype=np.float64)
    t = tol * max(float(length_s), 1e-12)
    ia = np.flatnonzero(np.abs(e - start_s) <= t)
    ib = np.flatnonzero(np.abs(e - (start_s + length_s)) <= t)
    if not len(ia) or not len(ib) or ib[0] <= ia[0]:
        return None
    w = np.zeros(len(e) - 1)
    w[ia[0]:ib[0]] = np.diff(e)[ia[0]:ib[0]] / float(length_s)
    return w


def bin_channels(bins: int, bands_nm: Sequence[float]) -> list[list[str]]:
    """Channel names of a per-light part: ``[k][c]`` -> ``bin{k}.{wl_c}nm``."""
    return [[band_channel(bin_prefix(k, bins), wl) for wl in bands_nm] for k in range(bins)]


def steady_channels(bands_nm: Sequence[float]) -> list[str]:
    """Channel names of a light's steady part (format version 3): ``steady.{wl_c}nm`` in band order."""
    return [band_channel(STEADY_PREFIX, wl) for wl in bands_nm]


def light_part_name(light_id: int, steady: bool = False) -> str:
    """EXR part name of a light's bins (``light<id>``) or of its steady part (``steady<id>``); decimal id."""
    return f"{'steady' if steady else 'light'}{int(light_id)}"


def parse_light_part(name: str) -> tuple[int, bool] | None:
    """``(light id, steady)`` of a part name made by :func:`light_part_name`, else None."""
    m = _LIGHT_PART.fullmatch(name)
    return None if m is None else (int(m.group(2)), m.group(1) == "steady")


def box_inside(inner: Sequence[int], outer: Sequence[int]) -> bool:
    """Whether the half-open pixel box ``inner`` (y0, x0, y1, x1) lies inside ``outer`` (a light part's data window
    inside its meta.json bbox, section 6.2 of ``docs/guide/corpus-format.md``)."""
    return outer[0] <= inner[0] and outer[1] <= inner[1] and inner[2] <= outer[2] and inner[3] <= outer[3]


def frame_dir(frame: int) -> str:
    """Directory name of frame ``frame``: ``f000``, ``f001``, ..."""
    return f"f{int(frame):03d}"


def group_storage(meta: Mapping[str, Any], group: str) -> str:
    """How ``group`` is stored: ``"lights"`` (per-light sparse time bins) or ``"static"`` (short/long).

    A group is stored per light when its meta entry is ``"flicker": true`` and its ``bins`` (default: the
    scene's ``timing.bins``) is > 0. Imported ISET-LFM groups use ``"flicker": true, "bins": 0``: flickering,
    but stored as exposure windows only (one PWM weight per frame).
    """
    groups = meta.get("groups", {})
    if group not in groups:
        raise ValueError(f"group {brief(group)} is not in this scene's meta.json groups {sorted(groups)}")
    g = groups[group]
    if not g.get("flicker", False):
        return "static"
    bins = int(g.get("bins", meta.get("timing", {}).get("bins", 0)))
    return "lights" if bins > 0 else "static"


def _group_bins(meta: Mapping[str, Any], group: str) -> int:
    g = meta["groups"][group]
    return int(g.get("bins", meta.get("timing", {}).get("bins", 0)))


def _check_version(v: Any, where: str) -> int:
    """``v`` as a readable format version; ``CorpusFileError`` naming ``where`` (and the version) otherwise."""
    if isinstance(v, int) and not isinstance(v, bool) and v > max(READABLE_VERSIONS):
        raise CorpusFileError(f"{where}: corpus format version {v} is newer than this lfmbench reads "
                              f"(versions {', '.join(map(str, READABLE_VERSIONS))}); upgrade lfmbench")
    if v not in READABLE_VERSIONS or isinstance(v, bool):
        raise CorpusFileError(f"{where}: unsupported corpus format version {brief(v)} (this lfmbench reads versions "
                              f"{', '.join(map(str, READABLE_VERSIONS))})")
    return int(v)
