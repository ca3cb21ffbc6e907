"""What a sweep is: its configuration (the identity that decides its numbers), the
assignment of its runs to rounds and chunks, its reference definition, and the validation of
a request. Nothing here computes or writes.

A study without racing is one round of every setting × every seed. A race (``race``) runs
seeds in rounds: round 0 the first ``min_seeds`` seeds of every setting, each later round
as many further seeds of the surviving settings as fill one chunk (at least one); which
settings survive a round is decided from the scores of the rounds before it
(:mod:`dockjax.sweep.race`), so the plan of every round is a function of the
configuration and of results that are themselves reproduced bit for bit.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from .. import checks, config
from ..algorithms import get, make_params
from ..instances import Instance, check_instances
from ..io import check_input_file, load_npz
from ..metrics import nondominated_points
from ..problem import bucket_rows
from ..runtime import check_memory
from .design import ParamSpec, Setting, build_settings, static_key

__all__ = ["FORMAT", "PILOT_SEED0", "COLUMNS", "INDICATOR_COLUMNS", "ConfigError", "SweepConfig", "ChunkSpec",
           "round_seeds", "plan_round", "pilot_spec", "load_front_file", "make_config", "blocks_of", "block_run"]

FORMAT = "dockjax-sweep/3"
PILOT_SEED0 = 1_000_000
"""First seed of the reference pilot (disjoint from a study's seeds)."""
INDICATOR_COLUMNS = ("HV", "IGD", "IGD+", "GD", "SP", "ONVG")
COLUMNS = ("setting", "algorithm", "pop", "iterations", "params", "seed", *INDICATOR_COLUMNS, "T_min", "T_max",
           "jerk_min", "jerk_max", "round", "chunk", "wall_s")
"""Columns of ``runs.csv`` (one row per run; ``params`` is space-separated ``name=value`` pairs); a
study over instances adds ``instance`` (the instance's name) after ``seed``."""


class ConfigError(ValueError):
    """Bad input or an incompatible results folder (the CLI's exit code 2)."""


@dataclass(frozen=True)
class SweepConfig:
    """The identity of a sweep: everything that decides its numbers."""

    settings: tuple[Setting, ...]
    preset: str
    seeds: int
    """Seeds per setting (the seed budget of a race)."""
    chunk: int
    reference: dict
    race: dict | None = None
    """None, or ``{"min_seeds": m, "alpha": a}``."""
    devices: int | None = None
    """CPU devices a chunk's runs are sharded over. Sharding changes the order of some
    floating-point reductions, and an optimiser's choices can then diverge after many
    iterations, so the count is part of the identity (None: not recorded, e.g. Dask)."""
    driver: str = "scan"
    """:func:`dockjax.optimize.optimize`'s driver: ``"scan"`` (fastest per iteration) or
    ``"host"`` (every algorithm shares the kernel's compilation: ``dockjax compare``)."""
    n_control: int = config.N_FREE
    """Free control points of the problem's spline (:class:`dockjax.DockingProblem`'s
    ``n_control``), written into the identity only when it is not the paper's 5."""
    instances: tuple[Instance, ...] = ()
    """The moves of a study over instances (:mod:`dockjax.instances`; empty: the preset's
    own move), written into the identity only when given. Every setting runs every seed on
    every instance; a block of the statistics is one (instance, seed) pair."""
    test_instances: tuple[Instance, ...] = ()
    """Held-out moves (:mod:`dockjax.sweep.testset`): the best setting and every one tied
    with it run again on them, in the folder's ``test/`` study; written into the identity
    only when given."""

    def identity(self) -> dict:
        return {"format": FORMAT, "preset": self.preset, "settings": [s.identity() for s in self.settings],
                "seeds": self.seeds, "chunk": self.chunk, "reference": self.reference, "devices": self.devices,
                "driver": self.driver, "race": self.race, "hv_ref": config.HV_REFERENCE,
                "normalisation": ("ideal and nadir of each instance's reference front (references/)"
                                  if self.instances else "ideal and nadir of reference.npz's front"),
                **({"n_control": self.n_control} if self.n_control != config.N_FREE else {}),
                **({"instances": [i.identity() for i in self.instances]} if self.instances else {}),
                **({"test_instances": [i.identity() for i in self.test_instances]} if self.test_instances else {})}

    @classmethod
    def from_identity(cls, d: dict) -> "SweepConfig":
        """The configuration of a stored identity (``config.json``'s ``identity``)."""
        def moves(key):
            return tuple(Instance(i["name"], {k: v for k, v in i.items() if k != "name"}) for i in d.get(key, ()))

        instances, test_instances = moves("instances"), moves("test_instances")
        return cls(settings=tuple(Setting.from_identity(s) for s in d["settings"]), preset=d["preset"],
                   seeds=int(d["seeds"]), chunk=int(d["chunk"]), reference=d["reference"], race=d["race"],
                   devices=d["devices"], driver=d["driver"], n_control=int(d.get("n_control", config.N_FREE)),
                   instances=instances, test_instances=test_instances)

    @property
    def algorithms(self) -> list[str]:
        return list(dict.fromkeys(s.algorithm for s in self.settings))

    @property
    def n_instances(self) -> int:
        """Moves of the study: its instances, or 1 (the preset's move)."""
        return max(1, len(self.instances))

    @property
    def n_blocks(self) -> int:
        """Blocks of the statistics: (instance, seed) pairs, ``n_instances × seeds``."""
        return self.n_instances * self.seeds

    def n_runs(self) -> int:
        """Runs of the full grid (every setting × every seed × every instance)."""
        return len(self.settings) * self.n_blocks


def blocks_of(cfg: SweepConfig, columns: dict) -> np.ndarray:
    """The block of each run of ``columns`` (a chunk's or the table's): ``seed ×
    instances + instance`` (the seed alone without instances), the column of the
    statistics' matrices. Blocks are numbered in the order a race runs them
    (:func:`block_run`): every instance with seed 0, then every instance with seed 1, ..."""
    seed = np.asarray(columns["seed"], np.int64)
    return seed * cfg.n_instances + np.asarray(columns.get("instance", np.zeros_like(seed)), np.int64)


def block_run(cfg: SweepConfig, block: int) -> tuple[int, int]:
    """``(instance, seed)`` of a block (:func:`blocks_of`); instance -1 without instances."""
    if not cfg.instances:
        return -1, block
    seed, instance = divmod(block, cfg.n_instances)
    return instance, seed


@dataclass(frozen=True)
class ChunkSpec:
    """One compiled call: ``len(seeds)`` runs of one algorithm, population and iteration
    count (``n_real`` real, the rest padding); ``hyper`` every run's named
    hyper-parameters (its setting's ``params``), the same static ones in every run."""

    round: int
    index: int
    preset: str
    algorithm: str
    pop: int
    iters: int
    settings: tuple[int, ...]
    seeds: tuple[int, ...]
    hyper: tuple[tuple[tuple[str, Any], ...], ...]
    n_real: int
    refine_steps: int = 0
    refine_rows: int | None = None
    """Rows per compiled call of the memetic finish (shared with the reference's)."""
    driver: str = "scan"
    n_control: int = config.N_FREE
    """Free control points of the problem's spline."""
    instance: int = -1
    """The instance the chunk's runs solve (its index in the study's instances), -1 for the
    preset's own move."""
    instance_fields: str = ""
    """That instance's :meth:`dockjax.instances.Instance.identity` as JSON ("" for the
    preset's move): a chunk carries its problem to wherever it runs."""

    def params(self) -> Any:
        """The algorithm's ``Params`` of the chunk: every hyper-parameter the settings name
        with a run axis (one value per run, so that every chunk of a study is one compiled
        program whatever its values), the others the algorithm's defaults."""
        Params = get(self.algorithm).Params
        statics = {k: v for k, v in self.hyper[0] if Params.__dataclass_fields__[k].metadata.get("static")}
        base = make_params(self.algorithm, self.pop, self.iters, **statics)
        names = sorted({k for h in self.hyper for k, _ in h} - set(statics))
        return dataclasses.replace(base, **{k: np.array([dict(h).get(k, getattr(base, k)) for h in self.hyper],
                                                         np.float64) for k in names})

    @property
    def label(self) -> str:
        """The algorithm column: e.g. ``imocs`` or, with the memetic finish, ``imocs+refine``."""
        return f"{self.algorithm}+refine" if self.refine_steps else self.algorithm

    @property
    def name(self) -> str:
        return f"round-{self.round:03d}-chunk-{self.index:05d}.npz"


def round_seeds(cfg: SweepConfig, round_index: int, seeds_done: int, n_alive: int) -> range:
    """The blocks of a round (:func:`blocks_of`; the seeds, without instances): every block
    without racing; in a race, ``min_seeds`` first, then as many as fill one chunk with the
    ``n_alive`` survivors (at least one), up to the budget (``seeds`` × instances). Over
    instances a race so brings new instances each round, as irace does, and gives them
    further seeds once every instance has been run."""
    total = cfg.n_blocks
    if cfg.race is None:
        return range(total) if round_index == 0 else range(0)
    if round_index == 0:
        return range(min(cfg.race["min_seeds"], total))
    k = max(1, cfg.chunk // max(n_alive, 1))
    return range(seeds_done, min(total, seeds_done + k))


def _chunk_size(n: int, limit: int) -> int:
    return math.ceil(n / math.ceil(n / limit))


def plan_round(cfg: SweepConfig, round_index: int, alive: Sequence[bool], seeds: range) -> list[ChunkSpec]:
    """The chunks of one round: the runs (alive setting, block of ``seeds``: a seed, or an
    (instance, seed) pair), grouped by compiled program
    (:func:`~dockjax.sweep.design.static_key`) and instance, cut into chunks; balanced sizes without
    racing, chunks of exactly ``chunk`` runs in a race (one compiled shape for every
    round). Short chunks are padded with repeats of their own runs, which are dropped."""
    groups: dict[tuple, list[tuple[int, int]]] = {}
    for i, s in enumerate(cfg.settings):
        if alive[i]:
            for block in seeds:
                k, seed = block_run(cfg, block)
                groups.setdefault((static_key(s), k), []).append((i, seed))
    chunks: list[ChunkSpec] = []
    rows = refine_rows(cfg)
    for (key, instance), runs in groups.items():
        algorithm, pop, iters, _, refine_steps = key
        size = cfg.chunk if cfg.race is not None else _chunk_size(len(runs), cfg.chunk)
        for k in range(0, len(runs), size):
            real = runs[k:k + size]
            padded = [real[j % len(real)] for j in range(size)]
            chunks.append(ChunkSpec(round=round_index, index=len(chunks), preset=cfg.preset, algorithm=algorithm,
                                    pop=pop, iters=iters, settings=tuple(i for i, _ in padded),
                                    seeds=tuple(s for _, s in padded),
                                    hyper=tuple(cfg.settings[i].params for i, _ in padded), n_real=len(real),
                                    refine_steps=refine_steps, refine_rows=rows if refine_steps else None,
                                    driver=cfg.driver, n_control=cfg.n_control, instance=instance,
                                    instance_fields=_instance_json(cfg, instance)))
    return chunks


def _instance_json(cfg: SweepConfig, instance: int) -> str:
    return json.dumps(cfg.instances[instance].identity(), sort_keys=True) if instance >= 0 else ""


def pilot_spec(cfg: SweepConfig, instance: int = -1) -> ChunkSpec:
    """The reference pilot (of ``instance``, -1 the preset's move): one chunk of the first
    algorithm at its default hyper-parameters, its largest population and its largest
    iteration count, seeds from :data:`PILOT_SEED0`."""
    first = cfg.settings[0]
    mine = [s for s in cfg.settings if s.algorithm == first.algorithm]
    pop, iters = max(s.pop for s in mine), max(s.iters for s in mine)
    size = min(cfg.chunk, max(2, len(mine) * cfg.seeds))
    return ChunkSpec(round=-1, index=0, preset=cfg.preset, algorithm=first.algorithm, pop=pop, iters=iters,
                     settings=(-1,) * size, seeds=tuple(PILOT_SEED0 + i for i in range(size)),
                     hyper=((),) * size, n_real=size, refine_steps=first.refine_steps,
                     refine_rows=refine_rows(cfg) if first.refine_steps else None, driver=cfg.driver,
                     n_control=cfg.n_control, instance=instance, instance_fields=_instance_json(cfg, instance))


REFINE_ROWS = 256
"""Most rows per compiled call of a study's gradient refinement (see :func:`refine_rows`)."""


def refine_rows(cfg: SweepConfig) -> int:
    """Rows per compiled call shared by every refinement of a study — the best-known
    front's and the memetic settings' — so that one compiled program serves them all: the
    kernel's bucket of the largest batch, at most :data:`REFINE_ROWS`."""
    sizes = [int(cfg.reference["n_points"])] if cfg.reference.get("kind") == "best-known" else []
    sizes += [min(cfg.chunk, cfg.seeds) * s.pop for s in cfg.settings if s.refine_steps]
    return min(REFINE_ROWS, bucket_rows(max(sizes or [1])))


def _sha256(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a, dtype=np.float64).tobytes()).hexdigest()


MAX_FRONT_FILE = 64 * 2**20
"""Largest reference-front file read (bytes)."""


def load_front_file(path: Path, log: Callable[[str], None] | None = None) -> np.ndarray:
    """A reference front from .npz (key 'front', 'reference_front' or 'F', or the only
    array) or .csv/.txt (two columns T, jerk; one header line allowed). The file must be a
    regular file of at most :data:`MAX_FRONT_FILE` bytes and hold real, finite numbers, two
    columns, at least two distinct points; dominated points are dropped, with a line to
    ``log`` saying how many. → distinct non-dominated (r, 2), sorted by T. Raises
    ConfigError naming what is wrong."""
    path = Path(path)
    what = f"--reference-front {path}"
    try:
        check_input_file(path, "--reference-front", MAX_FRONT_FILE)
        if path.suffix == ".npz":
            z = load_npz(path)
            key = next((k for k in ("front", "reference_front", "F") if k in z), None)
            if key is None and len(z) == 1:
                key = next(iter(z))
            if key is None:
                raise ConfigError(f"{what}: no array 'front' in {sorted(z)}")
            F = z[key]
            if F.dtype.kind not in "iuf":
                raise ConfigError(f"{what}: the front must hold real numbers, got dtype {F.dtype}")
        else:
            lines = path.read_text(encoding="utf-8-sig").strip().splitlines()
            with np.errstate(all="raise"), warnings.catch_warnings():
                warnings.simplefilter("error")
                try:
                    F = np.loadtxt(lines, delimiter=",", ndmin=2)
                except ValueError:
                    F = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
    except ConfigError:
        raise
    except (OSError, ValueError, UnicodeDecodeError, RuntimeWarning, FloatingPointError) as exc:
        raise ConfigError(f"{what} cannot be read: {exc}") from None
    F = np.asarray(F, dtype=np.float64)
    if F.ndim != 2 or F.shape[1] != 2:
        raise ConfigError(f"{what} must hold two columns (T, jerk), got shape {F.shape}")
    if not np.isfinite(F).all():
        raise ConfigError(f"{what} must hold finite numbers (row {int(np.argmin(np.isfinite(F).all(1)))} is not)")
    front = nondominated_points(F)
    if len(front) < 2:
        raise ConfigError(f"{what} must hold at least two distinct non-dominated points, got {len(front)}")
    if len(front) < len(F) and log is not None:
        log(f"reference front: {len(F) - len(front)} of {len(F)} points of {path} are dominated or repeated; "
            f"using the {len(front)} non-dominated ones")
    return front


def size_errors(algorithms, params, pop, iters, budget, samples, seeds, chunk) -> list[str]:
    """What a study would cost, refused before anything is built when it is too much: the
    number of settings (:data:`dockjax.config.MAX_SETTINGS`), the evaluations
    (:data:`dockjax.config.MAX_EVALUATIONS`) and the memory of one chunk."""
    grid = math.prod(max(1, len(s.values)) for s in params if not s.is_range)
    ranged = any(s.is_range for s in params)
    shapes = len(pop) if budget is not None else len(pop) * max(1, len(iters))
    n_settings = max(1, len(algorithms)) * grid * (max(1, samples) if ranged else 1) * max(1, shapes)
    if n_settings > config.MAX_SETTINGS:
        return [f"the design has {n_settings} settings (--samples, --param grids, --pop, --iters), more than "
                f"{config.MAX_SETTINGS}"]
    longest = max([budget // max(1, min(pop or [1]))] if budget is not None else list(iters) or [1])
    evaluations = n_settings * seeds * max(pop or [1]) * (longest + 1)
    errors = []
    if evaluations > config.MAX_EVALUATIONS:
        days = evaluations / config.EVALUATIONS_PER_SECOND / 86400
        errors.append(f"the study asks for about {evaluations:.3g} evaluations (settings × --seeds × --pop × --iters "
                      f"or --budget), about {days:.3g} days at {config.EVALUATIONS_PER_SECOND:,} a second; at most "
                      f"{config.MAX_EVALUATIONS:.0e}")
    runs = min(chunk, seeds)
    try:
        check_memory(runs * (2 * max(pop or [1]) * config.BYTES_PER_CANDIDATE + 16 * longest),
                     "a chunk of --chunk runs at --pop with --iters of history")
    except ValueError as exc:
        errors.append(str(exc))
    return errors


def make_config(*, algorithms: Sequence[str] = ("imocs",), params: Iterable[ParamSpec] = (), pop=(config.POP_SIZE,),
                iters: Sequence[int] = (config.SWEEP_ITERS,), budget: int | None = None, design: str = "grid",
                samples: int = 0, design_seed: int = 0, seeds: int = config.SWEEP_SEEDS, preset: str = "paper",
                refine_steps: int = 0, chunk: int = config.SWEEP_CHUNK, reference: str = "best-known",
                reference_front=None, race: bool = False, race_min_seeds: int = 5, race_alpha: float = 0.05,
                devices: int | None = None, best_known: dict | None = None,
                driver: str = "scan", n_control: int = config.N_FREE,
                instances: Sequence[Instance] = (),
                test_instances: Sequence[Instance] = ()) -> tuple[SweepConfig, np.ndarray | None]:
    """Validate a sweep (nothing is written, nothing is compiled) and build its
    configuration. ``reference``: ``"best-known"`` (default; ``best_known`` overrides
    settings of :data:`dockjax.config.BEST_KNOWN`), ``"pilot"`` or ``"file"``
    (``reference_front`` a path). ``instances``: the moves of a study over instances
    (:mod:`dockjax.instances`; each gets its own best-known or pilot reference; not with a
    reference file or a race). ``test_instances``: held-out moves the best settings run on
    afterwards (:mod:`dockjax.sweep.testset`; none of them a training move). Returns the
    configuration and the loaded reference front (None unless read from a file). Raises
    ConfigError with every problem on one line, naming the options."""
    errors: list[str] = []
    for name, values in (("--pop", list(pop)), ("--iters", list(iters)), ("--budget", [budget or 0]),
                         ("--seeds", [seeds]), ("--chunk", [chunk]), ("--samples", [samples]),
                         ("--design-seed", [design_seed]), ("--race-min-seeds", [race_min_seeds]),
                         ("--refine-steps", [refine_steps])):
        big = [v for v in values if abs(v) > config.MAX_COUNT]
        if big:
            errors.append(f"{name} {big[0]} is too large (at most {config.MAX_COUNT})")
    if errors:
        raise ConfigError("; ".join(errors))
    params = list(params)
    instances = tuple(instances)
    if len(instances) > 1_000:
        errors.append(f"--instances gives {len(instances)} moves, more than 1000")
    errors += size_errors(algorithms, params, pop, iters, budget, samples, seeds * max(1, len(instances)), chunk)
    if preset not in config.PRESETS:
        errors.append(f"--preset must be one of {', '.join(config.PRESETS)}, got {preset!r}")
    try:
        checks.integer("--n-control", n_control, 1, config.MAX_CONTROL)
    except ValueError as exc:
        errors.append(str(exc))
    if driver not in ("scan", "host"):
        errors.append(f"driver must be 'scan' or 'host', got {driver!r}")
    if not pop:
        errors.append("--pop grid is empty (give at least one population size)")
    bad_pop = [p for p in pop if p < 4]
    if bad_pop:
        errors.append(f"--pop values must be >= 4, got {bad_pop}")
    if budget is None and not iters:
        errors.append("--iters grid is empty (give at least one iteration count)")
    if budget is None and any(i < 1 for i in iters):
        errors.append(f"--iters values must be >= 1, got {[i for i in iters if i < 1]}")
    for name, v, lo in (("--seeds", seeds, 1), ("--chunk", chunk, 1), ("--refine-steps", refine_steps, 0),
                        ("--race-min-seeds", race_min_seeds, 2)):
        if v < lo:
            errors.append(f"--{name.lstrip('-')} must be >= {lo}, got {v}")
    if budget is not None and budget < 1:
        errors.append(f"--budget must be >= 1, got {budget}")
    if not (0.0 < race_alpha < 1.0):
        errors.append(f"--race-alpha must be in (0, 1), got {race_alpha}")
    if design not in ("grid", "random", "sobol"):
        errors.append(f"--design must be grid, random or sobol, got {design!r}")
    front = None
    ref: dict[str, Any]
    if reference_front is not None:
        reference = "file"
    if reference == "file":
        if reference_front is None:
            errors.append("--reference file needs --reference-front FILE")
            ref = {}
        else:
            try:
                front = load_front_file(reference_front)
                ref = {"kind": "file", "points": int(len(front)), "sha256": _sha256(front)}
            except ConfigError as exc:
                errors.append(str(exc))
                ref = {}
    elif reference == "pilot":
        ref = {"kind": "pilot", "seeds_from": PILOT_SEED0, "hyper": "defaults", "pop": "largest",
               "iters": "largest", "runs": "one chunk"}
    elif reference == "best-known":
        ref = {"kind": "best-known", **config.BEST_KNOWN, **(best_known or {})}
    else:
        errors.append(f"--reference must be best-known, pilot or file, got {reference!r}")
        ref = {}
    if instances and (reference == "file" or reference_front is not None):
        errors.append("--reference-front is one move's front: a study over --instances takes each instance's own "
                      "reference (--reference best-known or pilot)")
    if instances and not errors:
        try:
            check_instances(instances, preset, n_control)
        except ValueError as exc:
            errors.append(f"--instances: {exc}")
    test_instances = tuple(test_instances)
    if test_instances:
        if reference == "file" or reference_front is not None:
            errors.append("--reference-front is one move's front: the --test-instances take each instance's own "
                          "reference (--reference best-known or pilot)")
        if len(test_instances) > 1_000:
            errors.append(f"--test-instances gives {len(test_instances)} moves, more than 1000")
        seen = [i.fields for i in instances] if instances else [{"start": list(config.PRESETS[preset].get(
            "start", config.START)), "goal": list(config.PRESETS[preset].get("goal", config.GOAL))}]
        both = [i.name for i in test_instances if any(_same_move(i.fields, f) for f in seen)]
        if both:
            errors.append(f"--test-instances {both[:3]} are training moves too: a test set must be held out")
        if not errors:
            try:
                check_instances(test_instances, preset, n_control)
            except ValueError as exc:
                errors.append(f"--test-instances: {exc}")
    settings: list[Setting] = []
    if not errors:
        try:
            settings = build_settings(algorithms, params, pop, iters, budget, design, samples, design_seed,
                                      refine_steps)
        except ValueError as exc:
            errors.append(str(exc))
    if errors:
        raise ConfigError("; ".join(errors))
    cfg = SweepConfig(settings=tuple(settings), preset=preset, seeds=seeds, chunk=chunk, reference=ref,
                      race={"min_seeds": race_min_seeds, "alpha": race_alpha} if race else None,
                      devices=devices, driver=driver, n_control=int(n_control), instances=instances,
                      test_instances=test_instances)
    return cfg, front


def _same_move(a: dict, b: dict) -> bool:
    """Whether two instances' fields are the same move (every field equal as numbers)."""
    def norm(d: dict) -> str:
        return json.dumps({k: np.asarray(v, np.float64).tolist() if isinstance(v, (list, tuple, int, float)) else v
                           for k, v in d.items()}, sort_keys=True)

    return norm(a) == norm(b)
