"""Policies of nlos_horizon: paper (AHG), constant, oracle_constant, a trained model."""

import numpy as np
import pytest

import agents
import coloc_env

NAME = "nlos_horizon"


def episode_errors(env, policy, seed):
    observations, _ = env.reset(seed=seed)
    total = np.zeros(len(env.possible_agents))
    while env.agents:
        observations, _, _, _, infos = env.step(policy.act(observations))
        total += [infos[a]["error"] for a in env.possible_agents]
    return total


def test_oracle_constant_is_the_best_constant_horizon_in_hindsight():
    env = coloc_env.parallel_env(NAME, horizon=120)
    oracle = agents.make_policy("oracle_constant", env)
    best = episode_errors(env, oracle, 3)
    chosen = oracle.window.copy()
    for window in (4, 8, 12, 20, 30):
        errors = episode_errors(env, agents.make_policy(f"constant:{window}", env), 3)
        assert np.all(best <= errors + 1e-9)
        np.testing.assert_array_equal(errors[chosen[0] == window], best[chosen[0] == window])
    assert oracle.window.shape == (1, 4)


def test_paper_policy_keeps_every_neighbour_and_restarts_its_centre_each_episode():
    env = coloc_env.parallel_env(NAME, horizon=40)
    policy = agents.make_policy("paper", env)
    for seed in (0, 0):
        observations, _ = env.reset(seed=seed)
        actions = policy.act(observations)
        assert all(env.action_space(a).contains(actions[a]) for a in actions)
        assert all(np.all(actions[a][1:] == 1) for a in actions)
        first = {a: actions[a].copy() for a in actions}
    assert policy.centre.shape == (1, 4)
    for a in first:
        assert first[a][0] + 4 in range(4, 31)
    with pytest.raises(ValueError, match="likelihood"):
        agents.make_policy("paper:bayes", env)
    with pytest.raises(ValueError, match="window"):
        agents.make_policy("constant:50", env)


def test_training_smoke_run_saves_a_model_that_acts(tmp_path):
    from train.training import train

    path = train(NAME, timesteps=512, seed=0, out=str(tmp_path), progress_bar=False, curve_points=0)
    env = coloc_env.parallel_env(NAME, horizon=10)
    policy = agents.make_policy(path, env)
    observations, _ = env.reset(seed=0)
    actions = policy.act(observations)
    assert all(env.action_space(a).contains(np.asarray(actions[a], dtype=np.int64)) for a in actions)
    env.step(actions)
