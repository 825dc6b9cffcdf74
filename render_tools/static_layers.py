"""Static window layers: the static groups rendered once over a named union of capture windows.

A chopped sensor integrates the scene over n short sub-windows spread across the frame (12 x 0.1 ms over 10.22 ms:
lfmbench/configs/sensors/chopped.yaml). Static time bins (``RenderOptions.static_edges_s``) would need 2 n more edges,
each bin a full frame. A *layer* (``RenderOptions.static_layers``: a name and the windows ``[[start_s, length_s],
...]``, s from the frame start) is instead one full frame's samples spread over the union. Sample s of a pixel's
``spp`` lies in sub-window (j0 + floor(s n / spp)) mod n (:func:`sample_counts`: a pixel's samples spread evenly
over the sub-windows, stratified in time), where j0, the pixel's first sub-window, is dealt as a permutation of
every n consecutive runs of :data:`RUN_PX` pixels of a row with a random rotation per group (:func:`assignment`).
Sub-window j's samples are traced over [a_j, a_j + |w_j|) with the ego camera moving continuously and the moving
objects at the sub-window's middle (as a static time bin), one launch per sub-window, and each sample is weighted by
n |w_j| / |U| (|U|: the union's length). Unbiased for the time average over the union: j0 is uniform over the n (a
random rotation), so is each sample's sub-window, and E[n |w_j| / |U| L_j] = sum_j |w_j| / |U| L_j, the exact
length-weighted mean (Monte Carlo integration over a stratified discrete dimension: A. B. Owen, "Monte Carlo theory,
methods and examples", 2013, chapters 8 and 10). What it adds to a pixel's variance is the spread of L_j over its
samples' sub-windows, zero where nothing moves on screen. The cost is one static frame at ``spp`` (plus a scene
update and a kernel launch per sub-window where an object moves); the storage one (C, H, W) image per static group
and frame.

The layers of a scene are rendered after its other files (:func:`render_layer`) and stored beside them
(:mod:`lfmbench.corpus.window_layers`, :func:`write_layers`), so a corpus rendered without a layer gets it added
without a change to a file it already has (:func:`render_tools.jobs.add_layers`, ``lfmbench render --add-layers``).
"""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

#: Pixels in a row that share a sub-window (:func:`assignment`): the pixels of one sub-window are traced as row
#: segments of this length, so a 160x90 frame is about 3,600 tiles instead of 28,800 (the tracer's per-tile cost is
#: Python: 6.7 CPU s of a 160x90 frame went to 53,600 one-pixel tiles, measured with cProfile on 2026-11-28).
RUN_PX = 8


