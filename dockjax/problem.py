"""The docking problem: a validated configuration (conventions §1–6) that scores
populations in one compiled call.

``DockingProblem(...)`` holds the start and goal poses, the arm distance, the interval
bounds, the limits of paper Table 2 and the decision box; ``evaluate(X)`` returns the two
objectives F (:mod:`dockjax.objectives`) and the 24 limit columns G (:mod:`dockjax.limits`,
with the right arm's treatment from :mod:`dockjax.right_arm`) of every row, through
:func:`score_batch`: the rows go through the kernel in cache-sized passes, the screen's
rare overflow and the adaptive right arm's flagged rows are re-scored inside the same
program, and the rows are shared out over JAX's devices (:mod:`dockjax.devices`).

The computation runs in float64 inside ``jax.enable_x64`` (no global flag is flipped), and
the problem is a JAX pytree, so one compiled kernel serves every start, goal and limit of
the same shape.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import field
from functools import partial
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from . import checks, config, extrema, robot
from . import devices as dev
from .decoding import decode, span_angles, spans
from .kinematics import inverse_kinematics
from .limits import BOUND_TOLERANCE, SCREEN_BAND, columns, maxima, maxima_screened
from .objectives import cabin_jerk, jerk, jerk_nodes_for
from .pytrees import pytree_dataclass, static
from .right_arm import bound_overstatement, right_taylor_maxima
from .store import stored_jit
from .trajectory import Trajectory

__all__ = ["DockingProblem", "RIGHT_ARM_MODES", "make_problem", "score", "score_batch", "bucket_rows", "pad_rows"]


RIGHT_ARM_MODES = ("auto", "bound", "taylor", "adaptive")
"""The treatments of the right arm's nonlinear joints (see :class:`DockingProblem`)."""

def _control_box(start: np.ndarray, goal: np.ndarray, margin: float) -> np.ndarray:
    """The box of the free control points (conventions §3): (2, 6) lower and upper pose, the
    start-to-goal range widened by ``margin`` × the move, or by the zero-move margins
    where a coordinate does not move."""
    delta = goal - start
    m = np.where(delta == 0, np.asarray(config.ZERO_MOVE_MARGIN), margin * np.abs(delta))
    return np.stack([np.minimum(start, goal) - m, np.maximum(start, goal) + m])


