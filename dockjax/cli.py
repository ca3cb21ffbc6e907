"""The command line: ``dockjax sweep | compare | plan | track | demo`` (tyro), in one module.

Each subcommand is a frozen dataclass of options (defaults from :mod:`dockjax.config`) and a
function that validates them before any compilation (bad input, a parse error included:
one line on stderr, exit code 2, nothing written), then calls the library. The scripts in
``experiments/`` are thin wrappers: ``python experiments/sweep.py ARGS`` is ``dockjax sweep
ARGS``. The algorithms an option accepts are those of the registry
(:data:`dockjax.algorithms.ALGORITHMS`).

The command lines (not the library) turn on JAX's persistent compilation cache and ask
for one CPU device per usable core (:mod:`dockjax.runtime`). Each subcommand imports the
part of the library it runs, so that ``dockjax plan`` does not load the study machinery.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import io
import os
import re
import shutil
import signal
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal, Sequence

import numpy as np
import tyro

from . import checks, config
from .algorithms import ALGORITHMS
from .io import DamagedFileError, FolderLock, make_folders
from .runtime import check_memory, claim_devices, enable_compilation_cache, usable_cores, use_cpu_devices
from .track import AxisModel

__all__ = ["SweepArgs", "CompareArgs", "PlanArgs", "DemoArgs", "sweep", "compare", "plan", "demo", "main",
           "exit_with", "describe_failure", "check_out", "TrackArgs", "track"]

Algorithm = Literal[tuple(ALGORITHMS)]
Method = Literal[("direct", *ALGORITHMS)]
Preset = Literal["paper", "wide"]
Pose = tuple[float, float, float, float, float, float]


def _error(message: str) -> int:
    print(f"error: {message}", file=sys.stderr)
    return 2


ROOM = 200
"""Bytes of path kept free below PATH_MAX for the files a command writes inside --out."""


def check_out(path: Path, option: str = "--out") -> None:
    """ValueError unless ``path`` is, or can be created as, a writable folder whose files
    fit the file system's name and path limits; creates nothing."""
    path = Path(os.path.abspath(path))
    base = path
    while not base.exists():
        base = base.parent
    if not base.is_dir():
        raise ValueError(f"{option} {path} " + ("is not a folder" if base == path else
                                                f"cannot be created: {base} is not a folder"))
    try:
        name_max = os.pathconf(base, "PC_NAME_MAX")
        path_max = os.pathconf(base, "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    for part in path.relative_to(base).parts:
        if len(os.fsencode(part)) > name_max:
            raise ValueError(f"{option}: the name {part[:40]}... is {len(os.fsencode(part))} bytes, over the file "
                             f"system's {name_max}")
    if len(os.fsencode(str(path))) > path_max - ROOM:
        raise ValueError(f"{option} {str(path)[:60]}... is too long: {len(os.fsencode(str(path)))} bytes, the files "
                         f"inside need it below {path_max - ROOM}")
    if not os.access(base, os.W_OK | os.X_OK):
        raise ValueError(f"{option} {path}: {base} is not writable")


# -------------------------------------------------------------------------------- sweep
@dataclass(frozen=True)
class SweepArgs:
    """Hyper-parameter studies that never lose work: one or more algorithms, any of their hyper-parameters (grids,
    random or Sobol samples), population sizes and iteration counts, on common seeds or raced; every finished chunk of
    runs is saved atomically in --out, and re-running the same command resumes where it stopped. Writes runs.csv,
    summary.csv (intervals, tests against the best, effect sizes), report.md and figures. See docs/cli.md."""

    algorithm: tuple[Algorithm, ...] = ("imocs",)
    """Optimiser(s); several give a head-to-head on common seeds."""
    param: tuple[str, ...] = ()
    """Hyper-parameter values: NAME=v1,v2,... (a grid) or NAME=lo:hi (a range, sampled by --design); NAME is a
    Params field (e.g. rho, p_a, eta_c, w) or algorithm.field (e.g. nsga2.eta_m)."""
    rho: tuple[float, ...] = config.SWEEP_RHO
    """IMOCS's ρ grid, each in (0, 1) (the same as --param imocs.rho=...)."""
    alpha_max: tuple[float, ...] = config.SWEEP_ALPHA_MAX
    """IMOCS's α_max grid, each > 0 (the same as --param imocs.alpha_max=...)."""
    pop: tuple[int, ...] = (config.POP_SIZE,)
    """Population size(s), each >= 4 (one compilation per size)."""
    iters: tuple[int, ...] = (config.SWEEP_ITERS,)
    """Iteration count(s) per run."""
    budget: int | None = None
    """Budget-matched design: iterations = BUDGET // population for each --pop (instead of --iters)."""
    design: Literal["grid", "random", "sobol"] = "grid"
    """How the ranges of --param are sampled: grid (no ranges), random or sobol."""
    samples: int = 0
    """Points drawn from the box of the --param ranges (with --design random or sobol)."""
    design_seed: int = 0
    """Seed of the random or Sobol samples."""
    seeds: int = config.SWEEP_SEEDS
    """Runs per setting: seeds 0 .. N-1 (the same seeds for every setting); with --race, the seed budget."""
    race: bool = False
    """Race the settings: seeds in rounds, dropping settings significantly worse than the best (Friedman, then
    Conover's post-hoc test)."""
    race_min_seeds: int = 5
    """Seeds every setting gets before the first elimination."""
    race_alpha: float = 0.05
    """Significance level of the race's tests."""
    preset: Preset = "paper"
    """Problem preset: paper (h in [3.5, 10] s) or wide (h in [0.5, 10] s)."""
    n_control: int = config.N_FREE
    """Free control points of the problem's quintic B-spline (1 to 64; the paper's 5)."""
    instances: str | None = None
    """Moves to study over: a TOML file of [[instance]] tables (start, goal; optionally arm_distance,
    interval_bounds, n_control, limits) or random:N (N moves drawn around the paper's, seeded by --instance-seed);
    every setting runs every seed on every instance, each scored against its own reference front. See docs/cli.md."""
    instance_seed: int = 0
    """Seed of the moves drawn by --instances random:N (and --test-instances random:M)."""
    test_instances: str | None = None
    """Held-out moves (a file or random:M, as --instances; random moves follow the training ones in the same seeded
    draw, so none is a training move): afterwards the best setting and every one tied with it run the same seeds on
    them, in --out/test/, and report.md says whether the ranking held."""
    ablation: bool = False
    """Afterwards, the ablation path from the algorithm's defaults to the best setting: one hyper-parameter a step,
    each step's candidates run as a study in --out/ablation/step-K/; report.md gives each step's HV change and its
    Wilcoxon p-value."""
    refine_steps: int = 0
    """Memetic finish: polish every run's final population with this many gradient-refinement steps (dockjax.refine;
    the algorithm column then reads e.g. imocs+refine). 0: off."""
    out: Path = Path("results/sweep")
    """Results folder (created). Re-run the same command on it to resume; a folder holding a different configuration
    is refused."""
    chunk: int = config.SWEEP_CHUNK
    """Maximum runs per compiled call (part of the configuration: changing it refuses to resume)."""
    reference: Literal["best-known", "pilot", "file"] = "best-known"
    """Reference front of the indicators: the best-known front of the problem (computed once per problem and cached
    in $DOCKJAX_FRONTS or ~/.cache/dockjax/fronts), a pilot of the first algorithm, or --reference-front."""
    reference_front: Path | None = None
    """A stored front (.npz with key 'front', or .csv with columns T, jerk) to score against (implies --reference
    file)."""
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
    """CPU devices the runs of a chunk are sharded over (docs/performance.md for the speed-up). Default: one per
    usable core. Part of the configuration: the order of some floating-point sums depends on it, and an optimiser's
    choices can diverge from such a difference, so a folder resumes only with the count it was started with."""


def _study_devices(args: SweepArgs, here: int) -> int | None:
    """The CPU devices a study's chunks run on, part of its identity (the numbers depend on
    it): this process's for the local backend and a Dask cluster of threads started here,
    one for a cluster of processes started here (each worker a fresh process with JAX's
    one CPU device), unknown (None) for a scheduler's workers elsewhere."""
    if args.backend == "local" or (args.scheduler is None and not args.dask_processes):
        return here
    return 1 if args.scheduler is None else None


def _param_specs(args: SweepArgs):
    """--param, plus IMOCS's --rho/--alpha-max grids unless --param names those fields."""
    from .sweep import parse_param
    from .sweep.design import ParamSpec

    specs = [parse_param(p) for p in args.param]
    named = {(s.algorithm, s.field) for s in specs}
    for field, values, default in (("rho", args.rho, SweepArgs.rho), ("alpha_max", args.alpha_max,
                                                                        SweepArgs.alpha_max)):
        if (None, field) in named or ("imocs", field) in named:
            if values != default:
                raise ValueError(f"--{field.replace('_', '-')} and --param {field} both give {field}")
            continue
        if "imocs" in args.algorithm:
            if not values:
                raise ValueError(f"--{field.replace('_', '-')} grid is empty (give at least one value)")
            specs.append(ParamSpec(field, "imocs", values=tuple(values)))
    return specs


def sweep(args: SweepArgs) -> int:
    """Validate (exit 2 before any compilation, without leaving a folder behind), run the
    missing chunks, report."""
    from .sweep import ConfigError, claim_folder, make_config

    errors = [f"{name} must be >= 1, got {v}" for name, v in (("--workers", args.workers), ("--top", args.top))
              if v < 1]
    if args.workers > 4 * usable_cores():
        errors.append(f"--workers {args.workers} is more than four per usable core ({usable_cores()})")
    if args.scheduler is not None and args.backend != "dask":
        errors.append("--scheduler needs --backend dask")
    if args.backend == "dask":
        try:
            import distributed  # noqa: F401
        except ImportError:
            errors.append("--backend dask needs Dask distributed: pip install 'dockjax[distributed]'")
    try:
        pop = max(args.pop) if args.pop else config.POP_SIZE
        checks.integer("--n-control", args.n_control, 1, config.MAX_CONTROL)
        check_memory(min(args.chunk, args.seeds) * 2 * pop * config.candidate_bytes(args.n_control),
                     "a chunk of --chunk runs at --pop")
        check_memory(args.seeds * (2 * pop * 2 + 1024) * 8, "storing --seeds runs")
        check_out(args.out)
        n_devices = claim_devices(args.devices)  # before any JAX computation
    except ValueError as exc:
        return _error(str(exc))
    try:
        try:
            specs = _param_specs(args)
            instances = _moves("--instances", args.instances, args)
            skip = len(instances) if (args.instances or "").startswith("random:") else 0
            test_instances = _moves("--test-instances", args.test_instances, args, skip)
            cfg, front = make_config(algorithms=args.algorithm, params=specs, pop=args.pop, iters=args.iters,
                                     budget=args.budget, design=args.design, samples=args.samples,
                                     design_seed=args.design_seed, seeds=args.seeds, preset=args.preset,
                                     refine_steps=args.refine_steps, chunk=args.chunk, reference=args.reference,
                                     reference_front=args.reference_front, race=args.race,
                                     race_min_seeds=args.race_min_seeds, race_alpha=args.race_alpha,
                                     devices=_study_devices(args, n_devices), n_control=args.n_control,
                                     instances=instances, test_instances=test_instances)
        except ValueError as exc:
            raise ConfigError("; ".join([str(exc), *errors])) from None
        if errors:
            raise ConfigError("; ".join(errors))
        claim = claim_folder(args.out, cfg, command=_command("sweep"))
    except ConfigError as exc:
        return _error(str(exc))
    if "imocs" not in args.algorithm and (args.rho != SweepArgs.rho or args.alpha_max != SweepArgs.alpha_max):
        print("note: --rho and --alpha-max apply to IMOCS only")
    enable_compilation_cache()
    t0 = time.perf_counter()
    code = _run_study(cfg, claim, front=front, backend=args.backend, scheduler=args.scheduler,
                      workers=args.workers, dask_processes=args.dask_processes, progress=args.progress, top=args.top,
                      ablation=args.ablation)
    if code == 0:
        print(f"total {time.perf_counter() - t0:.1f} s")
    return code


def _moves(option: str, spec: str | None, args: SweepArgs, skip: int = 0) -> tuple:
    """The instances ``option`` gives (none when not given), or ValueError naming it."""
    from .instances import parse_instances

    if spec is None:
        return ()
    try:
        return parse_instances(spec, seed=args.instance_seed, preset=args.preset, n_control=args.n_control, skip=skip)
    except ValueError as exc:
        raise ValueError(f"{option}: {exc}") from None


def _command(name: str) -> str:
    """This process's command line, as the holder of a folder is named to another."""
    return " ".join(["dockjax", name, *(a for a in sys.argv[1:] if a != name)])


def _run_study(cfg, claim, *, top: int, extensions=(), ablation: bool = False, **options) -> int:
    """Run the missing chunks of a study folder this process holds (:func:`dockjax.sweep.
    claim_folder`, :func:`dockjax.sweep.run_sweep`) and report it, then release the folder;
    the exit code (0, 1 when the work cannot complete, 130 interrupted)."""
    from .sweep import ConfigError, report, run_sweep
    from .sweep.ablation import ablation_section, run_ablation
    from .sweep.testset import run_test_set, test_section

    out = claim.out
    finished = lambda: any((out / "chunks").glob("round-*.npz"))  # noqa: E731
    try:
        run_sweep(cfg, out, **options)
        if cfg.test_instances:
            run_test_set(cfg, out, top=top, **options)
            extensions = (*extensions, test_section)
        if ablation:
            extensions = (*extensions, ablation_section(run_ablation(cfg, out, top=top, **options)))
        report(out, top=top, extensions=extensions)
        return 0
    except ConfigError as exc:  # e.g. an unreachable scheduler; nothing was computed
        if not finished():
            claim.abandon()
        return _error(str(exc))
    except KeyboardInterrupt:
        done = list((out / "chunks").glob("round-*.npz"))
        print("\ninterrupted: " + (f"{len(done)} finished chunks are saved in {out / 'chunks'}; re-run the same "
                                   "command to resume" if done else "no chunk had finished"), file=sys.stderr)
        return 130
    except RuntimeError as exc:  # e.g. the reference holds no feasible trajectory
        if not finished():
            claim.abandon()
        print(f"error: {exc}", file=sys.stderr)
        return 1
    finally:
        claim.release()


# ------------------------------------------------------------------------------ compare
@dataclass(frozen=True)
class CompareArgs:
    """Reproduce the paper's comparison (§5) as a study: the algorithms × seeds on each preset against the best-known
    front, with the statistics of every sweep (bootstrap intervals, Friedman, Wilcoxon-Holm against the best, A12),
    plus the paper's indicators, Tables 3 and 4 and its figures, into --out/<preset>/ (a sweep folder: interrupt it
    and run the command again to resume)."""

    out: Path = Path("results/compare")
    """Results folder (created; one study folder per preset)."""
    seeds: int = config.N_SEEDS
    """Runs per algorithm (seeds 0 .. seeds-1, the same for every algorithm)."""
    pop: int = config.POP_SIZE
    """Population size."""
    iters: int = config.N_ITER
    """Iterations per run."""
    presets: tuple[Preset, ...] = tuple(config.PRESETS)
    """Problem presets to run."""
    n_control: int = config.N_FREE
    """Free control points of the problem's quintic B-spline (1 to 64; the paper's 5)."""
    algorithms: tuple[Algorithm, ...] = ("nsga2", "mopso", "mocs", "imocs")
    """Algorithms to compare."""
    refine_steps: int = config.MEMETIC_STEPS
    """Gradient-refinement steps of the "IMOCS + refine" setting (every IMOCS run's final population polished by
    dockjax.refine); 0 leaves it out."""
    best_known_points: int = config.BEST_KNOWN["n_points"]
    """Time caps of the best-known front's ε-constraint sweep (>= 2); the front is cached by problem identity in
    $DOCKJAX_FRONTS or ~/.cache/dockjax/fronts, shared with dockjax sweep."""
    best_known_anchors: int = config.BEST_KNOWN["n_exact"]
    """Time caps of the best-known front solved by sequential quadratic programming (>= 2), the anchors that the
    refined caps start from."""
    best_known_steps: int = config.BEST_KNOWN["steps"]
    """Refinement steps per time cap of the best-known front."""
    top: int = 10
    """Rows of each summary table printed."""
    progress: bool = True
    """Show a progress bar on stderr."""
    devices: int | None = None
    """CPU devices the work is shared over (the order of some floating-point sums depends on the count, so runs
    agree to rounding at first and may then diverge; a folder resumes only with its count). Default: one per
    usable core."""


def compare(args: CompareArgs) -> int:
    """Validate, then run and report each preset's study."""
    from .sweep import ConfigError, claim_folder, paper_config, paper_tables

    errors = [f"--{name} must be >= 1, got {v}" for name, v in (("top", args.top),) if v < 1]
    if not args.presets:
        errors.append("--presets must name at least one preset")
    try:
        checks.integer("--n-control", args.n_control, 1, config.MAX_CONTROL)
        check_memory(args.seeds * 2 * args.pop * config.candidate_bytes(args.n_control), "--seeds runs at --pop")
        check_out(args.out)
        checks.optional_integer("--devices", args.devices, 1)
    except ValueError as exc:
        errors.append(str(exc))
    configs = {}
    for preset in dict.fromkeys(args.presets):
        try:
            configs[preset] = paper_config(preset, seeds=args.seeds, pop=args.pop, iters=args.iters,
                                           algorithms=args.algorithms, refine_steps=args.refine_steps,
                                           best_known={"n_points": args.best_known_points,
                                                       "n_exact": args.best_known_anchors,
                                                       "steps": args.best_known_steps}, devices=None,
                                           n_control=args.n_control)
        except ConfigError as exc:
            errors.append(str(exc))
            break
    if errors:
        return _error("; ".join(dict.fromkeys(errors)))
    n_devices = claim_devices(args.devices)  # before any JAX computation
    claims = []
    try:
        for preset, cfg in configs.items():
            configs[preset] = cfg = dataclasses.replace(cfg, devices=n_devices)
            claims.append(claim_folder(args.out / preset, cfg, command=_command("compare")))
    except ConfigError as exc:
        for claim in claims:
            claim.abandon()
        if args.out.is_dir() and not any(args.out.iterdir()):
            args.out.rmdir()  # made for the presets' folders, now empty
        return _error(str(exc))
    enable_compilation_cache()
    t0 = time.perf_counter()
    for i, (preset, cfg) in enumerate(configs.items()):
        print(f"[{preset}] the paper's comparison: {', '.join(s.name for s in cfg.settings)}; {cfg.seeds} seeds")
        code = _run_study(cfg, claims[i], top=args.top, extensions=[paper_tables], progress=args.progress)
        if code:
            for claim in claims[i + 1:]:
                claim.release()
            return code
    print(f"wall time: {time.perf_counter() - t0:.1f} s")
    return 0


# --------------------------------------------------------------------------------- plan
@dataclass(frozen=True)
class PlanArgs:
    """Plan one certified docking trajectory and write trajectory.csv, summary.json and three figures (front.png,
    trajectory.png, limits.png) into --out, and with --export the controller files. Exit codes: 0 planned, 1 no
    trajectory meets the limits (the limit is named), 2 bad input."""

    start: Pose = config.START
    """Measured cabin pose x y z [mm] pitch yaw roll [deg]."""
    goal: Pose = config.GOAL
    """Docking pose x y z [mm] pitch yaw roll [deg]."""
    limits: Path | None = None
    """TOML or JSON file overriding travel, velocity, acceleration, jerk (4 or 8 numbers; 4K with --supports) and
    home (8; 4K)."""
    arm_distance: float = config.ARM_DISTANCE
    """Distance D2 between the arm ends [mm]."""
    supports: tuple[float, ...] | None = None
    """Offsets [mm] along the cabin axis of K >= 2 supports, the first 0 (default: the two arms at 0 and
    --arm-distance); each support has the four joints of an arm, and a limits file then gives 4 or 4K numbers."""
    interval_bounds: tuple[float, float] = config.INTERVAL_BOUNDS
    """Bounds of each knot interval [s] (n-control + 1 of them)."""
    n_control: int = config.N_FREE
    """Free control points of the quintic B-spline (1 to 64; the paper's 5): more points reach shorter times
    and smoother plans, at more solve time."""
    select: Literal["compromise", "time", "smooth"] = "compromise"
    """Which point of the front (paper Table 4 types)."""
    weights: tuple[float, float] | None = None
    """Weights (w_T, w_jerk) of Eq. 26; overrides --select."""
    duration: float | None = None
    """Plan of exactly this many seconds: the least jerk at that duration, overriding --select and --weights (exit 1
    below the shortest feasible time, naming the limit that binds it)."""
    rate: float = config.RATE
    """Servo rate of the CSV and the exports [Hz]."""
    move: Path | None = None
    """A staged move (TOML): start, goal and [[via]] poses, each with stop = true|false, dwell [s] and [via.limits]
    (scale = 0.1, or limit keys) for the stage that leaves it. Overrides --start and --goal where it gives them."""
    export: tuple[Literal["ros2", "axes"], ...] = ()
    """Controller files: ros2 writes trajectory_ros2.yaml and .json (a ROS 2 trajectory_msgs/JointTrajectory in m and
    rad, points at every knot time and at --rate), axes one set-point CSV per joint (axis-<joint>.csv at --rate)."""
    method: Method = "direct"
    """How the front is found: direct (shortest time, then the least jerk at --n-front time caps, by SQP) or an
    optimiser run (--pop, --iters, --seed, --refine-steps) whose chosen point is then solved to least jerk."""
    n_front: int = config.PLAN_FRONT
    """Time caps of the direct method's least-jerk front."""
    explain: bool = False
    """Print which limits bind and what each is worth (d T_min/d limit or d jerk/d limit), checked by
    re-planning with each binding limit changed by ±1 %."""
    pop: int = config.POP_SIZE
    """Optimiser population (--method other than direct)."""
    iters: int = config.N_ITER
    """Optimiser iterations (--method other than direct)."""
    seed: int = 0
    """Random seed (--method other than direct)."""
    refine_steps: int = config.PLAN_REFINE_STEPS
    """Steps of gradient refinement (dockjax.refine) polishing the optimiser's front; 0: none."""
    out: Path = Path("plan")
    """Output folder."""
    devices: int | None = None
    """CPU devices the work is shared over (for an optimiser the results may differ by the count, as for
    compare). Default: one per usable core for an optimiser, one for --method direct."""
    progress: bool = True
    """Show the step under way on stderr, when it is a terminal (a plan of many control points takes minutes)."""


PLAN_OPTIONS = {"weights": "--weights", "rate": "--rate", "method": "--method", "pop_size": "--pop",
                "n_iter": "--iters", "seed": "--seed", "refine_steps": "--refine-steps", "n_front": "--n-front",
                "start": "--start", "goal": "--goal", "arm_distance": "--arm-distance", "supports": "--supports",
                "interval_bounds": "--interval-bounds", "duration": "--duration", "n_control": "--n-control"}
"""The library's argument names of a plan and the options that give them."""


def _as_option(message: str, names: dict[str, str]) -> str:
    """A library error naming an argument (``"rate must be ..."``) as one naming its option."""
    head, sep, rest = message.partition(" ")
    return f"{names[head]}{sep}{rest}" if head in names else message


@contextlib.contextmanager
def _holding(out: Path, name: str):
    """A command's output folder for its whole run: created if missing and held by this
    process alone (:class:`dockjax.io.FolderLock`; another process holding it is refused
    with exit 2, naming it). Yields a list; the caller appends the files it wrote. Folders
    created here are removed again when nothing was written."""
    created = make_folders(out)
    lock = FolderLock(out, _command(name))
    lock.acquire()
    written: list[Path] = []
    try:
        yield written
    finally:
        if not written and created:
            shutil.rmtree(created[0], ignore_errors=True)
        lock.release(remove=not written and lock.created_file and not created)


def _make_plan(problem, weights, rate: float, **options):
    """:func:`dockjax.plan.plan` with the command line's failure: ``(plan, 0)``, or
    ``(None, 1)`` after one line naming the limit no trajectory meets."""
    from .plan import PlanError
    from .plan import plan as make_plan

    enable_compilation_cache()
    try:
        return make_plan(problem, weights=weights, rate=rate, **options), 0
    except PlanError as exc:
        print(f"no plan: {exc}", file=sys.stderr)
        return None, 1


def plan(args: PlanArgs) -> int:
    """Validate, plan, certify, write."""
    from . import select
    from .plan import check_duration, check_move, check_options, explain_text, load_limits, write_plan
    from .problem import DockingProblem

    weights = args.weights if args.weights is not None else select.PAPER_TYPES[args.select]
    if args.move is not None:
        return _plan_staged(args, weights)
    try:
        check_options(weights, args.rate, args.method, args.pop, args.iters, args.seed, args.refine_steps,
                      args.n_front)
        checks.integer("n_control", args.n_control, 1, config.MAX_CONTROL)
        if args.method != "direct":
            check_memory(2 * args.pop * config.candidate_bytes(args.n_control), "--pop")
        check_memory((args.n_control + 1) * max(args.interval_bounds[1], 1.0) * args.rate * 4
                     * max(2, len(args.supports or ())) * 100, "--rate over the longest trajectory")
        check_out(args.out)
        # before any JAX computation (DockingProblem computes); the direct method solves one
        # trajectory at a time, which one device does fastest
        claim_devices(args.devices if args.devices is not None or args.method != "direct" else 1)
        extra = load_limits(args.limits) if args.limits is not None else {}
        problem = DockingProblem(start=args.start, goal=args.goal, arm_distance=args.arm_distance,
                                 supports=args.supports, interval_bounds=args.interval_bounds,
                                 n_control=args.n_control, **extra)
        if args.export and problem.supports is not None:
            raise ValueError(f"--export is for the paper's two arms; --supports gives {problem.n_supports}")
        check_move(problem)
        check_duration(problem, args.duration)
    except ValueError as exc:
        return _error(_as_option(str(exc), PLAN_OPTIONS))
    with _holding(args.out, "plan") as files:
        p, code = _make_plan(problem, weights, args.rate, method=args.method, pop_size=args.pop, n_iter=args.iters,
                             seed=args.seed, refine_steps=args.refine_steps, n_front=args.n_front,
                             check_sensitivities=args.explain, duration=args.duration,
                             progress=args.progress and sys.stderr.isatty())
        if p is None:
            return code
        files += write_plan(p, args.out, export=args.export)
    print(f"planned T = {p.T:.3f} s, jerk = {p.jerk:.5g} (shortest feasible T = {p.settings['shortest_T_s']:.3f} s); "
          f"every limit certified at {args.rate:g} Hz and by the kernel's rigorous per-span maxima")
    if args.explain:
        print(explain_text(p.explanation))
    for f in files:
        print(f"  wrote {f}")
    return 0


def _plan_staged(args: PlanArgs, weights) -> int:
    """``dockjax plan --move FILE``: validate, plan every stage together, certify, write."""
    from .plan import PlanError, check_options
    from .stages import load_move_problem, plan_staged, stage_problems, write_staged

    try:
        for option, given in (("--duration", args.duration is not None), ("--export", bool(args.export)),
                              ("--explain", args.explain), ("--method", args.method != "direct"),
                              ("--supports", args.supports is not None)):
            if given:
                why = ("; every stage's binding limits are printed and written to summary.json"
                       if option == "--explain" else "")
                raise ValueError(f"{option} does not apply to a staged move (--move){why}")
        check_options(weights, args.rate, args.method, args.pop, args.iters, args.seed, args.refine_steps,
                      args.n_front)
        checks.integer("n_control", args.n_control, 1, config.MAX_CONTROL)
        check_out(args.out)
        claim_devices(1)
        problem, vias = load_move_problem(args.move, args.limits, start=args.start, goal=args.goal,
                                          arm_distance=args.arm_distance, interval_bounds=args.interval_bounds,
                                          n_control=args.n_control)
        stage_problems(problem, vias)  # every stage checked before any solve
    except ValueError as exc:
        return _error(_as_option(str(exc), PLAN_OPTIONS))
    enable_compilation_cache()
    with _holding(args.out, "plan") as files:
        try:
            sp = plan_staged(problem, vias, weights=weights, rate=args.rate, n_front=args.n_front)
        except PlanError as exc:
            print(f"no plan: {exc}", file=sys.stderr)
            return 1
        files += write_staged(sp, args.out)
    print(f"planned a staged move of {len(sp.stages)} stages: T = {sp.T:.3f} s, jerk = {sp.jerk:.5g}; every stage "
          f"certified at {args.rate:g} Hz and by the kernel's rigorous per-span maxima")
    for k, st in enumerate(sp.stages, 1):
        binding = ", ".join(b["limit"] for b in st.binding) or "none"
        print(f"  stage {k}: from t = {st.start_s:.3f} s for {st.T:.3f} s; binding limits: {binding}")
    for f in files:
        print(f"  wrote {f}")
    return 0


# --------------------------------------------------------------------------------- demo
@dataclass(frozen=True)
class DemoArgs:
    """Score a random population of the paper's docking problem in one compiled call and print the best feasible
    candidates (the non-dominated ones)."""

    n: int = 100_000
    """Population size (candidates drawn uniformly in the decision box)."""
    seed: int = 0
    """Seed of the random population."""
    top: int = 10
    """How many non-dominated feasible candidates to print (spread along the front)."""
    precision: Literal["float64", "float32"] = "float64"
    """Arithmetic of the kernel."""


def demo(args: DemoArgs) -> int:
    """Score, print the feasible non-dominated candidates."""
    if args.n < 1:
        return _error(f"--n must be >= 1, got {args.n}")
    if args.top < 1:
        return _error(f"--top must be >= 1, got {args.top}")
    if not 0 <= args.seed < 2**63:
        return _error(f"--seed must lie in [0, 2**63), got {args.seed}")
    try:
        check_memory(args.n * config.BYTES_PER_CANDIDATE, "--n")
    except ValueError as exc:
        return _error(str(exc))
    use_cpu_devices(usable_cores())  # before any JAX computation: the rows are shared out
    enable_compilation_cache()
    from .metrics import nondominated_points
    from .problem import DockingProblem

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
    front = nondominated_points(F[feasible])
    pick = np.unique(np.linspace(0, len(front) - 1, min(args.top, len(front))).round().astype(int))
    print(f"non-dominated feasible candidates: {len(front)}; showing {len(pick)}")
    print(f"{'T [s]':>10}  {'jerk':>10}")
    for i in pick:
        print(f"{front[i, 0]:10.4f}  {front[i, 1]:10.4f}")
    return 0


# --------------------------------------------------------------------------------- track
@dataclass(frozen=True)
class TrackArgs:
    """Plan a move, then simulate each joint's servo loop following it at the controller rate (the paper's §6):
    write tracking.json (max position and velocity errors per joint, the axis model), tracking.csv and
    tracking.png (planned against tracked position and velocity of the moving joints) into --out.
    Exit codes: 0 tracked, 1 no trajectory meets the limits, 2 bad input."""

    move: Literal["x", "z", "custom"] = "x"
    """The paper's X move (4.04 to -1.514 mm) or Z move (-1591.03 to -1601.47 mm), or custom (--start, --goal)."""
    start: Pose | None = None
    """Start pose for --move custom: x y z [mm] pitch yaw roll [deg]."""
    goal: Pose | None = None
    """Goal pose for --move custom."""
    interval_bounds: tuple[float, float] = config.INTERVAL_BOUNDS
    """Bounds of each of the six knot intervals [s]."""
    weights: tuple[float, float] = (1.0, 1.0)
    """Weights (w_T, w_jerk) of Eq. 26 choosing the planned trajectory."""
    rate: float = config.RATE
    """Controller rate [Hz]."""
    model: Annotated[AxisModel, tyro.conf.OmitArgPrefixes] = AxisModel()
    """Every joint's drive and servo loop (dockjax.track.AxisModel; the same for every joint)."""
    out: Path = Path("track")
    """Output folder."""


TRACK_OPTIONS = {"rate": "--rate", "weights": "--weights", "start": "--start", "goal": "--goal",
                 "interval_bounds": "--interval-bounds",
                 **{f"model.{f.name}": f"--{f.name.replace('_', '-')}" for f in dataclasses.fields(AxisModel)}}
"""The library's argument names of a tracking run and the options that give them."""


def track(args: TrackArgs) -> int:
    """Validate, plan, simulate, write."""
    from . import select
    from . import track as servo
    from .problem import DockingProblem

    if args.move == "custom":
        if args.start is None or args.goal is None:
            return _error("--move custom needs --start and --goal")
        start, goal = args.start, args.goal
    else:
        if args.start is not None or args.goal is not None:
            return _error(f"--start/--goal need --move custom (--move {args.move} is the paper's move)")
        start, goal = servo.PAPER_MOVES[args.move]
    try:
        select.check_weights(args.weights, 2)
        largest = servo.check_model(args.model, args.rate, config.N_JOINTS)
        check_out(args.out)
        use_cpu_devices(1)  # before any JAX computation: one trajectory, one device
        problem = DockingProblem(start=start, goal=goal, interval_bounds=args.interval_bounds)
    except ValueError as exc:
        return _error(_as_option(str(exc), TRACK_OPTIONS))
    with _holding(args.out, "track") as files:
        p, code = _make_plan(problem, args.weights, args.rate, check_sensitivities=False)
        if p is None:
            return code
        result = servo.track(p.samples, args.model, args.rate)
        files += servo.write_tracking(result, p, args.out, move=args.move, largest_pole=largest)
    print(f"planned T = {p.T:.3f} s; servo at {args.rate:g} Hz (largest closed-loop |z| = {largest:.4f})")
    print(f"{'joint':<8} {'max |position error|':>22} {'max |velocity error|':>22} {'measured velocity':>18}")
    for j in servo.moving_joints(p.samples):
        u = config.JOINT_UNITS[j]
        print(f"{config.JOINT_NAMES[j]:<8} {result.max_position_error[j]:>18.3g} {u:<3} "
              f"{result.max_velocity_error[j]:>16.3g} {u}/s {result.max_measured_velocity_error[j]:>12.3g} {u}/s")
    if args.move in servo.PAPER_ERRORS:
        (pe, ve), joint = servo.PAPER_ERRORS[args.move], config.JOINT_NAMES[servo.PAPER_JOINTS[args.move]]
        print(f"paper §6 ({joint}, hardware): {pe} mm, {ve} mm/s")
    print(f"  wrote {', '.join(str(f) for f in files)}")
    return 0


# ------------------------------------------------------------------------------ dispatch
COMMANDS = {"sweep": (SweepArgs, sweep), "compare": (CompareArgs, compare), "plan": (PlanArgs, plan),
            "track": (TrackArgs, track), "demo": (DemoArgs, demo)}
"""Subcommand → (options, function)."""


REPEATABLE = ("--param",)
"""Options that may be given several times; their values are joined."""


def _join_repeats(argv: Sequence[str]) -> list[str]:
    """``argv`` with the values of every repeated :data:`REPEATABLE` option joined into its
    first occurrence. Raises ValueError naming another option given twice (the parser
    would keep only its last value), ``--x`` and ``--no-x`` counting as one option."""
    argv = list(argv)
    groups: list[list] = []  # [key or None, the option token, its values]
    first: dict[str, list] = {}
    i = 0
    while i < len(argv):
        token = argv[i]
        if not (token.startswith("--") and len(token) > 2):
            groups.append([None, token, []])
            i += 1
            continue
        name, eq, inline = token.partition("=")
        j = i + 1
        while not eq and j < len(argv) and not argv[j].startswith("--"):
            j += 1
        values = [inline] if eq else argv[i + 1:j]
        key = "--" + name[5:] if name.startswith("--no-") else name
        if key in first and key not in REPEATABLE:
            raise ValueError(f"{key} is given twice (only one would count); give all its values once")
        if key in first:
            first[key][2].extend(values)
        else:
            first[key] = [key, name, values]
            groups.append(first[key])
        i = j
    return [t for _, name, values in groups for t in (name, *values)]


def parse(argv: Sequence[str]):
    """The options of ``dockjax ARGV`` (tyro), or an exit code: 0 after ``--help``, 2 after
    one line ``error: …`` for anything that cannot be parsed — tyro's framed message
    reduced to the line that says what is wrong, and its suggestion — or an option given
    twice (:func:`_join_repeats`)."""
    try:
        argv = _join_repeats(argv)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):
            return tyro.extras.subcommand_cli_from_dict({name: opts for name, (opts, _) in COMMANDS.items()},
                                                        args=list(argv), prog="dockjax")
    except SystemExit as exc:
        if not exc.code:
            return 0
        print(f"error: {_parse_error(captured.getvalue(), argv)}", file=sys.stderr)
        return 2


