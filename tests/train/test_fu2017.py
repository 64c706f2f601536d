"""``coloc reproduce fu2017`` on small runs, and a short training run on lossy_fusion."""

import json

import numpy as np
import pytest

import agents
import coloc_env
from train.cli import main
from train.reproduce.fu2017 import BEATS

FILTERS = ["naive_kf", "centralized", "centralized_paper_gain", "distributed", "informed_kf", "leader_only_kf",
           "ideal_kf"]
CLAIMS = ["centralized_beats_naive", "distributed_beats_naive", "centralized_beats_distributed", "naive_diverges",
          "centralized_beats_leader_only", "distributed_beats_leader_only"]


def test_reproduce_fu2017_writes_metrics_report_and_figures(tmp_path, capsys):
    assert main(["reproduce", "fu2017", "--runs", "60", "--seed", "2", "--out", str(tmp_path)]) == 0
    folder = tmp_path / "fu2017"
    m = json.loads((folder / "metrics.json").read_text())
    assert (m["runs"], m["seed"], m["steps"]) == (60, 2, 100)
    for key in ("mse", "mse_se", "mse_late", "mse_late_se"):
        assert sorted(m[key]) == ["L2", "L4"]
        for setting in ("L2", "L4"):
            assert sorted(m[key][setting]) == sorted(FILTERS)
    for setting in ("L2", "L4"):
        mse, se = m["mse"][setting], m["mse_se"][setting]
        assert sorted(m["claimed_late"][setting]) == sorted(
            ["centralized", "centralized_paper_gain", "leader_only_kf", "ideal_kf"])
        assert sorted(m["naive_divergence"][setting]) == ["mse_k40_49", "mse_k90_99"]
        assert sorted(m["claims"][setting]) == sorted(CLAIMS)
        assert {type(v) for v in m["claims"][setting].values()} == {bool}  # JSON true/false, not text
        # the informed KF bounds (A), which bounds every other filter of the raw measurements
        assert mse["ideal_kf"] < mse["informed_kf"] < mse["centralized"] < mse["leader_only_kf"]
        assert mse["centralized"] < mse["naive_kf"]
        # (A)'s own covariance is its error, within noise; the general KF's is not
        for name in ("centralized", "centralized_paper_gain", "leader_only_kf", "ideal_kf"):
            gap = abs(m["mse_late"][setting][name] - m["claimed_late"][setting][name])
            assert gap < 3 * m["mse_late_se"][setting][name], name
        assert m["mse_late"][setting]["naive_kf"] > 5 * m["own_covariance_late"][setting]["naive_kf"]
        for claim, (better, worse, _) in BEATS.items():
            c = m["comparisons"][setting][claim]
            # the paired mean is the difference of the two filters' means (linearity), so each claim
            # compares the filters it names over the whole run; a claim that holds orders their MSE
            assert c["difference"] == pytest.approx(mse[better] - mse[worse], abs=1e-9), claim
            assert c["se"] > 0, claim
            if m["claims"][setting][claim]:
                assert mse[better] < mse[worse], claim
        growth = m["comparisons"][setting]["naive_kf_growth_k90_99_minus_k40_49"]
        window = m["naive_divergence"][setting]
        assert growth["difference"] == pytest.approx(window["mse_k90_99"] - window["mse_k40_49"], abs=1e-9)
        if m["claims"][setting]["naive_diverges"]:
            assert window["mse_k90_99"] > window["mse_k40_49"]
        # (B)'s readings of (29), each against the references on the same runs
        readings = m["readings"][setting]
        assert sorted(readings) == sorted(["distributed", "distributed_forward",
                                           "distributed_forward_printed_covariance", "distributed_age_aware"])
        assert readings["distributed"]["mse"] == pytest.approx(mse["distributed"], abs=1e-9)
        for name, row in readings.items():
            assert sorted(row["versus"]) == sorted(["informed_kf", "leader_only_kf", "centralized", "naive_kf"])
            for ref, v in row["versus"].items():
                assert v["difference"] == pytest.approx(row["mse"] - mse[ref], abs=1e-9), (name, ref)
        # predicting the held packet forward removes the lag the printed reading keeps
        assert readings["distributed_forward"]["versus"]["naive_kf"]["difference"] < readings["distributed"][
            "versus"]["naive_kf"]["difference"]
        # Fig. 3 holds at this seed by a wide margin (the paper's main result)
        assert m["claims"][setting]["centralized_beats_naive"]
        assert se["centralized"] > 0
    for name in ("fig3_centralized_vs_naive.png", "fig4_distributed_vs_naive.png",
                 "fig5_centralized_vs_distributed.png", "all_filters.png", "consistency.png", "readings.png",
                 "report.md"):
        assert (folder / name).stat().st_size > 1000
    report = (folder / "report.md").read_text()
    assert "| the centralized algorithm beats the general Kalman filter (Fig. 3) | L2 |" in report
    assert_bound_rows(m["pcrb"])
    ideal = m["pcrb"]["L4"]["rows"]["ideal_kf"]
    assert "## Cramér–Rao bound" in report and f"| L4 | ideal_kf | {ideal['rmse']:.3g} |" in report
    assert f"{m['mse']['L4']['distributed']:.2f}" in report
    assert "| L2 | `distributed_forward` | " in report
    printed = capsys.readouterr().out
    assert "L2.centralized_beats_naive" in printed and "L4.naive_diverges" in printed


