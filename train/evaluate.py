"""``coloc evaluate``: a policy's mean estimation error over seeded episodes, with a 95 % interval.

Episodes use seeds EVAL_SEED_BASE + e (disjoint from training). The metric
is the scenario's own: the sum over steps and agents of ``infos[agent]["error"]``;
communication is the per-step sum over agents of ``infos[agent]["communication"]``
(components, messages or hops, as the scenario counts it)
(the realized squared error for bandwidth_fusion, whose paper cost J_50 adds
the k = 0 term ``Scenario.initial_cost()``).
"""

from __future__ import annotations

import os

import numpy as np

from train.io import read_json, write_json
from train.training import EVAL_SEED_BASE


def run_episodes(scenario: str, policy_name: str, episodes: int, seed_base: int = EVAL_SEED_BASE,
                 progress=None, **env_config) -> dict:
    import agents
    import coloc_env

    if episodes < 2:
        raise ValueError(f"episodes must be >= 2 for a confidence interval, got {episodes}")
    env = coloc_env.parallel_env(scenario, **env_config)
    policy = agents.make_policy(policy_name, env, seed=seed_base)
    costs, comms = [], []
    for e in range(episodes):
        observations, _ = env.reset(seed=seed_base + e)
        cost, comm, steps = 0.0, 0.0, 0
        while env.agents:
            observations, _, _, _, infos = env.step(policy.act(observations))
            cost += sum(float(info["error"]) for info in infos.values())
            comm += sum(float(info.get("communication", 0.0)) for info in infos.values())
            steps += 1
        costs.append(cost)
        comms.append(comm / steps)
        if progress:
            progress()
    costs = np.array(costs)
    offset = env.scenario.initial_cost()
    half = 1.96 * costs.std(ddof=1) / np.sqrt(len(costs))
    return {
        "scenario": scenario,
        "policy": policy_name,
        "episodes": episodes,
        "seed_base": seed_base,
        "mean_cost": float(costs.mean()),
        "ci95": float(half),
        "paper_cost": float(costs.mean() + offset),
        "initial_cost": float(offset),
        "communication_per_step": float(np.mean(comms)),
    }


def save(result: dict, out: str, key: str) -> str:
    """Merge ``result`` into ``out/<key>/evaluation.json`` (atomic), keyed by policy."""
    path = os.path.join(out, key, "evaluation.json")
    table = read_json(path, default={})
    table[result["policy"]] = result
    write_json(path, table)
    return path
