"""The MRCLAM loader: the real dataset 6 (when ../shared is beside the clone) and its error messages."""

from __future__ import annotations

import os

import numpy as np
import pytest

from coloc_env.data import mrclam, mrclam_noise

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.conftest import MRCLAM_DATASET6 as DATASET6  # noqa: E402
from tests.conftest import MRCLAM_SKIP_REASON  # noqa: E402


@pytest.fixture(scope="module")
def dataset6():
    if not os.path.isdir(DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)
    return mrclam.load_cached(DATASET6, 0.1)


def test_dataset6_shapes_and_alignment(dataset6):
    d = dataset6
    T = d.steps
    assert T > 7000
    assert d.odometry.shape == (T, 5, 2) and d.groundtruth.shape == (T, 5, 3)
    assert d.landmarks.shape == (15, 2) and np.isfinite(d.landmarks).all()
    assert np.allclose(np.diff(d.time), 0.1)
    assert np.all(np.abs(d.groundtruth[..., 2]) <= np.pi)
    # measurements: sorted by step, subjects 1..20 and never the observer itself
    assert np.all(np.diff(d.meas_step) >= 0)
    assert d.meas_subject.min() >= 1 and d.meas_subject.max() <= 20
    assert not np.any(d.meas_subject == d.meas_robot + 1)
    assert np.any(d.meas_subject <= 5) and np.any(d.meas_subject >= 6)
    assert d.dropped_unknown_barcode < 20
    # barcode 5 is robot 1, 90 is landmark 15 (Barcodes.dat)
    assert d.barcodes[5] == 1 and d.barcodes[90] == 15


def test_dataset6_measurements_match_ground_truth(dataset6):
    """Range to landmarks from the interpolated Vicon pose agrees with the camera to a few cm (median)."""
    d = dataset6
    lm = d.meas_subject >= 6
    pose = d.groundtruth[d.meas_step[lm], d.meas_robot[lm]]
    delta = d.landmarks[d.meas_subject[lm] - 6] - pose[:, :2]
    predicted = np.hypot(delta[:, 0], delta[:, 1])
    assert np.median(np.abs(predicted - d.meas_range[lm])) < 0.15
    bearing = np.arctan2(delta[:, 1], delta[:, 0]) - pose[:, 2]
    error = (d.meas_bearing[lm] - bearing + np.pi) % (2 * np.pi) - np.pi
    assert np.median(np.abs(error)) < 0.05


def test_dataset6_odometry_integrates_close_to_truth(dataset6):
    d = dataset6
    v, w = d.odometry[:50, 0, 0], d.odometry[:50, 0, 1]
    theta = d.groundtruth[0, 0, 2] + np.concatenate([[0], np.cumsum(w * d.dt)])[:-1]
    xy = d.groundtruth[0, 0, :2] + np.sum(d.dt * v[:, None] * np.stack([np.cos(theta), np.sin(theta)], 1), axis=0)
    assert np.linalg.norm(xy - d.groundtruth[50, 0, :2]) < 0.3


def test_window(dataset6):
    w = dataset6.window(100, 50)
    assert w.steps == 50
    assert np.array_equal(w.groundtruth, dataset6.groundtruth[100:150])
    assert w.meas_step.min() >= 0 and w.meas_step.max() < 50
    with pytest.raises(ValueError, match="window"):
        dataset6.window(dataset6.steps - 1, 5)


HEADER = "# header\n"


def _write_minimal(folder) -> None:
    """A tiny valid dataset: 20 subjects, 15 landmarks, 5 robots over 2 s."""
    codes = {s: 100 + s for s in range(1, 21)}
    (folder / "Barcodes.dat").write_text(HEADER + "".join(f"{s} {c}\n" for s, c in codes.items()))
    (folder / "Landmark_Groundtruth.dat").write_text(
        HEADER + "".join(f"{s} {s * 0.1} 1.0 0.001 0.001\n" for s in range(6, 21)))
    for r in range(1, 6):
        times = np.arange(0.0, 2.0, 0.02)
        (folder / f"Robot{r}_Odometry.dat").write_text(HEADER + "".join(f"{t:.3f} 0.1 0.0\n" for t in times))
        (folder / f"Robot{r}_Groundtruth.dat").write_text(
            HEADER + "".join(f"{t:.3f} {0.1 * t} {r} 0.0\n" for t in times))
        (folder / f"Robot{r}_Measurement.dat").write_text(HEADER + f"0.52 {codes[6]} 1.5 0.1\n0.61 999 1.0 0.0\n")


