"""UKF-CCL and UKF-DCL of wang2019 extended to planar robots with heading, range AND bearing, and landmarks.

Base algorithm: Wang L., Cui J., Kong D., Zhao L., "A distributed cooperative
localization algorithm for mobile multi-platforms oriented to unpredicted
communication topology", Trans. Nanjing Univ. Aero. Astro. 36(2):224-231,
2019 (eqs. 5-23; the position-only form is ``estimators.ukf_relay``, whose
sigma-point and relay-chain conventions this module keeps: lower Cholesky,
the measuring platforms ordered first (eq. 17), 2L + 1 points with
w_0 = lambda/(L + lambda), w_p = 0.5/(L + lambda), the look-up Cholesky
(15)-(16) along the chain, the sign and inverse corrections listed there).
Cross-covariance factorization: Roumeliotis S.I., Bekey G.A., "Distributed
multirobot localization", IEEE Trans. Robotics and Automation 18(5):781-795,
2002 (Sec. III-IV).

Extension (documented here because neither paper states it in this form)
-----------------------------------------------------------------------
State: robot i has s_i = (x_i, y_i, theta_i); the joint state is
s = [s_1; ...; s_N] in R^{3N}, covariance P (3N x 3N), L = 3N.

Time update (unicycle, Euler over dt, odometry u_i = (v_i, w_i) with white
noise of variances (sigma_v^2, sigma_w^2), the same for every robot or, for a
speed-dependent model (``odometry_variance``), one pair per robot):

    s_i <- s_i + dt [v_i cos theta_i; v_i sin theta_i; w_i],
    F_i = [[1, 0, -dt v_i sin theta_i], [0, 1, dt v_i cos theta_i], [0, 0, 1]],
    G_i = dt [[cos theta_i, 0], [sin theta_i, 0], [0, 1]],
    P_ii <- F_i P_ii F_i^T + G_i diag(sigma_v,i^2, sigma_w,i^2) G_i^T,
    P_ij <- F_i P_ij F_j^T  (i != j).

With the heading in the state the transition is no longer the identity and
the cross-covariances change (wang2019's position-only P_ij stays fixed).
The time update is the linearized (EKF) one so that the cross terms factor.
Roumeliotis-Bekey: write P_ij = Phi_i sigma_ij Phi_j^T with Phi_i the
product of robot i's own F_i since the start (Phi_i(0) = I); each robot
propagates only Phi_i <- F_i Phi_i and its own P_ii, and sigma_ij changes
only at observation updates. F_i has determinant 1, so Phi_i is invertible.

Observation: robot m measures robot n (or a known landmark l),

    h = [ ||p_n - p_m|| ; wrap(atan2(y_n - y_m, x_n - x_m) - theta_m) ],  R = diag(sigma_r^2, sigma_b^2),

a 2-vector instead of wang2019's scalar range. The UT is the one of
``estimators.ukf_relay`` on the joint state (L = 3N) with the observed
robots (m, n, or m alone for a landmark) ordered first. Bearings are
averaged as offsets from h(xbar): d_p = wrap(h(chi_p) - h(xbar)),
zbar = h(xbar) + sum_p w_p d_p, the deviations d_p - sum_q w_q d_q, and the
innovation nu = wrap(z - zbar). Pz (2 x 2) = sum_p w_p dz_p dz_p^T + R,
K = Pxz Pz^-1, s <- s + K nu, P <- P - K Pz K^T (heading wrapped after).

Only the first 3q columns of A (q = 2 observed robots, or 1 for a
landmark) move h; the other sigma points leave z at h(xbar). So with
g = sqrt(L + lambda) w_p (dz_p^+ - dz_p^-), p <= 3q (a 3q x 2 matrix),
Pxz_j = A_j[:, :3q] g for every robot j, and the distributed form is the
one of wang2019 with 3 x 3 blocks and 3 x 2 update weights:

* UKF-DCL along the chain c_1 = m (, c_2 = n), c_3, ...: receiver c_i forms
  P_{c_i c_j} = Phi_{c_i} sigma_{c_i c_j} Phi_{c_j}^T from its own row of
  sigma and the Phi_{c_j} carried in the message, its row of A by the
  look-up Cholesky (15)-(16), Pxz_{c_i} (20), its estimate (21), and the
  decrements Delta P_{c_i c_j} = Pxz_{c_i} Pz^-1 Pxz_{c_j}^T (22)-(23),
  stored as sigma_{c_i c_j} -= Phi_{c_i}^-1 Delta P Phi_{c_j}^-T.
* Truncated chains (reached set R, unreached U): gain [K_R; 0] and
  P_RU <- P_RU - K_R Pxz_U^T, where Pxz_U^T = g^T A_o^-1 P_{o,U}
  (o = observed robots) = r_U Phi_U^T with r_U = g^T A_o^-1 [Phi_o sigma_{o,U}],
  which the observers compute from their own rows. Hence
  sigma_RU -= Phi_R^-1 K_R r_U: exact, and no robot in U takes part.

A complete chain gives exactly the CCL update (tests: 1e-9 on the MRCLAM
data); the order of the robots after the observers does not matter.

Outlier gate (both forms identically): an observation whose normalized
innovation nu^T Pz^-1 nu exceeds ``gate`` is not applied (MRCLAM holds
misread barcodes and occluded detections); ``gate=None`` applies all.

Arrays: ``estimate`` (N, 3), ``cov`` (3N, 3N); ``FactoredCov`` holds
``P_ii`` (N, 3, 3), ``phi`` (N, 3, 3), ``sigma`` (N, N, 3, 3) (sigma[i, i] unused).
``ccl_update``, ``dcl_update`` and ``time_update`` take one copy;
the factored form also has a leading batch axis B: ``time_update_factored``
/ ``time_update_batch`` on (B, N, ...) and ``dcl_update_batch`` /
``dcl_update_rows`` on G copies at once (one chain length per call; in
place at chosen copies of (B, ...) arrays for the env backend).

Batched form (the same equations, no loop over copies)
------------------------------------------------------
The receivers of a chain update independently once the message (nu, Pz, g, the
rows of A, the Pxz of the up-neighbours, r_U) is formed, so the batched update
stacks them as well as the copies: A is the lower Cholesky factor of the chain's
covariance P_cc, whose rows the look-up Cholesky (15)-(16) forms receiver by
receiver (the observers' 3q x 3q block first, for the sigma points; the rest
only for copies the gate passes); Pxz = A[:, :3q] g for all receivers (20); the
decrements (22)-(23) as one product (Phi_c^-1 K)(Phi_c^-1 Pxz)^T over the
chain's 3k x 3k block, of which the pairs i > j are kept, and
Phi_{c_i}^-1 K_i r_U for the unreached robots; r_U = (A_o^-T g)^T [Phi_o sigma_{o,U}];
Phi_i^-1 [K_i, Pxz_i] by one LU solve per Phi_i; Pz^-1 (2 x 2) by its adjugate. Every sum is a stacked
matrix product or a linalg gufunc, so copy b's result does not depend on the
other copies of the call (bit for bit), and it equals ``dcl_update`` to
rounding (tests: 1e-12).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from estimators.ukf_relay import ukf_weights

__all__ = [
    "FactoredCov",
    "ccl_update",
    "ccl_update_copies",
    "correct_odometry",
    "dcl_update",
    "factor",
    "motion",
    "observe",
    "odometry_variance",
    "time_update",
    "dcl_update_batch",
    "dcl_update_rows",
    "time_update_batch",
    "time_update_copies",
    "time_update_factored",
    "wrap",
]


def wrap(angle):
    """Angle(s) wrapped to [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def motion(estimate: np.ndarray, odometry: np.ndarray, dt: float):
    """Unicycle step of every robot: new (N, 3) states and the Jacobians F (N, 3, 3), G (N, 3, 2)."""
    s, u = np.asarray(estimate, float), np.asarray(odometry, float)
    v, w, th = u[..., 0], u[..., 1], s[..., 2]
    c, si = np.cos(th), np.sin(th)
    new = np.stack([s[..., 0] + dt * v * c, s[..., 1] + dt * v * si, wrap(th + dt * w)], axis=-1)
    F = np.zeros((*s.shape[:-1], 3, 3))
    F[..., 0, 0] = F[..., 1, 1] = F[..., 2, 2] = 1.0
    F[..., 0, 2] = -dt * v * si
    F[..., 1, 2] = dt * v * c
    G = np.zeros((*s.shape[:-1], 3, 2))
    G[..., 0, 0], G[..., 1, 0], G[..., 2, 1] = dt * c, dt * si, dt
    return new, F, G


def _noise(G: np.ndarray, odometry_var) -> np.ndarray:
    """Q_i = G_i diag(sigma_v,i^2, sigma_w,i^2) G_i^T, (..., N, 3, 3); ``odometry_var`` (2,), (N, 2) or, with
    leading batch axes on G, (..., N, 2)."""
    q = np.asarray(odometry_var, float)
    robots = G.shape[:-2]
    if (q.ndim < 1 or q.shape[-1] != 2 or (q.ndim >= 2 and q.shape[:-1] not in (robots, robots[-1:]))
            or np.any(q < 0)):
        raise ValueError(
            f"odometry_var must be (sigma_v^2, sigma_w^2) >= 0, shape (2,) or (N, 2), got {odometry_var!r}")
    return (G * q[..., None, :]) @ np.swapaxes(G, -1, -2)


def correct_odometry(odometry, scale=(1.0, 1.0), delay: int = 0) -> np.ndarray:
    """Odometry (T, N, 2) with a calibrated scale and actuation delay: u'[k] = scale * u[max(k - delay, 0)].

    ``delay`` steps: the command logged at step k moves the robot from step k + delay on
    (a robot's response lags its command); before the first command the first one is held.
    """
    u = np.asarray(odometry, float)
    delay = int(delay)
    if delay < 0 or u.ndim < 2 or u.shape[-1] != 2:
        raise ValueError(f"correct_odometry: delay must be >= 0 and odometry (T, ..., 2), got {delay}, {u.shape}")
    index = np.maximum(np.arange(len(u)) - delay, 0)
    return u[index] * np.asarray(scale, float)


def odometry_variance(odometry, var0, var_gain=(0.0, 0.0), inflation=(1.0, 1.0)) -> np.ndarray:
    """Speed-dependent odometry variances, per robot: inflation * (var0 + var_gain * u^2), shape of ``odometry``.

    For (v, w): sigma_v^2 = r_v (a_v + b_v v^2), sigma_w^2 = r_w (a_w + b_w w^2); ``inflation``
    (r_v, r_w) >= 1 accounts for errors correlated over steps (see
    ``coloc_env.data.mrclam_noise.calibrate_noise``). The result is a valid ``odometry_var``
    for ``time_update`` / ``time_update_factored`` when ``odometry`` is (N, 2).
    """
    u = np.asarray(odometry, float)
    a, b, r = (np.asarray(x, float) for x in (var0, var_gain, inflation))
    if np.any(a < 0) or np.any(b < 0) or np.any(r <= 0):
        raise ValueError(
            f"odometry_variance: var0, var_gain must be >= 0 and inflation > 0, got {var0}, {var_gain}, {inflation}")
    return r * (a + b * u**2)


def time_update(estimate, cov, odometry, dt: float, odometry_var):
    """Joint (CCL) time update: s_i <- f(s_i, u_i), P <- F P F^T + G Q G^T with F block diagonal."""
    new, F, G = motion(estimate, odometry, dt)
    N = len(new)
    Fb = np.zeros((3 * N, 3 * N))
    Qb = np.zeros((3 * N, 3 * N))
    Q = _noise(G, odometry_var)
    for i in range(N):
        Fb[3 * i:3 * i + 3, 3 * i:3 * i + 3] = F[i]
        Qb[3 * i:3 * i + 3, 3 * i:3 * i + 3] = Q[i]
    P = Fb @ np.asarray(cov, float) @ Fb.T + Qb
    return new, 0.5 * (P + P.T)


@dataclass
class FactoredCov:
    """Roumeliotis-Bekey storage: P_ii, Phi_i per robot; P_ij = Phi_i sigma_ij Phi_j^T (i != j)."""

    P_ii: np.ndarray
    phi: np.ndarray
    sigma: np.ndarray

    def block(self, i: int, j: int) -> np.ndarray:
        if i == j:
            return self.P_ii[i]
        return self.phi[i] @ self.sigma[i, j] @ self.phi[j].T

    def joint(self) -> np.ndarray:
        """The joint covariance P (3N x 3N) the factors stand for."""
        N = len(self.P_ii)
        return np.block([[self.block(i, j) for j in range(N)] for i in range(N)])

    def copy(self) -> FactoredCov:
        return FactoredCov(self.P_ii.copy(), self.phi.copy(), self.sigma.copy())


def factor(cov: np.ndarray) -> FactoredCov:
    """Factors of a joint covariance with Phi_i = I."""
    cov = np.asarray(cov, float)
    N = cov.shape[0] // 3
    blocks = cov.reshape(N, 3, N, 3).transpose(0, 2, 1, 3).copy()
    P_ii = blocks[np.arange(N), np.arange(N)].copy()
    return FactoredCov(P_ii, np.broadcast_to(np.eye(3), (N, 3, 3)).copy(), blocks)


def time_update_factored(estimate, fcov: FactoredCov, odometry, dt: float, odometry_var):
    """Each robot alone: s_i <- f(s_i, u_i), P_ii <- F_i P_ii F_i^T + Q_i, Phi_i <- F_i Phi_i.

    Leading batch axes are allowed (see ``time_update_batch``); sigma is copied unchanged."""
    new, P_ii, phi = time_update_batch(estimate, fcov.P_ii, fcov.phi, odometry, dt, odometry_var)
    return new, FactoredCov(P_ii, phi, fcov.sigma.copy())


def time_update_batch(estimate, P_ii, phi, odometry, dt: float, odometry_var):
    """The factored time update on arrays with leading batch axes: ``estimate`` (..., N, 3), ``P_ii`` and
    ``phi`` (..., N, 3, 3), ``odometry`` (..., N, 2), ``odometry_var`` (2,), (N, 2) or (..., N, 2).

    Returns new ``(estimate, P_ii, phi)``; sigma does not change (the module's time update: F_i and
    Q_i = G_i diag(sigma_v,i^2, sigma_w,i^2) G_i^T per robot and copy). Every copy is computed by the
    same elementwise and stacked-matrix operations, so copy b equals the same copy updated alone.
    """
    new, F, G = motion(estimate, odometry, dt)
    P = F @ P_ii @ np.swapaxes(F, -1, -2) + _noise(G, odometry_var)
    return new, 0.5 * (P + np.swapaxes(P, -1, -2)), F @ phi


def observe(observer_state: np.ndarray, target_xy: np.ndarray) -> np.ndarray:
    """h = (range, bearing) from pose(s) (..., 3) to point(s) (..., 2), shape (..., 2)."""
    d = np.asarray(target_xy, float) - np.asarray(observer_state, float)[..., :2]
    return np.stack([np.hypot(d[..., 0], d[..., 1]),
                     wrap(np.arctan2(d[..., 1], d[..., 0]) - observer_state[..., 2])], axis=-1)


def _check(N, measuring, measured, landmark):
    if not 0 <= measuring < N:
        raise ValueError(f"measuring must be a robot in [0, {N - 1}], got {measuring}")
    if (measured is None) == (landmark is None):
        raise ValueError("give exactly one of measured (a robot) and landmark (a position)")
    if measured is not None and (not 0 <= measured < N or measured == measuring):
        raise ValueError(f"measured must be a robot in [0, {N - 1}] other than measuring, got {measured}")


def _moments(h_points: np.ndarray, h0: np.ndarray, w: np.ndarray, R: np.ndarray):
    """zbar, deviations (P, 2) and Pz of h evaluated on the sigma points (bearing as offsets from h0)."""
    d = h_points - h0
    d[:, 1] = wrap(d[:, 1])
    mu = w @ d
    dz = d - mu
    Pz = np.einsum("p,pa,pb->ab", w, dz, dz) + R
    return h0 + mu, dz, 0.5 * (Pz + Pz.T)


def ccl_update(estimate, cov, measuring: int, z, R, measured: int | None = None, landmark=None,
               lam: float = 0.0, reached=None, gate: float | None = None):
    """UKF-CCL observation update on the joint state (L = 3N, observed robots first).

    ``z`` = (range, bearing) measured by robot ``measuring`` of robot ``measured``
    or of the known ``landmark`` (x, y). ``reached`` (N,) bool: robots whose
    estimate updates (the others get gain 0; covariance of the gain [K_R; 0]).
    Returns ``(estimate, cov, applied)``; ``applied`` is False when the gate rejected z.
    """
    x, P = np.asarray(estimate, float), np.asarray(cov, float)
    N = len(x)
    _check(N, measuring, measured, landmark)
    L = 3 * N
    observed = [measuring] if measured is None else [measuring, measured]
    order = observed + [i for i in range(N) if i not in observed]
    idx = (3 * np.asarray(order)[:, None] + np.arange(3)).ravel()
    x_r, P_r = x.ravel()[idx], P[np.ix_(idx, idx)]
    w = ukf_weights(L, lam)
    cols = np.sqrt(L + lam) * np.linalg.cholesky(P_r).T
    chi = np.concatenate([x_r[None], x_r + cols, x_r - cols])
    target = chi[:, 3:5] if measured is not None else np.broadcast_to(np.asarray(landmark, float), (len(chi), 2))
    h = observe(chi[:, 0:3], target)
    z_bar, dz, Pz = _moments(h, h[0].copy(), w, np.asarray(R, float))
    nu = np.asarray(z, float) - z_bar
    nu[1] = wrap(nu[1])
    Pz_inv = np.linalg.inv(Pz)
    if gate is not None and nu @ Pz_inv @ nu > gate:
        return x.copy(), P.copy(), False
    Pxz = np.einsum("p,pl,pa->la", w, chi - x_r, dz)
    K = Pxz @ Pz_inv
    if reached is not None:
        K = K * np.repeat(np.asarray(reached, bool)[order], 3)[:, None]
    x_r = x_r + K @ nu
    KPxz = K @ Pxz.T
    P_r = P_r - KPxz - KPxz.T + K @ Pz @ K.T
    inverse = np.argsort(idx)
    x_new = x_r[inverse].reshape(N, 3)
    x_new[:, 2] = wrap(x_new[:, 2])
    P_new = P_r[np.ix_(inverse, inverse)]
    return x_new, 0.5 * (P_new + P_new.T), True


def ccl_update_copies(estimate, cov, measuring: int, z, R, measured: int | None = None, landmark=None,
                      lam: float = 0.0, gate: float | None = None):
    """``ccl_update`` on G copies that share one observation (robot ``measuring``, its target, ``z``) but
    not their state or noise: ``estimate`` (G, N, 3), ``cov`` (G, 3N, 3N), ``R`` (G, 2, 2).

    The same equations copy by copy (stacked Cholesky factors, sigma points, moments); the gate decides
    per copy. Returns ``(estimate, cov, applied (G,), nis (G,))``, nis = nu^T Pz^-1 nu of each copy.
    """
    x, P = np.asarray(estimate, float), np.asarray(cov, float)
    G, N = x.shape[:2]
    _check(N, measuring, measured, landmark)
    L = 3 * N
    observed = [measuring] if measured is None else [measuring, measured]
    order = observed + [i for i in range(N) if i not in observed]
    idx = (3 * np.asarray(order)[:, None] + np.arange(3)).ravel()
    x_r, P_r = x.reshape(G, L)[:, idx], P[:, idx][:, :, idx]
    w = ukf_weights(L, lam)
    cols = np.sqrt(L + lam) * np.swapaxes(np.linalg.cholesky(P_r), -1, -2)
    chi = np.concatenate([x_r[:, None], x_r[:, None] + cols, x_r[:, None] - cols], axis=1)  # (G, 2L + 1, L)
    target = (chi[..., 3:5] if measured is not None
              else np.broadcast_to(np.asarray(landmark, float), (*chi.shape[:2], 2)))
    h = observe(chi[..., 0:3], target)
    dev = h - h[:, :1]
    dev[..., 1] = wrap(dev[..., 1])
    mu = np.einsum("p,gpa->ga", w, dev)
    dz = dev - mu[:, None]
    Pz = np.einsum("p,gpa,gpb->gab", w, dz, dz) + np.asarray(R, float)
    Pz = 0.5 * (Pz + np.swapaxes(Pz, -1, -2))
    nu = np.asarray(z, float) - (h[:, 0] + mu)
    nu[:, 1] = wrap(nu[:, 1])
    Pz_inv = np.linalg.inv(Pz)
    nis = np.einsum("ga,gab,gb->g", nu, Pz_inv, nu)
    applied = np.ones(G, bool) if gate is None else nis <= gate
    Pxz = np.einsum("p,gpl,gpa->gla", w, chi - x_r[:, None], dz)
    K = (Pxz @ Pz_inv) * applied[:, None, None]
    x_r = x_r + np.einsum("gla,ga->gl", K, nu)
    KPxz = K @ np.swapaxes(Pxz, -1, -2)
    P_r = P_r - KPxz - np.swapaxes(KPxz, -1, -2) + K @ Pz @ np.swapaxes(K, -1, -2)
    inverse = np.argsort(idx)
    x_new = x_r[:, inverse].reshape(G, N, 3)
    x_new[..., 2] = wrap(x_new[..., 2])
    P_new = P_r[:, inverse][:, :, inverse]
    return x_new, 0.5 * (P_new + np.swapaxes(P_new, -1, -2)), applied, nis


def time_update_copies(estimate, cov, odometry, dt: float, odometry_var):
    """``time_update`` on G copies: ``estimate`` (G, N, 3), ``cov`` (G, 3N, 3N), ``odometry`` (N, 2) or
    (G, N, 2), ``odometry_var`` (G, N, 2)."""
    new, F, Gm = motion(estimate, np.broadcast_to(odometry, np.shape(estimate)[:-1] + (2,)), dt)
    G, N = new.shape[:2]
    blocks = np.asarray(cov, float).reshape(G, N, 3, N, 3)
    blocks = np.einsum("giab,gibjc,gjdc->giajd", F, blocks, F)
    blocks[:, np.arange(N), :, np.arange(N), :] += np.moveaxis(_noise(Gm, odometry_var), 0, 1)
    P = blocks.reshape(G, 3 * N, 3 * N)
    return new, 0.5 * (P + np.swapaxes(P, -1, -2))


def dcl_update(estimate, fcov: FactoredCov, chain, z, R, measured_in_chain: bool = True, landmark=None,
               lam: float = 0.0, gate: float | None = None):
    """UKF-DCL along the relay ``chain`` (robot indices, no repeats) on the factored covariance.

    ``chain[0]`` is the measuring robot; with ``measured_in_chain`` ``chain[1]``
    is the measured robot, otherwise ``landmark`` (x, y) is the target. Each
    receiver uses only its own P_ii, Phi_i, its row of sigma and the message
    (rows of A, update weights Pxz, Phi of its up-neighbours, S_m, and the
    r_U of the observers for robots the chain does not reach).
    Returns ``(estimate, fcov, applied)``, new objects.
    """
    x = np.array(estimate, dtype=float)
    N = len(x)
    chain = [int(c) for c in chain]
    q = 2 if measured_in_chain else 1
    if len(set(chain)) != len(chain) or not chain or any(not 0 <= c < N for c in chain):
        raise ValueError(f"chain must list distinct robots in [0, {N - 1}], got {chain}")
    if len(chain) < q:
        raise ValueError("a chain must reach the measuring and the measured robot")
    if not measured_in_chain and landmark is None:
        raise ValueError("landmark: a landmark observation needs its position")
    L, k = 3 * N, len(chain)
    w = ukf_weights(L, lam)
    w0, wp = w[0], w[1]
    scale = np.sqrt(L + lam)
    f = fcov.copy()
    A = np.zeros((3 * k, 3 * k))

    def row_block(i):  # look-up Cholesky (15)-(16) by receiver chain[i]
        ci = chain[i]
        if i:
            own = np.concatenate([f.block(ci, chain[j]) for j in range(i)], axis=1)  # (3, 3i)
            left = np.linalg.solve(A[:3 * i, :3 * i], own.T).T
            A[3 * i:3 * i + 3, :3 * i] = left
            schur = f.P_ii[ci] - left @ left.T
        else:
            schur = f.P_ii[ci]
        A[3 * i:3 * i + 3, 3 * i:3 * i + 3] = np.linalg.cholesky(0.5 * (schur + schur.T))

    for i in range(q):
        row_block(i)
    m = chain[0]
    dev = scale * A[:3 * q, :3 * q]  # sigma deviations of the observed robots, columns p <= 3q
    x_o = x[chain[:q]].ravel()
    plus, minus = x_o[:, None] + dev, x_o[:, None] - dev  # (3q, 3q): column p = point p
    pts = np.concatenate([plus.T, minus.T])  # (6q, 3q)
    if measured_in_chain:
        h, h0 = observe(pts[:, 0:3], pts[:, 3:5]), observe(x[m], x[chain[1], :2])
    else:
        lm = np.asarray(landmark, float)
        h, h0 = observe(pts[:, 0:3], lm), observe(x[m], lm)
    # the other 2(L - 3q) points and the centre leave z at h0 (deviation 0 from h0)
    h_all = np.concatenate([h0[None], h[:3 * q], np.repeat(h0[None], L - 3 * q, 0),
                            h[3 * q:], np.repeat(h0[None], L - 3 * q, 0)])
    z_bar, dz, Pz = _moments(h_all, h0.copy(), w, np.asarray(R, float))
    del w0
    nu = np.asarray(z, float) - z_bar
    nu[1] = wrap(nu[1])
    Pz_inv = np.linalg.inv(Pz)
    if gate is not None and nu @ Pz_inv @ nu > gate:
        return x, f, False
    g = scale * wp * (dz[1:1 + 3 * q] - dz[1 + L:1 + L + 3 * q])  # (3q, 2)

    unreached = [u for u in range(N) if u not in chain]
    if unreached:  # observers: r_U = g^T A_o^-1 [Phi_o sigma_{o,U}]
        rows = np.concatenate([np.concatenate([f.phi[o] @ f.sigma[o, u] for u in unreached], axis=1)
                               for o in chain[:q]])
        r_U = (g.T @ np.linalg.solve(A[:3 * q, :3 * q], rows)).reshape(2, len(unreached), 3)

    weights = []
    for i in range(k):
        if i >= q:
            row_block(i)
        ci = chain[i]
        Pxz_i = A[3 * i:3 * i + 3, :3 * q] @ g  # (20)
        weights.append(Pxz_i)
        K_i = Pxz_i @ Pz_inv
        x[ci] = x[ci] + K_i @ nu  # (21)
        phi_inv = np.linalg.inv(f.phi[ci])
        for j in range(i + 1):  # (22)-(23)
            cj = chain[j]
            delta = K_i @ weights[j].T
            if j == i:
                P = f.P_ii[ci] - delta
                f.P_ii[ci] = 0.5 * (P + P.T)
            else:
                f.sigma[ci, cj] -= phi_inv @ delta @ np.linalg.inv(f.phi[cj]).T
                f.sigma[cj, ci] = f.sigma[ci, cj].T
        for a, u in enumerate(unreached):
            f.sigma[ci, u] -= phi_inv @ K_i @ r_U[:, a, :]
            f.sigma[u, ci] = f.sigma[ci, u].T
    x[:, 2] = wrap(x[:, 2])
    return x, f, True


def dcl_update_batch(estimate, fcov: FactoredCov, chain, z, R, measured_in_chain: bool = True, landmark=None,
                     lam: float = 0.0, gate: float | None = None):
    """``dcl_update`` of G copies at once: ``estimate`` (G, N, 3), ``fcov`` with a leading axis G
    (``P_ii``, ``phi`` (G, N, 3, 3), ``sigma`` (G, N, N, 3, 3)), ``chain`` (G, k) (one chain length for
    all copies, each row distinct robots), ``z`` (G, 2), ``R`` (G, 2, 2) or (2, 2), ``landmark`` (G, 2)
    or (2,). Returns ``(estimate, fcov, applied)``, new objects, ``applied`` (G,) bool.

    Copy g equals ``dcl_update`` of copy g alone (to rounding: the same equations in stacked-matrix form,
    tests hold 1e-12); see ``dcl_update_rows``.
    """
    x = np.array(estimate, dtype=float)
    f = fcov.copy()
    applied = dcl_update_rows(x, f.P_ii, f.phi, f.sigma, np.arange(len(x)), chain, z, R,
                              measured_in_chain=measured_in_chain, landmark=landmark, lam=lam, gate=gate)
    return x, f, applied


@functools.lru_cache(maxsize=64)
def _lower(k: int) -> tuple[np.ndarray, np.ndarray]:
    """The index pairs (i, j), i > j, of a k x k lower triangle (read-only, cached)."""
    pairs = np.tril_indices(k, -1)
    for a in pairs:
        a.flags.writeable = False
    return pairs


@functools.lru_cache(maxsize=64)
def _weights(L: int, lam: float) -> np.ndarray:
    """``estimators.ukf_relay.ukf_weights`` (read-only, cached)."""
    w = ukf_weights(L, lam)
    w.flags.writeable = False
    return w


def _chain_blocks(P_ii, sigma, rows, chain, phic):
    """The chain's covariance blocks per copy, (G, k, k, 3, 3): P_{c_i c_i} = P_ii, and for i > j
    P_{c_i c_j} = Phi_{c_i} sigma_{c_i c_j} Phi_{c_j}^T (what receiver c_i forms from its own row of sigma and
    the Phi_{c_j} in the message); the upper blocks are left at zero (a lower Cholesky reads the lower
    triangle). Also returns the gathered sigma_{c_i c_j} (G, k(k-1)/2, 3, 3) of the pairs i > j."""
    G, k = chain.shape
    if k == 1:
        return P_ii[rows, chain[:, 0]][:, None, None], None
    lower_i, lower_j = _lower(k)
    S = sigma[rows[:, None], chain[:, lower_i], chain[:, lower_j]]
    blocks = np.zeros((G, k, k, 3, 3))
    blocks[:, lower_i, lower_j] = phic[:, lower_i] @ S @ phic[:, lower_j].mT
    diagonal = np.arange(k)
    blocks[:, diagonal, diagonal] = P_ii[rows[:, None], chain]
    return blocks, S


def _inv2(M: np.ndarray) -> np.ndarray:
    """Inverses of 2 x 2 matrices (G, 2, 2) by the adjugate, elementwise over the stack (Pz, positive definite)."""
    a, b, c, d = M.reshape(-1, 4).T
    det = a * d - b * c
    return (np.stack([d, -b, -c, a], axis=-1) / det[:, None]).reshape(M.shape)


def _cholesky_blocks(blocks: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor (G, 3k, 3k) of the block matrix (G, k, k, 3, 3) (its lower triangle)."""
    G, k = blocks.shape[:2]
    return np.linalg.cholesky(blocks.transpose(0, 1, 3, 2, 4).reshape(G, 3 * k, 3 * k))


def _moments_batch(h: np.ndarray, h0: np.ndarray, w: np.ndarray, R: np.ndarray):
    """``_moments`` per copy from the 2 x 3q points that move h: h (G, 6q, 2) (plus points, then minus),
    h0 (G, 2). The centre and the other 2(L - 3q) points sit at h0 (deviation 0 from h0), so with
    d_p = wrap(h_p - h0) on the moving points, w_p = w[1] on each of them and 1 - 6q w_p on the rest:

        mu = w_p sum_p d_p,  Pz = w_p sum_p (d_p - mu)(d_p - mu)^T + (1 - 6q w_p) mu mu^T + R.

    Returns zbar = h0 + mu (G, 2), the moving points' deviations d_p - mu (G, 6q, 2) and Pz (G, 2, 2). The sums
    are stacked matrix products, so every copy is computed by the same operation whatever G is."""
    wp = w[1]
    d = h - h0[:, None]
    d[..., 1] = wrap(d[..., 1])
    mu = wp * (_ones(d.shape[1]) @ d)
    dz = d - mu[:, None]
    rest = 1.0 - d.shape[1] * wp  # the centre's weight and the 2(L - 3q) points that stay at h0
    Pz = wp * (dz.mT @ dz) + rest * (mu[:, :, None] * mu[:, None, :]) + R
    return h0 + mu, dz, 0.5 * (Pz + Pz.mT)


@functools.lru_cache(maxsize=16)
def _ones(n: int) -> np.ndarray:
    out = np.ones(n)
    out.flags.writeable = False
    return out


def dcl_update_rows(estimate, P_ii, phi, sigma, rows, chain, z, R, measured_in_chain: bool = True,
                    landmark=None, lam: float = 0.0, gate: float | None = None) -> np.ndarray:
    """UKF-DCL of ``dcl_update`` on copies ``rows`` of batched arrays, in place.

    ``estimate`` (B, N, 3), ``P_ii``, ``phi`` (B, N, 3, 3), ``sigma`` (B, N, N, 3, 3) are updated at the
    distinct copies ``rows`` (G,); ``chain`` (G, k): copy rows[g]'s chain, one length k for all (group the
    copies by chain length); ``z`` (G, 2); ``R`` (G, 2, 2) or (2, 2); ``landmark`` (G, 2) or (2,) when not
    ``measured_in_chain``. Returns ``applied`` (G,) bool (False: the gate refused z, the copy is unchanged).

    The equations of the module docstring, stacked over the G copies and over the k receivers of the chain
    (each receiver's arithmetic uses its own row of A, of sigma, its Phi and the message, so the receivers'
    steps are independent given the message and run as one stacked operation; no Python loop over copies
    or receivers):

    * A: the rows the look-up Cholesky (15)-(16) forms receiver by receiver are the rows of the lower
      Cholesky factor of the chain's covariance P_cc (blocks Phi_{c_i} sigma_{c_i c_j} Phi_{c_j}^T,
      P_{c_i c_i}), factored here in one stacked call: first the observers' 3q x 3q block (the sigma
      points), then, for the copies the gate passes, the whole 3k x 3k (its rows for c_q, ..., c_k-1);
    * sigma points of the observed robots x_o +- sqrt(L + lambda) A_o (columns p <= 3q), h on them and
      h0 = h(xbar) for the other 2(L - 3q) + 1 points, zbar, dz, Pz with bearings as offsets from h0
      (``_moments_batch``), nu = wrap(z - zbar), the gate nu^T Pz^-1 nu > ``gate``;
    * g = sqrt(L + lambda) w_p (dz_p^+ - dz_p^-) (3q x 2); r_U = g^T A_o^-1 [Phi_o sigma_{o,U}] for the
      unreached robots U (truncated chains);
    * every receiver c_i: Pxz_{c_i} = A_{i, o} g (20), K_i = Pxz_{c_i} Pz^-1, s_{c_i} += K_i nu (21),
      P_{c_i c_i} -= K_i Pxz_{c_i}^T, sigma_{c_i c_j} -= Phi_{c_i}^-1 K_i Pxz_{c_j}^T Phi_{c_j}^-T (i > j;
      sigma_{c_j c_i} its transpose) (22)-(23), sigma_{c_i u} -= Phi_{c_i}^-1 K_i r_u (u in U); headings
      wrapped after.

    Sums run as stacked matrix products (matmul, the linalg gufuncs), so a copy's bits do not depend on the
    other copies of the call; they match ``dcl_update`` to rounding (tests: 1e-12).
    """
    x = estimate
    rows = np.asarray(rows, dtype=int).reshape(-1)
    G = len(rows)
    chain = np.asarray(chain, dtype=int).reshape(G, -1)
    N = x.shape[-2]
    k = chain.shape[1]
    q = 2 if measured_in_chain else 1
    if k < q:
        raise ValueError("a chain must reach the measuring and the measured robot")
    if not measured_in_chain and landmark is None:
        raise ValueError("landmark: a landmark observation needs its position")
    applied = np.zeros(G, dtype=bool)
    if not G:
        return applied
    in_chain = np.zeros((G, N), dtype=bool)  # each row: the robots its chain reaches
    if chain.min() >= 0 and chain.max() < N:
        in_chain[np.arange(G)[:, None], chain] = True
    if np.count_nonzero(in_chain) != G * k:
        raise ValueError(f"chain must list distinct robots in [0, {N - 1}] in each row, got {chain.tolist()}")
    copies = np.zeros(x.shape[0], dtype=bool)
    copies[rows] = True
    if np.count_nonzero(copies) != G:
        raise ValueError(f"rows must be distinct copies, got {rows.tolist()}")
    L = 3 * N
    w = _weights(L, lam)
    wp = w[1]
    scale = np.sqrt(L + lam)
    z, R = np.asarray(z, float), np.asarray(R, float)
    if z.shape != (G, 2):
        z = np.broadcast_to(z, (G, 2))
    if R.shape != (G, 2, 2):
        R = np.broadcast_to(R, (G, 2, 2))
    r = rows[:, None]
    phic = phi[r, chain]  # (G, k, 3, 3): Phi of the chain's robots
    blocks, S = _chain_blocks(P_ii, sigma, rows, chain, phic)
    A_o = _cholesky_blocks(blocks[:, :q, :q])  # the observers' rows (15)-(16)
    dev = scale * A_o
    x_o = x[r, chain[:, :q]].reshape(G, 3 * q)
    plus, minus = x_o[:, :, None] + dev, x_o[:, :, None] - dev  # (G, 3q, 3q): column p = point p
    # the mean (point 0: h0 = h(xbar)), then the 2 x 3q points that move h, (G, 6q + 1, 3q)
    pts = np.concatenate([x_o[:, None], plus.mT, minus.mT], axis=1)
    if measured_in_chain:
        h = observe(pts[..., 0:3], pts[..., 3:5])
    else:
        h = observe(pts[..., 0:3], np.asarray(landmark, float).reshape(-1, 1, 2))
    h0 = h[:, 0]
    z_bar, dz, Pz = _moments_batch(h[:, 1:], h0, w, R)  # the other points leave z at h0
    nu = z - z_bar
    nu[:, 1] = wrap(nu[:, 1])
    Pz_inv = _inv2(Pz)
    if gate is not None:
        applied = ~((nu[:, None, :] @ Pz_inv @ nu[:, :, None])[:, 0, 0] > gate)
    else:
        applied[:] = True
    keep = np.flatnonzero(applied)
    if not len(keep):
        return applied
    if len(keep) < G:
        rows, chain, phic, blocks, A_o, dz, nu, Pz_inv, in_chain = (
            a[keep] for a in (rows, chain, phic, blocks, A_o, dz, nu, Pz_inv, in_chain))
        S = None if S is None else S[keep]
        G, r = len(keep), rows[:, None]
    g = scale * wp * (dz[:, :3 * q] - dz[:, 3 * q:])  # (G, 3q, 2)
    A = _cholesky_blocks(blocks) if k > q else A_o  # (G, 3k, 3k): every receiver's row of A
    U = N - k
    Pxz = (A[:, :, :3 * q] @ g).reshape(G, k, 3, 2)  # (20), receiver i: rows 3i..3i+2
    K = Pxz @ Pz_inv[:, None]
    x[r, chain] = x[r, chain] + (K @ nu[:, None, :, None])[..., 0]  # (21)
    P = P_ii[r, chain] - K @ Pxz.mT  # (22)-(23), i = j
    P_ii[r, chain] = 0.5 * (P + P.mT)
    # (G, k, 3, 2) each: M_i = Phi_{c_i}^-1 K_i, V_i = Phi_{c_i}^-1 Pxz_{c_i} (one solve per Phi)
    MV = np.linalg.solve(phic, np.concatenate([K, Pxz], axis=-1)) if k > 1 or U else None
    if k > 1:  # (22)-(23), i > j: sigma_{c_i c_j} -= (Phi_{c_i}^-1 K_i) (Phi_{c_j}^-1 Pxz_{c_j})^T
        lower_i, lower_j = _lower(k)
        M, V = MV[..., :2], MV[..., 2:]
        delta = (M.reshape(G, 3 * k, 2) @ V.reshape(G, 3 * k, 2).mT).reshape(G, k, 3, k, 3)
        new = S - delta.transpose(0, 1, 3, 2, 4)[:, lower_i, lower_j]
        ci, cj = chain[:, lower_i], chain[:, lower_j]
        sigma[r, ci, cj] = new
        sigma[r, cj, ci] = new.mT
    if U:  # observers: r_U = g^T A_o^-1 [Phi_o sigma_{o,U}]; every receiver: sigma_{c_i u} -= Phi^-1 K_i r_u
        unreached = np.argsort(in_chain, axis=1, kind="stable")[:, :U]  # (G, U), ascending
        obs = chain[:, :q]
        prod = phic[:, :q, None] @ sigma[r[:, :, None], obs[:, :, None], unreached[:, None, :]]
        rows_o = prod.transpose(0, 1, 3, 2, 4).reshape(G, 3 * q, 3 * U)
        y = np.linalg.solve(A[:, :3 * q, :3 * q].mT, g)  # A_o^-T g
        r_U = (y.mT @ rows_o).reshape(G, 2, U, 3)
        r3, c3, u3 = r[:, :, None], chain[:, :, None], unreached[:, None, :]
        new = sigma[r3, c3, u3] - MV[:, :, None, :, :2] @ r_U.transpose(0, 2, 1, 3)[:, None]
        sigma[r3, c3, u3] = new
        sigma[r3, u3, c3] = new.mT
    x[rows, :, 2] = wrap(x[rows, :, 2])
    return applied
