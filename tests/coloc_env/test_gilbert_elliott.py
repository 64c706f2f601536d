"""The ``gilbert_elliott`` network: its seeded loss statistics match the module's closed forms, with no bad state it
is ``broadcast`` message for message, its link states are a function of (key, link, step) whatever calls or resets
happen, its acknowledgements reach the sender one step later, and its ranges are enforced."""

from __future__ import annotations

import numpy as np
import pytest

import coloc_env
from coloc_env.networks import GilbertElliott
from coloc_env.scenarios.composed import ComposedScenario


def _losses(config, B=8, N=5, K=1200, seed=0, rounds=1):
    """Every link's loss sequence (K, B, N, N - 1) over K steps with every agent in mutual range broadcasting once
    per step, the link states (K, B, N, N - 1), and the network's per-link counts summed over the steps."""
    net = config.build(N, B, "broadcast", rounds)
    net.reset([np.random.default_rng([seed, b]) for b in range(B)], np.arange(B))
    positions = np.broadcast_to(np.stack([np.arange(N) * 10.0, np.zeros(N)], axis=-1), (B, N, 2))
    decisions = np.ones((B, N, rounds), np.int64)
    off = ~np.eye(N, dtype=bool)
    lost, bad = [], []
    counts = np.zeros((3, B, N))
    for k in range(K):
        net.begin(np.full(B, k), positions, decisions)
        delivered = net.broadcast(np.ones((B, N), bool), np.ones((B, N, N), bool), 1.0, slot=0)
        lost.append(~delivered[:, off].reshape(B, N, N - 1))
        bad.append(net.link_bad()[:, off].reshape(B, N, N - 1))
        counts += [net.transmissions, net.link_attempts, net.link_deliveries]
    return np.array(lost), np.array(bad), counts


def _per_link(lost: np.ndarray) -> dict[str, np.ndarray]:
    """Each link's loss rate, lag-1 correlation and mean run of consecutive losses (independent links: their
    spread gives the standard error)."""
    x = lost.reshape(len(lost), -1).astype(float)
    rate = x.mean(axis=0)
    c = x - rate
    corr = (c[1:] * c[:-1]).mean(axis=0) / np.maximum(c.var(axis=0), 1e-300)
    runs = (x[:-1] * (1 - x[1:])).sum(axis=0) + x[-1]  # run ends
    return {"loss_rate": rate, "correlation": corr, "loss_run": x.sum(axis=0) / np.maximum(runs, 1)}


def _sojourns(bad: np.ndarray) -> float:
    """The mean length of the bad-state runs of every link (K, ...) pooled."""
    x = bad.reshape(len(bad), -1).astype(int)
    return x.sum() / ((x[:-1] * (1 - x[1:])).sum() + x[-1].sum())


def _within(values: np.ndarray, expected: float, sigmas: float = 3.0) -> None:
    se = values.std(ddof=1) / np.sqrt(values.size)
    assert abs(values.mean() - expected) <= sigmas * se, (values.mean(), expected, se)


@pytest.mark.parametrize("fields", [dict(loss_good=0.1, loss_bad=0.7, p_good_to_bad=0.1, p_bad_to_good=0.3),
                                    dict(loss_good=0.0, loss_bad=1.0, p_good_to_bad=0.05, p_bad_to_good=0.25)])
