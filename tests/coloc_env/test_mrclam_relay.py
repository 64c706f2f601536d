"""The mrclam_relay scenario: relay decisions on the replayed UTIAS MRCLAM dataset 6."""

import os
import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

import agents
import coloc_env
import estimators.ukf_relay_se2 as se2
from coloc_env.data import mrclam, mrclam_noise
from coloc_env.networks.blocks.relay_chain import STOP_REASONS
from tests.helpers import play

NAME = "mrclam_relay"
REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.conftest import MRCLAM_DATASET6 as DATASET6  # noqa: E402
from tests.conftest import MRCLAM_SKIP_REASON  # noqa: E402

N = 5

pytestmark = pytest.mark.skipif(not os.path.isdir(DATASET6), reason=MRCLAM_SKIP_REASON)


def make(render_mode=None, **config):
    config.setdefault("window_steps", 30)
    return coloc_env.parallel_env(NAME, render_mode=render_mode, data=DATASET6, **config)


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
        parallel_api_test(make(), num_cycles=40)
        parallel_seed_test(lambda: make(), num_cycles=20)
        api_test(coloc_env.env(NAME, data=DATASET6, window_steps=10), num_cycles=12)


def test_spaces_window_and_initial_state():
    env = make(render_mode="rgb_array")
    assert env.possible_agents == [f"robot_{i}" for i in range(N)]
    assert list(env.action_space("robot_3").nvec) == [N] + [N + 1] * N
    assert env.action_space("robot_0") is env.action_space("robot_0")
    assert env.observation_space("robot_1").shape == (3 * N + 7,)
    observations, infos = env.reset(seed=0)
    scenario = env.scenario
    assert env.state().shape == env.state_space.shape and np.isfinite(env.state()).all()
    assert scenario.horizon == 30 and coloc_env.parallel_env(NAME, data=DATASET6).scenario.horizon == 600
    start = int(scenario.world.start[0])
    assert 0 <= start <= scenario.world.data.steps - 1 - 30
    for i, agent in enumerate(env.possible_agents):
        np.testing.assert_array_equal(infos[agent]["estimated_position"], scenario.world.data.groundtruth[start, i, :2])
        np.testing.assert_array_equal(infos[agent]["true_position"], infos[agent]["estimated_position"])
        flags = observations[agent][N:2 * N]
        recorded = scenario.world.tables.first_index[start, i] >= 0
        np.testing.assert_array_equal(flags, recorded.astype(np.float32))
    np.testing.assert_allclose(infos["robot_0"]["trace"], 2e-4)
    assert env.render().shape[2] == 3
    # the offsets cover the run: different seeds, different windows
    seen = set()
    for s in range(8):
        env.reset(seed=s)
        seen.add(int(scenario.world.start[0]))
    assert len(seen) == 8


def test_data_path_from_the_environment_variable(monkeypatch):
    monkeypatch.setenv(mrclam.ENV_VAR, DATASET6)
    env = coloc_env.parallel_env(NAME, window_steps=5)
    assert env.scenario.world.data.steps > 7000
    monkeypatch.delenv(mrclam.ENV_VAR)
    with pytest.raises(ValueError, match="data.*COLOC_MRCLAM_DATA"):
        coloc_env.parallel_env(NAME)


@pytest.mark.parametrize("kwargs, field", [
    ({"window_steps": 10**6}, "window_steps"),
    ({"window_steps": 0}, "window_steps"),
    ({"window_steps": 2.5}, "window_steps"),
    ({"loss_at_zero": -0.1}, "loss_at_zero"),
    ({"loss_at_zero": 1.5}, "loss_at_zero"),
    ({"max_hops": 5}, "max_hops"),
    ({"comm_range": 0.0}, "comm_range"),
    ({"communication_cost": -1.0}, "communication_cost"),
    ({"hop_cost": -1.0}, "^mrclam_relay: hop_cost must be"),  # the old name, refused under the name written
    ({"gate": 0.0}, "gate"),
    ({"initial_position_std": 0.0}, "initial_position_std"),
    ({"calibration_s": -1.0}, "calibration_s"),
    ({"noise_model": "white"}, "noise_model"),
    ({"noise_model": None}, "noise_model"),
    ({"dt": 0.0}, "dt"),
    ({"reward": "rmse"}, "reward"),
    ({"data": os.path.join(DATASET6, "nowhere")}, "data"),
    ({"data": 3}, "data"),
    ({"window_step": 3}, "unknown config key"),
])
def test_bad_config_names_the_field(kwargs, field):
    config = {"data": DATASET6, **kwargs}
    with pytest.raises(ValueError, match=field):
        coloc_env.parallel_env(NAME, **config)


