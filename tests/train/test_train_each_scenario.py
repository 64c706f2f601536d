"""A short training run per scenario: it saves, reloads through agents.make_policy and plays an episode;
a model is refused by another scenario (its model.json) and by the same scenario with other spaces (the space
check, compared in full: an ``nvec`` change of the same shape is refused too)."""

import os

import gymnasium
import numpy as np
import pytest

import agents
import agents.sb3
import coloc_env
from tests.conftest import MRCLAM_DATA_ENV, MRCLAM_DATASET6, needs_mrclam
from train.training import train

# Short evaluation configs with the training spaces (the spaces do not depend on these fields).
SHORT = {
    "bandwidth_fusion": {"horizon": 5},
    "lossy_fusion": {"horizon": 5},
    "relay_ukf": {"horizon": 5},
    "nlos_horizon": {"horizon": 60},
    "gps_denied_nbp": {"horizon": 3, "num_particles": 20},
    "mrclam_relay": {"window_steps": 5, "data": MRCLAM_DATASET6},
    "contention_localization": {"horizon": 5},
    # a cross-combination of parts, trained by its name WORLD/NETWORK/BACKEND
    "circles/broadcast/ukf_ccl": {"horizon": 5},
}
# A field per scenario whose change changes the agents' spaces; nlos_horizon's keeps the shape and type and
# changes only the action space's nvec (27 window choices -> 17), the case a shape-and-type check lets through.
# (mrclam_relay has none: its five robots are the data set's.)
OTHER_SPACES = {
    "bandwidth_fusion": {"num_agents": 3},
    "lossy_fusion": {"num_agents": 3},
    "relay_ukf": {"num_agents": 3},
    "nlos_horizon": {"window_max": 20},
    "gps_denied_nbp": {"num_iterations": 3},
    "contention_localization": {"slots": 2},
}


def _spaces(env):
    agent = env.possible_agents[0]
    return env.observation_space(agent), env.action_space(agent)


@pytest.mark.parametrize("scenario", [pytest.param(s, marks=needs_mrclam) if s == "mrclam_relay" else s
                                      for s in sorted(SHORT)])
def test_short_training_saves_reloads_and_plays(scenario, tmp_path, monkeypatch):
    monkeypatch.setenv(MRCLAM_DATA_ENV, MRCLAM_DATASET6)  # training builds mrclam_relay from its default config
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

    # another scenario: refused by the scenario recorded in model.json
    other = "lossy_fusion" if scenario != "lossy_fusion" else "relay_ukf"
    with pytest.raises(ValueError, match=f"was trained on '{scenario}', not '{other}'"):
        agents.make_policy(path, coloc_env.parallel_env(other, **SHORT[other]))

    # the same scenario with other spaces passes the scenario check and is refused by the space check
    if scenario in OTHER_SPACES:
        changed = coloc_env.parallel_env(scenario, **SHORT[scenario], **OTHER_SPACES[scenario])
        model = agents.sb3.model_class(path).load(path, device="cpu")  # relay_ukf's is a MaskablePPO
        assert _spaces(changed) != (model.observation_space, model.action_space)  # the change does change a space
        if scenario == "nlos_horizon":
            ours, theirs = changed.action_space(changed.possible_agents[0]), model.action_space
            # both MultiDiscrete of one shape (the env's is MaskableMultiDiscrete, a subclass), another nvec
            multi = gymnasium.spaces.MultiDiscrete
            assert isinstance(ours, multi) and isinstance(theirs, multi)
            assert ours.shape == theirs.shape and ours.nvec[0] != theirs.nvec[0]
        with pytest.raises(ValueError, match=r"(?s)has (observation|action) space .*, the env has"):
            agents.make_policy(path, changed)

    # without its model.json a model for another scenario is still refused, by its spaces
    os.remove(os.path.splitext(path)[0] + ".json")
    with pytest.raises(ValueError, match=r"(?s)has (observation|action) space .*, the env has"):
        agents.make_policy(path, coloc_env.parallel_env(other, **SHORT[other]))
