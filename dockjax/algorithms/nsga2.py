"""NSGA-II (Deb, Pratap, Agarwal & Meyarivan 2002; conventions §7) as a pure JAX program.

K. Deb, A. Pratap, S. Agarwal and T. Meyarivan, "A fast and elitist multiobjective genetic
algorithm: NSGA-II", IEEE Transactions on Evolutionary Computation 6(2):182–197, 2002,
https://doi.org/10.1109/4235.996017.

One iteration (exactly ``pop_size`` evaluations, conventions §7's equal-budget rule):

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
here every individual is eligible, as conventions §7 states); pymoo's tournament compares feasible
pairs by Pareto dominance rather than rank (``comp_by_dom_and_crowding``); pymoo removes
duplicate children and re-mates; and survival ties are broken by index here
(:mod:`dockjax.pareto`).
"""

from __future__ import annotations

from dataclasses import replace

import jax
import jax.numpy as jnp

from .. import config, pareto
from .base import Algorithm, Population, merge_and_survive, param, pytree_dataclass, uniform_init_ask
from .variation import binary_tournament, polynomial_mutation, sbx

__all__ = ["Params", "State", "ALGORITHM", "init_ask", "init_tell", "ask", "tell", "final_population"]


@pytree_dataclass
class Params:
    """NSGA-II hyper-parameters (conventions §7 defaults). Every field but ``pop_size`` may be traced."""

    pop_size: int = param(config.POP_SIZE, symbol="N", lo=4, integer=True, is_static=True)
    """Population size N (evaluations per generation)."""
    eta_c: float = param(15.0, symbol="η_c", lo=0.0, open_lo=True)
    """SBX distribution index η_c > 0."""
    p_crossover: float = param(0.9, symbol="p_c", lo=0.0, hi=1.0)
    """Probability that a pair of parents is crossed, in [0, 1]."""
    eta_m: float = param(20.0, symbol="η_m", lo=0.0, open_lo=True)
    """Polynomial-mutation distribution index η_m > 0."""
    p_mutation: float = param(-1.0, symbol="p_m", lo=0.0, hi=1.0, also=(-1.0,))
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
    child_a, child_b = sbx(k_cross, U[pairs[:, 0]], U[pairs[:, 1]], params.eta_c, params.p_crossover)
    children = jnp.concatenate([child_a, child_b], axis=0)[:n]
    p_m = jnp.where(params.p_mutation < 0, 1.0 / U.shape[1], params.p_mutation)
    children = jnp.clip(polynomial_mutation(k_mut, children, params.eta_m, p_m), 0.0, 1.0)
    return children, replace(state, key=key)


def tell(state: State, offspring: Population, params: Params) -> State:
    """Merge the scored children with the parents; the best n survive (constrained rank,
    then crowding), with their recomputed rank and crowding distance."""
    pop, _ = merge_and_survive(state.pop, offspring, params.pop_size)
    rank, crowding = pareto.rank_and_crowding(pop.F, pop.cv)
    return State(key=state.key, pop=pop, rank=rank, crowding=crowding, iteration=state.iteration + 1)


def final_population(state: State) -> Population:
    """The population after the last iteration (all ``pop_size`` members are real)."""
    return state.pop


ALGORITHM = Algorithm(name="nsga2", Params=Params, State=State, init_ask=init_ask, init_tell=init_tell, ask=ask,
                      tell=tell, final_population=final_population)
