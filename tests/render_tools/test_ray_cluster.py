"""Rendering on a real multi-node Ray cluster on loopback (``ray start`` processes; the fake renderer of
``tests/data/render``).

CI-sized (marker ``integration``, run by ``make test-integration``): a cluster of 2 nodes of one CPU each, 4 tiny
scenes. A node that does not mount the corpus folder is refused before any scene starts, nothing written (the
folder hidden from it by a private tmpfs in its own mount namespace, as on a machine without the shared file
system; needs root and ``unshare``, else that part skips); then, into a folder both nodes see, the same node is
killed while it renders a scene: its task runs again on the head node and no scene is lost.

The bigger variant, opt-in (``LFMBENCH_RAY_CLUSTER=1``): Ray Client (``ray://``) from another process, one scene
and a resume."""
from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

ray = pytest.importorskip("ray")

from lfmbench import corpus as C  # noqa: E402
from render_tools import jobs as J  # noqa: E402
from render_tools.ray_jobs import RayOptions, SharedStorageError  # noqa: E402
from tests.data.render import data as render_data  # noqa: E402
from tests.data.render.data import fake_render_frames  # noqa: E402 - pickled by value with this module

#: Where a fake render of a scene announces the node it runs on (a folder every node shares: the test's).
MARK_ENV = "LFMBENCH_TEST_MARKS"
#: Seconds per fake frame: long enough for the node to be killed while it renders.
FRAME_S = 0.5


def slow_frames(scene, opts):
    """The fake renderer, ``FRAME_S`` per frame, after writing ``<marks>/<node id>-<scene>`` (which node renders
    it)."""
    import ray as _ray

    marks = Path(os.environ[MARK_ENV])
    (marks / f"{_ray.get_runtime_context().get_node_id()}-{scene['scene_id']}").write_text("")
    for frame in fake_render_frames(scene, opts):
        time.sleep(FRAME_S)
        yield frame


def slow_backend():
    from render_tools import render, scene

    return J.Backend(scene.generate_scene, render.RenderOptions, render.scene_meta, slow_frames,
                     scene.validate_scene)


OPTS = {"width": 24, "height": 16, "spp": 2, "frames": 2, "bins": 2}


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _launch(args: list[str], log: Path, prefix: list[str] | None = None, env=None) -> subprocess.Popen:
    """A ``ray start --block`` node, not waited for (a node started with the head's address waits for it)."""
    cmd = [str(Path(sys.executable).with_name("ray")), "start", "--block", "--disable-usage-stats",
           f"--dashboard-agent-listen-port={_port()}", *args]
    if prefix:  # a shell command: the prefix's last word, then the ray command
        cmd = [*prefix[:-1], f"{prefix[-1]} {' '.join(cmd)}"]
    p = subprocess.Popen(cmd, stdout=log.open("w"), stderr=subprocess.STDOUT, env=env, start_new_session=True)
    p.log = log
    return p


def _started(p: subprocess.Popen) -> subprocess.Popen:
    """``p`` once its log says the node started (fails with the log's tail if it exited)."""
    for _ in range(1500):
        if "Ray runtime started" in p.log.read_text() or p.poll() is not None:
            break
        time.sleep(0.2)
    assert p.poll() is None, p.log.read_text()[-2000:]
    return p


def _stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        p.terminate()  # `ray start --block` stops the processes it started
        try:
            p.wait(30)
        except subprocess.TimeoutExpired:
            p.kill()


def _wait_nodes(n: int) -> None:
    for _ in range(600):
        if sum(1 for x in ray.nodes() if x["Alive"]) >= n:
            return
        time.sleep(0.2)
    raise AssertionError(f"{n} Ray nodes did not come up")


class _Cluster:
    """Loopback nodes started by a test (stopped, with Ray's connection and the pickling registrations, at the
    end); ``env`` for the node processes."""

    def __init__(self, base: Path, marks: Path) -> None:
        from ray import cloudpickle

        self.base, self.nodes = base, []
        self.port, self.client_port = _port(), _port()
        self.env = {**os.environ, "RAY_AUTH_MODE": "disabled", MARK_ENV: str(marks),
                    "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[2]),
                                                   os.environ.get("PYTHONPATH", "")])}
        self._saved = {k: os.environ.get(k) for k in ("RAY_AUTH_MODE", MARK_ENV)}
        os.environ.update(RAY_AUTH_MODE="disabled", **{MARK_ENV: str(marks)})
        self.mod = sys.modules[__name__]
        cloudpickle.register_pickle_by_value(render_data)
        cloudpickle.register_pickle_by_value(self.mod)

    def head(self) -> subprocess.Popen:
        p = _launch(["--head", f"--port={self.port}", "--num-cpus=1", "--include-dashboard=false",
                     f"--ray-client-server-port={self.client_port}", f"--temp-dir={self.base / 't'}"],
                    self.base / "head.log", env=self.env)
        self.nodes.append(p)
        return p

    def node(self, name: str, prefix: list[str] | None = None) -> subprocess.Popen:
        """A node joining the head (launched, not waited for: :func:`_started`)."""
        p = _launch([f"--address=127.0.0.1:{self.port}", "--num-cpus=1"], self.base / f"{name}.log", prefix=prefix,
                    env=self.env)
        self.nodes.append(p)
        return p

    def close(self) -> None:
        from ray import cloudpickle

        ray.shutdown()
        for p in reversed(self.nodes):
            _stop(p)
        cloudpickle.unregister_pickle_by_value(self.mod)
        cloudpickle.unregister_pickle_by_value(render_data)
        for k, v in self._saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        shutil.rmtree(self.base, ignore_errors=True)


