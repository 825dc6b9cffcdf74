"""Import the released ISET-LFM dataset (Jamdar et al., ISETAuto scenes rendered by PBRT) into an lfmbench corpus.

Source layout (the upstream ISET-LFM repository, https://github.com/AyushJam/iset-lfm, its released dataset layout)::

    SRC/<SceneID>/<SceneID>_<group>/{lpd,spd}/01.exr .. 03.exr      group in headlights, streetlights,
                                                                    otherlights, skymap
    SRC/<SceneID>/<SceneID>_lf.mat        MATLAB struct ``sceneMeta`` (depthMap, instanceMap, objectslist,
                                          cameraSpeed [m/s], lpd_exposure [s], spd_exposure [s], fps)

(``<SceneID>_lf.mat`` is also looked for directly in ``SRC``; EXRs in a ``renderings/`` sub-folder of
``lpd``/``spd`` are accepted too, as ISET3D writes them.) Radiance channels are ``S0.<wl>,<frac>nm``
(e.g. ``S0.400,000nm`` = 400.000 nm, 400:10:700 nm), spectral radiance as rendered (no rescaling here:
upstream's 100 cd/m^2 normalisation happens only when ISETCam loads a file). Depth from ``P.X, P.Y, P.Z``
(older files ``Px, Py, Pz``): z-depth = |P.Z|, range = |P| (m); pixels with P = 0 (no surface) get +inf.

Mapping to the lfmbench format (``docs/guide/corpus-format.md``): every group becomes a statically stored group with
``short`` = the LPD render and ``long`` = the SPD render of that frame. Upstream renders no time bins, so the
flickering ``otherlights`` group is flagged ``{"flicker": true, "bins": 0}``: datasets fall back to one PWM
weight per frame and exposure (upstream's Option B). There are no per-light layers or ids upstream, so
``meta.json`` has no lights and ``mask.light`` is -1; ``mask.instance`` comes from an ``InstanceId`` channel, else
the ``.mat`` instanceMap, else -1. Timing from the ``.mat`` (defaults when missing, with a warning:
T_S = 4 ms, T_L = 1/90 s, 60 fps, speed unknown); the short window is centred in the long one as in
``docs/guide/contracts.md`` (upstream starts both at the frame start; the centring is our convention).
"""
from __future__ import annotations

import logging
import math
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from lfmbench.corpus import (AUX_CHANNELS, CorpusValueError, CorpusWriter, read_exr)

__all__ = ["ISET_GROUPS", "ISET_DEFAULTS", "IsetLfmScene", "find_scenes", "parse_band_channel",
           "load_scene_meta_mat", "iset_scene_frames", "iset_scene_meta", "import_isetlfm", "ImportReport"]

log = logging.getLogger(__name__)

#: Upstream light groups in upstream order, and which of them flicker (only otherlights upstream).
ISET_GROUPS = ("headlights", "streetlights", "otherlights", "skymap")
ISET_FLICKER = {"headlights": False, "streetlights": False, "otherlights": True, "skymap": False}
#: Values used when the scene's ``.mat`` is missing or lacks a field (ISET-LFM code, https://github.com/AyushJam/iset-lfm: dataset generation).
ISET_DEFAULTS = {
    "lpd_exposure": 0.004,        # s, middle of upstream's U[3, 5] ms
    "spd_exposure": 1.0 / 90.0,   # s (upstream writes 0.0111)
    "fps": 60.0,                  # frames / s
    "cameraSpeed": None,          # m/s, unknown without the .mat
    "fov_x_deg": 40.0,            # deg, ISET horizontal field of view (ISET-LFM code: optics and ISP)
    "line_time_s": 10e-6,         # s, default rolling-shutter line time (docs/guide/contracts.md)
}
#: Channel name of one band: ``S0.400,000nm`` (PBRT / ISET3D), also ``S0.400nm``.
_BAND_RE = re.compile(r"^S0\.(\d+)(?:[,.](\d+))?nm$")
_FRAME_RE = re.compile(r"^(\d+)\.exr$")
_DEPTH_CHANNELS = (("P.X", "P.Y", "P.Z"), ("Px", "Py", "Pz"))
#: Camera-to-world rotation of the OpenCV camera (x right, y down, z forward) looking along world +x in
#: ISO 8855 vehicle axes (x forward, y left, z up), as in render_tools.camera.
_R_WORLD_FROM_CV = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def parse_band_channel(name: str) -> float | None:
    """Wavelength (nm) of an ISET3D band channel (``"S0.400,000nm"`` -> 400.0), None for other channels."""
    m = _BAND_RE.match(name)
    if m is None:
        return None
    frac = m.group(2) or "0"
    return float(f"{m.group(1)}.{frac}")


