"""range_ls reports the covariance of the estimate it outputs: a fix's Gauss-Newton covariance with the
anchors' uncertainty (``estimators.range_ls.fix_covariance``)."""

from __future__ import annotations

import numpy as np

import estimators.range_ls as rl

# four anchors around the origin, ~200 m away, each with its own estimate covariance
ANCHORS = np.array([[180.0, 40.0], [-150.0, 120.0], [20.0, -210.0], [-90.0, -160.0]])
ANCHOR_COV = np.array([[[9.0, 2.0], [2.0, 4.0]], [[4.0, -1.0], [-1.0, 6.0]], [[2.0, 0.0], [0.0, 8.0]],
                       [[5.0, 1.5], [1.5, 5.0]]])
RANGE_STD = 2.0


def _fixes(trials: int, seed: int):
    """``trials`` fixes of the origin against noisy anchor estimates and noisy ranges: (fixes, J^T J, anchors)."""
    rng = np.random.default_rng(seed)
    truth = np.zeros(2)
    factor = np.linalg.cholesky(ANCHOR_COV)
    anchors = ANCHORS + np.einsum("kij,tkj->tki", factor, rng.standard_normal((trials, 4, 2)))
    ranges = np.linalg.norm(ANCHORS - truth, axis=-1) + RANGE_STD * rng.standard_normal((trials, 4))
    mask = np.ones((trials, 4), bool)
    p, JtJ, _ = rl.gauss_newton(np.zeros((trials, 2)) + 5.0, anchors, ranges, mask)
    return p, JtJ, anchors, mask


def _nees(error, cov):
    return np.einsum("ti,ti->t", error, np.linalg.solve(cov, error[..., None])[..., 0])


def test_fix_covariance_without_anchor_uncertainty_is_sigma_d_squared_inverse_jtj():
    p, JtJ, anchors, mask = _fixes(50, 1)
    cov = rl.fix_covariance(p, anchors, np.zeros((50, 4, 2, 2)), mask, np.full(50, RANGE_STD))
    np.testing.assert_allclose(cov, RANGE_STD**2 * np.linalg.inv(JtJ), rtol=1e-9, atol=0)


def test_fix_covariance_describes_the_fix_error_where_sigma_d_alone_does_not():
    trials = 4000
    p, JtJ, anchors, mask = _fixes(trials, 2)
    cov = rl.fix_covariance(p, anchors, np.broadcast_to(ANCHOR_COV, (trials, 4, 2, 2)), mask,
                            np.full(trials, RANGE_STD))
    honest = _nees(p, cov)  # truth at the origin: the error is p
    ranges_only = _nees(p, RANGE_STD**2 * np.linalg.inv(JtJ))
    # chi^2(2): mean 2, the mean of 4000 has a standard deviation of 0.032
    assert abs(honest.mean() - 2.0) < 0.15, honest.mean()
    assert ranges_only.mean() > 3.0, ranges_only.mean()


def test_update_reports_the_fix_covariance_where_it_outputs_a_fix():
    rng = np.random.default_rng(3)
    N = 6
    truth = np.vstack([ANCHORS, [[0.0, 0.0], [30.0, 10.0]]])
    normal = np.array([True, True, True, True, False, False])
    d = np.linalg.norm(truth[:, None] - truth[None], axis=-1)
    adjacency = d > 0
    noise = np.triu(rng.normal(0.0, RANGE_STD, d.shape), 1)
    ranges = np.where(adjacency, d + noise + noise.T, 0.0)
    mean = np.zeros((1, N, 4))
    mean[0, :, :2] = truth + rng.normal(0.0, 3.0, truth.shape)
    state = rl.initial_state(mean, np.diag([25.0, 25.0, 4.0, 4.0]))
    fix = np.where(normal[:, None], truth + rng.normal(0.0, 3.0, truth.shape), np.nan)
    posterior, estimate, estimate_cov, fixed = rl.update(rl.LsParams(), state, normal[None], fix[None],
                                                         adjacency[None], ranges[None], 3.0, RANGE_STD)
    assert fixed[0, 4:].all() and not fixed[0, :4].any()
    # fixed: the fix's covariance against the anchors' posterior covariances; else the KF posterior's
    anchors = np.broadcast_to(posterior.mean[0, :4, :2], (2, 4, 2))
    anchor_cov = np.broadcast_to(posterior.cov[0, :4, :2, :2], (2, 4, 2, 2))
    expected = rl.fix_covariance(estimate[0, 4:], anchors, anchor_cov, np.ones((2, 4), bool), np.full(2, RANGE_STD))
    np.testing.assert_allclose(estimate_cov[0, 4:], expected, rtol=1e-9, atol=0)
    np.testing.assert_allclose(estimate_cov[0, :4], posterior.cov[0, :4, :2, :2], rtol=0, atol=0)
    # the fix is the output; the KF mean fused it with the prediction
    assert not np.allclose(posterior.mean[0, 4:, :2], estimate[0, 4:])
