"""Sequential quadratic programming as a JAX array program: one smooth programme per call,
``vmap`` for a batch of programmes, such as the shortest-time programmes of many moves
(``benchmarks/bench_sqp.py``).

The programme, in unit-box coordinates ``u`` (n,)::

    minimise f(u)  subject to  c(u) <= 0 (m,),  a·u <= b,  0 <= u <= top

Each iteration (:func:`step`) takes the objective, its gradient, the constraints and their
Jacobian at ``u`` (``values``); keeps the ``rows`` constraints nearest their limits
(``lax.top_k``: the others are far from active, and the line search still sees every one);
solves the quadratic programme of the step with the quasi-Newton Hessian of the
Lagrangian (:func:`solve_qp`, a primal–dual interior-point method with Mehrotra's
predictor–corrector, a fixed number of iterations); and moves along the step as far as the
ℓ1 merit function ``f + ν (Σ max(0, c) + max(0, a·u − b))`` falls enough (Armijo, over a
fixed ladder of step lengths evaluated at once). The Hessian is Powell's damped BFGS update
of the Lagrangian's (Nocedal & Wright, *Numerical Optimization*, 2nd ed., Procedure 18.2);
the merit penalty ``ν`` follows the largest multiplier (ibid. §18.3). Shapes are static and
the loop is a ``lax.while_loop`` that stops when the step and the violation are below
:attr:`Params.tol` or after :attr:`Params.max_iter` iterations.
"""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp

from .pytrees import pytree_dataclass, static

__all__ = ["Params", "State", "solve_qp", "init", "step", "run", "positive_definite"]


@pytree_dataclass
class Params:
    """Hyper-parameters of :func:`run` (static: they fix shapes and loop counts)."""

    max_iter: int = static(80)
    """Most SQP iterations."""
    qp_iter: int = static(24)
    """Interior-point iterations of each quadratic programme."""
    rows: int = static(128)
    """Constraints of c kept in each quadratic programme (those nearest their limits; all when c has
    fewer)."""
    tol: float = static(1e-10)
    """Converged when the step's largest coordinate and the largest violation are below it."""


@pytree_dataclass
class State:
    """One programme's iterate: ``u`` (n,), the Hessian estimate ``B`` (n, n), the
    multipliers ``lam`` (m,) of c and ``lam_cap`` of the linear row, the gradient of the
    Lagrangian at the previous iterate with the current multipliers ``g_lag`` (n,), the
    previous step ``s`` (n,), the merit penalty ``nu``, the iteration count ``k``,
    ``fresh`` (B was just reset to ``B0``), ``done``, and ``B0`` (n, n), the estimate a reset
    returns to (the identity, or a positive definite form of the objective's Hessian)."""

    u: jax.Array
    B: jax.Array
    lam: jax.Array
    lam_cap: jax.Array
    g_lag: jax.Array
    s: jax.Array
    nu: jax.Array
    k: jax.Array
    fresh: jax.Array
    done: jax.Array
    B0: jax.Array