@dataclass
class IsetLfmScene:
    """One scene of the released dataset: its id, folder, ``{group: {"lpd": {frame: path}, "spd": {...}}}``,
    frame numbers (as in the file names, 1-based upstream) and the ``.mat`` path (or None)."""

    scene_id: str
    root: Path
    files: dict[str, dict[str, dict[int, Path]]]
    frames: list[int]
    mat: Path | None


def _frame_files(d: Path) -> dict[int, Path]:
    for cand in (d, d / "renderings"):
        if cand.is_dir():
            found = {int(m.group(1)): p for p in cand.iterdir() if (m := _FRAME_RE.match(p.name))}
            if found:
                return found
    return {}


def find_scenes(src: str | Path) -> list[IsetLfmScene]:
    """Scan ``src`` for ISET-LFM scene folders; raise ``ValueError`` naming the folder when one is inconsistent
    (a group without lpd or spd frames, or groups / exposures with different frame numbers)."""
    src = Path(src)
    if not src.is_dir():
        raise ValueError(f"src: ISET-LFM dataset folder {src} does not exist")
    scenes = []
    for d in sorted(p for p in src.iterdir() if p.is_dir()):
        sid = d.name
        files: dict[str, dict[str, dict[int, Path]]] = {}
        for g in ISET_GROUPS:
            gdir = d / f"{sid}_{g}"
            if not gdir.is_dir():
                continue
            per = {e: _frame_files(gdir / e) for e in ("lpd", "spd")}
            for e, fr in per.items():
                if not fr:
                    raise ValueError(f"{gdir / e}: no frame EXRs (01.exr, 02.exr, ...) found")
            files[g] = per
        if not files:
            continue
        frame_sets = {(g, e): tuple(sorted(fr)) for g, per in files.items() for e, fr in per.items()}
        ref = next(iter(frame_sets.values()))
        for (g, e), fs in frame_sets.items():
            if fs != ref:
                raise ValueError(f"{d / f'{sid}_{g}' / e}: frames {list(fs)} differ from {list(ref)} of the other "
                                 "groups")
        mat = next((p for p in (d / f"{sid}_lf.mat", src / f"{sid}_lf.mat") if p.is_file()), None)
        scenes.append(IsetLfmScene(sid, d, files, list(ref), mat))
    return scenes


def mat_decoded_bytes(path: Path, cap: int) -> int:
    """Bytes the data elements of a MATLAB v5 ``.mat`` file decode to, counted without keeping them: compressed
    elements (``miCOMPRESSED``, zlib) are inflated in 1 MiB steps and counted, stopping as soon as the count
    passes ``cap`` (returns a value > ``cap`` then); other elements count their declared size. Files of another
    version (v4, v7.3 HDF5): their size. Memory: at most a few MiB whatever the file declares."""
    import struct  # noqa: PLC0415
    import zlib  # noqa: PLC0415

    from lfmbench.fileio import open_regular  # noqa: PLC0415

    with open_regular(path, ".mat file") as fh:
        size = os.fstat(fh.fileno()).st_size
        head = fh.read(128)
        if len(head) < 128 or head[126:128] not in (b"IM", b"MI") or head[124:126] not in (b"\x00\x01", b"\x01\x00"):
            return size
        end = "<" if head[126:128] == b"IM" else ">"
        total = 0
        while total <= cap:
            tag = fh.read(8)
            if len(tag) < 8:
                break
            dtype, nbytes = struct.unpack(end + "II", tag)
            if dtype >> 16:  # small data element: data in the tag itself
                total += dtype >> 16
                continue
            if dtype != 15:  # miCOMPRESSED
                total += nbytes
                fh.seek(nbytes + (-nbytes % 8), 1)
                continue
            d, left = zlib.decompressobj(), nbytes
            while left > 0 and total <= cap:
                chunk = fh.read(min(left, 1 << 16))
                if not chunk:
                    break
                left -= len(chunk)
                buf = d.decompress(chunk, 1 << 20)
                total += len(buf)
                while d.unconsumed_tail and total <= cap:
                    buf = d.decompress(d.unconsumed_tail, 1 << 20)
                    total += len(buf)
            if left > 0:
                fh.seek(left, 1)
        return total