def test_validation_reads_no_data_and_building_checks_the_run(tmp_path):
    """The keywords are the parts' checks (no file is opened); the dataset and the window against the run are
    checked when an env is built, under the preset's keywords."""
    from coloc_env.scenarios.mrclam_relay import MrclamRelayConfig

    MrclamRelayConfig(data=str(tmp_path / "nowhere"), window_steps=10**6).validate()
    with pytest.raises(ValueError, match=r"^mrclam_relay: data: .*is not a folder"):
        coloc_env.parallel_env(NAME, data=str(tmp_path / "nowhere"))
    with pytest.raises(ValueError, match=r"^mrclam_relay: window_steps must be in \[1, \d+\] for this run"):
        coloc_env.parallel_env(NAME, data=DATASET6, window_steps=10**6)


def test_a_folder_that_is_not_a_dataset_names_data(tmp_path):
    with pytest.raises(ValueError, match="data: .*Barcodes.dat"):
        coloc_env.parallel_env(NAME, data=str(tmp_path))


@pytest.mark.parametrize("bad, match", [(np.nan, "finite"), (1.5, "of robot_2 must be an integer"), (5, r"action\[0\]"),
                                        (-1, r"action\[0\]")])
def test_bad_action_is_refused(bad, match):
    env = make()
    env.reset(seed=0)
    actions = {a: env.action_space(a).sample().astype(float) for a in env.agents}
    actions["robot_2"][0] = bad
    with pytest.raises(ValueError, match=match):
        env.step(actions)
    with pytest.raises(ValueError, match=r"action\[1:\]"):
        env.step({a: np.array([0, 6, 0, 0, 0, 0]) for a in env.agents})
    with pytest.raises(ValueError, match="shape"):
        env.step({a: np.zeros(2) for a in env.agents})


def test_same_seed_gives_identical_episodes_and_reset_continues_the_generator():
    env_a, env_b = make(window_steps=15), make(window_steps=15)
    first_a = play(env_a, agents.make_policy("random", env_a, seed=5), 11)
    first_b = play(env_b, agents.make_policy("random", env_b, seed=5), 11)
    assert len(first_a) == 16 and data_equivalence(first_a, first_b)
    other = play(make(window_steps=15), agents.make_policy("random", env_a, seed=5), 12)
    assert not data_equivalence(first_a, other)
    # the loss draws are counter-based from the network's key, drawn at reset
    start, keys = env_a.scenario.world.start.copy(), env_a.scenario.network.keys.copy()
    env_a.reset()
    env_b.reset()
    assert env_a.scenario.world.start[0] == env_b.scenario.world.start[0]
    np.testing.assert_array_equal(env_a.scenario.network.keys, env_b.scenario.network.keys)
    assert env_a.scenario.world.start[0] != start[0] and not np.array_equal(env_a.scenario.network.keys, keys)