def assignment(height: int, width: int, n: int, seed: int, run: int = RUN_PX) -> np.ndarray:
    """(H, W) int: the first sub-window (0 .. n - 1) of each pixel. Each row is cut into runs of ``run`` pixels
    (one sub-window per run), the runs in row-major order into groups of n; in group g run i takes sub-window
    (i + r_g) mod n, r_g uniform in 0 .. n - 1 drawn from ``seed``: every sub-window once per group, each pixel's
    sub-window uniform (over the seed)."""
    per_row = -(-width // run)
    q = np.arange(height)[:, None] * per_row + np.arange(width)[None, :] // run       # run index of each pixel
    r = np.random.default_rng(seed).integers(0, n, size=-(-height * per_row // n))
    return (q % n + r[q // n]) % n


def sample_counts(j0: np.ndarray, n: int, spp: int, j: int) -> np.ndarray:
    """Samples (same shape as ``j0``) that each pixel takes in sub-window ``j`` of ``n``: sample s of a pixel whose
    first sub-window is ``j0`` (:func:`assignment`) lies in sub-window (j0 + floor(s n / spp)) mod n, so a pixel's
    ``spp`` samples are spread evenly over the sub-windows (stratified in time) and each sample's sub-window is
    uniform over the n."""
    s = np.arange(spp)
    js = (j0[..., None] + (s * n) // spp) % n
    return (js == j).sum(-1)


def plan_layer(scene: dict, opts, sets, geo, wins_abs, t_subs, qmc: bool, key: str):
    """The layer's tiles over one frame, the same for every sub-window but the time: a list of (kind, group or
    union groups, crop, spp, light set, key) with ``kind`` "static" / "union" (the full frame at ``spp``) or
    "refine" (a static group's lamp in its box over every sub-window, objects at each sub-window's middle, at
    ``light_spp``), as :func:`render_tools.render.plan_static_bins` plans a time bin."""
    from . import render as R  # noqa: PLC0415

    full = (0, 0, opts.height, opts.width)
    light_spp = opts.light_spp or opts.spp
    rpad = R.refine_pad(scene, opts)
    union = list(getattr(sets, "union", ()) or ())
    out = []
    if union:
        out.append(("union", tuple(union), full, opts.spp, sets["union:static"], R._seed("union", key)))
    for g, info in R._selected_groups(scene, opts).items():
        if info["flicker"]:
            continue
        if g not in union:
            out.append(("static", g, full, opts.spp, sets[f"group:{g}"], R._seed("static", g, key)))
        for lt in ([lt for lt in scene["lights"] if lt["group"] == g] if light_spp > opts.spp else ()):
            boxes = [b for b in (geo.light_bbox(lt, t, a, b_, pad=rpad) for (a, b_), t in zip(wins_abs, t_subs))
                     if b is not None]
            if boxes:
                crop = (min(b[0] for b in boxes), min(b[1] for b in boxes), max(b[2] for b in boxes),
                        max(b[3] for b in boxes))
                out.append(("refine", g, crop, light_spp, sets[f"group:{g}"], R._seed("refine", g, key, lt["id"])))
    return out


def _segments(c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Row segments of ``c`` (h, w) int where it is > 0 and constant: (y, x0, x1, value), x1 exclusive."""
    h, w = c.shape
    start = np.ones((h, w), bool)
    start[:, 1:] = c[:, 1:] != c[:, :-1]
    ys, x0 = np.nonzero(start)
    ends = np.append(x0[1:], w)
    ends[np.append(ys[1:] != ys[:-1], True)] = w                  # a segment ends with its row
    v = c[ys, x0]
    keep = v > 0
    return ys[keep], x0[keep], ends[keep], v[keep]


def _pixel_tiles(plan, j0: np.ndarray, n: int, j: int, a: float, dt: float, qmc: bool, width: int):
    """Each entry of ``plan`` (:func:`plan_layer`) cut into one-row tiles over the pixels with samples in
    sub-window ``j`` ([a, a + dt) s, absolute), each with its count (:func:`sample_counts`). Returns (tiles,
    [(y, x0, x1, counts) arrays (P,) per entry, first tile index])."""
    from .tracer import Tile  # noqa: PLC0415

    tiles, where = [], []
    for kind, g, (y0, x0, y1, x1), spp, lset, key in plan:
        ys, xa, xb, cs = _segments(sample_counts(j0[y0:y1, x0:x1], n, spp, j))
        ys, xa, xb = ys + y0, xa + x0, xb + x0
        where.append(((ys, xa, xb, cs), len(tiles)))
        slots = len(g) if kind == "union" else 1
        # a tile's key: its entry's and its first pixel's index (its random numbers, whatever else is traced)
        tiles += [Tile((y, u, y + 1, v), 1, a, dt, k, lset, slots=slots, sobol=qmc,
                       key=(key * 0x9E3779B1 + y * width + u + 1) & 0x7FFFFFFF)
                  for y, u, v, k in zip(ys.tolist(), xa.tolist(), xb.tolist(), cs.tolist())]
    return tiles, where


def render_layer(scene: dict, opts, layer: tuple) -> Iterator[dict]:
    """Render ``layer`` (``(name, ((start_s, length_s), ...))``, an entry of :func:`parse_layers`) of every frame of
    ``scene``; yields ``{"frame": n, "static": {group: (C, H, W) float32}}``, the time-averaged spectral radiance
    (W sr^-1 m^-2 nm^-1) of each static group over the layer's union of windows (module docstring). Nothing is
    yielded for a scene where nothing moves (:func:`render_tools.render.scene_moves`: every window's average is the
    long window's)."""
    import gc  # noqa: PLC0415

    from . import backend
    from . import mitsuba_scene as ms
    from . import render as R

    R.validate_scene(scene)
    opts.validate()
    if not R.scene_moves(scene):
        return
    name, wins = layer
    n_sub = len(wins)
    union_s = float(sum(n for _, n in wins))
    scene, _filled = R.dots_lod(scene, opts)
    groups = R._selected_groups(scene, opts)
    mcache: dict = ms.prepare_geometry(scene, {})
    variant = backend.select_variant(opts.variant)
    if variant.startswith("scalar"):
        raise RuntimeError(f"variant: rendering needs a JIT variant of Mitsuba, got {variant}: {backend.llvm_hint()}")
    import drjit as dr  # noqa: PLC0415
    import mitsuba as mi  # noqa: PLC0415

    from . import tracer  # noqa: PLC0415

    geo = R.SceneGeometry(scene, opts)
    obj_moving = R.objects_move(scene)
    qmc = R.sobol_pixel_samples(scene, opts)
    H, W, C = opts.height, opts.width, len(opts.bands_nm)
    pad = None
    for f in range(opts.frames):
        tm = R.frame_timing(scene, opts, f)
        t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
        j0 = assignment(H, W, n_sub, R._seed(opts.seed, f, "layer", name))
        loaded = mi.load_dict(ms.mitsuba_dict(scene, t_obj, emit="all", cache=mcache, unit_sky=True,
                                              texture_filter=R.texture_filter(scene, opts)))
        if pad is None:
            pad = tracer.pad_registry(mi, dr, loaded, mcache["off_lens"])
        params = mi.traverse(loaded)
        wins_abs = [(tm["t0"] + a, tm["t0"] + a + n) for a, n in wins]
        t_subs = [0.5 * (a + b) if obj_moving else t_obj for a, b in wins_abs]
        plan, acc = None, None
        for j, ((ta, tb), t_sub) in enumerate(zip(wins_abs, t_subs)):
            lb = loaded
            if obj_moving and not ms.place_moving(params, scene, t_sub, mcache):
                lb = mi.load_dict(ms.mitsuba_dict(scene, t_sub, emit="all", cache=mcache, unit_sky=True,
                                              texture_filter=R.texture_filter(scene, opts)))
            sets = tracer.LightSets(mi, dr, lb, scene, list(groups), union=R.static_union(groups, opts))
            tr = tracer.Tracer(mi, dr, lb, sets, geo.ego, geo.fov, (W, H), opts.bands_nm, opts.band_width_nm,
                               sky_scale=ms.sky_scale(scene), gloss=R.glossy_choice(mi, dr, scene, opts, mcache))
            if plan is None:  # the same entries (light sets, crops) in every sub-window
                plan = plan_layer(scene, opts, sets, geo, wins_abs, t_subs, qmc, f"layer/{name}")
                acc = [np.zeros((e[0] == "union" and len(e[1]) or 1, C, e[2][2] - e[2][0], e[2][3] - e[2][1]))
                       for e in plan]
            pt, where = _pixel_tiles(plan, j0, n_sub, j, ta, tb - ta, qmc, W)
            out = tr.render(pt, R._seed(opts.seed, f, "layer", name, j)) if pt else []
            wsub = n_sub * (tb - ta) / union_s  # the sub-window's weight (module docstring)
            for e, ((ys, xa, xb, cs), i0), a_ in zip(plan, where, acc):
                ey, ex = e[2][0], e[2][1]
                for i, (y, u, v, k) in enumerate(zip(ys.tolist(), xa.tolist(), xb.tolist(), cs.tolist())):
                    # the tile's mean over its k samples, (S, C, v - u), weighted (module docstring)
                    a_[:, :, y - ey, u - ex:v - ex] += out[i0 + i].reshape(a_.shape[0], C, v - u) * (k * wsub / e[3])
            del tr, sets, lb
        imgs: dict = {}
        for (kind, g, (y0, x0, y1, x1), _spp, _set, _key), a_ in zip(plan, acc):  # refine pasted over the frame
            for s_, gj in enumerate(g if kind == "union" else [g]):
                imgs.setdefault(gj, np.zeros((C, H, W)))[:, y0:y1, x0:x1] = a_[s_]
        if obj_moving and not ms.place_moving(params, scene, t_obj, mcache):
            raise RuntimeError("place_moving: a moving mesh changed size between the sub-windows and the frame time")
        static = {g: backend.clamp_roundoff(img[None].astype(np.float32), name=f"frame {f} {g} layer {name}")[0]
                  for g, img in imgs.items()}
        if static and R.static_denoised(scene, opts):
            from . import denoise  # noqa: PLC0415

            boxes = R.static_lamp_boxes(scene, opts, f, geo, window=(tm["t0"] + wins[0][0],
                                                                      tm["t0"] + wins[-1][0] + wins[-1][1]))
            static.update(denoise.denoise_static(static, boxes, split=R.static_split(scene, opts)))
        del params, loaded
        gc.collect()
        yield {"frame": f, "static": static}
    del pad


def write_layers(root, scene_id: str, scene: dict, meta: dict, opts, dtype, render=None) -> dict[str, str]:
    """Render the layers of ``opts.static_layers`` that scene ``scene_id`` under corpus ``root`` does not list yet
    (its :data:`lfmbench.corpus.window_layers.LAYERS_FILE`) and write them: each layer's files (atomically), then
    the layers file listing old and new. A file already written is not touched. ``meta``: the scene's meta.json
    content; ``dtype``: the corpus's storage; ``render``: the layer renderer (default :func:`render_layer`).
    Returns ``{relpath: sha256}`` of the files written (empty when nothing is missing)."""
    from lfmbench.corpus import window_layers as WL  # noqa: PLC0415

    from . import render as R  # noqa: PLC0415

    sdir = Path(root) / "scenes" / scene_id
    old = WL.read_layers_file(sdir / WL.LAYERS_FILE, float(meta["timing"]["capture_window_s"]))
    have = {x["name"]: x for x in old}
    for name, wins in opts.static_layers:
        if name in have and tuple(map(tuple, have[name]["windows_s"])) != tuple(wins):
            raise ValueError(f"{sdir / WL.LAYERS_FILE}: layer {name!r} is stored with other windows than "
                             "static_layers asks for (a new layer needs a new name)")
    rec = {"spp": opts.spp, "light_spp": opts.light_spp or opts.spp, "seed": opts.seed,
           "static_pass": opts.static_pass}
    hashes: dict[str, str] = {}
    for lay in (lay for lay in opts.static_layers if lay[0] not in have):
        hashes.update(WL.write_layer(root, scene_id, meta, lay[0], lay[1], R.scene_moves(scene),
                                     ((fr["frame"], fr["static"]) for fr in (render or render_layer)(scene, opts, lay)),
                                     dtype, rec))
    return hashes
