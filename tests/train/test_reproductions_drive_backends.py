"""The Monte Carlo loops of wang2019 and wan2014 drive the composable backends (issue 14 §5) and still
compute what the validated estimator code computes on the same draws.

The references here are the estimators' own functions, run on the episodes the scenarios draw from the
same generators (``relay_ukf``'s :class:`RelayUKFScenario` with ``estimators.ukf_relay``; ``gps_denied_nbp``'s
``sample_episode`` with ``estimators.range_ls.step``), so a change in the backends, the worlds or the
seeding that moved a reproduction's numbers fails here.
"""

import numpy as np
import pytest

import estimators.range_ls as rl
import estimators.ukf_relay as ukf
from agents.relay_ukf import paper_actions
from coloc_env.config import build_config
from coloc_env.scenarios.gps_denied_nbp import GpsDeniedNbpConfig, sample_episode
from coloc_env.scenarios.relay_ukf import RelayUKFConfig, RelayUKFScenario
from train.reproduce import wan2014, wang2019


def _reference_wang2019(config, copies, policy_rng):
    """Errors (3, K, runs, N) of IL, CCL and DCL by the estimator functions on the relay_ukf scenario's draws."""
    runs = len(copies)
    scenario = RelayUKFScenario(config, batch=runs)
    scenario.reset(copies)
    K, N = config.horizon, config.num_platforms
    ccl_x, ccl_P, il_x = scenario.estimate.copy(), scenario.cov.copy(), scenario.estimate.copy()
    errors = np.zeros((3, K, runs, N))
    for k in range(K):
        event = scenario.measurement_event(paper_actions(scenario.distances(), scenario.schedule[:, k], policy_rng))
        scenario.measurement_update(event)
        used = np.flatnonzero(event.used)
        if len(used):
            ccl_x[used], ccl_P[used] = ukf.ccl_update(ccl_x[used], ccl_P[used], event.measuring[used],
                                                      event.partner[used], event.range[used],
                                                      config.range_noise_var, config.ukf_lambda)
        for e, estimate in enumerate((il_x, ccl_x, scenario.estimate)):
            errors[e, k] = np.linalg.norm(estimate - scenario.truth[k], axis=-1)
        speed, heading, heading_var = scenario.odometry()
        scenario.time_update()
        ccl_x, ccl_P = ukf.time_update(ccl_x, ccl_P, speed, heading, config.dt, config.speed_noise_std**2,
                                       heading_var)
        il_x, _ = ukf.time_update(il_x, None, speed, heading, config.dt, 0.0)
    return errors


def test_wang2019_backends_give_the_estimator_functions_numbers_on_the_same_draws():
    config = build_config(RelayUKFConfig, {"horizon": 120, "measurement_probability": 0.7})
    seed, block, runs = 4, 1, 3

    def generators():
        return wang2019._block_generators(seed, block, runs)

    copies, policy_rng = generators()
    reference = _reference_wang2019(config, copies, policy_rng)
    copies, policy_rng = generators()
    result = wang2019.simulate_runs(config, copies, policy_rng)
    np.testing.assert_allclose(result["curves"], reference.mean(axis=2), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(result["per_run"], reference.mean(axis=(1, 3)), rtol=1e-12, atol=1e-12)
    assert result["max_diff"] < 1e-9
    # the runs are real: cooperation moved the estimates away from dead reckoning
    assert np.all(result["per_run"][0] > result["per_run"][2])


def test_wang2019_rig_refuses_a_layout_the_circles_world_cannot_fly():
    config = build_config(RelayUKFConfig, {"horizon": 10, "directions": (1.0, 1.0, 1.0, 1.0)})
    with pytest.raises(ValueError, match="default layout"):  # refused, not silently replaced
        wang2019.Rig(config, 1)


def test_wan2014_ls_and_dr_backends_equal_the_estimator_on_the_same_episodes():
    config = build_config(GpsDeniedNbpConfig, {"num_uavs": 8, "horizon": 12, "num_particles": 30})
    world_seeds = [[6, r] for r in range(3)]
    episodes = [sample_episode(config, np.random.default_rng(s)) for s in world_seeds]
    out = wan2014.run_methods(config, [np.random.default_rng(s) for s in world_seeds],
                              [np.random.default_rng([6, 100_000 + r]) for r in range(3)], names=("ls", "dr"))
    motion = config.motion
    stack = {name: np.stack([getattr(e, name) for e in episodes]) for name in
             ("truth", "accel", "gps_normal", "gps_fix", "adjacency", "ranges", "init_position", "init_velocity")}
    np.testing.assert_array_equal(out["fault"], ~stack["gps_normal"])
    mean = np.concatenate([stack["init_position"], stack["init_velocity"]], axis=-1)
    var = [config.gps_std**2] * 2 + [config.velocity_spread**2] * 2
    for name, cooperative in (("ls", True), ("dr", False)):
        state = rl.initial_state(mean, np.diag(var))
        for k in range(config.horizon):
            state, estimate, _ = rl.step(rl.LsParams(cooperative=cooperative), state, stack["gps_normal"][:, k],
                                         stack["gps_fix"][:, k], stack["adjacency"][:, k], stack["ranges"][:, k],
                                         stack["accel"][:, k], motion.transition, motion.input_matrix,
                                         motion.process_noise, config.gps_std, config.range_std)
            expected = np.linalg.norm(estimate - stack["truth"][:, k, :, :2], axis=-1)
            np.testing.assert_allclose(out["errors"][name][:, k], expected, rtol=1e-12, atol=1e-12)
    fault = out["fault"]
    assert out["errors"]["ls"][fault].mean() < out["errors"]["dr"][fault].mean()


def test_wan2014_counts_dnbp_messages_and_broadcasts_from_the_network():
    config = build_config(GpsDeniedNbpConfig, {"num_uavs": 6, "horizon": 3, "num_particles": 20})
    out = wan2014.run_methods(config, [np.random.default_rng([1, r]) for r in range(2)],
                              [np.random.default_rng([1, 100_000 + r]) for r in range(2)], names=("dnbp",))
    assert 0 < out["broadcasts"] <= out["messages"]
    assert out["broadcasts"] <= 2 * config.horizon * config.num_uavs * config.num_iterations
    assert out["seconds"]["dnbp"] > 0
