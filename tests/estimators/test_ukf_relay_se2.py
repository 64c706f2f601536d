"""UKF-DCL on (x, y, theta) with the Roumeliotis-Bekey factorization equals UKF-CCL (1e-9)."""

from __future__ import annotations

import os

import numpy as np
import pytest

import estimators.ukf_relay_se2 as se2

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.conftest import MRCLAM_DATASET6 as DATASET6  # noqa: E402
from tests.conftest import MRCLAM_SKIP_REASON  # noqa: E402

R = np.diag([0.1**2, 0.05**2])
Q = (0.05**2, 0.2**2)


def _random_state(rng, N=4):
    x = np.column_stack([rng.uniform(-3, 3, (N, 2)), rng.uniform(-np.pi, np.pi, N)])
    a = rng.normal(size=(3 * N, 3 * N)) * 0.1
    return x, a @ a.T + 0.01 * np.eye(3 * N)


@pytest.mark.parametrize("landmark", [False, True])
@pytest.mark.parametrize("length", [2, 3, 4])
def test_dcl_equals_ccl_after_factored_time_updates(landmark, length):
    rng = np.random.default_rng(1)
    N = 4
    x, P = _random_state(rng, N)
    f = se2.factor(P)
    xd = x.copy()
    for _ in range(3):  # Phi_i != I before the update
        u = rng.normal(size=(N, 2)) * [0.3, 0.5]
        x, P = se2.time_update(x, P, u, 0.1, Q)
        xd, f = se2.time_update_factored(xd, f, u, 0.1, Q)
    chain = [2, 0, 3, 1][:length]
    reached = np.isin(np.arange(N), chain)
    z = np.array([2.0, 0.3])
    if landmark:
        lm = np.array([1.0, -2.0])
        x1, P1, _ = se2.ccl_update(x, P, 2, z, R, landmark=lm, reached=reached)
        x2, f2, _ = se2.dcl_update(xd, f, chain, z, R, measured_in_chain=False, landmark=lm)
    else:
        x1, P1, _ = se2.ccl_update(x, P, 2, z, R, measured=0, reached=reached)
        x2, f2, _ = se2.dcl_update(xd, f, chain, z, R)
    assert np.max(np.abs(x1 - x2)) < 1e-9
    assert np.max(np.abs(P1 - f2.joint())) < 1e-9
    assert np.all(np.linalg.eigvalsh(P1) > 0)


def test_chain_order_after_observers_does_not_matter():
    rng = np.random.default_rng(2)
    x, P = _random_state(rng)
    f = se2.factor(P)
    a = se2.dcl_update(x, f, [1, 3, 0, 2], [1.5, -0.2], R)
    b = se2.dcl_update(x, f, [1, 3, 2, 0], [1.5, -0.2], R)
    assert np.allclose(a[0], b[0], atol=1e-12) and np.allclose(a[1].joint(), b[1].joint(), atol=1e-12)


def test_gate_rejects_outlier():
    rng = np.random.default_rng(3)
    x, P = _random_state(rng)
    z = se2.observe(x[0], x[1, :2]) + [50.0, 0.0]
    _, _, applied = se2.ccl_update(x, P, 0, z, R, measured=1, gate=13.8)
    _, _, applied_d = se2.dcl_update(x, se2.factor(P), [0, 1], z, R, gate=13.8)
    assert not applied and not applied_d


def test_bad_arguments():
    rng = np.random.default_rng(4)
    x, P = _random_state(rng)
    with pytest.raises(ValueError, match="measured"):
        se2.ccl_update(x, P, 0, [1, 0], R, measured=0)
    with pytest.raises(ValueError, match="chain"):
        se2.dcl_update(x, se2.factor(P), [0, 0, 1], [1, 0], R)
    with pytest.raises(ValueError, match="odometry_var"):
        se2.time_update(x, P, np.zeros((4, 2)), 0.1, (-1.0, 0.0))


def test_dcl_equals_ccl_on_mrclam_slice():
    if not os.path.isdir(DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)
    from coloc_env.data import mrclam

    d = mrclam.load_cached(DATASET6, 0.1).window(0, 400)
    x = d.groundtruth[0].copy()
    P = 1e-4 * np.eye(15)
    xd, f = x.copy(), se2.factor(P)
    worst, applied = 0.0, 0
    for k in range(d.steps):
        s = d.measurements_at(k)
        for r, sub, rg, b in zip(d.meas_robot[s], d.meas_subject[s], d.meas_range[s], d.meas_bearing[s], strict=True):
            z = np.array([rg, b])
            if sub <= 5:
                chain = [r, sub - 1] + [i for i in range(5) if i not in (r, sub - 1)]
                x, P, a1 = se2.ccl_update(x, P, r, z, R, measured=sub - 1, gate=13.8)
                xd, f, a2 = se2.dcl_update(xd, f, chain, z, R, gate=13.8)
            else:
                chain = [r] + [i for i in range(5) if i != r]
                x, P, a1 = se2.ccl_update(x, P, r, z, R, landmark=d.landmarks[sub - 6], gate=13.8)
                xd, f, a2 = se2.dcl_update(xd, f, chain, z, R, measured_in_chain=False,
                                           landmark=d.landmarks[sub - 6], gate=13.8)
            assert a1 == a2
            applied += a1
        worst = max(worst, np.abs(x - xd).max(), np.abs(P - f.joint()).max())
        x, P = se2.time_update(x, P, d.odometry[k], d.dt, Q)
        xd, f = se2.time_update_factored(xd, f, d.odometry[k], d.dt, Q)
    assert applied > 100 and any(d.meas_subject <= 5)
    assert worst < 1e-9


