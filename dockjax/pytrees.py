"""Frozen dataclasses registered as JAX pytrees: the one way dockjax declares its pytrees.

Every field is a leaf (traced under ``jit``) unless marked :func:`static` (part of the
compiled program's identity, e.g. a population size or a mode name); nothing is lost on a
round trip through ``jit``, ``vmap`` or ``tree_map``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import jax

__all__ = ["pytree_dataclass", "static"]


def pytree_dataclass(cls=None, /, **options):
    """Decorator: ``cls`` as a frozen dataclass (``options`` go to :func:`dataclasses.dataclass`)
    registered as a JAX pytree; fields marked :func:`static` are its auxiliary data and
    fields declared with ``init=False`` are dropped from it (rebuilt with their defaults)."""

    def wrap(cls):
        dc = dataclass(frozen=True, **options)(cls)
        fields = [f for f in dataclasses.fields(dc) if f.init]
        meta = [f.name for f in fields if f.metadata.get("static", False)]
        data = [f.name for f in fields if not f.metadata.get("static", False)]
        return jax.tree_util.register_dataclass(dc, data_fields=data, meta_fields=meta)

    return wrap if cls is None else wrap(cls)


def static(default: Any) -> Any:
    """A static (non-traced) pytree dataclass field, e.g. the population size."""
    return field(default=default, metadata=dict(static=True))
