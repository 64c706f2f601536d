"""Cost-conditioned training (``coloc train --cost-range``, a settings module's ``COST_RANGE``) and evaluation at
fixed costs (``coloc evaluate --costs``, ``coloc frontier --models --costs``), on a small composition with a
settings module of the test's own."""

import json
import os
import shutil
import sys

import numpy as np
import pytest

import coloc_env
from tests.helpers import settings_module
from train import frontier, training
from train.cli import main
from train.evaluate import evaluate_policy, model_row, run_episodes
from train.io import read_json

SMALL = "drift/broadcast/kalman"  # 4 agents, 50 steps


def _settings_module():
    return settings_module(SMALL, ENV_CONFIG={"communication_cost": 0.3}, NUM_COPIES=2, CURVE_EPISODES=2)


@pytest.fixture
def settings(monkeypatch):
    """A settings module for SMALL (train/hyperparams has none): tiny rollouts, a fixed cost of 0.3."""
    module = _settings_module()
    monkeypatch.setitem(sys.modules, module.__name__, module)
    return module


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A cost-conditioned model of SMALL over [0.1, 10] and one trained at the fixed cost 0.3 (32 steps each), each
    alone in a folder (model.zip and model.json)."""
    out = tmp_path_factory.mktemp("trained")
    module = _settings_module()
    paths = []
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(sys.modules, module.__name__, module)
        for name, cost_range in (("ranged", (0.1, 10.0)), ("fixed", None)):
            path = training.train(SMALL, timesteps=32, seed=0, out=str(out / "runs" / name), progress_bar=False,
                                  curve_points=0, cost_range=cost_range)
            folder = out / name
            folder.mkdir()
            for file in ("model.zip", "model.json"):
                shutil.copy(os.path.join(os.path.dirname(path), file), folder / file)
            paths.append(str(folder / "model.zip"))
    return tuple(paths)


def test_the_cost_range_reaches_the_training_env_and_model_json(settings, tmp_path, monkeypatch):
    """``--cost-range`` is the training env's ``cost_range``: each copy's episode cost lies in it and is what its
    agents observe; model.json records it; the learning curve's points are the priced validation score."""
    built = []
    make = training.make_vec_env

    def spy(scenario, copies, env_config, seed, vec="native"):
        built.append((dict(env_config), make(scenario, copies, env_config, seed, vec)))
        return built[-1][1]

    monkeypatch.setattr(training, "make_vec_env", spy)
    assert main(["train", SMALL, "--timesteps", "64", "--curve-points", "1", "--cost-range", "0.1,10",
                 "--out", str(tmp_path)]) == 0
    (config, venv), = built
    assert config == {"communication_cost": 0.3, "cost_range": [0.1, 10.0]}
    core = venv.scenario
    assert core.costs.shape == (2,) and np.all((core.costs >= 0.1) & (core.costs <= 10.0))
    assert len(set(core.costs)) == 2  # drawn per copy, not the fixed 0.3
    observed = core.observation()[..., core.feature_index("communication_cost")]
    np.testing.assert_allclose(observed, np.repeat(core.costs[:, None], core.num_agents, axis=1), rtol=1e-6)
    folder = tmp_path / "drift/broadcast/kalman" / "seed0"
    meta = read_json(str(folder / "model.json"))
    assert meta["cost_range"] == [0.1, 10.0] and meta["env_config"]["cost_range"] == [0.1, 10.0]
    assert meta["checkpoint"]["validation_score"].startswith("mean over the costs [0.2154")
    curve = read_json(str(folder / "curve.json"))
    assert curve["validation_costs"] == pytest.approx([0.1 * 100 ** q for q in (1 / 6, 1 / 2, 5 / 6)])
    for point in curve["points"]:
        priced = [p["mean_cost"] + p["cost"] * p["messages_per_agent_step"] for p in point["at_costs"]]
        assert point["mean_cost"] == pytest.approx(np.mean(priced), rel=1e-12)
    best = min(curve["points"], key=lambda p: p["mean_cost"])
    assert meta["checkpoint"]["timesteps"] == best["timesteps"]


def test_a_settings_cost_range_is_the_default_and_none_turns_it_off(settings, tmp_path):
    settings.COST_RANGE = (0.0, 2.0)
    assert training.training_env_config(SMALL)[1] == (0.0, 2.0)
    assert training.training_env_config(SMALL, None) == ({"communication_cost": 0.3}, None)
    assert main(["train", SMALL, "--timesteps", "16", "--curve-points", "0", "--cost-range", "none",
                 "--out", str(tmp_path)]) == 0
    assert read_json(str(tmp_path / "drift/broadcast/kalman/seed0/model.json"))["cost_range"] is None
    settings.COST_RANGE = (3.0, 1.0)
    with pytest.raises(ValueError, match=r"COST_RANGE of train/hyperparams/drift__broadcast__kalman.py must be None "
                                         r"or a pair \(lo, hi\) with 0 <= lo <= hi <= 1e\+12"):
        training.training_env_config(SMALL)


