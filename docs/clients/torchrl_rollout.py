"""TorchRL on a coloc preset: ``PettingZooWrapper``, ``check_env_specs`` and a rollout.

    python docs/clients/torchrl_rollout.py

TorchRL groups agents by name prefix (``platform_0..3`` -> group
``"platform"``), so a rollout's tensordict holds ``("platform",
"observation")`` of shape (steps, agents, obs_dim), the actions under
``("platform", "action")`` and the rewards under ``("next", "platform",
"reward")``. ``categorical_actions=False`` keeps MultiDiscrete actions as
the integer vectors coloc expects (TorchRL's default one-hot encodes them).
"""

from __future__ import annotations

from torchrl.envs.libs.pettingzoo import PettingZooWrapper
from torchrl.envs.utils import check_env_specs

from coloc_env.envs import relay_ukf


def make_env(max_cycles: int = 32, seed: int = 0) -> PettingZooWrapper:
    return PettingZooWrapper(relay_ukf.parallel_env(max_cycles=max_cycles), use_mask=False,
                             categorical_actions=False, seed=seed)


def main(steps: int = 16, seed: int = 0):
    env = make_env(seed=seed)
    check_env_specs(env, seed=seed)  # the specs TorchRL derived match what the env returns
    rollout = env.rollout(steps)  # random actions from the action spec
    env.close()
    return rollout


if __name__ == "__main__":
    td = main()
    reward = td["next", "platform", "reward"]
    print(f"rollout {tuple(td.batch_size)} steps; reward per platform {reward.mean(dim=(0, 2)).tolist()}")
