"""Baselines of wan2014: dead reckoning and least squares against normal neighbours (ref. [7]).

Wan et al. 2014 compare dNBP with "the traditional cooperative localization
method in [7], where the fault UAVs are located based on nearby normal ones
only". The equations are lost in extraction; this module reconstructs them
from the paper's description (tags: [paper] stated in the text, [chosen]
chosen here where the paper gives none). Its noise parameters (``*_std``, sigma_gps, sigma_d,
sigma_acc) are standard deviations, as the paper states them.

**DR / GPS-only** (non-cooperative): a linear Kalman filter per UAV on the
constant-velocity model x(k+1) = F x + G a_hat + w, Q = sigma_acc^2 G G^T,
updated with the GPS fix (R = sigma_gps^2 I2) when the receiver is normal,
prediction only when it is faulty.

**LS [7]**: the same filter; a fault UAV with at least ``min_anchors`` (3
[chosen]) GPS-normal neighbours computes a snapshot fix against their KF
position estimates a_k and its measured ranges d_k, by Gauss-Newton on
sum_k (d_k - ||p - a_k||)^2 (<= 20 iterations, step tolerance 1e-4 m),
started from its predicted position and, if that fix fails the gate, from
the linearised solution 2 (a_k - a_1)^T p = d_1^2 - d_k^2 + ||a_k||^2 - ||a_1||^2.
Gate [chosen]: residual RMS <= 3 sigma_d, sqrt(tr sigma_d^2 (J^T J)^-1) <= 10
sigma_d and nu^T (C_pp + sigma_d^2 (J^T J)^-1)^-1 nu <= 13.8 with nu = p - p_pred.
An accepted fix is the output and a position pseudo-measurement of the KF
with covariance C_fix (below); otherwise the output is the dead-reckoning
estimate (the KF's). No fault-to-fault cooperation.

Reported covariance (``update``'s ``estimate_cov``): the covariance of the
estimate that is output. Where that is the KF mean it is the KF posterior
P_pp; where it is a fix it is the fix's Gauss-Newton covariance at the
solution p, with the anchors' own uncertainty in each range's variance:

    C_fix = (sum_k u_k u_k^T / s_k^2)^-1,  s_k^2 = sigma_d^2 + u_k^T C_k u_k,  u_k = (p - a_k) / ||p - a_k||

(C_k: anchor k's KF posterior position covariance, the 2 x 2 block its
broadcast carries with its estimate). The residual d_k - ||p - a_k|| linearised
at p is nu_k - u_k^T e_k (range noise nu_k, anchor error e_k, independent across
anchors), so s_k^2 is its variance and C_fix the covariance of the weighted
Gauss-Newton solution. sigma_d^2 (J^T J)^-1 (C_k = 0) leaves the anchors'
error out: the fixes were about 4 times overconfident with it (docs/consistency.md,
"wan2014: dNBP and range_ls covariances"). The KF posterior after fusing the fix
is not the fix's covariance: the output is the fix, not the fused mean. C_fix
is also the KF's pseudo-measurement covariance [chosen; it treats successive
fixes as independent, while an anchor's error persists from step to step].
The gate keeps sigma_d^2 (J^T J)^-1, as the reconstruction states it.

Arrays carry a leading batch axis B and the UAV axis N; everything is
vectorized: each fault UAV's normal neighbours are gathered into a list
padded to the largest neighbour count K of the step (a mask marks the
padding), so a Gauss-Newton iteration costs O(J K) for J fault UAVs. Covariance updates use the
Joseph form and are symmetrized.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.models import per_copy

__all__ = ["LsParams", "KalmanState", "initial_state", "predict", "update_position", "gauss_newton",
           "fix_covariance", "linearized_fix", "step", "update"]


@dataclass(frozen=True)
class LsParams:
    """Parameters of the baselines (the gates and the Gauss-Newton iteration of the module docstring).

    | field          | default | tag      | meaning                                                |
    |----------------|---------|----------|--------------------------------------------------------|
    | min_anchors    | 3       | [chosen] | ls_min_anchors: normal neighbours needed for a fix     |
    | max_rms        | 3       | [chosen] | ls_max_rms: residual RMS gate, in units of sigma_d     |
    | max_std        | 10      | [chosen] | ls_max_std: sqrt(tr cov) gate, in units of sigma_d     |
    | gate_chi2      | 13.8    | [chosen] | ls_gate_chi2: chi^2_2 99.9 % innovation gate           |
    | max_iterations | 20      | [chosen] | Gauss-Newton iterations                                |
    | tolerance      | 1e-4    | [chosen] | Gauss-Newton step tolerance [m]                        |
    | cooperative    | True    |          | False: no fixes at all (the DR / GPS-only baseline)    |
    """

    min_anchors: int = 3
    max_rms: float = 3.0
    max_std: float = 10.0
    gate_chi2: float = 13.8
    max_iterations: int = 20
    tolerance: float = 1e-4
    cooperative: bool = True


@dataclass
class KalmanState:
    """Per-UAV predicted mean (B, N, 4) and covariance (B, N, 4, 4) of the current step."""

    mean: np.ndarray
    cov: np.ndarray


def initial_state(mean: np.ndarray, cov: np.ndarray) -> KalmanState:
    """mean (B, N, 4), cov (4, 4) or (B, N, 4, 4)."""
    mean = np.asarray(mean, float)
    return KalmanState(mean.copy(), np.broadcast_to(np.asarray(cov, float), (*mean.shape, 4)).copy())


def _sym(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def predict(state: KalmanState, accel: np.ndarray, F: np.ndarray, G: np.ndarray, Q: np.ndarray) -> KalmanState:
    mean = state.mean @ F.T + accel @ G.T
    cov = _sym(F @ state.cov @ F.T + Q)
    return KalmanState(mean, cov)


def update_position(state: KalmanState, z: np.ndarray, R: np.ndarray, mask: np.ndarray) -> KalmanState:
    """Joseph-form update with a position measurement z (B, N, 2), covariance R (B, N, 2, 2), where ``mask``.

    The state is any (B, N, d) with the position first (H = [I2 0])."""
    d = state.mean.shape[-1]
    H = np.zeros((2, d))
    H[0, 0] = H[1, 1] = 1.0
    P = state.cov
    S = P[..., :2, :2] + R
    K = np.linalg.solve(S, P[..., :2, :]).swapaxes(-1, -2)  # P H^T S^-1 (S symmetric)
    innovation = np.where(mask[..., None], z - state.mean[..., :2], 0.0)
    mean = state.mean + np.einsum("...ij,...j->...i", K, innovation)
    IKH = np.eye(d) - K @ H
    cov = _sym(IKH @ P @ IKH.swapaxes(-1, -2) + K @ R @ K.swapaxes(-1, -2))
    return KalmanState(np.where(mask[..., None], mean, state.mean), np.where(mask[..., None, None], cov, P))


def _normal_matrix(p: np.ndarray, anchors: np.ndarray, ranges: np.ndarray, mask: np.ndarray):
    diff = p[:, None, :] - anchors
    dist = np.maximum(np.linalg.norm(diff, axis=-1), 1e-9)
    H = np.where(mask[..., None], diff / dist[..., None], 0.0)
    residual = np.where(mask, ranges - dist, 0.0)
    return H, residual


def gauss_newton(start: np.ndarray, anchors: np.ndarray, ranges: np.ndarray, mask: np.ndarray,
                 max_iterations: int = 20, tolerance: float = 1e-4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimize sum_k (d_k - ||p - a_k||)^2 for J problems.

    start (J, 2), anchors (J, K, 2), ranges (J, K), mask (J, K). Returns
    (p (J, 2), J^T J (J, 2, 2) at p, residual RMS (J,)). Rows converge
    independently (a converged row stops moving).
    """
    p = np.asarray(start, float).copy()
    active = np.ones(len(p), bool)
    for _ in range(max_iterations):
        H, residual = _normal_matrix(p, anchors, ranges, mask)
        JtJ = np.einsum("jki,jkl->jil", H, H)
        det = JtJ[:, 0, 0] * JtJ[:, 1, 1] - JtJ[:, 0, 1] ** 2
        good = active & (det > 1e-12)
        rhs = np.einsum("jki,jk->ji", H, residual)
        delta = np.zeros_like(p)
        if good.any():
            delta[good] = np.linalg.solve(JtJ[good], rhs[good][..., None])[..., 0]
        p = p + delta
        active = good & (np.linalg.norm(delta, axis=-1) > tolerance)
        if not active.any():
            break
    H, residual = _normal_matrix(p, anchors, ranges, mask)
    JtJ = np.einsum("jki,jkl->jil", H, H)
    rms = np.sqrt(np.sum(residual**2, axis=-1) / np.maximum(mask.sum(axis=-1), 1))
    return p, JtJ, rms


