"""One control of XLA's fusion: force an intermediate into a buffer of its own.

XLA:CPU fuses an array's computation into each consumer that reads it — a gather, or
several elementwise consumers — recomputing it there, and a bare
``jax.lax.optimization_barrier`` does not stop it (measured: the cuckoo ``ask`` and the
scoring kernel ran as fast with or without their barriers). :func:`materialize` does.
"""

from __future__ import annotations

import jax

__all__ = ["materialize"]


def materialize(x):
    """x (any pytree of arrays), computed into buffers of its own before any consumer reads
    it; the value is unchanged.

    A two-trip loop around an optimisation barrier is a boundary XLA neither fuses across
    nor simplifies away (a one-trip loop is inlined, and the barrier alone is ignored by
    the fusion passes). Without it, the discovery step of the cuckoo searches recomputes the
    whole Lévy step for every element its two row gathers read, and the scoring kernel
    recomputes its span coefficients, span angles and joint series in each consumer.
    Differentiable (a fixed-trip ``fori_loop``) and vmappable.
    """
    return jax.lax.fori_loop(0, 2, lambda _, y: jax.lax.optimization_barrier(y), x)
