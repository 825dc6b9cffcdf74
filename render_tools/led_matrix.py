"""LED pixel matrices: the ``dots`` lamp face (an array of LED dots on a rectangle), the 5x7 font of message
signs and destination displays, and text laid out on a matrix.

A ``dots`` face (:mod:`render_tools.scene_schema`): ``center`` (m), ``normal``, ``size`` [w, h] (m, the matrix's
extent), ``grid`` [columns, rows], ``dot`` (the lit share of the pitch, (0, 1]) and ``cells`` [[column, row],
...] (the lit dots; row 0 at the top, column 0 at the left seen from the front). Dot (c, r) is a square patch of
``dot * w / columns`` x ``dot * h / rows`` m centred on its cell. One light per pixel row of a message sign
(each row its own scan phase), or a disk of dots for a traffic signal's LED array.

:func:`filled_cells`: the same light with each lit dot spread over its whole cell at ``dot``^2 of its luminance
(the renderer's stand-in for a face whose dots are smaller than a pixel, :func:`render_tools.render.dots_lod`).

Font: the 5x7 dot-matrix glyphs of the Hitachi HD44780 character ROM (A00 table; Hitachi, "HD44780U (LCD-II)
dot matrix liquid crystal display controller/driver", datasheet, character codes 0x20-0x5A), upper case, digits
and a few signs; one blank column between glyphs.
"""
from __future__ import annotations

from types import MappingProxyType
from typing import Mapping

import numpy as np

__all__ = ["FONT_5X7", "GLYPH_W", "GLYPH_H", "MAX_GRID", "MAX_CELLS", "text_columns", "text_cells",
           "disk_cells", "dot_centers", "dots_area", "dots_mesh", "filled_cells"]

GLYPH_W, GLYPH_H = 5, 7
#: Largest matrix a ``dots`` face may declare: (columns, rows).
MAX_GRID = (1024, 256)
#: Most lit dots one light may list (a full 7-row sign of 160 columns lights ~1,000 per row at most).
MAX_CELLS = 4096

_G = {
    "A": "01110 10001 10001 10001 11111 10001 10001", "B": "11110 10001 10001 11110 10001 10001 11110",
    "C": "01110 10001 10000 10000 10000 10001 01110", "D": "11100 10010 10001 10001 10001 10010 11100",
    "E": "11111 10000 10000 11110 10000 10000 11111", "F": "11111 10000 10000 11110 10000 10000 10000",
    "G": "01110 10001 10000 10111 10001 10001 01111", "H": "10001 10001 10001 11111 10001 10001 10001",
    "I": "01110 00100 00100 00100 00100 00100 01110", "J": "00111 00010 00010 00010 00010 10010 01100",
    "K": "10001 10010 10100 11000 10100 10010 10001", "L": "10000 10000 10000 10000 10000 10000 11111",
    "M": "10001 11011 10101 10101 10001 10001 10001", "N": "10001 10001 11001 10101 10011 10001 10001",
    "O": "01110 10001 10001 10001 10001 10001 01110", "P": "11110 10001 10001 11110 10000 10000 10000",
    "Q": "01110 10001 10001 10001 10101 10010 01101", "R": "11110 10001 10001 11110 10100 10010 10001",
    "S": "01111 10000 10000 01110 00001 00001 11110", "T": "11111 00100 00100 00100 00100 00100 00100",
    "U": "10001 10001 10001 10001 10001 10001 01110", "V": "10001 10001 10001 10001 10001 01010 00100",
    "W": "10001 10001 10001 10101 10101 10101 01010", "X": "10001 10001 01010 00100 01010 10001 10001",
    "Y": "10001 10001 10001 01010 00100 00100 00100", "Z": "11111 00001 00010 00100 01000 10000 11111",
    "0": "01110 10001 10011 10101 11001 10001 01110", "1": "00100 01100 00100 00100 00100 00100 01110",
    "2": "01110 10001 00001 00010 00100 01000 11111", "3": "11111 00010 00100 00010 00001 10001 01110",
    "4": "00010 00110 01010 10010 11111 00010 00010", "5": "11111 10000 11110 00001 00001 10001 01110",
    "6": "00110 01000 10000 11110 10001 10001 01110", "7": "11111 00001 00010 00100 01000 01000 01000",
    "8": "01110 10001 10001 01110 10001 10001 01110", "9": "01110 10001 10001 01111 00001 00010 01100",
    " ": "00000 00000 00000 00000 00000 00000 00000", "-": "00000 00000 00000 11111 00000 00000 00000",
    ".": "00000 00000 00000 00000 00000 01100 01100", ":": "00000 01100 01100 00000 01100 01100 00000",
    "!": "00100 00100 00100 00100 00100 00000 00100", "/": "00000 00001 00010 00100 01000 10000 00000",
    "<": "00010 00100 01000 10000 01000 00100 00010", ">": "01000 00100 00010 00001 00010 00100 01000",
}
#: character -> 7 rows of 5 dots (1 = lit), top row first.
FONT_5X7: Mapping[str, tuple[str, ...]] = MappingProxyType({c: tuple(g.split()) for c, g in _G.items()})


