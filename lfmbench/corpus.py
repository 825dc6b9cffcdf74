"""The lfmbench radiance corpus: OpenEXR files + JSON metadata + a SHA-256 manifest.

This module defines the on-disk format specified in ``docs/corpus-format.md`` (and summarised in
``docs/contracts.md`` section 2) and everything that touches it:

* low-level EXR encoding / decoding through the OpenEXR 3.x Python API (``OpenEXR.File`` / ``OpenEXR.Part``):
  :func:`encode_static_exr`, :func:`encode_lights_exr`, :func:`encode_aux_exr`, :func:`read_exr`;
* :class:`CorpusWriter`: atomic writes (temporary name in the same directory, then :func:`os.replace`), a
  manifest that is rewritten atomically after each finished scene, resume support (:meth:`is_complete`);
* :class:`Corpus`: the reader (lazy: one file per frame and light group is decoded only when asked for, with
  a small cache so that reading ``short`` then ``long`` decodes the file once);
* :func:`validate_corpus`: a full check of a corpus (missing files, checksums, channels, NaN/inf/negative
  radiance, metadata consistency), used by ``lfmbench validate``;
* :func:`validate_meta`: consistency checks of a scene's ``meta.json`` (timing, bands, groups, camera).

Units: spectral radiance in W sr^-1 m^-2 nm^-1, wavelengths in nm, times in s, depth in m, bounding boxes in
pixels as half-open ``(y0, x0, y1, x1)`` (rows y0..y1-1, columns x0..x1-1).

Timing convention (``docs/contracts.md`` section 1): frame n starts at n / fps; the long window is
``[t_n, t_n + T_L)``, the short window is centred in it, and flickering groups are stored in K equal bins over
the capture window ``[t_n, t_n + T_L + readout_s)``.

References: OpenEXR file layout and multi-part files, https://openexr.com/en/latest/TechnicalIntroduction.html
(data window / display window, part names); SHA-256, FIPS PUB 180-4.
"""
from __future__ import annotations

import contextlib
import hashlib
import io
import json
import logging
import math
import os
import re
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np

from lfmbench import check
from lfmbench.check import check_scene_id, scene_id_error
from lfmbench.fileio import (TMP_PREFIX, AtomicWriteError, atomic_write_bytes, atomic_write_json,
                             json_default)

__all__ = [
    "FORMAT_NAME", "FORMAT_VERSION", "READABLE_VERSIONS", "STATIC_WINDOWS", "AUX_CHANNELS", "HALF_MAX",
    "HALF_MIN_NORMAL", "HALF_UNDERFLOW_ERROR_FRACTION", "RADIANCE_UNIT", "COMPRESSIONS", "STORAGES",
    "DEFAULT_STORAGE", "Storage", "resolve_storage", "round_mantissa", "scale_exponent", "store_layer",
    "scale_attr", "LayerStore", "StorageStats",
    "CorpusError", "CorpusNotFoundError", "CorpusFileError", "CorpusChannelError", "CorpusValueError",
    "CorpusWriteError", "band_channel", "bin_prefix", "static_channels", "bin_channels", "frame_dir",
    "group_storage", "encode_static_exr", "encode_lights_exr", "encode_aux_exr", "read_exr", "sha256_file",
    "atomic_write_bytes", "atomic_write_json", "make_splits", "validate_meta", "Corpus", "CorpusWriter",
    "ValidationReport", "validate_corpus", "encode_scene", "write_files", "prune_scene_dir", "ExrPart",
    "check_scene_id", "manifest_entry_errors", "inside_root", "check_splits", "RADIANCE_MAX",
]

log = logging.getLogger(__name__)

#: ``manifest.json`` "format" value and format version written by this module. Version 2 (HALF x 2^e layers,
#: codecs and mantissa rounding, ``docs/corpus-format.md``) reads every version-1 file unchanged.
FORMAT_NAME = "lfmbench-corpus"
FORMAT_VERSION = 2
#: Format versions this module reads.
READABLE_VERSIONS = (1, 2)
MANIFEST_NAME = "manifest.json"
SPLITS_NAME = "splits.json"
SCENES_DIR = "scenes"
#: Exposure windows stored for static (non-flickering) groups, in this channel-prefix order.
STATIC_WINDOWS = ("short", "long")
#: Channels of ``aux.exr``: z-depth and range (m) and instance / light ids (float32, -1 = none).
AUX_CHANNELS = ("depth.Z", "depth.R", "mask.instance", "mask.light")
#: Largest finite IEEE 754 binary16 value; radiance above it cannot be stored as HALF (IEEE 754-2008).
HALF_MAX = 65504.0
RADIANCE_UNIT = "W sr^-1 m^-2 nm^-1"
#: Plausibility ceiling of spectral radiance (W sr^-1 m^-2 nm^-1), checked on write, on read and by
#: :func:`validate_corpus`. The sun's disc seen from the ground peaks near 2e7 W sr^-1 m^-2 nm^-1
#: (a 5800 K black body: B_lambda(500 nm) ~ 2.6e7); an LED die is far dimmer. 1e9 is fifty times the sun, so a
#: value above it is a unit or scale error (e.g. a corrupted ``lfmbench_scale`` attribute), never a scene.
RADIANCE_MAX = 1e9
#: Name and channel of the placeholder part of a flickering-group EXR in which no light is visible.
EMPTY_PART = "empty"
#: Prefix of temporary files; stray ones (after a crash) are removed by :class:`CorpusWriter`.
#: Relative tolerance of the timing consistency checks (s / s).
TIMING_RTOL = 1e-6
#: Header attribute names (all prefixed ``lfmbench_``).
ATTR = {
    "kind": "lfmbench_kind", "scene": "lfmbench_scene_id", "frame": "lfmbench_frame",
    "group": "lfmbench_group", "units": "lfmbench_units", "light": "lfmbench_light_id",
    "nparts": "lfmbench_nparts", "bins": "lfmbench_bins", "stored": "lfmbench_stored_as",
    "version": "lfmbench_format_version", "mantissa": "lfmbench_mantissa_bits", "scale": "lfmbench_scale",
}


# --------------------------------------------------------------------------------------------------- errors
class CorpusError(ValueError):
    """Base class of every corpus problem; the message names the file or argument at fault."""


class CorpusNotFoundError(CorpusError):
    """The corpus root or its ``manifest.json`` does not exist (tells the user how to make one)."""


class CorpusFileError(CorpusError):
    """A corpus file is missing, unreadable, truncated or has a bad checksum."""


class CorpusChannelError(CorpusError):
    """An EXR lacks expected channels / parts or has channels the metadata does not announce."""


class CorpusValueError(CorpusError):
    """Radiance (or aux data) that is NaN, infinite or negative."""


#: Writing a corpus file failed (disk full, ...); the message names the file. Same class as
#: :class:`lfmbench.fileio.AtomicWriteError`.
CorpusWriteError = AtomicWriteError


# ---------------------------------------------------------------------------------------- channel naming
def _fmt_nm(wl: float) -> str:
    """Wavelength (nm) as written in channel names: ``400`` -> ``"400"``, ``402.5`` -> ``"402.5"``."""
    wl = float(wl)
    if not math.isfinite(wl) or wl <= 0:
        raise ValueError(f"wavelength must be a positive number of nm, got {wl!r}")
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


def static_channels(window: str, bands_nm: Sequence[float]) -> list[str]:
    """Channel names of one exposure window (``short`` / ``long``) of a static group, band order."""
    if window not in STATIC_WINDOWS:
        raise ValueError(f"window must be one of {STATIC_WINDOWS}, got {window!r}")
    return [band_channel(window, wl) for wl in bands_nm]


def bin_channels(bins: int, bands_nm: Sequence[float]) -> list[list[str]]:
    """Channel names of a per-light part: ``[k][c]`` -> ``bin{k}.{wl_c}nm``."""
    return [[band_channel(bin_prefix(k, bins), wl) for wl in bands_nm] for k in range(bins)]


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
        raise ValueError(f"group {group!r} is not in this scene's meta.json groups {sorted(groups)}")
    g = groups[group]
    if not g.get("flicker", False):
        return "static"
    bins = int(g.get("bins", meta.get("timing", {}).get("bins", 0)))
    return "lights" if bins > 0 else "static"


def _group_bins(meta: Mapping[str, Any], group: str) -> int:
    g = meta["groups"][group]
    return int(g.get("bins", meta.get("timing", {}).get("bins", 0)))


