"""Which policies are realizable, which are bounds, and each scenario's strongest realizable baselines."""

import math
import os

import numpy as np
import pytest

import agents
import coloc_env
from tests.conftest import MRCLAM_DATASET6, MRCLAM_SKIP_REASON

PRESETS = ["bandwidth_fusion", "lossy_fusion", "relay_ukf", "nlos_horizon", "gps_denied_nbp", "mrclam_relay"]
SMALL = {"nlos_horizon": {"horizon": 60}, "gps_denied_nbp": {"horizon": 3, "num_particles": 30},
         "relay_ukf": {"horizon": 5}, "lossy_fusion": {"horizon": 5}}


def _env(scenario):
    if scenario == "mrclam_relay":
        if not os.path.isdir(MRCLAM_DATASET6):
            pytest.skip(MRCLAM_SKIP_REASON)
        return coloc_env.parallel_env(scenario, data=MRCLAM_DATASET6, window_steps=30)
    return coloc_env.parallel_env(scenario, **SMALL.get(scenario, {}))


@pytest.mark.parametrize("scenario", [*PRESETS, "circles/relay/ukf_dcl"])
def test_available_policies_are_realizable_and_include_always_and_silent(scenario):
    available = agents.available_policies(scenario)
    assert {"random", "always", "silent"} <= set(available)
    assert not [name for name in available if name.startswith("bound_") or name.startswith("oracle_constant")]
    bounds = agents.bound_policies(scenario)
    assert all(name.startswith("bound_") for name in bounds) and not set(bounds) & set(available)
    assert set(agents.strongest_baselines(scenario)) <= set(available)


@pytest.mark.parametrize("scenario", PRESETS)
def test_every_listed_policy_and_bound_acts_within_the_action_space(scenario):
    env = _env(scenario)
    for name in agents.available_policies(scenario) + agents.bound_policies(scenario):
        policy = agents.make_policy(name, env, seed=0)
        observations, _ = env.reset(seed=0)
        actions = policy.act(observations)
        assert all(env.action_space(a).contains(np.asarray(actions[a], env.action_space(a).dtype))
                   for a in actions), name
        env.step(actions)


def test_baselines_named_by_the_issue():
    assert agents.strongest_baselines("bandwidth_fusion") == ("oracle_static",)
    assert agents.strongest_baselines("relay_ukf") == ("paper", "no_relay")
    assert agents.strongest_baselines("nlos_horizon") == ("best_constant",)
    assert agents.strongest_baselines("gps_denied_nbp") == ("paper", "threshold")
    assert agents.strongest_baselines("circles/relay/ukf_dcl") == ("always", "silent")
    from train.evaluate import baselines

    assert baselines("lossy_fusion") == ("leader_only_kf", "centralized_A")  # the informed filter is a bound


def test_the_hindsight_oracle_is_a_bound_and_its_old_name_an_alias():
    env = _env("nlos_horizon")
    assert agents.bound_policies("nlos_horizon") == ["bound_hindsight_constant"]
    assert type(agents.make_policy("oracle_constant", env)) is type(agents.make_policy("bound_hindsight_constant", env))
    with pytest.raises(ValueError, match="bounds: \\['bound_hindsight_constant'\\]"):
        agents.make_policy("hindsight", env)


def test_silent_sends_nothing_always_everything():
    env = _env("gps_denied_nbp")
    observations, _ = env.reset(seed=1)
    assert all(np.all(a == 1) for a in agents.make_policy("always", env).act(observations).values())
    assert all(np.all(a == 0) for a in agents.make_policy("silent", env).act(observations).values())
    env = _env("relay_ukf")
    observations, _ = env.reset(seed=1)
    n = len(env.possible_agents)
    assert all(a[1] == n for a in agents.make_policy("silent", env, seed=0).act(observations).values())
    env = _env("lossy_fusion")
    observations, _ = env.reset(seed=1)
    assert all(a[0] < 0 for a in agents.make_policy("silent", env).act(observations).values())
    env = _env("nlos_horizon")
    observations, _ = env.reset(seed=1)
    assert all(np.all(a[1:] == 0) for a in agents.make_policy("silent", env).act(observations).values())
    assert all(np.all(a[1:] == 1) for a in agents.make_policy("always", env).act(observations).values())


def test_threshold_rule_spares_the_broadcasts_of_diffuse_fault_beliefs():
    from agents.gps_denied_nbp import threshold_actions

    obs = np.zeros((3, 7))
    obs[0, 0] = 1.0  # GPS normal, diffuse prior: still broadcasts (its fix is the anchor)
    obs[0, 4] = math.log1p(50.0)
    obs[1, 4] = math.log1p(5.0)  # fault, tight prior
    obs[2, 4] = math.log1p(50.0)  # fault, diffuse prior
    np.testing.assert_array_equal(threshold_actions(obs, 10.0, 2), [[1, 1], [1, 1], [0, 0]])
    np.testing.assert_array_equal(threshold_actions(obs, math.inf, 2), np.ones((3, 2)))
    env = _env("gps_denied_nbp")
    with pytest.raises(ValueError, match="threshold spread must be a number of metres > 0"):
        agents.make_policy("threshold:wide", env)
    with pytest.raises(ValueError, match="threshold spread must be a number of metres > 0"):
        agents.make_policy("threshold:-3", env)


def test_bandwidth_silent_takes_the_least_the_budget_allows_and_always_the_most():
    env = coloc_env.parallel_env("bandwidth_fusion", budget=4, exact_budget=False)  # 3 links, 1..3 components each
    received = {}
    for name in ("always", "silent"):
        observations, _ = env.reset(seed=0)
        _, _, _, _, infos = env.step(agents.make_policy(name, env).act(observations))
        received[name] = [infos[a]["communication"] for a in env.possible_agents]
    assert received == {"always": [4.0] * 4, "silent": [3.0] * 4}
