"""Exact extrema of low-degree polynomials on an interval, as array programs.

The limits of conventions §6 need ``max |q(t)|``, ``max |q'(t)|`` and ``max |q''(t)|`` on every knot
span, where q is a quintic. The extrema of ``|Q|`` on ``[0, h]`` lie at the ends or at roots
of ``Q'``, so the roots are found by the derivative chain: the roots of the jerk (a
quadratic, closed form) split the span into pieces on which the acceleration is monotone,
each holding at most one root of it, found by safeguarded Newton; the roots of the
acceleration split it likewise for the velocity. No sampling, no Python loop over data:
every function works elementwise on arrays of coefficients (any leading shape).
"""

from __future__ import annotations

from functools import partial
from math import comb

import jax
import jax.numpy as jnp

from .bspline import poly_derivative, poly_eval
from .fusion import materialize

__all__ = [
    "reduce_max", "quadratic_roots", "bracketed_root", "roots_in_brackets", "chain_extrema", "span_maxima",
    "span_bounds", "rate_maxima", "jerk_times", "jerk_maxima",
]

NEWTON_STEPS = 8
"""Safeguarded Newton steps per bracket (quadratic convergence; the value at a root of the
derivative is accurate to second order in the root's error)."""


@partial(jax.custom_jvp, nondiff_argnums=(1,))
def reduce_max(x, axis):
    """``jnp.max(x, axis)`` (an int or a tuple of ints) whose derivative is the tangent
    at the first maximising element (a valid one-sided derivative).

    JAX's own rule for ``max`` finds the maximising elements by comparing ``x`` with the
    result for equality and divides by their count. XLA may compute ``x`` twice, in two
    fusions rounded differently; then no element compares equal and the derivative is
    0/0 = NaN (observed with XLA:CPU at ``--xla_backend_optimization_level=0``). Selecting
    by ``argmax`` needs no equality. The value, and so the kernel, is unchanged."""
    return jnp.max(x, axis)


@reduce_max.defjvp
def _reduce_max_jvp(axis, primals, tangents):
    (x,), (t,) = primals, tangents
    axes = (axis,) if isinstance(axis, int) else tuple(axis)
    axes = tuple(a % x.ndim for a in axes)
    keep = [a for a in range(x.ndim) if a not in axes]
    # the reduced axes moved last and flattened into one: a single argmax
    flat = lambda a: jnp.transpose(a, keep + list(axes)).reshape([x.shape[k] for k in keep] + [-1])  # noqa: E731
    xf, tf = flat(x), flat(t)
    i = jnp.argmax(xf, axis=-1)[..., None]
    return jnp.max(x, axis), jnp.take_along_axis(tf, i, axis=-1)[..., 0]


def _safe_div(num, den):
    ok = den != 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0), ok


def quadratic_roots(c, lo, hi):
    """Real roots of ``c0 + c1 τ + c2 τ²`` clipped to ``[lo, hi]``, sorted. c: (..., 3).

    Numerically stable form (``q = −(c1 + sign(c1)√disc)/2``); a missing root is returned as
    ``lo`` (harmless: the interval ends are always examined). Returns (..., 2).
    """
    c0, c1, c2 = c[..., 0], c[..., 1], c[..., 2]
    disc = c1 * c1 - 4.0 * c2 * c0
    real = disc >= 0.0
    sq = jnp.sqrt(jnp.where(real, disc, 0.0))
    q = -0.5 * (c1 + jnp.where(c1 >= 0.0, sq, -sq))
    r1, ok1 = _safe_div(q, c2)
    r2, ok2 = _safe_div(c0, q)
    r1 = jnp.where(real & ok1, r1, lo)
    r2 = jnp.where(real & ok2, r2, lo)
    r1, r2 = jnp.clip(r1, lo, hi), jnp.clip(r2, lo, hi)
    return jnp.stack([jnp.minimum(r1, r2), jnp.maximum(r1, r2)], axis=-1)


CERTIFICATE = 1e-7
"""Half-width, relative to the bracket, of the sign check that certifies a root."""


