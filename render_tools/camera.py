"""Ego camera: pose over time, intrinsics, projection, and a continuous-time motion-blur Mitsuba sensor.

World frame: ISO 8855 vehicle axes, right-handed, metres: x forward (initial heading 0), y left, z up.
The ego vehicle drives at constant speed ``v`` (m/s) with constant yaw rate ``omega`` (rad/s):

    psi(t) = psi0 + omega * t
    p(t)   = p0 + (v / omega) * [sin psi(t) - sin psi0, cos psi0 - cos psi(t), 0]     (omega != 0)
    p(t)   = p0 + v * t * [cos psi0, sin psi0, 0]                                     (omega == 0)

(the exact integral of a constant-speed, constant-turn-rate motion, the "CTRV" model: Schubert, Richter,
Wanielik, "Comparison and evaluation of advanced motion models for vehicle tracking", FUSION 2008).

Camera frames: Mitsuba's camera looks along its local +z with +y up and +x to the image **left**; poses
written to ``meta.json`` use the OpenCV convention (x right, y down, z forward), so that with the intrinsics
``K`` (pixels; pixel (i, j) covers [j, j+1) x [i, i+1), centre at j + 0.5) a world point X projects to
``u ~ K R^T (X - C)``.

:class:`MotionCamera` is a small ``mi.Sensor`` subclass wrapping a ``perspective`` sensor placed at the
origin: each ray sampled at time ``t`` (drawn by the integrator uniformly in a bin of ``bin_len`` s) is moved
by the pose at ``t``, so one render integrates the blur over the shutter interval continuously instead of
averaging sub-frames. The integrator's own ray time is the *fraction* of the bin (Mitsuba shutter [0, 1], or
[0, 0] for an instant): Mitsuba writes the shutter length into the kernel as a literal, so a shutter of
``bin_len`` s compiled one kernel per window length; the fraction times ``bin_len`` (an opaque value) lets
every window length share one kernel (the same float32 product ``u * bin_len``; images within 1 ulp of the
literal's). It renders an *atlas*: K time bins of a crop side by side along x and the ceil(C / 4) band passes
along y; in pass p the 4 wavelengths of a sample lie one in each of bands p + j * ceil(C / 4) (no random band
counts: see docs/guide/rendering.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Registered Mitsuba plugin name of :class:`MotionCamera`.
PLUGIN_NAME = "lfm_motion_camera"
#: Rotation from Mitsuba camera-local axes (x left, y up, z forward) to vehicle axes (x fwd, y left, z up):
#: columns are the images of local x, y, z.
R_VEHICLE_FROM_MI = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
#: OpenCV camera axes (x right, y down, z forward) expressed in Mitsuba camera-local axes.
R_MI_FROM_CV = np.diag([-1.0, -1.0, 1.0])
#: Sampler of every radiance render: stratified in each dimension for any sample count, which also
#: stratifies the in-band wavelength of the band-stratified passes (per-band noise ~10x below independent).
DEFAULT_SAMPLER = "multijitter"


def multijitter_count(spp: int) -> int:
    """The sample count Mitsuba's ``multijitter`` sampler uses for ``spp`` requested samples per pixel.

    It stratifies on an ``a x b`` grid with ``a = floor(sqrt(spp))``, ``b = ceil(spp / a)`` and rounds any
    other count up to ``a * b``, printing a ``Sample count rounded up`` warning on every render. Callers pass
    this count instead, so the render uses the same samples and the log stays readable: counts such as 1..4, 6,
    8, 9, 12, 16, 20, 24, 64 are kept; 5 -> 6, 32 -> 35.

    >>> [multijitter_count(n) for n in (1, 4, 5, 16, 32, 64)]
    [1, 4, 6, 16, 35, 64]
    """
    spp = int(spp)
    if spp < 1:
        raise ValueError(f"spp must be an integer >= 1, got {spp}")
    a = math.isqrt(spp)
    return a * -(-spp // a)
#: Near clipping distance of the Mitsuba perspective camera, m.
NEAR_CLIP_M = 0.01


@dataclass(frozen=True)
class EgoMotion:
    """Ego camera state: position ``p0`` (m, world), heading ``yaw0_rad`` (rad, about +z), pitch (rad, + looks
    up), speed ``speed_mps`` (m/s, >= 0) and yaw rate ``yaw_rate_rad_s`` (rad/s) at t = 0 s."""

    p0: tuple[float, float, float]
    yaw0_rad: float = 0.0
    pitch_rad: float = 0.0
    speed_mps: float = 0.0
    yaw_rate_rad_s: float = 0.0

    def __post_init__(self):
        if len(self.p0) != 3 or not all(math.isfinite(float(c)) for c in self.p0):
            raise ValueError(f"p0: expected 3 finite coordinates (m), got {self.p0!r}")
        if not math.isfinite(self.speed_mps) or self.speed_mps < 0:
            raise ValueError(f"speed_mps: must be finite and >= 0 m/s, got {self.speed_mps}")
        if not math.isfinite(self.yaw_rate_rad_s):
            raise ValueError(f"yaw_rate_rad_s: must be finite, got {self.yaw_rate_rad_s}")
        if not abs(self.pitch_rad) < math.pi / 2:
            raise ValueError(f"pitch_rad: must be in (-pi/2, pi/2), got {self.pitch_rad}")

    @classmethod
    def from_scene(cls, scene: dict) -> "EgoMotion":
        """Build from a validated scene dict's ``camera`` entry."""
        c = scene["camera"]
        return cls(p0=tuple(float(v) for v in c["position_m"]), yaw0_rad=math.radians(c["yaw_deg"]),
                   pitch_rad=math.radians(c["pitch_deg"]), speed_mps=float(c["speed_mps"]),
                   yaw_rate_rad_s=float(c["yaw_rate_rad_s"]))

    @property
    def moving(self) -> bool:
        return self.speed_mps != 0.0 or self.yaw_rate_rad_s != 0.0

    def position(self, t):
        """Camera centre (..., 3) m at time(s) ``t`` (s, scalar or array (...))."""
        t = np.asarray(t, dtype=np.float64)
        psi0, w, v = self.yaw0_rad, self.yaw_rate_rad_s, self.speed_mps
        if w == 0.0:
            d = np.stack([v * t * math.cos(psi0), v * t * math.sin(psi0), 0.0 * t], -1)
        else:
            psi = psi0 + w * t
            d = np.stack([(v / w) * (np.sin(psi) - math.sin(psi0)), (v / w) * (math.cos(psi0) - np.cos(psi)),
                          0.0 * t], -1)
        return np.asarray(self.p0) + d

    def rotation_mi(self, t) -> np.ndarray:
        """Rotation (..., 3, 3) from Mitsuba camera-local axes to world at time(s) ``t`` (s)."""
        t = np.asarray(t, dtype=np.float64)
        psi = self.yaw0_rad + self.yaw_rate_rad_s * t
        c, s = np.cos(psi), np.sin(psi)
        rz = np.zeros(t.shape + (3, 3))
        rz[..., 0, 0], rz[..., 0, 1], rz[..., 1, 0], rz[..., 1, 1], rz[..., 2, 2] = c, -s, s, c, 1.0
        return rz @ self._m0()

    def _m0(self) -> np.ndarray:
        """Constant part: pitch about vehicle +y (positive looks up) after the axis change, (3, 3)."""
        th = -self.pitch_rad
        ry = np.array([[math.cos(th), 0, math.sin(th)], [0, 1, 0], [-math.sin(th), 0, math.cos(th)]])
        return ry @ R_VEHICLE_FROM_MI

    def pose_cv(self, t) -> np.ndarray:
        """4x4 camera-to-world matrix (OpenCV camera axes) at time ``t`` (s, scalar) -> (4, 4)."""
        m = np.eye(4)
        m[:3, :3] = self.rotation_mi(float(t)) @ R_MI_FROM_CV
        m[:3, 3] = self.position(float(t))
        return m


