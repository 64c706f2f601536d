"""``coloc evaluate`` plays a named policy on the batched core (``run_policy_batched``) and gets what the
env loop (``run_episodes``) gets on the same seeds: episode for episode, every preset, every policy that
batches (``Policy.batching``). The two paths step the same arithmetic per copy except where a backend
sums over the batch in another order (dNBP), hence 1e-9 relative rather than bit for bit."""

import numpy as np
import pytest

import agents
import train.evaluate as ev
from tests.conftest import MRCLAM_DATASET6, needs_mrclam

SMALL = {
    "bandwidth_fusion": {"horizon": 12},
    "lossy_fusion": {"horizon": 12},
    "relay_ukf": {"horizon": 40},
    "nlos_horizon": {"horizon": 60},
    "gps_denied_nbp": {"horizon": 5, "num_particles": 30},
    "mrclam_relay": {"data": MRCLAM_DATASET6, "window_steps": 20},
    "contention_localization": {"horizon": 8},
}
# policies that read the env's truth, which no copy of the batched core hands them: the env loop only
ENV_LOOP_ONLY = {("contention_localization", "bound_polled_error")}


def _cases():
    for scenario in SMALL:
        names = agents.available_policies(scenario) + agents.bound_policies(scenario)
        marks = [needs_mrclam] if scenario == "mrclam_relay" else []
        for name in [*names, *ev.extra_rows(scenario)]:
            yield pytest.param(scenario, name, marks=marks)


@pytest.mark.parametrize(("scenario", "name"), list(_cases()))
def test_batched_policy_equals_the_env_loop(scenario, name):
    config = SMALL[scenario]
    batched = ev.run_policy_batched(scenario, name, 3, 77, **config)
    if (scenario, name) in ENV_LOOP_ONLY:
        assert batched is None
        return
    assert batched is not None, f"{scenario} {name} does not batch"
    looped = ev.run_episodes(scenario, name, 3, 77, **config)
    assert len(set(looped["per_episode_cost"])) == 3  # three distinct episodes
    np.testing.assert_allclose(batched["per_episode_cost"], looped["per_episode_cost"], rtol=1e-9, atol=0)
    np.testing.assert_allclose(batched["per_episode_communication"], looped["per_episode_communication"],
                               rtol=1e-12, atol=0)
    assert batched["initial_cost"] == looped["initial_cost"]


def test_batches_in_chunks_give_the_same_episodes(monkeypatch):
    whole = ev.run_policy_batched("relay_ukf", "paper", 5, 77, **SMALL["relay_ukf"])
    monkeypatch.setattr(ev, "EVALUATION_BATCH", 2)
    chunked = ev.run_policy_batched("relay_ukf", "paper", 5, 77, **SMALL["relay_ukf"])
    assert chunked["per_episode_cost"] == whole["per_episode_cost"]


@pytest.mark.parametrize("scenario", ["relay_ukf", "bandwidth_fusion"])
def test_a_stochastic_policys_episode_depends_on_its_seed_alone(scenario):
    """The policy's generator restarts per episode (``agents.base.episode_generator``): episode seed 78
    plays the same whether it comes first or second."""
    config = SMALL[scenario]
    from_77 = ev.run_episodes(scenario, "random", 3, 77, **config)["per_episode_cost"]
    from_78 = ev.run_episodes(scenario, "random", 2, 78, **config)["per_episode_cost"]
    assert from_77[1:] == from_78
    assert from_77[0] != from_77[1]


def test_policy_streams_differ_from_the_envs():
    from agents.base import episode_generator

    assert episode_generator(5).integers(2**62) != np.random.default_rng(5).integers(2**62)
    assert episode_generator(5).integers(2**62) == episode_generator(5).integers(2**62)


def test_evaluate_plays_named_policies_batched(monkeypatch):
    def loop_refused(*args, **kwargs):
        raise AssertionError("the env loop ran")

    monkeypatch.setattr(ev, "run_episodes", loop_refused)
    result = ev.evaluate_policy("lossy_fusion", "paper", 2, 77)
    assert result["episodes"] == 2 and result["policy"] == "paper"


@pytest.mark.parametrize("scenario", ["circles/broadcast/ukf_ccl", "target_cv/bernoulli_delay/kalman"])
def test_a_compositions_greedy_searches_every_copy_at_once_as_it_would_alone(scenario):
    """greedy's batched search (one trial step of the batched core per agent and candidate) chooses per copy what
    its search on that copy alone chooses: the same episodes, and on this seed some choice differs from always's."""
    config = {"horizon": 15, "communication_cost": 0.05}
    batched = ev.run_policy_batched(scenario, "greedy", 3, 77, **config)
    looped = ev.run_episodes(scenario, "greedy", 3, 77, **config)
    np.testing.assert_allclose(batched["per_episode_cost"], looped["per_episode_cost"], rtol=1e-9, atol=0)
    assert batched["per_episode_communication"] == looped["per_episode_communication"]
    always = ev.run_policy_batched(scenario, "always", 3, 77, **config)
    assert batched["per_episode_communication"] != always["per_episode_communication"]
