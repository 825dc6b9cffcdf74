"""Rendering on a real multi-node Ray cluster on loopback (``ray start`` processes; the fake renderer of
``tests/data/render``): a node killed while it renders loses no scene (its task is run again elsewhere), and a
node that does not mount the corpus folder is refused before any scene starts (the folder hidden from it by a
private mount namespace, as on a machine without the shared file system).

Opt-in (``LFMBENCH_RAY_CLUSTER=1``): starting three Ray nodes takes ~10 s of an idle 2-core machine and over a
minute of a loaded one, above what one test may cost in ``make test``. The node without the folder needs
``unshare`` and root (mount namespaces); that part skips without them."""
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

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not os.environ.get("LFMBENCH_RAY_CLUSTER"),
                                                   reason="multi-node Ray test: set LFMBENCH_RAY_CLUSTER=1")]

ray = pytest.importorskip("ray")

from lfmbench import corpus as C  # noqa: E402
from render_tools import jobs as J  # noqa: E402
from render_tools.ray_jobs import RayOptions, SharedStorageError  # noqa: E402

#: Where a fake render of a scene announces the node it runs on (a folder every node shares: the test's).
MARK_ENV = "LFMBENCH_TEST_MARKS"


def slow_frames(scene, opts):
    """The fake renderer, 1 s per frame, after writing ``<marks>/<node id>-<scene>`` (which node renders it)."""
    import ray as _ray

    from tests.data.render.data import fake_render_frames

    marks = Path(os.environ[MARK_ENV])
    (marks / f"{_ray.get_runtime_context().get_node_id()}-{scene['scene_id']}").write_text("")
    for frame in fake_render_frames(scene, opts):
        time.sleep(1.0)
        yield frame


def slow_backend():
    from render_tools import render, scene

    return J.Backend(scene.generate_scene, render.RenderOptions, render.scene_meta, slow_frames,
                     scene.validate_scene)


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(args: list[str], log: Path, prefix: list[str] | None = None, env=None) -> subprocess.Popen:
    cmd = [str(Path(sys.executable).with_name("ray")), "start", "--block", "--disable-usage-stats", *args]
    if prefix:  # a shell command: the prefix's last word, then the ray command
        cmd = [*prefix[:-1], f"{prefix[-1]} {' '.join(cmd)}"]
    p = subprocess.Popen(cmd, stdout=log.open("w"), stderr=subprocess.STDOUT, env=env, start_new_session=True)
    for _ in range(600):
        if "Ray runtime started" in log.read_text() or p.poll() is not None:
            break
        time.sleep(0.2)
    assert p.poll() is None, log.read_text()[-2000:]
    return p


def _stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        p.terminate()  # `ray start --block` stops the processes it started
        try:
            p.wait(30)
        except subprocess.TimeoutExpired:
            p.kill()


def _wait_nodes(n: int) -> None:
    for _ in range(300):
        if sum(1 for x in ray.nodes() if x["Alive"]) >= n:
            return
        time.sleep(0.2)
    raise AssertionError(f"{n} Ray nodes did not come up")


def test_cluster_kill_a_node_and_refuse_a_node_without_the_folder():
    from ray import cloudpickle

    from tests.data.render import data as render_data

    base = Path(tempfile.mkdtemp(prefix="lfr", dir="/tmp"))  # short: Ray's socket paths must fit 107 bytes
    shared = base / "shared"
    marks = shared / "marks"
    marks.mkdir(parents=True)
    env = {**os.environ, "RAY_AUTH_MODE": "disabled", MARK_ENV: str(marks),
           "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[2]), os.environ.get("PYTHONPATH", "")])}
    port = _port()
    nodes: list[subprocess.Popen] = []
    os.environ["RAY_AUTH_MODE"] = "disabled"
    mod = sys.modules[__name__]
    cloudpickle.register_pickle_by_value(render_data)
    cloudpickle.register_pickle_by_value(mod)
    try:
        client_port = _port()
        nodes.append(_start(["--head", f"--port={port}", "--num-cpus=1", "--include-dashboard=false",
                             f"--ray-client-server-port={client_port}", f"--temp-dir={base / 't'}"],
                            base / "head.log", env=env))
        nodes.append(_start([f"--address=127.0.0.1:{port}", "--num-cpus=1"], base / "b.log", env=env))
        os.environ[MARK_ENV] = str(marks)
        ray.init(address=f"127.0.0.1:{port}", log_to_driver=False)
        _wait_nodes(2)
        b_id = next(x["NodeID"] for x in ray.nodes() if x["Alive"] and not x.get("Resources", {}).get(
            f"node:__internal_head__"))
        # 1. node b is killed while it renders a scene: its task runs again on the head; no scene lost
        out = shared / "c"
        opts = {"width": 24, "height": 16, "spp": 2, "frames": 2, "bins": 2}
        jobs = J.make_jobs(out, n_scenes=4, seed=3, options=opts, backend=slow_backend())
        killed: list[str] = []

        def killer():
            for _ in range(600):
                started = [m.name for m in marks.iterdir() if m.name.startswith(b_id)]
                if started:
                    killed.append(started[0])
                    _stop(nodes[1])
                    return
                time.sleep(0.1)

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
        # 2. Ray Client (ray://, the extra's ray[client]) from another process: one scene, then a resume
        script = ("import sys; from lfmbench import corpus as C; from render_tools import jobs as J; "
                  "from tests.data.render.data import fake_backend; from ray import cloudpickle; "
                  "import tests.data.render.data as d; cloudpickle.register_pickle_by_value(d); "
                  f"o = {str(shared / 'rc')!r}; w = C.CorpusWriter(o); "
                  "s = J.run_jobs(J.make_jobs(o, n_scenes=1, seed=2, options=dict(width=24, height=16, spp=2, "
                  f"frames=2, bins=2), backend=fake_backend()), w, ray_address='ray://127.0.0.1:{client_port}'); "
                  "print('RENDERED', s.rendered, s.failed)")
        r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300)
        assert "RENDERED ['scene00000'] {}" in r.stdout, r.stdout[-2000:] + r.stderr[-3000:]
        assert C.CorpusWriter(shared / "rc").scenes == ["scene00000"]
        # 3. a node that does not see the folder (a private tmpfs over it) is refused before any scene starts
        if os.geteuid() != 0 or not shutil.which("unshare"):
            pytest.skip("a node without the shared folder needs root and unshare (mount namespace)")
        nodes.append(_start([f"--address=127.0.0.1:{port}", "--num-cpus=1"], base / "c.log",
                            prefix=["unshare", "-m", "--propagation", "private", "sh", "-c",
                                    f"mount -t tmpfs tmpfs {shared} && exec"], env=env))
        _wait_nodes(2)
        out2 = shared / "c2"
        w2 = C.CorpusWriter(out2)
        with pytest.raises(SharedStorageError, match=r"1 of 2 Ray node\(s\) do not write into this folder"):
            J.run_jobs(J.make_jobs(out2, n_scenes=2, seed=5, options=opts, backend=slow_backend()), w2,
                       ray_address="auto")
        assert w2.scenes == [] and not (out2 / "scenes").exists()  # nothing rendered, nothing committed
        assert not list(out2.glob(".lfmbench-node-*"))
    finally:
        ray.shutdown()
        for p in reversed(nodes):
            _stop(p)
        cloudpickle.unregister_pickle_by_value(mod)
        cloudpickle.unregister_pickle_by_value(render_data)
        os.environ.pop(MARK_ENV, None)
        shutil.rmtree(base, ignore_errors=True)