def fix_covariance(p: np.ndarray, anchors: np.ndarray, anchor_cov: np.ndarray, mask: np.ndarray,
                   range_std: np.ndarray) -> np.ndarray:
    """C_fix = (sum_k u_k u_k^T / s_k^2)^-1 with s_k^2 = sigma_d^2 + u_k^T C_k u_k (the module's "Reported
    covariance") for J fixes: p (J, 2), anchors (J, K, 2), anchor_cov (J, K, 2, 2), mask (J, K), range_std (J,)
    sigma_d. The fixes must have two independent directions (J^T J nonsingular, as the gate requires)."""
    u, _ = _normal_matrix(p, anchors, np.zeros(mask.shape), mask)
    var = np.asarray(range_std, float)[:, None] ** 2 + np.einsum("jki,jkil,jkl->jk", u, anchor_cov, u)
    info = np.einsum("jki,jkl,jk->jil", u, u, np.where(mask, 1.0 / var, 0.0))
    return _sym(np.linalg.inv(info))


def linearized_fix(anchors: np.ndarray, ranges: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Linear LS: subtract the first anchor's squared-range equation from the others (J, 2)."""
    first = np.argmax(mask, axis=-1)
    rows = np.arange(len(anchors))
    a1, d1 = anchors[rows, first], ranges[rows, first]
    A = 2.0 * (anchors - a1[:, None, :])
    b = d1[:, None] ** 2 - ranges**2 + np.sum(anchors**2, axis=-1) - np.sum(a1**2, axis=-1)[:, None]
    use = mask.copy()
    use[rows, first] = False
    A = np.where(use[..., None], A, 0.0)
    b = np.where(use, b, 0.0)
    AtA = np.einsum("jki,jkl->jil", A, A)
    Atb = np.einsum("jki,jk->ji", A, b)
    return np.einsum("jil,jl->ji", np.linalg.pinv(AtA), Atb)


def _gate(p, JtJ, rms, p_pred, C_pp, range_std, params):
    """range_std (J,): sigma_d of each fix's copy."""
    det = JtJ[:, 0, 0] * JtJ[:, 1, 1] - JtJ[:, 0, 1] ** 2
    ok = det > 1e-12
    safe = np.where(ok[:, None, None], JtJ, np.eye(2))
    cov = range_std[:, None, None] ** 2 * np.linalg.inv(safe)
    nu = p - p_pred
    S = C_pp + cov
    chi2 = np.einsum("ji,ji->j", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    accept = (ok & (rms <= params.max_rms * range_std)
              & (np.sqrt(np.trace(cov, axis1=-2, axis2=-1)) <= params.max_std * range_std)
              & (chi2 <= params.gate_chi2))
    return accept, cov


def step(params: LsParams, state: KalmanState, gps_normal: np.ndarray, gps_fix: np.ndarray, adjacency: np.ndarray,
         ranges: np.ndarray, accel: np.ndarray, F: np.ndarray, G: np.ndarray, Q: np.ndarray,
         gps_std: float | np.ndarray, range_std: float | np.ndarray) -> tuple[KalmanState, np.ndarray, np.ndarray]:
    """One step tau for B copies: GPS updates, LS fixes of fault UAVs, outputs, then prediction to tau + 1.

    ``state`` holds the predictions of tau. Returns (state of tau + 1,
    estimates (B, N, 2), fixed (B, N) bool: fault UAVs whose fix passed the gate).
    ``update`` followed by ``predict`` with the linear model (F, G, Q). ``gps_std`` and ``range_std`` are
    standard deviations (sigma_gps, sigma_d in m), not the variances the other estimators take.
    """
    posterior, estimate, _, fixed = update(params, state, gps_normal, gps_fix, adjacency, ranges, gps_std,
                                           range_std)
    return predict(posterior, accel, F, G, Q), estimate, fixed


def update(params: LsParams, state: KalmanState, gps_normal: np.ndarray, gps_fix: np.ndarray, adjacency: np.ndarray,
           ranges: np.ndarray, gps_std: float | np.ndarray, range_std: float | np.ndarray
           ) -> tuple[KalmanState, np.ndarray, np.ndarray, np.ndarray]:
    """The measurement half of ``step``: GPS updates, then the gated LS fixes of fault UAVs.

    ``state`` (any state dimension d >= 2, position first) holds the predictions of tau. Returns the
    posterior of tau, the estimates (B, N, 2), their covariance ``estimate_cov`` (B, N, 2, 2: C_fix where
    ``fixed``, else the posterior's position block; the module's "Reported covariance") and ``fixed``
    (B, N). The caller predicts with its own
    motion model (``predict`` for the linear constant-velocity one). ``gps_std`` and ``range_std`` are standard
    deviations (sigma_gps, sigma_d in m), not variances: one float for every copy or a (B,) array of each
    copy's.
    """
    gps_normal = np.asarray(gps_normal, bool)
    B, N = gps_normal.shape
    gps_std, range_std = per_copy("gps_std", gps_std, B), per_copy("range_std", range_std, B)
    R_gps = np.broadcast_to(gps_std[:, None, None, None] ** 2 * np.eye(2), (B, N, 2, 2))
    posterior = update_position(state, np.nan_to_num(gps_fix), R_gps, gps_normal)
    estimate = posterior.mean[..., :2].copy()
    fix_cov = None
    fixed = np.zeros((B, N), bool)
    anchors_ok = adjacency & gps_normal[:, None, :]  # [b, s, k]: k is a normal neighbour of s
    candidates = ~gps_normal & (anchors_ok.sum(axis=-1) >= params.min_anchors)
    if params.cooperative and candidates.any():
        b_idx, s_idx = np.nonzero(candidates)
        # each fault UAV's normal neighbours, in index order, padded to the most any of them has (K <= N):
        # the Gauss-Newton work follows the neighbour count, not the swarm size
        mask = anchors_ok[b_idx, s_idx]
        order = np.argsort(~mask, axis=1, kind="stable")[:, :int(mask.sum(axis=1).max())]
        anchors = posterior.mean[b_idx[:, None], order, :2]
        d = np.take_along_axis(ranges[b_idx, s_idx], order, axis=1)
        mask = np.take_along_axis(mask, order, axis=1)
        p_pred = state.mean[b_idx, s_idx, :2]
        C_pp = state.cov[b_idx, s_idx, :2, :2]
        p, JtJ, rms = gauss_newton(p_pred, anchors, d, mask, params.max_iterations, params.tolerance)
        accept, cov = _gate(p, JtJ, rms, p_pred, C_pp, range_std[b_idx], params)
        retry = ~accept
        if retry.any():
            p2, JtJ2, rms2 = gauss_newton(linearized_fix(anchors[retry], d[retry], mask[retry]), anchors[retry],
                                          d[retry], mask[retry], params.max_iterations, params.tolerance)
            accept2, cov2 = _gate(p2, JtJ2, rms2, p_pred[retry], C_pp[retry], range_std[b_idx][retry], params)
            p[retry], cov[retry], accept[retry] = p2, cov2, accept2
        fb, fs = b_idx[accept], s_idx[accept]
        fixed[fb, fs] = True
        z = np.zeros((B, N, 2))
        R = np.broadcast_to(np.eye(2), (B, N, 2, 2)).copy()
        anchor_cov = posterior.cov[b_idx[accept][:, None], order[accept], :2, :2]
        fix_cov = fix_covariance(p[accept], anchors[accept], anchor_cov, mask[accept], range_std[fb])
        z[fb, fs], R[fb, fs] = p[accept], fix_cov
        posterior = update_position(posterior, z, R, fixed)
        estimate[fb, fs] = p[accept]
    estimate_cov = posterior.cov[..., :2, :2].copy()
    if fix_cov is not None:
        estimate_cov[fixed] = fix_cov
    return posterior, estimate, estimate_cov, fixed
