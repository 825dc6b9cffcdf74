"""Speed and accuracy of the optics and split-pixel sensor model (issue 4, "Performance").

Measures, on this machine (CPU, float32 unless stated):

1. run time of one 256 x 256 x 31-band capture set (optics + three captures) - median of timed passes after a
   warm-up;
2. PSF truncation: error of the blurred irradiance against a 64-pixel-radius reference for kernel radii
   0..32 px, and the run time of direct and FFT convolution;
3. shot noise: distribution error of the rounded-Gaussian approximation against exact Poisson (Kolmogorov and
   total-variation distance, computed exactly from the CDFs) and the sampling time of both;
4. a photon-transfer curve (EMVA 1288) of the three ``ovt`` captures, and the spread over seeds of the
   parameters that the photon-transfer analysis of ``tests/sensor/test_emva1288.py`` recovers.

Writes the tables between the ``<!-- bench_sensor:start -->`` / ``<!-- bench_sensor:end -->`` markers of
``docs/benchmarks/sensor.md`` (the header above them is hand-written) and the plots ``docs/img/sensor_*.png``.
Run: ``.venv/bin/python benchmarks/bench_sensor.py``.
"""
from __future__ import annotations

import os
import platform
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import scipy.stats as st  # noqa: E402
import torch  # noqa: E402

from _timing import median_time  # noqa: E402
from lfmbench.fileio import atomic_save_figure, atomic_write_text  # noqa: E402
from lfmbench.sensor.optics import airy_kernel, apply_psf, simulate_optics  # noqa: E402
from lfmbench.sensor import (  # noqa: E402
    CAPTURES,
    electron_weights,
    load_preset,
    shot_noise,
    simulate_split_pixel,
)

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img"
WL = [float(w) for w in range(400, 701, 10)]
SIZE = 256
#: intra-op threads for the timings: 1, as in DataLoader workers (torch sets 1 thread per worker); on a shared
#: machine a single thread is also far less sensitive to other jobs than a 2-thread pool waiting at barriers
THREADS = int(os.environ.get("LFMBENCH_BENCH_THREADS", "1"))
T_S, T_L = 4e-3, 1 / 90


_LAST_MIN: list[float] = [float("nan")]


def _timeit(fn, repeat: int = 9, warmup: int = 2) -> float:
    """Median wall time of ``repeat`` calls after ``warmup`` calls, in s (the minimum goes to ``_LAST_MIN``)."""
    med, _LAST_MIN[0] = median_time(fn, repeat, warmup)
    return med


def _timed(fn, repeat: int = 15) -> tuple[float, float]:
    med = _timeit(fn, repeat=repeat)
    return med, _LAST_MIN[0]


def _atomic_write_text(path: Path, text: str) -> None:
    atomic_write_text(path, text)