def load_scene_meta_mat(path: Path | None, shape: tuple[int, int] | None = None) -> tuple[dict[str, Any], list[str]]:
    """Read ``sceneMeta`` from ``<SceneID>_lf.mat`` with ``scipy.io.loadmat``; missing fields (or a missing /
    unreadable file, e.g. MATLAB v7.3 HDF5) take :data:`ISET_DEFAULTS`. Returns (values, warning messages).

    Values: lpd_exposure, spd_exposure (s), fps (1/s), cameraSpeed (m/s or None), depthMap (H, W) m or None,
    instanceMap (H, W) or None.

    ``shape`` (H, W): the scene's image size from its EXR headers. The file is read only when its arrays decode to
    at most what that size justifies, two (H, W) float64 maps plus the limit ``mat_bytes``
    (:func:`mat_decoded_bytes`, counted before ``loadmat`` allocates anything); more is a
    :class:`lfmbench.limits.LimitError` naming the file (a compressed .mat of 1 MB can decode to 1 GB).
    """
    if path is not None:
        from lfmbench.limits import LimitError, limit  # noqa: PLC0415

        cap = limit("mat_bytes") + (2 * shape[0] * shape[1] * 8 if shape is not None else 0)
        n = mat_decoded_bytes(Path(path), cap)
        if n > cap:
            raise LimitError(str(path), f"content decoding to more than {cap:,} bytes (two {shape} float64 maps "
                             "plus the margin mat_bytes)", None, "mat_bytes")
    out: dict[str, Any] = {k: ISET_DEFAULTS[k] for k in ("lpd_exposure", "spd_exposure", "fps", "cameraSpeed")}
    out.update(depthMap=None, instanceMap=None)
    notes = []
    if path is None:
        notes.append("no <SceneID>_lf.mat: using default exposures (4 ms / 1/90 s), 60 fps, unknown speed")
        return out, notes
    try:
        import scipy.io  # noqa: PLC0415
        raw = scipy.io.loadmat(str(path), simplify_cells=True)
    except Exception as exc:  # NotImplementedError for v7.3 files, ValueError for corrupt ones
        notes.append(f"{path}: cannot be read by scipy.io.loadmat ({exc}); using defaults")
        return out, notes
    sm = raw.get("sceneMeta")
    if not isinstance(sm, dict):
        notes.append(f"{path}: no struct 'sceneMeta'; using defaults")
        return out, notes
    for k in ("lpd_exposure", "spd_exposure", "fps", "cameraSpeed"):
        if k in sm:
            v = np.asarray(sm[k], dtype=float).ravel()
            if v.size != 1 or not math.isfinite(v[0]) or v[0] < 0 or (k != "cameraSpeed" and v[0] == 0):
                raise ValueError(f"{path}: sceneMeta.{k} must be one finite number "
                                 f"{'>= 0' if k == 'cameraSpeed' else '> 0'}, got {sm[k]!r}")
            out[k] = float(v[0])
        else:
            notes.append(f"{path}: sceneMeta.{k} missing, using {out[k]!r}")
    for k in ("depthMap", "instanceMap"):
        if k in sm:
            a = np.asarray(sm[k], dtype=np.float32)
            if a.ndim == 2:
                out[k] = a
    return out, notes


def _read_frame_exr(path: Path) -> tuple[dict[float, np.ndarray], dict[str, np.ndarray]]:
    parts = read_exr(path)
    ch = parts[0].channels
    bands = {}
    other = {}
    for name, a in ch.items():
        wl = parse_band_channel(name)
        if wl is None:
            other[name] = np.asarray(a, dtype=np.float32)
        else:
            bands[wl] = np.asarray(a, dtype=np.float32)
    if not bands:
        raise ValueError(f"{path}: no spectral channels named like 'S0.400,000nm'")
    return bands, other


def _clean(arr: np.ndarray, path: Path, repair: bool, counts: dict) -> np.ndarray:
    bad = ~np.isfinite(arr) | (arr < 0)
    n = int(bad.sum())
    if n:
        if not repair:
            raise CorpusValueError(f"{path}: {n} NaN/inf/negative radiance values (use --repair to set them to 0)")
        arr = np.where(bad, np.float32(0), arr)
        counts[str(path)] = counts.get(str(path), 0) + n
    return arr


@dataclass
class _Prepared:
    scene: IsetLfmScene
    bands: list[float]
    height: int
    width: int
    mat: dict[str, Any]
    notes: list[str] = field(default_factory=list)


