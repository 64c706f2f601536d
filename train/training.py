"""``coloc train``: PPO with parameter sharing over a scenario's agents, read top to bottom.

Training seeds: seed S seeds torch and numpy (network, sampling) and copy c
of the environment with S + c, c < NUM_COPIES. Learning curves evaluate on
the validation seeds and ``coloc evaluate`` on the evaluation seeds of
``train.evaluate``; neither range overlaps the training seeds.

Writes ``OUT/SCENARIO/seedS/``: ``model.zip`` (+ ``model.json``: scenario,
config, ``cost_range``, spaces, which checkpoint it is), the best checkpoint on the validation seeds (its
point of the learning curve has the lowest validation score; the last weights where there is no
curve), ``best.zip`` and ``last.zip`` (the final weights), ``checkpoint.zip`` (replaced atomically as training goes),
``curve.json`` and ``learning_curve.png`` (validation score vs timesteps, each point with its 95 % interval,
the paper policy's level and interval as a line and band).

Cost conditioning. With a cost range (``--cost-range lo,hi``, else the settings module's ``COST_RANGE``) the
training env is built with ``cost_range=(lo, hi)``: each copy draws its episode's communication cost at reset
(log-uniform for lo > 0, ``coloc_env.composition``) and every agent observes it, so one network learns every
price. The validation score of a learning-curve point is then

    score = (1 / |C|) sum_{c in C} mean_e [ error_e(c) + c * m_e(c) ],

C = ``validation_costs(lo, hi)``: the cost law's quantiles at 1/6, 1/2 and 5/6 (the centres of its thirds; one
cost where lo = hi), error_e(c) the scenario's own per-episode metric and m_e(c) the communication per
agent-step (``communication_per_step / N``: messages for a composition) of validation episode e played in an
env built with ``communication_cost=c``: the frontier's two axes priced at c, for a composition the negative
mean reward under ``reward="error"``. The 95 % interval is over the episodes of the per-episode mean over C.
Without a cost range a point's score is the validation error, played at the training env's
``communication_cost`` (the cost the model observes). Either way the validation episodes are seeded
``VALIDATION_SEED_BASE + e`` (``train.evaluate``), disjoint from the training seeds and the evaluation seeds.
Under a cost range a settings module's ``COST_FEATURE = "scaled"`` makes the network read the observed cost as its
place in [lo, hi] (``agents.cost_feature.CostScaledExtractor``, the model's features extractor, saved with it);
``model.json`` records ``cost_feature``.

Paper entries. A settings module's ``PAPER_ENTRIES`` (``--paper-entries``) names action entries the model leaves to
the paper's rule (``agents.paper_entries``; relay_ukf's ``"partner"``: the paper's random ranging partner;
mrclam_relay's ``"measurement"``: the paper's measurement choice): the
training env fills them before each step and masks them to one choice (``paper_entries_env``), validation and
evaluation fill them as the paper's policy does on the same episode, and ``model.json`` records the name.

Sampled actions. A settings module's ``ACTIONS = "sampled"`` (``train.hyperparams.ACTIONS``) makes the model a
random-access policy: the learning curve scores it with sampled actions (torch seeded with the validation seed
base, as ``train.evaluate.run_model_batched`` does), ``model.json`` records ``"actions": "sampled"``, and
evaluation samples its actions too (``train.evaluate.model_actions``).
"""

from __future__ import annotations

import json
import os
import sys
import textwrap

import numpy as np

from coloc_env.config import BadInput
from train.io import copy_file, save_model, write_json
from train.leaderboard import metric

MAX_TRAINING_SEED = 10**5  # keeps S + c far below the validation and evaluation seed ranges
CURVE_POINTS = 10
DEFAULT_TIMESTEPS = 200_000  # a scenario's budget where its hyperparameter module sets no TIMESTEPS
CURVE_EPISODES = 16


