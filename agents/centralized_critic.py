"""A centralized critic with decentralized actors (CTDE) for stable-baselines3's PPO and sb3-contrib's MaskablePPO.

The training recipe ``CRITIC = "centralized"`` of a settings module in ``train/hyperparams``. Every agent's
observation is extended with its copy's ``state()`` (the global state the scenario documents under
"``state()`` (centralized critic)"): the sub-env sees ``[own observation | state]``. The policy network
(``CentralizedCriticPolicy``) gives the actor only the first ``local_dim`` entries, its own observation,
and the critic all of them. So the value baseline may use what no agent knows (every agent's view, the link
outcomes, ...) while the actions depend on the agent's own observation alone, and the trained policy runs
decentralized: ``extend_observation`` feeds the state in at evaluation too, and a test holds the actions
unchanged whatever the state part holds.

Why it can help: the reward of every coloc scenario is a team error that depends on all agents' choices and on
the episode's draws. A critic that sees one agent's view explains little of it, so the advantages are noisy;
with the state it explains more (Lowe et al. 2017, MADDPG; Foerster et al. 2018, COMA; Yu et al. 2022, MAPPO).

=================  =============================================================================================
part               what it does
=================  =============================================================================================
``critic_observation_space(obs, state)``  the Box of ``[obs | state]`` (bounds concatenated, float32)
``CriticStateObservation(venv)``   SB3 ``VecEnvWrapper`` over ``coloc_env.vector_env``: appends each copy's state
                                   to its agents' observations, including an ended episode's
                                   ``terminal_observation`` (the vector env's ``terminal_state``)
``CentralizedCriticPolicy``        PPO's policy: ``policy_kwargs={"local_dim": d}``
``MaskableCentralizedCriticPolicy`` the same for MaskablePPO
``extend_observation(obs, state)``  ``(..., N, d)`` observations and ``(..., S)`` states -> ``(..., N, d + S)``
=================  =============================================================================================
"""

from __future__ import annotations

import gymnasium
import numpy as np
import torch as th
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import MlpExtractor
from stable_baselines3.common.vec_env import VecEnvWrapper
from torch import nn

from coloc_env.config import BadInput

CRITICS = ("decentralized", "centralized")  # the settings' CRITIC: the agent's own view (PPO's default), or + state()


def critic_observation_space(observation_space: gymnasium.spaces.Box,
                             state_space: gymnasium.spaces.Box) -> gymnasium.spaces.Box:
    """The sub-env's Box under the centralized critic: ``[own observation | state]``, bounds concatenated."""
    low = np.concatenate([np.ravel(observation_space.low), np.ravel(state_space.low)]).astype(np.float32)
    high = np.concatenate([np.ravel(observation_space.high), np.ravel(state_space.high)]).astype(np.float32)
    return gymnasium.spaces.Box(low, high, dtype=np.float32)


def extend_observation(observation: np.ndarray, state: np.ndarray) -> np.ndarray:
    """``observation (..., N, d)`` and the copies' ``state (..., S)`` -> ``(..., N, d + S)``: every agent of a copy
    gets that copy's state after its own observation."""
    observation = np.asarray(observation, dtype=np.float32)
    state = np.asarray(state, dtype=np.float32)
    tiled = np.broadcast_to(state[..., None, :], (*observation.shape[:-1], state.shape[-1]))
    return np.concatenate([observation, tiled], axis=-1)


