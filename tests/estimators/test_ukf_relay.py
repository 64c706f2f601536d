"""UKF-CCL and UKF-DCL of wang2019: sigma points, DCL == CCL over chains, the departures from the print."""

import itertools

import numpy as np
import pytest

import estimators.ukf_relay as ur

N, L = 4, 8


def random_problem(rng, batch=(), spread=30.0):
    x = rng.normal(size=(*batch, N, 2)) * spread
    M = rng.normal(size=(*batch, L, L))
    P = M @ np.swapaxes(M, -1, -2) + 0.5 * np.eye(L)
    return x, P


def measure(rng, x, m, n):
    return ur.range_of(np.take_along_axis(x, m[..., None, None], -2)[..., 0, :],
                       np.take_along_axis(x, n[..., None, None], -2)[..., 0, :]) + rng.normal(size=np.shape(m))


@pytest.mark.parametrize("lam", [0.0, 1.0, -3.0])
def test_sigma_points_reproduce_mean_and_covariance(lam):
    rng = np.random.default_rng(0)
    x, P = random_problem(rng)
    mean = x.reshape(-1)
    chi = ur.sigma_points(mean, P, lam)
    w = ur.ukf_weights(L, lam)
    assert chi.shape == (2 * L + 1, L)
    assert w.sum() == pytest.approx(1.0, abs=1e-15)
    assert w[0] == pytest.approx(lam / (L + lam)) and np.allclose(w[1:], 0.5 / (L + lam))
    np.testing.assert_allclose(w @ chi, mean, atol=1e-12)
    dev = chi - mean
    np.testing.assert_allclose(np.einsum("p,pi,pj->ij", w, dev, dev), P, atol=1e-11)
    # the "-" point of column p sits at p + L, the mirror of the "+" point
    np.testing.assert_allclose(chi[1 + L:], 2 * mean - chi[1:1 + L], atol=1e-12)
    # columns are those of the lower Cholesky factor
    np.testing.assert_allclose(chi[1:1 + L] - mean, np.sqrt(L + lam) * np.linalg.cholesky(P).T, atol=1e-12)
    with pytest.raises(ValueError, match="lambda"):
        ur.ukf_weights(L, -8.0)


def test_dcl_equals_ccl_for_every_full_chain():
    rng = np.random.default_rng(1)
    chains = np.array(list(itertools.permutations(range(N))))  # all 24 serial topologies
    x, P = random_problem(rng, (len(chains),))
    z = measure(rng, x, chains[:, 0], chains[:, 1])
    for lam in (0.0, 2.0, -5.0):
        xc, Pc = ur.ccl_update(x, P, chains[:, 0], chains[:, 1], z, 1.0, lam)
        xd, Pd = ur.dcl_update(x, P, chains, np.full(len(chains), N), z, 1.0, lam)
        np.testing.assert_allclose(xd, xc, atol=1e-9, rtol=0)
        np.testing.assert_allclose(Pd, Pc, atol=1e-9, rtol=0)
        assert np.abs(xc - x).max() > 1e-3  # the update did something


def test_result_does_not_depend_on_the_order_of_the_later_receivers():
    rng = np.random.default_rng(2)
    x, P = random_problem(rng)
    z = measure(rng, x, np.array(2), np.array(0))
    results = [ur.dcl_update(x, P, np.array([2, 0, *rest]), 4, z, 1.0) for rest in ((1, 3), (3, 1))]
    np.testing.assert_allclose(results[0][0], results[1][0], atol=1e-10)
    np.testing.assert_allclose(results[0][1], results[1][1], atol=1e-10)


def test_leading_batch_axes_match_single_calls():
    rng = np.random.default_rng(3)
    x, P = random_problem(rng, (2, 3))
    chains = np.array([[rng.permutation(N) for _ in range(3)] for _ in range(2)])
    z = measure(rng, x, chains[..., 0], chains[..., 1])
    xb, Pb = ur.dcl_update(x, P, chains, np.full((2, 3), N), z, 1.0)
    xc, Pc = ur.ccl_update(x, P, chains[..., 0], chains[..., 1], z, 1.0)
    assert xb.shape == (2, 3, N, 2) and Pb.shape == (2, 3, L, L)
    for a, b in itertools.product(range(2), range(3)):
        xs, Ps = ur.dcl_update(x[a, b], P[a, b], chains[a, b], N, z[a, b], 1.0)
        np.testing.assert_allclose(xb[a, b], xs, atol=1e-12)
        np.testing.assert_allclose(Pb[a, b], Ps, atol=1e-12)
    np.testing.assert_allclose(xc, xb, atol=1e-9)


