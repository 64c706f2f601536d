"""Stable-Baselines3 PPO on a coloc preset through SuperSuit, in a few seconds.

    python docs/clients/sb3_ppo.py

SuperSuit turns the PettingZoo parallel env into an SB3 ``VecEnv`` with one
sub-env per agent (``pettingzoo_env_to_vec_env_v1``), so PPO trains one policy
shared by all agents; ``concat_vec_envs_v1`` stacks ``copies`` such envs. A
PPO rollout is ``n_steps`` x (copies x agents) transitions: here 32 x (2 x 4) =
256 per update, so ``learn(total_timesteps=512)`` is two updates. (SB3's
default ``n_steps=2048`` would make the first rollout 2048 x 8 = 16,384
transitions before anything is printed.) ``coloc_env.vector_env`` is the
faster native alternative (one batched numpy call for all copies, infos
already marked for truncation); this file shows the generic PettingZoo route, with
``train.training.mark_truncation`` (the wrapper ``coloc train --vec supersuit`` uses) marking
SuperSuit's episode ends as truncations.
"""

from __future__ import annotations

import supersuit as ss
from stable_baselines3 import PPO
from stable_baselines3.common.utils import set_random_seed
from stable_baselines3.common.vec_env import VecMonitor

from coloc_env.envs import relay_ukf
from train.training import mark_truncation


def make_vec_env(copies: int = 2, max_cycles: int = 64, seed: int = 0) -> VecMonitor:
    """``copies`` x 4 platforms of relay_ukf as one SB3 VecEnv; copy c starts as ``reset(seed=seed + c)``."""
    env = relay_ukf.parallel_env(max_cycles=max_cycles)
    vec = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(env), copies, num_cpus=0,
                                base_class="stable_baselines3")
    # SuperSuit's reset() passes no seed (and its VecEnv has no seed()): seed each copy's generator.
    for c, markov_env in enumerate(vec.venv.vec_envs):
        markov_env.par_env.seed_generator(seed + c)
    # SuperSuit reports the end of an episode (always at max_cycles) as a plain done: mark_truncation flags it
    # TimeLimit.truncated so that PPO bootstraps the last value. VecMonitor writes SB3's episode info
    # (return, length), so that PPO logs rollout/ep_rew_mean.
    return VecMonitor(mark_truncation(vec))


def main(total_timesteps: int = 512, copies: int = 2, seed: int = 0) -> PPO:
    vec = make_vec_env(copies=copies, seed=seed)
    set_random_seed(seed)  # SB3's own seeding of the policy's initial weights and sampling
    model = PPO("MlpPolicy", vec, n_steps=32, batch_size=64, n_epochs=2, device="cpu", verbose=0)
    model.learn(total_timesteps=total_timesteps)
    vec.close()
    return model


if __name__ == "__main__":
    trained = main()
    returns = [episode["r"] for episode in trained.ep_info_buffer]
    print(f"trained on {trained.num_timesteps} transitions "
          f"({trained.num_timesteps // (trained.n_steps * trained.n_envs)} PPO updates); "
          f"ep_rew_mean {sum(returns) / len(returns):.2f} over the last {len(returns)} agent-episodes")
