"""``PRESETS["mrclam_relay"]`` names (mrclam, relay per source, ukf_se2): the preset is those parts plus its codec.

The preset (a binding on the core) draws the window offset from its episode generator itself and its losses
from its network's key (a child of that generator); the plain composition's world draws the offset from its
own child generator (in the same way, so the preset reset with that child replays the same window) and the
relay network its losses from another child's key. Handed the composition's network key, the preset gives the
composition's estimates to 1e-9 under any routing, hop budget, range limit and loss.
"""

import dataclasses
import os
import pickle

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

import agents
import coloc_env
from coloc_env.data import mrclam
from coloc_env.networks.blocks.relay_chain import STOP_REASONS
from coloc_env.networks.relay import Relay
from coloc_env.scenarios.mrclam_relay import MrclamRelayConfig, MrclamRelayScenario

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.conftest import MRCLAM_DATASET6 as DATASET6  # noqa: E402
from tests.conftest import MRCLAM_SKIP_REASON  # noqa: E402

N = mrclam.NUM_ROBOTS
needs_data = pytest.mark.skipif(not os.path.isdir(DATASET6), reason=MRCLAM_SKIP_REASON)
PRESET = coloc_env.PRESETS["mrclam_relay"]


def test_the_preset_names_its_parts_with_the_scenarios_defaults():
    assert (PRESET.world.name, PRESET.network.name, PRESET.backend.name) == ("mrclam", "relay", "ukf_se2")
    PRESET.replace()  # the three parts are compatible and valid (reads no data)
    config = MrclamRelayConfig()
    world, network, backend = PRESET.world, PRESET.network, PRESET.backend
    assert world.data is None and world.start is None and world.num_agents == N
    assert world.horizon == config.window_steps
    for field in ("dt", "noise_model", "calibration_s", "initial_position_std", "initial_heading_std"):
        assert getattr(world, field) == getattr(config, field), field
    assert network.routing == "per_source"
    for field in ("comm_range", "max_hops", "loss_at_zero", "loss_length", "hop_cost_per_m2"):
        assert getattr(network, field) == getattr(config, field), field
    assert PRESET.communication_cost == config.communication_cost  # a hop's flat price: one name, the composition's
    assert backend.ukf_lambda == config.ukf_lambda and backend.gate == config.gate