def _prepare(scene: IsetLfmScene) -> _Prepared:
    g0 = next(iter(scene.files))
    f0 = scene.files[g0]["lpd"][scene.frames[0]]
    parts = read_exr(f0, header_only=True)
    names = parts[0].channel_names
    bands = sorted(wl for n in names if (wl := parse_band_channel(n)) is not None)
    if not bands:
        raise ValueError(f"{f0}: no spectral channels named like 'S0.400,000nm'")
    H, W = parts[0].window[2] - parts[0].window[0], parts[0].window[3] - parts[0].window[1]
    mat, notes = load_scene_meta_mat(scene.mat, (H, W))
    return _Prepared(scene, bands, H, W, mat, notes)


def iset_scene_meta(prep: _Prepared) -> dict:
    """``meta.json`` of an imported scene (timing from the ``.mat`` or defaults; see module docstring)."""
    sc, mat = prep.scene, prep.mat
    fps, ts, tl = mat["fps"], mat["lpd_exposure"], mat["spd_exposure"]
    H, W = prep.height, prep.width
    line = ISET_DEFAULTS["line_time_s"]
    readout = H * line
    fov = ISET_DEFAULTS["fov_x_deg"]
    fx = (W / 2) / math.tan(math.radians(fov) / 2)   # pinhole: f = (W/2) / tan(fov_x/2), pixels
    K = [[fx, 0.0, W / 2], [0.0, fx, H / 2], [0.0, 0.0, 1.0]]
    v = mat["cameraSpeed"]
    poses = []
    for n in range(len(sc.frames)):
        pair = []
        for t in (n / fps, n / fps + tl + readout):  # capture-window start and end (s)
            M = np.eye(4)
            M[:3, :3] = _R_WORLD_FROM_CV
            M[0, 3] = (v or 0.0) * t  # upstream: camera translates along its view axis at v (m/s)
            pair.append(M.tolist())
        poses.append(pair)
    bw = float(np.median(np.diff(prep.bands))) if len(prep.bands) > 1 else 10.0
    groups = {g: ({"flicker": True, "bins": 0} if ISET_FLICKER[g] else {"flicker": False}) for g in sc.files}
    return {
        "scene_id": sc.scene_id, "width": W, "height": H, "bands_nm": [float(b) for b in prep.bands],
        "band_width_nm": bw, "fps": fps, "frames": len(sc.frames),
        "timing": {"short_exposure_s": ts, "long_exposure_s": tl, "alignment": "center", "line_time_s": line,
                   "readout_s": readout, "capture_window_s": tl + readout, "bins": 0},
        "camera": {"fov_x_deg": fov, "K": K, "poses": poses, "speed_mps": v, "yaw_rate_rad_s": 0.0},
        "groups": groups, "lights": [],
        "source": {"dataset": "ISET-LFM", "scene_dir": sc.root.name, "frame_files": [f"{f:02d}.exr" for f in
                                                                                    sc.frames],
                   "radiance": "as rendered by PBRT/ISET3D (not rescaled)", "notes": prep.notes},
    }


def _aux(other: dict[str, np.ndarray], mat: dict, H: int, W: int) -> dict[str, np.ndarray]:
    aux = {n: np.full((H, W), -1.0, np.float32) for n in AUX_CHANNELS}
    for names in _DEPTH_CHANNELS:
        if all(n in other for n in names):
            P = np.stack([other[n] for n in names])
            rng = np.sqrt((P.astype(np.float64) ** 2).sum(0)).astype(np.float32)
            z = np.abs(P[2]).astype(np.float32)
            none = rng == 0
            aux["depth.R"] = np.where(none, np.inf, rng).astype(np.float32)
            aux["depth.Z"] = np.where(none, np.inf, z).astype(np.float32)
            break
    else:
        d = mat.get("depthMap")
        if d is not None and d.shape == (H, W):
            d = np.where(np.isfinite(d) & (d > 0), d, np.inf).astype(np.float32)
            aux["depth.Z"] = d
            aux["depth.R"] = d  # upstream stores one depth map; its kind (z or range) is not recorded
        else:
            aux["depth.Z"] = np.full((H, W), np.inf, np.float32)
            aux["depth.R"] = np.full((H, W), np.inf, np.float32)
    inst = other.get("InstanceId")
    if inst is None and mat.get("instanceMap") is not None and mat["instanceMap"].shape == (H, W):
        inst = mat["instanceMap"]
    if inst is not None:
        inst = np.asarray(inst, dtype=np.float32)
        aux["mask.instance"] = np.where(np.isfinite(inst) & (inst >= 0), np.round(inst), -1).astype(np.float32)
    return aux


