"""The algorithm contract, stated in one type, and what every optimiser shares.

An optimiser is an :class:`Algorithm`: a name, a ``Params`` pytree of hyper-parameters
(every field annotated with its symbol and allowed range, :func:`param`; the population
size is static, since it fixes shapes), a ``State`` pytree, and four pure functions in the
style of optax and evosax around one evaluation of ``pop_size`` candidates::

    init_ask(key, problem, params) -> (U, key)      init_tell(key, pop, params) -> State
    ask(state, problem, params) -> (U, state)       tell(state, pop, params) -> State
    final_population(state) -> Population

from which ``init`` and ``step`` follow (ask, score, tell). ``run(algorithm, key, problem,
params, n_iter)`` drives them with ``lax.scan``; it jits, and ``jax.vmap`` over keys or over
``Params`` leaves (ρ, α_max, …) runs many runs in one compiled call. All algorithms search
in the unit box (conventions §7) and evaluate exactly ``pop_size`` new candidates per
iteration (equal budgets).

A *problem* is any object with ``n_var``, ``n_obj``, ``n_con``, ``lower``, ``upper``
(natural units) and ``evaluate_jax(X) -> (F, G)`` (traceable; ``G`` may have 0 columns);
:class:`dockjax.DockingProblem` and :class:`dockjax.algorithms.zdt.ZDT1` are such problems.
It is passed to ``jit`` as a pytree (its arrays are traced, its shape information static).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import field
from typing import Any, Callable, NamedTuple, Protocol, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .. import checks, pareto
from ..pytrees import pytree_dataclass, static

__all__ = [
    "Algorithm", "Population", "param", "validate_params", "coerce", "as_params", "run_axes", "n_runs", "stack_params",
    "broadcast_params", "params_at", "pytree_dataclass", "static", "evaluate_unit", "evaluate_runs", "to_natural",
    "uniform_init_ask", "merge_and_survive", "run", "run_batch",
]


@pytree_dataclass
class Population:
    """Candidates in the unit box and their scores. U: (n, d); F: (n, m); G: (n, c); cv: (n,)."""

    U: jax.Array
    F: jax.Array
    G: jax.Array
    cv: jax.Array


class InitAsk(Protocol):
    def __call__(self, key: jax.Array, problem: Any, params: Any) -> tuple[jax.Array, jax.Array]:
        """The initial candidates ``U`` (pop_size, n_var) in the unit box, and the key left."""


class InitTell(Protocol):
    def __call__(self, key: jax.Array, pop: Population, params: Any) -> Any:
        """The first state, from the scored initial candidates."""


class Ask(Protocol):
    def __call__(self, state: Any, problem: Any, params: Any) -> tuple[jax.Array, Any]:
        """The next ``pop_size`` candidates to score, and the state (its key advanced)."""


class Tell(Protocol):
    def __call__(self, state: Any, pop: Population, params: Any) -> Any:
        """The state after the scored candidates ``pop`` are taken in."""


class FinalPopulation(Protocol):
    def __call__(self, state: Any) -> Population:
        """The algorithm's output set (a repository for MOPSO, the population otherwise)."""


class Algorithm(NamedTuple):
    """An optimiser (see the module docstring). Hashable, so it is a static argument of a
    compiled program; :data:`dockjax.algorithms.ALGORITHMS` holds the four of the paper."""

    name: str
    Params: type
    State: type
    init_ask: InitAsk
    init_tell: InitTell
    ask: Ask
    tell: Tell
    final_population: FinalPopulation

    def init(self, key: jax.Array, problem: Any, params: Any) -> Any:
        """``init_ask``, score, ``init_tell``: the first state (``pop_size`` evaluations)."""
        U, key = self.init_ask(key, problem, params)
        return self.init_tell(key, evaluate_unit(problem, U), params)

    def step(self, state: Any, problem: Any, params: Any) -> Any:
        """One iteration: ``ask``, score ``pop_size`` candidates, ``tell``."""
        U, state = self.ask(state, problem, params)
        return self.tell(state, evaluate_unit(problem, U), params)

    def validate(self, params: Any) -> None:
        """:func:`validate_params` (ValueError naming the field and its range)."""
        validate_params(params)


