"""Indicators (dockjax.metrics) against moocore and plain NumPy; the choice of one solution.

References: ``moocore.igd``, ``moocore.igd_plus`` and ``moocore.hypervolume`` agree with our
definitions exactly. GD and SP are checked against NumPy written here, because pymoo and
moocore define them differently (pymoo's GD is the mean distance, moocore's GD_p a power mean;
pymoo's SP divides by n, Schott's by n − 1).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import moocore
import numpy as np
import pytest

from dockjax import metrics, select

TOL = 1e-12
N, R = 24, 40  # one set size and one reference size, so jit compiles few shapes

gd = jax.jit(metrics.gd)
sp = jax.jit(metrics.sp)
igd = jax.jit(metrics.igd)
igd_plus = jax.jit(metrics.igd_plus)
hypervolume = jax.jit(metrics.hypervolume)
onvg = jax.jit(metrics.onvg)


def _front(rng: np.random.Generator, n: int, noise: float = 0.0) -> np.ndarray:
    """A convex 2-D front f2 = (1 − sqrt f1)², optionally pushed back by noise."""
    f1 = rng.random(n)
    F = np.stack([f1, (1 - np.sqrt(f1)) ** 2], axis=1)
    return F + noise * rng.random((n, 2))


# ----------------------------------------------------------------- plain NumPy references
def np_gd(F: np.ndarray, ref: np.ndarray) -> float:
    d = np.sqrt(((F[:, None, :] - ref[None, :, :]) ** 2).sum(-1)).min(axis=1)
    return float(np.sqrt((d**2).sum()) / len(F))


def np_sp(F: np.ndarray) -> float:
    n = len(F)
    d = np.array(
        [min(np.abs(F[i] - F[j]).sum() for j in range(n) if j != i) for i in range(n)]
    )
    return float(np.sqrt(((d.mean() - d) ** 2).sum() / (n - 1)))


def np_onvg(F: np.ndarray, valid: np.ndarray) -> int:
    P = F[valid]
    keep = []
    for i, p in enumerate(P):
        dominated = any(np.all(q <= p) and np.any(q < p) for q in P)
        if not dominated:
            keep.append(tuple(p))
    return len(set(keep))


# ------------------------------------------------------------------- moocore agreement
@pytest.mark.parametrize("seed", range(4))
def test_igd_igdplus_hv_match_moocore(x64, seed):
    rng = np.random.default_rng(seed)
    A = _front(rng, N, noise=0.2)
    Z = _front(rng, R)
    assert float(igd(A, Z)) == pytest.approx(moocore.igd(A, ref=Z), abs=TOL, rel=TOL)
    assert float(igd_plus(A, Z)) == pytest.approx(moocore.igd_plus(A, ref=Z), abs=TOL, rel=TOL)
    # Some points beyond the reference point: both must ignore them.
    ref = np.array([0.9, 0.8])
    assert float(hypervolume(A, ref)) == pytest.approx(
        moocore.hypervolume(A, ref=ref), abs=TOL, rel=TOL
    )


def test_igd_three_objectives_match_moocore(x64):
    rng = np.random.default_rng(7)
    A, Z = rng.random((N, 3)), rng.random((R, 3))
    assert float(igd(A, Z)) == pytest.approx(moocore.igd(A, ref=Z), abs=TOL, rel=TOL)
    assert float(igd_plus(A, Z)) == pytest.approx(moocore.igd_plus(A, ref=Z), abs=TOL, rel=TOL)


def test_hypervolume_with_duplicates_and_ties_matches_moocore(x64):
    A = np.array([[0.2, 0.8], [0.2, 0.5], [0.2, 0.5], [0.5, 0.5], [0.7, 0.1], [1.0, 0.0]])
    ref = np.array([1.0, 1.0])  # the last point lies on the boundary: no volume
    assert float(hypervolume(A, ref)) == pytest.approx(moocore.hypervolume(A, ref=ref), abs=TOL)
    assert float(hypervolume(A, ref=1.0)) == pytest.approx(0.8 * 0.5 + 0.3 * 0.4, abs=TOL)


def test_hypervolume_needs_two_objectives(x64):
    with pytest.raises(ValueError, match="2 objectives"):
        metrics.hypervolume(np.ones((3, 3)), ref=2.0)


# -------------------------------------------------------------------- NumPy references
@pytest.mark.parametrize("seed", range(4))
def test_gd_and_sp_match_numpy_definitions(x64, seed):
    rng = np.random.default_rng(100 + seed)
    A = _front(rng, N, noise=0.1)
    Z = _front(rng, R)
    assert float(gd(A, Z)) == pytest.approx(np_gd(A, Z), abs=TOL, rel=TOL)
    assert float(sp(A)) == pytest.approx(np_sp(A), abs=TOL, rel=TOL)


def test_gd_of_a_front_to_itself_is_zero(x64):
    Z = _front(np.random.default_rng(3), R)
    assert float(gd(Z, Z)) == 0.0
    assert float(igd(Z, Z)) == 0.0
    assert float(igd_plus(Z, Z)) == 0.0


def test_hypervolume_of_a_dominated_front_is_smaller(x64):
    Z = _front(np.random.default_rng(4), N)
    ref = np.array([1.1, 1.1])
    hv = float(hypervolume(Z, ref))
    assert hv > 0
    assert float(hypervolume(Z + np.array([0.0, 0.05]), ref)) < hv
    assert float(hypervolume(Z + 0.05, ref)) < hv


def test_sp_of_an_evenly_spaced_front_is_zero(x64):
    t = np.linspace(0.0, 1.0, N)
    assert float(sp(np.stack([t, 1 - t], axis=1))) == pytest.approx(0.0, abs=TOL)


# ------------------------------------------------------------------------------- ONVG
def test_onvg_counts_distinct_nondominated_feasible_points(x64):
    F = np.array(
        [
            [0.0, 1.0],  # non-dominated
            [0.0, 1.0],  # duplicate: counted once
            [0.5, 0.5],  # non-dominated
            [0.6, 0.6],  # dominated by [0.5, 0.5]
            [1.0, 0.0],  # non-dominated
            [0.1, 0.1],  # would dominate [0.5, 0.5] and [0.6, 0.6], but infeasible
            [np.nan, np.inf],  # garbage, masked
        ]
    )
    valid = np.array([True, True, True, True, True, False, False])
    assert int(onvg(F, valid=valid)) == 3
    mask = np.asarray(jax.jit(metrics.nondominated_mask)(F, valid=valid))
    np.testing.assert_array_equal(mask, [True, False, True, False, True, False, False])
    assert int(onvg(F[:5])) == 3
    valid[5] = True  # now [0.1, 0.1] dominates the middle points
    assert int(onvg(F, valid=valid)) == 3  # {[0, 1], [1, 0], [0.1, 0.1]}


@pytest.mark.parametrize("seed", range(3))
def test_onvg_matches_brute_force_on_a_grid(x64, seed):
    rng = np.random.default_rng(200 + seed)
    F = rng.integers(0, 4, size=(N, 2)).astype(float)  # many ties and duplicates
    valid = rng.random(N) < 0.8
    assert int(onvg(F, valid=valid)) == np_onvg(F, valid)


# --------------------------------------------------------------------- masks and vmap
def _masked_case(seed: int):
    rng = np.random.default_rng(300 + seed)
    F = _front(rng, N, noise=0.1)
    valid = rng.random(N) < 0.6
    valid[:2] = True
    F[~valid] = np.where(rng.random(((~valid).sum(), 2)) < 0.5, np.nan, -np.inf)
    return F, valid, _front(rng, R)


def test_masked_indicators_equal_unmasked_on_the_valid_subset(x64):
    ref = np.array([1.1, 1.1])
    for seed in range(3):
        F, valid, Z = _masked_case(seed)
        sub = F[valid]
        assert float(gd(F, Z, valid=valid)) == pytest.approx(np_gd(sub, Z), abs=TOL)
        assert float(sp(F, valid=valid)) == pytest.approx(np_sp(sub), abs=TOL)
        assert float(igd(F, Z, valid=valid)) == pytest.approx(moocore.igd(sub, ref=Z), abs=TOL)
        assert float(igd_plus(F, Z, valid=valid)) == pytest.approx(
            moocore.igd_plus(sub, ref=Z), abs=TOL
        )
        assert float(hypervolume(F, ref, valid=valid)) == pytest.approx(
            moocore.hypervolume(sub, ref=ref), abs=TOL
        )
        assert int(onvg(F, valid=valid)) == np_onvg(sub, np.ones(len(sub), bool))


def test_vmapped_indicators_equal_one_at_a_time(x64):
    cases = [_masked_case(s) for s in range(3)]
    Fb = jnp.asarray(np.stack([c[0] for c in cases]))
    Vb = jnp.asarray(np.stack([c[1] for c in cases]))
    Z = cases[0][2]
    ref = jnp.array([1.1, 1.1])

    @jax.jit
    def batch(F, V):
        one = lambda f, v: jnp.stack(  # noqa: E731
            [
                metrics.gd(f, Z, valid=v),
                metrics.sp(f, valid=v),
                metrics.igd(f, Z, valid=v),
                metrics.igd_plus(f, Z, valid=v),
                metrics.hypervolume(f, ref, valid=v),
                metrics.onvg(f, valid=v).astype(f.dtype),
            ]
        )
        return jax.vmap(one)(F, V)

    out = np.asarray(batch(Fb, Vb))
    for k, (F, valid, _) in enumerate(cases):
        sub = F[valid]
        expected = [
            np_gd(sub, Z),
            np_sp(sub),
            moocore.igd(sub, ref=Z),
            moocore.igd_plus(sub, ref=Z),
            moocore.hypervolume(sub, ref=np.array([1.1, 1.1])),
            np_onvg(sub, np.ones(len(sub), bool)),
        ]
        np.testing.assert_allclose(out[k], expected, rtol=1e-11, atol=TOL)


def test_empty_and_single_point_sets(x64):
    F = np.full((N, 2), np.nan)
    none = np.zeros(N, bool)
    Z = _front(np.random.default_rng(5), R)
    for value in (
        gd(F, Z, valid=none),
        sp(F, valid=none),
        igd(F, Z, valid=none),
        igd_plus(F, Z, valid=none),
    ):
        assert np.isnan(float(value))
    assert float(hypervolume(F, np.array([1.1, 1.1]), valid=none)) == 0.0
    assert int(onvg(F, valid=none)) == 0
    one = none.copy()
    one[3] = True
    F[3] = [0.5, 0.5]
    assert float(sp(F, valid=one)) == 0.0
    assert float(gd(F, Z, valid=one)) == pytest.approx(np_gd(F[one], Z), abs=TOL)


# ----------------------------------------------------------- normalisation, indicators()
def test_normalise_and_reference_normalisation(x64):
    Z = np.array([[20.0, 4.0], [40.0, 1.0], [60.0, 0.0]])
    ideal, nadir = metrics.reference_normalisation(Z)
    np.testing.assert_array_equal(ideal, [20.0, 0.0])
    np.testing.assert_array_equal(nadir, [60.0, 4.0])
    Zn = np.asarray(metrics.normalise(Z, ideal=ideal, nadir=nadir))
    np.testing.assert_allclose(Zn, [[0.0, 1.0], [0.5, 0.25], [1.0, 0.0]])
    flat = np.asarray(metrics.normalise(Z, ideal=[20.0, 3.0], nadir=[60.0, 3.0]))
    np.testing.assert_allclose(flat[:, 1], Z[:, 1] - 3.0)  # zero range: divided by 1


def test_indicators_normalise_by_the_reference_front_and_score_its_front():
    rng = np.random.default_rng(11)
    scale = np.array([40.0, 4.0])
    shift = np.array([20.0, 0.05])
    Z = _front(rng, R) * scale + shift
    F = _front(rng, N, noise=0.1) * scale + shift
    valid = rng.random(N) < 0.8
    F[~valid] = np.nan
    out = metrics.indicators(F, valid, Z)
    assert list(out) == list(metrics.NAMES)
    assert isinstance(out["ONVG"], int) and isinstance(out["HV"], float)

    ideal, nadir = Z.min(0), Z.max(0)
    Fn, Zn = (F - ideal) / (nadir - ideal), (Z - ideal) / (nadir - ideal)
    front = np.asarray(metrics.nondominated_mask(Fn, valid=valid))
    P = Fn[front]
    assert out["ONVG"] == len(P) == np_onvg(Fn, valid)
    assert out["GD"] == pytest.approx(np_gd(P, Zn), rel=1e-11)
    assert out["SP"] == pytest.approx(np_sp(P), rel=1e-11)
    assert out["IGD"] == pytest.approx(moocore.igd(P, ref=Zn), rel=1e-11)
    assert out["IGD+"] == pytest.approx(moocore.igd_plus(P, ref=Zn), rel=1e-11)
    assert out["HV"] == pytest.approx(moocore.hypervolume(P, ref=[1.1, 1.1]), rel=1e-11)
    # IGD+ and HV do not change when the dominated and infeasible points are included.
    Pall = Fn[valid]
    assert out["IGD+"] == pytest.approx(moocore.igd_plus(Pall, ref=Zn), rel=1e-11)
    assert out["HV"] == pytest.approx(moocore.hypervolume(Pall, ref=[1.1, 1.1]), rel=1e-11)

    batch = metrics.indicators(np.stack([F, F[::-1]]), np.stack([valid, valid[::-1]]), Z)
    for name in metrics.NAMES:
        assert batch[name].shape == (2,)
        np.testing.assert_allclose(batch[name], out[name], rtol=1e-11)
    # A fixed normalisation (scoring one run at a time) is honoured.
    fixed = metrics.indicators(F, valid, Z, ideal=ideal - 1.0, nadir=nadir + 1.0)
    assert fixed["HV"] != pytest.approx(out["HV"])


def test_indicators_rejects_bad_reference():
    with pytest.raises(ValueError, match="ref_front"):
        metrics.indicators(np.ones((3, 2)), None, np.ones((0, 2)))


# ------------------------------------------------------------------------ choice (Eq. 26)
def _convex_front(rng: np.random.Generator, n: int) -> np.ndarray:
    """Random convex (T, jerk) front, shuffled: jerk = c / (T − T0)."""
    T = np.sort(20.0 + 40.0 * rng.random(n))
    jerk = 2.0 / (T - 19.0) + 0.01 * rng.random()
    return rng.permutation(np.stack([T, jerk], axis=1))


@pytest.mark.parametrize("seed", range(5))
def test_time_and_smooth_types_pick_the_extremes(seed):
    F = _convex_front(np.random.default_rng(seed), 30)
    assert select.choose_type(F, "time") == int(np.argmin(F[:, 0]))
    assert select.choose_type(F, "smooth") == int(np.argmin(F[:, 1]))
    k = select.choose_type(F, "compromise")
    assert F[:, 0].min() < F[k, 0] < F[:, 0].max()


def test_compromise_picks_the_knee_of_a_symmetric_convex_front():
    t = np.linspace(0.0, 1.0, 21)  # sqrt f1 + sqrt f2 = 1, symmetric about f1 = f2
    F = np.stack([t**2, (1 - t) ** 2], axis=1) * np.array([40.0, 4.0]) + np.array([20.0, 0.0])
    order = np.random.default_rng(0).permutation(len(F))
    k = select.choose_type(F[order], "compromise")
    assert order[k] == 10
    delta = select.satisfaction(F, [1, 1])
    assert delta.max() == pytest.approx(0.75)  # (1/2)(0.75 + 0.75)
    assert delta[0] == pytest.approx(0.5) and delta[-1] == pytest.approx(0.5)


def test_satisfaction_values_ties_and_mask():
    F = np.array([[0.0, 1.0], [1.0, 0.0], [0.0, 1.0], [5.0, 5.0]])
    np.testing.assert_allclose(select.satisfaction(F[:3], [1, 1]), [0.5, 0.5, 0.5])
    assert select.choose(F[:3], [1, 1]) == 0  # tie: lowest index
    assert select.choose(F[:3], [0, 2]) == 1
    valid = np.array([False, True, True, False])
    assert select.choose(F, [1, 0], valid=valid) == 2
    assert np.isnan(select.satisfaction(F, [1, 0], valid=valid)[0])
    flat = np.array([[1.0, 3.0], [1.0, 2.0]])  # constant f1 contributes 0
    np.testing.assert_allclose(select.satisfaction(flat, [1, 1]), [0.0, 0.5])


@pytest.mark.parametrize(
    "weights, message",
    [
        ([1.0, np.nan], "finite"),
        ([1.0, np.inf], "finite"),
        ([1.0, -0.5], "non-negative"),
        ([0.0, 0.0], "all be zero"),
        ([1.0, 1.0, 1.0], "length"),
        ([[1.0, 1.0]], "length"),
    ],
)
def test_bad_weights_raise(weights, message):
    F = np.array([[0.0, 1.0], [1.0, 0.0]])
    with pytest.raises(ValueError, match=message):
        select.choose(F, weights)
    with pytest.raises(ValueError, match=message):
        select.check_weights(weights, 2)


def test_check_weights_returns_float_vector():
    w = select.check_weights((1, 0), 2)
    assert w.dtype == np.float64 and w.tolist() == [1.0, 0.0]
    with pytest.raises(ValueError, match="numbers"):
        select.check_weights(["a", "b"], 2)


def test_empty_set_and_unknown_type_raise():
    with pytest.raises(ValueError, match="empty"):
        select.choose(np.zeros((0, 2)), [1, 1])
    with pytest.raises(ValueError, match="empty"):
        select.choose(np.ones((2, 2)), [1, 1], valid=[False, False])
    with pytest.raises(ValueError, match="unknown type"):
        select.choose_type(np.ones((2, 2)), "fastest")
    assert select.PAPER_TYPES == {"compromise": (1, 1), "time": (1, 0), "smooth": (0, 1)}
