"""Kinematics of the dual-arm cabin-docking robot (paper §2, Eqs. 1–15; conventions §4).

The D-H base frame of Eqs. 1–7 is not the task frame of paper §3: its x axis is the cabin
axis (task Z), its y axis task X and its z axis task Y (conventions §4). Joint 1 of each arm is
the axial joint, joint 2 the lift, joint 3 the lateral joint and joint 4 the roll.

Readings fixed by conventions §4 (departures from the printed paper):

* Table 1's garbled row ``R_2`` is read as ``(θ, d, a, α) = (π/2, d_R2, 0, −π/2)`` and the
  link lengths ``d_L``, ``d_R`` and offsets ``d_L4``, ``d_R4`` are zero; with that, the
  product of the D-H transforms equals Eqs. 1–2 exactly.
* The right arm end is ``K_R = K_L + D_2 u(α, β)`` with the cabin axis
  ``u = (cos α sin β, sin α, cos α cos β)``. This keeps ``|K_R − K_L| = D_2`` (Eq. 13) and
  Eq. 10 exactly; the paper's Eq. 15 as printed does not keep the distance.
* ``θ_L = γ`` (Eq. 7); Eq. 5's constant offset ``π`` changes no objective or limit.

All functions accept NumPy or JAX arrays (they use ``jax.numpy``); angles of poses and
joints are in degrees, D-H angles in radians.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .robot import LEFT_ARM, RIGHT_ARM, arm_joints, cabin_axis, cabin_joints

__all__ = [
    "DH_LEFT",
    "DH_RIGHT",
    "dh_transform",
    "dh_chain",
    "forward_left",
    "forward_right",
    "eq1_left",
    "eq2_right",
    "right_end_point",
    "inverse_kinematics",
    "forward_kinematics",
]

_HALF_PI = np.pi / 2

# Rows (θ, d, a, α) of Table 1; a ``None`` marks the joint variable in that slot.
DH_LEFT = (
    (_HALF_PI, 0.0, 0.0, -_HALF_PI),  # Base-L0
    (0.0, "d1", 0.0, _HALF_PI),  # L1: axial
    (-_HALF_PI, "d2", 0.0, _HALF_PI),  # L2: lift
    (_HALF_PI, "d3", 0.0, _HALF_PI),  # L3: lateral (link length d_L = 0)
    ("theta", 0.0, 0.0, 0.0),  # L4: roll (d_L4 = 0)
)
"""Table 1, left arm, with ``d_L = d_L4 = 0`` (conventions §4)."""

DH_RIGHT = (
    (_HALF_PI, 0.0, 0.0, _HALF_PI),  # Base-R0
    (0.0, "d1", 0.0, -_HALF_PI),  # R1: axial
    (_HALF_PI, "d2", 0.0, -_HALF_PI),  # R2: lift (garbled row read per conventions §4)
    (-_HALF_PI, "d3", 0.0, -_HALF_PI),  # R3: lateral (link length d_R = 0)
    ("theta", 0.0, 0.0, 0.0),  # R4: roll (d_R4 = 0)
)
"""Table 1, right arm, with ``d_R = d_R4 = 0`` and row ``R_2`` read per conventions §4."""


def dh_transform(theta, d, a, alpha):
    """Standard D-H link transform ``Rz(θ)·Tz(d)·Tx(a)·Rx(α)``; angles in radians. (4, 4)."""
    ct, st = jnp.cos(theta), jnp.sin(theta)
    ca, sa = jnp.cos(alpha), jnp.sin(alpha)
    zero, one = jnp.zeros_like(ct), jnp.ones_like(ct)
    return jnp.stack(
        [
            jnp.stack([ct, -st * ca, st * sa, a * ct]),
            jnp.stack([st, ct * ca, -ct * sa, a * st]),
            jnp.stack([zero, sa + zero, ca + zero, d + zero]),
            jnp.stack([zero, zero, zero, one]),
        ]
    )


def dh_chain(table, d1, d2, d3, theta_deg):
    """Product of the D-H transforms of ``table`` for joint values (mm, mm, mm, °). (4, 4)."""
    values = {"d1": d1, "d2": d2, "d3": d3, "theta": jnp.deg2rad(theta_deg)}
    out = jnp.eye(4)
    for row in table:
        theta, d, a, alpha = (values[v] if isinstance(v, str) else v for v in row)
        out = out @ dh_transform(theta, d, a, alpha)
    return out


def forward_left(d1, d2, d3, theta_deg):
    """Left arm end frame in the D-H base frame by the D-H product (Eq. 1). (4, 4)."""
    return dh_chain(DH_LEFT, d1, d2, d3, theta_deg)


def forward_right(d1, d2, d3, theta_deg):
    """Right arm end frame in the D-H base frame by the D-H product (Eq. 2). (4, 4)."""
    return dh_chain(DH_RIGHT, d1, d2, d3, theta_deg)


def eq1_left(d1, d2, d3, theta_deg):
    """The closed form printed as paper Eq. 1. (4, 4)."""
    t = jnp.deg2rad(theta_deg)
    s, c = jnp.sin(t), jnp.cos(t)
    return jnp.array(
        [[0.0, 0.0, 1.0, -d1], [-s, -c, 0.0, -d3], [c, -s, 0.0, d2], [0.0, 0.0, 0.0, 1.0]]
    )


def eq2_right(d1, d2, d3, theta_deg):
    """The closed form printed as paper Eq. 2. (4, 4)."""
    t = jnp.deg2rad(theta_deg)
    s, c = jnp.sin(t), jnp.cos(t)
    return jnp.array(
        [[0.0, 0.0, -1.0, d1], [s, c, 0.0, -d3], [c, -s, 0.0, d2], [0.0, 0.0, 0.0, 1.0]]
    )


def right_end_point(pose, arm_distance):
    """Right arm end ``K_R = K_L + D_2 u(α, β)`` in task XYZ (mm). pose: (..., 6) → (..., 3)."""
    pose = jnp.asarray(pose)
    return pose[..., :3] + arm_distance * cabin_axis(pose[..., 3], pose[..., 4])


def inverse_kinematics(pose, arm_distance):
    """Joint values of both arms for a cabin pose (Eqs. 6–7 read per conventions §4).

    pose: (..., 6) ``[x, y, z, α, β, γ]`` (mm, °). Returns (..., 8) in the joint order
    ``[d_L1, d_L2, d_L3, θ_L, d_R1, d_R2, d_R3, θ_R]`` (mm, °), by :func:`arm_joints`.
    ``arm_distance`` may also be the offsets (K,) of a cabin's K supports: then (..., 4K)
    in the order of :func:`dockjax.robot.support_joints`, by :func:`dockjax.robot.cabin_joints`.
    """
    pose = jnp.asarray(pose)
    u = jnp.moveaxis(cabin_axis(pose[..., 3], pose[..., 4]), -1, 0)
    args = (pose[..., 0], pose[..., 1], pose[..., 2], pose[..., 5], *u)
    if np.ndim(arm_distance) == 1:
        return jnp.stack(cabin_joints(*args, arm_distance), axis=-1)
    return jnp.stack(arm_joints(*args, arm_distance), axis=-1)


def forward_kinematics(joints, arm_distance):
    """Cabin pose from the eight joints through the D-H products (Eqs. 1–2, 10, 12).

    joints: (8,) → pose (6,) ``[x, y, z, α, β, γ]`` (mm, °), with γ in [0, 360). The task
    coordinates of each end are read off the D-H base frame (x = task Z, y = task X,
    z = task Y); pitch and yaw from the vector between the two ends; γ from the left roll.
    """
    joints = jnp.asarray(joints)
    left = forward_left(*joints[LEFT_ARM])[:3, 3]
    right = forward_right(*joints[RIGHT_ARM])[:3, 3]
    to_task = lambda p: jnp.stack([p[1], p[2], p[0]])  # noqa: E731  base (Z, X, Y) → task
    kl, kr = to_task(left), to_task(right)
    axis = (kr - kl) / arm_distance
    pitch = jnp.rad2deg(jnp.arcsin(jnp.clip(axis[1], -1.0, 1.0)))  # Eq. 10
    yaw = jnp.rad2deg(jnp.arctan2(axis[0], axis[2]))  # Eq. 12 when α = 0
    roll = jnp.mod(joints[3], 360.0)
    return jnp.concatenate([kl, jnp.stack([pitch, yaw, roll])])
