"""Hostile and unlucky input, third round (issue 42; docs/guide/fault-catalogue.md): checkpoints whose weights
changed, sizes a file can claim, special files where a file is read, read-only corpora, two writers of one output,
a DRJIT_LIBLLVM_PATH that does not work, errors of DataLoader workers, the leaderboard at sweep scale.

Tiny generated files only; a case that could take the machine down runs in a subprocess under ``RLIMIT_AS``.
"""
from __future__ import annotations

import json
import math
import os
import random
import re
import socket
import stat
import subprocess
import sys
import textwrap
import time
import zipfile
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from lfmbench import fileio
from lfmbench.cli import app

REPO = Path(__file__).resolve().parents[1]


def _one_line(r, code=2):
    """A refused CLI run: exit ``code``, no traceback, one error line (rich may wrap it: joined)."""
    assert r.exit_code == code, r.output
    assert "Traceback" not in r.output, r.output
    return " ".join(r.output.split())


def _flip_tensor_byte(path: Path, entry_suffix: str = "data/0", at: int = 5) -> None:
    """Change one byte of the first stored tensor of a torch zip checkpoint in place (a bit rot on disk)."""
    with zipfile.ZipFile(path) as z:
        info = next(i for i in z.infolist() if i.filename.endswith(entry_suffix))
    raw = bytearray(path.read_bytes())
    off = info.header_offset
    name_len, extra_len = int.from_bytes(raw[off + 26:off + 28], "little"), int.from_bytes(raw[off + 28:off + 30],
                                                                                            "little")
    data = off + 30 + name_len + extra_len
    raw[data + at] ^= 0x40
    path.write_bytes(bytes(raw))


# ------------------------------------------------------------------------- 1. integrity of checkpoints
def test_a_changed_weight_is_refused_naming_the_file(tmp_path, monkeypatch):
    from lfmbench.baselines import learned
    from lfmbench.baselines.checkpoint import CheckpointError, content_sha256
    from tests.data.corpus.data import make_corpus

    torch.manual_seed(0)
    net = learned.LearnedFusion(4)
    path = learned.save_checkpoint(net, tmp_path / "w.pt")
    ck = learned.read_checkpoint(path)
    assert ck["content_sha256"] == content_sha256(ck) and ck["_content_verified"]
    # the same content on another device or after a round trip: the same hash; one changed value: another
    moved = {k: (v.double().float() if isinstance(v, torch.Tensor) else v) for k, v in ck.items()}
    assert content_sha256(moved) == ck["content_sha256"]
    sd = {k: v.clone() for k, v in ck["state_dict"].items()}
    first = next(iter(sd))
    sd[first].view(-1)[0] += 1e-7
    assert content_sha256({**ck, "state_dict": sd}) != ck["content_sha256"]

    _flip_tensor_byte(path)
    with pytest.raises(CheckpointError, match=r"w\.pt: content does not match its content_sha256"):
        learned.load_checkpoint(path)
    # the CLI: one line, exit 2, no result file (it scored 0.434 instead of 0.960 with exit 0)
    monkeypatch.chdir(tmp_path)
    root = make_corpus(tmp_path / "c", n_scenes=1)
    monkeypatch.setenv(learned.CHECKPOINT_ENV, str(path))
    r = CliRunner().invoke(app, ["evaluate", "--method", "learned", "--corpus", str(root), "--split", "all",
                                 "--repeats", "1", "--warmup", "0", "--no-perceptual", "-o", str(tmp_path / "r.json")])
    out = _one_line(r)
    assert "w.pt" in out and "does not match" in out and not (tmp_path / "r.json").exists()


