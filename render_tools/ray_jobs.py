"""Rendering on a Ray cluster (``lfmbench render --ray-address ...``) without losing a scene, and a resume that
does not hash unchanged files again.

What the cluster must share: the corpus folder (``--out``), mounted at the same path on the driver and on every
node that runs scenes (NFS, a cluster file system, or one machine). Workers write a scene's files there
themselves; only the driver writes ``manifest.json``. Two checks make a missing share an error instead of a
silent loss (before: a node with its own local folder "rendered" scenes whose files existed only on its disk):

- **before any scene starts** (:func:`check_shared_storage`): one small task pinned to every alive node writes a
  token file (a random nonce) into ``--out``; the driver must read every token back. A node whose token the driver
  cannot see is named and the run refused (exit 2): nothing rendered, nothing lost;
- **before a scene is committed** (:func:`check_visible`): the driver checks that every file the task reports
  exists on its side with the size the task wrote (a node joining later, a mount that went away). A scene that
  fails the check is failed, not committed; a re-run renders it again.

Resources and retries (:class:`RayOptions`): each scene task asks for ``cpus_per_scene`` CPUs and
``gpus_per_scene`` GPUs (Ray then sets ``CUDA_VISIBLE_DEVICES`` of the task, so concurrent scenes on a multi-GPU
node each get their own GPU) and runs Dr.Jit's kernels on that many threads (``ceil(cpus_per_scene)``,
:func:`task_threads`; before: every concurrent scene ran a thread per core of its node, so a node running N
scenes ran N x cores threads, and a second node on the same cores added almost nothing); a task whose worker or
node dies is run again up to ``max_retries`` times (safe: a scene's seed is fixed and every file is written
atomically, so a re-run writes the same bytes); errors raised by the render itself are not retried. At most ``max_in_flight`` tasks are submitted at a time (default: twice the
scenes the cluster can run at once), so the driver's memory does not grow with the number of scenes.

Resume (:class:`CompleteScenes`): a committed scene counts as complete when each of its files matches the
manifest's SHA-256; a file whose state (size, mtime, ctime, inode; :mod:`lfmbench.corpus.validate_cache`) is that
of an earlier check, by ``lfmbench validate`` or an earlier resume, is not read again (before: every resume hashed
every committed file, 0.4-0.9 TB for 10,000 scenes).
"""
from __future__ import annotations

import math
import os
import secrets
import socket
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["RayOptions", "SharedStorageError", "check_shared_storage", "check_visible", "run_ray",
           "CompleteScenes", "TOKEN_PREFIX", "task_threads"]

#: Name prefix of the token files of :func:`check_shared_storage` (removed after the check).
TOKEN_PREFIX = ".lfmbench-node-"


