"""Mitsuba 3 variant selection: the fast ``llvm_ad_spectral`` path where a working libLLVM exists, else
``scalar_spectral`` with a warning.

Facts this relies on (``/work/shared/reference/environment.md``): drjit's LLVM backend loads the shared
library named by ``DRJIT_LIBLLVM_PATH``; LLVM 15 crashes inside code generation on AVX-512 CPUs (a segfault
that cannot be caught in-process), while Debian's ``libllvm19`` works and is 5-10x faster than the scalar
variant. A candidate library is therefore *probed in a child process* (render of a tiny scene) before the
parent process commits to it; the verdict is cached on disk keyed by library path, size and mtime and the
Mitsuba version, so the probe costs a few seconds once per machine.

Functions
- :func:`find_libllvm` -> candidate library paths, best first.
- :func:`probe_llvm` -> whether a library renders in a child process.
- :func:`select_variant` -> the variant name, set in Mitsuba (``mi.set_variant``).
"""
from __future__ import annotations

import glob
import json
import os
import re
import subprocess
import sys
import warnings

from lfmbench.fileio import atomic_write_json

#: Preferred spectral variants, fast first.
LLVM_VARIANT = "llvm_ad_spectral"
SCALAR_VARIANT = "scalar_spectral"
#: Variants :func:`select_variant` accepts when named explicitly.
SUPPORTED_VARIANTS = (LLVM_VARIANT, SCALAR_VARIANT)
#: Major LLVM versions known to crash drjit on these CPUs (environment.md).
BROKEN_LLVM_MAJORS = (15,)
#: Directories searched for ``libLLVM*.so*``.
LLVM_SEARCH_DIRS = ("/usr/lib/x86_64-linux-gnu", "/usr/lib64", "/usr/lib", "/usr/local/lib")
#: Seconds allowed for the child-process probe.
PROBE_TIMEOUT_S = 120.0

_PROBE_SCRIPT = r"""
import mitsuba as mi, drjit as dr
mi.set_variant('llvm_ad_spectral')
s = mi.load_dict({'type': 'scene', 'integrator': {'type': 'path'},
    'sensor': {'type': 'perspective', 'film': {'type': 'specfilm', 'width': 8, 'height': 8,
               'b': {'type': 'regular', 'wavelength_min': 500, 'wavelength_max': 510, 'values': '1, 1'}}},
    'e': {'type': 'constant', 'radiance': 1.0},
    'r': {'type': 'sphere', 'center': [0, 0, 4], 'radius': 1.0}})
img = mi.render(s, spp=4)
v = float(dr.mean(mi.TensorXf(img)).array[0])
assert v == v and v > 0, v
print('LLVM_PROBE_OK', v)
"""

_chosen: str | None = None


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


def _cache_path() -> str:
    root = os.environ.get("XDG_CACHE_HOME", os.path.join(os.path.expanduser("~"), ".cache"))
    return os.path.join(root, "lfmbench", "llvm_probe.json")


def _cache_key(lib: str) -> str:
    import mitsuba  # noqa: PLC0415 - heavy, needed only here

    st = os.stat(lib)
    return f"{lib}|{st.st_size}|{int(st.st_mtime)}|mitsuba-{mitsuba.__version__}"


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
    cache: dict = {}
    if use_cache and os.path.isfile(cache_file):
        try:
            with open(cache_file, encoding="utf-8") as fh:
                cache = json.load(fh)
        except (OSError, ValueError):
            cache = {}
        if key in cache:
            return bool(cache[key])
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=lib)
    try:
        res = subprocess.run([sys.executable, "-c", _PROBE_SCRIPT], env=env, capture_output=True, text=True,
                             timeout=PROBE_TIMEOUT_S)
        ok = res.returncode == 0 and "LLVM_PROBE_OK" in res.stdout
    except subprocess.TimeoutExpired:
        ok = False
    if use_cache:
        cache[key] = ok
        atomic_write_json(cache_file, cache)
    return ok


def select_variant(variant: str | None = None) -> str:
    """Choose and set the Mitsuba variant for rendering; returns its name.

    Args:
        variant: ``None`` (auto: ``llvm_ad_spectral`` when a probed libLLVM works, else ``scalar_spectral``
            with a :class:`RuntimeWarning`), or one of :data:`SUPPORTED_VARIANTS` to force it
            (``llvm_ad_spectral`` still requires a working libLLVM and raises ``RuntimeError`` otherwise).
    Raises:
        ValueError: ``variant`` is not supported.
    """
    global _chosen
    import mitsuba as mi  # noqa: PLC0415

    if variant is not None and variant not in SUPPORTED_VARIANTS:
        raise ValueError(f"variant: {variant!r} not in {SUPPORTED_VARIANTS}")
    if variant == SCALAR_VARIANT:
        mi.set_variant(SCALAR_VARIANT)
        return SCALAR_VARIANT
    if _chosen is not None and (variant is None or variant == _chosen):
        mi.set_variant(_chosen)
        return _chosen
    # Once the LLVM backend was initialised in this process, its library is fixed: reuse it.
    if mi.variant() == LLVM_VARIANT:
        _chosen = LLVM_VARIANT
        return _chosen
    for lib in find_libllvm():
        if probe_llvm(lib):
            os.environ["DRJIT_LIBLLVM_PATH"] = lib
            try:
                mi.set_variant(LLVM_VARIANT)
            except (ImportError, AttributeError, RuntimeError) as exc:  # variant not built
                warnings.warn(f"llvm_ad_spectral unavailable ({exc}); using scalar_spectral", RuntimeWarning,
                              stacklevel=2)
                break
            _chosen = LLVM_VARIANT
            return _chosen
    if variant == LLVM_VARIANT:
        raise RuntimeError("variant: llvm_ad_spectral requested but no working libLLVM was found "
                           "(install Debian's libllvm19 and set DRJIT_LIBLLVM_PATH; see docs/rendering.md)")
    warnings.warn("no working libLLVM found (LLVM 15 crashes on these CPUs; install libllvm19 and set "
                  "DRJIT_LIBLLVM_PATH): rendering with the slow scalar_spectral variant", RuntimeWarning,
                  stacklevel=2)
    mi.set_variant(SCALAR_VARIANT)
    _chosen = SCALAR_VARIANT
    return _chosen


def is_llvm() -> bool:
    """True when the active Mitsuba variant is a JIT (llvm/cuda) one."""
    import mitsuba as mi  # noqa: PLC0415

    return mi.variant() is not None and not mi.variant().startswith("scalar")