def bracketed_root(c, dc, lo, hi, steps: int | None = None):
    """Root of a polynomial monotone on ``[lo, hi]`` by safeguarded Newton (rtsafe).

    c: (..., n) coefficients, dc their derivative; lo, hi: (...). Returns ``(x, width,
    slope)``: the root lies within ``width`` of x (a certificate: the sign of the polynomial
    is checked on both sides of x, else the whole remaining bracket is the width). Where the
    polynomial does not change sign on the bracket there is no root: the end with the
    smaller ``|value|`` is returned with width 0 (any point of the bracket is harmless).
    ``slope``: where the sign check failed, the largest ``|c|`` on the remaining bracket
    (its ends' values: c is monotone there), which holds both x and the root; elsewhere the
    largest finite number (no bound).
    """
    flo, fhi = poly_eval(c, lo), poly_eval(c, hi)
    # A root at (or within rounding of) an end needs no search: the ends are examined
    # anyway, and a monotone piece holds no other root. This also spares the double roots
    # of the clamped ends (velocity and acceleration vanish at t = 0 and t = T).
    reach = jnp.maximum(jnp.abs(lo), jnp.abs(hi))
    scale = poly_eval(jnp.abs(c), reach)
    tol = 64 * jnp.finfo(c.dtype).eps * scale
    flo = jnp.where(jnp.abs(flo) <= tol, 0.0, flo)
    fhi = jnp.where(jnp.abs(fhi) <= tol, 0.0, fhi)
    change = (flo * fhi) < 0.0
    # orient so that f(a) <= 0 <= f(b)
    up = flo <= fhi
    a = jnp.where(up, lo, hi)
    b = jnp.where(up, hi, lo)
    fa, fb = jnp.minimum(flo, fhi), jnp.maximum(flo, fhi)
    den = fb - fa
    x = jnp.where(den > 0, a - fa * (b - a) / jnp.where(den > 0, den, 1.0), 0.5 * (a + b))
    def newton(_, carry):
        x, a, b, last = carry
        fx = poly_eval(c, x)
        a = jnp.where(fx <= 0.0, x, a)
        b = jnp.where(fx > 0.0, x, b)
        dfx = poly_eval(dc, x)
        step, ok = _safe_div(fx, dfx)
        xn = x - step
        # rtsafe: bisect when Newton leaves the bracket or does not halve its last step
        small = jnp.abs(step) <= 1e-12 * jnp.abs(hi - lo)  # converged: stay
        good = ok & ((xn - a) * (xn - b) <= 0.0) & ((2.0 * jnp.abs(step) <= last) | small)
        x_new = jnp.where(good, xn, 0.5 * (a + b))
        return x_new, a, b, jnp.abs(x_new - x)

    # a rolled loop keeps the compiled program small (compile time matters here)
    x, a, b, _ = jax.lax.fori_loop(
        0, NEWTON_STEPS if steps is None else steps, newton, (x, a, b, jnp.abs(b - a))
    )
    eps = CERTIFICATE * jnp.abs(hi - lo)
    left = jnp.clip(x - eps, lo, hi)
    right = jnp.clip(x + eps, lo, hi)
    tight = poly_eval(c, left) * poly_eval(c, right) <= 0.0
    width = jnp.where(tight, right - left, jnp.abs(b - a))
    slope = jnp.where(change & ~tight, jnp.maximum(jnp.abs(poly_eval(c, a)), jnp.abs(poly_eval(c, b))),
                      jnp.finfo(c.dtype).max)
    fallback = jnp.where(jnp.abs(flo) <= jnp.abs(fhi), lo, hi)
    return jnp.where(change, x, fallback), jnp.where(change, width, 0.0), slope


def roots_in_brackets(c, edges):
    """Roots of c, one per bracket ``[edges[i], edges[i+1]]`` on which c is monotone.

    c: (..., n); edges: (..., k+1) sorted → roots (..., k), their certified widths and
    slopes (:func:`bracketed_root`).
    """
    dc = poly_derivative(c)
    lo, hi = edges[..., :-1], edges[..., 1:]
    return bracketed_root(c[..., None, :], dc[..., None, :], lo, hi)


def _rate_chain(c, h):
    """The first two links of the chain: ``(jerk roots, (acceleration roots, widths),
    slopes)`` of a quintic's series c (..., 6) on ``[0, h]``, as the ends plus interior
    roots; ``slopes`` (..., 5) bound ``|Q''|`` between each acceleration root and its
    estimate where the root's sign check failed (:func:`bracketed_root`; else, and at the
    ends, the largest finite number)."""
    zero = jnp.zeros_like(h)
    a = poly_derivative(c, 2)
    j = poly_derivative(a)
    jr = quadratic_roots(j, zero, h)  # (..., 2)
    ends_lo, ends_hi = zero[..., None], h[..., None]
    a_edges = jnp.concatenate([ends_lo, jr, ends_hi], axis=-1)  # (..., 4)
    ar, aw, slope = roots_in_brackets(a, a_edges)  # (..., 3), ordered
    v_edges = jnp.concatenate([ends_lo, ar, ends_hi], axis=-1)  # (..., 5)
    big = jnp.full_like(ends_lo, jnp.finfo(c.dtype).max)
    return a_edges, (v_edges, aw), jnp.concatenate([big, slope, big], axis=-1)


