"""The process-wide settings a command line makes before its first JAX computation: the
persistent compilation cache and the number of CPU devices. The library's computations
never call these by themselves (JAX's configuration belongs to the application); the CLIs
and the benchmarks do, and a Python program opts in with one call of
:func:`enable_compilation_cache` (also ``dockjax.enable_compilation_cache``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import jax

from . import checks

__all__ = ["enable_compilation_cache", "usable_cores", "use_cpu_devices", "claim_devices", "available_memory",
           "check_memory"]


CACHE_OFF = ("off", "0", "none", "")
"""Values of ``$DOCKJAX_CACHE`` that turn the persistent compilation cache off."""


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path | None:
    """Use JAX's persistent compilation cache, so that a new process reuses the programs an
    earlier one compiled: every program, the optimisers' too. (The kernel's and the
    planner's programs are loaded from dockjax's own store, :mod:`dockjax.store`, with or
    without it.)

    The folder: ``path``, else ``$DOCKJAX_CACHE``, else ``~/.cache/dockjax/jax``; every
    program is kept, however quick its compilation. A cache the application configured
    itself (``jax_compilation_cache_dir``, also set by JAX's ``JAX_COMPILATION_CACHE_DIR``)
    is left as it is, with its own settings, unless ``path`` is given; otherwise
    ``$DOCKJAX_CACHE=off`` (or ``0``, ``none``, empty) turns it off, as does a folder that
    cannot be made (a read-only home). Returns the folder in use, or None."""
    configured = jax.config.jax_compilation_cache_dir
    if path is None:
        if configured:
            return Path(configured)
        path = os.environ.get("DOCKJAX_CACHE", str(Path.home() / ".cache" / "dockjax" / "jax"))
        if path.strip().lower() in CACHE_OFF:
            return None
    folder = Path(path).expanduser()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    return folder


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


def use_cpu_devices(n: int) -> int:
    """Ask JAX for ``n`` CPU devices (before the process's first JAX computation). Batched
    runs of :func:`dockjax.optimize.optimize` and the rows of
    :meth:`dockjax.DockingProblem.evaluate` are then shared out over them
    (:mod:`dockjax.devices`). Returns the number of CPU devices JAX has: unchanged if its
    backend was already initialised."""
    try:
        jax.config.update("jax_num_cpu_devices", int(n))
    except RuntimeError:  # the backend exists already
        pass
    return len(jax.devices("cpu"))


def claim_devices(devices: int | None) -> int:
    """A command line's ``--devices`` (None: one per usable core): ask JAX for that many CPU
    devices. → the count JAX has. Raises ValueError, naming the option, for anything but an
    integer >= 1; notes on stderr when JAX's backend already had another count."""
    checks.optional_integer("--devices", devices, 1)
    have = use_cpu_devices(devices or usable_cores())
    if devices is not None and have != devices:
        print(f"note: JAX's CPU backend was already initialised with {have} device(s); using them",
              file=sys.stderr)
    return have


def available_memory() -> int:
    """Bytes of memory available to this process: ``MemAvailable`` of /proc/meminfo, else
    the physical memory (os.sysconf), else 2**40 where neither is known."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 1 << 40


def check_memory(need: float, what: str) -> None:
    """ValueError naming ``what`` when an estimated ``need`` (bytes) exceeds the memory
    available (:func:`available_memory`)."""
    have = available_memory()
    if need > have:
        raise ValueError(f"{what} needs about {need / 2**30:.3g} GiB of memory, more than the {have / 2**30:.3g} GiB "
                         "available; ask for less")
