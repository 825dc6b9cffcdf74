"""Mitsuba variant choice (render_tools.backend): CUDA > LLVM > scalar, forced variants, the CUDA probe, the
round-off clamp. No GPU needed: the CUDA render comparison skips where no CUDA device works."""
from __future__ import annotations

import os
import time
import warnings

import numpy as np
import pytest
from typer.testing import CliRunner

from lfmbench.cli import app
from render_tools import backend, render

LLVM = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"


@pytest.fixture
def fresh(monkeypatch, tmp_path):
    """No remembered choice, a private probe cache, no LFMBENCH_VARIANT; the Mitsuba variant restored after."""
    import mitsuba as mi

    before = mi.variant()
    monkeypatch.setattr(backend, "_chosen", None)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv(backend.VARIANT_ENV, raising=False)
    if "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(LLVM):
        monkeypatch.setenv("DRJIT_LIBLLVM_PATH", LLVM)
    yield mi
    monkeypatch.undo()
    if before:
        mi.set_variant(before)


def _cpu_choice() -> str:
    """What auto gives without CUDA on this machine: llvm when a libLLVM works, else scalar."""
    return backend.LLVM_VARIANT if any(backend.probe_llvm(lib) for lib in backend.find_libllvm()) \
        else backend.SCALAR_VARIANT


# ------------------------------------------------------------------------------------------- auto order
def test_auto_falls_back_to_llvm_or_scalar_when_cuda_is_unavailable(fresh, monkeypatch):
    calls = []
    monkeypatch.setattr(backend, "probe_cuda", lambda use_cache=True: calls.append(1) or False)
    monkeypatch.setattr(fresh, "variant", lambda: None)  # as in a fresh process
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the scalar fallback warns
        v = backend.select_variant()
    assert calls, "auto must try CUDA first"
    assert v == _cpu_choice()


def test_auto_prefers_cuda_when_it_works(fresh, monkeypatch):
    order = []
    monkeypatch.setattr(backend, "_set_cuda", lambda mi: order.append("cuda") or True)
    monkeypatch.setattr(backend, "_set_llvm", lambda mi: order.append("llvm") or True)
    monkeypatch.setattr(fresh, "variant", lambda: None)
    assert backend.select_variant() == backend.CUDA_VARIANT and order == ["cuda"]
    # LFMBENCH_VARIANT=cpu: CUDA is never tried
    monkeypatch.setattr(backend, "_chosen", None)
    monkeypatch.setenv(backend.VARIANT_ENV, "cpu")
    order.clear()
    assert backend.select_variant() == backend.LLVM_VARIANT and order == ["llvm"]
    # LFMBENCH_VARIANT naming a variant forces it; unknown values name the variable
    monkeypatch.setenv(backend.VARIANT_ENV, "scalar_spectral")
    assert backend.requested_variant(None) == "scalar_spectral"
    assert backend.requested_variant("llvm_ad_spectral") == "llvm_ad_spectral"  # explicit wins
    monkeypatch.setenv(backend.VARIANT_ENV, "gpu")
    with pytest.raises(ValueError, match="LFMBENCH_VARIANT"):
        backend.requested_variant(None)


def test_unknown_variant_is_a_value_error_naming_it():
    with pytest.raises(ValueError, match="variant"):
        backend.select_variant("cuda_rgb")
    with pytest.raises(ValueError, match="variant"):
        render.RenderOptions(variant="cuda_rgb")
    assert render.RenderOptions(variant="cuda_ad_spectral").variant == "cuda_ad_spectral"  # no probe here


# ------------------------------------------------------------------------------------- real CUDA probe
@pytest.mark.skipif(backend.find_libcuda() is not None, reason="this machine has a CUDA driver library")
def test_real_probe_says_no_cuda_quickly_without_a_driver(fresh):
    t0 = time.perf_counter()
    assert backend.probe_cuda() is False
    assert time.perf_counter() - t0 < 2.0  # no child process, no render
    assert "libcuda" in backend.cuda_unavailable_reason()
    with pytest.raises(ValueError, match=r"^variant: cuda_ad_spectral requested but no working CUDA device"):
        backend.check_variant("cuda_ad_spectral")
    with pytest.raises(ValueError, match="no working CUDA device"):
        backend.select_variant("cuda_ad_spectral")


