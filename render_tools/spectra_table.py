"""The precomputed spectra table of :mod:`render_tools.spectra` (:data:`render_tools.spectra.TABLE_FILE`): which
spectra it holds and how it is written from colour-science (a maintainer tool: ``python -m
render_tools.spectra_table`` rewrites it; renders only read it).

It sits above the scene generator (it reads the generator's default configuration), so :mod:`render_tools.spectra`
does not import :mod:`render_tools.scene`.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np


from lfmbench.fileio import atomic_write_text, load_yaml
from lfmbench.vocabulary import SPECTRUM_MODELS

from .scene import DEFAULT_CONFIG, empty_scene
from .spectra import (CMF_COLUMNS, CMFS_NAME, TABLE_FILE, _cmfs_colour, relative_spectrum_colour, spectrum_key,
                      wavelengths)

__all__ = ["table_spectra", "write_table"]


def table_spectra() -> list[dict]:
    """The spectrum dicts :func:`write_table` tabulates: every spectrum in the scene generator's default
    configuration (any mapping with a ``model`` key, in file order) and the D65 sky of ``empty_scene``."""
    cfg = load_yaml(DEFAULT_CONFIG)
    found: list[dict] = []

    def walk(x) -> None:
        if isinstance(x, dict):
            if "model" in x and x.get("model") in SPECTRUM_MODELS:
                found.append(dict(x))
                return
            for v in x.values():
                walk(v)
        elif isinstance(x, list):
            for v in x:
                walk(v)

    walk(cfg)
    walk(empty_scene()["sky"])
    out, seen = [], set()
    for spec in found:
        if spectrum_key(spec) not in seen:
            seen.add(spectrum_key(spec))
            out.append(spec)
    return out


def write_table(path: str | os.PathLike = TABLE_FILE) -> Path:
    """Write :data:`TABLE_FILE` from colour-science (atomically): wavelength, the CIE 1931 CMFs and the relative
    spectrum of every :func:`table_spectra` entry on the 1 nm grid, each value as 17 significant digits (the
    float64 read back is the value written). Returns the path."""
    import colour  # noqa: PLC0415

    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    if not np.array_equal(np.asarray(cmfs.wavelengths, float), wavelengths()):
        raise ValueError(f"{CMFS_NAME}: colour-science tabulates it on another grid than 360..830 nm step 1 nm; "
                         "the table would not reproduce its interpolation")
    cols = {"wavelength_nm": wavelengths()}
    cols.update(zip(CMF_COLUMNS, _cmfs_colour().T))
    for spec in table_spectra():
        cols[spectrum_key(spec)] = relative_spectrum_colour(spec)
    bad = [k for k in cols if "," in k or "\n" in k]
    if bad:
        raise ValueError(f"spectra {bad}: a name with a comma cannot be a CSV column")
    data = np.stack(list(cols.values()), -1)
    lines = [f"# written by `python -m render_tools.spectra_table` from colour-science {colour.__version__}; do not edit",
             "# relative spectra (max 1) and CIE 1931 2-degree CMFs on 360..830 nm, 1 nm step (render_tools.spectra)",
             ",".join(cols)]
    lines += [",".join(f"{v:.17g}" for v in row) for row in data]
    path = Path(path)
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path


if __name__ == "__main__":  # pragma: no cover - regenerates the table
    print(write_table())
