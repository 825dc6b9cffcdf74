"""The bench's sequences computed in a forked process beside the phase map (``run_bench``'s default where two
CPUs are usable) equal those computed in the caller's process, column by column; the child really ran."""
from __future__ import annotations

import numpy as np
import pytest

from lfmbench.flicker_bench import run as fbr
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
