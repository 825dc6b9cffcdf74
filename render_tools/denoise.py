"""Denoising of the static groups' full frames (scene version 2, :class:`render_tools.render.RenderOptions`
``static_denoise``).

Why: the static groups' full frames are traced at ``spp`` 1 per band pass (8 camera samples a pixel at the
``default`` profile); their Monte Carlo noise left a median per-pixel luminance error of the static light of 25 %
(day), 12 % (dry night) and 33 % (wet night) against spp-64/256 renders of 640x360 generator-2 frames, over the
10 % issue 23 asks for of the whole frame, and changing from frame to frame; more samples cost what the profile
cannot pay (spp 4: 1.8-2x the frame, still 18-20 % by day and on a wet night; docs/benchmarks/render.md). The
flickering layers (the lamps' crops at ``light_spp``: every LED pixel) are not touched.

What (one capture window of one frame; ``S[g, c]``: group g's spectral radiance in band c, (H, W)):

1. The lamps of the static groups (refined in their boxes at ``light_spp``, 10^3-10^5 times brighter than what is
   next to them) are *kept out*: inside their boxes the denoiser's input holds the mean of the ring around the box,
   and the output keeps the traced values there. (Fed as they are, the denoiser spread them over their neighbours:
   the LED pixels' error went from 1.6 % to 36 % on a night scene.)
2. The C bands are summed over the groups and into :data:`BROAD_BANDS` contiguous broad bands (thirds of the band
   list: 400-500, 500-600, 600-700 nm for the 31 default bands), each of which sums samples of every band pass;
   this 3-channel image is denoised by Intel Open Image Denoise's ``RT`` filter for HDR colour (A. T. Afra,
   "Intel Open Image Denoise", 2024, https://www.openimagedenoise.org; the ``pyoidn`` binding,
   https://github.com/Hyiker/pyoidn), on the CPU, without auxiliary images.
3. Each broad band's denoised value is split among the groups by their shares in a (2 r + 1)^2 px box around the
   pixel (r = :data:`SHARE_RADIUS_PX`) and within a group among its bands by their shares in a box of radius
   :data:`SHAPE_RADIUS_PX` (lamp boxes left out of both): for c in broad band k,
   ``S'[g, c] = B'[k] * box_r(S[g, k]) / box_r(B[k]) * box_R(S[g, c]) / box_R(S[g, k])``. The shares sum to 1,
   so the groups and bands of a pixel add up to the denoised broad band; within the boxes the split between
   groups and the spectral shape inside a broad band are averaged (an edge between differently coloured
   surfaces, or between what two groups light, is blurred over r or R px in those ratios only).
   With ``split="oidn"`` (:data:`SPLITS`; ``RenderOptions.static_split``) the groups' shares come from denoised
   images instead: each group's light summed over all its bands, ``T[g]``, in :data:`SPLIT_BLOCK_PX` px blocks,
   up to three groups per call of the same filter (as colour channels), bilinear back (``T'[g]``); the group's
   colour, its broad band's part of its light ``col[g, k] = box_R(S[g, k]) / box_R(T[g])``, from the box of the
   spectral shape; ``S'[g, c] = B'[k] * T'[g] col[g, k] / sum_h T'[h] col[h, k] * box_R(S[g, c]) / box_R(S[g,
   k])``. Why: on a wet road the static lamps' glossy reflections are sparse bright samples at spp 1; one of
   them in a 5 x 5 px box took that broad band's share for its group there, so the spectral shape inside the broad
   band flipped from one group's (HPS streetlights: most light at 589 nm) to the other's (white headlights) box by
   box: 4-6 px magenta and green squares in the denoised reflection streaks (docs/benchmarks/gallery.md). Denoised
   shares are smooth, and each group's colour is its own over R px; the broad bands (so luminance and colour at
   their resolution) are the same filter output as with ``box``. Cost: one call of the filter on a quarter of
   the pixels per three groups (measured in docs/benchmarks/gallery.md).

Not unbiased: the filter's output is its own estimate; edges and texture finer than the noise are smoothed, and
light it takes for outliers is removed. Measured on 640x360 frames of the ``default`` profile against spp-64/256
references (docs/benchmarks/render.md): the light outside the lamp boxes is kept within 1.7 % on a dry night and by
day, but a wet road's glossy reflections of the static lamps are sparse bright samples at spp 1, and the filter
blurs them: their brightest tenth loses about a quarter of its light, the rest of the road gains 7 %, the frame's
light outside the lamp boxes -15 % (short window; long -8 %). Smaller frames lose more (the same scenes, short
window, all static groups' light outside the lamp boxes: 320x180 at spp 1 dry night -3.6 %, wet -18 %, day -0.2 %;
160x90 at spp 2, the mini protocols' size, -4.1 / -18 / -0.5 %). These wet figures are with
``glossy_light_choice: plain``; with ``lobe`` (the default on scene version 2,
:class:`render_tools.render.RenderOptions`) the reflections are no longer sparse samples and a 320x180 wet night's
denoised static light is 0.986 of a spp-32 reference (plain: 0.558). Scaling the output back to the traced light
(over the frame, or in boxes of 8-64 px) was tried and not taken: over the frame it brightened everything else by 12 %
(median error 9.4 -> 16.4 %), in boxes it left square blotches where a single bright sample sat. ``static_denoise:
off`` keeps the traced (unbiased) estimate.
"""
from __future__ import annotations

