"""Every network's per-link accounting (``transmissions``, ``link_attempts``, ``link_deliveries``, ``collisions``)
follows the table of ``coloc_env.networks.base`` on known geometries, beside ``messages_sent``'s meaning per call,
and reaches the infos of compositions and presets."""

from __future__ import annotations

import numpy as np
import pytest

import coloc_env
from coloc_env.networks import BernoulliDelay, Broadcast, GilbertElliott, Ideal, Relay
from coloc_env.networks.blocks.relay_chain import STOP_REASONS
from tests.test_bad_config_properties import CHEAP_PRESET, presets

LINE = np.array([0.0, 100.0, 250.0, 600.0])  # comm_range 200: links 0-1 and 1-2 only


def _line_network(config, kind="broadcast", B=3, seed=0):
    N = len(LINE)
    net = config.build(N, B, kind)
    net.reset([np.random.default_rng([seed, b]) for b in range(B)], np.arange(B))
    positions = np.broadcast_to(np.stack([LINE, np.zeros(N)], axis=-1), (B, N, 2))
    net.begin(np.arange(B) + 3, positions, np.ones((B, N, len(net.transport_blocks()) or 1), np.int64))
    return net


@pytest.mark.parametrize("loss", [0.0, 0.5])
def test_a_broadcast_attempts_each_in_range_listener(loss):
    B, N = 3, len(LINE)
    net = _line_network(Broadcast(comm_range=200.0, loss=loss), B=B)
    delivered = np.zeros((B, N, N), bool)
    for slot in range(40):  # 40 rounds: each adds its own transmissions and attempts
        delivered_now = net.broadcast(np.ones((B, N), bool), np.ones((B, N, N), bool), 1.0, slot=slot)
        delivered |= delivered_now
    np.testing.assert_array_equal(net.transmissions, 40.0)  # every agent transmits each round, heard or not
    np.testing.assert_array_equal(net.link_attempts, np.broadcast_to([40.0, 80.0, 40.0, 0.0], (B, N)))
    assert (net.link_deliveries <= net.link_attempts).all()
    assert (net.messages_sent <= net.transmissions).all()  # transmissions that reached someone
    np.testing.assert_array_equal(net.collisions, 0.0)
    if loss == 0.0:
        np.testing.assert_array_equal(net.link_deliveries, net.link_attempts)
        np.testing.assert_array_equal(net.messages_sent, np.broadcast_to([40.0, 40.0, 40.0, 0.0], (B, N)))
    else:
        rate = net.link_deliveries[:, :3].sum() / net.link_attempts[:, :3].sum()
        assert 0.4 < rate < 0.6
        assert (net.messages_sent[:, :3] < 40).any()


def test_a_transmission_decided_off_or_unheard_is_counted_by_the_rule():
    B, N = 2, len(LINE)
    net = _line_network(Broadcast(comm_range=200.0), B=B)
    net._decisions = np.zeros((B, N, 1), np.int64)
    net._decisions[:, 1] = 1  # only agent 1 transmits
    listening = np.ones((B, N, N), bool)
    listening[:, :, 2] = False  # agent 2 does not take anyone's message
    net.broadcast(np.ones((B, N), bool), listening, 1.0, slot=0)
    np.testing.assert_array_equal(net.transmissions, np.broadcast_to([0.0, 1.0, 0.0, 0.0], (B, N)))
    np.testing.assert_array_equal(net.link_attempts, np.broadcast_to([0.0, 1.0, 0.0, 0.0], (B, N)))  # 1 -> 0 only
    np.testing.assert_array_equal(net.link_deliveries, net.link_attempts)


def test_central_messages_count_one_transmission_each_and_an_attempt_in_range():
    B, N = 2, len(LINE)
    net = _line_network(Ideal(), kind="central", B=B)
    net_range = _line_network(Broadcast(comm_range=200.0, loss=0.0), kind="central", B=B)
    senders = np.array([[0, 1, 2, 3, 3, -1], [3, 2, -1, -1, 1, 1]])
    for network in (net, net_range):
        delivered = network.messages_to(senders, 0, 2.0, np.arange(6))
        per_sender = [np.bincount(senders[b][senders[b] > 0], minlength=N) for b in range(B)]
        np.testing.assert_array_equal(network.transmissions, per_sender)  # the centre sends itself nothing
        np.testing.assert_array_equal(network.link_deliveries, network.messages_sent)
        assert network.link_deliveries.sum() == delivered.sum()
    np.testing.assert_array_equal(net.link_attempts, net.transmissions)
    np.testing.assert_array_equal(net_range.link_attempts, np.array([[0, 1, 0, 0], [0, 2, 0, 0]]))  # 1 in range of 0


@pytest.mark.parametrize("config", [Broadcast(comm_range=250.0, loss=0.3), Relay(comm_range=220.0, loss_at_zero=0.2),
                                    GilbertElliott(comm_range=250.0, loss_good=0.2)])