def text_columns(text: str) -> int:
    """Columns a text takes on a matrix: 5 per glyph and one blank column between glyphs."""
    return max(0, len(text) * (GLYPH_W + 1) - 1)


def text_cells(text: str, grid: tuple[int, int]) -> list[list[int]]:
    """Lit dots ``[[column, row], ...]`` of ``text`` centred on a ``grid`` (columns, rows) matrix.

    Raises ``ValueError`` if a character is not in :data:`FONT_5X7` or the text does not fit (the scene validator
    checks this first and names the field)."""
    cols, rows = int(grid[0]), int(grid[1])
    bad = sorted({c for c in text if c not in FONT_5X7})
    if bad:
        raise ValueError(f"characters {bad} are not in the 5x7 font ({''.join(sorted(FONT_5X7))})")
    need = text_columns(text)
    if need > cols or (text and rows < GLYPH_H):
        raise ValueError(f"text {text!r} needs {need} x {GLYPH_H} dots, the matrix has {cols} x {rows}")
    c0, r0 = (cols - need) // 2, (rows - GLYPH_H) // 2
    out = []
    for k, ch in enumerate(text):
        for r, line in enumerate(FONT_5X7[ch]):
            out += [[c0 + k * (GLYPH_W + 1) + c, r0 + r] for c, bit in enumerate(line) if bit == "1"]
    return sorted(out, key=lambda cr: (cr[1], cr[0]))


def disk_cells(n: int) -> list[list[int]]:
    """Dots of an ``n`` x ``n`` grid whose centres lie inside the inscribed circle (a round LED signal face)."""
    h = (n - 1) / 2
    return [[c, r] for r in range(n) for c in range(n) if (c - h) ** 2 + (r - h) ** 2 <= (n / 2) ** 2 - 0.25]


def dot_centers(face: dict, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """World centres (P, 3) m of the lit dots of a ``dots`` face whose in-plane axes are ``u`` (3,) (to the right
    seen from the front) and ``v`` (3,) (up), as the frame of :mod:`render_tools.mitsuba_scene` gives them."""
    w, h = face["size"]
    cols, rows = face["grid"]
    cells = np.asarray(face["cells"], dtype=float).reshape(-1, 2)
    a = -w / 2 + (cells[:, 0] + 0.5) * w / cols          # along u; column 0 at the left seen from the front
    b = h / 2 - (cells[:, 1] + 0.5) * h / rows           # along v; row 0 at the top
    return np.asarray(face["center"], dtype=float) + a[:, None] * u + b[:, None] * v


def dots_area(face: dict) -> float:
    """Emitting area (m^2) of a ``dots`` face: lit dots x dot size."""
    w, h = face["size"]
    cols, rows = face["grid"]
    d = float(face["dot"])
    return len(face["cells"]) * (d * w / cols) * (d * h / rows)


def dots_mesh(face: dict, u: np.ndarray, v: np.ndarray, offset) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of a ``dots`` face (in-plane axes ``u``, ``v`` as in :func:`dot_centers`) moved by ``offset``
    (3,) m: two per dot, wound counter-clockwise seen from the ``normal`` side (so the one-sided area emitter
    faces along ``normal``). V (4P, 3) m, F (2P, 3)."""
    w, h = face["size"]
    cols, rows = face["grid"]
    hu, hv = 0.5 * float(face["dot"]) * w / cols, 0.5 * float(face["dot"]) * h / rows
    c = dot_centers(face, u, v) + np.asarray(offset, dtype=float)
    corners = np.array([-hu * u - hv * v, hu * u - hv * v, hu * u + hv * v, -hu * u + hv * v])   # (4, 3)
    V = (c[:, None, :] + corners[None]).reshape(-1, 3)
    base = 4 * np.arange(len(c))[:, None]
    F = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    return V, F


def filled_cells(light: dict) -> dict:
    """A copy of a ``dots`` light whose lit dots each fill their whole cell (``dot`` 1) at ``dot``^2 of the
    light's luminance (cd/m^2): the same luminous intensity (cd: luminance x emitting area, and per cell, so a
    text or a disk keeps its shape) and the same spectrum, waveform and driver, without the dark gaps between
    the dots. The renderer's stand-in for a face whose dot pitch projects under a pixel
    (:func:`render_tools.render.dots_lod`): a pixel then sees the cells' mean instead of a few sub-pixel dots
    whose covered share the Monte Carlo estimate has to find (the moire of the dots against the pixel grid is
    left out: docs/benchmarks/render.md, "LED dot faces")."""
    d = float(light["dot"])
    return {**light, "dot": 1.0, "luminance_cd_m2": float(light["luminance_cd_m2"]) * d * d}
