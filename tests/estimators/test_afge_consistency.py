"""How conservative DFIR's covariance is, by fusion weighting, with the estimator's model matched.

The distance weights of Def. 6 sum to one (a covariance-intersection bound): with n independent fixes per
stamp the fused information keeps about 1/n of the plain sum, so P overstates the error covariance about n
times; the information weighting (the plain sum) is consistent. Measured in docs/gao2016.md, section 15.
"""

import numpy as np

from train.reproduce.gao2016 import composition_errors

MATCHED = {"p_nlos": 0.0, "turn_rates_deg": (0.0, 0.0, 0.0, 0.0), "accel_sigma": 1e-3}


def test_distance_weights_are_conservative_by_about_the_packets_fused_and_information_weights_are_not():
    seeds = [0, 1]
    distance = composition_errors({"name": "dfir", "weighting": "distance"}, seeds, MATCHED, horizon=120)
    information = composition_errors({"name": "dfir", "weighting": "information"}, seeds, MATCHED, horizon=120)
    # the same episodes: per episode, the CI bound's NEES is below half the plain sum's (n = 4 fixes fused)
    assert np.all(distance["nees"] < 0.5 * information["nees"])
    assert np.all(distance["nees"] < 1.0)  # conservative: below the 2 of a consistent 2-D estimate
    assert np.all((information["nees"] > 1.2) & (information["nees"] < 3.0))  # about 2, 4 agents x 70 steps
