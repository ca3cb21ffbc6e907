"""What a sweep is: its configuration (the identity that decides its numbers), the
assignment of its runs to chunks, its reference definition, and the validation of a
request. Nothing here computes or writes."""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from .. import algorithms, config
from ..algorithms import imocs
from ..metrics import nondominated_points
from .files import load_npz

__all__ = ["FORMAT", "GRID_ALGORITHMS", "PILOT_SEED0", "PILOT_HYPER", "COLUMNS", "INDICATOR_COLUMNS", "ConfigError",
           "SweepConfig", "ChunkSpec", "plan_chunks", "pilot_spec", "load_front_file", "make_config"]

FORMAT = "dockjax-sweep/1"
GRID_ALGORITHMS = ("imocs",)
"""Algorithms with the ρ and α_max hyper-parameters (IMOCS only)."""
PILOT_SEED0 = 1_000_000
PILOT_HYPER = {k: getattr(imocs.Params(), k) for k in ("rho", "alpha_max")}
"""The pilot's hyper-parameters: IMOCS's defaults."""
COLUMNS = ("algorithm", "pop", "rho", "alpha_max", "seed", "iterations", "HV", "IGD", "IGD+",
           "GD", "SP", "ONVG", "T_min", "T_max", "jerk_min", "jerk_max", "chunk", "wall_s")
"""Columns of ``runs.csv`` (one row per run)."""
INDICATOR_COLUMNS = ("HV", "IGD", "IGD+", "GD", "SP", "ONVG")


class ConfigError(ValueError):
    """Bad input or an incompatible results folder (the CLI's exit code 2)."""


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
        return {"format": FORMAT, **d, "hv_ref": config.HV_REFERENCE,
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


def _sha256(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a, dtype=np.float64).tobytes()).hexdigest()


def load_front_file(path: Path) -> np.ndarray:
    """A best-known front from .npz (key 'front', 'reference_front' or 'F', or the only
    array) or .csv/.txt (two columns T, jerk; a header line is skipped). → distinct
    non-dominated (r, 2). Raises ConfigError."""
    path = Path(path)
    try:
        if path.suffix == ".npz":
            z = load_npz(path)
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
    return nondominated_points(F)


def _grid(name: str, values: Iterable[float]) -> tuple[float, ...]:
    return tuple(sorted({float(v) for v in values}))


def make_config(*, rho=config.SWEEP_RHO, alpha_max=config.SWEEP_ALPHA_MAX, pop=(config.POP_SIZE,),
                seeds: int = config.SWEEP_SEEDS, iters: int = config.SWEEP_ITERS, algorithm: str = "imocs",
                preset: str = "paper", refine_steps: int = 0, chunk: int = config.SWEEP_CHUNK,
                reference_front=None) -> tuple[SweepConfig, np.ndarray | None]:
    """Validate a sweep (nothing is written, nothing is compiled) and build its
    configuration. Returns it and the loaded reference front (None for the pilot).
    Raises ConfigError with every problem on one line, naming the options."""
    errors: list[str] = []
    has_grid = algorithm in GRID_ALGORITHMS
    for name, vals, ok, rule in (
        ("--rho", rho, lambda v: 0.0 < v < 1.0, "in (0, 1)"),
        ("--alpha-max", alpha_max, lambda v: v > 0.0, "> 0"),
    ):
        if not vals:
            errors.append(f"{name} grid is empty (give at least one value)")
        elif has_grid:
            bad = [v for v in vals if not (math.isfinite(v) and ok(v))]
            if bad:
                errors.append(f"{name} values must be {rule}, got {bad}")
    if not pop:
        errors.append("--pop grid is empty (give at least one population size)")
    bad_pop = [p for p in pop if p < 4]
    if bad_pop:
        errors.append(f"--pop values must be >= 4, got {bad_pop}")
    for name, v, lo in (("--seeds", seeds, 1), ("--iters", iters, 1), ("--chunk", chunk, 1),
                        ("--refine-steps", refine_steps, 0)):
        if v < lo:
            errors.append(f"{name} must be >= {lo}, got {v}")
    front = None
    reference: dict[str, Any]
    if reference_front is not None:
        try:
            front = load_front_file(reference_front)
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
        algorithm=algorithm, preset=preset, pop=tuple(sorted(set(pop))),
        rho=_grid("rho", rho) if has_grid else None,
        alpha_max=_grid("alpha_max", alpha_max) if has_grid else None,
        seeds=seeds, iters=iters, chunk=chunk, reference=reference,
        refine_steps=refine_steps)
    # the algorithm's own checks (compiles nothing)
    algo = algorithms.get(cfg.algorithm)
    try:
        for p in cfg.pop:
            hyper = {"rho": np.asarray(cfg.rho), "alpha_max": np.asarray(cfg.alpha_max)} if has_grid else {}
            algorithms.make_params(algo, p, cfg.iters, **hyper)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    return cfg, front
