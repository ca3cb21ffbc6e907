"""MOCS: multi-objective cuckoo search (Yang & Deb 2013; paper §4.2, Eqs. 27–30; conventions §7).

X.-S. Yang and S. Deb, "Multiobjective cuckoo search for design optimization",
Computers & Operations Research 40(6), 2013, https://doi.org/10.1016/j.cor.2011.09.026.

One iteration (exactly ``pop_size`` evaluations, conventions §7's equal-budget rule):

1. Lévy flight (Eqs. 27–29): ``x' = x + α₀ · step ⊙ (x_j − x)``, Mantegna steps (β = 1.5),
   ``x_j`` drawn at random from the current rank-1 set for each nest, ``α₀ = 0.01``;
2. discovery on the moved nests: each component changes with probability ``p_a = 0.25``
   by ``r (x_a − x_b)``;
3. clip to the unit box, evaluate the n children once, merge them with their parents and
   keep the best n by constrained non-dominated rank, then crowding distance.

Departures from the paper, as fixed by conventions §7: uniform initialisation in the box (Eq. 30's
``N(0, 1)`` makes no sense in a bounded box); the Lévy move is kept and followed by
discovery (Yang's demo code overwrites it); children and parents are merged for survival.
"""

from __future__ import annotations

from dataclasses import replace

import jax
import jax.numpy as jnp

from .. import config, pareto
from .base import Algorithm, Population, merge_and_survive, param, pytree_dataclass, uniform_init_ask
from .operators import discovery, levy_step, random_rank1_partner

__all__ = ["Params", "State", "ALGORITHM", "init_ask", "init_tell", "ask", "tell", "final_population", "cuckoo_ask"]


@pytree_dataclass
class Params:
    """MOCS hyper-parameters (conventions §7 defaults)."""

    pop_size: int = param(config.POP_SIZE, symbol="n", lo=4, integer=True, is_static=True)
    """Number of nests n (evaluations per iteration)."""
    alpha0: float = param(0.01, symbol="α₀", lo=0.0, open_lo=True)
    """Step-size factor α₀ of Eq. 29, > 0."""
    p_a: float = param(0.25, symbol="p_a", lo=0.0, hi=1.0)
    """Discovery probability per component, in [0, 1]."""


@pytree_dataclass
class State:
    key: jax.Array
    pop: Population
    rank: jax.Array
    iteration: jax.Array
    """Completed iterations (int32)."""


def init_ask(key, problem, params: Params):
    """Uniform random nests in the unit box (conventions §7). → ``(U, key)``."""
    return uniform_init_ask(key, problem, params)


def init_tell(key, pop: Population, params: Params) -> State:
    """The state of the scored initial nests."""
    rank, _ = pareto.rank_and_crowding(pop.F, pop.cv)
    return State(key=key, pop=pop, rank=rank, iteration=jnp.zeros((), jnp.int32))


def cuckoo_ask(state: State, alpha, p_a):
    """The n children of one cuckoo iteration with Lévy step factor ``alpha`` (shared by
    MOCS and IMOCS): Lévy flight towards rank-1 partners, then discovery. → ``(U, state)``."""
    key, k_partner, k_levy, k_disc = jax.random.split(state.key, 4)
    U = state.pop.U
    partner = random_rank1_partner(k_partner, state.rank)
    moved = U + alpha * levy_step(k_levy, U.shape, U.dtype) * (U[partner] - U)
    moved = jnp.clip(moved, 0.0, 1.0)
    children = jnp.clip(discovery(k_disc, moved, p_a), 0.0, 1.0)
    return children, replace(state, key=key)


def ask(state: State, problem, params: Params):
    """The children of one MOCS iteration (fixed α₀). → ``(U, state)``."""
    return cuckoo_ask(state, params.alpha0, params.p_a)


def tell(state: State, children: Population, params: Params) -> State:
    """Merge the scored children with their parents; the best ``pop_size`` survive."""
    pop, rank = merge_and_survive(state.pop, children, params.pop_size)
    return State(key=state.key, pop=pop, rank=rank, iteration=state.iteration + 1)


def final_population(state: State) -> Population:
    """The population after the last iteration."""
    return state.pop


ALGORITHM = Algorithm(name="mocs", Params=Params, State=State, init_ask=init_ask, init_tell=init_tell, ask=ask,
                      tell=tell, final_population=final_population)
