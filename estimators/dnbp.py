"""Dynamic nonparametric belief propagation (dNBP) for UAVs that lost GPS.

Wan J., Zhong L., Zhang F., "Cooperative localization of multi-UAVs via
dynamic nonparametric belief propagation under GPS signal loss condition",
Int. J. Distributed Sensor Networks, 2014 (seed ``003_44c6eab8acc44e0f.txt``).
The extracted text lost every equation: equation numbers are the paper's,
their content is reconstructed from its description. Values are tagged
**[paper]** (stated in the text) or **[chosen]** (chosen here where the paper
gives none).

Model. UAV s has state x = [p; v] in R^4; between slices

    x(k+1) = F x(k) + G a_hat(k) + w,  w ~ N(0, sigma_acc^2 G G^T)                     (1)

Within a slice the unknowns are the positions, with node and pair potentials

    psi_s(p_s)      = rho_s(p_s) [N(z_s; p_s, sigma_gps^2 I2) if GPS normal]            (3)
    psi_st(p_s,p_t) = N(d_st; ||p_s - p_t||, sigma_d^2),  (s, t) in E                   (4)-(5)

and BP messages and beliefs (eqs. 8-9)

    m_ts(p_s) ∝ ∫ psi_st(p_s, p_t) psi_t(p_t) prod_{u in Gamma_t \\ s} m_ut(p_t) dp_t
    B_t(p_t)  ∝ psi_t(p_t) prod_{u in Gamma_t} m_ut(p_t)

so the sender's part of (8) is B_t / m_st (Ihler et al. 2005).

Nonparametric representation. A belief is M equally weighted particles in
R^4; a message m_ts is a 2-D Gaussian mixture of M centres, log-weights and
one isotropic bandwidth h_ts; a GPS fix is the one-component message
{z_s, 1, sigma_gps} (stored as M identical components).

* ``sample_messages`` — Algorithm 1. Weights w_i ∝ 1/m_st(p_t^i) when
  the reverse message exists on a fault<->fault link, else 1/M; stratified
  directions theta_i = 2 pi (pi_i + U_i)/M; centres
  c_i = p_t^i + (d_ts + nu_i)[cos theta_i, sin theta_i]; bandwidth
  h_ts = max(sqrt(h_rot(p_t, w)^2 + (pi d_ts / M)^2), 0.5 m) [chosen].
* ``belief_update`` — Algorithm 2, mixture importance sampling: proposal
  q = (rho + sum_u m_u)/(K+1) with ceil(k_is M/(K+1)) draws per component,
  weights pi/q in the log domain, systematic resampling to M, jitter
  N(0, h_rot^2 I2) (regularised resampling [chosen]) and velocity completion
  from the prior's conditional v | p [chosen].
* ``predict`` — Algorithm 3: x_i <- F x_i + G (a_hat + e_i),
  e_i ~ N(0, sigma_acc^2 I2); the forward message rho is the position KDE
  (bandwidth h_rho = h_rot) mixed with a defensive uniform:
  rho = (1 - eps) KDE + eps U(box) [chosen].
* ``step`` — Algorithm 4, one time step with the message schedule of the
  paper's Sec. 3.4 or the parallel schedule for the ablation.

Rule-of-thumb bandwidth [chosen form]: h_rot = sigma_hat ESS^(-1/6) with
sigma_hat^2 the weighted variance averaged over the two axes and
ESS = 1 / sum w_i^2 (Silverman, d = 2).

Noise parameters are standard deviations (``DnbpModel``'s sigma_acc,
sigma_gps, sigma_d; ``initial_state``'s ``velocity_std``), not the variances
the other estimators take: the particle draws and kernel bandwidths use them
as they are.

Array conventions: B copies (runs), N UAVs, M particles. ``prior`` and
``belief`` are (B, N, M, 4). A step's messages live in a pool of the
messages delivered in it, each receiver holding a slot table (slot t: the
message from t; slot N: its GPS fix), so memory and writes grow with the
messages, not with B N^2 M. All arithmetic is vectorized over copies,
particles and messages; what remains a Python loop over copies is only the
drawing of random numbers, one block per copy and purpose from that copy's
own generator, so that copy b of a batch is bit-identical to the same copy
run alone. Large kernel evaluations (proposals x mixture components) are
chunked to bound memory.

Compiled kernels. ``belief_update`` (Algorithm 2, where nearly all the time
goes) runs as two fused numba kernels, one receiver per iteration: proposals
and importance log-weights (``dnbp_kernels.belief_weights_source``: the prior's KDE and
every present message evaluated at each proposal, no (R, S, C, M)
temporaries), then normalization, systematic resampling, jitter and velocity
completion (``dnbp_kernels.belief_resample_source``). They reproduce the numpy path's
arithmetic in its order: the same exponents, numpy's pairwise sum for the
weight normalization, the flat-offset comparisons of ``_categorical`` (by
bisection or a merge instead of a scan: the same counts), so they make the
same draws; the particles equal the numpy path's to ~1e-13 m (the einsum of
h_rot sums in another order). A GPS fix (M identical components) is
evaluated once per point and added M times (the same sum). The other hot
loops (the mixture kernel of the correction weights and, on the numpy path,
the fast kernel, the velocity draw and the importance-weight combination)
are compiled per row and run on numba's threads above
``dnbp_kernels.PARALLEL_ELEMENTS`` kernel entries. The fused kernels run on one thread
per call or, from 4 receivers and 2^20 kernel entries, on slices of the
receivers run by worker threads (``dnbp_kernels.split_rows``: Python threads, the
kernels release the GIL; as many as the cores and NUMBA_NUM_THREADS, so
NUMBA_NUM_THREADS=1 runs one thread), each slice given its first row for the
flat offsets, so the bits are the whole call's. Algorithm 1's centres and
h_rot sums are one compiled pass too (``dnbp_kernels.message_rows_source``): the numpy
path's floats, since numpy's cos and sin are libm's and the sums keep
einsum's and the pairwise sum's orders; numpy's exp, log and pow are not
libm's (its AVX-512 loops round differently), so what needs them stays
numpy. numba's own threaded form of the fused kernels (``dnbp_kernels.FUSED_THREADS``)
is off: its waiting threads spin, which slows a machine whose other core is
busy. A row (receiver) reads only its own inputs, so the results depend
neither on the batch nor on the thread count. The numpy formulations stay
(``compiled=False``; also used where numba is not installed) and are what
the compiled kernels are tested against: equal up to float rounding (~1e-10
in a log density at kilometre coordinates); seeded episodes agree to 1e-9.
Timings, and the alternatives measured and not kept, are in
``docs/performance.md`` ("dNBP kernels").

Kernels (``DnbpModel.kernel``). ``"exact"`` (this module's default) is the
path above, bit for bit. ``"truncated"`` (the default of the ``dnbp``
backend and the ``gps_denied_nbp`` env; pass ``kernel="exact"`` for the
exact path) is an approximation of the compiled belief update and correction
weights (the numpy path is the exact one): at each point a mixture's terms
more than r^2/2 below the point's largest exponent are left out
(r = ``truncation``, 6 by default, in [1, 10]; with equal weights: every
component more than ~r bandwidths farther than the nearest; the exact
kernel's cut is 50, r = 10), the rest summed relative to the largest with a
branch-free polynomial exp (``dnbp_kernels.exp_small``, relative error < 1e-12 on
[-50, 0]) in fastmath loops that LLVM vectorizes (numba without SVML calls
libm's exp one term at a time), a GPS fix's K equal terms as K e^a (the
exact kernel adds e^a K times, for numpy's bits); the velocity completion
drops prior particles below e^(-r^2/2) of the largest weight the same way;
and a proposal is left out (weight 0) as soon as its weight is certainly
below e^(-r^2/2) / C of the best one so far (its unevaluated messages
bounded by their peak density sum_k w_k / (2 pi h^2), q by any evaluated
term / (K+1)), so proposals deep in one message's tail skip the other
messages. Bounds: each left-out term is < e^(-r^2/2) of the largest (1.5e-8
at r = 6), a log density moves by < K e^(-r^2/2) (1.5e-6 at K = 100), the
proposals left out carry < e^(-r^2/2) of the normalized weight together
(plus float rounding: ~1e-10 in a log density at kilometre coordinates, as
in the exact fast kernel). At r = 3 or 1 the episodes part by metres from
the first step. How closely the truncated kernel follows the exact one on
wan2014's points, and how much faster it is, is measured in
``docs/performance.md`` ("dNBP kernels").

Messages of fault senders (``DnbpModel.fault_message_power`` alpha, [chosen]).
On the loopy graph of the fault UAVs, a fault sender's belief already holds
what its receiver holds: the rings of the GPS-normal UAVs both hear, and the
receiver's own earlier messages relayed through a third UAV (Algorithm 1's
reverse-message correction removes only the direct echo). Taken at full
weight over the iterations, this information is counted again and again and
the beliefs grow overconfident (measured in docs/consistency.md, "wan2014:
dNBP and range_ls covariances", against one iteration, which sends no
fault -> fault message). A message of a GPS-faulty sender therefore enters
every product as m^alpha, a fractional BP message (Wiegerinck and Heskes
2003, "Fractional belief propagation"; for Gaussians, the information of the
message scaled by alpha, as covariance intersection weighs a source whose
correlation with the others is unknown). It is
done on the message's kernel: a ring's radial profile is about Gaussian with
variance h^2 + sigma_d^2 + sigma_t^2 (kernel, range noise, the sender's
position variance), and raising it to alpha multiplies that variance by
1/alpha, so

    h'^2 = h^2 + (1/alpha - 1) (h^2 + sigma_d^2 + sigma_t^2)              (``temper_bandwidth``)

(the ring's angular profile is widened too, which leaves a uniform ring as
it is). The reverse-message correction then divides by the tempered message,
as fractional BP does. alpha = 1 is the paper's algorithm; the default 0.5
was measured, with 0.35, 0.25 and 1, in docs/consistency.md (smaller alphas
leave the fault UAVs' lost-track tail and widen the rest, at a cost in
accuracy).

Reported covariance (``coloc_env.backends.particles.DnbpBackend.position_cov``):
the covariance of the density the belief particles stand for. A belief that
Algorithm 2 resampled is M draws of the regularized posterior
sum_j w_j N(p; p_j, h_rot^2 I2) (the jitter is its kernel), so the particles'
sample covariance estimates its covariance, kernel included:
Cov = (1/M) sum_i (p_i - p_bar)(p_i - p_bar)^T. A belief that is its prior's
particle set (a fault UAV that heard nobody) stands for the prior's KDE,
whose covariance adds the kernel: Cov + h_rho^2 I2.

Departures from the reconstruction
----------------------------------
* A GPS-faulty sender's message is tempered (alpha above); the paper's
  algorithm is alpha = 1.
* Velocity completion draws the prior particle j by inverse-CDF sampling of
  the categorical law p(j | p) ∝ exp(-||p - x_j||^2 / (2 h_rho^2)) (one
  uniform per new particle, not M Gumbels as Gumbel-max would use): the same
  distribution, M times fewer random numbers. The defensive uniform part of
  rho carries no velocity, so only the KDE part is used for v | p.
* A fault UAV's belief at the start of a step is its prior particle set
  itself (equally weighted), not a resample of it, which has the same law.
* If every importance weight of a receiver underflows (messages that do not
  overlap at all), its belief stays as it was; this did not occur at the
  defaults, it protects against inconsistent inputs.
* A UAV counts as broadcasting only when its broadcast reaches at least one
  eligible receiver (``coloc_env``'s medium counts the same way).
  Delivery itself is the caller's network (the ``deliver`` argument of
  ``step``); the estimator only decides who may send and who listens.
* In the parallel schedule the reverse-message correction is still applied
  to fault<->fault links only (the correction of Algorithm 1 is stated for
  every schedule).
* Kernel sums: exponents below -600 are clipped before ``exp`` (libm is ~10x
  slower on underflowing results), so a mixture whose every component is
  more than ~35 bandwidths away counts as density 0 there. Importance weights
  are first computed with the fast kernel of ``mixture_logpdf``; a
  receiver whose every weight vanishes is recomputed in the exact log domain.
  The compiled kernels also leave out of a sum the terms below e^-50 of its
  largest term (K of them change it by < K e^-50 ~ 1e-20, relative), except
  in a row whose largest exponent is within 50 of the floor, where every term
  counts as in the numpy kernel; in the velocity completion a prior particle
  whose weight is below e^-50 of the largest gets probability 0 (the numpy
  path floors it at e^-600 of the largest): either moves the CDF by less
  than its float64 resolution.
  A correction weight 1/m_st(p) at a particle where m_st is 0 is capped at the
  largest finite correction weight of that message.

Noticed, not changed: the regularization jitter h_rot = sigma_hat ESS^(-1/6)
(Algorithm 2's regularised resampling) uses a Gaussian reference, so a ring
or two-mode belief is thickened by a sizeable fraction of its radius (about
40 m for a 150 m ring at M = 400); unimodal tracking beliefs are not
affected (h_rot ~ 1 m).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from estimators import dnbp_kernels
from estimators.cv_models import ConstantVelocityAccel
from estimators.dnbp_kernels import EXP_FLOOR
from estimators.models import per_copy

__all__ = [
    "Deliver",
    "DnbpModel",
    "DnbpState",
    "StepResult",
    "rule_of_thumb_bandwidth",
    "mixture_logpdf",
    "prior_logpdf",
    "sample_messages",
    "temper_bandwidth",
    "belief_update",
    "fault_senders",
    "initial_state",
    "predict",
    "step",
]

# deliver(senders (B, N), listening (B, N, N)) -> delivered (B, N, N): the caller's network (see ``step``)
Deliver = Callable[[np.ndarray, np.ndarray], np.ndarray]
Propagate = Callable[[np.ndarray, Sequence[np.random.Generator]], np.ndarray]

# The mixture kernels of the belief update (DnbpModel.kernel) and the truncation radius r allowed, in bandwidths
# (r = 10 leaves out what the exact kernel leaves out: terms below e^-50 of the largest)
KERNELS = ("exact", "truncated")
TRUNCATION_RANGE = (1.0, 10.0)

_CHUNK_ELEMENTS = 1 << 16  # kernel entries per chunk (512 kB): stays in cache, bounds memory at any batch


@dataclass(frozen=True)
class DnbpModel:
    """Parameters of dNBP (the model, the representation and the schedule of the module docstring).

    | field              | symbol        | default | tag / meaning                                       |
    |--------------------|---------------|---------|-----------------------------------------------------|
    | dt                 | Delta t       | 1 s     | [chosen]                                            |
    | accel_noise_std    | sigma_acc     | 0.3     | [chosen] accelerometer noise, m/s^2                 |
    | gps_std            | sigma_gps     | 3 m     | [chosen]                                            |
    | range_std          | sigma_d       | 2 m     | [chosen]                                            |
    | num_particles      | M             | 100     | [chosen]; ~3 m error at 300 samples [paper]         |
    | num_iterations     | n_iter        | 5       | [chosen]; the case study needs 3 [paper]            |
    | oversampling       | k_is          | 2       | [chosen] k_is M proposals                           |
    | defensive_weight   | eps_def       | 0.01    | [chosen]                                            |
    | defensive_box      | (low, high)   | (-150, 1250) | [chosen] per axis: [-150, area+150+|v|dt T]    |
    | cold_box           | (low, high)   | (-150, 650)  | [chosen] cold-start "no knowledge" box         |
    | min_bandwidth      | h_min         | 0.5 m   | [chosen] floor of h_ts                              |
    | initial_threshold  | theta_0       | 3       | [paper] "at least three incoming messages"          |
    | schedule           |               | modified| [paper] Sec. 3.4; "parallel" for the ablation       |
    | kernel             |               | exact   | "exact" or "truncated" (approximate, faster;        |
    |                    |               |         | the module's Kernels note)                          |
    | truncation         | r             | 6       | [chosen] [1, 10] bandwidths, the truncated kernel's |
    |                    |               |         | cut: terms below e^(-r^2/2) of the largest left out |
    | fault_message_power| alpha         | 0.5     | [chosen] (0, 1]: a GPS-faulty sender's message      |
    |                    |               |         | enters as m^alpha (fractional BP; the module's      |
    |                    |               |         | "Messages of fault senders"); 1 = the paper's       |

    ``accel_noise_std``, ``gps_std`` and ``range_std`` are standard deviations (sigma), not the variances the
    other estimators take. Each is one float for every copy, or a (B,) array of one value per copy (copies whose
    noise differs, e.g. replays of different stretches of a recording); ``estimators.models.per_copy`` reads
    either.
    """

    dt: float = 1.0
    accel_noise_std: float = 0.3
    gps_std: float = 3.0
    range_std: float = 2.0
    num_particles: int = 100
    num_iterations: int = 5
    oversampling: int = 2
    defensive_weight: float = 0.01
    defensive_box: tuple[float, float] = (-150.0, 1250.0)
    cold_box: tuple[float, float] = (-150.0, 650.0)
    min_bandwidth: float = 0.5
    initial_threshold: int = 3
    schedule: str = "modified"
    kernel: str = "exact"
    truncation: float = 6.0
    fault_message_power: float = 0.5

    def __post_init__(self):
        if self.schedule not in ("modified", "parallel"):
            raise ValueError(f"schedule must be 'modified' or 'parallel', got {self.schedule!r}")
        if self.kernel not in KERNELS:
            raise ValueError(f"kernel must be 'exact' or 'truncated', got {self.kernel!r}")
        low, high = TRUNCATION_RANGE
        if not low <= self.truncation <= high:
            raise ValueError(f"truncation must be in [{low:g}, {high:g}] bandwidths, got {self.truncation!r}")
        for name in ("defensive_box", "cold_box"):
            low, high = getattr(self, name)
            if not high > low:
                raise ValueError(f"{name} must be (low, high) with high > low, got {(low, high)}")
        if not 0.0 < self.fault_message_power <= 1.0:
            raise ValueError(f"fault_message_power must be in (0, 1], got {self.fault_message_power!r}")
        if self.num_particles < 2 or self.num_iterations < 1 or self.oversampling < 1:
            raise ValueError("num_particles >= 2, num_iterations >= 1 and oversampling >= 1 are required")

    @property
    def motion(self) -> ConstantVelocityAccel:
        """The constant-velocity model of Algorithm 3 (wan2014 eq. 1) in the shape of ``estimators.cv_models``."""
        return ConstantVelocityAccel(self.dt, self.accel_noise_std**2)

    @property
    def transition(self) -> np.ndarray:
        return self.motion.transition

    @property
    def input_matrix(self) -> np.ndarray:
        return self.motion.input_matrix

    @property
    def proposal_capacity(self) -> int:
        """Upper bound of (K+1) ceil(k_is M / (K+1)) over K: k_is M + K with K < this bound's slack."""
        return self.oversampling * self.num_particles + 64


@dataclass
class DnbpState:
    """Per-UAV particle sets of the current slice.

    ``prior`` (B, N, M, 4): particles of the forward-time message rho_s;
    ``prior_bandwidth`` (B, N): its KDE bandwidth h_rho; ``prior_uniform``
    (B, N): rho_s is the cold-start box (no knowledge) instead of a KDE;
    ``belief`` (B, N, M, 4): the latest belief B_s (equal to ``prior`` before
    the first intraslice update); ``estimate`` (B, N, 2): belief means.
    """

    prior: np.ndarray
    prior_bandwidth: np.ndarray
    prior_uniform: np.ndarray
    belief: np.ndarray
    estimate: np.ndarray


@dataclass
class StepResult:
    """What one time step did, for metrics, observations and rendering.

    ``delivered`` (B, n_iter, N, N): [b, n, t, s] message t -> s in iteration n;
    ``broadcasts`` (B, N): broadcasts of each UAV in the step;
    ``received`` (B, N): distinct senders each UAV heard from;
    ``history``: belief particles (B, N, M, 4) after each iteration when recorded.
    """

    estimate: np.ndarray
    belief: np.ndarray
    delivered: np.ndarray
    broadcasts: np.ndarray
    received: np.ndarray
    history: list[np.ndarray] = field(default_factory=list)


# --- densities -----------------------------------------------------------------------------------------------------
def rule_of_thumb_bandwidth(points: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """h_rot = sigma_hat ESS^(-1/6) of weighted 2-D points (..., P, 2); weights (..., P) sum to 1."""
    points = np.asarray(points, float)
    if weights is None:
        weights = np.full(points.shape[:-1], 1.0 / points.shape[-2])
    mean = np.einsum("...p,...pd->...d", weights, points)
    var = np.einsum("...p,...pd->...", weights, (points - mean[..., None, :]) ** 2) / 2.0
    ess = 1.0 / np.sum(weights**2, axis=-1)
    return np.sqrt(np.maximum(var, 0.0)) * ess ** (-1.0 / 6.0)




def _logsumexp(a: np.ndarray, axis: int) -> np.ndarray:
    top = np.max(a, axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    shifted = np.maximum(a - top, EXP_FLOOR)
    shifted = np.where(np.isneginf(a), -np.inf, shifted)
    with np.errstate(divide="ignore"):
        return np.log(np.sum(np.exp(shifted), axis=axis)) + np.squeeze(top, axis=axis)



def mixture_logpdf(points: np.ndarray, centres: np.ndarray, log_weights: np.ndarray,
                   bandwidth: np.ndarray, exact: bool = True, compiled: bool = True) -> np.ndarray:
    """log sum_i w_i N(p; c_i, h^2 I2) for J mixtures at their own points.

    points (J, P, 2), centres (J, K, 2), log_weights (J, K) (normalized),
    bandwidth (J,) -> (J, P), chunked over J.

    ``exact=True`` evaluates in the log domain (log-sum-exp). ``exact=False``
    is the fast kernel: the exponent log w_i - ||p - c_i||^2 / (2 h^2) is
    formed as one batched matrix product (||p||^2 + ||c||^2 - 2 p.c, in
    float64: the cancellation costs ~1e-10 in the log density at kilometre
    coordinates) and summed in the linear domain. Every exponent is <= 0, so
    nothing overflows; a point farther than ~38 bandwidths from every
    component (density below ~K e^-600) counts as log 0 = -inf, which the
    callers treat (see ``belief_update``).

    ``compiled`` (fast kernel only): run it as one compiled pass per point
    (numba, threads over points), which forms the same exponents, takes the
    row's largest first and leaves out of the sum the terms more than 50
    below it (together < K e^-50 relative: below float64 resolution); the
    results equal the numpy kernel (``compiled=False``, also used where numba
    is missing) up to float rounding (the BLAS product rounds its dot product
    once more or less, ~1e-10 absolute in the log density at kilometre
    coordinates, like the cancellation itself).
    """
    points, centres = np.asarray(points, float), np.asarray(centres, float)
    J, P, K = points.shape[0], points.shape[1], centres.shape[1]
    h = np.asarray(bandwidth, float)
    out = np.empty((J, P))
    per = max(1, _CHUNK_ELEMENTS // max(1, P * K))
    log_norm = np.log(2.0 * np.pi * h**2)[:, None]
    if not exact:
        inv = 1.0 / h**2
        scaled = points * inv[:, None, None]
        point_term = -0.5 * np.sum(points**2, axis=-1) * inv[:, None]
        centre_term = log_weights - 0.5 * np.sum(centres**2, axis=-1) * inv[:, None]
        kernel = dnbp_kernels.row_kernel("mixture_rows", J * P * K) if compiled else None
        if kernel is not None and J * P:
            kernel(scaled, point_term, np.ascontiguousarray(centres), centre_term, log_norm[:, 0], out)
            return out
        transposed = np.swapaxes(centres, 1, 2)
        for lo in range(0, J, per):
            sl = slice(lo, min(J, lo + per))
            a = np.matmul(scaled[sl], transposed[sl])
            a += point_term[sl, :, None]
            a += centre_term[sl, None, :]
            np.clip(a, EXP_FLOOR, 0.0, out=a)  # the exact exponent is <= 0; the floor keeps exp fast
            np.exp(a, out=a)
            total = np.sum(a, axis=-1)
            # every component at the floor (each contributes e^-600): the density is below ~K e^-600, counted as 0
            with np.errstate(divide="ignore"):
                out[sl] = np.where(total > 2.0 * K * np.exp(EXP_FLOOR), np.log(total), -np.inf)
        return out - log_norm
    for lo in range(0, J, per):
        sl = slice(lo, min(J, lo + per))
        inv = (0.5 / h[sl] ** 2)[:, None, None]
        dx = points[sl, :, None, 0] - centres[sl, None, :, 0]
        dy = points[sl, :, None, 1] - centres[sl, None, :, 1]
        a = log_weights[sl, None, :] - (dx * dx + dy * dy) * inv
        out[sl] = _logsumexp(a, axis=-1)
    return out - log_norm


def _inside(points: np.ndarray, box: tuple[float, float]) -> np.ndarray:
    return np.all((points >= box[0]) & (points <= box[1]), axis=-1)


def prior_logpdf(model: DnbpModel, points: np.ndarray, particles: np.ndarray, bandwidth: np.ndarray,
                 uniform: np.ndarray, exact: bool = True) -> np.ndarray:
    """log rho(p) (Algorithm 3's forward message) at points (J, P, 2) for priors with particles (J, M, 2).

    rho = (1 - eps) KDE(h_rho) + eps U(defensive box), or U(cold box) where ``uniform``.
    """
    J, P = points.shape[:2]
    out = np.empty((J, P))
    uniform = np.asarray(uniform, bool)
    lo_c, hi_c = model.cold_box
    out[uniform] = np.where(_inside(points[uniform], model.cold_box), -2.0 * np.log(hi_c - lo_c), -np.inf)
    kde_rows = ~uniform
    if kde_rows.any():
        M = particles.shape[1]
        kde = mixture_logpdf(points[kde_rows], particles[kde_rows], np.full((int(kde_rows.sum()), M), -np.log(M)),
                             bandwidth[kde_rows], exact)
        eps = model.defensive_weight
        lo, hi = model.defensive_box
        with np.errstate(divide="ignore"):
            log_u = np.where(_inside(points[kde_rows], model.defensive_box),
                             np.log(eps) - 2.0 * np.log(hi - lo), -np.inf)
            out[kde_rows] = np.logaddexp(np.log1p(-eps) + kde, log_u)
    return out


# --- systematic / categorical draws by one flat searchsorted ----------------------------------------------------
def _categorical(cdf: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Row-wise inverse-CDF draws: cdf (R, K) non-decreasing ending at 1, u (R, S) in [0, 1) -> (R, S) indices.

    One ``searchsorted`` on the rows laid end to end with offsets 0, 1, 2, ...
    """
    R, K = cdf.shape
    offset = np.arange(R, dtype=float)[:, None]
    flat = (cdf + offset).ravel()
    idx = np.searchsorted(flat, (u + offset).ravel(), side="right").reshape(u.shape)
    return np.clip(idx - np.arange(R)[:, None] * K, 0, K - 1)


def _normalized_cdf(log_weights: np.ndarray) -> np.ndarray:
    """CDF rows (..., K) from log-weights; rows without mass become uniform."""
    top = np.max(log_weights, axis=-1, keepdims=True)
    ok = np.isfinite(top)
    w = np.exp(np.maximum(log_weights - np.where(ok, top, 0.0), EXP_FLOOR))
    w = np.where(ok & ~np.isneginf(log_weights), w, np.where(ok, 0.0, 1.0))
    cdf = np.cumsum(w, axis=-1)
    cdf /= cdf[..., -1:]
    cdf[..., -1] = 1.0
    return cdf


# --- Algorithm 1 -------------------------------------------------------------------------------------------------
def sample_messages(model: DnbpModel, sender_points: np.ndarray, distance: np.ndarray,
                    correction_log_weights: np.ndarray | None, permutation: np.ndarray, offset: np.ndarray,
                    range_noise: np.ndarray, compiled: bool = True, range_std: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Algorithm 1 for E messages t -> s.

    sender_points (E, M, 2): t's belief positions; distance (E,): d_ts;
    correction_log_weights (E, M): log w_i (normalized; None = uniform);
    permutation (E, M) a permutation of 0..M-1 per row, offset (E, M) U[0,1),
    range_noise (E, M) standard normal; range_std (E,) sigma_d of each
    message (None: ``model.range_std``, one float). Returns centres (E, M, 2),
    log-weights (E, M), bandwidths (E,). ``compiled`` (default, where numba
    is installed): the centres and h_rot's sums by one compiled pass
    (``dnbp_kernels.message_rows_source``), the same floats as the numpy path (False).
    """
    E, M = sender_points.shape[:2]
    range_std = per_copy("range_std", model.range_std if range_std is None else range_std, E)
    if correction_log_weights is None:
        correction_log_weights = np.full((E, M), -np.log(M))
    kernels = dnbp_kernels.fused_kernels() if compiled else None
    if kernels is not None and E:
        centres, var, square_sum = np.empty((E, M, 2)), np.empty(E), np.empty(E)
        kernels["messages"](np.ascontiguousarray(sender_points, float), np.ascontiguousarray(distance, float),
                            np.exp(correction_log_weights), np.ascontiguousarray(permutation),
                            np.ascontiguousarray(offset, float), np.ascontiguousarray(range_noise, float),
                            range_std, centres, var, square_sum)
        h_rot = np.sqrt(np.maximum(var, 0.0)) * (1.0 / square_sum) ** (-1.0 / 6.0)  # rule_of_thumb_bandwidth's
        bandwidth = np.maximum(np.sqrt(h_rot**2 + (np.pi * distance / M) ** 2), model.min_bandwidth)
        return centres, correction_log_weights, bandwidth
    theta = 2.0 * np.pi * (permutation + offset) / M
    radius = distance[:, None] + range_std[:, None] * range_noise
    centres = sender_points + radius[..., None] * np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    h_rot = rule_of_thumb_bandwidth(sender_points, np.exp(correction_log_weights))
    bandwidth = np.maximum(np.sqrt(h_rot**2 + (np.pi * distance / M) ** 2), model.min_bandwidth)
    return centres, correction_log_weights, bandwidth


def temper_bandwidth(bandwidth: np.ndarray, sender_points: np.ndarray, correction_log_weights: np.ndarray | None,
                     tempered: np.ndarray, alpha: float, range_std: np.ndarray) -> np.ndarray:
    """The bandwidths (E,) of E messages with those where ``tempered`` (E,) raised to the power alpha (the module's
    "Messages of fault senders"): h'^2 = h^2 + (1/alpha - 1) (h^2 + sigma_d^2 + sigma_t^2), so the ring's radial
    variance h^2 + sigma_d^2 + sigma_t^2 grows by 1/alpha, as for a Gaussian profile raised to alpha.
    sender_points (E, M, 2), correction_log_weights (E, M) or None (uniform), range_std (E,) sigma_d;
    sigma_t^2 is the sender's weighted position variance averaged over the two axes (h_rot's sigma_hat^2)."""
    E, M = sender_points.shape[:2]
    weights = np.full((E, M), 1.0 / M) if correction_log_weights is None else np.exp(correction_log_weights)
    mean = np.einsum("em,emd->ed", weights, sender_points)
    spread = np.einsum("em,emd->e", weights, (sender_points - mean[:, None, :]) ** 2) / 2.0
    radial = bandwidth**2 + np.asarray(range_std, float) ** 2 + spread
    return np.where(tempered, np.sqrt(bandwidth**2 + (1.0 / alpha - 1.0) * radial), bandwidth)


def correction_weights(sender_points: np.ndarray, reverse_centres: np.ndarray, reverse_log_weights: np.ndarray,
                       reverse_bandwidth: np.ndarray, truncation: float = 0.0) -> np.ndarray:
    """log w_i ∝ -log m_st(p_t^i), normalized (Alg. 1 step 1, Ihler's double-counting correction).

    ``truncation`` r > 0: m_st by the truncated kernel (the module's Kernels note) where numba is installed;
    0 (default): the fast kernel of ``mixture_logpdf``."""
    kernels = dnbp_kernels.fused_kernels() if truncation > 0.0 else None
    if kernels is not None:
        centres = np.asarray(reverse_centres, float)
        h = np.asarray(reverse_bandwidth, float)
        inv = 1.0 / h**2
        cx, cy = np.ascontiguousarray(centres[..., 0]), np.ascontiguousarray(centres[..., 1])
        centre_term = np.ascontiguousarray(reverse_log_weights - 0.5 * (cx * cx + cy * cy) * inv[:, None])
        log_m = np.empty(np.shape(sender_points)[:2])
        points = np.ascontiguousarray(sender_points, float)
        elements = points.shape[0] * points.shape[1] * cx.shape[1]
        which = 1 if dnbp_kernels.FUSED_THREADS and elements >= dnbp_kernels.FUSED_THREAD_ELEMENTS else 0
        kernel, log_norm, limit = kernels["mixture_truncated"][which], np.log(2.0 * np.pi * h**2), 0.5 * truncation**2

        def rows(a: int, b: int) -> None:  # messages a..b-1 (each row reads only its own inputs)
            kernel(points[a:b], cx[a:b], cy[a:b], centre_term[a:b], inv[a:b], log_norm[a:b], limit, log_m[a:b])

        dnbp_kernels.split_rows(rows, len(points), 1 if which else dnbp_kernels.split_pieces(len(points), elements))
    else:
        log_m = mixture_logpdf(sender_points, reverse_centres, reverse_log_weights, reverse_bandwidth, exact=False)
    log_w = -log_m
    finite = np.isfinite(log_w)
    if not finite.all():  # a 1/m_st at a zero of m_st: capped at the largest finite one
        cap = np.nanmax(np.where(finite, log_w, -np.inf))
        log_w = np.where(finite, log_w, cap)
        if not np.isfinite(cap):
            return log_w - _logsumexp(log_w, axis=-1)[:, None]
    # every weight finite: _logsumexp's arithmetic without its guards for infinities
    top = np.max(log_w, axis=-1, keepdims=True)
    shifted = np.subtract(log_w, top)
    np.maximum(shifted, EXP_FLOOR, out=shifted)
    np.exp(shifted, out=shifted)
    total = np.log(np.sum(shifted, axis=-1))
    total += top[:, 0]
    log_w -= total[:, None]
    return log_w


# --- Algorithm 2 -------------------------------------------------------------------------------------------------
def belief_update(model: DnbpModel, prior: np.ndarray, prior_bandwidth: np.ndarray, prior_uniform: np.ndarray,
                  centres: np.ndarray, log_weights: np.ndarray, bandwidth: np.ndarray, present: np.ndarray,
                  draws: dict[str, np.ndarray], compiled: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 2 (mixture importance sampling) for R receivers.

    prior (R, M, 4), prior_bandwidth (R,), prior_uniform (R,); incoming
    messages padded to S slots: centres (R, S, K, 2), log_weights (R, S, K),
    bandwidth (R, S), present (R, S). ``draws`` (see ``draw_belief``):
    ``pick`` (R, C) and ``box`` (R, C, 3) uniforms, ``noise`` (R, C, 2)
    normals with C = ``DnbpModel.proposal_capacity``, ``resample`` (R,),
    ``jitter`` (R, M, 2), ``velocity`` (R, M). Returns the new particles
    (R, M, 4) and a bool (R,) that is False where every weight underflowed
    (the prior is kept there). ``compiled`` (default): the fused numba kernels
    where numba is installed (see the module's "Compiled kernels"); False: the numpy
    path they are tested against.
    """
    R, M = prior.shape[:2]
    S = present.shape[1]
    K_r = present.sum(axis=1)
    per_comp = -(-model.oversampling * M // (K_r + 1))  # ceil(k_is M / (K+1))
    total = per_comp * (K_r + 1)
    if np.any(total > model.proposal_capacity):
        raise ValueError(f"too many incoming messages for the proposal capacity {model.proposal_capacity}")
    C = int(total.max())  # the draws have the fixed capacity; only the first C columns are used
    kernels = dnbp_kernels.fused_kernels() if compiled else None
    if kernels is not None and R:
        return _belief_update_fused(kernels, model, prior, prior_bandwidth, prior_uniform, centres, log_weights,
                                    bandwidth, present, draws, K_r, total, C)
    j = np.arange(C)[None, :]
    valid = j < total[:, None]
    rank = np.minimum(j // per_comp[:, None], K_r[:, None])  # 0 = prior, k = k-th present message
    with_prior = np.concatenate([np.ones((R, 1), bool), present], axis=1)
    order = np.argsort(~with_prior, axis=1, kind="stable")
    slot = np.take_along_axis(order, rank, axis=1)  # (R, C): 0 = prior, 1 + s = message slot s
    rows = np.arange(R)[:, None]

    # proposals from the prior (KDE + defensive uniform, or the cold box)
    pick, box, noise = draws["pick"][:, :C], draws["box"][:, :C], draws["noise"][:, :C]
    j_prior = np.minimum((pick * M).astype(int), M - 1)
    from_kde = prior[rows, j_prior, :2] + prior_bandwidth[:, None, None] * noise
    lo, hi = model.defensive_box
    defensive = lo + (hi - lo) * box[..., 1:]
    lo_c, hi_c = model.cold_box
    cold = lo_c + (hi_c - lo_c) * box[..., 1:]
    from_prior = np.where(prior_uniform[:, None, None], cold,
                          np.where((box[..., 0] < model.defensive_weight)[..., None], defensive, from_kde))
    # proposals from the messages: component by inverse CDF, then the kernel
    msg_slot = np.maximum(slot - 1, 0)
    cdf = _normalized_cdf(log_weights).reshape(R * S, -1)
    # each proposal reads the CDF row of its own (receiver, slot) pair: rows laid end to end, one searchsorted
    flat_pair = (rows * S + msg_slot).ravel()
    K = cdf.shape[1]
    flat = (cdf + np.arange(R * S, dtype=float)[:, None]).ravel()
    comp = np.searchsorted(flat, flat_pair + pick.ravel(), side="right") - flat_pair * K
    comp = np.clip(comp, 0, K - 1).reshape(R, C)
    from_msg = centres[rows, msg_slot, comp] + bandwidth[rows, msg_slot][..., None] * noise
    proposals = np.where((slot == 0)[..., None], from_prior, from_msg)

    # weights pi / q in the log domain; fast kernels first, the exact log-sum-exp only for a receiver
    # whose every weight vanished (all its proposals > ~38 bandwidths from some message)
    log_w = _importance_log_weights(model, proposals, prior, prior_bandwidth, prior_uniform, centres, log_weights,
                                    bandwidth, present, valid, K_r, exact=False)
    ok = np.isfinite(log_w).any(axis=1)
    if not ok.all():
        redo = np.flatnonzero(~ok)
        log_w[redo] = _importance_log_weights(
            model, proposals[redo], prior[redo], prior_bandwidth[redo], prior_uniform[redo], centres[redo],
            log_weights[redo], bandwidth[redo], present[redo], valid[redo], K_r[redo], exact=True)
        ok = np.isfinite(log_w).any(axis=1)
    weights = np.exp(log_w - np.where(ok, log_w.max(axis=1), 0.0)[:, None])
    weights /= np.where(ok, weights.sum(axis=1), 1.0)[:, None]
    weights = np.where(ok[:, None], weights, valid / total[:, None])

    # systematic resampling, then regularization jitter with the weighted proposal's h_rot
    cdf_w = np.cumsum(weights, axis=1)
    cdf_w /= cdf_w[:, -1:]
    cdf_w[:, -1] = 1.0
    u = (draws["resample"][:, None] + np.arange(M)[None, :]) / M
    idx = _categorical(cdf_w, u)
    h_rot = rule_of_thumb_bandwidth(proposals, weights)
    positions = proposals[rows, idx] + h_rot[:, None, None] * draws["jitter"]

    # velocity completion: v | p of the prior's KDE (uniform pick for the cold box)
    j_vel = _velocity_index(positions, prior, prior_bandwidth, prior_uniform, draws["velocity"])
    velocities = prior[rows, j_vel, 2:]
    particles = np.concatenate([positions, velocities], axis=-1)
    return np.where(ok[:, None, None], particles, prior), ok


def _belief_update_fused(kernels, model, prior, prior_bandwidth, prior_uniform, centres, log_weights, bandwidth,
                         present, draws, K_r, total, C):
    """``belief_update`` by the two fused kernels (proposals and weights; resampling and completion), with
    the exact log-domain recomputation of a receiver whose every fast weight vanished in between."""
    R, M = prior.shape[:2]
    elements = int(np.dot(total, K_r + 1)) * M
    # threads (off by default, see dnbp_kernels.FUSED_THREADS) over receivers, taken one at a time (dynamic chunks of 1)
    which = 1 if dnbp_kernels.FUSED_THREADS and R >= 4 and elements >= dnbp_kernels.FUSED_THREAD_ELEMENTS else 0
    # or slices of the receivers on the worker threads (dnbp_kernels.SPLIT_WORKERS; each slice's row offset
    # passed: the same bits)
    pieces = dnbp_kernels.split_pieces(R, elements) if not which else 1
    prior = np.ascontiguousarray(prior, float)
    prior_bandwidth = np.ascontiguousarray(prior_bandwidth, float)
    prior_uniform = np.ascontiguousarray(prior_uniform, bool)
    centres = np.ascontiguousarray(centres, float)
    log_weights = np.ascontiguousarray(log_weights, float)
    bandwidth = np.ascontiguousarray(bandwidth, float)
    present = np.ascontiguousarray(present, bool)
    pick = np.ascontiguousarray(draws["pick"], float)
    box = np.ascontiguousarray(draws["box"], float)
    noise = np.ascontiguousarray(draws["noise"], float)
    proposals = np.empty((R, C, 2))
    log_w = np.empty((R, C))
    lo, hi = model.defensive_box
    lo_c, hi_c = model.cold_box
    radius = float(model.truncation) if model.kernel == "truncated" else 0.0  # 0: the exact kernel
    weights = kernels["weights"][which]
    constants = (int(model.oversampling), float(model.defensive_weight), float(lo), float(hi), float(lo_c),
                 float(hi_c), radius)

    def weights_rows(a: int, b: int) -> None:
        weights(prior[a:b], prior_bandwidth[a:b], prior_uniform[a:b], centres[a:b], log_weights[a:b], bandwidth[a:b],
                present[a:b], pick[a:b], box[a:b], noise[a:b], *constants, a, proposals[a:b], log_w[a:b])

    with kernels["chunks"](1) if which else contextlib.nullcontext():
        dnbp_kernels.split_rows(weights_rows, R, pieces)
    ok = np.isfinite(log_w).any(axis=1)
    if not ok.all():
        redo = np.flatnonzero(~ok)
        valid = np.arange(C)[None, :] < total[redo, None]
        log_w[redo] = _importance_log_weights(
            model, proposals[redo], prior[redo], prior_bandwidth[redo], prior_uniform[redo], centres[redo],
            log_weights[redo], bandwidth[redo], present[redo], valid, K_r[redo], exact=True)
        ok = np.isfinite(log_w).any(axis=1)
    out = np.empty_like(prior)
    resample = np.ascontiguousarray(draws["resample"], float)
    jitter = np.ascontiguousarray(draws["jitter"], float)
    velocity = np.ascontiguousarray(draws["velocity"], float)
    resample_kernel = kernels["resample"][which]

    def resample_rows(a: int, b: int) -> None:
        resample_kernel(prior[a:b], prior_bandwidth[a:b], prior_uniform[a:b], proposals[a:b], log_w[a:b], ok[a:b],
                        resample[a:b], jitter[a:b], velocity[a:b], radius, a, out[a:b])

    with kernels["chunks"](1) if which else contextlib.nullcontext():
        dnbp_kernels.split_rows(resample_rows, R, pieces)
    return out, ok


def _velocity_index(positions: np.ndarray, prior: np.ndarray, prior_bandwidth: np.ndarray, prior_uniform: np.ndarray,
                    u: np.ndarray, compiled: bool = True) -> np.ndarray:
    """Prior particle j of each new particle i (R, M) for v | p: j ~ softmax_j(-||p_i - x_j||^2 / (2 h_rho^2)),
    by inverse CDF with the uniforms u (R, M); a uniform pick where the prior is the cold box."""
    R, M = positions.shape[:2]
    denominator = 2.0 * prior_bandwidth**2
    kernel = dnbp_kernels.row_kernel("velocity_rows", R * M * prior.shape[1]) if compiled else None
    if kernel is not None and R:
        out = np.empty((R, M), dtype=np.int64)
        kernel(np.ascontiguousarray(positions), np.ascontiguousarray(prior[..., :2]), denominator,
               np.asarray(prior_uniform, bool), np.ascontiguousarray(u, float), out)
        return out
    diff = positions[:, :, None, :] - prior[:, None, :, :2]
    logits = -np.sum(diff**2, axis=-1) / denominator[:, None, None]
    logits = np.where(prior_uniform[:, None, None], 0.0, logits)
    vcdf = _normalized_cdf(logits).reshape(R * M, -1)
    return _categorical(vcdf, u.reshape(R * M, 1)).reshape(R, M)


def _importance_log_weights(model, proposals, prior, prior_bandwidth, prior_uniform, centres, log_weights, bandwidth,
                            present, valid, K_r, exact: bool, compiled: bool = True) -> np.ndarray:
    """log pi(p) - log q(p) at the proposals (R, C); -inf where invalid or pi = 0."""
    R, S = present.shape
    C = proposals.shape[1]
    log_rho = prior_logpdf(model, proposals, prior[:, :, :2], prior_bandwidth, prior_uniform, exact)
    log_m = np.full((R, S, C), -np.inf)
    r_idx, s_idx = np.nonzero(present)
    if len(r_idx):
        log_m[r_idx, s_idx] = mixture_logpdf(proposals[r_idx], centres[r_idx, s_idx], log_weights[r_idx, s_idx],
                                             bandwidth[r_idx, s_idx], exact)
    kernel = dnbp_kernels.row_kernel("importance_rows", R * S * C) if compiled and not exact else None
    if kernel is not None and R * C:
        out = np.empty((R, C))
        kernel(log_rho, log_m, present, valid, np.log(K_r + 1.0), out)
        return out
    log_target = log_rho + np.sum(np.where(present[..., None], log_m, 0.0), axis=1)
    log_q = _logsumexp(np.concatenate([log_rho[:, None], log_m], axis=1), axis=1) - np.log(K_r + 1)[:, None]
    with np.errstate(invalid="ignore"):
        return np.where(valid & np.isfinite(log_q) & np.isfinite(log_target), log_target - log_q, -np.inf)


def draw_belief(rng: np.random.Generator, count: int, model: DnbpModel) -> dict[str, np.ndarray]:
    """The random numbers of ``count`` belief updates of one copy, as one block per purpose."""
    C, M = model.proposal_capacity, model.num_particles
    return {
        "pick": rng.random((count, C)),
        "box": rng.random((count, C, 3)),
        "noise": rng.standard_normal((count, C, 2)),
        "resample": rng.random(count),
        "jitter": rng.standard_normal((count, M, 2)),
        "velocity": rng.random((count, M)),
    }


def draw_messages(rng: np.random.Generator, count: int, model: DnbpModel) -> dict[str, np.ndarray]:
    """The random numbers of ``count`` messages of one copy (Alg. 1 step 2)."""
    M = model.num_particles
    return {
        "permutation": rng.permuted(np.broadcast_to(np.arange(M), (count, M)), axis=1),
        "offset": rng.random((count, M)),
        "range_noise": rng.standard_normal((count, M)),
    }


def _draw_per_copy(rngs: Sequence[np.random.Generator], copies: np.ndarray, batch: int, draw, model) -> dict:
    """Draw each copy's block from its own generator and stack them in ``copies`` order (copies sorted)."""
    if batch == 1:
        return draw(rngs[0], len(copies), model)
    counts = np.bincount(copies, minlength=batch)
    blocks = [draw(rngs[b], int(counts[b]), model) for b in range(batch) if counts[b]]
    if len(blocks) == 1:  # one copy (B = 1): its block as drawn
        return blocks[0]
    return {key: np.concatenate([blk[key] for blk in blocks]) for key in blocks[0]}


# --- schedule (the paper's Sec. 3.4) -------------------------------------------------------------------------
def fault_senders(fault: np.ndarray, heard_count: np.ndarray, qualified: np.ndarray, threshold: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Fault UAVs allowed to send at an iteration n >= 1 of the modified schedule.

    A fault UAV qualifies once it has heard from at least theta distinct
    neighbours; while no *new* fault UAV qualifies and theta > 1, theta drops
    by one (so 3 -> 2 -> 1 within one iteration); once qualified a UAV stays
    allowed for the rest of the step. fault, heard_count, qualified (B, N),
    threshold (B,). Returns (qualified, threshold) updated.
    """
    threshold = threshold.copy()
    while True:
        new = fault & ~qualified & (heard_count >= threshold[:, None])
        drop = ~new.any(axis=1) & (threshold > 1)
        if not drop.any():
            return qualified | new, threshold
        threshold = np.where(drop, threshold - 1, threshold)


# --- initial prior and Algorithm 3 --------------------------------------------------------------------------------
def initial_state(model: DnbpModel, rngs: Sequence[np.random.Generator], mode: str,
                  position_mean: np.ndarray, velocity_mean: np.ndarray, velocity_std: float) -> DnbpState:
    """The tau = 0 prior.

    ``warm``: p ~ N(position_mean, sigma_gps^2 I2), v ~ N(velocity_mean, velocity_std^2 I2), M draws per UAV;
    ``cold``: p ~ U(cold box), v ~ N(velocity_mean, velocity_std^2) and the prior density is the box.
    position_mean, velocity_mean: (B, N, 2); ``velocity_std`` is a standard deviation (m/s), not a variance.
    Each copy draws from its own generator.
    """
    if mode not in ("warm", "cold"):
        raise ValueError(f"init must be 'warm' or 'cold', got {mode!r}")
    B, N = velocity_mean.shape[:2]
    M = model.num_particles
    gps_std = per_copy("gps_std", model.gps_std, B)
    pos = np.empty((B, N, M, 2))
    vel = np.empty((B, N, M, 2))
    for b, rng in enumerate(rngs):
        if mode == "warm":
            pos[b] = position_mean[b, :, None, :] + gps_std[b] * rng.standard_normal((N, M, 2))
        else:
            lo, hi = model.cold_box
            pos[b] = lo + (hi - lo) * rng.random((N, M, 2))
        vel[b] = velocity_mean[b, :, None, :] + velocity_std * rng.standard_normal((N, M, 2))
    particles = np.concatenate([pos, vel], axis=-1)
    return DnbpState(prior=particles, prior_bandwidth=rule_of_thumb_bandwidth(pos),
                     prior_uniform=np.full((B, N), mode == "cold"), belief=particles.copy(),
                     estimate=pos.mean(axis=2))


def predict(model: DnbpModel, belief: np.ndarray, accel: np.ndarray, rngs: Sequence[np.random.Generator]
            ) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 3: particles of rho(k+1) (B, N, M, 4) and their KDE bandwidth h_rho (B, N)."""
    B, N, M = belief.shape[:3]
    sigma = per_copy("accel_noise_std", model.accel_noise_std, B)[:, None, None, None]
    e = np.stack([rng.standard_normal((N, M, 2)) for rng in rngs]) * sigma
    a = accel[:, :, None, :] + e
    dt = model.dt
    pos = belief[..., :2] + dt * belief[..., 2:] + 0.5 * dt**2 * a
    vel = belief[..., 2:] + dt * a
    return np.concatenate([pos, vel], axis=-1), rule_of_thumb_bandwidth(pos)


_POOL_ENTRIES_PER_ROW = 4  # a step's message pool starts with room for 4 messages per receiver, then doubles


class _MessagePool:
    """The messages of one time step: entries of M centres (2), M log-weights and one bandwidth, entry 0 a blank
    one (centres 0, uniform weights, bandwidth 1: what an absent slot of a padded gather reads). ``add(n)``
    appends n blank entries (growing the arrays by doubling) and returns their indices."""

    def __init__(self, num_particles: int, capacity: int):
        self.size = 1
        self.centres = np.zeros((capacity, num_particles, 2))
        self.log_weights = np.full((capacity, num_particles), -np.log(num_particles))
        self.bandwidth = np.ones(capacity)

    def add(self, count: int) -> np.ndarray:
        start, self.size = self.size, self.size + count
        capacity = len(self.bandwidth)
        if self.size > capacity:
            grown = max(self.size, 2 * capacity)
            M = self.centres.shape[1]
            self.centres = np.concatenate([self.centres, np.zeros((grown - capacity, M, 2))])
            self.log_weights = np.concatenate([self.log_weights, np.full((grown - capacity, M), -np.log(M))])
            self.bandwidth = np.concatenate([self.bandwidth, np.ones(grown - capacity)])
        return np.arange(start, self.size)


# --- Algorithm 4 -------------------------------------------------------------------------------------------------
def step(model: DnbpModel, state: DnbpState, gps_normal: np.ndarray, gps_fix: np.ndarray, deliver: Deliver,
         ranges: np.ndarray, accel: np.ndarray, rngs: Sequence[np.random.Generator],
         broadcast: np.ndarray | None = None, record: bool = False,
         propagate: Propagate | None = None) -> tuple[DnbpState, StepResult]:
    """One time step tau of dNBP (Algorithm 4) for B copies.

    gps_normal (B, N) bool; gps_fix (B, N, 2) (ignored where faulty);
    ``deliver`` the caller's network for this step, called once per
    iteration as ``deliver(senders, listening) -> delivered``: senders
    (B, N) bool, the UAVs that transmit in this iteration (allowed by the
    schedule and deciding to broadcast); listening (B, N, N) bool [t, s]:
    s takes t's message under the schedule (never t = s); delivered
    (B, N, N) bool [t, s]: t's message reaches s. A delivery where senders
    or listening say no raises ValueError;
    ranges (B, N, N) measured d_st, read only where delivered;
    accel (B, N, 2) the readings a_hat(tau) used to predict tau + 1;
    broadcast (B, N, n_iter) bool: whether each UAV broadcasts in each
    iteration when the schedule allows it (None = always, the paper's
    schedule); ``rngs``: one generator per copy; ``propagate`` replaces
    Algorithm 3 for another motion model: ``propagate(belief, rngs)`` returns
    the particles of rho(tau+1) (B, N, M, d), position first (None: the
    constant-velocity model of ``model``, with ``accel``). Returns the state of
    tau + 1 (prior = rho(tau+1), belief/estimate of tau) and a
    ``StepResult``.
    """
    B, N, M = state.prior.shape[:3]
    n_iter = model.num_iterations
    gps_normal = np.asarray(gps_normal, bool)
    fault = ~gps_normal
    if broadcast is None:
        broadcast = np.ones((B, N, n_iter), bool)
    broadcast = np.asarray(broadcast, bool)
    if broadcast.shape != (B, N, n_iter):
        raise ValueError(f"broadcast must have shape {(B, N, n_iter)}, got {broadcast.shape}")
    parallel = model.schedule == "parallel"
    truncation = float(model.truncation) if model.kernel == "truncated" else 0.0
    belief = state.prior.copy()
    # the prior's arrays with the copy and UAV axes merged: a (copy, UAV) pair is one row, gathered by one take
    d = state.prior.shape[3]
    prior_rows = np.ascontiguousarray(state.prior, float).reshape(B * N, M, d)
    prior_bandwidth_rows = np.ascontiguousarray(state.prior_bandwidth, float).reshape(B * N)
    prior_uniform_rows = np.ascontiguousarray(state.prior_uniform, bool).reshape(B * N)
    belief_rows = belief.reshape(B * N, M, d)

    # message store: a pool of messages (entry 0 a blank one, never read as present) and, per receiver row
    # b * N + s, the pool entry of each slot (0 = none): slot t < N holds t's message, slot N the GPS "message" of
    # a normal UAV. Memory and writes are O(messages delivered), not O(B N^2 M) as a dense [receiver, slot] store.
    S = N + 1
    slot_entry = np.zeros((B * N, S), np.int64)
    pool = _MessagePool(M, capacity=1 + int(gps_normal.sum()) + _POOL_ENTRIES_PER_ROW * B * N)
    gps_rows = np.flatnonzero(gps_normal.reshape(B * N))
    gps_entries = pool.add(len(gps_rows))
    pool.centres[gps_entries] = np.nan_to_num(np.asarray(gps_fix, float).reshape(B * N, 2)[gps_rows])[:, None, :]
    pool.bandwidth[gps_entries] = per_copy("gps_std", model.gps_std, B)[gps_rows // N]
    slot_entry[gps_rows, N] = gps_entries
    kernels = dnbp_kernels.fused_kernels()

    def update(b_idx: np.ndarray, rows: np.ndarray) -> None:
        draws = _draw_per_copy(rngs, b_idx, B, draw_belief, model)
        # each receiver's present slots, in slot order, padded to the most any of these receivers holds: the
        # belief update reads only present slots, in order, so the gathered copy is O(rows x messages held), not
        # O(rows x N) (the same bits)
        entries = slot_entry[rows]
        present = entries > 0
        held = max(1, int(present.sum(axis=1).max()))
        order = np.argsort(~present, axis=1, kind="stable")[:, :held]
        entries = np.take_along_axis(entries, order, axis=1)  # padding: the blank entry 0
        present = entries > 0
        centres, log_weights, bandwidth = pool.centres[entries], pool.log_weights[entries], pool.bandwidth[entries]
        if kernels is None:
            new, _ = belief_update(model, prior_rows[rows], prior_bandwidth_rows[rows], prior_uniform_rows[rows],
                                   centres, log_weights, bandwidth, present, draws)
        else:  # belief_update's fused path, its checks included
            K_r = present.sum(axis=1)
            total = -(-model.oversampling * M // (K_r + 1)) * (K_r + 1)
            if total.max() > model.proposal_capacity:
                raise ValueError(f"too many incoming messages for the proposal capacity {model.proposal_capacity}")
            new, _ = _belief_update_fused(kernels, model, prior_rows[rows], prior_bandwidth_rows[rows],
                                          prior_uniform_rows[rows], centres, log_weights, bandwidth, present, draws,
                                          K_r, total, int(total.max()))
        belief_rows[rows] = new

    # 1. normal UAVs: prior x GPS, fixed for the step in the modified schedule
    rows = np.flatnonzero(gps_normal)
    if len(rows):
        update(rows // N, rows)

    heard = np.zeros((B, N, N), bool)
    qualified = np.zeros((B, N), bool)
    threshold = np.full(B, model.initial_threshold)
    delivered_all = np.zeros((B, n_iter, N, N), bool)
    broadcasts = np.zeros((B, N), int)
    history = []
    not_self = ~np.eye(N, dtype=bool)
    listening_fault = fault[:, None, :] & not_self
    both_fault = fault[:, :, None] & fault[:, None, :]  # [b, t, s]: the reverse-message correction applies
    log_uniform = -np.log(M)
    for n in range(n_iter):
        if parallel:
            allowed = np.ones((B, N), bool)
            listening = np.broadcast_to(not_self, (B, N, N))
        else:
            if n == 0:
                allowed = gps_normal
            else:
                qualified, threshold = fault_senders(fault, heard.sum(axis=1), qualified, threshold)
                allowed = qualified & fault
            listening = listening_fault
        senders = allowed & broadcast[:, :, n]
        may = senders[:, :, None] & listening  # formed before the call: deliver cannot widen it
        delivered = np.asarray(deliver(senders, listening.copy()))
        if delivered.shape != (B, N, N) or delivered.dtype != bool:
            raise ValueError(f"deliver must return a ({B}, {N}, {N}) bool array, got {delivered.dtype} "
                             f"{delivered.shape}")
        if (delivered & ~may).any():
            raise ValueError("deliver returned a delivery the schedule did not allow")
        delivered_all[:, n] = delivered
        broadcasts += delivered.any(axis=2)
        b_idx, t_idx, s_idx = np.nonzero(delivered)
        if len(b_idx):
            t_rows, s_rows = b_idx * N + t_idx, b_idx * N + s_idx
            points = belief_rows[t_rows, :, :2]
            # correction with the reverse message t holds from s, fault <-> fault only
            back = slot_entry[t_rows, s_idx]
            reverse = (back > 0) & both_fault[b_idx, t_idx, s_idx]
            if reverse.any():
                corr = np.full((len(b_idx), M), log_uniform)
                back = back[reverse]
                corr[reverse] = correction_weights(points[reverse], pool.centres[back], pool.log_weights[back],
                                                   pool.bandwidth[back], truncation)
            else:
                corr = None
            draws = _draw_per_copy(rngs, b_idx, B, draw_messages, model)
            c, lw, h = sample_messages(model, points, ranges[b_idx, t_idx, s_idx], corr, draws["permutation"],
                                       draws["offset"], draws["range_noise"],
                                       range_std=per_copy("range_std", model.range_std, B)[b_idx])
            if model.fault_message_power < 1.0:
                h = temper_bandwidth(h, points, corr, fault[b_idx, t_idx], model.fault_message_power,
                                     per_copy("range_std", model.range_std, B)[b_idx])
            # written only after every message of this iteration is built (synchronous iteration)
            entry = slot_entry[s_rows, t_idx]
            fresh = entry == 0
            entry[fresh] = pool.add(int(fresh.sum()))
            slot_entry[s_rows, t_idx] = entry
            pool.centres[entry], pool.log_weights[entry], pool.bandwidth[entry] = c, lw, h
            heard[b_idx, t_idx, s_idx] = True
            receivers = np.flatnonzero(delivered.any(axis=1))  # np.unique(s_rows): rows b * N + s, sorted
            update(receivers // N, receivers)
        if record:
            history.append(belief.copy())

    estimate = belief[..., :2].mean(axis=2)
    if propagate is None:
        prior, h_rho = predict(model, belief, accel, rngs)
    else:
        prior = np.asarray(propagate(belief, rngs), float)
        h_rho = rule_of_thumb_bandwidth(prior[..., :2])
    new_state = DnbpState(prior=prior, prior_bandwidth=h_rho, prior_uniform=np.zeros((B, N), bool), belief=belief,
                          estimate=estimate)
    return new_state, StepResult(estimate=estimate, belief=belief, delivered=delivered_all, broadcasts=broadcasts,
                                 received=heard.sum(axis=1), history=history)
