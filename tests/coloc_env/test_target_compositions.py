"""Target estimation in the composable core: worlds drift / target_cv, networks bandwidth /
bernoulli_delay, backends bandwidth_fusion, centralized_lmmse, prediction_compensation, kalman."""

import numpy as np
import pytest

import agents
import coloc_env
import estimators.bandwidth_fusion as bf
import estimators.lossy_fusion as lf
from agents.lossy_fusion import paper_actions
from coloc_env.draws import uniforms
from coloc_env.scenarios.bandwidth_fusion import BandwidthFusionScenario, paper_selection, paper_weights
from coloc_env.scenarios.lossy_fusion import LossyFusionConfig, LossyFusionScenario
from coloc_env.worlds.blocks.target import ConstantVelocityTarget

OK = {(r["world"], r["network"], r["backend"]) for r in coloc_env.compatibility() if r["ok"]}


def _episode(spec, actions_of, seed, steps=None):
    """Per-step infos (list of dicts agent -> info), rewards, and the env, for ``actions_of(env, k)``."""
    env = coloc_env.parallel_env(spec)
    env.reset(seed=seed)
    infos, rewards, k = [], [], 0
    while env.agents and (steps is None or k < steps):
        _, reward, _, _, info = env.step(actions_of(env, k))
        infos.append(info)
        rewards.append(reward)
        k += 1
    return infos, rewards, env


def _stack(infos, key, env):
    return np.array([[info[a][key] for a in env.possible_agents] for info in infos])


def _always(env, k):
    return agents.make_policy("always", env).act({a: None for a in env.possible_agents})


def test_the_matrix_has_the_target_rows_the_issue_names():
    assert ("drift", "bernoulli_delay", "bandwidth_fusion") in OK
    assert ("drift", "ideal", "prediction_compensation") in OK
    assert ("drift", "ideal", "centralized_lmmse") in OK
    for world in ("drift", "target_cv"):
        backends = {b for w, _, b in OK if w == world}
        assert len(backends) >= 3, backends
    reasons = {(r["world"], r["network"], r["backend"]): r["reason"] for r in coloc_env.compatibility()}
    assert reasons[("drift", "ideal", "ukf_dcl")] == ("ukf_dcl estimates each agent's own position; world drift "
                                                      "asks for a shared target state")
    assert "cannot carry" in reasons[("drift", "bandwidth", "kalman")]


def test_the_bandwidth_fusion_preset_is_drift_bandwidth_bandwidth_fusion():
    """The preset is the composition drift + bandwidth + bandwidth_fusion plus its action codec: on the same
    seed the composition under the tables T1, P1 (its selection index and zero logits) gives the preset's
    truth, estimates, errors and traces exactly (the same draws and the same arithmetic), one step
    later (the backend reports xhat_i(k) at step k, the preset xhat_i(k+1) after step k), and the same
    messages and floats; the preset's reward is its own (xhat(k+1) against x(k+1))."""
    seed = 5
    spec = coloc_env.compose(world="drift", network="bandwidth", backend="bandwidth_fusion")
    env = coloc_env.parallel_env(spec)
    env.reset(seed=seed)
    composed = env.unwrapped.scenario
    links = composed.network.links
    relative = links.relative_selection(paper_selection("T1"))
    index = links.index_of(relative)
    assert np.all(index >= 0)
    N = len(env.possible_agents)
    preset_env = coloc_env.parallel_env("bandwidth_fusion")
    _, preset_info = preset_env.reset(seed=seed + 1)  # another episode, then made the same
    preset = preset_env.unwrapped.scenario
    assert isinstance(preset, BandwidthFusionScenario)
    preset.world.truth[:] = composed.world.truth
    preset.world.observations[:] = composed.world.observations
    preset.network.keys[:] = composed.network.keys
    paper = preset.encode_actions(paper_selection("T1"), paper_weights("P1"))
    np.testing.assert_array_equal(preset.decode_actions(paper[None])[0, :, 0], index)
    composition_action = {a: np.concatenate([[index[i]], np.zeros(N)]).astype(np.float32)
                          for i, a in enumerate(env.possible_agents)}
    assert (preset.composition.world, preset.composition.backend) == (spec.world, spec.backend)
    assert isinstance(preset.network, type(composed.network)) and preset.links == links
    keys = ("true_position", "estimated_position", "error")
    k = 0
    while env.agents:
        _, _, _, _, info = env.step(composition_action)
        # the composition's step k reports time k: the preset after k steps (before its step k)
        ref = {key: preset.info()[key][0] for key in keys}
        np.testing.assert_array_equal(_stack([info], "true_position", env)[0], ref["true_position"][:, :2])
        np.testing.assert_array_equal(_stack([info], "estimated_position", env)[0], ref["estimated_position"][:, :2])
        np.testing.assert_array_equal(_stack([info], "error", env)[0], ref["error"])
        np.testing.assert_array_equal(_stack([info], "trace", env)[0], _position_trace(preset))
        _, rewards, _, _, preset_info = preset_env.step({a: paper[i] for i, a in enumerate(env.possible_agents)})
        # the preset's step k: the components it received, its floats and messages are the network's of step k
        for key in ("messages_sent", "floats_sent"):
            np.testing.assert_array_equal(_stack([preset_info], key, env)[0], _stack([info], key, env)[0])
        np.testing.assert_array_equal([rewards[a] for a in env.possible_agents],
                                      -np.sum((preset.fusion.estimate[0] - preset.true_position()[0]) ** 2, axis=-1))
        k += 1
    # every receiver took exactly its budget: 5 components a step, counted at the senders
    assert np.all(_stack([preset_info], "components_received", env) == 5)
    assert np.sum(_stack([preset_info], "floats_sent", env)) == N * 5
    assert k == 50


