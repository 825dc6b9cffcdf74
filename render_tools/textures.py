"""Procedural albedo textures of scene generator 2 (scene version 2), generated at render time from a seed.

A material of a version-2 scene may carry ``texture``: ``{"kind", "seed", "size_m": [su, sv], ...}`` (plain data
in the scene file, a few numbers); :func:`texture_array` turns it into an (H, W, 3) linear-RGB albedo array in
[0, 0.95], row 0 at v = 0, which :mod:`render_tools.mitsuba_scene` hands to Mitsuba 3's ``bitmap`` texture as the
material's diffuse reflectance (spectral variants upsample each texel's RGB to a smooth reflectance spectrum,
Jakob and Hanika 2019, as they do the flat ``rgb`` of an untextured material). Nothing is shipped as an image: the
same descriptor always gives the same array (numpy ``default_rng(seed)``, fixed resolutions per kind).

Texture coordinates are a box projection in the object's frame at time 0 (:func:`box_uv`): a face whose normal is
mostly along z is mapped by (x, y), along y by (x, z), along x by (y, z); ``u = (a - origin_a) / su``,
``v = (b - origin_b) / sv``, wrapped (``repeat``). Textures therefore stay attached to moving objects.

Kinds (:data:`TEXTURES`; one registry entry each; ``rgb`` is the material's base colour):

- ``asphalt`` (road; u along the road, v across it, ``size_m`` [tile length, road width], ``lanes`` and
  ``lane_width_m``): aggregate (light stones and dark pores at 1-3 texels), low-frequency patches, darker polished
  tyre tracks 0.8 m either side of each lane's centre with an oil stain between them, thin branching cracks, a
  repaired patch.
- ``marking`` (lane paint): the paint worn through to the asphalt in patches, more along the wheel-swept edge.
- ``paving`` (sidewalks): slabs of ``slab_m`` with dark joints, each slab its own tint, fine grit.
- ``facade`` (buildings; ``size_m`` the facade's [width, height], ``origin_m`` its lower corner; ``bays``,
  ``floors``, ``window_m``, ``sill_z_m``, ``floor_m``: where the building's glass panes are): plaster/brick noise,
  a window frame around each pane, sills and floor ledges, rain streaks under the sills, a darker plinth, doors.
- ``paint`` (vehicles): a faint mottling of the clear coat and road dirt rising from the sills.
- ``bark`` (trunks): vertical furrows. ``foliage`` (crowns): clumps of lit and shaded leaves, some yellower.

Resolutions are fixed per kind (:data:`RESOLUTION`), so kernels compiled for one scene serve the next.
"""
from __future__ import annotations

import functools
import json
import math

import numpy as np

from lfmbench.registry import Registry

__all__ = ["TEXTURES", "RESOLUTION", "texture_array", "box_uv", "check_texture", "untextured"]

#: (rows = v, columns = u) texels of each kind.
RESOLUTION = {"asphalt": (512, 256), "marking": (32, 256), "paving": (256, 256), "facade": (256, 256),
              "paint": (64, 64), "bark": (64, 32), "foliage": (128, 128)}
#: Highest albedo a texel may take.
ALBEDO_MAX = 0.95

#: Texture kinds: ``name -> f(desc, rng, (H, W)) -> (H, W, 3)`` linear RGB albedo before clipping (``desc`` holds the
#: material's ``rgb`` as well as its ``texture``).
TEXTURES: Registry = Registry("texture")


@functools.lru_cache(maxsize=64)
def _lowpass(shape: tuple, cut_v: float, cut_u: float, power: float) -> np.ndarray:
    """The Fourier-domain filter (rows, cols // 2 + 1) of :func:`_noise` (``cut_v == cut_u``: isotropic,
    ``1 / (1 + (f / cutoff)^power)``) or :func:`_aniso_noise` (``power`` 0: ``1 / (1 + (fx/cut_u)^2 +
    (fy/cut_v)^2)``), made once per shape and cut-off (read-only: every texture of a kind shares it)."""
    if power:
        fy = np.fft.fftfreq(shape[0])[:, None]
        fx = np.fft.rfftfreq(shape[1])[None, :]
        f = np.sqrt(fx * fx + fy * fy)
        out = 1.0 + (f / cut_u) ** power
    else:
        fy = np.fft.fftfreq(shape[0])[:, None] / cut_v
        fx = np.fft.rfftfreq(shape[1])[None, :] / cut_u
        out = 1.0 + (fx * fx + fy * fy)
    out.setflags(write=False)
    return out


