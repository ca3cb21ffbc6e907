"""The sweep folder's array files: verified loading (:func:`dockjax.io.load_npz`)."""

from __future__ import annotations

from ..io import DamagedFileError, load_npz

__all__ = ["DamagedFileError", "load_npz"]
