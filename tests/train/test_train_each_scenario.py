"""A short training run per scenario: it saves, reloads through agents.make_policy and plays an episode."""

import numpy as np
import pytest

import agents
import coloc_env
from train.training import train

# Short evaluation configs with the training spaces (the spaces do not depend on these fields).
SHORT = {
    "bandwidth_fusion": {"horizon": 5},
    "lossy_fusion": {"horizon": 5},
    "relay_ukf": {"horizon": 5},
    "nlos_horizon": {"horizon": 60},
    "gps_denied_nbp": {"horizon": 3, "num_particles": 20},
}


@pytest.mark.parametrize("scenario", sorted(SHORT))
def test_short_training_saves_reloads_and_plays(scenario, tmp_path):
    path = train(scenario, timesteps=1, seed=0, out=str(tmp_path), progress_bar=False, curve_points=0)
    env = coloc_env.parallel_env(scenario, **SHORT[scenario])
    policy = agents.make_policy(path, env)
    observations, _ = env.reset(seed=5)
    steps = 0
    while env.agents:
        actions = policy.act(observations)
        assert set(actions) == set(observations)
        assert all(env.action_space(a).contains(np.asarray(actions[a]).astype(env.action_space(a).dtype))
                   for a in actions)
        observations, rewards, _, _, infos = env.step(actions)
        assert all(np.isfinite(r) for r in rewards.values())
        steps += 1
    assert steps == env.scenario.horizon
    # a model saved for one scenario is refused by another whose spaces differ
    other = "lossy_fusion" if scenario != "lossy_fusion" else "relay_ukf"
    with pytest.raises(ValueError):
        agents.make_policy(path, coloc_env.parallel_env(other, **SHORT[other]))
