"""mrclam_relay's ``measurement``: a trained model leaves each robot's measurement choice to ``paper``'s rule (the
lowest-index robot it recorded) and decides only the relays, so that it applies the measurements every fixed
schedule applies; with a settings module of the test's own on short windows of dataset 6."""

import os
import sys

import numpy as np
import pytest

import agents
import coloc_env
from agents.mrclam_relay import PaperMeasurement, paper_partners
from tests.conftest import MRCLAM_DATASET6, needs_mrclam
from tests.helpers import settings_module
from train import training
from train.evaluate import run_episodes, run_model_batched
from train.io import read_json

N = 5
SHORT = {"window_steps": 40, "data": MRCLAM_DATASET6}


def test_the_entry_is_the_papers_measurement_and_its_mask_one_choice():
    rng = np.random.default_rng(3)
    observations = rng.random((2, N, 3 * N + 7))
    observations[..., N:2 * N] = rng.random((2, N, N)) < 0.3
    observations[1, 2, N:2 * N] = 0.0  # robot 2 of copy 1 recorded nobody: it names itself
    actions = rng.integers(0, N + 1, size=(2, N, 1 + N))
    filled = PaperMeasurement().entries(None, observations, actions)
    np.testing.assert_array_equal(filled[..., 1:], actions[..., 1:])  # the relays are the model's
    np.testing.assert_array_equal(filled[..., 0], paper_partners(observations[..., N:2 * N] > 0.5))
    assert filled[1, 2, 0] == 2
    masks = rng.random((2 * N, N + N * (N + 1))) < 0.5
    restricted = PaperMeasurement().restrict(masks, N)
    np.testing.assert_array_equal(restricted[:, :N], np.tile(np.eye(N, dtype=bool), (2, 1)))
    np.testing.assert_array_equal(restricted[:, N:], masks[:, N:])


def _settings_module():
    return settings_module("mrclam_relay", ENV_CONFIG={"reward": "trace", "communication_cost": 2e-4, **SHORT},
                           NUM_COPIES=2, ALGORITHM="maskable_ppo", PAPER_ENTRIES="measurement",
                           LEADERBOARD_TARGET=("beat it", 0.02, 0.30))


def _train(folder, **options) -> str:
    if not os.path.isdir(MRCLAM_DATASET6):
        pytest.skip("MRCLAM dataset 6 not found")
    module = _settings_module()
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(sys.modules, module.__name__, module)
        return training.train("mrclam_relay", timesteps=64, seed=0, out=str(folder), progress_bar=False,
                              curve_points=0, cost_range=None, **options)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """An mrclam_relay model that leaves the measurement to the paper (64 steps on 40-step windows)."""
    return _train(tmp_path_factory.mktemp("trained"))


@pytest.fixture(scope="module")
def choosing(tmp_path_factory):
    """The same training with the measurement the model's own (``--paper-entries none``)."""
    return _train(tmp_path_factory.mktemp("choosing"), paper_entries=None)


def _measurements(policy_name: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(whose measurement each robot used at each step of the window ``seed`` (-1: none), the hops it delivered),
    the env loop."""
    env = coloc_env.parallel_env("mrclam_relay", **SHORT)
    policy = agents.make_policy(policy_name, env, seed=0)
    observations, _ = env.reset(seed=seed)
    policy.start_episode(seed)
    partners, hops = [], []
    while env.agents:
        observations, _, _, _, infos = env.step(policy.act(observations))
        partners.append([infos[a]["partner"] for a in env.possible_agents])
        hops.append([infos[a]["communication"] for a in env.possible_agents])
    return np.array(partners), np.array(hops)


@needs_mrclam
def test_a_model_leaving_the_measurement_applies_the_papers_measurements(trained, choosing):
    """The same windows: the model leaving the entry applies ``paper``'s (and ``no_relay``'s) measurements, the
    model that chooses them applies others at some step."""
    assert read_json(os.path.join(os.path.dirname(trained), "model.json"))["paper_entries"] == "measurement"
    chose, differ = [], []
    for seed in (10**6, 10**6 + 5):
        model, _ = _measurements(trained, seed)
        paper, _ = _measurements("paper", seed)
        chose.append((model >= 0).sum())
        np.testing.assert_array_equal(model, paper)
        np.testing.assert_array_equal(model, _measurements("no_relay", seed)[0])
        differ.append((_measurements(choosing, seed)[0] != paper).any())
    assert sum(chose) >= 10  # robots did record each other in these windows
    assert any(differ)


@needs_mrclam
def test_the_batched_evaluation_equals_the_env_loop(trained):
    looped = run_episodes("mrclam_relay", trained, 3, 10**6, **SHORT)
    env = coloc_env.parallel_env("mrclam_relay", **SHORT)
    policy = agents.make_policy(trained, env)
    assert isinstance(policy.paper_entries, PaperMeasurement)
    batched = run_model_batched(policy.model, "mrclam_relay", 3, 10**6, paper_entries=policy.paper_entries, **SHORT)
    assert batched["per_episode_cost"] == pytest.approx(looped["per_episode_cost"], rel=1e-12)
    assert batched["per_episode_communication"] == looped["per_episode_communication"]
