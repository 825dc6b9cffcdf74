"""Render jobs for ``lfmbench render``: job list, local process pool or Ray cluster, resume, atomic corpus writes.

One job = one scene: generate (or load) the scene, render every frame with
``render_tools.render.render_frames``, encode the EXRs (:func:`lfmbench.corpus.encode_scene`) and write them
atomically into the corpus (:func:`lfmbench.corpus.write_files`); encoding and writing run in a worker thread
(:class:`lfmbench.corpus.ThreadedSceneWriter`) while the next frame renders in the calling thread. Workers write the files themselves (the
output directory must be visible to them: the local machine, or a shared file system on a Ray cluster) and
return the files' SHA-256; only the driver touches ``manifest.json``, rewriting it atomically after each
finished scene. So a crash or Ctrl-C leaves a valid corpus: finished scenes are in the manifest with their
checksums, an unfinished one is not (its partial files are overwritten on resume, stray temporary files
removed), and re-running the same command skips every scene whose files match the manifest.

Seeds: scene i of a run with ``--seed K`` uses ``scene_seed(K, i)`` (a ``numpy.random.SeedSequence`` child),
so scene i is the same whatever ``--scenes N`` is and a run can be extended by raising N. A benchmark protocol
(:mod:`render_tools.protocol`, :func:`protocol_jobs`) gives every scene its id, seed, pinned conditions and
split instead; ``splits.json`` then comes from the protocol, not from :func:`lfmbench.corpus.make_splits`.

Over 500 lines for now: the job list, the local pool, the Ray driver and the resume logic are kept together while
the render orchestration is being reworked; the pool and the Ray driver are to become modules of their own.
"""
from __future__ import annotations

import contextlib
import functools
import json
import logging
import pickle
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from lfmbench.corpus import (DEFAULT_STORAGE, SPLITS_NAME, CorpusWriteError, CorpusWriter, ThreadedSceneWriter,
                             check_scene_id, prune_scene_dir)
from lfmbench.fileio import atomic_write_json

from . import reflections
from .ray_jobs import CompleteScenes, RayOptions, run_ray
from .workers import WorkerDied, run_supervised

__all__ = ["PROFILES_FILE", "Backend", "default_backend", "load_profile", "profile_names", "scene_seed",
           "scene_id_for", "RenderRequest", "RenderRequestError", "RenderPlan", "plan_render", "CONFIRM_ABOVE",
           "MAX_SCENES", "PROTOCOL_FIXED",
           "RenderJob", "make_jobs", "protocol_jobs", "write_splits", "run_job", "RunSummary", "run_jobs",
           "RenderInterrupted", "RayOptions", "LayerJob", "run_layer_job", "add_layers"]

log = logging.getLogger(__name__)

#: Render profiles (``--profile small|default``): plain YAML, keys are RenderOptions fields.
PROFILES_FILE = Path(__file__).with_name("configs") / "render_profiles.yaml"
#: Fractions of the train / val / test split written to ``splits.json``.
SPLIT_FRACTIONS = (0.6, 0.2, 0.2)
#: Default of ``run_jobs(isolate=...)``: render in worker processes also with ``workers=1``, so that a native
#: crash of the renderer (SIGFPE, SIGSEGV, out-of-memory kill) is reported with its scene and signal and the
#: other scenes go on (render_tools.workers). Tests of in-process fakes set it to False.
ISOLATE_RENDERS = True


@dataclass(frozen=True)
class Backend:
    """The renderer a job calls (``render_tools.scene`` + ``render_tools.render`` by default):
    ``generate_scene(seed, scene_id=..., **kw) -> dict``, ``RenderOptions(**fields)``,
    ``scene_meta(scene, opts) -> dict``,
    ``render_frames(scene, opts) -> Iterator[frame dict]``; optional ``validate_scene(scene) -> dict`` and
    ``render_layer(scene, opts, layer) -> Iterator[{"frame", "static"}]`` (a static window layer; default
    :func:`render_tools.static_layers.render_layer`)."""

    generate_scene: Callable[..., dict]
    RenderOptions: Callable[..., Any]
    scene_meta: Callable[[dict, Any], dict]
    render_frames: Callable[[dict, Any], Any]
    validate_scene: Callable[[dict], Any] | None = None
    render_layer: Callable[[dict, Any, tuple], Any] | None = None


def default_backend() -> Backend:
    """Import the Mitsuba renderer (heavy: only inside jobs and commands)."""
    from render_tools import render, scene  # noqa: PLC0415

    validate = getattr(scene, "validate_scene", None)
    # the corpus writer takes a wet road's grown light crops as SteadyBins (no K copies of a reflection in memory)
    frames = functools.partial(render.render_frames, steady_bins=True)
    return Backend(scene.generate_scene, render.RenderOptions, render.scene_meta, frames, validate)


