"""dNBP (wan2014): unit tests of its equations on small worked cases, the schedule, the kernels
and batch/seed reproducibility."""

import dataclasses

import numpy as np
import pytest

import estimators.dnbp as dn

ANCHORS_AND_TARGET = np.array([[0.0, 0.0], [300.0, 0.0], [0.0, 300.0], [120.0, 150.0]])


def over(adjacency):
    """The deliver callable of a plain radio network over ``adjacency`` (B, N, N): the estimator's caller's job."""
    return lambda senders, listening: senders[..., :, None] & adjacency & listening


def _ranges(positions, rng, std):
    d = np.linalg.norm(positions[:, None] - positions[None], axis=-1)
    noise = np.triu(std * rng.standard_normal(d.shape), 1)
    return d > 0, d + noise + noise.T


def test_three_anchors_and_a_flat_prior_converge_below_three_sigma_d():
    """A static fault UAV hearing three (almost exact) anchors from a cold start: error < 3 sigma_d after 5 steps."""
    model = dn.DnbpModel(num_particles=100, gps_std=0.1, num_iterations=1)
    first, last = [], []
    for seed in range(8):
        rng = np.random.default_rng(seed)
        state = dn.initial_state(model, [rng], "cold", np.zeros((1, 4, 2)), np.zeros((1, 4, 2)), 0.0)
        assert state.prior_uniform.all()
        for k in range(5):
            adjacency, ranges = _ranges(ANCHORS_AND_TARGET, rng, model.range_std)
            state, result = dn.step(model, state, np.array([[True, True, True, False]]), ANCHORS_AND_TARGET[None],
                                    over(adjacency[None]), ranges[None], np.zeros((1, 4, 2)), [rng])
            error = np.linalg.norm(result.estimate[0, 3] - ANCHORS_AND_TARGET[3])
            (first if k == 0 else last).append(error) if k in (0, 4) else None
    assert max(last) < 3 * model.range_std
    assert np.mean(last) < np.mean(first)


def test_one_anchor_message_is_a_ring():
    """Alg. 1 from a point anchor: radial spread ~ sigma_d, every direction covered; the belief is a ring too."""
    model = dn.DnbpModel(num_particles=400, range_std=2.0)
    M, d = model.num_particles, 150.0
    rng = np.random.default_rng(0)
    anchor = np.zeros((1, M, 2))
    draws = dn.draw_messages(rng, 1, model)
    centres, log_w, h = dn.sample_messages(model, anchor, np.array([d]), None, **draws)
    radius = np.linalg.norm(centres[0], axis=-1)
    assert abs(radius.mean() - d) < 0.5 and abs(radius.std() - model.range_std) < 0.3
    bins = np.histogram(np.arctan2(centres[0, :, 1], centres[0, :, 0]), bins=36, range=(-np.pi, np.pi))[0]
    assert np.all(bins > 0) and bins.max() <= M / 36 + 2  # stratified: even angular coverage
    assert h[0] == pytest.approx(max(np.pi * d / M, model.min_bandwidth))
    # belief of a UAV that hears only this anchor, from the cold box: a ring of radius d
    prior = np.concatenate([400 * rng.random((1, M, 2)) - 200, np.zeros((1, M, 2))], axis=-1)
    present = np.array([[True]])
    new, ok = dn.belief_update(model, prior, np.ones(1), np.array([True]), centres[:, None], log_w[:, None],
                               h[:, None], present, dn.draw_belief(rng, 1, model))
    assert ok[0]
    r = np.linalg.norm(new[0, :, :2], axis=-1)
    # the regularization jitter h_rot = sigma_hat ESS^(-1/6) of the spec thickens a ring belief (tens of
    # metres here), but it keeps its hole and its radius
    assert abs(np.median(r) - d) < 0.1 * d and np.mean(r < 0.3 * d) < 0.02
    quadrants = np.histogram(np.arctan2(new[0, :, 1], new[0, :, 0]), bins=8, range=(-np.pi, np.pi))[0]
    assert np.all(quadrants > 0)


CASE = np.array([[0.0, 0.0], [0.0, 250.0], [500.0, 125.0], [250.0, 125.0], [60.0, 200.0], [330.0, 200.0]])


