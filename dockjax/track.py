"""Servo tracking of a planned trajectory in simulation (the paper's §6 experiment).

Each joint of a plan is followed by its own drive and digital servo loop at the controller
rate; :func:`track` reports the largest position and velocity tracking errors per joint, as
the paper does for its X- and Z-axis moves (:data:`PAPER_MOVES`, :data:`PAPER_ERRORS`).

**Plant** (one joint, :class:`AxisModel`), normalised so that every quantity is in joint
units (mm or °) and seconds::

    m ẍ + b ẋ + f_c sign(ẋ) = u

``u`` is the drive command as an acceleration (joint units/s²): the acceleration it would
give the nominal inertia. ``m`` is the effective inertia relative to that nominal
(dimensionless), ``b`` the viscous damping (1/s) and ``f_c`` the Coulomb friction (joint
units/s²), with stiction: at rest the joint stays at rest while ``|u| ≤ f_c``.

**Integration.** ``u`` is held constant between controller ticks (zero-order hold), so on
each tick the plant is a linear system with a constant input as long as the sign of ``ẋ``
does not change. :func:`plant_step` integrates it *exactly* (closed form, no sub-steps): it
finds the instant, if any, at which the velocity reaches zero, then either sticks (``|u| ≤
f_c``) or slides on in the other direction for the rest of the tick. With ``f_c = 0`` the
step is the exact zero-order-hold discretisation of the linear plant.

**Controller** (at tick ``k``, period ``h = 1/rate``)::

    y_k  = x_0 + q round((x_k − x_0) / q)          encoder, resolution q (q = 0: exact),
                                                    zeroed at the initial position
    e_k  = r_k − y_k,    I_k = I_{k−1} + h e_k     position error and its integral
    ė_k  = F[(e_k − e_{k−1}) / h]                  its rate by differencing (0 at k = 0)
    u_k  = m̂ k_a a_ref,k + b̂ k_v v_ref,k + K_p e_k + K_i I_k + K_d ė_k

with the reference ``r``, ``v_ref``, ``a_ref`` of the plan at the tick. ``F`` is a
first-order low-pass ``w_k = w_{k−1} + α (z_k − w_{k−1})``, ``α = 1 − e^{−h/τ}`` (``τ = 0``:
no filter); the measured velocity reported beside the true one is ``F[(y_k − y_{k−1}) / h]``.
The rate of the error differences the reference as it differences the measurement, so a
loop that tracks exactly sees ``ė = 0`` (differencing the measurement alone against
``v_ref`` would lag it by half a tick, a false error of ``a h / 2``). The controller's
model ``m̂ = m (1 + δ_m)``, ``b̂ = b (1 + δ_b)`` differs from the plant by the model errors
(5 % by default), so the feed-forward is slightly wrong and the errors are nonzero. Unless
given, the PID gains place the poles of the controller's continuous-time model
``m̂ s² + b̂ s`` with PID at ``−ω`` and ``ω(−ζ ± j√(1−ζ²))``, ``ω = 2π f_bw``::

    K_d = (2ζ + 1) ω m̂ − b̂,   K_p = (2ζ + 1) ω² m̂,   K_i = ω³ m̂.

:func:`check_model` refuses a model whose linear closed loop (``f_c = 0``, exact encoder;
plant discretised exactly with zero-order hold) has a pole with ``|z| ≥ 1``.

Everything is deterministic: there is no random noise (the encoder quantisation is the only
measurement error). The loop of every joint runs in one compiled ``jax.lax.scan`` over the
ticks, vectorised over the joints, in float64 (inside ``jax.enable_x64``; no global flag
is changed).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg

from . import checks, config, plots
from .io import atomic_write_text, write_set
from .pytrees import pytree_dataclass
from .trajectory import Trajectory, sample_bucket

__all__ = ["AxisModel", "TrackResult", "PAPER_MOVES", "PAPER_ERRORS", "PAPER_JOINTS", "check_model",
           "closed_loop_poles", "gains", "plant_step", "simulate", "track", "moving_joints", "write_tracking"]

PAPER_MOVES: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {
    "x": ((4.04, -5.0, -1515.0, 0.0, 0.0, 180.0), (-1.514, -5.0, -1515.0, 0.0, 0.0, 180.0)),
    "z": ((745.0, -5.0, -1591.03, 0.0, 0.0, 180.0), (745.0, -5.0, -1601.47, 0.0, 0.0, 180.0)),
}
"""The paper's two §6 tracking moves as ``(start, goal)`` poses ``[x, y, z, pitch, yaw, roll]``
(mm, °), for ``DockingProblem(start=..., goal=...)``: X from 4.04 to −1.514 mm and Z from
−1591.03 to −1601.47 mm."""

PAPER_ERRORS: dict[str, tuple[float, float]] = {"x": (0.014, 0.465), "z": (0.018, 0.364)}
"""The paper's measured (real hardware) max tracking errors of each move: (position mm,
velocity mm/s)."""

PAPER_JOINTS: dict[str, int] = {"x": 2, "z": 0}
"""The joint each move drives (index in the joint order): X → the lateral joint ``d_L3 = −x``,
Z → the axial joint ``d_L1 = −z`` (:func:`dockjax.robot.arm_joints`). The right arm's
``d_R3 = −(x + D_2 u_x)`` and ``d_R1 = z + D_2 u_z`` move by the same amounts (the cabin axis
does not turn)."""

_FIELDS = ("mass", "damping", "friction", "mass_error", "damping_error", "bandwidth", "damping_ratio", "kp", "ki",
           "kd", "ka_ff", "kv_ff", "resolution", "velocity_filter")


@pytree_dataclass
class AxisModel:
    """One joint's drive and servo loop (see the module docstring for the equations).

    Every field is a number (the same for every joint) or a 1-D array with one value per
    joint (the annotations name the number); all are pytree leaves. Units: joint units (mm
    or °) and seconds. ``dockjax track`` takes every field as an option (``--mass``, ...).
    """

    mass: float = 1.0
    """``m``: effective inertia relative to the nominal (dimensionless, > 0)."""
    damping: float = 2.0
    """``b``: viscous damping (1/s, ≥ 0): a mechanical time constant m/b of 0.5 s."""
    friction: float = 1.0
    """``f_c``: Coulomb friction (joint units/s², ≥ 0): 1 % of Table 2's 100 mm/s²."""
    mass_error: float = 0.05
    """``δ_m``: the controller's inertia estimate is ``m̂ = m (1 + δ_m)`` (> −1)."""
    damping_error: float = 0.05
    """``δ_b``: the controller's damping estimate is ``b̂ = b (1 + δ_b)`` (> −1)."""
    bandwidth: float = 10.0
    """``f_bw``: closed-loop bandwidth of the default gains (Hz, > 0), 1/100 of the 1 kHz
    servo rate."""
    damping_ratio: float = 0.7
    """``ζ`` of the default gains' complex pole pair (> 0)."""
    kp: float | None = None
    """``K_p`` (1/s², ≥ 0); None: from the bandwidth."""
    ki: float | None = None
    """``K_i`` (1/s³, ≥ 0); None: from the bandwidth."""
    kd: float | None = None
    """``K_d`` (1/s, ≥ 0); None: from the bandwidth."""
    ka_ff: float = 1.0
    """``k_a``: acceleration feed-forward gain (≥ 0; 0: none)."""
    kv_ff: float = 1.0
    """``k_v``: velocity feed-forward gain (≥ 0; 0: none)."""
    resolution: float = 1e-4
    """``q``: encoder resolution (joint units, ≥ 0; 0: exact measurement); 0.1 µm on the
    linear joints."""
    velocity_filter: float = 0.0
    """``τ``: time constant (s, ≥ 0) of the low-pass on the differenced error (and measured
    velocity); 0: none."""


