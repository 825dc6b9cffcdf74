"""The compiled Poisson sampler (lfmbench.sensor.poisson) against the Poisson pmf, and its determinism contract."""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.stats as st
import torch

from lfmbench.sensor import poisson as P
from lfmbench.sensor import shot_noise

pytestmark = pytest.mark.skipif(not P.available(), reason="numba not importable")


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _chi2_pvalue(x: np.ndarray, mu: float) -> float:
    """Chi-square goodness of fit of integer draws to Poisson(mu); cells with expected count < 20 merged."""
    n = x.size
    lo, hi = int(st.poisson.ppf(1e-7, mu)), int(st.poisson.isf(1e-7, mu)) + 1
    ks = np.arange(lo, hi + 1)
    edges = [ks[0]]
    acc = 0.0
    for k in ks[:-1]:  # merge adjacent cells until each expects >= 20 draws
        acc += st.poisson.pmf(k, mu) * n
        if acc >= 20:
            edges.append(k + 1)
            acc = 0.0
    edges[-1] = hi  # the last cell takes the remainder
    cdf = lambda k: st.poisson.cdf(k - 1, mu)  # noqa: E731  P(X < k)
    expected = [cdf(edges[1])] + [cdf(b) - cdf(a) for a, b in zip(edges[1:-1], edges[2:])]
    expected.append(1.0 - sum(expected))
    observed = [np.sum(x < edges[1])] + [np.sum((x >= a) & (x < b)) for a, b in zip(edges[1:-1], edges[2:])]
    observed.append(np.sum(x >= edges[-1]))
    expected = np.array(expected) * n
    observed = np.array(observed)
    if len(observed) < 2:
        return 1.0 if observed[0] == n else 0.0
    chi2 = float(((observed - expected) ** 2 / np.maximum(expected, 1e-300)).sum())
    return float(st.chi2.sf(chi2, len(observed) - 1))


@pytest.mark.parametrize("mu", [0.01, 0.5, 3.0, 9.999999, 10.0, 10.000001, 37.0, 999.0, 1e5])
def test_distribution_matches_poisson_pmf(mu):
    """Chi-square test against the pmf on both sides of each branch edge (inversion | PTRS at 10)."""
    x = P.poisson(torch.full((200_000,), mu, dtype=torch.float64), _gen(int(mu * 1000) % 997)).numpy()
    assert np.all(x == np.round(x)) and x.min() >= 0
    assert _chi2_pvalue(x, mu) > 1e-4


def test_mixed_means_moments_per_pixel():
    """Heterogeneous means in one call (a per-pixel indexing or stream bug shows here): standardised sums."""
    g = _gen(3)
    mu = torch.from_numpy(np.random.default_rng(0).lognormal(0.0, 2.5, 400_000))  # 0.0003 .. 1e5 e-
    x = P.poisson(mu, g)
    z_mean = float((x - mu).sum() / mu.sum().sqrt())
    # E[(x - mu)^2] = mu: standardise the sum of (x - mu)^2 - mu by its s.d. sqrt(sum(2 mu^2 + mu))
    r = (x - mu) ** 2 - mu
    z_var = float(r.sum() / (2 * mu ** 2 + mu).sum().sqrt())
    assert abs(z_mean) < 5 and abs(z_var) < 5


def test_tiny_zero_and_huge_means():
    g = _gen(4)
    mu = torch.tensor([0.0, 1e-300, 5e-324, 1e-12] * 1000, dtype=torch.float64)
    assert torch.equal(P.poisson(mu, g), torch.zeros_like(mu))
    big = torch.full((100_000,), 1e12, dtype=torch.float64)
    x = P.poisson(big, g)
    assert abs(float(x.mean()) - 1e12) < 5 * math.sqrt(1e12 / 1e5)
    assert float(x.var()) == pytest.approx(1e12, rel=0.03)
    assert torch.isfinite(x).all()
    # beyond 2^52 the rounded normal takes over even with gaussian_above = inf (no int64 overflow in PTRS)
    for mu in (2.0 ** 53, 1e20):
        y = P.poisson(torch.full((20_000,), mu, dtype=torch.float64), g)
        assert torch.isfinite(y).all() and abs(float(y.mean()) / mu - 1) < 5 / math.sqrt(mu * 2e4)
        assert float(((y - mu) ** 2).mean()) / mu == pytest.approx(1.0, rel=0.06)
    y = P.poisson(torch.full((100,), 1e300, dtype=torch.float64), g)   # sqrt(mu) is below float64's spacing
    assert torch.isfinite(y).all() and float((y / 1e300 - 1).abs().max()) < 1e-12
    for backend in ("numba", "torch"):                                 # torch.poisson alone gives -2^63 here
        z = shot_noise(torch.full((1000,), 1e20, dtype=torch.float64), g, float("inf"), backend=backend)
        assert float((z / 1e20 - 1).abs().max()) < 1e-8


