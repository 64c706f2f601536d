"""World ``mrclam`` with backends ``ukf_se2``, ``range_ls`` and ``dead_reckoning`` (recorded UTIAS data, composed)."""

import os
import pickle

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

import agents
import coloc_env
from coloc_env.data import mrclam, mrclam_navigation
from coloc_env.scenarios.composed import ComposedScenario
from coloc_env.scenarios.mrclam_relay import MrclamRelayConfig, MrclamRelayScenario

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.conftest import MRCLAM_DATASET6 as DATASET6  # noqa: E402
from tests.conftest import MRCLAM_SKIP_REASON  # noqa: E402

N = mrclam.NUM_ROBOTS
needs_data = pytest.mark.skipif(not os.path.isdir(DATASET6), reason=MRCLAM_SKIP_REASON)


def world(**fields):
    return {"name": "mrclam", "data": DATASET6, "horizon": 40, **fields}


def _run(spec, seed, steps, policy_name="always"):
    """(truth (T, N, 2), estimates (T, N, 2), errors (T, N), total reward, env) of one seeded episode."""
    env = coloc_env.parallel_env(spec)
    policy = agents.make_policy(policy_name, env, seed=0)
    observations, _ = env.reset(seed=seed)
    truth, estimates, errors, total = [], [], [], 0.0
    for _ in range(steps):
        observations, rewards, _, _, infos = env.step(policy.act(observations))
        total += sum(rewards.values())
        truth.append([infos[a]["true_position"] for a in env.possible_agents])
        estimates.append([infos[a]["estimated_position"] for a in env.possible_agents])
        errors.append([infos[a]["position_error"] for a in env.possible_agents])
    return np.array(truth), np.array(estimates), np.array(errors), total, env


@needs_data
@pytest.mark.parametrize("network", ["ideal", "relay"])
@pytest.mark.parametrize("backend", ["ukf_se2", "range_ls", "dead_reckoning"])
def test_mrclam_compositions_pass_the_api_and_run(backend, network):
    spec = coloc_env.compose(world=world(), network=network, backend=backend)
    parallel_api_test(coloc_env.parallel_env(spec), num_cycles=10)
    for policy_name in ("random", "always"):
        truth, estimates, errors, total, env = _run(spec, 1, 30, policy_name)
        assert np.isfinite(total) and np.isfinite(estimates).all() and len(truth) == 30
        scenario = env.unwrapped.scenario
        space = env.observation_space(env.possible_agents[0])
        assert all(space.contains(o) for o in scenario.observation()[0])
        # the truth is the Vicon recording at the episode's offset
        start = scenario.world.start[0]
        np.testing.assert_array_equal(truth, scenario.world.data.groundtruth[start:start + 30, :, :2])


def _nearest_first_routing(positions, partner):
    """Scenario relay actions (N, N) [holder, source] that make every chain m -> partner[m] -> nearest not yet
    reached -> ... (the route of the composition's network with no routing decision)."""
    routing = np.full((N, N), N)
    distance = np.linalg.norm(positions[:, None] - positions[None], axis=-1)
    for m in range(N):
        if partner[m] < 0:
            continue
        chain = [m, partner[m]]
        while len(chain) < N:
            rest = [i for i in range(N) if i not in chain]
            chain.append(rest[int(np.argmin(distance[chain[-1], rest]))])
        for holder, nxt in zip(chain[1:-1], chain[2:], strict=True):
            routing[holder, m] = nxt
    return routing


