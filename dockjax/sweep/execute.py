"""Running chunks: one chunk is one compiled, vmapped :func:`dockjax.optimize.optimize` call
scored against the fixed reference; backends run chunks here (:class:`LocalBackend`) or
on a Dask cluster (:class:`DaskBackend`)."""

from __future__ import annotations

import logging
import time
from functools import lru_cache
from typing import Any, Callable, Iterator

import numpy as np

from .. import metrics
from ..optimize import optimize
from ..problem import make_problem
from ..runtime import enable_compilation_cache
from .config import INDICATOR_COLUMNS, ChunkSpec

__all__ = ["run_chunk", "LocalBackend", "DaskBackend"]


@lru_cache(maxsize=None)
def _problem(preset: str):
    return make_problem(preset)


def run_chunk(spec: ChunkSpec, reference: dict | None = None, *, devices: int | None = None
              ) -> dict[str, np.ndarray]:
    """Run one chunk (one compiled vmapped call) and score its real runs.

    ``reference``: {"front", "ideal", "nadir", "hv_ref"} or None (no indicators; the pilot).
    ``devices``: local devices the runs are sharded over (default all; see
    :func:`dockjax.optimize.optimize`; the results do not depend on it).
    Returns the chunk's table columns (one entry per real run), ``history`` (runs,
    iterations) the normalised hypervolume of each run's feasible set after every
    iteration, ``front_F`` (every run's distinct feasible non-dominated F, concatenated) and
    ``front_offsets``. A pure function of its arguments (apart from ``wall_s``); runs on a
    Dask worker as well.
    """
    t0 = time.perf_counter()
    hv_ref = scale = None
    if reference is not None:
        ideal, nadir = np.asarray(reference["ideal"]), np.asarray(reference["nadir"])
        span = np.where(nadir > ideal, nadir - ideal, 1.0)
        hv_ref, scale = ideal + float(reference["hv_ref"]) * span, float(np.prod(span))
    r = optimize(spec.algorithm, _problem(spec.preset), params=spec.params(), seeds=np.asarray(spec.seeds, np.int64),
                 n_iter=spec.iters, hv_ref=hv_ref, refine_steps=spec.refine_steps, devices=devices)
    n = spec.n_real
    fronts = r.fronts()[:n]
    out: dict[str, np.ndarray] = {
        "setting": np.asarray(spec.settings[:n], np.int64),
        "algorithm": np.asarray([spec.label] * n),
        "seed": np.asarray(spec.seeds[:n], np.int64),
        "round": np.full(n, spec.round, np.int64),
        "chunk": np.full(n, spec.index, np.int64),
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
    out["front_offsets"] = np.cumsum([0] + [len(f) for f in fronts]).astype(np.int64)
    out["wall_s"] = np.full(n, (time.perf_counter() - t0) / len(spec.seeds))
    return out


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
                self.client.run(enable_compilation_cache)

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
