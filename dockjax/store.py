"""Compiled programs kept on disk, so that a new process loads the planner's and the
kernel's programs instead of tracing and compiling them again.

:func:`stored_jit` is ``jax.jit`` plus a store: the first call of a new shape in a process
looks for the compiled program in the store's folder (:func:`folder`), loads it when found
(``jax.experimental.serialize_executable``: no tracing, no lowering, no compilation) and
otherwise compiles it through ``jax.jit`` and saves it there. Later calls of that shape in
the process use the loaded program directly.

The store is dockjax's own: it does not touch JAX's configuration (the persistent
compilation cache stays the application's choice; see
:func:`dockjax.runtime.enable_compilation_cache`), and it only ever holds dockjax's own
module-level functions. A program's key (:func:`key`) is a SHA-256 digest of everything
that decides what the compiled program computes:

* the function's module and name, and a digest of every source file of the package (any
  edit of dockjax's code gives new keys);
* the call's static arguments and its argument structure (the pytree, whose static fields
  — a problem's family, right-arm mode and jerk nodes — are ints, bools, strings or None),
  each array's shape, dtype and weak type;
* JAX's version and the jaxlib version, JAX's tracing configuration (64-bit mode and the
  other options JAX itself keys its traces on), ``XLA_FLAGS``, the backend's platform
  and version, the device kind and the number of devices.

A call whose key cannot be formed this way (an argument that is a tracer, an array on
another device, a static field of another type) goes through ``jax.jit`` as usual. So
does every call when the store is off (``$DOCKJAX_PROGRAMS=off``). A file that cannot be
read or loaded is compiled again and replaced; one that cannot be written (a read-only
folder) is skipped: the store only ever saves time. Processes that need the same new
program at once compile it once: the others wait for it (a lock file beside it) and load
it. The program compiled in a call is checked and gives that call's result (one run); a
program laid out on several devices is run but not kept. It keeps within :data:`MAX_BYTES`,
removing the files least recently saved or loaded. Files are written whole (a temporary
file renamed into place), so concurrent processes never read a partial one. The files are
pickles: the folder is trusted as the Python path is (by default it is in the user's own
cache folder).

A :class:`dockjax.plan.Planner` keeps its template there too (:func:`dockjax.plan.template`).
"""

from __future__ import annotations

import contextlib
import enum
import functools
import hashlib
import os
import pickle
import time
from pathlib import Path
from typing import Callable

import jax
import jax.numpy as jnp
import jaxlib
import numpy as np
from jax._src import config as jax_config  # JAX's own trace key (:func:`_trace_options`); no public API has it
from jax.experimental import serialize_executable

from .io import atomic_write

try:  # POSIX file locks (:func:`_compiling`); elsewhere the store works without them
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

__all__ = ["stored_jit", "StoredFunction", "folder", "key", "source_digest", "touch", "prune", "MAX_BYTES",
           "PROGRAMS_OFF"]

FORMAT = 1
"""Version of the store's file layout (part of every key)."""

MAX_BYTES = 4 << 30
"""The store's size limit (bytes): past it, the files least recently saved or loaded are
removed (:func:`prune`)."""

PROGRAMS_OFF = ("off", "0", "none", "")
"""Values of ``$DOCKJAX_PROGRAMS`` that turn the store off."""

_SIMPLE = (type(None), bool, int, float, str, np.bool_, np.integer, np.floating)


def folder() -> Path | None:
    """The store's folder: ``$DOCKJAX_PROGRAMS``, else ``~/.cache/dockjax/programs``; None
    when ``$DOCKJAX_PROGRAMS`` is ``off`` (or ``0``, ``none``, empty). Read at each new
    shape, so that a program may set it before its first call."""
    value = os.environ.get("DOCKJAX_PROGRAMS")
    if value is None:
        return Path.home() / ".cache" / "dockjax" / "programs"
    if value.strip().lower() in PROGRAMS_OFF:
        return None
    return Path(value).expanduser()


@functools.cache
def source_digest() -> str:
    """SHA-256 over the package's source files (relative path and bytes, in sorted order)."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def _simple(value) -> bool:
    """Whether ``value`` is made of None, bools, numbers, strings, enums and tuples of them
    (whose repr is exact and the same in every process)."""
    if isinstance(value, (tuple, list)):
        return all(_simple(v) for v in value)
    return isinstance(value, _SIMPLE) or isinstance(value, enum.Enum)


def _structure_ok(tree) -> bool:
    """Whether every node's static data of the pytree structure ``tree`` is :func:`_simple`."""
    node = tree.node_data()
    if node is not None and not _simple(node[1]):
        return False
    return all(_structure_ok(child) for child in tree.children())


def _trace_options() -> str:
    """JAX's tracing configuration (the values ``jax.jit`` keys its own traces on) and the
    64-bit mode, as text; options that are not plain values (the axis environment, empty
    outside a transformation) are left out."""
    items = [v for v in jax_config.trace_context() if _simple(v)]
    return repr((items, str(jax.typeof(1.0).dtype)))


