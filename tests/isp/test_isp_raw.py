"""lfmbench.isp.raw: black level, white balance of the mosaic, grey-world gains."""
from __future__ import annotations

import torch

from lfmbench.isp import gray_world_gains, subtract_black_level, white_balance_mosaic
from lfmbench.sensor import mosaic


# -------------------------------------------------------------------------------------------- black level, WB
def test_black_level_and_white_balance():
    raw = torch.full((2, 1, 4, 4), 164.0)
    assert torch.equal(subtract_black_level(raw, 64), torch.full_like(raw, 100.0))
    assert torch.allclose(subtract_black_level(raw, 64, 4095), torch.full_like(raw, 100 / 4031))
    wb = white_balance_mosaic(torch.ones(1, 1, 2, 2), [2.0, 1.0, 3.0], "GRBG")
    assert wb[0, 0].tolist() == [[1.0, 2.0], [3.0, 1.0]]  # G R / B G


def test_gray_world_gains_equalise_channel_means():
    rgb = torch.tensor([0.5, 1.0, 0.25]).reshape(1, 3, 1, 1).expand(2, 3, 8, 8)
    raw = mosaic(rgb, "RGGB")
    g = gray_world_gains(raw, "RGGB")
    assert torch.allclose(g, torch.tensor([[2.0, 1.0, 4.0]] * 2))
    balanced = white_balance_mosaic(raw, g, "RGGB")
    assert torch.allclose(balanced, torch.ones_like(balanced))
