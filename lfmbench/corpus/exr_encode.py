"""EXR encoding of corpus files through the OpenEXR 3.x Python API (``OpenEXR.File`` / ``OpenEXR.Part``), bytes in
memory, no I/O: :func:`encode_static_exr`, :func:`encode_lights_exr`, :func:`encode_aux_exr`, and the
steady-plus-bins form of a light crop (:func:`split_steady`, :class:`SteadyBins`). Decoding is
:mod:`lfmbench.corpus.exr`.

Units: spectral radiance in W sr^-1 m^-2 nm^-1, depth in m, bounding boxes in pixels as half-open
``(y0, x0, y1, x1)``.

References: OpenEXR file layout and multi-part files, https://openexr.com/en/latest/TechnicalIntroduction.html
(data window / display window, part names).
"""
from __future__ import annotations

import io
import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from lfmbench.corpus.errors import CorpusValueError
from lfmbench.corpus.exr import _check_aux, _exr
from lfmbench.corpus.naming import (ATTR, AUX_CHANNELS, EMPTY_PART, FORMAT_VERSION, RADIANCE_MAX, RADIANCE_UNIT,
                                    STATIC_BINS_VERSION, bin_prefix,
                                    STATIC_WINDOWS, bin_channels, light_part_name, static_channels,
                                    steady_channels)
from lfmbench.corpus.storage import (COMPRESSIONS, DEFAULT_STORAGE, EXTRA_COMPRESSIONS, LayerStore,
                                     Storage, StorageStats, resolve_storage, scale_attr, store_layer)

__all__ = ["encode_static_exr", "encode_lights_exr", "encode_aux_exr", "split_steady", "SteadyBins"]


def _check_radiance(arr: np.ndarray, what: str) -> np.ndarray:
    if isinstance(arr, SteadyBins):  # every value it stands for is in one of its two arrays
        _check_radiance(arr.steady, what)
        _check_radiance(arr.bins, what)
        return arr
    arr = np.asarray(arr)
    if not np.issubdtype(arr.dtype, np.floating):
        raise ValueError(f"{what}: radiance must be a floating-point array, got dtype {arr.dtype}")
    if not arr.size:
        return arr
    lo, hi = float(arr.min()), float(arr.max())  # NaN propagates through both; +-inf shows in one of them
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise CorpusValueError(f"{what}: radiance contains NaN or inf")
    if lo < 0:
        raise CorpusValueError(f"{what}: radiance contains negative values (min {lo:.3g})")
    if hi > RADIANCE_MAX:
        raise CorpusValueError(f"{what}: radiance {hi:.3g} {RADIANCE_UNIT} exceeds the plausibility "
                               f"ceiling RADIANCE_MAX = {RADIANCE_MAX:.0e} (50x the sun's disc): a unit or scale error")
    return arr


def _note_layer(ls: LayerStore, what: str, notes: list[str], stats: StorageStats | None) -> None:
    if stats is not None:
        stats.add(ls, what)
    elif ls.fallback:  # no aggregator: one note per fallback (rare: see HALF_UNDERFLOW_ERROR_FRACTION)
        notes.append(f"{what}: {ls.fallback}: stored as FLOAT")


def _base_header(width: int, height: int, data_window: tuple[int, int, int, int] | None = None,
                 compression: str = "zip") -> dict:
    """EXR header: ``compression`` (a key of :data:`COMPRESSIONS` / :data:`EXTRA_COMPRESSIONS`), scanlines,
    display window = full image, data window (y0, x0, y1, x1) half-open, ``lfmbench_format_version``."""
    exr = _exr()
    if data_window is None:
        data_window = (0, 0, height, width)
    y0, x0, y1, x1 = data_window
    return {
        "compression": getattr(exr, {**COMPRESSIONS, **EXTRA_COMPRESSIONS}[compression]),
        "type": exr.scanlineimage,
        "displayWindow": ((0, 0), (width - 1, height - 1)),
        "dataWindow": ((x0, y0), (x1 - 1, y1 - 1)),
        ATTR["version"]: FORMAT_VERSION,
    }


