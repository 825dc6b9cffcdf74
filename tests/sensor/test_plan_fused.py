"""The compiled chain of every capture plan (``simulate_plan_electrons`` backend "numba",
:func:`lfmbench.sensor.fused.chain_plan_fused`) against the torch chain it replaces on the CPU, output for output and
bit for bit (both compute the same float operations in the same order and dtype, so equality is exact, not a
tolerance), and the generator left in the same state (the same number of draws taken)."""
from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from lfmbench.sensor import available_presets, fixed_pattern, load_preset, simulate_plan_electrons

PLANS = [n for n in available_presets() if load_preset(n).architecture != "split_pixel"]


def _custom():
    """A four-read plan with what no shipped plan has: DSNU, dark current and PRNU on both photodiodes, a
    companded read, a read without read noise."""
    p = load_preset("imx490_4read")
    pds = {k: replace(v, dsnu_e=1.5, dark_current_e_per_s=40.0, prnu=0.02) for k, v in p.photodiodes.items()}
    caps = dict(p.captures)
    caps["sp2_lcg"] = replace(caps["sp2_lcg"], read_noise_e=0.0)
    caps["sp1_hcg"] = replace(caps["sp1_hcg"], companding=load_preset("mt9v024").captures["main"].companding)
    return replace(p, name="custom", photodiodes=pds, captures=caps)


def _means(p, dtype, shape=(2, 1, 6, 7)):
    g = torch.Generator().manual_seed(11)
    base = torch.rand(shape, generator=g, dtype=dtype) ** 4 * 2e5
    flat = base.view(-1)
    flat[:6] = torch.tensor([float("nan"), float("inf"), -1.0, 1e30, 0.0, 1e-3], dtype=dtype)
    return ({k: base * (0.3 + i) for i, k in enumerate(p.exposures)},
            {k: 0.01 / 3 ** i for i, k in enumerate(p.exposures)})


def _both(p, mean_e, exp_s, noise, fpn=None):
    outs, gens = [], []
    for backend in ("torch", "numba"):
        g = torch.Generator().manual_seed(5)
        outs.append(simulate_plan_electrons({k: v.clone() for k, v in mean_e.items()}, p, exp_s, g if noise else None,
                                            noise, fpn, check=False, backend=backend))
        gens.append(g)
    return outs, gens


@pytest.mark.parametrize("name", [*PLANS, "custom"])
def test_compiled_plan_chain_is_bit_identical_to_the_torch_chain(name):
    p = _custom() if name == "custom" else load_preset(name)
    for dtype in (torch.float32, torch.float64):
        mean_e, exp_s = _means(p, dtype)
        fpns = [None]
        if name == "custom":   # a crop of a larger pattern (a view, as the dataset passes) and per-sample maps
            full = fixed_pattern(p, 9, 10, dtype=dtype)
            fpns += [{k: v[1:7, 2:9] for k, v in full.items()},
                     {k: torch.stack([v[b:b + 6, b:b + 7] for b in range(2)])[:, None] for k, v in full.items()}]
        for fpn in fpns:
            for noise in (True, False):
                (ref, got), (g_ref, g_got) = _both(p, mean_e, exp_s, noise, fpn)
                assert list(got) == list(ref)
                for k in ref:
                    assert got[k].dtype == ref[k].dtype and got[k].shape == ref[k].shape, k
                    assert torch.equal(got[k], ref[k]), (name, dtype, noise, k)
                assert torch.equal(torch.randn(3, generator=g_ref), torch.randn(3, generator=g_got))
    assert ref["saturated"].any() and not ref["saturated"].all()


def test_plan_backend_is_checked():
    p = load_preset("lofic")
    x = {"hcg": torch.ones(1, 1, 2, 2)}
    with pytest.raises(ValueError, match="backend must be"):
        simulate_plan_electrons(x, p, {"hcg": 0.01}, noise=False, backend="fused")
    with pytest.raises(ValueError, match="backend='numba'"):
        simulate_plan_electrons({"hcg": torch.ones(1, 1, 2, 2).half()}, p, {"hcg": 0.01}, noise=False, backend="numba")
