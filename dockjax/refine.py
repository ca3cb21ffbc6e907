"""Gradient polishing of candidate trajectories (conventions §3, §5, §6).

:func:`refine` takes a set of candidates ``X`` (n, n_var) and, for every point i at once,
solves the sub-problem

    minimise jerk(x)  subject to  T(x) ≤ T_i,  G(x) ≤ 0 (the 24 limits of conventions §6),
    x in the decision box (conventions §3)

with Adam (optax) from the point itself. The whole batch is one parameter array: Adam is
per-coordinate, so summing the per-point losses gives n independent optimisations, run
by one compiled ``lax.fori_loop`` (the trip count is traced: changing ``steps`` does not
recompile), kept in the store of compiled programs (:mod:`dockjax.store`), so a new process
loads it.

* The variables live in the unit box, ``x = lower + u (upper − lower)``.
* The box and the time cap ``T ≤ T_i`` are kept by exact Euclidean projection after every
  update onto ``{0 ≤ u ≤ 1, Σ_k w_k u_k ≤ b_i}`` (the intervals' part; bisection on the
  multiplier of the one linear constraint), so every iterate satisfies both.
* The limits are handled by a smooth-plus-exact penalty on ``max(G + margin, 0)``
  (linear and quadratic terms; the ``margin`` keeps the iterates slightly inside). G has
  kinks (a maximum over time); that is harmless for a penalty method.
* The jerk objective (conventions §5) is recomputed here with a NaN-safe square root (the RMS of a
  joint that does not move has an infinite derivative at 0) and normalised by the input's
  jerk. The kernel's critical times carry no gradient (envelope theorem, see
  :func:`dockjax.extrema.chain_extrema`), so the backward pass never enters the root
  searches and stays finite at degenerate points (coincident control points, double
  roots). As a safeguard, a non-finite gradient entry would be zeroed, the row nudged by
  a small pseudo-random step, and the step counted in ``nonfinite_steps`` (0 expected).
* At every step the current iterate is scored with the problem's own kernel; the best
  iterate that is feasible (every column of the kernel's G ≤ 0, which never understates,
  conventions §6), has ``T ≤ T_i`` and has the lowest jerk is kept. For a feasible input the
  returned point must also have a strictly lower jerk than the input, so it is never
  dominated by it; for an infeasible input any feasible point with ``T ≤ T_i`` is a repair
  (it wins under Deb's constraint-domination, conventions §6) and the lowest-jerk one is kept.
  A point for which nothing qualifies is returned unchanged with ``improved`` False.

:func:`polish` is the same loop under given time caps (the best-known front's
ε-constraint sweep, :mod:`dockjax.best_known`).

Everything runs in float64 inside ``jax.enable_x64(True)``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import optax

from . import checks
from .decoding import spans
from .limits import columns, maxima, maxima_screened
from .objectives import cabin_jerk
from .problem import DockingProblem, bucket_rows, pad_rows
from .robot import join_pairs
from .store import stored_jit

__all__ = ["RefineResult", "refine", "polish", "check_settings", "objectives_safe"]


@dataclass(frozen=True)
class RefineResult:
    """Output of :func:`refine` (NumPy float64 / bool arrays, n rows as the input).

    ``X`` (n, n_var) the refined points (the input row where nothing was found),
    ``F`` (n, 2) and ``G`` (n, 24) their kernel scores, ``improved`` (n,) True where the
    row differs from the input, ``feasible`` (n,) kernel feasibility of the returned row,
    ``F_in``/``G_in`` the scores of the input, ``nonfinite_steps`` (n,) how many steps had a
    non-finite gradient entry (zeroed before the update; 0 expected), ``seconds`` wall time (compile included on
    the first call of a shape).
    """

    X: np.ndarray
    F: np.ndarray
    G: np.ndarray
    improved: np.ndarray
    feasible: np.ndarray
    F_in: np.ndarray
    G_in: np.ndarray
    nonfinite_steps: np.ndarray
    seconds: float


# -- the scores with a NaN-safe jerk -------------------------------------------------------


def objectives_safe(problem: DockingProblem, x, screen: bool = False):
    """``score`` (conventions §5–6) of one candidate with the NaN-safe jerk: x (n_var,) → F (2,),
    G (24,); differentiable everywhere the kernel is (G is piecewise smooth).

    Default: the full root chain, equal in value to :func:`dockjax.problem.score` except in
    the ``"adaptive"`` and ``"taylor"`` right-arm modes, where the bound treatment is used
    throughout (never understated, so safe to certify with, but it may overstate more;
    the Taylor models' subdivision loop has no reverse-mode derivative; :func:`refine`
    re-scores its results with the kernel). ``screen=True``: the limits by the screen of
    :func:`dockjax.limits.maxima_screened` without its overflow pass — columns near their
    limits exact with exact gradients (envelope theorem), the others rigorous upper bounds.
    Measured on the default problem it saves little in refinement (3.75 against 4.13 s for
    150 points × 200 steps; the backward pass dominates) and lands a hair lower in HV, so
    refinement keeps the full chain."""
    if problem.right_arm == "taylor":
        problem = problem.with_right_arm("bound")
    h, _, c, ref = spans(problem, x)
    rbs = problem.robots  # one per pair of supports (the robot, for two arms)
    F = jnp.stack([jnp.sum(h), cabin_jerk(rbs, c, h, ref, nodes=problem.jerk_nodes, differentiable=True)])
    M = join_pairs([maxima_screened(rb, c, h, ref)[0] if screen else maxima(rb, c, h, ref) for rb in rbs])
    return F, columns(rbs[0], M, problem.limits)


# -- projection onto the box with a time cap ----------------------------------------------


def _project(U, width_h, cap, n_bisect: int = 60):
    """Euclidean projection of each row of U (n, d) onto
    ``{0 ≤ u ≤ 1, Σ_k width_h[k] u[k] ≤ cap}`` (the first ``len(width_h)`` columns carry the
    intervals).
    cap (n,). ``u = clip(v − λ w, 0, 1)`` with λ ≥ 0 found by bisection."""
    U = jnp.clip(U, 0.0, 1.0)
    s = width_h.shape[0]
    v = U[:, :s]
    total = lambda lam: jnp.sum(width_h * jnp.clip(v - lam[:, None] * width_h, 0.0, 1.0), 1)  # noqa: E731
    over = total(jnp.zeros(v.shape[0], v.dtype)) > cap
    hi = jnp.full(v.shape[0], 1.0 / jnp.min(width_h), v.dtype)  # λ at which every u is 0
    lo = jnp.zeros_like(hi)

    def body(_, lh):
        lo, hi = lh
        mid = 0.5 * (lo + hi)
        too_big = total(mid) > cap
        return jnp.where(too_big, mid, lo), jnp.where(too_big, hi, mid)

    lo, hi = jax.lax.fori_loop(0, n_bisect, body, (lo, hi))
    vh = jnp.clip(v - hi[:, None] * width_h, 0.0, 1.0)  # the upper end keeps Σ ≤ cap
    return U.at[:, :s].set(jnp.where(over[:, None], vh, v))


# -- the polishing loop ---------------------------------------------------------------------


@stored_jit
def _polish(problem, settings, rows):
    """Projected Adam on all rows of U0 (n, d) at once; returns the best qualifying iterate
    per row (initialised with ``*_best0``; a candidate qualifies when kernel-feasible, with
    ``T ≤ cap_T`` and jerk < the incumbent). ``settings`` ``(steps, lr, lr_final, mu, rho,
    margin)`` (scalars); ``rows`` ``(U0, cap, j_scale, j_best0, x_best0, f_best0, g_best0)``,
    each with n rows. Row-wise: a row's result does not depend on the others."""
    steps, lr, lr_final, mu, rho, margin = settings
    U0, cap, j_scale, j_best0, x_best0, f_best0, g_best0 = rows
    lo = jnp.asarray(problem.lower, U0.dtype)
    width = jnp.asarray(problem.upper, U0.dtype) - lo
    width_h = width[: problem.n_intervals]
    # Σ w_k u_k ≤ cap_u, a hair inside so that rounding never lifts T above the cap
    cap_u = cap * (1.0 - 1e-12) - jnp.sum(lo[: problem.n_intervals])
    score_one = jax.vmap(objectives_safe, in_axes=(None, 0))

    def loss(U):
        X = lo + U * width
        F, G = score_one(problem, X)
        viol = jnp.maximum(G + margin, 0.0)
        per = F[:, 1] / j_scale + mu * jnp.sum(viol, 1) + rho * jnp.sum(viol * viol, 1)
        return jnp.sum(per), (X, F, G)

    grad_fn = jax.value_and_grad(loss, has_aux=True)
    opt = optax.scale_by_adam()

    def body(t, carry):
        U, state, jb, xb, fb, gb, nbad = carry
        (_, (X, F, G)), g = grad_fn(U)
        bad = ~jnp.all(jnp.isfinite(g), 1)
        nbad = nbad + bad
        ok = jnp.all(G <= 0.0, 1) & (F[:, 0] <= cap) & (F[:, 1] < jb)
        jb = jnp.where(ok, F[:, 1], jb)
        xb = jnp.where(ok[:, None], X, xb)
        fb = jnp.where(ok[:, None], F, fb)
        gb = jnp.where(ok[:, None], G, gb)
        g = jnp.nan_to_num(g, nan=0.0, posinf=0.0, neginf=0.0)
        upd, state = opt.update(g, state)
        frac = t / jnp.maximum(steps - 1, 1)
        rate = lr_final + (lr - lr_final) * 0.5 * (1.0 + jnp.cos(math.pi * frac))
        # a non-finite gradient (a degenerate point of the kernel's extrema search, e.g.
        # coincident control points) is zeroed; the row is nudged off the degeneracy
        nudge = 1e-3 * jnp.sin(12.9898 * (jnp.arange(U.size).reshape(U.shape) + 1.0) * (t + 1.0))
        U = U - rate * upd + jnp.where(bad[:, None], nudge, 0.0)
        U = _project(U, width_h, cap_u)
        return U, state, jb, xb, fb, gb, nbad

    U0 = _project(U0, width_h, cap_u)
    nbad = jnp.zeros(U0.shape[0], jnp.int32)
    carry = (U0, opt.init(U0), j_best0, x_best0, f_best0, g_best0, nbad)
    _, _, jb, xb, fb, gb, nbad = jax.lax.fori_loop(0, steps + 1, body, carry)
    return jb, xb, fb, gb, nbad


