"""Bandwidth budgets that scale: the completion-table codec and the DP decoding equal the
enumerated product of all links wherever both run (N = 2..6), and N = 16 constructs, resets and steps."""

import itertools

import numpy as np
import pytest

import coloc_env
from coloc_env.networks.bandwidth import Bandwidth
from coloc_env.networks.blocks import BandwidthBudget
from coloc_env.scenarios.bandwidth_fusion import (
    ENUMERATED_DECODE_LIMIT,
    BandwidthFusionConfig,
    BandwidthFusionScenario,
)
from tests.helpers import decode_tables

# (num_nodes, dim, budget, min_per_link, max_per_link, exact_budget): the paper's, relaxed, empty links allowed,
# and budgets at either end of their range
SETTINGS = [
    (2, 3, 2, 1, 3, True), (3, 3, 4, 1, 3, True), (4, 3, 5, 1, 3, True), (4, 3, 5, 1, 3, False),
    (4, 2, 3, 0, 2, True), (5, 3, 4, 1, 3, True), (5, 3, 7, 0, 3, False), (5, 3, 12, 1, 3, True),
    (6, 3, 8, 1, 2, True), (6, 2, 5, 0, 2, False), (3, 4, 5, 1, 4, True),
]


def enumerated_feasible(budget: BandwidthBudget) -> np.ndarray:
    """The reference listing of the budget's feasible selections (the product of all links' subsets, filtered), in
    the codec's order: exponential in N, only for small networks."""
    subsets = [np.array(bits, dtype=bool) for bits in itertools.product((0, 1), repeat=budget.dim)]
    subsets = [s for s in subsets if budget.min_per_link <= s.sum() <= budget.max_per_link]
    options = []
    for combo in itertools.product(subsets, repeat=budget.num_nodes - 1):
        total = sum(int(s.sum()) for s in combo)
        if total == budget.budget or (not budget.exact_budget and total <= budget.budget):
            options.append(np.stack(combo))
    return np.stack(options) if options else np.zeros((0, budget.num_nodes - 1, budget.dim), bool)


def _budget(setting) -> BandwidthBudget:
    budget = BandwidthBudget(*setting)
    budget.validate()
    return budget


@pytest.mark.parametrize("setting", SETTINGS)
def test_codec_lists_ranks_and_counts_the_enumerated_order(setting):
    budget = _budget(setting)
    reference = enumerated_feasible(budget)
    assert budget.size == len(reference) > 0
    np.testing.assert_array_equal(budget.feasible, reference)
    np.testing.assert_array_equal(budget.index_of(reference), np.arange(len(reference)))
    np.testing.assert_array_equal(budget.selection_at(np.arange(len(reference))), reference)
    assert np.all(budget.is_feasible(reference))


@pytest.mark.parametrize("setting", SETTINGS)
def test_best_selection_is_the_enumerated_argmax_with_its_ties(setting):
    """Generic scores, dyadic scores (exact sums, many exact ties) and all-zero scores (every selection ties:
    the first) decode to feasible[argmax(scores . feasible)], the first maximizer in the fixed order."""
    budget = _budget(setting)
    reference = enumerated_feasible(budget)
    flat = reference.reshape(len(reference), -1).astype(float)
    rng = np.random.default_rng(sum(setting[:5]))
    shape = (40, budget.num_nodes - 1, budget.dim)
    for scores in (rng.uniform(-1, 1, shape), rng.integers(-2, 3, shape) / 2.0, np.zeros(shape)):
        expected = reference[np.argmax(scores.reshape(len(scores), -1) @ flat.T, axis=-1)]
        np.testing.assert_array_equal(budget.best_selection(scores), expected)


