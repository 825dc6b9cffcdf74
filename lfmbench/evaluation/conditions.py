"""Conditions of every scored sample (time of day, PWM duty and frequency, ego speed) and their bins.

- :func:`sample_conditions`: PWM duty, frequency and miss probability of each sample of a batch, from its ``meta``
  (the dataset's per-light ``duty``, ``freq_hz`` and ``flicker`` arrays, and the sensor's own shortest capture's
  windows ``miss_windows_s``, else the split pixel's ``exposure_short_s``): means over the flickering lights.
- :func:`corpus_scene_conditions`: a ``scene_id -> {time_of_day, ego_speed_mps}`` reader of a corpus
  (``scene.json`` ``time_of_day``, ``meta.json`` ``camera.speed_mps``).
- :func:`load_bins`, :func:`bin_label`: the breakdown bins of ``lfmbench/configs/conditions.yaml``.
"""
from __future__ import annotations

import copy
import functools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from lfmbench.limits import brief
from lfmbench.fileio import load_yaml

#: The default bins (plain YAML a user can edit or replace with ``--conditions``).
CONDITIONS_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "conditions.yaml"
#: Label of a sample without a value for a condition.
NA = "n/a"


def load_bins(path: str | Path | None = None) -> dict[str, dict]:
    """Condition name -> ``{"categories": [...]}`` or ``{"edges": [...], "unit": str}``, checked.

    ``path``: a YAML file or the name of a shipped conditions file (:func:`lfmbench.resources.find_config`);
    default :data:`CONDITIONS_CONFIG`.

    Raises:
        ValueError: naming the file and the entry when the file is not such a mapping; an unknown name.
    """
    from lfmbench.resources import find_config

    p = Path(CONDITIONS_CONFIG if not path else find_config(path, "conditions", "--conditions"))
    try:  # a leaderboard reads the bins once per condition and row set: parsed and checked once per file version
        st = p.stat()
    except OSError:  # the read below names the file and the error
        return _read_bins(str(p))
    return copy.deepcopy(_read_bins_cached(str(p), str(p.resolve()), st.st_mtime_ns, st.st_size))


@functools.lru_cache(maxsize=8)
def _read_bins_cached(shown: str, resolved: str, mtime_ns: int, size: int) -> dict[str, dict]:
    """:func:`_read_bins` of ``shown`` once per (resolved path, mtime, size): a changed file is read again; callers
    get copies (:func:`load_bins`); an error is not kept."""
    return _read_bins(shown)


def _read_bins(p: str) -> dict[str, dict]:
    """The checked bins of conditions file ``p`` (:func:`load_bins`)."""
    try:
        cfg = load_yaml(p, source=f"conditions file {p}")
    except OSError as exc:
        raise ValueError(f"conditions file {p}: cannot read YAML ({exc.strerror or exc})") from None
    if not isinstance(cfg, dict) or not cfg:
        raise ValueError(f"conditions file {p}: must map condition names to bins")
    for name, spec in cfg.items():
        if not isinstance(spec, dict) or ("categories" in spec) == ("edges" in spec):
            raise ValueError(f"conditions file {p}: {name}: give either 'categories' or 'edges'")
        if "edges" in spec:
            e = spec["edges"]
            if (not isinstance(e, list) or len(e) < 2 or not all(isinstance(x, (int, float)) for x in e)
                    or any(b <= a for a, b in zip(e, e[1:]))):
                raise ValueError(f"conditions file {p}: {name}.edges must be >= 2 increasing numbers, got {brief(e)}")
        elif not isinstance(spec["categories"], list) or not spec["categories"]:
            raise ValueError(f"conditions file {p}: {name}.categories must be a non-empty list")
    return cfg


def _num(x: float) -> str:
    return "inf" if math.isinf(x) else f"{x:g}"


def bin_labels(spec: dict) -> list[str]:
    """Every label of a condition's bins, in order (``n/a`` last)."""
    if "categories" in spec:
        return [str(c) for c in spec["categories"]] + [NA]
    e = spec["edges"]
    return [f"[{_num(a)}, {_num(b)})" for a, b in zip(e, e[1:])] + [NA]


def bin_label(value: Any, spec: dict) -> str:
    """The bin of ``value`` under ``spec`` (see :func:`load_bins`); ``n/a`` for a missing or out-of-range value.

    >>> bin_label(0.3, {"edges": [0.0, 0.2, 0.35, 1.0]}), bin_label("night", {"categories": ["day", "night"]})
    ('[0.2, 0.35)', 'night')
    """
    if value is None:
        return NA
    if "categories" in spec:
        return str(value) if str(value) in [str(c) for c in spec["categories"]] else NA
    try:
        v = float(value)
    except (TypeError, ValueError):
        return NA
    e = spec["edges"]
    for a, b in zip(e, e[1:]):
        if a <= v < b:
            return f"[{_num(a)}, {_num(b)})"
    return NA


