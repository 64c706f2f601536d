"""The policy interface shared by every scenario: ``act(observations) -> actions``."""

from __future__ import annotations

import numpy as np

# The second word of every policy's per-episode seed, [seed, POLICY_STREAM]: the env draws episode e from
# default_rng(seed), so a policy seeded with the bare seed would replay the env's own random numbers.
POLICY_STREAM = 0x9E3779B9


def episode_generator(seed: int) -> np.random.Generator:
    """The generator a stochastic policy draws from in the episode ``env.reset(seed=seed)`` plays:
    ``default_rng([seed, POLICY_STREAM])``, a stream apart from the env's ``default_rng(seed)``."""
    return np.random.default_rng([int(seed), POLICY_STREAM])


def own_choice_only(masks: np.ndarray, num_agents: int) -> np.ndarray:
    """Action masks (rows, ...) of sub-envs ordered copy by copy, agent by agent, whose first entry's block (the
    first ``num_agents`` choices) keeps only the agent's own index: an entry left to the paper's rule
    (``agents.paper_entries``), so that a masked training spends no entropy and no gradient on it."""
    out = np.array(masks, dtype=bool, copy=True)
    out[:, :num_agents] = False
    out[np.arange(len(out)), np.arange(len(out)) % num_agents] = True
    return out


class Policy:
    """Maps a dict of observations (one per live agent) to a dict of actions.

    Policies that read privileged state (``greedy``, ``oracle_*``) keep a
    reference to the env and say so in their docstring.

    ``batching`` says how an evaluation (``train.evaluate``) may play many episodes at
    once on the scenario's batched core, with the same actions as the env loop:

    ========== ===========================================================================
    batching   what the policy reads, and how it is batched
    ========== ===========================================================================
    per_copy   only the observations ``act`` is given, the env's spaces and agent names, and
               its own generator: a shallow copy per episode, each given its copy's
               observations (so state is replaced, as ``start_episode`` replaces the
               generator, never mutated in place)
    core       the scenario core it was built on, every copy at once: built on a view of the
               batched core, ``batch_actions`` returns every copy's actions
    None       the env (or its core at batch 1) in ways that do not batch: the env loop only
    ========== ===========================================================================
    """

    batching: str | None = None

    def __init__(self, env):
        self.env = env

    def act(self, observations: dict) -> dict:  # pragma: no cover - interface
        raise NotImplementedError

    def observation_rows(self, observations: dict) -> tuple[list[str], np.ndarray]:
        """The env's agents in order and their observations stacked as floats (N, obs_dim), zeros for an agent
        without one (a policy that reads every agent's observation)."""
        order = list(self.env.possible_agents)
        dim = self.env.observation_space(order[0]).shape[0]
        rows = [np.asarray(observations[a], float) if a in observations else np.zeros(dim) for a in order]
        return order, np.stack(rows)

    def start_episode(self, seed: int) -> None:
        """Called by an evaluation before the episode ``env.reset(seed=seed)`` plays. A stochastic
        policy restarts its generator there (``episode_generator``), so that episode e's actions
        depend on its seed alone, whether the episodes run one after another or side by side."""

    def batch_actions(self) -> np.ndarray:  # pragma: no cover - interface of batching = "core"
        """Every copy's actions (B, N, *action_shape) for the batched core this policy was built on."""
        raise NotImplementedError


class SeededPolicy(Policy):
    """A stochastic policy: it draws from its own generator ``rng`` (``default_rng(seed)``), which an evaluation
    restarts for each episode (``episode_generator``)."""

    def __init__(self, env, seed: int | None = None):
        super().__init__(env)
        self.rng = np.random.default_rng(seed)

    def start_episode(self, seed: int) -> None:
        self.rng = episode_generator(seed)


class RandomPolicy(SeededPolicy):
    """Uniform samples of each agent's action space, from its own generator (``seed``; an evaluation
    restarts it for each episode: ``Policy.start_episode``)."""

    batching = "per_copy"

    def act(self, observations):
        actions = {}
        for agent in observations:
            space = self.env.action_space(agent)  # seeded just before its sample: spaces are shared
            space.seed(int(self.rng.integers(2**31 - 1)))
            actions[agent] = space.sample()
        return actions


class FixedActionPolicy(Policy):
    """Plays the same per-agent action every step (``actions``: (N, *action_shape) in agent order)."""

    batching = "per_copy"

    def __init__(self, env, actions: np.ndarray):
        super().__init__(env)
        self.actions = np.asarray(actions)

    def act(self, observations):
        order = self.env.possible_agents
        dtype = self.env.action_space(order[0]).dtype
        return {agent: self.actions[order.index(agent)].astype(dtype) for agent in observations}
