"""The estimators on real data: UTIAS MRCLAM (``coloc reproduce mrclam --data DIR``).

Data: Leung K.Y.K., Halpern Y., Barfoot T.D., Liu H.H.T., "The UTIAS
multi-robot cooperative localization and mapping dataset", IJRR
30(8):969-974, 2011 (cite it with these results). Not part of
``coloc reproduce all``: it needs a dataset folder (``--data`` or
``COLOC_MRCLAM_DATA``).

Estimators (:mod:`estimators.ukf_relay_se2`, state (x, y, theta) per robot):

* ``IL``  dead reckoning from the odometry (v, w), covariance by the same
  linearized time update (no measurements);
* ``CCL`` UKF-CCL on the joint state, every robot-to-robot (range, bearing)
  and every landmark sighting, in file order within a step;
* ``DCL`` UKF-DCL over the complete relay chain [m, n, the others ascending]
  (landmark: [m, the others]) with the Roumeliotis-Bekey factorization.

Setup (stated in ``report.md``): initial state = the Vicon pose at the first
step with standard deviations ``INITIAL_STD`` (0.01 m, 0.01 m, 0.01 rad);
noise from the data over a calibration window (the first ``CALIBRATION_S``
seconds): the odometry noise from odometry minus the Vicon-derived (v, w)
per step, the range and bearing noise from measured minus Vicon-predicted
values, each as a robust standard deviation (1.4826 x median absolute
deviation, so that the dataset's misread barcodes do not inflate it). The
evaluation runs over the whole run, the calibration window included.
Observations with a normalized innovation above the chi-square(2) 99.9 %
quantile are rejected (the same in CCL and DCL).

Writes ``OUT/mrclam/metrics.json``: ``rmse_position`` {"IL"|"CCL"|"DCL":
{"robot1".."robot5", "mean"}} (m), ``rmse_heading`` (rad, same shape),
``nees_mean`` (same shape; expectation 3), ``max_abs_diff_dcl_ccl`` (state
and covariance), ``duration_s``, ``steps``, ``noise``, ``observations``,
``claims``; ``report.md`` and figures ``trajectories.png``,
``error_over_time.png``, ``nees.png``.
"""

from __future__ import annotations

import os
import time

import numpy as np

import estimators.ukf_relay_se2 as se2
from coloc_env.data import mrclam
from train.io import save_figure, write_json, write_text

KEY = "mrclam"
RUNS = 1  # the data is one recorded run: no Monte Carlo
QUICK_RUNS = 1
QUICK_STEPS = 1500  # --quick: the first 150 s
CALIBRATION_S = 60.0
INITIAL_STD = (0.01, 0.01, 0.01)
GATE = 13.815510557964274  # chi-square(2) 0.999 quantile
N = mrclam.NUM_ROBOTS


def run_filters(d: mrclam.MrclamData, noise: dict, progress=None) -> dict:
    """IL, CCL and DCL over the whole of ``d``; estimates (T, N, 3) and own-block covariances (T, N, 3, 3)."""
    R = np.diag([noise["sigma_range"] ** 2, noise["sigma_bearing"] ** 2])
    Q = (noise["sigma_v"] ** 2, noise["sigma_w"] ** 2)
    P0 = np.diag(np.tile(np.square(INITIAL_STD), N))
    x_il, P_il = d.groundtruth[0].copy(), P0.copy()
    x_c, P_c = x_il.copy(), P0.copy()
    x_d, f = x_il.copy(), se2.factor(P0)
    T = d.steps
    out = {name: np.empty((T, N, 3)) for name in ("IL", "CCL", "DCL")}
    cov = {name: np.empty((T, N, 3, 3)) for name in ("IL", "CCL", "DCL")}
    diag = np.arange(N)
    counts = {"robot": 0, "landmark": 0, "rejected": 0}
    worst = 0.0
    for k in range(T):
        s = d.measurements_at(k)
        for r, sub, rg, b in zip(d.meas_robot[s], d.meas_subject[s], d.meas_range[s], d.meas_bearing[s], strict=True):
            z = np.array([rg, b])
            if sub <= N:
                n = int(sub) - 1
                chain = [int(r), n] + [i for i in range(N) if i not in (r, n)]
                x_c, P_c, ok = se2.ccl_update(x_c, P_c, int(r), z, R, measured=n, gate=GATE)
                x_d, f, ok_d = se2.dcl_update(x_d, f, chain, z, R, gate=GATE)
            else:
                lm = d.landmarks[sub - N - 1]
                chain = [int(r)] + [i for i in range(N) if i != r]
                x_c, P_c, ok = se2.ccl_update(x_c, P_c, int(r), z, R, landmark=lm, gate=GATE)
                x_d, f, ok_d = se2.dcl_update(x_d, f, chain, z, R, measured_in_chain=False, landmark=lm, gate=GATE)
            if ok != ok_d:
                raise RuntimeError(f"step {k}: the gate decided differently in CCL and DCL")
            counts["rejected" if not ok else ("robot" if sub <= N else "landmark")] += 1
        out["IL"][k], out["CCL"][k], out["DCL"][k] = x_il, x_c, x_d
        for name, P in (("IL", P_il), ("CCL", P_c)):
            cov[name][k] = P.reshape(N, 3, N, 3)[diag, :, diag, :]
        cov["DCL"][k] = f.P_ii
        worst = max(worst, float(np.abs(x_c - x_d).max()), float(np.abs(P_c - f.joint()).max()))
        u = d.odometry[k]
        x_il, P_il = se2.time_update(x_il, P_il, u, d.dt, Q)
        x_c, P_c = se2.time_update(x_c, P_c, u, d.dt, Q)
        x_d, f = se2.time_update_factored(x_d, f, u, d.dt, Q)
        if progress and k % 1000 == 0:
            progress(f"step {k}/{T}")
    return {"estimate": out, "cov": cov, "counts": counts, "max_abs_diff": worst}


