"""Action entries a trained model leaves to the paper's rule (a settings module's ``PAPER_ENTRIES``,
``coloc train --paper-entries``): relay_ukf's ``partner``, the paper's random ranging partner, on a short horizon
with a settings module of the test's own."""

import os
import sys

import numpy as np
import pytest

import agents
import coloc_env
from agents.relay_ukf import PaperPartner
from tests.helpers import settings_module
from train import training
from train.cli import main
from train.evaluate import run_episodes, run_model_batched
from train.io import read_json

SHORT = {"horizon": 30}


def _settings_module():
    return settings_module("relay_ukf", ENV_CONFIG={"reward": "trace", "communication_cost": 0.01, **SHORT},
                           NUM_COPIES=2, ALGORITHM="maskable_ppo", PAPER_ENTRIES="partner",
                           LEADERBOARD_TARGET=("beat it", 0.02, 0.30))


@pytest.fixture
def settings(monkeypatch):
    module = _settings_module()
    monkeypatch.setitem(sys.modules, module.__name__, module)
    return module


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A relay_ukf model that leaves the partner to the paper (64 steps on 30-step episodes)."""
    module = _settings_module()
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(sys.modules, module.__name__, module)
        return training.train("relay_ukf", timesteps=64, seed=0, out=str(tmp_path_factory.mktemp("trained")),
                              progress_bar=False, curve_points=0, cost_range=None)


def _partners(policy_name: str, seed: int) -> np.ndarray:
    """Whom each platform ranged with at each step of the episode ``seed`` (-1: none), the env loop."""
    env = coloc_env.parallel_env("relay_ukf", **SHORT)
    policy = agents.make_policy(policy_name, env, seed=0)
    observations, _ = env.reset(seed=seed)
    policy.start_episode(seed)
    rows = []
    while env.agents:
        observations, _, _, _, infos = env.step(policy.act(observations))
        rows.append([infos[a]["partner"] for a in env.possible_agents])
    return np.array(rows)


def test_a_model_leaving_the_partner_ranges_with_the_papers_partners(trained):
    """On the same episode the model, ``paper`` and ``no_relay`` range with the same partners (the same draws from
    the episode's generator), while the model's relays are its own."""
    assert read_json(os.path.join(os.path.dirname(trained), "model.json"))["paper_entries"] == "partner"
    for seed in (10**6, 10**6 + 7):
        model = _partners(trained, seed)
        assert (model >= 0).sum() >= 8  # platforms did measure
        np.testing.assert_array_equal(model, _partners("paper", seed))
        np.testing.assert_array_equal(model, _partners("no_relay", seed))


def test_the_batched_evaluation_equals_the_env_loop(trained):
    looped = run_episodes("relay_ukf", trained, 3, 10**6, **SHORT)
    env = coloc_env.parallel_env("relay_ukf", **SHORT)
    policy = agents.make_policy(trained, env)
    assert policy.paper_entries is not None
    batched = run_model_batched(policy.model, "relay_ukf", 3, 10**6, paper_entries=policy.paper_entries, **SHORT)
    assert batched["per_episode_cost"] == pytest.approx(looped["per_episode_cost"], rel=1e-12)
    assert batched["per_episode_communication"] == looped["per_episode_communication"]


def test_the_training_env_gets_the_drawn_partner_and_masks_the_entry_to_one_choice():
    N, copies = 4, 3
    inner = coloc_env.vector_env("relay_ukf", num_envs=copies, seed=5, **SHORT)
    venv = training.paper_entries_env(inner, PaperPartner(), N, seed=0)
    masks = np.stack(venv.env_method("action_masks"))
    unmasked = inner.action_masks()
    np.testing.assert_array_equal(masks[:, N:], unmasked[:, N:])  # the relay entry's choices are the env's
    np.testing.assert_array_equal(masks[:, :N], np.tile(np.eye(N, dtype=bool), (copies, 1)))
    assert [m.shape for m in venv.env_method("action_masks", indices=[1, 4])] == [(2 * N + 1,)] * 2
    sent = []
    step_async = inner.step_async
    inner.step_async = lambda actions: (sent.append(np.array(actions)), step_async(actions))[1]
    observations = venv.reset()
    measured = 0
    for _ in range(20):
        flags = observations.reshape(copies, N, -1)[:, :, N]
        # every agent asks for the last platform and relays to platform 2
        next_observations = venv.step(np.tile([N - 1, 2], (copies * N, 1)))[0]
        actions = sent[-1].reshape(copies, N, 2)
        np.testing.assert_array_equal(actions[..., 1], 2)
        for b in range(copies):
            m = np.flatnonzero(flags[b] > 0.5)
            others = np.setdiff1d(np.arange(N), m)
            np.testing.assert_array_equal(actions[b, others, 0], others)  # nobody but m ranges
            if len(m):
                measured += 1
                assert actions[b, m[0], 0] != m[0] and 0 <= actions[b, m[0], 0] < N
        observations = next_observations
    assert measured >= 10
    drawn = [a[:, 0] for a in sent]
    assert len({tuple(d) for d in drawn}) > 1  # the partners are drawn, not the model's constant N - 1


def test_none_turns_the_settings_entries_off_and_an_unknown_name_is_refused(settings, tmp_path, capsys):
    assert main(["train", "relay_ukf", "--timesteps", "16", "--curve-points", "0", "--cost-range", "none",
                 "--paper-entries", "none", "--out", str(tmp_path)]) == 0
    assert read_json(str(tmp_path / "relay_ukf/seed0/model.json"))["paper_entries"] is None
    capsys.readouterr()
    assert main(["train", "relay_ukf", "--seed", "1", "--paper-entries", "relay", "--out", str(tmp_path)]) != 0
    assert "coloc train: error: paper entries 'relay': relay_ukf has ['partner']" in capsys.readouterr().err
    assert not os.path.exists(tmp_path / "relay_ukf/seed1")
    with pytest.raises(ValueError, match=r"paper entries 'partner': lossy_fusion has none"):
        agents.paper_entries("lossy_fusion", "partner")
    with pytest.raises(ValueError, match=r"paper entries 'partner': drift/broadcast/kalman has none"):
        agents.paper_entries("drift/broadcast/kalman", "partner")


def test_a_seeded_model_draws_the_same_partners_without_an_evaluation(trained):
    """Played by hand (no ``start_episode``), the partners come from ``make_policy``'s seed, as ``paper``'s do."""
    def partners(name, seed):
        env = coloc_env.parallel_env("relay_ukf", **SHORT)
        policy = agents.make_policy(name, env, seed=seed)
        observations, _ = env.reset(seed=11)
        rows = []
        while env.agents:
            observations, _, _, _, infos = env.step(policy.act(observations))
            rows.append([infos[a]["partner"] for a in env.possible_agents])
        return np.array(rows)

    np.testing.assert_array_equal(partners(trained, 3), partners(trained, 3))
    np.testing.assert_array_equal(partners(trained, 3), partners("paper", 3))
    assert not np.array_equal(partners(trained, 3), partners(trained, 4))
