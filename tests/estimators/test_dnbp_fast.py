"""dNBP's compiled kernels (numba) compute what the numpy kernels compute: the same mixture log-densities up to
float rounding, the same velocity draws exactly, the same belief updates (the fused kernels) up to rounding, on
any batch and thread count, and the same seeded episodes."""

import dataclasses

import numpy as np
import pytest

import estimators.dnbp as dn
import estimators.dnbp_kernels as dk

pytest.importorskip("numba")


def _mixtures(rng, J=6, P=70, K=40, spread=200.0):
    """Mixtures at kilometre coordinates: rings and clusters, non-uniform weights, points near, far and between."""
    centre = 900.0 + rng.normal(size=(J, 1, 2)) * 50
    angle = rng.random((J, K)) * 2 * np.pi
    radius = np.where(np.arange(J)[:, None] % 2 == 0, 150.0 + rng.normal(size=(J, K)), rng.random((J, K)) * 5)
    centres = centre + radius[..., None] * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    points = centre + rng.normal(size=(J, P, 2)) * spread
    log_w = np.log(rng.dirichlet(np.ones(K) * 0.5, size=J))
    h = rng.choice([0.5, 1.5, 6.0, 20.0], size=J)
    return points, centres, log_w, h


def test_compiled_mixture_kernel_matches_the_numpy_kernel_and_the_log_domain():
    rng = np.random.default_rng(0)
    points, centres, log_w, h = _mixtures(rng)
    compiled = dn.mixture_logpdf(points, centres, log_w, h, exact=False)
    numpy = dn.mixture_logpdf(points, centres, log_w, h, exact=False, compiled=False)
    exact = dn.mixture_logpdf(points, centres, log_w, h, exact=True)
    finite = np.isfinite(numpy)
    assert 0.2 < finite.mean() < 0.95  # both near and far (density counted as 0) points are exercised
    np.testing.assert_array_equal(np.isfinite(compiled), finite)
    np.testing.assert_allclose(compiled[finite], numpy[finite], rtol=0, atol=1e-9)
    # the log domain has no floor: near it (~-600) the fast kernels' floored terms e^-600 count, above it not
    above = finite & (exact > -500)
    np.testing.assert_allclose(compiled[above], exact[above], rtol=0, atol=1e-7)


def test_rows_near_the_floor_sum_every_term_as_the_numpy_kernel_does():
    """Points whose nearest component sits 30..40 bandwidths away: the sum is compared with 2 K e^-600 there."""
    K = 30
    centres = np.zeros((1, K, 2)) + np.linspace(0, 1, K)[None, :, None]
    h = np.ones(1)
    distance = np.linspace(33.0, 36.0, 200)  # exponents from about -545 to -650
    points = np.stack([distance, np.zeros_like(distance)], axis=-1)[None]
    log_w = np.full((1, K), -np.log(K))
    compiled = dn.mixture_logpdf(points, centres, log_w, h, exact=False)
    numpy = dn.mixture_logpdf(points, centres, log_w, h, exact=False, compiled=False)
    assert np.isfinite(numpy).any() and not np.isfinite(numpy).all()
    np.testing.assert_array_equal(np.isfinite(compiled), np.isfinite(numpy))
    finite = np.isfinite(numpy)
    np.testing.assert_allclose(compiled[finite], numpy[finite], rtol=1e-12)


def test_compiled_velocity_draws_equal_the_numpy_draws():
    rng = np.random.default_rng(1)
    R, M = 7, 50
    prior = np.concatenate([rng.normal(size=(R, M, 2)) * 4 + 700, rng.normal(size=(R, M, 2))], axis=-1)
    positions = prior[:, :, :2] + rng.normal(size=(R, M, 2)) * 3
    bandwidth = rng.choice([0.3, 1.0, 3.0], size=R)
    uniform = np.arange(R) % 3 == 0
    u = rng.random((R, M))
    compiled = dn._velocity_index(positions, prior, bandwidth, uniform, u)
    numpy = dn._velocity_index(positions, prior, bandwidth, uniform, u, compiled=False)
    assert compiled.dtype.kind == "i" and compiled.shape == (R, M)
    np.testing.assert_array_equal(compiled, numpy)


