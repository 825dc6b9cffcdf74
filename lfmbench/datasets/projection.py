r"""Camera-projected radiance: the per-sensor cache behind :class:`~lfmbench.datasets.LFMCaptureDataset`.

Everything from scene radiance to mean photo-electrons is linear: optics (camera equation, cos^4, Airy PSF),
colour filters, QE and the spectral sum. Flicker only scales whole layers (a light's time bin, a window). So
each stored layer is projected once per sensor into a **mosaic electron rate** (e-/s at every pixel, through
that pixel's Bayer filter) for each photodiode:

.. math:: R_{pd}(y, x) = \sum_\lambda w^{pd}_{c(y,x),\lambda}\; \big(\mathrm{PSF}_\lambda * E_\lambda\big)(y, x),
          \qquad E_\lambda = \frac{\pi\,T_{lens}}{4N^2} L_\lambda

with :math:`w` from :func:`lfmbench.sensor.electron_weights` (e- per J m^-2 nm^-1). A capture then needs only
sums of these rates times PWM-weighted times (:mod:`lfmbench.datasets.assembly`). This is exact (no
approximation beyond those of the optics and sensor models): the PSF is applied per band before the
spectral sum. Per-light layers are projected in their bounding box padded by the PSF radius (zero radiance
outside the box, as stored).

Layers of one scene: ``static[pd]`` (F, H, W) e-/s, sum of the static groups over the window that photodiode
integrates (LPD: short, SPD: long), and where the corpus has static time bins (format version 4) ``static[bin<k>]``
(F, H, W) the bins' rates through the LPD (a capture plan's unit photodiode); ``group_static[g][pd]`` (F, H, W) for flickering groups stored without time
bins (imported ISET-LFM data); ``lights[f]`` list of ``(light_id, group, (y0, x0, y1, x1), {pd: (K, h, w)})``.
"""
from __future__ import annotations

import hashlib
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import torch

from lfmbench.sensor import optics as _optics
from lfmbench import sensor as _sensor
from lfmbench.corpus import (LAYERS_FILE, MANIFEST_NAME, SCENES_DIR, Corpus, CorpusFileError, bin_prefix,
                             check_scene_id, frame_dir, group_storage, layer_relpath, sha256_file, static_edges)
from lfmbench.fileio import atomic_torch_save
from lfmbench.vocabulary import PHOTODIODES


def layer_key(name: str) -> str:
    """The key of static window layer ``name`` among a scene's projected static layers (:class:`SceneLayers`)."""
    return f"layer:{name}"

#: Version of the cached layout; bump when the projection changes so stale caches are not reused.
CACHE_VERSION = 2
#: ``aux.exr`` channel behind each dataset output that needs one (every other output works without aux.exr).
AUX_FOR_OUTPUT = {"depth": "depth.Z", "light_index": "mask.light"}
#: Aux channels kept by :func:`build_layers` / :func:`load_or_build` when the caller does not say.
AUX_DEFAULT = ("depth.Z", "mask.light")


@dataclass
class SceneLayers:
    """Projected layers of one scene (see module docstring). Rates in e-/s, float32 tensors."""

    scene_id: str
    static: dict                      # pd -> (F, H, W)
    group_static: dict                # group -> pd -> (F, H, W)   (flickering groups without bins)
    lights: list                      # per frame: [(light_id, group, (y0, x0, y1, x1), {pd: (K, h, w)})]
    aux: dict = field(default_factory=dict)   # name -> (F, H, W) float32 ("depth.Z", "mask.light")


