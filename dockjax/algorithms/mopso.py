"""MOPSO (Coello Coello, Toscano Pulido & Salazar Lechuga 2004; conventions §7) as a JAX program.

C. A. Coello Coello, G. Toscano Pulido and M. Salazar Lechuga, "Handling multiple
objectives with particle swarm optimization", IEEE Transactions on Evolutionary
Computation 8(3):256–279, 2004, https://doi.org/10.1109/TEVC.2004.826067.

One iteration (exactly ``pop_size`` evaluations, conventions §7's equal-budget rule):

1. leaders: the adaptive hypergrid (``n_div`` = 30 divisions per objective) is laid over the
   repository's bounding box; each particle takes a leader by roulette over the occupied
   hypercubes with fitness ``10 / (members in the cube)``, then a member of that cube
   uniformly;
2. flight: ``v ← w v + r1 (pbest − x) + r2 (leader − x)`` (``w`` = 0.4, ``r1, r2 ~ U(0, 1)``
   per component), ``x ← x + v``; a component that leaves the unit box is clamped to the
   bound and its velocity reversed;
3. mutation (rate ``p_M`` = 0.5) while ``t < T_max p_M``: with probability
   ``(1 − t/(T_max p_M))^1.5`` a particle resamples one random dimension uniformly in
   ``x ± (1 − t/(T_max p_M))^1.5 / 2``, clipped to the box (``t`` = completed iterations,
   ``T_max`` = ``max_iter``);
4. the n particles are evaluated; the repository absorbs them (below); each personal best
   is replaced if the new position constrained-dominates it, kept if it dominates the new
   position, else replaced with probability ½.

The repository has a fixed capacity of ``pop_size`` slots and a validity mask
``archive_valid``. An update merges the repository's valid members with the n new
particles (2n candidates), keeps those that no other candidate constrained-dominates
(Deb's rule, :func:`dockjax.pareto.constrained_dominance`) and drops exact duplicates in
objective space (the older copy stays). If more than ``pop_size`` remain, the grid is laid
over them and members are removed from the most crowded hypercube first, one at a time,
until ``pop_size`` remain. This is done in one sort: within its cube each member gets its
position in index order (repository members before newcomers, each group in slot order);
removing from the most crowded cube always removes a member of largest position, so the
survivors are the first ``pop_size`` by (position, index). The deterministic tie rules:
within a cube the member of largest index goes first (so a newcomer in a crowded cube is
rejected before an incumbent, as in the paper's "enters only if its cube is less crowded");
between equally crowded cubes, the one whose last member has the larger index loses first.

Departures from the paper, all for fixed shapes in a compiled loop: particles enter the
repository as a batch, not one at a time; the grid is recomputed at every update from the
current members' bounds (the paper recomputes it only when a newcomer falls outside); the
member removed from a crowded cube is chosen by index rather than at random; the leader
roulette is sampled in one draw per particle with member weights ``1/c²`` (``c`` its cube's
count), which gives exactly the two-stage probabilities ``(10/c) / Σ (10/c') · 1/c``.
"""

from __future__ import annotations

from dataclasses import replace

import jax
import jax.numpy as jnp

from .. import config, pareto
from .base import Algorithm, Population, param, pytree_dataclass, uniform_init_ask

__all__ = [
    "Params", "State", "ALGORITHM", "init_ask", "init_tell", "ask", "tell", "final_population", "grid_coordinates",
    "update_repository",
]


@pytree_dataclass
class Params:
    """MOPSO hyper-parameters (conventions §7 defaults). ``w`` and ``mutation_rate`` may be traced."""

    pop_size: int = param(config.POP_SIZE, symbol="N", lo=4, integer=True, is_static=True)
    """Number of particles, and capacity of the repository."""
    max_iter: int = param(config.N_ITER, symbol="T_max", lo=1, integer=True, is_static=True)
    """T_max of the mutation schedule (set it to the number of iterations run)."""
    w: float = param(0.4, symbol="w", lo=0.0, hi=1.0)
    """Inertia weight, in [0, 1]."""
    n_div: int = param(30, symbol="divisions", lo=1, integer=True, is_static=True)
    """Hypergrid divisions per objective."""
    mutation_rate: float = param(0.5, symbol="p_M", lo=0.0, hi=1.0)
    """Mutation rate p_M in [0, 1]: mutation acts during the first ``p_M · max_iter``
    iterations (0 disables it)."""


