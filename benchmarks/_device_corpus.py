"""The corpus of ``bench_device_path.py``: random radiance, or the radiance of rendered scenes (``--levels``), in
the corpus format, written here.

Why rendered levels: the sensor chain's Poisson sampler costs differently per electron level (search under ~10
e-, rejection to ~1,000 e-, Gaussian above); random radiance put every pixel at 10-1,000 e-.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np


#: The synthetic corpus's four bands (nm): centres of the 31 rendered 10-nm bands (400-700 nm) taken in groups
#: of 8, 8, 8 and 7 (:func:`extract_levels`).
LEVEL_BANDS = (435.0, 515.0, 595.0, 670.0)
#: Each grouped band's width (nm): 310 nm / 4, so that sum(band radiance x width) equals the rendered bands' sum
#: (radiance x 10 nm) exactly.
LEVEL_BAND_WIDTH = 77.5


def _group_bands(arr: np.ndarray, bands: list[float]) -> np.ndarray:
    """(..., 31, H, W) radiance at 10-nm bands 400-700 nm -> (..., 4, H, W) at :data:`LEVEL_BANDS`: each group's
    sum of radiance x 10 nm over :data:`LEVEL_BAND_WIDTH` (the integral over wavelength kept exactly; the
    sensor's QE is then taken at the group's centre)."""
    b = np.asarray(bands)
    if len(b) != 31 or abs(b[0] - 400) > 1e-6 or abs(b[-1] - 700) > 1e-6:
        raise ValueError(f"levels: want a corpus of 31 bands 400-700 nm, this one has {len(b)} "
                         f"({b[0]:g}-{b[-1]:g} nm)")
    groups = (slice(0, 8), slice(8, 16), slice(16, 24), slice(24, 31))
    a = arr.astype(np.float64)
    return np.stack([a[..., g, :, :].sum(-3) * 10.0 / LEVEL_BAND_WIDTH for g in groups], -3).astype(np.float32)


def extract_levels(corpus: Path, n: int, out: Path) -> Path:
    """The radiance of ``n`` rendered scenes (frame 0; complete scenes of ``corpus`` taken in turn from each time of
    day, ``scene.json`` ``time_of_day``; ``corpus`` a rendered
    lfmbench corpus of 31 bands, e.g. ``lfmbench render --protocol lfmbench-v1 --split test``) in the four bands of
    :data:`LEVEL_BANDS`, written to ``out`` (npz, float16): per template t ``s{t}_short`` / ``s{t}_long`` (4, H, W)
    the static groups' sum over the short / long window, ``s{t}_boxes`` (L, 4) the visible flickering lights' boxes
    (y0, x0, y1, x1) px and ``s{t}_l{j}`` (K, 4, h, w) their bins, all W sr^-1 m^-2 nm^-1. A few MiB, small enough
    to carry to a GPU machine."""
    from lfmbench.corpus import Corpus
    from lfmbench.fileio import atomic_write_bytes

    c = Corpus(corpus)
    by_time: dict[str, list[str]] = {}
    for sid in sorted(c.scenes):
        by_time.setdefault(str(c.scene(sid).get("time_of_day", "?")), []).append(sid)
    # round robin over the times of day (day, dusk, night ...): the templates mix the corpus's light levels
    picked = [q[k] for k in range(max(map(len, by_time.values()), default=0)) for q in by_time.values() if k < len(q)]
    arrays: dict[str, np.ndarray] = {}
    t = 0
    for sid in picked[:n]:
        m = c.meta(sid)
        groups = c.groups(sid)
        stat = {w: sum(c.read_static(sid, 0, g, w) for g, v in groups.items() if not v["flicker"])
                for w in ("short", "long")}
        lights = [x for g, v in groups.items() if v["flicker"] for x in c.read_light_bins(sid, 0, g)]
        for w, a in stat.items():
            arrays[f"s{t}_{w}"] = _group_bands(a, m["bands_nm"]).astype(np.float16)
        arrays[f"s{t}_boxes"] = np.array([box for _i, box, _a in lights], np.int32).reshape(-1, 4)
        for j, (_i, _box, a) in enumerate(lights):
            arrays[f"s{t}_l{j}"] = _group_bands(a, m["bands_nm"]).astype(np.float16)
        arrays[f"s{t}_time"] = np.array(str(c.scene(sid).get("time_of_day", "?")))
        t += 1
    if t == 0:
        raise ValueError(f"--levels-from {corpus}: no scenes")
    import io

    buf = io.BytesIO()
    np.savez_compressed(buf, templates=np.int64(t), **arrays)
    atomic_write_bytes(out, buf.getvalue())
    return out


def _level_frames(meta: dict, lv, t: int, seed: int) -> list[dict]:
    """Frames of ``meta`` holding template ``t``'s radiance of :func:`extract_levels` (every frame the same) and
    the synthetic aux of :func:`tests.data.corpus.data.fake_frames`."""
    from tests.data.corpus.data import fake_frames

    frames = fake_frames(meta, seed=seed)
    short, long_ = (lv[f"s{t}_{w}"].astype(np.float32) for w in ("short", "long"))
    boxes = lv[f"s{t}_boxes"]
    for f in frames:
        f["static"] = {"skymap": {"short": short.copy(), "long": long_.copy()}}
        f["lights"] = {"otherlights": [(j, tuple(int(v) for v in boxes[j]), lv[f"s{t}_l{j}"].astype(np.float32))
                                       for j in range(len(boxes))]}
    return frames


def make_corpus(root: Path, scenes: int, width: int = 640, height: int = 360, frames: int = 4, bins: int = 8,
                lamps: int = 24, levels: Path | None = None) -> Path:
    """The throughput corpus (see module docstring): random radiance, or (``levels``: an npz of
    :func:`extract_levels`) scene i the rendered radiance of template i mod T at its size, its lights' boxes and
    bins, in every frame. Scenes are encoded in threads (OpenEXR and numpy release the GIL), at most twice as many
    scenes as threads at a time, and written in order."""
    from concurrent.futures import ThreadPoolExecutor

    from lfmbench import corpus as C
    from lfmbench.corpus.scene_files import encode_scene
    from lfmbench.corpus.writer import prune_scene_dir
    from tests.data.corpus.data import fake_frames, fake_meta, fake_scene, scale_frames

    if (root / "manifest.json").is_file():
        return root
    w = C.CorpusWriter(root)
    rng = np.random.default_rng(0)
    lv = dict(np.load(levels)) if levels is not None else None
    boxes_r = [[(int(rng.integers(0, height - 24)), int(rng.integers(0, width - 40))) for _ in range(lamps)]
               for _ in range(scenes)]

    def one(i: int) -> tuple[str, list]:
        if lv is not None:
            t = i % int(lv["templates"])
            boxes = lv[f"s{t}_boxes"]
            K = lv[f"s{t}_l0"].shape[0] if len(boxes) else bins
            _c, h, wd = lv[f"s{t}_long"].shape
            meta = fake_meta(f"scene{i:05d}", width=wd, height=h, frames=frames, bins=K, bands=list(LEVEL_BANDS),
                             groups={"skymap": {"flicker": False}, "otherlights": {"flicker": True}},
                             n_lights=len(boxes))
            meta["band_width_nm"] = LEVEL_BAND_WIDTH
            for lt, box in zip(meta["lights"], boxes):
                lt["bbox"] = [[int(v) for v in box] for _ in range(frames)]
            fr = _level_frames(meta, lv, t, i)
        else:
            meta = fake_meta(f"scene{i:05d}", width=width, height=height, frames=frames, bins=bins,
                             bands=[450.0, 530.0, 610.0, 690.0], n_lights=lamps)
            for lt, (y0, x0) in zip(meta["lights"], boxes_r[i]):
                lt["bbox"] = [[y0, x0, y0 + 24, x0 + 40] for _ in range(frames)]
            fr = scale_frames(fake_frames(meta, seed=i), 1e-3, 1e-3, False)
        sid = meta["scene_id"]
        return sid, list(encode_scene(sid, fake_scene(sid), meta, fr, dtype=w.storage))

    threads = max(1, min(16, os.cpu_count() or 1))
    with ThreadPoolExecutor(threads) as ex:
        for lo in range(0, scenes, 2 * threads):  # at most 2 x threads scenes' bytes in memory at once
            for sid, files in ex.map(one, range(lo, min(scenes, lo + 2 * threads))):
                hashes = w.write_files(files)
                prune_scene_dir(w.root, sid, hashes)
                w.commit_scene(sid, hashes)
    w.write_splits(0)
    return root
