"""Runs of an optimiser: one algorithm, a batch of seeds (and of hyper-parameters), one
:class:`Result`.

:func:`optimize` runs in float64, by default as one compiled, vmapped call
(``driver="scan"``), or (``driver="host"``) as a Python loop of vmapped ``ask``, one call of
the problem's kernel on every run's candidates, and vmapped ``tell``, so that the kernel's
compiled program is shared by every algorithm. The runs are shared out over JAX's devices
(:mod:`dockjax.devices`). :func:`refine_result` is the memetic finish (gradient refinement
of every final population, :mod:`dockjax.refine`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import checks, config, pareto, prng
from . import devices as dev
from . import refine as refine_mod
from .algorithms import Algorithm, base, get, make_params
from .metrics import hypervolume_2d

__all__ = ["Result", "optimize", "refine_result"]


@dataclass
class Result:
    """Final populations of a batch of runs (float64 NumPy arrays).

    Batch axis first: ``X`` (runs, n, n_var) natural units, ``U`` unit box, ``F`` (runs, n, 2),
    ``G`` (runs, n, n_con), ``cv`` (runs, n), ``feasible`` (runs, n), ``front`` (runs, n) the
    feasible non-dominated members of each final set; ``history`` (runs, n_iter) the
    hypervolume of each run's current feasible set after every iteration (reference point
    ``hv_ref``, in objective units), if requested; ``seconds`` wall time incl. compile.
    """

    algorithm: str
    params: Any
    seeds: np.ndarray
    X: np.ndarray
    U: np.ndarray
    F: np.ndarray
    G: np.ndarray
    cv: np.ndarray
    feasible: np.ndarray
    front: np.ndarray
    history: np.ndarray | None = None
    hv_ref: np.ndarray | None = None
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return self.F.shape[0]

    def run(self, i: int) -> dict[str, np.ndarray]:
        """The i-th run's final set: X, F, G and its feasible non-dominated members."""
        m = self.front[i]
        return {"X": self.X[i], "F": self.F[i], "G": self.G[i], "front_X": self.X[i][m],
                "front_F": self.F[i][m]}

    def fronts(self) -> list[np.ndarray]:
        """Each run's feasible non-dominated objective vectors (distinct), sorted by T."""
        out = []
        for i in range(len(self)):
            f = np.unique(self.F[i][self.front[i]], axis=0)
            out.append(f[np.argsort(f[:, 0])])
        return out


def _front_mask(F, cv):
    rank = pareto.nondominated_rank_2d(F, cv) if F.shape[1] == 2 else pareto.nondominated_rank(F, cv)
    return (rank == 0) & (cv <= 0)


