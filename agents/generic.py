"""Policies that work on any composition: ``always``, ``silent`` and ``greedy`` (``random`` is
``agents.base.RandomPolicy``).

``always`` plays every transport decision at its maximum (the full relay chain
nearest first, a broadcast at every opportunity, every packet transmitted);
``silent`` sends nothing; both keep the world's and the backend's default
decisions (the paper's weights, horizon, the nearest ranging partner). They
read only the composition's action blocks (``ComposedScenario.action_vector``).
``greedy`` (``GreedyPolicy``) looks one step ahead with the backend's own
covariance, where the backend has one.
"""

from __future__ import annotations

import copy
import itertools

import numpy as np

from agents.base import FixedActionPolicy, Policy
from coloc_env.config import BadInput
from coloc_env.scenarios.binding import PresetScenario


def _is_composition(scenario) -> bool:
    """A plain composition's actions are its blocks; a preset binding has its own action codec (and policies)."""
    return hasattr(scenario, "action_vector") and not isinstance(scenario, PresetScenario)


def _fixed(env, which: str) -> FixedActionPolicy:
    scenario = env.unwrapped.scenario
    if not _is_composition(scenario):
        raise BadInput(f"policy {'always' if which == 'maximum' else 'silent'!r} needs a composition "
                       f"(coloc_env.compose); {scenario.name} is a preset with its own policies")
    vector = scenario.action_vector(which)
    return FixedActionPolicy(env, np.tile(vector, (scenario.num_agents, 1)))


def always(env) -> FixedActionPolicy:
    """Every transport decision at its maximum, the default sensing and backend decisions."""
    return _fixed(env, "maximum")


def silent(env) -> FixedActionPolicy:
    """Nothing sent (every transport decision at its minimum), the default sensing and backend decisions."""
    return _fixed(env, "minimum")


class GreedyPolicy(Policy):
    """One-step look-ahead of the backend's own covariance (privileged: it copies the env's batched core).

    At each step it starts from the ``always`` action and, agent by agent in index order (the others
    at their choice so far), tries every candidate of that agent's discrete transport and backend
    entries on a copy of the core, keeping the candidate with the least team cost after this step's
    update

        J = sum_i tr P_i  +  communication_cost * (messages sent this step),

    tr P_i the trace the composition's ``reward="trace"`` uses (each agent's position covariance, or
    for a target world tr(M P_i M^T)). Ties keep the earlier candidate, so the result is never worse
    in J than ``always``. The copy steps with the readings of time k (what the agents have measured
    when they decide) and J reads only the backend's covariance, never the truth. Candidates: every
    combination of the agent's discrete network and backend entries when there are at most
    ``max_candidates`` of them, else each entry alone with the others fixed (coordinate search);
    sensing choices and continuous entries stay at their defaults.
    """

    def __init__(self, env, max_candidates: int = 64):
        super().__init__(env)
        core = env.unwrapped.scenario
        if not _is_composition(core):
            raise BadInput(f"policy 'greedy' needs a composition (coloc_env.compose); {core.name} is a preset "
                           "with its own policies")
        self.max_candidates = int(max_candidates)
        self.start = core.action_vector("maximum")
        entries, choices = [], []
        position = 0
        for blk, part in zip(core.blocks, core.block_parts, strict=True):
            for _ in range(blk.size):
                if blk.discrete and part in ("network", "backend") and blk.choices > 1:
                    entries.append(position)
                    choices.append(blk.choices)
                position += 1
        if not entries:
            raise BadInput(f"policy 'greedy' needs a decision to make; {core.name} has no transport or "
                           "backend decisions")
        self.entries = entries
        if int(np.prod(choices, dtype=float)) <= self.max_candidates:
            self.candidates = [dict(zip(entries, values, strict=True))
                               for values in itertools.product(*[range(c) for c in choices])]
        else:
            self.candidates = [{e: v} for e, c in zip(entries, choices, strict=True) for v in range(c)]
        if self._team_cost(core, np.tile(self.start, (core.num_agents, 1))) is None:
            raise BadInput(f"policy 'greedy' needs a backend with a covariance; {core.name}'s has none")

    batching = "core"

    @staticmethod
    def _team_costs(core, actions: np.ndarray) -> np.ndarray | None:
        """J per copy (B,) after stepping a copy of the batched ``core`` with ``actions`` (B, N, A); None where the
        backend has no covariance."""
        trial = copy.deepcopy(core)
        trial.step(actions)
        if getattr(trial, "estimand", "self") == "target":
            trace = trial.metric_traces()
        else:
            trace = trial.posterior_traces()
        if trace is None:
            return None
        return trace.sum(axis=-1) + trial.config.communication_cost * trial.network.messages_sent.sum(axis=-1)

    @staticmethod
    def _team_cost(core, actions: np.ndarray) -> float | None:
        """J of the first copy after stepping a copy of ``core`` with ``actions`` (N, A) in every copy."""
        costs = GreedyPolicy._team_costs(core, np.array(np.broadcast_to(actions, (core.batch, *np.shape(actions)))))
        return None if costs is None else float(costs[0])

    def batch_actions(self) -> np.ndarray:
        """(B, N, A): each copy's choice, copies searched at once (one trial step of the batched core per agent and
        candidate); each copy chooses what ``act`` chooses on it alone."""
        core = self.env.unwrapped.scenario
        actions = np.tile(self.start, (core.batch, core.num_agents, 1)).astype(float)
        best = self._team_costs(core, actions)
        for agent in range(core.num_agents):
            for candidate in self.candidates:
                trial = actions.copy()
                for entry, value in candidate.items():
                    trial[:, agent, entry] = value
                changed = np.any(trial != actions, axis=(1, 2))
                if not changed.any():
                    continue
                cost = self._team_costs(core, trial)
                better = changed & (cost < best)
                best = np.where(better, cost, best)
                actions[better] = trial[better]
        return actions

    def act(self, observations: dict) -> dict:
        actions = self.batch_actions()[0]
        names = self.env.possible_agents
        dtype = self.env.action_space(names[0]).dtype
        return {a: actions[names.index(a)].astype(dtype) for a in observations}


def greedy(env) -> GreedyPolicy:
    """One-step look-ahead of the backend's own covariance plus the communication cost (see ``GreedyPolicy``)."""
    return GreedyPolicy(env)


POLICIES = {"always": always, "silent": silent, "greedy": greedy}