def test_truncated_consistent_dcl_equals_ccl_with_gain_zero_on_the_unreached():
    rng = np.random.default_rng(4)
    B = 12
    x, P = random_problem(rng, (B,))
    chains = np.array([rng.permutation(N) for _ in range(B)])
    length = rng.integers(2, N + 1, size=B)
    padded = np.where(np.arange(N) < length[:, None], chains, -1)
    reached = np.zeros((B, N), bool)
    for b in range(B):
        reached[b, chains[b, :length[b]]] = True
    z = measure(rng, x, chains[:, 0], chains[:, 1])
    xd, Pd = ur.dcl_update(x, P, padded, length, z, 1.0)
    xc, Pc = ur.ccl_update(x, P, chains[:, 0], chains[:, 1], z, 1.0, reached=reached)
    np.testing.assert_allclose(xd, xc, atol=1e-9, rtol=0)
    np.testing.assert_allclose(Pd, Pc, atol=1e-9, rtol=0)
    np.testing.assert_array_equal(xd[~reached], x[~reached])  # unreached keep their estimates
    # the paper's rule differs exactly in the reached-unreached cross blocks
    xp, Pp = ur.dcl_update(x, P, padded, length, z, 1.0, truncation="paper")
    np.testing.assert_array_equal(xp, ur.dcl_update(x, P, padded, length, z, 1.0, method="chain")[0])
    np.testing.assert_allclose(xp, xd, atol=1e-9, rtol=0)
    cross = reached[:, :, None] & ~reached[:, None, :]
    blocks = np.abs(Pp - Pd).reshape(B, N, 2, N, 2).max(axis=(2, 4))
    assert np.all(blocks[~(cross | np.swapaxes(cross, 1, 2))] < 1e-12)
    partial = length < N
    assert np.all(blocks[cross & partial[:, None, None]] > 1e-9)
    # and P_RU unchanged under the paper's rule
    assert np.all(np.abs(Pp - P).reshape(B, N, 2, N, 2).max(axis=(2, 4))[cross] < 1e-12)


def test_ccl_equals_filterpy_unscented_kalman_filter():
    from filterpy.kalman import JulierSigmaPoints, UnscentedKalmanFilter

    rng = np.random.default_rng(5)
    for lam in (0.0, 1.5):
        x, P = random_problem(rng)
        m, n = 3, 1
        z = float(ur.range_of(x[m], x[n]) + 0.7)
        index = (2 * ur.reorder_first(N, np.array(m), np.array(n))[:, None] + np.arange(2)).ravel()
        np.testing.assert_array_equal(index[:4], [6, 7, 2, 3])
        points = JulierSigmaPoints(L, kappa=lam)
        filt = UnscentedKalmanFilter(dim_x=L, dim_z=1, dt=1.0, points=points, fx=lambda s, dt: s,
                                     hx=lambda s: np.array([np.hypot(s[0] - s[2], s[1] - s[3])]))
        filt.x, filt.P = x.ravel()[index].copy(), P[np.ix_(index, index)].copy()
        filt.Q, filt.R = np.zeros((L, L)), np.eye(1)
        filt.predict()  # identity transition, Q = 0: leaves the sigma points of (x, P)
        filt.update(np.array([z]))
        xc, Pc = ur.ccl_update(x, P, m, n, z, 1.0, lam)
        inverse = np.argsort(index)
        np.testing.assert_allclose(filt.x[inverse].reshape(N, 2), xc, atol=1e-9, rtol=0)
        np.testing.assert_allclose(filt.P[np.ix_(inverse, inverse)], Pc, atol=1e-9, rtol=0)


