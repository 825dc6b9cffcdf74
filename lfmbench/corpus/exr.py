"""EXR encoding and decoding of corpus files through the OpenEXR 3.x Python API (``OpenEXR.File`` /
``OpenEXR.Part``): :func:`encode_static_exr`, :func:`encode_lights_exr`, :func:`encode_aux_exr` (bytes, no I/O),
:func:`read_exr` (:class:`ExrPart` per part) and the per-layer scale of a decoded part (:func:`layer_scale`).

Units: spectral radiance in W sr^-1 m^-2 nm^-1, depth in m, bounding boxes in pixels as half-open
``(y0, x0, y1, x1)``.

References: OpenEXR file layout and multi-part files, https://openexr.com/en/latest/TechnicalIntroduction.html
(data window / display window, part names).
"""
from __future__ import annotations

import io
import math
import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from lfmbench.corpus.errors import CorpusChannelError, CorpusFileError, CorpusValueError
from lfmbench.corpus.naming import (ATTR, AUX_CHANNELS, EMPTY_PART, FORMAT_VERSION, RADIANCE_MAX, RADIANCE_UNIT,
                                    STATIC_BINS_VERSION, bin_prefix,
                                    STATIC_WINDOWS, _check_version, bin_channels, light_part_name, static_channels,
                                    steady_channels)
from lfmbench.limits import LimitError, limits_of
from lfmbench.corpus.storage import (COMPRESSIONS, DEFAULT_STORAGE, EXTRA_COMPRESSIONS, LayerStore, SCALE_EXP_RANGE,
                                     Storage, StorageStats, resolve_storage, scale_attr, store_layer)

__all__ = ["encode_static_exr", "encode_lights_exr", "encode_aux_exr", "ExrPart", "read_exr", "layer_scale",
           "check_exr_header", "exr_headers", "ExrHeaders", "split_steady", "SteadyBins"]


def _exr():
    try:
        import OpenEXR  # noqa: PLC0415
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ImportError("lfmbench.corpus needs the OpenEXR 3.x Python bindings: pip install 'OpenEXR>=3.2'") \
            from exc
    return OpenEXR


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


def _check_aux(name: str, a: np.ndarray, what: str) -> None:
    if np.isnan(a).any():
        raise CorpusValueError(f"{what} [{name}]: contains NaN")
    if name.startswith("depth."):
        if (a < 0).any():
            raise CorpusValueError(f"{what} [{name}]: negative depth")
    else:
        if not np.isfinite(a).all() or (a < -1).any() or (a != np.round(a)).any():
            raise CorpusValueError(f"{what} [{name}]: ids must be integers >= -1")


@dataclass
class ExrPart:
    """One decoded EXR part: name, header dict, data window ``(y0, x0, y1, x1)`` (half-open), display size
    ``(H, W)`` and channels ``{name: (h, w) ndarray}`` (None when read header-only)."""

    name: str
    header: dict
    window: tuple[int, int, int, int]
    size: tuple[int, int]
    channel_names: list[str]
    channels: dict[str, np.ndarray] | None = None


#: Bytes per pixel of the EXR pixel types UINT, HALF, FLOAT (OpenEXR file layout).
_EXR_TYPE_BYTES = {0: 4, 1: 2, 2: 4}
#: Attribute types whose values :func:`exr_headers` decodes (struct format; ``string``: the bytes as UTF-8).
_ATTR_FORMATS = {b"int": "<i", b"float": "<f", b"double": "<d"}
#: Version-field flags (OpenEXR file layout): single-part tiled, long names, non-image (deep), multi-part.
_TILED, _LONG_NAMES, _DEEP, _MULTIPART = 0x200, 0x400, 0x800, 0x1000
#: Bytes of an EXR file read at first for its headers.
HEAD_BYTES = 1 << 16


@dataclass
class ExrHeaders:
    """The headers of an EXR file as :func:`exr_headers` parsed them: per part its ``name`` (``""`` when the file
    has none, as OpenEXR reports it), the decoded ``int``/``float``/``double``/``string`` attributes and the
    windows (``attrs``), data window ``(y0, x0, y1, x1)`` and display size ``(H, W)`` (px), channel names in file
    order; ``plain``: a scanline image of a layout :func:`read_exr` can describe header-only by itself (not
    tiled, not deep)."""

    parts: list[dict]
    decoded_bytes: int
    plain: bool


