"""Interop: a :class:`dockjax.DockingProblem` (or any dockjax problem) as a pymoo ``Problem``.

pymoo (optional extra ``dockjax[pymoo]``) then runs its own algorithms on the compiled
kernel: one ``evaluate`` call scores the whole population (pymoo's ``elementwise=False``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["as_pymoo_problem"]


def as_pymoo_problem(problem):
    """Wrap ``problem`` as a pymoo ``Problem`` (natural units; G ≤ 0 feasible)."""
    try:
        from pymoo.core.problem import Problem
    except ImportError as exc:  # pragma: no cover
        raise ImportError("as_pymoo_problem needs pymoo: pip install 'dockjax[pymoo]'") from exc

    class _Wrapped(Problem):
        def __init__(self):
            super().__init__(n_var=problem.n_var, n_obj=problem.n_obj, n_ieq_constr=problem.n_con,
                             xl=np.asarray(problem.lower), xu=np.asarray(problem.upper))
            self.dockjax_problem = problem

        def _evaluate(self, x, out, *args, **kwargs):
            F, G = problem.evaluate(np.asarray(x, dtype=np.float64))
            out["F"] = F
            if problem.n_con:
                out["G"] = G

    return _Wrapped()
