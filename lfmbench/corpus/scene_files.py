"""One scene's files: :func:`encode_scene` (pure encoding, usable in render workers), :func:`write_files` (atomic
writes: temporary name in the same directory, then :func:`os.replace`) and :class:`ThreadedSceneWriter` (both in
a worker thread, fed one frame at a time while the caller renders the next). The corpus-level bookkeeping (lock,
journal, manifest, resume) is :mod:`lfmbench.corpus.writer`.
"""
from __future__ import annotations

import json
import logging
import os
import threading
from concurrent.futures import Executor, ThreadPoolExecutor
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np

from lfmbench.check import check_scene_id
from lfmbench.corpus.exr_encode import encode_aux_exr, encode_lights_exr, encode_static_exr
from lfmbench.corpus.meta import validate_meta
from lfmbench.corpus.naming import (ATTR, FORMAT_VERSION, SCENES_DIR, STATIC_BINS_VERSION, _group_bins, frame_dir,
                                    group_storage, static_edges)
from lfmbench.corpus.storage import DEFAULT_STORAGE, Storage, StorageStats, resolve_storage
from lfmbench.fileio import atomic_write_bytes, json_default

__all__ = ["encode_scene", "write_files", "ThreadedSceneWriter", "ENCODE_THREADS"]

log = logging.getLogger(__name__)


def _json_bytes(obj: Any) -> bytes:
    return (json.dumps(obj, indent=1, allow_nan=False, default=json_default) + "\n").encode("utf-8")


def _attrs(scene_id: str, frame: int, group: str) -> dict:
    return {ATTR["scene"]: scene_id, ATTR["frame"]: int(frame), ATTR["group"]: group}


def encode_scene(scene_id: str, scene: Mapping[str, Any], meta: Mapping[str, Any],
                 frames: Iterable[Mapping[str, Any]], *, dtype: str | Storage = DEFAULT_STORAGE,
                 notes: list[str] | None = None, executor: Executor | None = None) -> Iterator[tuple[str, bytes]]:
    """Yield ``(relpath, bytes)`` for every file of a scene, frame by frame (checks shapes vs ``meta``).

    Pure encoding (no disk access), so that render workers can call it; ``dtype`` (the storage) as in
    :class:`CorpusWriter`. ``meta.json`` gets a ``storage`` entry (format version, pixel type, compression,
    mantissa bits). ``notes`` receives at most one message per scene: the layers stored FLOAT instead of HALF
    (if any) with the largest measured errors; the error summary of every scene is logged at INFO level.
    ``executor``: a ``concurrent.futures`` executor (threads: numpy and OpenEXR release the GIL) that encodes the
    files of a frame in parallel; they are yielded in the same order, with the same bytes, as without it.

    ``frames`` yields the renderer's frame dicts (``render_tools.render.render_frames``)::

        {"frame": n, "static": {group: {"short": (C,H,W), "long": (C,H,W)}},  # or {"bins": (B,C,H,W)}: static
         "lights": {group: [(light_id, (y0,x0,y1,x1), (K,C,h,w))]},
         "aux": {"depth.Z": (H,W), "depth.R": (H,W), "mask.instance": (H,W), "mask.light": (H,W)}}
    """
    check_scene_id(scene_id)
    st = resolve_storage(dtype)
    meta = dict(meta)
    if meta.get("scene_id") != scene_id:
        raise ValueError(f"meta.json scene_id {meta.get('scene_id')!r} != scene id {scene_id!r}")
    validate_meta(meta, f"meta.json of scene {scene_id}")
    edges = static_edges(meta)  # static time bins: the scene is format version 4
    meta["storage"] = {"format_version": FORMAT_VERSION if edges is None else STATIC_BINS_VERSION, **st.to_dict()}
    stats = StorageStats()
    sdir = f"{SCENES_DIR}/{scene_id}"
    yield f"{sdir}/scene.json", _json_bytes(scene)
    yield f"{sdir}/meta.json", _json_bytes(meta)
    bands = meta["bands_nm"]
    H, W = meta["height"], meta["width"]
    seen: list[int] = []
    with_aux: list[int] = []

    def static_file(g: str, wins: Mapping[str, Any], what: str, n: int) -> tuple[bytes, StorageStats]:
        fstats = StorageStats()
        if (edges is None) != ("bins" not in wins):
            raise ValueError(f"{what}: static time bins given {'without' if edges is None else 'but not'} "
                             "meta.json timing.static_edges_s")
        if edges is not None:
            if np.asarray(wins["bins"]).shape[0] != len(edges) - 1:
                raise ValueError(f"{what}: {np.asarray(wins['bins']).shape[0]} static bins, meta.json "
                                 f"timing.static_edges_s has {len(edges) - 1}")
            wins = {"bins": wins["bins"]}
        data = encode_static_exr(wins, bands, dtype=st, what=what, notes=notes, stats=fstats,
                                 attrs=_attrs(scene_id, n, g))
        size = np.asarray(wins["bins" if edges is not None else "short"]).shape[-2:]
        if (H, W) != tuple(size):
            raise ValueError(f"{what}: image size {tuple(size)} != meta.json ({H}, {W})")
        return data, fstats

    def lights_file(g: str, ls: Sequence, what: str, n: int) -> tuple[bytes, StorageStats]:
        fstats = StorageStats()
        return encode_lights_exr(ls, bands, _group_bins(meta, g), H, W, dtype=st, what=what, notes=notes,
                                 stats=fstats, attrs=_attrs(scene_id, n, g)), fstats

    def aux_file(aux: Mapping[str, Any], what: str, n: int) -> tuple[bytes, None]:
        return encode_aux_exr(aux, H, W, what=what, attrs=_attrs(scene_id, n, "aux")), None

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
        tasks: list[tuple[str, Any, tuple]] = []  # (relpath, function, arguments): the frame's files in order
        for g, wins in static.items():
            what = f"{fdir}/{g}.exr"
            if group_storage(meta, g) != "static":
                raise ValueError(f"{what}: group {g!r} is flickering with bins > 0 in meta.json but was "
                                 "rendered as static windows")
            tasks.append((what, static_file, (g, wins, what, n)))
        for g, ls in lights.items():
            what = f"{fdir}/{g}.exr"
            if group_storage(meta, g) != "lights":
                raise ValueError(f"{what}: group {g!r} is static in meta.json but was rendered per light")
            known = {lt["id"] for lt in meta.get("lights", []) if lt.get("group") == g}
            bad = [lid for lid, _, _ in ls if int(lid) not in known]
            if bad:
                raise ValueError(f"{what}: light ids {bad} are not lights of group {g!r} in meta.json")
            tasks.append((what, lights_file, (g, ls, what, n)))
        if fr.get("aux"):
            with_aux.append(int(n))
            tasks.append((f"{fdir}/aux.exr", aux_file, (fr["aux"], f"{fdir}/aux.exr", n)))
        if executor is None:
            for what, fn, args in tasks:
                data, fstats = fn(*args)
                if fstats is not None:
                    stats.merge(fstats)
                yield what, data
            continue
        futures = [executor.submit(fn, *args) for _, fn, args in tasks]
        try:
            for (what, _, _), fut in zip(tasks, futures):
                data, fstats = fut.result()
                if fstats is not None:
                    stats.merge(fstats)
                yield what, data
        finally:  # an error, or the consumer stopped: the frame's files not started yet are not encoded
            for fut in futures:
                fut.cancel()
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