def test_real_child_probe_fails_cleanly_and_caches_the_verdict(fresh, monkeypatch, tmp_path):
    """An unusable driver library: the real child process tries cuda_ad_spectral, fails (drjit raises
    ImportError from mi.set_variant), and the parent gets False plus the reason; the verdict is cached."""
    fake = tmp_path / "libcuda.so.1"
    fake.write_bytes(b"")  # not a library: drjit cannot initialise CUDA from it
    monkeypatch.setenv("DRJIT_LIBCUDA_PATH", str(fake))
    assert backend.find_libcuda() == str(fake.resolve())
    assert backend.probe_cuda() is False
    assert "ImportError" in backend.cuda_unavailable_reason()
    cache = tmp_path / "cache" / "lfmbench" / "cuda_probe.json"
    assert cache.is_file() and "mitsuba-" in cache.read_text()
    monkeypatch.setattr(backend, "_run_cuda_child", lambda lib=None: pytest.fail("cache not used"))
    assert backend.probe_cuda() is False
    assert "cached" in backend.cuda_unavailable_reason()


def test_cli_explicit_cuda_without_gpu_is_a_one_line_error(fresh, monkeypatch, tmp_path):
    fake = tmp_path / "libcuda.so.1"
    fake.write_bytes(b"")  # a driver library that does not work: same answer on any machine
    monkeypatch.setenv("DRJIT_LIBCUDA_PATH", str(fake))
    out = tmp_path / "c"
    r = CliRunner().invoke(app, ["render", "--out", str(out), "--variant", "cuda_ad_spectral", "--width", "16",
                                 "--height", "8", "--profile", "small"])
    assert r.exit_code == 2, r.output
    assert "variant: cuda_ad_spectral requested but no working CUDA device" in r.output
    assert "Traceback" not in r.output and isinstance(r.exception, SystemExit)
    assert len([ln for ln in r.output.splitlines() if ln.strip()]) == 1
    assert not out.exists()  # refused before anything was written
    monkeypatch.setenv(backend.VARIANT_ENV, "cuda_ad_spectral")  # the same through the environment
    r = CliRunner().invoke(app, ["render", "--out", str(out), "--width", "16", "--height", "8", "--profile", "small"])
    assert r.exit_code == 2 and "no working CUDA device" in r.output and not out.exists()


# ----------------------------------------------------------------------------------- background probes
@pytest.fixture
def no_pending():
    yield
    backend._stop_pending()


@pytest.mark.skipif(backend.find_libcuda() is not None, reason="auto probes CUDA first on this machine")
def test_background_llvm_probe_gives_the_foreground_verdict(fresh, no_pending, monkeypatch):
    libs = backend.find_libllvm()
    if not libs:
        pytest.skip("no libLLVM candidate on this machine")
    started = backend.start_probes()
    assert started == [f"llvm:{libs[0]}"]
    assert backend.start_probes() == []  # already running: not started twice
    spawned = []
    real_spawn = backend._spawn
    monkeypatch.setattr(backend, "_spawn", lambda *a: spawned.append(1) or real_spawn(*a))
    bg = backend.probe_llvm(libs[0])  # collects the background child's verdict
    assert spawned == [] and not backend._pending
    fg = backend.probe_llvm(libs[0], use_cache=False)  # a new child in the foreground
    assert spawned == [1] and bg == fg
    # the verdict is cached: no child at all the next time
    assert backend.start_probes() == [] and not backend._pending
    # a forced scalar variant or LFMBENCH_VARIANT=scalar_spectral needs no probe
    assert backend.start_probes("scalar_spectral") == []


def test_background_cuda_probe_gives_the_foreground_verdict(fresh, no_pending, monkeypatch, tmp_path):
    fake = tmp_path / "libcuda.so.1"
    fake.write_bytes(b"")  # not a library: the child fails in mi.set_variant (the same on any machine)
    monkeypatch.setenv("DRJIT_LIBCUDA_PATH", str(fake))
    assert backend.start_probes("cuda_ad_spectral") == ["cuda"]
    assert backend.probe_cuda() is False
    bg = backend.cuda_unavailable_reason()
    assert not backend._pending and "ImportError" in bg
    ok, fg = backend._run_cuda_child(str(fake.resolve()))  # foreground child
    assert ok is False and fg == bg
    assert backend.start_probes("cuda_ad_spectral") == []  # cached