def test_case_study_schedule_sends_the_papers_messages():
    """Sec. 4.1: iteration 0: 1,2,3 -> 4; 1,2 -> 5; 3 -> 6. Iteration 1: 4 -> 5, 6. Iteration 2: 4 and 5 send."""
    model = dn.DnbpModel(num_particles=30, num_iterations=4)
    rng = np.random.default_rng(1)
    adjacency = (np.linalg.norm(CASE[:, None] - CASE[None], axis=-1) <= 300) & ~np.eye(6, dtype=bool)
    _, ranges = _ranges(CASE, rng, 2.0)
    state = dn.initial_state(model, [rng], "cold", np.zeros((1, 6, 2)), np.zeros((1, 6, 2)), 0.0)
    normal = np.array([[True, True, True, False, False, False]])
    _, result = dn.step(model, state, normal, CASE[None], over(adjacency[None]), ranges[None], np.zeros((1, 6, 2)),
                        [rng])

    def sent(n):
        return sorted((int(t) + 1, int(s) + 1) for t, s in zip(*np.nonzero(result.delivered[0, n]), strict=True))

    assert sent(0) == [(1, 4), (1, 5), (2, 4), (2, 5), (3, 4), (3, 6)]
    assert sent(1) == [(4, 5), (4, 6)]
    assert sent(2) == [(4, 5), (4, 6), (5, 4), (5, 6)]
    assert sent(3) == [(4, 5), (4, 6), (5, 4), (5, 6), (6, 4), (6, 5)]  # UAV6 now heard 3, 4, 5
    np.testing.assert_array_equal(result.broadcasts[0], [1, 1, 1, 3, 2, 1])
    np.testing.assert_array_equal(result.received[0], [0, 0, 0, 5, 4, 3])


def test_threshold_drops_within_one_iteration_and_never_rises():
    fault = np.array([[True, True, True, False]])
    qualified, threshold = dn.fault_senders(fault, np.array([[1, 0, 0, 5]]), np.zeros((1, 4), bool), np.array([3]))
    np.testing.assert_array_equal(qualified, [[True, False, False, False]])  # 3 -> 2 -> 1 in one call
    assert threshold[0] == 1
    qualified, threshold = dn.fault_senders(fault, np.array([[3, 2, 0, 5]]), np.zeros((1, 4), bool), np.array([3]))
    np.testing.assert_array_equal(qualified, [[True, False, False, False]]) and threshold[0] == 3
    # nobody new qualifies at 3: the threshold drops to 2 and UAV1 joins; UAV0 stays allowed
    qualified, threshold = dn.fault_senders(fault, np.array([[3, 2, 0, 5]]), qualified, threshold)
    np.testing.assert_array_equal(qualified, [[True, True, False, False]])
    assert threshold[0] == 2


def test_fast_kernel_matches_the_log_domain_and_far_points_count_as_zero():
    rng = np.random.default_rng(2)
    points = rng.normal(size=(3, 40, 2)) * 30 + 800.0
    centres = rng.normal(size=(3, 25, 2)) * 20 + 800.0
    log_w = np.log(rng.dirichlet(np.ones(25), size=3))
    h = np.array([3.0, 8.0, 0.5])
    exact = dn.mixture_logpdf(points, centres, log_w, h, exact=True)
    fast = dn.mixture_logpdf(points, centres, log_w, h, exact=False)
    finite = np.isfinite(fast)
    assert finite[:2].all()
    np.testing.assert_allclose(fast[finite], exact[finite], atol=1e-7)
    assert np.all(exact[~finite] < -600 + 10)
    direct = np.log(np.sum(np.exp(log_w[0]) * np.exp(-np.sum((points[0, :, None] - centres[0, None]) ** 2, -1)
                                                       / (2 * 9.0)), axis=-1) / (2 * np.pi * 9.0))
    np.testing.assert_allclose(exact[0], direct, atol=1e-10)


def test_rule_of_thumb_bandwidth():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(500, 2)) * [2.0, 4.0]
    w = rng.random(500)
    w /= w.sum()
    mean = w @ pts
    var = (w @ (pts - mean) ** 2).mean()
    assert dn.rule_of_thumb_bandwidth(pts, w) == pytest.approx(np.sqrt(var) * (1 / np.sum(w**2)) ** (-1 / 6))


def _random_world(rng, B, N):
    pos = 400 * rng.random((B, N, 2))
    d = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1)
    noise = np.triu(2 * rng.standard_normal(d.shape), 1)
    adjacency = (d <= 300) & ~np.eye(N, dtype=bool)
    normal = rng.random((B, N)) < 0.5
    return pos, normal, adjacency, np.where(adjacency, d + noise + np.swapaxes(noise, 1, 2), 0), rng.normal(
        size=(B, N, 2))


