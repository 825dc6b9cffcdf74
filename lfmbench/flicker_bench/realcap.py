"""Real bench captures: ROI-mean series in the layout of the CARpublic P2020 flicker code, and their KPIs.

Layout (two CSV files, UTF-8, comma-separated, one header row):

``series.csv``: the ROI means, one row per frame, one column per ROI: exactly the table that
``calc_roi_mean`` of CARpublic/P2020-flicker (``measure_flicker_demo.py``) builds (``pandas.DataFrame`` with
columns ``ROI_0``, ``ROI_1``, ...) and ``DataFrame.to_csv`` writes, so the same file feeds ``calc_FMI``,
``calc_FDI`` and ``calc_MMP`` there and this bench here. A first column that is unnamed or named ``frame`` (the
index ``to_csv`` adds) is skipped. Units: any linear unit (DN above black, e-, ...); the KPIs are ratios.
As in the reference, the first ``start_index`` frames are the baseline recorded with the LED OFF; the FDI takes
the mean of the first ``start_index // 4`` of them as the OFF level.

``meta.csv``: one row per ROI that was an LED patch, columns ``roi`` (a column of series.csv),
``frequency_hz``, ``duty`` (0..1], ``start_index`` (integer >= 0); optional ``luminance_cd_m2`` (the patch's ON
luminance; default: the bench's lowest luminance) and ``panel`` (the capture or method of the preset the
camera output corresponds to; default: the architecture's standard merge).

Every value must be a finite number; a missing column or a non-numeric value is a one-line error naming the file,
the column and the row. At most :data:`MAX_FRAMES` rows and :data:`MAX_ROIS` columns are read.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from lfmbench.flicker_bench.model import BenchError, MAX_FREQUENCY_HZ, MIN_FREQUENCY_HZ
from lfmbench.metrics.flicker import fdi, fmi, mmp

__all__ = ["Capture", "read_captures", "measured_kpis", "MAX_FRAMES", "MAX_ROIS"]

#: Most frames (rows) read from a series file.
MAX_FRAMES = 1_000_000
#: Most ROI columns of a series file.
MAX_ROIS = 4096
#: Most bytes of one CSV file (memory stays bounded whatever the file holds).
MAX_BYTES = 64 * 2 ** 20


@dataclass
class Capture:
    """One measured LED ROI: its series (frames,), PWM settings and the panel it is compared with."""

    roi: str
    series: np.ndarray
    frequency_hz: float
    duty: float
    start_index: int
    luminance_cd_m2: float | None
    panel: str | None


def _rows(path: Path, what: str):
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise BenchError(f"{what} {path}: cannot read ({exc.strerror or exc})") from None
    if not path.is_file():
        raise BenchError(f"{what} {path}: not a regular file")
    if size > MAX_BYTES:
        raise BenchError(f"{what} {path}: {size} bytes, more than the {MAX_BYTES} read")
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise BenchError(f"{what} {path}: cannot read as CSV ({exc})") from None
    if not rows or not rows[0]:
        raise BenchError(f"{what} {path}: empty file (need a header row)")
    return [h.strip() for h in rows[0]], rows[1:]


def _number(text: str, path: Path, col: str, row: int) -> float:
    try:
        v = float(text)
    except ValueError:
        raise BenchError(f"{path}: field '{col}' row {row}: not a number: {text[:40]!r}") from None
    if not math.isfinite(v):
        raise BenchError(f"{path}: field '{col}' row {row}: not a finite number: {text[:40]!r}")
    return v


def read_captures(series_csv: str | Path, meta_csv: str | Path) -> list[Capture]:
    """Read and check a series file and its meta file (module docstring); raises :class:`BenchError`."""
    sp, mp = Path(series_csv), Path(meta_csv)
    head, rows = _rows(sp, "--capture-series")
    skip = 1 if head and head[0] in ("", "frame") else 0
    cols = head[skip:]
    if not cols:
        raise BenchError(f"{sp}: no ROI column in the header")
    if len(cols) > MAX_ROIS:
        raise BenchError(f"{sp}: {len(cols)} ROI columns, at most {MAX_ROIS}")
    if len(rows) > MAX_FRAMES:
        raise BenchError(f"{sp}: {len(rows)} frames, at most {MAX_FRAMES}")
    if len(set(cols)) != len(cols):
        raise BenchError(f"{sp}: duplicate column names in the header")
    mhead, mrows = _rows(mp, "--capture-meta")
    for need in ("roi", "frequency_hz", "duty", "start_index"):
        if need not in mhead:
            raise BenchError(f"{mp}: missing column '{need}' (columns: {mhead})")
    out = []
    idx = {c: i for i, c in enumerate(mhead)}
    data: dict[str, np.ndarray] = {}
    for r, row in enumerate(mrows, start=2):
        if not any(x.strip() for x in row):
            continue
        if len(row) != len(mhead):
            raise BenchError(f"{mp}: row {r} has {len(row)} fields, the header {len(mhead)}")
        get = {k: row[i].strip() for k, i in idx.items()}
        roi = get["roi"]
        if roi not in cols:
            raise BenchError(f"{sp}: no column '{roi}' (named in {mp} row {r}); columns: {cols[:8]}")
        f = _number(get["frequency_hz"], mp, "frequency_hz", r)
        if not MIN_FREQUENCY_HZ <= f <= MAX_FREQUENCY_HZ:
            raise BenchError(f"{mp}: field 'frequency_hz' row {r}: {f:g} Hz outside the model's "
                             f"[{MIN_FREQUENCY_HZ:g}, {MAX_FREQUENCY_HZ:g}] Hz")
        d = _number(get["duty"], mp, "duty", r)
        if not 0 < d <= 1:
            raise BenchError(f"{mp}: field 'duty' row {r}: {d:g} outside (0, 1]")
        s = _number(get["start_index"], mp, "start_index", r)
        if s != int(s) or s < 0:
            raise BenchError(f"{mp}: field 'start_index' row {r}: must be an integer >= 0, got {get['start_index']!r}")
        lum = get.get("luminance_cd_m2", "")
        lum_v = _number(lum, mp, "luminance_cd_m2", r) if lum else None
        if lum_v is not None and lum_v <= 0:
            raise BenchError(f"{mp}: field 'luminance_cd_m2' row {r}: must be > 0")
        if roi not in data:
            j = cols.index(roi) + skip
            vals = np.empty(len(rows))
            for k, srow in enumerate(rows):
                if j >= len(srow) or not srow[j].strip():
                    raise BenchError(f"{sp}: field '{roi}' row {k + 2}: missing value")
                vals[k] = _number(srow[j], sp, roi, k + 2)
            data[roi] = vals
        if int(s) >= data[roi].size:
            raise BenchError(f"{mp}: field 'start_index' row {r}: {int(s)} >= the {data[roi].size} frames of '{roi}'")
        out.append(Capture(roi, data[roi], f, d, int(s), lum_v, get.get("panel") or None))
    if not out:
        raise BenchError(f"{mp}: no ROI row")
    return out


def measured_kpis(cap: Capture, delta: float = 0.1, contrast: float = 0.1) -> dict[str, float]:
    """P2020 FMI, MMP and FDI of one measured ROI (:mod:`lfmbench.metrics.flicker`, the CARpublic definitions),
    frames from ``start_index`` on; FDI with the OFF level of the first ``start_index // 4`` frames (NaN when
    ``start_index < 4``: no baseline frame)."""
    x = torch.from_numpy(cap.series)
    s = cap.start_index
    out = {"fmi": float(fmi(x, start_index=s)), "mmp": float(mmp(x, delta=delta, start_index=s))}
    out["fdi"] = float(fdi(x, contrast_threshold=contrast, start_index=s)) if s >= 4 else math.nan
    out["frames"] = int(cap.series.size - s)
    return out
