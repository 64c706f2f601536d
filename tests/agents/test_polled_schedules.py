"""The polled schedules of ``contention_localization`` (``agents.contention.PolledPolicy``): one UAV per slot,
never the listening centre, chosen by the stated score."""

from __future__ import annotations

import numpy as np
import pytest

import agents
import coloc_env


def _transmitters(actions: dict, env) -> list[int]:
    return sorted(env.possible_agents.index(a) for a, action in actions.items() if np.asarray(action)[0] == 1)


@pytest.mark.parametrize("name", ["bound_polled", "bound_polled_error", "bound_polled_age"])
def test_one_uav_per_slot_never_the_centre_and_nothing_collides(name):
    env = coloc_env.parallel_env("contention_localization", horizon=12)
    observations, _ = env.reset(seed=3)
    policy = agents.make_policy(name, env)
    assert name in agents.bound_policies("contention_localization")
    core = env.unwrapped.scenario
    for _ in range(12):
        actions = policy.act(observations)
        senders = _transmitters(actions, env)
        assert len(senders) == 1 and senders[0] != 0
        start = core.feature_index("distance")
        heard = [i for i in range(1, 10) if observations["uav_0"][start + i] * 100.0 <= 300.0]
        assert senders[0] in heard  # the centre hears the one it polls
        if name == "bound_polled_error":  # the largest current error among those it hears
            error = core.position_error()[0]
            assert error[senders[0]] == max(error[heard])
        if name == "bound_polled":
            index = core.feature_index("log_trace")
            assert observations[f"uav_{senders[0]}"][index] == max(observations[f"uav_{i}"][index] for i in heard)
        observations, _, _, _, infos = env.step(actions)
        assert sum(info["collisions"] for info in infos.values()) == 0


def test_the_oldest_first_schedule_polls_every_uav_that_sends_in_turn():
    """With every UAV within range of the centre, "age" is round robin over UAVs 1..N-1: each once per N-1 steps."""
    env = coloc_env.parallel_env("contention_localization", num_agents=4, area=100.0, horizon=9)
    observations, _ = env.reset(seed=0)
    policy = agents.make_policy("bound_polled_age", env)
    polled = []
    for _ in range(9):
        actions = policy.act(observations)
        polled += _transmitters(actions, env)
        observations, _, _, _, _ = env.step(actions)
    assert sorted(polled[:3]) == [1, 2, 3] and polled[3:6] == polled[:3] and polled[6:] == polled[:3]


def test_an_unknown_score_is_refused():
    from agents.contention import PolledPolicy

    env = coloc_env.parallel_env("contention_localization")
    with pytest.raises(ValueError, match=r"score must be one of \('trace', 'error', 'age'\), got 'x'"):
        PolledPolicy(env, "x")
