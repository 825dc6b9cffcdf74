"""lfmbench.isp.compand: companding round trip, monotonicity, knee checks, the module."""
from __future__ import annotations

import pytest
import torch

from lfmbench.isp import Compander, check_knees, compand, decompand


KNEES = [[0, 0], [1024, 1024], [8192, 1920], [65536, 2816], [524288, 3712], [16777215, 4095]]


# ------------------------------------------------------------------------------------------------- companding
def test_compand_round_trip_within_one_code():
    k = check_knees(KNEES, 24, 12)
    codes = torch.arange(4096, dtype=torch.float64)
    assert torch.equal(compand(decompand(codes, k), k), codes)  # every output code survives the round trip
    gen = torch.Generator().manual_seed(0)
    x = torch.cat([torch.arange(0, 70000, dtype=torch.float64),
                   torch.randint(0, 2 ** 24, (200_000,), generator=gen).double(),
                   k[:, 0], k[:, 0] - 1, k[:, 0] + 1]).clamp(0, 2 ** 24 - 1)
    y = compand(x, k)
    assert y.min() >= 0 and y.max() <= 4095 and torch.equal(y, y.round())
    back = decompand(y, k)
    slope = torch.tensor([float((k[i + 1, 1] - k[i, 1]) / (k[i + 1, 0] - k[i, 0])) for i in range(len(k) - 1)],
                         dtype=torch.float64)
    seg = torch.bucketize(x, k[1:-1, 0].contiguous(), right=True)
    half_code = 0.5 / slope[seg]  # half an output code, in input codes, on the segment of x (and its neighbour)
    half_code = torch.maximum(half_code, 0.5 / slope[(seg - 1).clamp_min(0)])
    assert bool(((back - x).abs() <= half_code + 1e-6).all())
    assert torch.equal(compand(back, k), y)  # within one code: re-companding gives the same code
    assert torch.equal(back[x < 1024], x[x < 1024])  # slope 1: lossless


def test_compand_monotone_and_hand_checked():
    k = check_knees(KNEES, 24, 12)
    assert compand(torch.tensor([1024.0, 1032.0, 8192.0, 16777215.0]), k).tolist() == [1024.0, 1025.0, 1920.0, 4095.0]
    x = torch.linspace(0, 2 ** 24 - 1, 100_001, dtype=torch.float64)
    assert bool((torch.diff(compand(x, k)) >= 0).all())


@pytest.mark.parametrize("knees, match", [
    ([[0, 0]], "at least 2"),
    ([[1, 0], [16777215, 4095]], r"knees\[0\]"),
    ([[0, 0], [1000, 4095]], r"knees\[1\].*must end at input code"),
    ([[0, 0], [10, 20], [16777215, 4095]], r"knees\[1\].*slope 2 > 1"),
    ([[0, 0], [10, 5], [5, 6], [16777215, 4095]], r"knees\[2\].*strictly greater"),
    ([[0, 0], [16777215, 5000]], r"exceeds the top code"),
    ([[0, 0], ["a", 1], [16777215, 4095]], r"knees\[1\].*pair"),
])
def test_check_knees_errors_name_the_field(knees, match):
    with pytest.raises(ValueError, match=match):
        check_knees(knees, 24, 12, source="link.yaml")


def test_compander_module_quantises_and_passes_gradient():
    m = Compander(KNEES, 24, 12, dn_per_unit=2.0)
    x = torch.tensor([0.2, 100.0, 1.0e5, 1e9], dtype=torch.float64, requires_grad=True)
    y = m(x)
    assert y[0].item() == 0.0 and y[1].item() == 100.0  # 0.2 e- -> code 0; 100 e- = code 200, slope 1: exact
    assert abs(y[2].item() - 1.0e5) <= 0.5 * 512 / 2.0  # half an output code of the 1/512 segment, in e-
    assert y[2].item() != 1.0e5  # ... and the link did lose something there
    assert y[3].item() == pytest.approx((2 ** 24 - 1) / 2.0)  # clipped at the top input code
    y.sum().backward()
    assert torch.equal(x.grad, torch.ones(4, dtype=torch.float64))  # straight-through
