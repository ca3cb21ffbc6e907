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
  k ∈ (travel about home, velocity, acceleration) (SPEC §6). The maxima are exact: for the
  joints linear in the pose they sit at span ends or at roots of the next derivative,
  found by the derivative chain of :mod:`dockjax.extrema`; for the right arm's nonlinear
  joints the roots of the first-order expansion (in pitch and yaw about the span's middle)
  are polished by one Newton step on the true joint function and the true value is taken.
  A safety margin of ``1e-9`` is added, so a column is never understated.
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

import math
from functools import partial
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from . import bspline, config, extrema, jets
from . import devices as dev
from .fusion import materialize
from .kinematics import inverse_kinematics

__all__ = ["DockingProblem", "score", "score_batch"]

_DEG = math.pi / 180.0
G_SAFETY = 1e-9
"""Added to every constraint column so that rounding never understates it (SPEC §6)."""
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
    * ``right_arm``: how the limits of the right arm's nonlinear joints are found:
      ``"bound"`` — exact extrema of the first-order expansion in pitch and yaw plus a
      rigorous bound of the remainder (fast; never understated; overstated by twice the
      bound, far below 0.01 when pitch and yaw move by tenths of a degree, as in the
      paper); ``"exact"`` — the true joint at the polished roots (slower; for large
      attitude changes); ``"adaptive"`` — ``"bound"`` for every candidate whose own
      overstatement bound (twice its remainder bound) is at most 0.01, ``"exact"`` for the
      others, which are gathered and scored in fixed-size chunks (the exact path runs only
      as often as needed); ``"auto"`` (default) picks ``"bound"`` when its worst-case
      overstatement over the decision box (a crude hull estimate) is below 0.01, else
      ``"adaptive"``.
    * ``jerk_nodes``: Gauss–Legendre nodes per knot span of the right arm's jerk integral
      (3 to 64); default None: 8, 12 or 24 from the box's range of pitch and yaw, enough
      for 1e-9 relative (:data:`JERK_NODES`).

    Attributes: ``n_var``, ``n_obj`` (2), ``n_con`` (24), ``lower``, ``upper`` (natural
    units, SPEC §3 order), ``limits`` (8, 3), ``home`` (8,), ``start``, ``goal``,
    ``right_arm``, ``jerk_nodes``.
    """

    n_obj = 2
    n_con = config.N_CON

    def __init__(
        self,
        *,
        start: Sequence[float] = config.START,
        goal: Sequence[float] = config.GOAL,
        arm_distance: float = config.ARM_DISTANCE,
        interval_bounds: tuple[float, float] = config.INTERVAL_BOUNDS,
        travel: Sequence[float] = config.TRAVEL,
        velocity: Sequence[float] = config.VELOCITY,
        acceleration: Sequence[float] = config.ACCELERATION,
        home: Sequence[float] | None = None,
        margin: float = config.MARGIN,
        reduced: bool = False,
        right_arm: str = "auto",
        jerk_nodes: int | None = None,
    ):
        start_a = _vector("start", start, (6,))
        goal_a = _vector("goal", goal, (6,))
        d2 = _vector("arm_distance", [arm_distance], (1,), positive=True)[0]
        bounds = _vector("interval_bounds", interval_bounds, (2,))
        lo, hi = bounds
        if lo <= 0 or lo >= hi:
            raise ValueError(f"interval_bounds must satisfy 0 < lo < hi, got ({lo}, {hi})")
        mg = _vector("margin", [margin], (1,))[0]
        if mg < 0:
            raise ValueError(f"margin must be >= 0, got {mg}")
        limits = np.stack(
            [_per_joint("travel", travel), _per_joint("velocity", velocity),
             _per_joint("acceleration", acceleration)],
            axis=1,
        )
        with jax.enable_x64(True):
            q0 = np.asarray(inverse_kinematics(start_a, d2))
            q1 = np.asarray(inverse_kinematics(goal_a, d2))
        home_a = 0.5 * (q0 + q1) if home is None else _vector("home", home, (8,))
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
        if reduced:
            lower, upper = h_lo, h_hi
        else:
            lower = np.concatenate([h_lo, np.tile(box_lo, config.N_FREE)])
            upper = np.concatenate([h_hi, np.tile(box_hi, config.N_FREE)])
        self.start, self.goal, self.arm_distance = start_a, goal_a, float(d2)
        self.interval_bounds = (float(lo), float(hi))
        # traced leaves (not static), so they never cause a recompilation
        self._bounds_margin = np.array([lo, hi, mg])
        self.limits, self.home = limits, home_a
        self.lower, self.upper = lower, upper
        self.margin, self.reduced = float(mg), bool(reduced)
        if right_arm not in ("auto", "bound", "exact", "adaptive"):
            raise ValueError(f"right_arm must be 'auto', 'bound', 'exact' or 'adaptive', got {right_arm!r}")
        if right_arm == "auto":
            right_arm = "bound" if self._bound_overstatement() <= BOUND_TOLERANCE else "adaptive"
        self.right_arm = right_arm
        if jerk_nodes is None:
            box = self._pose_box()
            jerk_nodes = jerk_nodes_for(float(np.max(box[1, 3:5] - box[0, 3:5])))
        elif isinstance(jerk_nodes, bool) or not isinstance(jerk_nodes, (int, np.integer)) or not 3 <= jerk_nodes <= 64:
            raise ValueError(f"jerk_nodes must be None (chosen from the box) or an integer from 3 to 64, got {jerk_nodes!r}")
        self.jerk_nodes = int(jerk_nodes)

    # -- pytree -------------------------------------------------------------------------
    _LEAVES = ("start", "goal", "arm_distance", "limits", "home", "lower", "upper", "_bounds_margin")
    _META = ("reduced", "right_arm", "jerk_nodes")

    def _tree_flatten(self):
        return tuple(getattr(self, k) for k in self._LEAVES), tuple(
            getattr(self, k) for k in self._META
        )

    @classmethod
    def _tree_unflatten(cls, meta, leaves):
        obj = object.__new__(cls)
        for k, v in zip(cls._LEAVES, leaves):
            object.__setattr__(obj, k, v)
        for k, v in zip(cls._META, meta):
            object.__setattr__(obj, k, v)
        bm = obj._bounds_margin
        if isinstance(bm, np.ndarray):
            object.__setattr__(obj, "interval_bounds", (float(bm[0]), float(bm[1])))
            object.__setattr__(obj, "margin", float(bm[2]))
        return obj

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
        ``"exact"`` or ``"adaptive"``); shares every array."""
        if mode not in ("bound", "exact", "adaptive"):
            raise ValueError(f"mode must be 'bound', 'exact' or 'adaptive', got {mode!r}")
        leaves, meta = self._tree_flatten()
        return DockingProblem._tree_unflatten((meta[0], mode) + meta[2:], leaves)

    @property
    def exact_right_arm(self) -> bool:
        return self.right_arm == "exact"

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
            F, G = dev.sharded(_evaluate_rows, (bool(screen),), where, (dev.SAME, dev.SHARDED), self, Xj)
            return np.asarray(F, np.float64)[:n], np.asarray(G, np.float64)[:n]

    def evaluate_jax(self, X, *, screen: bool = True):
        """Traceable batch scoring for use inside jit/vmap (the caller sets the precision).
        X: (n, n_var) → F (n, 2), G (n, 24); ``screen`` as in :meth:`evaluate`."""
        return score_batch(self, X, screen)

    def decode(self, x):
        """The trajectory of one decision vector (n_var,). See :class:`dockjax.Trajectory`."""
        from .trajectory import Trajectory

        arr = self.check_population(np.asarray(x, dtype=np.float64)[None, :])[0]
        return Trajectory(self, arr)


jax.tree_util.register_pytree_node(
    DockingProblem, DockingProblem._tree_flatten, DockingProblem._tree_unflatten
)


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


def _maxima(problem: DockingProblem, c, h, ref, *, with_need: bool = False):
    """``max_t |q_j − home_j|``, ``max |q_j'|``, ``max |q_j''|`` per joint. → (8, 3).

    With ``with_need``, also whether this candidate's bound treatment of the right arm may
    overstate by more than :data:`BOUND_TOLERANCE` (always False on the exact path)."""
    polys = materialize(_joint_polys(problem, c, h, ref))
    hh = jnp.broadcast_to(h[:, None], polys.shape[:2])
    spans, times = extrema.span_maxima(polys, hh)
    lin = extrema.reduce_max(spans, 0)  # (8, 3)
    if problem.right_arm == "exact":
        right = _right_polished(problem, c, h, ref, times)
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


def _right_polished(problem: DockingProblem, c, h, ref, times, newton: int = 4):
    """Right arm's nonlinear joints, for large attitude changes: from the roots of the
    linearised joint, ``newton`` Newton steps on the true joint's derivative, then the true
    value plus twice the last Newton correction ``Q'²/|Q''|`` (quadratic convergence makes
    it an overstatement of the remaining error), and the span ends. → (3 joints, 3)."""
    inner = jnp.concatenate([times[0][0][:, 4:7, 1:5], times[1][0][:, 4:7, 1:4], times[2][:, 4:7, 1:3]], -1)
    kind = np.array([0] * 4 + [1] * 3 + [2] * 2)  # the quantity each of the 9 points is a root for
    n_pts = kind.size
    diag = np.arange(3)

    def jets_at(pts):
        """Derivatives 0..4 of joint r at its own points pts[:, r]: (6, 3, 9) → (6, 3, 9, 5)
        (all three joints at all 27 points in one call, then each joint's own)."""
        d = jets.derivatives(right_jets(problem, c, pts.reshape(pts.shape[0], -1), 4, (0, 1, 2), ref))
        return d.reshape(pts.shape[0], 3, n_pts, 3, -1)[:, diag, :, diag].swapaxes(0, 1)

    def pick(d, i):  # derivative kind + i at each point: (6, 3, 9)
        return d[:, :, np.arange(n_pts), kind + i]

    def newton_step(_, carry):
        pts, d = carry
        q1, q2 = pick(d, 1), pick(d, 2)
        # the points carry no gradient (envelope theorem, see extrema.chain_extrema)
        pts = jax.lax.stop_gradient(
            jnp.clip(pts - jnp.where(q2 != 0, q1 / jnp.where(q2 != 0, q2, 1.0), 0.0), 0.0, h[:, None, None]))
        return pts, jets_at(pts)

    d = jets_at(inner)
    first = pick(d, 0)
    _, d = jax.lax.fori_loop(0, newton, newton_step, (inner, d))
    q0, q1, q2 = pick(d, 0), pick(d, 1), pick(d, 2)
    step = jnp.abs(jnp.where(q2 != 0, q1 / jnp.where(q2 != 0, q2, 1.0), 0.0))
    extra = jnp.where(step <= 1e-5 * h[:, None, None], jnp.abs(q1) * step, 0.0)
    ends = jnp.stack([jnp.zeros_like(h), h], -1)  # (6, 2)
    end = jets.derivatives(right_jets(problem, c, ends, 2, (0, 1, 2), ref))  # (6, 2, 3 joints, 3)
    home = problem.home[4:7]
    right = []
    for k in range(3):
        sel = kind == k
        shift = home[:, None] if k == 0 else 0.0
        vals = jnp.concatenate(
            [jnp.abs(first[:, :, sel] - shift), jnp.abs(q0[:, :, sel] - shift) + extra[:, :, sel],
             jnp.abs(end[..., k] - (home if k == 0 else 0.0)).swapaxes(1, 2)], 2)  # (6, 3, ·)
        right.append(extrema.reduce_max(vals, (0, 2)))
    return jnp.stack(right, axis=1)


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
    if screen and problem.right_arm != "exact":
        M, need, over, spans = _maxima_screened(problem, c, h, ref)
    else:
        M, need = _maxima(problem, c, h, ref, with_need=True)
        over, spans = jnp.zeros((), bool), None
    return F, _columns(problem, M), need, over, spans


def _columns(problem: DockingProblem, M):
    """G columns (..., 24) from the maxima (..., 8, 3) (SPEC §6, with the safety margin)."""
    return (M / problem.limits - 1.0 + G_SAFETY).reshape(M.shape[:-2] + (-1,))


def _limits_full(problem: DockingProblem, x):
    """G (24,) of one candidate by the full root chain (no objectives: less to compile)."""
    h, u, c = decode(problem, x)
    ref = materialize(span_angles(c, h))
    return _columns(problem, _maxima(problem, c, h, ref))


def score(problem: DockingProblem, x):
    """Objectives and constraint values of one candidate. x: (n_var,) → F (2,), G (24,).

    Every column comes from the exact root chain (no screening). In the ``"adaptive"``
    right-arm mode this is the exact path where the candidate needs it (both paths are
    computed: use :func:`score_batch` for populations)."""
    if problem.right_arm == "adaptive":
        F, G, need, _, _ = _score(problem.with_right_arm("bound"), x)
        _, Gx, _, _, _ = _score(problem.with_right_arm("exact"), x)
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


def _exact_path_rows(problem: DockingProblem, X):
    """``rows`` for :func:`_replace_rows`: G by the ``"exact"`` right-arm path."""
    exact = problem.with_right_arm("exact")
    return lambda idx: jax.vmap(partial(_limits_full, exact), in_axes=1, out_axes=1)(X[idx].T).T


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


def _score_pass(problem: DockingProblem, X, screen: bool, adaptive: bool):
    """One pass of :func:`score_batch` (bound or exact right arm): F, G (screen overflow
    re-scored) and the adaptive mode's ``need`` flags of the rows X."""
    F, G, need, over, spans = _score_plain(problem, X, screen)
    if spans is not None:
        G = _replace_rows(G, over & ~need if adaptive else over, _full_chain_rows(problem, spans), SCREEN_CHUNK)
    return F, G, need


def score_batch(problem: DockingProblem, X, screen: bool = True, chunk: int | None = None):
    """Traceable batch scoring: X (n, n_var) → F (n, 2), G (n, 24).

    ``screen`` (default): the limit columns come from :func:`_maxima_screened` (cheap
    bounds everywhere, the exact root chain on the few spans that need it); candidates
    with more such spans than the screen's slots are re-scored by the full path.
    ``screen=False``: every span through the root chain (about 2.5× dearer; every column
    exact to rounding).

    ``"adaptive"`` right arm: every candidate is scored by the bound path; those whose own
    overstatement bound exceeds :data:`BOUND_TOLERANCE` are re-scored by the exact path
    (see :func:`_replace_rows`), so the dear path costs only what is needed (usually
    nothing).

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
    bound = problem.with_right_arm("bound" if adaptive else problem.right_arm)
    n = X.shape[0]
    passes = max(1, -(-n // chunk))
    size = -(-n // passes)
    if passes == 1:
        F, G, need = _score_pass(bound, X, screen, adaptive)
    else:
        Xp = jnp.concatenate([X, jnp.broadcast_to(X[:1], (passes * size - n, X.shape[1]))])
        out = jax.lax.map(lambda x: _score_pass(bound, x, screen, adaptive), Xp.reshape(passes, size, -1))
        F, G, need = (a.reshape((passes * size,) + a.shape[2:])[:n] for a in out)
    if adaptive:
        G = _replace_rows(G, need, _exact_path_rows(problem, X), ADAPTIVE_CHUNK)
    return F, G


@partial(jax.jit, static_argnums=0)
def _evaluate_rows(screen: bool, problem: DockingProblem, X):
    """:func:`score_batch` for :meth:`DockingProblem.evaluate` (``screen`` first: static)."""
    return score_batch(problem, X, screen)


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
