"""dNBP's optional truncated kernel (``DnbpModel.kernel = "truncated"``) approximates the exact one within its
stated bound: the importance weights of real belief updates to 1e-6 in total variation at r = 6, seeded episodes
to 1e-3 m; a radius too small moves them visibly (so these tolerances test the truncation, not a copy of the exact
path); the library's default stays the exact kernel, the env's is the truncated one; bad values are refused by
name."""

import numpy as np
import pytest

import coloc_env
import estimators.dnbp as dn
import estimators.dnbp_kernels as dk

pytest.importorskip("numba")


def _updates(steps=4, num_particles=50):
    """The fused belief updates' inputs of a short gps_denied_nbp episode (exact kernel)."""
    captured = []
    original = dn._belief_update_fused

    def record(kernels, model, *args):
        captured.append((model, args))
        return original(kernels, model, *args)

    env = coloc_env.parallel_env("gps_denied_nbp", num_particles=num_particles, horizon=steps, kernel="exact")
    env.reset(seed=3)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(dn, "_belief_update_fused", record)
        while env.agents:
            env.step({a: np.ones(5, np.int64) for a in env.agents})
    return captured


def _weights(model, args, radius):
    prior, prior_bandwidth, prior_uniform, centres, log_weights, bandwidth, present, draws, _, _, C = args
    proposals, log_w = np.empty((prior.shape[0], C, 2)), np.empty((prior.shape[0], C))
    lo, hi = model.defensive_box
    lo_c, hi_c = model.cold_box
    dk.fused_kernels()["weights"][0](prior, prior_bandwidth, prior_uniform, centres, log_weights, bandwidth, present,
                                      draws["pick"], draws["box"], draws["noise"], model.oversampling,
                                      model.defensive_weight, lo, hi, lo_c, hi_c, radius, 0, proposals, log_w)
    return proposals, log_w


def _total_variation(updates, radius):
    worst = 0.0
    for model, args in updates:
        proposals, exact = _weights(model, args, 0.0)
        same, approximate = _weights(model, args, radius)
        np.testing.assert_array_equal(same, proposals)  # the same draws: only the weights differ
        for a, b in zip(exact, approximate, strict=True):
            assert np.isfinite(a).any() == np.isfinite(b).any()
            if np.isfinite(a).any():
                pa, pb = np.exp(a - a.max()), np.exp(b - b.max())
                worst = max(worst, float(np.abs(pa / pa.sum() - pb / pb.sum()).sum()))
    return worst


def test_truncated_importance_weights_equal_the_exact_ones_within_the_bound():
    updates = _updates()
    assert len(updates) > 10
    assert _total_variation(updates, 6.0) < 1e-6
    assert _total_variation(updates, 1.0) > 1e-3  # a radius too small is visible in the same measure


def test_exp_small_is_exp_to_1e12_on_its_range():
    x = np.linspace(-50.0, 0.0, 2001)
    approx = np.array([dk.compiled_helper("exp_small")(v) for v in x])
    np.testing.assert_allclose(approx, np.exp(x), rtol=1e-12, atol=0)


def _means(kernel, truncation, seed=0):
    env = coloc_env.parallel_env("gps_denied_nbp", num_particles=50, horizon=8, kernel=kernel, truncation=truncation)
    env.reset(seed=seed)
    means = []
    while env.agents:
        _, _, _, _, infos = env.step({a: np.ones(5, np.int64) for a in env.agents})
        means.append([infos[a]["estimated_position"] for a in sorted(infos)])
    return np.array(means)


def test_seeded_episodes_agree_with_the_exact_kernel_and_a_small_radius_does_not():
    exact = _means("exact", 6.0)
    assert np.abs(_means("truncated", 6.0) - exact).max() < 1e-3
    assert np.abs(_means("truncated", 1.0) - exact).max() > 0.1


def test_the_library_defaults_to_the_exact_kernel_and_the_env_to_the_truncated_one():
    assert dn.DnbpModel().kernel == "exact"
    assert coloc_env.backends.Dnbp().kernel == "truncated"
    assert coloc_env.scenarios.gps_denied_nbp.GpsDeniedNbpConfig().kernel == "truncated"
    assert coloc_env.parallel_env("gps_denied_nbp", kernel="exact").unwrapped.scenario.backend.model.kernel == "exact"


