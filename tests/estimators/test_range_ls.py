"""Baselines of wan2014: Gauss-Newton / linearized LS fixes, the gate, and the Kalman filters."""

import numpy as np
import pytest

import estimators.range_ls as rl
from coloc_env.worlds.blocks.cv_uav import ConstantVelocityUAVs

ANCHORS = np.array([[0.0, 0.0], [200.0, 0.0], [0.0, 200.0], [0.0, 0.0]])
MASK = np.array([True, True, True, False])
TARGET = np.array([80.0, 60.0])


def test_exact_ranges_give_the_position_from_both_starts():
    d = np.linalg.norm(ANCHORS - TARGET, axis=-1)
    lin = rl.linearized_fix(ANCHORS[None], d[None], MASK[None])
    np.testing.assert_allclose(lin[0], TARGET, atol=1e-9)
    p, JtJ, rms = rl.gauss_newton(np.array([[150.0, 150.0]]), ANCHORS[None], d[None], MASK[None])
    np.testing.assert_allclose(p[0], TARGET, atol=1e-6)
    assert rms[0] < 1e-6 and np.linalg.det(JtJ[0]) > 0


def _state(mean_pos, var):
    mean = np.zeros((1, 2, 4))
    mean[0, :, :2] = mean_pos
    return rl.initial_state(mean, np.diag([var, var, 1.0, 1.0]))


def test_ls_step_fixes_a_fault_uav_with_three_normal_neighbours_and_gates_a_mirror():
    motion = ConstantVelocityUAVs()
    F, G, Q = motion.transition, motion.input_matrix, motion.process_noise
    # UAV 0 is faulty; anchors are UAVs 1-3 (normal) given as exact GPS fixes with a tiny GPS std
    positions = np.vstack([TARGET, ANCHORS[:3]])
    d = np.linalg.norm(positions[:, None] - positions[None], axis=-1)
    normal = np.array([[False, True, True, True]])
    mean = np.zeros((1, 4, 4))
    mean[0, :, :2] = positions + np.array([[30.0, -20.0], [0, 0], [0, 0], [0, 0]])
    state = rl.initial_state(mean, np.diag([900.0, 900.0, 1.0, 1.0]))
    args = (normal, positions[None], (d > 0)[None], d[None], np.zeros((1, 4, 2)), F, G, Q, 1e-3, 2.0)
    _, estimate, fixed = rl.step(rl.LsParams(), state, *args)
    assert fixed[0].tolist() == [True, False, False, False]
    np.testing.assert_allclose(estimate[0, 0], TARGET, atol=1e-3)
    # dead reckoning: the same filter without fixes keeps the prediction
    _, dr, fixed_dr = rl.step(rl.LsParams(cooperative=False), state, *args)
    assert not fixed_dr.any()
    np.testing.assert_allclose(dr[0, 0], mean[0, 0, :2])
    # a confident prediction far from the fix fails the chi^2 innovation gate
    tight = rl.initial_state(mean, np.diag([1.0, 1.0, 1.0, 1.0]))
    _, est_gated, fixed_gated = rl.step(rl.LsParams(), tight, *args)
    assert not fixed_gated[0, 0]
    np.testing.assert_allclose(est_gated[0, 0], mean[0, 0, :2])


def test_kalman_update_is_symmetric_and_shrinks_the_covariance():
    state = _state(np.array([[0.0, 0.0], [5.0, 5.0]]), 100.0)
    z = np.array([[[1.0, 2.0], [0.0, 0.0]]])
    R = np.broadcast_to(4.0 * np.eye(2), (1, 2, 2, 2))
    post = rl.update_position(state, z, R, np.array([[True, False]]))
    np.testing.assert_allclose(post.mean[0, 0, :2], np.array([1.0, 2.0]) * 100 / 104)
    np.testing.assert_allclose(post.cov[0, 0, :2, :2], np.eye(2) * 400 / 104)
    np.testing.assert_array_equal(post.mean[0, 1], state.mean[0, 1])
    np.testing.assert_array_equal(post.cov, np.swapaxes(post.cov, -1, -2))


def test_a_per_copy_sigma_has_one_value_per_copy():
    state = _state(np.zeros((2, 2)), 1.0)
    args = (rl.LsParams(), state, np.ones((1, 2), bool), np.zeros((1, 2, 2)), np.zeros((1, 2, 2), bool),
            np.zeros((1, 2, 2)))
    as_float = rl.update(*args, 3.0, 2.0)[0]
    as_array = rl.update(*args, np.array([3.0]), np.array([2.0]))[0]
    np.testing.assert_array_equal(as_float.cov, as_array.cov)
    with pytest.raises(ValueError, match=r"gps_std must be a float or have shape \(1,\), got shape \(2,\)"):
        rl.update(*args, np.ones(2), 2.0)
