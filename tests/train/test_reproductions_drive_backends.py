"""The Monte Carlo loops of wang2019, wan2014, zhao2020, fu2017 and gao2016 drive the composable backends and still
compute what the validated estimator code computes on the same draws.

The references here are the estimators' own functions, run on the episodes the scenarios draw from the
same generators (``relay_ukf``'s draws and relay rules,
:class:`coloc_env.networks.blocks.relay_chain.RelayChainLinks`, with
``estimators.ukf_relay``; the ``gps_denied`` world's
``sample_episode`` with ``estimators.range_ls.step``; the ``drift`` world's ``draw_episode`` with
``estimators.bandwidth_fusion.step``; the ``target_cv`` world's episodes and the ``bernoulli_delay`` network's
link outcomes with ``estimators.lossy_fusion``'s filters), so a change in the backends, the worlds or the
seeding that moved a reproduction's numbers fails here.
"""

import dataclasses

import numpy as np

import estimators.bandwidth_fusion as bf
import estimators.lossy_fusion as lf
import estimators.range_ls as rl
import estimators.ukf_relay as ukf
from agents.relay_ukf import paper_actions
from coloc_env.backends.fusion import lossy_model
from coloc_env.config import build_config
from coloc_env.scenarios.bandwidth_fusion import BandwidthFusionConfig
from coloc_env.scenarios.gps_denied_nbp import GpsDeniedNbpConfig
from coloc_env.scenarios.lossy_fusion import LossyFusionConfig
from coloc_env.scenarios.nlos_horizon import NlosHorizonConfig
from coloc_env.scenarios.relay_ukf import RelayUKFConfig
from coloc_env.worlds.blocks.unicycle import UnicycleMotion
from coloc_env.worlds.drift import draw_episode
from coloc_env.worlds.gps_denied import sample_episode
from estimators.bandwidth_fusion import paper_selection, paper_weights
from train.reproduce import fu2017, gao2016, wan2014, wang2019, zhao2020


def _reference_wang2019(config, copies, policy_rng):
    """Errors (3, K, runs, N) of IL, CCL and DCL by the estimator functions on the episodes drawn from
    ``copies`` in the relay_ukf scenario's order (odometry noise, schedule, range noise), with the chains
    resolved by :class:`coloc_env.networks.blocks.relay_chain.RelayChainLinks` (the paper scenario's own delivery code,
    not the network the backends ask)."""
    runs, K, N, dt = len(copies), config.horizon, config.num_agents, config.dt
    world, network, _ = config.parts()
    truth, true_heading, true_speed, true_turn = world.tracks.trajectory(K)
    odometry, range_sensor, links = world.odometry, world.range_sensor, network.links
    speed, turn = np.empty((runs, K, N)), np.empty((runs, K, N))
    schedule, noise = np.empty((runs, K), dtype=int), np.empty((runs, K))
    for c, rng in enumerate(copies):
        speed_noise, turn_noise = odometry.sample_noise(rng, (K, N))
        occurs, who = rng.random(K), rng.integers(0, N, size=K)
        noise[c] = range_sensor.sample_noise(rng, (K,))
        speed[c], turn[c] = odometry.measure(true_speed, true_turn, speed_noise, turn_noise)
        schedule[c] = np.where(occurs < config.measurement_probability, who, -1)
    heading = np.swapaxes(UnicycleMotion(dt).headings(true_heading[0][None, :], np.swapaxes(turn, 1, 2)), 1, 2)
    rows = np.arange(runs)
    dcl_x = np.broadcast_to(truth[0], (runs, N, 2)).copy()
    dcl_P = np.broadcast_to(config.initial_position_std**2 * np.eye(2 * N), (runs, 2 * N, 2 * N)).copy()
    ccl_x, ccl_P, il_x = dcl_x.copy(), dcl_P.copy(), dcl_x.copy()
    errors = np.zeros((3, K, runs, N))
    for k in range(K):
        positions = np.broadcast_to(truth[k], (runs, N, 2))
        distances = np.linalg.norm(positions[:, :, None] - positions[:, None], axis=-1)
        actions = paper_actions(distances, schedule[:, k], policy_rng)
        measuring = schedule[:, k]
        source = np.maximum(measuring, 0)
        partner = np.where(measuring >= 0, actions[rows, source, 0], source)
        relay = links.resolve(positions, source, partner, actions[..., 1], np.zeros((runs, N - 1)))
        used = np.flatnonzero((measuring >= 0) & (partner != source) & (relay.length >= 2))
        if len(used):
            z = range_sensor.measure(positions[used, source[used]], positions[used, partner[used]], noise[used, k])
            dcl_x[used], dcl_P[used] = ukf.dcl_update(dcl_x[used], dcl_P[used], relay.chain[used],
                                                      relay.length[used], z, config.range_noise_var,
                                                      config.ukf_lambda, config.truncation)
            ccl_x[used], ccl_P[used] = ukf.ccl_update(ccl_x[used], ccl_P[used], source[used], partner[used], z,
                                                      config.range_noise_var, config.ukf_lambda)
        for e, estimate in enumerate((il_x, ccl_x, dcl_x)):
            errors[e, k] = np.linalg.norm(estimate - truth[k], axis=-1)
        heading_var = odometry.heading_variance(np.full(runs, k), dt)[:, None]
        q = config.speed_noise_std**2
        dcl_x, dcl_P = ukf.time_update(dcl_x, dcl_P, speed[:, k], heading[:, k], dt, q, heading_var)
        ccl_x, ccl_P = ukf.time_update(ccl_x, ccl_P, speed[:, k], heading[:, k], dt, q, heading_var)
        il_x, _ = ukf.time_update(il_x, None, speed[:, k], heading[:, k], dt, 0.0)
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


