"""The statistics of a study (dockjax.stats) and the race's decisions (dockjax.sweep.race),
against SciPy and hand-worked cases."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import stats as sps

from dockjax import stats
from dockjax.sweep.race import eliminate


def test_holm_matches_a_hand_worked_case():
    # sorted: 0.005·4 = 0.02, 0.01·3 = 0.03, 0.03·2 = 0.06, 0.04·1 = 0.04 → made monotone: 0.06
    np.testing.assert_allclose(stats.holm([0.01, 0.04, 0.03, 0.005]), [0.03, 0.06, 0.06, 0.02])
    np.testing.assert_allclose(stats.holm([0.5, 0.6]), [1.0, 1.0])  # capped at 1
    out = stats.holm([np.nan, 0.02, 0.01])
    assert np.isnan(out[0]) and np.allclose(out[1:], [0.02, 0.02])


def test_a12_counts_wins_and_half_ties():
    rng = np.random.default_rng(0)
    for _ in range(20):
        x = rng.integers(0, 5, rng.integers(1, 9)).astype(float)
        y = rng.integers(0, 5, rng.integers(1, 9)).astype(float)
        brute = np.mean([(a > b) + 0.5 * (a == b) for a, b in itertools.product(x, y)])
        assert stats.a12(x, y) == pytest.approx(brute)
    assert stats.a12([3, 4], [1, 2]) == 1.0 and stats.a12([1, 1], [1, 1]) == 0.5


def test_median_ci_is_scipys_percentile_bootstrap():
    x = np.random.default_rng(1).normal(size=25)
    med, lo, hi = stats.median_ci(x, seed=7)
    ref = sps.bootstrap((x,), np.median, method="percentile", n_resamples=2000, rng=np.random.default_rng(7))
    assert med == np.median(x) and lo <= med <= hi
    assert (lo, hi) == (ref.confidence_interval.low, ref.confidence_interval.high)
    assert stats.median_ci([2.0, 2.0, 2.0]) == (2.0, 2.0, 2.0)
    assert all(np.isnan(v) for v in stats.median_ci([np.nan]))


def test_the_clustered_interval_resamples_whole_instances():
    """Against a cluster bootstrap written here with NumPy (instances drawn with replacement,
    each with all its seeds; 20000 resamples): the percentile interval agrees within Monte
    Carlo error, and it is wider than the interval that treats every (instance, seed) value
    as independent when the instances differ more than the seeds."""
    rng = np.random.default_rng(3)
    M = rng.normal(0.0, 0.05, (6, 5)) + rng.normal(0.0, 1.0, (6, 1))  # instance effects dominate
    M[2, 1] = np.nan  # a missing run
    med, lo, hi = stats.median_ci_clustered(M, n_resamples=4000, seed=1)
    finite = M[np.isfinite(M)]
    assert med == np.median(finite)
    draws = rng.integers(0, 6, (20000, 6))
    meds = np.array([np.nanmedian(M[d]) for d in draws])
    ref_lo, ref_hi = np.percentile(meds, [2.5, 97.5])
    span = ref_hi - ref_lo
    assert abs(lo - ref_lo) < 0.1 * span and abs(hi - ref_hi) < 0.1 * span, (lo, hi, ref_lo, ref_hi)
    _, naive_lo, naive_hi = stats.median_ci(finite, seed=1)
    assert hi - lo > 1.5 * (naive_hi - naive_lo)
    assert stats.median_ci_clustered(M[:1], seed=1) == stats.median_ci(M[0], seed=1)  # one instance: its seeds
    assert np.isnan(stats.median_ci_clustered(np.full((2, 3), np.nan))[0])


def test_friedman_is_scipys_with_settings_as_treatments():
    S = np.random.default_rng(2).normal(size=(4, 9))
    assert stats.friedman(S) == pytest.approx(tuple(sps.friedmanchisquare(*S)))
    assert stats.friedman(S[:2])[1] == 1.0  # fewer than 3 settings: no test
    assert stats.friedman(np.ones((3, 5)))[1] == 1.0  # every seed ties everything


def test_compare_to_best_flags_the_worse_and_ties_the_equal():
    rng = np.random.default_rng(3)
    S = rng.normal(0.9, 0.01, (4, 12))  # the same distribution ...
    S[2] -= 0.1  # ... but one clearly worse
    c = stats.compare_to_best(S)
    best = int(np.argmax(np.median(S, axis=1)))
    assert c.best == best
    assert list(c.tied) == [i != 2 for i in range(4)]
    p = sps.wilcoxon(S[best], S[2]).pvalue
    assert c.p[2] == pytest.approx(p) and c.p_holm[2] == pytest.approx(min(1.0, 3 * p))
    assert c.a12[2] == 1.0 and np.isnan(c.p[best])


def test_conover_matches_a_hand_worked_case():
    # 3 settings, 4 seeds; ranks (1 = best) per seed: A 1,1,1,2; B 2,2,3,1; C 3,3,2,3
    S = np.array([[9, 9, 9, 8], [8, 8, 7, 9], [7, 7, 8, 7]], float)
    R = np.array([5.0, 8.0, 11.0])
    A = 1 + 1 + 1 + 4 + 4 + 4 + 9 + 1 + 9 + 9 + 4 + 9  # Σ r² = 56
    B = float(np.sum(R * R)) / 4  # 52.5
    margin = sps.t.ppf(0.975, 6) * np.sqrt(2 * 4 * (A - B) / 6)  # 2.447 · 2.160 = 5.29
    assert list(stats.conover(S, 0.05)) == list((R - R.min()) > margin) == [False, False, True]


def test_a_race_drops_the_clearly_worse_and_keeps_the_equal():
    """Synthetic race: setting 0 clearly worse, 1 and 2 equal (the same scores), 3 a little
    noisier but as good; nothing is decided before ``min_seeds``."""
    rng = np.random.default_rng(4)
    seeds = 12
    good = rng.normal(0.9, 0.01, seeds)
    scores = np.stack([good - 0.2 + rng.normal(0, 0.01, seeds), good, good, good + rng.normal(0, 0.001, seeds)])
    alive = np.ones(4, bool)
    early = eliminate(np.where(np.arange(seeds) < 3, scores, np.nan), alive, 0.05, min_seeds=5)
    assert early.all()
    for done in range(5, seeds + 1):
        alive = eliminate(np.where(np.arange(seeds) < done, scores, np.nan), alive, 0.05, min_seeds=5)
    assert list(alive) == [False, True, True, True]
    # two survivors are decided by the Wilcoxon signed-rank test
    two = eliminate(scores[[0, 1]], np.ones(2, bool), 0.05, min_seeds=5)
    assert list(two) == [False, True]
