"""The gps_denied_nbp scenario through its PettingZoo views."""

import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

import agents
import coloc_env
import estimators.dnbp as dn
from coloc_env.config import build_config
from coloc_env.networks.blocks.broadcast_medium import BroadcastMedium
from coloc_env.scenarios.gps_denied_nbp import GpsDeniedNbpConfig
from coloc_env.worlds.gps_denied import sample_episode
from tests.helpers import play

NAME = "gps_denied_nbp"
SMALL = {"num_agents": 5, "num_particles": 20, "horizon": 8, "area": 300.0}
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
        parallel_api_test(coloc_env.parallel_env(NAME, **SMALL), num_cycles=20)
        parallel_seed_test(lambda: coloc_env.parallel_env(NAME, **SMALL), num_cycles=20)
        api_test(coloc_env.env(NAME, **SMALL), num_cycles=10)


def test_spaces_state_render_and_infos():
    env = coloc_env.parallel_env(NAME, render_mode="rgb_array", **SMALL)
    assert env.possible_agents == [f"uav_{i}" for i in range(5)]
    assert env.action_space("uav_0") is env.action_space("uav_0")
    assert env.action_space("uav_0") == env.action_space("uav_4")
    # MultiDiscrete([2] * n_iter), not MultiBinary: RLlib's PPO refuses MultiBinary
    assert isinstance(env.action_space("uav_0"), gymnasium.spaces.MultiDiscrete)
    assert env.action_space("uav_0").nvec.tolist() == [2] * 5 and env.observation_space("uav_1").shape == (8 + 5 + 5,)
    _, infos = env.reset(seed=0)
    assert env.state().shape == env.state_space.shape
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3
    obs, rewards, _, _, infos = env.step({a: np.ones(5, np.int8) for a in env.agents})
    assert env.scenario.scene(0).particles.shape == (5, 20, 2)
    for key in ("true_position", "estimated_position", "position_error", "error", "trace", "fault", "broadcasts",
                "communication", "messages_sent", "floats_sent", "messages_received", "neighbours", "step"):
        assert key in infos["uav_0"]
    faults = [infos[a]["fault"] for a in env.agents]
    errors = [infos[a]["error"] for a in env.agents]
    expected = -np.mean([e for e, f in zip(errors, faults, strict=True) if f]) if any(faults) else 0.0
    assert rewards["uav_0"] == pytest.approx(expected)  # team reward, communication_cost 0
    # a broadcast is one message however many hear it (counted at the sender by the network); the receivers
    # count each message they took, so every message sent was received at least once
    sent = sum(infos[a]["messages_sent"] for a in env.possible_agents)
    received = sum(infos[a]["messages_received"] for a in env.possible_agents)
    assert 0 < sent <= received
    assert all(infos[a]["floats_sent"] == infos[a]["messages_sent"] * (3 * 20 + 1) for a in env.possible_agents)
    assert all(0 <= o[0] <= 1 for o in obs.values())
    assert env.render().ndim == 3


@pytest.mark.parametrize("kwargs, field", [
    ({"num_agents": 1}, "num_agents"),
    ({"p_normal_to_fault": 1.5}, "p_normal_to_fault"),
    ({"gps_std": 0.0}, "gps_std"),
    # subnormal: squared it is 0, and the particle kernels divide by it (found by hypothesis)
    ({"gps_std": 5e-324}, r"gps_std must be in \[0.001, 10000"),
    ({"min_bandwidth": 5e-324}, "min_bandwidth"),
    ({"accel_noise_std": 1e-300}, "accel_noise_std"),
    ({"range_std": -1.0}, "range_std"),
    ({"comm_range": 0.0}, "comm_range"),
    ({"num_normal": 11}, "num_normal"),
    ({"num_particles": 1}, "num_particles"),
    ({"init": "hot"}, "init"),
    ({"schedule": "random"}, "schedule"),
    ({"reward": "mse"}, "reward"),
    ({"communication_cost": -0.1}, "communication_cost"),
    ({"broadcast_cost": -0.1}, "^gps_denied_nbp: broadcast_cost must be in"),  # its older name, as written
    ({"team_reward": 1}, "team_reward"),
    ({"initial_threshold": 11}, r"initial_threshold must be in \[1, num_agents = 10\]"),
    ({"nominal_velocity": (20.0, np.nan)}, "nominal_velocity"),
    ({"defensive_weight": 1.0}, "defensive_weight"),
    ({"initial_threshold": 0}, "initial_threshold"),
    ({"particles": 10}, "unknown config key"),
])
def test_bad_config_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        coloc_env.parallel_env(NAME, **kwargs)


