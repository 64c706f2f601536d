"""``coloc bench --scaling``: the table's shape and fields, refused sizes, and refused flags (no speed is asserted)."""

from __future__ import annotations

import json
import os

import pytest

from train.bench import growth_exponent, run_scaling, scaling_compositions
from train.cli import main


def test_the_quick_table_has_one_row_per_composition_and_batch(tmp_path):
    pairs = [("dead_reckoning", "broadcast")]
    rows = run_scaling(str(tmp_path), quick=True, compositions=pairs, sizes=(5, 6, 200), cap=300,
                       layouts=("fixed density",))
    with open(os.path.join(tmp_path, "bench", "scaling.json")) as f:
        saved = json.load(f)
    assert os.path.getsize(os.path.join(tmp_path, "bench", "scaling.png")) > 0
    with open(os.path.join(tmp_path, "bench", "scaling.md")) as f:
        table = f.read().splitlines()
    assert table[0].startswith("| layout | backend |") and len(table) == 2 + len(rows)
    assert table[2].split(" | ")[7] == "refused"
    assert saved["sizes"] == [5, 6, 200] and saved["layouts"] == ["fixed density"]
    assert len(saved["rows"]) == len(rows) == len(pairs) * len(saved["batches"])
    for row in saved["rows"]:
        assert {"layout", "backend", "network", "batch", "current"} <= set(row)
        entry = row["current"]
        assert len(entry["env_steps_per_s"]) == len(entry["status"]) == 3
        assert entry["status"][:2] == ["ok", "ok"] and all(r > 0 for r in entry["env_steps_per_s"][:2])
        # 200 agents: refused by the world, with its message (not "over cap")
        assert entry["status"][2] == "refused" and entry["env_steps_per_s"][2] is None
        assert "world.num_agents must be in [2, 128]" in entry["errors"]["200"]
        assert entry["exponent"] == pytest.approx(growth_exponent((5, 6), entry["env_steps_per_s"][:2]))


def test_the_growth_exponent_is_the_log_log_slope_of_time_per_step():
    assert growth_exponent((10, 20, 40), (800.0, 200.0, 50.0)) == pytest.approx(2.0)
    assert growth_exponent((10, 20), (100.0, None)) is None


def test_every_backend_that_runs_on_gps_denied_has_a_row_and_the_ukfs_also_over_ideal_and_gilbert_elliott():
    pairs = scaling_compositions()
    assert {"dead_reckoning", "range_ls", "dnbp", "ukf_ccl", "ukf_dcl"} <= {b for b, _ in pairs}
    assert ("ukf_ccl", "ideal") in pairs and ("ukf_dcl", "ideal") in pairs
    assert ("ukf_ccl", "gilbert_elliott") in pairs and ("ukf_dcl", "gilbert_elliott") in pairs


@pytest.mark.parametrize("argv,flag", [
    (["--cap", "10"], "--cap"),
    (["--scaling", "--cap", "0"], "--cap"),
    (["--scaling", "--cap", "nan"], "--cap"),
    (["--scaling", "--scenarios", "relay_ukf"], "--scenarios"),
    (["--scaling", "--against", "HEAD", "--rounds", "3"], "--rounds"),
    (["--backends", "dnbp"], "--backends"),
    (["--sizes", "10"], "--sizes"),
    (["--batches", "8"], "--batches"),
    (["--scaling", "--backends", "dnbp", "nosuch"], "--backends"),
])
def test_refused_flags_name_the_flag(argv, flag, tmp_path, capsys):
    assert main(["bench", *argv, "--out", str(tmp_path)]) == 2
    assert flag in capsys.readouterr().err
    assert not os.path.exists(os.path.join(tmp_path, "bench", "scaling.json"))


@pytest.mark.parametrize("argv,message", [
    (["--sizes", "1"], "integer in [2, 128], got '1'"),
    (["--sizes", "129"], "integer in [2, 128], got '129'"),
    (["--batches", "0"], "integer in [1, 4096], got '0'"),
])
def test_sizes_and_batches_outside_their_range_are_refused(argv, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["bench", "--scaling", *argv, "--out", str(tmp_path)])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert argv[0] in err and message in err


def test_the_selection_flags_pick_the_rows_and_columns(tmp_path):
    assert main(["bench", "--scaling", "--quick", "--backends", "dead_reckoning", "--sizes", "6", "4", "--batches",
                 "2", "--out", str(tmp_path)]) == 0
    with open(os.path.join(tmp_path, "bench", "scaling.json")) as f:
        saved = json.load(f)
    assert saved["sizes"] == [4, 6] and saved["batches"] == [2]
    assert {(row["backend"], row["network"], row["batch"]) for row in saved["rows"]} == {
        ("dead_reckoning", "broadcast", 2)}
    assert len(saved["rows"]) == 2  # one per layout
