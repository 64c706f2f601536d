"""The lossy_fusion scenario through its PettingZoo views."""

import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

import agents
import coloc_env
import estimators.lossy_fusion as lf
from agents.lossy_fusion import paper_actions
from tests.helpers import play

NAME = "lossy_fusion"
X0 = np.array([100.0, 10.0, 100.0, 10.0, 100.0, 0.0])
P0 = np.diag([100.0, 5.0, 100.0, 5.0, 100.0, 5.0])
# The known-harmless warnings of pettingzoo.test: unbounded observation entries (positions, log-variances,
# errors: quantities with no finite bound, as the scenario docstring says). Only these, matched by message.
UNBOUNDED_OBSERVATION = r"Agent's (minimum|maximum) observation space value is -?infinity"


@pytest.mark.parametrize("num_agents", [2, 3])
def test_pettingzoo_api_and_seed_tests(num_agents):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # anything else PettingZoo reports only by warning fails the test
        warnings.filterwarnings("ignore", message=UNBOUNDED_OBSERVATION, category=UserWarning)
        parallel_api_test(coloc_env.parallel_env(NAME, num_agents=num_agents), num_cycles=120)
        parallel_seed_test(lambda: coloc_env.parallel_env(NAME, num_agents=num_agents), num_cycles=60)
        api_test(coloc_env.env(NAME, num_agents=num_agents), num_cycles=30)


def test_spaces_are_shared_and_cached():
    env = coloc_env.parallel_env(NAME, num_agents=4)
    assert env.possible_agents == ["uav_0", "uav_1", "uav_2", "uav_3"]
    assert env.action_space("uav_0") is env.action_space("uav_0")
    assert env.action_space("uav_0") == env.action_space("uav_3")
    assert env.action_space("uav_1").shape == (1 + 4 + 9,)
    assert env.observation_space("uav_1").shape == (3 + 12 + 4 + 5,)  # then the index and the named features
    env.reset(seed=0)
    assert env.state().shape == env.state_space.shape == (4 * 24 + 9,)


@pytest.mark.parametrize("kwargs, field", [
    ({"on_time_probability": 0.7, "late_probability": 0.4}, "on_time_probability \\+ late_probability"),
    ({"on_time_probability": 0.0, "late_probability": 0.0}, "on_time_probability \\+ late_probability"),
    ({"on_time_probability": 1.2}, "on_time_probability"),
    ({"late_probability": -0.1}, "late_probability"),
    ({"measurement_noise": -10.0}, "measurement_noise"),
    ({"measurement_noise": 0.0}, "measurement_noise"),
    ({"accel_noise": -5.0}, "accel_noise"),
    ({"num_agents": 1}, "num_agents"),
    ({"num_agents": 2.5}, "num_agents"),
    ({"period": 0.0}, "period"),
    ({"initial_cov": np.diag([100.0, 5, 100, 5, 100, -5]).tolist()}, "initial_cov"),
    ({"initial_cov": np.zeros((6, 6)).tolist()}, "^lossy_fusion: initial_cov must be positive definite"),
    ({"num_uavs": 3, "num_agents": 3}, "num_uavs is another name of num_agents"),
    ({"initial_state": [100.0, 10.0, 100.0]}, "initial_state"),
    ({"reward": "rmse"}, "reward"),
    ({"horizon": 0}, "horizon"),
    ({"communication_cost": -1.0}, "communication_cost"),
    ({"weight_logit_scale": 0.0}, "weight_logit_scale"),
    ({"alpha1": 0.4}, "unknown config key"),
])
def test_bad_config_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        coloc_env.parallel_env(NAME, **kwargs)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_is_refused(bad):
    env = coloc_env.parallel_env(NAME)
    env.reset(seed=0)
    actions = {a: env.action_space(a).sample() for a in env.agents}
    actions["uav_1"][0] = bad
    with pytest.raises(ValueError, match="finite"):
        env.step(actions)


def test_wrong_action_shape_is_refused():
    env = coloc_env.parallel_env(NAME)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step({a: np.zeros(3) for a in env.agents})


