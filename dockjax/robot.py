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
* **Supports** (conventions §4): a cabin carried by K ≥ 2 supports at offsets
  ``0 = o_1 < o_2 < … < o_K`` along its axis, each with the four joints of the paper's arms
  (:func:`support_joints`, :func:`cabin_joints`). The first support is the left arm; every
  other one has the right arm's joint map with its own offset. The kernel sees such a cabin
  as K − 1 *pairs* (the first support with each other one), each a two-arm :class:`Robot`
  (:func:`pair_rows`); :func:`join_pairs` puts the pairs' per-joint results back in the
  cabin's joint order.
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
           "cabin_axis", "cabin_axis_jets", "arm_joints", "LIMIT_KEYS", "check_limit_table", "MAX_SUPPORTS",
           "support_names", "support_joints", "pair_rows", "join_pairs", "cabin_joints"]


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


def column_names(n_kinds: int, joints: tuple = JOINTS) -> list[str]:
    """Names of the ``len(joints) · n_kinds`` columns of G, joint-major: ``"d_L1 travel"``,
    ``"d_L1 velocity"``, ..."""
    return [f"{j.name} {k.name}" for j in joints for k in kinds_of(n_kinds)]


def sampled_quantity(sample: dict, kind: LimitKind, home) -> np.ndarray:
    """The signed quantity that limit ``kind`` bounds, from a plan's samples (m, 8): the
    position about ``home`` (8,) for travel, else the time derivative of the kind's order
    (``sample[DERIVATIVES[kind.order]]``). Its largest magnitude is what the limit caps."""
    if kind.order == 0:
        return np.asarray(sample["position"]) - np.asarray(home)
    return np.asarray(sample[DERIVATIVES[kind.order]])


def by_kind(G, n_joints: int = len(JOINTS)) -> np.ndarray:
    """G (..., n_joints · kinds) as a float64 array (..., n_joints, kinds) (joint-major,
    :func:`column_names`; 8 joints: the paper's two arms)."""
    G = np.asarray(G, np.float64)
    return G.reshape(G.shape[:-1] + (n_joints, G.shape[-1] // n_joints))


MAX_SUPPORTS = 16
"""Most supports a cabin takes (:func:`support_joints`)."""

_ARM = (("d_{}1", "mm"), ("d_{}2", "mm"), ("d_{}3", "mm"), ("theta_{}", "deg"))


def support_names(k: int) -> tuple[str, ...]:
    """Names of k supports: ``("L", "R")`` for two (the paper's arms), else ``"L"``, ``"M1"``,
    …, ``"M{k−2}"``, ``"R"`` (left end, middle ones in order, right end)."""
    return ("L", *(f"M{i}" for i in range(1, k - 1)), "R")


def support_joints(k: int) -> tuple[Joint, ...]:
    """The 4k joints of a cabin on k supports, support by support, each in the arm order
    (axial, lift, lateral, roll): for two supports :data:`JOINTS`; a middle support ``M1``
    has ``d_M1_1``, ``d_M1_2``, ``d_M1_3``, ``theta_M1``. Every support but the first has
    attitude-dependent axial, lift and lateral joints."""
    if k == 2:
        return JOINTS
    return tuple(Joint(name.format(s + "_" * (len(s) > 1 and j < 3)), unit, i > 0 and j < 3)
                 for i, s in enumerate(support_names(k)) for j, (name, unit) in enumerate(_ARM))


def pair_rows(k: int) -> list[np.ndarray]:
    """For each support s = 2..k, the rows (8,) of the pair (the first support, support s)
    in the 4k joints of :func:`support_joints`: the pair's left arm is the first support,
    its right arm support s."""
    return [np.r_[LEFT_ARM.start:LEFT_ARM.stop, 4 * s:4 * s + 4] for s in range(1, k)]


def join_pairs(parts, axis: int = 0):
    """The k − 1 pairs' per-joint arrays (8 joints on ``axis``, :func:`pair_rows`) as one
    array of the cabin's 4k joints: the first support's from the first pair, each other
    support's from its own pair. One pair is returned as it is. NumPy in, NumPy out."""
    if len(parts) == 1:
        return parts[0]
    xp = np if all(isinstance(p, np.ndarray) for p in parts) else jnp
    left, right = np.arange(LEFT_ARM.start, LEFT_ARM.stop), np.arange(RIGHT_ARM.start, RIGHT_ARM.stop)
    return xp.concatenate([xp.take(parts[0], left, axis=axis)] + [xp.take(p, right, axis=axis) for p in parts],
                          axis=axis)



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


def cabin_joints(x, y, z, roll, axis_x, axis_y, axis_z, offsets) -> tuple:
    """The 4k joints of a cabin on k supports at ``offsets`` (k,) along its axis (mm, the
    first 0): the first support's joints as the left arm's, each other support's as the
    right arm's of :func:`arm_joints` with ``D_2`` its offset (its end ``K_L + o u``).
    With offsets ``(0, D_2)`` it is :func:`arm_joints`."""
    out = list(arm_joints(x, y, z, roll, axis_x, axis_y, axis_z, offsets[1]))
    for o in offsets[2:]:
        out += arm_joints(x, y, z, roll, axis_x, axis_y, axis_z, o)[RIGHT_ARM]
    return tuple(out)


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
