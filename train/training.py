"""``coloc train``: PPO with parameter sharing over a scenario's agents, read top to bottom.

Training seeds: seed S seeds torch and numpy (network, sampling) and copy c
of the environment with S + c, c < NUM_COPIES.
Evaluation (``coloc evaluate``) uses episode seeds from EVAL_SEED_BASE = 10**6
upward, which training never uses.
"""

from __future__ import annotations

import importlib
import json
import os

from train.io import write_json

EVAL_SEED_BASE = 10**6


def _mark_truncation_wrapper():
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class MarkTruncation(VecEnvWrapper):
        """Adds ``TimeLimit.truncated = True`` where SuperSuit reports an episode end.

        SuperSuit's MarkovVectorEnv stores ``terminal_observation`` but merges
        truncation into ``dones`` without the flag, so SB3 would treat the
        horizon as a terminal state and not bootstrap its value. coloc's
        episodes end only by truncation, so every end is marked.
        """

        def reset(self):
            return self.venv.reset()

        def step_wait(self):
            observations, rewards, dones, infos = self.venv.step_wait()
            for info in infos:
                if "terminal_observation" in info:
                    info["TimeLimit.truncated"] = True
            return observations, rewards, dones, infos

    return MarkTruncation


def make_supersuit_vec_env(scenario: str, copies: int, env_config: dict):
    """B copies x N agents as one SB3 VecEnv through SuperSuit (each agent a sub-env)."""
    import supersuit as ss

    import coloc_env

    env = coloc_env.parallel_env(scenario, **env_config)
    venv = ss.pettingzoo_env_to_vec_env_v1(env)
    return _mark_truncation_wrapper()(ss.concat_vec_envs_v1(venv, copies, num_cpus=0, base_class="stable_baselines3"))


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
    raise ValueError(f"vec must be 'native' or 'supersuit', got {vec!r}")


def train(scenario: str, timesteps: int, seed: int, out: str, vec: str = "native",
          progress_bar: bool = True, tensorboard: bool = False) -> str:
    """Train and save ``out/<scenario>/seed<S>/model.zip`` (+ ``model.json``); returns the model path."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    from train.hyperparams import load

    if timesteps < 1:
        raise ValueError(f"timesteps must be >= 1, got {timesteps}")
    hyper, env_config = load(scenario)
    copies = importlib.import_module(f"train.hyperparams.{scenario}").NUM_COPIES
    from stable_baselines3.common.utils import set_random_seed

    venv = VecMonitor(make_vec_env(scenario, copies, env_config, seed, vec))
    folder = os.path.join(out, scenario, f"seed{seed}")
    os.makedirs(folder, exist_ok=True)
    # One torch thread: a Ray worker runs with one, and a different thread count changes the
    # reduction order of the matmuls, so the same seed would give different weights there.
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        set_random_seed(seed)
        model = PPO("MlpPolicy", venv, device="cpu", verbose=0,
                    tensorboard_log=os.path.join(folder, "tb") if tensorboard else None, **hyper)
        model.action_space.seed(seed)
        model.learn(total_timesteps=timesteps, progress_bar=progress_bar)
    finally:
        torch.set_num_threads(threads)
    path = os.path.join(folder, "model.zip")
    tmp = os.path.join(folder, ".tmp-model.zip")
    model.save(tmp)
    os.replace(tmp, path)
    write_json(os.path.join(folder, "model.json"), {
        "scenario": scenario, "seed": seed, "timesteps": timesteps, "env_config": env_config,
        "hyperparams": json.loads(json.dumps(hyper)), "vec": vec, "copies": copies,
    })
    venv.close()
    return path
