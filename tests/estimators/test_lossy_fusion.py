"""The lossy-link estimators (fu2017) against enumerations, independent loops and Monte Carlo."""

import itertools

import numpy as np
import pytest
import scipy.linalg

import estimators.lossy_fusion as lf
from coloc_env.config import build_config
from coloc_env.scenarios.lossy_fusion import LossyFusionConfig, LossyFusionScenario

X0 = np.array([100.0, 10.0, 100.0, 10.0, 100.0, 0.0])
P0 = np.diag([100.0, 5.0, 100.0, 5.0, 100.0, 5.0])


def model_of(**kwargs) -> lf.LossyModel:
    """fu2017's model of the ``lossy_fusion`` preset with these keywords (its backend's)."""
    return LossyFusionScenario(build_config(LossyFusionConfig, kwargs)).model


def episodes(runs, seed, **kwargs):
    """The model, ``runs`` episodes of the ``lossy_fusion`` preset with these keywords (copy r reset with the r-th
    child of ``default_rng(seed)``): its world's ``truth`` x(0..K-1) (runs, K, 6) and readings ``z`` (runs, K, L, 3),
    its network's link ``outcome`` to the leader (runs, K, L), and the position rows H."""
    scenario = LossyFusionScenario(build_config(LossyFusionConfig, kwargs), batch=runs)
    scenario.reset(np.random.default_rng(seed).spawn(runs))
    sim = {"truth": scenario.world.truth[:, :scenario.horizon], "z": scenario.z, "outcome": scenario.link_outcomes()}
    return scenario.model, sim, scenario.H


def squared_errors(estimates, truth, H):
    return np.sum(((estimates - truth) @ H.T) ** 2, axis=-1)


def test_compensation_weights_are_eq29():
    np.testing.assert_allclose(lf.compensation_weights(0.4, 0.3), [0.4, 0.3 + 0.3 * 0.4, 0.3 * 0.6], atol=1e-15)
    np.testing.assert_allclose(lf.compensation_weights(1.0, 0.0), [1.0, 0.0, 0.0])


def test_received_measurements_follow_eq3():
    rng = np.random.default_rng(0)
    z = rng.normal(size=(4, 12, 3, 2))
    outcome = rng.integers(0, 3, size=(4, 12, 3))
    initial = np.array([5.0, -1.0])
    y = lf.received_measurements(z, outcome, initial)
    for r in range(4):
        for i in range(3):
            held, before = initial, initial
            for k in range(12):
                xi1, xi2 = outcome[r, k, i] == lf.ON_TIME, outcome[r, k, i] == lf.LATE
                held = xi1 * z[r, k, i] + xi2 * before + (1 - xi1 - xi2) * held
                before = z[r, k, i]
                np.testing.assert_array_equal(y[r, k, i], held)


def _enumerate_links(model):
    """Every joint outcome of the followers' links with its probability, as (xi1, xi2) per stacked row."""
    p, L = model.meas_dim, model.num_uavs
    probs = [(model.on_time[i], model.late[i], 1 - model.on_time[i] - model.late[i]) for i in range(1, L)]
    for codes in itertools.product(range(3), repeat=L - 1):
        prob = np.prod([probs[i][c] for i, c in enumerate(codes)])
        xi1 = np.repeat([1.0] + [float(c == lf.ON_TIME) for c in codes], p)
        xi2 = np.repeat([0.0] + [float(c == lf.LATE) for c in codes], p)
        yield prob, xi1, xi2


