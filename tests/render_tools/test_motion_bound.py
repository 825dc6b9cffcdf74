"""Screen motion of each pixel's surface point (render_tools.motion_bound) against closed forms of a pinhole camera.

Forward ego motion towards a wall at distance Z: a pixel at offset r px from the principal point sees its point at
offset r Z / (Z - d) after the camera advanced by d, so over [t_a, t_b] it moves r Z (1 / (Z - v t_b) - 1 / (Z - v
t_a)) px. A static camera and a point on an object moving sideways at w m/s: f w (t_b - t_a) / Z px. Written from
the pinhole model, not from the module's projection.
"""
from __future__ import annotations

import numpy as np
import pytest

from render_tools import motion_bound as mb
from render_tools import scene as scene_mod

W, H, FOV = 16, 10, 40.0


def _wall(speed, velocity=(0.0, 0.0, 0.0)):
    s = scene_mod.empty_scene(speed_mps=speed, fov_x_deg=FOV)
    s["objects"].append({"id": 3, "kind": "car", "velocity_mps": list(velocity),
                         "parts": [{"shape": "box", "center": [20.0, 0.0, 1.4], "size": [0.2, 30.0, 30.0],
                                    "material": "road"}]})
    return s


def test_forward_motion_matches_the_pinhole_closed_form():
    Z, v, ta, tb = 12.0, 25.0, 0.0, 0.0111
    m = mb.screen_motion_px(_wall(v), W, H, np.full((H, W), Z), np.full((H, W), -1.0), 0.0, 0.0, ta, tb)
    f = 0.5 * W / np.tan(np.radians(FOV) / 2)
    yy, xx = np.mgrid[0:H, 0:W] + 0.5
    r = np.hypot(xx - W / 2, yy - H / 2)
    want = r * Z * (1 / (Z - v * tb) - 1 / (Z - v * ta))
    assert np.allclose(m, want, rtol=1e-9, atol=1e-9)
    assert f > 0 and m.max() > 0.1                                       # the case is not trivially zero
    # a sky pixel does not move under translation
    d = np.full((H, W), Z)
    d[0, 0] = np.inf
    assert mb.screen_motion_px(_wall(v), W, H, d, np.full((H, W), -1.0), 0.0, 0.0, ta, tb)[0, 0] < 1e-4


def test_a_moving_object_moves_by_its_speed_over_depth():
    Z, w, ta, tb = 20.0, 15.0, 0.010, 0.011
    inst = np.full((H, W), -1.0)
    inst[:, W // 2:] = 3                                                 # the right half is the moving car
    m = mb.screen_motion_px(_wall(0.0, (0.0, -w, 0.0)), W, H, np.full((H, W), Z), inst, 0.0, 0.0055, ta, tb)
    f = 0.5 * W / np.tan(np.radians(FOV) / 2)
    assert np.allclose(m[:, W // 2:], f * w * (tb - ta) / Z, rtol=1e-9)
    assert np.all(m[:, :W // 2] == 0.0)
    mask = mb.motion_mask(m, 0.5 * f * w * (tb - ta) / Z, grow_px=1)
    assert mask[:, W // 2 - 1:].all() and not mask[:, :W // 2 - 1].any()   # grown by one column
    with pytest.raises(ValueError, match="depth_z"):
        mb.screen_motion_px(_wall(0.0), W, H, np.ones((2, 2)), np.ones((2, 2)), 0, 0, 0, 1)
