"""World parts: linear motion, linear sensors, bandwidth budgets."""

import itertools

import numpy as np
import pytest

from coloc_env.world import BandwidthBudget, LinearMotion, LinearSensor


def test_paper_budget_has_108_selections_and_relaxed_has_216():
    budget = BandwidthBudget()
    budget.validate()
    assert budget.feasible.shape == (108, 3, 3)
    # independent count: 3 neighbours, 1..3 components each, totals 5 (or <= 5)
    sizes = {k: sum(1 for s in itertools.product((0, 1), repeat=3) if sum(s) == k) for k in (1, 2, 3)}
    exact = sum(sizes[a] * sizes[b] * sizes[c] for a, b, c in itertools.product((1, 2, 3), repeat=3)
                if a + b + c == 5)
    relaxed = sum(sizes[a] * sizes[b] * sizes[c] for a, b, c in itertools.product((1, 2, 3), repeat=3)
                  if a + b + c <= 5)
    assert exact == 108 and relaxed == 216
    assert len(BandwidthBudget(exact_budget=False).feasible) == relaxed
    assert np.all(budget.feasible.sum(axis=(1, 2)) == 5)
    assert len({f.tobytes() for f in budget.feasible}) == 108


def test_relative_and_absolute_selections_round_trip():
    budget = BandwidthBudget()
    rng = np.random.default_rng(0)
    rel = budget.feasible[rng.integers(0, 108, size=(7, 4))]  # (7, N, N-1, n)
    full = budget.full_selection(rel)
    assert full.shape == (7, 4, 4, 3)
    assert np.all(full[:, np.arange(4), np.arange(4)])
    np.testing.assert_array_equal(budget.relative_selection(full), rel)
    # neighbour k of receiver i is node (i + 1 + k) mod N
    np.testing.assert_array_equal(full[:, 1, 3], rel[:, 1, 1])
    assert np.all(budget.index_of(rel) >= 0)


@pytest.mark.parametrize("kwargs, field", [
    ({"budget": 10}, "budget"), ({"budget": 2}, "budget"), ({"max_per_link": 4}, "max_per_link"),
    ({"min_per_link": 4}, "min_per_link"), ({"num_nodes": 1}, "num_nodes"), ({"budget": 2.5}, "budget"),
])
def test_budget_no_selection_can_meet_is_refused(kwargs, field):
    with pytest.raises(ValueError, match=field):
        BandwidthBudget(**kwargs).validate()


def test_linear_motion_steps_and_samples_its_covariance():
    W = np.diag([0.02, 0.05, 0.03])
    motion = LinearMotion(np.eye(3) * 0.9, np.array([0.5, 0.5, 0.5]), W)
    motion.validate()
    x = np.ones((4, 3))
    np.testing.assert_allclose(motion.step(x, np.zeros((4, 3))), 0.9 + 0.5)
    noise = motion.sample_noise(np.random.default_rng(0), (200_000,))
    np.testing.assert_allclose(np.cov(noise.T), W, atol=2e-3)
    with pytest.raises(ValueError, match="process_noise"):
        LinearMotion(np.eye(2), np.zeros(2), np.array([[1.0, 2.0], [2.0, 1.0]])).validate()
    with pytest.raises(ValueError, match="drift"):
        LinearMotion(np.eye(3), np.zeros(2), W).validate()


def test_linear_sensor_measures_and_validates():
    sensor = LinearSensor(np.array([[1.0, 0.0, 0.0]]), np.array([[0.1]]))
    sensor.validate(3)
    np.testing.assert_allclose(sensor.measure(np.array([[2.0, 3.0, 4.0]]), np.array([[0.5]])), [[2.5]])
    with pytest.raises(ValueError, match="noise"):
        LinearSensor(np.eye(2), np.zeros((2, 2))).validate(2)
    with pytest.raises(ValueError, match="measurement"):
        LinearSensor(np.eye(2), np.eye(2)).validate(3)