def _ccl_quantities(x, P, m, n, z, lam=0.0):
    """Pxz (absolute order), Pz and the lower factor rows of the reordered P, by hand."""
    order = ur.reorder_first(N, np.array(m), np.array(n))
    idx = (2 * order[:, None] + np.arange(2)).ravel()
    xr, Pr = x.ravel()[idx], P[np.ix_(idx, idx)]
    chi = ur.sigma_points(xr, Pr, lam)
    w = ur.ukf_weights(L, lam)
    zs = np.hypot(chi[:, 0] - chi[:, 2], chi[:, 1] - chi[:, 3])
    dz = zs - w @ zs
    Pz = w @ dz**2 + 1.0
    Pxz = np.einsum("p,pl,p->l", w, chi - xr, dz)
    return order, Pxz, Pz, np.linalg.cholesky(Pr), dz


def test_departures_signs_and_inverses():
    """(11)/(23) subtract and (22) needs Pz^-1: the printed forms give other matrices."""
    rng = np.random.default_rng(6)
    x, P = random_problem(rng)
    m, n = 0, 2
    z = float(ur.range_of(x[m], x[n]) - 0.4)
    _, Pc = ur.ccl_update(x, P, m, n, z, 1.0)
    order, Pxz, Pz, _, _ = _ccl_quantities(x, P, m, n, z)
    idx = (2 * order[:, None] + np.arange(2)).ravel()
    inverse = np.argsort(idx)
    K = Pxz / Pz
    corrected = P - np.outer(K, K)[np.ix_(inverse, inverse)] * Pz
    np.testing.assert_allclose(Pc, corrected, atol=1e-10)
    assert np.linalg.eigvalsh(P - Pc).min() > -1e-10  # the update never adds uncertainty
    printed_11 = P + np.outer(K, K)[np.ix_(inverse, inverse)] * Pz
    assert np.abs(printed_11 - Pc).max() > 1e-3
    # (22): Delta P_ij = Pxz^i Pz^-1 Pxz^j^T, not Pxz^i Pz Pxz^j^T
    delta = (P - Pc).reshape(N, 2, N, 2)
    Pxz_abs = Pxz[inverse].reshape(N, 2)
    np.testing.assert_allclose(delta[1, :, 3, :], np.outer(Pxz_abs[1], Pxz_abs[3]) / Pz, atol=1e-10)
    assert abs(Pz - 1.0) > 0.1
    assert np.abs(delta[1, :, 3, :] - np.outer(Pxz_abs[1], Pxz_abs[3]) * Pz).max() > 1e-6


def test_departures_sigma_points_of_18_and_own_columns_of_20():
    """(20) summed over the up-neighbours' '+' columns only misses the receiver's own columns and the
    '-' points; with them it is the CCL cross-covariance."""
    rng = np.random.default_rng(7)
    x, P = random_problem(rng)
    m, n = 1, 3
    z = float(ur.range_of(x[m], x[n]))
    order, Pxz, Pz, A, dz = _ccl_quantities(x, P, m, n, z)
    w = ur.ukf_weights(L, 0.0)
    scale = np.sqrt(L)
    for place in range(N):  # receiver at chain position `place`
        rows = slice(2 * place, 2 * place + 2)
        own = 2 * (place + 1)
        full = scale * w[1] * A[rows, :own] @ (dz[1:1 + own] - dz[1 + L:1 + L + own])
        np.testing.assert_allclose(full, Pxz[rows], atol=1e-10)
        printed = scale * w[1] * A[rows, :2 * place] @ dz[1:1 + 2 * place]  # 2|neigh^u| '+' columns
        assert np.abs(printed - Pxz[rows]).max() > 1e-6


def test_time_update_moves_blocks_and_keeps_cross_covariances():
    rng = np.random.default_rng(8)
    x, P = random_problem(rng, (3,))
    speed, heading = rng.uniform(0.5, 1.5, (3, N)), rng.uniform(-np.pi, np.pi, (3, N))
    xn, Pn = ur.time_update(x, P, speed, heading, 0.5, 0.25, 1e-3)
    np.testing.assert_allclose(xn - x, 0.5 * speed[..., None] * np.stack([np.cos(heading), np.sin(heading)], -1))
    Q = ur.process_noise(speed, heading, 0.5, 0.25, 1e-3)
    diff = (Pn - P).reshape(3, N, 2, N, 2)
    for i, j in itertools.product(range(N), range(N)):
        np.testing.assert_allclose(diff[:, i, :, j, :], Q[:, i] if i == j else 0.0, atol=1e-14)


