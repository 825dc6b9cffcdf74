"""``lfmbench evaluate`` and ``lfmbench leaderboard``: score fusion methods, rank them against run time.

Functional core (usable without the CLI):

- :func:`evaluate` runs one method over an iterable of batches (the data source is injectable: any iterable of
  sample dicts, ``docs/contracts.md`` section 3), scores every scene with :func:`lfmbench.metrics.score_batch`,
  times the method (warm-up, then the median of repeated synchronised calls, in ms per output megapixel),
  counts parameters and MACs of ``nn.Module`` methods, records versions, seeds, device and git revision, and
  writes the JSON result atomically after every batch. A method that raises, returns a wrong shape, NaN or
  inf is recorded per scene (``status``) and the run goes on.
- :func:`load_runs`, :func:`leaderboard_rows`, :func:`leaderboard_markdown`, :func:`plot_quality_vs_runtime`
  build the ranked leaderboard.

A method spec is a registered baseline name (:data:`lfmbench.baselines.REGISTRY`) or ``package.module:function``.
Result format: ``docs/metrics.md`` ("Result files").
"""
from __future__ import annotations

import datetime as _dt
import json
import math
import os
import platform
import re
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import torch

from lfmbench.fileio import atomic_save_figure, atomic_write_json, atomic_write_text

RESULT_FORMAT = "lfmbench-eval"
RESULT_VERSION = 1
#: Metrics shown in the leaderboard, in column order (name, header).
LEADERBOARD_COLUMNS = (
    ("psnr_mu", "PSNR-mu dB"), ("psnr_l", "PSNR-L dB"), ("ssim_mu", "SSIM-mu"), ("pu21_psnr", "PU21 dB"),
    ("cvvdp_jod", "JOD"), ("mmp_pred", "MMP"), ("fmi_abs_err", "|dFMI|"), ("fdi_pred", "FDI"),
    ("dropout_rate", "dropout"), ("series_rel_rmse", "series err"), ("psnr_mu_outside", "PSNR-mu out"),
    ("ghost_mae_mu", "ghost"),
)


class MethodOutputError(ValueError):
    """A method returned something that is not a finite (B, F, 1, H, W) tensor shaped like ``gt``."""


class EmptyDataError(ValueError):
    """The data source holds no scene."""


class DataSourceError(RuntimeError):
    """Reading a batch failed; the partial result (``status: failed``) has been written."""


class EvaluationInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`evaluate`; the partial result (``status: interrupted``) has been written."""

    def __init__(self, result: dict):
        super().__init__("interrupted")
        self.result = result


#: ``status`` of a finished result file; anything else (``running``: killed, ``interrupted``, ``failed``) is
#: not a result the leaderboard ranks without ``--include-incomplete``.
COMPLETE = "complete"


def _describe(exc: BaseException) -> str:
    """``Type: message`` of a method's exception; ``SystemExit`` (a method module calling ``sys.exit``) says so."""
    if isinstance(exc, SystemExit):
        return f"SystemExit: the method called sys.exit({exc.code!r}) (a method must return or raise, not exit)"
    return f"{type(exc).__name__}: {exc}"


# ----------------------------------------------------------------------------------------------- provenance
def _lfmbench_version() -> str:
    try:
        from importlib.metadata import version

        return version("lfmbench")
    except Exception:
        return "unknown"


def git_revision(path: str | Path | None = None) -> dict:
    """``{'commit': sha or 'unknown', 'dirty': bool | None}`` of the repository holding ``path`` (this package)."""
    where = Path(path or Path(__file__).resolve().parent)
    try:
        sha = subprocess.run(["git", "-C", str(where), "rev-parse", "HEAD"], capture_output=True, text=True,
                             timeout=10).stdout.strip()
        st = subprocess.run(["git", "-C", str(where), "status", "--porcelain", "--untracked-files=no"],
                            capture_output=True, text=True, timeout=10)
        return {"commit": sha if re.fullmatch(r"[0-9a-f]{40}", sha) else "unknown",
                "dirty": bool(st.stdout.strip()) if st.returncode == 0 else None}
    except (OSError, subprocess.SubprocessError):
        return {"commit": "unknown", "dirty": None}


def device_name(device: str | torch.device = "cpu") -> str:
    """Human-readable device name: the GPU's name, or the CPU model from /proc/cpuinfo."""
    dev = torch.device(device)
    if dev.type == "cuda" and torch.cuda.is_available():
        return torch.cuda.get_device_name(dev)
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return f"{line.split(':', 1)[1].strip()} ({os.cpu_count()} cores, {torch.get_num_threads()} threads)"
    except OSError:
        pass
    return platform.processor() or platform.machine()


