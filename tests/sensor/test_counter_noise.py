"""lfmbench.sensor.counter_noise: the compiled Poisson sampler's algorithm and streams as tensor operations.

Independent answers: the compiled sampler (tests/sensor/test_poisson.py holds it to the Poisson pmf), the Poisson pmf
itself (chi-square), the normal distribution's moments."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import torch

from lfmbench.counter_rng import derive_key
from lfmbench.sensor import counter_noise as CN

MEANS = [0.0, 1e-6, 0.02, 0.7, 3.0, 9.999, 10.0, 10.5, 37.0, 400.0, 999.0, 1000.0, 5e4, 3e6]


def _kernel_draws(mean: np.ndarray, seed: int, gaussian_above: float) -> np.ndarray:
    K = pytest.importorskip("lfmbench.sensor._poisson_kernel")
    out = np.empty_like(mean, dtype=np.float64)
    assert K.kernel(mean.astype(np.float64), out, np.uint64(seed & (2**64 - 1)), gaussian_above) == -1
    return out


@pytest.mark.parametrize("gaussian_above", [1000.0, math.inf])
def test_draws_equal_the_compiled_samplers(gaussian_above):
    # every branch and both sides of its edges, and a scene-like spread of means (the torch form evaluates every
    # branch for every value: kept small, the compiled sampler's own tests hold it to the Poisson pmf)
    rng = np.random.default_rng(1)
    mean = np.concatenate([np.repeat(MEANS, 100), rng.gamma(0.5, 40.0, 3000)])
    seeds = [0x0123456789ABCDEF, 2**63 + 5]
    got = CN.poisson(torch.tensor(np.stack([mean] * 2)),
                     torch.tensor([s - 2**64 if s >= 2**63 else s for s in seeds]), gaussian_above)
    for b, s in enumerate(seeds):
        want = _kernel_draws(mean, s, gaussian_above)
        diff = got[b].numpy() != want
        # libm and torch may round exp / log / lgamma differently in the last bit, which moves a draw that
        # sits on a decision boundary: allowed for at most 1 draw in 1,000 (none seen in 200,000 here), and then
        # by a few counts only
        assert diff.mean() <= 1e-3, (b, diff.sum())
        assert np.all(np.abs(got[b].numpy() - want)[diff] <= 3 * np.sqrt(mean[diff]) + 3)


@pytest.mark.parametrize("mu", [4.0, 25.0])
def test_distribution_is_poisson(mu):
    n = 20_000
    x = CN.poisson(torch.full((1, n), mu), torch.tensor([123])).numpy()[0]
    kmax = int(mu + 6 * math.sqrt(mu) + 6)
    counts = np.bincount(np.minimum(x.astype(np.int64), kmax), minlength=kmax + 1)
    pmf = np.array([math.exp(-mu + k * math.log(mu) - math.lgamma(k + 1)) for k in range(kmax + 1)])
    pmf[-1] = 1.0 - pmf[:-1].sum()
    expect = n * pmf
    keep = expect >= 5
    chi2 = float((((counts - expect) ** 2 / expect)[keep]).sum())
    dof = int(keep.sum()) - 1
    assert chi2 < dof + 5 * math.sqrt(2 * dof), (chi2, dof)  # far above the 99.9 % quantile only if wrong


def test_a_samples_draws_do_not_depend_on_the_batch():
    mean = torch.rand(5, 300, dtype=torch.float64) * 60
    seed = derive_key(4, torch.arange(5))
    full = CN.poisson(mean, seed, 1000.0)
    assert torch.equal(CN.poisson(mean[3:4], seed[3:4], 1000.0), full[3:4])
    assert torch.equal(CN.normal(seed[2:3], 300), CN.normal(seed, 300)[2:3])
    assert not torch.equal(full[0], full[1])


def test_normals_have_the_moments_of_a_standard_normal():
    z = CN.normal(derive_key(8, torch.arange(4)), 50_000).flatten().numpy()
    n = z.size
    assert abs(z.mean()) < 5 / math.sqrt(n) and abs(z.var() - 1) < 5 * math.sqrt(2 / n)
    assert abs((z ** 3).mean()) < 5 * math.sqrt(15 / n) and abs((z ** 4).mean() - 3) < 5 * math.sqrt(96 / n)


def test_shape_errors_name_the_arguments():
    with pytest.raises(ValueError, match="mean must be"):
        CN.poisson(torch.ones(3), torch.tensor([1]))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
@pytest.mark.parametrize("use_triton", [True, False])
@pytest.mark.parametrize("gaussian_above", [1000.0, math.inf])
def test_cuda_draws_equal_the_cpu_draws(monkeypatch, use_triton, gaussian_above):
    """The torch form and the Triton kernels on a GPU against the torch form on the CPU (libm and CUDA's math
    library may round a float64 function differently: at most 1 draw in 10,000 may move, by a few counts)."""
    monkeypatch.setattr(CN, "USE_TRITON", use_triton)
    rng = np.random.default_rng(2)
    mean = torch.tensor(np.stack([np.concatenate([np.repeat(MEANS, 50), rng.gamma(0.5, 40.0, 50000)])] * 3))
    seed = derive_key(1, torch.arange(3))
    cpu = CN.poisson(mean, seed, gaussian_above)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a Triton kernel that fails to compile must fail this test
        gpu = CN.poisson(mean.cuda(), seed.cuda(), gaussian_above).cpu()
    assert CN.USE_TRITON == use_triton
    diff = cpu != gpu
    assert diff.double().mean() <= 1e-4 and bool((torch.abs(cpu - gpu)[diff] <= 3 * mean[diff].sqrt() + 3).all())
    z_cpu, z_gpu = CN.normal(seed, 20000), CN.normal(seed.cuda(), 20000).cpu()
    assert torch.allclose(z_gpu, z_cpu, rtol=1e-13, atol=1e-13)
    half = CN.poisson(mean[1:2].cuda(), seed[1:2].cuda(), gaussian_above).cpu()
    assert torch.equal(half, gpu[1:2])                                          # alone or in a batch


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_sensor_chain_with_seeds_matches_the_cpu_chain():
    from lfmbench.sensor import fixed_pattern, load_preset, simulate_split_pixel_electrons

    g = torch.Generator().manual_seed(3)
    le = torch.rand(4, 3, 1, 32, 40, generator=g) ** 4 * 3e4
    preset = load_preset("ovt")
    fpn = fixed_pattern(preset, 32, 40)
    seeds = derive_key(5, torch.arange(4))
    cpu = simulate_split_pixel_electrons(le, le * 0.03, preset, 4e-3, 11e-3, fpn=fpn, seeds=seeds)
    gpu = simulate_split_pixel_electrons(le.cuda(), le.cuda() * 0.03, preset, 4e-3, 11e-3,
                                         fpn={k: v.cuda() for k, v in fpn.items()}, seeds=seeds.cuda())
    for k in cpu:
        g, c = gpu[k].cpu(), cpu[k]
        if k.endswith("_e"):  # DN -> e- in float32: the GPU may round a division or a fused multiply-add otherwise
            assert torch.allclose(g, c, rtol=1e-5, atol=1e-5 * float(c.abs().max())), k
        assert (g.round() != c.round() if k.endswith("_e") else g != c).double().mean() <= 1e-3, k  # rare flips


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_sensor_chain_with_seeds_is_the_same_in_torch_and_compiled_and_alone_or_batched(dtype):
    """``simulate_split_pixel_electrons(..., seeds=...)``: the torch chain (what a GPU runs) and the compiled CPU
    chain give the same outputs (bit for bit here; libm may round differently elsewhere), and a sample's outputs do
    not depend on the batch it is in."""
    from dataclasses import replace

    from lfmbench.sensor import fixed_pattern, load_preset, simulate_split_pixel_electrons

    g = torch.Generator().manual_seed(3)
    B, F, H, W = 3, 2, 10, 12
    le = torch.rand(B, F, 1, H, W, generator=g, dtype=dtype) ** 4 * 3e4
    se = le * 0.03
    ovt = load_preset("ovt")
    preset = replace(ovt, photodiodes={k: replace(v, prnu=0.02, dsnu_e=1.5) for k, v in ovt.photodiodes.items()})
    fpn = fixed_pattern(preset, H, W, dtype=dtype)
    seeds = derive_key(5, torch.arange(B))
    run = lambda x, y, s, backend: simulate_split_pixel_electrons(x, y, preset, 4e-3, 11e-3, fpn=fpn,  # noqa: E731
                                                                  backend=backend, seeds=s)
    ref, got = run(le, se, seeds, "torch"), run(le, se, seeds, "numba")
    one = run(le[1:2], se[1:2], seeds[1:2], "torch")
    for k in ref:
        assert torch.equal(ref[k], got[k]), k
        assert torch.equal(one[k], ref[k][1:2]), k
    assert not torch.equal(ref["lpd_hcg"][0], ref["lpd_hcg"][1])
    plain = simulate_split_pixel_electrons(le, se, preset, 4e-3, 11e-3, torch.Generator().manual_seed(0), fpn=fpn)
    for k in ("lpd_hcg_e", "spd_e"):  # the same distribution as the generator path: means within noise
        assert abs(float(ref[k].mean() - plain[k].mean())) < 0.02 * float(plain[k].mean())
    with pytest.raises(ValueError, match="either generator or seeds"):
        simulate_split_pixel_electrons(le, se, preset, 4e-3, 11e-3, g, seeds=seeds)
    with pytest.raises(ValueError, match="2 seeds for a batch of 3"):
        simulate_split_pixel_electrons(le, se, preset, 4e-3, 11e-3, seeds=seeds[:2])


def _chain_inputs():
    """A batch of 3 samples x 2 frames of 12 x 10 px crops of a 30 x 40 px sensor: dark to bright means per sample,
    a NaN, an inf and a huge mean, per-sample exposures, per-sample crop origins (incl. the frame's corners)."""
    from lfmbench.sensor import fixed_pattern, load_preset
    from lfmbench.sensor.fused import PatternCrops

    preset = load_preset("ovt")
    g = torch.Generator().manual_seed(1)
    scale = torch.tensor([0.3, 30.0, 3000.0]).view(3, 1, 1, 1, 1)
    lpd = torch.rand(3, 2, 1, 12, 10, generator=g) * scale
    lpd[0, 0, 0, 0, 0], lpd[0, 0, 0, 0, 1], lpd[1, 0, 0, 0, 0] = float("nan"), float("inf"), 1e9
    spd = torch.rand(3, 2, 1, 12, 10, generator=g) * scale * 20
    origin = torch.tensor([[0, 0], [5, 7], [18, 30]])
    crops = PatternCrops(fixed_pattern(preset, 30, 40), origin, (12, 10))
    ts, tl_ = torch.tensor([1e-3, 2e-3, 5e-3])[:, None], torch.tensor([11e-3, 11e-3, 10e-3])[:, None]
    return preset, lpd, spd, ts, tl_, crops, derive_key(9, torch.arange(3))


def test_pattern_crops_cut_the_whole_frame_maps_at_each_origin():
    """PatternCrops reads as the (B, 1, 1, h, w) crops cut by hand, and the chain gives the same numbers with it
    as with those crops."""
    from lfmbench.sensor import simulate_split_pixel_electrons

    preset, lpd, spd, ts, tl_, crops, seeds = _chain_inputs()
    by_hand = {k: torch.stack([m[y:y + 12, x:x + 10] for y, x in crops.origin.tolist()])[:, None, None]
               for k, m in crops.maps.items()}
    assert set(crops) == set(by_hand) and all(torch.equal(crops[k], by_hand[k]) for k in by_hand)
    a = simulate_split_pixel_electrons(lpd.clone(), spd.clone(), preset, ts, tl_, fpn=crops, seeds=seeds, check=False)
    b = simulate_split_pixel_electrons(lpd.clone(), spd.clone(), preset, ts, tl_, fpn=by_hand, seeds=seeds,
                                       check=False)
    assert all(torch.equal(a[k], b[k]) for k in a)
    with pytest.raises(ValueError, match="fpn: crops"):
        simulate_split_pixel_electrons(lpd[:2], spd[:2], preset, ts[:2], tl_[:2], fpn=crops, seeds=seeds[:2],
                                       check=False)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_triton_chain_equals_the_torch_chain():
    """The fused Triton chain (one pass per photodiode and per capture, whole-frame maps read at each origin)
    against the torch chain on the same GPU: the same float32 steps without fused multiply-adds, so outputs
    agree but where the two float64 noise implementations round a library function differently (<= 1e-3 of the
    values, as the CPU comparison above allows)."""
    from lfmbench.sensor import simulate_split_pixel_electrons

    preset, lpd, spd, ts, tl_, crops, seeds = _chain_inputs()
    dev = torch.device("cuda")
    args = (preset, ts.to(dev), tl_.to(dev))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a Triton kernel that fails to compile must fail this test
        fused = simulate_split_pixel_electrons(lpd.to(dev), spd.to(dev), *args, fpn=crops.to(dev, torch.float32),
                                               seeds=seeds.to(dev), check=False)
    torch_chain = simulate_split_pixel_electrons(lpd.to(dev), spd.to(dev), *args, fpn=crops.to(dev, torch.float32),
                                                 seeds=seeds.to(dev), check=False, backend="torch")
    assert CN.USE_TRITON
    for k in torch_chain:
        f, t = fused[k].cpu(), torch_chain[k].cpu()
        assert f.shape == t.shape and f.dtype == t.dtype, k
        if k.endswith("_e"):  # torch divides by a scalar as a product with its reciprocal on a GPU: 1 float32 ulp
            assert torch.allclose(f, t, rtol=2.5e-7, atol=2.5e-7 * float(t.abs().max())), k
        assert (f.round() != t.round() if k.endswith("_e") else f != t).double().mean() <= 1e-3, k


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_launch_shape_does_not_change_the_chain():
    """The fused chain's kernels draw each pixel from its own stream: the pixels per program and warps (what
    bench_sensor_device --sweep-launch tunes) change how long a block's loops run, never a count."""
    from lfmbench.sensor import _counter_triton as T
    from lfmbench.sensor import simulate_split_pixel_electrons

    preset, lpd, spd, ts, tl_, crops, seeds = _chain_inputs()
    dev = torch.device("cuda")
    args = (lpd.to(dev), spd.to(dev), preset, ts.to(dev), tl_.to(dev))
    kw = dict(fpn=crops.to(dev, torch.float32), seeds=seeds.to(dev), check=False)
    ref = simulate_split_pixel_electrons(*args, **kw)
    saved = dict(T.COLLECT_LAUNCH), dict(T.READOUT_LAUNCH)
    try:
        for (bc, wc), (br, wr) in (((32, 1), (64, 1)), ((128, 2), (1024, 8))):
            T.COLLECT_LAUNCH.update(BLOCK=bc, num_warps=wc)
            T.READOUT_LAUNCH.update(BLOCK=br, num_warps=wr)
            out = simulate_split_pixel_electrons(*args, **kw)
            assert all(torch.equal(out[k], ref[k]) for k in ref), (bc, wc, br, wr)
    finally:
        T.COLLECT_LAUNCH.update(saved[0])
        T.READOUT_LAUNCH.update(saved[1])


def test_chain_seeds_are_the_shot_and_read_seeds():
    seeds = derive_key(11, torch.arange(5))
    shot, read = CN.chain_seeds(seeds, 2, 3)
    assert shot.shape == (2, 5) and read.shape == (3, 5)
    for p in range(2):
        assert torch.equal(shot[p], CN.shot_seed(seeds, p))
    for c in range(3):
        assert torch.equal(read[c], CN.read_seed(seeds, c))
