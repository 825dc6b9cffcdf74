"""How radiance layers are stored in format version 2 (``docs/guide/corpus-format.md`` section 6): EXR pixel
type, per-layer power-of-two scale for HALF, mantissa rounding and compression (:class:`Storage`,
:data:`STORAGES`), and the encoding of one layer (:func:`store_layer`, no I/O).

Units: radiance in W sr^-1 m^-2 nm^-1; errors are relative (dimensionless).

References: IEEE 754-2008 binary16 (HALF) range and subnormals; OpenEXR compressions,
https://openexr.com/en/latest/TechnicalIntroduction.html
"""
from __future__ import annotations

import logging
import math
import re
from dataclasses import dataclass, field

import numpy as np

from lfmbench.corpus.naming import ATTR, STATIC_WINDOWS

__all__ = ["HALF_MAX", "COMPRESSIONS", "EXTRA_COMPRESSIONS", "HALF_MIN_NORMAL", "HALF_PRECISION_RANGE_LOG2",
           "SCALE_EXP_RANGE", "HALF_UNDERFLOW_ERROR_FRACTION", "MANTISSA_BITS", "Storage", "STORAGES",
           "DEFAULT_STORAGE", "resolve_storage", "round_mantissa", "scale_exponent", "LayerStore", "StorageStats",
           "store_layer", "scale_attr", "float_to_half"]

log = logging.getLogger(__name__)

#: Largest finite IEEE 754 binary16 value; radiance above it cannot be stored as HALF (IEEE 754-2008).
HALF_MAX = 65504.0
#: EXR compressions a corpus file may use, by name -> ``OpenEXR`` enum member. All are readable by OpenEXR 2.2
#: and later; every one of them is lossless on the channels lfmbench writes except PXR24 on FLOAT channels
#: (rounded to 24 bits, <= 2^-16 relative): DWAA/DWAB compress lossily only channels named R, G, B, Y, BY, RY
#: (and ``*.R`` ...), never ``short.400nm`` (checked in ``docs/benchmarks/storage.md``).
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
#: Values per chunk of :func:`store_layer`'s HALF encoding (256 Ki float32 = 1 MiB): its dozen temporaries stay
#: in the CPU cache instead of making a dozen passes over a 28 MB layer (measured in
#: docs/benchmarks/rendering-measurements.md, "Serial work around the tracer").
ENCODE_CHUNK = 1 << 18


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
#: ``docs/benchmarks/storage.md``); ``float32`` stores the pixels as format version 1 did (lossless FLOAT, ZIP).
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
    return _round_mantissa_inplace(a, int(bits))


def _round_mantissa_inplace(a: np.ndarray, bits: int) -> np.ndarray:
    """:func:`round_mantissa` on a float32 array ``a`` in place (returns ``a``)."""
    drop = 23 - bits
    if drop == 0:
        return a
    b = a.view(np.uint32)
    lsb = b >> np.uint32(drop)
    lsb &= np.uint32(1)
    b += np.uint32((1 << (drop - 1)) - 1)
    b += lsb
    b &= np.uint32(~((1 << drop) - 1) & 0xFFFFFFFF)
    return a


#: float32 bit patterns used by :func:`_half_parts`: 0.5 (its ulp is 2^-24, HALF's subnormal step), the exponent
#: re-bias 127 - 15 = 112, the smallest normal HALF 2^-14 (biased float32 exponent 113) and float32 infinity.
_HALF_SUB_ADD = np.float32(0.5)
_HALF_SUB_ADD_BITS = np.uint32(0x3F000000)
_HALF_REBIAS = np.uint32(112 << 10)
_HALF_NORMAL_MIN_BITS = np.uint32(113 << 23)
_F32_INF_BITS = np.uint32(0x7F800000)
#: float32 pattern of 2^16: a value rounded to it or beyond overflows HALF (65504 is its largest finite value).
_HALF_OVERFLOW_BITS = np.uint32(0x47800000)


