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
    ``hv_ref``, in objective units), if requested; ``params`` the algorithm's ``Params``
    with every run's hyper-parameters (each traced leaf (runs,); :meth:`params_of` gives
    one run's); ``seconds`` wall time incl. compile.
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

    def __repr__(self) -> str:
        runs, n = self.F.shape[:2]
        sizes = self.front.sum(axis=1)
        feasible = int(self.feasible.sum())
        return (f"Result({self.algorithm}: {runs} run{'s' * (runs != 1)} of {n} candidates, seeds "
                f"{_span(self.seeds)}; {feasible} feasible members, fronts of {int(sizes.min())}-{int(sizes.max())} "
                f"points; {self.seconds:.2f} s)")

    def params_of(self, i: int) -> Any:
        """The ``Params`` run ``i`` ran with (its hyper-parameters as plain numbers)."""
        return base.params_at(self.params, i)

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


def _span(seeds: np.ndarray) -> str:
    """``0..30`` for consecutive seeds, else the list (shortened)."""
    s = [int(v) for v in seeds]
    if len(s) > 1 and s == list(range(s[0], s[0] + len(s))):
        return f"{s[0]}..{s[-1]}"
    return str(s) if len(s) <= 6 else f"[{s[0]}, {s[1]}, ..., {s[-1]}]"


def _front_mask(F, cv):
    rank = pareto.nondominated_rank_2d(F, cv) if F.shape[1] == 2 else pareto.nondominated_rank(F, cv)
    return (rank == 0) & (cv <= 0)


def optimize(
    algorithm: str | Algorithm,
    problem,
    *,
    params: Any = None,
    seeds=(0,),
    pop_size: int | None = None,
    n_iter: int | None = None,
    hv_ref=None,
    refine_steps: int = 0,
    driver: str = "scan",
    devices: int | None = None,
    **hyper,
) -> Result:
    """Run ``algorithm`` on ``problem`` once per seed, all runs batched (vmapped) together.

    ``params``: the algorithm's ``Params`` pytree (e.g. ``imocs.Params(rho=0.4)``, or
    :func:`dockjax.algorithms.make_params`); a leaf of shape (runs,) gives every run its
    own value (a sweep in one call, :func:`dockjax.algorithms.base.stack_params`), a
    scalar is shared. Instead of ``params``, hyper-parameters may be given as keywords
    (``rho=0.4``, or ``rho=[0.3, 0.5]`` for one value per run) with ``pop_size`` (default
    150) and ``n_iter`` (default 100), which also sets ``max_iter`` where the algorithm
    has one. With ``params``, ``n_iter`` defaults to its ``max_iter`` (else 100).
    ``hv_ref`` (2,) in objective units records the hypervolume of the
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
    ``Result.params`` holds every run's hyper-parameters (leaves of shape (runs,)),
    ``Result.extra["devices"]`` the device count used, ``Result.extra["share_rows"]``
    whether the devices shared the rows of one batch rather than the runs.
    Bad input raises ValueError before compiling.
    """
    algo, seeds, params, n_iter, hv_ref = _check_request(algorithm, problem, params, seeds, pop_size, n_iter, hv_ref,
                                                         refine_steps, driver, hyper)
    # the scan driver shares each evaluation's rows when there are fewer runs than devices
    devs = dev.choose(devices, seeds.size if driver == "host" else max(seeds.size, params.pop_size))
    t0 = time.perf_counter()
    pop, front, trace, share = _run_on_devices(algo, problem, params, n_iter, seeds, hv_ref, driver, devs)
    with jax.enable_x64(True):
        X = np.asarray(base.to_natural(problem, jnp.asarray(pop.U)))
    result = Result(
        algorithm=algo.name, params=base.broadcast_params(params, seeds.size), seeds=seeds, X=X, U=pop.U,
        F=pop.F, G=pop.G, cv=pop.cv, feasible=pop.cv <= 0, front=front, history=trace,
        hv_ref=hv_ref, seconds=time.perf_counter() - t0, extra={"devices": len(devs), "share_rows": share},
    )
    return refine_result(problem, result, steps=int(refine_steps)) if refine_steps else result


