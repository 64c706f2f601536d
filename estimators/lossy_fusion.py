"""Cooperative target localization under Bernoulli delay and packet loss.

Fu X., Bi H., Gao X., "Multi-UAVs Cooperative Localization Algorithms with
Communication Constraints", Hindawi, 2017 (seed ``000_de65bd0f0f4a0cb7.txt``).

L UAVs observe one target; UAV 0 is the leader and the fusion centre:

    x(k+1)   = Phi x(k) + Gamma w(k)                                          (1)
    z_i(k)   = H x(k) + v_i(k),      v_i ~ N(0, R_i)                          (2)
    y_i(k)   = xi1_i(k) z_i(k) + xi2_i(k) z_i(k-1)
               + (1 - xi1_i(k) - xi2_i(k)) y_i(k-1)                           (3)

y_i(k) is what the leader holds from UAV i at slot k: the fresh packet (on
time, probability alpha1_i), the previous one (one step late, alpha2_i), or
what it held before (lost). xi are i.i.d. over k and UAVs; the leader's own
link is always on time (alpha1_0 = 1). Before k = 0 the buffers hold
z_i(-1) = y_i(-1) = H x0_mean (a known constant).

Two estimators from the paper and four baselines, all scored on the same runs:

(A) **centralized** (Sec. 3.1). The augmented state X(k) = [x(k); z(k-1); y(k-1)]
    obeys X(k+1) = Phit(k) X(k) + Gammat(k) W(k), y(k) = Ht(k) X(k) + xi1(k) v(k)
    (eqs. 5-6) with random matrices. With Phibar = E Phit, Hbar = E Ht (eq. 8),
    the innovation eps(k) = y(k) - Hbar Xhat(k|k-1) is orthogonal to the past,
    so the linear MMSE predictor is

        Xhat(k+1|k) = Phibar Xhat(k|k-1) + L(k) eps(k),  L(k) = M(k) Qeps(k)^-1   (ours)

    with (derived below, e = X - Xhat, P = E e e^T, Psi = E[dH X X^T dH^T])

        Qeps = Hbar P Hbar^T + Psi + E[xi1 R xi1]                             (20)
        M    = E[X(k+1) eps^T] = Phibar P Hbar^T + [0; R alpha1; Psi + alpha1 R]
        P(k+1|k) = A - L M^T - M L^T + L Qeps L^T,
        A = Phibar P Phibar^T + blockdiag(0, 0, Psi) + Qbar                   (16)

    for any gain L (the optimal gain gives A - M Qeps^-1 M^T). The filtered
    estimate is Xhat(k|k) = Xhat(k|k-1) + K eps, K = P Hbar^T Qeps^-1 (17-18),
    P(k|k) = P - K Qeps K^T (19); this K is the optimal filter gain for either
    predictor. ``gain="paper"`` uses the paper's L = Phibar K (21), which
    drops the correlation terms [0; R alpha1; Psi + alpha1 R] of M: it never
    uses that y(k) is itself the last block of X(k+1), so it keeps
    re-estimating a buffer the leader knows exactly.

    Psi needs the second moment q(k) = E X X^T of the augmented state (eq. 12),
    propagated as mean and covariance (q = Sigma + mu mu^T):

        mu(k+1)    = Phibar mu(k)
        Sigma(k+1) = Phibar Sigma Phibar^T + blockdiag(0, 0, Psi(q)) + Qbar.

    With a = H x - y(k-1), b = z(k-1) - y(k-1) stacked over UAVs, the third
    block row of Phit (= Ht) deviates from its mean by
    dH X = (xi1 - alpha1) a + (xi2 - alpha2) b, so per UAV i (blocks of other
    UAVs are independent, hence zero)

        Psi_ii = c11 E[a a^T] + c22 E[b b^T] + c12 E[a b^T + b a^T],
        c11 = alpha1 (1 - alpha1), c22 = alpha2 (1 - alpha2), c12 = -alpha1 alpha2.

(B) **distributed** prediction-compensation fusion (Sec. 3.2). Each follower
    runs its own Kalman filter on z_i and, at slot k, sends the packet
    [xhat_i(k|k), xhat_i(k|k-1), xhat_i(k|k-2)] with covariances (28). The
    leader keeps the last packet delivered (on time: this slot's; late: the
    previous slot's; lost: the one it held) and, not knowing its age,
    compensates it with the expectation weights (29)

        xbar_i = alpha1 xhat(k|k) + (alpha2 + (1 - alpha1 - alpha2) alpha1) xhat(k|k-1)
                 + (1 - alpha1 - alpha2)(1 - alpha1) xhat(k|k-2)               (29)

    (the same weights on the covariances), runs its own Kalman filter on z_0
    (27), fuses with scalar weights a_i = (1/tr P_i) / sum_j (1/tr P_j) (30),
    x0 = sum a_i xbar_i, P0 = sum a_i^2 P_i, and feeds x0, P0 back into its own
    filter (31).

Baselines: ``naive_kf`` (the paper's "general Kalman filter": a Kalman filter
that takes every received y_i(k) as a fresh z_i(k)), ``leader_only_kf`` (the
leader's own measurements), ``informed_kf`` (knows the age of every packet: a
Kalman filter on [x(k); x(k-1)] that takes a late packet as a measurement of
x(k-1) and skips duplicates and lost slots; given y and the ages it is the
MMSE estimator, so it bounds (A) from below) and ``ideal_kf`` (every z_i(k) on
time).

Three readings of (B)'s compensation (29) (``distributed_step(..., reading=...)``,
``READINGS``), all with the weights w = (w0, w1, w2) of (29):

* ``"current"`` (the default; the printed algorithm): the leader weighs the held
  packet's three entries [x(k'|k'), x(k'|k'-1), x(k'|k'-2)], formed at the
  slot k' <= k it left the follower, as if k' = k.
* ``"forward"`` (realizable; ours): (22) names what the leader should use at
  slot k: x(k|k) if the packet of k is on time, x(k|k-1) = Phi x(k-1|k-1) if the
  held packet is one slot old (late now, or lost now after an on-time one),
  x(k|k-2) = Phi^2 x(k-2|k-2) otherwise: the held packet's own filtered
  estimate x_h = x(k-a|k-a), predicted forward by its age a. The leader does
  not know a (no time stamps), so the expectation (26) over the link outcomes
  becomes an expectation over a = 0, 1, 2 with the same probabilities:

      xbar = sum_a w_a Phi^a x_h,
      Pbar = sum_a w_a (P_a + (Phi^a x_h - xbar)(Phi^a x_h - xbar)^T),
      P_a  = Phi^a P_h Phi^aT + sum_{j<a} Phi^j Q Phi^jT.

  w_a is the probability that the held packet is a slots old under (22):
  w0 = alpha1 (on time now), w1 = alpha2 + (1 - alpha1 - alpha2) alpha1 (late
  now, or lost now after an on-time one), w2 = the rest ((22) lumps every
  older packet into x(k|k-2)). Pbar is the error covariance of xbar given
  the age distribution (the law of total covariance: the mean of the
  hypotheses' covariances plus the spread of their means). (26) prints only
  the first term, sum_a w_a P_a, which claims the age's uncertainty costs
  nothing; the fusion weights (30) then trust the follower as if its age were
  known (``forward_spread=False`` keeps the printed form, to measure that).
  Every held packet is now an estimate of x(k): the lag of a stale one is
  removed on average (the mean predicted age is sum_a a w_a), where
  ``"current"`` leaves it all. With every link on time (alpha1 = 1) both
  readings are the filtered estimate of the fresh packet.
* ``"age_aware"`` (assumes time stamps the paper's agents do not have; a
  diagnostic): the leader knows the held packet's age a and predicts each of
  its three entries forward by a (x -> Phi^a x, P -> Phi^a P Phi^aT +
  sum_{j<a} Phi^j Q Phi^jT) before (29).

One more diagnostic, used by the reproduction to explain its numbers:
``centralized_filter(..., moments="printed")`` runs (A) with the second
moments exactly as printed in (12)-(14), (20).

Array conventions (a leading batch shape ``...`` is allowed):

* ``z``, ``y``     ``(..., K, L, p)``   measurements / received values, k = 0..K-1
* ``outcome``      ``(..., K, L)``      int codes ON_TIME, LATE, LOST per slot
* estimates        ``(..., K, n)``
* covariances      ``(K, n, n)`` where they do not depend on the data (the
  Kalman filters with fixed measurement sets, (A)), ``(..., K, n, n)`` where
  they do (``informed_kf``, ``distributed``).

Departures from the printed equations
-------------------------------------
* xi1 and xi2 are not independent Bernoulli variables: on time, late and
  lost are exclusive outcomes of one slot, so E[xi1 xi2] = 0 and
  Cov(xi1, xi2) = -alpha1 alpha2. Eqs. (12)-(13) weight the terms by
  A1 = alpha1(1 - alpha1), A2 = alpha2(1 - alpha2), A3 = A1 + A2 only; we use
  the full covariance of (xi1, xi2) (c12 above).
* Eqs. (12)-(13) keep only the squares H x x^T H^T, z z^T, y y^T and drop the
  cross terms -H x y^T, -z y^T, ... of E[dH X X^T dH^T]. As printed the
  moment is not invariant to a shift of the origin: in the paper's setting
  its trace at k = 50 is 1.2e6 m^2 against 741 m^2 for the derived one
  (L = 2). We use the differences a, b above; ``moments="printed"`` keeps
  the printed form for comparison.
* E[xi1 v v^T xi1] = alpha1 R because xi1^2 = xi1 (the paper itself states
  E[xi^2] = alpha). Eq. (14) and Qeps in (20) print alpha1 Qv alpha1.
* Eq. (16) as printed mixes terms (Delta Phi q Hbar^T L^T, Gammat with random
  xi inside an expectation); we derive P(k+1|k) for an arbitrary gain from
  e(k+1) = Phibar e + dPhi X + Gammat W - L eps as above.
* Eq. (21) L = Phibar K is not the optimal predictor gain (see (A)); both
  are provided and compared (``gain="optimal"``, ``gain="paper"``).
* The initial covariance (Sec. 3.1) is blockdiag(P0, 0, 0) with buffers
  H x0_mean, as the issue pins (the paper sets them to 0).
* The garbled Phit of eq. (6) is read as [[Phi, 0, 0], [H, 0, 0],
  [xi1 H, xi2, I - xi1 - xi2]] and Ht = [xi1 H, xi2, I - xi1 - xi2], which
  is what (4) gives.
* (B): the leader's fusion includes its own estimate (27) as i = 1 of (30);
  the paper's (29) fixes the weights on the packet contents without their age,
  which is what ``reading="current"`` implements (a delivered packet of age 1
  or more is used as if it were current); ``reading="forward"`` is the
  realizable reading of (22) and (26) derived above. Before k = 0 the held packet is the prior
  [x0_mean] * 3 with covariances P0 (the follower's x(0|-1) and x(0|-2)).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

__all__ = [
    "ON_TIME",
    "LATE",
    "LOST",
    "FILTERS",
    "LossyModel",
    "deliver",
    "received_measurements",
    "kalman_update",
    "kalman_filter",
    "informed_filter",
    "informed_initial",
    "informed_matrices",
    "informed_update",
    "AugmentedMatrices",
    "augmented_matrices",
    "link_moment",
    "printed_link_moment",
    "CentralizedState",
    "centralized_initial",
    "centralized_step",
    "centralized_filter",
    "compensation_weights",
    "inverse_trace_weights",
    "DistributedState",
    "distributed_initial",
    "age_propagators",
    "READINGS",
    "distributed_step",
    "distributed_filter",
    "run_filters",
]

ON_TIME, LATE, LOST = 0, 1, 2
READINGS = ("current", "forward", "age_aware")  # of (B)'s compensation (29): see the module docstring
FILTERS = ("naive_kf", "centralized", "centralized_paper_gain", "distributed", "informed_kf",
           "leader_only_kf", "ideal_kf")


@dataclass(frozen=True)
class LossyModel:
    """Target, sensors and links (eqs. 1-3).

    Parameters
    ----------
    transition : (n, n)  Phi
    process_noise : (n, n)  Gamma Q Gamma^T
    measurement : (p, n)  H, the same for every UAV
    measurement_noise : (L, p, p)  R_i
    on_time : (L,)  alpha1_i, the leader's must be 1
    late : (L,)  alpha2_i, the leader's must be 0
    """

    transition: np.ndarray
    process_noise: np.ndarray
    measurement: np.ndarray
    measurement_noise: np.ndarray
    on_time: np.ndarray
    late: np.ndarray

    def __post_init__(self):
        on_time, late = np.asarray(self.on_time, float), np.asarray(self.late, float)
        if on_time[0] != 1.0 or late[0] != 0.0:
            raise ValueError("on_time[0] must be 1 and late[0] 0: the leader's own link is always on time")
        if np.any(on_time < 0) or np.any(late < 0) or np.any(on_time + late > 1 + 1e-12):
            raise ValueError("on_time and late must be probabilities with on_time + late <= 1")
        if np.any(on_time + late <= 0):
            raise ValueError("on_time + late must be > 0: every UAV must deliver with positive probability")

    @property
    def num_uavs(self) -> int:
        return int(np.shape(self.measurement_noise)[0])

    @property
    def state_dim(self) -> int:
        return int(np.shape(self.transition)[0])

    @property
    def meas_dim(self) -> int:
        return int(np.shape(self.measurement)[0])


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + a.swapaxes(-1, -2))  # the method: np.swapaxes' dispatch costs more at small sizes


@functools.lru_cache(maxsize=32)
def _identity(n: int) -> np.ndarray:
    """I_n, built once per size (read-only: shared by every call)."""
    eye = np.eye(n)
    eye.flags.writeable = False
    return eye


try:  # the gufunc behind np.linalg.solve: the same LAPACK call, without ~20 us of argument checks per call
    from numpy.linalg._umath_linalg import solve as _lapack_solve
except ImportError:  # pragma: no cover - a numpy that moved it: the public function
    _lapack_solve = None


def _right_solve(S: np.ndarray, B: np.ndarray) -> np.ndarray:
    """B S^-1 for a symmetric positive definite S (Cholesky when unbatched).

    Batched, the values are np.linalg.solve's bit for bit (its gufunc, called directly when the operands are
    float64 stacks of equal rank); a singular S gives non-finite values there (numpy warns of an invalid
    value), and then np.linalg.solve raises its LinAlgError."""
    if S.ndim == 2 and B.ndim == 2:
        return scipy.linalg.cho_solve(scipy.linalg.cho_factor(S), B.T).T
    Bt = B.swapaxes(-1, -2)
    if _lapack_solve is not None and S.ndim == Bt.ndim and S.dtype == np.float64 and Bt.dtype == np.float64:
        solved = _lapack_solve(S, Bt, signature="dd->d")
        if math.isfinite(solved.sum()):  # one reduction: any NaN or inf makes the sum non-finite
            return solved.swapaxes(-1, -2)
    return np.linalg.solve(S, Bt).swapaxes(-1, -2)


def deliver(fresh: np.ndarray, previous: np.ndarray, held: np.ndarray, outcome: np.ndarray) -> np.ndarray:
    """Eq. (3) for one slot: ``fresh`` if on time, ``previous`` if late, else ``held``.

    ``outcome`` has shape (..., L); the arrays (..., L, *tail) broadcast against it (one of them at least
    carries every leading axis; the others may lack them, e.g. a covariance shared by the copies).
    """
    outcome = np.asarray(outcome)
    tail = max(np.ndim(fresh), np.ndim(previous), np.ndim(held)) - outcome.ndim
    code = outcome.reshape(outcome.shape + (1,) * tail)
    return np.where(code == ON_TIME, fresh, np.where(code == LATE, previous, held))


def received_measurements(z: np.ndarray, outcome: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """y(0..K-1) by eq. (3) from z (..., K, L, p) and outcomes (..., K, L); z(-1) = y(-1) = ``initial`` (p,)."""
    z = np.asarray(z, float)
    previous = np.broadcast_to(np.asarray(initial, float), z[..., 0, :, :].shape)
    held = previous
    y = np.empty_like(z)
    for k in range(z.shape[-3]):
        held = deliver(z[..., k, :, :], previous, held, outcome[..., k, :])
        y[..., k, :, :] = held
        previous = z[..., k, :, :]
    return y


# --- Kalman filters -------------------------------------------------------------------------------

def kalman_update(mean, cov, z, H, R, mask=None):
    """Measurement update in Joseph form; where ``mask`` (...) is False nothing changes.

    mean (..., n), cov (n, n) or (..., n, n), z (..., p), H (p, n), R (p, p) or (..., p, p).
    """
    H = np.asarray(H, float)
    PHt = cov @ H.T
    S = _sym(H @ PHt + R)
    K = _right_solve(S, PHt)
    innovation = z - mean @ H.T
    new_mean = mean + np.einsum("...ij,...j->...i", K, innovation)
    IKH = _identity(H.shape[1]) - K @ H
    new_cov = _sym(IKH @ cov @ IKH.swapaxes(-1, -2) + K @ R @ K.swapaxes(-1, -2))
    if mask is None:
        return new_mean, new_cov
    mask = np.asarray(mask, bool)
    return (np.where(mask[..., None], new_mean, mean),
            np.where(mask[..., None, None], new_cov, cov))


def _block_diag(blocks: np.ndarray) -> np.ndarray:
    return scipy.linalg.block_diag(*np.asarray(blocks, float))


def kalman_filter(model: LossyModel, x0_mean, P0, measurements: np.ndarray, uavs=None):
    """Kalman filter taking ``measurements`` (..., K, J, p) as fresh z of the UAVs ``uavs`` (J of them).

    Returns filtered estimates (..., K, n) and covariances (K, n, n) (the filter's own).
    """
    uavs = list(range(model.num_uavs)) if uavs is None else list(uavs)
    measurements = np.asarray(measurements, float)
    H = np.vstack([model.measurement] * len(uavs))
    R = _block_diag(np.asarray(model.measurement_noise)[uavs])
    Phi, Q = np.asarray(model.transition, float), np.asarray(model.process_noise, float)
    K = measurements.shape[-3]
    batch = measurements.shape[:-3]
    mean = np.broadcast_to(np.asarray(x0_mean, float), (*batch, model.state_dim))
    cov = np.asarray(P0, float)
    estimates = np.empty((*batch, K, model.state_dim))
    covariances = np.empty((K, model.state_dim, model.state_dim))
    for k in range(K):
        if k:
            mean, cov = mean @ Phi.T, _sym(Phi @ cov @ Phi.T + Q)
        mean, cov = kalman_update(mean, cov, measurements[..., k, :, :].reshape(*batch, -1), H, R)
        estimates[..., k, :], covariances[k] = mean, cov
    return estimates, covariances


def informed_matrices(model: LossyModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """F, Qa, H_now, H_before of the informed filter's state [x(k); x(k-1)] (see ``informed_filter``)."""
    n = model.state_dim
    H = np.asarray(model.measurement, float)
    Phi, Q = np.asarray(model.transition, float), np.asarray(model.process_noise, float)
    F = np.block([[Phi, np.zeros((n, n))], [np.eye(n), np.zeros((n, n))]])
    Qa = scipy.linalg.block_diag(Q, np.zeros((n, n)))
    return F, Qa, np.hstack([H, np.zeros_like(H)]), np.hstack([np.zeros_like(H), H])


def informed_initial(model: LossyModel, x0_mean, P0, batch_shape: tuple = ()):
    """(mean (..., 2n), cov (..., 2n, 2n), used_before (..., L)) of the informed filter before slot 0."""
    n, L = model.state_dim, model.num_uavs
    x0 = np.asarray(x0_mean, float)
    mean = np.broadcast_to(np.concatenate([x0, x0]), (*batch_shape, 2 * n)).copy()
    cov = np.broadcast_to(scipy.linalg.block_diag(P0, P0), (*batch_shape, 2 * n, 2 * n)).copy()
    used_before = np.ones((*batch_shape, L), bool)  # z(-1) is the known buffer: no information
    return mean, cov, used_before


def informed_update(model: LossyModel, mean, cov, used_before, y_k: np.ndarray, code: np.ndarray, mats=None):
    """One slot's updates of the informed filter: y_k (..., L, p), code (..., L) -> (mean, cov, used_before)."""
    R = np.asarray(model.measurement_noise, float)
    _, _, H_now, H_before = informed_matrices(model) if mats is None else mats
    for i in range(model.num_uavs):
        on_time = code[..., i] == ON_TIME
        late_new = (code[..., i] == LATE) & ~used_before[..., i]
        for H, mask in ((H_now, on_time), (H_before, late_new)):
            mean, cov = _masked_update(mean, cov, y_k[..., i, :], H, R[i], mask)
    return mean, cov, code == ON_TIME


def _masked_update(mean, cov, z, H, R, mask):
    """``kalman_update`` of the runs where ``mask`` (...) is True, computed for those runs only (each run's
    update is its own: the same values); new arrays where any run is updated, the inputs where none is."""
    if mask.all():
        return kalman_update(mean, cov, z, H, R)
    if not mask.any():
        return mean, cov
    rows = np.nonzero(mask)
    mean, cov = mean.copy(), cov.copy()
    mean[rows], cov[rows] = kalman_update(mean[rows], cov[rows], z[rows], H, R)
    return mean, cov


def informed_filter(model: LossyModel, x0_mean, P0, y: np.ndarray, outcome: np.ndarray):
    """Kalman filter that knows every packet's age (an informed bound on (A)).

    State [x(k); x(k-1)]: an on-time y_i(k) = z_i(k) measures x(k), a late one
    y_i(k) = z_i(k-1) measures x(k-1) unless z_i(k-1) was already delivered on
    time at k-1 (a duplicate) or k = 0 (the known buffer). Returns estimates
    (..., K, n) and covariances (..., K, n, n). One slot is ``informed_update``
    (after the time update x -> F x, P -> F P F^T + Qa of ``informed_matrices``).
    """
    n = model.state_dim
    y, outcome = np.asarray(y, float), np.asarray(outcome)
    K = y.shape[-3]
    batch = y.shape[:-3]
    mats = informed_matrices(model)
    F, Qa = mats[0], mats[1]
    mean, cov, used_before = informed_initial(model, x0_mean, P0, batch)
    estimates = np.empty((*batch, K, n))
    covariances = np.empty((*batch, K, n, n))
    for k in range(K):
        if k:
            mean, cov = mean @ F.T, _sym(F @ cov @ F.T + Qa)
        mean, cov, used_before = informed_update(model, mean, cov, used_before, y[..., k, :, :], outcome[..., k, :],
                                                 mats)
        estimates[..., k, :], covariances[..., k, :, :] = mean[..., :n], cov[..., :n, :n]
    return estimates, covariances


# --- (A) centralized augmented-state filter --------------------------------------------------------

@dataclass(frozen=True)
class AugmentedMatrices:
    """The fixed matrices of (A), built once per model (d = n + 2 L p, m = L p)."""

    phi_bar: np.ndarray      # (d, d) E Phit, eq. (8)
    h_bar: np.ndarray        # (m, d) E Ht
    fresh_diff: np.ndarray   # (m, d) a = [H_s, 0, -I] X = H x - y(k-1)
    late_diff: np.ndarray    # (m, d) b = [0, I, -I] X = z(k-1) - y(k-1)
    noise: np.ndarray        # (d, d) Qbar = E[Gammat W W^T Gammat^T]
    meas_noise: np.ndarray   # (m, m) R = blockdiag(R_i)
    on_time: np.ndarray      # (m,) alpha1 per stacked row
    link_cov: np.ndarray     # (3, m, m) c11, c22, c12 masks on same-UAV blocks


def augmented_matrices(model: LossyModel) -> AugmentedMatrices:
    n, p, L = model.state_dim, model.meas_dim, model.num_uavs
    m = L * p
    d = n + 2 * m
    H = np.asarray(model.measurement, float)
    Hs = np.vstack([H] * L)
    a1 = np.repeat(np.asarray(model.on_time, float), p)
    a2 = np.repeat(np.asarray(model.late, float), p)
    phi_bar = np.zeros((d, d))
    phi_bar[:n, :n] = model.transition
    phi_bar[n:n + m, :n] = Hs
    phi_bar[n + m:, :n] = a1[:, None] * Hs
    phi_bar[n + m:, n:n + m] = np.diag(a2)
    phi_bar[n + m:, n + m:] = np.diag(1.0 - a1 - a2)
    eye = np.eye(m)
    fresh_diff = np.hstack([Hs, np.zeros((m, m)), -eye])
    late_diff = np.hstack([np.zeros((m, n)), eye, -eye])
    R = _block_diag(model.measurement_noise)
    noise = np.zeros((d, d))
    noise[:n, :n] = model.process_noise
    noise[n:n + m, n:n + m] = R
    # E[v (xi1 v)^T] = R alpha1 and E[xi1 v v^T xi1] = alpha1 R (xi1^2 = xi1; R is block diagonal per UAV)
    noise[n:n + m, n + m:] = R * a1[None, :]
    noise[n + m:, n:n + m] = a1[:, None] * R
    noise[n + m:, n + m:] = a1[:, None] * R
    same_uav = np.kron(np.eye(L), np.ones((p, p)))
    link_cov = np.stack([same_uav * (a1 * (1 - a1))[:, None],
                         same_uav * (a2 * (1 - a2))[:, None],
                         same_uav * (-a1 * a2)[:, None]])
    return AugmentedMatrices(phi_bar, phi_bar[n + m:], fresh_diff, late_diff, noise, R, a1, link_cov)


def link_moment(mats: AugmentedMatrices, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Psi = E[dH X X^T dH^T] for E X = ``mean`` (d,), Cov X = ``cov`` (d, d); shape (m, m)."""
    Da, Db = mats.fresh_diff, mats.late_diff
    ma, mb = Da @ mean, Db @ mean
    Eaa = Da @ cov @ Da.T + np.outer(ma, ma)
    Ebb = Db @ cov @ Db.T + np.outer(mb, mb)
    Eab = Da @ cov @ Db.T + np.outer(ma, mb)
    c11, c22, c12 = mats.link_cov
    return _sym(c11 * Eaa + c22 * Ebb + c12 * (Eab + Eab.T))


def printed_link_moment(mats: AugmentedMatrices, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Psi as eqs. (12)-(13) print it: A1 o (H x x^T H^T) + A2 o (z z^T) + A3 o (y y^T), A3 = A1 + A2.

    Only for comparison (``moments="printed"``): it drops Cov(xi1, xi2) and the cross terms, so it
    depends on where the origin is.
    """
    m = mats.h_bar.shape[0]
    n = mats.phi_bar.shape[0] - 2 * m
    q = cov + np.outer(mean, mean)
    Sx = mats.fresh_diff[:, :n]
    Exx = Sx @ q[:n, :n] @ Sx.T
    Ezz, Eyy = q[n:n + m, n:n + m], q[n + m:, n + m:]
    c11, c22, _ = mats.link_cov
    return _sym(c11 * Exx + c22 * Ezz + (c11 + c22) * Eyy)


@dataclass
class CentralizedState:
    """Xhat(k|k-1) (..., d), P(k|k-1) (d, d) and the prior moments E X(k) (d,), Cov X(k) (d, d)."""

    estimate: np.ndarray
    covariance: np.ndarray
    moment_mean: np.ndarray
    moment_cov: np.ndarray


def centralized_initial(model: LossyModel, x0_mean, P0, batch_shape: tuple = ()) -> CentralizedState:
    """Xhat(0|-1) = [x0_mean; H x0_mean (xL); H x0_mean (xL)], P(0|-1) = blockdiag(P0, 0, 0)."""
    x0 = np.asarray(x0_mean, float)
    buffer = np.tile(np.asarray(model.measurement, float) @ x0, model.num_uavs)
    mean = np.concatenate([x0, buffer, buffer])
    d = mean.size
    cov = np.zeros((d, d))
    cov[:model.state_dim, :model.state_dim] = P0
    return CentralizedState(np.broadcast_to(mean, (*batch_shape, d)).copy(), cov, mean, cov.copy())


def centralized_step(model: LossyModel, state: CentralizedState, y: np.ndarray, gain: str = "optimal",
                     mats: AugmentedMatrices | None = None, moments: str = "derived"):
    """One slot of (A): filter with y(k) (..., L, p), then predict k+1.

    ``moments="printed"`` substitutes the paper's printed second moments
    (``printed_link_moment`` and alpha1 R alpha1 for E[xi1 R xi1], eqs. 12-14, 20) into the
    same recursion, to measure what they cost; its covariance is then no longer the true MSE.
    Returns (state for k+1, xhat(k|k) (..., n), P(k|k) of x (n, n)).
    """
    if gain not in ("optimal", "paper"):
        raise ValueError(f"gain must be 'optimal' or 'paper', got {gain!r}")
    if moments not in ("derived", "printed"):
        raise ValueError(f"moments must be 'derived' or 'printed', got {moments!r}")
    mats = mats or augmented_matrices(model)
    n, m = model.state_dim, mats.h_bar.shape[0]
    y = np.asarray(y, float).reshape(*np.shape(y)[:-2], m)
    P, Phi, Hb = state.covariance, mats.phi_bar, mats.h_bar
    a1 = mats.on_time
    noise = mats.noise
    if moments == "derived":
        psi = link_moment(mats, state.moment_mean, state.moment_cov)
        alpha_R = a1[:, None] * mats.meas_noise
    else:
        psi = printed_link_moment(mats, state.moment_mean, state.moment_cov)
        alpha_R = a1[:, None] * mats.meas_noise * a1[None, :]
        noise = noise.copy()
        noise[n + m:, n + m:] = alpha_R
    Qe = _sym(Hb @ P @ Hb.T + psi + alpha_R)
    PHt = P @ Hb.T
    K = _right_solve(Qe, PHt)
    innovation = y - state.estimate @ Hb.T
    filtered = state.estimate + innovation @ K.T
    filtered_cov = _sym(P - K @ Qe @ K.T)

    M = Phi @ PHt
    M[n:n + m] += alpha_R.T
    M[n + m:] += psi + alpha_R
    A = Phi @ P @ Phi.T + noise
    A[n + m:, n + m:] += psi
    if gain == "optimal":
        Lg = _right_solve(Qe, M)
        P_next = A - Lg @ M.T
    else:
        Lg = Phi @ K
        P_next = A - Lg @ M.T - M @ Lg.T + Lg @ Qe @ Lg.T
    predicted = state.estimate @ Phi.T + innovation @ Lg.T
    moment_cov = Phi @ state.moment_cov @ Phi.T + noise
    moment_cov[n + m:, n + m:] += psi
    nxt = CentralizedState(predicted, _sym(P_next), Phi @ state.moment_mean, _sym(moment_cov))
    return nxt, filtered[..., :n], filtered_cov[:n, :n]


def centralized_filter(model: LossyModel, x0_mean, P0, y: np.ndarray, gain: str = "optimal",
                       moments: str = "derived"):
    """(A) over an episode: y (..., K, L, p) -> estimates (..., K, n), own covariances (K, n, n)."""
    y = np.asarray(y, float)
    K, batch = y.shape[-3], y.shape[:-3]
    mats = augmented_matrices(model)
    state = centralized_initial(model, x0_mean, P0, batch)
    n = model.state_dim
    estimates, covariances = np.empty((*batch, K, n)), np.empty((K, n, n))
    for k in range(K):
        state, estimates[..., k, :], covariances[k] = centralized_step(model, state, y[..., k, :, :], gain, mats,
                                                                       moments)
    return estimates, covariances


# --- (B) distributed prediction-compensation fusion ------------------------------------------------

def compensation_weights(on_time, late) -> np.ndarray:
    """Weights of eq. (29) on [xhat(k|k), xhat(k|k-1), xhat(k|k-2)], shape (..., 3), normalized to sum 1."""
    a1, a2 = np.asarray(on_time, float), np.asarray(late, float)
    lost = 1.0 - a1 - a2
    w = np.stack([a1, a2 + lost * a1, lost * (1.0 - a1)], axis=-1)
    return w / w.sum(axis=-1, keepdims=True)


def inverse_trace_weights(covariances: np.ndarray, factors: np.ndarray | None = None) -> np.ndarray:
    """Eq. (30): a_i proportional to factor_i / tr P_i (factor 1 = the paper), over axis -3 of (..., L, n, n)."""
    weights = 1.0 / np.asarray(covariances).trace(axis1=-2, axis2=-1)  # the method: np.trace's dispatch costs more
    if factors is not None:
        weights = np.asarray(factors, float) * weights
    return weights / weights.sum(axis=-1, keepdims=True)


@dataclass
class DistributedState:
    """State of (B) after a slot (followers are UAVs 1..L-1, leading axes ``...``).

    prediction, prediction_cov   (..., L-1, 2, n[, n])  each follower's xhat(k|k-1), xhat(k|k-2) for the next slot
    packet, packet_cov           (..., L-1, 3, n[, n])  the packet each follower formed at the last slot
    sent                         (..., L-1) bool        whether it was transmitted (a late delivery needs it)
    held, held_cov               (..., L-1, 3, n[, n])  the last packet the leader received from each follower
    held_age                     (..., L-1) int         slots since that packet was formed
    leader_prediction(_cov)      (..., n[, n])          the leader's xhat(k|k-1) from the fed-back x0 (31)
    fused, fused_cov             (..., n[, n])          x0(k), P0(k) of eq. (30)
    weights                      (..., L)               the fusion weights a_i used (leader first)
    compensated(_cov)            (..., L-1, n[, n])     the compensated follower estimates of (29)
    delivered                    (..., L-1) int         ON_TIME / LATE (a packet arrived) or LOST (none)

    The followers' filters read every slot whatever they send, so ``prediction_cov`` and ``packet_cov``
    do not depend on the data: they may lack the leading axes (one stack shared by runs at the same slot),
    and ``distributed_step`` then returns them without those axes too.
    """

    prediction: np.ndarray
    prediction_cov: np.ndarray
    packet: np.ndarray
    packet_cov: np.ndarray
    sent: np.ndarray
    held: np.ndarray
    held_cov: np.ndarray
    held_age: np.ndarray
    leader_prediction: np.ndarray
    leader_prediction_cov: np.ndarray
    fused: np.ndarray
    fused_cov: np.ndarray
    weights: np.ndarray
    compensated: np.ndarray
    compensated_cov: np.ndarray
    delivered: np.ndarray


def distributed_initial(model: LossyModel, x0_mean, P0, batch_shape: tuple = ()) -> DistributedState:
    """Every filter starts from N(x0_mean, P0); the held (and previous) packet is [x0_mean] * 3, covariances P0."""
    F = model.num_uavs - 1
    x0, P0 = np.asarray(x0_mean, float), np.asarray(P0, float)

    def tile(a, *shape):
        return np.broadcast_to(a, (*batch_shape, *shape, *a.shape)).copy()

    return DistributedState(
        prediction=tile(x0, F, 2), prediction_cov=tile(P0, F, 2),
        packet=tile(x0, F, 3), packet_cov=tile(P0, F, 3), sent=np.ones((*batch_shape, F), bool),
        held=tile(x0, F, 3), held_cov=tile(P0, F, 3), held_age=np.zeros((*batch_shape, F), int),
        leader_prediction=tile(x0), leader_prediction_cov=tile(P0),
        fused=tile(x0), fused_cov=tile(P0),
        weights=np.full((*batch_shape, F + 1), 1.0 / (F + 1)),
        compensated=tile(x0, F), compensated_cov=tile(P0, F),
        delivered=np.full((*batch_shape, F), LOST),
    )


def age_propagators(model: LossyModel, max_age: int) -> tuple[np.ndarray, np.ndarray]:
    """Phi^a and sum_{j<a} Phi^j Q Phi^jT for a = 0..max_age, shapes (max_age+1, n, n)."""
    Phi, Q = np.asarray(model.transition, float), np.asarray(model.process_noise, float)
    n = model.state_dim
    powers, noise = [np.eye(n)], [np.zeros((n, n))]
    for _ in range(max_age):
        powers.append(Phi @ powers[-1])
        noise.append(Phi @ noise[-1] @ Phi.T + Q)
    return np.stack(powers), np.stack(noise)


def distributed_step(model: LossyModel, state: DistributedState, z: np.ndarray, outcome: np.ndarray,
                     transmit: np.ndarray | None = None, compensation: np.ndarray | None = None,
                     fusion_factors: np.ndarray | None = None, reading: str = "current",
                     forward_spread: bool = True) -> DistributedState:
    """One slot of (B) with this slot's z (..., L, p) and link outcomes (..., L).

    ``transmit`` (..., L-1) bool: whether each follower sends its packet this
    slot (default all; a packet not sent cannot arrive on time now nor late
    next slot). ``compensation`` (..., L-1, 3): weights (default eq. 29) on the
    three estimates ``reading`` makes of the held packet (``READINGS``,
    module docstring): ``"current"`` its entries [x(k'|k'), x(k'|k'-1),
    x(k'|k'-2)] as if current (the paper as printed); ``"forward"`` its
    filtered estimate predicted forward by 0, 1 and 2 slots (the age unknown:
    realizable); ``"age_aware"`` its entries predicted forward by its known
    age (assumes time stamps). ``forward_spread`` (``"forward"`` only): the
    compensated covariance includes the spread of the three predictions (the
    derived Pbar); False: (26)'s printed sum_a w_a P_a. ``fusion_factors``
    (..., L): a_i is proportional to factor_i / tr P_i (default 1, eq. 30).
    """
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}, got {reading!r}")
    Phi, Q = np.asarray(model.transition, float), np.asarray(model.process_noise, float)
    H, R = np.asarray(model.measurement, float), np.asarray(model.measurement_noise, float)
    z, outcome = np.asarray(z, float), np.asarray(outcome)
    followers = outcome[..., 1:]
    if transmit is None:
        transmit = np.ones(followers.shape, bool)
    else:
        transmit = np.broadcast_to(np.asarray(transmit, bool), followers.shape)
    if compensation is None:
        compensation = compensation_weights(model.on_time[1:], model.late[1:])

    # (28): each follower's filter, and its packet [x(k|k), x(k|k-1), x(k|k-2)]
    one_step, one_step_cov = state.prediction[..., 0, :], state.prediction_cov[..., 0, :, :]
    local, local_cov = kalman_update(one_step, one_step_cov, z[..., 1:, :], H, R[1:])
    packet = np.concatenate([local[..., None, :], state.prediction], axis=-2)
    packet_cov = np.concatenate([local_cov[..., None, :, :], state.prediction_cov], axis=-3)
    # concatenate of the expanded pieces is np.stack's result with less dispatch
    prediction = np.concatenate([local[..., None, :], one_step[..., None, :]], axis=-2) @ Phi.T
    prediction_cov = _sym(Phi @ np.concatenate([local_cov[..., None, :, :], one_step_cov[..., None, :, :]],
                                               axis=-3) @ Phi.T + Q)

    # delivery: eq. (3) on packets
    on_time = (followers == ON_TIME) & transmit
    late = (followers == LATE) & state.sent
    delivered = np.where(on_time, ON_TIME, np.where(late, LATE, LOST))
    held = deliver(packet, state.packet, state.held, delivered)
    held_cov = deliver(packet_cov, state.packet_cov, state.held_cov, delivered)
    held_age = np.where(on_time, 0, np.where(late, 1, state.held_age + 1))

    # (27): the leader's own filter from the fed-back estimate
    own, own_cov = kalman_update(state.leader_prediction, state.leader_prediction_cov, z[..., 0, :], H, R[0])

    # (29) compensation, (30) fusion, (31) feedback
    used, used_cov = held, held_cov
    if reading == "age_aware":
        powers, noise = age_propagators(model, int(held_age.max(initial=0)))
        step = powers[held_age][..., None, :, :]
        used = np.einsum("...ab,...b->...a", step, held)
        used_cov = _sym(step @ held_cov @ np.swapaxes(step, -1, -2) + noise[held_age][..., None, :, :])
    elif reading == "forward":  # Phi^a x_h, Phi^a P_h Phi^aT + sum_{j<a} Phi^j Q Phi^jT for a = 0, 1, 2
        powers, noise = age_propagators(model, 2)
        used = np.einsum("aij,...j->...ai", powers, held[..., 0, :])
        used_cov = _sym(powers @ held_cov[..., 0, None, :, :] @ np.swapaxes(powers, -1, -2) + noise)
    compensated = np.einsum("...j,...jn->...n", compensation, used)
    compensated_cov = np.einsum("...j,...jab->...ab", compensation, used_cov)
    if reading == "forward" and forward_spread:  # + sum_a w_a (m_a - xbar)(m_a - xbar)^T
        spread = used - compensated[..., None, :]
        compensated_cov = _sym(compensated_cov + np.einsum("...j,...ja,...jb->...ab", compensation, spread, spread))
    estimates = np.concatenate([own[..., None, :], compensated], axis=-2)
    covariances = np.concatenate([own_cov[..., None, :, :], compensated_cov], axis=-3)
    weights = inverse_trace_weights(covariances, fusion_factors)
    fused = np.einsum("...i,...in->...n", weights, estimates)
    fused_cov = _sym(np.einsum("...i,...iab->...ab", weights**2, covariances))
    return DistributedState(  # every field anew (dataclasses.replace would introspect them per call)
        prediction=prediction, prediction_cov=prediction_cov, packet=packet, packet_cov=packet_cov,
        sent=transmit.copy(), held=held, held_cov=held_cov, held_age=held_age,
        leader_prediction=fused @ Phi.T, leader_prediction_cov=_sym(Phi @ fused_cov @ Phi.T + Q),
        fused=fused, fused_cov=fused_cov, weights=weights, compensated=compensated,
        compensated_cov=compensated_cov, delivered=delivered,
    )


def distributed_filter(model: LossyModel, x0_mean, P0, z: np.ndarray, outcome: np.ndarray, reading: str = "current",
                       forward_spread: bool = True):
    """(B) over an episode with the paper's weights: estimates (..., K, n), own covariances P0(k) (..., K, n, n).

    ``reading``, ``forward_spread``: how the leader compensates a held packet (``distributed_step``;
    ``"current"`` is the paper as printed).
    """
    z = np.asarray(z, float)
    K, batch, n = z.shape[-3], z.shape[:-3], model.state_dim
    state = distributed_initial(model, x0_mean, P0, batch)
    shared = distributed_initial(model, x0_mean, P0)  # the followers' covariances: one stack for every run
    state.prediction_cov, state.packet_cov = shared.prediction_cov, shared.packet_cov
    estimates, covariances = np.empty((*batch, K, n)), np.empty((*batch, K, n, n))
    for k in range(K):
        state = distributed_step(model, state, z[..., k, :, :], outcome[..., k, :], reading=reading,
                                 forward_spread=forward_spread)
        estimates[..., k, :], covariances[..., k, :, :] = state.fused, state.fused_cov
    return estimates, covariances


def run_filters(model: LossyModel, x0_mean, P0, z: np.ndarray, outcome: np.ndarray, filters=FILTERS) -> dict:
    """Every filter of ``FILTERS`` on the same runs: name -> (estimates, own covariances)."""
    unknown = sorted(set(filters) - set(FILTERS))
    if unknown:
        raise ValueError(f"unknown filters {unknown}; available: {list(FILTERS)}")
    H = np.asarray(model.measurement, float)
    y = received_measurements(z, outcome, H @ np.asarray(x0_mean, float))
    makers = {
        "naive_kf": lambda: kalman_filter(model, x0_mean, P0, y),
        "centralized": lambda: centralized_filter(model, x0_mean, P0, y, "optimal"),
        "centralized_paper_gain": lambda: centralized_filter(model, x0_mean, P0, y, "paper"),
        "distributed": lambda: distributed_filter(model, x0_mean, P0, z, outcome),
        "informed_kf": lambda: informed_filter(model, x0_mean, P0, y, outcome),
        "leader_only_kf": lambda: kalman_filter(model, x0_mean, P0, z[..., :1, :], uavs=[0]),
        "ideal_kf": lambda: kalman_filter(model, x0_mean, P0, z),
    }
    return {name: makers[name]() for name in filters}
