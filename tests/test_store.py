"""The store of compiled programs (:mod:`dockjax.store`): a program is loaded rather than
compiled when, and only when, everything that decides it is the same; its results are
bit for bit those of ``jax.jit``; a damaged, unwritable or switched-off store never
changes a result.

Reference: plain ``jax.jit`` of the same function (JAX's own compilation, no store)."""

from __future__ import annotations

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from dockjax import store
from dockjax.pytrees import pytree_dataclass, static


@pytree_dataclass
class _Spec:
    """A small pytree like a problem: an array leaf and a static field."""

    scale: np.ndarray
    power: int = static(2)


@pytree_dataclass
class _ArrayStatic:
    """A pytree whose static field is an array (its repr is not exact): never stored."""

    scale: np.ndarray
    table: np.ndarray = static(None)


def _kernel(spec, x):
    """A function of a pytree and an array (the shape of dockjax's programs)."""
    return jnp.sum(spec.scale * jnp.sin(x) ** spec.power), jnp.cumsum(x)


def _scaled(flag, x):
    return x * (3.0 if flag else 0.5)


def _array_static(spec, x):
    return spec.scale * x


class _NoCompile:
    """Stands in for ``jax.jit`` of a stored function: fails if the store compiles."""

    def lower(self, *args):
        raise AssertionError("compiled instead of loaded")

    def __call__(self, *args):
        raise AssertionError("traced instead of loaded")


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.setenv("DOCKJAX_PROGRAMS", str(tmp_path / "programs"))
    return tmp_path / "programs"


def _files(folder):
    return sorted(p.name for p in folder.glob("*.program")) if folder.exists() else []


def _equal(a, b):
    for u, v in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        assert np.asarray(u).dtype == np.asarray(v).dtype
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))


def test_a_program_is_saved_once_and_loaded_bit_for_bit(folder):
    spec, x = _Spec(np.array([1.0, 2.0, 3.0])), np.linspace(0.1, 2.0, 3)
    f = store.stored_jit(_kernel)
    out = f(spec, x)
    _equal(out, jax.jit(_kernel)(spec, x))
    assert len(_files(folder)) == 1
    f(spec, x * 2.0)  # other values of the same shapes: the same program
    assert len(_files(folder)) == 1
    fresh = store.stored_jit(_kernel)  # as in a new process: nothing loaded yet
    fresh.__dict__["jitted"] = _NoCompile()
    _equal(fresh(spec, x), out)
    other = _Spec(np.array([-1.0, 0.5, 4.0]))  # other leaf values: loaded, computed with them
    _equal(fresh(other, x), jax.jit(_kernel)(other, x))