def param(default: Any, *, symbol: str, lo: float = -math.inf, hi: float = math.inf, open_lo: bool = False,
          open_hi: bool = False, integer: bool = False, is_static: bool = False, also: tuple = ()) -> Any:
    """A ``Params`` field with its paper symbol and allowed range, checked by
    :func:`validate_params` (``also``: extra allowed values, e.g. a sentinel). A static
    field (``is_static``) is part of the compiled program's identity (shapes, loop counts);
    the others may be traced, so ``vmap`` over them sweeps hyper-parameters."""
    meta = dict(symbol=symbol, lo=lo, hi=hi, open_lo=open_lo, open_hi=open_hi, integer=integer, also=tuple(also))
    if is_static:
        meta["static"] = True
    return field(default=default, metadata=meta)


def _rule(meta: dict) -> str:
    lo, hi = meta["lo"], meta["hi"]
    kind = "an integer" if meta["integer"] else "a number"
    if hi == math.inf:
        rule = f"{kind} {'>' if meta['open_lo'] else '>='} {lo:g}"
    else:
        rule = f"{kind} in {'(' if meta['open_lo'] else '['}{lo:g}, {hi:g}{')' if meta['open_hi'] else ']'}"
    return rule + "".join(f" or {a:g}" for a in meta["also"])


def validate_params(params: Any) -> None:
    """Check every field of a ``Params`` pytree against its :func:`param` range (each entry
    of an array-valued field, as in a sweep). Raises ValueError naming the field, its
    symbol, its allowed range and the value; before any compilation."""
    for f in dataclasses.fields(params):
        meta = f.metadata
        if "symbol" not in meta:
            continue
        value = getattr(params, f.name)
        what = f"{f.name} ({meta['symbol']})"
        if meta["integer"]:
            checks.integer(what, value, None if meta["lo"] == -math.inf else int(meta["lo"]),
                           None if meta["hi"] == math.inf else int(meta["hi"]))
            continue
        try:
            arr = checks.numbers(what, value)
        except ValueError:
            raise ValueError(f"{what} must be {_rule(meta)}, got {value!r}") from None
        lo, hi = meta["lo"], meta["hi"]
        ok = ((arr > lo) if meta["open_lo"] else (arr >= lo)) & ((arr < hi) if meta["open_hi"] else (arr <= hi))
        ok |= np.isin(arr, meta["also"])
        if not np.all(ok):
            raise ValueError(f"{what} must be {_rule(meta)}, got {arr.tolist()!r}")


def coerce(params_type: type, name: str, value: Any) -> Any:
    """``value`` of the ``Params`` field ``name`` in the field's own type: an int for an
    integer field (an integral float such as ``2.0`` is accepted, ``2.5`` is refused), a
    float otherwise, or a float64 array of them (a run axis). Raises ValueError naming
    the field and its range."""
    meta = params_type.__dataclass_fields__[name].metadata
    what = f"{name} ({meta.get('symbol', name)})"
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf" or (arr.dtype.kind == "f" and not np.all(np.isfinite(arr))):
        raise ValueError(f"{what} must be {_rule(meta)}, got {value!r}")
    if meta.get("integer"):
        if arr.ndim or not float(arr) == int(arr):
            raise ValueError(f"{what} must be {_rule(meta)}, got {value!r}")
        return int(arr)
    return arr.astype(np.float64) if arr.ndim else float(arr)


def as_params(params: Any) -> Any:
    """``params`` with every traced field in its type (:func:`coerce`: a float, an int, or a
    float64 array with one value per run; a list such as ``rho=[0.3, 0.5]`` becomes an
    array, a run axis), validated (:func:`validate_params`)."""
    fields = [f for f in dataclasses.fields(params) if f.init and not f.metadata.get("static")]
    params = dataclasses.replace(params, **{f.name: coerce(type(params), f.name, getattr(params, f.name))
                                            for f in fields if "symbol" in f.metadata})
    validate_params(params)
    return params


def run_axes(params: Any) -> Any:
    """``vmap``'s ``in_axes`` for a ``Params`` pytree whose leaves may carry a run axis:
    0 for a leaf with one (shape (runs,)), None for a scalar shared by every run."""
    return jax.tree_util.tree_map(lambda a: 0 if np.ndim(a) else None, params)