def test_pixels_and_seeds_independent():
    mu = torch.full((400_000,), 2.0, dtype=torch.float64)
    a = P.poisson(mu, _gen(5)).numpy()
    b = P.poisson(mu, _gen(6)).numpy()
    tol = 5 / math.sqrt(a.size)
    assert abs(np.corrcoef(a[:-1], a[1:])[0, 1]) < tol        # neighbouring pixels
    assert abs(np.corrcoef(a, b)[0, 1]) < tol                 # two seeds
    c = P.poisson(mu, _gen(5)).numpy()
    assert np.array_equal(a, c)                               # same generator state -> same draws


def test_counter_based_prefix_and_shape_invariance():
    """A pixel's draw depends on (seed, flat index, mean) only: prefixes and reshapes agree."""
    mu = torch.rand(64, 64, dtype=torch.float64, generator=_gen(7)) * 50
    full = P.poisson(mu, _gen(8))
    part = P.poisson(mu.reshape(-1)[:1000], _gen(8))
    assert torch.equal(full.reshape(-1)[:1000], part)
    assert torch.equal(P.poisson(mu.t(), _gen(8)), P.poisson(mu.t().contiguous(), _gen(8)))
    g = _gen(8)
    first, second = P.poisson(mu, g), P.poisson(mu, g)
    assert not torch.equal(first, second)                     # the generator advances


def test_gaussian_branch_and_dtype():
    g = _gen(9)
    mu = torch.full((100_000,), 5000.0, dtype=torch.float32)
    x = P.poisson(mu, g, gaussian_above=1000.0)
    assert x.dtype == torch.float32 and x.shape == mu.shape
    assert float(x.double().mean()) == pytest.approx(5000.0, abs=5 * math.sqrt(5000 / 1e5))
    assert float(x.double().var()) == pytest.approx(5000.0, rel=0.03)
    # switch at 0: every positive mean is a clamped rounded normal; zero stays zero
    y = P.poisson(torch.tensor([0.0] + [0.3] * 9999), g, gaussian_above=0.0)
    assert y[0] == 0 and y.min() >= 0 and float(y[1:].mean()) > 0.3   # clamping at 0 lifts the mean


def test_agrees_with_torch_backend():
    """Two-sample chi-square between the numba and torch backends of shot_noise at a mid mean."""
    mu = torch.full((200_000,), 6.5, dtype=torch.float64)
    a = shot_noise(mu, _gen(10), backend="numba").numpy().astype(int)
    b = shot_noise(mu, _gen(10), backend="torch").numpy().astype(int)
    ks = np.arange(0, 16)
    ca = np.array([np.sum(a == k) for k in ks[:-1]] + [np.sum(a >= ks[-1])])
    cb = np.array([np.sum(b == k) for k in ks[:-1]] + [np.sum(b >= ks[-1])])
    _, p, _, _ = st.chi2_contingency(np.stack([ca, cb]))
    assert p > 1e-4


def test_bad_input_named():
    with pytest.raises(ValueError, match="CPU tensor"):
        P.poisson(torch.ones(3, dtype=torch.int64), _gen(0))
    with pytest.raises(ValueError, match="generator"):
        P.poisson(torch.ones(3), None)
    for bad in (-1e-9, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="finite and >= 0.*flat index 2"):
            P.poisson(torch.tensor([1.0, 0.0, bad, 3.0]), _gen(0))
    with pytest.raises(ValueError, match="backend"):
        shot_noise(torch.ones(3), _gen(0), backend="cuda")


