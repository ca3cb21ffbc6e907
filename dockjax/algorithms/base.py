"""What every optimiser shares: the problem contract, the unit box, the run loop.

Every algorithm is a module with a ``Params`` pytree (hyper-parameters; the population size
is a static field, since it fixes shapes), a ``State`` pytree, and two pure functions in the
style of optax/evosax::

    init(key, problem, params) -> State
    step(state, problem, params) -> State

each the composition of an ask/tell pair around one evaluation of ``pop_size`` candidates
(in the style of evosax)::

    init_ask(key, problem, params) -> (U, key)      init_tell(key, pop, params) -> State
    ask(state, problem, params) -> (U, state)       tell(state, pop, params) -> State

``run(algorithm, key, problem, params, n_iter)`` drives them with ``lax.scan``; it jits,
and ``jax.vmap`` over keys or over ``Params`` leaves (ρ, α_max, …) runs many runs in one
compiled call. All algorithms search in the unit box (SPEC §7) and evaluate exactly
``pop_size`` new candidates per iteration (equal budgets).

A *problem* is any object with ``n_var``, ``n_obj``, ``n_con``, ``lower``, ``upper``
(NumPy, natural units) and ``evaluate_jax(X) -> (F, G)`` (traceable; ``G`` may have 0
columns); :class:`dockjax.DockingProblem` and :class:`ZDT1` are such problems. It is passed
to ``jit`` as a pytree (its arrays are traced, its shape information static).
"""

from __future__ import annotations

import dataclasses
from types import ModuleType
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from .. import pareto
from ..pytrees import pytree_dataclass, static

__all__ = [
    "pytree_dataclass",
    "static",
    "Population",
    "evaluate_unit",
    "evaluate_runs",
    "to_natural",
    "validate_common",
    "ZDT1",
    "hypervolume_2d",
]


@pytree_dataclass
class Population:
    """Candidates in the unit box and their scores. U: (n, d); F: (n, m); G: (n, c); cv: (n,)."""

    U: jax.Array
    F: jax.Array
    G: jax.Array
    cv: jax.Array


def to_natural(problem, U):
    """Unit box → natural units: ``lower + U (upper − lower)``."""
    lo = jnp.asarray(problem.lower, U.dtype)
    hi = jnp.asarray(problem.upper, U.dtype)
    return lo + U * (hi - lo)


def evaluate_unit(problem, U) -> Population:
    """Score unit-box candidates U (n, d) with the problem's traceable kernel."""
    F, G = problem.evaluate_jax(to_natural(problem, U))
    cv = pareto.total_violation(G) if G.shape[-1] else jnp.zeros(U.shape[0], U.dtype)
    return Population(U=U, F=F, G=G, cv=cv)


def evaluate_runs(problem, U) -> Population:
    """Every run's candidates U (runs, n, d) scored in one call of the kernel (not under
    ``vmap``: the kernel decides how it walks through them). → Population of (runs, n, ·)."""
    pop = evaluate_unit(problem, U.reshape((-1, U.shape[-1])))
    return jax.tree_util.tree_map(lambda a: a.reshape(U.shape[:2] + a.shape[1:]), pop)


def uniform_init_ask(key, problem, params):
    """``init_ask`` of the algorithms that start uniformly in the unit box (SPEC §7):
    ``pop_size`` uniform candidates. → ``(U, key)``."""
    k_init, key = jax.random.split(key)
    dtype = jnp.zeros(()).dtype
    return jax.random.uniform(k_init, (params.pop_size, problem.n_var), dtype), key


def evaluated_init(init_ask, init_tell, key, problem, params):
    """``init`` from an ``init_ask``/``init_tell`` pair: ask, score, tell."""
    U, key = init_ask(key, problem, params)
    return init_tell(key, evaluate_unit(problem, U), params)


def evaluated_step(ask, tell, state, problem, params):
    """``step`` from an ``ask``/``tell`` pair: ask, score ``pop_size`` candidates, tell."""
    U, state = ask(state, problem, params)
    return tell(state, evaluate_unit(problem, U), params)


def validate_common(pop_size: int, n_iter: int | None = None) -> None:
    """Checks shared by every algorithm, raised before any compilation."""
    if not isinstance(pop_size, (int, np.integer)) or isinstance(pop_size, bool) or pop_size < 4:
        raise ValueError(f"pop_size must be an integer >= 4, got {pop_size!r}")
    if n_iter is not None and (
        not isinstance(n_iter, (int, np.integer)) or isinstance(n_iter, bool) or n_iter < 1
    ):
        raise ValueError(f"n_iter must be an integer >= 1, got {n_iter!r}")


def _check_unit_interval(name: str, value, lo: float, hi: float, open_lo: bool, open_hi: bool):
    arr = np.asarray(value, dtype=np.float64)
    ok = np.isfinite(arr) & (arr > lo if open_lo else arr >= lo) & (arr < hi if open_hi else arr <= hi)
    if not np.all(ok):
        lb = "(" if open_lo else "["
        rb = ")" if open_hi else "]"
        raise ValueError(f"{name} must lie in {lb}{lo}, {hi}{rb}, got {arr.tolist()!r}")


def check_range(name: str, value, lo: float, hi: float = np.inf, *, open_lo=False, open_hi=False):
    """Raise ValueError unless every entry of ``value`` lies in the given interval."""
    _check_unit_interval(name, value, lo, hi, open_lo, open_hi)


