"""Run the public IEEE P2020 flicker reference code on shared ROI-mean series; write ``reference.json``.

The reference implementation is CARpublic/P2020-flicker (MIT License, Copyright (c) 2023 Connaught Automotive
Research), https://github.com/CARpublic/P2020-flicker, file ``metrics/flicker.py`` at commit
``fbd3c4487d1c2793ccf47b88b1a30ce40cf60212``: ``calc_FMI``, ``calc_FDI``, ``calc_MMP``, ``saturation_warning``.
Its code is NOT copied into lfmbench: this script imports it from a checkout and stores only the series and
its outputs, which ``tests/metrics/test_p2020_reference.py`` compares with :mod:`lfmbench.metrics.flicker`.

How ``reference.json`` was produced (Python 3.11, in a virtual environment holding the reference's pinned
``numpy~=1.24.3`` and ``pandas~=2.0.2`` from its ``requirements.txt``; numpy 1.24.4 and pandas 2.0.3 were used)::

    git clone https://github.com/CARpublic/P2020-flicker /tmp/P2020-flicker
    git -C /tmp/P2020-flicker checkout fbd3c4487d1c2793ccf47b88b1a30ce40cf60212
    python -m venv /tmp/p2020venv && /tmp/p2020venv/bin/pip install "numpy~=1.24.3" "pandas~=2.0.2"
    /tmp/p2020venv/bin/python tests/data/p2020/make_reference.py --reference /tmp/P2020-flicker

The script depends only on numpy, pandas and the standard library (it must run in the reference's
environment, without lfmbench). Its output is deterministic: the noisy series come from
``numpy.random.default_rng(seed)`` and are stored in the JSON, so the test never regenerates them.

Conventions of the reference that the cases exercise: frames are along axis 0 (rows; the demo
``measure_flicker_demo.py`` passes a pandas DataFrame of frames x ROIs); ``start_index`` is the first measured
frame; ``calc_FDI`` takes the OFF level ``x_off`` as the mean of the first ``uint16(start_index / 4)`` frames
(the baseline recorded with the light OFF); FDI and MMP divide by the number of measured frames; on a 2-D
numpy array (not a DataFrame) their ``.sum()`` adds the counts of all ROIs. Non-finite outputs are written as
the strings ``"nan"``, ``"inf"``, ``"-inf"`` (the file stays strict JSON).

Series units: ROI means in DN (8-bit video levels, as the reference demo), or any linear unit.
"""
from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import math
import platform
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

REPO_URL = "https://github.com/CARpublic/P2020-flicker"
COMMIT = "fbd3c4487d1c2793ccf47b88b1a30ce40cf60212"
OUT = Path(__file__).with_name("reference.json")


def pwm_series(frames: int, fps: float, exposure_s: float, led_hz: float, duty: float, on_dn: float,
               background_dn: float, phase_s: float = 0.0) -> list[float]:
    """ROI mean (DN) of a PWM LED seen through a global-shutter exposure: exact time average of a square wave.

    Frame n integrates ``[n / fps, n / fps + exposure_s)``; the LED is ON (``on_dn`` above ``background_dn``)
    during ``[k / led_hz - phase_s, k / led_hz - phase_s + duty / led_hz)`` for every integer k.
    """
    period = 1.0 / led_hz
    out = []
    for n in range(frames):
        t0 = n / fps + phase_s
        t1 = t0 + exposure_s
        on = 0.0
        for k in range(math.floor(t0 / period) - 1, math.ceil(t1 / period) + 1):
            a, b = k * period, k * period + duty * period
            on += max(0.0, min(b, t1) - max(a, t0))
        out.append(background_dn + on_dn * on / exposure_s)
    return out


