"""Error against run time of the PWM exposure model (issue 2).

Compares every closed-form implementation of :func:`lfmbench.flicker.pwm_exposure` and numerical integration
of the sampled waveform (midpoint rule, N = 10 .. 10^6 samples per exposure) against exact rational
arithmetic (``fractions.Fraction`` on the float inputs). Writes ``docs/benchmarks/flicker.md`` and
``docs/img/flicker_error_vs_speed.png``.

Run: ``make bench`` (or ``.venv/bin/python benchmarks/bench_flicker.py``).
"""
from __future__ import annotations

import math
import os
import platform
import time
from fractions import Fraction as Fr
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from lfmbench.fileio import atomic_save_figure, atomic_write_text  # noqa: E402
from lfmbench.flicker import pwm_exposure, pwm_level  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
rng = np.random.default_rng(2026)


def cases(n: int):
    """Random cases over the issue's ranges plus the extreme grid (duty 0/1, edges, 1e4 periods)."""
    T = 10 ** rng.uniform(-6, 0, n)
    D = rng.uniform(0, 1, n)
    ph = rng.uniform(-10, 10, n) * T
    te = rng.uniform(0, 20, n) * T
    k = n // 4  # a quarter of extremes
    D[:k] = rng.choice([0.0, 1e-12, 0.5, 1 - 1e-12, 1.0], k)
    te[:k] = rng.choice([0.0, 1e-9, 1.0, 1e4, 1e4 + 0.3], k) * T[:k]
    ph[:k] = rng.choice([0.0, 1.0, 0.999999999], k) * D[:k] * T[:k]
    return ph, te, T, D


def exact(ph, te, T, D):
    out = []
    for a, e, t, d in zip(ph, te, T, D):
        a, e, t, d = Fr(a), Fr(e), Fr(t), Fr(d)

        def F(x):
            q = math.floor(x / t)
            return q * d * t + min(x - q * t, d * t)
        out.append(F(a + e) - F(a))
    return out


def max_rel_err(got, ref) -> float:
    worst = 0.0
    for g, r in zip(got, ref):
        worst = max(worst, float(abs(Fr(float(g)) - r) / max(abs(r), Fr(1e-290))))
    return worst


def max_scaled_err(got, ref, te, T) -> float:
    """Max absolute error in units of max(exposure, period): the meaningful figure for float32."""
    return max(float(abs(Fr(float(g)) - r)) / max(e, t) for g, r, e, t in zip(got, ref, te, T))


def rate(fn, n_eval: int, repeats: int = 7) -> float:
    fn()  # warm-up (numba compile, allocator)
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return n_eval / float(np.median(ts))


def plain_numpy(ph, te, T, D):
    """The plain cumulative-ON-time formula in numpy (the issue's 5.5 M/s baseline)."""
    def F(x):
        return np.floor(x / T) * D * T + np.minimum(np.mod(x, T), D * T)
    return F(ph + te) - F(ph)