def solve_qp(H, g, A, b, lo, hi, iters: int):
    """``min ½ dᵀHd + gᵀd`` subject to ``A d <= b`` and ``lo <= d <= hi``: H (n, n)
    symmetric positive definite, A (r, n), b (r,), lo, hi (n,) with lo <= 0 <= hi.

    A primal–dual interior-point method with Mehrotra's predictor–corrector (Nocedal &
    Wright, Algorithm 16.4), ``iters`` iterations from ``d = 0`` with unit slacks and
    multipliers (an infeasible start). Each iteration factors ``H + Aᵀ (z/s) A + diag`` of
    the bounds once (Cholesky) for both directions. → ``(d (n,), z (r,))``: the step and the
    rows' multipliers (>= 0)."""
    r, n = A.shape
    h = jnp.concatenate([b, hi, -lo])
    eye = jnp.eye(n, dtype=H.dtype)

    def C(d):
        return jnp.concatenate([A @ d, d, -d])

    def CT(z):
        return A.T @ z[:r] + z[r:r + n] - z[r + n:]

    def direction(L, rc, rd, rp, s, z):
        w = (z * rp - rc) / s
        dd = jax.scipy.linalg.cho_solve((L, True), -rd - CT(w))
        dz = w + z * C(dd) / s
        ds = -rp - C(dd)
        return dd, ds, dz

    def longest(v, dv):
        """Largest step in (0, 1] keeping v + a dv >= 0."""
        return jnp.minimum(1.0, jnp.min(jnp.where(dv < 0, -v / jnp.where(dv < 0, dv, -1.0), jnp.inf)))

    def body(_, carry):
        d, s, z = carry
        rd = H @ d + g + CT(z)
        rp = C(d) + s - h
        mu = jnp.dot(s, z) / s.shape[0]
        D = z / s
        M = H + (A.T * D[:r]) @ A + jnp.diag(D[r:r + n] + D[r + n:])
        L = jnp.linalg.cholesky(M + 1e-14 * jnp.trace(M) / n * eye)
        _, ds_a, dz_a = direction(L, s * z, rd, rp, s, z)
        a_aff = jnp.minimum(longest(s, ds_a), longest(z, dz_a))
        mu_aff = jnp.dot(s + a_aff * ds_a, z + a_aff * dz_a) / s.shape[0]
        sigma = (mu_aff / jnp.maximum(mu, 1e-300)) ** 3
        dd, ds, dz = direction(L, s * z + ds_a * dz_a - sigma * mu, rd, rp, s, z)
        a = 0.99 * jnp.minimum(longest(s, ds), longest(z, dz))
        a = jnp.where(jnp.isfinite(a), a, 0.0)
        return d + a * dd, jnp.maximum(s + a * ds, 1e-300), jnp.maximum(z + a * dz, 1e-300)

    ones = jnp.ones(r + 2 * n, H.dtype)
    d, _, z = jax.lax.fori_loop(0, iters, body, (jnp.zeros(n, H.dtype), ones, ones))
    return jnp.clip(d, lo, hi), z[:r]


STEPS = (1.0, 0.5, 0.25, 0.1, 0.03, 0.01, 0.001)
"""The step lengths the line search tries (all at once); the longest that satisfies Armijo's
condition is taken, else the one of the lowest merit."""
ARMIJO = 1e-4
"""Armijo's sufficient-decrease fraction of the merit's directional derivative."""


def init(u0, lam_shape: int, B0=None) -> State:
    """The state at ``u0`` (n,): ``B0`` (n, n; default the identity) as Hessian estimate, zero
    multipliers."""
    n = u0.shape[0]
    z = jnp.zeros((), u0.dtype)
    B0 = jnp.eye(n, dtype=u0.dtype) if B0 is None else B0
    return State(u=u0, B=B0, lam=jnp.zeros(lam_shape, u0.dtype), lam_cap=z,
                 g_lag=jnp.zeros(n, u0.dtype), s=jnp.zeros(n, u0.dtype), nu=jnp.ones((), u0.dtype),
                 k=jnp.zeros((), jnp.int32), fresh=jnp.ones((), bool), done=jnp.zeros((), bool), B0=B0)


def positive_definite(H, floor: float = 1e-6):
    """H (n, n) symmetric with its eigenvalues raised to at least ``floor`` × the largest |eigenvalue|
    (and 1e-8): a positive definite Hessian estimate from an indefinite or singular one (the
    identity where H is zero, e.g. a linear objective)."""
    w, V = jnp.linalg.eigh(0.5 * (H + H.T))
    top = jnp.max(jnp.abs(w))
    w = jnp.where(top > 0, jnp.maximum(w, jnp.maximum(floor * top, 1e-8)), 1.0)
    return (V * w) @ V.T


