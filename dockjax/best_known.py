"""The best-known front of a problem: the yardstick of every study (conventions §8).

:func:`best_known_front` is an ε-constraint sweep over ``T`` from the shortest feasible time
to ``(n + 1) h_hi`` (``6 h_hi`` in the paper's family): anchors solved by sequential
quadratic programming (:mod:`dockjax.solve`) and a dense set of caps polished from them by
gradient refinement (:func:`dockjax.refine.polish`).
It never sees any optimiser's front: it depends only on the problem, so it is an
independent yardstick for the optimisers' fronts. :func:`best_known_cached` computes it once
per problem definition and settings and keeps it on disk (:func:`fronts_cache`), keyed by
:func:`best_known_key`; sweeps, comparisons and benchmarks ask it for their reference.

:func:`reference_point` is a fixed hypervolume reference point in objective units, set from
the problem alone before any run (for convergence curves).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from tqdm import tqdm

from . import checks, config
from .io import DamagedFileError, atomic_savez, load_npz
from .metrics import nondominated_points
from .problem import DockingProblem
from .refine import check_settings, polish
from .solve import floor_infeasibility, infeasibility, least_jerk_front, shortest, straight_line

__all__ = ["FrontResult", "best_known_front", "best_known_key", "best_known_cached",
           "fronts_cache", "reference_point", "BEST_KNOWN_FORMAT"]

BEST_KNOWN_FORMAT = 4
"""Version of the best-known front's computation: part of the key of a cached front."""


@dataclass(frozen=True)
class FrontResult:
    """Output of :func:`best_known_front`: the non-dominated feasible points, sorted by T.

    ``X`` (m, n_var), ``F`` (m, 2), ``G`` (m, 24); ``targets`` the swept time caps;
    ``seconds`` the wall time of its computation (compile included).
    """

    X: np.ndarray
    F: np.ndarray
    G: np.ndarray
    targets: np.ndarray
    seconds: float

    def __repr__(self) -> str:
        if not len(self.F):
            return "FrontResult(no points)"
        return (f"FrontResult({len(self.F)} points, T {self.F[0, 0]:.4g}..{self.F[-1, 0]:.4g} s, jerk "
                f"{self.F[-1, 1]:.4g}..{self.F[0, 1]:.4g}; {self.seconds:.1f} s)")


def best_known_front(problem: DockingProblem, *, n_points: int = 150, n_exact: int = 20, line: bool = False,
                     anchor_iter: int = 60, anchor_restarts: int = 0,
                     steps: int = 600, learning_rate: float = 0.05, penalty: float = 10.0,
                     margin: float = 1e-4, rows: int | None = None, progress: bool = False) -> FrontResult:
    """An ε-constraint sweep of T from the shortest feasible time to ``(n + 1) h_hi`` (the
    longest T; ``6 h_hi`` in the paper's family).

    1. The shortest time, and the least jerk at ``n_exact`` caps from it to the longest T
       (quadratically spaced: dense where the front is steep), by sequential quadratic
       programming (:func:`dockjax.solve.shortest`, :func:`dockjax.solve.least_jerk_front`;
       by continuation, and with ``line`` from the straight line too), each anchor's solve
       stopped after ``anchor_iter`` SLSQP iterations and ``anchor_restarts`` restarts
       (:func:`dockjax.solve.min_jerk`): the anchors. Step 2 polishes from them, so fully
       converged anchors are not needed (``python benchmarks/bench_refine.py`` compares
       the defaults with anchors solved to 200 iterations and 3 restarts, time and
       hypervolume, on the paper and wide presets).
    2. ``n_points`` caps evenly spaced over the same range, each started from the anchor
       just below it slowed to the cap (feasible, by exact time scaling) and polished in one
       batch by :func:`dockjax.refine.polish` (``steps``, ``learning_rate``, ``penalty``,
       ``margin``, ``rows`` as there): a dense front at the anchors' quality.

    Returns the kernel-feasible non-dominated points of both, sorted by T; ``targets`` the
    caps of step 2. Computed from the problem alone, without seeing any optimiser's front.
    ``progress``: a bar on stderr counting the ``n_exact + 2`` steps (the shortest time,
    each anchor, the polishing batch).
    Raises ValueError on bad settings and :class:`dockjax.solve.PlanError` (naming the
    limit) when no trajectory of the decision box meets the limits.
    """
    check_settings(problem, steps, learning_rate, penalty, margin, rows)
    checks.integer("n_points", n_points, 2)
    checks.integer("n_exact", n_exact, 2)
    checks.integer("anchor_iter", anchor_iter, 1)
    checks.integer("anchor_restarts", anchor_restarts, 0)
    t0 = time.perf_counter()
    with tqdm(total=int(n_exact) + 2, desc="best-known front", unit="step", disable=not progress, file=sys.stderr,
              leave=False) as bar:
        return _best_known_front(problem, int(n_points), int(n_exact), line, (int(anchor_iter), int(anchor_restarts)),
                                 steps, learning_rate, penalty, margin, rows, bar, t0)


