"""The relay_ukf scenario through its PettingZoo views."""

import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

import agents
import coloc_env
import estimators.ukf_relay as ur
from agents.relay_ukf import paper_actions
from coloc_env.config import build_config
from coloc_env.networks.blocks.relay_chain import STOP_REASONS
from coloc_env.scenarios.relay_ukf import RelayUKFConfig, RelayUKFScenario
from tests.helpers import play

NAME = "relay_ukf"
SHORT = {"horizon": 60}




# The known-harmless warnings of pettingzoo.test: unbounded observation entries (distances, log-variances:
# quantities with no finite bound, as the scenario docstring says) and a MultiDiscrete action space (a valid
# Gymnasium space that SB3, TorchRL and RLlib take; api_test suggests Box or Discrete). Only these.
UNBOUNDED_OBSERVATION = r"Agent's (minimum|maximum) observation space value is -?infinity"
MULTI_DISCRETE_ACTION = r"Action space for each agent probably should be gymnasium.spaces.box or"


def test_pettingzoo_api_and_seed_tests():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # anything else PettingZoo reports only by warning fails the test
        warnings.filterwarnings("ignore", message=UNBOUNDED_OBSERVATION, category=UserWarning)
        warnings.filterwarnings("ignore", message=MULTI_DISCRETE_ACTION, category=UserWarning)
        parallel_api_test(coloc_env.parallel_env(NAME), num_cycles=100)
        parallel_seed_test(lambda: coloc_env.parallel_env(NAME), num_cycles=50)
        api_test(coloc_env.env(NAME), num_cycles=30)


def test_spaces_defaults_and_geometry():
    env = coloc_env.parallel_env(NAME)
    assert env.possible_agents == ["platform_0", "platform_1", "platform_2", "platform_3"]
    assert env.action_space("platform_0") is env.action_space("platform_0")
    assert list(env.action_space("platform_2").nvec) == [4, 5]
    assert env.observation_space("platform_1").shape == (11 + 4,)  # then the named features
    observations, infos = env.reset(seed=0)
    assert env.state().shape == env.state_space.shape
    scenario = env.scenario
    assert scenario.horizon == 800 and scenario.config.dt == 0.5
    # the platforms stay within ~150 m of each other; every one turns by 0.015 rad/s at 1 m/s
    distances = np.linalg.norm(scenario.world.truth[:, :, None] - scenario.world.truth[:, None], axis=-1)
    assert distances.max() < 160.0
    step = np.linalg.norm(np.diff(scenario.world.truth, axis=0), axis=-1)
    np.testing.assert_allclose(step, 0.5, atol=1e-12)
    turn = np.diff(scenario.world.true_heading, axis=0)
    np.testing.assert_allclose(turn, np.broadcast_to(0.5 * 0.015 * np.array([1, -1, 1, 1]), turn.shape), atol=1e-12)
    for agent in env.possible_agents:
        np.testing.assert_array_equal(infos[agent]["estimated_position"], infos[agent]["true_position"])
    # the measuring flag is the schedule's
    flags = np.array([observations[a][4] for a in env.possible_agents])
    measuring = scenario.world.schedule[0, 0]
    assert flags.sum() == (measuring >= 0) and (measuring < 0 or flags[measuring] == 1)