@pytree_dataclass
class State:
    key: jax.Array
    pop: Population
    """The particles' current positions and scores, (pop_size, ·)."""
    velocity: jax.Array
    """(pop_size, n_var) velocities, unit-box units per iteration."""
    pbest: Population
    """Each particle's personal best, (pop_size, ·)."""
    repository: Population
    """External repository, (pop_size, ·) slots; slots where ``archive_valid`` is False hold
    F = G = cv = +inf (their U is stale)."""
    archive_valid: jax.Array
    """(pop_size,) bool, which repository slots hold members."""
    iteration: jax.Array
    """Completed iterations (int32)."""


def grid_coordinates(F: jax.Array, valid: jax.Array, n_div: int) -> jax.Array:
    """Hypercube of each row of F on a grid of ``n_div`` divisions per objective spanning
    the valid rows' bounding box. An objective with zero range puts everyone in cell 0.

    F: (n, m), valid: (n,) bool → (n, m) int32 in [0, n_div).
    """
    lo = jnp.min(jnp.where(valid[:, None], F, jnp.inf), axis=0)
    hi = jnp.max(jnp.where(valid[:, None], F, -jnp.inf), axis=0)
    width = hi - lo
    ok = jnp.isfinite(width) & (width > 0)
    scaled = jnp.where(ok, (F - lo) / jnp.where(ok, width, 1.0), 0.0)
    scaled = jnp.where(valid[:, None], scaled, 0.0)
    return jnp.clip(jnp.floor(scaled * n_div), 0, n_div - 1).astype(jnp.int32)


def _same_cube(coords: jax.Array, valid: jax.Array) -> jax.Array:
    """(n, n) bool: rows i, j valid and in the same hypercube."""
    same = jnp.all(coords[:, None, :] == coords[None, :, :], axis=-1)
    return same & valid[:, None] & valid[None, :]


def _mask_population(pop: Population, valid: jax.Array) -> Population:
    inf = jnp.asarray(jnp.inf, pop.F.dtype)
    return Population(
        U=pop.U,
        F=jnp.where(valid[:, None], pop.F, inf),
        G=jnp.where(valid[:, None], pop.G, inf),
        cv=jnp.where(valid, pop.cv, inf),
    )


def update_repository(
    repository: Population, archive_valid: jax.Array, new: Population, n_div: int
) -> tuple[Population, jax.Array]:
    """Absorb ``new`` into the repository (see the module docstring). Fixed shapes.

    Args:
        repository: (k, ·) slots; archive_valid: (k,) bool.
        new: (n, ·) newly evaluated particles.
        n_div: grid divisions per objective (static).

    Returns:
        The new repository (k slots, members first in candidate order, invalid slots
        padded with +inf scores) and its (k,) validity mask.
    """
    k = archive_valid.shape[0]
    cand = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b], axis=0), repository, new)
    valid = jnp.concatenate([archive_valid, jnp.ones(new.cv.shape, bool)])
    total = valid.shape[0]
    index = jnp.arange(total)

    dominated = jnp.any(pareto.constrained_dominance(cand.F, cand.cv) & valid[:, None], axis=0)
    keep = valid & ~dominated
    same = jnp.all(cand.F[:, None, :] == cand.F[None, :, :], axis=-1) & (
        cand.cv[:, None] == cand.cv[None, :]
    )
    duplicate = jnp.any(same & keep[:, None] & (index[:, None] < index[None, :]), axis=0)
    keep = keep & ~duplicate

    coords = grid_coordinates(cand.F, keep, n_div)
    same_cube = _same_cube(coords, keep)
    position = jnp.sum(same_cube & (index[None, :] < index[:, None]), axis=1)  # earlier cube mates
    position = jnp.where(keep, position, total)  # non-members sort last
    chosen = pareto.lexsort((position,))[:k]  # ties by index
    chosen_valid = position[chosen] < total
    # Present the chosen members in candidate order (incumbents keep their order), then padding.
    order = pareto.lexsort((jnp.where(chosen_valid, chosen, chosen + total),))
    chosen, chosen_valid = chosen[order], chosen_valid[order]
    repo = jax.tree_util.tree_map(lambda a: a[chosen], cand)
    return _mask_population(repo, chosen_valid), chosen_valid


def _select_leaders(key, repository: Population, archive_valid: jax.Array, n: int, n_div: int):
    """(n,) repository slot of each particle's leader: roulette over occupied cubes with
    fitness 10/count, then a uniform member, sampled as member weights 1/count²."""
    coords = grid_coordinates(repository.F, archive_valid, n_div)
    count = jnp.sum(_same_cube(coords, archive_valid), axis=1)
    logits = jnp.where(archive_valid, -2.0 * jnp.log(jnp.maximum(count, 1)), -jnp.inf)
    return jax.random.categorical(key, logits, shape=(n,))