def _bfgs(B, s, y):
    """Powell's damped BFGS update of B with step s and gradient change y (kept when the
    step is negligible)."""
    Bs = B @ s
    sBs = jnp.dot(s, Bs)
    sy = jnp.dot(s, y)
    theta = jnp.where(sy >= 0.2 * sBs, 1.0, 0.8 * sBs / jnp.maximum(sBs - sy, 1e-300))
    r = theta * y + (1.0 - theta) * Bs
    sr = jnp.dot(s, r)
    new = B - jnp.outer(Bs, Bs) / jnp.maximum(sBs, 1e-300) + jnp.outer(r, r) / jnp.maximum(sr, 1e-300)
    ok = (sBs > 1e-20) & (sr > 1e-20) & jnp.all(jnp.isfinite(new))
    return jnp.where(ok, 0.5 * (new + new.T), B)


def step(state: State, values: Callable, primal: Callable, a, b, top, params: Params) -> State:
    """One SQP iteration (module docstring). ``values(u) -> (f, ∇f (n,), c (m,), ∂c/∂u (m, n))``,
    ``primal(u) -> (f, c)``; ``a`` (n,), ``b``: the linear row ``a·u <= b``; ``top`` (n,): the
    box's upper corner (the lower is 0)."""
    u = state.u
    f, gf, c, J = values(u)
    y = gf + J.T @ state.lam - state.g_lag
    B = jnp.where(state.k > 0, _bfgs(state.B, state.s, y), state.B)
    idx = jax.lax.top_k(c, min(params.rows, c.shape[0]))[1]
    A = jnp.concatenate([J[idx], a[None]])
    rhs = jnp.concatenate([-c[idx], (b - a @ u)[None]])
    d, z = solve_qp(B, gf, A, rhs, -u, top - u, params.qp_iter)
    lam = jnp.zeros_like(c).at[idx].set(z[:-1])
    nu = jnp.maximum(state.nu, 1.5 * jnp.max(z) + 1e-6)

    def merit(fv, cv, uv):
        return fv + nu * (jnp.sum(jnp.maximum(cv, 0.0)) + jnp.maximum(a @ uv - b, 0.0))

    phi0 = merit(f, c, u)
    slope = jnp.dot(gf, d) - nu * (jnp.sum(jnp.maximum(c, 0.0)) + jnp.maximum(a @ u - b, 0.0))
    steps = jnp.asarray(STEPS, u.dtype)
    trial = jnp.clip(u[None] + steps[:, None] * d[None], 0.0, top)
    phis = jax.vmap(lambda ut: merit(*primal(ut), ut))(trial)
    phis = jnp.where(jnp.isfinite(phis), phis, jnp.inf)
    ok = phis <= phi0 + ARMIJO * steps * jnp.minimum(slope, 0.0)
    j = jnp.where(jnp.any(ok), jnp.argmax(ok), jnp.argmin(phis))
    better = jnp.any(ok) | (phis[j] < phi0)
    u_new = jnp.where(better, trial[j], u)
    s = u_new - u
    violation = jnp.maximum(jnp.max(c), a @ u - b)
    done = (jnp.max(jnp.abs(d)) <= params.tol) & (violation <= params.tol)
    # no step lowers the merit: the Hessian estimate starts afresh, and a fresh one that
    # fails too marks a stationary point of the merit
    done = done | (~better & state.fresh)
    B = jnp.where(better, B, state.B0)
    return State(u=u_new, B=B, lam=lam, lam_cap=z[-1], g_lag=gf + J.T @ lam, s=s, nu=nu, k=state.k + 1,
                 fresh=~better, done=done, B0=state.B0)


def run(u0, values: Callable, primal: Callable, a, b, top, m: int, params: Params = Params(),
        hessian: Callable | None = None) -> State:
    """SQP from ``u0`` (n,) until converged or :attr:`Params.max_iter` (see :func:`step`;
    ``m``: the number of constraints c). ``hessian(u) -> (n, n)``: the objective's Hessian,
    whose :func:`positive_definite` form at u0 starts (and restarts) the quasi-Newton
    estimate instead of the identity (a quadratic objective's curvature is then known from
    the first step). → the final :class:`State`."""
    state = init(u0, m, None if hessian is None else positive_definite(hessian(u0)))
    return jax.lax.while_loop(lambda st: (st.k < params.max_iter) & ~st.done,
                              lambda st: step(st, values, primal, a, b, top, params), state)
