"""dockjax: JAX-accelerated batch multi-objective trajectory planning for a dual-arm
cabin-docking robot (quintic B-splines, IMOCS and its peers).

The public entry point is :class:`DockingProblem`; see the README for the study scripts.
"""

from .problem import DockingProblem

__version__ = "0.1.0"

__all__ = ["DockingProblem", "__version__"]
