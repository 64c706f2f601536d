"""estimators.afge: Lemma 7 vs the recursion, fusion bound, delays, Kalman and AFGE on the
default world (docs/gao2016.md §14)."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

import estimators.afge as af
from coloc_env.config import build_config
from coloc_env.networks.blocks.bounded_delay import NEVER
from coloc_env.scenarios.nlos_horizon import NlosHorizonConfig
from coloc_env.worlds.nlos_orbit import draw_episode, in_turn

MOTION = af.MotionModel(1.0, 0.3)


def _episode(config, rng):
    """The episode the preset ``config``'s world draws from ``rng``, with one delay per packet from the world's
    packet uniforms by ``config``'s delay law (``NEVER`` where the neighbour is outside the RSA)."""
    world, network, _ = config.parts()
    ep = draw_episode(world, rng)
    delays = np.where(ep.in_rsa, network.delay.from_uniforms(ep.packet_uniforms), NEVER).astype(np.int16)
    return SimpleNamespace(truth=ep.truth, rss=ep.rss, aoa=ep.aoa, nav=ep.nav, modes=ep.modes, delays=delays,
                           prior=ep.prior)


def _fused(config, ep):
    """(Y, y, gamma) of ``ep`` by (stamp, lag) with ``config``'s fusion fields, every packet kept."""
    return af.fuse_episode(config.parts()[0].signal, ep.rss, ep.aoa, ep.nav, ep.modes, ep.delays,
                           config.buffer_length, config.n_strongest, config.mode_info, config.weighting,
                           config.min_packets)


def _motion(config):
    return config.parts()[0].motion_model.afge


def _ahg(config):
    return config.parts()[2].ahg


def random_fix(rng, scale=10.0):
    L = rng.normal(size=(2, 2))
    return rng.normal(size=2) * scale, L @ L.T + 0.3 * np.eye(2)


def recursion(fixes, motion=MOTION):
    stack = af.empty_stack((), 1)
    for s, fix in enumerate(fixes):
        if fix is None:
            Y, y, g = np.zeros((2, 2)), np.zeros(2), False
        else:
            Y = np.linalg.inv(fix[1])
            Y, y, g = Y, Y @ fix[0], True
        stack = af.stack_advance(motion, stack, Y, y, g, s, shift=False)
    return af.stack_estimates(stack)


@pytest.mark.parametrize("N, missing", [(2, ()), (3, (1,)), (7, (0, 3)), (12, (2, 5, 6, 11)), (30, (4,))])
def test_lemma7_batch_gain_equals_the_zero_information_recursion(N, missing):
    rng = np.random.default_rng(N)
    fixes = [None if i in missing else random_fix(rng) for i in range(N)]
    batch = af.dfir_batch(MOTION, fixes)
    np.testing.assert_allclose(batch["gain"] @ batch["G"], np.linalg.matrix_power(MOTION.transition, N - 1),
                               atol=1e-9)
    x, P, valid = recursion(fixes)
    assert valid[0]
    np.testing.assert_allclose(x[0], batch["estimate"], atol=1e-9, rtol=0)
    np.testing.assert_allclose(P[0], batch["cov"], atol=1e-9, rtol=0)


def test_recursion_needs_two_observed_stamps_and_batch_refuses_fewer():
    rng = np.random.default_rng(1)
    fixes = [None, random_fix(rng), None]
    _, _, valid = recursion(fixes)
    assert not valid[0]
    with pytest.raises(ValueError, match="two stamps"):
        af.dfir_batch(MOTION, fixes)


def test_stack_slot_n_is_the_horizon_of_the_last_n_stamps():
    rng = np.random.default_rng(2)
    fixes = [random_fix(rng) for _ in range(9)]
    stack = af.empty_stack((), 5)
    for s, (z, R) in enumerate(fixes):
        Y = np.linalg.inv(R)
        stack = af.stack_advance(MOTION, stack, Y, Y @ z, True, s)
    x, P, valid = af.stack_estimates(stack)
    assert not valid[0] and valid[1:].all()
    for N in range(2, 6):
        np.testing.assert_allclose(x[N - 1], af.dfir_batch(MOTION, fixes[-N:])["estimate"], atol=1e-9)


def test_distance_weighted_fusion_is_never_more_confident_than_information_fusion():
    rng = np.random.default_rng(3)
    signal = af.SignalModel()
    J = 6
    senders = rng.uniform(-800, 800, size=(50, J, 2))
    target = np.zeros(2)
    rel = target - senders
    d = np.linalg.norm(rel, axis=-1)
    rss = signal.tx_power_dbm - signal.reference_loss_db - 10 * signal.exponent * np.log10(d) + rng.normal(size=d.shape)
    aoa = np.arctan2(rel[..., 1], rel[..., 0])
    z, R, r_hat = af.packet_fixes(signal, senders, rss, aoa, np.zeros(d.shape))
    used = rng.random((50, J)) < 0.7
    used[:, 0] = True
    Yd, _, gd, _ = af.fuse_fixes(z, R, r_hat, used, "distance")
    Yi, _, gi, _ = af.fuse_fixes(z, R, r_hat, used, "information")
    assert gd.all() and gi.all()
    diff = np.linalg.inv(Yd) - np.linalg.inv(Yi)
    assert np.linalg.eigvalsh(diff).min() > -1e-9
    # weights sum to one: a single packet is fused to itself in both weightings
    one = np.zeros((50, J), bool)
    one[:, 2] = True
    Y1, y1, _, _ = af.fuse_fixes(z, R, r_hat, one, "distance")
    np.testing.assert_allclose(np.linalg.inv(Y1), R[:, 2], rtol=1e-10)
    np.testing.assert_allclose(np.linalg.solve(Y1, y1[..., None])[..., 0], z[:, 2], rtol=1e-10)


