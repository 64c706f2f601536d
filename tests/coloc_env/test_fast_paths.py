"""The fast paths of the target presets give the values of the plain code they stand in for, bit for bit:
counter-based uniforms on Python ints for a few copies, the bernoulli_delay network's draw made a step ahead,
the bandwidth network's lookup table and offered selections, one per-link packets call instead of one per
receiver, and the bandwidth estimator's identity test."""

import numpy as np
import pytest

import coloc_env
import coloc_env.draws as draws
import estimators.bandwidth_fusion as bf
from coloc_env.draws import uniforms
from coloc_env.networks import BernoulliDelay
from coloc_env.networks.bernoulli_delay import BLOCK_STEPS, BernoulliDelayNetwork

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def _reference_uniforms(keys, counters, shape):
    """The counter-based uniforms written out once, in the plain numpy form."""

    def mix(z):
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))

    keys = np.asarray(keys, dtype=np.uint64)
    z = keys.copy()
    for counter in counters:
        c = np.asarray(counter, dtype=np.int64).reshape(-1).astype(np.uint64)
        z = mix(z + _GOLDEN * (c + np.uint64(1)))
    cells = np.arange(int(np.prod(shape, dtype=np.int64)), dtype=np.uint64)
    offsets = (_GOLDEN * (cells + np.uint64(1))).reshape(shape)
    z = mix(z.reshape((len(keys),) + (1,) * len(shape)) + offsets)
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


@pytest.mark.parametrize("small_batch", [draws._SMALL_BATCH, 0])  # Python ints for a few copies, or numpy
def test_uniforms_equal_the_plain_hash_for_every_batch_and_counter_form(monkeypatch, small_batch):
    monkeypatch.setattr(draws, "_SMALL_BATCH", small_batch)
    rng = np.random.default_rng(0)
    for B in [0, 1, 2, 3, 7, 8, 9, 33]:
        for trial in range(20):
            keys = rng.integers(0, 2**63, size=B, dtype=np.int64).astype(np.uint64)
            if B and trial % 4 == 0:
                keys[0] = np.uint64(2**64 - 1)  # the largest key: every sum wraps
            counters = []
            for kind in rng.integers(0, 4, size=rng.integers(0, 4)):
                counters.append([int(rng.integers(-5, 10)), rng.integers(-3, 1000, size=B),
                                 np.array([int(rng.integers(2**62))]), np.int64(-1)][kind])
            shape = tuple(int(n) for n in rng.integers(1, 5, size=rng.integers(0, 3)))
            got, want = uniforms(keys, tuple(counters), shape), _reference_uniforms(keys, counters, shape)
            assert got.shape == want.shape and got.dtype == want.dtype
            assert got.tobytes() == want.tobytes()


def _bernoulli_network(batch, num_agents=5, seed=0):
    net = BernoulliDelay().build(num_agents, batch, "packets")
    net.reset([np.random.default_rng(seed + b) for b in range(batch)], np.arange(batch))
    return net


class _PerStepBernoulli(BernoulliDelayNetwork):
    """The plain per-step draw: a packet_delays of its own turns the block of draws off."""

    def packet_delays(self, distance, u):
        return super().packet_delays(distance, u)


def test_bernoulli_delay_block_of_draws_equals_the_per_step_draw():
    """Packets read from the block of delays drawn ahead (across block ends, and after a reset of some copies,
    whose keys and steps change) equal those of a network that draws two uniforms at every step."""
    B, N = 3, 5
    block = _bernoulli_network(B)
    plain = _PerStepBernoulli(BernoulliDelay(), N, B, "packets")
    plain.reset([np.random.default_rng(b) for b in range(B)], np.arange(B))
    senders = np.ones((B, N), bool)
    listening = np.ones((B, N, N), bool)
    positions = np.zeros((B, N, 2))
    transmit = np.ones((B, N, 1), np.int64)
    delivered = 0
    for k in range(3 * BLOCK_STEPS):
        if k == 40:  # copy 1 starts a new episode: a new key, and its steps restart
            for net in (block, plain):
                net.reset([np.random.default_rng(99)], np.array([1]))
        steps = np.array([k, k if k < 40 else k - 40, k])
        for net in (block, plain):
            net.begin(steps, positions, transmit)
        got, want = block.packets(senders, listening, 2.0, slot=1), plain.packets(senders, listening, 2.0, slot=1)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(block.messages_sent, plain.messages_sent)
        delivered += int((got == 1).sum())
    assert block._blocks and not plain._blocks and delivered > 0  # the block was used; late packets occurred


