"""``COST_FEATURE = "scaled"``: a cost-conditioned model reads the observed cost as its position in the training
range (``agents.cost_feature``), inside the saved model, so every path that plays it reads the same; on
``relay_ukf``'s short episodes with a settings module of the test's own."""

import math
import os
import sys

import numpy as np
import pytest
import torch

import agents
import coloc_env
from agents.cost_feature import CostScaledExtractor, scaled_cost
from tests.helpers import settings_module
from train import training
from train.evaluate import run_episodes, run_model_batched
from train.io import read_json

SHORT = {"horizon": 12}
COSTS = (0.01, 3.0)


@pytest.mark.parametrize(("cost_range", "costs", "expected"), [
    ((0.01, 3.0), [0.01, math.sqrt(0.03), 3.0, 0.0], [-1.0, 0.0, 1.0, 2 * math.log(0.001 / math.sqrt(0.03))
                                                       / math.log(300.0)]),
    ((0.0, 50.0), [0.0, 25.0, 50.0], [-1.0, 0.0, 1.0]),
    ((2.0, 2.0), [2.0, 3.0], [0.0, 0.5]),
    ((0.0, 0.0), [0.0, 1.0], [0.0, 1.0]),
])
def test_the_cost_reads_as_its_place_in_the_range(cost_range, costs, expected):
    got = scaled_cost(torch.tensor(costs, dtype=torch.float64), cost_range)
    np.testing.assert_allclose(got.numpy(), expected, rtol=0, atol=1e-12)


def _settings_module(**settings):
    return settings_module("relay_ukf", ENV_CONFIG={"reward": "trace", **SHORT}, NUM_COPIES=2,
                           LEADERBOARD_TARGET=("beat it", 0.02, 0.30), **settings)


def _train(folder, cost_range=COSTS, **settings) -> str:
    module = _settings_module(**settings)
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(sys.modules, module.__name__, module)
        return training.train("relay_ukf", timesteps=64, seed=0, out=str(folder), progress_bar=False,
                              curve_points=0, cost_range=cost_range)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A relay_ukf model over the cost range 0.01 to 3 that reads the cost scaled."""
    return _train(tmp_path_factory.mktemp("scaled"), COST_FEATURE="scaled")


def test_the_saved_model_reads_the_scaled_cost_and_records_it(trained):
    assert read_json(os.path.join(os.path.dirname(trained), "model.json"))["cost_feature"] == "scaled"
    for cost in (0.01, 0.2, 3.0):
        env = coloc_env.parallel_env("relay_ukf", communication_cost=cost, **SHORT)
        column = env.unwrapped.scenario.feature_index("communication_cost")
        observations, _ = env.reset(seed=10**6)
        model = agents.make_policy(trained, env).model
        assert isinstance(model.policy.features_extractor, CostScaledExtractor)
        batch = np.stack([observations[a] for a in env.possible_agents])
        features = model.policy.extract_features(torch.as_tensor(batch), model.policy.features_extractor)
        np.testing.assert_allclose(features[:, column].detach().numpy(),
                                   2 * math.log(cost / math.sqrt(0.03)) / math.log(300.0), rtol=1e-6)
        others = np.delete(np.arange(batch.shape[1]), column)
        np.testing.assert_array_equal(features[:, others].detach().numpy(), batch[:, others])


def test_the_batched_evaluation_equals_the_env_loop(trained):
    looped = run_episodes("relay_ukf", trained, 3, 10**6, communication_cost=0.2, **SHORT)
    model = agents.make_policy(trained, coloc_env.parallel_env("relay_ukf", **SHORT)).model
    batched = run_model_batched(model, "relay_ukf", 3, 10**6, communication_cost=0.2, **SHORT)
    assert batched["per_episode_cost"] == pytest.approx(looped["per_episode_cost"], rel=1e-12)


def test_a_fixed_cost_reads_the_raw_entry_and_the_default_is_raw(tmp_path):
    fixed = _train(tmp_path / "fixed", cost_range=None, COST_FEATURE="scaled")
    assert read_json(os.path.join(os.path.dirname(fixed), "model.json"))["cost_feature"] == "raw"
    default = _train(tmp_path / "default")
    assert read_json(os.path.join(os.path.dirname(default), "model.json"))["cost_feature"] == "raw"
    env = coloc_env.parallel_env("relay_ukf", **SHORT)
    assert not isinstance(agents.make_policy(default, env).model.policy.features_extractor, CostScaledExtractor)


def test_an_unknown_cost_feature_and_the_centralized_critic_are_refused(tmp_path):
    with pytest.raises(ValueError, match=r"COST_FEATURE of train/hyperparams/relay_ukf\.py must be one of "
                                         r"\['raw', 'scaled'\], got 'log'"):
        _train(tmp_path, COST_FEATURE="log")
    with pytest.raises(ValueError, match=r"COST_FEATURE of train/hyperparams/relay_ukf\.py must be one of"):
        _train(tmp_path, cost_range=None, COST_FEATURE="log")
    with pytest.raises(ValueError, match=r"COST_FEATURE 'scaled' of train/hyperparams/relay_ukf\.py: the "
                                         r"centralized critic reads the observation itself"):
        _train(tmp_path, COST_FEATURE="scaled", CRITIC="centralized")
    assert not os.path.exists(tmp_path / "relay_ukf")