def _check_request(algorithm, problem, params, seeds, pop_size, n_iter, hv_ref, refine_steps, driver, hyper):
    """:func:`optimize`'s arguments checked (ValueError before any compilation) and
    resolved: the algorithm, seeds (runs,), Params, the iteration count, hv_ref."""
    algo = get(algorithm)
    for name in ("n_var", "n_obj", "n_con", "lower", "upper", "evaluate_jax"):
        if not hasattr(problem, name):
            raise ValueError(f"problem must be a problem object such as DockingProblem() (it has no {name!r}), "
                             f"got {problem!r}")
    checks.optional_integer("pop_size", pop_size, 4)
    checks.optional_integer("n_iter", n_iter, 1)
    checks.integer("refine_steps", refine_steps, 0)
    checks.choice("driver", driver, ("scan", "host"))
    seeds = np.atleast_1d(np.asarray(seeds))
    if seeds.ndim != 1 or seeds.size == 0 or not np.issubdtype(seeds.dtype, np.integer):
        raise ValueError(f"seeds must be a non-empty 1-D list of integers, got {seeds!r}")
    if params is None:
        n_iter = config.N_ITER if n_iter is None else n_iter
        params = make_params(algo, config.POP_SIZE if pop_size is None else pop_size, n_iter, **hyper)
    else:
        if not isinstance(params, algo.Params):
            raise ValueError(f"params must be {algo.name}'s Params, got {type(params).__module__}."
                             f"{type(params).__name__}")
        if hyper:
            raise ValueError(f"give the hyper-parameters in params or as keywords, not both (got {sorted(hyper)})")
        if pop_size is not None and pop_size != params.pop_size:
            raise ValueError(f"pop_size {pop_size} differs from params.pop_size {params.pop_size}")
        params = base.as_params(params)
        n_iter = n_iter if n_iter is not None else getattr(params, "max_iter", config.N_ITER)
    runs = base.n_runs(params)
    if runs is not None and runs != seeds.size:
        raise ValueError(f"the per-run hyper-parameters have {runs} values, not one per seed ({seeds.size})")
    if hv_ref is not None:
        hv_ref = np.asarray(hv_ref, dtype=np.float64)
        if hv_ref.shape != (2,) or not np.all(np.isfinite(hv_ref)):
            raise ValueError(f"hv_ref must be two finite numbers, got {hv_ref!r}")
    return algo, seeds, params, int(n_iter), hv_ref


def _run_on_devices(algo, problem, params, n_iter, seeds, hv_ref, driver, devs):
    """Every run on the devices ``devs`` by the chosen driver: the runs shared out (padded
    to a multiple of the device count with copies of the last run, dropped again), or, with
    fewer runs than devices, every device running all of them and sharing each
    evaluation's rows. → (final populations, front masks, history or None, shared rows?)."""
    share = len(devs) > seeds.size
    n_runs, pad = seeds.size, (0 if share else -seeds.size % len(devs))
    padded = lambda a: np.concatenate([a, np.repeat(a[-1:], pad, 0)])  # noqa: E731
    with jax.enable_x64(True):
        keys = jax.vmap(prng.key)(jnp.asarray(padded(seeds)))  # JAX's keys, drawn faster
        params = jax.tree_util.tree_map(lambda a: jnp.asarray(padded(np.asarray(a))) if np.ndim(a) else a, params)
        ref = None if hv_ref is None else jnp.asarray(hv_ref)
        where = dev.mesh(devs)
        if share:
            out = dev.replicated(_run_batch_scan, (algo, n_iter, len(devs)), where, keys, problem, params, ref)
        else:
            keys = dev.put(keys, where)
            params = jax.tree_util.tree_map(lambda a: dev.put(a, where) if np.ndim(a) else a, params)
            specs = jax.tree_util.tree_map(lambda a: dev.SHARDED if np.ndim(a) else dev.SAME, params)
            if driver == "scan":
                out = dev.sharded(_run_batch_scan, (algo, n_iter, 1), where, (dev.SHARDED, dev.SAME, specs, dev.SAME),
                                  keys, problem, params, ref)
            else:
                out = _run_batch_host(algo, n_iter, keys, problem, params, specs, ref, where)
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
def _run_batch_scan(algo, n_iter, parts, keys, problem, params, hv_ref):
    """The scan driver; ``parts > 1``: inside :func:`dockjax.devices.replicated` over that
    many devices, each scoring its share of the rows."""
    history = None if hv_ref is None else (lambda s: _history(algo, s, hv_ref))
    evaluate = None if parts == 1 else partial(_shared_evaluate, parts)
    state, trace = base.run_batch(algo, keys, problem, params, n_iter, history=history, evaluate=evaluate)
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