def _encode(parts: list, what: str) -> bytes:
    exr = _exr()
    buf = io.BytesIO()
    try:
        exr.File(parts).write(buf)
    except Exception as exc:  # OpenEXR raises RuntimeError / ValueError from C++
        raise ValueError(f"{what}: OpenEXR could not encode the image: {exc}") from exc
    return buf.getvalue()


def encode_static_exr(windows: Mapping[str, np.ndarray], bands_nm: Sequence[float], *,
                      dtype: str | Storage = DEFAULT_STORAGE, attrs: Mapping[str, Any] | None = None,
                      what: str = "static group", notes: list[str] | None = None,
                      stats: StorageStats | None = None) -> bytes:
    """Encode a static group (one part, channels ``short.<wl>nm`` / ``long.<wl>nm``) as EXR bytes.

    Args:
        windows: ``{"short": (C, H, W), "long": (C, H, W)}`` time-averaged spectral radiance over each exposure
            window, W sr^-1 m^-2 nm^-1, finite and >= 0; or with ``"bins"``: (B, C, H, W) the time averages over
            the scene's static time bins (format version 4: channels ``bin<k>.<wl>nm``, one layer per bin, the
            file's ``lfmbench_format_version`` 4; ``short`` / ``long`` are then not stored: readers sum the bins).
        bands_nm: the C band centres (nm).
        dtype: storage, a name of :data:`STORAGES` (``"compact"``: HALF x 2^e with 5 mantissa bits, PIZ;
            ``"float16"``; ``"float32"``: lossless FLOAT as in format version 1) or a :class:`Storage`. Each
            window is one layer with its own scale, attribute ``lfmbench_scale_<window>``.
        attrs: extra header attributes (str / int / float values).
        what: the file's name for error messages.
        notes: list that receives one message per layer stored FLOAT instead of HALF.
        stats: optional accumulator of the layers' measured errors.
    """
    st = resolve_storage(dtype)
    notes = [] if notes is None else notes
    if "bins" in windows:  # static time bins (format version 4): the bins are stored, short and long are their sums
        b = np.asarray(windows["bins"])
        if b.ndim != 4 or b.shape[0] < 1:
            raise ValueError(f"{what}: static bins must be (B, C, H, W), got shape {b.shape}")
        windows = {bin_prefix(k, b.shape[0]): b[k] for k in range(b.shape[0])}
        names = tuple(windows)
    else:
        if set(windows) != set(STATIC_WINDOWS):
            raise ValueError(f"{what}: static windows must be exactly {STATIC_WINDOWS}, got {sorted(windows)}")
        names = STATIC_WINDOWS
    shape = None
    for w in names:
        a = _check_radiance(windows[w], f"{what} [{w}]")
        if a.ndim != 3 or a.shape[0] != len(bands_nm):
            raise ValueError(f"{what} [{w}]: expected shape (C={len(bands_nm)}, H, W), got {a.shape}")
        if shape is not None and a.shape != shape:
            raise ValueError(f"{what}: the static layers' shapes differ ({shape} and {a.shape})")
        shape = a.shape
    _, height, width = shape
    channels = {}
    stored = set()
    header = _base_header(width, height, compression=st.compression)
    if names != STATIC_WINDOWS:
        header[ATTR["version"]] = STATIC_BINS_VERSION
    header.update(attrs or {})
    for w in names:
        ls = store_layer(windows[w], st, f"{what} [{w}]")
        _note_layer(ls, f"{what} [{w}]", notes, stats)
        stored.add(ls.pixel_type)
        header[scale_attr(w)] = ls.scale
        for c, name in enumerate(static_channels(w, bands_nm)):
            channels[name] = ls.data[c]
    header[ATTR["kind"]] = "static"
    header[ATTR["units"]] = RADIANCE_UNIT
    header[ATTR["stored"]] = "float32" if "float32" in stored else "float16"
    header[ATTR["mantissa"]] = st.bits
    exr = _exr()
    return _encode([exr.Part(header, channels, "static")], what)


