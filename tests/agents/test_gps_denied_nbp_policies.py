"""Policies of gps_denied_nbp: the paper's schedule (always broadcast when allowed) and silence."""

import numpy as np
import pytest

import agents
import coloc_env


def test_paper_and_silent_emit_the_action_space_dtype():
    env = coloc_env.parallel_env("gps_denied_nbp", num_agents=4, num_particles=10, num_iterations=3, horizon=2)
    observations, _ = env.reset(seed=0)
    assert "paper" in agents.available_policies("gps_denied_nbp") and "silent" in agents.available_policies(
        "gps_denied_nbp")
    for name, bit in (("paper", 1), ("silent", 0)):
        actions = agents.make_policy(name, env).act(observations)
        for agent in env.agents:
            assert env.action_space(agent).contains(actions[agent])
            assert actions[agent].dtype == env.action_space(agent).dtype
            np.testing.assert_array_equal(actions[agent], np.full(3, bit))


def test_policies_refuse_another_scenario():
    with pytest.raises(ValueError, match="gps_denied_nbp"):
        agents.gps_denied_nbp.PaperPolicy(coloc_env.parallel_env("bandwidth_fusion"))
