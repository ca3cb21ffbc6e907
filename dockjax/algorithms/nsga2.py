"""NSGA-II (Deb, Pratap, Agarwal & Meyarivan 2002; SPEC §7) as a pure JAX program.

K. Deb, A. Pratap, S. Agarwal and T. Meyarivan, "A fast and elitist multiobjective genetic
algorithm: NSGA-II", IEEE Transactions on Evolutionary Computation 6(2):182–197, 2002,
https://doi.org/10.1109/4235.996017.

One iteration (exactly ``pop_size`` evaluations, SPEC §7's equal-budget rule):

1. binary tournament on Deb's constraint-domination, then rank, then crowding distance
   (:func:`~dockjax.algorithms.variation.binary_tournament`), ``2⌈n/2⌉`` winners;
2. bounded SBX on consecutive pairs of winners (η_c = 15, pair probability 0.9,
   per-variable probability 0.5; :func:`~dockjax.algorithms.variation.sbx`); an odd
   population drops the last child;
3. polynomial mutation (η_m = 20, per-variable probability 1/n_var;
   :func:`~dockjax.algorithms.variation.polynomial_mutation`), clip to the unit box;
4. evaluate the n children, merge them with the n parents and keep the best n by
   constrained non-dominated rank, then crowding distance (:func:`dockjax.pareto.survive`);
   the survivors' rank and crowding distance (recomputed on the survivors) drive the next
   tournament.

Differences from pymoo 0.6.2's ``NSGA2`` (the test-suite's reference), all deliberate:
pymoo mutates an individual only with probability 0.9 (then each variable with 1/n_var;
here every individual is eligible, as SPEC §7 states); pymoo's tournament compares feasible
pairs by Pareto dominance rather than rank (``comp_by_dom_and_crowding``); pymoo removes
duplicate children and re-mates; and survival ties are broken by index here
(:mod:`dockjax.pareto`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .. import pareto
from .base import (
    Population, check_range, evaluated_init, evaluated_step, pytree_dataclass, replace, static,
    uniform_init_ask, validate_common,
)
from .variation import binary_tournament, polynomial_mutation, sbx

__all__ = [
    "Params", "State", "init", "step", "init_ask", "init_tell", "ask", "tell", "validate",
    "final_population",
]


@pytree_dataclass
class Params:
    """NSGA-II hyper-parameters (SPEC §7 defaults). Every field but ``pop_size`` may be traced."""

    pop_size: int = static(150)
    eta_c: float = 15.0
    """SBX distribution index η_c > 0."""
    p_c: float = 0.9
    """Probability that a pair of parents is crossed, in [0, 1]."""
    eta_m: float = 20.0
    """Polynomial-mutation distribution index η_m > 0."""
    p_m: float = -1.0
    """Per-variable mutation probability in [0, 1]; the sentinel −1 (default) means
    ``1/n_var`` (a pytree leaf cannot be None and still be vmapped)."""


@pytree_dataclass
class State:
    key: jax.Array
    pop: Population
    """The current population, (pop_size, ·)."""
    rank: jax.Array
    """(pop_size,) int32 constrained non-dominated rank of ``pop`` (0 best)."""
    crowding: jax.Array
    """(pop_size,) crowding distance of ``pop`` within its fronts."""
    iteration: jax.Array
    """Completed iterations (int32)."""


def validate(problem, params: Params) -> None:
    """Clear ValueErrors for bad hyper-parameters, before any compilation."""
    validate_common(params.pop_size)
    check_range("eta_c", params.eta_c, 0.0, open_lo=True)
    check_range("p_c", params.p_c, 0.0, 1.0)
    check_range("eta_m", params.eta_m, 0.0, open_lo=True)
    p_m = np.asarray(params.p_m, dtype=np.float64)
    if not np.all((p_m == -1.0) | (np.isfinite(p_m) & (p_m >= 0.0) & (p_m <= 1.0))):
        raise ValueError(f"p_m must lie in [0, 1] or be -1 (meaning 1/n_var), got {p_m.tolist()!r}")


def _with_ranks(key, pop: Population) -> State:
    rank, crowding = pareto.rank_and_crowding(pop.F, pop.cv)
    return State(key=key, pop=pop, rank=rank, crowding=crowding, iteration=jnp.zeros((), jnp.int32))


def init_ask(key, problem, params: Params):
    """Uniform random population in the unit box. → ``(U, key)``."""
    return uniform_init_ask(key, problem, params)


def init_tell(key, pop: Population, params: Params) -> State:
    """The state of the scored initial population (ranks and crowding for the tournament)."""
    return _with_ranks(key, pop)


def ask(state: State, problem, params: Params):
    """The n children of one generation: tournament, SBX, mutation. → ``(U, state)``."""
    key, k_sel, k_cross, k_mut = jax.random.split(state.key, 4)
    n = params.pop_size
    U = state.pop.U
    n_pairs = (n + 1) // 2
    winners = binary_tournament(k_sel, state.rank, state.crowding, state.pop.cv, 2 * n_pairs)
    pairs = winners.reshape(n_pairs, 2)
    child_a, child_b = sbx(k_cross, U[pairs[:, 0]], U[pairs[:, 1]], params.eta_c, params.p_c)
    children = jnp.concatenate([child_a, child_b], axis=0)[:n]
    p_m = jnp.where(params.p_m < 0, 1.0 / U.shape[1], params.p_m)
    children = jnp.clip(polynomial_mutation(k_mut, children, params.eta_m, p_m), 0.0, 1.0)
    return children, replace(state, key=key)


def tell(state: State, offspring: Population, params: Params) -> State:
    """Merge the scored children with the parents; the best n survive (constrained rank,
    then crowding), with their recomputed rank and crowding distance."""
    merged = jax.tree_util.tree_map(
        lambda a, b: jnp.concatenate([a, b], axis=0), state.pop, offspring
    )
    keep = pareto.survive(merged.F, merged.cv, params.pop_size)
    pop = jax.tree_util.tree_map(lambda a: a[keep], merged)
    rank, crowding = pareto.rank_and_crowding(pop.F, pop.cv)
    return State(key=state.key, pop=pop, rank=rank, crowding=crowding, iteration=state.iteration + 1)


def init(key, problem, params: Params) -> State:
    """Uniform random population in the unit box, evaluated (``pop_size`` evaluations)."""
    return evaluated_init(init_ask, init_tell, key, problem, params)


def step(state: State, problem, params: Params) -> State:
    """One generation: :func:`ask` (tournament, SBX, mutation), evaluation of the n
    children, :func:`tell` (survival)."""
    return evaluated_step(ask, tell, state, problem, params)


def final_population(state: State) -> Population:
    """The population after the last iteration (all ``pop_size`` members are real)."""
    return state.pop
