"""The robot as data: its joints and the kinds of limit a joint can carry (conventions §4, §6).

* :data:`JOINTS`: the eight joints ``[d_L1, d_L2, d_L3, θ_L, d_R1, d_R2, d_R3, θ_R]`` with
  their units and whether they depend on the cabin's attitude (pitch and yaw: the right
  arm's axial, lift and lateral joints, :data:`ATTITUDE_JOINTS`), and the one pose → joints
  map, :func:`arm_joints` (Eqs. 6–7 read per conventions §4) with the cabin axis
  :func:`cabin_axis` and its Taylor series :func:`cabin_axis_jets`.
* :data:`LIMIT_KINDS`: travel, velocity, acceleration and jerk, each with the order of the
  time derivative it bounds, its unit suffix and how it scales when the trajectory is
  slowed by ``h → s h`` (by ``s^−power``). A problem's limit table has one column per kind it
  uses (:attr:`dockjax.DockingProblem.kinds`), joint-major in G.
* :class:`Robot`: one robot's numbers as the kernel takes them (a pytree: the arm distance,
  the home position and the limit table), :attr:`dockjax.DockingProblem.robot`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import jax.numpy as jnp
import numpy as np

from . import config, jets
from .pytrees import pytree_dataclass

__all__ = ["Joint", "LimitKind", "Robot", "JOINTS", "ATTITUDE_JOINTS", "LEFT_ARM", "RIGHT_ARM", "LIMIT_KINDS",
           "BASE_KINDS", "DERIVATIVES", "POSE_ATTITUDE", "kinds_of", "column_names", "sampled_quantity", "by_kind",
           "cabin_axis", "cabin_axis_jets", "arm_joints", "LIMIT_KEYS", "check_limit_table"]


@dataclass(frozen=True)
class Joint:
    """One joint: ``name``, ``unit`` (``"mm"`` or ``"deg"``) and ``attitude`` (its value
    depends on pitch and yaw through sines and cosines, conventions §4)."""

    name: str
    unit: str
    attitude: bool = False


@dataclass(frozen=True)
class LimitKind:
    """One kind of limit: ``name``; ``order`` of the time derivative it bounds (travel 0:
    the position about home); ``power``: slowing the trajectory by ``h → s h`` divides the
    quantity by ``s**power`` (0: unchanged); ``suffix`` of its unit (``"/s^2"``)."""

    name: str
    order: int
    power: int

    @property
    def suffix(self) -> str:
        """The unit suffix of the ``order``-th time derivative (:data:`dockjax.config.RATE_SUFFIXES`)."""
        return config.RATE_SUFFIXES[self.order]


ATTITUDE_JOINTS = slice(4, 7)
"""The joints whose values depend on the attitude: the right arm's axial, lift and lateral
joints (contiguous in the joint order)."""

POSE_ATTITUDE = slice(3, 5)
"""The attitude angles pitch α and yaw β in a pose ``[x, y, z, α, β, γ]`` (and in a control
point): the coordinates the joints of :data:`ATTITUDE_JOINTS` depend on."""

LEFT_ARM, RIGHT_ARM = slice(0, 4), slice(4, 8)
"""Each arm's four joints (axial, lift, lateral, roll) in the joint order."""

JOINTS: tuple[Joint, ...] = tuple(
    Joint(name, unit, ATTITUDE_JOINTS.start <= j < ATTITUDE_JOINTS.stop)
    for j, (name, unit) in enumerate(zip(config.JOINT_NAMES, config.JOINT_UNITS)))
"""The joints in the order of G, the samples and the CSV (conventions §4)."""

LIMIT_KINDS: tuple[LimitKind, ...] = (
    LimitKind("travel", 0, 0), LimitKind("velocity", 1, 1), LimitKind("acceleration", 2, 2), LimitKind("jerk", 3, 3),
)
"""Every kind of limit, in the order of a joint's columns."""

DERIVATIVES: tuple[str, ...] = ("position", "velocity", "acceleration", "jerk")
"""Names of a joint's time derivatives of order 0..3 (the keys of a plan's samples)."""

BASE_KINDS = 3
"""The kinds every problem has (paper Table 2: travel, velocity, acceleration); jerk is optional."""


LIMIT_KEYS: tuple[str, ...] = (*(k.name for k in LIMIT_KINDS), "home")
"""Keys of a limit table (a limits file, an instance's ``limits``): one per kind of limit
(4 or 8 numbers each, as :class:`dockjax.DockingProblem` takes them) and ``home`` (8 numbers)."""