def _best_known_front(problem, n_points, n_exact, line, anchor, steps, learning_rate, penalty, margin, rows, bar, t0):
    n = problem.n_intervals
    if (floor := floor_infeasibility(problem)) is not None:
        raise floor
    bar.set_postfix_str("shortest time")
    fastest = shortest(problem, straight_line(problem, [n * problem.interval_bounds[0]])[0])
    if fastest is None:
        raise infeasibility(problem)
    bar.update()
    bar.set_postfix_str("SQP anchors")
    t_max = n * problem.interval_bounds[1]
    caps = fastest.F[0] + (t_max - fastest.F[0]) * np.linspace(0.0, 1.0, n_exact + 1)[1:] ** 2
    anchors = [fastest] + least_jerk_front(problem, fastest, caps, line=line, max_iter=anchor[0], restarts=anchor[1],
                                                 on_cap=bar.update)
    bar.set_postfix_str(f"refining {n_points} caps")
    TA = np.array([a.F[0] for a in anchors])
    XA = np.array([a.x for a in anchors])
    targets = np.linspace(fastest.F[0], t_max, n_points)
    k = np.clip(np.searchsorted(TA, targets, side="right") - 1, 0, len(TA) - 1)
    X = XA[k].copy()
    X[:, :n] *= (targets / TA[k])[:, None]
    X = np.clip(X, problem.lower, problem.upper)
    xb, _, _, found, _ = polish(problem, X, targets, steps=steps, learning_rate=learning_rate, penalty=penalty,
                                margin=margin, rows=rows)
    bar.update()
    Xf = np.concatenate([XA, xb[found]])
    Ff, Gf = problem.evaluate(Xf, rows=rows)  # the kernel's word
    feas = np.all(Gf <= 0, 1)
    Xf, Ff, Gf = Xf[feas], Ff[feas], Gf[feas]
    _, order = nondominated_points(Ff, return_index=True)  # distinct, sorted by T
    return FrontResult(X=Xf[order], F=Ff[order], G=Gf[order], targets=targets,
                       seconds=time.perf_counter() - t0)


def best_known_key(problem: DockingProblem, **settings) -> str:
    """The identity of a best-known front: the problem's fields, the settings (default
    :data:`dockjax.config.BEST_KNOWN`) and :data:`BEST_KNOWN_FORMAT`, as sorted JSON."""
    settings = {**config.BEST_KNOWN, **settings}
    settings.pop("rows", None)
    return json.dumps({"format": BEST_KNOWN_FORMAT, "problem": problem.identity(), **settings}, sort_keys=True)


def fronts_cache() -> Path:
    """Where best-known fronts are cached: ``$DOCKJAX_FRONTS`` or ``~/.cache/dockjax/fronts``."""
    return Path(os.environ.get("DOCKJAX_FRONTS", Path.home() / ".cache" / "dockjax" / "fronts"))


def best_known_cached(problem: DockingProblem, path=None, log: Callable[[str], None] = print,
                      progress: bool = False, **settings) -> FrontResult:
    """:func:`best_known_front` of ``problem`` (settings default to
    :data:`dockjax.config.BEST_KNOWN`), reused from ``path`` (an ``.npz``; a folder such as
    :func:`fronts_cache`: a file named by the key's hash inside it) when that file was
    written for the same problem and settings (:func:`best_known_key`), else computed —
    with a line to ``log`` before it starts, as it takes a while, and with ``progress`` a
    bar on stderr while it runs — and written there atomically. ``path`` None: computed,
    not stored."""
    key = best_known_key(problem, **settings)
    if path is not None and Path(path).is_dir():
        path = Path(path) / f"best-known-{hashlib.sha256(key.encode()).hexdigest()[:16]}.npz"
    if path is not None and Path(path).exists():
        try:
            d = load_npz(path)
            if str(d["key"]) == key:
                log(f"best-known front: {len(d['F'])} points from {path}")
                return FrontResult(X=d["X"], F=d["F"], G=d["G"], targets=d["targets"], seconds=float(d["seconds"]))
        except (DamagedFileError, KeyError):
            log(f"best-known front: {path} is damaged; computed again")
    options = {**config.BEST_KNOWN, **settings}
    log(f"best-known front: computing ({options['n_exact']} SQP anchors, {options['n_points']} refined time caps; "
        "seconds to a minute, once per problem)")
    front = best_known_front(problem, **options, progress=progress)
    log(f"best-known front: {len(front.F)} points in {front.seconds:.1f} s (compile included)")
    if path is not None:
        atomic_savez(path, {"X": front.X, "F": front.F, "G": front.G, "targets": front.targets,
                            "seconds": front.seconds, "key": np.array(key)})
    return front


def reference_point(problem: DockingProblem) -> np.ndarray:
    """A fixed hypervolume reference point (objective units) for convergence curves, set
    before any run: T = (n + 1) h_max (6 h_max in the paper), and twice the jerk of the straight-line trajectory at the
    shortest intervals (a fast, plain candidate). → (2,)."""
    lo, hi = problem.interval_bounds
    F, _ = problem.evaluate(straight_line(problem, [problem.n_intervals * lo]))
    return np.array([problem.n_intervals * hi, 2 * F[0, 1]])
