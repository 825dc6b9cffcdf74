"""Mitsuba 3 variant selection: ``cuda_ad_spectral`` where a CUDA device works, else the fast
``llvm_ad_spectral`` path where a working libLLVM exists, else ``scalar_spectral`` with a warning.

Facts this relies on (measured on this project's machines; docs/guide/rendering.md): drjit's LLVM backend loads the shared
library named by ``DRJIT_LIBLLVM_PATH``; LLVM 15 crashes inside code generation on AVX-512 CPUs (a segfault
that cannot be caught in-process), while Debian's ``libllvm19`` works and is 5-10x faster than the scalar
variant. A candidate library is therefore *probed in a child process* (render of a tiny scene) before the
parent process commits to it; the verdict is cached on disk keyed by library path, size and mtime and the
Mitsuba version, so the probe costs a few seconds once per machine.

CUDA is probed the same way (a child renders a tiny scene with ``cuda_ad_spectral``; verdict cached keyed by
the CUDA driver library's path, size and mtime, the GPU models, ``CUDA_VISIBLE_DEVICES`` and the Mitsuba
version). Without a CUDA driver library (``libcuda.so``; no GPU, as on a CPU-only machine) the answer is "no"
at once, without a child process: drjit would only raise ``ImportError`` from ``mi.set_variant`` there
("the CUDA backend hasn't been initialized").

Background probes: :func:`start_probes` starts, without waiting, the child processes that a later
:func:`select_variant` / :func:`check_variant` would run (only those without a cached verdict: none at all
once the cache holds them); ``lfmbench render`` calls it first, so a cold probe (about 1.3 s of one core)
runs while the command imports its modules and generates the scene. :func:`probe_llvm` / :func:`probe_cuda`
then collect that child's verdict instead of starting their own (the same script, environment, timeout and
cache entry as a foreground probe).

``LFMBENCH_VARIANT`` (environment) changes the automatic choice: ``auto`` (default: CUDA, LLVM, scalar),
``cpu`` (never CUDA: LLVM, else scalar) or a variant name (used as if given explicitly).

Functions
- :func:`find_libllvm` -> candidate library paths, best first.
- :func:`probe_llvm` -> whether a library renders in a child process.
- :func:`find_libcuda`, :func:`probe_cuda` -> the CUDA driver library; whether ``cuda_ad_spectral`` renders.
- :func:`start_probes` -> start the probes a render will need in the background.
- :func:`select_variant` -> the variant name, set in Mitsuba (``mi.set_variant``).
- :func:`check_variant` -> fail early (before a render job writes anything) for an unusable explicit variant.
- :func:`clamp_roundoff` -> radiance with tiny negative round-off of the JIT back ends set to 0.

Size (about 640 lines): one job, choosing the back end a render runs on, in the order it is decided (the
variant asked for, the libLLVM candidates and their child-process probe, the CUDA probe, the on-disk verdicts).
"""
from __future__ import annotations

import atexit
import ctypes.util
import glob
import math
import os
import re
import subprocess
import sys
import time
import warnings

import numpy as np

from lfmbench.fileio import atomic_write_json, load_json
from lfmbench.resources import docs_url

#: Preferred spectral variants, fast first.
CUDA_VARIANT = "cuda_ad_spectral"
LLVM_VARIANT = "llvm_ad_spectral"
SCALAR_VARIANT = "scalar_spectral"
#: Variants :func:`select_variant` accepts when named explicitly.
SUPPORTED_VARIANTS = (CUDA_VARIANT, LLVM_VARIANT, SCALAR_VARIANT)
#: Environment variable overriding the automatic choice: ``auto``, ``cpu`` (no CUDA) or a variant name.
VARIANT_ENV = "LFMBENCH_VARIANT"
#: Values of :data:`VARIANT_ENV` besides the variant names.
VARIANT_MODES = ("auto", "cpu")
#: Where drjit looks for the CUDA driver library (besides ``DRJIT_LIBCUDA_PATH`` and the loader's cache).
CUDA_SEARCH_GLOBS = ("/usr/lib/x86_64-linux-gnu/libcuda.so*", "/usr/lib/aarch64-linux-gnu/libcuda.so*",
                     "/usr/lib/wsl/lib/libcuda.so*", "/usr/lib64/libcuda.so*", "/usr/local/nvidia/lib64/libcuda.so*")
