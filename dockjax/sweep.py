"""Hyper-parameter sweeps that never lose work (``experiments/sweep.py``).

A sweep runs one algorithm over a grid of population sizes × ρ × α_max × seeds on one
problem preset, scores every run against a reference front fixed before the first run
(SPEC §8), and writes everything into one results folder::

    OUT/
      config.json            the sweep's identity (grid, seeds, iterations, chunk size, preset,
                             algorithm, reference definition) + informational versions
      reference.npz          front (r, 2), ideal, nadir, hv_ref: the fixed reference and
                             normalisation of every indicator in the folder
      chunks/chunk-00012.npz one file per finished chunk: a tidy table (one row per run) and
                             each run's final front (feasible non-dominated F, distinct)
      runs.csv               every run, sorted by (pop, rho, alpha_max, seed)
      summary.csv / .md      per setting: median and IQR of HV, medians of IGD, IGD+, GD,
                             SP, ONVG, sorted by median HV (best first)
      fronts.npz             every run's final front (F concatenated, offsets, run keys)
      heatmap_hv_pop150.png  median HV over ρ × α_max, one per population size (IMOCS)
      hv_vs_pop.png          HV against population size, one line per (ρ, α_max)
      fronts_best_worst.png  every seed's front of the best and the worst setting

Execution. Runs are grouped by population size and cut into chunks of at most ``chunk``
runs (balanced: ``ceil(n / ceil(n / chunk))`` runs each, so a population size has one
chunk shape). One chunk is one compiled, vmapped :func:`dockjax.algorithms.optimize` call
(per-run seeds and, for IMOCS, per-run ρ and α_max via ``batch_params``); a short chunk is
padded with repeats of its own runs, which are dropped. So there is one compilation per
population size (per process). Both cores: the CLI asks JAX for one CPU device per usable
core (``--devices``) and the chunk's runs are sharded over them (``shard_map``: each
device runs its share, no communication; bit-identical results), ~1.9× the throughput of
one device on this 2-core host (the kernel's cache-sized passes are too small for XLA's
intra-op threads); worker processes pinned to one core each were no faster and compile
once each (README).

Never losing work. Each finished chunk is written atomically (temporary file in the same
folder, fsync, ``os.replace``), so a chunk file is either complete or absent, whatever
kills the process (Ctrl-C, ``kill -9``, power loss after the rename). Re-running the same
command resumes: ``config.json`` must match (else exit 2), ``reference.npz`` is reused,
chunk files that exist are loaded, not recomputed, and only the missing chunks run. The
assignment of runs to chunks is a function of the configuration alone (that is why the
chunk size is part of it: a run's numbers are reproduced bit for bit only in the same
compiled shape), so the final ``runs.csv`` of an interrupted and resumed sweep is identical
to an uninterrupted one's except for the ``wall_s`` column.

Reference front (SPEC §8: in a sweep, scored one run at a time, the reference and the
normalisation are fixed before the first run and stored with the results). By default a
deterministic *pilot*: one chunk of runs of the same algorithm at its default
hyper-parameters (IMOCS: ρ = 0.4, α_max = 0.1), the largest population size and the
sweep's iterations, seeds 1_000_000, 1_000_001, ... (disjoint from the sweep's); the
reference front is the non-dominated union of their final feasible sets, and ideal / nadir
(the normalisation) are its per-objective minimum / maximum. It has the shape of a sweep
chunk, so it costs no extra compilation. ``--reference-front FILE`` (.npz or .csv, two
columns T, jerk) uses a stored best-known front instead. Because the pilot is no better
than a good run, runs can dominate parts of it (GD and IGD+ then approach 0 and HV can
exceed the pilot's own); the numbers are comparable within one folder, not across folders
with different references.

For MOCS, NSGA-II and MOPSO (which have no ρ or α_max) the grid is a single setting per
population size, and the rho and alpha_max columns hold nan.

``wall_s`` is the wall time of the run's chunk (compilation included for the first chunk of
a population size in a process) divided by the chunk's size.

Backends. ``local`` (default) runs chunks one after another in this process; it needs no
service. ``dask`` sends chunks to a Dask distributed cluster (``--scheduler ADDRESS``, or a
``LocalCluster`` of ``--workers`` workers started here); the client writes each chunk file
as its future completes, so the layout and the resume behaviour are the same. Dask rather
than Ray: Dask distributed is pip-installable pure Python (``pip install
'dockjax[distributed]'``), its ``LocalCluster`` starts in-process in about a second (tests
use it), it needs no daemon or head node, and a chunk is one plain function call — the
task-graph features where Ray's actor model would help are not needed here. The local
cluster uses threads by default (``--no-dask-processes``; XLA releases the GIL while it
runs and the workers share one compilation); ``--dask-processes`` starts worker processes
instead (each compiles once, using the persistent compilation cache).

Test hook: the environment variable ``DOCKJAX_SWEEP_PAUSE`` (seconds) makes the sweep
sleep after each chunk it writes, so that a test can kill it between chunks.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Literal

import numpy as np

from .io import atomic_savez, atomic_write_text

__all__ = [
    "SweepArgs",
    "SweepConfig",
    "ChunkSpec",
    "ConfigError",
    "COLUMNS",
    "plan_chunks",
    "run_chunk",
    "run_sweep",
    "report",
    "main",
]

FORMAT = "dockjax-sweep/1"
GRID_ALGORITHMS = ("imocs",)
"""Algorithms with the ρ and α_max hyper-parameters (IMOCS only)."""
PILOT_SEED0 = 1_000_000
PILOT_HYPER = {"rho": 0.4, "alpha_max": 0.1}
HV_REF = 1.1
COLUMNS = ("algorithm", "pop", "rho", "alpha_max", "seed", "iterations", "HV", "IGD", "IGD+",
           "GD", "SP", "ONVG", "T_min", "T_max", "jerk_min", "jerk_max", "chunk", "wall_s")
"""Columns of ``runs.csv`` (one row per run)."""
INDICATOR_COLUMNS = ("HV", "IGD", "IGD+", "GD", "SP", "ONVG")


class ConfigError(ValueError):
    """Bad input or an incompatible results folder (the CLI's exit code 2)."""


# ------------------------------------------------------------------------------ CLI arguments
@dataclass(frozen=True)
class SweepArgs:
    """Large hyper-parameter sweeps that never lose work: every finished chunk of runs is saved atomically in --out, and re-running the same command after an interruption resumes where it stopped. Writes runs.csv (one row per run), summary.csv, figures. See the module docstring of dockjax.sweep for the file layout."""

    rho: tuple[float, ...] = (0.3, 0.4, 0.5)
    """Grid of the Bernoulli-map parameter ρ, each in (0, 1). IMOCS only; ignored (one value) for mocs, nsga2, mopso."""
    alpha_max: tuple[float, ...] = (0.05, 0.1, 0.2)
    """Grid of the maximum step α_max, each > 0. IMOCS only; ignored (one value) for mocs, nsga2, mopso."""
    pop: tuple[int, ...] = (150,)
    """Population size(s), each >= 4 (one compilation per size)."""
    seeds: int = 2
    """Runs per setting: seeds 0 .. N-1 (the same seeds for every setting)."""
    iters: int = 50
    """Iterations per run."""
    algorithm: Literal["imocs", "mocs", "nsga2", "mopso"] = "imocs"
    """Optimiser. ρ/α_max apply to IMOCS only; for the others the grid is a single setting."""
    preset: Literal["paper", "wide"] = "paper"
    """Problem preset: paper (h in [3.5, 10] s) or wide (h in [0.5, 10] s)."""
    refine_steps: int = 0
    """Memetic finish: polish every run's final population with this many gradient-refinement steps (dockjax.refine; the algorithm column then reads e.g. imocs+refine). 0: off."""
    out: Path = Path("results/sweep")
    """Results folder (created). Re-run the same command on it to resume; a folder holding a different configuration is refused."""
    chunk: int = 40
    """Maximum runs per compiled call (part of the configuration: changing it refuses to resume)."""
    reference_front: Path | None = None
    """Best-known front (.npz with key 'front', or .csv with columns T, jerk) to score against; default: a deterministic pilot computed at sweep start (see the module docstring)."""
    backend: Literal["local", "dask"] = "local"
    """local: chunks run in this process (no service needed); dask: a Dask cluster."""
    scheduler: str | None = None
    """Dask scheduler address (e.g. tcp://host:8786); default: start a LocalCluster."""
    workers: int = 2
    """Workers of the LocalCluster started for --backend dask without --scheduler."""
    dask_processes: bool = False
    """LocalCluster workers as processes (each compiles) instead of threads (shared compile)."""
    top: int = 10
    """Rows of the summary table printed (the full table is in summary.csv)."""
    progress: bool = True
    """Show a progress bar (runs done, runs/s, ETA) on stderr."""
    devices: int | None = None
    """CPU devices the runs of a chunk are sharded over (results are identical for any count; two devices on two cores run ~1.9x faster than one). Default: one per usable core. Not part of the configuration."""


@dataclass(frozen=True)
class SweepConfig:
    """The identity of a sweep: everything that decides its numbers."""

    algorithm: str
    preset: str
    pop: tuple[int, ...]
    rho: tuple[float, ...] | None
    alpha_max: tuple[float, ...] | None
    seeds: int
    iters: int
    chunk: int
    reference: dict
    refine_steps: int = 0

    def identity(self) -> dict:
        d = asdict(self)
        if not self.refine_steps:  # folders written before the option existed stay resumable
            d.pop("refine_steps")
        d["pop"] = list(self.pop)
        d["rho"] = None if self.rho is None else list(self.rho)
        d["alpha_max"] = None if self.alpha_max is None else list(self.alpha_max)
        return {"format": FORMAT, **d, "hv_ref": HV_REF,
                "normalisation": "ideal and nadir of reference.npz's front"}

    @property
    def has_grid(self) -> bool:
        return self.algorithm in GRID_ALGORITHMS

    def settings(self) -> list[tuple[int, float, float]]:
        rhos = self.rho if self.has_grid else (math.nan,)
        alphas = self.alpha_max if self.has_grid else (math.nan,)
        return [(p, r, a) for p in self.pop for r in rhos for a in alphas]

    def n_runs(self) -> int:
        return len(self.settings()) * self.seeds


@dataclass(frozen=True)
class ChunkSpec:
    """One compiled call: ``len(seeds)`` runs (``n_real`` real, the rest padding)."""

    index: int
    algorithm: str
    preset: str
    pop: int
    iters: int
    run_ids: tuple[int, ...]
    seeds: tuple[int, ...]
    rho: tuple[float, ...]
    alpha_max: tuple[float, ...]
    n_real: int
    refine_steps: int = 0

    @property
    def label(self) -> str:
        """The algorithm column: ``imocs`` or, with the memetic finish, ``imocs+refine``."""
        return f"{self.algorithm}+refine" if self.refine_steps else self.algorithm

    @property
    def name(self) -> str:
        return f"chunk-{self.index:05d}.npz"


def _chunk_size(n: int, limit: int) -> int:
    return math.ceil(n / math.ceil(n / limit))


def plan_chunks(cfg: SweepConfig) -> list[ChunkSpec]:
    """Runs (sorted by pop, ρ, α_max, seed; run id = position) cut into chunks per population
    size; a deterministic function of the configuration."""
    runs = [(p, r, a, s) for (p, r, a) in cfg.settings() for s in range(cfg.seeds)]
    chunks: list[ChunkSpec] = []
    for pop in cfg.pop:
        ids = [i for i, run in enumerate(runs) if run[0] == pop]
        size = _chunk_size(len(ids), cfg.chunk)
        for k in range(0, len(ids), size):
            real = ids[k : k + size]
            padded = [real[j % len(real)] for j in range(size)]
            chunks.append(ChunkSpec(
                index=len(chunks), algorithm=cfg.algorithm, preset=cfg.preset, pop=pop,
                iters=cfg.iters, run_ids=tuple(real), seeds=tuple(runs[i][3] for i in padded),
                rho=tuple(runs[i][1] for i in padded), alpha_max=tuple(runs[i][2] for i in padded),
                n_real=len(real), refine_steps=cfg.refine_steps))
    return chunks


def pilot_spec(cfg: SweepConfig) -> ChunkSpec:
    """The reference pilot: one chunk of the largest population, default hyper-parameters."""
    size = _chunk_size(len(cfg.settings()) // len(cfg.pop) * cfg.seeds, cfg.chunk)
    rho = PILOT_HYPER["rho"] if cfg.has_grid else math.nan
    alpha = PILOT_HYPER["alpha_max"] if cfg.has_grid else math.nan
    return ChunkSpec(index=-1, algorithm=cfg.algorithm, preset=cfg.preset, pop=max(cfg.pop),
                     iters=cfg.iters, run_ids=tuple(range(size)),
                     seeds=tuple(PILOT_SEED0 + i for i in range(size)), rho=(rho,) * size,
                     alpha_max=(alpha,) * size, n_real=size, refine_steps=cfg.refine_steps)


# ----------------------------------------------------------------------------- one chunk
@lru_cache(maxsize=None)
def _problem(preset: str):
    from .study import make_problem

    return make_problem(preset)


def _nondominated_2d(F: np.ndarray) -> np.ndarray:
    """Distinct non-dominated rows of (k, 2) F, sorted by the first column."""
    from .metrics import nondominated_points

    return nondominated_points(F)


def run_chunk(spec: ChunkSpec, reference: dict | None = None, *, devices: int | None = None
              ) -> dict[str, np.ndarray]:
    """Run one chunk (one compiled vmapped call) and score its real runs.

    ``reference``: {"front", "ideal", "nadir", "hv_ref"} or None (no indicators; the pilot).
    ``devices``: local devices the runs are sharded over (default all; see
    :func:`dockjax.algorithms.optimize`; the results do not depend on it).
    Returns the chunk's table columns (one entry per real run), ``front_F`` (every run's
    distinct feasible non-dominated F, concatenated) and ``front_offsets``. Pure function of
    its arguments (apart from ``wall_s``); runs on a Dask worker as well.
    """
    from .algorithms import optimize

    t0 = time.perf_counter()
    batch = None
    if spec.algorithm in GRID_ALGORITHMS:
        batch = {"rho": np.asarray(spec.rho, np.float64), "alpha_max": np.asarray(spec.alpha_max, np.float64)}
    r = optimize(spec.algorithm, _problem(spec.preset), seeds=np.asarray(spec.seeds, np.int64),
                 pop_size=spec.pop, n_iter=spec.iters, batch_params=batch,
                 refine_steps=spec.refine_steps, devices=devices)
    n = spec.n_real
    fronts = r.fronts()[:n]
    out: dict[str, np.ndarray] = {
        "run_id": np.asarray(spec.run_ids, np.int64),
        "algorithm": np.asarray([spec.label] * n),
        "pop": np.full(n, spec.pop, np.int64),
        "rho": np.asarray(spec.rho[:n], np.float64),
        "alpha_max": np.asarray(spec.alpha_max[:n], np.float64),
        "seed": np.asarray(spec.seeds[:n], np.int64),
        "iterations": np.full(n, spec.iters, np.int64),
        "chunk": np.full(n, spec.index, np.int64),
    }
    ext = np.array([[f[:, 0].min(), f[:, 0].max(), f[:, 1].min(), f[:, 1].max()] if len(f)
                    else [np.nan] * 4 for f in fronts]).reshape(n, 4)
    for j, k in enumerate(("T_min", "T_max", "jerk_min", "jerk_max")):
        out[k] = ext[:, j]
    if reference is not None:
        from . import metrics

        ind = metrics.indicators(r.F, r.front, reference["front"], hv_ref=float(reference["hv_ref"]),
                                 ideal=reference["ideal"], nadir=reference["nadir"])
        for k in INDICATOR_COLUMNS:
            key = k if k in ind else {"IGD+": "IGDplus"}.get(k, k)
            out[k] = np.asarray(ind[key])[:n].astype(np.int64 if k == "ONVG" else np.float64)
    out["front_F"] = np.concatenate([f for f in fronts] + [np.zeros((0, 2))]).astype(np.float64)
    out["front_offsets"] = np.cumsum([0] + [len(f) for f in fronts]).astype(np.int64)
    out["wall_s"] = np.full(n, (time.perf_counter() - t0) / len(spec.seeds))
    return out


# ------------------------------------------------------------------------------- files
def _atomic_savez(path: Path, arrays: dict[str, np.ndarray]) -> None:
    atomic_savez(path, arrays)


def _atomic_text(path: Path, text: str) -> None:
    atomic_write_text(path, text)


def _save_figure(fig, path: Path) -> Path:
    from .plots import save

    return save(fig, path)


def _load_npz(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _sha256(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a, dtype=np.float64).tobytes()).hexdigest()


def load_front_file(path: Path) -> np.ndarray:
    """A best-known front from .npz (key 'front', 'reference_front' or 'F', or the only
    array) or .csv/.txt (two columns T, jerk; a header line is skipped). → distinct
    non-dominated (r, 2). Raises ConfigError."""
    path = Path(path)
    try:
        if path.suffix == ".npz":
            z = _load_npz(path)
            key = next((k for k in ("front", "reference_front", "F") if k in z), None)
            if key is None and len(z) == 1:
                key = next(iter(z))
            if key is None:
                raise ConfigError(f"--reference-front {path}: no array 'front' in {sorted(z)}")
            F = z[key]
        else:
            lines = path.read_text().strip().splitlines()
            try:
                F = np.loadtxt(lines, delimiter=",", ndmin=2)
            except ValueError:
                F = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
    except ConfigError:
        raise
    except (OSError, ValueError) as exc:
        raise ConfigError(f"--reference-front {path} cannot be read: {exc}") from None
    F = np.asarray(F, dtype=np.float64)
    if F.ndim != 2 or F.shape[1] != 2 or len(F) == 0 or not np.isfinite(F).all():
        raise ConfigError(f"--reference-front {path} must hold a finite, non-empty (r, 2) array, got shape {F.shape}")
    return _nondominated_2d(F)


# ---------------------------------------------------------------------------- validation
def _grid(name: str, values: Iterable[float]) -> tuple[float, ...]:
    return tuple(sorted({float(v) for v in values}))


def make_config(args: SweepArgs) -> tuple[SweepConfig, np.ndarray | None]:
    """Validate the arguments (no file is written, nothing is compiled) and build the
    configuration. Returns it and the loaded reference front (None for the pilot).
    Raises ConfigError with every problem on one line."""
    errors: list[str] = []
    has_grid = args.algorithm in GRID_ALGORITHMS
    for name, vals, ok, rule in (
        ("--rho", args.rho, lambda v: 0.0 < v < 1.0, "in (0, 1)"),
        ("--alpha-max", args.alpha_max, lambda v: v > 0.0, "> 0"),
    ):
        if not vals:
            errors.append(f"{name} grid is empty (give at least one value)")
        elif has_grid:
            bad = [v for v in vals if not (math.isfinite(v) and ok(v))]
            if bad:
                errors.append(f"{name} values must be {rule}, got {bad}")
    if not args.pop:
        errors.append("--pop grid is empty (give at least one population size)")
    bad_pop = [p for p in args.pop if p < 4]
    if bad_pop:
        errors.append(f"--pop values must be >= 4, got {bad_pop}")
    for name, v, lo in (("--seeds", args.seeds, 1), ("--iters", args.iters, 1),
                        ("--chunk", args.chunk, 1), ("--workers", args.workers, 1), ("--top", args.top, 1),
                        ("--refine-steps", args.refine_steps, 0)):
        if v < lo:
            errors.append(f"{name} must be >= {lo}, got {v}")
    if args.scheduler is not None and args.backend != "dask":
        errors.append("--scheduler needs --backend dask")
    if args.backend == "dask":
        try:
            import distributed  # noqa: F401
        except ImportError:
            errors.append("--backend dask needs Dask distributed: pip install 'dockjax[distributed]'")
    front = None
    reference: dict[str, Any]
    if args.reference_front is not None:
        try:
            front = load_front_file(args.reference_front)
            reference = {"kind": "file", "points": int(len(front)), "sha256": _sha256(front)}
        except ConfigError as exc:
            errors.append(str(exc))
            reference = {}
    else:
        reference = {"kind": "pilot", "seeds_from": PILOT_SEED0,
                     "hyper": PILOT_HYPER if has_grid else "defaults",
                     "pop": "largest", "iters": "the sweep's", "runs": "one chunk"}
    if errors:
        raise ConfigError("; ".join(errors))
    cfg = SweepConfig(
        algorithm=args.algorithm, preset=args.preset, pop=tuple(sorted(set(args.pop))),
        rho=_grid("rho", args.rho) if has_grid else None,
        alpha_max=_grid("alpha_max", args.alpha_max) if has_grid else None,
        seeds=args.seeds, iters=args.iters, chunk=args.chunk, reference=reference,
        refine_steps=args.refine_steps)
    # the algorithm's own checks (imports JAX, compiles nothing)
    from . import algorithms

    algo = algorithms.get(cfg.algorithm)
    try:
        for p in cfg.pop:
            hyper = {"rho": np.asarray(cfg.rho), "alpha_max": np.asarray(cfg.alpha_max)} if has_grid else {}
            algo.validate(_problem(cfg.preset), algorithms.make_params(algo, p, cfg.iters, **hyper))
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    return cfg, front


def _diff(a: dict, b: dict) -> list[str]:
    keys = sorted(set(a) | set(b))
    return [f"{k}: folder has {a.get(k)!r}, command gives {b.get(k)!r}" for k in keys if a.get(k) != b.get(k)]


def prepare_folder(out: Path, cfg: SweepConfig) -> list[Path]:
    """Check that ``out`` can hold this sweep: created if missing (returns the folders
    created, outermost first, so that a caller can remove them), writable, and either new,
    empty or holding the same configuration with chunk files of this plan. Raises
    ConfigError; on error, folders created here are removed."""
    out = Path(out)
    created: list[Path] = []
    try:
        if out.exists() and not out.is_dir():
            raise ConfigError(f"--out {out} exists and is not a folder")
        if out.exists():
            cfg_path = out / "config.json"
            if cfg_path.exists():
                try:
                    stored = json.loads(cfg_path.read_text())["identity"]
                except (OSError, ValueError, KeyError, TypeError) as exc:
                    raise ConfigError(f"--out {out}: config.json is unreadable ({exc}); use another folder") from None
                want = json.loads(json.dumps(cfg.identity()))
                if stored != want:
                    raise ConfigError(f"--out {out} holds a different sweep configuration ("
                                      + "; ".join(_diff(stored, want)) + "); use another folder or the same options")
                _check_chunks(out, cfg)
            elif any(not p.name.startswith(".") for p in out.iterdir()):
                raise ConfigError(f"--out {out} is not empty and holds no sweep (no config.json); use a new or empty folder")
        else:
            missing = []
            p = out
            while not p.exists():
                missing.append(p)
                p = p.parent
            for p in reversed(missing):
                try:
                    p.mkdir()
                except OSError as exc:
                    raise ConfigError(f"--out {out} cannot be created: {exc.strerror or exc}") from None
                created.append(p)
        try:
            fd, probe = tempfile.mkstemp(dir=out, prefix=".write-test.")
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise ConfigError(f"--out {out} cannot be written: {exc.strerror or exc}") from None
    except ConfigError:
        remove_created(created)
        raise
    return created


def remove_created(created: list[Path]) -> None:
    """Remove folders this invocation created (outermost first in ``created``)."""
    if created:
        shutil.rmtree(created[0], ignore_errors=True)


def _check_chunks(out: Path, cfg: SweepConfig) -> None:
    plan = {c.name: c for c in plan_chunks(cfg)}
    folder = out / "chunks"
    if not folder.is_dir():
        return
    for path in sorted(folder.glob("chunk-*.npz")):
        spec = plan.get(path.name)
        if spec is None:
            raise ConfigError(f"--out {out}: {path.name} is not part of this sweep's plan; use another folder")
        try:
            with np.load(path, allow_pickle=False) as z:
                ids = tuple(int(i) for i in z["run_id"])
        except Exception:  # unreadable: recomputed later
            continue
        if ids != spec.run_ids:
            raise ConfigError(f"--out {out}: {path.name} holds other runs than this sweep's plan; use another folder")


# ----------------------------------------------------------------------------- backends
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
        import logging

        from distributed import Client, LocalCluster

        self.cluster = None
        if scheduler:
            self.client = Client(scheduler, timeout="15s")
        else:
            self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=processes,
                                        dashboard_address=None, silence_logs=logging.ERROR)
            self.client = Client(self.cluster)
            if processes:
                from .cli import enable_compilation_cache

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


# -------------------------------------------------------------------------------- sweep
def _write_config(out: Path, cfg: SweepConfig) -> None:
    path = out / "config.json"
    if path.exists():
        return
    import jax

    from . import __version__

    doc = {"identity": cfg.identity(),
           "info": {"dockjax": __version__, "jax": jax.__version__, "numpy": np.__version__,
                    "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "argv": sys.argv}}
    _atomic_text(path, json.dumps(doc, indent=2) + "\n")


def _reference(out: Path, cfg: SweepConfig, front: np.ndarray | None, backend, log) -> dict:
    path = out / "reference.npz"
    if path.exists():
        ref = _load_npz(path)
        log(f"reference: {len(ref['front'])} points from {path} (fixed at sweep start)")
        return ref
    t0 = time.perf_counter()
    if front is None:
        spec = pilot_spec(cfg)
        log(f"reference: pilot of {spec.n_real} {cfg.algorithm} runs (pop {spec.pop}, {cfg.iters} iterations, "
            f"{'ρ=0.4, α_max=0.1, ' if cfg.has_grid else ''}seeds {PILOT_SEED0}..) ...")
        _, res = next(backend.map(run_chunk, [spec]))
        front = _nondominated_2d(res["front_F"])
        if len(front) == 0:
            raise RuntimeError("the reference pilot found no feasible trajectory; raise --iters or "
                               "pass --reference-front")
        source = "pilot"
    else:
        source = "file"
    ref = {"front": front, "ideal": front.min(0), "nadir": front.max(0), "hv_ref": np.float64(HV_REF),
           "source": np.asarray(source)}
    _atomic_savez(path, ref)
    log(f"reference: {len(front)} points ({source}) in {time.perf_counter() - t0:.1f} s"
        f"{' (compile included)' if source == 'pilot' else ''}; ideal {np.round(ref['ideal'], 4).tolist()}, "
        f"nadir {np.round(ref['nadir'], 4).tolist()}")
    return ref


def run_sweep(cfg: SweepConfig, out: Path, *, front: np.ndarray | None = None, backend: str = "local",
              scheduler: str | None = None, workers: int = 2, dask_processes: bool = False,
              progress: bool = True, log: Callable[[str], None] = print) -> int:
    """Run every missing chunk of the sweep in ``out`` (after :func:`prepare_folder`).
    Returns the number of chunks computed now."""
    from tqdm import tqdm

    out = Path(out)
    chunks_dir = out / "chunks"
    if backend == "dask":
        try:
            be = DaskBackend(scheduler, workers, dask_processes)
        except (OSError, TimeoutError) as exc:
            where = f"the Dask scheduler at {scheduler}" if scheduler else "a Dask LocalCluster"
            raise ConfigError(f"cannot connect to {where}: {exc}") from None
    else:
        be = LocalBackend()
    pause = float(os.environ.get("DOCKJAX_SWEEP_PAUSE", "0") or 0)
    try:
        _write_config(out, cfg)
        chunks_dir.mkdir(exist_ok=True)
        for stale in chunks_dir.glob(".chunk-*.tmp"):  # left by a kill during a write
            stale.unlink(missing_ok=True)
        plan = plan_chunks(cfg)
        done = {c.index for c in plan if _readable(chunks_dir / c.name)}
        todo = [c for c in plan if c.index not in done]
        n_total = sum(c.n_real for c in plan)
        n_done = sum(c.n_real for c in plan if c.index in done)
        log(f"sweep: {plan[0].label if plan else cfg.algorithm}, {cfg.n_runs()} runs ({len(cfg.settings())} settings × {cfg.seeds} seeds, "
            f"{cfg.iters} iterations) in {len(plan)} chunks of {len(plan[0].seeds)}; "
            + (f"resuming: {len(done)} of {len(plan)} chunks already done" if done else "starting"))
        ref = _reference(out, cfg, front, be, log)
        if not todo:
            return 0
        reference = {k: ref[k] for k in ("front", "ideal", "nadir", "hv_ref")}
        bar = tqdm(total=n_total, initial=n_done, unit="run", disable=not progress, file=sys.stderr,
                   dynamic_ncols=True, smoothing=0.1)
        times: dict[int, list[float]] = {}
        try:
            for spec, res in be.map(run_chunk, todo, reference):
                _atomic_savez(chunks_dir / spec.name, res)
                seconds = float(res["wall_s"][0]) * len(spec.seeds)
                first = spec.pop not in times
                times.setdefault(spec.pop, []).append(seconds)
                bar.update(spec.n_real)
                if first:
                    bar.set_postfix_str(f"first chunk of pop {spec.pop} (compile + run): {seconds:.1f} s")
                else:
                    t = times[spec.pop]
                    bar.set_postfix_str(f"pop {spec.pop}: compile ≈ {max(t[0] - np.median(t[1:]), 0):.1f} s, "
                                        f"{np.median(t[1:]):.2f} s/chunk")
                if pause:
                    time.sleep(pause)
        finally:
            bar.close()
        for pop, t in times.items():
            later = f", later chunks {np.median(t[1:]):.2f} s each (compile ≈ {max(t[0] - np.median(t[1:]), 0):.1f} s)" if len(t) > 1 else ""
            log(f"pop {pop}: first chunk {t[0]:.1f} s{later}")
        return len(todo)
    finally:
        be.close()


def _readable(path: Path) -> bool:
    if not path.exists():
        return False
    try:
        with np.load(path, allow_pickle=False) as z:
            z["run_id"], z["front_offsets"]
        return True
    except Exception:
        return False


# -------------------------------------------------------------------------------- report
def _fmt(v) -> str:
    if isinstance(v, (str, np.str_)):
        return str(v)
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return repr(float(v))


def load_table(out: Path) -> tuple[dict[str, np.ndarray], list[np.ndarray]]:
    """Every chunk file of ``out`` merged: columns sorted by run id, and each run's front."""
    parts = [_load_npz(p) for p in sorted((Path(out) / "chunks").glob("chunk-*.npz"))]
    if not parts:
        raise RuntimeError(f"no chunk files in {out / 'chunks'}")
    cols = {k: np.concatenate([p[k] for p in parts]) for k in ("run_id",) + COLUMNS}
    fronts = [p["front_F"][o0:o1] for p in parts for o0, o1 in zip(p["front_offsets"][:-1], p["front_offsets"][1:])]
    order = np.argsort(cols["run_id"], kind="stable")
    return {k: v[order] for k, v in cols.items()}, [fronts[i] for i in order]


def _settings_summary(cols: dict[str, np.ndarray]) -> list[dict]:
    keys = list(zip(cols["pop"].tolist(), cols["rho"].tolist(), cols["alpha_max"].tolist()))
    rows = []
    seen: dict = {}
    for i, k in enumerate(keys):
        seen.setdefault(tuple("nan" if isinstance(x, float) and math.isnan(x) else x for x in k), []).append(i)
    for k, idx in seen.items():
        idx = np.asarray(idx)
        hv = cols["HV"][idx]
        q1, med, q3 = np.nanpercentile(hv, [25, 50, 75]) if np.isfinite(hv).any() else (np.nan,) * 3
        row = {"pop": int(k[0]), "rho": cols["rho"][idx[0]], "alpha_max": cols["alpha_max"][idx[0]],
               "runs": len(idx), "HV_median": med, "HV_iqr": q3 - q1, "_q": (q1, q3)}
        for ind in ("IGD", "IGD+", "GD", "SP", "ONVG"):
            v = cols[ind][idx].astype(float)
            row[f"{ind}_median"] = float(np.nanmedian(v)) if np.isfinite(v).any() else np.nan
        row["_idx"] = idx
        rows.append(row)
    rows.sort(key=lambda r: (-(r["HV_median"] if np.isfinite(r["HV_median"]) else -np.inf),
                             r["pop"], np.nan_to_num(r["rho"]), np.nan_to_num(r["alpha_max"])))
    return rows


def _label(row) -> str:
    if math.isnan(row["rho"]):
        return f"pop {row['pop']}"
    return f"pop {row['pop']}, ρ={row['rho']:g}, α_max={row['alpha_max']:g}"


def report(out: Path, *, top: int = 10, log: Callable[[str], None] = print) -> list[Path]:
    """Tables and figures of a finished sweep folder (every file atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    cols, fronts = load_table(out)
    ref = _load_npz(out / "reference.npz")
    written = []
    lines = [",".join(COLUMNS)] + [",".join(_fmt(cols[c][i]) for c in COLUMNS) for i in range(len(cols["run_id"]))]
    _atomic_text(out / "runs.csv", "\n".join(lines) + "\n")
    written.append(out / "runs.csv")
    offsets = np.cumsum([0] + [len(f) for f in fronts])
    _atomic_savez(out / "fronts.npz", {"F": np.concatenate(fronts + [np.zeros((0, 2))]), "offsets": offsets,
                                       **{k: cols[k] for k in ("run_id", "pop", "rho", "alpha_max", "seed")}})
    written.append(out / "fronts.npz")

    rows = _settings_summary(cols)
    scols = [k for k in rows[0] if not k.startswith("_")]
    _atomic_text(out / "summary.csv", "\n".join([",".join(scols)] + [",".join(_fmt(r[c]) for c in scols) for r in rows]) + "\n")
    md = ["| " + " | ".join(scols) + " |", "|" + "---|" * len(scols)]
    md += ["| " + " | ".join(f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c]) for c in scols) + " |" for r in rows]
    note = (f"\nIndicators on objectives normalised by the fixed reference front of reference.npz "
            f"({str(ref.get('source', 'pilot'))}, {len(ref['front'])} points; HV reference point {float(ref['hv_ref'])}).\n")
    _atomic_text(out / "summary.md", "\n".join(md) + "\n" + note)
    written += [out / "summary.csv", out / "summary.md"]

    algo = str(cols["algorithm"][0])
    log(f"\n{algo}: {len(cols['run_id'])} runs, {len(rows)} settings; best by median HV "
        f"(reference fixed at sweep start: {str(ref.get('source', 'pilot'))}, {len(ref['front'])} points)")
    log(f"{'rank':>4}  {'setting':<34} {'HV median':>10} {'IQR':>8} {'IGD':>8} {'GD':>9} {'SP':>8} {'ONVG':>5}")
    for k, r in enumerate(rows[:top]):
        log(f"{k + 1:>4}  {_label(r):<34} {r['HV_median']:>10.4f} {r['HV_iqr']:>8.4f} {r['IGD_median']:>8.4f} "
            f"{r['GD_median']:>9.5f} {r['SP_median']:>8.5f} {r['ONVG_median']:>5.0f}")
    if len(rows) > top:
        log(f"      ... {len(rows) - top} more in {out / 'summary.csv'}")

    # heat maps of median HV over rho x alpha_max, per population size (IMOCS)
    if not np.isnan(cols["rho"]).all():
        for pop in sorted({r["pop"] for r in rows}):
            sub = [r for r in rows if r["pop"] == pop]
            rhos = sorted({r["rho"] for r in sub})
            alphas = sorted({r["alpha_max"] for r in sub})
            M = np.full((len(rhos), len(alphas)), np.nan)
            for r in sub:
                M[rhos.index(r["rho"]), alphas.index(r["alpha_max"])] = r["HV_median"]
            fig, ax = plt.subplots(figsize=(1.2 * len(alphas) + 2.5, 0.9 * len(rhos) + 2))
            im = ax.imshow(M, origin="lower", cmap="viridis", aspect="auto")
            for i in range(len(rhos)):
                for j in range(len(alphas)):
                    ax.text(j, i, f"{M[i, j]:.3f}", ha="center", va="center", color="w", fontsize=8)
            ax.set_xticks(range(len(alphas)), [f"{a:g}" for a in alphas])
            ax.set_yticks(range(len(rhos)), [f"{r:g}" for r in rhos])
            ax.set_xlabel("α_max")
            ax.set_ylabel("ρ")
            ax.set_title(f"{algo}: median HV, pop {pop}")
            fig.colorbar(im, ax=ax)
            written.append(_save_figure(fig, out / f"heatmap_hv_pop{pop}.png"))
    # HV against population size, one line per (rho, alpha_max)
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    groups: dict = {}
    for r in rows:
        groups.setdefault((_fmt(r["rho"]), _fmt(r["alpha_max"])), []).append(r)
    pops = sorted({r["pop"] for r in rows})
    dx = 0.01 * (max(pops) - min(pops) or max(pops))  # side by side, so the bars stay readable
    for g, ((rho, alpha), rs) in enumerate(sorted(groups.items())):
        rs = sorted(rs, key=lambda r: r["pop"])
        x = np.array([r["pop"] for r in rs], float) + dx * (g - (len(groups) - 1) / 2)
        y = np.array([r["HV_median"] for r in rs])
        q = np.array([r["_q"] for r in rs]).reshape(-1, 2)
        label = algo if rho == "nan" else f"ρ={float(rho):g}, α_max={float(alpha):g}"
        ax.errorbar(x, y, yerr=[y - q[:, 0], q[:, 1] - y], marker="o", capsize=3, label=label)
    ax.set_xticks(pops)
    ax.set_xlabel("population size")
    ax.set_ylabel("hypervolume (median, bar = IQR)")
    ax.set_title(f"{algo}: HV against population size")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    written.append(_save_figure(fig, out / "hv_vs_pop.png"))
    # fronts of the best and the worst setting
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    R = ref["front"]
    ax.plot(R[:, 0], R[:, 1], ".-", color="0.5", lw=1, ms=4, drawstyle="steps-post",
            label="reference front (fixed at sweep start)")
    for r, color, what in ((rows[0], "C3", "best"), (rows[-1], "C0", "worst")):
        for n, i in enumerate(r["_idx"]):
            f = fronts[i]
            if len(f):
                ax.plot(f[:, 0], f[:, 1], "o", ms=3, color=color, alpha=0.6,
                        label=f"{what}: {_label(r)} (HV {r['HV_median']:.3f})" if n == 0 else None)
        if len(rows) == 1:
            break
    ax.set_xlabel("total time T [s]")
    ax.set_ylabel("jerk objective (Eq. 25)")
    ax.set_yscale("log")
    ax.set_title(f"{algo}: fronts of every seed, best and worst setting by median HV")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    written.append(_save_figure(fig, out / "fronts_best_worst.png"))
    log(f"wrote {', '.join(p.name for p in written)} to {out}")
    return written


# ----------------------------------------------------------------------------------- CLI
def main(argv: list[str] | None = None) -> int:
    """``python experiments/sweep.py``: parse, validate (exit 2 before any compilation and
    without leaving a folder behind), run the missing chunks, report."""
    import tyro

    args = tyro.cli(SweepArgs, args=argv)
    created: list[Path] = []
    from .cli import claim_devices

    try:
        claim_devices(args.devices)  # before any JAX computation
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        cfg, front = make_config(args)
        created = prepare_folder(args.out, cfg)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not cfg.has_grid and (args.rho != SweepArgs.rho or args.alpha_max != SweepArgs.alpha_max):
        print(f"note: --rho and --alpha-max apply to IMOCS only; {cfg.algorithm} runs one setting per population size")
    from .cli import enable_compilation_cache

    enable_compilation_cache()
    t0 = time.perf_counter()
    try:
        run_sweep(cfg, args.out, front=front, backend=args.backend, scheduler=args.scheduler,
                  workers=args.workers, dask_processes=args.dask_processes, progress=args.progress)
    except ConfigError as exc:  # e.g. an unreachable scheduler; nothing was computed
        remove_created(created)
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished chunks are saved in {args.out / 'chunks'}; re-run the same command to resume",
              file=sys.stderr)
        return 130
    except RuntimeError as exc:
        if created and not any((Path(args.out) / "chunks").glob("chunk-*.npz")):
            remove_created(created)
        print(f"error: {exc}", file=sys.stderr)
        return 1
    report(args.out, top=args.top)
    print(f"total {time.perf_counter() - t0:.1f} s")
    return 0