class CriticStateObservation(VecEnvWrapper):
    """``[own observation | copy's state]`` for every sub-env of a ``coloc_env.vector_env`` (copy b's agents are
    sub-envs ``b * N .. b * N + N - 1``).

    An ended episode's ``terminal_observation`` gets the state its copy had before the auto-reset (the vector
    env's ``terminal_state`` info), so that SB3 bootstraps the critic on the right state.
    """

    def __init__(self, venv):
        scenario = getattr(venv, "scenario", None)
        if scenario is None:
            raise BadInput("the centralized critic needs coloc_env.vector_env (it reads the core's state()); "
                           f"got {type(venv).__name__}")
        self.scenario = scenario
        self.num_copies = venv.num_copies
        self.num_agents = venv.num_agents
        self.local_dim = int(np.prod(venv.observation_space.shape))
        space = critic_observation_space(venv.observation_space, scenario.state_space())
        super().__init__(venv, observation_space=space)

    def _extend(self, flat_observation: np.ndarray) -> np.ndarray:
        per_copy = flat_observation.reshape(self.num_copies, self.num_agents, -1)
        return extend_observation(per_copy, self.scenario.state()).reshape(self.num_envs, -1)

    def reset(self) -> np.ndarray:
        return self._extend(self.venv.reset())

    def step_wait(self):
        observations, rewards, dones, infos = self.venv.step_wait()
        for info in infos:
            if "terminal_observation" in info:
                info["terminal_observation"] = np.concatenate([info["terminal_observation"],
                                                               info["terminal_state"]]).astype(np.float32)
        return self._extend(observations), rewards, dones, infos


class SplitMlpExtractor(nn.Module):
    """PPO's two MLPs, the actor's on the first ``local_dim`` features (the agent's own observation) and the
    critic's on all of them (own observation and the copy's state)."""

    def __init__(self, local_dim: int, feature_dim: int, net_arch, activation_fn, device):
        super().__init__()
        if not 0 < local_dim <= feature_dim:
            raise BadInput(f"local_dim must be in 1..{feature_dim} (the observation's size), got {local_dim!r}")
        self.local_dim = int(local_dim)
        actor = MlpExtractor(self.local_dim, net_arch=net_arch, activation_fn=activation_fn, device=device)
        critic = MlpExtractor(feature_dim, net_arch=net_arch, activation_fn=activation_fn, device=device)
        self.policy_net, self.latent_dim_pi = actor.policy_net, actor.latent_dim_pi
        self.value_net, self.latent_dim_vf = critic.value_net, critic.latent_dim_vf

    def forward(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: th.Tensor) -> th.Tensor:
        return self.policy_net(features[..., : self.local_dim])

    def forward_critic(self, features: th.Tensor) -> th.Tensor:
        return self.value_net(features)


class _CentralizedCritic:
    """The hook both policies share: ``local_dim`` kept, saved with the model, and the split extractor built."""

    local_dim: int

    def _build_mlp_extractor(self) -> None:
        self.mlp_extractor = SplitMlpExtractor(self.local_dim, self.features_dim, self.net_arch, self.activation_fn,
                                               self.device)

    def _get_constructor_parameters(self) -> dict:
        data = super()._get_constructor_parameters()
        data["local_dim"] = self.local_dim
        return data


class CentralizedCriticPolicy(_CentralizedCritic, ActorCriticPolicy):
    """SB3's ``MlpPolicy`` with the actor on the own observation and the critic on ``[own | state]``."""

    def __init__(self, observation_space, action_space, lr_schedule, *args, local_dim: int, **kwargs):
        self.local_dim = int(local_dim)
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)


class MaskableCentralizedCriticPolicy(_CentralizedCritic, MaskableActorCriticPolicy):
    """sb3-contrib's maskable ``MlpPolicy`` with the actor on the own observation and the critic on
    ``[own | state]``."""

    def __init__(self, observation_space, action_space, lr_schedule, *args, local_dim: int, **kwargs):
        self.local_dim = int(local_dim)
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)


def policy_class(algorithm: str):
    """The centralized-critic policy class of a training algorithm (``"ppo"`` or ``"maskable_ppo"``)."""
    return MaskableCentralizedCriticPolicy if algorithm == "maskable_ppo" else CentralizedCriticPolicy


def is_centralized(model) -> bool:
    """True when ``model`` was trained with the centralized critic (its observation carries the state)."""
    return isinstance(getattr(model, "policy", None), _CentralizedCritic)