def _atomic_savefig(fig, path: Path) -> None:
    atomic_save_figure(fig, path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def test_scene(dtype=torch.float32) -> torch.Tensor:
    """(1, 31, 256, 256) spectral radiance in W sr^-1 m^-2 nm^-1: dim road texture, a bright edge, small LEDs."""
    g = torch.Generator().manual_seed(0)
    base = 0.01 * (1 + 0.5 * torch.rand(1, 1, SIZE, SIZE, generator=g))
    img = base.expand(1, 31, SIZE, SIZE).clone()
    img[..., 40:120, 150:230] = 2.0                                  # a lit surface (sharp edges)
    wl = torch.tensor(WL)
    red = torch.exp(-0.5 * ((wl - 630) / 10) ** 2).reshape(1, 31, 1, 1)
    white = torch.ones(1, 31, 1, 1)
    for (y, x), spec, amp in [((60, 60), red, 300.0), ((62, 70), red, 300.0), ((180, 100), white, 3000.0),
                              ((200, 200), red, 50.0)]:
        img[..., y - 1:y + 2, x - 1:x + 2] = amp * spec
    return img.to(dtype)


# --------------------------------------------------------------------------------------------- capture set
def bench_capture_set() -> list[tuple[str, tuple[float, float]]]:
    preset = load_preset("ovt")
    torch.set_num_threads(THREADS)
    L = test_scene()
    kern = airy_kernel(WL, preset.optics.f_number, preset.pixel_pitch_m, preset.optics.psf_radius_px,
                       preset.optics.psf_oversample)
    g = torch.Generator().manual_seed(0)

    def optics():
        return simulate_optics(L, WL, preset.optics, preset.pixel_pitch_m, kernel=kern)

    E = optics()
    H_s, H_l = E * T_S, E * T_L

    def sensor():
        return simulate_split_pixel(H_s, H_l, preset, WL, T_S, T_L, generator=g)

    def sensor_nocheck():
        return simulate_split_pixel(H_s, H_l, preset, WL, T_S, T_L, generator=g, check=False)

    def sensor_poisson_only():
        return simulate_split_pixel(H_s, H_l, preset_p, WL, T_S, T_L, generator=g)

    from dataclasses import replace
    preset_p = replace(preset, shot_noise_gaussian_above_e=float("inf"))
    rows = [
        ("kernel build, 31 bands, R = 8 px, 11x11 sub-samples", _timed(lambda: airy_kernel(
            WL, preset.optics.f_number, preset.pixel_pitch_m, 8, 11), repeat=5)),
        ("optics: camera equation + Airy PSF (R = 8, auto = conv2d), kernel cached", _timed(optics)),
        ("optics without PSF (camera equation only)", _timed(
            lambda: simulate_optics(L, WL, preset.optics, preset.pixel_pitch_m, psf=False))),
        ("sensor: 3 captures, noise on (Gaussian shot noise >= 1000 e-)", _timed(sensor)),
        ("sensor: same, input checks off", _timed(sensor_nocheck)),
        ("sensor: exact Poisson everywhere", _timed(sensor_poisson_only)),
        ("sensor: noise off", _timed(lambda: simulate_split_pixel(H_s, H_l, preset, WL, T_S, T_L, noise=False))),
        ("capture set total (optics + sensor)", _timed(lambda: simulate_split_pixel(
            optics() * T_S, optics() * T_L, preset, WL, T_S, T_L, generator=g))),
    ]
    return rows


# -------------------------------------------------------------------------------------------- PSF truncation
def bench_psf() -> tuple[list[dict], Path]:
    preset = load_preset("ovt")
    N, pitch = preset.optics.f_number, preset.pixel_pitch_m
    L = test_scene(torch.float64)
    ref_k = airy_kernel(WL, N, pitch, 64, 5, dtype=torch.float64)
    ref = apply_psf(L, ref_k, method="fft")
    rows = []
    led = torch.zeros(SIZE, SIZE, dtype=torch.bool)
    for y, x in [(60, 60), (62, 70), (180, 100), (200, 200)]:
        led[y - 12:y + 13, x - 12:x + 13] = True
    L32 = L.float()
    for R in [0, 1, 2, 3, 4, 6, 8, 12, 16, 24, 32]:
        k = airy_kernel(WL, N, pitch, R, 11, dtype=torch.float64)
        out = apply_psf(L, k, method="fft") if R > 0 else L
        err = (out - ref).abs()
        rel_l1 = float(err.sum() / ref.sum())
        rel_led = float((err[..., led].sum() / ref[..., led].sum()))
        raw = airy_kernel([550.0], N, pitch, R, 11, normalize=False, dtype=torch.float64)
        k32 = k.float()
        t_conv = _timed(lambda: apply_psf(L32, k32, method="conv"), repeat=9) if R <= 16 else (np.nan, np.nan)
        t_fft = _timed(lambda: apply_psf(L32, k32, method="fft"), repeat=9) if R > 0 else (0.0, 0.0)
        rows.append({"R": R, "energy_550": float(raw.sum()), "rel_l1": rel_l1, "rel_led": rel_led,
                     "t_conv": t_conv, "t_fft": t_fft})
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    Rs = [r["R"] for r in rows]
    ax[0].semilogy(Rs, [r["rel_l1"] for r in rows], "o-", label="whole image, relative L1")
    ax[0].semilogy(Rs, [r["rel_led"] for r in rows], "s-", label="25x25 px around LEDs, relative L1")
    ax[0].semilogy(Rs, [1 - r["energy_550"] for r in rows], "^--", label="PSF power outside window (550 nm)")
    ax[0].set_xlabel("PSF truncation radius R (px)")
    ax[0].set_ylabel("error vs R = 64 px reference")
    ax[0].legend(fontsize=8)
    ax[0].grid(True, which="both", alpha=0.3)
    ax[1].plot(Rs[1:], [1e3 * r["t_fft"][1] for r in rows[1:]], "o-", label="FFT")
    ax[1].plot([r["R"] for r in rows if r["R"] <= 16], [1e3 * r["t_conv"][1] for r in rows if r["R"] <= 16], "s-",
               label="direct conv2d")
    ax[1].set_xlabel("PSF truncation radius R (px)")
    ax[1].set_ylabel("time per 256x256x31 image (ms, fastest pass)")
    ax[1].set_yscale("log")
    ax[1].legend(fontsize=8)
    ax[1].grid(True, which="both", alpha=0.3)
    fig.subplots_adjust(wspace=0.35)
    fig.suptitle(f"Airy PSF truncation (f/5.73, 2.8 um pixels, 400-700 nm), float32 timing, {THREADS} CPU thread(s)")
    path = IMG / "sensor_psf_truncation.png"
    _atomic_savefig(fig, path)
    return rows, path


# --------------------------------------------------------------------------------------------- shot noise
def bench_shot_noise() -> tuple[list[dict], Path]:
    torch.set_num_threads(THREADS)
    n = SIZE * SIZE * 3
    rows = []
    for mu in [0.1, 0.5, 1, 3, 9, 11, 30, 100, 300, 1000, 3000, 10000, 30000]:
        k = np.arange(0, int(mu + 12 * np.sqrt(mu) + 20))
        pois_cdf = st.poisson.cdf(k, mu)
        gauss_cdf = st.norm.cdf((k + 0.5 - mu) / np.sqrt(mu))    # P(round(mu + sqrt(mu) Z) <= k), clipped at 0
        ks = float(np.max(np.abs(pois_cdf - gauss_cdf)))
        pmf_p = np.diff(np.concatenate([[0.0], pois_cdf]))
        pmf_g = np.diff(np.concatenate([[0.0], gauss_cdf]))
        tv = 0.5 * float(np.abs(pmf_p - pmf_g).sum() + abs(1 - pois_cdf[-1] - (1 - gauss_cdf[-1])))
        m = torch.full((n,), float(mu))
        g = torch.Generator().manual_seed(0)
        t_n = _timed(lambda: shot_noise(m, g, float("inf"), backend="numba"), repeat=9)
        t_p = _timed(lambda: shot_noise(m, g, float("inf"), backend="torch"), repeat=9)
        t_g = _timed(lambda: shot_noise(m, g, 0.0, backend="torch"), repeat=9)
        rows.append({"mu": mu, "ks": ks, "tv": tv, "t_numba": t_n, "t_poisson": t_p, "t_gauss": t_g})
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    mus = [r["mu"] for r in rows]
    ax[0].loglog(mus, [r["ks"] for r in rows], "o-", label="Kolmogorov distance")
    ax[0].loglog(mus, [r["tv"] for r in rows], "s-", label="total variation distance")
    ax[0].axvline(1000, color="k", ls=":", label="preset switch-over (1000 e-)")
    ax[0].set_xlabel("mean electrons mu")
    ax[0].set_ylabel("rounded Gaussian vs Poisson")
    ax[0].legend(fontsize=8)
    ax[0].grid(True, which="both", alpha=0.3)
    ax[1].semilogx(mus, [1e3 * r["t_numba"][1] for r in rows], "^-", label="exact Poisson, lfmbench.sensor.poisson (numba)")
    ax[1].semilogx(mus, [1e3 * r["t_poisson"][1] for r in rows], "o-", label="exact Poisson, torch.poisson")
    ax[1].semilogx(mus, [1e3 * r["t_gauss"][1] for r in rows], "s-", label="rounded Gaussian")
    ax[1].set_xlabel("mean electrons mu")
    ax[1].set_ylabel(f"time for {n} samples (ms, fastest pass)")
    ax[1].set_yscale("log")
    ax[1].legend(fontsize=8)
    ax[1].grid(True, which="both", alpha=0.3)
    fig.suptitle(f"Shot noise: distribution error and sampling time (float32, {THREADS} CPU thread(s))")
    path = IMG / "sensor_shot_noise.png"
    _atomic_savefig(fig, path)
    return rows, path


# ---------------------------------------------------------------------------------------- photon transfer
def bench_ptc() -> Path:
    preset = load_preset("ovt")
    fig, ax = plt.subplots(1, 1, figsize=(6, 4))
    size = 96
    green = preset.cfa.index_map(size, size) == 1
    for cap, colour in zip(CAPTURES, ["C0", "C1", "C2"]):
        pd = preset.captures[cap].photodiode
        sat = preset.saturation_capacity_e(cap)
        levels = np.concatenate([[0.0], np.geomspace(1, 1.3 * sat, 60)])
        w = electron_weights(preset, [530.0], pd, bandwidths_nm=[1.0])[1, 0].item()
        H = torch.tensor(levels / w, dtype=torch.float32).reshape(1, -1, 1, 1, 1).expand(2, -1, 1, size, size)
        z = torch.zeros_like(H)
        lpd, spd = (H, z) if pd == "lpd" else (z, H)
        out = simulate_split_pixel(lpd, spd, preset, [530.0], 1e-3, 1e-3, torch.Generator().manual_seed(1),
                                   bandwidths_nm=[1.0])[cap][:, :, 0][..., green].double().numpy()
        mu = out.mean(axis=(0, 2))
        d = out[0] - out[1]
        var = 0.5 * d.var(axis=1)
        sig = mu - mu[0]
        keep = (sig > 0.05) & (np.arange(len(mu)) <= int(np.argmax(var)))   # above dark, up to the variance peak
        ax.loglog(sig[keep], var[keep], ".", color=colour, label=f"{cap} (K = {preset.system_gain(cap):.3f} DN/e-)")
        ax.axhline(var[0], color=colour, ls=":", lw=0.8)
        x = np.geomspace(0.1, preset.saturation_capacity_e(cap) * preset.system_gain(cap), 50)
        ax.loglog(x, var[0] + preset.system_gain(cap) * x, "-", color=colour, lw=0.8)
    ax.set_xlabel("mean signal above dark mu_y - mu_y.dark (DN)")
    ax.set_ylabel("temporal variance sigma_y^2 (DN^2)")
    ax.set_title("Photon transfer (EMVA 1288), ovt preset, green pixels, up to saturation\n"
                 "solid: sigma_y.dark^2 + K (mu_y - mu_y.dark) with the configured K; dotted: sigma_y.dark^2")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    path = IMG / "sensor_ptc.png"
    _atomic_savefig(fig, path)
    return path


def bench_emva_seeds(n_seeds: int = 6) -> list[dict]:
    """Relative errors of the EMVA 1288 estimates of tests/sensor/test_emva1288.py over ``n_seeds`` seeds."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("_emva", ROOT / "tests" / "test_emva1288.py")
    emva = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(emva)
    preset = load_preset("ovt")
    rows = []
    for cap in CAPTURES:
        cs = preset.captures[cap]
        pd = preset.photodiodes[cs.photodiode]
        clip = cs.voltage_swing_v / cs.conversion_gain_v_per_e
        sat_exp = emva.expected_saturation_e(pd.full_well_e, clip, cs.read_noise_e)
        sd_true = np.sqrt(cs.read_noise_e ** 2 + pd.dark_current_e_per_s * emva.T_SHORT)
        sat = preset.saturation_capacity_e(cap)
        levels = np.concatenate([[0.0], np.linspace(0.02, 0.7, 20) * sat, np.linspace(0.71, 1.15, 45) * sat])
        errs = {"K": [], "sd": [], "sd_emva": [], "sat": []}
        for seed in range(n_seeds):
            y, _ = emva._flat_field_pairs(preset, cap, levels, seed=1000 + seed)
            r = emva.photon_transfer(y)
            errs["K"].append(r["K"] / preset.system_gain(cap) - 1)
            errs["sd"].append(r["sigma_d_exact"] / sd_true - 1)
            errs["sd_emva"].append(r["sigma_d"] / sd_true - 1)
            errs["sat"].append(r["mu_e_sat"] / sat_exp - 1)
        rows.append({"capture": cap, "sat_expected": sat_exp, "clip": min(pd.full_well_e, clip),
                     **{k: (min(v), max(v)) for k, v in errs.items()}})
    return rows


def main() -> None:
    torch.set_num_threads(THREADS)
    cap_rows = bench_capture_set()
    psf_rows, psf_png = bench_psf()
    sn_rows, sn_png = bench_shot_noise()
    ptc_png = bench_ptc()
    emva_rows = bench_emva_seeds()
    lines = [
        f"Generated by `benchmarks/bench_sensor.py` on {platform.processor() or platform.machine()}, "
        f"torch {torch.__version__}, {torch.get_num_threads()} intra-op CPU thread(s) (as in a DataLoader worker; "
        "set LFMBENCH_BENCH_THREADS to change), float32 unless stated. "
        "Times are medians of timed passes after a warm-up (load average "
        f"{os.getloadavg()[0]:.1f} when the run started: other jobs shared the 2 cores, so the fastest pass is "
        "shown too; it is the better estimate of the cost on an idle machine).",
        "",
        "### One capture set: 256 x 256 pixels, 31 bands (400:10:700 nm), ovt preset",
        "",
        "| step | median time (ms) | fastest pass (ms) |",
        "|---|---:|---:|",
    ]
    lines += [f"| {name} | {1e3 * t[0]:.1f} | {1e3 * t[1]:.1f} |" for name, t in cap_rows]
    lines += [
        "",
        "### PSF truncation radius: error and time",
        "",
        "Reference: the same pixel-integrated Airy kernels truncated at R = 64 px (float64, FFT). Scene: dim "
        "textured background, a bright rectangle and four 3x3 LEDs up to 3e5 x the background. Kernels are "
        "renormalised to unit sum, so truncation moves the far tail's power into the window.",
        "",
        "| R (px) | PSF power in window at 550 nm | rel. L1 error, image | rel. L1 error, LED surroundings | "
        "conv2d (ms, median / fastest) | FFT (ms, median / fastest) |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for r in psf_rows:
        conv = "-" if np.isnan(r["t_conv"][0]) else f"{1e3 * r['t_conv'][0]:.1f} / {1e3 * r['t_conv'][1]:.1f}"
        lines.append(f"| {r['R']} | {r['energy_550']:.4f} | {r['rel_l1']:.2e} | {r['rel_led']:.2e} | {conv} | "
                     f"{1e3 * r['t_fft'][0]:.1f} / {1e3 * r['t_fft'][1]:.1f} |")
    lines += [
        "",
        f"![PSF truncation](../{psf_png.relative_to(ROOT / 'docs')})",
        "",
        "### Shot noise: rounded Gaussian N(mu, mu) against exact Poisson",
        "",
        f"Distances computed exactly from the two CDFs; times for {SIZE * SIZE * 3} samples of one mean. Both exact "
        "samplers draw the Poisson distribution (tests/sensor/test_poisson.py: chi-square against the pmf); "
        "`lfmbench.sensor.poisson` is what `shot_noise` uses on the CPU, `torch.poisson` on other devices. Below 1 e- the "
        "compiled sampler needs one uniform and one exp; between 1 and 10 e- its sequential search adds a few terms "
        "(evaluated four at a time, one branch per four terms); from 10 e- it is PTRS (two uniforms, a log only off "
        "the squeeze).",
        "",
        "| mean (e-) | Kolmogorov distance | total variation | lfmbench.sensor.poisson (ms, median / fastest) "
        "| torch.poisson (ms, median / fastest) | Gaussian (ms, median / fastest) |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for r in sn_rows:
        lines.append(f"| {r['mu']} | {r['ks']:.2e} | {r['tv']:.2e} | {1e3 * r['t_numba'][0]:.1f} / "
                     f"{1e3 * r['t_numba'][1]:.1f} | {1e3 * r['t_poisson'][0]:.1f} / "
                     f"{1e3 * r['t_poisson'][1]:.1f} | {1e3 * r['t_gauss'][0]:.1f} / {1e3 * r['t_gauss'][1]:.1f} |")
    lines += [
        "",
        f"![Shot noise](../{sn_png.relative_to(ROOT / 'docs')})",
        "",
        "### Photon transfer curve",
        "",
        f"![PTC](../{ptc_png.relative_to(ROOT / 'docs')})",
        "",
        "### EMVA 1288 estimates over 6 seeds (tests/sensor/test_emva1288.py analysis, 128 x 128 flat fields)",
        "",
        "Relative error range (min .. max) against the configured value; saturation against the expected position "
        "of the variance maximum, which itself lies below the clip point.",
        "",
        "| capture | K | sigma_d (exact quantisation) | sigma_d (1/12 DN^2) | mu_e.sat "
        "| expected mu_e.sat / clip (e-) |",
        "|---|---|---|---|---|---|",
    ]
    for r in emva_rows:
        f = lambda k: f"{100 * r[k][0]:+.1f} .. {100 * r[k][1]:+.1f} %"  # noqa: E731
        lines.append(f"| {r['capture']} | {f('K')} | {f('sd')} | {f('sd_emva')} | {f('sat')} | "
                     f"{r['sat_expected']:.0f} / {r['clip']:.0f} |")
    lines.append("")
    doc = ROOT / "docs" / "benchmarks" / "sensor.md"
    start, end = "<!-- bench_sensor:start -->", "<!-- bench_sensor:end -->"
    text = doc.read_text() if doc.exists() else f"# Sensor model: speed and accuracy\n\n{start}\n{end}\n"
    if start not in text or end not in text:
        text = text.rstrip() + f"\n\n## Benchmark\n\n{start}\n{end}\n"
    head, rest = text.split(start, 1)
    tail = rest.split(end, 1)[1]
    _atomic_write_text(doc, head + start + "\n" + "\n".join(lines) + "\n" + end + tail)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