def _parse_error(text: str, argv: Sequence[str]) -> str:
    """tyro's framed parse error as one line: the text between its first two rules, the
    first suggestion after "Perhaps you meant", and where to find the help."""
    raw = [re.sub(r"\[/?[a-z ]+\]", "", ln).strip(" │") for ln in text.splitlines()]
    lines = [ln.strip(" ╭╮╰╯─") for ln in raw]
    blocks, block = [], []
    for full, ln in zip(raw[1:], lines[1:]):  # the first line is the frame's title
        if full and set(full) <= set("-─ "):
            blocks.append(block)
            block = []
        elif ln:
            block.append(ln)
    blocks = [b for b in blocks + [block] if b]  # a plain-text frame draws a rule under its title too
    message = " ".join(blocks[0]) if blocks else (lines[0] if lines else "cannot parse the options")
    message = re.sub(r"\s+\.$", ".", message)
    hint = ""
    for b in blocks[1:]:
        if b and b[0].startswith("Perhaps you meant"):
            hint = f"; perhaps you meant {b[1].split()[0]}" if len(b) > 1 else ""
        elif b and b[0].startswith("Available subcommands"):
            hint = f"; {b[0][0].lower()}{b[0][1:]}"
    command = next((a for a in argv if a in COMMANDS), None)
    return f"{message}{hint} (see dockjax {command + ' ' if command else ''}--help)"