def test_augmented_moments_match_an_enumeration_of_the_link_outcomes():
    """Phibar, Psi = E[dPhi q dPhi^T] and Qbar = E[Gammat W W^T Gammat^T] from all 27 joint outcomes (L = 4)."""
    model = model_of(num_agents=4, on_time_probability=0.5, late_probability=0.2)
    mats = lf.augmented_matrices(model)
    n, m = model.state_dim, 3 * model.num_uavs
    d = n + 2 * m
    rng = np.random.default_rng(3)
    root = rng.normal(size=(d, d))
    cov, mean = root @ root.T, rng.normal(size=d) * 50
    q = cov + np.outer(mean, mean)
    Hs = np.vstack([model.measurement] * model.num_uavs)
    R = scipy.linalg.block_diag(*model.measurement_noise)
    Qw = scipy.linalg.block_diag(model.process_noise, R)
    phi_mean = np.zeros((d, d))
    spread = np.zeros((d, d))
    noise = np.zeros((d, d))
    total = 0.0
    outcomes = list(_enumerate_links(model))
    for prob, xi1, xi2 in outcomes:
        phi = np.zeros((d, d))
        phi[:n, :n] = model.transition
        phi[n:n + m, :n] = Hs
        phi[n + m:] = np.hstack([xi1[:, None] * Hs, np.diag(xi2), np.diag(1 - xi1 - xi2)])
        gamma = np.zeros((d, n + m))
        gamma[:n, :n] = np.eye(n)
        gamma[n:n + m, n:] = np.eye(m)
        gamma[n + m:, n:] = np.diag(xi1)
        phi_mean += prob * phi
        noise += prob * gamma @ Qw @ gamma.T
        total += prob
    for prob, xi1, xi2 in outcomes:
        phi = phi_mean.copy()
        phi[n + m:] = np.hstack([xi1[:, None] * Hs, np.diag(xi2), np.diag(1 - xi1 - xi2)])
        delta = phi - phi_mean
        spread += prob * delta @ q @ delta.T
    assert len(outcomes) == 27 and total == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(mats.phi_bar, phi_mean, atol=1e-12)
    np.testing.assert_allclose(mats.noise, noise, atol=1e-12)
    psi = lf.link_moment(mats, mean, cov)
    np.testing.assert_allclose(spread[n + m:, n + m:], psi, rtol=1e-9, atol=1e-9 * np.abs(psi).max())
    np.testing.assert_allclose(spread[: n + m], 0.0, atol=1e-9)
    # the paper's A1, A2, A3 weights (no Cov(xi1, xi2)) give a different matrix
    c11, c22, _ = mats.link_cov
    Da, Db = mats.fresh_diff, mats.late_diff
    without_cross = c11 * (Da @ q @ Da.T) + c22 * (Db @ q @ Db.T)
    assert np.abs(without_cross - psi).max() > 1e-3 * np.abs(psi).max()


def test_optimal_predictor_knows_the_received_buffer_exactly():
    """y(k) is the last block of X(k+1): the optimal gain leaves it no error, the paper's gain (21) does."""
    model = model_of(num_agents=3)
    mats = lf.augmented_matrices(model)
    m = 9
    y = np.tile(model.measurement @ X0, (3, 1))
    optimal = lf.centralized_initial(model, X0, P0)
    paper = lf.centralized_initial(model, X0, P0)
    for _ in range(5):
        optimal, *_ = lf.centralized_step(model, optimal, y, "optimal", mats)
        paper, *_ = lf.centralized_step(model, paper, y, "paper", mats)
        np.testing.assert_allclose(optimal.covariance[-m:, -m:], 0.0, atol=1e-9)
        assert np.trace(paper.covariance[-m:, -m:]) > 1.0


@pytest.mark.parametrize("num_agents", [2, 3])
def test_without_losses_every_filter_of_the_raw_measurements_is_the_ideal_kf(num_agents):
    model, sim, H = episodes(20, 1, num_agents=num_agents, on_time_probability=1.0, late_probability=0.0)
    results = lf.run_filters(model, X0, P0, sim["z"], sim["outcome"],
                             ("naive_kf", "centralized", "centralized_paper_gain", "informed_kf", "ideal_kf"))
    ideal, ideal_cov = results["ideal_kf"]
    for name in ("naive_kf", "centralized", "centralized_paper_gain", "informed_kf"):
        est, cov = results[name]
        np.testing.assert_allclose(est, ideal, atol=1e-8, rtol=0, err_msg=name)
        np.testing.assert_allclose(np.broadcast_to(cov, (20, *ideal_cov.shape)) if cov.ndim == 4 else cov,
                                   np.broadcast_to(ideal_cov, cov.shape), atol=1e-8, err_msg=name)


