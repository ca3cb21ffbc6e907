"""Validation shared by every public function and command line: each check raises a
``ValueError`` naming the argument, the rule and the value, before any expensive work.

Booleans are not numbers here (``True`` is not a population size), and every number must
be finite unless the rule says otherwise.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from .config import MAX_RATE

__all__ = ["is_integer", "integer", "optional_integer", "number", "numbers", "vector", "choice", "real_array",
           "boolean", "rate"]


def is_integer(value: Any) -> bool:
    """An int or NumPy integer, and not a boolean."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def integer(name: str, value: Any, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as an int, or ValueError unless it is an integer in ``[minimum, maximum]``."""
    if not is_integer(value) or (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
        if minimum is not None and maximum is not None:
            rule = f"an integer from {minimum} to {maximum}"
        elif minimum is not None:
            rule = f"an integer >= {minimum}"
        elif maximum is not None:
            rule = f"an integer <= {maximum}"
        else:
            rule = "an integer"
        raise ValueError(f"{name} must be {rule}, got {value!r}")
    return int(value)


def optional_integer(name: str, value: Any, minimum: int | None = None) -> int | None:
    """None, or :func:`integer`."""
    return None if value is None else integer(name, value, minimum)


def _interval(lo: float, hi: float, open_lo: bool, open_hi: bool) -> str:
    if hi == math.inf and lo != -math.inf:
        return f"{'>' if open_lo else '>='} {lo:g}"
    if lo == -math.inf and hi != math.inf:
        return f"{'<' if open_hi else '<='} {hi:g}"
    return f"in {'(' if open_lo else '['}{lo:g}, {hi:g}{')' if open_hi else ']'}"


def numbers(name: str, value: Any, lo: float = -math.inf, hi: float = math.inf, *, open_lo: bool = False,
            open_hi: bool = False) -> np.ndarray:
    """``value`` (a number or an array of them) as float64, or ValueError unless every entry
    is a finite real number in the interval."""
    arr = np.asarray(value)
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    arr = arr.astype(np.float64)
    ok = np.isfinite(arr) & ((arr > lo) if open_lo else (arr >= lo)) & ((arr < hi) if open_hi else (arr <= hi))
    if not np.all(ok):
        raise ValueError(f"{name} must be finite and {_interval(lo, hi, open_lo, open_hi)}, got "
                         f"{arr.tolist()!r}")
    return arr


def number(name: str, value: Any, lo: float = -math.inf, hi: float = math.inf, *, open_lo: bool = False,
           open_hi: bool = False) -> float:
    """One finite real number in the interval, as a float (see :func:`numbers`)."""
    arr = numbers(name, value, lo, hi, open_lo=open_lo, open_hi=open_hi)
    if arr.ndim:
        raise ValueError(f"{name} must be one number, got {value!r}")
    return float(arr)


def real_array(name: str, value: Any) -> np.ndarray:
    """``value`` as a float64 array, or ValueError unless every element is a real number:
    booleans, strings, complex numbers and other objects are refused (``True`` is not 1)."""
    try:
        raw = np.asarray(value)
    except (ValueError, TypeError):
        raise ValueError(f"{name} must be an array of numbers, got {value!r}") from None
    if raw.dtype.kind not in "iuf":
        kind = {"b": "booleans", "U": "strings", "S": "strings", "c": "complex numbers"}.get(raw.dtype.kind,
                                                                                            "non-numbers")
        raise ValueError(f"{name} must hold real numbers, got {kind}: {value!r}")
    # a list mixing booleans with numbers converts to numbers: look at its elements
    if isinstance(value, (list, tuple)) and any(isinstance(v, (bool, np.bool_))
                                                for v in np.asarray(value, dtype=object).ravel()):
        raise ValueError(f"{name} must hold real numbers, got booleans: {value!r}")
    return raw.astype(np.float64)


def boolean(name: str, value: Any) -> bool:
    """``value`` if it is True or False (a NumPy bool included), else ValueError."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def vector(name: str, value: Any, lengths: Sequence[int], *, positive: bool = False) -> np.ndarray:
    """A 1-D float64 array of one of the ``lengths``, finite (and > 0 with ``positive``);
    real numbers only (:func:`real_array`)."""
    arr = real_array(name, value)
    if arr.ndim != 1 or arr.shape[0] not in lengths:
        want = " or ".join(str(n) for n in lengths)
        raise ValueError(f"{name} must have {want} numbers, got {np.asarray(value).tolist()!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()!r}")
    if positive and np.any(arr <= 0):
        raise ValueError(f"{name} must be > 0, got {arr.tolist()!r}")
    return arr


def choice(name: str, value: Any, options: Sequence[str]) -> str:
    """``value`` if it is one of ``options``, else ValueError listing them."""
    if not isinstance(value, str) or value not in options:
        raise ValueError(f"{name} must be one of {', '.join(map(repr, options))}, got {value!r}")
    return value


def rate(value: Any, name: str = "rate") -> float:
    """A servo or sampling rate in Hz: a finite real number in ``(0, config.MAX_RATE]``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a positive number of samples per second, got {value!r}")
    if float(value) > MAX_RATE:
        raise ValueError(f"{name} must be at most {MAX_RATE:g} samples per second, got {value!r}")
    return float(value)
