"""Policies of lossy_fusion: the paper's fixed choices and the generic random policy."""

import numpy as np
import pytest

import agents
import coloc_env


def test_paper_policy_transmits_and_keeps_the_paper_weights():
    env = coloc_env.parallel_env("lossy_fusion", num_agents=3)
    assert agents.available_policies("lossy_fusion") == ["random", "paper", "always", "silent", "periodic",
                                                         "uncertainty", "send_on_delta", "value"]
    policy = agents.make_policy("paper", env)
    observations, _ = env.reset(seed=0)
    actions = policy.act(observations)
    for agent, action in actions.items():
        assert action.dtype == env.action_space(agent).dtype
        assert action[0] == 1.0 and np.all(action[1:] == 0.0)
    decoded = env.scenario.decode_actions(np.stack(list(actions.values()))[None])  # [transmit, tilts...]
    compensation, factors = env.scenario.backend.decode(decoded[..., 1:])
    assert np.all(decoded[0, :, 0] == 1.0) and np.all(factors == 1.0)
    np.testing.assert_allclose(compensation[0], np.tile([0.4, 0.42, 0.18], (2, 1)), atol=1e-15)
    _, _, _, _, infos = env.step(actions)
    assert sum(infos[a]["communication"] for a in env.possible_agents) == 2.0


def test_random_policy_is_seeded_and_in_the_action_space():
    env = coloc_env.parallel_env("lossy_fusion")
    observations, _ = env.reset(seed=0)
    first = agents.make_policy("random", env, seed=3).act(observations)
    again = agents.make_policy("random", env, seed=3).act(observations)
    for agent in env.possible_agents:
        assert env.action_space(agent).contains(first[agent])
        np.testing.assert_array_equal(first[agent], again[agent])


def test_unknown_policy_and_wrong_scenario_are_refused():
    env = coloc_env.parallel_env("lossy_fusion")
    with pytest.raises(ValueError, match="unknown policy"):
        agents.make_policy("greedy", env)
    from agents.lossy_fusion import PaperPolicy

    with pytest.raises(ValueError, match="lossy_fusion"):
        PaperPolicy(coloc_env.parallel_env("bandwidth_fusion"))