def versions(perceptual: bool, cd_per_unit: float | None = None) -> dict:
    """Versions stored with every result: lfmbench, torch, numpy, python, metric versions, cvvdp config."""
    import numpy as np

    from lfmbench.metrics import hdr, metric_versions

    return {"lfmbench": _lfmbench_version(), "torch": torch.__version__, "numpy": np.__version__,
            "python": platform.python_version(), "metrics": metric_versions(),
            "cvvdp": hdr.cvvdp_config(cd_per_unit) if perceptual else None}


# ---------------------------------------------------------------------------------------------- cost counting
def method_module(method: Callable) -> torch.nn.Module | None:
    """The ``nn.Module`` behind a method: the method itself, or its ``torch_module`` attribute (a module or a
    zero-argument callable returning one)."""
    if isinstance(method, torch.nn.Module):
        return method
    mod = getattr(method, "torch_module", None)
    if mod is None:
        return None
    return mod if isinstance(mod, torch.nn.Module) else mod()


def count_params_macs(module: torch.nn.Module, run: Callable[[], Any]) -> tuple[int, int]:
    """(trainable + frozen parameter count, multiply-accumulates of one ``run()``).

    MACs are counted with forward hooks: Conv1d/2d/3d ``out.numel() * in_channels / groups * prod(kernel)``,
    Linear ``out.numel() * in_features`` (bias and activations not counted).
    """
    macs = 0

    def conv_hook(m, inp, out):
        nonlocal macs
        k = 1
        for s in m.kernel_size:
            k *= s
        macs += out.numel() * (m.in_channels // m.groups) * k

    def lin_hook(m, inp, out):
        nonlocal macs
        macs += out.numel() * m.in_features

    hooks = []
    for m in module.modules():
        if isinstance(m, (torch.nn.Conv1d, torch.nn.Conv2d, torch.nn.Conv3d)):
            hooks.append(m.register_forward_hook(conv_hook))
        elif isinstance(m, torch.nn.Linear):
            hooks.append(m.register_forward_hook(lin_hook))
    try:
        with torch.no_grad():
            run()
    finally:
        for h in hooks:
            h.remove()
    return sum(p.numel() for p in module.parameters()), int(macs)


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def time_method(method: Callable, batch: dict, warmup: int = 1, repeats: int = 5,
                device: str | torch.device = "cpu") -> list[float]:
    """Wall time (ms) of ``repeats`` calls after ``warmup`` calls, synchronised on CUDA."""
    dev = torch.device(device)
    with torch.no_grad():
        for _ in range(warmup):
            method(dict(batch))
        _sync(dev)
        out = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            method(dict(batch))
            _sync(dev)
            out.append((time.perf_counter() - t0) * 1e3)
    return out


# ----------------------------------------------------------------------------------------------------- core
def check_output(pred: Any, gt: torch.Tensor) -> torch.Tensor:
    """Validate a method's output against ``gt`` (B, F, 1, H, W); raise :class:`MethodOutputError`."""
    if not isinstance(pred, torch.Tensor):
        raise MethodOutputError(f"method returned {type(pred).__name__}, expected a torch.Tensor")
    if tuple(pred.shape) != tuple(gt.shape):
        raise MethodOutputError(f"method returned shape {tuple(pred.shape)}, expected {tuple(gt.shape)} (shape of gt)")
    if not pred.is_floating_point():
        raise MethodOutputError(f"method returned dtype {pred.dtype}, expected a floating-point tensor")
    finite = torch.isfinite(pred)
    if not bool(finite.all()):
        n_nan, n_inf = int(torch.isnan(pred).sum()), int(torch.isinf(pred).sum())
        raise MethodOutputError(f"method returned non-finite values: {n_nan} NaN, {n_inf} inf")
    return pred


def _scene_ids(batch: dict) -> list[str]:
    b = batch["gt"].shape[0]
    meta = batch.get("meta", {})
    ids = None
    if isinstance(meta, dict):
        ids = meta.get("scene_id")
    elif isinstance(meta, (list, tuple)) and meta and isinstance(meta[0], dict):
        ids = [m.get("scene_id") for m in meta]
    if isinstance(ids, str):
        ids = [ids]
    if not isinstance(ids, (list, tuple)) or len(ids) != b:
        ids = [None] * b
    return [str(i) if i is not None else None for i in ids]


def _to(batch: dict, device: torch.device) -> dict:
    return {k: (v.to(device) if isinstance(v, torch.Tensor) else v) for k, v in batch.items()}


def _jsonable(x: Any) -> Any:
    """Floats that JSON cannot hold (NaN, +-inf) become the strings 'nan', 'inf', '-inf'."""
    if isinstance(x, float):
        return x if math.isfinite(x) else ("nan" if math.isnan(x) else ("inf" if x > 0 else "-inf"))
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, torch.Tensor):
        return _jsonable(x.tolist())
    if isinstance(x, Path):
        return str(x)
    return x


