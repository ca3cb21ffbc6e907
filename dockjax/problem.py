"""The docking problem: decision vector → trajectory → objectives and limits (SPEC §3–6).

``DockingProblem(...).evaluate(X)`` scores a whole population in one jitted, vmapped call:

* ``F[:, 0] = T = Σ h_k`` (Eq. 24);
* ``F[:, 1] = Σ_j sqrt((1/T) ∫_0^T q_j'''(t)² dt)`` over the eight joints (Eq. 25): the
  integrand is a polynomial for the joints linear in the pose (integrated in closed form
  per knot span), and smooth for the right arm's axial, lift and lateral joints (through
  sin/cos of pitch and yaw: Gauss–Legendre per knot span, with 8, 12 or 24 nodes as the
  decision box's range of pitch and yaw requires for 1e-9 relative: SPEC §5,
  :data:`JERK_NODES`);
* ``G[:, 3j + k] = max_t |quantity_k(t)| / limit_k − 1`` for joint j and quantity
  k ∈ (travel about home, velocity, acceleration) (SPEC §6). No column is ever below the
  true maximum: for the joints linear in the pose the extrema sit at span ends or at roots
  of the next derivative, found by the derivative chain of :mod:`dockjax.extrema`, each
  root certified by a sign change and its value carrying a rigorous margin; for the right
  arm's nonlinear joints every treatment (``right_arm``, see :class:`DockingProblem`) is
  an enclosure — the first-order expansion in pitch and yaw plus a remainder bound
  (``"bound"``), or Taylor models on sub-spans (``"taylor"``, :func:`right_taylor_maxima`).
  A safety margin of ``1e-9`` of the limit is added against rounding.
  **Screening** (the batch default, :func:`_maxima_screened`): cheap bounds from a grid of
  samples per span decide which spans can hold a column's maximum; only those go through
  the root chain. Columns within 5 % of their limit are exact as above; the others
  (comfortably satisfied or clearly violated) may overstate by at most 0.009 of the limit
  (SPEC §6 allows 0.01). ``screen=False`` sends every span through the chain.

The computation runs in float64 inside ``jax.enable_x64`` (no global flag is flipped), and
the problem is a JAX pytree, so one compiled kernel serves every start, goal and limit of
the same shape.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import field
from functools import partial
from typing import Any, ClassVar, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from . import bspline, config, extrema, jets
from . import devices as dev
from .fusion import materialize
from .pytrees import pytree_dataclass, static
from .kinematics import inverse_kinematics

__all__ = ["DockingProblem", "score", "score_batch"]

_DEG = math.pi / 180.0
G_SAFETY = 1e-9
"""Added to every constraint column so that rounding never understates it (SPEC §6)."""
RIGHT_ARM_MODES = ("auto", "bound", "taylor", "adaptive")
"""The treatments of the right arm's nonlinear joints (see :class:`DockingProblem`)."""
BOUND_TOLERANCE = 1e-2
"""SPEC §6: the most a G column may overstate its true value."""

JERK_NODES = ((1.0, 8), (8.0, 12), (math.inf, 24))
"""Gauss–Legendre nodes per knot span of the right arm's jerk integral (SPEC §5: 1e-9
relative) by the decision box's range of pitch and yaw (degrees, the larger): up to 1°, 8
nodes; up to 8°, 12; beyond, 24. Measured (session 8) against a 96-node reference over
candidates with knot intervals from 0.1 to 10 s and interior points at the box's corners,
worst relative error of the objective: 8 nodes 1e-13 at 0.24° (the paper's box), 1e-10 at
1.4°, 1e-9 at 2.6° (found by the property test), 3e-8 at 6°; 12 nodes 7e-13 at 7.2°,
1e-10 at 12°; 24 nodes 3e-14 at 24°, 48° and 90°. The nodes are static: one compiled
kernel per count."""


def jerk_nodes_for(attitude_range: float) -> int:
    """Nodes of :data:`JERK_NODES` for a box whose pitch and yaw span at most
    ``attitude_range`` degrees."""
    return next(n for top, n in JERK_NODES if attitude_range <= top)


def _vector(name: str, value, lengths: Sequence[int], positive: bool = False) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 1 or arr.shape[0] not in lengths:
        want = " or ".join(str(n) for n in lengths)
        raise ValueError(f"{name} must have {want} numbers, got {np.asarray(value).tolist()!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()!r}")
    if positive and np.any(arr <= 0):
        raise ValueError(f"{name} must be > 0, got {arr.tolist()!r}")
    return arr


def _control_box(start: np.ndarray, goal: np.ndarray, margin: float) -> np.ndarray:
    """The box of the free control points (SPEC §3): (2, 6) lower and upper pose, the
    start-to-goal range widened by ``margin`` × the move, or by the zero-move margins
    where a coordinate does not move."""
    delta = goal - start
    m = np.where(delta == 0, np.asarray(config.ZERO_MOVE_MARGIN), margin * np.abs(delta))
    return np.stack([np.minimum(start, goal) - m, np.maximum(start, goal) + m])


def _per_joint(name: str, value) -> np.ndarray:
    arr = _vector(name, value, (4, 8), positive=True)
    return np.tile(arr, 2) if arr.shape[0] == 4 else arr


