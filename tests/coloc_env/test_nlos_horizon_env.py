"""The nlos_horizon scenario through its PettingZoo views."""

import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

import agents
import coloc_env
import estimators.afge as af
from coloc_env.backends.nlos import episode_delays
from coloc_env.networks.blocks.bounded_delay import NEVER
from coloc_env.scenarios.nlos_horizon import NlosHorizonScenario
from tests.helpers import play

NAME = "nlos_horizon"
SHORT = {"horizon": 80}
# The known-harmless warnings of pettingzoo.test: unbounded observation entries (positions, log-variances,
# errors: quantities with no finite bound, as the scenario docstring says),
# and a MultiDiscrete action space (a valid Gymnasium space that SB3, TorchRL and RLlib take; api_test
# suggests Box or Discrete). Only these, matched by message.
UNBOUNDED_OBSERVATION = r"Agent's (minimum|maximum) observation space value is -?infinity"
MULTI_DISCRETE_ACTION = r"Action space for each agent probably should be gymnasium.spaces.box or"


def test_pettingzoo_api_and_seed_tests():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # anything else PettingZoo reports only by warning fails the test
        warnings.filterwarnings("ignore", message=UNBOUNDED_OBSERVATION, category=UserWarning)
        warnings.filterwarnings("ignore", message=MULTI_DISCRETE_ACTION, category=UserWarning)
        parallel_api_test(coloc_env.parallel_env(NAME, **SHORT), num_cycles=60)
        parallel_seed_test(lambda: coloc_env.parallel_env(NAME, **SHORT), num_cycles=40)
        api_test(coloc_env.env(NAME, **SHORT), num_cycles=20)


def test_spaces_are_shared_and_sized_by_the_config():
    env = coloc_env.parallel_env(NAME, **SHORT)
    assert env.possible_agents == ["uav_0", "uav_1", "uav_2", "uav_3"]
    assert env.action_space("uav_0") is env.action_space("uav_0")
    assert env.action_space("uav_0").nvec.tolist() == [27] + [2] * 8
    assert env.observation_space("uav_2").shape == (41 + 4 + 1,)  # then the index and the cost
    env.reset(seed=0)
    assert env.state().shape == env.state_space.shape
    small = coloc_env.parallel_env(NAME, num_neighbours=5, n_strongest=3, window_max=20, **SHORT)
    assert small.action_space("uav_0").nvec.tolist() == [17] + [2] * 5


@pytest.mark.parametrize("likelihood", ["predictive", "paper", "smoothed"])
def test_env_with_the_paper_policy_equals_afge_run_directly(likelihood):
    horizon = 150
    env = coloc_env.parallel_env(NAME, horizon=horizon, likelihood=likelihood)
    policy = agents.make_policy("paper", env)
    estimates, rewards = [], []
    observations, _ = env.reset(seed=21)
    while env.agents:
        observations, reward, _, _, infos = env.step(policy.act(observations))
        estimates.append([infos[a]["estimated_position"] for a in env.possible_agents])
        rewards.append([reward[a] for a in env.possible_agents])
    config = env.config
    core = NlosHorizonScenario(config)  # the episode reset(seed=21) draws: the world's draw, the network's delays
    core.reset([np.random.default_rng(21)])
    w, afge = core.world, core.backend.config
    delays = episode_delays(w, core.network, afge.payload)[0]
    Y, y, g = af.fuse_episode(w.signal, w.rss[0], w.aoa[0], w.nav[0], w.modes[0], np.where(delays >= 0, delays, NEVER),
                              config.buffer_length, afge.n_strongest, afge.mode_info, afge.weighting, afge.min_packets)
    truth = np.moveaxis(w.truth[0, :horizon, :, :2], 0, 1)
    out = af.run_fixed_mask(w.motion_model.afge, Y[:, :horizon], y[:, :horizon], g[:, :horizon], truth, w.prior[0],
                            afge.ahg, config.window_max, (likelihood,))
    direct = np.moveaxis(out[f"afge_{likelihood}_position"], 0, 1)
    np.testing.assert_allclose(np.array(estimates), direct, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(-np.array(rewards), np.moveaxis(out[f"afge_{likelihood}"], 0, 1),
                               rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("kwargs, field", [
    ({"p_nlos": 1.5}, "p_nlos"),
    ({"p10": -0.2}, "p10"),
    ({"delay_probs": (0.6, 0.3, 0.2, 0.1)}, "delay_probs"),
    ({"delay_probs": (0.6, 0.2, 0.1)}, "delay_probs"),
    ({"r_inf": 1000.0, "r_sup": 30.0}, "r_inf"),
    ({"r_inf": 0.0}, "r_inf"),
    ({"path_loss_exponent": 0.0}, "path_loss_exponent"),
    ({"group_size": 4}, "group_size"),
    ({"group_size": 0}, "group_size"),
    ({"window_min": 1}, "window_min"),
    ({"window_min": 31}, "window_min"),
    ({"window_min": 24}, "window_max - window_min"),
    ({"window_centre": 31}, "window_centre"),
    ({"window_min": 3}, "buffer_length"),
    ({"sigma_db": 0.0}, "sigma_db"),
    ({"sigma_nav": -1.0}, "sigma_nav"),
    ({"prior_std": (50.0, 0.0, 5.0, 5.0)}, "prior_std"),
    ({"mode_info": "oracle"}, "mode_info"),
    ({"weighting": "equal"}, "weighting"),
    ({"likelihood": "bayes"}, "likelihood"),
    ({"reward": "rmse"}, "reward"),
    ({"n_strongest": 9}, "n_strongest"),
    ({"horizn": 5}, "unknown config key"),
])
def test_bad_config_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        coloc_env.parallel_env(NAME, **kwargs)


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1.5, 27, -1])
def test_bad_actions_are_refused(bad):
    env = coloc_env.parallel_env(NAME, **SHORT)
    env.reset(seed=0)
    actions = {a: env.action_space(a).sample().astype(float) for a in env.agents}
    actions["uav_1"][0] = bad
    with pytest.raises(ValueError, match="of uav_1 must be (finite|an integer)"):
        env.step(actions)


