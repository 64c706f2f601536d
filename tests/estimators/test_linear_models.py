"""estimators.linear_models: the linear-Gaussian motion and measurement models of zhao2020 and fu2017."""

import numpy as np
import pytest

from coloc_env.worlds.blocks.motion import LinearMotion
from coloc_env.worlds.blocks.target import ConstantVelocityTarget
from estimators.linear_models import LinearGaussian, LinearObservation


def test_the_cv_model_is_the_worlds_target_and_samples_its_covariance():
    target = ConstantVelocityTarget(3, 1.0, 5.0)
    model = LinearGaussian(target.transition, np.zeros(6), target.process_noise)
    x = np.arange(12.0).reshape(2, 6)
    np.testing.assert_allclose(model.function(x), target.step(x, np.zeros((2, 3))))
    np.testing.assert_array_equal(model.jacobian(x), np.broadcast_to(target.transition, (2, 6, 6)))
    assert model.covar(x).shape == (2, 6, 6) and not model.identity_jacobian
    draws = model.rvs(np.random.default_rng(0), (200_000,))
    np.testing.assert_allclose(np.cov(draws.T), target.process_noise, atol=0.05)  # Q is singular (rank 3)


def test_the_drift_model_is_linear_motion_and_its_known_input_separates_exactly():
    A = np.array([[1.0, 0.1], [0.0, 0.9]])
    b = np.array([0.5, -0.2])
    Q = np.diag([0.02, 0.05])
    model, motion = LinearGaussian(A, b, Q), LinearMotion(A, b, Q)
    w = np.random.default_rng(1).standard_normal((10, 2))
    x = xt = np.array([10.0, 3.0])
    c = model.known_input(10)
    for k in range(10):
        x = motion.step(x, w[k])
        xt = xt @ A.T + w[k]  # the input-free model
        np.testing.assert_allclose(x, xt + c[k + 1], atol=1e-12)
    assert model.identity_jacobian is False and LinearGaussian(np.eye(2), b, Q).identity_jacobian


def test_the_observation_model_noise_per_sensor():
    C = np.kron(np.eye(3), [[1.0, 0.0]])
    V = np.stack([np.eye(3), 4.0 * np.eye(3)])
    obs = LinearObservation(C, V)
    assert obs.noise_of(2).shape == (2, 3, 3) and obs.dim == 3
    draws = obs.rvs(np.random.default_rng(2), (100_000,), 2)
    np.testing.assert_allclose(draws.var(axis=0), [[1, 1, 1], [4, 4, 4]], rtol=0.03)
    np.testing.assert_allclose(obs.function(np.arange(6.0)), [0.0, 2.0, 4.0])
    with pytest.raises(ValueError, match="noise has 2 sensors, expected 3"):
        obs.noise_of(3)


def test_bad_models_are_refused():
    with pytest.raises(ValueError, match=r"transition must be a square matrix"):
        LinearGaussian(np.ones((2, 3)), np.zeros(2), np.eye(2))
    with pytest.raises(ValueError, match=r"drift must be a finite \(2,\) vector"):
        LinearGaussian(np.eye(2), np.zeros(3), np.eye(2))
    with pytest.raises(ValueError, match=r"process_noise must be positive semi-definite"):
        LinearGaussian(np.eye(2), np.zeros(2), -np.eye(2))
    with pytest.raises(ValueError, match=r"noise\[1\] must be positive definite"):
        LinearObservation(np.eye(2), np.stack([np.eye(2), np.zeros((2, 2))]))