#: Relative tolerance of :func:`clamp_roundoff`: negatives down to -ROUNDOFF_RTOL * (layer peak) become 0.
ROUNDOFF_RTOL = 1e-6
#: Major LLVM versions known to crash drjit on these CPUs (docs/guide/install.md: LLVM 15 crashes in code generation on AVX-512).
BROKEN_LLVM_MAJORS = (15,)
#: Directories searched for ``libLLVM*.so*``.
LLVM_SEARCH_DIRS = ("/usr/lib/x86_64-linux-gnu", "/usr/lib64", "/usr/lib", "/usr/local/lib")
#: Seconds allowed for the child-process probe.
PROBE_TIMEOUT_S = 120.0

_PROBE_TEMPLATE = r"""
import sys
import mitsuba as mi, drjit as dr
try:
    mi.set_variant('{variant}')
except Exception as exc:  # no driver / no device / no libLLVM: drjit raises ImportError here
    print('{tag}_PROBE_FAIL', type(exc).__name__, str(exc).splitlines()[0] if str(exc) else '')
    sys.exit(3)
s = mi.load_dict({{'type': 'scene', 'integrator': {{'type': 'path'}},
    'sensor': {{'type': 'perspective', 'film': {{'type': 'specfilm', 'width': 8, 'height': 8,
               'b': {{'type': 'regular', 'wavelength_min': 500, 'wavelength_max': 510, 'values': '1, 1'}}}}}},
    'e': {{'type': 'constant', 'radiance': 1.0}},
    'r': {{'type': 'sphere', 'center': [0, 0, 4], 'radius': 1.0}}}})
img = mi.render(s, spp=4)
v = float(dr.mean(mi.TensorXf(img)).array[0])
assert v == v and v > 0, v
print('{tag}_PROBE_OK', v)
"""
#: Child-process probes: render an 8x8 scene with the variant; print ``<TAG>_PROBE_OK`` or ``<TAG>_PROBE_FAIL``.
_PROBE_SCRIPT = _PROBE_TEMPLATE.format(variant="llvm_ad_spectral", tag="LLVM")
_CUDA_PROBE_SCRIPT = _PROBE_TEMPLATE.format(variant="cuda_ad_spectral", tag="CUDA")

_chosen: str | None = None
#: Probe children started by :func:`start_probes` and not yet collected: key -> (Popen, start time in s of
#: ``time.monotonic``, library path). Keys: ``"llvm|" + _cache_key(lib)``, ``"cuda|" + _cuda_cache_key(lib)``.
_pending: dict[str, tuple[subprocess.Popen, float, str]] = {}
_atexit_registered = False
#: What :func:`_collect` returns when no background probe was started for a key.
_NOT_STARTED = object()
#: Why the last :func:`probe_cuda` said no (for error messages).
_cuda_reason: str = ""


class VariantUnavailableError(ValueError, RuntimeError):
    """An explicitly requested Mitsuba variant cannot run on this machine (a ``ValueError`` naming ``variant``;
    also a ``RuntimeError``, what an unusable ``llvm_ad_spectral`` raised before)."""


def _llvm_major(path: str) -> int | None:
    """LLVM major version read from a library file name (``libLLVM.so.19.1`` -> 19, ``libLLVM-15.so.1`` -> 15)."""
    name = os.path.basename(path)
    m = re.search(r"libLLVM[-.](?:so\.)?(\d+)", name)
    return int(m.group(1)) if m else None


