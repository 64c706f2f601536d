"""``coloc reproduce gao2016`` end to end on a small number of runs."""

import functools
import json

import pytest

from coloc_env.config import build_config
from coloc_env.scenarios.nlos_horizon import NlosHorizonConfig
from train.cli import main
from train.reproduce import gao2016

SPEC_KEYS = {
    "dfir_rmse_by_horizon", "dfir_best_horizon", "dfir_best_rmse", "afge_rmse", "afge_paper_likelihood_rmse",
    "afge_smoothed_rmse", "afge_mean_horizon", "afge_beats_best_constant", "afge_minus_best_mse_mean",
    "afge_minus_best_mse_2se", "kf_oracle_rmse", "kf_mode_mean_rmse", "kf_blind_rmse", "kf_oracle_matched_q_rmse",
    "kf_blind_matched_q_rmse", "afge_mean_horizon_turns", "afge_mean_horizon_straight", "afge_mode_mean_rmse",
    "afge_blind_rmse", "sweep", "packets_per_step_mean", "fused_obs_rate_lag0", "fused_obs_rate_final", "runs",
    "seed", "steps", "warmup", "T",
}


def test_reproduce_gao2016_writes_the_spec_metrics_report_and_figures(tmp_path, capsys, monkeypatch):
    # the CLI end to end on 150-step episodes with one turn (80..110): every estimator is a composition
    # stepped 1000 times per run at the paper's length, a minute for this test
    short = build_config(NlosHorizonConfig, {"horizon": 150, "turn_windows": ((80, 110),), "turn_rates_deg": (3.0,)})
    monkeypatch.setattr(gao2016, "run", functools.partial(gao2016.run, config=short))
    assert main(["reproduce", "gao2016", "--runs", "2", "--out", str(tmp_path)]) == 0
    folder = tmp_path / "gao2016"
    metrics = json.loads((folder / "metrics.json").read_text())
    assert set(metrics) == SPEC_KEYS | {"pcrb"}
    assert sorted(map(int, metrics["dfir_rmse_by_horizon"])) == list(range(2, 31))
    curve = metrics["dfir_rmse_by_horizon"]
    assert metrics["dfir_best_rmse"] == min(curve.values()) == curve[str(metrics["dfir_best_horizon"])]
    assert metrics["afge_beats_best_constant"] == (metrics["afge_rmse"] < metrics["dfir_best_rmse"])
    assert (metrics["runs"], metrics["seed"], metrics["steps"], metrics["warmup"]) == (2, 2016, 150, 50)
    sweep = metrics["sweep"]
    no_delay, heavy = [1.0, 0.0, 0.0, 0.0], [0.3, 0.25, 0.2, 0.15]
    assert [(s["p_nlos"], s["delay_probs"], s["mode_info"]) for s in sweep] == [
        (0.3, [0.6, 0.2, 0.1, 0.05], "known"), (0.1, [0.6, 0.2, 0.1, 0.05], "known"),
        (0.5, [0.6, 0.2, 0.1, 0.05], "known"), (0.3, no_delay, "known"), (0.3, heavy, "known"),
        (0.3, no_delay, "mean"), (0.3, no_delay, "blind"), (0.3, heavy, "mean"), (0.3, heavy, "blind")]
    assert sweep[0]["afge_smoothed_rmse"] == metrics["afge_smoothed_rmse"]
    assert sweep[0]["afge_rmse"] == metrics["afge_rmse"] and sweep[0]["kf_rmse"] == metrics["kf_oracle_rmse"]
    assert 4 <= metrics["afge_mean_horizon"] <= 30
    assert 0 < metrics["fused_obs_rate_lag0"] <= metrics["fused_obs_rate_final"] <= 1
    for name in ("fig4_rmse_vs_horizon.png", "fig6_rmse_over_time.png", "horizon_over_time.png",
                 "fig5b_packets_per_step.png", "report.md"):
        assert (folder / name).stat().st_size > 1000
    report = (folder / "report.md").read_text()
    assert "lower time-averaged RMSE than DFIR with the best constant horizon" in report
    assert f"{metrics['afge_rmse']:.3f}" in report
    assert "afge_beats_best_constant" in capsys.readouterr().out
    # the bound beside the default setting's estimators: over 2 seeded episodes (episodes <= runs), k >= 50;
    # every row's mean squared error is at least the centralized bound up to 3 standard errors over the runs
    block = metrics["pcrb"]
    assert (block["episodes"], block["seed"], block["same_episodes"]) == (2, 2016, False)
    assert set(block["rows"]) == {name for name, _, _ in gao2016.BOUND_ROWS} | {"dfir_best"}
    assert block["rows"]["afge"]["rmse"] ** 2 == pytest.approx(metrics["afge_rmse"] ** 2, rel=1e-12)
    assert block["rows"]["dfir_best"]["rmse"] == pytest.approx(metrics["dfir_best_rmse"], rel=1e-12)
    assert 0 < block["centralized"] <= block["delivered"] <= block["local"]
    for name, row in block["rows"].items():
        assert row["mse"] >= block["centralized"] ** 2 - 3 * row["mse_se"], name
    assert "## Cramér–Rao bound" in report and "LOS/NLOS mode of every link known" in report