def _environment() -> str:
    """JAX, jaxlib, XLA flags, and the default backend's platform, version, device kind and
    device count."""
    devices = jax.devices()
    return repr((jax.__version__, jaxlib.__version__, os.environ.get("XLA_FLAGS", ""), devices[0].platform,
                 devices[0].client.platform_version, devices[0].device_kind, len(devices)))


def key(fun: Callable, static: tuple, tree, avals: tuple) -> str:
    """The store's key (hex SHA-256) of ``fun`` called with ``static`` arguments and dynamic
    arguments of pytree structure ``tree`` and abstract values ``avals``."""
    text = repr((FORMAT, fun.__module__, fun.__qualname__, static, str(tree), tuple(str(a) for a in avals),
                 _trace_options(), _environment(), source_digest()))
    return hashlib.sha256(text.encode()).hexdigest()


def _plain_leaf(leaf) -> bool:
    """A leaf the store can take: a NumPy array or scalar, a Python number, or a JAX array
    on the default device alone (not a tracer)."""
    if isinstance(leaf, jax.core.Tracer):
        return False
    if isinstance(leaf, jax.Array):
        devices = leaf.sharding.device_set
        return len(devices) == 1 and next(iter(devices)) == jax.devices()[0]
    return isinstance(leaf, (np.ndarray, np.generic, bool, int, float, complex))


def _leaf_signature(leaf):
    """What decides a :func:`_plain_leaf`'s abstract value under a given tracing
    configuration (``jax.typeof``: shape, dtype, weak type), cheaper to form than that
    value: a JAX array's abstract value; a NumPy array's or scalar's type, shape and dtype;
    a Python number's type (Python numbers are weakly typed). None for a leaf the store
    cannot take."""
    if not _plain_leaf(leaf):
        return None
    if isinstance(leaf, jax.Array):
        return type(leaf), leaf.aval
    return type(leaf), getattr(leaf, "shape", None), getattr(leaf, "dtype", None)


class StoredFunction:
    """``jax.jit(fun, static_argnums=...)`` whose compiled programs are kept in the store
    (:func:`stored_jit`). Attributes of the jitted function (``lower``, ``trace``, ...)
    are those of ``jax.jit``'s."""

    def __init__(self, fun: Callable, static_argnums: tuple[int, ...] = ()):
        self.fun = fun
        self.static_argnums = tuple(static_argnums)
        self.jitted = jax.jit(fun, static_argnums=self.static_argnums)
        self._loaded: dict = {}
        functools.update_wrapper(self, fun)

    def __getattr__(self, name):
        return getattr(self.__dict__["jitted"], name)

    def __call__(self, *args):
        static = tuple(args[i] for i in self.static_argnums)
        dynamic = tuple(a for i, a in enumerate(args) if i not in self.static_argnums)
        leaves, tree = jax.tree.flatten(dynamic)
        signature = tuple(map(_leaf_signature, leaves))
        if None in signature:
            return self.jitted(*args)
        memo = (static, tree, signature, jax_config.trace_context())
        program = self._loaded.get(memo)
        if program is None:
            avals = tuple(jax.typeof(leaf) for leaf in leaves)
            found = self._program(args, static, tree, avals)
            if found is None:
                return self.jitted(*args)
            program, result = found
            self._loaded[memo] = program
            if result is not None:  # computed while the program was checked before saving
                return result
        return program(*dynamic)

    def _program(self, args, static, tree, avals):
        """The compiled program of this call and, when it was compiled here, its result on
        this call's arguments (else None): from the store, else compiled and saved. None
        when the call's key cannot be formed (the store is off, or a static value or static
        field is not a plain value). While one process compiles a program, another that
        wants the same one waits for it and loads it (a lock file beside it), rather than
        compiling it too."""
        where = folder()
        if where is None or not _simple(static) or not _structure_ok(tree):
            return None
        name = key(self.fun, static, tree, avals)
        path = where / f"{name}.program"
        try:
            return _load(path, name), None
        except Exception:  # absent, damaged, or from another version: compile anew
            pass
        with _compiling(path):
            try:  # saved by another process meanwhile
                return _load(path, name), None
            except Exception:
                pass
            lowered = self.jitted.lower(*args)
            if jax.config.jax_compilation_cache_dir:  # compiled afresh, not loaded from JAX's cache (NONCE_OPTION)
                compiled = lowered.compile(compiler_options={NONCE_OPTION: time.time_ns() % 1_000_000 + 16})
            else:
                compiled = lowered.compile()
            dynamic = tuple(a for i, a in enumerate(args) if i not in self.static_argnums)
            return compiled, _save(path, name, compiled, dynamic)


@contextlib.contextmanager
def _compiling(path: Path):
    """Hold an exclusive lock on ``path``'s lock file (``<key>.lock``, created as needed)
    for as long as the program is being compiled and saved. No lock where the folder
    cannot be written or the platform has no ``fcntl``: then two processes may both
    compile, and the second file written replaces the first (each is whole)."""
    handle = None
    if fcntl is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            handle = open(path.with_suffix(".lock"), "a")
            fcntl.flock(handle, fcntl.LOCK_EX)
        except OSError:
            if handle is not None:
                handle.close()
            handle = None
    try:
        yield
    finally:
        if handle is not None:
            handle.close()  # releases the lock


