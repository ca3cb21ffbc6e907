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

__all__ = ["enable_compilation_cache", "usable_cores", "use_cpu_devices", "claim_devices", "DemoArgs", "demo", "demo_main", "PlanArgs", "plan_cmd", "main"]


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


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


def use_cpu_devices(n: int) -> int:
    """Ask JAX for ``n`` CPU devices (CLIs only; must run before the process's first JAX
    computation). Runs batched by :func:`dockjax.algorithms.optimize`, and the rows of
    :meth:`dockjax.DockingProblem.evaluate`, are then shared out over them
    (:mod:`dockjax.devices`): on this 2-core CPU two devices give about twice the
    throughput of one device with XLA's intra-op threads (README, Performance). Returns the number of CPU devices JAX
    has: unchanged if its backend was already initialised (e.g. a CLI's ``main`` called
    twice in one process)."""
    import jax

    try:
        jax.config.update("jax_num_cpu_devices", int(n))
    except RuntimeError:  # the backend exists already
        pass
    return len(jax.devices("cpu"))


def claim_devices(devices: int | None) -> int:
    """A CLI's ``--devices`` (None: one per usable core): ask JAX for that many CPU devices
    (call before the process's first JAX computation). → the count JAX has.

    Raises ValueError, naming the option, for anything but an integer >= 1; notes on stderr
    when JAX's backend already had another count (e.g. a CLI's ``main`` called twice)."""
    if devices is not None and (isinstance(devices, bool) or not isinstance(devices, int) or devices < 1):
        raise ValueError(f"--devices must be >= 1, got {devices!r}")
    have = use_cpu_devices(devices or usable_cores())
    if devices is not None and have != devices:
        print(f"note: JAX's CPU backend was already initialised with {have} device(s); using them",
              file=sys.stderr)
    return have


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
    use_cpu_devices(usable_cores())  # before any JAX computation: the rows are shared out
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


Pose = tuple[float, float, float, float, float, float]


@dataclass(frozen=True)
class PlanArgs:
    """Plan one certified docking trajectory and write trajectory.csv, summary.json,
    front.png and trajectory.png into --out. Exit codes: 0 planned, 1 no trajectory meets
    the limits (the limit is named), 2 bad input."""

    start: Pose = (775.0, -35.0, -1315.0, 0.2, -0.2, 190.0)
    """Measured cabin pose x y z [mm] pitch yaw roll [deg]."""
    goal: Pose = (745.0, -5.0, -1515.0, 0.0, 0.0, 180.0)
    """Docking pose x y z [mm] pitch yaw roll [deg]."""
    limits: Path | None = None
    """TOML or JSON file overriding travel, velocity, acceleration (4 or 8 numbers) and home (8)."""
    arm_distance: float = 2000.0
    """Distance D2 between the arm ends [mm]."""
    interval_bounds: tuple[float, float] = (3.5, 10.0)
    """Bounds of each of the six knot intervals [s]."""
    select: Literal["compromise", "time", "smooth"] = "compromise"
    """Which point of the front (paper Table 4 types)."""
    weights: tuple[float, float] | None = None
    """Weights (w_T, w_jerk) of Eq. 26; overrides --select."""
    rate: float = 1000.0
    """Servo rate of the CSV [Hz]."""
    pop: int = 150
    """Optimiser population."""
    iters: int = 100
    """Optimiser iterations."""
    seed: int = 0
    """Random seed."""
    refine: bool = True
    """Polish the optimiser's front with gradient refinement (dockjax.refine) before choosing."""
    out: Path = Path("plan")
    """Output folder."""
    devices: int | None = None
    """CPU devices the work is shared over (the run is the same for any count, the
    refinement's scores equal to rounding). Default: one per usable core."""


def plan_cmd(args: PlanArgs) -> int:
    import math

    from . import DockingProblem, select
    from .plan import PlanError, load_limits, plan, write_plan

    def bad(msg: str) -> int:
        print(f"error: {msg}", file=sys.stderr)
        return 2

    for name in ("start", "goal"):
        if not all(math.isfinite(v) for v in getattr(args, name)):
            return bad(f"--{name} must be six finite numbers, got {list(getattr(args, name))}")
    if not (math.isfinite(args.rate) and args.rate > 0):
        return bad(f"--rate must be > 0, got {args.rate}")
    if args.pop < 4 or args.iters < 1:
        return bad(f"--pop must be >= 4 and --iters >= 1, got {args.pop} and {args.iters}")
    weights = args.weights if args.weights is not None else select.PAPER_TYPES[args.select]
    try:
        claim_devices(args.devices)  # before any JAX computation (DockingProblem computes)
        select.check_weights(weights, 2)
        extra = load_limits(args.limits) if args.limits is not None else {}
        problem = DockingProblem(start=args.start, goal=args.goal, arm_distance=args.arm_distance,
                                 interval_bounds=args.interval_bounds, **extra)
    except ValueError as exc:
        return bad(str(exc))
    if args.out.exists() and not args.out.is_dir():
        return bad(f"--out {args.out} exists and is not a folder")
    enable_compilation_cache()
    try:
        p = plan(problem, weights=weights, rate=args.rate, pop_size=args.pop, n_iter=args.iters,
                 seed=args.seed, refine=args.refine)
    except PlanError as exc:
        print(f"no plan: {exc}", file=sys.stderr)
        return 1
    try:
        files = write_plan(p, args.out)
    except OSError as exc:
        return bad(f"--out {args.out} cannot be written: {exc}")
    print(f"planned T = {p.T:.3f} s, jerk = {p.jerk:.5g}; every limit certified at {args.rate:g} Hz "
          f"and at the exact extrema per knot span")
    for f in files:
        print(f"  wrote {f}")
    return 0


def main() -> None:
    """``dockjax plan ...`` / ``dockjax demo ...``."""
    import tyro

    cmd = tyro.extras.subcommand_cli_from_dict({"plan": PlanArgs, "demo": DemoArgs})
    sys.exit(plan_cmd(cmd) if isinstance(cmd, PlanArgs) else demo(cmd))
