"""How far each pixel's surface point moves on screen over a time interval: the bound a sparse scheme of static time
bins needs (docs/benchmarks/motion-windows.md, "masked bins").

A static group's radiance in a time bin differs from its long-window average only where something moves on screen
during the capture window. :func:`screen_motion_px` measures that per pixel from the frame's AOVs: the first-hit point
of the pixel centre (``depth.Z`` at the AOV time, :func:`render_tools.render.frame_timing` ``t_aux``) is moved with
its object's velocity (0 for the static world) and projected with the ego camera's pose (:mod:`render_tools.camera`)
at ``samples`` times over the interval; the result is the diagonal of the bounding box of those projections, px.
:func:`motion_mask` thresholds it and grows it by a margin. What it does not see: light that a moving lamp throws on
static surfaces and shadows of moving objects (their footprint moves while the surface does not); the benchmark
measures the error that leaves.
"""
from __future__ import annotations

import numpy as np

from . import camera as cam_mod

#: Depth used for pixels that hit nothing (sky): far enough that translation does not move them, m.
FAR_M = 1.0e7


def screen_motion_px(scene: dict, width: int, height: int, depth_z: np.ndarray, instance: np.ndarray,
                     t_cam: float, t_obj: float, t_a: float, t_b: float, samples: int = 9) -> np.ndarray:
    """Screen-space extent of each pixel's surface point over [t_a, t_b], px.

    Args:
        scene: the scene dict (camera, objects with ``id`` and ``velocity_mps``).
        width, height: image size W, H, px.
        depth_z: (H, W) m depth along the optical axis of the pixel centres' first hits at time ``t_cam``
            (+inf where nothing is hit).
        instance: (H, W) object id of the hit (-1 or an id without velocity: static world).
        t_cam: time of the camera pose the depth was taken at, s (absolute, as the renderer's frame timing).
        t_obj: time at which the objects stood where the depth saw them, s.
        t_a, t_b: the interval, s; ``samples`` >= 2 times spread evenly over it, ends included.

    Returns:
        (H, W) float64: the diagonal of the bounding box of the pixel's projections over the interval, px
        (0 for a point that does not move on screen; inf where the point passes behind the camera).
    """
    depth_z = np.asarray(depth_z, np.float64)
    if depth_z.shape != (height, width) or np.shape(instance) != (height, width):
        raise ValueError(f"depth_z / instance: expected ({height}, {width}), got {depth_z.shape} / "
                         f"{np.shape(instance)}")
    if samples < 2:
        raise ValueError(f"samples: must be >= 2, got {samples}")
    ego = cam_mod.EgoMotion.from_scene(scene)
    K = cam_mod.intrinsics(width, height, float(scene["camera"]["fov_x_deg"]))
    v, u = np.mgrid[0:height, 0:width] + 0.5
    z = np.where(np.isfinite(depth_z), depth_z, FAR_M)
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)   # (H, W, 3) cv
    pose = ego.pose_cv(t_cam)
    pts = (rays * z[..., None]) @ pose[:3, :3].T + pose[:3, 3]                                   # world, m
    vel = np.zeros_like(pts)
    inst = np.asarray(instance)
    for o in scene["objects"]:
        vo = np.asarray(o.get("velocity_mps", (0.0, 0.0, 0.0)), np.float64)
        if np.any(vo != 0.0):
            vel[inst == o["id"]] = vo
    lo = np.full((height, width, 2), np.inf)
    hi = np.full((height, width, 2), -np.inf)
    behind = np.zeros((height, width), bool)
    for t in np.linspace(t_a, t_b, samples):
        uv, zc = cam_mod.project((pts + vel * (t - t_obj)).reshape(-1, 3), ego.pose_cv(t), K)
        uv, zc = uv.reshape(height, width, 2), zc.reshape(height, width)
        behind |= zc <= 0
        lo, hi = np.minimum(lo, uv), np.maximum(hi, uv)
    ext = np.hypot(*np.moveaxis(hi - lo, -1, 0))
    return np.where(behind, np.inf, ext)


def motion_mask(motion_px: np.ndarray, eps_px: float, grow_px: int = 1) -> np.ndarray:
    """(H, W) bool: pixels whose screen motion (:func:`screen_motion_px`) is at least ``eps_px`` px, grown by
    ``grow_px`` px in every direction (a moving edge's blur reaches the neighbouring pixels; scipy's binary
    dilation with a square structuring element)."""
    from scipy.ndimage import binary_dilation  # noqa: PLC0415

    m = np.asarray(motion_px) >= eps_px
    if grow_px > 0 and m.any():
        m = binary_dilation(m, structure=np.ones((2 * grow_px + 1, 2 * grow_px + 1), bool))
    return m
