"""``coloc bench --against REF``: the plumbing (export, one subprocess per tree, the joined table), not a speed."""

import json
import os
import shutil
import subprocess

import pytest

from train import bench
from train.bench import against, throughput

pytestmark = pytest.mark.skipif(shutil.which("git") is None or subprocess.run(
    ["git", "-C", os.path.dirname(bench.__file__), "rev-parse", "HEAD"], capture_output=True).returncode != 0,
    reason="needs the git repository")


def test_against_head_measures_both_trees_in_subprocesses_and_joins_the_rows(tmp_path, monkeypatch):
    monkeypatch.setattr(throughput, "SCENARIO_BATCHES", {"lossy_fusion": (1,)})
    rows = bench.run_against(str(tmp_path), "HEAD", scenarios=["lossy_fusion"], min_seconds=0.01, extras=False,
                             rounds=1)
    whats = {(r["what"], r["batch"]) for r in rows}
    assert ("vector_env", 1) in whats and ("estimator step", 1) in whats
    for row in rows:
        assert row["current_env_steps_per_s"] > 0 and row["reference_env_steps_per_s"] > 0
        assert row["ratio"] == pytest.approx(row["current_env_steps_per_s"] / row["reference_env_steps_per_s"])
    saved = json.loads((tmp_path / "bench" / "against.json").read_text())
    assert saved["reference"] == "HEAD" and len(saved["reference_commit"]) == 40 and saved["errors"] == {}
    assert saved["rows"] == rows


def test_the_reference_tree_is_what_its_subprocess_imports(tmp_path):
    commit = bench.export_commit("HEAD", str(tmp_path))
    assert (tmp_path / "train" / "__init__.py").exists() and len(commit) == 40
    failed = bench.bench_tree(str(tmp_path), "no_such_scenario", 0.01, (1,), extras=False)
    assert "error" in failed and "no_such_scenario" in failed["error"]


def test_rounds_keep_each_rows_best_rate():
    first = [{"scenario": "s", "what": "w", "batch": 1, "env_steps_per_s": 3.0},
             {"scenario": "s", "what": "w", "batch": 2, "env_steps_per_s": 9.0}]
    second = [{"scenario": "s", "what": "w", "batch": 1, "env_steps_per_s": 5.0},
              {"scenario": "s", "what": "w", "batch": 2, "env_steps_per_s": 1.0}]
    assert {r["batch"]: r["env_steps_per_s"] for r in against._best([first, second])} == {1: 5.0, 2: 9.0}


def test_compare_rows_joins_on_scenario_what_and_batch():
    current = [{"scenario": "s", "what": "w", "batch": 1, "env_steps_per_s": 30.0},
               {"scenario": "s", "what": "new", "batch": 1, "env_steps_per_s": 5.0}]
    reference = [{"scenario": "s", "what": "w", "batch": 1, "env_steps_per_s": 10.0},
                 {"scenario": "s", "what": "gone", "batch": 4, "env_steps_per_s": 2.0}]
    rows = {(r["what"], r["batch"]): r for r in bench.compare_rows(current, reference)}
    assert rows[("w", 1)]["ratio"] == pytest.approx(3.0)
    assert rows[("new", 1)]["ratio"] is None and rows[("new", 1)]["reference_env_steps_per_s"] is None
    assert rows[("gone", 4)]["ratio"] is None and rows[("gone", 4)]["current_env_steps_per_s"] is None