def _position_trace(scenario):
    cov = bf.node_covariances(scenario.fusion.error_cov, scenario.num_agents)[0]
    return cov[:, 0, 0] + cov[:, 1, 1]


def paper_model(num_agents: int) -> lf.LossyModel:
    """fu2017's model of its simulation (Sec. 4) written out from the paper: 3-D constant velocity, T = 1 s,
    q = 5, r = 10 per axis, alpha1 = 0.4, alpha2 = 0.3 (the leader's own link always on time)."""
    target, followers = ConstantVelocityTarget(3, 1.0, 5.0), num_agents - 1
    return lf.LossyModel(transition=target.transition, process_noise=target.process_noise,
                         measurement=target.position_matrix,
                         measurement_noise=np.tile(10.0 * np.eye(3), (num_agents, 1, 1)),
                         on_time=np.r_[1.0, np.full(followers, 0.4)], late=np.r_[0.0, np.full(followers, 0.3)])


def _uniform_outcomes(env, steps):
    """fu2017's per-slot codes of each follower's link to the leader, from the network's own uniforms."""
    net = env.unwrapped.scenario.network
    a1, a2 = net.config.on_time_probability, net.config.late_probability
    u = np.stack([uniforms(net.keys, (np.array([k]), 2, 0), (net.num_agents, net.num_agents))[0, :, 0]
                  for k in range(steps)])
    codes = np.where(u < a1, lf.ON_TIME, np.where(u < a1 + a2, lf.LATE, lf.LOST)).astype(np.int8)
    codes[:, 0] = lf.ON_TIME
    return codes


def test_the_lossy_fusion_preset_is_target_cv_bernoulli_delay_prediction_compensation():
    """The preset is the composition target_cv + bernoulli_delay + prediction_compensation plus its action codec:
    fed the same episode and the same network key, the composition under the paper's decisions gives the preset's
    fused estimates, errors and rewards (1e-12); the link draws include every outcome."""
    seed = 3
    spec = coloc_env.compose(world="target_cv", network="bernoulli_delay", backend="prediction_compensation")
    env = coloc_env.parallel_env(spec)
    env.reset(seed=seed)
    composed = env.unwrapped.scenario
    preset = LossyFusionScenario(LossyFusionConfig())
    preset.reset([np.random.default_rng(seed + 1)])  # another episode, then made the same
    preset.world.truth[:] = composed.world.truth
    preset.world.observations[:] = composed.world.observations
    preset.network.keys[:] = composed.network.keys
    assert {lf.ON_TIME, lf.LATE, lf.LOST} <= set(np.unique(_uniform_outcomes(env, 100)[:, 1]))
    paper = paper_actions(preset)[None]
    k = 0
    while env.agents:
        _, rewards, _, _, info = env.step(_always(env, k))
        preset.step(paper)
        ref = preset.info()
        np.testing.assert_allclose(_stack([info], "true_position", env)[0], ref["true_position"][0][:, :2],
                                   rtol=0, atol=1e-12)
        np.testing.assert_allclose(_stack([info], "estimated_position", env)[0], ref["estimated_position"][0][:, :2],
                                   rtol=0, atol=1e-12)
        np.testing.assert_allclose(_stack([info], "error", env)[0], ref["error"][0], rtol=0, atol=1e-12)
        np.testing.assert_allclose([rewards[a] for a in env.possible_agents], preset.reward()[0], rtol=0, atol=1e-12)
        k += 1
    assert k == 100


