"""`coloc reproduce wang2019` end to end on a small run, and its filterpy peer."""

import json

import numpy as np
import pytest

from coloc_env.config import build_config
from coloc_env.scenarios.relay_ukf import RelayUKFConfig
from train.cli import main


@pytest.mark.slow  # the whole reproduction (~30 s); its parts are pinned in test_pinned_numbers.py, its figures
# in test_figures.py and its backends' numbers in test_reproductions_drive_backends.py; run with -m slow
def test_reproduce_wang2019_writes_metrics_report_and_figures(tmp_path):
    assert main(["reproduce", "wang2019", "--runs", "2", "--seed", "2", "--out", str(tmp_path)]) == 0
    folder = tmp_path / "wang2019"
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["runs"] == 2
    assert metrics["max_abs_diff_dcl_ccl"] < 1e-9
    assert metrics["max_abs_diff_ccl_filterpy"] < 1e-9
    err = metrics["mean_distance_error"]
    assert set(err) == {"IL", "CCL", "DCL"}
    assert abs(err["DCL"] - err["CCL"]) < 1e-9 and err["CCL"] < err["IL"]
    assert sorted(metrics["error_vs_p"], key=float) == ["0.05", "0.1", "0.25", "0.5", "1.0"]
    il = {row["IL"] for row in metrics["error_vs_p"].values()}
    assert len(il) == 1  # common random numbers: dead reckoning sees no measurement
    assert metrics["error_vs_p"]["0.5"]["CCL"] == err["CCL"]
    ccl = [metrics["error_vs_p"][p]["CCL"] for p in ("0.05", "1.0")]
    assert ccl[1] < ccl[0] < err["IL"]
    trunc = metrics["truncated_chain"]
    assert trunc["paper"]["first_indefinite_step"] is not None and trunc["consistent"]["min_eigenvalue"] > 0
    assert set(metrics["claims"]) >= {"dcl_equals_ccl", "cooperation_beats_il", "ccl_matches_filterpy"}
    for name in ("fig5_trajectories.png", "fig6_platform_errors.png", "fig7_error_vs_p.png", "fig8_topology.png",
                 "truncated_chain.png", "report.md"):
        assert (folder / name).stat().st_size > 1000
    report = (folder / "report.md").read_text()
    assert "| IL |" in report and f"{err['IL']:.3f}" in report
    # the bound: the circles bound model is the world's problem (with or without turn-rate noise), so every
    # estimator's mean squared error is at or above pcrb_centralized up to 3 standard errors of its mean over the
    # runs (a correct bound is crossed with probability about 0.1 %)
    bounds = metrics["pcrb"]
    assert sorted(bounds) == ["default", "no_turn_rate_noise"]
    for block in bounds.values():
        # the preset's ukf_dcl relays estimates: its delivered bound is the information-set bound
        assert block["local"] > block["delivered"] >= block["centralized"] > 0
        assert sorted(block["rows"]) == ["CCL", "DCL", "IL"] and block["episodes"] == 2
        assert block["rows"]["CCL"]["mse"] == pytest.approx(block["rows"]["DCL"]["mse"], rel=1e-9)
        # IL reads no range, the bound every range: dead reckoning is far above it
        assert block["rows"]["IL"]["efficiency"] > block["rows"]["CCL"]["efficiency"]
    for setting, block in bounds.items():
        for name, row in block["rows"].items():
            assert row["mse"] >= block["centralized"] ** 2 - 3 * row["mse_se"], (setting, name)
    assert "## Cramér–Rao bound" in report and "| no turn-rate noise | CCL |" in report


def test_filterpy_update_equals_ccl():
    import estimators.ukf_relay as ur
    from train.reproduce.wang2019 import ccl_filterpy_difference, filterpy_ccl_update

    rng = np.random.default_rng(0)
    x = rng.normal(size=(4, 2)) * 40
    M = rng.normal(size=(8, 8))
    P = M @ M.T + np.eye(8)
    fx, fP = filterpy_ccl_update(x, P, 2, 3, 50.0, 1.0)
    cx, cP = ur.ccl_update(x, P, 2, 3, 50.0, 1.0)
    np.testing.assert_allclose(fx, cx, atol=1e-9)
    np.testing.assert_allclose(fP, cP, atol=1e-9)
    assert ccl_filterpy_difference(build_config(RelayUKFConfig, {"horizon": 100}), seed=0) < 1e-9
