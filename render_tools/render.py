"""Render a scene into per-frame, per-group spectral radiance: the entry point of the corpus writer.

:func:`render_frames` yields, for each frame n of a sequence (timing of ``docs/guide/contracts.md`` section 1):

- static groups (default headlights, streetlights, skymap): the time-averaged spectral radiance over the short
  (LPD) and long (SPD) exposure windows, (C, H, W) float32, W sr^-1 m^-2 nm^-1; the full frame is rendered at
  ``spp`` and every lamp's own crop again at ``light_spp`` (the HDR peaks get the low-noise estimate);
- flickering groups (default otherlights, signals): every light rendered alone, only inside its screen
  bounding box over the capture window (padded by :attr:`RenderOptions.pad_px`), in K time bins that tile
  the capture window [t_n, t_n + T_L + readout), each the time-averaged radiance over its bin with the light
  at its nominal (PWM level 1) emission: (K, C, h, w) float32;
- AOVs at mid short exposure: z-depth and range (m; +inf where a ray hits nothing), instance id and light id
  (float, -1 = none).

Spectral film: Mitsuba ``specfilm`` with one box sensitivity per band, [c - w/2, c + w/2] nm with height
1/w, so each channel is directly the band-averaged radiance per nm (a box of height 1 would return w * L).
Motion blur: the ego camera moves continuously during every shutter interval (:mod:`render_tools.camera`).
One Mitsuba render per window or per light: the sensor renders an *atlas* (K time bins along x, the
ceil(C / 4) band-stratified wavelength passes along y) of the crop, with crop, window start and bin length
as opaque JIT variables, so the LLVM kernels are reused across lights and frames. Moving objects are placed
at mid capture window. Full-frame (static-group) renders blur them with the ego motion only; a flickering
light on a moving vehicle is rendered with its true relative motion: the camera additionally moves by
``-v_vehicle (t - t_mid)``, which is exact for the lamp, its own vehicle and the light it throws on the road
under it (they move together), while static surroundings in its crop move with it (they only occlude or
reflect). With a static ego camera and a static lamp nothing changes inside a frame: the light is rendered
once and its K bins are exact copies.

Over 500 lines for now: the render options, the camera geometry, the lamp planning and the frame loop still share
this module while it is being reworked; they are to be split into one module each.
"""
from __future__ import annotations

import copy
import math
import zlib
from collections.abc import Iterator
from dataclasses import asdict, dataclass

import numpy as np

from lfmbench.corpus.naming import window_bin_weights
from lfmbench.vocabulary import GROUPS

from . import camera as cam_mod
from . import mitsuba_scene as ms
from . import reflections
from .scene_schema import scene_groups, validate_scene

#: Default spectral bands: centres 400..700 nm step 10 nm.
DEFAULT_BANDS_NM = tuple(float(w) for w in range(400, 701, 10))
#: Number of AOV passes OR-ed into the light mask (small lamps cover a pixel only partly), and their spp.
LIGHT_MASK_PASSES = 4
#: Screen-space sample times per capture window used to bound a light's motion, count.
BBOX_TIME_SAMPLES = 17
#: Light crops are grown to a multiple of this many px. 1: tight crops (the tracer's kernel does not depend
#: on crop sizes; with one ``mi.render`` per crop, 8 kept the number of compiled film sizes down).
CROP_QUANTUM_PX = 1
#: Dot pitch (px) under which a ``dots`` face drawn as it is gets ``RenderOptions.dots_spp_factor`` (its dots are
#: smaller than a pixel: their covered share of a pixel is what the lamp samples estimate).
DOTS_SPP_PX = 1.0
#: Dot pitch (px) under which a flickering ``dots`` face is drawn by its exact coverage (``dots_coverage`` exact): a
#: night scene's message sign 1.06 px apart, traced at light_spp 32, kept 5 % error and the scene's LED bins at
#: 2.0 %; 0.7 % drawn exact (docs/benchmarks/render.md, "LED dot faces against the real dots").
EXACT_DOTS_PX = 2.0
#: Largest projected side (px) of a flickering ``rect`` face drawn by its exact coverage (``dots_coverage`` exact:
#: a countdown's segments, whose thin bars carried a dusk scene's remaining LED-bin error when traced).
EXACT_RECT_PX = 4.0
#: Minimum depth of a projected point treated as in front of the camera, m.
MIN_DEPTH_M = 0.05
#: Height of the row bands a reflection crop is traced in, px (:meth:`SceneGeometry.reflection_tiles`): each band
#: only as wide as the reflection region in its rows (and the rows next to it).
REFLECTION_BAND_PX = 16
#: Ways of tracing the static groups' full frames (:class:`RenderOptions` ``static_pass``).
STATIC_PASSES = ("union", "per_group")
#: Ways of sharing a flickering lamp's crop samples among the band passes (:class:`RenderOptions`
#: ``lamp_pass_spp``, :func:`lamp_pass_spp`).
LAMP_PASS_SPP = ("auto", "spectrum", "uniform")
#: Ways of placing a pixel's samples in x, y and time (:class:`RenderOptions` ``pixel_samples``).
PIXEL_SAMPLES = ("auto", "sobol", "strata")
#: ``RenderOptions.pad_samples`` values.
PAD_SAMPLES = ("auto", "spp", "light")
#: ``RenderOptions.static_denoise`` values (:mod:`render_tools.denoise`).
STATIC_DENOISE = ("auto", "oidn", "off")
#: ``RenderOptions.static_split`` values (:data:`render_tools.denoise.SPLITS` and ``auto``).
STATIC_SPLIT = ("auto", "oidn", "box")
#: ``RenderOptions.glossy_light_choice`` values.
GLOSSY_LIGHT_CHOICE = ("auto", "lobe", "plain")
#: Values of :attr:`RenderOptions.static_bin_samples`.
STATIC_BIN_SAMPLES = ("independent", "common")
#: How a flickering dot face's own box is made (RenderOptions.dots_coverage).
DOTS_COVERAGE = ("auto", "traced", "exact")
#: Values of :attr:`RenderOptions.texture_filter` (Mitsuba's ``bitmap`` ``filter_type`` of the textures).
TEXTURE_FILTERS = ("auto", "bilinear", "nearest")
#: Values of :attr:`RenderOptions.reflection_edges`.
REFLECTION_EDGES = ("auto", "clip", "drop")


