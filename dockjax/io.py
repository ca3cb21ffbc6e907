"""Atomic file writing: a temporary file in the target's folder, fsync, then ``os.replace``,
so a file on disk is always either the previous one or the complete new one (an
interrupted run never leaves a half-written file). Array files carry a SHA-256 checksum of
their contents, verified on load (:func:`load_npz`), so a damaged file is recognised and
named instead of trusted."""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import zipfile
import zlib
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["DamagedFileError", "atomic_write", "atomic_write_text", "atomic_savez", "load_npz", "checksum",
           "write_set"]

CHECKSUM = "__sha256__"
"""The member of an ``.npz`` written by :func:`atomic_savez` that holds its checksum."""


class DamagedFileError(ValueError):
    """A result file that cannot be read or whose checksum does not match; names the file."""


def _usual_mode(path: str | os.PathLike) -> None:
    """mkstemp creates files with mode 0600; give them the usual 0666 & ~umask."""
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(path, 0o666 & ~mask)


def atomic_write(path: str | os.PathLike, write: Callable) -> Path:
    """Call ``write(binary file)`` on a temporary file next to ``path``, then rename it."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        _usual_mode(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write text (UTF-8) atomically."""
    return atomic_write(path, lambda fh: fh.write(text.encode()))


def checksum(arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 over every member's name, dtype, shape and bytes, in name order."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(np.asarray(arrays[name]))
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def atomic_savez(path: str | os.PathLike, arrays: dict[str, np.ndarray], *, compressed: bool = False) -> Path:
    """Write a NumPy ``.npz`` archive atomically, with its checksum (:func:`checksum`)."""
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    if CHECKSUM in arrays:
        raise ValueError(f"{CHECKSUM} is reserved")
    save = np.savez_compressed if compressed else np.savez
    return atomic_write(path, lambda fh: save(fh, **arrays, **{CHECKSUM: np.array(checksum(arrays))}))


def load_npz(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file (no pickled objects), its checksum verified when it
    has one. Raises :class:`DamagedFileError` naming the file when it cannot be read or
    does not match its checksum."""
    try:
        with np.load(path, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
        raise DamagedFileError(f"{path} is damaged or not an array file ({type(exc).__name__}: {exc})") from None
    stored = out.pop(CHECKSUM, None)
    if stored is not None and str(stored) != checksum(out):
        raise DamagedFileError(f"{path} is damaged: its contents do not match the checksum written with it")
    return out


def write_set(out: str | os.PathLike, write: Callable[[Path], list[Path]], owned: tuple[str, ...] = ()
              ) -> list[Path]:
    """Write a set of files into the folder ``out`` (created) as one: ``write(stage)`` writes
    them into a temporary folder inside ``out`` and returns their paths; only when every
    one is complete are they renamed into place, and files named in ``owned`` (every file
    the writer may make) that this set does not hold are removed, so that the folder never
    mixes two sets. A failure while writing leaves the previous set untouched and no
    temporary folder behind. Returns the final paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(dir=out, prefix=".stage-", suffix=".tmp"))
    try:
        written = write(stage)
        for f in written:
            os.replace(f, out / f.name)
        for name in set(owned) - {f.name for f in written}:
            (out / name).unlink(missing_ok=True)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return [out / f.name for f in written]
