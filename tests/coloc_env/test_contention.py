"""The ``contention`` network: the protocol model of interference, half duplex, capture, its accounting and
acknowledgements, and its equality with ``broadcast`` where nothing collides."""

from __future__ import annotations

import numpy as np
import pytest

import agents
import coloc_env
from coloc_env.networks import Contention


def _network(kind="broadcast", batch=1, n=3, rounds=1, **fields):
    net = Contention(**fields).build(n, batch, kind, rounds)
    net.reset([np.random.default_rng(b) for b in range(batch)], np.arange(batch))
    return net


def _line(*xs):
    """Agents on the x axis, one copy: positions (1, N, 2)."""
    return np.array([[[x, 0.0] for x in xs]])


def _begin(net, positions, sending):
    """``sending`` (B, N, Q) 0/1: the transmit block."""
    net.begin(np.zeros(len(positions), int), positions, np.asarray(sending, np.int64))


def test_a_lone_transmitter_reaches_every_silent_agent_in_range_and_no_one_beyond():
    net = _network(n=4, comm_range=200.0)
    _begin(net, _line(0, 150, 199, 201), [[[1], [0], [0], [0]]])
    everyone = np.ones((1, 4, 4), bool)
    delivered = net.broadcast(np.ones((1, 4), bool), everyone, 3.0)
    assert delivered[0, 0].tolist() == [False, True, True, False]
    assert net.transmissions[0].tolist() == [1, 0, 0, 0] and net.messages_sent[0].tolist() == [1, 0, 0, 0]
    assert net.link_attempts[0, 0] == 2 and net.link_deliveries[0, 0] == 2 and net.collisions[0, 0] == 0
    assert net.floats_sent[0].tolist() == [3.0, 0, 0, 0]
    assert net.observation_features()[0, :, 0].tolist() == [1.0, 0, 0, 0]  # both neighbours acknowledged


def test_half_duplex_a_transmitting_agent_hears_nothing_in_that_slot():
    net = _network(n=2, slots=2)
    # slot 0: both transmit (each deaf to the other); slot 1: only agent 0
    _begin(net, _line(0, 100), [[[1, 1], [1, 0]]])
    assert net.transmissions[0].tolist() == [2, 1]
    assert net.link_attempts[0].tolist() == [2, 1]
    assert net.link_deliveries[0].tolist() == [1, 0] and net.collisions[0].tolist() == [1, 1]
    assert net.observation_features()[0].tolist() == [[0.0, 1.0], [0.0, 0.0]]
    # a message of the round arrives where any of its slots got through: 0 -> 1 in slot 1, 1 -> 0 never
    delivered = net.broadcast(np.ones((1, 2), bool), np.ones((1, 2, 2), bool), 1.0)
    assert delivered[0].tolist() == [[False, True], [False, False]]


def test_a_hidden_terminal_collides_at_the_receiver_between_them():
    net = _network(n=3)
    _begin(net, _line(0, 150, 300), [[[1], [0], [1]]])  # 0 and 2 cannot hear each other; both reach 1
    assert net.link_deliveries[0].tolist() == [0, 0, 0] and net.collisions[0].tolist() == [1, 0, 1]
    # interference range 400 m: 2 now also disturbs 1's reception of 0 ... and a third silent agent beyond
    net = _network(n=3, interference_range=400.0)
    _begin(net, _line(0, 150, 500), [[[1], [0], [1]]])  # 2 is 350 m from 1: interferes, not heard
    assert net.link_deliveries[0].tolist() == [0, 0, 0] and net.link_attempts[0].tolist() == [1, 0, 0]
    net = _network(n=3, interference_range=300.0)
    _begin(net, _line(0, 150, 500), [[[1], [0], [1]]])  # 350 m > 300 m: no interference
    assert net.link_deliveries[0].tolist() == [1, 0, 0]


def test_capture_lets_the_stronger_frame_through_when_it_beats_the_others_by_the_ratio():
    # receiver at 0, transmitters at 50 m and 150 m: power ratio (150 / 50)^2 = 9
    for capture, through in ((5.0, [0, 1, 0]), (10.0, [0, 0, 0])):  # [sender]: heard by 0
        net = _network(kind="broadcast", n=3, capture=capture, comm_range=200.0)
        _begin(net, _line(0, 50, -150), [[[0], [1], [1]]])
        heard_by_0 = net.broadcast(np.ones((1, 3), bool), np.ones((1, 3, 3), bool), 1.0)[0, :, 0]
        assert heard_by_0.astype(int).tolist() == through, capture
    net = _network(kind="broadcast", n=3, capture=5.0, path_loss_exponent=1.0)  # ratio 3 < 5: collision
    _begin(net, _line(0, 50, -150), [[[0], [1], [1]]])
    assert not net.broadcast(np.ones((1, 3), bool), np.ones((1, 3, 3), bool), 1.0)[0, :, 0].any()


