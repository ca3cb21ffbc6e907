"""IMOCS: the paper's modified multi-objective cuckoo search (paper §4.3, Eqs. 31–33).

MOCS (:mod:`dockjax.algorithms.mocs`) with two changes:

* **Bernoulli chaotic initialisation** (Eqs. 31–32) with parameter ρ (default 0.4), one
  sequence per dimension, computed in float64 and guarded against the finite-precision
  collapse of the map (SPEC §7; :func:`dockjax.algorithms.operators.bernoulli_population`);
* **adaptive step** (Eq. 33): ``α₀ = α_max (1 − ((iter − 1)/Maxiter)²)`` at iteration
  ``iter = 1..Maxiter``, ``α_max`` default 0.1 (SPEC §7: the paper gives none; §4.3.2 asks
  for a step larger than MOCS's early on, decreasing to 0).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .base import check_range, evaluated_init, evaluated_step, pytree_dataclass, static, validate_common
from .mocs import State, cuckoo_ask, init_tell, tell
from .mocs import final_population as final_population
from .operators import bernoulli_population

__all__ = [
    "Params", "State", "init", "step", "init_ask", "init_tell", "ask", "tell", "validate",
    "final_population", "step_size",
]


@pytree_dataclass
class Params:
    """IMOCS hyper-parameters (SPEC §7 defaults)."""

    pop_size: int = static(150)
    max_iter: int = static(100)
    """``Maxiter`` of Eq. 33 (the run length)."""
    rho: float = 0.4
    """Bernoulli map parameter ρ ∈ (0, 1) (Eq. 31)."""
    alpha_max: float = 0.1
    """Maximum step ``α_max`` (Eq. 33)."""
    p_a: float = 0.25
    """Discovery probability per component."""


def validate(problem, params: Params) -> None:
    """Clear ValueErrors for bad hyper-parameters, before any compilation."""
    validate_common(params.pop_size, params.max_iter)
    check_range("rho", params.rho, 0.0, 1.0, open_lo=True, open_hi=True)
    check_range("alpha_max", params.alpha_max, 0.0, open_lo=True)
    check_range("p_a", params.p_a, 0.0, 1.0)


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


def init(key, problem, params: Params) -> State:
    """Chaotic nests (Eqs. 31–32), evaluated."""
    return evaluated_init(init_ask, init_tell, key, problem, params)


def step(state: State, problem, params: Params) -> State:
    """One IMOCS iteration: :func:`ask`, evaluate the n children, :func:`tell`."""
    return evaluated_step(ask, tell, state, problem, params)
