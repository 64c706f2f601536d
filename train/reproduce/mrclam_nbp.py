"""dNBP (wan2014) on real robot data: UTIAS MRCLAM, landmark-sighting robots as the "GPS-normal" UAVs.

dNBP with the robots that see landmarks playing the GPS-normal role: the
``dnbp`` backend (``estimators.dnbp``, Wan et al. 2014, reconstructed in
``docs/wan2014.md``) and the least-squares baseline ``range_ls``
(``coloc_env.backends.particles``) are driven, through a lossless
``broadcast`` network, on the slices (``SliceWorld``) of one MRCLAM dataset
(``coloc_env.data.mrclam.load_cached``; cite Leung et al., IJRR 2011). No
Vicon data after the calibration window enters any estimator; Vicon is used
for the noise calibration (the first 10 % of the run, the rule of
``coloc_env.data.mrclam.NoiseModel``, as in ``coloc reproduce mrclam``), for
the initial poses and for scoring.

Mapping of the data to dNBP's model (every choice)
--------------------------------------------------

* **Time slices.** Slice tau is data step k_tau = ``SLICE_STEPS`` tau (10 steps
  of 0.1 s: Delta t = 1 s), so that robot-robot ranges accumulate in a slice
  (dataset 6: a robot takes part in a robot-robot range in ~1/3 of the
  1-s slices). Measurements of steps [k_tau - 5, k_tau + 5) are binned to slice
  tau. The estimate of a slice is scored against the Vicon position at k_tau.
* **Heading.** dNBP's state is (p, v) without heading, so the heading that turns
  the odometry speed into a displacement and a landmark bearing into a direction
  comes from outside. Dead-reckoned heading is useless here (dataset 6: off by
  0.2-1.3 rad after 100 s, up to 1.9 rad later). We use each robot's OWN
  navigation filter: a per-robot UKF on (x, y, theta)
  (``estimators.ukf_relay_se2.ccl_update`` with N = 1) driven by its corrected
  odometry and updated only with its own landmark sightings (chi-square(2) 99.9 %
  gate), no robot-robot measurement: the analogue of a UAV's GPS/INS heading,
  non-cooperative. Its heading (and heading variance) at each data step is used;
  its position output is reported as a reference row ("own-nav UKF").
* **Motion prior.** Between slices robot s moves by the displacement
  Delta p_tau = sum_k dt v'_k [cos theta_k, sin theta_k] over the 10 data steps
  (v' the calibrated, delay-corrected odometry speed, theta_k the own-nav
  heading). dNBP's constant-velocity model is fed this displacement through its
  velocity slot: each slice's readings carry the velocity reading
  Delta p_tau / Delta t (the backends' per-step ``velocity``), to which every
  particle's velocity is set before the step, and the acceleration input is 0, so Algorithm 3 moves each
  particle by Delta p_tau + (Delta t^2 / 2) e, e ~ N(0, sigma_acc^2 I2). sigma_acc =
  2 sigma_Delta / Delta t^2 with sigma_Delta^2 = sum_k dt^2 sigma_v,k^2 +
  |Delta p|^2 sigma_theta^2 (calibrated speed variance of the odometry model,
  own-nav heading variance at the slice): the position random-walk std per slice.
  dNBP takes one sigma_acc per step, so the largest over the robots is used
  (the readings' per-step ``accel_std``; ``gps_std`` and ``range_std`` below likewise).
* **GPS-normal role.** A robot that sighted a landmark in the slice (a sighting
  accepted by its own-nav gate) gets a pseudo-fix
  p = l - r [cos(theta + b), sin(theta + b)] + (D(k_tau) - D(k)) per sighting at
  step k (l: the landmark's surveyed position, r, b: measured range and bearing,
  theta: own-nav heading at k, D: the odometry displacement track above, which
  carries the fix from step k to k_tau). Its noise, isotropic (dNBP's GPS message
  is isotropic): sigma_fix^2 = max(sigma_r^2, r^2 (sigma_b^2 + sigma_theta^2)) +
  |sigma_landmark|^2 with sigma_r, sigma_b the calibrated (inflated) range and
  bearing noise at the measured range and sigma_theta the own-nav heading std
  (the larger principal axis: conservative). Several sightings in a slice: their
  inverse-variance mean, with the SMALLEST single sigma_fix (no 1/n reduction:
  they share the heading error and, by the calibration, most of their
  measurement error). dNBP's model holds one sigma_gps, so a slice uses the
  largest sigma_fix of its normal robots. The other robots are "faulty" and
  localize by BP from robot-robot ranges.
* **Edges and ranges.** Edges = robot pairs with a robot-robot range (either
  direction) in the slice; d_st = median of those ranges (robust to a misread).
  The BEARING of a robot-robot sighting is not used: dNBP's pair potential is
  range-only. sigma_d^2 = calibrated (inflated) range variance at d_st + the
  motion within the bin, (0.29 s (|v_s| + |v_t|))^2 (0.29 s: the std of a time
  offset uniform on +-0.5 s); one sigma_d per slice, the largest over its edges.
  Range gate (``RANGE_GATE``, the ``dnbp`` backend's ``range_gate``; our addition,
  not the paper's): before a step a
  range is dropped when (d_st - ||mean_s - mean_t||)^2 / (sigma_d^2 + var_s +
  var_t) > 10.83 (chi-square(1) 99.9 %), means and per-axis variances of dNBP's
  OWN prior particles: misread barcodes give ranges metres off (4 of 1,441 edges
  of dataset 6 have a residual > 1 m). It lowered the full-run dNBP RMSE from
  1.15 m to 0.97 m (M = 100, seed 0); ``ls`` has its own gate.
* **Start.** All estimators start from the Vicon pose at step 0 (the setup of
  ``coloc reproduce mrclam``), std 0.01 m. dNBP: ``min_bandwidth`` 0.02 m (the
  spec's 0.5 m is for 200-m UAV ranges; robots range at 1-5 m), defensive box
  [-6, 9] m per axis (the arena and landmarks with a margin),
  ``num_particles`` ``PARTICLES`` (``QUICK_PARTICLES``), 5 iterations, the paper's
  modified schedule.

Methods, on the same slices: ``dnbp``; ``ls`` (the ``range_ls`` backend: the fault
robot fixed from >= 3 normal neighbours, gated, fed to a KF with the same
displacement prior and pseudo-fixes: the velocity reading sets the KF's velocity,
with zero variance, before each step); ``gps_only`` (the same backend on the
slices without ranges: the DR / GPS-only baseline of wan2014); ``dead_reckoning`` (odometry integrated with its
own dead-reckoned heading, the ``IL`` of ``coloc reproduce mrclam``);
``own_nav`` (the heading source's position, reference). Score: position RMSE
against Vicon pooled over (slice, robot) where the robot is faulty
(``rmse_fault``) and over all (``rmse_all``); dNBP is random, its generator is
``np.random.default_rng(seed)``.
"""