@pytest.mark.parametrize("schedule", ["modified", "parallel"])
def test_copy_b_of_a_batch_equals_the_copy_alone_and_seeds_reproduce(schedule):
    model = dn.DnbpModel(num_particles=24, num_iterations=3, schedule=schedule)
    B, N = 3, 6
    pos, normal, adjacency, ranges, accel = _random_world(np.random.default_rng(4), B, N)
    bits = np.random.default_rng(5).random((B, N, 3)) < 0.8

    def run(copies, seeds):
        rngs = [np.random.default_rng(s) for s in seeds]
        state = dn.initial_state(model, rngs, "warm", pos[copies], np.zeros((len(copies), N, 2)), 1.0)
        out = []
        for _ in range(2):
            state, result = dn.step(model, state, normal[copies], pos[copies], over(adjacency[copies]), ranges[copies],
                                    accel[copies], rngs, bits[copies])
            out.append((result.estimate, result.delivered, state.prior))
        return out

    batched = run(np.arange(B), [10, 11, 12])
    again = run(np.arange(B), [10, 11, 12])
    for b in range(B):
        alone = run(np.array([b]), [10 + b])
        for (eb, db, pb), (ea, da, pa), (e2, _, _) in zip(batched, alone, again, strict=True):
            np.testing.assert_array_equal(eb[b], ea[0])
            np.testing.assert_array_equal(db[b], da[0])
            np.testing.assert_array_equal(pb[b], pa[0])
            np.testing.assert_array_equal(eb, e2)
    other = run(np.arange(B), [10, 11, 13])
    assert not np.array_equal(other[-1][0][2], batched[-1][0][2])


def test_per_copy_sigmas_give_each_copy_what_its_own_floats_give():
    """A model holding (B,) arrays of sigma_gps, sigma_d and sigma_acc: copy b equals the copy alone with a model
    of copy b's floats, bit for bit (warm start, every iteration's messages, the prediction)."""
    base = dn.DnbpModel(num_particles=24, num_iterations=3)
    B, N = 3, 6
    pos, normal, adjacency, ranges, accel = _random_world(np.random.default_rng(4), B, N)
    sigmas = {"gps_std": np.array([3.0, 0.7, 5.0]), "range_std": np.array([2.0, 0.4, 6.0]),
              "accel_noise_std": np.array([0.3, 0.05, 1.2])}

    def run(model, copies):
        rngs = [np.random.default_rng(10 + b) for b in copies]
        state = dn.initial_state(model, rngs, "warm", pos[copies], np.zeros((len(copies), N, 2)), 1.0)
        for _ in range(2):
            state, _ = dn.step(model, state, normal[copies], pos[copies], over(adjacency[copies]), ranges[copies],
                               accel[copies], rngs)
        return state

    batched = run(dataclasses.replace(base, **sigmas), np.arange(B))
    for b in range(B):
        alone = run(dataclasses.replace(base, **{k: float(v[b]) for k, v in sigmas.items()}), np.array([b]))
        np.testing.assert_array_equal(batched.prior[b], alone.prior[0])
        np.testing.assert_array_equal(batched.belief[b], alone.belief[0])
    with pytest.raises(ValueError, match=r"gps_std must be a float or have shape \(3,\), got shape \(2,\)"):
        run(dataclasses.replace(base, gps_std=np.ones(2)), np.arange(B))


def test_a_step_gives_the_same_bits_whatever_room_its_message_pool_starts_with(monkeypatch):
    """The step's messages live in a pool that grows by doubling: starting it with no room for the delivered
    messages (every one added by growing) must not change a bit of the step."""
    model = dn.DnbpModel(num_particles=20, num_iterations=3)
    B, N = 2, 9
    pos, normal, adjacency, ranges, accel = _random_world(np.random.default_rng(8), B, N)

    def run():
        rngs = [np.random.default_rng(s) for s in (3, 4)]
        state = dn.initial_state(model, rngs, "warm", pos, np.zeros((B, N, 2)), 1.0)
        for _ in range(2):
            state, result = dn.step(model, state, normal, pos, over(adjacency), ranges, accel, rngs)
        return state.prior, result.received

    prior, received = run()
    assert received.sum() > 2 * B * N  # more messages than a pool started with no room holds without growing
    monkeypatch.setattr(dn, "_POOL_ENTRIES_PER_ROW", 0)
    grown_prior, grown_received = run()
    np.testing.assert_array_equal(grown_prior, prior)
    np.testing.assert_array_equal(grown_received, received)