def find_libllvm() -> list[str]:
    """Candidate libLLVM shared libraries, best first.

    ``DRJIT_LIBLLVM_PATH`` (when set and existing) comes first; then every ``libLLVM*.so*`` found in
    :data:`LLVM_SEARCH_DIRS` whose major version is not in :data:`BROKEN_LLVM_MAJORS`, newest first.
    """
    out: list[str] = []
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env and os.path.isfile(env):
        out.append(os.path.realpath(env))
    found = []
    for d in LLVM_SEARCH_DIRS:
        for p in glob.glob(os.path.join(d, "libLLVM*.so*")):
            rp = os.path.realpath(p)
            major = _llvm_major(rp) or _llvm_major(p)
            if major is None or major in BROKEN_LLVM_MAJORS or rp in out or any(rp == f[1] for f in found):
                continue
            found.append((major, rp))
    out += [p for _, p in sorted(found, reverse=True)]
    return out


def _cache_path(name: str = "llvm_probe.json") -> str:
    root = os.environ.get("XDG_CACHE_HOME", os.path.join(os.path.expanduser("~"), ".cache"))
    return os.path.join(root, "lfmbench", name)


def _read_cache(path: str) -> dict:
    if not os.path.isfile(path):
        return {}
    try:
        data = load_json(path, "probe cache")
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _write_cache(path: str, cache: dict) -> None:
    """Write the verdict cache ``cache`` to ``path`` atomically, without the verdicts of libraries that no longer
    exist (keys are ``"<library path>|..."``): a test's or a removed install's temporary library would otherwise
    stay in the file for ever."""
    kept = {k: v for k, v in cache.items() if os.path.exists(k.split("|", 1)[0])}
    atomic_write_json(path, kept)


def _mitsuba_version() -> str:
    """The installed Mitsuba version, from the package metadata (no ``import mitsuba``: 0.2-0.3 s, which
    :func:`start_probes` would spend before starting its child); ``mitsuba.__version__`` if there is none."""
    from importlib import metadata  # noqa: PLC0415

    try:
        return metadata.version("mitsuba")
    except metadata.PackageNotFoundError:  # e.g. a source build on PYTHONPATH
        import mitsuba  # noqa: PLC0415

        return mitsuba.__version__


def _cache_key(lib: str) -> str:
    st = os.stat(lib)
    return f"{lib}|{st.st_size}|{int(st.st_mtime)}|mitsuba-{_mitsuba_version()}"


def probe_llvm(lib: str, use_cache: bool = True) -> bool:
    """Whether ``llvm_ad_spectral`` renders with library ``lib``, checked in a child process.

    Args:
        lib: path of a libLLVM shared library.
        use_cache: read/write the verdict cache (``~/.cache/lfmbench/llvm_probe.json``).
    Returns:
        True when the child rendered a tiny scene and exited cleanly.
    """
    if not os.path.isfile(lib):
        raise ValueError(f"lib: no such libLLVM file {lib!r}")
    key = _cache_key(lib)
    cache_file = _cache_path()
    cache = _read_cache(cache_file) if use_cache else {}
    if key in cache:
        return bool(cache[key])
    res = _collect("llvm|" + key)
    if res is _NOT_STARTED:
        res = _spawn_and_wait(_PROBE_SCRIPT, _llvm_env(lib))
    ok = res is not None and res[0] == 0 and "LLVM_PROBE_OK" in res[1]
    if use_cache:
        cache[key] = ok
        _write_cache(cache_file, cache)
    return ok


def find_libcuda() -> str | None:
    """The CUDA driver library drjit would load, or None (no NVIDIA driver installed: no CUDA).

    Order as drjit's: ``DRJIT_LIBCUDA_PATH`` (when set and existing), the dynamic loader's cache
    (``libcuda.so``), then :data:`CUDA_SEARCH_GLOBS`. Only looks for the file; loads nothing.
    """
    env = os.environ.get("DRJIT_LIBCUDA_PATH")
    if env:
        return os.path.realpath(env) if os.path.isfile(env) else None
    name = ctypes.util.find_library("cuda")
    if name:
        for d in ("/usr/lib/x86_64-linux-gnu", "/usr/lib64", "/usr/lib", "/usr/lib/wsl/lib"):
            if os.path.isfile(os.path.join(d, name)):
                return os.path.realpath(os.path.join(d, name))
        return name  # found by the loader somewhere else
    for pattern in CUDA_SEARCH_GLOBS:
        hits = sorted(glob.glob(pattern))
        if hits:
            return os.path.realpath(hits[0])
    return None


