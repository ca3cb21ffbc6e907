"""Quintic clamped B-spline trajectories (paper §3.2, Eqs. 16–23; conventions §2).

Everything here is a pure ``jax.numpy`` function of the knots and control points, with
static shapes, so it jits and vmaps. The knot vector is built from the ``s`` intervals
``h_1..h_s`` (the paper: s = 6)::

    u = [0,0,0,0,0,0, t_1, …, t_{s−1}, T,T,T,T,T,T]      (Eq. 20; s + 11 knots, 17 in the paper)

with ``t_k = h_1 + … + h_k`` and ``T = t_s``. The ``s + 5`` control points are
``d_0 = d_1 = d_2 = P_o``, ``n = s − 1`` free ones (the paper: ``d_3..d_7``) and three copies
of ``P_e`` (Eqs. 18–19). The number of spans is read from the shapes, so one function serves
every ``n``; each distinct ``n`` compiles once.

For fast exact work the spline is converted, span by span, to local power series
``p(t) = Σ_m c[k, m] (t − t_{k})^m`` on span ``k = 0..s−1`` (``[t_k, t_{k+1}]`` with
``t_0 = 0``): the coefficients are the derivatives at the span's left knot, computed from
the derivative control points of Eq. 22 and the Cox–de Boor basis (Eq. 16).
"""

from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

DEGREE = 5
N_CTRL = 11
N_KNOTS = N_CTRL + DEGREE + 1  # 17
N_SPANS = 6
"""Spans of the paper's family (5 free control points); other families have ``n + 1``."""

__all__ = [
    "DEGREE",
    "N_SPANS",
    "knots",
    "interior_knots",
    "control_points",
    "line_control_points",
    "basis_functions",
    "span_coefficients",
    "poly_derivative",
    "poly_eval",
    "poly_taylor",
    "poly_taylor_terms",
    "evaluate",
    "insert_knots",
    "split_counts",
]


def knots(h):
    """Knot vector of Eq. 20 from the intervals. h: (..., s) → (..., s + 11)."""
    h = jnp.asarray(h)
    t = jnp.cumsum(h, axis=-1)
    zeros = jnp.zeros(h.shape[:-1] + (DEGREE + 1,), h.dtype)
    ends = jnp.broadcast_to(t[..., -1:], h.shape[:-1] + (DEGREE + 1,))
    return jnp.concatenate([zeros, t[..., :-1], ends], axis=-1)


def interior_knots(u):
    """The span boundaries ``t_1..t_{s−1}`` inside ``(0, T)`` of a knot vector (s + 11,)."""
    return u[DEGREE + 1 : u.shape[-1] - DEGREE - 1]


def control_points(start, goal, interior, h=None, boundary=None):
    """Control points of Eqs. 18–19. start, goal: (d,); interior: (n, d) → (n + 6, d).

    At rest at both ends (``boundary`` None) the first three are the start and the last
    three the goal (Eq. 19). ``boundary``: ``(v0, a0, v1, a1)``, each (d,), the velocity and
    acceleration at t = 0 and at T, with ``h`` (n + 1,) the knot intervals: the clamped
    quintic's end derivatives p'(0) = 5 (P1 − P0) / h1 and
    p''(0) = 20 / h1 · ((P2 − P1) / (h1 + h2) − (P1 − P0) / h1), solved for P1 and P2
    (conventions §2), and the same at T with the time reversed."""
    interior = jnp.asarray(interior)
    d = interior.shape[-1]
    start = jnp.asarray(start, interior.dtype)
    goal = jnp.asarray(goal, interior.dtype)
    if boundary is None:
        return jnp.concatenate([jnp.broadcast_to(start, (3, d)), interior, jnp.broadcast_to(goal, (3, d))], axis=0)
    v0, a0, v1, a1 = (jnp.asarray(b, interior.dtype) for b in boundary)
    h = jnp.asarray(h, interior.dtype)
    p1 = start + v0 * (h[0] / 5.0)
    p2 = p1 + (h[0] + h[1]) * (v0 / 5.0 + a0 * (h[0] / 20.0))
    q1 = goal - v1 * (h[-1] / 5.0)
    q2 = q1 + (h[-1] + h[-2]) * (a1 * (h[-1] / 20.0) - v1 / 5.0)
    return jnp.concatenate([jnp.stack([start, p1, p2]), interior, jnp.stack([q2, q1, goal])], axis=0)


