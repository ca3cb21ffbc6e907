"""Gradient polishing of candidate trajectories, and a best-known front (conventions §3, §5, §6).

:func:`refine` takes a set of candidates ``X`` (n, n_var) and, for every point i at once,
solves the sub-problem

    minimise jerk(x)  subject to  T(x) ≤ T_i,  G(x) ≤ 0 (the 24 limits of conventions §6),
    x in the decision box (conventions §3)

with Adam (optax) from the point itself. The whole batch is one parameter array: Adam is
per-coordinate, so summing the per-point losses gives n independent optimisations, run
by one jitted ``lax.fori_loop`` (the trip count is traced: changing ``steps`` does not
recompile).

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

:func:`best_known_front` is an ε-constraint sweep over ``T`` from the shortest feasible time
to ``6 h_hi``: anchors solved by sequential quadratic programming (:mod:`dockjax.solve`) and
a dense set of caps polished from them by the same machinery as :func:`refine`. It never
sees any optimiser's front: it depends only on the problem, so it is an independent
yardstick for the optimisers' fronts.

Everything runs in float64 inside ``jax.enable_x64(True)``.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax

from . import checks, config
from .decoding import decode, span_angles
from .fusion import materialize
from .io import DamagedFileError, atomic_savez, load_npz
from .limits import columns, maxima, maxima_screened
from .metrics import nondominated_points
from .objectives import mean_square_jerk
from .problem import DockingProblem, bucket_rows, pad_rows
from .solve import least_jerk_front, straight_line
from .solve import shortest as shortest_time

__all__ = ["RefineResult", "FrontResult", "refine", "best_known_front", "objectives_safe", "straight_line"]


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


@dataclass(frozen=True)
class FrontResult:
    """Output of :func:`best_known_front`: the non-dominated feasible points, sorted by T.

    ``X`` (m, n_var), ``F`` (m, 2), ``G`` (m, 24); ``targets`` the swept time caps.
    """

    X: np.ndarray
    F: np.ndarray
    G: np.ndarray
    targets: np.ndarray
    seconds: float


# -- objective with a NaN-safe jerk ------------------------------------------------------


def _safe_sqrt(v):
    pos = v > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, v, 1.0)), 0.0)


def _safe_jerk(problem, c, h, ref):
    """As ``problem._jerk`` (conventions §5, Eq. 25) with a square root whose gradient is finite
    (0) where a joint's mean-square jerk is 0."""
    ms = mean_square_jerk(problem, c, h, ref)
    return jnp.sum(_safe_sqrt(ms))


def objectives_safe(problem: DockingProblem, x, screen: bool = False):
    """``score`` (conventions §5–6) of one candidate with the NaN-safe jerk: x (n_var,) → F (2,),
    G (24,); differentiable everywhere the kernel is (G is piecewise smooth).

    Default: the full root chain, equal in value to :func:`dockjax.problem.score` except in
    the ``"adaptive"`` and ``"taylor"`` right-arm modes, where the bound treatment is used
    throughout (never understated, so safe to certify with, but it may overstate more;
    the Taylor models' subdivision loop has no reverse-mode derivative; :func:`refine`
    re-scores its results with the kernel). ``screen=True``: the limits by the screen of
    :func:`dockjax.problem._maxima_screened` without its overflow pass — columns near their
    limits exact with exact gradients (envelope theorem), the others rigorous upper bounds.
    Measured on the default problem it saves little in refinement (3.75 against 4.13 s for
    150 points × 200 steps; the backward pass dominates) and lands a hair lower in HV, so
    refinement keeps the full chain."""
    if problem.right_arm == "taylor":
        problem = problem.with_right_arm("bound")
    h, _, c = decode(problem, x)
    ref = materialize(span_angles(c, h))
    F = jnp.stack([jnp.sum(h), _safe_jerk(problem, c, h, ref)])
    if screen:
        M = maxima_screened(problem, c, h, ref)[0]
    else:
        M = maxima(problem, c, h, ref)
    return F, columns(problem, M)