def test_wang2019_rig_flies_the_configured_layout_and_matches_the_reference_on_it():
    directions = (1.0, 1.0, 1.0, 1.0)  # not the paper's (platform 1 flies clockwise there)
    config = build_config(RelayUKFConfig, {"horizon": 40, "directions": directions, "measurement_probability": 0.8})
    rig = wang2019.Rig(config, 1)
    np.testing.assert_array_equal(rig.world.truth, config.parts()[0].tracks.trajectory(40)[0])
    paper_layout = build_config(RelayUKFConfig, {"horizon": 40}).parts()[0].tracks.trajectory(40)[0]
    assert not np.array_equal(rig.world.truth, paper_layout)
    copies, policy_rng = wang2019._block_generators(2, 0, 2)
    reference = _reference_wang2019(config, copies, policy_rng)
    copies, policy_rng = wang2019._block_generators(2, 0, 2)
    result = wang2019.simulate_runs(config, copies, policy_rng)
    np.testing.assert_allclose(result["curves"], reference.mean(axis=2), rtol=1e-12, atol=1e-12)


def test_wan2014_ls_and_dr_backends_equal_the_estimator_on_the_same_episodes():
    config = build_config(GpsDeniedNbpConfig, {"num_agents": 8, "horizon": 12, "num_particles": 30})
    world_seeds = [[6, r] for r in range(3)]
    episodes = [sample_episode(config.parts()[0], np.random.default_rng(s)) for s in world_seeds]
    out = wan2014.run_methods(config, [np.random.default_rng(s) for s in world_seeds],
                              [np.random.default_rng([6, 100_000 + r]) for r in range(3)], names=("ls", "dr"))
    motion = config.parts()[0].motion
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
    config = build_config(GpsDeniedNbpConfig, {"num_agents": 6, "horizon": 3, "num_particles": 20})
    out = wan2014.run_methods(config, [np.random.default_rng([1, r]) for r in range(2)],
                              [np.random.default_rng([1, 100_000 + r]) for r in range(2)], names=("dnbp",))
    assert 0 < out["broadcasts"] <= out["messages"]
    assert out["broadcasts"] <= 2 * config.horizon * config.num_agents * config.num_iterations
    assert out["seconds"]["dnbp"] > 0


def _reference_zhao2020(config, pair, generators):
    """Squared errors (K+1, runs, N) of :func:`estimators.bandwidth_fusion.step` under the tables ``pair`` on the
    episodes :func:`~coloc_env.worlds.drift.draw_episode` draws from ``generators`` (the world's sampler, in its
    order): the truth recursion x(k+1) = A x(k) + B + w(k) and y_j = C x + v_j written out."""
    model = config.fusion_model()
    episodes = [draw_episode(config.parts()[0], rng) for rng in generators]
    x = np.stack([e["initial_state"] for e in episodes])
    w = np.stack([e["process_noise"] for e in episodes], axis=1)
    v = np.stack([e["measurement_noise"] for e in episodes], axis=1)
    selection, weights = paper_selection(pair[:2]), paper_weights(pair[2:])
    state = bf.initial_state(model, np.asarray(config.initial_state, float), np.asarray(config.initial_cov, float),
                             (len(episodes),))
    errors = [np.sum((state.estimate - x[:, None]) ** 2, axis=-1)]
    for k in range(config.horizon):
        state = bf.step(model, state, x[:, None] @ model.measurement.T + v[k], selection, weights)
        x = x @ model.transition.T + model.drift + w[k]
        errors.append(np.sum((state.estimate - x[:, None]) ** 2, axis=-1))
    return np.stack(errors)