@dataclass
class RenderOptions:
    """Render settings (SI units).

    width, height: image size, px. spp: samples per pixel *per band pass* of the full-frame renders (every band
    gets spp wavelength samples per pixel; a pixel costs ceil(C / 4) * spp camera samples). bins: K time bins of the
    capture window for flickering groups. bands_nm: band centres, nm. band_width_nm: box width, nm.
    frames: frames per sequence (any count >= 1; frames are rendered and written one at a time).
    fps: frame rate, 1/s. long_exposure_s: SPD exposure T_L, s (<= 1/fps).
    line_time_s: rolling-shutter line time, s (readout margin = height * line_time_s; the capture window
    T_L + readout may exceed 1/fps, e.g. 1080 rows x 10 us: windows of consecutive frames then overlap).
    groups: groups to render (None = all the scene has). seed: Monte Carlo seed. variant: Mitsuba variant,
    ``cuda_ad_spectral``, ``llvm_ad_spectral`` or ``scalar_spectral`` (None = auto, see
    :mod:`render_tools.backend`). aux: render AOVs. light_spp: spp of the per-light crops
    (None = spp). pad_px: padding of a light's crop around its moving screen bbox, px. static_pass: how the
    full frames of the static groups are traced: ``"union"`` (default: one camera path per sample records every
    static group, next-event estimation draws from all their lamps, :class:`render_tools.tracer.LightSets`) or
    ``"per_group"`` (one path per group and sample, as before 2026-11-23); both are unbiased per group.
    reflection_bins: time bins of the reflection part of a flickering light's crop in a wet scene (a divisor of
    ``bins``; None = ``bins``, exact): the grown crop is traced in ``reflection_bins`` bins, each repeated
    ``bins / reflection_bins`` times, and the lamp's own box again in all ``bins`` at ``light_spp`` over it. The
    PWM still applies bin by bin (the dataset weights every bin), so the reflection flickers exactly with its
    lamp; what is approximated is the reflection's motion inside a longer bin (1: its average over the capture
    window, 14.7 ms at 640x360). Cost of the reflection part: ``reflection_bins / bins`` of the exact one
    (docs/benchmarks/render-scale.md; error in docs/benchmarks/render.md). No effect on dry scenes.
    reflection_min_lux: a flickering light's reflection in a wet road is traced only when the illuminance it
    sends to the camera, E = I / d^2 lux (I: its luminance x face area, cd; d: lamp to camera, m, at mid capture
    window), is at least this; a dimmer light keeps only its own box (its reflection left out, as the light it
    throws on its surroundings outside its crop always was). 0: every light's reflection. Measured on a wet night:
    below 2e-3 lux a reflection averaged under 2 % of the lit road's luminance over its crop
    (docs/benchmarks/rendering-measurements.md, "Light left out by the reflection cut-off").
    dots_lod_px: a ``dots`` face (an LED matrix, a segmented lamp, scene version 2) whose dot pitch projects under
    this many px (in both directions, at every frame's capture window: :meth:`SceneGeometry.dots_pitch_px`) is
    rendered with its lit dots filling their cells at ``dot``^2 of the luminance
    (:func:`render_tools.led_matrix.filled_cells`: the same intensity per cell; the light keeps its id, waveform
    and driver, so a multiplexed sign's rows keep their own phases). Why: sub-pixel dots left each lamp pixel's
    covered share to ~256 camera samples, 7-21 % relative error per lamp kind in the LED bins at the
    ``default`` profile; the filled cells leave out the dots' moire against the pixel grid instead (4-10 % per
    LED pixel where the pitch is 0.3-0.6 px; docs/benchmarks/render.md, "LED dot faces"). 0: every dot face as it
    is. Scenes without dot faces (every lfmbench-v1 scene) render the same whatever it is.
    lamp_pass_spp: how a flickering lamp's own box shares its light_spp x P samples per pixel and bin among the P
    band passes: ``"uniform"`` (light_spp each, as before), ``"spectrum"`` (by the lamp's spectral radiance,
    :func:`lamp_pass_spp`: a narrow-band LED's few passes get most samples; every band stays unbiased) or
    ``"auto"`` (default: ``spectrum`` on scene version 2, ``uniform`` on version 1, whose renders are frozen).
    filled_spp_factor: light_spp multiplier (a power of two) of the flickering lights drawn as filled cells
    (``dots_lod_px``: signals' LED arrays, message signs, countdowns, destination displays): their lit shapes
    (a sign's scan lines, a disk's rim, a digit's bars) are thinner than a pixel, so their pixels' covered share is
    what the lamp samples estimate; at the ``default`` profile these lights (signals, message signs) carried two
    thirds of a night scene's LED-bin error for a fifth of its lamp samples (docs/benchmarks/render.md, "Pixel
    samples"). 1: as other lights.
    Scenes without dot faces (every lfmbench-v1 scene) render the same whatever it is.
    dots_spp_factor: light_spp multiplier (a power of two) of the flickering lights whose ``dots`` faces have a dot
    pitch under :data:`DOTS_SPP_PX` (1 px, over every frame's capture window) and are drawn as they are (not as
    filled cells: ``dots_lod_px`` 0 or under their pitch; :func:`dense_dots`): a pixel's share covered by
    sub-pixel dots is what their lamp samples estimate, and these lights (message signs, signals' LED arrays,
    countdowns, destination displays) carried the LED bins' error over 2 % against the real dot pattern; the
    other lamps were at 1.2 % with light_spp 32 (docs/benchmarks/render.md, "LED dot faces against the real
    dots"). 1 (default): as other lights. Scenes without dot faces render the same whatever it is.
    dots_coverage: how the own box of a flickering light without a beam (``spread_deg`` 90) whose face is ``dots``
    of pitch under :data:`EXACT_DOTS_PX` (message signs, signals' LED arrays, destination displays, far tail
    lamps) or a ``rect`` under :data:`EXACT_RECT_PX` (countdown segments; :func:`exact_faces`) is made: ``"traced"`` (camera samples, as
    every other light), ``"exact"`` (:func:`exact_face`: the face's band radiance times the exact share of each
    pixel its lit dots cover, averaged over each bin, :mod:`render_tools.dot_coverage`; occluders found by
    visibility rays; no camera sample, no Monte Carlo noise, and no ``dots_lod_px`` stand-in for these lights).
    ``"auto"`` (default): ``exact`` on scene version 2 (protocol version 4 of ``lfmbench-v2`` and its mini),
    ``traced`` on version 1, whose renders are frozen.
    What it leaves out: light of that face reflected by what lies inside its own box (none: the dots emit to the
    front of their plane). LED bins of the lamp crops against the real dots on 9 times of day x weathers 3.5-8.2 %
    -> 0.0-0.9 % for 0.84-1.25x their CPU (docs/benchmarks/render.md, "LED dot faces against the real dots").
    pixel_samples: where a pixel's samples lie in x, y and time (:class:`render_tools.tracer.Tile` ``sobol``):
    ``"strata"`` (each dimension stratified on its own, the strata of the dimensions paired at random),
    ``"sobol"`` (a randomly shifted Sobol' sequence: also stratified jointly, which an edge moving across the
    pixel during a bin needs; both unbiased) or ``"auto"`` (default: ``sobol`` on scene version 2, ``strata``
    on version 1, whose renders are frozen).
    reflection_block_px: 1 or 2 (:data:`render_tools.tracer.BLOCK`): a wet road's reflection bands are traced
    with one lane per block of that many px squared, its samples spread over the block and its mean written to
    each pixel of it (:class:`render_tools.tracer.Tile` ``block``): the reflection's image box-blurred over the
    block (its light in the block kept) for a quarter of its camera samples. A lamp's reflection in a glossy
    film is itself a blur many px wide (docs/guide/rendering.md, "Wet roads"; error in docs/benchmarks/render.md). 1:
    every pixel traced. No effect on dry scenes.
    pad_samples: samples of the ``pad_px`` ring around a lamp in its crop: ``"light"`` (``light_spp``, as the lamp
    itself), ``"spp"`` (``spp``, as the full frame: the ring holds no part of the lamp's face, only the light it
    throws on what is next to it; the lamp's own box keeps ``light_spp``; both unbiased) or ``"auto"`` (default:
    ``spp`` on scene version 2, ``light`` on version 1, whose renders are frozen). The ring held two thirds of a
    generator-2 night's lamp-crop samples (37.9 M of a scene's 3 frames, 12.6 M without it; docs/benchmarks/
    render-scale.md). A static group's lamp refines its own box only (the ring keeps the full frame's estimate).
    static_denoise: the static groups' short and long full frames of each frame denoised after tracing, the static
    groups' lamp boxes kept as traced (:mod:`render_tools.denoise`: Intel Open Image Denoise on three broad bands,
    split back among groups and bands by their local shares): ``"oidn"``, ``"off"`` (the traced estimate,
    unbiased) or ``"auto"`` (default: ``oidn`` on scene version 2, ``off`` on version 1, whose renders are frozen).
    At the ``default`` profile the median per-pixel error of a 640x360 v2 frame went from 25 / 12 / 31 % (day, dry
    night, wet night) to 4 / 3 / 9.5 % for 0.8-0.9 CPU s per frame (docs/benchmarks/render.md, "Scene generator
    2"); not unbiased (a wet road's static reflections are blurred: docs/guide/rendering.md, "Static frames denoised");
    the flickering lamps' own boxes are never denoised (their reflections: ``reflection_denoise``).
    static_split: how the denoised static frames are split back among the static groups
    (:func:`render_tools.denoise.denoise_static` ``split``): ``"box"`` (each group's share of a broad band in a 5 x 5
    px box of its spp-1 image: on a wet road, where the static lamps' reflections are sparse bright samples, it
    coloured 4-6 px squares magenta and green), ``"oidn"`` (by each group's light denoised on 2 x 2 px blocks, three
    groups per filter call, and the group's colour over 33 px; the broad bands, so the frame's light, are the same)
    or ``"auto"`` (default: ``oidn`` on a version-2 scene with a glossy road, a wet one, else ``box``: dry frames
    unchanged). Content: it changes the static groups' images of a wet version-2 frame (docs/benchmarks/gallery.md).
    glossy_light_choice: how next-event estimation draws a lamp at a point of a glossy coat (every
    ``roughplastic``: a wet road's water film and puddles, glass, car paint, lamp lenses, signs;
    :func:`render_tools.tracer.glossy_choice_table`): ``"lobe"`` (the lamp's weight times the coat's specular
    lobe towards it, :meth:`render_tools.tracer.Tracer._lamp_weights`: the lamp a point reflects gets its samples),
    ``"plain"`` (intensity, cosines and distance only: at spp 1 a wet road's reflections of the static lamps were
    sparse bright samples, which the static denoiser smeared into an orange sheet and split into coloured squares)
    or ``"auto"`` (default: ``lobe`` on scene version 2, ``plain`` on version 1). Unbiased either way (every lamp
    keeps a positive probability; the hit's MIS weight uses the same choice); content: a version-2 wet frame's
    noise and its denoised static frames change (docs/benchmarks/gallery.md).
    reflection_denoise: a flickering lamp's reflection in a wet road (the steady part of its grown crop outside
    its padded lamp box, traced at ``spp`` in ``reflection_block_px`` blocks) denoised after tracing, each light's
    layer alone (:func:`render_tools.denoise.denoise_reflection`: the static frames' denoiser on that one image
    at the resolution of its 2 x 2 px blocks, interpolated back and scaled to its traced light, its lamp box kept
    out and as traced): ``"oidn"``, ``"off"`` (the traced estimate, unbiased; at spp 1 in 2 x 2
    px blocks it is coloured 2 x 2 px speckle: each band pass draws its own sample of a block) or ``"auto"``
    (default: ``oidn`` on scene version 2, ``off`` on version 1). No layer is mixed with another, and the layer
    still scales with its lamp's PWM (the dataset weights it as before), so the flicker-free truth and the captures
    see the same reflection; not unbiased (docs/guide/rendering.md, "Wet roads"). Reflections traced in several
    time bins (``reflection_bins`` > 1 with motion) are left as traced.
    reflection_edges: where a flickering lamp's reflection region leaves the image (a streak running on below
    the bottom row or out at a side), its grown box (:meth:`SceneGeometry.light_bbox`) is bounded by ``"clip"``
    (each region cell's footprint clipped to the padded image in front of the camera: the box reaches the edge),
    ``"drop"`` (the region's grid points that project into the padded image only: the box stopped at the last
    point inside, up to one grid cell short of the edge; on a wet 640x360 night the bottom 12-13 rows held no
    flickering reflection, docs/guide/scenes.md) or ``"auto"`` (default: ``clip`` on scene version 2, ``drop``
    on version 1, whose renders are frozen). No effect on dry scenes.
    static_edges_s: times (s from the frame start, inside the capture window) at which the static groups are cut
    into time bins (:func:`static_bin_edges`): () (default) stores the short and long windows only, as every corpus
    before; any edges store the static groups in the bins between the sorted union of these edges and the short and
    long windows' (0, the short window's ends, T_L), each bin the time average of the scene over it with the
    moving objects at the bin's middle (:func:`render_frames`); the short and long windows are the exact
    length-weighted sums of their bins. Give the window edges of every capture of the sensors a corpus serves
    (:func:`lfmbench.sensor.plan.resolve_windows`; a protocol's ``render.static_edges_s``): each capture window is
    then an exact sum of bins, so a staggered exposure sees the scene (ego motion and moving vehicles) over its own
    time instead of the long window's average (docs/benchmarks/motion-windows.md). A scene where nothing moves (a
    static camera, no moving object) keeps the two windows whatever is asked (all bins would be equal).
    static_bin_samples: the random numbers of the static time bins: ``"independent"`` (default; every corpus
    rendered before it existed) draws each bin's samples anew, ``"common"`` gives every bin of a frame the same
    per-pixel sample sequence (common random numbers: pixel position, time as a fraction of the bin, wavelengths,
    path decisions), so two bins differ by what moves between them, not by independent Monte Carlo noise; each bin
    stays unbiased (docs/benchmarks/motion-storage.md).
    texture_filter: how the textures of scene version 2 (``texture`` of a material) are looked up: ``"bilinear"``
    (Mitsuba's ``bitmap`` default: four texels, each upsampled to the path's wavelengths, at every BSDF evaluation),
    ``"nearest"`` (one texel) or ``"auto"`` (default: ``nearest`` on scene version 2). Nearest costs 0.86 / 0.89 of
    a bilinear wet-night render's CPU cold / warm (320x180) and keeps the texture contrast (road 31.8 against 31.6 %
    RMS local contrast, 88 against 89 % of it kept by the denoiser; no texel blocks seen near the camera at 640x360:
    docs/benchmarks/textures.md). Scenes without textures render the same whatever it is.
    static_layers: named unions of capture windows (``[{"name", "windows_s": [[start_s, length_s], ...]}]``, s from
    the frame start; in increasing order, not overlapping, inside the capture window) whose static radiance is
    rendered as such, one full frame's samples spread over the union (:mod:`render_tools.static_layers`), and stored
    beside the scene's other files (:mod:`lfmbench.corpus.window_layers`): a capture whose windows are a layer's (the
    chopped preset's 12 sub-windows) is served from it exactly. () (default): none.
    """

    width: int = 640
    height: int = 360
    spp: int = 64
    bins: int = 8
    bands_nm: tuple = DEFAULT_BANDS_NM
    band_width_nm: float = 10.0
    frames: int = 3
    fps: float = 60.0
    long_exposure_s: float = 1.0 / 90.0
    line_time_s: float = 10e-6
    groups: tuple | None = None
    seed: int = 0
    variant: str | None = None
    aux: bool = True
    light_spp: int | None = None
    pad_px: int = 2
    static_pass: str = "union"
    reflection_bins: int | None = 1
    reflection_min_lux: float = 2e-3
    dots_lod_px: float = 1.0
    lamp_pass_spp: str = "auto"
    filled_spp_factor: int = 2
    dots_spp_factor: int = 1
    dots_coverage: str = "auto"
    pixel_samples: str = "auto"
    reflection_block_px: int = 2
    pad_samples: str = "auto"
    static_denoise: str = "auto"
    reflection_denoise: str = "auto"
    static_split: str = "auto"
    glossy_light_choice: str = "auto"
    static_edges_s: tuple = ()
    static_bin_samples: str = "independent"
    static_layers: tuple = ()
    texture_filter: str = "auto"
    reflection_edges: str = "auto"

    def __post_init__(self):
        self.bands_nm = tuple(float(b) for b in self.bands_nm)
        from lfmbench.corpus.window_layers import parse_layers  # noqa: PLC0415

        self.static_layers = parse_layers(self.static_layers, self.capture_window_s)
        self.static_edges_s = tuple(float(e) for e in (self.static_edges_s or ()))
        if self.groups is not None:
            self.groups = tuple(self.groups)
        self.validate()

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first impossible option."""
        for name in ("width", "height", "spp", "bins", "frames"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name}: must be an integer >= 1, got {v!r}")
        if self.light_spp is not None and (not isinstance(self.light_spp, (int, np.integer)) or self.light_spp < 1):
            raise ValueError(f"light_spp: must be None or an integer >= 1, got {self.light_spp!r}")
        rb = self.reflection_bins
        if rb is not None and (isinstance(rb, bool) or not isinstance(rb, (int, np.integer)) or rb < 1
                               or self.bins % rb):
            raise ValueError(f"reflection_bins: must be None or a divisor of bins ({self.bins}), got {rb!r}")
        lux = self.reflection_min_lux
        if isinstance(lux, bool) or not isinstance(lux, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(lux) and lux >= 0):
            raise ValueError(f"reflection_min_lux: must be a number >= 0 lux, got {lux!r}")
        lod = self.dots_lod_px
        if isinstance(lod, bool) or not isinstance(lod, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(lod) and lod >= 0):
            raise ValueError(f"dots_lod_px: must be a number >= 0 px, got {lod!r}")
        if self.lamp_pass_spp not in LAMP_PASS_SPP:
            raise ValueError(f"lamp_pass_spp: must be one of {LAMP_PASS_SPP}, got {self.lamp_pass_spp!r}")
        if self.reflection_block_px not in (1, 2) or isinstance(self.reflection_block_px, bool):
            raise ValueError(f"reflection_block_px: must be 1 or 2, got {self.reflection_block_px!r}")
        if self.pad_samples not in PAD_SAMPLES:
            raise ValueError(f"pad_samples: must be one of {PAD_SAMPLES}, got {self.pad_samples!r}")
        e = np.asarray(self.static_edges_s, dtype=np.float64)
        if e.size and (not np.all(np.isfinite(e)) or np.any(e < 0)
                       or np.any(e > self.capture_window_s * (1 + 1e-9))):
            raise ValueError(f"static_edges_s: every edge must lie in the capture window [0, "
                             f"{self.capture_window_s:.6g}] s from the frame start, got {list(self.static_edges_s)}")
        from lfmbench.corpus.window_layers import parse_layers  # noqa: PLC0415

        parse_layers(self.static_layers, self.capture_window_s)
        if self.static_bin_samples not in STATIC_BIN_SAMPLES:
            raise ValueError(f"static_bin_samples: must be one of {STATIC_BIN_SAMPLES}, got "
                             f"{self.static_bin_samples!r}")
        if self.texture_filter not in TEXTURE_FILTERS:
            raise ValueError(f"texture_filter: must be one of {TEXTURE_FILTERS}, got {self.texture_filter!r}")
        if self.reflection_edges not in REFLECTION_EDGES:
            raise ValueError(f"reflection_edges: must be one of {REFLECTION_EDGES}, got {self.reflection_edges!r}")
        if self.static_denoise not in STATIC_DENOISE:
            raise ValueError(f"static_denoise: must be one of {STATIC_DENOISE}, got {self.static_denoise!r}")
        if self.glossy_light_choice not in GLOSSY_LIGHT_CHOICE:
            raise ValueError(f"glossy_light_choice: must be one of {GLOSSY_LIGHT_CHOICE}, got "
                             f"{self.glossy_light_choice!r}")
        if self.static_split not in STATIC_SPLIT:
            raise ValueError(f"static_split: must be one of {STATIC_SPLIT}, got {self.static_split!r}")
        if self.reflection_denoise not in STATIC_DENOISE:
            raise ValueError(f"reflection_denoise: must be one of {STATIC_DENOISE}, got {self.reflection_denoise!r}")
        if self.dots_coverage not in DOTS_COVERAGE:
            raise ValueError(f"dots_coverage: must be one of {DOTS_COVERAGE}, got {self.dots_coverage!r}")
        if self.pixel_samples not in PIXEL_SAMPLES:
            raise ValueError(f"pixel_samples: must be one of {PIXEL_SAMPLES}, got {self.pixel_samples!r}")
        for name in ("filled_spp_factor", "dots_spp_factor"):
            f = getattr(self, name)
            if isinstance(f, bool) or not isinstance(f, (int, np.integer)) or f < 1 or f & (f - 1):
                raise ValueError(f"{name}: must be a power of two >= 1, got {f!r}")
        if self.static_pass not in STATIC_PASSES:
            raise ValueError(f"static_pass: must be one of {STATIC_PASSES}, got {self.static_pass!r}")
        if not isinstance(self.pad_px, (int, np.integer)) or self.pad_px < 0:
            raise ValueError(f"pad_px: must be an integer >= 0, got {self.pad_px!r}")
        if not self.bands_nm:
            raise ValueError("bands_nm: at least one band is needed")
        if not (math.isfinite(self.band_width_nm) and self.band_width_nm > 0):
            raise ValueError(f"band_width_nm: must be > 0 nm, got {self.band_width_nm}")
        b = np.asarray(self.bands_nm)
        if np.any(b - self.band_width_nm / 2 < 360.0) or np.any(b + self.band_width_nm / 2 > 830.0):
            raise ValueError(f"bands_nm: bands must lie inside 360..830 nm, got {self.bands_nm[0]}..{self.bands_nm[-1]}"
                             f" with width {self.band_width_nm}")
        if np.any(np.diff(b) < self.band_width_nm - 1e-9):
            raise ValueError("bands_nm: bands must be increasing and must not overlap (step >= band_width_nm)")
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"fps: must be > 0 1/s, got {self.fps}")
        if not (math.isfinite(self.long_exposure_s) and self.long_exposure_s > 0):
            raise ValueError(f"long_exposure_s: must be > 0 s, got {self.long_exposure_s}")
        if not (math.isfinite(self.line_time_s) and self.line_time_s >= 0):
            raise ValueError(f"line_time_s: must be >= 0 s, got {self.line_time_s}")
        # an exposure cannot outlast the frame; the capture window T_L + readout may (rolling-shutter frames
        # overlap in time: row y of frame n+1 starts at (n+1)/fps + y * line_time_s, docs/guide/corpus-format.md)
        if self.long_exposure_s > 1.0 / self.fps * (1 + 1e-9):
            raise ValueError(f"long_exposure_s: {self.long_exposure_s:.6g} s is longer than the frame time "
                             f"1/fps = {1.0 / self.fps:.6g} s")
        if self.groups is not None:
            for g in self.groups:
                if g not in GROUPS:
                    raise ValueError(f"groups: {g!r} not one of {GROUPS}")
        if not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ValueError(f"seed: must be an integer >= 0, got {self.seed!r}")
        from .backend import SUPPORTED_VARIANTS  # noqa: PLC0415 - no Mitsuba import

        if self.variant is not None and self.variant not in SUPPORTED_VARIANTS:
            raise ValueError(f"variant: must be None (auto) or one of {SUPPORTED_VARIANTS}, got {self.variant!r}")

    @property
    def readout_s(self) -> float:
        """Rolling-shutter readout margin, s: height * line_time_s."""
        return self.height * self.line_time_s

    @property
    def capture_window_s(self) -> float:
        """Capture window length W = T_L + readout, s."""
        return self.long_exposure_s + self.readout_s

    def to_dict(self) -> dict:
        d = asdict(self)
        d["bands_nm"] = list(self.bands_nm)
        d["groups"] = None if self.groups is None else list(self.groups)
        d["static_edges_s"] = list(self.static_edges_s)
        if not d["static_edges_s"]:  # the options of corpora rendered before it existed stay the same
            del d["static_edges_s"]
        if d["static_bin_samples"] == "independent":  # as before the option existed
            del d["static_bin_samples"]
        from lfmbench.corpus.window_layers import layers_dict  # noqa: PLC0415

        if d["texture_filter"] == "auto":  # as before the option existed
            del d["texture_filter"]
        if d["reflection_edges"] == "auto":  # as before the option existed
            del d["reflection_edges"]
        d["static_layers"] = layers_dict(self.static_layers)
        if not d["static_layers"]:
            del d["static_layers"]
        return d


def frame_timing(scene: dict, opts: RenderOptions, n: int) -> dict:
    """Windows of frame ``n`` (s, absolute, from the sequence start) per ``docs/guide/contracts.md`` section 1.

    Returns dict with ``t0``, ``long`` (a, b), ``short`` (a, b) (centre-aligned with long), ``window`` (a, b),
    ``bin_edges`` (K+1,) and ``t_aux`` (mid short exposure).
    """
    ts = float(scene["timing"]["short_exposure_s"])
    tl = opts.long_exposure_s
    if ts > tl:
        raise ValueError(f"scene.timing.short_exposure_s: {ts} s is longer than the long exposure {tl} s")
    t0 = n / opts.fps
    w = opts.capture_window_s
    short = (t0 + (tl - ts) / 2, t0 + (tl + ts) / 2)
    return {"t0": t0, "long": (t0, t0 + tl), "short": short, "window": (t0, t0 + w),
            "bin_edges": t0 + np.arange(opts.bins + 1) * (w / opts.bins), "t_aux": 0.5 * (short[0] + short[1])}


def _film(opts: RenderOptions, width: int, height: int) -> dict:
    """``specfilm`` of ``width`` x ``height`` px with one box band per entry of ``opts.bands_nm`` (height 1/w)."""
    w = opts.band_width_nm
    d = {"type": "specfilm", "width": int(width), "height": int(height), "rfilter": {"type": "box"},
         "component_format": "float32"}
    for i, c in enumerate(opts.bands_nm):
        d[f"band{i:03d}"] = {"type": "regular", "wavelength_min": c - w / 2, "wavelength_max": c + w / 2,
                             "values": f"{1.0 / w!r}, {1.0 / w!r}"}
    return d


def _seed(*parts) -> int:
    """Deterministic 31-bit render seed from integers/strings (CRC32)."""
    return zlib.crc32(("/".join(str(p) for p in parts)).encode()) & 0x7FFFFFFF


class SceneGeometry:
    """Where a scene's lamps are on screen over time (no Mitsuba): ego motion, intrinsics, light bboxes."""

    def __init__(self, scene: dict, opts: RenderOptions):
        self.scene, self.opts = scene, opts
        self.ego = cam_mod.EgoMotion.from_scene(scene)
        self.fov = float(scene["camera"]["fov_x_deg"])
        self.K = cam_mod.intrinsics(opts.width, opts.height, self.fov)
        self.wet = reflections.wet_road(scene)  # None: dry, no reflection region in any crop
        self.clip_edges = _on_from_version_2(opts.reflection_edges, "clip", scene)  # RenderOptions.reflection_edges
        self._grids: dict = {}  # (light id, t_obj) -> reflections.glossy_grid: a light's bbox and bands share it
        self._poses: dict = {}  # t -> camera pose: every light of a frame is projected at the same time samples
        self._extents: dict = {}  # light_bbox's screen extents (:meth:`_extent`)

    def pose_cv(self, t: float) -> np.ndarray:
        """:meth:`render_tools.camera.EgoMotion.pose_cv` at ``t`` (s), computed once per time (read-only)."""
        t = float(t)
        if t not in self._poses:
            self._poses[t] = self.ego.pose_cv(t)
            self._poses[t].flags.writeable = False
        return self._poses[t]

    def _glossy_grid(self, light: dict, t_obj: float):
        """:func:`render_tools.reflections.glossy_grid` of a light at ``t_obj`` (s), computed once per light and
        time (a frame's plan asks for it up to three times per light)."""
        key = (light["id"], float(t_obj))
        if key not in self._grids:
            self._grids[key] = reflections.glossy_grid(ms.light_points(self.scene, light, t_obj),
                                                        self.ego.position(t_obj), self.wet)
        return self._grids[key]

    def facing(self, light: dict, t_obj: float, times, moving: bool = False) -> bool:
        """Whether the lamp face points towards the camera at any of ``times`` (s); ``moving``: the lamp moves
        with its object (per-light renders), else it is held at its ``t_obj`` position."""
        times = np.asarray(times, dtype=np.float64)
        c = np.asarray(light["center"], float) + ms.object_offset(self.scene, light["instance"], t_obj)
        pos = self.ego.position(times)
        if moving:
            pos = pos - np.outer(times - t_obj, self.object_velocity(light))
        return bool(np.any((pos - c) @ np.asarray(light["normal"], float) > 0))

    def object_velocity(self, light: dict) -> np.ndarray:
        """(3,) world velocity (m/s) of the object a light is mounted on (zeros for a static light)."""
        return ms.object_offset(self.scene, light["instance"], 1.0)

    def reflected(self, light: dict, t_obj: float) -> bool:
        """Whether a flickering light's reflection in the wet road is traced (:class:`RenderOptions`
        ``reflection_min_lux``): a wet scene, and the illuminance I / d^2 (lux) the lamp sends to the camera at
        ``t_obj`` (s) at least the option's."""
        if self.wet is None:
            return False
        c = np.asarray(light["center"], float) + ms.object_offset(self.scene, light["instance"], t_obj)
        d2 = float(np.sum((c - self.ego.position(t_obj)) ** 2))
        e = float(light["luminance_cd_m2"]) * ms.plane_area(light) / max(d2, 1e-12)
        return e >= self.opts.reflection_min_lux

    def _reflection_uv(self, light: dict, t_obj: float, t: float, pts: np.ndarray) -> np.ndarray:
        """Screen points (N, 2) px at time ``t`` (s) of road points ``pts`` (N, 3) m (moving with the light's
        object from its ``t_obj`` position) that lie in front of the camera and within the padded image."""
        v = self.object_velocity(light)
        ruv, rz = cam_mod.project(pts + v * (t - t_obj), self.pose_cv(t), self.K)
        p = self.opts.pad_px
        ok = (rz > MIN_DEPTH_M) & (ruv[:, 0] >= -p) & (ruv[:, 0] <= self.opts.width + p) & \
            (ruv[:, 1] >= -p) & (ruv[:, 1] <= self.opts.height + p)
        return ruv[ok]

    def _edge_uv(self, light: dict, t_obj: float, times, cells: np.ndarray) -> np.ndarray:
        """Screen points (N, 2) px at ``times`` (T,) s that, with the cells' corners :meth:`_reflection_uv` keeps,
        bound the footprint of road ``cells`` (M, 4, 3) m (axis-aligned rectangles on z = 0,
        :func:`render_tools.reflections.glossy_cells`; moving with the light's object from its ``t_obj``
        position) clipped to the padded image in front of the camera (depth > :data:`MIN_DEPTH_M`), for the
        cells that cross its edge. In the road plane each bound is a half-plane ``a x + b y + c >= 0`` (the
        camera-space constraints ``z >= MIN_DEPTH_M``, ``-pad <= u <= W + pad``, ``-pad <= v <= H + pad``, linear
        where z > 0); the clipped cell is a convex polygon whose vertices are among the cell corners inside all
        five (kept by :meth:`_reflection_uv`), the crossings of its four sides with the five lines, and the ten
        crossings of two lines inside it (returned here): the box of their projections is the box of the
        footprint's part in the image, so a cell reaching behind the camera or past the image's edge bounds the
        box up to that edge instead of being dropped."""
        times = np.asarray(times, dtype=np.float64).reshape(-1)
        if not len(cells) or not len(times):
            return np.zeros((0, 2))
        off = np.outer(times - t_obj, self.object_velocity(light))  # (T, 3) m
        poses = np.stack([self.pose_cv(t) for t in times])
        r, c = poses[:, :3, :3], poses[:, :3, 3]  # camera coords of X: (X - c) @ r (render_tools.camera.project)
        K, p, W, H = self.K, self.opts.pad_px, self.opts.width, self.opts.height
        e3 = np.array([0.0, 0.0, 1.0])
        A = np.stack([e3, K[0] + p * e3, (W + p) * e3 - K[0], K[1] + p * e3, (H + p) * e3 - K[1]])  # (5, 3)
        al, be = r[:, 0] @ A.T, r[:, 1] @ A.T  # (T, 5): (x, y, 0) + off -> x r[0] + y r[1] + (off - c) @ r
        ga = np.einsum("tk,tkj->tj", off - c, r) @ A.T + np.array([-MIN_DEPTH_M, 0.0, 0.0, 0.0, 0.0])

        def inside(x, y, k):  # x, y, k (...,) -> (...,): in all five half-planes of time k, round-off margin
            ax, by, g = x[..., None] * al[k], y[..., None] * be[k], ga[k]
            return np.all(ax + by + g >= -1e-9 * (np.abs(ax) + np.abs(by) + np.abs(g) + 1.0), axis=-1)

        F = cells[None, :, :, 0, None] * al[:, None, None] + cells[None, :, :, 1, None] * be[:, None, None] \
            + ga[:, None, None]  # (T, M, 4, 5)
        cross = ~np.all(F >= 0, axis=(2, 3)) & ~np.any(np.all(F < 0, axis=2), axis=-1)  # (T, M)
        ti, mi = np.nonzero(cross)
        if not len(ti):
            return np.zeros((0, 2))
        cl = cells[mi]
        x0, x1 = cl[:, :, 0].min(1), cl[:, :, 0].max(1)
        y0, y1 = cl[:, :, 1].min(1), cl[:, :, 1].max(1)
        a_, b_, g_ = al[ti][:, None], be[ti][:, None], ga[ti][:, None]  # (n, 1, 5)
        k = np.broadcast_to(ti[:, None, None], (len(ti), 2, 5))
        pts, tk = [], []
        with np.errstate(divide="ignore", invalid="ignore"):
            # the sides x = x0, x1 (then y = y0, y1) against each line: the other coordinate (n, 2, 5) solved
            for side, lo, hi, c_side, c_other, is_y in ((np.stack([x0, x1], 1), y0, y1, a_, b_, False),
                                                         (np.stack([y0, y1], 1), x0, x1, b_, a_, True)):
                f = side[..., None]  # (n, 2, 1)
                o = -(f * c_side + g_) / c_other
                f = np.broadcast_to(f, o.shape)
                ok = np.isfinite(o) & (o >= lo[:, None, None]) & (o <= hi[:, None, None])
                xs, ys = (o, f) if is_y else (f, o)
                ok &= inside(xs, ys, k)
                pts.append(np.stack([xs[ok], ys[ok]], -1))
                tk.append(k[ok])
            i, j = np.triu_indices(5, 1)  # two lines crossing inside a cell (a corner of the visible road)
            det = al[:, i] * be[:, j] - al[:, j] * be[:, i]  # (T, 10)
            px = (be[:, i] * ga[:, j] - be[:, j] * ga[:, i]) / det
            py = (al[:, j] * ga[:, i] - al[:, i] * ga[:, j]) / det
            kk = np.broadcast_to(np.arange(len(times))[:, None], px.shape)
            q = np.isfinite(px) & np.isfinite(py)
            q[q] = inside(px[q], py[q], kk[q])
            hit = np.zeros(px.shape, dtype=bool)  # inside a cell crossing the edge at that time
            np.logical_or.at(hit, ti, (px[ti] >= x0[:, None]) & (px[ti] <= x1[:, None]) & (py[ti] >= y0[:, None])
                             & (py[ti] <= y1[:, None]))
            q &= hit
            pts.append(np.stack([px[q], py[q]], -1))
            tk.append(kk[q])
        xy, tk = np.concatenate(pts), np.concatenate(tk)
        if not len(xy):
            return np.zeros((0, 2))
        pc = np.einsum("nk,nkj->nj", np.concatenate([xy, np.zeros((len(xy), 1))], 1) + off[tk] - c[tk], r[tk])
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (pc @ K.T)[:, :2] / pc[:, 2:]
        return uv[(pc[:, 2] > 0) & np.all(np.isfinite(uv), axis=1)]

    def reflection_tiles(self, light: dict, t_obj: float, t_a: float, t_b: float, bbox) -> list[tuple]:
        """The crops (y0, x0, y1, x1) px that hold a flickering light's reflection inside its grown ``bbox``
        (:meth:`light_bbox`) over [t_a, t_b] s: the box cut into row bands of :data:`REFLECTION_BAND_PX`, each
        only as wide as the reflection region's cells (:func:`render_tools.reflections.glossy_cells`) that reach
        into the band or the bands next to it, at any of the time samples, padded by ``pad_px``; bands the region
        does not reach are left out. Disjoint; their union holds every region point of :meth:`light_bbox`. A cell
        reaching behind the camera covers its band and every band below (the streak runs under the camera).
        Empty when the light has no reflection region."""
        if not self.reflected(light, t_obj):
            return []
        cells = reflections.glossy_cells(None, None, self.wet, grid=self._glossy_grid(light, t_obj))
        if not len(cells):
            return []
        y0, x0, y1, x1 = bbox
        B, p = REFLECTION_BAND_PX, self.opts.pad_px
        nb = -(-(y1 - y0) // B)
        v = self.object_velocity(light)
        flat = cells.reshape(-1, 3)
        band = np.arange(nb)
        # every time sample's cells (their corners in front of the camera) first, then the bands' extents over all
        # of them at once: minima and maxima, whatever the order they are taken in (one (bands, cells) pass
        # instead of one per time sample)
        uvs, fronts = [], []
        for t in np.linspace(t_a, t_b, BBOX_TIME_SAMPLES):
            uv, z = cam_mod.project(flat + v * (t - t_obj), self.pose_cv(t), self.K)
            uvs.append(uv.reshape(-1, 4, 2))
            fronts.append(z.reshape(-1, 4) > MIN_DEPTH_M)
        uv, front = np.concatenate(uvs), np.concatenate(fronts)
        some, every = front.any(1), front.all(1)
        uv, front, every = uv[some], front[some], every[some]
        u, w = np.where(front, uv[..., 0], np.nan), np.where(front, uv[..., 1], np.nan)
        ya, yb = np.fmin.reduce(w, axis=1), np.fmax.reduce(w, axis=1)  # the corners in front (NaN: behind)
        xa, xb = np.fmin.reduce(u, axis=1), np.fmax.reduce(u, axis=1)
        # a cell reaching behind the camera: its rows down to the image's bottom, the box's full width
        part = ~every
        yb[part], xa[part], xb[part] = math.inf, -math.inf, math.inf
        ba = np.maximum(np.floor((ya - y0) / B) - 1, 0)
        bz = np.where(np.isfinite(yb), np.floor((yb - y0) / B) + 1, nb - 1)
        hit = (ba[None, :] <= band[:, None]) & (band[:, None] <= bz[None, :])  # (bands, cells)
        lo = np.where(hit, xa[None, :], np.inf).min(1, initial=np.inf)
        hi = np.where(hit, xb[None, :], -np.inf).max(1, initial=-np.inf)
        out = []
        for i in range(nb):
            if not hi[i] >= lo[i]:
                continue
            a = max(x0, int(math.floor(lo[i])) - p) if math.isfinite(lo[i]) else x0
            b = min(x1, int(math.ceil(hi[i])) + p) if math.isfinite(hi[i]) else x1
            if b > a:
                out.append((y0 + i * B, a, min(y1, y0 + (i + 1) * B), b))
        return out

    def dots_pitch_px(self, light: dict, times) -> float:
        """Largest screen distance (px) between neighbouring dot centres of a ``dots`` face, along its columns
        or its rows, at the face's four corners and any of ``times`` (s; the lamp moving with its object);
        inf where a corner is at or behind the camera plane (:data:`MIN_DEPTH_M`)."""
        u, v, _ = ms._frame(light["normal"])  # the frame its dots are laid out in
        (w, h), (cols, rows) = light["size"], light["grid"]
        c = np.asarray(light["center"], dtype=float)
        corners = np.array([c + a * w / 2 * u + b * h / 2 * v for a in (-1, 1) for b in (-1, 1)])
        pts = np.concatenate([corners, corners + u * (w / cols), corners + v * (h / rows)])  # (12, 3) m
        best = 0.0
        for t in np.asarray(times, dtype=np.float64).reshape(-1):
            uv, z = cam_mod.project(pts + ms.object_offset(self.scene, light["instance"], t), self.pose_cv(t),
                                    self.K)
            if np.any(z <= MIN_DEPTH_M):
                return math.inf
            step = np.linalg.norm(uv[4:].reshape(2, 4, 2) - uv[:4][None], axis=-1)  # (2, 4) px
            best = max(best, float(step.max()))
        return best

    def light_bbox(self, light: dict, t_obj: float, t_a: float, t_b: float, moving: bool = False,
                   reflection: bool = True, pad: int | None = None):
        """Screen bbox (y0, x0, y1, x1) px (end exclusive) of a light's face over [t_a, t_b] s, padded and
        clipped; None when not visible (behind the camera, outside the image or facing away). ``moving``: the
        lamp moves with its object over the interval (as per-light renders show it), else it is held at its
        ``t_obj`` position (as full-frame renders show it). In a wet scene a moving (flickering) light's box also
        holds its reflection in the road (:mod:`render_tools.reflections`) unless ``reflection`` is False or the
        light is too dim for its reflection to be traced (:meth:`reflected`). ``pad``: px around the box (None:
        ``opts.pad_px``)."""
        ext = self._extent(light, t_obj, t_a, t_b, moving, reflection)
        if ext is None:
            return None
        p = self.opts.pad_px if pad is None else pad
        x0, y0 = np.floor(ext[0]).astype(int) - p
        x1, y1 = np.ceil(ext[1]).astype(int) + p
        if x1 <= 0 or y1 <= 0 or x0 >= self.opts.width or y0 >= self.opts.height:
            return None
        x0, x1 = _round_span(x0, x1, self.opts.width)
        y0, y1 = _round_span(y0, y1, self.opts.height)
        return (int(y0), int(x0), int(y1), int(x1))

    def _extent(self, light: dict, t_obj: float, t_a: float, t_b: float, moving: bool, reflection: bool):
        """(min (x, y), max (x, y)) px of the screen points behind :meth:`light_bbox` (None: none visible),
        computed once per light and arguments (a lamp's padded and unpadded boxes share it)."""
        key = (light["id"], float(t_obj), float(t_a), float(t_b), bool(moving), bool(reflection))
        if key not in self._extents:
            self._extents[key] = self._project_extent(light, t_obj, t_a, t_b, moving, reflection)
        return self._extents[key]

    def _project_extent(self, light: dict, t_obj: float, t_a: float, t_b: float, moving: bool, reflection: bool):
        times = np.linspace(t_a, t_b, BBOX_TIME_SAMPLES)
        if not self.facing(light, t_obj, times, moving):
            return None
        pts = ms.light_points(self.scene, light, t_obj)
        v = self.object_velocity(light) if moving else np.zeros(3)
        # a flickering light's crop also holds its reflection in a wet road (render_tools.reflections)
        refl = reflections.glossy_points(None, None, self.wet, grid=self._glossy_grid(light, t_obj)) \
            if moving and reflection and self.reflected(light, t_obj) else None
        # where the region leaves the image, its cells' footprints clipped to it (RenderOptions.reflection_edges)
        cells = reflections.glossy_cells(None, None, self.wet, grid=self._glossy_grid(light, t_obj), whole=True) \
            if refl is not None and len(refl) and self.clip_edges else None
        uvs = [] if cells is None else [self._edge_uv(light, t_obj, times, cells)]
        for t in times:
            pose = self.pose_cv(t)
            pw = pts + v * (t - t_obj)
            uv, z = cam_mod.project(pw, pose, self.K)
            if refl is not None and len(refl):
                uvs.append(self._reflection_uv(light, t_obj, t, refl))
            if np.all(z <= MIN_DEPTH_M):
                continue
            if np.any(z <= MIN_DEPTH_M):  # straddles the camera plane: project the part in front of it
                uv, _ = cam_mod.project(clip_near(pw, z, MIN_DEPTH_M), pose, self.K)
            uvs.append(uv)
        if not uvs or not any(len(u) for u in uvs):
            return None
        uv = np.concatenate(uvs)
        return uv.min(0), uv.max(0)


def clip_near(points: np.ndarray, z: np.ndarray, near: float) -> np.ndarray:
    """The part of a convex planar polygon in front of the plane ``z = near`` (m), as points whose convex hull it
    is: its corners with z > near and the points where the segment between any corner in front and any corner
    behind crosses the plane (the crossings of its edges among them; the others lie inside it).

    points: (P, 3) world corners (any order), m; z: (P,) their depths along the optical axis, m (at least one
    > near). Returns (Q, 3) world points, m. A lamp that straddles the camera plane (a streetlight overhead, a
    car alongside) is bounded by what of it the camera can see, instead of the whole image (which made its
    light_spp refinement tile full-frame: lfmbench-v1 test scenes 32, 35 and 37 took 82-98 s each, now 31-45 s).
    """
    front = z > near
    pf, pb = points[front], points[~front]
    zf, zb = z[front][:, None], z[~front][None, :]
    s = (zf - near) / (zf - zb)  # (F, B) in (0, 1]: zf > near >= zb
    cross = pf[:, None, :] + s[..., None] * (pb[None, :, :] - pf[:, None, :])
    return np.concatenate([pf, cross.reshape(-1, 3)])


def _on_from_version_2(mode: str, on: str, scene: dict) -> bool:
    """An ``auto`` option's rule: ``mode`` is ``on``, or ``auto`` on scene version 2 and later (version 1's renders
    are frozen)."""
    return mode == on or (mode == "auto" and int(scene.get("version", 1)) >= 2)


def spectral_lamp_passes(scene: dict, opts: RenderOptions) -> bool:
    """Whether flickering lamps share their samples among band passes by spectrum (``opts.lamp_pass_spp``;
    ``auto``: scene version 2 and later)."""
    return _on_from_version_2(opts.lamp_pass_spp, "spectrum", scene)


def sobol_pixel_samples(scene: dict, opts: RenderOptions) -> bool:
    """Whether the tiles place their samples by Sobol' points (``opts.pixel_samples``; ``auto``: scene version 2
    and later)."""
    return _on_from_version_2(opts.pixel_samples, "sobol", scene)


def pad_at_spp(scene: dict, opts: RenderOptions) -> bool:
    """Whether a lamp's ``pad_px`` ring is traced at ``spp`` rather than ``light_spp`` (``opts.pad_samples``;
    ``auto``: scene version 2 and later)."""
    return _on_from_version_2(opts.pad_samples, "spp", scene)


def static_denoised(scene: dict, opts: RenderOptions) -> bool:
    """Whether the static groups' full frames are denoised (``opts.static_denoise``; ``auto``: scene version 2 and
    later)."""
    return _on_from_version_2(opts.static_denoise, "oidn", scene)


def static_split(scene: dict, opts: RenderOptions) -> str:
    """How the denoised static frames are split among the groups (``opts.static_split``; ``auto``: ``oidn`` on a scene
    of version 2 and later with a glossy road, :func:`render_tools.reflections.wet_road`, where the static lamps'
    reflections are sparse samples; else ``box``, as before)."""
    if opts.static_split == "auto":
        return "oidn" if int(scene.get("version", 1)) >= 2 and reflections.wet_road(scene) is not None else "box"
    return opts.static_split


def glossy_choice(mi, dr, scene: dict, opts: RenderOptions, cache: dict) -> dict | None:
    """The ``gloss`` table of :class:`render_tools.tracer.Tracer` (``opts.glossy_light_choice``; ``auto``: ``lobe`` on
    scene version 2 and later): None for ``plain``. ``cache``: the frame's :func:`render_tools.mitsuba_scene.
    mitsuba_dict` cache (its loaded BSDFs)."""
    if not _on_from_version_2(opts.glossy_light_choice, "lobe", scene):
        return None
    from . import tracer  # noqa: PLC0415

    return tracer.glossy_choice_table(mi, dr, cache["bsdfs"], scene["materials"]) or None


def reflections_denoised(scene: dict, opts: RenderOptions) -> bool:
    """Whether the flickering lamps' steady reflections are denoised, light by light (``opts.reflection_denoise``;
    ``auto``: scene version 2 and later)."""
    return _on_from_version_2(opts.reflection_denoise, "oidn", scene)


def texture_filter(scene: dict, opts: RenderOptions) -> str:
    """Mitsuba's ``filter_type`` of the scene's texture bitmaps (``opts.texture_filter``; ``auto``: ``nearest`` on
    scene version 2 and later, ``bilinear`` on version 1). Scenes without textures (every lfmbench-v1 scene) render
    the same whatever it is."""
    return "nearest" if _on_from_version_2(opts.texture_filter, "nearest", scene) else "bilinear"


def refine_pad(scene: dict, opts: RenderOptions) -> int | None:
    """The padding (px) of the box a static group's lamp is refined in (``light_bbox`` ``pad``): 0 (its own box, the
    pad ring keeping the full frame's estimate) when the ring is traced at spp (:func:`pad_at_spp`), else None
    (``opts.pad_px``)."""
    return 0 if pad_at_spp(scene, opts) else None


def static_lamp_boxes(scene: dict, opts: RenderOptions, n: int, geo: SceneGeometry | None = None,
                      window: tuple | None = None, t_obj: float | None = None) -> list[tuple]:
    """Boxes (y0, x0, y1, x1) px of the static groups' lamps in frame ``n``, over the short and the long window (or
    over ``window`` (a, b) s, absolute: a time bin, objects at ``t_obj`` s), as :func:`plan_frame`
    (:func:`plan_static_bins`) refines them: what :func:`render_tools.denoise.denoise_static` keeps as traced."""
    geo = geo or SceneGeometry(scene, opts)
    tm = frame_timing(scene, opts, n)
    if t_obj is None:
        t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    rpad = refine_pad(scene, opts)
    boxes = []
    for g, info in _selected_groups(scene, opts).items():
        if info["flicker"]:
            continue
        for lt in scene["lights"]:
            if lt["group"] == g:
                for a, b in ((tm["short"], tm["long"]) if window is None else (window,)):
                    bb = geo.light_bbox(lt, t_obj, a, b, pad=rpad)
                    if bb is not None:
                        boxes.append(tuple(int(v) for v in bb))
    return sorted(set(boxes))


def ring_boxes(outer: tuple, inner: tuple | None) -> list[tuple]:
    """The boxes (y0, x0, y1, x1), half-open, that cover ``outer`` less ``inner`` (a box inside it, or None:
    nothing): top and bottom rows full width, left and right between them; empty ones left out. Disjoint."""
    if inner is None:
        return [tuple(outer)]
    oy0, ox0, oy1, ox1 = outer
    iy0, ix0, iy1, ix1 = inner
    boxes = [(oy0, ox0, iy0, ox1), (iy1, ox0, oy1, ox1), (iy0, ox0, iy1, ix0), (iy0, ix1, iy1, ox1)]
    return [b for b in boxes if b[2] > b[0] and b[3] > b[1]]


def _inside(box: tuple | None, outer: tuple) -> tuple | None:
    """``box`` clipped to ``outer`` (both (y0, x0, y1, x1)); None when nothing is left."""
    if box is None:
        return None
    b = (max(box[0], outer[0]), max(box[1], outer[1]), min(box[2], outer[2]), min(box[3], outer[3]))
    return b if b[2] > b[0] and b[3] > b[1] else None


#: Band means of lamp spectra (:func:`light_bands`): key -> read-only (C,) array; at most :data:`_BANDS_KEPT` kept.
_BANDS: dict = {}
_BANDS_KEPT = 4096


def light_bands(light: dict, opts: RenderOptions) -> np.ndarray:
    """(C,) W sr^-1 m^-2 nm^-1, read-only: :func:`render_tools.spectra.band_means` of the light's
    :func:`render_tools.mitsuba_scene.light_spectrum` in ``opts``' bands, computed once per spectrum, luminance and
    bands (a 0.05 nm interpolation, 5 ms: :func:`lamp_pass_spp` and :func:`exact_face` asked for each lamp's in
    every frame, 1 CPU s per wet generator-2 night at 640x360). Keyed by the spectrum's canonical JSON, so an
    equal light gets the same array."""
    import json  # noqa: PLC0415

    from . import spectra  # noqa: PLC0415

    key = (json.dumps(light["spectrum"], sort_keys=True, default=repr), repr(light["luminance_cd_m2"]),
           tuple(float(b) for b in opts.bands_nm), float(opts.band_width_nm))
    out = _BANDS.get(key)
    if out is None:
        out = np.asarray(spectra.band_means(ms.light_spectrum(light), opts.bands_nm, opts.band_width_nm))
        out.flags.writeable = False
        if len(_BANDS) >= _BANDS_KEPT:
            _BANDS.clear()
        _BANDS[key] = out
    return out


def lamp_pass_spp(light: dict, opts: RenderOptions, light_spp: int | None = None) -> tuple | None:
    """Samples per pixel and bin of each band pass (P counts, powers of two) for ``light``'s own crop: its
    light_spp x P samples shared in proportion to the light's spectral radiance in each pass's bands (the sum
    over bands c = p, p + P, ... of its band means), rounded to powers of two (the strata of
    :meth:`render_tools.tracer.Tracer._pixel` need them), at least light_spp / 8 (every band keeps samples: each
    stays an unbiased mean of its own pass) and at most 4 x light_spp, never more than light_spp x P in all; then
    passes are doubled while the budget allows, the one with the largest share^2 / count first (Neyman
    allocation of a sum whose terms have the same relative noise). None where light_spp is not a power of two
    (its samples are not stratified) or the light emits nothing.

    Why: a narrow-band LED's light lies in 2-4 of the 8 passes; with light_spp in each, the passes that carry it
    got a quarter of the lamp's samples. Measured on a night scene (docs/benchmarks/render.md, "LED dot faces"):
    the LED bins' error 4.5 % -> 3.2 % for the same or fewer samples. ``light_spp``: the lamp's own count
    (:func:`lamp_light_spp`; default ``opts.light_spp``)."""
    n0 = light_spp or opts.light_spp or opts.spp
    if n0 & (n0 - 1):
        return None
    P = cam_mod.n_passes(len(opts.bands_nm))
    bands = light_bands(light, opts)
    share = np.array([bands[p::P].sum() for p in range(P)], dtype=np.float64)
    if not share.sum() > 0:
        return None
    share /= share.sum()
    budget, floor, cap = n0 * P, max(1, n0 // 8), 4 * n0
    n = np.clip(2.0 ** np.round(np.log2(np.maximum(share * budget, 1e-12))), floor, cap).astype(np.int64)
    while n.sum() > budget:  # halve where a sample is worth least
        n[int(np.argmax(np.where(n > floor, n / np.maximum(share, 1e-300), -1.0)))] //= 2
    while True:  # double where it is worth most, while the budget allows
        gain = np.where((n < cap) & (n.sum() + n <= budget), share ** 2 / n, -1.0)
        if gain.max() <= 0:
            break
        n[int(np.argmax(gain))] *= 2
    return tuple(int(v) for v in n)


def lamp_light_spp(light: dict, opts: RenderOptions, filled: frozenset | set = frozenset(),
                   dense: frozenset | set = frozenset()) -> int:
    """Samples per pixel, bin and band pass of a flickering light's own box: ``light_spp`` (else ``spp``), times
    ``opts.filled_spp_factor`` for the lights drawn as filled cells (ids ``filled``, from :func:`dots_lod`) and
    ``opts.dots_spp_factor`` for those whose sub-pixel dots are drawn as they are (ids ``dense``, from
    :func:`dense_dots`)."""
    n = opts.light_spp or opts.spp
    if light["id"] in filled:
        return n * opts.filled_spp_factor
    return n * opts.dots_spp_factor if light["id"] in dense else n


def dots_pitches(scene: dict, opts: RenderOptions) -> dict:
    """Light id -> the largest dot pitch (px) of each ``dots`` light over every frame's capture window
    (:meth:`SceneGeometry.dots_pitch_px`, sampled at :data:`BBOX_TIME_SAMPLES` times): what :func:`_subpixel_dots`
    compares with its threshold, computed once for the thresholds of one render (:func:`drawn_geometry`)."""
    if not any(lt["shape"] == "dots" for lt in scene["lights"]):
        return {}
    geo = SceneGeometry(scene, opts)
    times = np.concatenate([np.linspace(*frame_timing(scene, opts, n)["window"], BBOX_TIME_SAMPLES)
                            for n in range(opts.frames)])
    return {lt["id"]: geo.dots_pitch_px(lt, times) for lt in scene["lights"] if lt["shape"] == "dots"}


def _subpixel_dots(scene: dict, opts: RenderOptions, px: float, pitches: dict | None = None) -> list[int]:
    """Ids of the ``dots`` lights whose dot pitch stays under ``px`` px over every frame's capture window
    (:func:`dots_pitches`; ``pitches``: its result for this scene and options, else computed); [] when ``px`` is
    0."""
    if not px or not any(lt["shape"] == "dots" for lt in scene["lights"]):
        return []
    pitches = dots_pitches(scene, opts) if pitches is None else pitches
    return [lt["id"] for lt in scene["lights"] if lt["shape"] == "dots" and pitches[lt["id"]] < px]


def exact_coverage(scene: dict, opts: RenderOptions) -> bool:
    """Whether the small flickering dot and rect faces are made by their exact coverage (``opts.dots_coverage``;
    ``auto``: scene version 2 and later)."""
    return _on_from_version_2(opts.dots_coverage, "exact", scene)


def exact_faces(scene: dict, opts: RenderOptions, pitches: dict | None = None) -> list[int]:
    """Ids of the lights whose own box is made by :func:`exact_face` (``opts.dots_coverage`` ``exact``): a face
    without a beam (``spread_deg`` 90) in a flickering group, either ``dots`` whose dot pitch stays under
    :data:`EXACT_DOTS_PX` over every frame (:func:`_subpixel_dots`) or a ``rect`` whose sides stay under
    :data:`EXACT_RECT_PX` (a countdown's segments; its visibility parts then under a quarter of a pixel); []
    otherwise. Larger dots (tail and brake lamps near the camera,
    1.2 % LED-bin error traced at light_spp 32) are left to the tracer, which also draws the light a face throws
    on what is next to it inside its box (a tail lamp's on its bumper: 2.3 % of its box's light at dusk).
    ``pitches``: :func:`dots_pitches` of this scene and options (None: computed)."""
    if not exact_coverage(scene, opts):
        return []
    flick = {g for g, info in scene_groups(scene).items() if info["flicker"]}
    sub = set(_subpixel_dots(scene, opts, EXACT_DOTS_PX, pitches))
    rects = [lt for lt in scene["lights"] if lt["shape"] == "rect" and lt["group"] in flick]
    if rects:
        geo = SceneGeometry(scene, opts)
        times = np.concatenate([np.linspace(*frame_timing(scene, opts, n)["window"], BBOX_TIME_SAMPLES)
                                for n in range(opts.frames)])
        sub |= {lt["id"] for lt in rects if geo.dots_pitch_px(_as_dots(lt), times) < EXACT_RECT_PX}
    return [lt["id"] for lt in scene["lights"] if lt["id"] in sub and lt["group"] in flick
            and float(lt["spread_deg"]) >= 90.0]


def _as_dots(light: dict) -> dict:
    """A ``rect`` light as the ``dots`` face of one dot filling its one cell (the same rectangle); other shapes
    as they are."""
    if light["shape"] != "rect":
        return light
    return {**light, "shape": "dots", "grid": [1, 1], "dot": 1.0, "cells": [[0, 0]]}


def exact_face(scene: dict, light: dict, opts: RenderOptions, geo: "SceneGeometry", edges, crop, mi=None,
               loaded=None, t_obj: float = 0.0) -> np.ndarray:
    """The (K, C, h, w) float32 bins (W sr^-1 m^-2 nm^-1) of a ``dots`` (or ``rect``: one dot) light's face over ``crop`` (y0, x0, y1, x1)
    px in the K bins between ``edges`` (K + 1,) s: its band radiance (:func:`render_tools.spectra.band_means` of
    :func:`render_tools.mitsuba_scene.light_spectrum`, what the tracer's band samples average to) times the share
    of each pixel its lit dots cover (:func:`render_tools.dot_coverage.dots_coverage`), what the tracer's camera
    samples estimate for a face alone in its light set. ``loaded``: the frame's Mitsuba scene (objects at
    ``t_obj`` s; ``mi`` the module), whose surfaces hide dots (:func:`render_tools.dot_coverage.ray_visibility`);
    None: nothing in front of the face."""
    from . import dot_coverage  # noqa: PLC0415

    vis = None
    if loaded is not None:
        vel = geo.object_velocity(light)
        vis = dot_coverage.ray_visibility(mi, loaded, lambda t: np.outer(np.asarray(t) - t_obj, vel))
    cov = dot_coverage.dots_coverage(scene, _as_dots(light), geo.K, geo.pose_cv, crop, edges, vis)
    L = light_bands(light, opts)
    return (cov[:, None] * L[None, :, None, None]).astype(np.float32)


def dense_dots(scene: dict, opts: RenderOptions, filled=(), exact=None, pitches: dict | None = None) -> list[int]:
    """Ids of the lights whose sub-pixel dots are drawn as they are (:data:`DOTS_SPP_PX`, not among ``filled``,
    the ids :func:`dots_lod` drew as filled cells), whose own boxes get ``opts.dots_spp_factor`` times light_spp
    (:func:`lamp_light_spp`); [] when that factor is 1 (nothing to find). ``exact``, ``pitches``:
    :func:`exact_faces` and :func:`dots_pitches` of this scene and options (None: computed)."""
    if opts.dots_spp_factor == 1:
        return []
    skip = set(filled) | set(exact_faces(scene, opts, pitches) if exact is None else exact)
    return [i for i in _subpixel_dots(scene, opts, DOTS_SPP_PX, pitches) if i not in skip]


def dots_lod(scene: dict, opts: RenderOptions, exact=None, pitches: dict | None = None) -> tuple[dict, list[int]]:
    """The scene as the renderer draws it with ``opts``: each ``dots`` light whose dot pitch stays under
    ``opts.dots_lod_px`` px over every frame's capture window (:meth:`SceneGeometry.dots_pitch_px`, sampled at
    :data:`BBOX_TIME_SAMPLES` times) replaced by :func:`render_tools.led_matrix.filled_cells` (same id, group,
    waveform and driver). Returns (scene, ids of the lights replaced); ``scene`` itself (not a copy) when none
    is. One decision per light for the whole sequence, so a light never switches form between frames.
    ``exact``, ``pitches``: :func:`exact_faces` and :func:`dots_pitches` of this scene and options (None:
    computed)."""
    from . import led_matrix  # noqa: PLC0415

    # drawn by their exact coverage: no stand-in
    exact = set(exact_faces(scene, opts, pitches) if exact is None else exact)
    ids = [i for i in _subpixel_dots(scene, opts, opts.dots_lod_px, pitches) if i not in exact]
    if not ids:
        return scene, []
    out = dict(scene)
    out["lights"] = [led_matrix.filled_cells(lt) if lt["id"] in ids else lt for lt in scene["lights"]]
    return out, ids


#: The last scene's drawn form and screen geometry (:func:`drawn_faces`): ``[key, (drawn, lod ids, geometry),
#: exact ids]``.
_DRAWN: list = []


def drawn_geometry(scene: dict, opts: RenderOptions) -> tuple[dict, list[int], SceneGeometry]:
    """:func:`dots_lod` of ``scene`` and the :class:`SceneGeometry` of the scene it returns, made once for a scene
    and options: :func:`scene_meta` and :func:`render_frames` of one render ask for the same (on a wet generator-2
    night the lamps' boxes, their reflections' extents and the dot faces' pitches cost 1.4 CPU s per scene, 0.3 s on
    its generator-1 night: measured 2026-11-28). The last scene's are kept (one scene's arrays), keyed by the
    scene's content (canonical JSON, 20 ms for a generator-2 scene) and the options, so an equal scene gets the
    same results and a changed one new ones; the geometry's caches are functions of their arguments."""
    return drawn_faces(scene, opts)[:3]


def drawn_faces(scene: dict, opts: RenderOptions) -> tuple[dict, list[int], SceneGeometry, list[int]]:
    """:func:`drawn_geometry` and :func:`exact_faces` of ``scene`` (the same ids for the drawn scene: a filled
    stand-in keeps its grid, size, group and beam), kept with it: one render computed the exact faces three times
    before (dots_lod, scene_meta, render_frames; and the dot pitches behind them four times, 0.3 CPU s each on a
    wet generator-2 night at 640x360), now once, with the pitches shared by both thresholds (:func:`dots_pitches`).
    Returns (drawn scene, lod ids, geometry, exact ids); do not modify them."""
    import json  # noqa: PLC0415

    try:
        key = (json.dumps(scene, sort_keys=True, default=lambda o: o.tolist() if hasattr(o, "tolist") else repr(o)),
               repr(opts))
    except (TypeError, ValueError):  # not JSON-like (keys of mixed types): computed anew, not kept
        key = None
    if key is not None and _DRAWN and _DRAWN[0] == key:
        return (*_DRAWN[1], _DRAWN[2])
    pitches = dots_pitches(scene, opts) if opts.dots_lod_px or exact_coverage(scene, opts) else {}
    exact = exact_faces(scene, opts, pitches)
    drawn, ids = dots_lod(scene, opts, exact, pitches)
    out = (drawn, ids, SceneGeometry(drawn, opts))
    _DRAWN[:] = [key, out, exact] if key is not None else []
    return (*out, exact)


def _round_span(a: int, b: int, n: int) -> tuple[int, int]:
    """Grow [a, b) to a multiple of :data:`CROP_QUANTUM_PX`, kept inside [0, n)."""
    a, b = max(a, 0), min(b, n)
    size = min(-(-(b - a) // CROP_QUANTUM_PX) * CROP_QUANTUM_PX, n)
    a = max(0, min(a - (size - (b - a)) // 2, n - size))
    return a, a + size


def _selected_groups(scene: dict, opts: RenderOptions) -> dict:
    have = scene_groups(scene)
    if opts.groups is None:
        return have
    return {g: have[g] for g in opts.groups if g in have}


def static_union(groups: dict, opts: RenderOptions) -> list[str]:
    """The static groups traced together (``opts.static_pass == "union"``, two or more static groups selected:
    ``groups`` as :func:`_selected_groups`), in scene order; ``[]`` otherwise (each traced on its own)."""
    static = [g for g, info in groups.items() if not info["flicker"]]
    return static if opts.static_pass == "union" and len(static) >= 2 else []


def scene_meta(scene: dict, opts: RenderOptions) -> dict:
    """The ``meta.json`` content of a scene rendered with ``opts`` (see module docstring and the contract).

    Pure geometry and timing: no rendering, no Mitsuba needed.
    """
    validate_scene(scene)
    opts.validate()
    drawn, lod_ids, helper, exact = drawn_faces(scene, opts)  # crops as render_frames draws the lights
    ego = cam_mod.EgoMotion.from_scene(scene)
    fov = float(scene["camera"]["fov_x_deg"])
    K = cam_mod.intrinsics(opts.width, opts.height, fov)
    groups = _selected_groups(scene, opts)
    timings = [frame_timing(scene, opts, n) for n in range(opts.frames)]
    static_edges = static_bin_edges(scene, opts)
    lights = []
    for lt, lt_drawn in zip(scene["lights"], drawn["lights"]):
        if lt["group"] not in groups:
            continue
        bbs = []
        for tm in timings:
            bb = helper.light_bbox(lt_drawn, 0.5 * (tm["window"][0] + tm["window"][1]), *tm["window"],
                                   moving=groups[lt["group"]]["flicker"])  # as render_frames crops it
            bbs.append(None if bb is None else list(bb))
        lights.append({"id": lt["id"], "group": lt["group"], "kind": lt["kind"], "instance": lt["instance"],
                       "luminance_cd_m2": lt["luminance_cd_m2"], "spectrum": lt["spectrum"], "bbox": bbs})
        # timing of scene version 2 (lfmbench.flicker.waveforms; lights of one driver share a PWM draw)
        lights[-1].update({k: copy.deepcopy(lt[k]) for k in ("waveform", "driver") if k in lt})
    return {
        "scene_id": scene["scene_id"], "width": opts.width, "height": opts.height,
        "bands_nm": list(opts.bands_nm), "band_width_nm": opts.band_width_nm, "fps": opts.fps,
        "frames": opts.frames,
        "timing": {"short_exposure_s": float(scene["timing"]["short_exposure_s"]),
                   "long_exposure_s": opts.long_exposure_s, "alignment": "center", "line_time_s": opts.line_time_s,
                   "readout_s": opts.readout_s, "capture_window_s": opts.capture_window_s, "bins": opts.bins,
                   **({} if static_edges is None else {"static_edges_s": [float(e) for e in static_edges]})},
        "camera": {"fov_x_deg": fov, "K": K.tolist(), "convention": "opencv (x right, y down, z forward); "
                   "world ISO 8855 (x forward, y left, z up), m",
                   "poses": [[ego.pose_cv(tm["window"][0]).tolist(), ego.pose_cv(tm["window"][1]).tolist()]
                             for tm in timings],
                   "speed_mps": ego.speed_mps, "yaw_rate_rad_s": ego.yaw_rate_rad_s},
        "groups": groups,
        "lights": lights,
        "render": {"spp": opts.spp, "light_spp": opts.light_spp or opts.spp, "seed": opts.seed,
                   "pad_px": opts.pad_px, "static_pass": opts.static_pass,
                   **({"static_bin_samples": "common"} if static_edges is not None
                      and opts.static_bin_samples == "common" else {}),
                   **({"reflection_bins": opts.reflection_bins or opts.bins,
                       "reflection_min_lux": opts.reflection_min_lux,
                       "reflection_block_px": opts.reflection_block_px} if helper.wet else {}),
                   **({"dots_coverage": "exact", "dots_exact": list(exact)}
                      if exact_coverage(scene, opts) else {}),
                   **({"dots_lod_px": opts.dots_lod_px, "dots_lod": lod_ids,
                       "filled_spp_factor": opts.filled_spp_factor,
                       **({"dots_spp_factor": opts.dots_spp_factor, "dots_spp": dense_dots(scene, opts, lod_ids, exact)}
                          if opts.dots_spp_factor != 1 else {})}
                      if any(lt["shape"] == "dots" for lt in scene["lights"]) else {}),
                   **({"lamp_pass_spp": "spectrum" if spectral_lamp_passes(scene, opts) else "uniform",
                       "pixel_samples": "sobol" if sobol_pixel_samples(scene, opts) else "strata",
                       "pad_samples": "spp" if pad_at_spp(scene, opts) else "light",
                       "static_denoise": "oidn" if static_denoised(scene, opts) else "off",
                       **({"glossy_light_choice": "lobe" if _on_from_version_2(opts.glossy_light_choice, "lobe", scene)
                           else "plain"} if helper.wet else {}),
                       **({"static_split": static_split(scene, opts)} if static_denoised(scene, opts) else {}),
                       "texture_filter": texture_filter(scene, opts),
                       **({"reflection_denoise": "oidn" if reflections_denoised(scene, opts) else "off",
                           "reflection_edges": "clip" if helper.clip_edges else "drop"}
                          if helper.wet else {})}
                      if int(scene.get("version", 1)) >= 2 else {})},
    }


def _lookup(keys: np.ndarray, table: dict) -> np.ndarray:
    """Map integer ``keys`` (H, W) through ``table`` (missing -> -1) -> float32 (H, W)."""
    uniq, inv = np.unique(keys, return_inverse=True)
    vals = np.array([table.get(int(k), -1) for k in uniq], dtype=np.float32)
    return vals[inv].reshape(keys.shape)


def _aux_maps(loaded, scene: dict, shape_ids: np.ndarray, pos: np.ndarray, c: np.ndarray, fwd: np.ndarray,
              visible_lights: set) -> dict:
    """AOVs from camera-ray hits: ``shape_ids`` (N, H, W) registry ids of the first hit (0 = none) of N jittered
    passes, ``pos`` (3, H, W) m hit points of pass 0, camera centre ``c`` (3,) m and forward axis ``fwd`` (3,).
    Returns depth.Z, depth.R (m, +inf = no hit), mask.instance and mask.light (float32 (H, W), -1 = none; a
    pixel belongs to a light if any pass hit its face)."""
    import drjit as dr  # noqa: PLC0415
    import mitsuba as mi  # noqa: PLC0415

    inst_of, light_of = {}, {}
    ids = np.array(dr.reinterpret_array(mi.UInt32, loaded.shapes_dr()), dtype=np.int64)
    for sid, sh in zip(ids.tolist(), loaded.shapes()):
        name = sh.id()
        if name.startswith("light"):
            lid = int(name[5:])
            inst_of[sid] = scene["lights"][lid]["instance"]
            if lid in visible_lights:
                light_of[sid] = lid
        elif name.startswith("o"):
            inst_of[sid] = int(name[1:].split("_")[0])
    hit = shape_ids[0] != 0
    p = np.moveaxis(pos, 0, -1).astype(np.float64)
    out = {"depth.Z": np.where(hit, (p - c) @ fwd, np.inf).astype(np.float32),
           "depth.R": np.where(hit, np.linalg.norm(p - c, axis=-1), np.inf).astype(np.float32),
           "mask.instance": _lookup(shape_ids[0], inst_of)}
    light_mask = np.full(shape_ids.shape[1:], -1.0, np.float32)
    for k in range(shape_ids.shape[0]):
        lm = _lookup(shape_ids[k], light_of)
        light_mask = np.where((light_mask < 0) & (lm >= 0), lm, light_mask)
    out["mask.light"] = light_mask
    return out


def rest_spp(spp: int, frac: float) -> int:
    """Samples per pixel of the rest of the long window (the long exposure without the short one inside it).

    The long-window estimate is ``frac * short + (1 - frac) * rest`` (``frac`` = T_S / T_L; exact: the long
    exposure's time average split over its two parts, stratified sampling in time). With ``spp`` samples in
    each part of per-sample variance s^2 its variance is (frac^2 / spp + (1 - frac)^2 / n_rest) s^2; the
    old estimate (``spp`` samples over the whole long window) had s^2 / spp. Equal variance needs
    n_rest = spp (1 - frac) / (1 + frac): about half of ``spp`` for T_S / T_L = 0.36 (4 ms of 11.1 ms).
    Rounded up, at least 1.
    """
    return max(1, math.ceil(spp * (1.0 - frac) / (1.0 + frac) - 1e-9))


def scene_moves(scene: dict) -> bool:
    """Whether anything in ``scene`` moves: the ego camera (speed or yaw rate) or an object (a velocity)."""
    if cam_mod.EgoMotion.from_scene(scene).moving:
        return True
    return any(np.any(np.asarray(o.get("velocity_mps", (0.0, 0.0, 0.0)), float) != 0.0) for o in scene["objects"])


def objects_move(scene: dict) -> bool:
    """Whether an object of ``scene`` has a velocity (its static-group renders then place it per time bin)."""
    return any(np.any(np.asarray(o.get("velocity_mps", (0.0, 0.0, 0.0)), float) != 0.0) for o in scene["objects"])


def static_bin_edges(scene: dict, opts: RenderOptions) -> np.ndarray | None:
    """Edges (B + 1,) s from the frame start of the static groups' time bins (:class:`RenderOptions`
    ``static_edges_s``), the same in every frame: the sorted union of the asked edges and 0, the short window's ends
    and T_L (edges closer than 1e-9 of the capture window merged), or None when none is asked or nothing moves
    (:func:`scene_moves`: every bin would be the same image)."""
    if not opts.static_edges_s or not scene_moves(scene):
        return None
    ts, tl = float(scene["timing"]["short_exposure_s"]), opts.long_exposure_s
    pts = sorted({0.0, (tl - ts) / 2.0, (tl + ts) / 2.0, tl, *opts.static_edges_s})
    tol = 1e-9 * opts.capture_window_s
    out = [pts[0]]
    for e in pts[1:]:
        if e - out[-1] > tol:
            out.append(e)
    return np.asarray(out, dtype=np.float64)


def bin_key(opts: RenderOptions, k: int) -> tuple:
    """What names static time bin ``k`` in its seed and tile keys: ``(k,)``, or ``()`` for every bin with
    ``static_bin_samples="common"`` (the same random numbers in every bin)."""
    return () if opts.static_bin_samples == "common" else (k,)


def plan_static_bins(scene: dict, opts: RenderOptions, n: int, sets, geo: SceneGeometry, bins, t_obj: float,
                     qmc: bool, start: int = 0):
    """The tiles of the static groups over time bins (:func:`static_bin_edges`) and how to assemble them (plan
    entries as :func:`plan_frame`, window ``"bin<k>"``): per bin a full frame at ``spp`` (one union tile, or one per
    group) and each static group's lamp refined in its box over the bin at ``light_spp``, the objects held at
    ``t_obj`` (s). ``bins``: [(k, a, b)] absolute times, s; ``start``: index of the first tile in the launch."""
    from .tracer import Tile  # noqa: PLC0415

    full = (0, 0, opts.height, opts.width)
    light_spp = opts.light_spp or opts.spp
    rpad = refine_pad(scene, opts)
    union = list(getattr(sets, "union", ()) or ())
    tiles, plan = [], []
    for k, a, b in bins:
        win = f"bin{k}"
        kwin = "bin" + "".join(str(x) for x in bin_key(opts, k))  # the window's name in the tile keys
        if union:
            plan.append(("union", tuple(union), win, full, start + len(tiles), 1))
            tiles.append(Tile(full, 1, a, b - a, opts.spp, sets["union:static"], slots=len(union),
                              key=_seed("union", kwin), sobol=qmc))
        for g, info in _selected_groups(scene, opts).items():
            if info["flicker"]:
                continue
            lamps = [lt for lt in scene["lights"] if lt["group"] == g]
            for kind, crop, n_s, key in [("static", full, opts.spp, None)] * (g not in union) + [
                    ("refine", geo.light_bbox(lt, t_obj, a, b, pad=rpad), light_spp, lt["id"])
                    for lt in (lamps if light_spp > opts.spp else ())]:
                if crop is None:
                    continue
                plan.append((kind, g, win, crop, start + len(tiles), 1))
                tiles.append(Tile(crop, 1, a, b - a, n_s, sets[f"group:{g}"],
                                  key=_seed(kind, g, kwin, *(() if key is None else (key,))), sobol=qmc))
    return tiles, plan


def plan_frame(scene: dict, opts: RenderOptions, n: int, sets, geo: SceneGeometry | None = None,
               filled: frozenset | set = frozenset(), static: bool = True, dense: frozenset | set = frozenset(),
               exact: frozenset | set = frozenset()):
    """The tiles of frame ``n`` (:class:`render_tools.tracer.Tile`) and how to assemble them.

    Static groups: two full-frame tiles, the short window at ``spp`` and the rest of the long window (long minus
    short, a time gap in the tile) at :func:`rest_spp`, plus, when ``light_spp > spp``, each of the group's lamps
    in its own crop at ``light_spp`` (pasted over the full-frame estimate: both are unbiased estimates of the
    same pixels, the crop one with less variance where the HDR peaks are); the long window is assembled as
    ``frac * short + (1 - frac) * rest`` (plan window ``"rest"``, ``frac`` = T_S / T_L). Flickering groups:
    each visible light alone in its crop, K bins over the capture window, at ``light_spp`` (one bin repeated K
    times when neither the camera nor the lamp moves); in a wet scene a crop grown by the light's reflection
    (plan kind ``"light_box"``: zeros, no tile) gets the reflection's row bands (:meth:`SceneGeometry.
    reflection_tiles`) traced at ``spp`` in ``opts.reflection_bins`` bins and the lamp's own box at ``light_spp``
    in K bins pasted over them (plan kind ``"light_part"``); with ``pad_samples`` at spp (scene version 2) a lamp's
    ``pad_px`` ring is such parts too, traced at ``spp`` in K bins (:func:`ring_boxes`), its own unpadded box at
    ``light_spp`` over them, and a static group's lamp refines its unpadded box. ``sets``: the frame's
    :class:`tracer.LightSets` (or any mapping from set name to index). ``filled``: ids of the lights :func:`dots_lod` drew as filled cells (their own
    boxes get :func:`lamp_light_spp`). ``dense``: ids of the lights whose sub-pixel dots are drawn as they
    are (:func:`dense_dots`; their boxes get :func:`lamp_light_spp` too). ``exact``: ids of the lights whose
    own box is made by :func:`exact_face` instead of a tile (:func:`exact_faces`; its plan entry's tile index is
    ``("exact", light id)``, all K bins, repeat 1). ``static``: False leaves the static groups' tiles out (they are traced in
    time bins, :func:`plan_static_bins`). Returns (tiles, plan, visible light ids); plan entries are
    (kind, group, window or light id, crop, tile index, repeat): a tile of K / repeat bins, each bin repeated
    ``repeat`` times in a row to make the K bins.
    """
    from .tracer import Tile  # noqa: PLC0415

    geo = geo or SceneGeometry(scene, opts)
    tm = frame_timing(scene, opts, n)
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])  # moving objects placed at mid capture window
    full = (0, 0, opts.height, opts.width)
    light_spp = opts.light_spp or opts.spp
    tiles, plan, visible = [], [], set()
    (sa, sb), (la, lb) = tm["short"], tm["long"]
    # the long window = the short one inside it + the rest: the long estimate reuses the short samples
    # (rest_spp: same variance as ``spp`` over the whole long window, at less cost; :func:`rest_spp`)
    wins = [("short", sa, sb - sa, math.inf, 0.0, 1.0)]
    if (lb - la) - (sb - sa) > 1e-12 * (lb - la):
        wins.append(("rest", la, (lb - la) - (sb - sa), sa, sb - sa, (sb - sa) / (lb - la)))
    qmc = sobol_pixel_samples(scene, opts)
    ring_spp = pad_at_spp(scene, opts)  # a lamp's pad ring at spp, its own box at light_spp
    rpad = refine_pad(scene, opts)  # a static group's lamp refines its own box, the ring keeps the full frame
    union = list(getattr(sets, "union", ()) or ())
    if not static:
        wins = []
    if union and static:  # the static groups' full frames: one tile per window records all of them (one image per slot)
        for win, t0, dt, gap_at, gap_len, frac in wins:
            plan.append(("union", tuple(union), win, full, len(tiles), 1))
            tiles.append(Tile(full, 1, t0, dt, opts.spp if win == "short" else rest_spp(opts.spp, frac),
                              sets["union:static"], gap_at=gap_at, gap_len=gap_len, slots=len(union),
                              key=_seed("union", "long" if win == "rest" else win), sobol=qmc))
    for g, info in _selected_groups(scene, opts).items():
        lamps = [lt for lt in scene["lights"] if lt["group"] == g]
        if not info["flicker"]:
            k = sets[f"group:{g}"]
            for win, t0, dt, gap_at, gap_len, frac in wins:
                for kind, crop, n_s, key in [("static", full, opts.spp, None)] * (g not in union) + [
                        ("refine", geo.light_bbox(lt, t_obj, la, lb, pad=rpad) if win == "rest" else
                         geo.light_bbox(lt, t_obj, sa, sb, pad=rpad), light_spp, lt["id"])
                        for lt in (lamps if light_spp > opts.spp else ())]:
                    if crop is None:
                        continue
                    plan.append((kind, g, win, crop, len(tiles), 1))
                    spp = n_s if win == "short" else rest_spp(n_s, frac)
                    tiles.append(Tile(crop, 1, t0, dt, spp, k, gap_at=gap_at, gap_len=gap_len,
                                      key=_seed(kind, g, "long" if win == "rest" else win,
                                                *(() if key is None else (key,))), sobol=qmc))
            visible |= {lt["id"] for lt in lamps if geo.light_bbox(lt, t_obj, *tm["window"]) is not None}
            continue
        edges = tm["bin_edges"]
        spectral = spectral_lamp_passes(scene, opts)
        for lt in lamps:
            v = geo.object_velocity(lt)
            bb = geo.light_bbox(lt, t_obj, *tm["window"], moving=True)
            if bb is None:
                continue
            own_spp = lamp_light_spp(lt, opts, filled, dense)
            ps = lamp_pass_spp(lt, opts, own_spp) if spectral else None  # the lamp's own box: samples by spectrum
            visible.add(lt["id"])
            k = sets[f"light:{lt['id']}"]
            # wet road: the box holds the lamp's reflection too; that dim, smooth light is traced at ``spp`` and
            # the lamp's own box again at ``light_spp`` over it (both unbiased: the "refine" of static groups)
            lamp_bb = geo.light_bbox(lt, t_obj, *tm["window"], moving=True, reflection=False) if geo.wet else bb
            # pad_samples "spp": the lamp's padded box = its own (unpadded) box at light_spp + the ring at spp
            inner = _inside(geo.light_bbox(lt, t_obj, *tm["window"], moving=True, reflection=False, pad=0),
                            lamp_bb) if ring_spp and lamp_bb is not None else lamp_bb
            if lamp_bb == bb and inner == lamp_bb:  # no reflection region, no ring: the lamp's box alone
                crops = [("light", bb, own_spp, opts.bins, ())]
            else:  # the grown box (zeros) holds the reflection's row bands at spp in opts.reflection_bins bins,
                # each repeated, the ring at spp in K bins and the lamp's own box at light_spp in K bins over them
                plan.append(("light_box", g, lt["id"], bb, None, opts.bins))
                kb = opts.reflection_bins or opts.bins
                crops = [("light_part", c, opts.spp, kb, ("reflection", c[0]))
                         for c in (geo.reflection_tiles(lt, t_obj, *tm["window"], bb) if lamp_bb != bb else ())]
                if lamp_bb is not None and inner != lamp_bb:
                    crops += [("light_part", c, opts.spp, opts.bins, ("ring", c[0], c[1]))
                              for c in ring_boxes(lamp_bb, inner)]
                if inner is not None:
                    crops.append(("light_part", inner, own_spp, opts.bins, ("lamp",)))
            for kind, crop, n_s, nb, extra in crops:
                if lt["id"] in exact and (kind == "light" or extra == ("lamp",)):  # no samples: exact_face
                    plan.append((kind, g, lt["id"], crop, ("exact", lt["id"]), 1))
                    continue
                key = _seed("light", lt["id"], *extra)
                refl = extra[:1] == ("reflection",)
                own, blk = (None, opts.reflection_block_px) if refl else ((None, 1) if extra[:1] == ("ring",) else
                                                                          (ps, 1))
                if geo.ego.moving or np.any(v != 0.0):
                    plan.append((kind, g, lt["id"], crop, len(tiles), opts.bins // nb))
                    tiles.append(Tile(crop, nb, edges[0], (edges[-1] - edges[0]) / nb, n_s, k,
                                      tuple(float(x) for x in v), t_obj, key=key, pass_spp=own, sobol=qmc,
                                      block=blk))
                else:  # static camera and lamp inside the frame: all bins are the same image
                    plan.append((kind, g, lt["id"], crop, len(tiles), opts.bins))
                    tiles.append(Tile(crop, 1, edges[0], edges[-1] - edges[0], n_s, k, key=key, pass_spp=own,
                                      sobol=qmc, block=blk))
    return tiles, plan, visible


def _grown_crop(steady: np.ndarray, parts: list, K: int, as_steady_bins: bool):
    """The (K, C, h, w) bins of a light's crop made of parts (a wet road's reflection, a lamp's pad ring): ``steady``
    (C, h, w) holds the parts that are the same in every bin (the reflection bands), ``parts`` the others as
    (y0, x0, y1, x1) relative box and (K, C, bh, bw) bins, pasted in order over it. ``as_steady_bins``: a
    :class:`lfmbench.corpus.SteadyBins` (the steady image and the bins over the box bounding the varying parts),
    else the array."""
    from lfmbench.corpus import SteadyBins  # noqa: PLC0415

    if as_steady_bins:
        if not parts:
            return SteadyBins(steady, (0, 0, 0, 0), np.zeros((K, steady.shape[0], 0, 0), np.float32))
        if len(parts) == 1:
            return SteadyBins(steady, *parts[0])
        y0, x0 = min(b[0] for b, _ in parts), min(b[1] for b, _ in parts)
        y1, x1 = max(b[2] for b, _ in parts), max(b[3] for b, _ in parts)
        bins = np.empty((K, steady.shape[0], y1 - y0, x1 - x0), np.float32)
        bins[:] = steady[:, y0:y1, x0:x1]
        for (a, b, c, d), v in parts:
            bins[:, :, a - y0:c - y0, b - x0:d - x0] = v
        return SteadyBins(steady, (y0, x0, y1, x1), bins)
    arr = np.empty((K, *steady.shape), np.float32)
    arr[:] = steady
    for (y0, x0, y1, x1), bins in parts:
        arr[:, :, y0:y1, x0:x1] = bins
    return arr


def _denoise_reflections(scene: dict, geo: SceneGeometry, tm: dict, lights: dict, grown: dict, traced: dict) -> None:
    """Denoise, light by light, the steady reflection of every grown crop (``RenderOptions.reflection_denoise``):
    :func:`render_tools.denoise.denoise_reflection` on the crop's steady (C, h, w) image with the lamp's padded box
    (the one :func:`plan_frame` plans, relative to the crop) kept out and as traced, the filter's mirrored margin on
    the crop's sides at the image's edge only (:func:`render_tools.denoise.crop_edges`); in place in ``grown``."""
    from . import denoise  # noqa: PLC0415

    by_id = {lt["id"]: lt for lt in scene["lights"]}
    t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
    for g, items in lights.items():
        for lid, bb, arr in items:
            if arr is not None or (g, lid) not in grown:
                continue
            y0, x0 = bb[0], bb[1]
            lamp_bb = geo.light_bbox(by_id[lid], t_obj, *tm["window"], moving=True, reflection=False)
            boxes = [] if lamp_bb is None else [(lamp_bb[0] - y0, lamp_bb[1] - x0, lamp_bb[2] - y0, lamp_bb[3] - x0)]
            grown[g, lid][0] = denoise.denoise_reflection(grown[g, lid][0], traced[g, lid], boxes,
                                                          edges=denoise.crop_edges(bb, (geo.opts.height,
                                                                                        geo.opts.width)))


def render_frames(scene: dict, opts: RenderOptions, steady_bins: bool = False) -> Iterator[dict]:
    """Render every frame of ``scene``; yields one dict per frame (see module docstring)::

        {"frame": n,
         "static": {group: {"short": (C, H, W) float32, "long": (C, H, W) float32,
                            "bins": (B, C, H, W) float32 (only with static time bins)}},
         "static_edges_s": [B + 1 edges, s from the frame start] (only with static time bins),
         "lights": {group: [(light_id, (y0, x0, y1, x1), (K, C, h, w) float32)]},
         "aux": {"depth.Z", "depth.R", "mask.instance", "mask.light": (H, W) float32}}

    Radiance in W sr^-1 m^-2 nm^-1, time-averaged over the window / bin; bboxes in px, end exclusive.
    Each frame: its Mitsuba scene is loaded once with every emitter on, and all of its tiles
    (:func:`plan_frame`) are rendered by :class:`render_tools.tracer.Tracer` in one kernel launch (more when
    it exceeds :data:`render_tools.tracer.MAX_LANES`), then the AOVs in a second, small one.
    Static time bins (:func:`static_bin_edges`, ``opts.static_edges_s``): each bin's full frame is traced over its
    own time with the ego camera moving continuously and the moving objects at the bin's middle (one scene load
    per bin when an object moves, else the bins join the frame's launch); ``short`` and ``long`` are then the exact
    length-weighted sums of their bins.
    ``steady_bins``: a wet road's grown light crops (the lamp's K bins over its reflection, the same in every bin)
    as :class:`lfmbench.corpus.SteadyBins` instead of (K, C, h, w) arrays (what the corpus writer takes: the same
    files without K copies of the reflection in memory).
    Raises ``ValueError`` for an invalid scene or options (e.g. short exposure longer than the long one),
    ``RuntimeError`` when no JIT variant (LLVM or CUDA) of Mitsuba works.
    """
    import gc  # noqa: PLC0415

    validate_scene(scene)
    opts.validate()
    timings = [frame_timing(scene, opts, n) for n in range(opts.frames)]  # validates exposures up front
    # sub-pixel LED dots as filled cells (RenderOptions.dots_lod_px), and where the lamps are on screen
    # (and the dot faces made by their exact coverage, dots_coverage: exact_faces, the same for the drawn scene)
    scene, filled, geo, exact = drawn_faces(scene, opts)
    filled = frozenset(filled)
    exact = frozenset(exact)
    dense = frozenset(dense_dots(scene, opts, filled, exact))  # sub-pixel dots drawn as they are (dots_spp_factor)
    by_id = {lt["id"]: lt for lt in scene["lights"]}
    groups = _selected_groups(scene, opts)
    from . import backend  # noqa: PLC0415

    # numpy-only scene geometry and lamp spectra first: on a first run this overlaps the back-end probe, a child
    # process that select_variant waits for (render_tools.backend.start_probes)
    mcache: dict = ms.prepare_geometry(scene, {})  # BSDFs, static meshes and lamp spectra: once per scene
    variant = backend.select_variant(opts.variant)
    if variant.startswith("scalar"):
        raise RuntimeError("variant: rendering needs a JIT variant of Mitsuba (llvm_ad_spectral or "
                           f"cuda_ad_spectral), got {variant}: {backend.llvm_hint()}")
    import drjit as dr  # noqa: PLC0415
    import mitsuba as mi  # noqa: PLC0415

    from . import tracer  # noqa: PLC0415

    edges = static_bin_edges(scene, opts)  # None: the two windows, as before RenderOptions.static_edges_s
    obj_moving = edges is not None and objects_move(scene)
    tex_filter = texture_filter(scene, opts)
    for n, tm in enumerate(timings):
        t_obj = 0.5 * (tm["window"][0] + tm["window"][1])
        loaded = mi.load_dict(ms.mitsuba_dict(scene, t_obj, emit="all", cache=mcache, unit_sky=True,
                                              texture_filter=tex_filter))
        if n == 0:  # scenes of a size class share kernels; the next frames' objects take this frame's ids
            pad = tracer.pad_registry(mi, dr, loaded, mcache["off_lens"])
        sets = tracer.LightSets(mi, dr, loaded, scene, list(groups), union=static_union(groups, opts))
        gloss = glossy_choice(mi, dr, scene, opts, mcache)
        tr = tracer.Tracer(mi, dr, loaded, sets, geo.ego, geo.fov, (opts.width, opts.height), opts.bands_nm,
                           opts.band_width_nm, sky_scale=ms.sky_scale(scene), gloss=gloss)
        tiles, plan, visible = plan_frame(scene, opts, n, sets, geo, filled, static=edges is None,
                                            dense=dense, exact=exact)
        qmc = sobol_pixel_samples(scene, opts)
        bins = [] if edges is None else [(k, tm["t0"] + a, tm["t0"] + b) for k, (a, b) in
                                         enumerate(zip(edges[:-1], edges[1:]))]
        if bins and not obj_moving:  # only the camera moves: the bins are tiles of the frame's launch
            bt, bp = plan_static_bins(scene, opts, n, sets, geo, bins, t_obj, qmc, start=len(tiles))
            tiles, plan = tiles + bt, plan + bp
        imgs = tr.render(tiles, _seed(opts.seed, n, "frame")) if tiles else []
        if bins and obj_moving:  # moving objects: each bin traced with them at its middle
            # the frame's scene with only the moving meshes and beams moved (mitsuba_scene.place_moving); a scene
            # load per bin where a mesh's size changes with time
            params, moved = mi.traverse(loaded), False
            for k, a, b in bins:
                t_bin = 0.5 * (a + b)
                if ms.place_moving(params, scene, t_bin, mcache):
                    lb, moved = loaded, True
                else:
                    lb = mi.load_dict(ms.mitsuba_dict(scene, t_bin, emit="all", cache=mcache, unit_sky=True,
                                                      texture_filter=tex_filter))
                sb = tracer.LightSets(mi, dr, lb, scene, list(groups), union=static_union(groups, opts))
                trb = tracer.Tracer(mi, dr, lb, sb, geo.ego, geo.fov, (opts.width, opts.height), opts.bands_nm,
                                    opts.band_width_nm, sky_scale=ms.sky_scale(scene), gloss=gloss)
                bt, bp = plan_static_bins(scene, opts, n, sb, geo, [(k, a, b)], t_bin, qmc, start=len(imgs))
                imgs = list(imgs) + list(trb.render(bt, _seed(opts.seed, n, "bin", *bin_key(opts, k))) if bt else [])
                plan = plan + bp
                del trb, sb, lb
            if moved and not ms.place_moving(params, scene, t_obj, mcache):  # back to the frame's time (AOVs)
                raise RuntimeError("place_moving: a moving mesh changed size between the bins and the frame time")
            del params
        out = {"frame": n, "static": {}, "lights": {}, "aux": {}}
        grown = {}  # (group, light id) -> [steady (C, h, w), varying parts, K] of a grown crop
        traced = {}  # (group, light id) -> (h, w) bool: the pixels of a grown crop's steady image that were traced
        for kind, g, key, bb, ti, rep in plan:
            if kind == "light_box":  # a grown crop: zeros where no band of its reflection is traced
                y0, x0, y1, x1 = bb
                grown[g, key] = [np.zeros((len(opts.bands_nm), y1 - y0, x1 - x0), np.float32), [], rep]
                traced[g, key] = np.zeros((y1 - y0, x1 - x0), bool)
                out["lights"].setdefault(g, []).append((key, bb, None))  # filled in below
                continue
            if kind == "union":  # one image per static group (slot), in the union's order
                for j, gj in enumerate(g):
                    out["static"].setdefault(gj, {})[key] = backend.clamp_roundoff(
                        imgs[ti][j], name=f"frame {n} {gj} static {key}")[0]
                continue
            img = exact_face(scene, by_id[ti[1]], opts, geo, tm["bin_edges"], bb, mi, loaded, t_obj) \
                if isinstance(ti, tuple) else backend.clamp_roundoff(imgs[ti], name=f"frame {n} {g} {kind} {key}")
            if kind == "static":
                out["static"].setdefault(g, {})[key] = img[0]
            elif kind == "refine":
                y0, x0, y1, x1 = bb
                out["static"][g][key][:, y0:y1, x0:x1] = img[0]
            elif kind == "light_part":  # a reflection band or the lamp's own box inside its grown crop
                lid, (by0, bx0, _, _), _ = out["lights"][g][-1]
                steady, parts, _ = grown[g, lid]
                y0, x0, y1, x1 = bb
                rel = (y0 - by0, x0 - bx0, y1 - by0, x1 - bx0)
                if len(img) == 1 and not parts:  # the same in every bin, under no varying part yet
                    steady[:, rel[0]:rel[2], rel[1]:rel[3]] = img[0]
                    traced[g, lid][rel[0]:rel[2], rel[1]:rel[3]] = True
                else:
                    parts.append((rel, np.repeat(img, rep, axis=0) if rep > 1 else img))
            else:
                out["lights"].setdefault(g, []).append((key, bb, np.repeat(img, rep, axis=0) if rep > 1 else img))
        if grown and geo.wet and reflections_denoised(scene, opts):  # each light's steady reflection alone
            _denoise_reflections(scene, geo, tm, out["lights"], grown, traced)
        for g, items in out["lights"].items():
            for i, (lid, bb, arr) in enumerate(items):
                if arr is None:
                    items[i] = (lid, bb, _grown_crop(*grown[g, lid], steady_bins))
        if bins:  # the static groups in time bins: denoised bin by bin, short and long their exact sums
            if out["static"] and static_denoised(scene, opts):
                from . import denoise  # noqa: PLC0415

                for k, a, b in bins:
                    boxes = static_lamp_boxes(scene, opts, n, geo, window=(a, b),
                                              t_obj=0.5 * (a + b) if obj_moving else t_obj)
                    done = denoise.denoise_static({g: w[f"bin{k}"] for g, w in out["static"].items()}, boxes,
                                                  split=static_split(scene, opts))
                    for g, img in done.items():
                        out["static"][g][f"bin{k}"] = img
            for g, wins in out["static"].items():
                stack = np.stack([wins.pop(f"bin{k}") for k, _a, _b in bins])           # (B, C, H, W)
                wins["bins"] = stack
                for name in ("short", "long"):
                    a, b = tm[name]
                    wgt = window_bin_weights(edges, a - tm["t0"], b - a)
                    wins[name] = np.tensordot(wgt, stack.astype(np.float64), axes=1).astype(np.float32)
            out["static_edges_s"] = [float(e) for e in edges]
        else:
            frac = (tm["short"][1] - tm["short"][0]) / (tm["long"][1] - tm["long"][0])
            for g, wins in out["static"].items():  # long = frac * short + (1 - frac) * rest (:func:`rest_spp`)
                rest = wins.pop("rest", None)
                wins["long"] = wins["short"].copy() if rest is None else \
                    (frac * wins["short"] + (1.0 - frac) * rest).astype(np.float32)
        if out["static"] and static_denoised(scene, opts) and not bins:  # render_tools.denoise; lamp boxes as traced
            from . import denoise  # noqa: PLC0415

            boxes = static_lamp_boxes(scene, opts, n, geo)
            for win in ("short", "long"):
                done = denoise.denoise_static({g: w[win] for g, w in out["static"].items()}, boxes,
                                              split=static_split(scene, opts))
                for g, img in done.items():
                    out["static"][g][win] = img
        for g, info in groups.items():
            if info["flicker"]:
                out["lights"].setdefault(g, [])
        if opts.aux:
            ids, pos = tr.hits(tm["t_aux"], LIGHT_MASK_PASSES, _seed(opts.seed, n, "aux"))
            out["aux"] = _aux_maps(loaded, scene, ids, pos, geo.ego.position(tm["t_aux"]),
                                   geo.ego.rotation_mi(tm["t_aux"])[:, 2], visible)
        del tr, sets, loaded  # free the frame's Mitsuba objects before the next frame is loaded
        gc.collect()
        yield out
    del pad  # the registry padding lives as long as the scene's frames
