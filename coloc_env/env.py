"""PettingZoo views of a batched scenario: the parallel env (B = 1) and the AEC view.

``max_cycles`` is PettingZoo's name for the episode length (its
``max_cycles_test`` and the SISL/butterfly environments use it): every env
here accepts it and writes it into the field that sets the episode length,
the preset's declared ``episode_length_field`` (``horizon``; ``window_steps`` for
mrclam_relay, the replayed window) or a composition's ``horizon`` (``with_max_cycles``).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import gymnasium
import numpy as np
from pettingzoo import ParallelEnv

from coloc_env.config import BadInput, build_config, check_range, check_seed, module_names
from coloc_env.rendering import Renderer
from coloc_env.scenarios.base import Scenario

MAX_CYCLES_LIMIT = 1_000_000_000


def episode_length_field(scenario_cls: type[Scenario]) -> str:
    """The name of the config field of ``scenario_cls`` that ``max_cycles`` sets: a preset's declared
    ``episode_length_field``, ``horizon`` otherwise."""
    return getattr(scenario_cls, "episode_length_field", "horizon")


def with_max_cycles(scenario_cls: type[Scenario], composition, config: dict, max_cycles: int | None):
    """``(composition, config)`` with the episode length set to ``max_cycles`` (None: unchanged).

    A preset's flat config gets its episode-length field (``episode_length_field``); a
    composition gets ``Composition.replace(horizon=max_cycles)``. Giving both ``max_cycles`` and that
    field with different values is a ValueError, so neither silently wins.
    """
    if max_cycles is None:
        return composition, config
    check_range("max_cycles", max_cycles, 1, MAX_CYCLES_LIMIT, integer=True)
    if composition is not None:
        try:
            return composition.replace(horizon=int(max_cycles)), config
        except ValueError as exc:
            raise BadInput(f"max_cycles sets the composition's horizon: {exc}") from exc
    field = episode_length_field(scenario_cls)
    if field in config and config[field] != max_cycles:
        raise BadInput(f"max_cycles={max_cycles!r} and {field}={config[field]!r} both set the episode length "
                         f"of {scenario_cls.name}; give one of them")
    return composition, {**config, field: int(max_cycles)}


def build_scenario(scenario_cls: type[Scenario], batch: int, composition=None, max_cycles: int | None = None,
                   **config) -> Scenario:
    """``scenario_cls`` over ``batch`` copies from its flat config or a composition (and ``max_cycles``)."""
    composition, config = with_max_cycles(scenario_cls, composition, config, max_cycles)
    if composition is not None:  # a composition's scenario validates its own config
        return _built(scenario_cls, composition, batch)
    field = episode_length_field(scenario_cls)
    try:
        built = build_config(scenario_cls.Config, config)
    except ValueError as exc:
        message = str(exc).removeprefix(f"{scenario_cls.name}: ")  # a PresetConfig names its preset first
        if max_cycles is not None and message.startswith(field):
            raise BadInput(f"max_cycles sets {field} of {scenario_cls.name}: {message}") from exc
        raise
    return _built(scenario_cls, built, batch)


def _built(scenario_cls: type[Scenario], config, batch: int) -> Scenario:
    """``scenario_cls(config, batch)``; a ``ValueError`` while building (a part's build-time check: a range
    that depends on another part, a data file) is the config's fault: a ``BadInput``."""
    try:
        return scenario_cls(config, batch=batch)
    except BadInput:
        raise
    except ValueError as exc:
        raise BadInput(str(exc)) from exc


class MaskableMultiDiscrete(gymnasium.spaces.MultiDiscrete):
    """A ``MultiDiscrete`` whose ``sample(mask)`` also takes ``infos[agent]["action_mask"]``: an array of
    sum(nvec) 0/1 entries, one vector per dimension in order (any shape; gymnasium's tuple still works).
    PettingZoo's idiom ``env.action_space(agent).sample(info["action_mask"])`` then samples a valid action."""

    def sample(self, mask=None, probability=None):
        if isinstance(mask, np.ndarray) and self.nvec.ndim == 1 and mask.size == int(np.sum(self.nvec)):
            mask = tuple(np.split(mask.reshape(-1).astype(np.int8), np.cumsum(self.nvec)[:-1]))
        return super().sample(mask=mask, probability=probability)


def info_action_mask(space, mask: np.ndarray) -> np.ndarray:
    """One agent's flat mask (sum(nvec),) as ``infos[agent]["action_mask"]``: int8, flat, except (k, n) for a
    ``MultiDiscrete`` of k equal sizes n (the shape of TorchRL's one-hot spec of such a space, which its
    PettingZoo wrapper fills from this key). ``reshape(-1)`` always gives the flat layout."""
    mask = np.asarray(mask, dtype=np.int8)
    shape = _info_mask_shape(space)
    return mask if shape is None else mask.reshape(shape)


def _info_mask_shape(space) -> tuple[int, int] | None:
    """(k, n) for a ``MultiDiscrete`` of k equal sizes n, else None (flat): ``info_action_mask``'s layout."""
    if isinstance(space, gymnasium.spaces.MultiDiscrete) and space.nvec.ndim == 1 and len(np.unique(space.nvec)) == 1:
        return len(space.nvec), int(space.nvec[0])
    return None