def describe_failure(exc: BaseException) -> tuple[int, str]:
    """The exit code and one-line message for an exception that reaches the command line:
    2 for bad input (values, paths that cannot be used), 1 for work that cannot complete
    (a full disk, memory, a damaged result file, an internal error), 130 for an interrupt."""
    if isinstance(exc, KeyboardInterrupt):
        return 130, "interrupted; every finished result is saved (files are only ever replaced whole)"
    if isinstance(exc, DamagedFileError):
        return 1, str(exc)
    solve = sys.modules.get(f"{__package__}.solve")  # a PlanError can only come from a loaded solver
    if solve is not None and isinstance(exc, solve.PlanError):
        return 1, str(exc)
    if isinstance(exc, ValueError):
        return 2, str(exc)
    if isinstance(exc, MemoryError):
        return 1, "out of memory; ask for less at once (fewer --seeds, a smaller --pop or --chunk)"
    if isinstance(exc, OSError):
        where = f" ({exc.filename})" if exc.filename else ""
        reason = exc.strerror or str(exc)
        if exc.errno == errno.ENOSPC:
            return 1, f"the disk is full{where}; free space and run the command again (finished results are kept)"
        if exc.errno in (errno.ENAMETOOLONG, errno.EACCES, errno.EROFS, errno.ENOTDIR, errno.EISDIR, errno.EEXIST):
            return 2, f"cannot write{where}: {reason}"
        return 1, f"file system error{where}: {reason}"
    return 1, f"internal error: {type(exc).__name__}: {exc} (run with --debug for the traceback)"