def _mutate(key, U, t, max_iter: int, p_m):
    """Coello et al.'s decaying mutation on positions U (n, d) at iteration t."""
    n, d = U.shape
    k_apply, k_dim, k_val = jax.random.split(key, 3)
    horizon = max_iter * p_m
    frac = jnp.where(horizon > 0, t / jnp.where(horizon > 0, horizon, 1.0), 1.0)
    active = t < horizon
    strength = jnp.maximum(1.0 - frac, 0.0) ** 1.5
    apply = active & (jax.random.uniform(k_apply, (n,), U.dtype) < strength)
    dim = jax.random.randint(k_dim, (n,), 0, d)
    x = U[jnp.arange(n), dim]
    r = strength / 2.0
    lo, hi = jnp.maximum(x - r, 0.0), jnp.minimum(x + r, 1.0)
    new = lo + jax.random.uniform(k_val, (n,), U.dtype) * (hi - lo)
    hit = apply[:, None] & (jnp.arange(d)[None, :] == dim[:, None])
    return jnp.where(hit, new[:, None], U)


def _pbest_update(key, pbest: Population, new: Population) -> Population:
    """Replace if the new position constrained-dominates, keep if dominated, else a coin."""

    def pair(fa, ca, fb, cb):
        D = pareto.constrained_dominance(jnp.stack([fa, fb]), jnp.stack([ca, cb]))
        return D[1, 0], D[0, 1]

    new_wins, old_wins = jax.vmap(pair)(pbest.F, pbest.cv, new.F, new.cv)
    coin = jax.random.bernoulli(key, 0.5, new.cv.shape)
    take = new_wins | (~old_wins & coin)
    return jax.tree_util.tree_map(
        lambda a, b: jnp.where(take.reshape((-1,) + (1,) * (a.ndim - 1)), b, a), pbest, new
    )


def init_ask(key, problem, params: Params):
    """Uniform random particles in the unit box. → ``(U, key)``."""
    return uniform_init_ask(key, problem, params)


def init_tell(key, pop: Population, params: Params) -> State:
    """The scored particles at rest; pbest = the particles; the repository their
    constrained non-dominated members."""
    repo, valid = update_repository(pop, jnp.zeros((params.pop_size,), bool), pop, params.n_div)
    return State(
        key=key,
        pop=pop,
        velocity=jnp.zeros_like(pop.U),
        pbest=pop,
        repository=repo,
        archive_valid=valid,
        iteration=jnp.zeros((), jnp.int32),
    )


def ask(state: State, problem, params: Params):
    """The particles' next positions: leaders, flight, bounds, mutation. → ``(U, state)``
    (the state carries the new velocities)."""
    key, k_lead, k_r, k_mut = jax.random.split(state.key, 4)
    n = params.pop_size
    X = state.pop.U
    leader = state.repository.U[_select_leaders(k_lead, state.repository, state.archive_valid,
                                                n, params.n_div)]
    r1, r2 = jax.random.uniform(k_r, (2,) + X.shape, X.dtype)
    v = params.w * state.velocity + r1 * (state.pbest.U - X) + r2 * (leader - X)
    X = X + v
    out = (X < 0.0) | (X > 1.0)
    X = jnp.clip(X, 0.0, 1.0)
    v = jnp.where(out, -v, v)
    X = _mutate(k_mut, X, state.iteration.astype(X.dtype), params.max_iter, params.mutation_rate)
    return X, replace(state, key=key, velocity=v)


def tell(state: State, pop: Population, params: Params) -> State:
    """The scored particles update their personal bests and the repository."""
    key, k_pb = jax.random.split(state.key)
    repo, valid = update_repository(state.repository, state.archive_valid, pop, params.n_div)
    return State(
        key=key,
        pop=pop,
        velocity=state.velocity,
        pbest=_pbest_update(k_pb, state.pbest, pop),
        repository=repo,
        archive_valid=valid,
        iteration=state.iteration + 1,
    )


def final_population(state: State) -> Population:
    """The repository, the algorithm's output: (pop_size, ·) slots whose members are
    mutually non-dominated (constrained dominance). Empty slots (``~state.archive_valid``)
    carry F = G = cv = +inf, so they count as infeasible and are dominated by every real
    candidate: feasibility masks and non-dominated ranking drop them."""
    return state.repository


ALGORITHM = Algorithm(name="mopso", Params=Params, State=State, init_ask=init_ask, init_tell=init_tell, ask=ask,
                      tell=tell, final_population=final_population)
