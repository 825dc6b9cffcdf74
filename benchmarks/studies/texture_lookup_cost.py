"""Where the procedural textures' tracer cost is (issue 40, deliverable 5): writes the section "Texture lookup
variants" of docs/benchmarks/textures.md.

One process renders frame 0 of a generator-2 scene (default: seed 101, wet night, the case over the 1.5x target in
docs/benchmarks/render-scale.md) with the ``default`` profile's options at ``--size`` (default 160x90: the lookups are
a cost per path vertex, the same share at any size), in variants that take the textured materials apart step by step:

- ``flat``: every ``texture`` removed (flat colours, welded meshes without texture coordinates);
- ``uv``: the textured materials' meshes as rendered (unwelded, box-projected texture coordinates) with their flat
  base colour (Mitsuba's ``rgb``): the cost of the texture coordinates alone;
- ``nearest``: the bitmaps with nearest-texel lookups (one texel fetched and upsampled to the 4 wavelengths);
- ``bilinear``: as rendered (Mitsuba 3's ``bitmap``, bilinear: four texels fetched, each upsampled to the 4
  wavelengths by the Jakob-Hanika model, then interpolated).

Every variant is rendered once untimed (its kernel compiled or loaded from the disk cache), then ``--repeats`` times,
the variants alternating so that a change of the machine's load hits all alike. Reported per variant: CPU seconds of
the process inside :meth:`render_tools.tracer.Tracer.render` (the traced kernel; median), its ratio to ``bilinear``
render by render (median), and the operation count of the frame's largest Dr.Jit kernel (the path tracer with every
BSDF's callable; Dr.Jit's kernel history, independent of the load).

Usage: ``python benchmarks/studies/texture_lookup_cost.py [--seed 101] [--tod night] [--weather wet] [--size 160 90]
[--repeats 6]``.
"""
from __future__ import annotations

import argparse
import datetime
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import _llvm  # noqa: E402,F401 - sets DRJIT_LIBLLVM_PATH
from _timing import replace_section  # noqa: E402

SECTION = "## Texture lookup variants (issue 40)"
VARIANTS = ("flat", "uv", "nearest", "bilinear")


def main() -> None:
    import drjit as dr  # noqa: PLC0415

    from render_tools import mitsuba_scene as ms  # noqa: PLC0415
    from render_tools import render as rnd  # noqa: PLC0415
    from render_tools import scene as S  # noqa: PLC0415
    from render_tools import textures, tracer  # noqa: PLC0415
    from render_tools.jobs import load_profile  # noqa: PLC0415

    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=101)
    ap.add_argument("--tod", default="night")
    ap.add_argument("--weather", default="wet")
    ap.add_argument("--size", type=int, nargs=2, default=[160, 90])
    ap.add_argument("--repeats", type=int, default=6)
    ap.add_argument("--out", default=str(ROOT / "docs"))
    a = ap.parse_args()
    load0, t0 = os.getloadavg()[0], time.time()
    sc = S.generate_scene(a.seed, a.tod, generator=2, overrides={"weather": {"conditions": [a.weather]}})
    flat = textures.untextured(sc)
    opts = rnd.RenderOptions(**dict(load_profile("default"), frames=1, aux=False, seed=11, width=a.size[0],
                                    height=a.size[1], texture_filter="bilinear"))  # the variants replace it
    bitmap = ms._reflectance

    def nearest(m: dict, *_) -> dict:
        d = bitmap(m)
        return dict(d, filter_type="nearest") if d["type"] == "bitmap" else d

    setups = {"flat": (flat, bitmap), "uv": (sc, lambda m, *_: {"type": "rgb", "value": list(m["rgb"])}),
              "nearest": (sc, nearest), "bilinear": (sc, bitmap)}
    spent = [0.0]
    render = tracer.Tracer.render

    def timed(self, *args, **kw):
        c = time.process_time()
        try:
            return render(self, *args, **kw)
        finally:
            spent[0] += time.process_time() - c

    tracer.Tracer.render = timed
    cpu: dict = {v: [] for v in VARIANTS}
    ops: dict = {}
    try:
        for r in range(a.repeats + 1):
            for v in VARIANTS:
                scene, refl = setups[v]
                ms._reflectance = refl
                spent[0] = 0.0
                dr.kernel_history()  # clears it
                dr.set_flag(dr.JitFlag.KernelHistory, True)
                next(rnd.render_frames(scene, opts))
                dr.set_flag(dr.JitFlag.KernelHistory, False)
                hist = [h for h in dr.kernel_history() if h.get("type") == dr.KernelType.JIT]
                ops[v] = max((h.get("operation_count", 0) for h in hist), default=0)
                if r:
                    cpu[v].append(spent[0])
                print(v, "warm" if r else "first", f"{spent[0]:.2f} CPU s, kernel ops {ops[v]}", flush=True)
    finally:
        ms._reflectance = bitmap
        tracer.Tracer.render = render
    load1 = os.getloadavg()[0]
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [SECTION, "",
             f"Generated by `benchmarks/studies/texture_lookup_cost.py` on {date}, the project's shared 2-core AMD "
             f"EPYC (AVX2), 1-minute load average {load0:.1f} at the start and {load1:.1f} at the end "
             f"({(time.time() - t0) / 60:.0f} min): scene generator 2, seed {a.seed}, {a.tod}, {a.weather}, frame 0, "
             f"the `default` profile's options at {a.size[0]}x{a.size[1]}; CPU seconds in the tracer per render, "
             f"{a.repeats} renders per variant alternating (module docstring).", "",
             "| variant | tracer CPU s (median) | ratio to bilinear (median of render-by-render) | kernel operations |",
             "|---|---|---|---|"]
    for v in VARIANTS:
        ratio = statistics.median(x / y for x, y in zip(cpu[v], cpu["bilinear"]))
        lines.append(f"| {v} | {statistics.median(cpu[v]):.2f} | {ratio:.2f} | {ops[v]} |")
    lines += ["", "Run again with `python benchmarks/studies/texture_lookup_cost.py`.", ""]
    replace_section(Path(a.out) / "benchmarks" / "textures.md", SECTION, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