def test_same_seed_gives_identical_episodes_and_reset_continues_the_generator():
    env_a, env_b = coloc_env.parallel_env(NAME), coloc_env.parallel_env(NAME)
    policy_a, policy_b = agents.make_policy("random", env_a, seed=5), agents.make_policy("random", env_b, seed=5)
    first_a, first_b = play(env_a, policy_a, 11), play(env_b, policy_b, 11)
    assert len(first_a) == 101
    assert data_equivalence(first_a, first_b)
    other = play(coloc_env.parallel_env(NAME), agents.make_policy("random", env_a, seed=5), 12)
    assert not data_equivalence(first_a, other)
    _, info_a = env_a.reset()
    _, info_b = env_b.reset()
    np.testing.assert_array_equal(info_a["uav_0"]["true_position"], info_b["uav_0"]["true_position"])
    assert not np.array_equal(info_a["uav_0"]["true_position"], first_a[0][1]["uav_0"]["true_position"])


@pytest.mark.parametrize("num_agents, seed", [(2, 7), (4, 3)])
def test_env_with_paper_policy_equals_the_estimator(num_agents, seed):
    env = coloc_env.parallel_env(NAME, num_agents=num_agents)
    policy = agents.make_policy("paper", env)
    observations, infos = env.reset(seed=seed)
    scenario = env.scenario
    # the network's link draws, fixed at reset: the filter sees what the env's network delivers
    truth, z, outcome = scenario.world.truth[0].copy(), scenario.z[0].copy(), scenario.link_outcomes()[0]
    estimates, covariances = lf.distributed_filter(scenario.model, X0, P0, z, outcome)
    H = scenario.H
    k = 0
    while env.agents:
        observations, rewards, _, _, infos = env.step(policy.act(observations))
        expected = H @ estimates[k]
        for agent in env.possible_agents:
            np.testing.assert_allclose(infos[agent]["estimated_position"], expected, atol=1e-12, rtol=0)
            np.testing.assert_allclose(infos[agent]["true_position"], H @ truth[k], atol=1e-12, rtol=0)
            loss = np.sum((expected - H @ truth[k]) ** 2)
            assert rewards[agent] == pytest.approx(-loss, rel=1e-12, abs=1e-12)
        assert infos["uav_0"]["claimed_trace"] == pytest.approx(np.trace(H @ covariances[k] @ H.T), rel=1e-12)
        assert [infos[a]["link_outcome"] for a in env.possible_agents] == outcome[k].tolist()
        k += 1
    assert k == 100
    # the world the env drew is the paper's: the leader's link is always on time, followers' sometimes not
    assert np.all(outcome[:, 0] == lf.ON_TIME) and np.any(outcome[:, 1:] != lf.ON_TIME)


def test_silent_followers_deliver_nothing_and_pay_no_communication_cost():
    env = coloc_env.parallel_env(NAME, num_agents=3, communication_cost=2.0)
    paper = paper_actions(env.scenario)
    silent = paper.copy()
    silent[1:, 0] = -1.0
    observations, _ = env.reset(seed=1)
    for k in range(1, 6):
        observations, rewards, _, _, infos = env.step({a: silent[i] for i, a in enumerate(env.possible_agents)})
        for agent in ("uav_1", "uav_2"):
            assert infos[agent]["communication"] == 0.0
            # the prior packet from before k = 0 stays held: its age grows by one a slot
            assert infos[agent]["packet_age"] == k
            # (at slot 0 a late draw re-delivers that prior packet, the buffer before k = 0)
            assert infos[agent]["delivered"] == (lf.LATE if k == 1 and infos[agent]["link_outcome"] == lf.LATE
                                                 else lf.LOST)
        np.testing.assert_allclose(observations["uav_0"][3:5], k / 10, rtol=1e-6)
        assert rewards["uav_1"] == pytest.approx(-infos["uav_1"]["error"], abs=1e-12)
    observations, rewards, _, _, infos = env.step({a: paper[i] for i, a in enumerate(env.possible_agents)})
    for agent in ("uav_1", "uav_2"):
        assert infos[agent]["communication"] == 1.0
        assert rewards[agent] == pytest.approx(-infos[agent]["error"] - 2.0, abs=1e-12)
        # a packet arrives now only if this slot's draw is on time: nothing was sent last slot
        assert (infos[agent]["delivered"] == lf.ON_TIME) == (infos[agent]["link_outcome"] == lf.ON_TIME)
    assert rewards["uav_0"] == pytest.approx(-infos["uav_0"]["error"], abs=1e-12)


