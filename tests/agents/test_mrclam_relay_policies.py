"""Policies of mrclam_relay: paper, no_relay, random."""

import os

import numpy as np
import pytest

import agents
import coloc_env
from agents.mrclam_relay import complete_chain_routing, paper_actions, paper_partners

NAME = "mrclam_relay"
REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.conftest import MRCLAM_DATASET6 as DATASET6  # noqa: E402
from tests.conftest import MRCLAM_SKIP_REASON  # noqa: E402

N = 5


def follow(routing: np.ndarray, m: int, n: int) -> list[int]:
    """The chain of source m under a routing table (N holders, N sources), without losses."""
    chain = [m, n]
    while routing[chain[-1], m] < N and routing[chain[-1], m] not in chain:
        chain.append(int(routing[chain[-1], m]))
    return chain


def test_partners_are_the_lowest_recorded_robot_and_chains_are_complete():
    recorded = np.zeros((1, N, N), dtype=bool)
    recorded[0, 0, [3, 1]] = True
    recorded[0, 2, 4] = True
    recorded[0, 4, 2] = True
    partner = paper_partners(recorded)[0]
    np.testing.assert_array_equal(partner, [1, 1, 4, 3, 2])  # robots 1 and 3 recorded nobody
    routing = complete_chain_routing(partner[None])[0]
    assert follow(routing, 0, 1) == [0, 1, 2, 3, 4]
    assert follow(routing, 2, 4) == [2, 4, 0, 1, 3]
    assert follow(routing, 4, 2) == [4, 2, 0, 1, 3]
    assert np.all(routing[:, [1, 3]] == N)  # sources without a measurement: everyone stops
    actions = paper_actions(recorded)
    assert actions.shape == (1, N, N + 1) and actions.dtype == np.int64
    np.testing.assert_array_equal(actions[0, :, 1:], routing)
    assert np.all(paper_actions(recorded, relay=False)[0, :, 1:] == N)


@pytest.mark.skipif(not os.path.isdir(DATASET6), reason=MRCLAM_SKIP_REASON)
def test_paper_reaches_everyone_no_relay_stops_at_n_and_random_runs():
    assert set(agents.available_policies(NAME)) == {"random", "paper", "always", "silent", "no_relay", "periodic",
                                                    "uncertainty", "send_on_delta", "value"}
    for name in ("paper", "no_relay", "random"):
        env = coloc_env.parallel_env(NAME, data=DATASET6, window_steps=40)
        policy = agents.make_policy(name, env, seed=1)
        observations, _ = env.reset(seed=2)
        chains = 0
        while env.agents:
            actions = policy.act(observations)
            assert all(env.action_space(a).contains(np.asarray(actions[a])) for a in actions)
            observations, rewards, _, _, infos = env.step(actions)
            lengths = np.array([infos[a]["chain_length"] for a in env.possible_agents])
            chains += np.count_nonzero(lengths)
            if name == "paper":
                assert set(lengths.tolist()) <= {0, N}
            elif name == "no_relay":
                assert set(lengths.tolist()) <= {0, 2}
            assert np.isfinite(list(rewards.values())).all()
        if name != "random":
            assert chains > 0
    with pytest.raises(ValueError, match="unknown policy"):
        agents.make_policy("oracle", env)