@pytest.mark.parametrize("bad", ["5,1", "-1,2", "1", "a,b", "1,2,3", "nan,1", "0,1e13"])
def test_a_bad_cost_range_is_refused_before_anything_is_written(settings, tmp_path, capsys, bad):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", SMALL, f"--cost-range={bad}", "--out", str(tmp_path)])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "argument --cost-range: must be LO,HI with 0 <= LO <= HI <= 1e+12" in err
    assert os.listdir(tmp_path) == []
    with pytest.raises(ValueError, match=r"--cost-range \(lo, hi\)"):
        training.train(SMALL, timesteps=1, seed=0, out=str(tmp_path), progress_bar=False, cost_range=(2.0, 1.0))
    assert os.listdir(tmp_path) == []


def test_a_scenario_without_a_cost_range_keyword_is_refused_with_a_clear_message(settings, monkeypatch):
    """Where the scenario's config has no ``cost_range`` (a preset before its keyword), the refusal says so."""
    def refuse(name, **config):
        raise coloc_env.config.BadInput(f"unknown config key(s) {sorted(config)} for SomeConfig")

    monkeypatch.setattr(coloc_env, "parallel_env", refuse)
    with pytest.raises(ValueError, match=r"--cost-range: drift/broadcast/kalman takes no cost_range keyword"):
        training.training_env_config(SMALL, (0.1, 1.0))


def test_cost_balanced_reward_divides_each_step_by_its_own_episodes_cost():
    """Two identical seeded vec envs, one wrapped: each step's reward is the plain one over 1 + c / 0.5, c the
    cost drawn for the episode the step belongs to, including the last step of an episode (where the observation
    returned is already the next episode's, with a new cost)."""
    config = {"communication_cost": 0.3, "cost_range": [0.1, 10.0], "horizon": 3}
    plain = coloc_env.vector_env(SMALL, num_envs=2, seed=5, **config)
    index = plain.scenario.feature_index("communication_cost")
    wrapped = training.cost_balanced_reward(coloc_env.vector_env(SMALL, num_envs=2, seed=5, **config), index, 0.5)
    rng = np.random.default_rng(0)
    plain.reset()
    wrapped.reset()
    costs, episode_costs = [], []
    for _ in range(7):  # episodes of 3 steps: two boundaries
        costs.append(plain.scenario.costs.copy())
        actions = rng.integers(0, 2, (plain.num_envs, *plain.action_space.shape))
        _, reward, done, _ = plain.step(actions)
        _, scaled, done_w, _ = wrapped.step(actions)
        c = np.repeat(costs[-1], plain.num_agents)
        np.testing.assert_allclose(scaled, reward / (1 + c / 0.5), rtol=1e-6)
        np.testing.assert_array_equal(done, done_w)
        episode_costs.append(tuple(costs[-1]))
    assert len(set(episode_costs)) == 3  # three episodes, three draws per copy
    with pytest.raises(ValueError, match=r"COST_REWARD_SCALE must be a finite number > 0"):
        training.cost_balanced_reward(plain, index, 0.0)


def test_cost_reward_scale_reaches_training_and_model_json(settings, tmp_path):
    settings.COST_REWARD_SCALE = 2.0
    assert main(["train", SMALL, "--timesteps", "16", "--curve-points", "0", "--cost-range", "0.1,1",
                 "--out", str(tmp_path)]) == 0
    assert read_json(str(tmp_path / "drift/broadcast/kalman/seed0/model.json"))["cost_reward_scale"] == 2.0
    assert main(["train", SMALL, "--timesteps", "16", "--curve-points", "0", "--cost-range", "none",
                 "--out", str(tmp_path / "fixed")]) == 0  # a fixed cost: nothing to balance
    assert read_json(str(tmp_path / "fixed/drift/broadcast/kalman/seed0/model.json"))["cost_reward_scale"] is None
    settings.COST_REWARD_SCALE = -1
    with pytest.raises(ValueError, match=r"COST_REWARD_SCALE of train/hyperparams/drift__broadcast__kalman.py "
                                         r"must be a number > 0, got -1"):
        training.train(SMALL, timesteps=1, seed=0, out=str(tmp_path / "bad"), progress_bar=False,
                       cost_range=(0.1, 1.0))