@pytest.mark.slow
@pytest.mark.integration
def test_two_nodes_refuse_one_without_the_folder_and_lose_no_scene_when_one_is_killed():
    base = Path(tempfile.mkdtemp(prefix="lfr", dir="/tmp"))  # short: Ray's socket paths must fit 107 bytes
    shared, private = base / "shared", base / "private"
    marks = shared / "marks"
    marks.mkdir(parents=True)
    private.mkdir()
    cl = _Cluster(base, marks)
    isolate = os.geteuid() == 0 and shutil.which("unshare") is not None
    try:
        head = cl.head()
        # node b, started beside the head (it waits for it): in its own mount namespace a private tmpfs hides
        # `private` (root and unshare), so it does not see a corpus folder there; `shared` it sees as the driver
        b = cl.node("b", prefix=["unshare", "-m", "--propagation", "private", "sh", "-c",
                                 f"mount -t tmpfs tmpfs {private} && exec"] if isolate else None)
        _started(head), _started(b)
        ray.init(address=f"127.0.0.1:{cl.port}", log_to_driver=False)
        _wait_nodes(2)
        b_id = next(x["NodeID"] for x in ray.nodes() if x["Alive"] and not x.get("Resources", {}).get(
            "node:__internal_head__"))
        # 1. a corpus folder that node b does not see: refused before any scene starts, nothing written
        if isolate:
            out1 = private / "c1"
            w1 = C.CorpusWriter(out1)
            with pytest.raises(SharedStorageError, match=r"1 of 2 Ray node\(s\) do not write into this folder"):
                J.run_jobs(J.make_jobs(out1, n_scenes=2, seed=5, options=OPTS, backend=slow_backend()), w1,
                           ray_address="auto")
            assert w1.scenes == [] and not (out1 / "scenes").exists() and not list(marks.iterdir())
            assert not list(out1.glob(".lfmbench-node-*"))  # the driver's side holds no token either
        # 2. node b is killed while it renders a scene: its task runs again on the head; no scene lost
        out = shared / "c"
        jobs = J.make_jobs(out, n_scenes=4, seed=3, options=OPTS, backend=slow_backend())
        killed: list[str] = []

        def killer():
            for _ in range(3000):
                started = [m.name for m in marks.iterdir() if m.name.startswith(b_id)]
                if started:
                    killed.append(started[0])
                    _stop(b)
                    return
                time.sleep(0.05)

        t = threading.Thread(target=killer)
        t.start()
        w = C.CorpusWriter(out)
        s = J.run_jobs(jobs, w, ray_address="auto", ray_options=RayOptions(max_retries=3))
        t.join()
        assert killed, "node b never started a scene"
        assert sorted(s.rendered) == [f"scene{i:05d}" for i in range(4)] and not s.failed, s.failed
        w.write_splits(3)
        assert C.validate_corpus(out).ok
        assert not list(out.glob(".lfmbench-node-*"))  # the shared-folder tokens were removed
        if not isolate:
            pytest.skip("a node without the shared folder needs root and unshare (mount namespace): part 1 skipped")
    finally:
        cl.close()


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("LFMBENCH_RAY_CLUSTER"), reason="bigger Ray variant: set LFMBENCH_RAY_CLUSTER=1")
def test_ray_client_from_another_process_renders_and_resumes():
    """Ray Client (``ray://``, the extra's ``ray[client]``) from another process: one scene, then a resume that
    renders nothing."""
    base = Path(tempfile.mkdtemp(prefix="lfr", dir="/tmp"))
    marks = base / "shared" / "marks"
    marks.mkdir(parents=True)
    cl = _Cluster(base, marks)
    try:
        _started(cl.head())
        script = ("import sys; from lfmbench import corpus as C; from render_tools import jobs as J; "
                  "from tests.data.render.data import fake_backend; from ray import cloudpickle; "
                  "import tests.data.render.data as d; cloudpickle.register_pickle_by_value(d); "
                  f"o = {str(base / 'shared' / 'rc')!r}; w = C.CorpusWriter(o); "
                  "s = J.run_jobs(J.make_jobs(o, n_scenes=1, seed=2, options=dict(width=24, height=16, spp=2, "
                  f"frames=2, bins=2), backend=fake_backend()), w, ray_address='ray://127.0.0.1:{cl.client_port}'); "
                  "print('RENDERED', s.rendered, s.skipped, s.failed)")
        for expect in ("RENDERED ['scene00000'] [] {}", "RENDERED [] ['scene00000'] {}"):
            r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=cl.env,
                               timeout=300)
            assert expect in r.stdout, r.stdout[-2000:] + r.stderr[-3000:]
        assert C.CorpusWriter(base / "shared" / "rc").scenes == ["scene00000"]
    finally:
        cl.close()