def _mark_truncation_wrapper():
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class MarkTruncation(VecEnvWrapper):
        """Adds ``TimeLimit.truncated = True`` where SuperSuit reports an episode end.

        SuperSuit's MarkovVectorEnv stores ``terminal_observation`` but merges
        truncation into ``dones`` without the flag, so SB3 would treat the
        horizon as a terminal state and not bootstrap its value. coloc's
        episodes end only by truncation, so every end is marked.
        """

        def get_attr(self, attr_name, indices=None):
            # SB3's VecEnv constructor asks for render_mode through get_attr; SuperSuit's SB3 wrapper forwards
            # get_attr to its ConcatVecEnv, which has none, so SB3 would warn that render_mode is not defined.
            if attr_name == "render_mode":
                return [self.venv.render_mode for _ in self._get_indices(indices)]
            return self.venv.get_attr(attr_name, indices)

        def reset(self):
            return self.venv.reset()

        def step_wait(self):
            observations, rewards, dones, infos = self.venv.step_wait()
            for info in infos:
                if "terminal_observation" in info:
                    info["TimeLimit.truncated"] = True
            return observations, rewards, dones, infos

    return MarkTruncation


def mark_truncation(venv):
    """``venv``, a SuperSuit SB3 vec env, with every episode end flagged ``TimeLimit.truncated = True`` (so
    that PPO bootstraps the value of the last observation: coloc's episodes end only at the horizon)."""
    return _mark_truncation_wrapper()(venv)


def _cost_balanced_reward_wrapper():
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class CostBalancedReward(VecEnvWrapper):
        """Divides each step's reward by 1 + c / ``reference``, c the communication cost of the episode the step
        belongs to (the ``communication_cost`` feature of the observation the action was taken on).

        The factor is constant over an episode and the policy observes c, so for every cost the optimal policy is
        the unscaled reward's; what changes is the share of the gradient. Unscaled, an episode priced at c = 50
        has returns tens of times larger than one priced at 0.05, so its advantages set the per-batch
        normalization and the cheap episodes barely move the policy.
        """

        def __init__(self, venv, cost_index: int, reference: float):
            super().__init__(venv)
            self.cost_index = int(cost_index)
            self.reference = float(reference)
            self._costs = np.zeros(venv.num_envs)

        def reset(self):
            observations = self.venv.reset()
            self._costs = np.array(observations[:, self.cost_index], dtype=np.float64)
            return observations

        def step_wait(self):
            observations, rewards, dones, infos = self.venv.step_wait()
            # the cost of the step's own episode: after an episode ends, the observation is the next one's
            scaled = (rewards / (1.0 + self._costs / self.reference)).astype(rewards.dtype)
            self._costs = np.array(observations[:, self.cost_index], dtype=np.float64)
            return observations, scaled, dones, infos

    return CostBalancedReward


def cost_balanced_reward(venv, cost_index: int, reference: float):
    """``venv`` with each step's reward divided by 1 + c / ``reference`` (c: the episode's communication cost,
    read from observation entry ``cost_index``; ``reference`` > 0, in the metric's units per message): the
    settings module's ``COST_REWARD_SCALE``, for cost-conditioned training (the wrapper's docstring says why)."""
    if not np.isfinite(reference) or reference <= 0:
        raise BadInput(f"COST_REWARD_SCALE must be a finite number > 0 (metric units per message), got {reference!r}")
    return _cost_balanced_reward_wrapper()(venv, cost_index, reference)


def _paper_entries_wrapper():
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class PaperEntries(VecEnvWrapper):
        """Fills the action entries a model leaves to the paper's rule before the env receives the actions, and
        leaves those entries one choice in the action masks (``agents.paper_entries``: ``entries``,
        ``restrict``). Sub-envs are ordered copy by copy, agent by agent, as ``coloc_env.vector_env`` orders them;
        the draws come from one generator seeded by the training seed."""

        def __init__(self, venv, paper, num_agents: int, rng: np.random.Generator):
            super().__init__(venv)
            self.paper, self.num_agents, self.rng = paper, int(num_agents), rng
            self._observations = None

        def reset(self):
            self._observations = self.venv.reset()
            return self._observations

        def step_async(self, actions):
            actions = np.asarray(actions)
            copies = len(actions) // self.num_agents
            observed = self._observations.reshape(copies, self.num_agents, -1)
            filled = self.paper.entries(self.rng, observed, actions.reshape(copies, self.num_agents, -1))
            self.venv.step_async(filled.reshape(actions.shape).astype(actions.dtype))

        def step_wait(self):
            observations, rewards, dones, infos = self.venv.step_wait()
            self._observations = observations  # after an auto-reset: the next episode's, which the next action sees
            return observations, rewards, dones, infos

        def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
            if method_name != "action_masks":
                return self.venv.env_method(method_name, *method_args, indices=indices, **method_kwargs)
            masks = self.paper.restrict(np.stack(self.venv.env_method("action_masks")), self.num_agents)
            return [masks[i] for i in self._get_indices(indices)]

    return PaperEntries