def check_limit_table(data: Any, where: str) -> dict:
    """``data`` if it is a table of limit overrides (:data:`LIMIT_KEYS`, each a list of
    numbers), else ValueError naming ``where`` and what is wrong. The lengths and values are
    :class:`dockjax.DockingProblem`'s to check."""
    if not isinstance(data, dict):
        raise ValueError(f"{where} must hold a table of limits")
    unknown = sorted(set(data) - set(LIMIT_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; allowed {sorted(LIMIT_KEYS)}")
    for key, value in data.items():
        if not isinstance(value, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                  for v in value):
            raise ValueError(f"{where}: {key} must be a list of numbers, got {value!r}")
    return data


def kinds_of(n_kinds: int) -> tuple[LimitKind, ...]:
    """The first ``n_kinds`` (3 or 4) of :data:`LIMIT_KINDS`."""
    return LIMIT_KINDS[:n_kinds]


def column_names(n_kinds: int) -> list[str]:
    """Names of the ``8 · n_kinds`` columns of G, joint-major: ``"d_L1 travel"``,
    ``"d_L1 velocity"``, ..."""
    return [f"{j.name} {k.name}" for j in JOINTS for k in kinds_of(n_kinds)]


def sampled_quantity(sample: dict, kind: LimitKind, home) -> np.ndarray:
    """The signed quantity that limit ``kind`` bounds, from a plan's samples (m, 8): the
    position about ``home`` (8,) for travel, else the time derivative of the kind's order
    (``sample[DERIVATIVES[kind.order]]``). Its largest magnitude is what the limit caps."""
    if kind.order == 0:
        return np.asarray(sample["position"]) - np.asarray(home)
    return np.asarray(sample[DERIVATIVES[kind.order]])


def by_kind(G) -> np.ndarray:
    """G (..., 8 · kinds) as a float64 array (..., 8 joints, kinds) (joint-major,
    :func:`column_names`)."""
    G = np.asarray(G, np.float64)
    return G.reshape(G.shape[:-1] + (len(JOINTS), G.shape[-1] // len(JOINTS)))



def cabin_axis(pitch_deg, yaw_deg):
    """Unit cabin axis ``u(α, β) = (cos α sin β, sin α, cos α cos β)`` in task XYZ (conventions §4)."""
    a, b = jnp.deg2rad(pitch_deg), jnp.deg2rad(yaw_deg)
    return jnp.stack([jnp.cos(a) * jnp.sin(b), jnp.sin(a), jnp.cos(a) * jnp.cos(b)], axis=-1)


def cabin_axis_jets(pitch, yaw, near=None) -> tuple[list, list, list]:
    """Jets (:mod:`dockjax.jets`) of the cabin axis ``(u_x, u_y, u_z)`` from jets of pitch
    and yaw (lists of normalised Taylor coefficients, in radians).

    ``near``: None (the sines and cosines of the angles' values by the library), or, per
    angle, ``(offset, sin ref, cos ref)``: the value is ``ref + offset`` (radians, a small
    offset from a reference angle whose sine and cosine are known), and its sine and cosine
    come from :func:`dockjax.jets.sin_cos_near`."""
    trig = []
    for a, ref in zip((pitch, yaw), near or (None, None)):
        trig.append(jets.sin_cos(a) if ref is None else jets.sin_cos(a, *jets.sin_cos_near(*ref)))
    (sa, ca), (sb, cb) = trig
    # u_z before u_x: the order of the uses of cos α fixes the order in which reverse-mode
    # differentiation sums its cotangents, hence the gradients' last bits
    uz = jets.mul(ca, cb)
    return jets.mul(ca, sb), sa, uz


def arm_joints(x, y, z, roll, axis_x, axis_y, axis_z, arm_distance) -> tuple:
    """The one map from the cabin pose to the eight joints (Eqs. 6–7 read per conventions §4).

    ``x, y, z``: the left arm's end point (mm); ``roll`` γ (°); ``axis_*``: the cabin axis
    ``u(α, β) = (cos α sin β, sin α, cos α cos β)`` (:func:`cabin_axis`); the right arm's
    end is ``K_R = K_L + D_2 u``. Returns the joints in the order
    ``[d_L1, d_L2, d_L3, θ_L, d_R1, d_R2, d_R3, θ_R]`` =
    ``[−z, y, −x, γ, z + D_2 u_z, y + D_2 u_y, −(x + D_2 u_x), −γ]``.

    Linear in its arguments, so it serves values, power series (one coefficient array per
    argument) and Taylor coefficients alike: every caller in dockjax — the inverse
    kinematics (:func:`dockjax.kinematics.inverse_kinematics`), the kernel's joint series and
    jets (through :meth:`Robot.joints`), :class:`dockjax.Trajectory` — goes through it.
    """
    d2 = arm_distance
    return (-z, y, -x, roll, z + d2 * axis_z, y + d2 * axis_y, -(x + d2 * axis_x), -roll)


@pytree_dataclass
class Robot:
    """One robot's numbers, as the kernel (:mod:`dockjax.limits`, :mod:`dockjax.right_arm`,
    :mod:`dockjax.objectives`) takes them; every field is a leaf, so one compiled kernel
    serves every robot with the same number of limit kinds.

    * ``arm_distance``: D_2, the right arm's distance (mm, conventions §4), a scalar;
    * ``home``: (8,) the joints' home position, about which travel is measured (mm, °);
    * ``limits``: (8 joints, kinds) the limit table, columns in the order of
      :data:`LIMIT_KINDS` (travel, velocity, acceleration and, with jerk limits, jerk).

    The joint table (:data:`JOINTS`) and the form of the pose → joints map
    (:func:`arm_joints`) are the same for every robot of this design; :meth:`joints` applies
    the map with this robot's arm distance.
    """

    arm_distance: Any
    home: Any
    limits: Any

    @property
    def n_kinds(self) -> int:
        """Limit kinds per joint (static: the table's shape): 3, or 4 with jerk limits."""
        return self.limits.shape[-1]

    @property
    def has_jerk(self) -> bool:
        """Whether the table has a jerk column (static)."""
        return self.n_kinds > BASE_KINDS

    def joints(self, x, y, z, roll, axis_x, axis_y, axis_z) -> tuple:
        """The eight joints of this robot from the pose's terms: :func:`arm_joints` with
        ``D_2 = arm_distance`` (values, power series or Taylor coefficients alike)."""
        return arm_joints(x, y, z, roll, axis_x, axis_y, axis_z, self.arm_distance)
