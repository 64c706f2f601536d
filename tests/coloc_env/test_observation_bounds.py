"""Observation spaces carry finite bounds where the quantity is bounded (one-hots, flags, fractions), and every
observation of an episode, auto-resets included, lies inside its space (PettingZoo's api_test warns about a
space whose entries are all unbounded). Each scenario's table says which entries stay unbounded and why."""

import numpy as np
import pytest

import coloc_env
from tests.conftest import MRCLAM_DATASET6, needs_mrclam

STEPS = 14  # two episodes of SHORT's length: the auto-reset's first observation is checked too
SHORT = {
    "bandwidth_fusion": {"horizon": 7},
    "lossy_fusion": {"horizon": 7},
    "relay_ukf": {"horizon": 7},
    "gps_denied_nbp": {"horizon": 7, "num_particles": 30},
    "nlos_horizon": {"horizon": 7},
    "mrclam_relay": {"window_steps": 7, "data": MRCLAM_DATASET6},
}


def _presets():
    return [pytest.param(name, marks=needs_mrclam) if name == "mrclam_relay" else name for name in SHORT]


@pytest.mark.parametrize("name", _presets())
def test_every_observation_of_random_episodes_lies_in_the_bounded_space(name):
    venv = coloc_env.vector_env(name, num_envs=3, seed=5, **SHORT[name])
    space = venv.observation_space
    low, high = space.low, space.high
    fraction = venv.scenario.feature_index("step_fraction")
    assert (low[fraction], high[fraction]) == (0.0, 1.0), "the step fraction carries its bounds"
    venv.action_space.seed(11)
    obs = venv.reset()
    for _ in range(STEPS):
        assert obs.dtype == space.dtype and np.all(np.isfinite(obs))
        outside = (obs < low) | (obs > high)
        assert not outside.any(), f"entries {sorted(set(np.nonzero(outside)[1]))} leave their bounds"
        actions = np.stack([venv.action_space.sample() for _ in range(venv.num_envs)])
        obs, _, _, _ = venv.step(actions)


def test_the_bimodality_entry_is_at_most_one_and_one_for_two_equal_clusters():
    """gps_denied_nbp's entry 5, Sarle's (g^2 + 1) / kappa, is bounded by 1 (Pearson's inequality, which the
    particles' own moments obey) and reaches it for two equal point masses; a Gaussian cloud is near 1/3."""
    from coloc_env.scenarios.gps_denied_nbp import bimodality

    rng = np.random.default_rng(8)
    clouds = rng.standard_normal((200, 60, 2)) * rng.uniform(0.1, 50, (200, 1, 2))
    clouds[100:, :30] += rng.uniform(5, 500, (100, 1, 2))  # two clusters of various spreads and distances
    values = bimodality(clouds)
    assert np.all(values <= 1.0) and np.all(values > 0)
    assert bimodality(np.array([[0.0, 0.0]] * 25 + [[7.0, 3.0]] * 25)) == pytest.approx(1.0, abs=1e-12)
    assert abs(float(np.mean(bimodality(rng.standard_normal((400, 400, 2))))) - 1 / 3) < 0.02
