"""Defaults of the paper and of ``docs/conventions.md``, written once.

Units everywhere: seconds, millimetres, degrees.

* Poses ``[x, y, z, pitch α, yaw β, roll γ]`` (conventions §1, paper Eq. 34; the goal's Z sign
  is corrected to -1515 as conventions §1 explains).
* Joint order (conventions §4): ``[d_L1, d_L2, d_L3, θ_L, d_R1, d_R2, d_R3, θ_R]``; within one
  arm: axial (task Z), lift (task Y), lateral (task X), roll.
* Limits (paper Table 2, conventions §6) are given per arm joint in that order and apply to
  both arms.
"""

from __future__ import annotations

import math

DEG = math.pi / 180.0
"""Degrees to radians (angles are degrees everywhere but inside trigonometric calls)."""

START: tuple[float, ...] = (775.0, -35.0, -1315.0, 0.2, -0.2, 190.0)
"""Start pose ``P_o`` (paper Eq. 34)."""

GOAL: tuple[float, ...] = (745.0, -5.0, -1515.0, 0.0, 0.0, 180.0)
"""Goal pose ``P_e`` (paper Eq. 34, Z sign corrected per conventions §1)."""

ARM_DISTANCE: float = 2000.0
"""Distance ``D_2`` between the two arm ends in mm (conventions §4; the paper gives none)."""

INTERVAL_BOUNDS: tuple[float, float] = (3.5, 10.0)
"""Bounds of each knot interval ``h_k`` in s (conventions §3)."""

MARGIN: float = 0.1
"""Relative margin ``m_k = 0.1 |Δ_k|`` of the control-point box (conventions §3)."""

ZERO_MOVE_MARGIN: tuple[float, ...] = (1.0, 1.0, 1.0, 0.01, 0.01, 0.01)
"""Box half-margin where ``Δ_k = 0``: 1 mm for positions, 0.01° for angles (conventions §3)."""

# Per arm joint, in the order (axial d1 / task Z, lift d2 / task Y, lateral d3 / task X, roll θ).
TRAVEL: tuple[float, ...] = (600.0, 50.0, 50.0, 15.0)
"""Travel about home, mm or ° (paper Table 2)."""

VELOCITY: tuple[float, ...] = (400.0, 25.0, 2.5, 6.8)
"""|velocity| limits, mm/s or °/s (paper Table 2)."""

ACCELERATION: tuple[float, ...] = (100.0, 100.0, 100.0, 240.0)
"""|acceleration| limits, mm/s² or °/s² (paper Table 2)."""

POSE_NAMES: tuple[str, ...] = ("x", "y", "z", "pitch", "yaw", "roll")
POSE_UNITS: tuple[str, ...] = ("mm", "mm", "mm", "deg", "deg", "deg")
JOINT_NAMES: tuple[str, ...] = ("d_L1", "d_L2", "d_L3", "theta_L", "d_R1", "d_R2", "d_R3", "theta_R")
JOINT_UNITS: tuple[str, ...] = ("mm", "mm", "mm", "deg", "mm", "mm", "mm", "deg")
RATE_SUFFIXES: tuple[str, ...] = ("", "/s", "/s^2", "/s^3")
"""Unit suffix of a quantity's time derivative of order 0..3 (position, velocity, ...)."""


def unit(joint: int, order: int = 0) -> str:
    """The unit of joint ``joint``'s ``order``-th time derivative, e.g. ``"mm/s^2"``."""
    return JOINT_UNITS[joint] + RATE_SUFFIXES[order]


N_INTERVALS = 6
"""Six knot intervals ``h_1..h_6`` (conventions §2)."""
N_FREE = 5
"""Five free control points ``d_3..d_7`` (conventions §2): the paper's family and the default
``n_control`` of :class:`dockjax.DockingProblem`."""
MAX_CONTROL = 64
"""Most free control points a problem takes (``n_control``, 1..64)."""
N_POSE = 6
N_JOINTS = 8
N_VAR = N_INTERVALS + N_FREE * N_POSE  # 36, the paper's family
N_CON = 3 * N_JOINTS  # 24: travel, velocity and acceleration per joint (32 with jerk limits)