def test_a_relay_hop_is_one_transmission_and_one_link_attempt(config):
    B, N, J = 4, 7, 9
    rng = np.random.default_rng(2)
    net = config.build(N, B, "chain")
    net.reset([np.random.default_rng([2, b]) for b in range(B)], np.arange(B))
    net.begin(np.full(B, 5), rng.uniform(0.0, 400.0, (B, N, 2)), np.zeros((B, N, 1), np.int64))
    source = np.where(rng.random((B, J)) < 0.8, rng.integers(0, N, (B, J)), -1)
    result = net.relay_each(source, np.full((B, J), -1), lambda hop: 1.0, np.arange(J))
    expected_hops = np.zeros((B, N))
    expected_tries = np.zeros((B, N))
    for b in range(B):
        for j in range(J):
            chain, length = result.chain[b, j], result.length[b, j]
            for h in range(length - 1):
                expected_hops[b, chain[h]] += 1
            if result.stop[b, j] == STOP_REASONS.index("lost"):
                expected_tries[b, chain[length - 1]] += 1  # the lost hop: sent, not delivered
    assert expected_tries.sum() > 0 and expected_hops.sum() > 0
    np.testing.assert_array_equal(net.link_deliveries, expected_hops)
    np.testing.assert_array_equal(net.messages_sent, expected_hops)  # relay: delivered hops
    np.testing.assert_array_equal(net.transmissions, expected_hops + expected_tries)
    np.testing.assert_array_equal(net.link_attempts, net.transmissions)


def test_packets_count_attempts_and_their_arrivals_on_time_or_late():
    B, N = 3, 5
    net = BernoulliDelay(on_time_probability=0.5, late_probability=0.3).build(N, B, "packets")
    net.reset([np.random.default_rng([4, b]) for b in range(B)], np.arange(B))
    net.begin(np.full(B, 2), np.zeros((B, N, 2)), np.ones((B, N, 1), np.int64))
    listening = np.random.default_rng(1).random((B, N, N)) < 0.6
    delay = net.packets(np.ones((B, N), bool), listening, 3.0)
    named = listening & ~np.eye(N, dtype=bool)
    np.testing.assert_array_equal(net.transmissions, named.any(axis=-1))  # one packet per sender
    np.testing.assert_array_equal(net.messages_sent, net.transmissions)  # packets: attempts
    np.testing.assert_array_equal(net.link_attempts, named.sum(axis=-1))
    np.testing.assert_array_equal(net.link_deliveries, (delay >= 0).sum(axis=-1))
    assert ((delay == 1).any() and (delay == -1).any())
    # per-link payloads: each link is its own message
    net.begin(np.full(B, 3), np.zeros((B, N, 2)), np.ones((B, N, 1), np.int64))
    net.packets(np.ones((B, N), bool), named, np.where(named, 2.0, 0.0))
    np.testing.assert_array_equal(net.transmissions, named.sum(axis=-1))
    np.testing.assert_array_equal(net.messages_sent, net.transmissions)


def _first_step_infos(env):
    env.reset(seed=0)
    actions = {a: env.action_space(a).sample() for a in env.agents}
    _, _, _, _, infos = env.step(actions)
    return infos


@pytest.mark.parametrize("name", presets())
def test_every_preset_reports_the_link_counts_in_its_infos(name):
    infos = _first_step_infos(coloc_env.parallel_env(name, **CHEAP_PRESET.get(name, {})))
    for info in infos.values():
        for key in ("transmissions", "link_attempts", "link_deliveries", "collisions"):
            assert np.ndim(info[key]) == 0, key
        assert 0 <= info["link_deliveries"] <= info["link_attempts"]
        assert info["link_deliveries"] + info["collisions"] <= info["link_attempts"]
        if coloc_env.PRESETS[name].network.name != "contention":  # the only network where frames collide
            assert info["collisions"] == 0


def test_a_composition_reports_them_and_the_receive_ahead_path_keeps_the_steps_apart():
    """``afge`` receives before deciding: the step's record (counts included) is the one of its own step."""
    spec = coloc_env.compose("nlos_orbit", {"name": "random_delay", "transmit_decision": False}, "afge", horizon=6)
    env = coloc_env.parallel_env(spec)
    infos = _first_step_infos(env)
    assert all(key in info for info in infos.values()
               for key in ("transmissions", "link_attempts", "link_deliveries", "collisions"))
    spec = coloc_env.compose("circles", {"name": "broadcast", "comm_range": 150.0}, "ukf_ccl", horizon=6)
    env = coloc_env.parallel_env(spec)
    obs, infos = env.reset(seed=1)
    assert all(info["transmissions"] == 0 for info in infos.values())  # nothing sent at reset
    total = {"transmissions": 0.0, "link_deliveries": 0.0, "messages_sent": 0.0}
    for _ in range(5):
        _, _, _, _, infos = env.step({a: env.action_space(a).sample() for a in env.agents})
        for key in total:
            total[key] += sum(info[key] for info in infos.values())
    assert total["transmissions"] > 0
    assert total["link_deliveries"] == total["messages_sent"]  # central: one receiver per message