import sys

import numpy as np

#: Channels the denoiser sees: the band list cut into this many contiguous broad bands (Open Image Denoise
#: filters 3-channel colour).
BROAD_BANDS = 3
#: Radius (px) of the box over which a broad band's split among the groups is measured (step 3 above).
SHARE_RADIUS_PX = 2
#: Radius (px) of the box over which the split of a group's broad band among its bands (the spectral shape) is
#: measured: at 2 px the sparse samples of a wet road's reflections left colour blotches (hue of 5 x 5 px squares);
#: at 16 px none were seen, and the median error was the same (docs/benchmarks/render.md).
SHAPE_RADIUS_PX = 16
#: Ways of splitting a denoised broad band among the static groups (``denoise_static`` ``split``; module docstring
#: step 3): by the groups' shares in a box of :data:`SHARE_RADIUS_PX`, or by their denoised light.
SPLITS = ("box", "oidn")
#: Side (px) of the blocks the groups' light is denoised on for ``split="oidn"`` (a quarter of the pixels at 2).
SPLIT_BLOCK_PX = 2
#: Side (px) of the blocks on which the spectral shape's box means are taken (they vary over SHAPE_RADIUS_PX, so a
#: block grid 4 px apart holds them; interpolated back bilinearly): 16x fewer pixels for the C bands' box means.
SHAPE_BLOCK_PX = 4
#: Width (px) of the ring around a lamp box whose mean stands in for the box in the denoiser's input.
FILL_RING_PX = 2
#: Open Image Denoise's quality setting: ``fast`` (its smaller network). Measured on 640x360 frames of the
#: ``default`` profile (docs/benchmarks/render.md): against ``high`` +0.1 to +0.5 points of median error (day 4.0 ->
#: 4.1 %, dry night 2.6 -> 3.1 %, wet night 9.1 -> 9.5 %) for 0.8-0.9 instead of 1.2-1.3 CPU s per frame (two
#: windows, 2 cores), which the v2 render cost (at most 1.5x v1's, issue 23) needs.
QUALITY = "fast"
#: Side (px) Open Image Denoise rounds an image's height and width up to, filling the added rows and columns at the
#: bottom and right with zeros (its input stage: the U-Net's pooling levels need it; OIDN 2.x ``InputProcess``,
#: https://github.com/RenderKit/oidn). A noisy image was darkened at those edges: the mean of a flat field of
#: exponential noise through the filter, bottom row against the interior, 0.85 at 45 x 32 px and 0.92 at 90 x 160
#: (a wet 160 x 90 night's composed last row 0.85 of a reference; docs/benchmarks/rendering-measurements.md,
#: "Denoiser at the image edge").
OIDN_ALIGN_PX = 16
#: Width (px) of the mirrored margin the filter sees beyond every edge of an image where the image ends
#: (:func:`_mirror_pad`; a crop's sides inside the image get none, :func:`crop_edges`): its convolutions pad with
#: zeros too (a flat field's first and last columns 0.94-0.97 of the interior). Measured on
#: flat fields of exponential and of sparse (1 in 10, x10) noise, 60 draws each, edge rows and columns against the
#: interior: 0.72-1.21 with no margin, 1.01-1.16 at 8 px, 0.99-1.09 at 16 px, 0.98-1.02 at 32 px.
OIDN_MARGIN_PX = 32