@pytest.mark.parametrize("kwargs, field", [
    ({"measurement_probability": 1.5}, "measurement_probability"),
    ({"range_noise_var": 0.0}, "range_noise_var"),
    ({"speed_noise_std": -0.1}, "speed_noise_std"),
    ({"max_hops": 4}, r"^relay_ukf: max_hops must be in \[1, num_agents - 1 = 3\], got 4"),
    ({"max_hops": 0}, "max_hops"),
    ({"loss_at_zero": -0.1}, "loss_at_zero"),
    ({"comm_range": 0.0}, "comm_range"),
    ({"sensing_range": -5.0}, "sensing_range"),
    ({"centres": [[0.0, 0.0]] * 3}, "centres"),
    ({"directions": [1, 1, 0, 1]}, "directions"),
    ({"num_platforms": 1}, "^relay_ukf: num_platforms must be"),  # the older name, as written
    ({"num_agents": 1}, "^relay_ukf: num_agents must be"),
    ({"ukf_lambda": -8.0}, "ukf_lambda"),
    ({"initial_position_std": 0.0}, "initial_position_std"),
    ({"truncation": "ignore"}, "truncation"),
    ({"reward": "rmse"}, "reward"),
    ({"heading_noise": "yes"}, "heading_noise"),
    ({"horizon": 0}, "horizon"),
    ({"communication_cost": -1.0}, "^relay_ukf: communication_cost must be in"),
    ({"hop_cost": -1.0}, "^relay_ukf: hop_cost must be in"),  # the older name of communication_cost, as written
    ({"hop_cost_per_m2": -1.0}, "^relay_ukf: hop_cost_per_m2 must be in"),
    ({"max_hop": 2}, "unknown config key"),
])
def test_bad_config_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        coloc_env.parallel_env(NAME, **kwargs)


@pytest.mark.parametrize("bad, match", [(np.nan, "of platform_2 must be finite"), (np.inf, "finite"),
                                        (1.5, "of platform_2 must be an integer"), (7, r"action\[0\]"),
                                        (-1, r"action\[0\]")])
def test_bad_action_is_refused(bad, match):
    env = coloc_env.parallel_env(NAME, **SHORT)
    env.reset(seed=0)
    actions = {a: env.action_space(a).sample().astype(float) for a in env.agents}
    actions["platform_2"][0] = bad
    with pytest.raises(ValueError, match=match):
        env.step(actions)
    actions = {a: np.array([0, 5]) for a in env.agents}
    with pytest.raises(ValueError, match=r"action\[1\]"):
        env.step(actions)
    with pytest.raises(ValueError, match="shape"):
        env.step({a: np.zeros(3) for a in env.agents})


def test_same_seed_gives_identical_episodes_and_reset_continues_the_generator():
    env_a, env_b = coloc_env.parallel_env(NAME, **SHORT), coloc_env.parallel_env(NAME, **SHORT)
    first_a = play(env_a, agents.make_policy("paper", env_a, seed=5), 11)
    first_b = play(env_b, agents.make_policy("paper", env_b, seed=5), 11)
    assert len(first_a) == 61
    assert data_equivalence(first_a, first_b)
    other = play(coloc_env.parallel_env(NAME, **SHORT), agents.make_policy("paper", env_a, seed=5), 12)
    assert not data_equivalence(first_a, other)
    first_speed = env_a.scenario.world.measured_speed.copy()
    env_a.reset()
    env_b.reset()
    np.testing.assert_array_equal(env_a.scenario.world.schedule, env_b.scenario.world.schedule)
    np.testing.assert_array_equal(env_a.scenario.world.measured_speed, env_b.scenario.world.measured_speed)
    assert not np.array_equal(env_a.scenario.world.measured_speed, first_speed)


def test_batched_copies_equal_single_envs_seeded_alike():
    config = build_config(RelayUKFConfig, SHORT)
    batch = RelayUKFScenario(config, batch=3)
    batch.reset([np.random.default_rng(s) for s in (4, 5, 6)])
    singles = [RelayUKFScenario(config, batch=1) for _ in range(3)]
    for s, single in zip((4, 5, 6), singles, strict=True):
        single.reset([np.random.default_rng(s)])
    rng = np.random.default_rng(0)
    for _ in range(config.horizon):
        actions = paper_actions(batch.world.distances(), batch.world.schedule[np.arange(3), batch.k], rng)
        batch.step(actions)
        for b, single in enumerate(singles):
            single.step(actions[b:b + 1])
    for b, single in enumerate(singles):
        np.testing.assert_array_equal(batch.estimate[b], single.estimate[0])
        np.testing.assert_array_equal(batch.cov[b], single.cov[0])
    # reset of one copy leaves the others alone
    before = batch.estimate[[0, 2]].copy()
    batch.reset([np.random.default_rng(9)], env_index=[1])
    np.testing.assert_array_equal(batch.estimate[[0, 2]], before)
    assert batch.k.tolist() == [config.horizon, 0, config.horizon]


