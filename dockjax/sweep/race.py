"""Racing (``dockjax sweep --race``): spend seeds only on settings that may still be the best.

After every round (from ``min_seeds`` seeds on) the surviving settings are compared on the
seeds they all share, as irace does (López-Ibáñez et al. 2016, "The irace package"):
Friedman's test across them; if it rejects at ``alpha``, Conover's post-hoc comparison of
the rank sums against the best drops every setting significantly worse
(:func:`dockjax.stats.conover`); with two survivors, the Wilcoxon signed-rank test decides.
The race stops when the seed budget is spent or one setting is left. Everything here is a
pure function of the scores, so a resumed race takes the same decisions.
"""

from __future__ import annotations

import numpy as np
from scipy import stats as sps

from .. import stats

__all__ = ["eliminate"]


def eliminate(scores: np.ndarray, alive: np.ndarray, alpha: float, min_seeds: int) -> np.ndarray:
    """The survivors after a round. ``scores`` (settings, seeds) of the score to maximise
    (hypervolume), NaN where a run did not happen; ``alive`` (settings,) bool. The
    survivors are compared on the seeds where all of them have a score. → (settings,) bool."""
    alive = np.asarray(alive, bool).copy()
    idx = np.flatnonzero(alive)
    if idx.size < 2:
        return alive
    S = scores[idx]
    common = np.all(np.isfinite(S), axis=0)
    S = S[:, common]
    if S.shape[1] < min_seeds:
        return alive
    if idx.size == 2:
        d = S[0] - S[1]
        if np.all(d == 0):
            return alive
        p = sps.wilcoxon(S[0], S[1], alternative="two-sided").pvalue
        if p < alpha:
            alive[idx[int(np.median(S[0]) > np.median(S[1]))]] = False  # the one with the lower median
        return alive
    _, p = stats.friedman(S)
    if p < alpha:
        worse = stats.conover(S, alpha)
        alive[idx[worse]] = False
    return alive