class CoLocParallelEnv(ParallelEnv):
    """PettingZoo ``ParallelEnv`` over one copy of a ``Scenario``.

    ``reset(seed=s)`` gives the env ``np.random.default_rng(s)``; ``reset()``
    without a seed continues the same generator.
    Episodes end by truncation at the scenario's horizon; ``max_cycles``
    (PettingZoo's keyword) sets it (``with_max_cycles``).

    Where the action space is discrete (``Discrete`` / ``MultiDiscrete``), ``infos[agent]["action_mask"]``
    (at reset and every step) is the scenario's ``coloc_env.scenarios.base.Scenario.action_mask``
    for that agent as ``np.int8``: 1 = valid now. ``Discrete(n)``: shape (n,). ``MultiDiscrete(nvec)``: the
    concatenation of one vector per dimension (sb3_contrib's layout), flat (sum(nvec),), or (k, n) where
    all k sizes are n (``info_action_mask``, TorchRL's shape); the env's ``MaskableMultiDiscrete``
    takes it in ``action_space(agent).sample(mask)``, PettingZoo's idiom. Masked choices are never
    refused: by definition they do what a valid choice does (the scenario's table).
    """

    metadata = {"render_modes": [None, "rgb_array", "human"], "is_parallelizable": True, "render_fps": 5}

    def __init__(self, scenario_cls: type[Scenario], render_mode: str | None = None, *, composition=None,
                 max_cycles: int | None = None, **config):
        self.scenario = build_scenario(scenario_cls, 1, composition, max_cycles, **config)
        self.metadata = dict(self.metadata, name=self.scenario.name)
        self._renderer = Renderer(render_mode)
        self.render_mode = render_mode
        self.possible_agents = self.scenario.agent_names
        self.agents: list[str] = []
        self.step_count = 0  # steps of the current episode (a recurrent policy starts its memory at 0)
        self._rng: np.random.Generator | None = None
        self._observation_space = self.scenario.observation_space()
        self._action_space = self.scenario.action_space()
        if type(self._action_space) is gymnasium.spaces.MultiDiscrete:  # sample(mask) takes the infos' mask
            space = self._action_space
            self._action_space = MaskableMultiDiscrete(space.nvec, dtype=space.dtype, start=space.start)
        self._mask_shape = _info_mask_shape(self._action_space)  # the infos' action-mask layout (fixed)
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
        self._rng = np.random.default_rng(check_seed("seed", seed))

    def reset(self, seed=None, options=None):
        """A new episode; ``seed``: None (continue the generator) or an integer in [0, 2**63 - 1], else a
        ``ValueError`` (a string, a float, a boolean or NaN is never coerced)."""
        seed = check_seed("seed", seed)
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        self.scenario.reset([self._rng])
        self.agents = list(self.possible_agents)
        self.step_count = 0
        return self._observations(), self._infos()

    def step(self, actions):
        if not self.agents:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        stacked = self._stack_actions(actions)
        self.scenario.step(stacked[None])
        self.step_count += 1
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
        infos = {a: {k: v[0, i] for k, v in info.items()} for i, a in enumerate(self.possible_agents)}
        mask = self.scenario.action_mask()
        if mask is not None:  # a discrete action: its valid choices now (info_action_mask)
            mask = mask[0].astype(np.int8)
            if self._mask_shape is not None:
                mask = mask.reshape(len(self.possible_agents), *self._mask_shape)
            for i, a in enumerate(self.possible_agents):
                infos[a]["action_mask"] = mask[i]
        return infos

    def state(self):
        return self.scenario.state()[0]

    def render(self, mode: str | None = None):
        """The frame of the current step (``rgb_array``: an (H, W, 3) uint8 array; ``human``: a window).

        ``mode`` exists for clients that still pass it positionally (RLlib's ``PettingZooEnv.render``
        calls ``env.render(mode)``): it must be None or equal to ``render_mode``, which is fixed when
        the env is made, as PettingZoo's API requires.
        """
        if mode is not None and mode != self.render_mode:
            raise ValueError(f"render mode {mode!r} differs from this env's render_mode {self.render_mode!r}; "
                             "the mode is chosen when the env is made: parallel_env(..., render_mode=...)")
        if self.render_mode is None:
            return None
        return self._renderer.render(self.scenario.scene(0), agent_names=self.possible_agents)

    def close(self):
        self._renderer.close()


def _episode_length_fields() -> dict[str, str]:
    from coloc_env.scenarios import REGISTRY

    return {n: cls.episode_length_field for n, cls in REGISTRY.items() if cls.episode_length_field != "horizon"}


# the table of episode-length fields this module held before each preset declared its own
__getattr__ = module_names(__name__, {"EPISODE_LENGTH_FIELDS": _episode_length_fields},
                           deprecated={"EPISODE_LENGTH_FIELDS": "a preset's class declares episode_length_field"})
