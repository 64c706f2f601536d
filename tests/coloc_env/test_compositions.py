"""The composable core: every compatible composition, its errors and its consistency checks."""

import os
import pickle

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

import agents
import coloc_env
from coloc_env.data import mrclam
from tests.conftest import MRCLAM_DATASET6 as DATASET6  # noqa: E402
from tests.conftest import MRCLAM_SKIP_REASON, RECORDED_WORLDS  # noqa: E402

OK_ROWS = [r for r in coloc_env.compatibility() if r["ok"]]


def _rollout(spec, policy_name, seed, steps):
    env = coloc_env.parallel_env(spec)
    policy = agents.make_policy(policy_name, env, seed=0)
    observations, _ = env.reset(seed=seed)
    total, truth, estimates = 0.0, [], []
    for _ in range(steps):
        if not env.agents:
            break
        observations, rewards, _, _, infos = env.step(policy.act(observations))
        total += sum(rewards.values())
        truth.append([infos[a]["true_position"] for a in env.possible_agents])
        estimates.append([infos[a]["estimated_position"] for a in env.possible_agents])
    return total, np.array(truth), np.array(estimates), env


@pytest.mark.parametrize("row", OK_ROWS, ids=lambda r: f"{r['world']}/{r['network']}/{r['backend']}")
def test_every_compatible_composition_passes_the_api_and_runs(row, monkeypatch):
    if row["world"] in RECORDED_WORLDS:  # recorded data: its default data=None reads $COLOC_MRCLAM_DATA at build time
        if not os.path.isdir(DATASET6):
            pytest.skip(MRCLAM_SKIP_REASON)
        monkeypatch.setenv(mrclam.ENV_VAR, DATASET6)
    spec = coloc_env.compose(world=row["world"], network=row["network"], backend=row["backend"])
    parallel_api_test(coloc_env.parallel_env(spec), num_cycles=5)  # the two rollouts below step it further
    for policy_name in ("random", "always"):
        total, truth, _, env = _rollout(spec, policy_name, seed=1, steps=20)
        assert np.isfinite(total) and len(truth) == 20
        space = env.observation_space(env.possible_agents[0])
        observation = env.unwrapped.scenario.observation()[0]
        assert all(space.contains(o) for o in observation)


def test_the_matrix_has_the_rows_the_issue_names():
    ok = {(r["world"], r["network"], r["backend"]) for r in OK_ROWS}
    for backend in ("ukf_ccl", "ukf_dcl", "dead_reckoning"):
        assert ("circles", "ideal", backend) in ok
    assert all(set(r) == {"world", "network", "backend", "ok", "reason"} for r in coloc_env.compatibility())


BOTH_UKFS = sorted({r["world"] for r in OK_ROWS if r["network"] == "ideal" and r["backend"] == "ukf_dcl"}
                   & {r["world"] for r in OK_ROWS if r["network"] == "ideal" and r["backend"] == "ukf_ccl"})
# the others are slower per step (every pair ranges): fewer; the robots of mrclam_slices move under a metre in 12 s
UKF_STEPS = {"circles": 150, "mrclam_slices": 40}


@pytest.mark.parametrize("world", BOTH_UKFS)
def test_ukf_dcl_over_an_ideal_network_equals_ukf_ccl(world, request, monkeypatch):
    if world in RECORDED_WORLDS:
        monkeypatch.setenv(mrclam.ENV_VAR, request.getfixturevalue("mrclam_dataset6"))
    steps = UKF_STEPS.get(world, 12)
    runs = {b: _rollout(coloc_env.compose(world=world, network="ideal", backend=b), "always", 4, steps)
            for b in ("ukf_ccl", "ukf_dcl")}
    (_, truth_c, est_c, env_c), (_, truth_d, est_d, env_d) = runs["ukf_ccl"], runs["ukf_dcl"]
    np.testing.assert_array_equal(truth_c, truth_d)
    np.testing.assert_allclose(est_d, est_c, rtol=0, atol=1e-9)
    np.testing.assert_allclose(env_d.unwrapped.scenario.backend.cov, env_c.unwrapped.scenario.backend.cov,
                               rtol=0, atol=1e-9)
    # the fixes of the anchors and the ranges did move the estimates away from dead reckoning
    _, _, est_dr, _ = _rollout(coloc_env.compose(world=world, network="ideal", backend="dead_reckoning"),
                               "always", 4, steps)
    assert np.abs(est_dr - est_c).max() > 1.0


def test_the_ukfs_run_on_gps_denied_with_the_gps_normal_uavs_as_anchors():
    assert "gps_denied" in BOTH_UKFS