_CHUNK = 256


@stored_jit
def _score_rows(problem, X):
    """:func:`objectives_safe` of every row of X (n, n_var) → F (n, 2), G (n, n_con)."""
    return jax.vmap(objectives_safe, in_axes=(None, 0))(problem, X)


def check_settings(problem, steps, learning_rate, penalty, margin, rows=None) -> None:
    """ValueError naming the argument unless the polishing settings are usable (a
    :class:`DockingProblem`, ``steps >= 1``, positive rates, ``0 <= margin < 0.5``,
    ``rows`` None or >= 1)."""
    if not isinstance(problem, DockingProblem):
        raise ValueError(f"problem must be a DockingProblem, got {type(problem).__name__}")
    checks.integer("steps", steps, 1)
    checks.number("learning_rate", learning_rate, 0.0, open_lo=True)
    checks.number("penalty", penalty, 0.0, open_lo=True)
    checks.number("margin", margin, 0.0, 0.5, open_hi=True)
    checks.optional_integer("rows", rows, 1)


def polish(problem: DockingProblem, X, caps, *, steps: int = 200, learning_rate: float = 0.05,
           penalty: float = 10.0, margin: float = 1e-4, rows: int | None = None):
    """Every row of X (n, n_var) polished under ``T ≤ caps[i]`` (n,) by the projected Adam
    loop of the module docstring, in calls of one compiled shape (``rows`` rows, default
    the kernel's bucket of n, at most 256). A kernel-feasible input row is the incumbent,
    so only strict jerk improvements replace it.

    Returns ``(X_best, F_best, G_best, found, nonfinite_steps)``: per row the best
    qualifying iterate (feasible by the loop's own scores, :func:`objectives_safe`, never
    understated; ``T ≤ cap``; lowest jerk) or the input where none qualified (``found``
    False), and the count of steps with a non-finite gradient. Not re-scored by the
    problem's kernel: callers that certify do that (:func:`refine`)."""
    n = X.shape[0]
    size = min(_CHUNK, bucket_rows(n)) if rows is None else int(rows)
    parts = [_polish_chunk(problem, X[i:i + size], caps[i:i + size], size, steps, learning_rate, penalty, margin)
             for i in range(0, n, size)]
    jb, xb, fb, gb, nbad = (np.concatenate(a) for a in zip(*parts))
    return xb, fb, gb, np.isfinite(jb), nbad