def test_loss_rate_burst_and_lag_correlation_match_the_closed_forms(fields):
    config = GilbertElliott(comm_range=500.0, **fields)
    form = config.closed_forms()
    lost, bad, (transmissions, attempts, deliveries) = _losses(config)
    stats = _per_link(lost)
    for name in ("loss_rate", "correlation", "loss_run"):
        _within(stats[name], form[name])
    assert form["correlation"] > 0.2  # bursty: the check could fail for an i.i.d. channel
    # the bad state's sojourns: geometric with mean 1 / p_bad_to_good
    runs = np.array([_sojourns(bad[:, b]) for b in range(bad.shape[1])])
    _within(runs, form["burst"])
    if fields["loss_good"] == 0 and fields["loss_bad"] == 1:
        assert form["loss_run"] == pytest.approx(form["burst"])
    # the accounting reads the same rate: link_deliveries / link_attempts = 1 - L
    K, _B, N = lost.shape[0], lost.shape[1], lost.shape[2]
    np.testing.assert_array_equal(transmissions, K)
    np.testing.assert_array_equal(attempts, K * (N - 1))
    np.testing.assert_array_equal(deliveries, (~lost).sum(axis=(0, 3)))
    _within(1.0 - (deliveries / attempts).ravel(), form["loss_rate"])


def test_equal_losses_in_both_states_are_bernoulli():
    config = GilbertElliott(comm_range=500.0, loss_good=0.4, loss_bad=0.4, p_good_to_bad=0.1, p_bad_to_good=0.2)
    assert config.closed_forms()["correlation"] == 0.0
    lost, bad, _ = _losses(config, K=800)
    stats = _per_link(lost)
    _within(stats["loss_rate"], 0.4)
    _within(stats["correlation"], 0.0)
    assert bad.mean() > 0.2  # the chain runs; the losses ignore it


def _run(spec, steps=6, batch=3, seed=7):
    """Infos, delivered matrices and observations of a seeded play under seeded random actions."""
    core = ComposedScenario(spec, batch=batch)
    core.reset([np.random.default_rng([seed, b]) for b in range(batch)])
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps):
        core.step(np.stack([np.stack([_random_action(core, rng) for _ in range(core.num_agents)])
                            for _ in range(batch)]))
        out.append((core.info(), core.network.delivered.copy(), core.observation()))
    return core, out


def _random_action(core, rng):
    if not core.blocks:
        return np.zeros(1, core.action_space().dtype)
    return np.concatenate([rng.integers(0, blk.choices, blk.size) for blk in core.blocks]).astype(
        core.action_space().dtype)


@pytest.mark.parametrize("world, backend", [("circles", "ukf_ccl"), ("circles", "ukf_dcl"), ("gps_denied", "dnbp"),
                                            ("drift", "kalman"), ("gps_denied", "ukf_dcl")])
def test_with_no_bad_state_it_is_broadcast_with_loss_good_message_for_message(world, backend):
    """p_good_to_bad = 0: every link starts and stays good; the same seeds give the same deliveries, counts,
    estimates and observations (but the acknowledgements) as ``broadcast`` with ``loss = loss_good``; central
    messages, broadcasts, chains (circles: the copies share one distance matrix) and packets. The since-last-
    transmission features differ on purpose: over gilbert_elliott a reference is a transmission acknowledged,
    over broadcast one sent."""
    extra = {"num_particles": 30, "num_iterations": 1} if backend == "dnbp" else {}
    parts = dict(world=world, backend={"name": backend, **extra}, horizon=6)
    ge = coloc_env.compose(network={"name": "gilbert_elliott", "comm_range": 150.0, "loss_good": 0.35,
                                    "loss_bad": 1.0, "p_good_to_bad": 0.0, "p_bad_to_good": 0.5}, **parts)
    bc = coloc_env.compose(network={"name": "broadcast", "comm_range": 150.0, "loss": 0.35}, **parts)
    core_ge, a = _run(ge)
    core_bc, b = _run(bc)
    assert not core_ge.network.link_bad().any()
    N = core_ge.num_agents
    ack = core_ge.network.observation_size()
    assert ack == N and core_bc.network.observation_size() == 0
    lossy = False
    for (info_a, delivered_a, obs_a), (info_b, delivered_b, obs_b) in zip(a, b, strict=True):
        np.testing.assert_array_equal(delivered_a, delivered_b)
        for name, value in info_b.items():
            np.testing.assert_array_equal(info_a[name], value, err_msg=name)
        since = [core_ge.feature_index(name) for name in ("displacement", "steps_since", "message_value")]
        same = np.ones(obs_a.shape[-1], bool)
        same[since] = False
        cut = 3 * N + 2 + len(core_ge.own_features) + core_ge.world.feature_bounds()[0].size
        np.testing.assert_array_equal(obs_a[..., :cut][..., same[:cut]], obs_b[..., :cut][..., same[:cut]])
        np.testing.assert_array_equal(obs_a[..., cut + ack:], obs_b[..., cut:])
        np.testing.assert_array_equal(obs_a[..., cut:cut + ack], delivered_a)  # the ack: the sender's row
        lossy |= bool((info_a["link_deliveries"] < info_a["link_attempts"]).any())
    assert lossy