@pytest.mark.parametrize("gain, num_agents", [("optimal", 2), ("paper", 2), ("optimal", 4)])
def test_centralized_covariance_matches_its_monte_carlo_error(gain, num_agents):
    """(A)'s own P(k|k) is its true MSE: Monte Carlo within 3 standard errors, over all k and late k."""
    runs = 400
    model, sim, H = episodes(runs, 10 + num_agents, num_agents=num_agents)
    y = lf.received_measurements(sim["z"], sim["outcome"], H @ X0)
    est, cov = lf.centralized_filter(model, X0, P0, y, gain)
    err = squared_errors(est, sim["truth"], H)  # (runs, K)
    claimed = np.trace(H @ cov @ H.T, axis1=-2, axis2=-1)  # (K,)
    for window in (slice(0, 100), slice(50, 100), slice(0, 10)):
        per_run = err[:, window].mean(axis=1)
        se = per_run.std(ddof=1) / np.sqrt(runs)
        assert abs(per_run.mean() - claimed[window].mean()) < 3 * se, (window, per_run.mean(), claimed[window].mean())


def test_optimal_gain_is_never_worse_than_the_paper_gain():
    """Both own covariances are exact MSEs, so the LMMSE gain must give the smaller trace at every k."""
    for on_time, late in ((0.4, 0.3), (0.1, 0.8), (0.7, 0.0)):
        model, sim, H = episodes(1, 0, num_agents=3, on_time_probability=on_time, late_probability=late)
        y = lf.received_measurements(sim["z"], sim["outcome"], H @ X0)
        _, optimal = lf.centralized_filter(model, X0, P0, y, "optimal")
        _, paper = lf.centralized_filter(model, X0, P0, y, "paper")
        diff = np.trace(paper - optimal, axis1=-2, axis2=-1)
        assert np.all(diff > -1e-9)
        assert diff.max() > 1e-3


def test_orderings_over_seeded_monte_carlo():
    """ideal < informed < centralized < {leader only, naive}: paired differences beyond 3 standard errors."""
    runs = 300
    model, sim, H = episodes(runs, 5, num_agents=3)
    results = lf.run_filters(model, X0, P0, sim["z"], sim["outcome"])
    per_run = {name: squared_errors(est, sim["truth"], H).mean(axis=1) for name, (est, _) in results.items()}

    def clearly_below(a, b):
        diff = per_run[a] - per_run[b]
        return diff.mean() + 3 * diff.std(ddof=1) / np.sqrt(runs) < 0

    assert clearly_below("ideal_kf", "informed_kf")
    assert clearly_below("informed_kf", "centralized")
    assert clearly_below("centralized", "leader_only_kf")
    assert clearly_below("centralized", "naive_kf")
    assert clearly_below("leader_only_kf", "distributed")


def reference_distributed(model, z, outcome, transmit):
    """(B) written out slot by slot for one run, independently of the vectorized code."""
    Phi, Q, H = model.transition, model.process_noise, model.measurement
    R = model.measurement_noise
    L, K = model.num_uavs, z.shape[0]
    c = [lf.compensation_weights(model.on_time[i], model.late[i]) for i in range(L)]

    def kf(x, P, zz, Ri):
        S = H @ P @ H.T + Ri
        G = P @ H.T @ np.linalg.inv(S)
        return x + G @ (zz - H @ x), (np.eye(6) - G @ H) @ P

    pred1 = {i: (X0, P0) for i in range(1, L)}
    pred2 = {i: (X0, P0) for i in range(1, L)}
    previous = {i: [(X0, P0)] * 3 for i in range(1, L)}
    previous_sent = {i: True for i in range(1, L)}
    held = {i: [(X0, P0)] * 3 for i in range(1, L)}
    leader = (X0, P0)
    fused_all = []
    for k in range(K):
        for i in range(1, L):
            filtered = kf(*pred1[i], z[k, i], R[i])
            packet = [filtered, pred1[i], pred2[i]]
            if outcome[k, i] == lf.ON_TIME and transmit[k, i - 1]:
                held[i] = packet
            elif outcome[k, i] == lf.LATE and previous_sent[i]:
                held[i] = previous[i]
            previous[i], previous_sent[i] = packet, transmit[k, i - 1]
            pred2[i] = (Phi @ pred1[i][0], Phi @ pred1[i][1] @ Phi.T + Q)
            pred1[i] = (Phi @ filtered[0], Phi @ filtered[1] @ Phi.T + Q)
        own = kf(*leader, z[k, 0], R[0])
        estimates, covs = [own[0]], [own[1]]
        for i in range(1, L):
            estimates.append(sum(c[i][j] * held[i][j][0] for j in range(3)))
            covs.append(sum(c[i][j] * held[i][j][1] for j in range(3)))
        inv = np.array([1 / np.trace(P) for P in covs])
        a = inv / inv.sum()
        fused = sum(a[i] * estimates[i] for i in range(L))
        fused_cov = sum(a[i] ** 2 * covs[i] for i in range(L))
        fused_all.append(fused)
        leader = (Phi @ fused, Phi @ fused_cov @ Phi.T + Q)
    return np.array(fused_all)


