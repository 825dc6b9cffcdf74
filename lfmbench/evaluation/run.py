"""Run fusion methods over a stream of batches and score them: :func:`evaluate` (one method) and
:func:`evaluate_methods` (several methods on one pass over the data: each sample is read and simulated once and
shared by all of them).

The data source is injectable (any iterable of sample-dict batches, ``docs/guide/contracts.md`` section 3). Every
scene is scored with :func:`lfmbench.metrics.score_batch`; the method is timed (warm-up, then the median of
repeated synchronised calls, in ms per output megapixel) and its parameters and MACs counted when it is an
``nn.Module``; versions, seeds, device, git revision and the corpus identity are recorded; the JSON result is
written atomically after every batch. A method that raises, returns a wrong shape, NaN or inf is recorded per
scene (``status``) and the run goes on. At the end the result gets per-scene values, bootstrap confidence
intervals over scenes and the breakdown of the primary score by condition (``docs/guide/metrics.md``).

Resume (``resume=True``): a result file of the same evaluation (:func:`lfmbench.evaluation.results.differing_field`)
that a killed, interrupted or failed run left keeps its sample records, and only the samples after them are scored.
Every statistic is a function of the ordered sample records and every sample's numbers depend only on (dataset
seed, sample index), so the finished file equals an uninterrupted run's in every score (as merged shards do).
"""
from __future__ import annotations

import copy
import dataclasses
import datetime as _dt
import statistics
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import torch

from lfmbench.baselines.checkpoint import CheckpointError
from lfmbench.datasets.loading import EmptyDataError
from lfmbench.evaluation import stats
from lfmbench.evaluation.conditions import load_bins, sample_conditions
from lfmbench.evaluation.cost import count_params_macs, method_module, quartiles, sync, time_method, time_moved
from lfmbench.evaluation.provenance import device_name, git_revision, versions
from lfmbench.evaluation.results import (COMPLETE, RESULT_FORMAT, RESULT_VERSION, aggregate, breakdown, per_scene,
                                         write_json_atomic)

__all__ = ["evaluate", "evaluate_methods", "check_output", "MethodOutputError", "EmptyDataError", "DataSourceError",
           "EvaluationInterrupted", "ResumeError"]

#: A data source: batches, or ``start -> batches`` from sample ``start`` of the evaluation's order on (a resumed
#: run then reads only the samples it misses).
Batches = Iterable[dict] | Callable[[int], Iterable[dict]]


class MethodOutputError(ValueError):
    """A method returned something that is not a finite (B, F, 1, H, W) tensor shaped like ``gt``."""


class DataSourceError(RuntimeError):
    """Reading a batch failed; the partial result (``status: failed``) has been written."""


class ResumeError(ValueError):
    """A result file where a resumed evaluation would write that is not a run of this evaluation (another corpus,
    seed, method, options ...; not a result); the message names the file and the field. Nothing was written."""


class EvaluationInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`evaluate`; the partial result (``status: interrupted``) has been written.
    ``result``: the (first) method's partial result; ``results``: every method's (:func:`evaluate_methods`)."""

    def __init__(self, result: dict, results: list[dict] | None = None):
        super().__init__("interrupted")
        self.result = result
        self.results = results if results is not None else [result]


def _describe(exc: BaseException) -> str:
    """``Type: message`` of a method's exception; ``SystemExit`` (a method module calling ``sys.exit``) says so."""
    if isinstance(exc, SystemExit):
        return f"SystemExit: the method called sys.exit({exc.code!r}) (a method must return or raise, not exit)"
    return f"{type(exc).__name__}: {exc}"


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