def optimize(
    algorithm: str | Algorithm,
    problem,
    *,
    seeds=(0,),
    pop_size: int = config.POP_SIZE,
    n_iter: int = config.N_ITER,
    hv_ref=None,
    batch_params: dict[str, Any] | None = None,
    refine_steps: int = 0,
    driver: str = "scan",
    devices: int | None = None,
    **hyper,
) -> Result:
    """Run ``algorithm`` on ``problem`` once per seed, all runs batched (vmapped) together.

    ``hyper`` sets hyper-parameters (e.g. ``rho=0.4, alpha_max=0.1``); ``batch_params``
    maps hyper-parameter names to arrays of length ``len(seeds)`` to vary them per run (a
    sweep in one call). ``hv_ref`` (2,) in objective units records the hypervolume of the
    current feasible set after every iteration. ``refine_steps > 0`` makes the run memetic:
    the final population of every run is polished by :func:`refine_result` (gradient
    refinement, :mod:`dockjax.refine`) and the algorithm is reported as ``"<name>+refine"``.
    ``driver``: ``"scan"`` (default) compiles the whole batch of runs into one program
    (:func:`dockjax.algorithms.base.run_batch`; the fastest per iteration); ``"host"``
    drives the iterations from Python around one shared call of the problem's kernel, whose
    compiled program is then reused by every algorithm on problems of the same settings
    (the fastest to compile when several algorithms run, as in a comparison; slower per
    iteration). Both give the same results up to rounding.
    ``devices``: how many of JAX's local devices the runs are spread over (default all of
    them, at most one per run; each device runs its share, :mod:`dockjax.devices`). With
    the scan driver and fewer runs than devices (one run, say), every device runs the whole
    batch and computes its share of the rows of each evaluation instead
    (:func:`dockjax.devices.share_rows`; docs/performance.md measures both layouts). A CPU
    process has one device unless it asks for more *before* its first JAX computation,
    e.g. ``jax.config.update("jax_num_cpu_devices", 2)``, as the CLIs do
    (:func:`dockjax.runtime.use_cpu_devices`).
    The runs are padded to a multiple of the device count (copies of the last run, dropped
    again); results equal the one-device results (a test compares them).
    ``Result.extra["devices"]`` records the count used, ``Result.extra["share_rows"]``
    whether the devices shared the rows of one batch rather than the runs.
    Bad input raises ValueError before compiling.
    """
    algo, seeds, params, batch_params, hv_ref = _check_request(algorithm, seeds, pop_size, n_iter, hv_ref,
                                                               batch_params, refine_steps, driver, hyper)
    # the scan driver shares each evaluation's rows when there are fewer runs than devices
    devs = dev.choose(devices, seeds.size if driver == "host" else max(seeds.size, pop_size))
    t0 = time.perf_counter()
    pop, front, trace, share = _run_on_devices(algo, problem, params, n_iter, seeds, batch_params, hv_ref, driver,
                                               devs)
    with jax.enable_x64(True):
        X = np.asarray(base.to_natural(problem, jnp.asarray(pop.U)))
    result = Result(
        algorithm=algo.name, params=params, seeds=seeds, X=X, U=pop.U,
        F=pop.F, G=pop.G, cv=pop.cv, feasible=pop.cv <= 0, front=front, history=trace,
        hv_ref=hv_ref, seconds=time.perf_counter() - t0, extra={"devices": len(devs), "share_rows": share},
    )
    return refine_result(problem, result, steps=int(refine_steps)) if refine_steps else result


def _check_request(algorithm, seeds, pop_size, n_iter, hv_ref, batch_params, refine_steps, driver, hyper):
    """:func:`optimize`'s arguments checked (ValueError before any compilation) and
    resolved: the algorithm, seeds (runs,), Params, per-run overrides, hv_ref."""
    algo = get(algorithm)
    checks.integer("pop_size", pop_size, 4)
    checks.integer("n_iter", n_iter, 1)
    checks.integer("refine_steps", refine_steps, 0)
    checks.choice("driver", driver, ("scan", "host"))
    seeds = np.atleast_1d(np.asarray(seeds))
    if seeds.ndim != 1 or seeds.size == 0 or not np.issubdtype(seeds.dtype, np.integer):
        raise ValueError(f"seeds must be a non-empty 1-D list of integers, got {seeds!r}")
    params = make_params(algo, pop_size, n_iter, **hyper)
    batch_params = dict(batch_params or {})
    for name, values in batch_params.items():
        values = np.asarray(values, dtype=np.float64)
        if values.shape != seeds.shape:
            raise ValueError(f"batch_params[{name!r}] must have one value per seed ({seeds.size}), "
                             f"got shape {values.shape}")
        make_params(algo, pop_size, n_iter, **{**hyper, name: values})
        batch_params[name] = values
    if hv_ref is not None:
        hv_ref = np.asarray(hv_ref, dtype=np.float64)
        if hv_ref.shape != (2,) or not np.all(np.isfinite(hv_ref)):
            raise ValueError(f"hv_ref must be two finite numbers, got {hv_ref!r}")
    return algo, seeds, params, batch_params, hv_ref


