"""Posterior Cramér–Rao bound (PCRB) of discrete-time filtering, batched over Monte Carlo episodes.

Tichavský, Muravchik and Nehorai, "Posterior Cramér–Rao bounds for discrete-time
nonlinear filtering", IEEE Trans. Signal Processing 46(5):1386-1396, 1998 (TMN).
For x(k+1) = f_k(x(k)) + w(k), w ~ N(0, Q_k), and readings z(k) = h_k(x(k)) + v(k),
v ~ N(0, R_k), the information matrix J_k of x(k) obeys (TMN eq. 21 with eqs. 34-36)

    J_{k+1} = D22 - D21 (J_k + D11)^-1 D12,
    D11 = E[F_k^T Q_k^-1 F_k],  D12 = -E[F_k^T] Q_k^-1 = D21^T,  D22 = Q_k^-1 + E[H^T R^-1 H],

F_k = df_k/dx, H = dh_{k+1}/dx at the true state, and any estimator's error covariance
satisfies E[(xhat - x)(xhat - x)^T] >= J_k^-1. The expectations run over the
trajectories and readings: here they are Monte Carlo means over E episodes, taken
*per step* before the one recursion (a mean of per-episode bounds bounds the averaged
MSE only where what differs between the episodes is known to the estimator and
independent of its noises: the bound conditioned on it). Where the model lets Q_k
depend on the episode (drawn inputs), D12 reads -E[F_k^T Q_k^-1] and D22 -E[Q_k^-1] + ..., the same derivation with the
expectation taken over the pair.

Forms used (all exact rewrites of the recursion above, chosen by the arguments):

| case                                        | form                                                       |
|---------------------------------------------|------------------------------------------------------------|
| F_k and Q_k the same in every episode       | covariance form: P- = F P F^T + Q, P = (P-^-1 + I_z)^-1    |
|                                             | evaluated as P- - P- L (I + L^T P- L)^-1 L^T P- with       |
|                                             | I_z = L L^T: no inverse of Q or of P-, so a singular Q      |
|                                             | (position driven only through velocity) is exact           |
| F_k common, Q_k per episode                 | the same with Q_eff = (E[Q_k^-1])^-1 (the D-terms reduce   |
|                                             | to it: J+ = (F J^-1 F^T + Q_eff)^-1 + I_z, Woodbury)       |
| F_k per episode                             | the information form above                                  |

The last two invert each episode's Q_k. A singular one (odometry whose heading is known
exactly at k = 0: rank 1) is regularized to Q_k + eps (tr Q_k / n) I with eps =
``regularization`` (default 1e-9): more process noise. Where the episodes' singular Q_k
share their null space (circles at k = 0: every episode starts on the same heading) the
bound moves by O(eps) relative (a test measures < 1e-4 between eps = 1e-9 and 1e-11).
Where their null spaces differ, E[(Q_k + eps I)^-1] is large in every direction they
span, the averaged model has almost no process noise, and the bound, valid in the limit
(the TMN bound of the eps-model, whose MMSE tends to the exact one), becomes loose; a
problem like that (recorded SE(2) windows) is better run per episode in covariance form.

Fisher information of each reading kind (additive Gaussian noise, I = H^T R^-1 H at the
true state; "u" is the unit vector from the second point to the first):

| function                      | reading                                    | information                    |
|-------------------------------|--------------------------------------------|--------------------------------|
| ``linear_information``    | z = C x + v, v ~ N(0, R)                   | C^T R^-1 C                     |
| ``fix_information``       | position fix, per-axis variance s2         | I / s2 on the position block   |
| ``range_information``     | ||p_a - p_b|| + v, variance s2             | u u^T / s2 (a 2x2 block)       |
| ``pair_information``      | a range between two agents                 | [[B, -B], [-B, B]] on (a, b)   |
| (anchor range)                | to a known anchor: only the agent's block  | u u^T / s2                     |
| ``bearing_information``   | atan2 of p - s from a known s, variance s2 | n n^T / (d^2 s2), n normal to u|
| ``range_bearing_information`` | SE(2) pose observing a point: [r, b]   | H^T R^-1 H, H = [H_pose, H_pt] |
| ``rss_aoa_information``   | RSS (dBm) and AOA of p from a sender whose | H^T (R + s_nav2 H H^T)^-1 H    |
|                               | own position is known to s_nav2 per axis   | (the sender's position a       |
|                               | (gao2016); R per LOS/NLOS mode             | Gaussian nuisance, eliminated) |

RSS/AOA with the LOS/NLOS mode known to the bound (its bias subtracted, its variance
used) is a *genie* bound: an estimator that does not know the mode faces a mixture and
can do worse; nothing can do better.

Arrays carry leading batch axes (``...``); the recursion takes the episode axis E first.
"""

