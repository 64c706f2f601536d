"""Policies of relay_ukf: paper, no_relay, random, a trained model."""

import numpy as np
import pytest

import agents
import coloc_env
from agents.relay_ukf import nearest_chain_choices, paper_actions, random_partners

NAME = "relay_ukf"


def test_nearest_chain_choices_follow_the_nearest_platform_not_yet_reached():
    positions = np.array([[0.0, 0.0], [50.0, 0.0], [10.0, 0.0], [30.0, 0.0]])
    distances = np.linalg.norm(positions[:, None] - positions[None], axis=-1)[None]
    choice = nearest_chain_choices(distances, np.array([0]), np.array([1]))[0]
    # 0 -> 1 (measured), then from 1 the nearest unreached is 3 (20 m), then 2; 2 stops
    np.testing.assert_array_equal(choice, [1, 3, 4, 2])
    none = nearest_chain_choices(distances, np.array([-1]), np.array([1]))[0]
    np.testing.assert_array_equal(none, [4, 4, 4, 4])


def test_random_partners_are_uniform_over_the_others_and_reproducible():
    measuring = np.full(30000, 2)
    partners = random_partners(np.random.default_rng(0), measuring, 4)
    assert not np.any(partners == 2)
    np.testing.assert_allclose(np.bincount(partners, minlength=4)[[0, 1, 3]] / 30000, 1 / 3, atol=0.01)
    np.testing.assert_array_equal(partners, random_partners(np.random.default_rng(0), measuring, 4))


def test_paper_policy_reaches_everyone_and_no_relay_stops_at_n():
    for name, hops in (("paper", 3), ("no_relay", 1)):
        env = coloc_env.parallel_env(NAME, measurement_probability=1.0, horizon=40)
        policy = agents.make_policy(name, env, seed=1)
        observations, _ = env.reset(seed=0)
        partners = set()
        while env.agents:
            actions = policy.act(observations)
            assert all(env.action_space(a).contains(actions[a]) for a in actions)
            observations, _, _, _, infos = env.step(actions)
            assert infos["platform_0"]["hops"] == hops
            partners.update(int(infos[a]["partner"]) for a in infos if infos[a]["measuring"])
        assert len(partners) == 4  # random partners: every platform gets measured over 40 steps


def test_paper_policy_is_reproducible_from_its_seed_and_unknown_names_fail():
    env = coloc_env.parallel_env(NAME, measurement_probability=1.0)
    observations, _ = env.reset(seed=0)
    draws = []
    for seed in (3, 3, 4):
        policy = agents.make_policy("paper", env, seed=seed)
        draws.append([policy.act(observations)["platform_" + str(int(env.scenario.world.schedule[0, 0]))][0]
                      for _ in range(20)])
    assert draws[0] == draws[1] and draws[0] != draws[2]
    with pytest.raises(ValueError, match="unknown policy"):
        agents.make_policy("oracle", env)
    assert set(agents.available_policies(NAME)) == {"random", "paper", "always", "silent", "no_relay", "nearest_local",
                                                    "periodic", "uncertainty", "send_on_delta", "value"}


def test_paper_actions_batch_equals_single_calls():
    rng_a, rng_b = np.random.default_rng(7), np.random.default_rng(7)
    distances = np.random.default_rng(0).uniform(10, 100, (5, 4, 4))
    distances = 0.5 * (distances + np.swapaxes(distances, 1, 2))
    measuring = np.array([0, -1, 3, 2, 1])
    batch = paper_actions(distances, measuring, rng_a)
    partner = random_partners(rng_b, measuring, 4)
    for b in range(5):
        if measuring[b] >= 0:
            assert batch[b, measuring[b], 0] == partner[b]
    assert batch.dtype == np.int64


def test_training_smoke_then_the_saved_model_acts(tmp_path):
    from train.training import train

    path = train(NAME, timesteps=300, seed=0, out=str(tmp_path), progress_bar=False, curve_points=0)
    env = coloc_env.parallel_env(NAME, horizon=20)
    policy = agents.make_policy(path, env)
    observations, _ = env.reset(seed=0)
    while env.agents:
        actions = policy.act(observations)
        assert all(env.action_space(a).contains(np.asarray(actions[a])) for a in actions)
        observations, rewards, *_ = env.step(actions)
    assert all(np.isfinite(list(rewards.values())))


def test_nearest_local_reads_only_each_agents_own_observation():
    env = coloc_env.parallel_env(NAME, horizon=5)
    observations, _ = env.reset(seed=3)
    policy = agents.make_policy("nearest_local", env)
    actions = policy.act(observations)
    N = len(env.possible_agents)
    for i, agent in enumerate(env.possible_agents):
        alone = policy.act({agent: observations[agent]})[agent]  # the same choice without the others' views
        np.testing.assert_array_equal(alone, actions[agent])
        distances = observations[agent][N + 1:2 * N + 1].astype(float)
        distances[i] = np.inf
        assert actions[agent][1] == np.argmin(distances)
        assert actions[agent][0] == (np.argmin(distances) if observations[agent][N] > 0.5 else i)
