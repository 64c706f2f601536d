"""The MRCLAM noise model: odometry and range-bearing noise fitted against Vicon on the start of a run.

The one model of the
odometry and measurement noise that ``coloc reproduce mrclam`` and the
``mrclam_relay`` scenario both apply, fitted against Vicon on a calibration
window at the start of the run (``calibration_seconds``: the first
``CALIBRATION_FRACTION`` = 10 % of the run and at least ``CALIBRATION_MIN_S`` =
60 s; the baseline model, 60 s). ``NoiseModel.calibrate(d)`` fits and builds it;
per step it gives the corrected odometry of an absolute step, that
odometry's variances (the time update's Q) and R of each observation from its
measured range.
``fit_noise_scales`` fits the alternative "likelihood" model's scales by maximum composite likelihood
(cached on disk, ``coloc_env.data.fit_cache``).
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field

import numpy as np

from coloc_env.config import BadInput
from coloc_env.data.mrclam import NUM_LANDMARKS, NUM_ROBOTS, NUM_SUBJECTS, MrclamData, wrap_angle

__all__ = ["BASELINE_CALIBRATION_S", "CALIBRATION_FRACTION", "CALIBRATION_MIN_S", "GATE_999", "NOISE_MODELS",
           "NoiseModel", "calibrate_noise", "calibration_seconds", "fit_noise_scales"]


def _robust_std(values: np.ndarray) -> float:
    values = np.asarray(values, float)
    return float(1.4826 * np.median(np.abs(values - np.median(values))))


P68 = 68.27  # percentile of |e| that equals sigma for a zero-mean Gaussian
MAX_DELAY_S = 0.5  # odometry delays searched: 0 .. 0.5 s
GATE_999 = 13.815510557964274  # chi-square(2) 0.999 quantile: residuals beyond it are outliers


def _vicon_velocity(gt: np.ndarray, dt: float) -> np.ndarray:
    """(v, w) per step from Vicon poses (K + 1, N, 3): forward displacement and heading change over dt, (K, N, 2)."""
    step = np.diff(gt[..., :2], axis=0)
    heading = gt[:-1, :, 2]
    v = (step[..., 0] * np.cos(heading) + step[..., 1] * np.sin(heading)) / dt
    return np.stack([v, wrap_angle(np.diff(gt[..., 2], axis=0)) / dt], axis=-1)


def _scale(u: np.ndarray, truth: np.ndarray) -> float:
    """Least-squares gain through the origin, truth ~ s u, over all robots and steps (1 when u is all zero)."""
    power = float(np.sum(u * u))
    return float(np.sum(u * truth) / power) if power > 1e-12 else 1.0


def _delay_and_scale(odometry: np.ndarray, velocity: np.ndarray, max_delay: int) -> tuple[int, np.ndarray]:
    """Actuation delay n in 0..max_delay and (s_v, s_w) minimizing the odometry residual.

    For each n, s_c = least squares of the Vicon rate on the command logged n steps
    earlier (pooled over robots), and the cost is sum_c mse_c(n) / mse_c(0) over the
    common steps [max_delay, K); the smallest cost wins (ties: the smaller n).
    """
    K = len(velocity)
    max_delay = max(0, min(max_delay, K - 2))
    truth = velocity[max_delay:]
    costs, scales = [], []
    for n in range(max_delay + 1):
        u = odometry[max_delay - n:K - n]
        s = np.array([_scale(u[..., c], truth[..., c]) for c in range(2)])
        scales.append(s)
        costs.append(np.mean((s * u - truth) ** 2, axis=(0, 1)))
    base = np.maximum(costs[0], 1e-300)
    total = [float(np.sum(c / base)) for c in costs]
    n = int(np.argmin(total))
    return n, scales[n]


def _variance_model(error: np.ndarray, u: np.ndarray) -> tuple[float, float]:
    """(a, b) >= 0 of E[e^2 | u] = a + b u^2: non-negative least squares of e^2 on (1, u^2).

    The plain second moment (no trimming): heavy tails of the per-step error are real
    error the filter integrates, and the mean of e^2 is what its covariance must match.
    """
    from scipy.optimize import nnls

    e2, u2 = np.ravel(error) ** 2, np.ravel(u) ** 2
    scale = max(float(np.max(u2)), 1e-12)  # conditioning: fit b' = b * scale
    (a, b), _ = nnls(np.column_stack([np.ones_like(u2), u2 / scale]), e2)
    return float(a), float(b / scale)


def _correction_horizon(d: MrclamData, k: int) -> int:
    """Steps a robot dead-reckons between observations, as seen from a random instant, over steps [0, k).

    Gaps g between successive steps at which a robot measures or is measured (the
    window's start and end count as bounds), pooled over robots: E[g^2] / E[g], the
    mean length of the gap that contains a uniformly drawn step (length-biased mean).
    """
    gaps = []
    for r in range(NUM_ROBOTS):
        involved = ((d.meas_robot == r) | (d.meas_subject == r + 1)) & (d.meas_step < k)
        g = np.diff(np.concatenate([[0], np.unique(d.meas_step[involved]), [k]]))
        gaps.append(g[g > 0])
    g = np.concatenate(gaps).astype(float)
    return max(1, int(round(float(np.sum(g * g) / np.sum(g)))))


def _inflation(error: np.ndarray, var: np.ndarray, horizon: int) -> float:
    """max(1, E[(sum of H successive errors)^2] / E[sum of H white-model variances]) per robot, pooled.

    A white-noise model predicts Var(sum_H e) = sum_H sigma^2; errors correlated over
    L steps make it grow like L times that. The ratio at the correction horizon H
    (overlapping windows, all robots) is the factor the per-step variance needs so
    that the integrated error over H steps is not understated; never below 1.
    """
    H = max(1, min(int(horizon), len(error)))
    ce = np.concatenate([np.zeros((1, error.shape[1])), np.cumsum(error, axis=0)])
    cv = np.concatenate([np.zeros((1, var.shape[1])), np.cumsum(var, axis=0)])
    actual = np.mean((ce[H:] - ce[:-H]) ** 2)
    model = np.mean(cv[H:] - cv[:-H])
    return max(1.0, float(actual / model)) if model > 0 else 1.0


def _range_model(error: np.ndarray, true_range: np.ndarray, bins: int = 6) -> tuple[float, float]:
    """(a, b) >= 0 of sigma_r^2 = a + b r^2 from equal-count range bins.

    Per bin, sigma = the 68.27th percentile of |e| (about zero: a bias is error too;
    robust to the misread barcodes a chi-square gate rejects, but not understated
    like 1.4826 x MAD on heavy tails); non-negative least squares of sigma^2 on
    (1, r_bin^2) with r_bin the bin's median range, relative (weights 1 / sigma^2:
    each bin's variance estimate has the same relative error).
    """
    from scipy.optimize import nnls

    order = np.argsort(true_range)
    parts = [p for p in np.array_split(order, max(1, min(bins, len(order) // 20))) if len(p)]
    r = np.array([np.median(true_range[p]) for p in parts])
    s2 = np.array([np.percentile(np.abs(error[p]), P68) ** 2 for p in parts])
    if len(parts) < 2:
        return float(s2[0]), 0.0
    scale = max(float(np.max(r * r)), 1e-12)
    weight = 1.0 / np.maximum(s2, 1e-300)  # a bin's variance estimate has a relative error ~ sqrt(2 / n)
    (a, b), _ = nnls(np.column_stack([weight, weight * r * r / scale]), weight * s2)
    return float(a), float(b / scale)


def _measurement_inflation(error: np.ndarray, var: np.ndarray, pair: np.ndarray, step: np.ndarray,
                           horizon: int) -> float:
    """max(1, sum_b (sum of e over burst b)^2 / sum_b (sum of the model variances over b)).

    A burst = successive sightings of one subject by one robot with no gap longer than
    ``horizon`` steps. Independent errors give 1; errors shared by the sightings of a
    burst (a landmark's or a viewpoint's systematic error) give up to the burst size: the
    factor by which a white measurement model overcounts a burst's information.
    """
    actual = model = 0.0
    for key in np.unique(pair):
        idx = np.flatnonzero(pair == key)
        idx = idx[np.argsort(step[idx], kind="stable")]
        for burst in np.split(idx, np.flatnonzero(np.diff(step[idx]) > horizon) + 1):
            actual += float(np.sum(error[burst])) ** 2
            model += float(np.sum(var[burst]))
    return max(1.0, actual / model) if model > 0 else 1.0


def calibrate_noise(d: MrclamData, seconds: float = 60.0, gate: float = GATE_999) -> dict:
    """Noise (and odometry calibration) from the first ``seconds`` of ``d`` against the Vicon ground truth.

    Baseline keys (kept for existing callers): ``sigma_v``, ``sigma_w`` = 1.4826 x MAD of
    odometry minus the Vicon-derived (v, w) per step; ``sigma_range``, ``sigma_bearing`` =
    1.4826 x MAD of measured minus Vicon-predicted (range, bearing); ``calibration_s``,
    ``calibration_measurements``. MAD understates heavy tails, ignores the bias, delay
    and speed dependence of the odometry error and its correlation over steps; the
    keys below model them, each from the window's data by the stated rule:

    * ``odometry_delay_steps`` n, ``odometry_scale`` (s_v, s_w): the robot moves as
      u'[k] = s * u[k - n] (``estimators.ukf_relay_se2.correct_odometry``);
      n in 0..0.5 s minimizes the summed relative residual, s by least squares.
    * ``odometry_var0`` (a_v, a_w), ``odometry_var_gain`` (b_v, b_w): per-step
      variance of the corrected residual e = u' - u_vicon, E[e^2 | u'] = a + b u'^2
      (non-negative least squares of e^2 on (1, u'^2)).
    * ``correction_horizon_steps`` H: length-biased mean gap between a robot's
      observations; ``odometry_inflation`` (r_v, r_w) = max(1, E[(sum_H e)^2] /
      E[sum_H (a + b u'^2)]): the filter's per-step variance is
      r (a + b u'^2) (``estimators.ukf_relay_se2.odometry_variance``).
    * ``range_var`` (a_r, b_r): sigma_r^2 = a_r + b_r r^2 from the 68.27th
      percentile of |range residual| in equal-count range bins;
      ``sigma_bearing_p68`` the 68.27th percentile of |bearing residual|.
    * ``measurement_inflation`` (r_range, r_bearing): the errors of successive
      sightings of one subject by one robot are correlated (a landmark's, a
      viewpoint's systematic error), so the same rule as for the odometry: over
      bursts of sightings with no gap longer than H, max(1, sum (sum e)^2 / sum
      (sum sigma^2)), residuals beyond ``gate`` (normalized by the model) left out.
      The filter's R = diag(r_range (a_r + b_r r^2), r_bearing sigma_bearing_p68^2).
    * ``odometry_residual_std`` (v, w) after correction, ``odometry_lag1_autocorr``
      (v, w) and ``odometry_raw_mean`` (v, w): diagnostics.
    """
    from estimators.ukf_relay_se2 import observe

    k = max(2, min(d.steps - 1, int(round(seconds / d.dt))))
    velocity = _vicon_velocity(d.groundtruth[: k + 1], d.dt)
    v_gt, w_gt = velocity[..., 0], velocity[..., 1]
    sel = d.meas_step < k
    pose = d.groundtruth[d.meas_step[sel], d.meas_robot[sel]]
    subject = d.meas_subject[sel]
    target = np.where((subject <= NUM_ROBOTS)[:, None],
                      d.groundtruth[d.meas_step[sel], np.clip(subject - 1, 0, NUM_ROBOTS - 1), :2],
                      d.landmarks[np.clip(subject - NUM_ROBOTS - 1, 0, NUM_LANDMARKS - 1)])
    predicted = observe(pose, target)
    range_error = d.meas_range[sel] - predicted[:, 0]
    bearing_error = wrap_angle(d.meas_bearing[sel] - predicted[:, 1])

    odometry = d.odometry[:k]
    delay, scale = _delay_and_scale(odometry, velocity, int(round(MAX_DELAY_S / d.dt)))
    corrected = odometry[np.maximum(np.arange(k) - delay, 0)] * scale
    error = corrected - velocity
    var0, gain, inflation, residual_std, lag1 = [], [], [], [], []
    horizon = _correction_horizon(d, k)
    for c in range(2):
        a, b = _variance_model(error[..., c], corrected[..., c])
        var0.append(a)
        gain.append(b)
        inflation.append(_inflation(error[..., c], a + b * corrected[..., c] ** 2, horizon))
        residual_std.append(float(np.sqrt(np.mean(error[..., c] ** 2))))
        e = error[..., c] - error[..., c].mean(axis=0)
        denominator = float(np.sum(e * e))
        lag1.append(float(np.sum(e[1:] * e[:-1]) / denominator) if denominator > 0 else 0.0)
    measurement_inflation = [1.0, 1.0]
    if np.count_nonzero(sel):
        range_var = _range_model(range_error, predicted[:, 0])
        sigma_bearing_p68 = float(np.percentile(np.abs(bearing_error), P68))
        var_r = range_var[0] + range_var[1] * d.meas_range[sel] ** 2
        var_b = max(sigma_bearing_p68**2, 1e-300)
        inlier = range_error**2 / np.maximum(var_r, 1e-300) + bearing_error**2 / var_b <= gate
        pair = (d.meas_robot[sel] * (NUM_SUBJECTS + 1) + subject)[inlier]
        step_in = d.meas_step[sel][inlier]
        measurement_inflation = [
            _measurement_inflation(range_error[inlier], var_r[inlier], pair, step_in, horizon),
            _measurement_inflation(bearing_error[inlier], np.full(len(pair), var_b), pair, step_in, horizon)]
    else:
        range_var, sigma_bearing_p68 = (0.0, 0.0), 0.0
    return {
        "calibration_s": k * d.dt,
        "sigma_v": _robust_std(d.odometry[:k, :, 0] - v_gt),
        "sigma_w": _robust_std(d.odometry[:k, :, 1] - w_gt),
        "sigma_range": _robust_std(range_error) if np.count_nonzero(sel) else 0.0,
        "sigma_bearing": _robust_std(bearing_error) if np.count_nonzero(sel) else 0.0,
        "calibration_measurements": int(np.count_nonzero(sel)),
        "odometry_delay_steps": int(delay),
        "odometry_scale": [float(x) for x in scale],
        "odometry_var0": var0,
        "odometry_var_gain": gain,
        "correction_horizon_steps": int(horizon),
        "odometry_inflation": inflation,
        "range_var": [float(x) for x in range_var],
        "sigma_bearing_p68": sigma_bearing_p68,
        "measurement_inflation": measurement_inflation,
        "odometry_residual_std": residual_std,
        "odometry_lag1_autocorr": lag1,
        "odometry_raw_mean": [float(np.mean(d.odometry[:k, :, 0] - v_gt)), float(np.mean(d.odometry[:k, :, 1] - w_gt))],
    }


LIKELIHOOD_FACTORS = (4.0, 2.0, 2.0**0.5, 2.0**0.25)  # pattern-search step factors of fit_noise_scales
LIKELIHOOD_MOVES = 6  # at most this many moves per step factor
LIKELIHOOD_BOX = 1e3  # each scale stays within a factor of this of its start


def _likelihood_costs(d: MrclamData, noise: dict, scales: np.ndarray, steps: int, initial_std: float,
                      gate: float) -> np.ndarray:
    """Negative composite log-likelihood (G,) of the Vicon pose errors of UKF-CCL over steps [0, ``steps``).

    One filter per row of ``scales`` (G, 4) = (c_v, c_w, c_r, c_b), run as G stacked copies on the same
    data: odometry variances c (a + b u'^2), R = diag(c_r (a_r + b_r z_r^2), c_b sigma_b^2), start at the
    Vicon pose with std ``initial_std``; cost = sum over steps and robots of
    log det P_ii + e_i^T P_ii^-1 e_i (e_i: robot i's pose error after the step's updates, heading wrapped).
    """
    import estimators.ukf_relay_se2 as se2

    scales = np.asarray(scales, float)
    G, N = len(scales), NUM_ROBOTS
    white = NoiseModel.from_calibration({**noise, "odometry_inflation": [1.0, 1.0]}, "calibrated",
                                        inflate_measurements=False)
    u = white.odometry(d, np.arange(steps))
    q = white.odometry_var(u)  # (K, N, 2): the white per-step variances, scaled per copy below
    a_r, b_r = white.range_var
    x = np.broadcast_to(d.groundtruth[0], (G, N, 3)).copy()
    P = np.broadcast_to(np.eye(3 * N) * initial_std**2, (G, 3 * N, 3 * N)).copy()
    cost = np.zeros(G)
    rows = np.arange(N)
    R = np.zeros((G, 2, 2))
    for k in range(steps):
        s = d.measurements_at(k)
        for i in range(s.start, s.stop):
            sub, r = int(d.meas_subject[i]), int(d.meas_robot[i])
            z = np.array([d.meas_range[i], d.meas_bearing[i]])
            R[:, 0, 0] = scales[:, 2] * (a_r + b_r * z[0] ** 2)
            R[:, 1, 1] = scales[:, 3] * white.bearing_var
            target = {"measured": sub - 1} if sub <= N else {"landmark": d.landmarks[sub - N - 1]}
            x, P, _, _ = se2.ccl_update_copies(x, P, r, z, R, gate=gate, **target)
        own = P.reshape(G, N, 3, N, 3)[:, rows, :, rows, :].swapaxes(0, 1)  # (G, N, 3, 3)
        e = x - d.groundtruth[k]
        e[..., 2] = se2.wrap(e[..., 2])
        cost += np.sum(np.linalg.slogdet(own)[1] + np.einsum("gna,gnab,gnb->gn", e, np.linalg.inv(own), e), axis=1)
        if k + 1 < steps:
            x, P = se2.time_update_copies(x, P, u[k], d.dt, q[k][None] * scales[:, None, :2])
    return cost


def fit_noise_scales(d: MrclamData, noise: dict, steps: int, initial_std: float = 0.01,
                     gate: float = GATE_999, cache_dir: str | os.PathLike | None = None) -> dict:
    """Maximum-likelihood scales of the white noise model on the calibration window (steps [0, ``steps``)).

    The per-step shapes of ``noise`` (``calibrate_noise``: corrected odometry, variances a + b u'^2,
    sigma_r^2 = a_r + b_r r^2, sigma_b) describe one step's error; the errors are correlated over steps
    and over a burst of sightings, which a filter with white noise cannot represent. The scales
    (c_v, c_w, c_r, c_b) multiply the four variances so that the filter's covariance describes its error:
    they minimize ``_likelihood_costs``, the composite negative log-likelihood of UKF-CCL's pose errors
    against Vicon on the window (each step's error taken as N(0, P_ii), the time correlation of the errors
    ignored: a composite likelihood, whose maximizer is consistent for the marginal model). Search: a
    compass (pattern) search in log-scale from the moment rules' inflations (``odometry_inflation``,
    ``measurement_inflation``): the centre c and c with one scale multiplied or divided by f, 9 filters
    run at once (stacked copies); move to the best; for f in ``LIKELIHOOD_FACTORS`` (at most
    ``LIKELIHOOD_MOVES`` moves per f). Returns ``likelihood_scale`` [c_v, c_w, c_r, c_b],
    ``likelihood_cost`` (per step and robot), ``likelihood_start``, ``likelihood_passes``, ``likelihood_steps``
    and ``likelihood_converged`` (the last factor's pass kept its centre: no compass neighbour is better).
    Each scale stays within a factor ``LIKELIHOOD_BOX`` of its start: on a window too short to identify a
    scale (30 s of dataset 6: the ranges add little to the bearings there) the likelihood keeps improving
    slowly towards that scale's bound.

    Cached: in the process, and on disk (``coloc_env.data.fit_cache``: ``cache_dir``, else
    ``$COLOC_FIT_CACHE``, else the user's cache folder; ``"off"`` fits every time) under ``_fit_key``, a
    digest of the window's data, the noise shapes, the settings and the fit's code (``FIT_CODE_VERSION``
    and the source of the fit's functions), so a later process reads the fit instead of running it.
    """
    from coloc_env.data import fit_cache

    steps = max(2, min(int(steps), d.steps))
    key = _fit_key(d, noise, steps, initial_std, gate)
    if key in _FITS:
        return dict(_FITS[key])
    fit = fit_cache.cached("mrclam-likelihood", key, lambda: _search_scales(d, noise, steps, initial_std, gate),
                           functools.partial(_sound_fit, steps=steps), cache_dir)
    if len(_FITS) >= 8:
        _FITS.clear()
    _FITS[key] = dict(fit)
    return dict(fit)


def _sound_fit(fit, steps: int) -> bool:
    """Whether a stored fit has ``fit_noise_scales``' fields with usable values (4 finite positive scales)."""
    scale = np.asarray(fit["likelihood_scale"], float)
    return (scale.shape == (4,) and bool(np.all(np.isfinite(scale) & (scale > 0)))
            and np.isfinite(float(fit["likelihood_cost"])) and len(fit["likelihood_start"]) == 4
            and int(fit["likelihood_passes"]) >= 1 and int(fit["likelihood_steps"]) == steps
            and isinstance(fit["likelihood_converged"], bool))


def _search_scales(d: MrclamData, noise: dict, steps: int, initial_std: float, gate: float) -> dict:
    """``fit_noise_scales``' compass search (its docstring), uncached."""
    start = np.array([*noise["odometry_inflation"], *noise["measurement_inflation"]], float)
    grid = np.concatenate([np.zeros((1, 4)), np.eye(4), -np.eye(4)])  # the centre and one move along each axis
    centre = np.log(start)
    low, high = centre - np.log(LIKELIHOOD_BOX), centre + np.log(LIKELIHOOD_BOX)
    passes, best, settled = 0, None, False
    for f in LIKELIHOOD_FACTORS:
        settled = False
        for _ in range(LIKELIHOOD_MOVES):
            candidates = np.clip(centre + np.log(f) * grid, low, high)
            cost = _likelihood_costs(d, noise, np.exp(candidates), steps, initial_std, gate)
            passes += 1
            j = int(np.argmin(cost))  # ties keep the centre (row 0)
            best = float(cost[j])
            if j == 0:
                settled = True
                break
            centre = candidates[j]
    fit = {"likelihood_scale": [float(c) for c in np.exp(centre)], "likelihood_cost": best / (steps * NUM_ROBOTS),
           "likelihood_start": [float(c) for c in start], "likelihood_passes": passes,
           "likelihood_steps": int(steps), "likelihood_converged": bool(settled)}
    return fit


_FITS: dict = {}  # fit_noise_scales' results by a digest of everything they depend on


def _fit_key(d: MrclamData, noise: dict, steps: int, initial_std: float, gate: float) -> str:
    """Digest of the window's data (steps [0, steps)), the noise shapes and the settings a fit depends on."""
    import hashlib

    h = hashlib.sha256()
    sel = d.meas_step < steps
    for array in (d.odometry[:steps], d.groundtruth[:steps], d.landmarks, d.meas_step[sel], d.meas_robot[sel],
                  d.meas_subject[sel], d.meas_range[sel], d.meas_bearing[sel]):
        h.update(np.ascontiguousarray(array).tobytes())
    names = ("odometry_delay_steps", "odometry_scale", "odometry_var0", "odometry_var_gain", "odometry_inflation",
             "range_var", "sigma_bearing_p68", "measurement_inflation")
    h.update(repr(([noise[n] for n in names], d.dt, int(steps), float(initial_std), float(gate),
                   LIKELIHOOD_FACTORS, LIKELIHOOD_MOVES, LIKELIHOOD_BOX)).encode())
    h.update(_fit_code_version().encode())
    return h.hexdigest()


# The fit's code version, part of every fit's key: bump it when a change outside the functions whose source
# _fit_code_version reads (the UKF-CCL updates of estimators.ukf_relay_se2, the calibration's shapes) changes a fit.
FIT_CODE_VERSION = 1


@functools.lru_cache(maxsize=1)
def _fit_code_version() -> str:
    """``FIT_CODE_VERSION`` and a digest of the source of the fit's own functions (their file may be absent in an
    installation without sources: the version alone then)."""
    import hashlib
    import inspect

    h = hashlib.sha256(str(FIT_CODE_VERSION).encode())
    for function in (_likelihood_costs, _search_scales):
        try:
            h.update(inspect.getsource(function).encode())
        except (OSError, TypeError):
            h.update(function.__qualname__.encode())
    return f"fit code {FIT_CODE_VERSION} {h.hexdigest()}"


CALIBRATION_FRACTION = 0.1  # calibration window of the calibrated model: the first 10 % of the run ...
CALIBRATION_MIN_S = 60.0  # ... and at least 60 s
BASELINE_CALIBRATION_S = 60.0  # the baseline model (constant white noise): the first 60 s
NOISE_MODELS = ("calibrated", "baseline", "likelihood")


def calibration_seconds(d: MrclamData, kind: str = "calibrated") -> float:
    """Seconds at the start of ``d`` that ``calibrate_noise`` fits model ``kind`` on.

    ``"calibrated"`` and ``"likelihood"``: max(``CALIBRATION_MIN_S``, ``CALIBRATION_FRACTION`` x the duration of
    ``d``) (75.6 s of dataset 6; 60 s for a run shorter than 600 s); ``"baseline"``:
    ``BASELINE_CALIBRATION_S``. No ground truth after the window enters a filter.
    """
    _check_kind(kind)
    if kind == "baseline":
        return BASELINE_CALIBRATION_S
    return max(CALIBRATION_MIN_S, CALIBRATION_FRACTION * d.steps * d.dt)


def _check_kind(kind) -> None:
    if kind not in NOISE_MODELS:
        raise BadInput(f"noise_model must be one of {NOISE_MODELS}, got {kind!r}")


@dataclass(frozen=True)
class NoiseModel:
    """The noise model the MRCLAM filters apply, per step: odometry u', its variances Q(u'), R(range).

    One parametric family holds both models of ``calibrate_noise``'s output
    (``kind``), so the filters apply either through the same three methods:

    * ``odometry`` ``(d, k)``: u'[k] = s * u[max(k - n, 0)] for absolute step(s) k
      of the run ``d`` (n = ``odometry_delay_steps``, s = ``odometry_scale``; the rule of
      ``estimators.ukf_relay_se2.correct_odometry``: the command logged at step k
      moves the robot from k + n on; before the run's first command it is held). A
      replay that starts at step s > 0 thus uses the commands logged before s, as the
      robots did; it never indexes before step 0.
    * ``odometry_var`` ``(u')``: per robot and step, sigma_c^2 = r_c (a_c + b_c u'_c^2)
      (``estimators.ukf_relay_se2.odometry_variance``; a = ``odometry_var0``,
      b = ``odometry_var_gain``, r = ``odometry_inflation``): the ``odometry_var`` (N, 2) of
      ``estimators.ukf_relay_se2.time_update`` / ``time_update_factored``.
    * ``measurement_cov`` ``(range)``: R = diag(r_range (a_r + b_r z_r^2), sigma_b^2)
      from the MEASURED range z_r (the filter knows no other); ``bearing_var`` holds
      sigma_b^2 with its inflation applied.

    ``kind="calibrated"`` (``from_calibration``): every parameter as fitted by the rules
    documented in ``calibrate_noise`` (delay and scale, speed-dependent variance,
    inflation for errors correlated over the correction horizon, range-dependent
    sigma_r, 68.27th-percentile sigma_b, burst inflation of R; ``inflate_measurements=False``
    leaves the last out, the ablation of ``coloc reproduce mrclam``).
    ``kind="baseline"``: the simplest model, the same family with n = 0, s = 1,
    b = 0, r = 1, a = (sigma_v^2, sigma_w^2), sigma_r^2 = ``sigma_range``^2 (b_r = 0) and
    sigma_b = ``sigma_bearing`` (1.4826 x MAD, raw commands, constant white noise; these
    special values make each formula return the baseline's numbers exactly).
    ``kind="likelihood"``: the calibrated model's per-step shapes (delay, scale, a, b, a_r, b_r,
    sigma_b) with the moment-rule inflations replaced by the maximum-likelihood scales of
    ``fit_noise_scales`` on the same window: r = (c_v, c_w), ``range_inflation`` = c_r,
    ``bearing_var`` = c_b sigma_b^2. The consistent model (the one ``coloc reproduce mrclam``
    evaluates); its fit runs UKF-CCL filters on the window (seconds, once per run and process).
    ``calibration`` keeps the ``calibrate_noise`` dict it was built from.
    """

    kind: str
    odometry_delay_steps: int
    odometry_scale: tuple[float, float]
    odometry_var0: tuple[float, float]
    odometry_var_gain: tuple[float, float]
    odometry_inflation: tuple[float, float]
    range_var: tuple[float, float]
    range_inflation: float
    bearing_var: float
    calibration: dict | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        _check_kind(self.kind)
        if isinstance(self.odometry_delay_steps, bool) or int(self.odometry_delay_steps) != self.odometry_delay_steps \
                or self.odometry_delay_steps < 0:
            raise BadInput(f"odometry_delay_steps must be an integer >= 0, got {self.odometry_delay_steps!r}")
        for name, rule in (("odometry_scale", "finite"), ("odometry_var0", ">= 0"), ("odometry_var_gain", ">= 0"),
                           ("odometry_inflation", "> 0"), ("range_var", ">= 0")):
            value = np.asarray(getattr(self, name), float)
            bad = value < 0 if rule == ">= 0" else (value <= 0 if rule == "> 0" else np.zeros(value.shape, bool))
            if value.shape != (2,) or not np.all(np.isfinite(value)) or np.any(bad):
                condition = "" if rule == "finite" else f" {rule}"
                raise BadInput(f"{name} must be 2 finite numbers{condition}, got {getattr(self, name)!r}")
        if not (np.isfinite(self.range_inflation) and self.range_inflation > 0):
            raise BadInput(f"range_inflation must be > 0, got {self.range_inflation!r}")
        if not (np.isfinite(self.bearing_var) and self.bearing_var >= 0):
            raise BadInput(f"bearing_var must be >= 0, got {self.bearing_var!r}")

    @classmethod
    def from_calibration(cls, noise: dict, kind: str = "calibrated", inflate_measurements: bool = True) -> NoiseModel:
        """The model ``kind`` from a ``calibrate_noise`` dict (see the class docstring)."""
        _check_kind(kind)
        if kind == "baseline":
            return cls(kind, 0, (1.0, 1.0), (noise["sigma_v"] ** 2, noise["sigma_w"] ** 2), (0.0, 0.0), (1.0, 1.0),
                       (noise["sigma_range"] ** 2, 0.0), 1.0, noise["sigma_bearing"] ** 2, calibration=noise)
        if kind == "likelihood":
            if "likelihood_scale" not in noise:
                raise BadInput("noise_model 'likelihood' needs the calibration's likelihood_scale "
                                 "(fit_noise_scales; NoiseModel.calibrate(d, 'likelihood') fits it)")
            c_v, c_w, c_r, c_b = noise["likelihood_scale"]
            return cls(kind, int(noise["odometry_delay_steps"]), tuple(noise["odometry_scale"]),
                       tuple(noise["odometry_var0"]), tuple(noise["odometry_var_gain"]), (c_v, c_w),
                       tuple(noise["range_var"]), c_r, c_b * noise["sigma_bearing_p68"] ** 2, calibration=noise)
        r_r, r_b = noise["measurement_inflation"] if inflate_measurements else (1.0, 1.0)
        return cls(kind, int(noise["odometry_delay_steps"]), tuple(noise["odometry_scale"]),
                   tuple(noise["odometry_var0"]), tuple(noise["odometry_var_gain"]),
                   tuple(noise["odometry_inflation"]), tuple(noise["range_var"]), r_r,
                   r_b * noise["sigma_bearing_p68"] ** 2, calibration=noise)

    @classmethod
    def calibrate(cls, d: MrclamData, kind: str = "calibrated", seconds: float | None = None,
                  gate: float = GATE_999, cache_dir: str | os.PathLike | None = None) -> NoiseModel:
        """Fit on the start of ``d`` (``seconds``, default ``calibration_seconds`` of ``kind``) and build
        (``cache_dir``: where ``fit_noise_scales`` caches a ``"likelihood"`` fit)."""
        _check_kind(kind)
        seconds = calibration_seconds(d, kind) if seconds is None else seconds
        noise = calibrate_noise(d, seconds, gate=gate)
        if kind == "likelihood":
            noise.update(fit_noise_scales(d, noise, int(round(noise["calibration_s"] / d.dt)), gate=gate,
                                          cache_dir=cache_dir))
        return cls.from_calibration(noise, kind)

    def odometry(self, d: MrclamData, k) -> np.ndarray:
        """Corrected odometry u'[k] (..., N, 2) at absolute step(s) ``k`` (int or int array) of the run ``d``."""
        k = np.asarray(k)
        if k.dtype.kind not in "iu" or np.any(k < 0) or np.any(k >= d.steps):
            raise BadInput(f"odometry: steps must be integers in [0, {d.steps}), got {k!r}")
        return d.odometry[np.maximum(k - int(self.odometry_delay_steps), 0)] * np.asarray(self.odometry_scale, float)

    def odometry_var(self, u) -> np.ndarray:
        """Per-step (sigma_v^2, sigma_w^2) of corrected odometry ``u`` (..., 2), same shape."""
        from estimators.ukf_relay_se2 import odometry_variance

        return odometry_variance(u, self.odometry_var0, self.odometry_var_gain, self.odometry_inflation)

    def measurement_cov(self, measured_range) -> np.ndarray:
        """R (..., 2, 2) of a (range, bearing) observation whose measured range is ``measured_range`` (...)."""
        r = np.asarray(measured_range, float)
        a, b = self.range_var
        R = np.zeros((*r.shape, 2, 2))
        R[..., 0, 0] = self.range_inflation * (a + b * r * r)
        R[..., 1, 1] = self.bearing_var
        return R