from __future__ import annotations

import dataclasses
import os
import time
from types import SimpleNamespace

import numpy as np

import estimators.ukf_relay_se2 as se2
from coloc_env.backends.particles import Dnbp, RangeLs
from coloc_env.data import mrclam
from coloc_env.networks.broadcast import Broadcast
from coloc_env.worlds.base import Readings, World
from estimators.cv_models import ConstantVelocityAccel

SLICE_STEPS = 10  # data steps per slice: Delta t = 1 s
SLICE_DT = 1.0  # s: SLICE_STEPS steps of the 0.1-s data grid
PARTICLES = 100
QUICK_PARTICLES = 100
QUICK_SLICES = 100
INITIAL_STD = 0.01  # m and rad, as coloc reproduce mrclam
BIN_TIME_STD = SLICE_STEPS / np.sqrt(12.0)  # std (in data steps) of a measurement's offset from its slice step
BOX = (-6.0, 9.0)
RANGE_GATE: float | None = 10.83  # chi-square(1) 99.9 %: a range vs the distance of dNBP's own prior means
METHODS = ("dnbp", "dnbp_no_ranges", "ls", "gps_only", "dead_reckoning", "own_nav")
N = mrclam.NUM_ROBOTS


# --------------------------------------------------------------------------------------------- data -> slices
pseudo_fix = mrclam.pseudo_fix  # coloc_env.data.mrclam's (shared with the mrclam world's pseudo-fixes)
fix_std = mrclam.fix_std


def own_navigation(d: mrclam.MrclamData, model: mrclam.NoiseModel, x0: np.ndarray):
    """``coloc_env.data.mrclam.own_navigation`` from ``INITIAL_STD`` (poses, covariances, accepted)."""
    return mrclam.own_navigation(d, model, x0, INITIAL_STD)