def test_link_states_depend_on_the_key_the_link_and_the_step_only():
    """Asked at any step in any order, after any number of calls, the states are those of stepping from 0; a copy's
    reset changes its own states only; copy b of a batch has the states of the same key alone."""
    config = GilbertElliott(p_good_to_bad=0.2, p_bad_to_good=0.3)
    B, N = 4, 6
    rngs = [np.random.default_rng([3, b]) for b in range(B)]
    net = config.build(N, B, "broadcast")
    net.reset(rngs, np.arange(B))
    keys = net.keys.copy()
    stepped = []
    for k in range(12):
        net.begin(np.full(B, k), np.zeros((B, N, 2)), np.ones((B, N, 1), np.int64))
        stepped.append(net.link_bad().copy())
        net.broadcast(np.ones((B, N), bool), np.ones((B, N, N), bool), 1.0, slot=0)
        net.broadcast(np.ones((B, N), bool), np.ones((B, N, N), bool), 1.0, slot=1)
        np.testing.assert_array_equal(net.link_bad(), stepped[-1])  # delivery calls do not move the chains
    stepped = np.array(stepped)
    assert 0.1 < stepped.mean() < 0.9 and (stepped[1:] != stepped[:-1]).any()
    # out of order, on a fresh network with the same keys, and each copy alone
    fresh = config.build(N, B, "broadcast")
    fresh.keys[:] = keys
    for k in (9, 3, 11, 0, 5):
        fresh.begin(np.full(B, k), np.zeros((B, N, 2)), np.ones((B, N, 1), np.int64))
        np.testing.assert_array_equal(fresh.link_bad(), stepped[k])
    alone = config.build(N, 1, "broadcast")
    alone.keys[:] = keys[2:3]
    alone.begin(np.array([7]), np.zeros((1, N, 2)), np.ones((1, N, 1), np.int64))
    np.testing.assert_array_equal(alone.link_bad()[0], stepped[7, 2])
    # copies at different steps: each at its own
    fresh.begin(np.array([2, 8, 4, 11]), np.zeros((B, N, 2)), np.ones((B, N, 1), np.int64))
    np.testing.assert_array_equal(fresh.link_bad(), stepped[[2, 8, 4, 11], np.arange(B)])
    # resetting copy 1 alone: the others keep theirs
    net.reset([np.random.default_rng(99)], np.array([1]))
    net.begin(np.array([12, 0, 12, 12]), np.zeros((B, N, 2)), np.ones((B, N, 1), np.int64))
    again = config.build(N, B, "broadcast")
    again.keys[:] = keys
    again.begin(np.full(B, 12), np.zeros((B, N, 2)), np.ones((B, N, 1), np.int64))
    others = [0, 2, 3]
    np.testing.assert_array_equal(net.link_bad()[others], again.link_bad()[others])
    assert net.keys[1] != keys[1]