def _errors(d, estimate, cov):
    e = estimate - d.groundtruth
    e[..., 2] = se2.wrap(e[..., 2])
    pos = np.hypot(e[..., 0], e[..., 1])
    nees = np.einsum("tna,tnab,tnb->tn", e, np.linalg.inv(cov), e)
    return pos, np.abs(e[..., 2]), nees


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
    noise = mrclam.calibrate_noise(d, CALIBRATION_S)
    result = run_filters(d, noise, progress)
    pos_rmse, head_rmse, nees_mean, series = {}, {}, {}, {}
    for name in ("IL", "CCL", "DCL"):
        pos, head, nees = _errors(d, result["estimate"][name], result["cov"][name])
        series[name] = (pos, nees)
        pos_rmse[name] = _per_robot(np.sqrt(np.mean(pos**2, axis=0)))
        head_rmse[name] = _per_robot(np.sqrt(np.mean(head**2, axis=0)))
        nees_mean[name] = _per_robot(np.mean(nees, axis=0))
    claims = {
        "ccl_beats_il": bool(pos_rmse["CCL"]["mean"] < pos_rmse["IL"]["mean"]),
        "dcl_equals_ccl": bool(result["max_abs_diff"] < 1e-9),
        "ccl_consistent": bool(nees_mean["CCL"]["mean"] <= 3.0 * 1.5),
    }
    metrics = {
        "dataset": os.path.basename(os.path.normpath(d.path)),
        "rmse_position": pos_rmse, "rmse_heading": head_rmse, "nees_mean": nees_mean,
        "max_abs_diff_dcl_ccl": result["max_abs_diff"], "duration_s": d.steps * d.dt, "steps": d.steps,
        "dt": d.dt, "noise": noise, "observations": result["counts"], "quick": bool(quick),
        "initial_std": list(INITIAL_STD), "gate": GATE, "claims": claims,
        "runtime_s": time.perf_counter() - start,
    }
    folder = os.path.join(out, KEY)
    os.makedirs(folder, exist_ok=True)
    _figures(folder, d, result, series)
    write_json(os.path.join(folder, "metrics.json"), metrics)
    write_text(os.path.join(folder, "report.md"), _report(metrics))
    return metrics


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
    return f"""# UTIAS MRCLAM {m['dataset']}: IL vs UKF-CCL vs UKF-DCL

Data: Leung, Halpern, Barfoot, Liu, "The UTIAS multi-robot cooperative localization and mapping dataset",
IJRR 30(8):969-974, 2011. {m['steps']} steps of {m['dt']} s ({m['duration_s']:.1f} s{quick}).
Observations applied: {m['observations']['robot']} robot-to-robot, {m['observations']['landmark']} landmark;
{m['observations']['rejected']} rejected by the chi-square(2) 99.9 % gate.

Noise from the first {noise['calibration_s']:.0f} s against Vicon (1.4826 x MAD): sigma_v = {noise['sigma_v']:.4f} m/s,
sigma_w = {noise['sigma_w']:.4f} rad/s, sigma_range = {noise['sigma_range']:.4f} m,
sigma_bearing = {noise['sigma_bearing']:.4f} rad. Initial state: the Vicon pose, std {m['initial_std']}.

| estimator | RMSE pos robot1 | robot2 | robot3 | robot4 | robot5 | mean [m] | RMSE heading mean [rad] | mean NEES |
|---|---|---|---|---|---|---|---|---|
{rows}

| claim | our number | verdict |
|---|---|---|
| CCL beats IL (mean position RMSE) | {ccl:.3f} m vs {il:.3f} m | {verdict(c['ccl_beats_il'])} |
| DCL equals CCL (1e-9) | max abs diff {m['max_abs_diff_dcl_ccl']:.2e} | {verdict(c['dcl_equals_ccl'])} |
| CCL is consistent (mean NEES <= 4.5) | {nees['CCL']['mean']:.2f} (expectation 3) | {verdict(c['ccl_consistent'])} |

The NEES criterion is a single-run time average (no Monte Carlo on recorded data); the figure `nees.png`
shows it against the chi-square(3) 95 % band. Figures: `trajectories.png`, `error_over_time.png`, `nees.png`.
"""