def num(x: Any) -> float:
    """A metric value read back from a result file as float ('nan'/'inf' strings and None -> float)."""
    if x is None:
        return float("nan")
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def write_json_atomic(obj: dict, path: str | Path) -> Path:
    """Write JSON to ``path`` atomically (temporary file in the same directory, then ``os.replace``)."""
    path = Path(path)
    atomic_write_json(path, _jsonable(obj))
    return path


def _aggregate(scenes: list[dict]) -> dict:
    ok = [s for s in scenes if s.get("status") == "ok"]
    agg: dict[str, Any] = {"scenes": len(scenes), "scenes_ok": len(ok), "scenes_failed": len(scenes) - len(ok)}
    keys = [k for k in (ok[0]["metrics"] if ok else {}) if k != "lights"]
    for k in keys:
        vals = [num(s["metrics"].get(k)) for s in ok if not isinstance(s["metrics"].get(k), (bool, list, dict))]
        fin = [v for v in vals if math.isfinite(v) or math.isinf(v)]
        fin = [v for v in fin if not math.isnan(v)]
        if not fin:
            continue
        if k == "dropout_rate":  # pooled over all region-frames, not a mean of ratios
            rf = [(num(s["metrics"].get("region_frames")), num(s["metrics"].get(k))) for s in ok]
            tot = sum(n for n, v in rf if n > 0 and math.isfinite(v))
            agg[k] = sum(n * v for n, v in rf if n > 0 and math.isfinite(v)) / tot if tot else float("nan")
        else:
            agg[k] = statistics.fmean(fin)
    flags = [s["metrics"].get("saturation_flag") for s in ok if "saturation_flag" in s["metrics"]]
    if flags:
        agg["saturation_flag_scenes"] = int(sum(bool(f) for f in flags))
    return agg


def evaluate(method: Callable | str, batches: Iterable[dict], *, method_spec: str | None = None,
             output: str | Path | None = None, options=None, warmup: int = 1, repeats: int = 5,
             device: str | torch.device = "cpu", seeds: dict | None = None, dataset: dict | None = None,
             progress: bool = True, total: int | None = None) -> dict:
    """Evaluate one fusion method over a stream of batches.

    Args:
        method: callable ``batch -> (B, F, 1, H, W)`` or a spec (registered name / ``package.module:function``).
        batches: iterable of sample-dict batches (leading B); tensors are moved to ``device``.
        method_spec: the spec string stored in the result (default: ``method`` if it is a string).
        output: JSON path; rewritten atomically after every batch (partial results survive a crash).
        options: :class:`lfmbench.metrics.ScoreOptions`.
        warmup, repeats: timing protocol on the first batch the method handles (ms per output megapixel =
            median of ``repeats`` calls / (B x F x H x W / 1e6)).
        device: where the method and metrics run.
        seeds: stored as given (dataset seed, PWM seed, ...).
        dataset: description stored as given (corpus, split, ...).
        progress: tqdm progress bar.
        total: number of batches, for the progress bar.

    Returns:
        The result dict (also written to ``output``).

    Result ``status``: ``complete``; ``failed`` when no scene was scored (the method failed on every one) or
    the data source failed (:class:`DataSourceError`); ``interrupted`` after Ctrl-C
    (:class:`EvaluationInterrupted`, the partial result written first); ``running`` in a file whose run was
    killed. A method that calls ``sys.exit`` is recorded per scene like one that raises.

    Raises:
        EmptyDataError: if ``batches`` yields nothing.
        EvaluationInterrupted: on Ctrl-C (a ``KeyboardInterrupt``).
        lfmbench.baselines.MethodNotFoundError: for an unknown spec.
    """
    from lfmbench.baselines import get_method
    from lfmbench.metrics import ScoreOptions, hdr

    o = options or ScoreOptions()
    spec = method_spec or (method if isinstance(method, str) else getattr(method, "__qualname__", repr(method)))
    fn = get_method(method)
    dev = torch.device(device)
    result: dict[str, Any] = {
        "format": RESULT_FORMAT, "version": RESULT_VERSION,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "method": {"spec": spec, "params": None, "macs_per_call": None, "macs_per_megapixel": None},
        "dataset": dataset or {}, "seeds": seeds or {},
        "runtime": {"device": device_name(dev), "device_type": dev.type, "warmup": warmup, "repeats": repeats,
                    "ms_per_megapixel": None, "median_ms": None, "times_ms": None, "megapixels_per_call": None},
        "options": {"perceptual": o.perceptual, "fps": o.fps, "cd_per_unit": o.cd_per_unit,
                    "region": vars(o.region), "margin_px": o.margin_px, "ring_px": o.ring_px},
        "versions": versions(o.perceptual, o.cd_per_unit), "git": git_revision(),
        "command": " ".join(sys.argv), "status": "running", "notes": [], "aggregate": {}, "scenes": [],
    }
    perceptual = o.perceptual
    if perceptual:
        try:
            hdr.load_pycvvdp()
        except hdr.CvvdpUnavailableError as exc:
            perceptual = False
            result["notes"].append(f"perceptual metrics skipped: {exc}")
    base_opts = ScoreOptions(perceptual=False, fps=o.fps, cd_per_unit=o.cd_per_unit, region=o.region,
                             margin_px=o.margin_px, ring_px=o.ring_px)
    it = batches
    if progress:
        from tqdm import tqdm

        it = tqdm(batches, total=total, desc=f"evaluate {spec}", unit="batch")
    source = iter(it)
    try:
        n_batches = _run_batches(fn, source, result, output, dev, o, base_opts, perceptual, warmup, repeats)
    except KeyboardInterrupt:
        result["status"] = "interrupted"
        result["notes"].append(f"interrupted (Ctrl-C) after {len(result['scenes'])} scenes; not a complete result")
        result["aggregate"] = _aggregate(result["scenes"])
        if output is not None:
            write_json_atomic(result, output)
        raise EvaluationInterrupted(result) from None
    if n_batches == 0:
        raise EmptyDataError("the data source yielded no batch (empty corpus split?)")
    result["aggregate"] = _aggregate(result["scenes"])
    result["status"] = COMPLETE if result["aggregate"]["scenes_ok"] else "failed"
    if result["status"] == "failed":
        result["notes"].append("no scene was scored: the method failed on every scene")
    if output is not None:
        write_json_atomic(result, output)
    return result