#: Threads of :class:`ThreadedSceneWriter` that encode the files of one frame in parallel: 2 halves the time of
#: the last frame's encoding, which nothing else overlaps (while a frame renders, the render uses every core
#: and more threads would only take turns with it).
ENCODE_THREADS = 2


class _Stopped(Exception):
    """Raised inside the worker of :class:`ThreadedSceneWriter` by :meth:`ThreadedSceneWriter.abort`."""


_EMPTY = object()


class ThreadedSceneWriter:
    """:func:`encode_scene` + :func:`write_files` of one scene in a worker thread, fed frame by frame.

    The caller (e.g. a render loop in the main thread) hands each frame dict to :meth:`put` and goes on
    producing the next one while the worker encodes and writes the previous one: encoding (numpy, OpenEXR
    compression) and rendering (Dr.Jit releases the GIL while its kernels run) overlap. The hand-over has
    depth 1: :meth:`put` returns once the worker has *taken* the frame, i.e. finished the frame before, so
    at most one frame is being encoded while the next is produced (memory about one frame more than a
    serial loop). Files are written as :func:`write_files` writes them (temporary name, then rename), one at a
    time by the worker; the files of a frame are encoded by ``encode_threads`` threads in parallel (the same
    bytes as one thread).

    Errors: an exception in the worker (a bad frame, disk full: :class:`lfmbench.corpus.CorpusWriteError`)
    is raised again, the same object with its message, by the next :meth:`put` or by :meth:`close`. Used as
    a context manager, any exception in the block (including ``KeyboardInterrupt``) stops the worker at the
    next file boundary and joins it (:meth:`abort`) before it propagates; files already written stay
    complete, nothing is half-written, and the scene is not committed to any manifest.

    Example::

        with ThreadedSceneWriter(root, scene_id, scene, meta, dtype="compact", notes=notes) as w:
            for frame in render_frames(scene, opts):
                w.put(frame)
            hashes = w.close()          # {relpath: sha256}, as write_files returns

    Args:
        root: corpus root (files go under ``scenes/<scene_id>/``).
        scene_id, scene, meta, dtype, notes: as for :func:`encode_scene`.
        encode_threads: threads encoding a frame's files (default :data:`ENCODE_THREADS`; 1: the worker alone).
    """

    def __init__(self, root: str | os.PathLike, scene_id: str, scene: Mapping[str, Any], meta: Mapping[str, Any],
                 *, dtype: str | Storage = DEFAULT_STORAGE, notes: list[str] | None = None,
                 encode_threads: int = ENCODE_THREADS) -> None:
        if isinstance(encode_threads, bool) or not isinstance(encode_threads, int) or encode_threads < 1:
            raise ValueError(f"encode_threads must be an integer >= 1, got {encode_threads!r}")
        self.root = Path(root)
        self._args = (scene_id, scene, meta)
        self._dtype, self._notes = dtype, notes
        self._encode_threads = encode_threads
        self._cv = threading.Condition()
        self._slot: Any = _EMPTY
        self._end = self._stop = self._finished = False
        self._exc: BaseException | None = None
        self._hashes: dict[str, str] | None = None
        self._thread = threading.Thread(target=self._run, name=f"lfmbench-writer-{scene_id}", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------------------------------- worker
    def _frames(self) -> Iterator[Mapping[str, Any]]:
        while True:
            with self._cv:
                while self._slot is _EMPTY and not (self._end or self._stop):
                    self._cv.wait()
                if self._stop:
                    raise _Stopped
                if self._slot is _EMPTY:  # end of frames
                    return
                frame, self._slot = self._slot, _EMPTY
                self._cv.notify_all()
            yield frame

    def _files(self, executor: Executor | None) -> Iterator[tuple[str, bytes]]:
        scene_id, scene, meta = self._args
        files = encode_scene(scene_id, scene, meta, self._frames(), dtype=self._dtype, notes=self._notes,
                             executor=executor)
        try:
            for item in files:
                if self._stop:
                    raise _Stopped
                yield item
        finally:
            files.close()  # cancels the frame's files not yet being encoded

    def _run(self) -> None:
        try:
            if self._encode_threads == 1:
                self._hashes = write_files(self.root, self._files(None))
            else:
                with ThreadPoolExecutor(self._encode_threads, thread_name_prefix=self._thread.name) as pool:
                    self._hashes = write_files(self.root, self._files(pool))
        except _Stopped:
            pass
        except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
            self._exc = exc
        finally:
            with self._cv:
                self._finished = True
                self._cv.notify_all()

    # ------------------------------------------------------------------------------------------- caller
    def _raise_if_failed(self) -> None:
        if self._exc is not None:
            raise self._exc
        if self._finished:
            raise RuntimeError("ThreadedSceneWriter: the writer has already finished (put after close/abort)")

    def put(self, frame: Mapping[str, Any]) -> None:
        """Hand one frame dict (as :func:`encode_scene` reads them) to the worker; returns once it has taken it.
        Raises the worker's exception if it failed."""
        with self._cv:
            if self._end:
                raise RuntimeError("ThreadedSceneWriter.put: called after close()")
            self._raise_if_failed()
            self._slot = frame
            self._cv.notify_all()
            while self._slot is not _EMPTY and not self._finished:
                self._cv.wait()
            if self._slot is not _EMPTY:  # the worker ended without taking it
                self._slot = _EMPTY
                self._raise_if_failed()

    def close(self) -> dict[str, str]:
        """No more frames: wait for the worker to write the rest; returns ``{relpath: sha256}``. Raises the
        worker's exception if it failed (e.g. the frames do not match ``meta``)."""
        with self._cv:
            self._end = True
            self._cv.notify_all()
        self._thread.join()
        if self._exc is not None:
            raise self._exc
        if self._hashes is None:
            raise RuntimeError("ThreadedSceneWriter.close: the writer was aborted")
        return self._hashes

    def abort(self) -> None:
        """Stop the worker at its next file boundary and join it (a file being written is finished or, if
        its write fails, not there; no temporary file is left by :func:`write_files`)."""
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        self._thread.join()

    @property
    def alive(self) -> bool:
        """Whether the worker thread is still running."""
        return self._thread.is_alive()

    def __enter__(self) -> "ThreadedSceneWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.abort()
        elif not self._end:  # the block ended without close(): finish the scene (errors propagate)
            self.close()