def test_the_result_records_the_checkpoint_hash_and_the_leaderboard_shows_it(tmp_path, monkeypatch):
    from lfmbench.baselines import learned
    from tests.data.corpus.data import make_corpus

    torch.manual_seed(0)
    path = learned.save_checkpoint(learned.LearnedFusion(4), tmp_path / "w.pt")
    sha = learned.read_checkpoint(path)["content_sha256"]
    root = make_corpus(tmp_path / "c", n_scenes=1)
    monkeypatch.setenv(learned.CHECKPOINT_ENV, str(path))
    base = ["--corpus", str(root), "--split", "all", "--repeats", "1", "--warmup", "0", "--no-perceptual"]
    r = CliRunner().invoke(app, ["evaluate", "--method", "learned", *base, "-o", str(tmp_path / "r.json")])
    assert r.exit_code == 0, r.output
    ck = json.loads((tmp_path / "r.json").read_text())["method"]["checkpoint"]
    import hashlib

    assert ck["content_sha256"] == sha and ck["verified"] is True
    assert ck["file_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    other = json.loads((tmp_path / "r.json").read_text())  # the same numbers from a method without weights
    del other["method"]["checkpoint"]
    other["method"]["spec"] = "lpd_only"
    (tmp_path / "l.json").write_text(json.dumps(other))
    lb = tmp_path / "lb.json"
    r = CliRunner().invoke(app, ["leaderboard", str(tmp_path / "r.json"), str(tmp_path / "l.json"), "--json", str(lb),
                                 "--markdown", str(tmp_path / "lb.md"), "--plot", str(tmp_path / "lb.png")])
    assert r.exit_code == 0, r.output
    rows = {row["method"]: row for row in json.loads(lb.read_text())["rows"]}
    assert rows["learned"]["checkpoint_sha256"] == sha and rows["lpd_only"]["checkpoint_sha256"] is None
    assert sha[:12] in (tmp_path / "lb.md").read_text()


def test_an_old_checkpoint_without_hash_loads_with_one_warning_and_can_be_sealed(tmp_path):
    from lfmbench.baselines import learned
    from lfmbench.baselines.checkpoint import UnverifiedCheckpointWarning, seal

    net = learned.LearnedFusion(4)
    old = tmp_path / "old.pt"
    torch.save({"format_version": learned.FORMAT_VERSION, "width": 4, "state_dict": net.state_dict()}, old)
    with pytest.warns(UnverifiedCheckpointWarning, match="old.pt: no content_sha256"):
        m = learned.load_checkpoint(old)
    assert m.content_verified is False
    sha = seal(old)
    assert learned.read_checkpoint(old)["_content_verified"] and learned.read_checkpoint(old)["content_sha256"] == sha
    _flip_tensor_byte(old)
    with pytest.raises(ValueError, match="does not match"):  # a damaged file is never sealed
        seal(old)


# ------------------------------------------------------------------------ 3. no hang on special files
def _fifo(path: Path) -> Path:
    if path.exists():
        path.unlink()
    os.mkfifo(path)
    return path


def test_readers_refuse_a_fifo_at_once(tmp_path):
    from lfmbench.baselines.checkpoint import CheckpointError, read_weights
    from lfmbench.corpus.errors import CorpusFileError
    from lfmbench.corpus.exr import read_exr
    from lfmbench.corpus.meta import sha256_file

    t0 = time.monotonic()
    f = _fifo(tmp_path / "pipe")
    with pytest.raises(fileio.NotRegularFileError, match="pipe: JSON file is a FIFO"):
        fileio.load_json(f)
    with pytest.raises(ValueError, match="pipe: YAML file is a FIFO"):
        fileio.load_yaml(f)
    with pytest.raises(OSError, match="is a FIFO"):
        sha256_file(f)
    with pytest.raises(CorpusFileError, match="pipe: EXR file is a FIFO"):
        read_exr(f)
    with pytest.raises(CheckpointError, match="pipe: checkpoint is a FIFO"):
        read_weights(f)
    with pytest.raises(fileio.NotRegularFileError, match="is a character device"):
        fileio.read_bytes("/dev/zero")
    with pytest.raises(fileio.NotRegularFileError, match="is a directory"):
        fileio.read_bytes(tmp_path)
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(tmp_path / "s"))
    try:
        with pytest.raises(OSError):  # a socket cannot even be opened; never read
            fileio.read_bytes(tmp_path / "s")
    finally:
        sock.close()
    link = tmp_path / "link.json"  # a link is resolved first: a link to a FIFO is a FIFO
    link.symlink_to(f)
    with pytest.raises(fileio.NotRegularFileError, match="is a FIFO"):
        fileio.load_json(link)
    assert time.monotonic() - t0 < 5


def test_a_fifo_in_the_corpus_or_as_config_is_one_line_not_a_hang(tmp_path):
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1)
    man = json.loads((root / "manifest.json").read_text())
    _fifo(root / next(k for k in man["files"] if k.endswith(".exr")))
    t0 = time.monotonic()
    r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(root), "--split", "all",
                                 "--repeats", "1", "--warmup", "0", "--no-perceptual", "-o", str(tmp_path / "r.json")])
    out = _one_line(r, 1)  # the data source failed: exit 1, partial result written
    assert "is a FIFO" in out and ".exr" in out
    r = CliRunner().invoke(app, ["train", "--corpus", str(root), "--config", str(_fifo(tmp_path / "cfg.yaml")),
                                 "--out", str(tmp_path / "w.pt")])
    out = _one_line(r)
    assert "cfg.yaml" in out and "FIFO" in out
    assert time.monotonic() - t0 < 300  # (a hang never returns; the bound is loose for a loaded machine)


