"""lfmbench.counter_rng against an independent big-integer SplitMix64, the published SplitMix64 outputs, the
compiled Poisson sampler's own streams, and across devices and batch shapes."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from lfmbench import counter_rng as R

M64 = (1 << 64) - 1


def _mix_ref(z: int) -> int:
    """SplitMix64 variant-13 finaliser in Python integers (the algorithm as published)."""
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & M64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & M64
    return z ^ (z >> 31)


def _t(words) -> torch.Tensor:
    return torch.tensor([w - (1 << 64) if w >= 1 << 63 else w for w in words], dtype=torch.int64)


def test_published_splitmix64_outputs():
    # the first outputs of SplitMix64 seeded with 1234567 (as in the reference implementations' tests)
    want = [6457827717110365317, 3203168211198807973, 9817491932198370423, 4593380528125082431,
            16408922859458223821]
    got = [int(v) & M64 for v in R.mix64(_t([(1234567 + (j + 1) * R.GAMMA) & M64 for j in range(5)]))]
    assert got == want
    assert [_mix_ref((1234567 + (j + 1) * R.GAMMA) & M64) for j in range(5)] == want


def test_mix64_and_uniforms_equal_a_big_integer_reference():
    rng = np.random.default_rng(5)
    words = [int(w) for w in rng.integers(0, 2**63, 2000, dtype=np.uint64)] + [0, 1, M64, 1 << 63, (1 << 63) - 1]
    words += [w | (1 << 63) for w in words[:500]]  # the upper half of the range: negative int64 patterns
    assert [int(v) & M64 for v in R.mix64(_t(words))] == [_mix_ref(w) for w in words]
    u = R.uniforms(_t(words), 3, start=2)
    ref = [[((_mix_ref((w + (j + 1) * R.GAMMA) & M64) >> 11) + 0.5) / 2.0**53 for j in range(2, 5)] for w in words]
    assert u.dtype == torch.float64 and torch.equal(u, torch.tensor(ref, dtype=torch.float64))
    assert float(u.min()) > 0.0 and float(u.max()) < 1.0


def test_streams_are_the_compiled_poisson_samplers():
    """Pixel i of a Poisson call seeded s reads the stream keyed mix64(s) + i STRIDE: the numba kernel's own
    uniforms (its ``_uniform``) equal counter_rng's, draw for draw."""
    K = pytest.importorskip("lfmbench.sensor._poisson_kernel")
    seed = 0xDEADBEEF12345678
    base = _mix_ref(seed)
    for i in (0, 1, 7, 12345):
        state = np.uint64((base + i * ((R.GAMMA << R.STRIDE_LOG2) & M64)) & M64)
        want = []
        for _ in range(6):
            u, state = K._uniform(np.uint64(state))
            want.append(u)
        key = _t([(base + i * ((R.GAMMA << R.STRIDE_LOG2) & M64)) & M64])
        assert R.uniforms(key, 6)[0].tolist() == want


def test_a_draw_depends_on_key_and_counter_only():
    keys = R.derive_key(3, 7, torch.arange(64), 1)
    full = R.uniforms(keys, 10)
    assert torch.equal(R.uniforms(keys[17:18], 10), full[17:18])                  # alone or in a batch
    assert torch.equal(R.uniforms(keys, 4, start=6), full[:, 6:])                 # any slice of the stream
    assert torch.equal(R.derive_key(3, 7, torch.arange(64).view(8, 8), 1).flatten(), keys)
    assert len(set(keys.tolist())) == 64                                          # distinct streams
    assert not torch.equal(R.derive_key(3, 8, torch.arange(64), 1), keys)         # the epoch enters
    assert R.derive_key(3, 7, 17, 1) == keys[17]                                  # ints and tensors alike


def test_uniforms_are_uniform_and_independent():
    u = R.uniforms(R.derive_key(11, torch.arange(20000)), 2)
    x, y = u[:, 0].numpy(), u[:, 1].numpy()
    # Kolmogorov-Smirnov distance of 20,000 uniforms: 1.63 / sqrt(n) is the 1 % critical value
    xs = np.sort(x)
    d = np.max(np.maximum(np.arange(1, xs.size + 1) / xs.size - xs, xs - np.arange(xs.size) / xs.size))
    assert d < 1.63 / np.sqrt(xs.size)
    assert abs(np.corrcoef(x, y)[0, 1]) < 4 / np.sqrt(x.size)                     # within 4 s.d. of 0


def test_bad_arguments():
    with pytest.raises(ValueError, match="n must"):
        R.uniforms(R.derive_key(1), -1)
    with pytest.raises(ValueError, match="start must"):
        R.uniforms(R.derive_key(1), 2, start=1.5)
    with pytest.raises(TypeError, match="int64"):
        R.derive_key(torch.arange(3, dtype=torch.int32))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_gives_the_same_bits():
    keys = R.derive_key(3, 7, torch.arange(4096), 1)
    assert torch.equal(R.uniforms(keys.cuda(), 5).cpu(), R.uniforms(keys, 5))
    assert torch.equal(R.derive_key(3, 7, torch.arange(4096, device="cuda"), 1).cpu(), keys)


def test_uniform_at_is_one_draw_of_uniforms():
    keys = R.derive_key(9, torch.arange(100))
    assert torch.equal(torch.stack([R.uniform_at(keys, j) for j in range(3, 7)], -1), R.uniforms(keys, 4, start=3))