def _gpu_models() -> list[str]:
    """GPU model names from ``/proc/driver/nvidia/gpus/*/information`` (empty when unavailable)."""
    out = []
    for f in sorted(glob.glob("/proc/driver/nvidia/gpus/*/information")):
        try:
            with open(f, encoding="utf-8", errors="replace") as fh:
                for line in fh:
                    if line.startswith("Model:"):
                        out.append(line.split(":", 1)[1].strip())
        except OSError:
            continue
    return out


def _cuda_cache_key(lib: str) -> str:
    try:
        st = os.stat(lib)
        stamp = f"{st.st_size}|{int(st.st_mtime)}"
    except OSError:
        stamp = "?"
    return (f"{lib}|{stamp}|gpus={','.join(_gpu_models())}|"
            f"visible={os.environ.get('CUDA_VISIBLE_DEVICES', '*')}|mitsuba-{_mitsuba_version()}")


def probe_cuda(use_cache: bool = True) -> bool:
    """Whether ``cuda_ad_spectral`` renders on this machine, checked in a child process.

    No CUDA driver library (:func:`find_libcuda`): False at once, no child process (a CPU-only machine answers
    in about a millisecond). Otherwise a child renders an 8 x 8 px scene with ``cuda_ad_spectral`` (at most
    :data:`PROBE_TIMEOUT_S` s; a crash or hang of a broken driver stays in the child); the verdict is cached
    in ``~/.cache/lfmbench/cuda_probe.json`` keyed by driver library (path, size, mtime), GPU models,
    ``CUDA_VISIBLE_DEVICES`` and Mitsuba version. The reason for a "no" is kept for error messages.

    Args:
        use_cache: read/write the verdict cache.
    Returns:
        True when the child rendered the scene and exited cleanly.
    """
    global _cuda_reason
    lib = find_libcuda()
    if lib is None:
        _cuda_reason = "no CUDA driver library (libcuda.so) found; set DRJIT_LIBCUDA_PATH if it is elsewhere"
        return False
    key = _cuda_cache_key(lib)
    cache_file = _cache_path("cuda_probe.json")
    cache = _read_cache(cache_file) if use_cache else {}
    if key in cache:
        entry = cache[key]
        ok = bool(entry.get("ok")) if isinstance(entry, dict) else bool(entry)
        _cuda_reason = "" if ok else (entry.get("reason", "") if isinstance(entry, dict) else "") + " (cached)"
        return ok
    ok, reason = _run_cuda_child(lib)
    _cuda_reason = reason
    if use_cache:
        cache[key] = {"ok": ok, "reason": reason}
        _write_cache(cache_file, cache)
    return ok


def _cuda_env(lib: str | None) -> dict:
    env = dict(os.environ)
    if lib is not None and os.path.isabs(lib):
        env["DRJIT_LIBCUDA_PATH"] = lib
    return env


def _llvm_env(lib: str) -> dict:
    return dict(os.environ, DRJIT_LIBLLVM_PATH=lib)


