"""Every integer ``//`` and ``%`` in a Dr.Jit kernel has a divisor that cannot be 0 in a masked lane
(render_tools/kernel_rules.py). The check reads the source, so it fails on any CPU, not only on those whose
LLVM code traps (SIGFPE) on a division by the 0 that masked tail lanes gather."""
from __future__ import annotations

import ast
import textwrap
from pathlib import Path

import numpy as np
import pytest

from render_tools.kernel_rules import DIVISOR_HELPER, HOST_INT_CALLS, lane_divisor

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("render_tools", "lfmbench")


def _imports_drjit(tree: ast.AST) -> bool:
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "drjit" for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "drjit":
            return True
    return False


def _uses_jit(fn: ast.AST) -> bool:
    """A function builds kernel code when it refers to ``dr`` or ``mi`` (the Dr.Jit / Mitsuba modules)."""
    return any(isinstance(n, ast.Name) and n.id in ("dr", "mi") for n in ast.walk(fn))


def _safe(node: ast.AST, safe_names: set[str]) -> bool:
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
        return True
    if isinstance(node, ast.Name):
        return node.id.isupper() or node.id in safe_names
    if isinstance(node, ast.Attribute):
        return node.attr.isupper()
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
        return node.func.id == DIVISOR_HELPER or node.func.id in HOST_INT_CALLS
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Mult)):
        return _safe(node.left, safe_names) and _safe(node.right, safe_names)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        return _safe(node.operand, safe_names)
    return False


def _safe_names(fn: ast.AST) -> set[str]:
    """Names bound in ``fn`` only from safe expressions (``w = lane_divisor(...)``, ``a, b = (lane_divisor(x)
    for x in ...)``); iterated to a fixed point, so ``n = m * 2`` with a safe ``m`` counts."""
    safe: set[str] = set()
    bad: set[str] = set()
    changed = True
    while changed:
        changed = False
        for node in ast.walk(fn):
            if not isinstance(node, ast.Assign):
                continue
            for tgt in node.targets:
                names = [tgt] if isinstance(tgt, ast.Name) else list(getattr(tgt, "elts", []))
                val = node.value
                if isinstance(val, ast.GeneratorExp) and _safe(val.elt, safe):
                    ok = True
                elif isinstance(tgt, ast.Tuple) and isinstance(val, ast.Tuple):
                    ok = None
                    for t, v in zip(tgt.elts, val.elts):
                        if isinstance(t, ast.Name) and t.id not in safe and t.id not in bad and _safe(v, safe):
                            safe.add(t.id)
                            changed = True
                    continue
                else:
                    ok = _safe(val, safe)
                for t in names:
                    if isinstance(t, ast.Name):
                        if not ok:
                            bad.add(t.id)
                        elif t.id not in safe:
                            safe.add(t.id)
                            changed = True
    return safe - bad


def violations(source: str, filename: str = "<src>") -> list[str]:
    """``file:line: expr`` for every unguarded integer ``//`` or ``%`` in a kernel-building function."""
    tree = ast.parse(source, filename)
    if not _imports_drjit(tree):
        return []
    out = []
    for fn in ast.walk(tree):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)) or not _uses_jit(fn):
            continue
        safe = _safe_names(fn)
        for node in ast.walk(fn):
            if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.FloorDiv, ast.Mod)):
                div = node.right
            elif isinstance(node, ast.AugAssign) and isinstance(node.op, (ast.FloorDiv, ast.Mod)):
                div = node.value
            else:
                continue
            if isinstance(node, ast.BinOp) and isinstance(node.left, ast.Constant) and isinstance(node.left.value, str):
                continue  # "%" string formatting
            if not _safe(div, safe):
                out.append(f"{filename}:{node.lineno}: {ast.unparse(node)}")
    return sorted(set(out))


def test_every_kernel_divisor_is_guarded():
    files = [p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))]
    checked = [p for p in files if _imports_drjit(ast.parse(p.read_text(), str(p)))]
    assert any(p.name == "tracer.py" for p in checked)  # the check sees the kernel modules
    bad = [v for p in checked for v in violations(p.read_text(), str(p.relative_to(ROOT)))]
    assert not bad, "integer // or % by a value that can be 0 in a masked lane (use lane_divisor):\n" + "\n".join(bad)


KERNEL = '''
import drjit as dr
import mitsuba as mi
from render_tools.kernel_rules import lane_divisor
MAX_LANES = 1 << 20

def trace(tab, lane, n, {params}):
    g = lambda k: dr.gather(mi.UInt32, tab[k], lane)
    {body}
'''