# -- the paper's study (§5) and its presets -------------------------------------------------
POP_SIZE = 150
"""Population of every optimiser in the paper's study (§5.2)."""
N_ITER = 100
"""Iterations of every optimiser in the paper's study (§5.2)."""
N_SEEDS = 31
"""Runs per algorithm of the comparison (the paper reports one; 31 give statistics)."""
HV_REFERENCE = 1.1
"""Hypervolume reference point after normalisation by the reference front (conventions §8)."""
PRESETS: dict[str, dict] = {
    "paper": dict(interval_bounds=INTERVAL_BOUNDS),
    "wide": dict(interval_bounds=(0.5, 10.0)),
}
"""Problem presets: ``paper`` (h in [3.5, 10] s, conventions §3) and ``wide`` (h in
[0.5, 10] s, where the velocity limits rather than the interval bounds decide the fast end
of the front)."""
BEST_KNOWN = dict(n_points=150, n_exact=20, steps=600)
"""Settings of the best-known front used as the comparison's reference front."""
MEMETIC_STEPS = 100
"""Gradient-refinement steps of the comparison's "IMOCS + refine" rows."""
PAPER_INDICATORS: dict[str, tuple[float, float, float]] = {
    "nsga2": (150, 0.0065, 0.0049), "mopso": (36, 0.0220, 0.0420), "mocs": (133, 0.0041, 0.0064),
    "imocs": (150, 0.0019, 0.0037),
}
"""ONVG, GD and SP of the paper's one run per algorithm (§5.2), for the comparison's table."""

# -- one certified plan ---------------------------------------------------------------------
RATE = 1000.0
"""Servo rate of a plan's samples (Hz)."""
BYTES_PER_CANDIDATE = 16_384
"""A generous estimate of the working memory one candidate needs while a batch is scored
(float64 kernel intermediates) of the paper's family; the command lines refuse requests whose
estimate exceeds the available memory."""


def candidate_bytes(n_control: int = N_FREE) -> float:
    """:data:`BYTES_PER_CANDIDATE` for a spline of ``n_control`` free control points (the
    kernel's intermediates grow with the ``n_control + 1`` spans)."""
    return BYTES_PER_CANDIDATE * (n_control + 1) / N_INTERVALS
MAX_RATE = 10_000.0
"""Highest servo rate a plan or a tracking simulation accepts (Hz)."""
PLAN_REFINE_STEPS = 300
"""Gradient-refinement steps of an optimiser's front before a plan chooses its point."""
PLAN_FRONT = 8
"""Time caps of the least-jerk front a plan chooses from (besides the shortest time)."""

# -- the sweep (the main job) ---------------------------------------------------------------
SWEEP_RHO: tuple[float, ...] = (0.3, 0.4, 0.5)
SWEEP_ALPHA_MAX: tuple[float, ...] = (0.05, 0.1, 0.2)
SWEEP_SEEDS = 5
SWEEP_ITERS = 50
SWEEP_CHUNK = 40
"""Most runs per compiled call of a sweep."""

# -- the bounds of a request ----------------------------------------------------------------
MAX_COUNT = 2**31 - 1
"""Largest count (iterations, seeds, population, budget, ...) a request may give: the
optimisers count in 32-bit integers."""
MAX_SETTINGS = 100_000
"""Most settings one study may hold."""
MAX_EVALUATIONS = 10**11
"""Most candidate evaluations one study may ask for (about four days at the kernel's
300,000 evaluations a second on two cores)."""
EVALUATIONS_PER_SECOND = 300_000
"""The kernel's throughput on two CPU cores, for the time estimates of refusals."""
