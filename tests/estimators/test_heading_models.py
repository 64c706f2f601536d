"""The heading-error odometry model: Jacobian, noise, and the random walk it stands for."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.heading_models import OdometryHeadingError
from estimators.models import OdometryDisplacement

MODEL = OdometryHeadingError(dt=0.5, speed_var=0.25, turn_rate_var=1e-4)


def test_jacobian_matches_central_differences():
    rng = np.random.default_rng(0)
    state = rng.normal(size=(4, 3))
    inputs = np.column_stack([rng.uniform(0.5, 2.0, 4), rng.uniform(-np.pi, np.pi, 4), np.zeros(4)])
    F = MODEL.jacobian(state, inputs)
    h = 1e-6
    for j in range(3):
        step = np.zeros(3)
        step[j] = h
        numeric = (MODEL.function(state + step, inputs) - MODEL.function(state - step, inputs)) / (2 * h)
        np.testing.assert_allclose(F[..., :, j], numeric, atol=1e-8)


def test_zero_error_moves_like_the_displacement_model():
    rng = np.random.default_rng(1)
    position = rng.normal(size=(3, 2))
    inputs = np.column_stack([rng.uniform(0.5, 2.0, 3), rng.uniform(-np.pi, np.pi, 3), np.full(3, 0.3)])
    moved = MODEL.function(np.column_stack([position, np.zeros(3)]), inputs)
    np.testing.assert_allclose(moved[:, :2], OdometryDisplacement(0.5, 0.25).function(position, inputs), atol=1e-12)
    np.testing.assert_array_equal(moved[:, 2], 0.0)
    Q = MODEL.covar(np.column_stack([position, np.zeros(3)]), inputs)
    speed_only = OdometryDisplacement(0.5, 0.25).covar(position, inputs * np.array([1.0, 1.0, 0.0]))
    np.testing.assert_allclose(Q[:, :2, :2], speed_only, atol=1e-15)
    np.testing.assert_allclose(Q[:, 2, 2], 0.25 * 1e-4)
    np.testing.assert_array_equal(Q[:, :2, 2], 0.0)


def test_heading_error_variance_grows_as_the_integrated_turn_rate_noise():
    """k time updates of one platform: var(e) = (k + 1) dt^2 sigma_omega^2 (the prior is one increment)."""
    mean, cov = MODEL.augment(np.zeros((1, 2)), 0.01 * np.eye(2)[None])
    inputs = np.array([[1.0, 0.3, 0.0]])
    for _ in range(7):
        F = MODEL.jacobian(mean, inputs)[0]
        cov = (F @ cov[0] @ F.T + MODEL.covar(mean, inputs)[0])[None]
        mean = MODEL.function(mean, inputs)
    assert cov[0, 2, 2] == pytest.approx(8 * 0.25 * 1e-4, rel=1e-12)


@pytest.mark.parametrize(("field", "value", "match"), [
    ("dt", 0.0, "dt must be > 0"), ("speed_var", -1.0, "speed_var must be >= 0"),
    ("turn_rate_var", 0.0, "turn_rate_var must be > 0")])
def test_bad_fields_are_refused(field, value, match):
    fields = {"dt": 0.5, "speed_var": 0.25, "turn_rate_var": 1e-4, field: value}
    with pytest.raises(ValueError, match=match):
        OdometryHeadingError(**fields)
