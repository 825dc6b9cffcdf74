"""lfmbench.parallel.start_forked: the child's return value comes back, its exception is raised in the caller, a
child that dies without a word is one clear error."""
from __future__ import annotations

import os

import numpy as np
import pytest

from lfmbench.parallel import can_fork, start_forked

pytestmark = pytest.mark.skipif(not can_fork(), reason="needs fork and 2 usable CPUs")


def test_start_forked_returns_the_childs_value():
    a = np.arange(6.0).reshape(2, 3)
    wait = start_forked(lambda: {"x": a * 2, "pid": os.getpid()}, "the test child")
    out = wait()
    np.testing.assert_array_equal(out["x"], a * 2)
    assert out["pid"] != os.getpid()                    # it ran in another process


def test_start_forked_raises_the_childs_exception():
    def fail():
        raise KeyError("no such panel")

    wait = start_forked(fail, "the test child")
    with pytest.raises(KeyError, match="no such panel"):
        wait()


def test_start_forked_child_killed():
    wait = start_forked(lambda: os._exit(3), "the test child")
    with pytest.raises(RuntimeError, match="the test child ended without a result"):
        wait()
