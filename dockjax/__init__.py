"""dockjax: JAX-accelerated batch multi-objective trajectory planning for a dual-arm
cabin-docking robot (quintic B-splines, IMOCS and its peers).

The public entry point is :class:`DockingProblem`; :func:`dockjax.optimize.optimize` runs
the optimisers, :mod:`dockjax.plan` makes one certified trajectory, and the command line
``dockjax`` (:mod:`dockjax.cli`) runs studies and plans. See the README.
"""

from .problem import DockingProblem
from .version import __version__

__all__ = ["DockingProblem", "__version__"]