def gains(model: AxisModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(K_p, K_i, K_d)`` of the model: the given ones, or those from its bandwidth (placed
    on the controller's model ``m̂, b̂``). Each () or (n,), float64; not validated."""
    m_hat = np.asarray(model.mass, np.float64) * (1 + np.asarray(model.mass_error, np.float64))
    b_hat = np.asarray(model.damping, np.float64) * (1 + np.asarray(model.damping_error, np.float64))
    w = 2 * math.pi * np.asarray(model.bandwidth, np.float64)
    c = 2 * np.asarray(model.damping_ratio, np.float64) + 1
    derived = (c * w**2 * m_hat, w**3 * m_hat, c * w * m_hat - b_hat)
    given = (model.kp, model.ki, model.kd)
    return tuple(np.asarray(d if g is None else g, np.float64) for g, d in zip(given, derived))


def _resolve(model: AxisModel, n: int | None = None) -> dict[str, np.ndarray]:
    """The model's per-joint parameters, validated: name → (n,) float64 (n: the common length
    of the fields, 1 if all are numbers, or the given one)."""
    if not isinstance(model, AxisModel):
        raise ValueError(f"model must be an AxisModel, got {type(model).__name__}")
    rules = dict(mass=(0, True), damping=(0, False), friction=(0, False), mass_error=(-1, True),
                 damping_error=(-1, True), bandwidth=(0, True), damping_ratio=(0, True), ka_ff=(0, False),
                 kv_ff=(0, False), resolution=(0, False), velocity_filter=(0, False))
    values = {}
    for name in _FIELDS:
        v = getattr(model, name)
        if v is None and name in ("kp", "ki", "kd"):
            continue
        lo, open_lo = rules.get(name, (0, False))
        arr = checks.numbers(f"model.{name}", v, lo, open_lo=open_lo)
        if arr.ndim > 1:
            raise ValueError(f"model.{name} must be a number or one number per joint, got shape {arr.shape}")
        values[name] = arr
    lengths = {a.shape[0] for a in values.values() if a.ndim == 1}
    if len(lengths - {1} - ({n} if n else set())) > (0 if n else 1):
        parts = ", ".join(f"{k}: {a.shape[0]}" for k, a in values.items() if a.ndim == 1)
        raise ValueError(f"model fields have different numbers of joints ({parts}"
                         f"{'' if n is None else f'; the samples have {n}'})")
    size = n or max(lengths, default=1)
    kp, ki, kd = gains(model)
    for name, g in zip(("kp", "ki", "kd"), (kp, ki, kd)):
        if getattr(model, name) is None:
            arr = np.asarray(g)
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ValueError(f"model.{name} derived from the bandwidth is {arr.tolist()!r}, not >= 0 "
                                 f"(the damping estimate exceeds (2ζ + 1) ω m̂): give model.{name} or raise "
                                 "model.bandwidth")
        values[name] = np.asarray(g)
    out = {k: np.broadcast_to(v, (size,)).astype(np.float64) for k, v in values.items()}
    out["mass_hat"] = out["mass"] * (1 + out["mass_error"])
    out["damping_hat"] = out["damping"] * (1 + out["damping_error"])
    return out


def _loop_matrix(p: dict[str, np.ndarray], j: int, h: float) -> np.ndarray:
    """The linear closed loop of joint j (``f_c = 0``, exact encoder, zero reference, so
    ``e = −y``) as the map of the state ``[x_k, v_k, y_{k−1}, −ė_{k−1}, I_{k−1}]`` to the
    next one. (5, 5)."""
    m, b = p["mass"][j], p["damping"][j]
    A = np.zeros((3, 3))
    A[0, 1], A[1, 1], A[1, 2] = 1.0, -b / m, 1.0 / m
    E = scipy.linalg.expm(A * h)  # exact zero-order hold: [[Φ, Γ], [0, 1]]
    Phi, Gam = E[:2, :2], E[:2, 2]
    tau = p["velocity_filter"][j]
    alpha = 1.0 if tau == 0 else -math.expm1(-h / tau)
    kp, ki, kd = p["kp"][j], p["ki"][j], p["kd"][j]
    # rows give, from the state s: y_k = x_k, v̂_k, I_k, u_k
    y = np.array([1.0, 0, 0, 0, 0])
    vf = alpha * (y - np.array([0, 0, 1.0, 0, 0])) / h + (1 - alpha) * np.array([0, 0, 0, 1.0, 0])
    integral = np.array([0, 0, 0, 0, 1.0]) - h * y
    u = -kp * y + ki * integral - kd * vf
    M = np.zeros((5, 5))
    M[:2] = Phi @ np.eye(5)[:2] + np.outer(Gam, u)
    M[2], M[3], M[4] = y, vf, integral
    return M


def closed_loop_poles(model: AxisModel, rate: float = config.RATE) -> np.ndarray:
    """The discrete-time poles of each joint's linear closed loop at ``rate`` Hz (friction
    and quantisation left out; plant discretised exactly with zero-order hold): (n, 5)
    complex, n the model's number of joints (1 if every field is a number)."""
    rate = checks.rate(rate)
    p = _resolve(model)
    n = p["mass"].shape[0]
    return np.stack([np.linalg.eigvals(_loop_matrix(p, j, 1.0 / rate)) for j in range(n)])


def check_model(model: AxisModel, rate: float = config.RATE, n_joints: int | None = None) -> float:
    """Validate ``model`` at ``rate`` Hz (for ``n_joints`` joints if given): ValueError naming
    the field for a bad value, naming ``rate`` unless ``0 < rate ≤ config.MAX_RATE``, and
    saying "unstable" if a joint's linear closed loop has a pole with ``|z| ≥ 1``. Returns
    the largest ``|z|`` over the joints."""
    rate = checks.rate(rate)
    p = _resolve(model, n_joints)
    radii = np.array([np.max(np.abs(np.linalg.eigvals(_loop_matrix(p, j, 1.0 / rate))))
                      for j in range(p["mass"].shape[0])])
    if not np.all(radii < 1):  # NaN counts as unstable
        j = int(np.argmax(np.where(np.isnan(radii), np.inf, radii)))
        names = config.JOINT_NAMES if len(radii) == config.N_JOINTS else None
        which = f"joint {names[j]}" if names else f"joint {j}"
        raise ValueError(f"the closed loop of {which} is unstable at {rate:g} Hz: largest |z| = {radii[j]:.9g} "
                         "(>= 1); lower the gains or the bandwidth, or raise the rate")
    return float(np.max(radii))


# -- the plant ------------------------------------------------------------------------------

_SERIES_TERMS = 14


def _phi_psi(a, t):
    """``φ(t) = ∫_0^t e^{−as} ds`` and ``ψ(t) = ∫_0^t φ``, stable for ``a t → 0`` (series
    below 0.5, closed form above)."""
    z = a * t
    small = z < 0.5
    zs = jnp.where(small, z, 0.0)
    s1 = s2 = jnp.zeros_like(z)
    for n in range(_SERIES_TERMS - 1, -1, -1):  # Horner: Σ (−z)^n/(n+1)!, Σ (−z)^n/(n+2)!
        s1 = 1.0 / math.factorial(n + 1) - zs * s1
        s2 = 1.0 / math.factorial(n + 2) - zs * s2
    a_safe = jnp.where(small, 1.0, a)
    phi_closed = -jnp.expm1(-z) / a_safe
    psi_closed = (t - phi_closed) / a_safe
    return jnp.where(small, t * s1, phi_closed), jnp.where(small, t * t * s2, psi_closed)


def _slide(x, v, g, a, t):
    """Exact solution after t of ``ẋ = v, v̇ = g − a v`` from (x, v)."""
    phi, psi = _phi_psi(a, t)
    return x + v * phi + g * psi, v * jnp.exp(-a * t) + g * phi


def plant_step(x, v, u, dt, mass, damping, friction):
    """The plant ``m ẍ + b ẋ + f_c sign(ẋ) = u`` integrated exactly over ``dt`` (s) with the
    command ``u`` held: position and velocity after the step. Any broadcastable shapes.

    While the velocity keeps its sign the friction is the constant ``−f_c sign(ẋ)``; when
    it reaches zero the joint sticks if ``|u| ≤ f_c`` and otherwise slides on the other way
    (at most two phases per step, since ``u`` is constant). From rest it moves only if
    ``|u| > f_c``.
    """
    a = damping / mass
    moving = v != 0
    s = jnp.where(moving, jnp.sign(v), jnp.where(jnp.abs(u) > friction, jnp.sign(u), 0.0))
    g = jnp.where(s == 0, 0.0, (u - friction * s) / mass)
    crosses = moving & (g * s < 0)
    ratio = jnp.abs(v) / jnp.where(crosses, jnp.abs(g), 1.0)  # |v| / |g|: the stop time when a = 0
    z = a * ratio
    stop = ratio * jnp.where(z > 1e-4, jnp.log1p(z) / jnp.where(z > 1e-4, z, 1.0), 1 - z / 2 + z * z / 3)
    stops = crosses & (stop < dt)
    t1 = jnp.where(stops, stop, dt)
    x1, v1 = _slide(x, v, g, a, t1)
    s2 = jnp.where(jnp.abs(u) > friction, jnp.sign(u), 0.0)
    g2 = jnp.where(s2 == 0, 0.0, (u - friction * s2) / mass)
    x2, v2 = _slide(x1, jnp.zeros_like(v1), g2, a, jnp.where(stops, dt - t1, 0.0))
    return jnp.where(stops, x2, x1), jnp.where(stops, v2, v1)


# -- the loop ---------------------------------------------------------------------------------


def _loop(p, x0, ref, vel, acc, dt_prev, dt):
    """Every joint's servo loop over the ticks: p name → (n,); x0 (n,); ref, vel, acc (M, n)
    at the ticks; dt_prev, dt (M,) the lengths of the previous and the next tick. Returns
    the true position and velocity, the measured position and velocity at the ticks (M, n)."""
    q = p["resolution"]
    exact = q == 0
    q_safe = jnp.where(exact, 1.0, q)
    tau = p["velocity_filter"]
    tau_safe = jnp.where(tau > 0, tau, 1.0)

    def tick(carry, inputs):
        x, v, y_prev, e_prev, vf, edf, integral = carry
        r, vr, ar, hp, h = inputs
        y = jnp.where(exact, x, x0 + q * jnp.round((x - x0) / q_safe))
        e = r - y
        started = hp > 0
        hp_safe = jnp.where(started, hp, 1.0)
        alpha = jnp.where(tau > 0, -jnp.expm1(-hp / tau_safe), 1.0)
        vf = vf + alpha * (jnp.where(started, (y - y_prev) / hp_safe, 0.0) - vf)
        edf = edf + alpha * (jnp.where(started, (e - e_prev) / hp_safe, 0.0) - edf)
        integral = integral + h * e
        u = (p["mass_hat"] * p["ka_ff"] * ar + p["damping_hat"] * p["kv_ff"] * vr
             + p["kp"] * e + p["ki"] * integral + p["kd"] * edf)
        xn, vn = plant_step(x, v, u, h, p["mass"], p["damping"], p["friction"])
        return (xn, vn, y, e, vf, edf, integral), (x, v, y, vf)

    zero = jnp.zeros_like(x0)
    init = (x0, zero, x0, ref[0] - x0, zero, zero, zero)
    _, out = jax.lax.scan(tick, init, (ref, vel, acc, dt_prev, dt), unroll=8)
    return out


_loop_jit = jax.jit(_loop)


def _check_samples(samples: Any, rate: float) -> tuple[np.ndarray, ...]:
    if not isinstance(samples, dict):
        raise ValueError(f"samples must be a dict with t, position, velocity, acceleration, got "
                         f"{type(samples).__name__}")
    missing = [k for k in ("t", "position", "velocity", "acceleration") if k not in samples]
    if missing:
        raise ValueError(f"samples lack {', '.join(missing)}")
    t = checks.numbers("samples['t']", samples["t"])
    if t.ndim != 1 or t.size < 1:
        raise ValueError(f"samples['t'] must be a 1-D array of times, got shape {t.shape}")
    arrays = []
    for k in ("position", "velocity", "acceleration"):
        a = checks.numbers(f"samples[{k!r}]", samples[k])
        if a.ndim != 2 or a.shape[0] != t.size or a.shape[1] < 1:
            raise ValueError(f"samples[{k!r}] must have shape (m, n_joints) with m = {t.size}, got {a.shape}")
        arrays.append(a)
    if len({a.shape for a in arrays}) > 1:
        raise ValueError(f"samples' position, velocity and acceleration differ in shape: "
                         f"{[a.shape for a in arrays]}")
    h = 1.0 / rate
    d = np.diff(t)
    if d.size and (np.any(np.abs(d[:-1] - h) > 1e-6 * h) or not 0 < d[-1] <= h * (1 + 1e-6)):
        raise ValueError(f"samples['t'] must be spaced 1/rate = {h:.9g} s apart (the last step may be shorter), "
                         f"got steps from {d.min():.9g} to {d.max():.9g} s")
    return (t, *arrays)


def simulate(samples: dict, model: AxisModel = AxisModel(), rate: float = config.RATE) -> dict[str, np.ndarray]:
    """Track planned samples with every joint's servo loop.

    ``samples``: ``t`` (m,) the controller ticks ``t_0 + k/rate`` (the last step may be
    shorter, as in :meth:`dockjax.Trajectory.sample`), ``position``, ``velocity``,
    ``acceleration`` (m, n) the plan at the ticks (joint units, /s, /s²). Every joint starts
    at rest at its planned initial position. Returns, at the ticks, (m, n) float64 each:
    ``position`` and ``velocity`` (true plant state), ``measured_position`` (encoder) and
    ``measured_velocity`` (the encoder's differences, filtered by the model's low-pass).
    """
    rate = checks.rate(rate)
    t, ref, vel, acc = _check_samples(samples, rate)
    m, n = ref.shape
    check_model(model, rate, n)
    p = _resolve(model, n)
    size = sample_bucket(m)
    h = np.full(size, 0.0)
    h[: m - 1] = 1.0 / rate
    if m > 1:
        h[m - 2] = t[-1] - t[-2]
    hp = np.concatenate([[0.0], h[:-1]])
    pad = lambda a: np.concatenate([a, np.repeat(a[-1:], size - m, 0)])  # noqa: E731
    with jax.enable_x64(True):
        out = _loop_jit({k: jnp.asarray(v) for k, v in p.items()}, jnp.asarray(ref[0]), jnp.asarray(pad(ref)),
                        jnp.asarray(pad(vel)), jnp.asarray(pad(acc)), jnp.asarray(hp), jnp.asarray(h))
        out = [np.asarray(a)[:m] for a in out]
    return dict(zip(("position", "velocity", "measured_position", "measured_velocity"), out))


@pytree_dataclass
class TrackResult:
    """A tracked plan (:func:`track`). ``t`` (m,) s; ``planned_position``,
    ``planned_velocity``, ``position``, ``velocity`` (true plant), ``measured_velocity``
    (what the controller sees) (m, n) joint units and /s; ``max_position_error``,
    ``max_velocity_error`` (true velocity), ``max_measured_velocity_error`` (n,), absolute,
    joint units and /s; the ``model`` and the ``rate`` (Hz)."""

    t: Any
    planned_position: Any
    planned_velocity: Any
    position: Any
    velocity: Any
    measured_velocity: Any
    max_position_error: Any
    max_velocity_error: Any
    max_measured_velocity_error: Any
    model: AxisModel
    rate: Any

    @property
    def position_error(self) -> np.ndarray:
        """Tracked minus planned position (m, n)."""
        return self.position - self.planned_position

    @property
    def velocity_error(self) -> np.ndarray:
        """Tracked (true) minus planned velocity (m, n)."""
        return self.velocity - self.planned_velocity


def track(trajectory_or_samples: Trajectory | dict, model: AxisModel = AxisModel(),
          rate: float = config.RATE) -> TrackResult:
    """Simulate the servo tracking of a plan (the paper's §6 experiment) and its max errors.

    ``trajectory_or_samples``: a :class:`dockjax.Trajectory` (sampled at ``rate`` Hz) or a
    samples dict as :func:`simulate` takes (e.g. ``Plan.samples`` at the same rate).
    """
    rate = checks.rate(rate)
    if isinstance(trajectory_or_samples, Trajectory):
        samples = trajectory_or_samples.sample(rate)
    else:
        samples = trajectory_or_samples
    out = simulate(samples, model, rate)
    pos = np.asarray(samples["position"], np.float64)
    vel = np.asarray(samples["velocity"], np.float64)
    return TrackResult(
        t=np.asarray(samples["t"], np.float64), planned_position=pos, planned_velocity=vel,
        position=out["position"], velocity=out["velocity"], measured_velocity=out["measured_velocity"],
        max_position_error=np.max(np.abs(out["position"] - pos), axis=0),
        max_velocity_error=np.max(np.abs(out["velocity"] - vel), axis=0),
        max_measured_velocity_error=np.max(np.abs(out["measured_velocity"] - vel), axis=0),
        model=model, rate=rate,
    )


def moving_joints(samples: dict) -> list[int]:
    """The joints whose planned position changes between the first and the last sample."""
    q = np.asarray(samples["position"])
    return [j for j in range(q.shape[1]) if abs(q[-1, j] - q[0, j]) > 1e-9]


def write_tracking(result: TrackResult, plan, out, *, move: str = "custom", largest_pole: float | None = None
                   ) -> list[Path]:
    """Write ``tracking.json`` (the move, the plan's T and jerk, the axis model, each joint's
    largest errors and, for the paper's moves, its measured ones), ``tracking.csv``
    (planned and tracked position and velocity of the moving joints at every tick) and
    ``tracking.png`` into ``out``, as one set (:func:`dockjax.io.write_set`). ``plan``: the
    :class:`dockjax.plan.Plan` that was tracked."""
    moving = moving_joints(plan.samples)
    report = {
        "move": move, "start": plan.problem.start.tolist(), "goal": plan.problem.goal.tolist(), "T_s": plan.T,
        "jerk": plan.jerk, "rate_hz": result.rate, "largest_closed_loop_pole": largest_pole,
        "model": {f.name: (np.asarray(getattr(result.model, f.name)).tolist()
                           if getattr(result.model, f.name) is not None else None)
                  for f in dataclasses.fields(result.model)},
        "joints": {config.JOINT_NAMES[j]: {"unit": config.JOINT_UNITS[j],
                                           "max_position_error": float(result.max_position_error[j]),
                                           "max_velocity_error": float(result.max_velocity_error[j]),
                                           "max_measured_velocity_error": float(result.max_measured_velocity_error[j])}
                   for j in range(len(result.max_position_error))},
    }
    if move in PAPER_ERRORS:
        pe, ve = PAPER_ERRORS[move]
        report["paper"] = {"joint": config.JOINT_NAMES[PAPER_JOINTS[move]], "max_position_error_mm": pe,
                           "max_velocity_error_mm_s": ve}
    cols = [result.t] + [a[:, j] for j in moving for a in (result.planned_position, result.position,
                                                            result.planned_velocity, result.velocity)]
    header = ["t [s]"] + [f"{config.JOINT_NAMES[j]}{k}" for j in moving
                          for k in (" planned", " tracked", "_vel planned", "_vel tracked")]
    table = np.stack(cols, 1)

    def write(stage: Path) -> list[Path]:
        files = [atomic_write_text(stage / "tracking.json", json.dumps(report, indent=2) + "\n"),
                 atomic_write_text(stage / "tracking.csv", ",".join(header) + "\n"
                                   + "\n".join(",".join(f"{v:.12g}" for v in row) for row in table) + "\n")]
        files.append(plots.plot_tracking(result, moving[:2] if moving else [0], stage / "tracking.png",
                                         title=f"servo tracking of the planned move (T = {plan.T:.2f} s, "
                                               f"{result.rate:g} Hz)"))
        return files

    return write_set(out, write, owned=("tracking.json", "tracking.csv", "tracking.png"))