def test_a_model_at_cost_c_plays_as_in_an_env_built_with_that_cost(trained, monkeypatch):
    """``--costs`` plays each cost in an env built with ``communication_cost=c`` (the observation's cost feature is
    c), each its own row, equal episode by episode to the env loop of an env built so."""
    ranged, fixed = trained
    cores = []
    make = coloc_env.make_core

    def spy(*args, **kwargs):
        cores.append(make(*args, **kwargs))
        return cores[-1]

    monkeypatch.setattr(coloc_env, "make_core", spy)
    rows = {c: evaluate_policy(SMALL, ranged, 3, seed_base=40, bounds=False, cost=c) for c in (0.1, 4.0)}
    assert [r["policy"] for r in rows.values()] == [f"{ranged} @ cost=0.1", f"{ranged} @ cost=4"]
    played = [core for core in cores if core.batch == 3]
    assert len(played) == 2
    for core, c in zip(played, rows, strict=True):
        assert np.all(core.observation()[..., core.feature_index("communication_cost")] == np.float32(c))
    monkeypatch.setattr(coloc_env, "make_core", make)
    for c, row in rows.items():
        looped = run_episodes(SMALL, ranged, 3, seed_base=40, communication_cost=c)
        assert row["per_episode_cost"] == pytest.approx(looped["per_episode_cost"], rel=1e-9)
        assert row["per_episode_communication"] == pytest.approx(looped["per_episode_communication"], rel=1e-9)
    # without a cost: a ranged model at its range's median (1), a fixed-cost model at its own cost
    assert model_row(ranged) == (ranged, pytest.approx(1.0, rel=1e-12))
    assert model_row(fixed) == (fixed, 0.3)
    assert model_row(fixed, 2.0) == (f"{fixed} @ cost=2 (trained at fixed cost 0.3)", 2.0)
    # the other weights of a run are described by the run's model.json
    last = os.path.join(os.path.dirname(ranged), "last.zip")
    shutil.copy(ranged, last)
    assert model_row(last, 2.0) == (f"{last} @ cost=2", 2.0)
    os.remove(last)
    alone = os.path.join(os.path.dirname(os.path.dirname(ranged)), "alone.zip")
    shutil.copy(ranged, alone)
    assert model_row(alone, 2.0) == (f"{alone} @ cost=2 (no training cost recorded)", 2.0)
    assert model_row(alone) == (alone, None)
    os.remove(alone)


def test_evaluate_costs_records_one_row_per_cost(trained, tmp_path, capsys):
    ranged, fixed = trained
    out = str(tmp_path / "results")
    assert main(["evaluate", SMALL, "--policy", ranged, "--costs", "0.2,5", "--episodes", "2", "--out", out]) == 0
    assert main(["evaluate", SMALL, "--policy", fixed, "--costs", "5", "--episodes", "2", "--out", out]) == 0
    table = read_json(os.path.join(out, "drift_broadcast_kalman", "leaderboard.json"))
    assert set(table) == {f"{ranged} @ cost=0.2", f"{ranged} @ cost=5", f"{fixed} @ cost=5 (trained at fixed cost 0.3)"}
    assert [table[f"{ranged} @ cost={c}"]["communication_cost"] for c in ("0.2", "5")] == [0.2, 5.0]
    printed = capsys.readouterr().out
    assert f"{ranged} @ cost=0.2: mean realized cost" in printed
    assert main(["evaluate", SMALL, "--policy", "always", "--costs", "1", "--out", out]) == 2
    assert "--costs applies to trained models" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["evaluate", SMALL, "--policy", ranged, "--costs", "1,1", "--out", out])
    assert "argument --costs: must not repeat a cost" in capsys.readouterr().err


def test_frontier_with_models_and_costs_places_a_point_per_cost(trained, tmp_path, monkeypatch):
    """Each model at each cost is a point of its own, judged against the baseline frontier (here always, silent,
    random: the family grids are left out to keep the test short)."""
    ranged, _ = trained
    monkeypatch.setattr(frontier, "knob_grids", lambda scenario, horizon, quick=False: {})
    models = os.path.dirname(ranged)
    assert main(["frontier", SMALL, "--models", models, "--costs", "0.1,10", "--episodes", "2", "--seed", "0",
                 "--out", str(tmp_path)]) == 0
    metrics = json.loads((tmp_path / "frontier" / "drift__broadcast__kalman" / "metrics.json").read_text())
    points = {p["policy"]: p for p in metrics["points"] if p["kind"] == "model"}
    assert set(points) == {f"{ranged} @ cost=0.1", f"{ranged} @ cost=10"}
    assert [points[f"{ranged} @ cost={c}"]["cost"] for c in ("0.1", "10")] == [0.1, 10.0]
    assert all(p["family"] == ranged for p in points.values())  # one line through the model's costs
    assert set(points) <= set(metrics["judged"])
    assert "--costs 0.1,10" in metrics["command"]
    assert main(["frontier", SMALL, "--costs", "1", "--out", str(tmp_path / "other")]) == 2
