"""Behaviour under other process-level XLA settings, computed in one subprocess (they can
only be chosen before JAX starts): two CPU devices, as the sweep CLI asks for, and LLVM
optimisation level 0, which rounds fused computations differently, with JAX's default
(MLIR) fusion emitters where the rest of the suite compiles with the classic ones."""

from __future__ import annotations

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.conftest import TEST_FLAGS

SCRIPT = r"""
import os
import sys
import jax
jax.config.update("jax_num_cpu_devices", 2)
jax.config.update("jax_compilation_cache_dir", os.environ["DOCKJAX_CACHE"])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
import jax.numpy as jnp
import numpy as np
from dockjax import extrema
from dockjax.algorithms.zdt import ZDT1
from dockjax.optimize import optimize

out = {"devices": len(jax.local_devices())}
kw = dict(seeds=[3, 4, 5], pop_size=10, n_iter=4, hv_ref=np.array([1.2, 6.0]),
          rho=[0.3, 0.4, 0.6])
for driver in ("scan", "host"):
    for label, d in (("one", 1), ("two", None)):
        r = optimize("imocs", ZDT1(n_var=5), devices=d, driver=driver, **kw)
        out[f"{driver}_{label}_devices"] = r.extra["devices"]
        for field in ("U", "F", "G", "cv", "front", "history"):
            out[f"{driver}_{label}_{field}"] = getattr(r, field)
one = dict(seeds=[7], pop_size=11, n_iter=4, hv_ref=np.array([1.2, 6.0]), rho=0.3)
for label, d in (("one", 1), ("two", None)):
    r = optimize("imocs", ZDT1(n_var=5), devices=d, **one)
    out[f"single_{label}_layout"] = [r.extra["devices"], r.extra["share_rows"]]
    for field in ("U", "F", "front", "history"):
        out[f"single_{label}_{field}"] = getattr(r, field)
from dockjax import devices as dev
mesh = dev.mesh(jax.local_devices()[:2])
Xs = jnp.asarray(np.random.default_rng(2).normal(size=(3, 7, 4)))  # 7 rows along axis 1
def rowwise(x):  # results of two dtypes and three shapes, rows along axis 1
    return {"sum": x.sum(-1), "idx": jnp.argmax(x, -1).astype(jnp.int32), "outer": x[..., :, None] * x[..., None, :2]}
shared = jax.jit(lambda x: dev.replicated(lambda x: dev.share_rows(rowwise, 2, x, axis=1), (), mesh, x))(Xs)
for name, value in shared.items():
    out[f"share_rows_{name}"] = np.asarray(value)
    out[f"share_rows_{name}_direct"] = np.asarray(jax.jit(rowwise)(Xs)[name])
from dockjax import DockingProblem
problem = DockingProblem()
X = np.random.default_rng(1).uniform(problem.lower, problem.upper, (600, problem.n_var))
for label, d, screen in (("one", 1, False), ("two", None, False), ("two", None, True)):
    out[f"evaluate_{label}_{screen}"] = np.concatenate(problem.evaluate(X, devices=d, screen=screen), axis=1)
with jax.enable_x64(True):
    rng = np.random.default_rng(0)
    c = jnp.asarray(rng.normal(size=(6, 8, 6)))
    h = jnp.asarray(rng.uniform(3.0, 10.0, size=(6, 8)))
    f = jax.jit(lambda t: jax.jvp(lambda c: extrema.span_maxima(c, h)[0], (c,), (t,))[1])
    out["maxima_jvp"] = np.asarray(f(jnp.ones_like(c)))
np.savez(sys.argv[1], **out)
"""


@pytest.fixture(scope="module")
def other_process(tmp_path_factory, worker_id):
    """The subprocess's results, computed once per pytest run: pytest-xdist workers share
    them through a file in the run's temporary folder, under a lock (the pattern of
    pytest-xdist's documentation; without ``fcntl`` every worker computes its own)."""
    base = tmp_path_factory.getbasetemp()
    root = base if worker_id == "master" else base.parent
    path = root / "xla_settings.npz"
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        fcntl = None
    with open(root / "xla_settings.lock", "w") as lock:
        if fcntl is not None:
            fcntl.flock(lock, fcntl.LOCK_EX)
        if fcntl is None or not path.exists():
            part = root / f"xla_settings.{worker_id}.npz"
            # JAX's default code generation (tests/conftest.py's flags removed), at O0
            flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if f not in TEST_FLAGS]
            env = {**os.environ, "XLA_FLAGS": " ".join(flags + ["--xla_backend_optimization_level=0"])}
            r = subprocess.run([sys.executable, "-c", SCRIPT, str(part)], env=env, capture_output=True,
                               text=True, timeout=600)
            assert r.returncode == 0, r.stderr[-3000:]
            os.replace(part, path)
    return dict(np.load(path))