def exr_headers(path: str | os.PathLike, head: bytes | None = None) -> ExrHeaders:
    """Parse the headers of an EXR file (pure Python, nothing but the header bytes) and check what they declare
    against :mod:`lfmbench.limits` before any pixel buffer is allocated: number of parts (``exr_parts``),
    channels per part (``exr_channels``), display / data window sides (``exr_side``; both windows must have
    positive size), the decoded size of all parts (``exr_bytes``) and the header bytes (``exr_header_bytes``).

    Args:
        path: the file (named in every message; opened only when ``head`` does not hold the whole header).
        head: the first bytes of the file, when the caller has read them already (e.g. while hashing it).

    Raises:
        CorpusFileError: naming ``path``: not an EXR, truncated header, or a limit exceeded (the message names the
            limit and how to raise it).
    """
    path = os.fspath(path)  # (text: a Path per file costs more than this parse of a small header)
    cap_hdr, max_parts, max_ch, max_side, max_bytes = limits_of("exr_header_bytes", "exr_parts", "exr_channels",
                                                                "exr_side", "exr_bytes")
    fh = None
    buf = b""
    try:
        if head is None:
            fh = _open_exr(path)
            buf = fh.read(HEAD_BYTES)
        else:
            buf = bytes(head)

        def more(need: int) -> bytes:  # the buffer extended to ``need`` bytes (bounded by exr_header_bytes)
            nonlocal buf, fh
            while len(buf) < need:
                if len(buf) >= cap_hdr:
                    raise LimitError(str(path), "EXR header of more bytes", None, "exr_header_bytes")
                if fh is None:
                    fh = _open_exr(path)
                    fh.seek(len(buf))
                b = fh.read(min(max(need - len(buf), 1 << 20), cap_hdr - len(buf)))
                if not b:
                    raise CorpusFileError(f"EXR file {path} is truncated or corrupt: header ends early")
                buf += b
            return buf

        def cstr(i: int) -> tuple[bytes, int]:
            j = buf.find(b"\0", i, i + 257)
            while j < 0:
                if len(buf) - i > 256:
                    raise CorpusFileError(f"EXR file {path} is corrupt: a header name longer than 255 bytes")
                more(len(buf) + 1)
                j = buf.find(b"\0", i, i + 257)
            return buf[i:j], j + 1

        if len(buf) < 8:
            more(8)
        magic, flags = struct.unpack_from("<iI", buf, 0)
        if magic != 20000630:
            raise CorpusFileError(f"cannot read EXR file {path}: not an OpenEXR file (bad magic number)")
        multipart = bool(flags & _MULTIPART)
        plain = not flags & (_TILED | _DEEP)
        i, total = 8, 0
        parts: list[dict] = []
        while True:
            windows: dict[bytes, tuple[int, int, int, int]] = {}
            attrs: dict[str, Any] = {}
            names: list[str] = []
            n_ch, px_bytes, first = 0, 0.0, True
            while True:
                name, i = cstr(i)
                if not name:
                    break
                first = False
                typ, i = cstr(i)
                if len(buf) < i + 4:
                    more(i + 4)
                (size,) = struct.unpack_from("<i", buf, i)
                i += 4
                if size < 0:
                    raise CorpusFileError(f"EXR file {path} is corrupt: negative attribute size")
                if len(buf) < i + size:
                    more(i + size)
                if typ == b"chlist":
                    k, end = i, i + size
                    while k < end and buf[k] != 0:
                        j = buf.index(b"\0", k, end)
                        ptype, _, xs, ys = struct.unpack_from("<iIii", buf, j + 1)
                        n_ch += 1
                        if n_ch > max_ch:
                            raise LimitError(str(path), f"EXR part {len(parts)} with more than {max_ch:,} channels",
                                             None, "exr_channels")
                        names.append(buf[k:j].decode("utf-8", "replace"))
                        px_bytes += _EXR_TYPE_BYTES.get(ptype, 4) / max(1, xs) / max(1, ys)
                        k = j + 17
                elif typ == b"box2i" and size == 16 and name in (b"dataWindow", b"displayWindow"):
                    windows[name] = struct.unpack_from("<iiii", buf, i)
                elif typ in _ATTR_FORMATS and size == struct.calcsize(_ATTR_FORMATS[typ]):
                    (attrs[name.decode("utf-8", "replace")],) = struct.unpack_from(_ATTR_FORMATS[typ], buf, i)
                elif typ == b"string":
                    attrs[name.decode("utf-8", "replace")] = buf[i:i + size].decode("utf-8", "replace")
                i += size
            if first and multipart and parts:  # the empty header that ends a multi-part header list
                break
            if len(parts) >= max_parts:
                raise LimitError(str(path), f"EXR file with more than {max_parts:,} parts", None, "exr_parts")
            for key in (b"displayWindow", b"dataWindow"):
                if key not in windows:
                    raise CorpusFileError(f"cannot read EXR file {path}: part {len(parts)} has no "
                                          f"{key.decode()}")
                x0, y0, x1, y1 = windows[key]
                w, h = x1 - x0 + 1, y1 - y0 + 1
                if w < 1 or h < 1:
                    raise CorpusFileError(f"EXR file {path} part {len(parts)}: {key.decode()} "
                                          f"{windows[key]} is empty")
                if max(w, h) > max_side:
                    raise LimitError(str(path), f"EXR part {len(parts)} {key.decode()} side", max(w, h),
                                     "exr_side")
            x0, y0, x1, y1 = windows[b"dataWindow"]
            total += int((x1 - x0 + 1) * (y1 - y0 + 1) * px_bytes)
            if total > max_bytes:
                raise LimitError(str(path), f"EXR file declaring {total:,} or more decoded pixel bytes", total,
                                 "exr_bytes")
            wx0, wy0, wx1, wy1 = windows[b"displayWindow"]
            plain = plain and attrs.pop("type", "scanlineimage") == "scanlineimage"  # OpenEXR's is an enum
            attrs["dataWindow"], attrs["displayWindow"] = ((x0, y0), (x1, y1)), ((wx0, wy0), (wx1, wy1))
            parts.append({"name": attrs.get("name", ""), "attrs": attrs, "channels": names,
                          "window": (y0, x0, y1 + 1, x1 + 1), "size": (wy1 - wy0 + 1, wx1 - wx0 + 1)})
            if not multipart:
                break
    except LimitError as exc:
        raise CorpusFileError(str(exc)) from None
    except CorpusFileError:
        raise
    except (OSError, struct.error, ValueError) as exc:
        raise CorpusFileError(f"cannot read EXR file {path}: {exc}") from None
    finally:
        if fh is not None:
            fh.close()
    return ExrHeaders(parts, total, plain)


