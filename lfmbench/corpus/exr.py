"""EXR decoding of corpus files through the OpenEXR 3.x Python API (``OpenEXR.File`` / ``OpenEXR.Part``):
:func:`read_exr` (:class:`ExrPart` per part), the headers read without decoding pixels (:func:`exr_headers`,
:func:`check_exr_header`) and the per-layer scale of a decoded part (:func:`layer_scale`). Encoding is
:mod:`lfmbench.corpus.exr_encode` (it shares :func:`_exr` and the aux-channel check :func:`_check_aux`).

Units: spectral radiance in W sr^-1 m^-2 nm^-1, depth in m, bounding boxes in pixels as half-open
``(y0, x0, y1, x1)``.

References: OpenEXR file layout and multi-part files, https://openexr.com/en/latest/TechnicalIntroduction.html
(data window / display window, part names).
"""
from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from lfmbench.corpus.errors import CorpusChannelError, CorpusFileError, CorpusValueError
from lfmbench.corpus.naming import ATTR, RADIANCE_MAX, RADIANCE_UNIT, _check_version
from lfmbench.limits import LimitError, limits_of
from lfmbench.corpus.storage import SCALE_EXP_RANGE, scale_attr

__all__ = ["ExrPart", "read_exr", "layer_scale", "check_exr_header", "exr_headers", "ExrHeaders"]


def _exr():
    try:
        import OpenEXR  # noqa: PLC0415
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ImportError("lfmbench.corpus needs the OpenEXR 3.x Python bindings: pip install 'OpenEXR>=3.2'") \
            from exc
    return OpenEXR


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