def test_the_bandwidth_estimator_row_stays_finite_over_many_episodes():
    """It restarts every recorded cycle (at most an episode), as the env resets; a row that carried its state over
    many episodes' steps on the one fixed reading (the synthetic row before the replay) overflowed near step 1,750."""
    import warnings

    from train.bench import ESTIMATOR_STEPS

    step = ESTIMATOR_STEPS["bandwidth_fusion"](4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an overflow is a RuntimeWarning
        for _ in range(2_500):
            step()


def test_the_one_episode_row_plays_the_same_episode_in_every_copy():
    """The row's premise: with every copy seeded 0 the copies' observations are equal; the default seeds differ."""
    import numpy as np

    import coloc_env

    paper = bench.ActionSource("gps_denied_nbp").paper
    observations = {}
    for label, seeds in (("one episode", [0, 0, 0]), ("default", None)):
        venv = coloc_env.vector_env("gps_denied_nbp", num_envs=3, seed=0)
        if seeds is not None:
            venv._copy_seeds = seeds
        venv.reset()
        for _ in range(3):
            obs, *_ = venv.step(np.tile(paper, (3, 1)))
        observations[label] = obs.reshape(3, venv.num_agents, -1)
    same = observations["one episode"]
    assert np.array_equal(same[0], same[1]) and np.array_equal(same[0], same[2])
    assert not np.array_equal(observations["default"][0], observations["default"][1])


def test_a_reference_tree_without_the_one_episode_row_gets_it_from_the_driver(tmp_path, monkeypatch):
    """``--against`` an older commit: the driver measures the row with this tree's one_episode_rate in that tree."""
    bench.export_commit("HEAD", str(tmp_path))
    older = tmp_path / "train" / "bench"  # this bench, less its row
    shutil.rmtree(older, ignore_errors=True)
    shutil.copytree(os.path.dirname(bench.__file__), older, ignore=shutil.ignore_patterns("__pycache__"))
    source = (older / "throughput.py").read_text()
    row_line = source[source.index("ONE_EPISODE_ROWS = "):]
    source = source.replace(row_line[:row_line.index("\n") + 1], "")
    source = source.replace("if name in ONE_EPISODE_ROWS:", "if False:")
    assert "ONE_EPISODE_ROWS =" not in source and source.count("if False:") == 1
    (older / "throughput.py").write_text(source)
    package = (older / "__init__.py").read_text()
    package = package.replace("    ONE_EPISODE_ROWS,\n", "").replace('"ONE_EPISODE_ROWS", ', "")
    (older / "__init__.py").write_text(package)
    monkeypatch.setattr(throughput, "ONE_EPISODE_ROWS", ("lossy_fusion",))
    result = bench.bench_tree(str(tmp_path), "lossy_fusion", 0.01, (1, 2), extras=False)
    rows = {(r["what"], r["batch"]): r for r in result["rows"]}
    agents = bench.ActionSource("lossy_fusion").num_agents
    for batch in (1, 2):
        row = rows[(bench.ONE_EPISODE, batch)]
        assert row["env_steps_per_s"] > 0
        assert row["agent_steps_per_s"] == pytest.approx(row["env_steps_per_s"] * agents)
    monkeypatch.setattr(throughput, "SCENARIO_BATCHES", {})
    current = {(r["what"], r["batch"]) for r in bench.bench_scenario("lossy_fusion", 0.01, (1,))}
    assert (bench.ONE_EPISODE, 1) in current and ("vector_env", 1) in current


def test_bench_rounds_reach_run_against_and_bad_values_are_refused(tmp_path, monkeypatch, capsys):
    from train.cli import main

    seen = {}
    monkeypatch.setattr(bench, "run_against", lambda out, ref, **kwargs: seen.update(ref=ref, **kwargs) or [])
    assert main(["bench", "--quick", "--scenarios", "lossy_fusion", "--against", "HEAD", "--rounds", "3",
                 "--out", str(tmp_path)]) == 0
    assert seen["ref"] == "HEAD" and seen["rounds"] == 3
    assert main(["bench", "--scenarios", "lossy_fusion", "--rounds", "3", "--out", str(tmp_path)]) == 2
    assert "--rounds 3 needs --against REF" in capsys.readouterr().err
    for bad in ("21", "0", "-1", "1e308", "two", "True", ""):
        with pytest.raises(SystemExit):
            main(["bench", "--against", "HEAD", f"--rounds={bad}", "--out", str(tmp_path)])
        assert f"--rounds: must be an integer in [1, 20], got {bad!r}" in capsys.readouterr().err
