"""The screened limit columns (``DockingProblem.evaluate``'s default) against the full root
chain and against plain NumPy.

The screen replaces the exact search on most knot spans by cheap two-sided bounds; these
tests pin down what it promises: never below the exact maximum, at most 0.009 of the limit
above it, exact wherever a column is near its limit, the same feasibility, and bounds that
really bracket the maxima of arbitrary quintics (checked with NumPy's polynomial roots).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from dockjax import DockingProblem, extrema, limits
from dockjax import problem as P


def _numpy_maxima(c, h):
    """max |Q|, |Q'|, |Q''| of Σ c_m τ^m on [0, h] by dense sampling (20,001 points) and a
    bounded Brent polish around the best sample (scipy): no root finding, so no trouble
    with tiny leading coefficients."""
    from scipy.optimize import minimize_scalar

    poly = np.polynomial.Polynomial(c)
    t = np.linspace(0.0, h, 20001)
    out = []
    for k in range(3):
        q = poly.deriv(k) if k else poly
        v = np.abs(q(t))
        i = int(np.argmax(v))
        lo, hi = t[max(i - 1, 0)], t[min(i + 1, len(t) - 1)]
        best = v[i]
        if hi > lo:
            r = minimize_scalar(lambda x: -abs(q(x)), bounds=(lo, hi), method="bounded",
                                options={"xatol": 1e-14 * max(h, 1.0)})
            best = max(best, abs(q(r.x)))
        out.append(best)
    return np.array(out)


coef = st.floats(-10.0, 10.0, allow_nan=False)


@jax.jit
def _all_bounds(c, h):
    """L, U, the full root chain and the rate chain of one quintic: one compiled program
    (each hypothesis example would otherwise dispatch hundreds of eager ops)."""
    low, up = extrema.span_bounds(c, h)
    return low, up, extrema.span_maxima(c, h)[0], extrema.rate_maxima(c, h)


@given(c=st.lists(coef, min_size=6, max_size=6), h=st.floats(0.2, 12.0), scale=st.sampled_from([1.0, 1e-2, 1e-4]))
@example(c=[0.0, 0.0, 1.0, 0.0, -1.0, 1.6885950388683538e-64], h=1.0, scale=1.0)  # found by hypothesis
@example(c=[1.0, 0.0, 0.0, 0.0, 0.0, 1.0], h=7.0, scale=0.01)
@example(c=[0.0, 1.0, 1e-12, 0.0, 0.0, -1.0], h=0.5, scale=1.0)
def test_span_bounds_bracket_numpy_maxima(c, h, scale):
    # powers scaled so that every derivative matters on [0, h]
    c = np.asarray(c) * scale ** np.arange(6) / np.maximum(h, 1.0) ** np.arange(6)
    with jax.enable_x64(True):
        low, up, exact, rate = (np.asarray(a) for a in _all_bounds(jnp.asarray(c), jnp.asarray(h)))
    ref = _numpy_maxima(c, h)
    tol = 1e-9 * ref + 1e-14
    assert np.all(low <= ref + tol), (low, ref)
    assert np.all(up >= ref - tol), (up, ref)
    # the root chain is never below, and above only by its certified margins (small; e.g.
    # 6e-4 relative where an acceleration root sits within 1e-4 of a span end)
    assert np.all(exact >= ref - tol) and np.all(exact <= ref * (1 + 2e-3) + tol), (exact, ref)
    np.testing.assert_array_equal(rate, exact[1:])


@pytest.mark.parametrize("t0, k, h", [(3.3, 0.002, 5.0), (0.37, 1.0, 1.0), (2.5, 0.005, 5.0)])
def test_a_velocity_plateau_is_bounded_tightly(t0, k, h):
    """Q' = 1 − k (t − t0)⁴: the acceleration has a triple root at t0, too flat for the root's
    sign check, so the root search ends with a wide bracket. The velocity's maximum (1, at
    t0) is never understated and, bounded by the acceleration over that bracket, overstated
    by less than 1e-4 (the second-order bound alone gave 1 % on the first case)."""
    q = np.polynomial.Polynomial([0.0, 1.0]) - k * np.polynomial.Polynomial([-t0, 1.0]) ** 5 / 5
    c = np.zeros(6)
    c[: len(q.coef)] = q.coef
    with jax.enable_x64(True):
        _, _, exact, rate = (np.asarray(a) for a in _all_bounds(jnp.asarray(c), jnp.asarray(h)))
    ref = _numpy_maxima(c, h)
    assert ref[1] == pytest.approx(1.0, abs=1e-12)  # at t0
    assert ref[1] - 1e-12 <= exact[1] <= ref[1] * (1 + 1e-4), (exact[1], ref[1])
    np.testing.assert_array_equal(rate, exact[1:])


def test_span_bounds_tighten_with_the_grid():
    """U − L of the velocity shrinks like δ² (the gap term), so the sampled bounds are
    useful: at 16 sub-intervals the gap of a smooth quintic is a small fraction of it."""
    c = np.array([0.0, 0.3, 0.02, -0.004, 2e-4, -3e-6])
    h = 8.0
    with jax.enable_x64(True):
        low, up = (np.asarray(a) for a in extrema.span_bounds(jnp.asarray(c), jnp.asarray(h)))
    ref = _numpy_maxima(c, h)
    assert np.all(up - low <= 0.02 * ref)


def _sets(p, rng, n):
    """Random candidates of the box, and candidates near the straight line (mostly feasible
    or close to a limit)."""
    box = rng.uniform(p.lower, p.upper, (n, p.n_var))
    line = np.concatenate([np.linspace(p.start, p.goal, 7)[1:-1].ravel()])
    near = np.tile(np.concatenate([np.full(6, 0.0), line]), (n, 1))
    near[:, :6] = rng.uniform(p.lower[:6], p.upper[:6], (n, 6))
    near[:, 6:] += rng.normal(0.0, 0.05, (n, 30)) * (p.upper[6:] - p.lower[6:])
    return np.vstack([box, np.clip(near, p.lower, p.upper)])


@pytest.mark.parametrize("preset", ["paper", "wide"])
def test_screened_columns_against_the_full_chain(preset):
    p = DockingProblem() if preset == "paper" else DockingProblem(interval_bounds=(0.5, 10.0))
    X = _sets(p, np.random.default_rng(11), 512)
    # in calls of 16 rows: the compiled kernels of the reference and plan tests
    Fs, Gs = p.evaluate(X, rows=16)
    Ff, Gf = p.evaluate(X, screen=False, rows=16)
    np.testing.assert_array_equal(Fs, Ff)
    d = Gs - Gf
    assert d.min() >= -1e-12, "a screened column is below the exact maximum"
    assert d.max() <= limits.SCREEN_SLACK + 1e-12, "a screened column overstates by more than 0.009"
    near = np.abs(Gf) <= 0.02
    assert near.sum() >= 20, near.sum()  # the sets do reach the limits
    assert np.abs(d[near]).max() <= 1e-12, "a column near its limit is not exact"
    np.testing.assert_array_equal(Gs.max(1) <= 0, Gf.max(1) <= 0)
    # the overflow path (more failing spans than slots, or a failing travel) is exercised
    with jax.enable_x64(True):
        bound = p.with_right_arm("bound")
        over = np.asarray(jax.jit(P._score_plain, static_argnums=2)(bound, jnp.asarray(X), True)[3])
    assert 0 < over.sum() < len(X) // 4
