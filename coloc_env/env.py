"""PettingZoo views of a batched scenario: the parallel env (B = 1) and the AEC view."""

from __future__ import annotations

import functools
from collections.abc import Mapping

import numpy as np
from pettingzoo import ParallelEnv

from coloc_env.config import build_config
from coloc_env.rendering import Renderer
from coloc_env.scenarios.base import Scenario


class CoLocParallelEnv(ParallelEnv):
    """PettingZoo ``ParallelEnv`` over one copy of a :class:`Scenario`.

    ``reset(seed=s)`` gives the env ``np.random.default_rng(s)``; ``reset()``
    without a seed continues the same generator (DESIGN.md, Seeding).
    Episodes end by truncation at the scenario's horizon.
    """

    metadata = {"render_modes": [None, "rgb_array", "human"], "is_parallelizable": True, "render_fps": 5}

    def __init__(self, scenario_cls: type[Scenario], render_mode: str | None = None, *, composition=None, **config):
        if composition is not None:  # a composition's scenario validates its own config
            self.scenario = scenario_cls(composition, batch=1)
        else:
            self.scenario = scenario_cls(build_config(scenario_cls.Config, config), batch=1)
        self.metadata = dict(self.metadata, name=self.scenario.name)
        self._renderer = Renderer(render_mode)
        self.render_mode = render_mode
        self.possible_agents = self.scenario.agent_names
        self.agents: list[str] = []
        self._rng: np.random.Generator | None = None
        self._observation_space = self.scenario.observation_space()
        self._action_space = self.scenario.action_space()
        self.state_space = self.scenario.state_space()

    @functools.cache  # noqa: B019 - one space per agent name, shared by design
    def observation_space(self, agent):
        return self._observation_space

    @functools.cache  # noqa: B019
    def action_space(self, agent):
        return self._action_space

    @property
    def config(self):
        return self.scenario.config

    def seed_generator(self, seed: int | None) -> None:
        """Make the next ``reset()`` (without a seed) start as ``reset(seed=seed)`` would.

        For wrappers that call ``reset()`` without a seed (SuperSuit under SB3).
        """
        self._rng = np.random.default_rng(seed)

    def reset(self, seed=None, options=None):
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        self.scenario.reset([self._rng])
        self.agents = list(self.possible_agents)
        return self._observations(), self._infos()

    def step(self, actions):
        if not self.agents:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        stacked = self._stack_actions(actions)
        self.scenario.step(stacked[None])
        rewards = self.scenario.reward()[0]
        done = bool(self.scenario.done()[0])
        observations = self._observations()
        infos = self._infos()
        rewards = {a: float(rewards[i]) for i, a in enumerate(self.possible_agents)}
        terminations = {a: False for a in self.possible_agents}
        truncations = {a: done for a in self.possible_agents}
        if done:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def _stack_actions(self, actions) -> np.ndarray:
        """The action dict as a float array (N, *action_shape), or a ValueError naming the agent."""
        if not isinstance(actions, Mapping):
            raise ValueError(f"actions must be a dict {{agent: action}} for agents {self.agents}, "
                             f"got {type(actions).__name__}")
        unknown = [a for a in actions if a not in self.possible_agents]
        if unknown:
            raise ValueError(f"actions for unknown agent(s) {unknown!r}; the agents are {self.possible_agents}")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"actions missing for agents {missing}")
        shape = tuple(self._action_space.shape)
        rows = []
        for a in self.possible_agents:
            value = actions[a]
            try:
                raw = np.asarray(value)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"action of {a} must be an array of shape {shape}, got {value!r}") from exc
            if raw.dtype.kind not in "biuf":
                raise ValueError(f"action of {a} must be real numbers of shape {shape}, got {value!r}")
            if raw.shape != shape:
                raise ValueError(f"action of {a} must have shape {shape}, got shape {raw.shape}: {value!r}")
            rows.append(raw.astype(float))
        return np.stack(rows)

    def _observations(self):
        obs = self.scenario.observation()[0]
        return {a: obs[i] for i, a in enumerate(self.possible_agents)}

    def _infos(self):
        info = self.scenario.info()
        return {a: {k: v[0, i] for k, v in info.items()} for i, a in enumerate(self.possible_agents)}

    def state(self):
        return self.scenario.state()[0]

    def render(self):
        if self.render_mode is None:
            return None
        return self._renderer.render(self.scenario.scene(0))

    def close(self):
        self._renderer.close()