def test_a_program_another_process_is_compiling_is_waited_for_and_loaded(folder):
    import fcntl
    import threading

    spec, x = _Spec(np.array([1.0, 2.0, 3.0])), np.linspace(0.1, 2.0, 3)
    out = store.stored_jit(_kernel)(spec, x)
    (name,) = _files(folder)
    program = folder / name
    saved = program.read_bytes()
    program.unlink()
    fresh = store.stored_jit(_kernel)  # a new process: nothing loaded, and it must not compile
    fresh.__dict__["jitted"] = _NoCompile()
    got = {}
    with open(program.with_suffix(".lock"), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another process is compiling the program
        waiter = threading.Thread(target=lambda: got.update(out=fresh(spec, x)))
        waiter.start()
        waiter.join(1.0)
        assert waiter.is_alive(), "did not wait for the program being compiled"
        program.write_bytes(saved)  # ... and saves it
    waiter.join(60)
    _equal(got["out"], out)


def test_whatever_decides_the_program_gives_another_key(folder, monkeypatch):
    spec, x = _Spec(np.ones(3)), np.linspace(0.1, 2.0, 3)
    f = store.stored_jit(_kernel)
    f(spec, x)
    seen = set(_files(folder))

    def new_file(call):
        before = set(_files(folder))
        call()
        added = set(_files(folder)) - before
        assert len(added) == 1, added
        return added

    new_file(lambda: f(_Spec(np.ones(4)), np.linspace(0.1, 2.0, 4)))  # a shape
    new_file(lambda: f(spec, np.arange(3, dtype=np.int32)))  # a dtype
    new_file(lambda: f(_Spec(np.ones(3), power=3), x))  # a static field
    new_file(lambda: f(spec, 0.5))  # a weakly typed Python number
    with jax.enable_x64(True):
        new_file(lambda: f(spec, x))  # 64-bit mode
    g = store.stored_jit(_scaled, static_argnums=(0,))
    new_file(lambda: g(True, x))
    new_file(lambda: g(False, x))  # a static argument
    _equal(g(False, x), jax.jit(_scaled, static_argnums=0)(False, x))
    monkeypatch.setattr(store, "source_digest", lambda: "edited")
    new_file(lambda: store.stored_jit(_kernel)(spec, x))  # the package's source
    monkeypatch.setenv("XLA_FLAGS", os.environ.get("XLA_FLAGS", "") + " --xla_cpu_enable_fast_min_max=false")
    new_file(lambda: store.stored_jit(_kernel)(spec, x))  # the XLA flags
    assert seen <= set(_files(folder))


LEAVES = st.sampled_from([
    lambda: 0.5, lambda: 2, lambda: True, lambda: 1j, lambda: np.float64(0.5), lambda: np.float32(0.5),
    lambda: np.int32(2), lambda: np.bool_(True), lambda: np.zeros(3), lambda: np.zeros(3, np.float32),
    lambda: np.zeros((3, 1)), lambda: np.zeros(4), lambda: np.zeros(3, np.int64), lambda: jnp.zeros(3),
    lambda: jnp.zeros(3, jnp.int32), lambda: jnp.asarray(0.5), lambda: jnp.zeros(4)])


@given(a=LEAVES, b=LEAVES, x64=st.booleans())
def test_leaves_of_one_signature_have_one_abstract_value(a, b, x64):
    # the calls of a process reuse a loaded program by the leaves' signature: it must
    # decide what jax.typeof (the reference) gives, in either precision mode
    with jax.enable_x64(x64):
        u, v = a(), b()
        if store._leaf_signature(u) == store._leaf_signature(v):
            assert jax.typeof(u) == jax.typeof(v), (u, v)


def test_a_process_runs_each_abstract_value_with_its_own_program(folder):
    f = store.stored_jit(_kernel)
    spec = _Spec(np.ones(3))
    for x in (0.5, np.float32(0.5), np.float64(0.5), np.ones(3), np.ones(3, np.float32), jnp.ones(3)):
        for x64 in (False, True):
            with jax.enable_x64(x64):
                _equal(f(spec, x), jax.jit(_kernel)(spec, x))


def test_a_damaged_file_is_compiled_again_and_replaced(folder):
    spec, x = _Spec(np.ones(3)), np.linspace(0.1, 2.0, 3)
    store.stored_jit(_kernel)(spec, x)
    (path,) = folder.glob("*.program")
    path.write_bytes(path.read_bytes()[:100])
    _equal(store.stored_jit(_kernel)(spec, x), jax.jit(_kernel)(spec, x))
    fresh = store.stored_jit(_kernel)
    fresh.__dict__["jitted"] = _NoCompile()
    _equal(fresh(spec, x), jax.jit(_kernel)(spec, x))  # the replaced file loads


def test_a_file_whose_payload_or_key_differs_is_not_loaded(folder):
    """Each file carries its key and its payload's SHA-256: a file with a flipped byte, or
    one that names another key, is compiled again rather than run."""
    import pickle

    spec, x = _Spec(np.ones(3)), np.linspace(0.1, 2.0, 3)
    store.stored_jit(_kernel)(spec, x)
    (path,) = folder.glob("*.program")
    record = pickle.loads(path.read_bytes())
    payload = bytearray(record["program"][0])
    payload[len(payload) // 2] ^= 0xFF
    flipped = {**record, "program": (bytes(payload),) + tuple(record["program"][1:])}
    for damaged in (flipped, {**record, "key": "0" * 64}):
        path.write_bytes(pickle.dumps(damaged))
        fresh = store.stored_jit(_kernel)
        fresh.__dict__["jitted"] = _NoCompile()
        with pytest.raises(AssertionError, match="compiled instead of loaded"):
            fresh(spec, x)
        _equal(store.stored_jit(_kernel)(spec, x), jax.jit(_kernel)(spec, x))  # and replaced


def test_the_store_keeps_below_its_size_by_dropping_the_least_recently_used(folder, monkeypatch):
    """Past :data:`dockjax.store.MAX_BYTES` the files least recently saved or loaded go."""
    spec = _Spec(np.ones(3))
    f = store.stored_jit(_kernel)
    f(spec, np.ones(3))
    (oldest,) = folder.glob("*.program")
    size = oldest.stat().st_size
    f(spec, np.ones((2, 3)))
    newer = set(folder.glob("*.program")) - {oldest}
    os.utime(oldest, (1e9, 1e9))
    (second,) = newer
    os.utime(second, (1.5e9, 1.5e9))
    store.stored_jit(_kernel)(spec, np.ones(3))  # loaded: becomes the most recently used
    monkeypatch.setattr(store, "MAX_BYTES", int(2.5 * size))
    f(spec, np.ones((4, 3)))  # a third file: the least recently used one goes
    left = set(folder.glob("*.program"))
    assert oldest in left and second not in left and len(left) == 2


@pytest.mark.parametrize("value", ["off", "0", "none", ""])
def test_the_store_can_be_turned_off(monkeypatch, tmp_path, value):
    monkeypatch.setenv("DOCKJAX_PROGRAMS", value)
    monkeypatch.setenv("HOME", str(tmp_path))
    spec, x = _Spec(np.ones(3)), np.linspace(0.1, 2.0, 3)
    _equal(store.stored_jit(_kernel)(spec, x), jax.jit(_kernel)(spec, x))
    assert store.folder() is None and not any(tmp_path.rglob("*.program"))


def test_an_unwritable_folder_only_costs_the_saving(monkeypatch, tmp_path):
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("DOCKJAX_PROGRAMS", str(tmp_path / "file" / "programs"))
    spec, x = _Spec(np.ones(3)), np.linspace(0.1, 2.0, 3)
    _equal(store.stored_jit(_kernel)(spec, x), jax.jit(_kernel)(spec, x))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_calls_the_store_cannot_key_go_through_jit(folder):
    spec, x = _Spec(np.ones(3)), np.linspace(0.1, 2.0, 3)
    f = store.stored_jit(_kernel)
    # inside a transformation (tracers), vmapped and differentiated
    _equal(jax.jit(f)(spec, x), jax.jit(_kernel)(spec, x))
    _equal(jax.vmap(lambda x: f(spec, x))(np.stack([x, 2 * x])),
           jax.vmap(lambda x: _kernel(spec, x))(np.stack([x, 2 * x])))
    _equal(jax.grad(lambda x: f(spec, x)[0])(x), jax.grad(lambda x: _kernel(spec, x)[0])(x))
    # a static field whose repr is not exact
    a = _ArrayStatic(np.ones(3), np.arange(3.0))
    _equal(store.stored_jit(_array_static)(a, x), jax.jit(_array_static)(a, x))
    assert _files(folder) == []


SCRIPT = r"""
import sys
import jax
jax.config.update("jax_num_cpu_devices", 2)  # as the command lines ask: the programs use one of them
import numpy as np
import dockjax
from dockjax import solve
from dockjax.problem import DockingProblem

dockjax.enable_compilation_cache()
if sys.argv[2] == "load":  # the jitted function must not be used: the program comes from the store
    class NoCompile:
        def lower(self, *a):
            raise SystemExit("compiled instead of loaded")
        __call__ = lower
    solve._jerk_value.__dict__["jitted"] = NoCompile()
problem = DockingProblem()
x = np.random.default_rng(5).uniform(problem.lower, problem.upper, (3, problem.n_var))
with jax.enable_x64(True):
    np.save(sys.argv[1], np.array([float(solve._jerk_value(problem, xi)) for xi in x]))
"""


def test_a_new_process_loads_the_kernels_program_instead_of_compiling(folder, tmp_path):
    """A dockjax program compiled in one process is loaded by the next, whose results are
    bit for bit the first's (and this process's ``jax.jit``); both processes have two CPU
    devices, as the command lines do."""
    env = {**os.environ, "DOCKJAX_PROGRAMS": str(folder)}
    for name, mode in (("first", "compile"), ("second", "load")):
        r = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path / f"{name}.npy"), mode], env=env,
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
    first, second = np.load(tmp_path / "first.npy"), np.load(tmp_path / "second.npy")
    np.testing.assert_array_equal(second, first)
    from dockjax import solve
    from dockjax.problem import DockingProblem

    problem = DockingProblem()
    x = np.random.default_rng(5).uniform(problem.lower, problem.upper, (3, problem.n_var))
    with jax.enable_x64(True):
        here = np.array([float(solve._jerk_value.jitted(problem, xi)) for xi in x])
    np.testing.assert_array_equal(first, here)


