"""Moves as the instances of a study: many docking moves of one robot, read from a TOML file
or drawn at random in the robot's workspace.

A study tuned on one move answers for that move; over instances it answers for the moves a
line makes (irace's *instances*, the blocks of its Friedman test). An :class:`Instance` is a
named set of :class:`dockjax.DockingProblem` keyword overrides (a start and a goal pose, and
optionally the arm distance, the knot interval bounds, the limits and the number of free
control points); :meth:`Instance.problem` lays them over a preset's problem.

A file of instances holds one ``[[instance]]`` table per move::

    [[instance]]
    name = "lift"                    # optional; default "instance-<k>" (k from 0)
    start = [775, -35, -1315, 0.2, -0.2, 190]
    goal = [745, -5, -1515, 0, 0, 180]
    arm_distance = 2000              # optional (mm)
    interval_bounds = [3.5, 10]      # optional (s)
    n_control = 5                    # optional
    [instance.limits]                # optional: as a limits file (travel, velocity,
    velocity = [400, 25, 2.5, 6.8]   #   acceleration, jerk: 4 or 8 numbers; home: 8)

:func:`random_instances` draws moves around the paper's by :class:`Workspace` (documented
there), seeded, keeping only moves that meet the travel limits with room to spare and that
some trajectory can make within the longest time the interval bounds allow.
:func:`instances_text` writes any instances back as such a file (a study keeps the moves it
ran). :func:`parse_instances` reads the command line's ``FILE`` or ``random:N``.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from . import checks, config, robot
from .io import check_input_file
from .kinematics import inverse_kinematics
from .problem import DockingProblem
from .solve import floor_infeasibility

__all__ = ["Instance", "Workspace", "WORKSPACE", "INSTANCE_KEYS", "MAX_INSTANCES", "load_instances",
           "random_instances", "parse_instances", "instances_text", "check_instances"]

INSTANCE_KEYS = ("name", "start", "goal", "arm_distance", "interval_bounds", "n_control", "limits")
"""Keys of an ``[[instance]]`` table."""
MAX_INSTANCES = 10_000
"""Most instances a file or a random draw may give."""
DRAW_BLOCK = 64
"""Candidate moves :func:`random_instances` draws at a time."""
MAX_INSTANCES_FILE = 2**22
"""Largest instances file read (bytes)."""


@dataclass(frozen=True)
class Instance:
    """One move of a study: ``name`` and ``fields``, keyword arguments of
    :class:`dockjax.DockingProblem` (plain JSON data: ``start``, ``goal`` and any of
    ``arm_distance``, ``interval_bounds``, ``n_control`` and the limit table's keys,
    :data:`dockjax.robot.LIMIT_KEYS`) that replace the preset's."""

    name: str
    fields: dict

    def problem(self, preset: str = "paper", n_control: int = config.N_FREE) -> DockingProblem:
        """The preset's problem (:data:`dockjax.config.PRESETS`) with ``n_control`` free
        control points and this instance's fields laid over it; the home position is the
        midpoint of the instance's own start and goal unless its limits give one."""
        kw = {**config.PRESETS[preset], "n_control": n_control, **self.fields}
        kw["start"], kw["goal"] = np.asarray(kw["start"], np.float64), np.asarray(kw["goal"], np.float64)
        return DockingProblem(**kw)

    def identity(self) -> dict:
        """The instance as plain JSON data (a study's configuration records it)."""
        return {"name": self.name, **self.fields}


@dataclass(frozen=True)
class Workspace:
    """Where :func:`random_instances` draws moves: the start pose uniformly within
    ``± spread`` of ``start`` and the goal within ``± spread`` of ``goal``, coordinate by
    coordinate (poses ``[x, y, z, pitch, yaw, roll]``, mm and degrees; with the defaults
    pitch and yaw move by at most 2.2°, roll by 0–20°, the position by up to a few hundred
    mm); a draw is kept when every joint's move is at most ``travel_use`` of twice its
    travel limit (the home position is the midpoint of start and goal, so each end is
    within ``travel_use`` of the limit) and some trajectory can make it within the longest
    time the interval bounds allow (:func:`dockjax.solve.floor_infeasibility`)."""

    start: tuple[float, ...] = config.START
    goal: tuple[float, ...] = config.GOAL
    spread: tuple[float, ...] = (20.0, 20.0, 100.0, 1.0, 1.0, 5.0)
    travel_use: float = 0.9
    decimals: int = 3
    """Poses are rounded to this many decimals (mm, degrees), so that a file written by
    :func:`instances_text` gives the same moves."""


