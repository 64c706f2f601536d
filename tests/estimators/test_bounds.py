"""The PCRB recursion and the Fisher information of each reading kind (estimators.bounds)."""

import numpy as np
import pytest

import estimators.bounds as eb
from estimators.kalman import joseph_update


def _complex_step_jacobian(fun, x, eps=1e-30):
    """df/dx by the complex step (exact to rounding): Im f(x + i eps e_j) / eps. (Bearings are written as
    arctan(dy / dx) with dx > 0 in these geometries: the same derivative as atan2, which takes no complex.)"""
    x = np.asarray(x, float)
    columns = []
    for j in range(x.size):
        step = np.zeros(x.size, complex)
        step[j] = 1j * eps
        columns.append(np.imag(fun(x + step)) / eps)
    return np.stack(columns, axis=-1)


def test_static_ranges_to_anchors_closed_form():
    # one step, no prior: J = sum u u^T / s2; anchors east, north and south-west of the agent
    p = np.array([1.0, 2.0])
    anchors = np.array([[11.0, 2.0], [1.0, 12.0], [-2.0, -1.0]])
    s2 = 0.25
    info = eb.range_information(p, anchors, s2).sum(axis=0)
    r = 1 / np.sqrt(2)
    closed = (np.array([[1.0, 0.0], [0.0, 0.0]]) + np.array([[0.0, 0.0], [0.0, 1.0]])
              + np.array([[r * r, r * r], [r * r, r * r]])) / s2
    np.testing.assert_allclose(info, closed, rtol=0, atol=1e-9)
    bound = eb.filtering_bound(None, info[None], J0=np.zeros((2, 2)))
    np.testing.assert_allclose(bound[0], np.linalg.inv(closed), rtol=0, atol=1e-9)


def test_pair_information_is_the_jacobian_of_the_range_between_two_agents():
    x = np.array([0.3, -1.2, 4.0, 2.5])  # (a, b)
    s2 = 0.7
    H = _complex_step_jacobian(lambda z: np.sqrt((z[0] - z[2]) ** 2 + (z[1] - z[3]) ** 2)[None], x)
    expected = H.T @ H / s2
    block = eb.range_information(x[:2], x[2:], s2)
    np.testing.assert_allclose(eb.pair_information(block), expected, rtol=0, atol=1e-12)


def test_bearing_and_range_bearing_information_match_complex_step_jacobians():
    p, s = np.array([3.0, -4.0]), np.array([-1.0, 2.5])
    H = _complex_step_jacobian(lambda z: np.arctan((z[1] - s[1]) / (z[0] - s[0]))[None], p)
    np.testing.assert_allclose(eb.bearing_information(p, s, 0.01), H.T @ H / 0.01, rtol=1e-12, atol=1e-12)
    pose, point = np.array([1.0, 2.0, 0.4]), np.array([4.0, -2.0])
    R = np.diag([0.04, 0.003])

    def h(z):
        d = z[3:] - z[:2]
        return np.stack([np.sqrt(d[0] ** 2 + d[1] ** 2), np.arctan(d[1] / d[0]) - z[2]])

    H = _complex_step_jacobian(h, np.concatenate([pose, point]))
    np.testing.assert_allclose(eb.range_bearing_information(pose, point, R), H.T @ np.linalg.inv(R) @ H,
                               rtol=1e-10, atol=1e-12)


def test_rss_aoa_information_equals_the_schur_complement_of_the_sender_nuisance():
    p, s = np.array([120.0, -40.0]), np.array([-30.0, 85.0])
    eta, var, s_nav = 2.2, np.array([4.0, 3e-6]), 4.0

    def h(z):
        d = z[:2] - z[2:]
        return np.stack([-10 * eta * np.log10(np.sqrt(d[0] ** 2 + d[1] ** 2)), np.arctan(d[1] / d[0])])

    H = _complex_step_jacobian(h, np.concatenate([p, s]))  # (2, 4): target, sender
    joint = H.T @ np.diag(1 / var) @ H + np.diag([0, 0, 1 / s_nav, 1 / s_nav])
    schur = joint[:2, :2] - joint[:2, 2:] @ np.linalg.solve(joint[2:, 2:], joint[2:, :2])
    np.testing.assert_allclose(eb.rss_aoa_information(p, s, eta, var, s_nav), schur, rtol=1e-7)
    # without the nuisance: the plain H^T R^-1 H; the AOA row alone: the bearing information
    np.testing.assert_allclose(eb.rss_aoa_information(p, s, eta, var), H[:, :2].T @ np.diag(1 / var) @ H[:, :2],
                               rtol=1e-10)
    np.testing.assert_allclose(eb.rss_aoa_information(p, s, eta, var, use=(False, True)),
                               eb.bearing_information(p, s, var[1]), rtol=1e-10)


