"""The sweep folder's files: loading a stored array file (checked), and the atomic writers
of :mod:`dockjax.io`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["load_npz"]


def load_npz(path: Path) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file (no pickled objects)."""
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}
