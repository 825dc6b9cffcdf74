""":class:`Corpus`, the reader of an lfmbench corpus: lazy (one file per frame and light group is decoded
only when asked for), with a small cache so that reading ``short`` then ``long`` decodes the file once.
"""
from __future__ import annotations

import os
from collections import OrderedDict
from pathlib import Path
from typing import Sequence

import numpy as np

from lfmbench.limits import LimitError, brief, limit
from lfmbench.corpus.errors import CorpusChannelError, CorpusFileError, CorpusNotFoundError
from lfmbench.corpus.exr import ExrPart, _check_aux, _check_values, _stack, exr_headers, layer_scale, read_exr
from lfmbench.corpus.meta import (_check_manifest, _check_meta_storage, _load_json, check_splits, inside_root,
                                  load_meta)
from lfmbench.corpus.naming import (AUX_CHANNELS, EMPTY_PART, MANIFEST_NAME, SCENES_DIR, SPLITS_NAME, _group_bins,
                                    bin_channels, bin_prefix, box_inside, frame_dir, group_storage, parse_light_part,
                                    static_channels, steady_channels, STATIC_WINDOWS, static_edges, static_layers,
                                    window_bin_weights)
from lfmbench.corpus.window_layers import LAYERS_FILE, layer_relpath, read_layers_file

__all__ = ["Corpus"]


