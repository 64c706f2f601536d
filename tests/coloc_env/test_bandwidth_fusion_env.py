"""The bandwidth_fusion scenario through its PettingZoo views."""

import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

import agents
import coloc_env
import estimators.bandwidth_fusion as bf
from agents.bandwidth_fusion import advance_tables
from coloc_env.worlds.drift import draw_episode
from estimators.bandwidth_fusion import paper_selection, paper_weights
from tests.helpers import decode_tables, play

NAME = "bandwidth_fusion"
# The known-harmless warnings of pettingzoo.test: unbounded observation entries (positions, log-variances,
# errors: quantities with no finite bound, as the scenario docstring says). Only these, matched by message.
UNBOUNDED_OBSERVATION = r"Agent's (minimum|maximum) observation space value is -?infinity"


def test_pettingzoo_api_and_seed_tests():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # anything else PettingZoo reports only by warning fails the test
        warnings.filterwarnings("ignore", message=UNBOUNDED_OBSERVATION, category=UserWarning)
        parallel_api_test(coloc_env.parallel_env(NAME), num_cycles=60)
        parallel_seed_test(lambda: coloc_env.parallel_env(NAME), num_cycles=60)
        api_test(coloc_env.env(NAME), num_cycles=30)


def test_spaces_are_shared_and_cached():
    env = coloc_env.parallel_env(NAME)
    assert env.possible_agents == ["uav_0", "uav_1", "uav_2", "uav_3"]
    assert env.action_space("uav_0") is env.action_space("uav_0")
    assert env.action_space("uav_0") == env.action_space("uav_3")
    assert env.observation_space("uav_1").shape == (13 + 4 + 1,)  # then the index and the cost
    assert env.action_space("uav_1").shape == (13,)
    env.reset(seed=0)
    assert env.state().shape == env.state_space.shape


