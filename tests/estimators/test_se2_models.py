"""SE(2) odometry and range+bearing models: agreement with the SE(2) UKF's math, Jacobians, sampling."""

import numpy as np
import pytest

import estimators.ukf_relay_se2 as se2
from estimators.models import predict_joint
from estimators.se2_models import RangeBearingModel, SE2Odometry

DT = 0.1


def _states(rng, shape):
    s = rng.normal(size=(*shape, 3))
    s[..., 2] = rng.uniform(-np.pi, np.pi, shape)
    return s


def _inputs(rng, shape):
    return np.concatenate([rng.normal(size=(*shape, 2)), rng.uniform(1e-4, 1e-2, (*shape, 2))], axis=-1)


def test_the_motion_model_is_the_ukfs_propagation():
    rng = np.random.default_rng(0)
    model = SE2Odometry(DT)
    x, u = _states(rng, (4, 5)), _inputs(rng, (4, 5))
    new, F, G = se2.motion(x, u[..., :2], DT)
    np.testing.assert_allclose(model.function(x, u), new, rtol=0, atol=1e-12)
    np.testing.assert_allclose(model.jacobian(x, u), F, rtol=0, atol=1e-12)
    Q = np.einsum("...ab,...b,...cb->...ac", G, u[..., 2:], G)
    np.testing.assert_allclose(model.covar(x, u), Q, rtol=0, atol=1e-15)


def test_predict_joint_on_the_model_equals_the_ukfs_joint_time_update():
    rng = np.random.default_rng(1)
    N = 5
    model = SE2Odometry(DT)
    x, u = _states(rng, (N,)), _inputs(rng, (N,))
    A = rng.normal(size=(3 * N, 3 * N))
    P = A @ A.T + np.eye(3 * N)
    mean, cov = predict_joint(model, x, P, u)
    mean_ref, cov_ref = se2.time_update(x, P, u[:, :2], DT, u[:, 2:])
    np.testing.assert_allclose(mean, mean_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cov, cov_ref, rtol=0, atol=1e-12)


def test_the_motion_jacobian_matches_finite_differences():
    rng = np.random.default_rng(2)
    model = SE2Odometry(DT)
    x, u = _states(rng, ()), _inputs(rng, ())
    x[2] = 0.3  # away from the wrap
    eps = 1e-6
    numeric = np.stack([(model.function(x + eps * e, u) - model.function(x - eps * e, u)) / (2 * eps)
                        for e in np.eye(3)], axis=-1)
    np.testing.assert_allclose(model.jacobian(x, u), numeric, rtol=0, atol=1e-8)


def test_the_motion_noise_samples_have_the_model_covariance():
    rng = np.random.default_rng(3)
    model = SE2Odometry(DT)
    x = np.broadcast_to(np.array([0.0, 0.0, 0.7]), (200_000, 3))
    u = np.broadcast_to(np.array([0.5, 0.2, 0.04, 0.09]), (200_000, 4))
    w = model.rvs(rng, x, u)
    np.testing.assert_allclose(np.cov(w.T), model.covar(x[0], u[0]), rtol=0, atol=2e-6)


def test_the_range_bearing_model_is_the_ukfs_observation_and_its_jacobian_is_right():
    rng = np.random.default_rng(4)
    model = RangeBearingModel(range_var=0.01, bearing_var=0.002, range_var_gain=0.05)
    s, t = _states(rng, (6,)), rng.normal(size=(6, 2)) * 3
    np.testing.assert_array_equal(model.function(s, t), se2.observe(s, t))
    H_s, H_t = model.jacobian(s, t)
    eps = 1e-6
    for i in range(6):
        num_s = np.stack([se2.wrap(model.function(s[i] + eps * e, t[i]) - model.function(s[i] - eps * e, t[i]))
                          / (2 * eps) for e in np.eye(3)], axis=-1)
        num_t = np.stack([se2.wrap(model.function(s[i], t[i] + eps * e) - model.function(s[i], t[i] - eps * e))
                          / (2 * eps) for e in np.eye(2)], axis=-1)
        np.testing.assert_allclose(H_s[i], num_s, rtol=0, atol=1e-7)
        np.testing.assert_allclose(H_t[i], num_t, rtol=0, atol=1e-7)
    R = model.covar(np.array([1.0, 2.0]))
    np.testing.assert_allclose(R[:, 0, 0], [0.06, 0.21])
    np.testing.assert_allclose(R[:, 1, 1], 0.002)
    draws = model.rvs(rng, 100_000, true_range=2.0)
    np.testing.assert_allclose(draws.var(axis=0), [0.21, 0.002], rtol=0.02)


@pytest.mark.parametrize("bad", [{"range_var": -1.0, "bearing_var": 0.1}, {"range_var": 0.1, "bearing_var": np.nan}])
def test_bad_noise_is_refused(bad):
    with pytest.raises(ValueError, match="var"):
        RangeBearingModel(**bad)
    with pytest.raises(ValueError, match="dt"):
        SE2Odometry(0.0)
    with pytest.raises(ValueError, match="4 values"):
        SE2Odometry(DT).function(np.zeros(3), np.zeros(2))


def test_noise_draws_are_per_state_when_inputs_broadcast_over_particles():
    rng = np.random.default_rng(5)
    model = SE2Odometry(DT)
    particles = np.zeros((2, 1000, 3))
    u = np.broadcast_to(np.array([1.0, 0.0, 0.01, 0.01]), (2, 1, 4))
    w = model.rvs(rng, particles, u)
    assert w.shape == (2, 1000, 3)
    np.testing.assert_allclose(w[..., 0].std(axis=1), DT * 0.1, rtol=0.1)  # dt sigma_v along the heading 0
