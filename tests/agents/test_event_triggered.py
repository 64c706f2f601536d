"""The event-triggered families: their extremes are always and silent, their knobs order what they send, and
they act on the agent's own observation alone."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import agents
import coloc_env
from agents import event_triggered
from agents.event_triggered import EXTREMES

SMALL = "drift/broadcast/kalman"  # 4 agents, 50 steps
COVARIANCE = "gps_denied/broadcast/ukf_ccl"  # 10 agents, 30 steps, a covariance per agent


def play(scenario: str, policy_name: str, seed: int):
    """(actions (K, N, A), summed position error, messages) of one seeded episode through the PettingZoo env."""
    env = coloc_env.parallel_env(scenario)
    policy = agents.make_policy(policy_name, env, seed=0)
    observations, _ = env.reset(seed=seed)
    actions, error, messages = [], 0.0, 0.0
    while env.agents:
        chosen = policy.act(observations)
        actions.append(np.stack([chosen[a] for a in env.possible_agents]))
        observations, _, _, _, infos = env.step(chosen)
        error += sum(i["position_error"] for i in infos.values())
        messages += sum(i["messages_sent"] for i in infos.values())
    return np.array(actions), error, messages


@pytest.mark.parametrize("scenario", [SMALL, COVARIANCE])
@pytest.mark.parametrize("family", sorted(EXTREMES))
def test_a_family_at_its_extreme_knobs_is_always_and_silent(scenario, family):
    loud, quiet = EXTREMES[family]
    for knob, reference in ((loud, "always"), (quiet, "silent")):
        actions, error, messages = play(scenario, f"{family}:{knob}", seed=3)
        ref_actions, ref_error, ref_messages = play(scenario, reference, seed=3)
        assert np.array_equal(actions, ref_actions), (family, knob)
        assert error == ref_error and messages == ref_messages


def transmit_entries(scenario: str) -> np.ndarray:
    """Which action entries belong to the network's transport blocks."""
    core = coloc_env.make_core(scenario, batch=1)
    return np.concatenate([np.full(blk.size, part == "network") for blk, part in zip(core.blocks, core.block_parts,
                                                                                     strict=True)])


@pytest.mark.parametrize("period", [2, 5, 10])
def test_periodic_sends_one_in_p_of_always_staggered_by_index(period):
    actions, _, _ = play(SMALL, f"periodic:{period}", seed=1)  # 50 steps: P divides the horizon
    always, _, _ = play(SMALL, "always", seed=1)
    entries = transmit_entries(SMALL)
    sent, full = actions[..., entries].sum(), always[..., entries].sum()
    assert sent * period == full
    k, i = np.nonzero(actions[..., entries].any(axis=-1))
    assert np.all((k - i) % period == 0)


def test_periodic_with_p_equal_n_is_round_robin():
    actions, _, _ = play(SMALL, "periodic", seed=2)  # the default P = N = 4
    entries = transmit_entries(SMALL)
    assert np.all(actions[..., entries].any(axis=-1).sum(axis=1) == 1)  # one agent per step


def test_uncertainty_sends_less_as_its_threshold_grows():
    """Over seeded episodes, a higher threshold never sends more on average (the feedback of what was sent on the
    covariance can make single episodes cross, so the means over 4 episodes are compared, with no tolerance
    needed on this grid)."""
    messages = []
    for knob in ("0", "5", "50", "500", "inf"):
        messages.append(np.mean([play(COVARIANCE, f"uncertainty:{knob}", seed=s)[2] for s in range(4)]))
    assert all(a >= b for a, b in zip(messages[:-1], messages[1:], strict=True)), messages
    assert messages[0] > messages[2] > messages[-1] == 0


@pytest.mark.parametrize(("family", "knobs"), [("send_on_delta", ("0", "0.5", "2", "5", "20", "inf")),
                                               ("value", ("0", "0.5", "2", "5", "20", "inf"))])
def test_send_on_delta_and_value_send_less_as_their_knob_grows(family, knobs):
    """Over 4 seeded episodes of the small composition, a higher knob never sends more on average, and the ends and
    a middle knob are strictly apart (no tolerance needed on this grid: the means are compared as they are)."""
    messages = [np.mean([play(SMALL, f"{family}:{knob}", seed=s)[2] for s in range(4)]) for knob in knobs]
    assert all(a >= b for a, b in zip(messages[:-1], messages[1:], strict=True)), messages
    assert messages[0] > messages[1] > messages[-1] == 0, messages


def test_value_refuses_a_backend_without_a_message_value(monkeypatch):
    env = coloc_env.parallel_env(SMALL)
    monkeypatch.setattr(env.unwrapped.scenario.backend, "position_process_noise", lambda inputs=None: None)
    with pytest.raises(ValueError, match="policy 'value' reads the message value the backend declares; backend "
                                         "kalman on world drift declares none"):
        agents.make_policy("value:1", env)


@pytest.mark.parametrize("name", ["periodic:0", "periodic:2.5", "periodic:-1", "periodic:x", "uncertainty:-1",
                                  "uncertainty:nan", "uncertainty:abc", "send_on_delta:-0.5", "send_on_delta:nan",
                                  "value:-1", "value:x"])
def test_a_bad_knob_is_refused_naming_the_family(name):
    env = coloc_env.parallel_env(SMALL)
    family = name.split(":")[0]
    with pytest.raises(ValueError, match=f"{family}'s knob \\({family}:x\\) must be"):
        agents.make_policy(name, env)


def test_families_are_listed_where_the_network_has_a_transport_decision():
    assert {"periodic", "uncertainty", "send_on_delta", "value"} <= set(agents.available_policies(SMALL))
    assert "periodic" not in agents.available_policies("drift/ideal/kalman")
    env = coloc_env.parallel_env("drift/ideal/kalman")
    with pytest.raises(ValueError, match="unknown policy 'periodic' for drift/ideal/kalman"):
        agents.make_policy("periodic", env)
    with pytest.raises(ValueError, match="needs a transport decision; network ideal has none for backend kalman"):
        event_triggered.periodic(env)
    with pytest.raises(ValueError, match="preset bandwidth_fusion declares none"):  # no transmit decision maps
        event_triggered.periodic(coloc_env.parallel_env("bandwidth_fusion", horizon=3))


class _SpacesOnly:
    """What a realizable policy may read of its env once built: the agents and the spaces."""

    def __init__(self, env):
        self.possible_agents = env.possible_agents
        self.action_space = env.action_space
        self.observation_space = env.observation_space


@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_a_family_acts_on_the_observation_alone(data):
    """Built on the env, then cut off from it (only the spaces left): the same observation gives the same
    action, whatever the env's state, so the rule reads nothing but what the agent observes."""
    env = coloc_env.parallel_env(COVARIANCE)
    name = data.draw(st.sampled_from(["periodic:3", "uncertainty:1.5", "send_on_delta:2", "value:1.5"]))
    policy = agents.make_policy(name, env)
    space = env.observation_space(env.possible_agents[0])
    low, high = np.maximum(space.low, -50.0), np.minimum(space.high, 50.0)
    observation = np.array([data.draw(st.floats(float(lo), float(hi), allow_nan=False))
                            for lo, hi in zip(low, high, strict=True)], dtype=np.float32)
    agent = data.draw(st.sampled_from(env.possible_agents))
    expected = policy.act({agent: observation})[agent]
    policy.env = _SpacesOnly(env)
    assert np.array_equal(policy.act({agent: observation})[agent], expected)
