"""Atomic file writing: a temporary file in the target's folder, fsync, then ``os.replace``,
so a file on disk is always either the previous one or the complete new one (an
interrupted run never leaves a half-written file). Array files carry a SHA-256 checksum of
their contents, verified on load (:func:`load_npz`), so a damaged file is recognised and
named instead of trusted."""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import shutil
import signal
import stat
import sys
import tempfile
import threading
import time
import zipfile
import zlib
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["DamagedFileError", "FolderBusyError", "FolderLock", "LOCK_NAME", "atomic_write", "atomic_write_text",
           "atomic_savez", "load_npz", "checksum", "write_set", "make_folders", "check_input_file", "TEMP_PREFIX"]

CHECKSUM = "__sha256__"
"""The member of an ``.npz`` written by :func:`atomic_savez` that holds its checksum."""


TEMP_PREFIX = ".dockjax-"
"""Prefix of every temporary file and folder dockjax makes beside its outputs: files with it
are dockjax's own, and only those are ever removed as stale."""

LOCK_NAME = ".dockjax.lock"
"""The lock file inside a folder that one process writes (:class:`FolderLock`)."""


class DamagedFileError(ValueError):
    """A result file that cannot be read or whose checksum does not match; names the file."""


class FolderBusyError(ValueError):
    """Another process holds the folder (:class:`FolderLock`); names it."""


def _holder(fd: int, wait: float = 1.0) -> str:
    """What the lock file open at ``fd`` says of its holder: ``"PID … (command)"``. The
    holder writes it just after taking the lock, so an empty file is read again for up to
    ``wait`` seconds before settling for ``"another process"``."""
    deadline = time.monotonic() + wait
    while True:
        text = os.pread(fd, 4096, 0).decode(errors="replace").strip()
        if text or time.monotonic() >= deadline:
            return text or "another process"
        time.sleep(0.01)


