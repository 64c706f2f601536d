"""A stable-baselines3 ``VecEnv`` over B copies x N agents of one batched scenario.

Each agent of each copy is one sub-env (index ``b * N + i``), so SB3 trains
one policy shared by all agents (parameter sharing). Every step is one call of
the batched ``coloc_env.scenarios.base.Scenario`` core: no Python loop
over copies, except to build the info dicts of the copies whose episode just
ended (SB3 needs one dict per sub-env).

Seeding: copy b of ``vector_env(name, num_envs=B, seed=s)``
is exactly ``parallel_env(name)`` reset with seed ``s + b``, and a copy's
later episodes continue its generator as ``reset()`` would. ``seed(s)``
(called by SB3's ``PPO(seed=s)``) reseeds copy b with ``s + b`` at the next
reset.

Episodes end by truncation at the scenario's horizon (``max_cycles`` sets it, as
in ``coloc_env.env.CoLocParallelEnv``): finished copies are
reset automatically, and their sub-envs' infos carry ``terminal_observation``
and ``TimeLimit.truncated = True`` so that SB3 bootstraps the value of the
last observation, and ``terminal_state`` (the copy's ``state()`` before the
reset, for a centralized critic).

Action masks (discrete actions): ``CoLocVecEnv.action_masks`` gives one row per sub-env,
what ``sb3_contrib.MaskablePPO`` reads before every step (``get_action_masks``).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from itertools import repeat
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from coloc_env.config import MAX_NUM_ENVS, check_count, check_seed
from coloc_env.env import build_scenario
from coloc_env.rendering import Renderer
from coloc_env.scenarios.base import Scenario


class CoLocVecEnv(VecEnv):
    """B copies x N agents of ``scenario_cls`` as ``B * N`` SB3 sub-envs."""

    def __init__(self, scenario_cls: type[Scenario], num_envs: int, seed: int | None = None,
                 render_mode: str | None = None, *, composition=None, max_cycles: int | None = None, **config):
        check_count("num_envs", num_envs, 1, MAX_NUM_ENVS)
        check_seed("seed", seed, int(num_envs))
        self.scenario = build_scenario(scenario_cls, int(num_envs), composition, max_cycles, **config)
        self.num_copies = int(num_envs)
        self.num_agents = self.scenario.num_agents
        self.render_mode = render_mode
        self._renderer = Renderer(render_mode)
        super().__init__(self.num_copies * self.num_agents, self.scenario.observation_space(),
                         self.scenario.action_space())
        self._rngs: list[np.random.Generator] | None = None
        self._copy_seeds: list[int] | None = None
        self.seed(seed)
        self._actions: np.ndarray | None = None
        self._t_start = time.time()
        self._episode_returns = np.zeros(self.num_envs, dtype=np.float32)
        self._episode_lengths = np.zeros(self.num_envs, dtype=np.int64)

    # --- seeding and reset ---------------------------------------------------
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Copy b gets ``default_rng(seed + b)`` at the next reset; None draws fresh entropy."""
        if seed is None:
            self._copy_seeds = None
            return [None] * self.num_copies
        seed = check_seed("seed", seed, self.num_copies)
        self._copy_seeds = [seed + b for b in range(self.num_copies)]
        return list(self._copy_seeds)

    def reset(self) -> np.ndarray:
        if self._copy_seeds is not None or self._rngs is None:
            seeds = self._copy_seeds or [None] * self.num_copies
            self._rngs = [np.random.default_rng(s) for s in seeds]
            self._copy_seeds = None
        self.scenario.reset(self._rngs)
        self._episode_returns[:] = 0.0
        self._episode_lengths[:] = 0
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return self._flat_observation()

    def _flat_observation(self) -> np.ndarray:
        obs = self.scenario.observation()
        return obs.reshape(self.num_envs, *obs.shape[2:])

    # --- stepping ------------------------------------------------------------
    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        actions = np.asarray(self._actions)
        shape = self.action_space.shape
        expected = (self.num_envs, *shape)
        if actions.shape != expected:
            raise ValueError(f"actions must have shape {expected} (copies x agents = {self.num_envs} sub-envs, "
                             f"*action_shape), got {actions.shape}")
        self.scenario.step(actions.reshape(self.num_copies, self.num_agents, *shape))
        observation = self._flat_observation()
        rewards = self.scenario.reward().reshape(self.num_envs).astype(np.float32)
        done_copies = self.scenario.done()
        dones = np.repeat(done_copies, self.num_agents)
        self._episode_returns += rewards
        self._episode_lengths += 1
        # a fresh dict per sub-env (SB3 may write into them); repeat() makes no int per item, a quarter faster
        infos: list[dict[str, Any]] = [{} for _ in repeat(None, self.num_envs)]
        finished = np.flatnonzero(done_copies)
        if len(finished):
            states = self.scenario.state()
            elapsed = round(time.time() - self._t_start, 6)
            for b in finished:
                for i in range(self.num_agents):
                    sub = b * self.num_agents + i
                    episode = {"r": float(self._episode_returns[sub]), "l": int(self._episode_lengths[sub]),
                               "t": elapsed}
                    infos[sub] = {"terminal_observation": observation[sub].copy(), "TimeLimit.truncated": True,
                                  "terminal_state": states[b].copy(), "episode": episode}
            ended = np.repeat(done_copies, self.num_agents)
            self._episode_returns[ended] = 0.0
            self._episode_lengths[ended] = 0
            self.scenario.reset([self._rngs[b] for b in finished], env_index=finished)
            fresh = self.scenario.observation()[finished]
            observation = observation.reshape(self.num_copies, self.num_agents, *observation.shape[1:])
            observation[finished] = fresh
            observation = observation.reshape(self.num_envs, *observation.shape[2:])
        return observation, rewards, dones, infos

    def action_masks(self) -> np.ndarray:
        """(num_envs, sum(nvec)) bool: the valid choices of each sub-env's next action (sb3_contrib's
        ``get_action_masks``, through ``env_method``), ``Discrete(n)``: (num_envs, n). It reads the
        scenario's current state, so after an auto-reset in ``step_wait`` it is the new episode's. A
        ``Box`` action has nothing to mask: a ValueError."""
        mask = self.scenario.action_mask()
        if mask is None:
            raise ValueError(f"{self.scenario.name} has a {type(self.action_space).__name__} action: no action "
                             "masks (they exist for Discrete and MultiDiscrete actions)")
        return np.asarray(mask, dtype=bool).reshape(self.num_envs, -1)

    # --- the rest of the VecEnv interface --------------------------------------
    def close(self) -> None:
        self._renderer.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        renderer = Renderer("rgb_array")
        names = self.scenario.agent_names
        return [renderer.render(self.scenario.scene(b), agent_names=names) for b in range(self.num_copies)]

    def render(self, mode: str | None = None) -> np.ndarray | None:
        """Copy 0 through the shared renderer."""
        if (mode or self.render_mode) is None:
            return None
        return Renderer(mode or self.render_mode).render(self.scenario.scene(0), agent_names=self.scenario.agent_names)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self, attr_name) if hasattr(self, attr_name) else getattr(self.scenario, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"sub-envs of a batched scenario share their attributes; cannot set {attr_name!r}")

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        if method_name == "action_masks":  # one row per sub-env (sb3_contrib's get_action_masks stacks them)
            masks = self.action_masks(*method_args, **method_kwargs)
            return [masks[i] for i in self._get_indices(indices)]
        result = getattr(self.scenario, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]