@pytest.mark.parametrize("backend,reference", [
    ({"name": "centralized_lmmse"}, "centralized"),
    ({"name": "centralized_lmmse", "gain": "paper"}, "centralized_paper_gain"),
    ({"name": "kalman", "variant": "naive"}, "naive_kf"),
    ({"name": "kalman", "variant": "informed"}, "informed_kf"),
    ({"name": "kalman", "variant": "leader_only"}, "leader_only_kf"),
    ({"name": "kalman", "variant": "ideal"}, "ideal_kf"),
])
def test_fu2017_backends_equal_the_reproduction_filters(backend, reference):
    """On the episode and link outcomes the composition drew, each backend gives the filter of
    estimators.lossy_fusion.run_filters to 1e-9, with L = 3 UAVs."""
    seed, L = 11, 3
    spec = coloc_env.compose(world={"name": "target_cv", "num_agents": L, "horizon": 40}, network="bernoulli_delay",
                             backend=backend)
    infos, _, env = _episode(spec, _always, seed)
    world = env.unwrapped.scenario.world
    K = len(infos)
    outcome = _uniform_outcomes(env, K)
    model = paper_model(L)
    x0, P0 = world.prior()
    estimates, _ = lf.run_filters(model, x0, P0, world.observations[0], outcome, filters=(reference,))[reference]
    got = _stack(infos, "estimated_position", env)
    for i in range(L):  # the leader's estimate, reported by every agent
        np.testing.assert_allclose(got[:, i], estimates[:, [0, 2]], rtol=0, atol=1e-9)


def test_bernoulli_delay_delivers_at_most_one_packet_a_slot_with_the_papers_frequencies():
    spec = coloc_env.compose(world={"name": "target_cv", "num_agents": 8, "horizon": 400}, network="bernoulli_delay",
                             backend="kalman")
    env = coloc_env.parallel_env(spec)
    env.reset(seed=0)
    net = env.unwrapped.scenario.network
    senders = np.zeros((1, 8), bool)
    senders[0, 1:] = True
    listening = np.zeros((1, 8, 8), bool)
    listening[0, 1:, 0] = True
    positions = env.unwrapped.scenario.world.positions()
    delays = []
    for k in range(400):
        net.begin(np.array([k]), positions, np.ones((1, 8, 1), np.int64))
        delays.append(net.packets(senders, listening, 1.0)[0, 1:, 0])
    delays = np.array(delays)  # (K, followers)
    both = (delays[1:] == 0) & (delays[:-1] == 1)
    assert not both.any()
    assert abs((delays == 0).mean() - 0.4) < 0.03
    assert abs((delays == 1).mean() - 0.6 * 0.3) < 0.03
    assert set(np.unique(delays)) == {-1, 0, 1}


def _mean_error(spec, seeds, policy="always"):
    errors = []
    for seed in seeds:
        env = coloc_env.parallel_env(spec)
        pol = agents.make_policy(policy, env, seed=0)
        observations, _ = env.reset(seed=seed)
        per_step = []
        while env.agents:
            observations, _, _, _, infos = env.step(pol.act(observations))
            per_step.append([infos[a]["error"] for a in env.possible_agents])
        errors.append(np.mean(per_step))
    return np.array(errors)


def test_kalman_ideal_informed_naive_ordering_over_seeded_runs():
    """Over a lossy network, ideal <= informed <= naive in mean squared error (fu2017 Sec. 4), paired seeds."""
    world = {"name": "target_cv", "num_agents": 3, "horizon": 40}
    errors = {v: _mean_error(coloc_env.compose(world=world, network="bernoulli_delay",
                                               backend={"name": "kalman", "variant": v}), range(4))
              for v in ("ideal", "informed", "naive")}
    assert errors["ideal"].mean() < errors["informed"].mean() < errors["naive"].mean(), errors


def test_bandwidth_fusion_loses_accuracy_over_bernoulli_delay_on_drift():
    ideal = _mean_error(coloc_env.compose(world="drift", network="ideal", backend="bandwidth_fusion"), range(4))
    lossy = _mean_error(coloc_env.compose(world="drift", network="bernoulli_delay", backend="bandwidth_fusion"),
                        range(4))
    assert np.all(lossy > ideal), (ideal, lossy)