def test_zhao2020_preset_gives_the_estimator_functions_numbers_on_the_same_draws():
    config = build_config(BandwidthFusionConfig, {"horizon": 12})
    seed, runs = 5, 4
    blocks = {pair: zhao2020.monte_carlo_block(pair, runs, seed, config) for pair in ("T1P1", "T2P3")}
    for pair, block in blocks.items():
        reference = _reference_zhao2020(config, pair, zhao2020.episode_generators(seed, runs))
        np.testing.assert_allclose(block["per_run_cost"], reference.sum(axis=(0, 2)), rtol=1e-12, atol=0)
        np.testing.assert_allclose(block["mean_curve"], reference.sum(axis=2).mean(axis=1), rtol=1e-12, atol=0)
    # the runs are real and paired: the same episodes, other estimates under other tables
    assert not np.allclose(blocks["T1P1"]["per_run_cost"], blocks["T2P3"]["per_run_cost"])
    np.testing.assert_array_equal(blocks["T1P1"]["example_truth"], blocks["T2P3"]["example_truth"])


def _reference_fu2017(config, seeds):
    """Every filter of the reproduction by :mod:`estimators.lossy_fusion`'s own episode functions on the truth and
    measurements the preset's ``target_cv`` world draws from ``default_rng(seed)`` and the link outcomes of a
    ``bernoulli_delay`` network reset with that generator's first child (the preset's rule), without a backend:
    name -> (squared position errors (runs, K), own traces)."""
    K, copies = config.horizon, np.arange(len(seeds))
    world_config, network_config, _ = config.parts()
    world = world_config.build(len(seeds), K)
    world.reset([np.random.default_rng(s) for s in seeds], copies)
    truth, z = world.truth[:, :K], world.observations
    network = network_config.build(world.num_agents, len(seeds), "packets")
    network.reset([np.random.default_rng(s).spawn(2)[0] for s in seeds], copies)
    outcome = network.slot_outcomes(range(K))[:, :, :, 0].copy()  # each agent's link to the leader
    outcome[..., 0] = lf.ON_TIME
    model, H = lossy_model(world, network), world.metric
    x0, P0 = np.asarray(config.initial_state, float), np.asarray(config.initial_cov, float)
    runs = lf.run_filters(model, x0, P0, z, outcome)
    for name, (reading, spread, _) in fu2017.READINGS.items():
        runs[name] = lf.distributed_filter(model, x0, P0, z, outcome, reading, spread)
    y = lf.received_measurements(z, outcome, H @ x0)
    runs["centralized_printed_moments"] = lf.centralized_filter(model, x0, P0, y, "paper", "printed")
    return {name: (np.sum(((estimates - truth) @ H.T) ** 2, axis=-1), np.trace(H @ cov @ H.T, axis1=-2, axis2=-1))
            for name, (estimates, cov) in runs.items()}


def test_fu2017_compositions_give_the_estimator_filters_numbers_on_the_same_draws():
    config = build_config(LossyFusionConfig, {"num_agents": 3, "horizon": 30})
    block = fu2017.monte_carlo_block(3, 3, 4, 1, config)
    reference = _reference_fu2017(config, fu2017.block_seeds(3, 3, 4, 1))
    assert set(block["errors"]) == set(reference) == {*lf.FILTERS, *fu2017.DIAGNOSTICS}
    for name, (errors, own) in reference.items():
        np.testing.assert_allclose(block["errors"][name], errors, rtol=1e-9, atol=1e-9, err_msg=name)
        np.testing.assert_allclose(np.broadcast_to(block["own"][name], own.shape), own, rtol=1e-9, atol=1e-9,
                                   err_msg=name)
    # the runs are real and paired: every link outcome occurs, and the filters differ on the same episodes
    assert np.all(block["delivered"] > 0.1)
    assert block["errors"]["ideal_kf"].mean() < block["errors"]["informed_kf"].mean() < block["errors"][
        "naive_kf"].mean()


