"""Kalman pieces shared by the filters: symmetrize, the Joseph-form update with an optional gain mask.

Arrays carry leading batch axes (``...``). The Joseph form

    P+ = (I - K H) P (I - K H)^T + K R K^T

is the covariance of the estimator x+ = x + K (z - H x) for *any* gain K, so
it stays the true covariance when part of the gain is forced to zero (rows of
agents a relay chain did not reach: the consistent truncation of wang2019's
chains, ``estimators.ukf_relay``), and it keeps P symmetric positive
semi-definite in floating point.
"""

from __future__ import annotations

import numpy as np

__all__ = ["symmetrize", "joseph_update"]


def symmetrize(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def joseph_update(mean: np.ndarray, cov: np.ndarray, H: np.ndarray, z: np.ndarray, R: np.ndarray,
                  keep_rows: np.ndarray | None = None):
    """Linear update of ``mean`` (..., n), ``cov`` (..., n, n) with z = H x + v, H (..., m, n), R (..., m, m).

    The optimal gain K = P H^T S^-1 (S = H P H^T + R, solved by Cholesky); with ``keep_rows``
    (..., n) bool, the rows outside it are set to zero first (those state entries keep their
    value). Returns new ``(mean, cov)``.
    """
    PHt = cov @ np.swapaxes(H, -1, -2)
    S = symmetrize(H @ PHt + R)
    try:
        lower = np.linalg.cholesky(S)
    except np.linalg.LinAlgError as exc:
        raise np.linalg.LinAlgError("joseph_update: the innovation covariance H P H^T + R is not positive "
                                    "definite") from exc
    # K = PHt S^-1 via two triangular solves on the transposed system S K^T = PHt^T.
    Kt = np.linalg.solve(np.swapaxes(lower, -1, -2), np.linalg.solve(lower, np.swapaxes(PHt, -1, -2)))
    K = np.swapaxes(Kt, -1, -2)
    if keep_rows is not None:
        K = K * np.asarray(keep_rows, float)[..., :, None]
    innovation = z - np.einsum("...ij,...j->...i", H, mean)
    new_mean = mean + np.einsum("...ij,...j->...i", K, innovation)
    n = mean.shape[-1]
    A = np.eye(n) - K @ H
    new_cov = A @ cov @ np.swapaxes(A, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
    return new_mean, symmetrize(new_cov)