@pytest.mark.parametrize("body", [
    "w = g('w'); return lane % w",                       # gathered divisor (the SIGFPE of issue 21)
    "w, h = g('w'), g('h'); r = lane // w; return r % h",
    "return lane % (g('w') + 1)",                         # computed divisor
    "spp = g('spp'); x = lane; x %= spp; return x",
    "return lane // k",                                   # a parameter
])
def test_check_finds_unguarded_divisors(body):
    assert violations(textwrap.dedent(KERNEL).format(params="k", body=body)), body


@pytest.mark.parametrize("body", [
    "w = lane_divisor(g('w')); return lane % w",
    "w, h = (lane_divisor(g(k)) for k in ('w', 'h')); return (lane // w) % h",
    "return lane % lane_divisor(g('w'))",
    "return lane % 7 + lane // MAX_LANES",
    "W, H = 4, 3; return lane % (W * H)",
    "n2 = int(n); return lane // n2",
    "return '%d lanes' % n",
])
def test_check_accepts_guarded_divisors(body):
    assert not violations(textwrap.dedent(KERNEL).format(params="k", body=body)), body


def test_host_code_outside_kernels_is_not_checked():
    src = "import drjit as dr\ndef f(a, b):\n    return -(-a // b)\n"  # refers to neither dr nor mi
    assert not violations(src)


def test_lane_divisor_on_host_ints():
    assert [lane_divisor(v) for v in (0, 1, 5)] == [1, 1, 5]


ODD_RENDER = '''
import sys
import numpy as np
sys.path.insert(0, {root!r})
import drjit as dr
import mitsuba as mi
from tests.data.render.data import street as _street
from render_tools import backend, mitsuba_scene as ms, render, tracer
s = _street()
opts = render.RenderOptions(width=37, height=23, spp=3, light_spp=5, bins=3, frames=1, aux=False, seed=1)
backend.select_variant(None)
geo = render.SceneGeometry(s, opts)
loaded = mi.load_dict(ms.mitsuba_dict(s, 0.0, emit="all"))
sets = tracer.LightSets(mi, dr, loaded, s, ["streetlights", "otherlights"])
tr = tracer.Tracer(mi, dr, loaded, sets, geo.ego, geo.fov, (opts.width, opts.height), opts.bands_nm,
                   opts.band_width_nm)
# lanes = (5 x 7 px x 3 bins + 1 px x 2 bins) x P band passes = 107 P: no multiple of 16 for any P < 16
tiles = [tracer.Tile((3, 4, 8, 11), 3, 0.0, 0.004, 3, sets["group:streetlights"], key=5),
         tracer.Tile((10, 20, 11, 21), 2, 0.0, 0.008, 5, sets["light:0"], key=9)]
out = tr.render(tiles, 1)
lanes = sum((t.crop[2] - t.crop[0]) * (t.crop[3] - t.crop[1]) * t.bins * tr.P for t in tiles)
assert lanes % 16, lanes
assert all(np.isfinite(a).all() and (a >= 0).all() for a in out), "non-finite or negative radiance"
assert out[0].sum() > 0
print("ok", lanes)
'''


@pytest.mark.slow
@pytest.mark.jit
def test_render_whose_lane_count_is_no_multiple_of_the_packet_width(tmp_path):
    """37 x 23 px, 3 bins, odd sample counts: no launch is a multiple of 8 or 16 lanes, so the last packet has
    masked lanes. Before the divisors were guarded this died with SIGFPE on AVX-512 CPUs (issue 21). Run in a
    child process so that a crash is a test failure with its signal, not a dead test worker."""
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-c", ODD_RENDER.format(root=str(ROOT))], capture_output=True, text=True,
                       timeout=300, cwd=tmp_path)
    assert p.returncode == 0, f"render died (return code {p.returncode}): {p.stderr[-2000:]}"
    assert p.stdout.startswith("ok")


@pytest.mark.parametrize("n", [0, 1, 2, 3, 17, 1000])
@pytest.mark.parametrize("dtype", [None, np.uint32, np.float64])
def test_kernel_input_is_aligned_padded_and_keeps_the_values(n, dtype):
    """kernel_rules.kernel_input: 64-byte aligned whatever the source's address (a view at an odd offset), at
    least 2 entries (the tail repeats the last, 0 for none), the values cast to the dtype (float32 by default)."""
    from render_tools.kernel_rules import KERNEL_INPUT_ALIGN, kernel_input

    raw = np.arange(n + 1, dtype=np.float64)[1:] * 3  # a view 8 bytes into its buffer: not 64-byte aligned
    for _ in range(3):  # fresh buffers each call: alignment holds for each
        a = kernel_input(raw, dtype)
        assert a.ctypes.data % KERNEL_INPUT_ALIGN == 0
        assert a.dtype == np.dtype(np.float32 if dtype is None else dtype)
        assert a.shape == (max(n, 2),)
        np.testing.assert_array_equal(a[:n], raw.astype(a.dtype))
        if n < 2:
            assert (a[n:] == (raw[-1] if n else 0)).all()