def _half_parts(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """IEEE 754 binary16 of float32 values ``x`` (any shape), rounded to nearest, ties to even, as numpy's
    ``x.astype(np.float16)`` (bit for bit, also for -0, overflow to inf, inf; NaN gives the quiet NaN 0x7E00):
    returns ``(bits (uint16, same shape), value of each HALF as float32 (exact))``.

    Normal HALF results: the float32 pattern rounded at bit 13 (the carry into the exponent is right) and
    re-biased; subnormal ones (|x| < 2^-14): ``|x| + 0.5`` in float32 arithmetic rounds |x| to the
    multiple of 2^-24 (HALF's subnormal step), ties to even, and its low bits are the HALF's. Integer and float
    passes only, the two cases merged with bit masks (no branches): numpy's own cast takes a slow path for
    HALF-subnormal results (up to ~15x slower).
    """
    b = x.view(np.uint32)
    a = b & np.uint32(0x7FFFFFFF)
    rr = a >> np.uint32(13)
    rr &= np.uint32(1)
    rr += a
    rr += np.uint32(0x0FFF)  # a + 0xFFF + lsb: round to nearest even at bit 13
    rr &= np.uint32(0xFFFFE000)  # the rounded float32 pattern (normal HALF range)
    with np.errstate(invalid="ignore", over="ignore"):
        sub_f = a.view(np.float32) + _HALF_SUB_ADD  # rounded to 2^-24 steps (inf / NaN: replaced below)
        vb = (sub_f - _HALF_SUB_ADD).view(np.uint32)
    msk = (a < _HALF_NORMAL_MIN_BITS).astype(np.uint32)
    np.negative(msk, out=msk)  # all ones where the HALF is subnormal
    vb ^= rr  # value = msk ? subnormal value : rounded pattern
    vb &= msk
    vb ^= rr
    h32 = rr >> np.uint32(13)
    h32 -= _HALF_REBIAS  # wraps around for the subnormal range: replaced below
    np.minimum(h32, np.uint32(0x7C00), out=h32)  # overflow (>= 65520 after rounding) and inf -> inf
    sb = sub_f.view(np.uint32)
    sb -= _HALF_SUB_ADD_BITS
    sb ^= h32  # bits = msk ? subnormal bits : normal bits
    sb &= msk
    sb ^= h32
    big = rr >= _HALF_OVERFLOW_BITS
    if big.any():
        vb[big] = _F32_INF_BITS
    nan = a > _F32_INF_BITS
    if nan.any():
        sb[nan] = 0x7E00
        vb[nan] = 0x7FC00000
    h = sb.astype(np.uint16)
    sign = b >> np.uint32(16)
    sign &= np.uint32(0x8000)
    h |= sign.astype(np.uint16)
    vb |= b & np.uint32(0x80000000)
    return h, vb.view(np.float32)


def float_to_half(x: np.ndarray) -> np.ndarray:
    """``x.astype(np.float16)`` bit for bit (round to nearest even; NaN -> quiet NaN), faster where results are
    HALF subnormals: ``x`` any shape (converted to float32), returns float16 of the same shape."""
    x = np.ascontiguousarray(x, dtype=np.float32)
    flat = x.reshape(-1)
    out = np.empty(flat.size, np.uint16)
    for i in range(0, flat.size, ENCODE_CHUNK):
        out[i:i + ENCODE_CHUNK] = _half_parts(flat[i:i + ENCODE_CHUNK])[0]
    return out.view(np.float16).reshape(x.shape)


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

    def merge(self, other: "StorageStats") -> None:
        """Add another aggregate (e.g. of one file encoded in another thread) to this one."""
        self.layers += other.layers
        self.half += other.half
        self.fallbacks.extend(other.fallbacks)
        self.max_error = max(self.max_error, other.max_error)
        self.max_underflow_error = max(self.max_underflow_error, other.max_underflow_error)

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


def _encode_half(x: np.ndarray, e: int, mantissa_bits: int | None, total: float
                 ) -> tuple[np.ndarray, float, float]:
    """HALF encoding of a layer ``x`` (float32, W sr^-1 m^-2 nm^-1, any shape) scaled by 2^e: returns
    ``(half(round_m(x * 2^e)) as float16 of x's shape, error, underflow error)``, the errors as
    :func:`_energy_error` of the values read back (``half / 2^e``), the underflow one over the values below
    2^-14 after scaling. Works in chunks of :data:`ENCODE_CHUNK` values (cache-sized temporaries); the sums
    are float64 per chunk, so they may differ from one whole-array sum in the last digits."""
    x = np.ascontiguousarray(x, dtype=np.float32)
    flat = x.reshape(-1)
    out = np.empty(flat.size, np.uint16)
    s = np.float32(2.0 ** e)
    err = under = 0.0
    for i in range(0, flat.size, ENCODE_CHUNK):
        xc = flat[i:i + ENCODE_CHUNK]
        scaled = xc * s  # exact: power of two (unless float32 over/underflows: store_layer checks the peak)
        if mantissa_bits is not None:
            _round_mantissa_inplace(scaled, int(mantissa_bits))
        out[i:i + ENCODE_CHUNK], back = _half_parts(scaled)
        back /= s  # the value read back
        back -= xc
        np.abs(back, out=back)
        err += float(np.sum(back, dtype=np.float64))
        with np.errstate(invalid="ignore"):  # inf * 0 (an overflow, refused by store_layer) -> NaN
            back *= scaled < HALF_MIN_NORMAL  # (a multiply: a masked sum is ~8x slower on mixed masks)
        under += float(np.sum(back, dtype=np.float64))
    if total <= 0:
        return out.view(np.float16).reshape(x.shape), 0.0, 0.0
    return out.view(np.float16).reshape(x.shape), err / total, under / total


def store_layer(arr: np.ndarray, storage: str | Storage, what: str = "layer") -> LayerStore:
    """Encode one radiance layer for storage (no I/O): the scale rule of ``docs/guide/corpus-format.md`` section 6.

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
        h, err, under = _encode_half(x, e, st.mantissa_bits, total)
        reason = None
        if peak > 0 and not HALF_MIN_NORMAL <= peak * 2.0 ** e <= HALF_MAX:
            reason = f"peak {peak:.3g} cannot be scaled into HALF's range by 2^{e}"
        elif not math.isfinite(err) or under > st.max_underflow_error:
            reason = (f"HALF x 2^{e} would change the radiance by {under:.2g} (energy-weighted, values below "
                      f"HALF's normal range) > {st.max_underflow_error:.2g}")
        if reason is None:
            return LayerStore(h, "float16", float(2.0 ** e), err, under)
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
    if window not in STATIC_WINDOWS and not (isinstance(window, str) and re.fullmatch(r"bin\d{2,}", window)):
        raise ValueError(f"window must be one of {STATIC_WINDOWS}, a bin prefix or None, got {window!r}")
    return f"{ATTR['scale']}_{window}"
