"""``coloc evaluate``: a policy's mean estimation error over seeded episodes, with a 95 % interval.

Seeds (documented once, used everywhere):

* training: seed S seeds the network and copy c of the training env with S + c
  (small integers);
* learning curves during training: VALIDATION_SEED_BASE + e;
* ``coloc evaluate``: EVAL_SEED_BASE + e.

The three ranges are disjoint, so no policy is evaluated on a training seed
and nothing is tuned on the evaluation seeds.

The metric is the scenario's own, ``Scenario.episode_error`` of every step's
``infos[agent][Scenario.metric_error_key]`` (``"error"`` except where the paper samples
its error elsewhere in the step: relay_ukf's ``"posterior_error"``; by default the sum
over steps and agents); communication is the per-step sum over agents of
``infos[agent]["communication"]`` (components, messages or hops, as the
scenario counts it). ``paper_cost`` adds ``Scenario.initial_cost()``, the
part of a paper's cost an episode does not contain (bandwidth_fusion's k = 0
term).
"""

from __future__ import annotations

import numpy as np

EVAL_SEED_BASE = 10**6
VALIDATION_SEED_BASE = 2 * 10**6


def summarize(scenario, policy_name: str, costs, comms, seed_base: int, initial_cost: float) -> dict:
    costs = np.asarray(costs, float)
    half = 1.96 * costs.std(ddof=1) / np.sqrt(len(costs)) if len(costs) > 1 else float("nan")
    return {
        "scenario": scenario,
        "policy": policy_name,
        "episodes": len(costs),
        "seed_base": seed_base,
        "mean_cost": float(costs.mean()),
        "ci95": float(half),
        "paper_cost": float(costs.mean() + initial_cost),
        "initial_cost": float(initial_cost),
        "communication_per_step": float(np.mean(comms)),
    }


def evaluate_policy(scenario: str, policy_name: str, episodes: int, seed_base: int = EVAL_SEED_BASE,
                    progress=None, stochastic: bool = False) -> dict:
    """A trained model (``.zip``) on the batched core, any other policy through the PettingZoo env.

    The two paths give the same episodes (``vector_env`` equals ``parallel_env``
    copy for copy; a test checks the costs agree); the batched one runs every
    episode in one call per step. ``stochastic``: a model samples its actions
    (torch seeded with ``seed_base``) and is recorded as ``PATH.zip (stochastic)``.
    """
    if not policy_name.endswith(".zip"):
        return run_episodes(scenario, policy_name, episodes, seed_base, progress)
    import agents
    import coloc_env

    if episodes < 2:
        raise ValueError(f"episodes must be >= 2 for a confidence interval, got {episodes}")
    policy = agents.make_policy(policy_name, coloc_env.parallel_env(scenario))  # checks scenario and spaces
    result = run_model_batched(policy.model, scenario, episodes, seed_base, deterministic=not stochastic)
    if progress:
        for _ in range(episodes):
            progress()
    return dict(result, policy=policy_name + (" (stochastic)" if stochastic else ""))


def run_episodes(scenario: str, policy_name: str, episodes: int, seed_base: int = EVAL_SEED_BASE,
                 progress=None, **env_config) -> dict:
    """Any policy by name through the PettingZoo env, one episode per seed ``seed_base + e``."""
    import agents
    import coloc_env

    if episodes < 2:
        raise ValueError(f"episodes must be >= 2 for a confidence interval, got {episodes}")
    env = coloc_env.parallel_env(scenario, **env_config)
    policy = agents.make_policy(policy_name, env, seed=seed_base)
    error_key, weight_key = env.scenario.metric_error_key, env.scenario.metric_weight_key
    costs, comms = [], []
    for e in range(episodes):
        observations, _ = env.reset(seed=seed_base + e)
        errors, weights, comm = [], [], 0.0
        while env.agents:
            observations, _, _, _, infos = env.step(policy.act(observations))
            errors.append([float(infos[a][error_key]) for a in env.possible_agents])
            if weight_key:
                weights.append([float(infos[a][weight_key]) for a in env.possible_agents])
            comm += sum(float(info.get("communication", 0.0)) for info in infos.values())
        costs.append(float(env.scenario.episode_error(np.array(errors), np.array(weights) if weight_key else None)))
        comms.append(comm / len(errors))
        if progress:
            progress()
    return summarize(scenario, policy_name, costs, comms, seed_base, env.scenario.initial_cost())


def run_model_batched(model, scenario: str, episodes: int, seed_base: int, deterministic: bool = True,
                      **env_config) -> dict:
    """An SB3 model on ``episodes`` copies of the batched core at once (copy e seeded ``seed_base + e``).

    Steps the scenario core directly rather than the VecEnv, whose auto-reset
    would discard the last step's infos. Deterministic actions by default; sampled
    ones (``deterministic=False``) draw from torch's generator, seeded here with
    ``seed_base`` so that the run repeats.
    """
    if not deterministic:
        import torch

        torch.manual_seed(seed_base)
    import coloc_env
    from coloc_env.config import build_config

    cls = coloc_env.scenario_class(scenario)
    core = cls(build_config(cls.Config, env_config), batch=episodes)
    core.reset([np.random.default_rng(seed_base + e) for e in range(episodes)])
    shape = core.action_space().shape
    errors, weights, comm = [], [], np.zeros(episodes)
    while not core.done().all():
        observation = core.observation()
        actions, _ = model.predict(observation.reshape(episodes * core.num_agents, *observation.shape[2:]),
                                   deterministic=deterministic)
        core.step(np.asarray(actions, dtype=float).reshape(episodes, core.num_agents, *shape))
        info = core.info()
        errors.append(info[core.metric_error_key])
        if core.metric_weight_key:
            weights.append(info[core.metric_weight_key])
        comm += info["communication"].sum(axis=-1) if "communication" in info else 0.0
    # (episodes, T, N) -> (episodes,)
    cost = core.episode_error(np.stack(errors, axis=1), np.stack(weights, axis=1) if weights else None)
    return summarize(scenario, "model", cost, comm / len(errors), seed_base, core.initial_cost())
