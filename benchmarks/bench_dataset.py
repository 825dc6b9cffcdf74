"""Dataset benchmarks of :mod:`lfmbench.datasets` (issue 4, "Performance").

Measures on this machine (CPU; shared with other jobs, so every time is an upper bound; medians throughout):

1. **DataLoader throughput** of 3-frame 256 x 256 samples (``crop=256`` from 320 x 256 renders, all outputs but
   ``rgb``, noise on), ``num_workers=2``, batch size 1 and 4, in samples/s (median over timed passes after a
   warm-up pass) for three cache states:
   ``warm`` (projected layers in each worker's memory, ``persistent_workers=True``; also as ``warm_fs`` with
   torch's ``file_system`` tensor-sharing strategy, and the main process's CPU time per sample), ``disk`` (the on-disk
   per-sensor cache ``<corpus>/.cache`` is loaded for every sample, ``cache_scenes=0``) and ``cold`` (no cache:
   every sample decodes its EXR files and projects them again, ``cache_dir=False, cache_scenes=0``). The
   **I/O floor** is a Dataset that only decodes, through :class:`lfmbench.corpus.Corpus` (its decoded-file cache
   off), every EXR file a sample touches (the requested frames of every group, and aux) in the same DataLoader
   setup and returns their byte count. The OS page cache is warm in every mode (files were just written).
   A :mod:`cProfile` breakdown of the warm ``__getitem__`` names where the time goes.
2. **Time bins K**: the same scene (flickering groups only, one frame, same seed and spp) rendered at
   K = 1, 2, 4, 8, 16 and a reference K_ref = 64; for the same PWM draws, the noise-free LPD and SPD mean
   electrons composed by :func:`lfmbench.datasets.assembly.compose_frame` are compared with the reference:
   relative RMSE ``||e_K - e_ref|| / ||e_ref||`` over the frame (only flickering layers are rendered, so only LED
   pixels and their blur are non-zero), pooled over the draws. The Monte Carlo floor of that metric is the same
   comparison between two reference renders with different seeds. Render time (s) per K.
3. **PSF truncation**: projected rates of one scene (all groups, one frame) with ``optics.psf_radius_px`` =
   0, 1, 2, 4, 8, 16 against 32; error of the composed LPD mean electrons (same PWM draws): relative RMSE over
   the frame and the 99th percentile of the per-pixel relative error ``|e - e_ref| / (e_ref + eps)``
   (eps = 1 % of the mean of e_ref); time of :func:`lfmbench.datasets.projection.build_layers` (EXR decode
   included) and of one full-frame 31-band :meth:`Projector.project`.
4. **Rolling shutter**: the vectorised per-row bin weights (``compose_frame(shutter="rolling")``) against a
   brute force that samples each row's exposure window at N midpoints in time (PWM level and bin radiance at
   each instant, Riemann sum): relative RMSE of the flickering part of LPD and SPD over the frame vs N, and the
   time of both.

Writes ``docs/benchmarks/dataset.md`` (whole file), ``docs/img/dataset_*.png`` and raw numbers to
``<out>/results.json``. Renders go to ``<out>`` (default ``bench_out/dsbench``, git-ignored); the throughput
corpus is reused when complete (its render time is not a result), the K renders are redone every run (their
time is).

Run: ``.venv/bin/python benchmarks/bench_dataset.py [--quick] [--out DIR]`` (``--quick``: fewer passes,
K in {1, 4, 16} vs 32, fewer radii and N; about 3 min after the first run).
Needs ``DRJIT_LIBLLVM_PATH`` (set here to Debian's libLLVM 19 when that file exists) for llvm_ad_spectral.
"""
from __future__ import annotations

import argparse
import cProfile
import dataclasses
import json
import os
import platform
import pstats
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import _llvm  # noqa: E402,F401  (DRJIT_LIBLLVM_PATH before Mitsuba loads)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402,F401
import numpy as np  # noqa: E402
import torch  # noqa: E402
from torch.utils.data import DataLoader, Dataset  # noqa: E402

from _timing import median_time  # noqa: E402
from lfmbench.fileio import atomic_save_figure, atomic_write_text  # noqa: E402
from lfmbench import sensor as _sensor  # noqa: E402
from lfmbench.corpus import Corpus, CorpusWriter, group_storage  # noqa: E402
from lfmbench.datasets import LFMCaptureDataset  # noqa: E402
from lfmbench.datasets.assembly import compose_frame  # noqa: E402
from lfmbench.datasets.capture import DEFAULT_OUTPUTS  # noqa: E402
from lfmbench.datasets.projection import Projector, build_layers, load_or_build  # noqa: E402
from lfmbench.datasets.pwm import draw_scene_pwm, load_pwm_config  # noqa: E402


ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "benchmarks" / "dataset.md"
IMG = ROOT / "docs" / "img"
#: Throughput corpus: render size (px), crop (px), frames, spp, bins, render seed.
TP_SIZE = (256, 320)          # (height, width)
TP_CROP = 256
TP_FRAMES = 3
TP_SPP, TP_BINS, TP_SEED = 4, 8, 3
#: Target of issue 4 (samples/s, warm cache).
TARGET_SPS = 50.0


# ----------------------------------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------------------------------
def _atomic_write_text(path: Path, text: str) -> None:
    atomic_write_text(path, text)


def _atomic_savefig(fig, path: Path) -> None:
    atomic_save_figure(fig, path, dpi=110)
    plt.close(fig)


def _median_time(fn, repeat: int, warmup: int = 1) -> float:
    """Median wall time (s) of ``repeat`` calls after ``warmup`` calls."""
    return median_time(fn, repeat, warmup)[0]


def _log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def _render(out: Path, options: dict, seed: int, scenes: int = 1, scene: dict | None = None) -> tuple[float, float]:
    """Render ``scenes`` procedural scenes (or ``scene``) into corpus ``out`` in this process; returns the wall
    seconds of the render jobs (0 when everything was already complete) and the process CPU seconds (all
    threads) of the whole call."""
    from render_tools import jobs as J

    be = J.default_backend()
    jobs = J.make_jobs(out, n_scenes=scenes, seed=seed, options=options,
                       scenes=[scene] if scene is not None else None, backend=be, dtype="float32")
    writer = CorpusWriter(out, dtype="float32", render=J.render_record(seed, options, "float32", {}))
    c0 = time.process_time()
    summary = J.run_jobs(jobs, writer)
    cpu = time.process_time() - c0
    if summary.failed:
        raise RuntimeError(f"render into {out} failed: {summary.failed}")
    if not (Path(out) / "splits.json").is_file():
        writer.write_splits(seed)
    return float(sum(summary.seconds.values())), cpu


def _draws(meta: dict, n: int, seed: int) -> list[dict]:
    """``n`` PWM draws (light id -> PWM dict) for the scene's flickering lights (default pwm.yaml), drawn as
    the dataset draws them (:func:`lfmbench.datasets.pwm.draw_scene_pwm`)."""
    cfg = load_pwm_config(None)
    return [draw_scene_pwm(cfg, meta, np.random.default_rng([seed, i])).to_dicts()[0] for i in range(n)]