def _polish_chunk(problem, X, cap, size, steps, learning_rate, penalty, margin):
    """:func:`polish` of X (n ≤ size, d) padded to ``size`` rows (one compiled shape)."""
    n = X.shape[0]
    X, cap = pad_rows(X, size), pad_rows(cap, size)
    with jax.enable_x64(True):
        Xj = jnp.asarray(X)
        F0, G0 = _score_rows(problem, Xj)
        F0, G0 = np.asarray(F0), np.asarray(G0)
        feas0 = np.all(G0 <= 0, 1) & (F0[:, 0] <= cap)
        j_scale = np.where(np.isfinite(F0[:, 1]) & (F0[:, 1] > 0), F0[:, 1], 1.0)
        j0 = np.where(feas0, F0[:, 1], np.inf)
        lo, hi = np.asarray(problem.lower), np.asarray(problem.upper)
        U0 = np.clip((X - lo) / (hi - lo), 0.0, 1.0)
        rate = float(learning_rate)
        mu = float(penalty)
        settings = tuple(jnp.asarray(v) for v in (int(steps), rate, 0.01 * rate, mu, 10.0 * mu, float(margin)))
        rows = (jnp.asarray(U0), jnp.asarray(cap), jnp.asarray(j_scale), jnp.asarray(j0), Xj, jnp.asarray(F0),
                jnp.asarray(G0))
        out = _polish(problem, settings, rows)
    return tuple(np.asarray(a)[:n] for a in out)


