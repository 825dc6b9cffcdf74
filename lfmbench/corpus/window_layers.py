"""Static window layers of a corpus scene: the static groups' radiance over a named union of capture windows.

A layer (``RenderOptions.static_layers``, :mod:`render_tools.static_layers`) holds, per frame and static group, the
time average of the group's spectral radiance (W sr^-1 m^-2 nm^-1, (C, H, W)) over the union of its windows, e.g.
the chopped preset's 12 sub-windows; a capture whose windows are a layer's is served from it exactly
(:func:`lfmbench.datasets.plan_frames.exposure_static_layer`). Stored beside the scene's other files, none of which
changes when a layer is added (``docs/guide/corpus-format.md``, "Static window layers"):

- ``scenes/<id>/f<NNN>/<group>.layer_<name>.exr``: one part, channels ``bin00.<wl>nm`` (a static file with one
  bin, the union; written as :func:`lfmbench.corpus.encode_static_exr` writes time bins);
- ``scenes/<id>/window_layers.json``: ``{"format": "lfmbench-window-layers", "version": 1, "layers": [{"name",
  "windows_s": [[start_s, length_s], ...], "moves": bool, "render": {...}}]}``, written last (atomically), so a
  layer is listed only once all its files are on disk. ``moves`` false: nothing in the scene moves, no file is
  written and every window's static average is the long window's (served from it, exactly).

The one rule of what a layer may be is :func:`parse_layers` (the renderer's options and this file both use it).
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from lfmbench.corpus.errors import CorpusFileError

__all__ = ["LAYER_NAME", "LAYERS_FILE", "parse_layers", "layers_dict", "layer_relpath", "read_layers_file",
           "encode_layer", "layers_json", "write_layer"]

#: A layer's name: what its files and a capture plan's meta call it.
LAYER_NAME = re.compile(r"[a-z][a-z0-9_]{0,31}")
#: The file listing a scene's layers, under ``scenes/<id>/``.
LAYERS_FILE = "window_layers.json"
_FORMAT = "lfmbench-window-layers"
#: Most windows of one layer.
MAX_WINDOWS = 4096


def parse_layers(value: Any, capture_window_s: float, field: str = "static_layers") -> tuple:
    """``value`` (a list of ``{"name": str, "windows_s": [[start_s, length_s], ...]}``, or the tuple this returns)
    as ``((name, ((start_s, length_s), ...)), ...)`` (s from the frame start). Raises ``ValueError`` naming the
    field (``static_layers[i].windows_s[j]``) for a bad or repeated name, a window of length <= 0, windows out of
    increasing order or overlapping, or one outside the capture window [0, ``capture_window_s``] s."""
    out, names = [], set()
    if value is not None and not isinstance(value, (list, tuple)):
        raise ValueError(f"{field}: must be a list of {{name, windows_s}}, got {type(value).__name__}")
    for i, lay in enumerate(value or ()):
        where = f"{field}[{i}]"
        if isinstance(lay, Mapping):
            if set(lay) != {"name", "windows_s"}:
                raise ValueError(f"{where}: needs exactly the keys name and windows_s, got {sorted(map(str, lay))}")
            name, wins = lay["name"], lay["windows_s"]
        elif isinstance(lay, (tuple, list)) and len(lay) == 2:
            name, wins = lay
        else:
            raise ValueError(f"{where}: must be a mapping {{name, windows_s}}, got {type(lay).__name__}")
        if not isinstance(name, str) or not LAYER_NAME.fullmatch(name):
            raise ValueError(f"{where}.name: must match {LAYER_NAME.pattern}, got {name!r:.40}")
        if name in names:
            raise ValueError(f"{where}.name: {name!r} is given twice")
        names.add(name)
        if not isinstance(wins, (list, tuple)) or not 1 <= len(wins) <= MAX_WINDOWS:
            raise ValueError(f"{where}.windows_s: must be a list of 1-{MAX_WINDOWS} [start_s, length_s] pairs")
        ws, end = [], 0.0
        for j, w in enumerate(wins):
            try:
                if isinstance(w, (str, bytes)) or len(w) != 2:
                    raise TypeError
                a, n = (float(x) for x in w)
            except (TypeError, ValueError):
                raise ValueError(f"{where}.windows_s[{j}]: must be a pair [start_s, length_s] of numbers, got "
                                 f"{w!r:.60}") from None
            if not (np.isfinite(a) and np.isfinite(n) and n > 0 and a >= 0):
                raise ValueError(f"{where}.windows_s[{j}]: needs start >= 0 s and length > 0 s, got [{a}, {n}]")
            if a + n > capture_window_s * (1 + 1e-9):
                raise ValueError(f"{where}.windows_s[{j}]: ends at {(a + n) * 1e3:.6g} ms, after the capture window "
                                 f"of {capture_window_s * 1e3:.6g} ms")
            if j and a < end - 1e-12:
                raise ValueError(f"{where}.windows_s[{j}]: starts at {a * 1e3:.6g} ms, before the previous window "
                                 f"ends ({end * 1e3:.6g} ms): windows must be in increasing order and not overlap")
            ws.append((a, n))
            end = a + n
        out.append((name, tuple(ws)))
    return tuple(out)


def layers_dict(layers: Sequence) -> list[dict]:
    """The JSON form of :func:`parse_layers`'s tuple: ``[{"name", "windows_s": [[start_s, length_s], ...]}]``."""
    return [{"name": n, "windows_s": [[float(a), float(b)] for a, b in w]} for n, w in layers]


