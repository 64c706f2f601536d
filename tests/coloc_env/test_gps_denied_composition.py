"""World ``gps_denied`` with backends ``dnbp``, ``range_ls`` and ``dead_reckoning`` (wan2014 in the composable core)."""

import numpy as np
import pytest

import agents
import coloc_env
import estimators.dnbp as dn
from coloc_env.networks.blocks.broadcast_medium import BroadcastMedium
from coloc_env.scenarios.gps_denied_nbp import GpsDeniedNbpConfig
from coloc_env.worlds.gps_denied import sample_episode

DNBP_SMALL = {"name": "dnbp", "num_particles": 50}


def _run(spec, seed, steps):
    """(true positions (T, N, 2), estimates (T, N, 2), errors (T, N), fault flags (T, N), env) of one episode."""
    env = coloc_env.parallel_env(spec)
    policy = agents.make_policy("always", env, seed=0)
    observations, _ = env.reset(seed=seed)
    world = env.unwrapped.scenario.world
    truth, estimates, errors, fault = [], [], [], []
    for _ in range(steps):
        fault.append(~world.gps_normal[0, world.k[0]])
        observations, _, _, _, infos = env.step(policy.act(observations))
        truth.append([infos[a]["true_position"] for a in env.possible_agents])
        estimates.append([infos[a]["estimated_position"] for a in env.possible_agents])
        errors.append([infos[a]["position_error"] for a in env.possible_agents])
    return np.array(truth), np.array(estimates), np.array(errors), np.array(fault), env


def test_dnbp_over_broadcast_equals_the_estimator_on_the_scenarios_episode():
    """Same episode and estimator generator as the composition's children of the seed, the network's range =
    the world's: :func:`estimators.dnbp.step` over the paper scenario's broadcast medium gives the same estimates."""
    seed, steps = 3, 30
    spec = coloc_env.compose(world="gps_denied", network={"name": "broadcast", "comm_range": 300.0},
                             backend=DNBP_SMALL)
    truth, estimates, _, _, env = _run(spec, seed, steps)
    config = GpsDeniedNbpConfig(num_particles=50)
    world_rng, _, backend_rng = np.random.default_rng(seed).spawn(3)  # the composition's children of the seed
    episode = sample_episode(config.parts()[0], world_rng)
    np.testing.assert_array_equal(env.unwrapped.scenario.world.truth[0], episode.truth)
    model = env.unwrapped.scenario.backend.model
    state = dn.initial_state(model, [backend_rng], "warm", episode.init_position[None], episode.init_velocity[None],
                             config.velocity_spread)
    ones = np.ones((1, config.num_agents, config.num_iterations), bool)
    for k in range(steps):
        state, result = dn.step(model, state, episode.gps_normal[k][None], episode.gps_fix[k][None],
                                BroadcastMedium().over(episode.adjacency[k][None]), episode.ranges[k][None],
                                episode.accel[k][None], [backend_rng], ones)
        np.testing.assert_array_equal(truth[k], episode.truth[k, :, :2])
        np.testing.assert_allclose(estimates[k], result.estimate[0], rtol=0, atol=1e-9)


def test_cooperative_backends_beat_dead_reckoning_on_fault_uavs():
    """Seeded Monte Carlo, 3 seeds x 10 steps: mean position error of the GPS-fault UAVs."""
    errors = {}
    for name, backend in (("dead_reckoning", "dead_reckoning"), ("range_ls", "range_ls"), ("dnbp", DNBP_SMALL)):
        spec = coloc_env.compose(world="gps_denied", network="broadcast", backend=backend)
        per_seed = []
        for seed in range(3):
            _, _, e, fault, _ = _run(spec, seed, 10)
            per_seed.append(e[fault].mean())
        errors[name] = float(np.mean(per_seed))
    assert errors["dnbp"] < errors["dead_reckoning"], errors
    assert errors["range_ls"] < errors["dead_reckoning"], errors


@pytest.mark.parametrize("network", ["broadcast", "ideal"])
def test_the_same_seed_gives_every_backend_the_same_truth(network):
    truths = [_run(coloc_env.compose(world="gps_denied", network=network, backend=b), 5, 12)[0]
              for b in ("dead_reckoning", "range_ls", DNBP_SMALL)]
    for other in truths[1:]:
        np.testing.assert_array_equal(truths[0], other)


def test_dnbp_reports_particles_payload_and_rounds():
    spec = coloc_env.compose(world="gps_denied", network="ideal", backend=DNBP_SMALL)
    _, _, _, _, env = _run(spec, 0, 2)
    scenario = env.unwrapped.scenario
    assert scenario.network.rounds == 5
    assert scenario.backend.particles(0).shape == (10, 50, 2)
    sent = scenario.network.messages_sent[0]
    np.testing.assert_array_equal(scenario.network.floats_sent[0], sent * (3 * 50 + 1))
    cov = scenario.backend.position_cov()
    assert cov.shape == (1, 10, 2, 2) and np.all(np.linalg.eigvalsh(cov) >= 0)


def test_the_motion_model_matches_the_world_part():
    from coloc_env.worlds.blocks.cv_uav import ConstantVelocityUAVs
    from estimators.cv_models import ConstantVelocityAccel

    part, model = ConstantVelocityUAVs(1.5, 0.5, 0.3), ConstantVelocityAccel(1.5, 0.09)
    np.testing.assert_allclose(model.transition, part.transition)
    np.testing.assert_allclose(model.process_noise, part.process_noise)
    x, u = np.arange(12.0).reshape(3, 4), np.ones((3, 2))
    np.testing.assert_allclose(model.function(x, u), part.step(x, u))
