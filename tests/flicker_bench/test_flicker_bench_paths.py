"""The bench's faster paths against the plain ones: the sequences computed in a forked process beside the phase map
(``run_bench``'s default where two CPUs are usable) equal those computed in the caller's process, column by column
(the child really ran); the vectorised reduction of the linear pieces equals a plain loop over the pieces."""
from __future__ import annotations

import numpy as np
import pytest

from lfmbench.flicker_bench import run as fbr
from lfmbench.flicker_bench.exact import reduce_pieces
from lfmbench.flicker_bench.model import build_model
from lfmbench.parallel import can_fork


@pytest.mark.skipif(not can_fork(), reason="needs fork and 2 usable CPUs")
def test_forked_sequences_equal_in_process(monkeypatch):
    model = build_model("ovt")          # 3 captures and 6 merges, two of them bisected
    grid = fbr.Grid(np.array([60.0, 95.0, 1000.0]), np.array([0.1, 0.5]), np.array([10.0, 1e3, 1e5]))
    methods = fbr.bench_methods(model)
    started = []
    real = fbr.start_sequences
    monkeypatch.setattr(fbr, "start_sequences", lambda *a: started.append(1) or real(*a))
    forked = fbr.run_bench(model, grid, methods, frames=30)
    assert started and "sequence_wait_s" in forked.timings_s
    local = fbr.run_bench(model, grid, methods, frames=30, fork=False)
    assert len(started) == 1                          # fork=False started nothing
    assert forked.panels == local.panels
    for p in forked.panels:
        assert forked.columns[p].keys() == local.columns[p].keys()
        for k, v in forked.columns[p].items():
            # the same arithmetic; torch's thread count differs (1 in the child), which may reorder a sum
            np.testing.assert_allclose(v, local.columns[p][k], rtol=1e-12, atol=0, equal_nan=True, err_msg=f"{p} {k}")
    np.testing.assert_array_equal(forked.cover, local.cover)


def _band_loop(yl, yr, lo, hi):
    """Share of [0, 1] where the line yl -> yr lies strictly inside (lo, hi), one piece at a time."""
    d = yr - yl
    if d == 0:
        return 1.0 if lo < yl < hi else 0.0
    t0, t1 = sorted(((lo - yl) / d, (hi - yl) / d if hi != np.inf else np.sign(d) * np.inf))
    return min(max(min(t1, 1.0) - max(t0, 0.0), 0.0), 1.0)


def _reduce_loop(a, b, h, pha, phb, g, n, delta, thr):
    """The reduction written as a loop over the pieces in their order (the first extreme piece wins)."""
    vmin, vmax, pmin, pmax = [np.inf] * n, [-np.inf] * n, [np.nan] * n, [np.nan] * n
    mean, mmp, fdi = [0.0] * n, [0.0] * n, [0.0] * n
    for i, k in enumerate(g):
        lo, lp = (a[i], pha[i]) if a[i] <= b[i] else (b[i], phb[i])
        hi, hp = (a[i], pha[i]) if a[i] >= b[i] else (b[i], phb[i])
        if lo < vmin[k]:
            vmin[k], pmin[k] = lo, lp
        if hi > vmax[k]:
            vmax[k], pmax[k] = hi, hp
        mean[k] += h[i] * 0.5 * (a[i] + b[i])
    for i, k in enumerate(g):
        m = mean[k]
        mmp[k] += h[i] * _band_loop(a[i], b[i], m - delta * m, m + delta * m)
        fdi[k] += h[i] * _band_loop(a[i], b[i], thr, np.inf)
    return tuple(np.array(x) for x in (vmin, vmax, pmin, pmax, mean, mmp, fdi))


def test_reduce_pieces_equals_a_loop():
    rng = np.random.default_rng(3)
    P, n = 400, 23                                    # group 22 gets no piece
    g = rng.integers(0, n - 1, P)                     # unsorted, as the bisected pieces come
    a = rng.choice([1.0, 2.0, 5.0], P) + rng.normal(0, 0.5, P) * (rng.random(P) < 0.7)   # ties and flat pieces
    b = np.where(rng.random(P) < 0.2, a, a + rng.normal(0, 1.0, P))
    h = rng.random(P) / 20
    pha, phb = rng.random(P), rng.random(P)
    got = reduce_pieces(a, b, h, pha, phb, g, n, 0.1, 2.2)
    want = _reduce_loop(a, b, h, pha, phb, g, n, 0.1, 2.2)
    for name, x, y in zip(("vmin", "vmax", "pmin", "pmax"), got[:4], want[:4]):
        np.testing.assert_array_equal(x, y, err_msg=name)   # the same values picked: exact
    for name, x, y in zip(("mean", "mmp", "fdi"), got[4:], want[4:]):
        # sums in another order (numpy's pairwise sum): a few ulp of the largest term
        np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-15, err_msg=name)
    assert got[0][-1] == np.inf and got[1][-1] == -np.inf and got[5][-1] == 0.0