class Projector:
    """Projects corpus radiance through the optics and split-pixel CFA of one sensor preset.

    Args:
        preset: :class:`lfmbench.sensor.SensorPreset`.
        bands_nm: band centres (nm); band_width_nm: box width of each band (nm).
        height, width: full image size (pixels).
        optics: ``True`` applies the preset's lens (PSF per its config), ``False`` only the camera equation.
    """

    def __init__(self, preset, bands_nm: Sequence[float], band_width_nm: float, height: int, width: int,
                 optics: bool = True) -> None:
        self.preset = preset
        self.bands = [float(b) for b in bands_nm]
        self.H, self.W = int(height), int(width)
        cfg = preset.optics
        self.cfg = cfg
        self.use_psf = bool(optics and cfg.psf and cfg.psf_radius_px > 0)
        self.radius = cfg.psf_radius_px if self.use_psf else 0
        self.weights = {pd: _sensor.electron_weights(preset, self.bands, pd, [band_width_nm] * len(self.bands),
                                                     dtype=torch.float32) for pd in PHOTODIODES}   # (3, C)
        self.kernel = None
        if self.use_psf:
            n_w = cfg.f_number * (1.0 + abs(cfg.magnification))
            self.kernel = _optics.airy_kernel(self.bands, n_w, preset.pixel_pitch_m, cfg.psf_radius_px,
                                              cfg.psf_oversample, dtype=torch.float32)
        self.cfa = preset.cfa.index_map(self.H, self.W)                              # (H, W) 0 r, 1 g, 2 b
        self.cos4 = (_optics.cos4_falloff(self.H, self.W, preset.pixel_pitch_m, cfg.focal_length_m)
                     if (optics and cfg.cos4) else None)
        self.factor = float(_optics.radiance_to_irradiance(torch.ones(1, 1, 1), cfg.f_number, cfg.transmittance,
                                                           cfg.magnification)[0, 0, 0])

    def project(self, radiance: np.ndarray, box: tuple[int, int, int, int] | None = None) -> dict:
        """Project (N, C, h, w) spectral radiance (W sr^-1 m^-2 nm^-1) at ``box`` (None = full image).

        Returns:
            ``{pd: (N, h, w) float32 e-/s}`` on the same box (full image: replicate-padded PSF at the border;
            boxes: zero radiance outside the box).
        """
        L = torch.from_numpy(np.ascontiguousarray(radiance, dtype=np.float32))
        y0, x0 = (0, 0) if box is None else box[:2]
        h, w = L.shape[-2:]
        E = L * self.factor
        if self.cos4 is not None:
            E = E * self.cos4[y0:y0 + h, x0:x0 + w]
        if self.use_psf:
            E = _optics.apply_psf(E, self.kernel, padding="replicate" if box is None else "zeros")
        idx = self.cfa[y0:y0 + h, x0:x0 + w]
        out = {}
        for pd in PHOTODIODES:
            rgb = torch.einsum("nchw,kc->nkhw", E, self.weights[pd])                   # (N, 3, h, w)
            out[pd] = torch.gather(rgb, 1, idx.expand(rgb.shape[0], 1, h, w))[:, 0].contiguous()
        return out

    def padded_box(self, box: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
        """``box`` grown by the PSF radius and clipped to the image (half-open y0, x0, y1, x1)."""
        r = self.radius
        y0, x0, y1, x1 = box
        return max(0, y0 - r), max(0, x0 - r), min(self.H, y1 + r), min(self.W, x1 + r)

    def project_box(self, bins: np.ndarray, box: tuple[int, int, int, int]) -> tuple[tuple, dict]:
        """Project a per-light (K, C, h, w) layer; returns the padded box and ``{pd: (K, h', w')}``."""
        pb = self.padded_box(box)
        K, C = bins.shape[:2]
        buf = np.zeros((K, C, pb[2] - pb[0], pb[3] - pb[1]), dtype=np.float32)
        buf[:, :, box[0] - pb[0]:box[2] - pb[0], box[1] - pb[1]:box[3] - pb[1]] = bins
        return pb, self.project(buf, pb)


def unit_projection_preset(preset):
    """The twin of a capture plan's preset whose projected layers every architecture reads: split-pixel shaped, both
    photodiodes of fill factor 1, so ``static["lpd"]`` is the short stored window's rate and ``static["spd"]`` the
    long one's, per unit fill factor (e-/s); a plan's exposure multiplies by its photodiode's fill factor
    (:func:`lfmbench.datasets.plan_frames.compose_plan_frame`). A split-pixel preset is returned unchanged."""
    import dataclasses  # noqa: PLC0415
    from types import MappingProxyType  # noqa: PLC0415

    for pd, spec in preset.photodiodes.items():  # the layers carry one spectral response per plan
        if spec.spectral is not None:
            raise ValueError(f"{preset.source}: field 'photodiodes.{pd}.spectral': the dataset projects the corpus "
                             "through the preset's one 'spectral' response; per-photodiode curves are simulated by "
                             "lfmbench.sensor (ideal_electrons) only")
    if preset.architecture == "split_pixel":
        return preset
    unit = _sensor.PhotodiodeSpec(fill_factor=1.0, full_well_e=1.0)
    # only what the projection reads is kept (pitch, CFA, spectral curves, peak QE, optics): plans with the same
    # pixel and lens share one cache entry (its key is the repr of this preset)
    return dataclasses.replace(preset, name="unit-fill-factor", description="", adc_bits=12, black_level_dn=0.0,
                               saturation_fraction=0.95, shot_noise_gaussian_above_e=1000.0, fpn_seed=0,
                               photodiodes=MappingProxyType({pd: unit for pd in PHOTODIODES}),
                               captures=MappingProxyType({}), source="<unit>", architecture="split_pixel",
                               reference="lpd_hcg", readout=_sensor.plan.Readout(), frame_time_s=None)


def cache_key(preset, meta: dict, groups: Sequence[str], frames: int, optics: bool,
              sources: Mapping[str, str] | None = None, aux: Sequence[str] = AUX_DEFAULT) -> str:
    """Hash of everything the projected layers depend on: preset, optics, bands, groups, frames, the aux
    channels kept and the SHA-256 of every corpus file they are built from (``sources``: relpath -> digest from
    ``manifest.json``), so a re-rendered or re-imported scene gets a new key."""
    desc = {"v": CACHE_VERSION, "preset": repr(preset), "optics": bool(optics), "groups": sorted(groups),
            "frames": int(frames), "bands": meta["bands_nm"], "bw": meta.get("band_width_nm"),
            "aux": sorted(aux),
            "size": [meta["height"], meta["width"]], "sources": dict(sorted((sources or {}).items()))}
    return hashlib.sha256(json.dumps(desc, sort_keys=True, default=str).encode()).hexdigest()[:16]


def aux_channels(outputs: Sequence[str]) -> tuple[str, ...]:
    """The ``aux.exr`` channels a dataset needs for ``outputs``: ``mask.light`` for ``light_index``,
    ``depth.Z`` for ``depth``, nothing otherwise.

    This is the one rule for the optional ``aux.exr`` (``docs/guide/corpus-format.md`` section 6.3): it is read only
    when one of these outputs is asked for, so a corpus without it serves every other output.

    >>> aux_channels(("input_referred", "gt"))
    ()
    >>> aux_channels(("depth", "light_index"))
    ('depth.Z', 'mask.light')
    """
    want = set(outputs)
    return tuple(ch for out, ch in AUX_FOR_OUTPUT.items() if out in want)


def _missing_aux_error(corpus: Corpus, scene_id: str, aux: Sequence[str], rel: str) -> CorpusFileError:
    outs = [o for o, ch in AUX_FOR_OUTPUT.items() if ch in aux]
    return CorpusFileError(f"{corpus.root / rel}: missing; the outputs {outs} need aux.exr (channels "
                           f"{list(aux)}), which scene {scene_id!r} does not have (aux.exr is optional in the "
                           "corpus format): leave these outputs out or render the corpus with aux")


def source_files(corpus: Corpus, scene_id: str, groups: Sequence[str], frames: int,
                 aux: Sequence[str] = AUX_DEFAULT) -> dict[str, str]:
    """``{relpath: SHA-256 from the manifest}`` of the files :func:`build_layers` reads for these groups and
    the first ``frames`` frames (``meta.json``, one EXR per frame and group, and ``aux.exr`` when ``aux``
    names channels; a scene's static window layers, ``window_layers.json`` and each layer's files).

    Raises:
        lfmbench.corpus.CorpusFileError: a file the layers need is not in the manifest (names it), e.g.
            ``aux.exr`` when ``aux`` is not empty and the scene has none.
    """
    files = corpus.manifest["files"]
    rel0 = f"{SCENES_DIR}/{scene_id}"
    want = [f"{rel0}/meta.json"]
    timing = corpus.meta(scene_id)["timing"]
    if "window_layers" in timing:  # static window layers: their list and files (a new layer: a new cache key)
        want.append(f"{rel0}/{LAYERS_FILE}")
    wl = [x["name"] for x in timing.get("window_layers", ()) if x["moves"]]
    for f in range(int(frames)):
        want += [f"{rel0}/{frame_dir(f)}/{g}.exr" for g in groups]
        want += [layer_relpath(scene_id, f, g, n) for n in wl for g in groups
                 if group_storage(corpus.meta(scene_id), g) == "static"
                 and not corpus.meta(scene_id)["groups"][g].get("flicker", False)]
        if aux:
            rel = f"{rel0}/{frame_dir(f)}/aux.exr"
            if rel not in files:
                raise _missing_aux_error(corpus, scene_id, aux, rel)
            want.append(rel)
    missing = [r for r in want if r not in files]
    if missing:
        raise CorpusFileError(f"{corpus.root / MANIFEST_NAME}: scene {scene_id!r} lacks manifest entries "
                              f"{missing[:3]}{' ...' if len(missing) > 3 else ''}")
    return {r: files[r] for r in want}


def build_layers(corpus: Corpus, scene_id: str, preset, groups: Sequence[str] | None, frames: int,
                 optics: bool = True, aux: Sequence[str] = AUX_DEFAULT) -> SceneLayers:
    """Read the requested groups and frames of a scene (nothing else) and project them.

    Args:
        corpus: open corpus; scene_id: which scene.
        preset: sensor preset; groups: groups to include (None = all the scene has); frames: first F frames.
        optics: apply the lens PSF; aux: aux channels to keep ((F, H, W) each); ``aux.exr`` is read only when
            this is not empty (see :func:`aux_channels`).

    Raises:
        lfmbench.corpus.CorpusFileError: ``aux`` is not empty and the scene has no ``aux.exr`` (names the file
            and the outputs that need it).
    """
    meta = corpus.meta(scene_id)
    have = meta["groups"]
    use = list(have) if groups is None else [g for g in groups if g in have]
    proj = Projector(preset, meta["bands_nm"], float(meta.get("band_width_nm", 10.0)), meta["height"],
                     meta["width"], optics)
    H, W = meta["height"], meta["width"]
    static = {pd: torch.zeros(frames, H, W) for pd in PHOTODIODES}
    group_static: dict = {}
    lights: list = []
    window_of = {"lpd": "short", "spd": "long"}
    edges = static_edges(meta)  # static time bins (format version 4): projected too, one layer per bin
    if edges is not None:
        static.update({bin_prefix(k, len(edges) - 1): torch.zeros(frames, H, W) for k in range(len(edges) - 1)})
    # static window layers (lfmbench.corpus.window_layers): projected too, one layer each (a scene where nothing
    # moves stores none: the long window stands for them)
    wl = [x["name"] for x in meta["timing"].get("window_layers", ()) if x["moves"]]
    static.update({layer_key(n): torch.zeros(frames, H, W) for n in wl})
    for f in range(frames):
        per_frame = []
        for g in use:
            flick = bool(have[g].get("flicker", False))
            if edges is not None and not flick and group_storage(meta, g) == "static":
                _, bins = corpus.read_static_bins(scene_id, f, g)
                for k in range(bins.shape[0]):
                    rates = proj.project(bins[k][None])
                    static[bin_prefix(k, bins.shape[0])][f] += rates["lpd"][0]   # the plans' unit photodiode
                # the split pixel's windows: exact sums of the bins (read_static), as from a version-3 corpus
            if wl and not flick and group_storage(meta, g) == "static":
                for n in wl:
                    static[layer_key(n)][f] += proj.project(corpus.read_static_layer(scene_id, f, g, n)[None])["lpd"][0]
            if group_storage(meta, g) == "static":
                for pd in PHOTODIODES:
                    L = corpus.read_static(scene_id, f, g, window_of[pd])
                    rate = proj.project(L[None])[pd][0]
                    if flick:
                        group_static.setdefault(g, {p: torch.zeros(frames, H, W) for p in PHOTODIODES})[pd][f] = rate
                    else:
                        static[pd][f] += rate
            else:
                for light_id, box, bins in corpus.read_light_bins(scene_id, f, g):
                    pb, rates = proj.project_box(bins, tuple(int(v) for v in box))
                    per_frame.append((int(light_id), g, pb, rates))
        lights.append(per_frame)
    aux_out = {}
    if aux:
        rel = f"{SCENES_DIR}/{scene_id}/{frame_dir(0)}/aux.exr"
        if not (corpus.root / rel).is_file():
            raise _missing_aux_error(corpus, scene_id, aux, rel)
        arrs = [corpus.read_aux(scene_id, f, list(aux)) for f in range(frames)]
        aux_out = {n: torch.from_numpy(np.stack([a[n] for a in arrs]).astype(np.float32)) for n in aux}
    return SceneLayers(scene_id, static, group_static, lights, aux_out)


#: Keys of a cache entry (a plain dict of tensors, ints, strings, lists, tuples: ``torch.load(weights_only=True)``).
_ENTRY_KEYS = {"format", "scene_id", "sources", "static", "group_static", "lights", "aux"}
_warned: set[str] = set()


def _warn_once(key: str, msg: str) -> None:
    """One warning per ``key`` and process (a broken cache directory must not flood the log)."""
    if key not in _warned:
        _warned.add(key)
        warnings.warn(msg, CacheWarning, stacklevel=3)


class CacheWarning(UserWarning):
    """The on-disk projection cache could not be read or written; the layers were rebuilt from the corpus."""


def _stamp(root: Path, sources: Mapping[str, str]) -> dict[str, list[int]]:
    """``{relpath: [size (bytes), mtime (ns)]}`` of the source files, recorded in a cache entry."""
    out = {}
    for rel in sources:
        st = (root / rel).stat()
        out[rel] = [int(st.st_size), int(st.st_mtime_ns)]
    return out


def _verify_sources(root: Path, sources: Mapping[str, str]) -> None:
    """Check the SHA-256 of every source file against the manifest (the cache must hold what it lists)."""
    for rel, digest in sources.items():
        p = root / rel
        try:
            ok = sha256_file(p) == digest
        except OSError as exc:
            raise CorpusFileError(f"{p}: cannot read ({exc.strerror or exc})") from None
        if not ok:
            raise CorpusFileError(f"{p}: bad checksum (SHA-256 differs from {root / MANIFEST_NAME}); the file "
                                  "was changed or corrupted after the corpus was written: re-render the scene "
                                  "or run `lfmbench validate`")


def _read_entry(path: Path, scene_id: str, stamps: Mapping[str, list[int]]) -> SceneLayers | None:
    """A cache entry as :class:`SceneLayers`, or None when it is stale (a source file changed on disk).

    Loaded with ``torch.load(weights_only=True)``: tensors and plain containers only, never code. Raises
    ``ValueError`` for an entry that is unreadable or not shaped like one.
    """
    try:
        d = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises many types for a damaged or hostile file
        raise ValueError(f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}") from None
    if not isinstance(d, dict) or set(d) != _ENTRY_KEYS or d["format"] != CACHE_VERSION:
        raise ValueError("not a projection-cache entry of this lfmbench version")
    if d["scene_id"] != scene_id:
        raise ValueError(f"entry is for scene {d['scene_id']!r}")
    if d["sources"] != {k: list(v) for k, v in stamps.items()}:
        return None
    for pd_map in [d["static"], *d["group_static"].values()]:
        if not all(isinstance(pd_map.get(pd), torch.Tensor) for pd in PHOTODIODES):
            raise ValueError("entry lacks a photodiode layer")
    return SceneLayers(scene_id, d["static"], d["group_static"], d["lights"], d["aux"])


def load_or_build(corpus: Corpus, scene_id: str, preset, groups, frames: int, optics: bool,
                  cache_dir: Path | None, aux: Sequence[str] = AUX_DEFAULT) -> SceneLayers:
    """:func:`build_layers` with an on-disk cache under ``cache_dir/<key>/<scene_id>.pt`` (atomic writes).

    The key (:func:`cache_key`) includes the manifest SHA-256 of every file the layers are built from, and an
    entry records those files' size and modification time: a re-rendered scene or a file changed on disk is
    rebuilt, never served from the cache. A new entry is built only from files whose SHA-256 matches the
    manifest (``CorpusFileError`` naming the file otherwise). Entries are read with
    ``torch.load(weights_only=True)``, so a crafted file in a shared corpus cannot run code; an unreadable entry
    is rebuilt with one :class:`CacheWarning`. An unwritable ``cache_dir`` (read-only corpus) gives one
    :class:`CacheWarning` and the layers are used without being stored. ``aux``: the aux channels to keep
    (``aux.exr`` is read only when not empty; :func:`aux_channels`).
    """
    aux = tuple(aux)
    if cache_dir is None:
        return build_layers(corpus, scene_id, preset, groups, frames, optics, aux)
    check_scene_id(scene_id)
    meta = corpus.meta(scene_id)
    use = list(meta["groups"]) if groups is None else [g for g in groups if g in meta["groups"]]
    sources = source_files(corpus, scene_id, use, frames, aux)
    try:
        stamps = _stamp(corpus.root, sources)
    except OSError as exc:
        raise CorpusFileError(f"{exc.filename}: cannot read ({exc.strerror or exc})") from None
    path = Path(cache_dir) / cache_key(preset, meta, use, frames, optics, sources, aux) / f"{scene_id}.pt"
    if path.is_file():
        try:
            layers = _read_entry(path, scene_id, stamps)
        except ValueError as exc:
            _warn_once(str(path), f"projection cache entry {path} is unreadable ({exc}); rebuilding it from the "
                                  "corpus")
            layers = None
        if layers is not None:
            return layers
    _verify_sources(corpus.root, sources)
    layers = build_layers(corpus, scene_id, preset, use, frames, optics, aux)
    if _stamp(corpus.root, sources) != stamps:  # a file changed while it was read: do not store a mix
        return layers
    entry = {"format": CACHE_VERSION, "scene_id": scene_id, "sources": stamps, "static": layers.static,
             "group_static": layers.group_static, "lights": layers.lights, "aux": layers.aux}
    try:
        atomic_torch_save(entry, path)
    except OSError as exc:
        _warn_once(f"write:{cache_dir}", f"cannot write the projection cache in {cache_dir} "
                                         f"({exc.strerror or exc}); going on without it (choose a writable "
                                         "directory with cache_dir= or `lfmbench evaluate --cache-dir`)")
    return layers
