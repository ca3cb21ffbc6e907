"""One decoded trajectory: pose and joints with their derivatives at any times, and CSV export.

A :class:`Trajectory` is what :meth:`DockingProblem.decode` returns for one decision vector.
The pose follows the quintic B-spline of conventions §2 (exactly, through its per-span power
series); the joints follow conventions §4 (the right arm's axial, lift and lateral joints by
Taylor-mode arithmetic, :mod:`dockjax.jets`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from . import bspline, checks, config, jets, robot
from .config import DEG as _DEG
from .decoding import decode
from .io import atomic_write_text
from .store import stored_jit

if TYPE_CHECKING:
    from .problem import DockingProblem

__all__ = ["Trajectory", "sample_times", "sample_bucket", "bucket_durations", "COLUMN_SUFFIXES", "csv_header",
           "csv_text"]

COLUMN_SUFFIXES = ("", "_vel", "_acc", "_jerk")
"""Suffix of a joint's column name for its time derivative of order 0..3 (the CSVs)."""


def sample_times(T: float, rate: float) -> np.ndarray:
    """The sample times of a trajectory of duration ``T`` (s) at ``rate`` Hz: ``k / rate``
    for ``k = 0, 1, …`` below T, and a last one at exactly T."""
    rate = checks.rate(rate)
    n = int(np.floor(T * rate + 1e-9))
    t = np.arange(n + 1) / rate
    t = t[t < T - 1e-12]
    return np.append(t, T)


def sample_bucket(m: int) -> int:
    """Times per compiled call for ``m`` times: a power of two, at least 1024, so that one
    compiled program serves every trajectory length of a bucket (the sampling of a
    :class:`Trajectory` and the servo simulation of :func:`dockjax.track.simulate` pad
    to it)."""
    return max(1024, 1 << max(m - 1, 0).bit_length())