@pytest.mark.parametrize("network", ["ideal", "relay", "broadcast"])
def test_the_same_world_and_seed_give_every_backend_the_same_truth(network):
    truths = [_rollout(coloc_env.compose(world="circles", network=network, backend=b), "random", 7, 40)[1]
              for b in ("dead_reckoning", "ukf_ccl", "ukf_dcl")]
    for other in truths[1:]:
        np.testing.assert_array_equal(truths[0], other)


def test_a_lossy_relay_costs_accuracy_over_seeded_episodes():
    errors = {}
    for loss in (0.0, 0.9):
        spec = coloc_env.compose(world="circles", network={"name": "relay", "loss_at_zero": loss},
                                 backend="ukf_dcl", horizon=200)
        errors[loss] = []
        for seed in range(4):
            env = coloc_env.parallel_env(spec)
            policy = agents.make_policy("always", env)
            observations, _ = env.reset(seed=seed)
            per_step = []
            while env.agents:
                observations, _, _, _, infos = env.step(policy.act(observations))
                per_step.append([infos[a]["position_error"] for a in env.possible_agents])
            errors[loss].append(np.mean(per_step))
    assert np.all(np.array(errors[0.9]) > np.array(errors[0.0]))


def test_bad_options_name_the_part_and_field():
    with pytest.raises(ValueError, match=r"network\.loss_at_zero must be in \[0\.0, 1\.0\], got 1\.5"):
        coloc_env.compose(world="circles", network={"name": "relay", "loss_at_zero": 1.5}, backend="ukf_dcl")
    with pytest.raises(ValueError, match=r"unknown world 'nowhere'"):
        coloc_env.compose(world="nowhere", network="ideal", backend="ukf_dcl")
    with pytest.raises(ValueError, match=r"unknown network field\(s\) \['hops'\]"):
        coloc_env.compose(world="circles", network={"name": "relay", "hops": 2}, backend="ukf_dcl")
    with pytest.raises(ValueError, match=r"unknown composition option\(s\) \['loss_at_zero'\]"):
        coloc_env.compose(world="circles", network="relay", backend="ukf_dcl", loss_at_zero=0.1)
    with pytest.raises(ValueError, match=r"world\.num_anchors must be an integer"):
        coloc_env.compose(world={"name": "circles", "num_anchors": True}, network="ideal", backend="ukf_dcl")
    with pytest.raises(ValueError, match=r"reward must be one of"):
        coloc_env.compose(world="circles", network="ideal", backend="ukf_dcl", reward="loss")


def test_a_composition_is_frozen_picklable_and_equal_to_its_copy():
    spec = coloc_env.compose(world=coloc_env.worlds.Circles(num_agents=4), network="relay", backend="ukf_dcl",
                             reward="trace", communication_cost=0.01)
    assert pickle.loads(pickle.dumps(spec)) == spec
    with pytest.raises(AttributeError):
        spec.reward = "error"


def test_a_bad_action_names_its_block():
    env = coloc_env.parallel_env(coloc_env.compose(world="circles", network="relay", backend="ukf_dcl"))
    env.reset(seed=0)
    N = len(env.possible_agents)
    actions = {a: np.array([0, N + 2]) for a in env.possible_agents}
    with pytest.raises(ValueError, match=r"network block 'next_hop'.* of platform_0 must be an integer in \[0, 7\], "
                                         r"got 8"):
        env.step(actions)


def test_vector_env_copy_b_is_the_env_reset_with_seed_plus_b():
    spec = coloc_env.compose(world="circles", network="relay", backend="ukf_dcl", horizon=20)
    venv = coloc_env.vector_env(spec, num_envs=3, seed=10)
    venv.reset()
    N = 6
    for _ in range(20):
        obs, rewards, dones, _ = venv.step(np.tile(np.array([N, N + 1]), (3 * N, 1)))
        last = rewards.reshape(3, N)
    for b in range(3):
        env = coloc_env.parallel_env(spec)
        env.reset(seed=10 + b)
        for _ in range(20):
            _, rewards, _, _, _ = env.step({a: np.array([N, N + 1]) for a in env.possible_agents})
        np.testing.assert_allclose([rewards[a] for a in env.possible_agents], last[b], rtol=1e-6)


