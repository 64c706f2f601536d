"""RLlib PPO on a coloc preset through ``ParallelPettingZooEnv`` (one policy shared by all agents).

RLlib pins an older gymnasium than coloc's main environment, so this runs in a
venv of its own (``make rllib-example``; not part of ``make test`` or
``make demo``):

    python docs/clients/rllib_ppo.py

Notes: RLlib's wrapper calls ``env.render(mode)``, which coloc accepts when the
mode is the env's own ``render_mode``; RLlib's PPO takes ``MultiDiscrete``
action spaces (coloc has no ``MultiBinary`` ones). The small batch sizes make
one training iteration take seconds.
"""

from __future__ import annotations

from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
from ray.tune.registry import register_env

from coloc_env.envs import relay_ukf


def main(iterations: int = 1):
    register_env("coloc_relay_ukf", lambda config: ParallelPettingZooEnv(relay_ukf.parallel_env(**config)))
    config = (
        PPOConfig()
        .environment("coloc_relay_ukf", env_config={"max_cycles": 50})
        .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, *args, **kwargs: "shared")
        .env_runners(num_env_runners=0)
        .training(train_batch_size_per_learner=200, minibatch_size=50, num_epochs=1)
        .debugging(seed=0)
    )
    algo = config.build_algo()
    results = [algo.train() for _ in range(iterations)]
    algo.stop()
    return results


if __name__ == "__main__":
    for result in main():
        print({k: v for k, v in result.get("env_runners", {}).items() if "return" in k})
