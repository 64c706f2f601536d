"""The estimators on real data: UTIAS MRCLAM (``coloc reproduce mrclam --data DIR``).

Data: Leung K.Y.K., Halpern Y., Barfoot T.D., Liu H.H.T., "The UTIAS
multi-robot cooperative localization and mapping dataset", IJRR
30(8):969-974, 2011 (cite it with these results). Not part of
``coloc reproduce all``: it needs a dataset folder (``--data`` or
``COLOC_MRCLAM_DATA``).

Estimators (``estimators.ukf_relay_se2``, state (x, y, theta) per robot):

* ``IL``  dead reckoning from the odometry (v, w), covariance by the same
  linearized time update (no measurements): the ``dead_reckoning`` backend;
* ``CCL`` UKF-CCL on the joint state, every robot-to-robot (range, bearing)
  and every landmark sighting, in file order within a step (its own loop
  here: the independent check that DCL equals it);
* ``DCL`` UKF-DCL over the complete relay chain m -> n -> each hop on to the
  nearest robot not yet reached (landmark: m -> the others alike) with the
  Roumeliotis-Bekey factorization (any complete chain gives the CCL update):
  the ``ukf_se2`` backend (``landmark_updates="relay"``) over the ``ideal``
  network; IL and DCL both driven by the ``mrclam`` world's replay (``run_filters``).

Setup (stated in ``report.md``): initial state = the Vicon pose at the first
step with standard deviations ``INITIAL_STD`` (0.01 m, 0.01 m, 0.01 rad).
Observations with a normalized innovation above the chi-square(2) 99.9 %
quantile are rejected (the same in CCL and DCL). The filters run over the
whole run; no ground truth after the calibration window enters them. The
whole-run columns include the calibration window; ``evaluation`` reports each
model on the steps after it only (the part the noise was not fitted on).

Noise models, every parameter from the calibration window
(``coloc_env.data.mrclam_noise.calibration_seconds``: the first 10 % of the
run, at least 60 s: 75.6 s of dataset 6, 60 s of a ``--quick`` run) against
Vicon, applied per step by ``coloc_env.data.mrclam_noise.NoiseModel`` (the same
code as the ``mrclam`` world and the ``mrclam_relay`` scenario):

* per-step shapes by moment rules (``coloc_env.data.mrclam_noise.calibrate_noise``):
  the robots move as the command logged ``odometry_delay_steps`` earlier
  (0.2 s) times a scale (``odometry_scale``: they turn ~18 % and drive ~10 %
  less than commanded); odometry variances a_c + b_c u_c^2 (least squares of
  the squared residual); sigma_r^2 = a_r + b_r r^2 and sigma_b (68.27th
  percentile of |residual|);
* ``likelihood`` (the reported model): the four variances scaled by
  (c_v, c_w, c_range, c_bearing) that maximize the composite likelihood of
  UKF-CCL's pose errors against Vicon on the window
  (``coloc_env.data.mrclam_noise.fit_noise_scales``): the odometry errors are
  correlated over seconds (lag-1 autocorrelation 0.37 in v, a per-robot bias)
  and successive sightings of one subject share their error, which a white
  model cannot represent; the scales absorb both into the white model at the
  rate the filter actually integrates them (its own observation schedule);
* ``calibrated`` (``*_moments`` in metrics.json): the same shapes with the
  moment rules' inflations (the ratio of the actual to the white-model second
  moment of the odometry error summed over the correction horizon, the
  burst-sum ratio of the measurement errors), the model before the fit;
* ``baseline`` (``*_baseline``): constant 1.4826 x MAD noise over the first
  60 s, raw commands; ``ablation_no_measurement_inflation``: the moment rules
  without the measurement inflation.

Writes ``OUT/mrclam/metrics.json``: ``rmse_position`` {"IL"|"CCL"|"DCL":
{"robot1".."robot5", "mean"}} (m), ``rmse_heading`` (rad, same shape),
``nees_mean`` (same shape; expectation 3), ``max_abs_diff_dcl_ccl`` (state
and covariance, worst over the models), ``duration_s``, ``steps``,
``noise`` (the moment rules' keys and the fit's ``likelihood_*``),
``observations``, ``nees_fraction_in_band`` (CCL, chi-square(3) 95 % band),
``evaluation`` {"likelihood"|"calibrated"|"baseline"|"odometry_only": CCL on the steps
after the calibration window: ``nees_mean``, ``fraction_in_band``,
``rmse_position_mean``, ``nees_position``, ``nees_heading``, ``from_step``, ``steps``},
``rmse_position_moments``, ``nees_mean_moments``, ``nees_fraction_in_band_moments``,
the same with ``_baseline`` (``noise_baseline``,
``rmse_position_baseline``, ``rmse_heading_baseline``,
``nees_mean_baseline``, ``observations_baseline``), ``claims``;
``report.md`` and figures ``trajectories.png``, ``error_over_time.png``,
``nees.png`` (calibrated model).

Lossy / hop-limited links (``lossy_link_study``): the
``mrclam_relay`` scenario core, driven with the ``paper`` policy's actions
(complete chains m -> n -> the others ascending) over the whole run (window
start 0), runs UKF-DCL for each link setting of ``link_settings``: a
per-hop loss probability ``loss_at_zero`` in ``LOSS_LEVELS`` (0 = the
lossless complete chain, which is UKF-CCL on the scenario's observations) and
a hop budget ``max_hops`` in ``HOP_BUDGETS`` (lossless), plus IL by the
same noise model. Lossy settings run ``LOSS_DRAWS`` loss realizations
(copies seeded ``seed + b``; the same uniforms in every setting). ``--quick``:
one seeded window of ``QUICK_STUDY_STEPS`` steps, one draw. Written to
``metrics.json`` as ``lossy_links`` {setting | "IL": {"rmse_position_mean",
"rmse_position_draws", "nees_mean", "hops_per_step", "delivered_fraction",
"complete_fraction", "used_fraction", "chains_per_step", "draws", and the
setting's config fields}}, ``lossy_links_setup`` (window, start, seed,
draws, ``il_abs_diff_to_reproduction`` on a full run) and ``claims``
``lossy_*`` / ``hop_budget_1_worse_than_complete_chain``; figure
``lossy_links.png``.
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

import estimators.ukf_relay_se2 as se2
from coloc_env.config import BadInput
from coloc_env.data import mrclam, mrclam_noise
from train.io import save_figure, write_json, write_text
from train.reproduce import mrclam_nbp

KEY = "mrclam"
RUNS = 1  # the data is one recorded run: no Monte Carlo
QUICK_RUNS = 1
QUICK_STEPS = 1500  # --quick: the first 150 s
INITIAL_STD = (0.01, 0.01, 0.01)
GATE = mrclam_noise.GATE_999  # chi-square(2) 0.999 quantile
N = mrclam.NUM_ROBOTS


def _backend_parts(d: mrclam.MrclamData, noise: dict, model: mrclam_noise.NoiseModel, kind: str,
                   inflate_measurements: bool):
    """The ``mrclam`` world replaying ``d`` (batch 1, start 0, horizon T - 1) and, over the ``ideal`` network,
    the ``ukf_se2`` (DCL) and ``dead_reckoning`` (IL) backends on it, reset; the world's noise model is
    checked to be ``model``, the one ``noise`` gives (ValueError otherwise)."""
    import coloc_env

    full = mrclam.load_cached(d.path, d.dt)
    if d.steps < 2 or d.t0 != full.t0 or d.steps > full.steps:
        raise BadInput(f"run_filters needs a run or a prefix of it (the world replays {d.path} from step 0) "
                       f"of at least 2 steps; got {d.steps} steps from t0 = {d.t0}")
    if INITIAL_STD[0] != INITIAL_STD[1]:
        raise BadInput(f"the world has one initial position std for x and y, got INITIAL_STD = {INITIAL_STD}")
    world = {"name": "mrclam", "data": d.path, "dt": d.dt, "horizon": d.steps - 1, "start": 0,
             "noise_model": kind, "calibration_s": float(noise["calibration_s"]),
             "measurement_inflation": bool(inflate_measurements) or kind == "baseline",
             "robot_sightings": "all", "initial_position_std": INITIAL_STD[0],
             "initial_heading_std": INITIAL_STD[2]}
    dcl = coloc_env.compose(world=world, network="ideal", backend={"name": "ukf_se2", "gate": GATE,
                                                                       "landmark_updates": "relay"})
    il = coloc_env.compose(world=dcl.world, network="ideal", backend="dead_reckoning")
    w = dcl.world.build(1, dcl.episode_steps)
    network = dcl.network.build(w.num_agents, 1, dcl.backend.message_kind)
    backends = dcl.backend.build(w, network, 1), il.backend.build(w, network, 1)
    w.fixes_needed = any(b.reads_fixes for b in backends)  # neither reads the pseudo-fixes: none are made
    if w.noise_model != model:  # the world fits its own model: it must be the one the caller calibrated
        raise BadInput(f"the mrclam world's {kind} noise model (fitted on the first "
                       f"{noise['calibration_s']:g} s of {d.path}) differs from the given noise dict")
    # nothing is drawn (fixed start, lossless network); the generators only fill the interface
    rngs = np.random.default_rng(0).spawn(3)
    idx = np.arange(1)
    w.reset(rngs[:1], idx)
    network.reset(rngs[1:2], idx)
    for backend in backends:
        backend.reset(rngs[2:], idx)
    return w, network, *backends


def run_filters(d: mrclam.MrclamData, noise: dict, progress=None, baseline: bool = False,
                inflate_measurements: bool = True, kind: str | None = None) -> dict:
    """IL, CCL and DCL over the whole of ``d``; estimates (T, N, 3) and own-block covariances (T, N, 3, 3).

    ``noise``: a ``coloc_env.data.mrclam_noise.calibrate_noise`` dict, applied by
    ``coloc_env.data.mrclam_noise.NoiseModel``: ``baseline`` the constant 1.4826 x MAD noise on the
    raw commands (the model before calibration), else the calibrated model
    (``inflate_measurements=False``: without its measurement inflation, for the ablation).

    DCL and IL are the composition's backends, driven step by step as
    ``coloc_env.scenarios.composed.ComposedScenario.advance`` drives them: the ``mrclam`` world
    (``coloc_env.worlds.mrclam``, ``robot_sightings="all"``, the same noise model, fitted on the same
    window) replays ``d`` into ``ukf_se2`` (``coloc_env.backends.ukf_se2``: UKF-DCL over the ``ideal``
    network's complete chains, landmark sightings relayed too: ``landmark_updates="relay"``) and ``dead_reckoning``
    (``coloc_env.backends.dead_reckoning``). CCL (``ccl_update`` on the joint state) reads ``d`` and the
    noise model itself: the independent check that DCL equals CCL (``max_abs_diff``, state and joint
    covariance), and of the world's replay. ``d`` must be a loaded run or a prefix of it (``window(0, S)``)
    and ``noise`` its ``coloc_env.data.mrclam_noise.calibrate_noise`` of ``d`` (the world refits it on the
    run: ValueError if the two differ).
    """
    kind = kind or ("baseline" if baseline else "calibrated")
    model = mrclam_noise.NoiseModel.from_calibration(noise, kind, inflate_measurements=inflate_measurements)
    world, network, dcl, il = _backend_parts(d, noise, model, kind, inflate_measurements)
    odometry = model.odometry(d, np.arange(d.steps))  # corrected u'[k] (T, N, 2)
    Q = model.odometry_var(odometry)  # per-step, per-robot variances (T, N, 2)
    P0 = np.diag(np.tile(np.square(INITIAL_STD), N))
    x_c, P_c = d.groundtruth[0].copy(), P0.copy()
    T = d.steps
    out = {name: np.empty((T, N, 3)) for name in ("IL", "CCL", "DCL")}
    cov = {name: np.empty((T, N, 3, 3)) for name in ("IL", "CCL", "DCL")}
    diag = np.arange(N)
    counts = {"robot": 0, "landmark": 0, "rejected": 0}
    worst = 0.0
    sensing = np.full((1, N, 1), N)  # every robot each one recorded (with robot_sightings="all": every line)
    transport, decisions = np.zeros((1, N, 0), np.int64), np.zeros((1, N, 0))  # neither part has any
    for k in range(T):
        readings = world.readings(sensing)
        network.begin(world.k, world.positions().copy(), transport)
        dcl.update(readings, decisions)
        il.update(readings, decisions)
        s = d.measurements_at(k)
        applied, rejected = np.zeros(N), np.zeros(N)
        for r, sub, rg, b in zip(d.meas_robot[s], d.meas_subject[s], d.meas_range[s], d.meas_bearing[s], strict=True):
            z = np.array([rg, b])
            R = model.measurement_cov(float(rg))  # R from the measured range
            if sub <= N:
                x_c, P_c, ok = se2.ccl_update(x_c, P_c, int(r), z, R, measured=int(sub) - 1, gate=GATE)
            else:
                lm = d.landmarks[sub - N - 1]
                x_c, P_c, ok = se2.ccl_update(x_c, P_c, int(r), z, R, landmark=lm, gate=GATE)
            applied[r] += ok
            rejected[r] += not ok
            counts["rejected" if not ok else ("robot" if sub <= N else "landmark")] += 1
        # the backend records per observer and step, so the gate (and the world's replay) is compared at that grain
        if not (np.array_equal(applied, dcl.applied[0]) and np.array_equal(rejected, dcl.rejected[0])):
            raise RuntimeError(f"step {k}: the gate decided differently in CCL and DCL")
        out["CCL"][k], out["DCL"][k], out["IL"][k] = x_c, dcl.estimate[0], il.mean[0]
        cov["CCL"][k] = P_c.reshape(N, 3, N, 3)[diag, :, diag, :]
        cov["DCL"][k], cov["IL"][k] = dcl.P_ii[0], il.cov[0]
        worst = max(worst, float(np.abs(x_c - dcl.estimate[0]).max()), float(np.abs(P_c - dcl.joint_cov(0)).max()))
        if k + 1 < T:  # the world's horizon is T - 1: step T - 1 is read and updated, not predicted past
            dcl.predict(readings.inputs)
            il.predict(readings.inputs)
            world.advance()
            x_c, P_c = se2.time_update(x_c, P_c, odometry[k], d.dt, Q[k])
        if progress and k % 1000 == 0:
            progress(f"step {k}/{T}")
    return {"estimate": out, "cov": cov, "counts": counts, "max_abs_diff": worst}


# ---------------------------------------------------------------- DCL over lossy / hop-limited links

LOSS_LEVELS = (0.0, 0.3, 0.6, 0.9)  # loss_at_zero of every hop (loss_length = inf: independent of the distance)
HOP_BUDGETS = (1,)  # max_hops, lossless: the measured robot only
LOSS_DRAWS = 1  # loss realizations per lossy setting on the whole run (copies seeded seed, seed + 1, ...);
# 2 draws of dataset 6 (seeds 0, 1) differed by <= 0.003 m in RMSE, so one keeps the run under 5 minutes
QUICK_STUDY_STEPS = 300  # --quick: one seeded window of this many steps, one draw


def link_settings() -> dict[str, dict]:
    """The study's link settings: name -> ``mrclam_relay`` config fields (complete chains otherwise)."""
    settings = {("lossless" if p == 0 else f"loss_{p:g}"): {"loss_at_zero": float(p)} for p in LOSS_LEVELS}
    settings.update({f"hops_{h}": {"max_hops": int(h)} for h in HOP_BUDGETS})
    return settings


def _own_nees(error: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(..., N) NEES of (x, y, theta) from errors (..., N, 3) (heading wrapped here) and own blocks."""
    e = error.copy()
    e[..., 2] = se2.wrap(e[..., 2])
    return np.einsum("...a,...ab,...b->...", e, np.linalg.inv(cov), e)


def _il_core(scenario, start: int, steps: int):
    """IL on the study's window: a batched core (batch 1) of the scenario's ``mrclam`` world with the window
    fixed (``start``, ``steps``), the ``ideal`` network and the ``dead_reckoning`` backend (the noise model's
    odometry from the Vicon pose at the window start, the covariance by the same time update), reset."""
    import coloc_env
    from coloc_env.scenarios.composed import ComposedScenario

    world = dataclasses.replace(scenario.composition.world, start=start, horizon=steps)
    core = ComposedScenario(coloc_env.compose(world=world, network="ideal", backend="dead_reckoning"), batch=1)
    core.reset([np.random.default_rng(0)])  # nothing is drawn: the window is fixed, the network lossless
    return core


def lossy_link_study(data: str, window_steps: int, seed: int, settings: dict[str, dict] | None = None,
                     draws: int = LOSS_DRAWS, progress=None) -> dict:
    """UKF-DCL of the ``mrclam_relay`` scenario under the paper policy for each link setting, and IL.

    Drives the scenario core (``coloc_env.scenario_class``) with ``window_steps`` (``T - 1``: the whole
    run, window start 0) and the actions of ``agents.mrclam_relay.paper_actions`` from its observation
    (the ``paper`` policy: the lowest-index recorded robot, complete chains m -> n -> the others ascending).
    Copy b of a setting is reset with ``default_rng(seed + b)``: the same window and the same loss uniforms in
    every setting, so the losses are coupled (more loss, never more hops). A lossy setting runs ``draws``
    copies (loss realizations) when the window is the whole run, one otherwise; a lossless one runs one.

    The errors are taken at the window start (the Vicon pose, error 0) and after each step, against Vicon, as
    ``run_filters`` does. IL = the ``dead_reckoning`` backend on the scenario's world, the window fixed to
    copy 0's (``_il_core``): the noise model's odometry from the window start, with the covariance of the
    same time update. Per setting: ``rmse_position_mean`` (per-robot RMSE over the steps,
    mean over robots, mean over draws), ``rmse_position_draws``, ``nees_mean`` (x, y, theta; expectation 3),
    ``hops_per_step`` (delivered hops of all chains per step), ``delivered_fraction`` (delivered hops over the
    N - 1 hops of each complete chain), ``complete_fraction`` (chains that reached every robot),
    ``used_fraction`` (chosen robot measurements that reached the measured robot and passed the gate).
    """
    import coloc_env
    from agents.mrclam_relay import paper_actions

    settings = link_settings() if settings is None else settings
    cls = coloc_env.scenario_class("mrclam_relay")
    results, start = {}, None
    for index, (name, fields) in enumerate(settings.items()):
        first = index == 0  # IL runs alongside the first setting, on copy 0's window
        # the moment rules' model, as this study's report says (the scenario's default is "likelihood")
        config = cls.Config(data=data, window_steps=int(window_steps), **{"noise_model": "calibrated", **fields})
        scenario = cls(config, batch=1)
        lossy = config.loss_at_zero > 0 or config.loss_length < np.inf
        whole = window_steps >= scenario.world.data.steps - 1
        B = draws if lossy and whole else 1
        if B > 1:
            scenario = cls(config, batch=B)
        N, W = scenario.num_agents, scenario.horizon
        scenario.reset([np.random.default_rng(seed + b) for b in range(B)])
        start = scenario.world.start.copy() if start is None else start
        if not np.array_equal(scenario.world.start[:1], start[:1]):
            raise RuntimeError("the settings' windows differ for one seed")
        sq = np.zeros((B, N))  # summed squared position errors
        nees = np.zeros((B, N))
        il_sq, il_nees = np.zeros(N), np.zeros(N)
        il = _il_core(scenario, int(start[0]), W) if first else None
        hops = chains = complete = chosen = used = 0
        for k in range(W + 1):
            truth = scenario.world.poses()
            error = scenario.backend.estimate - truth
            sq += np.sum(error[..., :2] ** 2, axis=-1)
            nees += _own_nees(error, scenario.backend.P_ii)
            if il is not None:
                e_il = il.backend.mean[0] - truth[0]
                il_sq += np.sum(e_il[:, :2] ** 2, axis=-1)
                il_nees += _own_nees(e_il, il.backend.cov[0])
            if k == W:
                break
            if il is not None:
                il.step(np.full((1, N, 1), N))  # the world's sensing entry; dead reckoning reads the inputs only
            recorded = scenario.observation()[..., N:2 * N] > 0.5  # what PaperPolicy reads
            scenario.step(paper_actions(recorded))
            relay = scenario.backend.chains
            hops += int(relay.hops.sum())
            chains += int(np.sum(relay.length > 0))
            complete += int(np.sum(relay.length == N))
            chosen += int(np.sum(scenario.backend.partner >= 0))
            used += int(np.sum(scenario.backend.used))
            if progress and k % 2000 == 0:
                progress(f"lossy links {name}: step {k}/{W}")
        rmse = np.sqrt(sq / (W + 1)).mean(axis=-1)  # (B,) mean over robots of the per-robot RMSE
        results[name] = {
            **fields, "draws": B, "rmse_position_mean": float(rmse.mean()), "rmse_position_draws": rmse.tolist(),
            "nees_mean": float(nees.mean() / (W + 1)), "hops_per_step": hops / (B * W),
            "delivered_fraction": hops / max(1, chains * (N - 1)), "complete_fraction": complete / max(1, chains),
            "used_fraction": used / max(1, chosen), "chains_per_step": chains / (B * W)}
        if first:
            results["IL"] = {"draws": 1, "rmse_position_mean": float(np.sqrt(il_sq / (W + 1)).mean()),
                             "rmse_position_draws": [float(np.sqrt(il_sq / (W + 1)).mean())],
                             "nees_mean": float(il_nees.mean() / (W + 1)), "hops_per_step": 0.0,
                             "delivered_fraction": 0.0, "complete_fraction": 0.0, "used_fraction": 0.0,
                             "chains_per_step": 0.0}
    return {"settings": results, "window_steps": int(window_steps), "window_start": int(start[0]), "seed": int(seed),
            "draws": int(draws)}


def _errors(d, estimate, cov):
    e = estimate - d.groundtruth
    e[..., 2] = se2.wrap(e[..., 2])
    pos = np.hypot(e[..., 0], e[..., 1])
    nees = np.einsum("tna,tnab,tnb->tn", e, np.linalg.inv(cov), e)
    return pos, np.abs(e[..., 2]), nees


def _nees_split(d, estimate, cov) -> dict:
    """CCL NEES of the position block (expectation 2) and of the heading (expectation 1), the median of the
    full NEES (chi-square(3) median 2.37) and the lag-50-step (5 s) autocorrelation of the position error."""
    e = estimate - d.groundtruth
    e[..., 2] = se2.wrap(e[..., 2])
    position = np.einsum("tna,tnab,tnb->tn", e[..., :2], np.linalg.inv(cov[..., :2, :2]), e[..., :2])
    nees = np.einsum("tna,tnab,tnb->tn", e, np.linalg.inv(cov), e)
    lag = min(50, len(e) - 1)
    p = e[..., :2] - e[..., :2].mean(axis=0)
    acf = float(np.sum(p[lag:] * p[:-lag]) / np.sum(p * p)) if lag > 0 else 0.0
    return {"position": float(position.mean()), "heading": float(np.mean(e[..., 2] ** 2 / cov[..., 2, 2])),
            "median": float(np.median(nees)), "position_error_autocorr_5s": acf}


def _band_fraction(nees: np.ndarray) -> float:
    """Fraction of (step, robot) NEES values inside the chi-square(3) 95 % band."""
    from scipy.stats import chi2

    lo, hi = chi2.ppf([0.025, 0.975], 3)
    return float(np.mean((nees >= lo) & (nees <= hi)))


def _evaluation(d, result: dict, start: int) -> dict:
    """``_evaluation_of`` UKF-CCL."""
    return _evaluation_of(d, result, start, "CCL")


def _evaluation_of(d, result: dict, start: int, name: str) -> dict:
    """Estimator ``name`` of a ``run_filters`` result on the steps the noise was not fitted on
    (k >= ``start``): mean NEES (x, y, theta), the fraction of (step, robot) values in the chi-square(3)
    95 % band, position RMSE (mean over robots), position / heading NEES."""
    if start >= d.steps:
        return {"from_step": int(start), "steps": 0}
    est, cov = result["estimate"][name][start:], result["cov"][name][start:]
    e = est - d.groundtruth[start:]
    e[..., 2] = se2.wrap(e[..., 2])
    nees = np.einsum("tna,tnab,tnb->tn", e, np.linalg.inv(cov), e)
    position = np.einsum("tna,tnab,tnb->tn", e[..., :2], np.linalg.inv(cov[..., :2, :2]), e[..., :2])
    return {"from_step": int(start), "steps": int(d.steps - start), "nees_mean": float(nees.mean()),
            "fraction_in_band": _band_fraction(nees),
            "rmse_position_mean": float(np.sqrt(np.mean(np.sum(e[..., :2] ** 2, axis=-1), axis=0)).mean()),
            "nees_position": float(position.mean()), "nees_heading": float(np.mean(e[..., 2] ** 2 / cov[..., 2, 2]))}


def _per_robot(values: np.ndarray) -> dict:
    row = {f"robot{i + 1}": float(values[i]) for i in range(N)}
    row["mean"] = float(np.mean(values))
    return row


def run(out: str, runs: int = RUNS, seed: int = 0, quick: bool = False, executor: str = "local",
        address: str | None = None, config=None, progress=None, data: str | None = None) -> dict:
    """Run IL/CCL/DCL on one MRCLAM dataset folder, write ``out/mrclam/``, return the metrics dict.

    ``runs``, ``seed``, ``executor``, ``address`` and ``config`` are accepted for the
    common ``reproduce`` interface; the computation is deterministic and local.
    """
    start = time.perf_counter()
    d = mrclam.load_cached(data)
    if quick:
        d = d.window(0, min(QUICK_STEPS, d.steps))
    if progress:
        progress(f"loaded {d.path}: {d.steps} steps of {d.dt} s")
    moments = mrclam_noise.calibrate_noise(d, mrclam_noise.calibration_seconds(d, "calibrated"))
    calibration_steps = int(round(moments["calibration_s"] / d.dt))
    noise = {**moments, **mrclam_noise.fit_noise_scales(d, moments, calibration_steps)}
    noise_baseline = mrclam_noise.calibrate_noise(d, mrclam_noise.calibration_seconds(d, "baseline"))
    results = {"likelihood": run_filters(d, noise, progress, kind="likelihood"),
               "calibrated": run_filters(d, moments, progress),
               "baseline": run_filters(d, noise_baseline, progress, baseline=True),
               "odometry_only": run_filters(d, noise, progress, inflate_measurements=False)}
    summary = {}
    for model, result in results.items():
        pos_rmse, head_rmse, nees_mean, series = {}, {}, {}, {}
        for name in ("IL", "CCL", "DCL"):
            pos, head, nees = _errors(d, result["estimate"][name], result["cov"][name])
            series[name] = (pos, nees)
            pos_rmse[name] = _per_robot(np.sqrt(np.mean(pos**2, axis=0)))
            head_rmse[name] = _per_robot(np.sqrt(np.mean(head**2, axis=0)))
            nees_mean[name] = _per_robot(np.mean(nees, axis=0))
        summary[model] = {"rmse_position": pos_rmse, "rmse_heading": head_rmse, "nees_mean": nees_mean,
                          "series": series, "observations": result["counts"]}
    new, old = summary["likelihood"], summary["baseline"]
    pos_rmse, nees_mean = new["rmse_position"], new["nees_mean"]
    result, series = results["likelihood"], new["series"]
    claims = {
        "ccl_beats_il": bool(pos_rmse["CCL"]["mean"] < pos_rmse["IL"]["mean"]),
        "dcl_equals_ccl": bool(max(r["max_abs_diff"] for r in results.values()) < 1e-9),
        "ccl_consistent": bool(nees_mean["CCL"]["mean"] <= 3.0 * 1.5),
    }
    metrics = {
        "dataset": os.path.basename(os.path.normpath(d.path)),
        "rmse_position": pos_rmse, "rmse_heading": new["rmse_heading"], "nees_mean": nees_mean,
        "max_abs_diff_dcl_ccl": max(r["max_abs_diff"] for r in results.values()),
        "duration_s": d.steps * d.dt, "steps": d.steps,
        "dt": d.dt, "noise": noise, "observations": result["counts"], "quick": bool(quick),
        "nees_fraction_in_band": _band_fraction(series["CCL"][1]),
        "nees_split_ccl": _nees_split(d, result["estimate"]["CCL"], result["cov"]["CCL"]),
        "noise_baseline": noise_baseline, "rmse_position_baseline": old["rmse_position"],
        "rmse_heading_baseline": old["rmse_heading"], "nees_mean_baseline": old["nees_mean"],
        "observations_baseline": old["observations"],
        "nees_fraction_in_band_baseline": _band_fraction(old["series"]["CCL"][1]),
        "ablation_no_measurement_inflation": {
            key: summary["odometry_only"][key] for key in ("rmse_position", "nees_mean", "observations")},
        "initial_std": list(INITIAL_STD), "gate": GATE, "claims": claims,
        "rmse_position_moments": summary["calibrated"]["rmse_position"],
        "nees_mean_moments": summary["calibrated"]["nees_mean"],
        "nees_fraction_in_band_moments": _band_fraction(summary["calibrated"]["series"]["CCL"][1]),
        "evaluation": {model: _evaluation(d, results[model], calibration_steps) for model in results},
    }
    ev = metrics["evaluation"]["likelihood"]
    claims["ccl_consistent_on_evaluation"] = bool(ev["steps"] > 0 and 2.4 <= ev["nees_mean"] <= 3.75
                                                  and ev["fraction_in_band"] >= 0.9)
    full = mrclam.load_cached(d.path)  # the study replays the whole run (its own calibration, as the scenario)
    window = min(QUICK_STUDY_STEPS, QUICK_STEPS, full.steps - 1) if quick else full.steps - 1
    study = lossy_link_study(d.path, window, seed, draws=1 if quick else LOSS_DRAWS, progress=progress)
    links = study.pop("settings")
    metrics["lossy_links"] = links
    metrics["lossy_links_setup"] = {**study, "whole_run": window == full.steps - 1,
                                    "loss_levels": list(LOSS_LEVELS), "hop_budgets": list(HOP_BUDGETS)}
    if not quick:  # the same run, model and start: the study's IL is the reproduction's
        metrics["lossy_links_setup"]["il_abs_diff_to_reproduction"] = abs(
            links["IL"]["rmse_position_mean"] - pos_rmse["IL"]["mean"])
    claims.update(_lossy_claims(links))
    # dNBP with the landmark-sighting robots as the GPS-normal anchors (its own slices and calibration
    # over the whole run; --quick: the first slices).
    nbp = mrclam_nbp.run_nbp_study(full, seed=seed, quick=quick)
    metrics["dnbp_landmark_normal"] = {k: v for k, v in nbp.items() if k not in ("time_s", "error_fault_t")}
    metrics["runtime_s"] = time.perf_counter() - start
    folder = os.path.join(out, KEY)
    os.makedirs(folder, exist_ok=True)
    _figures(folder, d, result, series)
    _lossy_figure(folder, links)
    mrclam_nbp.figure(folder, nbp)
    write_json(os.path.join(folder, "metrics.json"), metrics)
    write_text(os.path.join(folder, "report.md"), _report(metrics) + "\n" + mrclam_nbp.report_section(nbp))
    return metrics


def _loss_names() -> list[str]:
    return [name for name, fields in link_settings().items() if "loss_at_zero" in fields]


def _lossy_claims(links: dict) -> dict:
    """What the study checks: hops fall and the error grows with the loss, between the lossless chain and IL."""
    loss = [links[name] for name in _loss_names()]
    rmse = [row["rmse_position_mean"] for row in loss]
    hops = [row["hops_per_step"] for row in loss]
    il, lossless = links["IL"]["rmse_position_mean"], links["lossless"]["rmse_position_mean"]
    dcl = [row for name, row in links.items() if name != "IL"]
    return {
        "lossy_hops_fall_with_loss": bool(all(b <= a for a, b in zip(hops, hops[1:], strict=False))),
        "lossy_error_grows_with_loss": bool(all(b >= a for a, b in zip(rmse, rmse[1:], strict=False))),
        "lossy_between_lossless_and_il": bool(all(lossless <= r <= il for r in rmse)),
        "hop_budget_1_worse_than_complete_chain": bool(all(
            links[f"hops_{h}"]["rmse_position_mean"] > lossless for h in HOP_BUDGETS)),
        "lossy_dcl_consistent": bool(all(row["nees_mean"] <= 3.0 * 1.5 for row in dcl)),
    }


def _lossy_figure(folder, links):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = _loss_names()
    p = [links[name]["loss_at_zero"] for name in names]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, key, label in ((axes[0], "rmse_position_mean", "position RMSE, mean over robots [m]"),
                           (axes[1], "nees_mean", "mean NEES (x, y, theta)")):
        ax.plot(p, [links[name][key] for name in names], "o-", color="C0", label="UKF-DCL, paper chains, lossy")
        if key == "rmse_position_mean":
            for name, x in zip(names, p, strict=True):
                draws = links[name]["rmse_position_draws"]
                ax.plot([x] * len(draws), draws, ".", color="C0", alpha=0.5)
        ax.axhline(links["lossless"][key], color="C2", ls="--", label="lossless complete chain (= CCL)")
        ax.axhline(links["IL"][key], color="C3", ls=":", label="IL (dead reckoning)")
        for h in HOP_BUDGETS:
            ax.axhline(links[f"hops_{h}"][key], color="C1", ls="-.", label=f"hop budget {h}, lossless")
        if key == "nees_mean":
            ax.axhline(3.0, color="k", lw=0.6, label="expectation 3")
        ax.set_xlabel("per-hop loss probability (loss_at_zero)")
        ax.set_ylabel(label)
        ax.set_yscale("log")
    axes[0].legend(fontsize=7)
    fig.suptitle("UKF-DCL over lossy / hop-limited relay links on the MRCLAM data")
    save_figure(os.path.join(folder, "lossy_links.png"), fig)


def _figures(folder, d, result, series):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.stats import chi2

    fig, ax = plt.subplots(figsize=(9, 6))
    colors = plt.cm.tab10(np.arange(N))
    for i in range(N):
        ax.plot(d.groundtruth[:, i, 0], d.groundtruth[:, i, 1], color=colors[i], lw=1.5, label=f"robot{i + 1} Vicon")
        ax.plot(result["estimate"]["CCL"][:, i, 0], result["estimate"]["CCL"][:, i, 1], "--", color=colors[i],
                lw=0.8, label=f"robot{i + 1} CCL")
        ax.plot(result["estimate"]["IL"][:, i, 0], result["estimate"]["IL"][:, i, 1], ":", color=colors[i], lw=0.8)
    ax.scatter(d.landmarks[:, 0], d.landmarks[:, 1], marker="^", color="k", label="landmarks")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    ax.set_title("MRCLAM trajectories: Vicon (solid), UKF-CCL (dashed), dead reckoning (dotted)")
    ax.legend(fontsize=6, ncol=2)
    save_figure(os.path.join(folder, "trajectories.png"), fig)

    fig, axes = plt.subplots(N, 1, figsize=(9, 10), sharex=True)
    for i, ax in enumerate(axes):
        for name, style in (("IL", ":"), ("CCL", "-"), ("DCL", "--")):
            ax.plot(d.time, series[name][0][:, i], style, label=name)
        ax.set_ylabel(f"robot{i + 1} [m]")
        ax.set_yscale("log")
    axes[0].legend()
    axes[-1].set_xlabel("time [s]")
    fig.suptitle("position error against Vicon")
    save_figure(os.path.join(folder, "error_over_time.png"), fig)

    fig, ax = plt.subplots(figsize=(9, 4))
    for i in range(N):
        ax.plot(d.time, series["CCL"][1][:, i], lw=0.6, label=f"robot{i + 1}")
    lo, hi = chi2.ppf([0.025, 0.975], 3)
    ax.axhspan(lo, hi, color="g", alpha=0.15, label="chi-square(3) 95 % band")
    ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("NEES (x, y, theta)")
    ax.set_title("UKF-CCL NEES per robot")
    ax.legend(fontsize=7)
    save_figure(os.path.join(folder, "nees.png"), fig)


def _report(m: dict) -> str:
    p, h, nees, noise = m["rmse_position"], m["rmse_heading"], m["nees_mean"], m["noise"]
    rows = "\n".join(
        f"| {name} | " + " | ".join(f"{p[name][f'robot{i + 1}']:.3f}" for i in range(N))
        + f" | **{p[name]['mean']:.3f}** | {h[name]['mean']:.3f} | {nees[name]['mean']:.1f} |"
        for name in ("IL", "CCL", "DCL"))
    c = m["claims"]
    verdict = lambda ok: "holds" if ok else "does not hold"  # noqa: E731
    quick = ", --quick" if m["quick"] else ""
    il, ccl = p["IL"]["mean"], p["CCL"]["mean"]
    base, abl = m["noise_baseline"], m["ablation_no_measurement_inflation"]

    def total(obs):
        return obs["robot"] + obs["landmark"] + obs["rejected"]

    def model_row(label, pos, ne, obs):
        return (f"| {label} | {pos['IL']['mean']:.3f} | {pos['CCL']['mean']:.3f} | {ne['CCL']['mean']:.1f} | "
                + " / ".join(f"{ne['CCL'][f'robot{i + 1}']:.1f}" for i in range(N))
                + f" | {obs['rejected']} ({100 * obs['rejected'] / max(1, total(obs)):.1f} %) |")

    models = "\n".join([
        model_row("before (baseline)", m["rmse_position_baseline"], m["nees_mean_baseline"],
                  m["observations_baseline"]),
        model_row("moment rules, odometry inflation only", abl["rmse_position"], abl["nees_mean"], abl["observations"]),
        model_row("moment rules (noise_model='calibrated')", m["rmse_position_moments"], m["nees_mean_moments"],
                  m["observations"]),
        model_row("maximum likelihood (noise_model='likelihood', this run)", p, nees, m["observations"]),
    ])
    a_r, b_r = noise["range_var"]
    sp = m["nees_split_ccl"]
    nees_before = m["nees_mean_baseline"]["CCL"]["mean"]
    return f"""# UTIAS MRCLAM {m['dataset']}: IL vs UKF-CCL vs UKF-DCL

Data: Leung, Halpern, Barfoot, Liu, "The UTIAS multi-robot cooperative localization and mapping dataset",
IJRR 30(8):969-974, 2011. {m['steps']} steps of {m['dt']} s ({m['duration_s']:.1f} s{quick}).
Observations applied: {m['observations']['robot']} robot-to-robot, {m['observations']['landmark']} landmark;
{m['observations']['rejected']} rejected by the chi-square(2) 99.9 % gate (the same gate in CCL and DCL).
Initial state: the Vicon pose, std {m['initial_std']}.

## Noise model (from the first {noise['calibration_s']:.1f} s against Vicon; no ground truth after it)

Every number below comes from the calibration window (the first 10 % of the run, at least 60 s) by a
stated rule (`coloc_env.data.mrclam_noise.calibrate_noise`); none was chosen by looking at the NEES.

* Odometry delay and scale: the robots follow the command logged {noise['odometry_delay_steps']} steps
  ({noise['odometry_delay_steps'] * m['dt']:.1f} s) earlier, the delay in 0..0.5 s that minimizes the residual
  against the Vicon-derived (v, w); scale (least squares) s_v = {noise['odometry_scale'][0]:.3f},
  s_w = {noise['odometry_scale'][1]:.3f} (the robots drive and turn less than commanded).
* Odometry noise, per step and per robot, speed-dependent: sigma_v^2 = r_v (a_v + b_v v^2),
  sigma_w^2 = r_w (a_w + b_w w^2) with a = ({noise['odometry_var0'][0]:.2e}, {noise['odometry_var0'][1]:.2e}),
  b = ({noise['odometry_var_gain'][0]:.3f}, {noise['odometry_var_gain'][1]:.3f}) (least squares of the squared
  corrected residual, whose rms is {noise['odometry_residual_std'][0]:.4f} m/s, {noise['odometry_residual_std'][1]:.4f}
  rad/s), and r = ({noise['odometry_inflation'][0]:.2f}, {noise['odometry_inflation'][1]:.2f}): the errors are
  correlated over steps (lag-1 autocorrelation {noise['odometry_lag1_autocorr'][0]:.2f} in v,
  {noise['odometry_lag1_autocorr'][1]:.2f} in w), so r is the ratio of the actual second moment of the error summed
  over H = {noise['correction_horizon_steps']} steps (the length-biased mean gap between a robot's observations)
  to the white model's.
* Range: sigma_r^2 = {a_r:.4f} + {b_r:.5f} r^2 (68.27th percentile of |residual| in equal-count range bins;
  the error grows with the range); bearing sigma_b = {noise['sigma_bearing_p68']:.4f} rad (68.27th percentile).
  Successive sightings of one subject by one robot share their error, so R is inflated by the same burst-sum
  rule (bursts with no gap longer than H): r_range = {noise['measurement_inflation'][0]:.1f},
  r_bearing = {noise['measurement_inflation'][1]:.1f}.
* Before (baseline, the model of the first version): constant white noise, 1.4826 x MAD over the first
  {base['calibration_s']:.0f} s, raw commands: sigma_v = {base['sigma_v']:.4f} m/s, sigma_w = {base['sigma_w']:.4f}
  rad/s, sigma_range = {base['sigma_range']:.4f} m, sigma_bearing = {base['sigma_bearing']:.4f} rad.

| noise model | IL RMSE pos mean [m] | CCL RMSE pos mean [m] | CCL mean NEES | per robot 1/2/3/4/5 | rejected (gate) |
|---|---|---|---|---|---|
{models}

Dead reckoning (IL) is not helped by the calibration on its own: its position error is dominated by the
heading drift it never corrects (IL heading RMSE {m['rmse_heading_baseline']['IL']['mean']:.3f} rad before,
{h['IL']['mean']:.3f} rad after).

Fraction of (step, robot) CCL NEES values in the chi-square(3) 95 % band: {100 * m['nees_fraction_in_band']:.1f} %
(moment rules {100 * m['nees_fraction_in_band_moments']:.1f} %, baseline \
{100 * m['nees_fraction_in_band_baseline']:.1f} %).

{_evaluation_section(m, verdict)}

## Results (maximum-likelihood model)

| estimator | RMSE pos robot1 | robot2 | robot3 | robot4 | robot5 | mean [m] | RMSE heading mean [rad] | mean NEES |
|---|---|---|---|---|---|---|---|---|
{rows}

| claim | our number | verdict |
|---|---|---|
| CCL beats IL (mean position RMSE) | {ccl:.3f} m vs {il:.3f} m | {verdict(c['ccl_beats_il'])} |
| DCL equals CCL (1e-9) | max abs diff {m['max_abs_diff_dcl_ccl']:.2e} | {verdict(c['dcl_equals_ccl'])} |
| CCL is consistent (mean NEES <= 4.5) | {nees['CCL']['mean']:.2f} (expectation 3; before {nees_before:.1f}) \
| {verdict(c['ccl_consistent'])} |

The NEES criterion is a single-run time average (no Monte Carlo on recorded data); the figure `nees.png`
shows it against the chi-square(3) 95 % band. CCL NEES split: position {sp['position']:.2f} (expectation 2),
heading {sp['heading']:.2f} (expectation 1), median {sp['median']:.2f} (chi-square(3) median 2.37). Where the mean
still exceeds 4.5, the residual cause is what a white-noise filter on (x, y, theta) cannot represent: errors
that persist for seconds (autocorrelation of the position error over 5 s: {sp['position_error_autocorr_5s']:.2f}),
which a uniform inflation matches only on average (short bursts of sightings get too much, long ones too
little); modelling them needs more state (odometry biases, per-landmark range offsets) or a decorrelating
update schedule. Figures: `trajectories.png`, `error_over_time.png`, `nees.png`.

{_lossy_report(m)}"""


def _evaluation_section(m: dict, verdict) -> str:
    noise, ev = m["noise"], m["evaluation"]
    rows = "\n".join(f"| {name} | {e['nees_mean']:.2f} | {100 * e['fraction_in_band']:.1f} % | "
                     f"{e['rmse_position_mean']:.4f} | {e['nees_position']:.2f} / {e['nees_heading']:.2f} |"
                     for name, e in ev.items() if e.get("steps"))
    ml = ev["likelihood"]
    start = ", ".join(f"{x:.2f}" for x in noise["likelihood_start"])
    c = noise["likelihood_scale"]
    return (f"Maximum-likelihood scales (`coloc_env.data.mrclam_noise.fit_noise_scales`: the composite likelihood of "
            f"UKF-CCL's pose errors against Vicon on the calibration window, compass search from the moment rules' "
            f"inflations {start}): c_v = {c[0]:.2f}, c_w = {c[1]:.2f}, c_range = {c[2]:.2f}, c_bearing = {c[3]:.2f} "
            f"({noise['likelihood_passes']} passes of 9 filters).\n\n"
            f"On the part of the run the noise was NOT fitted on (steps {ml['from_step']} on, {ml['steps']} steps):\n\n"
            "| noise model | CCL mean NEES | in chi-square(3) 95 % band | position RMSE mean [m] | "
            "NEES position / heading |\n|---|---|---|---|---|\n" + rows + "\n\n"
            "| claim | our number | verdict |\n|---|---|---|\n"
            f"| CCL consistent where not fitted (mean NEES in [2.4, 3.75], >= 90 % in band) | "
            f"{ml.get('nees_mean', float('nan')):.2f}, {100 * ml.get('fraction_in_band', float('nan')):.1f} % | "
            f"{verdict(m['claims']['ccl_consistent_on_evaluation'])} |\n")


def _lossy_report(m: dict) -> str:
    links, setup, c = m["lossy_links"], m["lossy_links_setup"], m["claims"]
    verdict = lambda ok: "holds" if ok else "does not hold"  # noqa: E731
    labels = {"IL": "IL (dead reckoning, no communication)", "lossless": "lossless complete chain (= CCL)"}
    labels.update({name: f"per-hop loss {links[name]['loss_at_zero']:g}" for name in _loss_names()
                   if name != "lossless"})
    labels.update({f"hops_{h}": f"hop budget {h} (measured robot only), lossless" for h in HOP_BUDGETS})
    order = ["lossless", *[n for n in _loss_names() if n != "lossless"], *[f"hops_{h}" for h in HOP_BUDGETS], "IL"]

    def row(name):
        r = links[name]
        spread = (f" ({min(r['rmse_position_draws']):.4f}..{max(r['rmse_position_draws']):.4f})"
                  if r["draws"] > 1 else "")
        return (f"| {labels[name]} | {r['rmse_position_mean']:.4f}{spread} | {r['nees_mean']:.2f} | "
                f"{r['hops_per_step']:.3f} | {100 * r['delivered_fraction']:.1f} % | "
                f"{100 * r['complete_fraction']:.1f} % | {100 * r['used_fraction']:.1f} % |")

    if setup["whole_run"]:
        draws = (f"{setup['draws']} loss draws per lossy setting (copies seeded {setup['seed']}.."
                 f"{setup['seed'] + setup['draws'] - 1}; RMSE: mean (min..max) over draws)" if setup["draws"] > 1
                 else f"one loss draw (seed {setup['seed']})")
        span = f"the whole run ({setup['window_steps']} steps from step 0), {draws}"
    else:
        span = (f"one seeded window of {setup['window_steps']} steps from step {setup['window_start']} "
                f"(seed {setup['seed']}, one loss draw; --quick)")
    names = _loss_names()
    levels = " / ".join(f"{links[n]['loss_at_zero']:g}" for n in names)
    rmse = " / ".join(f"{links[n]['rmse_position_mean']:.4f}" for n in names) + f" m at loss {levels}"
    hops = " / ".join(f"{links[n]['hops_per_step']:.3f}" for n in names) + f" at loss {levels}"
    lossless, il = links["lossless"]["rmse_position_mean"], links["IL"]["rmse_position_mean"]
    worst = max(links[n]["rmse_position_mean"] for n in names)
    budget = ", ".join(f"{links['hops_' + str(h)]['rmse_position_mean']:.4f}" for h in HOP_BUDGETS)
    nees = max(links[n]["nees_mean"] for n in links if n != "IL")
    first_loss = links[names[1]] if len(names) > 1 else links["lossless"]
    h1 = links[f"hops_{HOP_BUDGETS[0]}"] if HOP_BUDGETS else links["lossless"]
    reading = (
        f"A hop budget of {HOP_BUDGETS[0] if HOP_BUDGETS else '-'} (only the measured robot updates) costs "
        f"{100 * (h1['rmse_position_mean'] / lossless - 1):.1f} % in RMSE for {100 * h1['delivered_fraction']:.0f} "
        f"% of the hops (every measurement is still used). Per-hop loss {first_loss.get('loss_at_zero', 0):g} "
        f"delivers {100 * first_loss['delivered_fraction']:.0f} % of the hops and costs "
        f"{100 * first_loss['rmse_position_mean'] / lossless - 100:.1f} % in RMSE: a lost first hop drops the "
        f"measurement altogether ({100 * first_loss['used_fraction']:.1f} % used). The NEES criterion "
        f"fails for the lossless chain already ({links['lossless']['nees_mean']:.2f}, the noise model's residual "
        f"overconfidence, see above); the losses add at most {nees - links['lossless']['nees_mean']:.2f} to it.")
    il_check = (f" The study's IL is the reproduction's IL above (difference "
                f"{setup['il_abs_diff_to_reproduction']:.1e} m)." if "il_abs_diff_to_reproduction" in setup else "")
    table = "\n".join(row(name) for name in order)
    return f"""## UKF-DCL over lossy / hop-limited links (scenario `mrclam_relay`)

The `mrclam_relay` scenario core replays the data with the `paper` policy's actions (each robot uses its
lowest-index recorded robot measurement of the step; chains m -> n -> the other robots ascending) through the
project's relay link model (`coloc_env.networks.blocks.relay_chain`): each hop is lost with probability `loss_at_zero`
(independent of its length here), a lost hop ends the chain there (the robots it reached update by the exact
truncated-chain UKF-DCL; a lost first hop drops the measurement), `max_hops` caps the hops. Landmark sightings
update the robot that saw them (no communication). Noise: the calibrated model of the whole run. The same seed
gives the same loss uniforms in every setting, so the losses are coupled. Span: {span}.
Without losses the chains are complete and UKF-DCL is UKF-CCL on these observations (to 1e-9,
`tests/coloc_env/test_mrclam_relay.py`); it uses fewer observations than the CCL above (one robot measurement
per robot and step, landmarks only to the robot that saw them): {lossless:.4f} m vs the CCL above
{m['rmse_position']['CCL']['mean']:.4f} m.{il_check}

| link setting | position RMSE mean [m] | mean NEES | hops / step | hops delivered | chains complete | \
measurements used |
|---|---|---|---|---|---|---|
{table}

| claim | our number | verdict |
|---|---|---|
| fewer hops with more loss (coupled draws) | {hops} | {verdict(c['lossy_hops_fall_with_loss'])} |
| the error grows with the loss | {rmse} | {verdict(c['lossy_error_grows_with_loss'])} |
| lossy DCL lies between the lossless chain and IL | {lossless:.4f} <= ... <= {worst:.4f} <= {il:.4f} m \
| {verdict(c['lossy_between_lossless_and_il'])} |
| hop budget 1 is worse than the complete chain | {budget} vs {lossless:.4f} m \
| {verdict(c['hop_budget_1_worse_than_complete_chain'])} |
| DCL stays consistent over lossy links (mean NEES <= 4.5) | worst {nees:.2f} \
| {verdict(c['lossy_dcl_consistent'])} |

{reading}

Figure: `lossy_links.png` (RMSE and NEES against the per-hop loss probability; dots: the draws).
"""