def profile_names() -> list[str]:
    """Names of the render profiles in :data:`PROFILES_FILE`, in file order (``--profile`` help, checks)."""
    from lfmbench.fileio import load_yaml  # noqa: PLC0415

    return list(load_yaml(PROFILES_FILE))


def load_profile(profile: str | Path) -> dict:
    """RenderOptions overrides of a profile: a name in :data:`PROFILES_FILE` or a path to a YAML file.

    Raises ``ValueError`` naming the file for an unknown profile, malformed YAML or a value that is not a
    mapping.
    """
    from lfmbench.fileio import InputFileError, load_yaml  # noqa: PLC0415

    p = Path(profile)
    if p.suffix in (".yaml", ".yml", ".json") and p.is_file():
        try:
            data = load_yaml(p)
        except OSError as exc:
            raise ValueError(f"{p}: cannot read the profile: {exc.strerror or exc}") from None
        except InputFileError as exc:  # one line, position included
            raise ValueError(f"{p}: cannot read the profile: {str(exc).removeprefix(f'{p}: ')}") from None
        src = p
    else:
        table = load_yaml(PROFILES_FILE)
        if str(profile) not in table:
            raise ValueError(f"profile: {profile!r} is not in {PROFILES_FILE} (known: {sorted(table)}) "
                             "and is not a YAML file")
        data = table[str(profile)]
        src = PROFILES_FILE
    if not isinstance(data, dict):
        raise ValueError(f"{src}: profile {profile!r} must be a mapping of RenderOptions fields")
    return dict(data)


def scene_seed(seed: int, index: int) -> int:
    """Seed of scene ``index`` of a run seeded ``seed``: first word of ``SeedSequence(seed, spawn_key=(index,))``
    (independent streams per scene, numpy's recommended way to derive child seeds)."""
    if seed < 0 or index < 0:
        raise ValueError(f"seed and index must be >= 0, got seed={seed}, index={index}")
    return int(np.random.SeedSequence(seed, spawn_key=(index,)).generate_state(1, np.uint32)[0])


def scene_id_for(index: int) -> str:
    """Scene id of generated scene ``index``: ``scene00000``, ``scene00001``, ..."""
    return f"scene{index:05d}"


@dataclass
class RenderJob:
    """One scene to render into ``out``: id, seed, RenderOptions fields (without ``seed``), an explicit scene
    dict (from a scene JSON file) or None to generate one with ``generate_scene(seed, **scene_kw)``;
    ``meta_extra``: fields added to the scene's ``meta.json`` (e.g. ``protocol``)."""

    index: int
    scene_id: str
    seed: int
    out: str
    options: dict
    scene: dict | None = None
    scene_kw: dict = field(default_factory=dict)
    dtype: str = DEFAULT_STORAGE
    backend: Backend | None = None
    meta_extra: dict = field(default_factory=dict)


def make_jobs(out: str | Path, *, n_scenes: int, seed: int, options: Mapping[str, Any],
              scenes: Sequence[dict] | None = None, scene_ids: Sequence[str] | None = None,
              scene_kw: Mapping[str, Any] | None = None, dtype: str = DEFAULT_STORAGE,
              backend: Backend | None = None) -> list[RenderJob]:
    """The job list: ``n_scenes`` generated scenes, or one job per explicit scene dict in ``scenes`` (id from
    ``scene_ids``, else its ``scene_id`` field, else ``scene<i>``)."""
    if "seed" in options:
        raise ValueError("options: give the run seed as seed=, not inside the RenderOptions fields")
    out = Path(out).resolve()  # workers (Ray) may run in another working directory
    jobs = []
    if scenes:
        ids = set()
        for i, sc in enumerate(scenes):
            sid = str(scene_ids[i] if scene_ids else (sc.get("scene_id") or scene_id_for(i)))
            check_scene_id(sid)
            if sid in ids:
                raise ValueError(f"scene files: duplicate scene_id {sid!r}")
            ids.add(sid)
            jobs.append(RenderJob(i, sid, scene_seed(seed, i), str(out), dict(options), dict(sc),
                                  dict(scene_kw or {}), dtype, backend))
        return jobs
    if isinstance(n_scenes, bool) or not isinstance(n_scenes, int) or n_scenes < 1:
        raise ValueError(f"scenes: number of scenes must be an integer >= 1, got {n_scenes!r}")
    for i in range(n_scenes):
        jobs.append(RenderJob(i, scene_id_for(i), scene_seed(seed, i), str(out), dict(options), None,
                              dict(scene_kw or {}), dtype, backend))
    return jobs


