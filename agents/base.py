"""The policy interface shared by every scenario: ``act(observations) -> actions``."""

from __future__ import annotations

import numpy as np


class Policy:
    """Maps a dict of observations (one per live agent) to a dict of actions.

    Policies that read privileged state (``greedy``, ``oracle_*``) keep a
    reference to the env and say so in their docstring.
    """

    def __init__(self, env):
        self.env = env

    def act(self, observations: dict) -> dict:  # pragma: no cover - interface
        raise NotImplementedError


class RandomPolicy(Policy):
    """Uniform samples of each agent's action space, from its own generator (``seed``)."""

    def __init__(self, env, seed: int | None = None):
        super().__init__(env)
        self.rng = np.random.default_rng(seed)

    def act(self, observations):
        actions = {}
        for agent in observations:
            space = self.env.action_space(agent)
            space.seed(int(self.rng.integers(2**31 - 1)))
            actions[agent] = space.sample()
        return actions


class FixedActionPolicy(Policy):
    """Plays the same per-agent action every step (``actions``: (N, *action_shape) in agent order)."""

    def __init__(self, env, actions: np.ndarray):
        super().__init__(env)
        self.actions = np.asarray(actions)

    def act(self, observations):
        order = self.env.possible_agents
        dtype = self.env.action_space(order[0]).dtype
        return {agent: self.actions[order.index(agent)].astype(dtype) for agent in observations}
