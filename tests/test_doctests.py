"""The examples in the docstrings of lfmbench (and render_tools) run and give what they show."""
from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import pytest

_ROOT = Path(__file__).resolve().parents[1]
MODULES = sorted(".".join(p.relative_to(_ROOT).with_suffix("").parts)
                 for pkg in ("lfmbench", "render_tools") for p in (_ROOT / pkg).rglob("*.py")
                 if ">>>" in p.read_text(encoding="utf-8"))


def test_there_are_examples():
    assert {"lfmbench.check", "lfmbench.datasets.projection", "render_tools.camera"} <= set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    mod = importlib.import_module(name)
    res = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert res.failed == 0, (f"{res.failed} of {res.attempted} examples of {name} failed (details: "
                             f"pytest --doctest-modules {name.replace('.', '/')}.py)")