class FolderLock:
    """One writer per folder: an advisory lock (``flock``) on :data:`LOCK_NAME` inside it,
    held from :meth:`acquire` to :meth:`release` (or the end of a ``with`` block). The
    operating system releases it when the process ends, however it ends, so a lock left
    by a killed process is no obstacle. While held, the file names the holder's PID and
    command, which a second process is told when it is refused. Within one process the
    lock is re-entrant: a writer that holds a folder may call code that takes it again."""

    _held: dict[Path, list[int]] = {}
    """Folders this process holds: resolved path → [file descriptor, depth]."""

    def __init__(self, folder: str | os.PathLike, command: str | None = None):
        self.folder = Path(folder)
        self.command = command or " ".join([Path(sys.argv[0]).name if sys.argv else "python", *sys.argv[1:]])
        self._key: Path | None = None
        self.created_file = False
        """Whether this lock's acquisition created the lock file (the folder had none)."""

    def acquire(self) -> "FolderLock":
        """Take the lock (the folder must exist), or raise :class:`FolderBusyError`."""
        key = self.folder.resolve()
        if key in FolderLock._held:
            FolderLock._held[key][1] += 1
            self._key = key
            return self
        path = key / LOCK_NAME
        while True:
            existed = path.exists()
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = _holder(fd)
                os.close(fd)
                raise FolderBusyError(f"{self.folder} is in use by {holder}; wait for it to finish or use another "
                                      "folder") from None
            try:  # the file locked must still be the folder's (its holder may have removed it)
                same = os.fstat(fd).st_ino == os.stat(path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, f"PID {os.getpid()} ({self.command})".encode())
        FolderLock._held[key] = [fd, 1]
        self._key = key
        self.created_file = not existed
        return self

    def release(self, *, remove: bool = False) -> None:
        """Release the lock; with ``remove`` (and when this process held the folder only
        through this lock) remove the lock file too, as one does with a folder left as it
        was found."""
        if self._key is None:
            return
        held = FolderLock._held[self._key]
        held[1] -= 1
        if held[1] == 0:
            if remove:
                (self._key / LOCK_NAME).unlink(missing_ok=True)  # while held: no one else has it
            os.close(held[0])
            del FolderLock._held[self._key]
        self._key = None

    def __enter__(self) -> "FolderLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def check_input_file(path: str | os.PathLike, what: str, max_bytes: int) -> Path:
    """``path`` if it is a regular file of at most ``max_bytes``, else ValueError naming
    ``what``: a FIFO, a device such as /dev/zero or a folder is refused before it is read,
    so that reading it cannot block or exhaust the memory."""
    path = Path(path)
    try:
        st = path.stat()
    except OSError as exc:
        raise ValueError(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{what} {path} is not a regular file")
    if st.st_size > max_bytes:
        raise ValueError(f"{what} {path} is {st.st_size} bytes, more than the {max_bytes} such a file may hold")
    return path


def make_folders(path: str | os.PathLike) -> list[Path]:
    """Create ``path`` and its missing parents; the folders created, outermost first (so
    that a caller can remove what it made). Raises OSError."""
    path = Path(path)
    missing = []
    p = path
    while not p.exists():
        missing.append(p)
        p = p.parent
    created = []
    for p in reversed(missing):
        p.mkdir()
        created.append(p)
    return created


def _usual_mode(path: str | os.PathLike) -> None:
    """mkstemp creates files with mode 0600; give them the usual 0666 & ~umask."""
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(path, 0o666 & ~mask)


def atomic_write(path: str | os.PathLike, write: Callable) -> Path:
    """Call ``write(binary file)`` on a temporary file next to ``path``, then rename it."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f"{TEMP_PREFIX}{path.name}.", suffix=".tmp")
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


def load_npz(path: str | os.PathLike, *, require_checksum: bool = False) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file (no pickled objects), its checksum verified when it
    has one (and required with ``require_checksum``). Raises :class:`DamagedFileError`
    naming the file when it cannot be read, has no checksum where one is required, or does
    not match its checksum."""
    try:
        with np.load(path, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
        raise DamagedFileError(f"{path} is damaged or not an array file ({type(exc).__name__}: {exc})") from None
    stored = out.pop(CHECKSUM, None)
    if stored is None and require_checksum:
        raise DamagedFileError(f"{path} carries no checksum, so it cannot prove its contents")
    if stored is not None and str(stored) != checksum(out):
        raise DamagedFileError(f"{path} is damaged: its contents do not match the checksum written with it")
    return out


@contextlib.contextmanager
def _interrupts_deferred():
    """Ctrl-C (SIGINT) held back while the block runs and delivered after it (in the main
    thread; elsewhere the block runs as it is)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def write_set(out: str | os.PathLike, write: Callable[[Path], list[Path]], owned: tuple[str, ...] = ()
              ) -> list[Path]:
    """Write a set of files into the folder ``out`` (created) as one: ``write(stage)`` writes
    them into a temporary folder inside ``out`` and returns their paths; only when every
    one is complete are they renamed into place, and files named in ``owned`` (every file
    the writer may make) that this set does not hold are removed, so that the folder never
    mixes two sets. The folder is held (:class:`FolderLock`) while the set is written, and
    the staging folders of a writer that was killed are removed. A failure while writing
    leaves the previous set untouched and no temporary folder behind. Returns the final
    paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with FolderLock(out):
        for stale in out.glob(f"{TEMP_PREFIX}stage-*.tmp"):  # a set whose writer was killed
            shutil.rmtree(stale, ignore_errors=True)
        stage = Path(tempfile.mkdtemp(dir=out, prefix=f"{TEMP_PREFIX}stage-", suffix=".tmp"))
        try:
            written = write(stage)
            with _interrupts_deferred():  # the renames happen all or none
                for f in written:
                    os.replace(f, out / f.name)
                for name in set(owned) - {f.name for f in written}:
                    (out / name).unlink(missing_ok=True)
        finally:
            shutil.rmtree(stage, ignore_errors=True)
    return [out / f.name for f in written]