def _run_on_devices(algo, problem, params, n_iter, seeds, batch_params, hv_ref, driver, devs):
    """Every run on the devices ``devs`` by the chosen driver: the runs shared out (padded
    to a multiple of the device count with copies of the last run, dropped again), or, with
    fewer runs than devices, every device running all of them and sharing each
    evaluation's rows. → (final populations, front masks, history or None, shared rows?)."""
    share = len(devs) > seeds.size
    n_runs, pad = seeds.size, (0 if share else -seeds.size % len(devs))
    padded = lambda a: np.concatenate([a, np.repeat(a[-1:], pad, 0)])  # noqa: E731
    with jax.enable_x64(True):
        keys = jax.vmap(prng.key)(jnp.asarray(padded(seeds)))  # JAX's keys, drawn faster
        overrides = {k: jnp.asarray(padded(v)) for k, v in batch_params.items()}
        ref = None if hv_ref is None else jnp.asarray(hv_ref)
        where = dev.mesh(devs)
        if share:
            out = dev.replicated(_run_batch_scan, (algo, n_iter, len(devs)), where, keys, problem, params,
                                 overrides, ref)
        elif driver == "scan":
            keys, overrides = dev.put((keys, overrides), where)
            R, S = dev.SHARDED, dev.SAME
            out = dev.sharded(_run_batch_scan, (algo, n_iter, 1), where, (R, S, S, R, S), keys, problem, params,
                              overrides, ref)
        else:
            keys, overrides = dev.put((keys, overrides), where)
            out = _run_batch_host(algo, n_iter, keys, problem, params, overrides, ref, where)
        pop, front, trace = jax.tree_util.tree_map(lambda a: np.asarray(a)[:n_runs], out)
    return pop, front, trace, share


def refine_result(problem, result: Result, *, steps: int = 100, **options) -> Result:
    """The memetic finish: every member of every run's final population polished at once by
    :func:`dockjax.refine.refine` (jerk lowered at no longer T within the limits; an
    infeasible member repaired where possible), then each run's feasible non-dominated set
    recomputed. A refined member never is dominated by the one it replaces, so no run's
    front gets worse. ``options`` go to :func:`~dockjax.refine.refine` (learning_rate,
    penalty, margin). Returns a new :class:`Result` called ``"<algorithm>+refine"``; its
    ``history`` is the optimiser's (before refinement), ``extra`` holds ``refine_seconds``
    and ``improved`` (runs, n).
    """
    runs, n, d = result.X.shape
    t0 = time.perf_counter()
    r = refine_mod.refine(problem, result.X.reshape(runs * n, d), steps=steps, **options)
    X, F, G = (a.reshape(runs, n, -1) for a in (r.X, r.F, r.G))
    with jax.enable_x64(True):
        cv = jax.vmap(pareto.total_violation)(jnp.asarray(G))
        front = np.asarray(_front_batch(jnp.asarray(F), cv))
        cv = np.asarray(cv)
    lo, hi = np.asarray(problem.lower), np.asarray(problem.upper)
    U = np.where(r.improved.reshape(runs, n, 1), (X - lo) / (hi - lo), result.U)
    seconds = time.perf_counter() - t0
    return replace(
        result, algorithm=f"{result.algorithm}+refine", X=X, U=U, F=F, G=G, cv=cv, feasible=cv <= 0,
        front=front, seconds=result.seconds + seconds,
        extra={**result.extra, "refine_seconds": seconds, "refine_steps": steps,
               "improved": r.improved.reshape(runs, n)},
    )


_front_batch = jax.jit(jax.vmap(_front_mask))


# -- the batch drivers of :func:`optimize` ---------------------------------------------------
#
# "scan": :func:`base.run_batch`, one compiled program per (algorithm, n_iter, shapes).
# "host": one iteration of every run is three compiled calls: ``ask`` (vmapped over runs),
# the problem's kernel on all runs' candidates at once, ``tell`` (vmapped). The kernel is one
# program per (problem settings, rows) whatever the algorithm, so the four algorithms of a
# comparison — and problems that differ only in their arrays (presets) — share its
# compilation, the dear one; the per-algorithm programs are small. The result equals the
# scan driver's up to rounding (a test compares them).
# Both run on each device of a mesh for its share of the runs (:func:`dockjax.devices.sharded`).