@pytest.mark.parametrize("kwargs", [{"reward": "trace"}, {"reward": "trace", "team_reward": False},
                                    {"reward": "own"}, {"team_reward": False}])
def test_the_reward_follows_its_table(kwargs):
    """"trace" is the belief's RMS sqrt(tr Cov) (the ``trace`` info key is tr Cov, m^2), in metres as "error" is;
    the team's is the mean over the fault UAVs, ``team_reward=False`` (or the older ``reward="own"``) gives each
    UAV its own; the cost is per broadcast the schedule counts."""
    cost = 0.25
    env = coloc_env.parallel_env(NAME, communication_cost=cost, num_normal=2, **kwargs, **SMALL)  # 3 faulty
    config = env.unwrapped.scenario.config
    assert config.team_reward == kwargs.get("team_reward", kwargs.get("reward") != "own")
    assert build_config(GpsDeniedNbpConfig, {"reward": "team"}) == GpsDeniedNbpConfig()
    policy = agents.make_policy("random", env, seed=1)
    for _, rewards, infos in play(env, policy, 4)[1:]:
        info = [infos[a] for a in env.possible_agents]
        loss = np.array([np.sqrt(i["trace"]) if config.reward == "trace" else i["error"] for i in info])
        fault = np.array([i["fault"] for i in info])
        broadcasts = np.array([i["broadcasts"] for i in info])
        if config.team_reward:
            mean = loss[fault].mean() if fault.any() else 0.0
            expected = np.full(len(info), -mean - cost * broadcasts.sum())
        else:
            expected = -loss - cost * broadcasts
        np.testing.assert_allclose([rewards[a] for a in env.possible_agents], expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_or_misshaped_action_is_refused(bad):
    env = coloc_env.parallel_env(NAME, **SMALL)
    env.reset(seed=0)
    actions = {a: np.ones(5) for a in env.agents}
    actions["uav_2"][3] = bad
    with pytest.raises(ValueError, match="finite"):
        env.step(actions)
    with pytest.raises(ValueError, match="shape"):
        env.step({a: np.ones(4) for a in env.agents})


def test_integer_and_bool_actions_decode_as_the_discrete_check_does():
    """check_discrete_actions' shortcut for in-range integers and bools gives the int64 array that its full checks
    give the same values as floats; other values and dtypes still reach the checks and their errors."""
    scenario = coloc_env.vector_env(NAME, num_envs=2, **SMALL).scenario
    bits = np.random.default_rng(0).integers(0, 2, size=(2, 5, 5))
    checked = scenario.decode_actions(bits.astype(float))  # floats take the full checks
    assert checked.dtype == np.int64
    for actions in (bits, bits.astype(np.int8), bits.astype(np.uint16), bits.astype(bool)):
        decoded = scenario.decode_actions(actions)
        assert decoded.dtype == np.int64
        np.testing.assert_array_equal(decoded, checked)
    for value in (2, -1, 0.5):
        bad = bits.astype(type(value))
        bad[1, 3, 2] = value
        with pytest.raises(ValueError, match=r"action\[2\] \(broadcast in NBP iteration 2\)"):
            scenario.decode_actions(bad)
    with pytest.raises(ValueError, match="shape"):
        scenario.decode_actions(bits[:, :, :4])


def test_same_seed_gives_identical_episodes_and_reset_continues_the_generator():
    env_a, env_b = coloc_env.parallel_env(NAME, **SMALL), coloc_env.parallel_env(NAME, **SMALL)
    first_a = play(env_a, agents.make_policy("random", env_a, seed=5), 11)
    first_b = play(env_b, agents.make_policy("random", env_b, seed=5), 11)
    assert len(first_a) == 9 and data_equivalence(first_a, first_b)
    other = play(coloc_env.parallel_env(NAME, **SMALL), agents.make_policy("random", env_a, seed=5), 12)
    assert not data_equivalence(first_a, other)
    _, info_a = env_a.reset()
    _, info_b = env_b.reset()
    np.testing.assert_array_equal(info_a["uav_0"]["estimated_position"], info_b["uav_0"]["estimated_position"])
    assert not np.array_equal(info_a["uav_0"]["true_position"], first_a[0][1]["uav_0"]["true_position"])


def test_env_with_paper_policy_equals_the_estimator_called_directly():
    env = coloc_env.parallel_env(NAME, **SMALL)
    policy = agents.make_policy("paper", env)
    observations, _ = env.reset(seed=7)
    # the same episode and estimator generator, rebuilt from the seed exactly as reset does
    config = build_config(GpsDeniedNbpConfig, SMALL)
    rng = np.random.default_rng(7)
    episode = sample_episode(config.parts()[0], rng)
    estimator_rng = rng.spawn(1)[0]
    model = env.unwrapped.scenario.backend.model
    state = dn.initial_state(model, [estimator_rng], "warm", episode.init_position[None], episode.init_velocity[None],
                             config.velocity_spread)
    for k in range(config.horizon):
        observations, rewards, _, _, infos = env.step(policy.act(observations))
        state, result = dn.step(model, state, episode.gps_normal[k][None], episode.gps_fix[k][None],
                                BroadcastMedium().over(episode.adjacency[k][None]), episode.ranges[k][None],
                                episode.accel[k][None], [estimator_rng])
        for i, agent in enumerate(env.possible_agents):
            np.testing.assert_array_equal(infos[agent]["estimated_position"], result.estimate[0, i])
            np.testing.assert_array_equal(infos[agent]["true_position"], episode.truth[k, i, :2])
            assert infos[agent]["broadcasts"] == result.broadcasts[0, i]
    assert not env.agents


def test_silent_policy_sends_nothing_and_paper_beats_it_on_fault_uavs():
    config = {"num_agents": 8, "num_particles": 40, "horizon": 10, "num_normal": 4}
    totals = {}
    for name in ("paper", "silent"):
        env = coloc_env.parallel_env(NAME, **config)
        policy = agents.make_policy(name, env)
        errors, broadcasts = [], 0
        for seed in range(2):
            for _, _, infos in play(env, policy, seed)[1:]:
                errors += [infos[a]["error"] for a in env.possible_agents if infos[a]["fault"]]
                broadcasts += sum(infos[a]["broadcasts"] for a in env.possible_agents)
        totals[name] = (np.mean(errors), broadcasts)
    assert totals["silent"][1] == 0 and totals["paper"][1] > 0
    assert totals["paper"][0] < totals["silent"][0]
    paper = agents.make_policy("paper", env).act({"uav_0": None})["uav_0"]
    assert env.action_space("uav_0").contains(paper.astype(env.action_space("uav_0").dtype))


def test_the_observation_says_what_the_neighbours_heard():
    """Entry 7 is the mean, over a UAV's neighbours within R now, of how many distinct UAVs each heard from in
    the step just done (the network's delivery record), / (N - 1); 0 at reset and when nobody broadcasts."""
    for bits in (1, 0):
        env = coloc_env.parallel_env(NAME, **SMALL)
        observations, _ = env.reset(seed=2)
        scenario = env.unwrapped.scenario
        np.testing.assert_array_equal([observations[a][7] for a in env.agents], 0.0)  # nothing heard at reset
        action = np.full(scenario.config.num_iterations, bits)
        N = scenario.num_agents
        for k in range(4):
            observations, *_ = env.step({a: action for a in env.agents})
            heard = scenario.network.delivered[0].sum(axis=0)  # [t, s]: t's message reached s, any round
            now = scenario.world.adjacency[0, k + 1].astype(float)
            expected = (now @ heard) / np.maximum(now.sum(axis=1), 1) / (N - 1)
            np.testing.assert_allclose([observations[a][7] for a in env.possible_agents], expected, atol=1e-6)
            assert bits == 1 or not np.any(expected)
        assert bits == 0 or any(observations[a][7] > 0 for a in env.possible_agents)
