"""UKF cooperative localization, centralized (UKF-CCL) and distributed over a relay chain (UKF-DCL).

Wang L., Cui J., Kong D., Zhao L., "A distributed cooperative localization
algorithm for mobile multi-platforms oriented to unpredicted communication
topology", Transactions of Nanjing University of Aeronautics and
Astronautics 36(2):224-231, 2019 (seed ``002_1a9a5ea84f86e0cc.txt``).

N platforms in the plane; the state is the stacked position
x = [x_1; ...; x_N] in R^{2N} with joint covariance P (2N x 2N).

Time update (eq. 1, 3-4). Platform i integrates its odometry, the measured
speed V_mi(k) and the heading phi_mi(k) (integrated from the measured turn
rate):

    xbar_i(k+1) = xhat_i(k) + dt V_mi(k) [cos phi_mi(k); sin phi_mi(k)],
    Pbar_ii     = Phat_ii + Q_i(k),       Pbar_ij = Phat_ij (i != j).

The position transition is the identity, so cross-covariances do not change
and every platform predicts alone. Q_i(k) = dt^2 sigma_v^2 u u^T with
u = [cos phi; sin phi] (the paper's speed noise) plus, optionally, the
heading term below.

Observation update with one range z = ||x_m - x_n|| + noise, R = sigma_r^2.

UKF-CCL (eqs. 5-12, 17). The joint state is reordered so that the blocks
of the measuring platform m and the measured platform n come first (eq. 17);
A is the lower Cholesky factor of the reordered P, L = 2N, and the 2L + 1
sigma points are

    xi^(0) = x,  xi^(p) = x + sqrt(L + lambda) A[:, p],  xi^(p+L) = x - sqrt(L + lambda) A[:, p],
    p = 1..L,   w_0 = lambda / (L + lambda),  w_p = 0.5 / (L + lambda).

    zbar = sum_p w_p h(xi^(p)),  Pz = sum_p w_p (h(xi^(p)) - zbar)^2 + R,
    Pxz  = sum_p w_p (xi^(p) - x)(h(xi^(p)) - zbar),
    K = Pxz / Pz,  xhat = xbar + K (z - zbar),  Phat = Pbar - K Pz K^T.

UKF-DCL (Sec. 3, Algorithms 1-2). The location information travels along a
serial chain c_1 = m -> c_2 = n -> c_3 -> ...; it never revisits a platform.
Receiver c_i holds its own row of covariance blocks P_{c_i, .} and gets from
the message the row blocks A_j (j < i) of its up-neighbours:

* look-up Cholesky (15)-(16): A_{i,<i}^T = A_{<i}^{-1} [P_{c_i c_1} ... P_{c_i c_{i-1}}]^T
  (forward substitution), A_ii = chol(P_{c_i c_i} - A_{i,<i} A_{i,<i}^T);
* m (c_1) forms A_11 = chol(P_mm) and sends it to n; n forms A_2 and returns
  its sigma deviations; m evaluates h on the sigma points and packs the
  source location information S_m = {z - zbar, h(xi^(p)) - zbar, Pz} (eq. 13);
* each receiver's own sigma deviations (18), its update weight Pxz^i (20),
  its estimate (21), and its covariance blocks with every up-neighbour
  (22)-(23); it appends A_i and Pxz^i to the message and passes it on.

With m and n first, only the first four columns of A move h: all sigma points
beyond them leave z at h(xbar). A complete chain therefore gives exactly the
CCL update (the tests check 1e-9).

Truncated chains. When the chain stops before every platform (hop budget
spent, link lost, a platform chose to stop), the reached set R updates and
the unreached set U keeps its estimate (gain K_U = 0). The paper leaves
P_RU unchanged; that is not the covariance of any estimator and P becomes
indefinite within a few hundred steps (``truncation="paper"``, kept for
comparison). By default (``truncation="consistent"``) the cross-covariances
become the covariance of the gain [K_R; 0]:

    P_RU <- P_RU - K_R P_zU,   P_zU = P_(mn),z^T P_(mn)^-1 P_(mn),U,

which m and n compute from their own blocks (P_zU = g^T A_mn^-1 [P_mU; P_nU]
with g = sqrt(L + lambda) w_p (dzeta_q)_{q<=4}) and carry in the message. It
is exact for the UT with m, n ordered first, and equals the CCL update with
the same gain (``ccl_update`` with ``reached``).

Cost. The range reads only the blocks of m and n, so the update needs only
the first 2d columns of the factor, P[:, mn] A_mn^-T (``range_terms``):
a 2d x 2d Cholesky, 4d + 1 range evaluations and O(L d) work per reading,
then a rank-2 change of P (O(L^2)); ``range_updates`` applies a step's J
readings in order with the rank-2 terms kept aside and folded into P every
16 readings (O(J L^2) per step, against O(J L^3) for a full factor per
reading), and ``fix_updates`` the position fixes as rank-4 changes. The
printed forms stay available and give the same numbers to rounding:
``ccl_update(method="sigma")`` (the 2L + 1 sigma points from the L x L
factor) and ``dcl_update(method="chain")`` (hop by hop).

Array conventions (a leading batch shape ``...`` is allowed everywhere):

* ``estimate``   ``(..., N, 2)``   positions x_i
* ``cov``        ``(..., 2N, 2N)`` joint covariance P, block (i, j) = P_ij
* ``measuring``, ``measured`` ``(...)`` int: m, n
* ``chain``      ``(..., N)`` int, platforms in relay order (c_1 = m, c_2 = n), padded with -1
* ``chain_length`` ``(...)`` int >= 2, number of platforms reached

Departures from the printed equations
-------------------------------------
* (5): the "-" sigma points use column p - 2N, not p - n.
* (8): R is added once, not inside the sum over sigma points (the printed
  form adds it 4N + 1 times).
* (11) and (23): the covariance decreases, Phat = Pbar - K Pz K^T (printed with +
  in (11)); (12) and (21) divide by Pz: K = Pxz Pz^-1.
* (22): Delta P_ij = Pxz^i Pz^-1 (Pxz^j)^T; the printed Pxz^i Pz (Pxz^j)^T
  misses the inverses K = Pxz Pz^-1 on both sides of Pz.
* (18): only the "+" points are printed; the "-" points sit at p + 2N, and
  the scale is sqrt(2N + lambda), not sqrt(n + lambda).
* (20): the sum must run over the receiver's own columns too, p <= 2(|neigh^u_i| + 1),
  and over the "-" points p + 2N: Pxz^i = sqrt(2N + lambda) w_p sum_q A_i[:, q] (dzeta_q - dzeta_{q+2N}).
* lambda is not given in the paper; the default 0 (filterpy's JulierSigmaPoints
  default) keeps every weight non-negative.
* The paper's initial positions are known (P(0) = 0); a Cholesky factor of a
  singular P does not exist, so callers start from a small P(0) (the scenario's
  ``initial_position_std``).
* Truncated chains: the consistent cross-covariance update above instead of
  leaving P_RU unchanged (the paper's rule stays available).
* Heading noise (optional, ``process_noise``): the paper's Q carries only
  the speed noise, although the heading is integrated from a noisy turn rate.
  With ``heading_var`` > 0 the displacement's first-order sensitivity to the
  heading error adds dt^2 V_m^2 sigma_phi^2(k) n n^T, n = [-sin phi; cos phi],
  sigma_phi^2(k) the variance of the integrated heading. This is an
  approximation: the heading error is a random walk, so its effect on the
  position is correlated in time, which a position-only white Q cannot
  carry; it keeps the per-step marginal variance right.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "ccl_update",
    "dcl_update",
    "fix_updates",
    "range_terms",
    "range_updates",
    "process_noise",
    "range_of",
    "reorder_first",
    "sigma_points",
    "time_update",
    "ukf_weights",
]

def ukf_weights(dim: int, lam: float) -> np.ndarray:
    """Weights w_0 = lambda/(dim+lambda), w_p = 0.5/(dim+lambda) of the 2 dim + 1 sigma points."""
    if dim + lam <= 0:
        raise ValueError(f"lambda must be > -{dim} (dim + lambda > 0), got {lam}")
    w = np.full(2 * dim + 1, 0.5 / (dim + lam))
    w[0] = lam / (dim + lam)
    return w


PAPER_RULE_WARNING = (
    "truncation='paper' is wang2019's rule (P_RU left unchanged on a truncated chain): it loses positive "
    "definiteness within tens of steps of truncated chains (coloc reproduce wang2019 measures where), and the "
    "next update then raises a ValueError naming it. It is kept for the reproduction; use "
    "truncation='consistent' (the default) for episodes that must run.")


def paper_rule_failure(exc: Exception, step) -> np.linalg.LinAlgError:
    """The error an env raises when the paper's truncation rule has broken the covariance (a ValueError)."""
    return np.linalg.LinAlgError(f"truncation='paper' lost positive definiteness at step {step}: {exc}. "
                                 "Use truncation='consistent' (the default) for episodes that must run.")


