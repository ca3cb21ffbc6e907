"""The Cox–de Boor basis of dockjax.bspline against SciPy's B-spline design matrix, and its
derivative rule (the value computes a stage's divisions together, derivatives go through
the plain recursion)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from scipy.interpolate import BSpline

from dockjax import bspline

P = bspline.DEGREE
SPANS = P + np.arange(bspline.N_SPANS)  # the left knot of every span


def _knots(seed):
    h = np.random.default_rng(seed).uniform(0.5, 10.0, 6)
    return bspline.knots(jnp.asarray(h))


def test_basis_at_the_span_knots_equals_scipy(x64):
    for seed in range(3):
        u = _knots(seed)
        out = bspline.basis_functions(u, SPANS, u[SPANS], P)
        un = np.asarray(u)
        for q in range(P + 1):
            # SciPy's degree-q basis on the same knots, at each span's left knot
            dm = BSpline.design_matrix(un[SPANS], un, q).toarray()
            for i in range(q + 1):
                ours = np.asarray(out[q][i])
                np.testing.assert_allclose(ours, dm[np.arange(len(SPANS)), SPANS - q + i], rtol=1e-12, atol=1e-14)


def test_basis_derivatives_are_the_plain_recursions_bit_for_bit(x64):
    """The stacked divisions give the same values; the custom JVP differentiates the plain
    recursion, so the gradient (and a JVP) equals the plain recursion's exactly, and
    agrees with central differences."""
    u = _knots(7)
    w = [jnp.asarray(np.random.default_rng(q).normal(size=(q + 1, len(SPANS)))) for q in range(P + 1)]

    def loss(fn):
        return lambda u: sum(jnp.sum(wq * jnp.stack(bq)) for wq, bq in zip(w, fn(u)))

    fast = lambda u: bspline.basis_functions(u, SPANS, u[SPANS], P)  # noqa: E731
    plain = lambda u: bspline._basis_recursion(u, SPANS, u[SPANS], P, stacked=False)  # noqa: E731
    for a, b in zip(jax.tree_util.tree_leaves(fast(u)), jax.tree_util.tree_leaves(plain(u))):
        np.testing.assert_array_equal(a, b)
    g_fast, g_plain = jax.jit(jax.grad(loss(fast)))(u), jax.jit(jax.grad(loss(plain)))(u)
    np.testing.assert_array_equal(g_fast, g_plain)
    t = jnp.asarray(np.random.default_rng(1).normal(size=u.shape))
    _, d_fast = jax.jvp(loss(fast), (u,), (t,))
    _, d_plain = jax.jvp(loss(plain), (u,), (t,))
    assert float(d_fast) == float(d_plain)
    # finite differences along t: the knots' order is kept for a small step
    eps = 1e-6
    fd = (loss(fast)(u + eps * t) - loss(fast)(u - eps * t)) / (2 * eps)
    np.testing.assert_allclose(float(d_fast), float(fd), rtol=1e-6)