def evaluate(method: Callable | str, batches: Batches, *, method_spec: str | None = None,
             output: str | Path | None = None, options=None, warmup: int = 1, repeats: int = 5,
             device: str | torch.device = "cpu", seeds: dict | None = None, dataset: dict | None = None,
             progress: bool = True, total: int | None = None, corpus: dict | None = None,
             scene_conditions: Callable[[str], dict] | None = None, conditions_file: str | Path | None = None,
             resume: bool = False, log: Callable[[str], None] | None = print) -> dict:
    """Evaluate one fusion method over a stream of batches.

    Args:
        method: callable ``batch -> (B, F, 1, H, W)`` or a spec (registered name / ``package.module:function``).
        batches: iterable of sample-dict batches (leading B); tensors are moved to ``device``. Or a callable
            ``start -> batches`` yielding the samples from position ``start`` of the evaluation's order on
            (:data:`Batches`; ``start`` > 0 only when resuming).
        method_spec: the spec string stored in the result (default: ``method`` if it is a string).
        output: JSON path; rewritten atomically after every batch (partial results survive a crash).
        options: :class:`lfmbench.metrics.ScoreOptions`.
        warmup, repeats: timing protocol on the first batch the method handles (ms per output megapixel =
            median of ``repeats`` calls / (B x F x H x W / 1e6); ``runtime.iqr_ms_per_megapixel`` their
            interquartile range; ``runtime.threads`` torch's CPU threads; ``runtime.time_moved`` whether the
            scored calls' median left that range, :func:`lfmbench.evaluation.cost.time_moved`).
        device: where the method and metrics run.
        seeds: stored as given (dataset seed, PWM seed, ...).
        dataset: description stored as given (corpus, split, ...).
        progress: a progress bar (:func:`lfmbench.progress.track`: live on a terminal, a few plain lines in a
            log).
        total: number of batches, for the progress bar.
        corpus: the corpus identity (:func:`lfmbench.evaluation.provenance.corpus_identity`) stored as
            ``corpus``; None for a data source that is not a corpus (the leaderboard then ranks the result only
            with other results without a corpus).
        scene_conditions: ``scene_id -> {"time_of_day", "ego_speed_mps"}`` stored with every sample record
            (:func:`lfmbench.evaluation.conditions.corpus_scene_conditions`); PWM duty and frequency come from
            the batch ``meta``.
        conditions_file: bins of the breakdown by condition (default ``lfmbench/configs/conditions.yaml``).
        resume: continue ``output`` when it holds a result of this evaluation (same ``dataset``, shard included,
            and :data:`lfmbench.evaluation.results.SAME_FIELDS`; the same checkpoint file): its sample records are
            kept and only the samples after them scored; a ``complete`` one is returned as it is, unscored. A
            batch must not hold both recorded and missing samples (batches of one never do). False: start
            again, overwriting ``output``.
        log: one line per file resumed, one line for all the methods skipped (None: silent).

    Returns:
        The result dict (also written to ``output``).

    Result ``status``: ``complete``; ``failed`` when no scene was scored (the method failed on every one) or
    the data source failed (:class:`DataSourceError`); ``interrupted`` after Ctrl-C
    (:class:`EvaluationInterrupted`, the partial result written first); ``running`` in a file whose run was
    killed. A method that calls ``sys.exit`` is recorded per scene like one that raises.

    Raises:
        EmptyDataError: if ``batches`` yields nothing (and nothing was recorded before a resume).
        EvaluationInterrupted: on Ctrl-C (a ``KeyboardInterrupt``).
        ResumeError: ``resume`` and ``output`` holds a result of another evaluation, or no result.
        lfmbench.baselines.MethodNotFoundError: for an unknown spec.
    """
    return evaluate_methods([method], batches, method_specs=[method_spec], outputs=[output], options=options,
                            warmup=warmup, repeats=repeats, device=device, seeds=seeds, dataset=dataset,
                            progress=progress, total=total, corpus=corpus, scene_conditions=scene_conditions,
                            conditions_file=conditions_file, resume=resume, log=log)[0]