@pytest.mark.parametrize("kwargs, field", [
    ({"budget": 10}, "budget"),
    ({"process_noise": [[0.02, 0.1, 0.0], [0.1, 0.05, 0.0], [0.0, 0.0, 0.03]]}, "process_noise"),
    ({"measurement_noise": [[1.0, 0.0], [0.0, 1.0]]}, "measurement"),
    ({"drift": [0.5, 0.5]}, "drift"),
    ({"initial_cov": [[-1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]}, "initial_cov"),
    ({"reward": "rmse"}, "reward"),
    ({"horizon": 0}, "horizon"),
    ({"component_cost": -1.0}, "component_cost"),
    ({"num_agents": 1}, "num_agents"),
    ({"bugdet": 5}, "unknown config key"),
    ({"initial_state": [10.0, np.nan, 10.0]}, "initial_state"),
])
def test_bad_config_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        coloc_env.parallel_env(NAME, **kwargs)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_is_refused(bad):
    env = coloc_env.parallel_env(NAME)
    env.reset(seed=0)
    actions = {a: env.action_space(a).sample() for a in env.agents}
    actions["uav_2"] = actions["uav_2"].astype(float)
    actions["uav_2"][4] = bad
    with pytest.raises(ValueError, match="finite"):
        env.step(actions)


def test_wrong_action_shape_is_refused():
    env = coloc_env.parallel_env(NAME)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step({a: np.zeros(5) for a in env.agents})


def test_same_seed_gives_identical_episodes_and_reset_continues_the_generator():
    env_a, env_b = coloc_env.parallel_env(NAME), coloc_env.parallel_env(NAME)
    policy_a, policy_b = agents.make_policy("random", env_a, seed=5), agents.make_policy("random", env_b, seed=5)
    first_a, first_b = play(env_a, policy_a, 11), play(env_b, policy_b, 11)
    assert len(first_a) == 51
    assert data_equivalence(first_a, first_b)
    other = play(coloc_env.parallel_env(NAME), agents.make_policy("random", env_a, seed=5), 12)
    assert not data_equivalence(first_a, other)
    # reset() without a seed continues the generator: a new episode, the same in both envs
    obs_a, info_a = env_a.reset()
    obs_b, info_b = env_b.reset()
    np.testing.assert_array_equal(info_a["uav_0"]["true_position"], info_b["uav_0"]["true_position"])
    assert not np.array_equal(info_a["uav_0"]["true_position"], first_a[0][1]["uav_0"]["true_position"])


@pytest.mark.parametrize("tables", ["T1P1", "T2P3", "T3P2"])
def test_env_with_paper_policy_equals_the_estimator(tables):
    env = coloc_env.parallel_env(NAME)
    policy = agents.make_policy(f"paper:{tables}", env)
    observations, infos = env.reset(seed=7)
    scenario = env.scenario
    # the episode reset(seed=7) draws: the drift world's draw_episode on the episode's generator
    episode = draw_episode(scenario.config.parts()[0], np.random.default_rng(7))
    truth = episode["initial_state"]
    np.testing.assert_array_equal(scenario.true_position()[0], np.tile(truth, (scenario.num_agents, 1)))
    noise_v, noise_w = episode["measurement_noise"], episode["process_noise"]
    model = scenario.config.fusion_model()
    state = bf.initial_state(model, np.full(3, 10.0), np.diag([0.19, 0.09, 0.08]))
    selection, weights = paper_selection(tables[:2]), paper_weights(tables[2:])
    k = 0
    while env.agents:
        observations, rewards, _, _, infos = env.step(policy.act(observations))
        state = bf.step(model, state, truth + noise_v[k], selection, weights)
        truth = truth + model.drift + noise_w[k]
        k += 1
        for i, agent in enumerate(env.possible_agents):
            np.testing.assert_allclose(infos[agent]["estimated_position"], state.estimate[i], atol=1e-12, rtol=0)
            np.testing.assert_allclose(infos[agent]["true_position"], truth, atol=1e-12, rtol=0)
            assert rewards[agent] == pytest.approx(-np.sum((state.estimate[i] - truth) ** 2), abs=1e-12)
    assert k == 50


def test_infos_carry_the_contract_keys_in_the_presets_units():
    """position_error is the distance of the estimate, trace the exact tr Sigma_i, and messages_sent /
    floats_sent what the network counted at each sender: under T1 one message to each receiver that takes a
    component of it (min_per_link = 1: all N - 1 of them) carrying the components that receiver took."""
    env = coloc_env.parallel_env(NAME)
    policy = agents.make_policy("paper", env)
    observations, infos = env.reset(seed=2)
    assert all(infos[a]["messages_sent"] == 0 and infos[a]["floats_sent"] == 0 for a in env.possible_agents)
    T1 = paper_selection("T1")  # [i, j]: receiver i takes these components of j
    taken_from = T1.sum(axis=-1).sum(axis=0) - 3  # over the receivers, without the node itself
    for _ in range(4):
        observations, _, _, _, infos = env.step(policy.act(observations))
        for j, agent in enumerate(env.possible_agents):
            info = infos[agent]
            assert info["position_error"] == np.sqrt(info["error"])
            # norm and sqrt of the sum of squares may round differently in the last bit (numpy's own sum order)
            assert info["position_error"] == pytest.approx(
                np.linalg.norm(info["estimated_position"] - info["true_position"]), rel=1e-15)
            assert info["trace"] == info["trace_error"] > 0
            assert info["messages_sent"] == 3
            assert info["floats_sent"] == taken_from[j]
    assert sum(infos[a]["floats_sent"] for a in env.possible_agents) == 4 * 5


def test_advance_tables_takes_decoded_selections_and_weights():
    """advance_tables(scenario, selection, weights) (the reproduction's greedy curve) steps the parts with that
    selection and those weights (to rounding: the backend's softmax of their logarithms)."""
    env = coloc_env.parallel_env(NAME)
    env.reset(seed=0)
    scenario = env.scenario
    relative = scenario.links.relative_selection(paper_selection("T2"))[None]
    for name in ("P1", "P3"):
        weights = paper_weights(name)[None]
        advance_tables(scenario, relative, weights)
        np.testing.assert_array_equal(scenario.selection, relative)
        np.testing.assert_allclose(scenario.backend.weights, weights, rtol=0, atol=1e-15)
    assert scenario.k[0] == 2
    with pytest.raises(ValueError, match="budget"):
        advance_tables(scenario, np.ones_like(relative), weights)


def test_every_feasible_selection_and_weights_round_trip_through_the_action():
    env = coloc_env.parallel_env(NAME)
    scenario = env.scenario
    rng = np.random.default_rng(0)
    for option in range(len(scenario.links.feasible)):
        selection = np.stack([scenario.links.feasible[(option + 17 * i) % 108] for i in range(4)])
        weights = rng.dirichlet(np.ones(4) * 5, size=4)
        actions = scenario.encode_actions(selection, weights)
        assert np.all(np.abs(actions) <= 1)
        decoded_sel, decoded_w = decode_tables(scenario, actions[None])
        np.testing.assert_array_equal(decoded_sel[0], selection)
        np.testing.assert_allclose(decoded_w[0], weights, atol=1e-14)
    with pytest.raises(ValueError, match="budget"):
        scenario.encode_actions(np.ones((4, 3, 3), bool), paper_weights("P1"))
    with pytest.raises(ValueError, match="zero weight"):
        scenario.encode_actions(paper_selection("T1"), np.eye(4))
    with pytest.raises(ValueError, match="sum_j p_ij"):
        scenario.encode_actions(paper_selection("T1"), np.full((4, 4), 0.3))


def test_rewards_follow_the_reward_option_and_communication_cost():
    """component_cost per component received, communication_cost per message sent (one per receiver that takes a
    component: min_per_link = 1, so every node sends to its 3 receivers), both subtracted in m^2."""
    for reward in ("error", "trace"):
        env = coloc_env.parallel_env(NAME, reward=reward, component_cost=0.01, communication_cost=0.1)
        policy = agents.make_policy("paper", env)
        observations, _ = env.reset(seed=3)
        observations, rewards, _, _, infos = env.step(policy.act(observations))
        for agent in env.possible_agents:
            info = infos[agent]
            loss = info["error"] if reward == "error" else info["trace"]
            assert info["components_received"] == 5 and info["messages_sent"] == 3
            assert rewards[agent] == pytest.approx(-loss - 0.05 - 0.3, abs=1e-12)


def test_observation_is_local_and_ages_count_missing_components():
    env = coloc_env.parallel_env(NAME)
    policy = agents.make_policy("paper", env)
    observations, _ = env.reset(seed=0)
    np.testing.assert_allclose(observations["uav_0"][:3], np.log([0.19, 0.09, 0.08]), rtol=1e-6)
    for _ in range(3):
        observations, *_ = env.step(policy.act(observations))
    ages = observations["uav_0"][3:12].reshape(3, 3) * 50
    # T1, receiver uav_0: neighbour uav_1 sends y only, uav_2 sends x, y, uav_3 sends y, z
    np.testing.assert_allclose(ages, [[3, 0, 3], [0, 0, 3], [3, 0, 0]], atol=1e-5)
    assert observations["uav_0"][env.scenario.feature_index("step_fraction")] == pytest.approx(3 / 50)


def test_rgb_render_draws_a_frame():
    env = coloc_env.parallel_env(NAME, render_mode="rgb_array")
    env.reset(seed=0)
    env.step({a: env.action_space(a).sample() for a in env.agents})
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert frame.std() > 10  # something was drawn
    assert coloc_env.parallel_env(NAME).render() is None
    with pytest.raises(ValueError, match="render_mode"):
        coloc_env.parallel_env(NAME, render_mode="video")


def test_unknown_scenario_is_refused():
    with pytest.raises(ValueError, match="unknown scenario"):
        coloc_env.parallel_env("no_such_scenario")


def test_human_render_draws_without_returning_a_frame():
    import matplotlib

    matplotlib.use("Agg")  # no screen in CI: the window is drawn off-screen
    env = coloc_env.parallel_env(NAME, render_mode="human")
    env.reset(seed=0)
    with warnings.catch_warnings():
        # plt.show() on the off-screen Agg backend says so; nothing else is expected
        warnings.filterwarnings("ignore", message="FigureCanvasAgg is non-interactive", category=UserWarning)
        assert env.render() is None
    assert env._renderer._figure is not None and len(env._renderer._figure.axes) == 2
    env.close()


# One action per node, held for the whole episode, that drove a receiver's bound negative at step 50: node 3
# weights node 0 and takes component 0 from it, while node 0's own component 0 is compensated from its prediction
# for 50 steps (its M grows to about 1e14, where eq. 19's difference was lost to rounding).
NEGATIVE_BOUND_ACTION = [
    [-0.8722483452553913, -0.08014155700127312, 0.10429522307448824, 0.344490041555394, -0.43417158468548256,
     0.8745707108819181, 0.8726069408050718, -0.11890060216603371, -0.5997187992358741, -0.9631517301465218,
     -0.8120355201872773, 0.44066665457580223, 0.39843555839012423],
    [-0.8185092921774471, -0.05873768814595026, -0.1922240344156838, 0.9855457139910544, -0.8378370137387321,
     0.32214263696479684, -0.7273441326293721, 0.4781327158682287, 0.5693317455928755, -0.8794769138148242,
     -0.012583977854779382, 0.9283340983744017, -0.425684272255068],
    [-0.38391739134332536, -0.8990778721025221, 0.5769299623603199, -0.6911424858142616, -0.08908206624098414,
     -0.32250271228765826, -0.8165221358333594, -0.09683873060269677, 0.3568796869604163, -0.9971835932568303,
     0.6048863477059692, 0.8982742156715082, -0.5191674797104655],
    [0.4705296995484658, -0.3866951573908437, 0.126063326473693, 0.050725456149913306, 0.38619287890644305,
     -0.4602324620627918, 0.6312795514361436, 0.48781643521813667, 0.07984473197612352, -0.3858397264675626,
     -0.4852665457420895, -0.7678610814923792, 0.8515523486707159],
]


@settings(max_examples=10, deadline=None)
@example(actions=np.array(NEGATIVE_BOUND_ACTION))
@given(actions=arrays(np.float64, (4, 13), elements=st.floats(-1.0, 1.0)))
def test_any_held_action_keeps_every_bound_at_least_w(actions):
    """Any Box action (the selection scores and weight logits of every node), held for a whole episode: no
    warning, and every M_i(k) keeps its diagonal >= W's (eq. 19: W plus positive semi-definite terms), so the
    observation's log-diagonal is finite."""
    env = coloc_env.parallel_env(NAME)
    env.reset(seed=0)
    scenario = env.unwrapped.scenario
    floor = np.diag(scenario.backend.model.process_noise)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        while env.agents:
            observations, *_ = env.step({a: actions[i] for i, a in enumerate(env.possible_agents)})
            assert (np.diagonal(scenario.fusion.bound, axis1=-2, axis2=-1) >= floor).all()
            assert all(np.isfinite(o).all() for o in observations.values())
