"""The right arm's axial, lift and lateral joints: jets and rigorous limit treatments.

These three joints go through sin/cos of pitch and yaw (conventions §4), so neither their
jerk integral nor their extrema have a closed form.

* :func:`right_terms`: their Taylor coefficients at any local times (Taylor-mode
  arithmetic through :func:`dockjax.robot.cabin_axis_jets` and the one pose→joints
  map :func:`dockjax.robot.arm_joints`), for the jerk objective and the Taylor models.
* **Bound** treatment: the first-order expansion in pitch and yaw about each span's middle
  is a quintic in time, whose extrema the root chain finds exactly
  (:func:`dockjax.limits.joint_series`); :func:`linearisation_remainders` bounds how far
  the true joint and its first two derivatives can be from it.
  :func:`bound_overstatement` bounds the worst case over a decision box.
* **Taylor** treatment (:func:`right_taylor_maxima`): Taylor models on sub-spans with a
  rigorous remainder majorant.

Every function but :func:`bound_overstatement` (host-side, of a problem's decision box) is
traceable and takes the robot's numbers (:class:`dockjax.robot.Robot`: D_2, home, limits).
"""

from __future__ import annotations

import math
from functools import partial
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from . import bspline, extrema
from .config import DEG as _DEG
from .robot import ATTITUDE_JOINTS, POSE_ATTITUDE, cabin_axis_jets

if TYPE_CHECKING:
    from .problem import DockingProblem
    from .robot import Robot

__all__ = [
    "right_terms", "hessian_norms", "remainder_bound", "linearisation_remainders",
    "bound_overstatement", "right_taylor_maxima",
]


def right_terms(robot: "Robot", c, tau, order: int, ref) -> list:
    """Jets of the right arm's axial, lift and lateral joints ``d_R1``, ``d_R2``, ``d_R3``
    (conventions §4), each a list of its normalised Taylor coefficients 0..order.

    c: (s, 6 powers, 6 coords) span coefficients; tau: (s, m) local times per span; ref:
    :func:`dockjax.decoding.span_angles` of the spans (the jets' reference angles). Each
    coefficient is (s, m). The pose's jets go through the cabin axis
    (:func:`dockjax.robot.cabin_axis_jets`) and the one pose→joints map
    (:meth:`dockjax.robot.Robot.joints`), coefficient by coefficient (it is linear).
    """
    pose = [bspline.poly_taylor_terms(c[:, None, :, i], tau, order) for i in range(5)]
    mid, sin_m, cos_m = ref
    near = [(_DEG * (pose[3 + i][0] - mid[:, i, None]), sin_m[:, i, None], cos_m[:, i, None]) for i in (0, 1)]
    axis = cabin_axis_jets([_DEG * a for a in pose[3]], [_DEG * a for a in pose[4]], near)
    joints = [robot.joints(x, y, z, 0.0, ux, uy, uz)
              for x, y, z, ux, uy, uz in zip(pose[0], pose[1], pose[2], *axis)]
    return [[j[4 + r] for j in joints] for r in range(3)]


def hessian_norms(sin_a, sin_b):
    """Bounds of the Hessian norms of ``cos a cos b``, ``sin a``, ``cos a sin b`` given
    bounds of ``|sin a|`` and ``|sin b|`` (their eigenvalues are ``−cos(a ± b)``,
    ``−sin a`` and ``−cos a sin b ± sin a cos b``)."""
    one = jnp.ones_like(sin_a)
    return jnp.stack([one, sin_a, jnp.minimum(one, sin_a + sin_b)], axis=-1)


THIRD_DERIVATIVE = math.sqrt(2.0)
"""A bound of the third directional derivative ``|D³f[u, u, u]| / |u|³`` of ``cos a cos b``,
``sin a`` and ``cos a sin b``: with ``cos a cos b = ½[cos(a+b) + cos(a−b)]`` it is
``½(|u_1+u_2|³ + |u_1−u_2|³) <= ½ (2|u|²)^{3/2} = √2 |u|³`` (likewise for ``cos a sin b``;
``|u_1|³ <= |u|³`` for ``sin a``)."""


