"""The maximum-likelihood noise model of MRCLAM: the fit's optimality, and ukf_se2's consistency on dataset 6
where the noise was not fitted (mean 3-DOF NEES in [2.4, 3.75], >= 90 % of (step, robot) values in the
chi-square(3) 95 % band, position RMSE at most 10 % above the moment rules' model on the same steps)."""

from __future__ import annotations

import numpy as np
import pytest

from coloc_env.data import mrclam, mrclam_noise


def test_fit_is_a_local_optimum_of_the_likelihood(mrclam_dataset6):
    """On the first 60 s the search settles: the fitted scales cost less than their start and no more than any
    compass neighbour at the last factor."""
    d = mrclam.load_cached(mrclam_dataset6).window(0, 700)
    noise = mrclam_noise.calibrate_noise(d, 60.0)
    steps = int(round(noise["calibration_s"] / d.dt))
    fit = mrclam_noise.fit_noise_scales(d, noise, steps)
    assert fit["likelihood_converged"]
    centre = np.log(fit["likelihood_scale"])
    f = np.log(mrclam_noise.LIKELIHOOD_FACTORS[-1])
    points = np.exp(np.concatenate([[centre], centre + f * np.eye(4), centre - f * np.eye(4),
                                    [np.log(fit["likelihood_start"])]]))
    cost = mrclam_noise._likelihood_costs(d, noise, points, steps, 0.01, mrclam_noise.GATE_999)
    assert cost[0] / (steps * mrclam.NUM_ROBOTS) == pytest.approx(fit["likelihood_cost"], rel=1e-12)
    assert np.all(cost[0] <= cost[1:-1]) and cost[0] < cost[-1]
    model = mrclam_noise.NoiseModel.from_calibration({**noise, **fit}, "likelihood")
    assert model.odometry_inflation == tuple(fit["likelihood_scale"][:2])
    assert model.range_inflation == fit["likelihood_scale"][2]
    assert model.bearing_var == pytest.approx(fit["likelihood_scale"][3] * noise["sigma_bearing_p68"] ** 2)


def test_likelihood_kind_needs_its_scales():
    noise = {"odometry_delay_steps": 0, "odometry_scale": [1.0, 1.0], "odometry_var0": [1e-4, 1e-3],
             "odometry_var_gain": [0.0, 0.0], "range_var": [1e-3, 0.0], "sigma_bearing_p68": 0.01}
    with pytest.raises(ValueError, match="likelihood_scale"):
        mrclam_noise.NoiseModel.from_calibration(noise, "likelihood")
    with pytest.raises(ValueError, match="noise_model must be one of"):
        mrclam_noise.NoiseModel.from_calibration(noise, "maximum")


@pytest.mark.slow
def test_ukf_se2_is_consistent_on_dataset6_where_not_fitted(mrclam_dataset6):
    """The whole run through the ukf_se2 backend (UKF-DCL over complete chains, checked equal to CCL step by
    step by run_filters), evaluated on the steps after the calibration window."""
    from train.reproduce import mrclam as reproduce

    d = mrclam.load_cached(mrclam_dataset6)
    moments = mrclam_noise.calibrate_noise(d, mrclam_noise.calibration_seconds(d, "likelihood"))
    start = int(round(moments["calibration_s"] / d.dt))
    noise = {**moments, **mrclam_noise.fit_noise_scales(d, moments, start)}
    ml = reproduce._evaluation_of(d, reproduce.run_filters(d, noise, kind="likelihood"), start, "DCL")
    before = reproduce._evaluation_of(d, reproduce.run_filters(d, moments), start, "DCL")
    assert 2.4 <= ml["nees_mean"] <= 3.75
    assert ml["fraction_in_band"] >= 0.9
    assert ml["rmse_position_mean"] <= 1.1 * before["rmse_position_mean"]
    assert before["nees_mean"] > 3.75  # the moment rules' model is the overconfident one
