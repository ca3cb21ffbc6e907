"""Gradient polishing and the best-known front (dockjax.refine), checked against the
independent dense reference (tests/reference.py) and the problem's own kernel."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dockjax import DockingProblem
from dockjax.best_known import best_known_front
from dockjax.metrics import hypervolume
from dockjax.refine import refine
from dockjax.solve import straight_line
from tests.conftest import short_imocs_runs
from tests.reference import dense_check

HV_REF = (61.0, 20.0)
STEPS = 150


@pytest.fixture(scope="module")
def problem():
    return DockingProblem()


@pytest.fixture(scope="module")
def imocs_result(problem):
    return short_imocs_runs(problem)  # the program of the README's snippet and the sweeps


@pytest.fixture(scope="module")
def imocs_front(imocs_result):
    """Every feasible non-dominated member of the two short runs (16 rows at most)."""
    r = imocs_result
    m = r.front
    return r.X[m], r.F[m]


@pytest.fixture(scope="module")
def refined(problem, imocs_front):
    X, _ = imocs_front
    return refine(problem, X, steps=STEPS)


def _hv(F, valid=None):  # noqa: D103
    with jax.enable_x64(True):
        return float(hypervolume(jnp.asarray(F), HV_REF, valid=None if valid is None else jnp.asarray(valid)))


def test_gradients_stay_finite(refined):
    assert np.all(refined.nonfinite_steps == 0)


def test_safe_objective_matches_kernel(problem, imocs_front, refined):
    # F_in/G_in come from the NaN-safe objective of refine.py; the kernel must agree
    F_ref, G_ref = problem.evaluate(imocs_front[0])
    np.testing.assert_allclose(refined.F_in, F_ref, rtol=1e-13)
    np.testing.assert_allclose(refined.G_in, G_ref, rtol=0, atol=1e-13)


def test_refined_points_dominate_or_equal_inputs_and_are_dense_feasible(problem, imocs_front, refined):
    X_in = imocs_front[0]
    F_in, _ = problem.evaluate(X_in)
    F, G = problem.evaluate(refined.X)
    np.testing.assert_allclose(F, refined.F, rtol=1e-12)
    assert refined.X.shape == X_in.shape
    # never dominated by the input: T no longer and jerk no higher
    assert np.all(F[:, 0] <= F_in[:, 0])
    assert np.all(F[:, 1] <= F_in[:, 1])
    assert np.all(np.where(refined.improved, F[:, 1] < F_in[:, 1], np.all(refined.X == X_in, 1)))
    # the inputs are feasible, so the outputs are too: kernel and the independent dense check
    assert np.all(G <= 0) and np.all(refined.feasible)
    Gd, feas = dense_check(problem, refined.X, n_samples=4001)
    assert np.all(feas), Gd.max(1)
    assert np.all((refined.X >= problem.lower) & (refined.X <= problem.upper))
    assert refined.improved.mean() >= 0.75


def test_refine_raises_hypervolume_of_short_imocs_run(problem, imocs_front, refined):
    _, F_front = imocs_front
    hv_in = _hv(F_front)
    F_all = np.vstack([F_front, refined.F])
    assert _hv(F_all) > hv_in
    assert _hv(refined.F) > hv_in


def test_best_known_front_is_feasible_and_beats_short_imocs(problem, imocs_front, capfd, monkeypatch):
    from dockjax import best_known

    closed = []

    class Bar(best_known.tqdm):  # records the count each bar reached when it closed
        def close(self):
            closed.append((self.n, self.total))
            super().close()

    monkeypatch.setattr(best_known, "tqdm", Bar)
    front = best_known_front(problem, n_points=6, n_exact=3, steps=STEPS, progress=True)
    # its progress: the shortest time, 3 anchors and the polishing batch, on stderr
    err = capfd.readouterr().err
    assert "best-known front" in err and "1/5" in err and "SQP anchors" in err, err[-500:]
    assert set(closed) == {(5, 5)}  # (tqdm may close a bar twice: at exit and when collected)
    assert len(front.F) >= 3
    F, G = problem.evaluate(front.X)
    np.testing.assert_allclose(F, front.F, rtol=1e-12)
    assert np.all(G <= 0)
    Gd, feas = dense_check(problem, front.X, n_samples=4001)
    assert np.all(feas), Gd.max(1)
    assert np.all(np.diff(front.F[:, 0]) > 0) and np.all(np.diff(front.F[:, 1]) < 0)
    assert _hv(front.F) >= _hv(imocs_front[1])


def test_infeasible_input_is_repaired_or_returned_unchanged(problem):
    X = straight_line(problem, [21.0, 60.0])
    X[1, 6:] = problem.upper[6:]  # a wild detour
    r = refine(problem, X, steps=20)
    # the corner of the box (coincident control points, double roots of the derivatives)
    # has a finite gradient: the critical times carry none (envelope theorem)
    assert np.all(r.nonfinite_steps == 0)
    for i in range(2):
        if r.improved[i]:
            assert r.feasible[i] and r.F[i, 0] <= X[i, :6].sum()
        else:
            assert np.all(r.X[i] == X[i])


@pytest.mark.parametrize(
    "kwargs, match",
    [({"steps": 0}, "steps"), ({"learning_rate": -1.0}, "learning_rate"),
     ({"penalty": float("nan")}, "penalty"), ({"margin": 0.7}, "margin"), ({"rows": 0}, "rows"),
     ({"rows": 2.5}, "rows")],
)
def test_refine_rejects_bad_arguments(problem, kwargs, match):
    with pytest.raises(ValueError, match=match):
        refine(problem, straight_line(problem, [30.0]), **kwargs)


def test_refine_rejects_bad_population(problem):
    with pytest.raises(ValueError):
        refine(problem, np.zeros((2, 5)))
    x = straight_line(problem, [30.0])
    x[0, 3] = np.nan
    with pytest.raises(ValueError):
        refine(problem, x)
    with pytest.raises(ValueError, match="n_points"):
        best_known_front(problem, n_points=1)
    with pytest.raises(ValueError, match="anchor_iter"):
        best_known_front(problem, anchor_iter=0)
    with pytest.raises(ValueError, match="anchor_restarts"):
        best_known_front(problem, anchor_restarts=-1)


@pytest.fixture(scope="module")
def memetic(problem, imocs_result):
    from dockjax.optimize import refine_result

    return imocs_result, refine_result(problem, imocs_result, steps=60)  # 16 rows: compiled above


def test_memetic_finish_never_worsens_a_member_and_raises_each_runs_hypervolume(problem, memetic):
    r, m = memetic
    assert m.algorithm == "imocs+refine" and r.algorithm == "imocs"
    assert m.X.shape == r.X.shape and m.extra["improved"].shape == r.F.shape[:2]
    for i in range(len(r)):
        # member by member: a feasible member is replaced by one that it does not dominate
        feas = r.feasible[i]
        assert np.all(m.feasible[i][feas])
        assert np.all(m.F[i][feas] <= r.F[i][feas] + 1e-12)
        # scores of the new members agree with a fresh evaluation, fronts are feasible on
        # the independent dense check, and U matches X
        F, G = problem.evaluate(m.X[i])
        np.testing.assert_allclose(F, m.F[i], rtol=1e-12)
        np.testing.assert_allclose(m.X[i], problem.lower + m.U[i] * (problem.upper - problem.lower), atol=1e-9)
        _, ok = dense_check(problem, m.X[i][m.front[i]], n_samples=4001)
        assert np.all(ok)
        assert _hv(m.F[i], m.front[i]) > _hv(r.F[i], r.front[i])


def test_optimize_rejects_negative_refine_steps(problem):
    from dockjax.optimize import optimize

    with pytest.raises(ValueError, match="refine_steps"):
        optimize("imocs", problem, pop_size=16, n_iter=5, refine_steps=-1)


@pytest.mark.parametrize("screen", [True, False])
def test_gradient_of_the_limits_matches_finite_differences(problem, screen):
    """The critical times carry no gradient (envelope theorem): the derivative of every G
    column along random directions (forward mode; reverse mode is its transpose) must
    still equal the central finite difference of the kernel's values — of the full root
    chain, and of the screened columns (exact near the limits, bounds elsewhere) that
    refinement differentiates by default."""
    from dockjax.refine import objectives_safe

    x0 = straight_line(problem, [33.0])[0]
    rng = np.random.default_rng(5)
    width = problem.upper - problem.lower
    x0[6:] += rng.uniform(-0.02, 0.02, x0.size - 6) * width[6:]
    x0[:6] += rng.uniform(-0.3, 0.3, 6)
    dirs = rng.normal(size=(3, x0.size)) * width * 1e-2
    with jax.enable_x64(True):
        jvp = jax.jit(jax.vmap(lambda v: jax.jvp(lambda x: objectives_safe(problem, x, screen),
                                                  (jnp.asarray(x0),), (v,))[1]))
        dFs, dGs = jvp(jnp.asarray(dirs))
    tangents = zip(np.asarray(dFs), np.asarray(dGs))
    eps = 1e-5
    rows = np.concatenate([[x0 + eps * v, x0 - eps * v] for v in dirs])
    F, G = problem.evaluate(np.vstack([rows, np.repeat(rows[:1], 16 - len(rows), 0)]), screen=screen)
    for k, (dF, dG) in enumerate(tangents):
        fd_G = (G[2 * k] - G[2 * k + 1]) / (2 * eps)
        fd_J = (F[2 * k, 1] - F[2 * k + 1, 1]) / (2 * eps)
        np.testing.assert_allclose(dG, fd_G, rtol=1e-4, atol=1e-7 * np.abs(fd_G).max())
        np.testing.assert_allclose(float(dF[1]), fd_J, rtol=1e-5)