@dataclass(frozen=True)
class RayOptions:
    """Per-scene Ray task options: CPUs and GPUs per scene (fractions allowed), retries of a task whose worker or
    node died, tasks in flight (None: twice the scenes the cluster runs at once)."""

    cpus_per_scene: float = 1.0
    gpus_per_scene: float = 0.0
    max_retries: int = 3
    max_in_flight: int | None = None

    def __post_init__(self) -> None:
        for name in ("cpus_per_scene", "gpus_per_scene"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v < 1e6:
                raise ValueError(f"--ray-{name.replace('_', '-')} must be a number >= 0, got {v!r:.40}")
        if self.cpus_per_scene == 0 and self.gpus_per_scene == 0:
            raise ValueError("--ray-cpus-per-scene and --ray-gpus-per-scene cannot both be 0 (a scene needs a CPU "
                             "or a GPU)")
        if isinstance(self.max_retries, bool) or not isinstance(self.max_retries, int) or self.max_retries < 0:
            raise ValueError(f"max_retries must be an integer >= 0, got {self.max_retries!r:.40}")
        if self.max_in_flight is not None and (not isinstance(self.max_in_flight, int) or self.max_in_flight < 1):
            raise ValueError(f"max_in_flight must be None or an integer >= 1, got {self.max_in_flight!r:.40}")


class SharedStorageError(ValueError):
    """Some Ray nodes do not see the corpus folder of the driver (``--out``); nothing was rendered."""


def _write_token(out: str, name: str, nonce: str) -> dict:
    """On a node: write ``nonce`` to ``out/name`` (the folder is made if missing); where it went and who wrote."""
    info = {"host": socket.gethostname(), "pid": os.getpid(), "error": None}
    try:
        os.makedirs(out, exist_ok=True)
        p = os.path.join(out, name)
        with open(p + ".tmp", "w") as fh:
            fh.write(nonce)
        os.replace(p + ".tmp", p)
    except OSError as exc:
        info["error"] = f"{type(exc).__name__}: {exc.strerror or exc}"
    return info


def _remove_token(out: str, name: str, nonce: str) -> None:
    """On a node: remove its own token (only a file holding ``nonce``: one this check wrote)."""
    p = os.path.join(out, name)
    try:
        with open(p) as fh:
            if fh.read(64) != nonce:
                return
        os.unlink(p)
    except OSError:
        pass


def _nodes(ray) -> list[dict]:
    """Alive nodes that can run a scene task (any CPU or GPU)."""
    return [n for n in ray.nodes() if n.get("Alive") and (n.get("Resources", {}).get("CPU", 0) > 0
                                                          or n.get("Resources", {}).get("GPU", 0) > 0)]


def check_shared_storage(out: str | os.PathLike, timeout_s: float = 120.0) -> int:
    """Check that every alive node of the connected Ray cluster writes into the driver's ``out`` (see the module
    docstring); returns the number of nodes checked.

    Raises:
        SharedStorageError: naming each node whose token the driver does not see (its host and node id), or that
            could not write it; the tokens are removed first.
    """
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    out = Path(out).resolve()
    nonce = secrets.token_hex(16)
    nodes = _nodes(ray)
    write = ray.remote(num_cpus=0, max_retries=0)(_write_token)
    names = {n["NodeID"]: f"{TOKEN_PREFIX}{n['NodeID'][:16]}-{nonce[:8]}" for n in nodes}
    refs = {n["NodeID"]: write.options(scheduling_strategy=NodeAffinitySchedulingStrategy(n["NodeID"], soft=False))
            .remote(str(out), names[n["NodeID"]], nonce) for n in nodes}
    infos = dict(zip(refs, ray.get(list(refs.values()), timeout=timeout_s)))
    bad = []
    for n in nodes:
        nid, info = n["NodeID"], infos[n["NodeID"]]
        p = out / names[nid]
        try:
            seen = p.read_text()[:64] == nonce
        except OSError:
            seen = False
        if seen:
            p.unlink(missing_ok=True)
        else:
            why = info["error"] or "its token file is not in this folder on the driver"
            bad.append(f"{n.get('NodeManagerAddress', info['host'])} (host {info['host']}, node {nid[:12]}): {why}")
    if bad:
        rm = ray.remote(num_cpus=0, max_retries=0)(_remove_token)
        ray.get([rm.options(scheduling_strategy=NodeAffinitySchedulingStrategy(n["NodeID"], soft=False))
                 .remote(str(out), names[n["NodeID"]], nonce) for n in nodes], timeout=timeout_s)
        raise SharedStorageError(
            f"--out {out}: {len(bad)} of {len(nodes)} Ray node(s) do not write into this folder: "
            + "; ".join(bad[:4]) + ("; ..." if len(bad) > 4 else "")
            + ". Every node must mount the corpus folder at the same path (docs/guide/distributed.md); nothing "
              "was rendered")
    return len(nodes)


def check_visible(out: Path, res: dict) -> str | None:
    """None when every file a scene task reported (``res["sizes"]``: path in the corpus -> bytes) is on the driver
    with that size; else why not (one line naming the first file and the node)."""
    for rel, size in (res.get("sizes") or {}).items():
        p = out / rel
        try:
            st = p.stat()
        except OSError:
            return (f"{rel}, written on {res.get('host', '?')}, is not in {out} on the driver: the corpus folder "
                    "is not shared by every Ray node (docs/guide/distributed.md)")
        if st.st_size != size:
            return (f"{rel}: {st.st_size} bytes on the driver, {size} written on {res.get('host', '?')}: the "
                    "corpus folder is not the same on every Ray node (docs/guide/distributed.md)")
    return None


def task_threads(cpus: float) -> int | None:
    """Threads of a scene task that asked Ray for ``cpus`` CPUs: ``ceil(cpus)`` (at least 1); None for a task
    that asked for none (a GPU scene: Dr.Jit's default)."""
    return None if cpus <= 0 else max(1, math.ceil(cpus))


def _ray_job(job, run_job: Callable[[Any], dict], threads: int | None = None) -> dict:
    """The scene task: ``run_job(job)`` (:func:`render_tools.jobs.run_job`) with Dr.Jit's thread pool at
    ``threads`` (the CPUs the task asked Ray for, :func:`task_threads`; None: left as it is), plus the size of
    every file it wrote and its host."""
    if threads is not None:
        import drjit as dr  # noqa: PLC0415 - the renderer's own dependency

        if dr.thread_count() != threads:
            dr.set_thread_count(threads)
    res = run_job(job)
    out = Path(job.out)
    res["sizes"] = {rel: (out / rel).stat().st_size for rel in res["hashes"]}
    res["host"] = socket.gethostname()
    return res


class VisibilityError(RuntimeError):
    """A scene's files are not on the driver's side (no shared folder): the scene is failed, not committed."""


def _connect(ray, address: str, workers: int) -> None:
    if ray.is_initialized():
        return
    if address == "local":
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    elif address.startswith("ray://"):
        try:
            import grpc  # noqa: F401,PLC0415 - Ray Client's transport
        except ImportError:
            raise ImportError("--ray-address ray://...: Ray Client needs `pip install 'ray[client]'` (part of "
                              "'lfmbench[distributed]')") from None
        ray.init(address=address, log_to_driver=False)
    else:
        ray.init(address=address, log_to_driver=False)


def run_ray(todo: Sequence, address: str, workers: int, finished: Callable[[Any, dict | None, BaseException | None],
                                                                           None],
            out: Path, options: RayOptions | None = None, run_job: Callable[[Any], dict] | None = None) -> None:
    """Run the scene jobs ``todo`` on Ray (``address``: ``local``, ``auto``, ``host:port`` or ``ray://host:port``),
    each by ``run_job(job)`` (:func:`render_tools.jobs.run_job`) in a task, calling ``finished(job, result, exc)``
    on the driver after each; the shared-folder check first."""
    try:
        import ray  # noqa: PLC0415
    except ImportError as exc:
        raise ImportError("--ray-address needs Ray: pip install 'lfmbench[distributed]'") from exc
    opts = options or RayOptions()
    _connect(ray, address, workers)
    nodes = _nodes(ray)
    if not any(n.get("Resources", {}).get("CPU", 0) >= opts.cpus_per_scene
               and n.get("Resources", {}).get("GPU", 0) >= opts.gpus_per_scene for n in nodes):
        have = ", ".join(f"{n.get('Resources', {}).get('CPU', 0):g} CPU {n.get('Resources', {}).get('GPU', 0):g} GPU"
                         for n in nodes[:4])
        raise ValueError(f"--ray-cpus-per-scene {opts.cpus_per_scene:g} --ray-gpus-per-scene "
                         f"{opts.gpus_per_scene:g}: no Ray node has that much (nodes: {have or 'none'}); a scene "
                         "task would wait forever")
    check_shared_storage(out)
    remote = ray.remote(num_cpus=opts.cpus_per_scene, num_gpus=opts.gpus_per_scene,
                        max_retries=opts.max_retries, retry_exceptions=False)(_ray_job)
    limit = opts.max_in_flight
    if limit is None:
        res = ray.cluster_resources()
        slots = [res.get("CPU", 0) / opts.cpus_per_scene if opts.cpus_per_scene else float("inf"),
                 res.get("GPU", 0) / opts.gpus_per_scene if opts.gpus_per_scene else float("inf")]
        limit = max(1, 2 * int(min(slots)))
    threads = task_threads(opts.cpus_per_scene)
    queue = iter(todo)
    pending: dict = {}

    def submit() -> None:
        while len(pending) < limit:
            j = next(queue, None)
            if j is None:
                return
            pending[remote.remote(j, run_job, threads)] = j

    submit()
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                job = pending.pop(ref)
                try:
                    res = ray.get(ref)
                except Exception as exc:  # noqa: BLE001 - RayTaskError wraps the job's exception
                    cause = getattr(exc, "cause", None)
                    finished(job, None, cause if isinstance(cause, BaseException) else exc)
                else:
                    why = check_visible(out, res)
                    if why is None:
                        finished(job, res, None)
                    else:
                        finished(job, None, VisibilityError(why))
            submit()
    except KeyboardInterrupt:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise


class CompleteScenes:
    """``complete(scene_id)``: the scene is committed in ``writer``'s manifest and every file has the manifest's
    SHA-256, a file hashed only when the validation cache (``<corpus>/.cache/validate.bin``,
    :class:`lfmbench.corpus.validate_cache.ValidateCache`) has no key for its current state; :meth:`save` records
    the files hashed here (those settled, :data:`~lfmbench.corpus.validate_cache.RACY_S`) and keeps the keys
    already there (of ``lfmbench validate``'s scenes too)."""

    def __init__(self, writer) -> None:
        from lfmbench.corpus.validate_cache import ValidateCache, default_cache_path, max_cache_bytes

        self.writer = writer
        man = writer.manifest
        self.files: dict[str, dict[str, str]] = {}
        for rel, digest in man["files"].items():
            self.files.setdefault(rel.split("/", 2)[1] if rel.count("/") >= 1 else "", {})[rel] = digest
        self.n_files, self.n_scenes = len(man["files"]), len(man["scenes"])
        self.cache = ValidateCache(default_cache_path(writer.root), max_cache_bytes(self.n_files, self.n_scenes))
        self.hashed = 0

    def __call__(self, scene_id: str) -> bool:
        from lfmbench.corpus.meta import sha256_file

        if not self.writer.is_complete(scene_id, verify=False):
            return False
        root = self.writer.root
        for rel, digest in self.files.get(scene_id, {}).items():
            p = root / rel
            try:
                st = os.lstat(p)
            except OSError:
                return False
            if not p.is_file():
                return False
            key = self.cache.file_key(rel, st, digest)
            if self.cache.has(key):
                continue
            self.hashed += 1
            if sha256_file(p) != digest:
                return False
            if self.cache.settled(st):
                self.cache.add(key)
        return True

    def save(self) -> None:
        """Write the cache back when this check added keys (keys already there are kept while they fit the
        corpus's bound, :func:`~lfmbench.corpus.validate_cache.max_cache_bytes`)."""
        if not self.cache.added:
            return
        if len(self.cache.keys | self.cache.added) <= self.n_files + 2 * self.n_scenes:
            self.cache.used |= self.cache.keys
        self.cache.save()