@needs_data
@pytest.mark.parametrize("network", ["ideal", {"name": "relay", "loss_at_zero": 0.0}])
def test_ukf_se2_reproduces_the_mrclam_relay_scenario(network):
    """The scenario's window, partner choices and nearest-first chains over a loss-free network: the composition's
    ukf_se2 holds the scenario's estimates and covariance factors to 1e-9 at every step."""
    steps, rng = 80, np.random.default_rng(5)
    scenario = MrclamRelayScenario(MrclamRelayConfig(data=DATASET6, window_steps=steps))
    scenario.reset([np.random.default_rng(11)])
    start = int(scenario.world.start[0])
    spec = coloc_env.compose(world=world(start=start, horizon=steps), network=network, backend="ukf_se2")
    env = coloc_env.parallel_env(spec)
    env.reset(seed=0)
    core = env.unwrapped.scenario
    backend = core.backend
    relay_block = len(core.blocks) > 1  # relay: next_hop = N + 1 (nearest not yet reached)
    used = 0
    for _ in range(steps):
        choice = rng.integers(0, N, size=N)  # each robot's choice of whose measurement to use
        a = scenario.world.absolute_step()[0]
        recorded = scenario.world.tables.first_index[a, np.arange(N), choice] >= 0
        partner = np.where(recorded & (choice != np.arange(N)), choice, -1)
        routing = _nearest_first_routing(scenario.true_position()[0], partner)
        scenario.step(np.concatenate([choice[:, None], routing], axis=1)[None])
        used += int(scenario.backend.used.sum())
        actions = {agent: np.array([choice[i]] + ([N + 1] if relay_block else []))
                   for i, agent in enumerate(env.possible_agents)}
        env.step(actions)
        np.testing.assert_allclose(backend.estimate[0], scenario.backend.estimate[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(backend.P_ii[0], scenario.backend.P_ii[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(backend.joint_cov(0), scenario.backend.joint_cov(0), rtol=0, atol=1e-9)
    assert used > 5, "the window must hold applied robot-robot measurements for the comparison to mean anything"
    assert scenario.backend.landmarks_applied.sum() + used > 0


@needs_data
def test_ukf_se2_beats_dead_reckoning_on_paired_windows():
    """Seeded Monte Carlo: 3 episodes of 20 s (random offsets of the recording, the same for both backends)."""
    errors = {}
    for backend in ("ukf_se2", "dead_reckoning"):
        spec = coloc_env.compose(world=world(horizon=200), network="relay", backend=backend)
        errors[backend] = [_run(spec, seed, 200)[2].mean() for seed in range(3)]
    difference = np.array(errors["dead_reckoning"]) - np.array(errors["ukf_se2"])
    assert np.all(difference > 0), errors
    assert np.mean(errors["ukf_se2"]) < 0.8 * np.mean(errors["dead_reckoning"]), errors


@needs_data
def test_pseudo_fixes_come_from_the_robots_own_navigation_and_are_consistent_with_vicon():
    """From the run's start the world's own-navigation filters are :func:`mrclam_navigation.own_navigation`
    exactly; every pseudo-fix lies within the 99 % radius (Rayleigh, 3.03 sigma) of its stated variance around the
    Vicon position."""
    steps = 120
    spec = coloc_env.compose(world=world(start=0, horizon=steps), network="ideal", backend="dead_reckoning")
    env = coloc_env.parallel_env(spec)
    replay = env.unwrapped.scenario.world
    replay.fixes_needed = True  # dead reckoning reads no fix; the world makes them for this inspection
    env.reset(seed=0)
    d = replay.data
    poses, _, _ = mrclam_navigation.own_navigation(d.window(0, steps + 1), replay.noise_model, d.groundtruth[0])
    normalized, variances = [], []
    for k in range(steps):
        np.testing.assert_array_equal(replay.nav_pose[0], poses[k])
        readings = replay.readings(np.full((1, N, 1), N))
        valid = readings.fix_valid[0]
        error = np.linalg.norm(readings.fix[0][valid] - replay.positions()[0][valid], axis=-1)
        normalized += list(error / np.sqrt(readings.extra["fix_var"][0][valid]))
        variances += list(readings.extra["fix_var"][0][valid])
        env.step({agent: np.array([N]) for agent in env.possible_agents})
    assert len(normalized) > 30
    assert max(normalized) < np.sqrt(-2 * np.log(0.01)), max(normalized)
    assert min(variances) <= replay.fix_noise_var() <= max(variances)


@needs_data
def test_every_backend_sees_the_same_recording_for_a_seed():
    truths = [_run(coloc_env.compose(world=world(), network="relay", backend=b), 7, 20, "random")[0]
              for b in ("ukf_se2", "dead_reckoning")]
    np.testing.assert_array_equal(truths[0], truths[1])
    other_seed = _run(coloc_env.compose(world=world(), network="relay", backend="ukf_se2"), 8, 20)[0]
    assert not np.array_equal(truths[0], other_seed)  # another seed, another offset of the recording


@needs_data
def test_batch_copies_replay_different_offsets():
    spec = coloc_env.compose(world=world(num_agents=3), network="relay", backend="ukf_se2")
    core = ComposedScenario(spec, batch=4)  # the batched core of vector_env(spec, num_envs=4)
    core.reset([np.random.default_rng(3 + b) for b in range(4)])
    replay = core.world
    assert len(set(replay.start.tolist())) == 4  # four offsets of the recording, one per copy
    assert replay.positions().shape == (4, 3, 2)
    np.testing.assert_array_equal(replay.positions()[2], replay.data.groundtruth[replay.start[2], :3, :2])


def test_a_composition_is_picklable_and_loads_no_data(tmp_path, monkeypatch):
    missing = str(tmp_path / "nowhere")
    spec = coloc_env.compose(world={"name": "mrclam", "data": missing}, network="relay", backend="ukf_se2")
    again = pickle.loads(pickle.dumps(spec))
    assert again == spec and again.world.data == missing
    with pytest.raises(ValueError, match="world.data"):
        coloc_env.parallel_env(spec)
    monkeypatch.delenv(mrclam.ENV_VAR, raising=False)
    spec = coloc_env.compose(world="mrclam", network="ideal", backend="dead_reckoning")
    with pytest.raises(ValueError, match=f"world.data.*{mrclam.ENV_VAR}"):
        coloc_env.parallel_env(spec)


@pytest.mark.parametrize("field, value", [("num_agents", 6), ("dt", 0.0), ("horizon", 0), ("start", -1),
                                          ("noise_model", "white"), ("calibration_s", 0.0),
                                          ("initial_position_std", 0.0), ("initial_heading_std", -1.0),
                                          ("data", 3)])
def test_bad_world_fields_name_the_field(field, value):
    with pytest.raises(ValueError, match=f"world.{field}"):
        coloc_env.compose(world={"name": "mrclam", field: value}, network="ideal", backend="ukf_se2")


@needs_data
def test_run_dependent_bounds_are_checked_at_build():
    for fields, name in (({"horizon": 10**6}, "world.horizon"), ({"start": 10**6, "horizon": 10}, "world.start")):
        spec = coloc_env.compose(world=world(**fields), network="ideal", backend="ukf_se2")
        with pytest.raises(ValueError, match=name):
            coloc_env.parallel_env(spec)


def test_bad_backend_fields_and_incompatible_worlds():
    with pytest.raises(ValueError, match="backend.gate"):
        coloc_env.compose(world="mrclam", network="ideal", backend={"name": "ukf_se2", "gate": 0.0})
    with pytest.raises(ValueError, match="ukf_se2 runs on se2_odometry"):
        coloc_env.compose(world="circles", network="ideal", backend="ukf_se2")
    with pytest.raises(ValueError, match="ukf_dcl runs on .*odometry_displacement.*world mrclam moves by se2_odometry"):
        coloc_env.compose(world="mrclam", network="relay", backend="ukf_dcl")
    rows = {(r["world"], r["network"], r["backend"]): r for r in coloc_env.compatibility()}
    assert rows[("mrclam", "relay", "ukf_se2")]["ok"] and rows[("mrclam", "ideal", "dead_reckoning")]["ok"]
