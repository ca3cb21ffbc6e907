"""Running chunks: one chunk is one compiled, vmapped :func:`dockjax.optimize.optimize` call
scored against the fixed reference; backends run chunks here (:class:`LocalBackend`) or
on a Dask cluster (:class:`DaskBackend`)."""

from __future__ import annotations

import json
import logging
import signal
import time
from functools import lru_cache
from typing import Any, Callable, Iterator

import jax
import numpy as np

from .. import config, metrics
from ..instances import Instance
from ..metrics import nondominated_points
from ..optimize import optimize, refine_result
from ..problem import make_problem
from ..runtime import enable_compilation_cache
from .config import INDICATOR_COLUMNS, ChunkSpec

__all__ = ["run_chunk", "problem_of", "reference_of", "LocalBackend", "DaskBackend"]


@lru_cache(maxsize=None)
def problem_of(preset: str, n_control: int = config.N_FREE, instance_fields: str = ""):
    """The problem of a preset with ``n_control`` free control points
    (:func:`dockjax.problem.make_problem`), or of an instance laid over it
    (``instance_fields``: :meth:`dockjax.instances.Instance.identity` as JSON,
    :attr:`ChunkSpec.instance_fields`), made once per process."""
    if not instance_fields:
        return make_problem(preset, n_control=n_control)
    d = json.loads(instance_fields)
    return Instance(d.pop("name"), d).problem(preset, n_control)


def reference_of(references, instance: int) -> dict | None:
    """The reference of ``instance`` (-1: the preset's move) among ``references``: one
    reference dict, a sequence of them (one per instance), or None."""
    if references is None or isinstance(references, dict):
        return references
    return references[max(instance, 0)]


def run_chunk(spec: ChunkSpec, reference: dict | None = None, *, devices: int | None = None
              ) -> dict[str, np.ndarray]:
    """Run one chunk (one compiled vmapped call) and score its real runs.

    ``reference``: {"front", "ideal", "nadir", "hv_ref"} or None (no indicators; the pilot),
    or one such dict per instance of the study (the chunk's own is used).
    ``devices``: local devices the runs are sharded over (default all; see
    :func:`dockjax.optimize.optimize`: the numbers may depend on the count).
    Returns the chunk's table columns (one entry per real run), ``history`` (runs,
    iterations) the normalised hypervolume of each run's feasible set after every
    iteration, ``front_F`` and ``front_X`` (every run's distinct feasible non-dominated
    points, sorted by T, concatenated) and ``front_offsets``. A pure function of its
    arguments (apart from ``wall_s``); runs on a Dask worker as well.
    """
    t0 = time.perf_counter()
    hv_ref = scale = None
    reference = reference_of(reference, spec.instance)
    if reference is not None:
        ideal, nadir = np.asarray(reference["ideal"]), np.asarray(reference["nadir"])
        span = np.where(nadir > ideal, nadir - ideal, 1.0)
        hv_ref, scale = ideal + float(reference["hv_ref"]) * span, float(np.prod(span))
    problem = problem_of(spec.preset, spec.n_control, spec.instance_fields)
    r = optimize(spec.algorithm, problem, params=spec.params(), seeds=np.asarray(spec.seeds, np.int64),
                 n_iter=spec.iters, hv_ref=hv_ref, driver=spec.driver, devices=devices)
    if spec.refine_steps:
        r = refine_result(problem, r, steps=spec.refine_steps, rows=spec.refine_rows)
    n = spec.n_real
    fronts, front_X = [], []
    for i in range(n):  # each run's distinct feasible non-dominated points, sorted by T
        F, idx = nondominated_points(r.F[i][r.front[i]], return_index=True)
        fronts.append(F)
        front_X.append(r.X[i][r.front[i]][idx])
    out: dict[str, np.ndarray] = {
        "setting": np.asarray(spec.settings[:n], np.int64),
        "algorithm": np.asarray([spec.label] * n),
        "seed": np.asarray(spec.seeds[:n], np.int64),
        "round": np.full(n, spec.round, np.int64),
        "chunk": np.full(n, spec.index, np.int64),
        **({"instance": np.full(n, spec.instance, np.int64)} if spec.instance >= 0 else {}),
    }
    ext = np.array([[f[:, 0].min(), f[:, 0].max(), f[:, 1].min(), f[:, 1].max()] if len(f)
                    else [np.nan] * 4 for f in fronts]).reshape(n, 4)
    for j, k in enumerate(("T_min", "T_max", "jerk_min", "jerk_max")):
        out[k] = ext[:, j]
    if reference is not None:
        ind = metrics.indicators(r.F, r.front, reference["front"], hv_ref=float(reference["hv_ref"]),
                                 ideal=reference["ideal"], nadir=reference["nadir"])
        for k in INDICATOR_COLUMNS:
            out[k] = np.asarray(ind[k])[:n].astype(np.int64 if k == "ONVG" else np.float64)
        out["history"] = np.asarray(r.history[:n], np.float64) / scale
    out["front_F"] = np.concatenate([f for f in fronts] + [np.zeros((0, 2))]).astype(np.float64)
    out["front_X"] = np.concatenate(front_X + [np.zeros((0, r.X.shape[-1]))]).astype(np.float64)
    out["front_offsets"] = np.cumsum([0] + [len(f) for f in fronts]).astype(np.int64)
    out["wall_s"] = np.full(n, (time.perf_counter() - t0) / len(spec.seeds))
    return out


def _ignore_interrupts() -> None:
    """On a Dask worker process: ignore SIGINT (the client handles Ctrl-C)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


class LocalBackend:
    """Chunks one after another in this process."""

    def map(self, fn: Callable, specs: list[ChunkSpec], *args) -> Iterator[tuple[ChunkSpec, Any]]:
        for spec in specs:
            yield spec, fn(spec, *args)

    def close(self) -> None:
        pass


class DaskBackend:
    """Chunks as tasks of a Dask distributed cluster; results come back as they complete."""

    def __init__(self, scheduler: str | None, workers: int, processes: bool):
        from distributed import Client, LocalCluster

        self.cluster = None
        if scheduler:
            self.client = Client(scheduler, timeout="15s")
        else:
            self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=processes,
                                        dashboard_address=None, silence_logs=logging.ERROR)
            self.client = Client(self.cluster)
            if processes:
                cache = jax.config.jax_compilation_cache_dir
                if cache:  # the workers use this process's compilation cache, if it has one
                    self.client.run(enable_compilation_cache, cache)
                # Ctrl-C is the client's to handle (it closes the cluster): the workers, in its
                # process group, would each print a traceback
                self.client.run(_ignore_interrupts)

    def map(self, fn: Callable, specs: list[ChunkSpec], *args) -> Iterator[tuple[ChunkSpec, Any]]:
        from distributed import as_completed

        futures = {self.client.submit(fn, spec, *args, pure=False): spec for spec in specs}
        try:
            for fut in as_completed(futures):
                yield futures[fut], fut.result()
        finally:
            for fut in futures:
                fut.cancel()

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()
