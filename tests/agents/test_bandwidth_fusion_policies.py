"""Policies of bandwidth_fusion: paper, random, greedy, oracle_static, trained models."""

import numpy as np
import pytest

import agents
import coloc_env
import estimators.bandwidth_fusion as bf
from agents.bandwidth_fusion import advance_tables, coordinate_descent, greedy_selection
from estimators.bandwidth_fusion import paper_selection, paper_weights
from tests.helpers import decode_tables

NAME = "bandwidth_fusion"
M0 = np.diag([0.19, 0.09, 0.08])


def test_make_policy_refuses_unknown_names_and_tables():
    env = coloc_env.parallel_env(NAME)
    with pytest.raises(ValueError, match="unknown policy"):
        agents.make_policy("clever", env)
    with pytest.raises(ValueError, match="T1P1"):
        agents.make_policy("paper:T9", env)
    with pytest.raises(ValueError, match="does not exist"):
        agents.make_policy("/nonexistent/model.zip", env)


def test_paper_policy_decodes_to_the_printed_tables():
    env = coloc_env.parallel_env(NAME)
    for t in ("T1", "T2", "T3"):
        for p in ("P1", "P2", "P3"):
            policy = agents.make_policy(f"paper:{t}{p}", env)
            observations, _ = env.reset(seed=0)
            actions = policy.act(observations)
            sel, w = decode_tables(env.scenario, np.stack([actions[a] for a in env.possible_agents])[None])
            np.testing.assert_array_equal(env.scenario.links.full_selection(sel[0]), paper_selection(t))
            np.testing.assert_allclose(w[0], paper_weights(p), atol=1e-15)
            assert all(env.action_space(a).contains(actions[a]) for a in actions)


def test_random_policy_is_reproducible_from_its_seed():
    env = coloc_env.parallel_env(NAME)
    observations, _ = env.reset(seed=0)
    a1 = agents.make_policy("random", env, seed=3).act(observations)
    a2 = agents.make_policy("random", env, seed=3).act(observations)
    a3 = agents.make_policy("random", env, seed=4).act(observations)
    assert all(np.array_equal(a1[k], a2[k]) for k in a1)
    assert not all(np.array_equal(a1[k], a3[k]) for k in a1)


def test_greedy_choice_minimizes_each_receivers_next_trace():
    env = coloc_env.parallel_env(NAME)
    env.reset(seed=0)
    scenario = env.scenario
    weights = paper_weights("P1")
    for _ in range(3):  # move away from the symmetric initial state
        advance_tables(scenario, scenario.links.relative_selection(paper_selection("T3"))[None], weights[None])
    chosen = greedy_selection(scenario, weights[None])[0]
    gain = bf.gains(scenario.backend.model, scenario.fusion.bound[0])
    base = scenario.links.relative_selection(paper_selection("T1"))
    for i in range(4):
        def trace_if(option, i=i):
            rel = base.copy()
            rel[i] = option
            nxt = bf.exact_covariance_step(scenario.backend.model, scenario.fusion.error_cov[0], gain,
                                           scenario.links.full_selection(rel), weights)
            return bf.node_traces(nxt, 4)[i]
        best = min(trace_if(opt) for opt in scenario.links.feasible)
        assert trace_if(chosen[i]) == pytest.approx(best, abs=1e-14)


def test_greedy_beats_the_paper_tables_in_exact_cost():
    from train.reproduce.zhao2020 import greedy_exact_curve

    config = coloc_env.parallel_env(NAME).config
    greedy = greedy_exact_curve(config).sum()
    exact, _ = bf.expected_cost(config.fusion_model(), M0, paper_selection("T1"), paper_weights("P1"), 50)
    assert greedy < exact.sum()