def test_the_sender_observes_its_deliveries_one_step_later():
    spec = coloc_env.compose(world="circles", network={"name": "gilbert_elliott", "comm_range": 150.0}, backend="dnbp",
                             horizon=5)
    core = ComposedScenario(spec, batch=2)
    core.reset([np.random.default_rng(b) for b in range(2)])
    N = core.num_agents
    cut = 3 * N + 2 + len(core.own_features) + core.world.feature_bounds()[0].size
    space = core.observation_space()
    assert core.obs_dim == space.shape[0] == core.observation().shape[-1]
    np.testing.assert_array_equal(core.observation()[..., cut:cut + N], 0.0)  # nothing sent yet
    rng = np.random.default_rng(0)
    for _ in range(4):
        core.step(np.stack([np.stack([_random_action(core, rng) for _ in range(N)]) for _ in range(2)]))
        obs = core.observation()
        np.testing.assert_array_equal(obs[..., cut:cut + N], core.network.delivered)  # [t, s]: t's own row
        assert all(space.contains(o) for o in obs.reshape(-1, obs.shape[-1]))
    core.reset([np.random.default_rng(5)], env_index=[1])
    np.testing.assert_array_equal(core.observation()[1, :, cut:cut + N], 0.0)


def test_the_bound_over_gilbert_elliott_records_its_deliveries():
    """``pcrb`` of a composition over the network: with no bad state it is the ``broadcast`` bound with
    ``loss = loss_good``; with bursts its delivered bound moves, never below the centralized one."""
    good = {"name": "gilbert_elliott", "comm_range": 150.0, "loss_good": 0.3, "p_good_to_bad": 0.0}
    same = coloc_env.pcrb(coloc_env.compose("circles", good, "ukf_ccl", horizon=8), episodes=2, seed=1)
    ref = coloc_env.pcrb(coloc_env.compose("circles", {"name": "broadcast", "comm_range": 150.0, "loss": 0.3},
                                           "ukf_ccl", horizon=8), episodes=2, seed=1)
    for name in ("centralized", "delivered", "local"):
        np.testing.assert_allclose(same[name], ref[name], rtol=1e-12, atol=0)
    bursty = coloc_env.pcrb(coloc_env.compose("circles", {"name": "gilbert_elliott", "comm_range": 150.0},
                                              "ukf_ccl", horizon=8), episodes=2, seed=1)
    assert (bursty["delivered"] >= bursty["centralized"] * (1 - 1e-9)).all()
    np.testing.assert_allclose(bursty["centralized"], ref["centralized"], rtol=1e-12)  # the network's alone
    assert not np.allclose(bursty["delivered"], ref["delivered"])


@pytest.mark.parametrize("field, low, high", [("loss_good", 0.0, 1.0), ("loss_bad", 0.0, 1.0),
                                              ("p_good_to_bad", 0.0, 1.0), ("p_bad_to_good", 0.0, 1.0)])
def test_every_probability_is_refused_beyond_both_ends(field, low, high):
    for value in (low, high):
        GilbertElliott(**{field: value}).validate()
    for value in (low - 1e-9, high + 1e-9, float("nan")):
        with pytest.raises(ValueError, match=rf"network\.{field} must be in \[0\.0, 1\.0\]"):
            coloc_env.compose("circles", {"name": "gilbert_elliott", field: value}, "ukf_ccl")


def test_a_chain_without_transitions_and_a_bad_range_are_refused():
    with pytest.raises(ValueError, match=r"network\.p_good_to_bad \+ network\.p_bad_to_good must be > 0"):
        coloc_env.compose("circles", {"name": "gilbert_elliott", "p_good_to_bad": 0.0, "p_bad_to_good": 0.0}, "ukf_ccl")
    for value in (0.0, -1.0):
        with pytest.raises(ValueError, match=r"network\.comm_range must be in \(0\.0, inf\]"):
            coloc_env.compose("circles", {"name": "gilbert_elliott", "comm_range": value}, "ukf_ccl")
    coloc_env.compose("circles", {"name": "gilbert_elliott", "comm_range": float("inf")}, "ukf_ccl")