def _noise(rng: np.random.Generator, shape, cutoff: float, power: float = 2.0) -> np.ndarray:
    """Periodic (tileable) band-limited noise of ``shape`` (rows, cols), zero mean, unit standard deviation:
    white noise filtered in the Fourier domain by ``1 / (1 + (f / cutoff)^power)`` (f in cycles per texel), so
    the tile wraps seamlessly in both directions."""
    w = rng.standard_normal(shape)
    out = np.fft.irfft2(np.fft.rfft2(w) / _lowpass(tuple(shape), cutoff, cutoff, power), s=shape)
    return (out - out.mean()) / max(float(out.std()), 1e-12)


def _aniso_noise(rng: np.random.Generator, shape, cut_v: float, cut_u: float) -> np.ndarray:
    """Periodic noise, unit standard deviation, with different cut-offs along v (rows) and u (columns)."""
    w = rng.standard_normal(shape)
    out = np.fft.irfft2(np.fft.rfft2(w) / _lowpass(tuple(shape), cut_v, cut_u, 0.0), s=shape)
    return (out - out.mean()) / max(float(out.std()), 1e-12)


def _rgb(desc: dict) -> np.ndarray:
    return np.asarray(desc["rgb"], dtype=np.float64)


def _texel_m(n: int, size_m: float) -> np.ndarray:
    """(n,) positions (m) of the centres of ``n`` texels spanning ``size_m`` metres."""
    return (np.arange(n) + 0.5) / n * size_m


def _cracks(rng: np.random.Generator, shape, n: int, steps: int) -> np.ndarray:
    """A mask (rows, cols) in {0, 1} of ``n`` thin random-walk cracks (wrapping), each branching once: unit steps
    whose heading wanders by N(0, 0.12 rad) per step."""
    m = np.zeros(shape)
    H, W = shape
    for _ in range(2 * n):
        ang = rng.uniform(0, 2 * math.pi) + np.cumsum(rng.normal(0.0, 0.12, steps))
        r = rng.uniform(0, H) + np.cumsum(np.sin(ang))
        c = rng.uniform(0, W) + np.cumsum(np.cos(ang))
        m[r.astype(int) % H, c.astype(int) % W] = 1.0
    return m