def test_coordinate_descent_ends_in_a_local_optimum():
    env = coloc_env.parallel_env(NAME)
    scenario = env.scenario
    weights = paper_weights("P1")
    horizon = 8
    start = paper_selection("T2")
    selection, cost, sweeps, evaluations, history = coordinate_descent(
        scenario.backend.model, scenario.links, M0, weights, start, horizon)
    start_cost = bf.expected_cost(scenario.backend.model, M0, start, weights, horizon)[0].sum()
    assert history[0] == pytest.approx(start_cost, rel=1e-12)
    assert cost <= start_cost and all(np.diff(history) <= 0)
    assert cost == pytest.approx(bf.expected_cost(scenario.backend.model, M0, scenario.links.full_selection(selection),
                                                  weights, horizon)[0].sum(), rel=1e-12)
    # no single receiver can improve alone
    for i in range(4):
        for option in scenario.links.feasible:
            trial = selection.copy()
            trial[i] = option
            trial_cost = bf.expected_cost(scenario.backend.model, M0, scenario.links.full_selection(trial), weights,
                                          horizon)[0].sum()
            assert trial_cost >= cost * (1 - 1e-9)
    assert evaluations == 1 + 108 * 4 * sweeps


def _fake_search(calls):
    def search(scenario):
        calls.append(scenario.config)
        return [{"start": t, "weights": p, "selection": paper_selection(t)[:, 1:].tolist(), "cost": 10.0 + i,
                 "sweeps": 1, "evaluations": 1, "history": [10.0 + i]}
                for i, (p, t) in enumerate((p, t) for p in ("P1", "P2", "P3") for t in ("T1", "T2", "T3"))]
    return search


def test_oracle_static_search_is_read_from_the_disk_cache_once_stored(tmp_path, monkeypatch):
    """The search runs once per scenario config and cache folder: a process that has not run it (the in-process
    cache emptied) reads the stored results, the best first; another config is another entry."""
    from agents import bandwidth_fusion as policies

    calls = []
    monkeypatch.setenv("COLOC_FIT_CACHE", str(tmp_path))
    monkeypatch.setattr(policies, "_search", _fake_search(calls))
    monkeypatch.setattr(policies, "_SEARCH_CACHE", {})
    scenario = coloc_env.parallel_env(NAME).scenario
    first = policies.oracle_static_search(scenario)
    policies._SEARCH_CACHE.clear()
    second = policies.oracle_static_search(scenario)
    assert len(calls) == 1 and len(list(tmp_path.glob("bandwidth-fusion-oracle-static-*.json"))) == 1
    assert [(r.start, r.weights, r.cost) for r in second] == [(r.start, r.weights, r.cost) for r in first]
    assert (second[0].start, second[0].weights, second[0].cost) == ("T1", "P1", 10.0)
    assert second[0].selection.dtype == bool and second[0].selection.shape == (4, 3, 3)
    policies.oracle_static_search(coloc_env.parallel_env(NAME, horizon=20).scenario)
    assert len(calls) == 2 and len(list(tmp_path.glob("bandwidth-fusion-oracle-static-*.json"))) == 2


def test_the_shipped_oracle_static_search_is_current():
    """The tests read the default scenario's oracle_static search from tests/data/fit_cache (conftest), or each
    worker searches for about 13 s. When this fails the search's code changed: run this file's tests once (they
    write the new entry there), commit it and delete the stale one."""
    from agents import bandwidth_fusion as policies
    from coloc_env.data import fit_cache
    from tests.conftest import SHIPPED_FIT_CACHE

    key = policies._search_key(coloc_env.parallel_env(NAME).scenario)
    path = fit_cache.entry_path(SHIPPED_FIT_CACHE, "bandwidth-fusion-oracle-static", key)
    assert fit_cache.read(path, key, policies._sound_search) is not None, f"no current entry {path}"


def test_sb3_model_loads_only_for_matching_spaces(tmp_path):
    from train.training import train

    path = train(NAME, timesteps=256, seed=0, out=str(tmp_path), progress_bar=False)
    env = coloc_env.parallel_env(NAME)
    policy = agents.make_policy(path, env)
    observations, _ = env.reset(seed=0)
    actions = policy.act(observations)
    assert set(actions) == set(env.possible_agents)
    assert all(env.action_space("uav_0").shape == a.shape for a in actions.values())
    with pytest.raises(ValueError, match="space"):
        agents.make_policy(path, coloc_env.parallel_env(NAME, num_agents=3, budget=4))