# ------------------------------------------------------------------------------------------- atomic I/O
# atomic_write_bytes / atomic_write_json live in lfmbench.fileio (one implementation for the package)


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """SHA-256 hex digest (FIPS 180-4) of a file, read in 1 MiB chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while True:
            b = fh.read(chunk)
            if not b:
                break
            h.update(b)
    return h.hexdigest()


def _load_json(path: Path, what: str) -> Any:
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise CorpusFileError(f"{what} is missing: {path}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CorpusFileError(f"{what} {path} is not valid JSON: {exc}") from exc


# ------------------------------------------------------------------------------------------ EXR encoding
def _exr():
    try:
        import OpenEXR  # noqa: PLC0415
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ImportError("lfmbench.corpus needs the OpenEXR 3.x Python bindings: pip install 'OpenEXR>=3.2'") \
            from exc
    return OpenEXR


def _check_radiance(arr: np.ndarray, what: str) -> np.ndarray:
    arr = np.asarray(arr)
    if not np.issubdtype(arr.dtype, np.floating):
        raise ValueError(f"{what}: radiance must be a floating-point array, got dtype {arr.dtype}")
    if arr.size and not np.isfinite(arr).all():
        raise CorpusValueError(f"{what}: radiance contains NaN or inf")
    if arr.size and float(arr.min()) < 0:
        raise CorpusValueError(f"{what}: radiance contains negative values (min {float(arr.min()):.3g})")
    if arr.size and float(arr.max()) > RADIANCE_MAX:
        raise CorpusValueError(f"{what}: radiance {float(arr.max()):.3g} {RADIANCE_UNIT} exceeds the plausibility "
                               f"ceiling RADIANCE_MAX = {RADIANCE_MAX:.0e} (50x the sun's disc): a unit or scale error")
    return arr


#: EXR compressions a corpus file may use, by name -> ``OpenEXR`` enum member. All are readable by OpenEXR 2.2
#: and later; every one of them is lossless on the channels lfmbench writes except PXR24 on FLOAT channels
#: (rounded to 24 bits, <= 2^-16 relative): DWAA/DWAB compress lossily only channels named R, G, B, Y, BY, RY
#: (and ``*.R`` ...), never ``short.400nm`` (checked in ``docs/storage-benchmark.md``).
COMPRESSIONS = {"none": "NO_COMPRESSION", "rle": "RLE_COMPRESSION", "zips": "ZIPS_COMPRESSION",
                "zip": "ZIP_COMPRESSION", "piz": "PIZ_COMPRESSION", "pxr24": "PXR24_COMPRESSION",
                "dwaa": "DWAA_COMPRESSION", "dwab": "DWAB_COMPRESSION"}
#: Compressions accepted only with ``Storage(allow_lossy_codec=True)`` (benchmarks): B44/B44A quantise every
#: HALF channel (up to ~12 % per value), an error the writer does not measure; ZSTD / HTJ2K need OpenEXR >= 3.4.
EXTRA_COMPRESSIONS = {"b44": "B44_COMPRESSION", "b44a": "B44A_COMPRESSION", "zstd": "ZSTD_COMPRESSION",
                      "htj2k32": "HTJ2K32_COMPRESSION", "htj2k256": "HTJ2K256_COMPRESSION"}
#: Smallest positive normal binary16 value, 2^-14 ~ 6.1e-5 (IEEE 754-2008).
HALF_MIN_NORMAL = 2.0 ** -14
#: Octaves R below a HALF layer's peak in which every value keeps the full relative precision of the stored
#: mantissa bits m (2^20 ~ 1.05e6, 120 dB, the range of an HDR automotive sensor). HALF's subnormals have an
#: absolute step of 2^-24, i.e. m-bit relative precision down to 2^(m-24); so the layer is scaled by 2^e with
#: its peak in [2^(P-1), 2^P), P = R - 23 + m (P = 2 for m = 5, 7 for m = 10), and values below peak * 2^-R
#: keep an absolute error <= 2^-25 / 2^e (W sr^-1 m^-2 nm^-1), below 2^-(R+m+1) of the peak.
HALF_PRECISION_RANGE_LOG2 = 20
#: Allowed range of the scale exponent e (2^e must be a normal float32 for the float attribute).
SCALE_EXP_RANGE = (-126, 127)
#: Bound of the energy-weighted relative error ``sum_{x*s < 2^-14} |x' - x| / sum x`` caused by values that fall
#: below HALF's normal range after scaling (x' the value read back, s = 2^e), as a multiple of the rounding
#: bound 2^-(m+1) of m mantissa bits: a quarter, i.e. 2^-(m+3) (1.2e-4 for m = 10, 3.9e-3 for m = 5). A layer
#: above it is stored FLOAT (with the same mantissa rounding). Subnormal HALF keeps an absolute step of 2^-24,
#: so this error is <= n * 2^-(P+24) for a layer of n values whose peak is >= 2^(P-1).
HALF_UNDERFLOW_ERROR_FRACTION = 0.25
#: Explicit mantissa bits of the EXR pixel types.
MANTISSA_BITS = {"float16": 10, "float32": 23}


@dataclass(frozen=True)
class Storage:
    """How radiance layers (a static group's window: C bands; a light: K bins x C bands) are stored.

    Attributes:
        dtype: ``"float16"``: EXR HALF holding ``radiance * 2^e`` with one power-of-two scale per layer (peak
            in [2^(P-1), 2^P), see :func:`scale_exponent`), FLOAT fallback for a layer whose underflow error
            would exceed :attr:`max_underflow_error`; ``"float32"``: EXR FLOAT, scale 1.
        compression: a key of :data:`COMPRESSIONS`.
        mantissa_bits: round every stored value to this many explicit mantissa bits (round to nearest, ties to
            even) before compression, 1..10 for HALF, 1..23 for FLOAT; ``None`` keeps all. The relative
            error of a value in the normal range is <= 2^-(mantissa_bits + 1).
        allow_lossy_codec: accept :data:`EXTRA_COMPRESSIONS` (benchmarks only).
    """

    dtype: str = "float16"
    compression: str = "zip"
    mantissa_bits: int | None = None
    allow_lossy_codec: bool = False

    def __post_init__(self) -> None:
        if self.dtype not in MANTISSA_BITS:
            raise ValueError(f"dtype must be 'float32' (EXR FLOAT) or 'float16' (EXR HALF x 2^e), got "
                             f"{self.dtype!r}")
        known = dict(COMPRESSIONS, **(EXTRA_COMPRESSIONS if self.allow_lossy_codec else {}))
        if self.compression not in known:
            raise ValueError(f"compression must be one of {sorted(known)}, got {self.compression!r}")
        mb = self.mantissa_bits
        top = MANTISSA_BITS[self.dtype]
        if mb is not None and (isinstance(mb, bool) or not isinstance(mb, int) or not 1 <= mb <= top):
            raise ValueError(f"mantissa_bits must be None or an integer in [1, {top}] for {self.dtype}, got {mb!r}")

    @property
    def bits(self) -> int:
        """Explicit mantissa bits actually kept (10 for HALF, 23 for FLOAT when not rounded)."""
        return MANTISSA_BITS[self.dtype] if self.mantissa_bits is None else int(self.mantissa_bits)

    @property
    def max_rel_rounding_error(self) -> float:
        """Largest relative change of a value in HALF's normal range (or any FLOAT value): 2^-(bits+1)."""
        return 2.0 ** -(self.bits + 1)

    @property
    def max_underflow_error(self) -> float:
        """Largest energy-weighted error from values below HALF's normal range before a layer is stored FLOAT:
        ``HALF_UNDERFLOW_ERROR_FRACTION * 2^-(bits+1)``."""
        return HALF_UNDERFLOW_ERROR_FRACTION * self.max_rel_rounding_error

    def to_dict(self) -> dict:
        """``meta.json`` ``storage`` entry (without ``format_version``)."""
        return {"dtype": self.dtype, "compression": self.compression, "mantissa_bits": self.bits}


#: Named storages (``lfmbench render --storage NAME``). ``compact`` is the default of new corpora (chosen in
#: ``docs/storage-benchmark.md``); ``float32`` stores the pixels as format version 1 did (lossless FLOAT, ZIP).
STORAGES = {
    "compact": Storage("float16", "piz", 5),
    "float16": Storage("float16", "zip", None),
    "float32": Storage("float32", "zip", None),
}
DEFAULT_STORAGE = "compact"


def resolve_storage(storage: str | Storage, what: str = "dtype") -> Storage:
    """A :class:`Storage` from a name of :data:`STORAGES` or a :class:`Storage`; ``ValueError`` naming ``what``."""
    if isinstance(storage, Storage):
        return storage
    if isinstance(storage, str) and storage in STORAGES:
        return STORAGES[storage]
    raise ValueError(f"{what} must be one of {sorted(STORAGES)} or a corpus.Storage, got {storage!r}")


def round_mantissa(arr: np.ndarray, bits: int) -> np.ndarray:
    """``arr`` (finite, any float dtype) as float32 rounded to ``bits`` explicit mantissa bits (1..23).

    Round to nearest, ties to even, on the float32 bit pattern (a carry into the exponent is the correct
    result); relative change <= 2^-(bits+1) for normal float32 values. Returns a new float32 array.
    """
    a = np.array(arr, dtype=np.float32, copy=True)
    if not 1 <= int(bits) <= 23:
        raise ValueError(f"bits must be in [1, 23], got {bits!r}")
    drop = 23 - int(bits)
    if drop == 0:
        return a
    b = a.view(np.uint32)
    lsb = (b >> np.uint32(drop)) & np.uint32(1)
    b += np.uint32((1 << (drop - 1)) - 1) + lsb
    b &= np.uint32(~((1 << drop) - 1) & 0xFFFFFFFF)
    return a


def scale_exponent(peak: float, bits: int = 10) -> int:
    """Exponent e of the power-of-two scale of a HALF layer with maximum ``peak`` (W sr^-1 m^-2 nm^-1) whose
    values keep ``bits`` mantissa bits: ``peak * 2^e`` lies in [2^(P-1), 2^P) with
    ``P = HALF_PRECISION_RANGE_LOG2 - 23 + bits``; 0 for an all-zero layer; clipped to :data:`SCALE_EXP_RANGE`."""
    if not peak > 0:
        return 0
    top = HALF_PRECISION_RANGE_LOG2 - 23 + int(bits)
    _, q = math.frexp(float(peak))  # peak = f * 2^q, f in [0.5, 1)
    return int(min(max(top - q, SCALE_EXP_RANGE[0]), SCALE_EXP_RANGE[1]))


@dataclass
class LayerStore:
    """One stored layer: the array to write (float16 or float32), its EXR pixel type, the scale ``2^e`` the
    radiance was multiplied by, and the measured energy-weighted relative errors (dimensionless) of the
    values read back: ``error`` over the whole layer, ``underflow_error`` from values below HALF's normal range."""

    data: np.ndarray
    pixel_type: str
    scale: float
    error: float
    underflow_error: float
    fallback: str | None = None


@dataclass
class StorageStats:
    """Aggregate of :class:`LayerStore` results (for one readable note per scene instead of one per layer)."""

    layers: int = 0
    half: int = 0
    fallbacks: list[str] = field(default_factory=list)
    max_error: float = 0.0
    max_underflow_error: float = 0.0

    def add(self, ls: LayerStore, what: str) -> None:
        self.layers += 1
        self.half += ls.pixel_type == "float16"
        self.max_error = max(self.max_error, ls.error)
        self.max_underflow_error = max(self.max_underflow_error, ls.underflow_error)
        if ls.fallback:
            self.fallbacks.append(f"{what}: {ls.fallback}")

    def summary(self, what: str, storage: Storage) -> str:
        """One line: layers, HALF share, largest errors, FLOAT fallbacks (the first three named)."""
        s = (f"{what}: {self.layers} radiance layers, {self.half} HALF x 2^e ({storage.bits} mantissa bits, "
             f"{storage.compression}); energy-weighted relative error max {self.max_error:.2g}, from values "
             f"below HALF's normal range max {self.max_underflow_error:.2g}")
        if self.fallbacks:
            s += (f"; {len(self.fallbacks)} layer(s) stored FLOAT: " + "; ".join(self.fallbacks[:3])
                  + (" ..." if len(self.fallbacks) > 3 else ""))
        return s


def _energy_error(orig: np.ndarray, back: np.ndarray, total: float, mask: np.ndarray | None = None
                  ) -> tuple[float, float]:
    """``(sum|back - orig| / total, same sum over mask / total)``; float32 differences of nearby values are
    exact (Sterbenz), sums in float64."""
    if total <= 0:
        return 0.0, 0.0
    d = np.abs(back - orig)
    under = float(np.sum(d[mask], dtype=np.float64)) / total if mask is not None else 0.0
    return float(np.sum(d, dtype=np.float64)) / total, under


def store_layer(arr: np.ndarray, storage: str | Storage, what: str = "layer") -> LayerStore:
    """Encode one radiance layer for storage (no I/O): the scale rule of ``docs/corpus-format.md`` section 6.

    Args:
        arr: radiance, any shape (e.g. (C, H, W) or (K, C, h, w)), W sr^-1 m^-2 nm^-1, finite and >= 0.
        storage: a :class:`Storage` or a name of :data:`STORAGES`.
        what: the layer's name for messages.

    HALF: ``stored = half(round_m(arr * 2^e))`` with ``e = scale_exponent(max(arr), m)``; the reader computes
    ``stored / 2^e``. The scale is a power of two, so it changes no mantissa bit: the only errors are the
    rounding to ``bits`` mantissa bits (<= 2^-(bits+1) relative) and, for values below 2^-14 after scaling,
    HALF's subnormal step (measured: ``underflow_error``). When that exceeds
    :data:`HALF_UNDERFLOW_ERROR_FRACTION` (or the exponent had to be clipped) the layer is stored FLOAT with
    scale 1 and the same mantissa rounding.
    """
    st = resolve_storage(storage, "storage")
    x = np.asarray(arr, dtype=np.float32)
    total = float(np.sum(x, dtype=np.float64))
    if st.dtype == "float16":
        peak = float(np.max(x)) if x.size else 0.0
        e = scale_exponent(peak, st.bits)
        scaled = x * np.float32(2.0 ** e)  # exact: power of two (unless float32 over/underflows, checked below)
        if st.mantissa_bits is not None:
            scaled = round_mantissa(scaled, st.bits)
        h = scaled.astype(np.float16)
        back = h.astype(np.float32) / np.float32(2.0 ** e)
        err, under = _energy_error(x, back, total, scaled < HALF_MIN_NORMAL)
        reason = None
        if peak > 0 and not HALF_MIN_NORMAL <= peak * 2.0 ** e <= HALF_MAX:
            reason = f"peak {peak:.3g} cannot be scaled into HALF's range by 2^{e}"
        elif not math.isfinite(err) or under > st.max_underflow_error:
            reason = (f"HALF x 2^{e} would change the radiance by {under:.2g} (energy-weighted, values below "
                      f"HALF's normal range) > {st.max_underflow_error:.2g}")
        if reason is None:
            return LayerStore(np.ascontiguousarray(h), "float16", float(2.0 ** e), err, under)
        log.debug("%s: %s: stored FLOAT", what, reason)
        fb = round_mantissa(x, st.bits) if st.mantissa_bits is not None else np.ascontiguousarray(x)
        return LayerStore(fb, "float32", 1.0, _energy_error(x, fb, total)[0], 0.0, reason)
    out = round_mantissa(x, st.bits) if st.mantissa_bits is not None else np.ascontiguousarray(x)
    return LayerStore(out, "float32", 1.0, _energy_error(x, out, total)[0] if st.mantissa_bits else 0.0, 0.0)


def scale_attr(window: str | None) -> str:
    """Header attribute holding a layer's scale 2^e: ``lfmbench_scale_short`` / ``lfmbench_scale_long`` for the
    windows of a static part, ``lfmbench_scale`` (``window=None``) for a light part."""
    if window is None:
        return ATTR["scale"]
    if window not in STATIC_WINDOWS:
        raise ValueError(f"window must be one of {STATIC_WINDOWS} or None, got {window!r}")
    return f"{ATTR['scale']}_{window}"


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
            window, W sr^-1 m^-2 nm^-1, finite and >= 0.
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
    if set(windows) != set(STATIC_WINDOWS):
        raise ValueError(f"{what}: static windows must be exactly {STATIC_WINDOWS}, got {sorted(windows)}")
    shape = None
    for w in STATIC_WINDOWS:
        a = _check_radiance(windows[w], f"{what} [{w}]")
        if a.ndim != 3 or a.shape[0] != len(bands_nm):
            raise ValueError(f"{what} [{w}]: expected shape (C={len(bands_nm)}, H, W), got {a.shape}")
        if shape is not None and a.shape != shape:
            raise ValueError(f"{what}: short {shape} and long {a.shape} shapes differ")
        shape = a.shape
    _, height, width = shape
    channels = {}
    stored = set()
    header = _base_header(width, height, compression=st.compression)
    header.update(attrs or {})
    for w in STATIC_WINDOWS:
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


def encode_lights_exr(lights: Sequence[tuple[int, Sequence[int], np.ndarray]], bands_nm: Sequence[float],
                      bins: int, height: int, width: int, *, dtype: str | Storage = DEFAULT_STORAGE,
                      attrs: Mapping[str, Any] | None = None, what: str = "flickering group",
                      notes: list[str] | None = None, stats: StorageStats | None = None) -> bytes:
    """Encode a flickering group as a multi-part EXR: one part ``light<id>`` per light, sparse data windows.

    Args:
        lights: ``[(light_id, (y0, x0, y1, x1), bins_array)]`` with ``bins_array`` of shape (K, C, h, w),
            h = y1 - y0, w = x1 - x0, spectral radiance W sr^-1 m^-2 nm^-1 time-averaged over each bin with the
            light at PWM level 1. Boxes are half-open pixel ranges inside the H x W image.
        bands_nm: the C band centres (nm).
        bins: K, the number of time bins.
        height, width: full image size H, W (the display window).
        dtype: storage as in :func:`encode_static_exr`; each light (K x C bins) is one layer with its own
            scale, attribute ``lfmbench_scale`` of its part.
        notes, stats: as in :func:`encode_static_exr`.

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
        ls = store_layer(a, st, pw)
        _note_layer(ls, pw, notes, stats)
        channels = {names[k][c]: ls.data[k, c] for k in range(bins) for c in range(len(bands_nm))}
        header = _base_header(width, height, (y0, x0, y1, x1), st.compression)
        header.update(attrs or {})
        header.update({ATTR["kind"]: "lights", ATTR["light"]: lid, ATTR["bins"]: int(bins),
                       ATTR["units"]: RADIANCE_UNIT, ATTR["stored"]: ls.pixel_type, scale_attr(None): ls.scale,
                       ATTR["mantissa"]: st.bits})
        parts.append((lid, header, channels))
    if not parts:
        header = _base_header(width, height, (0, 0, 1, 1), st.compression)
        header.update(attrs or {})
        header.update({ATTR["kind"]: "lights", ATTR["nparts"]: 0, ATTR["bins"]: int(bins)})
        return _encode([exr.Part(header, {EMPTY_PART: np.zeros((1, 1), np.float32)}, EMPTY_PART)], what)
    out = []
    for lid, header, channels in sorted(parts, key=lambda p: p[0]):
        header[ATTR["nparts"]] = len(parts)
        out.append(exr.Part(header, channels, f"light{lid}"))
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


# ------------------------------------------------------------------------------------------ EXR decoding
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


def read_exr(path: str | os.PathLike, *, header_only: bool = False) -> list[ExrPart]:
    """Decode every part of an EXR file (OpenEXR 3.x reads whole files: all parts, all channels).

    Raises :class:`CorpusFileError` naming ``path`` when it is missing, not an EXR, or truncated (a part whose
    pixels cannot be read, detected by comparing with the part count of the header).
    """
    exr = _exr()
    path = Path(path)
    if not path.is_file():
        raise CorpusFileError(f"EXR file is missing: {path}")
    try:
        hdr = exr.File(str(path), header_only=True)
        n_parts = len(hdr.parts)
        f = hdr if header_only else exr.File(str(path), separate_channels=True)
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
    ``docs/corpus-format.md``): header attribute :func:`scale_attr` of ``window`` (``None``: a light part),
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


# ------------------------------------------------------------------------------------------------ splits
def make_splits(scene_ids: Iterable[str], seed: int,
                fractions: Sequence[float] = (0.6, 0.2, 0.2)) -> dict[str, list[str]]:
    """Deterministic train / val / test split of scene ids.

    The sorted ids are shuffled with ``numpy.random.default_rng(seed)``; test gets ``round(f_test * n)``
    scenes but at least one, val ``round(f_val * n)`` (only while train keeps >= 1 scene), train the rest.

    Args:
        scene_ids: the ids (order does not matter).
        seed: integer seed.
        fractions: (train, val, test), each >= 0, summing to 1.
    """
    fr = [float(f) for f in fractions]
    if len(fr) != 3 or any(f < 0 for f in fr) or abs(sum(fr) - 1) > 1e-9:
        raise ValueError(f"fractions must be three numbers >= 0 summing to 1, got {fractions!r}")
    ids = sorted(set(scene_ids))
    n = len(ids)
    order = np.random.default_rng(seed).permutation(n)
    ids = [ids[i] for i in order]
    n_test = min(n, max(1, round(fr[2] * n))) if n else 0
    n_val = min(round(fr[1] * n), max(0, n - n_test - 1))
    test, val, train = ids[:n_test], ids[n_test:n_test + n_val], ids[n_test + n_val:]
    return {"train": sorted(train), "val": sorted(val), "test": sorted(test)}


# ------------------------------------------------------------------------------------------------- meta
_META_REQUIRED = ("scene_id", "width", "height", "bands_nm", "fps", "frames", "timing", "groups")
_TIMING_REQUIRED = ("short_exposure_s", "long_exposure_s", "capture_window_s")


def validate_meta(meta: Mapping[str, Any], where: str = "meta.json") -> None:
    """Check a scene's ``meta.json`` content; raise ``ValueError`` naming ``where`` and the field.

    Checks: required fields; image size > 0; bands strictly increasing and positive (nm); fps > 0; frames >= 1;
    ``0 < short_exposure_s <= long_exposure_s <= 1/fps`` (an exposure cannot be longer than the frame time);
    ``capture_window_s == long_exposure_s + readout_s`` (the bins must cover both windows; the capture window
    may exceed 1/fps with a rolling shutter, since row i of frame n+1 starts at t_(n+1) + i * line_time);
    bins >= 1 for per-light groups; camera ``speed_mps >= 0``; groups known by name with a boolean
    ``flicker``; lights with unique integer ids >= 0 whose group exists.
    """
    if not isinstance(meta, Mapping):
        raise ValueError(f"{where}: must be a JSON object")
    for k in _META_REQUIRED:
        if k not in meta:
            raise ValueError(f"{where}: missing field {k!r}")
    why = _scene_id_error(meta["scene_id"])
    if why is not None:
        raise ValueError(f"{where}: field 'scene_id': {why}")
    for k in ("width", "height", "frames"):
        v = meta[k]
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ValueError(f"{where}: field {k!r} must be an integer >= 1, got {v!r}")
    bands = meta["bands_nm"]
    if not isinstance(bands, list) or not bands:
        raise ValueError(f"{where}: field 'bands_nm' must be a non-empty list of wavelengths (nm)")
    try:
        b = np.asarray(bands, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: field 'bands_nm' must hold numbers (nm), got {bands!r}") from None
    if not np.isfinite(b).all() or (b <= 0).any() or (np.diff(b) <= 0).any():
        raise ValueError(f"{where}: field 'bands_nm' must be positive and strictly increasing, got {bands!r}")
    fps = check.get_number(meta, "fps", where, lo=0.0, lo_open=True)
    frame_time = 1.0 / fps
    t = meta["timing"]
    if not isinstance(t, Mapping):
        raise ValueError(f"{where}: field 'timing' must be an object")
    tw = f"{where} timing"
    for k in _TIMING_REQUIRED:
        check.get_number(t, k, where, "timing.", lo=0.0, lo_open=True)
    ts, tl, cw = t["short_exposure_s"], t["long_exposure_s"], t["capture_window_s"]
    readout = check.get_number(t, "readout_s", where, "timing.", lo=0.0, default=0.0)
    tol = TIMING_RTOL * frame_time
    if tl > frame_time + tol:
        raise ValueError(f"{tw}: long_exposure_s = {tl} s is longer than the frame time 1/fps = {frame_time:.6g} s")
    if ts > tl + tol:
        raise ValueError(f"{tw}: short_exposure_s = {ts} s is longer than long_exposure_s = {tl} s")
    if abs(cw - (tl + readout)) > tol:
        raise ValueError(f"{tw}: capture_window_s = {cw} s must equal long_exposure_s + readout_s = "
                         f"{tl + readout} s so that the time bins cover the exposure windows")
    if "alignment" in t and t["alignment"] != "center":
        raise ValueError(f"{tw}: alignment must be 'center', got {t['alignment']!r}")
    groups = meta["groups"]
    if not isinstance(groups, Mapping) or not groups:
        raise ValueError(f"{where}: field 'groups' must be a non-empty object")
    for name, g in groups.items():
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", str(name)) or name == "aux":
            raise ValueError(f"{where}: group name {name!r} must be an identifier other than 'aux'")
        if not isinstance(g, Mapping) or not isinstance(g.get("flicker"), bool):
            raise ValueError(f"{where}: groups[{name!r}] must be an object with a boolean 'flicker'")
        if "bins" in g and (isinstance(g["bins"], bool) or not isinstance(g["bins"], int) or g["bins"] < 0):
            raise ValueError(f"{where}: groups[{name!r}].bins must be an integer >= 0, got {g['bins']!r}")
        if g["flicker"] and "bins" not in g:
            kb = t.get("bins")
            if isinstance(kb, bool) or not isinstance(kb, int) or kb < 1:
                raise ValueError(f"{tw}: field 'bins' must be an integer >= 1 for flickering group {name!r}, "
                                 f"got {kb!r}")
    cam = meta.get("camera", {}) or {}
    if not isinstance(cam, Mapping):
        raise ValueError(f"{where}: field 'camera' must be an object, got {cam!r}")
    if cam.get("speed_mps") is not None:
        check.get_number(cam, "speed_mps", where, "camera.", lo=0.0)
    ids = set()
    lights = meta.get("lights", [])
    if not isinstance(lights, list):
        raise ValueError(f"{where}: field 'lights' must be a list of objects, got {lights!r}")
    for i, light in enumerate(lights):
        if not isinstance(light, Mapping):
            raise ValueError(f"{where}: lights[{i}] must be an object with 'id' and 'group', got {light!r}")
        lid = light.get("id")
        if isinstance(lid, bool) or not isinstance(lid, int) or lid < 0 or lid in ids:
            raise ValueError(f"{where}: lights[{i}].id must be a unique integer >= 0, got {lid!r}")
        ids.add(lid)
        if light.get("group") not in groups:
            raise ValueError(f"{where}: lights[{i}].group {light.get('group')!r} is not in groups")
        _check_light_fields(light, f"lights[{i}]", where, meta["frames"], meta["height"], meta["width"])


#: Light kinds the renderer writes (``render_tools.scene.LIGHT_KINDS``); other writers may use other names.
LIGHT_KINDS = ("headlight", "streetlight", "tail", "brake", "indicator", "billboard", "signal")
#: Spectrum models the renderer writes (``render_tools.spectra.SPECTRUM_MODELS``) and their fields.
SPECTRUM_MODELS = {"led": ("peak_nm", "fwhm_nm"), "light_source": ("name",), "illuminant": ("name",),
                   "daylight": ("cct_k",)}


def _check_light_fields(light: Mapping[str, Any], name: str, where: str, frames: int, H: int, W: int) -> None:
    """The optional, informative fields of a ``meta.json`` light (``docs/corpus-format.md`` section 4):
    ``kind`` non-empty str, ``instance`` int >= -1, ``luminance_cd_m2`` finite number >= 0 (cd/m^2),
    ``spectrum`` object with a str ``model``, ``bbox`` list of ``frames`` entries, each null or a half-open
    ``[y0, x0, y1, x1]`` of ints with ``0 <= y0 < y1 <= H`` and ``0 <= x0 < x1 <= W`` (px)."""
    if "kind" in light and (not isinstance(light["kind"], str) or not light["kind"]):
        check.fail(f"{name}.kind", f"must be a non-empty string, got {light['kind']!r}", where)
    if "instance" in light:
        check.check_integer(light["instance"], f"{name}.instance", where, lo=-1)
    if "luminance_cd_m2" in light:
        check.check_number(light["luminance_cd_m2"], f"{name}.luminance_cd_m2", where, lo=0.0)
    if "spectrum" in light:
        sp = light["spectrum"]
        if not isinstance(sp, Mapping) or not isinstance(sp.get("model"), str):
            check.fail(f"{name}.spectrum", f"must be an object with a string 'model', got {sp!r}", where)
    if "bbox" in light:
        bb = light["bbox"]
        if not isinstance(bb, list) or len(bb) != frames:
            check.fail(f"{name}.bbox", f"must be a list of {frames} boxes (one per frame, null = not visible), "
                       f"got {bb!r}", where)
        for n, b in enumerate(bb):
            if b is None:
                continue
            ok = (isinstance(b, list) and len(b) == 4
                  and all(isinstance(v, int) and not isinstance(v, bool) for v in b)
                  and 0 <= b[0] < b[2] <= H and 0 <= b[1] < b[3] <= W)
            if not ok:
                check.fail(f"{name}.bbox[{n}]", f"must be null or [y0, x0, y1, x1] integers with 0 <= y0 < y1 <= "
                           f"{H} and 0 <= x0 < x1 <= {W} (half-open, px), got {b!r}", where)


def _check_meta_storage(meta: Mapping[str, Any], path: Path | str) -> None:
    """Check the optional ``storage`` entry of a ``meta.json`` (format version 2); raise naming ``path``."""
    sto = meta.get("storage")
    if sto is None:
        return
    if not isinstance(sto, Mapping):
        raise CorpusFileError(f"{path}: field 'storage' must be an object")
    _check_version(sto.get("format_version"), f"{path} storage.format_version")


# ----------------------------------------------------------------------------------------------- reader
def _empty_manifest() -> dict:
    return {"format": FORMAT_NAME, "version": FORMAT_VERSION, "scenes": [], "files": {}}


def _check_version(v: Any, where: str) -> int:
    """``v`` as a readable format version; ``CorpusFileError`` naming ``where`` (and the version) otherwise."""
    if isinstance(v, int) and not isinstance(v, bool) and v > FORMAT_VERSION:
        raise CorpusFileError(f"{where}: corpus format version {v} is newer than this lfmbench reads "
                              f"(versions {', '.join(map(str, READABLE_VERSIONS))}); upgrade lfmbench")
    if v not in READABLE_VERSIONS or isinstance(v, bool):
        raise CorpusFileError(f"{where}: unsupported corpus format version {v!r} (this lfmbench reads versions "
                              f"{', '.join(map(str, READABLE_VERSIONS))})")
    return int(v)


def _check_manifest(man: Any, path: Path, *, entries: bool = True) -> dict:
    """The manifest if its format, version and (``entries``) every scene id and file entry are valid; else
    ``CorpusFileError`` naming ``path`` and the first bad entry (:func:`manifest_entry_errors`)."""
    if not isinstance(man, dict) or man.get("format") != FORMAT_NAME:
        raise CorpusFileError(f"{path}: not an lfmbench corpus manifest (format must be {FORMAT_NAME!r})")
    _check_version(man.get("version"), str(path))
    if not isinstance(man.get("scenes"), list) or not isinstance(man.get("files"), dict):
        raise CorpusFileError(f"{path}: 'scenes' must be a list and 'files' an object")
    if entries:
        bad = manifest_entry_errors(man, path)
        if bad:
            more = f" (and {len(bad) - 1} more bad entries)" if len(bad) > 1 else ""
            raise CorpusFileError(bad[0] + more)
    return man


def _scene_id_error(scene_id: Any) -> str | None:
    why = scene_id_error(scene_id)
    return None if why is None else f"scene_id {why}"


def _file_entry_error(rel: Any, digest: Any, scenes: set) -> str | None:
    """Why a manifest file entry is refused (None if it is fine): a relative POSIX path
    ``scenes/<scene id>/...`` without ``.``/``..`` components, of a listed scene, with a SHA-256 hex digest."""
    if not isinstance(rel, str) or not rel:
        return "file path must be a non-empty string"
    if rel.startswith("/") or "\\" in rel or re.match(r"[A-Za-z]:", rel):
        return "absolute file path (must be relative to the corpus root)"
    parts = rel.split("/")
    if any(p in ("", ".", "..") for p in parts):
        return "file path with an empty, '.' or '..' component (must stay inside the corpus root)"
    if len(parts) < 3 or parts[0] != SCENES_DIR or _scene_id_error(parts[1]) is not None:
        return f"file path must lie under {SCENES_DIR}/<scene id>/"
    if parts[1] not in scenes:
        return f"file of scene {parts[1]!r}, which is not in 'scenes'"
    if not isinstance(digest, str) or not re.fullmatch(r"[0-9a-f]{64}", digest):
        return "SHA-256 must be 64 lowercase hex digits"
    return None


def manifest_entry_errors(man: Mapping[str, Any], path: Path | str) -> list[str]:
    """Errors (each naming ``path`` and the entry) for manifest scene ids that are not safe directory names
    (:func:`check_scene_id`, the rule used when writing) and file entries that could leave the corpus root
    (absolute, ``..``) or are malformed. Used by :class:`Corpus` (raises on the first) and
    :func:`validate_corpus` (reports all)."""
    out = []
    for sid in man["scenes"]:
        why = _scene_id_error(sid)
        if why is not None:
            out.append(f"{path}: scene entry {sid!r} refused: {why}")
    scenes = {s for s in man["scenes"] if isinstance(s, str)}
    for rel, digest in man["files"].items():
        why = _file_entry_error(rel, digest, scenes)
        if why is not None:
            out.append(f"{path}: file entry {rel!r} refused: {why}")
    return out


def inside_root(root: Path, rel: str, what: str) -> Path:
    """``root / rel`` resolved (symbolic links followed); ``CorpusFileError`` naming ``what`` and ``rel`` when it
    leaves the resolved corpus root."""
    base = Path(root).resolve()
    p = (base / rel).resolve()
    if p != base and base not in p.parents:
        raise CorpusFileError(f"{what}: entry {rel!r} resolves to {p}, outside the corpus root {base}")
    return p


def check_splits(sp: Any, path: Path | str) -> dict[str, list[str]]:
    """``splits.json`` content checked: an object whose ``train``/``val``/``test`` are lists of scene ids
    (:func:`check_scene_id`); ``CorpusFileError`` naming ``path`` and the entry otherwise."""
    if not isinstance(sp, dict):
        raise CorpusFileError(f"{path}: must be a JSON object {{\"train\": [...], \"val\": [...], \"test\": "
                              f"[...]}}, got a {type(sp).__name__}")
    for k, ids in sp.items():
        if not isinstance(ids, list):
            raise CorpusFileError(f"{path}: split {k!r} must be a list of scene ids, got a {type(ids).__name__}")
        for sid in ids:
            why = _scene_id_error(sid)
            if why is not None:
                raise CorpusFileError(f"{path}: split {k!r} entry {sid!r} refused: {why}")
    return sp


class Corpus:
    """Read an lfmbench corpus (see ``docs/corpus-format.md``).

    Files are decoded only when a method asks for them; the last ``cache_size`` decoded EXR files are kept in
    memory (so ``read_static(..., "short")`` then ``(..., "long")`` decodes once). OpenEXR 3.x decodes whole
    files, so a call reads every channel of that one frame/group file, never other groups or frames.

    Args:
        root: corpus directory (holds ``manifest.json``).
        check_values: check every array returned for NaN / inf / negative radiance (cheap min/max).
        cache_size: number of decoded EXR files kept (>= 0).

    Example:
        >>> c = Corpus("demo_out/corpus")                                        # doctest: +SKIP
        >>> L = c.read_static(c.scenes[0], 0, "headlights", "short")             # doctest: +SKIP
        >>> L.shape                                                              # doctest: +SKIP
        (C, H, W)
    """

    def __init__(self, root: str | os.PathLike, *, check_values: bool = True, cache_size: int = 4) -> None:
        self.root = Path(root)
        mpath = self.root / MANIFEST_NAME
        if not mpath.is_file():
            raise CorpusNotFoundError(f"no lfmbench corpus at {self.root} ({MANIFEST_NAME} missing): make one with "
                                      "`lfmbench render --out DIR` or `lfmbench import-isetlfm SRC DIR`")
        self.manifest = _check_manifest(_load_json(mpath, "manifest"), mpath)
        self.check_values = bool(check_values)
        if cache_size < 0:
            raise ValueError(f"cache_size must be >= 0, got {cache_size}")
        self._cache_size = int(cache_size)
        self._cache: OrderedDict[Path, list[ExrPart]] = OrderedDict()
        self._meta: dict[str, dict] = {}
        self._inside: set[str] = set()

    # -- index
    @property
    def scenes(self) -> list[str]:
        """Scene ids recorded as complete in the manifest (sorted)."""
        return sorted(self.manifest["scenes"])

    @property
    def splits(self) -> dict[str, list[str]]:
        """``splits.json`` content ``{"train": [...], "val": [...], "test": [...]}``."""
        path = self.root / SPLITS_NAME
        return check_splits(_load_json(path, "splits file"), path)

    def _scene_dir(self, scene_id: str) -> Path:
        if scene_id not in self.manifest["scenes"]:
            raise KeyError(f"scene {scene_id!r} is not in corpus {self.root} (see Corpus.scenes)")
        if scene_id not in self._inside:  # ids were checked with the manifest; symbolic links are resolved here
            inside_root(self.root, f"{SCENES_DIR}/{scene_id}", str(self.root / MANIFEST_NAME))
            self._inside.add(scene_id)
        return self.root / SCENES_DIR / scene_id

    def meta(self, scene_id: str) -> dict:
        """The scene's ``meta.json`` (camera, timing, bands, groups, lights)."""
        if scene_id not in self._meta:
            p = self._scene_dir(scene_id) / "meta.json"
            m = _load_json(p, "scene metadata")
            validate_meta(m, str(p))
            _check_meta_storage(m, p)
            self._meta[scene_id] = m
        return self._meta[scene_id]

    def scene(self, scene_id: str) -> dict:
        """The editable scene description ``scene.json`` the scene was rendered from."""
        return _load_json(self._scene_dir(scene_id) / "scene.json", "scene description")

    def path(self, scene_id: str, frame: int, group: str) -> Path:
        """Path of the EXR of ``group`` (or ``"aux"``) in frame ``frame``."""
        return self._scene_dir(scene_id) / frame_dir(frame) / f"{group}.exr"

    def groups(self, scene_id: str) -> dict[str, dict]:
        """``meta.json`` groups: ``{name: {"flicker": bool, ...}}``."""
        return self.meta(scene_id)["groups"]

    # -- decoding
    def _parts(self, path: Path) -> list[ExrPart]:
        if path in self._cache:
            self._cache.move_to_end(path)
            return self._cache[path]
        parts = read_exr(path)
        if self._cache_size:
            self._cache[path] = parts
            while len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        return parts

    def _frame_group(self, scene_id: str, frame: int, group: str) -> tuple[dict, Path]:
        m = self.meta(scene_id)
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or not 0 <= frame < m["frames"]:
            raise ValueError(f"frame must be an integer in [0, {m['frames']}) for scene {scene_id!r}, got {frame!r}")
        if group not in m["groups"]:
            raise ValueError(f"group {group!r} is not in scene {scene_id!r} (groups: {sorted(m['groups'])})")
        return m, self.path(scene_id, frame, group)

    @staticmethod
    def _band_list(m: dict, bands: Sequence[float] | None) -> list[float]:
        all_b = [float(b) for b in m["bands_nm"]]
        if bands is None:
            return all_b
        out = []
        for b in bands:
            if not any(abs(float(b) - a) < 1e-6 for a in all_b):
                raise ValueError(f"bands: {b!r} nm is not a band of this scene ({all_b[0]:g}..{all_b[-1]:g} nm)")
            out.append(float(b))
        return out

    def read_static(self, scene_id: str, frame: int, group: str, window: str,
                    bands: Sequence[float] | None = None) -> np.ndarray:
        """Time-averaged spectral radiance of a statically stored group over one exposure window.

        Args:
            scene_id, frame, group: which file.
            window: ``"short"`` (LPD) or ``"long"`` (SPD) exposure window.
            bands: band centres (nm) to return, default all of ``meta["bands_nm"]``.

        Returns:
            ndarray (C, H, W) float32, W sr^-1 m^-2 nm^-1.
        """
        m, path = self._frame_group(scene_id, frame, group)
        if group_storage(m, group) != "static":
            raise ValueError(f"group {group!r} of scene {scene_id!r} is stored per light in time bins: use "
                             "read_light_bins")
        names = static_channels(window, self._band_list(m, bands))
        parts = self._parts(path)
        arr = _stack(parts[0], names, path)
        scale = layer_scale(parts[0], window, path)
        if scale != 1.0:
            arr /= np.float32(scale)  # exact: a power of two
        if arr.shape[1:] != (m["height"], m["width"]):
            raise CorpusChannelError(f"EXR file {path}: image is {arr.shape[1:]}, meta.json says "
                                     f"({m['height']}, {m['width']})")
        if self.check_values:
            _check_values(arr, path, f"[{window}]")
        return arr

    def read_light_bins(self, scene_id: str, frame: int, group: str, bands: Sequence[float] | None = None
                        ) -> list[tuple[int, tuple[int, int, int, int], np.ndarray]]:
        """Per-light time bins of a flickering group.

        Returns:
            ``[(light_id, (y0, x0, y1, x1), ndarray (K, C, h, w) float32)]`` sorted by light id; boxes are
            half-open pixel ranges; values are spectral radiance (W sr^-1 m^-2 nm^-1) averaged over each of the
            K bins of the capture window with the light at PWM level 1. Empty list when no light is visible.
        """
        m, path = self._frame_group(scene_id, frame, group)
        if group_storage(m, group) != "lights":
            raise ValueError(f"group {group!r} of scene {scene_id!r} is stored as short/long windows "
                             f"(bins 0): use read_static")
        k = _group_bins(m, group)
        bl = self._band_list(m, bands)
        names = [n for row in bin_channels(k, bl) for n in row]
        out = []
        for p in self._parts(path):
            if p.name == EMPTY_PART:
                continue
            mt = re.fullmatch(r"light(\d+)", p.name)
            if mt is None:
                raise CorpusChannelError(f"EXR file {path}: unexpected part {p.name!r} (want light<id>)")
            arr = _stack(p, names, path).reshape(k, len(bl), p.window[2] - p.window[0], p.window[3] - p.window[1])
            scale = layer_scale(p, None, path)
            if scale != 1.0:
                arr /= np.float32(scale)  # exact: a power of two
            if self.check_values:
                _check_values(arr, path, f"part {p.name!r}")
            out.append((int(mt.group(1)), p.window, arr))
        return sorted(out, key=lambda t: t[0])

    def read_aux(self, scene_id: str, frame: int, names: Sequence[str] | None = None) -> dict[str, np.ndarray]:
        """Aux channels of a frame: ``{name: (H, W) float32}``; depth in m (+inf: no surface), ids -1 = none.

        Args:
            names: subset of :data:`AUX_CHANNELS` (default all).
        """
        m = self.meta(scene_id)
        if not 0 <= int(frame) < m["frames"]:
            raise ValueError(f"frame must be in [0, {m['frames']}) for scene {scene_id!r}, got {frame!r}")
        names = list(AUX_CHANNELS if names is None else names)
        bad = [n for n in names if n not in AUX_CHANNELS]
        if bad:
            raise ValueError(f"names: unknown aux channels {bad} (known: {AUX_CHANNELS})")
        path = self.path(scene_id, frame, "aux")
        part = self._parts(path)[0]
        arr = _stack(part, names, path)
        if self.check_values:
            for n, a in zip(names, arr):
                _check_aux(n, a, f"EXR file {path}")
        return {n: a for n, a in zip(names, arr)}


# ----------------------------------------------------------------------------------------------- writer
class CorpusWriter:
    """Write an lfmbench corpus atomically, scene by scene.

    Every file goes through :func:`atomic_write_bytes` (temp file in the same directory + :func:`os.replace`);
    a scene enters ``manifest.json`` (rewritten atomically) only after all its files are on disk, so a crash or
    Ctrl-C leaves the corpus valid: the unfinished scene is simply absent and is redone on resume. Stray
    temporary files of a killed run are removed when a writer opens the corpus.

    Args:
        root: corpus directory (created if needed).
        dtype: storage of the radiance layers: a name of :data:`STORAGES` or a :class:`Storage`. Default
            ``"compact"`` (HALF x per-layer 2^e, mantissas rounded to 5 bits: <= 2^-6 ~ 1.6 % relative per value,
            PIZ); ``"float16"`` (HALF x 2^e, 10 bits, <= 2^-11); ``"float32"`` (lossless FLOAT, as version 1).
        render: optional dict of the options the corpus is rendered with, stored in the manifest as
            ``"render"``; re-opening with different options raises ``ValueError`` (resume safety).
    """

    def __init__(self, root: str | os.PathLike, *, dtype: str | Storage = DEFAULT_STORAGE,
                 render: Mapping[str, Any] | None = None) -> None:
        self.root = Path(root)
        self.storage = resolve_storage(dtype)
        self.dtype = dtype
        if self.root.exists() and not self.root.is_dir():
            raise ValueError(f"corpus root {self.root} exists and is not a directory")
        self.root.mkdir(parents=True, exist_ok=True)
        mpath = self.root / MANIFEST_NAME
        if mpath.exists():
            self.manifest = _check_manifest(_load_json(mpath, "manifest"), mpath)
            # version-2 readers read version-1 files: new scenes may join an old corpus, which becomes version 2
            self.manifest["version"] = FORMAT_VERSION
        else:
            self.manifest = _empty_manifest()
            self.write_manifest()  # an empty corpus is a valid corpus
        if render is not None:
            render = json.loads(json.dumps(dict(render), default=json_default))
            old = self.manifest.get("render")
            if old is not None and old != render:
                diff = sorted(k for k in set(old) | set(render) if old.get(k) != render.get(k))
                raise ValueError(f"corpus {self.root} was rendered with different options ({', '.join(diff)}); "
                                 "use a new --out directory or the original options to resume")
            if old is None:
                self.manifest["render"] = render
                self.write_manifest()
        self.notes: list[str] = []
        self.cleanup_temp()

    def cleanup_temp(self) -> int:
        """Remove temporary files left by an interrupted run; returns how many were removed."""
        n = 0
        for p in self.root.rglob(TMP_PREFIX + "*"):
            with contextlib.suppress(OSError):
                p.unlink()
                n += 1
        return n

    @property
    def scenes(self) -> list[str]:
        return sorted(self.manifest["scenes"])

    def _rel(self, path: Path) -> str:
        return path.relative_to(self.root).as_posix()

    def is_complete(self, scene_id: str, *, verify: bool = True) -> bool:
        """True when the scene is in the manifest and (``verify``) all its files exist with their SHA-256."""
        if scene_id not in self.manifest["scenes"]:
            return False
        prefix = f"{SCENES_DIR}/{scene_id}/"
        files = {k: v for k, v in self.manifest["files"].items() if k.startswith(prefix)}
        if not files:
            return False
        if not verify:
            return True
        for rel, digest in files.items():
            p = self.root / rel
            if not p.is_file() or sha256_file(p) != digest:
                return False
        return True

    def write_manifest(self) -> None:
        """Rewrite ``manifest.json`` atomically (scenes and files sorted)."""
        self.manifest["scenes"] = sorted(set(self.manifest["scenes"]))
        self.manifest["files"] = dict(sorted(self.manifest["files"].items()))
        atomic_write_json(self.root / MANIFEST_NAME, self.manifest)

    def encode_scene(self, scene_id: str, scene: Mapping[str, Any], meta: Mapping[str, Any],
                     frames: Iterable[Mapping[str, Any]]) -> Iterator[tuple[str, bytes]]:
        """:func:`encode_scene` with this writer's storage (HALF -> FLOAT fallback notes go to ``self.notes``)."""
        return encode_scene(scene_id, scene, meta, frames, dtype=self.storage, notes=self.notes)

    def write_files(self, files: Iterable[tuple[str, bytes]]) -> dict[str, str]:
        """:func:`write_files` under this corpus root."""
        return write_files(self.root, files)

    def commit_scene(self, scene_id: str, hashes: Mapping[str, str]) -> None:
        """Record a finished scene and its files' SHA-256 in the manifest (written atomically)."""
        check_scene_id(scene_id)
        prefix = f"{SCENES_DIR}/{scene_id}/"
        if not hashes or any(not k.startswith(prefix) for k in hashes):
            raise ValueError(f"commit_scene: file paths must lie under {prefix}")
        self.manifest["files"] = {k: v for k, v in self.manifest["files"].items() if not k.startswith(prefix)}
        self.manifest["files"].update(hashes)
        self.manifest["scenes"] = sorted(set(self.manifest["scenes"]) | {scene_id})
        self.write_manifest()

    def forget_scene(self, scene_id: str) -> None:
        """Drop a scene from the manifest (before re-rendering it); its files stay until overwritten."""
        prefix = f"{SCENES_DIR}/{scene_id}/"
        if scene_id in self.manifest["scenes"]:
            self.manifest["scenes"].remove(scene_id)
            self.manifest["files"] = {k: v for k, v in self.manifest["files"].items() if not k.startswith(prefix)}
            self.write_manifest()

    def write_scene(self, scene_id: str, scene: Mapping[str, Any], meta: Mapping[str, Any],
                    frames: Iterable[Mapping[str, Any]]) -> dict[str, str]:
        """Encode, write and commit one scene (files as they are rendered, manifest last); returns the hashes.

        Removes files of the scene that a previous, different run left and that this run did not write
        (:func:`prune_scene_dir`).
        """
        self.forget_scene(scene_id)
        hashes = self.write_files(self.encode_scene(scene_id, scene, meta, frames))
        prune_scene_dir(self.root, scene_id, hashes)
        self.commit_scene(scene_id, hashes)
        return hashes

    def write_splits(self, seed: int, fractions: Sequence[float] = (0.6, 0.2, 0.2)) -> dict[str, list[str]]:
        """Write ``splits.json`` from the manifest's scenes (see :func:`make_splits`)."""
        splits = make_splits(self.manifest["scenes"], seed, fractions)
        atomic_write_json(self.root / SPLITS_NAME, splits)
        return splits


def prune_scene_dir(root: str | os.PathLike, scene_id: str, keep: Iterable[str]) -> list[str]:
    """Delete files under ``scenes/<scene_id>/`` whose relpath is not in ``keep`` (stale files of an earlier,
    different render of the scene); returns the removed relpaths. Empty frame directories are removed too."""
    root = Path(root)
    sdir = root / SCENES_DIR / scene_id
    keep = set(keep)
    removed = []
    if sdir.is_dir():
        for p in sorted(sdir.rglob("*"), reverse=True):
            rel = p.relative_to(root).as_posix()
            if p.is_file() and rel not in keep and not p.name.startswith(TMP_PREFIX):
                p.unlink()
                removed.append(rel)
            elif p.is_dir() and not any(p.iterdir()):
                p.rmdir()
    return removed


def _json_bytes(obj: Any) -> bytes:
    return (json.dumps(obj, indent=1, allow_nan=False, default=json_default) + "\n").encode("utf-8")


def _attrs(scene_id: str, frame: int, group: str) -> dict:
    return {ATTR["scene"]: scene_id, ATTR["frame"]: int(frame), ATTR["group"]: group}


def encode_scene(scene_id: str, scene: Mapping[str, Any], meta: Mapping[str, Any],
                 frames: Iterable[Mapping[str, Any]], *, dtype: str | Storage = DEFAULT_STORAGE,
                 notes: list[str] | None = None) -> Iterator[tuple[str, bytes]]:
    """Yield ``(relpath, bytes)`` for every file of a scene, frame by frame (checks shapes vs ``meta``).

    Pure encoding (no disk access), so that render workers can call it; ``dtype`` (the storage) as in
    :class:`CorpusWriter`. ``meta.json`` gets a ``storage`` entry (format version, pixel type, compression,
    mantissa bits). ``notes`` receives at most one message per scene: the layers stored FLOAT instead of HALF
    (if any) with the largest measured errors; the error summary of every scene is logged at INFO level.

    ``frames`` yields the renderer's frame dicts (``render_tools.render.render_frames``)::

        {"frame": n, "static": {group: {"short": (C,H,W), "long": (C,H,W)}},
         "lights": {group: [(light_id, (y0,x0,y1,x1), (K,C,h,w))]},
         "aux": {"depth.Z": (H,W), "depth.R": (H,W), "mask.instance": (H,W), "mask.light": (H,W)}}
    """
    check_scene_id(scene_id)
    st = resolve_storage(dtype)
    meta = dict(meta)
    if meta.get("scene_id") != scene_id:
        raise ValueError(f"meta.json scene_id {meta.get('scene_id')!r} != scene id {scene_id!r}")
    validate_meta(meta, f"meta.json of scene {scene_id}")
    meta["storage"] = {"format_version": FORMAT_VERSION, **st.to_dict()}
    stats = StorageStats()
    sdir = f"{SCENES_DIR}/{scene_id}"
    yield f"{sdir}/scene.json", _json_bytes(scene)
    yield f"{sdir}/meta.json", _json_bytes(meta)
    bands = meta["bands_nm"]
    H, W = meta["height"], meta["width"]
    seen: list[int] = []
    with_aux: list[int] = []
    for fr in frames:
        n = fr.get("frame")
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 0 <= n < meta["frames"] \
                or n in seen:
            raise ValueError(f"scene {scene_id}: frame index {n!r} is invalid or repeated "
                             f"(meta.json frames = {meta['frames']})")
        seen.append(int(n))
        fdir = f"{sdir}/{frame_dir(n)}"
        static = fr.get("static", {}) or {}
        lights = fr.get("lights", {}) or {}
        got = set(static) | set(lights)
        if got != set(meta["groups"]) or set(static) & set(lights):
            raise ValueError(f"scene {scene_id} frame {n}: groups rendered {sorted(got)} do not match "
                             f"meta.json groups {sorted(meta['groups'])}")
        for g, wins in static.items():
            what = f"{fdir}/{g}.exr"
            if group_storage(meta, g) != "static":
                raise ValueError(f"{what}: group {g!r} is flickering with bins > 0 in meta.json but was "
                                 "rendered as static windows")
            data = encode_static_exr(wins, bands, dtype=st, what=what, notes=notes, stats=stats,
                                     attrs=_attrs(scene_id, n, g))
            if (H, W) != tuple(np.asarray(wins["short"]).shape[1:]):
                raise ValueError(f"{what}: image size {np.asarray(wins['short']).shape[1:]} != meta.json "
                                 f"({H}, {W})")
            yield what, data
        for g, ls in lights.items():
            what = f"{fdir}/{g}.exr"
            if group_storage(meta, g) != "lights":
                raise ValueError(f"{what}: group {g!r} is static in meta.json but was rendered per light")
            known = {lt["id"] for lt in meta.get("lights", []) if lt.get("group") == g}
            bad = [lid for lid, _, _ in ls if int(lid) not in known]
            if bad:
                raise ValueError(f"{what}: light ids {bad} are not lights of group {g!r} in meta.json")
            yield what, encode_lights_exr(ls, bands, _group_bins(meta, g), H, W, dtype=st,
                                          what=what, notes=notes, stats=stats, attrs=_attrs(scene_id, n, g))
        if fr.get("aux"):
            with_aux.append(int(n))
            yield f"{fdir}/aux.exr", encode_aux_exr(fr["aux"], H, W, what=f"{fdir}/aux.exr",
                                                    attrs=_attrs(scene_id, n, "aux"))
    if sorted(seen) != list(range(meta["frames"])):
        raise ValueError(f"scene {scene_id}: got frames {sorted(seen)}, meta.json announces "
                         f"{meta['frames']}")
    if with_aux and len(with_aux) != len(seen):
        raise ValueError(f"scene {scene_id}: aux given for frames {sorted(with_aux)} only (all frames or none)")
    summary = stats.summary(f"scene {scene_id}", st)
    log.info("%s", summary)
    if stats.fallbacks and notes is not None:
        notes.append(summary)


def write_files(root: str | os.PathLike, files: Iterable[tuple[str, bytes]]) -> dict[str, str]:
    """Write ``(relpath, bytes)`` pairs under ``root`` atomically (safe in parallel workers).

    Returns ``{relpath: sha256}``; the manifest is not touched (see :meth:`CorpusWriter.commit_scene`).
    """
    root = Path(root)
    out = {}
    for rel, data in files:
        p = (root / rel).resolve()
        if root.resolve() not in p.parents:
            raise ValueError(f"file path {rel!r} escapes the corpus root")
        out[rel] = atomic_write_bytes(p, data)
    return out


# ------------------------------------------------------------------------------------------- validation
@dataclass
class ValidationReport:
    """Result of :func:`validate_corpus`: ``errors`` (each names a file), ``warnings``, counters."""

    root: str
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    n_scenes: int = 0
    n_files: int = 0

    @property
    def ok(self) -> bool:
        return not self.errors

    def to_dict(self) -> dict:
        return {"root": self.root, "ok": self.ok, "n_scenes": self.n_scenes, "n_files": self.n_files,
                "errors": self.errors, "warnings": self.warnings}


def validate_corpus(root: str | os.PathLike, *, check_pixels: bool = True,
                    progress: Any = None) -> ValidationReport:
    """Check a whole corpus; never raises for corpus problems, collects them in the report.

    Checks: manifest format; ``splits.json`` (ids known, disjoint); per scene ``scene.json`` / ``meta.json``
    (:func:`validate_meta`); every expected EXR present (each frame x group, ``aux.exr`` all or none) and in
    the manifest; every manifest file present with the right SHA-256; files on disk not in the manifest
    (warning); per EXR: display window = meta size, parts / channels exactly as meta.json announces
    (``short``/``long`` x bands, or ``light<id>`` parts with K bins x bands, data windows inside the image,
    ids of that group), and (``check_pixels``) NaN / inf / negative radiance and invalid aux values.

    Args:
        root: corpus directory.
        check_pixels: decode pixel data (slow for big corpora) in addition to headers.
        progress: optional callable ``progress(done, total)`` called after each scene.
    """
    root = Path(root)
    rep = ValidationReport(str(root))
    err = rep.errors.append
    mpath = root / MANIFEST_NAME
    if not mpath.is_file():
        err(f"{mpath}: manifest missing (not an lfmbench corpus)")
        return rep
    try:
        man = _check_manifest(_load_json(mpath, "manifest"), mpath, entries=False)
    except CorpusError as exc:
        err(str(exc))
        return rep
    bad_entries = manifest_entry_errors(man, mpath)
    rep.errors.extend(bad_entries)
    scenes = [s for s in man["scenes"] if _scene_id_error(s) is None]
    rep.n_scenes = len(scenes)
    files: dict[str, str] = {rel: d for rel, d in man["files"].items()
                             if _file_entry_error(rel, d, set(scenes)) is None}
    rep.n_files = len(man["files"])
    # checksums and presence of every listed file (only entries that stay inside the root)
    for rel, digest in files.items():
        try:
            p = inside_root(root, rel, str(mpath))
        except CorpusFileError as exc:
            err(str(exc))
            continue
        p = root / rel
        if not p.is_file():
            err(f"{p}: missing (listed in manifest)")
        elif sha256_file(p) != digest:
            err(f"{p}: bad checksum (SHA-256 differs from manifest)")
    # splits
    spath = root / SPLITS_NAME
    if not spath.is_file():
        err(f"{spath}: missing")
    else:
        try:
            sp = check_splits(_load_json(spath, "splits file"), spath)
            ids = [s for k in ("train", "val", "test") for s in sp.get(k, [])]
            if set(sp) != {"train", "val", "test"}:
                err(f"{spath}: keys must be train, val, test; got {sorted(sp)}")
            if len(ids) != len(set(ids)):
                err(f"{spath}: a scene appears in more than one split")
            unknown = sorted(set(ids) - set(scenes))
            if unknown:
                err(f"{spath}: scenes not in the manifest: {unknown[:5]}")
            unsplit = sorted(set(scenes) - set(ids))
            if unsplit:
                rep.warnings.append(f"{spath}: scenes in no split: {unsplit[:5]}")
        except CorpusError as exc:
            err(str(exc))
    # files on disk not in the manifest
    sroot = root / SCENES_DIR
    if sroot.is_dir():
        for p in sorted(sroot.rglob("*")):
            if p.is_file():
                rel = p.relative_to(root).as_posix()
                if p.name.startswith(TMP_PREFIX):
                    rep.warnings.append(f"{p}: temporary file of an interrupted run")
                elif rel not in files and rel.split("/")[1] in scenes:
                    rep.warnings.append(f"{p}: not in manifest")
        for d in sorted(sroot.iterdir()):
            if d.is_dir() and d.name not in scenes:
                rep.warnings.append(f"{d}: incomplete scene (not in manifest; re-run the render to finish it)")
    for i, sid in enumerate(sorted(scenes)):
        try:
            inside_root(root, f"{SCENES_DIR}/{sid}", str(mpath))
        except CorpusFileError as exc:
            err(str(exc))
            continue
        _validate_scene(root, sid, files, rep, check_pixels)
        if progress is not None:
            progress(i + 1, len(scenes))
    return rep


def _validate_scene(root: Path, sid: str, files: Mapping[str, str], rep: ValidationReport,
                    check_pixels: bool) -> None:
    err = rep.errors.append
    sdir = root / SCENES_DIR / sid
    rel0 = f"{SCENES_DIR}/{sid}"
    for name in ("scene.json", "meta.json"):
        if f"{rel0}/{name}" not in files:
            err(f"{sdir / name}: not in manifest")
    if not (sdir / "scene.json").is_file():
        err(f"{sdir / 'scene.json'}: missing")
    else:
        try:
            sc = _load_json(sdir / "scene.json", "scene description")
            if not isinstance(sc, dict):
                err(f"{sdir / 'scene.json'}: must hold a JSON object (free-form content), got a {type(sc).__name__}")
        except CorpusError as exc:
            err(str(exc))
    mp = sdir / "meta.json"
    try:
        meta = _load_json(mp, "scene metadata")
        validate_meta(meta, str(mp))
        _check_meta_storage(meta, mp)
    except (CorpusError, ValueError) as exc:
        err(str(exc))
        return
    if meta["scene_id"] != sid:
        err(f"{mp}: scene_id {meta['scene_id']!r} != directory name {sid!r}")
    H, W, bands = meta["height"], meta["width"], meta["bands_nm"]
    aux_frames = [n for n in range(meta["frames"]) if f"{rel0}/{frame_dir(n)}/aux.exr" in files
                  or (sdir / frame_dir(n) / "aux.exr").is_file()]
    if aux_frames and len(aux_frames) != meta["frames"]:
        miss = sorted(set(range(meta["frames"])) - set(aux_frames))
        err(f"{sdir}: aux.exr missing for frames {miss}")
    light_ids = {}
    bbox_of = {}  # light id -> per-frame box (half-open) or None, where meta.json gives one
    for lt in meta.get("lights", []):
        light_ids.setdefault(lt["group"], set()).add(lt["id"])
        if "bbox" in lt:
            bbox_of[lt["id"]] = lt["bbox"]
    for n in range(meta["frames"]):
        for g in list(meta["groups"]) + (["aux"] if n in aux_frames else []):
            p = sdir / frame_dir(n) / f"{g}.exr"
            rel = p.relative_to(root).as_posix()
            if not p.is_file():
                if rel not in files:  # listed-but-missing files were already reported
                    err(f"{p}: missing")
                continue
            if rel not in files:
                err(f"{p}: not in manifest")
            try:
                parts = read_exr(p, header_only=not check_pixels)
            except CorpusError as exc:
                err(str(exc))
                continue
            for part in parts:
                if part.size != (H, W):
                    err(f"{p} part {part.name!r}: display window {part.size} != meta.json ({H}, {W})")
            if g == "aux":
                _validate_channels(p, parts[0], set(AUX_CHANNELS), rep)
                if check_pixels and parts[0].channels is not None:
                    for name in AUX_CHANNELS:
                        if name in parts[0].channels:
                            try:
                                _check_aux(name, np.asarray(parts[0].channels[name]), str(p))
                            except CorpusValueError as exc:
                                err(str(exc))
                continue
            if group_storage(meta, g) == "static":
                if len(parts) != 1:
                    err(f"{p}: static group must have exactly one part, has {len(parts)}")
                want = {c for w in STATIC_WINDOWS for c in static_channels(w, bands)}
                _validate_channels(p, parts[0], want, rep)
                if parts[0].window != (0, 0, H, W):
                    err(f"{p}: data window {parts[0].window} must cover the whole image")
                for w in STATIC_WINDOWS:
                    _validate_storage_attrs(p, parts[0], w, rep)
                _validate_pixels(p, parts[0], rep, check_pixels)
            else:
                K = _group_bins(meta, g)
                want = {c for row in bin_channels(K, bands) for c in row}
                ids = light_ids.get(g, set())
                if len(parts) == 1 and parts[0].name == EMPTY_PART:
                    shown = [lid for lid in sorted(ids) if bbox_of.get(lid, [None] * (n + 1))[n] is not None]
                    if shown:
                        err(f"{p}: no light is stored but meta.json bbox[{n}] of lights {shown} is not null")
                    continue
                have_parts = set()
                for part in parts:
                    mt = re.fullmatch(r"light(\d+)", part.name)
                    if mt is None:
                        err(f"{p}: unexpected part name {part.name!r} (want light<id>)")
                        continue
                    if int(mt.group(1)) not in ids:
                        err(f"{p}: part {part.name!r} is not a light of group {g!r} in meta.json")
                    have_parts.add(int(mt.group(1)))
                    bbs = bbox_of.get(int(mt.group(1)))
                    if bbs is not None and bbs[n] is None:
                        err(f"{p}: part {part.name!r} is stored but meta.json bbox[{n}] is null (not visible)")
                    elif bbs is not None and tuple(bbs[n]) != tuple(part.window):
                        err(f"{p}: part {part.name!r} data window {part.window} != meta.json bbox[{n}] {bbs[n]} "
                            "(half-open (y0, x0, y1, x1))")
                    y0, x0, y1, x1 = part.window
                    if not (0 <= y0 < y1 <= H and 0 <= x0 < x1 <= W):
                        err(f"{p}: part {part.name!r} data window {part.window} outside the {H}x{W} image")
                    _validate_channels(p, part, want, rep)
                    _validate_storage_attrs(p, part, None, rep)
                    _validate_pixels(p, part, rep, check_pixels)
                for lid in sorted(ids - have_parts):
                    bb = bbox_of.get(lid, [None] * (n + 1))[n]
                    if bb is not None:
                        err(f"{p}: meta.json bbox[{n}] of light {lid} is {bb} but the file has no part "
                            f"'light{lid}' (null bbox = not visible)")


def _validate_channels(p: Path, part: ExrPart, want: set[str], rep: ValidationReport) -> None:
    have = set(part.channel_names)
    missing, extra = sorted(want - have), sorted(have - want)
    if missing:
        rep.errors.append(f"{p} part {part.name!r}: missing channels {missing[:4]}"
                          f"{' ...' if len(missing) > 4 else ''} ({len(missing)} in all)")
    if extra:
        rep.errors.append(f"{p} part {part.name!r}: unexpected channels {extra[:4]}"
                          f"{' ...' if len(extra) > 4 else ''} ({len(extra)} in all)")


def _validate_storage_attrs(p: Path, part: ExrPart, window: str | None, rep: ValidationReport) -> None:
    """Format-version-2 attributes: the layer's scale (a power of two) and ``lfmbench_mantissa_bits``."""
    try:
        layer_scale(part, window, p)
    except CorpusFileError as exc:
        rep.errors.append(str(exc))
    mb = part.header.get(ATTR["mantissa"])
    if mb is not None and (isinstance(mb, bool) or not isinstance(mb, int) or not 1 <= mb <= 23):
        rep.errors.append(f"{p} part {part.name!r}: attribute {ATTR['mantissa']} = {mb!r} must be an integer "
                          "in [1, 23]")


def _validate_pixels(p: Path, part: ExrPart, rep: ValidationReport, check_pixels: bool) -> None:
    if not check_pixels or part.channels is None:
        return
    n_nan = n_inf = n_neg = n_big = 0
    peak = 0.0
    for name, a in part.channels.items():
        a = np.asarray(a, dtype=np.float32)
        n_nan += int(np.isnan(a).sum())
        n_inf += int(np.isinf(a).sum())
        n_neg += int((a < 0).sum())
        window = name.split(".", 1)[0]
        try:
            scale = layer_scale(part, window if window in STATIC_WINDOWS else None, p)
        except CorpusFileError:  # reported by _validate_storage_attrs
            continue
        fin = a[np.isfinite(a)]
        if fin.size:
            big = fin.astype(np.float64) / scale > RADIANCE_MAX
            n_big += int(big.sum())
            peak = max(peak, float(fin.max()) / scale)
    for n, what in ((n_nan, "NaN"), (n_inf, "inf"), (n_neg, "negative")):
        if n:
            rep.errors.append(f"{p} part {part.name!r}: {n} {what} radiance values")
    if n_big:
        rep.errors.append(f"{p} part {part.name!r}: {n_big} radiance values above the plausibility ceiling "
                          f"RADIANCE_MAX = {RADIANCE_MAX:.0e} {RADIANCE_UNIT} (max {peak:.3g}): a unit or scale "
                          "error")