# the second word of the training generator of paper entries, [training seed, PAPER_ENTRIES_STREAM]
PAPER_ENTRIES_STREAM = 0x50A9E5


def paper_entries_env(venv, paper, num_agents: int, seed: int):
    """``venv`` (``coloc_env.vector_env``) whose actions get ``paper``'s entries (``agents.paper_entries``) drawn
    from ``default_rng([seed, PAPER_ENTRIES_STREAM])`` and whose action masks leave those entries one choice."""
    return _paper_entries_wrapper()(venv, paper, num_agents, np.random.default_rng([int(seed), PAPER_ENTRIES_STREAM]))


def make_supersuit_vec_env(scenario: str, copies: int, env_config: dict):
    """B copies x N agents as one SB3 VecEnv through SuperSuit (each agent a sub-env)."""
    import supersuit as ss

    import coloc_env

    env = coloc_env.parallel_env(scenario, **env_config)
    venv = ss.pettingzoo_env_to_vec_env_v1(env)
    return mark_truncation(ss.concat_vec_envs_v1(venv, copies, num_cpus=0, base_class="stable_baselines3"))


def seed_supersuit_vec_env(venv, seed: int) -> None:
    """Copy c of a SuperSuit SB3 vec env starts its next ``reset()`` as if seeded ``seed + c``.

    SuperSuit's SB3 wrapper forwards ``seed()`` to ``ConcatVecEnv``, which has
    none, and its ``reset()`` passes no seed, so the copies' generators are set
    directly: both vectorizations then start from the same episodes.
    """
    for c, markov_env in enumerate(venv.venv.venv.vec_envs):
        markov_env.par_env.seed_generator(seed + c)


def make_vec_env(scenario: str, copies: int, env_config: dict, seed: int, vec: str = "native"):
    """The training VecEnv: the native batched ``vector_env`` (default) or SuperSuit's, seeded alike."""
    import coloc_env

    if vec == "native":
        return coloc_env.vector_env(scenario, num_envs=copies, seed=seed, **env_config)
    if vec == "supersuit":
        venv = make_supersuit_vec_env(scenario, copies, env_config)
        seed_supersuit_vec_env(venv, seed)
        return venv
    raise BadInput(f"vec must be 'native' or 'supersuit', got {vec!r}")


VALIDATION_COST_QUANTILES = (1 / 6, 1 / 2, 5 / 6)


def validation_costs(cost_range: tuple[float, float]) -> list[float]:
    """The fixed costs a cost-conditioned model is validated at: the quantiles ``VALIDATION_COST_QUANTILES`` of
    ``cost_range``'s law (``coloc_env.composition.draw_costs``: log-uniform for lo > 0, uniform on [0, hi] for
    lo = 0); the one cost lo where lo = hi."""
    lo, hi = float(cost_range[0]), float(cost_range[1])
    if lo == hi:
        return [lo]
    if lo > 0:
        return [float(np.exp(np.log(lo) + q * (np.log(hi) - np.log(lo)))) for q in VALIDATION_COST_QUANTILES]
    return [q * hi for q in VALIDATION_COST_QUANTILES]


def priced_score(rows: dict, num_agents: int) -> dict:
    """The validation score of the module docstring from ``rows`` {cost c: the result row played at c on the same
    episodes}: per episode, the mean over the costs of error + c * communication per agent-step; its mean and 95 %
    interval, with each cost's error and communication per agent-step beside them."""
    from train.evaluate import mean_ci95

    per_episode = np.mean([np.asarray(row["per_episode_cost"], float)
                           + c * np.asarray(row["per_episode_communication"], float) / num_agents
                           for c, row in rows.items()], axis=0)
    mean, half = mean_ci95(per_episode)
    return {"mean_cost": mean, "ci95": half,
            "at_costs": [{"cost": c, "mean_cost": row["mean_cost"],
                          "messages_per_agent_step": row["communication_per_step"] / num_agents}
                         for c, row in rows.items()]}


def observed_cost(env_config: dict) -> dict:
    """The part of a training env config that a fixed-cost model observes and is validated at: its
    ``communication_cost`` (the scenario's default where it sets none); nothing else of the training config
    enters the validation env, which is the evaluation env."""
    return {"communication_cost": env_config["communication_cost"]} if "communication_cost" in env_config else {}