def test_threads_and_batches_do_not_change_the_compiled_results(monkeypatch):
    rng = np.random.default_rng(2)
    points, centres, log_w, h = _mixtures(rng, J=12, P=90, K=60)
    monkeypatch.setattr(dk, "PARALLEL_ELEMENTS", 1)
    threaded = dn.mixture_logpdf(points, centres, log_w, h, exact=False)
    monkeypatch.setattr(dk, "PARALLEL_ELEMENTS", 1 << 62)
    serial = dn.mixture_logpdf(points, centres, log_w, h, exact=False)
    alone = np.concatenate([dn.mixture_logpdf(points[j:j + 1], centres[j:j + 1], log_w[j:j + 1], h[j:j + 1],
                                              exact=False) for j in range(len(h))])
    np.testing.assert_array_equal(threaded, serial)
    np.testing.assert_array_equal(alone, serial)


def _episode(steps=4):
    import coloc_env

    env = coloc_env.vector_env("gps_denied_nbp", num_envs=3, seed=7, num_particles=40, horizon=steps)
    env.reset()
    actions = np.ones((env.num_envs, 5), dtype=np.int8)  # one row per (copy, agent)
    out = []
    for _ in range(steps - 1):
        _, reward, _, _ = env.step(actions)
        out.append(reward)
    return np.array(out)


def test_a_seeded_env_episode_is_the_same_with_the_numpy_kernels(monkeypatch):
    """The kernels' rounding differences (~1e-10 in a log density) do not move a seeded episode."""
    compiled = _episode()
    monkeypatch.setattr(dk, "compiled_kernels", lambda: None)
    monkeypatch.setattr(dk, "fused_kernels", lambda: None)
    numpy = _episode()
    np.testing.assert_allclose(compiled, numpy, rtol=1e-9)