# -- projection onto the box with a time cap ----------------------------------------------


def _project(U, width_h, cap, n_bisect: int = 60):
    """Euclidean projection of each row of U (n, d) onto
    ``{0 ≤ u ≤ 1, Σ_k width_h[k] u[k] ≤ cap}`` (the first 6 columns carry the intervals).
    cap (n,). ``u = clip(v − λ w, 0, 1)`` with λ ≥ 0 found by bisection."""
    U = jnp.clip(U, 0.0, 1.0)
    v = U[:, : config.N_INTERVALS]
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
    return U.at[:, : config.N_INTERVALS].set(jnp.where(over[:, None], vh, v))


# -- the polishing loop ---------------------------------------------------------------------


@jax.jit
def _polish(problem, U0, cap, j_scale, steps, lr, lr_final, mu, rho, margin, j_best0, x_best0, f_best0, g_best0):
    """Projected Adam on all rows of U0 (n, d) at once; returns the best qualifying iterate
    per row (initialised with ``*_best0``; a candidate qualifies when kernel-feasible, with
    ``T ≤ cap_T`` and jerk < the incumbent)."""
    lo = jnp.asarray(problem.lower, U0.dtype)
    width = jnp.asarray(problem.upper, U0.dtype) - lo
    width_h = width[: config.N_INTERVALS]
    # Σ w_k u_k ≤ cap_u, a hair inside so that rounding never lifts T above the cap
    cap_u = cap * (1.0 - 1e-12) - jnp.sum(lo[: config.N_INTERVALS])
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
_score_rows = jax.jit(jax.vmap(objectives_safe, in_axes=(None, 0)))


def _check_common(problem, steps, learning_rate, penalty, margin):
    if not isinstance(problem, DockingProblem):
        raise ValueError(f"problem must be a DockingProblem, got {type(problem).__name__}")
    checks.integer("steps", steps, 1)
    checks.number("learning_rate", learning_rate, 0.0, open_lo=True)
    checks.number("penalty", penalty, 0.0, open_lo=True)
    checks.number("margin", margin, 0.0, 0.5, open_hi=True)


def _bucket(n: int) -> int:
    """Rows per compiled call: the kernel's bucket (:func:`dockjax.problem.bucket_rows`),
    at most :data:`_CHUNK` (larger batches go in chunks of _CHUNK)."""
    return min(_CHUNK, bucket_rows(n))


def _check_rows(rows):
    checks.optional_integer("rows", rows, 1)


def _evaluate(problem, X, rows=None):
    """``problem.evaluate(X)``; with ``rows``, in calls of exactly ``rows`` rows (the last one
    padded with copies of its first row), so that every call shares one compiled shape."""
    if rows is None or len(X) == 0:
        return problem.evaluate(X)
    parts = []
    for i in range(0, len(X), rows):
        part = X[i:i + rows]
        F, G = problem.evaluate(pad_rows(part, rows))
        parts.append((F[:len(part)], G[:len(part)]))
    return tuple(np.concatenate(a) for a in zip(*parts))


def _run(problem, X, cap, steps, learning_rate, penalty, margin, keep_input, rows=None):
    """Shared driver: polish X (n, d) under ``T ≤ cap`` (n,), in chunks of one compiled
    shape (``rows``, default :func:`_bucket`); see :func:`_run_chunk`."""
    n = X.shape[0]
    size = _bucket(n) if rows is None else int(rows)
    parts = [_run_chunk(problem, X[i:i + size], cap[i:i + size], size, steps, learning_rate, penalty,
                        margin, keep_input) for i in range(0, n, size)]
    return tuple(np.concatenate(a) for a in zip(*parts))