# ------------------------------------------------------------------------ 5. one writer per output
def test_a_second_writer_of_one_output_is_refused_and_a_stale_lock_taken_over(tmp_path):
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1)
    out = tmp_path / "w.pt"
    held = fileio.OutputLock(out, "--out")  # another training holds --out (flock: per open file, so also here)
    assert (tmp_path / ".w.pt.lock").read_text().startswith(f"pid {os.getpid()} host ")
    r = CliRunner().invoke(app, ["train", "--method", "learned", "--corpus", str(root), "--out", str(out),
                                 "--epochs", "1"])
    msg = _one_line(r)
    assert "--out" in msg and "w.pt is being written by another lfmbench process" in msg and not out.exists()
    res = tmp_path / "r.json"
    with fileio.OutputLock(res, "--output"):
        r = CliRunner().invoke(app, ["evaluate", "--method", "lpd_only", "--corpus", str(root), "--split", "all",
                                     "--output", str(res)])
        assert "--output" in _one_line(r) and not res.exists()
    assert not (tmp_path / ".r.json.lock").exists()  # removed on release
    held.release()
    assert not (tmp_path / ".w.pt.lock").exists()
    # a lock file left by a killed writer (no flock held, its pid gone) is taken over
    (tmp_path / ".w.pt.lock").write_text("pid 999999999 host elsewhere\n")
    with fileio.OutputLock(out, "--out") as lk:
        assert lk.fd is not None
    # /dev/null is written in place and never locked
    assert fileio.OutputLock("/dev/null").lock is None
    # the "saved" line is read back from the file: its parameters and content hash are what the file holds
    from lfmbench.baselines import learned

    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("model:\n  width: 4\ntrain:\n  epochs: 1\n  batch_size: 1\n  samples_per_scene: 1\n  crop: 8\n"
                   "  workers: 0\n  split: all\n")
    r = CliRunner().invoke(app, ["train", "--method", "learned", "--corpus", str(root), "--config", str(cfg),
                                 "--out", str(out), "--no-resume"])
    assert r.exit_code == 0, r.output
    ck = learned.read_checkpoint(out)
    n = sum(v.numel() for v in ck["state_dict"].values())
    assert f"{n:,} parameters" in r.output and f"weights sha256 {ck['content_sha256'][:12]}" in r.output


def _cache_writer(corpus, cache, barrier, q):
    """A process that builds sample 0 through the projection cache at the same moment as its twin; an entry it
    reads half-written would be a CacheWarning, made an error here."""
    import warnings

    import torch

    from lfmbench.datasets import LFMCaptureDataset
    from lfmbench.datasets.projection import CacheWarning

    torch.set_num_threads(1)
    warnings.simplefilter("error", CacheWarning)
    try:
        ds = LFMCaptureDataset(corpus, split="all", frames=2, cache_dir=cache, optics=False)
        barrier.wait(60)
        q.put(("ok", {k: v.sum().item() for k, v in ds[0].items() if isinstance(v, torch.Tensor)}))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent
        q.put(("error", repr(exc)))


def test_two_processes_writing_one_cache_entry_leave_a_whole_one(tmp_path):
    """Two processes build the same projection-cache entry at once (a shared --cache-dir): each writes a temporary
    file and renames it (``os.replace``), so the entry is always one writer's whole file: both get the uncached
    sample's values, a third process reads the entry without a warning, and no temporary file is left."""
    import multiprocessing as mp
    import warnings

    from lfmbench.datasets import LFMCaptureDataset
    from lfmbench.datasets.projection import CacheWarning
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1, frames=2)
    cache = tmp_path / "cache"
    # the uncached values first (this also loads the preset once, for the forked processes)
    want = {k: v.sum().item() for k, v in
            LFMCaptureDataset(root, split="all", frames=2, cache_dir=False, optics=False)[0].items() if hasattr(v, "sum")}
    ctx = mp.get_context("fork")
    barrier, q = ctx.Barrier(2), ctx.Queue()
    procs = [ctx.Process(target=_cache_writer, args=(root, cache, barrier, q)) for _ in range(2)]
    for p in procs:
        p.start()
    got = [q.get(timeout=120) for _ in procs]
    for p in procs:
        p.join(60)
    assert [g[0] for g in got] == ["ok", "ok"], got
    entries = [p for p in cache.rglob("*") if p.is_file()]
    assert len(entries) == 1 and entries[0].suffix == ".pt", entries  # one entry, no temporary file left
    with warnings.catch_warnings():
        warnings.simplefilter("error", CacheWarning)
        again = LFMCaptureDataset(root, split="all", frames=2, cache_dir=cache, optics=False)[0]
    for k, v in want.items():
        assert got[0][1][k] == pytest.approx(v, rel=1e-6) and got[1][1][k] == pytest.approx(v, rel=1e-6), k
        assert again[k].sum().item() == pytest.approx(v, rel=1e-6), k


# ------------------------------------------------------------------------ 4. read-only corpora
def _unprivileged():
    """How to run a command that file permissions bind: as is for a user other than root; as root, under
    ``setpriv`` with every capability dropped (root without CAP_DAC_OVERRIDE obeys permission bits like any
    user; a uid like 65534 cannot run the interpreter where it lives under /root). None: neither is possible."""
    if os.getuid() != 0:
        return []
    import shutil

    if shutil.which("setpriv") is None:
        return None
    probe = subprocess.run(["setpriv", "--bounding-set=-all", "--inh-caps=-all", sys.executable, "-c",
                            "import os, sys, tempfile\nd = tempfile.mkdtemp(); os.chmod(d, 0o555)\n"
                            "try:\n open(os.path.join(d, 'x'), 'w')\nexcept PermissionError:\n sys.exit(0)\n"
                            "sys.exit(1)"], capture_output=True)
    return ["setpriv", "--bounding-set=-all", "--inh-caps=-all"] if probe.returncode == 0 else None


