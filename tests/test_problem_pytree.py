"""DockingProblem as a JAX pytree: every attribute survives jit, tree_map and replace."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from dockjax import DockingProblem

KW = dict(start=(770.0, -30.0, -1320.0, 0.3, -0.1, 188.0), interval_bounds=(2.5, 9.0), margin=0.2,
          travel=(600.0, 60.0, 60.0, 15.0), right_arm="bound")


def test_a_traced_problem_keeps_interval_bounds_margin_and_limits():
    p = DockingProblem(**KW)

    @jax.jit
    def read(q):
        lo, hi = q.interval_bounds
        return jnp.stack([lo, hi, q.margin, q.arm_distance]), q.limits, q.lower, q.upper, q.home

    with jax.enable_x64(True):
        scalars, limits, lower, upper, home = (np.asarray(a) for a in read(p))
    np.testing.assert_array_equal(scalars, [2.5, 9.0, 0.2, 2000.0])
    np.testing.assert_array_equal(limits, p.limits)
    np.testing.assert_array_equal(lower, p.lower)
    np.testing.assert_array_equal(upper, p.upper)
    np.testing.assert_array_equal(home, p.home)
    assert limits[5, 0] == 60.0 and lower[0] == 2.5 and upper[0] == 9.0


def test_tree_map_and_with_right_arm_keep_every_attribute():
    p = DockingProblem(**KW)
    for q in (jax.tree_util.tree_map(lambda a: a, p), p.with_right_arm("taylor")):
        assert q.interval_bounds == (2.5, 9.0) and q.margin == 0.2 and q.jerk_nodes == p.jerk_nodes
        for name in ("start", "goal", "limits", "home", "lower", "upper"):
            np.testing.assert_array_equal(getattr(q, name), getattr(p, name))
    assert p.with_right_arm("taylor").right_arm == "taylor"
    leaves, treedef = jax.tree_util.tree_flatten(p)
    assert len(leaves) == 12 and jax.tree_util.tree_unflatten(treedef, leaves).margin == 0.2


def test_the_kernel_takes_the_robot_as_data_one_program_for_every_robot():
    """The limit maxima read D_2, home and the limit table from the Robot pytree alone: a
    robot with another arm distance and home is scored as the dense reference says for that
    robot, by the same compiled program."""
    from dockjax import limits
    from dockjax.decoding import spans
    from dockjax.robot import Robot
    from tests import reference as R

    p = DockingProblem(right_arm="bound")
    x = np.random.default_rng(3).uniform(p.lower, p.upper)

    @jax.jit
    def maxima(robot, x):
        h, _, c, ref = spans(p, x)
        return limits.maxima(robot, c, h, ref)

    other = Robot(arm_distance=1500.0, home=np.asarray(p.home) + 5.0, limits=2.0 * np.asarray(p.limits))
    assert len(jax.tree_util.tree_leaves(other)) == 3 and other.n_kinds == 3 and not other.has_jerk
    with jax.enable_x64(True):
        for robot in (p.robot, other):
            M = np.asarray(maxima(robot, x))
            dense = R.dense_quantity_maxima(x, p.start, p.goal, robot.arm_distance, home=np.asarray(robot.home),
                                            n_samples=20001)
            lim = np.asarray(robot.limits)
            assert np.all(M >= dense - 1e-9), np.min(M - dense)
            assert np.all(M <= dense + 0.011 * lim), np.max((M - dense) / lim)
        assert not np.allclose(np.asarray(maxima(other, x)), np.asarray(maxima(p.robot, x)))
    assert maxima._cache_size() == 1
