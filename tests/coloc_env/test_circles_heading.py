"""ukf_ccl / ukf_dcl on circles: the heading-error model is consistent at the world's defaults, the
position-only one is not, and the heading model is no less accurate (paired seeded episodes)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import coloc_env
from train.consistency import band_checks, play

EPISODES, STEPS, SEED = 20, 400, 100


def run(backend: str, motion: str, episodes: int = EPISODES, steps: int = STEPS, **world):
    """Per-step own-position NEES (K, E, N) and per-episode mean squared position error (E,), `always` policy."""
    nees, squared = play(backend, motion, episodes, SEED, world, horizon=steps)
    return nees, squared.mean(axis=(0, 2))


@pytest.fixture(scope="module")
def ccl_runs():
    return {motion: run("ukf_ccl", motion) for motion in ("heading", "displacement")}


MATCHED_PRIOR = {"initial_position_std": 1e-6}  # the world starts each estimate at the true position


def test_heading_model_is_consistent_at_the_defaults_and_position_only_is_not():
    """circles' defaults (turn-rate noise on) with the prior that matches the known start: 40 independent
    checks (one step and agent each, steps 3..120, each on its own 20 seeded episodes). With the heading model
    at most Binomial(40, 0.05)'s 99.9 % quantile lie outside the chi-square(40)/20 band; the position-only
    model lies above it more often than chance allows."""
    means, (low, high), allowed = band_checks("ukf_ccl", "heading", MATCHED_PRIOR)
    assert allowed == 7
    assert int(np.sum((means < low) | (means > high))) <= allowed, np.round(means, 2).tolist()
    means, (low, high), allowed = band_checks("ukf_ccl", "displacement", MATCHED_PRIOR)
    assert int(np.sum(means > high)) > allowed


def test_heading_model_is_no_less_accurate(ccl_runs):
    diff = ccl_runs["heading"][1] - ccl_runs["displacement"][1]
    upper = diff.mean() + stats.t.ppf(0.975, len(diff) - 1) * diff.std(ddof=1) / np.sqrt(len(diff))
    assert upper < 0.0


def test_dcl_over_ideal_equals_ccl_with_the_heading_model():
    """Complete chains: UKF-DCL on (x, y, e) blocks is UKF-CCL (the relay's d-dimensional blocks)."""
    ccl = run("ukf_ccl", "heading", episodes=2, steps=100)[0]
    dcl = run("ukf_dcl", "heading", episodes=2, steps=100)[0]
    np.testing.assert_allclose(dcl, ccl, rtol=1e-7)


def test_without_turn_rate_noise_both_motions_are_the_same_filter():
    a = run("ukf_ccl", "heading", episodes=2, steps=100, heading_noise=False)
    b = run("ukf_ccl", "displacement", episodes=2, steps=100, heading_noise=False)
    np.testing.assert_array_equal(a[0], b[0])


def test_bad_motion_is_refused():
    with pytest.raises(ValueError, match="motion"):
        coloc_env.compose(world="circles", network="ideal", backend={"name": "ukf_ccl", "motion": "unicycle"})
