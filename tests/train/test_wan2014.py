"""``coloc reproduce wan2014`` on a small configuration, the training smoke run and the bench rows."""

import json

import numpy as np
import pytest

from coloc_env.config import build_config
from coloc_env.scenarios.gps_denied_nbp import GpsDeniedNbpConfig
from train.reproduce import wan2014

SMALL = {"num_agents": 6, "horizon": 3, "num_particles": 30}


def test_reproduce_writes_the_spec_metrics_report_and_figures(tmp_path):
    config = build_config(GpsDeniedNbpConfig, SMALL)
    metrics = wan2014.run(str(tmp_path), runs=2, seed=3, config=config)
    folder = tmp_path / "wan2014"
    on_disk = json.loads((folder / "metrics.json").read_text())
    assert on_disk["claims"] == metrics["claims"]
    # every claim of the report's table, so that a summary counting metrics.json counts what report.md shows
    assert list(metrics["claims"]) == ["case_study", "dnbp_beats_ls_default", "dnbp_below_ls_over_time",
                                       "dr_about_twice", "ls_degrades_sparse_normals", "dnbp_beats_ls_mid_range",
                                       "ls_beats_dnbp_large_range", "error_increases_with_noise",
                                       "dnbp_always_better_noise", "error_decreases_with_M", "time_grows_with_M"]
    from train.demo_summary import _report_claims
    assert [holds for _, holds in _report_claims(str(folder / "report.md"))] == list(metrics["claims"].values())
    assert metrics["paper"] == "wan2014" and metrics["runs"] == 2 and metrics["seed_base"] == 3
    d = metrics["default"]
    for method in ("dnbp", "ls", "dr"):
        assert len(d[method]["err_fault_t"]) == 3
        assert {"err_fault", "err_all", "err_normal", "fail_rate", "err_fault_run_std"} <= set(d[method])
    assert d["time_per_fault_uav_step_s"] > 0 and d["broadcasts_per_step"] > 0
    assert d["msgs_per_step"] >= d["broadcasts_per_step"]
    assert list(metrics["sweep_normal_ratio"]) == ["0.2", "0.3", "0.5", "0.7"]
    assert list(metrics["sweep_particles"]) == ["50", "100", "200", "300"]
    assert list(metrics["sweep_comm_range"]) == ["150", "250", "350", "500"]
    # the fixed-proportion sweep has exactly round(ratio N) normal UAVs at every step
    assert metrics["sweep_normal_ratio"]["0.5"]["fault_fraction"] == 0.5
    # a point equal to the default is the default (common random numbers)
    assert metrics["sweep_gps_std"]["3"] == metrics["default"]
    assert metrics["case_study"]["schedule_matches_paper"] is True
    for name in ("fig4_case_study.png", "fig5_error_vs_time.png", "fig6_sweeps.png", "tradeoff.png", "report.md"):
        assert (folder / name).stat().st_size > 1000
    report = (folder / "report.md").read_text()
    assert "| Fig. 6(b): for R > 500 m LS is slightly better than dNBP |" in report
    # the bound model of gps_denied is the world's own and every method reads no more than it: each method's mean
    # squared error is at or above pcrb_centralized up to 3 standard errors of its mean over the runs (a correct
    # bound is crossed with probability about 0.1 %)
    block = on_disk["pcrb"]
    assert block["local"] > block["centralized"] > 0 and block["episodes"] == 2
    assert sorted(block["rows"]) == ["dnbp", "dr", "ls"]
    for name, row in block["rows"].items():
        assert row["mse"] >= block["centralized"] ** 2 - 3 * row["mse_se"], name
    assert "_mse_runs" not in on_disk["default"]
    assert "## Cramér–Rao bound" in report and "| default point | dnbp |" in report


def test_evaluate_point_is_reproducible_and_baselines_are_ordered():
    base = {**SMALL, "horizon": 4, "num_normal": 3}
    a = wan2014.evaluate_point({}, base, 2, 0)
    b = wan2014.evaluate_point({}, base, 2, 0)
    for key in ("dnbp", "ls", "dr"):
        assert a[key] == b[key]
    assert a["fault_fraction"] == 0.5 and a["dnbp"]["err_fault"] != a["ls"]["err_fault"]
    assert np.isclose(a["dr"]["err_normal"], a["ls"]["err_normal"])  # normal UAVs: the same GPS filter
    c = wan2014.evaluate_point({}, base, 2, 1)
    assert c["dnbp"] != a["dnbp"]


def test_train_smoke_then_the_model_plays_the_env(tmp_path):
    import agents
    import coloc_env
    from train.training import train

    path = train("gps_denied_nbp", timesteps=64, seed=1, out=str(tmp_path), progress_bar=False, curve_points=0)
    assert (tmp_path / "gps_denied_nbp" / "seed1" / "model.zip").is_file()
    env = coloc_env.parallel_env("gps_denied_nbp", num_agents=10, num_particles=20, horizon=3)
    policy = agents.make_policy(path, env)
    observations, _ = env.reset(seed=0)
    steps = 0
    while env.agents:
        actions = policy.act(observations)
        assert actions["uav_0"].shape == (5,)
        assert all(env.action_space(a).contains(np.asarray(actions[a], env.action_space(a).dtype)) for a in actions)
        observations, rewards, _, _, infos = env.step(actions)
        steps += 1
        for agent, info in infos.items():
            assert np.isfinite(rewards[agent])
            # the reported error is the distance of the played belief's estimate from the truth
            distance = np.linalg.norm(np.asarray(info["estimated_position"]) - np.asarray(info["true_position"]))
            assert info["error"] == pytest.approx(distance, abs=1e-9), agent
    assert steps == 3


def test_bench_reports_time_per_fault_uav_step():
    from train.bench.throughput import ESTIMATOR_STEPS, _gps_denied_nbp_particle_rows

    ESTIMATOR_STEPS["gps_denied_nbp"](2)()
    rows = _gps_denied_nbp_particle_rows(0.1, batch=1, steps=1)
    assert [r["what"] for r in rows] == [f"dNBP step, M = {m}" for m in (50, 100, 200, 300)]
    assert all(r["time_per_fault_uav_step_s"] > 0 for r in rows)