def chain_extrema(c, h):
    """Critical times of a quintic's value, velocity and acceleration on ``[0, h]``.

    c: (..., 6) power-series coefficients in τ ∈ [0, h]; h: (...). Returns
    ``((travel_times (..., 6), widths), (velocity_times (..., 5), widths),
    acceleration_times (..., 4))``: the ends and the roots of the first, second and third
    derivative respectively (the last in closed form), each root within its width of the
    true one.
    """
    return _chain(c, h)[0]


def _chain(c, h):
    """:func:`chain_extrema` and the slopes of :func:`_rate_chain`."""
    # The critical times carry no gradient (envelope theorem: at an interior root of Q' the
    # derivative of Q(τ*) with respect to the coefficients is ∂Q/∂c at τ*). So the root
    # searches run on constants: the backward pass never enters the Newton loops (cheaper,
    # and no 0·∞ at a double root). Times equal to the span end get h back, with its
    # gradient (the end of a span moves with h).
    h_in = h
    c, h = jax.lax.stop_gradient(c), jax.lax.stop_gradient(h)
    a_edges, (v_edges, aw), slope = _rate_chain(c, h)
    vr, vw, _ = roots_in_brackets(poly_derivative(c), v_edges)  # (..., 4)
    ends_lo, ends_hi = v_edges[..., :1], v_edges[..., -1:]
    t_edges = jnp.concatenate([ends_lo, vr, ends_hi], axis=-1)  # (..., 6)
    pad = jnp.zeros_like(ends_lo)
    end = lambda t: jnp.where(t == h[..., None], h_in[..., None], t)  # noqa: E731
    return (
        (end(t_edges), jnp.concatenate([pad, vw, pad], -1)),
        (end(v_edges), jnp.concatenate([pad, aw, pad], -1)),
        end(a_edges),
    ), slope


def _at(c, t):
    """Power series c (..., n) at times t (..., m) → (..., m)."""
    return poly_eval(c[..., None, :], t)


def jerk_times(j, h):
    """The candidate times of ``max |j|`` on ``[0, h]`` for a quadratic j (..., 3) (the jerk of a
    quintic): the ends and the vertex (clipped into the span; no gradient, envelope theorem).
    → (..., 3)."""
    peak, _ = _safe_div(-j[..., 1], 2.0 * j[..., 2])
    peak = jax.lax.stop_gradient(jnp.clip(peak, 0.0, h))
    return jnp.stack([jnp.zeros_like(h), h, peak], -1)


def _quadratic_max(j, h):
    """``max |j|`` on ``[0, h]`` of a quadratic j (..., 3): at the ends or the vertex, exact."""
    return reduce_max(jnp.abs(_at(j, jerk_times(j, h))), -1)


def jerk_maxima(c, h):
    """The largest |jerk| (third derivative) of a quintic c (..., 6) on ``[0, h]`` (...): the
    jerk is a quadratic, so it is reached at an end or at the vertex (closed form, exact to
    rounding)."""
    return _quadratic_max(poly_derivative(c, 3), h)


def _rate_maxima(d, h, vt, vw, at, slope):
    """max |Q'| and |Q''| from the critical times (see :func:`span_maxima`); d: the series
    of Q and its first three derivatives. At a velocity critical time x within w of the
    root, ``|Q'| <= |Q'(x)| + min(|Q''(x)| w + J w²/2, S w)``, J the jerk's maximum on the
    span and S ``slope`` (:func:`_rate_chain`): where a root's sign check failed, as on a
    plateau of the velocity (``Q''`` nearly zero over the bracket), S w is far the smaller."""
    amax = reduce_max(jnp.abs(_at(d[2], at)), -1)
    jmax = _quadratic_max(d[3], h)
    v = jnp.abs(_at(d[1], vt))
    second = v + jnp.abs(_at(d[2], vt)) * vw + 0.5 * jmax[..., None] * vw * vw
    vmax = reduce_max(jnp.minimum(second, v + slope * vw), -1)
    return vmax, amax


def span_maxima(c, h):
    """Maxima of ``|c|``, ``|c'|``, ``|c''|`` of a quintic on ``[0, h]``, never understated.

    c: (..., 6), h: (...) → maxima (..., 3) and the critical times of :func:`chain_extrema`.
    At a root x of ``Q'`` certified within width w, ``|Q| <= |Q(x)| + |Q'(x)| w + M w²/2``
    with M the maximum of ``|Q''|`` on the span (exact: the acceleration's maximum for the
    value, the jerk's for the velocity), so rounding or slow convergence can only overstate;
    for the velocity, where a root's sign check failed, also ``|Q'(x)| + S w`` with S the
    acceleration's largest ``|value|`` over the search's last bracket (:func:`_rate_maxima`).
    """
    times, slope = _chain(c, h)
    (tt, tw), (vt, vw), at = times
    d = [c] + [poly_derivative(c, k) for k in range(1, 4)]
    vmax, amax = _rate_maxima(d, h, vt, vw, at, slope)
    pmax = reduce_max(
        jnp.abs(_at(d[0], tt)) + jnp.abs(_at(d[1], tt)) * tw + 0.5 * amax[..., None] * tw * tw, -1
    )
    return jnp.stack([pmax, vmax, amax], -1), times


