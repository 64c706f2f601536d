"""Leaderboard rows and target verdicts on hand-made tables (the paired arithmetic: test_paired_leaderboard)."""

import numpy as np

from tests.helpers import leaderboard_row as _row
from train.leaderboard import rows, target_verdict


def test_nlos_target_uses_the_validated_best_constant_not_the_hindsight_bound_or_paper():
    rng = np.random.default_rng(1)
    best = 7.0 + rng.standard_normal(20)
    table = {"paper": _row("paper", best + 3.0, scenario="nlos_horizon"),
             "best_constant": _row("best_constant", best, scenario="nlos_horizon"),
             "constant:6": _row("constant:6", best - 0.3, scenario="nlos_horizon"),  # not a baseline: one of many
             "bound_hindsight_constant": _row("bound_hindsight_constant", best - 2.0, scenario="nlos_horizon"),
             "x/seed2/model.zip": _row("x/seed2/model.zip", best + 0.5 + 0.01 * rng.standard_normal(20),
                                       scenario="nlos_horizon")}
    line = target_verdict("nlos_horizon", table)
    assert "Strongest realizable baseline: best_constant" in line and "seed2: worse" in line and "**not met**" in line
    assert target_verdict("nlos_horizon", {"paper": table["paper"]}) is None


def test_stochastic_models_get_their_own_summary_and_do_not_count_for_the_target():
    paper = np.linspace(1.4, 1.6, 10)
    table = {"paper": _row("paper", paper, comm=1.5), "a.zip": _row("a.zip", paper + 0.1, comm=0.8),
             "a.zip (stochastic)": _row("a.zip (stochastic)", paper - 0.1, comm=0.8)}
    names = [r["policy"] for r in rows(table)]
    assert names == ["paper", "a.zip (stochastic)", "a.zip", "trained (mean of 1 seed)",
                     "trained, stochastic (mean of 1 seed)"]
    line = target_verdict("relay_ukf", table)
    assert "a.zip: worse" in line and "stochastic" not in line


def test_trained_summary_pairs_the_per_episode_mean_over_seeds():
    paper = np.linspace(1.0, 2.0, 12)
    table = {"paper": _row("paper", paper), "s0/model.zip": _row("s0/model.zip", paper - 0.2),
             "s1/model.zip": _row("s1/model.zip", paper + 0.1)}
    summary = rows(table)[-1]
    assert summary["policy"] == "trained (mean of 2 seeds)"
    np.testing.assert_allclose(summary["per_episode_cost"], paper - 0.05, atol=1e-12)
    assert summary["spread"] == (float(np.mean(paper - 0.2)), float(np.mean(paper + 0.1)))
