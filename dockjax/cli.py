"""Console entry points (tyro). Each parses its arguments, validates them before any
compilation, then calls the library.

The CLIs (not the library) turn on JAX's persistent compilation cache, in
``$DOCKJAX_CACHE`` or ``~/.cache/dockjax/jax``, so a second run of the same shapes skips
compilation.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

__all__ = ["enable_compilation_cache", "DemoArgs", "demo", "demo_main"]


def enable_compilation_cache() -> None:
    """Use JAX's persistent compilation cache (CLIs only; the library never flips config)."""
    import jax

    path = Path(os.environ.get("DOCKJAX_CACHE", Path.home() / ".cache" / "dockjax" / "jax"))
    try:
        path.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(path))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    except OSError:  # read-only home: run without the cache
        pass


@dataclass(frozen=True)
class DemoArgs:
    """Score a random population of the paper's docking problem in one compiled call and
    print the best feasible candidates (the non-dominated ones)."""

    n: int = 100_000
    """Population size (candidates drawn uniformly in the decision box)."""
    seed: int = 0
    """Seed of the random population."""
    top: int = 10
    """How many non-dominated feasible candidates to print (spread along the front)."""
    precision: Literal["float64", "float32"] = "float64"
    """Arithmetic of the kernel."""


def demo(args: DemoArgs) -> int:
    if args.n < 1:
        print(f"error: --n must be >= 1, got {args.n}", file=sys.stderr)
        return 2
    if args.top < 1:
        print(f"error: --top must be >= 1, got {args.top}", file=sys.stderr)
        return 2
    enable_compilation_cache()
    import jax

    from . import DockingProblem, pareto

    problem = DockingProblem()
    rng = np.random.default_rng(args.seed)
    X = rng.uniform(problem.lower, problem.upper, (args.n, problem.n_var))
    print(problem)
    t0 = time.perf_counter()
    problem.evaluate(X, precision=args.precision)  # compile for this shape
    t1 = time.perf_counter()
    F, G = problem.evaluate(X, precision=args.precision)
    t2 = time.perf_counter()
    print(f"compile + first call: {t1 - t0:.2f} s; scoring {args.n} candidates: {t2 - t1:.3f} s "
          f"({args.n / (t2 - t1):,.0f} evaluations/s, {args.precision})")
    feasible = np.all(G <= 0, axis=1)
    print(f"feasible: {feasible.sum()} of {args.n} ({100 * feasible.mean():.1f} %)")
    if not feasible.any():
        worst = np.argmax(np.mean(G > 0, axis=0))
        print(f"no feasible candidate; most often violated column: {worst}")
        return 0
    Ff = F[feasible]
    with jax.enable_x64(True):
        rank = np.asarray(pareto.nondominated_rank_2d(Ff, np.zeros(len(Ff))))
    front = Ff[rank == 0]
    front = front[np.argsort(front[:, 0])]
    pick = np.unique(np.linspace(0, len(front) - 1, min(args.top, len(front))).round().astype(int))
    print(f"non-dominated feasible candidates: {len(front)}; showing {len(pick)}")
    print(f"{'T [s]':>10}  {'jerk':>10}")
    for i in pick:
        print(f"{front[i, 0]:10.4f}  {front[i, 1]:10.4f}")
    return 0


def demo_main() -> None:
    import tyro

    sys.exit(demo(tyro.cli(DemoArgs)))