def check_exr_header(path: str | os.PathLike, head: bytes | None = None) -> dict:
    """:func:`exr_headers` of ``path``, summed up: ``{"parts": n, "decoded_bytes": b}``. Deep and tiled layouts
    are passed on to OpenEXR, which reports them. Raises ``CorpusFileError`` as :func:`exr_headers`."""
    h = exr_headers(path, head)
    return {"parts": len(h.parts), "decoded_bytes": h.decoded_bytes}


def _open_exr(path: str):
    """The EXR file ``path`` opened for reading (:func:`lfmbench.fileio.open_regular`); a FIFO, device or socket is
    a :class:`CorpusFileError` naming it."""
    from lfmbench.fileio import NotRegularFileError, open_regular  # noqa: PLC0415

    try:
        return open_regular(path, "EXR file")
    except NotRegularFileError as exc:
        raise CorpusFileError(str(exc)) from None


def read_exr(path: str | os.PathLike, *, header_only: bool = False, head: bytes | None = None) -> list[ExrPart]:
    """Decode every part of an EXR file (OpenEXR 3.x reads whole files: all parts, all channels).

    The headers are parsed and checked first (:func:`exr_headers`): a file that declares more parts, channels,
    pixels or decoded bytes than :mod:`lfmbench.limits` allows is refused before OpenEXR allocates anything.
    ``header_only``: the parts are described from that parse alone (no second read of the header by OpenEXR);
    ``ExrPart.header`` then holds the ``int``/``float``/``double``/``string`` attributes and the two windows
    (tiled and deep files, which lfmbench does not write, go through OpenEXR's full header instead).
    ``head``: the file's first bytes, when the caller has read them already.

    Raises :class:`CorpusFileError` naming ``path`` when it is missing, not an EXR, truncated (a part whose
    pixels cannot be read, detected by comparing with the part count of the header) or above a limit.
    """
    path = os.fspath(path)
    if head is None and not os.path.exists(path):
        raise CorpusFileError(f"EXR file is missing: {path}")
    if head is None:
        _open_exr(path).close()  # a FIFO or device: one line, never a read that waits
    hdrs = exr_headers(path, head)
    if header_only and hdrs.plain:
        out = []
        for p in hdrs.parts:
            h = p["attrs"]
            if ATTR["version"] in h:
                _check_version(h[ATTR["version"]], f"EXR file {path} part {p['name']!r} ({ATTR['version']})")
            out.append(ExrPart(name=p["name"], header=h, window=p["window"], size=p["size"],
                               channel_names=p["channels"]))
        return out
    exr = _exr()
    n_parts = len(hdrs.parts)
    try:
        f = exr.File(str(path), header_only=header_only, separate_channels=True)
    except Exception as exc:  # RuntimeError from the C++ library
        raise CorpusFileError(f"cannot read EXR file {path}: {exc}") from exc
    if len(f.parts) != n_parts:
        raise CorpusFileError(f"EXR file {path} is truncated or corrupt: {len(f.parts)} of {n_parts} parts "
                              "could be read")
    out = []
    for p in f.parts:
        h = p.header
        if ATTR["version"] in h:
            _check_version(h[ATTR["version"]], f"EXR file {path} part {p.name()!r} ({ATTR['version']})")
        (dx0, dy0), (dx1, dy1) = (tuple(int(v) for v in c) for c in h["dataWindow"])
        (wx0, wy0), (wx1, wy1) = (tuple(int(v) for v in c) for c in h["displayWindow"])
        names = [c.name for c in h.get("channels", [])] if header_only else list(p.channels)
        chans = None
        if not header_only:
            chans = {}
            for k, ch in p.channels.items():
                px = ch.pixels
                if px is None or px.shape != (dy1 - dy0 + 1, dx1 - dx0 + 1):
                    raise CorpusFileError(f"EXR file {path} part {p.name()!r}: channel {k!r} could not be read")
                chans[k] = px
        out.append(ExrPart(name=p.name(), header=dict(h), window=(dy0, dx0, dy1 + 1, dx1 + 1),
                           size=(wy1 - wy0 + 1, wx1 - wx0 + 1), channel_names=names, channels=chans))
    return out