def n_runs(params: Any) -> int | None:
    """The length of the run axis of a ``Params`` pytree (None: every leaf is a scalar).
    Raises ValueError when leaves disagree or one has more than one axis."""
    sizes = set()
    for f in dataclasses.fields(params):
        if f.metadata.get("static"):
            continue
        shape = np.shape(getattr(params, f.name))
        if len(shape) > 1:
            raise ValueError(f"{f.name} must be a number or a 1-D array (one value per run), got shape {shape}")
        sizes.update(shape)
    if len(sizes) > 1:
        raise ValueError(f"the per-run hyper-parameters have different lengths {sorted(sizes)}")
    return sizes.pop() if sizes else None


def stack_params(params: Sequence[Any]) -> Any:
    """One ``Params`` pytree from several (one per run) of the same static fields: every
    traced leaf gets a run axis, (runs,)."""
    params = list(params)
    if not params:
        raise ValueError("stack_params needs at least one Params")
    return jax.tree_util.tree_map(lambda *a: np.stack([np.asarray(v, np.float64) for v in a]), *params)


def broadcast_params(params: Any, runs: int) -> Any:
    """``params`` with every traced leaf as a float64 array of shape (runs,)."""
    return jax.tree_util.tree_map(lambda a: np.broadcast_to(np.asarray(a, np.float64), (runs,)).copy(), params)


def params_at(params: Any, i: int) -> Any:
    """The ``Params`` of run ``i`` of a pytree whose leaves may carry a run axis (scalars
    as Python floats)."""
    return jax.tree_util.tree_map(lambda a: float(np.asarray(a)[i]) if np.ndim(a) else a, params)


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
    """``init_ask`` of the algorithms that start uniformly in the unit box (conventions §7):
    ``pop_size`` uniform candidates. → ``(U, key)``."""
    k_init, key = jax.random.split(key)
    dtype = jnp.zeros(()).dtype
    return jax.random.uniform(k_init, (params.pop_size, problem.n_var), dtype), key


def merge_and_survive(parents: Population, children: Population, n: int) -> tuple[Population, jax.Array]:
    """Merge parents and children (2n) and keep the best n by constrained non-dominated
    rank, then crowding distance, then index (conventions §7). Returns the survivors and
    their ranks."""
    merged = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b], 0), parents, children)
    idx, rank = pareto.survive(merged.F, merged.cv, n, return_rank=True)
    return jax.tree_util.tree_map(lambda a: a[idx], merged), rank


def run(
    algorithm: Algorithm,
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
    algorithm: Algorithm,
    keys: jax.Array,
    problem,
    params,
    n_iter: int,
    *,
    history: Callable | None = None,
    evaluate: Callable | None = None,
):
    """A batch of runs (``keys`` (runs,)) of :func:`run` in one ``lax.scan`` (traceable).

    ``params`` is the algorithm's ``Params`` pytree; a leaf of shape (runs,) gives every run
    its own value (e.g. ρ of a sweep, :func:`stack_params`), a scalar is shared. The
    algorithm's ``ask`` and ``tell`` are vmapped over the runs, and the
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
    evaluate = evaluate_runs if evaluate is None else evaluate
    axes = run_axes(params)

    U0, key0 = jax.vmap(lambda p, k: algorithm.init_ask(k, problem, p), in_axes=(axes, 0))(params, keys)
    runs, n = U0.shape[:2]
    init_tell = jax.vmap(lambda p, k, pop: algorithm.init_tell(k, pop, p), in_axes=(axes, 0, 0))
    ask = jax.vmap(lambda p, s: algorithm.ask(s, problem, p), in_axes=(axes, 0))
    tell = jax.vmap(lambda p, s, pop: algorithm.tell(s, pop, p), in_axes=(axes, 0, 0))
    zeros = lambda m: jnp.zeros((runs, n, m), U0.dtype)  # noqa: E731
    blank = Population(U=U0, F=zeros(problem.n_obj), G=zeros(problem.n_con), cv=zeros(1)[..., 0])
    state = init_tell(params, key0, blank)  # a placeholder of the state's shape

    def body(s, i):
        first = i == 0  # not batched, so the conds stay branches
        U, s = jax.lax.cond(first, lambda s: (U0, s), lambda s: ask(params, s), s)
        pop = evaluate(problem, U)
        s = jax.lax.cond(first, lambda s, p: init_tell(params, key0, p), lambda s, p: tell(params, s, p), s, pop)
        return s, (jax.vmap(history)(s) if history is not None else None)

    state, trace = jax.lax.scan(body, state, jnp.arange(n_iter + 1))
    return state, jax.tree_util.tree_map(lambda a: jnp.moveaxis(a[1:], 0, 1), trace)