class Corpus:
    """Read an lfmbench corpus (see ``docs/guide/corpus-format.md``).

    Files are decoded only when a method asks for them; the last ``cache_size`` decoded EXR files are kept in
    memory (so ``read_static(..., "short")`` then ``(..., "long")`` decodes once). OpenEXR 3.x decodes whole
    files, so a call reads every channel of that one frame/group file, never other groups or frames.

    Args:
        root: corpus directory (holds ``manifest.json``).
        check_values: check every array returned for NaN / inf / negative radiance (cheap min/max).
        cache_size: number of decoded EXR files kept (>= 0).

    Example:
        >>> c = Corpus("demo_out/corpus")                                        # doctest: +SKIP
        >>> L = c.read_static(c.scenes[0], 0, "headlights", "short")             # doctest: +SKIP
        >>> L.shape                                                              # doctest: +SKIP
        (C, H, W)
    """

    def __init__(self, root: str | os.PathLike, *, check_values: bool = True, cache_size: int = 4) -> None:
        self.root = Path(root)
        mpath = self.root / MANIFEST_NAME
        if not mpath.is_file():
            raise CorpusNotFoundError(f"no lfmbench corpus at {self.root} ({MANIFEST_NAME} missing): make one with "
                                      "`lfmbench render --out DIR` or `lfmbench import-isetlfm SRC DIR`")
        self.manifest = _check_manifest(_load_json(mpath, "manifest"), mpath)
        self.check_values = bool(check_values)
        if cache_size < 0:
            raise ValueError(f"cache_size must be >= 0, got {cache_size}")
        self._cache_size = int(cache_size)
        self._cache: OrderedDict[Path, list[ExrPart]] = OrderedDict()
        self._meta: dict[str, dict] = {}
        self._inside: set[str] = set()
        self._scene_set = set(self.manifest["scenes"])
        self._frames_checked: set[tuple[str, int]] = set()

    # -- index
    @property
    def scenes(self) -> list[str]:
        """Scene ids recorded as complete in the manifest (sorted)."""
        return sorted(self.manifest["scenes"])

    @property
    def splits(self) -> dict[str, list[str]]:
        """``splits.json`` content ``{"train": [...], "val": [...], "test": [...]}``."""
        path = self.root / SPLITS_NAME
        return check_splits(_load_json(path, "splits file"), path)

    def _scene_dir(self, scene_id: str) -> Path:
        if scene_id not in self._inside and scene_id not in self._scene_set:
            raise KeyError(f"scene {brief(scene_id)} is not in corpus {self.root} (see Corpus.scenes)")
        if scene_id not in self._inside:  # ids were checked with the manifest; symbolic links are resolved here
            inside_root(self.root, f"{SCENES_DIR}/{scene_id}", str(self.root / MANIFEST_NAME))
            self._inside.add(scene_id)
        return self.root / SCENES_DIR / scene_id

    def meta(self, scene_id: str) -> dict:
        """The scene's ``meta.json`` (camera, timing, bands, groups, lights); with static window layers
        (``window_layers.json``, :mod:`lfmbench.corpus.window_layers`) ``timing["window_layers"]`` lists them:
        ``[{"name", "windows_s": [[start_s, length_s], ...], "moves": bool}]``."""
        if scene_id not in self._meta:
            p = self._scene_dir(scene_id) / "meta.json"
            m = load_meta(p)
            _check_meta_storage(m, p)
            layers = read_layers_file(p.parent / LAYERS_FILE, float(m["timing"]["capture_window_s"]))
            if layers:  # static window layers (lfmbench.corpus.window_layers): what captures they serve
                m["timing"]["window_layers"] = [{"name": x["name"], "windows_s": [list(w) for w in x["windows_s"]],
                                                 "moves": x["moves"]} for x in layers]
            self._meta[scene_id] = m
        return self._meta[scene_id]

    def scene(self, scene_id: str) -> dict:
        """The editable scene description ``scene.json`` the scene was rendered from."""
        return _load_json(self._scene_dir(scene_id) / "scene.json", "scene description")

    def path(self, scene_id: str, frame: int, group: str) -> Path:
        """Path of the EXR of ``group`` (or ``"aux"``) in frame ``frame``."""
        return self._scene_dir(scene_id) / frame_dir(frame) / f"{group}.exr"

    def groups(self, scene_id: str) -> dict[str, dict]:
        """``meta.json`` groups: ``{name: {"flicker": bool, ...}}``."""
        return self.meta(scene_id)["groups"]

    # -- decoding
    def _parts(self, path: Path) -> list[ExrPart]:
        if path in self._cache:
            self._cache.move_to_end(path)
            return self._cache[path]
        parts = read_exr(path)
        if self._cache_size:
            self._cache[path] = parts
            while len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        return parts

    def _frame_group(self, scene_id: str, frame: int, group: str) -> tuple[dict, Path]:
        m = self.meta(scene_id)
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or not 0 <= frame < m["frames"]:
            raise ValueError(f"frame must be an integer in [0, {m['frames']}) for scene {brief(scene_id)}, got {brief(frame)}")
        if group not in m["groups"]:
            raise ValueError(f"group {brief(group)} is not in scene {brief(scene_id)} (groups: {sorted(m['groups'])})")
        self._check_frame(scene_id, int(frame))
        return m, self.path(scene_id, frame, group)

    def _check_frame(self, scene_id: str, frame: int) -> None:
        """Refuse a frame whose EXR files (every group of ``meta.json`` and ``aux``) together declare more decoded
        pixel bytes than the limit ``exr_frame_bytes``, from their headers alone, before any of them is decoded
        (each file alone is bounded by ``exr_bytes``); once per frame. ``CorpusFileError`` naming the frame
        folder, the total and the file that took it over; a file missing here is reported when it is read."""
        if (scene_id, frame) in self._frames_checked:
            return
        cap, total = limit("exr_frame_bytes"), 0
        for g in [*self.meta(scene_id)["groups"], "aux"]:
            f = self.path(scene_id, frame, g)
            if not os.path.lexists(f):
                continue
            total += exr_headers(f).decoded_bytes
            if total > cap:
                raise CorpusFileError(str(LimitError(
                    str(f.parent), f"EXR files of one frame declaring {total:,} or more decoded pixel bytes (counted "
                    f"up to {f.name})", None, "exr_frame_bytes")))
        self._frames_checked.add((scene_id, frame))

    @staticmethod
    def _band_list(m: dict, bands: Sequence[float] | None) -> list[float]:
        all_b = [float(b) for b in m["bands_nm"]]
        if bands is None:
            return all_b
        out = []
        for b in bands:
            if not any(abs(float(b) - a) < 1e-6 for a in all_b):
                raise ValueError(f"bands: {brief(b)} nm is not a band of this scene ({all_b[0]:g}..{all_b[-1]:g} nm)")
            out.append(float(b))
        return out

    def read_static(self, scene_id: str, frame: int, group: str, window: str,
                    bands: Sequence[float] | None = None) -> np.ndarray:
        """Time-averaged spectral radiance of a statically stored group over one exposure window.

        Args:
            scene_id, frame, group: which file.
            window: ``"short"`` (LPD) or ``"long"`` (SPD) exposure window.
            bands: band centres (nm) to return, default all of ``meta["bands_nm"]``.

        Returns:
            ndarray (C, H, W) float32, W sr^-1 m^-2 nm^-1.
        """
        m, path = self._frame_group(scene_id, frame, group)
        if group_storage(m, group) != "static":
            raise ValueError(f"group {brief(group)} of scene {brief(scene_id)} is stored per light in time bins: use "
                             "read_light_bins")
        edges = static_edges(m)
        if edges is not None and window in STATIC_WINDOWS:  # format version 4: the exact sum of its time bins
            tm = m["timing"]
            ts, tl = float(tm["short_exposure_s"]), float(tm["long_exposure_s"])
            a, n = ((tl - ts) / 2.0, ts) if window == "short" else (0.0, tl)
            wgt = window_bin_weights(edges, a, n, tol=1e-6)
            _, bins = self.read_static_bins(scene_id, frame, group, bands)
            return np.tensordot(wgt, bins.astype(np.float64), axes=1).astype(np.float32)
        names = static_channels(window, self._band_list(m, bands))
        parts = self._parts(path)
        arr = _stack(parts[0], names, path)
        scale = layer_scale(parts[0], window, path)
        if scale != 1.0:
            arr /= np.float32(scale)  # exact: a power of two
        if arr.shape[1:] != (m["height"], m["width"]):
            raise CorpusChannelError(f"EXR file {path}: image is {arr.shape[1:]}, meta.json says "
                                     f"({m['height']}, {m['width']})")
        if self.check_values:
            _check_values(arr, path, f"[{window}]")
        return arr

    def read_static_layer(self, scene_id: str, frame: int, group: str, name: str,
                          bands: Sequence[float] | None = None) -> np.ndarray:
        """Static window layer ``name`` of a static group (:mod:`lfmbench.corpus.window_layers`): (C, H, W) float32,
        W sr^-1 m^-2 nm^-1, the time average over the layer's windows. ``ValueError`` when the scene does not list
        the layer with files (a scene where nothing moves has none: every window's average is the long window's)."""
        m = self.meta(scene_id)
        lay = next((x for x in m["timing"].get("window_layers", ()) if x["name"] == name), None)
        if lay is None or not lay["moves"]:
            raise ValueError(f"scene {brief(scene_id)} has no stored static window layer {brief(name)} "
                             f"({LAYERS_FILE})")
        if group_storage(m, group) != "static":
            raise ValueError(f"group {brief(group)} of scene {brief(scene_id)} is stored per light in time bins")
        path = self.root / layer_relpath(scene_id, frame, group, name)
        if not path.is_file():
            raise CorpusFileError(f"{path}: missing (listed in {LAYERS_FILE} of scene {scene_id})")
        return self._static_image(self._parts(path)[0], bin_prefix(0, 1), m, bands, path, f"[layer {name}]")

    def _static_image(self, part, w: str, m: dict, bands: Sequence[float] | None, path: Path, label: str
                      ) -> np.ndarray:
        """One static image of an EXR part (channel prefix ``w``), its stored scale undone, checked against meta's
        size (and its values, with ``check_values``): (C, H, W) float32 W sr^-1 m^-2 nm^-1."""
        arr = _stack(part, static_channels(w, self._band_list(m, bands)), path)
        scale = layer_scale(part, w, path)
        if scale != 1.0:
            arr /= np.float32(scale)
        if arr.shape[1:] != (m["height"], m["width"]):
            raise CorpusChannelError(f"EXR file {path}: image is {arr.shape[1:]}, meta.json says "
                                     f"({m['height']}, {m['width']})")
        if self.check_values:
            _check_values(arr, path, label)
        return arr

    def read_static_bins(self, scene_id: str, frame: int, group: str, bands: Sequence[float] | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
        """The static time bins of a statically stored group (format version 4, ``meta.json``
        ``timing.static_edges_s``): ``(edges (B + 1,) s from the frame start, (B, C, H, W) float32 W sr^-1 m^-2
        nm^-1)``, bin k the time average over [edges[k], edges[k + 1]). ``ValueError`` for a scene without them."""
        m, path = self._frame_group(scene_id, frame, group)
        edges = static_edges(m)
        if edges is None:
            raise ValueError(f"scene {brief(scene_id)} has no static time bins (meta.json timing.static_edges_s): "
                             "read_static its short and long windows")
        if group_storage(m, group) != "static":
            raise ValueError(f"group {brief(group)} of scene {brief(scene_id)} is stored per light in time bins: use "
                             "read_light_bins")
        part = self._parts(path)[0]
        out = [self._static_image(part, w, m, bands, path, f"[{w}]") for w in static_layers(m)]
        return np.asarray(edges, dtype=np.float64), np.stack(out)

    def read_light_bins(self, scene_id: str, frame: int, group: str, bands: Sequence[float] | None = None
                        ) -> list[tuple[int, tuple[int, int, int, int], np.ndarray]]:
        """Per-light time bins of a flickering group.

        Returns:
            ``[(light_id, (y0, x0, y1, x1), ndarray (K, C, h, w) float32)]`` sorted by light id; boxes are
            half-open pixel ranges; values are spectral radiance (W sr^-1 m^-2 nm^-1) averaged over each of the
            K bins of the capture window with the light at PWM level 1. Empty list when no light is visible.
            The box is the light's meta.json ``bbox`` of the frame (its part's data window when meta.json
            does not list the light); a version-3 light's ``light<id>`` bins and ``steady<id>`` part (the same
            value in every bin) are assembled into it, zeros elsewhere (``docs/guide/corpus-format.md`` 6.2).
        """
        m, path = self._frame_group(scene_id, frame, group)
        if group_storage(m, group) != "lights":
            raise ValueError(f"group {brief(group)} of scene {brief(scene_id)} is stored as short/long windows "
                             f"(bins 0): use read_static")
        k = _group_bins(m, group)
        bl = self._band_list(m, bands)
        names = [n for row in bin_channels(k, bl) for n in row]
        found: dict[int, dict[bool, tuple]] = {}
        for p in self._parts(path):
            if p.name == EMPTY_PART:
                continue
            kind = parse_light_part(p.name)
            if kind is None:
                raise CorpusChannelError(f"EXR file {path}: unexpected part {brief(p.name)} (want light<id> or "
                                         "steady<id>)")
            lid, steady = kind
            chans = steady_channels(bl) if steady else names
            arr = _stack(p, chans, path)
            if not steady:
                arr = arr.reshape(k, len(bl), p.window[2] - p.window[0], p.window[3] - p.window[1])
            scale = layer_scale(p, None, path)
            if scale != 1.0:
                arr /= np.float32(scale)  # exact: a power of two
            if self.check_values:
                _check_values(arr, path, f"part {brief(p.name)}")
            found.setdefault(lid, {})[steady] = (p.window, arr)
        boxes = {int(lt["id"]): lt.get("bbox") for lt in m.get("lights", [])}
        out = []
        for lid, got in sorted(found.items()):
            if False not in got:
                raise CorpusChannelError(f"EXR file {path}: part 'steady{lid}' without its part 'light{lid}'")
            bb = (boxes.get(lid) or [None] * (frame + 1))[frame]
            wins = [w for w, _ in got.values()]
            box = tuple(int(v) for v in bb) if bb is not None else (
                min(w[0] for w in wins), min(w[1] for w in wins), max(w[2] for w in wins), max(w[3] for w in wins))
            y0, x0, y1, x1 = box
            if not all(box_inside(w, box) for w in wins):
                raise CorpusChannelError(f"EXR file {path}: a data window of light {lid} {wins} is not inside its "
                                         f"box {box} (meta.json bbox[{frame}])")
            (bw, barr) = got[False]
            if len(got) == 1 and bw == box:  # the whole box in bins (format versions 1 and 2, most v3 lights)
                out.append((lid, box, barr))
                continue
            full = np.zeros((k, len(bl), y1 - y0, x1 - x0), np.float32)
            if True in got:  # the same value in every bin; zero where the bins part lies (split_steady)
                (sy0, sx0, sy1, sx1), sarr = got[True]
                full[:, :, sy0 - y0:sy1 - y0, sx0 - x0:sx1 - x0] = sarr
            by0, bx0, by1, bx1 = bw
            full[:, :, by0 - y0:by1 - y0, bx0 - x0:bx1 - x0] += barr
            out.append((lid, box, full))
        return out

    def read_aux(self, scene_id: str, frame: int, names: Sequence[str] | None = None) -> dict[str, np.ndarray]:
        """Aux channels of a frame: ``{name: (H, W) float32}``; depth in m (+inf: no surface), ids -1 = none.

        Args:
            names: subset of :data:`AUX_CHANNELS` (default all).
        """
        m = self.meta(scene_id)
        if not 0 <= int(frame) < m["frames"]:
            raise ValueError(f"frame must be in [0, {m['frames']}) for scene {brief(scene_id)}, got {brief(frame)}")
        names = list(AUX_CHANNELS if names is None else names)
        bad = [n for n in names if n not in AUX_CHANNELS]
        if bad:
            raise ValueError(f"names: unknown aux channels {bad} (known: {AUX_CHANNELS})")
        self._check_frame(scene_id, int(frame))
        path = self.path(scene_id, frame, "aux")
        part = self._parts(path)[0]
        arr = _stack(part, names, path)
        if self.check_values:
            for n, a in zip(names, arr):
                _check_aux(n, a, f"EXR file {path}")
        return {n: a for n, a in zip(names, arr)}
