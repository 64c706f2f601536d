"""The bandwidth-limited fusion estimator (zhao2020) against independent derivations."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import estimators.bandwidth_fusion as bf
from estimators.bandwidth_fusion import paper_selection, paper_weights
from tests.conftest import random_selection, random_weights

M0 = np.diag([0.19, 0.09, 0.08])


def general_model():
    """Non-identity A and a 2x3 C with per-node V, so the identity fast paths are not taken."""
    A = np.array([[0.95, 0.1, 0.0], [-0.05, 1.0, 0.02], [0.0, 0.03, 0.9]])
    C = np.array([[1.0, 0.2, 0.0], [0.0, 0.5, 1.0]])
    V = np.stack([np.array([[0.03, 0.01], [0.01, 0.05]]) * (1 + 0.3 * j) for j in range(4)])
    return bf.FusionModel(A, np.array([0.5, -0.2, 0.1]), C, np.diag([0.02, 0.05, 0.03]), V)


@pytest.fixture(params=["paper", "general"])
def any_model(request, paper_model):
    return paper_model if request.param == "paper" else general_model()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1))
def test_realized_errors_follow_corrected_eq11(any_model, seed):
    """e(k+1) = F e(k) + G [w; v] holds to 1e-12 for the actual estimates (any T, any p, any A, C)."""
    rng = np.random.default_rng(seed)
    model = any_model
    N, n, m = 4, 3, model.measurement_dim
    selection, weights = random_selection(rng), random_weights(rng)
    state = bf.initial_state(model, np.full(n, 10.0), M0)
    x = np.full(n, 10.0) + rng.normal(size=n)
    for _ in range(6):
        v, w = rng.normal(size=(N, m)) * 0.2, rng.normal(size=n) * 0.2
        F, G = bf.error_transition(model, bf.gains(model, state.bound), selection, weights)
        e = (x - state.estimate).ravel()
        state = bf.step(model, state, x @ model.measurement.T + v, selection, weights)
        x = model.transition @ x + model.drift + w
        predicted = F @ e + G @ np.concatenate([w, v.ravel()])
        np.testing.assert_allclose(predicted, (x - state.estimate).ravel(), atol=1e-12)


def test_eq11_as_printed_is_wrong(paper_model):
    """The printed Tbar_ji L_j v_j would mis-predict the error; T_ji L_j v_j is right."""
    rng = np.random.default_rng(1)
    selection, weights = paper_selection("T1"), paper_weights("P2")
    state = bf.initial_state(paper_model, np.full(3, 10.0), M0)
    x = np.full(3, 10.3)
    v = rng.normal(size=(4, 3))
    gain = bf.gains(paper_model, state.bound)
    e = x - state.estimate
    nxt = bf.step(paper_model, state, x + v, selection, weights)
    e_next = x + paper_model.drift - nxt.estimate  # w = 0
    for i in range(4):
        common = sum(weights[i, j] * (np.diag(selection[i, j]) @ (paper_model.transition - gain[j]) @ e[j]
                                      + np.diag(~selection[i, j]) @ e[i]) for j in range(4))
        printed = common - sum(weights[i, j] * np.diag(~selection[i, j]) @ gain[j] @ v[j] for j in range(4))
        derived = common - sum(weights[i, j] * np.diag(selection[i, j]) @ gain[j] @ v[j] for j in range(4))
        np.testing.assert_allclose(derived, e_next[i], atol=1e-12)
        assert np.abs(printed - e_next[i]).max() > 1e-3


def eq15(model, M, L, selection, weights):
    """The bound recursion (15) for arbitrary gains L, written out term by term."""
    A, C, W = model.transition, model.measurement, model.process_noise
    out = []
    for i in range(4):
        Mi = W.copy()
        for j in range(4):
            T = np.diag(selection[i, j].astype(float))
            Tb = np.eye(3) - T
            K = A - L[j] @ C
            Mi = Mi + 2 * weights[i, j] * (T @ K @ M[j] @ K.T @ T.T + Tb @ A @ M[i] @ A.T @ Tb.T)
            Mi = Mi + weights[i, j] * T @ L[j] @ model.measurement_noise[j] @ L[j].T @ T.T
        out.append(Mi)
    return np.stack(out)


def test_gain18_and_recursion19_minimize_eq15(any_model):
    rng = np.random.default_rng(2)
    selection, weights = paper_selection("T3"), paper_weights("P3")
    M = np.stack([M0 * (1 + i) for i in range(4)])
    L = bf.gains(any_model, M)
    at_optimum = eq15(any_model, M, L, selection, weights)
    np.testing.assert_allclose(bf.bound_step(any_model, M, selection, weights), at_optimum, atol=1e-12)
    for _ in range(20):
        perturbed = L + 0.05 * rng.normal(size=L.shape)
        assert np.trace(eq15(any_model, M, perturbed, selection, weights), axis1=1, axis2=2).sum() > \
            np.trace(at_optimum, axis1=1, axis2=2).sum()


@pytest.mark.parametrize("pair", ["T1P1", "T1P2", "T1P3", "T2P1", "T3P1"])
def test_bound_dominates_exact_covariance(paper_model, pair):
    selection, weights = paper_selection(pair[:2]), paper_weights(pair[2:])
    state = bf.initial_state(paper_model, np.zeros(3), M0)
    for _ in range(50):
        gain = bf.gains(paper_model, state.bound)
        state.error_cov = bf.exact_covariance_step(paper_model, state.error_cov, gain, selection, weights)
        state.bound = bf.bound_step(paper_model, state.bound, selection, weights)
        gap = state.bound - bf.node_covariances(state.error_cov, 4)
        assert np.linalg.eigvalsh(gap).min() >= -1e-9 * np.abs(state.bound).max()


def _monte_carlo(model, x0, M0, selection, weights, horizon, rng, runs):
    """Squared errors (horizon+1, runs, N) of ``runs`` realizations of the paper's model (1)-(2) with x(0) ~
    N(x0, M0), filtered by :func:`bf.step` (a reference simulation of the system, here only: the package's
    worlds draw the episodes elsewhere)."""
    n, m = model.state_dim, model.measurement_dim
    x = rng.multivariate_normal(x0, M0, size=runs)
    process = rng.multivariate_normal(np.zeros(n), model.process_noise, size=(horizon, runs))
    meas = np.stack([rng.multivariate_normal(np.zeros(m), V, size=(horizon, runs)) for V in model.measurement_noise],
                    axis=2)
    state = bf.initial_state(model, x0, M0, (runs,))
    state.error_cov = None
    errors = [np.sum((state.estimate - x[:, None, :]) ** 2, axis=-1)]
    for k in range(horizon):
        y = x[:, None, :] @ model.measurement.T + meas[k]
        state = bf.step(model, state, y, selection, weights)
        x = x @ model.transition.T + model.drift + process[k]
        errors.append(np.sum((state.estimate - x[:, None, :]) ** 2, axis=-1))
    return np.stack(errors)


def test_exact_cost_matches_monte_carlo_within_3_percent(any_model):
    selection, weights = paper_selection("T1"), paper_weights("P1")
    exact, bound = bf.expected_cost(any_model, M0, selection, weights, 50)
    squared_error = _monte_carlo(any_model, np.full(3, 10.0), M0, selection, weights, 50, np.random.default_rng(0), 500)
    mc = squared_error.sum(axis=(0, 2)).mean()
    assert abs(mc / exact.sum() - 1) < 0.03
    # the per-step, per-node traces too, where Monte Carlo has 500 samples of a 3-d error
    np.testing.assert_allclose(squared_error.mean(axis=1)[1:], exact[1:], rtol=0.2)
    assert exact[0].sum() == pytest.approx(4 * np.trace(M0), abs=1e-12)
    assert np.all(bound.sum() >= exact.sum())


def test_batch_axis_equals_per_copy_steps(any_model):
    paper_model = any_model
    rng = np.random.default_rng(3)
    B = 5
    selections = np.stack([random_selection(rng) for _ in range(B)])
    weights = np.stack([random_weights(rng) for _ in range(B)])
    batched = bf.initial_state(paper_model, np.full(3, 10.0), M0, (B,))
    singles = [bf.initial_state(paper_model, np.full(3, 10.0), M0) for _ in range(B)]
    for _ in range(4):
        y = rng.normal(size=(B, 4, paper_model.measurement_dim)) + 10
        batched = bf.step(paper_model, batched, y, selections, weights)
        singles = [bf.step(paper_model, s, y[b], selections[b], weights[b]) for b, s in enumerate(singles)]
    for b in range(B):
        np.testing.assert_allclose(batched.estimate[b], singles[b].estimate, atol=1e-12)
        np.testing.assert_allclose(batched.bound[b], singles[b].bound, atol=1e-12)
        np.testing.assert_allclose(batched.error_cov[b], singles[b].error_cov, atol=1e-12)


def test_time_varying_schedule_of_constants_equals_fixed(paper_model):
    selection, weights = paper_selection("T2"), paper_weights("P2")
    fixed = bf.expected_cost(paper_model, M0, selection, weights, 10)
    scheduled = bf.expected_cost(paper_model, M0, np.stack([selection] * 10), np.stack([weights] * 10), 10,
                                 time_varying=True)
    np.testing.assert_allclose(fixed[0], scheduled[0], atol=1e-12)
    np.testing.assert_allclose(fixed[1], scheduled[1], atol=1e-12)


def test_full_selection_has_no_compensation(paper_model):
    """With every component sent, node i's estimate is the p-weighted mean of the intermediates."""
    rng = np.random.default_rng(4)
    state = bf.initial_state(paper_model, np.full(3, 10.0), M0)
    y = rng.normal(size=(4, 3)) + 10
    weights = random_weights(rng)
    gain = bf.gains(paper_model, state.bound)
    lam = bf.intermediate_estimates(paper_model, state.estimate, y, gain)
    fused = bf.fuse(paper_model, state.estimate, lam, np.ones((4, 4, 3), bool), weights)
    np.testing.assert_allclose(fused, weights @ lam, atol=1e-12)


