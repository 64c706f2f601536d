"""``coloc evaluate``'s paper-policy error equals each reproduction's number on the same seeds.

The env side is :func:`train.evaluate.run_episodes` with the ``paper`` policy on the
evaluation seeds ``EVAL_SEED_BASE + e``. The reproduction side is each paper module's
``paper_policy_costs``: the same episodes (drawn by the preset's world from
``default_rng(seed)``, as ``env.reset(seed=...)`` draws them), run through the
reproduction's Monte Carlo code (batched, not the env's step). The two paths sum or average
in different orders and batch differently, so the numbers agree to rounding (1e-9
relative), not bit for bit. Where a reproduction drives the same backends as the env, the
second test also checks the env against the estimator functions run without the core.

Shorter episodes than the papers' where a default episode is slow; both sides get the
same config.
"""

import importlib

import numpy as np
import pytest

import coloc_env
from coloc_env.config import build_config
from train.evaluate import EVAL_SEED_BASE, run_episodes

# scenario -> (reproduction, episodes, config overrides for both sides)
CASES = {
    "bandwidth_fusion": ("zhao2020", 4, {}),
    "lossy_fusion": ("fu2017", 2, {}),
    "relay_ukf": ("wang2019", 2, {"horizon": 200}),
    "nlos_horizon": ("gao2016", 2, {"horizon": 300, "num_agents": 2}),
    "gps_denied_nbp": ("wan2014", 2, {"horizon": 10, "num_particles": 50}),
}


@pytest.mark.parametrize("scenario", list(CASES))
def test_evaluate_paper_policy_equals_the_reproduction_on_the_same_seeds(scenario):
    key, episodes, overrides = CASES[scenario]
    reproduction = importlib.import_module(f"train.reproduce.{key}")
    config = build_config(coloc_env.scenario_class(scenario).Config, overrides)
    seeds = [EVAL_SEED_BASE + e for e in range(episodes)]

    env = run_episodes(scenario, "paper", episodes, seed_base=EVAL_SEED_BASE, **overrides)
    costs = reproduction.paper_policy_costs(seeds, config)

    assert costs.shape == (episodes,)
    assert np.all(costs > 0) and len(set(costs.tolist())) == episodes  # real, distinct episodes
    assert env["mean_cost"] == pytest.approx(costs.mean(), rel=1e-9, abs=0)
    # The part of the paper's cost an episode does not contain: bandwidth_fusion's k = 0 term,
    # here from the reproduction's exact covariance, against the env's initial_cost.
    initial = reproduction.initial_term(config) if scenario == "bandwidth_fusion" else 0.0
    assert env["paper_cost"] == pytest.approx(costs.mean() + initial, rel=1e-9, abs=0)


def _wang2019_by_the_estimator_functions(seeds, config) -> np.ndarray:
    """Per-episode paper metric of UKF-DCL from ``estimators.ukf_relay`` on chains resolved by
    :class:`coloc_env.networks.blocks.relay_chain.RelayChainLinks` (the paper scenario's own delivery code): no backend,
    no network, no env. The paper policy's partners in episode e come from ``episode_generator(seeds[e])``,
    as ``coloc evaluate`` seeds it."""
    from agents.base import episode_generator
    from tests.train.test_reproductions_drive_backends import _reference_wang2019

    dcl = 2  # rows IL, CCL, DCL
    return np.array([_reference_wang2019(config, [np.random.default_rng(s)], episode_generator(s))[dcl].mean()
                     for s in seeds])