def test_presets_are_compositions_and_build_the_same_env():
    assert coloc_env.SCENARIOS == tuple(coloc_env.PRESETS)
    spec = coloc_env.PRESETS["relay_ukf"]
    assert isinstance(spec, coloc_env.Composition) and spec.world.num_agents == 4
    outs = []
    for target in ("relay_ukf", spec):
        env = coloc_env.parallel_env(target, horizon=30)
        policy = agents.make_policy("paper", env, seed=0)
        observations, _ = env.reset(seed=2)
        total = 0.0
        while env.agents:
            observations, rewards, _, _, _ = env.step(policy.act(observations))
            total += sum(rewards.values())
        outs.append(total)
    assert outs[0] == outs[1]


def test_a_relays_hop_cost_is_charged_in_the_composed_reward_at_the_holder():
    """A relay hop's price (its flat price, the network's older name ``hop_cost`` of the composition's
    ``communication_cost``, and the network's ``hop_cost_per_m2`` d^2): a composition's reward is minus the agent's
    error minus the cost of the hops it sent (and the same episode without a price differs by exactly that)."""
    def run(**fields):
        spec = coloc_env.compose(world="circles", network={"name": "relay", **fields}, backend="ukf_dcl", horizon=12)
        env = coloc_env.parallel_env(spec)
        policy = agents.make_policy("always", env, seed=0)
        observations, _ = env.reset(seed=2)
        rows = []
        while env.agents:
            observations, rewards, _, _, infos = env.step(policy.act(observations))
            scenario = env.unwrapped.scenario
            cost = fields.get("hop_cost", 0.0) * scenario.network.messages_sent[0] + scenario.network.cost_sent[0]
            rows.append(([rewards[a] for a in env.possible_agents], [infos[a]["error"] for a in env.possible_agents],
                         cost))
        return rows

    priced, free = run(hop_cost=0.5, hop_cost_per_m2=0.001), run()
    charged = 0.0
    for (reward, error, cost), (free_reward, free_error, free_cost) in zip(priced, free, strict=True):
        np.testing.assert_allclose(reward, -np.asarray(error) - cost, rtol=0, atol=1e-12)
        np.testing.assert_allclose(error, free_error, rtol=0, atol=0)  # the price changes no estimate
        np.testing.assert_allclose(free_reward, -np.asarray(free_error), rtol=0, atol=1e-12)
        assert not np.any(free_cost)
        charged += cost.sum()
    assert charged > 0.5 * len(priced)  # hops were sent (and priced) at most steps


def test_a_composition_name_builds_the_composition_it_names():
    """``WORLD/NETWORK/BACKEND`` (``Composition.name``) is accepted wherever a preset name is: the same env,
    copy for copy, as ``compose`` of the three parts, with the composition-level options as its config."""
    name = "circles/broadcast/ukf_ccl"
    spec = coloc_env.compose("circles", "broadcast", "ukf_ccl", reward="trace", horizon=6)
    by_name = coloc_env.parallel_env(name, reward="trace", horizon=6)
    by_spec = coloc_env.parallel_env(spec)
    assert by_name.unwrapped.scenario.composition == spec and by_name.unwrapped.scenario.name == name
    obs_a, _ = by_name.reset(seed=3)
    obs_b, _ = by_spec.reset(seed=3)
    assert all(np.array_equal(obs_a[a], obs_b[a]) for a in obs_b)
    for a in by_name.possible_agents:
        by_name.action_space(a).seed(7)
    for _ in range(6):
        actions = {a: by_name.action_space(a).sample() for a in by_name.agents}
        step_a, step_b = by_name.step(actions), by_spec.step(actions)
        for got, want in zip(step_a[:2], step_b[:2], strict=True):
            assert all(np.array_equal(got[a], want[a]) for a in want)
    core = coloc_env.make_core(name, batch=3, horizon=6)
    assert core.batch == 3 and core.composition == spec.replace(reward="error")
    assert coloc_env.scenario_class(name) is type(core)


@pytest.mark.parametrize(("name", "config", "message"), [
    ("circles/broadcast", {}, "a composition name is WORLD/NETWORK/BACKEND"),
    ("circles/telepathy/ukf_ccl", {}, "unknown network 'telepathy'"),
    ("drift/ideal/ukf_ccl", {}, "ukf_ccl estimates each agent's own position"),
    ("circles/broadcast/ukf_ccl", {"hop_cost": 1.0}, r"unknown composition option\(s\) \['hop_cost'\]"),
])
def test_a_bad_composition_name_says_what_is_wrong(name, config, message):
    with pytest.raises(ValueError, match=message):
        coloc_env.parallel_env(name, **config)
    if not config:
        with pytest.raises(ValueError, match=message):
            coloc_env.scenario_class(name)