def test_uncollected_background_probe_is_stopped(fresh, monkeypatch, tmp_path):
    fake = tmp_path / "libcuda.so.1"
    fake.write_bytes(b"")
    monkeypatch.setenv("DRJIT_LIBCUDA_PATH", str(fake))
    monkeypatch.setattr(backend, "_CUDA_PROBE_SCRIPT", "import time; time.sleep(60)")
    assert backend.start_probes("cuda_ad_spectral") == ["cuda"]
    (proc, _, _), = backend._pending.values()
    t0 = time.perf_counter()
    backend._stop_pending()  # what runs at exit when a command ends before it needs the verdict
    assert proc.returncode is not None and not backend._pending
    assert time.perf_counter() - t0 < 10


# ------------------------------------------------------------------------------------------ round-off
def test_clamp_roundoff_zeroes_tiny_negatives_only():
    a = np.array([[2.0, -1.25e-9, 0.5], [0.0, 1.0, -2e-6]], np.float32)  # peak 2: tolerance 2e-6
    out = backend.clamp_roundoff(a)
    assert out.dtype == np.float32 and out.shape == a.shape
    assert np.array_equal(out, np.maximum(a, 0)) and a[0, 1] < 0  # input untouched
    clean = np.ones((2, 3, 4), np.float32)
    assert backend.clamp_roundoff(clean) is clean  # nothing to do: no copy
    bad = a.copy()
    bad[1, 2] = -2.1e-6
    with pytest.raises(ValueError, match=r"light 3.*-2\.1e-06.*peak"):
        backend.clamp_roundoff(bad, name="light 3")
    with pytest.raises(ValueError, match="negative"):
        backend.clamp_roundoff(np.array([0.0, -1e-12], np.float32))  # dark layer: no peak, no tolerance
    nan = np.array([np.nan, 1.0, -1e-9], np.float32)
    got = backend.clamp_roundoff(nan)
    assert np.isnan(got[0]) and got[2] == 0.0  # NaN left for the corpus writer to report
    with pytest.raises(ValueError, match="x: negative"):
        backend.clamp_roundoff(a, rel_tol=0.0, name="x")
    with pytest.raises(ValueError, match="rel_tol"):
        backend.clamp_roundoff(a, rel_tol=-1.0)


# ----------------------------------------------------------------------------------- CUDA vs LLVM render
def _cuda_works() -> bool:
    return backend.find_libcuda() is not None and backend.probe_cuda()


@pytest.mark.slow
@pytest.mark.skipif(not _cuda_works(), reason="no working CUDA device")
def test_cuda_render_matches_llvm_mean():
    if _cpu_choice() != backend.LLVM_VARIANT:  # a GPU machine whose Mitsuba has no LLVM variant (seen on an H200)
        pytest.skip("no working llvm_ad_spectral to compare the CUDA render with")
    from tests.data.render.data import wall_scene as _wall_scene

    s = _wall_scene()
    means = {}
    for v in (backend.CUDA_VARIANT, _cpu_choice()):
        opts = render.RenderOptions(width=16, height=8, spp=32, bins=2, frames=1, aux=False, variant=v)
        fr = next(render.render_frames(s, opts))
        st = backend.clamp_roundoff(fr["static"]["streetlights"]["long"])
        (_, _, bins), = fr["lights"]["otherlights"]
        means[v] = (float(st.mean()), float(backend.clamp_roundoff(bins).mean()))
    (a1, b1), (a2, b2) = means.values()
    assert a1 > 0 and b1 > 0
    assert a1 == pytest.approx(a2, rel=0.02) and b1 == pytest.approx(b2, rel=0.02)


def test_probe_cache_drops_verdicts_of_libraries_that_are_gone(fresh, tmp_path):
    """A verdict for a library path that no longer exists (a test's temporary file, a removed install) is dropped
    when the cache is next written; verdicts for existing libraries stay."""
    lib = tmp_path / "libLLVM.so.19.1"
    lib.write_bytes(b"")
    gone = str(tmp_path / "removed" / "libLLVM.so.19.1")
    path = tmp_path / "cache" / "lfmbench" / "llvm_probe.json"
    backend._write_cache(str(path), {f"{lib}|0|1|mitsuba-x": True, f"{gone}|64|1|mitsuba-x": False})
    kept = backend._read_cache(str(path))
    assert list(kept) == [f"{lib}|0|1|mitsuba-x"] and kept[f"{lib}|0|1|mitsuba-x"] is True