@partial(jax.jit, static_argnames="algo")
def _batch_init_ask(algo, keys, problem, params):
    return jax.vmap(lambda k, p: algo.init_ask(k, problem, p), in_axes=(0, base.run_axes(params)))(keys, params)


@partial(jax.jit, static_argnames="algo")
def _batch_ask(algo, state, problem, params):
    return jax.vmap(lambda s, p: algo.ask(s, problem, p), in_axes=(0, base.run_axes(params)))(state, params)


_batch_evaluate = jax.jit(base.evaluate_runs)


def _history(algo, state, hv_ref):
    if hv_ref is None:
        return None
    pop = algo.final_population(state)
    return hypervolume_2d(pop.F, pop.cv <= 0, hv_ref)


@partial(jax.jit, static_argnames="algo")
def _batch_init_tell(algo, keys, pop, params):
    return jax.vmap(lambda k, q, p: algo.init_tell(k, q, p), in_axes=(0, 0, base.run_axes(params)))(keys, pop, params)


@partial(jax.jit, static_argnames="algo")
def _batch_tell(algo, state, pop, params, hv_ref):
    def one(s, q, p):
        s = algo.tell(s, q, p)
        return s, _history(algo, s, hv_ref)

    return jax.vmap(one, in_axes=(0, 0, base.run_axes(params)))(state, pop, params)


@partial(jax.jit, static_argnames="algo")
def _batch_final(algo, state):
    pop = jax.vmap(algo.final_population)(state)
    return pop, jax.vmap(_front_mask)(pop.F, pop.cv)


def _run_batch_host(algo, n_iter, keys, problem, params, specs, hv_ref, where=None):
    """Every run of a batch (keys, ``params`` whose leaves may carry a run axis, ``specs``
    their placement) for ``n_iter`` iterations, driven from Python; each device of the mesh
    ``where`` (None: one device) runs its share of the runs. → (final populations, front
    masks, history or None)."""
    R, S = dev.SHARDED, dev.SAME
    U, key0 = dev.sharded(_batch_init_ask, (algo,), where, (R, S, specs), keys, problem, params)
    pop = dev.sharded(_batch_evaluate, (), where, (S, R), problem, U)
    state = dev.sharded(_batch_init_tell, (algo,), where, (R, R, specs), key0, pop, params)
    trace = []
    for _ in range(n_iter):
        U, state = dev.sharded(_batch_ask, (algo,), where, (R, S, specs), state, problem, params)
        pop = dev.sharded(_batch_evaluate, (), where, (S, R), problem, U)
        state, hv = dev.sharded(_batch_tell, (algo,), where, (R, R, specs, S), state, pop, params, hv_ref)
        trace.append(hv)
    pop, front = dev.sharded(_batch_final, (algo,), where, (R,), state)
    return pop, front, (None if hv_ref is None else jnp.stack(trace, axis=1))