def remainder_bound(d2, hess, delta, vel, acc, jerk=None):
    """``D_2 ×`` bounds of the remainder of the first-order expansion and its first two
    time derivatives: ``½Hδ²``, ``HδV``, ``H(δA + V²)`` (mean-value theorem), and with
    ``jerk`` (a bound J of the angles' third derivative) its third: ``HδJ + 3HVA + √2 V³``
    (the remainder ``R = f(φ) − f(φ_m) − ∇f(φ_m)·(φ − φ_m)`` has third derivative
    ``D³f[φ', φ', φ'] + 3 φ'ᵀ H φ'' + (∇f(φ) − ∇f(φ_m))·φ⁽³⁾``). (..., 3 joints, 3 or 4)."""
    h = hess
    cols = [0.5 * h * delta[..., None] ** 2, h * (delta * vel)[..., None],
            h * (delta * acc + vel * vel)[..., None]]
    if jerk is not None:
        cols.append(h * (delta * jerk + 3.0 * vel * acc)[..., None] + THIRD_DERIVATIVE * (vel * vel * vel)[..., None])
    return d2 * jnp.stack(cols, axis=-1)


def linearisation_remainders(robot: "Robot", c, h, ref):
    """Rigorous bounds, per span, of how far the right arm's axial, lift and lateral joints
    (and their first two derivatives) can be from their first-order expansion in pitch
    and yaw about the span's middle. → (s spans, 3 joints, kinds): travel, velocity,
    acceleration (and jerk when the robot has jerk limits), in mm, mm/s, ...

    From the series of α and β re-centred at the span's middle,
    ``|α(t) − α_m| <= Σ_{m>=1} |a_m| (h/2)^m`` and likewise for the derivatives.
    """
    mid, sin_m, _ = ref
    half = 0.5 * h[:, None]
    ang = [_DEG * jnp.abs(a) for a in bspline.poly_taylor_terms(jnp.swapaxes(c[:, :, POSE_ATTITUDE], 1, 2), half)]
    hp = [jnp.ones_like(half)]  # powers of h/2 by products (no pow): (6, 1) each
    for _ in range(5):
        hp.append(hp[-1] * half)
    dev = sum(ang[m] * hp[m] for m in range(1, 6))  # (6, 2)
    vel = sum(m * ang[m] * hp[m - 1] for m in range(1, 6))
    acc = sum(m * (m - 1) * ang[m] * hp[m - 2] for m in range(2, 6))
    jrk = sum(m * (m - 1) * (m - 2) * ang[m] * hp[m - 3] for m in range(3, 6)) if robot.has_jerk else None

    def norm(v):  # Euclidean norm with a finite gradient (0) at 0
        s = jnp.sum(v * v, -1)
        return jnp.where(s > 0, jnp.sqrt(jnp.where(s > 0, s, 1.0)), 0.0)

    sin_bound = jnp.minimum(1.0, jnp.abs(sin_m) + dev)  # (6, 2)
    hess = hessian_norms(sin_bound[:, 0], sin_bound[:, 1])  # (6, 3)
    return remainder_bound(robot.arm_distance, hess, norm(dev), norm(vel), norm(acc),
                           None if jrk is None else norm(jrk))


def bound_overstatement(problem: "DockingProblem") -> float:
    """Worst-case overstatement (in units of the limit) of the ``"bound"`` treatment over
    the problem's decision box, from hull bounds of pitch and yaw and their derivatives: a
    B-spline stays in the hull of its control points, and its derivatives' control points
    give ``|α'| <= 5 Δ/h_lo``, ``|α''| <= 40 Δ/h_lo²`` and ``|α⁽³⁾| <= 240 Δ/h_lo³`` (Δ the box's
    range). Host-side
    (NumPy data of a constructed problem)."""
    box = problem.pose_box()
    rng = _DEG * (box[1, POSE_ATTITUDE] - box[0, POSE_ATTITUDE])
    far = np.minimum(1.0, _DEG * np.max(np.abs(box[:, POSE_ATTITUDE]), axis=0))
    h_lo = problem.interval_bounds[0]
    worst = 0.0
    with jax.enable_x64(True):
        hess = np.asarray(hessian_norms(far[0], far[1]))
        for rb in problem.robots:  # one pair of supports at a time (two arms: the robot)
            b = np.asarray(
                remainder_bound(
                    rb.arm_distance, hess, np.hypot(*rng), 5 * np.hypot(*rng) / h_lo,
                    40 * np.hypot(*rng) / h_lo**2, None if problem.jerk is None else 240 * np.hypot(*rng) / h_lo**3,
                )
            )
            worst = max(worst, float(np.max(2 * b / np.asarray(rb.limits)[ATTITUDE_JOINTS])))
    return worst


