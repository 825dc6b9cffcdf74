"""Reference renderer: Mitsuba's own ``path`` integrator through ``mi.render``, one call per window or light.

Independent of :mod:`render_tools.tracer` (different camera code, film, sampler and integrator), so the tests
compare the two; the benchmarks use it as the brute-force side (sub-frame and relative-motion references).
Scenes: :func:`render_tools.mitsuba_scene.mitsuba_dict` with ``emit`` = one group, and
:func:`render_tools.mitsuba_scene.set_solo` for one light of it.
"""
from __future__ import annotations

import numpy as np

from . import camera as cam_mod
from .render import RenderOptions, SceneGeometry, _film

class ReferenceRenderer(SceneGeometry):
    """Stock Mitsuba rendering of one scene: ``mi.render`` with the ``path`` integrator of a per-group Mitsuba
    scene and the :class:`camera.MotionCamera` sensor, one call per window or light (the renderer before
    :mod:`render_tools.tracer`; slow: each call is traced and, for new crop sizes or scene layouts, compiled)."""

    def __init__(self, scene: dict, opts: RenderOptions):
        from . import backend  # noqa: PLC0415

        super().__init__(scene, opts)
        self.variant = backend.select_variant(opts.variant)
        import drjit as dr  # noqa: PLC0415
        import mitsuba as mi  # noqa: PLC0415

        self.mi, self.dr = mi, dr

    def sensor(self, t_start: float, bin_len: float, bins: int = 1, crop=None, film=None, bands: bool = True,
               velocity=(0.0, 0.0, 0.0), t_ref: float = 0.0):
        """Loaded atlas sensor (:func:`camera.sensor_dict`): ``bins`` bins of ``bin_len`` s from ``t_start``
        over ``crop`` (y0, x0, y1, x1) px; ``bands``: band-stratified passes on a spectral film; ``velocity``
        (m/s) and ``t_ref`` (s): an object's motion rendered as relative camera motion."""
        opts = self.opts
        y0, x0, y1, x1 = crop if crop is not None else (0, 0, opts.height, opts.width)
        w = opts.band_width_nm
        passes = cam_mod.n_passes(len(opts.bands_nm)) if bands else 1
        film = film or _film(opts, (x1 - x0) * bins, (y1 - y0) * passes)
        lo = [c - w / 2 for c in opts.bands_nm] if bands else None
        return self.mi.load_dict(cam_mod.sensor_dict(self.ego, self.fov, film, (opts.width, opts.height), t_start,
                                                     bin_len, bins, (y0, x0, y1, x1), lo, w,
                                                     object_velocity_mps=velocity, t_ref=t_ref))

    def render(self, scene_obj, t_start, bin_len, spp, seed, crop=None, bins: int = 1,
               velocity=(0.0, 0.0, 0.0), t_ref: float = 0.0) -> np.ndarray:
        """Radiance W sr^-1 m^-2 nm^-1 of ``bins`` consecutive time bins -> (bins, C, h, w) float32, in one
        Mitsuba render of an atlas (bins along x, band passes along y, summed here). ``velocity`` (m/s) and
        ``t_ref`` (s): render an object held at its ``t_ref`` position with its own motion (relative camera
        motion, :func:`camera.sensor_dict`). ``spp`` is rounded up to a count the multijitter sampler accepts
        (:func:`camera.multijitter_count`: what Mitsuba would use anyway, without its warning per render)."""
        opts = self.opts
        y0, x0, y1, x1 = crop if crop is not None else (0, 0, opts.height, opts.width)
        h, w = y1 - y0, x1 - x0
        P = cam_mod.n_passes(len(opts.bands_nm))
        img = self.mi.render(scene_obj, sensor=self.sensor(t_start, bin_len, bins, crop, velocity=velocity,
                                                           t_ref=t_ref), spp=cam_mod.multijitter_count(spp),
                              seed=int(seed))
        a = np.array(img, dtype=np.float32).reshape(P, h, bins, w, len(opts.bands_nm)).sum(0)
        return np.ascontiguousarray(a.transpose(1, 3, 0, 2))

