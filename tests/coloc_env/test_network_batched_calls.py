"""A step's J relay chains or centre messages resolved in one network call equal J calls in order: the same chains,
deliveries, loss draws and accounting, bit for bit (a lossy network, so the draws matter)."""

from __future__ import annotations

import numpy as np
import pytest

from coloc_env.networks import chains
from coloc_env.networks.base import RelayChain
from coloc_env.networks.blocks.relay_chain import STOP_REASONS
from coloc_env.networks.broadcast import Broadcast
from coloc_env.networks.ideal import Ideal
from coloc_env.networks.relay import Relay


def started(config, kind, B=4, N=7, seed=0):
    rng = np.random.default_rng(seed)
    net = config.build(N, B, kind)
    net.reset([np.random.default_rng([seed, b]) for b in range(B)], np.arange(B))
    decisions = rng.integers(0, 2, size=(B, N, len(net.transport_blocks())))
    net.begin(rng.integers(0, 20, size=B), rng.uniform(0.0, 400.0, size=(B, N, 2)), decisions)
    return net, rng


def snapshot(net):
    return net.messages_sent.copy(), net.floats_sent.copy(), net.delivered.copy()


@pytest.mark.parametrize("config", [Broadcast(comm_range=250.0, loss=0.3), Ideal()])
def test_relay_over_J_sources_equals_J_relay_calls(config):
    B, N, J = 4, 7, 9
    one, rng = started(config, "chain", B, N)
    many, _ = started(config, "chain", B, N)
    source = np.where(rng.random((B, J)) < 0.8, rng.integers(0, N, (B, J)), -1)
    first = np.where(rng.random((B, J)) < 0.7, (source + rng.integers(1, N, (B, J))) % N, -1)
    slots = 3 + np.arange(J)

    def floats(hop):
        return 10.5 + 3 * hop

    calls = [one.relay(source[:, j], first[:, j], floats, slot=int(slots[j])) for j in range(J)]
    batched = many.relay_each(source, first, floats, slots)
    assert batched.chain.shape == (B, J, N)
    for name in ("chain", "length", "hop_distance", "stop"):
        np.testing.assert_array_equal(getattr(batched, name), np.stack([getattr(c, name) for c in calls], axis=1))
    for a, b in zip(snapshot(one), snapshot(many), strict=True):
        np.testing.assert_array_equal(a, b)
    assert isinstance(many.last_chain, RelayChain)
    np.testing.assert_array_equal(many.last_chain.chain, calls[-1].chain)
    assert (batched.length[source < 0] == 0).all() and (batched.length[source >= 0] >= 1).all()


@pytest.mark.parametrize("config", [Broadcast(comm_range=250.0, loss=0.3), Ideal()])
def test_messages_to_the_centre_equal_one_broadcast_per_message(config):
    B, N, J = 5, 6, 11
    one, rng = started(config, "central", B, N, seed=1)
    many, _ = started(config, "central", B, N, seed=1)
    senders = np.where(rng.random((B, J)) < 0.8, rng.integers(0, N, (B, J)), -1)
    slots = np.arange(J)
    expected = np.zeros((B, J), bool)
    rows = np.arange(B)
    for j in range(J):
        one_hot = np.zeros((B, N), bool)
        one_hot[rows[senders[:, j] >= 0], senders[senders[:, j] >= 0, j]] = True
        listening = np.zeros((B, N, N), bool)
        listening[:, :, 0] = True
        delivered = one.broadcast(one_hot, listening, 2.0, slot=int(slots[j]))
        expected[:, j] = (senders[:, j] >= 0) & delivered[rows, np.maximum(senders[:, j], 0), 0]
    np.testing.assert_array_equal(many.messages_to(senders, 0, 2.0, slots), expected)
    for a, b in zip(snapshot(one), snapshot(many), strict=True):
        np.testing.assert_array_equal(a, b)
    assert 0 < expected.sum() < (senders > 0).sum() or isinstance(config, Ideal)


@pytest.mark.parametrize("config", [Broadcast(comm_range=150.0), Ideal()])
def test_nearest_first_chains_go_to_the_nearest_unreached_platform_until_it_is_out_of_range(config):
    """The definition, hop by hop: the nearest platform the chain has not reached (ties to the lower index), the
    chain stopping with "out_of_range" when that one is beyond the range, "complete" when none is left."""
    B, N, J = 3, 12, 10
    net, rng = started(config, "chain", B, N, seed=3)
    source = rng.integers(0, N, (B, J))
    first = np.where(rng.random((B, J)) < 0.5, (source + rng.integers(1, N, (B, J))) % N, -1)
    result = net.relay_each(source, first, lambda hop: 1.0, np.arange(J))
    distance = net.distances()
    reach = getattr(config, "comm_range", np.inf)
    stops = set()
    for b in range(B):
        for j in range(J):
            chain, holder, reached = [source[b, j]], source[b, j], {source[b, j]}
            stop = "complete"
            while len(chain) < N:
                masked = np.where(np.isin(np.arange(N), list(reached)), np.inf, distance[b, holder])
                target = first[b, j] if len(chain) == 1 and first[b, j] >= 0 else int(np.argmin(masked))
                if distance[b, holder, target] > reach:
                    stop = "out_of_range"
                    break
                chain.append(target)
                reached.add(target)
                holder = target
            stops.add(stop)
            np.testing.assert_array_equal(result.chain[b, j], chain + [-1] * (N - len(chain)))
            assert STOP_REASONS[result.stop[b, j]] == stop
    # the range cuts chains at different hops (finished chains leave the search while others go on)
    assert ("out_of_range" in stops and len(set(result.length.ravel())) > 2) if reach < np.inf \
        else stops == {"complete"}


@pytest.mark.parametrize("config", [Broadcast(comm_range=250.0, loss=0.3), Relay(comm_range=220.0, max_hops=3,
                                                                                 loss_at_zero=0.1)])
def test_chains_resolved_without_numba_are_the_compiled_chains(config, monkeypatch):
    """The chain resolver runs compiled where numba is installed and as plain Python elsewhere: the same chains,
    stop reasons and accounting."""
    B, N, J = 3, 8, 10

    def run():
        net, rng = started(config, "chain", B, N, seed=5)
        source = np.where(rng.random((B, J)) < 0.8, rng.integers(0, N, (B, J)), -1)
        first = np.where(rng.random((B, J)) < 0.5, (source + rng.integers(1, N, (B, J))) % N, -1)
        return net.relay_each(source, first, lambda hop: 1.0 + hop, np.arange(J)), snapshot(net)

    compiled, compiled_counts = run()
    monkeypatch.setattr(chains, "compiled_resolver", lambda: None)
    plain, plain_counts = run()
    for name in ("chain", "length", "hop_distance", "stop"):
        np.testing.assert_array_equal(getattr(plain, name), getattr(compiled, name))
    for a, b in zip(plain_counts, compiled_counts, strict=True):
        np.testing.assert_array_equal(a, b)
    assert len(set(compiled.stop.ravel())) >= 3  # several stop reasons met