def test_minimal_dataset_parses(tmp_path):
    _write_minimal(tmp_path)
    d = mrclam.load(tmp_path, dt=0.1)
    assert d.steps == 19
    assert np.allclose(d.odometry[..., 0], 0.1) and np.allclose(d.odometry[..., 1], 0.0)
    assert np.allclose(d.groundtruth[3, 2], [0.03, 3.0, 0.0])
    assert np.array_equal(d.meas_step, [5] * 5) and np.array_equal(d.meas_subject, [6] * 5)
    assert d.dropped_unknown_barcode == 5


def test_missing_file_names_it(tmp_path):
    _write_minimal(tmp_path)
    os.remove(tmp_path / "Robot3_Measurement.dat")
    with pytest.raises(ValueError, match="Robot3_Measurement.dat"):
        mrclam.load(tmp_path)


def test_not_a_dataset(tmp_path):
    with pytest.raises(ValueError, match="Barcodes.dat"):
        mrclam.load(tmp_path)
    with pytest.raises(ValueError, match="not a folder"):
        mrclam.load(tmp_path / "nowhere")


@pytest.mark.parametrize(("file", "bad_line", "match"), [
    ("Robot2_Odometry.dat", "1.0 0.1\n", "expected 3 fields"),
    ("Robot4_Groundtruth.dat", "1.0 abc 0.0 0.0\n", "not a number"),
    ("Robot1_Measurement.dat", "0.7 106 nan 0.0\n", "non-finite"),
    ("Robot5_Odometry.dat", "0.01 0.1 0.0\n", "time goes backwards"),
])
def test_malformed_line_names_file_and_line(tmp_path, file, bad_line, match):
    _write_minimal(tmp_path)
    path = tmp_path / file
    lines = path.read_text().splitlines(keepends=True)
    lines.insert(3, bad_line)  # line 4 of the file
    path.write_text("".join(lines))
    with pytest.raises(ValueError, match=rf"{file}, line 4: {match}"):
        mrclam.load(tmp_path)


def test_barcodes_must_cover_every_subject(tmp_path):
    _write_minimal(tmp_path)
    path = tmp_path / "Barcodes.dat"
    path.write_text(path.read_text().replace("20 120\n", ""))
    with pytest.raises(ValueError, match="Barcodes.dat"):
        mrclam.load(tmp_path)


def test_data_path_from_env_or_error(tmp_path, monkeypatch):
    monkeypatch.delenv(mrclam.ENV_VAR, raising=False)
    with pytest.raises(ValueError, match="COLOC_MRCLAM_DATA"):
        mrclam.load()
    _write_minimal(tmp_path)
    monkeypatch.setenv(mrclam.ENV_VAR, str(tmp_path))
    assert mrclam.load().steps == 19


def test_bad_dt(tmp_path):
    _write_minimal(tmp_path)
    with pytest.raises(ValueError, match="dt"):
        mrclam.load(tmp_path, dt=0.0)


# ---------------------------------------------------------------- the shared noise model


def test_calibration_window_rule(dataset6):
    d = dataset6
    assert mrclam_noise.calibration_seconds(d) == max(60.0, 0.1 * d.steps * d.dt)
    assert mrclam_noise.calibration_seconds(d) > 75.0  # dataset 6: 10 % of the run
    assert mrclam_noise.calibration_seconds(d.window(0, 1500)) == 60.0  # a short run: at least 60 s
    assert mrclam_noise.calibration_seconds(d, "baseline") == 60.0
    with pytest.raises(ValueError, match="noise_model"):
        mrclam_noise.calibration_seconds(d, "white")