def rate_maxima(c, h):
    """Maxima of ``|c'|`` and ``|c''|`` of a quintic on ``[0, h]`` as in :func:`span_maxima`
    (same values), without the value's link of the chain (3 of its 7 root searches).
    c: (..., 6), h: (...) → (..., 2)."""
    h_in = h
    c, h = jax.lax.stop_gradient(c), jax.lax.stop_gradient(h)
    a_edges, (v_edges, aw), slope = _rate_chain(c, h)
    pad = jnp.zeros_like(h[..., None])
    end = lambda t: jnp.where(t == h[..., None], h_in[..., None], t)  # noqa: E731
    d = [c] + [poly_derivative(c, k) for k in range(1, 4)]
    vmax, amax = _rate_maxima(d, h_in, end(v_edges), jnp.concatenate([pad, aw, pad], -1), end(a_edges), slope)
    return jnp.stack([vmax, amax], -1)


SAMPLES = (8, 16, 8)
"""Uniform sub-intervals per span of :func:`span_bounds` for the value, the velocity and the
acceleration (the velocity limits bind in the paper's problem, so it gets the finest grid)."""


def _sampled_max(terms, m):
    """max over s = i/m, i = 0..m, of |Σ_p terms[p] s^p| (elementwise; constants folded)."""
    out = None
    for i in range(m + 1):
        s = i / m
        v = terms[0]
        for p in range(1, len(terms)):
            v = v + terms[p] * s**p
        out = jnp.abs(v) if out is None else jnp.maximum(out, jnp.abs(v))
    return out


def _derivative_terms(terms):
    """The derivative of Σ_p terms[p] s^p as a list (what :func:`poly_derivative` computes,
    term by term)."""
    return [terms[p] * float(p) for p in range(1, len(terms))]


def _bernstein_max(terms):
    """max |Bernstein coefficient| of Σ_p terms[p] s^p on [0, 1]: a bound of max |.| there
    (convex hull property)."""
    n = len(terms) - 1
    out = None
    for i in range(n + 1):
        b = sum(terms[p] * (comb(i, p) / comb(n, p)) for p in range(i + 1))
        out = jnp.abs(b) if out is None else jnp.maximum(out, jnp.abs(b))
    return out


def span_bounds(c, h):
    """Cheap two-sided estimates of the maxima of ``|c|``, ``|c'|``, ``|c''|`` of a quintic
    on ``[0, h]``.

    c: (..., 6) power series in τ ∈ [0, h], h: (...) → ``(L, U)``, each (..., 3). L is the
    largest ``|Q^(k)|`` on a uniform grid of :data:`SAMPLES` sub-intervals (a lower bound of
    the maximum), U a rigorous upper bound: between two grid points ``δ`` apart, an interior
    maximum t* of ``|Q|`` has ``Q'(t*) = 0``, so ``|Q(t*)| − |Q(t_i)| <= M δ²/8`` at the nearest
    grid point, M a bound of ``|Q''|`` on the span (here: the next quantity's U for the value,
    the Bernstein hull of the quadratic jerk for the velocity, the ends of the linear snap for
    the acceleration). Everything is a fixed number of multiply-adds per span, with no
    division but ``1/h``: far cheaper than :func:`span_maxima`, which the caller keeps
    for the spans where ``U − L`` matters.
    """
    terms = [c[..., 0]]
    hp = h
    for p in range(1, 6):  # coefficients in s = τ/h ∈ [0, 1]
        terms.append(c[..., p] * hp)
        hp = hp * h
    ih = 1.0 / h
    mp, mv, ma = SAMPLES
    # the derivatives' coefficients as lists of arrays (the products of poly_derivative,
    # in its order): stacking them on a short last axis made XLA move the spans off the
    # vectorised minor axis
    vel = _derivative_terms(terms)
    acc = _derivative_terms(vel)
    jerk = _derivative_terms(acc)
    snap = _derivative_terms(jerk)
    # the samples are the dear part: computed once (XLA fused them into both results)
    lp, lv, la = materialize(
        (_sampled_max(terms, mp), _sampled_max(vel, mv) * ih, _sampled_max(acc, ma) * ih * ih))
    us = jnp.maximum(jnp.abs(snap[0]), jnp.abs(snap[0] + snap[1])) * ih**4
    uj = _bernstein_max(jerk) * ih**3
    gap = 0.125 * h * h
    ua = la + us * gap / ma**2
    uv = lv + uj * gap / mv**2
    up = lp + ua * gap / mp**2
    return jnp.stack([lp, lv, la], -1), jnp.stack([up, uv, ua], -1)