@pytest.mark.parametrize("driver", ["scan", "host"])
def test_runs_sharded_over_two_devices_equal_one_device(other_process, driver):
    """``optimize`` spreads a batch of runs over the local devices (``shard_map``, each
    device its share; three runs on two devices are padded to four), with either driver:
    the final populations, fronts and hypervolume histories must be bit-identical to the
    single-device program's."""
    o = {k[len(driver) + 1:]: v for k, v in other_process.items() if k.startswith(driver + "_")}
    assert int(other_process["devices"]) == 2 and (int(o["one_devices"]), int(o["two_devices"])) == (1, 2)
    for field in ("U", "F", "G", "cv", "front", "history"):
        np.testing.assert_array_equal(o[f"two_{field}"], o[f"one_{field}"], err_msg=field)
    assert o["two_F"].shape[0] == 3 and not np.array_equal(o["two_U"][0], o["two_U"][2])


def test_one_run_shares_its_rows_over_two_devices(other_process):
    """One run and two devices: every device runs the whole run and scores its share of
    each evaluation's rows (11 nests: 6 and 5, padded), gathering the rest from the other
    (``share_rows``). The result must be bit-identical to the single-device run's."""
    o = other_process
    assert o["single_one_layout"].tolist() == [1, 0] and o["single_two_layout"].tolist() == [2, 1]
    for field in ("U", "F", "front", "history"):
        np.testing.assert_array_equal(o[f"single_two_{field}"], o[f"single_one_{field}"], err_msg=field)
    assert o["single_two_F"].shape == (1, 11, 2) and o["single_two_history"].shape == (1, 4)


def test_share_rows_gathers_results_of_several_dtypes_and_shapes(other_process):
    """:func:`dockjax.devices.share_rows` gathers all results of one dtype in one
    ``all_gather``: 7 rows (4 and 3, padded) along axis 1 of results of two dtypes and
    three shapes must come back equal to the function on the whole array."""
    o = other_process
    for name, shape in (("sum", (3, 7)), ("idx", (3, 7)), ("outer", (3, 7, 4, 2))):
        assert o[f"share_rows_{name}"].shape == shape
        np.testing.assert_array_equal(o[f"share_rows_{name}"], o[f"share_rows_{name}_direct"], err_msg=name)
    assert o["share_rows_idx"].dtype == np.int32


def test_evaluate_shared_over_two_devices_equals_one_device(other_process):
    """``DockingProblem.evaluate`` shares 600 rows out over two devices (320 each, padded):
    without screening the scores must equal one device's to rounding (the rows sit at
    other places of the vectorised loops); with it, F likewise, and each G column between
    the exact one-device value and that plus the screen's allowance (a column outside the
    screen's band may overstate by at most :data:`dockjax.limits.SCREEN_SLACK`, never
    understate)."""
    from dockjax.limits import SCREEN_SLACK

    o = other_process
    one, two, screened = o["evaluate_one_False"], o["evaluate_two_False"], o["evaluate_two_True"]
    assert one.shape == two.shape == screened.shape == (600, 26) and np.all(np.isfinite(one))
    np.testing.assert_allclose(two[:, :2], one[:, :2], rtol=1e-12)
    np.testing.assert_allclose(two[:, 2:], one[:, 2:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(screened[:, :2], one[:, :2], rtol=1e-12)
    excess = screened[:, 2:] - one[:, 2:]
    assert excess.min() >= -1e-12 and excess.max() <= SCREEN_SLACK, (excess.min(), excess.max())


def test_derivative_of_the_maxima_survives_recomputation(other_process):
    """JAX's own derivative of ``max`` compares the operand with the result for equality
    and divides by the count; when XLA computes the operand twice with different rounding,
    nothing compares equal and it returns 0/0. XLA:CPU does so at LLVM optimisation level
    0, which made the limits' gradient NaN (this test failed with ``jnp.max``: 77 of 144
    entries). :func:`dockjax.extrema.reduce_max` selects by argmax instead: the derivative
    must be finite and equal to this process's (default optimisation level)."""
    from dockjax import extrema

    rng = np.random.default_rng(0)
    with jax.enable_x64(True):
        c = jnp.asarray(rng.normal(size=(6, 8, 6)))
        h = jnp.asarray(rng.uniform(3.0, 10.0, size=(6, 8)))
        # jitted as in the subprocess (op by op, the chain's loops took ~13 s here)
        here = jax.jit(lambda t: jax.jvp(lambda c: extrema.span_maxima(c, h)[0], (c,), (t,))[1])(jnp.ones_like(c))
    there = other_process["maxima_jvp"]
    assert np.all(np.isfinite(there))
    np.testing.assert_allclose(there, np.asarray(here), rtol=1e-9, atol=1e-9)