def _reference_gao2016(config, index, generators, mode_info="known", lag0=False, accel_sigma=None):
    """DFIR of every horizon, AFGE with each likelihood and the delay-aware KF by :mod:`estimators.afge`'s
    episode functions (``run_fixed_mask``, ``run_kalman``) on the fused packets of the episodes the
    ``nlos_horizon`` scenario of sweep setting ``index`` draws from ``generators``, with its network's delays
    (``lag0``: every late packet dropped): squared errors of target 0."""
    import estimators.afge as af
    from coloc_env.backends.nlos import episode_delays
    from coloc_env.networks.blocks.bounded_delay import NEVER
    from coloc_env.scenarios.nlos_horizon import NlosHorizonScenario

    cfg = dataclasses.replace(gao2016._setting_config(config, index), mode_info=mode_info)
    core = NlosHorizonScenario(cfg, batch=len(generators))
    core.reset(generators)
    world, afge = core.world, core.backend.config
    delays = episode_delays(world, core.network, afge.payload)
    keep = (delays == 0) if lag0 else (delays >= 0)
    delays = np.where(keep, delays, NEVER).astype(np.int16)
    parts = [af.fuse_episode(world.signal, world.rss[b], world.aoa[b], world.nav[b], world.modes[b], delays[b],
                             cfg.buffer_length, afge.n_strongest, afge.mode_info, afge.weighting, afge.min_packets)
             for b in range(len(generators))]
    K = cfg.horizon
    Y, y, g = (np.concatenate([p[n] for p in parts])[:, :K] for n in range(3))
    truth = np.moveaxis(world.truth[:, :K, :, :2], 1, 2).reshape(-1, K, 2)
    prior = world.prior.reshape(-1, 4)
    motion = world.motion_model.afge
    out = af.run_fixed_mask(motion, Y, y, g, truth, prior, afge.ahg, max(gao2016.HORIZONS),
                            ("predictive", "paper", "smoothed"))
    accel_var = None if accel_sigma is None else accel_sigma**2
    out["kf"] = af.run_kalman(motion, Y, y, g, truth, prior, world.prior_cov, accel_var=accel_var)
    return out


def test_gao2016_compositions_give_the_estimator_functions_numbers_on_the_same_draws():
    config = dataclasses.replace(build_config(NlosHorizonConfig, {"horizon": 60}), num_agents=1)
    seed, runs = 2016, (0, 1)
    block = gao2016.monte_carlo_block(config, seed, runs)

    def close(got, want, what):
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9, err_msg=what)

    for label, index, mode_info, lag0 in gao2016.VARIANTS:
        generators = [np.random.default_rng([seed + index, r]) for r in runs]
        ref = _reference_gao2016(config, index, generators, mode_info, lag0)
        close(block["afge"][label], ref["afge_predictive"], label)
        close(block["dfir"][label], ref["dfir"], label)
        close(block["kf"][label], ref["kf"], label)
        if label in block["afge_smoothed"]:
            close(block["afge_smoothed"][label], ref["afge_smoothed"], label)
        if label == "known":
            close(block["afge_paper"][label], ref["afge_paper"], label)
            np.testing.assert_array_equal(block["afge_horizon"], ref["afge_predictive_horizon"])
        if label in block["kf_matched"]:
            generators = [np.random.default_rng([seed + index, r]) for r in runs]
            matched = _reference_gao2016(config, index, generators, mode_info, lag0, gao2016.MATCHED_ACCEL_SIGMA)
            close(block["kf_matched"][label], matched["kf"], label)
    assert set(block["kf_matched"]) == {"known", "blind"}
    # a run's numbers do not depend on the block it runs in (the executor's tasks)
    alone = gao2016.monte_carlo_block(config, seed, runs[1:])
    for name in ("afge", "dfir", "kf", "afge_smoothed"):
        for label, values in alone[name].items():
            np.testing.assert_array_equal(values, block[name][label][1:], err_msg=f"{name} {label}")
    # the runs are real and paired: AFGE beats the constant horizon 2 and knowing the modes helps it
    assert block["afge"]["known"].mean() < block["dfir"]["known"][..., 1].mean()
    assert block["afge"]["known"].mean() < block["afge"]["blind"].mean()