TAYLOR_TIGHT = 1e-8
"""Target overstatement of the ``"taylor"`` treatment, in units of the limit, for the
columns it makes tight (those near their limit, or all with ``screen=False``): twice the
remainder bound of every sub-span that can hold the maximum, when at most
``2**TAYLOR_TIGHT_LEVELS`` sub-spans per knot span achieve it."""

TAYLOR_TIGHT_LEVELS = 5

TAYLOR_LOOSE = 0.005
"""Target overstatement of the ``"taylor"`` treatment's first pass, in units of the limit
(half of conventions §6's 0.01), met whenever ``2**TAYLOR_LEVELS`` sub-spans per knot span do."""

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


def _taylor_remainders(wa, wp, wm, trig, r, d2, kinds: int = 3):
    """Bounds of ``|R|``, ``|R'|``, ``|R''|`` on ``|s| <= r`` of the remainders
    ``R(s) = q(t_c + s) − Σ_{k<=5} q_k s^k`` of the right arm's axial, lift and lateral
    joints' Taylor series about t_c. → (..., 3 joints, ``kinds``) in mm, mm/s, mm/s² (and
    mm/s³ with 4 kinds).

    ``wa``, ``wp``, ``wm``: 5 arrays each, nonnegative majorants of the Taylor coefficients
    1..5 about t_c of α, α + β and α − β (rad); ``trig``: upper bounds of
    ``(|sin α|, |cos α|, |sin(α+β)|, |cos(α+β)|, |sin(α−β)|, |cos(α−β)|)`` at t_c; r like
    them.

    The joints are ``pose + D_2 f`` with f one of ``sin α``,
    ``cos α cos β = ½[cos(α+β) + cos(α−β)]``, ``cos α sin β = ½[sin(β+α) + sin(β−α)]``
    (conventions §4); the pose is quintic, so R is ``D_2`` times f's remainder. With
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
    powers = [r4 * r2, 6.0 * r4 * r, 30.0 * r4, 120.0 * r2 * r][:kinds]  # 6! r^(6-i) / (6-i)!
    powers = jnp.stack(powers, -1)
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
    m = bspline.poly_taylor_terms(jnp.swapaxes(c[:, :, POSE_ATTITUDE], 1, 2), half)  # 6 × (6 spans, 2)
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


def _taylor_anchors(robot: "Robot", c, h, ref):
    """Twice the remainder bounds, in units of the limits, of a knot span cut into
    ``2**a`` sub-spans, at the levels ``a`` of :data:`TAYLOR_ANCHORS`. → (s spans, anchors,
    3 joints, kinds)."""
    w, trig = _span_majorants(c, h, ref)
    anchors = np.asarray(TAYLOR_ANCHORS)
    r = h[:, None] * jnp.asarray(0.5 ** (anchors + 1), h.dtype)  # (6, A)
    col = lambda i: [a[:, i, None] for a in w]  # noqa: E731
    rem = _taylor_remainders(col(0), col(1), col(2), [t[:, None] for t in trig], r, robot.arm_distance,
                             robot.n_kinds)
    return 2.0 * rem / robot.limits[ATTITUDE_JOINTS]


def _taylor_levels(anchors, tol, top: int):
    """Subdivision level of each knot span: the fewest ``2**ℓ`` sub-spans for which twice the
    remainder bound is at most ``tol`` (3 joints, kinds; units of the limit; ``inf`` ignores a
    column) for every column, at most ``top``. anchors: :func:`_taylor_anchors`. → (6,) int.

    From an anchor level a, a remainder bound at level ℓ >= a is at most the anchor's
    ``× 2^{−(6−i)(ℓ−a)}`` for the i-th derivative (the majorant's factor only shrinks with
    r), so each anchor gives a valid level in closed form; the smallest is taken."""
    a = np.asarray(TAYLOR_ANCHORS, np.int32)[None, :, None, None]
    order = np.array([6, 5, 4, 3][:anchors.shape[-1]], np.int32)  # the remainder of the i-th derivative is O(r^(6−i))
    # ratio <= 2**e (frexp's exponent: integer work, no float64 logarithm); inf and nan
    # ratios ask for the top level
    ratio = anchors / tol
    _, e = jnp.frexp(jnp.where(jnp.isfinite(ratio), jnp.maximum(ratio, 1.0), 2.0 ** 1000))
    per = jnp.max(a + (jnp.maximum(e, 0) + order - 1) // order, axis=(2, 3))  # (6, A)
    return jnp.minimum(jnp.min(per, axis=1), top).astype(jnp.int32)


def _taylor_subspans(robot: "Robot", c, r, tc):
    """Upper and lower bounds (B, 3 joints, kinds) of the right arm's maxima on B sub-spans,
    each of centre ``tc`` (local time in its knot span) and half-width ``r`` (B,), on the
    span of coefficients c (B, 6 powers, 6 coords). See :func:`right_taylor_maxima`."""
    raw = bspline.poly_taylor_terms(jnp.swapaxes(c[:, :, POSE_ATTITUDE], 1, 2), tc[:, None])  # 6 × (B, 2), °
    # the jets' reference angles: pitch and yaw at t_c themselves (library sine and
    # cosine, accurate for any angle)
    ref = (raw[0], jnp.sin(_DEG * raw[0]), jnp.cos(_DEG * raw[0]))
    q = right_terms(robot, c, tc[:, None], 5, ref)  # 3 × 6 × (B, 1)
    polys = jnp.stack([jnp.concatenate(t, -1) for t in q], 1)  # (B, 3, 6) about t_c
    first = jnp.stack(bspline.poly_taylor_terms(polys, -r[:, None]), -1)  # about t_c − r
    first = first.at[..., 0].add(-robot.home[ATTITUDE_JOINTS])
    width = jnp.broadcast_to(2.0 * r[:, None], first.shape[:2])
    vals, _ = extrema.span_maxima(first, width)
    if robot.has_jerk:
        vals = jnp.concatenate([vals, extrema.jerk_maxima(first, width)[..., None]], -1)
    ang = [_DEG * jnp.stack([a[:, 0], a[:, 0] + a[:, 1], a[:, 0] - a[:, 1]], -1) for a in raw]
    w = [jnp.abs(a) for a in ang[1:]]
    _, sin_c, cos_c = ref
    trig = [jnp.minimum(1.0, jnp.abs(v) + 1e-15)
            for v in _angle_sums(sin_c[:, 0], cos_c[:, 0], sin_c[:, 1], cos_c[:, 1])]
    rem = _taylor_remainders([a[:, 0] for a in w], [a[:, 1] for a in w], [a[:, 2] for a in w],
                             trig, r, robot.arm_distance, robot.n_kinds)  # (B, 3 joints, kinds)
    return vals + rem, vals - rem


def _taylor_pass(robot: "Robot", c, h, levels):
    """One pass of :func:`right_taylor_maxima` over a batch: every knot span k of row i cut
    into ``2**levels[i, k]`` sub-spans (none where the level is −1); the sub-spans of all
    rows form one queue, scored :data:`TAYLOR_ROUND` at a time in a ``lax.while_loop``
    (so the trip count is the batch's total work, not its largest row's). → per span upper
    bounds (n, s, 3, kinds) (0 where not cut) and per row lower bounds (n, 3, kinds); s spans per row."""
    n, s = h.shape
    dtype = c.dtype
    count = jnp.where(levels >= 0, jnp.left_shift(1, jnp.maximum(levels, 0)), 0).reshape(-1)  # (n·6,)
    ends = jnp.cumsum(count)
    total = ends[-1]
    flat = lambda a: a.reshape((n * s,) + a.shape[2:])  # noqa: E731
    cf, hf = flat(c), flat(h)

    def body(carry):
        g, upper, lower = carry
        idx = g * TAYLOR_ROUND + jnp.arange(TAYLOR_ROUND, dtype=ends.dtype)
        valid = idx < total
        item = jnp.minimum(jnp.searchsorted(ends, idx, side="right"), n * s - 1)
        k = jnp.maximum(count[item], 1)
        j = idx - (ends[item] - k)
        r = hf[item] / (2.0 * k.astype(dtype))
        tc = (2.0 * j.astype(dtype) + 1.0) * r
        up, low = _taylor_subspans(robot, cf[item], r, tc)
        up = jnp.where(valid[:, None, None], up, 0.0)
        low = jnp.where(valid[:, None, None], low, 0.0)
        return g + 1, upper.at[item].max(up), lower.at[item // s].max(low)

    k = robot.n_kinds
    init = (jnp.zeros((), ends.dtype), jnp.zeros((n * s, 3, k), dtype),
            jnp.zeros((n, 3, k), dtype))
    _, upper, lower = jax.lax.while_loop(lambda carry: carry[0] * TAYLOR_ROUND < total, body, init)
    return upper.reshape(n, s, 3, k), lower


def right_taylor_maxima(robot: "Robot", c, h, ref, band: float | None = None, active=None):
    """Rigorous maxima of the right arm's axial, lift and lateral joints (travel about home,
    |velocity|, |acceleration|) by Taylor models on sub-spans, for a batch.

    c: (n, 6 spans, 6 powers, 6 coords), h: (n, 6), ref: :func:`dockjax.decoding.span_angles` of each row
    ((n, 6, 2) each); ``active`` (n,) bool: rows to score (default all; the others return
    0). → (n, 3 joints, kinds): travel, |velocity|, |acceleration| (and |jerk|).

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
    above the lower bound of a column to be made tight: with ``band``, the columns whose
    bounds reach within that fraction of the limit (the screen's
    :data:`dockjax.limits.SCREEN_BAND`), else (None) every column. A span's
    value is the smaller of its two passes' bounds (both are upper bounds). The passes are
    the two trips of one ``fori_loop``, so the compiled program holds one copy of the pass."""
    lim = robot.limits[ATTITUDE_JOINTS]
    shape = (3, robot.n_kinds)
    anchors = jax.vmap(partial(_taylor_anchors, robot))(c, h, ref)  # (n, s, A, 3, kinds)
    loose = jax.vmap(lambda a: _taylor_levels(a, jnp.full(shape, TAYLOR_LOOSE, c.dtype), TAYLOR_LEVELS))(anchors)
    if active is not None:
        loose = jnp.where(active[:, None], loose, -1)

    def second(anchors, U1, lo, loose):
        top = U1.max(axis=0)
        if band is not None:
            far = (top < (1.0 - band) * lim) | (lo > (1.0 + band) * lim)
        else:
            far = jnp.zeros(shape, bool)
        open_ = ~far[None] & (U1 - lo[None] > TAYLOR_TIGHT * lim[None])  # (s, 3, kinds)
        tol = jnp.where(open_, TAYLOR_TIGHT, jnp.inf)
        tight = jax.vmap(lambda a, t: _taylor_levels(a[None], t, TAYLOR_TIGHT_LEVELS)[0])(anchors, tol)
        return jnp.where(jnp.any(open_, axis=(1, 2)) & (tight > loose), tight, -1)

    def trip(i, carry):
        # trip 0 is the first pass (loose levels), trip 1 the second (levels from the
        # first's bounds): one loop of two trips compiles one copy of the pass, not two
        U1, lo, _, _ = carry
        levels = jnp.where(i == 0, loose, jax.vmap(second)(anchors, U1, lo, loose))
        U, low = _taylor_pass(robot, c, h, levels)
        first = i == 0
        return jnp.where(first, U, U1), jnp.where(first, low, lo), U, levels

    n, s = h.shape
    zeros = jnp.zeros((n, s) + shape, c.dtype)
    init = (zeros, jnp.zeros((n,) + shape, c.dtype), zeros, loose)
    U1, _, U2, levels = jax.lax.fori_loop(0, 2, trip, init)
    U = jnp.where((levels >= 0)[..., None, None], jnp.minimum(U1, U2), U1)
    return extrema.reduce_max(U, 1)