def test_one_per_link_packets_call_equals_one_call_per_receiver():
    """floats (B, N, N): every link its own message; the delays, messages and floats equal N calls that each
    send to one receiver with the per-sender payload (the backend's former loop)."""
    B, N = 4, 5
    rng = np.random.default_rng(3)
    count = rng.integers(0, 3, size=(B, N, N)).astype(float)  # [t, s]: floats t sends s
    one, each = _bernoulli_network(B), _bernoulli_network(B)
    positions = np.zeros((B, N, 2))
    for k in range(5):
        for net in (one, each):
            net.begin(np.full(B, k), positions, rng.integers(0, 2, size=(B, N, 1)) if k else np.ones((B, N, 1), int))
        each._decisions = one._decisions
        delay = one.packets(np.ones((B, N), bool), count > 0, count)
        for s in range(N):
            listening = np.zeros((B, N, N), bool)
            listening[:, :, s] = True
            floats = count[:, :, s].copy()
            floats[:, s] = 0.0
            d = each.packets(floats > 0, listening, floats)
            np.testing.assert_array_equal(d[:, :, s], delay[:, :, s])
        np.testing.assert_array_equal(one.messages_sent, each.messages_sent)
        np.testing.assert_array_equal(one.floats_sent, each.floats_sent)
        np.testing.assert_array_equal(one.delivered, each.delivered)


@pytest.mark.parametrize("config", [{}, {"num_agents": 5, "budget": 6}])
def test_bandwidth_lookup_table_and_offered_selections_decode_like_the_unranking(config):
    env = coloc_env.vector_env("bandwidth_fusion", num_envs=1, **config)
    net = env.scenario.network
    links = net.links
    F, N = links.size, links.num_nodes
    assert net._table is not None
    index = np.arange(F * N).reshape(-1, N) % F  # every feasible selection, at every receiver
    want = links.full_selection(links.selection_at(index))
    net._decisions = index[:, :, None]
    np.testing.assert_array_equal(net.component_selection(), want)
    table, net._table = net._table, None
    try:
        np.testing.assert_array_equal(net.component_selection(), want)  # the unranking itself
        net.offer_selection(index, links.selection_at(index))
        np.testing.assert_array_equal(net.component_selection(), want)
        net.offer_selection(index[::-1], links.selection_at(index[::-1]))  # an offer for other indices: ignored
        np.testing.assert_array_equal(net.component_selection(), want)
    finally:
        net._table = table
    net._decisions = np.full((1, N, 1), F)
    with pytest.raises(ValueError, match="selection index"):
        net.component_selection()


def test_identity_test_agrees_with_the_value_comparison():
    cases = [np.eye(3), np.eye(4), -0.0 + np.zeros((3, 3)) + np.eye(3), np.where(np.eye(3) > 0, 1.0, -0.0),
             np.eye(3, dtype=np.float32), np.eye(3, dtype=int), np.eye(3) * 2, np.ones((3, 3)), np.eye(3)[:2],
             np.eye(6)[::2, ::2], np.zeros((2, 3, 3))]
    for matrix in cases:
        want = matrix.ndim == 2 and matrix.shape[0] == matrix.shape[1] and np.array_equal(
            matrix, np.eye(len(matrix)))
        assert bf._is_identity(matrix) == want