NONCE_OPTION = "xla_debug_buffer_assignment_show_max"
"""An XLA option of debugging printouts only (no effect on the program), set to a fresh
value for each compilation the store saves while JAX's persistent cache is in use. XLA:CPU
serialises an executable that JAX's cache loaded without its code (the copy fails when
run: :func:`_save` checks); a fresh value gives the compilation a key of its own in that
cache, so that it is compiled, not loaded (and the cache keeps one entry that is not read
again)."""


def _load(path: Path, name: str):
    """The program saved in ``path`` under the key ``name``; raises unless the file holds
    that key, in this format, with the SHA-256 digest of its payload."""
    record = pickle.loads(path.read_bytes())
    payload, in_tree, out_tree = record["program"]
    if (record["format"], record["key"], record["sha256"]) != (FORMAT, name, hashlib.sha256(payload).hexdigest()):
        raise ValueError(f"{path} is not the program {name}")
    _prepare_linear_algebra()
    program = serialize_executable.deserialize_and_load(payload, in_tree, out_tree, execution_devices=_device())
    touch(path)
    return program


@functools.cache
def _prepare_linear_algebra() -> None:
    """Set up the process's linear algebra routines before a program is loaded. On the CPU,
    a compiled program calls LAPACK (a Cholesky factorisation, an eigendecomposition) through
    function pointers that jaxlib sets when the process first lowers such an operation; a
    program loaded from the store is not lowered, and would call unset pointers (a
    segmentation fault). Lowering one small Cholesky factorisation sets them (nothing is
    compiled); on other platforms it does no harm."""
    jax.jit(jnp.linalg.cholesky).lower(jnp.eye(2))


def touch(path: Path) -> None:
    """Mark a file of the store as used now (its modification time; :func:`prune` removes
    the least recently used first). Nothing happens in a read-only folder."""
    try:
        os.utime(path)
    except OSError:
        pass


def prune(where: Path) -> None:
    """Remove the store's files (programs and :func:`dockjax.plan.template` fronts) least
    recently saved or loaded until the rest take at most :data:`MAX_BYTES`."""
    files = []
    for path in [*where.glob("*.program"), *where.glob("*.template.npz")]:
        try:
            st = path.stat()
        except OSError:  # removed meanwhile by another process
            continue
        files.append((st.st_mtime, st.st_size, path))
    total = sum(size for _, size, _ in files)
    for _, size, path in sorted(files, key=lambda f: f[0]):
        if total <= MAX_BYTES:
            break
        path.unlink(missing_ok=True)
        path.with_suffix(".lock").unlink(missing_ok=True)
        total -= size


def _save(path: Path, name: str, compiled, dynamic: tuple):
    """Write ``compiled`` to ``path`` (under the key ``name``, with its payload's digest)
    once a copy loaded from the bytes computes, on the call's own arguments ``dynamic``, bit
    for bit what ``compiled`` does (anything else, or a folder that cannot be written, and
    nothing is saved). → ``compiled``'s result on ``dynamic`` when it was computed, else None."""
    result = None
    if _device_count(compiled) > 1:  # a stored program is loaded onto one device (_device)
        return result
    try:
        payload, in_tree, out_tree = serialize_executable.serialize(compiled)
        data = pickle.dumps({"format": FORMAT, "key": name, "sha256": hashlib.sha256(payload).hexdigest(),
                             "program": (payload, in_tree, out_tree)})
        copy = serialize_executable.deserialize_and_load(*pickle.loads(data)["program"], execution_devices=_device())
        result = compiled(*dynamic)
        want, got = jax.tree.leaves(result), jax.tree.leaves(copy(*dynamic))
        if len(want) != len(got) or not all(_same_bits(a, b) for a, b in zip(want, got)):
            return result
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, lambda fh: fh.write(data))
        prune(path.parent)
    except Exception:  # an executable that does not serialise, a read-only folder, a full disk
        pass
    return result


def _device_count(compiled) -> int:
    """The number of devices a compiled program's inputs and outputs are laid out on (a
    program that shares its work out over several devices is not kept: loaded onto one
    device, XLA aborts the process)."""
    shardings = jax.tree.leaves((compiled.input_shardings, compiled.output_shardings),
                                is_leaf=lambda s: isinstance(s, jax.sharding.Sharding))
    return max((len(s.device_set) for s in shardings), default=1)


def _device() -> list:
    """The device a stored program runs on: JAX's default one (the programs are compiled
    for one device, also in a process with several)."""
    return jax.devices()[:1]


def _same_bits(a, b) -> bool:
    """Whether two arrays have the same dtype, shape and bytes."""
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def stored_jit(fun: Callable | None = None, *, static_argnums: tuple[int, ...] = ()):
    """Decorator: :class:`StoredFunction` of ``fun`` (a module-level function of dockjax;
    ``static_argnums`` as for ``jax.jit``)."""
    if fun is None:
        return functools.partial(stored_jit, static_argnums=static_argnums)
    return StoredFunction(fun, static_argnums)