def protocol_jobs(out: str | Path, protocol, *, options: Mapping[str, Any] | None = None,
                  backend: Backend | None = None, splits: Sequence[str] | None = None) -> list[RenderJob]:
    """One job per scene of ``protocol`` (a :class:`render_tools.protocol.Protocol`), in file order (train, val,
    test): the scene's id and seed, its pinned conditions as generator overrides, the protocol's storage, and
    ``meta.json`` field ``protocol`` = ``{name, version, sha256, split}``. ``options``: RenderOptions fields
    (default: the protocol's ``render``; the CLI adds only ``variant``). ``splits``: only the scenes of these
    splits (default: all); the job indices stay the scenes' places in the protocol."""
    opts = dict(protocol.render if options is None else options)
    out = Path(out).resolve()
    return [RenderJob(i, ps.scene_id, ps.seed, str(out), dict(opts), None, ps.scene_kw(), protocol.storage,
                      backend, {"protocol": dict(protocol.record(), split=ps.split)})
            for i, ps in enumerate(protocol.scenes) if splits is None or ps.split in splits]


def write_splits(writer: CorpusWriter, split_seed: int | None = None,
                 splits: Mapping[str, Sequence[str]] | None = None) -> dict[str, list[str]] | None:
    """Rewrite ``splits.json`` (atomically) for the scenes in ``writer``'s manifest: from the fixed ``splits``
    (a protocol's; scenes not yet complete are left out) or else from ``make_splits(scenes, split_seed)``;
    neither given: nothing is written (returns None)."""
    if splits is not None:
        have = set(writer.scenes)
        out = {k: sorted(s for s in splits.get(k, ()) if s in have) for k in ("train", "val", "test")}
        atomic_write_json(writer.root / SPLITS_NAME, out)
        return out
    if split_seed is not None:
        return writer.write_splits(split_seed, SPLIT_FRACTIONS)
    return None


def _prepare(job: RenderJob, be: Backend) -> tuple[dict, Any, dict]:
    if job.scene is not None:
        scene = dict(job.scene)
        if be.validate_scene is not None:
            scene = be.validate_scene(scene) or scene
    else:
        scene = be.generate_scene(job.seed, scene_id=job.scene_id, **job.scene_kw)
    opts = be.RenderOptions(**job.options, seed=job.seed)
    meta = dict(be.scene_meta(scene, opts))
    meta.update(job.meta_extra)
    meta["scene_id"] = job.scene_id
    return scene, opts, meta


def run_job(job: RenderJob | Mapping[str, Any]) -> dict:
    """Render one scene and write its files (atomically) into ``job.out``; returns
    ``{"scene_id", "hashes": {relpath: sha256}, "notes": [...], "seconds"}``. Does not touch the manifest."""
    if not isinstance(job, RenderJob):
        job = RenderJob(**job)
    t0 = time.perf_counter()
    be = job.backend or default_backend()
    scene, opts, meta = _prepare(job, be)
    notes: list[str] = reflections.untraced_note(scene)
    # frame n is encoded and written in a worker thread while frame n + 1 renders here (the main thread keeps
    # the render, so Ctrl-C reaches it as before); an error or interrupt stops and joins the worker
    with ThreadedSceneWriter(job.out, job.scene_id, scene, meta, dtype=job.dtype, notes=notes) as w:
        for frame in be.render_frames(scene, opts):
            w.put(frame)
            del frame  # the worker holds it now: at most one frame encoded while the next renders
        hashes = w.close()
    if opts.static_layers:  # the static window layers, beside the scene's other files (render_tools.static_layers)
        from .static_layers import write_layers  # noqa: PLC0415

        hashes.update(write_layers(job.out, job.scene_id, scene, meta, opts, job.dtype, be.render_layer))
    prune_scene_dir(job.out, job.scene_id, hashes)
    return {"scene_id": job.scene_id, "hashes": hashes, "notes": notes, "seconds": time.perf_counter() - t0}


@dataclass
class RunSummary:
    """Outcome of :func:`run_jobs`: scene ids rendered, skipped (already complete), failed (id -> message),
    and per-scene seconds."""

    rendered: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def _is_interrupt(exc: BaseException) -> bool:
    """True for Ctrl-C seen through a renderer: Mitsuba / Dr.Jit turn the ``KeyboardInterrupt`` raised by the
    SIGINT handler inside a render into a ``RuntimeError`` (the cause or message still names it)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, KeyboardInterrupt) or "KeyboardInterrupt" in str(exc):
            return True
        exc = exc.__cause__ or exc.__context__
    return False


@contextlib.contextmanager
def _sigint_flag(hit: list):
    """Append ``True`` to ``hit`` when SIGINT arrives while the block runs (the previous handler still runs, so
    Ctrl-C still raises ``KeyboardInterrupt`` where Python code is running). Only in the main thread. A process
    that was started with SIGINT ignored (a background job of a non-interactive shell, ``nohup ... &``) keeps
    ignoring it, as Unix programs do: stop such a run with SIGTERM (the corpus stays valid, docs/guide/corpus-format.md)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    prev = signal.getsignal(signal.SIGINT)
    if prev == signal.SIG_IGN:  # the flag would be set but nothing would stop the run: leave SIGINT ignored
        yield
        return

    def handler(signum, frame):
        hit.append(True)
        if callable(prev):
            prev(signum, frame)
        elif prev == signal.SIG_DFL:
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, prev)