LINALG_SCRIPT = r"""
import sys
import jax
import jax.numpy as jnp
import numpy as np
from dockjax import store

def factor(a):  # XLA:CPU calls LAPACK for both
    return jnp.linalg.cholesky(a @ a.T + jnp.eye(a.shape[0])), jnp.linalg.eigh(a + a.T)[0]

f = store.stored_jit(factor)
if sys.argv[2] == "load":
    class NoCompile:
        def lower(self, *a):
            raise SystemExit("compiled instead of loaded")
        __call__ = lower
    f.__dict__["jitted"] = NoCompile()
a = np.random.default_rng(3).normal(size=(5, 5))
np.save(sys.argv[1], np.concatenate([np.ravel(v) for v in f(a)]))
"""


def test_a_new_process_loads_and_runs_a_program_that_calls_lapack(folder, tmp_path):
    """A program with a Cholesky factorisation and an eigendecomposition (as the batched
    planner's SQP has) compiled in one process runs in the next, loaded without lowering,
    bit for bit alike (such a program once crashed the loading process). Reference: NumPy's
    LAPACK on the same matrices."""
    env = {**os.environ, "DOCKJAX_PROGRAMS": str(folder)}
    for name, mode in (("first", "compile"), ("second", "load")):
        r = subprocess.run([sys.executable, "-c", LINALG_SCRIPT, str(tmp_path / f"{name}.npy"), mode], env=env,
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, f"{mode}: exit code {r.returncode}\n{r.stderr[-3000:]}"
    first, second = np.load(tmp_path / "first.npy"), np.load(tmp_path / "second.npy")
    np.testing.assert_array_equal(second, first)
    a = np.random.default_rng(3).normal(size=(5, 5)).astype(np.float32)
    want = np.concatenate([np.linalg.cholesky(a @ a.T + np.eye(5)).ravel(), np.linalg.eigvalsh(a + a.T)])
    np.testing.assert_allclose(first, want, rtol=1e-4, atol=1e-4)


SHARDED_SCRIPT = """
import sys
import jax
jax.config.update("jax_num_cpu_devices", 2)
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec
from dockjax import store

def halves(x):  # each of two devices squares its half of the rows
    mesh = Mesh(np.asarray(jax.local_devices()[:2]), ("items",))
    return jax.shard_map(lambda v: v ** 2, mesh=mesh, in_specs=PartitionSpec("items"),
                         out_specs=PartitionSpec("items"))(x)

f = store.stored_jit(halves)
out = [np.asarray(f(jnp.arange(8.0))) for _ in range(2)]
np.save(sys.argv[1], np.stack(out))
"""


def test_a_program_laid_out_on_several_devices_is_run_but_not_kept(folder, tmp_path):
    """A stored function whose program shares its work over two devices gives its result
    and is not saved (a program loaded onto one device but laid out on two made XLA abort
    the process). Reference: NumPy's squares."""
    env = {**os.environ, "DOCKJAX_PROGRAMS": str(folder)}
    r = subprocess.run([sys.executable, "-c", SHARDED_SCRIPT, str(tmp_path / "out.npy")], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, f"exit code {r.returncode}\n{r.stderr[-3000:]}"
    np.testing.assert_array_equal(np.load(tmp_path / "out.npy"), np.tile(np.arange(8.0) ** 2, (2, 1)))
    assert _files(folder) == []


def test_a_planners_template_is_saved_and_loaded_bit_for_bit(tmp_path, monkeypatch):
    """A :class:`dockjax.plan.Planner` keeps its template front in the store: a new planner
    of the same problem loads it without solving, and plans bit for bit alike; another
    ``n_front`` or problem is another file; a damaged file is solved again."""
    from dockjax import plan as P
    from dockjax.problem import DockingProblem

    problem = DockingProblem()
    goal = np.asarray(problem.goal) + np.array([2.0, -1.0, 1.0, 0.05, 0.0, 0.5])
    # the programs, loaded in this process from the run's store (the new folder then holds templates only)
    shortest, front = P._direct_front(problem, 2)  # the front solved directly
    P.Planner(problem, n_front=2).plan(goal=goal)
    folder = tmp_path / "programs"
    monkeypatch.setenv("DOCKJAX_PROGRAMS", str(folder))
    first = P.Planner(problem, n_front=2)
    np.testing.assert_array_equal(first.warm()._template, np.array([shortest.x] + [s.x for s in front]))
    (path,) = folder.glob("*.template.npz")
    a = first.plan(goal=goal)
    solve_front = P._direct_front

    def no_template_solve(q, *a, **k):  # the new move's own front is solved; the template's must not be
        if np.array_equal(q.goal, problem.goal):
            pytest.fail("the template was solved again")
        return solve_front(q, *a, **k)

    monkeypatch.setattr(P, "_direct_front", no_template_solve)
    b = P.Planner(problem, n_front=2).plan(goal=goal)
    np.testing.assert_array_equal(b.x, a.x)
    assert (b.T, b.jerk) == (a.T, a.jerk)
    assert P.template_key(problem, 3) != P.template_key(problem, 2)
    assert P.template_key(DockingProblem(goal=goal), 2) != P.template_key(problem, 2)
    path.write_bytes(path.read_bytes()[:-40])
    with pytest.raises(pytest.fail.Exception, match="solved again"):
        P.Planner(problem, n_front=2).warm()