def _random_system(rng, n=4, m=2, singular_q=True):
    A = np.eye(n) + 0.3 * rng.standard_normal((n, n))
    G = rng.standard_normal((n, n // 2 if singular_q else n))
    Q = G @ G.T  # rank n/2: position driven only through the noise's range
    C = rng.standard_normal((m, n))
    L = rng.standard_normal((m, m))
    R = L @ L.T + 0.1 * np.eye(m)
    M = rng.standard_normal((n, n))
    P0 = M @ M.T + 0.5 * np.eye(n)
    return A, Q, C, R, P0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_linear_gaussian_bound_equals_the_kalman_covariance(seed):
    rng = np.random.default_rng(seed)
    A, Q, C, R, P0 = _random_system(rng)
    K, agents = 30, 3
    H = np.vstack([C] * agents)
    Rs = np.kron(np.eye(agents), R)
    P, covs = P0, []
    mean = np.zeros(A.shape[0])
    for k in range(K):
        if k:
            P = A @ P @ A.T + Q
        mean, P = joseph_update(mean, P, H, np.zeros(H.shape[0]), Rs)
        covs.append(P)
    info = np.broadcast_to(eb.linear_information(H, Rs), (K, *A.shape))
    bound = eb.filtering_bound(P0, info, np.broadcast_to(A, (K - 1, *A.shape)), np.broadcast_to(Q, (K - 1, *Q.shape)))
    scale = np.abs(np.array(covs)).max()
    np.testing.assert_allclose(bound, np.array(covs), rtol=0, atol=1e-9 * scale)


def test_information_form_step_equals_the_covariance_form_for_a_common_model():
    rng = np.random.default_rng(3)
    A, Q, C, R, P0 = _random_system(rng, singular_q=False)
    info = eb.linear_information(C, R)
    J = np.linalg.inv(P0)
    J_next = eb.information_step(J, np.broadcast_to(A, (5, 4, 4)), np.broadcast_to(Q, (5, 4, 4)), info,
                                 regularization=0.0)
    P_next = eb.fuse_information(eb.predict_covariance(P0, A, Q), info)
    np.testing.assert_allclose(np.linalg.inv(J_next), P_next, rtol=1e-9)


def test_the_bound_averages_information_not_bounds():
    # two episodes, one with a reading and one without: TMN's bound inverts the averaged information, which is
    # smaller than the mean of the per-episode bounds (Jensen) and is the one that bounds the averaged MSE
    P0 = np.eye(2)
    infos = np.array([np.eye(2) * 4.0, np.zeros((2, 2))])
    averaged = eb.filtering_bound(P0, infos.mean(axis=0)[None])[0]
    np.testing.assert_allclose(averaged, np.eye(2) / 3.0, rtol=1e-12)
    per_episode = np.mean([eb.filtering_bound(P0, i[None])[0] for i in infos], axis=0)
    assert np.trace(per_episode) > np.trace(averaged)


def test_per_episode_singular_noise_regularization_moves_the_bound_by_little():
    rng = np.random.default_rng(4)
    E, K = 8, 20
    heading = rng.uniform(0, 0.2, size=(K - 1, E))
    u = np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    Q = 0.25 * u[..., :, None] * u[..., None, :]  # rank 1 per episode, a different direction in each
    Q[5:] += 1e-4 * np.eye(2)
    info = np.broadcast_to(np.eye(2) * 0.5, (K, 2, 2)).copy()
    info[1:5] = 0.0
    loose = eb.filtering_bound(0.01 * np.eye(2), info, None, Q, regularization=1e-9)
    tight = eb.filtering_bound(0.01 * np.eye(2), info, None, Q, regularization=1e-11)
    loose_trace, tight_trace = np.trace(loose, axis1=1, axis2=2), np.trace(tight, axis1=1, axis2=2)
    # more process noise, a larger bound; by less than 1e-4 of it (eps = 1e-9 moves it ~1e-5 here)
    assert np.all(loose_trace >= tight_trace - 1e-15)
    np.testing.assert_allclose(loose_trace, tight_trace, rtol=1e-4)


def test_bad_prior_arguments_are_named():
    with pytest.raises(ValueError, match="exactly one of P0"):
        eb.filtering_bound(np.eye(2), np.zeros((1, 2, 2)), J0=np.eye(2))
    with pytest.raises(ValueError, match=r"P0 must be \(2, 2\)"):
        eb.filtering_bound(np.eye(3), np.zeros((1, 2, 2)))
