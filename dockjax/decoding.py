"""Decision vector → trajectory: knot intervals, knots and per-span power series of the
pose (conventions §2–3), and the reference angles of each span.

Everything here is traceable (jit, vmap) and works on one candidate; the kernel vmaps it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax.numpy as jnp

from . import bspline, config
from .config import DEG as _DEG
from .fusion import materialize
from .robot import POSE_ATTITUDE

if TYPE_CHECKING:
    from .problem import DockingProblem

__all__ = ["decode", "span_angles", "spans"]


def decode(problem: "DockingProblem", x):
    """Intervals, knots and span coefficients of one candidate.

    x: (n_var,) → ``h`` (s,), ``u`` (s + 11,), ``c`` (s spans, 6 powers, 6 pose coordinates),
    with s = ``problem.n_intervals`` (6 in the paper).
    """
    s = problem.n_intervals
    h = x[:s]
    if problem.reduced:
        interior = bspline.line_control_points(problem.start, problem.goal, problem.n_control).astype(x.dtype)
    else:
        interior = x[s:].reshape(problem.n_control, config.N_POSE)
    u = bspline.knots(h)
    ctrl = bspline.control_points(problem.start, problem.goal, interior, h, problem.boundary)
    # Materialise: stops XLA from re-fusing (and so recomputing) the conversion into
    # every broadcasting consumer downstream.
    return materialize((h, u, bspline.span_coefficients(ctrl, u)))


def span_angles(c, h):
    """Pitch and yaw (°) at the middle of each span with their sines and cosines.

    c: (s, 6, 6), h: (s,) → (mid (s, 2), sin (s, 2), cos (s, 2)): the reference angles of
    the expansions used for the right arm (one trig call per span and angle).
    """
    mid = bspline.poly_eval(jnp.swapaxes(c[..., POSE_ATTITUDE], 1, 2), 0.5 * h[:, None])  # (s, 2)
    return mid, jnp.sin(_DEG * mid), jnp.cos(_DEG * mid)


def spans(problem: "DockingProblem", x):
    """What the kernels need of one candidate: ``h`` (s,), ``u`` (s + 11,), ``c`` (s, 6, 6) of
    :func:`decode` and the reference angles ``ref`` of :func:`span_angles` (materialised:
    computed once for every consumer)."""
    h, u, c = decode(problem, x)
    return h, u, c, materialize(span_angles(c, h))