def assert_bound_rows(bounds):
    """The pcrb block per setting: local >= delivered >= centralized; every filter's mean squared 2-D error at or
    above the centralized bound, and every filter but the ideal KF (the only one that reads every follower's
    measurement on time) at or above the delivered one, each up to 3 standard errors of the mean over the runs
    (a bound on the expected MSE: a correct one is crossed by the run mean with probability about 0.1 %); the
    ideal KF attains the centralized bound (its covariance is the bound) within 3 standard errors both ways."""
    assert sorted(bounds) == ["L2", "L4"]
    for setting, block in bounds.items():
        assert block["local"] >= block["delivered"] >= block["centralized"] > 0, setting
        assert sorted(block["rows"]) == sorted(FILTERS)
        for name, row in block["rows"].items():
            assert row["mse"] >= block["centralized"] ** 2 - 3 * row["mse_se"], (setting, name)
            assert row["efficiency"] == pytest.approx(row["rmse"] / block["centralized"], rel=1e-12)
            if name != "ideal_kf":
                assert row["mse"] >= block["delivered"] ** 2 - 3 * row["mse_se"], (setting, name)
        ideal = block["rows"]["ideal_kf"]
        assert abs(ideal["mse"] - block["centralized"] ** 2) <= 3 * ideal["mse_se"], setting
    # more followers, more information: a tighter centralized bound; the leader's own is the same
    assert bounds["L4"]["centralized"] < bounds["L2"]["centralized"]
    assert bounds["L4"]["local"] == pytest.approx(bounds["L2"]["local"], rel=1e-12)


def test_reproduce_is_deterministic_and_blocks_do_not_depend_on_the_run_count():
    from coloc_env.config import build_config
    from coloc_env.scenarios.lossy_fusion import LossyFusionConfig
    from train.reproduce.fu2017 import monte_carlo_block

    config = build_config(LossyFusionConfig, {})
    a = monte_carlo_block(2, 5, 7, 0, config)
    b = monte_carlo_block(2, 5, 7, 0, config)
    c = monte_carlo_block(2, 5, 7, 1, config)
    for name in FILTERS:
        np.testing.assert_array_equal(a["errors"][name], b["errors"][name])
    assert not np.array_equal(a["errors"]["ideal_kf"], c["errors"]["ideal_kf"])
    with pytest.raises(ValueError, match="runs"):
        from train.reproduce.fu2017 import run

        run("/nonexistent", runs=1)


def test_training_smoke_run_gives_a_loadable_policy(tmp_path):
    from train.training import train

    # one rollout (128 steps x 32 sub-envs) is 4096 transitions whatever the budget
    path = train("lossy_fusion", 4096, seed=1, out=str(tmp_path), progress_bar=False)
    env = coloc_env.parallel_env("lossy_fusion")
    policy = agents.make_policy(path, env)
    observations, _ = env.reset(seed=0)
    steps = 0
    while env.agents:
        actions = policy.act(observations)
        assert all(env.action_space(a).contains(np.asarray(actions[a], np.float64)) for a in actions)
        observations, rewards, *_ = env.step(actions)
        assert all(np.isfinite(r) for r in rewards.values())
        steps += 1
    assert steps == 100