def test_env_with_paper_policy_equals_the_estimator_called_directly():
    env = coloc_env.parallel_env(NAME, horizon=300)
    policy = agents.make_policy("paper", env, seed=3)
    observations, infos = env.reset(seed=7)
    scenario = env.scenario
    config = scenario.config
    x = np.array([infos[a]["true_position"] for a in env.possible_agents])
    P = 0.01 * np.eye(8)
    speed, heading = scenario.world.measured_speed[0].copy(), scenario.world.measured_heading[0].copy()
    schedule, noise = scenario.world.schedule[0].copy(), scenario.world.range_noise[0].copy()
    truth = scenario.world.truth
    updates, k = 0, 0
    while env.agents:
        actions = policy.act(observations)
        observations, rewards, _, _, infos = env.step(actions)
        chain = [int(infos[a]["chain_position"]) for a in env.possible_agents]
        m = schedule[k]
        if m >= 0:
            n = int(actions[env.possible_agents[m]][0])
            order = np.argsort(chain)
            assert sorted(chain) == [0, 1, 2, 3] and order[0] == m and order[1] == n  # complete chain from m -> n
            # the paper's topology: after n, always the nearest platform not yet reached
            for place in range(2, 4):
                holder, reached = order[place - 1], set(order[:place])
                d = np.linalg.norm(truth[k] - truth[k, holder], axis=-1)
                # ties within float32 rounding of the observed distances may go either way
                assert d[order[place]] <= min(d[j] for j in range(4) if j not in reached) + 1e-4
            z = np.linalg.norm(truth[k, m] - truth[k, n]) + noise[k]
            x, P = ur.dcl_update(x, P, order, 4, z, config.range_noise_var, config.ukf_lambda)
            updates += 1
        else:
            assert chain == [-1] * 4
        # the metric's error: time k after its measurement update, before the prediction
        posterior = np.linalg.norm(x - truth[k], axis=-1)
        for i, agent in enumerate(env.possible_agents):
            assert infos[agent]["posterior_error"] == pytest.approx(posterior[i], abs=1e-12)
        x, P = ur.time_update(x, P, speed[k], heading[k], config.dt, config.speed_noise_std**2,
                              k * config.dt**2 * config.turn_rate_noise_std**2)
        k += 1
        errors = np.linalg.norm(x - truth[k], axis=-1)
        for i, agent in enumerate(env.possible_agents):
            np.testing.assert_allclose(infos[agent]["estimated_position"], x[i], atol=1e-12, rtol=0)
            np.testing.assert_allclose(infos[agent]["true_position"], truth[k, i], atol=1e-12, rtol=0)
            assert rewards[agent] == pytest.approx(-errors.mean(), abs=1e-12)
        np.testing.assert_allclose(scenario.cov[0], P, atol=1e-12, rtol=0)
    assert k == 300 and 100 < updates < 200  # p = 0.5


