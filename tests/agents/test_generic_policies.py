"""Generic policies of any composition: always, silent and the one-step-look-ahead greedy."""

import copy

import numpy as np
import pytest

import agents
import coloc_env
from agents.generic import GreedyPolicy

SPEC = coloc_env.compose(world="circles", network="relay", backend="ukf_dcl", reward="trace",
                         communication_cost=0.02, horizon=8)



def _messages(core, actions: np.ndarray) -> float:
    """The messages a step of ``actions`` would send, on a copy of the core (the core itself does not move)."""
    trial = copy.deepcopy(core)
    trial.step(actions[None])
    return float(trial.network.messages_sent[0].sum())

def test_greedy_is_never_worse_than_always_one_step_ahead_and_sends_less():
    env = coloc_env.parallel_env(SPEC)
    greedy = agents.make_policy("greedy", env)
    observations, _ = env.reset(seed=5)
    core = env.unwrapped.scenario
    always = np.tile(core.action_vector("maximum"), (core.num_agents, 1))
    sent = {"greedy": 0.0, "always": 0.0}
    while env.agents:
        chosen = greedy.act(observations)
        stacked = np.stack([chosen[a] for a in env.possible_agents])
        cost_greedy = GreedyPolicy._team_cost(core, stacked)
        cost_always = GreedyPolicy._team_cost(core, always)
        assert cost_greedy <= cost_always + 1e-12
        sent["always"] += _messages(core, always)
        observations, _, _, _, infos = env.step(chosen)
        sent["greedy"] += sum(infos[a]["messages_sent"] for a in env.possible_agents)
    assert sent["greedy"] < sent["always"]


def test_greedy_refuses_what_it_cannot_score():
    no_decision = coloc_env.parallel_env(coloc_env.compose(world="circles", network="ideal", backend="ukf_ccl"))
    with pytest.raises(ValueError, match="greedy.*needs a decision"):
        agents.make_policy("greedy", no_decision)
    with pytest.raises(ValueError, match="greedy.*needs a composition"):
        GreedyPolicy(coloc_env.parallel_env("relay_ukf"))  # a preset's own greedy is agents.relay_ukf's
