"""Quality indicators of a final set: ONVG, GD, SP, IGD, IGD+ and hypervolume (conventions §8).

Definitions (conventions §10), all for minimisation:

- **ONVG**: the number of distinct non-dominated points among the valid (feasible) rows.
- **GD** (D. A. Van Veldhuizen, "Multiobjective evolutionary algorithms: classifications,
  analyses, and new innovations", PhD thesis, AFIT, 1999):
  ``sqrt(Σ_i d_i²) / n``, ``d_i`` the Euclidean distance of point i to the nearest reference
  point. pymoo's GD is the mean ``d_i`` and moocore's is ``(mean d_i^p)^(1/p)``; neither
  equals this one.
- **SP** (J. R. Schott, "Fault tolerant design using single and multicriteria genetic
  algorithm optimization", MSc thesis, MIT, 1995): ``sqrt(Σ_i (d̄ − d_i)² / (n − 1))``,
  ``d_i`` the L1 distance of point i to the nearest *other* point (pymoo divides by n).
- **IGD**: the mean over reference points of the Euclidean distance to the nearest set point.
- **IGD+** (H. Ishibuchi, H. Masuda, Y. Tanigaki, Y. Nojima, EMO 2015,
  https://doi.org/10.1007/978-3-319-15892-1_8): as IGD with
  ``d+(z, a) = sqrt(Σ_k max(a_k − z_k, 0)²)``, ``z`` a reference point and ``a`` a set point.
- **HV**: the exact 2-D hypervolume of the points that strictly dominate the reference point
  (:func:`hypervolume_2d`).

Every indicator function here is a pure ``jax.numpy`` function of fixed shapes: it jits and
vmaps. Each takes an optional boolean ``valid`` mask — a keyword, except in
:func:`hypervolume_2d` (``F, feasible, ref``) and :func:`indicators` (``F, valid,
ref_front``), where it is positional — so that a fixed-shape population with infeasible or
otherwise invalid rows can be scored inside ``jit``/``vmap``: masked rows are ignored
entirely (their values may be anything, including NaN or inf).
On an empty set (no valid row) GD, SP, IGD and IGD+ are NaN; ONVG and HV are 0. SP of a single
point is 0 (there is no spread to measure).

Precision follows the inputs (float32 by default; float64 under
``with jax.enable_x64(True):``). :func:`indicators` is the NumPy-in/NumPy-out layer: it
normalises by the reference front (conventions §8), computes every indicator in float64 and returns
plain Python numbers.

Shapes: ``n`` set points, ``r`` reference points, ``m`` objectives.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import config, pareto
from .pareto import constrained_dominance

__all__ = [
    "gd",
    "hypervolume_2d",
    "hypervolume",
    "hypervolume_numpy",
    "igd",
    "igd_plus",
    "indicator_values",
    "indicators",
    "nondominated_mask",
    "normalise",
    "onvg",
    "reference_normalisation",
    "sp",
]

#: Names of the indicators returned by :func:`indicators`, in order.
NAMES = ("ONVG", "GD", "SP", "IGD", "IGD+", "HV")


# ----------------------------------------------------------------------------- helpers
def _prepare(F: jax.Array, valid: jax.Array | None, name: str = "F") -> tuple[jax.Array, jax.Array]:
    """F as a float (n, m) array with masked rows zeroed (so NaN/inf cannot leak), and the mask."""
    F = jnp.asarray(F)
    if not jnp.issubdtype(F.dtype, jnp.floating):
        F = F.astype(jnp.result_type(float))
    if F.ndim != 2:
        raise ValueError(f"{name} must be (n, m), got shape {F.shape}")
    if valid is None:
        valid = jnp.ones(F.shape[0], dtype=bool)
    else:
        valid = jnp.asarray(valid, dtype=bool)
        if valid.shape != F.shape[:1]:
            raise ValueError(f"valid must have shape {F.shape[:1]}, got {valid.shape}")
    return jnp.where(valid[:, None], F, 0.0), valid


def _reference(ref: jax.Array, F: jax.Array) -> jax.Array:
    ref = jnp.asarray(ref, dtype=F.dtype)
    if ref.ndim != 2 or ref.shape[1] != F.shape[1] or ref.shape[0] == 0:
        raise ValueError(
            f"ref must be a non-empty (r, {F.shape[1]}) reference set, got shape {ref.shape}"
        )
    return ref


def _sq_dist(A: jax.Array, B: jax.Array) -> jax.Array:
    """(a, b) squared Euclidean distances between the rows of A (a, m) and B (b, m)."""
    diff = A[:, None, :] - B[None, :, :]
    return jnp.sum(diff * diff, axis=-1)


# ------------------------------------------------------------------------ normalisation
def normalise(F: jax.Array, /, *, ideal: jax.Array, nadir: jax.Array) -> jax.Array:
    """``(F − ideal) / (nadir − ideal)``, objective by objective.

    Args:
        F: (..., m) objective values.
        ideal: (m,) lower corner (the reference front's per-objective minimum).
        nadir: (m,) upper corner (the reference front's per-objective maximum).

    Returns:
        (..., m) normalised values; an objective with ``nadir == ideal`` is divided by 1
        (shifted only).
    """
    F = jnp.asarray(F)
    ideal = jnp.asarray(ideal, dtype=F.dtype)
    nadir = jnp.asarray(nadir, dtype=F.dtype)
    span = nadir - ideal
    return (F - ideal) / jnp.where(span == 0, 1.0, span)


def reference_normalisation(
    ref_front: jax.Array, /, *, valid: jax.Array | None = None
) -> tuple[jax.Array, jax.Array]:
    """The ideal and nadir points of a reference front: its per-objective min and max.

    Args:
        ref_front: (r, m) reference front.
        valid: optional (r,) bool mask of the rows to use.

    Returns:
        ``(ideal, nadir)``, each (m,). With no valid row both are NaN.
    """
    R, valid = _prepare(ref_front, valid, name="ref_front")
    valid = valid[:, None]
    ideal = jnp.min(jnp.where(valid, R, jnp.inf), axis=0)
    nadir = jnp.max(jnp.where(valid, R, -jnp.inf), axis=0)
    empty = ~jnp.any(valid)
    return jnp.where(empty, jnp.nan, ideal), jnp.where(empty, jnp.nan, nadir)


# ---------------------------------------------------------------------------- ONVG
def nondominated_mask(
    F: jax.Array, /, *, valid: jax.Array | None = None, unique: bool = True
) -> jax.Array:
    """The valid rows that no other valid row Pareto-dominates.

    Args:
        F: (n, m) objective values, minimised.
        valid: optional (n,) bool mask; masked rows neither count nor dominate.
        unique: keep only the first (lowest-index) copy of exact duplicates.

    Returns:
        (n,) bool mask. O(n² m) work and memory.
    """
    F, valid = _prepare(F, valid)
    cv = jnp.where(valid, 0.0, 1.0).astype(F.dtype)  # masked rows: infeasible, dominate nobody
    D = constrained_dominance(F, cv)  # D[i, j]: i dominates j
    keep = valid & ~jnp.any(D & valid[:, None], axis=0)
    if unique:
        n = F.shape[0]
        same = jnp.all(F[:, None, :] == F[None, :, :], axis=-1)
        earlier = jnp.arange(n)[:, None] < jnp.arange(n)[None, :]  # [i, j]: i < j
        keep = keep & ~jnp.any(same & earlier & keep[:, None], axis=0)
    return keep


def nondominated_points(F, /, *, return_index: bool = False):
    """Distinct non-dominated rows of a 2-objective set F (k, 2), sorted by the first
    objective (NumPy; O(k log k): sort, then keep rows whose second objective beats every
    earlier one). With ``return_index``, also the indices of those rows in F."""
    F = np.asarray(F, dtype=np.float64).reshape(-1, 2)
    U, idx = np.unique(F, axis=0, return_index=True)  # sorted by f0, then f1
    if len(U):
        best = np.minimum.accumulate(U[:, 1])
        keep = np.ones(len(U), bool)
        keep[1:] = U[1:, 1] < best[:-1]
        U, idx = U[keep], idx[keep]
    return (U, idx) if return_index else U


def onvg(F: jax.Array, /, *, valid: jax.Array | None = None) -> jax.Array:
    """Overall non-dominated vector generation: distinct non-dominated valid points.

    Args:
        F: (n, m) objective values, minimised.
        valid: optional (n,) bool mask (e.g. feasibility).

    Returns:
        () int32 count; 0 for an empty set. Exact duplicates count once.
    """
    return jnp.sum(nondominated_mask(F, valid=valid, unique=True), dtype=jnp.int32)


# ---------------------------------------------------------------------- GD, IGD, IGD+
def gd(F: jax.Array, /, ref: jax.Array, *, valid: jax.Array | None = None) -> jax.Array:
    """Van Veldhuizen's generational distance ``sqrt(Σ_i d_i²) / n``.

    Args:
        F: (n, m) set, minimised.
        ref: (r, m) reference front.
        valid: optional (n,) bool mask; ``n`` counts the valid rows only.

    Returns:
        () GD; NaN with no valid row.
    """
    F, valid = _prepare(F, valid)
    ref = _reference(ref, F)
    d2 = jnp.min(_sq_dist(F, ref), axis=1)  # (n,) squared distance to the nearest ref point
    n = jnp.sum(valid)
    total = jnp.sum(jnp.where(valid, d2, 0.0))
    return jnp.where(n > 0, jnp.sqrt(total) / jnp.maximum(n, 1), jnp.nan)


def _inverted(dist: jax.Array, valid: jax.Array) -> jax.Array:
    """Mean over reference points (rows) of the distance to the nearest valid set point."""
    nearest = jnp.min(jnp.where(valid[None, :], dist, jnp.inf), axis=1)
    return jnp.where(jnp.any(valid), jnp.mean(jnp.where(jnp.any(valid), nearest, 0.0)), jnp.nan)


def _inverted_distance(F, ref, valid, plus: bool) -> jax.Array:
    F, valid = _prepare(F, valid)
    ref = _reference(ref, F)
    if plus:  # d+(z, a) = sqrt(Σ_k max(a_k − z_k, 0)²), z in ref, a in F
        excess = jnp.maximum(F[None, :, :] - ref[:, None, :], 0.0)  # (r, n, m)
        return _inverted(jnp.sqrt(jnp.sum(excess * excess, axis=-1)), valid)
    return _inverted(jnp.sqrt(_sq_dist(ref, F)), valid)


def igd(F: jax.Array, /, ref: jax.Array, *, valid: jax.Array | None = None) -> jax.Array:
    """Inverted generational distance of F (n, m) to the reference front ``ref`` (r, m): the
    mean over ``ref`` of the Euclidean distance to the nearest valid point (``valid``: an
    optional (n,) mask). → (); NaN with no valid row. Agrees with ``moocore.igd``."""
    return _inverted_distance(F, ref, valid, plus=False)


def igd_plus(F: jax.Array, /, ref: jax.Array, *, valid: jax.Array | None = None) -> jax.Array:
    """IGD+ (:func:`igd` with ``d+(z, a) = sqrt(Σ_k max(a_k − z_k, 0)²)``, z in ``ref``, a in F).
    → (); NaN with no valid row. Agrees with ``moocore.igd_plus``."""
    return _inverted_distance(F, ref, valid, plus=True)


# ------------------------------------------------------------------------------ SP
def sp(F: jax.Array, /, *, valid: jax.Array | None = None) -> jax.Array:
    """Schott's spacing ``sqrt(Σ_i (d̄ − d_i)² / (n − 1))``, d_i the L1 distance to the
    nearest other valid point.

    Args:
        F: (n, m) set.
        valid: optional (n,) bool mask; ``n`` counts the valid rows only.

    Returns:
        () SP; 0 for a single point, NaN with no valid row. Duplicates are kept (a duplicated
        point has ``d_i = 0``); pass a :func:`nondominated_mask` to score the distinct set.
    """
    F, valid = _prepare(F, valid)
    n_rows = F.shape[0]
    l1 = jnp.sum(jnp.abs(F[:, None, :] - F[None, :, :]), axis=-1)
    other = valid[None, :] & ~jnp.eye(n_rows, dtype=bool)
    d = jnp.min(jnp.where(other, l1, jnp.inf), axis=1)
    n = jnp.sum(valid)
    use = valid & (n >= 2)
    d = jnp.where(use, d, 0.0)
    dbar = jnp.sum(d) / jnp.maximum(n, 1)
    var = jnp.sum(jnp.where(use, (dbar - d) ** 2, 0.0)) / jnp.maximum(n - 1, 1)
    return jnp.where(n >= 2, jnp.sqrt(var), jnp.where(n == 1, 0.0, jnp.nan))


# ------------------------------------------------------------------------------ HV
def hypervolume_2d(F, feasible, ref):
    """Exact 2-D hypervolume (minimisation) of the feasible points of F (n, 2) up to ``ref``.

    Traceable: sort by f1, keep the running minimum of f2, sum the rectangles.
    """
    big = jnp.asarray(jnp.inf, F.dtype)
    f1 = jnp.where(feasible & jnp.all(F < ref, axis=1), F[:, 0], big)
    order = pareto.lexsort((f1,))
    f1s = f1[order]
    f2s = jnp.where(jnp.isfinite(f1s), F[order, 1], ref[1])
    best = jax.lax.cummin(f2s)
    prev = jnp.concatenate([jnp.full((1,), ref[1], F.dtype), best[:-1]])
    width = jnp.where(jnp.isfinite(f1s), ref[0] - f1s, 0.0)
    return jnp.sum(width * jnp.maximum(prev - best, 0.0))


def hypervolume(F: jax.Array, /, ref: Any, *, valid: jax.Array | None = None) -> jax.Array:
    """Exact hypervolume (minimisation) of a 2-objective set up to the reference point.

    Only valid points strictly better than ``ref`` in both objectives contribute.

    Args:
        F: (n, 2) set, minimised.
        ref: (2,) reference point, or a scalar used for both objectives.
        valid: optional (n,) bool mask.

    Returns:
        () hypervolume; 0 when no valid point dominates ``ref``. Agrees with
        ``moocore.hypervolume(F, ref=ref)``.
    """
    F, valid = _prepare(F, valid)
    if F.shape[1] != 2:
        raise ValueError(f"hypervolume is implemented for 2 objectives, got {F.shape[1]}")
    ref = jnp.broadcast_to(jnp.asarray(ref, dtype=F.dtype), (2,))
    return hypervolume_2d(F, valid, ref)


def hypervolume_numpy(F, ref) -> float:
    """NumPy in, float out: :func:`hypervolume` of a (n, 2) set in float64 (inside
    ``jax.enable_x64``; no global flag is changed), in the units of F."""
    with jax.enable_x64(True):
        return float(hypervolume(jnp.asarray(np.asarray(F, dtype=np.float64)), np.asarray(ref, dtype=np.float64)))


# ---------------------------------------------------------------------- all at once
def indicator_values(
    F: jax.Array,
    /,
    ref_front: jax.Array,
    *,
    valid: jax.Array | None = None,
    ideal: jax.Array | None = None,
    nadir: jax.Array | None = None,
    hv_ref: float = config.HV_REFERENCE,
) -> dict[str, jax.Array]:
    """Every indicator of conventions §8 as a traceable function (jit/vmap it).

    The set and the reference front are normalised by ``ideal`` and ``nadir`` (default: the
    reference front's, :func:`reference_normalisation`). The set that is scored is the
    approximation set the final set represents: its distinct non-dominated valid points
    (the points ONVG counts); GD, SP, IGD, IGD+ and HV are computed on it. (Dropping dominated
    points leaves IGD+ and HV unchanged, and GD/SP then describe the front the run returns.)

    Args:
        F: (n, m) final set, minimised.
        ref_front: (r, m) reference front (in the same units as F).
        valid: optional (n,) bool mask (feasible rows).
        ideal, nadir: optional (m,) normalisation; pass fixed ones when runs are scored one at
            a time against a reference fixed beforehand (conventions §8).
        hv_ref: reference point of the hypervolume after normalisation (scalar or (m,)).

    Returns:
        ``{"ONVG", "GD", "SP", "IGD", "IGD+", "HV"}`` -> () arrays (the ONVG one int32).
    """
    F = jnp.asarray(F)
    R = jnp.asarray(ref_front, dtype=F.dtype)
    if ideal is None or nadir is None:
        i0, n0 = reference_normalisation(R)
        ideal = i0 if ideal is None else ideal
        nadir = n0 if nadir is None else nadir
    Fn = normalise(F, ideal=ideal, nadir=nadir)
    Rn = normalise(R, ideal=ideal, nadir=nadir)
    front = nondominated_mask(Fn, valid=valid, unique=True)
    return {
        "ONVG": jnp.sum(front, dtype=jnp.int32),
        "GD": gd(Fn, Rn, valid=front),
        "SP": sp(Fn, valid=front),
        "IGD": igd(Fn, Rn, valid=front),
        "IGD+": igd_plus(Fn, Rn, valid=front),
        "HV": hypervolume(Fn, hv_ref, valid=front),
    }


_indicator_values_jit = jax.jit(indicator_values)


def indicators(
    F: Any,
    valid: Any,
    ref_front: Any,
    *,
    hv_ref: float = config.HV_REFERENCE,
    ideal: Any = None,
    nadir: Any = None,
) -> dict[str, Any]:
    """NumPy in, NumPy out: ONVG, GD, SP, IGD, IGD+ and HV of a final set (conventions §8).

    Computes :func:`indicator_values` in float64 (inside ``jax.enable_x64``; no global flag is
    changed) on objectives normalised by the reference front's ideal and nadir points, with the
    hypervolume reference point ``hv_ref`` (1.1) after normalisation.

    Args:
        F: (n, m) final set, or (..., n, m) a batch of final sets of equal size.
        valid: (n,) / (..., n) bool feasibility mask, or None for all rows.
        ref_front: (r, m) reference front, in the units of F.
        hv_ref: hypervolume reference point after normalisation.
        ideal, nadir: optional fixed normalisation (m,); default the reference front's.

    Returns:
        dict name -> value, in the order of :data:`NAMES`: Python ``int``/``float`` for one set,
        NumPy arrays of the batch
        shape for a batch.
    """
    F = np.asarray(F, dtype=np.float64)
    if F.ndim < 2:
        raise ValueError(f"F must be (n, m) or (..., n, m), got shape {F.shape}")
    valid = np.ones(F.shape[:-1], bool) if valid is None else np.asarray(valid, dtype=bool)
    if valid.shape != F.shape[:-1]:
        raise ValueError(f"valid must have shape {F.shape[:-1]}, got {valid.shape}")
    R = np.asarray(ref_front, dtype=np.float64)
    if R.ndim != 2 or R.shape[1] != F.shape[-1] or R.shape[0] == 0 or not np.isfinite(R).all():
        raise ValueError(f"ref_front must be a finite, non-empty (r, {F.shape[-1]}) array")
    if ideal is None:
        ideal = R.min(axis=0)
    if nadir is None:
        nadir = R.max(axis=0)
    ideal = np.asarray(ideal, dtype=np.float64)
    nadir = np.asarray(nadir, dtype=np.float64)
    hv = np.broadcast_to(np.asarray(hv_ref, dtype=np.float64), (F.shape[-1],))
    with jax.enable_x64(True):
        kw = dict(ideal=ideal, nadir=nadir, hv_ref=hv)
        if F.ndim == 2:
            out = _indicator_values_jit(F, R, valid=valid, **kw)
            return {k: (int(out[k]) if k == "ONVG" else float(out[k])) for k in NAMES}
        batch = F.shape[:-2]
        Fb = F.reshape((-1,) + F.shape[-2:])
        vb = valid.reshape((-1, F.shape[-2]))
        out = _batched(Fb, R, vb, ideal, nadir, hv)
        return {k: np.asarray(out[k]).reshape(batch) for k in NAMES}


@jax.jit
def _batched(F, R, valid, ideal, nadir, hv_ref):
    def one(f, v):
        return indicator_values(f, R, valid=v, ideal=ideal, nadir=nadir, hv_ref=hv_ref)

    return jax.vmap(one)(F, valid)
