"""The 24 limit columns G (conventions §6): per joint, travel about home, |velocity| and
|acceleration| against the limits of paper Table 2.

``G[3j + k] = max_t |quantity_k(t)| / limit_k − 1``; feasible when every column is <= 0. No
column is ever below the true maximum:

* the joints linear in the pose are quintics on each knot span; their extrema sit at span
  ends or at roots of the next derivative, found by the derivative chain of
  :mod:`dockjax.extrema`, each root certified by a sign change and its value carrying a
  rigorous margin (:func:`maxima`);
* the right arm's nonlinear joints follow the problem's treatment
  (:mod:`dockjax.right_arm`);
* **screening** (:func:`maxima_screened`): cheap two-sided bounds from a grid of samples
  per span decide which spans can hold a column's maximum; only those go through the root
  chain. Columns within :data:`SCREEN_BAND` of their limit are exact as above; the others
  (comfortably satisfied or clearly violated) may overstate by at most
  :data:`SCREEN_SLACK` of the limit (conventions §6 allows 0.01);
* :data:`G_SAFETY` is added against rounding (:func:`columns`).

Every function is traceable and takes the robot's numbers (:class:`dockjax.robot.Robot`:
D_2, home, the limit table), not the whole problem.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax.numpy as jnp

from . import extrema
from .config import DEG as _DEG
from .fusion import materialize
from .right_arm import linearisation_remainders, right_taylor_maxima
from .robot import ATTITUDE_JOINTS

if TYPE_CHECKING:
    from .robot import Robot

__all__ = [
    "G_SAFETY", "BOUND_TOLERANCE", "SCREEN_SLOTS", "SCREEN_BAND", "SCREEN_SLACK", "joint_series", "maxima",
    "maxima_screened", "columns",
]


G_SAFETY = 1e-9
"""Added to every constraint column so that rounding never understates it (conventions §6)."""

BOUND_TOLERANCE = 1e-2
"""conventions §6: the most a G column may overstate its true value."""


SCREEN_SLOTS = 3
"""Spans per candidate that :func:`maxima_screened` sends through the exact root chain."""
SCREEN_BAND = 0.05
"""Columns whose estimate lies within this fraction of the limit (either side) are exact."""
SCREEN_SLACK = 0.009
"""The most a column outside the band may overstate (conventions §6 allows 0.01)."""


def joint_series(robot: "Robot", c, h, ref):
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
    # the cabin axis linearised in pitch and yaw about the span's middle, then the one
    # pose→joints map (linear, so it maps the power series coefficient by coefficient)
    # (u_z, u_y, u_x in this order: see robot.cabin_axis_jets)
    uz = ca * cb * e0 - sa * cb * da - ca * sb * db
    uy = sa * e0 + ca * da
    ux = ca * sb * e0 - sa * sb * da + ca * cb * db
    polys = jnp.stack(robot.joints(x, y, z, g, ux, uy, uz), axis=1)
    return polys - robot.home[None, :, None] * e0


def _with_jerk(robot: "Robot", M, polys, h, rem):
    """M (8, 3) with the robot's jerk column appended when it has jerk limits: per span the
    closed-form maximum of the series' quadratic jerk (:func:`dockjax.extrema.jerk_maxima`),
    plus the right arm's remainder ``rem`` (s, 3 joints) where given. → (8, kinds)."""
    if not robot.has_jerk:
        return M
    spans = extrema.jerk_maxima(polys, jnp.broadcast_to(h[:, None], polys.shape[:2]))  # (s, 8)
    if rem is not None:
        spans = spans.at[:, ATTITUDE_JOINTS].add(rem)
    return jnp.concatenate([M, extrema.reduce_max(spans, 0)[:, None]], -1)