def iset_scene_frames(prep: _Prepared, *, repair: bool = False, counts: dict | None = None) -> Iterator[dict]:
    """Frame dicts (as ``render_tools.render.render_frames`` yields) of an imported scene."""
    counts = {} if counts is None else counts
    sc = prep.scene
    for n, fnum in enumerate(sc.frames):
        static = {}
        aux_src: dict[str, np.ndarray] = {}
        for g, per in sc.files.items():
            wins = {}
            for e, win in (("lpd", "short"), ("spd", "long")):
                path = per[e][fnum]
                bands, other = _read_frame_exr(path)
                miss = [b for b in prep.bands if b not in bands]
                if miss or len(bands) != len(prep.bands):
                    raise ValueError(f"{path}: bands {sorted(bands)} differ from {prep.bands} of "
                                     f"{sc.files[next(iter(sc.files))]['lpd'][sc.frames[0]]}")
                arr = np.stack([bands[b] for b in prep.bands])
                if arr.shape[1:] != (prep.height, prep.width):
                    raise ValueError(f"{path}: image is {arr.shape[1:]}, expected ({prep.height}, {prep.width})")
                wins[win] = _clean(arr, path, repair, counts)
                if e == "lpd":  # depth / instance ids: first group's LPD render that has them
                    for k, v in other.items():
                        if k == "InstanceId" or any(k in t for t in _DEPTH_CHANNELS):
                            aux_src.setdefault(k, v)
            static[g] = wins
        yield {"frame": n, "static": static, "lights": {},
               "aux": _aux(aux_src, prep.mat, prep.height, prep.width)}


@dataclass
class ImportReport:
    """What :func:`import_isetlfm` did: scenes imported / skipped (already complete), repaired value counts
    per file, and warnings."""

    imported: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    repaired: dict[str, int] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def import_isetlfm(src: str | Path, out: str | Path, *, scenes: list[str] | None = None, seed: int = 0,
                   dtype: str = "float32", repair: bool = False, resume: bool = True,
                   progress: Callable[[str], None] | None = None) -> ImportReport:
    """Import ISET-LFM scenes from ``src`` into the corpus at ``out`` (created or extended), then write
    ``splits.json`` (seeded, see :func:`lfmbench.corpus.make_splits`).

    Args:
        src: dataset folder holding ``<SceneID>/`` folders.
        out: corpus directory.
        scenes: scene ids to import (default all found).
        seed: split seed.
        dtype: storage (a name of :data:`lfmbench.corpus.STORAGES`): ``"float32"`` (exact copy, default) or
            ``"float16"`` (HALF x per-layer 2^e), ``"compact"``.
        repair: replace NaN / inf / negative radiance by 0 (counted) instead of failing.
        resume: skip scenes already complete in ``out`` (checksums verified).
        progress: called with each scene id when it is done.
    """
    found = find_scenes(src)
    if not found:
        raise ValueError(f"src: no ISET-LFM scenes (<SceneID>/<SceneID>_<group>/lpd/01.exr) under {src}")
    if scenes is not None:
        byid = {s.scene_id: s for s in found}
        unknown = [s for s in scenes if s not in byid]
        if unknown:
            raise ValueError(f"scenes: {unknown} not found under {src}")
        found = [byid[s] for s in scenes]
    writer = CorpusWriter(out, dtype=dtype)
    rep = ImportReport()
    for sc in found:
        if resume and writer.is_complete(sc.scene_id):
            rep.skipped.append(sc.scene_id)
        else:
            prep = _prepare(sc)
            for msg in prep.notes:
                warnings.warn(f"scene {sc.scene_id}: {msg}", stacklevel=2)
                rep.warnings.append(f"scene {sc.scene_id}: {msg}")
            meta = iset_scene_meta(prep)
            # the scene's folder relative to the dataset folder: no path of the importing machine in the corpus
            # (the same download imported anywhere gives the same files and hashes)
            scene = {"source": "ISET-LFM", "scene_id": sc.scene_id, "dataset_dir": sc.root.name,
                     "imported_by": "lfmbench import-isetlfm"}
            writer.write_scene(sc.scene_id, scene, meta, iset_scene_frames(prep, repair=repair, counts=rep.repaired))
            rep.imported.append(sc.scene_id)
        if progress is not None:
            progress(sc.scene_id)
    writer.write_splits(seed)
    rep.warnings.extend(writer.notes)
    return rep