from __future__ import annotations

import numpy as np

__all__ = ["bearing_information", "effective_process_noise", "filtering_bound", "fix_information", "fuse_information",
           "information_step", "linear_information", "pair_information", "predict_covariance",
           "range_bearing_information", "range_information", "rss_aoa_information", "unit_vectors"]

DEFAULT_REGULARIZATION = 1e-9


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + np.swapaxes(a, -1, -2))


def _factor(info: np.ndarray, tol: float = 0.0) -> np.ndarray:
    """L (n, r) with L L^T = info (PSD, symmetric), from the eigendecomposition; r = its numerical rank."""
    values, vectors = np.linalg.eigh(_sym(info))
    keep = values > max(tol, 1e-14 * max(float(values.max(initial=0.0)), 1e-300))
    return vectors[:, keep] * np.sqrt(values[keep])


def fuse_information(P: np.ndarray, info: np.ndarray) -> np.ndarray:
    """(P^-1 + info)^-1 for a PSD P (possibly singular) and PSD ``info`` (n, n), without inverting either:
    P - P L (I + L^T P L)^-1 L^T P with info = L L^T (Woodbury)."""
    L = _factor(info)
    if L.shape[1] == 0:
        return P.copy()
    PL = P @ L
    S = np.eye(L.shape[1]) + L.T @ PL
    return _sym(P - PL @ np.linalg.solve(S, PL.T))


