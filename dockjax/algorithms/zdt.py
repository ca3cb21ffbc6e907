"""ZDT1 (Zitzler, Deb & Thiele 2000), a problem with a known front for testing optimisers."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["ZDT1"]


class ZDT1:
    """ZDT1 (Zitzler, Deb & Thiele 2000): 30 variables in [0, 1], two objectives, no limits.

    Known front ``f2 = 1 − sqrt(f1)``, ``f1 ∈ [0, 1]`` (:meth:`pareto_front`).
    """

    n_obj = 2
    n_con = 0

    def __init__(self, n_var: int = 30):
        self.n_var = int(n_var)
        self.lower = np.zeros(self.n_var)
        self.upper = np.ones(self.n_var)

    def evaluate_jax(self, X):
        f1 = X[:, 0]
        g = 1.0 + 9.0 * jnp.mean(X[:, 1:], axis=1)
        f2 = g * (1.0 - jnp.sqrt(jnp.clip(f1 / g, 0.0, None)))
        return jnp.stack([f1, f2], 1), jnp.zeros((X.shape[0], 0), X.dtype)

    def evaluate(self, X):
        with jax.enable_x64(True):
            F, G = self.evaluate_jax(jnp.asarray(X, jnp.float64))
            return np.asarray(F), np.asarray(G)

    @staticmethod
    def pareto_front(n: int = 1000) -> np.ndarray:
        f1 = np.linspace(0.0, 1.0, n)
        return np.stack([f1, 1.0 - np.sqrt(f1)], 1)

    def __repr__(self) -> str:
        return f"ZDT1(n_var={self.n_var})"


jax.tree_util.register_pytree_node(
    ZDT1, lambda p: ((), p.n_var), lambda n, _: ZDT1(n)
)
