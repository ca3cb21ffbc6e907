"""One certified docking trajectory a controller can run (the ``dockjax plan`` command).

:func:`plan` optimises the problem (IMOCS by default), ranks the feasible front by the
weighted satisfaction of Eq. 26 (conventions §8), and certifies the best candidate before anything
is written: the trajectory sampled at the servo rate must respect every limit at every
sample, and the kernel's per-span maxima (conventions §6: rigorous upper bounds, never
understated, in every right-arm treatment) must too. If
the chosen candidate fails, the next best is tried; if none passes, :class:`PlanError`
names the limit that cannot be met.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import config, plots, select
from .io import atomic_write_text
from .metrics import nondominated_points
from .optimize import optimize
from .problem import DockingProblem
from .refine import refine as polish
from .trajectory import Trajectory
from .version import __version__

__all__ = ["PlanError", "Plan", "plan", "load_limits", "write_plan"]


class PlanError(RuntimeError):
    """No candidate passes the certificate; the message names the limit."""


@dataclass
class Plan:
    """A certified trajectory. ``samples``: t (m,), pose (m, 6), position/velocity/
    acceleration/jerk (m, 8) at ``rate`` Hz with a last sample at exactly T."""

    problem: DockingProblem
    trajectory: Trajectory
    x: np.ndarray
    T: float
    jerk: float
    front: np.ndarray
    samples: dict
    rate: float
    weights: tuple
    settings: dict = field(default_factory=dict)

    def margins(self) -> dict:
        """Per joint: max |velocity|, |acceleration|, travel about home (from the samples),
        and certified margins to the limits (from the kernel's G, never understated: within
        5 % of a limit exact for the joints linear in the pose and within the right-arm
        treatment's tolerance for the others; otherwise conservative by at most 1 % of the
        limit)."""
        s, lim = self.samples, self.problem.limits
        G = self.problem.evaluate(self.x[None])[1][0].reshape(8, 3)
        out = {}
        for j, name in enumerate(config.JOINT_NAMES):
            exact = (G[j] + 1.0) * lim[j]
            out[name] = {
                "unit": config.JOINT_UNITS[j],
                "max_abs_velocity": float(np.max(np.abs(s["velocity"][:, j]))),
                "max_abs_acceleration": float(np.max(np.abs(s["acceleration"][:, j]))),
                "max_travel_from_home": float(np.max(np.abs(s["position"][:, j] - self.problem.home[j]))),
                "velocity_limit": float(lim[j, 1]),
                "acceleration_limit": float(lim[j, 2]),
                "travel_limit": float(lim[j, 0]),
                "velocity_margin": float(lim[j, 1] - exact[1]),
                "acceleration_margin": float(lim[j, 2] - exact[2]),
                "travel_margin": float(lim[j, 0] - exact[0]),
            }
        return out


def load_limits(path: str | Path) -> dict:
    """Read limit overrides from a TOML or JSON file: keys ``travel``, ``velocity``,
    ``acceleration`` (4 or 8 numbers) and ``home`` (8 numbers). Unknown keys are refused."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ValueError(f"limits file {path} cannot be read: {exc.strerror or exc}") from None
    try:
        if path.suffix.lower() == ".toml":
            data = tomllib.loads(text)
        else:
            data = json.loads(text)
    except Exception as exc:  # noqa: BLE001 - any parse error is bad input
        kind = path.suffix.lstrip('.').upper() or 'JSON'
        raise ValueError(f"limits file {path} is not valid {kind}: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"limits file {path} must hold a table of limits")
    allowed = {"travel", "velocity", "acceleration", "home"}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ValueError(f"limits file {path}: unknown key(s) {unknown}; allowed {sorted(allowed)}")
    return data


def _sample_violation(problem: DockingProblem, s: dict) -> tuple[float, str]:
    """Largest sampled ``|quantity|/limit − 1`` and its name."""
    lim = problem.limits
    vals = np.stack([
        np.max(np.abs(s["position"] - problem.home), 0) / lim[:, 0],
        np.max(np.abs(s["velocity"]), 0) / lim[:, 1],
        np.max(np.abs(s["acceleration"]), 0) / lim[:, 2],
    ], 1) - 1.0
    j, k = np.unravel_index(np.argmax(vals), vals.shape)
    return float(vals[j, k]), f"{config.JOINT_NAMES[j]} {config.QUANTITIES[k]}"


def plan(problem: DockingProblem | None = None, *, weights=(1.0, 1.0), rate: float = config.RATE,
         pop_size: int = config.POP_SIZE, n_iter: int = config.N_ITER, seed: int = 0, algorithm: str = "imocs",
         refine_steps: int = config.PLAN_REFINE_STEPS) -> Plan:
    """Optimise, polish the front with ``refine_steps`` steps of gradient refinement
    (:mod:`dockjax.refine`; 0: none), choose by Eq. 26 with ``weights`` (w_T, w_jerk), certify, and return
    a Plan.

    Raises ValueError on bad input (before any compilation) and :class:`PlanError` when no
    candidate can meet the limits.
    """
    problem = problem or DockingProblem()
    w = select.check_weights(weights, 2)
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a positive number of samples per second, got {rate!r}")
    res = optimize(algorithm, problem, seeds=[seed], pop_size=pop_size, n_iter=n_iter)
    m = res.front[0]
    if not m.any():
        j = int(np.argmin(res.cv[0]))
        G = res.G[0][j].reshape(8, 3)
        jj, kk = np.unravel_index(np.argmax(G), G.shape)
        raise PlanError(
            f"no feasible trajectory found: the limit {config.JOINT_NAMES[jj]} "
            f"{config.QUANTITIES[kk]} ({problem.limits[jj, kk]:g} "
            f"{config.JOINT_UNITS[jj]}{['', '/s', '/s^2'][kk]}) cannot be met "
            f"(best candidate exceeds it by {100 * G[jj, kk]:.1f} %; T is at most "
            f"{6 * problem.interval_bounds[1]:g} s with interval bounds {problem.interval_bounds})"
        )
    F, X = res.F[0][m], res.X[0][m]
    F, idx = nondominated_points(F, return_index=True)
    X = X[idx]
    if refine_steps:
        r = polish(problem, X, steps=refine_steps)
        keep = r.feasible
        X = np.concatenate([X, r.X[keep & r.improved]])
        F, idx = nondominated_points(np.concatenate([F, r.F[keep & r.improved]]), return_index=True)
        X = X[idx]
    order = np.argsort(-np.asarray(select.satisfaction(F, w)), kind="stable")
    worst = (np.inf, "")
    for j in order:
        traj = problem.decode(X[j])
        s = traj.sample(rate)
        v, name = _sample_violation(problem, s)
        g = problem.evaluate(X[j][None])[1][0]
        if v <= 0 and np.all(g <= 0):
            settings = {"weights": list(map(float, w)), "rate": float(rate), "pop_size": pop_size,
                        "n_iter": n_iter, "seed": seed, "algorithm": algorithm,
                        "refine_steps": int(refine_steps)}
            return Plan(problem, traj, X[j], float(F[j, 0]), float(F[j, 1]), F[np.argsort(F[:, 0])],
                        s, float(rate), tuple(w), settings)
        worst = min(worst, (max(v, float(g.max())), name))
    raise PlanError(f"no candidate passes the certificate; closest fails {worst[1]} by {100 * worst[0]:.2f} %")


def write_plan(p: Plan, out: str | Path) -> list[Path]:
    """Write trajectory.csv, summary.json, front.png and trajectory.png into ``out``
    (each file atomically)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = [p.trajectory.to_csv(out / "trajectory.csv", p.rate)]
    summary = {
        "dockjax_version": __version__,
        "T_s": p.T,
        "jerk": p.jerk,
        "x": p.x.tolist(),
        "front": p.front.tolist(),
        "joints": p.margins(),
        "settings": {**p.settings, "start": p.problem.start.tolist(), "goal": p.problem.goal.tolist(),
                     "arm_distance": p.problem.arm_distance,
                     "interval_bounds": list(p.problem.interval_bounds),
                     "limits": {q: p.problem.limits[:, k].tolist() for k, q in enumerate(config.QUANTITIES)},
                     "home": p.problem.home.tolist()},
    }
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    files.append(out / "summary.json")
    label = p.settings.get("algorithm", "imocs") + ("+refine" if p.settings.get("refine_steps") else "")
    files.append(plots.plot_fronts({label: p.front}, out / "front.png", highlight=(p.T, p.jerk),
                                   title=f"front and chosen point (T = {p.T:.2f} s)"))
    s = p.samples
    files.append(plots.plot_joints(s, p.problem.limits, out / "trajectory.png",
                                   title=f"planned joints, T = {p.T:.2f} s, jerk = {p.jerk:.4g}"))
    return files
