"""Controller exports (``dockjax plan --export ros2 axes``): the exported points, interpolated
quintically as a ROS 2 joint trajectory controller does (SciPy's ``BPoly.from_derivatives``
matches position, velocity and acceleration at both ends of each segment), reproduce the
plan computed by the independent reference of ``tests/reference.py``, and stay within
every limit."""

from __future__ import annotations

import json
import typing

import numpy as np
import pytest
import yaml
from scipy.interpolate import BPoly

from dockjax import config, export
from dockjax.problem import DockingProblem

from . import reference as R

SI = np.array([1e-3 if u == "mm" else np.pi / 180 for u in config.JOINT_UNITS])
"""Joint units → SI (m, rad), written here independently of the package."""


def _points(msg: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Times (s) and positions, velocities, accelerations (m, 8) of a JointTrajectory."""
    pts = msg["points"]
    t = np.array([p["time_from_start"]["sec"] + p["time_from_start"]["nanosec"] * 1e-9 for p in pts])
    return t, *(np.array([p[k] for p in pts]) for k in ("positions", "velocities", "accelerations"))


def _controller(t, P, V, A):
    """The controller's interpolation: per joint, the quintic on each segment matching the
    position, velocity and acceleration at both of its ends."""
    return [BPoly.from_derivatives(t, np.stack([P[:, j], V[:, j], A[:, j]], 1)) for j in range(8)]


def test_the_ros2_export_at_the_default_rate_reproduces_a_time_optimal_plan_within_a_micrometre_and_every_limit(
        wide_time_plan):
    folder, _ = wide_time_plan
    s = json.loads((folder / "summary.json").read_text())
    problem = DockingProblem(interval_bounds=tuple(s["settings"]["interval_bounds"]))
    x = np.array(s["x"])
    tr = problem.decode(x)
    msg = json.loads(export.to_json(export.joint_trajectory(tr)))  # the default rate, 1 kHz
    assert msg["joint_names"] == list(config.JOINT_NAMES)
    t, P, V, A = _points(msg)
    assert t[0] == 0.0 and abs(t[-1] - s["T_s"]) <= 0.5e-9 and np.all(np.diff(t) > 0)
    # every sample time k / 1000 s is a point, and every interior knot time (to the nanosecond)
    # unless a sample lies within 10 µs of it (1 % of the period)
    grid = np.append(np.arange(0, s["T_s"] - 1e-9, 1e-3), s["T_s"])
    assert np.all(np.isin(np.round(grid[:-1] * 1e9), np.round(t * 1e9)))
    knots = np.cumsum(x[: problem.n_intervals])[:-1]
    to_point = np.min(np.abs(t[None, :] - knots[:, None]), axis=1)
    to_sample = np.min(np.abs(grid[None, :] - knots[:, None]), axis=1)
    assert np.all((to_point <= 0.5e-9) | (to_sample < 1e-5)) and len(t) == len(grid) + np.sum(to_sample >= 1e-5)
    # the exported states are the plan's (independent B-spline and kinematics)
    ref = R.joint_derivatives(x, problem.start, problem.goal, problem.arm_distance, np.minimum(t, s["T_s"]))
    for k, got in enumerate((P, V, A)):
        np.testing.assert_allclose(got / SI, ref[k], rtol=0, atol=1e-9 * (1 + np.abs(ref[k]).max()))
    # interpolated as the controller does, between and at the points
    dense = np.linspace(0.0, t[-1], 400_001)
    quintic = _controller(t, P, V, A)
    truth = R.joint_derivatives(x, problem.start, problem.goal, problem.arm_distance, np.minimum(dense, s["T_s"]))
    dev = np.array([np.abs(q(dense) / SI[j] - truth[0][:, j]).max() for j, q in enumerate(quintic)])
    linear = np.array([u == "mm" for u in config.JOINT_UNITS])
    assert dev[linear].max() <= 1e-3, dev  # mm: 1 µm
    assert (dev[~linear] * np.pi / 180).max() <= 1e-6, dev  # rad: 1 µrad
    lim = problem.limits
    for k in (1, 2):
        peak = np.array([np.abs(q(dense, k) / SI[j]).max() for j, q in enumerate(quintic)])
        assert np.all(peak <= lim[:, k] * (1 + 1e-9)), (k, peak / lim[:, k])
    travel = np.array([np.abs(q(dense) / SI[j] - problem.home[j]).max() for j, q in enumerate(quintic)])
    assert np.all(travel <= lim[:, 0] * (1 + 1e-9))
    # the plan is time-optimal: some limit is reached, so the check above is not vacuous
    assert max((np.array([np.abs(q(dense, k) / SI[j]).max() for j, q in enumerate(quintic)]) / lim[:, k]).max()
               for k in (1, 2)) > 0.99


def test_plan_export_writes_the_ros2_message_in_yaml_and_json_and_one_set_point_table_per_axis(paper_plan):
    yaml_msg = yaml.load((paper_plan / "trajectory_ros2.yaml").read_text(), Loader=yaml.CSafeLoader)
    json_msg = json.loads((paper_plan / "trajectory_ros2.json").read_text())
    assert yaml_msg == json_msg  # the same message, every float exact
    assert set(yaml_msg) == {"header", "joint_names", "points"}
    assert set(yaml_msg["points"][0]) == {"positions", "velocities", "accelerations", "effort", "time_from_start"}
    assert all(0 <= p["time_from_start"]["nanosec"] < 10**9 for p in yaml_msg["points"])
    table = np.loadtxt(paper_plan / "trajectory.csv", delimiter=",", skiprows=1)
    t, P, V, A = _points(yaml_msg)
    on_grid = np.isin(np.round(t * 1e9), np.round(table[:, 0] * 1e9))
    assert on_grid.sum() == len(table)  # the CSV's times (200 Hz), plus the knots
    joints = table[:, 7:].reshape(len(table), 8, 4)
    np.testing.assert_allclose(P[on_grid] / SI, joints[:, :, 0], rtol=1e-12, atol=1e-9)
    for name, unit in zip(config.JOINT_NAMES, config.JOINT_UNITS):
        path = paper_plan / f"axis-{name}.csv"
        header = path.read_text().splitlines()[0].split(",")
        assert header == ["t [s]", f"{name} [{unit}]", f"{name}_vel [{unit}/s]", f"{name}_acc [{unit}/s^2]"]
        axis = np.loadtxt(path, delimiter=",", skiprows=1)
        j = config.JOINT_NAMES.index(name)
        np.testing.assert_allclose(axis[:, 0], table[:, 0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(axis[:, 1:], joints[:, j, :3], rtol=1e-12, atol=1e-9)


def test_a_plan_without_export_removes_the_exports_of_the_plan_before_it(paper_plan, tmp_path):
    import shutil

    from dockjax.plan import Plan, write_plan

    folder = tmp_path / "plan"
    shutil.copytree(paper_plan, folder)
    s = json.loads((folder / "summary.json").read_text())
    problem = DockingProblem()
    tr = problem.decode(np.array(s["x"]))
    p = Plan(problem, tr, tr.x, tr.T, s["jerk"], np.array(s["front"]), tr.sample(200.0), 200.0, (1.0, 1.0),
             {"method": "direct"}, {"objective": "x", "binding": []})
    with pytest.raises(ValueError, match="export must be any of ros2, axes, got 'ros'"):
        write_plan(p, folder, export=("ros",))
    assert (folder / "trajectory_ros2.yaml").exists()  # a refused request changes nothing
    write_plan(p, folder)
    assert not list(folder.glob("trajectory_ros2.*")) and not list(folder.glob("axis-*.csv"))


def test_the_cli_offers_exactly_the_library_s_exports():
    from dockjax.cli import PlanArgs

    hint = typing.get_type_hints(PlanArgs)["export"]
    assert typing.get_args(typing.get_args(hint)[0]) == export.EXPORTS