def _per_sample(meta: Any, key: str, b: int) -> list:
    """``meta[key]`` split into ``b`` per-sample entries (collated dict, or a list of per-sample dicts)."""
    if isinstance(meta, (list, tuple)):
        return [m.get(key) if isinstance(m, dict) else None for m in meta][:b] + [None] * max(0, b - len(meta))
    if not isinstance(meta, dict) or key not in meta:
        return [None] * b
    v = meta[key]
    try:
        import torch

        if isinstance(v, torch.Tensor):
            return list(v.reshape(b, -1)) if v.ndim >= 1 and v.shape[0] == b else [v] * b
    except ImportError:  # pragma: no cover
        pass
    if isinstance(v, (list, tuple)) and len(v) == b:
        return list(v)
    return [v] * b


def _has(meta: Any, key: str) -> bool:
    """Whether a collated ``meta`` (dict) or a list of per-sample dicts holds ``key``."""
    if isinstance(meta, dict):
        return key in meta
    return isinstance(meta, (list, tuple)) and any(isinstance(m, dict) and key in m for m in meta)


def sample_conditions(batch: dict) -> list[dict]:
    """PWM conditions of each sample of a batch, means over the sample's flickering lights (``meta`` arrays
    ``duty``, ``freq_hz``, ``flicker`` of shape (B, L)): ``pwm_duty`` (1), ``pwm_freq_hz`` (Hz) and
    ``pwm_miss_prob`` (1; the expected share of frames in which the sensor's shortest capture sees the light dark:
    for a capture plan, :func:`lfmbench.flicker.windows_miss_probability` of its own windows ``miss_windows_s``
    ((W, 2) s, the dataset's meta: a staggered sensor's 0.1 ms, a chopped sensor's union of sub-windows, a LOFIC
    sensor's 11 ms), for the split pixel :func:`lfmbench.flicker.miss_probability` of its LPD's short exposure
    ``exposure_short_s`` (s); the light's period and duty);
    left out when the sample has no flickering light or the meta lacks them. ``time_of_day`` and
    ``ego_speed_mps`` are taken from ``meta`` when a data source provides them."""
    import torch

    from lfmbench.flicker import miss_probability, windows_miss_probability

    b = batch["gt"].shape[0]
    meta = batch.get("meta", {})
    duty, freq, flick, t_s = (_per_sample(meta, k, b) for k in ("duty", "freq_hz", "flicker", "exposure_short_s"))
    mw = _per_sample(meta, "miss_windows_s", b) if _has(meta, "miss_windows_s") else [None] * b
    out = []
    for i in range(b):
        rec: dict[str, Any] = {}
        if flick[i] is None:
            out.append(rec)
            continue
        f = torch.as_tensor(flick[i]).reshape(-1).bool()
        vals = {}
        for name, arr in (("pwm_duty", duty[i]), ("pwm_freq_hz", freq[i])):
            if arr is not None:
                a = torch.as_tensor(arr, dtype=torch.float64).reshape(-1)
                if a.shape == f.shape and bool(f.any()):
                    vals[name] = a[f]
                    rec[name] = float(a[f].mean())
        ok = {"pwm_duty", "pwm_freq_hz"} <= vals.keys() and bool((vals["pwm_freq_hz"] > 0).all())
        if ok and mw[i] is not None:   # a capture plan: its own shortest capture's windows (a chopped union too)
            wins = torch.as_tensor(mw[i], dtype=torch.float64).reshape(-1, 2).tolist()
            rec["pwm_miss_prob"] = float(sum(windows_miss_probability(wins, 1.0 / float(f_), float(d_))
                                             for f_, d_ in zip(vals["pwm_freq_hz"], vals["pwm_duty"]))
                                         / len(vals["pwm_duty"]))
        elif ok and t_s[i] is not None:   # the split pixel: its LPD's short window
            ts = float(torch.as_tensor(t_s[i], dtype=torch.float64).reshape(-1)[0])
            rec["pwm_miss_prob"] = float(miss_probability(ts, 1.0 / vals["pwm_freq_hz"], vals["pwm_duty"]).mean())
        for key in ("time_of_day", "ego_speed_mps"):
            v = _per_sample(meta, key, b)[i]
            if v is not None:
                rec[key] = v if isinstance(v, str) else float(v)
        out.append(rec)
    return out


def corpus_scene_conditions(corpus) -> Callable[[str], dict]:
    """``scene_id -> {"time_of_day": str, "ego_speed_mps": float}`` read (once per scene) from an
    :class:`lfmbench.corpus.Corpus`; a field the scene files lack is left out."""
    cache: dict[str, dict] = {}

    def get(scene_id: str) -> dict:
        if scene_id not in cache:
            rec: dict[str, Any] = {}
            try:
                tod = corpus.scene(scene_id).get("time_of_day")
                if isinstance(tod, str):
                    rec["time_of_day"] = tod
            except (OSError, ValueError, KeyError, AttributeError):  # a scene file the dataset did not need
                pass
            try:
                v = corpus.meta(scene_id).get("camera", {}).get("speed_mps")
                if isinstance(v, (int, float)) and math.isfinite(v):
                    rec["ego_speed_mps"] = float(v)
            except (OSError, ValueError, KeyError, AttributeError):  # a scene file the dataset did not need
                pass
            cache[scene_id] = rec
        return cache[scene_id]

    return get
