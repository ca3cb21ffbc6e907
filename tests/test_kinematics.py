"""Kinematics (paper §2, Eqs. 1–15; conventions §4) against the closed forms and the reference."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from dockjax import kinematics as K
from tests import reference as R

RNG_SEED = 20240601


def _random_joints(rng, n):
    d = rng.uniform(-2500.0, 2500.0, size=(n, 3))
    theta = rng.uniform(-400.0, 400.0, size=(n, 1))
    return np.hstack([d, theta])


def _random_poses(rng, n):
    xyz = rng.uniform(-2000.0, 2000.0, size=(n, 3))
    pitch = rng.uniform(-89.0, 89.0, size=(n, 1))
    yaw = rng.uniform(-89.0, 89.0, size=(n, 1))
    roll = rng.uniform(-400.0, 400.0, size=(n, 1))
    return np.hstack([xyz, pitch, yaw, roll])


def _angle_diff(a, b):
    """Smallest signed difference of angles in degrees."""
    return (np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0


@pytest.mark.parametrize(
    ("dh", "closed"),
    [(K.forward_left, K.eq1_left), (K.forward_right, K.eq2_right)],
    ids=["left_eq1", "right_eq2"],
)
def test_dh_product_equals_closed_form(x64, dh, closed):
    rng = np.random.default_rng(RNG_SEED)
    for q in _random_joints(rng, 50):
        a = np.asarray(dh(*q))
        b = np.asarray(closed(*q))
        assert a.dtype == np.float64
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def test_closed_forms_match_printed_matrices(x64):
    """Eqs. 1–2 as printed in the paper, written out here independently."""
    d1, d2, d3, th = 123.0, -45.0, 67.0, 30.0
    s, c = np.sin(np.deg2rad(th)), np.cos(np.deg2rad(th))
    eq1 = np.array([[0, 0, 1, -d1], [-s, -c, 0, -d3], [c, -s, 0, d2], [0, 0, 0, 1]])
    eq2 = np.array([[0, 0, -1, d1], [s, c, 0, -d3], [c, -s, 0, d2], [0, 0, 0, 1]])
    np.testing.assert_allclose(np.asarray(K.forward_left(d1, d2, d3, th)), eq1, atol=1e-12)
    np.testing.assert_allclose(np.asarray(K.forward_right(d1, d2, d3, th)), eq2, atol=1e-12)


def test_inverse_kinematics_matches_reference(x64):
    rng = np.random.default_rng(RNG_SEED + 1)
    poses = _random_poses(rng, 200)
    for d2 in (1500.0, 2000.0, 3000.0):
        got = np.asarray(K.inverse_kinematics(poses, d2))
        want = R.joints_of_pose(poses, d2)
        assert got.shape == (200, 8)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)


def test_forward_kinematics_of_inverse_is_identity(x64):
    rng = np.random.default_rng(RNG_SEED + 2)
    for pose in _random_poses(rng, 100):
        d2 = rng.uniform(500.0, 4000.0)
        back = np.asarray(K.forward_kinematics(K.inverse_kinematics(pose, d2), d2))
        assert back.shape == (6,)
        np.testing.assert_allclose(back[:3], pose[:3], rtol=0, atol=1e-9)
        np.testing.assert_allclose(_angle_diff(back[3:], pose[3:]), 0.0, atol=1e-9)


def test_dh_end_points_are_the_arm_ends(x64):
    """The translation of each D-H product, read in task axes (base x = task Z, y = X,
    z = Y), is K_L and K_R = K_L + D2·u(α, β)."""
    rng = np.random.default_rng(RNG_SEED + 3)
    for pose in _random_poses(rng, 50):
        d2 = 2000.0
        q = R.joints_of_pose(pose, d2)
        left = np.asarray(K.forward_left(*q[:4]))[:3, 3]
        right = np.asarray(K.forward_right(*q[4:]))[:3, 3]
        a, b = np.deg2rad(pose[3]), np.deg2rad(pose[4])
        kl = pose[:3]
        kr = kl + d2 * np.array([np.cos(a) * np.sin(b), np.sin(a), np.cos(a) * np.cos(b)])
        np.testing.assert_allclose(left[[1, 2, 0]], kl, atol=1e-9)
        np.testing.assert_allclose(right[[1, 2, 0]], kr, atol=1e-9)
        np.testing.assert_allclose(np.asarray(K.right_end_point(pose, d2)), kr, atol=1e-9)


def test_roll_joints_follow_roll(x64):
    pose = np.array([1.0, 2.0, 3.0, 0.5, -0.5, 190.0])
    q = np.asarray(K.inverse_kinematics(pose, 2000.0))
    assert q[3] == pytest.approx(190.0)
    assert q[7] == pytest.approx(-190.0)


def test_arm_distance_is_constant_along_decoded_trajectory():
    from dockjax import DockingProblem

    rng = np.random.default_rng(RNG_SEED + 4)
    start = (770.0, -30.0, -1300.0, 1.5, -2.0, 185.0)
    goal = (745.0, -5.0, -1515.0, -1.0, 2.5, 180.0)
    d2 = 2600.0
    p = DockingProblem(
        start=start, goal=goal, arm_distance=d2, travel=(600, 100, 100, 15)
    )
    x = rng.uniform(p.lower, p.upper)
    traj = p.decode(x)
    t = np.sort(rng.uniform(0.0, traj.T, 1000))
    j = np.asarray(traj.joints(t))
    kl = np.stack([-j[:, 2], j[:, 1], -j[:, 0]], axis=1)
    kr = np.stack([-j[:, 6], j[:, 5], j[:, 4]], axis=1)
    dist = np.linalg.norm(kr - kl, axis=1)
    np.testing.assert_allclose(dist, d2, rtol=1e-12)
    # the same through the pose and the kinematics helper
    pose = np.asarray(traj.pose(t))
    with jax.enable_x64(True):
        kr2 = np.asarray(K.right_end_point(pose, d2))
    np.testing.assert_allclose(np.linalg.norm(kr2 - pose[:, :3], axis=1), d2, rtol=1e-12)
    np.testing.assert_allclose(kr2, kr, rtol=0, atol=1e-9)
