"""RLlib PPO on a coloc preset through ``ParallelPettingZooEnv`` (one policy shared by all agents).

RLlib pins an older gymnasium than coloc's main environment, so this runs in a
venv of its own (``make rllib-example``; not part of ``make test`` or
``make demo``):

    PYTHONHASHSEED=0 python docs/clients/rllib_ppo.py [--preset relay_ukf] [--iterations 3] [--max-cycles 50]

It trains on RLlib's new API stack (RLModule, Learner, EnvRunner) with no remote
workers (``num_env_runners=0``: sampling and learning run in this process; Ray
still starts its local core processes, limited here to 2 CPUs without the
dashboard) and prints the mean episode return of each iteration (the
return summed over the agents, and per agent).

Notes: RLlib's wrapper calls ``env.render(mode)``, which coloc accepts when the
mode is the env's own ``render_mode``. RLlib's PPO takes coloc's
``MaskableMultiDiscrete`` action spaces as the ``MultiDiscrete`` they subclass
(one categorical per dimension); ``infos[agent]["action_mask"]`` reaches the
episodes but RLlib's default RLModule does not read it, so the policy may pick
masked choices, which the env plays as its explicit "stop" / "no measurement"
choice (docs/clients/README.md, "Action masks"). RLlib's ``MultiAgentEpisode``
orders agents through sets of their names: without a fixed ``PYTHONHASHSEED``
the returns change from run to run whatever ``seed``. The small batch sizes
make one training iteration take seconds.
"""

from __future__ import annotations

import argparse
import time

import ray
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
from ray.tune.registry import register_env

import coloc_env


def make_env(config: dict) -> ParallelPettingZooEnv:
    config = dict(config)
    return ParallelPettingZooEnv(coloc_env.parallel_env(config.pop("preset"), **config))


def main(preset: str = "relay_ukf", iterations: int = 3, max_cycles: int = 50, seed: int = 0) -> list[dict]:
    ray.init(num_cpus=2, include_dashboard=False, ignore_reinit_error=True)
    register_env("coloc", make_env)
    config = (
        PPOConfig()
        .environment("coloc", env_config={"preset": preset, "max_cycles": max_cycles})
        .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, *args, **kwargs: "shared")
        .env_runners(num_env_runners=0)
        .learners(num_learners=0)
        .training(train_batch_size_per_learner=200, minibatch_size=50, num_epochs=1)
        .debugging(seed=seed)
    )
    algo = config.build_algo()
    results = []
    try:
        for iteration in range(1, iterations + 1):
            start = time.perf_counter()
            result = algo.train()
            runners = result.get("env_runners", {})
            agents = runners.get("agent_episode_returns_mean", {})
            per_agent = sum(agents.values()) / len(agents) if agents else float("nan")
            print(f"iteration {iteration}: episode return {runners.get('episode_return_mean', float('nan')):.2f}"
                  f" (summed over agents; {per_agent:.2f} per agent), episodes {runners.get('num_episodes', 0)},"
                  f" env steps {int(runners.get('num_env_steps_sampled_lifetime', 0))},"
                  f" {time.perf_counter() - start:.1f} s", flush=True)
            results.append(result)
    finally:
        algo.stop()
        ray.shutdown()
    return results


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="relay_ukf", help="a name of coloc_env.PRESETS")
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument("--max-cycles", type=int, default=50, help="episode length")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    main(args.preset, args.iterations, args.max_cycles, args.seed)