def _per_joint(name: str, value, n_joints: int = config.N_JOINTS) -> np.ndarray:
    arr = checks.vector(name, value, sorted({4, n_joints}), positive=True)
    return np.tile(arr, n_joints // 4) if arr.shape[0] == 4 else arr


def _supports(value, arm_distance: float):
    """``(offsets or None, arm distance)`` of the ``supports`` argument (see
    :class:`DockingProblem`): None for the paper's two arms, whose distance is then the
    second offset."""
    if value is None:
        return None, arm_distance
    offs = checks.real_array("supports", value)
    if offs.ndim != 1 or not 2 <= offs.shape[0] <= robot.MAX_SUPPORTS or not np.all(np.isfinite(offs)):
        raise ValueError(f"supports must be 2 to {robot.MAX_SUPPORTS} finite offsets (mm), "
                         f"got {np.asarray(value).tolist()!r}")
    if offs[0] != 0 or np.any(np.diff(offs) <= 0):
        raise ValueError(f"supports must start at 0 (the first support, the pose's reference point) and increase, "
                         f"got {offs.tolist()!r}")
    if arm_distance != config.ARM_DISTANCE and arm_distance != offs[-1]:
        raise ValueError(f"arm_distance {arm_distance:g} and supports {offs.tolist()!r} disagree: give one "
                         "(with supports, arm_distance is the last offset)")
    return (None if len(offs) == 2 else offs), float(offs[-1])


BOUNDARY_FIELDS = ("start_velocity", "start_acceleration", "goal_velocity", "goal_acceleration")
"""The fields of :attr:`DockingProblem.boundary`."""


@pytree_dataclass(kw_only=True, eq=False)
class DockingProblem:
    """The paper's trajectory-planning problem as a batched scoring kernel.

    Keyword arguments (defaults in :mod:`dockjax.config`, conventions §1–6; mm, s, degrees):

    * ``start``, ``goal``: poses ``[x, y, z, pitch, yaw, roll]`` (6,).
    * ``start_velocity``, ``start_acceleration``, ``goal_velocity``, ``goal_acceleration``:
      the pose's velocity (mm/s, °/s) and acceleration (mm/s², °/s²) at t = 0 and at T
      (6,) each; default None: at rest (the paper). When any is non-zero the first and
      last two control points follow from them and the intervals
      (:func:`dockjax.bspline.control_points`), the others default to zero, and
      :attr:`boundary` holds the four; all zero is the same as None.
    * ``arm_distance``: ``D_2``, distance between the arm ends (mm).
    * ``supports``: the offsets (mm) along the cabin axis of K ≥ 2 supports (at most
      :data:`dockjax.robot.MAX_SUPPORTS`), the first 0 and increasing (conventions §4);
      default None: the paper's two arms at 0 and ``arm_distance``. Each support has the
      four joints of the paper's arms (:func:`dockjax.robot.support_joints`): the limits
      then take 4 numbers (every support) or 4K, ``home`` 4K, and G has 4K joints'
      columns. Two supports are the same problem as ``arm_distance`` = the second offset;
      with more, ``arm_distance`` is the last offset, every limit column is exact (no
      screening) and ``right_arm`` is ``"bound"`` or ``"taylor"`` (``"auto"`` chooses
      between them as below, with ``"taylor"`` in the place of ``"adaptive"``).
    * ``interval_bounds``: ``(lo, hi)`` of each knot interval ``h_k`` (s), ``0 < lo < hi``.
    * ``travel``, ``velocity``, ``acceleration``: limits of Table 2, 4 numbers in the arm
      joint order (axial, lift, lateral, roll), applied to both arms, or 8 numbers in the
      joint order ``[d_L1, d_L2, d_L3, θ_L, d_R1, d_R2, d_R3, θ_R]`` (4K with ``supports``).
    * ``jerk``: optional |jerk| limits (mm/s³, °/s³), 4 or 8 numbers like ``velocity``;
      default None: no jerk limits (the paper's 24 columns). With them, G has 32 columns:
      each joint's travel, velocity, acceleration and jerk (:attr:`column_names`).
    * ``home``: (8,) (4K with ``supports``) joint home positions for the travel limits; default the midpoint of
      each joint's start and goal values.
    * ``margin``: relative margin of the control-point box (conventions §3).
    * ``n_control``: the number n of free control points (1 to 64; default 5, the paper's
      ``d_3..d_7``). The spline then has n + 1 knot intervals and the decision vector is
      ``[h_1..h_{n+1}, d_1..d_n]``, 7n + 1 numbers (conventions §2–3 for any n).
    * ``reduced``: if true, only the n + 1 intervals are free and the n control points lie
      evenly spaced on the segment from start to goal (conventions §3); ``n_var`` is then n + 1.
    * ``right_arm``: how the limits of the right arm's nonlinear joints are found; every
      treatment gives columns that are never below the true maxima:

      - ``"bound"``: exact extrema of the first-order expansion in pitch and yaw plus a
        rigorous bound of the remainder (fast). It overstates by at most twice that bound,
        which is far below 0.01 of the limit when pitch and yaw move slowly (tenths of a
        degree over seconds, as in the paper) but not in general: the remainder of the
        acceleration grows with the square of the angular rates, whatever the span length.
      - ``"taylor"``: Taylor models on sub-spans (:func:`dockjax.right_arm.right_taylor_maxima`): the true
        joint's degree-5 Taylor polynomial on as many sub-spans as the remainder needs,
        its certified root chain, and a rigorous remainder bound. Within
        :data:`dockjax.right_arm.TAYLOR_TIGHT` (1e-8) of the limit where it matters (columns within 5 % of
        their limit; every column with ``screen=False``) and within :data:`dockjax.right_arm.TAYLOR_LOOSE`
        (0.005) elsewhere, as long as ``2**TAYLOR_TIGHT_LEVELS`` and
        ``2**TAYLOR_LEVELS`` sub-spans per knot span suffice (beyond, still never
        understated). The dearest treatment.
      - ``"adaptive"``: ``"bound"`` for every candidate whose own overstatement bound is at
        most 0.01, ``"taylor"`` for the others (gathered and scored in fixed-size chunks,
        so the dear path runs only as often as needed). Within 0.01 everywhere.
      - ``"auto"`` (default): ``"bound"`` when its worst-case overstatement over the
        decision box (a hull estimate) is at most 0.01, else ``"adaptive"``; candidates
        that :meth:`evaluate` receives from outside the box, where the bound may exceed
        0.01, are re-scored by ``"adaptive"``. Within 0.01 everywhere.
      (``"exact"``, the former name of ``"taylor"``, is accepted with a warning.)
    * ``jerk_nodes``: Gauss–Legendre nodes per knot span of the right arm's jerk integral
      (3 to 64); default None: 8, 12 or 24 from the box's range of pitch and yaw, enough
      for 1e-9 relative (:data:`dockjax.objectives.JERK_NODES`).

    Attributes: ``n_var``, ``n_intervals`` (n + 1), ``n_obj`` (2), ``kinds`` (the limit kinds,
    :data:`dockjax.robot.LIMIT_KINDS`), ``n_con`` (8 per kind: 24, or 32 with jerk limits),
    ``column_names``, ``n_supports``, ``offsets``, ``joints``, ``joint_names``, ``n_joints``
    (8, or 4K), ``robots`` (one :class:`dockjax.robot.Robot` per pair of supports), ``lower``,
    ``upper`` (natural units, conventions §3 order), ``limits`` (n_joints, kinds),
    ``robot`` (what the kernel takes: D_2, home and the limit table,
    :class:`dockjax.robot.Robot`), and the arguments in resolved form: ``start``, ``goal`` (6,), ``arm_distance``,
    ``interval_bounds`` (a pair of floats), ``travel``, ``velocity``, ``acceleration``,
    ``jerk`` ((8,) or None), ``home`` (8,), ``margin``, ``reduced``, ``right_arm``
    (never ``"auto"``), ``jerk_nodes`` (an int).

    The problem is a JAX pytree (a frozen dataclass): its arrays and numbers are leaves,
    traced under ``jit`` (one compiled kernel serves every start, goal and limit), and
    ``n_control``, ``reduced``, ``right_arm`` and ``jerk_nodes`` are static.
    """

    n_obj: ClassVar[int] = 2

    start: Any = config.START
    goal: Any = config.GOAL
    start_velocity: Any = None
    start_acceleration: Any = None
    goal_velocity: Any = None
    goal_acceleration: Any = None
    arm_distance: Any = config.ARM_DISTANCE
    supports: Any = None
    interval_bounds: Any = config.INTERVAL_BOUNDS
    travel: Any = config.TRAVEL
    velocity: Any = config.VELOCITY
    acceleration: Any = config.ACCELERATION
    jerk: Any = None
    home: Any = None
    margin: Any = config.MARGIN
    n_control: int = static(config.N_FREE)
    reduced: bool = static(False)
    right_arm: str = static("auto")
    jerk_nodes: int | None = static(None)
    box: Any = None
    """``(lower, upper)`` of the decision vector, derived in the constructor (pass None)."""
    _auto_bound: bool = field(default=False, init=False, repr=False)
    """``right_arm="auto"`` chose ``"bound"`` (host-side only: not part of the pytree)."""

    def __post_init__(self):
        if self.box is not None:  # rebuilt from its fields (jit, vmap, tree_map, replace)
            return
        set_ = partial(object.__setattr__, self)
        set_("n_control", checks.integer("n_control", self.n_control, 1, config.MAX_CONTROL))
        start_a = checks.vector("start", self.start, (6,))
        goal_a = checks.vector("goal", self.goal, (6,))
        d2 = checks.vector("arm_distance", [self.arm_distance], (1,), positive=True)[0]
        offsets, d2 = _supports(self.supports, d2)
        set_("supports", offsets)
        n_joints = self.n_joints
        bounds = checks.vector("interval_bounds", self.interval_bounds, (2,))
        lo, hi = bounds
        if lo <= 0 or lo >= hi:
            raise ValueError(f"interval_bounds must satisfy 0 < lo < hi, got ({lo}, {hi})")
        mg = checks.vector("margin", [self.margin], (1,))[0]
        states = {k: None if getattr(self, k) is None else checks.vector(k, getattr(self, k), (6,))
                  for k in BOUNDARY_FIELDS}
        if all(v is None or not np.any(v) for v in states.values()):
            states = dict.fromkeys(BOUNDARY_FIELDS)
        else:
            states = {k: np.zeros(6) if v is None else v for k, v in states.items()}
        if mg < 0:
            raise ValueError(f"margin must be >= 0, got {mg}")
        names = ("travel", "velocity", "acceleration")
        travel, velocity, acceleration = (_per_joint(k, getattr(self, k), n_joints) for k in names)
        jerk_a = None if self.jerk is None else _per_joint("jerk", self.jerk, n_joints)
        limits = np.stack([travel, velocity, acceleration], axis=1)
        with jax.enable_x64(True):
            q0, q1 = (np.asarray(inverse_kinematics(p, d2 if offsets is None else offsets)) for p in (start_a, goal_a))
        home_a = 0.5 * (q0 + q1) if self.home is None else checks.vector("home", self.home, (n_joints,))
        for j, joint in enumerate(self.joints):
            name = joint.name
            move = abs(q1[j] - q0[j])
            if move > 2 * limits[j, 0]:
                raise ValueError(
                    f"start-to-goal move of joint {name} is {move:.6g} {joint.unit}, "
                    f"longer than its stroke 2 x travel = {2 * limits[j, 0]:.6g}"
                )
            for label, q in (("start", q0[j]), ("goal", q1[j])):
                if abs(q - home_a[j]) > limits[j, 0] * (1 + 1e-12):
                    raise ValueError(
                        f"{label} value {q:.6g} of joint {name} is outside its travel "
                        f"{home_a[j]:.6g} ± {limits[j, 0]:.6g} about home"
                    )
        checks.boolean("reduced", self.reduced)
        with np.errstate(over="ignore", invalid="ignore"):
            box_lo, box_hi = _control_box(start_a, goal_a, mg)
        if not (np.all(np.isfinite(box_lo)) and np.all(np.isfinite(box_hi))
                and np.all(np.abs(np.concatenate([box_lo, box_hi])) < 1e12)):
            raise ValueError(f"margin {mg:g} makes the control-point box unbounded (|coordinates| >= 1e12); "
                             "give a smaller margin")
        h_lo, h_hi = np.full(self.n_intervals, lo), np.full(self.n_intervals, hi)
        if self.reduced:
            lower, upper = h_lo, h_hi
        else:
            lower = np.concatenate([h_lo, np.tile(box_lo, self.n_control)])
            upper = np.concatenate([h_hi, np.tile(box_hi, self.n_control)])
        for k, v in (("start", start_a), ("goal", goal_a), ("arm_distance", float(d2)),
                     ("interval_bounds", (float(lo), float(hi))), ("travel", travel), ("velocity", velocity),
                     ("acceleration", acceleration), ("jerk", jerk_a), ("home", home_a), ("margin", float(mg)),
                     ("reduced", bool(self.reduced)), *states.items(), ("box", (lower, upper))):
            set_(k, v)
        right_arm = self.right_arm
        if right_arm == "exact":
            warnings.warn("right_arm='exact' is now called 'taylor'", DeprecationWarning, stacklevel=3)
            right_arm = "taylor"
        if right_arm not in RIGHT_ARM_MODES:
            raise ValueError(f"right_arm must be one of {', '.join(map(repr, RIGHT_ARM_MODES))}, got {right_arm!r}")
        if right_arm == "adaptive" and offsets is not None:
            raise ValueError("right_arm='adaptive' is for two supports; with more give 'bound', 'taylor' or 'auto'")
        set_("_auto_bound", right_arm == "auto" and bound_overstatement(self) <= BOUND_TOLERANCE)
        if right_arm == "auto":
            right_arm = "bound" if self._auto_bound else self.fallback
        set_("right_arm", right_arm)
        jerk_nodes = self.jerk_nodes
        if jerk_nodes is None:
            box = self.pose_box()
            jerk_nodes = jerk_nodes_for(float(np.max(box[1, robot.POSE_ATTITUDE] - box[0, robot.POSE_ATTITUDE])))
        set_("jerk_nodes", checks.integer("jerk_nodes", jerk_nodes, 3, 64))

    @property
    def lower(self):
        """Lower bounds of the decision vector (n_var,), natural units (conventions §3)."""
        return self.box[0]

    @property
    def upper(self):
        """Upper bounds of the decision vector (n_var,), natural units (conventions §3)."""
        return self.box[1]

    @property
    def limits(self):
        """The limit table (8 joints, kinds): travel about home, |velocity|, |acceleration|
        (Table 2) and, with jerk limits, |jerk|; the columns follow :attr:`kinds`."""
        stack = jnp.stack if isinstance(self.travel, jax.Array) else np.stack
        cols = [self.travel, self.velocity, self.acceleration] + ([] if self.jerk is None else [self.jerk])
        return stack(cols, axis=1)

    @property
    def robot(self) -> robot.Robot:
        """The robot's numbers as the kernel takes them (:class:`dockjax.robot.Robot`): D_2,
        :attr:`home` and the limit table :attr:`limits` (traceable: built from the leaves).
        Two supports only (ValueError with more: see :attr:`robots`)."""
        if self.supports is not None:
            raise ValueError(f"this cabin has {self.n_supports} supports: its kernel takes one robot per pair "
                             "of supports (DockingProblem.robots); this operation is for two supports")
        return robot.Robot(arm_distance=self.arm_distance, home=self.home, limits=self.limits)

    def joint_values(self, x, y, z, roll, axis_x, axis_y, axis_z) -> tuple:
        """The pose → joints map of this cabin (:attr:`n_joints` values, power series or
        Taylor coefficients alike): :meth:`dockjax.robot.Robot.joints` for two supports,
        :func:`dockjax.robot.cabin_joints` at :attr:`offsets` for more."""
        if self.supports is None:
            return self.robot.joints(x, y, z, roll, axis_x, axis_y, axis_z)
        return robot.cabin_joints(x, y, z, roll, axis_x, axis_y, axis_z, self.supports)

    @property
    def robots(self) -> tuple:
        """One :class:`dockjax.robot.Robot` per pair (the first support, support s), s = 2..K
        (:func:`dockjax.robot.pair_rows`): the pair's offset as D_2, its home and limit rows;
        ``(robot,)`` for two supports (traceable)."""
        if self.supports is None:
            return (self.robot,)
        take = jnp.take if isinstance(self.home, jax.Array) else np.take
        lim = self.limits
        return tuple(robot.Robot(arm_distance=self.supports[s + 1], home=take(self.home, rows, axis=0),
                                 limits=take(lim, rows, axis=0))
                     for s, rows in enumerate(robot.pair_rows(self.n_supports)))

    @property
    def n_supports(self) -> int:
        """K, the supports carrying the cabin (2: the paper's arms; static)."""
        return 2 if self.supports is None else int(np.shape(self.supports)[-1])

    @property
    def offsets(self) -> np.ndarray:
        """The supports' offsets (K,) along the cabin axis (mm): ``(0, arm_distance)`` for two."""
        return np.array([0.0, self.arm_distance]) if self.supports is None else np.asarray(self.supports)

    @property
    def joints(self) -> tuple:
        """The joints (:func:`dockjax.robot.support_joints`): 8, or 4 per support."""
        return robot.support_joints(self.n_supports)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Names of :attr:`joints`, in the order of G's joints, the samples and the CSV."""
        return tuple(j.name for j in self.joints)

    @property
    def n_joints(self) -> int:
        """Joints: 4 per support (8 for the paper's two arms)."""
        return 4 * self.n_supports

    @property
    def fallback(self) -> str:
        """The right-arm treatment ``"auto"`` turns to where the bound may overstate:
        ``"adaptive"``, or ``"taylor"`` with more than two supports."""
        return "adaptive" if self.supports is None else "taylor"

    @property
    def boundary(self) -> tuple | None:
        """``(start_velocity, start_acceleration, goal_velocity, goal_acceleration)``, each
        (6,), or None when the trajectory starts and ends at rest."""
        if self.start_velocity is None:
            return None
        return tuple(getattr(self, k) for k in BOUNDARY_FIELDS)

    @property
    def kinds(self) -> tuple:
        """The limit kinds of the table's columns (:data:`dockjax.robot.LIMIT_KINDS`): travel,
        velocity, acceleration, and jerk when the problem has jerk limits."""
        return robot.kinds_of(self.n_kinds)

    @property
    def n_kinds(self) -> int:
        """Limit kinds per joint: 3, or 4 with jerk limits."""
        return robot.BASE_KINDS + (self.jerk is not None)

    @property
    def n_con(self) -> int:
        """Limit columns of G: :attr:`n_joints` × :attr:`n_kinds` (24, or 32 with jerk limits,
        for the paper's two arms)."""
        return self.n_joints * self.n_kinds

    @property
    def column_names(self) -> list[str]:
        """What each column of G bounds, joint-major: ``"d_L1 travel"``, ``"d_L1 velocity"``,
        ..., ``"theta_R acceleration"`` (and each joint's ``"jerk"`` with jerk limits)."""
        return robot.column_names(self.n_kinds, self.joints)

    def pose_box(self) -> np.ndarray:
        """The control points' box (:func:`_control_box`), also in the reduced setting, so
        that both settings take the same paths."""
        return _control_box(self.start, self.goal, self.margin)

    def identity(self) -> dict:
        """Every field that decides the problem's scores, as plain JSON data (host-side)."""
        out = {}
        for f in dataclasses.fields(self):
            if not f.init or f.name == "box":
                continue
            if ((f.name == "n_control" and self.n_control == config.N_FREE)
                    or (f.name in ("jerk", "supports", *BOUNDARY_FIELDS) and getattr(self, f.name) is None)):
                continue  # left out at their defaults: the identities and the caches keyed on them stay as they were
            v = getattr(self, f.name)
            out[f.name] = np.asarray(v).tolist() if isinstance(v, (np.ndarray, tuple, list)) else v
        return out

    def with_n_control(self, n_control: int) -> "DockingProblem":
        """The same move, limits and bounds with a spline of ``n_control`` free control points."""
        if n_control == self.n_control:
            return self
        kw = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
              if f.init and f.name not in ("box", "n_control", "right_arm")}
        return DockingProblem(**kw, n_control=n_control, right_arm="auto" if self._auto_bound else self.right_arm)

    def with_right_arm(self, mode: str) -> "DockingProblem":
        """The same problem with another treatment of the right arm (``"bound"``,
        ``"taylor"`` or ``"adaptive"``); shares every array."""
        if mode not in RIGHT_ARM_MODES[1:]:
            raise ValueError(f"mode must be 'bound', 'taylor' or 'adaptive', got {mode!r}")
        return dataclasses.replace(self, right_arm=mode)

    # -- public API ---------------------------------------------------------------------
    @property
    def n_intervals(self) -> int:
        """Knot intervals ``h_1..h_{n+1}`` of the spline: ``n_control + 1`` (6 in the paper)."""
        return self.n_control + 1

    @property
    def n_var(self) -> int:
        """Length of the decision vector: ``n_intervals`` (+ 6 ``n_control`` unless reduced)."""
        return self.n_intervals if self.reduced else self.n_intervals + config.N_POSE * self.n_control

    def __repr__(self) -> str:
        f = lambda a: "(" + ", ".join(f"{v:g}" for v in np.ravel(a)) + ")"  # noqa: E731
        if np.ndim(self.start) != 1:  # leaves with a batch axis (dockjax.bulk.stack_moves)
            return (f"DockingProblem(batch of {np.shape(self.start)[0]} moves, "
                    f"{f'n_control={self.n_control}, ' if self.n_control != config.N_FREE else ''}n_var={self.n_var})")
        return (
            f"DockingProblem(start={f(self.start)}, goal={f(self.goal)}, "
            f"arm_distance={self.arm_distance:g}, "
            f"{f'supports={f(self.supports)}, ' if self.supports is not None else ''}"
            f"interval_bounds={self.interval_bounds}, "
            f"{f'n_control={self.n_control}, ' if self.n_control != config.N_FREE else ''}"
            f"{f'jerk={f(self.jerk)}, ' if self.jerk is not None else ''}"
            f"n_var={self.n_var}{', reduced' if self.reduced else ''})"
        )

    def check_population(self, X) -> np.ndarray:
        """Validate a population: (n, n_var) finite numbers → float64 array. Not clipped."""
        arr = checks.real_array("X", X)
        if arr.ndim != 2 or arr.shape[1] != self.n_var:
            raise ValueError(f"X must have shape (n, {self.n_var}), got {np.shape(X)}")
        if not np.all(np.isfinite(arr)):
            bad = np.argwhere(~np.isfinite(arr))[0]
            raise ValueError(
                f"X must be finite, got {arr[tuple(bad)]} at row {bad[0]}, column {bad[1]}"
            )
        if np.any(arr[:, : self.n_intervals] <= 0):
            bad = np.argwhere(arr[:, : self.n_intervals] <= 0)[0]
            raise ValueError(
                f"X intervals h_k must be > 0, got {arr[tuple(bad)]} at row {bad[0]}, column {bad[1]}"
            )
        return arr

    def evaluate(
        self, X, *, precision: str = "float64", screen: bool = True, devices: int | None = None,
        rows: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Score a population in one compiled call.

        X: (n, n_var) decision vectors in natural units (conventions §3 order; not clipped).
        Returns ``F`` (n, 2) ``[T, jerk]`` and ``G`` (n, 24) as float64 NumPy arrays.
        ``precision="float32"`` runs the same kernel in single precision (faster, about
        1e-5 relative; for quick looks only). ``screen=False`` sends every knot span through
        the exact root chain (several times slower): every column is then exact to rounding,
        instead of exact near its limit (within 5 %) and at most 0.009 above the truth
        elsewhere (conventions §6 allows 0.01); see :func:`score_batch`. ``devices``: how many of
        JAX's local devices share the rows (default all, at most one per
        :data:`ROWS_PER_DEVICE` rows; see :mod:`dockjax.devices`). ``rows``: score in calls
        of exactly that many rows (the last one padded), so that every call of one ``rows``
        shares one compiled program; default one call, padded to :func:`bucket_rows`.
        """
        arr = self.check_population(X)
        checks.optional_integer("rows", rows, 1)
        if rows is not None and len(arr) > 0:
            parts = [self.evaluate(pad_rows(arr[i:i + rows], rows), precision=precision, screen=screen,
                                   devices=devices) for i in range(0, len(arr), rows)]
            n = [len(arr[i:i + rows]) for i in range(0, len(arr), rows)]
            return tuple(np.concatenate([p[k][:m] for p, m in zip(parts, n)]) for k in (0, 1))
        if precision not in ("float64", "float32"):
            raise ValueError(f"precision must be 'float64' or 'float32', got {precision!r}")
        if not isinstance(screen, (bool, np.bool_)):
            raise ValueError(f"screen must be True or False, got {screen!r}")
        n = arr.shape[0]
        if n == 0:
            return np.zeros((0, self.n_obj)), np.zeros((0, self.n_con))
        devs = dev.choose(devices, -(-n // ROWS_PER_DEVICE))
        # pad to a bucket of rows (copies of row 0, dropped again): populations of nearby
        # sizes share one compiled shape; every device gets as many rows
        rows = -(-bucket_rows(n) // len(devs)) * len(devs)
        padded = pad_rows(arr, rows) if n else arr
        where = dev.mesh(devs)
        dtype = jnp.float64 if precision == "float64" else jnp.float32
        with jax.enable_x64(precision == "float64"):
            Xj = dev.put(jnp.asarray(padded, dtype), where)
            F, G, need = dev.sharded(_evaluate_rows, (bool(screen),), where, (dev.SAME, dev.SHARDED), self, Xj)
            F, G = np.asarray(F, np.float64)[:n], np.asarray(G, np.float64)[:n]
        rows = np.flatnonzero(np.asarray(need)[:n]) if self._auto_bound else ()
        if len(rows):
            # "auto" chose the bound because it meets conventions §6's 0.01 on the decision box;
            # these rows (outside the box) are where it may not: the adaptive treatment
            # re-scores them (compiled only when first needed)
            G = np.array(G)
            _, G[rows] = self.with_right_arm(self.fallback).evaluate(arr[rows], precision=precision, screen=screen,
                                                                   devices=devices)
        bad = ~(np.all(np.isfinite(F), 1) & np.all(np.isfinite(G), 1))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(f"X row {i} is outside the kernel's numeric range (its scores overflow in "
                             f"{precision}: intervals {arr[i, :self.n_intervals].tolist()}); keep intervals and "
                             "control points within a few orders of magnitude of the problem's box")
        return F, G

    def evaluate_jax(self, X, *, screen: bool = True):
        """Traceable batch scoring for use inside jit/vmap (the caller sets the precision).
        X: (n, n_var) → F (n, 2), G (n, 24); ``screen`` as in :meth:`evaluate`."""
        return score_batch(self, X, screen)

    def decode(self, x):
        """The trajectory of one decision vector (n_var,). See :class:`dockjax.Trajectory`."""
        arr = self.check_population(np.asarray(x, dtype=np.float64)[None, :])[0]
        return Trajectory(self, arr)


def make_problem(preset: str, right_arm: str = "auto", n_control: int = config.N_FREE) -> DockingProblem:
    """The problem of a preset (:data:`dockjax.config.PRESETS`: ``"paper"`` or ``"wide"``);
    ``right_arm`` and ``n_control`` as in :class:`DockingProblem`."""
    checks.choice("preset", preset, tuple(config.PRESETS))
    return DockingProblem(**config.PRESETS[preset], right_arm=right_arm, n_control=n_control)


def _score(problem: DockingProblem, x, screen: bool = False):
    """F (2,), G (24,), the adaptive mode's ``need`` flag and the screen's ``over`` flag of
    one candidate (``screen``: :func:`dockjax.limits.maxima_screened` instead of :func:`dockjax.limits.maxima`)."""
    h, _, c, ref = spans(problem, x)
    if problem.supports is not None:
        return _score_supports(problem, h, c, ref)
    rb = problem.robot
    F = jnp.stack([jnp.sum(h), jerk(rb, c, h, ref, nodes=problem.jerk_nodes)])
    if screen and problem.right_arm != "taylor":
        M, need, over, series = maxima_screened(rb, c, h, ref)
    else:
        M, need = maxima(rb, c, h, ref, taylor=problem.right_arm == "taylor", with_need=True, screen=screen)
        over, series = jnp.zeros((), bool), None
    return F, columns(rb, M), need, over, series


def _score_supports(problem: DockingProblem, h, c, ref):
    """:func:`_score` of a cabin on more than two supports: the maxima of each pair of
    supports (:attr:`DockingProblem.robots`, every span through the root chain, the
    problem's right-arm treatment) joined into the cabin's joints; the jerk objective over
    all of them (:func:`dockjax.objectives.cabin_jerk`)."""
    taylor = problem.right_arm == "taylor"
    parts = [maxima(rb, c, h, ref, taylor=taylor, with_need=True) for rb in problem.robots]
    M = robot.join_pairs([m for m, _ in parts])
    need = jnp.any(jnp.stack([n for _, n in parts]))
    F = jnp.stack([jnp.sum(h), cabin_jerk(problem.robots, c, h, ref, nodes=problem.jerk_nodes)])
    return F, columns(None, M, problem.limits), need, jnp.zeros((), bool), None


def score(problem: DockingProblem, x):
    """Objectives and constraint values of one candidate. x: (n_var,) → F (2,), G (24,).

    Every column comes from the full root chain (no screening). In the ``"adaptive"``
    right-arm mode the ``"taylor"`` treatment replaces the bound where the candidate needs
    it (both are computed: use :func:`score_batch` for populations)."""
    if problem.right_arm == "adaptive":
        F, G, need, _, _ = _score(problem.with_right_arm("bound"), x)
        _, Gx, _, _, _ = _score(problem.with_right_arm("taylor"), x)
        return F, jnp.where(need, Gx, G)
    F, G, _, _, _ = _score(problem, x)
    return F, G


def _score_plain(problem: DockingProblem, X, screen: bool = False):
    # candidates along the last axis inside (X.T): XLA then streams every elementwise step
    # over contiguous candidates (faster than along the first)
    F, G, need, over, spans = jax.vmap(
        partial(_score, screen=screen), in_axes=(None, 1), out_axes=(1, 1, 0, 0, 0)
    )(problem, X.T)
    return F.T, G.T, need, over, spans


def right_columns(problem: DockingProblem) -> slice:
    """The columns of G of the right arm's axial, lift and lateral joints (contiguous,
    joint-major: 12..20, or 16..27 with jerk limits)."""
    k = problem.n_kinds
    return slice(robot.ATTITUDE_JOINTS.start * k, robot.ATTITUDE_JOINTS.stop * k)


def _right_columns_taylor(problem: DockingProblem, X, screen: bool, active=None):
    """G's :func:`right_columns` (the right arm's axial, lift and lateral joints) of the rows
    of X (n, n_var) by :func:`right_taylor_maxima`. → (n, 3 · kinds)."""
    h, _, c = jax.vmap(partial(decode, problem))(X)
    ref = jax.vmap(span_angles)(c, h)
    M = right_taylor_maxima(problem.robot, c, h, ref, SCREEN_BAND if screen else None, active)
    full = jnp.zeros(M.shape[:1] + (config.N_JOINTS, problem.n_kinds), M.dtype).at[:, robot.ATTITUDE_JOINTS].set(M)
    return columns(problem.robot, full)[:, right_columns(problem)]


ADAPTIVE_CHUNK = 32
"""Candidates per call of a re-scoring path (the ``"adaptive"`` right arm's exact path, the
screen's overflow)."""
SCREEN_CHUNK = 8
"""Candidates per call of the screen's overflow path (rare: small chunks waste least)."""


def _replace_rows(G, mask, rows, chunk: int):
    """Replace the rows of G where ``mask`` holds by ``rows(idx)`` (k, 24) for index
    chunks of ``k = min(n, chunk)``: the flagged rows are gathered in order and scored
    inside a ``lax.while_loop`` that stops when none is left (usually at once)."""
    n = G.shape[0]
    k = min(n, chunk)
    # the flagged rows first, in order (a scatter: cheaper than a sort); the rest of
    # ``order`` is row 0, never reached but by the clamped last window
    count = jnp.sum(mask)
    slot = jnp.where(mask, jnp.cumsum(mask) - 1, n)
    order = jnp.zeros(n, jnp.int32).at[slot].set(jnp.arange(n, dtype=jnp.int32), mode="drop")

    def body(carry):
        start, G = carry
        # dynamic_slice clamps the window into [0, n): a row met twice, or one that was not
        # flagged, keeps its values (so a row's result never depends on its neighbours)
        idx = jax.lax.dynamic_slice(order, (start,), (k,))
        return start + k, G.at[idx].set(jnp.where(mask[idx, None], rows(idx), G[idx]))

    _, G = jax.lax.while_loop(lambda c: c[0] < count, body, (jnp.zeros((), count.dtype), G))
    return G


def _taylor_rows(problem: DockingProblem, X, G, mask, screen: bool):
    """``rows`` for :func:`_replace_rows`: the rows of G with the right arm's nonlinear
    columns from :func:`right_taylor_maxima` (only the flagged rows are scored)."""
    taylor = problem.with_right_arm("taylor")
    cols = right_columns(problem)
    return lambda idx: G[idx].at[:, cols].set(_right_columns_taylor(taylor, X[idx], screen, mask[idx]))


def _full_chain_rows(problem: DockingProblem, spans, G):
    """``rows`` for :func:`_replace_rows`: G from every span of the screen's stored series
    through the full root chain (the screen's overflow; no re-decoding). The jerk columns,
    never screened, are kept."""
    series, lengths, extra = spans

    def rows(idx):
        vals, _ = extrema.span_maxima(series[idx], lengths[idx])  # (k, spans × joints, 3)
        M = vals.reshape(idx.shape[0], problem.n_intervals, -1, 3).max(axis=1) + extra[idx]
        if problem.jerk is None:
            return columns(problem.robot, M)
        base = columns(problem.robot, M, problem.limits[:, :3]).reshape(M.shape)
        jerk = G[idx].reshape(M.shape[:2] + (problem.n_kinds,))[..., 3:]
        return jnp.concatenate([base, jerk], -1).reshape(idx.shape[0], -1)

    return rows


KERNEL_CHUNK = 48
"""Most candidates per pass of :func:`score_batch` (its default ``chunk``)."""


def _score_pass(problem: DockingProblem, X, screen: bool, taylor: bool):
    """One pass of :func:`score_batch` (bound right arm; with ``taylor`` its nonlinear
    columns then come from :func:`right_taylor_maxima`): F, G (screen overflow re-scored)
    and the adaptive mode's ``need`` flags of the rows X."""
    F, G, need, over, spans = _score_plain(problem, X, screen)
    if spans is not None:
        G = _replace_rows(G, over, _full_chain_rows(problem, spans, G), SCREEN_CHUNK)
    if taylor:
        G = G.at[:, right_columns(problem)].set(_right_columns_taylor(problem.with_right_arm("taylor"), X, screen))
    return F, G, need


def score_batch(problem: DockingProblem, X, screen: bool = True, chunk: int | None = None,
                with_need: bool = False):
    """Traceable batch scoring: X (n, n_var) → F (n, 2), G (n, 24) (and, ``with_need``, the
    rows (n,) whose bound treatment may overstate by more than :data:`BOUND_TOLERANCE`).

    ``screen`` (default): the limit columns come from :func:`dockjax.limits.maxima_screened` (cheap
    bounds everywhere, the exact root chain on the few spans that need it); candidates
    with more such spans than the screen's slots are re-scored by the full path.
    ``screen=False``: every span through the root chain (several times dearer; every column
    exact to rounding, the right arm's as the treatment allows).

    The right arm's nonlinear columns: ``"bound"`` as the kernel computes them;
    ``"taylor"`` from :func:`right_taylor_maxima` for every row; ``"adaptive"``: every
    candidate is scored by the bound path, and those whose own overstatement bound
    exceeds :data:`BOUND_TOLERANCE` get their nine columns from
    :func:`right_taylor_maxima` (see :func:`_replace_rows`), so the dear path costs only
    what is needed (usually nothing).

    The rows go through in passes (``lax.map``) of at most ``chunk`` (default
    :data:`KERNEL_CHUNK`), split evenly (padded with copies of row 0, dropped again): a
    pass's intermediates then stay in the CPU's caches, where one pass over thousands of
    rows streams every intermediate array (hundreds of kB each) through memory.
    """
    chunk = KERNEL_CHUNK if chunk is None else chunk
    checks.integer("chunk", chunk, 1)
    adaptive = problem.right_arm == "adaptive"
    if problem.supports is None:
        taylor = problem.right_arm == "taylor"
        bound = problem.with_right_arm("bound")
    else:  # more than two supports: _score_supports applies the treatment, every span exact
        taylor, bound, screen = False, problem, False
    n = X.shape[0]
    passes = max(1, -(-n // chunk))
    size = -(-n // passes)
    if passes == 1:
        F, G, need = _score_pass(bound, X, screen, taylor)
    else:
        Xp = jnp.concatenate([X, jnp.broadcast_to(X[:1], (passes * size - n, X.shape[1]))])
        out = jax.lax.map(lambda x: _score_pass(bound, x, screen, taylor), Xp.reshape(passes, size, -1))
        F, G, need = (a.reshape((passes * size,) + a.shape[2:])[:n] for a in out)
    if adaptive:
        G = _replace_rows(G, need, _taylor_rows(problem, X, G, need, screen), ADAPTIVE_CHUNK)
    return (F, G, need) if with_need else (F, G)


@stored_jit(static_argnums=(0,))
def _evaluate_rows(screen: bool, problem: DockingProblem, X):
    """:func:`score_batch` for :meth:`DockingProblem.evaluate` (``screen`` first: static),
    with the bound treatment's ``need`` flags."""
    return score_batch(problem, X, screen, with_need=True)


ROWS_PER_DEVICE = 256
""":meth:`DockingProblem.evaluate` gives a device at least this many rows (fewer are
quicker on one device than shared out)."""


def pad_rows(a: np.ndarray, size: int) -> np.ndarray:
    """a (n, ...) with copies of its first row appended up to ``size`` rows (n >= 1): one
    compiled shape for nearby batch sizes; the caller drops the extra rows again."""
    return np.concatenate([a, np.repeat(a[:1], size - len(a), 0)])


def bucket_rows(n: int) -> int:
    """Rows of the compiled call of :meth:`DockingProblem.evaluate` for n candidates: 16 up
    to 16 rows, then multiples of 16 up to 256, of 128 up to 4096, then of 1024 (at most
    ~11 % padding beyond 16 rows, ~2.5 % beyond 4096)."""
    for step, top in ((16, 256), (128, 4096)):
        if n <= top:
            return max(step, -(-n // step) * step)
    return -(-n // 1024) * 1024