def test_compiled_kernel_reused_from_numba_cache():
    """A second process loads the kernel from numba's on-disk cache instead of compiling it (a closure over
    arrays defeated the cache and cost 0.5-0.8 s in every DataLoader worker). The first process is this one:
    its call compiles the kernel into the cache, or loads it from there (then the cache is there already)."""
    import subprocess
    import sys

    P.poisson(torch.ones(3), torch.Generator())
    script = ("import torch\nfrom lfmbench.sensor import poisson\nfrom lfmbench.sensor._poisson_kernel import kernel\n"
              "poisson.poisson(torch.ones(3), torch.Generator())\n"
              "print(sum(kernel.stats.cache_hits.values()), sum(kernel.stats.cache_misses.values()))")
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    hits, misses = map(int, r.stdout.split())
    assert hits >= 1 and misses == 0


def test_no_import_cycle_between_poisson_and_its_kernel():
    """The shared constant lives in lfmbench.constants: the kernel does not import lfmbench.sensor.poisson."""
    import ast
    import inspect

    import lfmbench.sensor._poisson_kernel as K
    from lfmbench import constants
    from lfmbench.sensor import poisson

    mods = {n.module for n in ast.walk(ast.parse(inspect.getsource(K))) if isinstance(n, ast.ImportFrom)}
    mods |= {a.name for n in ast.walk(ast.parse(inspect.getsource(K))) if isinstance(n, ast.Import) for a in n.names}
    assert "lfmbench.sensor.poisson" not in mods and "lfmbench" not in mods
    assert poisson.EXACT_LIMIT == K._EXACT_LIMIT == constants.POISSON_EXACT_LIMIT == 2.0 ** 52


def _splitmix_uniform(state: int) -> tuple[float, int]:
    """One SplitMix64 step in plain Python integers [Steele2014] (the kernel's ``_uniform``): (u in (0, 1), state)."""
    m = (1 << 64) - 1
    state = (state + 0x9E3779B97F4A7C15) & m
    z = state
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & m
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & m
    z ^= z >> 31
    return ((z >> 11) + 0.5) / 9007199254740992.0, state


def test_inversion_equals_a_plain_sequential_search():
    """Below 10 e- the kernel evaluates the inversion's terms four at a time; the counts must be those of the
    textbook one-term-at-a-time search [Devroye1986] (X.3.3) written here in plain Python, on each pixel's own
    counter-based stream (start mix(seed) + i * 2^20 * gamma): the same uniforms, products and sums, so the same k
    for every pixel, including means where F(k) stalls below u (mu ~ 1e-300), the means below 1 e- where k = 0 is
    decided by a lower bound of exp(-mu) without computing it, and the last k of the table."""
    m64 = (1 << 64) - 1
    mus = np.concatenate([np.geomspace(1e-300, 1e-3, 40), np.linspace(1e-3, 9.999999, 1500),
                          np.full(400, 9.9999), np.full(60, 0.7), np.geomspace(9e-4, 0.3, 300),
                          np.linspace(0.3, 1.7, 2000)])
    seed = 123456789
    out = torch.empty(mus.size, dtype=torch.float64)
    from lfmbench.sensor._poisson_kernel import kernel
    assert kernel(mus, out.numpy(), np.uint64(seed), math.inf) == -1

    def mix(z: int) -> int:
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & m64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & m64
        return z ^ (z >> 31)

    base = mix(seed)
    stride = (0x9E3779B97F4A7C15 << 20) & m64
    ref = []
    for i, mu in enumerate(mus):
        u, _ = _splitmix_uniform((base + i * stride) & m64)
        p = f = math.exp(-mu)
        k = 0
        while u > f and p > 0.0:
            k += 1
            p *= mu * (1.0 / k)
            f += p
        ref.append(k)
    ref = np.array(ref, dtype=np.float64)
    assert np.array_equal(out.numpy(), ref), np.flatnonzero(out.numpy() != ref)[:10]
    assert ref.max() >= 17 and (ref == 0).sum() >= 40                   # both ends of the search exercised