def test_relay_choices_truncate_the_chain_and_hop_costs_enter_the_reward():
    env = coloc_env.parallel_env(NAME, measurement_probability=1.0, communication_cost=0.5, hop_cost_per_m2=1e-3,
                                 **SHORT)
    observations, _ = env.reset(seed=1)
    scenario = env.scenario
    m = int(scenario.world.schedule[0, 0])
    n = (m + 1) % 4
    third = (m + 2) % 4
    actions = {a: np.array([i, 4]) for i, a in enumerate(env.possible_agents)}
    actions[env.possible_agents[m]] = np.array([n, 2])  # m's relay choice is not used
    actions[env.possible_agents[n]] = np.array([n, third])
    actions[env.possible_agents[third]] = np.array([third, m])  # back to m: a revisit ends the chain
    before = scenario.estimate[0].copy()
    observations, rewards, _, _, infos = env.step(actions)
    chain = [int(infos[a]["chain_position"]) for a in env.possible_agents]
    assert chain[m] == 0 and chain[n] == 1 and chain[third] == 2 and sorted(chain)[0] == -1
    assert STOP_REASONS[int(infos["platform_0"]["chain_stop"])] == "revisit"
    assert infos["platform_0"]["hops"] == 2 and sum(infos[a]["communication"] for a in infos) == 2
    d = np.linalg.norm(scenario.world.truth[0, [m, n]] - scenario.world.truth[0, [n, third]], axis=-1)
    assert infos["platform_0"]["hop_cost"] == pytest.approx(1.0 + 1e-3 * np.sum(d**2), abs=1e-12)
    errors = np.array([infos[a]["error"] for a in env.possible_agents])
    assert rewards["platform_0"] == pytest.approx(-errors.mean() - infos["platform_0"]["hop_cost"], abs=1e-12)
    unreached = [i for i in range(4) if chain[i] < 0][0]
    speed, heading = scenario.world.measured_speed[0, 0], scenario.world.measured_heading[0, 0]
    np.testing.assert_allclose(scenario.estimate[0, unreached],
                               before[unreached] + 0.5 * speed[unreached] * np.array(
                                   [np.cos(heading[unreached]), np.sin(heading[unreached])]), atol=1e-12)
    # ranging with oneself declines the measurement: nobody updates, no hop
    m = int(scenario.world.schedule[0, 1])
    observations, rewards, _, _, infos = env.step({a: np.array([i, 4]) for i, a in enumerate(env.possible_agents)})
    assert infos["platform_0"]["hops"] == 0 and infos["platform_0"]["chain_stop"] == -1
    assert not any(infos[a]["measuring"] for a in infos)


def test_trace_reward_uses_the_filters_own_covariance():
    env = coloc_env.parallel_env(NAME, reward="trace", **SHORT)
    policy = agents.make_policy("paper", env, seed=0)
    observations, _ = env.reset(seed=2)
    for _ in range(5):
        observations, rewards, _, _, infos = env.step(policy.act(observations))
    traces = np.array([infos[a]["trace"] for a in env.possible_agents])
    assert rewards["platform_1"] == pytest.approx(-np.sqrt(traces).mean(), abs=1e-12)
    np.testing.assert_allclose(np.exp(observations["platform_1"][9]), traces[1], rtol=1e-6)


def test_truncated_chains_keep_p_positive_definite_only_with_the_consistent_update():
    """Hop budget 1 (only m and n update), 800 steps, several copies."""
    smallest = {}
    for rule in ("consistent", "paper"):
        config = build_config(RelayUKFConfig, {"max_hops": 1, "truncation": rule})
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            scenario = RelayUKFScenario(config, batch=4)
        assert any("truncation='paper'" in str(w.message) for w in caught) == (rule == "paper")
        rng = np.random.default_rng(0)
        scenario.reset(rng.spawn(4))
        values = []
        try:
            for k in range(config.horizon):
                scenario.step(paper_actions(scenario.world.distances(), scenario.world.schedule[:, k], rng))
                values.append(np.linalg.eigvalsh(scenario.cov).min())
        except np.linalg.LinAlgError as exc:
            assert rule == "paper" and "positive definite" in str(exc)
        smallest[rule] = np.array(values)
        assert np.all(scenario.chain.length <= 2)
    assert len(smallest["consistent"]) == 800 and smallest["consistent"].min() > 0
    assert smallest["paper"].min() < 0