def test_noise_model_applies_the_calibration_per_step(dataset6):
    """Calibrated: the estimator's correct_odometry / odometry_variance rules, R from the measured range;
    baseline: exactly the constant 1.4826 x MAD noise on the raw commands."""
    import estimators.ukf_relay_se2 as se2

    d = dataset6
    noise = mrclam_noise.calibrate_noise(d, mrclam_noise.calibration_seconds(d))
    model = mrclam_noise.NoiseModel.from_calibration(noise)
    assert model == mrclam_noise.NoiseModel.calibrate(d) and model.calibration is noise
    n, scale = noise["odometry_delay_steps"], np.asarray(noise["odometry_scale"])
    assert n == 2
    every = np.arange(d.steps)
    u = model.odometry(d, every)
    np.testing.assert_array_equal(u, se2.correct_odometry(d.odometry, scale, n))
    # absolute steps: the command logged n steps earlier, held at the run's start (never before step 0)
    np.testing.assert_array_equal(model.odometry(d, [0, 1, 2, 3]), d.odometry[[0, 0, 0, 1]] * scale)
    np.testing.assert_array_equal(model.odometry(d, 500), d.odometry[498] * scale)
    np.testing.assert_array_equal(model.odometry(d, np.array([[500, 7]])), u[None, [500, 7]])
    for bad in (-1, d.steps, 2.0):
        with pytest.raises(ValueError, match="steps"):
            model.odometry(d, bad)
    q = model.odometry_var(u[500])
    assert q.shape == (5, 2)
    np.testing.assert_array_equal(q, se2.odometry_variance(u[500], noise["odometry_var0"],
                                                           noise["odometry_var_gain"], noise["odometry_inflation"]))
    (a, b), (r_r, r_b) = noise["range_var"], noise["measurement_inflation"]
    R = model.measurement_cov(2.5)
    np.testing.assert_array_equal(R, np.diag([r_r * (a + b * 2.5 * 2.5), r_b * noise["sigma_bearing_p68"] ** 2]))
    assert model.measurement_cov(4.0)[0, 0] > R[0, 0] > model.measurement_cov(0.5)[0, 0]  # grows with the range
    stacked = model.measurement_cov(d.meas_range[:50])
    assert stacked.shape == (50, 2, 2)
    np.testing.assert_array_equal(stacked[7], model.measurement_cov(float(d.meas_range[7])))
    plain = mrclam_noise.NoiseModel.from_calibration(noise, inflate_measurements=False)
    assert plain.measurement_cov(2.5)[1, 1] == noise["sigma_bearing_p68"] ** 2

    base_noise = mrclam_noise.calibrate_noise(d, mrclam_noise.calibration_seconds(d, "baseline"))
    base = mrclam_noise.NoiseModel.from_calibration(base_noise, "baseline")
    assert base == mrclam_noise.NoiseModel.calibrate(d, "baseline") != model
    np.testing.assert_array_equal(base.odometry(d, every), d.odometry)
    np.testing.assert_array_equal(base.odometry_var(u), np.broadcast_to(
        [base_noise["sigma_v"] ** 2, base_noise["sigma_w"] ** 2], u.shape))
    for rng in (0.3, 4.0):
        np.testing.assert_array_equal(base.measurement_cov(rng),
                                      np.diag([base_noise["sigma_range"] ** 2, base_noise["sigma_bearing"] ** 2]))


@pytest.mark.parametrize("change, field", [
    ({"kind": "white"}, "noise_model"),
    ({"odometry_delay_steps": -1}, "odometry_delay_steps"),
    ({"odometry_delay_steps": 1.5}, "odometry_delay_steps"),
    ({"odometry_var0": (-1.0, 0.0)}, "odometry_var0"),
    ({"odometry_inflation": (0.0, 1.0)}, "odometry_inflation"),
    ({"odometry_scale": (np.nan, 1.0)}, "odometry_scale"),
    ({"range_var": (1.0,)}, "range_var"),
    ({"range_inflation": 0.0}, "range_inflation"),
    ({"bearing_var": -1.0}, "bearing_var"),
])
def test_noise_model_validates_its_fields(change, field):
    import dataclasses

    good = mrclam_noise.NoiseModel("calibrated", 2, (0.9, 0.8), (1e-4, 1e-3), (0.1, 0.1), (2.0, 2.0), (1e-3, 1e-3),
                                   3.0, 1e-4)
    with pytest.raises(ValueError, match=field):
        dataclasses.replace(good, **change)


@pytest.mark.parametrize("name, module", [("NoiseModel", "coloc_env.data.mrclam_noise"),
                                          ("calibrate_noise", "coloc_env.data.mrclam_noise"),
                                          ("own_navigation", "coloc_env.data.mrclam_navigation")])
def test_moved_names_still_read_from_the_loader_with_a_warning(name, module):
    import importlib

    from coloc_env.data import mrclam

    with pytest.warns(DeprecationWarning, match=rf"coloc_env.data.mrclam.{name} moved to {module}.{name}"):
        moved = getattr(mrclam, name)
    assert moved is getattr(importlib.import_module(module), name)
    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        mrclam.no_such_name  # noqa: B018
