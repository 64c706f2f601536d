"""Adaptive finite-horizon group estimator (AFGE) with delay-aware FIR (DFIR).

Gao S., Gao Y., Zhong Y., Wei W., "Adaptive finite-horizon group estimator for networked
navigation under mixed LOS/NLOS environments and random delay", 2016 (seed
``004_4a0edde314525ef9.txt``). The extracted text lost every formula; this module
implements the reconstruction in ``docs/gao2016.md`` (the contract; "§N" below is its section N)
and keeps its labels: **[paper]** stated in the text we have, **[reconstructed]** rebuilt from the
prose and standard results, **[chosen]** a value the paper had but we lost.

Pipeline for one target (all functions take a leading batch shape ``...``):

1. Packet -> position fix (§4, eqs. 4-6) [reconstructed], ``packet_fixes``.
   Neighbour j sends its own position estimate p_hat_j, the RSS and the AOA of the target.
   With the mode information m (the true NLOS flag / pi / 0 for ``mode_info`` =
   ``known`` / ``mean`` / ``blind``) the NLOS bias is removed and the variance moment-matched,
   ``bias = m mu``, ``var = s^2 + m s_b^2 + m (1 - m) mu^2``; then
   ``r_hat = d0 10^((P_T - PL(d0) - RSS - m mu_db) / (10 n))``, ``th_hat = theta - m mu_theta``,
   ``z_j = p_hat_j + r_hat [cos th_hat, sin th_hat]``, ``sigma_r = kappa r_hat sqrt(var_db)``
   (``kappa = ln 10 / (10 n)``), ``R_j = J diag(sigma_r^2, var_theta) J^T + P_j``.
2. Reorganisation by stamp (Step 1, Lemma 4) [paper/reconstructed], ``known_at_lag``:
   at time k the packets of stamp s known are those with delay tau <= k - s; stamps older
   than k - D are final. A packet with tau > D never counts.
3. Complementary fusion (Step 2, eqs. 21-27, Def. 6) [reconstructed], ``fuse_fixes``:
   among the known packets keep the ``n_strongest`` by RSS [paper: "only the strongest
   received signals are adopted"], weights ``w_j = r_hat_j / sum_l r_hat_l`` (``distance``,
   Def. 6) or ``w_j = 1`` (``information``), ``Y = sum_j w_j R_j^-1``, ``y = sum_j w_j R_j^-1 z_j``;
   the observation ``z(s) = Y^-1 y = H x(s) + v(s)``, ``R(s) = Y^-1``, ``H = [I_2, 0]``.
   ``gamma(s, l) = 1[#used >= n_min]`` (Remark 5); gamma = 0 -> Y = 0, y = 0.
4. DFIR (Lemma 7, eqs. 33-46) [reconstructed]: ``dfir_batch`` is the batch
   unbiased minimum-variance FIR gain
   ``K = F W0 + C Xi^-1 (I - G W0)``, ``W0 = (G^T Xi^-1 G)^-1 G^T Xi^-1``, ``F = A^(N-1)``,
   ``C = S Qw L^T``; ``stack_advance`` is the equivalent recursive form, an information
   filter started with ZERO information at the horizon's first stamp, predict
   ``M = A^-T Y A^-1, Y <- (I + M Gam)^-1 M, y <- (I + M Gam)^-1 A^-T y`` (valid for singular
   Y), update ``Y += H^T Y(s) H, y += H^T y(s)``. Every horizon N = 1..N_max is one slot of a
   stack (shift in a zero filter, predict, update), so one stack gives all constant-N DFIRs.
   The estimate exists when at least two stamps with gamma = 1 lie in the horizon
   (``G`` observable for the CV model); otherwise the output is the prediction
   ``A x_hat(k-1)`` (``valid = False``). Delays: ``buffer_step`` keeps the stack at the
   last final stamp k - D and re-runs the last D stamps with the packets received so far.
5. AHG policy and AFGE (Algorithm 10) [reconstructed, after horizon-group-shift FIR]:
   ``ahg_group``, ``ahg_select`` with the costs ``predictive_costs`` (default),
   ``in_sample_costs`` (``likelihood="paper"``) and ``smooth_costs`` (``"smoothed"``,
   an extension, not in the paper).
6. Baseline: the delay-aware Kalman filter on the same fused observations (§8) is the
   same information recursion without the shift, started from the prior at stamp 0
   (``shift=False`` in ``buffer_step``; ``run_kalman``).

State ``x = [p_x, p_y, v_x, v_y]`` (m, m/s), ``x(k+1) = A x(k) + B w(k)``, ``w ~ N(0, sigma_a^2 I_2)``,
``A = [[I, T I], [0, I]]``, ``B = [[T^2/2 I], [T I]]`` [reconstructed: the paper writes a 2-D
position/velocity model with period T].

Departures
----------
* The printed formulas are lost: everything above is the reconstruction, not a
  transcription. In particular the distance weights of Def. 6 are normalised to sum to one
  (a covariance-intersection-type bound, so the fused R(s) is never smaller than the plain
  information sum). The fixes are independent, so the bound is conservative by about the number
  n of packets fused per stamp (Y(s) keeps about 1/n of sum_j R_j^-1, and a horizon's P scales
  with the R(s)): with the model matched (LOS only, no turns, sigma_a = 1e-3) and n_strongest = 4
  (4.00 packets fused per stamp) the mean position NEES (2 DOF) is 0.57 for DFIR and 0.60 for
  AFGE, P about 3.5 times the error covariance; ``weighting="information"`` reads 2.05 and 2.15
  on the same episodes (consistent). Measurements and commands: docs/gao2016.md, section 15.
* AHG's "maximum likelihood" cost is the one-step predictive
  likelihood; the in-sample residual (``likelihood="paper"``) favours short horizons because
  the estimate already contains z(k).
* Where no horizon in the group has a finite cost (e.g. the previous estimate of every
  member was invalid) AHG is treated like a step without a fresh observation: the centre's
  estimate (or the largest valid member) is output and the centre kept.
* Numerical health (every documented extreme stays finite, symmetric and PSD): the
  information predict is formed in Joseph form, ``Y <- L M L^T + K Q^-1 K^T`` (a sum of
  congruences; the short Woodbury form ``M - K B^T M`` went indefinite to rounding once one
  step's process noise dwarfs the fixes, e.g. T = 1e4 s), and the inverse ``P = Y^-1`` is
  guarded: a horizon with two observed stamps whose Y is nonetheless singular to rounding (one
  fix with 1e-20 of the other's information, as sigma_db = 100 dB produces) has no estimate
  (``valid = False``: the output is the prediction) instead of dividing by zero
  (``information_predict``, ``_spd_inverse4``). Information form rather than a
  covariance filter because a horizon starts with zero information; Joseph form rather than a
  square-root (QR) information filter because it keeps the 2x2 block closed forms and the
  compiled kernel's cost.
* Speed: the recursion is written on the 2x2 blocks of the CV model and inverts only 2x2
  blocks in closed form (Woodbury in the predict, a Schur complement of the velocity block
  for Y^-1): numpy's stacked matmul/solve on 4x4 matrices is dominated by per-matrix
  overhead. The reference batch form ``dfir_batch`` uses
  ``scipy.linalg.solve``; a test holds the two equal to 1e-9.
* Speed: this module is the numpy reference. Where numba is installed, a time step's buffer
  re-run and estimates (``buffer_estimates``), the packet fixes (``packet_fixes``), their
  selection and fusion (``fuse_packets``) and AHG's costs (``predictive_costs``) run as the
  compiled kernels of ``estimators.afge_kernels``, one (copy, target) element at a time, with the
  same formulas in the same order, so results agree to the last bit on the tests' machine and
  to 1e-9 by test; ``compiled=False`` is the numpy reference, also used without numba.

Noise parameters: the library's models take variances (``estimators.models``); this module keeps the
paper's standard deviations where the paper states them (``MotionModel.accel_sigma``, the ``sigma_*``
fields of ``SignalModel``), each said so in its docstring; ``run_kalman``'s ``accel_var`` is a variance.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg

from estimators import afge_kernels as kernels
from estimators.afge_kernels import INVERTIBLE_TOL, joseph_predict

__all__ = [
    "SPEED_OF_LIGHT",
    "MODE_INFOS",
    "WEIGHTINGS",
    "LIKELIHOODS",
    "MotionModel",
    "SignalModel",
    "AHGParams",
    "HorizonStack",
    "reference_path_loss",
    "range_from_power",
    "mode_weight",
    "packet_fixes",
    "known_at_lag",
    "select_strongest",
    "fuse_fixes",
    "fused_fix",
    "fuse_packets",
    "fuse_episode",
    "dfir_batch",
    "information_predict",
    "buffer_estimates",
    "empty_stack",
    "prior_stack",
    "stack_advance",
    "stack_estimates",
    "buffer_observations",
    "buffer_step",
    "predictive_costs",
    "in_sample_costs",
    "smooth_costs",
    "ahg_group",
    "ahg_select",
    "run_fixed_mask",
    "run_kalman",
]

SPEED_OF_LIGHT = 299_792_458.0
MODE_INFOS = ("known", "mean", "blind")
WEIGHTINGS = ("distance", "information")
LIKELIHOODS = ("predictive", "paper", "smoothed")


# --------------------------------------------------------------------------------------
# models
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MotionModel:
    """The estimator's constant-velocity model (§2) [reconstructed].

    ``period`` T (s), ``accel_sigma`` sigma_a (m/s^2), a standard deviation (not a variance):
    Q = sigma_a^2 I_2, Gam = B Q B^T.
    """

    period: float = 1.0
    accel_sigma: float = 0.3

    @cached_property
    def transition(self) -> np.ndarray:
        """A = [[I_2, T I_2], [0, I_2]]."""
        return np.block([[np.eye(2), self.period * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])

    @cached_property
    def noise_input(self) -> np.ndarray:
        """B = [[T^2/2 I_2], [T I_2]]."""
        return np.vstack([0.5 * self.period**2 * np.eye(2), self.period * np.eye(2)])

    @cached_property
    def accel_cov(self) -> np.ndarray:
        """Q = sigma_a^2 I_2."""
        return self.accel_sigma**2 * np.eye(2)

    @cached_property
    def process_cov(self) -> np.ndarray:
        """Gam = B Q B^T."""
        return self.noise_input @ self.accel_cov @ self.noise_input.T

    @cached_property
    def measurement(self) -> np.ndarray:
        """H = [I_2, 0]."""
        return np.hstack([np.eye(2), np.zeros((2, 2))])


@dataclass(frozen=True)
class SignalModel:
    """What the estimator knows of the RSS/AOA packets (§4) [reconstructed].

    Units: dBm / dB, Hz, m, radians. ``sigma_db``, ``sigma_theta``, ``nlos_sigma_db``, ``nlos_sigma_theta``
    and ``sigma_nav`` (m per axis) are standard deviations, not variances. ``p_nlos`` is pi, used by
    ``mode_info="mean"``.
    """

    tx_power_dbm: float = 20.0
    frequency_hz: float = 2.4e9
    d0: float = 1.0
    exponent: float = 2.2
    sigma_db: float = 2.0
    sigma_theta: float = np.deg2rad(0.1)
    nlos_bias_db: float = 6.0
    nlos_sigma_db: float = 4.0
    nlos_bias_theta: float = np.deg2rad(1.0)
    nlos_sigma_theta: float = np.deg2rad(1.0)
    sigma_nav: float = 2.0
    p_nlos: float = 0.3

    @property
    def reference_loss_db(self) -> float:
        return reference_path_loss(self.frequency_hz, self.d0)


@dataclass(frozen=True)
class AHGParams:
    """Design parameters of the AHG policy (Algorithm 10) [chosen]: N_min, N_max, dN, M, N_c(0).

    ``likelihood`` one of ``LIKELIHOODS``; ``smoothing`` lam of the smoothed variant.
    """

    window_min: int = 4
    window_max: int = 30
    window_step: int = 2
    group_size: int = 5
    centre0: int = 12
    likelihood: str = "predictive"
    smoothing: float = 0.5

    @property
    def half(self) -> int:
        """h = (M - 1) / 2."""
        return (self.group_size - 1) // 2


@dataclass
class HorizonStack:
    """Information filters, one per horizon N = 1..S (slot N-1), or one Kalman filter (S = 1).

    ``info`` (..., S, 4, 4) Y, ``vector`` (..., S, 4) y, ``stamps`` (..., S) the number of
    stamps with gamma = 1 in each horizon (the estimate exists when >= 2).
    """

    info: np.ndarray
    vector: np.ndarray
    stamps: np.ndarray

    def copy(self) -> HorizonStack:
        return HorizonStack(self.info.copy(), self.vector.copy(), self.stamps.copy())

    def select(self, keep: np.ndarray, other: HorizonStack) -> HorizonStack:
        """``self`` where ``keep`` (...) else ``other``."""
        k = np.asarray(keep, bool)
        return HorizonStack(np.where(k[..., None, None, None], self.info, other.info),
                            np.where(k[..., None, None], self.vector, other.vector),
                            np.where(k[..., None], self.stamps, other.stamps))


# --------------------------------------------------------------------------------------
# packets -> fused position observations (§4-5)
# --------------------------------------------------------------------------------------
def reference_path_loss(frequency_hz: float, d0: float) -> float:
    """Free-space loss at d0, PL(d0) = 20 log10(4 pi d0 f / c) (dB) (Def. 2) [reconstructed]."""
    return float(20.0 * np.log10(4.0 * np.pi * d0 * frequency_hz / SPEED_OF_LIGHT))


def range_from_power(power_dbm, tx_power_dbm: float, reference_loss_db: float, exponent: float, d0: float):
    """Distance of the log-distance model with received power ``power_dbm`` (Def. 2):
    ``r(P) = d0 10^((P_T - PL(d0) - P) / (10 n))`` [reconstructed]."""
    return d0 * 10.0 ** ((tx_power_dbm - reference_loss_db - np.asarray(power_dbm, float)) / (10.0 * exponent))


def mode_weight(mode_info: str, modes: np.ndarray, p_nlos: float) -> np.ndarray:
    """m per packet: the true NLOS flag (``known``), pi (``mean``) or 0 (``blind``) (§4)."""
    modes = np.asarray(modes)
    if mode_info == "known":
        return modes.astype(float)
    if mode_info == "mean":
        return np.full(modes.shape, float(p_nlos))
    if mode_info == "blind":
        return np.zeros(modes.shape)
    raise ValueError(f"mode_info must be one of {MODE_INFOS}, got {mode_info!r}")


def packet_fixes(signal: SignalModel, sender_position, rss, aoa, m, compiled: bool | None = None):
    """Target position fix of each packet (§4, eqs. 4-6 + sender error) [reconstructed].

    ``sender_position`` (..., 2) p_hat_j, ``rss`` (...) dBm, ``aoa`` (...) rad (bearing of the
    target seen from j), ``m`` (...) mode weight. Returns ``z`` (..., 2), ``R`` (..., 2, 2),
    ``r_hat`` (...). ``compiled`` (default: where numba is installed) runs
    ``estimators.afge_kernels.fixes_kernel``, equal to this numpy form (``compiled=False``, the reference) to
    rounding: tests hold it to 1e-9.
    """
    pair = kernels.pair("fixes", compiled)
    if pair is not None:
        return kernels.packet_fixes(pair, signal, sender_position, rss, aoa, m)
    m = np.asarray(m, float)
    var_db = signal.sigma_db**2 + m * signal.nlos_sigma_db**2 + m * (1.0 - m) * signal.nlos_bias_db**2
    var_theta = (signal.sigma_theta**2 + m * signal.nlos_sigma_theta**2
                 + m * (1.0 - m) * signal.nlos_bias_theta**2)
    # RSS = ... - eps with E[eps] = m mu_db, so adding m mu_db back removes the NLOS attenuation.
    r_hat = range_from_power(np.asarray(rss, float) + m * signal.nlos_bias_db, signal.tx_power_dbm,
                             signal.reference_loss_db, signal.exponent, signal.d0)
    theta = np.asarray(aoa, float) - m * signal.nlos_bias_theta
    c, s = np.cos(theta), np.sin(theta)
    z = np.asarray(sender_position, float) + r_hat[..., None] * np.stack([c, s], axis=-1)
    kappa = np.log(10.0) / (10.0 * signal.exponent)
    var_r = (kappa * r_hat) ** 2 * var_db
    var_t = r_hat**2 * var_theta  # tangential variance, (r sigma_theta)^2
    # J diag(var_r, var_theta) J^T with J = [[c, -r s], [s, r c]], written out
    R = np.empty((*z.shape, 2))
    R[..., 0, 0] = c * c * var_r + s * s * var_t + signal.sigma_nav**2
    R[..., 1, 1] = s * s * var_r + c * c * var_t + signal.sigma_nav**2
    R[..., 0, 1] = R[..., 1, 0] = c * s * (var_r - var_t)
    return z, R, r_hat


def known_at_lag(delays: np.ndarray, lag) -> np.ndarray:
    """Packets of a stamp known ``lag`` steps later: tau <= lag (Step 1) [paper].

    ``delays`` holds tau in 0..D, anything larger (lost, or never sent) never arrives. A lag
    is at most D: the caller never asks past the buffer, so a packet with tau > D is never used.
    """
    return np.asarray(delays) <= np.asarray(lag)


def select_strongest(rss: np.ndarray, usable: np.ndarray, n_strongest: int) -> np.ndarray:
    """The ``n_strongest`` usable packets by RSS along the last axis (ties: lower index) [paper]."""
    usable = np.asarray(usable, bool)
    key = np.where(usable, np.asarray(rss, float), -np.inf)
    order = np.argsort(-key, axis=-1, kind="stable")
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.broadcast_to(np.arange(order.shape[-1]), order.shape), axis=-1)
    return usable & (rank < n_strongest)


def _inv2(R: np.ndarray) -> np.ndarray:
    """Closed-form inverse of symmetric 2x2 blocks (cheaper than a stacked LAPACK call)."""
    det = R[..., 0, 0] * R[..., 1, 1] - R[..., 0, 1] * R[..., 1, 0]
    out = np.empty_like(R)
    out[..., 0, 0] = R[..., 1, 1] / det
    out[..., 1, 1] = R[..., 0, 0] / det
    out[..., 0, 1] = -R[..., 0, 1] / det
    out[..., 1, 0] = -R[..., 1, 0] / det
    return out


def fuse_fixes(z, R, r_hat, used, weighting: str = "distance", min_packets: int = 1):
    """Complementary fusion of one stamp's packets (Step 2, eqs. 21-27, Def. 6) [reconstructed].

    Packets on the second-to-last axis: ``z`` (..., J, 2), ``R`` (..., J, 2, 2), ``r_hat``
    (..., J), ``used`` (..., J) bool. Returns ``(Y, y, gamma, count)`` with Y (..., 2, 2),
    y (..., 2), gamma (...) bool, count (...) int; gamma = 0 gives Y = 0, y = 0.
    """
    used = np.asarray(used, bool)
    count = used.sum(axis=-1)
    if weighting == "distance":
        # Def. 6: larger weight to farther neighbours, weights sum to one
        dist = np.where(used, r_hat, 0.0)
        total = dist.sum(axis=-1, keepdims=True)
        w = dist / np.where(total > 0, total, 1.0)
    elif weighting == "information":
        w = used.astype(float)
    else:
        raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    gamma = count >= min_packets
    w = np.where(gamma[..., None], w, 0.0)
    Rinv = _inv2(np.where(used[..., None, None], R, np.eye(2)))
    Y = np.einsum("...j,...jab->...ab", w, Rinv)
    y = np.einsum("...j,...jab,...jb->...a", w, Rinv, np.where(used[..., None], z, 0.0))
    return Y, y, gamma, count


def fused_fix(Y: np.ndarray, y: np.ndarray, gamma: np.ndarray):
    """z(s) = Y^-1 y and R(s) = Y^-1 where gamma (else z = 0, R = I as placeholders)."""
    gamma = np.asarray(gamma, bool)
    safe = np.where(gamma[..., None, None], Y, np.eye(2))
    R = _inv2(safe)
    z = np.einsum("...ab,...b->...a", R, np.where(gamma[..., None], y, 0.0))
    return z, R


def fuse_packets(signal: SignalModel, rss, aoa, nav, modes, delays, lags, keep, n_strongest: int,
                 mode_info: str = "known", weighting: str = "distance", min_packets: int = 1,
                 fixes: tuple | None = None, compiled: bool | None = None):
    """Steps 1-2 for buffered stamps: the fused observation of each stamp from its packets
    known now (§4-5) [paper/reconstructed]; ``known_at_lag``, ``select_strongest``,
    ``mode_weight``, ``packet_fixes`` and ``fuse_fixes`` in that order.

    Packets on the last axis J: ``rss``/``aoa``/``modes``/``delays`` (..., J), ``nav`` (..., J, 2)
    the senders' position estimates; ``lags`` (...) how long ago each stamp was (negative: not
    yet sent); ``keep`` (..., J) a selection mask applied before the ``n_strongest`` rule.
    ``fixes``: ``packet_fixes`` of these packets (z, R, r_hat) when the caller has them
    (a packet's fix depends neither on the lag nor on the mask). ``compiled`` (default: where
    numba is installed) selects and sums in one pass per stamp (``estimators.afge_kernels.fuse_kernel``;
    equal to the numpy path, ``compiled=False``, to rounding). Returns ``(Y, y, gamma, used)``.
    """
    if fixes is None:
        fixes = packet_fixes(signal, nav, rss, aoa, mode_weight(mode_info, modes, signal.p_nlos))
    z, R, r_hat = fixes
    if weighting not in WEIGHTINGS:
        raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    lags = np.asarray(lags)
    pair = kernels.pair("fuse", compiled)
    if pair is None:
        known = known_at_lag(delays, np.where(lags >= 0, lags, -1)[..., None]) & (lags >= 0)[..., None]
        used = select_strongest(rss, known & keep, n_strongest)
        Y, y, gamma, _ = fuse_fixes(z, R, r_hat, used, weighting, min_packets)
        return Y, y, gamma, used
    return kernels.fuse_packets(pair, z, R, r_hat, rss, delays, lags, keep, n_strongest, weighting == "distance",
                                min_packets)


def fuse_episode(signal: SignalModel, rss, aoa, nav, modes, delays, buffer_length: int, n_strongest: int,
                 mode_info: str = "known", weighting: str = "distance", min_packets: int = 1):
    """Every fused observation of a whole episode by (stamp, lag), every packet kept: ``fuse_packets`` of
    stamp s as known at lag l = 0..D (D = ``buffer_length``).

    Packets (K+1, T, J) of T targets from J senders: ``rss``, ``aoa``, ``modes``, ``delays`` (a delay above D
    never arrives), ``nav`` (K+1, T, J, 2). Returns ``(Y, y, gamma)``, (T, K+1, D+1, 2, 2), (T, K+1, D+1, 2)
    and (T, K+1, D+1): the layout ``run_fixed_mask`` and ``run_kalman`` take.
    """
    rss = np.asarray(rss)
    lags = np.broadcast_to(np.arange(buffer_length + 1), (*rss.shape[:2], buffer_length + 1))
    Y, y, gamma, _ = fuse_packets(signal, rss[:, :, None], np.asarray(aoa)[:, :, None], np.asarray(nav)[:, :, None],
                                  np.asarray(modes)[:, :, None], np.asarray(delays)[:, :, None], lags,
                                  np.ones(1, bool), n_strongest, mode_info, weighting, min_packets)
    return np.moveaxis(Y, 0, 1), np.moveaxis(y, 0, 1), np.moveaxis(gamma, 0, 1)


# --------------------------------------------------------------------------------------
# DFIR: batch form (Lemma 7) and the recursive stack
# --------------------------------------------------------------------------------------
def dfir_batch(motion: MotionModel, fixes: list) -> dict:
    """Batch unbiased minimum-variance FIR over one horizon (Lemma 7, eqs. 33-46) [reconstructed].

    ``fixes``: one entry per stamp m..k, oldest first, ``(z (2,), R (2, 2))`` or ``None``
    (gamma = 0). Builds ``Z = G x(m) + L W + V``, ``x(k) = A^(N-1) x(m) + S W`` and returns
    ``{"gain": K, "G": G, "F": A^(N-1), "estimate": K Z, "cov": P}`` with
    ``K = F W0 + C Xi^-1 (I - G W0)``, ``C = S Qw L^T``,
    ``P = K Xi K^T - K L Qw S^T - S Qw L^T K^T + S Qw S^T``. Unbatched reference
    implementation (it is what the recursion is tested against).
    """
    A, Bw, Q, H = motion.transition, motion.noise_input, motion.accel_cov, motion.measurement
    N = len(fixes)
    power = [np.linalg.matrix_power(A, i) for i in range(N)]
    G_rows, L_rows, Z, Rs = [], [], [], []
    for i, fix in enumerate(fixes):
        if fix is None:
            continue
        G_rows.append(H @ power[i])
        row = np.zeros((2, 2 * (N - 1)))
        for t in range(i):  # w(m + t) reaches x(m + i) through A^(i-1-t) B
            row[:, 2 * t:2 * t + 2] = H @ power[i - 1 - t] @ Bw
        L_rows.append(row)
        Z.append(np.asarray(fix[0], float))
        Rs.append(np.asarray(fix[1], float))
    if len(Z) < 2:
        raise ValueError("dfir_batch needs at least two stamps with an observation (G observable)")
    G, L, Zv = np.vstack(G_rows), np.vstack(L_rows), np.concatenate(Z)
    S = np.hstack([power[N - 2 - t] @ Bw for t in range(N - 1)]) if N > 1 else np.zeros((4, 0))
    Qw = np.kron(np.eye(N - 1), Q)
    Xi = L @ Qw @ L.T + scipy.linalg.block_diag(*Rs)
    F = power[N - 1]
    C = S @ Qw @ L.T
    Xi_inv_G = scipy.linalg.solve(Xi, G, assume_a="pos")
    W0 = scipy.linalg.solve(G.T @ Xi_inv_G, Xi_inv_G.T, assume_a="pos")
    C_Xi_inv = scipy.linalg.solve(Xi, C.T, assume_a="pos").T
    K = F @ W0 + C_Xi_inv @ (np.eye(len(Zv)) - G @ W0)
    P = K @ Xi @ K.T - K @ L @ Qw @ S.T - S @ Qw @ L.T @ K.T + S @ Qw @ S.T
    return {"gain": K, "G": G, "F": F, "estimate": K @ Zv, "cov": 0.5 * (P + P.T)}


# 2x2 blocks as 4-tuples of arrays (a00, a01, a10, a11): every operation is a few
# elementwise numpy calls over the whole batch. Stacked matmul/solve on (..., 4, 4) arrays is
# dominated by per-matrix overhead, and BLAS threads contend on a loaded machine.
def _blk(X, r, c):
    return (X[..., r, c], X[..., r, c + 1], X[..., r + 1, c], X[..., r + 1, c + 1])


def _tr(a):
    return (a[0], a[2], a[1], a[3])


def _mul(a, b):
    return (a[0] * b[0] + a[1] * b[2], a[0] * b[1] + a[1] * b[3], a[2] * b[0] + a[3] * b[2], a[2] * b[1] + a[3] * b[3])


def _mul_t(a, b):
    """a @ b^T."""
    return (a[0] * b[0] + a[1] * b[1], a[0] * b[2] + a[1] * b[3], a[2] * b[0] + a[3] * b[1], a[2] * b[2] + a[3] * b[3])


def _lin(*terms):
    """sum_i c_i X_i for pairs (c_i, X_i) of scalars and blocks."""
    return tuple(sum(c * X[i] for c, X in terms) for i in range(4))


def _inv(a):
    det = a[0] * a[3] - a[1] * a[2]
    return (a[3] / det, -a[1] / det, -a[2] / det, a[0] / det)


def _vec(a, v):
    return (a[0] * v[0] + a[1] * v[1], a[2] * v[0] + a[3] * v[1])


def _assemble(P11, P12, P22, shape) -> np.ndarray:
    """Symmetric (..., 4, 4) from its blocks (the symmetric parts of P11 and P22)."""
    out = np.empty((*shape, 4, 4))
    out[..., 0, 0], out[..., 1, 1] = P11[0], P11[3]
    out[..., 0, 1] = out[..., 1, 0] = 0.5 * (P11[1] + P11[2])
    out[..., 2, 2], out[..., 3, 3] = P22[0], P22[3]
    out[..., 2, 3] = out[..., 3, 2] = 0.5 * (P22[1] + P22[2])
    for i, (r, c) in enumerate(((0, 2), (0, 3), (1, 2), (1, 3))):
        out[..., r, c] = out[..., c, r] = P12[i]
    return out


def information_predict(motion: MotionModel, info: np.ndarray, vector: np.ndarray, accel_var=None):
    """Information-form prediction valid for singular Y (§6) [reconstructed], in Joseph form.

    ``M = A^-T Y A^-1``, ``Y <- (I + M Gam)^-1 M``, ``y <- (I + M Gam)^-1 A^-T y``. With
    Gam = B Q B^T, Woodbury gives ``(I + M Gam)^-1 = I - K B^T``, ``K = M B W^-1``,
    ``W = Q^-1 + B^T M B``: only a 2x2 matrix is inverted, and it is positive definite whatever
    Y is. The information is formed in Joseph form,
    ``Y <- L M L^T + K Q^-1 K^T``, ``L = I - K B^T``, algebraically equal to ``M - K B^T M``
    (expand and use ``B^T M B = W - Q^-1``), evaluated as ``estimators.afge_kernels.joseph_predict`` says. The short
    form ``M - K B^T M`` subtracts two nearly equal matrices when the process
    noise wipes out most of the information along B (a long period T with anisotropic fused fixes:
    at T = 1e4 s, sigma_a = 0.3 m/s^2 the position noise of one step is 1.5e7 m): there its
    rounding error exceeded the small eigenvalues of Y, Y went indefinite and P = Y^-1 had
    negative variances; the Joseph correction keeps Y PSD to rounding there
    (tests/estimators/test_afge_health.py holds it at T = 1e3 and 1e4 s). Written on the 2x2 blocks
    of the CV model
    (A = [[I, T I], [0, I]], B = [[T^2/2 I], [T I]]) in ``estimators.afge_kernels.joseph_predict``, which the
    compiled kernel shares. ``accel_var``
    (scalar or broadcastable to the leading shape of ``info`` without the last two axes)
    overrides sigma_a^2, e.g. per batch element.
    """
    T = float(motion.period)
    q = motion.accel_sigma**2 if accel_var is None else np.asarray(accel_var, float)
    v = (vector[..., 0], vector[..., 1], vector[..., 2], vector[..., 3])
    P11, P12, P22, y = joseph_predict(_blk(info, 0, 0), _blk(info, 0, 2), _blk(info, 2, 2), v, T, 0.5 * T * T, T,
                                      1.0 / q)
    out = np.empty(info.shape)
    out[..., 0, 0], out[..., 1, 1], out[..., 2, 2], out[..., 3, 3] = P11[0], P11[2], P22[0], P22[2]
    out[..., 0, 1] = out[..., 1, 0] = P11[1]
    out[..., 2, 3] = out[..., 3, 2] = P22[1]
    for i, (r, c) in enumerate(((0, 2), (0, 3), (1, 2), (1, 3))):
        out[..., r, c] = out[..., c, r] = P12[i]
    return out, np.stack(y, axis=-1)


def empty_stack(batch_shape: tuple, size: int) -> HorizonStack:
    """The stack before stamp 0: zero information in every slot (horizons before stamp 0 are
    truncated to stamps 0..k automatically)."""
    return HorizonStack(np.zeros((*batch_shape, size, 4, 4)), np.zeros((*batch_shape, size, 4)),
                        np.zeros((*batch_shape, size), dtype=np.int64))


def prior_stack(prior_mean: np.ndarray, prior_cov: np.ndarray) -> HorizonStack:
    """A Kalman filter (S = 1) holding the prior of x(0) (before stamp 0's update), §8."""
    prior_mean = np.asarray(prior_mean, float)
    Y0 = np.linalg.inv(np.asarray(prior_cov, float))
    info = np.broadcast_to(Y0, (*prior_mean.shape[:-1], 1, 4, 4)).copy()
    vector = (info @ prior_mean[..., None, :, None])[..., 0]
    return HorizonStack(info, vector, np.full((*prior_mean.shape[:-1], 1), 2, dtype=np.int64))


def stack_advance(motion: MotionModel, stack: HorizonStack, obs_info, obs_vector, obs_success, stamp,
                  shift: bool = True, accel_var=None) -> HorizonStack:
    """Advance every filter by one stamp (§6): shift in a zero filter (``shift``), predict
    (where ``stamp > 0``), update with the fused observation of that stamp.

    ``obs_info`` (..., 2, 2), ``obs_vector`` (..., 2), ``obs_success`` (...) gamma, ``stamp``
    (...) int; a negative stamp leaves that element unchanged (nothing to process yet).
    """
    stamp = np.asarray(stamp)
    active = stamp >= 0
    if not active.any():
        return stack
    info, vector, stamps = stack.info, stack.vector, stack.stamps
    if shift:
        info = np.concatenate([np.zeros_like(info[..., :1, :, :]), info[..., :-1, :, :]], axis=-3)
        vector = np.concatenate([np.zeros_like(vector[..., :1, :]), vector[..., :-1, :]], axis=-2)
        stamps = np.concatenate([np.zeros_like(stamps[..., :1]), stamps[..., :-1]], axis=-1)
    predict = stamp > 0
    var = None if accel_var is None else np.asarray(accel_var, float)[..., None]  # one per stack slot
    if predict.all():  # the usual case: no selection, the predicted arrays are fresh
        info, vector = information_predict(motion, info, vector, var)
    elif predict.any():
        pred_info, pred_vector = information_predict(motion, info, vector, var)
        info = np.where(predict[..., None, None, None], pred_info, info)
        vector = np.where(predict[..., None, None], pred_vector, vector)
    elif not shift:
        info, vector = info.copy(), vector.copy()
    # H^T Y(s) H and H^T y(s) touch only the position block
    info[..., :2, :2] += np.asarray(obs_info)[..., None, :, :]
    vector[..., :2] += np.asarray(obs_vector)[..., None, :]
    stamps = stamps + np.asarray(obs_success, np.int64)[..., None]
    new = HorizonStack(info, vector, stamps)
    return new if active.all() else new.select(active, stack)


def _spd_inverse4(Y: np.ndarray):
    """Inverse of symmetric PSD 4x4 blocks by the Schur complement of the velocity block (2x2
    closed forms), guarded: returns ``(P, ok)``.

    ``P = [[Sc^-1, -Sc^-1 T1], [-T1^T Sc^-1, Y22^-1 + T1^T Sc^-1 T1]]``, ``T1 = Y12 Y22^-1``,
    ``Sc = Y11 - T1 Y12^T``: a congruence of ``diag(Sc^-1, Y22^-1)``, so P is PSD exactly when both
    2x2 blocks are positive definite. ``ok`` says they are, with a margin that rounding cannot
    cross: ``det Y22 > tol tr(Y22)^2`` and ``det Sc > tol tr(Sc) tr(Y11)`` (det / tr is the
    smallest eigenvalue to a factor of 2; Sc is a difference of matrices of the size of Y11, so its
    rounding error is relative to Y11), tol = ``INVERTIBLE_TOL``. Where not ``ok`` the
    divisions are guarded (P is that of the identity) and the caller treats the slot as having no
    estimate: two observed stamps make Y invertible in exact arithmetic, but not in floating
    point when one stamp's fix carries almost no information (sigma_db = 100 dB gives ranges
    r_hat = d0 10^(eps / 10n) over tens of decades, so a fix's information can be 1e-20 of the
    other stamp's) or when every fix constrains the same direction.
    """
    Y11, Y12, Y22 = _blk(Y, 0, 0), _blk(Y, 0, 2), _blk(Y, 2, 2)
    tol = INVERTIBLE_TOL
    det22, tr22 = Y22[0] * Y22[3] - Y22[1] * Y22[2], Y22[0] + Y22[3]
    ok = (tr22 > 0.0) & (det22 > tol * tr22 * tr22)
    one, zero = np.ones_like(det22), np.zeros_like(det22)
    Y22 = tuple(np.where(ok, a, b) for a, b in zip(Y22, (one, zero, zero, one), strict=True))
    Y22i = _inv(Y22)
    T1 = _mul(Y12, Y22i)
    Sc = _lin((1.0, Y11), (-1.0, _mul_t(T1, Y12)))
    detS, trS = Sc[0] * Sc[3] - Sc[1] * Sc[2], Sc[0] + Sc[3]
    ok &= (trS > 0.0) & (detS > tol * trS * (Y11[0] + Y11[3]))
    Sc = tuple(np.where(ok, a, b) for a, b in zip(Sc, (one, zero, zero, one), strict=True))
    Sci = _inv(Sc)
    P12 = _lin((-1.0, _mul(Sci, T1)))
    P22 = _lin((1.0, Y22i), (-1.0, _mul(_tr(T1), P12)))
    return _assemble(Sci, P12, P22, Y.shape[:-2]), ok


def stack_estimates(stack: HorizonStack, min_stamps: int = 2):
    """x_hat_N = Y^-1 y, P_N = Y^-1 and validity per slot: at least ``min_stamps`` observed
    stamps and Y numerically invertible (``_spd_inverse4``); an invalid slot has no estimate
    (its x and P are placeholders: those of Y = I, y = 0)."""
    valid = stack.stamps >= min_stamps
    P, ok = _spd_inverse4(np.where(valid[..., None, None], stack.info, np.eye(4)))
    valid = valid & ok
    P = np.where(valid[..., None, None], P, np.eye(4))
    y = np.where(valid[..., None], stack.vector, 0.0)
    x = np.stack([P[..., i, 0] * y[..., 0] + P[..., i, 1] * y[..., 1] + P[..., i, 2] * y[..., 2]
                  + P[..., i, 3] * y[..., 3] for i in range(4)], axis=-1)
    return x, P, valid


def buffer_observations(fused_info, fused_vector, fused_success, k):
    """The buffer at time k from observations precomputed by (stamp, lag) (Step 1).

    ``fused_*`` (..., K, D+1, ...): the fused observation of stamp s known at time s + l.
    Returns the D+1 stamps k-D..k (oldest first) as arrays (..., D+1, ...) and their stamps;
    stamps before 0 come back empty (gamma = 0, stamp < 0).
    """
    D = fused_success.shape[-1] - 1
    stamps = np.arange(k - D, k + 1)
    s = np.clip(stamps, 0, None)
    lag = k - s
    Y = fused_info[..., s, lag, :, :]
    y = fused_vector[..., s, lag, :]
    g = fused_success[..., s, lag] & (stamps >= 0)
    Y = np.where(g[..., None, None], Y, 0.0)
    y = np.where(g[..., None], y, 0.0)
    return Y, y, g, stamps


def buffer_step(motion: MotionModel, final: HorizonStack, k, buffer_info, buffer_vector, buffer_success,
                shift: bool = True, accel_var=None) -> tuple[HorizonStack, HorizonStack]:
    """One time step of the delay-aware re-run (§6): returns (final at k - D, current at k).

    ``final`` holds stamps < k - D; ``buffer_*`` (..., D+1, ...) the observations of stamps
    k-D..k as known at time k (oldest first). Stamp k - D becomes final now (all its packets
    arrived); stamps k-D+1..k are re-filtered from it with the packets received so far.
    ``k`` is an int or an array (...) (copies at different times).
    """
    k = np.asarray(k)
    D = buffer_success.shape[-1] - 1
    final = stack_advance(motion, final, buffer_info[..., 0, :, :], buffer_vector[..., 0, :],
                          buffer_success[..., 0], k - D, shift, accel_var)
    current = final
    for i in range(1, D + 1):
        current = stack_advance(motion, current, buffer_info[..., i, :, :], buffer_vector[..., i, :],
                                buffer_success[..., i], k - D + i, shift, accel_var)
    return final, current


def buffer_estimates(motion: MotionModel, final: HorizonStack, k, buffer_info, buffer_vector, buffer_success,
                     shift: bool = True, accel_var=None, min_stamps: int = 2, compiled: bool | None = None):
    """``buffer_step`` then ``stack_estimates`` of the current stack: (final, x, P, valid).

    The scenario's and the backend's step at time k: the stack of every horizon is advanced
    once per buffered stamp and read once. ``compiled`` (default: where numba is installed)
    runs ``estimators.afge_kernels.buffer_kernel``, the same arithmetic element by element (equal to the
    numpy path to rounding: tests hold it to 1e-9), instead of the numpy block form
    (``compiled=False``), which is the reference and the path without numba.
    """
    pair = kernels.pair("buffer", compiled)
    if pair is None:
        final, current = buffer_step(motion, final, k, buffer_info, buffer_vector, buffer_success, shift, accel_var)
        return (final, *stack_estimates(current, min_stamps))
    info, vector, stamps, x, P, valid = kernels.buffer_estimates(
        pair, final.info, final.vector, final.stamps, k, buffer_info, buffer_vector, buffer_success, shift,
        motion.accel_sigma**2 if accel_var is None else accel_var, float(motion.period), min_stamps)
    return HorizonStack(info, vector, stamps), x, P, valid


# --------------------------------------------------------------------------------------
# AHG and AFGE (Algorithm 10)
# --------------------------------------------------------------------------------------
def _quadratic2(e0, e1, S):
    """e^T S^-1 e and det S for a 2-vector (e0, e1) and a 2x2 block tuple S."""
    det = S[0] * S[3] - S[1] * S[2]
    return (S[3] * e0 * e0 - (S[1] + S[2]) * e0 * e1 + S[0] * e1 * e1) / det, det


def predictive_costs(motion: MotionModel, prev_x, prev_P, prev_valid, z, R, compiled: bool | None = None,
                     fresh=None):
    """One-step predictive likelihood cost of the newest observation for every horizon
    (``likelihood="predictive"``) [reconstructed]:
    ``e = z(k) - H A x_N(k-1)``, ``S = H (A P_N(k-1) A^T + Gam) H^T + R(k)``, ``J = e^T S^-1 e + ln det S``.

    ``prev_x`` (..., S, 4), ``prev_P`` (..., S, 4, 4), ``prev_valid`` (..., S), ``z`` (..., 2),
    ``R`` (..., 2, 2). Invalid -> +inf. ``fresh`` (...) gamma(k, 0): without a fresh observation
    there is nothing to score and the cost is +inf for every horizon (``z`` and ``R`` are then
    ``fused_fix``'s placeholders 0 and I; scoring them, as a smoothed cost would, adds
    ``|p|^2 / S``-sized terms that favour the horizon with the largest S, the shortest). ``compiled``
    (default: where numba is installed) runs ``estimators.afge_kernels.costs_kernel``, equal to this numpy form
    (``compiled=False``, the reference) to rounding: tests hold it to 1e-9.
    """
    costs = _predictive_costs(motion, prev_x, prev_P, prev_valid, z, R, compiled)
    return costs if fresh is None else np.where(np.asarray(fresh, bool)[..., None], costs, np.inf)


def _predictive_costs(motion: MotionModel, prev_x, prev_P, prev_valid, z, R, compiled):
    T = float(motion.period)
    pair = kernels.pair("costs", compiled)
    if pair is not None:
        return kernels.predictive_costs(pair, prev_x, prev_P, prev_valid, z, R, T, motion.process_cov)
    e0 = z[..., None, 0] - (prev_x[..., 0] + T * prev_x[..., 2])
    e1 = z[..., None, 1] - (prev_x[..., 1] + T * prev_x[..., 3])
    P11, P12, P22 = _blk(prev_P, 0, 0), _blk(prev_P, 0, 2), _blk(prev_P, 2, 2)
    Rb = tuple(r[..., None] for r in _blk(R, 0, 0))
    G = motion.process_cov
    Gb = (G[0, 0], G[0, 1], G[1, 0], G[1, 1])
    S = _lin((1.0, P11), (T, P12), (T, _tr(P12)), (T * T, P22), (1.0, Gb), (1.0, Rb))  # (A P A^T + Gam)_pp + R
    quad, det = _quadratic2(e0, e1, S)
    return np.where(prev_valid, quad + np.log(np.where(prev_valid, det, 1.0)), np.inf)


def in_sample_costs(x, valid, z, R, fresh=None):
    """In-sample residual ``J = (z(k) - H x_N(k))^T R(k)^-1 (.)`` (``likelihood="paper"``) [reconstructed];
    +inf where invalid, and for every horizon where ``fresh`` (...) is False (as ``predictive_costs``)."""
    e0, e1 = z[..., None, 0] - x[..., 0], z[..., None, 1] - x[..., 1]
    quad, _ = _quadratic2(e0, e1, tuple(r[..., None] for r in _blk(R, 0, 0)))
    if fresh is not None:
        valid = valid & np.asarray(fresh, bool)[..., None]
    return np.where(valid, quad, np.inf)


def smooth_costs(raw: np.ndarray, count: np.ndarray, costs: np.ndarray, lam: float):
    """Exponential forgetting per horizon size (``likelihood="smoothed"``, not in the paper):
    ``Jbar_N(k) = lam Jbar_N(k-1) + (1 - lam) J_N(k)`` where J_N(k) is finite, bias-corrected by
    ``1 - lam^count`` [chosen lam = 0.5]. Returns (raw, count, corrected costs; inf if count = 0).

    J_N(k) must be +inf at a step without a fresh observation (``predictive_costs`` with
    ``fresh``): the sum of one-step predictive log-likelihoods scores each reading once, and a
    step where no packet of stamp k arrived by time k has no reading to score. Scoring the
    placeholder fix there (z = 0, R = I) adds ``|p|^2 / S_N``, smallest for the horizon with the
    largest S, and drove the choice to N_min under heavy delay (q_0 = 0.3: no packet of the
    newest stamp in 0.7^8 = 6 % of steps). lam = 0.5 was chosen on seeds that the reported
    comparison does not use. The smoothed cost is the default nowhere: with ``mode_info="known"``
    and little delay it stays worse than the predictive one (+32 % MSE at the default delay of
    ``nlos_orbit``/``random_delay``): the two agree on straight legs, but the smoother cost reacts
    later when a turn begins and AHG's centre then moves at most h dN per step. Under heavy delay
    (q = 0.3, 0.25, 0.2, 0.15) it is within 2 % of the predictive cost with the mode known and
    better with it unknown; the numbers and the command are in docs/gao2016.md, section 7."""
    finite = np.isfinite(costs)
    raw = np.where(finite, lam * raw + (1.0 - lam) * np.where(finite, costs, 0.0), raw)
    count = count + finite
    corrected = np.where(count > 0, raw / np.where(count > 0, 1.0 - lam ** count, 1.0), np.inf)
    return raw, count, corrected


def ahg_group(params: AHGParams, centre: np.ndarray) -> np.ndarray:
    """H(k) = {clip(N_c + (i - (M+1)/2) dN, N_min, N_max) : i = 1..M}, shape (..., M) (step (a))."""
    offsets = (np.arange(1, params.group_size + 1) - (params.group_size + 1) // 2) * params.window_step
    # minimum(maximum(.)): np.clip's integers without its dispatch, which cost more than the arithmetic here
    return np.minimum(np.maximum(np.asarray(centre)[..., None] + offsets, params.window_min), params.window_max)


def ahg_select(params: AHGParams, centre: np.ndarray, costs: np.ndarray, valid: np.ndarray,
               fresh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Steps (b)-(d) of Algorithm 10 for every element: the horizon to output and the next centre.

    ``costs`` and ``valid`` (..., S) over horizons N = 1..S, ``fresh`` (...) gamma(k, 0).
    Returns ``(chosen, centre)`` where ``chosen`` is the horizon N whose estimate is output,
    or 0 when no member is valid (output the prediction A x_hat(k-1)). With a fresh
    observation and a finite cost: N* = argmin_N J_N over the group (ties: the first, i.e.
    the smallest N), next centre clip(N*, N_min + h dN, N_max - h dN). Otherwise the centre's
    estimate (or the largest valid member) and the centre is kept.
    """
    centre = np.asarray(centre)
    group = ahg_group(params, centre)
    idx = group - 1
    valid_g = np.take_along_axis(valid, idx, axis=-1)
    cost_g = np.where(valid_g, np.take_along_axis(costs, idx, axis=-1), np.inf)
    best = np.argmin(cost_g, axis=-1)
    best_cost = np.take_along_axis(cost_g, best[..., None], axis=-1)[..., 0]
    adapt = np.asarray(fresh, bool) & np.isfinite(best_cost)
    chosen_adapt = np.take_along_axis(group, best[..., None], axis=-1)[..., 0]
    lo, hi = params.window_min + params.half * params.window_step, params.window_max - params.half * params.window_step
    next_centre = np.where(adapt, np.clip(chosen_adapt, lo, hi), centre)
    centre_valid = np.take_along_axis(valid, (centre - 1)[..., None], axis=-1)[..., 0]
    largest_valid = np.max(np.where(valid_g, group, 0), axis=-1)
    chosen_hold = np.where(centre_valid, centre, largest_valid)
    return np.where(adapt, chosen_adapt, chosen_hold), next_centre


# --------------------------------------------------------------------------------------
# a whole episode on precomputed observations (scripts, tests, reproduction)
# --------------------------------------------------------------------------------------
def _predict_mean(motion: MotionModel, x: np.ndarray) -> np.ndarray:
    """A x for stacks of states (..., 4)."""
    T = float(motion.period)
    return np.stack([x[..., 0] + T * x[..., 2], x[..., 1] + T * x[..., 3], x[..., 2], x[..., 3]], axis=-1)


def run_fixed_mask(motion: MotionModel, fused_info, fused_vector, fused_success, truth_position,
                   prior_mean, params: AHGParams | None = None, stack_size: int = 30,
                   likelihoods: tuple = ("predictive",)) -> dict:
    """Run DFIR for every N = 1..``stack_size`` and AFGE for each ``likelihoods`` entry over one
    episode whose fused observations were precomputed by (stamp, lag) (a fixed packet selection).

    ``fused_*`` (..., K, D+1, ...), ``truth_position`` (..., K, 2), ``prior_mean`` (..., 4): the
    prior of x(0), the output of every estimator while it has no estimate of its own.
    Returns per-step squared position errors: ``dfir`` (..., K, S) (constant N = slot + 1),
    ``afge_<likelihood>`` (..., K) with ``afge_<likelihood>_horizon`` (..., K) and
    ``afge_<likelihood>_position`` (..., K, 2), and ``dfir_valid`` (..., K, S).
    """
    params = params or AHGParams()
    for name in likelihoods:
        if name not in LIKELIHOODS:
            raise ValueError(f"likelihood must be one of {LIKELIHOODS}, got {name!r}")
    batch = fused_success.shape[:-2]
    K = fused_success.shape[-2]
    final = empty_stack(batch, stack_size)
    prev_x = np.zeros((*batch, stack_size, 4))
    prev_P = np.broadcast_to(np.eye(4), (*batch, stack_size, 4, 4)).copy()
    prev_valid = np.zeros((*batch, stack_size), bool)
    prior_mean = np.broadcast_to(np.asarray(prior_mean, float), (*batch, 4))
    const_pred = np.broadcast_to(prior_mean[..., None, :], (*batch, stack_size, 4)).copy()
    out = {"dfir": np.empty((*batch, K, stack_size)), "dfir_valid": np.empty((*batch, K, stack_size), bool)}
    afge = {}
    for name in likelihoods:
        afge[name] = {"centre": np.full(batch, params.centre0), "pred": prior_mean.copy(),
                      "raw": np.zeros((*batch, stack_size)), "count": np.zeros((*batch, stack_size), np.int64)}
        out[f"afge_{name}"] = np.empty((*batch, K))
        out[f"afge_{name}_horizon"] = np.empty((*batch, K), np.int64)
        out[f"afge_{name}_position"] = np.empty((*batch, K, 2))
    for k in range(K):
        Yb, yb, gb, _ = buffer_observations(fused_info, fused_vector, fused_success, k)
        final, x, P, valid = buffer_estimates(motion, final, k, Yb, yb, gb)
        truth = truth_position[..., k, None, :]
        const_out = np.where(valid[..., None], x, const_pred)
        out["dfir"][..., k, :] = np.sum((const_out[..., :2] - truth) ** 2, axis=-1)
        out["dfir_valid"][..., k, :] = valid
        const_pred = _predict_mean(motion, const_out)
        fresh = gb[..., -1]
        z, R = fused_fix(Yb[..., -1, :, :], yb[..., -1, :], fresh)
        for name, st in afge.items():
            if name == "paper":
                costs = in_sample_costs(x, valid, z, R, fresh)
            else:
                costs = predictive_costs(motion, prev_x, prev_P, prev_valid, z, R, fresh=fresh)
                if name == "smoothed":
                    st["raw"], st["count"], costs = smooth_costs(st["raw"], st["count"], costs, params.smoothing)
            chosen, st["centre"] = ahg_select(params, st["centre"], costs, valid, fresh)
            picked = np.take_along_axis(x, np.maximum(chosen - 1, 0)[..., None, None], axis=-2)[..., 0, :]
            output = np.where((chosen > 0)[..., None], picked, st["pred"])
            st["pred"] = _predict_mean(motion, output)
            out[f"afge_{name}"][..., k] = np.sum((output[..., :2] - truth[..., 0, :]) ** 2, axis=-1)
            out[f"afge_{name}_horizon"][..., k] = chosen
            out[f"afge_{name}_position"][..., k, :] = output[..., :2]
        prev_x, prev_P, prev_valid = x, P, valid
    return out


def run_kalman(motion: MotionModel, fused_info, fused_vector, fused_success, truth_position, prior_mean,
               prior_cov, accel_var=None) -> np.ndarray:
    """Delay-aware Kalman filter on the same fused observations (§8): the posterior at
    k - D is kept and the last D stamps re-filtered each step; prior x(0) ~ N(``prior_mean``,
    ``prior_cov``). ``accel_var`` (scalar or (...)) is its sigma_a^2 (default: the model's).
    Returns the per-step squared position error (..., K)."""
    batch, K = fused_success.shape[:-2], fused_success.shape[-2]
    final = prior_stack(np.broadcast_to(np.asarray(prior_mean, float), (*batch, 4)), prior_cov)
    errors = np.empty((*batch, K))
    for k in range(K):
        Yb, yb, gb, _ = buffer_observations(fused_info, fused_vector, fused_success, k)
        final, x, _, _ = buffer_estimates(motion, final, k, Yb, yb, gb, shift=False, accel_var=accel_var,
                                          min_stamps=0)
        errors[..., k] = np.sum((x[..., 0, :2] - truth_position[..., k, :]) ** 2, axis=-1)
    return errors