def broad_bands(n_bands: int, n: int = BROAD_BANDS) -> list[slice]:
    """``n`` contiguous slices covering ``range(n_bands)`` as evenly as rounding allows (thirds by default)."""
    if n_bands < 1:
        raise ValueError(f"n_bands: must be >= 1, got {n_bands}")
    e = np.linspace(0, n_bands, min(n, n_bands) + 1).round().astype(int)
    return [slice(int(a), int(b)) for a, b in zip(e[:-1], e[1:])]


def _window_sums(x: np.ndarray, r: int, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Sums of ``x`` (float64) over the windows [i - r, i + r] along ``axis`` clipped to the array, and the number
    of elements each window holds, shaped to broadcast against ``x``. From a cumulative sum: for inputs >= 0 the
    cumulative sum never decreases, so a window of zeros sums to exactly 0 and no sum is negative."""
    n = x.shape[axis]
    c = np.cumsum(x, axis=axis, dtype=np.float64)
    c = np.concatenate([np.zeros_like(np.take(c, [0], axis=axis)), c], axis=axis)
    i = np.arange(n)
    hi, lo = np.minimum(i + r + 1, n), np.maximum(i - r, 0)
    count = (hi - lo).astype(np.float64)
    shape = [1] * x.ndim
    shape[axis] = n
    return np.take(c, hi, axis=axis) - np.take(c, lo, axis=axis), count.reshape(shape)


def _box_mean(x: np.ndarray, r: int) -> np.ndarray:
    """(N, H, W) -> (N, H, W) float32: the mean over the (2r+1)^2 px box of each pixel, over the pixels of the box
    inside the image (only ratios of two such means are used, and both see the same pixels); the same as
    ``torch.nn.functional.avg_pool2d(x, 2r+1, 1, r, count_include_pad=False)`` (tested), summed in float64 along
    rows, then columns."""
    rows, n_r = _window_sums(np.asarray(x, np.float32), r, 2)
    both, n_c = _window_sums(rows, r, 1)
    return (both / (n_r * n_c)).astype(np.float32)


def _block_sums(x: np.ndarray, f: int) -> np.ndarray:
    """(N, h f, w f) -> (N, h, w) float64: sums over f x f px blocks, the same numbers as
    ``x.astype(np.float64).reshape(N, h, f, w, f).sum(axis=(2, 4))`` (each block row summed in order, then the
    rows in order, from +0: numpy's order for blocks under 8 px, tested bit for bit), without the float64 copy of
    ``x`` and numpy's strided two-axis reduction (a quarter of the static denoising's CPU time on a wet
    generator-2 night at 640x360). Blocks of 8 px or more: numpy's sum itself (its pairwise order)."""
    N, Hf, Wf = x.shape
    h, w = Hf // f, Wf // f
    if f >= 8:
        return np.asarray(x, np.float64).reshape(N, h, f, w, f).sum(axis=(2, 4))
    y = x.reshape(N, h, f, w, f)
    out = np.zeros((N, h, w), np.float64)
    for a in range(f):
        row = y[:, :, a, :, 0].astype(np.float64)
        for b in range(1, f):
            row += y[:, :, a, :, b]
        out += row
    return out


def _block_mean(x: np.ndarray, f: int) -> np.ndarray:
    """(N, H, W) -> (N, ceil(H / f), ceil(W / f)) float32: means over f x f px blocks (a block cut by the image's
    edge: over its pixels inside)."""
    x = np.asarray(x, np.float32)
    N, H, W = x.shape
    h, w = -(-H // f), -(-W // f)
    if H == h * f and W == w * f:  # whole blocks: no padding, every block holds f * f pixels (the same sums)
        sums = _block_sums(x, f)
        sums /= float(f * f)
        return sums.astype(np.float32)
    pad = np.zeros((N, h * f, w * f), np.float64)
    pad[:, :H, :W] = x
    cnt = np.zeros((h * f, w * f), np.float64)
    cnt[:H, :W] = 1.0
    sums = _block_sums(pad, f)
    return (sums / cnt.reshape(h, f, w, f).sum(axis=(1, 3))).astype(np.float32)


def _upsample(x: np.ndarray, f: int, shape: tuple) -> np.ndarray:
    """(N, h, w) block values -> (N, H, W) float32: bilinear between the blocks' centres (edges held), cut to
    ``shape`` (H, W); ``torch.nn.functional.interpolate(x, scale_factor=f, mode="bilinear",
    align_corners=False)``'s sampling (an output pixel i reads source position (i + 0.5) / f - 0.5, clamped at 0)."""
    x = np.asarray(x, np.float32)

    def taps(n_out: int, n_in: int):
        src = np.maximum((np.arange(n_out) + 0.5) / f - 0.5, 0.0)
        i0 = np.minimum(np.floor(src).astype(int), n_in - 1)
        i1 = np.minimum(i0 + 1, n_in - 1)
        return i0, i1, (src - i0).astype(np.float32)

    y0, y1, ly = taps(shape[0], x.shape[1])
    x0, x1, lx = taps(shape[1], x.shape[2])
    # the same float32 products and sums as ``x[:, y0, :] * (1 - ly)[None, :, None] + x[:, y1, :] * ly[None, :,
    # None]`` and ``rows[:, :, x0] * (1 - lx) + rows[:, :, x1] * lx``, gathered with ``take`` and computed in
    # place (about a third less CPU on (31, 360, 640) px: fewer full-size temporaries)
    rows = np.take(x, y0, axis=1)
    rows *= (1 - ly)[None, :, None]
    below = np.take(x, y1, axis=1)
    below *= ly[None, :, None]
    rows += below
    out = np.take(rows, x0, axis=2)
    out *= 1 - lx
    far = np.take(rows, x1, axis=2)
    far *= lx
    out += far
    return out


def keep_mask(shape: tuple, boxes) -> np.ndarray:
    """(H, W) bool: False inside any of ``boxes`` ((y0, x0, y1, x1) px, end exclusive, clipped to the image)."""
    keep = np.ones(shape, bool)
    for y0, x0, y1, x1 in boxes:
        keep[max(y0, 0):max(y1, 0), max(x0, 0):max(x1, 0)] = False
    return keep


def _fill_boxes(b: np.ndarray, keep: np.ndarray, boxes) -> np.ndarray:
    """Broad bands (k, H, W) with each lamp box replaced by the mean of the kept pixels of the
    :data:`FILL_RING_PX` ring around it (0 where the ring holds none)."""
    out = b.copy()
    H, W = keep.shape
    for y0, x0, y1, x1 in boxes:
        ya, xa, yb, xb = max(y0, 0), max(x0, 0), min(y1, H), min(x1, W)
        if ya >= yb or xa >= xb:
            continue
        ra, rb = max(ya - FILL_RING_PX, 0), min(yb + FILL_RING_PX, H)
        ca, cb = max(xa - FILL_RING_PX, 0), min(xb + FILL_RING_PX, W)
        ring = keep[ra:rb, ca:cb]
        vals = b[:, ra:rb, ca:cb][:, ring]
        out[:, ya:yb, xa:xb] = (vals.mean(axis=1) if vals.size else np.zeros(len(b)))[:, None, None]
    return out


def _import_pyoidn():
    """The ``pyoidn`` module, imported without torch where torch is not loaded yet: its import tries ``import torch``
    only to accept tensors as well (seconds of CPU in every render process), and numpy arrays are all this module
    passes it. In a process that has torch already, a plain import."""
    if "pyoidn" in sys.modules or "torch" in sys.modules:
        import pyoidn  # noqa: PLC0415

        return pyoidn
    sys.modules["torch"] = None  # makes pyoidn's ``import torch`` raise ImportError: its numpy-only mode
    try:
        import pyoidn  # noqa: PLC0415
    finally:
        del sys.modules["torch"]
    return pyoidn


def crop_edges(box, shape) -> tuple[bool, bool, bool, bool]:
    """Which sides (top, bottom, left, right) of the crop ``box`` (y0, x0, y1, x1) px, end exclusive, of an image
    of ``shape`` (H, W) px meet the image's own edge (y0 <= 0, y1 >= H, x0 <= 0, x1 >= W)."""
    y0, x0, y1, x1 = (int(v) for v in box)
    H, W = (int(v) for v in shape)
    return y0 <= 0, y1 >= H, x0 <= 0, x1 >= W


def edge_margins(edges=(True, True, True, True), margin: int | None = None) -> tuple[int, int, int, int]:
    """(top, bottom, left, right) px of mirrored margin for an image whose sides ``edges`` (top, bottom, left,
    right; :func:`crop_edges`) are the image's own edge: ``margin`` (default :data:`OIDN_MARGIN_PX`) there, 0 on a
    crop's sides inside the image."""
    m = OIDN_MARGIN_PX if margin is None else int(margin)
    if len(edges) != 4:
        raise ValueError(f"edges: (top, bottom, left, right) expected, got {edges!r}")
    return tuple(m if bool(e) else 0 for e in edges)


def _sides(margin) -> tuple[int, int, int, int]:
    """``margin`` as (top, bottom, left, right) px >= 0: None (:data:`OIDN_MARGIN_PX` on every side), one int for
    every side, or four ints."""
    if margin is None:
        margin = OIDN_MARGIN_PX
    if np.ndim(margin) == 0:
        margin = (int(margin),) * 4
    t = tuple(int(v) for v in margin)
    if len(t) != 4 or min(t) < 0:
        raise ValueError(f"margin: an int or (top, bottom, left, right) px >= 0 expected, got {margin!r}")
    return t


def _mirror_pad(img: np.ndarray, margin=None, align: int | None = None) -> np.ndarray:
    """(C, H, W) -> (C, H + t + b + a, W + l + r + c): the image mirrored beyond its edges by ``margin`` px (one int
    for every side or (top, bottom, left, right) = (t, b, l, r); default :data:`OIDN_MARGIN_PX` on every side), its
    edge pixels repeated (numpy's ``symmetric`` mode: any size, a margin larger than the image mirrors it again),
    and a, c < ``align`` (default :data:`OIDN_ALIGN_PX`) more mirrored rows and columns at the bottom and right so
    that both sides are multiples of ``align`` (mirrored there even where the margin is 0: never zeros). The
    image's own pixels are ``[:, t:t + H, l:l + W]`` of the result."""
    t, b, l_, r = _sides(margin)
    f = OIDN_ALIGN_PX if align is None else int(align)
    _, H, W = img.shape
    return np.pad(img, ((0, 0), (t, b + (-(H + t + b)) % f), (l_, r + (-(W + l_ + r)) % f)), mode="symmetric")


def oidn_rgb(img: np.ndarray, margin=None) -> np.ndarray:
    """Open Image Denoise's ``RT`` filter on an HDR image (3, H, W) >= 0 (any linear unit) -> (3, H, W) float32
    >= 0. The image is divided by its mean level (channels summed) before and multiplied after: the filter's own
    exposure estimate ignores values under about 1e-8 and returned noise of that absolute size for darker images
    (a night sky's radiance is ~1e-6 W sr^-1 m^-2 nm^-1); an all-black image is returned black. The filter sees the
    image mirrored ``margin`` px beyond its edges (None: :data:`OIDN_MARGIN_PX` on every side, for a whole image; one
    int, or (top, bottom, left, right) px: :func:`edge_margins`, for a crop whose sides inside a larger image get
    none) and grown to a multiple of :data:`OIDN_ALIGN_PX` with mirrored rows and columns (:func:`_mirror_pad`),
    and the image's own pixels are cut back out. Raises ``RuntimeError`` when the ``pyoidn``
    package is not installed."""
    try:
        pyoidn = _import_pyoidn()
    except ImportError as e:  # pragma: no cover - pyoidn is a dependency
        raise RuntimeError("static_denoise: 'oidn' needs the pyoidn package (Intel Open Image Denoise): "
                           "pip install pyoidn, or render with static_denoise: off") from e
    t, b, l_, r = _sides(margin)
    img = np.asarray(img, np.float32)
    level = float(img.sum(0).mean())  # the filter's exposure estimate ignores values under ~1e-8: scale to ~1
    if not (level > 0 and np.isfinite(level)):
        return np.zeros_like(img) if level == 0 else img.copy()
    H, W = img.shape[1:]
    x = np.ascontiguousarray(np.moveaxis(_mirror_pad(img * np.float32(1.0 / level), (t, b, l_, r)), 0, -1))
    y = pyoidn.denoise(x, hdr=True, quality=QUALITY)
    y = np.moveaxis(np.asarray(y, np.float32), -1, 0)[:, t:t + H, l_:l_ + W]
    return np.maximum(y, 0.0) * np.float32(level)


def _denoised_group_light(tot: np.ndarray, keep: np.ndarray, boxes, denoiser) -> np.ndarray:
    """The groups' light ``tot`` (G, H, W) >= 0 (lamp boxes zeroed) denoised for ``split="oidn"``: boxes filled
    from their rings, :data:`SPLIT_BLOCK_PX` px block means, each group divided by its mean (the filter treats its
    channels as colour: the night sky's light, 1e-3 of the streetlights', came out +23 % unscaled, dry night
    320x180), ``denoiser`` on three groups at a time (zero channels pad the last call), multiplied back, bilinear
    back to (G, H, W) float32 >= 0."""
    G, H, W = tot.shape
    f = SPLIT_BLOCK_PX
    lo = _block_mean(_fill_boxes(tot, keep, boxes), f)
    out = np.empty_like(lo)
    level = lo.mean(axis=(1, 2), dtype=np.float64)  # each group scaled to a mean of 1: a faint group (the night
    level = np.where(level > 0, level, 1.0).astype(np.float32)[:, None, None]  # sky) is not a bright one's residue
    lo = lo / level
    for i in range(0, G, 3):
        chunk = np.zeros((3,) + lo.shape[1:], np.float32)
        n = min(3, G - i)
        chunk[:n] = lo[i:i + n]
        out[i:i + n] = np.maximum(np.asarray(denoiser(chunk), np.float32)[:n], 0.0)
    out *= level
    return _upsample(out, f, (H, W))


def denoise_static(images: dict, boxes=(), radius: int = SHARE_RADIUS_PX, shape_radius: int | None = None,
                   denoiser=oidn_rgb, split: str = "box") -> dict:
    """Denoise the static groups' images of one window (module docstring).

    Args:
        images: group -> (C, H, W) float32 spectral radiance (W sr^-1 m^-2 nm^-1) >= 0, the same shape for all.
        boxes: lamp boxes (y0, x0, y1, x1) px, end exclusive: left out of the denoiser and kept as they are.
        radius: px, the box radius of the groups' shares (:data:`SHARE_RADIUS_PX`).
        shape_radius: px, the box radius of the spectral shape inside a broad band (None: :data:`SHAPE_RADIUS_PX`).
        denoiser: (k, H, W) -> (k, H, W), k = :data:`BROAD_BANDS` (:func:`oidn_rgb`; tests pass others).
        split: how a broad band is split among the groups (:data:`SPLITS`, module docstring): ``"box"`` (their
            shares in a box of ``radius``) or ``"oidn"`` (their light denoised, ``radius`` unused).

    Returns:
        group -> (C, H, W) float32: per pixel and broad band, the groups' bands sum to the denoised broad band
        outside the boxes; inside them the input values.
    """
    shape_radius = SHAPE_RADIUS_PX if shape_radius is None else shape_radius
    if split not in SPLITS:
        raise ValueError(f"split: must be one of {SPLITS}, got {split!r}")
    groups = list(images)
    if not groups:
        return {}
    first = np.asarray(images[groups[0]])
    C, H, W = first.shape
    G = len(groups)
    keep = keep_mask((H, W), boxes)
    parts = broad_bands(C)
    B = np.zeros((max(len(parts), BROAD_BANDS), H, W), np.float32)  # zero channels pad fewer than 3 bands
    per_group = []  # each group's broad bands (k, H, W)
    for g in groups:
        x = np.asarray(images[g], np.float32)
        if x.shape != first.shape:
            raise ValueError(f"images[{g!r}]: shape {x.shape}, expected {first.shape} as {groups[0]!r}")
        per_group.append(np.stack([x[p].sum(0) for p in parts]))
        B[:len(parts)] += per_group[-1]
    k = len(parts)
    filled = _fill_boxes(B, keep, boxes)
    Bd = np.asarray(denoiser(filled), np.float32)[:k]
    kf = keep.astype(np.float32)
    even = Bd / G  # no kept light near: B' split evenly among the groups (B' is ~0 there)
    f = SHAPE_BLOCK_PX
    rb = max(1, round(shape_radius / f))
    by_box = split == "box" or G == 1
    if by_box:
        den = _box_mean(B[:k] * kf, radius)  # (k, H, W): box means of the broad bands, all groups
    else:  # the groups' denoised light T'[g] times their colour col[g, k], normalised over the groups
        light = _denoised_group_light(np.stack([(xk * kf).sum(0) for xk in per_group]), keep, boxes, denoiser)
        est, kbox = [], []
        for xk, t in zip(per_group, light):
            klo = _box_mean(_block_mean(xk * kf, f), rb)  # box_R(S[g, k]) on the blocks
            kbox.append(klo)
            tlo = klo.sum(0)
            col = np.where(tlo > 0, klo / np.where(tlo > 0, tlo, 1.0), 1.0 / k)
            est.append(_upsample(col, f, (H, W)) * t[None])  # (k, H, W): T'[g] col[g, k]
        den = np.sum(est, axis=0)
    ok = den > 0
    scale = np.where(ok, Bd / np.where(ok, den, 1.0), 0.0)  # B'[k] / den: box_r(B[k]), or sum_g T'[g] col[g, k]
    out = {}
    for i, (g, xk) in enumerate(zip(groups, per_group)):
        x = np.asarray(images[g], np.float32)
        xk = xk * kf
        # (k, H, W): the group's part of B'[k]
        share = np.where(ok, (_box_mean(xk, radius) if by_box else est[i]) * scale, even)
        # band c's share of the group's broad band, box_R(S[g, c]) / box_R(S[g, k]): smooth over R px, so
        # measured on f x f px blocks (box radius R / f) and interpolated back
        lo = _box_mean(_block_mean(x * kf, f), rb)
        klo = _box_mean(_block_mean(xk, f), rb) if by_box else kbox[i]
        shape_lo = np.empty_like(lo)
        for j, p in enumerate(parts):
            d = klo[j]
            shape_lo[p] = np.where(d > 0, lo[p] / np.where(d > 0, d, 1.0), 1.0 / (p.stop - p.start))
        y = _upsample(shape_lo, f, (H, W))
        for j, p in enumerate(parts):
            y[p] *= share[j]
        y[:, ~keep] = x[:, ~keep]
        out[g] = y
    return out


#: Side (px) of the blocks a flickering lamp's reflection is denoised on (:func:`denoise_reflection`): the tracer's
#: reflection blocks (``RenderOptions.reflection_block_px``, 2 by default).
REFLECTION_BLOCK_PX = 2


def denoise_reflection(img: np.ndarray, traced: np.ndarray, boxes=(), block: int = REFLECTION_BLOCK_PX,
                       denoiser=None, edges=(True, True, True, True)) -> np.ndarray:
    """Denoise one flickering lamp's steady reflection image (``RenderOptions.reflection_denoise``).

    Why: a wet road's reflection of a flickering lamp is traced at ``spp`` (1 at the ``default`` profile) in 2 x 2
    px blocks, and each band pass draws its own sample of a block, so the traced layer is coloured 2 x 2 px speckle
    (docs/benchmarks/gallery.md). Open Image Denoise fed that image at full resolution leaves it (tested: the error of
    a synthetic streak 0.47 -> 0.46; noise correlated over 2 x 2 px reads as detail to a filter trained on
    per-pixel noise), so the image is denoised at the blocks' resolution, where each block is one pixel of
    independent noise, and interpolated back.

    What: the lamp's box(es) filled with the mean of the ring around them (:func:`_fill_boxes`: the lamp's own
    light, 10^3-10^5 times brighter, stays out), ``block`` x ``block`` px block means (:func:`_block_mean`),
    :func:`denoise_static` with this one image as its only group, bilinear back to full size (:func:`_upsample`);
    the boxes keep their traced values and the pixels that were not traced (``traced`` False outside the boxes:
    the grown crop's zeros) stay 0; then the denoised reflection is scaled to the traced one's sum over its pixels
    and bands (the traced sum is an unbiased estimate of the reflection's light; the filter alone lost 7-8 % of it
    on a lamp's streak at spp 1, tests/render_tools/test_reflections.py), so each light's reflected light is the
    traced light and only its distribution over the pixels and bands is the filter's. No other layer enters, and
    the output scales with the input (:func:`oidn_rgb` divides by the image's level and multiplies back): a PWM
    weight applied before or after gives the same image. Not unbiased per pixel (the streak's edges are blurred
    over the block and the filter's shape is kept; measured in docs/benchmarks/render.md, "Reflection speckle").

    Args:
        img: (C, h, w) float32 >= 0, the lamp's spectral radiance (W sr^-1 m^-2 nm^-1) over its grown crop.
        traced: (h, w) bool, the pixels the reflection bands (and the lamp's parts) were traced in.
        boxes: the lamp's padded box(es) (y0, x0, y1, x1) px relative to the crop, end exclusive: kept as traced.
        block: px, the side of the blocks denoised as one pixel (1: full resolution).
        denoiser: as :func:`denoise_static`'s; None: :func:`oidn_rgb` with its mirrored margin on the sides in
            ``edges`` only.
        edges: which sides (top, bottom, left, right) of the crop are the image's own edge (:func:`crop_edges`;
            default: all, a whole image). Only there does the filter see the mirrored margin (where the image ends);
            a side inside the image gets none (only the mirrored alignment rows or columns): the grown crop holds
            the lamp's reflection region and a pad, so its sides inside the image are dim (their outer 4 px held
            0.11 % of the crops' light on a wet 640x360 night). Against 32 px on every side (protocol version 6),
            over that frame's 41 crops: the denoised reflections differ by 0.07 of their mean (RMS), against 0.81
            between two Monte Carlo seeds; the crops' denoising 1.57 -> 1.06 CPU s a frame (a 16 x 24 px block
            image 17 -> 3 ms). The layer's real neighbours beyond such a side are zeros (nothing of this light is
            traced or composed outside its crop), but as context they darken a crop's lit edge (a flat field's
            edges 0.74-0.82 of a whole image's, tests/render_tools/test_denoise.py) and cost as much as the
            margin: not taken (docs/benchmarks/render-scale.md, "Denoiser margin by crop").

    Returns:
        (C, h, w) float32; ``img`` itself when nothing outside the boxes was traced or lit.
    """
    img = np.asarray(img, np.float32)
    traced = np.asarray(traced, bool)
    if traced.shape != img.shape[1:]:
        raise ValueError(f"traced: shape {traced.shape}, expected {img.shape[1:]} as the image")
    keep = keep_mask(traced.shape, boxes)
    refl = traced & keep
    if not refl.any() or not img[:, refl].any():
        return img
    x = _fill_boxes(img, keep, boxes) if boxes else img
    lo = _block_mean(x, block) if block > 1 else x
    if denoiser is None:
        margins = edge_margins(edges)
        denoiser = lambda b: oidn_rgb(b, margins)  # noqa: E731
    y = denoise_static({0: lo}, (), denoiser=denoiser)[0]
    if block > 1:
        y = _upsample(y, block, img.shape[1:])
    y = np.where(refl, y, np.float32(0.0))
    got, want = float(y.sum(dtype=np.float64)), float(img[:, refl].sum(dtype=np.float64))
    if got > 0:  # the traced light of the reflection, an unbiased estimate of its total, is kept
        y *= np.float32(want / got)
    return np.where(keep, y, img).astype(np.float32)
