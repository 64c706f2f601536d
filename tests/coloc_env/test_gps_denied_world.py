"""World parts of gps_denied_nbp: constant-velocity UAVs, Markov GPS, range network, broadcast medium."""

import numpy as np
import pytest

from coloc_env.networks.blocks.broadcast_medium import BroadcastMedium
from coloc_env.worlds.blocks.cv_uav import ConstantVelocityUAVs
from coloc_env.worlds.blocks.gps_markov import MarkovGPS
from coloc_env.worlds.blocks.range_network import RangeNetwork


def test_cv_model_matrices_and_the_estimator_noise_covariance():
    motion = ConstantVelocityUAVs(dt=0.5, accel_std=0.5, accel_noise_std=0.3)
    F, G = motion.transition, motion.input_matrix
    x = np.array([1.0, 2.0, 3.0, -4.0])
    a = np.array([0.2, -0.6])
    np.testing.assert_allclose(motion.step(x, a), F @ x + G @ a, atol=1e-12)
    # the estimator sees x(k+1) - F x - G a_hat = -G e: its covariance is Q = sigma_acc^2 G G^T
    rng = np.random.default_rng(0)
    true, reading = motion.sample_accelerations(rng, (200_000,))
    residual = (true - reading) @ G.T
    np.testing.assert_allclose(np.cov(residual.T), motion.process_noise, rtol=0.02, atol=5e-4)
    np.testing.assert_allclose(true.std(axis=0), 0.5, rtol=0.01)


def test_cv_trajectory_integrates_steps():
    motion = ConstantVelocityUAVs()
    accel = np.random.default_rng(1).normal(size=(4, 3, 2))
    start = np.zeros((3, 4))
    start[:, 2] = 20.0
    traj = motion.trajectory(start, accel)
    assert traj.shape == (5, 3, 4)
    np.testing.assert_allclose(traj[2], motion.step(motion.step(start, accel[0]), accel[1]))


def test_markov_gps_stationary_law_switching_rates_and_fixes():
    gps = MarkovGPS(p_normal_to_fault=0.1, p_fault_to_normal=0.3, noise_std=3.0)
    normal = gps.sample_states(np.random.default_rng(2), 4000, 50)
    assert abs(normal.mean() - 0.75) < 0.01
    assert abs(normal[0].mean() - 0.75) < 0.15
    was_normal, now_normal = normal[:-1], normal[1:]
    assert abs((~now_normal[was_normal]).mean() - 0.1) < 0.01
    assert abs(now_normal[~was_normal].mean() - 0.3) < 0.01
    z = gps.measure(np.zeros((2, 2)), np.ones((2, 2)), np.array([True, False]))
    np.testing.assert_array_equal(z[0], [1.0, 1.0])
    assert np.all(np.isnan(z[1]))


def test_markov_gps_fixed_proportion_and_validation():
    fixed = MarkovGPS.fixed_states(np.random.default_rng(3), 5, 10, 3)
    assert fixed.shape == (5, 10) and np.all(fixed.sum(axis=1) == 3) and np.all(fixed == fixed[0])
    with pytest.raises(ValueError, match="n_normal"):
        MarkovGPS.fixed_states(np.random.default_rng(3), 5, 10, 11)
    with pytest.raises(ValueError, match="p_normal_to_fault"):
        MarkovGPS(p_normal_to_fault=1.5).validate()
    assert MarkovGPS(0.0, 0.0).stationary_normal == 0.5


def test_range_network_is_symmetric_and_range_limited():
    network = RangeNetwork(comm_range=100.0, noise_std=2.0)
    positions = np.array([[0.0, 0.0], [60.0, 80.0], [0.0, 150.0]])  # 0-1: 100 m (in), 0-2: 150 m, 1-2: 94 m
    noise = network.sample_noise(np.random.default_rng(4), (), 3)
    adjacency, ranges = network.measure(positions, noise)
    np.testing.assert_array_equal(adjacency, [[False, True, False], [True, False, True], [False, True, False]])
    np.testing.assert_array_equal(ranges, ranges.T)
    assert ranges[0, 2] == 0.0 and abs(ranges[0, 1] - 100.0 - noise[0, 1]) < 1e-12
    big = network.sample_noise(np.random.default_rng(5), (20_000,), 4)
    np.testing.assert_array_equal(big, np.swapaxes(big, -1, -2))
    assert abs(big[:, 0, 1].std() - 2.0) < 0.05 and np.all(big[:, 2, 2] == 0)
    with pytest.raises(ValueError, match="comm_range"):
        RangeNetwork(comm_range=0.0).validate()


def test_broadcast_medium_counts_broadcasts_and_messages():
    adjacency = np.array([[0, 1, 1], [1, 0, 0], [1, 0, 0]], bool)
    senders = np.array([True, True, False])
    listening = np.array([[1, 1, 0], [1, 1, 1], [1, 1, 1]], bool)  # node 2 does not listen to node 0
    delivered, broadcasts = BroadcastMedium.deliver(senders, adjacency, listening)
    np.testing.assert_array_equal(delivered, [[0, 1, 0], [1, 0, 0], [0, 0, 0]])
    np.testing.assert_array_equal(broadcasts, [1, 1, 0])
    _, alone = BroadcastMedium.deliver(np.array([False, False, True]), adjacency, np.zeros((3, 3), bool))
    np.testing.assert_array_equal(alone, [0, 0, 0])  # nobody listening: no broadcast
    assert BroadcastMedium().payload(np.array(2), 100) == 2 * 301
