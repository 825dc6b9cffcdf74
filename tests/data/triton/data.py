"""The Triton kernels run by Triton's interpreter on the CPU (``TRITON_INTERPRET=1``, set before Triton is
imported: run as ``TRITON_INTERPRET=1 python -m tests.data.triton.data``), each against the torch form it stands
in for, through the library's own dispatch (the kernels' readiness test, which asks for CUDA tensors, is widened
to CPU tensors here). Prints one ``OK <name>`` line per check, or ``SKIP <why>`` when Triton is not installed;
an assertion error ends it with a non-zero status."""
from __future__ import annotations

import math
import os
import sys
import warnings

import torch


def main() -> int:
    if os.environ.get("TRITON_INTERPRET") != "1":
        print("SKIP TRITON_INTERPRET=1 is not set")
        return 0
    try:
        import triton  # noqa: F401
    except ImportError:
        print("SKIP Triton is not installed")
        return 0
    import numpy as np

    from lfmbench.counter_rng import derive_key
    from lfmbench.datasets import device as D
    from lfmbench.datasets import batch_compose as BC
    from lfmbench.datasets import batched as BT
    from lfmbench.datasets import row_gather as RG
    from lfmbench.sensor import counter_noise as CN
    from lfmbench.triton_kernels import TritonKernels

    TritonKernels.ready = lambda self, t: self.enabled and self.module() is not None
    CN.kernels_ready = lambda t: CN.USE_TRITON and CN._KERNELS.module() is not None
    warnings.simplefilter("error", RuntimeWarning)  # a kernel that fails (and falls back) fails the check
    torch.set_num_threads(1)

    # 1. the row gather: index_select, bit for bit
    g = torch.Generator().manual_seed(0)
    table, idx = torch.rand(50, 7, generator=g), torch.randint(0, 50, (300,), generator=g)
    assert torch.equal(RG._KERNELS.call("gather_rows", table, idx), table.index_select(0, idx))
    print("OK gather_rows")

    # 2. counter noise: Poisson and normal draws of the kernels against the torch form (the same integer hashing;
    #    numpy's and torch's float64 libm may round a function differently: 1 draw in 10,000 may move, by a few counts)
    rng = np.random.default_rng(2)
    mean = torch.tensor(np.stack([np.concatenate([[0.0, 0.5, 3.0, 40.0, 900.0, 2e4], rng.gamma(0.5, 40.0, 800)])] * 2))
    seed = derive_key(1, torch.arange(2))
    for above in (1000.0, math.inf):
        CN.USE_TRITON = True
        tri = CN.poisson(mean, seed, above)
        assert CN.USE_TRITON
        CN.USE_TRITON = False
        ref = CN.poisson(mean, seed, above)
        diff = tri != ref
        assert diff.double().mean() <= 1e-4 and bool((torch.abs(tri - ref)[diff] <= 3 * mean[diff].sqrt() + 3).all())
    CN.USE_TRITON = True
    z = CN.normal(seed, 500)
    CN.USE_TRITON = False
    assert torch.allclose(z, CN.normal(seed, 500), rtol=1e-13, atol=1e-13)
    CN.USE_TRITON = True
    print("OK counter poisson, normal")

    # 3. the fused sensor chain against the torch chain (as tests/sensor/test_counter_noise.py on a GPU)
    from lfmbench.sensor import fixed_pattern, load_preset, simulate_split_pixel_electrons
    from lfmbench.sensor.fused import PatternCrops, chain_triton

    preset = load_preset("ovt")
    scale = torch.tensor([0.3, 30.0, 3000.0]).view(3, 1, 1, 1, 1)
    lpd = torch.rand(3, 2, 1, 12, 10, generator=g) * scale
    spd = torch.rand(3, 2, 1, 12, 10, generator=g) * scale * 20
    crops = PatternCrops(fixed_pattern(preset, 30, 40), torch.tensor([[0, 0], [5, 7], [18, 30]]), (12, 10))
    ts, tl_ = torch.tensor([1e-3, 2e-3, 5e-3])[:, None], torch.tensor([11e-3, 11e-3, 10e-3])[:, None]
    seeds = derive_key(9, torch.arange(3))
    import lfmbench.sensor.noise as NZ

    calls = []

    def counted(*a, **k):
        calls.append(1)
        return chain_triton(*a, **k)

    NZ.chain_triton = counted
    NZ._poisson.available = lambda: False  # else the CPU takes the numba chain (chain_fused)
    fused = simulate_split_pixel_electrons(lpd, spd, preset, ts, tl_, fpn=crops.to("cpu", torch.float32),
                                           seeds=seeds, check=False)
    assert calls
    ref = simulate_split_pixel_electrons(lpd, spd, preset, ts, tl_, fpn=crops.to("cpu", torch.float32), seeds=seeds,
                                         check=False, backend="torch")
    for k in ref:
        f, t = fused[k], ref[k]
        assert f.shape == t.shape and f.dtype == t.dtype, k
        assert (f.round() != t.round() if k.endswith("_e") else f != t).double().mean() <= 1e-3, k
    print("OK sensor chain")

    # 4. the device program's crops and lamp entries, and the batched composition (tests/datasets on a GPU)
    import tempfile
    from pathlib import Path

    from lfmbench.datasets import LFMCaptureDataset
    from lfmbench.datasets.batched import tensor_leaves
    from tests.data.corpus.data import make_corpus

    with tempfile.TemporaryDirectory() as d:
        root = make_corpus(Path(d) / "c", n_scenes=2)
        ds = LFMCaptureDataset(root, split="all", frames=3, crop=(12, 16), samples_per_scene=2,
                               outputs=("raw", "input_referred", "saturated", "gt", "light_index", "depth"),
                               noise_streams="counter")
        db = D.DeviceBatches(ds, batch_size=4, device="cpu", seed=1)
        a = db.pieces(range(4))
        D._ENTRY_KERNELS.enabled = False
        b = db.pieces(range(4))
        D._ENTRY_KERNELS.enabled = True
        assert a["entry_pix"].shape[0] > 0
        for k in ("entry_pix", "entry_slot", "entry_values", "static", "light_index", "depth"):
            if k in b:
                assert torch.equal(a[k], b[k]), k
        print("OK device crops and entries")
        tri = BT.simulate_batch(a, ds.preset, noise_streams="counter")
        BC._COMPOSE_KERNELS.enabled = False
        ref = BT.simulate_batch(b, ds.preset, noise_streams="counter")
        BC._COMPOSE_KERNELS.enabled = True
        xs, ys = dict(tensor_leaves(tri)), dict(tensor_leaves(ref))
        assert xs.keys() == ys.keys()
        for k in xs:  # float32 sums in another order: within rounding; a count may move where a mean moved
            x, y = xs[k], ys[k]
            assert x.shape == y.shape and x.dtype == y.dtype, k
            if x.is_floating_point():
                close = torch.isclose(x, y, rtol=1e-5, atol=1e-5 * float(y.abs().max() if y.numel() else 1))
                assert close.double().mean() >= 0.999, k
            else:
                assert (x != y).double().mean() <= 2e-3, k
        print("OK batched composition")
    return 0


if __name__ == "__main__":
    sys.exit(main())
