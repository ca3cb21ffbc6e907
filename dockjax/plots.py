"""Every figure of dockjax (matplotlib's object API: figures are drawn off screen by their
own canvas, so importing this module changes no backend and no global state).

Each function takes plain NumPy data and a path, writes one PNG atomically and returns
the path.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from . import config, robot
from .io import atomic_write

__all__ = ["save", "plot_fronts", "plot_left_arm", "plot_joints", "plot_convergence", "plot_heatmap",
           "plot_median_iqr", "plot_front_groups", "plot_anytime", "plot_eaf", "plot_tracking", "plot_sensitivities",
           "worth_drawing"]

MAX_PLOT_POINTS = 1000
"""Samples per line drawn by :func:`plot_joints` (a stride keeps the first and last)."""

COLORS = {"imocs": "C3", "mocs": "C1", "nsga2": "C0", "mopso": "C2", "imocs+refine": "C4"}
LABELS = {"imocs": "IMOCS", "mocs": "MOCS", "nsga2": "NSGA-II", "mopso": "MOPSO",
          "imocs+refine": "IMOCS + refine"}


def _axes(nrows: int = 1, ncols: int = 1, figsize=(6.5, 4.5), **kw):
    """A new figure and its axes (an array for several)."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kw)


def _finish(fig, ax, path, *, xlabel: str, ylabel: str, title: str, log_y: bool = False, legend_size=None) -> Path:
    """Labels, log scale, legend and grid of a one-axes figure, then :func:`save`."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if log_y:
        ax.set_yscale("log")
    ax.set_title(title)
    _legend_outside(ax, legend_size)
    ax.grid(alpha=0.3)
    return save(fig, path)


def _legend_outside(ax, size=None) -> None:
    """The legend to the right of the axes, where it covers no data (the saved figure
    grows to hold it)."""
    ax.legend(fontsize=size, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)


def save(fig, path: str | os.PathLike) -> Path:
    """Save a figure as PNG atomically."""
    return atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=120, bbox_inches="tight"))


def plot_fronts(fronts: dict[str, np.ndarray], path, *, reference=None, title="", highlight=None,
                reference_label="reference front") -> Path:
    """All algorithms' fronts in one plot (the paper's Fig. 12). fronts: name → (k, 2);
    ``highlight``: one (T, jerk) point to mark (e.g. the chosen trajectory)."""
    fig, ax = _axes()
    if reference is not None and len(reference):
        r = reference[np.argsort(reference[:, 0])]
        ax.plot(r[:, 0], r[:, 1], "-", color="0.4", lw=1.2, label=reference_label)
    for name, f in fronts.items():
        if len(f):
            ax.plot(f[:, 0], f[:, 1], "o", ms=3, color=COLORS.get(name), label=LABELS.get(name, name))
    if highlight is not None:
        ax.plot([highlight[0]], [highlight[1]], "*", ms=14, color="k", label="chosen")
    return _finish(fig, ax, path, xlabel="total time T [s]", ylabel="jerk objective (Eq. 25)",
                   title=title or "Pareto fronts", log_y=True)


def plot_left_arm(samples: dict[str, dict[str, np.ndarray]], path) -> Path:
    """Left arm end X, Y, Z: position, velocity, acceleration of the chosen trajectories
    (the paper's Figs. 13–21). samples: label → {"t", "pose", "pose_vel", "pose_acc"}."""
    fig, axes = _axes(3, 3, figsize=(12, 8), sharex=False)
    names = ("position [mm]", "velocity [mm/s]", "acceleration [mm/s²]")
    for label, s in samples.items():
        for i, axis in enumerate("XYZ"):
            for k, key in enumerate(("pose", "pose_vel", "pose_acc")):
                axes[i, k].plot(s["t"], s[key][:, i], label=label)
                axes[i, k].set_title(f"{axis} {names[k]}", fontsize=9)
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
        ax.set_xlabel("t [s]", fontsize=8)
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    return save(fig, path)


def plot_joints(sample: dict[str, np.ndarray], limits: np.ndarray, path, *, title="", home=None) -> Path:
    """The joints' travel about home, velocity, acceleration (and, with a jerk column,
    jerk) as fractions of their limits (one panel per kind of limit, limits ±1 dashed).
    sample: {"t", "position", "velocity", "acceleration", "jerk"} (m, 8) (or 4 per support,
    :func:`dockjax.robot.support_joints`); limits (8, kinds)
    (columns as :data:`dockjax.robot.LIMIT_KINDS`), or (m, 8, kinds) per sample (a staged
    move's stages); home (8,) (default: the midpoint of the first and last positions)."""
    limits = np.asarray(limits)
    kinds = robot.kinds_of(limits.shape[-1])
    fig, axes = _axes(len(kinds), 1, figsize=(9, 3 * len(kinds)), sharex=True)
    m = len(sample["t"])
    pick = np.unique(np.append(np.arange(0, m, max(1, -(-m // MAX_PLOT_POINTS))), m - 1))
    pos = sample["position"]
    home = 0.5 * (pos[0] + pos[-1]) if home is None else np.asarray(home)
    series = [robot.sampled_quantity(sample, k, home) / limits[..., i] for i, k in enumerate(kinds)]
    names = [("travel about home" if k.order == 0 else k.name) + " / limit" for k in kinds]
    t = sample["t"][pick]
    joints = robot.support_joints(pos.shape[1] // 4)
    for ax, y, name in zip(axes, series, names):
        for j, joint in enumerate(joints):
            ax.plot(t, y[pick, j], lw=1.2, ls=("-", "--", ":", "-.")[j // 4 % 4], label=joint.name)
        for sgn in (-1, 1):
            ax.axhline(sgn, color="C3", ls=":", lw=1)
        ax.set_ylabel(name, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, ncol=4, loc="lower right")
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(title or "joint profiles against their limits")
    fig.tight_layout()
    return save(fig, path)


def plot_convergence(histories: dict[str, np.ndarray], path, *, title="") -> Path:
    """Hypervolume over iterations per algorithm: median and interquartile band over seeds.
    histories: name → (runs, n_iter)."""
    fig, ax = _axes()
    for name, h in histories.items():
        it = np.arange(1, h.shape[1] + 1)
        q1, med, q3 = np.percentile(h, [25, 50, 75], axis=0)
        ax.plot(it, med, color=COLORS.get(name), label=LABELS.get(name, name))
        ax.fill_between(it, q1, q3, color=COLORS.get(name), alpha=0.2)
    return _finish(fig, ax, path, xlabel="iteration", ylabel="hypervolume of the feasible set",
                   title=title or "convergence")


def plot_heatmap(M: np.ndarray, rows, cols, path, *, xlabel: str, ylabel: str, title: str, tied=None,
                 best=None) -> Path:
    """A value per grid cell, annotated. M: (len(rows), len(cols)). ``tied`` (same shape,
    bool): cells not significantly worse than the best, framed and marked "="; ``best``
    (row, column): the best cell, marked "★". The colour scale spans the values drawn,
    however small their differences: the marks say which differences are significant."""
    fig, ax = _axes(figsize=(1.2 * len(cols) + 2.5, 0.9 * len(rows) + 2.3))
    im = ax.imshow(M, origin="lower", cmap="viridis", aspect="auto")
    tied = np.zeros(M.shape, bool) if tied is None else np.asarray(tied, bool)
    for i in range(len(rows)):
        for j in range(len(cols)):
            mark = "★ " if best is not None and (i, j) == tuple(best) else "= " if tied[i, j] else ""
            ax.text(j, i, f"{mark}{M[i, j]:.3f}", ha="center", va="center", color="w", fontsize=8)
            if tied[i, j] or mark:
                ax.add_patch(Rectangle((j - 0.46, i - 0.46), 0.92, 0.92, fill=False, ec="w", lw=1.5))
    ax.set_xticks(range(len(cols)), [f"{a:g}" for a in cols])
    ax.set_yticks(range(len(rows)), [f"{r:g}" for r in rows])
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if tied.any():
        note = ("every setting is tied with the best: no difference is significant" if tied.all()
                else "★ best, = tied with the best (not significantly worse)")
        ax.set_title(f"{title}\n{note}", fontsize=9)
    else:
        ax.set_title(title)
    fig.colorbar(im, ax=ax)
    return save(fig, path)


def plot_median_iqr(lines: dict[str, tuple], path, *, xlabel: str, ylabel: str, title: str) -> Path:
    """Medians with interquartile bars, one line per label: ``label → (x (k,), median (k,),
    quartiles (k, 2))``; the lines are shifted sideways a little so the bars stay readable."""
    fig, ax = _axes()
    xs = np.concatenate([v[0] for v in lines.values()]) if lines else np.zeros(1)
    dx = 0.01 * (np.ptp(xs) or np.max(np.abs(xs)) or 1.0)
    for g, (label, (x, y, q)) in enumerate(lines.items()):
        ax.errorbar(x + dx * (g - (len(lines) - 1) / 2), y, yerr=[y - q[:, 0], q[:, 1] - y], marker="o", capsize=3,
                    label=label)
    ax.set_xticks(np.unique(xs))
    return _finish(fig, ax, path, xlabel=xlabel, ylabel=ylabel, title=title, legend_size=7)


def plot_importance(bars: dict[str, tuple[list[str], np.ndarray, np.ndarray]], path, *, title: str) -> Path:
    """Horizontal bars of importances with their intervals, one group of bars per label:
    ``label → (parameter names (k,), importances (k,), intervals (k, 2))``; every label
    names the same parameters."""
    fig, ax = _axes()
    labels = list(bars)
    names = bars[labels[0]][0] if labels else []
    height = 0.8 / max(len(labels), 1)
    y = np.arange(len(names), dtype=float)
    for g, label in enumerate(labels):
        _, v, ci = bars[label]
        v, ci = np.asarray(v, float), np.asarray(ci, float).reshape(-1, 2)
        ax.barh(y + (g - (len(labels) - 1) / 2) * height, v, height=height, label=label,
                xerr=[v - ci[:, 0], ci[:, 1] - v], capsize=3)
    ax.set_yticks(y, names)
    ax.set_xlim(0, 1)
    return _finish(fig, ax, path, xlabel="importance (PED-ANOVA, sums to 1; bar = 95 % bootstrap interval)",
                   ylabel="hyper-parameter", title=title, legend_size=8)


def plot_front_groups(groups: dict[str, list[np.ndarray]], reference: np.ndarray, path, *, reference_label: str,
                      title: str) -> Path:
    """Every front of each group (``label → fronts (k, 2)``) in one colour, over a reference front."""
    fig, ax = _axes()
    ax.plot(reference[:, 0], reference[:, 1], ".-", color="0.5", lw=1, ms=4, drawstyle="steps-post",
            label=reference_label)
    for color, (label, fronts) in zip(("C3", "C0", "C2", "C1"), groups.items()):
        first = True
        for f in fronts:
            if len(f):
                ax.plot(f[:, 0], f[:, 1], "o", ms=3, color=color, alpha=0.6, label=label if first else None)
                first = False
    return _finish(fig, ax, path, xlabel="total time T [s]", ylabel="jerk objective (Eq. 25)", title=title,
                   log_y=True, legend_size=7)


def plot_anytime(curves: dict[str, tuple[np.ndarray, np.ndarray]], path, *, title: str) -> Path:
    """Median and interquartile band over runs of a quantity against evaluations:
    ``label → (evaluations (k,), values (runs, k))``."""
    fig, ax = _axes()
    for g, (label, (x, H)) in enumerate(curves.items()):
        q1, med, q3 = np.percentile(H, [25, 50, 75], axis=0)
        ax.plot(x, med, color=f"C{g}", label=label)
        ax.fill_between(x, q1, q3, color=f"C{g}", alpha=0.2)
    return _finish(fig, ax, path, xlabel="evaluations", ylabel="hypervolume (normalised)", title=title,
                   legend_size=7)


def plot_deviation(lines: dict[str, tuple[np.ndarray, np.ndarray]], path, *, xlabel: str, ylabel: str,
                   title: str) -> Path:
    """Log-log lines with markers, ``label → (x (k,), y (k,))`` (zeros drawn at 1e-12)."""
    fig, ax = _axes()
    for label, (x, y) in lines.items():
        ax.plot(x, np.maximum(y, 1e-12), marker="o", label=label)
    ax.set_xscale("log")
    return _finish(fig, ax, path, xlabel=xlabel, ylabel=ylabel, title=title, log_y=True)


def plot_joined(first: dict[str, np.ndarray], second: dict[str, np.ndarray], t_switch: float, path) -> Path:
    """The joints' velocities of a plan (``first``'s samples) until ``t_switch`` s, then of
    the plan made from its state there (``second``'s samples, its time 0 drawn at
    ``t_switch``), with the rest of the first dashed: linear joints (mm/s) and rotary
    joints (°/s) in two panels."""
    fig, axes = _axes(1, 2, figsize=(12.0, 4.0))
    before = first["t"] <= t_switch
    for ax, unit in zip(axes, ("mm", "deg")):
        for j, (name, u) in enumerate(zip(config.JOINT_NAMES, config.JOINT_UNITS)):
            if u != unit:
                continue
            line, = ax.plot(first["t"][before], first["velocity"][before, j], lw=1.0, label=name)
            ax.plot(first["t"][~before], first["velocity"][~before, j], lw=0.8, ls="--", color=line.get_color(),
                    alpha=0.5)
            ax.plot(t_switch + second["t"], second["velocity"][:, j], lw=1.0, color=line.get_color())
        ax.axvline(t_switch, color="k", lw=0.6, ls=":")
        ax.set(xlabel="t [s]", ylabel=f"velocity [{unit}/s]",
               title=f"replanned at t = {t_switch:.2f} s (dashed: the first plan's rest)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return save(fig, path)


def plot_eaf(surface_a: np.ndarray, surface_b: np.ndarray, diff: np.ndarray, label_a: str, label_b: str,
             runs_a: int, runs_b: int, reference: np.ndarray, path) -> Path:
    """Median attainment surfaces of two settings (points (k, 2) each) and their EAF
    difference (``moocore.eafdiff(..., rectangles=True)``: rows ``x0, y0, x1, y1, d`` with
    d = runs of A − runs of B attaining the rectangle), in objective space. The difference is
    painted onto a grid (linear in T, logarithmic in jerk) and drawn as one image."""
    fig, ax = _axes(figsize=(7.5, 5))
    pts = np.concatenate([reference, surface_a, surface_b])
    lo, hi = pts.min(axis=0) * np.array([0.98, 0.9]), pts.max(axis=0) * 1.05
    xs = np.linspace(lo[0], hi[0], 401)
    ys = np.geomspace(lo[1], hi[1], 301)
    xc, yc = 0.5 * (xs[1:] + xs[:-1]), np.sqrt(ys[1:] * ys[:-1])
    img = np.zeros((yc.size, xc.size))
    nz = diff[diff[:, 4] != 0]
    i0, i1 = np.searchsorted(xc, nz[:, 0]), np.searchsorted(xc, nz[:, 2])
    j0, j1 = np.searchsorted(yc, nz[:, 1]), np.searchsorted(yc, nz[:, 3])
    for a, b, c, d, v in zip(j0, j1, i0, i1, nz[:, 4]):
        img[a:b, c:d] = v
    scale = max(runs_a, runs_b)
    im = ax.pcolormesh(xs, ys, img / scale, cmap="RdBu_r", vmin=-1, vmax=1, shading="flat", rasterized=True)
    fig.colorbar(im, ax=ax, label="(runs of the first − runs of the second attaining) / runs")
    for surf, label, color in ((surface_a, label_a, "C3"), (surface_b, label_b, "C0")):
        s = surf[np.argsort(surf[:, 0])]
        ax.plot(s[:, 0], s[:, 1], drawstyle="steps-post", color=color, lw=1.5, label=f"median attainment: {label}")
    r = reference[np.argsort(reference[:, 0])]
    ax.plot(r[:, 0], r[:, 1], "-", color="0.3", lw=0.8, label="reference front")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_yscale("log")
    ax.set_xlabel("total time T [s]")
    ax.set_ylabel("jerk objective (Eq. 25)")
    ax.set_title("EAF difference (red: attained more often by the first, blue: by the second)", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(alpha=0.3)
    return save(fig, path)


def plot_tracking(result, joints, path, *, title: str = "", error: bool = True) -> Path:
    """Planned against tracked position and velocity of the ``joints`` (indices) of a
    :class:`dockjax.track.TrackResult` (the paper's Figs. 23–26): one row per joint, position
    left and velocity right, and with ``error`` the tracking error (tracked − planned) in
    its own axes below each, on its own scale."""
    joints = [int(j) for j in np.atleast_1d(joints)]
    n = np.asarray(result.position).shape[1]
    if not joints or any(j < 0 or j >= n for j in joints):
        raise ValueError(f"joints must be indices from 0 to {n - 1}, got {joints!r}")
    names = config.JOINT_NAMES if n == config.N_JOINTS else tuple(f"joint {j}" for j in range(n))
    units = config.JOINT_UNITS if n == config.N_JOINTS else ("",) * n
    per_joint = 2 if error else 1
    fig = Figure(figsize=(12, (4.6 if error else 3.6) * len(joints)))
    grid = fig.add_gridspec(per_joint * len(joints), 2, height_ratios=[3, 1.4] * len(joints) if error else None)
    t = np.asarray(result.t)
    pairs = (("position", result.planned_position, result.position, ""),
             ("velocity", result.planned_velocity, result.velocity, "/s"))
    for row, j in enumerate(joints):
        for col, (what, planned, tracked, per) in enumerate(pairs):
            ax = fig.add_subplot(grid[per_joint * row, col])
            planned, tracked = np.asarray(planned)[:, j], np.asarray(tracked)[:, j]
            unit = f" [{units[j]}{per}]" if units[j] else ""
            ax.plot(t, tracked, color="C3", lw=0.8, alpha=0.7, label="tracked")
            ax.plot(t, planned, color="C0", lw=1.5, ls="--", label="planned", zorder=3)  # visible over the noise
            ax.set_ylabel(f"{names[j]} {what}{unit}", fontsize=8)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="best")
            ax.set_title(f"{names[j]} {what}: max |error| = {np.max(np.abs(tracked - planned)):.3g}{unit}",
                         fontsize=9)
            if error:
                below = fig.add_subplot(grid[per_joint * row + 1, col], sharex=ax)
                below.plot(t, tracked - planned, color="0.35", lw=0.8)
                below.set_ylabel(f"error{unit}", fontsize=8)
                below.grid(alpha=0.3)
                below.set_xlabel("t [s]", fontsize=8)
            else:
                ax.set_xlabel("t [s]", fontsize=8)
    fig.suptitle(title or "servo tracking")
    fig.tight_layout()
    return save(fig, path)


def worth_drawing(explanation: dict) -> list[dict]:
    """The binding limits of a plan whose value is more than rounding: a 1 % change of the
    limit moves the objective by more than 1e-6 of the largest such change (and by more
    than 1e-12 at all); none whose sensitivity is unknown."""
    rows = [r for r in explanation.get("binding", []) if r["sensitivity"] is not None]
    effect = [abs(0.01 * r["sensitivity"] * r["value"]) for r in rows]
    top = max(effect, default=0.0)
    return [r for r, e in zip(rows, effect) if e > max(1e-6 * top, 1e-12)]


def plot_sensitivities(explanation: dict, path, *, title: str = "") -> Path:
    """The marginal value of each binding limit of a plan (:func:`dockjax.plan.explain`) that
    is worth drawing (:func:`worth_drawing`): one bar per limit, ``d objective / d limit``
    scaled to a 1 % change of the limit (objective units), the finite-difference check as a
    marker where present."""
    rows = worth_drawing(explanation)
    fig, ax = _axes(figsize=(6.5, 1.2 + 0.5 * max(len(rows), 1)))
    unit = "s" if explanation.get("objective") == "T_s" else "jerk"
    if rows:
        y = np.arange(len(rows))
        ax.barh(y, [0.01 * r["sensitivity"] * r["value"] for r in rows], color="C0",
                label="from the optimum's multipliers")
        fd = [(i, 0.01 * r["finite_difference"] * r["value"]) for i, r in enumerate(rows) if "finite_difference" in r]
        if fd:
            ax.plot([v for _, v in fd], [i for i, _ in fd], "k|", ms=16, mew=2, label="re-planned ± 1 %")
        ax.set_yticks(y, [r["limit"] for r in rows])
        ax.axvline(0.0, color="0.3", lw=0.8)
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, "no limit has a value", ha="center", va="center", transform=ax.transAxes)
        ax.set_yticks([])
    ax.set_xlabel(f"change of the {'shortest time' if unit == 's' else 'jerk objective'} for +1 % of the limit "
                  f"[{unit}]")
    ax.set_title(title or "what each binding limit is worth", fontsize=10)
    ax.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    return save(fig, path)
