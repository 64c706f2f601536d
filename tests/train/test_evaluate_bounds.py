"""coloc evaluate's bound and consistency columns (train.evaluate.attach_bounds)."""

import numpy as np
import pytest

import coloc_env
from train.evaluate import EVAL_SEED_BASE, evaluate_policy


def test_replayed_actions_give_the_bound_of_the_named_policy():
    name = "target_cv/bernoulli_delay/centralized_lmmse"
    row = evaluate_policy(name, "always", 4)
    bound = coloc_env.pcrb(coloc_env.composition_named(name), episodes=4, seed=EVAL_SEED_BASE, policy="always")
    for key in ("centralized", "local", "delivered"):
        assert row[f"pcrb_{key}"] == pytest.approx(np.sqrt(bound[key].mean()), rel=1e-12)
    assert row["efficiency"] == pytest.approx(row["rmse"] / row["pcrb_centralized"], rel=1e-12)
    assert row["pcrb_local"] >= row["pcrb_delivered"] >= row["pcrb_centralized"]
    assert row["efficiency"] > 1.0


def test_bounds_on_the_first_episodes_are_the_bounds_of_those_episodes():
    """bound_episodes K: the errors on all E episodes, the bounds on the first K (the pcrb of K episodes)."""
    name = "target_cv/bernoulli_delay/centralized_lmmse"
    row = evaluate_policy(name, "always", 5, bound_episodes=2)
    whole = evaluate_policy(name, "always", 5)
    bound = coloc_env.pcrb(coloc_env.composition_named(name), episodes=2, seed=EVAL_SEED_BASE, policy="always")
    assert (row["pcrb_episodes"], whole["pcrb_episodes"]) == (2, 5)
    assert row["per_episode_cost"] == whole["per_episode_cost"] and row["rmse"] == whole["rmse"]
    for key in ("centralized", "local", "delivered"):
        assert row[f"pcrb_{key}"] == pytest.approx(np.sqrt(bound[key].mean()), rel=1e-12)
    assert row["pcrb_delivered"] != whole["pcrb_delivered"]  # other episodes, another mean


@pytest.mark.parametrize("scenario", ["bandwidth_fusion", "gps_denied_nbp"])
def test_preset_rows_carry_rmse_bounds_and_the_nees_band(scenario):
    row = evaluate_policy(scenario, "paper", 2)
    assert row["rmse"] > row["pcrb_centralized"] > 0
    low, high = row["nees_band"]
    assert low < 2 < high and 0 <= row["nees_in_band"] <= 1
    assert row["pcrb_model_based"] is False
    assert row["pcrb_local"] > row["pcrb_centralized"]
    # both presets' messages carry estimates: the information-set bound
    assert row["pcrb_local"] >= row["pcrb_delivered"] >= row["pcrb_centralized"]


def test_the_leaderboard_shows_the_bounds_table(tmp_path):
    from train.leaderboard import record

    row = evaluate_policy("bandwidth_fusion", "paper", 2)
    record(row, str(tmp_path), "zhao2020", draw=False)
    text = (tmp_path / "leaderboard.md").read_text()
    assert "Estimation bounds (posterior Cramér-Rao" in text
    line = next(line for line in text.splitlines() if line.startswith("| paper |") and "%" in line)
    assert f"{row['rmse']:.4g}" in line and f"{row['efficiency']:.3g}" in line


@pytest.mark.parametrize("runner", ["run_policy_batched", "run_episodes"])
def test_an_se2_backend_gets_a_pose_nees_at_least_its_position_nees(runner, mrclam_dataset6):
    """mrclam_relay (ukf_se2): beside the position NEES (2 degrees of freedom) the pose NEES (3) with its
    chi^2(3E)/E band. For one covariance, the Mahalanobis distance of the whole pose is at least that of its
    position block (a Schur complement), so each (step, agent) pose NEES >= its position NEES: both read the
    same estimate at the same time."""
    from scipy import stats

    import train.evaluate as ev

    trace = {}
    config = {"data": mrclam_dataset6, "window_steps": 20}
    row = getattr(ev, runner)("mrclam_relay", "paper", 2, trace=trace, **config)
    position, pose = (np.concatenate(trace[key], axis=0) for key in ("nees", "pose_nees"))  # (E, K, N) each
    assert pose.shape == position.shape and np.all(pose >= position - 1e-9) and np.any(pose > position + 1e-6)
    out = ev.attach_bounds(row, "mrclam_relay", EVAL_SEED_BASE, trace, bounds=False, **config)
    assert out["pose_nees"] == pytest.approx(pose.mean(), rel=1e-12)
    assert out["pose_nees_band"] == pytest.approx([stats.chi2.ppf(q, 6) / 2 for q in (0.025, 0.975)], rel=1e-12)
    assert out["pose_nees"] >= out["nees"]


def test_a_position_backend_gets_no_pose_nees():
    row = evaluate_policy("circles/ideal/ukf_ccl", "always", 2, bounds=False)
    assert row["nees"] is not None and "pose_nees" not in row