def _rel_rmse(est: list[torch.Tensor], ref: list[torch.Tensor]) -> float:
    """Pooled relative RMSE sqrt(sum (est - ref)^2 / sum ref^2) over a list of arrays (1)."""
    num = sum(float(((e.double() - r.double()) ** 2).sum()) for e, r in zip(est, ref))
    den = sum(float((r.double() ** 2).sum()) for r in ref)
    return float(np.sqrt(num / den)) if den > 0 else float("nan")


# ----------------------------------------------------------------------------------------------------------
# 1. throughput
# ----------------------------------------------------------------------------------------------------------
class _IOFloor(Dataset):
    """Decodes every EXR file a sample of ``ds`` touches (same scene, frames, groups, aux) and nothing else.

    Returns ``{"bytes": int64 tensor ()}``: the decoded size; the arrays themselves are dropped.
    """

    def __init__(self, ds: LFMCaptureDataset) -> None:
        self.root, self.scene_ids, self.frames = ds.root, ds.scene_ids, ds.frames
        self.samples_per_scene = ds.samples_per_scene
        self.corpus: Corpus | None = None

    def __len__(self) -> int:
        return len(self.scene_ids) * self.samples_per_scene

    def __getitem__(self, index: int) -> dict:
        if self.corpus is None:  # opened in the worker; decoded-file cache off: every sample decodes again
            self.corpus = Corpus(self.root, cache_size=0)
        c = self.corpus
        sid = self.scene_ids[index // self.samples_per_scene]
        meta = c.meta(sid)
        n = 0
        for f in range(self.frames):
            for g in meta["groups"]:
                if group_storage(meta, g) == "static":
                    # both windows live in one file: a second read_static would decode it again (cache off),
                    # which the dataset does not do either (the corpus cache keeps the file between the two)
                    n += c.read_static(sid, f, g, "short").nbytes * 2
                else:
                    n += sum(b.nbytes for _i, _b, b in c.read_light_bins(sid, f, g))
            n += sum(a.nbytes for a in c.read_aux(sid, f, ["depth.Z", "mask.light"]).values())
        return {"bytes": torch.tensor(n, dtype=torch.int64)}


def _passes(ds: Dataset, batch_size: int, n_passes: int, persistent: bool, warmup: bool = True,
            main_cpu: list | None = None) -> list[float]:
    """samples/s of ``n_passes`` timed passes over ``ds`` (2 workers), after one untimed warm-up pass if
    ``warmup``. Each pass includes starting the workers unless ``persistent``. ``main_cpu`` (if given) receives
    the main process's CPU time per sample (s) of each timed pass: receiving batches from the workers."""
    loader = DataLoader(ds, batch_size=batch_size, shuffle=False, num_workers=2,
                        persistent_workers=persistent, prefetch_factor=2)
    rates = []
    for p in range(n_passes + int(warmup)):
        t0, c0 = time.perf_counter(), time.process_time()
        n = 0
        for batch in loader:
            n += len(batch["meta"]["index"]) if "meta" in batch else len(batch["bytes"])
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        if p or not warmup:
            rates.append(n / dt)
            if main_cpu is not None:
                main_cpu.append(dc / n)
    del loader
    return rates


def bench_throughput(root: Path, quick: bool) -> dict:
    """Samples/s of LFMCaptureDataset (warm, disk, cold cache) and of the I/O floor; batch 1 and 4."""
    cache = root / ".cache"
    n_scenes = len(Corpus(root).scenes)
    sps_warm = 16
    n_pass = 3 if quick else 5
    res: dict = {"scenes": n_scenes, "rows": []}

    def make(mode: str, sps: int) -> LFMCaptureDataset:
        kw = dict(split="all", sensor="ovt", frames=TP_FRAMES, crop=TP_CROP, seed=0, outputs=DEFAULT_OUTPUTS,
                  samples_per_scene=max(1, sps // n_scenes))
        if mode == "warm":
            return LFMCaptureDataset(root, cache_dir=cache, cache_scenes=8, **kw)
        if mode == "disk":
            return LFMCaptureDataset(root, cache_dir=cache, cache_scenes=0, **kw)
        return LFMCaptureDataset(root, cache_dir=False, cache_scenes=0, **kw)

    # build the on-disk cache once (not timed here; its cost is the cold per-sample cost times scenes)
    warm = make("warm", sps_warm)
    for sid in warm.scene_ids:
        load_or_build(warm.corpus, sid, warm.preset, None, TP_FRAMES, True, cache)
    for bs in (1, 4):
        for mode, sps, passes, persistent, warmup in (("warm", sps_warm, n_pass, True, True),
                                                      ("warm_fs", sps_warm, n_pass, True, True),
                                                      ("disk", 8, 2 if quick else 3, False, True),
                                                      ("cold", 8, 1, False, False),
                                                      ("io_floor", 8, 2 if quick else 3, False, True)):
            base = make("warm" if mode in ("io_floor", "warm_fs") else mode, sps)
            ds = _IOFloor(base) if mode == "io_floor" else base
            main_cpu: list = []
            # warm_fs: torch's "file_system" sharing strategy (tensors cross to the main process by shm name
            # instead of by file descriptor); a process-wide user setting, restored afterwards
            strategy = torch.multiprocessing.get_sharing_strategy()
            if mode == "warm_fs":
                torch.multiprocessing.set_sharing_strategy("file_system")
            try:
                rates = _passes(ds, bs, passes, persistent, warmup, main_cpu)
            finally:
                torch.multiprocessing.set_sharing_strategy(strategy)
            row = {"batch": bs, "mode": mode, "samples": len(ds), "passes": len(rates),
                   "sps": statistics.median(rates), "sps_all": rates, "main_cpu_s": statistics.median(main_cpu)}
            res["rows"].append(row)
            _log(f"throughput batch {bs} {mode}: {row['sps']:.2f} samples/s ({[round(r, 2) for r in rates]})")
    floor = {r["batch"]: r["sps"] for r in res["rows"] if r["mode"] == "io_floor"}
    for r in res["rows"]:
        r["ratio_to_io"] = r["sps"] / floor[r["batch"]]
    # bytes one sample decodes, and one sample's output size
    io = _IOFloor(warm)
    res["bytes_per_sample"] = int(io[0]["bytes"])
    s = warm[0]
    res["sample_bytes"] = int(sum(v.numel() * v.element_size() for v in s.values() if torch.is_tensor(v)))
    res["shot"] = _shot_noise_costs(warm)
    res["profile"] = _profile(warm, 6 if quick else 12)
    res["pyspy"] = _pyspy_profile(root, 4 if quick else 8)
    return res


_PROFILE_DS: list = []


def _shot_noise_costs(ds: LFMCaptureDataset) -> dict:
    """Cost (s, one torch thread) of :func:`lfmbench.sensor.shot_noise` on one sample's LPD mean electrons
    (F, 1, h, w), against ``torch.poisson`` and ``torch.randn`` on all its pixels; share of pixels below the
    preset's Gaussian switch-over."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        s = ds[0]
        m = (s["gt"]).float()
        gsw = float(ds.preset.shot_noise_gaussian_above_e)
        g = torch.Generator().manual_seed(0)
        return {"switch_e": gsw, "frac_small": float((m < gsw).double().mean()), "pixels": m.numel(),
                "shot_noise_s": _median_time(lambda: _sensor.shot_noise(m, g, gsw), 15),
                "shot_noise_torch_s": _median_time(lambda: _sensor.shot_noise(m, g, gsw, backend="torch"), 15),
                "poisson_s": _median_time(lambda: torch.poisson(m, generator=g), 15),
                "randn_s": _median_time(lambda: torch.randn(m.shape, generator=g), 15)}
    finally:
        torch.set_num_threads(threads)


#: Functions whose inclusive share of the workers' busy time the py-spy profile reports.
SPY_FUNCS = ("LFMCaptureDataset.__getitem__", "compose_frame", "window_bin_exposure", "pwm_exposure",
             "simulate_split_pixel_electrons", "shot_noise", "read_capture", "collate")


def _spy_child(root: Path, seconds: float) -> None:
    """DataLoader passes (2 workers, batch 1) for py-spy to sample (run as a child process): one warm-up pass,
    then ``ready`` on stdout, then warm passes for ``seconds`` s."""
    ds = LFMCaptureDataset(root, split="all", sensor="ovt", frames=TP_FRAMES, crop=TP_CROP, seed=0,
                           outputs=DEFAULT_OUTPUTS, samples_per_scene=8, cache_dir=root / ".cache")
    loader = DataLoader(ds, batch_size=1, shuffle=False, num_workers=2, persistent_workers=True)
    for _ in loader:
        pass
    print("ready", flush=True)
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for _ in loader:
            pass


def _pyspy_profile(root: Path, seconds: float) -> dict | None:
    """py-spy (``--subprocesses``, 100 Hz, busy samples only), attached after the warm-up pass, of warm
    DataLoader passes: inclusive share of each :data:`SPY_FUNCS` entry in the samples taken in the worker
    processes. None when py-spy is unavailable."""
    import subprocess
    from collections import Counter

    spy = shutil.which("py-spy") or str(Path(sys.executable).with_name("py-spy"))
    if not os.path.exists(spy):
        return None
    with tempfile.TemporaryDirectory() as td:
        raw = Path(td) / "spy.txt"
        child = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--spy-child", str(root),
                                  "--spy-seconds", str(seconds + 3)], stdout=subprocess.PIPE, text=True)
        try:
            while child.stdout.readline().strip() != "ready":
                if child.poll() is not None:
                    _log("py-spy: the DataLoader child exited early")
                    return None
            cmd = [spy, "record", "--subprocesses", "--format", "raw", "-r", "100", "-o", str(raw),
                   "--duration", str(int(seconds)), "--pid", str(child.pid)]
            proc = subprocess.run(cmd, capture_output=True, text=True)
        finally:
            child.wait()
        if proc.returncode != 0 or not raw.is_file():
            _log(f"py-spy failed ({proc.returncode}): {proc.stderr[-300:]}")
            return None
        counts: Counter = Counter()
        worker = 0
        for line in raw.read_text().splitlines():
            stack, n = line.rsplit(" ", 1)
            frames = [f.split(" (")[0] for f in stack.split(";")]
            if "_worker_loop" not in frames:
                continue
            worker += int(n)
            for name in set(frames) & set(SPY_FUNCS):
                counts[name] += int(n)
    return {"samples": worker, "share": {k: counts[k] / worker for k in SPY_FUNCS if worker}}


def _profile(ds: LFMCaptureDataset, n: int) -> list[tuple[str, float, float]]:
    """cProfile of ``n`` warm ``__getitem__`` calls in a forked child with one torch thread, i.e. under the
    conditions of a DataLoader worker (lfmbench.flicker picks its serial numba kernel there):
    [(function, cumulative share, seconds per sample)] of the main stages."""
    import multiprocessing as mp

    _PROFILE_DS[:] = [ds]
    with mp.get_context("fork").Pool(1) as pool:
        return pool.apply(_profile_child, (n,))


def _profile_child(n: int) -> list[tuple[str, float, float]]:
    ds = _PROFILE_DS[0]
    torch.set_num_threads(1)
    for i in range(min(2, len(ds))):
        ds[i]
    w0, c0 = time.perf_counter(), time.process_time()
    for i in range(n):
        ds[i % len(ds)]
    wall, cpu = (time.perf_counter() - w0) / n, (time.process_time() - c0) / n
    pr = cProfile.Profile()
    t0 = time.perf_counter()
    pr.enable()
    for i in range(n):
        ds[i % len(ds)]
    pr.disable()
    total = time.perf_counter() - t0
    st = pstats.Stats(pr)
    want = {"__getitem__": "LFMCaptureDataset.__getitem__", "compose_frame": "capture.compose_frame",
            "window_bin_exposure": "capture.window_bin_exposure", "pwm_exposure": "flicker.pwm_exposure",
            "einsum": "torch.einsum (compose_frame)",
            "simulate_split_pixel_electrons": "sensor.simulate_split_pixel_electrons",
            "shot_noise": "sensor.shot_noise", "read_capture": "sensor.read_capture",
            "check_radiometric": "optics.check_radiometric", "fixed_pattern": "sensor.fixed_pattern",
            "_meta": "LFMCaptureDataset._meta", "_draw": "LFMCaptureDataset._draw"}
    rows = {}
    for (file, _line, func), (_cc, _nc, _tt, ct, _callers) in st.stats.items():
        if func in want and ("lfmbench" in file or func == "einsum"):
            name = want[func]
            rows[name] = max(rows.get(name, 0.0), ct)
    out = [(k, v / total, v / n) for k, v in sorted(rows.items(), key=lambda kv: -kv[1])]
    out.insert(0, ("total (wall, under cProfile)", 1.0, total / n))
    return {"rows": out, "wall_s": wall, "cpu_s": cpu, "n": n}


# ----------------------------------------------------------------------------------------------------------
# 2. time bins
# ----------------------------------------------------------------------------------------------------------
def bench_bins(out: Path, scene: dict, size: tuple[int, int], ks: list[int], k_ref: int, spp: int,
               light_spp: int, n_draws: int) -> dict:
    """Render ``scene`` (flickering groups only, frame 0) at each K and compare composed exposures."""
    preset = _sensor.load_preset("ovt")
    groups = sorted({lt["group"] for lt in scene["lights"]} & {"otherlights", "signals"})
    base = {"width": size[1], "height": size[0], "spp": spp, "light_spp": light_spp, "frames": 1,
            "groups": groups}
    seed = 11
    res: dict = {"ks": ks, "k_ref": k_ref, "groups": groups, "size": list(size), "spp": spp,
                 "light_spp": light_spp, "draws": n_draws, "rows": []}
    layers: dict = {}
    # warm-up: import mitsuba and compile the common kernels once so K=1 is not charged for them
    shutil.rmtree(out / "warmup", ignore_errors=True)
    _render(out / "warmup", {**base, "bins": 1}, seed, scene=scene)
    for K in ks + [k_ref, "ref2"]:
        d = out / f"k{K}"
        shutil.rmtree(d, ignore_errors=True)
        kk = k_ref if K == "ref2" else K
        sec, cpu = _render(d, {**base, "bins": kk}, seed + 1 if K == "ref2" else seed, scene=scene)
        c = Corpus(d)
        sid = c.scenes[0]
        layers[K] = (build_layers(c, sid, preset, None, 1, optics=True, aux=()), c.meta(sid), sec, cpu)
        _log(f"bins K={K}: render {sec:.1f} s wall, {cpu:.1f} s CPU")
    meta = layers[k_ref][1]
    draws = _draws(meta, n_draws, seed=5)
    H, W = meta["height"], meta["width"]

    def composed(K):
        L, m = layers[K][:2]
        return [compose_frame(L, m, 0, (0, 0, H, W), p, {}, "global") for p in draws]

    ref = composed(k_ref)
    for K in ks + ["ref2"]:
        est = composed(K)
        row = {"K": K, "render_s": layers[K][2], "render_cpu_s": layers[K][3]}
        for key in ("lpd", "spd", "gt"):
            row[key] = _rel_rmse([e[key] for e in est], [r[key] for r in ref])
        res["rows"].append(row)
        _log(f"bins K={K}: rel RMSE lpd {row['lpd']:.4f} spd {row['spd']:.4f} gt {row['gt']:.4f}")
    res["ref_render_s"] = layers[k_ref][2]
    res["ref_render_cpu_s"] = layers[k_ref][3]
    res["speed_mps"] = float(scene.get("camera", {}).get("speed_mps", float("nan")))
    res["scene_id"] = meta.get("scene_id")
    res["lights"] = len([lt for lt in meta.get("lights", []) if lt["group"] in groups])
    res["led_pixels"] = int(sum((r["lpd"] > 0).sum() for r in ref[:1]))
    return res


# ----------------------------------------------------------------------------------------------------------
# 3. PSF truncation
# ----------------------------------------------------------------------------------------------------------
def bench_psf(root: Path, radii: list[int], r_ref: int, n_draws: int, repeat: int) -> dict:
    c = Corpus(root)
    sid = c.scenes[0]
    meta = c.meta(sid)
    H, W = meta["height"], meta["width"]
    base = _sensor.load_preset("ovt")
    draws = _draws(meta, n_draws, seed=7)
    L = c.read_static(sid, 0, "skymap" if "skymap" in meta["groups"] else next(iter(meta["groups"])), "short")

    def preset_r(r):
        return dataclasses.replace(base, optics=dataclasses.replace(base.optics, psf_radius_px=r))

    out = {}
    for r in radii + [r_ref]:
        p = preset_r(r)
        layers = build_layers(c, sid, p, None, 1, optics=True, aux=())
        t_build = _median_time(lambda: build_layers(c, sid, p, None, 1, optics=True, aux=()), repeat, warmup=0)
        proj = Projector(p, meta["bands_nm"], float(meta.get("band_width_nm", 10.0)), H, W, True)
        t_proj = _median_time(lambda: proj.project(L[None]), 4 * repeat + 1, warmup=1)
        comp = [compose_frame(layers, meta, 0, (0, 0, H, W), d, {}, "global")["lpd"] for d in draws]
        out[r] = (comp, t_build, t_proj)
        _log(f"psf R={r}: build_layers {t_build:.2f} s, project {t_proj * 1e3:.1f} ms")
    ref = out[r_ref][0]
    rows = []
    for r in radii + [r_ref]:
        comp, tb, tp = out[r]
        eps = 0.01 * float(torch.stack(ref).double().mean())
        rel = torch.cat([((e.double() - q.double()).abs() / (q.double() + eps)).flatten() for e, q in zip(comp, ref)])
        rows.append({"R": r, "rel_rmse": _rel_rmse(comp, ref), "p99_rel": float(torch.quantile(rel[::7], 0.99)),
                     "frac_1pc": float((rel > 0.01).double().mean()), "max_rel": float(rel.max()),
                     "build_s": tb, "project_s": tp})
    return {"scene_id": sid, "size": [H, W], "r_ref": r_ref, "draws": n_draws, "rows": rows,
            "groups": sorted(meta["groups"])}


# ----------------------------------------------------------------------------------------------------------
# 4. rolling shutter
# ----------------------------------------------------------------------------------------------------------
def _pwm_level(t: np.ndarray, period: float, duty: float, phase: float) -> np.ndarray:
    """Ideal PWM level (0 or 1) at times ``t`` (s): ON during [phase + k T, phase + k T + D T)."""
    return (np.mod(t - phase, period) < duty * period).astype(np.float64)


def brute_rolling(layers, meta: dict, frame: int, params: dict[int, dict], n_samples: int) -> dict:
    """Flickering part of the rolling-shutter LPD/SPD mean electrons (e-, (H, W)) by dense time sampling.

    Row y's window [a + y * line_time, + T) is sampled at ``n_samples`` midpoints t_i; each sample adds
    ``T / n * R_{k(t_i)}(y, x) * s(t_i)`` (bin radiance times the PWM level at that instant).
    """
    tm = meta["timing"]
    H, W = meta["height"], meta["width"]
    ts, tl = float(tm["short_exposure_s"]), float(tm["long_exposure_s"])
    t0 = frame / float(meta["fps"])
    K, cw = int(tm["bins"]), float(tm["capture_window_s"])
    lt = float(tm.get("line_time_s", 0.0))
    start = {"lpd": t0 + (tl - ts) / 2.0, "spd": t0}
    length = {"lpd": ts, "spd": tl}
    out = {pd: torch.zeros(H, W, dtype=torch.float64) for pd in ("lpd", "spd")}
    u = (np.arange(n_samples) + 0.5) / n_samples
    for light_id, _g, (by0, bx0, by1, bx1), rates in layers.lights[frame]:
        p = params.get(light_id)
        if p is None:
            continue
        if p["rise_s"] or p["fall_s"]:
            raise ValueError("brute_rolling: params must have rise_s = fall_s = 0 (ideal pulses)")
        rows = np.arange(by0, by1, dtype=np.float64)
        for pd in ("lpd", "spd"):
            t = start[pd] + rows[:, None] * lt + u[None, :] * length[pd]                 # (rows, n) s
            k = np.clip(np.floor((t - t0) / cw * K).astype(np.int64), 0, K - 1)
            s = _pwm_level(t, p["period_s"], p["duty"], p["phase_s"]) * (length[pd] / n_samples)
            wk = np.zeros((len(rows), K))
            np.add.at(wk, (np.repeat(np.arange(len(rows)), n_samples), k.ravel()), s.ravel())
            out[pd][by0:by1, bx0:bx1] += torch.einsum("kyx,yk->yx", rates[pd].double(), torch.from_numpy(wk))
    return out


def bench_rolling(root: Path, ns: list[int], n_draws: int, repeat: int) -> dict:
    c = Corpus(root)
    sid = c.scenes[0]
    meta = c.meta(sid)
    H, W = meta["height"], meta["width"]
    layers = load_or_build(c, sid, _sensor.load_preset("ovt"), None, 1, True, root / ".cache" / "bench_rolling")
    draws = _draws(meta, n_draws, seed=9)
    crop = (0, 0, H, W)

    def vec(shutter):
        res = []
        for d in draws:
            full = compose_frame(layers, meta, 0, crop, d, {}, shutter)
            static = compose_frame(layers, meta, 0, crop, {}, {}, shutter)
            res.append({pd: (full[pd] - static[pd]).double() for pd in ("lpd", "spd")})
        return res

    exact = vec("rolling")
    glob = vec("global")
    t_vec = _median_time(lambda: [compose_frame(layers, meta, 0, crop, d, {}, "rolling") for d in draws],
                         repeat) / n_draws
    t_glob = _median_time(lambda: [compose_frame(layers, meta, 0, crop, d, {}, "global") for d in draws],
                          repeat) / n_draws
    rows = []
    for n in ns:
        bf = [brute_rolling(layers, meta, 0, d, n) for d in draws]
        t_b = _median_time(lambda: brute_rolling(layers, meta, 0, draws[0], n), repeat, warmup=1)
        row = {"N": n, "brute_s": t_b,
               "lpd": _rel_rmse([e["lpd"] for e in exact], [b["lpd"] for b in bf]),
               "spd": _rel_rmse([e["spd"] for e in exact], [b["spd"] for b in bf])}
        rows.append(row)
        _log(f"rolling N={n}: rel RMSE lpd {row['lpd']:.2e} spd {row['spd']:.2e}, brute {t_b:.3f} s")
    return {"scene_id": sid, "size": [H, W], "draws": n_draws, "rows": rows, "vec_s": t_vec, "global_s": t_glob,
            "global_vs_rolling_lpd": _rel_rmse([g["lpd"] for g in glob], [e["lpd"] for e in exact]),
            "line_time_s": float(meta["timing"].get("line_time_s", 0.0)), "bins": int(meta["timing"]["bins"]),
            "lights": sum(1 for _ in layers.lights[0])}


# ----------------------------------------------------------------------------------------------------------
# report
# ----------------------------------------------------------------------------------------------------------
def plots(tp: dict, bins: dict, psf: dict, rs: dict) -> None:
    # throughput
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    modes = ["warm", "warm_fs", "disk", "cold", "io_floor"]
    x = np.arange(len(modes))
    for j, bs in enumerate((1, 4)):
        v = [next(r["sps"] for r in tp["rows"] if r["mode"] == m and r["batch"] == bs) for m in modes]
        ax.bar(x + (j - 0.5) * 0.38, v, 0.38, label=f"batch {bs}")
        for xi, vi in zip(x + (j - 0.5) * 0.38, v):
            ax.text(xi, vi, f"{vi:.1f}", ha="center", va="bottom", fontsize=7)
    ax.axhline(TARGET_SPS, color="k", ls="--", lw=0.8, label=f"target {TARGET_SPS:.0f}/s")
    ceil = 2.0 / tp["profile"]["cpu_s"]
    ax.axhline(ceil, color="g", ls=":", lw=1.0, label=f"2 idle cores, warm ({ceil:.0f}/s, from CPU time)")
    ax.set_xticks(x, ["warm cache", "warm cache,\nfile_system\nsharing", "disk cache", "cold\n(no cache)",
                      "I/O floor\n(EXR decode)"], fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("samples / s (median)")
    ax.set_title("DataLoader, 2 workers, 3 frames 256x256 (shared 2-core CPU)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    _atomic_savefig(fig, IMG / "dataset_throughput.png")

    # approximations: error vs time
    fig, axes = plt.subplots(1, 3, figsize=(12.5, 3.8))
    ax = axes[0]
    rows = [r for r in bins["rows"] if r["K"] != "ref2"]
    floor = next(r for r in bins["rows"] if r["K"] == "ref2")
    tkey = "render_cpu_s" if "render_cpu_s" in rows[0] else "render_s"
    for key, mk in (("lpd", "o-"), ("spd", "s-"), ("gt", "^-")):
        ax.plot([r[tkey] for r in rows], [r[key] for r in rows], mk, label=f"{key.upper()} e-")
        for r in rows:
            if key == "lpd":
                ax.annotate(f"K={r['K']}", (r[tkey], r[key]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")
    ax.axhline(floor["lpd"], color="gray", ls=":", lw=1, label="MC floor (LPD, 2 seeds)")
    ax.axvline(bins["ref_render_cpu_s" if tkey == "render_cpu_s" else "ref_render_s"], color="k", ls="--", lw=0.6,
               label=f"K_ref={bins['k_ref']} render")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"render {'CPU' if tkey == 'render_cpu_s' else 'wall'} time (s), flickering groups, 1 frame")
    ax.set_ylabel(f"rel. RMSE vs K={bins['k_ref']}")
    ax.set_title("time bins K", fontsize=9)
    ax.legend(fontsize=7)
    ax = axes[1]
    prow = [r for r in psf["rows"] if r["R"] != psf["r_ref"]]
    ax.plot([r["project_s"] * 1e3 for r in prow], [max(r["rel_rmse"], 1e-9) for r in prow], "o-",
            label="rel. RMSE (frame)")
    ax.plot([r["project_s"] * 1e3 for r in prow], [max(r["p99_rel"], 1e-9) for r in prow], "s-",
            label="99th pct per-pixel rel. error")
    for r in prow:
        ax.annotate(f"R={r['R']}", (r["project_s"] * 1e3, max(r["rel_rmse"], 1e-9)), fontsize=7, xytext=(3, 3),
                    textcoords="offset points")
    ref_t = next(r for r in psf["rows"] if r["R"] == psf["r_ref"])["project_s"] * 1e3
    ax.axvline(ref_t, color="k", ls="--", lw=0.6, label=f"R={psf['r_ref']} time")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time of one full-frame 31-band projection (ms)")
    ax.set_ylabel(f"error vs R={psf['r_ref']} (LPD e-)")
    ax.set_title("PSF truncation radius", fontsize=9)
    ax.legend(fontsize=7)
    ax = axes[2]
    ax.plot([r["brute_s"] for r in rs["rows"]], [r["lpd"] for r in rs["rows"]], "o-", label="LPD")
    ax.plot([r["brute_s"] for r in rs["rows"]], [r["spd"] for r in rs["rows"]], "s-", label="SPD")
    for r in rs["rows"]:
        ax.annotate(f"N={r['N']}", (r["brute_s"], r["lpd"]), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.axvline(rs["vec_s"], color="k", ls="--", lw=0.8, label="per-row bin weights (time)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time per frame (s)")
    ax.set_ylabel("rel. RMSE, bin weights vs brute force N")
    ax.set_title("rolling shutter: weights vs dense time sampling", fontsize=9)
    ax.legend(fontsize=7)
    for ax in axes:
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    fig.tight_layout()
    _atomic_savefig(fig, IMG / "dataset_approximations.png")


def _airy_outside(radius_px: int, wavelength_nm: float = 550.0) -> float:
    """Fraction (1) of the ``ovt`` lens's Airy PSF energy outside a circle of ``radius_px`` pixels."""
    from lfmbench.sensor.optics import airy_encircled_energy

    p = _sensor.load_preset("ovt")
    r = torch.tensor([radius_px * p.pixel_pitch_m], dtype=torch.float64)
    n_w = p.optics.f_number * (1.0 + abs(p.optics.magnification))
    return 1.0 - float(airy_encircled_energy(r, wavelength_nm * 1e-9, n_w)[0]) if radius_px > 0 else 1.0


def _summary(tp: dict, bins: dict, psf: dict, rs: dict) -> list[str]:
    """Key numbers, computed from the results."""
    warm = max(r["sps"] for r in tp["rows"] if r["mode"] == "warm")
    warm_b = {r["batch"]: r["sps"] for r in tp["rows"] if r["mode"] == "warm"}
    reached = [b for b, v in warm_b.items() if v >= TARGET_SPS]
    cold = max(r["sps"] for r in tp["rows"] if r["mode"] == "cold")
    io = max(r["sps"] for r in tp["rows"] if r["mode"] == "io_floor")
    floor = next(r["lpd"] for r in bins["rows"] if r["K"] == "ref2")
    big = [r for r in bins["rows"] if r["K"] != "ref2" and r["K"] >= 4]
    p8 = next((r for r in psf["rows"] if r["R"] == 8), None)
    last = rs["rows"][-1]
    out = ["## Summary", "",
           "- Throughput (2 workers, 3 frames 256x256): **"
           + ", ".join(f"{v:.1f} samples/s warm at batch {b}" for b, v in sorted(warm_b.items()))
           + f"**, {cold:.2f} cold; target {TARGET_SPS:.0f}/s "
           + (f"reached at batch {', '.join(str(b) for b in sorted(reached))}" if reached else "**not reached**")
           + " on this shared machine. "
           f"Warm samples are CPU-bound (shot noise, read-out and composition, section 1) and "
           f"{warm / io:.0f}x faster than merely decoding the EXR files a sample touches ({io:.1f}/s), so the "
           "per-sensor cache is what makes training feasible.",
           "- Time bins: relative RMSE of the LPD mean electrons on LED pixels against K = "
           f"{bins['k_ref']}: " + ", ".join(f"K = {r['K']} {r['lpd'] * 100:.1f} %" for r in bins["rows"]
                                            if r["K"] != "ref2")
           + f"; Monte Carlo floor {floor * 100:.1f} % (two K = {bins['k_ref']} renders, different seeds)"
           + (f", so from K = 4 on ({min(r['lpd'] for r in big) * 100:.1f} - {max(r['lpd'] for r in big) * 100:.1f} %) "
              "the remaining error is mostly render noise" if big else "")
           + f"; render CPU time {bins['rows'][0].get('render_cpu_s', 0):.1f} s at K = {bins['rows'][0]['K']}, "
           f"{bins.get('ref_render_cpu_s', 0):.1f} s at K = {bins['k_ref']}."]
    if p8:
        out.append(f"- PSF truncation at the default R = 8 px: {p8['rel_rmse'] * 100:.1f} % relative RMSE against "
                   f"R = {psf['r_ref']}, but {p8['frac_1pc'] * 100:.0f} % of the pixels are more than 1 % off (lost "
                   "diffraction halo around bright lights in dark surroundings).")
    out.append(f"- Rolling shutter: the per-row bin weights are exact; dense time sampling converges to them "
               f"(relative RMSE {last['lpd']:.1e} at N = {last['N']}) and is slower "
               f"({last['brute_s'] * 1e3:.0f} ms vs {rs['vec_s'] * 1e3:.0f} ms per frame).")
    return out + [""]


def report(tp: dict, bins: dict, psf: dict, rs: dict, env: dict, quick: bool, prof_note: str) -> str:
    L = ["# Dataset benchmark (throughput, error against run time)", "",
         f"Generated by `benchmarks/bench_dataset.py{' --quick' if quick else ''}` on {env['date']} "
         f"({env['machine']}, {env['cpus']} CPUs, torch {env['torch']}, {torch.get_num_threads()} threads in the "
         f"main process). **The machine was shared with other engineers' jobs** (load average "
         f"{env['load_start']} at the start, {env['load_end']} at the end), so every time is an upper bound and "
         f"ratios are more reliable than absolute numbers. All times are medians.", "",
         *_summary(tp, bins, psf, rs),
         "![throughput](img/dataset_throughput.png)", "",
         "## 1. DataLoader throughput", "",
         f"`LFMCaptureDataset(split='all', sensor='ovt', frames={TP_FRAMES}, crop={TP_CROP}, outputs=DEFAULT_OUTPUTS,"
         f" noise=True)` on a corpus of {tp['scenes']} rendered scene(s) of {TP_SIZE[1]}x{TP_SIZE[0]} px (31 bands, "
         f"K = {TP_BINS} time bins, all light groups), `DataLoader(num_workers=2, shuffle=False)`; median over the "
         "timed passes after one warm-up pass. Modes: **warm**: projected layers in each worker's memory "
         "(`persistent_workers=True`); **disk**: the per-sensor cache `<corpus>/.cache/<hash>/<scene>.pt` loaded "
         "for every sample (`cache_scenes=0`); **cold**: no cache at all (`cache_dir=False, cache_scenes=0`): "
         "every sample decodes its EXR files and projects them (optics + CFA) again; **I/O floor**: a Dataset "
         "that only decodes (via `lfmbench.corpus.Corpus`, decoded-file cache off) the same EXR files a sample "
         "touches, same DataLoader. The OS page cache is warm in every mode.", "",
         f"One sample decodes {tp['bytes_per_sample'] / 2**20:.1f} MiB of EXR data (float32) and returns "
         f"{tp['sample_bytes'] / 2**20:.2f} MiB of tensors.", "",
         "| batch | mode | samples / pass | timed passes | samples/s (median) | min - max over passes | "
         "ratio to I/O floor | main-process CPU (ms / sample) |", "|---|---|---|---|---|---|---|---|"]
    for r in tp["rows"]:
        L.append(f"| {r['batch']} | {r['mode']} | {r['samples']} | {r['passes']} | {r['sps']:.2f} | "
                 f"{min(r['sps_all']):.2f} - {max(r['sps_all']):.2f} | {r['ratio_to_io']:.2f} | "
                 f"{r.get('main_cpu_s', float('nan')) * 1e3:.1f} |")
    warm_b = {r["batch"]: r["sps"] for r in tp["rows"] if r["mode"] == "warm"}
    L += ["", f"Target: at least {TARGET_SPS:.0f} samples/s with a warm cache: "
          + "; ".join(f"batch {b}: **{'reached' if v >= TARGET_SPS else 'not reached'}** ({v:.1f} samples/s)"
                      for b, v in sorted(warm_b.items())) + ".", "",
          "The main process only receives batches, yet it spends several ms of CPU per sample at batch 1: every "
          "tensor of a batch (the 10 outputs and 11 numeric `meta` fields) crosses to it through its own "
          "shared-memory segment, so the per-tensor cost is paid per sample at batch 1 and per 4 samples at "
          "batch 4. On two cores that CPU is taken from the workers. Mode **warm_fs** is the warm mode with "
          "`torch.multiprocessing.set_sharing_strategy(\"file_system\")` (tensors cross by shared-memory name, "
          "not by file descriptor), a process-wide setting a training script may choose (docs/guide/datasets.md): "
          "it roughly halves that main-process cost.", "",
          "Where the time of one warm sample goes (cProfile of `__getitem__` in one process with one torch "
          "thread, as in a DataLoader worker; cumulative time, so nested rows overlap):", "",
          "| function | share of wall time | ms / sample |", "|---|---|---|"]
    for name, share, sec in tp["profile"]["rows"]:
        L.append(f"| `{name}` | {share * 100:.0f} % | {sec * 1e3:.1f} |")
    pf = tp["profile"]
    L += ["", f"Without the profiler one warm sample takes {pf['wall_s'] * 1e3:.0f} ms wall and "
          f"{pf['cpu_s'] * 1e3:.0f} ms of CPU time in one process (one torch thread); two workers on two idle "
          f"cores could therefore give at most about {2.0 / pf['cpu_s']:.1f} samples/s."]
    spy = tp.get("pyspy")
    if spy:
        L += ["", f"py-spy on the real DataLoader (`py-spy record --subprocesses`, 100 Hz, attached after the "
              f"warm-up pass, batch 1; "
              f"{spy['samples']} busy samples in the two workers): inclusive share of the workers' busy time:", "",
              "| function | share |", "|---|---|"]
        for k in SPY_FUNCS:
            L.append(f"| `{k}` | {spy['share'].get(k, 0.0) * 100:.0f} % |")
    if prof_note:
        L += ["", prof_note]
    # bins
    L += ["", "![approximations](img/dataset_approximations.png)", "",
          "## 2. Time bins K (radiance constant within a bin)", "",
          f"Scene `{bins['scene_id']}` ({bins['size'][1]}x{bins['size'][0]} px, {bins['lights']} flickering "
          f"lights, groups {', '.join(bins['groups'])} only, frame 0, ego camera moving at "
          f"{bins.get('speed_mps', float('nan')):.1f} m/s), rendered with the same "
          f"seed, spp {bins['spp']} and light_spp {bins['light_spp']} at each K; reference K = {bins['k_ref']}. "
          f"Mean electrons (noise-free, before clipping) composed by `compose_frame` for the same "
          f"{bins['draws']} PWM draws (default `pwm.yaml`), global shutter; error = pooled relative RMSE "
          "over the frame against the reference (LPD short exposure, SPD long exposure, and `gt`, the "
          "duty-cycle-weighted truth). Render time: in-process `render_tools` jobs after a warm-up render "
          "(so JIT compilation of new film sizes is included, Mitsuba import is not). The last row compares two "
          f"K = {bins['k_ref']} renders with different seeds: the Monte Carlo floor of the metric.", "",
          "CPU time (all threads of this process) is less sensitive to the other jobs on the machine than "
          "wall time.", "",
          "| K | render wall (s) | render CPU (s) | rel. RMSE LPD | rel. RMSE SPD | rel. RMSE gt |",
          "|---|---|---|---|---|---|"]
    for r in bins["rows"]:
        k = f"{bins['k_ref']} (2nd seed: MC floor)" if r["K"] == "ref2" else str(r["K"])
        L.append(f"| {k} | {r['render_s']:.1f} | {r.get('render_cpu_s', float('nan')):.1f} | {r['lpd']:.4f} | "
                 f"{r['spd']:.4f} | {r['gt']:.4f} |")
    L.append(f"| {bins['k_ref']} (reference) | {bins['ref_render_s']:.1f} | "
             f"{bins.get('ref_render_cpu_s', float('nan')):.1f} | 0 | 0 | 0 |")
    # psf
    L += ["", "## 3. PSF truncation radius", "",
          f"Scene `{psf['scene_id']}` ({psf['size'][1]}x{psf['size'][0]} px, all groups, frame 0), sensor `ovt` "
          "(f/5.73, 2.8 um; the Airy kernel of each band is truncated to (2R+1)^2 px and renormalised to unit "
          f"sum), against R = {psf['r_ref']}: LPD mean electrons composed for {psf['draws']} PWM draws. "
          "Relative RMSE over the frame, and the 99th percentile / maximum of the per-pixel relative error "
          "|e - e_ref| / (e_ref + eps), eps = 1 % of the mean, and the share of pixels where it exceeds 1 %. "
          "The last-but-two column is the Airy energy outside a circle of radius R px at 550 nm "
          "(`lfmbench.sensor.optics.airy_encircled_energy`; it falls as 1/R): the renormalised kernel puts it back "
          "into the core, so the pixels around bright lights lose their diffraction halo; where the scene is "
          "dark that halo dominates, hence the large per-pixel errors even at R = 16. "
          "`build_layers`: projecting every layer of the scene "
          "(EXR decode included, the per-scene cost of a cold cache); `project`: one full-frame 31-band layer "
          "(direct conv2d below a 31 px kernel, FFT above; `lfmbench.sensor.optics.apply_psf`).", "",
          "| R (px) | rel. RMSE | p99 per-pixel rel. err | pixels > 1 % off | max per-pixel rel. err | "
          "Airy energy outside R | build_layers (s) | project (ms) |", "|---|---|---|---|---|---|---|---|"]
    for r in psf["rows"]:
        L.append(f"| {r['R']}{' (ref)' if r['R'] == psf['r_ref'] else ''} | {r['rel_rmse']:.2e} | "
                 f"{r['p99_rel']:.2e} | {r['frac_1pc'] * 100:.1f} % | {r['max_rel']:.2e} | {_airy_outside(r['R']) * 100:.1f} % | {r['build_s']:.2f} | {r['project_s'] * 1e3:.1f} |")
    # rolling
    L += ["", "## 4. Rolling shutter through per-row bin weights", "",
          f"Scene `{rs['scene_id']}` ({rs['size'][1]}x{rs['size'][0]} px, {rs['lights']} flickering lights in "
          f"frame 0, K = {rs['bins']}, line time {rs['line_time_s'] * 1e6:.0f} us), {rs['draws']} PWM draws. "
          "Exact method (`compose_frame(shutter='rolling')`): per-row window starts, exact PWM exposure of each "
          "bin's overlap with each row's window. Brute force: each row's window sampled at N midpoints in time, "
          "PWM level and bin radiance at each instant (Riemann sum, `brute_rolling` in the script). Error: pooled "
          "relative RMSE of the flickering part (e-) over the frame; it falls as 1/N because the PWM edges fall "
          "between samples, i.e. the brute force converges to the per-row weights, which carry no error of "
          "their own beyond the bin approximation of section 2.", "",
          "| N samples / row window | brute force (s / frame) | rel. RMSE LPD | rel. RMSE SPD |", "|---|---|---|---|"]
    for r in rs["rows"]:
        L.append(f"| {r['N']} | {r['brute_s']:.3f} | {r['lpd']:.2e} | {r['spd']:.2e} |")
    L += ["", f"Per-row bin weights: {rs['vec_s'] * 1e3:.1f} ms per frame (all lights, LPD + SPD + gt; global "
          f"shutter: {rs['global_s'] * 1e3:.1f} ms). Rolling vs global shutter differ by a relative RMSE of "
          f"{rs['global_vs_rolling_lpd']:.3f} (LPD, flickering part): the effect is not negligible.", "",
          "## Notes", "",
          "- Static layers keep their global-shutter motion blur under a rolling shutter (documented in "
          "docs/guide/datasets.md); not measured here.",
          "- Renders are small (few lights, few pixels); errors are for these scenes, not a bound."]
    return "\n".join(L) + "\n"


def _run(out: Path, q: bool, only: set, env: dict, prev: dict) -> dict:
    """Run the requested sections; returns the results (also saved to ``<out>/results.json``)."""
    t_all = time.perf_counter()
    tp_root = out / "tp"
    _log("throughput corpus (reused when complete)")
    _render(tp_root, {"width": TP_SIZE[1], "height": TP_SIZE[0], "spp": TP_SPP, "bins": TP_BINS,
                      "frames": TP_FRAMES}, TP_SEED, scenes=2)
    res = dict(prev)

    def save() -> None:
        _atomic_write_text(out / "results.json", json.dumps(res, indent=1, default=str))

    if "tp" in only:
        res["tp"] = bench_throughput(tp_root, q)
        save()
    if "bins" in only:
        scene = Corpus(tp_root).scene(Corpus(tp_root).scenes[0])
        ks, k_ref = ([1, 4, 16], 32) if q else ([1, 2, 4, 8, 16], 64)
        res["bins"] = bench_bins(out / "bins", scene, (256, 320), ks, k_ref, spp=4, light_spp=16 if q else 64,
                                 n_draws=16)
        save()
    if "psf" in only:
        res["psf"] = bench_psf(tp_root, [0, 1, 2, 4, 8] if q else [0, 1, 2, 4, 8, 16], 16 if q else 32,
                               n_draws=4, repeat=1 if q else 2)
        save()
    if "rolling" in only:
        res["rolling"] = bench_rolling(tp_root, [16, 64, 256, 1024] if q else [16, 64, 256, 1024, 4096],
                                       n_draws=4, repeat=3 if q else 5)
    env["load_end"] = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    res["env"] = env
    res["quick"] = q
    res["seconds"] = time.perf_counter() - t_all
    save()
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer passes, Ks, radii and N (about 3 min)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench_out" / "dsbench", help="render directory")
    ap.add_argument("--only", default="tp,bins,psf,rolling", help="comma list of sections to run (others "
                    "are taken from <out>/results.json)")
    ap.add_argument("--report-only", action="store_true", help="only rewrite the doc and plots from "
                    "<out>/results.json")
    ap.add_argument("--spy-child", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--spy-seconds", type=float, default=5.0, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.spy_child:
        _spy_child(a.spy_child, a.spy_seconds)
        return 0
    q = a.quick
    out = a.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    only = set(a.only.split(","))
    env = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "machine": platform.processor() or
           platform.machine(), "cpus": os.cpu_count(), "torch": torch.__version__,
           "load_start": ", ".join(f"{x:.1f}" for x in os.getloadavg())}
    prev = {}
    if (out / "results.json").is_file():
        prev = json.loads((out / "results.json").read_text())
    if a.report_only:
        res = prev
        q = bool(res.get("quick", False))
        env = res["env"]
    else:
        res = _run(out, q, only, env, prev)
    warm = max(r["sps"] for r in res["tp"]["rows"] if r["mode"] == "warm")
    note = ""
    sh = (res["tp"].get("pyspy") or {}).get("share") or {}
    if sh:
        pc = {k: f"{sh.get(k, float('nan')) * 100:.0f} %" for k in SPY_FUNCS}
        sn = res["tp"].get("shot", {})
        note = (("**Below target.** " if warm < TARGET_SPS else "")
                + f"A warm sample does no file I/O: the workers are CPU-bound. In the workers "
                f"(py-spy) `simulate_split_pixel_electrons` takes {pc['simulate_split_pixel_electrons']}, of it "
                f"`shot_noise` {pc['shot_noise']}; `compose_frame` {pc['compose_frame']}; collation into shared "
                f"memory {pc['collate']}. With {res['tp']['profile']['cpu_s'] * 1e3:.0f} ms of CPU per sample, two "
                f"idle cores would give about {2.0 / res['tp']['profile']['cpu_s']:.0f} samples/s before the "
                "DataLoader's own costs.")
        if sn:
            note += (f" `shot_noise` on one sample's `gt` (LPD mean electrons; {sn['pixels']} px, "
                     f"{sn['frac_small'] * 100:.1f} % below the {sn['switch_e']:.0f} e- Gaussian switch-over, so "
                     f"exact Poisson almost everywhere): {sn['shot_noise_s'] * 1e3:.1f} ms with the compiled "
                     f"sampler of `lfmbench.sensor.poisson` (what the CPU path uses), "
                     f"{sn['shot_noise_torch_s'] * 1e3:.1f} ms with the `torch` backend, against "
                     f"{sn['poisson_s'] * 1e3:.1f} ms for bare `torch.poisson` and "
                     f"{sn['randn_s'] * 1e3:.1f} ms for `torch.randn` on every pixel.")
    plots(res["tp"], res["bins"], res["psf"], res["rolling"])
    text = report(res["tp"], res["bins"], res["psf"], res["rolling"], env, q, note)
    old = DOC.read_text() if DOC.is_file() else ""
    for part in ("batched-capture", "architectures"):  # sections bench_batched_capture.py / bench_architectures.py
        begin, end = f"<!-- {part}:begin -->", f"<!-- {part}:end -->"  # rewrite: kept as they are
        if begin in old and end in old:
            text = text.rstrip("\n") + "\n\n" + old[old.index(begin):old.index(end) + len(end)] + "\n"
    _atomic_write_text(DOC, text)
    _log(f"wrote {DOC} and {IMG}/dataset_*.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
