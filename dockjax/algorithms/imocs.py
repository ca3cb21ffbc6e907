"""IMOCS: the paper's modified multi-objective cuckoo search (paper §4.3, Eqs. 31–33).

MOCS (:mod:`dockjax.algorithms.mocs`) with two changes:

* **Bernoulli chaotic initialisation** (Eqs. 31–32) with parameter ρ (default 0.4), one
  sequence per dimension, computed in float64 and guarded against the finite-precision
  collapse of the map (conventions §7; :func:`dockjax.algorithms.operators.bernoulli_population`);
* **adaptive step** (Eq. 33): ``α₀ = α_max (1 − ((iter − 1)/Maxiter)²)`` at iteration
  ``iter = 1..Maxiter``, ``α_max`` default 0.1 (conventions §7: the paper gives none; §4.3.2 asks
  for a step larger than MOCS's early on, decreasing to 0).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .. import config
from .base import Algorithm, param, pytree_dataclass
from .mocs import State, cuckoo_ask, final_population, init_tell, tell
from .operators import bernoulli_population

__all__ = ["Params", "State", "ALGORITHM", "init_ask", "init_tell", "ask", "tell", "final_population", "step_size"]


@pytree_dataclass
class Params:
    """IMOCS hyper-parameters (conventions §7 defaults)."""

    pop_size: int = param(config.POP_SIZE, symbol="n", lo=4, integer=True, is_static=True)
    """Number of nests n (evaluations per iteration)."""
    max_iter: int = param(config.N_ITER, symbol="Maxiter", lo=1, integer=True, is_static=True)
    """``Maxiter`` of Eq. 33 (the run length)."""
    rho: float = param(0.4, symbol="ρ", lo=0.0, hi=1.0, open_lo=True, open_hi=True)
    """Bernoulli map parameter ρ ∈ (0, 1) (Eq. 31)."""
    alpha_max: float = param(0.1, symbol="α_max", lo=0.0, open_lo=True)
    """Maximum step ``α_max`` > 0 (Eq. 33)."""
    p_a: float = param(0.25, symbol="p_a", lo=0.0, hi=1.0)
    """Discovery probability per component, in [0, 1]."""


def step_size(iteration, params: Params):
    """Eq. 33 at the 1-based iteration ``iter = iteration + 1`` (iteration = completed steps)."""
    frac = iteration / params.max_iter
    return params.alpha_max * (1.0 - frac * frac)


def init_ask(key, problem, params: Params):
    """Chaotic nests (Eqs. 31–32). → ``(U, key)``."""
    k_init, key = jax.random.split(key)
    dtype = jnp.zeros(()).dtype
    return bernoulli_population(k_init, params.pop_size, problem.n_var, params.rho, dtype), key


def ask(state: State, problem, params: Params):
    """The children of one IMOCS iteration (adaptive α₀ of Eq. 33). → ``(U, state)``."""
    alpha = step_size(state.iteration.astype(state.pop.U.dtype), params)
    return cuckoo_ask(state, alpha, params.p_a)


ALGORITHM = Algorithm(name="imocs", Params=Params, State=State, init_ask=init_ask, init_tell=init_tell, ask=ask,
                      tell=tell, final_population=final_population)
