"""The ``contention_localization`` preset: collisions cost the centre its readings, and the bounds show it."""

from __future__ import annotations

import numpy as np
import pytest

import agents
import coloc_env


def test_the_delivered_bound_shows_what_collisions_and_a_schedule_do():
    """``always``: every UAV within range of the centre collides, so the centre's delivered bound sits well above
    the centralized one; round robin delivers one UAV's readings per step and its bound is below always's. For the
    centre's own column (the receiver of the ``central`` kind) local >= delivered >= centralized."""
    config = {"horizon": 12}
    env = coloc_env.parallel_env("contention_localization", **config)
    schedule = agents.make_policy("round_robin", env)
    bounds = {name: coloc_env.pcrb("contention_localization", episodes=2, seed=0, policy=policy, **config)
              for name, policy in (("always", "always"), ("round_robin", schedule.act))}
    always, rr = bounds["always"], bounds["round_robin"]
    late = slice(4, None)  # after the first steps, when the prior no longer dominates
    assert np.mean(always["delivered"][late]) > 5 * np.mean(always["centralized"][late])
    assert np.mean(rr["delivered"][late]) < 0.8 * np.mean(always["delivered"][late])
    for b in (always, rr):
        centre = (b["local"][:, 0], b["delivered"][:, 0], b["centralized"][:, 0])
        assert np.all(centre[0] >= centre[1] * (1 - 1e-9)) and np.all(centre[1] >= centre[2] * (1 - 1e-9))


def test_the_preset_is_the_composition_of_its_parts_and_its_policies_read_the_network():
    spec = coloc_env.PRESETS["contention_localization"]
    assert (spec.world.name, spec.network.name, spec.backend.name) == ("gps_denied", "contention", "ukf_ccl")
    assert spec.network.comm_range == spec.world.comm_range == 300.0
    names = agents.available_policies("contention_localization")
    assert {"paper", "round_robin", "aloha", "always", "silent"} <= set(names)
    assert {"round_robin", "aloha"} <= set(agents.available_policies("circles/contention/ukf_ccl"))
    assert "round_robin" not in agents.available_policies("circles/broadcast/ukf_ccl")
    env = coloc_env.parallel_env(coloc_env.compose(world="circles", network="broadcast", backend="ukf_ccl"))
    with pytest.raises(ValueError, match=r"unknown policy 'round_robin' for circles/broadcast/ukf_ccl"):
        agents.make_policy("round_robin", env)
    with pytest.raises(ValueError, match=r"aloha's transmit probability \(aloha:p\) must be a number in \(0, 1\], "
                                         r"got '1\.5'"):
        agents.make_policy("aloha:1.5", coloc_env.parallel_env("contention_localization"))


def test_always_collides_and_round_robin_does_not_on_the_preset():
    sums = {}
    for name in ("always", "round_robin"):
        env = coloc_env.parallel_env("contention_localization", horizon=10)
        policy = agents.make_policy(name, env, seed=0)
        observations, _ = env.reset(seed=0)
        total = np.zeros(3)
        while env.agents:
            observations, _, _, _, infos = env.step(policy.act(observations))
            total += [sum(infos[a][key] for a in env.possible_agents)
                      for key in ("link_attempts", "link_deliveries", "collisions")]
        sums[name] = total
    assert sums["always"][2] > 0.9 * sums["always"][0]  # most of always's link attempts collide
    assert sums["round_robin"][2] == 0 and sums["round_robin"][1] == sums["round_robin"][0] > 0