class ZDT1:
    """ZDT1 (Zitzler, Deb & Thiele 2000): 30 variables in [0, 1], two objectives, no limits.

    Known front ``f2 = 1 − sqrt(f1)``, ``f1 ∈ [0, 1]`` (:meth:`pareto_front`).
    """

    n_obj = 2
    n_con = 0

    def __init__(self, n_var: int = 30):
        self.n_var = int(n_var)
        self.lower = np.zeros(self.n_var)
        self.upper = np.ones(self.n_var)

    def evaluate_jax(self, X):
        f1 = X[:, 0]
        g = 1.0 + 9.0 * jnp.mean(X[:, 1:], axis=1)
        f2 = g * (1.0 - jnp.sqrt(jnp.clip(f1 / g, 0.0, None)))
        return jnp.stack([f1, f2], 1), jnp.zeros((X.shape[0], 0), X.dtype)

    def evaluate(self, X):
        with jax.enable_x64(True):
            F, G = self.evaluate_jax(jnp.asarray(X, jnp.float64))
            return np.asarray(F), np.asarray(G)

    @staticmethod
    def pareto_front(n: int = 1000) -> np.ndarray:
        f1 = np.linspace(0.0, 1.0, n)
        return np.stack([f1, 1.0 - np.sqrt(f1)], 1)

    def __repr__(self) -> str:
        return f"ZDT1(n_var={self.n_var})"


jax.tree_util.register_pytree_node(
    ZDT1, lambda p: ((), p.n_var), lambda n, _: ZDT1(n)
)


def hypervolume_2d(F, feasible, ref):
    """Exact 2-D hypervolume (minimisation) of the feasible points of F (n, 2) up to ``ref``.

    Traceable: sort by f1, keep the running minimum of f2, sum the rectangles.
    """
    big = jnp.asarray(jnp.inf, F.dtype)
    f1 = jnp.where(feasible & jnp.all(F < ref, axis=1), F[:, 0], big)
    order = pareto.lexsort((f1,))
    f1s = f1[order]
    f2s = jnp.where(jnp.isfinite(f1s), F[order, 1], ref[1])
    best = jax.lax.cummin(f2s)
    prev = jnp.concatenate([jnp.full((1,), ref[1], F.dtype), best[:-1]])
    width = jnp.where(jnp.isfinite(f1s), ref[0] - f1s, 0.0)
    return jnp.sum(width * jnp.maximum(prev - best, 0.0))


def run(
    algorithm: ModuleType,
    key: jax.Array,
    problem,
    params,
    n_iter: int,
    *,
    history: Callable | None = None,
):
    """Initialise and iterate ``n_iter`` steps with ``lax.scan`` (traceable; jit it).

    One run of :func:`run_batch`: the result is the same as ``init`` then ``step``
    repeated. ``history(state) -> pytree`` is recorded after every step (e.g. the
    hypervolume of the current population) without leaving the compiled loop. Returns
    ``(state, trace)``; ``jax.vmap`` of it over keys or ``Params`` leaves runs a batch.
    """
    out = run_batch(algorithm, key[None], problem, params, n_iter, history=history)
    return jax.tree_util.tree_map(lambda a: a[0], out)


def run_batch(
    algorithm: ModuleType,
    keys: jax.Array,
    problem,
    params,
    n_iter: int,
    *,
    overrides: dict | None = None,
    history: Callable | None = None,
    evaluate: Callable | None = None,
):
    """A batch of runs (``keys`` (runs,)) of :func:`run` in one ``lax.scan`` (traceable).

    ``overrides`` maps ``Params`` field names to per-run arrays (runs,) (e.g. ρ of a
    sweep). The algorithm's ``ask`` and ``tell`` are vmapped over the runs, and the
    problem's kernel is called once per pass on every run's candidates together (so the
    kernel, not ``vmap``, decides how it walks through them: see
    :func:`dockjax.problem.score_batch`). The kernel appears once in the compiled program
    (it is the dear part to compile): the scan runs ``n_iter + 1`` times, and each pass
    asks for candidates (the initial population in pass 0, the algorithm's ``ask`` after),
    scores them, and hands the scores back (``init_tell`` in pass 0, ``tell`` after).
    ``evaluate(problem, U) -> Population``, for U (runs, n, d), replaces
    :func:`evaluate_runs` (e.g. with one whose rows are shared out over devices:
    :func:`dockjax.devices.share_rows`). Returns ``(state, trace)`` with the runs on the
    leading axis of every leaf.
    """
    ov = dict(overrides or {})
    evaluate = evaluate_runs if evaluate is None else evaluate

    def per_run(f):
        return jax.vmap(lambda o, *a: f(*a, replace(params, **o) if o else params))

    U0, key0 = per_run(lambda k, p: algorithm.init_ask(k, problem, p))(ov, keys)
    runs, n = U0.shape[:2]
    init_tell = per_run(algorithm.init_tell)
    ask = per_run(lambda s, p: algorithm.ask(s, problem, p))
    tell = per_run(algorithm.tell)
    zeros = lambda m: jnp.zeros((runs, n, m), U0.dtype)  # noqa: E731
    blank = Population(U=U0, F=zeros(problem.n_obj), G=zeros(problem.n_con), cv=zeros(1)[..., 0])
    state = init_tell(ov, key0, blank)  # a placeholder of the state's shape

    def body(s, i):
        first = i == 0  # not batched, so the conds stay branches
        U, s = jax.lax.cond(first, lambda s: (U0, s), lambda s: ask(ov, s), s)
        pop = evaluate(problem, U)
        s = jax.lax.cond(first, lambda s, p: init_tell(ov, key0, p), lambda s, p: tell(ov, s, p), s, pop)
        return s, (jax.vmap(history)(s) if history is not None else None)

    state, trace = jax.lax.scan(body, state, jnp.arange(n_iter + 1))
    return state, jax.tree_util.tree_map(lambda a: jnp.moveaxis(a[1:], 0, 1), trace)


def replace(obj, **changes):
    """``dataclasses.replace`` for the frozen pytree dataclasses here."""
    return dataclasses.replace(obj, **changes)
