"""Behaviour under other process-level XLA settings, computed in one subprocess (they can
only be chosen before JAX starts): two CPU devices, as the sweep CLI asks for, and LLVM
optimisation level 0, which rounds fused computations differently."""

from __future__ import annotations

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

SCRIPT = r"""
import sys
import jax
jax.config.update("jax_num_cpu_devices", 2)
import jax.numpy as jnp
import numpy as np
from dockjax import extrema
from dockjax.algorithms import ZDT1, optimize

out = {"devices": len(jax.local_devices())}
kw = dict(seeds=[3, 4, 5], pop_size=10, n_iter=4, hv_ref=np.array([1.2, 6.0]),
          batch_params={"rho": [0.3, 0.4, 0.6]})
for label, d in (("one", 1), ("two", None)):
    r = optimize("imocs", ZDT1(n_var=5), devices=d, **kw)
    out[f"{label}_devices"] = r.extra["devices"]
    for field in ("U", "F", "G", "cv", "front", "history"):
        out[f"{label}_{field}"] = getattr(r, field)
with jax.enable_x64(True):
    rng = np.random.default_rng(0)
    c = jnp.asarray(rng.normal(size=(6, 8, 6)))
    h = jnp.asarray(rng.uniform(3.0, 10.0, size=(6, 8)))
    f = jax.jit(lambda t: jax.jvp(lambda c: extrema.span_maxima(c, h)[0], (c,), (t,))[1])
    out["maxima_jvp"] = np.asarray(f(jnp.ones_like(c)))
np.savez(sys.argv[1], **out)
"""


@pytest.fixture(scope="module")
def other_process(tmp_path_factory):
    path = tmp_path_factory.mktemp("xla") / "out.npz"
    env = {**os.environ, "XLA_FLAGS": (os.environ.get("XLA_FLAGS", "") + " --xla_backend_optimization_level=0").strip()}
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(path)], env=env, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return dict(np.load(path))


def test_runs_sharded_over_two_devices_equal_one_device(other_process):
    """``optimize`` spreads a batch of runs over the local devices (``shard_map``, each
    device its share; three runs on two devices are padded to four): the final
    populations, fronts and hypervolume histories must be bit-identical to the
    single-device program's."""
    o = other_process
    assert int(o["devices"]) == 2 and (int(o["one_devices"]), int(o["two_devices"])) == (1, 2)
    for field in ("U", "F", "G", "cv", "front", "history"):
        np.testing.assert_array_equal(o[f"two_{field}"], o[f"one_{field}"], err_msg=field)
    assert o["two_F"].shape[0] == 3 and not np.array_equal(o["two_U"][0], o["two_U"][2])


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
        here = jax.jvp(lambda c: extrema.span_maxima(c, h)[0], (c,), (jnp.ones_like(c),))[1]
    there = other_process["maxima_jvp"]
    assert np.all(np.isfinite(there))
    np.testing.assert_allclose(there, np.asarray(here), rtol=1e-9, atol=1e-9)