def test_rgb_render_draws_trajectories_and_the_chain():
    env = coloc_env.parallel_env(NAME, render_mode="rgb_array", measurement_probability=1.0, **SHORT)
    policy = agents.make_policy("paper", env, seed=0)
    observations, _ = env.reset(seed=0)
    for _ in range(10):
        observations, *_ = env.step(policy.act(observations))
    scene = env.scenario.scene(0)
    assert len(scene.links) == 3 and scene.directed and scene.trails.shape == (4, 11, 2)
    assert [link.target for link in scene.links[:-1]] == [link.source for link in scene.links[1:]]
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8 and frame.std() > 10


def test_the_papers_truncation_rule_warns_when_chosen_and_fails_with_a_clear_error():
    """wang2019's rule (P_RU unchanged on a truncated chain) loses positive definiteness; the env says so
    when the rule is chosen and, when it happens, raises a ValueError naming the option."""
    with pytest.warns(UserWarning, match="truncation='paper'.*loses positive definiteness"):
        env = coloc_env.parallel_env("relay_ukf", truncation="paper", max_hops=1, horizon=300)
    policy = agents.make_policy("paper", env, seed=0)
    observations, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match="truncation='paper' lost positive definiteness at step"):
        while env.agents:
            observations, *_ = env.step(policy.act(observations))
    # the default rule runs the same episode to its end
    env = coloc_env.parallel_env("relay_ukf", max_hops=1, horizon=300)
    policy = agents.make_policy("paper", env, seed=0)
    observations, _ = env.reset(seed=0)
    while env.agents:
        observations, rewards, *_ = env.step(policy.act(observations))
    assert all(np.isfinite(list(rewards.values())))


def test_reset_infos_report_no_chain_or_messages_of_the_episode_before():
    env = coloc_env.parallel_env(NAME, horizon=4, measurement_probability=1.0)
    policy = agents.make_policy("paper", env, seed=0)
    observations, _ = env.reset(seed=1)
    sent = 0.0
    while env.agents:
        observations, _, _, _, infos = env.step(policy.act(observations))
        sent += sum(infos[a]["messages_sent"] for a in env.possible_agents)
    assert sent > 0 and max(infos[a]["chain_position"] for a in env.possible_agents) > 0
    _, infos = env.reset(seed=2)
    for a in env.possible_agents:
        assert infos[a]["messages_sent"] == 0 and infos[a]["floats_sent"] == 0
        assert infos[a]["chain_position"] == -1 and infos[a]["partner"] == -1 and infos[a]["hops"] == 0


def test_a_relay_hop_budget_beyond_the_team_is_refused_in_a_composition_too():
    with pytest.raises(ValueError, match=r"^network.max_hops must be in \[1, world.num_agents - 1 = 5\], got 6"):
        coloc_env.parallel_env(coloc_env.compose(world="circles", network={"name": "relay", "max_hops": 6},
                                                 backend="ukf_dcl"))
    env = coloc_env.parallel_env(coloc_env.compose(world="circles", network={"name": "relay", "max_hops": 5},
                                                   backend="ukf_dcl"))
    assert env.scenario.network.max_hops() == 5


def test_communication_cost_is_the_cost_of_a_hop_under_both_names():
    rewards = []
    for cost in ({"communication_cost": 0.25}, {"hop_cost": 0.25}):
        env = coloc_env.parallel_env(NAME, measurement_probability=1.0, **cost, **SHORT)
        assert env.scenario.composition.communication_cost == 0.25
        env.reset(seed=3)
        actions = {a: np.array([(i + 1) % 4, 4]) for i, a in enumerate(env.possible_agents)}
        _, reward, _, _, infos = env.step(actions)
        hops = infos["platform_0"]["hops"]
        assert hops == 1 and infos["platform_0"]["hop_cost"] == 0.25 * hops
        errors = np.array([infos[a]["error"] for a in env.possible_agents])
        assert reward["platform_0"] == pytest.approx(-errors.mean() - 0.25, abs=1e-12)
        rewards.append(reward["platform_0"])
    assert rewards[0] == rewards[1]
