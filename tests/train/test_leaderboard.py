"""Leaderboard target verdicts on hand-made tables."""

from train.leaderboard import target_verdict


def _row(policy, mean, ci=0.1, comm=1.0, scenario="relay_ukf"):
    return {"scenario": scenario, "policy": policy, "mean_cost": mean, "ci95": ci, "paper_cost": mean,
            "communication_per_step": comm, "episodes": 10}


def test_verdict_needs_fewer_messages_where_the_target_says_so():
    table = {"paper": _row("paper", 1.50, comm=1.5), "/m/seed0/model.zip": _row("/m/seed0/model.zip", 1.45, comm=1.0)}
    assert "**met**" in target_verdict("relay_ukf", table)
    table["/m/seed0/model.zip"] = _row("/m/seed0/model.zip", 1.45, comm=1.6)  # better error, more hops
    assert "**not met**" in target_verdict("relay_ukf", table)


def test_verdict_margin_and_noise():
    paper = _row("paper", 100.0, ci=5.0, scenario="lossy_fusion")
    for mean, verdict in ((89.0, "**met**"), (93.0, "**not met, within noise**"), (99.0, "**not met**")):
        table = {"paper": paper, "a.zip": _row("a.zip", mean, ci=1.0, scenario="lossy_fusion")}
        assert verdict in target_verdict("lossy_fusion", table), mean


def test_verdict_uses_the_best_constant_horizon_and_skips_untrained_tables():
    table = {"paper": _row("paper", 3.0), "constant:6": _row("constant:6", 2.7),
             "constant:12": _row("constant:12", 2.9), "oracle_constant": _row("oracle_constant", 2.0),
             "x.zip": _row("x.zip", 2.8)}
    line = target_verdict("nlos_horizon", table)
    assert "constant:6 2.7" in line and "**not met, within noise**" in line
    assert target_verdict("nlos_horizon", {"paper": _row("paper", 3.0)}) is None


def test_stochastic_models_get_their_own_summary_and_do_not_count_for_the_target():
    from train.leaderboard import rows

    table = {"paper": _row("paper", 1.5, comm=1.5), "a.zip": _row("a.zip", 1.6, comm=0.8),
             "a.zip (stochastic)": _row("a.zip (stochastic)", 1.4, comm=0.8)}
    names = [r["policy"] for r in rows(table)]
    assert names == ["paper", "a.zip (stochastic)", "a.zip", "trained (mean of 1 seed)",
                     "trained, stochastic (mean of 1 seed)"]
    assert "Trained 1.6 " in target_verdict("relay_ukf", table)