def evaluate_methods(methods: Sequence[Callable | str], batches: Batches, *,
                     method_specs: Sequence[str | None] | None = None,
                     outputs: Sequence[str | Path | None] | None = None, options=None, warmup: int = 1,
                     repeats: int = 5, device: str | torch.device = "cpu", seeds: dict | None = None,
                     dataset: dict | None = None, progress: bool = True, total: int | None = None,
                     corpus: dict | None = None, scene_conditions: Callable[[str], dict] | None = None,
                     conditions_file: str | Path | None = None, resume: bool = False,
                     log: Callable[[str], None] | None = print) -> list[dict]:
    """Evaluate several fusion methods on ONE pass over the batches: each batch is read (simulated) once and
    scored for every method, one batch in memory at a time.

    Every method gets its own copy of the batch (``copy.deepcopy``, the last method the original), so a method that
    edits its input cannot change what the next one sees; the scores are those of :func:`evaluate` run once per
    method over the same data (a test compares them sample by sample). Arguments as :func:`evaluate`, per method
    in ``method_specs`` and ``outputs`` (one result file each, rewritten after every batch). With ``resume``, every
    file is checked before any is written; a method with a complete file is skipped, and only the samples missing
    for at least one method are read (a callable ``batches`` from the first of them on), each method scoring those
    it misses.

    Returns:
        The result dicts, in the order of ``methods``.

    Raises:
        EmptyDataError, EvaluationInterrupted (its ``results`` holds every method's partial result),
        DataSourceError (every method's partial result written first), ResumeError, MethodNotFoundError: as
        :func:`evaluate`.
    """
    from lfmbench.baselines import get_method
    from lfmbench.metrics import PRIMARY, ScoreOptions, hdr

    methods = list(methods)
    if not methods:
        raise ValueError("methods must name at least one method")
    specs = list(method_specs) if method_specs is not None else [None] * len(methods)
    outs = list(outputs) if outputs is not None else [None] * len(methods)
    if len(specs) != len(methods) or len(outs) != len(methods):
        raise ValueError(f"method_specs and outputs must have one entry per method ({len(methods)})")
    o = options or ScoreOptions()
    fns = [get_method(m) for m in methods]  # every method (and checkpoint) is found before any data is read
    bins = load_bins(conditions_file)
    dev = torch.device(device)
    notes: list[str] = []
    perceptual = o.perceptual
    if perceptual:
        try:
            hdr.load_pycvvdp()
        except hdr.CvvdpUnavailableError as exc:
            perceptual = False
            notes.append(f"perceptual metrics skipped: {exc}")
    opts = dataclasses.replace(o, perceptual=perceptual)
    if o.isp is not None:  # a bad pipeline file is bad input, found before any data is read
        from lfmbench.isp import load_pipeline

        isp_id = load_pipeline(o.isp).identity()
    else:
        isp_id = None
    runs = []
    for m, fn, spec, out in zip(methods, fns, specs, outs):
        spec = spec or (m if isinstance(m, str) else getattr(m, "__qualname__", repr(m)))
        runs.append(_MethodRun(fn, spec, out, o, opts, warmup, repeats, dev, seeds, dataset, corpus, notes))
        if isp_id is not None:
            runs[-1].result["options"]["isp"] = isp_id
    done = [r.resume(fn, log) for r, fn in zip(runs, fns)] if resume else [False] * len(runs)  # all checked first
    todo = [r for r, d in zip(runs, done) if not d]
    skipped = [r for r, d in zip(runs, done) if d]
    if skipped and log:  # one line, however many methods
        where = {str(Path(r.output).parent) for r in skipped}
        log(f"{', '.join(r.spec for r in skipped)} skipped: complete result(s) of this evaluation in "
            f"{where.pop() if len(where) == 1 else ', '.join(str(r.output) for r in skipped)} (--no-resume scores "
            "them again)")
    if not todo:
        return [r.result for r in runs]
    from lfmbench.progress import track

    start = min(r.kept for r in todo) if callable(batches) else 0
    desc = f"evaluate {todo[0].spec}" if len(todo) == 1 else f"evaluate {len(todo)} methods"
    tracked = track(batches(start) if callable(batches) else batches, total=total, description=desc, unit="batch",
                    enabled=progress)
    if start:
        tracked.bar.set(start)  # batches of one: the samples kept are the batches done
    source = iter(tracked)
    try:
        n_batches = _run_batches(todo, source, dev, scene_conditions, start)
    except KeyboardInterrupt:
        for r in todo:
            r.result["status"] = "interrupted"
            r.result["notes"].append(f"interrupted (Ctrl-C) after {len(r.result['scenes'])} scenes; not a complete "
                                     "result")
            _finish(r.result, bins, PRIMARY)
            r.write()
        raise EvaluationInterrupted(todo[0].result, [r.result for r in runs]) from None
    if n_batches == 0 and not any(r.kept for r in todo):
        raise EmptyDataError("the data source yielded no batch (empty corpus split?)")
    for r in todo:
        _finish(r.result, bins, PRIMARY)
        r.result["status"] = COMPLETE if r.result["aggregate"]["scenes_ok"] else "failed"
        if r.result["status"] == "failed":
            r.result["notes"].append("no scene was scored: the method failed on every scene")
        r.write()
    return [r.result for r in runs]