def maxima(robot: "Robot", c, h, ref, *, taylor: bool = False, with_need: bool = False, screen: bool = False):
    """``max_t |q_j − home_j|``, ``max |q_j'|``, ``max |q_j''|`` (and ``max |q_j'''|`` with jerk
    limits) per joint. → (8, kinds).

    ``taylor`` (static): the right arm's ``"taylor"`` treatment, else its ``"bound"`` one.
    With ``with_need``, also whether this candidate's bound treatment of the right arm may
    overstate by more than :data:`BOUND_TOLERANCE` (always False in the ``"taylor"``
    treatment). ``screen``: as in :func:`dockjax.right_arm.right_taylor_maxima` (the ``"taylor"`` treatment's
    choice of tight columns)."""
    polys = materialize(joint_series(robot, c, h, ref))
    hh = jnp.broadcast_to(h[:, None], polys.shape[:2])
    spans, _ = extrema.span_maxima(polys, hh)
    lin = extrema.reduce_max(spans, 0)  # (8, 3)
    if taylor:
        band = SCREEN_BAND if screen else None
        right = right_taylor_maxima(robot, c[None], h[None], tuple(a[None] for a in ref), band)[0]
        need = jnp.zeros((), bool)
        lin = _with_jerk(robot, lin, polys, h, None)
    else:
        rems = linearisation_remainders(robot, c, h, ref)  # (s, 3 joints, kinds)
        rem = extrema.reduce_max(rems, 0)  # (3 joints, kinds)
        lin = _with_jerk(robot, lin, polys, h, rems[..., 3] if robot.has_jerk else None)
        # the jerk column already holds the remainder (added per span by _with_jerk)
        right = lin[ATTITUDE_JOINTS] + (jnp.pad(rem[:, :3], ((0, 0), (0, 1))) if robot.has_jerk else rem)
        need = jnp.any(2.0 * rem > BOUND_TOLERANCE * robot.limits[ATTITUDE_JOINTS])
    out = lin.at[ATTITUDE_JOINTS].set(right)
    return (out, need) if with_need else out


def maxima_screened(robot: "Robot", c, h, ref):
    """The maxima of :func:`maxima` (bound treatment of the right arm) for a fraction of
    the cost. → ``(M (8, 3), need, over, spans)``.

    Every span gets the cheap two-sided estimates of :func:`dockjax.extrema.span_bounds`
    (``L <= max <= U``). A column's value is the largest span value, so a span whose U is
    at most the column's largest L (plus a tolerance) cannot change it by more than the
    tolerance. The tolerance is 0 for columns whose estimate lies within
    :data:`SCREEN_BAND` of the limit (there the decisions are made: those columns are
    exact), and :data:`SCREEN_SLACK` of the limit, less the right arm's remainder
    overstatement, for the others (comfortably satisfied or clearly violated limits; the conventions
    §6 allows 0.01). The spans whose velocity or acceleration fails the test — usually
    none or one per candidate — go through the root chain of those two
    (:func:`dockjax.extrema.rate_maxima`), up to :data:`SCREEN_SLOTS` of them; ``over``
    flags a candidate with more, or with a failing travel (rare: positions are smooth):
    its columns are then valid upper bounds, not necessarily within the tolerance, and it
    is re-scored by the full chain on all its spans, as :func:`dockjax.problem.score_batch` does (from the
    returned ``(span series (48, 6), span lengths (48,), right-arm remainders (8, 3))``)."""
    polys = materialize(joint_series(robot, c, h, ref))  # (6, 8, 6)
    hh = jnp.broadcast_to(h[:, None], polys.shape[:2])
    low, up = materialize(extrema.span_bounds(polys, hh))  # (6, 8, 3); read by several fusions
    rems = linearisation_remainders(robot, c, h, ref)  # (s, 3 joints, kinds)
    rem_all = extrema.reduce_max(rems, 0)  # (3 joints, kinds)
    rem = rem_all[:, :3]
    extra = jnp.zeros((8, 3), c.dtype).at[ATTITUDE_JOINTS].set(rem)
    lim = robot.limits[:, :3]
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
    need = jnp.any(2.0 * rem_all > BOUND_TOLERANCE * robot.limits[ATTITUDE_JOINTS])
    over = jnp.any(rest) | jnp.any(fail[:, 0])
    # the jerk (a quadratic per span) is exact and cheap: no screening
    M = _with_jerk(robot, M, polys, h, rems[..., 3] if robot.has_jerk else None)
    return M, need, over, (polys.reshape(n_items, -1), hh.reshape(-1), extra)


def columns(robot: "Robot", M, limits=None):
    """G columns (..., 8 · kinds) from the maxima (..., 8, kinds), joint-major (conventions §6,
    with the safety margin); ``limits`` (8, kinds) replaces the robot's table (a subset of
    its kinds)."""
    lim = robot.limits if limits is None else limits
    return (M / lim - 1.0 + G_SAFETY).reshape(M.shape[:-2] + (-1,))
