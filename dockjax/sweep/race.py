"""Racing (``dockjax sweep --race``): spend seeds only on settings that may still be the best.

After every round (from ``min_seeds`` seeds on) the surviving settings are compared on the
seeds they all share, as irace does (López-Ibáñez et al. 2016, "The irace package"):
Friedman's test across them; if it rejects at ``alpha``, Conover's post-hoc comparison of
the rank sums against the best drops every setting significantly worse
(:func:`dockjax.stats.conover`); with two survivors, the Wilcoxon signed-rank test decides.
The race stops when the seed budget is spent or one setting is left. Over instances a block
is an (instance, seed) pair and each round brings new instances (irace's iterated race),
then further seeds of them. Everything here is a
pure function of the scores, and the decision after a round (:func:`decide`) sees only the
seeds run by then, so a resumed race, a re-run of a finished one and the report
(:func:`replay`) take the same decisions, whatever else the folder holds.
"""

from __future__ import annotations

import numpy as np
from scipy import stats as sps

from .. import stats
from .config import round_seeds

__all__ = ["eliminate", "decide", "replay"]


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


def decide(cfg, scores: np.ndarray, alive: np.ndarray, seeds_done: int) -> np.ndarray:
    """The survivors after a round of the race of ``cfg`` that ended with ``seeds_done``
    blocks run (seeds; over instances, (instance, seed) pairs in the race's order,
    :func:`dockjax.sweep.config.blocks_of`): :func:`eliminate` on the scores (settings,
    blocks) of blocks ``0 .. seeds_done − 1`` only (a later round's scores, where present,
    are not looked at)."""
    seen = np.where(np.arange(scores.shape[1])[None, :] < seeds_done, scores, np.nan)
    return eliminate(seen, alive, cfg.race["alpha"], cfg.race["min_seeds"])


def replay(cfg, scores: np.ndarray) -> list[tuple[range, np.ndarray]]:
    """Every round of the race of ``cfg`` from the scores (settings, seeds) of its finished
    runs: ``(the round's seeds, the survivors after it)``, the decisions of :func:`decide`."""
    alive = np.ones(len(cfg.settings), bool)
    rounds, done, r = [], 0, 0
    while True:
        seeds = round_seeds(cfg, r, done, int(alive.sum()))
        if len(seeds) == 0:
            break
        done = seeds.stop
        alive = decide(cfg, scores, alive, done)
        rounds.append((seeds, alive.copy()))
        r += 1
        if alive.sum() <= 1 or done >= cfg.n_blocks:
            break
    return rounds