def cases() -> list[dict]:
    """The shared series: name, ``series`` (frames), ``start_index`` and the thresholds passed to the reference."""
    rng = np.random.default_rng(20200)
    c = []

    def add(name, series, start_index=0, contrast_threshold=0.1, delta=0.1, max_val=240.0, note=""):
        c.append({"name": name, "series": [float(v) for v in series], "start_index": int(start_index),
                  "contrast_threshold": contrast_threshold, "delta": delta, "max_val": max_val, "note": note})

    base = [12.0] * 8  # 8 baseline frames with the light OFF: x_off = mean of the first 8 // 4 = 2 frames
    add("pwm_duty25_short_exposure_24f", base + pwm_series(24, 30.0, 1e-3, 95.0, 0.25, 180.0, 12.0), 8,
        note="95 Hz, 25 % duty LED, 1 ms exposure at 30 fps: frames see ON, OFF or part of a pulse")
    add("pwm_duty25_long_exposure_24f", base + pwm_series(24, 30.0, 11e-3, 95.0, 0.25, 180.0, 12.0), 8,
        note="11 ms exposure > one 10.5 ms PWM period: the ROI mean stays near duty x ON (mitigated)")
    add("pwm_duty10_100f", [12.0] * 100 + pwm_series(100, 30.0, 2e-3, 90.5, 0.10, 200.0, 12.0), 100,
        note="the demo's layout: 100 baseline frames, start_index 100, 100 measured frames")
    add("pwm_duty50_24f_no_baseline", pwm_series(24, 30.0, 1e-3, 61.0, 0.5, 100.0, 5.0), 0,
        note="start_index 0: FMI, MMP measured on all frames; FDI has no baseline frame (x_off = NaN)")
    add("constant_24f", [50.0] * 32, 8, note="steady light: FMI 0, MMP 1, FDI 0 (no contrast to OFF)")
    add("single_dropout_24f", base + [100.0] * 11 + [12.0] + [100.0] * 12, 8,
        note="one extinguished frame: FMI (100-12)/(100+12), MMP 23/24")
    add("alternating_on_off_24f", base + [200.0, 12.0] * 12, 8, note="ON/OFF every other frame: MMP 0")
    add("noisy_steady_100f", list(12 + rng.normal(0, 1.0, 100)) + list(150 + rng.normal(0, 8.0, 100)), 100,
        note="Gaussian noise sigma 8 DN on 150 DN (5.3 %), baseline sigma 1 DN")
    add("noisy_flicker_24f", list(12 + rng.normal(0, 1.0, 8))
        + list(60 + 40 * np.sin(np.arange(24) * 0.7) + rng.normal(0, 3.0, 24)), 8)
    add("all_zero_24f", [0.0] * 32, 8, note="zero max: FMI 0/0 = NaN, MMP 0 (strict band around 0), FDI 0/0")
    add("zero_off_level", [0.0] * 8 + [0.0, 5.0] * 12, 8, note="x_off = 0: contrasts +inf (detected) and NaN")
    add("saturation_at_and_above_max", base + [230.0, 240.0, 240.5, 255.0, 239.9] * 4 + [235.0] * 4, 8,
        note="240 is not flagged (strict >), 240.5 and 255 are; the baseline is not saturated")
    add("mmp_dyadic_ties", [1.0] * 4 + [0.75, 1.25, 1.0, 1.0], 4, delta=0.25,
        note="values exactly on mean (1 +- delta) (exact in binary): outside the strict band, MMP 1/2")
    add("mmp_decimal_ties", [1.0] * 4 + [0.9, 1.1, 1.0, 1.0], 4,
        note="0.9 and 1.1 as decimal literals: 0.9 + 1.1 rounds to 2.0, so the band edges equal them")
    add("fdi_threshold_tie", [1.0] * 4 + [1.5, 1.5000001, 2.0, 1.0], 4, contrast_threshold=0.5,
        note="contrast exactly 0.5 is not detected (strict >)")
    add("negative_values", [-1.0] * 4 + [-2.0, 3.0, 0.5, -0.5, 4.0, 1.0], 4,
        note="a noisy dark output can be negative: the formulas apply unchanged (x_off < 0 flips contrasts)")
    add("start_index_not_multiple_of_4", [10.0, 12.0, 14.0, 40.0, 40.0] + [30.0, 11.0, 13.0, 30.0, 30.0] * 4, 10,
        note="uint16(10 / 4) = 2 baseline frames: x_off = 11")
    add("start_index_below_4", [10.0, 10.0, 30.0, 31.0, 29.0, 10.0] * 4, 2,
        note="uint16(2 / 4) = 0 baseline frames: x_off = mean of nothing = NaN, FDI 0")
    add("one_measured_frame", [3.0] * 4 + [7.0], 4, note="T = 1: FMI 0, MMP 1")
    return c