def layer_scale(part: ExrPart, window: str | None, path: str | os.PathLike) -> float:
    """The scale 2^e by which a layer's stored values exceed the radiance (format version 2, section 6 of
    ``docs/guide/corpus-format.md``): header attribute :func:`scale_attr` of ``window`` (``None``: a light part),
    1.0 when absent (version 1). ``CorpusFileError`` naming the file unless it is a power of two 2^e,
    e in :data:`SCALE_EXP_RANGE`."""
    key = scale_attr(window)
    v = part.header.get(key, 1.0)
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0
    if ok:
        f, q = math.frexp(float(v))
        ok = f == 0.5 and SCALE_EXP_RANGE[0] <= q - 1 <= SCALE_EXP_RANGE[1]
    if not ok:
        raise CorpusFileError(f"EXR file {path} part {part.name!r}: attribute {key} = {v!r} must be a power of "
                              f"two 2^e with e in [{SCALE_EXP_RANGE[0]}, {SCALE_EXP_RANGE[1]}]")
    return float(v)


def _stack(part: ExrPart, names: Sequence[str], path: Path) -> np.ndarray:
    missing = [n for n in names if n not in part.channels]
    if missing:
        raise CorpusChannelError(f"EXR file {path} part {part.name!r} lacks channels {missing[:4]}"
                                 f"{' ...' if len(missing) > 4 else ''}")
    return np.stack([np.asarray(part.channels[n], dtype=np.float32) for n in names])


def _check_values(arr: np.ndarray, path: Path, what: str) -> None:
    if arr.size == 0:
        return
    lo = float(arr.min())
    if not math.isfinite(lo) or not math.isfinite(float(arr.max())):
        raise CorpusValueError(f"EXR file {path} {what}: radiance contains NaN or inf")
    if lo < 0:
        raise CorpusValueError(f"EXR file {path} {what}: radiance contains negative values (min {lo:.3g})")
    hi = float(arr.max())
    if hi > RADIANCE_MAX:
        raise CorpusValueError(f"EXR file {path} {what}: radiance {hi:.3g} {RADIANCE_UNIT} exceeds the plausibility "
                               f"ceiling RADIANCE_MAX = {RADIANCE_MAX:.0e} (50x the sun's disc): a unit or scale "
                               "error; run `lfmbench validate`")