def _run_chunk(problem, X, cap, size, steps, learning_rate, penalty, margin, keep_input):
    """Polish X (n ≤ size, d) under ``T ≤ cap`` (n,); when keep_input, the input row is the
    incumbent if kernel-feasible (so only strict jerk improvements are taken)."""
    n = X.shape[0]
    X, cap = pad_rows(X, size), pad_rows(cap, size)  # one compiled shape per bucket
    with jax.enable_x64(True):
        Xj = jnp.asarray(X)
        F0, G0 = _score_rows(problem, Xj)
        F0, G0 = np.asarray(F0), np.asarray(G0)
        feas0 = np.all(G0 <= 0, 1) & (F0[:, 0] <= cap)
        j_scale = np.where(np.isfinite(F0[:, 1]) & (F0[:, 1] > 0), F0[:, 1], 1.0)
        j0 = np.where(feas0 & keep_input, F0[:, 1], np.inf)
        lo, hi = np.asarray(problem.lower), np.asarray(problem.upper)
        U0 = np.clip((X - lo) / (hi - lo), 0.0, 1.0)
        jb, xb, fb, gb, nbad = _polish(
            problem, jnp.asarray(U0), jnp.asarray(cap), jnp.asarray(j_scale), jnp.asarray(int(steps)),
            jnp.asarray(float(learning_rate)), jnp.asarray(0.01 * float(learning_rate)),
            jnp.asarray(float(penalty)), jnp.asarray(10.0 * float(penalty)), jnp.asarray(float(margin)),
            jnp.asarray(j0), Xj, jnp.asarray(F0), jnp.asarray(G0),
        )
        out = (F0, G0, np.asarray(jb), np.asarray(xb), np.asarray(fb), np.asarray(gb), np.asarray(nbad))
    return tuple(a[:n] for a in out)