def validate(run, scenario: str, env_config: dict, cost_range, num_agents: int) -> dict:
    """One validation result {``mean_cost``, ``ci95``, ...} by the module docstring's score: ``run(**config)``
    plays the validation episodes in an env built with ``config`` and returns the result row."""
    if cost_range is None:
        return run(**observed_cost(env_config))
    return priced_score({c: run(communication_cost=c) for c in validation_costs(cost_range)}, num_agents)


def _callbacks(scenario: str, folder: str, timesteps: int, curve: list, points: int, episodes: int, report=None,
               env_config: dict | None = None, cost_range=None, num_agents: int = 1, at_costs: list | None = None,
               paper=None, deterministic: bool = True):
    from stable_baselines3.common.callbacks import BaseCallback

    from train.evaluate import VALIDATION_SEED_BASE, run_model_batched

    class CheckpointAndCurve(BaseCallback):
        """An atomic checkpoint and a validation point of the learning curve every
        ``timesteps / points`` timesteps, and at most once per rollout (a budget smaller than one
        rollout would otherwise record on every vectorized step)."""

        def __init__(self):
            super().__init__()
            self.at_costs = [] if at_costs is None else at_costs
            self.next_at = 0
            self.every = 1
            self.best: tuple[float, int] | None = None  # (validation mean cost, timesteps) of best.zip

        def _on_training_start(self) -> None:
            rollout = self.model.n_steps * self.model.get_env().num_envs
            self.every = max(timesteps // max(points, 1), rollout)

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.next_at:
                self.next_at = self.num_timesteps + self.every
                self._record()
            return True

        def _on_training_end(self) -> None:
            if points and (not curve or curve[-1][0] != self.num_timesteps):
                self._record()

        def _record(self) -> None:
            save_model(os.path.join(folder, "checkpoint.zip"), self.model)
            if points:
                result = validate(lambda **config: run_model_batched(self.model, scenario, episodes,
                                                                     VALIDATION_SEED_BASE, paper_entries=paper,
                                                                     deterministic=deterministic, **config),
                                  scenario, env_config or {}, cost_range, num_agents)
                curve.append((int(self.num_timesteps), result["mean_cost"], result["ci95"]))
                if "at_costs" in result:
                    self.at_costs.append(result["at_costs"])
                # the best point on the validation seeds is the model that is kept (never the evaluation seeds)
                better = self.best is None or result["mean_cost"] < self.best[0]
                if better:
                    save_model(os.path.join(folder, "best.zip"), self.model)
                    self.best = (float(result["mean_cost"]), int(self.num_timesteps))
                if report is not None:
                    unit = metric(scenario)[1]
                    what = "error" if cost_range is None else "score (error + cost x messages)"
                    report(f"{self.num_timesteps:,} timesteps (budget {timesteps:,}): validation {what} "
                           f"{result['mean_cost']:.4g} +- {result['ci95']:.3g} {unit} ({episodes} episodes)"
                           + (", the best so far" if better else ""))

    return CheckpointAndCurve()


def curve_reference(scenario: str) -> str:
    """The fixed policy a learning curve is drawn against: the paper's policy, or for a composition (no paper
    ran it) the first of its baselines, ``always``."""
    import agents
    import coloc_env

    return agents.COMPOSITION_BASELINES[0] if coloc_env.is_composition_name(scenario) else "paper"


def _play(scenario: str, policy: str, episodes: int, seed_base: int, **env_config) -> dict:
    """A named policy's result row on episodes ``seed_base + e`` in an env built with ``env_config`` (batched
    where the policy batches)."""
    from train.evaluate import run_episodes, run_policy_batched

    row = run_policy_batched(scenario, policy, episodes, seed_base, **env_config)
    return row if row is not None else run_episodes(scenario, policy, episodes, seed_base, **env_config)


def write_learning_curve(folder: str, scenario: str, curve: list, title: str, episodes: int = CURVE_EPISODES,
                         env_config: dict | None = None, cost_range=None, at_costs: list | None = None,
                         acting: str = "deterministic") -> None:
    """``curve.json`` and ``learning_curve.png`` with the paper policy (a composition: ``always``) on the same
    validation seeds, scored alike (the module docstring: with a cost range, priced at the validation costs)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import coloc_env
    from train.evaluate import VALIDATION_SEED_BASE
    from train.io import save_figure

    reference = curve_reference(scenario)
    num_agents = coloc_env.make_core(scenario, batch=1).num_agents
    paper = validate(lambda **config: _play(scenario, reference, episodes, VALIDATION_SEED_BASE, **config),
                     scenario, env_config or {}, cost_range, num_agents)
    points = [{"timesteps": t, "mean_cost": c, "ci95": h} for t, c, h in curve]
    for point, priced in zip(points, at_costs or [], strict=False):
        point["at_costs"] = priced
    content = {"scenario": scenario, "validation_seed_base": VALIDATION_SEED_BASE, "episodes": episodes,
               "points": points, reference: {"mean_cost": paper["mean_cost"], "ci95": paper["ci95"]}}
    name, unit = metric(scenario)
    if cost_range is not None:
        costs = validation_costs(cost_range)
        content.update(cost_range=list(cost_range), validation_costs=costs,
                       score="mean over validation_costs c of (error + c * communication per agent-step)")
        name = f"{name} + cost x messages, mean over costs {', '.join(f'{c:.3g}' for c in costs)}"
    write_json(os.path.join(folder, "curve.json"), content)
    unit = unit.replace("^2", "\u00b2")
    fig, ax = plt.subplots(figsize=(7.5, 4.8), layout="constrained")
    steps, costs, half = (np.array(v, dtype=float) for v in zip(*curve, strict=True))
    n = episodes
    # a few validation points: each its own 95 % interval (an error bar), not a band interpolated between them
    ax.errorbar(steps, costs, yerr=half, fmt="o-", color="tab:blue", capsize=4, ms=6,
                label=f"trained policy ({acting}): mean and 95 % interval over {n} validation episodes")
    p_mean, p_half = float(paper["mean_cost"]), float(paper["ci95"])
    ax.axhline(p_mean, color="k", ls="--", label=f"{reference} policy on the same {n} episodes: {p_mean:.4g} {unit}")
    ax.axhspan(p_mean - p_half, p_mean + p_half, color="0.5", alpha=0.15,
               label=f"{reference} policy: 95 % interval over {n} validation episodes (\u00b1{p_half:.2g} {unit})")
    ax.set_xlabel("training timesteps [agent transitions]")
    what = "validation error" if cost_range is None else "validation score"
    ax.set_ylabel("\n".join(textwrap.wrap(f"{what}: {name} [{unit}]", 48)), fontsize=9)
    ax.set_title(title, fontsize=10)
    ax.grid(True, color="0.92", lw=0.6)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=1, frameon=False)
    save_figure(os.path.join(folder, "learning_curve.png"), fig)


FROM_SETTINGS = "settings"  # train's cost_range default: the settings module's COST_RANGE


def training_env_config(scenario: str, cost_range=FROM_SETTINGS) -> tuple[dict, tuple[float, float] | None]:
    """(the training env config, its cost range) of ``scenario``: the settings module's ``ENV_CONFIG`` with
    ``cost_range`` = ``cost_range`` (``FROM_SETTINGS``: its ``COST_RANGE``; None: none, a fixed cost), checked
    before any training: a ``BadInput`` naming ``--cost-range`` and the allowed range for a bad pair, and one
    saying so where the scenario takes no ``cost_range`` keyword."""
    import coloc_env
    from coloc_env.composition import check_cost_range
    from train.hyperparams import cost_range as settings_cost_range
    from train.hyperparams import load

    env_config = load(scenario)[1]
    if isinstance(cost_range, str) and cost_range == FROM_SETTINGS:
        cost_range = settings_cost_range(scenario)
    elif cost_range is not None:
        cost_range = tuple(cost_range) if isinstance(cost_range, (list, tuple)) else cost_range
        check_cost_range("--cost-range (lo, hi)", cost_range)
        cost_range = (float(cost_range[0]), float(cost_range[1]))
    env_config.pop("cost_range", None)
    if cost_range is None:
        return env_config, None
    env_config["cost_range"] = list(cost_range)
    try:
        coloc_env.parallel_env(scenario, **env_config).close()
    except ValueError as exc:
        if "cost_range" not in str(exc):
            raise
        raise BadInput(f"--cost-range: {scenario} takes no cost_range keyword, so it cannot draw a cost per episode "
                       f"(train it without --cost-range, at its fixed communication_cost): {exc}") from exc
    return env_config, cost_range


def _cost_feature_index(scenario: str, env_config: dict) -> int:
    """Where an agent's observation of ``scenario`` carries the episode's communication cost."""
    import coloc_env

    env = coloc_env.parallel_env(scenario, **env_config)
    try:
        return int(env.unwrapped.scenario.feature_index("communication_cost"))
    finally:
        env.close()


def train(scenario: str, timesteps: int | None, seed: int, out: str, vec: str = "native",
          progress_bar: bool = True, tensorboard: bool = False, curve_points: int = CURVE_POINTS,
          cost_range=FROM_SETTINGS, paper_entries=FROM_SETTINGS) -> str:
    """Train and save ``out/<scenario>/seed<S>/model.zip`` (+ ``model.json``); returns the model path.

    ``timesteps`` None: the scenario's budget (``TIMESTEPS`` of ``train/hyperparams/<scenario>.py``,
    ``DEFAULT_TIMESTEPS`` where it sets none). ``curve_points`` validation points make the learning
    curve (0: no curve, only checkpoints). ``cost_range``: (lo, hi) with 0 <= lo <= hi <= 1e12, the training
    env's ``cost_range`` (the module docstring), None for a fixed cost, or ``FROM_SETTINGS`` (the settings
    module's ``COST_RANGE``, none where it sets none). ``paper_entries``: the name of the action entries the model
    leaves to the paper's rule (``agents.paper_entries``), None for none, or ``FROM_SETTINGS`` (the settings
    module's ``PAPER_ENTRIES``, none where it sets none).
    """
    import torch
    from stable_baselines3.common.vec_env import VecMonitor

    from agents.sb3 import algorithm_class
    from train import hyperparams
    from train.hyperparams import algorithm, budget, cost_reward_scale, critic, curve_episodes, load, module, setting

    if timesteps is None:
        timesteps = budget(scenario, DEFAULT_TIMESTEPS)
    if isinstance(timesteps, bool) or not isinstance(timesteps, (int, np.integer)) or timesteps < 1:
        raise BadInput(f"timesteps must be an integer >= 1, got {timesteps!r}")
    if not 0 <= seed < MAX_TRAINING_SEED:
        raise BadInput(f"seed must be in [0, {MAX_TRAINING_SEED}) (disjoint from evaluation seeds), got {seed}")
    if tensorboard:
        try:
            import tensorboard as _  # noqa: F401
        except ImportError as exc:
            raise BadInput("--tensorboard needs the tensorboard package: pip install tensorboard") from exc
    import agents

    hyper = load(scenario)[0]
    if isinstance(paper_entries, str) and paper_entries == FROM_SETTINGS:
        paper_entries = setting(scenario, "PAPER_ENTRIES")
    paper = agents.paper_entries(scenario, paper_entries)
    if paper is not None and vec != "native":
        raise BadInput(f"--paper-entries {paper_entries}: reads the native vector env's sub-env order; use --vec "
                       f"native, not {vec!r}")
    env_config, cost_range = training_env_config(scenario, cost_range)
    episodes = curve_episodes(scenario, CURVE_EPISODES)
    copies = module(scenario).NUM_COPIES
    algorithm_name = algorithm(scenario)
    if algorithm_name == "maskable_ppo" and vec != "native":
        raise BadInput(f"{scenario} trains with maskable_ppo, which reads the native vector env's action masks; "
                       f"use --vec native, not {vec!r}")
    critic_name = critic(scenario)
    acting = hyperparams.actions(scenario)
    if critic_name == "centralized" and vec != "native":
        raise BadInput(f"{scenario} trains with a centralized critic, which reads the native vector env's state(); "
                       f"use --vec native, not {vec!r}")
    Algorithm = algorithm_class(algorithm_name)
    from stable_baselines3.common.utils import set_random_seed

    if critic_name == "centralized" and algorithm_name == "recurrent_ppo":
        raise BadInput(f"{scenario}: the centralized critic is built for ppo and maskable_ppo, not recurrent_ppo")
    inner = make_vec_env(scenario, copies, env_config, seed, vec)
    if paper is not None:
        inner = paper_entries_env(inner, paper, inner.num_envs // copies, seed)
    reward_scale = cost_reward_scale(scenario) if cost_range is not None else None
    feature = hyperparams.cost_feature(scenario)  # checked whatever the range
    if cost_range is None:  # a fixed cost is one value the whole training: nothing to scale
        feature = "raw"
    if feature != "raw" and critic_name == "centralized":
        raise BadInput(f"COST_FEATURE {feature!r} of train/hyperparams/{hyperparams.module_name(scenario)}.py: the "
                       f"centralized critic reads the observation itself; use COST_FEATURE 'raw' with it")
    cost_index = (_cost_feature_index(scenario, env_config)
                  if reward_scale is not None or feature != "raw" else None)
    model_kwargs = {}
    if feature == "scaled":
        from agents.cost_feature import CostScaledExtractor

        model_kwargs = {"features_extractor_class": CostScaledExtractor,
                        "features_extractor_kwargs": {"column": cost_index, "cost_range": tuple(cost_range)}}
    policy = "MlpLstmPolicy" if algorithm_name == "recurrent_ppo" else "MlpPolicy"
    if critic_name == "centralized":
        from agents.centralized_critic import CriticStateObservation, policy_class

        inner = CriticStateObservation(inner)
        policy = policy_class(algorithm_name)
        hyper["policy_kwargs"] = {**hyper.get("policy_kwargs", {}), "local_dim": inner.local_dim}
    # VecMonitor above the scaling: its episode returns (SB3's logs) are the ones PPO optimizes
    venv = VecMonitor(inner if reward_scale is None else cost_balanced_reward(inner, cost_index, reward_scale))
    folder = os.path.join(out, scenario, f"seed{seed}")
    os.makedirs(folder, exist_ok=True)
    # One torch thread: a Ray worker runs with one, and a different thread count changes the
    # reduction order of the matmuls, so the same seed would give different weights there.
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        set_random_seed(seed)
        settings = dict(hyper)
        if model_kwargs:  # hyper stays JSON (model.json); the extractor's class goes to the model only
            settings["policy_kwargs"] = {**hyper.get("policy_kwargs", {}), **model_kwargs}
        model = Algorithm(policy, venv, device="cpu", verbose=0,
                    tensorboard_log=os.path.join(folder, "tb") if tensorboard else None, **settings)
        model.action_space.seed(seed)
        curve: list = []
        # SB3's live bar on a terminal; elsewhere (a pipe, a log file) a plain line per validation point,
        # since a redrawn bar there is one line hundreds of columns wide
        live_bar = progress_bar and sys.stdout.isatty()
        report = None
        if progress_bar and not live_bar:
            def report(message: str) -> None:
                print(f"{scenario} seed {seed}: {message}", flush=True)
        callback = _callbacks(scenario, folder, timesteps, curve, curve_points, episodes, report, env_config,
                              cost_range, inner.num_envs // copies, paper=paper,
                              deterministic=acting == "deterministic")
        model.learn(total_timesteps=timesteps, progress_bar=live_bar, callback=callback)
    finally:
        torch.set_num_threads(threads)
    path = os.path.join(folder, "model.zip")
    save_model(os.path.join(folder, "last.zip"), model)
    if callback.best is not None:  # model.zip is the best validation checkpoint; last.zip the final weights
        selected = {"selected": "best on the validation seeds", "timesteps": callback.best[1],
                    "validation_mean_cost": callback.best[0], "validation_episodes": episodes,
                    "validation_score": "error" if cost_range is None else
                    f"mean over the costs {validation_costs(cost_range)} of error + cost x messages per agent-step"}
        source = os.path.join(folder, "best.zip")
    else:
        selected = {"selected": "last (no validation curve)", "timesteps": int(model.num_timesteps)}
        source = os.path.join(folder, "last.zip")
    copy_file(source, path)
    write_json(os.path.join(folder, "model.json"), {
        "checkpoint": selected,
        "scenario": scenario, "seed": seed, "timesteps": timesteps, "env_config": env_config,
        "cost_range": None if cost_range is None else list(cost_range),
        "cost_reward_scale": reward_scale, "paper_entries": paper_entries,
        "hyperparams": json.loads(json.dumps(hyper)), "vec": vec, "copies": copies, "algorithm": algorithm_name,
        "critic": critic_name, "actions": acting, "cost_feature": feature,
        "observation_space": repr(venv.observation_space), "action_space": repr(venv.action_space),
    })
    venv.close()
    if curve:
        what = "error" if cost_range is None else "score"
        write_learning_curve(folder, scenario, curve, f"{scenario}, seed {seed}: validation {what} vs timesteps",
                             episodes, env_config, cost_range, callback.at_costs, acting)
    return path