def test_parallel_schedule_lets_normal_uavs_absorb_messages_and_silence_is_dead_reckoning():
    model = dn.DnbpModel(num_particles=20, num_iterations=2)
    rng = np.random.default_rng(6)
    pos, normal, adjacency, ranges, accel = _random_world(rng, 1, 5)
    normal[:] = [[True, True, False, False, True]]
    adjacency[:] = ~np.eye(5, dtype=bool)
    ranges = np.where(adjacency, np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1), 0)
    state = dn.initial_state(model, [np.random.default_rng(0)], "warm", pos, np.zeros((1, 5, 2)), 1.0)
    par = dataclasses.replace(model, schedule="parallel")
    _, result = dn.step(par, state, normal, pos, over(adjacency), ranges, accel, [np.random.default_rng(1)])
    assert result.delivered[0, :, :, 0].any()  # a normal UAV received
    assert result.delivered[0, 0, 2].any() and result.broadcasts[0].tolist() == [2] * 5
    _, modified = dn.step(model, state, normal, pos, over(adjacency), ranges, accel, [np.random.default_rng(1)])
    assert not modified.delivered[0][:, :, normal[0]].any()  # no message into a normal UAV
    silent = np.zeros((1, 5, 2), bool)
    _, quiet = dn.step(model, state, normal, pos, over(adjacency), ranges, accel, [np.random.default_rng(1)], silent)
    assert not quiet.delivered.any() and quiet.broadcasts.sum() == 0
    np.testing.assert_array_equal(quiet.belief[0, 2], state.prior[0, 2])  # fault UAV keeps its prior


def test_deliver_is_the_callers_network_and_may_not_exceed_the_schedule():
    model = dn.DnbpModel(num_particles=20, num_iterations=2)
    pos, normal, adjacency, ranges, accel = _random_world(np.random.default_rng(6), 1, 5)
    normal[:] = [[True, True, False, False, True]]
    state = dn.initial_state(model, [np.random.default_rng(0)], "warm", pos, np.zeros((1, 5, 2)), 1.0)
    with pytest.raises(ValueError, match="deliver returned a delivery the schedule did not allow"):
        dn.step(model, state, normal, pos, lambda s, listening: np.ones((1, 5, 5), bool), ranges, accel,
                [np.random.default_rng(1)])
    # a network that loses every message: allowed, and nothing is delivered or counted
    _, lost = dn.step(model, state, normal, pos, lambda s, listening: np.zeros_like(listening), ranges, accel,
                      [np.random.default_rng(1)])
    assert not lost.delivered.any() and lost.broadcasts.sum() == 0


def test_a_tempered_message_has_its_radial_variance_divided_by_alpha():
    """temper_bandwidth: the ring of a fault sender's message, sampled from its mixture, has 1/alpha times the
    radial variance of the untempered ring (a Gaussian profile raised to alpha); untempered rows are unchanged."""
    model = dn.DnbpModel(num_particles=400, range_std=2.0)
    M, d, alpha = model.num_particles, 150.0, 0.5
    rng = np.random.default_rng(4)
    sender = 3.0 * rng.standard_normal((2, M, 2))  # a sender with a 3 m position spread
    draws = dn.draw_messages(rng, 2, model)
    centres, log_w, h = dn.sample_messages(model, sender, np.full(2, d), None, **draws)
    tempered = dn.temper_bandwidth(h, sender, None, np.array([True, False]), alpha, np.full(2, model.range_std))
    assert tempered[1] == h[1] and tempered[0] > h[0]
    np.testing.assert_array_equal(dn.temper_bandwidth(h, sender, None, np.array([True, True]), 1.0,
                                                      np.full(2, model.range_std)), h)

    def radial_variance(bandwidth):
        pick = rng.integers(0, M, 200_000)
        points = centres[0, pick] + bandwidth * rng.standard_normal((200_000, 2))
        return np.linalg.norm(points - sender[0].mean(axis=0), axis=-1).var()

    assert radial_variance(tempered[0]) / radial_variance(h[0]) == pytest.approx(1.0 / alpha, rel=0.1)


def test_fault_message_power_is_checked():
    with pytest.raises(ValueError, match=r"fault_message_power must be in \(0, 1\]"):
        dn.DnbpModel(fault_message_power=0.0)
    with pytest.raises(ValueError, match=r"fault_message_power must be in \(0, 1\]"):
        dn.DnbpModel(fault_message_power=1.5)
