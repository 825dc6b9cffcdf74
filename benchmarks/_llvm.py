"""Point drjit at Debian's libLLVM 19 before Mitsuba loads, unless the user set ``DRJIT_LIBLLVM_PATH``.

LLVM 15 crashes in code generation on this machine's AVX-512 CPUs (docs/guide/rendering.md); the benchmark scripts
that render import this module first (``import _llvm``; run them as ``python benchmarks/<script>.py``).
"""
from __future__ import annotations

import os

#: Debian's libllvm19 (``make llvm`` installs it).
LLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"

if "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(LLVM19):
    os.environ["DRJIT_LIBLLVM_PATH"] = LLVM19