def _wan2014_by_the_estimator_function(seeds, config) -> np.ndarray:
    """Per-episode fault-UAV error of :func:`estimators.dnbp.step` over the paper scenario's broadcast medium
    on ``sample_episode``'s draws (all broadcasts the schedule allows), with the dNBP parameters written out
    (the defensive box covers the whole flight): no backend, no network, no env."""
    import estimators.dnbp as dn
    from coloc_env.networks.blocks.broadcast_medium import BroadcastMedium
    from coloc_env.worlds.gps_denied import sample_episode

    travel, m = float(np.linalg.norm(config.nominal_velocity)) * config.dt * config.horizon, config.box_margin
    model = dn.DnbpModel(
        dt=config.dt, accel_noise_std=config.accel_noise_std, gps_std=config.gps_std, range_std=config.range_std,
        num_particles=config.num_particles, num_iterations=config.num_iterations, oversampling=config.oversampling,
        defensive_weight=config.defensive_weight, defensive_box=(-m, config.area + m + travel),
        cold_box=(-m, config.area + m), min_bandwidth=config.min_bandwidth,
        initial_threshold=config.initial_threshold, schedule=config.schedule, kernel=config.kernel,
        truncation=config.truncation)
    costs = []
    for s in seeds:
        rng = np.random.default_rng(s)
        episode = sample_episode(config.parts()[0], rng)
        estimator_rng = rng.spawn(1)[0]
        state = dn.initial_state(model, [estimator_rng], "warm", episode.init_position[None],
                                 episode.init_velocity[None], config.velocity_spread)
        errors, fault = [], []
        ones = np.ones((1, config.num_agents, config.num_iterations), bool)
        for k in range(config.horizon):
            state, result = dn.step(model, state, episode.gps_normal[k][None], episode.gps_fix[k][None],
                                    BroadcastMedium().over(episode.adjacency[k][None]), episode.ranges[k][None],
                                    episode.accel[k][None], [estimator_rng], ones)
            errors.append(np.linalg.norm(result.estimate[0] - episode.truth[k, :, :2], axis=-1))
            fault.append(~episode.gps_normal[k])
        errors, fault = np.array(errors), np.array(fault)
        costs.append(float(errors[fault].mean()) if fault.any() else 0.0)
    return np.array(costs)


def _zhao2020_by_the_estimator_functions(seeds, config) -> np.ndarray:
    """J_K without its k = 0 term of :func:`estimators.bandwidth_fusion.step` under T1P1 on ``draw_episode``'s
    draws: no backend, no network, no env."""
    from tests.train.test_reproductions_drive_backends import _reference_zhao2020

    errors = _reference_zhao2020(config, "T1P1", [np.random.default_rng(s) for s in seeds])
    return errors[1:].sum(axis=(0, 2))


def _fu2017_by_the_estimator_functions(seeds, config) -> np.ndarray:
    """Per-episode MSE of (B) as printed, :func:`estimators.lossy_fusion.distributed_filter`, on
    the world's truth and measurements and the network's link outcomes: no backend, no env."""
    from tests.train.test_reproductions_drive_backends import _reference_fu2017

    return _reference_fu2017(config, seeds)["distributed"][0].mean(axis=1)


INDEPENDENT = {"relay_ukf": _wang2019_by_the_estimator_functions, "gps_denied_nbp": _wan2014_by_the_estimator_function,
               "bandwidth_fusion": _zhao2020_by_the_estimator_functions,
               "lossy_fusion": _fu2017_by_the_estimator_functions}


@pytest.mark.parametrize("scenario", list(INDEPENDENT))
def test_evaluate_paper_policy_equals_an_independent_estimator_path(scenario):
    """Every preset here is a binding on the core and its reproduction drives the same backends, so the test
    above is nearly circular for them: here the reference is the estimator functions on the scenario's draws,
    without the composable core."""
    _, episodes, overrides = CASES[scenario]
    config = build_config(coloc_env.scenario_class(scenario).Config, overrides)
    seeds = [EVAL_SEED_BASE + e for e in range(episodes)]
    env = run_episodes(scenario, "paper", episodes, seed_base=EVAL_SEED_BASE, **overrides)
    reference = INDEPENDENT[scenario](seeds, config)
    assert np.all(reference > 0) and len(set(reference.tolist())) == episodes
    assert env["mean_cost"] == pytest.approx(reference.mean(), rel=1e-9, abs=0)
