"""Statistics of a benchmark over scenes: bootstrap confidence intervals, paired tests against the best method.

Defines
-------
- :func:`bootstrap_ci`: a confidence interval of the mean (or of a pooled ratio) over scenes, by the bootstrap
  (``scipy.stats.bootstrap``, BCa, seeded).
- :func:`paired_test`: each method against the best, paired over the scenes both scored: the exact Wilcoxon
  signed-rank test (``scipy.stats.wilcoxon``) and a bootstrap CI of the mean paired difference.
- :func:`holm`: Holm's step-down adjustment of the p-values of those comparisons.

The unit of resampling is the scene: samples of one scene (several PWM draws) share its geometry and are not
independent, so they are averaged per scene first (``lfmbench.evaluation.results.per_scene``).

References
----------
- B. Efron, "Better bootstrap confidence intervals", JASA 82(397), 1987 (BCa); B. Efron and R. J. Tibshirani,
  "An Introduction to the Bootstrap", Chapman & Hall 1993.
- F. Wilcoxon, "Individual comparisons by ranking methods", Biometrics Bulletin 1(6), 1945.
- S. Holm, "A simple sequentially rejective multiple test procedure", Scand. J. Statistics 6(2), 1979.
- J. Demsar, "Statistical comparisons of classifiers over multiple data sets", JMLR 7, 2006 (Wilcoxon
  signed-rank for two methods over data sets; Holm for comparisons with a control).
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence

import numpy as np

#: Bootstrap resamples per interval (``scipy.stats.bootstrap`` ``n_resamples``).
N_RESAMPLES = 10_000
#: Confidence level of every interval.
CONFIDENCE = 0.95
#: Seed of the bootstrap and permutation generators (results are reproducible).
SEED = 0
#: The bootstrap interval method (``scipy.stats.bootstrap`` ``method``); ``percentile`` is the fallback when
#: BCa is undefined (e.g. 2 scenes: the jackknife acceleration has no spread).
METHOD = "BCa"
#: Significance level used to mark a difference in the tables (on Holm-adjusted p-values).
ALPHA = 0.05


def settings() -> dict:
    """The statistics settings stored with every result and leaderboard."""
    return {"ci": f"bootstrap over scenes ({METHOD}, percentile fallback), scipy.stats.bootstrap",
            "n_resamples": N_RESAMPLES, "confidence": CONFIDENCE, "seed": SEED,
            "paired_test": "Wilcoxon signed-rank over scenes (scipy.stats.wilcoxon, two-sided; exact without "
                           "ties or zeros, else a seeded sign-flip permutation distribution), Holm-adjusted",
            "alpha": ALPHA}


def _finite(values, weights=None) -> tuple[np.ndarray, np.ndarray | None]:
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if weights is None:
        return v[np.isfinite(v)], None
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    if w.shape != v.shape:
        raise ValueError(f"weights must have the shape of values {v.shape}, got {w.shape}")
    ok = np.isfinite(v) & np.isfinite(w) & (w > 0)
    return v[ok], w[ok]


def bootstrap_ci(values: Sequence[float], weights: Sequence[float] | None = None, *,
                 n_resamples: int = N_RESAMPLES, confidence: float = CONFIDENCE, seed: int = SEED,
                 method: str = METHOD) -> tuple[float, float]:
    """Bootstrap confidence interval of the mean of ``values`` (one per scene), or of the pooled ratio
    ``sum(v w) / sum(w)`` when ``weights`` are given (scenes resampled with their weights).

    Non-finite values (and non-positive weights) are left out. Fewer than 2 values give ``(nan, nan)``; values
    that are all equal give ``(v, v)``. BCa intervals that come out undefined fall back to the percentile method.

    Args:
        values: (N,) per-scene values, any unit.
        weights: optional (N,) non-negative weights (e.g. region-frames per scene).
        n_resamples: bootstrap resamples.
        confidence: confidence level in (0, 1).
        seed: seed of the resampling generator.
        method: ``BCa``, ``percentile`` or ``basic`` (``scipy.stats.bootstrap``).

    Returns:
        (low, high) in the unit of ``values``.
    """
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    from scipy import stats

    v, w = _finite(values, weights)
    if v.size < 2:
        return float("nan"), float("nan")
    if np.all(v == v[0]):
        return float(v[0]), float(v[0])
    if w is None:
        data, paired = (v,), False

        def stat(x, axis=-1):
            return np.mean(x, axis=axis)
    else:
        data, paired = (v, w), True

        def stat(x, y, axis=-1):
            return np.sum(x * y, axis=axis) / np.sum(y, axis=axis)

    for m in dict.fromkeys((method, "percentile")):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy's DegenerateDataWarning: handled by the fallback
            res = stats.bootstrap(data, stat, n_resamples=n_resamples, confidence_level=confidence, method=m,
                                  paired=paired, vectorized=True, rng=np.random.default_rng(seed))
        lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
        if math.isfinite(lo) and math.isfinite(hi):
            return lo, hi
    return float("nan"), float("nan")


def wilcoxon_p(diffs: Sequence[float], seed: int = SEED, n_resamples: int = N_RESAMPLES) -> float:
    """Two-sided p-value of the Wilcoxon signed-rank test that the paired differences are centred on 0.

    Zero differences are dropped (Wilcoxon's convention). Without ties the exact null distribution is used
    (``method='exact'``); with ties the p-value comes from the sign-flip permutation distribution of the
    signed-rank statistic (``scipy.stats.PermutationMethod``, exhaustive when ``2^n <= n_resamples``, else
    ``n_resamples`` seeded flips). No non-zero difference gives 1.0; no difference at all gives NaN.

    Args:
        diffs: (N,) paired differences (method - best), per scene.

    Returns:
        p in [0, 1], or NaN.
    """
    from scipy import stats

    d = np.asarray(diffs, dtype=np.float64).reshape(-1)
    d = d[np.isfinite(d)]
    if d.size == 0:
        return float("nan")
    nz = d[d != 0]
    if nz.size == 0:
        return 1.0
    ties = np.unique(np.abs(nz)).size < nz.size
    method = (stats.PermutationMethod(n_resamples=n_resamples, rng=np.random.default_rng(seed)) if ties
              else ("exact" if nz.size <= 50 else "asymptotic"))
    return float(stats.wilcoxon(nz, zero_method="wilcox", alternative="two-sided", method=method).pvalue)


def paired_test(values: Sequence[float], best: Sequence[float], **ci_kw) -> dict:
    """A method against the best one, paired over scenes (``values[i]`` and ``best[i]`` on the same scene).

    Args:
        values, best: (N,) per-scene values of one metric; pairs with a non-finite member are dropped.
        ci_kw: passed to :func:`bootstrap_ci` (the CI of the mean difference).

    Returns:
        ``{"n": pairs, "mean_diff": mean(values - best), "ci": [low, high] of it, "p": Wilcoxon p}``.
    """
    a, b = np.asarray(values, dtype=np.float64), np.asarray(best, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"values and best must be paired (same length), got {a.shape} and {b.shape}")
    ok = np.isfinite(a) & np.isfinite(b)
    d = a[ok] - b[ok]
    lo, hi = bootstrap_ci(d, **ci_kw)
    return {"n": int(d.size), "mean_diff": float(d.mean()) if d.size else float("nan"), "ci": [lo, hi],
            "p": wilcoxon_p(d)}


def paired_by_scene(values: Mapping[str, float | None], best: Mapping[str, float | None], **ci_kw) -> dict:
    """:func:`paired_test` over the scenes both scored: ``values`` and ``best`` map scene id -> that scene's value of
    one metric (None or non-finite: not scored, the pair dropped); scenes of only one side are left out.

    >>> paired_by_scene({"a": 1.0, "b": 3.0, "c": None}, {"a": 0.5, "b": 2.5, "d": 9.0})["mean_diff"]
    0.5
    """
    ids = [s for s in best if s in values]
    return paired_test([values[s] for s in ids], [best[s] for s in ids], **ci_kw)


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values (family-wise error control), NaN entries kept as NaN.

    Sorted ascending, ``p_(i)`` becomes ``max_{j <= i} min(1, (m - j + 1) p_(j))`` with m the number of
    finite p-values.

    >>> [round(p, 3) for p in holm([0.01, 0.04, 0.03, float("nan")])]
    [0.03, 0.06, 0.06, nan]
    """
    p = np.asarray(pvalues, dtype=np.float64)
    idx = [i for i in np.argsort(p) if math.isfinite(p[i])]
    m = len(idx)
    out = [float("nan")] * len(p)
    run = 0.0
    for j, i in enumerate(idx):
        run = max(run, min(1.0, (m - j) * float(p[i])))
        out[i] = run
    return out