def intrinsics(width: int, height: int, fov_x_deg: float) -> np.ndarray:
    """Pinhole intrinsics K (3, 3) in pixels for a horizontal field of view ``fov_x_deg`` (deg), square
    pixels, principal point at the image centre: ``fx = fy = (width / 2) / tan(fov_x / 2)``."""
    if width < 1 or height < 1:
        raise ValueError(f"width/height: must be >= 1 px, got {width}x{height}")
    if not 0.0 < fov_x_deg < 180.0:
        raise ValueError(f"fov_x_deg: must be in (0, 180) deg, got {fov_x_deg}")
    f = 0.5 * width / math.tan(math.radians(fov_x_deg) / 2)
    return np.array([[f, 0.0, width / 2.0], [0.0, f, height / 2.0], [0.0, 0.0, 1.0]])


def project(points_world: np.ndarray, pose_cv: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project world points (N, 3) m with camera-to-world ``pose_cv`` (4, 4) and ``K`` (3, 3).

    Returns (uv (N, 2) continuous pixel coordinates (x right, y down), z (N,) m depth along the optical axis).
    """
    pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    r, c = pose_cv[:3, :3], pose_cv[:3, 3]
    pc = (pts - c) @ r  # = R^T (X - C) per row
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (pc @ K.T)[:, :2] / z[:, None]
    return uv, z


def ensure_registered() -> None:
    """Register :class:`MotionCamera` as plugin :data:`PLUGIN_NAME` for the active Mitsuba variant."""
    import mitsuba as mi  # noqa: PLC0415

    key = mi.variant()
    if key in _REGISTERED:
        return
    _REGISTERED[key] = _make_class(mi)
    mi.register_sensor(PLUGIN_NAME, lambda props: _REGISTERED[key](props))


_REGISTERED: dict = {}


def _make_class(mi):
    import drjit as dr  # noqa: PLC0415

    n_lambda = 4  # MI_SPECTRUM_SAMPLES of Mitsuba's spectral variants

    class MotionCamera(mi.Sensor):
        """Perspective camera moving along the CTRV path of :class:`EgoMotion`, with band-stratified
        wavelength sampling (see module docstring).

        Properties: ``fov`` (deg, horizontal), ``px, py, pz`` (m), ``yaw0`` (rad), ``pitch`` (rad),
        ``speed`` (m/s), ``yaw_rate`` (rad/s), ``shutter_open`` (0), ``shutter_close`` (1, or 0 for
        ``bin_len`` 0: the integrator's ray time is the fraction of a bin), ``film``,
        ``t_start`` (s, added to every ray time: the pose at ray time t is the pose at t_start + t),
        ``band_lo`` (comma-separated lower band edges, nm), ``band_width`` (nm), ``full_width`` /
        ``full_height`` (px), ``crop_x, crop_y, crop_w, crop_h`` (px), ``bin_len`` (s), ``tiles_x`` (bins),
        ``tiles_y`` (band passes), ``obj_vx, obj_vy, obj_vz`` (m/s) and ``t_ref`` (s): the velocity of an
        object placed at its ``t_ref`` position, whose own motion is rendered by moving the camera by
        ``-v_obj (t - t_ref)`` (relative motion; default 0); see :func:`sensor_dict`.
        """

        def __init__(self, props):
            mi.Sensor.__init__(self, props)
            self.fov = props.get("fov", 40.0)
            self.p0_scalar = [props.get("px", 0.0), props.get("py", 0.0), props.get("pz", 0.0)]
            yaw0 = props.get("yaw0", 0.0)
            self.pitch = props.get("pitch", 0.0)
            speed = props.get("speed", 0.0)
            yaw_rate = props.get("yaw_rate", 0.0)
            self.turning = yaw_rate != 0.0
            self.full_w = int(props.get("full_width", self.film().size()[0]))
            self.full_h = int(props.get("full_height", self.film().size()[1]))
            self.tiles_x = int(props.get("tiles_x", 1))
            self.tiles_y = int(props.get("tiles_y", 1))
            scalar = mi.variant().startswith("scalar")

            def opaque(v, t=mi.Float):
                return v if scalar else dr.opaque(t, v)

            # Every scene-dependent number is an opaque JIT variable, so kernels are shared by all scenes
            # with the same film size (drjit's kernel cache), not rebuilt per scene.
            self.p0 = [opaque(v) for v in self.p0_scalar]
            self.speed, self.yaw_rate = opaque(speed), opaque(yaw_rate if self.turning else 1.0)
            self.yaw0, self.cos0, self.sin0 = opaque(yaw0), opaque(math.cos(yaw0)), opaque(math.sin(yaw0))
            # relative motion of one object (per-light renders of lamps on moving vehicles): opaque, so a
            # moving and a static lamp share one kernel
            self.v_obj = [opaque(props.get(k, 0.0)) for k in ("obj_vx", "obj_vy", "obj_vz")]
            self.t_ref = opaque(props.get("t_ref", 0.0))

            # Opaque JIT variables: crop, window and band pass change per render without recompiling.
            self.t_start = opaque(props.get("t_start", 0.0))
            self.bin_len = opaque(props.get("bin_len", 0.0))
            if self.shutter_open() != 0.0 or self.shutter_open_time() not in (0.0, 1.0):
                raise ValueError(f"shutter_open, shutter_close: must be 0 and 1 (or 0 and 0), the ray time being the "
                                 f"fraction of a bin, got {self.shutter_open()}, "
                                 f"{self.shutter_open() + self.shutter_open_time()}")
            self.crop = [opaque(props.get(k, d)) for k, d in (("crop_x", 0.0), ("crop_y", 0.0),
                                                               ("crop_w", float(self.full_w)),
                                                               ("crop_h", float(self.full_h)))]
            lo = [float(v) for v in props.get("band_lo", "").split(",") if v.strip()]
            self.n_bands = len(lo)
            self.band_w = props.get("band_width", 10.0)
            if self.n_bands:
                self.n_pass = n_passes(self.n_bands)
                if self.tiles_y != self.n_pass:
                    raise ValueError(f"tiles_y: must equal the number of band passes {self.n_pass}")
                # sentinel: wavelengths of a missing band go to 820..830 nm, outside every band (contribute 0)
                self.band_lo = (lo + [830.0 - self.band_w]) if scalar else mi.Float(lo + [830.0 - self.band_w])
            self.srf = self.film().sensor_response_function()
            self.inner = mi.load_dict({"type": "perspective", "fov": self.fov, "fov_axis": "x",
                                       "near_clip": NEAR_CLIP_M, "far_clip": 1e5,
                                       "film": {"type": "hdrfilm", "width": self.full_w, "height": self.full_h,
                                                "rfilter": {"type": "box"}},
                                       "sampler": self.sampler()})
            th = -self.pitch
            ry = np.array([[math.cos(th), 0, math.sin(th)], [0, 1, 0], [-math.sin(th), 0, math.cos(th)]])
            self.m0 = [[opaque(float(x)) for x in row] for row in (ry @ R_VEHICLE_FROM_MI)]

        def _rot(self, v, c, s):
            m = self.m0
            x = m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z
            y = m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z
            z = m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z
            return mi.Vector3f(c * x - s * y, s * x + c * y, z)

        def _frame(self, time):
            if not self.turning:
                c, s = self.cos0, self.sin0
                off = mi.Vector3f(self.speed * time * c, self.speed * time * s, 0.0)
            else:
                psi = self.yaw0 + self.yaw_rate * time
                c, s = dr.cos(psi), dr.sin(psi)
                k = self.speed / self.yaw_rate
                off = mi.Vector3f(k * (s - self.sin0), k * (self.cos0 - c), 0.0)
            dt = time - self.t_ref
            p = mi.Point3f(self.p0[0] - self.v_obj[0] * dt, self.p0[1] - self.v_obj[1] * dt,
                           self.p0[2] - self.v_obj[2] * dt) + off
            return p, c, s

        def _wavelengths(self, ray, w, u, band_pass):
            """Pass p puts wavelength k uniformly inside band p + k * n_pass (one per band, no band-count
            noise); the specfilm weight becomes 4 so that each covered band receives exactly L(lambda)."""
            if not self.n_bands:
                return w
            wl = []
            for k in range(n_lambda):
                idx = dr.minimum(band_pass + k * self.n_pass, self.n_bands)
                if isinstance(self.band_lo, list):
                    lo = self.band_lo[int(idx)]
                else:
                    lo = dr.gather(mi.Float, self.band_lo, idx)
                uk = u + k / n_lambda
                uk = dr.select(uk >= 1.0, uk - 1.0, uk)
                wl.append(lo + uk * self.band_w)
            ray.wavelengths = mi.Spectrum(wl[0], wl[1], wl[2], wl[3])
            # specfilm.prepare_sample divides by its sampling SRF m_srf (a resampled sum of the bands), so
            # the weight that makes band j receive exactly L(lambda) is 4 * w * m_srf(lambda) (each band box
            # has height 1/w); this replaces the inner sensor's weight (which assumes m_srf sampling).
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.wavelengths = ray.wavelengths
            return self.srf.eval(si) * (n_lambda * self.band_w)

        def _atlas(self, time, sample2):
            """Atlas tile (bin k along x, band pass p along y) -> position sample on the full image and the
            absolute time t_start + k * bin_len + time * bin_len (``time``: the fraction of the bin, in [0, 1))."""
            X = sample2.x * self.tiles_x
            Y = sample2.y * self.tiles_y
            k, p = dr.floor(X), dr.floor(Y)
            pos = mi.Point2f((self.crop[0] + (X - k) * self.crop[2]) / self.full_w,
                             (self.crop[1] + (Y - p) * self.crop[3]) / self.full_h)
            return pos, self.t_start + k * self.bin_len + time * self.bin_len, mi.UInt32(p)

        def _moved_ray(self, inner_sample, time, sample1, sample2, sample3, active):
            """Sample the inner camera at the atlas position, set the spectral weights, and move the ray into the
            camera frame at its absolute time. Returns (ray, weight, (position, cos yaw, sin yaw))."""
            pos, t_abs, band_pass = self._atlas(time, sample2)
            ray, w = inner_sample(time, sample1, pos, sample3, active)
            w = self._wavelengths(ray, w, sample1, band_pass)
            p, c, s = self._frame(t_abs)
            ray.o = p + self._rot(ray.o, c, s)
            ray.d = self._rot(ray.d, c, s)
            ray.time = t_abs
            return ray, w, (p, c, s)

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            ray, w, _ = self._moved_ray(self.inner.sample_ray, time, sample1, sample2, sample3, active)
            return ray, w

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            ray, w, (p, c, s) = self._moved_ray(self.inner.sample_ray_differential, time, sample1, sample2,
                                                sample3, active)
            ray.o_x = p + self._rot(ray.o_x, c, s)
            ray.o_y = p + self._rot(ray.o_y, c, s)
            ray.d_x = self._rot(ray.d_x, c, s)
            ray.d_y = self._rot(ray.d_y, c, s)
            return ray, w

        def bbox(self):
            return mi.ScalarBoundingBox3f(mi.ScalarPoint3f(self.p0_scalar))

        def traverse(self, callback):
            pass

        def parameters_changed(self, keys=None):
            pass

        def to_string(self):
            return (f"MotionCamera[fov={self.fov}, p0={self.p0_scalar}, turning={self.turning}, "
                    f"shutter=[{self.shutter_open()}, +{self.shutter_open_time()}], bands={self.n_bands}]")

    return MotionCamera


def sensor_dict(ego: EgoMotion, fov_x_deg: float, film: dict, full_size: tuple[int, int], t_start: float,
                bin_len: float, bins: int = 1, crop=None, band_lo_nm=None, band_width_nm: float = 10.0,
                sampler: dict | None = None, object_velocity_mps=(0.0, 0.0, 0.0), t_ref: float = 0.0) -> dict:
    """Mitsuba dict of the ego camera (:class:`MotionCamera`) rendering an *atlas*.

    The film (``film``, a dict) must be ``bins * w`` wide and ``n_passes * h`` high for a crop of w x h px
    (``n_passes`` = :func:`n_passes` of the bands, 1 without bands). Tile (p, k) holds time bin k, i.e. the
    crop integrated over [t_start + k * bin_len, t_start + (k + 1) * bin_len) s, for band pass p.

    Args:
        full_size: (width, height) of the full image, px.
        crop: (y0, x0, y1, x1) px of the full image (default: all of it).
        band_lo_nm: lower edges (nm) of the film's box bands; given, pass p samples one wavelength in each of
            bands ``p + j * n_pass`` (j = 0..3) and the tiles of all passes add up to every band. None:
            Mitsuba's own wavelength sampling (for AOVs with an RGB film).
        object_velocity_mps: (3,) world velocity (m/s) of an object that the scene holds at its position at
            ``t_ref`` (s): the camera then moves by ``-v (t - t_ref)`` on top of the ego motion, so the object
            is seen with its true relative motion (and everything else as if it moved with the object).
    """
    v_obj = [float(v) for v in object_velocity_mps]
    if len(v_obj) != 3 or not all(math.isfinite(v) for v in v_obj) or not math.isfinite(float(t_ref)):
        raise ValueError(f"object_velocity_mps: expected 3 finite values (m/s) and a finite t_ref (s), got "
                         f"{object_velocity_mps!r}, {t_ref!r}")
    if not (math.isfinite(bin_len) and bin_len >= 0):
        raise ValueError(f"bin_len: shutter interval must be >= 0 s, got {bin_len}")
    if not isinstance(bins, (int, np.integer)) or bins < 1:
        raise ValueError(f"bins: must be an integer >= 1, got {bins!r}")
    W, H = int(full_size[0]), int(full_size[1])
    y0, x0, y1, x1 = crop if crop is not None else (0, 0, H, W)
    ensure_registered()
    d = {"type": PLUGIN_NAME, "fov": float(fov_x_deg), "px": float(ego.p0[0]), "py": float(ego.p0[1]),
         "pz": float(ego.p0[2]), "yaw0": float(ego.yaw0_rad), "pitch": float(ego.pitch_rad),
         "speed": float(ego.speed_mps), "yaw_rate": float(ego.yaw_rate_rad_s), "film": film,
         "sampler": sampler or {"type": DEFAULT_SAMPLER},
         "shutter_open": 0.0, "shutter_close": 1.0 if bin_len > 0 else 0.0,  # ray time: fraction of a bin
         "t_start": float(t_start), "bin_len": float(bin_len), "full_width": W, "full_height": H,
         "crop_x": float(x0), "crop_y": float(y0), "crop_w": float(x1 - x0), "crop_h": float(y1 - y0),
         "tiles_x": int(bins), "tiles_y": 1, "obj_vx": v_obj[0], "obj_vy": v_obj[1], "obj_vz": v_obj[2],
         "t_ref": float(t_ref)}
    if band_lo_nm is not None:
        d.update({"band_lo": ", ".join(repr(float(v)) for v in band_lo_nm), "band_width": float(band_width_nm),
                  "tiles_y": n_passes(len(band_lo_nm))})
    return d


def n_passes(n_bands: int) -> int:
    """Render passes needed to cover ``n_bands`` bands with 4 wavelengths per sample."""
    return -(-int(n_bands) // 4)
