"""Observation spaces carry finite bounds where the quantity is bounded (one-hots, flags, fractions), and every
observation of an episode, auto-resets included, lies inside its space (issue: PettingZoo's api_test warned that
every entry of some presets was unbounded). Each scenario's table says which entries stay unbounded and why."""

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
# the entry that is the step fraction k / horizon (the last one but for two presets; see their tables)
FRACTION_INDEX = {name: -1 for name in SHORT} | {"gps_denied_nbp": 6, "lossy_fusion": 1}


def _presets():
    return [pytest.param(name, marks=needs_mrclam) if name == "mrclam_relay" else name for name in SHORT]


@pytest.mark.parametrize("name", _presets())
def test_every_observation_of_random_episodes_lies_in_the_bounded_space(name):
    venv = coloc_env.vector_env(name, num_envs=3, seed=5, **SHORT[name])
    space = venv.observation_space
    low, high = space.low, space.high
    fraction = FRACTION_INDEX[name]
    assert (low[fraction], high[fraction]) == (0.0, 1.0), "the step fraction carries its bounds"
    venv.action_space.seed(11)
    obs = venv.reset()
    for _ in range(STEPS):
        assert obs.dtype == space.dtype and np.all(np.isfinite(obs))
        outside = (obs < low) | (obs > high)
        assert not outside.any(), f"entries {sorted(set(np.nonzero(outside)[1]))} leave their bounds"
        actions = np.stack([venv.action_space.sample() for _ in range(venv.num_envs)])
        obs, _, _, _ = venv.step(actions)
