"""``coloc study``: paired backend comparisons over a sweep, on small runs."""

import json
import math
import os
import re

import numpy as np
import pytest
from scipy import stats

import agents
import coloc_env
from train import study
from train.cli import main
from train.study import run_study

SMALL = ["--world", "circles", "--network", "relay", "--backends", "ukf_dcl,dead_reckoning",
         "--sweep", "network.loss_at_zero=0,0.5", "--episodes", "3", "--horizon", "12"]
NAME = "circles_relay_network.loss_at_zero"
CELL_KEYS = {"position_error", "messages_per_step", "floats_per_step", "nees", "per_episode_error", "rmse",
             "pcrb_centralized", "pcrb_local", "pcrb_delivered", "efficiency", "nees_band", "nees_in_band"}


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """The small study run through the command line (seed 7), and its folder."""
    out = tmp_path_factory.mktemp("small")
    assert main(["study", *SMALL, "--seed", "7", "--out", str(out)]) == 0
    return out / "study" / NAME


def env_loop_errors(backend: str, loss: float, seed: int, episodes: int, horizon: int) -> np.ndarray:
    """Per-episode mean position error from a plain PettingZoo loop, independent of train.study."""
    env = coloc_env.parallel_env(coloc_env.compose(world="circles", network={"name": "relay", "loss_at_zero": loss},
                                                   backend=backend, horizon=horizon))
    policy = agents.make_policy("always", env)
    means = []
    for e in range(episodes):
        observations, _ = env.reset(seed=seed + e)
        errors = []
        while env.agents:
            observations, _, _, _, infos = env.step(policy.act(observations))
            errors.append([infos[a]["position_error"] for a in env.possible_agents])
        means.append(np.mean(np.array(errors)))
    return np.array(means)