def test_slotted_aloha_matches_its_closed_forms_within_three_standard_errors():
    """n agents in mutual range, one slot, each transmitting with probability p: a frame reaches a given
    neighbour iff the other n - 1 are silent, (1 - p)^(n - 1); a (sender, receiver) pair succeeds per slot with
    p (1 - p)^(n - 1); a slot carries exactly one frame with n p (1 - p)^(n - 1)."""
    n, p, B, steps = 6, 0.2, 64, 40
    rng = np.random.default_rng(3)
    net = _network(batch=B, n=n, comm_range=np.inf)
    positions = np.broadcast_to(rng.uniform(0, 100, (1, n, 2)), (B, n, 2))
    everyone = np.ones((B, n, n), bool)
    frames, delivered, pairs, single = [], [], [], []  # per slot (copy, step): the slots are independent trials
    for _ in range(steps):
        _begin(net, positions, (rng.random((B, n, 1)) < p).astype(int))
        frames.append(net.link_attempts.sum(axis=1))
        delivered.append(net.link_deliveries.sum(axis=1))
        pairs.append(net.broadcast(np.ones((B, n), bool), everyone, 1.0).sum(axis=(1, 2)))
        single.append(net.transmissions.sum(axis=1) == 1)
        assert np.array_equal(net.collisions, net.link_attempts - net.link_deliveries)
    frames, delivered, pairs, single = (np.concatenate(x).astype(float) for x in (frames, delivered, pairs, single))
    trials = len(frames)
    q = (1 - p) ** (n - 1)

    def within(numerator, denominator, expected):  # a ratio of sums over independent trials: the delta method
        ratio = numerator.sum() / denominator.sum()
        se = np.sqrt(np.sum((numerator - expected * denominator) ** 2)) / denominator.sum()
        return abs(ratio - expected) < 3 * se

    assert within(delivered, frames, q)  # a frame reaches a neighbour: the other n - 1 silent
    assert within(pairs, np.full(trials, n * (n - 1.0)), p * q)  # a pair per slot: p (1 - p)^(n - 1)
    assert within(single, np.ones(trials), n * p * q)  # one frame alone in the slot
    assert not within(delivered, frames, (1 - p) ** (n - 2))  # the test tells n from n - 1 contenders


def test_the_aloha_policy_to_the_centre_matches_its_closed_form():
    """``aloha:p`` on a ``central`` backend, every agent in range: the centre only listens, so a frame of one of
    the n - 1 others reaches it iff the other n - 2 are silent, (1 - p)^(n - 2)."""
    p = 0.3
    spec = coloc_env.compose(world="circles", network={"name": "contention", "comm_range": np.inf},
                             backend="ukf_ccl", horizon=150)
    env = coloc_env.parallel_env(spec)
    policy = agents.make_policy(f"aloha:{p}", env, seed=0)
    observations, _ = env.reset(seed=0)
    n = env.unwrapped.scenario.num_agents
    attempts = deliveries = 0.0
    for _ in range(150):
        observations, _, _, _, infos = env.step(policy.act(observations))
        attempts += sum(infos[a]["link_attempts"] for a in env.possible_agents)
        deliveries += sum(infos[a]["link_deliveries"] for a in env.possible_agents)
        assert infos[env.possible_agents[0]]["transmissions"] == 0  # the centre never transmits
    q = (1 - p) ** (n - 2)
    assert attempts > 100
    assert abs(deliveries / attempts - q) < 3 * np.sqrt(q * (1 - q) / attempts)


@pytest.mark.parametrize("world, backend", [("circles", "ukf_ccl"), ("gps_denied", "range_ls")])
def test_a_single_transmitting_agent_gives_the_broadcast_networks_episode(world, backend):
    """Nothing collides when one agent transmits: the estimates are ``broadcast``'s, bit for bit."""
    runs = {}
    for network in ("broadcast", "contention"):
        env = coloc_env.parallel_env(coloc_env.compose(world=world, network=network, backend=backend, horizon=25))
        core = env.unwrapped.scenario
        env.reset(seed=4)
        vector = core.action_vector("maximum")
        start = sum(b.size for b, part in zip(core.blocks, core.block_parts, strict=True) if part == "world")
        estimates = []
        for _ in range(25):
            actions = np.tile(vector, (core.num_agents, 1))
            actions[[i for i in range(core.num_agents) if i != 2], start] = 0  # agent 2 alone transmits
            _, _, _, _, infos = env.step({a: actions[i] for i, a in enumerate(env.possible_agents)})
            estimates.append([infos[a]["estimated_position"] for a in env.possible_agents])
            if network == "contention":
                assert sum(infos[a]["collisions"] for a in env.possible_agents) == 0
        runs[network] = np.array(estimates)
    assert np.array_equal(runs["broadcast"], runs["contention"])