def test_compiled_importance_weights_equal_the_numpy_combination():
    """log pi - log q from the prior and the present messages, absent slots and far proposals included."""
    rng = np.random.default_rng(3)
    model = dn.DnbpModel(num_particles=20)
    R, S, M, C = 5, 4, 20, 45
    prior = np.concatenate([rng.normal(size=(R, M, 2)) * 3 + 300, rng.normal(size=(R, M, 2))], axis=-1)
    proposals = 300 + rng.normal(size=(R, C, 2)) * np.where(rng.random((R, C, 1)) < 0.3, 200.0, 4.0)
    centres = 300 + rng.normal(size=(R, S, M, 2)) * 30
    log_weights = np.log(rng.dirichlet(np.ones(M), size=(R, S)))
    bandwidth = rng.choice([1.0, 5.0], size=(R, S))
    present = rng.random((R, S)) < 0.6
    present[0] = False
    K_r = present.sum(axis=1)
    valid = np.arange(C)[None, :] < rng.integers(C // 2, C + 1, size=R)[:, None]
    args = (model, proposals, prior, np.full(R, 1.0), np.arange(R) == 1, centres, log_weights, bandwidth, present,
            valid, K_r)
    compiled = dn._importance_log_weights(*args, exact=False)
    numpy = dn._importance_log_weights(*args, exact=False, compiled=False)
    finite = np.isfinite(numpy)
    assert finite.any() and not finite.all()
    np.testing.assert_array_equal(np.isfinite(compiled), finite)
    np.testing.assert_allclose(compiled[finite], numpy[finite], rtol=0, atol=1e-9)


# --- the fused belief update (Algorithm 2 in two compiled kernels) --------------------------------------------
def _receivers(rng, R=9, S=5, M=40, far=False):
    """Belief-update inputs of R receivers: KDE and cold-box priors, 0..S present messages (rings, clusters, a GPS
    fix of identical components), non-uniform message weights; ``far``: messages that do not overlap at all."""
    model = dn.DnbpModel(num_particles=M)
    centre = 600.0 + rng.normal(size=(R, 1, 2)) * 30
    prior = np.concatenate([centre + rng.normal(size=(R, M, 2)) * 4, rng.normal(size=(R, M, 2))], axis=-1)
    prior_bandwidth = dn.rule_of_thumb_bandwidth(prior[..., :2])
    prior_uniform = np.arange(R) % 4 == 1
    angle = rng.random((R, S, M)) * 2 * np.pi
    radius = np.where(np.arange(S)[None, :, None] % 2 == 0, 120.0 + rng.normal(size=(R, S, M)), 3.0)
    centres = centre[:, None] + radius[..., None] * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    centres[:, -1] = centre + rng.normal(size=(R, 1, 2)) * 2  # a GPS fix: M identical components
    if far:
        centres += 400.0 * np.arange(S)[None, :, None, None]
    log_weights = np.log(rng.dirichlet(np.ones(M), size=(R, S)))
    log_weights[:, -1] = -np.log(M)
    bandwidth = rng.choice([0.5, 2.0, 6.0], size=(R, S))
    present = rng.random((R, S)) < 0.6
    present[0] = False  # the prior alone
    present[2] = True  # every slot
    draws = dn.draw_belief(rng, R, model)
    return model, (prior, prior_bandwidth, prior_uniform, centres, log_weights, bandwidth, present, draws)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fused_belief_update_equals_the_numpy_path(seed):
    """The same proposals, weights and draws: the particles agree to rounding (~1e-13 m at 600 m)."""
    model, args = _receivers(np.random.default_rng(seed))
    fused, ok = dn.belief_update(model, *args)
    numpy, ok_numpy = dn.belief_update(model, *args, compiled=False)
    np.testing.assert_array_equal(ok, ok_numpy)
    assert ok.all()
    np.testing.assert_allclose(fused, numpy, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(fused[..., 2:], numpy[..., 2:])  # velocities are copied: the same draws


def test_fused_belief_update_recomputes_vanished_weights_in_the_log_domain(monkeypatch):
    """Messages 400 m apart: every fast weight underflows, the exact log domain takes over as in the numpy path."""
    model, args = _receivers(np.random.default_rng(3), far=True)
    exact_rows = []
    log_weights = dn._importance_log_weights

    def spy(*a, exact, **k):
        if exact:
            exact_rows.append(len(a[1]))
        return log_weights(*a, exact=exact, **k)

    monkeypatch.setattr(dn, "_importance_log_weights", spy)
    fused, ok = dn.belief_update(model, *args)
    assert exact_rows and exact_rows[0] >= 2
    numpy, ok_numpy = dn.belief_update(model, *args, compiled=False)
    assert exact_rows[1] == exact_rows[0]  # the same receivers recomputed
    np.testing.assert_array_equal(ok, ok_numpy)
    np.testing.assert_allclose(fused, numpy, rtol=0, atol=1e-9)


def test_fused_belief_update_depends_neither_on_threads_nor_on_the_batch(monkeypatch):
    model, args = _receivers(np.random.default_rng(4), R=12)
    monkeypatch.setattr(dk, "FUSED_THREADS", True)
    monkeypatch.setattr(dk, "PARALLEL_ELEMENTS", 1)
    threaded, _ = dn.belief_update(model, *args)
    monkeypatch.setattr(dk, "FUSED_THREADS", False)
    serial, _ = dn.belief_update(model, *args)
    np.testing.assert_array_equal(threaded, serial)
    # a receiver alone: the draws' flat offsets differ (row 0 instead of r), which moves nothing here
    *arrays, draws = args
    for r in (2, 5, 11):
        alone, _ = dn.belief_update(model, *[a[r:r + 1] for a in arrays], {k: v[r:r + 1] for k, v in draws.items()})
        np.testing.assert_allclose(alone[0], serial[r], rtol=0, atol=1e-9)


@pytest.mark.parametrize("n", [1, 7, 8, 9, 127, 128, 129, 264, 1000, 5000])
def test_compiled_sum_is_numpys_pairwise_sum(n):
    values = np.exp(np.random.default_rng(n).normal(size=n) * 4)
    assert dk.compiled_helper("numpy_sum")(values, n) == values.sum()


def test_fused_belief_update_split_over_worker_threads_gives_the_same_bits(monkeypatch):
    """Slices of the receivers on the worker threads (each slice's row offset passed to the kernels) compute the
    whole call's bits."""
    for kernel, far in (("exact", False), ("truncated", False), ("exact", True)):
        model, args = _receivers(np.random.default_rng(6), R=11, far=far)
        model = dataclasses.replace(model, kernel=kernel)
        monkeypatch.setattr(dk, "SPLIT_WORKERS", 1)
        serial, ok_serial = dn.belief_update(model, *args)
        monkeypatch.setattr(dk, "SPLIT_WORKERS", 2)
        monkeypatch.setattr(dk, "SPLIT_ELEMENTS", 0)
        for per_worker in (1, 3, 11):
            monkeypatch.setattr(dk, "SPLIT_PER_WORKER", per_worker)
            assert dk.split_pieces(11, 1) == min(11, 2 * per_worker)
            split, ok_split = dn.belief_update(model, *args)
            np.testing.assert_array_equal(split, serial)
            np.testing.assert_array_equal(ok_split, ok_serial)


@pytest.mark.parametrize("M", [2, 7, 100, 129, 300])
def test_compiled_messages_equal_the_numpy_messages_bit_for_bit(M):
    """sample_messages' compiled pass (centres, h_rot's sums in einsum's and numpy's orders) gives the numpy
    path's floats exactly, with and without correction weights, for one message and for many."""
    rng = np.random.default_rng(M)
    model = dn.DnbpModel(num_particles=M)
    for E in (1, 13):
        senders = rng.uniform(-200, 1200, size=(E, 1, 2)) + rng.normal(size=(E, M, 2)) * rng.uniform(0.5, 60)
        distance = rng.random(E) * 200
        raw = rng.normal(size=(E, M)) * 3
        for correction in (None, raw - np.log(np.exp(raw).sum(axis=1, keepdims=True))):
            draws = dn.draw_messages(rng, E, model)
            compiled = dn.sample_messages(model, senders, distance, correction, **draws)
            numpy = dn.sample_messages(model, senders, distance, correction, **draws, compiled=False)
            for a, b in zip(compiled, numpy, strict=True):
                np.testing.assert_array_equal(a, b)


def test_correction_weights_normalize_as_logsumexp_does():
    """The correction weights' normalization (every weight finite, or capped first) equals
    log w - _logsumexp(log w) bit for bit."""
    rng = np.random.default_rng(8)
    E, M = 6, 80
    senders = 400.0 + rng.normal(size=(E, M, 2)) * 30.0
    centres = 400.0 + rng.normal(size=(E, M, 2)) * 30.0
    centres[2] += 3000.0  # m_st = 0 at every particle of message 2 (capped at the largest finite weight)
    senders[4, :5] += 5000.0  # and at a few particles of message 4
    log_w = np.log(rng.dirichlet(np.ones(M), size=E))
    h = rng.uniform(1.0, 8.0, size=E)
    for truncation in (0.0, 6.0):
        if truncation:
            log_m, inv = np.empty((E, M)), 1.0 / h**2  # the kernel's inputs as correction_weights forms them
            cx, cy = np.ascontiguousarray(centres[..., 0]), np.ascontiguousarray(centres[..., 1])
            dk.fused_kernels()["mixture_truncated"][0](
                senders, cx, cy, log_w - 0.5 * (cx * cx + cy * cy) * inv[:, None], inv, np.log(2.0 * np.pi * h**2),
                0.5 * truncation**2, log_m)
        else:
            log_m = dn.mixture_logpdf(senders, centres, log_w, h, exact=False)
        raw = -log_m
        finite = np.isfinite(raw)
        assert not finite[2].any() and not finite[4].all() and finite[0].all()
        raw = np.where(finite, raw, np.nanmax(np.where(finite, raw, -np.inf)))
        expected = raw - dn._logsumexp(raw, axis=-1)[:, None]
        np.testing.assert_array_equal(dn.correction_weights(senders, centres, log_w, h, truncation), expected)