def test_small_study_writes_the_three_files_with_the_documented_shape(small):
    assert sorted(os.listdir(small)) == ["metrics.json", "position_error.png", "report.md"]
    metrics = json.loads((small / "metrics.json").read_text())
    assert metrics["world"] == "circles" and metrics["network"] == "relay" and metrics["reference"] == "ukf_dcl"
    assert list(metrics["backends"]) == ["ukf_dcl", "dead_reckoning"]
    for backend, cells in metrics["backends"].items():
        assert list(cells) == ["0", "0.5"]
        for cell in cells.values():
            assert set(cell) == CELL_KEYS
            assert set(cell["position_error"]) == {"mean", "ci95"}
            assert cell["position_error"]["mean"] == pytest.approx(np.mean(cell["per_episode_error"]), abs=1e-15)
            assert len(cell["per_episode_error"]) == 3 and cell["position_error"]["ci95"] > 0
            assert 0 < cell["nees"] < 100  # both backends have a covariance
        if backend == "dead_reckoning":  # sends nothing
            assert all(c["messages_per_step"] == c["floats_per_step"] == 0 for c in cells.values())
    ukf = metrics["backends"]["ukf_dcl"]
    assert ukf["0"]["messages_per_step"] > ukf["0.5"]["messages_per_step"] > 0  # relay loss cuts chains short
    assert ukf["0"]["floats_per_step"] > ukf["0"]["messages_per_step"]
    assert set(metrics["paired"]) == {"dead_reckoning"}
    for pair in metrics["paired"]["dead_reckoning"].values():
        assert set(pair) == {"mean", "ci95", "verdict"} and pair["verdict"] in ("lower", "higher", "no difference")
    config = metrics["config"]
    assert (config["seed"], config["episodes"], config["policy"], config["horizon"]) == (7, 3, "always", 12)
    assert config["sweep"] == {"part": "network", "field": "loss_at_zero", "values": [0, 0.5], "keys": ["0", "0.5"]}
    assert config["compositions"]["ukf_dcl"]["0.5"]["network"]["loss_at_zero"] == 0.5
    assert config["compositions"]["ukf_dcl"]["0"]["network"]["comm_range"] == "inf"  # JSON-safe
    report = (small / "report.md").read_text()
    for title in ("Position error (m)", "Messages per agent per step", "Floats per agent per step", "NEES",
                  "Paired difference in position error against ukf_dcl"):
        assert f"## {title}" in report
    assert "| backend | 0 | 0.5 |" in report and "| dead_reckoning | +" in report
    assert "coloc study --world circles --network relay --backends ukf_dcl,dead_reckoning" in report
    png = (small / "position_error.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000


def test_the_same_seed_reproduces_metrics_exactly_and_another_seed_does_not(small, tmp_path):
    assert main(["study", *SMALL, "--seed", "7", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "study" / NAME / "metrics.json").read_bytes() == (small / "metrics.json").read_bytes()
    spec = coloc_env.compose(world="circles", network={"name": "relay", "loss_at_zero": 0.0}, backend="ukf_dcl",
                             horizon=12)
    metrics = json.loads((small / "metrics.json").read_text())
    same, other = (study.run_cell(spec, "always", 3, seed)["error"] for seed in (7, 8))
    assert list(same) == metrics["backends"]["ukf_dcl"]["0"]["per_episode_error"]
    assert not np.allclose(same, other)


def test_paired_differences_equal_an_independent_env_loop(small):
    metrics = json.loads((small / "metrics.json").read_text())
    for key, loss in (("0", 0.0), ("0.5", 0.5)):
        ukf = env_loop_errors("ukf_dcl", loss, seed=7, episodes=3, horizon=12)
        dead = env_loop_errors("dead_reckoning", loss, seed=7, episodes=3, horizon=12)
        np.testing.assert_allclose(metrics["backends"]["ukf_dcl"][key]["per_episode_error"], ukf, rtol=0, atol=1e-12)
        diff = dead - ukf
        pair = metrics["paired"]["dead_reckoning"][key]
        assert pair["mean"] == pytest.approx(diff.mean(), abs=1e-12)
        half = stats.t.ppf(0.975, 2) * diff.std(ddof=1) / math.sqrt(3)
        assert pair["ci95"] == pytest.approx(half, abs=1e-12)
    # the same seeds give the same truth: dead reckoning sends nothing, so the loss cannot change its errors
    dead = metrics["backends"]["dead_reckoning"]
    assert dead["0"]["per_episode_error"] == dead["0.5"]["per_episode_error"]


def _incompatible_backend(world: str, network: str):
    rows = [r for r in coloc_env.compatibility() if r["world"] == world and r["network"] == network and not r["ok"]]
    if not rows:
        pytest.skip(f"every backend is compatible with {world}/{network} now")
    return rows[0]["backend"], rows[0]["reason"]


BAD = [
    (dict(sweep="network.no_such=1,2"), "no_such"),
    (dict(sweep="netwrk.loss_at_zero=0"), "PART must be one of"),
    (dict(sweep="network.loss_at_zero"), "PART.FIELD=v1,v2"),
    (dict(sweep="network.loss_at_zero=0,1.5"), r"network.loss_at_zero must be in \[0(\.0)?, 1(\.0)?\], got 1.5"),
    (dict(sweep="network.loss_at_zero=0,,1"), "empty value"),
    (dict(sweep="network.loss_at_zero=0.5,0.50"), "twice"),
    (dict(sweep="network.name=ideal"), "cannot change network.name"),
    (dict(backends="ukf_dcl,no_such"), "unknown backend 'no_such'"),
    (dict(backends="ukf_dcl,ukf_dcl"), "more than once"),
    (dict(world="no_world"), "unknown world 'no_world'"),
    (dict(episodes=1), r"episodes must be an integer in \[2, "),
    (dict(episodes=True), "episodes must be an integer"),
    (dict(episodes=1e308), "episodes must be an integer"),
    (dict(seed=-1), "seed must be an integer"),
    (dict(seed=None), "seed must be an integer"),
    (dict(horizon=0), "horizon must be"),
    (dict(policy="greedy"), "policy must be one of"),
    (dict(policy="paper", batched=True), "batched runs support"),
    (dict(executor="dask"), "executor must be"),
    (dict(name="../escape"), "name must be"),
]


@pytest.mark.parametrize(("change", "message"), BAD)
def test_bad_input_is_a_value_error_naming_it_and_writes_nothing(tmp_path, change, message):
    args = dict(world="circles", network="relay", backends="ukf_dcl,dead_reckoning",
                sweep="network.loss_at_zero=0,0.5", episodes=2, horizon=5, out=str(tmp_path))
    args.update(change)
    with pytest.raises(ValueError, match=message):
        run_study(**args)
    assert list(tmp_path.iterdir()) == []


def test_an_incompatible_backend_is_refused_with_its_reason(tmp_path, capsys):
    backend, reason = _incompatible_backend("circles", "relay")
    with pytest.raises(ValueError, match=re.escape(reason)):
        run_study("circles", "relay", ["ukf_dcl", backend], episodes=2, horizon=5, out=str(tmp_path))
    assert main(["study", "--world", "circles", "--network", "relay", "--backends", f"ukf_dcl,{backend}",
                 "--episodes", "2", "--out", str(tmp_path)]) == 2
    assert reason in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_an_unwritable_output_is_refused_before_any_episode(tmp_path, monkeypatch):
    def no_computing(*args, **kwargs):
        raise AssertionError("an episode ran before the output folder was checked")

    monkeypatch.setattr(study, "run_cell", no_computing)
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(ValueError, match="not writable"):
        run_study("circles", "relay", "dead_reckoning", episodes=2, horizon=5, out=str(blocker))


def test_ukf_dcl_over_a_lossless_relay_beats_dead_reckoning(tmp_path):
    metrics, _ = run_study("circles", "relay", "dead_reckoning,ukf_dcl", sweep="network.loss_at_zero=0",
                           episodes=8, horizon=60, seed=3, batched=True, out=str(tmp_path))
    pair = metrics["paired"]["ukf_dcl"]["0"]
    assert pair["verdict"] == "lower" and pair["mean"] + pair["ci95"] < 0


def test_batched_cells_equal_the_per_episode_env_run(tmp_path):
    """Random actions (policy seeded S + e) and the batched core match the env run up to rounding."""
    common = dict(world="circles", network="relay", backends="ukf_dcl,dead_reckoning", policy="random",
                  sweep="network.loss_at_zero=0,0.5", episodes=3, horizon=6, seed=11)
    per_episode, _ = run_study(**common, out=str(tmp_path / "env"))
    batched, _ = run_study(**common, batched=True, out=str(tmp_path / "batched"))
    for backend, cells in per_episode["backends"].items():
        for key, cell in cells.items():
            other = batched["backends"][backend][key]
            np.testing.assert_allclose(other["per_episode_error"], cell["per_episode_error"], rtol=0, atol=1e-9)
            assert other["messages_per_step"] == cell["messages_per_step"]
            assert other["nees"] == pytest.approx(cell["nees"], rel=1e-9)
    # random transport really differs from always (the policy is in play)
    spec = coloc_env.compose(world="circles", network={"name": "relay", "loss_at_zero": 0}, backend="ukf_dcl",
                             horizon=6)
    always = study.run_cell(spec, "always", 3, 11, batched=True)
    assert always["messages"].mean() != per_episode["backends"]["ukf_dcl"]["0"]["messages_per_step"]


def test_without_a_sweep_each_backend_runs_once_at_its_defaults(tmp_path):
    metrics, folder = run_study("circles", "ideal", "dead_reckoning", episodes=2, horizon=4, out=str(tmp_path))
    assert folder == os.path.join(str(tmp_path), "study", "circles_ideal")
    assert list(metrics["backends"]["dead_reckoning"]) == ["default"] and metrics["paired"] == {}
    assert metrics["config"]["sweep"] is None
    assert os.path.getsize(os.path.join(folder, "position_error.png")) > 5000  # the bar chart
    _, named = run_study("circles", "ideal", "dead_reckoning", episodes=2, horizon=4, out=str(tmp_path),
                         name="mine")
    assert named == os.path.join(str(tmp_path), "study", "mine")


def test_sweep_values_parse_sensibly():
    assert [study.parse_value(t) for t in ("true", "False", "none", "3", "-2", "0.5", "1e3", "inf", "ring")] == [
        True, False, None, 3, -2, 0.5, 1000.0, math.inf, "ring"]
    assert isinstance(study.parse_value("3"), int) and isinstance(study.parse_value("3.0"), float)
    assert study.parse_sweep("world.num_agents=4,5") == ("world", "num_agents", ["4", "5"], [4, 5])
    assert study.parse_sweep(None) is None


def test_verdicts_and_nees():
    assert study.verdict(-1.0, 0.5) == "lower" and study.verdict(1.0, 0.5) == "higher"
    assert study.verdict(0.2, 0.5) == "no difference"
    assert study.verdict(1e-12, 1e-13) == "no difference"  # rounding between equal backends is not a result
    error = np.array([[1.0, 2.0], [0.5, -1.0]])
    cov = np.array([[[2.0, 0.0], [0.0, 4.0]], [[1.0, 0.5], [0.5, 1.0]]])
    expected = [e @ np.linalg.inv(p) @ e for e, p in zip(error, cov, strict=True)]
    np.testing.assert_allclose(study._nees(error, cov), expected, rtol=1e-12)
    no_cov = {"error": np.array([1.0, 2.0]), "messages": np.zeros(2), "floats": np.zeros(2),
              "nees": np.full(2, np.nan), "squared_error": np.array([1.0, 4.0]), "nees_steps": None}
    row = study.cell_metrics(no_cov)
    assert row["nees"] is None and row["nees_band"] is None and row["pcrb_centralized"] is None
    assert row["rmse"] == pytest.approx(np.sqrt(2.5), rel=1e-15)


def test_help_documents_every_option(capsys):
    with pytest.raises(SystemExit):
        main(["study", "--help"])
    text = capsys.readouterr().out
    for option in ("--world", "--network", "--backends", "--sweep", "--policy", "--episodes", "--seed", "--horizon",
                   "--batched", "--executor", "--address", "--out", "--name", "metrics.json", "report.md",
                   "position_error.png", "paired"):
        assert option in text


def test_cells_travel_to_an_executor_and_give_the_local_numbers(small, tmp_path, monkeypatch):
    """--executor ray hands run_cell and pickled cells to train.executor.map_tasks (here a stand-in that
    pickles them as Ray does, without Ray's start-up); the numbers equal the local run byte for byte."""
    import pickle

    import train.executor

    calls = []

    def pickling_executor(fn, items, executor="local", address=None, progress=None):
        calls.append((executor, address, len(items)))
        fn, items = pickle.loads(pickle.dumps((fn, list(items))))
        return [pickle.loads(pickle.dumps(fn(*item))) for item in items]

    monkeypatch.setattr(train.executor, "map_tasks", pickling_executor)
    assert main(["study", *SMALL, "--seed", "7", "--executor", "ray", "--address", "ray://nowhere:1",
                 "--out", str(tmp_path)]) == 0
    assert calls == [("ray", "ray://nowhere:1", 4)]  # one task per (backend, value) cell
    assert (tmp_path / "study" / NAME / "metrics.json").read_bytes() == (small / "metrics.json").read_bytes()


@pytest.mark.slow  # Ray's start-up and its workers' imports take ~20 s; run with -m slow
def test_ray_cells_equal_local(tmp_path):
    ray = pytest.importorskip("ray")
    common = dict(world="circles", network="relay", backends="ukf_dcl,dead_reckoning",
                  sweep="network.loss_at_zero=0,0.5", episodes=2, horizon=6, seed=5)
    local, folder_local = run_study(**common, out=str(tmp_path / "local"))
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        remote, folder_ray = run_study(**common, executor="ray", out=str(tmp_path / "ray"))
    finally:
        ray.shutdown()
    assert remote == local
    with open(os.path.join(folder_ray, "metrics.json"), "rb") as a, \
            open(os.path.join(folder_local, "metrics.json"), "rb") as b:
        assert a.read() == b.read()


def test_result_files_get_the_users_permissions(tmp_path):
    import os

    from train.io import write_text

    path = tmp_path / "report.md"
    write_text(str(path), "x")
    mask = os.umask(0)
    os.umask(mask)
    assert (path.stat().st_mode & 0o777) == (0o666 & ~mask)


def test_study_rows_carry_the_bounds_efficiency_and_the_nees_band(tmp_path):
    metrics, folder = run_study("drift", "bernoulli_delay", "kalman,centralized_lmmse,prediction_compensation",
                                episodes=12, seed=3, horizon=20, out=str(tmp_path))
    bounds = coloc_env.pcrb(coloc_env.compose("drift", "bernoulli_delay", "kalman", horizon=20), episodes=12, seed=3)
    for cells in metrics["backends"].values():
        cell = cells["default"]
        assert cell["pcrb_centralized"] == pytest.approx(np.sqrt(bounds["centralized"].mean()), rel=1e-12)
        assert cell["pcrb_local"] == pytest.approx(np.sqrt(bounds["local"].mean()), rel=1e-12)
        assert cell["efficiency"] == pytest.approx(cell["rmse"] / cell["pcrb_centralized"], rel=1e-12)
        assert cell["efficiency"] > 1.0  # no estimator beats the bound on these 12 episodes
        # prediction_compensation's messages are estimates: the information-set bound
        assert cell["pcrb_local"] >= cell["pcrb_delivered"] >= cell["pcrb_centralized"]
        low, high = cell["nees_band"]
        assert low < 2 < high
    # the kalman backend (naive by default) and centralized_lmmse have matched models: most per-step NEES in band
    assert metrics["backends"]["centralized_lmmse"]["default"]["nees_in_band"] >= 0.8
    report = (tmp_path / "study" / "drift_bernoulli_delay" / "report.md").read_text()
    assert "## RMSE (m) and efficiency" in report and "## Posterior Cramér-Rao bounds" in report
    assert "% in band" in report


def test_sweeps_over_the_shared_medium_and_the_bursty_links(tmp_path):
    """``--sweep`` reaches the new channels' fields: under ``always`` every agent but the centre (which only
    listens) sends in every slot, so twice the slots charge exactly twice the frames and change nothing else; a
    bad state that loses every frame delivers a subset of what a lossless one does (the same counter-based
    draws), so its delivered bound cannot be lower."""
    slots, _ = run_study("circles", "contention", "ukf_ccl", sweep="network.slots=1,2", episodes=2, horizon=4,
                         batched=True, out=str(tmp_path / "contention"))
    one, two = slots["backends"]["ukf_ccl"]["1"], slots["backends"]["ukf_ccl"]["2"]
    assert two["messages_per_step"] == pytest.approx(2 * one["messages_per_step"], rel=1e-12)
    assert two["per_episode_error"] == one["per_episode_error"]
    bursts, _ = run_study("circles", "gilbert_elliott", "ukf_ccl", sweep="network.loss_bad=0,1", episodes=2,
                          horizon=4, batched=True, out=str(tmp_path / "bursts"))
    lossless, lossy = bursts["backends"]["ukf_ccl"]["0"], bursts["backends"]["ukf_ccl"]["1"]
    assert lossy["pcrb_delivered"] >= lossless["pcrb_delivered"] - 1e-12
    assert lossy["messages_per_step"] <= lossless["messages_per_step"]