def line_control_points(start, goal, n: int = N_SPANS - 1):
    """``n`` interior points evenly spaced on the segment start→goal, at ``i / (n + 1)``,
    i = 1..n (conventions §3; the paper's ``d_3..d_7`` for n = 5). → (n, d)."""
    start, goal = jnp.asarray(start), jnp.asarray(goal)
    s = jnp.arange(1, n + 1, dtype=start.dtype)[:, None] / float(n + 1)
    return start + s * (goal - start)


def _basis_recursion(u, spans, t, degree: int, stacked: bool):
    """Cox–de Boor triangle of :func:`basis_functions`; ``stacked``: a stage's j divisions
    as one array operation (XLA:CPU gives each separate division its own small kernel).
    The divisions are elementwise either way, so the values are identical."""
    spans = np.asarray(spans)
    left = [t - u[spans + 1 - j] for j in range(1, degree + 1)]
    right = [u[spans + j] - t for j in range(1, degree + 1)]
    n = [jnp.ones_like(t)]
    out = [n]
    for j in range(1, degree + 1):
        if stacked:
            temps = list(jnp.stack(n) / jnp.stack([right[r] + left[j - r - 1] for r in range(j)]))
        saved = jnp.zeros_like(t)
        new = []
        for r in range(j):
            temp = temps[r] if stacked else n[r] / (right[r] + left[j - r - 1])
            new.append(saved + right[r] * temp)
            saved = left[j - r - 1] * temp
        new.append(saved)
        n = new
        out.append(n)
    return out


@partial(jax.custom_jvp, nondiff_argnums=(1, 3))
def basis_functions(u, spans, t, degree: int):
    """The nonzero basis functions of every degree 0..``degree`` (Eq. 16) at points t.

    Cox–de Boor recursion in the triangular form of Piegl & Tiller, *The NURBS Book*,
    Algorithm A2.2, vectorised over points: ``spans`` (static integer array) holds each
    point's knot span, ``u[span] <= t <= u[span + 1]`` with ``u[span] < u[span + 1]``, so
    no denominator vanishes. u: (m,), t: shaped like ``spans`` → a list whose entry q is
    the ``q + 1`` functions ``N_{span−q..span, q}(t)`` (each shaped like t) of degree q.

    The value computes a stage's divisions together (fewer, larger kernels); derivatives
    differentiate the plain recursion, one division at a time, so that gradients are
    rounded exactly as they were before that change.
    """
    return _basis_recursion(u, spans, t, degree, stacked=True)


@basis_functions.defjvp
def _basis_functions_jvp(spans, degree, primals, tangents):
    return jax.jvp(lambda u, t: _basis_recursion(u, spans, t, degree, stacked=False), primals, tangents)


def _derivative_levels(ctrl, u, order: int):
    """Control points of the derivative splines of orders 0..order (Eq. 22, repeated):
    ``P^(m)_i = (p − m + 1)(P^(m−1)_{i+1} − P^(m−1)_i) / (u_{i+p+1} − u_{i+m})``; the
    derivative of order m has degree ``p − m`` on the knots ``u[m : len(u) − m]`` (Eq. 23)."""
    p = DEGREE
    q = ctrl
    levels = [q]
    for m in range(1, order + 1):
        n = q.shape[0] - 1
        den = u[p + 1 : p + 1 + n] - u[m : m + n]
        q = (p - m + 1) * (q[1:] - q[:-1]) / den[:, None]
        levels.append(q)
    return levels


def span_coefficients(ctrl, u):
    """Local power-series coefficients of the trajectory on each span.

    Returns ``c`` (s, 6, d): on span k, ``p(t) = Σ_m c[k, m] τ^m`` with ``τ = t − u[5 + k]``;
    ``c[k, m] = p^(m)(u[5+k]) / m!`` from the derivative control points of Eq. 22 evaluated
    with the basis of Eq. 16 (Eq. 21). ctrl: (s + 5, d), u: (s + 11,); s = 6 in the paper.

    The derivative of order m has degree ``p − m`` on the knots ``u[m : 17 − m]``, where
    the left knot of span k has index ``p + k − m``: its basis there is the degree-``p − m``
    stage of one Cox–de Boor triangle over the s left knots, with the same knot
    differences for every m.
    """
    p = DEGREE
    n_spans = ctrl.shape[0] - p
    k = np.arange(n_spans)
    bases = basis_functions(u, p + k, u[p + k], p)
    coeffs = []
    for m, q in enumerate(_derivative_levels(ctrl, u, p)):
        nb = bases[p - m]
        # elementwise over the span's p − m + 1 control points (fuses; no tiny matmuls)
        val = sum(nb[i][:, None] * q[i : i + n_spans] for i in range(p - m + 1))
        coeffs.append(val / math.factorial(m))
    return jnp.stack(coeffs, axis=1)