def test_distributed_matches_an_independent_slot_by_slot_implementation():
    model, sim, H = episodes(3, 2, num_agents=3, horizon=25)
    rng = np.random.default_rng(0)
    transmit = rng.random((3, 25, 2)) < 0.7
    state = lf.distributed_initial(model, X0, P0, (3,))
    fused = []
    for k in range(25):
        state = lf.distributed_step(model, state, sim["z"][:, k], sim["outcome"][:, k], transmit[:, k])
        fused.append(state.fused)
    fused = np.stack(fused, axis=1)
    for r in range(3):
        expected = reference_distributed(model, sim["z"][r], sim["outcome"][r], transmit[r])
        np.testing.assert_allclose(fused[r], expected, rtol=1e-10, atol=1e-9)
    paper, _ = lf.distributed_filter(model, X0, P0, sim["z"], sim["outcome"])
    always = reference_distributed(model, sim["z"][0], sim["outcome"][0], np.ones((25, 2), bool))
    np.testing.assert_allclose(paper[0], always, rtol=1e-10, atol=1e-9)


def test_batch_axes_give_the_same_numbers_as_a_flat_batch():
    model, sim, H = episodes(6, 4, num_agents=3, horizon=15)
    flat = lf.run_filters(model, X0, P0, sim["z"], sim["outcome"])
    shaped = lf.run_filters(model, X0, P0, sim["z"].reshape(2, 3, 15, 3, 3), sim["outcome"].reshape(2, 3, 15, 3))
    for name in lf.FILTERS:
        np.testing.assert_allclose(shaped[name][0].reshape(6, 15, 6), flat[name][0], atol=1e-9, err_msg=name)
    single = lf.run_filters(model, X0, P0, sim["z"][4], sim["outcome"][4])
    for name in lf.FILTERS:
        np.testing.assert_allclose(single[name][0], flat[name][0][4], atol=1e-9, err_msg=name)


def test_model_and_filter_arguments_are_checked():
    model = model_of()
    with pytest.raises(ValueError, match="leader"):
        lf.LossyModel(model.transition, model.process_noise, model.measurement, model.measurement_noise,
                      np.array([0.4, 0.4]), np.array([0.3, 0.3]))
    with pytest.raises(ValueError, match="on_time \\+ late <= 1"):
        lf.LossyModel(model.transition, model.process_noise, model.measurement, model.measurement_noise,
                      np.array([1.0, 0.8]), np.array([0.0, 0.3]))
    with pytest.raises(ValueError, match="gain"):
        lf.centralized_step(model, lf.centralized_initial(model, X0, P0), np.zeros((2, 3)), gain="fast")
    with pytest.raises(ValueError, match="unknown filters"):
        lf.run_filters(model, X0, P0, np.zeros((1, 3, 2, 3)), np.zeros((1, 3, 2), int), ("kalman",))


def test_derived_link_moment_does_not_depend_on_the_origin_but_the_printed_one_does():
    model = model_of(num_agents=3)
    mats = lf.augmented_matrices(model)
    rng = np.random.default_rng(8)
    d = mats.phi_bar.shape[0]
    root = rng.normal(size=(d, d))
    cov, mean = root @ root.T, rng.normal(size=d)
    shift = np.array([500.0, 0.0, -300.0, 0.0, 800.0, 0.0])
    moved = mean + np.concatenate([shift, np.tile(model.measurement @ shift, 6)])  # every position moves
    np.testing.assert_allclose(lf.link_moment(mats, moved, cov), lf.link_moment(mats, mean, cov), atol=1e-8)
    printed, printed_moved = lf.printed_link_moment(mats, mean, cov), lf.printed_link_moment(mats, moved, cov)
    assert np.trace(printed_moved) > 100 * np.trace(printed)
