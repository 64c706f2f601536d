"""ccl_update_copies / time_update_copies: G stacked copies equal the single-copy updates copy by copy."""

from __future__ import annotations

import numpy as np
import pytest

import estimators.ukf_relay_se2 as se2

G, N = 4, 5


@pytest.fixture
def copies():
    rng = np.random.default_rng(7)
    x = rng.normal(size=(G, N, 3))
    A = rng.normal(size=(G, 3 * N, 3 * N))
    P = 0.01 * A @ np.swapaxes(A, -1, -2) + 0.01 * np.eye(3 * N)
    R = np.stack([np.diag([0.01 * (g + 1), 1e-3 * (g + 1)]) for g in range(G)])
    return x, P, R


@pytest.mark.parametrize("target", [{"measured": 3}, {"landmark": np.array([1.0, -2.0])}])
def test_ccl_update_copies_equals_ccl_update(copies, target):
    x, P, R = copies
    z = np.array([2.5, 0.4])
    gate = 6.0  # some copies pass, some do not
    xb, Pb, applied, nis = se2.ccl_update_copies(x, P, 1, z, R, gate=gate, **target)
    for g in range(G):
        xs, Ps, ok = se2.ccl_update(x[g], P[g], 1, z, R[g], gate=gate, **target)
        assert ok == applied[g]
        np.testing.assert_allclose(xb[g], xs, atol=1e-12)
        np.testing.assert_allclose(Pb[g], Ps, atol=1e-12)
        _, _, free = se2.ccl_update(x[g], P[g], 1, z, R[g], gate=float(nis[g]) * (1 + 1e-9), **target)
        _, _, shut = se2.ccl_update(x[g], P[g], 1, z, R[g], gate=float(nis[g]) * (1 - 1e-9), **target)
        assert free and not shut  # nis is the statistic the gate compares
    assert applied.any() and not applied.all()


def test_time_update_copies_equals_time_update(copies):
    x, P, _ = copies
    rng = np.random.default_rng(8)
    u = rng.normal(size=(N, 2))
    q = rng.uniform(1e-4, 1e-2, size=(G, N, 2))
    xb, Pb = se2.time_update_copies(x, P, u, 0.1, q)
    for g in range(G):
        xs, Ps = se2.time_update(x[g], P[g], u, 0.1, q[g])
        np.testing.assert_allclose(xb[g], xs, atol=1e-12)
        np.testing.assert_allclose(Pb[g], Ps, atol=1e-12)