def main(argv: Sequence[str] | None = None) -> int:
    """``dockjax <subcommand> [options] [--debug]``; returns the exit code (the console
    script exits with it). Expected failures print one line ``error: …`` and give exit code
    2 (bad input), 1 (cannot complete) or 130 (interrupted), without a traceback unless
    ``--debug`` is given (:func:`describe_failure`)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    argv = [a for a in argv if a != "--debug"]
    interrupted: list[int] = []

    def on_interrupt(signum, frame):  # remembered: an interrupt raised inside a garbage-collection
        interrupted.append(signum)   # callback is swallowed by the interpreter
        raise KeyboardInterrupt

    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, on_interrupt) if main_thread else None
    try:
        args = parse(argv)
        if isinstance(args, int):
            return args
        run = next(fn for opts, fn in COMMANDS.values() if isinstance(args, opts))
        code = run(args)
        if interrupted and code == 0:
            raise KeyboardInterrupt
        return code
    except (KeyboardInterrupt, Exception) as exc:  # noqa: BLE001 - one line per failure, see describe_failure
        if debug:
            raise
        code, message = describe_failure(exc)
        print(f"\n{message}" if code == 130 else f"error: {message}", file=sys.stderr)
        return code
    finally:
        if main_thread and previous is not None:
            signal.signal(signal.SIGINT, previous)


def exit_with(code: int) -> None:
    """Exit with ``code``; after an interrupt without the interpreter's shutdown, which can
    crash while interrupted XLA computations still hold their threads."""
    if code == 130:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    sys.exit(code)


def console() -> None:
    """The ``dockjax`` console script."""
    exit_with(main())

