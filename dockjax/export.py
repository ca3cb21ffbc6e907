"""Controller-ready exports of a trajectory: a ROS 2 ``JointTrajectory`` and per-axis set-point tables.

* :func:`joint_trajectory`: the plan as a ``trajectory_msgs/msg/JointTrajectory`` (a dict
  with the message's fields; :func:`to_yaml` and :func:`to_json` write it). Its points are
  the trajectory's states (position, velocity, acceleration of the eight joints) at every
  sample time ``k / rate`` and at every knot time, in SI units (m, rad, s) as ROS expects.
  A joint trajectory controller given positions, velocities and accelerations interpolates
  each segment by the quintic polynomial that matches them at both ends; the pose is a
  quintic polynomial between knots and the joints are smooth functions of it, so that
  interpolation reproduces the plan to far below a micrometre at 1 kHz
  (``docs/planning.md`` gives the measured deviation).
* :func:`axis_tables`: one set-point table per joint (time, position, velocity and
  acceleration at ``rate`` Hz, in the joint's unit), for controllers fed at a fixed rate.

Times are whole nanoseconds (``time_from_start`` is ``sec`` + ``nanosec``): each point is
the state at its rounded time, so a point and its stamp always agree.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import numpy as np

from . import config, robot
from .config import DEG
from .trajectory import COLUMN_SUFFIXES

if TYPE_CHECKING:
    from .trajectory import Trajectory

__all__ = ["NS", "KNOT_GAP", "SI_SCALE", "export_times", "joint_trajectory", "to_yaml", "to_json", "axis_tables",
           "EXPORTS"]

EXPORTS = ("ros2", "axes")
"""The kinds of export (``dockjax plan --export``)."""

NS = 1_000_000_000
"""Nanoseconds per second (the resolution of ``time_from_start``)."""

KNOT_GAP = 0.01
"""A knot time closer than this fraction of the sample period to a sample time is left out
(the pose is C⁴ across a knot, so the segment holding it is reproduced just as well, and a
controller's quintic over a very short segment is ill-conditioned)."""

SI_SCALE = {"mm": 1e-3, "deg": DEG}
"""Factor from a joint's unit to SI (m, rad)."""


def export_times(trajectory: "Trajectory", rate: float) -> np.ndarray:
    """The times of the exported points, in whole nanoseconds (int64, increasing): every
    sample time ``k / rate`` with the last at T (:meth:`Trajectory.sample_times`) and every
    interior knot time not within :data:`KNOT_GAP` of a sample period of one."""
    samples = np.round(trajectory.sample_times(rate) * NS).astype(np.int64)
    knots = np.round(np.unique(trajectory.knots[6:-6]) * NS).astype(np.int64)
    gap = KNOT_GAP * NS / rate
    near = np.abs(samples[None, :] - knots[:, None]).min(axis=1) < gap if len(knots) else np.zeros(0, bool)
    return np.union1d(samples, knots[~near])


def _states(trajectory: "Trajectory", t_ns: np.ndarray) -> dict[str, np.ndarray]:
    """Samples (:meth:`Trajectory.at`) at times in nanoseconds (the last clipped to T, where
    the trajectory is at rest)."""
    return trajectory.at(np.minimum(t_ns / NS, trajectory.T))


def joint_trajectory(trajectory: "Trajectory", rate: float = config.RATE) -> dict:
    """The trajectory as a ROS 2 ``trajectory_msgs/msg/JointTrajectory``: ``header`` (zero
    stamp: the controller starts it on receipt), ``joint_names`` (conventions §4 order) and
    ``points``, each with ``positions``, ``velocities``, ``accelerations`` (8 each, m and rad
    per s⁰, s¹, s²), an empty ``effort`` and ``time_from_start`` (``sec``, ``nanosec``), at
    :func:`export_times`."""
    t_ns = export_times(trajectory, rate)
    s = _states(trajectory, t_ns)
    scale = np.array([SI_SCALE[u] for u in config.JOINT_UNITS])
    fields = {"positions": s["position"] * scale, "velocities": s["velocity"] * scale,
              "accelerations": s["acceleration"] * scale}
    points = []
    for i, t in enumerate(t_ns.tolist()):
        points.append({**{k: v[i].tolist() for k, v in fields.items()}, "effort": [],
                       "time_from_start": {"sec": t // NS, "nanosec": t % NS}})
    return {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
            "joint_names": [j.name for j in robot.JOINTS], "points": points}


def to_json(msg: dict) -> str:
    """A message of :func:`joint_trajectory` as JSON text."""
    return json.dumps(msg, separators=(",", ":")) + "\n"


def _flow(values) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def to_yaml(msg: dict) -> str:
    """A message of :func:`joint_trajectory` as YAML text, in the layout of ``ros2 topic pub``
    and of ROS 2 parameter files (block mappings, flow sequences of numbers); floats are
    written to round-trip exactly."""
    lines = ["header:", "  stamp:", f"    sec: {msg['header']['stamp']['sec']}",
             f"    nanosec: {msg['header']['stamp']['nanosec']}", "  frame_id: ''",
             "joint_names: [" + ", ".join(msg["joint_names"]) + "]", "points:"]
    for p in msg["points"]:
        lines += [f"- positions: {_flow(p['positions'])}", f"  velocities: {_flow(p['velocities'])}",
                  f"  accelerations: {_flow(p['accelerations'])}", "  effort: []",
                  f"  time_from_start: {{sec: {p['time_from_start']['sec']}, "
                  f"nanosec: {p['time_from_start']['nanosec']}}}"]
    return "\n".join(lines) + "\n"


def axis_tables(trajectory: "Trajectory", rate: float = config.RATE) -> dict[str, str]:
    """One CSV text per joint (keyed by its name): ``t [s]``, position, velocity and
    acceleration in the joint's unit (mm or deg, per s, per s²) at the sample times
    ``k / rate`` with the last at T, each time a whole nanosecond."""
    t_ns = np.round(trajectory.sample_times(rate) * NS).astype(np.int64)
    s = _states(trajectory, t_ns)
    out = {}
    for j, joint in enumerate(robot.JOINTS):
        header = ["t [s]"] + [f"{joint.name}{COLUMN_SUFFIXES[k]} [{config.unit(j, k)}]"
                              for k in range(3)]
        table = np.stack([t_ns / NS, s["position"][:, j], s["velocity"][:, j], s["acceleration"][:, j]], 1)
        rows = "\n".join("%.9f,%.17g,%.17g,%.17g" % tuple(r) for r in table.tolist())
        out[joint.name] = ",".join(header) + "\n" + rows + "\n"
    return out