def test_the_preset_is_picklable_and_lists_without_the_data(tmp_path, monkeypatch, capsys):
    from train.cli import main

    monkeypatch.delenv(mrclam.ENV_VAR, raising=False)
    assert pickle.loads(pickle.dumps(PRESET)) == PRESET
    assert main(["list"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.strip().startswith("mrclam_relay"))
    assert line.split()[1:] == ["mrclam", "/", "relay", "/", "ukf_se2", "(coloc/mrclam_relay-v2)"]
    with pytest.raises(ValueError, match=mrclam.ENV_VAR):  # the data is read when an env is built, not before
        coloc_env.parallel_env(PRESET)


def _scenario_action(scenario, rng, noise=0.2):
    """A scenario action (N, 1 + N): whose measurement to use (a robot recorded at this step where there is one),
    then the routing table [holder, 1 + source] (0..N, N or itself = stop): each source's chain in a random order
    of the robots, a fraction ``noise`` of the entries replaced by random ones. A valid composition action."""
    recorded = scenario.world.tables.first_index[scenario.world.absolute_step()[0]] >= 0  # (N, N) [observer, subject]
    choice = np.array([rng.choice(np.flatnonzero(row)) if row.any() else rng.integers(0, N) for row in recorded])
    routing = np.full((N, N), N)
    for m in range(N):
        rest = [i for i in rng.permutation(N) if i not in (m, choice[m])]
        order = [choice[m], *rest]
        for holder, nxt in zip(order[:-1], order[1:], strict=True):
            routing[holder, m] = nxt
    routing = np.where(rng.random((N, N)) < noise, rng.integers(0, N + 1, size=(N, N)), routing)
    return np.concatenate([choice[:, None], routing], axis=1)


def _lockstep(seed, steps, scenario_fields, network_fields, inject, action_seed=5, composition_fields=None):
    """Drive the scenario and the composition of the preset's parts with the same (random) scenario actions.

    Returns per-step statistics; asserts equality (1e-9) of the estimates and covariance factors, and equality
    of the messages per holder and the team's hop cost, at every step."""
    world = dataclasses.replace(PRESET.world, data=DATASET6, horizon=steps)
    network = dataclasses.replace(PRESET.network, **network_fields)
    spec = coloc_env.compose(world=world, network=network, backend=PRESET.backend, **(composition_fields or {}))
    env = coloc_env.parallel_env(spec)
    env.reset(seed=seed)
    core = env.unwrapped.scenario
    scenario = MrclamRelayScenario(MrclamRelayConfig(data=DATASET6, window_steps=steps, **scenario_fields))
    scenario.reset([np.random.default_rng(seed).spawn(3)[0]])  # the composition's world child of the seed
    assert scenario.world.start[0] == core.world.start[0]
    if inject:  # the binding's network draws its losses from its own key: hand it the composition's
        scenario.network.keys[:] = core.network.keys
    rng = np.random.default_rng(action_seed)
    stats = {"used": 0, "stops": np.zeros(len(STOP_REASONS), int), "split_routes": 0, "cost": 0.0}
    for _ in range(steps):
        action = _scenario_action(scenario, rng)
        scenario.step(action[None])
        env.step({agent: action[i] for i, agent in enumerate(env.possible_agents)})
        backend = core.backend
        np.testing.assert_allclose(backend.estimate[0], scenario.backend.estimate[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(backend.P_ii[0], scenario.backend.P_ii[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(backend.joint_cov(0), scenario.backend.joint_cov(0), rtol=0, atol=1e-9)
        info = scenario.info()
        np.testing.assert_array_equal(core.network.messages_sent[0], info["communication"][0])
        cost = scenario.step_cost()
        np.testing.assert_allclose(core.communication_costs()[0].sum(), cost[0], rtol=1e-12, atol=0)
        stats["used"] += int(scenario.backend.used.sum())
        chains = scenario.backend.chains
        stops = chains.stop.reshape(N)
        stats["stops"] += np.bincount(stops[stops >= 0], minlength=len(STOP_REASONS))
        routes = chains.next_hop(N)  # [source, holder] the next hop each holder gave that source's chain
        for holder in range(N):
            stats["split_routes"] += len(set(routes[:, holder][routes[:, holder] >= 0].tolist())) > 1
        stats["cost"] += float(cost[0])
    return stats


@needs_data
def test_the_preset_parts_equal_the_scenario_on_its_defaults():
    """Loss-free (the preset's default): nothing to inject but the window; random partners and routing tables."""
    stats = _lockstep(seed=4, steps=150, scenario_fields={}, network_fields={}, inject=False)
    assert stats["used"] > 5, stats  # applied robot-robot measurements
    assert stats["split_routes"] > 0, stats  # chains through one holder went on to different robots
    assert stats["stops"][STOP_REASONS.index("lost")] == 0 and stats["stops"][STOP_REASONS.index("stopped")] > 0


@needs_data
def test_the_preset_parts_equal_the_scenario_given_the_networks_losses_and_hop_costs():
    links = {"loss_at_zero": 0.3, "loss_length": 12.0, "comm_range": 6.0, "max_hops": 3, "hop_cost_per_m2": 0.002}
    stats = _lockstep(seed=9, steps=150, scenario_fields={**links, "communication_cost": 0.01},
                      network_fields=links, inject=True, composition_fields={"communication_cost": 0.01})
    for reason in ("lost", "stopped", "hop_budget"):
        assert stats["stops"][STOP_REASONS.index(reason)] > 0, (reason, stats)
    assert stats["used"] > 5 and stats["split_routes"] > 0 and stats["cost"] > 0, stats


@needs_data
def test_without_the_injected_losses_the_two_differ():
    """The check above can fail: the scenario on its own loss draws loses other hops than the network."""
    links = {"loss_at_zero": 0.3}
    with pytest.raises(AssertionError, match=r"(?i)not equal"):
        _lockstep(seed=9, steps=60, scenario_fields=links, network_fields=links, inject=False)


def _network(routing, N=4, **fields):
    return Relay(loss_at_zero=0.0, routing=routing, **fields).build(N, 1, "chain")


def test_per_source_routing_follows_each_sources_entry_and_accounts_hop_costs():
    net = _network("per_source", hop_cost_per_m2=0.25)
    assert [(b.name, b.size, b.choices) for b in net.transport_blocks()] == [("next_hop", 4, 6)]
    positions = np.array([[[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [6.0, 0.0]]])
    decisions = np.full((1, 4, 4), 4)  # [batch, holder, source]; 4 = stop
    decisions[0, 1, 0] = 2  # holder 1 passes source 0's chain to 2, ...
    decisions[0, 2, 0] = 3
    decisions[0, 1, 3] = 0  # ... and source 3's chain to 0
    decisions[0, 0, 3] = 5  # then 0 passes it to the nearest not yet reached (2)
    net.begin(np.array([0]), positions, decisions)
    a = net.relay(np.array([0]), np.array([1]), lambda hop: 1.0, slot=0)
    np.testing.assert_array_equal(a.chain[0], [0, 1, 2, 3])
    b = net.relay(np.array([3]), np.array([1]), lambda hop: 1.0, slot=1)
    np.testing.assert_array_equal(b.chain[0], [3, 1, 0, 2])
    np.testing.assert_array_equal(net.messages_sent[0], [2, 2, 1, 1])
    cost = lambda d: 0.25 * d**2  # noqa: E731
    expected = [cost(1) + cost(3), cost(2) + cost(1), cost(3), cost(5)]  # hops at their holders
    np.testing.assert_allclose(net.cost_sent[0], expected, rtol=1e-12)
    net.begin(np.array([1]), positions, decisions)
    assert not net.cost_sent.any()


def test_per_holder_routing_is_the_default_and_unchanged():
    net = _network("per_holder")
    assert Relay().routing == "per_holder"
    assert [(b.name, b.size, b.choices) for b in net.transport_blocks()] == [("next_hop", 1, 6)]
    positions = np.array([[[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [6.0, 0.0]]])
    net.begin(np.array([0]), positions, np.array([[[5], [3], [4], [4]]]))  # 1 -> 3, the others stop
    np.testing.assert_array_equal(net.relay(np.array([0]), np.array([1]), lambda hop: 1.0).chain[0], [0, 1, 3, -1])
    np.testing.assert_array_equal(net.relay(np.array([2]), np.array([1]), lambda hop: 1.0).chain[0], [2, 1, 3, -1])
    assert not net.cost_sent.any()  # no hop cost by default


@pytest.mark.parametrize("field, value, message", [
    ("routing", "per_chain", r"network\.routing must be one of \('per_holder', 'per_source'\), got 'per_chain'"),
    ("hop_cost", -1.0, r"network\.hop_cost must be in \[0\.0, 1000000000000\.0\]"),
    ("hop_cost_per_m2", float("nan"), r"network\.hop_cost_per_m2"),
])
def test_bad_relay_fields_name_the_field(field, value, message):
    with pytest.raises(ValueError, match=message):
        coloc_env.compose(world="circles", network={"name": "relay", field: value}, backend="ukf_dcl")


def test_a_per_source_relay_composition_passes_the_api_and_runs():
    spec = coloc_env.compose(world="circles", network={"name": "relay", "routing": "per_source"}, backend="ukf_dcl",
                             horizon=30)
    parallel_api_test(coloc_env.parallel_env(spec), num_cycles=10)
    for policy_name in ("random", "always"):
        env = coloc_env.parallel_env(spec)
        policy = agents.make_policy(policy_name, env, seed=0)
        observations, _ = env.reset(seed=1)
        total, messages = 0.0, 0.0
        while env.agents:
            observations, rewards, _, _, infos = env.step(policy.act(observations))
            total += sum(rewards.values())
            messages += sum(infos[a]["messages_sent"] for a in env.possible_agents)
        assert np.isfinite(total) and messages > 0, (policy_name, total, messages)


@needs_data
def test_the_preset_and_its_name_build_the_same_env():
    outs = []
    for target in ("mrclam_relay", PRESET):
        env = coloc_env.parallel_env(target, data=DATASET6, window_steps=40)
        assert type(env.unwrapped.scenario) is MrclamRelayScenario  # the binding, not a composition of the parts
        policy = agents.make_policy("paper", env, seed=0)
        observations, _ = env.reset(seed=2)
        rewards_seen = []
        while env.agents:
            observations, rewards, _, _, _ = env.step(policy.act(observations))
            rewards_seen.append([rewards[a] for a in env.possible_agents])
        outs.append(np.array(rewards_seen))
    np.testing.assert_array_equal(outs[0], outs[1])