def test_rewards_follow_the_reward_option():
    for reward in ("error", "trace"):
        env = coloc_env.parallel_env(NAME, reward=reward)
        policy = agents.make_policy("paper", env)
        observations, _ = env.reset(seed=3)
        for _ in range(4):
            observations, rewards, _, _, infos = env.step(policy.act(observations))
        key = "error" if reward == "error" else "claimed_trace"
        for agent in env.possible_agents:
            assert rewards[agent] == pytest.approx(-infos[agent][key], abs=1e-12)
        np.testing.assert_allclose(sum(infos[a]["fusion_weight"] for a in env.possible_agents), 1.0, atol=1e-12)


def test_weight_tilts_reach_the_estimator():
    """Tilting the leader's fusion weight toward itself moves the weights the estimator uses."""
    env = coloc_env.parallel_env(NAME)
    scenario = env.scenario
    actions = paper_actions(scenario)
    actions[0, 1] = 1.0  # the leader's own fusion tilt
    actions[0, 4] = -1.0  # follower 1: less weight on x(s|s-1)
    decoded = scenario.decode_actions(actions[None])  # the network's transmit, then the backend's tilts
    compensation, factors = scenario.backend.decode(decoded[..., 1:])
    assert decoded[0, 1:, 0].tolist() == [1.0]
    np.testing.assert_allclose(factors, [[np.exp(3.0), 1.0]])
    paper_c = lf.compensation_weights(0.4, 0.3)
    expected = paper_c * np.exp([0.0, -3.0, 0.0])
    np.testing.assert_allclose(compensation[0, 0], expected / expected.sum(), atol=1e-15)
    env.reset(seed=0)
    _, _, _, _, tilted = env.step({a: actions[i] for i, a in enumerate(env.possible_agents)})
    env.reset(seed=0)
    _, _, _, _, plain = env.step({a: paper_actions(scenario)[i] for i, a in enumerate(env.possible_agents)})
    assert tilted["uav_0"]["fusion_weight"] > plain["uav_0"]["fusion_weight"]


def test_observation_is_local():
    env = coloc_env.parallel_env(NAME, num_agents=3)
    policy = agents.make_policy("paper", env)
    observations, _ = env.reset(seed=0)
    np.testing.assert_allclose(observations["uav_0"][2], np.log(315.0), rtol=1e-6)
    for _ in range(3):
        observations, *_ = env.step(policy.act(observations))
    assert observations["uav_0"][0] == 1.0 and observations["uav_1"][0] == 0.0
    assert observations["uav_1"][1] == pytest.approx(3 / 100)
    # followers know only their own filter: the leader's slots are zero
    np.testing.assert_array_equal(observations["uav_1"][3:11], 0.0)
    assert np.all(observations["uav_0"][5:11] > 0)


def test_rgb_render_draws_a_frame():
    env = coloc_env.parallel_env(NAME, render_mode="rgb_array", num_agents=3)
    env.reset(seed=0)
    assert env.render().shape[2] == 3
    env.step({a: env.action_space(a).sample() for a in env.agents})
    frame = env.render()
    assert frame.ndim == 3 and frame.dtype == np.uint8 and frame.std() > 10
    assert coloc_env.parallel_env(NAME).render() is None


def test_without_time_stamps_the_leader_sees_arrivals_not_ages():
    """Packets carry no stamp in the paper: the leader's entry 3 counts the slots since the held packet
    arrived, which is its age except while a late packet is held (one slot less); with ``time_stamps`` the
    entry is the age. Same episode either way (the option changes only the observation)."""
    seen = {}
    for stamps in (False, True):
        env = coloc_env.parallel_env("lossy_fusion", horizon=60, time_stamps=stamps)
        scenario = env.unwrapped.scenario
        policy = agents.make_policy("paper", env)
        observations, _ = env.reset(seed=4)
        entry, ages, late_held = [], [], []
        held_late = False
        for _ in range(60):
            observations, *_ = env.step(policy.act(observations))
            code = scenario.fusion.delivered[0, 0]
            held_late = code == lf.LATE or (held_late and code == lf.LOST)
            entry.append(observations["uav_0"][3] * 10.0)
            ages.append(scenario.fusion.held_age[0, 0])
            late_held.append(held_late)
        seen[stamps] = (np.array(entry), np.array(ages), np.array(late_held))
    entry, ages, late_held = seen[False]
    assert late_held.any() and not late_held.all()
    np.testing.assert_allclose(entry, ages - late_held, atol=1e-5)
    np.testing.assert_allclose(seen[True][0], ages, atol=1e-5)
    np.testing.assert_array_equal(seen[True][1], ages)
