"""Statistics of a study: which settings are as good as the best, and how sure that is.

Every test comes from SciPy; what SciPy does not have is written here from its textbook
definition and checked against hand-worked cases in the tests:

* :func:`median_ci`: the median and a bootstrap interval (``scipy.stats.bootstrap``,
  percentile method, an explicit seed);
* :func:`friedman`: Friedman's test across settings on common seeds
  (``scipy.stats.friedmanchisquare``; settings as treatments, seeds as blocks);
* :func:`holm`: Holm's step-down adjustment of p-values (Holm 1979);
* :func:`a12`: the Vargha–Delaney effect size ``A₁₂ = P(X > Y) + ½ P(X = Y)``, from the
  Mann–Whitney U statistic (``scipy.stats.mannwhitneyu``);
* :func:`compare_to_best`: the best setting by median, two-sided Wilcoxon signed-rank tests
  of every other setting against it on common seeds (``scipy.stats.wilcoxon``), Holm's
  correction and A₁₂; a setting is *tied with the best* unless its adjusted p-value is below
  α and its median is worse;
* :func:`conover`: the post-hoc comparison of Friedman rank sums (Conover 1999, §5.8, as in
  irace's racing), used by the race to drop settings early.

Scores are "higher is better" (hypervolume); pass ``-IGD+`` for a lower-is-better score.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

__all__ = ["median_ci", "median_ci_clustered", "friedman", "holm", "a12", "Comparison", "compare_to_best", "conover"]


def median_ci(x, confidence: float = 0.95, n_resamples: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """``(median, low, high)`` of the values x: a percentile bootstrap interval of the median
    (``scipy.stats.bootstrap``, ``n_resamples`` resamples from ``seed``). NaN values are
    dropped; one value gives a zero-width interval, none gives NaNs."""
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan, math.nan
    med = float(np.median(x))
    if x.size == 1 or np.ptp(x) == 0:
        return med, med, med
    res = sps.bootstrap((x,), np.median, confidence_level=confidence, n_resamples=n_resamples, method="percentile",
                        rng=np.random.default_rng(seed))
    return med, float(res.confidence_interval.low), float(res.confidence_interval.high)


def median_ci_clustered(M, confidence: float = 0.95, n_resamples: int = 2000,
                        seed: int = 0) -> tuple[float, float, float]:
    """``(median, low, high)`` of the values M (clusters, members), the interval by
    resampling whole clusters (a study's instances, each with its seeds): a percentile
    bootstrap (``scipy.stats.bootstrap`` over the cluster indices) of the median of every
    finite value in the resampled clusters. One cluster gives :func:`median_ci` over its
    members; no finite value gives NaNs."""
    M = np.asarray(M, dtype=np.float64)
    if M.ndim != 2:
        raise ValueError(f"M must be (clusters, members), got shape {M.shape}")
    finite = M[np.isfinite(M)]
    if finite.size == 0:
        return math.nan, math.nan, math.nan
    keep = np.flatnonzero(np.isfinite(M).any(axis=1))
    if keep.size == 1:
        return median_ci(M[keep[0]], confidence, n_resamples, seed)
    med = float(np.median(finite))
    if np.ptp(finite) == 0:
        return med, med, med

    def statistic(idx):
        values = M[idx.astype(np.int64)]
        return np.median(values[np.isfinite(values)])

    res = sps.bootstrap((keep.astype(np.float64),), statistic, vectorized=False, confidence_level=confidence,
                        n_resamples=n_resamples, method="percentile", rng=np.random.default_rng(seed))
    return med, float(res.confidence_interval.low), float(res.confidence_interval.high)


def friedman(scores) -> tuple[float, float]:
    """Friedman's test: ``scores`` (settings, seeds), every setting on the same seeds.
    → ``(statistic, p)``; ``(nan, 1.0)`` with fewer than 3 settings or 2 seeds, or when
    every seed ranks the settings the same way by ties (no information)."""
    S = np.asarray(scores, dtype=np.float64)
    if S.ndim != 2 or S.shape[0] < 3 or S.shape[1] < 2:
        return math.nan, 1.0
    if np.all(np.ptp(S, axis=0) == 0):
        return math.nan, 1.0
    res = sps.friedmanchisquare(*S)
    return float(res.statistic), float(res.pvalue)


def holm(p) -> np.ndarray:
    """Holm's step-down adjusted p-values, in the input order: sorted ascending,
    ``p_(i) · (m − i)`` for i = 0.., made non-decreasing, capped at 1. NaN stays NaN."""
    p = np.asarray(p, dtype=np.float64)
    out = np.full(p.shape, np.nan)
    ok = np.flatnonzero(np.isfinite(p))
    if ok.size == 0:
        return out
    order = ok[np.argsort(p[ok], kind="stable")]
    m = order.size
    adjusted = np.minimum(1.0, np.maximum.accumulate(p[order] * (m - np.arange(m))))
    out[order] = adjusted
    return out


def a12(x, y) -> float:
    """Vargha–Delaney A₁₂ of x over y: ``P(X > Y) + ½ P(X = Y)`` for one value drawn from each
    (0.5: no effect; 1: every x beats every y), ``U / (m n)`` with the Mann–Whitney U of x."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    x, y = x[np.isfinite(x)], y[np.isfinite(y)]
    if x.size == 0 or y.size == 0:
        return math.nan
    if np.ptp(np.concatenate([x, y])) == 0:
        return 0.5
    u = sps.mannwhitneyu(x, y, alternative="two-sided").statistic
    return float(u) / (x.size * y.size)


@dataclass(frozen=True)
class Comparison:
    """Every setting against the best (see :func:`compare_to_best`); arrays over settings."""

    best: int
    median: np.ndarray
    p: np.ndarray
    """Two-sided Wilcoxon signed-rank p-value against the best (NaN for the best)."""
    p_holm: np.ndarray
    """Holm-adjusted p-values (NaN for the best)."""
    a12: np.ndarray
    """A₁₂ of the best over the setting (0.5 for the best itself)."""
    tied: np.ndarray
    """Not significantly worse than the best at level ``alpha`` (True for the best)."""
    friedman_p: float
    alpha: float


def compare_to_best(scores, alpha: float = 0.05) -> Comparison:
    """``scores`` (settings, seeds), higher is better, every setting on the same seeds.

    The best is the setting of largest median (ties: the smaller index). Every other setting
    is tested against it by the two-sided Wilcoxon signed-rank test of the paired
    differences (``scipy.stats.wilcoxon``, exact for small samples; 1.0 where every
    difference is 0), the p-values are adjusted by :func:`holm`, and a setting is tied with
    the best unless its adjusted p-value is below ``alpha`` and its median is below the
    best's."""
    S = np.asarray(scores, dtype=np.float64)
    k = S.shape[0]
    med = np.median(S, axis=1)
    best = int(np.argmax(med))
    p = np.full(k, np.nan)
    effect = np.full(k, 0.5)
    for j in range(k):
        if j == best:
            continue
        d = S[best] - S[j]
        p[j] = 1.0 if np.all(d == 0) else float(sps.wilcoxon(S[best], S[j], alternative="two-sided").pvalue)
        effect[j] = a12(S[best], S[j])
    p_adj = holm(p)
    tied = ~((p_adj < alpha) & (med < med[best]))
    tied[best] = True
    return Comparison(best=best, median=med, p=p, p_holm=p_adj, a12=effect, tied=tied,
                      friedman_p=friedman(S)[1], alpha=alpha)


def conover(scores, alpha: float = 0.05) -> np.ndarray:
    """Friedman's post-hoc test against the best (Conover 1999, §5.8), as irace races:
    ``scores`` (settings, seeds), higher is better. Within each seed the settings are ranked
    (1 = best, ties averaged); with rank sums ``R_j``, ``A = Σ r_ij²`` and
    ``B = Σ R_j² / b``, a setting is worse than the best (smallest rank sum) when
    ``R_j − R_best > t_{1−α/2, (b−1)(k−1)} sqrt(2 b (A − B) / ((b−1)(k−1)))``.
    → (settings,) bool, True where significantly worse. Nothing is worse when the ranks
    carry no information (every seed ties everything)."""
    S = np.asarray(scores, dtype=np.float64)
    k, b = S.shape
    if k < 2 or b < 2:
        return np.zeros(k, bool)
    ranks = np.stack([sps.rankdata(-S[:, i]) for i in range(b)], axis=1)  # (k, b), 1 = best
    R = ranks.sum(axis=1)
    A = float(np.sum(ranks * ranks))
    B = float(np.sum(R * R)) / b
    dof = (b - 1) * (k - 1)
    if A - B <= 0:
        return np.zeros(k, bool)
    margin = sps.t.ppf(1.0 - alpha / 2.0, dof) * math.sqrt(2.0 * b * (A - B) / dof)
    return (R - R.min()) > margin