def test_correct_odometry_shifts_and_scales():
    u = np.arange(12, dtype=float).reshape(6, 1, 2) + 1.0  # (T=6, N=1, 2)
    out = se2.correct_odometry(u, scale=(0.5, 2.0), delay=2)
    assert out.shape == u.shape
    assert np.allclose(out[2:], u[:-2] * [0.5, 2.0])  # command of step k - 2 moves the robot at step k
    assert np.allclose(out[:2], u[0] * [0.5, 2.0])  # before the first command: the first one held
    assert np.array_equal(se2.correct_odometry(u), u)
    with pytest.raises(ValueError, match="delay"):
        se2.correct_odometry(u, delay=-1)


def test_odometry_variance_speed_dependent():
    u = np.array([[0.0, 0.0], [0.1, 0.2], [0.3, -0.6]])
    q = se2.odometry_variance(u, (1e-4, 1e-3), (0.1, 0.2), (2.0, 3.0))
    assert np.allclose(q, [2.0, 3.0] * (np.array([1e-4, 1e-3]) + np.array([0.1, 0.2]) * u**2))
    assert np.all(np.diff(q[:, 0]) > 0) and np.all(np.diff(q[:, 1]) > 0)  # larger speed, larger sigma
    with pytest.raises(ValueError, match="var0"):
        se2.odometry_variance(u, (-1.0, 0.0))


def test_per_robot_odometry_variance():
    """(N, 2) variances: each robot's block gets its own G Q G^T; DCL still equals CCL."""
    rng = np.random.default_rng(5)
    N = 4
    x, P = _random_state(rng, N)
    u = rng.normal(size=(N, 2)) * [0.3, 0.5]
    q = se2.odometry_variance(u, (1e-4, 1e-3), (0.1, 0.2))
    x1, P1 = se2.time_update(x, P, u, 0.1, q)
    _, F, G = se2.motion(x, u, 0.1)
    for i in range(N):
        expected = F[i] @ P[3 * i:3 * i + 3, 3 * i:3 * i + 3] @ F[i].T + G[i] @ np.diag(q[i]) @ G[i].T
        assert np.allclose(P1[3 * i:3 * i + 3, 3 * i:3 * i + 3], expected, atol=1e-14)
    x2, f = se2.time_update_factored(x, se2.factor(P), u, 0.1, q)
    assert np.allclose(x1, x2, atol=1e-14) and np.max(np.abs(P1 - f.joint())) < 1e-12
    z = np.array([2.0, 0.3])
    a = se2.ccl_update(x1, P1, 1, z, R, measured=3)
    b = se2.dcl_update(x2, f, [1, 3, 0, 2], z, R)
    assert np.max(np.abs(a[0] - b[0])) < 1e-9 and np.max(np.abs(a[1] - b[1].joint())) < 1e-9
    with pytest.raises(ValueError, match="odometry_var"):
        se2.time_update(x, P, u, 0.1, np.ones((N - 1, 2)))


def _factored_copies(rng, copies, N=5):
    """``copies`` independent (estimate, FactoredCov) with Phi_i != I (three factored time updates each)."""
    out = []
    for _ in range(copies):
        x, P = _random_state(rng, N)
        f = se2.factor(P)
        for _ in range(3):
            x, f = se2.time_update_factored(x, f, rng.normal(size=(N, 2)) * [0.3, 0.5], 0.1, Q)
        out.append((x, f))
    return out


def _stack(copies):
    x = np.stack([c[0] for c in copies])
    return x, se2.FactoredCov(*(np.stack([getattr(c[1], a) for c in copies]) for a in ("P_ii", "phi", "sigma")))


