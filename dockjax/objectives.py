"""The two objectives of the paper, both minimised (Eqs. 24–25, conventions §5).

* ``T = Σ h_k``, the total time (Eq. 24);
* the jerk objective ``Σ_j sqrt((1/T) ∫_0^T q_j'''(t)² dt)`` over the eight joints (Eq. 25):
  for the joints linear in the pose the jerk is a quadratic on each knot span and its square
  integrates in closed form; for the right arm's axial, lift and lateral joints (through
  sin/cos of pitch and yaw) the jerk comes from Taylor-mode arithmetic
  (:func:`dockjax.right_arm.right_terms`) and Gauss–Legendre per span, with as many nodes
  as the decision box's range of pitch and yaw needs for 1e-9 relative (:data:`JERK_NODES`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import jax.numpy as jnp
import numpy as np

from .right_arm import right_terms
from .robot import JOINTS, arm_joints, join_pairs

if TYPE_CHECKING:
    from .robot import Robot

__all__ = ["JERK_NODES", "jerk_nodes_for", "jerk", "cabin_jerk", "mean_square_jerk", "safe_sqrt"]


JERK_NODES = ((1.0, 8), (8.0, 12), (math.inf, 24))
"""Gauss–Legendre nodes per knot span of the right arm's jerk integral (conventions §5: 1e-9
relative) by the decision box's range of pitch and yaw (degrees, the larger): up to 1°, 8
nodes; up to 8°, 12; beyond, 24. Worst relative error of the objective against a 96-node
reference, over candidates with knot intervals from 0.1 to 10 s and interior points at the
box's corners: 8 nodes 1e-13 at 0.24° (the paper's box), 1e-10 at
1.4°, 1e-9 at 2.6° (found by the property test), 3e-8 at 6°; 12 nodes 7e-13 at 7.2°,
1e-10 at 12°; 24 nodes 3e-14 at 24°, 48° and 90°. The nodes are static: one compiled
kernel per count."""


def jerk_nodes_for(attitude_range: float) -> int:
    """Nodes of :data:`JERK_NODES` for a box whose pitch and yaw span at most
    ``attitude_range`` degrees."""
    return next(n for top, n in JERK_NODES if attitude_range <= top)


def safe_sqrt(v):
    """``sqrt(v)`` for ``v > 0`` and 0 elsewhere, with a finite (zero) gradient at 0, where
    ``jnp.sqrt``'s is infinite (a joint that does not move has zero mean-square jerk)."""
    pos = v > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, v, 1.0)), 0.0)


def jerk(robot: "Robot", c, h, ref, *, nodes: int, differentiable: bool = False):
    """Sum over the eight joints of the RMS jerk (Eq. 25); see :func:`mean_square_jerk`.
    ``differentiable``: through :func:`safe_sqrt`, so that gradients stay finite where a
    joint does not move (refinement, the SQP programmes); the value is the same."""
    sqrt = safe_sqrt if differentiable else jnp.sqrt
    return jnp.sum(sqrt(mean_square_jerk(robot, c, h, ref, nodes)))


def cabin_jerk(robots: tuple, c, h, ref, *, nodes: int, differentiable: bool = False):
    """:func:`jerk` of a cabin on K supports: the sum over its 4K joints, from the mean-square
    jerks of each pair of supports (:attr:`dockjax.DockingProblem.robots`) joined by
    :func:`dockjax.robot.join_pairs`; one pair is :func:`jerk`."""
    if len(robots) == 1:
        return jerk(robots[0], c, h, ref, nodes=nodes, differentiable=differentiable)
    sqrt = safe_sqrt if differentiable else jnp.sqrt
    return jnp.sum(sqrt(join_pairs([mean_square_jerk(rb, c, h, ref, nodes) for rb in robots])))


def mean_square_jerk(robot: "Robot", c, h, ref, nodes: int):
    """``(1/T) ∫ (d³q_j/dt³)² dt`` of the eight joints (8,) (Eq. 25): in closed form per span
    for the joints linear in the pose, by Gauss–Legendre per span for the right arm's
    nonlinear ones (``nodes`` per span (static): a problem's ``jerk_nodes``, :data:`JERK_NODES`).
    robot: :class:`dockjax.robot.Robot` (D_2); c, h, ref: as :func:`dockjax.right_arm.right_terms`."""
    xi, w = np.polynomial.legendre.leggauss(nodes)
    tau = 0.5 * h[:, None] * (1.0 + jnp.asarray(xi, c.dtype))  # (6, n)
    weights = 0.5 * h[:, None] * jnp.asarray(w, c.dtype)
    # joints linear in the pose: the jerk on a span is a quadratic a + bτ + cτ², whose
    # square integrates in closed form over [0, h] (what the quadrature gives, exactly)
    a, b, q = (m * c[:, k, :] for m, k in ((6.0, 3), (24.0, 4), (60.0, 5)))  # (6 spans, 6 coords)
    hk = h[:, None]
    lin = jnp.sum(hk * (a * a + hk * (a * b + hk * ((b * b + 2.0 * a * q) / 3.0
                                                      + hk * (0.5 * b * q + hk * (q * q / 5.0))))), axis=0)
    # the right arm's third Taylor coefficients as separate arrays (no stacking: the
    # reverse pass, used by refinement, then fuses)
    right = iter([jnp.sum(weights * (6.0 * j[3]) ** 2) for j in right_terms(robot, c, tau, 3, ref)])
    # a joint that does not depend on the attitude is ± one pose coordinate (arm_joints with
    # the cabin axis and arm distance zero), so its mean-square jerk is that coordinate's
    linear = arm_joints(lin[0], lin[1], lin[2], lin[5], 0.0, 0.0, 0.0, 0.0)
    return jnp.stack([next(right) if joint.attitude else jnp.abs(v) for joint, v in zip(JOINTS, linear)]) / jnp.sum(h)