class RenderInterrupted(KeyboardInterrupt):
    """Ctrl-C during ``run_jobs``; carries the :class:`RunSummary` of what was finished and recorded."""

    def __init__(self, summary: RunSummary):
        super().__init__("interrupted")
        self.summary = summary


def run_jobs(jobs: Sequence[RenderJob], writer: CorpusWriter, *, workers: int = 1, ray_address: str | None = None,
             on_start: Callable[[int, int], None] | None = None,
             on_done: Callable[[str, str], None] | None = None, resume: bool = True,
             split_seed: int | None = None, splits: Mapping[str, Sequence[str]] | None = None,
             isolate: bool | None = None, ray_options: "RayOptions | None" = None) -> RunSummary:
    """Run the jobs not yet complete in ``writer``'s corpus; commit each finished scene to the manifest.

    Args:
        jobs: from :func:`make_jobs` (all with ``out == writer.root``).
        writer: the corpus writer (only the driver writes the manifest).
        workers: parallel scenes, each in a worker process (:func:`render_tools.workers.run_supervised`; each
            Mitsuba llvm render already uses every core, so 1 is usually fastest on a small machine). A worker
            killed by a signal fails its scene with the signal and a hint; a fresh worker renders the others.
        isolate: with ``workers=1``, render in one worker process (True) or in this process (False: a native
            crash then ends this process); None: :data:`ISOLATE_RENDERS` (True).
        ray_address: run on Ray instead: ``"local"`` (start or reuse a local instance with ``workers`` CPUs),
            ``"auto"`` or ``"ray://host:port"`` (Ray Client, ``pip install 'lfmbench[distributed]'``); the output
            directory must be one folder every Ray node mounts at the same path (:mod:`render_tools.ray_jobs`:
            checked before any scene starts, and every scene's files are checked on this machine before it is
            committed).
        ray_options: per-scene resources, retries and tasks in flight on Ray (:class:`RayOptions`).
        on_start: ``on_start(n_todo, n_skipped)`` once the resume check is done.
        on_done: ``on_done(scene_id, status)`` with status ``rendered`` / ``failed`` after each job.
        resume: skip scenes complete in the manifest (files present with matching SHA-256).
        split_seed: when given, ``splits.json`` is rewritten (atomically) from the manifest's scenes after the
            resume check and after every committed scene, so the manifest and the splits describe the complete
            scenes at every moment (a killed run leaves a corpus that passes ``lfmbench validate``).
        splits: fixed ``{"train": [ids], "val": [...], "test": [...]}`` (a protocol's): written like
            ``split_seed``'s splits, restricted to the complete scenes; takes precedence over ``split_seed``.

    A :class:`lfmbench.corpus.CorpusWriteError` (e.g. disk full) stops the run and propagates; Ctrl-C raises
    :class:`RenderInterrupted`, also when the renderer turned it into another exception (Mitsuba raises
    ``RuntimeError``): a scene interrupted by SIGINT is never recorded as failed. Other job errors are
    collected in ``failed`` and the run continues.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    summary = RunSummary()
    todo = []
    root = writer.root.resolve()
    for j in jobs:
        if Path(j.out).resolve() != root:
            raise ValueError(f"job {j.scene_id}: out {j.out} is not the writer's corpus {writer.root}")
    hook = writer.on_compact
    # splits.json follows the manifest: rewritten with it (at most O(1) amortized per scene, see CorpusWriter)
    writer.on_compact = lambda: write_splits(writer, split_seed, splits)
    try:
        return _run_jobs(jobs, writer, workers, ray_address, on_start, on_done, resume, isolate, summary, todo,
                         ray_options)
    finally:
        try:
            writer.flush()  # the scenes committed since the last manifest rewrite (also after Ctrl-C or an error)
        finally:
            writer.on_compact = hook


def _run_jobs(jobs, writer, workers, ray_address, on_start, on_done, resume, isolate, summary, todo,
              ray_options=None) -> RunSummary:
    """The body of :func:`run_jobs`, with ``writer.on_compact`` writing the splits."""
    complete = CompleteScenes(writer)  # files unchanged since they were hashed are not hashed again
    for j in jobs:
        if resume and complete(j.scene_id):
            summary.skipped.append(j.scene_id)
        else:
            writer.forget_scene(j.scene_id)
            todo.append(j)
    complete.save()
    writer.write_manifest()  # the manifest and splits.json after the resume check
    if on_start is not None:
        on_start(len(todo), len(summary.skipped))
    hit: list[bool] = []

    def finished(job: RenderJob, res: dict | None, exc: BaseException | None) -> None:
        if exc is not None:
            if isinstance(exc, CorpusWriteError):
                raise exc
            if hit or _is_interrupt(exc):
                raise KeyboardInterrupt from exc
            if isinstance(exc, WorkerDied):  # its writer thread died with it, perhaps in the middle of a file
                writer.cleanup_temp(job.scene_id)
            summary.failed[job.scene_id] = f"{type(exc).__name__}: {exc}"
            log.error("scene %s failed: %s", job.scene_id, exc)
            if on_done is not None:
                on_done(job.scene_id, "failed")
            return
        writer.commit_scene(job.scene_id, res["hashes"])  # the manifest and splits follow (CorpusWriter)
        summary.rendered.append(job.scene_id)
        summary.seconds[job.scene_id] = float(res["seconds"])
        summary.notes.extend(res.get("notes", []))
        if on_done is not None:
            on_done(job.scene_id, "rendered")

    in_process = workers == 1 and not (ISOLATE_RENDERS if isolate is None else isolate)
    if todo and not in_process and not ray_address:
        try:
            pickle.dumps(todo[0])
        except Exception as exc:  # noqa: BLE001 - a local function, a lambda, an open handle in the backend
            raise ValueError(f"jobs: job {todo[0].scene_id} does not pickle, so it cannot render in a worker "
                             f"process ({type(exc).__name__}: {exc}); use module-level functions in the backend, "
                             "or run_jobs(..., workers=1, isolate=False) to render in this process") from None
    try:
        with _sigint_flag(hit):
            _dispatch(todo, ray_address, 0 if in_process else workers, finished, writer.root, ray_options)
    except KeyboardInterrupt:
        writer.cleanup_temp()
        raise RenderInterrupted(summary) from None
    return summary


def _dispatch(todo: Sequence[RenderJob], ray_address: str | None, workers: int, finished: Callable,
              out: Path | None = None, ray_options=None, fn: Callable[[Any], dict] | None = None) -> None:
    """Run the jobs on Ray, in this process (``workers`` 0) or in worker processes; ``finished(job, result,
    exc)`` after each. ``fn``: what runs one job (default :func:`run_job`; not on Ray)."""
    fn = fn or run_job
    if ray_address:
        if todo:
            run_ray(todo, ray_address, max(workers, 1), finished, Path(todo[0].out if out is None else out),
                    ray_options, run_job)
    elif workers == 0:
        for j in todo:
            try:
                res = fn(j)
            except (KeyboardInterrupt, CorpusWriteError):
                raise
            except Exception as exc:  # noqa: BLE001 - one bad scene must not stop the others
                finished(j, None, exc)
            else:
                finished(j, res, None)
    else:
        _run_pool(todo, workers, finished, fn)


def _run_pool(todo: Sequence[RenderJob], workers: int, finished: Callable, fn: Callable = run_job) -> None:
    run_supervised(todo, fn, workers, finished, label=lambda j: f"scene {j.scene_id}")


def render_record(seed: int, options: Mapping[str, Any], dtype: str, scene_kw: Mapping[str, Any],
                  protocol: Mapping[str, Any] | None = None) -> dict:
    """What the manifest records as ``"render"`` (a resume with different values is refused). The Mitsuba
    ``variant`` is left out: it changes speed, not the radiance being estimated. ``protocol``: the
    ``Protocol.record()`` of a protocol render (``{name, version, sha256}``), stored as ``render.protocol``."""
    opts = {k: v for k, v in options.items() if k != "variant"}
    rec = {"seed": int(seed), "options": opts, "dtype": dtype, "scene_kw": dict(scene_kw)}
    if protocol is not None:
        rec["protocol"] = dict(protocol)
    return json.loads(json.dumps(rec, default=str))


@dataclass
class LayerJob:
    """The missing static window layers of one scene of a corpus (:func:`add_layers`): the corpus ``out``, the
    scene's id and seed, the protocol's RenderOptions fields (without ``seed``) and storage."""

    out: str
    scene_id: str
    seed: int
    options: dict
    dtype: str = DEFAULT_STORAGE
    backend: Backend | None = None


def run_layer_job(job: LayerJob) -> dict:
    """Render and write the static window layers scene ``job.scene_id`` does not have yet, from its own
    ``scene.json`` and ``meta.json`` (:func:`render_tools.static_layers.write_layers`); returns ``{"scene_id",
    "hashes": {relpath: sha256} (empty: nothing was missing), "seconds"}``. Does not touch the manifest."""
    from lfmbench.fileio import load_json  # noqa: PLC0415

    from .static_layers import write_layers  # noqa: PLC0415

    t0 = time.perf_counter()
    be = job.backend or default_backend()
    sdir = Path(job.out) / "scenes" / job.scene_id
    scene = load_json(sdir / "scene.json", "scene description")
    meta = load_json(sdir / "meta.json", "scene metadata")
    opts = be.RenderOptions(**job.options, seed=job.seed)
    hashes = write_layers(job.out, job.scene_id, scene, meta, opts, job.dtype, be.render_layer)
    return {"scene_id": job.scene_id, "hashes": hashes, "seconds": time.perf_counter() - t0}


def add_layers(out: str | Path, protocol, backend: Backend | None = None,
               on_done: Callable[[str, float], None] | None = None, *, workers: int = 1,
               isolate: bool | None = None) -> dict[str, float]:
    """Bring a corpus rendered with an earlier version of ``protocol`` (a :class:`render_tools.protocol.Protocol`)
    up to it when the two differ only by ``render.static_layers``: render each scene's missing static window layers
    (:func:`run_layer_job`, from the scene's own ``scene.json`` and ``meta.json``) and write them beside its files,
    none of which changes; then commit each scene's new files and record the protocol's version in the manifest's
    ``render``. A scene's ``meta.json`` keeps the version it was rendered with; its ``window_layers.json`` records
    how each layer was rendered. Returns ``{scene_id: seconds}`` of the scenes that got a layer
    (``on_done(scene_id, seconds)`` after each, in the order they finish).

    ``workers`` and ``isolate`` as in :func:`run_jobs`: scenes in parallel worker processes, and with ``workers=1``
    one worker process unless ``isolate`` is False (default :data:`ISOLATE_RENDERS`).

    Raises:
        ValueError: the corpus was not rendered with this protocol's name, or with other settings than the
            protocol's apart from ``static_layers`` (naming what differs); nothing is written then. A scene's
            error stops the run (the scenes committed before it keep their layers; a rerun renders the rest).
        RenderInterrupted: Ctrl-C (also when the renderer turned it into another exception); every scene whose
            layers were committed keeps them, no partial file is kept, and a rerun adds the missing ones.
    """
    from lfmbench.corpus import CorpusWriter  # noqa: PLC0415

    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    out = Path(out)
    w = CorpusWriter(out, dtype=protocol.storage)
    try:
        old = w.render or {}
        want = render_record(old.get("seed", 0), protocol.render, protocol.storage, {}, protocol=protocol.record())
        if (old.get("protocol") or {}).get("name") != protocol.name:
            raise ValueError(f"--add-layers: corpus {out} was not rendered with protocol {protocol.name} (its "
                             f"manifest's render.protocol is {(old.get('protocol') or {}).get('name')!r})")
        def strip(r):
            return {k: v for k, v in (r.get("options") or {}).items() if k not in ("static_layers", "variant")}

        diff = sorted(k for k in set(strip(old)) | set(strip(want)) if strip(old).get(k) != strip(want).get(k))
        diff += [k for k in ("dtype", "scene_kw") if old.get(k) != want.get(k)]
        if diff:
            raise ValueError(f"--add-layers: corpus {out} was rendered with other settings than {protocol.path} "
                             f"({', '.join(diff)}), not only other static_layers: render it anew with --out")
        seeds = {ps.scene_id: ps.seed for ps in protocol.scenes}
        todo = [LayerJob(str(out.resolve()), sid, seeds[sid], dict(protocol.render), protocol.storage, backend)
                for sid in w.scenes if sid in seeds]
        done: dict[str, float] = {}
        hit: list[bool] = []

        def finished(job: LayerJob, res: dict | None, exc: BaseException | None) -> None:
            if exc is not None:
                if hit or _is_interrupt(exc):
                    raise KeyboardInterrupt from exc
                raise exc
            if res["hashes"]:
                w.commit_scene(job.scene_id, {**w.scene_files(job.scene_id), **res["hashes"]})
                done[job.scene_id] = float(res["seconds"])
                if on_done is not None:
                    on_done(job.scene_id, done[job.scene_id])

        in_process = workers == 1 and not (ISOLATE_RENDERS if isolate is None else isolate)
        if todo and not in_process:
            try:
                pickle.dumps(todo[0])
            except Exception as exc:  # noqa: BLE001 - as in run_jobs: a backend of local functions
                raise ValueError(f"jobs: the layers of {todo[0].scene_id} do not pickle, so they cannot render in a "
                                 f"worker process ({type(exc).__name__}: {exc}); use module-level functions in the "
                                 "backend, or add_layers(..., workers=1, isolate=False)") from None
        try:
            with _sigint_flag(hit):
                _dispatch(todo, None, 0 if in_process else workers, finished, fn=run_layer_job)
        except KeyboardInterrupt:
            w.cleanup_temp()
            raise RenderInterrupted(RunSummary(rendered=list(done), seconds=dict(done))) from None
        w.set_render(want)
        return done
    finally:
        w.close()


# ------------------------------------------------------------------------------------- a render request
#: Sizes above which a render asks for ``--yes`` (a typo such as ``--frames 1000`` would start a
#: render of many hours per scene; ``--scenes 100000000`` would build a job list of gigabytes first).
CONFIRM_ABOVE = {"scenes": 10_000, "frames": 300, "width": 7680, "height": 4320, "spp": 4096, "bins": 256}
#: Largest ``--scenes`` accepted at all (even with ``--yes``).
MAX_SCENES = 1_000_000
#: Options that a protocol fixes: given together with ``--protocol`` they are refused (edit a copy of the
#: protocol file instead, which changes its hash). ``--variant``, ``--workers``, ``--ray-address``,
#: ``--no-resume`` and ``--yes`` change how, not what, is rendered and stay allowed.
PROTOCOL_FIXED = ("scenes", "width", "height", "spp", "seed", "bins", "frames", "groups", "profile", "scene",
                  "storage", "half")


class RenderRequestError(ValueError):
    """A render request that cannot run: one line naming the option (``lfmbench render`` exits 2 with it)."""


@dataclass
class RenderRequest:
    """What ``lfmbench render`` was asked for (None: the default, or the protocol's value). Pixels, samples per
    pixel, time bins, frames; ``groups`` and ``splits`` lists of names; ``scene_files`` scene JSON paths."""

    out: Path
    scenes: int | None = None
    width: int | None = None
    height: int | None = None
    spp: int | None = None
    seed: int | None = None
    bins: int | None = None
    frames: int | None = None
    groups: list | None = None
    profile: str | None = None
    protocol: str | None = None
    splits: list | None = None
    workers: int = 1
    scene_files: list | None = None
    variant: str | None = None
    storage: str | None = None
    half: bool = False
    yes: bool = False


@dataclass
class RenderPlan:
    """The jobs of a request, the corpus writer they go to, the run seed, the fixed splits of a protocol (None:
    drawn from the seed), the RenderOptions fields and the radiance storage."""

    jobs: list
    writer: Any
    seed: int
    splits: dict | None
    options: dict
    dtype: str


def plan_render(req: RenderRequest, backend: Backend | None = None) -> RenderPlan:
    """Resolve a request into its jobs, checking everything before anything is rendered: the profile or protocol,
    option values and sanity limits, scene files, the Mitsuba variant, the storage (on resume: the corpus's own,
    read from its ``manifest.json``).

    Raises:
        RenderRequestError: a bad option (the message names it). ValueError, CorpusError, CorpusWriteError,
            OSError: from the profile, protocol or corpus (``--out`` not writable).
    """
    from lfmbench.corpus import STORAGES, CorpusWriter  # noqa: PLC0415
    from lfmbench.fileio import InputFileError, load_json  # noqa: PLC0415

    from render_tools import backend as B  # noqa: PLC0415

    def fail(msg: str) -> None:
        raise RenderRequestError(msg)

    out, scenes, seed, profile, protocol = req.out, req.scenes, req.seed, req.profile, req.protocol
    width, height, spp, bins, frames, variant = req.width, req.height, req.spp, req.bins, req.frames, req.variant
    groups, scene_file, storage, half, yes, workers = (req.groups, req.scene_files, req.storage, req.half, req.yes,
                                                       req.workers)
    proto = None
    splits_wanted = req.splits or None
    if splits_wanted is not None:
        if protocol is None:
            fail("--split needs --protocol (a plain render's split is drawn from --seed after rendering)")
        from render_tools.protocol import SPLITS  # noqa: PLC0415

        bad = [s for s in splits_wanted if s not in SPLITS]
        if bad:
            fail(f"--split {bad[0]!r} is not a split; choose from {', '.join(SPLITS)}")
    if protocol is not None:
        given = {"scenes": scenes, "width": width, "height": height, "spp": spp, "seed": seed, "bins": bins,
                 "frames": frames, "groups": groups, "profile": profile, "scene": scene_file, "storage": storage,
                 "half": half or None}
        clash = [f"--{k}" for k in PROTOCOL_FIXED if given[k] not in (None, [])]
        if clash:
            fail(f"{', '.join(clash)} cannot be combined with --protocol: the protocol fixes the scenes, splits "
                 "and render settings (edit a copy of the protocol file with a new name or version and pass its "
                 "path instead)")
    scenes = 1 if scenes is None else scenes
    seed = 0 if seed is None else seed
    profile = "default" if profile is None else profile
    if protocol is not None:
        from render_tools.protocol import load_protocol  # noqa: PLC0415

        proto = load_protocol(protocol)
    options = dict(proto.render) if proto is not None else load_profile(profile)
    given = {"width": width, "height": height, "spp": spp, "bins": bins, "frames": frames, "variant": variant}
    options.update({k: v for k, v in given.items() if v is not None})
    if groups:
        options["groups"] = list(groups)
    for k in ("width", "height", "spp", "bins", "frames"):
        v = options.get(k)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            fail(f"--{k} must be an integer >= 1, got {v!r}")
    if seed < 0:
        fail(f"--seed must be >= 0, got {seed}")
    if not scene_file and scenes < 1:
        fail(f"--scenes must be an integer >= 1, got {scenes}")
    if not scene_file and scenes > MAX_SCENES:
        fail(f"--scenes {scenes} is above the limit of {MAX_SCENES:,} scenes per run")
    sizes = dict(options, scenes=None if scene_file else scenes)
    for k, limit in CONFIRM_ABOVE.items():
        v = sizes.get(k)
        if isinstance(v, int) and v > limit and not yes:
            fail(f"--{k} {v} is above the sanity limit {limit:,} (a render of this size takes very long or "
                 f"needs much memory); pass --yes if you mean it")
    if workers < 1:
        fail(f"--workers must be >= 1, got {workers}")
    scene_dicts = None
    if scene_file:
        scene_dicts = []
        for p in scene_file:
            try:
                sc = load_json(p, "scene file")
            except OSError as exc:
                fail(f"--scene {p}: cannot read scene JSON: {exc.strerror or exc}")
            except InputFileError as exc:
                fail(f"--scene {p}: cannot read scene JSON: {str(exc).removeprefix(f'{p}: cannot read JSON: ')}")
            if not isinstance(sc, dict):
                fail(f"--scene {p}: a scene file must hold a JSON object")
            try:  # the user's own mesh files (OBJ, PLY, glTF), resolved inside the scene file's folder
                from render_tools.assets import expand_assets  # noqa: PLC0415

                sc = expand_assets(sc, p)
            except ValueError as exc:
                fail(f"--scene {p}: {exc}")
            scene_dicts.append(sc)
    backend = backend or default_backend()
    # check options and scene files before anything is written (unknown fields, impossible values)
    try:
        backend.RenderOptions(**options, seed=0)
    except TypeError as exc:  # an unknown field in the profile
        if proto is not None:
            fail(f"protocol file {proto.path}: render: {exc}")
        fail(f"{profile if Path(profile).is_file() else PROFILES_FILE} (profile {profile!r}): {exc}")
    # a forced variant (--variant, profile or LFMBENCH_VARIANT) that cannot run here: one line, exit 2
    B.start_probes(options.get("variant"))  # the profile or protocol may name another variant
    B.check_variant(options.get("variant"))
    if scene_dicts and backend.validate_scene is not None:
        for p, sc in zip(scene_file, scene_dicts):
            try:
                backend.validate_scene(sc)
            except ValueError as exc:
                fail(f"--scene {p}: {exc}")
    if half and storage not in (None, "float16"):
        fail(f"--half means --storage float16, but --storage {storage} was given")
    dtype = "float16" if half else storage
    if proto is not None:
        dtype = proto.storage
    if dtype is None:  # resume with the corpus's own storage, else the default of new corpora
        try:
            old = load_json(Path(out) / "manifest.json", "manifest", "manifest_bytes").get("render") or {}
        except (OSError, ValueError, AttributeError):
            old = {}
        dtype = old.get("dtype") if old.get("dtype") in STORAGES else DEFAULT_STORAGE
    if dtype not in STORAGES:
        fail(f"--storage must be one of {', '.join(sorted(STORAGES))}, got {dtype!r}")
    ids = [str(sc.get("scene_id") or Path(p).stem) for p, sc in zip(scene_file, scene_dicts)] \
        if scene_dicts else None
    if proto is not None:
        job_list = protocol_jobs(out, proto, options=options, backend=backend, splits=splits_wanted)
    else:
        job_list = make_jobs(out, n_scenes=scenes, seed=seed, options=options, scenes=scene_dicts,
                               scene_ids=ids, dtype=dtype, backend=backend)
    writer = CorpusWriter(out, dtype=dtype, render=render_record(
        seed, options, dtype, {}, protocol=None if proto is None else proto.record()))
    fixed_splits = None if proto is None else proto.splits
    return RenderPlan(job_list, writer, seed, fixed_splits, options, dtype)
