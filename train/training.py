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


def make_supersuit_vec_env(scenario: str, copies: int, env_config: dict):
    """B copies x N agents as one SB3 VecEnv through SuperSuit (each agent a sub-env)."""
    import supersuit as ss

    import coloc_env

    env = coloc_env.parallel_env(scenario, **env_config)
    venv = ss.pettingzoo_env_to_vec_env_v1(env)
    return ss.concat_vec_envs_v1(venv, copies, num_cpus=0, base_class="stable_baselines3")


def seed_supersuit_vec_env(venv, seed: int) -> None:
    """Reset copy c of a SuperSuit SB3 vec env with seed ``seed + c``.

    SuperSuit's SB3 wrapper forwards ``seed()`` to ``ConcatVecEnv``, which has
    none, so SB3's own ``PPO(seed=...)`` fails on it; seeding through reset
    works because a later ``reset()`` without a seed continues each copy's
    generator (DESIGN.md, Seeding).
    """
    venv.venv.reset(seed=seed)


def train(scenario: str, timesteps: int, seed: int, out: str, vec: str = "supersuit",
          progress_bar: bool = True, tensorboard: bool = False) -> str:
    """Train and save ``out/<scenario>/seed<S>/model.zip`` (+ ``model.json``); returns the model path."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    from train.hyperparams import load

    if timesteps < 1:
        raise ValueError(f"timesteps must be >= 1, got {timesteps}")
    if vec != "supersuit":
        raise ValueError(f"vec must be 'supersuit', got {vec!r}")
    hyper, env_config = load(scenario)
    copies = importlib.import_module(f"train.hyperparams.{scenario}").NUM_COPIES
    from stable_baselines3.common.utils import set_random_seed

    supersuit_env = make_supersuit_vec_env(scenario, copies, env_config)
    seed_supersuit_vec_env(supersuit_env, seed)
    venv = VecMonitor(supersuit_env)
    folder = os.path.join(out, scenario, f"seed{seed}")
    os.makedirs(folder, exist_ok=True)
    set_random_seed(seed)
    model = PPO("MlpPolicy", venv, device="cpu", verbose=0,
                tensorboard_log=os.path.join(folder, "tb") if tensorboard else None, **hyper)
    model.action_space.seed(seed)
    model.learn(total_timesteps=timesteps, progress_bar=progress_bar)
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