def _run_cuda_child(lib: str | None = None) -> tuple[bool, str]:
    """The CUDA probe's verdict from a child process (the one :func:`start_probes` started for ``lib``, else a
    new one); returns (ok, reason for a failure)."""
    res = _NOT_STARTED if lib is None else _collect("cuda|" + _cuda_cache_key(lib))
    if res is _NOT_STARTED:
        res = _spawn_and_wait(_CUDA_PROBE_SCRIPT, _cuda_env(lib))
    if res is None:
        return False, f"the CUDA probe did not finish in {PROBE_TIMEOUT_S:g} s"
    code, out, err = res
    if code == 0 and "CUDA_PROBE_OK" in out:
        return True, ""
    lines = [ln for ln in (out + "\n" + err).splitlines() if ln.strip()]
    fail = [ln for ln in lines if ln.startswith("CUDA_PROBE_FAIL")]
    why = fail[0][len("CUDA_PROBE_FAIL"):].strip() if fail else (lines[-1] if lines else "")
    return False, f"probe render failed (exit {code}): {why[:200]}"


def _spawn(script: str, env: dict) -> tuple[subprocess.Popen, float]:
    """Start a probe child (``python -c script``) without waiting; output captured as text."""
    proc = subprocess.Popen([sys.executable, "-c", script], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)
    return proc, time.monotonic()


def _wait(proc: subprocess.Popen, started: float) -> tuple[int, str, str] | None:
    """(exit status, stdout, stderr) of a probe child, or None when it ran past :data:`PROBE_TIMEOUT_S` (counted
    from its start; it is killed then)."""
    try:
        out, err = proc.communicate(timeout=max(0.0, PROBE_TIMEOUT_S - (time.monotonic() - started)))
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        return None
    except BaseException:  # Ctrl-C while waiting: do not leave the child behind
        proc.kill()
        proc.wait()
        raise
    return proc.returncode, out, err


def _spawn_and_wait(script: str, env: dict) -> tuple[int, str, str] | None:
    return _wait(*_spawn(script, env))


def _collect(key: str):
    """The result (as :func:`_wait`'s) of the background probe started for ``key``, waiting for it;
    :data:`_NOT_STARTED` when none was started (the caller then probes in the foreground)."""
    entry = _pending.pop(key, None)
    return _NOT_STARTED if entry is None else _wait(*entry[:2])


def _stop_pending() -> None:
    """Kill the probe children nobody collected (the command ended early, e.g. on bad options)."""
    while _pending:
        _, (proc, _, _) = _pending.popitem()
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


def _start(key: str, script: str, env: dict, lib: str) -> bool:
    global _atexit_registered
    if key in _pending:
        return False
    _pending[key] = (*_spawn(script, env), lib)
    if not _atexit_registered:
        atexit.register(_stop_pending)
        _atexit_registered = True
    return True


def finish_probes() -> None:
    """Wait for the background probes of :func:`start_probes` and cache their verdicts (for callers that will
    not render in this process, e.g. before starting a process pool whose workers read the cache)."""
    for key, (_, _, lib) in list(_pending.items()):
        if key.startswith("llvm|"):
            probe_llvm(lib)
        else:
            probe_cuda()
    _stop_pending()  # any not collected above (a library changed meanwhile)


def start_probes(variant: str | None = None) -> list[str]:
    """Start in the background the child-process probes that :func:`select_variant` (``variant``) will need,
    without waiting for them; returns what was started (``"cuda"``, ``"llvm:<lib>"``; empty when every
    needed verdict is cached or no probe is needed).

    Mirrors :func:`select_variant`'s order: a forced ``scalar_spectral`` needs none; auto (or
    ``cuda_ad_spectral``) on a machine with a CUDA driver library probes CUDA (LLVM only later, in the
    foreground, if CUDA fails); otherwise the first libLLVM candidate without a cached verdict is probed (the
    candidates before it are cached as failing). :func:`probe_llvm` / :func:`probe_cuda` collect the verdicts
    and cache them as a foreground probe does. Never raises: a bad ``variant`` or ``LFMBENCH_VARIANT`` is
    reported by :func:`select_variant` / :func:`check_variant`, where it is used.
    """
    started: list[str] = []
    try:
        v = requested_variant(variant)
    except ValueError:
        return started
    if v == SCALAR_VARIANT or _chosen is not None:
        return started
    no_cuda = os.environ.get(VARIANT_ENV, "").strip() == "cpu"
    try:
        cuda_lib = find_libcuda() if v == CUDA_VARIANT or (v is None and not no_cuda) else None
        if cuda_lib is not None:
            key = _cuda_cache_key(cuda_lib)
            if key not in _read_cache(_cache_path("cuda_probe.json")) and \
                    _start("cuda|" + key, _CUDA_PROBE_SCRIPT, _cuda_env(cuda_lib), cuda_lib):
                started.append("cuda")
            return started  # auto: LLVM is needed only if CUDA fails; forced CUDA: never
        if v == CUDA_VARIANT:
            return started  # no driver library: the answer is "no" at once, no child
        cache = _read_cache(_cache_path())
        for lib in find_libllvm():
            key = _cache_key(lib)
            if key in cache:
                if cache[key]:
                    break  # a cached working library: no probe
                continue
            if _start("llvm|" + key, _PROBE_SCRIPT, _llvm_env(lib), lib):
                started.append(f"llvm:{lib}")
            break
    except OSError:  # a library vanished between the search and stat(): the foreground probe reports it
        pass
    return started