#: Runs the ``lfmbench`` commands of argv[1] (a JSON list of argument lists) in this process, one after the other;
#: prints per command its exit code, output and the exception it let out (None for none, or a plain exit).
_RUN_COMMANDS = textwrap.dedent("""
    import json, sys, traceback
    from typer.testing import CliRunner
    from lfmbench.cli import app
    out = []
    for args in json.loads(sys.argv[1]):
        r = CliRunner().invoke(app, args)
        exc = r.exception if r.exception is not None and not isinstance(r.exception, SystemExit) else None
        out.append({"exit_code": r.exit_code, "output": r.output[-3000:],
                    "exception": None if exc is None else "".join(traceback.format_exception(exc))[-3000:]})
    print(json.dumps(out))
""")


@pytest.mark.slow
def test_every_command_that_reads_a_corpus_works_on_a_read_only_one(tmp_path):
    from tests.data.corpus.data import make_corpus

    wrap = _unprivileged()
    if wrap is None:
        pytest.skip("running as root without setpriv: permission bits do not bind here")
    root = make_corpus(tmp_path / "c", n_scenes=1)
    (tmp_path / "cache").mkdir()
    before = sorted((str(p.relative_to(root)), p.stat().st_mtime_ns) for p in root.rglob("*"))
    for p in [root, *root.rglob("*")]:
        p.chmod(p.stat().st_mode & ~0o222)
    env = dict(os.environ, PYTHONPATH=str(REPO), HOME=str(tmp_path / "nohome"), XDG_CACHE_HOME=str(tmp_path / "nohome"))

    commands = [["evaluate", "--method", "lpd_only", "--corpus", str(root), "--split", "test", "--cache-dir",
                 str(tmp_path / "cache"), "-o", str(tmp_path / "r.json"), "--no-perceptual", "--repeats", "1",
                 "--warmup", "0"],
                ["validate", str(root)]]
    try:
        # both commands in one unprivileged process (each start imports torch: a few s of CPU), each as the
        # command line runs it (typer's CliRunner: exit code, output, and any exception the command let out)
        r = subprocess.run([*wrap, sys.executable, "-c", _RUN_COMMANDS, json.dumps(commands)], env=env,
                           capture_output=True, text=True, timeout=300, cwd=tmp_path)
        assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
        ev, va = json.loads(r.stdout.splitlines()[-1])
        assert ev["exit_code"] == 0 and ev["exception"] is None, ev
        assert json.loads((tmp_path / "r.json").read_text())["corpus"]["test_draws_sha256"]
        assert list((tmp_path / "cache" / "test_params").glob("*.json"))  # the frozen draws kept there
        assert va["exit_code"] == 0 and va["exception"] is None, va
        assert sorted((str(p.relative_to(root)), p.stat().st_mtime_ns) for p in root.rglob("*")) == before
    finally:
        for p in [root, *root.rglob("*")]:
            p.chmod(p.stat().st_mode | 0o200)


# ------------------------------------------------------------------------ 7. one line per failure
class _RaisingData(torch.utils.data.Dataset):
    def __len__(self):
        return 4

    def __getitem__(self, i):
        from lfmbench.corpus.errors import CorpusFileError

        raise CorpusFileError(f"EXR file /data/c/scenes/s{i}/f000/static.exr is truncated or corrupt")


class _DyingData(torch.utils.data.Dataset):
    def __len__(self):
        return 4

    def __getitem__(self, i):
        import signal

        os.kill(os.getpid(), signal.SIGKILL)  # what the out-of-memory killer does


def _fake_train(dataset):
    def train(*a, **k):
        it = iter(torch.utils.data.DataLoader(dataset, num_workers=1, batch_size=1))
        try:
            for _ in it:
                pass
        finally:
            # the error's traceback holds the iterator (its frames' ``self``): shut its worker down here, not in
            # whichever later test a garbage collection frees it, where torch's join waited 2 x 5 s for a
            # worker of the raising case (2026-11-28: 10 s charged to a random test of the suite)
            it._shutdown_workers()
    return train


@pytest.mark.parametrize("data, code, want", [
    (_RaisingData(), 2, "error: EXR file /data/c/scenes/s0/f000/static.exr is truncated or corrupt (in DataLoader "
                        "worker process 0)"),
    (_DyingData(), 1, "DataLoader worker (pid"),
])
def test_dataloader_worker_errors_and_deaths_are_one_line(tmp_path, monkeypatch, data, code, want):
    import lfmbench.train as T
    from lfmbench.limits import WORKER_DEATH_HINT
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1)
    monkeypatch.setattr(T, "train", _fake_train(data))
    args = ["train", "--method", "learned", "--corpus", str(root), "--out", str(tmp_path / "w.pt")]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == code, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(" ".join(lines)) < 400 and "Traceback" not in r.output and "Original" not in r.output, r.output
    assert want in " ".join(r.output.split()), r.output
    if code == 1:  # (torch notices a dead worker within its 5 s status interval: not run twice)
        assert WORKER_DEATH_HINT in " ".join(r.output.split())
        return
    monkeypatch.setenv("LFMBENCH_DEBUG", "1")  # the traceback behind the line, on request
    r = CliRunner().invoke(app, args)
    assert r.exit_code == code and "Traceback" in r.output