def _finish(result: dict, bins: dict, metric: str) -> None:
    """Final statistics of a result: aggregate with bootstrap CIs, per-scene values, breakdown of ``metric``, and
    the check of the timing against the scored calls (:func:`lfmbench.evaluation.cost.time_moved`)."""
    rt = result["runtime"]
    scored = [rec["call_ms"] / rec["megapixels"] for rec in result["scenes"][1:]  # the first call warmed up
              if rec.get("status") == "ok" and rec.get("call_ms") is not None and rec.get("megapixels")]
    if scored and rt.get("times_ms"):
        rt["scored_ms_per_megapixel"] = statistics.median(scored)
        mps = rt["megapixels_per_call"]
        rt["time_moved"] = time_moved([t / mps for t in rt["times_ms"]], scored)
    result["aggregate"] = aggregate(result["scenes"], ci=True)
    result["per_scene"] = per_scene(result["scenes"])
    result["breakdown"] = {"metric": metric, "bins": bins, "by": breakdown(result["scenes"], metric, bins)}


class _MethodRun:
    """One method's part of an evaluation: its result dict (written to ``output`` after every batch), the timing
    state, and :meth:`score` for one batch."""

    def __init__(self, fn, spec: str, output, o, opts, warmup: int, repeats: int, dev: torch.device,
                 seeds: dict | None, dataset: dict | None, corpus: dict | None, notes: list[str]) -> None:
        self.fn, self.spec, self.output, self.opts = fn, spec, output, opts
        self.warmup, self.repeats, self.dev, self.timed = warmup, repeats, dev, False
        self.kept = 0  # sample records taken over from a resumed file: the first ``kept`` samples are not scored
        self.result: dict[str, Any] = {
            "format": RESULT_FORMAT, "version": RESULT_VERSION,
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "method": {"spec": spec, "params": None, "macs_per_call": None, "macs_per_megapixel": None},
            "dataset": dict(dataset or {}), "corpus": corpus, "seeds": dict(seeds or {}),
            "runtime": {"device": device_name(dev), "device_type": dev.type, "warmup": warmup, "repeats": repeats,
                        "ms_per_megapixel": None, "median_ms": None, "times_ms": None, "megapixels_per_call": None,
                        "iqr_ms": None, "iqr_ms_per_megapixel": None, "threads": torch.get_num_threads(),
                        "interop_threads": torch.get_num_interop_threads(), "scored_ms_per_megapixel": None,
                        "time_moved": None},
            "options": {"perceptual": o.perceptual, "fps": o.fps, "cd_per_unit": o.cd_per_unit,
                        "region": vars(o.region), "margin_px": o.margin_px, "ring_px": o.ring_px,
                        # only when not the default: results scored against their own gt keep their options
                        **({"reference": o.reference} if o.reference != "own" else {})},
            "versions": versions(o.perceptual, o.cd_per_unit), "git": git_revision(),
            "command": " ".join(sys.argv), "status": "running", "notes": list(notes), "statistics": stats.settings(),
            "aggregate": {}, "per_scene": [], "breakdown": {}, "scenes": [],
        }

    def write(self) -> None:
        if self.output is not None:
            write_json_atomic(self.result, self.output)

    def resume(self, fn, log: Callable[[str], None] | None) -> bool:
        """Take over the sample records (``self.kept``), timing and costs of the result file ``output`` when it
        holds a run of this evaluation; True when that run is complete (its result becomes ``self.result``, the
        file is left as it is). No file: False, nothing kept.

        Raises:
            ResumeError: the file is not a result, is another evaluation's (the field named), its method's
                checkpoint file has changed since, or its records are not in sample order.
        """
        from lfmbench.evaluation.provenance import file_sha256
        from lfmbench.evaluation.results import differing_field
        from lfmbench.fileio import load_json_input

        if self.output is None or not Path(self.output).is_file():
            return False  # nothing to continue; a device, FIFO or folder is left to the writer, which names it
        again = "; pass --no-resume to start again (the file is overwritten) or choose another output file"
        try:
            old = load_json_input(self.output, "result file")
        except ValueError as exc:
            raise ResumeError(f"{exc}{again}") from None
        if not isinstance(old, dict) or old.get("format") != RESULT_FORMAT or not isinstance(old.get("scenes"), list):
            raise ResumeError(f"result file {self.output}: not an {RESULT_FORMAT} result{again}")
        field = differing_field(self.result, old)
        ck = (old.get("method") or {}).get("checkpoint") or {}
        path = getattr(fn, "checkpoint_path", None)
        if field is None and ck.get("file_sha256") and callable(path) and Path(path()).is_file() \
                and file_sha256(path()) != ck["file_sha256"]:
            field = "method.checkpoint"  # the same method name with other weights: another evaluation
        if field is not None:
            raise ResumeError(f"result file {self.output} holds another evaluation (field {field!r} differs){again}")
        if any(not isinstance(rec, dict) or rec.get("index") != i for i, rec in enumerate(old["scenes"])):
            raise ResumeError(f"result file {self.output}: its sample records are not in sample order{again}")
        if old.get("status") == COMPLETE:  # skipped: evaluate_methods says so once for all such methods
            self.result = old
            return True
        self.kept = len(old["scenes"])
        self.result["scenes"] = old["scenes"]
        self.result["created"] = old.get("created", self.result["created"])
        if (old.get("runtime") or {}).get("times_ms"):  # timed on its first scored batch, as an uninterrupted run
            self.result["runtime"], self.result["method"], self.timed = old["runtime"], old["method"], True
        self.result["notes"].append(f"resumed: {self.kept} sample record(s) kept from a run with status "
                                    f"{old.get('status')!r}")
        if log:
            log(f"resuming {self.output} ({old.get('status')}): {self.kept} sample(s) recorded, scoring the rest")
        return False

    def _record(self, ids: list, conds: list[dict], **fields) -> None:
        for sid, c in zip(ids, conds):
            self.result["scenes"].append({"scene_id": sid, "index": len(self.result["scenes"]), **fields,
                                          "conditions": dict(c)})

    def score(self, batch: dict, ids: list, conds: list[dict]) -> None:
        """Run the method on one batch (on the device), score it into the result and rewrite the file."""
        from lfmbench.metrics import score_batch

        fn, dev = self.fn, self.dev
        gt = batch["gt"].clone()  # a method that edits its input in place must not change the reference
        t0 = time.perf_counter()
        try:
            with torch.no_grad():
                pred = fn(dict(batch))
            sync(dev)
            call_ms = (time.perf_counter() - t0) * 1e3
            self._record_checkpoint()
            pred = check_output(pred, gt)
        except CheckpointError:  # the method's weights file is bad input, not a scene failure: stop here
            raise
        except (Exception, SystemExit) as exc:  # the method's failure is a result, not a crash
            status = "bad_output" if isinstance(exc, MethodOutputError) else "error"
            self._record(ids, conds, status=status, error=_describe(exc))
        else:
            try:
                scores = score_batch(pred, dict(batch, gt=gt), self.opts)
            except Exception as exc:
                self._record(ids, conds, status="metric_error", error=f"{type(exc).__name__}: {exc}")
            else:
                mp = gt[0].numel() / 1e6
                for sid, s, c in zip(ids, scores, conds):
                    self.result["scenes"].append({"scene_id": sid, "index": len(self.result["scenes"]),
                                                  "status": "ok", "call_ms": call_ms / gt.shape[0], "megapixels": mp,
                                                  "metrics": s, "conditions": dict(c)})
                if not self.timed:
                    self.timed = True
                    self._time(batch, call_ms, gt)
        self.result["aggregate"] = aggregate(self.result["scenes"])
        self.write()

    def _record_checkpoint(self) -> None:
        """``method.checkpoint``: path and SHA-256 (content, file) of the weights a checkpoint-backed method ran
        with (verified when loaded); a result names the weights its numbers come from."""
        prov = getattr(self.fn, "checkpoint_provenance", None)
        rec = prov() if callable(prov) else None
        if rec is not None:
            self.result["method"]["checkpoint"] = rec

    def _time(self, batch: dict, call_ms: float, gt: torch.Tensor) -> None:
        fn, res = self.fn, self.result
        try:
            times = time_method(fn, batch, warmup=max(0, self.warmup - 1), repeats=self.repeats, device=self.dev)
            med = statistics.median(times) if times else call_ms
            q25, q75 = quartiles(times) if times else (call_ms, call_ms)
            mps = gt.numel() / 1e6
            res["runtime"].update(times_ms=times, median_ms=med, megapixels_per_call=mps, ms_per_megapixel=med / mps,
                                  iqr_ms=[q25, q75], iqr_ms_per_megapixel=[q25 / mps, q75 / mps])
            module = method_module(fn)
            if module is not None:
                params, macs = count_params_macs(module, lambda: fn(dict(batch)))
                res["method"].update(params=params, macs_per_call=macs, macs_per_megapixel=macs / mps)
        except (Exception, SystemExit) as exc:
            res["notes"].append(f"timing failed: {_describe(exc)}")