def test_fu2017_backends_on_drift_follow_the_known_input():
    """On drift (known input B = v dt) the fu2017 filters, written for B = 0, run by the change of variables:
    over ideal links the LMMSE equals the Kalman filter with every measurement, and both stay unbiased."""
    runs = {}
    for backend in ("centralized_lmmse", {"name": "kalman", "variant": "ideal"}, "prediction_compensation"):
        spec = coloc_env.compose(world="drift", network="ideal", backend=backend)
        infos, _, env = _episode(spec, _always, 2)
        runs[spec.backend.name] = (_stack(infos, "estimated_position", env), _stack(infos, "position_error", env))
    np.testing.assert_allclose(runs["centralized_lmmse"][0], runs["kalman"][0], rtol=0, atol=1e-9)
    # the drift moves the target 25 m over the episode; the estimates track it to centimetres
    assert runs["kalman"][1].mean() < 0.2 and runs["prediction_compensation"][1].mean() < 0.3


def test_the_same_seed_gives_every_target_backend_the_same_truth():
    truths = []
    for backend in ("bandwidth_fusion", "centralized_lmmse", "prediction_compensation", "kalman"):
        infos, _, env = _episode(coloc_env.compose(world="target_cv", network="bernoulli_delay", backend=backend),
                                 _always, 4, steps=20)
        truths.append(_stack(infos, "true_position", env))
        np.testing.assert_array_equal(truths[-1][:, 0], env.unwrapped.scenario.world.truth[0, :20][:, [0, 2]])
    for other in truths[1:]:
        np.testing.assert_array_equal(truths[0], other)


def test_target_infos_and_trace_reward():
    spec = coloc_env.compose(world="target_cv", network="ideal", backend="prediction_compensation", reward="trace")
    infos, rewards, env = _episode(spec, _always, 0, steps=5)
    scenario = env.unwrapped.scenario
    cov = scenario.backend.posterior_state_cov[0, 0]
    H = scenario.world.metric
    assert rewards[-1]["uav_0"] == pytest.approx(-np.trace(H @ cov @ H.T), rel=1e-12)
    info = infos[-1]["uav_1"]
    assert info["true_position"].shape == (2,) and info["trace"] == pytest.approx(cov[0, 0] + cov[2, 2])
    np.testing.assert_allclose(info["position_error"],
                               np.linalg.norm(info["estimated_position"] - info["true_position"]))


def test_bad_target_options_name_the_part_and_field():
    with pytest.raises(ValueError, match=r"network\.on_time_probability \+ network\.late_probability must be in"):
        coloc_env.compose(world="target_cv", network={"name": "bernoulli_delay", "on_time_probability": 0.8,
                                                     "late_probability": 0.5}, backend="kalman")
    with pytest.raises(ValueError, match=r"world\.horizon must be an integer"):
        coloc_env.compose(world={"name": "drift", "horizon": 2.5}, network="ideal", backend="kalman")
    with pytest.raises(ValueError, match=r"world\.initial_cov must be a \(3, 3\) covariance"):
        coloc_env.compose(world={"name": "drift", "initial_cov": ((1.0, 0.0), (0.0, 1.0))}, network="ideal",
                          backend="kalman")
    with pytest.raises(ValueError, match=r"backend\.variant must be one of"):
        coloc_env.compose(world="drift", network="ideal", backend={"name": "kalman", "variant": "smart"})
    with pytest.raises(ValueError, match=r"backend\.moments must be one of"):
        coloc_env.compose(world="target_cv", network="bernoulli_delay",
                          backend={"name": "centralized_lmmse", "moments": "exact"})
    with pytest.raises(ValueError, match=r"backend\.forward_spread must be True or False"):
        coloc_env.compose(world="target_cv", network="bernoulli_delay",
                          backend={"name": "prediction_compensation", "forward_spread": "yes"})
    spec = coloc_env.compose(world="drift", network={"name": "bandwidth", "budget": 10}, backend="bandwidth_fusion")
    with pytest.raises(ValueError, match=r"network\.budget must be in \[3, 9\], got 10"):
        coloc_env.parallel_env(spec)


def test_vector_env_copy_b_is_the_env_reset_with_seed_plus_b():
    spec = coloc_env.compose(world="drift", network="bernoulli_delay", backend="centralized_lmmse", horizon=20)
    venv = coloc_env.vector_env(spec, num_envs=3, seed=10)
    venv.reset()
    N = 4
    for _ in range(20):
        _, rewards, _, _ = venv.step(np.ones((3 * N, 1), np.int64))
        last = rewards.reshape(3, N)
    for b in range(3):
        env = coloc_env.parallel_env(spec)
        env.reset(seed=10 + b)
        for _ in range(20):
            _, rewards, _, _, _ = env.step({a: np.array([1]) for a in env.possible_agents})
        np.testing.assert_allclose([rewards[a] for a in env.possible_agents], last[b], rtol=1e-6)
    assert len(set(last[:, 0])) == 3  # three different episodes