def test_an_unexpected_exception_is_one_line_naming_its_type(monkeypatch, tmp_path):
    import lfmbench.train as T
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1)

    def boom(*a, **k):
        raise ZeroDivisionError("division by zero\nsecond line")

    monkeypatch.setattr(T, "train", boom)
    r = CliRunner().invoke(app, ["train", "--method", "learned", "--corpus", str(root), "--out", str(tmp_path / "w")])
    assert r.exit_code == 1 and "Traceback" not in r.output
    out = " ".join(r.output.split())
    assert "error: ZeroDivisionError: division by zero / second line (unexpected: `lfmbench --debug" in out


# ------------------------------------------------------------------------ 6. the user's DRJIT_LIBLLVM_PATH
@pytest.mark.jit
@pytest.mark.slow
@pytest.mark.parametrize("bad", ["missing", "not_llvm"])
def test_a_drjit_libllvm_path_that_does_not_work_is_named_and_the_working_one_used(tmp_path, bad):
    """With DRJIT_LIBLLVM_PATH naming a missing file or a library that is not LLVM, a fresh process renders with
    the libLLVM the probe finds (every scene failed with "install libllvm19 and set DRJIT_LIBLLVM_PATH"), and
    says so in one warning line naming the variable, its value and the library used."""
    path = tmp_path / "libLLVM.so.19.1"
    if bad == "not_llvm":
        path.write_bytes(b"\x7fELF" + b"\0" * 60)  # a file, not a library Dr.Jit can use
    code = ("import warnings\nwarnings.formatwarning = lambda m, *a, **k: f'warning: {m}\\n'\n"
            "from render_tools import backend\nprint(backend.select_variant())\n")
    # the probe verdicts go to a private cache (seeded from the user's, so that the working library is not probed
    # again): a verdict for this temporary path must not be left in the user's ~/.cache
    from render_tools.backend import _cache_path

    home_cache = Path(_cache_path())
    before = home_cache.read_bytes() if home_cache.is_file() else None
    cache = tmp_path / "cache"
    (cache / "lfmbench").mkdir(parents=True)
    if before is not None:
        (cache / "lfmbench" / home_cache.name).write_bytes(before)
    env = dict(os.environ, PYTHONPATH=str(REPO), DRJIT_LIBLLVM_PATH=str(path), LFMBENCH_VARIANT="cpu",
               XDG_CACHE_HOME=str(cache))
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (home_cache.read_bytes() if home_cache.is_file() else None) == before, "the user's probe cache changed"
    if bad == "not_llvm":  # a file was probed: its verdict went to the private cache
        assert str(path) in (cache / "lfmbench" / home_cache.name).read_text()
    assert r.stdout.split()[-1] == "llvm_ad_spectral", r.stdout + r.stderr[-2000:]
    warn = [ln for ln in r.stderr.splitlines() if ln.startswith("warning:")]
    assert len(warn) == 1 and f"DRJIT_LIBLLVM_PATH={path} does not work" in warn[0] and "using /" in warn[0], r.stderr
    assert ("no such file" if bad == "missing" else "probe render with it failed") in warn[0]


# ------------------------------------------------------------------------ 8. ranking at sweep scale
def test_pareto_front_sweep_equals_the_pairwise_definition_with_ties():
    from lfmbench.evaluation.leaderboard import PARETO_AXES, _pareto, _pareto_pairwise

    rng = random.Random(42)
    for trial in range(300):
        n = rng.randint(0, 40)
        levels = rng.choice([3, 5, 50])  # few levels: many ties on one axis, on both, exact duplicates
        rows = []
        for _ in range(n):
            v = [rng.randint(0, levels) / levels for _ in PARETO_AXES]
            if rng.random() < 0.1:
                v[rng.randrange(2)] = float("nan")
            if rng.random() < 0.05:
                v[rng.randrange(2)] = rng.choice([float("inf"), -float("inf")])
            rows.append({PARETO_AXES[0]: v[0], PARETO_AXES[1]: v[1],
                         "status": "complete" if rng.random() < 0.85 else "interrupted"})
        want = _pareto_pairwise(rows, PARETO_AXES)
        _pareto(rows, PARETO_AXES)
        assert [r["pareto"] for r in rows] == [want[id(r)] for r in rows], (trial, rows)


