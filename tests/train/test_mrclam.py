"""coloc reproduce mrclam: the CLI choice, the data error, and a quick run on dataset 6."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from coloc_env.data import mrclam_noise
from train.cli import PAPERS, build_parser

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.conftest import MRCLAM_DATASET6 as DATASET6  # noqa: E402
from tests.conftest import MRCLAM_SKIP_REASON  # noqa: E402


def test_cli_accepts_mrclam_not_in_all():
    args = build_parser().parse_args(["reproduce", "mrclam", "--data", "somewhere"])
    assert args.paper == "mrclam" and args.data == "somewhere"
    assert "mrclam" not in PAPERS


def test_missing_data_is_a_clear_error(tmp_path, monkeypatch):
    from train.reproduce import mrclam

    monkeypatch.delenv("COLOC_MRCLAM_DATA", raising=False)
    with pytest.raises(ValueError, match="COLOC_MRCLAM_DATA"):
        mrclam.run(str(tmp_path), quick=True)


def test_quick_reproduce_on_dataset6(tmp_path, monkeypatch):
    if not os.path.isdir(DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)
    from train.reproduce import mrclam

    monkeypatch.setattr(mrclam, "QUICK_STEPS", 400)
    metrics = mrclam.run(str(tmp_path), quick=True, data=DATASET6)
    folder = tmp_path / "mrclam"
    for name in ("metrics.json", "report.md", "trajectories.png", "error_over_time.png", "nees.png",
                 "nbp_error_over_time.png"):
        assert (folder / name).is_file()
    stored = json.loads((folder / "metrics.json").read_text())
    assert set(stored["rmse_position"]) == {"IL", "CCL", "DCL"}
    assert "dnbp_beats_dead_reckoning" in stored["dnbp_landmark_normal"]["claims"]
    assert "dNBP" in (folder / "report.md").read_text()
    assert set(stored["rmse_position"]["CCL"]) == {f"robot{i}" for i in range(1, 6)} | {"mean"}
    assert stored["steps"] == 400
    assert metrics["max_abs_diff_dcl_ccl"] < 1e-9
    assert metrics["rmse_position"]["CCL"]["mean"] < metrics["rmse_position"]["IL"]["mean"]
    # the calibrated model is reported next to the baseline, and is the better-calibrated one
    assert {"noise_baseline", "nees_mean_baseline", "rmse_position_baseline", "observations_baseline"} <= set(stored)
    assert set(stored["nees_mean_baseline"]["CCL"]) == {f"robot{i}" for i in range(1, 6)} | {"mean"}
    assert stored["noise"]["odometry_delay_steps"] == 2
    assert metrics["nees_mean"]["CCL"]["mean"] < metrics["nees_mean_baseline"]["CCL"]["mean"]
    assert metrics["observations"]["rejected"] < metrics["observations_baseline"]["rejected"]
    report = (folder / "report.md").read_text()
    assert "before (baseline)" in report and "68.27th percentile" in report
    # lossy links: a short seeded window in --quick, every setting and IL, its figure and report section
    assert set(stored["lossy_links"]) == set(mrclam.link_settings()) | {"IL"}
    setup = stored["lossy_links_setup"]
    assert setup["window_steps"] == min(mrclam.QUICK_STUDY_STEPS, 600) and not setup["whole_run"]
    assert stored["lossy_links"]["lossless"]["delivered_fraction"] == 1.0
    assert stored["claims"]["lossy_hops_fall_with_loss"]
    assert (folder / "lossy_links.png").is_file() and "lossy / hop-limited links" in report


# ---------------------------------------------------------------- calibrate_noise on synthetic data


def _synthetic(rng, T=3000, delay=2, scale=(0.9, 0.8), var0=(1e-4, 4e-3), gain=(0.05, 0.1), rho=0.0,
               range_var=(0.004, 0.002), sigma_b=0.01, pair_bias=0.0, p_see=0.3):
    """Robots whose true velocity is scale * (command logged ``delay`` steps earlier) minus noise of
    variance var0 + gain u^2 (AR(1) with coefficient ``rho``); (range, bearing) to landmarks with
    white noise of variance range_var[0] + range_var[1] r^2 and sigma_b (+ a constant error per pair)."""
    from coloc_env.data import mrclam
    from estimators.ukf_relay_se2 import observe

    dt, N = 0.1, 5
    hold = 20
    clean = np.repeat(np.stack([rng.uniform(0.0, 0.2, (T // hold + 1, N)),
                                rng.uniform(-0.5, 0.5, (T // hold + 1, N))], -1), hold, axis=0)[:T]
    sd = np.sqrt(np.asarray(var0) + np.asarray(gain) * clean**2)
    white = rng.normal(size=(T, N, 2))
    e = np.empty_like(white)
    e[0] = white[0]
    for k in range(1, T):
        e[k] = rho * e[k - 1] + np.sqrt(1 - rho**2) * white[k]
    e *= sd
    true = clean - e
    gt = np.zeros((T, N, 3))
    gt[0, :, :2] = rng.uniform(-3, 3, (N, 2))
    for k in range(T - 1):
        th = gt[k, :, 2]
        gt[k + 1] = gt[k] + dt * np.stack([true[k, :, 0] * np.cos(th), true[k, :, 0] * np.sin(th), true[k, :, 1]], -1)
    gt[..., 2] = (gt[..., 2] + np.pi) % (2 * np.pi) - np.pi
    command = np.concatenate([clean[delay:], np.repeat(clean[-1:], delay, 0)]) / np.asarray(scale)
    landmarks = rng.uniform(-5, 5, (15, 2))
    bias = pair_bias * rng.normal(size=(N, 15, 2))
    steps, robots, subjects, ranges, bearings = [], [], [], [], []
    for k in range(T):
        for r in range(N):
            if rng.random() < p_see:
                lm = (k // hold + 3 * r) % 15  # bursts: a robot sees one landmark for `hold` steps
                h = observe(gt[k, r], landmarks[lm])
                sr = np.sqrt(range_var[0] + range_var[1] * h[0] ** 2)
                steps.append(k)
                robots.append(r)
                subjects.append(lm + 6)
                ranges.append(h[0] + sr * (rng.normal() + bias[r, lm, 0]))
                bearings.append(h[1] + sigma_b * (rng.normal() + bias[r, lm, 1]))
    return mrclam.MrclamData(
        path="synthetic", dt=dt, t0=0.0, time=dt * np.arange(T), odometry=command, groundtruth=gt,
        landmarks=landmarks, landmark_std=np.zeros((15, 2)), barcodes={}, meas_step=np.array(steps),
        meas_robot=np.array(robots), meas_subject=np.array(subjects), meas_range=np.array(ranges),
        meas_bearing=np.array(bearings), dropped_unknown_barcode=0)


def test_calibrate_noise_recovers_injected_model():
    d = _synthetic(np.random.default_rng(0))
    n = mrclam_noise.calibrate_noise(d, d.steps * d.dt)
    for key in ("sigma_v", "sigma_w", "sigma_range", "sigma_bearing", "calibration_s", "calibration_measurements"):
        assert key in n  # the baseline keys stay
    assert n["odometry_delay_steps"] == 2
    assert np.allclose(n["odometry_scale"], [0.9, 0.8], rtol=0.03)
    for c, (a, b) in enumerate([(1e-4, 0.05), (4e-3, 0.1)]):
        for u in (0.0, 0.15, 0.4):
            truth = np.sqrt(a + b * u * u)
            model = np.sqrt(n["odometry_var0"][c] + n["odometry_var_gain"][c] * u * u)
            assert abs(model / truth - 1) < 0.15, (c, u, model, truth)
        # white errors: the summed error over the horizon matches the white model
        assert 1.0 <= n["odometry_inflation"][c] < 1.3
    for r in (2.0, 6.0):
        model = np.sqrt(n["range_var"][0] + n["range_var"][1] * r * r)
        assert abs(model / np.sqrt(0.004 + 0.002 * r * r) - 1) < 0.15
    assert abs(n["sigma_bearing_p68"] / 0.01 - 1) < 0.1
    assert max(n["measurement_inflation"]) < 1.5
    # MAD over raw commands understates: the baseline sigma_w ignores the scale error and the speed dependence
    assert n["correction_horizon_steps"] >= 2


def test_speed_dependent_sigma_grows_with_speed():
    import estimators.ukf_relay_se2 as se2

    n = mrclam_noise.calibrate_noise(_synthetic(np.random.default_rng(1), T=2000), 200.0)
    q = se2.odometry_variance(np.array([[0.0, 0.0], [0.2, 0.5]]), n["odometry_var0"], n["odometry_var_gain"],
                              n["odometry_inflation"])
    assert np.all(q[1] > 1.5 * q[0])


def test_correlated_errors_are_inflated():
    d = _synthetic(np.random.default_rng(2), rho=0.9, pair_bias=2.0)
    n = mrclam_noise.calibrate_noise(d, d.steps * d.dt)
    assert n["odometry_lag1_autocorr"][0] > 0.8
    assert n["odometry_inflation"][0] > 2.5 and n["odometry_inflation"][1] > 2.5
    # a constant error per (robot, landmark) pair of 2 sigma: bursts of sightings share it
    assert min(n["measurement_inflation"]) > 2.0


# ---------------------------------------------------------------- DCL over lossy / hop-limited links


def test_lossy_link_study_lossless_is_the_paper_policy_and_losses_cut_hops():
    """On a short seeded window: the lossless setting is the scenario under ``agents``' paper policy (1e-9),
    coupled losses never deliver more hops, and a hop budget of 1 delivers exactly the first hop of each chain."""
    if not os.path.isdir(DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)
    import agents
    import coloc_env
    from train.reproduce import mrclam

    W, seed, N = 120, 4, 5
    study = mrclam.lossy_link_study(DATASET6, W, seed)
    links = study["settings"]
    assert set(links) == set(mrclam.link_settings()) | {"IL"}
    # the study's noise model (train.reproduce.mrclam.lossy_link_study: the moment rules)
    env = coloc_env.parallel_env("mrclam_relay", data=DATASET6, window_steps=W, noise_model="calibrated")
    policy = agents.make_policy("paper", env)
    observations, infos = env.reset(seed=seed)
    assert int(env.scenario.world.start[0]) == study["window_start"]
    errors = [np.array([infos[f"robot_{i}"]["error"] for i in range(N)])]
    dead_reckoning = [np.zeros(N)]
    hops = 0
    while env.agents:
        observations, _, _, _, infos = env.step(policy.act(observations))
        errors.append(np.array([infos[f"robot_{i}"]["error"] for i in range(N)]))
        dead_reckoning.append(np.array([infos[f"robot_{i}"]["dead_reckoning_error"] for i in range(N)]))
        hops += int(infos["robot_0"]["hops"])
    rmse = lambda e: float(np.sqrt(np.mean(np.square(e), axis=0)).mean())  # noqa: E731
    lossless = links["lossless"]
    assert lossless["rmse_position_mean"] == pytest.approx(rmse(errors), abs=1e-9)
    assert links["IL"]["rmse_position_mean"] == pytest.approx(rmse(dead_reckoning), abs=1e-9)
    assert lossless["hops_per_step"] == pytest.approx(hops / W, abs=1e-12)
    assert lossless["delivered_fraction"] == lossless["complete_fraction"] == lossless["used_fraction"] == 1.0
    # coupled uniforms: more loss never delivers more hops; some loss drops some hops
    loss = [links[name] for name in ("lossless", "loss_0.3", "loss_0.6", "loss_0.9")]
    assert all(b["hops_per_step"] <= a["hops_per_step"] for a, b in zip(loss, loss[1:], strict=False))
    assert loss[-1]["hops_per_step"] < lossless["hops_per_step"]
    assert all(row["chains_per_step"] == lossless["chains_per_step"] > 0 for row in loss)
    budget = links["hops_1"]
    assert budget["hops_per_step"] == pytest.approx(budget["chains_per_step"])
    assert budget["delivered_fraction"] == pytest.approx(1 / (N - 1)) and budget["complete_fraction"] == 0.0
    assert all(np.isfinite(row["nees_mean"]) and row["nees_mean"] > 0 for row in links.values())