def main() -> None:
    n_err, n_speed = 3000, 2_000_000
    ph, te, T, D = cases(n_err)
    ref = exact(ph, te, T, D)
    sph, ste, sT, sD = cases(n_speed)
    rows = []

    def add(name, got, evals_per_s, note="", ref_=None, inputs=None):
        ref_ = ref if ref_ is None else ref_
        te_, T_ = (te, T) if inputs is None else inputs
        err, serr = max_rel_err(got, ref_), max_scaled_err(got, ref_, te_, T_)
        rows.append((name, err, serr, evals_per_s, note))
        print(f"{name:40s} max rel err {err:9.2e}  scaled {serr:9.2e}  {evals_per_s / 1e6:9.2f} M eval/s  {note}")

    add("closed form, numba float64 (default)", pwm_exposure(ph, te, T, D),
        rate(lambda: pwm_exposure(sph, ste, sT, sD), n_speed), "2 threads, input checks on")
    add("closed form, numba float64, check=False", pwm_exposure(ph, te, T, D, check=False),
        rate(lambda: pwm_exposure(sph, ste, sT, sD, check=False), n_speed))
    tt = [torch.tensor(x) for x in (ph, te, T, D)]
    stt = [torch.tensor(x) for x in (sph, ste, sT, sD)]
    add("closed form, torch float64", pwm_exposure(*tt).numpy(),
        rate(lambda: pwm_exposure(*stt), n_speed), "differentiable")
    t32 = [x.float() for x in tt]
    s32 = [x.float() for x in stt]
    in32 = [x.double().numpy() for x in t32]  # the exact answer for the float32-rounded inputs
    add("closed form, torch float32", pwm_exposure(*t32).double().numpy(),
        rate(lambda: pwm_exposure(*s32), n_speed), "scaled error is the meaningful one",
        ref_=exact(*in32), inputs=(in32[1], in32[2]))
    add("closed form, generic numpy (fallback)", pwm_exposure(ph, te, T, D, backend="numpy"),
        rate(lambda: pwm_exposure(sph, ste, sT, sD, backend="numpy"), n_speed), "backend='numpy'")
    add("plain numpy cumulative formula", plain_numpy(ph, te, T, D),
        rate(lambda: plain_numpy(sph, ste, sT, sD), n_speed), "no EFT, no checks")

    quad_rows = []
    sel = slice(0, 300)
    qref = ref[sel]
    for N in (10, 100, 1000, 10_000, 100_000, 1_000_000):
        m = max(1, min(300, 20_000_000 // (N * 8)))  # cases per chunk to bound memory

        def quad(idx=np.arange(300)):
            out = np.empty(len(idx))
            for s in range(0, len(idx), m):
                j = idx[s:s + m]
                t = ph[j, None] + (np.arange(N) + 0.5)[None, :] * (te[j, None] / N)
                out[s:s + m] = pwm_level(t, T[j, None], D[j, None]).sum(-1) * (te[j] / N)
            return out
        qv = quad()
        err, serr = max_rel_err(qv, qref), max_scaled_err(qv, qref, te[sel], T[sel])
        n_t = 300 if N <= 10_000 else (30 if N == 100_000 else 6)
        r = rate(lambda: quad(np.arange(n_t)), n_t, repeats=3)
        quad_rows.append((N, err, serr, r))
        print(f"midpoint quadrature N={N:>8d}         max rel err {err:9.2e}  scaled {serr:9.2e}  {r / 1e6:9.5f} M eval/s")

    # ---- table
    lines = ["# PWM exposure model: error against run time", "",
             f"Measured by `make bench` (`benchmarks/bench_flicker.py`) on {time.strftime('%Y-%m-%d', time.gmtime())}, "
             f"1-minute load average {os.getloadavg()[0]:.1f} at the end, on {platform.processor() or platform.machine()}, "
             f"{os.cpu_count()} cores, numpy {np.__version__}, torch {torch.__version__}; medians of 7 timed "
             "runs after a warm-up, 2,000,000 evaluations each. Error: maximum relative error against exact "
             f"rational arithmetic on {n_err} cases (3000 random over period 1 us..1 s, duty [0, 1], phase "
             "+-10 periods, exposure 0..20 periods; a quarter extreme: duty 0, 1e-12, 0.5, 1-1e-12, 1; exposure "
             "0, 1e-9, 1, 1e4 periods; phase on the pulse edges). Values below 1e-290 count absolutely.", "",
             "Scaled error: max absolute error / max(exposure, period).", "",
             "| implementation | max rel. error | max scaled error | M evaluations/s | note |", "|---|---|---|---|---|"]
    for name, err, serr, r, note in rows:
        lines.append(f"| {name} | {err:.2e} | {serr:.2e} | {r / 1e6:.1f} | {note} |")
    lines += ["", "Numerical integration of the sampled waveform (midpoint rule, N samples per exposure, first 300 "
              "cases; its relative error is huge where the exact value is 0 or tiny, so compare the scaled error):",
              "", "| N samples | max rel. error | max scaled error | M evaluations/s |", "|---|---|---|---|"]
    for N, err, serr, r in quad_rows:
        lines.append(f"| {N:,} | {err:.2e} | {serr:.2e} | {r / 1e6:.5f} |")
    lines += ["", "![error vs speed](../img/flicker_error_vs_speed.png)", ""]
    atomic_write_text(ROOT / "docs" / "benchmarks" / "flicker.md", "\n".join(lines))

    # ---- plot
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, err, serr, r, _ in rows:
        ax.scatter(r, max(serr, 1e-17), s=40, label=name)
    ax.plot([r for *_, r in quad_rows], [e for _, _, e, _ in quad_rows], "k.-", label="midpoint quadrature")
    for N, _, e, r in quad_rows:
        ax.annotate(f"N={N:g}", (r, e), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.axhline(1e-12, color="gray", ls="--", lw=0.8)
    ax.axvline(20e6, color="gray", ls=":", lw=0.8)
    ax.set(xscale="log", yscale="log", xlabel="evaluations per second (2 cores)",
           ylabel="max |error| / max(exposure, period)", title="PWM radiant exposure: error against run time")
    ax.legend(fontsize=7, loc="lower center", bbox_to_anchor=(0.42, 0.02))
    fig.tight_layout()
    atomic_save_figure(fig, ROOT / "docs" / "img" / "flicker_error_vs_speed.png", dpi=120)
    print("wrote docs/benchmarks/flicker.md and docs/img/flicker_error_vs_speed.png")


if __name__ == "__main__":
    main()
