"""Shared fixtures of the test suite. Fake data comes from ``tests/data/<name>/data.py`` (import those modules;
test modules never import each other)."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

# the repository root, so that ``tests.data`` imports the same way under ``pytest`` and ``python -m pytest``
_ROOT = str(Path(__file__).resolve().parents[1])
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)


@pytest.fixture
def fake(monkeypatch):
    """``render_tools.jobs.default_backend`` replaced by the fake renderer of ``tests/data/render/data.py``;
    yields the list of scene ids it was called for."""
    from render_tools import jobs as J
    from tests.data.render.data import CALLS, FAIL, fake_backend

    CALLS.clear()
    FAIL.clear()
    monkeypatch.setattr(J, "default_backend", fake_backend)
    yield CALLS
    FAIL.clear()


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """A 3-scene fake corpus (``tests.data.corpus.data.make_corpus``, 16 x 24 px, 3 frames), shared by the tests
    of a module (a module may define its own ``corpus``)."""
    from tests.data.corpus.data import make_corpus

    return make_corpus(tmp_path_factory.mktemp("corpus"))