@pytest.mark.parametrize("noise_model", ["calibrated", "baseline"])
def test_paper_policy_without_losses_equals_ukf_ccl_under_the_reproductions_noise_model(noise_model):
    """Complete chains: the scenario's UKF-DCL estimates are UKF-CCL's (landmarks: the robot that saw them).

    The reference applies the noise model as ``coloc reproduce mrclam`` (``run_filters``) does: fitted
    afresh by the shared window rule, the corrected odometry series of the whole run (so the window's
    first steps integrate the commands logged before it), per-step Q, R from each measured range.
    (``run_filters`` on ``d.window(start, W)`` itself is no reference: it applies every landmark
    sighting to all robots, the scenario to the robot that saw it, and holds the window's first command
    where the scenario uses the earlier ones.)
    """
    env = make(window_steps=80, noise_model=noise_model)
    policy = agents.make_policy("paper", env)
    observations, _ = env.reset(seed=3)
    scenario = env.scenario
    d, gate = scenario.world.data, scenario.config.gate
    model = mrclam_noise.NoiseModel.calibrate(d, noise_model)  # calibration_seconds(d, noise_model) of the run
    assert model == scenario.world.noise_model and model.kind == noise_model
    odometry = model.odometry(d, np.arange(d.steps))  # the series run_filters integrates
    Q = model.odometry_var(odometry)
    start = int(scenario.world.start[0])
    delay = 2 if noise_model == "calibrated" else 0
    assert model.odometry_delay_steps == delay and start >= delay
    np.testing.assert_array_equal(odometry[start], d.odometry[start - delay] * np.asarray(model.odometry_scale))
    x, P = d.groundtruth[start].copy(), 1e-4 * np.eye(3 * N)
    applied = {"robot": 0, "landmark": 0}
    for k in range(80):
        actions = policy.act(observations)
        partner = [int(actions[f"robot_{m}"][0]) for m in range(N)]
        observations, rewards, _, _, infos = env.step(actions)
        a, used = start + k, set()
        s = d.measurements_at(a)
        for j in range(s.start, s.stop):
            m, subject = int(d.meas_robot[j]), int(d.meas_subject[j])
            z = np.array([d.meas_range[j], d.meas_bearing[j]])
            R = model.measurement_cov(float(d.meas_range[j]))
            if subject > N:
                x, P, ok = se2.ccl_update(x, P, m, z, R, landmark=d.landmarks[subject - N - 1],
                                          reached=np.arange(N) == m, gate=gate)
                applied["landmark"] += ok
            elif subject - 1 == partner[m] and m not in used:  # the lowest-index robot m recorded
                used.add(m)
                assert partner[m] == min(int(n) - 1 for n in d.meas_subject[s][d.meas_robot[s] == m] if n <= N)
                x, P, ok = se2.ccl_update(x, P, m, z, R, measured=subject - 1, gate=gate)
                applied["robot"] += ok
                assert infos[f"robot_{m}"]["chain_length"] == N  # complete chain
        x, P = se2.time_update(x, P, odometry[a], d.dt, Q[a])
        np.testing.assert_allclose(scenario.backend.estimate[0], x, atol=1e-9, rtol=0)
        np.testing.assert_allclose(scenario.backend.joint_cov(0), P, atol=1e-9, rtol=0)
        errors = np.linalg.norm(x[:, :2] - d.groundtruth[a + 1, :, :2], axis=-1)
        assert rewards["robot_0"] == pytest.approx(-errors.mean(), abs=1e-9)
    assert applied["robot"] > 5 and applied["landmark"] > 20


def _replay(seed, window_steps, **config):
    """Paper policy, no loss: (observations rejected by the gate, applied, mean position error [m])."""
    env = make(window_steps=window_steps, **config)
    policy = agents.make_policy("paper", env)
    observations, _ = env.reset(seed=seed)
    rejected = applied = 0
    errors = []
    while env.agents:
        observations, _, _, _, infos = env.step(policy.act(observations))
        rejected += sum(int(infos[a]["rejected"]) for a in infos)
        applied += sum(int(infos[a]["used"]) + int(infos[a]["landmarks"]) for a in infos)
        errors.append([infos[a]["error"] for a in infos])
    return int(env.scenario.world.start[0]), rejected, applied, float(np.mean(errors))


def test_calibrated_noise_model_rejects_fewer_observations_than_the_baseline():
    """The baseline (constant MAD noise, raw commands) is overconfident: its gate refuses a large share."""
    rows = []
    for seed in (0, 1, 2):
        start, rej_c, app_c, err_c = _replay(seed, 150)
        start_b, rej_b, app_b, err_b = _replay(seed, 150, noise_model="baseline")
        assert start_b == start  # the same window
        rows.append((rej_c, rej_b))
        print(f"seed {seed} window [{start}, {start + 150}): rejected calibrated {rej_c}/{rej_c + app_c}, "
              f"baseline {rej_b}/{rej_b + app_b}; mean error calibrated {err_c:.4f} m, baseline {err_b:.4f} m")
        assert rej_c <= rej_b
    rejected = np.sum(rows, axis=0)
    assert rejected[1] > 50 and rejected[0] < 0.2 * rejected[1]