def _run_batches(runs: list[_MethodRun], source, dev, scene_conditions: Callable[[str], dict] | None,
                 start: int = 0) -> int:
    """The loop of :func:`evaluate_methods`: read each batch once, score it for every method that has not recorded
    its samples (:attr:`_MethodRun.kept`; the source begins at sample ``start``), each result rewritten after each
    batch, without the bootstrap, which runs once at the end; returns the number of batches."""
    n_batches, at = 0, start
    while True:
        try:
            batch = next(source)
        except StopIteration:
            break
        except Exception as exc:  # the data source failed (corrupt file ...): save what we have, then stop
            from lfmbench.limits import one_line  # noqa: PLC0415 - a DataLoader worker's error: its own message

            why = f"{type(exc).__name__}: {one_line(str(exc))}"
            for r in runs:
                r.result["status"] = "failed"
                r.result["notes"].append(f"data source failed after {n_batches} batches: {why}")
                r.result["aggregate"] = aggregate(r.result["scenes"])
                r.write()
            raise DataSourceError(f"reading batch {n_batches} failed: {why}") from exc
        n_batches += 1
        batch = _to(batch, dev)
        if "gt" not in batch:
            raise ValueError(f"batch {n_batches - 1} has no 'gt' key (keys: {sorted(batch)})")
        ids = _scene_ids(batch)
        conds = sample_conditions(batch)
        for sid, c in zip(ids, conds):
            if scene_conditions is not None and sid is not None:
                c.update(scene_conditions(sid))
        first, at = at, at + len(ids)
        scoring = [r for r in runs if r.kept < at]  # a resumed method scores only the samples it misses
        for r in scoring:
            if r.kept > first:
                raise ValueError(f"resume: batch {n_batches - 1} holds samples {first}..{at - 1}, of which "
                                 f"{r.output} has recorded the first {r.kept - first}; resume needs batches that "
                                 "begin where a file's records end (batches of one do)")
        for i, r in enumerate(scoring):
            # each method its own copy (the last one the original): an in-place edit cannot reach the next method
            r.score(batch if i == len(scoring) - 1 else copy.deepcopy(batch), ids, conds)
    return n_batches
