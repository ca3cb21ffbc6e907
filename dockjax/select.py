"""The choice of one solution from a front (paper Eq. 26, conventions §8).

Each point of a front (minimised objectives) gets the weighted satisfaction

    δ = (1/m) Σ_i w_i (f_i,max − f_i) / (f_i,max − f_i,min),

the maxima and minima taken over the given points. δ is a *satisfaction* (1 at the ideal
point, 0 at the nadir), so the chosen point **maximises** it. The paper says "minimised";
minimising δ picks an end of a convex front (the worst point on the weighted objectives),
which contradicts the paper's own Type 2/Type 3 choices, so conventions §8 adopts the maximising
convention.

The paper's three types, with the objectives ordered ``(T, jerk)``:

- Type 1, compromise: ``w = [1, 1]`` (the knee of a convex front);
- Type 2, shortest time: ``w = [1, 0]`` (the minimum-T point);
- Type 3, lowest jerk: ``w = [0, 1]`` (the minimum-jerk point).

Ties are broken by the lowest index. An objective whose values are all equal contributes 0
(its range is taken as 1). Plain NumPy (float64): the choice is made once per front, outside
any compiled loop, and the weights are validated eagerly.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["PAPER_TYPES", "check_weights", "choose", "choose_type", "satisfaction"]

#: Weights of the paper's three solution types (objectives ordered ``(T, jerk)``).
PAPER_TYPES: dict[str, tuple[float, float]] = {
    "compromise": (1.0, 1.0),  # Type 1
    "time": (1.0, 0.0),  # Type 2, shortest time
    "smooth": (0.0, 1.0),  # Type 3, lowest jerk
}


def check_weights(weights: Any, m: int) -> np.ndarray:
    """Validate Eq. 26 weights: a vector of length ``m``, finite, non-negative, not all zero.

    Returns:
        (m,) float64 weights.

    Raises:
        ValueError: naming the first rule broken.
    """
    try:
        w = np.asarray(weights, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"weights must be a vector of {m} numbers, got {weights!r}") from exc
    if w.ndim != 1 or w.shape[0] != m:
        raise ValueError(f"weights must be a vector of length m = {m}, got shape {w.shape}")
    if not np.isfinite(w).all():
        raise ValueError(f"weights must be finite, got {w.tolist()}")
    if (w < 0).any():
        raise ValueError(f"weights must be non-negative, got {w.tolist()}")
    if not (w > 0).any():
        raise ValueError("weights must not all be zero")
    return w


def _check(F: Any, weights: Any, valid: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    F = np.asarray(F, dtype=np.float64)
    if F.ndim != 2:
        raise ValueError(f"F must be a (n, m) array of objective values, got shape {F.shape}")
    n, m = F.shape
    if valid is None:
        valid = np.ones(n, dtype=bool)
    else:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != (n,):
            raise ValueError(f"valid must have shape ({n},), got {valid.shape}")
    if n == 0 or not valid.any():
        raise ValueError("cannot choose from an empty set of points")
    if not np.isfinite(F[valid]).all():
        raise ValueError("F has non-finite values in the rows considered")
    return F, check_weights(weights, m), valid


def satisfaction(F: Any, /, weights: Any, *, valid: Any = None) -> np.ndarray:
    """The weighted satisfaction δ of Eq. 26 for every point.

    Args:
        F: (n, m) objective values of the front, minimised.
        weights: (m,) finite, non-negative, not all zero.
        valid: optional (n,) bool mask; the extremes are taken over the valid rows only.

    Returns:
        (n,) δ in [0, Σ w / m] for valid rows; NaN for masked rows.

    Raises:
        ValueError: bad weights, an empty set, or non-finite values.
    """
    F, w, valid = _check(F, weights, valid)
    fmin = F[valid].min(axis=0)
    fmax = F[valid].max(axis=0)
    span = fmax - fmin
    span = np.where(span > 0, span, 1.0)
    delta = ((fmax - F) / span) @ w / F.shape[1]
    return np.where(valid, delta, np.nan)


def choose(F: Any, /, weights: Any, *, valid: Any = None) -> int:
    """Index of the point maximising the satisfaction δ (Eq. 26; ties: lowest index).

    Args:
        F: (n, m) objective values of the front, minimised.
        weights: (m,) finite, non-negative, not all zero.
        valid: optional (n,) bool mask; the index returned is into F and always valid.

    Returns:
        The row index into F.
    """
    delta = satisfaction(F, weights, valid=valid)
    return int(np.argmax(np.where(np.isnan(delta), -np.inf, delta)))


def choose_type(F: Any, kind: str, /, *, valid: Any = None) -> int:
    """Index of the paper's solution of type ``kind``: ``"compromise"``, ``"time"``, ``"smooth"``.

    ``F`` must have the two objectives ``(T, jerk)``. See :data:`PAPER_TYPES`.
    """
    if kind not in PAPER_TYPES:
        raise ValueError(f"unknown type {kind!r}; choose one of {sorted(PAPER_TYPES)}")
    return choose(F, PAPER_TYPES[kind], valid=valid)
