"""The batched SQP core (dockjax.sqp) against SciPy's SLSQP: its quadratic programmes on random
feasible QPs, and whole programmes (a vmapped batch) with nonlinear constraints."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize

from dockjax import sqp


def _slsqp_qp(H, g, A, b, lo, hi):
    res = minimize(lambda x: 0.5 * x @ H @ x + g @ x, np.zeros(len(g)), jac=lambda x: H @ x + g, method="SLSQP",
                   bounds=list(zip(lo, hi)), constraints=[{"type": "ineq", "fun": lambda x: b - A @ x,
                                                           "jac": lambda x: -A}],
                   options={"ftol": 1e-12, "maxiter": 1000})
    assert res.success, res.message
    return res.fun


def test_qp_matches_slsqp_on_random_feasible_programmes():
    rng = np.random.default_rng(1)
    n, r = 8, 14  # one shape: one compiled solver
    with jax.enable_x64(True):
        qp = jax.jit(sqp.solve_qp, static_argnums=6)
        for _ in range(25):
            M = rng.normal(size=(n, n))
            H = M @ M.T + 0.05 * np.eye(n)
            g = rng.normal(size=n) * 3
            lo, hi = -rng.uniform(0.1, 2, n), rng.uniform(0.1, 2, n)
            A = rng.normal(size=(r, n))
            inside = rng.uniform(lo, hi) * 0.5  # a point strictly inside the box meets every row
            b = A @ inside + rng.uniform(0.0, 1.0, r)
            d, z = qp(*(jnp.asarray(a) for a in (H, g, A, b, lo, hi)), 40)
            d, z = np.asarray(d), np.asarray(z)
            want = _slsqp_qp(H, g, A, b, lo, hi)
            got = 0.5 * d @ H @ d + g @ d
            assert got == pytest.approx(want, rel=1e-8, abs=1e-9)
            assert np.max(A @ d - b) <= 1e-8
            assert np.all(z >= 0)


def _programme(p, q, r):
    """min Σ (u − p)² subject to |u − q_i|² <= r_i² (a non-empty intersection of balls)."""
    def f(u):
        return jnp.sum((u - p) ** 2)

    def c(u):
        return jnp.sum((u[None] - q) ** 2, -1) - r ** 2

    def values(u):
        fv, fg = jax.value_and_grad(f)(u)
        return fv, fg, c(u), jax.jacfwd(c)(u)

    return f, c, values, lambda u: (f(u), c(u))


def test_sqp_batch_matches_slsqp_on_nonlinear_programmes():
    rng = np.random.default_rng(2)
    n, m, B = 5, 6, 4
    centre = rng.uniform(0.3, 0.7, (B, n))
    P = rng.uniform(-0.5, 1.5, (B, n))
    Q = centre[:, None] + rng.normal(scale=0.2, size=(B, m, n))
    R = np.linalg.norm(Q - centre[:, None], axis=-1) + rng.uniform(0.05, 0.3, (B, m))  # each ball holds the centre
    a = np.zeros(n)
    a[0] = 1.0
    b = 0.9
    top = np.ones(n)
    params = sqp.Params(max_iter=100, qp_iter=30, rows=4)
    with jax.enable_x64(True):
        def one(p, q, r, u0):
            _, _, values, primal = _programme(p, q, r)
            return sqp.run(u0, values, primal, jnp.asarray(a), b, jnp.asarray(top), m, params)

        out = jax.jit(jax.vmap(one))(jnp.asarray(P), jnp.asarray(Q), jnp.asarray(R), jnp.asarray(centre))
        for k in range(B):
            f, c, _, _ = _programme(jnp.asarray(P[k]), jnp.asarray(Q[k]), jnp.asarray(R[k]))
            res = minimize(lambda u: float(f(u)), centre[k], jac=lambda u: np.asarray(jax.grad(f)(u)),
                           method="SLSQP", bounds=[(0, 1)] * n,
                           constraints=[{"type": "ineq", "fun": lambda u: -np.asarray(c(u))},
                                        {"type": "ineq", "fun": lambda u: b - a @ u}],
                           options={"ftol": 1e-14, "maxiter": 500})
            assert res.success, res.message
            u = np.asarray(out.u[k])
            assert float(f(u)) == pytest.approx(res.fun, rel=1e-6, abs=1e-9)
            assert np.max(np.asarray(c(u))) <= 1e-8 and a @ u <= b + 1e-9
            assert np.all((u >= 0) & (u <= 1))
            assert int(out.k[k]) < params.max_iter  # converged, not stopped by the count