def test_invalid_selection_and_weights_are_refused():
    bad = np.ones((4, 4, 3), bool)
    bad[2, 2, 1] = False
    with pytest.raises(ValueError, match="T_ii = I"):
        bf.check_selection(bad)
    with pytest.raises(ValueError, match="sum_j p_ij must equal 1"):
        bf.check_weights(np.full((4, 4), 0.3))
    with pytest.raises(ValueError, match=">= 0"):
        bf.check_weights(np.array([[1.5, -0.5], [0.5, 0.5]]))
    with pytest.raises(ValueError, match="leading time axis"):
        bf.expected_cost(bf.FusionModel(np.eye(3), np.zeros(3), np.eye(3), np.eye(3), np.stack([np.eye(3)] * 4)),
                         M0, paper_selection("T1"), paper_weights("P1"), 5, time_varying=True)


@pytest.mark.parametrize("m", [0.19, 1e6, 0.19 * 2.0**49, 3e14, 1e16])
def test_a_sender_s_corrected_bound_is_its_closed_form_however_large_its_bound(paper_model, m):
    """A = C = I, diagonal M_j: the bracket of eq. (19) is, per component, m - m^2 / (m + v/2) =
    m (v/2) / (m + v/2), about v/2 once m >> v (a node whose compensated components grew for 50 steps:
    about 1e14). Receiver 0 takes component 0 from node 1 only, with weight 1: M_0(k+1)[0, 0] =
    2 m (v/2) / (m + v/2) + W[0, 0], to 1e-9, never the rounding of a difference of two 1e14 numbers."""
    N, n = 4, 3
    bound = np.broadcast_to(M0, (N, n, n)).copy()
    bound[1, 0, 0] = m
    selection = np.zeros((N, N, n), bool)
    selection[np.arange(N), np.arange(N)] = True
    selection[0, 1, 0] = True
    weights = np.eye(N)
    weights[0] = [0.0, 1.0, 0.0, 0.0]
    half_v = 0.5 * paper_model.measurement_noise[1, 0, 0]
    expected = 2.0 * m * half_v / (m + half_v) + paper_model.process_noise[0, 0]
    assert bf.bound_step(paper_model, bound, selection, weights)[0, 0, 0] == pytest.approx(expected, rel=1e-9)