def poly_derivative(c, order: int = 1):
    """Coefficients of the ``order``-th derivative of a power series along axis -1."""
    for _ in range(order):
        deg = c.shape[-1] - 1
        c = c[..., 1:] * jnp.arange(1, deg + 1, dtype=c.dtype)
    return c


def poly_eval(c, x):
    """Horner evaluation of ``Σ_m c[..., m] x^m`` (coefficients along the last axis)."""
    out = c[..., -1]
    for m in range(c.shape[-1] - 2, -1, -1):
        out = out * x + c[..., m]
    return out


def poly_taylor_terms(c, x, order: int | None = None) -> list:
    """Normalised Taylor coefficients ``p^(k)(x)/k!``, k = 0..order, of a power series at x,
    as a list of arrays (a jet, :mod:`dockjax.jets`).

    Repeated synthetic division by ``(τ − x)`` (Horner's shift). c: (..., n), x broadcastable
    to ``c[..., 0]`` (default order n − 1).
    """
    n_out = c.shape[-1] if order is None else order + 1
    b = [c[..., m] for m in range(c.shape[-1])]
    out = []
    while len(out) < n_out:
        accs = [b[-1]]
        for m in range(len(b) - 2, -1, -1):
            accs.append(accs[-1] * x + b[m])
        out.append(accs[-1])
        b = accs[-2::-1]
    return out


def poly_taylor(c, x, order: int | None = None):
    """:func:`poly_taylor_terms` stacked along a new last axis → (..., order + 1)."""
    out = poly_taylor_terms(c, x, order)
    return jnp.stack(jnp.broadcast_arrays(*out), axis=-1)


def evaluate(c, u, t, derivative: int = 0):
    """Evaluate the spline (or a derivative) at times t from its span coefficients.

    c: (s, 6, d) from :func:`span_coefficients`, u: (s + 11,), t: (m,) in [0, T] → (m, d).
    """
    t = jnp.asarray(t)
    k = jnp.searchsorted(interior_knots(u), t, side="right")
    tau = t - u[DEGREE + k]
    ck = jnp.moveaxis(c[k], 1, -1)  # (m, d, 6)
    return poly_eval(poly_derivative(ck, derivative), tau[:, None])


def insert_knots(u, ctrl, new):
    """The same spline on a finer knot vector, by Boehm's knot insertion (host-side NumPy).

    u: (m,) clamped knots of degree :data:`DEGREE`, ctrl: (m − 6, d), new: knots to insert,
    each inside ``(u[0], u[-1])``. → ``(u', ctrl')`` with ``len(new)`` more knots and control
    points. Each new control point is a convex combination of two old ones, so a convex box
    holding the old points holds the new; the curve is unchanged (up to rounding).
    """
    u = np.asarray(u, np.float64)
    P = np.asarray(ctrl, np.float64)
    p = DEGREE
    for t in np.sort(np.asarray(new, np.float64)):
        k = int(np.searchsorted(u, t, side="right")) - 1  # u[k] <= t < u[k + 1]
        i = np.arange(k - p + 1, k + 1)
        a = (t - u[i]) / (u[i + p] - u[i])
        mid = (1.0 - a)[:, None] * P[i - 1] + a[:, None] * P[i]
        P = np.concatenate([P[: k - p + 1], mid, P[k:]])
        u = np.insert(u, k + 1, t)
    return u, P


def split_counts(h, total: int, shortest: float = 0.0) -> np.ndarray:
    """Into how many equal pieces to cut each interval h (s,) to make ``total`` intervals
    (``total >= s``): in proportion to the lengths (largest remainders first), no piece
    shorter than ``shortest`` where the lengths allow it. → (s,) ints summing to ``total``."""
    h = np.asarray(h, np.float64)
    cap = np.maximum(1, np.floor(h / shortest).astype(int)) if shortest > 0 else np.full(h.shape, total)
    counts = np.ones(h.shape, int)
    for _ in range(total - len(h)):
        room = counts < cap
        score = np.where(room, h / counts, -np.inf) if room.any() else h / counts
        counts[int(np.argmax(score))] += 1
    return counts
