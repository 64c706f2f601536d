"""coloc reproduce mrclam: the CLI choice, the data error, and a quick run on dataset 6."""

from __future__ import annotations

import json
import os

import pytest

from train.cli import PAPERS, build_parser

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DATASET6 = os.path.join(REPO_ROOT, "..", "shared", "data", "mrclam", "MRCLAM_Dataset6")


def test_cli_accepts_mrclam_not_in_all():
    args = build_parser().parse_args(["reproduce", "mrclam", "--data", "somewhere"])
    assert args.paper == "mrclam" and args.data == "somewhere"
    assert "mrclam" not in PAPERS


def test_missing_data_is_a_clear_error(tmp_path, monkeypatch):
    from train.reproduce import mrclam

    monkeypatch.delenv("COLOC_MRCLAM_DATA", raising=False)
    with pytest.raises(ValueError, match="COLOC_MRCLAM_DATA"):
        mrclam.run(str(tmp_path), quick=True)


def test_quick_reproduce_on_dataset6(tmp_path, monkeypatch):
    if not os.path.isdir(DATASET6):
        pytest.skip(f"MRCLAM dataset 6 not found at {DATASET6}")
    from train.reproduce import mrclam

    monkeypatch.setattr(mrclam, "QUICK_STEPS", 600)
    metrics = mrclam.run(str(tmp_path), quick=True, data=DATASET6)
    folder = tmp_path / "mrclam"
    for name in ("metrics.json", "report.md", "trajectories.png", "error_over_time.png", "nees.png"):
        assert (folder / name).is_file()
    stored = json.loads((folder / "metrics.json").read_text())
    assert set(stored["rmse_position"]) == {"IL", "CCL", "DCL"}
    assert set(stored["rmse_position"]["CCL"]) == {f"robot{i}" for i in range(1, 6)} | {"mean"}
    assert stored["steps"] == 600
    assert metrics["max_abs_diff_dcl_ccl"] < 1e-9
    assert metrics["rmse_position"]["CCL"]["mean"] < metrics["rmse_position"]["IL"]["mean"]