@pytest.mark.parametrize(("landmark", "length"), [(True, k) for k in range(1, 6)] + [(False, k) for k in range(2, 6)])
def test_batched_dcl_equals_dcl_of_each_copy_alone(landmark, length):
    """dcl_update_batch on G = 6 copies (different states, chains, measurements; one refused by the gate) equals
    dcl_update of each copy (1e-12), and a copy's result does not depend on the others of its batch."""
    rng = np.random.default_rng(10 + length + 10 * landmark)
    N, G = 5, 6
    copies = _factored_copies(rng, G, N)
    chains = np.stack([rng.permutation(N)[:length] for _ in range(G)])
    lm = rng.uniform(-3, 3, (G, 2))
    z = np.stack([se2.observe(x[c[0]], lm[g] if landmark else x[c[1], :2])
                  for g, ((x, _), c) in enumerate(zip(copies, chains, strict=True))])
    z += rng.normal(size=(G, 2)) * [0.1, 0.05]
    z[3, 0] += 50.0  # an outlier: the gate refuses it in this copy only
    Rs = np.stack([np.diag([(0.05 + 0.02 * g) ** 2, 0.05**2]) for g in range(G)])
    kw = {"measured_in_chain": not landmark, "lam": 0.5, "gate": 13.8}
    x, f = _stack(copies)
    xb, fb, applied = se2.dcl_update_batch(x, f, chains, z, Rs, landmark=lm if landmark else None, **kw)
    assert applied.tolist() == [True, True, True, False, True, True]
    for g, (x1, f1) in enumerate(copies):
        x2, f2, ok = se2.dcl_update(x1, f1, chains[g], z[g], Rs[g], landmark=lm[g] if landmark else None, **kw)
        assert ok == applied[g]
        np.testing.assert_allclose(xb[g], x2, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fb.P_ii[g], f2.P_ii, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fb.sigma[g], f2.sigma, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(fb.phi[g], f2.phi)
    np.testing.assert_array_equal(xb[3], x[3])  # refused: unchanged
    np.testing.assert_array_equal(fb.sigma[3], f.sigma[3])
    # copies 1 and 4 alone, in place, inside the batch: the same bits, the other copies untouched
    xi, fi = x.copy(), f.copy()
    ok = se2.dcl_update_rows(xi, fi.P_ii, fi.phi, fi.sigma, [4, 1], chains[[4, 1]], z[[4, 1]], Rs[[4, 1]],
                             landmark=lm[[4, 1]] if landmark else None, **kw)
    assert ok.tolist() == [True, True]
    for g in range(G):
        source = (xb, fb) if g in (1, 4) else (x, f)
        np.testing.assert_array_equal(xi[g], source[0][g])
        np.testing.assert_array_equal(fi.P_ii[g], source[1].P_ii[g])
        np.testing.assert_array_equal(fi.sigma[g], source[1].sigma[g])


def test_batched_dcl_of_a_complete_chain_is_ccl():
    rng = np.random.default_rng(21)
    copies = _factored_copies(rng, 3, 4)
    chains = np.array([[0, 2, 1, 3], [3, 1, 0, 2], [1, 0, 3, 2]])
    z = np.array([[2.0, 0.3], [1.5, -0.4], [0.8, 2.9]])
    xb, fb, applied = se2.dcl_update_batch(*_stack(copies), chains, z, R)
    assert applied.all()
    for g, (x, f) in enumerate(copies):
        x1, P1, _ = se2.ccl_update(x, f.joint(), chains[g, 0], z[g], R, measured=chains[g, 1])
        assert np.max(np.abs(x1 - xb[g])) < 1e-9
        joint = se2.FactoredCov(fb.P_ii[g], fb.phi[g], fb.sigma[g]).joint()
        assert np.max(np.abs(P1 - joint)) < 1e-9


def test_batched_time_update_equals_each_copy_alone():
    rng = np.random.default_rng(22)
    copies = _factored_copies(rng, 4, 5)
    u = rng.normal(size=(4, 5, 2)) * [0.3, 0.5]
    q = se2.odometry_variance(u, (1e-4, 1e-3), (0.1, 0.2))
    x, f = _stack(copies)
    for var in (q, Q, q[0]):  # per copy and robot, one pair, one pair per robot shared by the copies
        xb, P_ii, phi = se2.time_update_batch(x, f.P_ii, f.phi, u, 0.1, var)
        for g, (x1, f1) in enumerate(copies):
            x2, f2 = se2.time_update_factored(x1, f1, u[g], 0.1, var if np.ndim(var) < 3 else var[g])
            np.testing.assert_allclose(xb[g], x2, rtol=0, atol=1e-12)
            np.testing.assert_allclose(P_ii[g], f2.P_ii, rtol=0, atol=1e-12)
            np.testing.assert_allclose(phi[g], f2.phi, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="odometry_var"):
        se2.time_update_batch(x, f.P_ii, f.phi, u, 0.1, q[:, :4])


def test_batched_dcl_bad_arguments():
    x, f = _stack(_factored_copies(np.random.default_rng(23), 2, 4))
    with pytest.raises(ValueError, match="chain must list distinct robots"):
        se2.dcl_update_batch(x, f, [[0, 1, 1], [0, 1, 2]], [[1, 0], [1, 0]], R)
    with pytest.raises(ValueError, match="chain must list distinct robots"):
        se2.dcl_update_batch(x, f, [[0, 4], [0, 1]], [[1, 0], [1, 0]], R)
    with pytest.raises(ValueError, match="must reach the measuring and the measured"):
        se2.dcl_update_batch(x, f, [[0], [1]], [[1, 0], [1, 0]], R)
    with pytest.raises(ValueError, match="rows must be distinct copies"):
        se2.dcl_update_rows(x, f.P_ii, f.phi, f.sigma, [1, 1], [[0, 1], [2, 3]], [[1, 0], [1, 0]], R)
    with pytest.raises(ValueError, match="landmark"):
        se2.dcl_update_batch(x, f, [[0], [1]], [[1, 0], [1, 0]], R, measured_in_chain=False)
