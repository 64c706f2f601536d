"""Models that act by sampled actions (a settings module's ``ACTIONS = "sampled"``): the learning curve scores them
so, ``model.json`` records it, and evaluation and the env-loop policy play them so; on
``contention_localization`` with a settings module of the test's own (the learning curve and the evaluation play
the preset's own episodes, the env loop short ones)."""

import os
import sys

import numpy as np
import pytest

import agents
import coloc_env
from coloc_env.config import BadInput
from tests.helpers import settings_module
from train import training
from train.evaluate import VALIDATION_SEED_BASE, evaluate_policy, run_model_batched
from train.io import read_json

SHORT = {"horizon": 8}
NUM_AGENTS = 10
CURVE_EPISODES = 3
COSTS = (1.0, 300.0)


def _settings_module(**settings):
    return settings_module("contention_localization", ENV_CONFIG={}, NUM_COPIES=2, CURVE_EPISODES=CURVE_EPISODES,
                           LEADERBOARD_TARGET=("beat it", 0.02, 0.30), **settings)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A sampled-action model over a cost range (one rollout, a learning curve of one point)."""
    module = _settings_module(ACTIONS="sampled")
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(sys.modules, module.__name__, module)
        return training.train("contention_localization", timesteps=64, seed=0,
                               out=str(tmp_path_factory.mktemp("trained")), progress_bar=False, curve_points=1,
                               cost_range=COSTS)


def _validation_score(model, deterministic: bool) -> float:
    """The learning curve's score of ``model`` (``training.validate``) with the given kind of actions."""
    return training.validate(
        lambda **config: run_model_batched(model, "contention_localization", CURVE_EPISODES,
                                           VALIDATION_SEED_BASE, deterministic=deterministic, **config),
        "contention_localization", {}, COSTS, NUM_AGENTS)["mean_cost"]


def test_the_model_records_sampled_actions_and_its_curve_scored_them(trained):
    record = read_json(os.path.join(os.path.dirname(trained), "model.json"))
    assert record["actions"] == "sampled"
    model = agents.make_policy(trained, coloc_env.parallel_env("contention_localization")).model
    kept = record["checkpoint"]["validation_mean_cost"]
    assert _validation_score(model, deterministic=False) == pytest.approx(kept, rel=1e-12)
    assert _validation_score(model, deterministic=True) != pytest.approx(kept, rel=1e-6)


def test_evaluation_plays_a_model_as_its_model_json_records(trained):
    as_recorded = evaluate_policy("contention_localization", trained, 3, 10**6, bounds=False, cost=10.0)
    sampled = evaluate_policy("contention_localization", trained, 3, 10**6, bounds=False, cost=10.0,
                              stochastic=True)
    most_likely = evaluate_policy("contention_localization", trained, 3, 10**6, bounds=False, cost=10.0,
                                  stochastic=False)
    assert as_recorded["policy"].endswith(" (stochastic)") and not most_likely["policy"].endswith(" (stochastic)")
    assert as_recorded["per_episode_cost"] == pytest.approx(sampled["per_episode_cost"], rel=1e-12)
    assert as_recorded["per_episode_cost"] != pytest.approx(most_likely["per_episode_cost"], rel=1e-6)


def _actions(policy, seed: int) -> np.ndarray:
    env = policy.env
    observations, _ = env.reset(seed=seed)
    policy.start_episode(seed)
    rows = []
    while env.agents:
        actions = policy.act(observations)
        rows.append(np.concatenate([np.ravel(actions[a]) for a in env.possible_agents]))
        observations, *_ = env.step(actions)
    return np.array(rows)


def test_the_env_loop_policy_samples_and_an_episode_repeats(trained):
    env = coloc_env.parallel_env("contention_localization", communication_cost=10.0, **SHORT)
    policy = agents.make_policy(trained, env)
    assert policy.deterministic is False
    first, again = _actions(policy, 10**6 + 3), _actions(policy, 10**6 + 3)
    np.testing.assert_array_equal(first, again)
    most_likely = agents.make_policy(trained, env, deterministic=True)
    assert most_likely.deterministic is True
    draws = np.array([_actions(policy, 10**6 + e) for e in range(4)])
    choices = np.array([_actions(most_likely, 10**6 + e) for e in range(4)])
    assert (draws != choices).any()


@pytest.mark.parametrize("weights", ["best.zip", "last.zip"])
def test_the_runs_other_weights_act_as_its_model_json_records(trained, weights, tmp_path):
    """``best.zip`` and ``last.zip`` have no sidecar of their own: the run's ``model.json`` describes them, so the
    env-loop policy samples and the evaluation names the row so; the same zip copied out of the run has no record
    and acts by its most likely actions."""
    path = os.path.join(os.path.dirname(trained), weights)
    env = coloc_env.parallel_env("contention_localization", communication_cost=10.0, **SHORT)
    assert agents.make_policy(path, env).deterministic is False
    assert evaluate_policy("contention_localization", path, 2, 10**6, bounds=False,
                           cost=10.0)["policy"].endswith(" (stochastic)")
    alone = tmp_path / weights
    alone.write_bytes(open(path, "rb").read())
    assert agents.make_policy(str(alone), env).deterministic is True


def test_an_unknown_actions_setting_is_refused(tmp_path, monkeypatch):
    module = _settings_module(ACTIONS="greedy")
    monkeypatch.setitem(sys.modules, module.__name__, module)
    with pytest.raises(BadInput, match=r"ACTIONS of train/hyperparams/contention_localization\.py must be one of "
                                       r"\['deterministic', 'sampled'\], got 'greedy'"):
        training.train("contention_localization", timesteps=64, seed=0, out=str(tmp_path), progress_bar=False,
                       curve_points=0, cost_range=COSTS)
    assert not os.listdir(tmp_path)


def test_the_frontier_names_a_sampled_models_points_so(trained):
    from train import frontier

    points = [c["policy"] for c in frontier.cells("contention_localization", 30, [trained], costs=[10.0, 30.0])
              if c["kind"] == "model"]
    assert points == [f"{trained} @ cost=10 (stochastic)", f"{trained} @ cost=30 (stochastic)"]


def test_the_leaderboard_target_counts_the_sampled_row_of_a_model_trained_to_sample(trained, tmp_path):
    """A sampled-action model's ``... (stochastic)`` row is judged for the target; another model's sampled row (no
    model.json saying it samples) is shown only."""
    from tests.helpers import leaderboard_row as _row
    from train.leaderboard import STOCHASTIC, target_verdict

    paper = np.linspace(13.0, 14.0, 12)
    other = str(tmp_path / "seed7" / "model.zip")
    table = {"paper": _row("paper", paper, comm=0.9, scenario="contention_localization"),
             trained + STOCHASTIC: _row(trained + STOCHASTIC, paper + 3.0, comm=1.5,
                                        scenario="contention_localization"),
             other + STOCHASTIC: _row(other + STOCHASTIC, paper - 3.0, comm=1.5, scenario="contention_localization")}
    line = target_verdict("contention_localization", table)
    assert "seed0: worse" in line and "seed7" not in line and "**not met**" in line
    del table[trained + STOCHASTIC]
    assert target_verdict("contention_localization", table) is None