@partial(jax.jit, static_argnames=("algo", "n_iter", "parts"))
def _run_batch_scan(algo, n_iter, parts, keys, problem, params, overrides, hv_ref):
    """The scan driver; ``parts > 1``: inside :func:`dockjax.devices.replicated` over that
    many devices, each scoring its share of the rows."""
    history = None if hv_ref is None else (lambda s: _history(algo, s, hv_ref))
    evaluate = None if parts == 1 else partial(_shared_evaluate, parts)
    state, trace = base.run_batch(algo, keys, problem, params, n_iter, overrides=overrides, history=history,
                                  evaluate=evaluate)
    pop = jax.vmap(algo.final_population)(state)
    return pop, jax.vmap(_front_mask)(pop.F, pop.cv), trace


def _shared_evaluate(parts, problem, U):
    """:func:`base.evaluate_runs` with each of ``parts`` devices scoring its share of the
    rows (:func:`dockjax.devices.share_rows`). Every device has U already: only the scores
    are gathered."""
    def scores(u):
        pop = base.evaluate_runs(problem, u)
        return pop.F, pop.G, pop.cv

    F, G, cv = dev.share_rows(scores, parts, U, axis=1)
    return base.Population(U=U, F=F, G=G, cv=cv)


def _with(params, ov):
    return replace(params, **ov) if ov else params


@partial(jax.jit, static_argnames="algo")
def _batch_init_ask(algo, keys, problem, params, overrides):
    return jax.vmap(lambda k, ov: algo.init_ask(k, problem, _with(params, ov)))(keys, overrides)


@partial(jax.jit, static_argnames="algo")
def _batch_ask(algo, state, problem, params, overrides):
    return jax.vmap(lambda s, ov: algo.ask(s, problem, _with(params, ov)))(state, overrides)


_batch_evaluate = jax.jit(base.evaluate_runs)


def _history(algo, state, hv_ref):
    if hv_ref is None:
        return None
    pop = algo.final_population(state)
    return hypervolume_2d(pop.F, pop.cv <= 0, hv_ref)


@partial(jax.jit, static_argnames="algo")
def _batch_init_tell(algo, keys, pop, params, overrides):
    return jax.vmap(lambda k, p, ov: algo.init_tell(k, p, _with(params, ov)))(keys, pop, overrides)


@partial(jax.jit, static_argnames="algo")
def _batch_tell(algo, state, pop, params, overrides, hv_ref):
    def one(s, p, ov):
        s = algo.tell(s, p, _with(params, ov))
        return s, _history(algo, s, hv_ref)

    return jax.vmap(one)(state, pop, overrides)


@partial(jax.jit, static_argnames="algo")
def _batch_final(algo, state):
    pop = jax.vmap(algo.final_population)(state)
    return pop, jax.vmap(_front_mask)(pop.F, pop.cv)


def _run_batch_host(algo, n_iter, keys, problem, params, overrides, hv_ref, where=None):
    """Every run of a batch (keys, per-run hyper-parameter overrides) for ``n_iter``
    iterations, driven from Python; each device of the mesh ``where`` (None: one device)
    runs its share of the runs. → (final populations, front masks, history or None)."""
    R, S = dev.SHARDED, dev.SAME
    U, key0 = dev.sharded(_batch_init_ask, (algo,), where, (R, S, S, R), keys, problem, params, overrides)
    pop = dev.sharded(_batch_evaluate, (), where, (S, R), problem, U)
    state = dev.sharded(_batch_init_tell, (algo,), where, (R, R, S, R), key0, pop, params, overrides)
    trace = []
    for _ in range(n_iter):
        U, state = dev.sharded(_batch_ask, (algo,), where, (R, S, S, R), state, problem, params, overrides)
        pop = dev.sharded(_batch_evaluate, (), where, (S, R), problem, U)
        state, hv = dev.sharded(_batch_tell, (algo,), where, (R, R, S, R, S), state, pop, params, overrides, hv_ref)
        trace.append(hv)
    pop, front = dev.sharded(_batch_final, (algo,), where, (R,), state)
    return pop, front, (None if hv_ref is None else jnp.stack(trace, axis=1))
