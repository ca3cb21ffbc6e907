"""Every figure of the study (matplotlib, Agg backend; nothing is shown on screen).

Each function takes plain NumPy data and a path, writes one PNG atomically and returns
the path.
"""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from . import config  # noqa: E402
from .io import atomic_write  # noqa: E402

__all__ = ["save", "plot_fronts", "plot_left_arm", "plot_joints", "plot_convergence"]

COLORS = {"imocs": "C3", "mocs": "C1", "nsga2": "C0", "mopso": "C2", "imocs+refine": "C4"}
LABELS = {"imocs": "IMOCS", "mocs": "MOCS", "nsga2": "NSGA-II", "mopso": "MOPSO",
          "imocs+refine": "IMOCS + refine"}


def save(fig, path: str | os.PathLike) -> Path:
    """Save a figure as PNG atomically and close it."""
    try:
        return atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=120, bbox_inches="tight"))
    finally:
        plt.close(fig)


def plot_fronts(fronts: dict[str, np.ndarray], path, *, reference=None, title="", highlight=None,
                reference_label="reference front") -> Path:
    """All algorithms' fronts in one plot (the paper's Fig. 12). fronts: name → (k, 2);
    ``highlight``: one (T, jerk) point to mark (e.g. the chosen trajectory)."""
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    if reference is not None and len(reference):
        r = reference[np.argsort(reference[:, 0])]
        ax.plot(r[:, 0], r[:, 1], "-", color="0.4", lw=1.2, label=reference_label)
    for name, f in fronts.items():
        if len(f):
            ax.plot(f[:, 0], f[:, 1], "o", ms=3, color=COLORS.get(name), label=LABELS.get(name, name))
    if highlight is not None:
        ax.plot([highlight[0]], [highlight[1]], "*", ms=14, color="k", label="chosen")
    ax.set_xlabel("total time T [s]")
    ax.set_ylabel("jerk objective (Eq. 25)")
    ax.set_yscale("log")
    ax.set_title(title or "Pareto fronts")
    ax.legend()
    ax.grid(alpha=0.3)
    return save(fig, path)


def plot_left_arm(samples: dict[str, dict[str, np.ndarray]], path) -> Path:
    """Left arm end X, Y, Z: position, velocity, acceleration of the chosen trajectories
    (the paper's Figs. 13–21). samples: label → {"t", "pose", "pose_vel", "pose_acc"}."""
    fig, axes = plt.subplots(3, 3, figsize=(12, 8), sharex=False)
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


def plot_joints(sample: dict[str, np.ndarray], limits: np.ndarray, path, *, title="") -> Path:
    """The eight joints' position, velocity and acceleration, limits dashed.
    sample: {"t", "position", "velocity", "acceleration"} (m, 8); limits (8, 3)."""
    fig, axes = plt.subplots(8, 3, figsize=(12, 16), sharex=True)
    for j in range(8):
        unit = config.JOINT_UNITS[j]
        for k, (key, u) in enumerate(zip(("position", "velocity", "acceleration"), ("", "/s", "/s²"))):
            ax = axes[j, k]
            ax.plot(sample["t"], sample[key][:, j], color="C0")
            if k > 0:
                for sgn in (-1, 1):
                    ax.axhline(sgn * limits[j, k], color="C3", ls="--", lw=0.8)
            ax.set_ylabel(f"{config.JOINT_NAMES[j]} [{unit}{u}]", fontsize=7)
            ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle(title or "joint profiles")
    fig.tight_layout()
    return save(fig, path)


def plot_convergence(histories: dict[str, np.ndarray], path, *, title="") -> Path:
    """Hypervolume over iterations per algorithm: median and interquartile band over seeds.
    histories: name → (runs, n_iter)."""
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for name, h in histories.items():
        it = np.arange(1, h.shape[1] + 1)
        q1, med, q3 = np.percentile(h, [25, 50, 75], axis=0)
        ax.plot(it, med, color=COLORS.get(name), label=LABELS.get(name, name))
        ax.fill_between(it, q1, q3, color=COLORS.get(name), alpha=0.2)
    ax.set_xlabel("iteration")
    ax.set_ylabel("hypervolume of the feasible set")
    ax.set_title(title or "convergence")
    ax.legend()
    ax.grid(alpha=0.3)
    return save(fig, path)