def _run_batches(fn, source, result: dict, output, dev, o, base_opts, perceptual: bool, warmup: int,
                 repeats: int) -> int:
    """The loop of :func:`evaluate`: score every batch into ``result`` (rewritten to ``output`` after each);
    returns the number of batches."""
    from lfmbench.metrics import hdr, score_batch

    timed = False
    n_batches = 0
    while True:
        try:
            batch = next(source)
        except StopIteration:
            break
        except Exception as exc:  # the data source failed (corrupt file ...): save what we have, then stop
            result["status"] = "failed"
            result["notes"].append(f"data source failed after {n_batches} batches: {type(exc).__name__}: {exc}")
            result["aggregate"] = _aggregate(result["scenes"])
            if output is not None:
                write_json_atomic(result, output)
            raise DataSourceError(f"reading batch {n_batches} failed: {type(exc).__name__}: {exc}") from exc
        n_batches += 1
        batch = _to(batch, dev)
        if "gt" not in batch:
            raise ValueError(f"batch {n_batches - 1} has no 'gt' key (keys: {sorted(batch)})")
        gt = batch["gt"].clone()  # a method that edits its input in place must not change the reference
        ids = _scene_ids(batch)
        t0 = time.perf_counter()
        try:
            with torch.no_grad():
                pred = fn(dict(batch))
            _sync(dev)
            call_ms = (time.perf_counter() - t0) * 1e3
            pred = check_output(pred, gt)
        except (Exception, SystemExit) as exc:  # the method's failure is a result, not a crash
            status = "bad_output" if isinstance(exc, MethodOutputError) else "error"
            for i, sid in enumerate(ids):
                result["scenes"].append({"scene_id": sid, "index": len(result["scenes"]), "status": status,
                                         "error": _describe(exc)})
        else:
            try:
                scores = score_batch(pred, dict(batch, gt=gt), base_opts)
            except Exception as exc:
                scores = None
                for i, sid in enumerate(ids):
                    result["scenes"].append({"scene_id": sid, "index": len(result["scenes"]), "status": "metric_error",
                                             "error": f"{type(exc).__name__}: {exc}"})
            if scores is not None:
                if perceptual:
                    for name, f in (("pu21_psnr", lambda p, g: hdr.pu21_psnr(p, g, o.cd_per_unit, o.fps)),
                                    ("cvvdp_jod", lambda p, g: hdr.cvvdp_jod(p, g, o.fps, o.cd_per_unit))):
                        try:
                            v = f(pred, gt)
                            for s, x in zip(scores, v):
                                s[name] = float(x)
                        except Exception as exc:
                            for s in scores:
                                s[name] = float("nan")
                                s.setdefault("errors", []).append(f"{name}: {type(exc).__name__}: {exc}")
                mp = gt[0].numel() / 1e6
                for sid, s in zip(ids, scores):
                    result["scenes"].append({"scene_id": sid, "index": len(result["scenes"]), "status": "ok",
                                             "call_ms": call_ms / gt.shape[0], "megapixels": mp, "metrics": s})
                if not timed:
                    timed = True
                    try:
                        times = time_method(fn, batch, warmup=max(0, warmup - 1), repeats=repeats, device=dev)
                        med = statistics.median(times) if times else call_ms
                        mps = gt.numel() / 1e6
                        result["runtime"].update(times_ms=times, median_ms=med, megapixels_per_call=mps,
                                                 ms_per_megapixel=med / mps)
                        module = method_module(fn)
                        if module is not None:
                            params, macs = count_params_macs(module, lambda: fn(dict(batch)))
                            result["method"].update(params=params, macs_per_call=macs, macs_per_megapixel=macs / mps)
                    except (Exception, SystemExit) as exc:
                        result["notes"].append(f"timing failed: {_describe(exc)}")
        result["aggregate"] = _aggregate(result["scenes"])
        if output is not None:
            write_json_atomic(result, output)
    return n_batches


