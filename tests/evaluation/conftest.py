"""Shared by the evaluation tests: the study scripts of benchmarks/studies loaded as modules."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

STUDIES = Path(__file__).resolve().parents[2] / "benchmarks" / "studies"


def _load(name: str):
    """``benchmarks/studies/<name>.py`` as a module (the folder is no package), under a name of its own."""
    spec = importlib.util.spec_from_file_location(f"{name}_study", STUDIES / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="session")
def load_study():
    """The loader of the study scripts: ``load_study(name)`` -> the module ``benchmarks/studies/<name>.py``."""
    return _load