def cuda_unavailable_reason() -> str:
    """Why the last :func:`probe_cuda` answered no ("" after a yes or before any probe)."""
    return _cuda_reason


def requested_variant(variant: str | None = None) -> str | None:
    """The variant a render must use: ``variant`` when given, else :data:`VARIANT_ENV` when it names one,
    else None (automatic). Raises ``ValueError`` naming ``variant`` / ``LFMBENCH_VARIANT`` for unknown names."""
    if variant is not None:
        if variant not in SUPPORTED_VARIANTS:
            raise ValueError(f"variant: {variant!r} not in {SUPPORTED_VARIANTS}")
        return variant
    env = os.environ.get(VARIANT_ENV, "").strip()
    if not env or env in VARIANT_MODES:
        return None
    if env not in SUPPORTED_VARIANTS:
        raise ValueError(f"{VARIANT_ENV}: {env!r} is not one of {VARIANT_MODES + SUPPORTED_VARIANTS}")
    return env


def _cuda_error() -> VariantUnavailableError:
    return VariantUnavailableError(
        f"variant: {CUDA_VARIANT} requested but no working CUDA device ({_cuda_reason or 'probe failed'}); "
        f"use --variant {LLVM_VARIANT} or leave --variant out (auto) on this machine")


def check_variant(variant: str | None = None) -> None:
    """Fail early, before a render job writes anything, when the variant a render would be forced to use
    (``variant``, else :data:`VARIANT_ENV`) cannot run here. Automatic choice always succeeds (it falls back).

    Raises:
        ValueError: unknown variant name.
        VariantUnavailableError: ``cuda_ad_spectral`` without a working CUDA device, or ``llvm_ad_spectral``
            without a working libLLVM (one line naming ``variant``).
    """
    v = requested_variant(variant)
    if v == CUDA_VARIANT and not probe_cuda():
        raise _cuda_error()
    if v != SCALAR_VARIANT and "drjit" not in sys.modules:
        trust_llvm_env()  # a DRJIT_LIBLLVM_PATH that does not work: one line, and the working library used
    if v == LLVM_VARIANT and not any(probe_llvm(lib) for lib in find_libllvm()):
        raise VariantUnavailableError(f"variant: {LLVM_VARIANT} requested but no working libLLVM was found "
                                      f"({llvm_hint()})")


#: What :func:`trust_llvm_env` found wrong with ``DRJIT_LIBLLVM_PATH`` (one line), or None.
_llvm_env_note: str | None = None
LLVM_ENV = "DRJIT_LIBLLVM_PATH"