# ---------------------------------------------------------------------------------------------- data source
def make_dataset(corpus: str | Path, split: str = "test", seed: int = 0, crop: int | None = None, **kwargs):
    """``lfmbench.datasets.LFMCaptureDataset(corpus, split=split, seed=seed, ...)``, with clear errors."""
    root = Path(corpus)
    if not root.is_dir():
        raise FileNotFoundError(f"corpus directory {root} does not exist; render one first (see README)")
    from lfmbench.datasets import LFMCaptureDataset

    if crop is not None:
        kwargs["crop"] = crop
    ds = LFMCaptureDataset(root, split=split, seed=seed, **kwargs)
    if len(ds) == 0:
        raise EmptyDataError(f"corpus {root}: split {split!r} holds no scenes")
    return ds


def collate_samples(samples: list[dict]) -> dict:
    """Collate sample dicts into a batch: tensors stacked (default_collate), ``meta`` collated when its fields
    line up, else kept as a list of per-sample dicts."""
    from torch.utils.data import default_collate

    out = default_collate([{k: v for k, v in s.items() if k != "meta"} for s in samples])
    metas = [s.get("meta", {}) for s in samples]
    try:
        out["meta"] = default_collate(metas)
    except Exception:
        out["meta"] = metas
    return out


# ----------------------------------------------------------------------------------------------- leaderboard
def load_runs(paths: Iterable[str | Path]) -> list[dict]:
    """Read evaluation JSON files; raise ValueError naming a file that is not an lfmbench result."""
    runs = []
    for p in paths:
        p = Path(p)
        try:
            d = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"run file {p}: cannot read JSON ({type(exc).__name__}: {exc})") from None
        if not isinstance(d, dict) or d.get("format") != RESULT_FORMAT:
            fmt = d.get("format") if isinstance(d, dict) else None
            raise ValueError(f"run file {p}: not an {RESULT_FORMAT} result (format={fmt!r})")
        for key, typ in (("method", dict), ("runtime", dict), ("aggregate", dict), ("status", str)):
            if not isinstance(d.get(key), typ):
                raise ValueError(f"run file {p}: field {key!r} missing or not a{'n object' if typ is dict else ' string'}"
                                 " (a truncated or hand-made result?)")
        if not isinstance(d["method"].get("spec"), str):
            raise ValueError(f"run file {p}: field 'method.spec' missing")
        d["_path"] = str(p)
        runs.append(d)
    if not runs:
        raise ValueError("no run files given")
    return runs


def leaderboard_rows(runs: list[dict], sort_by: str = "psnr_mu") -> list[dict]:
    """One row per run, ranked by ``sort_by`` (direction from the metric registry; missing values last)."""
    from lfmbench.metrics import REGISTRY

    if sort_by not in REGISTRY:
        raise ValueError(f"sort_by must be a registered metric ({', '.join(REGISTRY)}), got {sort_by!r}")
    higher = REGISTRY[sort_by].higher_is_better
    rows = []
    for r in runs:
        agg = r.get("aggregate", {})
        row = {"method": r["method"]["spec"], "path": r.get("_path"), "device": r["runtime"].get("device"),
               "ms_per_megapixel": num(r["runtime"].get("ms_per_megapixel")),
               "params": r["method"].get("params"), "macs_per_megapixel": r["method"].get("macs_per_megapixel"),
               "scenes": agg.get("scenes", 0), "failed": agg.get("scenes_failed", 0), "status": r.get("status")}
        for k, _ in LEADERBOARD_COLUMNS:
            row[k] = num(agg.get(k))
        rows.append(row)

    def key(row):
        v = row[sort_by]
        if math.isnan(v):
            return (1, 0.0)
        return (0, -v if higher else v)

    rows.sort(key=lambda row: (row["status"] != COMPLETE, *key(row)))  # incomplete runs after complete ones
    for i, row in enumerate(rows):
        row["rank"] = i + 1
    return rows


def _status_mark(row: dict) -> str:
    """`` (interrupted)`` etc. after the method name of a run whose status is not ``complete``."""
    return "" if row.get("status") == COMPLETE else f" ({row.get('status')}: not a complete result)"


