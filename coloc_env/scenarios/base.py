"""The scenario interface: one batched core that every env view wraps.

A scenario holds B copies of a world + network + estimator and steps them in
one numpy call. ``env_index=None`` means all copies (VMAS's convention).
Subclasses document observation, action, reward and termination in a
cartpole-style table in their module docstring.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import ClassVar

import gymnasium
import numpy as np

from coloc_env.config import validate_fields
from coloc_env.rendering import Scene


class Scenario(abc.ABC):
    """Batched core of one paper setting. Shapes: B copies, N agents."""

    name: ClassVar[str]
    paper: ClassVar[str]
    Config: ClassVar[type]
    agent_prefix: ClassVar[str] = "uav"
    # The info key whose per-step values the episode metric reduces (``episode_error``'s ``errors``).
    metric_error_key: ClassVar[str] = "error"
    # An info key whose per-step values weight the episode metric (None: unweighted).
    metric_weight_key: ClassVar[str | None] = None

    def __init__(self, config, batch: int = 1):
        if not isinstance(batch, (int, np.integer)) or batch < 1:
            raise ValueError(f"batch must be a positive integer, got {batch!r}")
        if dataclasses.is_dataclass(config) and not hasattr(config, "world"):
            validate_fields(config)
        else:
            config.validate()
        self.config = config
        self.batch = int(batch)

    # --- static description -------------------------------------------------
    @property
    def num_agents(self) -> int:
        """N; by default the config's ``num_agents`` (a scenario whose agents are named otherwise overrides)."""
        return self.config.num_agents

    @property
    def horizon(self) -> int:
        """Steps per episode (truncation); by default the config's ``horizon``."""
        return self.config.horizon

    @abc.abstractmethod
    def observation_space(self) -> gymnasium.spaces.Space: ...

    @abc.abstractmethod
    def action_space(self) -> gymnasium.spaces.Space: ...

    @abc.abstractmethod
    def state_space(self) -> gymnasium.spaces.Box: ...

    @property
    def agent_names(self) -> list[str]:
        return [f"{self.agent_prefix}_{i}" for i in range(self.num_agents)]

    # --- dynamics -------------------------------------------------------------
    def _indices(self, env_index) -> np.ndarray:
        if env_index is None:
            return np.arange(self.batch)
        idx = np.atleast_1d(np.asarray(env_index, dtype=int))
        if np.any((idx < 0) | (idx >= self.batch)):
            raise ValueError(f"env_index must be in [0, {self.batch - 1}], got {env_index!r}")
        return idx

    @abc.abstractmethod
    def reset(self, rngs: list[np.random.Generator], env_index=None) -> None:
        """Start new episodes in the copies ``env_index`` (None = all), one generator per copy."""

    @abc.abstractmethod
    def step(self, actions: np.ndarray) -> None:
        """Advance every copy one step; ``actions`` has shape (B, N, *action_shape)."""

    @abc.abstractmethod
    def observation(self) -> np.ndarray: ...

    @abc.abstractmethod
    def reward(self) -> np.ndarray: ...

    @abc.abstractmethod
    def done(self) -> np.ndarray: ...

    @abc.abstractmethod
    def state(self) -> np.ndarray: ...

    @abc.abstractmethod
    def info(self) -> dict[str, np.ndarray]: ...

    @abc.abstractmethod
    def true_position(self) -> np.ndarray:
        """Every agent's ``infos[agent]["true_position"]`` at once: (B, N, d), the truth at the time of the
        current estimate, in the same d and unit as that info key."""

    @abc.abstractmethod
    def scene(self, b: int) -> Scene: ...

    def action_mask(self) -> np.ndarray | None:
        """The choices valid now, for the next step's action, from what the agents may know: bool.

        ``Discrete(n)``: (B, N, n); ``MultiDiscrete(nvec)``: (B, N, sum(nvec)), one boolean vector per
        dimension, concatenated in order (the layout of sb3_contrib's ``MaskableMultiCategorical``);
        None for a ``Box`` or ``MultiBinary`` space (nothing to mask). Default: every choice valid. A
        scenario masks a choice only where the env would refuse it or where it does nothing by
        definition (an alias of an explicit "stop" / "none" choice), never on what the agents cannot
        observe; at least one choice of every dimension stays valid. The env views pass it on:
        ``infos[agent]["action_mask"]`` and ``CoLocVecEnv.action_masks()``.
        """
        space = self.action_space()
        if isinstance(space, gymnasium.spaces.Discrete):
            size = int(space.n)
        elif isinstance(space, gymnasium.spaces.MultiDiscrete):
            size = int(np.sum(space.nvec))
        else:
            return None
        return np.ones((self.batch, self.num_agents, size), dtype=bool)

    def initial_cost(self) -> float:
        """Expected cost of the state before the first step, which an episode's return does not
        contain but a paper's cost may (bandwidth_fusion's k = 0 term). 0 by default."""
        return 0.0

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The paper's metric of whole episodes from ``infos[agent]["error"]``.

        ``errors`` has shape (..., T, N): every step's error of every agent
        (``infos[agent][metric_error_key]``, by default ``"error"``);
        ``weights`` the same shape, ``infos[agent][metric_weight_key]`` where the
        scenario names one. Default: the sum over steps and agents, a cost like
        J_K. A scenario whose paper averages over time, over some agents only,
        or whose estimate is shared by all agents, overrides this (its
        docstring says which).
        """
        return np.asarray(errors, float).sum(axis=(-2, -1))

    # --- helpers for subclasses ----------------------------------------------
    def refuse_action(self, bad: np.ndarray, values: np.ndarray, rule: str, labels=()) -> None:
        """Raise the ValueError of the first True entry of ``bad`` (B, N, k): ``"{label} of {agent} must be
        {rule}, got {value}"`` (``", copy b"`` after the agent where B > 1); ``labels[i]`` names entry i of
        an agent's flat action (default ``action[i]``). The one message every action check uses."""
        flat_bad = np.asarray(bad).reshape(self.batch, self.num_agents, -1)
        flat_values = np.asarray(values, float).reshape(self.batch, self.num_agents, -1)
        copy, agent, i = (int(v) for v in np.argwhere(flat_bad)[0])
        label = labels[i] if i < len(labels) else f"action[{i}]"
        where = self.agent_names[agent] + (f", copy {copy}" if self.batch > 1 else "")
        raise ValueError(f"{label} of {where} must be {rule}, got {flat_values[copy, agent, i]:g}")

    def check_actions(self, actions) -> np.ndarray:
        """Actions as a float array (B, N, *shape); a NaN/inf (naming the agent), a wrong shape, a string or a
        complex number is a ValueError.

        The rule for values, the same in every scenario and composition: entries of a continuous (``Box``)
        block are clipped to their bounds; entries of a discrete block outside its choices (or, in a
        ``MultiDiscrete``, not integers) and non-finite values anywhere are refused with a ValueError
        naming the agent (``refuse_action``)."""
        space = self.action_space()
        raw = np.asarray(actions)
        if raw.dtype.kind not in "biuf":  # strings (even "1"), complex numbers, None, objects: refused
            raise ValueError(f"actions must be real numbers, got an array of dtype {raw.dtype}")
        arr = raw.astype(float)
        expected = (self.batch, self.num_agents, *space.shape)
        if arr.shape != expected:
            raise ValueError(f"actions must have shape {expected} (batch, agents, *action_shape), got {arr.shape}")
        if not np.isfinite(arr).all():
            self.refuse_action(~np.isfinite(arr), arr, "finite")
        return arr

    def check_discrete_actions(self, actions, labels=()) -> np.ndarray:
        """MultiDiscrete actions as int64 (B, N, k): finite (``check_actions``), integral and in
        [0, nvec). A value out of range is a ValueError naming its index by ``labels[i]`` (what index
        i chooses; default ``action[i]``)."""
        nvec = np.asarray(self.action_space().nvec)
        raw = np.asarray(actions)
        # integers (or bools) of the right shape, all in range: a policy's usual output, which the checks below
        # would pass unchanged; anything else goes through them (and their errors)
        if raw.dtype.kind in "biu" and raw.shape == (self.batch, self.num_agents, *nvec.shape) and (
                (raw >= 0) & (raw < nvec)).all():
            return raw.astype(np.int64)
        arr = self.check_actions(actions)
        bad = (arr != np.round(arr)) | (arr < 0) | (arr >= nvec)
        if np.any(bad):
            i = int(np.argwhere(bad.reshape(self.batch, self.num_agents, -1))[0][2])
            self.refuse_action(bad, arr, f"an integer in [0, {nvec.reshape(-1)[i] - 1}]", labels)
        return arr.astype(np.int64)
