"""The information-set delivered bound (coloc_env.bounds.information_set) of backends whose messages carry estimates."""

import numpy as np
import pytest

import coloc_env
from coloc_env.bounds import pcrb, record_play
from coloc_env.bounds.information_set import SetRecursion, held, receiver_entries
from coloc_env.bounds.models import bound_problem


@pytest.mark.parametrize("name", ["target_cv/bernoulli_delay/kalman", "drift/random_delay/centralized_lmmse",
                                  "target_cv/relay/kalman"])
def test_where_messages_are_readings_the_sets_give_the_readings_bound(name):
    """Each message taken to carry only its sender's reading of its step: the sets' bound (the forward pass over
    the arrivals, no lag augmentation) equals the lag-augmented delivered bound of reading packets, to 1e-9."""
    spec = coloc_env.composition_named(name, horizon=25)
    for seed in (0, 1):
        core = coloc_env.make_core(spec, batch=1)
        record = record_play(core, np.random.default_rng(seed), "always", None)
        problem = bound_problem(core, record)
        arrival = held(problem.readings, record, core.num_agents, "readings")
        entries, capped = receiver_entries(problem.readings, arrival[0], record.steps, lag_cap=10)
        assert capped == 0
        c = problem.centralized
        sets = SetRecursion(c.P0, c.F, c.Q, entries, record.steps, c.positions[:1]).run()
        np.testing.assert_allclose(sets, problem.delivered[0].run(), rtol=1e-9, atol=0)
        assert np.any(sets[:, 0] > c.run()[:, 0] * (1 + 1e-6))  # some packet late or lost: not the centralized


@pytest.mark.parametrize("world", ["gps_denied", "circles"])
def test_ukf_dcl_over_ideal_delivers_the_centralized_bound(world):
    """Every chain reaches everyone in its step: every reading is in every set at once."""
    bound = pcrb(coloc_env.compose(world, "ideal", "ukf_dcl", horizon=8), episodes=2, seed=0)
    np.testing.assert_allclose(bound["delivered"], bound["centralized"], rtol=1e-9, atol=1e-12)
    assert bound["delivered_capped"] == 0.0


@pytest.mark.parametrize("spec", [
    coloc_env.compose("gps_denied", {"name": "relay", "loss_at_zero": 1.0}, "ukf_dcl", horizon=12),
    coloc_env.compose("circles", {"name": "relay", "loss_at_zero": 1.0}, "ukf_dcl", horizon=20),
], ids=["gps_denied", "circles"])
def test_ukf_dcl_whose_every_hop_is_lost_gets_the_local_bound(spec):
    """No chain passes a hop: a range never leaves its platform (condition (c)), every set is the agent's own."""
    bound = pcrb(spec, episodes=2, seed=0)
    np.testing.assert_allclose(bound["delivered"], bound["local"], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("backend", ["dnbp", "range_ls"])
def test_silent_broadcasts_give_the_local_bound(backend):
    spec = coloc_env.compose("gps_denied", "broadcast", backend, horizon=10)
    silent = pcrb(spec, episodes=2, seed=0, policy="silent")
    np.testing.assert_allclose(silent["delivered"], silent["local"], rtol=1e-9, atol=1e-12)
    always = pcrb(spec, episodes=2, seed=0)
    assert always["delivered"].mean() < silent["delivered"].mean()


def test_truncated_chains_lie_between_and_grow_with_the_loss():
    """circles/relay/ukf_dcl with chains of at most 2 hops: centralized <= delivered <= local at every step and
    agent, and the delivered bound grows with the hop loss (the same uniforms lose a superset of hops)."""
    means = []
    for loss in (0.0, 0.3, 0.6):
        spec = coloc_env.compose("circles", {"name": "relay", "loss_at_zero": loss, "max_hops": 2}, "ukf_dcl",
                                 horizon=40)
        bound = pcrb(spec, episodes=2, seed=0)
        assert np.all(bound["delivered"] >= bound["centralized"] * (1 - 1e-9) - 1e-12)
        assert np.all(bound["delivered"] <= bound["local"] * (1 + 1e-9) + 1e-12)
        means.append(bound["delivered"][1:].mean())
    assert means[0] > pcrb(coloc_env.compose("circles", "ideal", "ukf_dcl", horizon=40), episodes=2,
                           seed=0)["centralized"][1:].mean()
    assert means[0] < means[1] < means[2], means


def test_a_prediction_compensation_leader_credits_each_estimate_with_its_senders_history():
    """Over bernoulli_delay a lost packet's readings reach the leader with the sender's next packet: the sets'
    bound lies below the readings' delivered bound of the same deliveries (kalman's) and above centralized."""
    estimates = pcrb(coloc_env.compose("target_cv", "bernoulli_delay", "prediction_compensation", horizon=30),
                     episodes=3, seed=0)
    readings = pcrb(coloc_env.compose("target_cv", "bernoulli_delay", "kalman", horizon=30), episodes=3, seed=0)
    assert np.all(estimates["delivered"] <= readings["delivered"] * (1 + 1e-9))
    assert np.any(estimates["delivered"] < readings["delivered"] * (1 - 1e-6))
    assert np.all(estimates["delivered"] >= estimates["centralized"] * (1 - 1e-9))


def test_a_lag_cap_credits_late_readings_earlier_and_says_how_many():
    spec = coloc_env.compose("gps_denied", "broadcast", "range_ls", horizon=12)
    exact = pcrb(spec, episodes=1, seed=0, lag_cap=50)
    capped = pcrb(spec, episodes=1, seed=0, lag_cap=0)
    assert exact["delivered_capped"] == 0.0 < capped["delivered_capped"]
    assert np.all(capped["delivered"] <= exact["delivered"] * (1 + 1e-9))  # earlier information: lower
    with pytest.raises(ValueError, match=r"lag_cap must be an integer in \[0, 50\]"):
        pcrb(spec, episodes=1, lag_cap=51)
