"""The four optimisers of the paper's comparison as JAX array programs.

``imocs`` (the paper's), ``mocs`` (Yang & Deb 2013), ``nsga2`` (Deb et al. 2002) and
``mopso`` (Coello et al. 2004), each an :class:`~dockjax.algorithms.base.Algorithm`
(the contract: ``Params``, ``State``, ``init_ask``/``init_tell``/``ask``/``tell``,
``final_population``) in its own module. :data:`ALGORITHMS` is the one registry: the
drivers (:func:`dockjax.optimize.optimize`), the command lines' choices and the tests'
parametrisations are taken from it.
"""

from __future__ import annotations

from typing import Any

from . import imocs, mocs, mopso, nsga2
from .base import Algorithm, Population, coerce, validate_params

__all__ = ["ALGORITHMS", "Algorithm", "Population", "get", "make_params"]

ALGORITHMS: dict[str, Algorithm] = {a.name: a for a in (imocs.ALGORITHM, mocs.ALGORITHM, nsga2.ALGORITHM,
                                                           mopso.ALGORITHM)}
"""Every optimiser by name."""


def get(name: str | Algorithm) -> Algorithm:
    """The algorithm called ``name`` (case-insensitive: imocs, mocs, nsga2, mopso), or
    ``name`` itself if it is an :class:`Algorithm`."""
    if isinstance(name, Algorithm):
        return name
    key = str(name).lower().replace("-", "").replace("_", "")
    if key not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {sorted(ALGORITHMS)}, got {name!r}")
    return ALGORITHMS[key]


def make_params(algorithm: str | Algorithm, pop_size: int, n_iter: int, **hyper) -> Any:
    """Build and validate the algorithm's ``Params`` (``max_iter`` follows ``n_iter`` where
    the algorithm has it). A value may be a number or a 1-D array with one value per run
    (a run axis, :func:`~dockjax.algorithms.base.run_axes`); each is converted to its
    field's type (:func:`~dockjax.algorithms.base.coerce`: ``2.0`` is the integer 2 for an
    integer field). Raises ValueError naming an unknown or out-of-range field."""
    algorithm = get(algorithm)
    fields = algorithm.Params.__dataclass_fields__
    unknown = sorted(set(hyper) - set(fields))
    if unknown:
        raise ValueError(
            f"unknown hyper-parameter(s) {unknown} for {algorithm.name}; "
            f"allowed: {sorted(set(fields) - {'pop_size', 'max_iter'})}"
        )
    kwargs = {k: coerce(algorithm.Params, k, v) for k, v in hyper.items()}
    kwargs["pop_size"] = pop_size
    if "max_iter" in fields:
        kwargs["max_iter"] = n_iter
    params = algorithm.Params(**kwargs)
    validate_params(params)
    return params
