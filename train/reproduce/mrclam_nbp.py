"""dNBP (wan2014) on real robot data: UTIAS MRCLAM, landmark-sighting robots as the "GPS-normal" UAVs.

The ``dnbp`` backend (``estimators.dnbp``, Wan et al. 2014, reconstructed in
``docs/wan2014.md``) and the least-squares baseline ``range_ls``
(``coloc_env.backends.particles``) are driven by the composed core
(``coloc_env.scenarios.composed.ComposedScenario``), through a lossless
``broadcast`` network, on the ``mrclam_slices`` world
(``coloc_env.worlds.mrclam_slices``: one MRCLAM dataset in 1-s slices, the
robots that sighted a landmark in a slice GPS-normal with a pseudo-fix, the
others faulty with robot-robot ranges; its docstring gives every rule of the
mapping; cite Leung et al., IJRR 2011). No Vicon data after the calibration
window enters any estimator; Vicon is used for the noise calibration (the
first 10 % of the run, the rule of ``coloc_env.data.mrclam_noise.NoiseModel``, as in
``coloc reproduce mrclam``), for the initial poses and for scoring.

The plan (every choice)
-----------------------

* **Slices.** The world's defaults (10 data steps of 0.1 s: Delta t = 1 s), from
  slice 0 (``start=0``): the first ``QUICK_SLICES`` slices (``--quick``) or the
  whole run. dNBP's constant-velocity model is fed each slice's displacement
  through its velocity slot (the readings' ``velocity``, to which every
  particle's velocity is set before the step, zero acceleration input) with the
  slice's sigma_acc, sigma_gps and sigma_d (the readings' per-step ``accel_std``,
  ``gps_std``, ``range_std``).
* **Range gate** (``RANGE_GATE``, the ``dnbp`` backend's ``range_gate``; our
  addition, not the paper's): before a step a range is dropped when (d_st -
  ||mean_s - mean_t||)^2 / (sigma_d^2 + var_s + var_t) > 10.83 (chi-square(1)
  99.9 %), means and per-axis variances of dNBP's OWN prior particles: misread
  barcodes give ranges metres off (4 of 1,441 edges of dataset 6 have a residual
  > 1 m). It lowered the full-run dNBP RMSE from 1.15 m to 0.97 m (M = 100,
  seed 0); ``ls`` has its own gate.
* **Start.** All estimators start from the Vicon pose at step 0 (the setup of
  ``coloc reproduce mrclam``), std ``INITIAL_STD`` (the world's ``initial_std``;
  dNBP's warm start spreads its particles by it). dNBP: ``min_bandwidth`` 0.02 m
  (the spec's 0.5 m is for 200-m UAV ranges; robots range at 1-5 m), defensive
  box ``BOX`` per axis (the world's ``region``: the arena and landmarks with a
  margin), ``num_particles`` ``PARTICLES`` (``QUICK_PARTICLES``), 5 iterations,
  the paper's modified schedule, the exact kernel.

Methods, on the same slices: ``dnbp``; ``dnbp_no_ranges`` (the same on the world
without ranges, ``ranges=False``: the ablation); ``ls`` (the ``range_ls`` backend:
the fault robot fixed from >= 3 normal neighbours, gated, fed to a KF with the
same displacement prior and pseudo-fixes: the velocity reading sets the KF's
velocity, with zero variance, before each step); ``gps_only`` (the same backend
on the world without ranges: the DR / GPS-only baseline of wan2014);
``dead_reckoning`` (odometry integrated with its own dead-reckoned heading, the
``IL`` of ``coloc reproduce mrclam``); ``own_nav`` (the heading source's
position, the world's ``Slices.own_nav``: reference). Score: position RMSE
against Vicon pooled over (slice, robot) where the robot is faulty
(``rmse_fault``) and over all (``rmse_all``); dNBP is random, its generator is
``np.random.default_rng(seed)``.
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

import estimators.ukf_relay_se2 as se2
from coloc_env.backends.particles import Dnbp, RangeLs
from coloc_env.composition import compose
from coloc_env.data import mrclam, mrclam_noise
from coloc_env.env import build_scenario
from coloc_env.networks.broadcast import Broadcast
from coloc_env.scenarios.composed import ComposedScenario
from coloc_env.worlds.mrclam_slices import MrclamSlices, Slices

PARTICLES = 100
QUICK_PARTICLES = 100
QUICK_SLICES = 100
INITIAL_STD = 0.01  # m and rad, as coloc reproduce mrclam
BOX = (-6.0, 9.0)
RANGE_GATE: float | None = 10.83  # chi-square(1) 99.9 %: a range vs the distance of dNBP's own prior means
METHODS = ("dnbp", "dnbp_no_ranges", "ls", "gps_only", "dead_reckoning", "own_nav")
N = mrclam.NUM_ROBOTS


# --------------------------------------------------------------------------------------------- the world
def slice_world(d: mrclam.MrclamData, num_slices: int | None = None) -> MrclamSlices:
    """The ``mrclam_slices`` world of the study on the run ``d``: slices 0..num_slices-1 (all by default), the
    start of the module docstring (``INITIAL_STD``, ``BOX``)."""
    world = MrclamSlices(data=d.path, start=0, initial_std=INITIAL_STD, region=BOX)
    S = len(world.tables()[1])
    return dataclasses.replace(world, horizon=S if num_slices is None else min(int(num_slices), S))


def slices_of(world: MrclamSlices) -> Slices:
    """The slices the world's episode replays (its first ``horizon`` from ``start``)."""
    table = world.tables()[1]
    window = slice(world.start, world.start + world.horizon)
    return dataclasses.replace(table, **{f.name: getattr(table, f.name)[window]
                                         for f in dataclasses.fields(table) if f.name != "dt"})