@pytree_dataclass(kw_only=True, eq=False)
class DockingProblem:
    """The paper's trajectory-planning problem as a batched scoring kernel.

    Keyword arguments (SPEC defaults in :mod:`dockjax.config`; mm, s, degrees):

    * ``start``, ``goal``: poses ``[x, y, z, pitch, yaw, roll]`` (6,).
    * ``arm_distance``: ``D_2``, distance between the arm ends (mm).
    * ``interval_bounds``: ``(lo, hi)`` of each knot interval ``h_k`` (s), ``0 < lo < hi``.
    * ``travel``, ``velocity``, ``acceleration``: limits of Table 2, 4 numbers in the arm
      joint order (axial, lift, lateral, roll), applied to both arms, or 8 numbers in the
      joint order ``[d_L1, d_L2, d_L3, θ_L, d_R1, d_R2, d_R3, θ_R]``.
    * ``home``: (8,) joint home positions for the travel limits; default the midpoint of
      each joint's start and goal values.
    * ``margin``: relative margin of the control-point box (SPEC §3).
    * ``reduced``: if true, only the six intervals are free and ``d_3..d_7`` lie evenly
      spaced on the segment from start to goal (SPEC §3); ``n_var`` is then 6.
    * ``right_arm``: how the limits of the right arm's nonlinear joints are found; every
      treatment gives columns that are never below the true maxima:

      - ``"bound"``: exact extrema of the first-order expansion in pitch and yaw plus a
        rigorous bound of the remainder (fast). It overstates by at most twice that bound,
        which is far below 0.01 of the limit when pitch and yaw move slowly (tenths of a
        degree over seconds, as in the paper) but not in general: the remainder of the
        acceleration grows with the square of the angular rates, whatever the span length.
      - ``"taylor"``: Taylor models on sub-spans (:func:`right_taylor_maxima`): the true
        joint's degree-5 Taylor polynomial on as many sub-spans as the remainder needs,
        its certified root chain, and a rigorous remainder bound. Within
        :data:`TAYLOR_TIGHT` (1e-8) of the limit where it matters (columns within 5 % of
        their limit; every column with ``screen=False``) and within :data:`TAYLOR_LOOSE`
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
      for 1e-9 relative (:data:`JERK_NODES`).

    Attributes: ``n_var``, ``n_obj`` (2), ``n_con`` (24), ``lower``, ``upper`` (natural
    units, SPEC §3 order), ``limits`` (8, 3), and the arguments in resolved form: ``start``,
    ``goal`` (6,), ``arm_distance``, ``interval_bounds`` (a pair of floats), ``travel``,
    ``velocity``, ``acceleration``, ``home`` (8,), ``margin``, ``reduced``, ``right_arm``
    (never ``"auto"``), ``jerk_nodes`` (an int).

    The problem is a JAX pytree (a frozen dataclass): its arrays and numbers are leaves,
    traced under ``jit`` (one compiled kernel serves every start, goal and limit), and
    ``reduced``, ``right_arm`` and ``jerk_nodes`` are static.
    """

    n_obj: ClassVar[int] = 2
    n_con: ClassVar[int] = config.N_CON

    start: Any = config.START
    goal: Any = config.GOAL
    arm_distance: Any = config.ARM_DISTANCE
    interval_bounds: Any = config.INTERVAL_BOUNDS
    travel: Any = config.TRAVEL
    velocity: Any = config.VELOCITY
    acceleration: Any = config.ACCELERATION
    home: Any = None
    margin: Any = config.MARGIN
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
        start_a = _vector("start", self.start, (6,))
        goal_a = _vector("goal", self.goal, (6,))
        d2 = _vector("arm_distance", [self.arm_distance], (1,), positive=True)[0]
        bounds = _vector("interval_bounds", self.interval_bounds, (2,))
        lo, hi = bounds
        if lo <= 0 or lo >= hi:
            raise ValueError(f"interval_bounds must satisfy 0 < lo < hi, got ({lo}, {hi})")
        mg = _vector("margin", [self.margin], (1,))[0]
        if mg < 0:
            raise ValueError(f"margin must be >= 0, got {mg}")
        travel, velocity, acceleration = (_per_joint(k, getattr(self, k)) for k in ("travel", "velocity", "acceleration"))
        limits = np.stack([travel, velocity, acceleration], axis=1)
        with jax.enable_x64(True):
            q0 = np.asarray(inverse_kinematics(start_a, d2))
            q1 = np.asarray(inverse_kinematics(goal_a, d2))
        home_a = 0.5 * (q0 + q1) if self.home is None else _vector("home", self.home, (8,))
        for j, name in enumerate(config.JOINT_NAMES):
            move = abs(q1[j] - q0[j])
            if move > 2 * limits[j, 0]:
                raise ValueError(
                    f"start-to-goal move of joint {name} is {move:.6g} {config.JOINT_UNITS[j]}, "
                    f"longer than its stroke 2 x travel = {2 * limits[j, 0]:.6g}"
                )
            for label, q in (("start", q0[j]), ("goal", q1[j])):
                if abs(q - home_a[j]) > limits[j, 0] * (1 + 1e-12):
                    raise ValueError(
                        f"{label} value {q:.6g} of joint {name} is outside its travel "
                        f"{home_a[j]:.6g} ± {limits[j, 0]:.6g} about home"
                    )
        box_lo, box_hi = _control_box(start_a, goal_a, mg)
        h_lo, h_hi = np.full(6, lo), np.full(6, hi)
        if self.reduced:
            lower, upper = h_lo, h_hi
        else:
            lower = np.concatenate([h_lo, np.tile(box_lo, config.N_FREE)])
            upper = np.concatenate([h_hi, np.tile(box_hi, config.N_FREE)])
        for k, v in (("start", start_a), ("goal", goal_a), ("arm_distance", float(d2)),
                     ("interval_bounds", (float(lo), float(hi))), ("travel", travel), ("velocity", velocity),
                     ("acceleration", acceleration), ("home", home_a), ("margin", float(mg)),
                     ("reduced", bool(self.reduced)), ("box", (lower, upper))):
            set_(k, v)
        right_arm = self.right_arm
        if right_arm == "exact":
            warnings.warn("right_arm='exact' is now called 'taylor'", DeprecationWarning, stacklevel=3)
            right_arm = "taylor"
        if right_arm not in RIGHT_ARM_MODES:
            raise ValueError(f"right_arm must be one of {', '.join(map(repr, RIGHT_ARM_MODES))}, got {right_arm!r}")
        set_("_auto_bound", right_arm == "auto" and self._bound_overstatement() <= BOUND_TOLERANCE)
        if right_arm == "auto":
            right_arm = "bound" if self._auto_bound else "adaptive"
        set_("right_arm", right_arm)
        jerk_nodes = self.jerk_nodes
        if jerk_nodes is None:
            box = self._pose_box()
            jerk_nodes = jerk_nodes_for(float(np.max(box[1, 3:5] - box[0, 3:5])))
        elif isinstance(jerk_nodes, bool) or not isinstance(jerk_nodes, (int, np.integer)) or not 3 <= jerk_nodes <= 64:
            raise ValueError(f"jerk_nodes must be None (chosen from the box) or an integer from 3 to 64, got {jerk_nodes!r}")
        set_("jerk_nodes", int(jerk_nodes))

    @property
    def lower(self):
        """Lower bounds of the decision vector (n_var,), natural units (SPEC §3)."""
        return self.box[0]

    @property
    def upper(self):
        """Upper bounds of the decision vector (n_var,), natural units (SPEC §3)."""
        return self.box[1]

    @property
    def limits(self):
        """Limits (8 joints, 3): travel about home, |velocity|, |acceleration| (Table 2)."""
        stack = jnp.stack if isinstance(self.travel, jax.Array) else np.stack
        return stack([self.travel, self.velocity, self.acceleration], axis=1)

    def _pose_box(self) -> np.ndarray:
        """The control points' box (:func:`_control_box`), also in the reduced setting, so
        that both settings take the same paths."""
        return _control_box(self.start, self.goal, self.margin)

    def _bound_overstatement(self) -> float:
        """Worst-case overstatement (in units of the limit) of the ``"bound"`` treatment of
        the right arm over the decision box, from hull bounds of pitch and yaw and their
        derivatives (``|α'| <= 5 Δ/h_lo``, ``|α''| <= 40 Δ/h_lo²``)."""
        box = self._pose_box()
        rng = _DEG * (box[1, 3:5] - box[0, 3:5])
        far = np.minimum(1.0, _DEG * np.max(np.abs(box[:, 3:5]), axis=0))
        h_lo = self.interval_bounds[0]
        with jax.enable_x64(True):
            hess = np.asarray(_hessian_norms(far[0], far[1]))
            b = np.asarray(
                _remainder_bound(
                    self.arm_distance, hess, np.hypot(*rng), 5 * np.hypot(*rng) / h_lo,
                    40 * np.hypot(*rng) / h_lo**2,
                )
            )
        return float(np.max(2 * b / self.limits[4:7]))

    def with_right_arm(self, mode: str) -> "DockingProblem":
        """The same problem with another treatment of the right arm (``"bound"``,
        ``"taylor"`` or ``"adaptive"``); shares every array."""
        if mode not in RIGHT_ARM_MODES[1:]:
            raise ValueError(f"mode must be 'bound', 'taylor' or 'adaptive', got {mode!r}")
        return dataclasses.replace(self, right_arm=mode)

    # -- public API ---------------------------------------------------------------------
    @property
    def n_var(self) -> int:
        return config.N_INTERVALS if self.reduced else config.N_VAR

    def __repr__(self) -> str:
        f = lambda a: "(" + ", ".join(f"{v:g}" for v in np.ravel(a)) + ")"  # noqa: E731
        return (
            f"DockingProblem(start={f(self.start)}, goal={f(self.goal)}, "
            f"arm_distance={self.arm_distance:g}, interval_bounds={self.interval_bounds}, "
            f"n_var={self.n_var}{', reduced' if self.reduced else ''})"
        )

    def check_population(self, X) -> np.ndarray:
        """Validate a population: (n, n_var) finite numbers → float64 array. Not clipped."""
        arr = np.asarray(X, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != self.n_var:
            raise ValueError(f"X must have shape (n, {self.n_var}), got {np.shape(X)}")
        if not np.all(np.isfinite(arr)):
            bad = np.argwhere(~np.isfinite(arr))[0]
            raise ValueError(
                f"X must be finite, got {arr[tuple(bad)]} at row {bad[0]}, column {bad[1]}"
            )
        if np.any(arr[:, : config.N_INTERVALS] <= 0):
            bad = np.argwhere(arr[:, : config.N_INTERVALS] <= 0)[0]
            raise ValueError(
                f"X intervals h_k must be > 0, got {arr[tuple(bad)]} at row {bad[0]}, column {bad[1]}"
            )
        return arr

    def evaluate(
        self, X, *, precision: str = "float64", screen: bool = True, devices: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Score a population in one compiled call.

        X: (n, n_var) decision vectors in natural units (SPEC §3 order; not clipped).
        Returns ``F`` (n, 2) ``[T, jerk]`` and ``G`` (n, 24) as float64 NumPy arrays.
        ``precision="float32"`` runs the same kernel in single precision (faster, about
        1e-5 relative; for quick looks only). ``screen=False`` sends every knot span through
        the exact root chain (about 2.5× slower): every column is then exact to rounding,
        instead of exact near its limit (within 5 %) and at most 0.009 above the truth
        elsewhere (SPEC §6 allows 0.01); see :func:`score_batch`. ``devices``: how many of
        JAX's local devices share the rows (default all, at most one per
        :data:`ROWS_PER_DEVICE` rows; see :mod:`dockjax.devices`).
        """
        arr = self.check_population(X)
        if precision not in ("float64", "float32"):
            raise ValueError(f"precision must be 'float64' or 'float32', got {precision!r}")
        if not isinstance(screen, (bool, np.bool_)):
            raise ValueError(f"screen must be True or False, got {screen!r}")
        n = arr.shape[0]
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
            # "auto" chose the bound because it meets SPEC §6's 0.01 on the decision box;
            # these rows (outside the box) are where it may not: the adaptive treatment
            # re-scores them (compiled only when first needed)
            G = np.array(G)
            _, G[rows] = self.with_right_arm("adaptive").evaluate(arr[rows], precision=precision, screen=screen,
                                                                   devices=devices)
        return F, G

    def evaluate_jax(self, X, *, screen: bool = True):
        """Traceable batch scoring for use inside jit/vmap (the caller sets the precision).
        X: (n, n_var) → F (n, 2), G (n, 24); ``screen`` as in :meth:`evaluate`."""
        return score_batch(self, X, screen)

    def decode(self, x):
        """The trajectory of one decision vector (n_var,). See :class:`dockjax.Trajectory`."""
        from .trajectory import Trajectory

        arr = self.check_population(np.asarray(x, dtype=np.float64)[None, :])[0]
        return Trajectory(self, arr)


# -- the kernel ----------------------------------------------------------------------------


def decode(problem: DockingProblem, x):
    """Intervals, knots and span coefficients of one candidate.

    x: (n_var,) → ``h`` (6,), ``u`` (17,), ``c`` (6 spans, 6 powers, 6 pose coordinates).
    """
    h = x[: config.N_INTERVALS]
    if problem.reduced:
        interior = bspline.line_control_points(problem.start, problem.goal).astype(x.dtype)
    else:
        interior = x[config.N_INTERVALS :].reshape(config.N_FREE, config.N_POSE)
    u = bspline.knots(h)
    ctrl = bspline.control_points(problem.start, problem.goal, interior)
    # Materialise: stops XLA from re-fusing (and so recomputing) the conversion into
    # every broadcasting consumer downstream.
    return materialize((h, u, bspline.span_coefficients(ctrl, u)))


_RIGHT_COORDS = ((2, 3, 4), (1, 3), (0, 3, 4))
"""Pose coordinates (x=0, y=1, z=2, α=3, β=4) each right-arm joint depends on."""


def span_angles(c, h):
    """Pitch and yaw (°) at the middle of each span with their sines and cosines.

    c: (6, 6, 6), h: (6,) → (mid (6, 2), sin (6, 2), cos (6, 2)): the reference angles of
    the expansions used for the right arm (one trig call per span and angle).
    """
    mid = bspline.poly_eval(jnp.swapaxes(c[..., 3:5], 1, 2), 0.5 * h[:, None])  # (6, 2)
    return mid, jnp.sin(_DEG * mid), jnp.cos(_DEG * mid)


def right_terms(problem: DockingProblem, c, tau, order: int, joints, ref) -> list:
    """Jets of the right arm's axial, lift and lateral joints (SPEC §4), as coefficient lists.

    c: (6, 6 powers, 6 coords) span coefficients; tau: (6, m) local times per span; ref:
    :func:`span_angles`. Returns, for each requested (static) joint, the list of its
    normalised Taylor coefficients 0..order, each (6, m): (0) ``d_R1 = z + D_2 cos α cos β``,
    (1) ``d_R2 = y + D_2 sin α``, (2) ``d_R3 = −(x + D_2 cos α sin β)``.
    """
    coords = sorted(set().union(*(_RIGHT_COORDS[j] for j in joints)))
    pose = {i: bspline.poly_taylor_terms(c[:, None, :, i], tau, order) for i in coords}
    mid, sin_m, cos_m = ref
    trig = {}
    for i in (3, 4):
        if i in pose:
            s0, c0 = jets.sin_cos_near(
                _DEG * (pose[i][0] - mid[:, i - 3, None]), sin_m[:, i - 3, None], cos_m[:, i - 3, None]
            )
            trig[i] = jets.sin_cos([_DEG * a for a in pose[i]], s0, c0)
    d2 = problem.arm_distance
    make = (
        lambda: [p + d2 * q for p, q in zip(pose[2], jets.mul(trig[3][1], trig[4][1]))],
        lambda: [p + d2 * q for p, q in zip(pose[1], trig[3][0])],
        lambda: [-(p + d2 * q) for p, q in zip(pose[0], jets.mul(trig[3][1], trig[4][0]))],
    )
    return [make[j]() for j in joints]


def right_jets(problem: DockingProblem, c, tau, order: int, joints, ref):
    """:func:`right_terms` stacked: (6, m, len(joints), order + 1)."""
    return jnp.stack([jets.stack(j) for j in right_terms(problem, c, tau, order, joints, ref)], axis=-2)


def _joint_polys(problem: DockingProblem, c, h, ref):
    """Power series of the eight joints on each span, minus home; the right arm's axial,
    lift and lateral joints linearised in pitch and yaw about the span's middle.
    c: (6, 6, 6), h: (6,) → (6 spans, 8 joints, 6 powers)."""
    x, y, z, a, b, g = (c[:, :, i] for i in range(6))
    mid, sin_m, cos_m = ref
    am, bm = mid[:, 0:1], mid[:, 1:2]
    sa, ca, sb, cb = sin_m[:, 0:1], cos_m[:, 0:1], sin_m[:, 1:2], cos_m[:, 1:2]
    e0 = jnp.zeros(6, c.dtype).at[0].set(1.0)
    da = _DEG * (a - am * e0)
    db = _DEG * (b - bm * e0)
    d2 = problem.arm_distance
    r1 = z + d2 * (ca * cb * e0 - sa * cb * da - ca * sb * db)
    r2 = y + d2 * (sa * e0 + ca * da)
    r3 = -(x + d2 * (ca * sb * e0 - sa * sb * da + ca * cb * db))
    polys = jnp.stack([-z, y, -x, g, r1, r2, r3, -g], axis=1)
    return polys - problem.home[None, :, None] * e0


def _maxima(problem: DockingProblem, c, h, ref, *, with_need: bool = False, screen: bool = False):
    """``max_t |q_j − home_j|``, ``max |q_j'|``, ``max |q_j''|`` per joint. → (8, 3).

    With ``with_need``, also whether this candidate's bound treatment of the right arm may
    overstate by more than :data:`BOUND_TOLERANCE` (always False in the ``"taylor"``
    treatment). ``screen``: as in :func:`right_taylor_maxima` (the ``"taylor"`` treatment's
    choice of tight columns)."""
    polys = materialize(_joint_polys(problem, c, h, ref))
    hh = jnp.broadcast_to(h[:, None], polys.shape[:2])
    spans, _ = extrema.span_maxima(polys, hh)
    lin = extrema.reduce_max(spans, 0)  # (8, 3)
    if problem.right_arm == "taylor":
        right = right_taylor_maxima(problem, c[None], h[None], tuple(a[None] for a in ref), screen)[0]
        need = jnp.zeros((), bool)
    else:
        rem = extrema.reduce_max(_right_remainder_bounds(problem, c, h, ref), 0)  # (3 joints, 3)
        right = lin[4:7] + rem
        need = jnp.any(2.0 * rem > BOUND_TOLERANCE * problem.limits[4:7])
    out = lin.at[4:7].set(right)
    return (out, need) if with_need else out


SCREEN_SLOTS = 3
"""Spans per candidate that :func:`_maxima_screened` sends through the exact root chain."""
SCREEN_BAND = 0.05
"""Columns whose estimate lies within this fraction of the limit (either side) are exact."""
SCREEN_SLACK = 0.009
"""The most a column outside the band may overstate (SPEC §6 allows 0.01)."""


def _maxima_screened(problem: DockingProblem, c, h, ref):
    """The maxima of :func:`_maxima` (bound treatment of the right arm) for a fraction of
    the cost. → ``(M (8, 3), need, over, spans)``.

    Every span gets the cheap two-sided estimates of :func:`dockjax.extrema.span_bounds`
    (``L <= max <= U``). A column's value is the largest span value, so a span whose U is
    at most the column's largest L (plus a tolerance) cannot change it by more than the
    tolerance. The tolerance is 0 for columns whose estimate lies within
    :data:`SCREEN_BAND` of the limit (there the decisions are made: those columns are
    exact), and :data:`SCREEN_SLACK` of the limit, less the right arm's remainder
    overstatement, for the others (comfortably satisfied or clearly violated limits; SPEC
    §6 allows 0.01). The spans whose velocity or acceleration fails the test — usually
    none or one per candidate — go through the root chain of those two
    (:func:`dockjax.extrema.rate_maxima`), up to :data:`SCREEN_SLOTS` of them; ``over``
    flags a candidate with more, or with a failing travel (rare: positions are smooth):
    its columns are then valid upper bounds, not necessarily within the tolerance, and it
    is re-scored by the full chain on all its spans, as :func:`score_batch` does (from the
    returned ``(span series (48, 6), span lengths (48,), right-arm remainders (8, 3))``)."""
    polys = materialize(_joint_polys(problem, c, h, ref))  # (6, 8, 6)
    hh = jnp.broadcast_to(h[:, None], polys.shape[:2])
    low, up = materialize(extrema.span_bounds(polys, hh))  # (6, 8, 3); read by several fusions
    rem = extrema.reduce_max(_right_remainder_bounds(problem, c, h, ref), 0)  # (3 joints, 3)
    extra = jnp.zeros((8, 3), c.dtype).at[4:7].set(rem)
    lim = problem.limits
    top = low.max(axis=0)
    est = top + extra
    far = (est < (1.0 - SCREEN_BAND) * lim) | (est > (1.0 + SCREEN_BAND) * lim)
    tol = jnp.where(far, jnp.maximum(SCREEN_SLACK * lim - 2.0 * extra, 0.0), 0.0)
    # computed once: XLA would otherwise recompute the test in each of its consumers
    fail = materialize((up > top + tol).reshape(-1, 3))  # (48 spans × joints, 3)
    flags = fail[:, 1] | fail[:, 2]
    n_items = flags.shape[0]
    items = jnp.arange(n_items)
    # the first SCREEN_SLOTS flagged items, in order (index 0 for an empty slot)
    rest, idx, filled = flags, [], []
    for _ in range(SCREEN_SLOTS):
        i = jnp.argmax(rest)
        idx.append(i)
        filled.append(rest[i])
        rest = rest & (items > i)
    idx = jnp.stack(idx)  # (R,)
    exact = extrema.rate_maxima(polys.reshape(n_items, -1)[idx], hh.reshape(-1)[idx])  # (R, 2)
    up_items = up.reshape(n_items, 3)
    # rates: the largest U of the spans not sent to the chain, then each chain result
    # (never above its span's U) at its joint; all values are >= 0
    slotted = flags & ~rest
    rate = extrema.reduce_max(jnp.where(slotted[:, None], 0.0, up_items[:, 1:]).reshape(up.shape[:2] + (2,)), 0)
    joint = jnp.arange(up.shape[1])
    for r in range(SCREEN_SLOTS):
        hit = (joint == idx[r] % up.shape[1]) & filled[r]  # (8,)
        rate = jnp.maximum(rate, jnp.where(hit[:, None], jnp.minimum(up_items[idx[r], 1:], exact[r]), 0.0))
    M = jnp.concatenate([extrema.reduce_max(up[..., :1], 0), rate], axis=1) + extra
    need = jnp.any(2.0 * rem > BOUND_TOLERANCE * lim[4:7])
    over = jnp.any(rest) | jnp.any(fail[:, 0])
    return M, need, over, (polys.reshape(n_items, -1), hh.reshape(-1), extra)


def _hessian_norms(sin_a, sin_b):
    """Bounds of the Hessian norms of ``cos a cos b``, ``sin a``, ``cos a sin b`` given
    bounds of ``|sin a|`` and ``|sin b|`` (their eigenvalues are ``−cos(a ± b)``,
    ``−sin a`` and ``−cos a sin b ± sin a cos b``)."""
    one = jnp.ones_like(sin_a)
    return jnp.stack([one, sin_a, jnp.minimum(one, sin_a + sin_b)], axis=-1)


def _remainder_bound(d2, hess, delta, vel, acc):
    """``D_2 ×`` bounds of the remainder of the first-order expansion and its first two
    time derivatives: ``½Hδ²``, ``HδV``, ``H(δA + V²)`` (mean-value theorem). (..., 3 joints, 3)."""
    h = hess
    return d2 * jnp.stack(
        [0.5 * h * delta[..., None] ** 2, h * (delta * vel)[..., None],
         h * (delta * acc + vel * vel)[..., None]],
        axis=-1,
    )


def _right_remainder_bounds(problem: DockingProblem, c, h, ref):
    """Rigorous bounds, per span, of how far the right arm's axial, lift and lateral joints
    (and their first two derivatives) can be from their first-order expansion in pitch
    and yaw about the span's middle. → (6 spans, 3 joints, 3 quantities), mm.

    From the series of α and β re-centred at the span's middle,
    ``|α(t) − α_m| <= Σ_{m>=1} |a_m| (h/2)^m`` and likewise for the derivatives.
    """
    mid, sin_m, _ = ref
    half = 0.5 * h[:, None]
    ang = [_DEG * jnp.abs(a) for a in bspline.poly_taylor_terms(jnp.swapaxes(c[:, :, 3:5], 1, 2), half)]
    hp = [jnp.ones_like(half)]  # powers of h/2 by products (no pow): (6, 1) each
    for _ in range(5):
        hp.append(hp[-1] * half)
    dev = sum(ang[m] * hp[m] for m in range(1, 6))  # (6, 2)
    vel = sum(m * ang[m] * hp[m - 1] for m in range(1, 6))
    acc = sum(m * (m - 1) * ang[m] * hp[m - 2] for m in range(2, 6))
    def norm(v):  # Euclidean norm with a finite gradient (0) at 0
        s = jnp.sum(v * v, -1)
        return jnp.where(s > 0, jnp.sqrt(jnp.where(s > 0, s, 1.0)), 0.0)

    sin_bound = jnp.minimum(1.0, jnp.abs(sin_m) + dev)  # (6, 2)
    hess = _hessian_norms(sin_bound[:, 0], sin_bound[:, 1])  # (6, 3)
    return _remainder_bound(problem.arm_distance, hess, norm(dev), norm(vel), norm(acc))


TAYLOR_TIGHT = 1e-8
"""Target overstatement of the ``"taylor"`` treatment, in units of the limit, for the
columns it makes tight (those near their limit, or all with ``screen=False``): twice the
remainder bound of every sub-span that can hold the maximum, when at most
``2**TAYLOR_TIGHT_LEVELS`` sub-spans per knot span achieve it."""
TAYLOR_TIGHT_LEVELS = 5
TAYLOR_LOOSE = 0.005
"""Target overstatement of the ``"taylor"`` treatment's first pass, in units of the limit
(half of SPEC §6's 0.01), met whenever ``2**TAYLOR_LEVELS`` sub-spans per knot span do."""
TAYLOR_LEVELS = 14
TAYLOR_ANCHORS = (0, 1, 2, 4, 7, 10, 13)
"""Subdivision levels at which :func:`_taylor_anchors` evaluates the remainder bounds."""
TAYLOR_ROUND = 96
"""Sub-spans scored per trip of the ``"taylor"`` treatment's loop."""


def _hyperbolic_jet6(w, r):
    """Sixth Taylor coefficients ``(cosh U)_6``, ``(sinh U)_6`` at r of ``U(s) = Σ_{k=1..5} w_k s^k``
    (w: 5 nonnegative arrays, r: like them), about s = r: the recurrences
    ``sh_k = (1/k) Σ_j j u_j ch_{k−j}``, ``ch_k = (1/k) Σ_j j u_j sh_{k−j}`` (all terms >= 0)."""
    zero = jnp.zeros_like(r)
    w = jnp.broadcast_arrays(zero, *w)
    u = bspline.poly_taylor_terms(jnp.stack(w, -1), r) + [zero]  # U(r + σ), orders 0..6
    sh, ch = [jnp.sinh(u[0])], [jnp.cosh(u[0])]
    for k in range(1, 7):
        sh.append(sum(j * u[j] * ch[k - j] for j in range(1, k + 1)) / k)
        ch.append(sum(j * u[j] * sh[k - j] for j in range(1, k + 1)) / k)
    return ch[6], sh[6]


def _taylor_remainders(wa, wp, wm, trig, r, d2):
    """Bounds of ``|R|``, ``|R'|``, ``|R''|`` on ``|s| <= r`` of the remainders
    ``R(s) = q(t_c + s) − Σ_{k<=5} q_k s^k`` of the right arm's axial, lift and lateral
    joints' Taylor series about t_c. → (..., 3 joints, 3) in mm, mm/s, mm/s².

    ``wa``, ``wp``, ``wm``: 5 arrays each, nonnegative majorants of the Taylor coefficients
    1..5 about t_c of α, α + β and α − β (rad); ``trig``: upper bounds of
    ``(|sin α|, |cos α|, |sin(α+β)|, |cos(α+β)|, |sin(α−β)|, |cos(α−β)|)`` at t_c; r like
    them.

    The joints are ``pose + D_2 f`` with f one of ``sin α``,
    ``cos α cos β = ½[cos(α+β) + cos(α−β)]``, ``cos α sin β = ½[sin(β+α) + sin(β−α)]``
    (SPEC §4); the pose is quintic, so R is ``D_2`` times f's remainder. With
    ``φ = φ_c + u(s)``, ``sin φ = sin φ_c cos u + cos φ_c sin u`` and
    ``cos φ = cos φ_c cos u − sin φ_c sin u``; the coefficients of ``cos u`` and ``sin u``
    are at most those of ``cosh U`` and ``sinh U`` when U majorises u. So every Taylor
    coefficient of f from order 6 on is at most that of a series M with nonnegative
    coefficients, and ``|R^(i)(s)| <= D_2 M^(6)(r) r^{6−i}/(6−i)!`` (Taylor's theorem on M,
    whose derivatives increase on r >= 0). All terms are nonnegative, so rounding is
    relative; the factor ``1 + 1e-12`` covers it.
    """
    sa, ca, sp, cp, sm, cm = trig
    cha, sha = _hyperbolic_jet6(wa, r)
    chp, shp = _hyperbolic_jet6(wp, r)
    chm, shm = _hyperbolic_jet6(wm, r)
    m6 = jnp.stack([0.5 * (cp * chp + sp * shp + cm * chm + sm * shm),  # d_R1: cos α cos β
                    sa * cha + ca * sha,  # d_R2: sin α
                    0.5 * (sp * chp + cp * shp + sm * chm + cm * shm)], -1)  # d_R3: cos α sin β
    r2 = r * r
    r4 = r2 * r2
    powers = jnp.stack([r4 * r2, 6.0 * r4 * r, 30.0 * r4], -1)  # 6! r^(6-i) / (6-i)!
    return (d2 * (1.0 + 1e-12)) * m6[..., :, None] * powers[..., None, :]


def _angle_sums(sa, ca, sb, cb):
    """``(sin α, cos α, sin(α+β), cos(α+β), sin(α−β), cos(α−β))`` from the sines and cosines."""
    return (sa, ca, sa * cb + ca * sb, ca * cb - sa * sb, sa * cb - ca * sb, ca * cb + sa * sb)


def _span_majorants(c, h, ref):
    """Per knot span, majorants valid about any point of it: ``(w_α, w_+, w_−)`` (5 arrays
    (6, 3) of ``sup |φ^(k)|/k!``, k = 1..5, for φ = α, α+β, α−β in rad, from the series
    re-centred at the span's middle) and bounds of the six sines and cosines of
    :func:`_taylor_remainders` (their values at the middle plus the largest deviation)."""
    half = 0.5 * h[:, None]
    m = bspline.poly_taylor_terms(jnp.swapaxes(c[:, :, 3:5], 1, 2), half)  # 6 × (6 spans, 2)
    m = [_DEG * jnp.stack([a[:, 0], a[:, 0] + a[:, 1], a[:, 0] - a[:, 1]], -1) for a in m]
    hp = [jnp.ones_like(half)]
    for _ in range(5):
        hp.append(hp[-1] * half)
    w = [sum(math.comb(j, k) * jnp.abs(m[j]) * hp[j - k] for j in range(k, 6)) for k in range(1, 6)]
    dev = sum(jnp.abs(m[j]) * hp[j] for j in range(1, 6))  # (6, 3): largest |φ − φ_mid|
    _, sin_m, cos_m = ref
    mid = _angle_sums(sin_m[:, 0], cos_m[:, 0], sin_m[:, 1], cos_m[:, 1])
    trig = [jnp.minimum(1.0, jnp.abs(v) + dev[:, i // 2]) for i, v in enumerate(mid)]
    return w, trig


def _taylor_anchors(problem: DockingProblem, c, h, ref):
    """Twice the remainder bounds, in units of the limits, of a knot span cut into
    ``2**a`` sub-spans, at the levels ``a`` of :data:`TAYLOR_ANCHORS`. → (6 spans, anchors,
    3 joints, 3)."""
    w, trig = _span_majorants(c, h, ref)
    anchors = np.asarray(TAYLOR_ANCHORS)
    r = h[:, None] * jnp.asarray(0.5 ** (anchors + 1), h.dtype)  # (6, A)
    col = lambda i: [a[:, i, None] for a in w]  # noqa: E731
    rem = _taylor_remainders(col(0), col(1), col(2), [t[:, None] for t in trig], r, problem.arm_distance)
    return 2.0 * rem / problem.limits[4:7]


def _taylor_levels(anchors, tol, top: int):
    """Subdivision level of each knot span: the fewest ``2**ℓ`` sub-spans for which twice the
    remainder bound is at most ``tol`` (3 joints, 3; units of the limit; ``inf`` ignores a
    column) for every column, at most ``top``. anchors: :func:`_taylor_anchors`. → (6,) int.

    From an anchor level a, a remainder bound at level ℓ >= a is at most the anchor's
    ``× 2^{−(6−i)(ℓ−a)}`` for the i-th derivative (the majorant's factor only shrinks with
    r), so each anchor gives a valid level in closed form; the smallest is taken."""
    a = np.asarray(TAYLOR_ANCHORS, np.int32)[None, :, None, None]
    order = np.array([6, 5, 4], np.int32)  # the remainder of the i-th derivative is O(r^(6−i))
    # ratio <= 2**e (frexp's exponent: integer work, no float64 logarithm); inf and nan
    # ratios ask for the top level
    ratio = anchors / tol
    _, e = jnp.frexp(jnp.where(jnp.isfinite(ratio), jnp.maximum(ratio, 1.0), 2.0 ** 1000))
    per = jnp.max(a + (jnp.maximum(e, 0) + order - 1) // order, axis=(2, 3))  # (6, A)
    return jnp.minimum(jnp.min(per, axis=1), top).astype(jnp.int32)


def _taylor_subspans(problem: DockingProblem, c, r, tc):
    """Upper and lower bounds (B, 3 joints, 3) of the right arm's maxima on B sub-spans,
    each of centre ``tc`` (local time in its knot span) and half-width ``r`` (B,), on the
    span of coefficients c (B, 6 powers, 6 coords). See :func:`right_taylor_maxima`."""
    raw = bspline.poly_taylor_terms(jnp.swapaxes(c[:, :, 3:5], 1, 2), tc[:, None])  # 6 × (B, 2), °
    # the jets' reference angles: pitch and yaw at t_c themselves (library sine and
    # cosine, accurate for any angle)
    ref = (raw[0], jnp.sin(_DEG * raw[0]), jnp.cos(_DEG * raw[0]))
    q = right_terms(problem, c, tc[:, None], 5, (0, 1, 2), ref)  # 3 × 6 × (B, 1)
    polys = jnp.stack([jnp.concatenate(t, -1) for t in q], 1)  # (B, 3, 6) about t_c
    first = jnp.stack(bspline.poly_taylor_terms(polys, -r[:, None]), -1)  # about t_c − r
    first = first.at[..., 0].add(-problem.home[4:7])
    vals, _ = extrema.span_maxima(first, jnp.broadcast_to(2.0 * r[:, None], first.shape[:2]))
    ang = [_DEG * jnp.stack([a[:, 0], a[:, 0] + a[:, 1], a[:, 0] - a[:, 1]], -1) for a in raw]
    w = [jnp.abs(a) for a in ang[1:]]
    _, sin_c, cos_c = ref
    trig = [jnp.minimum(1.0, jnp.abs(v) + 1e-15)
            for v in _angle_sums(sin_c[:, 0], cos_c[:, 0], sin_c[:, 1], cos_c[:, 1])]
    rem = _taylor_remainders([a[:, 0] for a in w], [a[:, 1] for a in w], [a[:, 2] for a in w],
                             trig, r, problem.arm_distance)  # (B, 3 joints, 3)
    return vals + rem, vals - rem


def _taylor_pass(problem: DockingProblem, c, h, levels):
    """One pass of :func:`right_taylor_maxima` over a batch: every knot span k of row i cut
    into ``2**levels[i, k]`` sub-spans (none where the level is −1); the sub-spans of all
    rows form one queue, scored :data:`TAYLOR_ROUND` at a time in a ``lax.while_loop``
    (so the trip count is the batch's total work, not its largest row's). → per span upper
    bounds (n, 6, 3, 3) (0 where not cut) and per row lower bounds (n, 3, 3)."""
    n = h.shape[0]
    dtype = c.dtype
    count = jnp.where(levels >= 0, jnp.left_shift(1, jnp.maximum(levels, 0)), 0).reshape(-1)  # (n·6,)
    ends = jnp.cumsum(count)
    total = ends[-1]
    flat = lambda a: a.reshape((n * config.N_INTERVALS,) + a.shape[2:])  # noqa: E731
    cf, hf = flat(c), flat(h)

    def body(carry):
        g, upper, lower = carry
        idx = g * TAYLOR_ROUND + jnp.arange(TAYLOR_ROUND, dtype=ends.dtype)
        valid = idx < total
        item = jnp.minimum(jnp.searchsorted(ends, idx, side="right"), n * config.N_INTERVALS - 1)
        k = jnp.maximum(count[item], 1)
        j = idx - (ends[item] - k)
        r = hf[item] / (2.0 * k.astype(dtype))
        tc = (2.0 * j.astype(dtype) + 1.0) * r
        up, low = _taylor_subspans(problem, cf[item], r, tc)
        up = jnp.where(valid[:, None, None], up, 0.0)
        low = jnp.where(valid[:, None, None], low, 0.0)
        return g + 1, upper.at[item].max(up), lower.at[item // config.N_INTERVALS].max(low)

    init = (jnp.zeros((), ends.dtype), jnp.zeros((n * config.N_INTERVALS, 3, 3), dtype),
            jnp.zeros((n, 3, 3), dtype))
    _, upper, lower = jax.lax.while_loop(lambda carry: carry[0] * TAYLOR_ROUND < total, body, init)
    return upper.reshape(n, config.N_INTERVALS, 3, 3), lower


def right_taylor_maxima(problem: DockingProblem, c, h, ref, screen: bool = False, active=None):
    """Rigorous maxima of the right arm's axial, lift and lateral joints (travel about home,
    |velocity|, |acceleration|) by Taylor models on sub-spans, for a batch.

    c: (n, 6 spans, 6 powers, 6 coords), h: (n, 6), ref: :func:`span_angles` of each row
    ((n, 6, 2) each); ``active`` (n,) bool: rows to score (default all; the others return
    0). → (n, 3 joints, 3).

    On a sub-span of centre t_c and half-width r, the joint is its degree-5 Taylor
    polynomial about t_c (Taylor-mode arithmetic, :func:`right_terms`) plus a remainder
    bounded by :func:`_taylor_remainders` (from the coefficients of pitch and yaw at t_c).
    The polynomial's maxima come from the certified root chain of
    :func:`dockjax.extrema.span_maxima` and the remainder bound is added; so every value
    is an upper bound of the true maximum, above it by at most twice the remainder bound
    (plus the chain's certified widths), and the polynomial's maximum less the remainder
    bound is a lower bound.

    Two passes (:func:`_taylor_pass`): the first cuts every span as finely as
    :data:`TAYLOR_LOOSE` needs (:func:`_taylor_levels`); the second re-cuts, as finely as
    :data:`TAYLOR_TIGHT` needs, only the spans that can still hold a value more than that
    above the lower bound of a column to be made tight: with ``screen``, the columns whose
    bounds reach within :data:`SCREEN_BAND` of the limit, else every column. A span's
    value is the smaller of its two passes' bounds (both are upper bounds)."""
    lim = problem.limits[4:7]
    anchors = jax.vmap(partial(_taylor_anchors, problem))(c, h, ref)  # (n, 6, A, 3, 3)
    loose = jax.vmap(lambda a: _taylor_levels(a, jnp.full((3, 3), TAYLOR_LOOSE, c.dtype), TAYLOR_LEVELS))(anchors)
    if active is not None:
        loose = jnp.where(active[:, None], loose, -1)
    U1, lo = _taylor_pass(problem, c, h, loose)

    def second(anchors, U1, lo, loose):
        top = U1.max(axis=0)
        if screen:
            far = (top < (1.0 - SCREEN_BAND) * lim) | (lo > (1.0 + SCREEN_BAND) * lim)
        else:
            far = jnp.zeros((3, 3), bool)
        open_ = ~far[None] & (U1 - lo[None] > TAYLOR_TIGHT * lim[None])  # (6, 3, 3)
        tol = jnp.where(open_, TAYLOR_TIGHT, jnp.inf)
        tight = jax.vmap(lambda a, t: _taylor_levels(a[None], t, TAYLOR_TIGHT_LEVELS)[0])(anchors, tol)
        return jnp.where(jnp.any(open_, axis=(1, 2)) & (tight > loose), tight, -1)

    levels = jax.vmap(second)(anchors, U1, lo, loose)
    U2, _ = _taylor_pass(problem, c, h, levels)
    U = jnp.where((levels >= 0)[..., None, None], jnp.minimum(U1, U2), U1)
    return extrema.reduce_max(U, 1)


def _right_columns_taylor(problem: DockingProblem, X, screen: bool, active=None):
    """G columns 12..20 (the right arm's axial, lift and lateral joints) of the rows of X
    (n, n_var) by :func:`right_taylor_maxima`. → (n, 9)."""
    h, _, c = jax.vmap(partial(decode, problem))(X)
    ref = jax.vmap(span_angles)(c, h)
    M = right_taylor_maxima(problem, c, h, ref, screen, active)
    return (M / problem.limits[4:7] - 1.0 + G_SAFETY).reshape(X.shape[0], -1)


def _jerk(problem: DockingProblem, c, h, ref):
    """Sum over the eight joints of the RMS jerk (Eq. 25); see :func:`_mean_square_jerk`."""
    return jnp.sum(jnp.sqrt(_mean_square_jerk(problem, c, h, ref)))


def _mean_square_jerk(problem: DockingProblem, c, h, ref):
    """``(1/T) ∫ (d³q_j/dt³)² dt`` of the eight joints (8,) (Eq. 25): in closed form per span
    for the joints linear in the pose, by Gauss–Legendre per span for the right arm's
    nonlinear ones (``problem.jerk_nodes`` per span, :data:`JERK_NODES`)."""
    xi, w = np.polynomial.legendre.leggauss(problem.jerk_nodes)
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
    right = [jnp.sum(weights * (6.0 * j[3]) ** 2) for j in right_terms(problem, c, tau, 3, (0, 1, 2), ref)]
    return jnp.stack([lin[2], lin[1], lin[0], lin[5], *right, lin[5]]) / jnp.sum(h)


def _score(problem: DockingProblem, x, screen: bool = False):
    """F (2,), G (24,), the adaptive mode's ``need`` flag and the screen's ``over`` flag of
    one candidate (``screen``: :func:`_maxima_screened` instead of :func:`_maxima`)."""
    h, u, c = decode(problem, x)
    T = jnp.sum(h)
    ref = materialize(span_angles(c, h))
    F = jnp.stack([T, _jerk(problem, c, h, ref)])
    if screen and problem.right_arm != "taylor":
        M, need, over, spans = _maxima_screened(problem, c, h, ref)
    else:
        M, need = _maxima(problem, c, h, ref, with_need=True, screen=screen)
        over, spans = jnp.zeros((), bool), None
    return F, _columns(problem, M), need, over, spans


def _columns(problem: DockingProblem, M):
    """G columns (..., 24) from the maxima (..., 8, 3) (SPEC §6, with the safety margin)."""
    return (M / problem.limits - 1.0 + G_SAFETY).reshape(M.shape[:-2] + (-1,))


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
    # over contiguous candidates, about 1.3× faster than along the first
    F, G, need, over, spans = jax.vmap(
        partial(_score, screen=screen), in_axes=(None, 1), out_axes=(1, 1, 0, 0, 0)
    )(problem, X.T)
    return F.T, G.T, need, over, spans


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
    return lambda idx: G[idx].at[:, 12:21].set(_right_columns_taylor(taylor, X[idx], screen, mask[idx]))


def _full_chain_rows(problem: DockingProblem, spans):
    """``rows`` for :func:`_replace_rows`: G from every span of the screen's stored series
    through the full root chain (the screen's overflow; no re-decoding)."""
    series, lengths, extra = spans

    def rows(idx):
        vals, _ = extrema.span_maxima(series[idx], lengths[idx])  # (k, 48, 3)
        M = vals.reshape(idx.shape[0], config.N_INTERVALS, -1, 3).max(axis=1) + extra[idx]
        return _columns(problem, M)

    return rows


KERNEL_CHUNK = 48
"""Most candidates per pass of :func:`score_batch` (its default ``chunk``)."""


def _score_pass(problem: DockingProblem, X, screen: bool, taylor: bool):
    """One pass of :func:`score_batch` (bound right arm; with ``taylor`` its nonlinear
    columns then come from :func:`right_taylor_maxima`): F, G (screen overflow re-scored)
    and the adaptive mode's ``need`` flags of the rows X."""
    F, G, need, over, spans = _score_plain(problem, X, screen)
    if spans is not None:
        G = _replace_rows(G, over, _full_chain_rows(problem, spans), SCREEN_CHUNK)
    if taylor:
        G = G.at[:, 12:21].set(_right_columns_taylor(problem.with_right_arm("taylor"), X, screen))
    return F, G, need


def score_batch(problem: DockingProblem, X, screen: bool = True, chunk: int | None = None,
                with_need: bool = False):
    """Traceable batch scoring: X (n, n_var) → F (n, 2), G (n, 24) (and, ``with_need``, the
    rows (n,) whose bound treatment may overstate by more than :data:`BOUND_TOLERANCE`).

    ``screen`` (default): the limit columns come from :func:`_maxima_screened` (cheap
    bounds everywhere, the exact root chain on the few spans that need it); candidates
    with more such spans than the screen's slots are re-scored by the full path.
    ``screen=False``: every span through the root chain (about 2.5× dearer; every column
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
    rows streams every intermediate array (hundreds of kB each) through memory. Measured
    on this CPU, one core, 2,400 candidates: ~1.5× faster than one pass.
    """
    chunk = KERNEL_CHUNK if chunk is None else chunk
    if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
        raise ValueError(f"chunk must be an integer >= 1, got {chunk!r}")
    adaptive = problem.right_arm == "adaptive"
    taylor = problem.right_arm == "taylor"
    bound = problem.with_right_arm("bound")
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


@partial(jax.jit, static_argnums=0)
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