def test_process_noise_matches_the_displacement_spread():
    """Q is the first-order covariance of dt V_m [cos, sin] under speed and heading errors."""
    rng = np.random.default_rng(9)
    dt, speed, heading, speed_var, heading_var = 0.5, 1.3, 0.7, 0.04, 1e-4
    samples = 200_000
    v = speed + np.sqrt(speed_var) * rng.standard_normal(samples)
    phi = heading + np.sqrt(heading_var) * rng.standard_normal(samples)
    moves = dt * v[:, None] * np.stack([np.cos(phi), np.sin(phi)], -1)
    Q = ur.process_noise(np.array([speed]), np.array([heading]), dt, speed_var, heading_var)[0]
    np.testing.assert_allclose(np.cov(moves.T), Q, rtol=0.03, atol=1e-6)
    no_heading = ur.process_noise(np.array([speed]), np.array([heading]), dt, speed_var, 0.0)[0]
    assert np.linalg.matrix_rank(no_heading) == 1 and np.linalg.matrix_rank(Q) == 2


@pytest.mark.parametrize("shape, heading_var_shape", [((4,), ()), ((3, 4), (3, 4)), ((4,), (2, 4)), ((), ())])
def test_process_noise_is_the_two_rank_one_terms(shape, heading_var_shape):
    """Q = dt^2 sigma_v^2 u u^T + dt^2 V^2 sigma_phi^2 n n^T entry by entry, u along the heading, n across it,
    for batched speeds and headings and a heading variance of its own shape (broadcast)."""
    rng = np.random.default_rng(11)
    speed, heading = rng.uniform(0.0, 30.0, shape), rng.uniform(-7.0, 7.0, shape)
    heading_var = rng.uniform(0.0, 0.1, heading_var_shape)
    dt, speed_var = 0.1, 0.5
    Q = ur.process_noise(speed, heading, dt, speed_var, heading_var)
    u = np.stack([np.cos(heading), np.sin(heading)], -1)
    n = np.stack([-np.sin(heading), np.cos(heading)], -1)
    lateral = dt**2 * speed**2 * heading_var
    expected = (dt**2 * speed_var * np.einsum("...r,...c->...rc", u, u)
                + lateral[..., None, None] * np.einsum("...r,...c->...rc", n, n))
    assert Q.shape == (*np.broadcast_shapes(shape, heading_var_shape), 2, 2)
    np.testing.assert_allclose(Q, expected, rtol=1e-14, atol=1e-18)
    np.testing.assert_allclose(Q, np.swapaxes(Q, -1, -2), rtol=1e-14, atol=1e-18)


def test_bad_inputs_are_refused():
    rng = np.random.default_rng(10)
    x, P = random_problem(rng)
    with pytest.raises(ValueError, match="revisit"):
        ur.dcl_update(x, P, np.array([0, 1, 0, -1]), 3, 10.0, 1.0)
    with pytest.raises(ValueError, match="chain_length"):
        ur.dcl_update(x, P, np.array([0, -1, -1, -1]), 1, 10.0, 1.0)
    with pytest.raises(ValueError, match="m != n"):
        ur.dcl_update(x, P, np.array([2, 2, 1, 0]), 4, 10.0, 1.0)
    with pytest.raises(ValueError, match="truncation"):
        ur.dcl_update(x, P, np.array([0, 1, 2, 3]), 4, 10.0, 1.0, truncation="ignore")
    with pytest.raises(ValueError, match="differ"):
        ur.ccl_update(x, P, 1, 1, 10.0, 1.0)
    bad = P.copy()
    bad[0, 0] = -1.0
    with pytest.raises(np.linalg.LinAlgError, match="positive definite"):
        ur.dcl_update(x, bad, np.array([0, 1, 2, 3]), 4, 10.0, 1.0)