@pytest.mark.parametrize(("options", "message"), [
    ({"kernel": "grid"}, r"kernel must be one of \('exact', 'truncated'\), got 'grid'"),
    ({"truncation": 0.5}, r"truncation must be in \[1.0, 10.0\], got 0.5"),
    ({"truncation": 12.0}, r"truncation must be in \[1.0, 10.0\], got 12.0"),
])
def test_bad_kernel_options_are_refused_by_name(options, message):
    with pytest.raises(ValueError, match=message):
        coloc_env.parallel_env("gps_denied_nbp", **options)
    with pytest.raises(ValueError, match="backend." + message):
        coloc_env.compose(world="gps_denied", network="broadcast", backend={"name": "dnbp", **options})
    field = next(iter(options))
    with pytest.raises(ValueError, match=f"^{field} must be"):
        dn.DnbpModel(**options)


def test_truncated_correction_weights_are_within_the_log_density_bound():
    """log w_i = -log m_st(p_i) normalized: a log density moves by < K e^(-r^2/2) (1.5e-6 at r = 6, K = 100)."""
    rng = np.random.default_rng(4)
    E, M = 5, 100
    senders = 700.0 + rng.normal(size=(E, M, 2)) * 4.0
    angle = rng.random((E, M)) * 2 * np.pi
    centres = senders.mean(axis=1, keepdims=True) + (150.0 + 2.0 * rng.normal(size=(E, M)))[..., None] * np.stack(
        [np.cos(angle), np.sin(angle)], axis=-1)
    senders[:, : M // 2] = centres[:, : M // 2] + rng.normal(size=(E, M // 2, 2)) * 5.0  # half near the ring
    log_w = np.log(rng.dirichlet(np.ones(M), size=E))
    h = np.array([1.0, 3.0, 6.0, 9.0, 12.0])
    exact = dn.correction_weights(senders, centres, log_w, h)
    assert np.abs(dn.correction_weights(senders, centres, log_w, h, truncation=6.0) - exact).max() < 2 * M * np.exp(-18)
    assert np.abs(dn.correction_weights(senders, centres, log_w, h, truncation=1.0) - exact).max() > 1e-2


def test_truncated_correction_weights_depend_neither_on_threads_nor_on_the_batch(monkeypatch):
    """The correction weights' truncated kernel, threaded over messages (its renamed copy), split over the worker
    threads, or serial, and one message alone: the same numbers (each message's row reads only its own inputs).

    The serial kernel on the whole batch, on slices of it and on one message gives the same bits; the threaded copy
    is another compiled function, and its fastmath point kernel (inlined) may be contracted differently by LLVM
    there, so it agrees to a few units in the last place (a row reading another row's inputs would be far off)."""
    rng = np.random.default_rng(5)
    E, M = 7, 60
    senders = 500.0 + rng.normal(size=(E, M, 2)) * 6.0
    centres = 500.0 + rng.normal(size=(E, M, 2)) * 40.0
    log_w = np.log(rng.dirichlet(np.ones(M), size=E))
    h = rng.uniform(1.0, 8.0, size=E)
    monkeypatch.setattr(dk, "FUSED_THREADS", True)
    monkeypatch.setattr(dk, "FUSED_THREAD_ELEMENTS", 1)
    threaded = dn.correction_weights(senders, centres, log_w, h, truncation=6.0)
    monkeypatch.setattr(dk, "FUSED_THREADS", False)
    serial = dn.correction_weights(senders, centres, log_w, h, truncation=6.0)
    np.testing.assert_allclose(threaded, serial, rtol=1e-14, atol=0)
    monkeypatch.setattr(dk, "SPLIT_WORKERS", 2)
    monkeypatch.setattr(dk, "SPLIT_ELEMENTS", 0)
    split = dn.correction_weights(senders, centres, log_w, h, truncation=6.0)  # slices on the worker threads
    np.testing.assert_array_equal(split, serial)
    for e in (0, 3, 6):
        alone = dn.correction_weights(senders[e:e + 1], centres[e:e + 1], log_w[e:e + 1], h[e:e + 1], truncation=6.0)
        np.testing.assert_array_equal(alone[0], serial[e])