def test_relay_choices_truncate_the_chain_and_hop_costs_enter_the_reward():
    env = make(window_steps=200, hop_cost=0.5, hop_cost_per_m2=1e-2)
    paper = agents.make_policy("paper", env)
    observations, _ = env.reset(seed=1)
    scenario = env.scenario
    while True:  # replay with the paper policy until a robot recorded another one
        flags = np.array([observations[a][N:2 * N] for a in env.possible_agents])
        if flags.any():
            break
        observations, *_ = env.step(paper.act(observations))
    m, n = (int(v) for v in np.argwhere(flags)[0])
    third = next(i for i in range(N) if i not in (m, n))
    actions = {a: np.array([i] + [N] * N) for i, a in enumerate(env.possible_agents)}
    actions[f"robot_{m}"][0] = n
    actions[f"robot_{n}"][1 + m] = third
    actions[f"robot_{third}"][1 + m] = m  # back to m: a revisit ends the chain
    actions[f"robot_{third}"][1 + n] = m  # another source's entry: not used
    positions = scenario.true_position()[0]
    observations, rewards, _, _, infos = env.step(actions)
    assert infos[f"robot_{m}"]["partner"] == n and infos[f"robot_{m}"]["chain_length"] == 3
    assert STOP_REASONS[int(infos[f"robot_{m}"]["chain_stop"])] == "revisit"
    assert infos["robot_0"]["hops"] == 2 and sum(infos[a]["communication"] for a in infos) == 2
    assert infos[f"robot_{m}"]["communication"] == 1 and infos[f"robot_{n}"]["communication"] == 1
    assert all(infos[f"robot_{i}"]["chain_length"] == 0 for i in range(N) if i != m)
    d = np.linalg.norm(positions[[m, n]] - positions[[n, third]], axis=-1)
    cost = 2 * 0.5 + 1e-2 * np.sum(d**2)
    assert infos["robot_0"]["hop_cost"] == pytest.approx(cost, abs=1e-12)
    errors = [infos[a]["error"] for a in env.possible_agents]
    assert rewards["robot_4"] == pytest.approx(-np.mean(errors) - cost, abs=1e-12)


def _episode(seed, **config):
    env = make(window_steps=60, **config)
    policy = agents.make_policy("paper", env)
    observations, _ = env.reset(seed=seed)
    errors, traces, lengths, stops = [], [], [], []
    while env.agents:
        observations, _, _, _, infos = env.step(policy.act(observations))
        errors.append([infos[a]["error"] for a in env.possible_agents])
        traces.append([infos[a]["trace"] for a in env.possible_agents])
        lengths.append([infos[a]["chain_length"] for a in env.possible_agents])
        stops.append([infos[a]["chain_stop"] for a in env.possible_agents])
    return np.mean(errors), np.mean(traces), np.array(lengths), np.array(stops)


def test_lossy_links_cut_chains_and_cost_accuracy():
    """Same seeds: same windows, actions and loss draws, so each lossy chain is a prefix of the lossless one. The
    filter knows it has less (its trace grows). Its error over these 6 s windows is not compared: the paired
    differences (lossy - lossless mean error) of 8 seeds have either sign under both noise models (-0.5 to
    +1.6 mm against a mean of 18 mm), so which mean is larger is noise."""
    ideal = [_episode(seed) for seed in range(4)]
    lossy = [_episode(seed, loss_at_zero=0.7) for seed in range(4)]
    for (_, _, length, stop), (_, _, cut, cut_stop) in zip(ideal, lossy, strict=True):
        assert np.all(cut <= length)
        assert np.all(stop[length > 0] == STOP_REASONS.index("complete"))
        shorter = cut < length
        assert np.all(cut_stop[shorter] == STOP_REASONS.index("lost"))
    hops = lambda runs: sum(np.maximum(r[2] - 1, 0).sum() for r in runs)  # noqa: E731
    assert hops(lossy) < 0.5 * hops(ideal)
    assert np.mean([r[1] for r in lossy]) > np.mean([r[1] for r in ideal])  # the filter knows it has less


def test_batched_copies_equal_single_envs_and_reset_one_copy():
    from coloc_env.config import build_config
    from coloc_env.scenarios.mrclam_relay import MrclamRelayConfig, MrclamRelayScenario

    config = build_config(MrclamRelayConfig, {"data": DATASET6, "window_steps": 12})
    batch = MrclamRelayScenario(config, batch=3)
    batch.reset([np.random.default_rng(s) for s in (4, 5, 6)])
    singles = [MrclamRelayScenario(config, batch=1) for _ in range(3)]
    for s, single in zip((4, 5, 6), singles, strict=True):
        single.reset([np.random.default_rng(s)])
    from agents.mrclam_relay import paper_actions

    for _ in range(12):
        actions = paper_actions(batch.observation()[..., N:2 * N] > 0.5)
        batch.step(actions)
        for b, single in enumerate(singles):
            single.step(actions[b:b + 1])
    for b, single in enumerate(singles):
        np.testing.assert_array_equal(batch.backend.estimate[b], single.backend.estimate[0])
        np.testing.assert_array_equal(batch.backend.sigma[b], single.backend.sigma[0])
    before = batch.backend.estimate[[0, 2]].copy()
    batch.reset([np.random.default_rng(9)], env_index=[1])
    np.testing.assert_array_equal(batch.backend.estimate[[0, 2]], before)
    assert batch.k.tolist() == [12, 0, 12]