def _clip_box(box: Sequence[int], height: int, width: int, what: str) -> tuple[int, int, int, int]:
    if len(box) != 4:
        raise ValueError(f"{what}: bbox must be (y0, x0, y1, x1), got {box!r}")
    y0, x0, y1, x1 = (int(v) for v in box)
    if not (0 <= y0 < y1 <= height and 0 <= x0 < x1 <= width):
        raise ValueError(f"{what}: bbox {box} is empty or outside the {height}x{width} image")
    return y0, x0, y1, x1


def _bounding_box(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """Half-open (y0, x0, y1, x1) of the True pixels of a (h, w) mask, None when there are none."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return None
    return int(rows[0]), int(cols[0]), int(rows[-1]) + 1, int(cols[-1]) + 1


@dataclass(frozen=True)
class SteadyBins:
    """A light's K bins over its box given as one steady image plus the bins of a sub-box: bin k is ``steady``
    outside ``box`` and ``bins[k]`` inside it (what :func:`split_steady` finds, known beforehand).

    Why: a wet road's reflection of a lamp is traced once (``RenderOptions.reflection_bins`` 1) in a box many
    times the lamp's own; written out as K equal copies, a 640x360 wet night's grown boxes take about a GB per
    frame, whose first writes cost about 1.3 CPU s per frame (page faults) before :func:`split_steady` finds the
    copies again. The renderer hands this form to the corpus writer instead (``render_frames(steady_bins=True)``),
    which encodes the same bytes from it. ``np.asarray(x)`` gives the (K, C, h, w) array.

    Attributes:
        steady: (C, h, w) float32 radiance (W sr^-1 m^-2 nm^-1) of every bin outside ``box`` (values inside
            ``box`` are not used).
        box: (y0, x0, y1, x1) half-open, relative to the light's box; (0, 0, 0, 0) when no pixel changes.
        bins: (K, C, y1 - y0, x1 - x0) float32 radiance of each bin inside ``box``.
    """

    steady: np.ndarray
    box: tuple
    bins: np.ndarray

    def __post_init__(self):
        y0, x0, y1, x1 = self.box
        c, h, w = self.steady.shape
        if self.bins.ndim != 4 or self.bins.shape[1:] != (c, y1 - y0, x1 - x0) or not (
                0 <= y0 <= y1 <= h and 0 <= x0 <= x1 <= w):
            raise ValueError(f"SteadyBins: bins {self.bins.shape} and box {self.box} do not fit steady "
                             f"{self.steady.shape}")

    @property
    def shape(self) -> tuple[int, int, int, int]:
        return (self.bins.shape[0], *self.steady.shape)

    @property
    def dtype(self) -> np.dtype:
        return np.result_type(self.steady, self.bins)

    def window(self, y0: int, x0: int, y1: int, x1: int) -> np.ndarray:
        """The (K, C, y1 - y0, x1 - x0) bins of a window of the light's box (relative, half-open)."""
        out = np.empty((self.shape[0], self.shape[1], y1 - y0, x1 - x0), self.dtype)
        out[:] = self.steady[None, :, y0:y1, x0:x1]
        by0, bx0, by1, bx1 = self.box
        a, b, c, d = max(y0, by0), max(x0, bx0), min(y1, by1), min(x1, bx1)
        if a < c and b < d:
            out[:, :, a - y0:c - y0, b - x0:d - x0] = self.bins[:, :, a - by0:c - by0, b - bx0:d - bx0]
        return out

    def __array__(self, dtype=None, copy=None):
        out = self.window(0, 0, *self.steady.shape[1:])
        return out if dtype is None else out.astype(dtype, copy=False)

    def split(self) -> tuple[tuple[int, int, int, int], tuple[int, int, int, int] | None, np.ndarray]:
        """:func:`split_steady` of the (K, C, h, w) array, the same boxes and values, without building it: the
        bins can differ inside ``box`` only."""
        y0, x0, y1, x1 = self.box
        varies = np.zeros(self.steady.shape[1:], bool)
        for k in range(1, self.bins.shape[0]):
            varies[y0:y1, x0:x1] |= (self.bins[k] != self.bins[0]).any(axis=0)
        bins_box = _bounding_box(varies) or (0, 0, 1, 1)
        steady = self.steady.copy()
        steady[:, y0:y1, x0:x1] = self.bins[0]
        a, b, c, d = bins_box
        steady[:, a:c, b:d] = 0.0
        return bins_box, _bounding_box(steady.any(axis=0)), steady


def split_steady(arr: np.ndarray) -> tuple[tuple[int, int, int, int], tuple[int, int, int, int] | None, np.ndarray]:
    """Where a light's bins change and where they do not (format version 3, ``docs/guide/corpus-format.md`` 6.2).

    Args:
        arr: (K, C, h, w) a light's bins over its box, any units (exact float comparisons, no tolerance).

    Returns:
        ``(bins_box, steady_box, steady)``, boxes half-open (y0, x0, y1, x1) relative to the light's box:
        ``bins_box`` bounds the pixels whose value differs between two bins in some band (the 1x1 box at the
        origin when none does); ``steady`` (C, h, w) is bin 0 outside ``bins_box`` and 0 inside it, and
        ``steady_box`` bounds its non-zero pixels (None when it is all zero). So for every bin k,
        ``arr[k] == steady + (arr[k] inside bins_box, 0 outside)`` exactly. Why: a wet road's reflection of a
        lamp is traced once and holds the same value in all K bins (``RenderOptions.reflection_bins`` 1), in a box
        many times the lamp's own; stored once instead of K times, the group's file shrinks by up to K x.
    """
    if isinstance(arr, SteadyBins):
        return arr.split()
    K, _, h, w = arr.shape
    varies = np.zeros((h, w), bool)
    for k in range(1, K):
        varies |= (arr[k] != arr[0]).any(axis=0)
    bins_box = _bounding_box(varies) or (0, 0, 1, 1)
    steady = arr[0].copy()
    y0, x0, y1, x1 = bins_box
    steady[:, y0:y1, x0:x1] = 0.0
    return bins_box, _bounding_box(steady.any(axis=0)), steady


def encode_lights_exr(lights: Sequence[tuple[int, Sequence[int], np.ndarray]], bands_nm: Sequence[float],
                      bins: int, height: int, width: int, *, dtype: str | Storage = DEFAULT_STORAGE,
                      attrs: Mapping[str, Any] | None = None, what: str = "flickering group",
                      notes: list[str] | None = None, stats: StorageStats | None = None,
                      steady: bool = True) -> bytes:
    """Encode a flickering group as a multi-part EXR: per light a part ``light<id>`` (its K bins) and, where some
    of its pixels hold the same value in every bin, a part ``steady<id>`` (those pixels once); sparse data windows.

    Args:
        lights: ``[(light_id, (y0, x0, y1, x1), bins_array)]`` with ``bins_array`` of shape (K, C, h, w),
            h = y1 - y0, w = x1 - x0, spectral radiance W sr^-1 m^-2 nm^-1 time-averaged over each bin with the
            light at PWM level 1. Boxes are half-open pixel ranges inside the H x W image (meta.json ``bbox``).
        bands_nm: the C band centres (nm).
        bins: K, the number of time bins.
        height, width: full image size H, W (the display window).
        dtype: storage as in :func:`encode_static_exr`; each part (K x C bins, or the C steady bands) is one layer
            with its own scale, attribute ``lfmbench_scale`` of its part.
        notes, stats: as in :func:`encode_static_exr`.
        steady: split each light by :func:`split_steady` (format version 3); False stores every light's K bins
            over its whole box (the version-2 layout, still valid).

    A group with no visible light is stored as one placeholder part named ``empty`` (1x1, channel ``empty``,
    attribute ``lfmbench_nparts = 0``) because an EXR file needs at least one part.
    """
    st = resolve_storage(dtype)
    notes = [] if notes is None else notes
    if bins < 1:
        raise ValueError(f"{what}: bins must be >= 1, got {bins}")
    exr = _exr()
    names = bin_channels(bins, bands_nm)
    parts = []
    seen = set()
    for light_id, box, arr in lights:
        lid = int(light_id)
        if lid < 0 or lid in seen:
            raise ValueError(f"{what}: light ids must be unique and >= 0, got {light_id!r}")
        seen.add(lid)
        pw = f"{what} light{lid}"
        y0, x0, y1, x1 = _clip_box(box, height, width, pw)
        a = _check_radiance(arr, pw)
        if a.shape != (bins, len(bands_nm), y1 - y0, x1 - x0):
            raise ValueError(f"{pw}: expected shape (K={bins}, C={len(bands_nm)}, {y1 - y0}, {x1 - x0}) "
                             f"for bbox {(y0, x0, y1, x1)}, got {a.shape}")
        whole = (0, 0, y1 - y0, x1 - x0)
        layers = [(False, whole, a)]
        if steady and bins > 1:
            bb, sb, sa = split_steady(a)
            if bb != whole:  # some pixels are the same in every bin: the bins' box shrinks
                layers = [(False, bb, a.window(*bb) if isinstance(a, SteadyBins) else a[:, :, bb[0]:bb[2], bb[1]:bb[3]])]
                if sb is not None:
                    layers.append((True, sb, sa[:, sb[0]:sb[2], sb[1]:sb[3]]))
        if isinstance(layers[0][2], SteadyBins):  # stored whole: the (K, C, h, w) array
            layers[0] = (False, whole, np.asarray(a))
        for is_steady, (by0, bx0, by1, bx1), data in layers:
            name = light_part_name(lid, is_steady)
            ls = store_layer(data, st, f"{what} {name}")
            _note_layer(ls, f"{what} {name}", notes, stats)
            if is_steady:
                channels = {n: ls.data[c] for c, n in enumerate(steady_channels(bands_nm))}
            else:
                channels = {names[k][c]: ls.data[k, c] for k in range(bins) for c in range(len(bands_nm))}
            header = _base_header(width, height, (y0 + by0, x0 + bx0, y0 + by1, x0 + bx1), st.compression)
            header.update(attrs or {})
            header.update({ATTR["kind"]: "lights", ATTR["light"]: lid, ATTR["bins"]: int(bins),
                           ATTR["units"]: RADIANCE_UNIT, ATTR["stored"]: ls.pixel_type, scale_attr(None): ls.scale,
                           ATTR["mantissa"]: st.bits})
            parts.append(((lid, is_steady), header, channels, name))
    if not parts:
        header = _base_header(width, height, (0, 0, 1, 1), st.compression)
        header.update(attrs or {})
        header.update({ATTR["kind"]: "lights", ATTR["nparts"]: 0, ATTR["bins"]: int(bins)})
        return _encode([exr.Part(header, {EMPTY_PART: np.zeros((1, 1), np.float32)}, EMPTY_PART)], what)
    out = []
    for _, header, channels, name in sorted(parts, key=lambda p: p[0]):
        header[ATTR["nparts"]] = len(parts)
        out.append(exr.Part(header, channels, name))
    return _encode(out, what)


def encode_aux_exr(aux: Mapping[str, np.ndarray], height: int, width: int, *,
                   attrs: Mapping[str, Any] | None = None, what: str = "aux") -> bytes:
    """Encode ``aux.exr``: FLOAT channels ``depth.Z``, ``depth.R`` (m; +inf where no surface) and
    ``mask.instance``, ``mask.light`` (integer ids stored as float32, -1 = none), each (H, W)."""
    if set(aux) != set(AUX_CHANNELS):
        raise ValueError(f"{what}: aux channels must be exactly {AUX_CHANNELS}, got {sorted(aux)}")
    channels = {}
    for name in AUX_CHANNELS:
        a = np.asarray(aux[name])
        if a.shape != (height, width):
            raise ValueError(f"{what} [{name}]: expected shape ({height}, {width}), got {a.shape}")
        a = np.ascontiguousarray(a, dtype=np.float32)
        _check_aux(name, a, what)
        channels[name] = a
    header = _base_header(width, height)
    header.update(attrs or {})
    header[ATTR["kind"]] = "aux"
    return _encode([_exr().Part(header, channels, "aux")], what)