def dead_reckoning(d: mrclam.MrclamData, model: mrclam.NoiseModel, x0: np.ndarray) -> np.ndarray:
    """Odometry alone, heading dead-reckoned too: poses (T, N, 3)."""
    u = model.odometry(d, np.arange(d.steps))
    out = np.empty((d.steps, N, 3))
    x = np.array(x0, float)
    for k in range(d.steps):
        out[k] = x
        x = se2.motion(x, u[k], d.dt)[0]
    return out


@dataclasses.dataclass(frozen=True)
class Slices:
    """The data mapped to dNBP's slices (S slices, N robots); see the module docstring.

    steps (S,), truth (S, N, 2) Vicon (scoring only), normal (S, N), fix (S, N, 2), fix_std (S, N),
    adjacency (S, N, N), ranges (S, N, N), range_std (S,), velocity (S, N, 2) = Delta p / Delta t to the
    next slice, accel_std (S,), dead_reckoning (S, N, 2), own_nav (S, N, 2), initial (N, 3).
    """

    steps: np.ndarray
    truth: np.ndarray
    normal: np.ndarray
    fix: np.ndarray
    fix_std: np.ndarray
    adjacency: np.ndarray
    ranges: np.ndarray
    range_std: np.ndarray
    velocity: np.ndarray
    accel_std: np.ndarray
    dead_reckoning: np.ndarray
    own_nav: np.ndarray
    initial: np.ndarray

    def __len__(self) -> int:
        return len(self.steps)


