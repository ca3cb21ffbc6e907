"""dockjax: JAX-accelerated batch multi-objective trajectory planning for a dual-arm
cabin-docking robot (quintic B-splines, IMOCS and its peers).

The problem is :class:`DockingProblem`; :func:`dockjax.optimize.optimize` runs the
optimisers, :func:`dockjax.plan.plan` makes one certified trajectory and
:class:`dockjax.plan.Planner` many, :mod:`dockjax.sweep` runs studies, and the command line
``dockjax`` (:mod:`dockjax.cli`) does all of it. Every module is reachable from
``import dockjax`` (``dockjax.plan.plan``, ``dockjax.sweep.report``, ...), and the main
classes are names of the package itself (``dockjax.Planner``, ``dockjax.Result``, ...);
both are loaded on first use, so ``import dockjax`` stays light. See the README.
"""

from __future__ import annotations

import importlib

from .problem import DockingProblem
from .version import __version__

MODULES = ("algorithms", "best_known", "bspline", "bulk", "checks", "cli", "config", "decoding", "devices", "export",
           "extrema", "fusion", "instances", "interop", "io", "jets", "kinematics", "limits", "metrics", "objectives",
           "optimize", "pareto", "plan", "plots", "problem", "prng", "pytrees", "refine", "right_arm", "robot",
           "runtime", "select", "solve", "sqp", "stages", "stats", "store", "sweep", "track", "trajectory", "version")
"""The public modules, each an attribute of the package."""

NAMES = {"Result": "optimize", "Plan": "plan", "Planner": "plan", "PlanError": "solve", "Trajectory": "trajectory",
         "FrontResult": "best_known", "AxisModel": "track", "ALGORITHMS": "algorithms",
         "enable_compilation_cache": "runtime"}
"""Classes, tables and functions of the package namespace, by the module that defines them."""

__all__ = ["DockingProblem", "__version__", *NAMES, *MODULES]


def __getattr__(name: str):
    if name in MODULES:
        return importlib.import_module(f".{name}", __name__)
    if name in NAMES:
        return getattr(importlib.import_module(f".{NAMES[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