def test_same_seed_gives_identical_episodes_and_reset_continues_the_generator():
    env_a, env_b = coloc_env.parallel_env(NAME, **SHORT), coloc_env.parallel_env(NAME, **SHORT)
    first_a = play(env_a, agents.make_policy("random", env_a, seed=5), 11)
    first_b = play(env_b, agents.make_policy("random", env_b, seed=5), 11)
    assert len(first_a) == 81
    assert data_equivalence(first_a, first_b)
    other = play(coloc_env.parallel_env(NAME, **SHORT), agents.make_policy("random", env_a, seed=5), 12)
    assert not data_equivalence(first_a, other)
    _, info_a = env_a.reset()
    _, info_b = env_b.reset()
    np.testing.assert_array_equal(info_a["uav_0"]["estimated_position"], info_b["uav_0"]["estimated_position"])
    assert not np.array_equal(info_a["uav_0"]["estimated_position"], first_a[0][1]["uav_0"]["estimated_position"])


def test_dropping_every_neighbour_leaves_only_the_prediction_and_costs_count_packets():
    env = coloc_env.parallel_env(NAME, horizon=30, communication_cost=0.5)
    observations, _ = env.reset(seed=4)
    scenario = env.scenario
    keep_all = {a: scenario.encode_actions(np.array(6)) for a in env.agents}
    for _ in range(10):
        observations, rewards, _, _, infos = env.step(keep_all)
    for a in env.possible_agents:
        assert infos[a]["valid"] and infos[a]["communication"] > 0
        assert rewards[a] == pytest.approx(-infos[a]["error"] - 0.5 * infos[a]["communication"], abs=1e-12)
    last = {a: infos[a]["estimated_position"] for a in env.possible_agents}
    drop_all = {a: scenario.encode_actions(np.array(6), np.zeros(8)) for a in env.agents}
    _, rewards, _, _, infos = env.step(drop_all)
    for a in env.possible_agents:
        assert infos[a]["communication"] == 0
        # fewer stamps observed in the window than with every packet, and the output moves on
        assert not np.array_equal(infos[a]["estimated_position"], last[a])
    for _ in range(6):
        _, rewards, _, _, infos = env.step(drop_all)
    for a in env.possible_agents:
        assert not infos[a]["valid"]  # no stamp of the last 6 observed: the prediction A x_hat(k-1)
        assert rewards[a] == pytest.approx(-infos[a]["error"], abs=1e-12)


def test_trace_reward_is_the_output_covariance():
    env = coloc_env.parallel_env(NAME, horizon=20, reward="trace")
    policy = agents.make_policy("paper", env)
    observations, _ = env.reset(seed=1)
    for _ in range(10):
        observations, rewards, _, _, infos = env.step(policy.act(observations))
    for a in env.possible_agents:
        assert rewards[a] == pytest.approx(-infos[a]["trace"], rel=1e-12)
        assert 0 < infos[a]["trace"] < 1e3


def test_rgb_render_draws_a_frame():
    env = coloc_env.parallel_env(NAME, render_mode="rgb_array", **SHORT)
    env.reset(seed=0)
    env.step({a: env.action_space(a).sample() for a in env.agents})
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 10