def trust_llvm_env() -> str | None:
    """Check the user's ``DRJIT_LIBLLVM_PATH`` before Dr.Jit reads it (drjit loads the library it names once per
    process and shuts its LLVM backend down for good when that fails, so a bad value made every scene fail even
    where a working libLLVM was installed).

    Unset, or naming a library that renders (:func:`probe_llvm`, cached): nothing to do, None. Naming a missing
    file, something that is not a regular file, or a library that does not render: the variable is replaced by
    the first working candidate of :func:`find_libllvm` (or removed when there is none), and one line saying so is
    returned and warned once per process (worker processes inherit the corrected variable). Returns that line.
    """
    global _llvm_env_note
    env = os.environ.get(LLVM_ENV)
    if not env or _llvm_env_note is not None:
        return _llvm_env_note
    if not os.path.exists(env):
        why = "no such file"
    elif not os.path.isfile(env):
        why = "not a regular file"
    else:
        try:
            if probe_llvm(os.path.realpath(env)):
                return None
        except (OSError, ValueError):
            pass
        why = "a probe render with it failed: not a libLLVM Dr.Jit can use here"
    del os.environ[LLVM_ENV]
    working = None
    for lib in find_libllvm():
        try:
            if probe_llvm(lib):
                working = lib
                break
        except (OSError, ValueError):
            continue
    if working is not None:
        os.environ[LLVM_ENV] = working
        _llvm_env_note = f"{LLVM_ENV}={env} does not work ({why}); using {working}, which works here"
    else:
        _llvm_env_note = (f"{LLVM_ENV}={env} does not work ({why}), and no other working libLLVM was found in "
                          f"{', '.join(LLVM_SEARCH_DIRS)}")
    warnings.warn(_llvm_env_note, RuntimeWarning, stacklevel=2)
    return _llvm_env_note


def llvm_hint() -> str:
    """What to do about a missing LLVM back end: what was wrong with ``DRJIT_LIBLLVM_PATH`` when it was set,
    else how to install one."""
    return _llvm_env_note or (f"install Debian's libllvm19 and set DRJIT_LIBLLVM_PATH; see "
                              f"{docs_url('guide/install.md#system-dependency')}")


def _set_llvm(mi) -> bool:
    """Probe the libLLVM candidates and set ``llvm_ad_spectral``; False when none works."""
    for lib in find_libllvm():
        if probe_llvm(lib):
            os.environ["DRJIT_LIBLLVM_PATH"] = lib
            try:
                mi.set_variant(LLVM_VARIANT)
            except (ImportError, AttributeError, RuntimeError) as exc:  # variant not built
                warnings.warn(f"llvm_ad_spectral unavailable ({exc}); using scalar_spectral", RuntimeWarning,
                              stacklevel=3)
                return False
            return True
    return False


def _set_cuda(mi) -> bool:
    """Probe CUDA and set ``cuda_ad_spectral``; False when it does not work (nothing changed then)."""
    global _cuda_reason
    if not probe_cuda():
        return False
    try:
        mi.set_variant(CUDA_VARIANT)
    except (ImportError, AttributeError, RuntimeError) as exc:  # probe passed in the child, not here
        _cuda_reason = f"{type(exc).__name__}: {exc}"
        return False
    return True