def multi_roi_case(single: list[dict]) -> dict:
    """Three ROIs side by side (frames x ROIs), start_index 8, as the demo's DataFrame."""
    names = ["pwm_duty25_short_exposure_24f", "single_dropout_24f", "noisy_flicker_24f"]
    cols = [next(c for c in single if c["name"] == n)["series"] for n in names]
    return {"name": "three_rois_frames_by_rois", "rois": names, "series": [list(r) for r in zip(*cols)],
            "start_index": 8, "contrast_threshold": 0.1, "delta": 0.1, "max_val": 240.0}


def enc(v) -> object:
    """JSON value of a number / array: lists for arrays, strings for non-finite floats."""
    if isinstance(v, (pd.Series, pd.DataFrame)):
        v = v.to_numpy()
    if isinstance(v, np.ndarray):
        return [enc(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [enc(x) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    v = float(v)
    if math.isnan(v):
        return "nan"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return v


def run_reference(ref, series, c: dict) -> dict:
    """The four reference functions on ``series`` (numpy array or DataFrame, frames along axis 0)."""
    s = c["start_index"]
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        out = {
            "fmi": ref.calc_FMI(series, start_index=s),
            "fdi": ref.calc_FDI(series, start_index=s, contrast_threshold=c["contrast_threshold"]),
            "mmp": ref.calc_MMP(series, start_index=s, delta=c["delta"]),
        }
        flag, idx = ref.saturation_warning(series, max_val=c["max_val"])
    out = {k: enc(v) for k, v in out.items()}
    out["sat_flag"], out["sat_idx"] = enc(flag), enc(idx)  # a DataFrame gives one flag per ROI
    out["warnings"] = sorted({f"{x.category.__name__}: {x.message}" for x in w})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", required=True, type=Path,
                    help=f"checkout of {REPO_URL} at commit {COMMIT} (holds metrics/flicker.py)")
    ap.add_argument("--out", type=Path, default=OUT, help="output JSON (default: next to this script)")
    a = ap.parse_args()
    path = a.reference / "metrics" / "flicker.py"
    if not path.is_file():
        sys.exit(f"--reference {a.reference}: no metrics/flicker.py there (clone {REPO_URL})")
    try:
        head = subprocess.run(["git", "-C", str(a.reference), "rev-parse", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        head = None
    if head is not None and head != COMMIT:
        sys.exit(f"--reference {a.reference} is at commit {head}, expected {COMMIT}")
    spec = importlib.util.spec_from_file_location("p2020_reference_flicker", path)
    ref = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ref)
    single = cases()
    for c in single:
        c["reference"] = run_reference(ref, np.asarray(c["series"], dtype=np.float64), c)
    m = multi_roi_case(single)
    arr = np.asarray(m["series"], dtype=np.float64)
    df = pd.DataFrame(arr, columns=[f"ROI_{i}" for i in range(arr.shape[1])])  # as measure_flicker_demo.py
    m["reference_dataframe"] = run_reference(ref, df, m)
    m["reference_ndarray"] = run_reference(ref, arr, m)
    doc = {
        "reference": {"repository": REPO_URL, "commit": COMMIT, "file": "metrics/flicker.py",
                      "sha256": hashlib.sha256(path.read_bytes()).hexdigest(), "license": "MIT",
                      "functions": ["calc_FMI", "calc_FDI", "calc_MMP", "saturation_warning"]},
        "produced_with": {"script": "tests/data/p2020/make_reference.py", "python": platform.python_version(),
                          "numpy": np.__version__, "pandas": pd.__version__},
        "conventions": "series: frames along axis 0 (ROI means, DN); non-finite values as strings",
        "cases": single,
        "multi_roi": m,
    }
    text = json.dumps(doc, indent=1, allow_nan=False)
    # one line per list of numbers / flags (a compact, still diff-friendly file)
    text = re.sub(r"\[\s*([^\[\]{}]*?)\s*\]", lambda mt: "[" + re.sub(r"\s*\n\s*", " ", mt.group(1)) + "]", text)
    a.out.write_text(text + "\n", encoding="utf-8")
    print(f"wrote {a.out}: {len(single)} single-ROI cases and one {arr.shape[0]} x {arr.shape[1]} multi-ROI case")


if __name__ == "__main__":
    main()