WORKSPACE = Workspace()
"""The default :class:`Workspace`: around the paper's move."""


def _vector(value: Any, n: int, where: str) -> list[float]:
    if not isinstance(value, list) or len(value) != n or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        raise ValueError(f"{where} must be {n} finite numbers, got {value!r}")
    return [float(v) for v in value]


def _instance(table: Any, k: int, where: str) -> Instance:
    """One ``[[instance]]`` table checked (keys and types; the values are the problem's to check)."""
    if not isinstance(table, dict):
        raise ValueError(f"{where}: instance {k} must be a table")
    label = f"{where}: instance {k}" + (f" ({table['name']!r})" if isinstance(table.get("name"), str) else "")
    unknown = sorted(set(table) - set(INSTANCE_KEYS))
    if unknown:
        raise ValueError(f"{label}: unknown key(s) {unknown}; allowed {list(INSTANCE_KEYS)}")
    for key in ("start", "goal"):
        if key not in table:
            raise ValueError(f"{label}: {key} is missing (6 numbers: x, y, z in mm, pitch, yaw, roll in degrees)")
    name = table.get("name", f"instance-{k}")
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"{label}: name must be a non-empty string, got {name!r}")
    fields: dict[str, Any] = {"start": _vector(table["start"], 6, f"{label}: start"),
                              "goal": _vector(table["goal"], 6, f"{label}: goal")}
    if "arm_distance" in table:
        fields["arm_distance"] = checks.number(f"{label}: arm_distance", table["arm_distance"], 0.0, open_lo=True)
    if "interval_bounds" in table:
        fields["interval_bounds"] = _vector(table["interval_bounds"], 2, f"{label}: interval_bounds")
    if "n_control" in table:
        fields["n_control"] = checks.integer(f"{label}: n_control", table["n_control"], 1, config.MAX_CONTROL)
    if "limits" in table:
        fields.update(robot.check_limit_table(table["limits"], f"{label}: limits"))
    return Instance(name.strip(), fields)


def load_instances(path: str | Path) -> tuple[Instance, ...]:
    """The instances of a TOML file of ``[[instance]]`` tables (module docstring). Raises
    ValueError naming the file, the instance and what is wrong; names must be distinct."""
    path = check_input_file(path, "instances file", MAX_INSTANCES_FILE)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"instances file {path} cannot be read: {getattr(exc, 'strerror', None) or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"instances file {path} is not valid TOML ({exc})") from None
    unknown = sorted(set(data) - {"instance"})
    if unknown:
        raise ValueError(f"instances file {path}: unknown key(s) {unknown}; give the moves as [[instance]] tables")
    tables = data.get("instance")
    if not isinstance(tables, list) or not tables:
        raise ValueError(f"instances file {path} holds no [[instance]] table")
    if len(tables) > MAX_INSTANCES:
        raise ValueError(f"instances file {path} holds {len(tables)} instances, more than {MAX_INSTANCES}")
    out = tuple(_instance(t, k, f"instances file {path}") for k, t in enumerate(tables))
    names = [i.name for i in out]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"instances file {path}: instance names must be distinct, {twice} repeated")
    return out