def test_pareto_front_of_20000_rows_is_the_known_staircase():
    """20,000 rows whose front is known by construction: 1,000 rows on a staircase (each better on one axis and worse
    on the other than its neighbours) and 19,000 rows each worse on both axes than one of them. (Its speed is in
    benchmarks/bench_leaderboard.py, not timed here.)"""
    from lfmbench.evaluation.leaderboard import PARETO_AXES, _pareto
    from lfmbench.metrics import REGISTRY

    rng = random.Random(1)
    better = [1.0 if REGISTRY[a].higher_is_better else -1.0 for a in PARETO_AXES]   # +1: larger is better

    def row(u, v):  # u, v in "goodness" units: larger is better on both axes
        return {PARETO_AXES[0]: better[0] * u, PARETO_AXES[1]: better[1] * v, "status": "complete"}

    front = [row(i / 1000, 1.0 - i / 1000) for i in range(1000)]
    rest = []
    for _ in range(19_000):
        i = rng.randrange(1000)
        rest.append(row(i / 1000 - rng.uniform(1e-6, 0.5), 1.0 - i / 1000 - rng.uniform(1e-6, 0.5)))
    rows = front + rest
    rng.shuffle(rows)
    _pareto(rows, PARETO_AXES)
    assert all(r["pareto"] for r in front) and not any(r["pareto"] for r in rest)


def _random_records(rng: random.Random, n_scenes: int = 5) -> list[dict]:
    """Sample records of several draws per scene with NaN, None, missing values, zero and missing weights."""
    from lfmbench.metrics import REGISTRY

    recs = []
    for i in range(n_scenes):
        for _ in range(rng.randint(1, 3)):
            m = {}
            for name, spec in REGISTRY.items():
                u = rng.random()
                if u < 0.1:
                    continue
                m[name] = None if u < 0.15 else "nan" if u < 0.2 else float("nan") if u < 0.25 else rng.uniform(0, 1)
                if spec.weight and rng.random() < 0.9:
                    m[spec.weight] = float(rng.choice([0, 1, 7, 30]))
            recs.append({"scene_id": f"s{i}", "status": "ok" if rng.random() < 0.9 else "failed", "metrics": m,
                         "conditions": {"time_of_day": "day", "pwm_duty": rng.random()}})
    return recs


def test_per_scene_and_row_values_equal_their_definitions():
    """The one-pass values of a sweep's rows: each scene's value is the mean (or the pooled ratio) of its samples'
    finite values, computed here from the definition; each row value equals metric_summary's."""
    import statistics

    from lfmbench.evaluation.results import metric_summary, per_scene, scene_means
    from lfmbench.metrics import REGISTRY

    rng = random.Random(7)
    for _ in range(15):
        recs = _random_records(rng)
        scenes = per_scene(recs)
        for sc in scenes:
            mine = [r["metrics"] for r in recs if r["scene_id"] == sc["scene_id"] and r["status"] == "ok"]
            for name, spec in REGISTRY.items():
                vals = [(m.get(name), m.get(spec.weight) if spec.weight else 1.0) for m in mine]
                vals = [(float(v), float(w) if w is not None else 0.0) for v, w in vals
                        if isinstance(v, float) and v == v]
                if not vals:
                    assert name not in sc["metrics"]
                elif spec.aggregate == "pooled":
                    tot = sum(w for _, w in vals if w > 0)
                    want = sum(v * w for v, w in vals if w > 0) / tot if tot else float("nan")
                    assert sc["metrics"][name] == pytest.approx(want, nan_ok=True, rel=1e-12), name
                else:
                    assert sc["metrics"][name] == pytest.approx(statistics.fmean(v for v, _ in vals), rel=1e-12)
        means = scene_means(scenes)
        for name in REGISTRY:
            if any(name in s["metrics"] for s in scenes):
                want = metric_summary(scenes, name, ci=False)["value"]
                assert means[name] == want or (math.isnan(means[name]) and math.isnan(want)), name
            else:
                assert name not in means


def test_the_console_table_of_a_sweep_shows_its_best_rows_and_counts_the_rest(capsys):
    """Drawing 10,000 rows with rich took about half of a sweep's leaderboard: the console shows PRINT_ROWS rows and
    one line counting the others (the Markdown and JSON files hold every row)."""
    from lfmbench.evaluation import leaderboard as L
    from lfmbench.metrics import REGISTRY

    rows = [{"method": f"run{i:03d}", "rank": i + 1, "status": "complete", "ci": {}, "vs_best": None,
             "ms_per_megapixel": 1.0, "ms_iqr": None, "params": 10, "failed": 0, "scenes": 8, "n_scenes": 8,
             **{k: 0.5 for k in REGISTRY}} for i in range(L.PRINT_ROWS + 7)]
    L.print_leaderboard(rows)
    out = capsys.readouterr().out
    assert f"run{L.PRINT_ROWS - 1:03d}" in out and f"run{L.PRINT_ROWS:03d}" not in out
    assert "7 more rows (ranks > 50): every row is in the Markdown and JSON files" in out
    L.print_leaderboard(rows[:3])
    assert "more rows" not in capsys.readouterr().out


def test_json_numbers_that_overflow_are_refused_on_the_fast_path_too():
    """Floats are converted by the C parser and the tree checked after: an overflowing number (inf) is refused
    naming it, as the per-number hook did; the largest finite float and long digit strings in text are read."""
    from lfmbench.fileio import InputFileError, loads_json

    for bad, named in (("[1e999]", "1e999"), ('{"a": {"b": [0.5, -1E+400]}}', "-1E+400"),
                       ("[" + "9" * 400 + ".0]", "9999")):
        with pytest.raises(InputFileError, match=f"f.json: cannot read JSON: number {re.escape(named)}"):
            loads_json(bad, "f.json")
    assert loads_json('{"a": [1.7976931348623157e308, "1e999", "' + "0" * 64 + '"]}', "f.json")["a"][0] == 1.7976931348623157e308
    seen = []
    with pytest.raises(InputFileError, match="number 1e999"):  # a reader's counting hook sees the file once
        loads_json('[{"x": 1}, {"y": 1e999}]', "f.json", object_hook=lambda d: seen.append(d) or d)
    assert seen == [{"x": 1}]