def test_round_robin_with_one_slot_per_agent_never_collides_and_equals_broadcast_always():
    n = coloc_env.worlds.GpsDenied().num_agents
    estimates = {}
    contention = coloc_env.compose(world="gps_denied", network={"name": "contention", "slots": n},
                                   backend="ukf_ccl", horizon=12)
    broadcast = coloc_env.compose(world="gps_denied", network="broadcast", backend="ukf_ccl", horizon=12)
    for name, composition, policy_name in (("contention", contention, "round_robin"),
                                           ("broadcast", broadcast, "always")):
        env = coloc_env.parallel_env(composition)
        policy = agents.make_policy(policy_name, env, seed=0)
        observations, _ = env.reset(seed=2)
        rows = []
        for _ in range(12):
            observations, _, _, _, infos = env.step(policy.act(observations))
            rows.append([infos[a]["estimated_position"] for a in env.possible_agents])
            if name == "contention":
                names = env.possible_agents
                assert sum(infos[a]["collisions"] for a in names) == 0
                assert sum(infos[a]["link_deliveries"] for a in names) == sum(infos[a]["link_attempts"] for a in names)
                assert [infos[a]["transmissions"] for a in names] == [0.0] + [1.0] * (n - 1)  # the centre listens
        estimates[name] = np.array(rows)
    assert np.array_equal(estimates["contention"], estimates["broadcast"])


def test_acknowledgements_are_observed_one_step_later_and_cleared_at_reset():
    env = coloc_env.parallel_env(coloc_env.compose(world="circles", network={"name": "contention", "slots": 3},
                                                   backend="ukf_ccl", horizon=5))
    core = env.unwrapped.scenario
    observations, _ = env.reset(seed=0)
    N = core.num_agents
    ack = slice(3 * N + 2 + len(core.own_features) + core.world.feature_bounds()[0].size, None)
    assert all(np.all(o[ack] == 0) for o in observations.values()) and observations["platform_1"][ack].size == 3
    actions = np.tile(core.action_vector("minimum"), (N, 1))
    start = sum(b.size for b, part in zip(core.blocks, core.block_parts, strict=True) if part == "world")
    actions[1, start + 1] = 1  # agent 1 alone, in slot 1
    observations, *_ = env.step({a: actions[i] for i, a in enumerate(env.possible_agents)})
    in_range = core.network.distances()[0, 1, 0] <= 200.0
    assert observations["platform_1"][ack].tolist() == [0.0, float(in_range), 0.0]
    assert all(np.all(observations[a][ack] == 0) for a in env.possible_agents if a != "platform_1")
    observations, _ = env.reset(seed=1)
    assert all(np.all(o[ack] == 0) for o in observations.values())


def test_the_centre_of_a_central_backend_only_listens():
    env = coloc_env.parallel_env(coloc_env.compose(world="circles", network={"name": "contention", "slots": 2},
                                                   backend="ukf_ccl"))
    env.reset(seed=0)
    mask = env.unwrapped.scenario.action_mask()
    core = env.unwrapped.scenario
    start = sum(b.choices * b.size for b, part in zip(core.blocks, core.block_parts, strict=True) if part == "world")
    transmit = mask[0, :, start:start + 4].reshape(core.num_agents, 2, 2)
    assert not transmit[0, :, 1].any() and transmit[0, :, 0].all() and transmit[1:].all()


@pytest.mark.parametrize("fields, message", [
    ({"slots": 0}, r"network\.slots must be in \[1, 64\], got 0"),
    ({"slots": 65}, r"network\.slots must be in \[1, 64\], got 65"),
    ({"slots": 2.0}, r"network\.slots must be an integer"),
    ({"comm_range": 0.0}, r"network\.comm_range must be in \(0\.0, inf\]"),
    ({"interference_range": 199.0}, r"network\.interference_range must be in \[comm_range = 200\.0, inf\]"),
    ({"comm_range": 50.0, "interference_range": 40.0}, r"network\.interference_range must be in \[comm_range = 50"),
    ({"capture": 0.5}, r"network\.capture must be 0 \(off\) or in \[1\.0, 1000000\.0\], got 0\.5"),
    ({"capture": 2e6}, r"network\.capture must be 0 \(off\) or in \[1\.0, 1000000\.0\]"),
    ({"capture": -1.0}, r"network\.capture must be 0 \(off\)"),
    ({"path_loss_exponent": 0.5}, r"network\.path_loss_exponent must be in \[1\.0, 10\.0\], got 0\.5"),
    ({"path_loss_exponent": 10.5}, r"network\.path_loss_exponent must be in \[1\.0, 10\.0\], got 10\.5"),
])
def test_bad_fields_are_refused_naming_the_field_and_its_range(fields, message):
    with pytest.raises(ValueError, match=message):
        coloc_env.compose(world="circles", network={"name": "contention", **fields}, backend="ukf_ccl")


def test_the_ends_of_each_range_are_accepted():
    for fields in ({"slots": 1}, {"slots": 64}, {"interference_range": 200.0}, {"interference_range": np.inf},
                   {"capture": 0.0}, {"capture": 1.0}, {"capture": 1e6}, {"path_loss_exponent": 1.0},
                   {"path_loss_exponent": 10.0}):
        coloc_env.compose(world="circles", network={"name": "contention", **fields}, backend="ukf_ccl")


def test_relay_chains_are_refused_with_the_reason():
    with pytest.raises(ValueError, match=r"ukf_dcl sends chain messages; network contention cannot carry them "
                                         r"\(the relay kernel has no notion of simultaneous transmissions\)"):
        coloc_env.compose(world="circles", network="contention", backend="ukf_dcl")
