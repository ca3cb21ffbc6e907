"""Truncated Taylor series ("jets") for the right arm's nonlinear joints (conventions §5).

A jet is a sequence of arrays, its normalised Taylor coefficients ``a[k] = a^(k)(t) / k!``
(:func:`terms` splits a stacked jet along its last axis, :func:`stack` joins one). Kept as
separate arrays, every operation is elementwise: XLA fuses the forward pass and, above
all, the reverse pass (a jet stacked along an axis makes every coefficient access a slice,
whose transpose is a pad: hundreds of small unfused ops in a gradient). The right arm's
axial, lift and lateral joints go through ``sin``/``cos`` of the pitch and yaw (conventions
§4), so their derivatives up to the jerk (and beyond, for the Taylor models of the limits)
follow from Taylor-mode arithmetic: the Cauchy product and the classic sine/cosine
recurrences (Griewank & Walther, *Evaluating Derivatives*, §13.2).
"""

from __future__ import annotations

import math

import jax.numpy as jnp

__all__ = ["terms", "stack", "mul", "sin_cos", "sin_cos_near", "derivatives"]

# Taylor coefficients of sin and cos in powers of x² (|x| <= 1.5 after the argument is
# quartered: truncation error below 1e-16).
_SIN = tuple((-1) ** k / math.factorial(2 * k + 1) for k in range(10))
_COS = tuple((-1) ** k / math.factorial(2 * k) for k in range(10))


def sin_cos_near(x, ref_sin, ref_cos):
    """``sin(r + x)`` and ``cos(r + x)`` from ``sin r``, ``cos r`` and a small offset x.

    Polynomial sine and cosine of ``x/4`` (Horner in ``(x/4)²``), doubled twice, then the
    angle-addition formulas: a few multiply-adds instead of two library calls, accurate to
    ~1e-15 for ``|x| <= 6`` rad. Used for pitch and yaw, whose offsets within one knot span
    from the span's middle are small.
    """
    y = 0.25 * x
    y2 = y * y
    s = _SIN[-1]
    c = _COS[-1]
    for k in range(len(_SIN) - 2, -1, -1):
        s = s * y2 + _SIN[k]
        c = c * y2 + _COS[k]
    s = s * y
    for _ in range(2):
        s, c = 2.0 * s * c, 1.0 - 2.0 * s * s
    return ref_sin * c + ref_cos * s, ref_cos * c - ref_sin * s


def terms(a) -> list:
    """The coefficients of a jet stacked along the last axis, as a list."""
    return [a[..., k] for k in range(a.shape[-1])]


def stack(jet):
    """A jet (sequence of coefficient arrays) stacked along a new last axis."""
    return jnp.stack(jnp.broadcast_arrays(*jet), axis=-1)


def mul(a, b) -> list:
    """Cauchy product of two jets of equal order: ``(ab)_k = Σ_j a_j b_{k−j}``."""
    return [sum(a[j] * b[k - j] for j in range(k + 1)) for k in range(len(a))]


def sin_cos(a, s0=None, c0=None) -> tuple[list, list]:
    """Jets of ``sin a`` and ``cos a``: ``s_k = (1/k) Σ_j j a_j c_{k−j}``, ``c_k = −(1/k) Σ_j j a_j s_{k−j}``.

    ``s0``, ``c0``: the values ``sin a_0``, ``cos a_0`` if already known.
    """
    s = [jnp.sin(a[0]) if s0 is None else s0]
    c = [jnp.cos(a[0]) if c0 is None else c0]
    for k in range(1, len(a)):
        s.append(sum(j * a[j] * c[k - j] for j in range(1, k + 1)) / k)
        c.append(-sum(j * a[j] * s[k - j] for j in range(1, k + 1)) / k)
    return s, c


def derivatives(jet):
    """Derivatives ``f^(k) = k! · a_k`` from a jet stacked along the last axis."""
    n = jet.shape[-1]
    return jet * jnp.asarray([math.factorial(k) for k in range(n)], jet.dtype)