def incomplete_runs(runs: list[dict]) -> list[str]:
    """``"<path>: status <status>"`` for each run that is not complete (interrupted, failed, killed)."""
    return [f"{r.get('_path')}: status {r.get('status')!r}" for r in runs if r.get("status") != COMPLETE]


def _fmt(v: Any, nd: int = 3) -> str:
    if v is None:
        return "-"
    if isinstance(v, int):
        return f"{v:,}"
    v = float(v)
    if math.isnan(v):
        return "-"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{nd}f}" if abs(v) < 1e4 else f"{v:.3g}"


def _columns(rows: list[dict]) -> list[tuple[str, str]]:
    return [(k, h) for k, h in LEADERBOARD_COLUMNS if any(not math.isnan(r[k]) for r in rows)]


def leaderboard_markdown(rows: list[dict], sort_by: str = "psnr_mu") -> str:
    """The ranked table as GitHub Markdown."""
    cols = _columns(rows)
    head = ["#", "method"] + [h for _, h in cols] + ["ms/MP", "params", "MACs/MP", "failed"]
    lines = [f"Ranked by `{sort_by}`; run time = median ms per output megapixel after warm-up.", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [str(r["rank"]), f"`{r['method']}`" + _status_mark(r)] + [_fmt(r[k], 2 if k.startswith(("psnr", "pu21")) else 3)
                                                         for k, _ in cols]
        cells += [_fmt(r["ms_per_megapixel"], 1), _fmt(r["params"]), _fmt(r["macs_per_megapixel"], 0),
                  f"{r['failed']}/{r['scenes']}"]
        lines.append("| " + " | ".join(cells) + " |")
    devs = sorted({str(r["device"]) for r in rows})
    lines += ["", f"Device: {'; '.join(devs)}."]
    return "\n".join(lines) + "\n"


def plot_quality_vs_runtime(rows: list[dict], path: str | Path, metric: str = "psnr_mu") -> Path:
    """Scatter of ``metric`` against run time (ms per megapixel, log axis), one point per method (legend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lfmbench.metrics import REGISTRY

    fig, ax = plt.subplots(figsize=(7.6, 4.4), dpi=120)
    markers = "osD^vP*Xh<>p"
    for i, r in enumerate(rows):
        x, y = r["ms_per_megapixel"], r[metric]
        if math.isnan(x) or math.isnan(y) or x <= 0:
            continue
        # a legend rather than text labels: methods of similar cost and quality overlap
        ax.scatter([x], [y], s=40, marker=markers[i % len(markers)], label=f"{r.get('rank', i + 1)}. {r['method']}")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    ax.set_xscale("log")
    ax.margins(x=0.25, y=0.1)
    ax.set_xlabel("run time [ms per megapixel] (log)")
    spec = REGISTRY.get(metric)
    ax.set_ylabel(f"{metric} [{spec.unit}]" if spec else metric)
    ax.set_title(f"Quality vs run time ({'higher' if spec is None or spec.higher_is_better else 'lower'} is better)")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    path = atomic_save_figure(fig, path)
    plt.close(fig)
    return path


def print_leaderboard(rows: list[dict], sort_by: str = "psnr_mu", note: str = "") -> None:
    """Print the ranked rows as a rich table (the main columns; the Markdown file has them all)."""
    from rich.console import Console
    from rich.table import Table

    shown = ("psnr_mu", "ssim_mu", "cvvdp_jod", "mmp_pred", "dropout_rate", "ghost_mae_mu", sort_by)
    cols = [(k, h) for k, h in _columns(rows) if k in shown]
    console = Console()
    if not console.is_terminal:
        console = Console(width=160)
    table = Table(title=f"lfmbench leaderboard (ranked by {sort_by}{'; ' + note if note else ''})")
    for h in ["#", "method"] + [h for _, h in cols] + ["ms/MP", "params", "failed"]:
        table.add_column(h, justify="left" if h == "method" else "right", no_wrap=h == "method")
    for r in rows:
        table.add_row(str(r["rank"]), r["method"] + _status_mark(r), *[_fmt(r[k], 2 if k.startswith(("psnr", "pu21")) else 3)
                                                     for k, _ in cols],
                      _fmt(r["ms_per_megapixel"], 1), _fmt(r["params"]), f"{r['failed']}/{r['scenes']}")
    console.print(table)


def benchmark(corpus: str | Path, methods: Iterable[str] | None = None, runs_dir: str | Path = "runs",
              split: str = "test", seed: int = 0, crop: int | None = None, max_scenes: int | None = None,
              perceptual: bool = True, repeats: int = 5, device: str = "cpu", sort_by: str = "psnr_mu",
              progress: bool = True, samples_per_scene: int = 1) -> list[dict]:
    """Evaluate several methods on one corpus split and build the leaderboard (what ``make demo`` needs).

    Writes ``runs_dir/<method>.json`` per method, ``runs_dir/leaderboard.md`` and ``runs_dir/leaderboard.png``,
    prints the table and returns the ranked rows. ``methods`` defaults to every registered baseline.
    """
    from itertools import islice

    from torch.utils.data import DataLoader

    from lfmbench.baselines import REGISTRY
    from lfmbench.metrics import ScoreOptions

    runs_dir = Path(runs_dir)
    ds = make_dataset(corpus, split, seed=seed, crop=crop, samples_per_scene=samples_per_scene)
    n = len(ds) if max_scenes is None else min(len(ds), max_scenes)
    paths = []
    for m in (list(methods) if methods is not None else list(REGISTRY)):
        loader = DataLoader(ds, batch_size=1, shuffle=False, num_workers=0, collate_fn=collate_samples)
        out = runs_dir / f"{_safe_name(m)}.json"
        evaluate(m, islice(loader, n), method_spec=m, output=out, options=ScoreOptions(perceptual=perceptual),
                 repeats=repeats, device=device, seeds={"dataset": seed},
                 dataset={"corpus": str(corpus), "split": split, "scenes": n, "crop": crop,
                          "samples_per_scene": samples_per_scene}, progress=progress,
                 total=n)
        paths.append(out)
    rows = leaderboard_rows(load_runs(paths), sort_by)
    _write_text_atomic(leaderboard_markdown(rows, sort_by), runs_dir / "leaderboard.md")
    plot_quality_vs_runtime(rows, runs_dir / "leaderboard.png", sort_by)
    print_leaderboard(rows, sort_by, note=f"all columns in {runs_dir / 'leaderboard.md'}")
    return rows


def _write_text_atomic(text: str, path: str | Path) -> Path:
    atomic_write_text(path, text)
    return Path(path)


def _safe_name(spec: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", spec).strip("_") or "method"


# ------------------------------------------------------------------------------------------------------- CLI
def register(app) -> None:
    """Add the ``evaluate`` and ``leaderboard`` commands to the typer ``app``."""
    import typer

    @app.command("evaluate")
    def evaluate_cmd(
        method: str = typer.Option(..., "--method", "-m",
                                   help="registered name (e.g. lpd_only) or package.module:function"),
        corpus: Path = typer.Option(..., "--corpus", help="corpus root directory"),
        split: str = typer.Option("test", help="corpus split"),
        output: Path = typer.Option(None, "--output", "-o", help="result JSON (default runs/<method>.json)"),
        seed: int = typer.Option(0, help="dataset seed (PWM draws, noise)"),
        max_scenes: int = typer.Option(None, help="evaluate at most this many scenes"),
        crop: int = typer.Option(None, help="square crop in px passed to the dataset"),
        samples_per_scene: int = typer.Option(1, help="PWM draws per scene (test draws frozen in the corpus)"),
        repeats: int = typer.Option(5, help="timed calls after warm-up"),
        warmup: int = typer.Option(1, help="untimed warm-up calls"),
        perceptual: bool = typer.Option(True, help="also PU21-PSNR and ColorVideoVDP (needs cvvdp)"),
        device: str = typer.Option("cpu", help="torch device, e.g. cpu or cuda"),
        threads: int = typer.Option(None, help="torch CPU threads (default: torch's choice); recorded"),
        cache_dir: Path = typer.Option(None, "--cache-dir",
                                       help="projected-radiance cache directory (default <corpus>/.cache; "
                                            "any writable directory for a read-only corpus)"),
    ) -> None:
        """Score a fusion method on a corpus split; write per-scene and aggregate metrics as JSON.

        Exit status: 0 every scene scored, 1 some scenes failed or the data source failed (the result file
        says which), 2 bad input, 130 interrupted (the result file has status "interrupted").
        """
        def fail(msg: str, code: int = 2) -> None:
            typer.secho(f"error: {msg}", fg=typer.colors.RED, err=True)
            raise typer.Exit(code)

        if threads is not None:
            if threads < 1:
                fail(f"--threads must be >= 1, got {threads}")
            torch.set_num_threads(threads)
        for name, v, lo in (("--max-scenes", max_scenes, 1), ("--samples-per-scene", samples_per_scene, 1),
                            ("--repeats", repeats, 1), ("--warmup", warmup, 0), ("--crop", crop, 2)):
            if v is not None and v < lo:
                fail(f"{name} must be an integer >= {lo}, got {v}")
        try:
            dev = torch.device(device)
        except (RuntimeError, ValueError):
            fail(f"--device must be a torch device such as cpu, cuda or cuda:0, got {device!r}")
        if dev.type == "cuda" and not torch.cuda.is_available():
            fail(f"--device {device}: CUDA is not available on this machine (use --device cpu)")
        out = output or Path("runs") / f"{_safe_name(method)}.json"
        try:  # an unwritable --output is found before any work is done
            if out.is_dir():
                raise IsADirectoryError(21, "is a directory")
            out.parent.mkdir(parents=True, exist_ok=True)
            import tempfile

            with tempfile.TemporaryFile(dir=out.parent):
                pass
        except OSError as exc:
            fail(f"--output {out}: cannot write the result file there ({exc.strerror or exc})")
        from itertools import islice

        from torch.utils.data import DataLoader

        from lfmbench.baselines import MethodNotFoundError, get_method
        from lfmbench.metrics import ScoreOptions

        try:
            fn = get_method(method)
            extra = {} if cache_dir is None else {"cache_dir": cache_dir}
            ds = make_dataset(corpus, split, seed=seed, crop=crop, samples_per_scene=samples_per_scene, **extra)
        except (MethodNotFoundError, FileNotFoundError, EmptyDataError, RuntimeError, ValueError) as exc:
            fail(str(exc))
        n = len(ds) if max_scenes is None else min(len(ds), max_scenes)
        loader = DataLoader(ds, batch_size=1, shuffle=False, num_workers=0, collate_fn=collate_samples)
        try:
            res = evaluate(fn, islice(loader, n), method_spec=method, output=out,
                           options=ScoreOptions(perceptual=perceptual), warmup=warmup, repeats=repeats, device=device,
                           seeds={"dataset": seed}, dataset={"corpus": str(corpus), "split": split, "scenes": n,
                                                             "crop": crop}, total=n)
        except EvaluationInterrupted as exc:
            n_done = len(exc.result["scenes"])
            typer.secho(f"interrupted: {n_done} scene(s) scored; {out} is marked status \"interrupted\" "
                        "(the leaderboard skips it); run the command again for a complete result",
                        fg=typer.colors.YELLOW, err=True)
            raise typer.Exit(130) from None
        except (DataSourceError, EmptyDataError) as exc:
            fail(f"{exc} (partial results in {out})", 1)
        except OSError as exc:  # the result file could not be written (disk full, ...)
            fail(f"{exc.filename}: {exc.strerror or exc}" if exc.filename else (exc.strerror or str(exc)))
        agg = res["aggregate"]
        typer.echo(f"{method}: {agg.get('scenes_ok', 0)}/{agg.get('scenes', 0)} scenes ok, PSNR-mu "
                   f"{_fmt(agg.get('psnr_mu'), 2)} dB, MMP {_fmt(agg.get('mmp_pred'))}, "
                   f"{_fmt(res['runtime']['ms_per_megapixel'], 1)} ms/MP -> {out}")
        bad = [sc for sc in res["scenes"] if sc.get("status") != "ok"]
        if bad:
            fail(f"{len(bad)} of {len(res['scenes'])} scenes failed (first: scene {bad[0].get('scene_id')}: "
                 f"{bad[0].get('error', bad[0].get('status'))}); see {out}", 1)

    @app.command("leaderboard")
    def leaderboard_cmd(
        runs: list[Path] = typer.Argument(..., help="evaluation JSON files, e.g. runs/*.json"),
        sort_by: str = typer.Option("psnr_mu", help="metric to rank by"),
        markdown: Path = typer.Option(Path("runs/leaderboard.md"), help="Markdown table output"),
        plot: Path = typer.Option(Path("runs/leaderboard.png"), help="quality-vs-run-time PNG output"),
        include_incomplete: bool = typer.Option(False, "--include-incomplete",
                                                help="rank interrupted or failed runs too (marked in the table)"),
    ) -> None:
        """Rank evaluation results; print a table, write Markdown and a quality-vs-run-time plot.

        Runs whose status is not "complete" (interrupted, failed, or killed while "running") are refused unless
        --include-incomplete, which ranks them after the complete ones and marks them.
        """
        try:
            loaded = load_runs(p for p in runs if p.suffix == ".json")
            bad = incomplete_runs(loaded)
            if bad and not include_incomplete:
                raise ValueError(f"{len(bad)} run file(s) are not complete results ({'; '.join(bad[:3])}"
                                 f"{' ...' if len(bad) > 3 else ''}); re-run them, leave them out, or pass "
                                 "--include-incomplete to rank them marked")
            rows = leaderboard_rows(loaded, sort_by)
        except ValueError as exc:
            typer.secho(f"error: {exc}", fg=typer.colors.RED, err=True)
            raise typer.Exit(2) from None
        print_leaderboard(rows, sort_by, note=f"all columns in {markdown}")
        try:
            _write_text_atomic(leaderboard_markdown(rows, sort_by), markdown)
            plot_quality_vs_runtime(rows, plot, sort_by)
        except OSError as exc:
            typer.secho(f"error: {exc}", fg=typer.colors.RED, err=True)
            raise typer.Exit(2) from None
        typer.echo(f"wrote {markdown} and {plot}")