def layer_relpath(scene_id: str, frame: int, group: str, name: str) -> str:
    """Relative path (from the corpus root) of a layer's file for one frame and static group."""
    return f"scenes/{scene_id}/f{int(frame):03d}/{group}.layer_{name}.exr"


def read_layers_file(path: str | Path, capture_window_s: float) -> list[dict]:
    """The layers listed in a scene's :data:`LAYERS_FILE` (``[]`` when there is none): ``[{"name", "windows_s":
    ((start_s, length_s), ...), "moves": bool, "render": dict}]``. ``CorpusFileError`` naming the file and field
    for a malformed one."""
    from lfmbench.fileio import load_json  # noqa: PLC0415

    p = Path(path)
    if not p.is_file():
        return []
    try:
        d = load_json(p, "window layers")
        if not isinstance(d, dict) or d.get("format") != _FORMAT or d.get("version") != 1:
            raise ValueError(f"format/version: must be {_FORMAT!r} version 1")
        items = d.get("layers")
        if not isinstance(items, list):
            raise ValueError("layers: must be a list")
        parsed = parse_layers([{"name": x.get("name"), "windows_s": x.get("windows_s")} if isinstance(x, dict)
                               else x for x in items], capture_window_s, "layers")
        out = []
        for i, ((name, wins), x) in enumerate(zip(parsed, items)):
            if not isinstance(x.get("moves"), bool):
                raise ValueError(f"layers[{i}].moves: must be true or false")
            out.append({"name": name, "windows_s": wins, "moves": x["moves"], "render": dict(x.get("render") or {})})
        return out
    except (ValueError, OSError) as exc:
        raise CorpusFileError(f"{p}: {exc}") from None


def layers_json(old: Iterable[Mapping[str, Any]], new: Iterable[Mapping[str, Any]]) -> dict:
    """The content of :data:`LAYERS_FILE` listing the layers ``old`` (as :func:`read_layers_file` returns them)
    and ``new`` (same keys) in that order."""
    return {"format": _FORMAT, "version": 1,
            "layers": [{"name": x["name"], "windows_s": [[float(a), float(b)] for a, b in x["windows_s"]],
                        "moves": bool(x["moves"]), "render": dict(x.get("render") or {})}
                       for x in [*old, *new]]}


def encode_layer(img: np.ndarray, bands_nm: Sequence[float], dtype, attrs: Mapping[str, Any], what: str) -> bytes:
    """EXR bytes of one layer image (C, H, W) float32 W sr^-1 m^-2 nm^-1: a static file with one bin."""
    from lfmbench.corpus.exr_encode import encode_static_exr  # noqa: PLC0415

    return encode_static_exr({"bins": np.asarray(img, np.float32)[None]}, bands_nm, dtype=dtype, attrs=attrs,
                             what=what)


def write_layer(root: str | Path, scene_id: str, meta: Mapping[str, Any], name: str, windows: Sequence,
                moves: bool, frames: Iterable[tuple[int, Mapping[str, np.ndarray]]], dtype,
                render: Mapping[str, Any] | None = None) -> dict[str, str]:
    """Write static window layer ``name`` (``windows``: [(start_s, length_s)]) of scene ``scene_id`` under corpus
    ``root``: each frame's images (``frames``: ``(frame, {group: (C, H, W) float32 W sr^-1 m^-2 nm^-1})``, none when
    ``moves`` is False) as files (atomically, temporary name then rename), then the scene's :data:`LAYERS_FILE`
    listing the layers it had and this one (written last: a layer is listed only once its files are all there).
    Files the scene already has are not touched. ``meta``: the scene's meta.json content (bands, size, capture
    window); ``dtype``: the corpus's storage. Returns ``{relpath: sha256}`` of the files written. ``ValueError``
    naming the file for a layer the scene lists already, or images of the wrong size, before anything is written
    for the frame at fault."""
    from lfmbench.corpus.scene_files import write_files  # noqa: PLC0415
    from lfmbench.fileio import atomic_write_json  # noqa: PLC0415

    root = Path(root)
    lpath = root / "scenes" / scene_id / LAYERS_FILE
    cw = float(meta["timing"]["capture_window_s"])
    (name, wins), = parse_layers([{"name": name, "windows_s": [list(w) for w in windows]}], cw)
    old = read_layers_file(lpath, cw)
    if any(x["name"] == name for x in old):
        raise ValueError(f"{lpath}: lists layer {name!r} already (a new layer needs a new name)")
    bands, shape = meta["bands_nm"], (len(meta["bands_nm"]), int(meta["height"]), int(meta["width"]))

    def files():
        for f, imgs in frames:
            for g, img in sorted(imgs.items()):
                what = f"scene {scene_id} frame {f} {g} layer {name}"
                if np.shape(img) != shape:
                    raise ValueError(f"{what}: image is {np.shape(img)}, meta.json says {shape}")
                yield layer_relpath(scene_id, f, g, name), encode_layer(
                    img, bands, dtype, {"lfmbench_scene_id": scene_id, "lfmbench_frame": int(f),
                                        "lfmbench_group": g}, what)

    hashes = write_files(root, files()) if moves else {}
    new = {"name": name, "windows_s": wins, "moves": bool(moves), "render": dict(render or {})}
    hashes[f"scenes/{scene_id}/{LAYERS_FILE}"] = atomic_write_json(lpath, layers_json(old, [new]))
    return hashes