def test_nlos_correction_has_the_simulators_sign():
    """With the true mode the NLOS bias is removed: the corrected range is unbiased (in dB)."""
    signal = af.SignalModel()
    d = 400.0
    mean_rss = signal.tx_power_dbm - signal.reference_loss_db - 10 * signal.exponent * np.log10(d)
    nlos_rss = mean_rss - signal.nlos_bias_db  # NLOS weakens the signal
    _, _, r_known = af.packet_fixes(signal, np.zeros(2), nlos_rss, 0.0, 1.0)
    _, _, r_blind = af.packet_fixes(signal, np.zeros(2), nlos_rss, 0.0, 0.0)
    assert r_known == pytest.approx(d, rel=1e-12)
    assert r_blind > d * 1.5  # uncorrected, the range is too long
    _, R_known, _ = af.packet_fixes(signal, np.zeros(2), nlos_rss, 0.0, 1.0)
    _, R_los, _ = af.packet_fixes(signal, np.zeros(2), mean_rss, 0.0, 0.0)
    assert np.trace(R_known) > np.trace(R_los)  # the NLOS spread is added


def _single_packet_episode(config, stamp, tau):
    ep = _episode(config, np.random.default_rng(0))
    delays = np.full(ep.delays.shape, NEVER, np.int16)
    delays[stamp, 0, 3] = tau
    ep.delays = delays
    return ep


@pytest.mark.parametrize("tau", [0, 2, 3, 4])
def test_a_packet_counts_once_at_its_own_stamp_and_never_past_the_buffer(tau):
    config = build_config(NlosHorizonConfig, {"num_agents": 1, "horizon": 20})
    Y, y, gamma = _fused(config, _single_packet_episode(config, 7, tau))
    D = config.buffer_length
    expected = np.zeros(gamma.shape, bool)
    if tau <= D:
        expected[0, 7, tau:] = True
    np.testing.assert_array_equal(gamma, expected)
    # run over time: the packet's information enters the horizon filters exactly once
    motion = _motion(config)
    final = af.empty_stack((1,), 3)
    for k in range(gamma.shape[1] - 1):
        Yb, yb, gb, _ = af.buffer_observations(Y, y, gamma, k)
        final, current = af.buffer_step(motion, final, k, Yb, yb, gb)
        assert current.stamps.max() == int(tau <= D and 7 + tau <= k <= 7 + 2)