def random_instances(n: int, *, seed: int = 0, preset: str = "paper", n_control: int = config.N_FREE,
                     workspace: Workspace = WORKSPACE) -> tuple[Instance, ...]:
    """``n`` moves drawn by ``workspace`` (:class:`Workspace`) from NumPy's generator seeded
    with ``seed``: candidates are drawn in blocks and kept in the order drawn while they
    pass the workspace's checks under the preset's limits and interval bounds, so the k-th
    instance depends on the seed alone. Named ``random-<seed>-<k>``."""
    n = checks.integer("instances", n, 1, MAX_INSTANCES)
    seed = checks.integer("instance seed", seed, 0)
    checks.choice("preset", preset, tuple(config.PRESETS))
    spread = checks.vector("workspace spread", workspace.spread, (6,))
    if np.any(spread < 0):
        raise ValueError(f"workspace spread must be non-negative, got {list(workspace.spread)}")
    checks.number("workspace travel_use", workspace.travel_use, 0.0, 1.0, open_lo=True)
    base = DockingProblem(**config.PRESETS[preset], n_control=n_control)
    travel = np.asarray(base.limits)[:, 0]
    rng = np.random.default_rng(seed)
    out: list[Instance] = []
    drawn = 0
    while len(out) < n:
        block = DRAW_BLOCK  # fixed, so that the k-th move does not depend on n
        if drawn > 100 * n + 1000:
            raise ValueError(f"the workspace {workspace} gives no move that meets the checks: fewer than 1 % of "
                             f"{drawn} draws passed; narrow its spread")
        S = np.round(np.asarray(workspace.start) + rng.uniform(-1, 1, (block, 6)) * spread, workspace.decimals)
        G = np.round(np.asarray(workspace.goal) + rng.uniform(-1, 1, (block, 6)) * spread, workspace.decimals)
        drawn += block
        move = np.abs(np.asarray(inverse_kinematics(G, base.arm_distance) - inverse_kinematics(S, base.arm_distance)))
        fits = np.all(move <= 2.0 * workspace.travel_use * travel, axis=1) & np.any(S != G, axis=1)
        for s, g in zip(S[fits], G[fits]):
            if len(out) == n:
                break
            inst = Instance(f"random-{seed}-{len(out)}", {"start": s.tolist(), "goal": g.tolist()})
            if floor_infeasibility(inst.problem(preset, n_control)) is None:
                out.append(inst)
    return tuple(out)


def parse_instances(spec: str, *, seed: int = 0, preset: str = "paper", n_control: int = config.N_FREE,
                    skip: int = 0) -> tuple[Instance, ...]:
    """The command line's instances: ``random:N`` (:func:`random_instances` with ``seed``;
    the N moves after the first ``skip`` of that draw, e.g. a test set after the training
    moves) or the path of a TOML file (:func:`load_instances`)."""
    if not isinstance(spec, str) or not spec:
        raise ValueError(f"instances must be a file or random:N, got {spec!r}")
    if spec.startswith("random:"):
        count = spec.split(":", 1)[1]
        if not count.isdigit():
            raise ValueError(f"instances random:N needs a whole number N, got {spec!r}")
        n = checks.integer("instances", int(count), 1, MAX_INSTANCES)
        return random_instances(skip + n, seed=seed, preset=preset, n_control=n_control)[skip:]
    return load_instances(spec)


def check_instances(instances: Sequence[Instance], preset: str = "paper",
                    n_control: int = config.N_FREE) -> list[DockingProblem]:
    """Each instance's problem, or ValueError naming the first instance whose move is bad
    input (its values out of range, start equal to goal, or a move no trajectory can make
    within the longest time the interval bounds allow). Cheap: no trajectory is solved."""
    out = []
    for inst in instances:
        try:
            p = inst.problem(preset, n_control)
        except ValueError as exc:
            raise ValueError(f"instance {inst.name!r}: {exc}") from None
        if np.array_equal(np.asarray(p.start), np.asarray(p.goal)):
            raise ValueError(f"instance {inst.name!r}: start and goal are the same pose: there is no move")
        if (err := floor_infeasibility(p)) is not None:
            raise ValueError(f"instance {inst.name!r}: {err}")
        out.append(p)
    return out


def _toml_value(v: Any) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v) if isinstance(v, float) else str(v)


def instances_text(instances: Sequence[Instance]) -> str:
    """The instances as a TOML file that :func:`load_instances` reads back to the same
    instances (floats written by ``repr``, exactly)."""
    limit_keys = set(robot.LIMIT_KEYS)
    lines = []
    for inst in instances:
        lines += ["[[instance]]", f"name = {_toml_value(inst.name)}"]
        lines += [f"{k} = {_toml_value(v)}" for k, v in inst.fields.items() if k not in limit_keys]
        limits = {k: v for k, v in inst.fields.items() if k in limit_keys}
        if limits:
            lines.append("[instance.limits]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in limits.items()]
        lines.append("")
    return "\n".join(lines)