def select_variant(variant: str | None = None) -> str:
    """Choose and set the Mitsuba variant for rendering; returns its name.

    Args:
        variant: ``None`` (auto: :data:`VARIANT_ENV` when it names a variant; else ``cuda_ad_spectral`` when a
            CUDA device works (not with ``LFMBENCH_VARIANT=cpu``), else ``llvm_ad_spectral`` when a probed
            libLLVM works, else ``scalar_spectral`` with a :class:`RuntimeWarning`), or one of
            :data:`SUPPORTED_VARIANTS` to force it (``cuda_ad_spectral`` / ``llvm_ad_spectral`` raise
            :class:`VariantUnavailableError` when they cannot run here).
    Raises:
        ValueError: ``variant`` is not supported.
    """
    global _chosen
    if requested_variant(variant) != SCALAR_VARIANT and "drjit" not in sys.modules:
        trust_llvm_env()  # before drjit reads DRJIT_LIBLLVM_PATH (it does so once per process)
    import mitsuba as mi  # noqa: PLC0415

    variant = requested_variant(variant)
    if variant == SCALAR_VARIANT:
        mi.set_variant(SCALAR_VARIANT)
        return SCALAR_VARIANT
    no_cuda = os.environ.get(VARIANT_ENV, "").strip() == "cpu"
    if _chosen is not None and (variant is None or variant == _chosen) and not (no_cuda and _chosen == CUDA_VARIANT):
        mi.set_variant(_chosen)
        return _chosen
    if variant == CUDA_VARIANT:
        if not _set_cuda(mi):
            raise _cuda_error()
        _chosen = CUDA_VARIANT
        return _chosen
    # Once a JIT backend was initialised in this process (its libLLVM is fixed), reuse it in auto mode.
    current = mi.variant()
    if current == LLVM_VARIANT or (current == CUDA_VARIANT and variant is None and not no_cuda):
        _chosen = current
        return _chosen
    if variant is None and not no_cuda and _set_cuda(mi):
        _chosen = CUDA_VARIANT
        return _chosen
    if _set_llvm(mi):
        _chosen = LLVM_VARIANT
        return _chosen
    if variant == LLVM_VARIANT:
        raise VariantUnavailableError("variant: llvm_ad_spectral requested but no working libLLVM was found "
                                      f"({llvm_hint()})")
    warnings.warn(f"no working libLLVM found (LLVM 15 crashes on these CPUs; {llvm_hint()}): rendering with the "
                  "slow scalar_spectral variant", RuntimeWarning, stacklevel=2)
    mi.set_variant(SCALAR_VARIANT)
    _chosen = SCALAR_VARIANT
    return _chosen


def clamp_roundoff(radiance: np.ndarray, rel_tol: float = ROUNDOFF_RTOL, name: str = "radiance") -> np.ndarray:
    """Set tiny negative round-off of a rendered radiance layer to 0; keep larger negatives an error.

    The JIT back ends (notably ``cuda_ad_spectral``) return values like -1.25e-9 W sr^-1 m^-2 nm^-1 where the
    exact answer is 0, which the corpus writer refuses. Values ``v`` with ``-rel_tol * peak <= v < 0`` (``peak``
    = the layer's largest value, same units) become 0; anything more negative is a real bug and raises.

    Args:
        radiance: one layer as the renderer returns it, e.g. (C, H, W) or (K, C, h, w) float32,
            W sr^-1 m^-2 nm^-1. NaN / inf are left as they are (the corpus writer reports them).
        rel_tol: tolerance relative to the layer peak (dimensionless, >= 0).
        name: what to call the layer in the error message.
    Returns:
        ``radiance`` itself when nothing is negative, else a copy (same shape and dtype) with the round-off
        set to 0.
    Raises:
        ValueError: ``rel_tol`` is negative or not finite; ``radiance`` has a negative value below
            ``-rel_tol * peak`` (message names ``name``, the minimum and the peak).
    """
    if not (isinstance(rel_tol, (int, float)) and math.isfinite(rel_tol) and rel_tol >= 0):
        raise ValueError(f"rel_tol: must be a finite number >= 0, got {rel_tol!r}")
    a = np.asarray(radiance)
    if a.size == 0:
        return radiance
    lo = np.nanmin(a) if np.isnan(a).any() else a.min()
    if not lo < 0:  # also all-NaN
        return radiance
    finite = a[np.isfinite(a)]
    peak = max(float(finite.max()), 0.0) if finite.size else 0.0
    if lo < -rel_tol * peak:
        raise ValueError(f"{name}: negative value {float(lo):.3g} below the round-off tolerance "
                         f"-{rel_tol:g} x peak ({peak:.3g}); not clamped")
    return np.where(a < 0, np.zeros((), a.dtype), a)


def is_llvm() -> bool:
    """True when the active Mitsuba variant is a JIT (llvm/cuda) one."""
    import mitsuba as mi  # noqa: PLC0415

    return mi.variant() is not None and not mi.variant().startswith("scalar")