def predict_covariance(P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """F P F^T + Q (the covariance-form time update of the bound)."""
    return _sym(F @ P @ F.T + Q)


def _regularized_inverse(Q: np.ndarray, regularization: float) -> np.ndarray:
    n = Q.shape[-1]
    scale = np.trace(Q, axis1=-2, axis2=-1)[..., None, None] / n
    scale = np.where(scale > 0, scale, 1.0)
    return np.linalg.inv(_sym(Q) + regularization * scale * np.eye(n))


def effective_process_noise(Q: np.ndarray, regularization: float = DEFAULT_REGULARIZATION) -> np.ndarray:
    """(E[Q_e^-1])^-1 over the leading episode axis of Q (E, n, n), each Q_e regularized as the module says."""
    return _sym(np.linalg.inv(_sym(_regularized_inverse(Q, regularization).mean(axis=0))))


def information_step(J: np.ndarray, F: np.ndarray, Q: np.ndarray, info_next: np.ndarray,
                     regularization: float = DEFAULT_REGULARIZATION) -> np.ndarray:
    """One TMN step J_k -> J_{k+1} = D22 - D21 (J_k + D11)^-1 D12 with the D-terms averaged over episodes.

    F (E, n, n) or (n, n), Q (E, n, n) or (n, n), ``info_next`` (n, n) the mean reading information at k + 1.
    """
    Qi = _regularized_inverse(Q, regularization)
    F = np.asarray(F, float)
    FtQi = np.swapaxes(F, -1, -2) @ Qi
    D11 = FtQi @ F
    D12 = -FtQi
    if D11.ndim == 3:
        D11, D12 = D11.mean(axis=0), D12.mean(axis=0)
    D22 = (Qi.mean(axis=0) if Qi.ndim == 3 else Qi) + info_next
    return _sym(D22 - D12.T @ np.linalg.solve(_sym(J + D11), D12))


def _is_common(a: np.ndarray | None) -> bool:
    """True when ``a`` has no episode axis or is the same in every episode."""
    return a is None or a.ndim == 2 or bool(np.all(a == a[:1]))


def filtering_bound(P0: np.ndarray | None, info: np.ndarray, F: np.ndarray | None = None,
                    Q: np.ndarray | None = None, regularization: float = DEFAULT_REGULARIZATION,
                    J0: np.ndarray | None = None) -> np.ndarray:
    """The PCRB covariance J_k^-1 (K, n, n) of the posterior at every step k = 0..K-1.

    | argument | shape                          | meaning                                                      |
    |----------|--------------------------------|--------------------------------------------------------------|
    | P0       | (n, n) PSD                     | prior covariance of x(0) (J0 = P0^-1; singular allowed       |
    |          |                                | where the covariance form runs)                               |
    | J0       | (n, n) PSD, instead of P0      | prior information (0: no prior); J0 + info[0] must then be   |
    |          |                                | invertible                                                   |
    | info     | (K, n, n) PSD                  | mean (over episodes) Fisher information of the readings of k |
    | F        | (K-1, n, n) or (K-1, E, n, n)  | transition Jacobian k -> k+1 (None: the identity)            |
    | Q        | (K-1, n, n) or (K-1, E, n, n)  | process noise k -> k+1 (None: zero: a static state)          |

    Step k: the readings of k are fused (posterior of k, recorded), then the state moves to k + 1.
    """
    info = np.asarray(info, float)
    K, n = info.shape[0], info.shape[-1]
    if (P0 is None) == (J0 is None):
        raise ValueError("give exactly one of P0 (prior covariance) and J0 (prior information)")
    prior = np.asarray(P0 if J0 is None else J0, float)
    if prior.shape != (n, n):
        raise ValueError(f"{'P0' if J0 is None else 'J0'} must be ({n}, {n}), got {prior.shape}")
    P = prior
    out = np.empty((K, n, n))
    J = None  # the information form's state, once a step needs it
    for k in range(K):
        if k:
            Fk = np.eye(n) if F is None else np.asarray(F[k - 1], float)
            Qk = np.zeros((n, n)) if Q is None else np.asarray(Q[k - 1], float)
            if _is_common(Fk):
                Fc = Fk if Fk.ndim == 2 else Fk[0]
                Qc = Qk if _is_common(Qk) and Qk.ndim == 2 else (Qk[0] if _is_common(Qk)
                                                                  else effective_process_noise(Qk, regularization))
                P = fuse_information(predict_covariance(P, Fc, Qc), info[k])
                J = None
            else:
                if J is None:
                    J = _sym(np.linalg.inv(P))
                J = information_step(J, Fk, Qk, info[k], regularization)
                P = _sym(np.linalg.inv(J))
        elif J0 is None:
            P = fuse_information(P, info[0])
        else:
            J = _sym(prior + info[0])
            try:
                P = _sym(np.linalg.inv(J))
            except np.linalg.LinAlgError as exc:
                raise np.linalg.LinAlgError("J0 + info[0] is singular: the first readings do not determine the "
                                            "state") from exc
            J = None
        out[k] = P
    return out


# --- Fisher information of the reading kinds ---------------------------------------------------------------

def linear_information(C: np.ndarray, R: np.ndarray) -> np.ndarray:
    """C^T R^-1 C (..., n, n) of z = C x + v, v ~ N(0, R)."""
    C, R = np.asarray(C, float), np.asarray(R, float)
    return _sym(np.swapaxes(C, -1, -2) @ np.linalg.solve(R, C))


def fix_information(variance, dim: int = 2) -> np.ndarray:
    """I / variance (..., dim, dim): a position fix with independent axes of this variance."""
    v = np.asarray(variance, float)
    return np.eye(dim) / v[..., None, None]


def unit_vectors(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u, d): u = (a - b) / ||a - b|| (..., 2) and d = ||a - b|| (...)."""
    rel = np.asarray(a, float) - np.asarray(b, float)
    d = np.sqrt(np.sum(rel * rel, axis=-1))
    return rel / np.where(d > 0, d, 1.0)[..., None], d


def range_information(a: np.ndarray, b: np.ndarray, variance) -> np.ndarray:
    """u u^T / variance (..., 2, 2) of a range ||a - b|| + v: the block on either end (a known anchor b: the
    whole information of a; two agents: see ``pair_information``)."""
    u, _ = unit_vectors(a, b)
    return u[..., :, None] * u[..., None, :] / np.asarray(variance, float)[..., None, None]


def pair_information(block: np.ndarray) -> np.ndarray:
    """[[B, -B], [-B, B]] (..., 4, 4) on the stacked positions (a, b) of a reading of a - b with block B."""
    top = np.concatenate([block, -block], axis=-1)
    return np.concatenate([top, -top], axis=-2)


def bearing_information(position: np.ndarray, sender: np.ndarray, variance) -> np.ndarray:
    """n n^T / (d^2 variance) (..., 2, 2) of the bearing atan2(p - s) of ``position`` from a known ``sender``."""
    u, d = unit_vectors(position, sender)
    n = np.stack([-u[..., 1], u[..., 0]], axis=-1) / d[..., None]
    return n[..., :, None] * n[..., None, :] / np.asarray(variance, float)[..., None, None]


def range_bearing_information(pose: np.ndarray, point: np.ndarray, R: np.ndarray) -> np.ndarray:
    """H^T R^-1 H (..., 5, 5) on [pose (x, y, theta); point (x, y)] of z = [||t - p||, atan2(t - p) - theta] + v.

    H_pose = [[-d^T / r, 0], [d_y / r^2, -d_x / r^2, -1]], H_point = [[d^T / r], [-d_y / r^2, d_x / r^2]]
    with d = t - p (the Jacobian of ``estimators.se2_models.RangeBearingModel``). For a known
    landmark keep the pose block [:3, :3]; for a robot observed, the full matrix on both states.
    """
    s, t = np.asarray(pose, float), np.asarray(point, float)
    d = t - s[..., :2]
    r2 = np.sum(d * d, axis=-1)
    r = np.sqrt(r2)
    dx, dy = d[..., 0], d[..., 1]
    H = np.zeros((*d.shape[:-1], 2, 5))
    H[..., 0, 0], H[..., 0, 1] = -dx / r, -dy / r
    H[..., 1, 0], H[..., 1, 1], H[..., 1, 2] = dy / r2, -dx / r2, -1.0
    H[..., 0, 3], H[..., 0, 4] = dx / r, dy / r
    H[..., 1, 3], H[..., 1, 4] = -dy / r2, dx / r2
    return _sym(np.swapaxes(H, -1, -2) @ np.linalg.solve(np.asarray(R, float), H))


def rss_aoa_information(position: np.ndarray, sender: np.ndarray, exponent: float, variances: np.ndarray,
                        sender_var: float = 0.0, use: tuple[bool, bool] = (True, True)) -> np.ndarray:
    """Information (..., 2, 2) on the target ``position`` of one RSS (dBm) + AOA (rad) reading from ``sender``.

    RSS = P_t - L_0 - 10 eta log10(d / d0) + bias + e_rss, AOA = atan2(p - s) + bias + e_aoa: the gradient in
    p is [-10 eta / ln 10 u^T / d; n^T / d] (n the unit normal). ``variances`` (..., 2): var(e_rss), var(e_aoa)
    in the mode the link is in (known: a genie bound). The sender's position is known only to ``sender_var``
    per axis (its navigation estimate): the reading is then also a function of that Gaussian nuisance, whose
    elimination gives H^T (R + sender_var H H^T)^-1 H (H the gradient in p; the one in s is -H). ``use`` keeps
    the RSS and/or the AOA row.
    """
    u, d = unit_vectors(position, sender)
    n = np.stack([-u[..., 1], u[..., 0]], axis=-1)
    H = np.stack([-10.0 * exponent / np.log(10.0) * u / d[..., None], n / d[..., None]], axis=-2)
    rows = [i for i in (0, 1) if use[i]]
    H = H[..., rows, :]
    var = np.asarray(variances, float)[..., rows]
    R = var[..., :, None] * np.eye(len(rows)) + sender_var * H @ np.swapaxes(H, -1, -2)
    return _sym(np.swapaxes(H, -1, -2) @ np.linalg.solve(R, H))