def test_infeasible_selections_rank_minus_one_and_bad_indices_are_refused():
    budget = _budget((5, 3, 7, 1, 3, True))
    chosen = budget.selection_at(np.array([0, 5, budget.size - 1]))
    too_many = chosen.copy()
    too_many[:, 0] = True  # link 0 full: the total exceeds the budget unless it was full already
    empty_link = chosen.copy()
    empty_link[:, 1] = False  # below min_per_link
    assert np.all(budget.index_of(empty_link) == -1)
    np.testing.assert_array_equal(budget.index_of(too_many) == -1, too_many.sum(axis=(-1, -2)) != 7)
    with pytest.raises(ValueError, match=r"selection index must be in \[0, "):
        budget.selection_at(np.array([budget.size]))


@pytest.mark.parametrize("num_agents, budget", [(4, 5), (5, 6), (6, 7)])
def test_scenario_decodes_like_the_enumerated_argmax(num_agents, budget):
    """108 and 594 selections decode by the listed argmax, 2,835 (above ENUMERATED_DECODE_LIMIT) by the
    dynamic programme: both are the reference argmax, on generic and on tied (dyadic) scores."""
    config = BandwidthFusionConfig(num_agents=num_agents, budget=budget)
    scenario = BandwidthFusionScenario(config, batch=3)
    assert (scenario._feasible is None) == (scenario.links.size > ENUMERATED_DECODE_LIMIT)
    reference = enumerated_feasible(scenario.links)
    flat = reference.reshape(len(reference), -1).astype(float)
    rng = np.random.default_rng(3)
    shape = (3, num_agents, scenario.action_dim)
    for actions in (rng.uniform(-1.2, 1.2, shape), rng.integers(-2, 3, shape) / 2.0):
        selection, _ = decode_tables(scenario, actions)
        scores = np.clip(actions, -1, 1)[..., : (num_agents - 1) * 3]
        np.testing.assert_array_equal(selection, reference[np.argmax(scores @ flat.T, axis=-1)])


def test_sixteen_uavs_construct_reset_step_and_round_trip_their_actions():
    budget = 25  # (N-1) min_per_link = 15 .. (N-1) max_per_link = 45
    env = coloc_env.parallel_env("bandwidth_fusion", num_agents=16, budget=budget)
    env.reset(seed=0)
    scenario = env.unwrapped.scenario
    assert scenario.links.size > 10**11  # what enumeration could not list
    rng = np.random.default_rng(0)
    selection = scenario.links.selection_at(rng.integers(0, scenario.links.size, size=16))
    weights = np.full((16, 16), 1.0 / 16)
    actions = scenario.encode_actions(selection, weights)
    decoded, decoded_weights = decode_tables(scenario, actions[None])
    np.testing.assert_array_equal(decoded[0], selection)
    np.testing.assert_allclose(decoded_weights[0], weights, atol=1e-12)
    observations, rewards, *_ = env.step({a: actions[i] for i, a in enumerate(env.possible_agents)})
    assert np.all(scenario.links.components_received(scenario.selection) == budget)
    assert all(np.isfinite(r) for r in rewards.values())

    vec = coloc_env.vector_env("bandwidth_fusion", num_envs=4, seed=1, num_agents=16, budget=budget)
    vec.reset()
    vec.step(np.random.default_rng(2).uniform(-1, 1, (vec.num_envs, *vec.action_space.shape)))
    assert np.all(vec.scenario.links.is_feasible(vec.scenario.selection))


def test_network_counts_without_listing_and_names_the_limit():
    links = Bandwidth(budget=5).budget_for(4, 3)
    assert links.size == 108
    with pytest.raises(ValueError, match=r"network\.budget: 16 agents x 3 components give \d+ feasible selections, "
                                         r"more than 100000 \(a Discrete action\)"):
        Bandwidth(budget=25).budget_for(16, 3)


def test_greedy_refuses_a_search_it_cannot_finish():
    from agents.bandwidth_fusion import greedy_selection

    scenario = BandwidthFusionScenario(BandwidthFusionConfig(num_agents=16, budget=25), batch=1)
    with pytest.raises(ValueError, match="greedy scores every feasible selection: .* more than 4096"):
        greedy_selection(scenario, np.full((1, 16, 16), 1.0 / 16))