@TEXTURES.register("asphalt")
def asphalt(desc: dict, rng: np.random.Generator, shape) -> np.ndarray:
    H, W = shape
    sv = desc["size_m"][1]
    base = _rgb(desc)
    patches = 0.15 * _noise(rng, shape, 0.01) + 0.08 * _noise(rng, shape, 0.04)
    stones = rng.random(shape)
    agg = np.where(stones > 0.93, 0.45, 0.0) + np.where(stones < 0.06, -0.35, 0.0) + 0.06 * _noise(rng, shape, 0.4)
    y = _texel_m(H, sv) - sv / 2  # metres across the road (v), 0 at the road's centre line
    track = np.zeros(H)
    lw = float(desc.get("lane_width_m", 3.5))
    for k in range(int(desc.get("lanes", 1))):
        for side in (1, -1):
            c = side * (k + 0.5) * lw
            for off in (-0.8, 0.8):
                track += 0.12 * np.exp(-0.5 * ((y - c - off) / 0.25) ** 2)  # polished, lighter
            track += -0.45 * np.exp(-0.5 * ((y - c) / 0.3) ** 2)  # oil stain between the tracks
    track = track[:, None] * (1.0 + 0.5 * _aniso_noise(rng, shape, 0.05, 0.004))
    cracks = _cracks(rng, shape, int(rng.integers(3, 8)), 220)
    cracks = np.maximum(cracks, np.roll(cracks, 1, axis=0))  # 2 texels wide (sealed with tar)
    patch = np.zeros(shape)
    if rng.random() < 0.7:  # a repaired patch (darker, fresher asphalt)
        r0, c0 = int(rng.integers(0, H)), int(rng.integers(0, W))
        ph, pw = int(rng.integers(H // 16, H // 6)), int(rng.integers(W // 8, W // 3))
        rows, cols = (np.arange(r0, r0 + ph) % H), (np.arange(c0, c0 + pw) % W)
        patch[np.ix_(rows, cols)] = -0.35
    f = np.exp(patches + agg + track + patch - 0.8 * cracks)
    return base[None, None, :] * f[..., None]


@TEXTURES.register("marking")
def marking(desc: dict, rng: np.random.Generator, shape) -> np.ndarray:
    base = _rgb(desc)
    under = np.asarray(desc.get("under_rgb", [0.08, 0.08, 0.08]))
    wear = _noise(rng, shape, 0.05) + 0.5 * _noise(rng, shape, 0.3)
    keep = 1.0 / (1.0 + np.exp(-3.0 * (wear + 0.5)))  # ~70 % of the paint left, worn in patches
    grit = 1.0 + 0.08 * _noise(rng, shape, 0.5)
    return (keep[..., None] * base + (1 - keep[..., None]) * under) * grit[..., None]


@TEXTURES.register("paving")
def paving(desc: dict, rng: np.random.Generator, shape) -> np.ndarray:
    H, W = shape
    su, sv = desc["size_m"]
    slab = float(desc.get("slab_m", 0.6))
    base = _rgb(desc)
    u = _texel_m(W, su)
    v = _texel_m(H, sv)
    iu, iv = np.floor(u / slab).astype(int), np.floor(v / slab).astype(int)
    tints = rng.normal(0.0, 0.1, (iv.max() + 1, iu.max() + 1))
    f = tints[iv[:, None], iu[None, :]] + 0.07 * _noise(rng, shape, 0.3) + 0.05 * _noise(rng, shape, 0.03)
    joint_w = 0.02
    ju = np.minimum(u % slab, slab - u % slab) < joint_w
    jv = np.minimum(v % slab, slab - v % slab) < joint_w
    f = f - 0.6 * (ju[None, :] | jv[:, None])
    return base[None, None, :] * np.exp(f)[..., None]


@TEXTURES.register("facade")
def facade(desc: dict, rng: np.random.Generator, shape) -> np.ndarray:
    # Every pattern but the noise and the bricks depends on the column (u) or the row (z) alone: computed on those
    # axes and broadcast (the same numbers, element for element, as on the (H, W) grid; far fewer operations).
    H, W = shape
    w_m, h_m = desc["size_m"]
    base = _rgb(desc)
    u = _texel_m(W, w_m)  # metres along the facade (columns)
    z = _texel_m(H, h_m)  # metres above ground (rows)
    U, Z = u[None, :], z[:, None]
    brick = rng.random() < 0.4
    f = 0.05 * _noise(rng, shape, 0.02) + 0.04 * _noise(rng, shape, 0.3)
    if brick:  # running bond, 0.25 x 0.075 m courses with mortar joints
        course = np.floor(Z / 0.075)
        uu = U + 0.125 * (course % 2)
        mortar = (Z % 0.075 < 0.012) | (uu % 0.25 < 0.012)
        f = f + rng.normal(0, 0.08) + 0.08 * np.sin(course * 12.9898 + np.floor(uu / 0.25) * 78.233) - 0.25 * mortar
    col = base[None, None, :] * np.exp(f)[..., None]
    frame = np.asarray([0.75, 0.74, 0.7]) if rng.random() < 0.6 else np.asarray([0.08, 0.08, 0.09])
    ledge = np.clip(base * 1.4 + 0.1, 0, ALBEDO_MAX)
    bays, floors = int(desc["bays"]), int(desc["floors"])
    ww, wh = desc["window_m"]
    z0, fh = float(desc["sill_z_m"]), float(desc["floor_m"])
    bay = w_m / bays
    du = np.abs(U - (np.clip(np.floor(U / bay), 0, bays - 1) + 0.5) * bay)  # (1, W) from the nearest pane's centre, m
    fl = np.clip(np.floor((Z - z0 + 1.2) / fh), 0, floors - 1)
    dz = Z - (z0 + fl * fh)  # (H, 1) above the nearest sill below (or 1.2 m under it), m
    col[(du < ww / 2 + 0.08) & (dz > -0.08) & (dz < wh + 0.08)] = frame
    col[(du < ww / 2 + 0.12) & (dz > -0.14) & (dz < -0.06)] = ledge
    ridges = 0.5 + 0.5 * np.sin(U * rng.uniform(20, 40) + rng.uniform(0, 6))
    streak = (du < ww / 2) & (dz < -0.14) & (dz > -1.2)
    streak = streak * np.clip(1.0 - (-0.14 - dz) / 1.1, 0, 1) * ridges
    dl = Z - (z0 + wh + 0.55) - np.clip(np.floor((Z - z0 - wh - 0.55) / fh), 0, floors - 1) * fh
    col[((dl > 0) & (dl < 0.12) & (Z < z0 + floors * fh))[:, 0]] = ledge  # a floor ledge between the storeys
    col *= np.exp(-0.25 * streak)[..., None]
    plinth = (Z < 0.45)[:, 0]
    col[plinth] = col[plinth] * 0.6
    door = np.asarray([0.18, 0.1, 0.06]) if rng.random() < 0.5 else np.asarray([0.06, 0.07, 0.08])
    gap = bay - ww
    grain = 1.0 + 0.1 * _noise(rng, shape, 0.2)
    for k in rng.permutation(bays)[:max(1, bays // 3)]:
        cu = k * bay if (gap > 1.3 and k > 0) else (k + 0.5) * bay
        d = (np.abs(U - cu) < 0.5) & (Z < 2.2)
        col[(np.abs(U - cu) < 0.58) & (Z < 2.28)] = frame
        col[d] = door * grain[d][:, None]
    return col


@TEXTURES.register("paint")
def paint(desc: dict, rng: np.random.Generator, shape) -> np.ndarray:
    H, _ = shape
    sv = desc["size_m"][1]
    base = _rgb(desc)
    z = _texel_m(H, sv)
    dirt = np.clip(1.0 - z / 0.6, 0, 1)[:, None] * (0.6 + 0.4 * _noise(rng, shape, 0.2))
    mottle = 0.04 * _noise(rng, shape, 0.05)
    grime = np.asarray([0.12, 0.1, 0.08])
    t = np.clip(0.5 * dirt, 0, 1)[..., None]
    return (base * np.exp(mottle)[..., None]) * (1 - t) + grime * t


@TEXTURES.register("bark")
def bark(desc: dict, rng: np.random.Generator, shape) -> np.ndarray:
    base = _rgb(desc)
    furrows = _aniso_noise(rng, shape, 0.03, 0.25)
    f = 0.35 * np.tanh(1.5 * furrows) + 0.1 * _noise(rng, shape, 0.4)
    return base[None, None, :] * np.exp(f)[..., None]


@TEXTURES.register("foliage")
def foliage(desc: dict, rng: np.random.Generator, shape) -> np.ndarray:
    base = _rgb(desc)
    clumps = _noise(rng, shape, 0.06)
    leaves = _noise(rng, shape, 0.5)
    f = 0.35 * clumps + 0.25 * leaves
    yellow = np.clip(0.5 * _noise(rng, shape, 0.03), 0, 1)[..., None] * np.asarray([0.6, 0.3, -0.3])
    return base[None, None, :] * np.exp(f)[..., None] * (1.0 + yellow)


def untextured(scene: dict) -> dict:
    """A deep copy of ``scene`` whose materials carry no ``texture`` (flat colours: the comparison case of the
    texture studies in benchmarks/studies/)."""
    import copy  # noqa: PLC0415

    flat = copy.deepcopy(scene)
    for m in flat.get("materials", {}).values():
        m.pop("texture", None)
    return flat


def check_texture(tex, path: str) -> None:
    """Validate a material's ``texture`` entry; raises ``ValueError("<path>.<field>: ...")``."""
    if not isinstance(tex, dict):
        raise ValueError(f"{path}: expected an object")
    if tex.get("kind") not in TEXTURES:
        raise ValueError(f"{path}.kind: {tex.get('kind')!r} not one of {', '.join(TEXTURES.names())}")
    if not isinstance(tex.get("seed"), int) or isinstance(tex.get("seed"), bool) or not 0 <= tex["seed"] < 2 ** 63:
        raise ValueError(f"{path}.seed: expected an integer in [0, 2^63)")
    s = tex.get("size_m")
    if not (isinstance(s, list) and len(s) == 2 and all(isinstance(x, (int, float)) and 0.01 <= x <= 1000 for x in s)):
        raise ValueError(f"{path}.size_m: expected [u, v] in metres, each in [0.01, 1000]")
    o = tex.get("origin_m", [0.0, 0.0, 0.0])
    if not (isinstance(o, list) and len(o) == 3 and all(isinstance(x, (int, float)) and abs(x) < 1e5 for x in o)):
        raise ValueError(f"{path}.origin_m: expected [x, y, z] in metres")
    if tex["kind"] == "facade":
        for k in ("bays", "floors"):
            if not isinstance(tex.get(k), int) or not 1 <= tex[k] <= 64:
                raise ValueError(f"{path}.{k}: expected an integer in [1, 64]")
        for k in ("sill_z_m", "floor_m"):
            if not isinstance(tex.get(k), (int, float)) or not 0 < tex[k] < 100:
                raise ValueError(f"{path}.{k}: expected metres in (0, 100)")
        wm = tex.get("window_m")
        if not (isinstance(wm, list) and len(wm) == 2 and all(isinstance(x, (int, float)) and 0 < x < 100 for x in wm)):
            raise ValueError(f"{path}.window_m: expected [width, height] in metres")


def texture_array(desc: dict, rgb) -> np.ndarray:
    """The albedo texture of ``desc`` (a material's ``texture``) over base colour ``rgb`` (3,) in [0, 1]:
    (H, W, 3) float32 linear RGB in [0, :data:`ALBEDO_MAX`], row 0 at v = 0, H x W = :data:`RESOLUTION` of its
    kind. Deterministic in ``desc`` (its ``seed``) and ``rgb``. The last :data:`CACHED` arrays are kept in the
    process by their descriptor and colour (a scene rendered again in one process, e.g. frame by frame or by the
    texture studies, makes its textures once); the array returned is a copy, the caller's."""
    return _texture_cached(json.dumps(desc, sort_keys=True), tuple(float(c) for c in rgb)).copy()


#: Textures kept in a process by :func:`texture_array` (float32: 0.8 MB a 256 x 256 facade, 1.6 MB an asphalt tile;
#: a wet night's 46 textures about 25 MB).
CACHED = 64


@functools.lru_cache(maxsize=CACHED)
def _texture_cached(desc_json: str, rgb: tuple) -> np.ndarray:
    desc = json.loads(desc_json)
    kind = desc["kind"]
    rng = np.random.default_rng([int(desc["seed"]), sorted(TEXTURES.names()).index(kind)])
    arr = TEXTURES.get(kind)(dict(desc, rgb=list(rgb)), rng, RESOLUTION[kind])
    out = np.clip(arr, 0.0, ALBEDO_MAX).astype(np.float32)
    out.setflags(write=False)
    return out


def box_uv(V: np.ndarray, F: np.ndarray, desc: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unwelded vertices (3m, 3), faces (m, 3) and box-projected texture coordinates (3m, 2) of mesh (V (n, 3) m,
    F (m, 3)) for texture ``desc``: each face mapped by the two world axes most nearly in its plane, minus
    ``origin_m``, divided by ``size_m`` (module docstring)."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F)
    P = V[F]  # (m, 3, 3)
    n = np.abs(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]))
    axis = np.argmax(n, axis=1)  # 0: x-facing -> (y, z); 1: y-facing -> (x, z); 2: z-facing -> (x, y)
    ua = np.where(axis == 0, 1, 0)
    va = np.where(axis == 2, 1, 2)
    o = np.asarray(desc.get("origin_m", [0.0, 0.0, 0.0]), dtype=np.float64)
    su, sv = (float(x) for x in desc["size_m"])
    Pf = P.reshape(-1, 3)
    rows = np.arange(len(Pf))
    uvu = (Pf[rows, np.repeat(ua, 3)] - o[np.repeat(ua, 3)]) / su
    uvv = (Pf[rows, np.repeat(va, 3)] - o[np.repeat(va, 3)]) / sv
    return Pf, np.arange(len(Pf)).reshape(-1, 3), np.stack([uvu, uvv], axis=1)