def build_slices(d: mrclam.MrclamData, model: mrclam.NoiseModel, num_slices: int | None = None) -> Slices:
    """Map ``d`` to slices 0..num_slices-1 (all that fit by default) by the rules of the module docstring."""
    S_max = (d.steps - 1) // SLICE_STEPS + 1
    S = S_max if num_slices is None else min(int(num_slices), S_max)
    d = d.window(0, min(d.steps, SLICE_STEPS * S + SLICE_STEPS // 2))  # the steps the slices use (and the next)
    x0 = d.groundtruth[0].copy()
    pose, cov, accepted = own_navigation(d, model, x0)
    dr = dead_reckoning(d, model, x0)
    u = model.odometry(d, np.arange(d.steps))
    q = model.odometry_var(u)
    dt, slice_dt = d.dt, d.dt * SLICE_STEPS
    heading = pose[..., 2]
    step_disp = dt * u[..., 0, None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    track = np.concatenate([np.zeros((1, N, 2)), np.cumsum(step_disp, axis=0)])  # D(k), (T + 1, N, 2)
    along_var = np.concatenate([np.zeros((1, N)), np.cumsum(dt * dt * q[..., 0], axis=0)])
    steps = SLICE_STEPS * np.arange(S)
    half = SLICE_STEPS // 2
    bin_of = (d.meas_step + half) // SLICE_STEPS  # step k -> slice round(k / 10), bins [k_tau - 5, k_tau + 5)
    keep = bin_of < S
    normal = np.zeros((S, N), bool)
    fix = np.zeros((S, N, 2))
    fstd = np.zeros((S, N))
    # landmark sightings accepted by the robot's own-nav gate
    lm = keep & accepted & (d.meas_subject > N)
    idx = np.flatnonzero(lm)
    k, r, tau = d.meas_step[idx], d.meas_robot[idx], bin_of[idx]
    land = d.landmarks[d.meas_subject[idx] - N - 1]
    offset = track[steps[tau], r] - track[k, r]
    p = pseudo_fix(land, d.meas_range[idx], d.meas_bearing[idx], heading[k, r], offset)
    R = model.measurement_cov(d.meas_range[idx])
    heading_var = cov[k, r, 2, 2]
    sd = fix_std(d.meas_range[idx], R[:, 0, 0], R[:, 1, 1], heading_var,
                 np.sum(d.landmark_std[d.meas_subject[idx] - N - 1] ** 2, axis=-1))
    w = 1.0 / sd**2
    wsum = np.zeros((S, N))
    np.add.at(wsum, (tau, r), w)
    np.add.at(fix, (tau, r), w[:, None] * p)
    normal = wsum > 0
    fix[normal] /= wsum[normal][:, None]
    fstd[:] = np.inf
    np.minimum.at(fstd, (tau, r), sd)
    fstd[~normal] = 0.0
    # robot-robot ranges: median per unordered pair and slice
    rr = np.flatnonzero(keep & (d.meas_subject <= N))
    a, b = d.meas_robot[rr], d.meas_subject[rr] - 1
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    adjacency = np.zeros((S, N, N), bool)
    ranges = np.zeros((S, N, N))
    key = (bin_of[rr] * N + lo) * N + hi
    order = np.argsort(key, kind="stable")
    uniq, start = np.unique(key[order], return_index=True)
    for kk, group in zip(uniq, np.split(order, start[1:]), strict=True):
        t_, i_, j_ = kk // (N * N), (kk // N) % N, kk % N
        ranges[t_, i_, j_] = ranges[t_, j_, i_] = float(np.median(d.meas_range[rr[group]]))
        adjacency[t_, i_, j_] = adjacency[t_, j_, i_] = True
    speed = np.abs(u[steps, :, 0])
    motion = BIN_TIME_STD * dt * (speed[:, :, None] + speed[:, None, :])
    var_edges = model.measurement_cov(ranges)[..., 0, 0] + motion**2
    range_std = np.sqrt(np.max(np.where(adjacency, var_edges, 0.0), axis=(1, 2)))
    # motion prior: displacement to the next slice (the last slice: zero motion, never used for scoring)
    nxt = np.minimum(steps + SLICE_STEPS, d.steps)
    disp = track[nxt] - track[steps]
    disp_var = along_var[nxt] - along_var[steps] + np.sum(disp**2, axis=-1) * cov[steps, :, 2, 2]
    accel_std = 2.0 * np.sqrt(np.max(disp_var, axis=1)) / slice_dt**2
    return Slices(steps=steps, truth=d.groundtruth[steps, :, :2].copy(), normal=normal, fix=fix, fix_std=fstd,
                  adjacency=adjacency, ranges=ranges, range_std=range_std, velocity=disp / slice_dt,
                  accel_std=accel_std, dead_reckoning=dr[steps, :, :2], own_nav=pose[steps, :, :2], initial=x0)


# --------------------------------------------------------------------------------------------- estimators
class SliceWorld(World):
    """The slices as a world for the ``dnbp`` and ``range_ls`` backends (one copy, k = slice index).

    Motion: ``estimators.cv_models.ConstantVelocityAccel`` with Delta t = 1 s. Readings of slice k: the
    pseudo-fixes (``fix_valid`` = normal), the median ranges of the edges (symmetric), and in ``extra``
    (``coloc_env.backends.particles``' per-step keys) ``velocity`` = Delta p / Delta t to the next slice,
    ``gps_std`` = the largest sigma_fix of the slice's normal robots (``INITIAL_STD`` when none),
    ``range_std`` = the slice's sigma_d (0.1 m when it has no edge), ``accel_std`` = the slice's sigma_acc,
    floored at 1e-3 m, 1e-3 m and 1e-4 m/s^2. ``fix_noise_var`` is ``INITIAL_STD``^2: dNBP's warm start
    spreads the particles by sigma_gps; every step brings its own. Region: ``BOX``.
    """

    agent_prefix = "robot"

    def __init__(self, sl: Slices):
        config = SimpleNamespace(name="mrclam_slices", num_agents=N, dt=SLICE_DT, velocity_spread=INITIAL_STD,
                                 measurements=frozenset({"range", "position_fix"}))
        super().__init__(config, 1, len(sl))
        self.slices = sl
        self.motion_model = ConstantVelocityAccel(SLICE_DT, 0.0)  # sigma_acc comes with each slice's readings

    def fix_noise_var(self) -> float:
        return INITIAL_STD**2

    def range_noise_var(self) -> float:
        return 0.1**2

    def draw_episode(self, rngs, idx) -> None:
        return None  # the slices are the episode

    def positions(self) -> np.ndarray:
        return self.slices.truth[min(int(self.k[0]), len(self.slices) - 1)][None].copy()

    def initial_belief(self):
        mean = np.zeros((1, N, 4))
        mean[0, :, :2] = self.slices.initial[:, :2]
        cov = np.broadcast_to(np.diag([INITIAL_STD**2] * 2 + [0.0, 0.0]), (1, N, 4, 4)).copy()
        return mean, cov

    def region(self):
        return BOX, BOX

    def readings(self, sensing: np.ndarray) -> Readings:
        sl, t = self.slices, int(self.k[0])
        normal, adjacency = sl.normal[t], sl.adjacency[t]
        gps = float(np.max(sl.fix_std[t])) if normal.any() else INITIAL_STD
        range_std = float(sl.range_std[t]) if adjacency.any() else 0.1
        extra = {"velocity": sl.velocity[t][None], "gps_std": np.array([max(gps, 1e-3)]),
                 "range_std": np.array([max(range_std, 1e-3)]),
                 "accel_std": np.array([max(float(sl.accel_std[t]), 1e-4)])}
        return Readings(inputs=np.zeros((1, N, 2)), range=np.where(adjacency, sl.ranges[t], np.nan)[None],
                        range_valid=adjacency[None].copy(), fix=sl.fix[t][None].copy(), fix_valid=normal[None].copy(),
                        extra=extra)


def dnbp_config(particles: int) -> Dnbp:
    """The ``dnbp`` backend of the study: the module docstring's start, ``RANGE_GATE``, the exact kernel."""
    return Dnbp(num_particles=particles, box_margin=0.0, min_bandwidth=0.02, kernel="exact", range_gate=RANGE_GATE)


def _drive(sl: Slices, backend_config, rng: np.random.Generator | None, tally) -> np.ndarray:
    """Run ``backend_config`` over the slices on a lossless ``broadcast`` network: estimates (S, N, 2);
    ``tally(backend)`` after every step."""
    world = SliceWorld(sl)
    network = Broadcast().build(N, 1, backend_config.message_kind, backend_config.rounds)
    backend = backend_config.build(world, network, 1)
    idx = np.arange(1)
    world.reset([None], idx)
    network.reset([np.random.default_rng(0)], idx)  # lossless: no draw is used
    backend.reset([rng], idx)
    transmit = np.ones((1, N, backend_config.rounds), np.int64)
    out = np.empty((len(sl), N, 2))
    for t in range(len(sl)):
        network.begin(world.k, world.positions(), transmit)
        backend.step(world.readings(np.zeros((1, N, 0), np.int64)), np.zeros((1, N, 0)))
        out[t] = backend.posterior_position[0]
        tally(backend)
        world.advance()
    return out


def run_dnbp(sl: Slices, particles: int, seed: int) -> tuple[np.ndarray, dict]:
    """dNBP (the ``dnbp`` backend) over the slices: estimates (S, N, 2) and message counts; generator
    ``default_rng(seed)``."""
    counts = {"messages": 0, "broadcasts": 0, "gated_ranges": 0}

    def tally(backend):
        counts["messages"] += int(backend.last_result.delivered.sum())
        counts["broadcasts"] += int(backend.last_result.broadcasts.sum())
        counts["gated_ranges"] += int(backend.last_gated.sum()) // 2  # each edge is held by both ends

    return _drive(sl, dnbp_config(particles), np.random.default_rng(seed), tally), counts


def run_kalman(sl: Slices, cooperative: bool) -> tuple[np.ndarray, int]:
    """The ``range_ls`` backend over the slices (cooperative: LS fixes from >= 3 normal neighbours; else on the
    slices without ranges, GPS-only): estimates (S, N, 2) and the LS fixes accepted."""
    fixes = [0]

    def tally(backend):
        fixes[0] += int(backend.last_fixed.sum())

    if not cooperative:
        sl = dataclasses.replace(sl, adjacency=np.zeros_like(sl.adjacency))
    return _drive(sl, RangeLs(), None, tally), fixes[0]


def _scores(estimate: np.ndarray, sl: Slices) -> dict:
    e2 = np.sum((estimate - sl.truth) ** 2, axis=-1)
    fault = ~sl.normal
    return {"rmse_fault": float(np.sqrt(e2[fault].mean())), "rmse_all": float(np.sqrt(e2.mean())),
            "mean_err_fault": float(np.sqrt(e2[fault]).mean()),
            "rmse_fault_per_robot": [float(np.sqrt(e2[fault[:, i], i].mean())) if fault[:, i].any() else None
                                     for i in range(N)]}


def run_nbp_study(d: mrclam.MrclamData, seed: int, quick: bool, particles: int | None = None,
                  num_slices: int | None = None) -> dict:
    """dNBP, LS, GPS-only KF, dead reckoning and the own-nav UKF on the slices of ``d`` (module docstring).

    quick: the first ``QUICK_SLICES`` slices (100 s) with ``QUICK_PARTICLES``; else every slice with
    ``PARTICLES``. ``particles`` / ``num_slices`` override (tests). Noise calibrated on ``d``'s first 10 %.
    """
    start = time.perf_counter()
    model = mrclam.NoiseModel.calibrate(d)
    M = particles or (QUICK_PARTICLES if quick else PARTICLES)
    S = num_slices if num_slices is not None else (QUICK_SLICES if quick else None)
    sl = build_slices(d, model, S)
    t0 = time.perf_counter()
    est_dnbp, counts = run_dnbp(sl, M, seed)
    dnbp_s = time.perf_counter() - t0
    est_alone, _ = run_dnbp(dataclasses.replace(sl, adjacency=np.zeros_like(sl.adjacency)), M, seed)
    est_ls, ls_fixes = run_kalman(sl, True)
    est_gps, _ = run_kalman(sl, False)
    estimates = {"dnbp": est_dnbp, "dnbp_no_ranges": est_alone, "ls": est_ls, "gps_only": est_gps,
                 "dead_reckoning": sl.dead_reckoning,
                 "own_nav": sl.own_nav}
    scores = {name: _scores(est, sl) for name, est in estimates.items()}
    err = {name: np.linalg.norm(est - sl.truth, axis=-1) for name, est in estimates.items()}
    fault = ~sl.normal
    with np.errstate(invalid="ignore"):
        err_t = {name: np.where(fault.any(axis=1), np.sum(e * fault, axis=1) / np.maximum(fault.sum(axis=1), 1),
                                np.nan) for name, e in err.items()}
    r = {name: scores[name]["rmse_fault"] for name in METHODS}
    claims = {
        "dnbp_beats_dead_reckoning": bool(r["dnbp"] < r["dead_reckoning"]),
        "dnbp_beats_ls": bool(r["dnbp"] < r["ls"]),
        "dnbp_beats_gps_only": bool(r["dnbp"] < r["gps_only"]),
        "dnbp_beats_own_nav": bool(r["dnbp"] < r["own_nav"]),
        "ranges_help_dnbp": bool(r["dnbp"] < r["dnbp_no_ranges"]),
    }
    edges = sl.adjacency.sum(axis=(1, 2)) / 2
    return {
        "dataset": os.path.basename(os.path.normpath(d.path)), "seed": int(seed), "quick": bool(quick),
        "slices": len(sl), "slice_s": SLICE_STEPS * d.dt, "particles": int(M),
        "iterations": dnbp_config(M).num_iterations,
        "scores": scores, "claims": claims,
        "normal_fraction": float(sl.normal.mean()), "edges_per_slice": float(edges.mean()),
        "fault_with_edge_fraction": float((sl.adjacency.any(axis=2) & fault).sum() / max(fault.sum(), 1)),
        "fault_with_normal_neighbour_fraction": float(
            ((sl.adjacency & sl.normal[:, None, :]).any(axis=2) & fault).sum() / max(fault.sum(), 1)),
        "ls_fixes": int(ls_fixes), "gated_ranges": counts["gated_ranges"], "messages": counts["messages"],
        "broadcasts": counts["broadcasts"],
        "median_fix_std_m": float(np.median(sl.fix_std[sl.normal])) if sl.normal.any() else None,
        "median_range_std_m": float(np.median(sl.range_std[sl.adjacency.any(axis=(1, 2))])),
        "median_accel_std": float(np.median(sl.accel_std)),
        "dnbp_runtime_s": dnbp_s, "runtime_s": time.perf_counter() - start,
        "time_s": (sl.steps * d.dt).tolist(),
        "error_fault_t": {name: [None if np.isnan(v) else float(v) for v in e] for name, e in err_t.items()},
    }


# --------------------------------------------------------------------------------------------- outputs
LABELS = {"dnbp": "dNBP", "dnbp_no_ranges": "dNBP without ranges (ablation)", "ls": "LS (range_ls)",
          "gps_only": "GPS-only KF (pseudo-fixes, no ranges)",
          "dead_reckoning": "dead reckoning (odometry)", "own_nav": "own-nav UKF (heading source)"}


def figure(folder: str, result: dict) -> str:
    """``folder/nbp_error_over_time.png``: mean error of the faulty robots per slice, per method. Returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from train.io import save_figure

    t = np.asarray(result["time_s"])
    fig, ax = plt.subplots(figsize=(9, 4))
    for name, style in (("dead_reckoning", ":"), ("own_nav", "-."), ("gps_only", "--"), ("ls", "-"),
                        ("dnbp_no_ranges", ":"), ("dnbp", "-")):
        e = np.array([np.nan if v is None else v for v in result["error_fault_t"][name]])
        ax.plot(t, e, style, lw=0.8, label=f"{LABELS[name]}: RMSE {result['scores'][name]['rmse_fault']:.3f} m")
    ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("mean error of faulty robots [m]")
    ax.set_title(f"dNBP on {result['dataset']} (landmark sighting = GPS-normal), M = {result['particles']}")
    ax.legend(fontsize=7)
    path = os.path.join(folder, "nbp_error_over_time.png")
    save_figure(path, fig)
    return path


def report_section(result: dict) -> str:
    """Markdown section: the mapping in brief, the table, and what holds (with numbers, negatives included)."""
    s = result["scores"]
    lines = [
        "## dNBP with landmark-sighting robots as GPS-normal (wan2014 on real data)",
        "",
        f"{result['dataset']}, {result['slices']} slices of {result['slice_s']:.0f} s"
        f"{' (quick: the first slices only)' if result['quick'] else ' (the whole run)'}, M = {result['particles']} "
        f"particles, {result['iterations']} iterations, seed {result['seed']}. A robot that sighted a landmark in the "
        "slice is GPS-normal with a pseudo-fix (landmark position, measured range and bearing, own-nav heading; "
        f"median std {result['median_fix_std_m']:.3f} m); the others are faulty and localize by BP from robot-robot "
        f"ranges (median sigma_d {result['median_range_std_m']:.3f} m; bearing unused). Motion prior: odometry "
        "displacement with the heading of each robot's own landmark-aided UKF (dead-reckoned heading drifts by "
        "radians). Normal robot-slices: "
        f"{result['normal_fraction']:.1%}; edges per slice {result['edges_per_slice']:.2f}; faulty robot-slices with "
        f"any range {result['fault_with_edge_fraction']:.1%}, with a normal neighbour "
        f"{result['fault_with_normal_neighbour_fraction']:.1%}; LS fixes accepted: {result['ls_fixes']}.",
        "",
        "| method | RMSE faulty [m] | mean error faulty [m] | RMSE all [m] |",
        "|---|---|---|---|",
    ]
    for name in METHODS:
        lines.append(f"| {LABELS[name]} | {s[name]['rmse_fault']:.3f} | {s[name]['mean_err_fault']:.3f} | "
                     f"{s[name]['rmse_all']:.3f} |")
    r = {name: s[name]["rmse_fault"] for name in METHODS}

    def verdict(a, b):
        holds = r[a] < r[b]
        return (f"* {LABELS[a]} {'beats' if holds else 'does NOT beat'} {LABELS[b]} on the faulty robots: "
                f"{r[a]:.3f} m vs {r[b]:.3f} m ({'holds' if holds else 'does not hold'}).")

    lines += ["", "What holds:", "", verdict("dnbp", "dead_reckoning"), verdict("dnbp", "ls"),
              verdict("dnbp", "gps_only"), verdict("dnbp", "own_nav"), verdict("dnbp", "dnbp_no_ranges"), ""]
    if not result["claims"]["ranges_help_dnbp"]:
        lines += [
              "Diagnosis (why the ranges hurt dNBP here): dNBP's regularized resampling adds N(0, h_rot^2) "
              "jitter at every belief update "
              "(h_rot = sigma ESS^(-1/6), ~ +20 % variance per update at M = 100), so a robot's particle cloud "
              "grows until a pseudo-fix (std ~ 0.5 m) holds it, where the Kalman filters accumulate fixes to "
              "~0.1 m; a faulty robot with one ranged neighbour then slides along that neighbour's ring (the "
              "spec's known flip/ring weakness), and a few misread ranges (residual > 1 m) pull it further. "
              "LS needs >= 3 normal neighbours ranged in one slice, which almost never happens with 5 robots, "
              "so LS is (nearly) the GPS-only KF.", ""]
    lines += [f"Ranges dropped by the gate: {result['gated_ranges']}. "
              f"dNBP time: {result['dnbp_runtime_s']:.1f} s for {result['slices']} slices "
              f"({result['messages']} messages, {result['broadcasts']} broadcasts); study total "
              f"{result['runtime_s']:.1f} s.", ""]
    return "\n".join(lines)