def refine(problem: DockingProblem, X, *, steps: int = 200, learning_rate: float = 0.05, penalty: float = 10.0,
           margin: float = 1e-4, rows: int | None = None) -> RefineResult:
    """Polish every row of X (n, n_var) (natural units) by projected Adam in the unit box:
    minimise jerk with ``T ≤ T_i`` and all 24 limits, see the module docstring.

    ``learning_rate`` is Adam's step in unit-box coordinates, cosine-decayed to 1 % of
    itself over ``steps``; ``penalty`` the weight μ of the linear penalty ``μ Σ max(G +
    margin, 0)`` (10 μ for its quadratic part) against the jerk normalised by the input's.
    Rows outside the box are clipped into it as the starting point (the input row is still
    returned when nothing better is found). ``rows``: rows per compiled call (default the
    kernel's bucket of n, at most 256; calls of one ``rows`` share a compiled program).
    Raises ValueError on bad input.
    """
    check_settings(problem, steps, learning_rate, penalty, margin, rows)
    X = problem.check_population(X)
    if X.shape[0] == 0:
        raise ValueError("X must have at least one row")
    t0 = time.perf_counter()
    T = X[:, : problem.n_intervals].sum(1)
    xb, fb, gb, found, nbad = polish(problem, X, T, steps=steps, learning_rate=learning_rate, penalty=penalty,
                                     margin=margin, rows=rows)
    found &= ~np.all(xb == X, 1)
    # the kernel has the last word (in the "adaptive" right-arm mode the loop used the
    # bound path, which never understates but may overstate more): a refined row is kept
    # only if the kernel finds it feasible, no longer, and — for a feasible input — of
    # strictly lower jerk
    F0, G0 = problem.evaluate(X, rows=rows)
    if found.any():
        Fk, Gk = problem.evaluate(xb[found], rows=rows)
        feas_in = np.all(G0[found] <= 0, 1)
        ok = (np.all(Gk <= 0, 1) & (Fk[:, 0] <= T[found] * (1 + 1e-12))
              & (~feas_in | (Fk[:, 1] < F0[found, 1])))
        fb[found], gb[found] = Fk, Gk
        found[np.flatnonzero(found)[~ok]] = False
    Xo = np.where(found[:, None], xb, X)
    Fo = np.where(found[:, None], fb, F0)
    Go = np.where(found[:, None], gb, G0)
    return RefineResult(
        X=Xo, F=Fo, G=Go, improved=found, feasible=np.all(Go <= 0, 1), F_in=F0, G_in=G0,
        nonfinite_steps=nbad,
        seconds=time.perf_counter() - t0,
    )