# ------------------------------------------------------------------------ 2. memory a file can claim
def _mat_bomb(path: Path, n_doubles: int, name: bytes = b"depthMap") -> None:
    """A valid MATLAB v5 .mat file holding one compressed (n, 1) float64 array of zeros, written in time and memory
    of the file's size (about n / 1,000 bytes): deflate blocks of 1 MiB of zeros, each after a full flush, are
    identical, so one is repeated; the Adler-32 of the zeros is computed, not summed."""
    import struct
    import zlib

    body = (struct.pack("<IIII", 6, 8, 6, 0) + struct.pack("<IIii", 5, 8, n_doubles, 1)
            + struct.pack("<II", 1, len(name)) + name.ljust(8, b"\0") + struct.pack("<II", 9, n_doubles * 8))
    head = struct.pack("<II", 14, len(body) + n_doubles * 8) + body
    chunk = 1 << 20
    c = zlib.compressobj(9)
    first = c.compress(head) + c.flush(zlib.Z_FULL_FLUSH)
    block = c.compress(bytes(chunk)) + c.flush(zlib.Z_FULL_FLUSH)
    a = zlib.adler32(head)
    lo, hi = a & 0xFFFF, ((a >> 16) + n_doubles * 8 * (a & 0xFFFF)) % 65521  # zeros: a fixed, b += a per byte
    comp = first + block * (n_doubles * 8 // chunk) + c.flush(zlib.Z_FINISH)[:-4] + struct.pack(">I", hi << 16 | lo)
    hdr = b"MATLAB 5.0 MAT-file, zlib bomb".ljust(116, b" ") + bytes(8) + b"\x00\x01IM"
    path.write_bytes(hdr + struct.pack("<II", 15, len(comp)) + comp)


def test_a_small_mat_file_claiming_a_gigabyte_is_refused_within_a_memory_bound(tmp_path):
    """A 1 MB ``<SceneID>_lf.mat`` whose compressed array decodes to 1 GiB: the importer counts what it decodes to
    before ``loadmat`` allocates (it peaked at 1.45 GB); the bound is enforced: the import runs under RLIMIT_AS of
    768 MiB, where loading the array would fail with MemoryError instead of the one line."""
    import scipy.io

    from lfmbench.corpus import isetlfm as I
    from tests.corpus.test_isetlfm import make_iset_scene

    small = tmp_path / "small.mat"  # the generator writes what loadmat reads
    _mat_bomb(small, 1 << 17)
    assert scipy.io.loadmat(str(small))["depthMap"].shape == (1 << 17, 1)
    assert I.mat_decoded_bytes(small, 1 << 30) >= 8 << 17
    src = tmp_path / "iset"
    make_iset_scene(src, "s1", groups=("skymap",), frames=1)
    mat = src / "s1" / "s1_lf.mat"
    _mat_bomb(mat, 1 << 27)  # 1 GiB of float64 zeros
    assert mat.stat().st_size < 1_100_000
    code = textwrap.dedent(f"""
        import resource, sys
        resource.setrlimit(resource.RLIMIT_AS, (768 << 20, 768 << 20))
        sys.argv = ["lfmbench", "import-isetlfm", {str(src)!r}, {str(tmp_path / "c")!r}]
        from lfmbench.cli import app
        app()
    """)
    r = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=str(REPO)), capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 2, r.stdout + r.stderr[-3000:]
    err = " ".join(r.stderr.split())
    assert "s1_lf.mat" in err and "mat_bytes" in err and "Traceback" not in err and "MemoryError" not in err, err


