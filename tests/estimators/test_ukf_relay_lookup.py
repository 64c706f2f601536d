"""The look-up form of the UKF range update and the rank-k fix update equal today's sigma-point, hop-by-hop and
Joseph paths (the same arithmetic reorganized: 1e-9), reading by reading and over whole sequences."""

from __future__ import annotations

import numpy as np
import pytest

import estimators.ukf_relay as ur
from estimators.kalman import joseph_update


def problem(rng, B, N, d):
    L = d * N
    x = rng.normal(scale=40.0, size=(B, N, d))
    G = rng.normal(size=(B, L, L))
    return x, G @ np.swapaxes(G, -1, -2) / L + 4.0 * np.eye(L)


def pairs(rng, B, J, N):
    m = rng.integers(0, N, size=(B, J))
    return m, (m + rng.integers(1, N, size=(B, J))) % N


@pytest.mark.parametrize("d,lam", [(2, 0.0), (4, 0.0), (4, 0.7)])
def test_one_lookup_range_update_equals_the_2L_plus_1_sigma_points(d, lam):
    rng = np.random.default_rng(d)
    B, N = 6, 5
    x, P = problem(rng, B, N, d)
    m, n = pairs(rng, B, 1, N)
    z = rng.uniform(10.0, 90.0, B)
    reached = rng.random((B, N)) < 0.5
    reached[np.arange(B), m[:, 0]] = reached[np.arange(B), n[:, 0]] = True
    for keep in (None, reached):
        xs, Ps = ur.ccl_update(x, P, m[:, 0], n[:, 0], z, 4.0, lam, reached=keep, method="sigma")
        xl, Pl = ur.ccl_update(x, P, m[:, 0], n[:, 0], z, 4.0, lam, reached=keep)
        np.testing.assert_allclose(xl, xs, atol=1e-9, rtol=0)
        np.testing.assert_allclose(Pl, Ps, atol=1e-9, rtol=0)


@pytest.mark.parametrize("d", [2, 4])
def test_a_sequence_of_readings_folded_in_blocks_equals_the_readings_one_by_one(d):
    """J = 23 readings with block 4 (five folds of the kept rank-2 terms), some inactive, with and without the
    reached masks of truncated chains, against ccl_update's sigma points applied one reading at a time."""
    rng = np.random.default_rng(10 + d)
    B, N, J, lam, R = 3, 6, 23, 0.3, 2.5
    x, P = problem(rng, B, N, d)
    m, n = pairs(rng, B, J, N)
    z = rng.uniform(10.0, 90.0, (B, J))
    active = rng.random((B, J)) < 0.8
    reached = rng.random((B, J, N)) < 0.6
    b, j = np.indices((B, J))
    reached[b, j, m] = reached[b, j, n] = True
    for keep in (None, reached):
        xl, Pl = x.copy(), P.copy()
        ur.range_updates(xl, Pl, m, n, np.where(active, z, np.nan), active, R, lam, keep, block=4)
        xs, Ps = x.copy(), P.copy()
        for jj in range(J):
            for bb in np.flatnonzero(active[:, jj]):
                xs[bb], Ps[bb] = ur.ccl_update(xs[bb], Ps[bb], m[bb, jj], n[bb, jj], z[bb, jj], R, lam,
                                               reached=None if keep is None else keep[bb, jj], method="sigma")
        np.testing.assert_allclose(xl, xs, atol=1e-9, rtol=0)
        np.testing.assert_allclose(Pl, Ps, atol=1e-9, rtol=0)
        np.testing.assert_array_equal(Pl, np.swapaxes(Pl, -1, -2))


@pytest.mark.parametrize("truncation", ["consistent", "paper"])
def test_the_closed_form_chain_equals_the_chain_hop_by_hop(truncation):
    rng = np.random.default_rng(3)
    B, N, d = 8, 6, 4
    x, P = problem(rng, B, N, d)
    chains = np.array([rng.permutation(N) for _ in range(B)])
    length = rng.integers(2, N + 1, size=B)
    padded = np.where(np.arange(N) < length[:, None], chains, -1)
    z = rng.uniform(10.0, 90.0, B)
    xc, Pc = ur.dcl_update(x, P, padded, length, z, 1.0, 0.0, truncation, method="chain")
    xl, Pl = ur.dcl_update(x, P, padded, length, z, 1.0, 0.0, truncation, method="lookup")
    np.testing.assert_allclose(xl, xc, atol=1e-9, rtol=0)
    np.testing.assert_allclose(Pl, Pc, atol=1e-9, rtol=0)


def test_fix_updates_equal_the_joseph_form_agent_by_agent():
    rng = np.random.default_rng(5)
    B, N, d = 5, 5, 4
    L = d * N
    x, P = problem(rng, B, N, d)
    fix = rng.normal(scale=40.0, size=(B, N, 2))
    active = rng.random((B, N)) < 0.7
    R = np.array([[9.0, 1.0], [1.0, 4.0]])
    reached = rng.random((B, N, N)) < 0.5
    reached[:, np.arange(N), np.arange(N)] = True
    for keep in (None, reached):
        xl, Pl = x.copy(), P.copy()
        ur.fix_updates(xl, Pl, np.where(active[..., None], fix, np.nan), active, R, keep)
        xj, Pj = x.reshape(B, L).copy(), P.copy()
        for i in range(N):
            H = np.zeros((2, L))
            H[:, d * i:d * i + 2] = np.eye(2)
            used = np.flatnonzero(active[:, i])
            rows = None if keep is None else np.repeat(keep[used, i], d, axis=-1)
            xj[used], Pj[used] = joseph_update(xj[used], Pj[used], H, fix[used, i], R, rows)
        np.testing.assert_allclose(xl.reshape(B, L), xj, atol=1e-9, rtol=0)
        np.testing.assert_allclose(Pl, Pj, atol=1e-9, rtol=0)


def test_bad_input_names_the_argument():
    rng = np.random.default_rng(0)
    x, P = problem(rng, 2, 3, 2)
    with pytest.raises(ValueError, match="method must be 'lookup' or 'sigma'"):
        ur.ccl_update(x, P, [0, 1], [1, 2], [5.0, 5.0], 1.0, method="full")
    with pytest.raises(ValueError, match="method must be 'lookup' or 'chain'"):
        ur.dcl_update(x, P, np.array([[0, 1, 2]] * 2), [3, 3], [5.0, 5.0], 1.0, method="sigma")
    with pytest.raises(ValueError, match="measuring and measured platforms must differ"):
        ur.range_updates(x, P, np.array([[1], [0]]), np.array([[1], [2]]), np.ones((2, 1)), np.ones((2, 1), bool),
                         1.0)
