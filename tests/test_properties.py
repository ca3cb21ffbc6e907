"""Invariances of the objectives (conventions §2, §5) checked with hypothesis.

Problems are built from a few fixed configurations (cached), so that hypothesis varies the
candidates and not the compiled kernel.
"""

from __future__ import annotations

import functools

import numpy as np
from hypothesis import example, given
from hypothesis import strategies as st

from dockjax import DockingProblem
from tests import reference as R

WIDE = (0.1, 100.0)
CONFIGS = (
    # (start, goal, D2)
    ((775.0, -35.0, -1315.0, 0.2, -0.2, 190.0), (745.0, -5.0, -1515.0, 0.0, 0.0, 180.0), 2000.0),
    ((700.0, 20.0, -1300.0, -1.0, 1.5, 175.0), (760.0, -10.0, -1450.0, 1.2, -1.0, 183.0), 2800.0),
)
SAME_POSES = (
    ((775.0, -35.0, -1315.0, 0.2, -0.2, 190.0), 2000.0),
    ((700.0, 20.0, -1300.0, -1.0, 1.5, 175.0), 2800.0),
)
TRAVEL = (600.0, 150.0, 150.0, 15.0)


@functools.lru_cache(maxsize=None)
def _problem(start, goal, d2):
    return DockingProblem(
        start=start, goal=goal, arm_distance=d2, interval_bounds=WIDE, travel=TRAVEL
    )


def _evaluate(p, X):
    """Evaluate rows of X, padded to 2 rows so every test shares one compiled batch size."""
    X = np.asarray(X, dtype=np.float64)
    n = len(X)
    F, G = p.evaluate(np.vstack([X, X[: 2 - n]]) if n < 2 else X)
    return np.asarray(F)[:n], np.asarray(G)[:n]


unit = st.floats(0.0, 1.0, allow_nan=False)
unit_vectors = st.lists(unit, min_size=30, max_size=30)
intervals = st.lists(st.floats(0.5, 10.0, allow_nan=False), min_size=6, max_size=6)


def _candidate(p, h, fractions):
    """x with intervals h and interior points at the given fractions of the box."""
    lo, hi = p.lower[6:], p.upper[6:]
    return np.concatenate([np.asarray(h), lo + np.asarray(fractions) * (hi - lo)])


@given(
    cfg=st.sampled_from(CONFIGS),
    h=intervals,
    fractions=unit_vectors,
    s=st.floats(0.2, 8.0, allow_nan=False),
)
# found by hypothesis: with a fixed 8-node quadrature the jerk missed 1e-9 by 2 % here (a
# 0.5 s span sweeping the box's 2.6° of pitch); the box now gets 12 nodes (JERK_NODES)
@example(cfg=CONFIGS[1], h=[2.0, 1.0, 0.5, 9.0, 1.0, 2.0], fractions=[0.0, 0.0, 0.75, 1.0] + [0.0] * 26, s=1.0)
def test_scaling_time_scales_T_and_jerk(cfg, h, fractions, s):
    p = _problem(*cfg)
    x = _candidate(p, h, fractions)
    xs = x.copy()
    xs[:6] *= s
    F, _ = _evaluate(p, [x, xs])
    np.testing.assert_allclose(F[1, 0], s * F[0, 0], rtol=1e-9)
    np.testing.assert_allclose(F[1, 1], F[0, 1] / s**3, rtol=1e-9)
    # and the unscaled one against the reference
    T, jerk = R.reference_objectives(x, cfg[0], cfg[1], cfg[2])
    np.testing.assert_allclose(F[0], [T, jerk], rtol=1e-9)


@given(pose=st.sampled_from(SAME_POSES), h=intervals)
def test_standing_still_has_zero_jerk(pose, h):
    start, d2 = pose
    p = _problem(start, start, d2)  # start == goal: the zero-move margins keep the box open
    assert np.all(p.upper > p.lower)
    x = np.concatenate([np.asarray(h), np.tile(start, 5)])
    F, G = _evaluate(p, [x])
    np.testing.assert_allclose(F[0, 0], np.sum(h), rtol=1e-12)
    assert abs(F[0, 1]) <= 1e-9
    # nothing moves: every |quantity| is 0, so every column is exactly -1 (up to round-off)
    np.testing.assert_allclose(G[0], -1.0, atol=1e-9)


@given(cfg=st.sampled_from(CONFIGS), h=intervals, fractions=unit_vectors)
def test_reversing_keeps_both_objectives(cfg, h, fractions):
    start, goal, d2 = cfg
    p = _problem(start, goal, d2)
    q = _problem(goal, start, d2)
    x = _candidate(p, h, fractions)
    interior = x[6:].reshape(5, 6)
    xr = np.concatenate([np.asarray(h)[::-1], interior[::-1].ravel()])
    F, G = _evaluate(p, [x])
    Fr, Gr = _evaluate(q, [xr])
    np.testing.assert_allclose(Fr, F, rtol=1e-9)
    # the reversed motion visits the same states backwards: same maxima about the same home
    # (each column may overstate by up to 0.01, conventions §6, so only that much may differ)
    np.testing.assert_allclose(Gr, G, rtol=0, atol=0.01 + 1e-9)