def test_buffer_rerun_equals_filtering_every_stamp_once_with_what_is_known():
    config = build_config(NlosHorizonConfig, {"num_agents": 1, "horizon": 40, "delay_probs": (0.3, 0.3, 0.2, 0.1)})
    ep = _episode(config, np.random.default_rng(5))
    Y, y, gamma = _fused(config, ep)
    D, S = config.buffer_length, 6
    final = af.empty_stack((1,), S)
    for k in range(30):
        Yb, yb, gb, _ = af.buffer_observations(Y, y, gamma, k)
        final, current = af.buffer_step(_motion(config), final, k, Yb, yb, gb)
    fresh = af.empty_stack((1,), S)
    for s in range(30):
        lag = min(29 - s, D)
        fresh = af.stack_advance(_motion(config), fresh, Y[:, s, lag], y[:, s, lag], gamma[:, s, lag], s)
    np.testing.assert_allclose(current.info, fresh.info, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(current.vector, fresh.vector, rtol=1e-12, atol=1e-9)


def test_without_delay_the_buffer_rerun_changes_nothing():
    config = build_config(NlosHorizonConfig, {"num_agents": 1, "horizon": 120, "buffer_length": 0,
                                              "delay_probs": (1.0,)})
    ep = _episode(config, np.random.default_rng(6))
    Y, y, g = _fused(config, ep)
    truth = np.moveaxis(ep.truth[:, :, :2], 0, 1)
    tile = lambda a: np.repeat(a, 4, axis=2)  # noqa: E731 - D = 3 buffer holding the same observations
    direct = af.run_fixed_mask(_motion(config), Y, y, g, truth, ep.prior, _ahg(config), 30)
    buffered = af.run_fixed_mask(_motion(config), tile(Y), tile(y), tile(g), truth, ep.prior, _ahg(config), 30)
    for key in ("dfir", "afge_predictive"):
        np.testing.assert_allclose(buffered[key], direct[key], rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(buffered["afge_predictive_horizon"], direct["afge_predictive_horizon"])


def test_ahg_group_selection_and_centre_rules():
    params = af.AHGParams()
    np.testing.assert_array_equal(af.ahg_group(params, np.array([12, 8, 26])),
                                  [[8, 10, 12, 14, 16], [4, 6, 8, 10, 12], [22, 24, 26, 28, 30]])
    costs = np.full((1, 30), 10.0)
    costs[0, 15] = 1.0  # N = 16 best in the group of 12
    costs[0, 29] = 0.0  # N = 30 outside the group: ignored
    valid = np.ones((1, 30), bool)
    chosen, centre = af.ahg_select(params, np.array([12]), costs, valid, np.array([True]))
    assert chosen[0] == 16 and centre[0] == 16
    chosen, centre = af.ahg_select(params, np.array([26]), np.where(np.arange(30) == 29, 0.0, 5.0)[None], valid,
                                   np.array([True]))
    assert chosen[0] == 30 and centre[0] == 26  # clipped to N_max - h dN
    # no fresh observation: the centre's estimate, centre kept
    chosen, centre = af.ahg_select(params, np.array([12]), costs, valid, np.array([False]))
    assert chosen[0] == 12 and centre[0] == 12
    # the centre without an estimate: the largest valid member; none valid: 0 (predict)
    valid2 = valid.copy()
    valid2[0, 11:] = False
    chosen, _ = af.ahg_select(params, np.array([12]), costs, valid2, np.array([False]))
    assert chosen[0] == 10
    chosen, centre = af.ahg_select(params, np.array([12]), costs, np.zeros((1, 30), bool), np.array([True]))
    assert chosen[0] == 0 and centre[0] == 12


def test_smoothed_costs_forget_exponentially_and_correct_the_start_bias():
    raw, count = np.zeros(2), np.zeros(2, np.int64)
    raw, count, c1 = af.smooth_costs(raw, count, np.array([4.0, np.inf]), 0.8)
    assert c1[0] == pytest.approx(4.0) and np.isinf(c1[1])
    raw, count, c2 = af.smooth_costs(raw, count, np.array([2.0, 3.0]), 0.8)
    assert c2[0] == pytest.approx((0.8 * 0.2 * 4 + 0.2 * 2) / (1 - 0.64))
    assert c2[1] == pytest.approx(3.0) and count.tolist() == [2, 1]


def test_seeded_monte_carlo_oracle_kf_beats_blind_kf():
    """sigma_a = 1 m/s^2 (matched to the turns), pi = 0.3: knowing the mode lowers the error."""
    config = build_config(NlosHorizonConfig, {"num_agents": 1, "horizon": 300})
    runs = 6
    eps = [_episode(config, np.random.default_rng([2016, r])) for r in range(runs)]
    fused = [_fused(dataclasses.replace(config, mode_info=mode), ep)
             for mode in ("known", "blind") for ep in eps]
    cat = lambda i: np.concatenate([f[i] for f in fused])[:, :300]  # noqa: E731
    truth = np.concatenate([np.moveaxis(ep.truth[:300, :, :2], 0, 1) for ep in eps] * 2)
    prior = np.concatenate([ep.prior for ep in eps] * 2)
    err = af.run_kalman(_motion(config), cat(0), cat(1), cat(2), truth, prior, config.parts()[0].prior_cov,
                         accel_var=1.0)
    mse = err[:, 50:].mean(axis=1)
    diffs = mse[:runs] - mse[runs:]
    assert diffs.mean() + 2 * diffs.std(ddof=1) / np.sqrt(runs) < 0


@pytest.fixture(scope="module")
def default_world_runs():
    """Three full default episodes (1000 s, turns included), DFIR for every N and AFGE."""
    config = build_config(NlosHorizonConfig, {"num_agents": 1})
    eps = [_episode(config, np.random.default_rng([7, r])) for r in range(3)]
    fused = [_fused(config, ep) for ep in eps]
    K = config.horizon
    cat = lambda i: np.concatenate([f[i] for f in fused])[:, :K]  # noqa: E731
    truth = np.concatenate([np.moveaxis(ep.truth[:K, :, :2], 0, 1) for ep in eps])
    prior = np.concatenate([ep.prior for ep in eps])
    return config, af.run_fixed_mask(_motion(config), cat(0), cat(1), cat(2), truth, prior, _ahg(config), 30)


def test_dfir_rmse_vs_horizon_has_an_interior_minimum(default_world_runs):
    _, out = default_world_runs
    rmse = np.sqrt(out["dfir"][:, 50:].mean(axis=(0, 1)))[1:]  # N = 2..30
    best = int(np.argmin(rmse)) + 2
    assert 2 < best < 30
    assert rmse[0] > 1.2 * rmse.min() and rmse[-1] > 1.2 * rmse.min()


def test_afge_horizon_is_shorter_in_turns_than_on_straight_legs(default_world_runs):
    config, out = default_world_runs
    h = out["afge_predictive_horizon"][:, 50:]
    turning = in_turn(config.parts()[0], config.horizon)[50:, 0]
    chosen = h > 0
    in_turns = h[chosen & turning].mean()
    straight = h[chosen & ~turning].mean()
    assert in_turns + 2 < straight