def dead_reckoning(d: mrclam.MrclamData, model: mrclam_noise.NoiseModel, x0: np.ndarray) -> np.ndarray:
    """Odometry alone, heading dead-reckoned too: poses (T, N, 3)."""
    u = model.odometry(d, np.arange(d.steps))
    out = np.empty((d.steps, N, 3))
    x = np.array(x0, float)
    for k in range(d.steps):
        out[k] = x
        x = se2.motion(x, u[k], d.dt)[0]
    return out


# --------------------------------------------------------------------------------------------- estimators
def dnbp_config(particles: int) -> Dnbp:
    """The ``dnbp`` backend of the study: the module docstring's start, ``RANGE_GATE``, the exact kernel."""
    return Dnbp(num_particles=particles, box_margin=0.0, min_bandwidth=0.02, kernel="exact", range_gate=RANGE_GATE)


class _StudyCore(ComposedScenario):
    """The composed core with the backend's generator given (``backend_rng``: the study's stream,
    ``default_rng(seed)``) instead of a child of the episode's; the world (a fixed start) and the lossless
    network draw nothing from theirs."""

    backend_rng: np.random.Generator | None = None

    def part_generators(self, rng: np.random.Generator) -> tuple:
        return rng, rng, self.backend_rng


def _drive(world_config: MrclamSlices, backend_config, rng: np.random.Generator | None, tally) -> np.ndarray:
    """Run ``backend_config`` over the world's episode (one copy) on a lossless ``broadcast`` network through the
    composed core (``ComposedScenario.step``, every robot transmitting in every round: the ``always`` action):
    estimates (S, N, 2), the backend's generator ``rng``; ``tally(backend)`` after every step."""
    spec = compose(world=world_config, network=Broadcast(), backend=backend_config)
    core = build_scenario(_StudyCore, 1, spec)
    core.backend_rng = rng
    core.reset([np.random.default_rng(0)])
    always = np.broadcast_to(core.action_vector("maximum"), (1, N, len(core.action_vector("maximum"))))
    out = np.empty((core.horizon, N, 2))
    for t in range(core.horizon):
        core.step(always)
        out[t] = core.backend.posterior_position[0]
        tally(core.backend)
    return out


def run_dnbp(world: MrclamSlices, particles: int, seed: int) -> tuple[np.ndarray, dict]:
    """dNBP (the ``dnbp`` backend) over the world's slices: estimates (S, N, 2) and message counts; generator
    ``default_rng(seed)``."""
    counts = {"messages": 0, "broadcasts": 0, "gated_ranges": 0}

    def tally(backend):
        counts["messages"] += int(backend.last_result.delivered.sum())
        counts["broadcasts"] += int(backend.last_result.broadcasts.sum())
        counts["gated_ranges"] += int(backend.last_gated.sum()) // 2  # each edge is held by both ends

    return _drive(world, dnbp_config(particles), np.random.default_rng(seed), tally), counts


def run_kalman(world: MrclamSlices, cooperative: bool) -> tuple[np.ndarray, int]:
    """The ``range_ls`` backend over the world's slices (cooperative: LS fixes from >= 3 normal neighbours; else
    on the world without ranges, GPS-only): estimates (S, N, 2) and the LS fixes accepted."""
    fixes = [0]

    def tally(backend):
        fixes[0] += int(backend.last_fixed.sum())

    if not cooperative:
        world = dataclasses.replace(world, ranges=False)
    return _drive(world, RangeLs(), None, tally), fixes[0]


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
    ``PARTICLES``. ``particles`` / ``num_slices`` override (tests). Noise calibrated on ``d``'s first 10 %
    (the world's noise model).
    """
    start = time.perf_counter()
    M = particles or (QUICK_PARTICLES if quick else PARTICLES)
    world = slice_world(d, num_slices if num_slices is not None else (QUICK_SLICES if quick else None))
    sl = slices_of(world)
    model = world.tables()[0].noise_model
    t0 = time.perf_counter()
    est_dnbp, counts = run_dnbp(world, M, seed)
    dnbp_s = time.perf_counter() - t0
    est_alone, _ = run_dnbp(dataclasses.replace(world, ranges=False), M, seed)
    est_ls, ls_fixes = run_kalman(world, True)
    est_gps, _ = run_kalman(world, False)
    dr = dead_reckoning(d.window(0, int(sl.steps[-1]) + 1), model, d.groundtruth[0])[sl.steps, :, :2]
    estimates = {"dnbp": est_dnbp, "dnbp_no_ranges": est_alone, "ls": est_ls, "gps_only": est_gps,
                 "dead_reckoning": dr, "own_nav": sl.own_nav}
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
        "slices": len(sl), "slice_s": sl.dt, "particles": int(M),
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