def test_preset_and_config_sizes_are_refused_before_allocation(tmp_path):
    import yaml

    from lfmbench.baselines.checkpoint import CheckpointError, check_model_size
    from lfmbench.baselines import unet as U
    from lfmbench.limits import LimitError
    from lfmbench.sensor.preset import PRESET_DIR, load_preset
    from lfmbench.sensor.spectral_data import read_spectral_csv

    d = yaml.safe_load((PRESET_DIR / "ovt.yaml").read_text())
    d["spectral"]["filters"] = str(PRESET_DIR.parent.parent / "data" / d["spectral"]["filters"])
    for optics, field in (({"psf_radius_px": 100_000}, "'optics.psf_radius_px' = 100,000"),
                          ({"psf_radius_px": 200, "psf_oversample": 50}, "PSF grid of 402,002,500")):
        p = tmp_path / "p.yaml"
        p.write_text(yaml.safe_dump({**d, "optics": optics}))
        with pytest.raises(LimitError, match=rf"p\.yaml: .*{field}.* above the limit psf_"):
            load_preset(str(p))
    big = tmp_path / "filters.csv"  # a spectral file of 5 MB: refused from its size
    big.write_text("wavelength_nm,r,g,b\n" + "500,0.1,0.2,0.3\n" * 320_000)
    p.write_text(yaml.safe_dump({**d, "spectral": {**d["spectral"], "filters": str(big)}}))
    with pytest.raises(ValueError, match="filters.csv: spectral file of .* above the limit spectral_file_bytes"):
        read_spectral_csv(load_preset(str(p)).filters_path)
    cfg = U.config_from_dict({"model": {"base_channels": 100_000, "depth": 3}}, "u.yaml")
    t0 = time.monotonic()
    with pytest.raises(CheckpointError, match=r"u\.yaml: network \(field 'model'\) of [\d,]+ is above the limit"):
        check_model_size(lambda: U.UNetFusion(cfg.model), "u.yaml")
    assert time.monotonic() - t0 < 5  # counted on the meta device: nothing of 10^13 weights was allocated
    cfgf = tmp_path / "huge.yaml"
    cfgf.write_text("model:\n  base_channels: 100000\n")
    r = CliRunner().invoke(app, ["train", "--corpus", str(tmp_path), "--config", str(cfgf), "--out",
                                 str(tmp_path / "w.pt")])
    out = _one_line(r)
    assert "huge.yaml" in out and "model_parameters" in out


def test_a_training_batch_above_the_memory_limit_is_refused_before_simulation(tmp_path, monkeypatch):
    """min(train.batch_size, samples) x one sample's bytes is checked against batch_bytes before the first batch is
    simulated (a large batch of large crops died in the allocator, naming nothing): one line naming the field and
    the limit, nothing written."""
    from lfmbench.limits import LimitError, check_batch_bytes
    from tests.data.corpus.data import make_corpus

    check_batch_bytes(4, 1 << 20, "c.yaml")  # 4 MiB: far below
    with pytest.raises(LimitError, match=r"c\.yaml: field 'train.batch_size' = 1,000,000,000 samples of "
                                         r"1,048,576 bytes \(crop 64\): a batch of [\d,]+ is above the limit batch_"):
        check_batch_bytes(10**9, 1 << 20, "c.yaml", "crop 64")
    root = make_corpus(tmp_path / "c", n_scenes=1, frames=2)
    cfg = tmp_path / "big.yaml"
    cfg.write_text("model:\n  width: 4\ntrain:\n  epochs: 1\n  batch_size: 64\n  samples_per_scene: 64\n"
                   "  crop: 8\n  workers: 0\n  split: all\n  frames: 2\n")
    # 64 samples of a few KB each: above a limit of 64 KB (the default, 16 GiB, takes a real corpus to pass)
    r = CliRunner().invoke(app, ["--limit", "batch_bytes=65536", "train", "--method", "learned", "--corpus",
                                 str(root), "--config", str(cfg), "--out", str(tmp_path / "w.pt")])
    out = _one_line(r)
    assert "train.batch_size" in out and "batch_bytes" in out and not (tmp_path / "w.pt").exists(), out


def test_an_exr_frame_of_many_files_is_bounded_before_any_is_decoded(tmp_path, monkeypatch):
    """Each EXR file is bounded by ``exr_bytes``; a frame of several files, each below it, is bounded as a whole by
    ``exr_frame_bytes``, summed from the headers before any file of the frame is decoded: one line naming the frame
    folder, the file that took it over and the limit. A frame at the limit reads."""
    from lfmbench import corpus as C
    from lfmbench import limits
    from lfmbench.corpus import reader
    from lfmbench.corpus.exr import check_exr_header
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1)
    fdir = root / "scenes" / "scene00000" / "f000"
    total = sum(check_exr_header(f)["decoded_bytes"] for f in fdir.glob("*.exr"))
    assert all(check_exr_header(f)["decoded_bytes"] < total for f in fdir.glob("*.exr"))  # no file alone is over
    decoded = []
    real = reader.read_exr
    monkeypatch.setattr(reader, "read_exr", lambda p, **k: decoded.append(p) or real(p, **k))
    limits.set_limit("exr_frame_bytes", total - 1)
    try:
        c = C.Corpus(root)
        for read in (lambda: c.read_static_bins("scene00000", 0, "skymap"), lambda: c.read_aux("scene00000", 0)):
            with pytest.raises(C.CorpusFileError, match=r"f000: EXR files of one frame declaring [\d,]+ or more "
                                                         r"decoded pixel bytes \(counted up to \w+\.exr\).*"
                                                         r"exr_frame_bytes=") as e:
                read()
            assert "\n" not in str(e.value)
        assert decoded == []                                  # refused from the headers: nothing decoded
        limits.set_limit("exr_frame_bytes", total)
        c = C.Corpus(root)
        assert c.read_aux("scene00000", 0) and decoded        # at the limit: read
    finally:
        limits.set_limit("exr_frame_bytes", None)
    assert limits.limit("exr_frame_bytes") == 8 << 30