def _cholesky(matrix: np.ndarray, what: str) -> np.ndarray:
    try:
        return np.linalg.cholesky(matrix)
    except np.linalg.LinAlgError as exc:
        smallest = np.linalg.eigvalsh(0.5 * (matrix + np.swapaxes(matrix, -1, -2))).min()
        raise np.linalg.LinAlgError(
            f"{what} is not positive definite (smallest eigenvalue {smallest:.3g}); "
            "the covariance lost positive definiteness") from exc


def _lower_solve(lower: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """lower^-1 rhs on stacks (np.linalg: scipy's triangular solver takes no batch axis)."""
    return np.linalg.solve(lower, rhs)


def range_of(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """h(x_a, x_b) = ||x_a - x_b|| over the last axis."""
    return np.sqrt(np.sum((np.asarray(a) - np.asarray(b)) ** 2, axis=-1))


def process_noise(speed: np.ndarray, heading: np.ndarray, dt: float, speed_var: float,
                  heading_var: np.ndarray | float = 0.0) -> np.ndarray:
    """Q_i(k), shape (..., N, 2, 2): dt^2 sigma_v^2 u u^T + dt^2 V_m^2 sigma_phi^2 n n^T, with u = (cos phi,
    sin phi) along the track and n = (-sin phi, cos phi) across it.

    Each entry is written out, (a u_r) u_c + (b n_r) n_c, rather than formed from outer products: the same
    floats at a fraction of the array calls (the estimator's prediction and the observation's message value
    compute it every step)."""
    speed, heading = np.asarray(speed, float), np.asarray(heading, float)
    cos, sin = np.cos(heading), np.sin(heading)
    along = dt**2 * speed_var
    lateral = dt**2 * speed**2 * np.asarray(heading_var, float)
    # a u_r and b n_r: the first factor of each entry's two terms (n = (-sin, cos))
    along_0, along_1 = along * cos, along * sin
    across_0, across_1 = lateral * -sin, lateral * cos
    Q = np.empty((*np.broadcast_shapes(cos.shape, lateral.shape), 2, 2))
    Q[..., 0, 0] = along_0 * cos + across_0 * -sin
    Q[..., 0, 1] = along_0 * sin + across_0 * cos
    Q[..., 1, 0] = along_1 * cos + across_1 * -sin
    Q[..., 1, 1] = along_1 * sin + across_1 * cos
    return Q


def time_update(estimate: np.ndarray, cov: np.ndarray | None, speed: np.ndarray, heading: np.ndarray,
                dt: float, speed_var: float, heading_var: np.ndarray | float = 0.0):
    """Eq. (1) for every platform; Pbar_ii = P_ii + Q_i, cross-covariances unchanged.

    ``cov`` may be None (independent localization without a covariance).
    Returns ``(estimate, cov)``, new arrays.
    """
    speed, heading = np.asarray(speed, float), np.asarray(heading, float)
    step = dt * speed[..., None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    estimate = np.asarray(estimate, float) + step
    if cov is None:
        return estimate, None
    N = estimate.shape[-2]
    Q = process_noise(speed, heading, dt, speed_var, heading_var)
    cov = np.array(cov, dtype=float, copy=True)
    for i in range(N):  # N diagonal blocks, each batched over copies
        cov[..., 2 * i:2 * i + 2, 2 * i:2 * i + 2] += Q[..., i, :, :]
    return estimate, cov


def _block_index(platforms: np.ndarray, d: int = 2) -> np.ndarray:
    """State indices of the d-blocks of ``platforms`` (..., k) -> (..., d k)."""
    platforms = np.asarray(platforms)
    return (d * platforms[..., :, None] + np.arange(d)).reshape(*platforms.shape[:-1], -1)


def reorder_first(num_platforms: int, measuring: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """Platform order [m, n, the others ascending], shape (..., N) (eq. 17)."""
    measuring, measured = np.asarray(measuring), np.asarray(measured)
    ids = np.broadcast_to(np.arange(num_platforms), (*measuring.shape, num_platforms))
    rest = (ids != measuring[..., None]) & (ids != measured[..., None])
    others = np.sort(np.where(rest, ids, num_platforms), axis=-1)[..., : num_platforms - 2]
    return np.concatenate([measuring[..., None], measured[..., None], others], axis=-1)


def sigma_points(mean: np.ndarray, cov: np.ndarray, lam: float) -> np.ndarray:
    """The 2L + 1 sigma points of eq. (5) with the lower Cholesky factor, shape (..., 2L+1, L).

    Point p (1 <= p <= L) is mean + sqrt(L + lambda) A[:, p-1]; point p + L the "-" one.
    """
    L = mean.shape[-1]
    ukf_weights(L, lam)
    columns = np.sqrt(L + lam) * np.swapaxes(_cholesky(cov, "the joint covariance"), -1, -2)
    mean = mean[..., None, :]
    return np.concatenate([mean, mean + columns, mean - columns], axis=-2)


def _flatten_batch(*arrays, core_ndims):
    batch = np.asarray(arrays[0]).shape[: np.ndim(arrays[0]) - core_ndims[0]]
    flat = [np.asarray(a).reshape(-1, *np.shape(a)[np.ndim(a) - c:]) for a, c in zip(arrays, core_ndims, strict=True)]
    return batch, flat


# --- the look-up form of one range update: O(L d + L^2) per reading ------------------------------------------


def _mn_index(measuring: np.ndarray, measured: np.ndarray, d: int) -> np.ndarray:
    """(B, 2d) state indices of the blocks of m and n, m's first (the first 2d coordinates of eq. 17's order)."""
    return np.concatenate([d * measuring[:, None] + np.arange(d), d * measured[:, None] + np.arange(d)], axis=1)


def range_terms(x: np.ndarray, P: np.ndarray, measuring: np.ndarray, measured: np.ndarray, lam: float,
                range_var: float):
    """(Pxz (B, L), Pz (B,), zbar (B,)) of one range m -> n per copy, from P's 2d rows of m and n only.

    ``x`` (B, N, d) with the position first in each block, ``P`` (B, L, L), L = d N. With m and n ordered
    first (eq. 17) the lower Cholesky factor A of P has zeros in the m and n rows beyond column 2d, so
    the sigma points p > 2d all give h(xbar) and their deviations cancel in Pxz (this is what makes the
    distributed chain exact). What remains is

        A_mn = chol(P_(mn)),  the 4d + 1 distinct points x_(mn) +- sqrt(L + lambda) A_mn[:, q], q < 2d,
        zbar = (w_0 + 2 (L - 2d) w_p) h(xbar) + w_p sum_q (h(xi_q^+) + h(xi_q^-)),
        Pz   = (w_0 + 2 (L - 2d) w_p) (h(xbar) - zbar)^2 + w_p sum_q ((dz_q^+)^2 + (dz_q^-)^2) + R,
        Pxz  = A[:, :2d] g = P[:, mn] A_mn^-T g,   g_q = sqrt(L + lambda) w_p (dz_q^+ - dz_q^-),

    the first 2d columns of the full factor being P[:, mn] A_mn^-T (the look-up Cholesky of eqs. 15-16
    applied to every platform at once). The numbers are those of the 2L + 1 point UT of
    ``ccl_update`` (``method="sigma"``) in exact arithmetic (tests: 1e-9). Cost per reading: a
    2d x 2d Cholesky, 4d + 1 range evaluations and one (L x 2d) product, O(L d); no L x L factor.
    """
    B, N, d = x.shape
    idx = _mn_index(np.asarray(measuring, int), np.asarray(measured, int), d)
    band = P[np.arange(B)[:, None], idx]  # (B, 2d, L): P's rows of m and n (= its columns: P is symmetric)
    flat = x.reshape(B, -1)
    return _terms_of_band(band, idx, np.take_along_axis(flat, idx[:, [0, 1, d, d + 1]], axis=1), d,
                          _UkfConstants(d * N, d, lam), range_var)


class _UkfConstants:
    """The weights of the 2L + 1 point UT as the look-up form uses them."""

    def __init__(self, L: int, d: int, lam: float):
        w = ukf_weights(L, lam)
        self.scale, self.wp = np.sqrt(L + lam), w[1]
        self.w_mean = w[0] + 2 * (L - 2 * d) * w[1]  # the weight of h(xbar): the mean and every point beyond 2d
        self.signs = np.array([1.0, -1.0])[:, None]


def _terms_of_band(band: np.ndarray, idx: np.ndarray, positions: np.ndarray, d: int, c: _UkfConstants,
                   range_var: float):
    """``range_terms`` from the rows ``band`` (B, 2d, L) of P at ``idx`` (B, 2d) and the positions
    [x_m; x_n] (B, 4)."""
    P_mn = np.take_along_axis(band, idx[:, None, :], axis=2)
    A = _cholesky(P_mn, "the joint covariance")
    base = positions[:, :2] - positions[:, 2:]  # (B, 2)
    spread = c.scale * (A[:, 0:2, :] - A[:, d:d + 2, :])  # (B, 2, 2d): the range's share of each sigma column
    z0 = np.sqrt(np.sum(base**2, axis=-1))
    z_pm = np.sqrt(np.sum((base[:, :, None, None] + c.signs * spread[:, :, None, :]) ** 2, axis=1))  # (B, 2, 2d)
    z_bar = c.w_mean * z0 + c.wp * z_pm.sum(axis=(1, 2))
    dz = z_pm - z_bar[:, None, None]
    Pz = c.w_mean * (z0 - z_bar) ** 2 + c.wp * np.sum(dz**2, axis=(1, 2)) + range_var
    g = c.scale * c.wp * (dz[:, 0] - dz[:, 1])
    v = np.linalg.solve(np.swapaxes(A, -1, -2), g[:, :, None])  # A_mn^-T g
    Pxz = np.matmul(np.swapaxes(band, -1, -2), v)[..., 0]
    return Pxz, Pz, z_bar


def range_updates(estimate: np.ndarray, cov: np.ndarray, measuring: np.ndarray, measured: np.ndarray,
                  z: np.ndarray, active: np.ndarray, range_var: float, lam: float = 0.0,
                  reached: np.ndarray | None = None, truncation: str = "consistent", block: int = 16) -> None:
    """J range readings per copy applied in order (sequential UKF updates), in place on (B, ...) arrays.

    ``estimate`` (B, N, d), ``cov`` (B, L, L), both C-contiguous; ``measuring``, ``measured``, ``z``,
    ``active`` (B, J): reading j of copy b is m -> n with value z, applied where ``active`` (an inactive
    one is skipped: its gain is 0, any m and n). ``reached`` (B, J, N) bool: the platforms a reading's
    update reaches (all by default: UKF-CCL); the others keep their estimate, and their
    cross-covariances with the reached become those of the gain [K_R; 0] (``truncation="consistent"``)
    or stay unchanged (``"paper"``). Reading j equals ``ccl_update`` / ``dcl_update`` of the
    state after readings < j (tests: 1e-9).

    Each reading changes P by a rank-2 term, P - K Pxz^T - Pxz K^T + K Pz K^T = P - (K C^T + C K^T)
    with C = Pxz - Pz K / 2, and reads only the 2d rows of m and n. The terms are kept aside, P =
    P_0 - U V^T (U = [K_1 C_1 ...], V = [C_1 K_1 ...]), and folded into P every ``block`` readings
    with one matrix product. Cost per reading: ``range_terms`` on the rows P_0[mn] - U[mn] V^T
    (O(L d block)), no L x L work; per ``block`` readings one (L x 2 block) x (2 block x L) product;
    in all O(J L^2 + J L d block) per step, never an L x L factor or 2L + 1 sigma points.
    """
    if truncation not in ("consistent", "paper"):
        raise ValueError(f"truncation must be 'consistent' or 'paper', got {truncation!r}")
    B, N, d = estimate.shape
    L = d * N
    measuring, measured = np.asarray(measuring, int), np.asarray(measured, int)
    active = np.asarray(active, bool)
    J = measuring.shape[1]
    if np.any(active & (measuring == measured)):
        raise ValueError("measuring and measured platforms must differ")
    if not active.any():
        return
    c = _UkfConstants(L, d, lam)
    idx_all = np.concatenate([d * np.where(active, measuring, 0)[..., None] + np.arange(d),
                              d * np.where(active, measured, 1)[..., None] + np.arange(d)], axis=-1)  # (B, J, 2d)
    x = estimate.reshape(B, L)  # a view: the updates land in ``estimate``
    rows = np.arange(B)[:, None]
    innovations = np.nan_to_num(np.asarray(z, float))
    U, V = np.zeros((B, 2 * block, L)), np.zeros((B, 2 * block, L))  # P = P_0 - U^T V (rows: K_1, C_1, ...)
    scratch = np.empty((B, L, L))
    used = 0

    def fold() -> None:
        np.matmul(np.swapaxes(U[:, :used], -1, -2), V[:, :used], out=scratch)
        cov.__isub__(scratch)

    for j in range(J):
        on = active[:, j]
        if not on.any():
            continue
        idx = idx_all[:, j]
        band = cov[rows, idx]
        if used:
            band -= np.matmul(np.swapaxes(np.take_along_axis(U[:, :used], idx[:, None, :], axis=2), -1, -2),
                              V[:, :used])
        Pxz, Pz, z_bar = _terms_of_band(band, idx, np.take_along_axis(x, idx[:, [0, 1, d, d + 1]], axis=1), d, c,
                                        range_var)
        keep = on[:, None] if reached is None else np.repeat(on[:, None] & reached[:, j], d, axis=1)
        gain = Pxz * (keep / Pz[:, None])
        x += gain * np.where(on, innovations[:, j] - z_bar, 0.0)[:, None]
        C = Pxz - 0.5 * Pz[:, None] * gain
        if reached is not None and truncation == "paper":
            C *= keep
        U[:, used], U[:, used + 1], V[:, used], V[:, used + 1] = gain, C, C, gain
        used += 2
        if used == 2 * block:
            fold()
            used = 0
    if used:
        fold()
    _symmetrize_in_place(cov, scratch)


def _apply_gain(x: np.ndarray, P: np.ndarray, gain: np.ndarray, Pxz: np.ndarray, S: np.ndarray,
                innovation: np.ndarray, keep: np.ndarray | None, scratch: np.ndarray) -> None:
    """x += K innovation and P <- P - K Pxz^T - Pxz K^T + K S K^T in place, as -(K C^T + C K^T).

    ``gain`` K (B, L, k), ``Pxz`` (B, L, k), S (B, k, k), ``innovation`` (B, k); C = Pxz - K S / 2, so that
    K C^T + C K^T = K Pxz^T + Pxz K^T - K S K^T. ``keep`` (B, L) masks K (rows outside keep their
    estimate). ``scratch`` (B, L, L) holds the one (B, L, 2k) x (B, 2k, L) product [K C] [C K]^T. Not
    symmetrized: callers symmetrize once after their updates.
    """
    if keep is not None:
        gain = gain * keep[..., None]
    x += np.matmul(gain, innovation[..., None])[..., 0].reshape(x.shape)
    C = Pxz - 0.5 * np.matmul(gain, S)
    np.matmul(np.concatenate([gain, C], axis=-1), np.swapaxes(np.concatenate([C, gain], axis=-1), -1, -2),
              out=scratch)
    P -= scratch


def fix_updates(estimate: np.ndarray, cov: np.ndarray, fix: np.ndarray, active: np.ndarray, R: np.ndarray,
                reached: np.ndarray | None = None) -> None:
    """Position fixes z_i = p_i + v, v ~ N(0, R), agent by agent, in place (linear, Joseph-equivalent).

    ``fix`` (B, N, 2), ``active`` (B, N), ``R`` (2, 2); ``reached`` (B, N, N) [b, i]: the platforms fix
    i's update reaches (all by default). With H selecting agent i's position, S = P_ii + R,
    K = P[:, i] S^-1 masked to the reached rows, and the Joseph form
    (I - K H) P (I - K H)^T + K R K^T = P - K P[i, :] - P[:, i] K^T + K S K^T, computed as a rank-4
    update: O(L) per fix for the gain, O(L^2) for the covariance, never an L x L product
    (``estimators.kalman.joseph_update`` forms (I - K H) P (I - K H)^T: O(L^3); tests: 1e-9).
    """
    B, N, d = estimate.shape
    L = d * N
    scratch = np.empty((B, L, L))
    R = np.asarray(R, float)
    rows = np.arange(B)
    for i in range(N):
        on = np.asarray(active[:, i], bool)
        if not on.any():
            continue
        band = cov[:, d * i:d * i + 2, :]  # (B, 2, L) = P[i-position rows]
        S = band[:, :, d * i:d * i + 2] + R
        S = 0.5 * (S + np.swapaxes(S, -1, -2))
        Pxz = np.swapaxes(band, -1, -2)  # (B, L, 2)
        gain = np.swapaxes(np.linalg.solve(S, band), -1, -2)  # P[:, i] S^-1 (S symmetric)
        keep = on[:, None] if reached is None else np.repeat(on[:, None] & reached[:, i], d, axis=1)
        innovation = np.where(on[:, None], np.nan_to_num(fix[rows, i]) - estimate[rows, i, :2], 0.0)
        _apply_gain(estimate, cov, gain, Pxz.copy(), S, innovation, keep, scratch)
    _symmetrize_in_place(cov, scratch)


def _symmetrize_in_place(P: np.ndarray, scratch: np.ndarray) -> None:
    np.add(P, np.swapaxes(P, -1, -2), out=scratch)
    np.multiply(scratch, 0.5, out=P)


def ccl_update(estimate: np.ndarray, cov: np.ndarray, measuring, measured, z, range_var: float,
               lam: float = 0.0, reached: np.ndarray | None = None, method: str = "lookup"):
    """UKF-CCL observation update (eqs. 5-12, 17).

    ``method="lookup"`` (default) forms only what the range reads (``range_terms``: the 2d x 2d
    Cholesky of P_(mn), O(L^2) per reading); ``method="sigma"`` builds the generic 2L + 1 sigma
    points from the full L x L Cholesky factor (O(L^3) per reading), as printed. They agree to
    rounding (tests: 1e-9).

    ``reached`` (..., N) bool (optional): platforms whose estimate updates; the
    others keep theirs (gain 0) and the covariance is that of the gain
    [K_R; 0], P - K Pxz^T - Pxz K^T + K Pz K^T, which is P - K Pz K^T (eq. 11,
    with the sign corrected) when every platform is reached. Returns new
    ``(estimate, cov)``.
    """
    if method not in ("lookup", "sigma"):
        raise ValueError(f"method must be 'lookup' or 'sigma', got {method!r}")
    N, d = np.shape(estimate)[-2:]
    L = d * N
    all_reached = reached is None
    if reached is None:
        reached = np.ones((*np.shape(measuring), N), dtype=bool)
    batch, (x, P, m, n, zz, reach) = _flatten_batch(
        estimate, cov, measuring, measured, z, reached, core_ndims=(2, 2, 0, 0, 0, 1))
    m, n = m.astype(int), n.astype(int)
    if np.any(m == n):
        raise ValueError("measuring and measured platforms must differ")
    if method == "lookup":
        x, P = x.astype(float).copy(), P.astype(float).copy()
        range_updates(x, P, m[:, None], n[:, None], zz[:, None], np.ones((len(x), 1), bool), range_var, lam,
                      None if all_reached else reach[:, None].astype(bool))
        return x.reshape(*batch, N, d), P.reshape(*batch, L, L)
    order = reorder_first(N, m, n)
    idx = _block_index(order, d)  # (B, L)
    x_r = np.take_along_axis(x.reshape(-1, L), idx, axis=-1)
    P_r = np.take_along_axis(np.take_along_axis(P, idx[:, :, None], axis=1), idx[:, None, :], axis=2)
    chi = sigma_points(x_r, P_r, lam)  # (B, 2L+1, L)
    w = ukf_weights(L, lam)
    z_sigma = range_of(chi[..., 0:2], chi[..., d:d + 2])  # (B, 2L+1): positions lead each block
    z_bar = z_sigma @ w
    dz = z_sigma - z_bar[:, None]
    Pz = (dz**2) @ w + range_var
    Pxz = np.einsum("p,bpl,bp->bl", w, chi - x_r[:, None, :], dz)
    gain = Pxz / Pz[:, None] * np.repeat(np.take_along_axis(reach, order, axis=-1), d, axis=-1)
    x_r = x_r + gain * (zz - z_bar)[:, None]
    outer_kx = gain[:, :, None] * Pxz[:, None, :]
    P_r = P_r - outer_kx - np.swapaxes(outer_kx, -1, -2) + Pz[:, None, None] * gain[:, :, None] * gain[:, None, :]
    P_r = 0.5 * (P_r + np.swapaxes(P_r, -1, -2))
    inverse = np.argsort(idx, axis=-1)
    x_new = np.take_along_axis(x_r, inverse, axis=-1).reshape(x.shape)
    P_new = np.take_along_axis(np.take_along_axis(P_r, inverse[:, :, None], axis=1), inverse[:, None, :], axis=2)
    return x_new.reshape(*batch, N, d), P_new.reshape(*batch, L, L)


def _gather_blocks(P: np.ndarray, rows: np.ndarray, cols: np.ndarray, d: int = 2) -> np.ndarray:
    """P[b, blocks of rows[b]][:, blocks of cols[b]] for each copy b: rows (B, r), cols (B, c) -> (B, d r, d c)."""
    ri, ci = _block_index(rows, d), _block_index(cols, d)
    return P[np.arange(len(P))[:, None, None], ri[:, :, None], ci[:, None, :]]


def _add_blocks(P: np.ndarray, rows: np.ndarray, cols: np.ndarray, values: np.ndarray, d: int = 2) -> None:
    ri, ci = _block_index(rows, d), _block_index(cols, d)
    P[np.arange(len(P))[:, None, None], ri[:, :, None], ci[:, None, :]] += values


def dcl_update(estimate: np.ndarray, cov: np.ndarray, chain: np.ndarray, chain_length, z, range_var: float,
               lam: float = 0.0, truncation: str = "consistent", method: str | None = None):
    """UKF-DCL observation update along the relay chain (Sec. 3, Algorithms 1-2).

    ``chain[..., 0]`` measures ``chain[..., 1]``; the location information
    then reaches ``chain[..., 2:chain_length]`` in order. Each receiver's
    quantities are computed only from its own blocks and the message (the
    row blocks A_j and update weights Pxz^j of its up-neighbours, S_m, and
    for ``truncation="consistent"`` the P_zj of every platform, formed by m
    and n). The joint ``cov`` array stands for the platforms' rows: receiver
    c_i writes P_{c_i c_j} for its up-neighbours and the symmetric block
    P_{c_j c_i} (the paper's "obtained by transposition").

    ``method="chain"`` runs the chain hop by hop (Algorithms 1-2): each
    receiver forms its row block A_i by look-up Cholesky, so a covariance that
    lost positive definiteness fails at the first Schur complement that is not
    (what ``truncation="paper"`` needs to be caught). Copies are vectorized per
    chain position, so the loop runs over at most N positions, never over
    copies: O(N) Cholesky factors and triangular solves of growing size per
    reading. ``method="lookup"`` computes the same numbers in closed form: g
    vanishes beyond the first 2d columns, so receiver c_i's update weight is
    Pxz^i = A_i[:, :2d] g = P_{c_i,(mn)} A_mn^-T g, and the chain's update is
    ``ccl_update`` with ``reached`` the chain's platforms (consistent rule)
    or with the cross-covariances to the unreached left alone (paper rule);
    O(L^2) per reading (``range_updates``; tests: 1e-9 against the chain).
    The default is ``"lookup"`` for ``truncation="consistent"`` and ``"chain"``
    for ``"paper"``. Returns new ``(estimate, cov)``.
    """
    if truncation not in ("consistent", "paper"):
        raise ValueError(f"truncation must be 'consistent' or 'paper', got {truncation!r}")
    method = method or ("lookup" if truncation == "consistent" else "chain")
    if method not in ("lookup", "chain"):
        raise ValueError(f"method must be 'lookup' or 'chain', got {method!r}")
    N, d = np.shape(estimate)[-2:]
    L = d * N
    batch, (x, P, chain, length, zz) = _flatten_batch(
        estimate, cov, chain, chain_length, z, core_ndims=(2, 2, 1, 0, 0))
    x, P = x.astype(float).copy(), P.astype(float).copy()
    chain, length = chain.astype(int), length.astype(int)
    B = len(x)
    if np.any(length < 2) or np.any(length > N):
        raise ValueError(f"chain_length must be in [2, {N}] (a measurement reaches at least m and n)")
    positions = np.arange(N)
    valid = np.where(positions < length[:, None], chain, -1)
    if np.any(valid[:, :2] < 0) or np.any(valid >= N) or np.any(valid[:, 0] == valid[:, 1]):
        raise ValueError(f"chain entries must be platforms in [0, {N - 1}], m != n")
    hop_copy, hop_position = np.nonzero(valid >= 0)
    reached_mask = np.zeros((B, N), dtype=bool)
    reached_mask[hop_copy, valid[hop_copy, hop_position]] = True
    if np.any(reached_mask.sum(axis=1) != length):
        raise ValueError("a chain must not revisit a platform")
    if method == "lookup":
        range_updates(x, P, chain[:, :1], chain[:, 1:2], zz[:, None], np.ones((B, 1), bool), range_var, lam,
                      reached_mask[:, None], truncation)
        return x.reshape(*batch, N, d), P.reshape(*batch, L, L)

    scale = np.sqrt(L + lam)
    w = ukf_weights(L, lam)
    w0, wp = w[0], w[1]
    rows = np.arange(B)
    A = np.zeros((B, L, L))  # the message's lower block-triangular rows A_1..A_i, in chain order

    def own_row_block(sub, i):
        """Receiver chain[sub, i]'s row block A_i from its own P blocks and A_{<i} (eqs. 15-16)."""
        receiver = chain[sub, i:i + 1]
        P_ii = _gather_blocks(P[sub], receiver, receiver, d)
        if i == 0:
            return None, _cholesky(P_ii, "P_mm")
        upstream = chain[sub, :i]
        own = _gather_blocks(P[sub], receiver, upstream, d)  # (b, d, d i) = [P_{c_i c_1} ... P_{c_i c_{i-1}}]
        left = np.swapaxes(_lower_solve(A[sub, : d * i, : d * i], np.swapaxes(own, -1, -2)), -1, -2)
        schur = P_ii - left @ np.swapaxes(left, -1, -2)
        return left, _cholesky(0.5 * (schur + np.swapaxes(schur, -1, -2)), f"the Schur complement at hop {i}")

    # Algorithm 1: m and n form A_1, A_2 and the source location information S_m (eq. 13).
    for i in (0, 1):
        left, diag = own_row_block(rows, i)
        if left is not None:
            A[:, d * i:d * i + d, : d * i] = left
        A[:, d * i:d * i + d, d * i:d * i + d] = diag
    m, n = chain[:, 0], chain[:, 1]
    dev_m, dev_n = scale * A[:, 0:2, :], scale * A[:, d:d + 2, :]  # (B, 2, L) position sigma deviations (18)
    x_m, x_n = x[rows, m, :2], x[rows, n, :2]
    z0 = range_of(x_m, x_n)
    z_plus = range_of((x_m[:, :, None] + dev_m - x_n[:, :, None] - dev_n).transpose(0, 2, 1), 0.0)
    z_minus = range_of((x_m[:, :, None] - dev_m - x_n[:, :, None] + dev_n).transpose(0, 2, 1), 0.0)
    z_bar = w0 * z0 + wp * (z_plus.sum(axis=1) + z_minus.sum(axis=1))
    dzeta0, dzeta_plus, dzeta_minus = z0 - z_bar, z_plus - z_bar[:, None], z_minus - z_bar[:, None]
    Pz = w0 * dzeta0**2 + wp * (np.sum(dzeta_plus**2, axis=1) + np.sum(dzeta_minus**2, axis=1)) + range_var
    innovation = zz - z_bar
    g = scale * wp * (dzeta_plus - dzeta_minus)  # (B, L): Pxz^i = A_i g over the receiver's own columns

    if truncation == "consistent":
        # m and n: P_zj = g^T A_mn^-1 [P_mj; P_nj] for every platform j, carried in the message.
        mn_rows = _gather_blocks(P, chain[:, :2], np.broadcast_to(np.arange(N), (B, N)), d)  # (B, 2d, L)
        P_zj = np.einsum("bq,bqc->bc", g[:, :2 * d], _lower_solve(A[:, :2 * d, :2 * d], mn_rows)).reshape(B, N, d)

    update_weight = np.zeros((B, N, d))  # Pxz^{c_j} in chain order, appended by each receiver
    for i in range(N):
        sub = np.flatnonzero(length > i)
        if len(sub) == 0:
            break
        if i >= 2:  # Algorithm 2 (1): the receiver's row block from the message
            left, diag = own_row_block(sub, i)
            A[sub, d * i:d * i + d, : d * i] = left
            A[sub, d * i:d * i + d, d * i:d * i + d] = diag
        own_columns = d * (i + 1)
        Pxz_i = np.einsum("bac,bc->ba", A[sub, d * i:d * i + d, :own_columns], g[sub, :own_columns])  # (20)
        update_weight[sub, i] = Pxz_i
        receiver = chain[sub, i]
        x[sub, receiver] += Pxz_i / Pz[sub, None] * innovation[sub, None]  # (21)
        # (22)-(23): Delta P_{c_i c_j} = Pxz^i Pz^-1 (Pxz^j)^T for the up-neighbours and itself
        upstream = update_weight[sub, : i + 1]  # (b, i+1, d)
        delta = Pxz_i[:, :, None, None] * upstream[:, None, :, :] / Pz[sub, None, None, None]
        delta = delta.reshape(len(sub), d, d * (i + 1))  # columns: blocks c_1..c_i
        P_sub = P[sub]
        _add_blocks(P_sub, receiver[:, None], chain[sub, : i + 1], -delta, d)
        if i > 0:
            _add_blocks(P_sub, chain[sub, :i], receiver[:, None], -np.swapaxes(delta[:, :, : d * i], -1, -2), d)
        P[sub] = P_sub

    if truncation == "consistent":
        unreached = ~reached_mask
        partial = np.flatnonzero(unreached.any(axis=1))
        if len(partial):
            gain = np.zeros((B, N, d))  # K_r = Pxz^r / Pz in absolute platform order
            gain[hop_copy, valid[hop_copy, hop_position]] = update_weight[hop_copy, hop_position]
            gain = gain / Pz[:, None, None]
            cross = gain[:, :, None, :, None] * P_zj[:, None, :, None, :]  # (B, r, u, d, d) = K_r P_zu
            mask = (reached_mask[:, :, None] & unreached[:, None, :])[:, :, :, None, None]
            cross = np.where(mask, cross, 0.0).transpose(0, 1, 3, 2, 4).reshape(B, L, L)
            P[partial] -= cross[partial] + np.swapaxes(cross[partial], -1, -2)
    P = 0.5 * (P + np.swapaxes(P, -1, -2))
    return x.reshape(*batch, N, d), P.reshape(*batch, L, L)