def bucket_durations(t_lo: float, t_hi: float, rate: float) -> list[float]:
    """One duration in ``[t_lo, t_hi]`` per :func:`sample_bucket` that trajectories of
    those durations fall in at ``rate`` Hz: sampling one trajectory of each compiles every
    program that sampling any of them needs."""
    lo, hi = (sample_bucket(len(sample_times(t, rate))) for t in (t_lo, t_hi))
    out, b = [], lo
    while b <= hi:
        out.append(min(max((b // 2 + 1) / rate, t_lo), t_hi))
        b *= 2
    return out


@stored_jit
def _jets_at(problem: "DockingProblem", x, t):
    """Pose jets (m, 6, 4) and joint jets (m, n_joints, 4) at times t (m,), orders 0..3."""
    h, u, c = decode(problem, x)
    k = jnp.searchsorted(bspline.interior_knots(u), t, side="right")
    tau = t - u[bspline.DEGREE + k]
    pose = bspline.poly_taylor(jnp.swapaxes(c[k], 1, 2), tau[:, None], 3)  # (m, 6, 4)
    px, py, pz, pa, pb, pg = (pose[:, i] for i in range(6))  # stacked jets (m, 4)
    axis = (jets.stack(u) for u in robot.cabin_axis_jets(jets.terms(_DEG * pa), jets.terms(_DEG * pb)))
    joints = jnp.stack(problem.joint_values(px, py, pz, pg, *axis), axis=1)
    return jets.derivatives(pose), jets.derivatives(joints)


class Trajectory:
    """The trajectory of one candidate (use :meth:`DockingProblem.decode`).

    Attributes: ``x`` (n_var,), ``T`` (s), ``intervals`` (n + 1,), ``knots`` (n + 12,),
    ``control_points`` (n + 6, 6), ``problem``; n = ``problem.n_control`` (5 in the paper).
    """

    def __init__(self, problem: "DockingProblem", x: np.ndarray):
        self.problem = problem
        self.x = np.asarray(x, dtype=np.float64)
        self.intervals = self.x[: problem.n_intervals].copy()
        self.T = float(np.sum(self.intervals))
        self.knots = np.concatenate(
            [np.zeros(6), np.cumsum(self.intervals)[:-1], np.full(6, self.T)]
        )
        if problem.reduced:
            with jax.enable_x64(True):
                interior = np.asarray(bspline.line_control_points(problem.start, problem.goal, problem.n_control))
        else:
            interior = self.x[problem.n_intervals :].reshape(problem.n_control, config.N_POSE)
        with jax.enable_x64(True):
            self.control_points = np.asarray(bspline.control_points(problem.start, problem.goal, interior,
                                                                    self.intervals, problem.boundary))

    def __repr__(self) -> str:
        return f"Trajectory(T={self.T:.6g} s, intervals={np.round(self.intervals, 6).tolist()})"

    def _times(self, t) -> np.ndarray:
        arr = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if arr.ndim != 1:
            raise ValueError(f"t must be a scalar or 1-D array of times, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError("t must be finite")
        tol = 1e-9 * max(1.0, self.T)
        if np.any(arr < -tol) or np.any(arr > self.T + tol):
            raise ValueError(f"t must lie in [0, T] = [0, {self.T:.9g}] s, got [{arr.min()}, {arr.max()}]")
        return np.clip(arr, 0.0, self.T)

    def _jets(self, t):
        """Pose and joint jets at t (m,), in calls of :func:`sample_bucket` times (padded
        with the last time) so that one compiled program serves many trajectory lengths."""
        m = len(t)
        size = sample_bucket(m)
        tp = np.concatenate([t, np.full(size - m, t[-1] if m else 0.0)])
        with jax.enable_x64(True):
            pose, joints = _jets_at(self.problem, jnp.asarray(self.x), jnp.asarray(tp))
        return np.asarray(pose)[:m], np.asarray(joints)[:m]

    def _eval(self, t, derivative: int):
        if derivative not in (0, 1, 2, 3):
            raise ValueError(f"derivative must be 0, 1, 2 or 3, got {derivative!r}")
        pose, joints = self._jets(self._times(t))
        return pose[..., derivative], joints[..., derivative]

    def pose(self, t, derivative: int = 0) -> np.ndarray:
        """Pose ``[x, y, z, α, β, γ]`` (or its ``derivative``-th time derivative) at t: (m, 6)."""
        return self._eval(t, derivative)[0]

    def joints(self, t, derivative: int = 0) -> np.ndarray:
        """The joints (conventions §4 order; 8, or 4 per support) or a time derivative (0..3)
        at t: (m, n_joints)."""
        return self._eval(t, derivative)[1]

    def sample_times(self, rate: float) -> np.ndarray:
        """Times ``k / rate`` for ``k = 0, 1, …`` up to T, and a last one at exactly T."""
        return sample_times(self.T, rate)

    def at(self, t) -> dict[str, np.ndarray]:
        """The state at times ``t`` (m,) in [0, T] s: ``t``, ``pose`` (m, 6) and, per joint,
        ``position``, ``velocity``, ``acceleration``, ``jerk`` (m, 8)."""
        t = self._times(t)
        pose, joints = self._jets(t)
        out = {"t": t, "pose": pose[..., 0]}
        for k, name in enumerate(robot.DERIVATIVES):
            out[name] = joints[..., k]
        return out

    def sample(self, rate: float) -> dict[str, np.ndarray]:
        """:meth:`at` the :meth:`sample_times` (``rate`` Hz, a last sample at exactly T)."""
        return self.at(self.sample_times(rate))

    def csv_header(self) -> list[str]:
        """The columns of :meth:`to_csv` (:func:`csv_header`)."""
        return csv_header(self.problem.n_joints)

    def to_csv(self, path: str | os.PathLike, rate: float) -> Path:
        """Write time, pose and each joint's position, velocity, acceleration and jerk,
        sampled at ``rate`` Hz with a last row at exactly T, to ``path`` (atomically)."""
        path = Path(path)
        atomic_write_text(path, csv_text(self.sample(rate)))
        return path


def csv_header(n_joints: int = config.N_JOINTS) -> list[str]:
    """The columns of a trajectory CSV: time, the pose, and each joint's position,
    velocity, acceleration and jerk, units in brackets; ``n_joints``: 8 (the paper's arms)
    or 4 per support (:func:`dockjax.robot.support_joints`)."""
    cols = ["t [s]"] + [f"{n} [{u}]" for n, u in zip(config.POSE_NAMES, config.POSE_UNITS)]
    for name, unit in ((j.name, j.unit) for j in robot.support_joints(n_joints // 4)):
        cols += [f"{name}{s} [{unit}{p}]" for s, p in zip(COLUMN_SUFFIXES, config.RATE_SUFFIXES)]
    return cols


def csv_text(samples: dict) -> str:
    """Samples (:meth:`Trajectory.sample`'s keys) as CSV text under :func:`csv_header`."""
    s = samples
    per_joint = np.stack([s[k] for k in robot.DERIVATIVES], -1)
    table = np.concatenate([s["t"][:, None], s["pose"], per_joint.reshape(len(s["t"]), -1)], 1)
    row = ",".join(["%.17g"] * table.shape[1])
    return "\n".join([",".join(csv_header(per_joint.shape[1])), *(row % tuple(r) for r in table.tolist())]) + "\n"
