"""Every preset observes its episode's communication cost and takes ``cost_range=(lo, hi)`` as compositions do:
the fixed cost observed as configured, a drawn cost reproduced by its seed, inside [lo, hi], charged by the
reward, and a degenerate range the fixed cost."""

import numpy as np
import pytest

import agents
import coloc_env
from coloc_env.composition import draw_costs
from coloc_env.scenarios.composed import cost_generator
from tests.test_bad_config_properties import CHEAP_PRESET, HAVE_MRCLAM

SHORT = {"horizon": 4}
CHEAP = {name: {**SHORT, **CHEAP_PRESET.get(name, {})} for name in coloc_env.SCENARIOS}
CHEAP["mrclam_relay"] = {k: v for k, v in CHEAP["mrclam_relay"].items() if k != "horizon"} | {"window_steps": 4}
CHEAP["nlos_horizon"] = {"horizon": 4}
PRESETS = [name for name in coloc_env.SCENARIOS if name != "mrclam_relay" or HAVE_MRCLAM]


def play(name: str, seed: int, **config):
    """(observations (T + 1, N, d), rewards (T, N), position errors (T, N)) of one seeded episode of the
    preset's ``always`` policy (every message sent)."""
    env = coloc_env.parallel_env(name, **CHEAP[name], **config)
    policy = agents.make_policy("always", env, seed=seed)
    obs, _ = env.reset(seed=seed)
    observations, rewards, errors = [np.stack([obs[a] for a in env.possible_agents])], [], []
    while env.agents:
        obs, reward, _, _, infos = env.step(policy.act(obs))
        observations.append(np.stack([obs[a] for a in env.possible_agents]))
        rewards.append([reward[a] for a in env.possible_agents])
        errors.append([infos[a]["position_error"] for a in env.possible_agents])
    return np.array(observations), np.array(rewards), np.array(errors)


def cost_entry(name: str) -> int:
    return coloc_env.make_core(name, **CHEAP[name]).feature_index("communication_cost")


@pytest.mark.parametrize("name", PRESETS)
def test_the_fixed_cost_is_observed_and_charged(name):
    observations, rewards, errors = play(name, 3, communication_cost=0.7)
    np.testing.assert_array_equal(observations[..., cost_entry(name)], np.float32(0.7))
    free = play(name, 3)
    np.testing.assert_array_equal(free[0][..., cost_entry(name)], 0.0)
    np.testing.assert_array_equal(errors, free[2])  # the cost moves no estimate
    assert rewards.sum() < free[1].sum()  # always sends: the cost is charged


@pytest.mark.parametrize("name", PRESETS)
def test_a_cost_range_is_drawn_per_episode_reproducibly_inside_the_range(name):
    first = play(name, 5, cost_range=(0.1, 10.0))
    again = play(name, 5, cost_range=(0.1, 10.0))
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)
    costs = first[0][..., cost_entry(name)]
    cost = costs[0, 0]
    assert 0.1 <= cost <= 10.0 and np.all(costs == cost)  # one cost for the whole episode, every agent
    np.testing.assert_array_equal(first[2], play(name, 5)[2])  # the draw moves no other draw
    core = coloc_env.make_core(name, **CHEAP[name], cost_range=(0.1, 10.0))
    core.reset([np.random.default_rng(5)])
    # the composition's law and generator: the first child stream of the world's generator
    world_rng = core.part_generators(np.random.default_rng(5))[0]
    assert core.costs[0] == draw_costs((0.1, 10.0), [cost_generator(world_rng)])[0]
    assert np.float32(core.costs[0]) == cost


@pytest.mark.parametrize("name", PRESETS)
def test_a_degenerate_range_is_the_fixed_cost(name):
    ranged = play(name, 2, cost_range=(0.3, 0.3))
    fixed = play(name, 2, communication_cost=0.3)
    for a, b in zip(ranged, fixed, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(("value", "match"), [
    ((2.0, 1.0), r"cost_range must be None or a pair \(lo, hi\) with 0 <= lo <= hi <= 1e\+12, got lo = 2.0 > hi"),
    ((-1.0, 1.0), r"cost_range\[0\] \(lo\) must be in \[0.0, 1000000000000.0\], got -1.0"),
    ((1.0,), r"cost_range must be None or a pair"),
])
@pytest.mark.parametrize("name", ["relay_ukf", "gps_denied_nbp", "lossy_fusion"])
def test_a_bad_cost_range_is_refused_naming_the_preset_and_the_field(name, value, match):
    with pytest.raises(ValueError, match=f"{name}: {match}"):
        coloc_env.parallel_env(name, cost_range=value)