def refine(
    problem: DockingProblem,
    X,
    *,
    steps: int = 200,
    learning_rate: float = 0.05,
    penalty: float = 10.0,
    margin: float = 1e-4,
    rows: int | None = None,
) -> RefineResult:
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
    _check_common(problem, steps, learning_rate, penalty, margin)
    _check_rows(rows)
    X = problem.check_population(X)
    if X.shape[0] == 0:
        raise ValueError("X must have at least one row")
    t0 = time.perf_counter()
    _, _, jb, xb, fb, gb, nbad = _run(problem, X, X[:, : config.N_INTERVALS].sum(1), steps,
                                      learning_rate, penalty, margin, keep_input=True, rows=rows)
    found = np.isfinite(jb) & ~np.all(xb == X, 1)
    # the kernel has the last word (in the "adaptive" right-arm mode the loop used the
    # bound path, which never understates but may overstate more): a refined row is kept
    # only if the kernel finds it feasible, no longer, and — for a feasible input — of
    # strictly lower jerk
    F0, G0 = _evaluate(problem, X, rows)
    if found.any():
        Fk, Gk = _evaluate(problem, xb[found], rows)
        feas_in = np.all(G0[found] <= 0, 1)
        ok = (np.all(Gk <= 0, 1) & (Fk[:, 0] <= X[found, : config.N_INTERVALS].sum(1) * (1 + 1e-12))
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


def best_known_front(
    problem: DockingProblem,
    *,
    n_points: int = 150,
    n_exact: int = 20,
    line: bool = False,
    steps: int = 600,
    learning_rate: float = 0.05,
    penalty: float = 10.0,
    margin: float = 1e-4,
    rows: int | None = None,
) -> FrontResult:
    """An ε-constraint sweep of T from the shortest feasible time to ``6 h_hi``.

    1. The shortest time, and the least jerk at ``n_exact`` caps from it to ``6 h_hi``
       (quadratically spaced: dense where the front is steep), by sequential quadratic
       programming (:func:`dockjax.solve.shortest`, :func:`dockjax.solve.least_jerk_front`;
       by continuation, and with ``line`` from the straight line too): the anchors.
    2. ``n_points`` caps evenly spaced over the same range, each started from the anchor
       just below it slowed to the cap (feasible, by exact time scaling) and polished in one
       batch by the machinery of :func:`refine` (``steps``, ``learning_rate``, ``penalty``,
       ``margin``, ``rows`` as there): a dense front at the anchors' quality.

    Returns the kernel-feasible non-dominated points of both, sorted by T; ``targets`` the
    caps of step 2. Computed from the problem alone, without seeing any optimiser's front.
    """
    _check_common(problem, steps, learning_rate, penalty, margin)
    _check_rows(rows)
    checks.integer("n_points", n_points, 2)
    checks.integer("n_exact", n_exact, 2)
    t0 = time.perf_counter()
    n = config.N_INTERVALS
    shortest = shortest_time(problem, straight_line(problem, [n * problem.interval_bounds[0]])[0])
    if shortest is None:
        raise ValueError("no trajectory of the decision box meets the limits")
    t_max = n * problem.interval_bounds[1]
    caps = shortest.F[0] + (t_max - shortest.F[0]) * np.linspace(0.0, 1.0, int(n_exact) + 1)[1:] ** 2
    anchors = [shortest] + least_jerk_front(problem, shortest, caps, line=line)
    TA = np.array([a.F[0] for a in anchors])
    XA = np.array([a.x for a in anchors])
    targets = np.linspace(shortest.F[0], t_max, int(n_points))
    k = np.clip(np.searchsorted(TA, targets, side="right") - 1, 0, len(TA) - 1)
    X = XA[k].copy()
    X[:, :n] *= (targets / TA[k])[:, None]
    X = np.clip(X, problem.lower, problem.upper)
    _, _, jb, xb, fb, gb, _ = _run(problem, X, targets, steps, learning_rate, penalty, margin, keep_input=True,
                                   rows=rows)
    ok = np.isfinite(jb) & np.all(gb <= 0, 1)
    Xf = np.concatenate([XA, xb[ok]])
    Ff, Gf = _evaluate(problem, Xf, rows)  # the kernel's word
    feas = np.all(Gf <= 0, 1)
    Xf, Ff, Gf = Xf[feas], Ff[feas], Gf[feas]
    _, order = nondominated_points(Ff, return_index=True)  # distinct, sorted by T
    return FrontResult(X=Xf[order], F=Ff[order], G=Gf[order], targets=targets,
                       seconds=time.perf_counter() - t0)


BEST_KNOWN_FORMAT = 3
"""Version of the best-known front's computation: part of the key of a cached front."""


def best_known_key(problem: DockingProblem, **settings) -> str:
    """The identity of a best-known front: the problem's fields, the settings (default
    :data:`dockjax.config.BEST_KNOWN`) and :data:`BEST_KNOWN_FORMAT`, as sorted JSON."""
    settings = {**config.BEST_KNOWN, **settings}
    settings.pop("rows", None)
    return json.dumps({"format": BEST_KNOWN_FORMAT, "problem": problem.identity(), **settings}, sort_keys=True)


def best_known_cached(problem: DockingProblem, path=None, log=print, **settings) -> FrontResult:
    """:func:`best_known_front` of ``problem`` (settings default to
    :data:`dockjax.config.BEST_KNOWN`), reused from ``path`` (an ``.npz``; a folder: a file
    named by the key's hash inside it) when that file was written for the same problem and
    settings (:func:`best_known_key`), else computed and written there atomically."""
    key = best_known_key(problem, **settings)
    if path is not None and Path(path).is_dir():
        path = Path(path) / f"best-known-{hashlib.sha256(key.encode()).hexdigest()[:16]}.npz"
    if path is not None and Path(path).exists():
        try:
            d = load_npz(path)
            if str(d["key"]) == key:
                log(f"best-known front: {len(d['F'])} points from {path}")
                return FrontResult(X=d["X"], F=d["F"], G=d["G"], targets=d["targets"], seconds=float(d["seconds"]))
        except (DamagedFileError, KeyError):
            log(f"best-known front: {path} is damaged; computed again")
    front = best_known_front(problem, **{**config.BEST_KNOWN, **settings})
    log(f"best-known front: {len(front.F)} points in {front.seconds:.1f} s (compile included)")
    if path is not None:
        atomic_savez(path, {"X": front.X, "F": front.F, "G": front.G, "targets": front.targets,
                            "seconds": front.seconds, "key": np.array(key)})
    return front
